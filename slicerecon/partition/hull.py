"""The visual hull: the 3-D occupancy implied by three orthographic silhouettes."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from ..errors import GeometryError, InputError
from ..sections import AXIS_NAMES, Projections, in_plane_axes

__all__ = ["visual_hull"]


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
