"""Exact unions with manifold3d, conversions, and Taubin smoothing."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from slicerecon import shapes
from slicerecon.errors import EmptyMaskError, GeometryError, InputError, OptionError
from slicerecon.surface.marching import volume_to_mesh
from slicerecon.surface.merge import from_manifold, to_manifold, union_meshes
from slicerecon.surface.smooth import taubin_smooth


def _box(lo, hi) -> trimesh.Trimesh:
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    centre = trimesh.transformations.translation_matrix((lo + hi) / 2)
    return trimesh.creation.box(extents=hi - lo, transform=centre)


def _closed(mesh: trimesh.Trimesh) -> None:
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.is_volume
    assert mesh.volume > 0


def test_union_of_overlapping_boxes_is_exact() -> None:
    merged = union_meshes([_box((0, 0, 0), (2, 2, 2)), _box((1, 1, 1), (3, 3, 3))])
    _closed(merged)
    assert merged.volume == pytest.approx(8 + 8 - 1, rel=1e-12)


def test_union_of_boxes_sharing_a_face_fuses_them() -> None:
    merged = union_meshes([_box((0, 0, 0), (2, 2, 2)), _box((2, 0, 0), (5, 1, 2))])
    _closed(merged)
    assert merged.volume == pytest.approx(8 + 6, rel=1e-12)
    assert len(merged.split(only_watertight=False)) == 1
    assert merged.euler_number == 2


def test_union_keeps_disjoint_components() -> None:
    merged = union_meshes([_box((0, 0, 0), (1, 1, 1)), _box((5, 5, 5), (6, 7, 6))])
    _closed(merged)
    assert len(merged.split(only_watertight=False)) == 2
    assert merged.volume == pytest.approx(3.0)


def test_union_drops_empty_inputs_and_fixes_inverted_ones() -> None:
    inverted = _box((0, 0, 0), (1, 2, 3))
    inverted.invert()
    assert inverted.volume < 0
    merged = union_meshes([None, trimesh.Trimesh(), inverted])  # type: ignore[list-item]
    _closed(merged)
    assert merged.volume == pytest.approx(6.0)


def test_union_errors() -> None:
    with pytest.raises(EmptyMaskError):
        union_meshes([])
    with pytest.raises(EmptyMaskError):
        union_meshes([trimesh.Trimesh()])
    open_box = _box((0, 0, 0), (1, 1, 1))
    open_box = trimesh.Trimesh(open_box.vertices, open_box.faces[:-2])
    with pytest.raises(GeometryError, match="mesh 1"):
        union_meshes([_box((0, 0, 0), (1, 1, 1)), open_box])
    with pytest.raises(InputError):
        union_meshes(["not a mesh"])  # type: ignore[list-item]


def test_from_manifold_keeps_outward_faces_under_a_mirror() -> None:
    solid = to_manifold(_box((0, 0, 0), (1, 2, 3)))
    mirror = np.diag([-2.0, 1.0, 1.0, 1.0])
    mesh = from_manifold(solid, transform=mirror)
    _closed(mesh)
    assert mesh.volume == pytest.approx(12.0)
    assert mesh.bounds[:, 0] == pytest.approx([-2.0, 0.0])


# -- smoothing ------------------------------------------------------------------------
def test_taubin_smoothing_keeps_the_sphere_closed_and_its_volume() -> None:
    ball = shapes.sphere(20.0)
    mesh = volume_to_mesh(ball)
    smoothed = taubin_smooth(mesh, iterations=10)
    _closed(smoothed)
    assert np.array_equal(smoothed.faces, mesh.faces)
    assert not np.allclose(smoothed.vertices, mesh.vertices)
    change = smoothed.volume / mesh.volume - 1.0
    assert abs(change) < 0.01  # measured: about -0.2 %
    # The staircase is smoothed out: vertex radii spread less around the mean.
    radii = np.linalg.norm(mesh.vertices - mesh.center_mass, axis=1)
    smooth_radii = np.linalg.norm(smoothed.vertices - smoothed.center_mass, axis=1)
    assert smooth_radii.std() < 0.8 * radii.std()


def test_taubin_leaves_input_untouched_and_checks_options() -> None:
    mesh = _box((0, 0, 0), (1, 1, 1))
    before = mesh.vertices.copy()
    assert np.array_equal(taubin_smooth(mesh, iterations=0).vertices, before)
    taubin_smooth(mesh, iterations=3)
    assert np.array_equal(mesh.vertices, before)
    for bad in (
        dict(iterations=-1),
        dict(iterations=1.5),
        dict(lamb=1.2),
        dict(mu=-0.3),
        dict(mu=0.5),
    ):
        with pytest.raises(OptionError):
            taubin_smooth(mesh, **bad)  # type: ignore[arg-type]
    with pytest.raises(InputError):
        taubin_smooth("mesh")  # type: ignore[arg-type]
