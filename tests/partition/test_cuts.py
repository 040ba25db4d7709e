"""The cut action on a tiny L-shape, checked by hand, and against a per-voxel reference."""

from __future__ import annotations

import numpy as np
import pytest

from slicerecon.corners import harris_corners
from slicerecon.errors import GeometryError, OptionError
from slicerecon.partition.cuts import (
    Cut,
    choose_sides,
    cut_to_action,
    line_sides,
    side_image,
    snap_action,
    snap_actions,
    split,
    view_shapes,
)
from slicerecon.sections import Box

SHAPE = (16, 14, 4)


def _l_shape() -> np.ndarray:
    """Arm A: x 1..10, y 1..4 (160 voxels); arm B: x 1..4, y 5..12 (128 voxels); z 0..3."""
    occ = np.zeros(SHAPE, dtype=bool)
    occ[1:11, 1:5] = True
    occ[1:5, 5:13] = True
    return occ


def _corners(occ: np.ndarray) -> tuple[np.ndarray, ...]:
    return tuple(harris_corners(occ.any(axis=a)) for a in range(3))


def _act(p1: tuple[float, float], p2: tuple[float, float], view: int, jitter: float = 0.0):
    m, n = view_shapes(SHAPE)[view]
    return np.array(
        [
            (p1[0] + 0.5 + jitter) / m,
            (p1[1] + 0.5 - jitter) / n,
            (p2[0] + 0.5 - jitter) / m,
            (p2[1] + 0.5 + jitter) / n,
            (view + 0.5) / 3,
        ]
    )


def test_view_shapes() -> None:
    assert view_shapes(SHAPE) == ((14, 4), (16, 4), (16, 14))


def test_snap_to_nearest_corners_in_the_chosen_view() -> None:
    corners = _corners(_l_shape())
    cut = snap_action(_act((4.5, 4.5), (4.5, 12.5), 2, jitter=0.8), corners, view_shapes(SHAPE))
    assert cut == Cut(2, (4.5, 4.5), (4.5, 12.5))
    # c in [0, 1/3) picks view x, c = 1 picks view z.
    act = _act((0.5, -0.5), (12.5, 3.5), 0)
    assert snap_action(act, corners, view_shapes(SHAPE)) == Cut(0, (0.5, -0.5), (12.5, 3.5))
    act[4] = 1.0
    assert snap_action(act, corners, view_shapes(SHAPE)).view == 2


def test_degenerate_actions_give_none() -> None:
    corners = _corners(_l_shape())
    same = _act((4.5, 4.5), (4.6, 4.4), 2)
    assert snap_action(same, corners, view_shapes(SHAPE)) is None
    no_corners = (corners[0], corners[1], np.zeros((0, 2)))
    assert snap_action(_act((0.5, 0.5), (4.5, 4.5), 2), no_corners, view_shapes(SHAPE)) is None


def test_cut_to_action_round_trips_through_snap_action() -> None:
    corners = _corners(_l_shape())
    for view in range(3):
        pts = corners[view]
        for i in range(len(pts)):
            for j in range(len(pts)):
                if i != j:
                    cut = Cut(view, tuple(pts[i]), tuple(pts[j]))
                    assert (
                        snap_action(
                            cut_to_action(cut, view_shapes(SHAPE)), corners, view_shapes(SHAPE)
                        )
                        == cut
                    )


def test_split_separates_the_smaller_side_with_exact_counts() -> None:
    occ = _l_shape()
    w, rest = split(occ, Cut(2, (4.5, 4.5), (4.5, 12.5)))  # the line x = 4.5
    assert w.sum() == 6 * 4 * 4 == 96 and rest.sum() == 288 - 96
    assert Box.of_mask(w) == Box((5, 1, 0), (11, 5, 4))
    assert not (w & rest).any() and np.array_equal(w | rest, occ)


def test_diagonal_cut_leaves_voxels_on_the_line_in_the_rest() -> None:
    occ = _l_shape()
    w, rest = split(occ, Cut(2, (4.5, 4.5), (0.5, 0.5)))  # the line x = y
    # Strict sides: x > y holds 30 pixels (120 voxels), x < y 38 pixels (152), on the line 4 (16).
    assert w.sum() == 120 and rest.sum() == 168
    on_line = np.zeros(SHAPE, dtype=bool)
    for i in range(1, 5):
        on_line[i, i] = True
    assert not (w & on_line).any() and (rest[on_line]).all()
    assert Box.of_mask(w) == Box((2, 1, 0), (11, 5, 4))


def test_cut_that_removes_nothing_gives_none() -> None:
    occ = _l_shape()
    assert split(occ, Cut(2, (0.5, 0.5), (0.5, 12.5))) is None  # all voxels have x >= 1
    assert split(np.zeros(SHAPE, dtype=bool), Cut(2, (4.5, 4.5), (4.5, 12.5))) is None


def test_equal_sides_tie_break_does_not_depend_on_end_point_order() -> None:
    occ = np.zeros((4, 2, 2), dtype=bool)
    occ[:] = True
    w1, _ = split(occ, Cut(2, (1.5, -0.5), (1.5, 1.5)))
    w2, _ = split(occ, Cut(2, (1.5, 1.5), (1.5, -0.5)))
    assert np.array_equal(w1, w2) and w1.sum() == 8 and w1[:2].all()


@pytest.mark.parametrize("view", [0, 1, 2])
def test_split_matches_a_per_voxel_reference_in_every_view(view: int) -> None:
    rng = np.random.default_rng(3)
    occ = rng.random((7, 8, 9)) < 0.4
    a, b = [ax for ax in range(3) if ax != view]
    cut = Cut(view, (0.5, 1.5), (5.5, 6.5))
    result = split(occ, cut)
    assert result is not None
    w, rest = result
    side = {}
    for idx in zip(*np.nonzero(occ), strict=True):
        r, c = idx[a], idx[b]
        s = (5.5 - 0.5) * (c - 1.5) - (6.5 - 1.5) * (r - 0.5)
        side[idx] = int(np.sign(s))
    pos = [i for i, s in side.items() if s > 0]
    neg = [i for i, s in side.items() if s < 0]
    smaller = pos if len(pos) <= len(neg) else neg
    expected = np.zeros_like(occ)
    for idx in smaller:
        expected[idx] = True
    assert np.array_equal(w, expected) and np.array_equal(rest, occ & ~expected)


def test_invalid_cuts_and_actions_raise() -> None:
    with pytest.raises(GeometryError, match="distinct"):
        Cut(2, (0.5, 0.5), (0.5, 0.5))
    with pytest.raises(OptionError, match="view"):
        Cut(3, (0.5, 0.5), (1.5, 0.5))
    corners = _corners(_l_shape())
    with pytest.raises(OptionError, match="5 numbers"):
        snap_action(np.zeros(4), corners, view_shapes(SHAPE))
    with pytest.raises(OptionError, match="NaN"):
        snap_action(np.array([0, 0, 1, 1, np.nan]), corners, view_shapes(SHAPE))


def test_cut_dict_round_trip() -> None:
    cut = Cut(1, (0.5, -0.5), (10.5, 3.5))
    assert Cut.from_dict(cut.to_dict()) == cut


def _padded(corners: tuple[np.ndarray, ...], k: int) -> tuple[np.ndarray, np.ndarray]:
    pts = np.zeros((3, k, 2))
    valid = np.zeros((3, k), dtype=bool)
    for v, c in enumerate(corners):
        pts[v, : len(c)] = c[:k]
        valid[v, : len(c)] = True
    return pts, valid


def test_batched_snapping_is_the_single_action_rule_per_row() -> None:
    rng = np.random.default_rng(0)
    shapes = [_l_shape(), rng.random(SHAPE) < 0.3, np.zeros(SHAPE, dtype=bool)]
    shapes[2][3:6, 2:9, 1:3] = True
    corners = [_corners(occ) for occ in shapes]
    corners.append((np.zeros((0, 2)), corners[0][1], np.zeros((0, 2))))  # views without corners
    k = max(len(c) for cs in corners for c in cs)
    padded = [_padded(c, k) for c in corners]
    actions = rng.random((400, 5))
    actions[::7] = rng.random((len(actions[::7]), 5)) * 1.4 - 0.2  # clipped to [0, 1]
    which = rng.integers(len(corners), size=len(actions))
    pts = np.stack([padded[w][0] for w in which])
    valid = np.stack([padded[w][1] for w in which])
    snapped = snap_actions(actions, pts, valid, view_shapes(SHAPE))
    for i, (action, w) in enumerate(zip(actions, which, strict=True)):
        expected = snap_action(action, corners[w], view_shapes(SHAPE))
        assert snapped.cut(i) == expected
        assert bool(snapped.degenerate[i]) == (expected is None)
    assert snapped.degenerate.any() and not snapped.degenerate.all()
    with pytest.raises(OptionError, match="rows of 5"):
        snap_actions(np.zeros((3, 4)), pts[:3], valid[:3], view_shapes(SHAPE))
    with pytest.raises(OptionError, match="corners must be"):
        snap_actions(actions[:2], pts[:3], valid[:3], view_shapes(SHAPE))


def test_line_sides_are_side_image_per_row_and_ignore_end_point_order() -> None:
    cuts = [
        Cut(2, (0.5, 0.5), (4.5, 4.5)),
        Cut(2, (4.5, 12.5), (4.5, 4.5)),
        Cut(2, (10.5, -0.5), (0.5, 3.5)),
    ]
    p1 = np.array([c.p1 for c in cuts])
    p2 = np.array([c.p2 for c in cuts])
    sides = line_sides(p1, p2, (16, 14))
    assert sides.shape == (3, 16, 14) and sides.dtype == np.int8
    np.testing.assert_array_equal(line_sides(p2, p1, (16, 14)), sides)
    for cut, image in zip(cuts, sides, strict=True):
        np.testing.assert_array_equal(image, side_image(cut, (16, 14)))
    assert (line_sides(p1[:1], p1[:1], (16, 14)) == 0).all()  # no line: no side


def test_choose_sides_takes_the_smaller_side_and_the_plus_side_on_ties() -> None:
    keep, nothing = choose_sides([3, 9, 5, 0, 4], [8, 2, 5, 7, 0])
    assert keep.tolist() == [1, -1, 1, 1, -1]
    assert nothing.tolist() == [False, False, False, True, True]
