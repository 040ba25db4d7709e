"""Regions that drift between planes: shift-aware signed-distance interpolation.

Shape-based interpolation (:mod:`~slicerecon.surface.sdf`) blends two planes'
signed distances at each pixel. Where a region of one plane does not overlap
any region of the next one (a slanted rod whose discs move by more than their
diameter between planes), the blend is positive everywhere half-way: the two
discs each close off towards the other and the structure falls apart into
one piece per plane. ITK's morphological contour interpolation fails the
same way.

This module joins such regions. Per pair of consecutive planes, the regions
(connected components, 8-connected) of each plane that overlap nothing on
the other plane are paired when they are each other's nearest such region
and close enough that one structure can plausibly join them: the gap
between them (centroid distance less both equivalent radii) is at most the
distance between the planes, i.e. a surface inclined by at most 45 degrees
beyond touching. A pair's distances are blended in a moving frame, the
translation that carries one centroid onto the other, as registration-based
shape interpolation does (Goshtasby et al. 1992; Penney et al. 2004, who
register the slices before blending their distances)::

    d_t(x) = (1 - t) d_a(x - t s) + t d_b(x + (1 - t) s),   s = c_b - c_a,

and the region swept by the moving blend is added to the slab's field (the
union: the minimum of the distances). At ``t = 0`` and ``t = 1`` the moving
blend is the planes' own region, so the planes are still reproduced exactly;
regions that overlap their neighbours are left to the plain interpolation.
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Iterator

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

__all__ = [
    "consecutive_drifting_pairs",
    "drifting_pairs",
    "join_drifting_regions",
    "moving_blend",
    "swept_blends",
]

_EIGHT = np.ones((3, 3), dtype=bool)


class _Region:
    """One connected region of a plane mask: its pixels, centroid and equivalent radius."""

    def __init__(self, mask: NDArray[np.bool_], spacing: NDArray[np.float64]) -> None:
        self.mask = mask
        pix = np.argwhere(mask).astype(np.float64)
        self.centroid = pix.mean(axis=0)  # pixel indices
        self.radius = float(np.sqrt(pix.shape[0] * spacing.prod() / np.pi))  # mm


_Labels = tuple[NDArray[np.int32], int]


def _label(mask: NDArray[np.bool_]) -> _Labels:
    labels, n = ndimage.label(mask, structure=_EIGHT)
    return labels, int(n)


def _lonely_regions(
    labelled: _Labels, other: NDArray[np.bool_], spacing: NDArray[np.float64]
) -> list[_Region]:
    """The regions of a labelled mask that share no pixel with ``other``."""
    labels, n = labelled
    if n == 0:
        return []
    touching = np.unique(labels[other & (labels > 0)])
    lonely = np.setdiff1d(np.arange(1, n + 1), touching)
    return [_Region(labels == k, spacing) for k in lonely]


_Pair = tuple[NDArray[np.bool_], NDArray[np.bool_], NDArray[np.float64]]


def _pairs(
    lower: NDArray[np.bool_],
    upper: NDArray[np.bool_],
    labelled: tuple[Callable[[], _Labels], Callable[[], _Labels]],
    spacing: NDArray[np.float64],
    gap_mm: float,
) -> list[_Pair]:
    """:func:`drifting_pairs` with the planes' labellings computed on demand."""
    if not (lower.any() and upper.any()):
        return []
    overlap = np.count_nonzero(lower & upper)
    if overlap == min(np.count_nonzero(lower), np.count_nonzero(upper)):
        return []  # one plane inside the other: every region of it overlaps
    below = _lonely_regions(labelled[0](), upper, spacing)
    if not below:
        return []
    above = _lonely_regions(labelled[1](), lower, spacing)
    if not above:
        return []
    ca = np.stack([r.centroid for r in below])
    cb = np.stack([r.centroid for r in above])
    dist = np.linalg.norm((ca[:, None, :] - cb[None, :, :]) * spacing, axis=-1)
    pairs = []
    for i, region in enumerate(below):
        j = int(np.argmin(dist[i]))
        if int(np.argmin(dist[:, j])) != i:
            continue
        if dist[i, j] - region.radius - above[j].radius > gap_mm:
            continue
        pairs.append((region.mask, above[j].mask, cb[j] - ca[i]))
    return pairs


def drifting_pairs(
    lower: NDArray[np.bool_],
    upper: NDArray[np.bool_],
    spacing: NDArray[np.float64],
    gap_mm: float,
) -> list[_Pair]:
    """Pairs of non-overlapping regions of two consecutive planes that one structure joins.

    Parameters
    ----------
    lower, upper : ndarray of shape (M, N), bool
        The two planes' masks on one in-plane grid.
    spacing : ndarray of shape (2,)
        Pixel size along rows and columns, mm.
    gap_mm : float
        Distance between the two planes along the section axis, mm.

    Returns
    -------
    list of (ndarray, ndarray, ndarray of shape (2,))
        Per pair: the lower region's mask, the upper region's mask and the
        translation from the lower centroid to the upper one, pixels. Empty
        when every region overlaps the other plane (the usual case).
    """
    return _pairs(lower, upper, (lambda: _label(lower), lambda: _label(upper)), spacing, gap_mm)


def consecutive_drifting_pairs(
    masks: NDArray[np.bool_],
    w: NDArray[np.float64],
    spacing: NDArray[np.float64],
    axis_spacing: float,
) -> dict[int, list[_Pair]]:
    """:func:`drifting_pairs` of every two consecutive planes, each plane labelled once.

    Parameters
    ----------
    masks : ndarray of shape (P, M, N), bool
        The planes' masks, in order along the section axis.
    w : ndarray of shape (P,)
        Their positions along the section axis, index units.
    spacing : ndarray of shape (2,)
        In-plane pixel size, mm.
    axis_spacing : float
        Voxel size along the section axis, mm.

    Returns
    -------
    dict
        ``i`` → the pairs between planes ``i`` and ``i + 1``, for the ``i``
        that have any.
    """
    label = functools.cache(lambda i: _label(masks[i]))
    out = {}
    for i in range(len(masks) - 1):
        gap = float(w[i + 1] - w[i]) * axis_spacing
        pairs = _pairs(
            masks[i],
            masks[i + 1],
            (functools.partial(label, i), functools.partial(label, i + 1)),
            spacing,
            gap,
        )
        if pairs:
            out[i] = pairs
    return out


def moving_blend(
    d_a: NDArray[np.float32],
    d_b: NDArray[np.float32],
    shift_px: NDArray[np.float64],
    t: float,
) -> NDArray[np.float32]:
    """The signed distance of a drifting pair at fraction ``t`` of the way between its planes.

    Parameters
    ----------
    d_a, d_b : ndarray of shape (M, N), float32
        In-plane signed distances (mm, negative inside) of the lower and the
        upper region alone.
    shift_px : ndarray of shape (2,)
        Translation from the lower region's centroid to the upper one's, pixels.
    t : float
        Position between the lower (0) and the upper plane (1).

    Returns
    -------
    ndarray of shape (M, N), float32
        ``(1 - t) d_a(x - t s) + t d_b(x + (1 - t) s)``, read bilinearly
        (values beyond the grid repeat its border).
    """
    grid = np.indices(d_a.shape, dtype=np.float64)
    at_a = grid - (t * shift_px)[:, None, None]
    at_b = grid + ((1.0 - t) * shift_px)[:, None, None]
    lower = ndimage.map_coordinates(d_a, at_a, order=1, mode="nearest")
    upper = ndimage.map_coordinates(d_b, at_b, order=1, mode="nearest")
    return ((1.0 - t) * lower + t * upper).astype(np.float32)


def swept_blends(
    masks: NDArray[np.bool_],
    w: NDArray[np.float64],
    positions: NDArray[np.float64],
    spacing: NDArray[np.float64],
    axis_spacing: float,
    distance: Callable[[NDArray[np.bool_], NDArray[np.float64]], NDArray[np.float32]],
) -> Iterator[tuple[int, NDArray[np.float32]]]:
    """The moving blend of every drifting pair on every layer strictly between its planes.

    Parameters
    ----------
    masks : ndarray of shape (P, M, N), bool
        The planes' masks, in order along the section axis.
    w : ndarray of shape (P,)
        Their positions along the section axis, index units.
    positions : ndarray of shape (S,)
        Positions of the layers to blend onto along the section axis, index units
        (field samples, or grid rows).
    spacing : ndarray of shape (2,)
        In-plane pixel size, mm.
    axis_spacing : float
        Voxel size along the section axis, mm.
    distance : callable
        ``distance(mask, spacing)``: the in-plane signed distance of a mask
        (:func:`~slicerecon.surface.sdf.plane_signed_distance`).

    Yields
    ------
    k : int
        Index into ``positions`` of a layer between the pair's planes.
    blend : ndarray of shape (M, N), float32
        The pair's :func:`moving_blend` there (mm, negative inside).
    """
    for i, pairs in consecutive_drifting_pairs(masks, w, spacing, axis_spacing).items():
        between = np.flatnonzero((positions > w[i]) & (positions < w[i + 1]))
        for lower, upper, shift_px in pairs:
            d_a, d_b = distance(lower, spacing), distance(upper, spacing)
            for k in between:
                t = float((positions[k] - w[i]) / (w[i + 1] - w[i]))
                yield int(k), moving_blend(d_a, d_b, shift_px, t)


def join_drifting_regions(
    field: NDArray[np.float32],
    samples: NDArray[np.float64],
    w: NDArray[np.float64],
    used: NDArray[np.int64],
    masks: NDArray[np.bool_],
    spacing: NDArray[np.float64],
    axis_spacing: float,
    distance: Callable[[NDArray[np.bool_], NDArray[np.float64]], NDArray[np.float32]],
) -> None:
    """Add the moving blend of every drifting pair of regions to ``field``, in place.

    Parameters
    ----------
    field : ndarray of shape (S, M, N), float32
        The interpolated signed distance (mm, negative inside), axis first,
        on the in-plane grid of ``masks``.
    samples : ndarray of shape (S,)
        Position of each field layer along the section axis, index units.
    w : ndarray of shape (P,)
        Position of each plane along the section axis, index units.
    used : ndarray of int
        The planes interpolated into ``field``, in order.
    masks : ndarray of shape (P, M, N), bool
        The planes' masks on the field's in-plane grid.
    spacing, axis_spacing, distance
        As for :func:`swept_blends`.
    """
    order = np.asarray(used, dtype=np.int64)
    for k, blend in swept_blends(masks[order], w[order], samples, spacing, axis_spacing, distance):
        np.minimum(field[k], blend, out=field[k])
