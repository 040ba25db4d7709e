"""Evaluation reports over a results directory: HTML, figures, CSV and JSON.

A *results directory* holds case directories at any depth. A case directory
is one that holds ``plan.json`` (written by :func:`slicerecon.reconstruct.run_case`,
usually with ``metrics.json``, ``mesh.<fmt>`` and ``preview.png``) or
``error.json`` (a failed case: ``{"case": ..., "input": ..., "error": "message"}``,
optionally with ``"type"`` or ``"error_type"`` (the exception's name, shown
before the message), ``"method"`` and ``"planner"`` (or a ``"config"`` object
holding them)). The case name is the directory's
path relative to the results directory, with ``/`` separators.

:func:`collect_results` reads every case; :func:`write_report` writes

* ``metrics.csv``: one row per case (case, method, planner, planes, status,
  every metric, seconds, error);
* ``summary.json``: per method/planner (and per method/planner/planes) the
  number of cases and failures and mean / median / std / min / max of each metric;
* ``report.html``: one self-contained page (figures embedded as base64 PNG
  data URIs) with summary tables, box plots of IoU and Chamfer-L1 per method,
  IoU against the number of planes, per-case 3-D renders (ground truth,
  reconstruction, reconstruction coloured by its distance to the ground-truth
  surface in mm) and the failures;
* ``report_assets/``: the same figures as PNG files, for slides and papers.

:func:`evaluate_dataset` runs :func:`~slicerecon.reconstruct.run_case` on every
NIfTI mask of a directory for several methods, then writes the report.

Rendering uses matplotlib's Agg backend (no display); every output depends on
the inputs only (no timestamps, no unseeded randomness), so re-running on the
same results gives byte-identical files.
"""

from __future__ import annotations

import base64
import csv
import dataclasses
import html
import io
import json
import logging
import math
import os
import shutil
import tempfile
import urllib.parse
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from .errors import InputError, OptionError

if TYPE_CHECKING:
    import trimesh
    from matplotlib.figure import Figure

    from .reconstruct import ReconstructConfig

__all__ = [
    "CaseResult",
    "collect_results",
    "summarize",
    "write_report",
    "dataset_masks",
    "evaluate_dataset",
    "REPORT_FILES",
]

logger = logging.getLogger(__name__)

REPORT_FILES = ("metrics.csv", "summary.json", "report.html", "report_assets")
"""Names :func:`write_report` writes inside the results directory."""

_ASSETS = "report_assets"

_TABLE_METRICS = (
    ("volume_iou", "volume IoU", "{:.3f}"),
    ("surface_iou", "surface IoU", "{:.3f}"),
    ("dice", "Dice", "{:.3f}"),
    ("chamfer_l1_mm", "Chamfer-L1 (mm)", "{:.3f}"),
    ("chamfer_l1", "Chamfer-L1 / diag", "{:.4f}"),
    ("f_score", "F-score", "{:.3f}"),
    ("hd95_mm", "HD95 (mm)", "{:.2f}"),
    ("assd_mm", "ASSD (mm)", "{:.3f}"),
    ("volume_error", "volume error", "{:+.3f}"),
)
"""Metrics shown in the HTML tables: key, column title, number format."""

_MESH_SUFFIXES = (".stl", ".ply", ".obj", ".off")
_RENDER_FACES = 4000
"""Faces drawn per surface in a render (larger meshes are decimated)."""
_RENDER_GRID = 128
"""Marching-cubes samples along the longest side of a ground-truth mask for renders."""
_PNG_METADATA = {"Software": None}
"""Drop matplotlib's version stamp so PNGs only depend on what they show."""


# -- collecting ---------------------------------------------------------------------------


@dataclass(frozen=True)
class CaseResult:
    """One case of a results directory.

    Attributes
    ----------
    case : str
        Path of the case directory relative to the results directory (posix).
    directory : Path
        The case directory.
    method, planner : str or None
        ``plan["config"]["method"]`` / ``["planner"]`` (for a failure: the
        values ``error.json`` gives, or None).
    planes : int or None
        Number of section planes used (``plan["sections"]["n_planes"]``).
    metrics : dict of str to float, or None
        The numbers of ``metrics.json`` (None without ground truth, or for a
        failure); ``n_points`` stays an int.
    error : str or None
        The failure message of ``error.json``, or why ``plan.json`` is unreadable.
    seconds : float or None
        Total run time, s (sum of ``plan["timings_s"]``).
    input, ground_truth : str or None
        The input and ground-truth paths as recorded in ``plan.json``.
    config : dict
        ``plan["config"]`` (empty for a failure).
    mesh_path, preview_path : Path or None
        The reconstructed mesh / preview PNG when present.
    """

    case: str
    directory: Path
    method: str | None
    planner: str | None
    planes: int | None
    metrics: dict[str, float] | None
    error: str | None
    seconds: float | None
    input: str | None
    ground_truth: str | None
    config: dict[str, Any]
    mesh_path: Path | None
    preview_path: Path | None

    @property
    def ok(self) -> bool:
        """True when the case ran to the end (it may still lack metrics)."""
        return self.error is None

    @property
    def group(self) -> str:
        """``"method/planner"`` label of the case's group."""
        return f"{self.method or '?'}/{self.planner or '?'}"


def _read_json(path: Path) -> dict[str, Any]:
    payload = json.loads(path.read_text(encoding="utf-8"))
    if not isinstance(payload, dict):
        raise ValueError("not a JSON object")
    return payload


def _sub(payload: dict[str, Any], key: str) -> dict[str, Any]:
    value = payload.get(key)
    return value if isinstance(value, dict) else {}


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


def _failed_case(name: str, directory: Path, payload: dict[str, Any], message: str) -> CaseResult:
    config = _sub(payload, "config")
    method = payload.get("method", config.get("method"))
    planner = payload.get("planner", config.get("planner"))
    return CaseResult(
        case=name,
        directory=directory,
        method=None if method is None else str(method),
        planner=None if planner is None else str(planner),
        planes=None,
        metrics=None,
        error=message,
        seconds=None,
        input=None if payload.get("input") is None else str(payload["input"]),
        ground_truth=None,
        config={},
        mesh_path=None,
        preview_path=None,
    )


def _read_case(name: str, directory: Path) -> CaseResult:
    plan_path = directory / "plan.json"
    error_path = directory / "error.json"
    use_error = error_path.is_file() and (
        not plan_path.is_file() or error_path.stat().st_mtime > plan_path.stat().st_mtime
    )
    if use_error:
        try:
            payload = _read_json(error_path)
        except (OSError, ValueError) as exc:
            return _failed_case(name, directory, {}, f"unreadable error.json ({exc})")
        message = str(payload.get("error") or "unknown error")
        kind = payload.get("type", payload.get("error_type"))
        if kind and not message.startswith(f"{kind}:"):
            message = f"{kind}: {message}"
        return _failed_case(name, directory, payload, message)
    try:
        plan = _read_json(plan_path)
    except (OSError, ValueError) as exc:
        return _failed_case(name, directory, {}, f"unreadable plan.json ({exc})")
    config = _sub(plan, "config")
    sections = _sub(plan, "sections")
    metrics: dict[str, float] | None = None
    metrics_path = directory / "metrics.json"
    if metrics_path.is_file():
        try:
            raw = _read_json(metrics_path)
        except (OSError, ValueError) as exc:
            return _failed_case(name, directory, plan, f"unreadable metrics.json ({exc})")
        metrics = {
            str(k): v for k, v in raw.items()
            if isinstance(v, int | float) and not isinstance(v, bool)
        }
    timings = _sub(plan, "timings_s")
    seconds = (
        float(sum(float(v) for v in timings.values() if isinstance(v, int | float)))
        if timings else None
    )
    return CaseResult(
        case=name,
        directory=directory,
        method=None if config.get("method") is None else str(config["method"]),
        planner=None if config.get("planner") is None else str(config["planner"]),
        planes=_as_int(sections.get("n_planes")),
        metrics=metrics,
        error=None,
        seconds=seconds,
        input=None if plan.get("input") is None else str(plan["input"]),
        ground_truth=None if plan.get("ground_truth") is None else str(plan["ground_truth"]),
        config=dict(config),
        mesh_path=_first_file(directory, "mesh", _MESH_SUFFIXES),
        preview_path=_first_file(directory, "preview", (".png",)),
    )


def _results_root(results_dir: str | os.PathLike[str]) -> Path:
    root = Path(results_dir)
    if not root.exists():
        raise InputError(f"results directory not found: {root}")
    if not root.is_dir():
        raise InputError(f"{root} is not a directory; pass the directory `slicerecon run/batch` "
                         "wrote its case folders into")
    return root


def collect_results(results_dir: str | os.PathLike[str]) -> list[CaseResult]:
    """Read every case directory below ``results_dir``.

    Parameters
    ----------
    results_dir : path-like
        A directory holding case directories (any depth). A case directory
        holds ``plan.json`` (a finished case) or ``error.json`` (a failed
        one); when both exist the newer file wins. Hidden directories and
        ``report_assets`` are skipped.

    Returns
    -------
    list of CaseResult
        Sorted by case name. Unreadable JSON files give failed cases, not errors.

    Raises
    ------
    InputError
        If ``results_dir`` does not exist or is not a directory.
    """
    root = _results_root(results_dir)
    cases: list[CaseResult] = []
    for current, dirs, files in os.walk(root):
        dirs[:] = sorted(d for d in dirs if not d.startswith(".") and d != _ASSETS)
        if "plan.json" in files or "error.json" in files:
            directory = Path(current)
            name = directory.relative_to(root).as_posix()
            cases.append(_read_case(name, directory))
    cases.sort(key=lambda c: c.case)
    logger.info("collected %d case(s) from %s", len(cases), root)
    return cases


# -- statistics ---------------------------------------------------------------------------


def _metric_names(cases: Sequence[CaseResult]) -> list[str]:
    """Every metric key, in the order of first appearance."""
    names: dict[str, None] = {}
    for case in cases:
        for key in case.metrics or {}:
            names.setdefault(key, None)
    return list(names)


def _finite(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def _stats(values: Sequence[float]) -> dict[str, float | int | None]:
    data = np.asarray([v for v in values if math.isfinite(v)], dtype=np.float64)
    if data.size == 0:
        return {"n": 0, "mean": None, "median": None, "std": None, "min": None, "max": None}
    return {
        "n": int(data.size),
        "mean": _finite(float(data.mean())),
        "median": _finite(float(np.median(data))),
        "std": _finite(float(data.std(ddof=1))) if data.size > 1 else None,
        "min": _finite(float(data.min())),
        "max": _finite(float(data.max())),
    }


def _group_stats(cases: Sequence[CaseResult], names: Sequence[str]) -> dict[str, Any]:
    ok = [c for c in cases if c.ok]
    return {
        "count": len(cases),
        "failures": len(cases) - len(ok),
        "metrics": {
            name: _stats([c.metrics[name] for c in ok if c.metrics and name in c.metrics])
            for name in names
        },
        "seconds": _stats([c.seconds for c in ok if c.seconds is not None]),
    }


def _sort_key(value: str | int | None) -> tuple[int, str | int]:
    return (1, "") if value is None else (0, value)


def summarize(cases: Sequence[CaseResult]) -> dict[str, Any]:
    """Per-group statistics of the metrics (what ``summary.json`` holds).

    Parameters
    ----------
    cases : sequence of CaseResult

    Returns
    -------
    dict
        ``n_cases``, ``n_failures``, ``metrics`` (names), ``groups`` (one
        entry per method/planner: ``method``, ``planner``, ``count`` = cases
        in the group including failures, ``failures``, ``metrics`` =
        ``{name: {n, mean, median, std, min, max}}`` over the finished cases
        that have the metric, ``std`` the sample standard deviation (ddof 1,
        None below two values), ``seconds`` the same statistics of run time),
        ``by_planes`` (the same per method/planner/number of planes) and
        ``failures`` (case, method, planner, input, error). Non-finite values
        are left out of the statistics; absent statistics are None.
    """
    names = _metric_names(cases)
    groups: dict[tuple[str | None, str | None], list[CaseResult]] = {}
    by_planes: dict[tuple[str | None, str | None, int | None], list[CaseResult]] = {}
    for case in cases:
        groups.setdefault((case.method, case.planner), []).append(case)
        if case.ok:
            by_planes.setdefault((case.method, case.planner, case.planes), []).append(case)
    return {
        "n_cases": len(cases),
        "n_failures": sum(not c.ok for c in cases),
        "metrics": names,
        "groups": [
            {"method": m, "planner": p, **_group_stats(groups[(m, p)], names)}
            for m, p in sorted(groups, key=lambda k: (_sort_key(k[0]), _sort_key(k[1])))
        ],
        "by_planes": [
            {"method": m, "planner": p, "planes": n, **_group_stats(by_planes[(m, p, n)], names)}
            for m, p, n in sorted(
                by_planes, key=lambda k: (_sort_key(k[0]), _sort_key(k[1]), _sort_key(k[2]))
            )
        ],
        "failures": [
            {"case": c.case, "method": c.method, "planner": c.planner, "input": c.input,
             "error": c.error}
            for c in cases if not c.ok
        ],
    }


# -- tables -------------------------------------------------------------------------------


def _csv_text(cases: Sequence[CaseResult]) -> str:
    names = _metric_names(cases)
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(["case", "method", "planner", "planes", "status", *names, "seconds", "error"])
    for c in cases:
        metrics = c.metrics or {}
        writer.writerow([
            c.case,
            c.method or "",
            c.planner or "",
            "" if c.planes is None else c.planes,
            "ok" if c.ok else "failed",
            *(repr(metrics[n]) if n in metrics else "" for n in names),
            "" if c.seconds is None else repr(round(c.seconds, 4)),
            c.error or "",
        ])
    return buffer.getvalue()


# -- figures ------------------------------------------------------------------------------


def _pyplot() -> Any:
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def _png_bytes(fig: Figure, *, dpi: int = 80) -> bytes:
    """The figure as a 256-colour PNG (a third of the size of matplotlib's RGBA PNG)."""
    from PIL import Image

    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=dpi, metadata=_PNG_METADATA)
    _pyplot().close(fig)
    buffer.seek(0)
    with Image.open(buffer) as image:
        palette = image.convert("RGB").quantize(colors=256, method=Image.Quantize.FASTOCTREE)
    out = io.BytesIO()
    palette.save(out, format="png", optimize=True)
    return out.getvalue()


def _group_labels(cases: Sequence[CaseResult]) -> dict[str, list[CaseResult]]:
    """Finished cases grouped by method (by method/planner when a method has several)."""
    planners: dict[str | None, set[str | None]] = {}
    for c in cases:
        planners.setdefault(c.method, set()).add(c.planner)
    grouped: dict[str, list[CaseResult]] = {}
    for c in cases:
        if not c.ok:
            continue
        label = c.method or "?"
        if len(planners[c.method]) > 1:
            label = c.group
        grouped.setdefault(label, []).append(c)
    return dict(sorted(grouped.items()))


_BOX_METRICS = (
    ("volume_iou", "volume IoU"),
    ("surface_iou", "surface IoU"),
    ("chamfer_l1_mm", "Chamfer-L1 (mm)"),
)


def _box_plot(cases: Sequence[CaseResult]) -> bytes | None:
    grouped = _group_labels(cases)
    panels = [
        (key, title) for key, title in _BOX_METRICS
        if any(c.metrics and key in c.metrics for g in grouped.values() for c in g)
    ]
    if not panels:
        return None
    plt = _pyplot()
    labels = list(grouped)
    width = max(3.2, 0.55 * len(labels) + 1.4)
    fig, axes = plt.subplots(1, len(panels), figsize=(width * len(panels), 3.6), squeeze=False)
    fig.subplots_adjust(left=0.08, right=0.98, bottom=0.16, top=0.9, wspace=0.3)
    for ax, (key, title) in zip(axes[0], panels, strict=True):
        data = [
            [v for c in grouped[label] if c.metrics and math.isfinite(v := c.metrics.get(
                key, math.nan))]
            for label in labels
        ]
        ax.boxplot(data, tick_labels=labels, showmeans=True)
        for i, values in enumerate(data, start=1):
            ax.plot(np.full(len(values), float(i)), values, "o", ms=3, alpha=0.5, color="tab:blue")
        ax.set_title(title, fontsize=10)
        ax.tick_params(axis="x", labelrotation=30, labelsize=8)
        ax.tick_params(axis="y", labelsize=8)
        ax.grid(axis="y", alpha=0.3)
    return _png_bytes(fig)


def _planes_plot(cases: Sequence[CaseResult]) -> bytes | None:
    grouped = _group_labels(cases)
    plane_counts = {c.planes for g in grouped.values() for c in g
                    if c.planes is not None and c.metrics and "volume_iou" in c.metrics}
    if len(plane_counts) < 2:
        return None
    plt = _pyplot()
    keys = [(k, t) for k, t in _BOX_METRICS if k.endswith("iou")]
    fig, axes = plt.subplots(1, len(keys), figsize=(4.2 * len(keys), 3.6), squeeze=False)
    fig.subplots_adjust(left=0.1, right=0.98, bottom=0.14, top=0.9, wspace=0.3)
    for ax, (key, title) in zip(axes[0], keys, strict=True):
        for i, (label, members) in enumerate(grouped.items()):
            pts = sorted(
                (c.planes, c.metrics[key]) for c in members
                if c.planes is not None and c.metrics
                and math.isfinite(c.metrics.get(key, math.nan))
            )
            if not pts:
                continue
            colour = f"C{i % 10}"
            xs, ys = np.array(pts, dtype=np.float64).T
            ax.plot(xs, ys, "o", ms=3, alpha=0.35, color=colour)
            levels = np.unique(xs)
            means = [float(ys[xs == x].mean()) for x in levels]
            ax.plot(levels, means, "-o", ms=4, color=colour, label=label)
        ax.set_xlabel("number of planes", fontsize=9)
        ax.set_ylabel(title, fontsize=9)
        ax.set_title(f"{title} against number of planes", fontsize=9)
        ax.grid(alpha=0.3)
        ax.tick_params(labelsize=8)
        ax.legend(fontsize=8)
    return _png_bytes(fig)


# -- per-case renders ---------------------------------------------------------------------


def _decimate(
    vertices: NDArray[np.float64], faces: NDArray[np.int64], max_faces: int
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Vertex-clustering decimation to at most ``max_faces`` faces (for display only).

    Vertices are snapped to a uniform grid (cell size grown until few enough
    faces remain), each cell's vertices replaced by their mean, and faces that
    collapse or repeat are dropped. Deterministic; the result is not
    guaranteed to stay watertight.
    """
    if len(faces) <= max_faces:
        return vertices, faces
    lo = vertices.min(axis=0)
    area = float(np.linalg.norm(np.cross(
        vertices[faces[:, 1]] - vertices[faces[:, 0]],
        vertices[faces[:, 2]] - vertices[faces[:, 0]],
    ), axis=1).sum() / 2.0)
    cell = math.sqrt(max(area, 1e-12) / max_faces)
    new_v, new_f = vertices, faces
    for _ in range(20):
        keys = np.floor((vertices - lo) / cell).astype(np.int64)
        _, inverse = np.unique(keys, axis=0, return_inverse=True)
        inverse = inverse.reshape(-1)
        counts = np.bincount(inverse)
        sums = np.zeros((counts.size, 3))
        np.add.at(sums, inverse, vertices)
        new_v = sums / counts[:, None]
        f = inverse[faces]
        f = f[(f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])]
        _, first = np.unique(np.sort(f, axis=1), axis=0, return_index=True)
        new_f = f[np.sort(first)]
        if len(new_f) <= max_faces:
            break
        cell *= 1.3
    return new_v, new_f


def _resolve(path_text: str, roots: Sequence[Path]) -> Path | None:
    path = Path(path_text)
    if path.is_absolute():
        return path if path.exists() else None
    for candidate in (path, *(root / path for root in roots)):
        if candidate.exists():
            return candidate
    return None


class _TruthCache:
    """The last ground-truth surface read (cases of one input are adjacent in sorted order)."""

    def __init__(self) -> None:
        self.key: tuple[str, Any, Any] | None = None
        self.mesh: trimesh.Trimesh | None = None

    def get(self, case: CaseResult, root: Path) -> tuple[trimesh.Trimesh | None, str]:
        """The case's ground-truth surface (world mm) or None, and a note on where it came from."""
        if case.metrics is None:
            return None, "no ground truth (sparse input)"
        source = case.ground_truth or case.input
        if source is None:
            return None, "plan.json names no input"
        path = _resolve(source, (root, case.directory))
        if path is None:
            return None, f"ground truth {source} not found"
        key = (str(path.resolve()), case.config.get("label"), case.config.get("roi"))
        if key != self.key:
            self.key, self.mesh = key, None
            self.mesh = _truth_surface(path, case.config)
        return self.mesh, f"ground truth: {Path(source).name}"


def _truth_surface(path: Path, config: dict[str, Any]) -> trimesh.Trimesh | None:
    from .io import detect_kind, load_input
    from .io.mesh import read_mesh
    from .sections import Volume
    from .surface.marching import volume_to_mesh

    if detect_kind(path).kind == "mesh":
        return read_mesh(path)
    data = load_input(
        path,
        label=config.get("label"),
        roi=config.get("roi"),
        allow_irregular=bool(config.get("allow_irregular", False)),
    )
    if not isinstance(data, Volume):
        return None
    cropped = data.crop(pad=1)
    step = max(1, math.ceil(max(cropped.shape) / _RENDER_GRID))
    return volume_to_mesh(cropped, step_size=step)


def _face_shading(vertices: NDArray[np.float64], faces: NDArray[np.int64]) -> NDArray[np.float64]:
    """Two-sided Lambert shading in [0.35, 1] of each face, light from the upper front."""
    tri = vertices[faces]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = normals / np.where(length > 0, length, 1.0)
    light = np.array([0.4, -0.6, 0.7])
    light /= np.linalg.norm(light)
    return 0.35 + 0.65 * np.abs(normals @ light)


def _draw_surface(
    ax: Any, vertices: NDArray[np.float64], faces: NDArray[np.int64], colours: NDArray[np.float64]
) -> None:
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    collection = Poly3DCollection(vertices[faces], facecolors=colours, edgecolors="none",
                                  linewidths=0.0)
    ax.add_collection3d(collection)


def _frame(ax: Any, lo: NDArray[np.float64], hi: NDArray[np.float64], title: str) -> None:
    centre = (lo + hi) / 2.0
    half = float(np.max(hi - lo)) / 2.0 or 1.0
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(centre[2] - half, centre[2] + half)
    ax.set_box_aspect((1.0, 1.0, 1.0), zoom=1.3)
    ax.view_init(elev=22, azim=-60)
    ax.set_axis_off()
    ax.set_title(title, fontsize=9)


def _render_case(case: CaseResult, truth: trimesh.Trimesh | None) -> tuple[bytes, dict[str, float]]:
    """3-D render: ground truth | reconstruction | reconstruction coloured by error (mm).

    Returns the PNG bytes and distance statistics of the error panel (empty
    without ground truth).
    """
    import trimesh as tm
    from matplotlib import colormaps
    from matplotlib.colors import Normalize

    from .io.mesh import read_mesh

    assert case.mesh_path is not None
    recon = read_mesh(case.mesh_path)
    rv, rf = _decimate(np.asarray(recon.vertices, np.float64),
                       np.asarray(recon.faces, np.int64), _RENDER_FACES)
    lo, hi = rv.min(axis=0), rv.max(axis=0)
    panels = 3 if truth is not None else 1
    plt = _pyplot()
    fig = plt.figure(figsize=(3.3 * panels + (0.5 if truth is not None else 0.0), 3.4))
    stats: dict[str, float] = {}
    recon_shade = _face_shading(rv, rf)[:, None]
    recon_colour = np.clip(recon_shade * np.array([[0.95, 0.55, 0.25]]), 0, 1)
    if truth is None:
        ax = fig.add_subplot(1, 1, 1, projection="3d")
        _draw_surface(ax, rv, rf, recon_colour)
        _frame(ax, lo, hi, f"reconstruction ({len(recon.faces)} faces)")
        fig.subplots_adjust(left=0.0, right=1.0, bottom=0.0, top=0.9)
        return _png_bytes(fig), stats
    gv, gf = _decimate(np.asarray(truth.vertices, np.float64),
                       np.asarray(truth.faces, np.int64), _RENDER_FACES)
    lo, hi = np.minimum(lo, gv.min(axis=0)), np.maximum(hi, gv.max(axis=0))
    # Distance of each drawn reconstruction face centre to the full-resolution truth surface.
    _, dist, _ = tm.proximity.closest_point(truth, rv[rf].mean(axis=1))
    dist = np.asarray(dist, dtype=np.float64)
    stats = {"mean_mm": float(dist.mean()), "p95_mm": float(np.percentile(dist, 95)),
             "max_mm": float(dist.max())}
    vmax = max(float(np.percentile(dist, 99)), 1e-3)
    norm = Normalize(vmin=0.0, vmax=vmax)
    cmap = colormaps["viridis"]
    error_colour = np.clip(cmap(norm(dist))[:, :3] * (0.55 + 0.45 * recon_shade), 0, 1)
    truth_colour = np.clip(_face_shading(gv, gf)[:, None] * np.array([[0.55, 0.65, 0.85]]), 0, 1)
    width = 3.3 * 3 + 0.5
    axes = [fig.add_axes((i * 3.3 / width, 0.0, 3.3 / width, 0.9), projection="3d")
            for i in range(3)]
    _draw_surface(axes[0], gv, gf, truth_colour)
    _frame(axes[0], lo, hi, "ground truth")
    _draw_surface(axes[1], rv, rf, recon_colour)
    _frame(axes[1], lo, hi, "reconstruction")
    _draw_surface(axes[2], rv, rf, error_colour)
    _frame(axes[2], lo, hi, f"distance to truth (mean {stats['mean_mm']:.2f} mm)")
    cax = fig.add_axes((9.9 / width, 0.12, 0.12 / width, 0.66))
    bar = fig.colorbar(plt.cm.ScalarMappable(norm=norm, cmap=cmap), cax=cax)
    bar.ax.set_title("mm", fontsize=8)
    bar.ax.tick_params(labelsize=7)
    return _png_bytes(fig), stats


# -- HTML ---------------------------------------------------------------------------------

_CSS = """
body{font-family:-apple-system,Segoe UI,Helvetica,Arial,sans-serif;margin:1.5em;color:#222}
h1{font-size:1.5em}h2{font-size:1.25em;margin-top:1.6em;border-bottom:1px solid #ccc}
h3{font-size:1.05em}
table{border-collapse:collapse;font-size:.85em;margin:.5em 0}
th,td{border:1px solid #ccc;padding:.2em .5em;text-align:right}
th{background:#f2f2f2}td.t,th.t{text-align:left}
tr.failed td{background:#fde8e8}
figure{display:inline-block;margin:.4em;vertical-align:top}
figcaption{font-size:.8em;color:#444;max-width:800px}
.note{color:#555;font-size:.85em}
"""


def _e(value: object) -> str:
    return html.escape(str(value), quote=True)


def _img(data: bytes, alt: str) -> str:
    encoded = base64.b64encode(data).decode("ascii")
    return f'<img src="data:image/png;base64,{encoded}" alt="{_e(alt)}">'


def _fmt(value: float | None, spec: str) -> str:
    if value is None or not math.isfinite(value):
        return "–"
    return spec.format(value)


def _summary_table(summary: dict[str, Any], names: Sequence[str]) -> str:
    shown = [(k, t, f) for k, t, f in _TABLE_METRICS if k in names]
    head = "".join(f"<th>{_e(t)}<br><small>mean ± std (median)</small></th>" for _, t, _ in shown)
    rows = []
    for g in summary["groups"]:
        cells = []
        for key, _, spec in shown:
            s = g["metrics"][key]
            std = "" if s["std"] is None else f" ± {_fmt(s['std'], spec.replace('+', ''))}"
            cells.append(f"<td>{_fmt(s['mean'], spec)}{std} ({_fmt(s['median'], spec)})</td>")
        sec = g["seconds"]
        rows.append(
            f"<tr><td class=t>{_e(g['method'] or '?')}</td><td class=t>{_e(g['planner'] or '?')}"
            f"</td><td>{g['count']}</td><td>{g['failures']}</td>{''.join(cells)}"
            f"<td>{_fmt(sec['mean'], '{:.2f}')}</td></tr>"
        )
    return (
        "<table><tr><th class=t>method</th><th class=t>planner</th><th>cases</th>"
        f"<th>failures</th>{head}<th>seconds<br><small>mean</small></th></tr>"
        + "".join(rows) + "</table>"
    )


def _link(target: Path | None, root: Path, text: str) -> str:
    if target is None:
        return ""
    href = urllib.parse.quote(target.relative_to(root).as_posix())
    return f'<a href="{_e(href)}">{_e(text)}</a>'


def _case_tables(cases: Sequence[CaseResult], names: Sequence[str], root: Path) -> str:
    shown = [(k, t, f) for k, t, f in _TABLE_METRICS if k in names]
    head = "".join(f"<th>{_e(t)}</th>" for _, t, _ in shown)
    methods = sorted({c.method for c in cases}, key=_sort_key)
    parts = []
    for method in methods:
        rows = []
        for c in (c for c in cases if c.method == method):
            metrics = c.metrics or {}
            cells = "".join(f"<td>{_fmt(metrics.get(k), f)}</td>" for k, _, f in shown)
            status = "" if c.ok else " class=failed"
            links = " ".join(x for x in (
                _link(c.mesh_path, root, "mesh"),
                _link(c.preview_path, root, "preview"),
                _link(c.directory / "plan.json" if c.ok else c.directory / "error.json", root,
                      "plan" if c.ok else "error"),
            ) if x)
            rows.append(
                f"<tr{status}><td class=t>{_e(c.case)}</td><td class=t>{_e(c.planner or '?')}</td>"
                f"<td>{'' if c.planes is None else c.planes}</td>{cells}"
                f"<td>{_fmt(c.seconds, '{:.2f}')}</td><td class=t>{links}</td></tr>"
            )
        parts.append(
            f"<h3>method: {_e(method or 'unknown')}</h3><table><tr><th class=t>case</th>"
            f"<th class=t>planner</th><th>planes</th>{head}<th>seconds</th>"
            f"<th class=t>files</th></tr>{''.join(rows)}</table>"
        )
    return "".join(parts)


def _failures_section(cases: Sequence[CaseResult]) -> str:
    failed = [c for c in cases if not c.ok]
    if not failed:
        return "<h2 id=failures>Failures</h2><p>No failures.</p>"
    rows = "".join(
        f"<tr class=failed><td class=t>{_e(c.case)}</td><td class=t>{_e(c.method or '?')}</td>"
        f"<td class=t>{_e(c.input or '')}</td><td class=t>{_e(c.error)}</td></tr>"
        for c in failed
    )
    return (
        f"<h2 id=failures>Failures ({len(failed)})</h2><table><tr><th class=t>case</th>"
        f"<th class=t>method</th><th class=t>input</th><th class=t>error</th></tr>{rows}</table>"
    )


_DEFINITIONS = f"""
<h2 id=definitions>Metric definitions</h2>
<p class=note>All distances in world millimetres; exact definitions in the slicerecon
documentation (<code>docs/metrics.md</code>). <b>Volume IoU</b> and <b>Dice</b>: overlap of the
occupancies on the evaluation grid. <b>Surface IoU</b>: IoU of the two surface shells (voxels
within one voxel of the boundary). <b>Chamfer-L1</b>: mean of the two directed mean distances
between surface samples (mm, and divided by the ground-truth bounding-box diagonal).
<b>F-score</b>: harmonic mean of precision and recall of surface samples within τ.
<b>HD95</b>: larger of the two directed 95th-percentile distances. <b>ASSD</b>: mean of all
surface distances. <b>Volume error</b>: (V<sub>pred</sub> − V<sub>gt</sub>) / V<sub>gt</sub>.
Summary statistics: mean ± sample standard deviation (median) over the finished cases.
Renders: meshes with more than {_RENDER_FACES} faces are decimated for display; the error
colours are the distance (mm) of each drawn face centre to the full ground-truth surface, colour
scale clipped at the 99th percentile.</p>
"""


def _html(
    title: str,
    cases: Sequence[CaseResult],
    summary: dict[str, Any],
    figures: dict[str, bytes],
    renders: list[tuple[CaseResult, bytes | None, str]],
    root: Path,
    render_note: str,
) -> str:
    from . import __version__

    names = summary["metrics"]
    n_ok = summary["n_cases"] - summary["n_failures"]
    methods = sorted({c.method or "?" for c in cases})
    out = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        f"<title>{_e(title)}</title><style>{_CSS}</style></head><body>",
        f"<h1>{_e(title)}</h1>",
        f"<p>{summary['n_cases']} case(s): {n_ok} finished, {summary['n_failures']} failed "
        f"(<a href=#failures>failures</a>). Methods: {_e(', '.join(methods))}. "
        f"Tables: <a href=metrics.csv>metrics.csv</a>, <a href=summary.json>summary.json</a>. "
        f"<span class=note>slicerecon {_e(__version__)}</span></p>",
        "<h2>Summary per method and planner</h2>",
        _summary_table(summary, names) if names else "<p>No case has metrics "
        "(no ground truth was available).</p>",
    ]
    if figures:
        out.append("<h2>Figures</h2>")
        captions = {
            "boxplots": "Volume IoU, surface IoU and Chamfer-L1 per method (box: quartiles, "
                        "line: median, triangle: mean, dots: cases).",
            "iou_vs_planes": "IoU against the number of section planes (line: mean per count).",
        }
        for name, data in figures.items():
            out.append(f"<figure>{_img(data, name)}<figcaption>{_e(captions[name])}"
                       "</figcaption></figure>")
    out.append("<h2>Cases</h2>")
    out.append(_case_tables(cases, names, root))
    out.append("<h2>Renders</h2>")
    if render_note:
        out.append(f"<p class=note>{_e(render_note)}</p>")
    for case, png, note in renders:
        metrics = case.metrics or {}
        caption = f"{case.case} — {case.method}/{case.planner}, {case.planes} planes"
        if "volume_iou" in metrics:
            caption += f", volume IoU {metrics['volume_iou']:.3f}"
        if "chamfer_l1_mm" in metrics:
            caption += f", Chamfer-L1 {metrics['chamfer_l1_mm']:.3f} mm"
        caption += f"; {note}"
        body = _img(png, f"render of {case.case}") if png is not None else ""
        out.append(f"<figure>{body}<figcaption>{_e(caption)}</figcaption></figure>")
    out.append(_failures_section(cases))
    out.append(_DEFINITIONS)
    out.append("</body></html>")
    return "\n".join(out) + "\n"


# -- writing ------------------------------------------------------------------------------


def _slug(case: str) -> str:
    text = "".join(ch if ch.isalnum() or ch in "-_." else "_" for ch in case.replace("/", "__"))
    return text or "case"


def _write_assets(root: Path, files: dict[str, bytes]) -> None:
    """Replace ``root/report_assets`` by a folder holding ``files`` (relative name → bytes)."""
    target = root / _ASSETS
    staging = Path(tempfile.mkdtemp(prefix=f".{_ASSETS}.", dir=root))
    umask = os.umask(0)
    os.umask(umask)
    staging.chmod(0o777 & ~umask)  # mkdtemp makes it private; give it a normal folder's mode
    try:
        for name, data in files.items():
            path = staging / name
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(data)
        if target.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{_ASSETS}.old.", dir=root))
            os.replace(target, old / _ASSETS)
            shutil.rmtree(old, ignore_errors=True)
        os.replace(staging, target)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise


def _write_text(path: Path, text: str) -> None:
    from .io.atomic import atomic_path

    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def write_report(
    results_dir: str | os.PathLike[str],
    *,
    title: str | None = None,
    renders: bool = True,
    max_renders: int | None = 100,
) -> Path:
    """Write ``metrics.csv``, ``summary.json``, ``report.html`` and ``report_assets/``.

    Parameters
    ----------
    results_dir : path-like
        Directory of case directories (see :func:`collect_results`); the
        report files are written into it, each atomically (``report_assets``
        is replaced as a whole).
    title : str, optional
        Page title; default ``"slicerecon report: <directory name>"``.
    renders : bool
        Draw the per-case 3-D renders (ground truth, reconstruction,
        distance-coloured reconstruction); about a second per case.
    max_renders : int or None
        Render at most this many finished cases (the first ones by name);
        None renders all.

    Returns
    -------
    Path
        The ``report.html`` file.

    Raises
    ------
    InputError
        If the directory does not exist or holds no case directory.
    OptionError
        If ``max_renders`` is negative.

    Notes
    -----
    A case whose render fails (missing or unreadable mesh or ground truth) is
    still listed; the reason is shown in place of the render and logged.
    """
    if max_renders is not None and max_renders < 0:
        raise OptionError(f"max_renders must be >= 0 or None (got {max_renders})")
    root = _results_root(results_dir)
    cases = collect_results(root)
    if not cases:
        raise InputError(
            f"{root} holds no cases: expected case directories with plan.json (written by "
            "`slicerecon run`, `batch` or `evaluate-dataset`) or error.json"
        )
    if title is None:
        title = f"slicerecon report: {root.resolve().name}"
    summary = summarize(cases)
    assets: dict[str, bytes] = {}
    figures: dict[str, bytes] = {}
    for name, make in (("boxplots", _box_plot), ("iou_vs_planes", _planes_plot)):
        data = make(cases)
        if data is not None:
            figures[name] = data
            assets[f"{name}.png"] = data

    rendered: list[tuple[CaseResult, bytes | None, str]] = []
    candidates = [c for c in cases if c.ok and c.mesh_path is not None]
    note = "" if renders else "Renders were not requested (--no-renders)."
    if renders:
        chosen = candidates if max_renders is None else candidates[:max_renders]
        if len(chosen) < len(candidates):
            note = f"Renders of the first {len(chosen)} of {len(candidates)} cases by name."
        truths = _TruthCache()
        for case in chosen:
            try:
                truth, where = truths.get(case, root)
                png, stats = _render_case(case, truth)
            except Exception as exc:  # one bad case must not stop the report
                logger.warning("cannot render %s: %s", case.case, exc)
                rendered.append((case, None, f"render failed: {type(exc).__name__}: {exc}"))
                continue
            if stats:
                where += (f"; face-centre distance to truth mean {stats['mean_mm']:.2f} mm, "
                          f"95th percentile {stats['p95_mm']:.2f} mm, max {stats['max_mm']:.2f} mm")
            rendered.append((case, png, where))
            asset, k = f"cases/{_slug(case.case)}.png", 2
            while asset in assets:
                asset, k = f"cases/{_slug(case.case)}-{k}.png", k + 1
            assets[asset] = png
            logger.info("rendered %s", case.case)

    _write_assets(root, assets)
    _write_text(root / "metrics.csv", _csv_text(cases))
    payload = {"title": title, **summary}
    _write_text(root / "summary.json", json.dumps(payload, indent=2, allow_nan=False) + "\n")
    report = root / "report.html"
    _write_text(report, _html(title, cases, summary, figures, rendered, root, note))
    logger.info("report of %d case(s) written to %s", len(cases), report)
    return report


# -- dataset evaluation -------------------------------------------------------------------


def dataset_masks(dataset_dir: str | os.PathLike[str]) -> list[tuple[str, Path]]:
    """The NIfTI masks of a dataset directory, with their case names.

    Parameters
    ----------
    dataset_dir : path-like
        Directory searched recursively for ``*.nii`` and ``*.nii.gz`` (hidden
        files and folders skipped; any ``manifest.json`` is ignored).

    Returns
    -------
    list of (str, Path)
        ``(case, path)`` sorted by case, the case being the path relative to
        ``dataset_dir`` without the NIfTI suffix (posix).

    Raises
    ------
    InputError
        If the directory does not exist or holds no NIfTI file.
    """
    root = Path(dataset_dir)
    if not root.is_dir():
        raise InputError(f"dataset directory not found: {root}")
    found: list[tuple[str, Path]] = []
    for current, dirs, files in os.walk(root):
        dirs[:] = sorted(d for d in dirs if not d.startswith("."))
        for name in sorted(files):
            lower = name.lower()
            if name.startswith(".") or not lower.endswith((".nii", ".nii.gz")):
                continue
            path = Path(current) / name
            stem = name[: -len(".nii.gz")] if lower.endswith(".nii.gz") else name[: -len(".nii")]
            found.append(((path.parent.relative_to(root) / stem).as_posix(), path))
    if not found:
        raise InputError(f"{root} holds no NIfTI masks (*.nii, *.nii.gz)")
    found.sort(key=lambda item: item[0])
    names = [case for case, _ in found]
    if len(set(names)) != len(names):
        dup = sorted({n for n in names if names.count(n) > 1})
        raise InputError(f"{root} holds both .nii and .nii.gz files for case(s) {', '.join(dup)}; "
                         "keep one of each")
    return found


def _check_methods(methods: Sequence[str], config: ReconstructConfig) -> list[str]:
    cleaned = [m.strip() for m in methods if m.strip()]
    if not cleaned:
        raise OptionError("give at least one method (e.g. --method loft,sdf)")
    if len(set(cleaned)) != len(cleaned):
        raise OptionError(f"methods are repeated: {', '.join(cleaned)}")
    for method in cleaned:
        dataclasses.replace(config, method=method)  # validates the name
    return cleaned


def evaluate_dataset(
    dataset_dir: str | os.PathLike[str],
    outdir: str | os.PathLike[str],
    *,
    methods: Sequence[str] = ("hybrid",),
    config: ReconstructConfig | None = None,
    title: str | None = None,
    renders: bool = True,
    resume: bool = True,
    progress: Callable[[str], None] | None = None,
) -> Path:
    """Reconstruct every mask of a dataset with each method, then write the report.

    Runs sequentially: for each ``(case, path)`` of :func:`dataset_masks` and
    each method, :func:`~slicerecon.reconstruct.run_case` writes into
    ``outdir/<case>/<method>/``. A failing case writes ``error.json`` there
    (case, input, method, planner, error) and the others go on.

    Parameters
    ----------
    dataset_dir : path-like
        Directory of NIfTI masks (searched recursively).
    outdir : path-like
        Results directory.
    methods : sequence of str
        Surface methods (values of ``ReconstructConfig.method``).
    config : ReconstructConfig, optional
        Every other option; its ``method`` is replaced by each of ``methods``.
    title : str, optional
        Report title.
    renders : bool
        Draw per-case renders in the report.
    resume : bool
        Skip a case/method whose ``plan.json`` was written with the same config.
    progress : callable, optional
        Called with a short status line before each run.

    Returns
    -------
    Path
        The ``report.html`` file.

    Raises
    ------
    InputError
        If the dataset holds no NIfTI mask.
    OptionError
        If a method is unknown or repeated.
    """
    from .reconstruct import ReconstructConfig, run_case

    base = config if config is not None else ReconstructConfig()
    chosen = _check_methods(methods, base)
    masks = dataset_masks(dataset_dir)
    out = Path(outdir)
    out_resolved = out.resolve()
    masks = [(c, p) for c, p in masks if out_resolved not in p.resolve().parents]
    if not masks:
        raise InputError(f"{dataset_dir} holds no NIfTI masks outside the output directory")
    total = len(masks) * len(chosen)
    done = 0
    for case, path in masks:
        for method in chosen:
            done += 1
            run_config = dataclasses.replace(base, method=method)
            case_dir = out / case / method
            if resume and _finished(case_dir, run_config):
                logger.info("skip %s/%s: already done with the same options", case, method)
                continue
            if progress is not None:
                progress(f"[{done}/{total}] {case} ({method})")
            try:
                run_case(path, case_dir, run_config)
            except Exception as exc:  # a failed case is recorded and never stops the others
                logger.warning("%s (%s) failed: %s", case, method, exc)
                for stale in ("plan.json", "metrics.json"):
                    (case_dir / stale).unlink(missing_ok=True)
                record = {"case": f"{case}/{method}", "input": str(path), "method": method,
                          "planner": run_config.planner, "error": f"{type(exc).__name__}: {exc}"}
                _write_text(case_dir / "error.json", json.dumps(record, indent=2) + "\n")
            else:
                (case_dir / "error.json").unlink(missing_ok=True)
    return write_report(out, title=title, renders=renders)


def _finished(case_dir: Path, config: ReconstructConfig) -> bool:
    plan_path = case_dir / "plan.json"
    if not plan_path.is_file() or (case_dir / "error.json").is_file():
        return False
    try:
        recorded = _read_json(plan_path).get("config")
    except (OSError, ValueError):
        return False
    return bool(recorded == json.loads(json.dumps(dataclasses.asdict(config))))
