"""Does the partition help?  ``heuristic`` planner against ``none`` (one part).

For each shape, section axis and plane count, the script samples the dense
mask, reconstructs with both planners (same sections, same projections, same
surface method) and evaluates against the dense mask.  It prints a markdown
table, the per-setting winner, and the win count (``--out FILE`` also writes
it; ``docs/results.md`` shows it)::

    python benchmarks/planner_quality.py

Nothing here is tuned per shape: every setting uses the library defaults.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from slicerecon.metrics import evaluate
from slicerecon.reconstruct import prepare_inputs, reconstruct
from slicerecon.shapes import make_shape


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--shapes", default="y_branch,chair,torus,two_spheres")
    parser.add_argument("--axes", default="x,y,z")
    parser.add_argument("--slices", default="6,10,16")
    parser.add_argument("--method", default="sdf", help="surface method (default: the library's)")
    parser.add_argument("--no-carve", action="store_true", help="do not carve by the hull")
    parser.add_argument("--n-points", type=int, default=20_000)
    parser.add_argument("--out", type=Path)
    args = parser.parse_args()
    header = (
        f"Command: `python benchmarks/planner_quality.py --shapes {args.shapes} --axes {args.axes} "
        f"--slices {args.slices} --method {args.method}{' --no-carve' if args.no_carve else ''}`. "
        "Volume IoU (higher is better) and "
        "Chamfer-L1 as a fraction of the ground-truth bounding-box diagonal (lower is better), "
        "x1000.\n\n"
        "| shape | axis | planes | IoU none | IoU heuristic | Chamfer none | Chamfer heuristic "
        "| parts | heuristic wins both |\n|---|---|---|---|---|---|---|---|---|"
    )
    rows = [header]
    wins = ties = total = 0
    per_shape: dict[str, list[tuple[float, float, float, float]]] = {}
    start = time.perf_counter()
    for name in args.shapes.split(","):
        volume = make_shape(name)
        for axis in args.axes.split(","):
            for n in (int(s) for s in args.slices.split(",")):
                sections, projections, truth = prepare_inputs(volume, slices=n, axis=axis)
                scores = {}
                parts = 0
                for planner in ("none", "heuristic"):
                    result = reconstruct(
                        sections,
                        projections,
                        planner=planner,
                        method=args.method,
                        carve=not args.no_carve,
                    )
                    scores[planner] = evaluate(result.mesh, truth, n_points=args.n_points, seed=0)
                    parts = len(result.plan.parts)
                none, heur = scores["none"], scores["heuristic"]
                per_shape.setdefault(name, []).append(
                    (none.volume_iou, heur.volume_iou, none.chamfer_l1, heur.chamfer_l1)
                )
                win = heur.volume_iou > none.volume_iou and heur.chamfer_l1 < none.chamfer_l1
                tie = (
                    abs(heur.volume_iou - none.volume_iou) < 1e-4
                    and abs(heur.chamfer_l1 - none.chamfer_l1) < 1e-7
                )
                verdict = "yes" if win else "tie" if tie else "no"
                wins += win
                ties += tie
                total += 1
                rows.append(
                    f"| {name} | {axis} | {sections.n_planes} | {none.volume_iou:.3f} "
                    f"| {heur.volume_iou:.3f} | {1000 * none.chamfer_l1:.2f} "
                    f"| {1000 * heur.chamfer_l1:.2f} | {parts} | {verdict} |"
                )
                print(rows[-1], flush=True)
    rows.append(
        f"\nThe heuristic planner beats `none` on both metrics in {wins} of {total} settings "
        f"and ties (the same single part) in {ties} "
        f"({time.perf_counter() - start:.0f} s on this machine)."
    )
    rows.append(
        "\nPer shape, over its settings: mean volume IoU and mean Chamfer-L1 (x1000), and the "
        "settings the heuristic wins on both metrics.\n\n"
        "| shape | settings | IoU none | IoU heuristic | Chamfer none | Chamfer heuristic "
        "| heuristic wins |\n|---|---|---|---|---|---|---|"
    )
    for name, values in per_shape.items():
        v = np.asarray(values)
        won = int(np.sum((v[:, 1] > v[:, 0]) & (v[:, 3] < v[:, 2])))
        rows.append(
            f"| {name} | {len(v)} | {v[:, 0].mean():.3f} | {v[:, 1].mean():.3f} "
            f"| {1000 * v[:, 2].mean():.2f} | {1000 * v[:, 3].mean():.2f} | {won} of {len(v)} |"
        )
    text = "\n".join(rows) + "\n"
    if args.out:
        args.out.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
