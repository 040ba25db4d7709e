"""Shapes of several separate components: two spheres and blobs."""

from __future__ import annotations

import math
from typing import Annotated

import numpy as np
from numpy.typing import NDArray

from ..sections import Volume
from .draws import Draws
from .grid import Spacing, compose, rasterize
from .params import Mm, Seed, between, checked
from .solids import oriented_ellipsoid, random_rotation


@checked
def two_spheres(
    radius: Mm = 20.0, distance: Mm = 60.0, *, spacing: Spacing = 1.0, margin: int = 3
) -> Volume:
    """Two equal balls with centres ``distance`` apart along x (two components if apart).

    Parameters
    ----------
    radius : float, default 20
        Radius of each ball, mm.
    distance : float, default 60
        Distance between the centres, mm; below ``2 * radius`` the balls merge.
    spacing, margin
        As for :func:`sphere`.

    Returns
    -------
    Volume
        Centred at world (0, 0, 0).
    """
    r = radius
    d = distance / 2.0

    def inside(x: NDArray, y: NDArray, z: NDArray) -> NDArray[np.bool_]:
        yz = y * y + z * z
        return ((x - d) ** 2 + yz <= r * r) | ((x + d) ** 2 + yz <= r * r)

    return rasterize(
        inside,
        (-d - r, -r, -r),
        (d + r, r, r),
        spacing=spacing,
        margin=margin,
        name="two_spheres",
    )


@checked
def blobs(
    extent: Mm = 80.0,
    blob_radius: Mm = 14.0,
    *,
    count: Annotated[int, between(1, 32)] = 4,
    seed: Seed = None,
    spacing: Spacing = 1.0,
    margin: int = 3,
) -> Volume:
    """Several separate ellipsoidal blobs (one component each), like lesions or nodules.

    Each blob has semi-axes of 60–100 % of ``blob_radius`` and a random
    orientation; centres are drawn in a cube of side ``extent`` so that
    neighbouring blobs stay at least ``blob_radius / 2`` apart (when they do
    not fit, the cube grows).

    Parameters
    ----------
    extent : float, default 80
        Side of the cube the blobs are drawn in, mm.
    blob_radius : float, default 14
        Largest semi-axis of a blob, mm.
    count : int, default 4
        Number of blobs (1 to 32).
    seed : int, optional
        Seed of positions, semi-axes and orientations. None gives blobs of
        equal size on a ring.
    spacing, margin
        As for :func:`sphere`.

    Returns
    -------
    Volume
        Foreground centroid at world (0, 0, 0).
    """
    side = extent
    r = blob_radius
    n = count
    draws = Draws(seed)
    gap = r / 2
    separation = 2 * r + gap
    parts = []
    if not draws.seeded:
        ring = 0.0 if n == 1 else separation / (2 * math.sin(math.pi / n))
        for k in range(n):
            ang = 2 * math.pi * k / n
            centre = (ring * math.cos(ang), ring * math.sin(ang), 0.3 * r * (-1) ** k)
            parts.append(oriented_ellipsoid(centre, (r, 0.8 * r, 0.65 * r)))
        return compose(parts, spacing=spacing, margin=margin, name="blobs")
    rng = draws.rng
    half = max(side / 2 - r, 0.0)
    centres: list[NDArray[np.float64]] = []
    while len(centres) < n:
        for _ in range(200):
            candidate = rng.uniform(-half, half, size=3)
            if all(np.linalg.norm(candidate - c) >= separation for c in centres):
                centres.append(candidate)
                break
        else:
            half = half * 1.2 + gap  # does not fit: draw in a larger cube
    for middle in centres:
        radii = r * np.sort(rng.uniform(0.6, 1.0, size=3))[::-1]
        radii[0] = r
        parts.append(oriented_ellipsoid(middle, radii, random_rotation(rng)))
    return compose(parts, spacing=spacing, margin=margin, name="blobs")
