"""Training the learned cut planner: :class:`TrainConfig` and :func:`train`.

One run (``slicerecon train --config il_rl``):

1. Build the shape pools: every family of ``shapes`` (all registered families
   when empty) with seeds ``0 .. train_shapes - 1`` for training and seeds
   ``EVAL_SEED_OFFSET + 0 .. eval_shapes - 1`` for evaluation (never trained on).
2. Phase 0: roll out the heuristic expert for ``demo_episodes`` episodes into
   the demonstration buffer ``R_D`` (skipped without demonstrations).
3. Phase I: ``pretrain_updates`` updates on ``R_D`` alone (actor: cloning
   loss only; critic: TD on the demonstrations).
4. Phase II (``explore``): the actor plus Gaussian or Ornstein-Uhlenbeck noise
   acts in ``n_envs`` episodes; transitions (with the expert's action at each
   state) go to ``R_A``; ``updates_per_step`` updates per batched env step on
   minibatches from ``R_D`` and ``R_A``.
5. Every ``eval_every`` updates: the greedy actor on the held-out shapes; the
   CSV log gets the mean IoU of the parts' reconstructions with the shapes
   (the reward's reconstruction, ``reward_surface``; ``docs/policy.md``).

Outputs in ``out``: ``log.csv``, ``checkpoint.pt`` (networks, optimizers,
buffers, counters, RNG states; ``resume=True`` continues from it; plain data
only, read without unpickling code, see :mod:`slicerecon.policy.checkpoint`),
``actor.safetensors`` (the final actor) and ``config.json``; TensorBoard
event files under ``tb/`` when the ``tensorboard`` package is installed.
"""

from __future__ import annotations

import csv
import io
import json
import logging
import math
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from ..errors import FormatError, OptionError
from ..io.atomic import atomic_path
from ..partition.episodes import ShapePool
from ..shapes import shape_names
from .buffers import ReplayBuffer
from .checkpoint import load_checkpoint, save_checkpoint
from .config import CONFIG_NAMES, EVAL_SEED_OFFSET, TrainConfig, config_path, load_config
from .ddpg import DDPG
from .demos import collect_demos, collect_lookahead_demos
from .env import CutEnv
from .observation import Observation
from .weights import save_actor

__all__ = [
    "TrainConfig",
    "TrainResult",
    "EVAL_SEED_OFFSET",
    "CONFIG_NAMES",
    "config_path",
    "load_config",
    "train",
    "evaluate_actor",
    "training_pool",
]

logger = logging.getLogger(__name__)

LOG_FIELDS = (
    "update",
    "env_steps",
    "phase",
    "critic_loss",
    "actor_loss",
    "bc_loss",
    "q_mean",
    "q_filter_frac",
    "episode_reward",
    "eval_iou",
    "eval_return",
    "elapsed_s",
)


@dataclass
class TrainResult:
    """What :func:`train` produced.

    Attributes
    ----------
    out : Path
        Output directory.
    actor_path : Path
        ``actor.safetensors``.
    log_path : Path
        ``log.csv``.
    n_updates : int
    eval_iou : float
        Last evaluation's mean IoU of ``∪ S_i`` with the held-out shapes.
    heuristic_eval_iou : float
        The heuristic expert's on the same shapes (NaN when not measured).
    agent : DDPG
        The trained networks.
    """

    out: Path
    actor_path: Path
    log_path: Path
    n_updates: int
    eval_iou: float
    heuristic_eval_iou: float
    agent: DDPG = field(repr=False)


# -- pieces of the loop -----------------------------------------------------------------
def _shape_names(config: TrainConfig) -> list[str]:

    names = list(config.shapes) if config.shapes else shape_names()
    unknown = sorted(set(names) - set(shape_names()))
    if unknown:
        raise OptionError(
            f"unknown shape famil(ies) {', '.join(unknown)}; choose from {', '.join(shape_names())}"
        )
    return names


def training_pool(
    config: TrainConfig, pool_file: str | os.PathLike[str] | None = None
) -> ShapePool:
    """The shapes a run trains on: each family's training seeds and the real shapes' copies.

    Parameters
    ----------
    config : TrainConfig
    pool_file : path-like, optional
        Read the pool from this file (:meth:`ShapePool.save`) instead of
        building it: for machines without the real shapes' packages. It must
        hold exactly the grids the config lists (families and seeds, every
        real shape's copies) on the config's grid.

    Raises
    ------
    OptionError
        For an unknown family, or a pool file that is not this config's pool.
    InputError, FormatError
        For a missing or unreadable pool file.
    """
    if pool_file is None:
        return ShapePool.build(
            _shape_names(config),
            range(config.train_shapes),
            grid=config.grid,
            real=config.real_shapes,
            real_variants=config.real_variants,
            max_stretch=config.max_stretch,
        )
    pool = ShapePool.load(pool_file)
    listed = ShapePool.listing(
        _shape_names(config),
        range(config.train_shapes),
        real=config.real_shapes,
        real_variants=config.real_variants,
    )
    held = list(zip(pool.names, pool.seeds, strict=True))
    if pool.grid != config.grid or held != listed:
        missing = sorted({f"{n}/{s}" for n, s in listed} - {f"{n}/{s}" for n, s in held})
        raise OptionError(
            f"{pool_file} is not the shape pool of config {config.name!r}: grid {pool.grid} "
            f"(config {config.grid}), {len(held)} grids (config {len(listed)})"
            + (f", missing {', '.join(missing[:5])}" if missing else "")
        )
    return pool


def _make_env(
    config: TrainConfig,
    pool: ShapePool,
    *,
    n_envs: int,
    augment: bool,
    seed: int,
    device: torch.device,
) -> CutEnv:
    return CutEnv(
        pool,
        n_envs=n_envs,
        resolution=config.resolution,
        max_corners=config.max_corners,
        max_steps=config.max_steps,
        min_remaining=config.min_remaining,
        lam=config.lam,
        planes=(config.planes_min, config.planes_max),
        augment=augment,
        reward=config.reward,
        reward_surface=config.reward_surface,
        candidates=config.candidates,
        device=device,
        seed=seed,
    )


def evaluate_actor(
    policy: Callable[[Observation, CutEnv], torch.Tensor], env: CutEnv, *, seed: int
) -> tuple[float, float]:
    """Run one greedy episode per slot on the env's pool (slot ``i`` = shape ``i``).

    Parameters
    ----------
    policy : callable
        ``policy(obs, env) -> actions (B, 5)``.
    env : CutEnv
        Its ``n_envs`` must equal its pool size.
    seed : int
        Seed of the plane-count draws (the same seed gives the same episodes).

    Returns
    -------
    (mean IoU of ``∪ S_i`` with ``O``, mean episode return)
    """
    obs = env.reset(seed=seed, shapes=list(range(env.n_envs)))
    iou = torch.full((env.n_envs,), float("nan"))
    ret = torch.full((env.n_envs,), float("nan"))
    for _ in range(env.max_steps):
        out = env.step(policy(obs, env))
        first = out.done.cpu() & torch.isnan(iou)
        iou[first] = out.final_iou.cpu()[first]
        ret[first] = out.episode_return.cpu()[first]
        obs = out.obs
    return float(iou.mean()), float(ret.mean())


def _expert_policy(obs: Observation, env: CutEnv) -> torch.Tensor:
    actions, valid = env.expert_actions()
    # without an expert cut, a degenerate action (a no-op: both ends on one corner)
    actions[~valid] = 0.0
    return torch.from_numpy(actions)


class _Noise:
    """Gaussian or Ornstein-Uhlenbeck exploration noise, (B, 5)."""

    def __init__(
        self, kind: str, sigma: float, shape: tuple[int, int], rng: np.random.Generator
    ) -> None:
        self.kind, self.sigma, self.rng = kind, float(sigma), rng
        self.state = np.zeros(shape)

    def __call__(self, done: np.ndarray | None = None) -> np.ndarray:
        if self.kind == "gaussian":
            return self.rng.normal(0.0, self.sigma, self.state.shape)
        if done is not None:
            self.state[done] = 0.0
        theta, dt = 0.15, 1.0
        self.state += theta * (-self.state) * dt + self.sigma * np.sqrt(dt) * self.rng.normal(
            size=self.state.shape
        )
        return self.state.copy()


def _rng_state(np_rng: np.random.Generator, env: CutEnv, gen: torch.Generator) -> dict[str, Any]:
    return {
        "torch": torch.get_rng_state(),
        "numpy": np_rng.bit_generator.state,
        "env": env.rng.bit_generator.state,
        "sample": gen.get_state(),
    }


def _resume_state(path: Path, config: TrainConfig) -> dict[str, Any]:
    """The checkpoint at ``path``, read safely, checked to be of ``config``'s run."""
    ckpt = load_checkpoint(path)
    same = {k: v for k, v in config.to_dict().items() if k != "total_updates"}
    if {k: v for k, v in ckpt["config"].items() if k != "total_updates"} != same:
        raise OptionError(
            f"{path} was written by another config; use a fresh --out or the same config"
        )
    return ckpt


def _write_csv(path: Path, rows: list[dict[str, Any]]) -> None:

    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=LOG_FIELDS)
    writer.writeheader()
    for row in rows:
        writer.writerow({k: row.get(k, "") for k in LOG_FIELDS})
    with atomic_path(path) as tmp:
        tmp.write_text(buf.getvalue())


def _tensorboard(out: Path) -> Any:
    try:
        from torch.utils.tensorboard import SummaryWriter
    except ImportError:
        return None
    return SummaryWriter(str(out / "tb"))


def _mean(values: list[float]) -> float:
    vals = [v for v in values if not math.isnan(v)]
    return float(np.mean(vals)) if vals else float("nan")


# -- the loop ---------------------------------------------------------------------------
def train(
    config: TrainConfig,
    *,
    out: str | os.PathLike[str],
    device: str | torch.device = "cpu",
    resume: bool = False,
    progress: Callable[[int, int, dict[str, float]], None] | None = None,
    pool: ShapePool | None = None,
) -> TrainResult:
    """Train an actor-critic cut planner (see the module docstring).

    Parameters
    ----------
    config : TrainConfig
    out : path-like
        Output directory (created).
    device : str or torch.device, optional
        ``cpu`` or ``cuda``.
    resume : bool, optional
        Continue from ``out/checkpoint.pt`` (networks, optimizers, buffers,
        counters, RNG states; running episodes restart). The file is read with
        :func:`slicerecon.policy.checkpoint.load_checkpoint`: tensors and plain
        data only, never code.
    progress : callable, optional
        ``progress(n_updates, total_updates, last_metrics)`` after every update.
    pool : ShapePool, optional
        The training shapes (default: :func:`training_pool` of ``config``; a
        pool read from a file with it, checked against the config).

    Returns
    -------
    TrainResult

    Raises
    ------
    OptionError
        For an unavailable device or a checkpoint of another config.
    FormatError
        With ``resume``, for a checkpoint that cannot be loaded safely (it holds
        Python objects other than tensors and plain data: an old pickled or a
        tampered file), is damaged, or does not fit the networks of ``config``.
    """
    dev = torch.device(device)
    if dev.type == "cuda" and not torch.cuda.is_available():
        raise OptionError("--device cuda was asked for but CUDA is not available; use cpu")
    outdir = Path(out)
    outdir.mkdir(parents=True, exist_ok=True)
    ckpt_path = outdir / "checkpoint.pt"
    log_path = outdir / "log.csv"
    start = time.perf_counter()
    ckpt = _resume_state(ckpt_path, config) if resume and ckpt_path.is_file() else None

    torch.manual_seed(config.seed)
    np_rng = np.random.default_rng(config.seed)
    gen = torch.Generator().manual_seed(config.seed)
    names = _shape_names(config)
    train_pool = training_pool(config) if pool is None else pool
    eval_pool = ShapePool.build(
        names, range(EVAL_SEED_OFFSET, EVAL_SEED_OFFSET + config.eval_shapes), grid=config.grid
    )
    env = _make_env(
        config,
        train_pool,
        n_envs=config.n_envs,
        augment=config.augment,
        seed=config.seed,
        device=dev,
    )
    eval_env = _make_env(
        config, eval_pool, n_envs=len(eval_pool), augment=False, seed=config.seed, device=dev
    )
    eval_seed = config.seed + 1
    agent = DDPG(
        config.net,
        device=dev,
        gamma=config.gamma,
        actor_lr=config.actor_lr,
        critic_lr=config.critic_lr,
        rl_weight=config.rl_weight,
        bc_weight=config.bc_weight,
        q_filter=config.q_filter,
        bc_on_agent=config.bc_on_agent,
        target_update=config.target_update,
        target_period=config.target_period,
        tau=config.tau,
        logit_penalty=config.logit_penalty,
        bc_choice=config.bc_loss == "choice",
    )
    demos, replay = (
        ReplayBuffer(
            config.buffer_size,
            resolution=config.resolution,
            max_corners=config.max_corners,
            candidates=config.candidates,
        )
        for _ in range(2)
    )
    rows: list[dict[str, Any]] = []
    env_steps = 0
    heuristic_iou = float("nan")
    elapsed_before = 0.0

    if ckpt is not None:
        try:
            agent.load_state_dict(ckpt["agent"])
            demos.load_state_dict(ckpt["demos"])
            replay.load_state_dict(ckpt["replay"])
            rows = [dict(row) for row in ckpt["rows"]]
            env_steps = int(ckpt["env_steps"])
            heuristic_iou = float(ckpt["heuristic_eval_iou"])
            elapsed_before = float(ckpt["elapsed_s"])
            torch.set_rng_state(ckpt["rng"]["torch"])
            np_rng.bit_generator.state = ckpt["rng"]["numpy"]
            gen.set_state(ckpt["rng"]["sample"])
            env.rng.bit_generator.state = ckpt["rng"]["env"]
        except (KeyError, TypeError, ValueError, RuntimeError, IndexError) as exc:
            raise FormatError(
                f"{ckpt_path} does not fit this config's networks, buffers or RNG states "
                f"({type(exc).__name__}: {' '.join(str(exc).split())[:300]}); it cannot be "
                "resumed: start a new run with another --out"
            ) from exc
        logger.info("resumed %s at update %d", ckpt_path, agent.n_updates)
        obs = env.reset()
    else:
        if resume:
            logger.info("no checkpoint in %s: starting a new run", outdir)
        heuristic_iou, _ = evaluate_actor(_expert_policy, eval_env, seed=eval_seed)
        logger.info("heuristic expert on the held-out shapes: IoU %.4f", heuristic_iou)
        if config.demo_episodes:
            if config.demo_lookahead:
                demo_return = collect_lookahead_demos(
                    env,
                    demos,
                    config.demo_episodes,
                    config.seed,
                    candidates=config.demo_lookahead,
                    margin=config.demo_margin,
                )
            else:
                demo_return = collect_demos(
                    env, demos, config.demo_episodes, config.seed, stops=config.expert_stops
                )
            logger.info("%d demonstration transitions (mean return %.3f)", len(demos), demo_return)
        obs = env.reset(seed=config.seed + 2)
    (outdir / "config.json").write_text(json.dumps(config.to_dict(), indent=2) + "\n")

    writer = _tensorboard(outdir)
    noise = _Noise(config.noise, config.noise_sigma, (config.n_envs, 5), np_rng)
    need_expert = config.bc_weight > 0 and config.bc_on_agent
    episode_rewards: list[float] = []
    window: dict[str, list[float]] = {}
    last: dict[str, float] = {}
    last_eval = float("nan")
    best_eval = max(
        (float(r["eval_iou"]) for r in rows if r.get("eval_iou") not in (None, "")),
        default=-math.inf,
    )

    def meta(n_updates: int) -> dict[str, Any]:
        return {
            "grid": config.grid,
            "max_steps": config.max_steps,
            "config": config.to_dict(),
            "n_updates": n_updates,
            "families": names,
            "real_shapes": list(config.real_shapes),
            "heuristic_eval_iou": heuristic_iou,
        }

    def checkpoint() -> None:
        state = {
            "config": config.to_dict(),
            "agent": agent.state_dict(),
            "demos": demos.state_dict(),
            "replay": replay.state_dict(),
            "rows": rows,
            "env_steps": env_steps,
            "heuristic_eval_iou": heuristic_iou,
            "elapsed_s": elapsed_before + time.perf_counter() - start,
            "rng": _rng_state(np_rng, env, gen),
        }
        save_checkpoint(state, ckpt_path)

    def env_step(random_actions: bool) -> None:
        nonlocal obs, env_steps
        if random_actions:
            actions = torch.from_numpy(np_rng.random((config.n_envs, 5))).float()
        else:
            actions = agent.act(obs).cpu() + torch.from_numpy(noise()).float()
            actions = actions.clamp(0.0, 1.0)
            if config.explore_stops > 0:
                stops = torch.from_numpy(np_rng.random(config.n_envs) < config.explore_stops)
                actions[stops] = 0.0
        if need_expert:
            ea, ev = env.expert_actions()
            if config.expert_stops:
                ev = np.ones_like(ev)  # no cut left: the expert stops (zeros)
        else:
            ea, ev = np.zeros((config.n_envs, 5), np.float32), np.zeros(config.n_envs, bool)
        step = env.step(actions)
        replay.add(
            obs,
            actions,
            step.reward.cpu(),
            step.obs,
            step.done.cpu().float(),
            torch.from_numpy(ea),
            torch.from_numpy(ev.astype(np.float32)),
        )
        if config.noise == "ou":
            noise.state[step.done.cpu().numpy()] = 0.0
        finished = step.episode_return.cpu().numpy()
        episode_rewards.extend(finished[~np.isnan(finished)].tolist())
        obs = step.obs
        env_steps += config.n_envs

    while agent.n_updates < config.total_updates:
        pretraining = agent.n_updates < config.pretrain_updates
        if config.explore and not pretraining:
            env_step(random_actions=len(demos) == 0 and len(replay) < config.learning_starts)
            if len(demos) == 0 and len(replay) < config.learning_starts:
                continue
            n_updates = config.updates_per_step
        else:
            n_updates = 1
        for _ in range(n_updates):
            demo_batch = (
                demos.sample(config.batch_size, generator=gen, device=dev) if len(demos) else None
            )
            agent_batch = (
                replay.sample(config.batch_size, generator=gen, device=dev)
                if len(replay) and config.explore and not pretraining
                else None
            )
            last = agent.update(demo_batch, agent_batch, pretrain=pretraining)
            for key, value in last.items():
                window.setdefault(key, []).append(value)
            u = agent.n_updates
            row: dict[str, Any] | None = None
            if u % config.log_every == 0 or u == config.total_updates:
                row = {
                    "update": u,
                    "env_steps": env_steps,
                    "phase": "pretrain" if pretraining else "train",
                }
                row.update({k: _mean(v) for k, v in window.items()})
                row["episode_reward"] = _mean(episode_rewards)
                window.clear()
                episode_rewards.clear()
            if u % config.eval_every == 0 or u == config.total_updates:
                iou, ret = evaluate_actor(lambda o, _e: agent.act(o), eval_env, seed=eval_seed)
                row = row or {
                    "update": u,
                    "env_steps": env_steps,
                    "phase": "pretrain" if pretraining else "train",
                }
                row.update(eval_iou=iou, eval_return=ret)
                last_eval = iou
                if config.keep_best and iou > best_eval:
                    best_eval = iou
                    save_actor(agent.actor, outdir / "actor_best.safetensors", extra=meta(u))
                logger.info("update %d: eval IoU %.4f (heuristic %.4f)", u, iou, heuristic_iou)
            if row is not None:
                row["elapsed_s"] = round(elapsed_before + time.perf_counter() - start, 2)
                rows.append(row)
                _write_csv(log_path, rows)
                if writer is not None:
                    for key, value in row.items():
                        if isinstance(value, float) and not math.isnan(value):
                            writer.add_scalar(key, value, u)
            if u % config.checkpoint_every == 0 or u == config.total_updates:
                checkpoint()
            if progress is not None:
                progress(u, config.total_updates, {**last, "eval_iou": last_eval})
            if u >= config.total_updates:
                break
    if not rows:
        _write_csv(log_path, rows)
    if not ckpt_path.is_file():
        checkpoint()
    if writer is not None:
        writer.close()
    actor_path = save_actor(agent.actor, outdir / "actor.safetensors", extra=meta(agent.n_updates))
    evals = [r["eval_iou"] for r in rows if "eval_iou" in r]
    return TrainResult(
        outdir,
        actor_path,
        log_path,
        agent.n_updates,
        float(evals[-1]) if evals else float("nan"),
        heuristic_iou,
        agent,
    )
