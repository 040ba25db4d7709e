"""The data model: geometry, validation and conversions of Volume / CrossSections / Box."""

from __future__ import annotations

import numpy as np
import pytest

from slicerecon import (
    Box,
    CrossSections,
    EmptyMaskError,
    GeometryError,
    InputError,
    OptionError,
    Projection,
    Projections,
    Volume,
)
from slicerecon.sections import axis_index


def _rotation(seed: int) -> np.ndarray:
    q, r = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def _oblique_affine(spacing=(0.8, 1.1, 2.5), origin=(-12.0, 30.0, 7.5), seed=3) -> np.ndarray:
    aff = np.eye(4)
    aff[:3, :3] = _rotation(seed) * np.asarray(spacing)
    aff[:3, 3] = origin
    return aff


def test_volume_geometry_follows_affine():
    mask = np.zeros((10, 12, 8), bool)
    mask[2:5, 3:9, 1:7] = True
    aff = _oblique_affine()
    vol = Volume(mask, aff)
    np.testing.assert_allclose(vol.spacing, (0.8, 1.1, 2.5))
    assert vol.voxel_volume == pytest.approx(0.8 * 1.1 * 2.5)
    assert vol.volume_mm3 == pytest.approx(3 * 6 * 6 * 0.8 * 1.1 * 2.5)
    assert vol.is_oblique
    assert not Volume(mask, np.diag([0.8, 1.1, 2.5, 1.0])).is_oblique
    pts = np.array([[0, 0, 0], [9, 11, 7], [2.5, 3.25, 1.0]])
    np.testing.assert_allclose(vol.world_to_index(vol.index_to_world(pts)), pts, atol=1e-9)
    lo, hi = vol.bounding_box_vox()
    assert lo.tolist() == [2, 3, 1] and hi.tolist() == [5, 9, 7]
    np.testing.assert_array_equal(vol.occupied_planes("z"), np.arange(1, 7))


def test_volume_is_readonly_copy():
    mask = np.zeros((4, 4, 4), bool)
    vol = Volume(mask)
    mask[0, 0, 0] = True
    assert not vol.mask.any()
    with pytest.raises(ValueError):
        vol.mask[0, 0, 0] = True


def test_crop_and_pad_keep_world_positions():
    mask = np.zeros((20, 20, 20), bool)
    mask[5:9, 6:12, 10:13] = True
    vol = Volume(mask, _oblique_affine())
    cropped = vol.crop(pad=1)
    assert cropped.shape == (6, 8, 5)
    assert np.count_nonzero(cropped.mask) == np.count_nonzero(mask)
    # A foreground voxel keeps its world position.
    np.testing.assert_allclose(
        cropped.index_to_world([1, 1, 1]), vol.index_to_world([5, 6, 10]), atol=1e-9
    )
    padded = cropped.pad(3)
    np.testing.assert_allclose(
        padded.index_to_world([4, 4, 4]), vol.index_to_world([5, 6, 10]), atol=1e-9
    )


@pytest.mark.parametrize(
    ("mask", "affine", "error", "words"),
    [
        (np.zeros((3, 3)), np.eye(4), InputError, "3-D"),
        (np.full((3, 3, 3), 2), np.eye(4), InputError, "binary"),
        (np.zeros((3, 3, 3)), np.zeros((4, 4)), GeometryError, "last row"),
        (np.zeros((3, 3, 3)), np.diag([1, 0, 1, 1]), GeometryError, "singular"),
        (np.zeros((3, 3, 3)), np.full((4, 4), np.nan), GeometryError, "NaN"),
    ],
)
def test_volume_rejects_bad_input_with_clear_errors(mask, affine, error, words):
    with pytest.raises(error, match=words):
        Volume(mask, affine)


def test_empty_volume_bounding_box_is_a_clear_error():
    with pytest.raises(EmptyMaskError, match="empty"):
        Volume(np.zeros((3, 3, 3), bool)).bounding_box_vox()


def test_axis_names():
    assert [axis_index(a) for a in ("x", "Y", "z", 0, 2, -1)] == [0, 1, 2, 0, 2, 2]
    with pytest.raises(OptionError):
        axis_index("w")
    with pytest.raises(OptionError):
        axis_index(3)


def _ring_sections() -> CrossSections:
    yy, xx = np.mgrid[0:40, 0:40]
    r = np.hypot(xx - 19.5, yy - 19.5)
    ring = (r < 15) & (r > 6)
    masks = np.stack([ring, ring, r < 10])
    aff = np.diag([0.5, 0.5, 3.0, 1.0])
    aff[:3, 3] = (10.0, -5.0, 100.0)
    return CrossSections(masks, [2.0, 5.0, 6.0], "z", aff, (40, 40, 10))


def test_planes_in_a_box_include_its_faces_and_bridge_empty_boxes():
    cs = _ring_sections()  # planes at z = 2, 5, 6
    # A box [lo, hi) spans lo - 0.5 .. hi - 0.5 along z: planes on faces count.
    np.testing.assert_array_equal(cs.planes_in(Box((0, 0, 0), (40, 40, 10))), [0, 1, 2])
    np.testing.assert_array_equal(cs.planes_in(Box((0, 0, 3), (40, 40, 6))), [1])
    np.testing.assert_array_equal(cs.planes_in(Box((0, 0, 6), (40, 40, 7))), [2])
    between = Box((0, 0, 3), (40, 40, 5))  # 2.5 .. 4.5: no plane
    assert cs.planes_in(between).size == 0
    np.testing.assert_array_equal(cs.planes_in(between, bridge=True), [0, 1])
    beyond = Box((0, 0, 7), (40, 40, 10))  # past the last plane: nothing to bridge
    assert cs.planes_in(beyond, bridge=True).size == 0


def test_cross_sections_positions_and_gaps_in_mm():
    cs = _ring_sections()
    np.testing.assert_allclose(cs.normal, (0, 0, 1))
    np.testing.assert_allclose(cs.positions, (106.0, 115.0, 118.0))
    np.testing.assert_allclose(cs.gaps, (9.0, 3.0))
    assert cs.plane_axes == (0, 1)
    np.testing.assert_allclose(
        cs.plane_to_world(1, [[0, 0], [2, 4]]), [[10, -5, 115], [11, -3, 115]]
    )


def test_contours_flag_holes_and_match_area():
    cs = _ring_sections()
    contours = cs.contours(0)
    assert sorted(c.is_hole for c in contours) == [False, True]
    # Signed shoelace area: outer positive, hole negative; their sum ~ pixel count.
    total = 0.0
    for c in contours:
        x, y = c.points_px[:, 0], c.points_px[:, 1]
        total += 0.5 * (np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))
    assert total == pytest.approx(np.count_nonzero(cs.masks[0]), rel=0.03)
    assert cs.area_mm2(0) == pytest.approx(np.count_nonzero(cs.masks[0]) * 0.25)


def test_cross_sections_to_volume_round_trip():
    cs = _ring_sections()
    vol = cs.to_volume()
    assert vol.shape == (40, 40, 10)
    np.testing.assert_array_equal(vol.occupied_planes("z"), [2, 5, 6])
    np.testing.assert_array_equal(vol.mask[:, :, 5], cs.masks[1])
    sub = cs.select([0, 2])
    np.testing.assert_allclose(sub.positions, (106.0, 118.0))


def test_cross_sections_validation():
    masks = np.zeros((2, 5, 6), bool)
    with pytest.raises(GeometryError, match="increasing"):
        CrossSections(masks, [3, 3], 2, np.eye(4), (5, 6, 9))
    with pytest.raises(GeometryError, match="positions"):
        CrossSections(masks, [1, 2, 3], 2, np.eye(4), (5, 6, 9))
    with pytest.raises(GeometryError, match="does not match"):
        CrossSections(masks, [1, 2], 0, np.eye(4), (5, 6, 9))
    off_grid = CrossSections(masks, [1.0, 2.5], 2, np.eye(4), (5, 6, 9))
    assert not off_grid.is_on_grid
    with pytest.raises(GeometryError, match="between grid"):
        off_grid.to_volume()
    with pytest.raises(EmptyMaskError):
        off_grid.require_foreground()


def test_box_arithmetic():
    box = Box((1, 2, 3), (4, 6, 9))
    assert box.shape == (3, 4, 6) and box.n_voxels == 72
    assert box.intersect(Box((3, 0, 0), (10, 3, 4))) == Box((3, 2, 3), (4, 3, 4))
    assert box.intersect(Box((4, 0, 0), (5, 5, 5))) is None
    assert box.contains_index([[0.5, 1.5, 2.5], [3.6, 2, 3]]).tolist() == [True, False]
    mask = np.zeros((6, 7, 10), bool)
    mask[box.slices] = True
    assert Box.of_mask(mask) == box
    with pytest.raises(GeometryError):
        Box((0, 0, 0), (1, 0, 1))


def test_projections_container():
    views = tuple(Projection(np.ones((3, 4), bool), a, np.eye(4)) for a in range(3))
    proj = Projections(views, source="volume")
    assert proj["z"] is views[2] and len(proj) == 3
    np.testing.assert_allclose(views[2].pixel_spacing, (1, 1))
    with pytest.raises(GeometryError):
        Projections(views[::-1])


def test_atomic_writes_get_normal_permissions(tmp_path) -> None:  # type: ignore[no-untyped-def]
    import os
    import stat

    from slicerecon.io.atomic import atomic_path

    umask = os.umask(0o022)
    try:
        with atomic_path(tmp_path / "a.txt") as tmp:
            tmp.write_text("x")
    finally:
        os.umask(umask)
    assert stat.S_IMODE((tmp_path / "a.txt").stat().st_mode) == 0o644
    assert [p.name for p in tmp_path.iterdir()] == ["a.txt"]


def test_world_bounds_are_those_of_the_voxels_on_an_oblique_grid() -> None:
    """On a grid turned 30°, the corners of the voxels' index box reach beyond the
    voxels: `info` put a liver 19 mm further than its voxels. The bounds are now those
    of the voxel centres themselves, as ``slicerecon info`` reports them."""
    turn = np.radians(30.0)
    affine = np.eye(4)
    affine[:3, :3] = [[np.cos(turn), -np.sin(turn), 0], [np.sin(turn), np.cos(turn), 0], [0, 0, 2]]
    ijk = np.indices((30, 30, 10))
    ball = ((ijk[0] - 15) ** 2 + (ijk[1] - 15) ** 2 + (2 * (ijk[2] - 5)) ** 2) < 64
    lo, hi = Volume(ball, affine).bounding_box_mm()
    centres = np.argwhere(ball) @ affine[:3, :3].T + affine[:3, 3]
    np.testing.assert_allclose(lo, centres.min(axis=0))
    np.testing.assert_allclose(hi, centres.max(axis=0))
