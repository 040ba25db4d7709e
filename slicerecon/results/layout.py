"""Where a case's files are: their names, and the layout of a results folder."""

from __future__ import annotations

import json
import os
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal, get_args

__all__ = [
    "DONE_FILE",
    "ERROR_FILE",
    "KEY_METRICS",
    "MESHES_DIR",
    "MESH_STEM",
    "MESH_SUFFIXES",
    "METRICS_CSV",
    "METRICS_FILE",
    "PLAN_FILE",
    "PREVIEW_FILE",
    "REPORT_ASSETS",
    "REPORT_FILES",
    "REPORT_HTML",
    "STATUSES",
    "STRUCTURES_FILE",
    "SUMMARY_COLUMNS",
    "SUMMARY_CSV",
    "SUMMARY_JSON",
    "CaseFiles",
    "ResultsLayout",
    "Status",
    "mesh_file",
]

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
    "read_as",
    "warnings",
)
"""Columns of ``summary.csv``, in order (``read_as``: how the input was read; ``warnings``:
the case's warning lines, joined by `` | ``)."""


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
        found = first_file(self.directory, MESH_STEM, MESH_SUFFIXES)
        if found is not None:
            return found
        meshes = self.meshes()
        return meshes[0] if meshes else None

    def meshes(self) -> list[Path]:
        """Every structure's mesh that ``structures.json`` lists and that exists, in order."""
        try:
            payload = read_json(self.structures)
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


# -- JSON helpers shared by the readers ----------------------------------------------------
def read_json(path: Path) -> dict[str, Any]:
    payload = json.loads(path.read_text(encoding="utf-8"))
    if not isinstance(payload, dict):
        raise ValueError("not a JSON object")
    return payload


def sub_object(payload: Mapping[str, Any], key: str) -> dict[str, Any]:
    value = payload.get(key)
    return value if isinstance(value, dict) else {}


def str_or_none(value: object) -> str | None:
    return None if value is None else str(value)


def first_file(directory: Path, stem: str, suffixes: Iterable[str]) -> Path | None:
    for suffix in suffixes:
        candidate = directory / f"{stem}{suffix}"
        if candidate.is_file():
            return candidate
    return None
