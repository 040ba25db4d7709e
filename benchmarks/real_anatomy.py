"""Real-anatomy protocol: reconstruction variants against plain SDF on the dev / val real shapes.

Every case of ``benchmarks/real_split.toml`` (real shapes read from installed
packages, :mod:`slicerecon.realshapes`, normalised to 96–160 voxels across,
see ``docs/realshapes.md``) is sampled at N evenly spaced planes along each
chosen axis (:func:`slicerecon.reconstruct.prepare_inputs`, projections from
the dense mask), reconstructed by each variant
(:func:`slicerecon.reconstruct.reconstruct`) and scored by
``benchmarks/independent_eval.py``, which does not use
:mod:`slicerecon.metrics`::

    python benchmarks/real_anatomy.py --half both --planes 6,12,24 --axes x,y,z --jobs 2 \\
        --out docs/data/real_anatomy.csv

writes every number to the CSV ``--out`` and prints a markdown report (summary,
strata, largest losses, per case) to stdout. The
numbers are deterministic: every random sample is seeded from the case,
setting and variant, and nothing depends on ``--jobs`` or on the order in
which cases finish. Wall times go to stderr (and to the CSV with
``--timings``), never to the markdown.

To add a variant, add an entry to :data:`VARIANTS` (keyword arguments of
:func:`~slicerecon.reconstruct.reconstruct`) and pass its name to ``--variants``.
Tune only on ``--half dev``; ``val`` is for confirming a change once.
"""

from __future__ import annotations

import argparse
import csv
import io
import logging
import multiprocessing
import os
import shlex
import sys
import time
import tomllib
import zlib
from collections.abc import Iterable
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))  # independent_eval, as a script or not

from independent_eval import Truth, score_mesh  # noqa: E402

from slicerecon.errors import DependencyError, SlicereconError  # noqa: E402
from slicerecon.reconstruct import PLAIN_SDF  # noqa: E402
from slicerecon.sections import Volume  # noqa: E402

SPLIT_FILE = Path(__file__).resolve().with_name("real_split.toml")
"""The committed development / validation split (``benchmarks/draw_real_split.py``)."""

VARIANTS: dict[str, dict[str, Any]] = {
    "sdf-plain": PLAIN_SDF.to_dict(),
    "default": {},
    "loft-heuristic": {"method": "loft", "planner": "heuristic"},
    "itk-mci": {"method": "itk-mci", "planner": "none"},
    "sdf-hull": {"method": "sdf-hull", "planner": "none"},
    "sdf-heuristic": {"method": "sdf", "planner": "heuristic"},
    "hybrid-none": {"method": "hybrid", "planner": "none", "carve": False},
    "sdf-pchip-none": {"method": "sdf", "planner": "none", "interpolation": "pchip"},
    "hybrid-linear-heuristic": {
        "method": "hybrid",
        "planner": "heuristic",
        "interpolation": "linear",
    },
    "sdf-carve-only": {"method": "sdf", "planner": "heuristic", "cover": False},
    "sdf-cover-none": {"method": "sdf", "planner": "none"},
    "sdf-no-drift": {"join_drift": False},
    "sdf-policy": {"planner": "policy"},
    "lookahead": {"planner": "lookahead"},
}
"""Variant name → keyword arguments of :func:`slicerecon.reconstruct.reconstruct`.

``default`` passes nothing, so it is whatever the library's defaults are when
the benchmark runs (at the time of writing: heuristic planner, sdf surface
with PCHIP interpolation across planes, carved by the visual hull).
``hybrid-linear-heuristic`` is the default before that change."""

VARIANT_NOTES: dict[str, str] = {
    "sdf-plain": "signed-distance interpolation between the planes, one part, not carved: "
    "the baseline",
    "default": "library defaults of `reconstruct()`",
    "loft-heuristic": "contour lofting with the heuristic planner, carved (the paper's method)",
    "itk-mci": "ITK morphological contour interpolation (whole shape)",
    "sdf-hull": "signed-distance interpolation intersected with the visual hull (whole shape)",
    "sdf-heuristic": "signed-distance interpolation per part of the heuristic plan, carved",
    "hybrid-none": "hybrid surface, one part, not carved",
    "sdf-pchip-none": "signed-distance interpolation, PCHIP across planes, one part, carved",
    "hybrid-linear-heuristic": "the default until 2026-11-29: hybrid surface, linear, heuristic "
    "planner, carved",
    "sdf-carve-only": "the default until 2026-12-01: sdf, PCHIP, heuristic planner, carved but "
    "not covering the silhouettes",
    "sdf-cover-none": "sdf, PCHIP, carved and covering, one part (no planner)",
    "sdf-no-drift": "the default until 2026-12-02: as the default, but regions that overlap "
    "nothing on the next plane are not joined",
    "sdf-policy": "the default surface with the learned planner (the shipped `il_rl` actor)",
}

DEFAULT_VARIANTS = ("sdf-plain", "default", "loft-heuristic", "itk-mci")
BASELINE = "sdf-plain"
MARGIN = 0.005
"""A win (loss) is a volume IoU better (worse) than the baseline's by more than this."""

MESH_LOADERS = ("pymeshlab_mesh", "fsaverage5_surface", "mne_fsaverage_surface")
"""Loaders of :mod:`slicerecon.realshapes` that voxelize a mesh (they take ``mesh_resolution``)."""

FIELDS = (
    "half",
    "stratum",
    "case",
    "axis",
    "planes",
    "variant",
    "volume_iou",
    "chamfer_l1_mm",
    "hd95_mm",
    "d_iou",
    "d_chamfer_mm",
    "d_hd95_mm",
    "vs_baseline",
    "watertight",
    "volume_ratio",
    "parts",
    "grid",
    "spacing_mm",
    "error",
)

log = logging.getLogger("real_anatomy")


# -- the protocol -------------------------------------------------------------------
def load_split(path: Path = SPLIT_FILE) -> tuple[dict[str, Any], dict[str, dict[str, str]]]:
    """The protocol settings and the cases (name → ``half``, ``stratum``, ``group``)."""
    with open(path, "rb") as fh:
        data = tomllib.load(fh)
    return data["protocol"], data["cases"]


def load_case(name: str, protocol: dict[str, Any]) -> Volume:
    """A case's ground-truth mask, normalised as the protocol says."""
    from slicerecon.realshapes import REAL_SHAPES, normalise, real_shape

    loader = getattr(REAL_SHAPES[name], "func", None)
    options = {}
    if getattr(loader, "__name__", "") in MESH_LOADERS:
        options["resolution"] = int(protocol["mesh_resolution"])
    return normalise(
        real_shape(name, **options),
        min_extent=int(protocol["min_extent"]),
        max_extent=int(protocol["max_extent"]),
    )


def _seed(*parts: object) -> int:
    """A stable seed from the parts' text (same on every machine and run)."""
    return zlib.crc32("|".join(str(p) for p in parts).encode())


# -- one case (runs in a worker process) --------------------------------------------
_WARM: set[str] = set()


def _warm_up(variants: Iterable[str], specs: dict[str, dict[str, Any]] | None = None) -> None:
    """Run each variant once on a tiny ball so first-call costs (ITK) are not timed."""
    from slicerecon.reconstruct import prepare_inputs, reconstruct
    from slicerecon.shapes import sphere

    specs = VARIANTS if specs is None else specs
    sections, projections, _ = prepare_inputs(sphere(8.0), slices=5, projections="gt")
    for name in variants:
        if name not in _WARM:
            reconstruct(sections, projections, **specs[name])
            _WARM.add(name)


def run_case(
    name: str,
    info: dict[str, str],
    protocol: dict[str, Any],
    axes: list[str],
    planes: list[int],
    variants: list[str],
    specs: dict[str, dict[str, Any]] | None = None,
) -> list[dict[str, Any]]:
    """Every (axis, planes, variant) row of one case.

    ``specs`` maps variant names to their ``reconstruct()`` arguments (default
    :data:`VARIANTS`; passed explicitly to worker processes, which are spawned).
    """
    from slicerecon.reconstruct import prepare_inputs, reconstruct

    specs = VARIANTS if specs is None else specs
    logging.getLogger("slicerecon").setLevel(logging.ERROR)
    _warm_up(variants, specs)
    volume = load_case(name, protocol)
    base = {"half": info["half"], "stratum": info["stratum"], "case": name}
    rows: list[dict[str, Any]] = []
    truths: dict[tuple[tuple[int, ...], bytes], Truth] = {}
    for axis in axes:
        for n in planes:
            try:
                sections, projections, truth = prepare_inputs(
                    volume, slices=n, axis=axis, projections="gt"
                )
            except SlicereconError as exc:
                rows += [
                    {**base, "axis": axis, "planes": n, "variant": v, "error": str(exc)}
                    for v in variants
                ]
                continue
            assert truth is not None
            key = (truth.shape, truth.affine.tobytes())
            if key not in truths:
                truths[key] = Truth(truth.mask, truth.affine, seed=_seed(protocol["seed"], name))
            reference = truths[key]
            for variant in variants:
                row: dict[str, Any] = {
                    **base,
                    "axis": axis,
                    "planes": sections.n_planes,
                    "variant": variant,
                    "grid": "x".join(str(s) for s in truth.shape),
                    "spacing_mm": "x".join(f"{s:.3g}" for s in truth.spacing),
                }
                start = time.perf_counter()
                try:
                    result = reconstruct(sections, projections, **specs[variant])
                except SlicereconError as exc:
                    row.update(seconds=time.perf_counter() - start, error=str(exc))
                    rows.append(row)
                    continue
                row["seconds"] = time.perf_counter() - start
                scores = score_mesh(
                    np.asarray(result.mesh.vertices),
                    np.asarray(result.mesh.faces),
                    reference,
                    seed=_seed(protocol["seed"], name, axis, n, variant),
                )
                row.update(
                    volume_iou=scores.volume_iou,
                    chamfer_l1_mm=scores.chamfer_l1_mm,
                    hd95_mm=scores.hd95_mm,
                    watertight=scores.watertight,
                    volume_ratio=scores.volume_ratio,
                    parts=len(result.plan.parts),
                    error="",
                )
                rows.append(row)
    return rows


# -- report -------------------------------------------------------------------------
def _compare(rows: list[dict[str, Any]]) -> None:
    """Fill the differences to the baseline and the win / tie / loss of every row."""
    base = {
        (r["case"], r["axis"], r["planes"]): r
        for r in rows
        if r["variant"] == BASELINE and not r.get("error")
    }
    for r in rows:
        b = base.get((r["case"], r["axis"], r["planes"]))
        if r["variant"] == BASELINE or b is None:
            continue
        if r.get("error"):
            r["vs_baseline"] = "loss"
            continue
        r["d_iou"] = r["volume_iou"] - b["volume_iou"]
        r["d_chamfer_mm"] = r["chamfer_l1_mm"] - b["chamfer_l1_mm"]
        r["d_hd95_mm"] = r["hd95_mm"] - b["hd95_mm"]
        r["vs_baseline"] = (
            "win" if r["d_iou"] > MARGIN else "loss" if r["d_iou"] < -MARGIN else "tie"
        )


def _fmt(value: object, digits: int = 3, signed: bool = False) -> str:
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float | np.floating):
        return f"{value:+.{digits}f}" if signed else f"{value:.{digits}f}"
    return "" if value is None else str(value)


def _settings(rows: list[dict[str, Any]]) -> list[tuple[str, str, int]]:
    seen: dict[tuple[str, str, int], None] = {}
    for r in rows:
        seen.setdefault((r["half"], r["axis"], int(r["planes"])), None)
    order = {"dev": 0, "val": 1}
    return sorted(seen, key=lambda s: (order.get(s[0], 2), s[1], s[2]))


def _common_cases(group: list[dict[str, Any]], variants: list[str]) -> set[str]:
    """Cases of a setting on which every variant produced a mesh."""
    ok: dict[str, set[str]] = {}
    for r in group:
        if not r.get("error"):
            ok.setdefault(r["case"], set()).add(r["variant"])
    return {case for case, have in ok.items() if have >= set(variants)}


def _mean(rows: list[dict[str, Any]], key: str) -> float:
    vals = [float(r[key]) for r in rows if r.get(key) not in (None, "")]
    return float(np.mean(vals)) if vals else float("nan")


def _summary_lines(rows: list[dict[str, Any]], variants: list[str]) -> list[str]:
    out = [
        "Means are over the cases on which every variant produced a mesh (`cases`); a "
        "variant's errors count as losses.",
        "",
        "| half | axis | planes | variant | cases | mean IoU | mean ΔIoU | wins / ties / losses "
        "| mean Chamfer-L1 mm | mean HD95 mm | watertight | errors |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for half, axis, n in _settings(rows):
        group = [r for r in rows if (r["half"], r["axis"], int(r["planes"])) == (half, axis, n)]
        common = _common_cases(group, variants)
        for variant in variants:
            mine = [r for r in group if r["variant"] == variant]
            if not mine:
                continue
            ok = [r for r in mine if r["case"] in common]
            errors = sum(bool(r.get("error")) for r in mine)
            if variant == BASELINE:
                record, d_iou = "—", "—"
            else:
                count = {
                    k: sum(r.get("vs_baseline") == k for r in mine) for k in ("win", "tie", "loss")
                }
                record = f"{count['win']} / {count['tie']} / {count['loss']}"
                d_iou = _fmt(_mean(ok, "d_iou"), signed=True)
            tight = sum(bool(r.get("watertight")) for r in mine if not r.get("error"))
            out.append(
                f"| {half} | {axis} | {n} | {variant} | {len(ok)} | "
                f"{_fmt(_mean(ok, 'volume_iou'))} | {d_iou} | {record} | "
                f"{_fmt(_mean(ok, 'chamfer_l1_mm'))} | {_fmt(_mean(ok, 'hd95_mm'), 2)} | "
                f"{tight}/{len(mine) - errors} | {errors} |"
            )
    return out


def _stratum_lines(rows: list[dict[str, Any]], variants: list[str]) -> list[str]:
    others = [v for v in variants if v != BASELINE]
    out = [
        "| half | axis | planes | stratum | cases | "
        + " | ".join(f"`{v}` ΔIoU" for v in others)
        + " |",
        "|---|---|---|---|---|" + "---|" * len(others),
    ]
    for half, axis, n in _settings(rows):
        group = [r for r in rows if (r["half"], r["axis"], int(r["planes"])) == (half, axis, n)]
        common = _common_cases(group, variants)
        for stratum in sorted({r["stratum"] for r in group}):
            mine = [r for r in group if r["stratum"] == stratum and r["case"] in common]
            cases = {r["case"] for r in mine}
            cells = [
                _fmt(_mean([r for r in mine if r["variant"] == v], "d_iou"), signed=True)
                for v in others
            ]
            out.append(
                f"| {half} | {axis} | {n} | {stratum} | {len(cases)} | " + " | ".join(cells) + " |"
            )
    return out


def _worst_lines(rows: list[dict[str, Any]], variants: list[str], k: int = 5) -> list[str]:
    out: list[str] = []
    for half, axis, n in _settings(rows):
        for variant in variants:
            if variant == BASELINE:
                continue
            mine = [
                r
                for r in rows
                if (r["half"], r["axis"], int(r["planes"]), r["variant"])
                == (half, axis, n, variant)
                and r.get("d_iou") not in (None, "")
            ]
            losses = sorted(
                (r for r in mine if r["vs_baseline"] == "loss"), key=lambda r: r["d_iou"]
            )[:k]
            if losses:
                listed = ", ".join(f"{r['case']} ({r['d_iou']:+.3f})" for r in losses)
                out.append(f"* {half}, {axis}, {n} planes, `{variant}`: {listed}")
    return out or ["* none"]


def _case_tables(rows: list[dict[str, Any]], variants: list[str]) -> list[str]:
    out: list[str] = []
    others = [v for v in variants if v != BASELINE]
    for half, axis, n in _settings(rows):
        group = [r for r in rows if (r["half"], r["axis"], int(r["planes"])) == (half, axis, n)]
        by_case: dict[str, dict[str, dict[str, Any]]] = {}
        for r in group:
            by_case.setdefault(r["case"], {})[r["variant"]] = r
        cases = sorted(by_case, key=lambda c: (next(iter(by_case[c].values()))["stratum"], c))
        out += [
            "",
            f"### {half}: {n} planes along {axis}",
            "",
            "Volume IoU (Δ to `sdf-plain`; a win/loss beyond ±0.005 is marked ▲/▼):",
            "",
            "| case | stratum | grid | " + " | ".join(variants) + " |",
            "|---|---|---|" + "---|" * len(variants),
        ]
        for case in cases:
            cells = []
            for v in variants:
                r = by_case[case].get(v)
                if r is None:
                    cells.append("")
                elif r.get("error"):
                    cells.append("error")
                elif v == BASELINE or r.get("d_iou") in (None, ""):
                    cells.append(_fmt(r["volume_iou"]))
                else:
                    mark = {"win": " ▲", "loss": " ▼"}.get(r["vs_baseline"], "")
                    cells.append(f"{r['volume_iou']:.3f} ({r['d_iou']:+.3f}){mark}")
            first = next(iter(by_case[case].values()))
            out.append(
                f"| {case} | {first['stratum']} | {first.get('grid', '')} | "
                + " | ".join(cells)
                + " |"
            )
        out += [
            "",
            "Chamfer-L1 / HD95, mm (watertight unless marked *open*):",
            "",
            "| case | " + " | ".join(variants) + " |",
            "|---|" + "---|" * len(variants),
        ]
        for case in cases:
            cells = []
            for v in variants:
                r = by_case[case].get(v)
                if r is None:
                    cells.append("")
                elif r.get("error"):
                    cells.append(f"error: {r['error']}")
                else:
                    open_ = "" if r["watertight"] else " *open*"
                    cells.append(f"{r['chamfer_l1_mm']:.3f} / {r['hd95_mm']:.2f}{open_}")
            out.append(f"| {case} | " + " | ".join(cells) + " |")
        if others:
            out.append("")
    return out


def write_report(
    out: Path,
    rows: list[dict[str, Any]],
    command: str,
    variants: list[str],
    skipped: dict[str, str],
    timings: bool,
    library: str = "",
) -> None:
    """Write the CSV ``out`` (suffix ``.csv``) and print the markdown report."""
    csv_path = out.with_suffix(".csv")
    fields = list(FIELDS) + (["seconds"] if timings else [])
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=fields, lineterminator="\n")
    writer.writeheader()
    for r in rows:
        writer.writerow(
            {
                k: _fmt(r.get(k), 6)
                if isinstance(r.get(k), float)
                else ("" if r.get(k) is None else r.get(k))
                for k in fields
            }
        )
    _write_atomic(csv_path, buffer.getvalue())

    legend = [f"| `{v}` | {_kwargs(v)} | {VARIANT_NOTES.get(v, '')} |" for v in variants]
    lines = [
        "# Real-anatomy protocol: results",
        "",
        f"Command: `{command}`",
        "",
        *([f"Library: {library}.", ""] if library else []),
        "Written by `benchmarks/real_anatomy.py`; raw numbers in "
        f"`{csv_path.as_posix()}`. Cases, halves and grid normalisation: "
        "`benchmarks/real_split.toml` and `docs/realshapes.md`. Each case is sampled at N "
        "evenly spaced planes along the axis (`prepare_inputs`, projections from the dense "
        "mask) and reconstructed by every variant from exactly these inputs. Scores come "
        "from `benchmarks/independent_eval.py`, not `slicerecon.metrics`: volume IoU of "
        "the mesh rasterized on the ground-truth grid, Chamfer-L1 (mean of the two "
        "directed mean distances) and HD95 (larger directed 95th percentile) between the "
        "mesh and the marching-cubes boundary of the mask, in mm. All samples are seeded: a "
        "rerun gives the same numbers. "
        f"A win / loss is a volume IoU above / below `{BASELINE}`'s by more than {MARGIN}.",
        "",
        "| variant | `reconstruct()` arguments | what it is |",
        "|---|---|---|",
        *legend,
    ]
    if skipped:
        lines += ["", *[f"Variant `{v}` was skipped: {why}" for v, why in skipped.items()]]
    lines += ["", "## Summary (means over the cases of each half)", ""]
    lines += _summary_lines(rows, variants)
    lines += ["", "Mean ΔIoU to `sdf-plain` by source stratum:", ""]
    lines += _stratum_lines(rows, variants)
    lines += ["", "Losses against `sdf-plain` (largest first):", ""]
    lines += _worst_lines(rows, variants)
    lines += ["", "## Per case"]
    lines += _case_tables(rows, variants)
    print("\n".join(lines).rstrip())


def library_state() -> str:
    """Which slicerecon the numbers are for: its git commit, and any uncommitted library files."""
    import subprocess

    import slicerecon

    root = Path(slicerecon.__file__).resolve().parent.parent
    try:
        commit = subprocess.run(
            ["git", "-C", str(root), "rev-parse", "--short=12", "HEAD"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "-C", str(root), "status", "--porcelain", "--", "slicerecon"],
            capture_output=True,
            text=True,
            check=True,
        ).stdout.split("\n")
    except (OSError, subprocess.CalledProcessError):
        return f"slicerecon {getattr(slicerecon, '__version__', '?')} (not a git checkout)"
    changed = sorted(line[3:] for line in dirty if line.strip())
    state = f"with uncommitted changes to {', '.join(changed)}" if changed else "clean"
    return f"slicerecon at commit `{commit}` ({state})"


def _kwargs(variant: str) -> str:
    kw = VARIANTS[variant]
    return ", ".join(f"`{k}={v!r}`" for k, v in kw.items()) or "(none: library defaults)"


def _write_atomic(path: Path, text: str) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp{os.getpid()}")
    tmp.write_text(text)
    tmp.replace(path)


# -- command line -------------------------------------------------------------------
def _available(variants: list[str]) -> tuple[list[str], dict[str, str]]:
    kept, skipped = [], {}
    for name in variants:
        try:
            _warm_up([name])
        except DependencyError as exc:
            skipped[name] = str(exc)
            continue
        kept.append(name)
    return kept, skipped


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--half", choices=("dev", "val", "both"), default="dev")
    parser.add_argument("--planes", default="12", help="comma-separated plane counts")
    parser.add_argument("--axes", default="x,y,z", help="comma-separated section axes")
    parser.add_argument(
        "--variants",
        default=",".join(DEFAULT_VARIANTS),
        help=f"comma-separated, from: {', '.join(VARIANTS)}; {BASELINE} is always added",
    )
    parser.add_argument(
        "--cases", default="", help="comma-separated subset of the half's cases (default: all)"
    )
    parser.add_argument("--split", type=Path, default=SPLIT_FILE)
    parser.add_argument("--jobs", type=int, default=1, help="worker processes (cases in parallel)")
    parser.add_argument(
        "--timings", action="store_true", help="add a seconds column to the CSV (not reproducible)"
    )
    parser.add_argument(
        "--policy-weights",
        default="",
        help="comma-separated actor files (.safetensors): each adds a variant "
        "policy-<file stem>, the default surface planned by that actor",
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=Path("docs/data/real_anatomy.csv"),
        help="CSV of every number (the markdown report goes to stdout)",
    )
    args = parser.parse_args(argv)
    for item in (w.strip() for w in args.policy_weights.split(",") if w.strip()):
        path = Path(item)
        if not path.is_file():
            parser.error(f"--policy-weights: no such file {item}")
        VARIANTS[f"policy-{path.stem}"] = {"planner": "policy", "weights": str(path.resolve())}
        VARIANT_NOTES[f"policy-{path.stem}"] = f"the default surface planned by the actor `{item}`"
    logging.basicConfig(level=logging.INFO, format="%(message)s", stream=sys.stderr)
    logging.getLogger("slicerecon").setLevel(logging.ERROR)

    protocol, cases = load_split(args.split)
    halves = ("dev", "val") if args.half == "both" else (args.half,)
    wanted = [v.strip() for v in args.variants.split(",") if v.strip()]
    wanted += [v for v in VARIANTS if v.startswith("policy-") and v not in wanted]
    unknown = [v for v in wanted if v not in VARIANTS]
    if unknown:
        parser.error(f"unknown variants {unknown}; choose from {list(VARIANTS)}")
    variants = [BASELINE] + [v for v in wanted if v != BASELINE]
    axes = [a.strip() for a in args.axes.split(",") if a.strip()]
    if any(a not in ("x", "y", "z") for a in axes):
        parser.error(f"--axes takes x, y and z (got {args.axes!r})")
    planes = [int(n) for n in args.planes.split(",") if n.strip()]
    if any(n < 2 for n in planes):
        parser.error("--planes must be at least 2")
    names = [n for n in cases if cases[n]["half"] in halves]
    if args.cases:
        subset = [c.strip() for c in args.cases.split(",") if c.strip()]
        missing = [c for c in subset if c not in names]
        if missing:
            parser.error(f"cases not in the chosen half: {missing}")
        names = subset
    from slicerecon.realshapes import available_real_shapes

    present = set(available_real_shapes())
    absent = [n for n in names if n not in present]
    for n in absent:
        log.warning("skipping %s: its source package is not installed (docs/realshapes.md)", n)
    names = sorted(
        (n for n in names if n in present), key=lambda n: (cases[n]["half"], cases[n]["stratum"], n)
    )

    variants, skipped = _available(variants)
    if BASELINE not in variants:
        parser.error(f"the baseline {BASELINE} cannot run: {skipped.get(BASELINE)}")
    for v, why in skipped.items():
        log.warning("skipping variant %s: %s", v, why)

    start = time.perf_counter()
    rows: list[dict[str, Any]] = []
    done = 0

    def report(case_rows: list[dict[str, Any]]) -> None:
        nonlocal done
        done += 1
        for r in case_rows:
            text = (
                (
                    f"IoU {r['volume_iou']:.3f} CD {r['chamfer_l1_mm']:.3f} "
                    f"HD95 {r['hd95_mm']:.2f} {r['seconds']:.1f}s"
                )
                if not r.get("error")
                else f"ERROR {r['error']}"
            )
            log.info(
                "[%d/%d %5.0fs] %-4s %-26s %s %2s %-15s %s",
                done,
                len(names),
                time.perf_counter() - start,
                r["half"],
                r["case"],
                r["axis"],
                r["planes"],
                r["variant"],
                text,
            )
        rows.extend(case_rows)

    specs = {v: VARIANTS[v] for v in variants}
    task_args = [(n, cases[n], protocol, axes, planes, variants, specs) for n in names]
    if args.jobs > 1:
        # spawned, not forked: the parent has run torch (the policy variants' warm-up)
        spawn = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(max_workers=args.jobs, mp_context=spawn) as pool:
            futures = [pool.submit(run_case, *a) for a in task_args]
            for future in as_completed(futures):
                report(future.result())
    else:
        for a in task_args:
            report(run_case(*a))
    order = {n: i for i, n in enumerate(names)}
    rank = {v: i for i, v in enumerate(variants)}
    rows.sort(key=lambda r: (order[r["case"]], r["axis"], int(r["planes"]), rank[r["variant"]]))
    _compare(rows)
    command = shlex.join(
        ["python", "benchmarks/real_anatomy.py", *(sys.argv[1:] if argv is None else argv)]
    )
    write_report(args.out, rows, command, variants, skipped, args.timings, library_state())
    total = time.perf_counter() - start
    for v in variants:
        secs = [r["seconds"] for r in rows if r["variant"] == v and "seconds" in r]
        log.info("%-15s reconstruct() total %.0f s over %d runs", v, sum(secs), len(secs))
    log.info(
        "wrote %s in %.0f s (%d cases, %d jobs)",
        args.out.with_suffix(".csv"),
        total,
        len(names),
        args.jobs,
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
