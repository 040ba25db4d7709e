"""The shapes metrics compare, their derived surfaces, the result records and checks."""

from __future__ import annotations

import logging
from dataclasses import asdict, dataclass
from functools import cached_property
from typing import NamedTuple

import numpy as np
import trimesh
from numpy.typing import NDArray

from ..errors import EmptyMaskError, InputError, OptionError, SlicereconError
from ..rasterize import mesh_to_mask, require_closed
from ..sections import Volume
from ..surface.marching import signed_volume, volume_to_mesh

logger = logging.getLogger(__name__)

Shape = Volume | trimesh.Trimesh
"""A shape to evaluate: a binary Volume or a closed mesh, world mm."""

DEFAULT_N_POINTS = 100_000
"""Surface samples per shape for the distance metrics."""

DEFAULT_RESOLUTION = 128
"""Voxels along the longest side of the evaluation grid when the ground truth is a mesh."""

MAX_GRID_VOXELS = 400_000_000
"""Refuse evaluation grids larger than this (about 0.4 GB per boolean mask)."""

CHUNK_VOXELS = 4_000_000
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


class MetricInput:
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
        """The surface to sample, world mm (marching cubes for a Volume, not repaired:
        sampling needs no closed mesh, :func:`~slicerecon.surface.marching.volume_to_mesh`)."""
        if isinstance(self.shape, Volume):
            return volume_to_mesh(self.shape, repair=False)
        return self.shape

    @cached_property
    def bounds_mm(self) -> NDArray[np.float64]:
        """World-axis-aligned bounds ``[min, max]`` of the shape, ndarray of shape (2, 3)."""
        if isinstance(self.shape, Volume):
            lo, hi = self.shape.bounding_box_vox()
            corners = lo - 0.5 + CUBE_CORNERS * (hi - lo)
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
            return resample_nearest(self.shape, affine, shape)
        return mesh_to_mask(self.shape, affine, shape)


CUBE_CORNERS = np.array(list(np.ndindex(2, 2, 2)), dtype=np.float64)


def metric_inputs(pred: Shape, gt: Shape) -> tuple[MetricInput, MetricInput]:
    return MetricInput(pred, "prediction"), MetricInput(gt, "ground truth")


def check_n_points(n_points: int) -> int:
    if isinstance(n_points, bool) or not isinstance(n_points, int | np.integer):
        raise OptionError(f"n_points must be an integer (got {n_points!r})")
    if n_points < 1:
        raise OptionError(f"n_points must be >= 1 (got {n_points})")
    return int(n_points)


def check_positive(value: float | None, name: str) -> float | None:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float | np.integer | np.floating):
        raise OptionError(f"{name} must be a number (got {value!r})")
    if not np.isfinite(value) or value <= 0:
        raise OptionError(f"{name} must be a positive finite number (got {value})")
    return float(value)


def check_resolution(resolution: int) -> int:
    if isinstance(resolution, bool) or not isinstance(resolution, int | np.integer):
        raise OptionError(f"resolution must be an integer (got {resolution!r})")
    if resolution < 8:
        raise OptionError(f"resolution must be at least 8 voxels (got {resolution})")
    return int(resolution)


def as_rng(seed: int | np.random.Generator) -> np.random.Generator:
    if isinstance(seed, np.random.Generator):
        return seed
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer):
        raise OptionError(f"seed must be an integer or a numpy Generator (got {seed!r})")
    return np.random.default_rng(int(seed))


def place(
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


def resample_nearest(
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
        return place(volume.mask, np.rint(shift).astype(np.int64), shape)

    out = np.zeros(shape, dtype=bool)
    lo, hi = volume.bounding_box_vox()
    corners = volume.index_to_world(lo - 0.5 + CUBE_CORNERS * (hi - lo))
    ijk = corners @ np.linalg.inv(affine)[:3, :3].T + np.linalg.inv(affine)[:3, 3]
    first = np.clip(np.floor(ijk.min(axis=0)).astype(np.int64), 0, shape)
    last = np.clip(np.ceil(ijk.max(axis=0)).astype(np.int64) + 1, 0, shape)
    if np.any(last <= first):
        return out
    jj, kk = np.meshgrid(np.arange(first[1], last[1]), np.arange(first[2], last[2]), indexing="ij")
    plane = np.stack([np.zeros_like(jj), jj, kk], axis=-1).astype(np.float64)  # (J, K, 3)
    rows = max(1, CHUNK_VOXELS // max(1, jj.size))
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
