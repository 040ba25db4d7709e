"""What a case's records hold: :class:`CaseResult` (one case) and :class:`FailureRecord`
(``error.json``)."""

from __future__ import annotations

import json
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .. import __version__
from ..io.atomic import atomic_path
from ..labels import Structure
from .layout import ERROR_FILE, KEY_METRICS, STATUSES, Status, str_or_none, sub_object

__all__ = ["CaseResult", "FailureRecord", "StructureRecord", "error_text"]


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
        return error_text(self.error, self.error_type)

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
        config = sub_object(payload, "config")
        method = payload.get("method", config.get("method"))
        planner = payload.get("planner", config.get("planner"))
        kind = payload.get("type", payload.get("error_type"))
        return cls(
            case=str(payload.get("case") or case),
            input=str_or_none(payload.get("input")),
            error=str(payload.get("error") or "unknown error"),
            error_type="" if not kind else str(kind),
            kind=str(payload.get("kind") or ""),
            method=str_or_none(method),
            planner=str_or_none(planner),
            traceback=str(payload.get("traceback") or ""),
            slicerecon_version=str(payload.get("slicerecon_version") or ""),
        )

    def write(self, directory: str | os.PathLike[str]) -> Path:
        """Write ``directory/error.json`` atomically; return its path."""

        target = Path(directory) / ERROR_FILE
        with atomic_path(target) as tmp:
            tmp.write_text(json.dumps(self.to_json(), indent=2) + "\n", encoding="utf-8")
        return target


@dataclass(frozen=True)
class StructureRecord:
    """One structure of a finished case, as ``structures.json`` records it.

    Attributes
    ----------
    value : int
        Its label value (SegmentNumber, ROINumber).
    name : str
        Its name ("" when the input has none).
    colour : tuple of 3 int or None
        Its own display colour (RGB 0-255), when the input gave one.
    status : str
        ``reconstructed``, or why it was not (``not on any kept plane``, ...).
    planes : int or None
        Planes that annotate it.
    volume_mm3 : float or None
        Volume of its reconstruction.
    parts : int or None
        Cuboid parts of its plan.
    mesh_path : Path or None
        Its mesh, when written and present.
    metrics : mapping of str to float, or None
        Its metrics against its own ground truth (when known).
    """

    value: int
    name: str = ""
    colour: tuple[int, int, int] | None = None
    status: str = ""
    planes: int | None = None
    volume_mm3: float | None = None
    parts: int | None = None
    mesh_path: Path | None = None
    metrics: Mapping[str, float] | None = None

    @property
    def label(self) -> str:
        """``"<value>_<name>"`` (or the value alone): its key in ``metrics.json`` and
        the stem of its mesh file."""
        return self.structure.label

    @property
    def structure(self) -> Structure:
        """The :class:`~slicerecon.labels.Structure` (value, name, colour)."""
        return Structure(self.value, self.name, self.colour)


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
        The reconstructed mesh / preview PNG when present (for several
        structures, ``mesh_path`` is the first structure's mesh).
    structures : tuple of StructureRecord
        Every structure of ``structures.json`` (names, colours, statuses,
        meshes, per-structure metrics); empty when the folder has none.
    coordinates : str or None
        The world frame of the meshes (``RAS`` or ``LPS``), when recorded.
    warnings : tuple of str
        The warnings the case gave when it ran (one line each).
    read_as : str
        How the input was read (``plan.json``'s ``annotation``: dense, or which
        planes of which axes), the line ``run`` prints; empty when not known.
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
    structures: tuple[StructureRecord, ...] = ()
    coordinates: str | None = None
    warnings: tuple[str, ...] = ()
    read_as: str = ""

    def __post_init__(self) -> None:
        if self.status not in STATUSES:
            raise ValueError(f"status must be one of {', '.join(STATUSES)} (got {self.status!r})")

    @property
    def ok(self) -> bool:
        """True when the case is finished (``ok`` or ``skipped``; it may lack metrics)."""
        return self.status != "failed"

    @property
    def several(self) -> bool:
        """True for a case of several structures."""
        return len(self.structures) > 1

    @property
    def group(self) -> str:
        """``"method/planner"`` label of the case's group."""
        return f"{self.method or '?'}/{self.planner or '?'}"

    @property
    def error_text(self) -> str:
        """``"<type>: <message>"`` of a failed case (empty for a finished one)."""
        return error_text(self.error, self.error_type)

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
            "read_as": self.read_as,
            "warnings": " | ".join(w.replace("\n", " ").strip() for w in self.warnings),
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
            "warnings": list(self.warnings),
        }


def error_text(message: str, kind: str) -> str:
    if kind and not message.startswith(f"{kind}:"):
        return f"{kind}: {message}"
    return message
