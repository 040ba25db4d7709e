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

import logging
from dataclasses import asdict, dataclass
from functools import cached_property
from typing import NamedTuple

import numpy as np
import trimesh
from numpy.typing import NDArray

from .errors import EmptyMaskError, GeometryError, InputError, OptionError, SlicereconError
from .rasterize import mesh_to_mask, require_closed
from .sections import Volume
from .surface.marching import signed_volume, volume_to_mesh

__all__ = [
    "Shape",
    "Metrics",
    "Occupancy",
    "SurfaceDistances",
    "occupancy",
    "sample_surface",
    "surface_distances",
    "volume_iou",
    "dice",
    "surface_iou",
    "chamfer_l1",
    "f_score",
    "hd95",
    "assd",
    "evaluate",
]

logger = logging.getLogger(__name__)

Shape = Volume | trimesh.Trimesh
"""A shape to evaluate: a binary Volume or a closed mesh, world mm."""

DEFAULT_N_POINTS = 100_000
"""Surface samples per shape for the distance metrics."""

DEFAULT_RESOLUTION = 128
"""Voxels along the longest side of the evaluation grid when the ground truth is a mesh."""

_MAX_GRID_VOXELS = 400_000_000
"""Refuse evaluation grids larger than this (about 0.4 GB per boolean mask)."""

_CHUNK_VOXELS = 4_000_000
"""Voxels resampled at once by nearest-neighbour index mapping."""


# -- results ------------------------------------------------------------------------------


@dataclass(frozen=True)
class Metrics:
    """All metrics of a prediction against a ground truth.

    See ``docs/metrics.md`` for the exact definitions.

    Attributes
    ----------
    volume_iou : float
        Intersection over union of the occupancies, in [0, 1].
    dice : float
        Dice coefficient of the occupancies, in [0, 1].
    surface_iou : float
        Intersection over union of the two surface shells (voxels within
        ``surface_tolerance_mm`` of the boundary), in [0, 1].
    chamfer_l1_mm : float
        Mean of the two directed mean surface distances, mm.
    chamfer_l1 : float
        ``chamfer_l1_mm`` divided by the ground-truth bounding-box diagonal
        ("Chamfer-L1 / diag"), unitless.
    f_score : float
        Harmonic mean of ``precision`` and ``recall`` at ``tau_mm``, in [0, 1].
    precision : float
        Fraction of predicted surface samples within ``tau_mm`` of the ground truth.
    recall : float
        Fraction of ground-truth surface samples within ``tau_mm`` of the prediction.
    hd95_mm : float
        Larger of the two directed 95th-percentile surface distances, mm.
    assd_mm : float
        Mean of all surface distances of both directions pooled, mm.
    volume_pred_mm3, volume_gt_mm3 : float
        Enclosed volumes, mm³ (voxel count × voxel volume for a Volume, the
        enclosed volume for a mesh).
    volume_error : float
        Signed relative volume error ``(volume_pred - volume_gt) / volume_gt``.
    tau_mm : float
        F-score distance threshold, mm.
    surface_tolerance_mm : float
        Shell half-width of the surface IoU, mm.
    voxel_size_mm : float
        Largest voxel side of the evaluation grid, mm.
    n_points : int
        Surface samples per shape.
    """

    volume_iou: float
    dice: float
    surface_iou: float
    chamfer_l1_mm: float
    chamfer_l1: float
    f_score: float
    precision: float
    recall: float
    hd95_mm: float
    assd_mm: float
    volume_pred_mm3: float
    volume_gt_mm3: float
    volume_error: float
    tau_mm: float
    surface_tolerance_mm: float
    voxel_size_mm: float
    n_points: int

    def to_dict(self) -> dict[str, float | int]:
        """JSON-ready ``{name: value}`` with plain Python numbers."""
        return {
            key: int(value) if key == "n_points" else float(value)
            for key, value in asdict(self).items()
        }


class Occupancy(NamedTuple):
    """Both shapes rasterized on one evaluation grid.

    Attributes
    ----------
    pred, gt : ndarray of shape (I, J, K), bool
        Voxel centres inside the prediction / the ground truth.
    affine : ndarray of shape (4, 4)
        Voxel index → world mm of the evaluation grid.
    """

    pred: NDArray[np.bool_]
    gt: NDArray[np.bool_]
    affine: NDArray[np.float64]

    @property
    def spacing(self) -> NDArray[np.float64]:
        """Voxel size along the grid axes, mm, ndarray of shape (3,)."""
        return np.linalg.norm(self.affine[:3, :3], axis=0)

    @property
    def voxel_volume(self) -> float:
        """Volume of one voxel, mm³."""
        return float(abs(np.linalg.det(self.affine[:3, :3])))


class SurfaceDistances(NamedTuple):
    """Nearest-neighbour distances between the surface samples of two shapes.

    Attributes
    ----------
    pred_to_gt : ndarray of shape (N,)
        Distance from each predicted-surface sample to the nearest
        ground-truth sample, mm.
    gt_to_pred : ndarray of shape (N,)
        Distance from each ground-truth sample to the nearest predicted
        sample, mm.
    gt_diagonal_mm : float
        Diagonal of the ground-truth surface's axis-aligned bounding box, mm.
    """

    pred_to_gt: NDArray[np.float64]
    gt_to_pred: NDArray[np.float64]
    gt_diagonal_mm: float


# -- inputs -------------------------------------------------------------------------------


class _Input:
    """A validated shape with its derived surface, bounds and volume (computed once)."""

    def __init__(self, shape: object, role: str) -> None:
        self.role = role
        if isinstance(shape, Volume):
            if shape.is_empty:
                raise EmptyMaskError(f"the {role} mask is empty: there is nothing to evaluate")
        elif isinstance(shape, trimesh.Trimesh):
            try:
                require_closed(shape)
            except SlicereconError as err:
                raise type(err)(f"{role}: {err}") from err
        else:
            raise InputError(
                f"the {role} must be a slicerecon Volume or a closed trimesh.Trimesh "
                f"(got {type(shape).__name__}); read files with slicerecon.io first"
            )
        self.shape: Shape = shape

    @cached_property
    def surface(self) -> trimesh.Trimesh:
        """The closed surface, world mm (marching cubes for a Volume)."""
        if isinstance(self.shape, Volume):
            return volume_to_mesh(self.shape)
        return self.shape

    @cached_property
    def bounds_mm(self) -> NDArray[np.float64]:
        """World-axis-aligned bounds ``[min, max]`` of the shape, ndarray of shape (2, 3)."""
        if isinstance(self.shape, Volume):
            lo, hi = self.shape.bounding_box_vox()
            corners = lo - 0.5 + _CUBE_CORNERS * (hi - lo)
            world = self.shape.index_to_world(corners)
            return np.stack([world.min(axis=0), world.max(axis=0)])
        return np.asarray(self.shape.bounds, dtype=np.float64)

    @cached_property
    def volume_mm3(self) -> float:
        """Enclosed volume, mm³."""
        if isinstance(self.shape, Volume):
            return self.shape.volume_mm3
        volume = signed_volume(self.shape.vertices, self.shape.faces)
        if volume < 0:
            logger.debug("the %s mesh is wound inwards; using |volume|", self.role)
        return abs(volume)

    def rasterize(self, affine: NDArray[np.float64], shape: tuple[int, int, int]) -> NDArray:
        """Occupancy of the voxel centres of a grid, ndarray of shape ``shape``, bool."""
        if isinstance(self.shape, Volume):
            return _resample_nearest(self.shape, affine, shape)
        return mesh_to_mask(self.shape, affine, shape)


_CUBE_CORNERS = np.array(list(np.ndindex(2, 2, 2)), dtype=np.float64)


def _inputs(pred: Shape, gt: Shape) -> tuple[_Input, _Input]:
    return _Input(pred, "prediction"), _Input(gt, "ground truth")


def _check_n_points(n_points: int) -> int:
    if isinstance(n_points, bool) or not isinstance(n_points, int | np.integer):
        raise OptionError(f"n_points must be an integer (got {n_points!r})")
    if n_points < 1:
        raise OptionError(f"n_points must be >= 1 (got {n_points})")
    return int(n_points)


def _check_positive(value: float | None, name: str) -> float | None:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise OptionError(f"{name} must be a number (got {value!r})")
    if not np.isfinite(value) or value <= 0:
        raise OptionError(f"{name} must be a positive finite number (got {value})")
    return float(value)


def _check_resolution(resolution: int) -> int:
    if isinstance(resolution, bool) or not isinstance(resolution, int | np.integer):
        raise OptionError(f"resolution must be an integer (got {resolution!r})")
    if resolution < 8:
        raise OptionError(f"resolution must be at least 8 voxels (got {resolution})")
    return int(resolution)


def _rng(seed: int | np.random.Generator) -> np.random.Generator:
    if isinstance(seed, np.random.Generator):
        return seed
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer):
        raise OptionError(f"seed must be an integer or a numpy Generator (got {seed!r})")
    return np.random.default_rng(int(seed))


# -- occupancy ----------------------------------------------------------------------------


def occupancy(
    pred: Shape,
    gt: Shape,
    *,
    resolution: int = DEFAULT_RESOLUTION,
    voxel_size: float | None = None,
    margin_mm: float = 0.0,
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
    """
    p, g = _inputs(pred, gt)
    return _occupancy(
        p,
        g,
        resolution=_check_resolution(resolution),
        voxel_size=_check_positive(voxel_size, "voxel_size"),
        margin_mm=_check_margin(margin_mm),
    )


def _check_margin(margin_mm: float) -> float:
    if margin_mm == 0:
        return 0.0
    value = _check_positive(margin_mm, "margin_mm")
    assert value is not None
    return value


def _occupancy(
    pred: _Input, gt: _Input, *, resolution: int, voxel_size: float | None, margin_mm: float,
    pred_occupancy: Volume | None = None,
) -> Occupancy:
    if np.any(pred.bounds_mm[0] > gt.bounds_mm[1]) or np.any(gt.bounds_mm[0] > pred.bounds_mm[1]):
        logger.warning(
            "the bounding boxes of prediction and ground truth do not overlap; "
            "are they in the same world coordinates?"
        )
    if isinstance(gt.shape, Volume):
        affine, shape, offset = _lattice_grid(gt.shape, pred.bounds_mm, margin_mm)
        gt_mask = _place(gt.shape.mask, offset, shape)
    else:
        affine, shape = _isotropic_grid(
            np.concatenate([pred.bounds_mm, gt.bounds_mm]), resolution, voxel_size, margin_mm
        )
        gt_mask = gt.rasterize(affine, shape)
    known = _on_lattice(pred_occupancy, affine)
    if known is not None and isinstance(gt.shape, Volume):
        assert pred_occupancy is not None
        pred_mask = _place(pred_occupancy.mask, -known, shape)
    else:
        pred_mask = pred.rasterize(affine, shape)
    logger.debug(
        "evaluation grid %s, spacing %s mm: %d predicted and %d true voxels",
        shape, np.round(np.linalg.norm(affine[:3, :3], axis=0), 4),
        int(np.count_nonzero(pred_mask)), int(np.count_nonzero(gt_mask)),
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
    if n > _MAX_GRID_VOXELS:
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
    corners = other_bounds[0] + _CUBE_CORNERS * (other_bounds[1] - other_bounds[0])
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


def _place(
    mask: NDArray[np.bool_], offset: NDArray[np.int64], shape: tuple[int, int, int]
) -> NDArray[np.bool_]:
    """Copy ``mask`` into a grid of ``shape`` whose voxel 0 is ``mask``'s voxel ``offset``."""
    out = np.zeros(shape, dtype=bool)
    src_lo = np.maximum(offset, 0)
    src_hi = np.minimum(offset + np.asarray(shape), mask.shape)
    if np.any(src_hi <= src_lo):
        return out
    dst_lo = src_lo - offset
    dst_hi = src_hi - offset
    out[dst_lo[0] : dst_hi[0], dst_lo[1] : dst_hi[1], dst_lo[2] : dst_hi[2]] = mask[
        src_lo[0] : src_hi[0], src_lo[1] : src_hi[1], src_lo[2] : src_hi[2]
    ]
    return out


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


def _resample_nearest(
    volume: Volume, affine: NDArray[np.float64], shape: tuple[int, int, int]
) -> NDArray[np.bool_]:
    """Nearest-neighbour value of ``volume`` at every voxel centre of a grid.

    A voxel centre takes the value of the volume's voxel whose cell holds it
    (index rounded half up); centres outside the volume's grid are background.
    """
    to_src = np.linalg.inv(volume.affine) @ affine  # grid index -> volume index
    linear, shift = to_src[:3, :3], to_src[:3, 3]
    if np.allclose(linear, np.eye(3), atol=1e-9) and np.allclose(shift, np.rint(shift), atol=1e-6):
        # Same lattice: an exact integer shift.
        return _place(volume.mask, np.rint(shift).astype(np.int64), shape)

    out = np.zeros(shape, dtype=bool)
    lo, hi = volume.bounding_box_vox()
    corners = volume.index_to_world(lo - 0.5 + _CUBE_CORNERS * (hi - lo))
    ijk = corners @ np.linalg.inv(affine)[:3, :3].T + np.linalg.inv(affine)[:3, 3]
    first = np.clip(np.floor(ijk.min(axis=0)).astype(np.int64), 0, shape)
    last = np.clip(np.ceil(ijk.max(axis=0)).astype(np.int64) + 1, 0, shape)
    if np.any(last <= first):
        return out
    jj, kk = np.meshgrid(
        np.arange(first[1], last[1]), np.arange(first[2], last[2]), indexing="ij"
    )
    plane = np.stack([np.zeros_like(jj), jj, kk], axis=-1).astype(np.float64)  # (J, K, 3)
    rows = max(1, _CHUNK_VOXELS // max(1, jj.size))
    src_shape = np.asarray(volume.shape)
    for i0 in range(int(first[0]), int(last[0]), rows):
        ii = np.arange(i0, min(i0 + rows, int(last[0])), dtype=np.float64)
        grid = np.broadcast_to(plane, (len(ii), *plane.shape)).copy()
        grid[..., 0] = ii[:, None, None]
        src = np.floor(grid @ linear.T + shift + 0.5).astype(np.int64)
        inside = np.all((src >= 0) & (src < src_shape), axis=-1)
        values = np.zeros(inside.shape, dtype=bool)
        hit = src[inside]
        values[inside] = volume.mask[hit[:, 0], hit[:, 1], hit[:, 2]]
        out[i0 : i0 + len(ii), first[1] : last[1], first[2] : last[2]] = values
    return out


def _iou(occ: Occupancy) -> float:
    inter = np.count_nonzero(occ.pred & occ.gt)
    union = np.count_nonzero(occ.pred | occ.gt)
    return float(inter / union) if union else 1.0


def _dice(occ: Occupancy) -> float:
    inter = np.count_nonzero(occ.pred & occ.gt)
    total = np.count_nonzero(occ.pred) + np.count_nonzero(occ.gt)
    return float(2.0 * inter / total) if total else 1.0


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
    offsets = np.stack(
        np.meshgrid(*(np.arange(-r, r + 1) for r in reach), indexing="ij"), axis=-1
    )
    structure = np.sqrt(((offsets * np.asarray(spacing)) ** 2).sum(axis=-1)) <= limit
    if structure.sum() <= 125:
        # Dilation and erosion by the structure's offsets, one shifted view at a
        # time (a few times faster than scipy's binary morphology here). As with
        # scipy's default border, nothing beyond the grid is near the mask's
        # other side: the shell is dilation(mask) minus erosion(mask).
        near_inside = np.zeros_like(mask)
        deep_inside = mask.copy()
        low = np.pad(mask, [(r, r) for r in reach], constant_values=False)
        high = np.pad(mask, [(r, r) for r in reach], constant_values=True)
        for offset in offsets[structure]:
            view = tuple(slice(r + o, r + o + n)
                         for r, o, n in zip(reach, offset, mask.shape, strict=True))
            near_inside |= low[view]
            deep_inside &= high[view]
        return near_inside & ~deep_inside
    inside = ndimage.distance_transform_edt(mask, sampling=spacing)
    outside = ndimage.distance_transform_edt(~mask, sampling=spacing)
    return np.where(mask, inside <= limit, outside <= limit)


def _surface_iou(occ: Occupancy, tol: float) -> float:
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
    return _iou(occupancy(pred, gt, resolution=resolution, voxel_size=voxel_size))


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
    return _dice(occupancy(pred, gt, resolution=resolution, voxel_size=voxel_size))


def surface_iou(
    pred: Shape,
    gt: Shape,
    *,
    tolerance_mm: float | None = None,
    resolution: int = DEFAULT_RESOLUTION,
    voxel_size: float | None = None,
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

    Returns
    -------
    float
        In [0, 1]; 1 for identical occupancies, 0 when the surfaces are more
        than about ``2 * tolerance_mm`` apart everywhere.
    """
    tol = _check_positive(tolerance_mm, "tolerance_mm")
    p, g = _inputs(pred, gt)
    margin = tol if tol is not None else 0.0
    occ = _occupancy(
        p,
        g,
        resolution=_check_resolution(resolution),
        voxel_size=_check_positive(voxel_size, "voxel_size"),
        margin_mm=margin,
    )
    return _surface_iou(occ, tol if tol is not None else float(occ.spacing.max()))


# -- surface samples ----------------------------------------------------------------------


def sample_surface(
    mesh: trimesh.Trimesh, n_points: int, *, seed: int | np.random.Generator = 0
) -> NDArray[np.float64]:
    """Points drawn uniformly by area on a triangle mesh.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Any triangle mesh (need not be closed), world mm.
    n_points : int
        Number of points.
    seed : int or numpy.random.Generator, optional
        Seed or generator of the random draws.

    Returns
    -------
    ndarray of shape (n_points, 3)
        Sample positions, world mm.

    Raises
    ------
    GeometryError
        If the mesh has no area.
    """
    n = _check_n_points(n_points)
    rng = _rng(seed)
    triangles = np.asarray(mesh.triangles, dtype=np.float64)
    cumulative = np.cumsum(np.asarray(mesh.area_faces, dtype=np.float64))
    if len(cumulative) == 0 or not cumulative[-1] > 0:
        raise GeometryError("the mesh has no surface area to sample")
    face = np.searchsorted(cumulative, rng.random(n) * cumulative[-1], side="right")
    face = np.minimum(face, len(cumulative) - 1)
    u, v = rng.random((2, n))
    fold = u + v > 1.0
    u[fold], v[fold] = 1.0 - u[fold], 1.0 - v[fold]
    a, b, c = triangles[face, 0], triangles[face, 1], triangles[face, 2]
    return a + u[:, None] * (b - a) + v[:, None] * (c - a)


def surface_distances(
    pred: Shape,
    gt: Shape,
    *,
    n_points: int = DEFAULT_N_POINTS,
    seed: int | np.random.Generator = 0,
) -> SurfaceDistances:
    """Sample both surfaces and measure nearest-neighbour distances between the samples.

    Parameters
    ----------
    pred, gt : Volume or trimesh.Trimesh
        Prediction and ground truth, world mm. A Volume's surface is its
        marching-cubes mesh.
    n_points : int, optional
        Samples per surface.
    seed : int or numpy.random.Generator, optional
        Both surfaces are sampled with generators started from the same
        sub-seed drawn from ``seed``, so a shape compared with itself gives
        identical samples and zero distances, and swapping ``pred`` and
        ``gt`` swaps the two distance arrays exactly.

    Returns
    -------
    SurfaceDistances
    """
    return _surface_distances(*_inputs(pred, gt), n_points=_check_n_points(n_points), seed=seed)


def _surface_distances(
    pred: _Input, gt: _Input, *, n_points: int, seed: int | np.random.Generator
) -> SurfaceDistances:
    from scipy.spatial import cKDTree

    sub_seed = int(_rng(seed).integers(2**63 - 1))
    pts_pred = sample_surface(pred.surface, n_points, seed=sub_seed)
    pts_gt = sample_surface(gt.surface, n_points, seed=sub_seed)
    pred_to_gt, _ = cKDTree(pts_gt).query(pts_pred)
    gt_to_pred, _ = cKDTree(pts_pred).query(pts_gt)
    lo, hi = gt.surface.bounds
    diagonal = float(np.linalg.norm(np.asarray(hi) - np.asarray(lo)))
    return SurfaceDistances(
        np.asarray(pred_to_gt, dtype=np.float64),
        np.asarray(gt_to_pred, dtype=np.float64),
        diagonal,
    )


def _chamfer_mm(dist: SurfaceDistances) -> float:
    return 0.5 * (float(dist.pred_to_gt.mean()) + float(dist.gt_to_pred.mean()))


def _precision_recall(dist: SurfaceDistances, tau_mm: float) -> tuple[float, float, float]:
    precision = float(np.mean(dist.pred_to_gt < tau_mm))
    recall = float(np.mean(dist.gt_to_pred < tau_mm))
    total = precision + recall
    f = 2.0 * precision * recall / total if total > 0 else 0.0
    return f, precision, recall


def _hd95(dist: SurfaceDistances) -> float:
    return max(
        float(np.percentile(dist.pred_to_gt, 95)), float(np.percentile(dist.gt_to_pred, 95))
    )


def _assd(dist: SurfaceDistances) -> float:
    return float(np.concatenate([dist.pred_to_gt, dist.gt_to_pred]).mean())


def _check_tau(tau: float) -> float:
    value = _check_positive(tau, "tau")
    assert value is not None
    return value


def chamfer_l1(
    pred: Shape,
    gt: Shape,
    *,
    n_points: int = DEFAULT_N_POINTS,
    seed: int | np.random.Generator = 0,
    normalized: bool = False,
) -> float:
    """Chamfer-L1 distance: the mean of the two directed mean surface distances.

    Parameters
    ----------
    pred, gt : Volume or trimesh.Trimesh
        Prediction and ground truth, world mm.
    n_points, seed
        Surface sampling; see :func:`surface_distances`.
    normalized : bool, optional
        Divide by the ground-truth bounding-box diagonal ("Chamfer-L1 / diag").

    Returns
    -------
    float
        Distance in mm, or unitless when ``normalized``.
    """
    dist = surface_distances(pred, gt, n_points=n_points, seed=seed)
    value = _chamfer_mm(dist)
    return value / dist.gt_diagonal_mm if normalized else value


def f_score(
    pred: Shape,
    gt: Shape,
    *,
    tau: float = 0.01,
    n_points: int = DEFAULT_N_POINTS,
    seed: int | np.random.Generator = 0,
) -> float:
    """F-score of the surfaces at distance threshold ``tau`` × ground-truth diagonal.

    Parameters
    ----------
    pred, gt : Volume or trimesh.Trimesh
        Prediction and ground truth, world mm.
    tau : float, optional
        Threshold as a fraction of the ground-truth bounding-box diagonal.
    n_points, seed
        Surface sampling; see :func:`surface_distances`.

    Returns
    -------
    float
        ``2 P R / (P + R)`` in [0, 1] with precision ``P`` (predicted samples
        closer than the threshold to the ground truth) and recall ``R``
        (ground-truth samples closer than the threshold to the prediction).
    """
    tau = _check_tau(tau)
    dist = surface_distances(pred, gt, n_points=n_points, seed=seed)
    return _precision_recall(dist, tau * dist.gt_diagonal_mm)[0]


def hd95(
    pred: Shape,
    gt: Shape,
    *,
    n_points: int = DEFAULT_N_POINTS,
    seed: int | np.random.Generator = 0,
) -> float:
    """95th-percentile Hausdorff distance, mm: the larger of the two directed 95th percentiles.

    Parameters
    ----------
    pred, gt : Volume or trimesh.Trimesh
        Prediction and ground truth, world mm.
    n_points, seed
        Surface sampling; see :func:`surface_distances`.

    Returns
    -------
    float
    """
    return _hd95(surface_distances(pred, gt, n_points=n_points, seed=seed))


def assd(
    pred: Shape,
    gt: Shape,
    *,
    n_points: int = DEFAULT_N_POINTS,
    seed: int | np.random.Generator = 0,
) -> float:
    """Average symmetric surface distance, mm: the mean of both directions' distances pooled.

    With the same number of samples on both surfaces it equals the Chamfer-L1
    distance in mm.

    Parameters
    ----------
    pred, gt : Volume or trimesh.Trimesh
        Prediction and ground truth, world mm.
    n_points, seed
        Surface sampling; see :func:`surface_distances`.

    Returns
    -------
    float
    """
    return _assd(surface_distances(pred, gt, n_points=n_points, seed=seed))


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
) -> Metrics:
    """Every metric of ``pred`` against ``gt`` from one grid and one set of samples.

    Parameters
    ----------
    pred, gt : Volume or trimesh.Trimesh
        Prediction and ground truth, world mm. Meshes must be closed.
    n_points : int, optional
        Surface samples per shape (default 100 000).
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

    Returns
    -------
    Metrics

    Raises
    ------
    InputError, EmptyMaskError, GeometryError
        If a shape is of the wrong type, empty or not a closed mesh.
    OptionError
        If an option is out of range.
    """
    n = _check_n_points(n_points)
    tau = _check_tau(tau)
    tol = _check_positive(surface_tolerance_mm, "surface_tolerance_mm")
    res = _check_resolution(resolution)
    size = _check_positive(voxel_size, "voxel_size")
    _rng(seed)  # validate before the expensive work
    p, g = _inputs(pred, gt)

    occ = _occupancy(p, g, resolution=res, voxel_size=size, margin_mm=tol or 0.0,
                     pred_occupancy=pred_occupancy)
    tol_mm = tol if tol is not None else float(occ.spacing.max())
    dist = _surface_distances(p, g, n_points=n, seed=seed)
    tau_mm = tau * dist.gt_diagonal_mm
    f, precision, recall = _precision_recall(dist, tau_mm)
    chamfer_mm = _chamfer_mm(dist)
    return Metrics(
        volume_iou=_iou(occ),
        dice=_dice(occ),
        surface_iou=_surface_iou(occ, tol_mm),
        chamfer_l1_mm=chamfer_mm,
        chamfer_l1=chamfer_mm / dist.gt_diagonal_mm,
        f_score=f,
        precision=precision,
        recall=recall,
        hd95_mm=_hd95(dist),
        assd_mm=_assd(dist),
        volume_pred_mm3=p.volume_mm3,
        volume_gt_mm3=g.volume_mm3,
        volume_error=(p.volume_mm3 - g.volume_mm3) / g.volume_mm3,
        tau_mm=tau_mm,
        surface_tolerance_mm=tol_mm,
        voxel_size_mm=float(occ.spacing.max()),
        n_points=n,
    )
