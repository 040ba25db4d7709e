"""Train a tiny cut planner for ~50 updates and use it (runs in well under a minute).

The settings are far too small to learn a useful planner; the point is to show
the pieces: a :class:`~slicerecon.policy.train.TrainConfig`, :func:`train`
(writing a CSV log, a checkpoint and ``actor.safetensors``), and the trained
actor used by the ``"policy"`` planner through ``plan_partition(...,
weights=...)``. For real training use ``slicerecon train --config il_rl``.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

if __name__ == "__main__":
    import torch

    from slicerecon.partition.planner import plan_partition
    from slicerecon.policy.train import TrainConfig, train
    from slicerecon.shapes import make_shape

    torch.set_num_threads(1)
    config = TrainConfig(
        name="tiny_il_rl",
        shapes=("box", "two_spheres", "y_branch"),
        train_shapes=2,
        eval_shapes=1,
        grid=24,
        resolution=32,
        max_corners=8,
        max_steps=4,
        n_envs=4,
        channels=4,
        hidden=32,
        batch_size=32,
        buffer_size=2000,
        demo_episodes=8,
        pretrain_updates=20,
        total_updates=50,
        explore=True,
        rl_weight=1.0,
        bc_weight=1.0,
        q_filter=True,
        bc_on_agent=True,
        log_every=10,
        eval_every=25,
        checkpoint_every=25,
    )
    with tempfile.TemporaryDirectory() as tmp:
        result = train(config, out=tmp)
        print(
            f"{result.n_updates} updates; held-out surrogate IoU {result.eval_iou:.3f} "
            f"(heuristic {result.heuristic_eval_iou:.3f})"
        )
        print(Path(result.log_path).read_text().splitlines()[-1])
        shape = make_shape("y_branch", seed=123, spacing=3.0).mask
        plan = plan_partition(shape, planner="policy", weights=result.actor_path, max_parts=4)
        print(f"policy plan: {len(plan.parts)} parts, covers the shape: {plan.covers(shape)}")
