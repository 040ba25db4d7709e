"""Training episodes: shapes in cubic grids, their sections and visual hull."""

from __future__ import annotations

import numpy as np
import pytest

from slicerecon.errors import EmptyMaskError, OptionError
from slicerecon.partition.episodes import (
    SECTION_AXIS,
    ShapePool,
    episode_sections,
    fit_to_cube,
    occupancy_hull,
    shape_occupancy,
)
from slicerecon.sampling import sample_sections
from slicerecon.sections import Box, Volume


def test_fit_to_cube_centres_the_bounding_box() -> None:
    mask = np.zeros((9, 5, 7), dtype=bool)
    mask[2:5, 1:2, 0:7] = True  # box of shape (3, 1, 7)
    out = fit_to_cube(mask, 10)
    assert out.shape == (10, 10, 10) and out.sum() == mask.sum()
    assert Box.of_mask(out) == Box((3, 4, 1), (6, 5, 8))  # (10 - s) // 2 per axis
    with pytest.raises(OptionError, match="does not fit"):
        fit_to_cube(mask, 6)
    with pytest.raises(EmptyMaskError):
        fit_to_cube(np.zeros((3, 3, 3), dtype=bool), 4)


def test_shape_occupancy_spans_the_grid_less_its_margin() -> None:
    occ = shape_occupancy("chair", seed=2, grid=24)
    box = Box.of_mask(occ)
    assert occ.shape == (24, 24, 24) and max(box.shape) <= 22
    assert max(box.shape) >= 20  # the longest side is scaled up to the inner size
    assert min(box.lo) >= 1 and max(box.hi) <= 23
    pool = ShapePool.build(["chair", "torus"], [2, 3], grid=24)
    assert len(pool) == 4 and pool.grid == 24 and pool.names == ("chair",) * 2 + ("torus",) * 2
    np.testing.assert_array_equal(pool.occupancies[0], occ)
    with pytest.raises(OptionError):
        ShapePool.build([], [0], grid=24)


def test_episode_sections_are_the_library_sections() -> None:
    occ = np.zeros((8, 9, 20), dtype=bool)
    occ[2:6, 3:7, 4:15] = True  # occupied z-planes 4..14
    sections = episode_sections(occ, 5)
    ref = sample_sections(Volume(occ), n=5, axis="z")
    assert sections.axis == SECTION_AXIS
    np.testing.assert_array_equal(sections.indices, ref.indices)
    np.testing.assert_array_equal(sections.masks, ref.masks)
    assert sections.indices.tolist() == [4, 7, 9, 12, 14]
    assert episode_sections(occ, 40).n_planes == 11  # no more planes than the range holds
    assert episode_sections(occ, 1).indices.tolist() == [4]
    with pytest.raises(OptionError):
        episode_sections(occ, 0)


def test_occupancy_hull_is_the_intersection_of_the_extruded_silhouettes() -> None:
    rng = np.random.default_rng(1)
    occ = rng.random((6, 7, 8)) < 0.2
    hull = occupancy_hull(occ)
    expected = occ.any(0)[None] & occ.any(1)[:, None] & occ.any(2)[:, :, None]
    np.testing.assert_array_equal(hull, expected)
    assert not (occ & ~hull).any()
