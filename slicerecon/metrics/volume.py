"""Occupancy on one evaluation grid: volume IoU, Dice and surface IoU."""

from __future__ import annotations

import logging

import numpy as np
from numpy.typing import NDArray

from ..errors import OptionError
from ..io.limits import DEFAULT_MEMORY_BUDGET_GB, check_budget, check_grid
from ..sections import Volume
from .inputs import (
    CUBE_CORNERS,
    DEFAULT_RESOLUTION,
    MAX_GRID_VOXELS,
    MetricInput,
    Occupancy,
    Shape,
    check_positive,
    check_resolution,
    metric_inputs,
    place,
)

logger = logging.getLogger(__name__)


# -- occupancy ----------------------------------------------------------------------------


def occupancy(
    pred: Shape,
    gt: Shape,
    *,
    resolution: int = DEFAULT_RESOLUTION,
    voxel_size: float | None = None,
    margin_mm: float = 0.0,
    memory_budget_gb: float = DEFAULT_MEMORY_BUDGET_GB,
) -> Occupancy:
    """Rasterize a prediction and a ground truth on one common evaluation grid.

    Parameters
    ----------
    pred, gt : Volume or trimesh.Trimesh
        The shapes, world mm. Meshes must be closed.
    resolution : int, optional
        When ``gt`` is a mesh: voxels along the longest side of the bounding
        box of both shapes (isotropic grid). Ignored when ``gt`` is a Volume.
    voxel_size : float, optional
        When ``gt`` is a mesh: the isotropic voxel size in mm, overriding
        ``resolution``. Ignored when ``gt`` is a Volume.
    margin_mm : float, optional
        Background kept around both shapes, mm. At least one voxel plus one
        largest voxel side is always kept.
    memory_budget_gb : float, optional
        Refuse a grid whose masks would not fit this budget, GiB, before
        allocating them (:func:`slicerecon.io.limits.check_grid`).

    Returns
    -------
    Occupancy
        Both masks of shape (I, J, K) and the grid's affine. With a Volume
        ground truth the grid is the ground truth's own lattice, cropped or
        extended by whole voxels to the union of both shapes plus the margin,
        so ``gt`` is reproduced exactly.

    Raises
    ------
    InputError, EmptyMaskError, GeometryError
        If a shape is of the wrong type, empty or not closed.
    OptionError
        If an option is out of range, or the grid would be unreasonably large
        (e.g. shapes in different world coordinates).
    MemoryBudgetError
        If the grid exceeds ``memory_budget_gb``.
    """
    p, g = metric_inputs(pred, gt)
    return occupancy_grid(
        p,
        g,
        resolution=check_resolution(resolution),
        voxel_size=check_positive(voxel_size, "voxel_size"),
        margin_mm=_check_margin(margin_mm),
        memory_budget_gb=check_budget(memory_budget_gb),
    )


def _check_margin(margin_mm: float) -> float:
    if margin_mm == 0:
        return 0.0
    value = check_positive(margin_mm, "margin_mm")
    assert value is not None
    return value


OCCUPANCY_BYTES_PER_VOXEL = 8
"""Bytes per voxel of the evaluation grid for occupancy alone (both masks, resampling)."""
SHELL_BYTES_PER_VOXEL = 32
"""Bytes per voxel of :func:`evaluate` when the surface shells are shifted views
(measured with tracemalloc: 22-24 B, rounded up)."""
SHELL_EDT_BYTES_PER_VOXEL = 96
"""Bytes per voxel of :func:`evaluate` when the surface shells need distance
transforms (a tolerance spanning many voxels; measured 67 B, rounded up)."""


def _shell_needs_edt(spacing: NDArray[np.float64], tol: float) -> bool:
    """True when :func:`_shell` uses distance transforms (more than 125 offsets)."""
    reach = np.floor(tol * (1.0 + 1e-9) / np.asarray(spacing, dtype=np.float64))
    if float(np.prod(2 * reach + 1)) > 1e6:
        return True
    offsets = np.stack(
        np.meshgrid(*(np.arange(-r, r + 1) for r in reach.astype(np.int64)), indexing="ij"),
        axis=-1,
    )
    inside = np.sqrt(((offsets * spacing) ** 2).sum(axis=-1)) <= tol * (1.0 + 1e-9)
    return int(inside.sum()) > 125


def _check_budget(
    shape: tuple[int, int, int],
    affine: NDArray[np.float64],
    shell_tolerance_mm: float | None,
    memory_budget_gb: float,
) -> None:
    """Refuse an evaluation grid whose arrays would not fit the memory budget."""
    per_voxel = float(OCCUPANCY_BYTES_PER_VOXEL)
    if shell_tolerance_mm is not None:
        spacing = np.linalg.norm(affine[:3, :3], axis=0)
        tol = shell_tolerance_mm or float(spacing.max())
        edt = _shell_needs_edt(spacing, tol)
        per_voxel = SHELL_EDT_BYTES_PER_VOXEL if edt else SHELL_BYTES_PER_VOXEL
    check_grid(
        shape,
        what="the evaluation grid of the metrics (the ground truth's voxels, with a margin of "
        "the surface tolerance around both shapes)",
        memory_budget_gb=memory_budget_gb,
        bytes_per_voxel=per_voxel,
    )


def occupancy_grid(
    pred: MetricInput,
    gt: MetricInput,
    *,
    resolution: int,
    voxel_size: float | None,
    margin_mm: float,
    pred_occupancy: Volume | None = None,
    memory_budget_gb: float = DEFAULT_MEMORY_BUDGET_GB,
    shell_tolerance_mm: float | None = None,
) -> Occupancy:
    """Both shapes on one evaluation grid, the grid checked against the memory budget first.

    ``shell_tolerance_mm``: the tolerance the surface shells will be computed
    with (0 for the default, the largest voxel side; None when no shell is
    computed): it decides the memory per voxel of the check.

    Raises
    ------
    MemoryBudgetError
        The grid's arrays would exceed ``memory_budget_gb``.
    """
    if np.any(pred.bounds_mm[0] > gt.bounds_mm[1]) or np.any(gt.bounds_mm[0] > pred.bounds_mm[1]):
        logger.warning(
            "the bounding boxes of prediction and ground truth do not overlap; "
            "are they in the same world coordinates?"
        )
    if isinstance(gt.shape, Volume):
        affine, shape, offset = _lattice_grid(gt.shape, pred.bounds_mm, margin_mm)
        _check_budget(shape, affine, shell_tolerance_mm, memory_budget_gb)
        gt_mask = place(gt.shape.mask, offset, shape)
    else:
        affine, shape = _isotropic_grid(
            np.concatenate([pred.bounds_mm, gt.bounds_mm]), resolution, voxel_size, margin_mm
        )
        _check_budget(shape, affine, shell_tolerance_mm, memory_budget_gb)
        gt_mask = gt.rasterize(affine, shape)
    known = _on_lattice(pred_occupancy, affine)
    if known is not None and isinstance(gt.shape, Volume):
        assert pred_occupancy is not None
        pred_mask = place(pred_occupancy.mask, -known, shape)
    else:
        pred_mask = pred.rasterize(affine, shape)
    logger.debug(
        "evaluation grid %s, spacing %s mm: %d predicted and %d true voxels",
        shape,
        np.round(np.linalg.norm(affine[:3, :3], axis=0), 4),
        int(np.count_nonzero(pred_mask)),
        int(np.count_nonzero(gt_mask)),
    )
    return Occupancy(pred_mask, gt_mask, affine)


def _on_lattice(volume: Volume | None, affine: NDArray[np.float64]) -> NDArray[np.int64] | None:
    """Index of ``volume``'s first voxel on the grid of ``affine``, when both share a lattice."""
    if volume is None or not np.allclose(volume.affine[:3, :3], affine[:3, :3], atol=1e-9):
        return None
    offset = np.linalg.solve(affine[:3, :3], volume.affine[:3, 3] - affine[:3, 3])
    whole = np.round(offset)
    if not np.allclose(offset, whole, atol=1e-6):
        return None
    return whole.astype(np.int64)


def _check_grid_size(shape: tuple[int, int, int]) -> None:
    n = int(np.prod(np.asarray(shape, dtype=np.int64)))
    if n > MAX_GRID_VOXELS:
        raise OptionError(
            f"the evaluation grid would have {n} voxels (shape {shape}); check that prediction "
            "and ground truth are in the same world coordinates, or pass a larger voxel_size"
        )


def _lattice_grid(
    volume: Volume, other_bounds: NDArray[np.float64], margin_mm: float
) -> tuple[NDArray[np.float64], tuple[int, int, int], NDArray[np.int64]]:
    """The volume's lattice over the union of its foreground and ``other_bounds``.

    Returns the grid affine, its shape, and the index of the grid's first
    voxel in the volume's own indices.
    """
    lo, hi = volume.bounding_box_vox()
    corners = other_bounds[0] + CUBE_CORNERS * (other_bounds[1] - other_bounds[0])
    ijk = volume.world_to_index(corners)
    # One voxel, plus room for the outer half of a surface shell one voxel wide.
    spacing = volume.spacing
    margin = 1 + np.ceil(max(margin_mm, float(spacing.max())) / spacing - 1e-9).astype(np.int64)
    first = np.minimum(lo, np.floor(ijk.min(axis=0)).astype(np.int64)) - margin
    last = np.maximum(hi, np.ceil(ijk.max(axis=0)).astype(np.int64) + 1) + margin
    shape = (int(last[0] - first[0]), int(last[1] - first[1]), int(last[2] - first[2]))
    _check_grid_size(shape)
    affine = volume.affine.copy()
    affine[:3, 3] = volume.index_to_world(first.astype(np.float64))
    return affine, shape, first


def _isotropic_grid(
    points: NDArray[np.float64], resolution: int, voxel_size: float | None, margin_mm: float
) -> tuple[NDArray[np.float64], tuple[int, int, int]]:
    """Axis-aligned isotropic grid covering ``points`` (world mm) plus a margin.

    Voxel cells tile space from the points' minimum corner: cell faces lie at
    ``min + n * h`` and voxel centres at ``min + (n + 1/2) * h``.
    """
    lo, hi = points.min(axis=0), points.max(axis=0)
    extent = hi - lo
    h = voxel_size if voxel_size is not None else float(extent.max()) / resolution
    if h <= 0:
        raise OptionError("both shapes are a single point; there is nothing to evaluate")
    margin = 1 + int(np.ceil(max(margin_mm, h) / h - 1e-9))
    counts = np.maximum(np.ceil(extent / h - 1e-9).astype(np.int64), 1) + 2 * margin
    shape = (int(counts[0]), int(counts[1]), int(counts[2]))
    _check_grid_size(shape)
    affine = np.diag([h, h, h, 1.0])
    affine[:3, 3] = lo + (0.5 - margin) * h
    return affine, shape


def occupancy_iou(occ: Occupancy) -> float:
    inter = np.count_nonzero(occ.pred & occ.gt)
    union = np.count_nonzero(occ.pred | occ.gt)
    return float(inter / union) if union else 1.0


def occupancy_dice(occ: Occupancy) -> float:
    inter = np.count_nonzero(occ.pred & occ.gt)
    total = np.count_nonzero(occ.pred) + np.count_nonzero(occ.gt)
    return float(2.0 * inter / total) if total else 1.0


def _shifted_morphology(
    mask: NDArray[np.bool_], reach: NDArray[np.int64], offsets: NDArray[np.int64], *, dilate: bool
) -> NDArray[np.bool_]:
    """Binary dilation (OR) or erosion (AND) of ``mask`` by a set of grid offsets.

    The offsets (rows of ``offsets``, within ``reach`` per axis) are grouped by
    their position on the two axes other than the one of longest reach (the
    run axis). Each group must span a symmetric run ``-w..w`` along the run
    axis, as the offsets of a ball or an ellipsoid do: the 1-D dilations along
    the run axis are built once per width, by two shifted views per width,
    and each group then costs one more shifted view. An ellipsoid reaching 3
    voxels in-plane and 1 across (39 offsets) takes 15 passes instead of 39.
    Any other offset set is combined one shifted view per offset. Beyond the
    grid counts as outside for a dilation and inside for an erosion.
    """
    ndim = mask.ndim
    padded = np.pad(mask, [(int(r), int(r)) for r in reach], constant_values=not dilate)
    combine = np.logical_or if dilate else np.logical_and
    run = int(np.argmax(reach))
    others = [a for a in range(ndim) if a != run]
    groups: dict[tuple[int, ...], list[int]] = {}
    for offset in offsets:
        groups.setdefault(tuple(int(offset[a]) for a in others), []).append(int(offset[run]))
    widths: dict[tuple[int, ...], int] = {}
    for key, along in groups.items():
        w = max(abs(v) for v in along)
        if sorted(along) != list(range(-w, w + 1)):
            widths = {}
            break
        widths[key] = w

    def view(shift: dict[int, int], axes: list[int]) -> tuple[slice, ...]:
        index = [slice(None)] * ndim
        for a in axes:
            start = int(reach[a]) + shift.get(a, 0)
            index[a] = slice(start, start + mask.shape[a])
        return tuple(index)

    if not widths:  # not runs along one axis: one shifted view per offset
        out = padded[view(dict(enumerate(offsets[0])), list(range(ndim)))].copy()
        for offset in offsets[1:]:
            combine(out, padded[view(dict(enumerate(offset)), list(range(ndim)))], out=out)
        return out
    lines: dict[int, NDArray[np.bool_]] = {}
    current = padded[view({}, [run])].copy()
    for w in range(max(widths.values()) + 1):
        if w:
            combine(current, padded[view({run: w}, [run])], out=current)
            combine(current, padded[view({run: -w}, [run])], out=current)
        if w in widths.values():
            lines[w] = current.copy() if w < max(widths.values()) else current
    out = None
    for key, w in widths.items():
        piece = lines[w][view(dict(zip(others, key, strict=True)), others)]
        if out is None:
            out = piece.copy()
        else:
            combine(out, piece, out=out)
    assert out is not None
    return out


def _shell(mask: NDArray[np.bool_], spacing: NDArray[np.float64], tol: float) -> NDArray:
    """Voxels whose centre lies within ``tol`` mm of a centre of opposite occupancy.

    Computed as a binary dilation of each side by the set of grid offsets not
    longer than ``tol`` mm, which is exactly the thresholded distance transform
    but touches only a small neighbourhood per voxel; for tolerances spanning
    many voxels the distance transform is used instead.
    """
    from scipy import ndimage

    if not mask.any() or mask.all():
        return np.zeros_like(mask)
    limit = tol * (1.0 + 1e-9)
    reach = np.floor(limit / np.asarray(spacing, dtype=np.float64)).astype(np.int64)
    offsets = np.stack(np.meshgrid(*(np.arange(-r, r + 1) for r in reach), indexing="ij"), axis=-1)
    structure = np.sqrt(((offsets * np.asarray(spacing)) ** 2).sum(axis=-1)) <= limit
    if structure.sum() <= 125:
        # Dilation and erosion by the structure's offsets on shifted views (a few
        # times faster than scipy's binary morphology here). As with scipy's
        # default border, nothing beyond the grid is near the mask's other side:
        # the shell is dilation(mask) minus erosion(mask).
        chosen = offsets[structure]
        near_inside = _shifted_morphology(mask, reach, chosen, dilate=True)
        deep_inside = _shifted_morphology(mask, reach, chosen, dilate=False)
        return near_inside & ~deep_inside
    inside = ndimage.distance_transform_edt(mask, sampling=spacing)
    outside = ndimage.distance_transform_edt(~mask, sampling=spacing)
    return np.where(mask, inside <= limit, outside <= limit)


def occupancy_surface_iou(occ: Occupancy, tol: float) -> float:
    spacing = occ.spacing
    shell_pred = _shell(occ.pred, spacing, tol)
    shell_gt = _shell(occ.gt, spacing, tol)
    union = np.count_nonzero(shell_pred | shell_gt)
    return float(np.count_nonzero(shell_pred & shell_gt) / union) if union else 1.0


def volume_iou(
    pred: Shape, gt: Shape, *, resolution: int = DEFAULT_RESOLUTION, voxel_size: float | None = None
) -> float:
    """Volume intersection over union ``|P ∩ G| / |P ∪ G|`` on the evaluation grid.

    Parameters
    ----------
    pred, gt : Volume or trimesh.Trimesh
        Prediction and ground truth, world mm.
    resolution, voxel_size
        Evaluation grid when ``gt`` is a mesh; see :func:`occupancy`.

    Returns
    -------
    float
        In [0, 1]; 1 for identical occupancies.
    """
    return occupancy_iou(occupancy(pred, gt, resolution=resolution, voxel_size=voxel_size))


def dice(
    pred: Shape, gt: Shape, *, resolution: int = DEFAULT_RESOLUTION, voxel_size: float | None = None
) -> float:
    """Dice coefficient ``2 |P ∩ G| / (|P| + |G|)`` on the evaluation grid.

    Parameters
    ----------
    pred, gt : Volume or trimesh.Trimesh
        Prediction and ground truth, world mm.
    resolution, voxel_size
        Evaluation grid when ``gt`` is a mesh; see :func:`occupancy`.

    Returns
    -------
    float
        In [0, 1]; equals ``2 IoU / (1 + IoU)``.
    """
    return occupancy_dice(occupancy(pred, gt, resolution=resolution, voxel_size=voxel_size))


def surface_iou(
    pred: Shape,
    gt: Shape,
    *,
    tolerance_mm: float | None = None,
    resolution: int = DEFAULT_RESOLUTION,
    voxel_size: float | None = None,
    memory_budget_gb: float = DEFAULT_MEMORY_BUDGET_GB,
) -> float:
    """Intersection over union of the two surface shells on the evaluation grid.

    The shell of a shape is the set of evaluation-grid voxels whose centre
    lies within ``tolerance_mm`` (Euclidean, world mm) of a voxel centre of
    the opposite occupancy: a band about ``2 * tolerance_mm`` thick straddling
    the surface.

    Parameters
    ----------
    pred, gt : Volume or trimesh.Trimesh
        Prediction and ground truth, world mm.
    tolerance_mm : float, optional
        Shell half-width, mm. Default: the largest voxel side of the
        evaluation grid (the smallest value for which every voxel touching
        the boundary, on either side, is in the shell).
    resolution, voxel_size
        Evaluation grid when ``gt`` is a mesh; see :func:`occupancy`.
    memory_budget_gb : float, optional
        Refuse a grid whose shells would not fit this budget, GiB.

    Returns
    -------
    float
        In [0, 1]; 1 for identical occupancies, 0 when the surfaces are more
        than about ``2 * tolerance_mm`` apart everywhere.

    Raises
    ------
    MemoryBudgetError
        If the evaluation grid exceeds ``memory_budget_gb``.
    """
    tol = check_positive(tolerance_mm, "tolerance_mm")
    p, g = metric_inputs(pred, gt)
    margin = tol if tol is not None else 0.0
    occ = occupancy_grid(
        p,
        g,
        resolution=check_resolution(resolution),
        voxel_size=check_positive(voxel_size, "voxel_size"),
        margin_mm=margin,
        memory_budget_gb=check_budget(memory_budget_gb),
        shell_tolerance_mm=margin,
    )
    return occupancy_surface_iou(occ, tol if tol is not None else float(occ.spacing.max()))
