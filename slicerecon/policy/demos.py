"""Demonstrations for the replay buffer ``R_D``: the heuristic expert, or its lookahead.

:func:`collect_demos` rolls out the heuristic expert in the batched
:class:`~slicerecon.policy.env.CutEnv`. :func:`collect_lookahead_demos`
demonstrates the expert's one-step lookahead
(:func:`~slicerecon.partition.lookahead.lookahead_cut`), which needs the
shape and a reconstruction at every choice: it runs each episode the env
draws as a numpy :class:`~slicerecon.partition.state.PartitionState` with the
env's own reward and reconstruction (the env and the numpy episode follow
the same rules, ``tests/policy/test_env.py``), and encodes each state with
:func:`~slicerecon.policy.observation.observe_state`.
"""

from __future__ import annotations

import functools
import logging

import numpy as np
import torch

from ..errors import OptionError
from ..partition.cuts import cut_to_action
from ..partition.lookahead import lookahead_cut
from ..partition.state import PartitionState
from .buffers import ReplayBuffer
from .env import CutEnv
from .observation import Observation, observe_state
from .reward import part_surface_voxels
from .surrogate import surrogate_reconstruction

__all__ = ["collect_demos", "collect_lookahead_demos", "episode_state"]

logger = logging.getLogger(__name__)


def collect_demos(
    env: CutEnv, buffer: ReplayBuffer, episodes: int, seed: int, *, stops: bool = False
) -> float:
    """Roll out the heuristic into ``buffer``; returns the mean demonstration return.

    Parameters
    ----------
    env : CutEnv
        Draws the episodes (its own augmentation and plane counts).
    buffer : ReplayBuffer
        Receives the transitions; their cloning target is the expert's action.
    episodes : int
        Episodes to demonstrate (at least; whole batches of ``env.n_envs``).
    seed : int
        Seed of the episode draws.
    stops : bool, optional

        The step where the expert has no cut left is demonstrated too, as
        the stop action (all zeros: a degenerate no-op).

    Returns
    -------
    float
        Mean return of the finished demonstration episodes.

    Raises
    ------
    OptionError
        If the expert found no cut in any episode (no demonstrations).
    """
    obs = env.reset(seed=seed)
    finished, returns = 0, []
    while finished < episodes:
        actions, has_cut = env.expert_actions()
        valid = np.ones_like(has_cut) if stops else has_cut
        if not valid.any():  # the expert has no cut in any slot: those episodes are over
            finished += env.n_envs
            obs = env.reset()
            continue
        act = torch.from_numpy(actions)
        out = env.step(act)
        # an episode where the expert has no cut left ends there (as the heuristic planner)
        buffer.add(
            obs.select(torch.from_numpy(valid)),
            act[valid],
            out.reward.cpu()[valid],
            out.obs.select(torch.from_numpy(valid)),
            out.done.cpu()[valid].float(),
            act[valid],
            torch.ones(int(valid.sum())),
        )
        done = out.done.cpu().numpy() | ~has_cut
        finished += int(done.sum())
        returns.extend(out.episode_return.cpu().numpy()[out.done.cpu().numpy()].tolist())
        stuck = [int(e) for e in np.flatnonzero(~has_cut)]
        if stuck:
            env._start(stuck, [env._draw(e, None) for e in stuck])  # noqa: SLF001
        obs = env.observation()
    if len(buffer) == 0:
        raise OptionError(
            f"the heuristic expert found no cut in {finished} episodes on these training "
            "shapes: no demonstrations; use other shapes or demo_episodes = 0"
        )
    return float(np.mean(returns)) if returns else float("nan")


def episode_state(env: CutEnv, slot: int) -> PartitionState:
    """A numpy episode on slot ``slot``'s shape, sections and hull, with the env's rules.

    Its reconstruction is the env's reward surface, memoised per box (the
    exact part surface, :func:`~slicerecon.policy.reward.part_surface_voxels`,
    or :func:`~slicerecon.policy.surrogate.surrogate_reconstruction`); its
    reward kind, ``lam``, ``max_steps``, ``min_remaining`` and ``max_corners``
    are the env's. The env's contract test steps both in lockstep.
    """
    occ, sections, hull = env.episode(slot)
    if env.reward_surface == "surrogate":
        make = surrogate_reconstruction(sections, hull)
    else:
        make = functools.partial(part_surface_voxels, sections, hull)
    return PartitionState(
        occ,
        reconstruct=functools.cache(make),
        lam=env.lam,
        reward=env.reward_kind,
        max_steps=env.max_steps,
        min_remaining=env.min_remaining,
        max_corners=env.max_corners,
    )


def collect_lookahead_demos(
    env: CutEnv,
    buffer: ReplayBuffer,
    episodes: int,
    seed: int,
    *,
    candidates: int,
    margin: float,
) -> float:
    """Demonstrate the expert's one-step lookahead on ``episodes`` episodes the env draws.

    Each step's choice is :func:`~slicerecon.partition.lookahead.lookahead_cut`
    (a cut, or the stop: all zeros); the transition's cloning target is that
    action. An episode's demonstration ends at its first stop (the states
    after it are the same region with fewer steps left).

    Parameters
    ----------
    env : CutEnv
        Draws the episodes; its ``candidates`` decides whether observations
        carry the expert's first cuts.
    buffer : ReplayBuffer
    episodes : int
        Episodes to demonstrate (at least; whole batches of ``env.n_envs``).
    seed : int
        Seed of the episode draws.
    candidates : int
        Expert cuts the lookahead scores besides the stop.
    margin : float
        IoU a choice must gain over the expert's to replace it.

    Returns
    -------
    float
        Mean return of the demonstrated episodes.
    """
    env.reset(seed=seed)
    returns: list[float] = []
    deviations = steps = 0
    while len(returns) < episodes:
        for slot in range(env.n_envs):
            state = episode_state(env, slot)
            total = 0.0
            obs = _observe(env, state)
            while not state.done:
                choice = lookahead_cut(state, candidates=candidates, margin=margin)
                stop = choice.cut is None
                action = np.zeros(5) if stop else cut_to_action(choice.cut, state.image_shapes)
                deviations += int(abs(choice.value - choice.expert_value) > 0.0)
                steps += 1
                result = state.apply_cut(choice.cut)
                total += result.reward
                act = torch.from_numpy(np.asarray(action, dtype=np.float32))[None]
                next_obs = _observe(env, state)
                buffer.add(
                    obs,
                    act,
                    torch.tensor([result.reward], dtype=torch.float32),
                    next_obs,
                    torch.tensor([float(result.done)]),
                    act,
                    torch.ones(1),
                )
                obs = next_obs
                if stop:
                    break
            returns.append(total)
        env.reset()
    logger.info("lookahead demonstrations: %d steps, %d away from the expert", steps, deviations)
    return float(np.mean(returns))


def _observe(env: CutEnv, state: PartitionState) -> Observation:
    return observe_state(
        state,
        resolution=env.resolution,
        max_corners=env.max_corners,
        max_steps=env.max_steps,
        candidates=env.candidates,
        device="cpu",
    )
