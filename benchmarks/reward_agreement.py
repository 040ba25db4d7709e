"""Agreement of the training reward's part reconstructions with the surface inference makes.

The reward's second term is ``IoU(S_i, W_i)``: how well the reconstruction
``S_i`` of a part from the sections inside its box matches the part.
Inference reconstructs a part with ``part_voxels(sections, box, method="sdf",
hull=hull, interpolation="pchip")`` carved by the hull
(:func:`slicerecon.policy.reward.part_surface_voxels`, the env's
``reward_surface="exact"``). This benchmark runs random partition episodes
(:class:`~slicerecon.partition.state.PartitionState`, random actions: half
uniform, half a cut between two random corners of a random view) on the
procedural shapes, in the training setting (``G^3`` grids, 8-16 z-planes per
episode, ground-truth hull), and compares per part ``IoU(S_i, W_i)`` of

* ``surrogate``: the env's default batched torch surrogate
  (:mod:`slicerecon.policy.surrogate`), and
* ``nearest-plane``: the env's reconstruction before it (each voxel copies the
  nearest kept plane inside the box, no hull),

with the exact one: Pearson and Spearman correlation, mean and largest
absolute difference; the same for the reward ``R_i`` (``lam = 1``) and for
each episode's IoU of ``∪ S_i`` with the shape. Parts are every part of an
episode, the leftover of ``finish()`` included.

    python benchmarks/reward_agreement.py [--seeds 5] [--episodes 6] [--out FILE]
"""

from __future__ import annotations

import argparse
import functools
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from scipy import stats

from slicerecon.io.atomic import atomic_path
from slicerecon.partition.cuts import Cut, cut_to_action
from slicerecon.partition.episodes import ShapePool
from slicerecon.partition.state import PartitionState, iou
from slicerecon.policy.reward import episode_reconstruction
from slicerecon.policy.surrogate import surrogate_reconstruction
from slicerecon.sections import Box, CrossSections
from slicerecon.shapes import shape_names

METHODS = ("surrogate", "nearest-plane")


def nearest_plane_voxels(occupancy: np.ndarray, sections: CrossSections, box: Box) -> np.ndarray:
    """The env's reconstruction before this benchmark's surrogate (for comparison only)."""
    kept = sections.indices.astype(np.int64)
    lo, hi = box.lo[2], box.hi[2]
    inside = kept[(kept >= lo) & (kept < hi)]
    candidates = inside if inside.size else kept
    z = np.arange(lo, hi)
    nearest = candidates[np.argmin(np.abs(z[:, None] - candidates[None, :]), axis=1)]
    return occupancy[box.slices[0], box.slices[1], :][:, :, nearest]


def random_action(state: PartitionState, rng: np.random.Generator) -> np.ndarray:
    """Uniform in [0, 1]^5, or (half the time) a cut between two corners of a random view."""
    view = int(rng.integers(3))
    corners = state.corners()[view]
    if rng.random() < 0.5 and len(corners) >= 2:
        a, b = rng.choice(len(corners), 2, replace=False)
        return cut_to_action(Cut(view, tuple(corners[a]), tuple(corners[b])), state.image_shapes)
    return rng.random(5)


class Agreement(NamedTuple):
    rows: list[dict[str, Any]]
    n_parts: int
    n_episodes: int
    ms_per_part: dict[str, float]


def run(pool: ShapePool, *, episodes: int, max_steps: int, seed: int) -> Agreement:
    rng = np.random.default_rng(seed)
    ious: dict[str, list[float]] = {"exact": [], **{m: [] for m in METHODS}}
    shares: list[float] = []
    finals: dict[str, list[float]] = {"exact": [], **{m: [] for m in METHODS}}
    seconds = {"exact": 0.0, "surrogate": 0.0}
    for occ in pool.occupancies:
        for _ in range(episodes):
            exact, sections, hull = episode_reconstruction(occ, int(rng.integers(8, 17)))
            recon: dict[str, Callable[[Box], np.ndarray]] = {
                "exact": exact,
                "surrogate": surrogate_reconstruction(sections, hull),
                "nearest-plane": functools.partial(nearest_plane_voxels, occ, sections),
            }
            state = PartitionState(occ, max_steps=max_steps, max_corners=16)
            parts: list[tuple[Box, np.ndarray]] = []
            while not state.done:
                before = state.remaining
                result = state.step(random_action(state, rng))
                if result.part is not None:
                    parts.append((result.part.box, before & ~state.remaining))
            if state.remaining.any():
                parts.append((Box.of_mask(state.remaining), np.asarray(state.remaining)))
            unions = {name: np.zeros(occ.shape, dtype=bool) for name in recon}
            for box, w in parts:
                shares.append(int(w.sum()) / int(occ.sum()))
                for name, fn in recon.items():
                    start = time.perf_counter()
                    s = fn(box)
                    if name in seconds:
                        seconds[name] += time.perf_counter() - start
                    ious[name].append(iou(s, w[box.slices]))
                    unions[name][box.slices] |= s
            for name, union in unions.items():
                finals[name].append(iou(union, occ))
    n_parts = len(shares)
    rewards = {k: np.asarray(shares) + np.asarray(v) for k, v in ious.items()}
    rows = []
    for name in METHODS:
        for what, data in (("IoU(S_i, W_i)", ious), ("R_i", rewards), ("episode IoU", finals)):
            ref, got = np.asarray(data["exact"]), np.asarray(data[name])
            rows.append(
                {
                    "reconstruction": name,
                    "quantity": what,
                    "n": len(ref),
                    "pearson": float(stats.pearsonr(ref, got)[0]),
                    "spearman": float(stats.spearmanr(ref, got)[0]),
                    "mean_abs": float(np.mean(np.abs(ref - got))),
                    "max_abs": float(np.max(np.abs(ref - got))),
                    "mean": float(np.mean(got)),
                    "mean_exact": float(np.mean(ref)),
                }
            )
    return Agreement(
        rows, n_parts, len(finals["exact"]), {k: 1e3 * v / n_parts for k, v in seconds.items()}
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--grid", type=int, default=32)
    parser.add_argument("--seeds", type=int, default=5, help="shapes per family")
    parser.add_argument("--episodes", type=int, default=6, help="random episodes per shape")
    parser.add_argument("--max-steps", type=int, default=7)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=None, help="write the table (markdown)")
    args = parser.parse_args()
    names = shape_names()
    pool = ShapePool.build(names, range(30_000, 30_000 + args.seeds), grid=args.grid)
    result = run(pool, episodes=args.episodes, max_steps=args.max_steps, seed=args.seed)
    lines = [
        f"`python benchmarks/reward_agreement.py --grid {args.grid} --seeds {args.seeds} "
        f"--episodes {args.episodes} --max-steps {args.max_steps} --seed {args.seed}`: "
        f"{result.n_parts} parts of {result.n_episodes} random episodes on "
        f"{len(pool)} shapes ({len(names)} families, seeds 30 000+), each against the exact "
        "part surface.",
        "",
        "| reconstruction | quantity | n | Pearson | Spearman | mean abs diff | max abs diff "
        "| mean (exact) |",
        "|---|---|---:|---:|---:|---:|---:|---|",
    ]
    for r in result.rows:
        lines.append(
            f"| {r['reconstruction']} | {r['quantity']} | {r['n']} | {r['pearson']:.4f} | "
            f"{r['spearman']:.4f} | {r['mean_abs']:.4f} | {r['max_abs']:.3f} | "
            f"{r['mean']:.3f} ({r['mean_exact']:.3f}) |"
        )
    ms = result.ms_per_part
    lines += [
        "",
        f"One part at a time on the CPU: exact {ms['exact']:.1f} ms, "
        f"surrogate {ms['surrogate']:.1f} ms per part (the env batches the surrogate).",
        "",
    ]
    text = "\n".join(lines)
    print(text)
    if args.out is not None:
        with atomic_path(args.out) as tmp:
            tmp.write_text("# Reward reconstruction agreement\n\n" + text)
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
