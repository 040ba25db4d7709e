"""Reconstruction from planes along several axes: every drawn view used at once.

An annotator may draw a structure on a few axial slices and on one or two
sagittal and coronal ones. Each **view** (the planes of one orientation) is
interpolated across its own planes as shape-based interpolation does
(:func:`slicerecon.surface.across_planes.fill_between`: the in-plane signed
distances, linear or monotone cubic along the view's normal), and the views are
blended voxel by voxel with weights ``1 / (D + eps) ** p``, ``D`` the distance
to the view's nearest plane (inverse-distance weighting, Shepard 1968):

* on a drawn plane its own view has ``D = 0``, so the result's section there is
  the drawn mask (the zero level lies half-way between pixel centres, as in
  every signed-distance surface here);
* between the axial planes the axial view dominates, near a sagittal plane the
  sagittal view, and where the axial stack ends, a sagittal plane that shows
  the structure going on takes over;
* a view of three planes or more is taken to cover the structure along its
  normal (it ends at its outer planes, as shape-based interpolation ends);
  a view of one or two planes is extruded beyond them and weighs only near them.

Between two planes of one view and nothing else, the result is that view's own
interpolation: a single-axis annotation gives shape-based interpolation.
This is not a union of per-axis results (ITK's morphological contour
interpolation takes one), and every view constrains every point.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..annotation import Annotation
from ..errors import EmptyMaskError, GeometryError
from ..sections import Volume, in_plane_axes
from .across_planes import fill_between
from .marching import march_field
from .sdf import SdfField, plane_signed_distance

__all__ = ["VIEW_WEIGHT_EXPONENT", "ViewsSurface", "views_field", "views_surface"]

logger = logging.getLogger(__name__)

VIEW_WEIGHT_EXPONENT = 2.0
"""``p`` of the views' inverse-distance weights (chosen on the development shapes)."""
COMPLETE_VIEW = 3
"""A view of this many planes or more is taken to cover the structure along its normal."""
CROP_PAD = 3
"""Voxels kept around the drawn foreground."""
_EPS_MM = 1e-3


@dataclass
class ViewsSurface:
    """A structure reconstructed from several views.

    Attributes
    ----------
    mesh : trimesh.Trimesh
        Closed, outward, world mm.
    occupancy : Volume
        The voxel centres inside, on the crop of the reference grid.
    field : SdfField
        The blended signed-distance field (padded), for a joint resolution.
    """

    mesh: object
    occupancy: Volume
    field: SdfField


def _view_axes(annotation: Annotation, value: int) -> dict[int, list[tuple[float, NDArray]]]:
    """The planes of structure ``value`` by grid axis: ``{axis: [(index, mask), ...]}``."""
    inverse = np.linalg.inv(annotation.affine)
    views: dict[int, list[tuple[float, NDArray]]] = {}
    for plane in annotation.planes_of(value):
        normal = plane.pose.normal
        found = None
        for axis in range(3):
            a, b = in_plane_axes(axis)
            if np.allclose(plane.pose.affine[:3, 0], annotation.affine[:3, a]) and np.allclose(
                plane.pose.affine[:3, 1], annotation.affine[:3, b]
            ):
                found = axis
                break
        if found is None or not np.isfinite(normal).all():
            raise GeometryError(
                "a plane is not a slice of the reference grid: several views are reconstructed "
                "on grid-aligned planes"
            )
        index = (inverse[:3, :3] @ plane.pose.affine[:3, 3] + inverse[:3, 3])[found]
        views.setdefault(found, []).append((float(index), plane.mask(value)))
    return {axis: sorted(p, key=lambda item: item[0]) for axis, p in views.items()}


def views_field(
    annotation: Annotation,
    value: int,
    *,
    interpolation: str = "pchip",
    exponent: float = VIEW_WEIGHT_EXPONENT,
) -> SdfField:
    """The blended signed-distance field of one structure drawn in several views.

    Parameters
    ----------
    annotation : Annotation
        Planes perpendicular to grid axes of its reference grid.
    value : int
        The structure.
    interpolation : {"pchip", "linear"}
        Across each view's planes.
    exponent : float
        ``p`` of the inverse-distance weights.

    Returns
    -------
    SdfField
        mm, negative inside, on the crop of the reference grid around the
        drawn foreground, padded by one positive sample (``axis`` 2,
        ``upsample`` 1).

    Raises
    ------
    EmptyMaskError
        The structure is drawn nowhere.
    GeometryError
        A plane that is not a slice of the reference grid.
    """
    views = _view_axes(annotation, value)
    shape = np.asarray(annotation.grid_shape)
    lo, hi = shape.copy(), np.zeros(3, dtype=np.int64)
    for axis, planes in views.items():
        a, b = in_plane_axes(axis)
        for index, mask in planes:
            if not mask.any():
                continue
            rows = np.flatnonzero(mask.any(axis=1))
            cols = np.flatnonzero(mask.any(axis=0))
            k = int(round(index))
            lo[a], hi[a] = min(lo[a], rows[0]), max(hi[a], rows[-1] + 1)
            lo[b], hi[b] = min(lo[b], cols[0]), max(hi[b], cols[-1] + 1)
            lo[axis], hi[axis] = min(lo[axis], k), max(hi[axis], k + 1)
    if np.any(hi <= lo):
        raise EmptyMaskError(f"structure {value} is drawn on no plane")
    lo = np.maximum(lo - CROP_PAD, 0)
    hi = np.minimum(hi + CROP_PAD, shape)
    size = tuple(int(v) for v in hi - lo)
    spacing = np.linalg.norm(annotation.affine[:3, :3], axis=0)
    far = np.float32(np.linalg.norm(np.asarray(size) * spacing) + spacing.max())
    numerator = np.zeros(size, dtype=np.float32)
    denominator = np.zeros(size, dtype=np.float32)
    for axis, planes in views.items():
        own, distance = _view(planes, axis, lo, hi, spacing, far, interpolation)
        weight = 1.0 / np.power(distance + _EPS_MM, exponent, dtype=np.float32)
        numerator += weight * own
        denominator += weight
    values = numerator / denominator
    padded = np.full(tuple(n + 2 for n in size), far, dtype=np.float32)
    padded[1:-1, 1:-1, 1:-1] = values
    affine = annotation.affine.copy()
    affine[:3, 3] = annotation.affine[:3, :3] @ (lo - 1.0) + annotation.affine[:3, 3]
    return SdfField(padded, affine, (int(lo[0]), int(lo[1]), int(lo[2])), 1, 2)


def _view(
    planes: list[tuple[float, NDArray]],
    axis: int,
    lo: NDArray[np.int64],
    hi: NDArray[np.int64],
    spacing: NDArray[np.float64],
    far: np.float32,
    interpolation: str,
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """One view's interpolated field and each voxel's distance (mm) to its nearest plane,
    both on the crop in grid axis order."""
    a, b = in_plane_axes(axis)
    pixel = spacing[[a, b]]
    indices = np.array([p[0] for p in planes], dtype=np.float64)
    distances = {}
    for n, (_, mask) in enumerate(planes):
        d = plane_signed_distance(mask[lo[a] : hi[a], lo[b] : hi[b]], pixel)
        distances[n] = d
    samples = np.arange(lo[axis], hi[axis], dtype=np.float64)
    field = np.full((samples.size, hi[a] - lo[a], hi[b] - lo[b]), far, dtype=np.float32)
    used = np.arange(len(planes))
    fill_between(field, samples, indices, used, distances, interpolation)
    for side, n in ((0, 0), (1, len(planes) - 1)):
        beyond = samples < indices[n] if side == 0 else samples > indices[n]
        base = np.minimum(distances[n], far)
        if len(planes) >= COMPLETE_VIEW:
            gap = np.abs(samples[beyond] - indices[n]).astype(np.float32) * np.float32(
                spacing[axis]
            )
            field[beyond] = np.maximum(base[None], gap[:, None, None])
        else:
            field[beyond] = base[None]
    field = np.minimum(np.nan_to_num(field, posinf=far), far)
    nearest = np.min(np.abs(samples[:, None] - indices[None, :]), axis=1) * spacing[axis]
    distance = np.broadcast_to(nearest.astype(np.float32)[:, None, None], field.shape)
    return np.moveaxis(field, 0, axis), np.moveaxis(distance, 0, axis)


def views_surface(
    annotation: Annotation,
    value: int,
    *,
    interpolation: str = "pchip",
    exponent: float = VIEW_WEIGHT_EXPONENT,
) -> ViewsSurface:
    """Mesh and occupancy of one structure drawn in several views (:func:`views_field`).

    Returns
    -------
    ViewsSurface

    Raises
    ------
    EmptyMaskError
        Nothing inside.
    """
    field = views_field(annotation, value, interpolation=interpolation, exponent=exponent)
    values = field.values
    if not np.any(values < 0):
        raise EmptyMaskError(f"structure {value}: the blended views hold no inside sample")
    step = float(np.min(np.linalg.norm(field.affine[:3, :3], axis=0)))
    nudge = np.float32(1e-3 * step)
    flat = values.reshape(-1)
    near = np.flatnonzero(np.abs(flat) < nudge)
    flat[near] = np.where(flat[near] < 0, -nudge, nudge)
    mesh = march_field(values, field.affine)
    occupancy_affine = field.affine.copy()
    occupancy_affine[:3, 3] = field.affine[:3, :3] @ np.ones(3) + field.affine[:3, 3]
    occupancy = Volume(values[1:-1, 1:-1, 1:-1] < 0, occupancy_affine)
    return ViewsSurface(mesh, occupancy, field)
