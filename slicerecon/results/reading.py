"""Reading case folders back (:func:`read_case`, :func:`collect_results`) and the
runner's table (:func:`write_summary`)."""

from __future__ import annotations

import csv
import logging
import os
from collections.abc import Iterable, Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

from ..errors import InputError
from ..io.atomic import atomic_path
from .layout import (
    SUMMARY_COLUMNS,
    CaseFiles,
    ResultsLayout,
    read_json,
    str_or_none,
    sub_object,
)
from .records import CaseResult, FailureRecord, StructureRecord

__all__ = ["collect_results", "read_case", "write_summary"]

logger = logging.getLogger(__name__)


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
        return sub_object(read_json(files.done), "result")
    except (OSError, ValueError):
        return {}


def _colour(value: object) -> tuple[int, int, int] | None:
    if isinstance(value, list | tuple) and len(value) == 3:
        try:
            r, g, b = (int(round(float(c))) for c in value)
        except (TypeError, ValueError):
            return None
        return r, g, b
    return None


def _structures(
    files: CaseFiles, per_structure: Mapping[str, Mapping[str, float]] | None
) -> tuple[tuple[StructureRecord, ...], str | None]:
    """``structures.json``'s structures (absent or unreadable: none) and frame."""
    try:
        payload = read_json(files.structures)
    except (OSError, ValueError):
        return (), None
    records = []
    for item in payload.get("structures") or []:
        if not isinstance(item, dict) or _as_int(item.get("value")) is None:
            continue
        mesh = item.get("mesh")
        path = files.directory / mesh if isinstance(mesh, str) and mesh else None
        record = StructureRecord(
            value=int(item["value"]),
            name=str(item.get("name") or ""),
            colour=_colour(item.get("colour")),
            status=str(item.get("status") or ""),
            planes=_as_int(item.get("planes")),
            volume_mm3=_as_float(item.get("volume_mm3")),
            parts=_as_int(item.get("parts")),
            mesh_path=path if path is not None and path.is_file() else None,
        )
        own = item.get("metrics")
        metrics = _numbers(own) if isinstance(own, dict) else None
        if metrics is None and per_structure:
            metrics = dict(per_structure.get(record.label) or {}) or None
        records.append(replace(record, metrics=metrics))
    frame = payload.get("coordinates")
    return tuple(records), frame if frame in ("RAS", "LPS") else None


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
            payload = read_json(files.error)
        except (OSError, ValueError) as exc:
            record = FailureRecord(case, None, f"unreadable error.json ({exc})")
            return _failed(case, folder, record)
        return _failed(case, folder, FailureRecord.from_json(payload, case=case))
    if not has_plan:
        return _failed(case, folder, FailureRecord(case, None, "no plan.json or error.json"))
    try:
        plan = read_json(files.plan)
    except (OSError, ValueError) as exc:
        return _failed(case, folder, FailureRecord(case, None, f"unreadable plan.json ({exc})"))
    config = sub_object(plan, "config")
    metrics: dict[str, float] | None = None
    per_structure: dict[str, dict[str, float]] | None = None
    if files.metrics.is_file():
        try:
            raw = read_json(files.metrics)
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
        str(k): float(v)
        for k, v in sub_object(plan, "timings_s").items()
        if _as_float(v) is not None
    }
    done = _done_record(files)
    recorded_input = str_or_none(plan.get("input"))
    parts = plan.get("parts")
    if not isinstance(parts, list) and isinstance(plan.get("structures"), list):
        parts = [
            p
            for item in plan["structures"]
            if isinstance(item, dict)
            for p in ((item.get("plan") or {}).get("parts") or [])
        ]
    watertight = done.get("watertight")
    structures, frame = _structures(files, per_structure)
    return CaseResult(
        case=case,
        input=str_or_none(done.get("input")) or recorded_input,
        kind=str(done.get("kind") or ""),
        status="ok",
        parts=len(parts) if isinstance(parts, list) else _as_int(done.get("parts")),
        planes=_as_int(sub_object(plan, "sections").get("n_planes")),
        watertight=watertight if isinstance(watertight, bool) else None,
        metrics=metrics,
        seconds=_as_float(done.get("seconds")),
        method=str_or_none(config.get("method")),
        planner=str_or_none(config.get("planner")),
        input_path=recorded_input,
        ground_truth=str_or_none(plan.get("ground_truth")),
        config=dict(config),
        timings_s=timings,
        directory=folder,
        mesh_path=files.find_mesh(),
        preview_path=files.find_preview(),
        structure_metrics=per_structure,
        structures=structures,
        coordinates=frame,
        warnings=tuple(str(w) for w in done.get("warnings") or () if isinstance(w, str)),
        read_as=str(plan.get("annotation") or ""),
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

    target = Path(path)
    with atomic_path(target) as tmp:
        with open(tmp, "w", newline="", encoding="utf-8") as fh:
            writer = csv.DictWriter(fh, fieldnames=list(SUMMARY_COLUMNS))
            writer.writeheader()
            for result in results:
                writer.writerow(result.to_row())
    return target
