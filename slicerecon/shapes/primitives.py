"""Primitive shapes: sphere, ellipsoid and box, with closed-form volumes."""

from __future__ import annotations

import numpy as np

from ..sections import Volume
from .grid import Spacing, rasterize
from .params import Mm, MmXYZ, checked
from .solids import in_box


@checked
def sphere(radius: Mm = 40.0, *, spacing: Spacing = 1.0, margin: int = 3) -> Volume:
    """A ball.

    Parameters
    ----------
    radius : float, default 40
        Radius, mm.
    spacing : float or sequence of 3 floats, default 1
        Voxel size, mm (one value, or one per axis x, y, z).
    margin : int, default 3
        Empty voxels around the shape on every side.

    Returns
    -------
    Volume
        Centred at world (0, 0, 0).
    """
    r = radius
    return rasterize(
        lambda x, y, z: x * x + y * y + z * z <= r * r,
        (-r, -r, -r),
        (r, r, r),
        spacing=spacing,
        margin=margin,
        name="sphere",
    )


@checked
def ellipsoid(
    radii: MmXYZ = (40.0, 30.0, 20.0), *, spacing: Spacing = 1.0, margin: int = 3
) -> Volume:
    """An axis-aligned ellipsoid.

    Parameters
    ----------
    radii : sequence of 3 floats, default (40, 30, 20)
        Semi-axes along x, y, z, mm.
    spacing, margin
        As for :func:`sphere`.

    Returns
    -------
    Volume
        Centred at world (0, 0, 0).
    """
    a, b, c = radii
    return rasterize(
        lambda x, y, z: (x / a) ** 2 + (y / b) ** 2 + (z / c) ** 2 <= 1.0,
        (-a, -b, -c),
        (a, b, c),
        spacing=spacing,
        margin=margin,
        name="ellipsoid",
    )


@checked
def box(size: MmXYZ = (60.0, 40.0, 30.0), *, spacing: Spacing = 1.0, margin: int = 3) -> Volume:
    """An axis-aligned cuboid.

    Parameters
    ----------
    size : sequence of 3 floats, default (60, 40, 30)
        Edge lengths along x, y, z, mm.
    spacing, margin
        As for :func:`sphere`.

    Returns
    -------
    Volume
        Centred at world (0, 0, 0).
    """
    h = np.array(size) / 2.0
    return rasterize(
        lambda x, y, z: in_box(x, y, z, -h, h),
        -h,
        h,
        spacing=spacing,
        margin=margin,
        name="box",
    )
