"""Several structures at once: one label per voxel, meshes that touch without overlapping.

Each structure is reconstructed on its own (:func:`slicerecon.reconstruct.reconstruct`
with ``keep_field=True``), giving a signed-distance field ``f_s`` (mm,
negative inside) on the shared sections grid. :func:`resolve` then gives every
sample to the structure it is *most inside*: the label of a sample is
``argmin_s f_s`` where that minimum is negative, and background elsewhere. No
sample belongs to two structures, and structures whose fields both reach a
sample still meet there, with no gap between them.

The mesh of structure ``s`` is the zero level of the competitive field

    g_s = max(f_s, (f_s - min_{t != s} f_t) / 2),

which is negative exactly where ``s`` wins a sample. Between two structures
``s`` and ``t`` that touch, ``g_t = -g_s`` on both sides of their interface,
so marching cubes puts the two meshes' interface vertices at the same places:
the meshes share the interface surface, without overlap or gap.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from typing import NamedTuple

import numpy as np
import trimesh
from numpy.typing import NDArray

from ..annotated_planes import drawn_box
from ..annotation import Annotation
from ..errors import OptionError
from ..sections import in_plane_axes
from .marching import march_field
from .sdf import SdfField

__all__ = ["JointResult", "fields_bytes", "keep_drawn_sections", "resolve"]

logger = logging.getLogger(__name__)

LEVEL_GAP = 1e-2
"""Smallest distance of a meshed sample from the zero level, in sample spacings.

Samples nearer the level are moved off it (a tie, exactly on it, to its owner's
side), so that no vertex lies within about 1 % of a spacing of a grid sample.
Marching cubes puts a vertex on each grid edge the level crosses; vertices on
the edges around one sample that nearly lies on the level are nearly one
point, and a mesh file that stores float32 coordinates (STL) merges them when
read back, pinching the surface: edges shared by 4 or 6 faces. The gap keeps
them at least a few hundred float32 steps apart for grids within a metre of
the origin. Both structures of an interface move their shared samples alike
(``g_t = -g_s`` stays true), so their meshes still share the interface."""


class JointResult(NamedTuple):
    """Structures resolved against each other.

    Attributes
    ----------
    labels : ndarray of shape grid_shape, int32
        At every voxel centre of the reference grid, the index (into the
        ``fields`` given to :func:`resolve`) of the structure that holds it,
        or -1 for background.
    meshes : list of trimesh.Trimesh or None
        One closed, outward mesh per structure (world mm), None for a
        structure that wins no sample.
    """

    labels: NDArray[np.int32]
    meshes: list[trimesh.Trimesh | None]


def _extent(field: SdfField) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """First sample (global sample coordinates) and shape of a padded field."""
    scale = np.ones(3, dtype=np.int64)
    scale[field.axis] = field.upsample
    start = np.asarray(field.lo, dtype=np.int64) * scale - 1
    return start, np.asarray(field.values.shape, dtype=np.int64)


def keep_drawn_sections(
    fields: Sequence[SdfField | None],
    values: Sequence[int],
    annotation: Annotation,
    nested: Mapping[int, int] | None = None,
) -> int:
    """Keep every drawn section in a partition: its pixels go to the structure drawn there.

    A plane that does not speak for a structure (structures drawn on planes of
    their own: a lesion on one extra slice, organs on every 4th) leaves that
    structure's field there interpolated from its own planes, and in the
    :func:`resolve` competition it could take the pixels another structure is
    drawn on. In a partition a drawn pixel is no other structure's, so over
    the slice such a plane stands for (half a voxel each side) and its drawn
    pixels, each structure it does not speak for is made outside: its field
    there is replaced by its absolute value. In place.

    Parameters
    ----------
    fields : sequence of SdfField or None
        One per structure, on the annotation's grid (as for :func:`resolve`).
    values : sequence of int
        The structures' values, in the order of ``fields``.
    annotation : Annotation
        The planes, and the structures each speaks for.
    nested : mapping of int to int, optional
        Inner structure → outer one (:func:`cut_nested`): the outer's drawn
        pixels on its own planes do not make the inner outside (they were
        drawn without it, not beside it).

    Returns
    -------
    int
        How many samples were made outside.
    """
    inverse = np.linalg.inv(annotation.affine)
    changed = 0
    for plane in annotation.planes:
        if plane.structures is None or not plane.masks:
            continue
        axis = annotation.axis_of(plane.pose)
        if axis is None or annotation.grid_shift(plane.pose, axis) is None:
            continue  # a plane off the grid's slices keeps the blend
        drawn = annotation.grid_mask(plane, None, axis)
        index = float((inverse[:3, :3] @ plane.pose.affine[:3, 3] + inverse[:3, 3])[axis])
        a, b = in_plane_axes(axis)
        for value, field in zip(values, fields, strict=True):
            if field is None or plane.annotates(value):
                continue
            outer = (nested or {}).get(value)
            here = drawn
            if outer is not None and outer in plane.masks:
                here = drawn & ~annotation.grid_mask(plane, outer, axis)
            to_grid = inverse @ field.affine  # sample index -> grid index (diagonal)
            along = to_grid[axis, axis] * np.arange(field.values.shape[axis]) + to_grid[axis, 3]
            layer = np.flatnonzero(np.abs(along - index) <= 0.5 + 1e-6)
            rows = np.rint(to_grid[a, a] * np.arange(field.values.shape[a]) + to_grid[a, 3]).astype(
                np.int64
            )
            cols = np.rint(to_grid[b, b] * np.arange(field.values.shape[b]) + to_grid[b, 3]).astype(
                np.int64
            )
            ok_rows = (rows >= 0) & (rows < here.shape[0])
            ok_cols = (cols >= 0) & (cols < here.shape[1])
            if not layer.size or not ok_rows.any() or not ok_cols.any():
                continue
            mask = np.zeros((rows.size, cols.size), dtype=bool)
            mask[np.ix_(ok_rows, ok_cols)] = here[np.ix_(rows[ok_rows], cols[ok_cols])]
            if not mask.any():
                continue
            view = np.moveaxis(field.values, (axis, a, b), (0, 1, 2))  # writes through
            for k in layer:
                section = view[k]
                flip = mask & (section < 0)
                changed += int(np.count_nonzero(flip))
                section[flip] = -section[flip]
    return changed


def cut_nested(
    fields: Sequence[SdfField | None], values: Sequence[int], nested: Mapping[int, int]
) -> None:
    """Cut each inner structure out of its outer one, in a partition. In place.

    A structure drawn inside another on planes of its own
    (:func:`slicerecon.annotated_planes.nested_apart`: a lesion inside its
    organ) lies deep inside the outer's interpolation, and :func:`resolve`
    would give every sample to the outer. The outer's field becomes the
    difference of the two, ``max(outer, -inner)`` (constructive solid
    geometry on signed distances), so the inner wins where it is inside.

    Parameters
    ----------
    fields : sequence of SdfField or None
        One per structure, on one reference grid (as for :func:`resolve`).
    values : sequence of int
        The structures' values, in the order of ``fields``.
    nested : mapping of int to int
        Inner structure → outer structure.
    """
    where = {v: i for i, v in enumerate(values)}
    for inner, outer in nested.items():
        cut, kept = fields[where[inner]], fields[where[outer]]
        if cut is None or kept is None:
            continue
        (start_cut, size_cut), (start_kept, size_kept) = _extent(cut), _extent(kept)
        lo = np.maximum(start_cut, start_kept)
        hi = np.minimum(start_cut + size_cut, start_kept + size_kept)
        if np.any(hi <= lo):
            continue
        in_cut = tuple(
            slice(int(a), int(b)) for a, b in zip(lo - start_cut, hi - start_cut, strict=True)
        )
        in_kept = tuple(
            slice(int(a), int(b)) for a, b in zip(lo - start_kept, hi - start_kept, strict=True)
        )
        np.maximum(kept.values[in_kept], -cut.values[in_cut], out=kept.values[in_kept])


def fields_bytes(annotation: Annotation, upsample: int, pad: int) -> int:
    """Bytes the fields of a partition's structures take until they are resolved together:
    each structure's float32 field on its drawn box (``pad`` voxels around it, refined
    ``upsample`` times along one axis), and the resolution's three arrays on the box of
    all (20 structures of a 512 x 512 x 200 map peaked at 1 GB; 80 at 2.7 GB, over a
    budget of 1.2 GiB that one structure's estimate had let through)."""
    total, lo_all, hi_all = 0, None, None
    for value in annotation.values:
        box = drawn_box(annotation, value, pad=pad)
        if box is None:
            continue
        lo, hi = box
        total += 4 * int(np.prod(hi - lo)) * upsample
        lo_all = lo if lo_all is None else np.minimum(lo_all, lo)
        hi_all = hi if hi_all is None else np.maximum(hi_all, hi)
    if lo_all is not None and hi_all is not None:
        total += 12 * int(np.prod(hi_all - lo_all)) * upsample
    return total


def resolve(fields: Sequence[SdfField | None], grid_shape: tuple[int, int, int]) -> JointResult:
    """Give every sample to the structure it is most inside; mesh each structure's share.

    Parameters
    ----------
    fields : sequence of SdfField or None
        One field per structure on the same reference grid (same section
        axis and ``upsample``); None for a structure with nothing to reconstruct.
    grid_shape : tuple of int
        The reference grid ``(I, J, K)``.

    Returns
    -------
    JointResult

    Raises
    ------
    OptionError
        If the fields do not share the section axis and sampling.
    """
    present = [f for f in fields if f is not None]
    if not present:
        return JointResult(np.full(grid_shape, -1, dtype=np.int32), [None] * len(fields))
    axis, upsample = present[0].axis, present[0].upsample
    if any(f.axis != axis or f.upsample != upsample for f in present):
        raise OptionError("the structures' fields must share the section axis and sampling")
    extents = [None if f is None else _extent(f) for f in fields]
    starts = np.array([e[0] for e in extents if e is not None])
    stops = np.array([e[0] + e[1] for e in extents if e is not None])
    origin = starts.min(axis=0)
    shape = tuple(int(v) for v in stops.max(axis=0) - origin)
    best = np.full(shape, np.inf, dtype=np.float32)
    second = np.full(shape, np.inf, dtype=np.float32)
    owner = np.full(shape, -1, dtype=np.int32)

    def region(i: int) -> tuple[slice, slice, slice]:
        start, size = extents[i]  # type: ignore[misc]
        a, b, c = (
            slice(int(s0 - o), int(s0 - o + n))
            for s0, o, n in zip(start, origin, size, strict=True)
        )
        return a, b, c

    for i, field in enumerate(fields):
        if field is None:
            continue
        where = region(i)
        values = field.values
        here_best, here_second = best[where], second[where]
        wins = values < here_best
        here_second[...] = np.where(wins, here_best, np.minimum(here_second, values))
        here_best[...] = np.where(wins, values, here_best)
        owner[where] = np.where(wins, i, owner[where])

    meshes: list[trimesh.Trimesh | None] = []
    for i, field in enumerate(fields):
        if field is None:
            meshes.append(None)
            continue
        where = region(i)
        mine = owner[where] == i
        if not np.any(mine & (best[where] < 0)):
            meshes.append(None)
            continue
        others = np.where(mine, second[where], best[where])
        competitive = np.maximum(field.values, 0.5 * (field.values - others)).astype(np.float32)
        _off_the_level(competitive, mine, field.affine)
        meshes.append(march_field(competitive, field.affine))
    labels = _voxel_labels(owner, best, origin, axis, upsample, grid_shape)
    logger.debug("resolved %d structures on a %s sample grid", len(present), shape)
    return JointResult(labels, meshes)


def _off_the_level(
    values: NDArray[np.float32], mine: NDArray[np.bool_], affine: NDArray[np.float64]
) -> None:
    """Move samples within :data:`LEVEL_GAP` spacings of the zero level off it, in place.

    A sample exactly on the level (a tie between two structures) goes to the
    side of its owner (``mine``: inside).
    """
    gap = np.float32(LEVEL_GAP * float(np.min(np.linalg.norm(affine[:3, :3], axis=0))))
    near = np.abs(values) < gap
    if not near.any():
        return
    inside = np.where(values[near] == 0, mine[near], values[near] < 0)
    values[near] = np.where(inside, -gap, gap)


def _voxel_labels(
    owner: NDArray[np.int32],
    best: NDArray[np.float32],
    origin: NDArray[np.int64],
    axis: int,
    upsample: int,
    grid_shape: tuple[int, int, int],
) -> NDArray[np.int32]:
    """The winners at the voxel centres of the reference grid (-1 where nothing is inside)."""
    labels = np.full(grid_shape, -1, dtype=np.int32)
    won = np.where(best < 0, owner, -1)
    index = []
    for ax, n in enumerate(grid_shape):
        step = upsample if ax == axis else 1
        # voxel v's centre is sample v * step + (step - 1) / 2 (odd step)
        centres = np.arange(n) * step + (step - 1) // 2 - origin[ax]
        index.append(centres)
    valid = [(c >= 0) & (c < won.shape[ax]) for ax, c in enumerate(index)]
    sub = won[np.ix_(index[0][valid[0]], index[1][valid[1]], index[2][valid[2]])]
    labels[np.ix_(valid[0], valid[1], valid[2])] = sub
    return labels
