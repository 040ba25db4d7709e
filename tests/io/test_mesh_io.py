"""Tests for slicerecon.io.mesh: mesh files, atomic writing, voxelization."""

from __future__ import annotations

import pathlib

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

from slicerecon.errors import EmptyMaskError, FormatError, GeometryError, InputError, OptionError
from slicerecon.io.mesh import read_mesh, read_mesh_volume, voxelize_mesh, write_mesh


def _pymeshlab_samples() -> pathlib.Path | None:
    try:
        import pymeshlab
    except ImportError:
        return None
    folder = pathlib.Path(pymeshlab.__file__).parent / "tests" / "sample_meshes"
    return folder if folder.is_dir() else None


@pytest.fixture()
def sphere() -> trimesh.Trimesh:
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=12.5)
    mesh.apply_translation([-40.0, 15.25, 120.0])  # world mm, away from the origin
    return mesh


@pytest.mark.parametrize("suffix", [".stl", ".ply", ".obj", ".off", ".STL"])
def test_round_trip_preserves_vertices_and_watertightness(tmp_path, sphere, suffix):
    path = write_mesh(sphere, tmp_path / "out" / f"sphere{suffix}")
    assert [p.name for p in path.parent.iterdir()] == [f"sphere{suffix}"]  # no temp left
    back = read_mesh(path)
    assert back.is_watertight
    assert len(back.vertices) == len(sphere.vertices)
    assert len(back.faces) == len(sphere.faces)
    # STL does not keep vertex order: compare vertex sets both ways
    dist_there, _ = cKDTree(sphere.vertices).query(back.vertices)
    dist_back, _ = cKDTree(back.vertices).query(sphere.vertices)
    assert max(dist_there.max(), dist_back.max()) < 1e-5
    assert back.volume == pytest.approx(sphere.volume, rel=1e-6)


def test_explicit_format_and_bad_format_options(tmp_path, sphere):
    path = write_mesh(sphere, tmp_path / "mesh.bin", file_format="PLY")
    assert path.read_bytes().startswith(b"ply")
    with pytest.raises(OptionError, match="cannot tell the mesh format"):
        write_mesh(sphere, tmp_path / "mesh.vtk")
    with pytest.raises(OptionError, match="unknown mesh format"):
        write_mesh(sphere, tmp_path / "mesh.vtk", file_format="vtk")
    with pytest.raises(OptionError, match="contradicts the suffix"):
        write_mesh(sphere, tmp_path / "mesh.stl", file_format="obj")
    with pytest.raises(InputError, match="no faces"):
        write_mesh(trimesh.Trimesh(), tmp_path / "empty.stl")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["mesh.bin"]


def test_scene_with_two_objects_is_concatenated(tmp_path):
    a = trimesh.creation.box(extents=(2.0, 2.0, 2.0))
    b = trimesh.creation.icosphere(radius=1.0).apply_translation([5.0, 0.0, 0.0])
    path = tmp_path / "scene.obj"
    trimesh.Scene({"box": a, "ball": b}).export(path)
    mesh = read_mesh(path)
    assert len(mesh.faces) == len(a.faces) + len(b.faces)
    assert mesh.volume == pytest.approx(a.volume + b.volume, rel=1e-6)


def test_voxelized_sphere_volume_within_2_percent(sphere):
    volume = voxelize_mesh(sphere, resolution=64, pad=3)
    analytic = 4.0 / 3.0 * np.pi * 12.5**3
    assert volume.volume_mm3 == pytest.approx(analytic, rel=0.02)
    # isotropic, world-aligned, longest side / resolution
    np.testing.assert_allclose(volume.spacing, 25.0 / 64 * np.ones(3), rtol=1e-3)
    assert not volume.is_oblique
    # `pad` empty voxels on every side, and the grid is centred on the mesh
    lo, hi = volume.bounding_box_vox()
    assert np.all(lo >= 3) and np.all(np.asarray(volume.shape) - hi >= 3)
    centre = volume.index_to_world((np.asarray(volume.shape) - 1) / 2.0)
    np.testing.assert_allclose(centre, sphere.bounds.mean(axis=0), atol=1e-9)


def test_voxelize_with_pitch(sphere):
    volume = voxelize_mesh(sphere, pitch=0.5, pad=0)
    np.testing.assert_allclose(volume.spacing, 0.5)
    assert volume.shape == (50, 50, 50)
    assert volume.volume_mm3 == pytest.approx(sphere.volume, rel=0.02)


def test_voxelize_bad_options_and_tiny_mesh(sphere):
    with pytest.raises(OptionError, match="pitch"):
        voxelize_mesh(sphere, pitch=-1.0)
    with pytest.raises(OptionError, match="resolution"):
        voxelize_mesh(sphere, resolution=0)
    with pytest.raises(OptionError, match="pad"):
        voxelize_mesh(sphere, pad=-1)
    with pytest.raises(OptionError, match="larger pitch"):
        voxelize_mesh(sphere, pitch=1e-3)
    # a thin ring: the 3 mm grid's centres (multiples of 3 mm from the ring's
    # centre) all lie more than 0.5 mm from its circular core
    ring = trimesh.creation.torus(major_radius=10.0, minor_radius=0.2)
    with pytest.raises(EmptyMaskError, match="smaller pitch"):
        voxelize_mesh(ring, pitch=3.0)


def test_open_mesh_gives_clear_geometry_error(tmp_path, sphere):
    holed = trimesh.Trimesh(sphere.vertices, sphere.faces[1:], process=False)
    with pytest.raises(GeometryError, match=r"mesh is not closed \(3 open edges") as info:
        voxelize_mesh(holed)
    assert "repair it" in str(info.value)
    path = write_mesh(holed, tmp_path / "holed.ply")
    with pytest.raises(GeometryError, match="not closed"):
        read_mesh_volume(path)


def test_read_mesh_volume_from_file(tmp_path, sphere):
    path = write_mesh(sphere, tmp_path / "sphere.stl")
    volume = read_mesh_volume(path, resolution=48)
    assert volume.volume_mm3 == pytest.approx(4.0 / 3.0 * np.pi * 12.5**3, rel=0.02)


@pytest.mark.skipif(_pymeshlab_samples() is None, reason="pymeshlab sample meshes not installed")
def test_pymeshlab_bunnies():
    folder = _pymeshlab_samples()
    assert folder is not None
    closed = folder / "bunny.obj"
    if not closed.exists():
        pytest.skip("pymeshlab's bunny.obj is not packaged")
    bunny = read_mesh(closed)
    assert bunny.is_watertight
    volume = voxelize_mesh(bunny, resolution=64)
    assert volume.volume_mm3 == pytest.approx(bunny.volume, rel=0.02)
    textured = folder / "bunny10k_textured.obj"
    if textured.exists():  # the scanned bunny with holes in its base
        with pytest.raises(GeometryError, match=r"mesh is not closed \(\d+ open edges"):
            read_mesh_volume(textured)


def test_missing_and_unsupported_files(tmp_path):
    with pytest.raises(InputError, match="not found"):
        read_mesh(tmp_path / "nope.stl")
    (tmp_path / "mesh.vtk").write_text("# vtk DataFile")
    with pytest.raises(FormatError, match="unsupported mesh format"):
        read_mesh(tmp_path / "mesh.vtk")


@pytest.mark.parametrize(
    ("name", "content"),
    [
        ("noise.stl", bytes(np.random.default_rng(2).integers(0, 256, 3000, dtype=np.uint8))),
        ("noise.ply", bytes(np.random.default_rng(3).integers(0, 256, 3000, dtype=np.uint8))),
        ("words.obj", b"hello world\nthis is not a mesh\n"),
        ("short.off", b"OFF\n3 1 0\n0 0 0\n1 0 0\n"),
        ("empty.stl", b""),
    ],
)
def test_corrupt_files_raise_format_error(tmp_path, name, content):
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(FormatError):
        read_mesh(path)
