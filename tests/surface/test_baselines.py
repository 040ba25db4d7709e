"""Whole-shape baselines: poisson, sdf-hull, itk-mci (slicerecon.surface.baselines)."""

from __future__ import annotations

import importlib.util
import logging
import math
import subprocess
import sys
import types
from pathlib import Path

import numpy as np
import pytest
import trimesh

from slicerecon import shapes
from slicerecon.cli import main
from slicerecon.errors import DependencyError, GeometryError, InputError, OptionError
from slicerecon.io.nifti import write_nifti
from slicerecon.metrics import evaluate
from slicerecon.rasterize import mesh_to_mask
from slicerecon.reconstruct import METHODS, WHOLE_SHAPE_METHODS, prepare_inputs, reconstruct
from slicerecon.sampling import dense_count, visual_hull
from slicerecon.sections import CrossSections
from slicerecon.surface import baselines
from slicerecon.surface.baselines import (
    BASELINES,
    contour_samples,
    poisson,
    reconstruct_baseline,
    sdf_hull,
    sections_box,
)
from slicerecon.surface.sdf import sdf_mesh

SMALL = {
    "sphere": {"radius": 12.0},
    "torus": {"major": 12.0, "minor": 5.0},
    "y_branch": {"trunk_length": 15.0, "branch_length": 15.0, "spread": 10.0, "radius": 4.0},
}
"""Small shapes (grids of 16..44 voxels a side) so the file runs in seconds."""

N_PLANES = 8


def _require(method: str) -> None:
    """Skip ITK tests when the optional extra is not installed."""
    if method == "itk-mci":
        pytest.importorskip("itk")
        if importlib.util.find_spec("itk.MorphologicalContourInterpolationPython") is None:
            pytest.skip('itk-morphologicalcontourinterpolation missing ("slicerecon[itk]")')


def _closed_outward(mesh: trimesh.Trimesh) -> None:
    assert isinstance(mesh, trimesh.Trimesh)
    assert mesh.is_watertight
    assert mesh.is_winding_consistent
    assert mesh.volume > 0


@pytest.fixture(scope="module")
def small_inputs() -> dict[str, tuple]:
    out = {}
    for name, params in SMALL.items():
        out[name] = prepare_inputs(shapes.make_shape(name, **params), slices=N_PLANES)
    return out


def test_registry_matches_the_reconstruct_methods() -> None:
    assert set(BASELINES) == set(WHOLE_SHAPE_METHODS)
    assert set(WHOLE_SHAPE_METHODS) <= set(METHODS)
    assert {"loft", "sdf"} <= set(METHODS) - set(WHOLE_SHAPE_METHODS)


@pytest.mark.parametrize("shape", sorted(SMALL))
@pytest.mark.parametrize("method", ["poisson", "sdf-hull", "itk-mci"])
def test_baseline_is_closed_outward_and_resembles_the_shape(
    method: str, shape: str, small_inputs: dict[str, tuple]
) -> None:
    _require(method)
    sections, projections, truth = small_inputs[shape]
    mesh = BASELINES[method](sections, projections)
    _closed_outward(mesh)
    # World mm, inside the reference grid (plus one voxel).
    corners = (
        np.array(list(np.ndindex(2, 2, 2)), dtype=float) * (np.asarray(sections.grid_shape) + 1.0)
        - 1.0
    )
    world = corners @ sections.affine[:3, :3].T + sections.affine[:3, 3]
    assert np.all(mesh.bounds[0] >= world.min(axis=0) - 1e-6)
    assert np.all(mesh.bounds[1] <= world.max(axis=0) + 1e-6)
    # Recognizably the shape: 8 planes give every method a volume IoU of 0.82..0.99 here.
    assert evaluate(mesh, truth, n_points=5000).volume_iou > 0.8


@pytest.mark.parametrize("method", ["poisson", "sdf-hull", "itk-mci"])
def test_sphere_volume_within_five_percent(method: str) -> None:
    """12 planes through a 12 mm ball: volume within 5 % of 4/3 π r³."""
    _require(method)
    radius = 12.0
    sections, projections, _ = prepare_inputs(shapes.sphere(radius), slices=12)
    mesh = BASELINES[method](sections, projections)
    exact = 4.0 / 3.0 * math.pi * radius**3
    assert abs(mesh.volume - exact) / exact < 0.05


@pytest.mark.parametrize("method", ["poisson", "sdf-hull", "itk-mci"])
def test_dense_input_beats_sparse_input_on_a_sphere(method: str) -> None:
    _require(method)
    volume = shapes.sphere(12.0)
    scores = {}
    for n in (5, dense_count(5)):
        sections, projections, truth = prepare_inputs(volume, slices=n)
        mesh = BASELINES[method](sections, projections)
        scores[n] = evaluate(mesh, truth, n_points=10_000, seed=0)
    sparse, dense = scores[5], scores[dense_count(5)]
    assert dense.volume_iou > sparse.volume_iou
    assert dense.chamfer_l1_mm < sparse.chamfer_l1_mm


def test_reconstruct_runs_a_baseline_on_one_part(small_inputs: dict[str, tuple]) -> None:
    sections, projections, _ = small_inputs["y_branch"]
    result = reconstruct(sections, projections, planner="heuristic", method="sdf-hull")
    _closed_outward(result.mesh)
    assert result.plan.planner == "none"
    assert len(result.plan.parts) == 1
    box = result.plan.parts[0].box
    assert box == sections_box(sections)
    # The box holds every section pixel.
    on_grid = np.zeros(sections.grid_shape, dtype=bool)
    view = np.moveaxis(on_grid, sections.axis, 0)
    view[np.round(sections.indices).astype(int)] = sections.masks
    assert on_grid[box.slices].sum() == on_grid.sum()
    assert set(result.timings) == {"plan", "surface"}


def test_unknown_method_exits_2_with_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = write_nifti(shapes.sphere(6.0), tmp_path / "ball.nii.gz")
    out = tmp_path / "out"
    assert main(["run", str(path), "-o", str(out), "--method", "marching"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1
    assert "--method" in err[0] and "poisson" in err[0] and "'marching'" in err[0]
    assert not (out / "mesh.stl").exists()


def test_reconstruct_baseline_rejects_unknown_names(small_inputs: dict[str, tuple]) -> None:
    sections, projections, _ = small_inputs["sphere"]
    with pytest.raises(OptionError, match="sdf-hull"):
        reconstruct_baseline(sections, projections, method="loft")


def test_contour_normals_point_out_of_an_anisotropic_ball() -> None:
    ball = shapes.sphere(10.0, spacing=(0.8, 1.0, 1.5))
    sections, _, _ = prepare_inputs(ball, slices=6)
    points, normals = contour_samples(sections, caps=False)
    assert points.shape == normals.shape and points.shape[1] == 3
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-9)
    # In-plane normals (no z component) and pointing away from the ball's centre (0, 0, 0).
    np.testing.assert_allclose(normals[:, 2], 0.0, atol=1e-9)
    radial = points[:, :2] / np.linalg.norm(points[:, :2], axis=1, keepdims=True)
    assert np.all(np.einsum("ij,ij->i", normals[:, :2], radial) > 0.5)
    with_caps, cap_normals = contour_samples(sections, caps=True)
    caps = cap_normals[len(points) :]
    assert len(caps) == sections.masks[0].sum() + sections.masks[-1].sum()
    assert set(np.round(caps[:, 2]).astype(int).tolist()) == {-1, 1}
    # Cap points lie on the first / last plane.
    positions = sections.positions
    z_caps = with_caps[len(points) :, 2]
    assert np.all(np.isclose(z_caps, positions[0]) | np.isclose(z_caps, positions[-1]))


def test_poisson_falls_back_to_rasterizing_a_non_manifold_surface(
    monkeypatch: pytest.MonkeyPatch,
    caplog: pytest.LogCaptureFixture,
    small_inputs: dict[str, tuple],
) -> None:
    sections, projections, _ = small_inputs["sphere"]
    direct = poisson(sections)
    monkeypatch.setattr(baselines, "_as_solid", lambda verts, faces: None)
    with caplog.at_level(logging.WARNING, logger="slicerecon.surface.baselines"):
        fallback = poisson(sections)
    assert "rasterizing" in caplog.text
    _closed_outward(fallback)
    assert abs(fallback.volume - direct.volume) / direct.volume < 0.1


def test_poisson_without_the_filter_raises_dependency_error(
    monkeypatch: pytest.MonkeyPatch, small_inputs: dict[str, tuple]
) -> None:
    fake = types.ModuleType("pymeshlab")
    fake.MeshSet = type("MeshSet", (), {})  # type: ignore[attr-defined]
    monkeypatch.setitem(sys.modules, "pymeshlab", fake)
    sections, _, _ = small_inputs["sphere"]
    with pytest.raises(DependencyError, match="screened Poisson"):
        poisson(sections)


def test_itk_mci_without_itk_raises_dependency_error(
    monkeypatch: pytest.MonkeyPatch, small_inputs: dict[str, tuple]
) -> None:
    monkeypatch.setitem(sys.modules, "itk", None)
    sections, projections, _ = small_inputs["sphere"]
    with pytest.raises(DependencyError, match=r"slicerecon\[itk\]"):
        reconstruct_baseline(sections, projections, method="itk-mci")


def test_itk_mci_rejects_planes_between_grid_indices() -> None:
    masks = np.zeros((2, 8, 8), dtype=bool)
    masks[:, 2:6, 2:6] = True
    sections = CrossSections(masks, [1.0, 4.5], 2, np.eye(4), (8, 8, 8))
    with pytest.raises(GeometryError, match="between grid"):
        baselines.itk_mci(sections)


def test_sdf_hull_needs_projections(small_inputs: dict[str, tuple]) -> None:
    sections, _, _ = small_inputs["sphere"]
    with pytest.raises(InputError, match="projections"):
        sdf_hull(sections, None)  # type: ignore[arg-type]


def test_sdf_hull_stays_inside_the_hull_where_plain_sdf_does_not() -> None:
    chair = shapes.make_shape("chair")
    sections, projections, _ = prepare_inputs(chair, slices=6, axis="y")
    hull = visual_hull(projections, sections.grid_shape)
    carved = mesh_to_mask(sdf_hull(sections, projections), sections.affine, sections.grid_shape)
    plain = mesh_to_mask(sdf_mesh(sections), sections.affine, sections.grid_shape)
    assert np.count_nonzero(plain & ~hull) > 0  # interpolation alone leaves the hull
    assert np.count_nonzero(carved & ~hull) == 0
    assert np.count_nonzero(carved) > 0.9 * np.count_nonzero(plain & hull)


@pytest.mark.slow
@pytest.mark.parametrize("shape", ["sphere", "torus", "y_branch", "chair"])
@pytest.mark.parametrize("method", ["poisson", "sdf-hull", "itk-mci"])
def test_baselines_on_full_size_shapes(method: str, shape: str) -> None:
    _require(method)
    sections, projections, truth = prepare_inputs(shapes.make_shape(shape), slices=12)
    mesh = BASELINES[method](sections, projections)
    _closed_outward(mesh)
    if shape != "chair":
        assert evaluate(mesh, truth, n_points=20_000).volume_iou > 0.75
    # The chair's thin legs and sharp seat are a known weakness of the whole-shape
    # baselines (volume IoU 0.64 poisson, 0.68 itk-mci at 12 planes, see
    # docs/data/compare_methods.csv): only closedness is asserted for it.


@pytest.mark.slow
def test_itk_mci_process_exits_cleanly() -> None:
    """ITK's interpolator corrupted the heap on several threads (abort at exit)."""
    _require("itk-mci")
    code = (
        "from slicerecon import shapes\n"
        "from slicerecon.reconstruct import prepare_inputs\n"
        "from slicerecon.surface.baselines import itk_mci\n"
        "s, p, t = prepare_inputs(shapes.sphere(15.0), slices=8)\n"
        "assert itk_mci(s).is_watertight\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, timeout=300)
    assert done.returncode == 0, done.stderr.decode()[-2000:]
