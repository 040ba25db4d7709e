"""The voxel grid of a shape: layout, rasterization of inside tests, centring.

The grid is axis-aligned with voxel size ``spacing`` (mm, one value or one
per axis x, y, z). It covers the shape's bounding box plus ``margin`` empty
voxels on every side; voxel centres are laid out symmetrically about the
bounding box centre. :func:`compose` evaluates a union (minus a union) of
:class:`Part` solids on a loose box and crops to the foreground plus exactly
``margin`` voxels. Either way the affine's origin is chosen so that the
centroid of the foreground voxel centres sits at world ``(0, 0, 0)``.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import OptionError
from ..sections import Volume
from .params import check_margin, sizes_xyz

logger = logging.getLogger(__name__)

MAX_VOXELS = 1 << 27
"""Largest grid a shape function builds (134 M voxels); finer spacings raise OptionError."""

Spacing = float | Sequence[float]
Inside = Callable[[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]], NDArray]
"""Inside test on broadcastable world coordinate arrays x (I,1,1), y (1,J,1), z (1,1,K), mm."""


def grid_axes(
    lo: ArrayLike, hi: ArrayLike, *, spacing: Spacing, margin: int, name: str
) -> tuple[NDArray[np.float64], list[NDArray[np.float64]], NDArray[np.int64]]:
    """Voxel size, centre positions along x, y, z and counts of the grid around ``[lo, hi]``.

    Centres sit at ``±(k + 1/2) * spacing`` from the box centre: ``floor(half /
    s + 1/2)`` of them per side lie within the box, so every foreground centre
    is on the grid; ``margin`` more lie outside on every side.
    """
    sp = np.array(sizes_xyz(spacing, "spacing"))
    margin = check_margin(margin)
    lo_mm = np.asarray(lo, dtype=np.float64)
    hi_mm = np.asarray(hi, dtype=np.float64)
    centre = 0.5 * (lo_mm + hi_mm)
    half = 0.5 * (hi_mm - lo_mm)
    per_side = np.maximum(np.floor(half / sp + 0.5 + 1e-9).astype(np.int64), 1)
    counts = 2 * per_side + 2 * margin
    if float(np.prod(counts.astype(np.float64))) > MAX_VOXELS:
        raise OptionError(
            f"{name}: spacing {tuple(sp)} mm needs a grid of {tuple(counts)} voxels; "
            f"use a coarser spacing (at most {MAX_VOXELS} voxels)"
        )
    first = centre - 0.5 * (counts - 1) * sp  # world position of voxel 0, before centring
    axes = [first[a] + sp[a] * np.arange(counts[a]) for a in range(3)]
    return sp, axes, counts


class NoVoxelError(OptionError):
    """No voxel centre of the grid falls inside the shape (the grid is too coarse)."""


def centred_volume(
    mask: NDArray[np.bool_],
    axes: list[NDArray[np.float64]],
    sp: NDArray[np.float64],
    name: str,
) -> Volume:
    """Wrap ``mask`` (centres at ``axes``) in a Volume whose foreground centroid is at 0."""
    if not mask.any():
        raise NoVoxelError(
            f"{name}: no voxel centre falls inside the shape at spacing {tuple(sp)} mm; "
            "use a finer spacing or larger sizes"
        )
    ijk = np.nonzero(mask)
    centroid = np.array([axes[a][ijk[a]].mean() for a in range(3)])
    affine = np.diag([*sp, 1.0])
    affine[:3, 3] = np.array([axes[a][0] for a in range(3)]) - centroid
    volume = Volume(np.ascontiguousarray(mask), affine)
    logger.debug("%s: %r", name, volume)
    return volume


def rasterize(
    inside: Inside,
    lo: ArrayLike,
    hi: ArrayLike,
    *,
    spacing: Spacing,
    margin: int,
    name: str,
) -> Volume:
    """Evaluate ``inside`` at the voxel centres of a grid around the box ``[lo, hi]`` (mm).

    Voxel centres are symmetric about the box centre; the origin is then moved
    so that the foreground centroid is at world (0, 0, 0).
    """
    sp, axes, counts = grid_axes(lo, hi, spacing=spacing, margin=margin, name=name)
    x, y, z = np.ix_(*axes)
    mask = np.broadcast_to(inside(x, y, z), tuple(int(c) for c in counts))
    return centred_volume(mask, axes, sp, name)


class Part(NamedTuple):
    """A solid for :func:`compose`: an inside test and a box (mm) that contains it."""

    inside: Inside
    lo: NDArray[np.float64]
    hi: NDArray[np.float64]


def compose(
    parts: Sequence[Part],
    *,
    minus: Sequence[Part] = (),
    spacing: Spacing,
    margin: int,
    name: str,
) -> Volume:
    """Rasterize the union of ``parts`` minus the union of ``minus``.

    Each part is evaluated only on the grid block inside its box. The grid is
    laid out around the union of the parts' boxes (which may be loose) and
    then cropped to the foreground plus exactly ``margin`` voxels per side;
    the foreground centroid is moved to world (0, 0, 0).
    """
    lo = np.min([p.lo for p in parts], axis=0)
    hi = np.max([p.hi for p in parts], axis=0)
    sp, axes, counts = grid_axes(lo, hi, spacing=spacing, margin=margin, name=name)
    mask = np.zeros(tuple(int(c) for c in counts), dtype=bool)

    def block(part: Part) -> tuple[tuple[slice, ...], NDArray[np.bool_]] | None:
        slices = []
        for a in range(3):
            i0 = int(np.searchsorted(axes[a], part.lo[a], side="left"))
            i1 = int(np.searchsorted(axes[a], part.hi[a], side="right"))
            if i1 <= i0:
                return None
            slices.append(slice(i0, i1))
        x, y, z = np.ix_(*(axes[a][slices[a]] for a in range(3)))
        shape = tuple(s.stop - s.start for s in slices)
        return tuple(slices), np.broadcast_to(part.inside(x, y, z), shape)

    for part in parts:
        found = block(part)
        if found is not None:
            mask[found[0]] |= found[1]
    for part in minus:
        found = block(part)
        if found is not None:
            mask[found[0]] &= ~found[1]
    if mask.any():
        keep = []
        for a in range(3):
            occupied = np.flatnonzero(mask.any(axis=tuple(b for b in range(3) if b != a)))
            keep.append(slice(int(occupied[0]) - margin, int(occupied[-1]) + 1 + margin))
        mask = mask[tuple(keep)]
        axes = [axes[a][keep[a]] for a in range(3)]
    return centred_volume(mask, axes, sp, name)
