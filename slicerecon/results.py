"""A case on disk: the result records and the layout of a results folder.

This module is the one owner of what a reconstruction leaves on disk. The
runner (:mod:`pipelines.batch`) writes it; the report (:mod:`slicerecon.report`)
and anyone else read it back with :func:`read_case` / :func:`collect_results`.

Layout
------
A *results folder* holds *case folders* at any depth (hidden folders and
``report_assets/`` are not searched)::

    RESULTS/
      summary.csv              one row per case of the last batch (the runner)
      metrics.csv              one row per case, every metric (the report)
      summary.json             statistics per method/planner (the report)
      report.html              the HTML report
      report_assets/           the report's figures as PNG files
      <case>/                  a finished case (what ``slicerecon run`` writes)
        mesh.<fmt> or meshes/<value>_<name>.<fmt>  structures.json  plan.json
        [metrics.json]  labels.nii.gz  labels.seg.nrrd  preview.png  [done.json]
      <case>/                  a failed case
        error.json
      <case>/<config>/         several configurations of one case
                               (``slicerecon evaluate-dataset``): one case folder each

A case folder is one that holds ``plan.json`` (finished) or ``error.json``
(failed); when both are there the newer file wins. A case's *name* is its
folder's path relative to the results folder, with ``/`` separators
(``liver_003`` for a batch, ``liver_003/loft`` for one method of
``evaluate-dataset``). ``done.json`` is the runner's completion marker: it
holds the resume key, the case's mesh files and the :meth:`CaseResult.to_json`
record of the run.

One schema serves one structure and many (:mod:`slicerecon.case_outputs`
writes it): a case of one structure has ``mesh.<fmt>``, a case of several has
``meshes/<value>_<name>.<fmt>``, and ``structures.json`` lists every structure
with its mesh's path; ``metrics.json`` holds the case's metrics at its top
level (the mean over the structures) and each structure's under ``structures``.

Records
-------
* :class:`CaseResult`: one case (status ``ok``, ``failed`` or ``skipped``,
  metrics, timings, paths); one row of ``summary.csv`` (:meth:`CaseResult.to_row`).
* :class:`FailureRecord`: the one ``error.json`` format.
* :class:`CaseFiles` / :class:`ResultsLayout`: where the files are.
"""

from __future__ import annotations

import csv
import json
import logging
import os
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, get_args

from .errors import InputError

__all__ = [
    "DONE_FILE",
    "ERROR_FILE",
    "KEY_METRICS",
    "MESH_SUFFIXES",
    "METRICS_CSV",
    "METRICS_FILE",
    "PLAN_FILE",
    "PREVIEW_FILE",
    "REPORT_ASSETS",
    "REPORT_FILES",
    "REPORT_HTML",
    "STATUSES",
    "SUMMARY_COLUMNS",
    "SUMMARY_CSV",
    "STRUCTURES_FILE",
    "SUMMARY_JSON",
    "CaseFiles",
    "CaseResult",
    "FailureRecord",
    "ResultsLayout",
    "Status",
    "collect_results",
    "mesh_file",
    "read_case",
    "write_summary",
]

logger = logging.getLogger(__name__)

# -- names --------------------------------------------------------------------------------
PLAN_FILE = "plan.json"
"""A finished case's plan, configuration, sections and timings (``run_case``)."""
METRICS_FILE = "metrics.json"
"""A finished case's metrics against the ground truth (when it was known)."""
PREVIEW_FILE = "preview.png"
"""A finished case's preview image."""
STRUCTURES_FILE = "structures.json"
"""A finished case's structures: names, statuses, volumes and mesh paths."""
MESH_STEM = "mesh"
"""A finished case of one structure has its mesh in ``mesh.<format>``."""
MESHES_DIR = "meshes"
"""A finished case of several structures has one mesh per structure in ``meshes/``."""
MESH_SUFFIXES = (".stl", ".ply", ".obj", ".off")
"""Mesh suffixes looked for in a case folder, in this order."""
ERROR_FILE = "error.json"
"""A failed case's :class:`FailureRecord`."""
DONE_FILE = "done.json"
"""The runner's completion marker (resume key and :meth:`CaseResult.to_json`), written last."""
SUMMARY_CSV = "summary.csv"
"""The runner's table: one :meth:`CaseResult.to_row` per case."""
METRICS_CSV = "metrics.csv"
"""The report's table: one row per case with every metric."""
SUMMARY_JSON = "summary.json"
"""The report's statistics per method/planner."""
REPORT_HTML = "report.html"
"""The report's page."""
REPORT_ASSETS = "report_assets"
"""The report's figures as PNG files (never searched for cases)."""
REPORT_FILES = (METRICS_CSV, SUMMARY_JSON, REPORT_HTML, REPORT_ASSETS)
"""Names the report writes inside a results folder."""

Status = Literal["ok", "failed", "skipped"]
STATUSES: tuple[str, ...] = get_args(Status)
"""``ok``: finished; ``failed``: raised (see ``error.json``); ``skipped``: finished
by an earlier run with the same inputs and options."""

KEY_METRICS = (
    "volume_iou",
    "dice",
    "surface_iou",
    "chamfer_l1_mm",
    "hd95_mm",
    "assd_mm",
    "volume_error",
)
"""Metrics copied into ``summary.csv`` (when ground truth is known)."""
SUMMARY_COLUMNS = (
    "case",
    "input",
    "kind",
    "status",
    "error",
    "error_type",
    "parts",
    "planes",
    "watertight",
    *KEY_METRICS,
    "seconds",
)
"""Columns of ``summary.csv``, in order."""


# -- where the files are ------------------------------------------------------------------
def mesh_file(label: str, mesh_format: str, *, several: bool) -> str:
    """A structure's mesh path relative to its case folder.

    Parameters
    ----------
    label : str
        The structure's ``<value>_<name>`` (:attr:`slicerecon.labels.Structure.label`).
    mesh_format : str
        ``stl``, ``ply`` or ``obj``.
    several : bool
        Whether the case has several structures.

    Returns
    -------
    str
        ``mesh.<format>`` for one structure, ``meshes/<label>.<format>`` for several.
    """
    if several:
        return f"{MESHES_DIR}/{label}.{mesh_format}"
    return f"{MESH_STEM}.{mesh_format}"


@dataclass(frozen=True)
class CaseFiles:
    """The files of one case folder.

    Attributes
    ----------
    directory : Path
        The case folder.
    """

    directory: Path

    @property
    def plan(self) -> Path:
        """``plan.json``."""
        return self.directory / PLAN_FILE

    @property
    def metrics(self) -> Path:
        """``metrics.json``."""
        return self.directory / METRICS_FILE

    @property
    def preview(self) -> Path:
        """``preview.png``."""
        return self.directory / PREVIEW_FILE

    @property
    def structures(self) -> Path:
        """``structures.json``."""
        return self.directory / STRUCTURES_FILE

    @property
    def error(self) -> Path:
        """``error.json``."""
        return self.directory / ERROR_FILE

    @property
    def done(self) -> Path:
        """``done.json``."""
        return self.directory / DONE_FILE

    def mesh(self, mesh_format: str) -> Path:
        """``mesh.<mesh_format>`` (``mesh_format`` without a dot, e.g. ``"stl"``)."""
        return self.directory / f"{MESH_STEM}.{mesh_format}"

    def find_mesh(self) -> Path | None:
        """The case's mesh: ``mesh.<suffix>`` (the first of :data:`MESH_SUFFIXES` that
        exists), else the first structure's mesh of ``structures.json``, or None."""
        found = _first_file(self.directory, MESH_STEM, MESH_SUFFIXES)
        if found is not None:
            return found
        meshes = self.meshes()
        return meshes[0] if meshes else None

    def meshes(self) -> list[Path]:
        """Every structure's mesh that ``structures.json`` lists and that exists, in order."""
        try:
            payload = _read_json(self.structures)
        except (OSError, ValueError):
            return []
        found = []
        for record in payload.get("structures") or []:
            name = record.get("mesh") if isinstance(record, dict) else None
            if isinstance(name, str) and (self.directory / name).is_file():
                found.append(self.directory / name)
        return found

    def find_preview(self) -> Path | None:
        """``preview.png`` when it exists, else None."""
        return self.preview if self.preview.is_file() else None


@dataclass(frozen=True)
class ResultsLayout:
    """Where things live in a results folder.

    Attributes
    ----------
    root : Path
        The results folder.
    """

    root: Path

    def case(self, name: str) -> CaseFiles:
        """The files of case ``name`` (a posix path relative to :attr:`root`)."""
        return CaseFiles(self.root.joinpath(*name.split("/")))

    def case_name(self, directory: Path) -> str:
        """The name of the case folder ``directory`` (its posix path below :attr:`root`)."""
        return directory.relative_to(self.root).as_posix()

    @property
    def summary_csv(self) -> Path:
        """``summary.csv``."""
        return self.root / SUMMARY_CSV

    @property
    def metrics_csv(self) -> Path:
        """``metrics.csv``."""
        return self.root / METRICS_CSV

    @property
    def summary_json(self) -> Path:
        """``summary.json``."""
        return self.root / SUMMARY_JSON

    @property
    def report_html(self) -> Path:
        """``report.html``."""
        return self.root / REPORT_HTML

    @property
    def report_assets(self) -> Path:
        """``report_assets/``."""
        return self.root / REPORT_ASSETS

    def case_folders(self) -> Iterator[Path]:
        """Every case folder below :attr:`root`, in sorted walk order.

        A case folder holds ``plan.json`` or ``error.json``. Hidden folders
        (staging folders of a running batch among them) and ``report_assets``
        are not searched.
        """
        for current, dirs, files in os.walk(self.root):
            dirs[:] = sorted(d for d in dirs if not d.startswith(".") and d != REPORT_ASSETS)
            if PLAN_FILE in files or ERROR_FILE in files:
                yield Path(current)


# -- records ------------------------------------------------------------------------------
@dataclass(frozen=True)
class FailureRecord:
    """What ``error.json`` holds: why a case failed.

    Written as ``{"case", "input", "kind", "error", "type", "method",
    "planner", "traceback", "slicerecon_version"}`` (:meth:`to_json`).
    :meth:`from_json` also reads the older formats: ``"error_type"`` instead
    of ``"type"``, ``method`` / ``planner`` inside a ``"config"`` object, and
    any of the optional keys missing.

    Attributes
    ----------
    case : str
        The case name.
    input : str or None
        The input path the reconstruction was given.
    error : str
        The message (without the exception's name).
    error_type : str
        The exception's class name (``"type"`` in the file); empty when unknown.
    kind : str
        The input kind (:data:`pipelines.discover.CASE_KINDS`); empty when unknown.
    method, planner : str or None
        The configuration's surface method and planner.
    traceback : str
        The formatted traceback (empty when there is none to give).
    slicerecon_version : str
        The version that ran the case.
    """

    case: str
    input: str | None
    error: str
    error_type: str = ""
    kind: str = ""
    method: str | None = None
    planner: str | None = None
    traceback: str = ""
    slicerecon_version: str = ""

    @classmethod
    def from_exception(
        cls,
        exc: BaseException,
        *,
        case: str,
        input: str | None,
        kind: str = "",
        method: str | None = None,
        planner: str | None = None,
        traceback: str = "",
    ) -> FailureRecord:
        """The record of ``exc`` (its message, or its class name when it has none)."""
        from . import __version__

        return cls(
            case=case,
            input=input,
            error=str(exc) or type(exc).__name__,
            error_type=type(exc).__name__,
            kind=kind,
            method=method,
            planner=planner,
            traceback=traceback,
            slicerecon_version=__version__,
        )

    @property
    def text(self) -> str:
        """``"<type>: <message>"`` (the message alone when the type is unknown or
        already leads it)."""
        return _error_text(self.error, self.error_type)

    def to_json(self) -> dict[str, Any]:
        """The ``error.json`` object."""
        return {
            "case": self.case,
            "input": self.input,
            "kind": self.kind,
            "error": self.error,
            "type": self.error_type,
            "method": self.method,
            "planner": self.planner,
            "traceback": self.traceback,
            "slicerecon_version": self.slicerecon_version,
        }

    @classmethod
    def from_json(cls, payload: Mapping[str, Any], *, case: str = "") -> FailureRecord:
        """Read an ``error.json`` object (this format or an older one).

        Parameters
        ----------
        payload : mapping
            The decoded file.
        case : str
            The case name to use when the file gives none.
        """
        config = _sub(payload, "config")
        method = payload.get("method", config.get("method"))
        planner = payload.get("planner", config.get("planner"))
        kind = payload.get("type", payload.get("error_type"))
        return cls(
            case=str(payload.get("case") or case),
            input=_str_or_none(payload.get("input")),
            error=str(payload.get("error") or "unknown error"),
            error_type="" if not kind else str(kind),
            kind=str(payload.get("kind") or ""),
            method=_str_or_none(method),
            planner=_str_or_none(planner),
            traceback=str(payload.get("traceback") or ""),
            slicerecon_version=str(payload.get("slicerecon_version") or ""),
        )

    def write(self, directory: str | os.PathLike[str]) -> Path:
        """Write ``directory/error.json`` atomically; return its path."""
        from .io.atomic import atomic_path

        target = Path(directory) / ERROR_FILE
        with atomic_path(target) as tmp:
            tmp.write_text(json.dumps(self.to_json(), indent=2) + "\n", encoding="utf-8")
        return target


@dataclass(frozen=True)
class CaseResult:
    """One case: how it ended, what it measured and where its files are.

    The runner makes one per case (status ``ok``, ``failed`` or
    ``skipped``); :func:`read_case` makes one from a case folder (``ok`` or
    ``failed``). Fields that a source does not know stay at their defaults.

    Attributes
    ----------
    case : str
        The case name: its folder relative to the results folder (posix).
    input : str or None
        The input as the run names it: relative to INDIR for a batch (as in
        ``summary.csv``); else the path ``plan.json`` / ``error.json`` records.
    kind : str
        Input kind (:data:`pipelines.discover.CASE_KINDS`); empty when unknown.
    status : {"ok", "failed", "skipped"}
        ``skipped``: finished by an earlier run with the same key.
    error, error_type : str
        Message and exception class name of a failed case (else empty).
    parts, planes : int or None
        Number of cuboid parts and of section planes used.
    watertight : bool or None
        Whether the mesh is closed (known to the runner, not to ``plan.json``).
    metrics : mapping of str to float, or None
        The numbers of ``metrics.json`` (None without ground truth, or for a
        failure); ``n_points`` stays an int.
    seconds : float or None
        Wall time of the case as the runner measured it, s (for a skipped
        case: of the run that made its outputs); None when not known (a
        folder written by ``slicerecon run``).
    method, planner : str or None
        The configuration's surface method and planner.
    input_path : str or None
        The input path as ``plan.json`` / ``error.json`` record it (what the
        report resolves to find the ground truth).
    ground_truth : str or None
        The ``--gt`` path as ``plan.json`` records it.
    config : mapping
        ``plan["config"]``, the whole :class:`~slicerecon.reconstruct.ReconstructConfig`
        (empty when not known).
    timings_s : mapping of str to float
        ``plan["timings_s"]``: seconds per stage (read, sections, plan, surface,
        metrics, write).
    directory : Path or None
        The case folder.
    structure_metrics : mapping of str to mapping, or None
        A case with several structures: each structure's metrics by its
        ``<value>_<name>`` (then :attr:`metrics` holds their mean).
    mesh_path, preview_path : Path or None
        The reconstructed mesh / preview PNG when present.
    """

    case: str
    input: str | None = None
    kind: str = ""
    status: Status = "ok"
    error: str = ""
    error_type: str = ""
    parts: int | None = None
    planes: int | None = None
    watertight: bool | None = None
    metrics: Mapping[str, float] | None = None
    seconds: float | None = None
    method: str | None = None
    planner: str | None = None
    input_path: str | None = None
    ground_truth: str | None = None
    config: Mapping[str, Any] = field(default_factory=dict)
    timings_s: Mapping[str, float] = field(default_factory=dict)
    directory: Path | None = None
    mesh_path: Path | None = None
    preview_path: Path | None = None
    structure_metrics: Mapping[str, Mapping[str, float]] | None = None

    def __post_init__(self) -> None:
        if self.status not in STATUSES:
            raise ValueError(f"status must be one of {', '.join(STATUSES)} (got {self.status!r})")

    @property
    def ok(self) -> bool:
        """True when the case is finished (``ok`` or ``skipped``; it may lack metrics)."""
        return self.status != "failed"

    @property
    def group(self) -> str:
        """``"method/planner"`` label of the case's group."""
        return f"{self.method or '?'}/{self.planner or '?'}"

    @property
    def error_text(self) -> str:
        """``"<type>: <message>"`` of a failed case (empty for a finished one)."""
        return _error_text(self.error, self.error_type)

    @property
    def stage_seconds(self) -> float | None:
        """The sum of :attr:`timings_s`, s (None when there are none)."""
        if not self.timings_s:
            return None
        return float(sum(float(v) for v in self.timings_s.values()))

    def to_row(self) -> dict[str, Any]:
        """The ``summary.csv`` row: one value per :data:`SUMMARY_COLUMNS` entry."""
        metrics = self.metrics or {}
        row: dict[str, Any] = {
            "case": self.case,
            "input": self.input or "",
            "kind": self.kind,
            "status": self.status,
            "error": self.error.replace("\n", " ").strip(),
            "error_type": self.error_type,
            "parts": "" if self.parts is None else self.parts,
            "planes": "" if self.planes is None else self.planes,
            "watertight": "" if self.watertight is None else str(self.watertight).lower(),
            "seconds": "" if self.seconds is None else f"{self.seconds:.3f}",
        }
        for name in KEY_METRICS:
            value = metrics.get(name)
            row[name] = "" if value is None else f"{value:.6g}"
        return row

    def to_json(self) -> dict[str, Any]:
        """The run's record kept in ``done.json`` (``"result"``): the :meth:`to_row`
        fields as JSON values (metrics as a mapping), plus method and planner."""
        return {
            "case": self.case,
            "input": self.input,
            "kind": self.kind,
            "status": self.status,
            "parts": self.parts,
            "planes": self.planes,
            "watertight": self.watertight,
            "metrics": dict(self.metrics or {}),
            "seconds": self.seconds,
            "method": self.method,
            "planner": self.planner,
        }


# -- reading ------------------------------------------------------------------------------
def _error_text(message: str, kind: str) -> str:
    if kind and not message.startswith(f"{kind}:"):
        return f"{kind}: {message}"
    return message


def _read_json(path: Path) -> dict[str, Any]:
    payload = json.loads(path.read_text(encoding="utf-8"))
    if not isinstance(payload, dict):
        raise ValueError("not a JSON object")
    return payload


def _sub(payload: Mapping[str, Any], key: str) -> dict[str, Any]:
    value = payload.get(key)
    return value if isinstance(value, dict) else {}


def _str_or_none(value: object) -> str | None:
    return None if value is None else str(value)


def _first_file(directory: Path, stem: str, suffixes: Iterable[str]) -> Path | None:
    for suffix in suffixes:
        candidate = directory / f"{stem}{suffix}"
        if candidate.is_file():
            return candidate
    return None


def _as_int(value: object) -> int | None:
    try:
        return None if value is None else int(value)  # type: ignore[call-overload]
    except (TypeError, ValueError):
        return None


def _as_float(value: object) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return float(value)


def _numbers(raw: Mapping[str, Any]) -> dict[str, float]:
    return {
        str(k): v for k, v in raw.items() if isinstance(v, int | float) and not isinstance(v, bool)
    }


def _failed(name: str, directory: Path, record: FailureRecord) -> CaseResult:
    return CaseResult(
        case=name,
        input=record.input,
        kind=record.kind,
        status="failed",
        error=record.error,
        error_type=record.error_type,
        method=record.method,
        planner=record.planner,
        input_path=record.input,
        directory=directory,
    )


def _done_record(files: CaseFiles) -> dict[str, Any]:
    """``done.json``'s ``result`` object, or empty (absent or unreadable: not an error)."""
    try:
        return _sub(_read_json(files.done), "result")
    except (OSError, ValueError):
        return {}


def read_case(directory: str | os.PathLike[str], *, name: str | None = None) -> CaseResult:
    """Read one case folder.

    Parameters
    ----------
    directory : path-like
        A folder holding ``plan.json`` (finished) or ``error.json`` (failed);
        when both are there the newer file wins, so a re-run that failed is
        not hidden by an old success.
    name : str, optional
        The case name (default: the folder's name).

    Returns
    -------
    CaseResult
        Status ``ok`` or ``failed``. An unreadable ``plan.json``,
        ``metrics.json`` or ``error.json`` gives a failed case saying so; a
        folder holding neither file gives a failed case too. ``kind``,
        ``parts``, ``watertight`` and ``seconds`` come from ``done.json`` when
        the runner wrote one.
    """
    folder = Path(directory)
    files = CaseFiles(folder)
    case = folder.name if name is None else name
    has_plan, has_error = files.plan.is_file(), files.error.is_file()
    if has_error and (not has_plan or files.error.stat().st_mtime > files.plan.stat().st_mtime):
        try:
            payload = _read_json(files.error)
        except (OSError, ValueError) as exc:
            record = FailureRecord(case, None, f"unreadable error.json ({exc})")
            return _failed(case, folder, record)
        return _failed(case, folder, FailureRecord.from_json(payload, case=case))
    if not has_plan:
        return _failed(case, folder, FailureRecord(case, None, "no plan.json or error.json"))
    try:
        plan = _read_json(files.plan)
    except (OSError, ValueError) as exc:
        return _failed(case, folder, FailureRecord(case, None, f"unreadable plan.json ({exc})"))
    config = _sub(plan, "config")
    metrics: dict[str, float] | None = None
    per_structure: dict[str, dict[str, float]] | None = None
    if files.metrics.is_file():
        try:
            raw = _read_json(files.metrics)
            if isinstance(raw.get("structures"), dict):  # each structure, and their mean
                per_structure = {
                    str(k): _numbers(v) for k, v in raw["structures"].items() if isinstance(v, dict)
                }
                raw = raw.get("mean") or raw
                if len(per_structure) < 2:
                    per_structure = None
            metrics = _numbers(raw)
        except (OSError, ValueError) as exc:
            record = FailureRecord.from_json(
                {
                    "input": plan.get("input"),
                    "config": config,
                    "error": f"unreadable metrics.json ({exc})",
                },
                case=case,
            )
            return _failed(case, folder, record)
    timings = {
        str(k): float(v) for k, v in _sub(plan, "timings_s").items() if _as_float(v) is not None
    }
    done = _done_record(files)
    recorded_input = _str_or_none(plan.get("input"))
    parts = plan.get("parts")
    if not isinstance(parts, list) and isinstance(plan.get("structures"), list):
        parts = [
            p
            for item in plan["structures"]
            if isinstance(item, dict)
            for p in ((item.get("plan") or {}).get("parts") or [])
        ]
    watertight = done.get("watertight")
    return CaseResult(
        case=case,
        input=_str_or_none(done.get("input")) or recorded_input,
        kind=str(done.get("kind") or ""),
        status="ok",
        parts=len(parts) if isinstance(parts, list) else _as_int(done.get("parts")),
        planes=_as_int(_sub(plan, "sections").get("n_planes")),
        watertight=watertight if isinstance(watertight, bool) else None,
        metrics=metrics,
        seconds=_as_float(done.get("seconds")),
        method=_str_or_none(config.get("method")),
        planner=_str_or_none(config.get("planner")),
        input_path=recorded_input,
        ground_truth=_str_or_none(plan.get("ground_truth")),
        config=dict(config),
        timings_s=timings,
        directory=folder,
        mesh_path=files.find_mesh(),
        preview_path=files.find_preview(),
        structure_metrics=per_structure,
    )


def collect_results(results_dir: str | os.PathLike[str]) -> list[CaseResult]:
    """Read every case folder below ``results_dir``.

    Parameters
    ----------
    results_dir : path-like
        A results folder (see the module documentation): case folders at any
        depth; hidden folders and ``report_assets`` are skipped.

    Returns
    -------
    list of CaseResult
        Sorted by case name. Unreadable JSON files give failed cases, not errors.

    Raises
    ------
    InputError
        If ``results_dir`` does not exist or is not a directory.
    """
    root = Path(results_dir)
    if not root.exists():
        raise InputError(f"results directory not found: {root}")
    if not root.is_dir():
        raise InputError(
            f"{root} is not a directory; pass the directory `slicerecon run/batch` "
            "wrote its case folders into"
        )
    layout = ResultsLayout(root)
    cases = [read_case(folder, name=layout.case_name(folder)) for folder in layout.case_folders()]
    cases.sort(key=lambda c: c.case)
    logger.info("collected %d case(s) from %s", len(cases), root)
    return cases


# -- writing ------------------------------------------------------------------------------
def write_summary(results: Iterable[CaseResult], path: str | os.PathLike[str]) -> Path:
    """Write ``summary.csv`` atomically: complete, or not at all.

    Parameters
    ----------
    results : iterable of CaseResult
        One row each (:meth:`CaseResult.to_row`), in the order given.
    path : path-like
        Target file; an existing one is replaced only by a complete table.

    Returns
    -------
    Path
    """
    from .io.atomic import atomic_path

    target = Path(path)
    with atomic_path(target) as tmp:
        with open(tmp, "w", newline="", encoding="utf-8") as fh:
            writer = csv.DictWriter(fh, fieldnames=list(SUMMARY_COLUMNS))
            writer.writeheader()
            for result in results:
                writer.writerow(result.to_row())
    return target
