"""Tests of slicerecon.sampling: plane choice and projections."""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest
from scipy import ndimage

from slicerecon.errors import EmptyMaskError, OptionError
from slicerecon.sampling import (
    dense_count,
    evenly_spaced_planes,
    pool_any,
    pool_sections,
    projections_from_sections,
    projections_from_volume,
    sample_sections,
)
from slicerecon.sections import CrossSections, Volume

SPACING = np.array([0.8, 0.8, 2.0])
ORIGIN = np.array([-12.0, 5.0, 30.0])
RADIUS = 40.0  # mm
CENTRE = np.array([54.0, 55.0, 24.3])  # voxel index; in-plane on a voxel centre


def _affine() -> np.ndarray:
    aff = np.diag([*SPACING, 1.0])
    aff[:3, 3] = ORIGIN
    return aff


@pytest.fixture(scope="module")
def ball() -> Volume:
    """A ball of radius 40 mm on an anisotropic grid with a non-zero origin."""
    i, j, k = np.ogrid[:110, :110, :50]
    d2 = sum(((idx - c) * s) ** 2 for idx, c, s in zip((i, j, k), CENTRE, SPACING, strict=True))
    return Volume(d2 <= RADIUS**2, _affine())


def _round_half_up_linspace(first: int, last: int, n: int) -> list[int]:
    half = Fraction(1, 2)
    return [first + math.floor(Fraction(k * (last - first), n - 1) + half) for k in range(n)]


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.count_nonzero(a & b) / np.count_nonzero(a | b))


# -- plane choice ---------------------------------------------------------------------
def test_n_planes_follow_analytic_extent(ball: Volume) -> None:
    half = RADIUS / SPACING[2]  # the ball spans +-20 planes around its centre
    first, last = math.ceil(CENTRE[2] - half), math.floor(CENTRE[2] + half)
    sections = sample_sections(ball, n=16)
    expected = _round_half_up_linspace(first, last, 16)
    assert sections.indices.tolist() == expected
    assert sections.axis == 2
    assert sections.grid_shape == ball.shape
    np.testing.assert_array_equal(sections.affine, ball.affine)
    np.testing.assert_array_equal(sections.masks, ball.mask[:, :, expected].transpose(2, 0, 1))
    np.testing.assert_allclose(sections.positions, ORIGIN[2] + SPACING[2] * np.array(expected))


def test_every_keeps_last_plane_only_on_step(ball: Volume) -> None:
    first, last = 5, 44  # 40 planes: ceil(24.3 - 20), floor(24.3 + 20)
    on_step = sample_sections(ball, every=3)
    assert on_step.indices.tolist() == list(range(first, last + 1, 3))
    assert on_step.indices[-1] == last
    off_step = sample_sections(ball, every=4)
    assert off_step.indices.tolist() == list(range(first, last + 1, 4))
    assert off_step.indices[-1] == 41


def test_default_keeps_every_plane_and_other_axes_work(ball: Volume) -> None:
    everything = sample_sections(ball)
    np.testing.assert_array_equal(everything.indices, ball.occupied_planes(2))
    along_x = sample_sections(ball, n=5, axis="x")
    planes_x = ball.occupied_planes(0)
    assert along_x.axis == 0
    assert along_x.masks.shape == (5, 110, 50)
    assert along_x.indices.tolist() == _round_half_up_linspace(planes_x[0], planes_x[-1], 5)
    np.testing.assert_array_equal(along_x.masks[2], ball.mask[int(along_x.indices[2])])


def test_sampling_errors(ball: Volume) -> None:
    with pytest.raises(OptionError, match="not both"):
        sample_sections(ball, n=5, every=2)
    with pytest.raises(OptionError, match="holds only 40"):
        sample_sections(ball, n=41)
    with pytest.raises(OptionError, match="n must be >= 2"):
        sample_sections(ball, n=1)
    with pytest.raises(OptionError, match="every must be >= 1"):
        sample_sections(ball, every=0)
    with pytest.raises(OptionError, match="axis"):
        sample_sections(ball, n=4, axis="w")
    with pytest.raises(EmptyMaskError):
        sample_sections(Volume(np.zeros((8, 8, 8), dtype=bool)), n=3)
    assert sample_sections(ball, n=40).indices.tolist() == list(range(5, 45))


def test_dense_planes_are_sparse_planes_plus_midpoints() -> None:
    for first, last in [(0, 9), (3, 40), (7, 71), (10, 11)]:
        available = last - first + 1
        for n in range(2, (available + 1) // 2 + 1):
            sparse = evenly_spaced_planes(first, last, n)
            dense = evenly_spaced_planes(first, last, dense_count(n))
            assert dense.size == 2 * n - 1
            np.testing.assert_array_equal(dense[::2], sparse)
            assert np.all((dense[1::2] > sparse[:-1]) & (dense[1::2] < sparse[1:]))
    with pytest.raises(OptionError):
        dense_count(1)


# -- projections ----------------------------------------------------------------------
def _box_volume() -> tuple[Volume, tuple[int, int, int], tuple[int, int, int]]:
    lo, hi = (4, 6, 3), (15, 12, 20)
    mask = np.zeros((20, 18, 24), dtype=bool)
    mask[lo[0] : hi[0], lo[1] : hi[1], lo[2] : hi[2]] = True
    return Volume(mask, _affine()), lo, hi


def _rectangle(shape: tuple[int, int], rows: tuple[int, int], cols: tuple[int, int]) -> np.ndarray:
    out = np.zeros(shape, dtype=bool)
    out[rows[0] : rows[1], cols[0] : cols[1]] = True
    return out


def test_projections_from_volume_of_box_are_rectangles() -> None:
    volume, lo, hi = _box_volume()
    proj = projections_from_volume(volume)
    assert proj.source == "volume"
    shape = volume.shape
    for a in range(3):
        r, c = (ax for ax in range(3) if ax != a)
        expected = _rectangle((shape[r], shape[c]), (lo[r], hi[r]), (lo[c], hi[c]))
        np.testing.assert_array_equal(proj[a].image, expected)
        assert proj[a].axis == a
    with pytest.raises(EmptyMaskError):
        projections_from_volume(Volume(np.zeros((4, 4, 4), dtype=bool)))


def test_projections_from_sections_of_box_span_first_to_last_plane() -> None:
    volume, lo, hi = _box_volume()
    sections = sample_sections(volume, every=5)  # planes 3, 8, 13, 18 (19 left out)
    last = int(sections.indices[-1])
    assert last == 18
    proj = projections_from_sections(sections)
    assert proj.source == "sections"
    shape = volume.shape
    np.testing.assert_array_equal(
        proj["z"].image, _rectangle((shape[0], shape[1]), (lo[0], hi[0]), (lo[1], hi[1]))
    )
    np.testing.assert_array_equal(
        proj["x"].image, _rectangle((shape[1], shape[2]), (lo[1], hi[1]), (lo[2], last + 1))
    )
    np.testing.assert_array_equal(
        proj["y"].image, _rectangle((shape[0], shape[2]), (lo[0], hi[0]), (lo[2], last + 1))
    )


def test_projections_from_all_planes_equal_volume_projections(ball: Volume) -> None:
    derived = projections_from_sections(sample_sections(ball))
    truth = projections_from_volume(ball)
    for a in range(3):
        np.testing.assert_array_equal(derived[a].image, truth[a].image)


def test_sphere_side_views_from_16_planes(ball: Volume) -> None:
    derived = projections_from_sections(sample_sections(ball, n=16))
    truth = projections_from_volume(ball)
    for a in (0, 1):
        grown = ndimage.binary_dilation(truth[a].image, np.ones((3, 3), dtype=bool))
        assert not np.any(derived[a].image & ~grown)  # inside the silhouette up to one pixel
        assert _iou(derived[a].image, truth[a].image) >= 0.98  # measured 0.990


def test_cone_side_views_match_within_one_pixel() -> None:
    i, j, k = np.ogrid[:61, :61, :45]
    radius = 28.0 * (1.0 - k / 44.0)  # apex at plane 44, base radius 28 voxels at plane 0
    cone = Volume((i - 30.0) ** 2 + (j - 30.0) ** 2 <= radius**2, np.eye(4))
    sections = sample_sections(cone, n=8)
    derived = projections_from_sections(sections)
    truth = projections_from_volume(cone)
    first, last = int(sections.indices[0]), int(sections.indices[-1])
    square = np.ones((3, 3), dtype=bool)
    for a in (0, 1):
        d, t = derived[a].image, truth[a].image[:, first : last + 1]
        assert not np.any(d & ~ndimage.binary_dilation(truth[a].image, square))
        assert not np.any(t & ~ndimage.binary_dilation(d, square)[:, first : last + 1])


def _sections_of_intervals(
    intervals: list[tuple[int, int] | None], indices: list[float], n_rows: int = 12
) -> CrossSections:
    """Planes perpendicular to z whose masks hold y-intervals over x rows 2..5."""
    masks = np.zeros((len(intervals), 8, 40), dtype=bool)
    for plane, span in enumerate(intervals):
        if span is not None:
            masks[plane, 2:6, span[0] : span[1]] = True
    return CrossSections(masks, indices, 2, np.eye(4), (8, 40, n_rows))


def test_side_view_morphs_intervals_between_fractional_planes() -> None:
    # [10, 30) at z = 0.25 grows by one pixel per side and unit of z to [6, 34) at 4.25.
    sections = _sections_of_intervals([(10, 30), (6, 34)], [0.25, 4.25])
    view = projections_from_sections(sections)["x"].image  # rows y, columns z
    assert view.shape == (40, 12)
    expected = np.zeros_like(view)
    for g in range(1, 5):
        expected[10 - g : 30 + g, g] = True
    expected[10:30, 0] = True  # the voxel layer holding the first plane (z = 0.25) holds it
    np.testing.assert_array_equal(view, expected)
    other = projections_from_sections(sections)["y"].image  # rows x, columns z
    np.testing.assert_array_equal(other, _rectangle((8, 12), (2, 6), (0, 5)))


def test_side_view_stops_at_empty_planes() -> None:
    sections = _sections_of_intervals([(10, 20), None, (12, 22)], [0.0, 4.0, 8.0])
    view = projections_from_sections(sections)["x"].image
    assert view[10:20, 0].all() and view[12:22, 8].all()
    assert not view[:, 1:8].any()
    with pytest.raises(EmptyMaskError):
        projections_from_sections(_sections_of_intervals([None, None], [1.0, 3.0]))


def test_single_fractional_plane_lands_on_nearest_row() -> None:
    sections = _sections_of_intervals([(10, 20)], [6.4])
    view = projections_from_sections(sections)["x"].image
    expected = np.zeros_like(view)
    expected[10:20, 6] = True
    np.testing.assert_array_equal(view, expected)


@pytest.mark.parametrize("factor", [1, 2, 3, 5])
def test_pool_any_sets_a_cell_exactly_when_its_block_holds_a_voxel(factor: int) -> None:
    from slicerecon.sampling import pool_any

    rng = np.random.default_rng(3)
    mask = rng.random((13, 7, 11)) > 0.97
    pooled = pool_any(mask, factor)
    assert pooled.shape == tuple(-(-n // factor) for n in mask.shape)
    for index in np.ndindex(pooled.shape):
        block = mask[tuple(slice(i * factor, (i + 1) * factor) for i in index)]
        assert pooled[index] == block.any()


def test_pooled_sections_keep_their_planes_in_millimetres(ball: Volume) -> None:
    """Pooling moves each plane to the coarse index of the same world position; masks are
    any-pooled in-plane; the grid is ceil(shape / factor)."""
    sections = sample_sections(ball, n=7, axis="z")
    assert pool_sections(sections, 1) is sections
    coarse = pool_sections(sections, 3)
    assert coarse.grid_shape == (37, 37, 17)
    for fine_idx, coarse_idx, mask, fine in zip(
        sections.indices, coarse.indices, coarse.masks, sections.masks, strict=True
    ):
        fine_world = sections.affine @ np.array([54.0, 55.0, fine_idx, 1.0])
        coarse_world = coarse.affine @ np.array(
            [(54.0 + 0.5) / 3 - 0.5, (55.5) / 3 - 0.5, coarse_idx, 1.0]
        )
        np.testing.assert_allclose(coarse_world, fine_world, atol=1e-9)
        np.testing.assert_array_equal(mask, pool_any(fine, 3))
    with pytest.raises(OptionError):
        pool_sections(sections, 0)
