"""Compare every reconstruction method on the same sections: loft, sdf and the baselines.

For each shape (procedural shapes of :mod:`slicerecon.shapes` and, when
nilearn is installed, the MNI152 brain mask) and for a sparse (``n`` planes)
and a dense (:func:`slicerecon.sampling.dense_count` ``(n) = 2n - 1`` planes)
setting, the dense mask is sampled once (:func:`slicerecon.reconstruct.prepare_inputs`,
projections from the mask) and every method reconstructs from exactly these
inputs in this one process (:func:`slicerecon.reconstruct.reconstruct`, library
defaults: carving by the hull on for loft and sdf), then is evaluated against
the dense mask (:func:`slicerecon.metrics.evaluate`). It writes every number to
the CSV ``--out`` and prints the markdown tables (per case, and the summary
that ``docs/results.md`` shows) to stdout. The tables of ``docs/results.md``::

    S=sphere,torus,y_branch,chair,two_spheres,kidney,lung,vessel_tree,brain,genus2,table,\\
    mni152_brain,mni152_wm,frog_liver,frog_kidney,frog_brain,pymeshlab_bunny
    python benchmarks/compare_methods.py --shapes $S --out docs/data/compare_methods.csv
    python benchmarks/compare_methods.py --projections sections --shapes $S --methods \\
        "sdf + heuristic (default),sdf + heuristic (carve only),hybrid + heuristic,\\
    loft + heuristic,loft + none,sdf plain,sdf-hull" --out docs/data/compare_methods_sections.csv
    python benchmarks/compare_methods.py --projections sections --shapes $S --methods \\
        "sdf + heuristic (default),sdf + lookahead" \\
        --out docs/data/compare_methods_sections_lookahead.csv

Each method is warmed up once on a tiny ball before timing, so ITK's ~10 s
first-call cost and pymeshlab's plugin loading are not charged to a case.
Nothing is tuned per shape.
"""

from __future__ import annotations

import argparse
import csv
import io
import logging
import shlex
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from slicerecon.errors import DependencyError, SlicereconError
from slicerecon.io.atomic import atomic_path
from slicerecon.metrics import evaluate
from slicerecon.reconstruct import prepare_inputs, reconstruct
from slicerecon.sampling import dense_count
from slicerecon.sections import Volume, axis_index
from slicerecon.shapes import make_shape, shape_names, sphere


@dataclass(frozen=True)
class Variant:
    """One column of the comparison: a surface method and (for loft/sdf) a planner."""

    label: str
    method: str
    planner: str
    carve: bool = True
    cover: bool = True
    interpolation: str = "pchip"
    join_drift: bool = True


DEFAULT_LABEL = "sdf + heuristic (default)"
"""The library's defaults: sdf (PCHIP), heuristic planner, carved, covering the silhouettes."""

VARIANTS = (
    Variant(DEFAULT_LABEL, "sdf", "heuristic"),
    Variant("sdf + heuristic (carve only)", "sdf", "heuristic", cover=False),
    Variant("sdf + lookahead", "sdf", "lookahead"),
    Variant("hybrid + heuristic", "hybrid", "heuristic"),
    Variant("loft + heuristic", "loft", "heuristic"),
    Variant("loft + heuristic (uncarved)", "loft", "heuristic", carve=False),
    Variant("loft + none", "loft", "none"),
    Variant("sdf plain", "sdf", "none", carve=False, interpolation="linear", join_drift=False),
    Variant("sdf-hull", "sdf-hull", "none"),
    Variant("poisson", "poisson", "none"),
    Variant("itk-mci", "itk-mci", "none"),
)

_PROJECTION_TEXT = {
    "gt": "projections from the dense mask (`--projections gt`)",
    "sections": "projections derived from the sections alone (`--projections sections`)",
}

FIELDS = (
    "shape",
    "setting",
    "planes",
    "variant",
    "method",
    "planner",
    "volume_iou",
    "surface_iou",
    "chamfer_l1_mm",
    "hd95_mm",
    "volume_error",
    "watertight",
    "parts",
    "seconds",
    "error",
)


def _load_shapes(names: list[str], real_resolution: int) -> list[tuple[str, Volume]]:
    from slicerecon.realshapes import REAL_SHAPES, real_shape

    out: list[tuple[str, Volume]] = []
    for name in names:
        if name in REAL_SHAPES:
            try:
                volume = real_shape(name, resolution=real_resolution)
            except DependencyError as exc:
                logging.warning("skipping %s: %s", name, exc)
                continue
        else:
            volume = make_shape(name)
        out.append((name, volume))
    return out


def _available_variants(variants: tuple[Variant, ...]) -> list[Variant]:
    """Warm every method up on a tiny ball; drop those whose dependency is missing."""
    sections, projections, _ = prepare_inputs(sphere(8.0), slices=5)
    kept = []
    for variant in variants:
        try:
            reconstruct(
                sections,
                projections,
                planner=variant.planner,
                method=variant.method,
                carve=variant.carve,
                cover=variant.cover,
                interpolation=variant.interpolation,
                join_drift=variant.join_drift,
            )
        except DependencyError as exc:
            logging.warning("skipping %s: %s", variant.label, exc)
            continue
        kept.append(variant)
    return kept


def _fmt(value: object, digits: int = 3) -> str:
    if isinstance(value, float):
        return f"{value:.{digits}f}"
    return "" if value is None else str(value)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--shapes",
        default="sphere,torus,y_branch,chair,two_spheres,mni152_brain",
        help="comma-separated shape names (procedural, or real: slicerecon.realshapes)",
    )
    parser.add_argument("--slices", default="12", help="comma-separated sparse plane counts")
    parser.add_argument("--axis", default="z", help="section axis: x, y or z")
    parser.add_argument(
        "--projections",
        default="gt",
        choices=("gt", "sections"),
        help="silhouettes from the dense mask (the paper's prior) or derived from the sections "
        "(what a user with contours only has)",
    )
    parser.add_argument(
        "--methods",
        default=",".join(v.label for v in VARIANTS),
        help="comma-separated variants (labels as in the table)",
    )
    parser.add_argument(
        "--real-resolution",
        type=int,
        default=96,
        help="real shapes downsampled to at most this many voxels a side",
    )
    parser.add_argument("--n-points", type=int, default=20_000, help="surface samples per mesh")
    parser.add_argument(
        "--out",
        type=Path,
        default=Path("docs/data/compare_methods.csv"),
        help="CSV of every number (the markdown tables go to stdout)",
    )
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")

    names = [s.strip() for s in args.shapes.split(",") if s.strip()]
    from slicerecon.realshapes import REAL_SHAPES

    unknown = [n for n in names if n not in REAL_SHAPES and n not in shape_names()]
    if unknown:
        parser.error(f"unknown shapes {unknown}; choose from {shape_names() + list(REAL_SHAPES)}")
    wanted = [m.strip() for m in args.methods.split(",") if m.strip()]
    labels = {v.label: v for v in VARIANTS}
    if any(m not in labels for m in wanted):
        parser.error(f"unknown methods {wanted}; choose from {list(labels)}")
    sparse_counts = [int(n) for n in args.slices.split(",")]
    axis = axis_index(args.axis)

    variants = _available_variants(tuple(labels[m] for m in wanted))
    rows: list[dict[str, Any]] = []
    for shape_name, volume in _load_shapes(names, args.real_resolution):
        available = volume.occupied_planes(axis).size
        for n in sparse_counts:
            for setting, count in (("sparse", n), ("dense", dense_count(n))):
                if count > available:
                    logging.warning(
                        "%s: %d planes asked, %d available; using all", shape_name, count, available
                    )
                    count = available
                sections, projections, truth = prepare_inputs(
                    volume, slices=count, axis=axis, projections=args.projections
                )
                assert truth is not None
                for variant in variants:
                    row: dict[str, Any] = {
                        "shape": shape_name,
                        "setting": setting,
                        "planes": sections.n_planes,
                        "variant": variant.label,
                        "method": variant.method,
                        "planner": variant.planner
                        if variant.method in ("hybrid", "loft", "sdf")
                        else "-",
                    }
                    start = time.perf_counter()
                    try:
                        result = reconstruct(
                            sections,
                            projections,
                            planner=variant.planner,
                            method=variant.method,
                            carve=variant.carve,
                            cover=variant.cover,
                            interpolation=variant.interpolation,
                            join_drift=variant.join_drift,
                        )
                        row["seconds"] = time.perf_counter() - start
                        metrics = evaluate(result.mesh, truth, n_points=args.n_points, seed=0)
                    except SlicereconError as exc:
                        row["seconds"] = time.perf_counter() - start
                        row["error"] = str(exc)
                        rows.append(row)
                        print(
                            f"{shape_name:14s} {setting:6s} {variant.label:18s} ERROR {exc}",
                            file=sys.stderr,
                            flush=True,
                        )
                        continue
                    row.update(
                        volume_iou=metrics.volume_iou,
                        surface_iou=metrics.surface_iou,
                        chamfer_l1_mm=metrics.chamfer_l1_mm,
                        hd95_mm=metrics.hd95_mm,
                        volume_error=metrics.volume_error,
                        watertight=bool(result.mesh.is_watertight),
                        parts=len(result.plan.parts),
                        error="",
                    )
                    rows.append(row)
                    print(
                        f"{shape_name:14s} {setting:6s} {sections.n_planes:3d} "
                        f"{variant.label:18s} IoU {metrics.volume_iou:.3f} "
                        f"sIoU {metrics.surface_iou:.3f} CD {metrics.chamfer_l1_mm:.3f} mm "
                        f"HD95 {metrics.hd95_mm:.2f} mm {row['seconds']:.2f} s",
                        file=sys.stderr,
                        flush=True,
                    )
    command = shlex.join(["python", "benchmarks/compare_methods.py", *(argv or sys.argv[1:])])
    _write(args.out, rows, command, [v.label for v in variants], args)
    return 0


def _write(
    out: Path,
    rows: list[dict[str, Any]],
    command: str,
    labels: list[str],
    args: argparse.Namespace,
) -> None:
    csv_path = out.with_suffix(".csv")
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=FIELDS, lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: row.get(k, "") for k in FIELDS})
    with atomic_path(csv_path) as tmp:
        tmp.write_text(buffer.getvalue())

    lines = [
        "# Reconstruction methods compared",
        "",
        f"Command: `{command}`",
        "",
        f"Written by `benchmarks/compare_methods.py`; raw numbers in `{csv_path.as_posix()}`. "
        f"Sections along {args.axis}, {_PROJECTION_TEXT[args.projections]}, "
        f"{args.n_points} surface samples per mesh, seed 0. Every method runs in one process "
        "on the same sections; each was warmed up once before timing. Seconds are wall "
        "time of `reconstruct()` (planning + surface + carve), measured on a machine "
        "whose 2 CPU cores were shared with other jobs, so compare them within a row group "
        "only. loft/sdf use the library default `carve=True`; the whole-shape baselines "
        "(sdf-hull, poisson, itk-mci) run without a planner and are not carved. "
        "`loft + heuristic (uncarved)` is the paper's method without carving; `sdf plain` is the "
        "classic signed-distance interpolation between planes (linear, one part, no carving): the "
        "strong baseline the default has to beat.",
        "",
        "Volume IoU and surface IoU: higher is better; Chamfer-L1 and HD95 (mm): lower is "
        "better. The best value of each group is in bold.",
        "",
        "| shape | setting | planes | method | volume IoU | surface IoU | Chamfer-L1 mm "
        "| HD95 mm | watertight | s |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    groups: dict[tuple[object, object], list[dict[str, Any]]] = {}
    for row in rows:
        groups.setdefault((row["shape"], row["setting"]), []).append(row)
    for group in groups.values():
        ok = [r for r in group if not r.get("error")]
        best = {}
        for key, pick in (
            ("volume_iou", max),
            ("surface_iou", max),
            ("chamfer_l1_mm", min),
            ("hd95_mm", min),
        ):
            if ok:
                best[key] = pick(float(r[key]) for r in ok)
        for r in group:
            if r.get("error"):
                lines.append(
                    f"| {r['shape']} | {r['setting']} | {r['planes']} | {r['variant']} | "
                    f"error: {r['error']} | | | | | {_fmt(r['seconds'], 2)} |"
                )
                continue
            cells = []
            for key, digits in (
                ("volume_iou", 3),
                ("surface_iou", 3),
                ("chamfer_l1_mm", 3),
                ("hd95_mm", 2),
            ):
                text = _fmt(float(r[key]), digits)
                cells.append(f"**{text}**" if float(r[key]) == best[key] else text)
            lines.append(
                f"| {r['shape']} | {r['setting']} | {r['planes']} | {r['variant']} | "
                f"{' | '.join(cells)} | {'yes' if r['watertight'] else 'NO'} | "
                f"{_fmt(r['seconds'], 2)} |"
            )
    lines += ["", "## Summary", ""]
    lines += _summary(rows, labels)
    print("\n".join(lines))


def _summary(rows: list[dict[str, Any]], labels: list[str]) -> list[str]:
    """Mean metrics per method, and head-to-head counts of the default loft against sdf."""
    ok = [r for r in rows if not r.get("error")]
    out = [
        "Mean over all shapes and settings (each method on the same cases):",
        "",
        "| method | cases | mean volume IoU | mean surface IoU | mean Chamfer-L1 mm "
        "| mean HD95 mm | mean s |",
        "|---|---|---|---|---|---|---|",
    ]
    for label in labels:
        mine = [r for r in ok if r["variant"] == label]
        if not mine:
            continue

        def mean(key: str, rs: list[dict[str, Any]] = mine) -> float:
            return sum(float(r[key]) for r in rs) / len(rs)

        out.append(
            f"| {label} | {len(mine)} | {mean('volume_iou'):.3f} | {mean('surface_iou'):.3f} "
            f"| {mean('chamfer_l1_mm'):.3f} | {mean('hd95_mm'):.2f} | {mean('seconds'):.2f} |"
        )
    by_case: dict[tuple[object, object], dict[object, dict[str, Any]]] = {}
    for r in ok:
        by_case.setdefault((r["shape"], r["setting"]), {})[r["variant"]] = r
    default = DEFAULT_LABEL
    for other in ("sdf plain", "sdf + heuristic (carve only)", "loft + heuristic"):
        pairs = [(c[default], c[other]) for c in by_case.values() if default in c and other in c]
        if not pairs:
            continue
        wins_iou = sum(float(d["volume_iou"]) > float(o["volume_iou"]) for d, o in pairs)
        wins_cd = sum(float(d["chamfer_l1_mm"]) < float(o["chamfer_l1_mm"]) for d, o in pairs)
        losses = [
            f"{d['shape']} {d['setting']}"
            for d, o in pairs
            if float(o["volume_iou"]) > float(d["volume_iou"]) + 1e-3
        ]
        lost = f" It loses by more than 0.001 IoU on: {', '.join(losses)}." if losses else ""
        out += [
            "",
            f"Default (`sdf`, heuristic planner, cover) against `{other}` on {len(pairs)} cases: "
            f"higher volume IoU in {wins_iou}, lower Chamfer-L1 in {wins_cd}.{lost}",
        ]
    return out


if __name__ == "__main__":
    sys.exit(main())
