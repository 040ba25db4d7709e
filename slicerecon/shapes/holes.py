"""Shapes with through holes: a torus, a genus-2 solid and a plate with holes."""

from __future__ import annotations

import math
from typing import Annotated

import numpy as np
from numpy.typing import NDArray

from ..errors import OptionError
from ..sections import Volume
from .draws import Draws
from .grid import Part, Spacing, compose, rasterize
from .params import Mm, MmXYZ, Seed, between, checked, reject_if
from .solids import frustum, rounded_box


@checked
def torus(major: Mm = 30.0, minor: Mm = 10.0, *, spacing: Spacing = 1.0, margin: int = 3) -> Volume:
    """A ring torus whose hole axis is z.

    Parameters
    ----------
    major : float, default 30
        Distance from the hole axis to the centre of the tube, mm.
    minor : float, default 10
        Tube radius, mm; must be smaller than ``major``.
    spacing, margin
        As for :func:`sphere`.

    Returns
    -------
    Volume
        Centred at world (0, 0, 0).
    """
    big = major
    small = minor
    if small >= big:
        raise OptionError(
            f"torus minor radius ({small} mm) must be smaller than its major radius ({big} mm)"
        )
    outer = big + small
    return rasterize(
        lambda x, y, z: (np.sqrt(x * x + y * y) - big) ** 2 + z * z <= small * small,
        (-outer, -outer, -small),
        (outer, outer, small),
        spacing=spacing,
        margin=margin,
        name="torus",
    )


@checked
def genus2(
    major: Mm = 25.0,
    minor: Mm = 8.0,
    *,
    seed: Seed = None,
    spacing: Spacing = 1.0,
    margin: int = 3,
) -> Volume:
    """Two ring tori fused side by side along x: one solid with two holes along z.

    The centres are ``2 * (major + f * minor)`` apart with ``f`` in
    ``[0.3, 0.8]`` (0.5 without a seed): the tubes merge between the rings
    while both holes stay open.

    Parameters
    ----------
    major : float, default 25
        Distance from each hole's axis to its tube's centre, mm.
    minor : float, default 8
        Tube radius, mm; below ``major / 2``.
    seed : int, optional
        Seed of the overlap ``f`` and of a tilt of the second ring (up to 10°).
    spacing, margin
        As for :func:`sphere`.

    Returns
    -------
    Volume
        Foreground centroid at world (0, 0, 0).
    """
    big = major
    small = minor
    reject_if(
        "genus2", small >= big / 2, f"minor ({small} mm) must be under half of major ({big} mm)"
    )
    draws = Draws(seed)
    d = big + draws.uniform(0.3, 0.8, 0.5) * small
    tilt = math.radians(draws.uniform(-10.0, 10.0, 0.0))
    cos_t, sin_t = math.cos(tilt), math.sin(tilt)

    def ring(cx: float, tilted: bool) -> Part:
        def inside(x: NDArray, y: NDArray, z: NDArray) -> NDArray[np.bool_]:
            px = x - cx
            if tilted:  # rotate about the y axis through the ring's centre
                px, pz = cos_t * px - sin_t * z, sin_t * px + cos_t * z
            else:
                pz = z
            return (np.sqrt(px * px + y * y) - big) ** 2 + pz * pz <= small * small

        reach = big + small
        return Part(
            inside, np.array([cx - reach, -reach, -reach]), np.array([cx + reach, reach, reach])
        )

    return compose([ring(-d, False), ring(d, True)], spacing=spacing, margin=margin, name="genus2")


@checked
def plate_with_holes(
    size: MmXYZ = (100.0, 50.0, 12.0),
    hole_radius: Mm = 9.0,
    *,
    holes: Annotated[int, between(1, 8)] = 2,
    seed: Seed = None,
    spacing: Spacing = 1.0,
    margin: int = 3,
) -> Volume:
    """A rounded plate pierced along z by ``holes`` round holes in a row along x (genus = holes).

    Parameters
    ----------
    size : sequence of 3 floats, default (100, 50, 12)
        Plate size along x, y, z, mm.
    hole_radius : float, default 9
        Radius of the holes, mm; a ring of at least ``hole_radius / 2`` is
        kept around each hole.
    holes : int, default 2
        Number of holes (1 to 8).
    seed : int, optional
        Seed of the holes' offsets from their evenly spaced positions and of
        their radii (80–100 %).
    spacing, margin
        As for :func:`sphere`.

    Returns
    -------
    Volume
        Foreground centroid at world (0, 0, 0).
    """
    sx, sy, sz = size
    rh = hole_radius
    n = holes
    draws = Draws(seed)
    pitch = sx / n
    reject_if(
        "plate_with_holes",
        3 * rh > pitch or 3 * rh > sy,
        f"hole_radius ({rh} mm) must be at most a third of the plate depth and of the "
        f"hole pitch ({pitch:.3g} mm)",
    )
    plate = rounded_box((-sx / 2, -sy / 2, -sz / 2), (sx / 2, sy / 2, sz / 2), min(sz, sy) / 4)
    minus = []
    for k in range(n):
        r = rh * draws.uniform(0.8, 1.0, 1.0)
        slack_x = pitch / 2 - 1.5 * rh
        slack_y = sy / 2 - 1.5 * rh
        cx = -sx / 2 + pitch * (k + 0.5) + draws.uniform(-1.0, 1.0, 0.0) * slack_x
        cy = draws.uniform(-1.0, 1.0, 0.0) * slack_y
        minus.append(frustum((cx, cy, -sz), (cx, cy, sz), r))
    return compose([plate], minus=minus, spacing=spacing, margin=margin, name="plate_with_holes")
