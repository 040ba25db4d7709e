"""Reconstruction quality: a predicted shape against a ground-truth shape.

Each shape is either a :class:`~slicerecon.sections.Volume` (binary mask plus
affine) or a closed :class:`trimesh.Trimesh`, both in world millimetres. Two
representations are derived from each shape, once:

* **Occupancy** on one common evaluation grid (:func:`occupancy`). When the
  ground truth is a Volume, the grid is its own voxel lattice (extended, by
  whole voxels, to cover the prediction too). When it is a mesh, the grid is
  isotropic with voxel size ``longest side / resolution`` of the bounding box
  of both shapes. Meshes are rasterized at voxel centres
  (:func:`slicerecon.rasterize.mesh_to_mask`); a Volume on another grid is
  resampled by nearest neighbour in world space.
  → :func:`volume_iou`, :func:`dice`, :func:`surface_iou`.
* **Surface samples**: ``n_points`` points drawn uniformly by area on each
  surface (a Volume's surface is its marching-cubes mesh,
  :func:`slicerecon.surface.marching.volume_to_mesh`), and the distance from
  every sample to the nearest sample of the other surface (KD-tree).
  → :func:`chamfer_l1`, :func:`f_score`, :func:`hd95`, :func:`assd`.

:func:`evaluate` computes all of them from one occupancy grid and one set of
samples. The exact definitions are in ``docs/metrics.md``.
"""

from __future__ import annotations

import numpy as np

from ..errors import MemoryBudgetError
from ..io.limits import DEFAULT_MEMORY_BUDGET_GB, check_budget
from ..sections import Volume
from .inputs import (
    DEFAULT_N_POINTS,
    DEFAULT_RESOLUTION,
    Metrics,
    Occupancy,
    Shape,
    SurfaceDistances,
    as_rng,
    check_n_points,
    check_positive,
    check_resolution,
    metric_inputs,
)
from .surface import (
    assd,
    assd_of,
    chamfer_l1,
    chamfer_mm,
    check_tau,
    distances_between,
    f_score,
    hd95,
    hd95_of,
    precision_recall,
    sample_surface,
    surface_distances,
    surface_samples,
)
from .volume import (
    dice,
    occupancy,
    occupancy_dice,
    occupancy_grid,
    occupancy_iou,
    occupancy_surface_iou,
    surface_iou,
    volume_iou,
)

__all__ = [
    "DEFAULT_N_POINTS",
    "DEFAULT_RESOLUTION",
    "Metrics",
    "Occupancy",
    "Shape",
    "SurfaceDistances",
    "assd",
    "chamfer_l1",
    "dice",
    "evaluate",
    "f_score",
    "hd95",
    "occupancy",
    "sample_surface",
    "surface_distances",
    "surface_iou",
    "volume_iou",
]

# -- everything at once -------------------------------------------------------------------


def evaluate(
    pred: Shape,
    gt: Shape,
    *,
    n_points: int = DEFAULT_N_POINTS,
    seed: int | np.random.Generator = 0,
    tau: float = 0.01,
    surface_tolerance_mm: float | None = None,
    resolution: int = DEFAULT_RESOLUTION,
    voxel_size: float | None = None,
    pred_occupancy: Volume | None = None,
    memory_budget_gb: float = DEFAULT_MEMORY_BUDGET_GB,
) -> Metrics:
    """Every metric of ``pred`` against ``gt`` from one grid and one set of samples.

    Parameters
    ----------
    pred, gt : Volume or trimesh.Trimesh
        Prediction and ground truth, world mm. Meshes must be closed.
    n_points : int, optional
        Surface samples per shape, at most (default 100 000): a surface small
        on the evaluation grid gets fewer, at least 32 per voxel face
        (:func:`~slicerecon.metrics.surface.surface_samples`); the record's
        ``n_points`` is the number drawn.
    seed : int or numpy.random.Generator, optional
        Seed of the surface sampling.
    tau : float, optional
        F-score threshold as a fraction of the ground-truth bounding-box diagonal.
    surface_tolerance_mm : float, optional
        Shell half-width of the surface IoU, mm (default: the largest voxel
        side of the evaluation grid).
    resolution, voxel_size
        Evaluation grid when ``gt`` is a mesh; see :func:`occupancy`.
    pred_occupancy : Volume, optional
        The voxel centres inside ``pred``, already known on the lattice of a
        ``gt`` Volume (same voxel axes, origin a whole number of voxels away),
        e.g. the sign of the field ``pred`` was extracted from
        (:attr:`slicerecon.reconstruct.Reconstruction.occupancy`). It is used
        instead of rasterizing ``pred`` (the same voxels, without the cost);
        ignored when the lattices differ.
    memory_budget_gb : float, optional
        Refuse an evaluation grid whose arrays (masks, surface shells, distance
        transforms) would not fit this budget, GiB, before allocating them;
        ``--max-memory`` (:func:`slicerecon.io.limits.check_grid`). An
        allocation the machine refuses within the budget is a
        :class:`~slicerecon.errors.MemoryBudgetError` too.

    Returns
    -------
    Metrics

    Raises
    ------
    InputError, EmptyMaskError, GeometryError
        If a shape is of the wrong type, empty or not a closed mesh.
    OptionError
        If an option is out of range.
    MemoryBudgetError
        If the evaluation grid exceeds ``memory_budget_gb``, or the machine
        runs out of memory.
    """
    try:
        return _evaluate(
            pred,
            gt,
            n_points=n_points,
            seed=seed,
            tau=tau,
            surface_tolerance_mm=surface_tolerance_mm,
            resolution=resolution,
            voxel_size=voxel_size,
            pred_occupancy=pred_occupancy,
            memory_budget_gb=check_budget(memory_budget_gb),
        )
    except MemoryError as exc:
        raise MemoryBudgetError(
            "computing the metrics ran out of memory: this machine has less free memory than "
            "the budget (--max-memory) allows; lower --max-memory, or free memory"
        ) from exc


def _evaluate(
    pred: Shape,
    gt: Shape,
    *,
    n_points: int,
    seed: int | np.random.Generator,
    tau: float,
    surface_tolerance_mm: float | None,
    resolution: int,
    voxel_size: float | None,
    pred_occupancy: Volume | None,
    memory_budget_gb: float,
) -> Metrics:
    n = check_n_points(n_points)
    tau = check_tau(tau)
    tol = check_positive(surface_tolerance_mm, "surface_tolerance_mm")
    res = check_resolution(resolution)
    size = check_positive(voxel_size, "voxel_size")
    as_rng(seed)  # validate before the expensive work
    p, g = metric_inputs(pred, gt)

    occ = occupancy_grid(
        p,
        g,
        resolution=res,
        voxel_size=size,
        margin_mm=tol or 0.0,
        pred_occupancy=pred_occupancy,
        memory_budget_gb=memory_budget_gb,
        shell_tolerance_mm=tol or 0.0,
    )
    tol_mm = tol if tol is not None else float(occ.spacing.max())
    n = surface_samples(p, g, n, float(occ.spacing.max()))
    dist = distances_between(p, g, n_points=n, seed=seed)
    tau_mm = tau * dist.gt_diagonal_mm
    f, precision, recall = precision_recall(dist, tau_mm)
    chamfer = chamfer_mm(dist)
    return Metrics(
        volume_iou=occupancy_iou(occ),
        dice=occupancy_dice(occ),
        surface_iou=occupancy_surface_iou(occ, tol_mm),
        chamfer_l1_mm=chamfer,
        chamfer_l1=chamfer / dist.gt_diagonal_mm,
        f_score=f,
        precision=precision,
        recall=recall,
        hd95_mm=hd95_of(dist),
        assd_mm=assd_of(dist),
        volume_pred_mm3=p.volume_mm3,
        volume_gt_mm3=g.volume_mm3,
        volume_error=(p.volume_mm3 - g.volume_mm3) / g.volume_mm3,
        tau_mm=tau_mm,
        surface_tolerance_mm=tol_mm,
        voxel_size_mm=float(occ.spacing.max()),
        n_points=n,
    )
