"""Tests for slicerecon.metrics against analytic values, with stated tolerances."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from slicerecon.errors import EmptyMaskError, GeometryError, InputError, OptionError
from slicerecon.metrics import (
    assd,
    chamfer_l1,
    dice,
    evaluate,
    f_score,
    hd95,
    occupancy,
    sample_surface,
    surface_iou,
    volume_iou,
)
from slicerecon.sections import Volume

N_POINTS = 20_000  # enough for sub-0.05 mm sampling error on the shapes below; keeps tests fast
ANISO = np.array([0.7, 0.9, 1.3])


def _ball(radius: float, spacing, *, centre=(0.0, 0.0, 0.0), half: float = 23.0, flip_x=False):
    """Voxelized ball (centres within ``radius`` mm) on a grid centred near ``centre``."""
    spacing = np.asarray(spacing, dtype=float)
    centre = np.asarray(centre, dtype=float)
    shape = tuple(int(n) for n in np.ceil(2 * half / spacing))
    linear = np.diag(spacing * np.array([-1.0 if flip_x else 1.0, 1.0, 1.0]))
    affine = np.eye(4)
    affine[:3, :3] = linear
    affine[:3, 3] = centre - linear @ ((np.asarray(shape) - 1) / 2.0 + 0.3)
    ijk = np.indices(shape).reshape(3, -1).T
    world = ijk @ linear.T + affine[:3, 3]
    inside = np.linalg.norm(world - centre, axis=1) <= radius
    return Volume(inside.reshape(shape), affine)


def _cube_volume(lo: int, hi: int, spacing, *, shift_mm=(0.0, 0.0, 0.0), size: int = 40):
    mask = np.zeros((size, size, size), dtype=bool)
    mask[lo:hi, lo:hi, lo:hi] = True
    affine = np.diag([*spacing, 1.0])
    affine[:3, 3] = np.asarray(shift_mm) + np.array([3.0, -2.0, 7.0])
    return Volume(mask, affine)


# -- concentric spheres -------------------------------------------------------------------

R_OUT, R_IN = 20.0, 15.0


@pytest.fixture(scope="module")
def concentric_meshes():
    outer = trimesh.creation.icosphere(subdivisions=4, radius=R_OUT)
    inner = trimesh.creation.icosphere(subdivisions=4, radius=R_IN)
    return inner, outer, evaluate(inner, outer, n_points=N_POINTS)


def test_concentric_mesh_spheres_volume_iou_within_1_percent(concentric_meshes):
    _, _, m = concentric_meshes
    assert m.volume_iou == pytest.approx((R_IN / R_OUT) ** 3, rel=0.01)
    assert m.dice == pytest.approx(2 * m.volume_iou / (1 + m.volume_iou), rel=1e-12)
    # both icospheres are the same polyhedron scaled: the volume ratio is exact
    assert m.volume_error == pytest.approx((R_IN / R_OUT) ** 3 - 1, abs=1e-9)


def test_concentric_mesh_spheres_distances_equal_the_gap(concentric_meshes):
    _, _, m = concentric_meshes
    gap = R_OUT - R_IN
    # tolerance: 1 % of the gap (polyhedral approximation ~0.01 mm + sampling)
    assert m.chamfer_l1_mm == pytest.approx(gap, abs=0.05)
    assert m.assd_mm == pytest.approx(m.chamfer_l1_mm, rel=1e-12)  # equal sample counts
    assert m.hd95_mm == pytest.approx(gap, abs=0.1)
    diagonal = 2 * R_OUT * np.sqrt(3)
    assert m.chamfer_l1 == pytest.approx(m.chamfer_l1_mm / diagonal, rel=1e-3)
    assert m.tau_mm == pytest.approx(0.01 * diagonal, rel=1e-3)
    # surfaces 5 mm apart: nothing within tau (0.69 mm) nor within one voxel
    assert m.f_score == 0.0
    assert m.surface_iou == 0.0


def test_concentric_voxel_spheres_on_a_fine_grid():
    outer = _ball(R_OUT, [0.5, 0.5, 0.5])
    inner = _ball(R_IN, [0.5, 0.5, 0.5])
    m = evaluate(inner, outer, n_points=N_POINTS)
    assert m.volume_iou == pytest.approx((R_IN / R_OUT) ** 3, rel=0.01)
    # marching-cubes surfaces of masks deviate from the spheres by up to half a voxel
    assert m.chamfer_l1_mm == pytest.approx(R_OUT - R_IN, abs=0.25)


def test_bigger_gap_gives_bigger_distances():
    outer = trimesh.creation.icosphere(subdivisions=3, radius=R_OUT)
    inner = trimesh.creation.icosphere(subdivisions=3, radius=18.0)
    close = chamfer_l1(inner, outer, n_points=5000)
    far = chamfer_l1(inner.copy().apply_scale(0.5), outer, n_points=5000)
    assert close == pytest.approx(2.0, abs=0.05)
    assert far == pytest.approx(11.0, abs=0.1)


# -- shifted cubes ------------------------------------------------------------------------


def test_cube_shifted_by_whole_voxels_has_exact_iou():
    spacing = ANISO
    side, shift = 20, 5  # voxels
    gt = _cube_volume(10, 10 + side, spacing)
    pred = _cube_volume(10, 10 + side, spacing, shift_mm=(shift * spacing[0], 0.0, 0.0))
    expected = (side - shift) / (side + shift)
    assert volume_iou(pred, gt) == pytest.approx(expected, rel=1e-12)
    assert dice(pred, gt) == pytest.approx(2 * expected / (1 + expected), rel=1e-12)


def test_cube_shifted_off_grid_is_resampled_to_the_nearest_voxel():
    spacing = ANISO
    gt = _cube_volume(10, 30, spacing)
    pred = _cube_volume(10, 30, spacing, shift_mm=(3.6, 0.0, 0.0))  # 5.14 voxels
    # nearest-neighbour resampling moves the cube by round(5.14) = 5 voxels
    assert volume_iou(pred, gt) == pytest.approx(15 / 25, rel=1e-12)
    s, d = 20 * spacing[0], 3.6
    assert volume_iou(pred, gt) == pytest.approx((s - d) / (s + d), rel=0.03)


def test_mesh_cube_shifted_along_x():
    s, d = 20.0, 5.0
    gt = trimesh.creation.box(extents=(s, s, s))
    pred = gt.copy().apply_translation((d, 0.0, 0.0))
    occ = occupancy(pred, gt)
    h = occ.spacing.max()
    expected = (s - d) / (s + d)
    # voxel-centre sampling miscounts at most one layer of voxels at each face along x
    bound = h / (s - d) + h / (s + d)
    assert volume_iou(pred, gt) == pytest.approx(expected, rel=bound)
    assert volume_iou(pred, gt, voxel_size=0.1) == pytest.approx(expected, rel=0.01)


# -- identical shapes and grids -----------------------------------------------------------


@pytest.mark.parametrize("kind", ["volume", "mesh"])
def test_identical_shapes_score_perfectly(kind):
    shape = (
        _ball(12.0, ANISO, half=15.0)
        if kind == "volume"
        else trimesh.creation.box(extents=(10.0, 20.0, 7.0))
    )
    m = evaluate(shape, shape, n_points=N_POINTS)
    assert m.volume_iou == 1.0 and m.dice == 1.0 and m.surface_iou == 1.0
    assert m.chamfer_l1_mm == 0.0 and m.hd95_mm == 0.0 and m.assd_mm == 0.0
    assert m.f_score == 1.0 and m.volume_error == 0.0


def test_same_shape_on_other_grids_is_resampled_exactly():
    gt = _cube_volume(8, 20, (1.0, 1.5, 2.0), size=30)
    fine = np.repeat(np.repeat(np.repeat(gt.mask, 2, 0), 2, 1), 2, 2)
    half = np.diag([0.5, 0.75, 1.0, 1.0])
    half[:3, 3] = gt.affine[:3, 3] - np.array([0.25, 0.375, 0.5])  # sub-voxel centres
    assert volume_iou(Volume(fine, half), gt) == 1.0
    mirrored = gt.affine.copy()
    mirrored[:3, 0] *= -1
    mirrored[:3, 3] = gt.index_to_world([gt.shape[0] - 1, 0, 0])
    assert volume_iou(Volume(gt.mask[::-1], mirrored), gt) == 1.0


def test_mesh_and_volume_of_the_same_sphere_agree():
    mesh = trimesh.creation.icosphere(subdivisions=4, radius=R_OUT)
    volume = _ball(R_OUT, ANISO)
    a = evaluate(mesh, volume, n_points=N_POINTS)
    b = evaluate(volume, mesh, n_points=N_POINTS)
    # grids: the volume's own (1.3 mm max) for a, isotropic 0.32 mm for b (the staircase
    # of the coarse mask then shows as ~3.5 % of the volume)
    assert a.volume_iou > 0.99 and b.volume_iou > 0.95
    assert abs(a.volume_error) < 0.01
    # surface distances use the same samples whichever shape is the ground truth
    assert a.chamfer_l1_mm == b.chamfer_l1_mm
    assert a.hd95_mm == b.hd95_mm and a.assd_mm == b.assd_mm
    # marching cubes on the mask stays within a quarter of the largest voxel on average
    assert a.chamfer_l1_mm < 0.25 * ANISO.max()
    assert a.f_score > 0.99 and b.f_score > 0.99


# -- surface IoU ---------------------------------------------------------------------------


def test_surface_iou_of_a_one_voxel_dilation_matches_the_definition():
    n = 10
    gt_mask = np.zeros((20, 20, 20), dtype=bool)
    gt_mask[5 : 5 + n, 5 : 5 + n, 5 : 5 + n] = True
    pred_mask = np.zeros_like(gt_mask)
    pred_mask[4 : 6 + n, 4 : 6 + n, 4 : 6 + n] = True
    # shells at 1 mm on a 1 mm grid: the inner layer (touching the background) plus the
    # face-adjacent outer layer. The predicted inner layer holds the true outer layer.
    gt_shell = n**3 - (n - 2) ** 3 + 6 * n**2
    pred_shell = (n + 2) ** 3 - n**3 + 6 * (n + 2) ** 2
    inter = 6 * n**2
    expected = inter / (gt_shell + pred_shell - inter)
    assert surface_iou(Volume(pred_mask), Volume(gt_mask)) == pytest.approx(expected, rel=1e-12)
    # a tolerance of 2 voxels puts the whole dilation inside both shells
    assert surface_iou(Volume(pred_mask), Volume(gt_mask), tolerance_mm=2.0) > expected


# -- the per-metric functions agree with evaluate -----------------------------------------


def test_single_metric_functions_match_evaluate():
    gt = trimesh.creation.box(extents=(20.0, 16.0, 12.0))
    pred = trimesh.creation.icosphere(subdivisions=3, radius=9.0)
    m = evaluate(pred, gt, n_points=5000, seed=3)
    kw = {"n_points": 5000, "seed": 3}
    assert volume_iou(pred, gt) == m.volume_iou
    assert dice(pred, gt) == m.dice
    assert surface_iou(pred, gt) == m.surface_iou
    assert chamfer_l1(pred, gt, **kw) == m.chamfer_l1_mm
    assert chamfer_l1(pred, gt, normalized=True, **kw) == m.chamfer_l1
    assert f_score(pred, gt, **kw) == m.f_score
    assert hd95(pred, gt, **kw) == m.hd95_mm
    assert assd(pred, gt, **kw) == m.assd_mm
    assert 0.0 < m.f_score < 1.0 and 0.0 < m.volume_iou < 1.0


def test_seeded_sampling_is_reproducible():
    gt = trimesh.creation.box(extents=(20.0, 16.0, 12.0))
    pred = trimesh.creation.icosphere(subdivisions=3, radius=9.0)
    first = evaluate(pred, gt, n_points=5000, seed=7)
    assert evaluate(pred, gt, n_points=5000, seed=7) == first
    other = evaluate(pred, gt, n_points=5000, seed=np.random.default_rng(1))
    assert other.chamfer_l1_mm != first.chamfer_l1_mm
    assert other.chamfer_l1_mm == pytest.approx(first.chamfer_l1_mm, rel=0.05)


def test_sample_surface_is_uniform_by_area():
    box = trimesh.creation.box(extents=(10.0, 2.0, 1.0))  # faces of 20, 10 and 2 mm^2
    pts = sample_surface(box, 40_000, seed=0)
    on_big = np.isclose(np.abs(pts[:, 2]), 0.5)  # the two 10 x 2 faces
    assert on_big.mean() == pytest.approx(40.0 / 64.0, abs=0.01)
    assert np.all(np.abs(pts) <= np.array([5.0, 1.0, 0.5]) + 1e-9)


def test_to_dict_is_json_ready(concentric_meshes):
    _, _, m = concentric_meshes
    data = json.loads(json.dumps(m.to_dict()))
    assert data["n_points"] == N_POINTS
    assert set(data) >= {
        "volume_iou",
        "dice",
        "surface_iou",
        "chamfer_l1_mm",
        "chamfer_l1",
        "f_score",
        "hd95_mm",
        "assd_mm",
        "volume_pred_mm3",
        "volume_gt_mm3",
        "volume_error",
    }


# -- bad inputs ---------------------------------------------------------------------------


def test_empty_mask_is_rejected():
    empty = Volume(np.zeros((5, 5, 5), dtype=bool))
    box = trimesh.creation.box(extents=(2.0, 2.0, 2.0))
    with pytest.raises(EmptyMaskError, match="prediction mask is empty"):
        evaluate(empty, box)
    with pytest.raises(EmptyMaskError, match="ground truth mask is empty"):
        volume_iou(box, empty)


def test_open_mesh_is_rejected():
    box = trimesh.creation.box(extents=(2.0, 2.0, 2.0))
    open_box = trimesh.Trimesh(box.vertices, box.faces[:-1], process=False)
    with pytest.raises(GeometryError, match="prediction: mesh is not closed"):
        evaluate(open_box, box)


@pytest.mark.parametrize("bad", [np.ones((3, 3, 3), dtype=bool), "mesh.stl", None])
def test_wrong_types_are_rejected(bad):
    box = trimesh.creation.box(extents=(2.0, 2.0, 2.0))
    with pytest.raises(InputError, match="Volume or a closed trimesh"):
        evaluate(bad, box)
    with pytest.raises(InputError, match="ground truth"):
        chamfer_l1(box, bad)


@pytest.mark.parametrize(
    "kwargs",
    [
        {"n_points": 0},
        {"tau": 0.0},
        {"tau": float("nan")},
        {"seed": "zero"},
        {"resolution": 2},
        {"voxel_size": -1.0},
        {"surface_tolerance_mm": 0.0},
    ],
)
def test_bad_options_are_rejected(kwargs):
    box = trimesh.creation.box(extents=(2.0, 2.0, 2.0))
    with pytest.raises(OptionError):
        evaluate(box, box, **kwargs)


def test_shapes_in_different_coordinates_are_rejected():
    box = trimesh.creation.box(extents=(2.0, 2.0, 2.0))
    far = box.copy().apply_translation((1e6, 0.0, 0.0))  # 1 km: a 2e6-voxel-long grid
    with pytest.raises(OptionError, match="same world coordinates"):
        volume_iou(far, _ball(3.0, [0.5, 0.5, 0.5], half=4.0))


# -- the memory budget ----------------------------------------------------------------------


def _slab(z_spacing: float) -> Volume:
    mask = np.zeros((40, 40, 6), bool)
    mask[10:30, 10:30, 1:5] = True
    return Volume(mask, np.diag([0.8, 0.8, z_spacing, 1.0]))


def test_an_evaluation_grid_over_the_budget_is_refused_before_allocating() -> None:
    """0.8 x 0.8 x 2000 mm voxels: the default shell tolerance (2000 mm) widens the grid by
    2500 voxels in-plane; evaluate took 5 minutes and 23 GB whatever --max-memory said."""
    import time

    from slicerecon.errors import MemoryBudgetError

    start = time.perf_counter()
    with pytest.raises(MemoryBudgetError, match=r"evaluation grid.*5024 x 5024 x 10"):
        evaluate(_slab(2000.0), _slab(2000.0), n_points=1000, memory_budget_gb=0.5)
    with pytest.raises(MemoryBudgetError, match="memory budget of 0.5 GiB"):
        surface_iou(_slab(2000.0), _slab(2000.0), memory_budget_gb=0.5)
    assert time.perf_counter() - start < 1.0
    # the same shapes on 2 mm slices fit: the budget does not refuse ordinary grids
    assert evaluate(_slab(2.0), _slab(2.0), n_points=1000, memory_budget_gb=0.5).dice == 1.0
    with pytest.raises(OptionError, match="max-memory"):
        evaluate(_slab(2.0), _slab(2.0), memory_budget_gb=-1)


def test_memory_the_machine_refuses_is_one_clear_error(monkeypatch) -> None:
    from slicerecon.errors import MemoryBudgetError
    from slicerecon.metrics import volume

    def refuse(*args, **kwargs):
        raise MemoryError

    monkeypatch.setattr(volume, "place", refuse)
    with pytest.raises(MemoryBudgetError, match="ran out of memory"):
        evaluate(_slab(2.0), _slab(2.0), n_points=1000)


def test_run_refuses_the_metrics_grid_in_one_line(tmp_path, capsys) -> None:
    """A 12 kB NRRD of such voxels, through ``slicerecon run``."""
    nrrd = pytest.importorskip("nrrd")
    from slicerecon.cli import main

    path = tmp_path / "aniso.nrrd"
    header = {
        "space": "left-posterior-superior",
        "space directions": np.diag([0.8, 0.8, 2000.0]),
        "space origin": [0.0, 0.0, 0.0],
        "kinds": ["domain"] * 3,
        "encoding": "gzip",
    }
    nrrd.write(str(path), _slab(2000.0).mask.astype(np.uint8), header, index_order="F")
    assert main(["run", str(path), "-o", str(tmp_path / "out"), "--max-memory", "0.5"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and "evaluation grid" in err[0]
