"""Lofting: closed, outward meshes with the right volume, topology and extent."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from slicerecon import shapes
from slicerecon.errors import EmptyMaskError, InputError, OptionError
from slicerecon.rasterize import mesh_to_mask
from slicerecon.sampling import sample_sections
from slicerecon.sections import Box, CrossSections, Volume
from slicerecon.surface.loft import loft, loft_solid


def _closed(mesh: trimesh.Trimesh) -> None:
    assert mesh.is_watertight
    assert mesh.is_winding_consistent
    assert mesh.is_volume
    assert mesh.volume > 0


def _iou(mesh: trimesh.Trimesh, volume: Volume) -> float:
    pred = mesh_to_mask(mesh, volume.affine, volume.shape)
    return float((pred & volume.mask).sum() / (pred | volume.mask).sum())


@pytest.fixture(scope="module")
def sphere() -> Volume:
    return shapes.sphere(40.0)


def test_sphere_volume_within_3_percent(sphere: Volume) -> None:
    # Acceptance criterion: 16 planes from the first to the last occupied plane,
    # ends extended to the sphere's box (half a voxel beyond the end planes).
    sections = sample_sections(sphere, n=16)
    mesh = loft(sections, box=Box.of_mask(sphere.mask), extend_to_box=True)
    _closed(mesh)
    assert mesh.volume == pytest.approx(sphere.volume_mm3, rel=0.03)
    assert len(mesh.split(only_watertight=False)) == 1
    assert mesh.euler_number == 2  # a sphere: genus 0


def test_sphere_without_box_is_capped_at_end_planes(sphere: Volume) -> None:
    sections = sample_sections(sphere, n=16)
    mesh = loft(sections)
    _closed(mesh)
    assert mesh.volume == pytest.approx(sphere.volume_mm3, rel=0.03)
    # Flat caps exactly at the first and last plane (world z = index - 42.5 here).
    z = sphere.index_to_world(
        np.array([[0, 0, sections.indices[0]], [0, 0, sections.indices[-1]]])
    )[:, 2]
    assert mesh.bounds[0, 2] == pytest.approx(z[0])
    assert mesh.bounds[1, 2] == pytest.approx(z[1])


def test_box_shape_is_exact() -> None:
    # Rectangular contours lie on pixel edges except at the 4 corners, which
    # marching squares cuts by 1/8 pixel each; prisms reach the box faces. So a
    # voxel cuboid comes back exactly, less those corner prisms.
    cuboid = shapes.box((30.0, 20.0, 24.0))
    sections = sample_sections(cuboid, n=5)
    mesh = loft(sections, box=Box.of_mask(cuboid.mask), extend_to_box=True)
    _closed(mesh)
    assert mesh.volume == pytest.approx((30 * 20 - 4 / 8) * 24, rel=1e-12)


def test_torus_perpendicular_keeps_its_hole() -> None:
    # z-planes cut the torus in annuli: outer contour plus a hole.
    torus = shapes.torus(30.0, 10.0)
    sections = sample_sections(torus, n=12, axis="z")
    mesh = loft(sections, box=Box.of_mask(torus.mask), extend_to_box=True)
    _closed(mesh)
    assert mesh.euler_number == 0  # genus 1: the hole goes through
    assert len(mesh.split(only_watertight=False)) == 1
    assert mesh.volume == pytest.approx(torus.volume_mm3, rel=0.03)


def test_torus_parallel_branches_and_merges() -> None:
    # x-planes cut the torus in one blob at the ends and two blobs in between.
    torus = shapes.torus(30.0, 10.0)
    sections = sample_sections(torus, n=12, axis="x")
    blobs = [len(np.unique(_labels(m))) - 1 for m in sections.masks]
    assert min(blobs) == 1 and max(blobs) == 2
    mesh = loft(sections, box=Box.of_mask(torus.mask), extend_to_box=True)
    _closed(mesh)
    assert mesh.euler_number == 0
    assert len(mesh.split(only_watertight=False)) == 1
    assert _iou(mesh, torus) > 0.9


def test_y_branch_one_to_two() -> None:
    vessel = shapes.y_branch()
    sections = sample_sections(vessel, n=16, axis="z")
    assert len(np.unique(_labels(sections.masks[0]))) - 1 == 1
    assert len(np.unique(_labels(sections.masks[-1]))) - 1 == 2
    mesh = loft(sections, box=Box.of_mask(vessel.mask), extend_to_box=True)
    _closed(mesh)
    assert len(mesh.split(only_watertight=False)) == 1
    assert mesh.euler_number == 2
    assert _iou(mesh, vessel) > 0.9


def test_appearing_component_closes_half_way() -> None:
    # A rod along z over the whole range, and a ball beside it in the middle.
    mask = np.zeros((40, 30, 60), dtype=bool)
    mask[5:11, 10:16, 2:58] = True
    i, j, k = np.ogrid[:40, :30, :60]
    mask |= (i - 28) ** 2 + (j - 15) ** 2 + (k - 30) ** 2 <= 7**2
    planes = np.arange(2, 58, 6)
    sections = CrossSections(
        mask[:, :, planes].transpose(2, 0, 1), planes, 2, np.eye(4), mask.shape
    )
    mesh = loft(sections)
    _closed(mesh)
    parts = sorted(mesh.split(only_watertight=False), key=lambda m: m.bounds[0, 0])
    assert len(parts) == 2
    ball = parts[1]
    with_ball = planes[sections.masks[:, 20:, :].any(axis=(1, 2))]
    gap = 6.0
    # Unmatched contours close with a cone whose apex is half-way to the next plane.
    assert ball.bounds[0, 2] == pytest.approx(with_ball[0] - gap / 2)
    assert ball.bounds[1, 2] == pytest.approx(with_ball[-1] + gap / 2)


@pytest.mark.parametrize("axis", [0, 1, 2])
@pytest.mark.parametrize(
    "diagonal",
    [(0.8, 1.2, 2.5), (-0.8, 1.2, 2.5), (1.0, -1.0, -0.5)],
    ids=["aniso", "flip", "flip2"],
)
def test_anisotropic_and_mirrored_affines(sphere: Volume, axis: int, diagonal) -> None:
    volume = Volume(sphere.mask, np.diag([*diagonal, 1.0]))
    sections = sample_sections(volume, n=16, axis=axis)
    mesh = loft(sections, box=Box.of_mask(volume.mask), extend_to_box=True)
    _closed(mesh)
    assert mesh.volume == pytest.approx(volume.volume_mm3, rel=0.03)
    # The mesh overlays the mask in world mm.
    centre = volume.index_to_world(np.argwhere(volume.mask).mean(axis=0))
    assert np.allclose(mesh.center_mass, centre, atol=0.5)


def test_oblique_affine(sphere: Volume) -> None:
    angle = np.deg2rad(30.0)
    rot = np.array(
        [[np.cos(angle), -np.sin(angle), 0.0], [np.sin(angle), np.cos(angle), 0.0], [0.0, 0.0, 1.0]]
    )
    affine = np.eye(4)
    affine[:3, :3] = rot @ np.diag([0.7, 0.7, 2.0])
    affine[:3, 3] = (10.0, -5.0, 3.0)
    volume = Volume(sphere.mask, affine)
    mesh = loft(sample_sections(volume, n=16), box=Box.of_mask(volume.mask), extend_to_box=True)
    _closed(mesh)
    assert mesh.volume == pytest.approx(volume.volume_mm3, rel=0.03)
    assert _iou(mesh, volume) > 0.95


def test_single_plane_is_one_voxel_thick_slab() -> None:
    masks = np.zeros((1, 20, 30), dtype=bool)
    masks[0, 4:12, 5:20] = True
    affine = np.diag([0.5, 0.5, 3.0, 1.0])
    sections = CrossSections(masks, [7.0], 2, affine, (20, 30, 15))
    mesh = loft(sections)
    _closed(mesh)
    assert mesh.volume == pytest.approx((8 * 15 - 4 / 8) * 0.25 * 3.0, rel=1e-12)
    assert mesh.bounds[:, 2] == pytest.approx([6.5 * 3.0, 7.5 * 3.0])


def test_fractional_non_uniform_planes_span_first_to_last() -> None:
    masks = np.zeros((3, 20, 20), dtype=bool)
    masks[:, 5:15, 5:15] = True
    sections = CrossSections(masks, [10.5, 13.25, 20.0], 2, np.eye(4), (20, 20, 30))
    mesh = loft(sections)
    _closed(mesh)
    assert mesh.volume == pytest.approx((100.0 - 4 / 8) * (20.0 - 10.5), rel=1e-12)


def test_box_between_planes_uses_the_crossing_slab(sphere: Volume) -> None:
    sections = sample_sections(sphere, every=10)  # planes 3, 13, 23, ...
    full = Box.of_mask(sphere.mask)
    thin = Box((full.lo[0], full.lo[1], 40), (full.hi[0], full.hi[1], 43))
    assert not np.any((sections.indices >= 39.5) & (sections.indices <= 42.5))
    mesh = loft(sections, box=thin, extend_to_box=True)
    _closed(mesh)
    assert mesh.bounds[:, 2] == pytest.approx([39.5 - 42.5, 42.5 - 42.5])
    with pytest.raises(EmptyMaskError):
        loft(sections, box=thin, extend_to_box=False)


def test_empty_inputs_raise_or_return_none(sphere: Volume) -> None:
    empty = CrossSections(np.zeros((3, 10, 10), dtype=bool), [1, 4, 7], 2, np.eye(4), (10, 10, 9))
    with pytest.raises(EmptyMaskError):
        loft(empty)
    assert loft_solid(empty) is None
    sections = sample_sections(sphere, n=16)
    corner = Box((0, 0, 0), (5, 5, 86))
    assert loft_solid(sections, box=corner, extend_to_box=True) is None
    with pytest.raises(EmptyMaskError, match="inside the box"):
        loft(sections, box=corner)


def test_bad_arguments(sphere: Volume) -> None:
    sections = sample_sections(sphere, n=4)
    with pytest.raises(InputError):
        loft(sphere.mask)  # type: ignore[arg-type]
    with pytest.raises(InputError):
        loft(sections, box=((0, 0, 0), (5, 5, 5)))  # type: ignore[arg-type]
    with pytest.raises(OptionError, match="outside the reference grid"):
        loft(sections, box=Box((100, 100, 100), (110, 110, 110)))
    with pytest.raises(OptionError):
        loft(sections, extend_to_box="yes")  # type: ignore[arg-type]


def _labels(mask: np.ndarray) -> np.ndarray:
    from scipy import ndimage

    return ndimage.label(mask)[0]
