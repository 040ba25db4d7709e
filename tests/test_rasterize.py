"""Tests for slicerecon.rasterize: voxel-centre occupancy of closed meshes."""

from __future__ import annotations

import time

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from slicerecon.errors import GeometryError, OptionError
from slicerecon.rasterize import mesh_to_mask


def _centred_affine(linear: np.ndarray, shape: tuple[int, int, int]) -> np.ndarray:
    """Affine with the given 3x3 part whose grid centre sits at the world origin."""
    affine = np.eye(4)
    affine[:3, :3] = linear
    affine[:3, 3] = -linear @ ((np.asarray(shape) - 1) / 2.0)
    return affine


def _voxel_centres(affine: np.ndarray, shape: tuple[int, int, int]) -> np.ndarray:
    ijk = np.indices(shape).reshape(3, -1).T.astype(np.float64)
    return ijk @ affine[:3, :3].T + affine[:3, 3]


def _convex_signed_distance(mesh: trimesh.Trimesh, points: np.ndarray) -> np.ndarray:
    """Max over face planes of the signed distance: < 0 exactly inside a convex mesh.

    ``mesh`` must be convex and contain the origin. Points well inside the
    in-sphere or outside the circumsphere are decided from their radius alone.
    """
    normals = mesh.face_normals
    offsets = np.einsum("ij,ij->i", normals, mesh.triangles[:, 0])
    radius = np.linalg.norm(points, axis=1)
    inner, outer = offsets.min(), np.linalg.norm(mesh.vertices, axis=1).max()
    # off the shell between in- and circumsphere, only the sign of this is exact
    out = np.where(radius < inner, radius - inner, radius - outer)
    shell = (radius >= inner - 1e-3) & (radius <= outer + 1e-3)
    out[shell] = (points[shell] @ normals.T - offsets).max(axis=1)
    return out


@pytest.fixture(scope="module")
def oblique_sphere_case():
    radius = 20.0
    sphere = trimesh.creation.icosphere(subdivisions=4, radius=radius)
    rotation = Rotation.random(random_state=np.random.default_rng(7)).as_matrix()
    spacing = np.array([0.7, 0.9, 1.3])
    shape = (66, 52, 38)  # covers the sphere in every rotated direction
    affine = _centred_affine(rotation @ np.diag(spacing), shape)
    mask = mesh_to_mask(sphere, affine, shape)
    return sphere, affine, shape, mask


def test_oblique_anisotropic_sphere_volume_within_2_percent(oblique_sphere_case):
    sphere, affine, _, mask = oblique_sphere_case
    voxel_volume = abs(np.linalg.det(affine[:3, :3]))
    measured = np.count_nonzero(mask) * voxel_volume
    analytic = 4.0 / 3.0 * np.pi * 20.0**3
    assert measured == pytest.approx(analytic, rel=0.02)
    # the polyhedron itself is ~0.2% smaller than the ideal sphere; stay closer to it
    assert measured == pytest.approx(sphere.volume, rel=0.01)


def test_oblique_sphere_matches_exact_convex_inside_test(oblique_sphere_case):
    sphere, affine, shape, mask = oblique_sphere_case
    distance = _convex_signed_distance(sphere, _voxel_centres(affine, shape))
    np.testing.assert_array_equal(mask.ravel(), distance < 0)


def test_oblique_sphere_agrees_with_trimesh_contains(oblique_sphere_case):
    sphere, affine, shape, mask = oblique_sphere_case
    rng = np.random.default_rng(3)
    centres = _voxel_centres(affine, shape)
    # trimesh.contains may use float32 ray casting: keep points clear of the surface
    clear = np.abs(_convex_signed_distance(sphere, centres)) > 1e-3
    pick = rng.choice(np.flatnonzero(clear), size=3000, replace=False)
    expected = sphere.contains(centres[pick])
    np.testing.assert_array_equal(mask.ravel()[pick], expected)
    assert expected.any() and not expected.all()


def test_box_between_voxel_centres_gives_exact_count():
    # spacing (0.5, 1, 2) mm, origin at 0: centres at 0, 0.5, 1.0, ... along x
    affine = np.diag([0.5, 1.0, 2.0, 1.0])
    box = trimesh.creation.box(bounds=[[1.25, 2.5, 3.0], [4.25, 9.5, 13.0]])
    mask = mesh_to_mask(box, affine, (12, 12, 10))
    # x centres 1.5..4.0 -> 6; y centres 3..9 -> 7; z centres 4..12 -> 5
    assert np.count_nonzero(mask) == 6 * 7 * 5
    expected = np.zeros((12, 12, 10), dtype=bool)
    expected[3:9, 3:10, 2:7] = True
    np.testing.assert_array_equal(mask, expected)


def test_box_faces_on_voxel_centres_follow_half_open_rule():
    # every face passes exactly through voxel centres, and rays hit triangle
    # diagonals and vertices exactly: the result is still exact and deterministic
    box = trimesh.creation.box(bounds=[[2.0, 3.0, 4.0], [7.0, 9.0, 10.0]])
    mask = mesh_to_mask(box, np.eye(4), (12, 12, 12))
    expected = np.zeros((12, 12, 12), dtype=bool)
    expected[2:7, 3:9, 4:10] = True
    np.testing.assert_array_equal(mask, expected)


def test_nonconvex_torus_on_mirrored_grid_matches_mesh_volume():
    torus = trimesh.creation.torus(major_radius=15.0, minor_radius=5.0)
    assert torus.is_watertight
    shape = (80, 80, 24)
    # LPS-like grid: x and y axes mirrored, plus a small oblique tilt
    tilt = Rotation.from_euler("x", 10, degrees=True).as_matrix()
    affine = _centred_affine(tilt @ np.diag([-0.6, -0.6, 1.2]), shape)
    mask = mesh_to_mask(torus, affine, shape)
    measured = np.count_nonzero(mask) * abs(np.linalg.det(affine[:3, :3]))
    assert measured == pytest.approx(torus.volume, rel=0.02)
    # the hole of the torus (around the grid centre) is empty
    assert not mask[38:42, 38:42, :].any()


def test_mesh_larger_than_grid_fills_it_and_mesh_outside_grid_leaves_it_empty():
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=50.0)
    shape = (8, 9, 10)
    inner = _centred_affine(np.eye(3), shape)
    assert mesh_to_mask(sphere, inner, shape).all()
    outside = inner.copy()
    outside[:3, 3] += 200.0
    assert not mesh_to_mask(sphere, outside, shape).any()


def test_open_mesh_raises_geometry_error():
    sphere = trimesh.creation.icosphere(subdivisions=2, radius=5.0)
    open_mesh = trimesh.Trimesh(sphere.vertices, sphere.faces[1:], process=False)
    with pytest.raises(GeometryError, match=r"not closed \(3 open edges") as info:
        mesh_to_mask(open_mesh, np.eye(4), (4, 4, 4))
    assert "repair" in str(info.value)


def test_bad_grid_arguments_raise_clear_errors():
    sphere = trimesh.creation.icosphere(subdivisions=1, radius=2.0)
    with pytest.raises(GeometryError, match="singular"):
        mesh_to_mask(sphere, np.diag([1.0, 0.0, 1.0, 1.0]), (4, 4, 4))
    with pytest.raises(OptionError, match="three positive integers"):
        mesh_to_mask(sphere, np.eye(4), (4, 0, 4))


def test_256_cubed_grid_with_80k_faces_is_fast():
    sphere = trimesh.creation.icosphere(subdivisions=6, radius=100.0)  # 81,920 faces
    shape = (256, 256, 256)
    affine = _centred_affine(np.diag([0.85, 0.85, 0.85]), shape)
    start = time.perf_counter()
    mask = mesh_to_mask(sphere, affine, shape)
    elapsed = time.perf_counter() - start
    assert np.count_nonzero(mask) * 0.85**3 == pytest.approx(sphere.volume, rel=0.005)
    assert elapsed < 15.0, f"rasterizing took {elapsed:.1f} s"
