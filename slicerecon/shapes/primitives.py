"""Primitive shapes: sphere, ellipsoid and box, with closed-form volumes; a slanted rod."""

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


def slanted_rod(
    *,
    radius: float,
    slope: float,
    shape: tuple[int, int, int],
    start: float = 8.0,
) -> Volume:
    """A rod along z whose axis moves along x: a structure that drifts between planes.

    On a grid of 1 mm voxels (identity affine): voxel ``(i, j, k)`` is inside
    when ``(i - start - slope * k)**2 + (j - J / 2)**2 <= radius**2``; the first
    and last two z layers are left empty, so the rod has flat ends inside the
    grid. Not a registered family (it is the test and benchmark case of
    :mod:`slicerecon.surface.drift`).

    Parameters
    ----------
    radius : float
        Radius of the rod's cross-section, mm (= voxels).
    slope : float
        Shift of the axis along x per z layer, voxels.
    shape : tuple of 3 int
        Grid shape ``(I, J, K)``; it must hold the rod (it is clipped otherwise).
    start : float, optional
        x index of the axis on layer 0.

    Returns
    -------
    Volume
    """
    i, j, k = np.meshgrid(*(np.arange(n, dtype=np.float64) for n in shape), indexing="ij")
    inside = (i - start - slope * k) ** 2 + (j - shape[1] / 2.0) ** 2 <= radius**2
    inside[:, :, :2] = False
    inside[:, :, -2:] = False
    return Volume(inside, np.eye(4))
