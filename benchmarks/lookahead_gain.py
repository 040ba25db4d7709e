"""How much better than the heuristic expert its one-step lookahead is, where the shape is known.

The lookahead (:func:`slicerecon.partition.lookahead.lookahead_cut`) scores the
expert's first ``--candidates`` cuts and the stop, each followed by the
expert to the end, on the known shape, and keeps the expert's choice unless
another is better by more than ``--margin`` (volume IoU). It is the teacher
of the ``demo_lookahead`` configs: this measures what there is to learn.

Episodes are drawn as in training by the env of a shipped config (its
shape pool: the procedural families' training seeds and the real
development shapes in stretched copies; random 90-degree rotations and
flips; 6-24 section planes), and each is run twice as a numpy
:class:`~slicerecon.partition.state.PartitionState` with the exact reward
surface: by the expert alone, and by the lookahead at every step. Reported:
the mean IoU of both, the episodes the lookahead improves or worsens, and
where its gains come from (per family, by kind of choice: another of the
expert's cuts, or stopping).

The same episodes are also run by the lookahead as inference can score it,
without the shape (:func:`slicerecon.partition.lookahead.plan_lookahead`'s
values, each with its default margin): on held-out section planes
(:func:`~slicerecon.partition.lookahead.held_out_value`) and on the
silhouettes (:func:`~slicerecon.partition.lookahead.silhouette_value`); their
episodes are read off the same IoU with the shape.

It prints a markdown report (``--out FILE`` also writes it; ``docs/results.md``
shows it)::

    python benchmarks/lookahead_gain.py --episodes 240 \\
        --config benchmarks/configs/il_rl_choice.toml --candidates 4 --margin 0.002 --seed 7
"""

from __future__ import annotations

import argparse
import collections
import time
from pathlib import Path

import numpy as np
import torch

from slicerecon.io.atomic import atomic_path
from slicerecon.partition.lookahead import (
    LOOKAHEAD_MARGINS,
    expert_value,
    held_out_value,
    lookahead_cut,
    run_lookahead,
    silhouette_value,
)
from slicerecon.policy.config import load_config
from slicerecon.policy.demos import episode_state
from slicerecon.policy.env import CutEnv
from slicerecon.policy.reward import part_surface_voxels
from slicerecon.policy.train import training_pool


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--config", default="benchmarks/configs/il_rl_choice.toml")
    parser.add_argument("--episodes", type=int, default=240)
    parser.add_argument("--candidates", type=int, default=4)
    parser.add_argument("--margin", type=float, default=0.002)
    parser.add_argument("--seed", type=int, default=7)
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    torch.set_num_threads(1)
    cfg = load_config(args.config)
    pool = training_pool(cfg)
    env = CutEnv(
        pool,
        n_envs=8,
        resolution=cfg.resolution,
        max_corners=cfg.max_corners,
        max_steps=cfg.max_steps,
        min_remaining=cfg.min_remaining,
        planes=(cfg.planes_min, cfg.planes_max),
        reward="gain",
        seed=args.seed,
    )
    env.reset(seed=args.seed)
    start = time.perf_counter()
    expert, teacher = [], []
    blind: dict[str, list[float]] = {"planes": [], "silhouettes": []}
    gains: dict[tuple[str, str], list[float]] = collections.defaultdict(list)
    while len(expert) < args.episodes:
        for slot in range(env.n_envs):
            state = episode_state(env, slot)
            family = pool.names[env.shape_id[slot]]
            expert.append(expert_value(state))
            _, sections, hull = env.episode(slot)
            values = {
                "planes": held_out_value(
                    sections, lambda s, box, hull=hull: part_surface_voxels(s, hull, box)
                ),
                "silhouettes": silhouette_value([hull.any(axis=a) for a in range(3)]),
            }
            for name, value in values.items():
                blind[name].append(
                    run_lookahead(
                        state.copy(),
                        candidates=args.candidates,
                        margin=LOOKAHEAD_MARGINS[name],
                        value=value,
                    ).potential()
                )
            while not state.done:
                choice = lookahead_cut(state, candidates=args.candidates, margin=args.margin)
                if choice.value > choice.expert_value:
                    kind = "stop" if choice.cut is None else "another cut"
                    gains[(family, kind)].append(choice.value - choice.expert_value)
                if choice.cut is None:
                    break
                state.apply_cut(choice.cut)
            teacher.append(state.potential())
        env.reset()
    seconds = time.perf_counter() - start
    e, t = np.array(expert), np.array(teacher)
    diff = t - e
    lines = [
        "# The expert's one-step lookahead against the expert (training episodes)",
        "",
        "```bash",
        f"python benchmarks/lookahead_gain.py --episodes {args.episodes} --config {args.config} "
        f"--candidates {args.candidates} --margin {args.margin} --seed {args.seed}",
        "```",
        "",
        f"{len(e)} episodes drawn as in training by `{args.config}`'s env (grid {cfg.grid}^3, "
        f"{cfg.planes_min}-{cfg.planes_max} planes, rotations and flips), exact reward surface; "
        f"{seconds:.0f} s on this machine.",
        "",
        "| planner | mean IoU | episodes better by > 0.001 | worse by > 0.001 |",
        "|---|---:|---:|---:|",
        f"| expert | {e.mean():.4f} | — | — |",
        f"| lookahead | {t.mean():.4f} | {int((diff > 0.001).sum())} | "
        f"{int((diff < -0.001).sum())} |",
        *[
            f"| lookahead on {name}, no shape (margin {LOOKAHEAD_MARGINS[name]}) | "
            f"{np.mean(v):.4f} | {int((np.array(v) - e > 0.001).sum())} | "
            f"{int((np.array(v) - e < -0.001).sum())} |"
            for name, v in blind.items()
        ],
        "",
        "Where the lookahead's choices gain (per family and kind of choice; a step's gain is "
        "the IoU its choice leads to less the expert's choice's):",
        "",
        "| family | choice | steps | total gain | largest |",
        "|---|---|---:|---:|---:|",
    ]
    for (family, kind), values in sorted(gains.items(), key=lambda kv: -sum(kv[1])):
        lines.append(
            f"| {family} | {kind} | {len(values)} | {sum(values):.3f} | {max(values):.3f} |"
        )
    text = "\n".join(lines) + "\n"
    if args.out is None:
        print(text)
    else:
        with atomic_path(args.out) as tmp:
            Path(tmp).write_text(text)
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
