"""Episode bookkeeping: rewards by hand, no-ops, episode end, coverage after finish()."""

from __future__ import annotations

import numpy as np
import pytest

from slicerecon.errors import EmptyMaskError, GeometryError, OptionError
from slicerecon.partition.cuts import Cut, cut_to_action
from slicerecon.partition.state import (
    NOOP_REWARD,
    PartitionState,
    count_iou,
    episode_done,
    iou,
    part_rewards,
)
from slicerecon.sampling import projections_from_volume
from slicerecon.sections import Box, Volume

SHAPE = (16, 14, 4)
DIAGONAL = Cut(2, (0.5, 0.5), (4.5, 4.5))  # W: 120 voxels, box x 2..10, y 1..4, z 0..3
ACROSS = Cut(2, (4.5, 4.5), (4.5, 12.5))  # W: 96 voxels, box x 5..10, y 1..4


def _l_shape() -> np.ndarray:
    occ = np.zeros(SHAPE, dtype=bool)
    occ[1:11, 1:5] = True
    occ[1:5, 5:13] = True
    return occ


def _full_box(box: Box) -> np.ndarray:
    return np.ones(box.shape, dtype=bool)


def test_reward_is_part_share_plus_weighted_reconstruction_iou() -> None:
    state = PartitionState(_l_shape(), reconstruct=_full_box, lam=1.0)
    result = state.step(cut_to_action(DIAGONAL, state.image_shapes))
    assert result.part is not None and result.part.box == Box((2, 1, 0), (11, 5, 4))
    # IoU(W, O) = 120 / 288; S fills the 9*4*4 = 144-voxel box, IoU(S, W) = 120 / 144.
    assert result.reward == pytest.approx(120 / 288 + 120 / 144, abs=1e-12)
    assert result.info["iou_part"] == pytest.approx(120 / 288)
    assert result.info["iou_reconstruction"] == pytest.approx(120 / 144)
    assert result.part.mask_voxels == 120 and state.remaining_voxels == 168


def test_lambda_weights_and_missing_reconstructor_drops_the_second_term() -> None:
    def half(box: Box) -> np.ndarray:
        s = np.zeros(box.shape, dtype=bool)
        s[: box.shape[0] // 2] = True
        return s

    weighted = PartitionState(_l_shape(), reconstruct=half, lam=0.5).apply_cut(ACROSS)
    # W fills its 6x4x4 box; S is the first 3 x-planes of it: IoU(S, W) = 48 / 96.
    assert weighted.reward == pytest.approx(96 / 288 + 0.5 * 0.5, abs=1e-12)
    plain = PartitionState(_l_shape()).apply_cut(ACROSS)
    assert plain.reward == pytest.approx(96 / 288) and plain.info["iou_reconstruction"] is None


def test_noop_steps_count_and_give_the_noop_reward() -> None:
    state = PartitionState(_l_shape(), max_steps=3)
    before = state.remaining.copy()
    degenerate = np.array([0.3, 0.3, 0.3, 0.3, 0.9])  # both ends snap to the same corner
    result = state.step(degenerate)
    assert result.part is None and result.reward == NOOP_REWARD
    assert result.info["noop"] == "degenerate" and state.step_count == 1
    result = state.apply_cut(Cut(2, (0.5, 0.5), (0.5, 12.5)))
    assert result.info["noop"] == "removes_nothing" and state.step_count == 2
    assert np.array_equal(state.remaining, before) and state.parts == []


def test_episode_ends_at_max_steps_and_rejects_further_steps() -> None:
    state = PartitionState(_l_shape(), max_steps=1)
    assert state.apply_cut(ACROSS).done
    with pytest.raises(OptionError, match="episode is over"):
        state.apply_cut(DIAGONAL)


def test_episode_ends_when_little_remains() -> None:
    # After the cut 192 of 288 voxels remain (0.667): done for min_remaining 0.7, not for 0.6.
    assert PartitionState(_l_shape(), min_remaining=0.7).apply_cut(ACROSS).done
    assert not PartitionState(_l_shape(), min_remaining=0.6).apply_cut(ACROSS).done


def test_finish_makes_parts_that_partition_and_cover_the_shape() -> None:
    occ = _l_shape()
    state = PartitionState(occ, reconstruct=_full_box)
    state.apply_cut(DIAGONAL)
    state.apply_cut(Cut(2, (0.5, 12.5), (4.5, 12.5)))  # removes nothing (no voxel at y > 12)
    parts = state.finish()
    assert len(parts) == 2 and parts[-1].cut is None
    assert sum(p.mask_voxels for p in parts) == occ.sum()
    covered = np.zeros(SHAPE, dtype=bool)
    for p in parts:
        covered[p.box.slices] = True
    assert not (occ & ~covered).any()
    assert state.finish() == parts and state.done and state.remaining_voxels == 0


def test_projections_use_the_sampling_layout_and_corners_follow_the_remaining_region() -> None:
    occ = _l_shape()
    state = PartitionState(occ)
    expected = projections_from_volume(Volume(occ))
    for mine, theirs in zip(state.projections(), expected.views, strict=True):
        assert np.array_equal(mine, theirs.image)
    assert len(state.corners()[2]) == 6
    state.apply_cut(ACROSS)  # what remains is a 4 x 12 rectangle in view z
    np.testing.assert_array_equal(
        state.corners()[2], [[0.5, 0.5], [0.5, 12.5], [4.5, 0.5], [4.5, 12.5]]
    )
    points, valid = state.padded_corners(8)
    assert points.shape == (3, 8, 2) and valid.sum(axis=1).tolist() == [4, 4, 4]


def test_same_actions_give_the_same_episode() -> None:
    actions = [np.array([0.1, 0.9, 0.35, 0.35, 0.9]), np.array([0.0, 0.0, 0.3, 0.3, 0.9])]
    runs = []
    for _ in range(2):
        state = PartitionState(_l_shape())
        rewards = [state.step(a).reward for a in actions]
        runs.append((rewards, state.finish()))
    assert runs[0] == runs[1] and len(runs[0][1]) >= 2


def test_bad_inputs_raise() -> None:
    with pytest.raises(EmptyMaskError):
        PartitionState(np.zeros(SHAPE, dtype=bool))
    with pytest.raises(OptionError, match="min_remaining"):
        PartitionState(_l_shape(), min_remaining=1.5)
    state = PartitionState(_l_shape(), reconstruct=lambda box: np.ones((1, 1, 1), dtype=bool))
    with pytest.raises(GeometryError, match="box shape"):
        state.apply_cut(ACROSS)


def test_iou_of_empty_masks_is_one() -> None:
    empty = np.zeros((2, 2), dtype=bool)
    assert iou(empty, empty) == 1.0
    assert iou(np.eye(2, dtype=bool), np.ones((2, 2), dtype=bool)) == 0.5


def test_batched_rules_are_the_states_rules() -> None:
    np.testing.assert_array_equal(count_iou([0, 3, 2], [0, 6, 8]), [1.0, 0.5, 0.25])
    np.testing.assert_allclose(part_rewards([0.5, 0.25], [1.0, 0.5], lam=0.5), [1.0, 0.5])
    np.testing.assert_array_equal(part_rewards([0.5, 0.25], None, lam=0.5), [0.5, 0.25])
    done = episode_done(
        [0, 5, 100, 100], [100, 100, 100, 100], [1, 1, 1, 3], max_steps=3, min_remaining=0.06
    )
    assert done.tolist() == [True, True, False, True]
    # PartitionState's reward and end are these functions of its counts
    state = PartitionState(_l_shape(), reconstruct=_full_box, lam=0.3, min_remaining=0.7)
    result = state.apply_cut(DIAGONAL)
    expected = part_rewards([120 / 288], [count_iou([120], [144])[0]], lam=0.3)[0]
    assert result.reward == expected
    assert result.done == episode_done([168], [288], [1], max_steps=8, min_remaining=0.7)[0]
