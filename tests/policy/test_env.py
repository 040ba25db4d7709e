"""The torch cut environment against the numpy partition episode (the rules' one implementation)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from slicerecon.errors import OptionError
from slicerecon.partition.cuts import Cut, cut_to_action, snap_action
from slicerecon.partition.episodes import ShapePool, episode_sections, occupancy_hull
from slicerecon.partition.heuristic import expert_action
from slicerecon.partition.state import NOOP_REWARD, PartitionState, iou
from slicerecon.policy.demos import episode_state
from slicerecon.policy.env import CutEnv
from slicerecon.policy.observation import observe_state
from slicerecon.sections import Box

FAMILIES = ("chair", "torus", "two_spheres", "y_branch", "box")


@pytest.fixture(scope="module")
def pool() -> ShapePool:
    return ShapePool.build(FAMILIES, [3], grid=28)


@pytest.fixture(scope="module")
def big_pool() -> ShapePool:
    return ShapePool.build(FAMILIES + ("table", "lamp", "genus2", "vessel_tree"), [0, 1], grid=24)


def _reference(env: CutEnv, i: int, surface: str) -> PartitionState:
    """A numpy episode on the same shape with the same reconstruction as slot ``i``."""
    assert env.reward_surface == surface
    return episode_state(env, i)


def _final_iou(state: PartitionState) -> float:
    union = np.zeros(state.occupancy.shape, dtype=bool)
    for part in state.finish():
        union[part.box.slices] |= np.asarray(state.reconstruct(part.box), dtype=bool)
    return iou(union, np.asarray(state.occupancy))


def _actions(env: CutEnv, rng: np.random.Generator) -> np.ndarray:
    """Half uniform actions, half cuts between two random corners of a random view."""
    actions = rng.random((env.n_envs, 5))
    for i in range(env.n_envs):
        view = int(rng.integers(3))
        corners = env.corner_px[i, view][env.corner_valid[i, view]]
        if rng.random() < 0.5 and len(corners) >= 2:
            a, b = rng.choice(len(corners), 2, replace=False)
            cut = Cut(view, tuple(corners[a]), tuple(corners[b]))
            actions[i] = cut_to_action(cut, env.image_shapes)
    return actions


def _run_contract(env: CutEnv, steps: int, seed: int, surface: str) -> dict[str, int]:
    """Step env and numpy episodes in lockstep; every rule must agree exactly."""
    rng = np.random.default_rng(seed)
    states = [_reference(env, i, surface) for i in range(env.n_envs)]
    starts = [s.potential() for s in states]
    seen = {"cuts": 0, "degenerate": 0, "removes_nothing": 0, "ends": 0}
    for _ in range(steps):
        actions = _actions(env, rng)
        befores = [s.remaining for s in states]
        snapped = [
            snap_action(actions[i], s.corners(), s.image_shapes) for i, s in enumerate(states)
        ]
        out = env.step(actions)
        rec = env.last_step
        assert rec is not None
        for i, state in enumerate(states):
            assert rec.cuts.cut(i) == snapped[i]  # same snapped cut (or both degenerate)
            result = state.step(actions[i])
            assert bool(out.noop[i]) == (result.part is None) == bool(rec.noop[i])
            if result.part is None:
                reason = "degenerate" if rec.cuts.degenerate[i] else "removes_nothing"
                assert result.info["noop"] == reason
                assert out.reward[i].item() == NOOP_REWARD
                assert not rec.part[i].any()
                seen[reason] += 1
            else:
                w = befores[i] & ~state.remaining
                np.testing.assert_array_equal(rec.part[i].cpu().numpy(), w)  # same W_i
                assert Box(tuple(rec.lo[i]), tuple(rec.hi[i])) == result.part.box
                assert rec.iou_part[i] == pytest.approx(result.info["iou_part"], abs=1e-12)
                assert rec.iou_reconstruction[i] == pytest.approx(
                    result.info["iou_reconstruction"], abs=1e-12
                )
                assert rec.reward[i] == pytest.approx(result.reward, abs=1e-12)
                assert out.reward[i].item() == pytest.approx(result.reward, abs=1e-6)
                seen["cuts"] += 1
            assert bool(out.done[i]) == result.done
            if result.done:
                assert out.final_iou[i].item() == pytest.approx(_final_iou(state), abs=1e-6)
                assert int(out.n_parts[i]) == len(state.parts)
                assert out.episode_return[i].item() == pytest.approx(
                    sum(p.reward for p in state.parts if p.cut is not None), abs=1e-5
                )
                if env.reward_kind == "gain":  # the return telescopes: final IoU - one part's
                    assert out.episode_return[i].item() == pytest.approx(
                        _final_iou(state) - starts[i], abs=1e-5
                    )
                    assert state.potential() == pytest.approx(_final_iou(state), abs=1e-12)
                states[i] = _reference(env, i, surface)  # the env started a new episode
                starts[i] = states[i].potential()
                seen["ends"] += 1
            else:
                np.testing.assert_array_equal(env.remaining[i].cpu().numpy(), state.remaining)
                assert int(env.step_count[i]) == state.step_count
    return seen


def test_env_follows_the_partition_rules(big_pool: ShapePool) -> None:
    """Thousands of random actions: same snapped cuts, parts W_i, no-ops, rewards and ends."""
    env = CutEnv(
        big_pool,
        n_envs=12,
        resolution=32,
        max_corners=12,
        max_steps=6,
        lam=0.7,
        augment=True,
        reward_surface="surrogate",
        seed=5,
    )
    env.reset(seed=5)
    seen = _run_contract(env, steps=170, seed=11, surface="surrogate")
    assert sum(seen.values()) - seen["ends"] == 12 * 170 >= 2000
    assert seen["cuts"] >= 500 and seen["degenerate"] >= 50 and seen["removes_nothing"] >= 20
    assert seen["ends"] >= 200


def _exact_env(pool: ShapePool, *, reward: str) -> CutEnv:
    """One episode per pool shape, 9 planes, the exact part surface."""
    env = CutEnv(
        pool,
        n_envs=len(pool),
        resolution=32,
        max_corners=12,
        max_steps=5,
        augment=False,
        reward=reward,
        reward_surface="exact",
    )
    env.load(list(pool.occupancies), n_planes=[9] * len(pool))
    return env


def test_env_reward_equals_partition_state_with_the_exact_surface(pool: ShapePool) -> None:
    """reward_surface="exact": the reward is PartitionState's with inference's part surface."""
    env = _exact_env(pool, reward="paper")
    seen = _run_contract(env, steps=12, seed=3, surface="exact")
    assert seen["cuts"] >= 15


def test_env_gain_reward_equals_partition_state(pool: ShapePool) -> None:
    """reward="gain": each step's reward is PartitionState's change of the whole IoU."""
    env = _exact_env(pool, reward="gain")
    np.testing.assert_allclose(
        env.potential,
        [_reference(env, i, "exact").potential() for i in range(len(pool))],
        atol=1e-12,
    )
    seen = _run_contract(env, steps=12, seed=3, surface="exact")
    assert seen["cuts"] >= 15 and seen["ends"] >= 5


def test_gain_reward_punishes_a_cut_that_lowers_the_iou() -> None:
    """Halving a ball: two parts reconstruct it a little worse than one, so the gain is < 0."""
    from slicerecon.partition.episodes import shape_occupancy
    from slicerecon.policy.reward import episode_reconstruction

    ball = shape_occupancy("sphere", seed=0, grid=24)
    recon, _, _ = episode_reconstruction(ball, 6)
    gain = PartitionState(ball, reconstruct=recon, reward="gain", max_corners=12)
    paper = PartitionState(ball, reconstruct=recon, reward="paper", max_corners=12)
    start = gain.potential()
    cut = Cut(2, (0.5, 11.5), (23.5, 11.5))
    g, p = gain.apply_cut(cut), paper.apply_cut(cut)
    assert g.part is not None and p.part is not None
    assert g.reward == pytest.approx(gain.potential() - start, abs=1e-12)
    assert g.reward < 0
    assert p.reward > 1.0  # the paper's reward pays for any part
    with pytest.raises(OptionError):
        PartitionState(ball, reward="gain")  # the gain needs a reconstruction
    with pytest.raises(OptionError):
        PartitionState(ball, reconstruct=recon, reward="area")


def test_episodes_use_the_library_sections_and_hull(pool: ShapePool) -> None:
    env = CutEnv(pool, n_envs=len(pool), resolution=32, max_corners=12, augment=False)
    env.load(list(pool.occupancies), n_planes=[9, 12, 30, 2, 1])
    for i, (occ, n) in enumerate(zip(pool.occupancies, [9, 12, 30, 2, 1], strict=True)):
        got_occ, sections, hull = env.episode(i)
        np.testing.assert_array_equal(got_occ, occ)
        ref = episode_sections(occ, n)
        np.testing.assert_array_equal(sections.indices, ref.indices)
        np.testing.assert_array_equal(sections.masks, ref.masks)
        np.testing.assert_array_equal(hull, occupancy_hull(occ))
        planes = env.plane_index[i][env.plane_valid[i]].numpy()
        np.testing.assert_array_equal(planes, ref.indices.astype(int))


@pytest.mark.parametrize("candidates", [0, 3])
def test_expert_action_matches_numpy(pool: ShapePool, candidates: int) -> None:
    """With candidates the env reads the expert's action off its first listed cut."""
    env = CutEnv(
        pool, n_envs=len(pool), resolution=32, max_corners=12, augment=False, candidates=candidates
    )
    env.load(list(pool.occupancies))
    actions, valid = env.expert_actions()
    for i, occ in enumerate(pool.occupancies):
        ref = expert_action(PartitionState(occ, max_corners=12))
        assert valid[i] == (ref is not None)
        if ref is not None:
            np.testing.assert_allclose(actions[i], ref, atol=1e-6)


def test_observation_matches_observe_state(pool: ShapePool) -> None:
    """The planner's encoding of a numpy state equals the env's observation."""
    env = CutEnv(pool, n_envs=len(pool), resolution=32, max_corners=12, max_steps=5, augment=False)
    env.load(list(pool.occupancies))
    actions, _ = env.expert_actions()
    obs = env.step(actions).obs
    for i in range(len(pool)):
        state = PartitionState(env.remaining[i].numpy().copy(), max_corners=12, max_steps=5)
        state.step_count = int(env.step_count[i])
        ref = observe_state(state, resolution=32, max_corners=12, max_steps=5)
        for a, b in zip(obs.select(slice(i, i + 1)), ref, strict=True):
            torch.testing.assert_close(a, b, atol=1e-6, rtol=0)


def test_episode_statistics_and_bad_actions(pool: ShapePool) -> None:
    env = CutEnv(pool, n_envs=3, resolution=32, max_corners=12, max_steps=2, seed=1)
    env.reset(seed=1)
    with pytest.raises(OptionError):
        env.step(np.zeros((2, 5)))
    with pytest.raises(OptionError):
        env.step(np.full((3, 5), np.nan))
    with pytest.raises(OptionError):
        CutEnv(pool, n_envs=1, reward_surface="loft")
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
    envs = [
        CutEnv(pool, n_envs=n, resolution=32, max_corners=12, max_steps=4, augment=False, device=d)
        for d in ("cpu", "cuda")
    ]
    for env in envs:
        env.load(list(pool.occupancies), n_planes=[9] * n)
    rng = np.random.default_rng(3)
    for _ in range(4):
        actions = torch.from_numpy(rng.random((n, 5)))
        cpu, gpu = (env.step(actions) for env in envs)
        torch.testing.assert_close(cpu.reward, gpu.reward.cpu())
        assert torch.equal(cpu.done, gpu.done.cpu())
        assert torch.equal(envs[0].remaining, envs[1].remaining.cpu())
