"""Extension slabs: parts follow the visual hull from their outermost plane to their box face."""

from __future__ import annotations

import numpy as np
import pytest

from slicerecon.errors import GeometryError
from slicerecon.options import ReconstructOptions
from slicerecon.rasterize import mesh_to_mask
from slicerecon.sampling import projections_from_volume, visual_hull
from slicerecon.sections import Box, CrossSections, Volume
from slicerecon.shapes.primitives import slanted_rod
from slicerecon.surface.extension import LayerMap, extension_maps, interpolate_maps
from slicerecon.surface.loft import loft_solid
from slicerecon.surface.part import reconstruct_part


def _linear(method: str) -> ReconstructOptions:
    """A per-part method with classic linear interpolation and no drift joining."""
    return ReconstructOptions(method=method, interpolation="linear", join_drift=False)


def _tube(slope: float, radius: float = 6.0, shape: tuple[int, int, int] = (60, 30, 64)) -> Volume:
    """A straight tube along z whose axis drifts by ``slope`` voxels along x per layer."""
    return slanted_rod(radius=radius, slope=slope, shape=shape, start=12.0)


def _sections(volume: Volume, planes: list[int]) -> CrossSections:
    masks = np.stack([volume.mask[:, :, p] for p in planes])
    return CrossSections(
        masks, np.asarray(planes, dtype=np.float64), 2, volume.affine, volume.shape
    )


def _hull(volume: Volume) -> np.ndarray:
    return visual_hull(projections_from_volume(volume), volume.shape)


def _iou_in_layers(mesh, volume: Volume, layers: np.ndarray) -> float:  # type: ignore[no-untyped-def]
    pred = mesh_to_mask(mesh, volume.affine, volume.shape)[:, :, layers]
    truth = volume.mask[:, :, layers]
    return float((pred & truth).sum() / (pred | truth).sum())


def test_a_hull_of_constant_extent_gives_the_prism() -> None:
    tube = _tube(slope=0.0)
    hull = _hull(tube)
    box = Box((0, 0, 2), (60, 30, 62))
    maps = extension_maps(hull, box, 2, 30.0, 1)
    assert len(maps) == 1 and maps[0].is_identity() and maps[0].w == pytest.approx(61.5)
    sections = _sections(tube, [20, 30])
    with_hull = loft_solid(sections, box=box, extend_to_box=True, hull=hull)
    prism = loft_solid(sections, box=box, extend_to_box=True)
    assert with_hull is not None and prism is not None
    assert with_hull.volume() == pytest.approx(prism.volume(), rel=1e-9)


@pytest.mark.parametrize("method", ["loft", "sdf"])
def test_extension_follows_a_slanted_tube(method: str) -> None:
    # Planes at z = 24 and 40 only; the box reaches z = 2..62, so about 20
    # layers on each side have no section. The tube drifts 0.5 voxel per layer:
    # a prism misses it by up to 11 voxels (more than its radius), the
    # hull-guided extension follows it. (Between the planes the SDF blend of a
    # moving disc is known to thin out; only the extension slabs are scored.)
    tube = _tube(slope=0.5)
    sections = _sections(tube, [24, 40])
    box = Box((0, 0, 2), (60, 30, 62))
    guided = reconstruct_part(sections, box, _linear(method), hull=_hull(tube))
    prism = reconstruct_part(sections, box, _linear(method))
    assert guided is not None and prism is not None
    assert guided.is_watertight and guided.is_volume
    assert len(guided.split(only_watertight=False)) == 1
    slabs = np.r_[2:24, 41:62]
    assert _iou_in_layers(guided, tube, slabs) >= 0.85
    assert _iou_in_layers(prism, tube, slabs) <= 0.5


def test_maps_are_monotone_and_invertible() -> None:
    source = np.array([[10.0, 20.0], [5.0, 25.0]])
    target = np.array([[14.0, 34.0], [5.0, 15.0]])
    layer = LayerMap(3.0, source, target)
    # A circle reaching past the source extent on every side.
    t = np.linspace(0.0, 2.0 * np.pi, 90, endpoint=False)
    circle = np.column_stack([15.0 + 8.0 * np.cos(t), 15.0 + 14.0 * np.sin(t)])
    mapped = layer.forward(circle)
    np.testing.assert_allclose(layer.inverse(mapped), circle, atol=1e-12)
    # Monotone per axis: the order of coordinates is kept, so the polygon
    # stays simple and counter-clockwise.
    for ax in (0, 1):
        order = np.argsort(circle[:, ax], kind="stable")
        assert np.all(np.diff(mapped[order, ax]) >= -1e-12)
    area = 0.5 * np.sum(
        mapped[:, 0] * np.roll(mapped[:, 1], -1) - mapped[:, 1] * np.roll(mapped[:, 0], -1)
    )
    assert area > 0
    # Extent edges land on the target edges; beyond them points move with the nearer edge.
    np.testing.assert_allclose(
        layer.forward(np.array([[10.0, 5.0], [20.0, 25.0]])), [[14.0, 5.0], [34.0, 15.0]]
    )
    np.testing.assert_allclose(layer.forward(np.array([[8.0, 27.0]])), [[12.0, 17.0]])


def test_interpolated_maps_are_linear_in_w() -> None:
    source = np.array([[0.0, 10.0], [0.0, 10.0]])
    maps = [LayerMap(0.0, source, source), LayerMap(4.0, source, source + 8.0)]
    middle = interpolate_maps(maps, 1.0)
    np.testing.assert_allclose(middle.target, source + 2.0)
    np.testing.assert_allclose(interpolate_maps(maps, 9.0).target, source + 8.0)


def test_a_hull_on_another_grid_is_refused() -> None:
    tube = _tube(slope=0.0)
    sections = _sections(tube, [20, 30])
    with pytest.raises(GeometryError, match="grid"):
        loft_solid(
            sections,
            box=Box((0, 0, 2), (60, 30, 62)),
            extend_to_box=True,
            hull=np.ones((4, 4, 4), dtype=bool),
        )


def test_maps_follow_a_hull_that_narrows_along_x() -> None:
    # Sections perpendicular to x (axis 0): in-plane axes are y and z. The hull
    # narrows linearly in y away from the anchor layer, by one voxel per layer
    # on each side.
    hull = np.zeros((12, 40, 10), dtype=bool)
    for i in range(12):
        half = 15 - i
        hull[i, 20 - half : 20 + half, 2:8] = True
    box = Box((0, 0, 0), (12, 40, 10))
    maps = extension_maps(hull, box, 0, 2.0, 1)  # anchor plane at x = 2, slab up to 11.5
    assert [m.w for m in maps][-1] == pytest.approx(11.5)
    # On layer i the y extent is [20 - half, 20 + half) in pixels, i.e. edges
    # 19.5 - half .. 19.5 + half; z keeps its extent.
    for m in maps[:-1]:
        half = 15 - m.w
        np.testing.assert_allclose(m.target[0], (19.5 - half, 19.5 + half))
        np.testing.assert_allclose(m.target[1], (1.5, 7.5))
    # A point half-way to the upper y edge on the plane stays half-way.
    layer = maps[3]
    (y0, y1), (s0, s1) = layer.target[0], layer.source[0]
    mid = layer.forward(np.array([[0.5 * (s0 + s1) + 0.25 * (s1 - s0), 4.0]]))
    assert mid[0, 0] == pytest.approx(0.5 * (y0 + y1) + 0.25 * (y1 - y0))


def test_loft_and_sdf_extensions_agree() -> None:
    # Both surface methods carry the same contour through the same maps, so
    # their extension slabs hold nearly the same voxels.
    tube = _tube(slope=0.5)
    sections = _sections(tube, [24, 40])
    box = Box((0, 0, 2), (60, 30, 62))
    hull = _hull(tube)
    slabs = np.r_[2:24, 41:62]
    masks = []
    for method in ("loft", "sdf"):
        mesh = reconstruct_part(sections, box, _linear(method), hull=hull)
        masks.append(mesh_to_mask(mesh, tube.affine, tube.shape)[:, :, slabs])
    agreement = (masks[0] & masks[1]).sum() / (masks[0] | masks[1]).sum()
    assert agreement >= 0.9


@pytest.mark.parametrize("method", ["loft", "sdf"])
def test_a_plane_on_the_box_face_needs_no_extension(method: str) -> None:
    # Contour inputs put planes at any position; one exactly on a face (2.5
    # is the lower face of a box starting at index 3) has no slab to fill.
    tube = _tube(slope=0.0)
    masks = np.stack([tube.mask[:, :, 10]] * 3)
    sections = CrossSections(masks, np.array([2.5, 10.0, 20.0]), 2, tube.affine, tube.shape)
    box = Box((0, 0, 3), (60, 30, 25))
    mesh = reconstruct_part(sections, box, _linear(method), hull=_hull(tube))
    assert mesh is not None and mesh.is_watertight and mesh.is_volume
    z = mesh.bounds[:, 2]
    assert z[0] == pytest.approx(2.5, abs=0.51) and z[1] == pytest.approx(24.5, abs=0.51)
