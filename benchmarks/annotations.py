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
side by side in this process.
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

LAYOUTS = ("axial12", "every2", "axial12+2+2", "axial6+2+2")
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
    axial = _evenly(z, 12 if layout.startswith("axial12") else 6)
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


def ours(sparse: np.ndarray, affine: np.ndarray) -> tuple[np.ndarray, str]:
    """slicerecon from the sparse label map alone: its label map, and how it read the input."""
    from slicerecon.case import reconstruct_structures
    from slicerecon.case_inputs import case_from_label_map
    from slicerecon.labels import LabelMap
    from slicerecon.reconstruct import ReconstructConfig

    label_map = LabelMap.from_array(sparse.astype(np.uint8), affine)
    reading = case_from_label_map(label_map, ReconstructConfig()).annotation.source
    result = reconstruct_structures(label_map)
    return result.labels > 0, reading


def plain_sdf(sparse: np.ndarray, spacing: np.ndarray, axial: np.ndarray) -> np.ndarray:
    """Linear signed-distance interpolation between the axial planes (no slicerecon code)."""
    field, (x0, y0) = plain_sdf_field(sparse, spacing, axial)
    out = np.zeros(sparse.shape, dtype=bool)
    out[x0 : x0 + field.shape[0], y0 : y0 + field.shape[1], :] = field < 0
    return out


def itk_mci(sparse: np.ndarray, spacing: np.ndarray) -> np.ndarray:
    """ITK's morphological contour interpolation, all axes (Slicer's Fill between slices)."""
    import itk

    image = itk.image_from_array(np.ascontiguousarray(sparse, dtype=np.uint8))
    image.SetSpacing([float(s) for s in spacing[::-1]])
    threads = itk.MultiThreaderBase.GetGlobalDefaultNumberOfThreads()
    itk.MultiThreaderBase.SetGlobalDefaultNumberOfThreads(1)  # the filter is not thread-safe
    try:
        interpolator = itk.MorphologicalContourInterpolator.New(image)
        interpolator.Update()
        filled = np.asarray(itk.array_from_image(interpolator.GetOutput())) > 0
    finally:
        itk.MultiThreaderBase.SetGlobalDefaultNumberOfThreads(threads)
    return filled | sparse


def run_case(name: str, protocol: dict[str, Any], layouts: list[str]) -> list[dict[str, Any]]:
    """Every layout of one case: the three (or four) reconstructions and their IoUs."""
    truth = load_case(name, protocol)
    mask, affine, spacing = truth.mask, truth.affine, truth.spacing
    rows = []
    for layout in layouts:
        planes = layout_planes(mask, layout)
        sparse = sparse_mask(mask, planes)
        row: dict[str, Any] = {"case": name, "layout": layout}
        start = time.perf_counter()
        result, reading = ours(sparse, affine)
        row["ours_s"] = time.perf_counter() - start
        row["ours"] = iou(result, mask)
        row["reading"] = reading
        row["plain_sdf"] = iou(plain_sdf(sparse, spacing, planes[2]), mask)
        start = time.perf_counter()
        row["itk_mci"] = iou(itk_mci(sparse, spacing), mask)
        row["itk_s"] = time.perf_counter() - start
        if len(planes) > 1:
            axial_only, _ = ours(sparse_mask(mask, {2: planes[2]}), affine)
            row["ours_axial_only"] = iou(axial_only, mask)
        rows.append(row)
        print(
            f"{name:24s} {layout:12s} ours {row['ours']:.4f} plain {row['plain_sdf']:.4f} "
            f"itk {row['itk_mci']:.4f} axial-only {row.get('ours_axial_only', float('nan')):.4f} "
            f"| {reading}",
            file=sys.stderr,
            flush=True,
        )
    return rows


def _counts(diffs: np.ndarray) -> str:
    return (
        f"{int(np.sum(diffs > TIE))} / {int(np.sum(np.abs(diffs) <= TIE))} / "
        f"{int(np.sum(diffs < -TIE))}"
    )


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
            "ours − plain SDF (w / t / l) | ours − ITK-MCI (w / t / l) | worst vs plain SDF |",
            "|---|---:|---:|---:|---:|---|---|---:|",
        ]
        for layout in LAYOUTS:
            sel = [r for r in own if r["layout"] == layout]
            if not sel:
                continue
            ours_v = np.array([r["ours"] for r in sel])
            plain = np.array([r["plain_sdf"] for r in sel])
            itk = np.array([r["itk_mci"] for r in sel])
            axial = [r["ours_axial_only"] for r in sel if "ours_axial_only" in r]
            axial_text = f"{np.mean(axial):.4f}" if axial else "–"
            lines.append(
                f"| {layout} | {ours_v.mean():.4f} | {plain.mean():.4f} | {itk.mean():.4f} | "
                f"{axial_text} | {(ours_v - plain).mean():+.4f} ({_counts(ours_v - plain)}) | "
                f"{(ours_v - itk).mean():+.4f} ({_counts(ours_v - itk)}) | "
                f"{(ours_v - plain).min():+.4f} |"
            )
        lines.append("")
    lines += [
        "<details><summary>Per case</summary>",
        "",
        "| half | case | layout | ours | plain SDF | ITK-MCI | ours, axial only | read as |",
        "|---|---|---|---:|---:|---:|---:|---|",
    ]
    for r in rows:
        axial = f"{r['ours_axial_only']:.4f}" if "ours_axial_only" in r else "–"
        lines.append(
            f"| {halves[r['case']]} | {r['case']} | {r['layout']} | {r['ours']:.4f} | "
            f"{r['plain_sdf']:.4f} | {r['itk_mci']:.4f} | {axial} | {r['reading']} |"
        )
    lines += ["", "</details>", ""]
    return "\n".join(lines)


def speed(repeat: int) -> str:
    """Ours against ITK-MCI on the 340 × 285 × 120 organ annotated 12 + 2 + 2, side by side."""
    import bench_clinical

    with_tmp = Path(__import__("tempfile").mkdtemp())
    cases = bench_clinical.make_cases(with_tmp)
    mask, spacing = cases["liver 340x285x120"]
    affine = np.diag([*spacing, 1.0])
    sparse = sparse_mask(mask, layout_planes(mask, "axial12+2+2"))
    itk_mci(sparse[:8, :8, :8], np.asarray(spacing))  # ITK's first call loads the filter
    times: dict[str, list[float]] = {"ours": [], "itk": []}
    for _ in range(repeat):
        start = time.perf_counter()
        result, reading = ours(sparse, affine)
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


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--half", choices=("dev", "val", "both"), default="dev")
    parser.add_argument("--layouts", default=",".join(LAYOUTS))
    parser.add_argument("--cases", default=None, help="comma-separated subset")
    parser.add_argument("--out", type=Path, default=None, help="CSV of every number")
    parser.add_argument("--speed", action="store_true", help="time the clinical-size case only")
    parser.add_argument("--repeat", type=int, default=2)
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
        fields = ["case", "layout", "ours", "plain_sdf", "itk_mci", "ours_axial_only", "reading"]
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
