"""Choose cross-sections from a dense mask, and derive orthographic projections.

Sections
--------
:func:`sample_sections` keeps some planes of a dense :class:`~slicerecon.sections.Volume`
perpendicular to one grid axis. The candidate range runs from the first to the
last plane that holds any foreground, both included:

* ``n=N`` keeps ``N`` planes evenly spaced over that range, rounded to grid
  planes with *round half up*: plane ``k`` (``k = 0 .. N-1``) is
  ``first + floor(k * (last - first) / (N - 1) + 1/2)``, computed in exact
  integer arithmetic, so the first and last planes are always kept and no
  plane repeats;
* ``every=K`` keeps ``first, first + K, first + 2K, ...`` up to ``last``; the
  last plane is kept only when it falls on the step.

The sections stay on the volume's own grid (same affine and grid shape), so
they can be compared voxel for voxel with the volume they came from.
:func:`dense_count` gives the paper's "dense" setting (twice the contours) for
a sparse count ``N``: ``2N - 1`` planes, which keeps every sparse plane and
adds one half-way between each consecutive pair.

Projections
-----------
:func:`projections_from_volume` gives the exact silhouettes of a dense mask
(the paper's prior). :func:`projections_from_sections` derives silhouettes from
the sections alone, for inputs where nothing else is known: the view along the
section axis is the union of the plane masks; a side view (along an in-plane
axis) holds each plane's 1-D profile on the plane's row and, between two
consecutive planes, a morph of their profiles (linear interpolation of 1-D
signed distance functions). See ``docs/sampling.md``.
"""

from __future__ import annotations

import logging
import math

import numpy as np
from numpy.typing import NDArray

from .errors import EmptyMaskError, GeometryError, InputError, OptionError
from .sections import (
    AXIS_NAMES,
    CrossSections,
    Projection,
    Projections,
    Volume,
    axis_index,
    in_plane_axes,
)

__all__ = [
    "pool_any",
    "pool_sections",
    "visual_hull",
    "dense_count",
    "evenly_spaced_planes",
    "projections_from_sections",
    "projections_from_volume",
    "sample_sections",
]

logger = logging.getLogger(__name__)


def _check_count(value: object, name: str, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer):
        raise OptionError(f"{name} must be an integer (got {value!r})")
    if int(value) < minimum:
        raise OptionError(f"{name} must be >= {minimum} (got {value})")
    return int(value)


def evenly_spaced_planes(first: int, last: int, n: int) -> NDArray[np.int64]:
    """Return ``n`` grid plane indices evenly spaced from ``first`` to ``last``.

    Plane ``k`` is ``first + floor(k * (last - first) / (n - 1) + 1/2)`` (round
    half up), computed with integers so that no floating-point error can move a
    plane. Both ends are included.

    Parameters
    ----------
    first, last : int
        First and last plane index of the range, ``first <= last``.
    n : int
        Number of planes, ``2 <= n <= last - first + 1``.

    Returns
    -------
    ndarray of shape (n,), int64
        Strictly increasing plane indices.

    Raises
    ------
    OptionError
        If ``n < 2``, the range is reversed, or ``n`` exceeds the number of
        planes in the range.
    """
    n = _check_count(n, "n", 2)
    first, last = int(first), int(last)
    if last < first:
        raise OptionError(f"the range must run upwards (got first={first}, last={last})")
    available = last - first + 1
    if n > available:
        raise OptionError(
            f"cannot keep {n} planes: the range from plane {first} to plane {last} "
            f"holds only {available}; ask for at most {available}"
        )
    span = last - first
    k = np.arange(n, dtype=np.int64)
    return first + (2 * k * span + (n - 1)) // (2 * (n - 1))


def dense_count(n: int) -> int:
    """Number of planes of the "dense" setting that goes with ``n`` sparse planes.

    The paper compares sparse input with dense input of twice as many contours.
    slicerecon uses ``2n - 1`` planes: with :func:`evenly_spaced_planes` over the
    same range, the dense planes are exactly the sparse planes plus one plane
    half-way (rounded half up) between each consecutive pair.

    Parameters
    ----------
    n : int
        Number of sparse planes, ``n >= 2``.

    Returns
    -------
    int
        ``2 * n - 1``.
    """
    n = _check_count(n, "n", 2)
    return 2 * n - 1


def sample_sections(
    volume: Volume,
    *,
    n: int | None = None,
    every: int | None = None,
    axis: int | str = "z",
) -> CrossSections:
    """Keep some planes of a dense mask as cross-sections.

    The planes are chosen in the range from the first to the last plane
    (perpendicular to ``axis``) that holds any foreground, both included.

    Parameters
    ----------
    volume : Volume
        The dense mask.
    n : int, optional
        Keep ``n`` planes evenly spaced over the range, rounded half up to grid
        planes (see :func:`evenly_spaced_planes`); the first and last planes of
        the range are always kept. ``2 <= n <=`` number of planes in the range.
    every : int, optional
        Keep every ``every``-th plane from the first one: ``first, first +
        every, ...`` up to the last plane of the range. The last plane is kept
        only if it falls on the step. Give ``n`` or ``every``, not both; with
        neither, every plane of the range is kept (``every=1``).
    axis : int or {"x", "y", "z"}, default "z"
        Grid axis the planes are perpendicular to.

    Returns
    -------
    CrossSections
        On the volume's own grid: ``masks`` of shape (P, M, N) are the volume's
        planes (``numpy.moveaxis(volume.mask, axis, 0)[indices]``), ``indices``
        the kept plane indices (as floats), ``affine`` and ``grid_shape`` the
        volume's.

    Raises
    ------
    OptionError
        If both ``n`` and ``every`` are given, either is out of range, or ``n``
        exceeds the number of planes in the range (the message says how many
        there are).
    EmptyMaskError
        If the volume holds no foreground.
    """
    if not isinstance(volume, Volume):
        raise InputError(f"sample_sections needs a Volume (got {type(volume).__name__})")
    ax = axis_index(axis)
    if n is not None and every is not None:
        raise OptionError(f"give either n (got {n}) or every (got {every}), not both")
    if n is not None:
        n = _check_count(n, "n", 2)
    step = 1 if every is None else _check_count(every, "every", 1)

    occupied = volume.occupied_planes(ax)
    if occupied.size == 0:
        raise EmptyMaskError(
            "the mask is empty: no plane holds foreground, so there is nothing to sample; "
            "check the label or threshold that made it"
        )
    first, last = int(occupied[0]), int(occupied[-1])
    if n is not None:
        indices = evenly_spaced_planes(first, last, n)
    else:
        indices = np.arange(first, last + 1, step, dtype=np.int64)
        if indices.size == 1 and last > first:
            logger.warning(
                "every=%d keeps only plane %d: the shape spans planes %d..%d along %s",
                step,
                first,
                first,
                last,
                AXIS_NAMES[ax],
            )
    masks = np.moveaxis(volume.mask, ax, 0)[indices]
    logger.debug(
        "kept %d of planes %d..%d along %s: %s",
        indices.size,
        first,
        last,
        AXIS_NAMES[ax],
        indices.tolist(),
    )
    return CrossSections(masks, indices.astype(np.float64), ax, volume.affine, volume.shape)


def projections_from_volume(volume: Volume) -> Projections:
    """The exact orthographic silhouettes of a dense mask (the paper's prior).

    Parameters
    ----------
    volume : Volume
        The dense mask, of shape (I, J, K).

    Returns
    -------
    Projections
        ``source="volume"``; view ``a`` is ``volume.mask.any(axis=a)``, with rows
        and columns along the two remaining grid axes in increasing order
        (shapes (J, K), (I, K) and (I, J)).

    Raises
    ------
    EmptyMaskError
        If the volume holds no foreground.
    """
    if not isinstance(volume, Volume):
        raise InputError(f"projections_from_volume needs a Volume (got {type(volume).__name__})")
    if volume.is_empty:
        raise EmptyMaskError("the mask is empty: its projections would show nothing")
    x, y, z = (Projection(np.asarray(volume.mask.any(axis=a)), a, volume.affine) for a in range(3))
    return Projections((x, y, z), source="volume")


def _distance_to(target: NDArray[np.bool_]) -> NDArray[np.float64]:
    """Distance, in pixels, from every pixel to the nearest ``True`` pixel of its row.

    ``target`` is of shape (P, L); the result has the same shape and is ``inf``
    on rows without a ``True`` pixel.
    """
    pos = np.arange(target.shape[1], dtype=np.float64)
    left = np.maximum.accumulate(np.where(target, pos, -np.inf), axis=1)
    right = np.minimum.accumulate(np.where(target, pos, np.inf)[:, ::-1], axis=1)[:, ::-1]
    return np.minimum(pos - left, right - pos)


def _signed_distance_1d(profiles: NDArray[np.bool_]) -> NDArray[np.float64]:
    """Signed distance to the boundary of 1-D profiles, pixels, positive inside.

    The boundary lies half-way between an inside and an outside pixel, and
    outside both ends of the row; an inside pixel next to it has distance
    ``0.5``, an outside pixel ``-0.5``. Rows without foreground are ``-inf``.

    Parameters
    ----------
    profiles : ndarray of shape (P, L), bool

    Returns
    -------
    ndarray of shape (P, L), float64
    """
    padded = np.pad(profiles, ((0, 0), (1, 1)))
    inside = _distance_to(~padded)[:, 1:-1] - 0.5
    outside = _distance_to(padded)[:, 1:-1] - 0.5
    return np.where(profiles, inside, -outside)


def _side_view(
    profiles: NDArray[np.bool_], indices: NDArray[np.float64], n_rows: int
) -> NDArray[np.bool_]:
    """Rows of a side view from per-plane 1-D profiles.

    Parameters
    ----------
    profiles : ndarray of shape (P, L), bool
        Profile of each plane along the in-plane axis kept by the view.
    indices : ndarray of shape (P,)
        Plane positions along the section axis (index coordinates, increasing).
    n_rows : int
        Grid size along the section axis.

    Returns
    -------
    ndarray of shape (n_rows, L), bool
        Row ``g`` is the profile of the plane at ``g`` if there is one, the
        signed-distance morph of the two planes around ``g`` if ``g`` lies
        between planes, and empty outside ``[indices[0], indices[-1]]``, except
        the rows nearest to fractional end planes, which hold their profiles.
    """
    image = np.zeros((n_rows, profiles.shape[1]), dtype=bool)
    lo = max(math.ceil(indices[0]), 0)
    hi = min(math.floor(indices[-1]), n_rows - 1)
    if lo > hi:
        # No grid row lies between the first and the last plane (e.g. one
        # fractional plane): put each profile on its nearest grid row.
        rows = np.clip(np.rint(indices).astype(np.int64), 0, n_rows - 1)
        for row, profile in zip(rows, profiles, strict=True):
            image[row] |= profile
        return image
    grid = np.arange(lo, hi + 1)
    below = np.searchsorted(indices, grid, side="right") - 1
    on_plane = indices[below] == grid
    image[grid[on_plane]] = profiles[below[on_plane]]
    between = ~on_plane
    if np.any(between):
        g, i = grid[between], below[between]
        sdf = _signed_distance_1d(profiles)
        w = ((g - indices[i]) / (indices[i + 1] - indices[i]))[:, None]
        # 0 < w < 1 here, so an empty profile (-inf) keeps the row empty, never NaN.
        image[g] = (1.0 - w) * sdf[i] + w * sdf[i + 1] >= 0.0
    # An end plane between grid rows also marks the row it lies in, so that the
    # voxel layer holding it (and any box around it) contains it.
    for end in (0, -1):
        row = int(np.clip(np.rint(indices[end]), 0, n_rows - 1))
        if not lo <= row <= hi:
            image[row] |= profiles[end]
    return image


def _drifting_layers(sections: CrossSections) -> list[tuple[int, NDArray[np.bool_]]]:
    """The regions that join drifting pairs sweep on the grid layers between planes.

    Per grid row strictly between two consecutive planes, the in-plane mask
    of each drifting pair's moving blend there
    (:func:`~slicerecon.surface.drift.swept_blends`): what the signed-distance
    surface adds, so that the derived silhouettes hold it too.
    """
    from .surface.drift import swept_blends
    from .surface.sdf import plane_signed_distance

    rows = np.arange(sections.grid_shape[sections.axis], dtype=np.float64)
    blends = swept_blends(
        sections.masks,
        sections.indices,
        rows,
        sections.spacing[list(sections.plane_axes)],
        float(sections.spacing[sections.axis]),
        plane_signed_distance,
    )
    return [(row, blend < 0) for row, blend in blends]


def projections_from_sections(sections: CrossSections) -> Projections:
    """Orthographic silhouettes derived from the cross-sections alone.

    Use these when no projection of the true shape is known.

    * The view along the section axis is the union of the plane masks.
    * A view along an in-plane axis ``a`` is built row by row along the
      section axis. Each plane contributes its 1-D profile (``mask.any`` over
      ``a``), placed on the grid row of its index. On each grid index strictly
      between two consecutive planes, the row is the morph of their two
      profiles: the 1-D signed distance functions (pixels, positive inside,
      boundary half-way between pixels) are interpolated linearly in the plane
      index and thresholded at 0 (a pixel exactly on the morphed boundary is
      inside). Intervals thus slide and grow or shrink from one plane to the
      next; a profile that is empty (an empty plane) stops the silhouette at
      the neighbouring plane. Rows outside ``[first plane, last plane]`` are
      empty, except that an end plane at a fractional index also fills the row
      nearest to it (the voxel layer it lies in).
    * Fractional plane indices are allowed: the rows are the integer grid
      indices between them. If no grid index lies between the first and the
      last plane, each profile is put on its nearest grid row.

    Parameters
    ----------
    sections : CrossSections
        The planes, on a reference grid of shape ``grid_shape``.

    Returns
    -------
    Projections
        ``source="sections"``; views on the reference grid, laid out as in
        :class:`~slicerecon.sections.Projection` (rows and columns along the
        two remaining grid axes in increasing order).

    Raises
    ------
    EmptyMaskError
        If no plane holds any foreground.
    """
    if not isinstance(sections, CrossSections):
        raise InputError(
            f"projections_from_sections needs CrossSections (got {type(sections).__name__})"
        )
    sections.require_foreground()
    s = sections.axis
    n_rows = sections.grid_shape[s]
    drifting = _drifting_layers(sections)
    along = np.asarray(sections.masks.any(axis=0))
    for _, region in drifting:
        along |= region
    views: dict[int, Projection] = {s: Projection(along, s, sections.affine)}
    for plane_dim, a in enumerate(sections.plane_axes, start=1):
        # (P, L): each plane's profile along the other in-plane axis b
        profiles = np.asarray(sections.masks.any(axis=plane_dim))
        b = next(ax for ax in sections.plane_axes if ax != a)
        image = _side_view(profiles, sections.indices, n_rows)  # rows along s, columns along b
        for row, region in drifting:
            image[row] |= region.any(axis=plane_dim - 1)
        if b < s:
            image = image.T
        views[a] = Projection(image, a, sections.affine)
    return Projections((views[0], views[1], views[2]), source="sections")


def pool_any(mask: NDArray[np.bool_], factor: int) -> NDArray[np.bool_]:
    """Any-pooling: a coarser mask whose cell is set when any voxel of its block is.

    Parameters
    ----------
    mask : ndarray of shape (N_0, ..., N_d), bool
    factor : int
        Block size along every axis (>= 1). The grid is padded with background
        up to a multiple of ``factor``.

    Returns
    -------
    ndarray of shape (ceil(N_0 / factor), ...), bool
        ``mask`` itself when ``factor`` is 1.
    """
    if factor == 1:
        return mask
    out = mask
    for axis in range(mask.ndim):  # one axis at a time: each reduction reads one axis
        extra = (-out.shape[axis]) % factor
        if extra:
            out = np.pad(out, [(0, extra) if a == axis else (0, 0) for a in range(out.ndim)])
        shape = out.shape[:axis] + (out.shape[axis] // factor, factor) + out.shape[axis + 1 :]
        out = out.reshape(shape).any(axis=axis + 1)
    return out


def pool_sections(sections: CrossSections, factor: int) -> CrossSections:
    """The cross-sections on the grid :func:`pool_any` makes, ``factor`` times coarser.

    Each plane's mask is any-pooled in-plane; its position moves to the
    coarse grid's index coordinates (a fine index ``i`` lies at
    ``(i + 0.5) / factor - 0.5``); the affine maps the coarse voxel centres to
    the centres of their blocks, so distances in mm are kept.

    Parameters
    ----------
    sections : CrossSections
    factor : int
        Block size (>= 1) along every axis.

    Returns
    -------
    CrossSections
        On a grid of shape ``ceil(grid_shape / factor)``; ``sections`` itself
        when ``factor`` is 1.

    Raises
    ------
    OptionError
        For ``factor < 1``.
    """
    f = int(factor)
    if f < 1:
        raise OptionError(f"factor must be >= 1 (got {factor})")
    if f == 1:
        return sections
    masks = np.stack([pool_any(m, f) for m in sections.masks])
    affine = np.array(sections.affine, dtype=np.float64)
    affine[:3, 3] = affine[:3, :3] @ np.full(3, (f - 1) / 2.0) + affine[:3, 3]
    affine[:3, :3] = affine[:3, :3] * f
    return CrossSections(
        masks,
        (np.asarray(sections.indices) + 0.5) / f - 0.5,
        sections.axis,
        affine,
        tuple(-(-int(n) // f) for n in sections.grid_shape),
    )


def visual_hull(projections: Projections, grid_shape: tuple[int, int, int]) -> NDArray[np.bool_]:
    """Intersection of the three silhouettes, each extruded along its viewing axis.

    At inference time this is the best 3-D occupancy known from the
    projections alone and is what the partition planners run on; during
    training the ground-truth mask is used instead. The hull contains every
    shape with these silhouettes, so it is a superset of the true shape.

    Parameters
    ----------
    projections : Projections
        ``views[a].image`` of shape ``grid_shape`` without axis ``a`` (rows and
        columns along the remaining axes, increasing).
    grid_shape : tuple of int
        ``(I, J, K)`` of the voxel grid.

    Returns
    -------
    ndarray of shape (I, J, K), bool
        ``hull[i, j, k] = x[j, k] & y[i, k] & z[i, j]``.
    """
    if not isinstance(projections, Projections):
        raise InputError(f"expected a Projections object (got {type(projections).__name__})")
    shape = tuple(int(s) for s in grid_shape)
    if len(shape) != 3 or min(shape) < 1:
        raise GeometryError(f"grid_shape must be three positive sizes (got {grid_shape})")
    for view in projections.views:
        a, b = in_plane_axes(view.axis)
        if view.image.shape != (shape[a], shape[b]):
            raise GeometryError(
                f"the view along {AXIS_NAMES[view.axis]} has shape {view.image.shape}, but the "
                f"grid {shape} needs {(shape[a], shape[b])}; derive projections on the same grid"
            )
    x, y, z = (view.image for view in projections.views)
    return x[np.newaxis, :, :] & y[:, np.newaxis, :] & z[:, :, np.newaxis]
