"""Carving a reconstruction by the visual hull of its projections.

The orthographic projections are silhouettes of the true shape, so the shape
lies inside their visual hull (the voxels whose three projections are all
foreground). Interpolating between planes knows nothing of the projections:
a lofted or signed-distance surface bulges out of the hull wherever the shape
narrows, ends or turns between two planes. :func:`carve` intersects the
surface with the hull, an exact Boolean in manifold3d, so every part of the
reconstruction that the projections rule out is removed.

Only where the surface leaves the hull is anything computed: the
outside-the-hull voxels near those places are meshed by marching cubes and
subtracted, which keeps the cost proportional to what is carved.
"""

from __future__ import annotations

import logging

import numpy as np
import trimesh
from numpy.typing import ArrayLike, NDArray

from ..errors import EmptyMaskError, InputError
from ..rasterize import mesh_to_mask
from ..sections import Box, Volume
from .marching import volume_to_mesh
from .merge import check_closed, from_manifold, to_manifold

__all__ = ["HULL_LEVEL", "carve"]

logger = logging.getLogger(__name__)

HULL_LEVEL = 0.49
"""Marching-cubes level of the hull (0.5 is the voxel boundary): the carve
keeps 1 % of a voxel more than the hull, so it never cuts a contour that the
hull contains and the two surfaces never coincide."""

_TEST_OFFSET = 0.5
"""A surface sample counts as outside the hull when it stays outside after moving
this many voxels along any axis: sub-voxel excursions (voxelisation noise of
the hull around a smooth surface) are left alone."""

_OUTSIDE_HULL = (
    "the reconstruction lies entirely outside the projections' visual hull; "
    "check that the projections belong to these sections (or use --no-carve)"
)

_REACH = 2
"""Voxels by which the carved region is grown around the samples found outside."""


def carve(
    mesh: trimesh.Trimesh, hull: ArrayLike, affine: ArrayLike, *, seed: int = 0
) -> trimesh.Trimesh:
    """Intersect a closed mesh with a voxel visual hull.

    Only the parts of the surface that leave the hull are touched: the surface
    is sampled (about two points per voxel face of area); when samples lie
    outside the hull, the voxels of the solid outside the hull (rasterized
    voxel centres, plus the voxels of those samples) grown by ``_REACH``
    voxels and kept outside the hull are meshed and subtracted with an exact
    Boolean.
    A surface that stays inside the hull is returned unchanged, at the cost of
    the sampling only.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Closed, outward reconstruction in world mm.
    hull : ndarray of shape (I, J, K), bool
        The visual hull on the reference grid.
    affine : ndarray of shape (4, 4)
        Voxel index → world mm of the grid.
    seed : int, default 0
        Seed of the surface sampling.

    Returns
    -------
    trimesh.Trimesh
        ``mesh ∩ hull``: closed, manifold, outward, world mm.

    Raises
    ------
    InputError
        If ``hull`` is not a 3-D array.
    EmptyMaskError
        If the hull is empty or the intersection encloses no volume.
    """
    from scipy import ndimage

    hull_mask = np.asarray(hull)
    if hull_mask.ndim != 3:
        raise InputError(f"the hull must be a 3-D mask (got shape {hull_mask.shape})")
    hull_mask = hull_mask.astype(bool, copy=False)
    if not hull_mask.any():
        raise EmptyMaskError("the visual hull is empty: the projections hold no foreground")
    grid = Volume(hull_mask, np.asarray(affine, dtype=np.float64))
    outside, fraction_out = _outside_voxels(mesh, grid, seed=seed)
    if fraction_out == 1.0:
        raise EmptyMaskError(_OUTSIDE_HULL)
    if not outside.any():
        logger.debug("carve: the surface stays inside the hull")
        return mesh
    # Work in the bounding box of the outside samples, grown: there, everything
    # of the solid outside the hull (rasterized voxel centres, plus the voxels
    # of thin slivers that hold no centre but samples), grown and kept outside
    # the hull, is the region to cut away.
    found = Box.of_mask(outside)
    grow = 2 * _REACH + 1
    work = Box(
        tuple(max(lo - grow, 0) for lo in found.lo),  # type: ignore[arg-type]
        tuple(min(hi + grow, n) for hi, n in zip(found.hi, grid.shape, strict=True)),  # type: ignore[arg-type]
    )
    sub_affine = grid.affine.copy()
    sub_affine[:3, 3] = grid.index_to_world(np.asarray(work.lo, dtype=np.float64))
    outside_hull = ~hull_mask[work.slices]
    solid_out = mesh_to_mask(mesh, sub_affine, work.shape) & outside_hull
    seeds = outside[work.slices] | solid_out
    region = ndimage.binary_dilation(seeds, iterations=_REACH) & outside_hull
    cutter = volume_to_mesh(Volume(region, sub_affine).crop(pad=1), level=1.0 - HULL_LEVEL)
    solid = to_manifold(mesh) - to_manifold(cutter)
    if solid.is_empty() or solid.volume() <= 0:
        raise EmptyMaskError(_OUTSIDE_HULL)
    carved = from_manifold(solid)
    check_closed(carved, "carve")
    if logger.isEnabledFor(logging.DEBUG):
        logger.debug(
            "carved by the hull: %.6g -> %.6g mm^3", float(mesh.volume), float(carved.volume)
        )
    return carved


def _outside_voxels(
    mesh: trimesh.Trimesh, grid: Volume, *, seed: int
) -> tuple[NDArray[np.bool_], float]:
    """Voxels of ``grid`` holding surface samples outside its mask, and the fraction outside."""
    spacing = grid.spacing
    face_area = float(np.min(spacing)) ** 2
    count = int(np.clip(mesh.area / face_area * 2.0, 1_000, 2_000_000))
    points, _ = trimesh.sample.sample_surface(mesh, count, seed=seed)
    index = grid.world_to_index(points)
    shape = np.array(grid.shape)
    out = np.ones(len(index), dtype=bool)
    offsets = np.vstack([np.zeros(3), _TEST_OFFSET * np.vstack([np.eye(3), -np.eye(3)])])
    for offset in offsets:
        ijk = np.round(index + offset).astype(np.int64)
        valid = np.all((ijk >= 0) & (ijk < shape), axis=1)
        inside = np.zeros(len(ijk), dtype=bool)
        inside[valid] = grid.mask[tuple(ijk[valid].T)]
        out &= ~inside
    marked = np.zeros(grid.shape, dtype=bool)
    ijk = np.clip(np.round(index[out]).astype(np.int64), 0, shape - 1)
    marked[tuple(ijk.T)] = True
    return marked, float(out.mean())
