"""What the expert's lookahead gains on real anatomy, scored with and without the shape.

On one half of the real-anatomy split (default: development), every case is
sampled at ``--planes`` planes along z with its ground-truth projections
(as ``benchmarks/real_anatomy.py``), and reconstructed with the default
surface by four planners:

* ``heuristic``: the expert (the default);
* ``lookahead``: the expert checked on held-out planes
  (:func:`slicerecon.partition.lookahead.plan_lookahead`, ``value="planes"``);
* ``lookahead-silhouettes``: the same scored on the silhouettes;
* ``oracle``: the same lookahead scored on the true mask (IoU of the
  partition's part surface with it; margin 0.002): what a value that knew
  the shape would gain, the ceiling of the two above. It cannot run at
  inference.

Meshes are scored by ``benchmarks/independent_eval.py`` (volume IoU), paired
against the heuristic per case, and printed as markdown (``--out FILE`` also
writes it; ``docs/results.md`` shows both halves). Choose on ``--half dev``
only::

    python benchmarks/lookahead_real.py --half dev --planes 12
    python benchmarks/lookahead_real.py --half val --planes 12
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from independent_eval import Truth, score_mesh  # noqa: E402
from real_anatomy import SPLIT_FILE, _seed, load_case, load_split  # noqa: E402

from slicerecon.io.atomic import atomic_path  # noqa: E402
from slicerecon.partition import planner as planner_registry  # noqa: E402
from slicerecon.partition.lookahead import plan_lookahead, run_lookahead  # noqa: E402
from slicerecon.partition.state import Part, PartitionState, iou  # noqa: E402
from slicerecon.reconstruct import prepare_inputs, reconstruct  # noqa: E402

TRUTH: dict[str, np.ndarray] = {}
"""The current case's true mask on the planning grid (the oracle's value reads it)."""

PLANNERS = ("heuristic", "lookahead", "lookahead-silhouettes", "oracle")


def _plan_oracle(occupancy: np.ndarray, *, surface: Any, **common: Any) -> list[Part]:
    """The lookahead scored on the true mask (needs it: a diagnostic, not a planner)."""
    truth = TRUTH["mask"]
    if truth.shape != occupancy.shape:
        raise ValueError("the oracle plans on the full grid only")
    state = PartitionState(
        occupancy,
        reconstruct=lambda box: surface.part(surface.sections, box),
        max_steps=int(common["max_parts"]) - 1,
        min_remaining=float(common["min_remaining"]),
    )
    value = lambda s: iou(s.reconstruction(), truth)  # noqa: E731
    return run_lookahead(state, candidates=4, margin=0.002, value=value).finish()


def _plan_silhouettes(occupancy: np.ndarray, **options: Any) -> list[Part]:
    return plan_lookahead(occupancy, value="silhouettes", **options)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--half", choices=("dev", "val"), default="dev")
    parser.add_argument("--planes", type=int, default=12)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    # the two measuring planners exist only in this benchmark: added to the registry here
    planner_registry.PLANNERS["oracle"] = planner_registry.PlannerEntry(
        "oracle", _plan_oracle, needs_surface=True
    )
    planner_registry.PLANNERS["lookahead-silhouettes"] = planner_registry.PlannerEntry(
        "lookahead-silhouettes", _plan_silhouettes, needs_surface=True
    )
    protocol, cases = load_split(SPLIT_FILE)
    names = [n for n, c in cases.items() if c["half"] == args.half]
    start = time.perf_counter()
    rows = []
    for name in names:
        volume = load_case(name, protocol)
        sections, projections, truth = prepare_inputs(
            volume, slices=args.planes, axis="z", projections="gt"
        )
        assert truth is not None
        TRUTH["mask"] = np.asarray(truth.mask, dtype=bool)
        reference = Truth(truth.mask, truth.affine, seed=_seed(protocol["seed"], name))
        row: dict[str, Any] = {"case": name}
        for planner in PLANNERS:
            result = reconstruct(sections, projections, planner=planner)
            scores = score_mesh(
                np.asarray(result.mesh.vertices),
                np.asarray(result.mesh.faces),
                reference,
                seed=_seed(protocol["seed"], name, "z", args.planes, "default"),
            )
            row[planner] = (scores.volume_iou, len(result.plan.parts))
        rows.append(row)
        print(name, {p: f"{row[p][0]:.4f}/{row[p][1]}" for p in PLANNERS}, file=sys.stderr)
    seconds = time.perf_counter() - start
    base = np.array([r["heuristic"][0] for r in rows])
    lines = [
        f"# The expert's lookahead on real anatomy ({args.half} half, "
        f"{args.planes} planes along z)",
        "",
        "```bash",
        f"python benchmarks/lookahead_real.py --half {args.half} --planes {args.planes}"
        + ("" if args.out is None else f" --out {args.out}"),
        "```",
        "",
        f"{len(rows)} cases, ground-truth projections, the default surface; volume IoU by "
        f"`benchmarks/independent_eval.py`; {seconds / 60:.1f} min on this machine. "
        "`oracle` scores the lookahead's choices on the true mask and cannot run at inference.",
        "",
        "| planner | mean IoU | mean difference to heuristic | wins / ties / losses (±0.001) |",
        "|---|---:|---:|---:|",
    ]
    for planner in PLANNERS:
        v = np.array([r[planner][0] for r in rows])
        d = v - base
        lines.append(
            f"| {planner} | {v.mean():.4f} | {d.mean():+.4f} | "
            f"{int((d > 0.001).sum())} / {int((abs(d) <= 0.001).sum())} / "
            f"{int((d < -0.001).sum())} |"
        )
    lines += ["", "Per case, volume IoU (parts):", ""]
    lines += ["| case | " + " | ".join(PLANNERS) + " |", "|---|" + "---:|" * len(PLANNERS)]
    for r in rows:
        cells = " | ".join(f"{r[p][0]:.4f} ({r[p][1]})" for p in PLANNERS)
        lines.append(f"| {r['case']} | {cells} |")
    text = "\n".join(lines) + "\n"
    if args.out is None:
        print(text)
    else:
        with atomic_path(args.out) as tmp:
            Path(tmp).write_text(text)
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
