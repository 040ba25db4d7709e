"""The torch cut environment against the numpy partition episode."""

from __future__ import annotations

import functools

import numpy as np
import pytest
import torch

from slicerecon.errors import OptionError
from slicerecon.partition.heuristic import expert_action
from slicerecon.partition.state import PartitionState
from slicerecon.policy.env import (
    CutEnv,
    ShapePool,
    nearest_plane_voxels,
    observe_state,
    section_planes,
)
from slicerecon.sections import Box

FAMILIES = ("chair", "torus", "two_spheres", "y_branch", "box")


@pytest.fixture(scope="module")
def pool() -> ShapePool:
    return ShapePool.build(FAMILIES, [3], grid=28)


def _numpy_states(pool: ShapePool, n_planes: int, max_steps: int) -> list[PartitionState]:
    states = []
    for occ in pool.occupancies:
        planes = section_planes(occ, n_planes)
        recon = functools.partial(nearest_plane_voxels, occ, planes)
        states.append(PartitionState(occ, reconstruct=recon, lam=0.7, max_steps=max_steps,
                                     max_corners=12))
    return states


def test_env_matches_partition_state(pool: ShapePool) -> None:
    """Same actions -> same remaining region, reward, no-op and done flags as numpy."""
    n, steps = len(pool), 6
    env = CutEnv(pool, n_envs=n, resolution=32, max_corners=12, max_steps=steps, lam=0.7,
                 augment=False)
    env.load(list(pool.occupancies), n_planes=[9] * n)
    states = _numpy_states(pool, 9, steps)
    rng = np.random.default_rng(7)
    n_cuts = n_noops = 0
    for _ in range(steps):
        actions = rng.random((n, 5))
        expert, valid = env.expert_actions()
        use = valid & (rng.random(n) < 0.6)
        actions[use] = expert[use]
        out = env.step(actions)
        for i, state in enumerate(states):
            if state.done:
                continue
            result = state.step(actions[i])
            assert out.reward[i].item() == pytest.approx(result.reward, abs=1e-6)
            assert bool(out.noop[i]) == (result.part is None)
            assert bool(out.done[i]) == result.done
            n_cuts += result.part is not None
            n_noops += result.part is None
            if not result.done:
                np.testing.assert_array_equal(env.remaining[i].numpy(), state.remaining)
    assert n_cuts >= 5 and n_noops >= 1  # both kinds of step were exercised


def test_expert_action_matches_numpy(pool: ShapePool) -> None:
    env = CutEnv(pool, n_envs=len(pool), resolution=32, max_corners=12, augment=False)
    env.load(list(pool.occupancies))
    actions, valid = env.expert_actions()
    for i, occ in enumerate(pool.occupancies):
        ref = expert_action(PartitionState(occ, max_corners=12))
        assert valid[i] == (ref is not None)
        if ref is not None:
            np.testing.assert_allclose(actions[i], ref, atol=1e-6)


def test_observation_matches_observe_state(pool: ShapePool) -> None:
    """The planner's encoding of a numpy state equals the env's observation."""
    env = CutEnv(pool, n_envs=len(pool), resolution=32, max_corners=12, max_steps=5,
                 augment=False)
    env.load(list(pool.occupancies))
    actions, _ = env.expert_actions()
    obs = env.step(actions).obs
    for i in range(len(pool)):
        state = PartitionState(env.remaining[i].numpy().copy(), max_corners=12, max_steps=5)
        state.step_count = int(env.step_count[i])
        ref = observe_state(state, resolution=32, max_corners=12, max_steps=5)
        for a, b in zip(obs.select(slice(i, i + 1)), ref, strict=True):
            torch.testing.assert_close(a, b, atol=1e-6, rtol=0)


def test_nearest_plane_surrogate_copies_planes() -> None:
    occ = np.zeros((6, 6, 10), dtype=bool)
    occ[1:5, 1:5, 2:8] = True
    occ[2:3, 2:3, 5] = False  # a hole on plane 5 only
    box = Box((0, 0, 3), (6, 6, 8))
    s = nearest_plane_voxels(occ, np.array([2, 5, 7]), box)
    assert s.shape == box.shape
    # z = 3 -> plane 5 (2 is outside the box), z = 6 -> plane 5 (tie goes to the lower)
    np.testing.assert_array_equal(s[:, :, 0], occ[:, :, 5])
    np.testing.assert_array_equal(s[:, :, 3], occ[:, :, 5])
    np.testing.assert_array_equal(s[:, :, 4], occ[:, :, 7])
    # a box without a plane uses the nearest plane overall
    s2 = nearest_plane_voxels(occ, np.array([2, 7]), Box((0, 0, 4), (6, 6, 5)))
    np.testing.assert_array_equal(s2[:, :, 0], occ[:, :, 2])


def test_episode_statistics_and_bad_actions(pool: ShapePool) -> None:
    env = CutEnv(pool, n_envs=3, resolution=32, max_corners=12, max_steps=2, seed=1)
    env.reset(seed=1)
    with pytest.raises(OptionError):
        env.step(np.zeros((2, 5)))
    with pytest.raises(OptionError):
        env.step(np.full((3, 5), np.nan))
    env.step(np.random.default_rng(0).random((3, 5)))
    out = env.step(np.random.default_rng(1).random((3, 5)))
    assert bool(out.done.all())  # max_steps = 2
    assert torch.all((out.final_iou > 0) & (out.final_iou <= 1))
    assert torch.all(out.n_parts >= 1)
    assert torch.all(env.step_count == 0)  # automatic reset


@pytest.mark.gpu
@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA device")
def test_gpu_env_matches_cpu_env(pool: ShapePool) -> None:
    n = len(pool)
    envs = [CutEnv(pool, n_envs=n, resolution=32, max_corners=12, max_steps=4, augment=False,
                   device=d) for d in ("cpu", "cuda")]
    for env in envs:
        env.load(list(pool.occupancies), n_planes=[9] * n)
    rng = np.random.default_rng(3)
    for _ in range(4):
        actions = torch.from_numpy(rng.random((n, 5)))
        cpu, gpu = (env.step(actions) for env in envs)
        torch.testing.assert_close(cpu.reward, gpu.reward.cpu())
        assert torch.equal(cpu.done, gpu.done.cpu())
        assert torch.equal(envs[0].remaining, envs[1].remaining.cpu())
