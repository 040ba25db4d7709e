"""Carving by the visual hull: closed results, never outside the hull, helps where it should."""

from __future__ import annotations

import io

import numpy as np
import pytest
import trimesh

from slicerecon.errors import EmptyMaskError
from slicerecon.metrics import evaluate
from slicerecon.reconstruct import prepare_inputs, reconstruct
from slicerecon.sampling import projections_from_sections, projections_from_volume, visual_hull
from slicerecon.sections import CrossSections, Volume
from slicerecon.shapes import make_shape
from slicerecon.surface.carve import carve


def _stl_round_trip(mesh: trimesh.Trimesh) -> trimesh.Trimesh:
    buffer = io.BytesIO()
    mesh.export(buffer, file_type="stl")
    buffer.seek(0)
    return trimesh.load(buffer, file_type="stl")


@pytest.mark.parametrize("axis", ["x", "y", "z"])
def test_carved_chair_stays_manifold_after_stl(axis: str) -> None:
    # The chair's carved surface touches itself along edges; the written file
    # must still be a closed 2-manifold once vertices are merged by position.
    sections, projections, _ = prepare_inputs(make_shape("chair"), slices=6, axis=axis)
    mesh = reconstruct(sections, projections, planner="none", carve=True).mesh
    loaded = _stl_round_trip(mesh)
    assert loaded.is_watertight and loaded.is_winding_consistent
    edges = np.sort(loaded.edges, axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    assert np.all(counts == 2)


def test_carving_never_adds_volume_and_stays_inside_the_hull() -> None:
    torus = make_shape("torus")
    sections, projections, truth = prepare_inputs(torus, slices=8, axis="x")
    raw = reconstruct(sections, projections, planner="none", carve=False).mesh
    carved = reconstruct(sections, projections, planner="none", carve=True, cover=False).mesh
    assert carved.volume <= raw.volume + 1e-6
    hull = visual_hull(projections, sections.grid_shape)
    # Sample the carved surface; every point lies within a voxel of the hull.
    points = carved.vertices
    index = np.round(Volume(hull, sections.affine).world_to_index(points)).astype(int)
    index = np.clip(index, 0, np.array(hull.shape) - 1)
    from scipy.ndimage import binary_dilation

    assert binary_dilation(hull)[tuple(index.T)].all()
    assert truth is not None
    assert (
        evaluate(carved, truth, n_points=10_000).volume_iou
        > evaluate(raw, truth, n_points=10_000).volume_iou
    )


def test_cuboid_composite_is_recovered_exactly_from_its_silhouettes() -> None:
    # A box: the hull of its three silhouettes is the box itself.
    box = make_shape("box")
    sections, projections, truth = prepare_inputs(box, slices=4)
    mesh = reconstruct(sections, projections, carve=True).mesh
    assert truth is not None
    assert evaluate(mesh, truth, n_points=10_000).volume_iou > 0.99


def test_hull_from_other_shape_is_a_clear_error() -> None:
    sphere = make_shape("sphere", radius=10.0)
    sections, _, _ = prepare_inputs(sphere, slices=5)
    mesh = reconstruct(sections, projections_from_volume(sphere.crop(pad=3))).mesh
    far = np.zeros((40, 40, 40), bool)
    far[:3, :3, :3] = True
    affine = np.eye(4)
    affine[:3, 3] = 500.0  # a hull half a metre away from the sphere
    with pytest.raises(EmptyMaskError, match="outside"):
        carve(mesh, far, affine)


@pytest.mark.parametrize("shape", ["sphere", "kidney"])
def test_cover_fills_the_silhouettes_in_the_section_planes(shape: str) -> None:
    # Between two planes the interpolation falls short of the silhouettes; the
    # cover adds, on every ray of the two views whose rays lie in the section
    # planes, what the silhouette says is there. It stays inside the hull.
    sections, projections, truth = prepare_inputs(make_shape(shape), slices=6, axis="z")
    assert truth is not None
    hull = visual_hull(projections, sections.grid_shape)
    results = {
        cover: reconstruct(sections, projections, planner="none", carve=True, cover=cover)
        for cover in (False, True)
    }
    for cover, result in results.items():
        assert result.mesh.is_watertight
        occupancy = result.occupancy
        assert occupancy is not None
        full = np.zeros(hull.shape, dtype=bool)
        lo = np.round(np.linalg.solve(sections.affine, occupancy.affine)[:3, 3]).astype(int)
        full[tuple(slice(a, a + n) for a, n in zip(lo, occupancy.shape, strict=True))] = (
            occupancy.mask
        )
        assert not np.any(full & ~hull)
        missed = sum(int(np.count_nonzero(hull.any(axis=a) & ~full.any(axis=a))) for a in (0, 1))
        if cover:
            assert missed == 0
        else:
            assert missed > 0
    iou = {c: evaluate(r.mesh, truth, n_points=10_000).volume_iou for c, r in results.items()}
    assert iou[True] > iou[False]


def test_silhouettes_derived_from_the_sections_are_not_covered() -> None:
    # Derived side views say nothing the sections do not: covering them would
    # only copy their interpolation, so the cover leaves them alone.
    sections, _, _ = prepare_inputs(make_shape("kidney"), slices=6, axis="z")
    derived = projections_from_sections(sections)
    assert derived.source == "sections"
    covered = reconstruct(sections, derived, planner="none", cover=True).occupancy
    carved = reconstruct(sections, derived, planner="none", cover=False).occupancy
    assert covered is not None and carved is not None
    np.testing.assert_array_equal(covered.mask, carved.mask)


def test_the_cover_adds_no_piece_of_its_own() -> None:
    # A rod whose discs (radius 5 mm) move 8 mm along x per 4 mm plane: the
    # blend between planes thins, and rays of the side silhouettes miss it. Each
    # covered sample must join the shape; a lone one would be a speck of its own.
    shape = (90, 30, 40)
    i, j, k = np.meshgrid(*(np.arange(n, dtype=np.float64) for n in shape), indexing="ij")
    inside = (i - 8.0 - 2.0 * k) ** 2 + (j - 15.0) ** 2 <= 25.0
    inside[:, :, :2] = False
    inside[:, :, -2:] = False
    volume = Volume(inside, np.eye(4))
    planes = list(range(4, 37, 4))
    sections = CrossSections(
        np.stack([inside[:, :, p] for p in planes]), np.asarray(planes, float), 2, np.eye(4), shape
    )
    projections = projections_from_volume(volume)
    covered = reconstruct(sections, projections, planner="none")
    carved = reconstruct(sections, projections, planner="none", cover=False)
    assert len(covered.mesh.split(only_watertight=False)) == 1
    assert covered.mesh.volume > carved.mesh.volume
