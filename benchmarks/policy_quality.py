"""Learned planners against the heuristic on held-out procedural shapes (paper Table 2).

For every shape family (``slicerecon.shapes.shape_names()``) and held-out seed
(``HOLDOUT_SEED`` + i: never used by training, whose seeds are < 10 000, nor by
its evaluation, 10 000 + i) the dense shape is sampled at ``--slices`` planes
with its ground-truth projections, reconstructed with ``reconstruct()`` and
each planner (``none``, ``heuristic`` and the three shipped actors ``ddpg``,
``il``, ``il_rl`` through ``planner="policy"`` + ``weights=``) and scored with
``evaluate()`` (volume IoU, Chamfer-L1 in mm). A second sweep varies the
number of contours on a subset of families. Writes every case to the JSON
``--out``, two figures into ``--figures`` (IoU against the number of contours,
and the training curves: held-out surrogate IoU against update, from the
training logs) and prints the markdown tables that ``docs/results.md`` shows.

    python benchmarks/policy_quality.py --seeds 3 --voxels 44 --slices 12 --contours 6,12,20 \\
        --out docs/data/policy_quality.json
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

HOLDOUT_SEED = 20_000
PLANNERS = ("none", "heuristic", "lookahead", "ddpg", "il", "il_rl")
LEARNED = ("ddpg", "il", "il_rl")
WEIGHTS_DIR = Path(__file__).resolve().parents[1] / "slicerecon" / "policy" / "weights"


def make_volume(name: str, seed: int, voxels: int) -> Any:
    """The shape with its longest side about ``voxels`` voxels."""
    from slicerecon.shapes import make_shape

    coarse = make_shape(name, seed=seed, spacing=2.0, margin=0)
    lo, hi = coarse.bounding_box_vox()
    extent = float(np.max((hi - lo) * coarse.spacing))
    return make_shape(name, seed=seed, spacing=extent / voxels)


def run_case(task: tuple[str, int, int, int, str]) -> dict[str, Any]:
    """Reconstruct and score one (family, seed, slices, planner)."""
    import torch

    torch.set_num_threads(1)
    from slicerecon.errors import SlicereconError
    from slicerecon.metrics import evaluate
    from slicerecon.reconstruct import prepare_inputs, reconstruct

    name, seed, voxels, slices, planner, weights_dir = task
    row: dict[str, Any] = {"family": name, "seed": seed, "slices": slices, "planner": planner}
    try:
        volume = make_volume(name, seed, voxels)
        # flat shapes have few z planes: keep at most as many as they occupy
        available = int(volume.occupied_planes(2).size)
        sections, projections, truth = prepare_inputs(volume, slices=min(slices, available))
        row["slices"] = sections.n_planes
        kwargs: dict[str, Any] = {"planner": planner}
        if planner in LEARNED:
            kwargs = {"planner": "policy", "weights": Path(weights_dir) / f"{planner}.safetensors"}
        start = time.perf_counter()
        result = reconstruct(sections, projections, **kwargs)
        row["seconds"] = time.perf_counter() - start
        metrics = evaluate(result.mesh, truth, n_points=20_000, seed=0)
        row.update(
            volume_iou=metrics.volume_iou,
            chamfer_mm=metrics.chamfer_l1_mm,
            parts=len(result.plan.parts),
        )
    except SlicereconError as exc:
        row["error"] = f"{type(exc).__name__}: {exc}"
    return row


def _mean(values: list[float]) -> float:
    vals = [v for v in values if v is not None and not math.isnan(v)]
    return float(np.mean(vals)) if vals else float("nan")


def _fmt(v: float, digits: int = 3) -> str:
    return "—" if math.isnan(v) else f"{v:.{digits}f}"


def table(rows: list[dict[str, Any]], families: list[str]) -> list[str]:
    lines = [
        "| family | "
        + " | ".join(f"{p} IoU" for p in PLANNERS)
        + " | "
        + " | ".join(f"{p} CD" for p in PLANNERS)
        + " |",
        "|---|" + "---:|" * (2 * len(PLANNERS)),
    ]
    for fam in [*families, "**mean**"]:
        sel = rows if fam == "**mean**" else [r for r in rows if r["family"] == fam]
        ious = [
            _mean([r.get("volume_iou", math.nan) for r in sel if r["planner"] == p])
            for p in PLANNERS
        ]
        cds = [
            _mean([r.get("chamfer_mm", math.nan) for r in sel if r["planner"] == p])
            for p in PLANNERS
        ]
        lines.append(
            f"| {fam} | "
            + " | ".join(_fmt(v) for v in ious)
            + " | "
            + " | ".join(_fmt(v, 2) for v in cds)
            + " |"
        )
    return lines


def paired(rows: list[dict[str, Any]], planner: str) -> tuple[int, int, int, float]:
    """Wins / ties / losses of ``planner`` against the heuristic (IoU, per shape)."""
    by_key: dict[tuple[str, int], dict[str, float]] = {}
    for r in rows:
        if "volume_iou" in r:
            by_key.setdefault((r["family"], r["seed"]), {})[r["planner"]] = r["volume_iou"]
    wins = ties = losses = 0
    diffs = []
    for vals in by_key.values():
        if planner in vals and "heuristic" in vals:
            d = vals[planner] - vals["heuristic"]
            diffs.append(d)
            wins += d > 1e-3
            losses += d < -1e-3
            ties += abs(d) <= 1e-3
    return wins, ties, losses, _mean(diffs)


def figure_contours(rows: list[dict[str, Any]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 3.8))
    for p in PLANNERS:
        counts = sorted({r["slices"] for r in rows if r["planner"] == p})
        means = [
            _mean(
                [
                    r.get("volume_iou", math.nan)
                    for r in rows
                    if r["planner"] == p and r["slices"] == c
                ]
            )
            for c in counts
        ]
        ax.plot(counts, means, marker="o", label=p)
    ax.set_xlabel("number of contours (planes)")
    ax.set_ylabel("mean volume IoU")
    ax.set_title("IoU against number of contours (held-out shapes)")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def figure_training(logs: dict[str, Path], heuristic: float | None, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5.5, 3.8))
    for name, log in logs.items():
        with open(log, newline="") as fh:
            pts = [
                (int(r["update"]), float(r["eval_iou"]))
                for r in csv.DictReader(fh)
                if r.get("eval_iou")
            ]
        if pts:
            ax.plot(*zip(*pts, strict=True), marker=".", label=name)
    if heuristic is not None:
        ax.axhline(heuristic, color="k", linestyle="--", label="heuristic")
    ax.set_xlabel("training update")
    ax.set_ylabel("surrogate IoU (eval shapes)")
    ax.set_title("IoU against training iteration")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--out",
        type=Path,
        default=Path("docs/data/policy_quality.json"),
        help="JSON of every case (the markdown tables go to stdout)",
    )
    parser.add_argument("--figures", type=Path, default=Path("docs/figures"))
    parser.add_argument("--seeds", type=int, default=1, help="held-out seeds per family")
    parser.add_argument("--voxels", type=int, default=44, help="longest side of a shape")
    parser.add_argument("--slices", type=int, default=12)
    parser.add_argument("--contours", default="6,12,20")
    parser.add_argument(
        "--contour-families",
        default="",
        help="default: every family with enough z planes for all counts",
    )
    parser.add_argument("--families", default="", help="comma-separated (default: all)")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument(
        "--weights-dir",
        type=Path,
        default=WEIGHTS_DIR,
        help="folder of ddpg / il / il_rl .safetensors (default: the shipped actors)",
    )
    args = parser.parse_args()

    from slicerecon.io.atomic import atomic_path
    from slicerecon.shapes import shape_names

    families = [f for f in args.families.split(",") if f] or shape_names()
    tasks = [
        (f, HOLDOUT_SEED + i, args.voxels, args.slices, p, str(args.weights_dir))
        for f in families
        for i in range(args.seeds)
        for p in PLANNERS
    ]
    counts = [int(c) for c in args.contours.split(",")]
    sweep_fams = [f for f in args.contour_families.split(",") if f in families] or [
        f
        for f in families
        if make_volume(f, HOLDOUT_SEED, args.voxels).occupied_planes(2).size >= max(counts)
    ]
    sweep = [
        (f, HOLDOUT_SEED, args.voxels, c, p, str(args.weights_dir))
        for f in sweep_fams
        for c in counts
        if c != args.slices
        for p in PLANNERS
    ]
    start = time.perf_counter()
    with ProcessPoolExecutor(max_workers=args.workers) as pool:
        rows = list(pool.map(run_case, tasks))
        sweep_rows = list(pool.map(run_case, sweep))
    elapsed = time.perf_counter() - start
    raw = args.out.with_suffix(".json")
    with atomic_path(raw) as tmp:
        tmp.write_text(json.dumps({"main": rows, "contours": sweep_rows}, indent=1) + "\n")

    weights = args.weights_dir
    manifest_path = weights / "manifest.json"
    manifest = json.loads(manifest_path.read_text()) if manifest_path.is_file() else {}
    if "heuristic_eval_iou" not in manifest:  # each actor file records it too
        from slicerecon.policy.weights import load_actor

        for name in LEARNED:
            if (weights / f"{name}.safetensors").is_file():
                meta = load_actor(weights / f"{name}.safetensors")[1]
                if "heuristic_eval_iou" in meta:
                    manifest["heuristic_eval_iou"] = meta["heuristic_eval_iou"]
                    break
    args.figures.mkdir(parents=True, exist_ok=True)
    fig1 = args.figures / "policy_iou_vs_contours.png"
    sweep_all = sweep_rows + [
        r for r in rows if r["family"] in sweep_fams and r["seed"] == HOLDOUT_SEED
    ]
    figure_contours(sweep_all, fig1)
    fig2 = args.figures / "policy_iou_vs_training.png"
    logs = {n: weights / f"{n}_log.csv" for n in LEARNED if (weights / f"{n}_log.csv").is_file()}
    figure_training(logs, manifest.get("heuristic_eval_iou"), fig2)

    errors = [r for r in rows + sweep_rows if "error" in r]
    shipped = weights.resolve() == Path(WEIGHTS_DIR).resolve()
    dir_option = "" if shipped else f" --weights-dir {weights}"
    whose = (
        "the shipped actors (`slicerecon/policy/weights/`, see its README)"
        if shipped
        else f"the actors in `{weights}` (`ddpg`, `il`, `il_rl` are file names there, "
        "not how each actor was trained)"
    )
    lines = [
        "# Learned planner against the heuristic (held-out shapes)",
        "",
        f"`python benchmarks/policy_quality.py --seeds {args.seeds} --voxels {args.voxels} "
        f"--slices {args.slices} --contours {args.contours}{dir_option}` "
        f"({elapsed / 60:.1f} min, "
        f"{args.workers} workers).",
        "",
        f"{len(families)} families x {args.seeds} held-out seed(s) (seeds {HOLDOUT_SEED}+, "
        "never seen in training or its evaluation), longest side "
        f"{args.voxels} voxels, {args.slices} planes along z (fewer for flat shapes: as many "
        "as they occupy), ground-truth projections, "
        "the default surface (`sdf` with PCHIP, carved and covering the silhouettes); "
        "`reconstruct()` + `evaluate()` "
        f"(20 000 surface samples). The learned planners are {whose}.",
        "",
        "## Volume IoU and Chamfer-L1 (mm) per family",
        "",
        *table(rows, families),
        "",
        "## Paired against the heuristic (volume IoU per shape, |difference| <= 0.001 a tie)",
        "",
        "| planner | wins | ties | losses | failed | mean IoU difference |",
        "|---|---:|---:|---:|---:|---:|",
    ]
    for p in (q for q in PLANNERS if q != "heuristic"):
        w, t, lo, d = paired(rows, p)
        failed = sum(1 for r in rows if r["planner"] == p and "error" in r)
        lines.append(f"| {p} | {w} | {t} | {lo} | {failed} | {d:+.4f} |")
    lines += [
        "",
        "Failed: the case raised an error (listed at the end); it is left out of the means",
        "and of wins / ties / losses.",
    ]
    parts = {
        p: _mean([r.get("parts", math.nan) for r in rows if r["planner"] == p]) for p in PLANNERS
    }
    secs = {
        p: _mean([r.get("seconds", math.nan) for r in rows if r["planner"] == p]) for p in PLANNERS
    }
    lines += [
        "",
        "| planner | mean parts | mean reconstruct s |",
        "|---|---:|---:|",
        *[f"| {p} | {parts[p]:.2f} | {secs[p]:.2f} |" for p in PLANNERS],
        "",
        f"## IoU against number of contours ({', '.join(sweep_fams)}; seed {HOLDOUT_SEED})",
        "",
        f"![IoU vs contours](figures/{fig1.name})",
        "",
        "| planes | " + " | ".join(PLANNERS) + " |",
        "|---:|" + "---:|" * len(PLANNERS),
    ]
    for c in sorted({r["slices"] for r in sweep_all}):
        vals = [
            _mean(
                [
                    r.get("volume_iou", math.nan)
                    for r in sweep_all
                    if r["planner"] == p and r["slices"] == c
                ]
            )
            for p in PLANNERS
        ]
        lines.append(f"| {c} | " + " | ".join(_fmt(v) for v in vals) + " |")
    lines += [
        "",
        "## IoU against training iteration",
        "",
        f"![IoU vs training](figures/{fig2.name})",
        "",
        "The curves are the training logs' `eval_iou`: the environment's surrogate IoU",
        "(union of the parts' nearest-plane reconstructions against the shape, on the",
        "training evaluation shapes, seeds 10 000+), with the heuristic's value on the",
        "same shapes dashed. It is a cheap proxy, not the surface IoU of the table above.",
        "",
    ]
    if errors:
        lines += (
            ["## Failed cases", ""]
            + [
                f"- {r['family']} seed {r['seed']} {r['planner']} ({r['slices']} planes): "
                f"{r['error']}"
                for r in errors
            ]
            + [""]
        )
    print("\n".join(lines))


if __name__ == "__main__":
    main()
