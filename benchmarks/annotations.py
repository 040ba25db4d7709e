"""Annotations as clinicians draw them: sparse label maps, every 2nd slice, several views.

Every case of ``benchmarks/real_split.toml`` (the real shapes of
``benchmarks/real_anatomy.py``, normalised the same way) is turned into the
annotation a clinician would hand over, a **sparse label map** holding only
some planes of the true mask, in one of these layouts:

``axial12``      12 axial planes, evenly spaced from the first to the last occupied one
``every2``       every 2nd axial slice
``axial12+2+2``  the 12 axial planes plus 2 sagittal and 2 coronal ones (at 1/3 and 2/3
                 of the structure's extent along x and y)
``axial6+2+2``   6 axial planes plus the same 2 sagittal and 2 coronal ones
``inner8+2+2``   8 axial planes over the middle 60 % of the structure's axial extent (its
                 ends left undrawn on that view) plus the same 2 sagittal and 2 coronal
                 ones, which reach the ends

or, as contours (the polygons an RTSTRUCT holds, traced on each plane of the
true mask, in world mm; written as a version 2 contour file on the mask's grid):

``rt-axial8``          8 axial planes
``rt-axial8+3+3``      the 8 axial planes plus 3 sagittal and 3 coronal ones (1/4, 1/2, 3/4)
``rt-radial8``         8 planes through the structure's long axis, 22.5° apart
``rt-axial8+tilted3``  the 8 axial planes plus 3 planes through the centre tilted 30°, 45°, 60°

and reconstructed from that sparse label map alone, as a user would
(``slicerecon.case.reconstruct_structures`` on the array and its affine: the
reading is detected, not told), beside the two baselines:

``plain SDF``    signed-distance interpolation, linear between the layout's
                 **axial** planes (``benchmarks/plain_sdf.py``, no slicerecon code)
``ITK-MCI``      ITK's morphological contour interpolation (3D Slicer's "Fill between
                 slices") on the same sparse label map, all axes (its default)

and, for the layouts with extra views, ``ours, axial only``: slicerecon on the
layout's axial planes alone. Every reconstruction is scored by volume IoU of
its label map against the true mask on the input's grid, computed here with
numpy (not :mod:`slicerecon.metrics`)::

    python benchmarks/annotations.py --half both --out docs/data/annotations.csv

prints the markdown tables (per layout: means, wins / ties / losses against
each baseline, per case) and writes every number to ``--out``. ``--half dev``
is the half to choose on. ``--speed`` times the 340 × 285 × 120 organ of
``benchmarks/bench_clinical.py`` annotated 12 + 2 + 2, ours against ITK-MCI,
side by side in this process. ``--ceiling`` bounds what the 2 + 2 extra views
can add locally: our 12-axial-plane result made exact within ``r`` voxels of
the extra planes, by an oracle that knows the true mask there.
"""

from __future__ import annotations

import argparse
import csv
import io
import shlex
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from plain_sdf import plain_sdf_field  # noqa: E402
from real_anatomy import SPLIT_FILE, load_case, load_split  # noqa: E402

LAYOUTS = (
    "axial12",
    "every2",
    "axial12+2+2",
    "axial6+2+2",
    "inner8+2+2",
    "rt-axial8",
    "rt-axial8+3+3",
    "rt-radial8",
    "rt-axial8+tilted3",
)
CONTOUR_LAYOUTS = ("rt-axial8", "rt-axial8+3+3", "rt-radial8", "rt-axial8+tilted3")
"""Layouts drawn as contours (polygons in world mm, as an RTSTRUCT holds them)."""
INNER_CUT = 0.2
"""``inner8+2+2``: the share of the axial extent left undrawn at each end on the axial view."""
TIE = 0.001
"""|IoU difference| at most this is a tie."""


def _evenly(occupied: np.ndarray, n: int) -> np.ndarray:
    first, last = int(occupied[0]), int(occupied[-1])
    return np.unique(np.round(np.linspace(first, last, min(n, last - first + 1))).astype(int))


def layout_planes(mask: np.ndarray, layout: str) -> dict[int, np.ndarray]:
    """The annotated slice indices of a layout, by axis."""
    z = np.flatnonzero(mask.any(axis=(0, 1)))
    if layout == "every2":
        return {2: np.arange(z[0], z[-1] + 1, 2)}
    if layout.startswith("inner"):
        cut = int(round(INNER_CUT * (z[-1] - z[0])))
        z = np.arange(z[0] + cut, z[-1] - cut + 1)
    axial = _evenly(
        z, 12 if layout.startswith("axial12") else 8 if layout.startswith("inner") else 6
    )
    planes = {2: axial}
    if layout.endswith("+2+2"):
        for axis, other in ((0, (1, 2)), (1, (0, 2))):
            occupied = np.flatnonzero(mask.any(axis=other))
            span = occupied[-1] - occupied[0]
            planes[axis] = np.unique([int(occupied[0] + round(span * f)) for f in (1 / 3, 2 / 3)])
    return planes


def sparse_mask(mask: np.ndarray, planes: dict[int, np.ndarray]) -> np.ndarray:
    """The true mask on the given slices only."""
    out = np.zeros_like(mask)
    for axis, indices in planes.items():
        view_out = np.moveaxis(out, axis, 0)
        view_out[indices] = np.moveaxis(mask, axis, 0)[indices]
    return out


def iou(a: np.ndarray, b: np.ndarray) -> float:
    union = np.count_nonzero(a | b)
    return float(np.count_nonzero(a & b)) / union if union else 1.0


def _closed(result: Any) -> bool:
    """Whether every mesh of a reconstruction is watertight (each edge in two faces)."""
    return bool(result.reconstructed) and all(r.mesh.is_watertight for r in result.reconstructed)


def ours(sparse: np.ndarray, affine: np.ndarray) -> tuple[np.ndarray, str, bool]:
    """slicerecon from the sparse label map alone: its label map, how it read the input,
    and whether its meshes are watertight."""
    from slicerecon.case import reconstruct_structures
    from slicerecon.case_inputs import case_from_label_map
    from slicerecon.labels import LabelMap
    from slicerecon.reconstruct import ReconstructConfig

    label_map = LabelMap.from_array(sparse.astype(np.uint8), affine)
    reading = case_from_label_map(label_map, ReconstructConfig()).annotation.source
    result = reconstruct_structures(label_map)
    return result.labels > 0, reading, _closed(result)


def plain_sdf(sparse: np.ndarray, spacing: np.ndarray, axial: np.ndarray) -> np.ndarray:
    """Linear signed-distance interpolation between the axial planes (no slicerecon code)."""
    field, (x0, y0) = plain_sdf_field(sparse, spacing, axial)
    out = np.zeros(sparse.shape, dtype=bool)
    out[x0 : x0 + field.shape[0], y0 : y0 + field.shape[1], :] = field < 0
    return out


def itk_mci_labels(sparse: np.ndarray, spacing: np.ndarray) -> np.ndarray:
    """ITK's morphological contour interpolation (Slicer's Fill between slices), all axes,
    every label of the sparse label map at once: the filled label map, drawn voxels kept."""
    import itk

    image = itk.image_from_array(np.ascontiguousarray(sparse, dtype=np.uint8))
    image.SetSpacing([float(s) for s in spacing[::-1]])
    threads = itk.MultiThreaderBase.GetGlobalDefaultNumberOfThreads()
    itk.MultiThreaderBase.SetGlobalDefaultNumberOfThreads(1)  # the filter is not thread-safe
    try:
        interpolator = itk.MorphologicalContourInterpolator.New(image)
        interpolator.Update()
        filled = np.asarray(itk.array_from_image(interpolator.GetOutput()))
    finally:
        itk.MultiThreaderBase.SetGlobalDefaultNumberOfThreads(threads)
    return np.where(sparse > 0, sparse, filled)


def itk_mci(sparse: np.ndarray, spacing: np.ndarray) -> np.ndarray:
    """ITK's morphological contour interpolation, all axes (Slicer's Fill between slices)."""
    return itk_mci_labels(sparse, spacing) > 0


def _plane_mask(
    mask: np.ndarray,
    affine: np.ndarray,
    origin: np.ndarray,
    u: np.ndarray,
    v: np.ndarray,
    step: float,
    size: int,
) -> tuple[np.ndarray, np.ndarray]:
    """The true mask on a plane's pixels (nearest voxel), and the pixels' world positions."""
    from scipy import ndimage

    r, c = np.meshgrid(np.arange(size) - size / 2, np.arange(size) - size / 2, indexing="ij")
    world = origin + (r[..., None] * u + c[..., None] * v) * step
    index = (world - affine[:3, 3]) @ np.linalg.inv(affine[:3, :3]).T
    values = ndimage.map_coordinates(
        mask.astype(np.uint8), index.reshape(-1, 3).T, order=0, mode="constant"
    ).reshape(r.shape)
    return values.astype(bool), world


def _traced(
    mask: np.ndarray, affine: np.ndarray, normal: np.ndarray, point: np.ndarray
) -> list[list[list[float]]]:
    """The polygons of the true mask's section by the plane through ``point``, world mm."""
    from skimage import measure

    normal = normal / np.linalg.norm(normal)
    directions = affine[:3, :3] / np.linalg.norm(affine[:3, :3], axis=0)
    aligned = np.flatnonzero(np.abs(directions.T @ normal) > 1 - 1e-9)
    if aligned.size:  # a slice of the image: traced on its own pixels, as drawn on it
        axis = int(aligned[0])
        k = int(round(np.linalg.solve(affine[:3, :3], point - affine[:3, 3])[axis]))
        rows, cols = (a for a in range(3) if a != axis)
        polygons = []
        for contour in measure.find_contours(
            np.pad(np.take(mask, k, axis=axis), 1).astype(float), 0.5
        ):
            rc = contour[:-1] - 1.0
            if len(rc) < 3:
                continue
            ijk = np.zeros((len(rc), 3))
            ijk[:, rows], ijk[:, cols], ijk[:, axis] = rc[:, 0], rc[:, 1], k
            polygons.append((ijk @ affine[:3, :3].T + affine[:3, 3]).tolist())
        return polygons
    world_axis = np.eye(3)[int(np.argmin(np.abs(normal)))]
    u = world_axis - (world_axis @ normal) * normal
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    step = float(np.min(np.linalg.norm(affine[:3, :3], axis=0)))
    extent = np.linalg.norm(np.asarray(mask.shape) * np.linalg.norm(affine[:3, :3], axis=0))
    size = int(np.ceil(extent / step)) + 4
    # the plane's pixels centred on the grid's centre, projected onto the plane
    middle = affine[:3, :3] @ ((np.asarray(mask.shape) - 1) / 2.0) + affine[:3, 3]
    point = middle + ((point - middle) @ normal) * normal
    section, world = _plane_mask(mask, affine, point, u, v, step, size)
    polygons = []
    for contour in measure.find_contours(np.pad(section.astype(float), 1), 0.5):
        rc = contour[:-1] - 1.0
        if len(rc) < 3:
            continue
        r, c = rc[:, 0] - size / 2, rc[:, 1] - size / 2
        pts = point + (r[:, None] * u + c[:, None] * v) * step
        polygons.append(pts.tolist())
    return polygons


def _long_axis(mask: np.ndarray, affine: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The structure's centre and long axis (first principal direction), world mm."""
    points = np.argwhere(mask).astype(np.float64) @ affine[:3, :3].T + affine[:3, 3]
    centre = points.mean(axis=0)
    _, _, vt = np.linalg.svd(points - centre, full_matrices=False)
    return centre, vt[0]


def contour_planes(mask: np.ndarray, affine: np.ndarray, layout: str) -> list[tuple]:
    """The planes ``(normal, point)`` of a contour layout, world mm."""
    index_to_world = lambda ijk: affine[:3, :3] @ np.asarray(ijk, float) + affine[:3, 3]  # noqa: E731
    z = np.flatnonzero(mask.any(axis=(0, 1)))
    axial_normal = affine[:3, 2] / np.linalg.norm(affine[:3, 2])
    planes = []
    if layout != "rt-radial8":
        for k in _evenly(z, 8):
            planes.append((axial_normal, index_to_world([0, 0, k])))
    centre, axis = _long_axis(mask, affine)
    if layout == "rt-axial8+3+3":
        for ax in (0, 1):
            occupied = np.flatnonzero(mask.any(axis=tuple(a for a in range(3) if a != ax)))
            normal = affine[:3, ax] / np.linalg.norm(affine[:3, ax])
            for f in (0.25, 0.5, 0.75):
                ijk = [0, 0, 0]
                ijk[ax] = int(occupied[0] + round((occupied[-1] - occupied[0]) * f))
                planes.append((normal, index_to_world(ijk)))
    elif layout == "rt-radial8":
        side = np.cross(axis, np.eye(3)[int(np.argmin(np.abs(axis)))])
        side /= np.linalg.norm(side)
        other = np.cross(axis, side)
        for t in np.radians(22.5 * np.arange(8)):
            planes.append((np.cos(t) * side + np.sin(t) * other, centre))
    elif layout == "rt-axial8+tilted3":
        tilt_axis = affine[:3, 0] / np.linalg.norm(affine[:3, 0])
        for degrees in (30, 45, 60):
            t = np.radians(degrees)
            normal = np.cos(t) * axial_normal + np.sin(t) * np.cross(tilt_axis, axial_normal)
            planes.append((normal, centre))
    return planes


def contours_sparse(truth: Any, layout: str, directory: Path) -> tuple[Path, np.ndarray | None]:
    """The layout's contours as a version 2 contour file on the truth's grid, and (for a
    layout on grid slices) the same planes as a sparse label map."""
    import json

    mask, affine = truth.mask, truth.affine
    planes = contour_planes(mask, affine, layout)
    doc = {
        "format": "slicerecon-contours",
        "version": 2,
        "units": "mm",
        "grid": {"affine": affine.tolist(), "shape": list(mask.shape)},
        "planes": [
            {"normal": list(map(float, n)), "polygons": polys}
            for n, p in planes
            if (polys := _traced(mask, affine, n, p))
        ],
    }
    path = directory / f"{layout}.json"
    path.write_text(json.dumps(doc))
    sparse = None
    if layout in ("rt-axial8", "rt-axial8+3+3"):
        inverse = np.linalg.inv(affine)
        by_axis: dict[int, list[int]] = {}
        for normal, point in planes:
            ax = int(
                np.argmax(np.abs(inverse[:3, :3] @ normal * np.linalg.norm(affine[:3, :3], axis=0)))
            )
            by_axis.setdefault(ax, []).append(
                int(round((inverse[:3, :3] @ point + inverse[:3, 3])[ax]))
            )
        sparse = sparse_mask(mask, {a: np.array(k) for a, k in by_axis.items()})
    return path, sparse


def ours_contours(path: Path) -> tuple[np.ndarray, str, bool]:
    """slicerecon from the contour file alone: its label map on the file's grid, how it
    read the file, and whether its meshes are watertight."""
    from slicerecon.case import reconstruct_case
    from slicerecon.case_inputs import load_case
    from slicerecon.reconstruct import ReconstructConfig

    config = ReconstructConfig()
    case = load_case(path, config)
    result = reconstruct_case(case, config)
    return result.labels > 0, case.annotation.source, _closed(result)


def run_case(name: str, protocol: dict[str, Any], layouts: list[str]) -> list[dict[str, Any]]:
    """Every layout of one case: the three (or four) reconstructions and their IoUs."""
    truth = load_case(name, protocol)
    mask, affine, spacing = truth.mask, truth.affine, truth.spacing
    rows = []
    import tempfile

    scratch = Path(tempfile.mkdtemp(prefix="annotations-"))
    for layout in layouts:
        row: dict[str, Any] = {"case": name, "layout": layout}
        if layout in CONTOUR_LAYOUTS:
            path, sparse = contours_sparse(truth, layout, scratch)
            start = time.perf_counter()
            result, reading, closed = ours_contours(path)
            row["ours_s"] = time.perf_counter() - start
            row["ours"], row["reading"], row["watertight"] = iou(result, mask), reading, closed
            if sparse is not None:
                axial = _evenly(np.flatnonzero(mask.any(axis=(0, 1))), 8)
                row["plain_sdf"] = iou(plain_sdf(sparse, spacing, axial), mask)
                row["itk_mci"] = iou(itk_mci(sparse, spacing), mask)
            if layout != "rt-axial8" and layout != "rt-radial8":
                axial_path, _ = contours_sparse(truth, "rt-axial8", scratch)
                row["ours_axial_only"] = iou(ours_contours(axial_path)[0], mask)
            rows.append(row)
            _say(row)
            continue
        planes = layout_planes(mask, layout)
        sparse = sparse_mask(mask, planes)
        start = time.perf_counter()
        result, reading, closed = ours(sparse, affine)
        row["ours_s"] = time.perf_counter() - start
        row["ours"], row["reading"], row["watertight"] = iou(result, mask), reading, closed
        row["plain_sdf"] = iou(plain_sdf(sparse, spacing, planes[2]), mask)
        start = time.perf_counter()
        row["itk_mci"] = iou(itk_mci(sparse, spacing), mask)
        row["itk_s"] = time.perf_counter() - start
        if len(planes) > 1:
            axial_only, _, _ = ours(sparse_mask(mask, {2: planes[2]}), affine)
            row["ours_axial_only"] = iou(axial_only, mask)
        rows.append(row)
        _say(row)
    return rows


def _say(row: dict[str, Any]) -> None:
    def fmt(key: str) -> str:
        return f"{row[key]:.4f}" if key in row else "  –   "

    print(
        f"{row['case']:24s} {row['layout']:18s} ours {fmt('ours')} plain {fmt('plain_sdf')} "
        f"itk {fmt('itk_mci')} axial-only {fmt('ours_axial_only')} | {row['reading']}",
        file=sys.stderr,
        flush=True,
    )


def _counts(diffs: np.ndarray) -> str:
    return (
        f"{int(np.sum(diffs > TIE))} / {int(np.sum(np.abs(diffs) <= TIE))} / "
        f"{int(np.sum(diffs < -TIE))}"
    )


def _column(sel: list[dict[str, Any]], key: str) -> np.ndarray | None:
    values = [r[key] for r in sel if key in r]
    return np.array(values) if len(values) == len(sel) else None


def _versus(ours_v: np.ndarray, other: np.ndarray | None) -> str:
    if other is None:
        return "–"
    return f"{(ours_v - other).mean():+.4f} ({_counts(ours_v - other)})"


def report(rows: list[dict[str, Any]], halves: dict[str, str], command: str) -> str:
    """The markdown tables: per half and layout, means and paired counts; then per case."""
    lines = [f"Measured by `{command}` (volume IoU against the true mask).", ""]
    for half in ("dev", "val"):
        own = [r for r in rows if halves[r["case"]] == half]
        if not own:
            continue
        lines += [
            f"**{'Development' if half == 'dev' else 'Validation'} half** "
            f"({len({r['case'] for r in own})} cases)",
            "",
            "| layout | ours | plain SDF (axial) | ITK-MCI (all axes) | ours, axial only | "
            "ours − plain SDF (w / t / l) | ours − ITK-MCI (w / t / l) | "
            "ours − axial only (w / t / l) | worst vs plain SDF | watertight |",
            "|---|---:|---:|---:|---:|---|---|---|---:|---:|",
        ]
        for layout in LAYOUTS:
            sel = [r for r in own if r["layout"] == layout]
            if not sel:
                continue
            ours_v = np.array([r["ours"] for r in sel])
            plain, itk, axial = (
                _column(sel, k) for k in ("plain_sdf", "itk_mci", "ours_axial_only")
            )
            mean = lambda v: "–" if v is None else f"{v.mean():.4f}"  # noqa: E731
            worst = "–" if plain is None else f"{(ours_v - plain).min():+.4f}"
            lines.append(
                f"| {layout} | {ours_v.mean():.4f} | {mean(plain)} | {mean(itk)} | {mean(axial)} | "
                f"{_versus(ours_v, plain)} | {_versus(ours_v, itk)} | {_versus(ours_v, axial)} | "
                f"{worst} | {sum(bool(r.get('watertight')) for r in sel)} / {len(sel)} |"
            )
        lines.append("")
    lines += [
        "<details><summary>Per case</summary>",
        "",
        "| half | case | layout | ours | plain SDF | ITK-MCI | ours, axial only | read as |",
        "|---|---|---|---:|---:|---:|---:|---|",
    ]
    for r in rows:
        cells = [
            f"{r[k]:.4f}" if k in r else "–" for k in ("plain_sdf", "itk_mci", "ours_axial_only")
        ]
        lines.append(
            f"| {halves[r['case']]} | {r['case']} | {r['layout']} | {r['ours']:.4f} | "
            f"{' | '.join(cells)} | {r['reading']} |"
        )
    lines += ["", "</details>", ""]
    return "\n".join(lines)


def speed(repeat: int) -> str:
    """Ours against ITK-MCI on the 340 × 285 × 120 organ annotated 12 + 2 + 2, side by side."""
    import bench_clinical

    mask, spacing = bench_clinical.liver_340()
    affine = np.diag([*spacing, 1.0])
    sparse = sparse_mask(mask, layout_planes(mask, "axial12+2+2"))
    itk_mci(sparse[:8, :8, :8], np.asarray(spacing))  # ITK's first call loads the filter
    times: dict[str, list[float]] = {"ours": [], "itk": []}
    for _ in range(repeat):
        start = time.perf_counter()
        result, reading, _ = ours(sparse, affine)
        times["ours"].append(time.perf_counter() - start)
        start = time.perf_counter()
        filled = itk_mci(sparse, np.asarray(spacing))
        times["itk"].append(time.perf_counter() - start)
    best = {k: min(v) for k, v in times.items()}
    return (
        f"340x285x120 organ, 12 axial + 2 sagittal + 2 coronal planes ({reading}): "
        f"ours {best['ours']:.2f} s (IoU {iou(result, mask):.4f}), ITK-MCI {best['itk']:.2f} s "
        f"(IoU {iou(filled, mask):.4f}); ratio {best['ours'] / best['itk']:.2f} "
        f"(best of {repeat}, alternating)"
    )


def ceiling(names: list[str], protocol: dict[str, Any], reaches: tuple[int, ...]) -> str:
    """How much 2 sagittal and 2 coronal planes can add to 12 axial ones, at best locally.

    Our axial-only result with every voxel within ``r`` voxels of the extra planes set
    to the truth (an oracle that knows the shape near the planes), beside our axial-only
    and 12 + 2 + 2 results: the mean volume IoU of each.
    """
    columns: dict[str, list[float]] = {"axial only": [], "12 + 2 + 2": []}
    columns.update({f"oracle, r = {r}": [] for r in reaches})
    for name in names:
        truth = load_case(name, protocol)
        mask = truth.mask.astype(bool)
        planes = layout_planes(mask, "axial12+2+2")
        alone = ours(sparse_mask(mask, {2: planes[2]}), truth.affine)[0]
        columns["axial only"].append(iou(alone, mask))
        columns["12 + 2 + 2"].append(iou(ours(sparse_mask(mask, planes), truth.affine)[0], mask))
        apart = [
            np.min(np.abs(np.arange(mask.shape[a])[:, None] - planes[a][None, :]), axis=1)
            for a in (0, 1)
        ]
        near = np.minimum(apart[0][:, None, None], apart[1][None, :, None])
        for r in reaches:
            columns[f"oracle, r = {r}"].append(iou(np.where(near <= r, mask, alone), mask))
        print(name, {k: round(v[-1], 4) for k, v in columns.items()}, file=sys.stderr)
    head = "| " + " | ".join(columns) + " |"
    rule = "|" + "---:|" * len(columns)
    means = "| " + " | ".join(f"{np.mean(v):.4f}" for v in columns.values()) + " |"
    return "\n".join([f"{len(names)} cases", "", head, rule, means])


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--half", choices=("dev", "val", "both"), default="dev")
    parser.add_argument("--layouts", default=",".join(LAYOUTS))
    parser.add_argument("--cases", default=None, help="comma-separated subset")
    parser.add_argument("--out", type=Path, default=None, help="CSV of every number")
    parser.add_argument("--speed", action="store_true", help="time the clinical-size case only")
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument(
        "--ceiling",
        action="store_true",
        help="the axial-only result made exact near the 2 + 2 extra planes (an oracle)",
    )
    args = parser.parse_args(argv)
    command = "python benchmarks/annotations.py " + shlex.join(argv or sys.argv[1:])
    if args.speed:
        print(speed(args.repeat))
        return 0
    protocol, cases = load_split(SPLIT_FILE)
    halves = {n: c["half"] for n, c in cases.items()}
    names = [n for n in cases if args.half == "both" or halves[n] == args.half]
    if args.cases:
        names = [n for n in names if n in args.cases.split(",")]
    if args.ceiling:
        print(ceiling(names, protocol, (0, 1, 3)))
        return 0
    layouts = [lay for lay in args.layouts.split(",") if lay]
    unknown = sorted(set(layouts) - set(LAYOUTS))
    if unknown:
        parser.error(f"unknown layouts {unknown}; choose from {', '.join(LAYOUTS)}")
    rows = []
    for name in names:
        try:
            rows += run_case(name, protocol, layouts)
        except Exception as exc:  # noqa: BLE001 - a case whose package is missing is listed
            print(f"{name}: skipped ({type(exc).__name__}: {exc})", file=sys.stderr)
    if args.out is not None:
        fields = [
            "case",
            "layout",
            "ours",
            "plain_sdf",
            "itk_mci",
            "ours_axial_only",
            "watertight",
            "reading",
        ]
        buffer = io.StringIO()
        writer = csv.DictWriter(buffer, fieldnames=["half", *fields], extrasaction="ignore")
        writer.writeheader()
        for r in rows:
            writer.writerow({"half": halves[r["case"]], **{k: _fmt(r.get(k)) for k in fields}})
        args.out.write_text(buffer.getvalue(), encoding="utf-8")
    print(report(rows, halves, command))
    return 0


def _fmt(value: Any) -> Any:
    return f"{value:.6f}" if isinstance(value, float) else ("" if value is None else value)


if __name__ == "__main__":
    sys.exit(main())
