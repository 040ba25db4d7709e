"""Carving a reconstruction by the visual hull of its projections.

The orthographic projections are silhouettes of the true shape, so the shape
lies inside their visual hull (the voxels whose three projections are all
foreground). Interpolating between planes knows nothing of the projections:
a lofted or signed-distance surface bulges out of the hull wherever the shape
narrows, ends or turns between two planes. :func:`carve` intersects the
surface with the hull, an exact Boolean in manifold3d, so every part of the
reconstruction that the projections rule out is removed.

The hull is meshed by marching cubes at level ``HULL_LEVEL`` (slightly below
0.5, so its surface sits 1 % of a voxel outside the half-voxel boundary that
the section contours use): the carve then never cuts into a contour that the
hull itself contains, and the two surfaces never coincide exactly.
"""

from __future__ import annotations

import logging

import numpy as np
import trimesh
from numpy.typing import ArrayLike

from ..errors import EmptyMaskError, InputError
from ..sections import Volume
from .marching import volume_to_mesh
from .merge import check_closed, from_manifold, to_manifold

__all__ = ["HULL_LEVEL", "carve"]

logger = logging.getLogger(__name__)

HULL_LEVEL = 0.49
"""Marching-cubes level of the hull mask (0.5 is the voxel boundary)."""


def carve(mesh: trimesh.Trimesh, hull: ArrayLike, affine: ArrayLike) -> trimesh.Trimesh:
    """Intersect a closed mesh with a voxel visual hull.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Closed, outward reconstruction in world mm.
    hull : ndarray of shape (I, J, K), bool
        The visual hull on the reference grid.
    affine : ndarray of shape (4, 4)
        Voxel index → world mm of the grid.

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
    hull_mask = np.asarray(hull)
    if hull_mask.ndim != 3:
        raise InputError(f"the hull must be a 3-D mask (got shape {hull_mask.shape})")
    hull_mask = hull_mask.astype(bool, copy=False)
    if not hull_mask.any():
        raise EmptyMaskError("the visual hull is empty: the projections hold no foreground")
    grid = Volume(hull_mask, np.asarray(affine, dtype=np.float64))
    hull_mesh = volume_to_mesh(grid, level=HULL_LEVEL)
    solid = to_manifold(mesh) ^ to_manifold(hull_mesh)
    if solid.is_empty() or solid.volume() <= 0:
        raise EmptyMaskError(
            "the reconstruction lies entirely outside the projections' visual hull; "
            "check that the projections belong to these sections (or use --no-carve)"
        )
    carved = from_manifold(solid)
    check_closed(carved, "carve")
    logger.debug(
        "carved by the hull: %.6g -> %.6g mm^3", float(mesh.volume), float(carved.volume)
    )
    return carved
