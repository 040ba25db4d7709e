"""Polygons on parallel planes -> CrossSections: grouping, grids, even-odd filling."""

from __future__ import annotations

import numpy as np
import pytest

from slicerecon.errors import EmptyMaskError, GeometryError, InputError, OptionError
from slicerecon.io.polygons import (
    polygon_normal,
    polygons_from_sections,
    rasterize_polygons,
    sections_from_polygons,
)
from slicerecon.sections import CrossSections, Volume


def circle(radius, centre, *, n=720, u=(1.0, 0.0, 0.0), v=(0.0, 1.0, 0.0)):
    """Counter-clockwise regular n-gon inscribed in a circle, in the plane spanned by u, v."""
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    return (
        np.asarray(centre, float)
        + radius * np.cos(t)[:, None] * np.asarray(u, float)
        + radius * np.sin(t)[:, None] * np.asarray(v, float)
    )


def ngon_area(radius, n=720):
    return 0.5 * n * radius**2 * np.sin(2.0 * np.pi / n)


def square(lo, hi, z):
    return np.array([[lo, lo, z], [hi, lo, z], [hi, hi, z], [lo, hi, z]], float)


def test_newell_normal_and_area_of_tilted_square():
    rot = np.array([[1, 0, 0], [0, np.cos(0.3), -np.sin(0.3)], [0, np.sin(0.3), np.cos(0.3)]])
    pts = square(0.0, 4.0, 0.0) @ rot.T
    normal, area = polygon_normal(pts)
    np.testing.assert_allclose(normal, rot @ [0, 0, 1], atol=1e-12)
    assert area == pytest.approx(16.0, rel=1e-12)


def test_axis_aligned_square_covers_whole_pixels():
    cs = sections_from_polygons([square(0.0, 10.0, 5.0)], pixel_spacing=1.0)
    assert cs.axis == 2 and cs.n_planes == 1
    np.testing.assert_allclose(cs.affine[:3, :3], np.eye(3))  # single plane: 1 mm step
    assert cs.positions[0] == pytest.approx(5.0, abs=1e-12)
    assert cs.area_mm2(0) == pytest.approx(100.0, abs=1e-9)  # exactly 10 x 10 pixels
    # 2-pixel margin of background on every side
    fg = np.argwhere(cs.masks[0])
    assert fg.min(axis=0).tolist() == [2, 2]
    assert (np.array(cs.masks.shape[1:]) - 1 - fg.max(axis=0)).tolist() == [2, 2]


def test_default_pixel_spacing_is_extent_over_256():
    cs = sections_from_polygons([square(-20.0, 31.2, 0.0)])
    assert cs.spacing[0] == pytest.approx(51.2 / 256)
    assert cs.masks.shape[1:] == (260, 260)


def test_nested_polygons_fill_even_odd_whatever_their_winding():
    outer = square(0.0, 30.0, 0.0)
    hole = square(5.0, 25.0, 0.0)  # same winding as the outer one
    island = square(10.0, 20.0, 0.0)[::-1]  # opposite winding
    cs = sections_from_polygons([outer, hole, island], pixel_spacing=1.0)
    assert cs.area_mm2(0) == pytest.approx(900 - 400 + 100, abs=1e-9)
    origin = cs.affine[:2, 3]
    centre = np.round(np.array([15.0, 15.0]) - origin).astype(int)
    in_hole = np.round(np.array([7.0, 15.0]) - origin).astype(int)
    assert cs.masks[0][tuple(centre)] and not cs.masks[0][tuple(in_hole)]


def test_ring_area_matches_analytic_value():
    ring = [circle(20.0, (3.0, -4.0, 7.0)), circle(8.0, (5.0, -2.0, 7.0))]
    cs = sections_from_polygons(ring, pixel_spacing=0.1)
    expected = ngon_area(20.0) - ngon_area(8.0)
    assert cs.area_mm2(0) == pytest.approx(expected, rel=0.01)


def test_planes_are_grouped_sorted_and_irregular_gaps_kept():
    polys = [circle(5.0, (0, 0, z)) for z in (5.0, -1.0, 1.0)]
    polys.append(circle(3.0, (0.0, 20.0, 5.0 + 1e-4)))  # same plane within 0.01 mm
    polys.append(circle(2.0, (20.0, 0.0, 1.0)))  # second island on the plane z = 1
    cs = sections_from_polygons(polys, pixel_spacing=0.5)
    np.testing.assert_allclose(cs.positions, [-1.0, 1.0, 5.0], atol=1e-4)
    np.testing.assert_array_equal(cs.indices, [0.0, 1.0, 3.0])  # snapped within 0.01 mm
    np.testing.assert_allclose(cs.gaps, [2.0, 4.0], atol=1e-4)
    assert cs.grid_shape[2] == 4
    assert cs.area_mm2(1) > cs.area_mm2(0)  # the island counts
    assert cs.area_mm2(2) > cs.area_mm2(0)


@pytest.mark.parametrize(
    ("normal", "in_plane"),
    [((1.0, 0.0, 0.0), (1, 2)), ((0.0, 1.0, 0.0), (2, 0)), ((0.0, 0.0, -1.0), (0, 1))],
)
def test_axis_aligned_contours_give_an_axis_aligned_right_handed_grid(normal, in_plane):
    n = np.asarray(normal)
    u, v = np.eye(3)[in_plane[0]], np.eye(3)[in_plane[1]]
    polys = [circle(6.0, 10.0 * d * np.abs(n) + 1.0, u=u, v=v) for d in (0, 1, 3)]
    cs = sections_from_polygons(polys, pixel_spacing=0.25)
    assert np.linalg.det(cs.affine[:3, :3]) > 0
    assert not Volume(np.ones(cs.grid_shape, bool), cs.affine).is_oblique
    np.testing.assert_allclose(cs.normal, np.abs(n))  # oriented along +axis
    np.testing.assert_allclose(cs.positions, [1.0, 11.0, 31.0], atol=1e-9)


def test_given_normal_fixes_direction_and_empty_planes():
    polys = [circle(6.0, (0, 0, z)) for z in (2.0, 4.0)]
    cs = sections_from_polygons(polys, normal=(0, 0, -1), empty_positions=[-8.0], pixel_spacing=0.5)
    np.testing.assert_allclose(cs.normal, [0, 0, -1], atol=1e-12)
    # positions along -z: z = 8 (empty), 4, 2
    np.testing.assert_allclose(cs.positions, [-8.0, -4.0, -2.0], atol=1e-9)
    np.testing.assert_allclose(cs.indices, [0.0, 2.0, 3.0], atol=1e-9)
    assert not cs.masks[0].any() and cs.masks[1].any() and cs.masks[2].any()


def test_oblique_stack():
    n = np.array([1.0, 2.0, 2.0]) / 3.0
    u = np.cross(n, [1.0, 0.0, 0.0])
    u /= np.linalg.norm(u)
    v = np.cross(n, u)
    polys = [circle(10.0, 4.0 * d * n + (3, 1, 2), u=u, v=v) for d in range(4)]
    cs = sections_from_polygons(polys, pixel_spacing=0.2)
    np.testing.assert_allclose(cs.normal, n, atol=1e-9)
    np.testing.assert_allclose(cs.gaps, 4.0, atol=1e-9)
    for p in range(4):
        assert cs.area_mm2(p) == pytest.approx(ngon_area(10.0), rel=0.01)


def test_reference_grid_indices_and_pixels():
    affine = np.diag([0.5, 0.5, 2.0, 1.0])
    affine[:3, 3] = (-20.0, -20.0, -10.0)
    polys = [square(-5.25, 4.75, z) for z in (-6.0, 0.0, 2.0)]
    cs = sections_from_polygons(polys, reference=(affine, (80, 80, 12)))
    assert cs.grid_shape == (80, 80, 12) and cs.axis == 2
    np.testing.assert_array_equal(cs.indices, [2.0, 5.0, 6.0])
    assert cs.is_on_grid
    # pixel centres -5 .. 4.5 (i = 30 .. 49) are inside
    np.testing.assert_array_equal(np.flatnonzero(cs.masks[0].any(axis=1)), np.arange(30, 50))
    np.testing.assert_array_equal(cs.to_volume().occupied_planes(), [2, 5, 6])


def test_contours_beside_the_reference_grid_are_not_said_to_be_too_small():
    """Contours given in voxel indices, not mm, lay beside the image grid in its planes:
    the error said "smaller than a pixel; choose a smaller pixel_spacing", an option that
    a reference grid ignores."""
    affine = np.diag([0.5, 0.5, 2.0, 1.0])
    affine[:3, 3] = (-20.0, -20.0, -10.0)
    polys = [square(30.0, 38.0, z) for z in (-6.0, 0.0)]  # in-plane beyond -20 .. 20 mm
    with pytest.raises(EmptyMaskError, match="lie beside it in its planes") as info:
        sections_from_polygons(polys, reference=(affine, (80, 80, 12)))
    assert "pixel_spacing" not in str(info.value)


def test_reference_grid_along_another_axis():
    affine = np.diag([2.0, 1.0, 1.0, 1.0])
    polys = [np.array([[x, 2, 2], [x, 8, 2], [x, 8, 9], [x, 2, 9]], float) for x in (4.0, 10.0)]
    cs = sections_from_polygons(polys, reference=(affine, (10, 12, 12)))
    assert cs.axis == 0
    np.testing.assert_array_equal(cs.indices, [2.0, 5.0])
    assert cs.area_mm2(0) == pytest.approx(42.0)


def test_round_trip_through_polygons_is_exact():
    i, j, k = np.mgrid[0:24, 0:20, 0:9]
    ball = (i - 11.3) ** 2 + (j - 9.6) ** 2 + 4 * (k - 4.2) ** 2 < 60
    shell = ball & ~((i - 11.3) ** 2 + (j - 9.6) ** 2 + 4 * (k - 4.2) ** 2 < 15)
    affine = np.array([[0, 0.9, 0, 4], [0.9, 0, 0, -3], [0, 0, -2.5, 7], [0, 0, 0, 1.0]])
    planes = [1, 3, 4, 7]
    original = CrossSections(np.moveaxis(shell, 2, 0)[planes], planes, 2, affine, shell.shape)
    polys = [ring for _, rings in polygons_from_sections(original) for ring in rings]
    back = sections_from_polygons(polys, reference=(affine, shell.shape))
    np.testing.assert_array_equal(back.indices, original.indices)
    np.testing.assert_array_equal(back.masks, original.masks)


def test_rasterize_half_open_rule_on_pixel_centres():
    mask = rasterize_polygons([[[1, 1], [4, 1], [4, 3], [1, 3]]], (6, 5))
    expected = np.zeros((6, 5), bool)
    expected[1:4, 1:3] = True
    np.testing.assert_array_equal(mask, expected)


def test_not_parallel_planes_raise_geometry_error():
    tilted = circle(5.0, (0, 0, 3), v=(0, np.cos(0.2), np.sin(0.2)))
    with pytest.raises(GeometryError, match="not on parallel planes: polygon 1 is tilted 10.8°"):
        sections_from_polygons([circle(20.0, (0, 0, 0)), tilted])


def test_slight_tilt_within_tolerance_is_accepted():
    tilted = circle(5.0, (0, 0, 3), v=(0, np.cos(0.005), np.sin(0.005)))
    cs = sections_from_polygons([circle(5.0, (0, 0, 0)), tilted], pixel_spacing=0.5)
    assert cs.n_planes == 2


def test_non_planar_polygon_raises_geometry_error():
    bent = square(0.0, 10.0, 0.0)
    bent[2, 2] = 0.5
    with pytest.raises(GeometryError, match="polygon 0 is not planar"):
        sections_from_polygons([bent], axis_tolerance_deg=10.0)


def test_planes_not_parallel_to_reference_grid():
    with pytest.raises(GeometryError, match="not parallel to any slice direction"):
        sections_from_polygons(
            [circle(5.0, (0, 0, 0), v=(0, 0.8, 0.6))], reference=(np.eye(4), (20, 20, 20))
        )


def test_plane_outside_reference_grid():
    with pytest.raises(GeometryError, match="outside the image grid"):
        sections_from_polygons([square(1, 5, 40.0)], reference=(np.eye(4), (10, 10, 10)))


def test_empty_and_bad_input():
    with pytest.raises(EmptyMaskError, match="no contours given"):
        sections_from_polygons([])
    with pytest.raises(EmptyMaskError, match="encloses any area"):
        sections_from_polygons([[[0, 0, 0], [1, 1, 0], [2, 2, 0]]])
    with pytest.raises(EmptyMaskError, match="smaller than a pixel"):
        sections_from_polygons([square(0.1, 0.2, 0.0)], pixel_spacing=1.0)
    with pytest.raises(InputError, match="polygon 1: a polygon needs at least 3 points"):
        sections_from_polygons([square(0, 1, 0), [[0, 0, 0], [1, 0, 0]]])
    with pytest.raises(InputError, match="NaN"):
        sections_from_polygons([[[0, 0, 0], [1, 0, np.nan], [0, 1, 0]]])
    with pytest.raises(InputError, match=r"\(N, 3\)"):
        sections_from_polygons([[[0, 0], [1, 0], [0, 1]]])
    with pytest.raises(OptionError, match="pixel_spacing"):
        sections_from_polygons([square(0, 1, 0)], pixel_spacing=0.0)
    with pytest.raises(OptionError, match="pixel_spacing .* gives"):
        sections_from_polygons([square(0, 1000, 0)], pixel_spacing=0.01)
    with pytest.raises(OptionError, match="normal"):
        sections_from_polygons([square(0, 1, 0)], empty_positions=[3.0])


def test_rasterize_matches_point_in_polygon_on_random_star_polygons():
    from skimage.measure import points_in_poly

    rng = np.random.default_rng(7)
    a, b = np.mgrid[0:64, 0:48]
    centres = np.c_[a.ravel(), b.ravel()].astype(float)
    for _ in range(20):
        t = np.sort(rng.uniform(0, 2 * np.pi, 40))
        r = rng.uniform(5, 22, 40)
        poly = np.c_[32.3 + r * np.cos(t), 23.7 + r * np.sin(t)]
        expected = points_in_poly(centres, poly).reshape(a.shape)
        np.testing.assert_array_equal(rasterize_polygons([poly], a.shape), expected)
