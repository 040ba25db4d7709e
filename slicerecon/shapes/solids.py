"""Solids the family shapes are built of: boxes, capsules, cones, ellipsoids, prisms.

Each builder returns a :class:`~slicerecon.shapes.grid.Part` (an inside test
on world coordinates, mm, and a box that contains it) for
:func:`~slicerecon.shapes.grid.compose`; :func:`in_box` and
:func:`in_capsule` are the bare inside tests.
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .grid import Part


def vec(v: ArrayLike) -> NDArray[np.float64]:
    return np.asarray(v, dtype=np.float64)


def in_box(x: NDArray, y: NDArray, z: NDArray, lo: ArrayLike, hi: ArrayLike) -> NDArray[np.bool_]:
    """Points in the axis-aligned box ``[lo, hi)`` (mm)."""
    lo = np.asarray(lo, dtype=np.float64)
    hi = np.asarray(hi, dtype=np.float64)
    # Half-open, like a Python slice: a face on a row of voxel centres keeps the
    # row below it, so a box of size L on a grid of spacing s holds L / s voxels
    # whenever s divides L, wherever the faces fall.
    return (x >= lo[0]) & (x < hi[0]) & (y >= lo[1]) & (y < hi[1]) & (z >= lo[2]) & (z < hi[2])


def in_capsule(
    x: NDArray,
    y: NDArray,
    z: NDArray,
    start: Sequence[float],
    end: Sequence[float],
    radius: float,
) -> NDArray[np.bool_]:
    """Points closer than ``radius`` to the segment ``start``-``end`` (mm)."""
    p0 = np.asarray(start, dtype=np.float64)
    d = np.asarray(end, dtype=np.float64) - p0
    rel = (x - p0[0], y - p0[1], z - p0[2])
    t = (rel[0] * d[0] + rel[1] * d[1] + rel[2] * d[2]) / float(d @ d)
    t = np.clip(t, 0.0, 1.0)
    dist2 = sum((r - t * dc) ** 2 for r, dc in zip(rel, d, strict=True))
    return dist2 < radius * radius


def aligned_box(lo: Sequence[float], hi: Sequence[float]) -> Part:
    """The axis-aligned box ``[lo, hi)`` (:func:`in_box`) as a part."""
    return Part(functools.partial(in_box, lo=lo, hi=hi), vec(lo), vec(hi))


def capsule(
    start: ArrayLike, end: ArrayLike, radius: float, end_radius: float | None = None
) -> Part:
    """Points closer to segment ``start``-``end`` than a radius varying linearly along it."""
    p0, p1 = vec(start), vec(end)
    r0 = float(radius)
    r1 = r0 if end_radius is None else float(end_radius)
    d = p1 - p0
    dd = float(d @ d)

    def inside(x: NDArray, y: NDArray, z: NDArray) -> NDArray[np.bool_]:
        rel = (x - p0[0], y - p0[1], z - p0[2])
        if dd == 0.0:
            t: Any = 0.0
        else:
            t = np.clip((rel[0] * d[0] + rel[1] * d[1] + rel[2] * d[2]) / dd, 0.0, 1.0)
        dist2 = sum((r - t * dc) ** 2 for r, dc in zip(rel, d, strict=True))
        r = r0 + (r1 - r0) * t
        return dist2 < r * r

    reach = max(r0, r1)
    return Part(inside, np.minimum(p0, p1) - reach, np.maximum(p0, p1) + reach)


def frustum(
    start: ArrayLike, end: ArrayLike, radius: float, end_radius: float | None = None
) -> Part:
    """A solid truncated cone (cylinder when the radii agree) with flat caps."""
    p0, p1 = vec(start), vec(end)
    r0 = float(radius)
    r1 = r0 if end_radius is None else float(end_radius)
    d = p1 - p0
    dd = float(d @ d)

    def inside(x: NDArray, y: NDArray, z: NDArray) -> NDArray[np.bool_]:
        rel = (x - p0[0], y - p0[1], z - p0[2])
        t = (rel[0] * d[0] + rel[1] * d[1] + rel[2] * d[2]) / dd
        radial2 = sum((r - t * dc) ** 2 for r, dc in zip(rel, d, strict=True))
        r = r0 + (r1 - r0) * t
        return (t >= 0.0) & (t <= 1.0) & (radial2 <= r * r)

    reach = max(r0, r1)
    return Part(inside, np.minimum(p0, p1) - reach, np.maximum(p0, p1) + reach)


def oriented_ellipsoid(
    centre: ArrayLike, radii: ArrayLike, rotation: ArrayLike | None = None
) -> Part:
    """An ellipsoid; ``rotation`` (3x3) holds its semi-axis directions as columns."""
    c = vec(centre)
    r = vec(radii)
    rot = np.eye(3) if rotation is None else vec(rotation)

    def inside(x: NDArray, y: NDArray, z: NDArray) -> NDArray[np.bool_]:
        rel = (x - c[0], y - c[1], z - c[2])
        total: Any = 0.0
        for j in range(3):
            u = rel[0] * rot[0, j] + rel[1] * rot[1, j] + rel[2] * rot[2, j]
            total = total + (u / r[j]) ** 2
        return total <= 1.0

    half = np.sqrt(((rot * r) ** 2).sum(axis=1))
    return Part(inside, c - half, c + half)


def rounded_box(lo: ArrayLike, hi: ArrayLike, radius: float) -> Part:
    """An axis-aligned box ``[lo, hi]`` with edges and corners rounded by ``radius``."""
    lo_, hi_ = vec(lo), vec(hi)
    c = 0.5 * (lo_ + hi_)
    h = 0.5 * (hi_ - lo_)
    rad = min(float(radius), float(h.min()))
    core = h - rad

    def inside(x: NDArray, y: NDArray, z: NDArray) -> NDArray[np.bool_]:
        total: Any = 0.0
        for a, coord in enumerate((x, y, z)):
            total = total + np.maximum(np.abs(coord - c[a]) - core[a], 0.0) ** 2
        return total <= rad * rad

    return Part(inside, lo_, hi_)


def prism(polygon: ArrayLike, axis: int, low: float, high: float) -> Part:
    """A convex polygon in the plane of the two other axes, extruded from ``low`` to ``high``.

    ``polygon`` is (M, 2): coordinates along the two remaining axes in
    increasing order (for ``axis=1``: x and z).
    """
    poly = vec(polygon)
    area2 = float(
        np.sum(poly[:, 0] * np.roll(poly[:, 1], -1) - np.roll(poly[:, 0], -1) * poly[:, 1])
    )
    if area2 < 0:
        poly = poly[::-1]
    a_ax, b_ax = (ax for ax in range(3) if ax != axis)
    edges = np.roll(poly, -1, axis=0) - poly

    def inside(x: NDArray, y: NDArray, z: NDArray) -> NDArray[np.bool_]:
        coords = (x, y, z)
        a, b, w = coords[a_ax], coords[b_ax], coords[axis]
        out = (w >= low) & (w <= high)
        for (pa, pb), (ea, eb) in zip(poly, edges, strict=True):
            out = out & (ea * (b - pb) - eb * (a - pa) >= 0.0)
        return out

    lo = np.zeros(3)
    hi = np.zeros(3)
    lo[[a_ax, b_ax]] = poly.min(axis=0)
    hi[[a_ax, b_ax]] = poly.max(axis=0)
    lo[axis], hi[axis] = low, high
    return Part(inside, lo, hi)


def frame(direction: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Two unit vectors perpendicular to ``direction`` and to each other."""
    d = direction / np.linalg.norm(direction)
    helper = np.array([1.0, 0.0, 0.0]) if abs(d[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(d, helper)
    u /= np.linalg.norm(u)
    return u, np.cross(d, u)


def random_rotation(rng: np.random.Generator) -> NDArray[np.float64]:
    """A uniformly random 3x3 rotation matrix."""
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q
