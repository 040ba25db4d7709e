"""End-to-end reconstruction: watertight meshes and accuracy on known shapes."""

from __future__ import annotations

import numpy as np
import pytest

from slicerecon.metrics import evaluate
from slicerecon.options import ReconstructOptions
from slicerecon.reconstruct import prepare_inputs, reconstruct
from slicerecon.sections import Volume
from slicerecon.shapes import analytic_volume, make_shape


def _run(
    volume: Volume,
    *,
    slices: int = 16,
    axis: str = "z",
    planner: str = "heuristic",
    method: str = "loft",
):  # type: ignore[no-untyped-def]
    sections, projections, truth = prepare_inputs(volume, slices=slices, axis=axis)
    result = reconstruct(sections, projections, planner=planner, method=method)
    assert truth is not None
    return result, evaluate(result.mesh, truth, n_points=20_000, seed=0)


def _assert_closed_manifold(mesh) -> None:  # type: ignore[no-untyped-def]
    assert mesh.is_watertight, "mesh has open edges"
    assert mesh.is_winding_consistent, "faces are not consistently oriented"
    assert mesh.volume > 0, "faces point inwards"
    # Manifold: every edge is shared by exactly two faces.
    edges = np.sort(mesh.edges, axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert np.all(counts == 2)


@pytest.mark.parametrize("method", ["hybrid", "loft", "sdf"])
def test_sphere_radius_40_with_16_planes(method: str) -> None:
    sphere = make_shape("sphere", radius=40.0)
    result, metrics = _run(sphere, method=method)
    _assert_closed_manifold(result.mesh)
    assert metrics.volume_iou >= 0.95
    assert abs(metrics.volume_error) <= 0.03
    # Against the analytic ball too, not only its voxelisation.
    exact = analytic_volume("sphere", radius=40.0)
    assert result.mesh.volume == pytest.approx(exact, rel=0.03)


@pytest.mark.parametrize("name", ["torus", "y_branch", "chair", "two_spheres"])
@pytest.mark.parametrize("planner", ["none", "heuristic"])
def test_every_output_is_closed_and_manifold(name: str, planner: str) -> None:
    result, metrics = _run(make_shape(name), slices=10, planner=planner)
    _assert_closed_manifold(result.mesh)
    assert metrics.volume_iou > 0.6
    from slicerecon.reconstruct import planning_occupancy

    assert result.plan.covers(planning_occupancy(result.sections, result.projections))


def test_two_components_stay_two() -> None:
    result, _ = _run(make_shape("two_spheres"), slices=12)
    assert len(result.mesh.split(only_watertight=True)) == 2


def test_heuristic_beats_no_projection_on_the_chair() -> None:
    chair = make_shape("chair")
    _, none = _run(chair, planner="none")
    _, heuristic = _run(chair, planner="heuristic")
    assert heuristic.volume_iou > none.volume_iou
    assert heuristic.chamfer_l1 < none.chamfer_l1


def test_anisotropic_spacing_keeps_world_geometry() -> None:
    vol = make_shape("ellipsoid", spacing=(0.7, 0.9, 2.5))
    result, metrics = _run(vol, slices=12)
    _assert_closed_manifold(result.mesh)
    assert result.mesh.volume == pytest.approx(vol.volume_mm3, rel=0.05)
    assert metrics.volume_iou > 0.9


def test_mni_brain_mask() -> None:
    datasets = pytest.importorskip("nilearn.datasets")
    img = datasets.load_mni152_brain_mask(resolution=2)
    brain = Volume(np.asarray(img.get_fdata()) > 0.5, img.affine)
    result, metrics = _run(brain, slices=12)
    _assert_closed_manifold(result.mesh)
    assert metrics.volume_iou > 0.9


def test_real_mesh_input_gives_a_closed_surface_after_stl_round_trip() -> None:
    # The voxelized pymeshlab cow: the carved union of eight parts touches
    # itself along edges, which must not survive as non-manifold edges in STL.
    import io

    import trimesh

    from slicerecon.io import load_input
    from slicerecon.realshapes import pymeshlab_sample_dir

    cow = load_input(pymeshlab_sample_dir() / "cow.obj")
    result, metrics = _run(cow, slices=10)
    buffer = io.BytesIO()
    result.mesh.export(buffer, file_type="stl")
    buffer.seek(0)
    _assert_closed_manifold(trimesh.load(buffer, file_type="stl"))
    assert metrics.volume_iou > 0.8


@pytest.mark.slow
@pytest.mark.parametrize("method", ["hybrid", "loft", "sdf"])
def test_every_procedural_shape_every_axis_is_closed_after_stl(method: str) -> None:
    import io

    import trimesh

    from slicerecon.shapes import shape_names

    for name in shape_names():
        for axis in "xyz":
            for planner in ("none", "heuristic"):
                volume = make_shape(name, seed=1)
                result, _ = _run(volume, slices=8, axis=axis, planner=planner, method=method)
                buffer = io.BytesIO()
                result.mesh.export(buffer, file_type="stl")
                buffer.seek(0)
                _assert_closed_manifold(trimesh.load(buffer, file_type="stl"))


def test_hybrid_lofts_simple_parts_and_interpolates_folded_ones() -> None:
    from slicerecon.reconstruct import planning_occupancy
    from slicerecon.sections import Box
    from slicerecon.surface.loft import correspondence_is_simple

    # A sphere's contours correspond one to one: hybrid is exactly the loft.
    sphere = make_shape("sphere", radius=20.0)
    sections, projections, _ = prepare_inputs(sphere, slices=8)
    box = Box((0, 0, 0), sections.grid_shape)
    assert correspondence_is_simple(sections, box)
    loft = reconstruct(sections, projections, planner="none", method="loft").mesh
    hybrid = reconstruct(sections, projections, planner="none", method="hybrid").mesh
    assert hybrid.volume == pytest.approx(loft.volume, rel=1e-9)
    # Blobs appear and vanish between planes: not simple, and the hybrid
    # result is closed and covers the occupancy the planner saw.
    blobs = make_shape("blobs", seed=3)
    sections, projections, truth = prepare_inputs(blobs, slices=6)
    assert not correspondence_is_simple(sections, Box((0, 0, 0), sections.grid_shape))
    result = reconstruct(sections, projections, method="hybrid")
    _assert_closed_manifold(result.mesh)
    assert result.plan.covers(planning_occupancy(sections, projections))


def test_mni_white_matter_hybrid_beats_loft() -> None:
    # Folded tissue: contours split and merge between planes, where lofting
    # is ill posed; the hybrid interpolates those parts instead.
    pytest.importorskip("nilearn")
    from slicerecon.realshapes import mni152

    wm = mni152("wm", resolution=64)
    _, loft = _run(wm, slices=16, method="loft")
    result, hybrid = _run(wm, slices=16, method="hybrid")
    _assert_closed_manifold(result.mesh)
    assert hybrid.volume_iou > loft.volume_iou


def test_lookahead_planner_end_to_end_and_on_a_pooled_grid() -> None:
    """``planner="lookahead"`` gives a closed mesh whose plan covers the occupancy, on the
    grid itself and on a pooled planning grid (its sections and hull pooled alike)."""
    from slicerecon.partition.planner import plan_partition
    from slicerecon.reconstruct import _planning_surface, planning_occupancy
    from slicerecon.sampling import visual_hull

    result, metrics = _run(make_shape("y_branch"), slices=10, planner="lookahead", method="sdf")
    _assert_closed_manifold(result.mesh)
    assert metrics.volume_iou > 0.8
    occupancy = planning_occupancy(result.sections, result.projections)
    assert result.plan.planner == "lookahead" and result.plan.covers(occupancy)
    hull = visual_hull(result.projections, result.sections.grid_shape)
    surface = _planning_surface(result.sections, hull, ReconstructOptions())
    pooled = plan_partition(occupancy, planner="lookahead", max_grid=16, surface=surface)
    assert pooled.covers(occupancy) and pooled.grid_shape == occupancy.shape


def test_python_callers_mistakes_get_one_error_that_says_what_to_pass() -> None:
    """Arguments in the wrong order or of the wrong type gave an AttributeError or a
    TypeError deep inside, or a message about something else ("already sparse")."""
    from slicerecon.errors import InputError, OptionError
    from slicerecon.reconstruct import ReconstructConfig

    mask = make_shape("sphere", resolution=32)
    with pytest.raises(InputError, match="takes a Volume or CrossSections .*Volume\\(mask"):
        prepare_inputs(mask.mask, slices=4)
    sections, projections, _ = prepare_inputs(mask, slices=6)
    with pytest.raises(InputError, match=r"takes \(sections, projections\).*got Projections"):
        reconstruct(projections, sections)
    with pytest.raises(OptionError, match="--slices must be a whole number \\(got '12'\\)"):
        ReconstructConfig(slices="12")
    assert ReconstructConfig(slices=np.int64(12)).slices == 12
    # a list of structures, as Python callers give it, is the comma-separated selection
    assert ReconstructConfig(label=[3, "Liver"]).selectors == [3, "Liver"]
    assert ReconstructConfig(roi=("GTV",)).selectors == ["GTV"]


def test_projections_of_another_grid_are_refused() -> None:
    """Projections of the right shape on another grid (another affine) were taken as the
    sections' own, without a word."""
    from slicerecon.errors import GeometryError
    from slicerecon.sampling import projections_from_volume

    volume = make_shape("sphere", radius=10.0)
    sections, _, _ = prepare_inputs(volume, slices=8)
    moved = volume.affine.copy()
    moved[:3, 3] += 5.0
    elsewhere = projections_from_volume(Volume(volume.mask, moved))
    with pytest.raises(GeometryError, match="another grid"):
        reconstruct(sections, elsewhere)
