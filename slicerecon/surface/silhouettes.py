"""A signed-distance field made consistent with the projections: the implicit carve and cover.

The projections are silhouettes of the true shape, so the shape lies inside
their visual hull and meets every silhouette ray. On a field sampled on the
reference grid (negative inside; :mod:`slicerecon.surface.sdf`):

* :func:`carve_field` raises every sample outside the hull to the hull level
  (the implicit carve: one marching cubes gives the intersection);
* :func:`cover_silhouettes` lowers, on every ray of the two views whose rays
  lie in the section planes that meets the silhouette but not the shape, the
  hull samples the field came nearest to (the cover: the shape fills the
  silhouettes).

``docs/method.md`` (section 7) gives the rules and the measurements behind
:data:`COVER_DEPTH`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ..errors import EmptyMaskError
from ..sections import CrossSections
from .extension import check_hull

__all__ = ["COVER_DEPTH", "HULL_LEVEL", "carve_field", "cover_silhouettes", "hull_samples"]


HULL_LEVEL = 0.49
"""Where the implicit carve puts the hull's surface between an inside and an
outside voxel centre: 0.49 of the way from the outside one, keeping 1 % of a
voxel more than the hull (the level of :data:`slicerecon.surface.carve.HULL_LEVEL`)."""


def hull_samples(
    sections: CrossSections,
    hull: NDArray[np.bool_],
    lo: tuple[int, ...],
    hi: tuple[int, ...],
    upsample: int,
) -> NDArray[np.bool_]:
    """The hull on the padded samples of the box ``[lo, hi)``; beyond the grid is outside.

    Returns a bool array of the padded field's shape.

    Along the section axis each voxel's value is repeated ``upsample`` times.
    """
    axis = sections.axis
    grid = sections.grid_shape
    padded_lo = [max(v - 1, 0) for v in lo]
    padded_hi = [min(v + 1, n) for v, n in zip(hi, grid, strict=True)]
    crop = hull[tuple(slice(a, b) for a, b in zip(padded_lo, padded_hi, strict=True))]
    inside = np.zeros([h - low + 2 for low, h in zip(lo, hi, strict=True)], dtype=bool)
    start = [a - (low - 1) for a, low in zip(padded_lo, lo, strict=True)]
    inside[tuple(slice(s0, s0 + n) for s0, n in zip(start, crop.shape, strict=True))] = crop
    if upsample > 1:
        core = np.repeat(
            np.take(inside, range(1, inside.shape[axis] - 1), axis=axis), upsample, axis=axis
        )
        edge = [np.take(inside, [0], axis=axis), np.take(inside, [-1], axis=axis)]
        inside = np.concatenate([edge[0], core, edge[1]], axis=axis)
    return inside


def carve_field(
    sections: CrossSections,
    union: NDArray[np.float32],
    lo: tuple[int, int, int],
    hi: tuple[int, int, int],
    upsample: int,
    carve: NDArray[np.bool_] | None,
    *,
    cover: bool = False,
) -> NDArray[np.float32]:
    """Carve a padded field by the hull (and, with ``cover``, cover the silhouettes), in place.

    Parameters
    ----------
    sections : CrossSections
        The sections the field was interpolated from (grid, spacing, axis).
    union : ndarray, float32
        The field (mm, negative inside) on the samples of the grid box
        ``[lo, hi)`` padded by one sample on every side, ``upsample`` samples
        per voxel along the section axis.
    lo, hi : tuple of int
        The box on the reference grid.
    upsample : int
        Samples per voxel along the section axis.
    carve : ndarray of shape ``sections.grid_shape``, bool, or None
        The visual hull; None leaves the field as it is.
    cover : bool
        Also cover the silhouettes (:func:`cover_silhouettes`).

    Returns
    -------
    ndarray
        ``union`` itself.

    Raises
    ------
    EmptyMaskError
        If no sample stays inside.
    """
    if carve is not None:
        check_hull(carve, sections.grid_shape)
        inside = hull_samples(sections, carve, lo, hi, upsample)
        level = np.float32(HULL_LEVEL * float(np.min(sections.spacing)))
        np.maximum(union, level, out=union, where=~inside)
        if cover:
            core = (slice(1, -1),) * 3  # the padding stays positive: the surface stays closed
            cover_silhouettes(
                union[core],
                inside[core],
                sections.axis,
                level,
                np.float32(COVER_DEPTH * float(np.min(sections.spacing))),
            )
        del inside
        if not union.min() < 0:
            raise EmptyMaskError(
                "the reconstruction lies entirely outside the projections' visual hull"
            )
    return union


COVER_DEPTH = 0.5
"""How far above its ray's deepest hull sample a sample may lie and still be
added by the silhouette cover, in units of the smallest voxel size (chosen on the
real-anatomy development half from 0.1, 0.25, 0.5 and 1: 0.5 and 1 tied,
``docs/method.md``, section 7)."""


def cover_silhouettes(
    union: NDArray[np.float32],
    inside: NDArray[np.bool_],
    axis: int,
    level: np.float32,
    depth: np.float32,
) -> None:
    """Make every silhouette ray that lies in a section plane meet the shape, in place.

    The carve removes what the silhouettes rule out; this adds what they
    require. A ray of a view whose viewing axis lies in the section planes
    (the two views other than the one along ``axis``) crosses one layer of
    samples; its silhouette pixel is set when the hull (``inside``) holds a
    sample on it. Where such a ray holds no inside sample, the interpolation
    missed the shape there (the shape reaches that far between two planes,
    which neither plane shows). The ray's samples inside the hull whose field
    is within ``depth`` of its lowest one (the places the interpolation found
    nearest to inside) are set to ``-level``, so the surface passes around
    them. Rays along ``axis`` are left alone: they cross every interpolated
    layer, so the missing voxel has no good place along them.

    Covered samples that join no part of the shape (a lone ray's sample, which
    marching cubes would turn into a speck of its own) are given back their
    field values: the cover only grows the shape, it never adds pieces.

    ``union`` and ``inside`` share their shape (samples in grid axis order).
    """
    shape_inside = union < 0
    added: list[tuple[tuple[NDArray[np.intp], ...], NDArray[np.float32]]] = []
    for ray_axis in (ax for ax in range(3) if ax != axis):
        missed = np.any(inside, axis=ray_axis) & ~np.any(shape_inside, axis=ray_axis)
        lines = np.nonzero(missed)  # each missed ray by its indices on the other two axes
        if lines[0].size == 0:
            continue
        values = np.moveaxis(union, ray_axis, -1)  # views: writes reach ``union``
        held = np.moveaxis(inside, ray_axis, -1)[lines]  # (rays, samples along the ray)
        rays = np.where(held, values[lines], np.inf)
        near = held & (rays <= rays.min(axis=1, keepdims=True) + depth)
        ray, along = np.nonzero(near)
        index: list[NDArray[np.intp]] = [along, along, along]
        others = [ax for ax in range(3) if ax != ray_axis]
        index[others[0]], index[others[1]] = lines[0][ray], lines[1][ray]
        where = tuple(index)
        added.append((where, union[where].copy()))
        union[where] = -level
        shape_inside[where] = True
    if added:
        _drop_lone_cover(union, shape_inside, added)


def _drop_lone_cover(
    union: NDArray[np.float32],
    shape_inside: NDArray[np.bool_],
    added: list[tuple[tuple[NDArray[np.intp], ...], NDArray[np.float32]]],
) -> None:
    """Give back their values to covered samples not 6-connected to the uncovered shape.

    Works on the covered samples only (a few per missed ray), never on the
    whole field: a covered sample is anchored when a 6-neighbour was inside
    before the cover, and anchoring spreads to covered neighbours until
    nothing changes.
    """
    shape = np.asarray(union.shape)
    flat = np.unique(np.concatenate([np.ravel_multi_index(w, union.shape) for w, _ in added]))
    coords = np.stack(np.unravel_index(flat, union.shape))  # (3, n)
    n = flat.size
    anchored = np.zeros(n, dtype=bool)
    rows, cols = [], []  # 6-neighbour pairs of covered samples (indices into flat)
    for ax in range(3):
        for step in (-1, 1):
            moved = coords.copy()
            moved[ax] += step
            ok = np.flatnonzero((moved[ax] >= 0) & (moved[ax] < shape[ax]))
            nb = np.ravel_multi_index(moved[:, ok], union.shape)
            at = np.minimum(np.searchsorted(flat, nb), n - 1)
            covered = flat[at] == nb
            rows.append(ok[covered])
            cols.append(at[covered])
            was_inside = shape_inside[np.unravel_index(nb[~covered], union.shape)]
            anchored[ok[~covered][was_inside]] = True
    # anchoring spreads through covered neighbours: a component is anchored when any
    # of its samples is
    graph = coo_matrix(
        (
            np.ones(sum(r.size for r in rows), dtype=np.int8),
            (np.concatenate(rows), np.concatenate(cols)),
        ),
        shape=(n, n),
    )
    _, component = connected_components(graph, directed=False)
    held = np.zeros(int(component.max()) + 1, dtype=bool)
    held[component[anchored]] = True
    anchored = held[component]
    lone = flat[~anchored]
    if lone.size == 0:
        return
    for where, before in reversed(added):  # the first cover's values last: the originals
        back = np.isin(np.ravel_multi_index(where, union.shape), lone)
        union[tuple(w[back] for w in where)] = before[back]
