"""Throughput of the torch cut environment (env steps per second).

Steps ``B`` episodes with uniformly random actions on procedural training
shapes and reports environment steps per second (``B`` x batched steps / s):
a single env on the CPU, batched on the CPU (B = 64, 256) and, when CUDA is
available, batched on the GPU, for each reward surface asked for
(``--surfaces exact,surrogate``). Corner detection stays on the CPU (numpy
Harris corners of the episodes whose remaining region changed), as do the
rules' decisions (:mod:`slicerecon.partition.cuts`, :mod:`~slicerecon.partition.state`)
and the ``exact`` reward surface. Prints a markdown table (and writes it to
``--out`` when given).

    python benchmarks/env_throughput.py --grid 32 --resolution 64 --seconds 20 --threads 2
"""

from __future__ import annotations

import argparse
import os
import platform
import time
from pathlib import Path

import numpy as np
import torch

from slicerecon.io.atomic import atomic_path
from slicerecon.partition.episodes import ShapePool
from slicerecon.policy.env import CutEnv
from slicerecon.shapes import shape_names


def measure(
    pool: ShapePool,
    *,
    n_envs: int,
    device: str,
    resolution: int,
    seconds: float,
    surface: str = "exact",
    warmup: float = 0.0,
    seed: int = 0,
) -> tuple[float, int]:
    env = CutEnv(
        pool,
        n_envs=n_envs,
        resolution=resolution,
        max_corners=16,
        max_steps=7,
        reward_surface=surface,
        device=device,
        seed=seed,
    )
    env.reset(seed=seed)
    rng = np.random.default_rng(seed)
    start = time.perf_counter()
    env.step(torch.from_numpy(rng.random((n_envs, 5))))  # warm-up: caches of corners, planes
    while time.perf_counter() - start < warmup:
        env.step(torch.from_numpy(rng.random((n_envs, 5))))
    if device == "cuda":
        torch.cuda.synchronize()
    steps, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds or steps < 3:
        env.step(torch.from_numpy(rng.random((n_envs, 5))))
        steps += 1
    if device == "cuda":
        torch.cuda.synchronize()
    elapsed = time.perf_counter() - start
    return n_envs * steps / elapsed, steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=None, help="also write the markdown here")
    parser.add_argument("--grid", type=int, default=32)
    parser.add_argument("--resolution", type=int, default=64)
    parser.add_argument("--seconds", type=float, default=10.0, help="per measurement")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument(
        "--warmup",
        type=float,
        default=5.0,
        help="seconds stepped before each measurement (fills the caches)",
    )
    parser.add_argument("--batches", default="1,64,256")
    parser.add_argument(
        "--surfaces",
        default="exact,surrogate",
        help="reward surfaces to measure, comma-separated (exact, surrogate)",
    )
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    pool = ShapePool.build(shape_names(), range(4), grid=args.grid)
    surfaces = args.surfaces.split(",")
    runs = [("cpu", int(b), s) for s in surfaces for b in args.batches.split(",")]
    if torch.cuda.is_available():
        runs += [
            ("cuda", int(b), s) for s in surfaces for b in args.batches.split(",") if int(b) > 1
        ]
    rows = []
    load_before = os.getloadavg()[0]
    for device, b, surface in runs:
        rate, steps = measure(
            pool,
            n_envs=b,
            device=device,
            resolution=args.resolution,
            seconds=args.seconds,
            surface=surface,
            warmup=args.warmup,
        )
        rows.append((device, b, surface, steps, rate))
        print(f"{device:5s} B={b:4d} {surface:9s}: {rate:8.1f} env steps/s ({steps} batched steps)")
    lines = [
        "# Cut environment throughput",
        "",
        f"`python benchmarks/env_throughput.py --grid {args.grid} --resolution "
        f"{args.resolution} --seconds {args.seconds:g} --warmup {args.warmup:g} "
        f"--threads {args.threads} --surfaces {args.surfaces}`",
        "",
        f"Grid {args.grid}^3, observed silhouettes {args.resolution}x{args.resolution}, "
        f"16 corners per view, random actions, {len(pool)} shapes of "
        f"{len(set(pool.names))} families. torch {torch.__version__}, {args.threads} "
        f"thread(s), {platform.processor() or platform.machine()}; CUDA "
        f"{'available' if torch.cuda.is_available() else 'not available (no GPU rows)'}.",
        "",
        "| device | B (episodes) | reward surface | batched steps | env steps / s |",
        "|---|---:|---|---:|---:|",
    ]
    lines += [f"| {d} | {b} | {f} | {s} | {r:.1f} |" for d, b, f, s, r in rows]
    lines += [
        "",
        "An env step is one cut in one episode (snapping, split, part box, reward with the",
        "given part surface, automatic reset with the episode's plane distances and hull);",
        "the Harris corners of every changed",
        "silhouette come from the library's numpy code on the CPU, memoised on the",
        "silhouette's bits (episodes revisit the pool's shapes, so many are cache hits;",
        "a cold cache is slower), which bounds the GPU rows too.",
        "",
        f"Machine load (1-min load average) before / after the measurements: "
        f"{load_before:.1f} / {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores — "
        "other jobs shared the CPU, so these rates are lower bounds.",
        "",
    ]
    print("\n".join(lines))
    if args.out is not None:
        with atomic_path(args.out) as tmp:
            tmp.write_text("\n".join(lines))
        print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
