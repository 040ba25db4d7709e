"""The heuristic expert: candidate segments by hand, and obvious parts of chair / T shapes."""

from __future__ import annotations

import numpy as np

from slicerecon.corners import harris_corners
from slicerecon.partition.cuts import Cut, snap_action
from slicerecon.partition.heuristic import (
    Segment,
    expert_action,
    expert_cut,
    expert_segments,
    nearest_neighbour_pairs,
    segment_band,
)
from slicerecon.partition.planner import plan_partition
from slicerecon.partition.state import PartitionState


def _l_image() -> np.ndarray:
    img = np.zeros((16, 14), dtype=bool)
    img[1:11, 1:5] = True
    img[1:5, 5:13] = True
    return img


def chair(n: int = 48) -> np.ndarray:
    """Seat slab, back slab at low x and four legs, with numpy (13 312 voxels)."""
    occ = np.zeros((n, n, n), dtype=bool)
    occ[8:40, 8:40, 18:22] = True  # seat
    occ[8:12, 8:40, 22:44] = True  # back
    for x in (8, 36):
        for y in (8, 36):
            occ[x : x + 4, y : y + 4, 4:18] = True  # legs
    return occ


def t_shape(n: int = 48) -> np.ndarray:
    """A horizontal slab on a vertical stem."""
    occ = np.zeros((n, n, n), dtype=bool)
    occ[6:42, 6:42, 30:38] = True
    occ[20:28, 6:42, 6:30] = True
    return occ


def box_fill(occ: np.ndarray, planner: str) -> float:
    plan = plan_partition(occ, planner=planner)
    assert plan.covers(occ)
    return occ.sum() / sum(box.n_voxels for box in plan.boxes)


def test_nearest_neighbour_pairs_are_deduplicated() -> None:
    pts = np.array([[0.0, 0.0], [0.0, 1.0], [5.0, 5.0], [5.0, 7.0], [9.0, 9.0]])
    assert nearest_neighbour_pairs(pts) == [(0, 1), (2, 3), (3, 4)]
    assert nearest_neighbour_pairs(pts[:1]) == []


def test_segment_band_is_two_pixels_wide_along_a_lattice_line() -> None:
    band = segment_band((4.5, 0.5), (4.5, 6.5), (10, 10))
    expected = np.zeros((10, 10), dtype=bool)
    # Pixels 4-5 along the segment, plus the four touching its end vertices (0.707 px away),
    # which is what closes a cut at a concave corner.
    expected[4:6, 0:8] = True
    assert np.array_equal(band, expected)


def test_l_silhouette_has_one_splitting_segment_with_hand_computed_cost() -> None:
    img = _l_image()
    corners = harris_corners(img)
    empty = np.zeros((0, 2))
    segments = expert_segments([img.T, img, img], [empty, empty, corners])
    # Only the diagonal from the outer corner to the concave corner splits the L. The
    # pieces leave 32 - 26 = 6 and 40 - 34 = 6 box pixels uncovered.
    assert segments == [Segment(2, (0.5, 0.5), (4.5, 4.5), 12.0)]


def test_box_has_no_expert_cut() -> None:
    occ = np.zeros((12, 12, 12), dtype=bool)
    occ[2:9, 3:10, 1:11] = True
    state = PartitionState(occ)
    assert expert_cut(state) is None and expert_action(state) is None


def test_expert_action_applies_exactly_the_expert_cut() -> None:
    state = PartitionState(t_shape())
    cut = expert_cut(state)
    action = expert_action(state)
    assert isinstance(cut, Cut) and action.shape == (5,)
    assert ((action >= 0) & (action <= 1)).all()
    assert snap_action(action, state.corners(), state.image_shapes) == cut
    assert state.step(action).part is not None


def test_t_shape_splits_into_its_slab_and_stem() -> None:
    occ = t_shape()
    plan = plan_partition(occ, planner="heuristic")
    boxes = sorted((b.lo, b.hi) for b in plan.boxes)
    assert boxes == [((6, 6, 30), (42, 42, 38)), ((20, 6, 6), (28, 42, 30))]
    assert box_fill(occ, "heuristic") == 1.0  # measured: 1.000 vs 0.417 for one box
    assert box_fill(occ, "none") < 0.42


def test_chair_boxes_fit_the_shape_far_better_than_one_box() -> None:
    occ = chair()
    heuristic, single = box_fill(occ, "heuristic"), box_fill(occ, "none")
    # Measured: 0.718 (3 parts: back + near legs, far legs, seat) vs 0.191.
    assert single < 0.2
    assert heuristic > 0.6 and heuristic > 3 * single


def test_expert_is_deterministic() -> None:
    first = plan_partition(chair(), planner="heuristic")
    second = plan_partition(chair(), planner="heuristic")
    assert first == second
