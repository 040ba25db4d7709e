"""Tests for slicerecon.surface.marching: watertight marching-cubes meshes in world mm."""

from __future__ import annotations

import numpy as np
import pytest

from slicerecon.errors import EmptyMaskError, GeometryError, InputError, OptionError
from slicerecon.sections import Volume
from slicerecon.surface.marching import field_to_mesh, volume_to_mesh

RADIUS = 20.0
SPACING = np.array([0.7, 0.9, 1.3])
SPHERE_VOLUME = 4.0 / 3.0 * np.pi * RADIUS**3


def _grid(spacing: np.ndarray, centre: np.ndarray, *, flip_x: bool = False):
    """Shape and affine of a grid covering a sphere of RADIUS around ``centre`` (mm)."""
    shape = tuple(int(n) for n in np.ceil(2 * (RADIUS + 3) / spacing))
    linear = np.diag(spacing * np.array([-1.0 if flip_x else 1.0, 1.0, 1.0]))
    affine = np.eye(4)
    affine[:3, :3] = linear
    affine[:3, 3] = centre - linear @ ((np.asarray(shape) - 1) / 2.0 + 0.3)
    return shape, affine


def _world_centres(shape, affine) -> np.ndarray:
    ijk = np.indices(shape).reshape(3, -1).T.astype(np.float64)
    return (ijk @ affine[:3, :3].T + affine[:3, 3]).reshape(*shape, 3)


def _sphere_volume(*, flip_x: bool = False) -> tuple[Volume, np.ndarray]:
    centre = np.array([10.0, -5.0, 30.0])
    shape, affine = _grid(SPACING, centre, flip_x=flip_x)
    dist = np.linalg.norm(_world_centres(shape, affine) - centre, axis=-1)
    return Volume(dist <= RADIUS, affine), centre


@pytest.fixture(scope="module")
def sphere():
    volume, centre = _sphere_volume()
    return volume, centre, volume_to_mesh(volume)


def test_sphere_mesh_is_closed_volume(sphere):
    _, _, mesh = sphere
    assert mesh.is_watertight
    assert mesh.is_winding_consistent
    assert mesh.is_volume
    # merged duplicate vertices: every vertex position is unique
    assert len(np.unique(mesh.vertices, axis=0)) == len(mesh.vertices)


def test_sphere_volume_within_3_percent(sphere):
    _, _, mesh = sphere
    assert mesh.volume > 0
    assert mesh.volume == pytest.approx(SPHERE_VOLUME, rel=0.03)


def test_sphere_vertices_within_one_voxel_of_radius(sphere):
    _, centre, mesh = sphere
    radius = np.linalg.norm(mesh.vertices - centre, axis=1)
    assert np.abs(radius - RADIUS).max() <= SPACING.max()
    # and the surface is centred where the sphere is, in world mm
    np.testing.assert_allclose(mesh.vertices.mean(axis=0), centre, atol=0.1)


def test_negative_determinant_affine_keeps_outward_orientation():
    volume, centre = _sphere_volume(flip_x=True)
    assert np.linalg.det(volume.affine[:3, :3]) < 0
    mesh = volume_to_mesh(volume)
    assert mesh.is_volume
    assert mesh.volume == pytest.approx(SPHERE_VOLUME, rel=0.03)
    normals_out = np.einsum("ij,ij->i", mesh.face_normals, mesh.triangles_center - centre)
    assert np.mean(normals_out > 0) > 0.99


def test_mask_touching_the_grid_border_is_closed():
    mask = np.ones((4, 5, 6), dtype=bool)
    affine = np.diag([2.0, 1.0, 0.5, 1.0])
    mesh = volume_to_mesh(Volume(mask, affine))
    assert mesh.is_volume
    # surface half a voxel beyond the outer centres along each axis: a 8 x 5 x 3 mm box,
    # minus the corners marching cubes cuts off
    assert mesh.bounds[0] == pytest.approx([-1.0, -0.5, -0.25])
    assert mesh.bounds[1] == pytest.approx([7.0, 4.5, 2.75])
    assert 0.8 * 120.0 < mesh.volume < 120.0


@pytest.mark.parametrize("step", [2, 3])
def test_step_size_keeps_the_mesh_closed(sphere, step):
    volume, _, _ = sphere
    mesh = volume_to_mesh(volume, step_size=step)
    assert mesh.is_volume
    assert mesh.volume == pytest.approx(SPHERE_VOLUME, rel=0.08)


def test_cavity_and_two_components_are_kept():
    mask = np.zeros((20, 12, 12), dtype=bool)
    mask[1:9, 1:9, 1:9] = True
    mask[3:6, 3:6, 3:6] = False  # a closed cavity inside the first cube
    mask[11:19, 2:10, 2:10] = True
    mesh = volume_to_mesh(Volume(mask))
    assert mesh.is_volume
    assert len(mesh.split(only_watertight=False)) == 3
    # the cavity subtracts: the mesh encloses roughly the foreground voxel count
    assert mesh.volume == pytest.approx(np.count_nonzero(mask), rel=0.1)


def test_empty_mask_raises():
    with pytest.raises(EmptyMaskError, match="empty"):
        volume_to_mesh(Volume(np.zeros((4, 4, 4), dtype=bool)))


@pytest.mark.parametrize("kwargs", [{"level": 1.0}, {"level": 0.0}, {"step_size": 0}])
def test_bad_options_raise(kwargs):
    mask = np.zeros((4, 4, 4), dtype=bool)
    mask[1:3, 1:3, 1:3] = True
    with pytest.raises(OptionError):
        volume_to_mesh(Volume(mask), **kwargs)


def test_not_a_volume_raises():
    with pytest.raises(InputError, match="Volume"):
        volume_to_mesh(np.ones((3, 3, 3), dtype=bool))  # type: ignore[arg-type]


@pytest.mark.parametrize("flip_x", [False, True])
def test_signed_distance_field_sphere_is_accurate(flip_x):
    centre = np.array([0.0, 0.0, 0.0])
    shape, affine = _grid(SPACING, centre, flip_x=flip_x)
    sdf = np.linalg.norm(_world_centres(shape, affine) - centre, axis=-1) - RADIUS
    mesh = field_to_mesh(sdf, affine)
    assert mesh.is_volume
    # interpolated iso-surface of an exact distance: far tighter than a voxel
    radius = np.linalg.norm(mesh.vertices - centre, axis=1)
    assert np.abs(radius - RADIUS).max() < 0.05
    assert mesh.volume == pytest.approx(SPHERE_VOLUME, rel=0.01)
    inverted = field_to_mesh(-sdf, affine, inside="positive")
    assert inverted.volume == pytest.approx(mesh.volume, rel=1e-9)


def test_field_values_on_the_level_give_a_closed_mesh():
    # integer-valued distance field: many samples lie exactly on the level
    ijk = np.indices((15, 15, 15)) - 7
    field = np.abs(ijk).max(axis=0).astype(float) - 4.0
    mesh = field_to_mesh(field, np.eye(4))
    assert mesh.is_volume
    assert len(mesh.split(only_watertight=False)) == 1
    # the iso-surface is the cube |x|_inf = 4 with edges and corners cut by
    # marching cubes (at most one voxel deep): between the 7^3 and 8^3 cubes
    assert np.abs(mesh.vertices - 7.0).max() == pytest.approx(4.0, abs=1e-4)
    assert 7.0**3 < mesh.volume < 8.0**3


def test_field_reaching_the_border_is_capped():
    field = -np.ones((5, 5, 5))
    mesh = field_to_mesh(field, np.eye(4))
    assert mesh.is_volume
    assert np.all(mesh.bounds[0] < 0) and np.all(mesh.bounds[1] > 4)


def test_bad_fields_raise():
    with pytest.raises(EmptyMaskError):
        field_to_mesh(np.ones((4, 4, 4)), np.eye(4))
    with pytest.raises(InputError, match="NaN"):
        field_to_mesh(np.full((4, 4, 4), np.nan), np.eye(4))
    with pytest.raises(InputError, match="3-D"):
        field_to_mesh(np.zeros((4, 4)), np.eye(4))
    with pytest.raises(OptionError, match="inside"):
        field_to_mesh(-np.ones((4, 4, 4)), np.eye(4), inside="in")  # type: ignore[arg-type]
    with pytest.raises(GeometryError, match="singular"):
        field_to_mesh(-np.ones((4, 4, 4)), np.diag([1.0, 0.0, 1.0, 1.0]))


def test_noisy_masks_still_give_closed_manifold_surfaces() -> None:
    # Random masks hit marching-cubes configurations that skimage resolves with
    # edges shared by four faces; volume_to_mesh must repair them.
    rng = np.random.default_rng(0)
    for _ in range(20):
        mask = rng.random((10, 10, 10)) < 0.45
        volume = Volume(mask, np.diag([0.8, 0.9, 2.0, 1.0]))
        mesh = volume_to_mesh(volume)
        assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
        edges = np.sort(mesh.edges, axis=1)
        _, counts = np.unique(edges, axis=0, return_counts=True)
        assert np.all(counts == 2)


def test_folded_real_mask_is_repaired_with_a_handful_of_voxels() -> None:
    # The MNI152 white matter at 2 mm hits the ambiguous configurations; the
    # repair fills only blocks next to the offending edges.
    pytest.importorskip("nilearn")
    from slicerecon.realshapes import mni152
    from slicerecon.surface.marching import _repair_ambiguous_blocks

    wm = mni152("wm", resolution=96)
    mesh = volume_to_mesh(wm)
    assert mesh.is_watertight and mesh.is_winding_consistent
    fixed, added = _repair_ambiguous_blocks(wm.mask, level=0.5)
    assert np.all(fixed[wm.mask])
    assert added < 1e-3 * wm.mask.sum()


def test_march_field_repairs_the_non_manifold_edges_of_equal_magnitude_fields() -> None:
    # A field of +-0.5 only (what the implicit carve and cover leave near the hull)
    # makes scikit-image emit edges shared by four faces; the repair makes the
    # ambiguous blocks inside and marches again, in place.
    from slicerecon.surface.marching import march_field

    rng = np.random.default_rng(0)
    field = np.full((6, 6, 6), 0.5, dtype=np.float32)
    field[1:5, 1:5, 1:5] = np.where(rng.random((4, 4, 4)) < 0.5, -0.5, 0.5)
    before = field.copy()
    assert not march_field(field.copy(), np.eye(4), repair=False).is_watertight
    mesh = march_field(field, np.eye(4))
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
    changed = (field < 0) != (before < 0)
    assert 0 < changed.sum() <= 16  # a few samples, all made inside
    assert np.all(field[changed] < 0)
    assert np.all(field[[0, -1], :, :] > 0) and np.all(field[:, :, [0, -1]] > 0)
