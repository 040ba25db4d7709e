"""Seeded procedural shapes as binary volumes, for training and tests.

Every shape is a function ``name(size parameters..., *, options..., spacing=1.0,
margin=3)`` returning a :class:`~slicerecon.sections.Volume`. The parameters
before the ``*`` are sizes in millimetres; keyword-only options choose a style
or a count, and the family shapes take a ``seed`` for their structure. Each
shape is defined implicitly (an inside test evaluated at voxel centres;
composite shapes are unions, and differences, of boxes, rounded boxes,
spheres, ellipsoids, capsules, cones and extruded polygons, a capsule being the
points closer than its radius to a segment).

Families
--------
:data:`FAMILIES` groups the shapes: primitives, furniture (chair, table, lamp,
sofa), objects (airplane, car, rifle, guitar), anatomy (brain, kidney, lung,
vessel_tree, y_branch), holes (torus, genus2, plate_with_holes) and
multi_component (two_spheres, blobs); :func:`family_of` names a shape's family.

Grid
----
The grid is axis-aligned with voxel size ``spacing`` (mm, one value or one per
axis x, y, z). It covers the shape's bounding box plus ``margin`` empty voxels
on every side; voxel centres are laid out symmetrically about the bounding
box centre (which thus falls on a voxel corner, so that, e.g., a 60 mm box at
1 mm spacing holds exactly 60 voxels along x). Composite family shapes are
evaluated on a loose box and cropped to the foreground plus exactly
``margin`` voxels. The affine's origin is then chosen so that the centroid of
the foreground voxel centres sits at world ``(0, 0, 0)``; for the symmetric
primitives this is their analytic centre.

Registry
--------
:data:`SHAPES` maps names to shape functions; :func:`make_shape` builds one by
name, optionally with seeded random proportions (every size parameter scaled
by an independent factor drawn from ``U(0.8, 1.2)``; same seed, same mask),
seeded structure (for the shapes that take a ``seed``) and a ``resolution``
(largest extent in voxels). :func:`analytic_volume` gives the exact volume of
the primitives.
"""

from __future__ import annotations

import functools
import inspect
import logging
import math
from collections.abc import Callable, Sequence
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import OptionError
from .sections import Volume

__all__ = [
    "FAMILIES",
    "SHAPES",
    "SCALE_RANGE",
    "airplane",
    "analytic_volume",
    "blobs",
    "box",
    "brain",
    "car",
    "chair",
    "ellipsoid",
    "family_of",
    "genus2",
    "guitar",
    "kidney",
    "lamp",
    "lung",
    "make_shape",
    "plate_with_holes",
    "rifle",
    "shape_names",
    "shape_params",
    "sofa",
    "sphere",
    "table",
    "torus",
    "two_spheres",
    "vessel_tree",
    "y_branch",
]

logger = logging.getLogger(__name__)

SCALE_RANGE: tuple[float, float] = (0.8, 1.2)
"""Range of the random factor applied to each size parameter by a seeded :func:`make_shape`."""

_MAX_VOXELS = 1 << 27
"""Largest grid a shape function builds (134 M voxels); finer spacings raise OptionError."""

Spacing = float | Sequence[float]
Inside = Callable[[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]], NDArray]
"""Inside test on broadcastable world coordinate arrays x (I,1,1), y (1,J,1), z (1,1,K), mm."""


# -- validation ---------------------------------------------------------------------
def _positive(value: object, name: str) -> float:
    try:
        out = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise OptionError(f"{name} must be a number of mm (got {value!r})") from None
    if not math.isfinite(out) or out <= 0.0:
        raise OptionError(f"{name} must be a positive finite size in mm (got {value!r})")
    return out


def _triple(value: object, name: str) -> tuple[float, float, float]:
    if isinstance(value, int | float | np.integer | np.floating):
        v = _positive(value, name)
        return v, v, v
    try:
        items = list(value)  # type: ignore[call-overload]
    except TypeError:
        raise OptionError(f"{name} must be one size or three sizes in mm (got {value!r})") from None
    if len(items) != 3:
        raise OptionError(f"{name} must hold 3 sizes (x, y, z) in mm (got {len(items)})")
    a, b, c = (_positive(v, f"{name}[{i}]") for i, v in enumerate(items))
    return a, b, c


def _check_margin(margin: object) -> int:
    if isinstance(margin, bool) or not isinstance(margin, int | np.integer) or margin < 0:
        raise OptionError(f"margin must be a whole number of voxels >= 0 (got {margin!r})")
    return int(margin)


# -- rasterization ------------------------------------------------------------------
def _grid(
    lo: ArrayLike, hi: ArrayLike, *, spacing: Spacing, margin: int, name: str
) -> tuple[NDArray[np.float64], list[NDArray[np.float64]], NDArray[np.int64]]:
    """Voxel size, centre positions along x, y, z and counts of the grid around ``[lo, hi]``.

    Centres sit at ``±(k + 1/2) * spacing`` from the box centre: ``floor(half /
    s + 1/2)`` of them per side lie within the box, so every foreground centre
    is on the grid; ``margin`` more lie outside on every side.
    """
    sp = np.array(_triple(spacing, "spacing"))
    margin = _check_margin(margin)
    lo_mm = np.asarray(lo, dtype=np.float64)
    hi_mm = np.asarray(hi, dtype=np.float64)
    centre = 0.5 * (lo_mm + hi_mm)
    half = 0.5 * (hi_mm - lo_mm)
    per_side = np.maximum(np.floor(half / sp + 0.5 + 1e-9).astype(np.int64), 1)
    counts = 2 * per_side + 2 * margin
    if float(np.prod(counts.astype(np.float64))) > _MAX_VOXELS:
        raise OptionError(
            f"{name}: spacing {tuple(sp)} mm needs a grid of {tuple(counts)} voxels; "
            f"use a coarser spacing (at most {_MAX_VOXELS} voxels)"
        )
    first = centre - 0.5 * (counts - 1) * sp  # world position of voxel 0, before centring
    axes = [first[a] + sp[a] * np.arange(counts[a]) for a in range(3)]
    return sp, axes, counts


class _NoVoxelError(OptionError):
    """No voxel centre of the grid falls inside the shape (the grid is too coarse)."""


def _centred_volume(
    mask: NDArray[np.bool_],
    axes: list[NDArray[np.float64]],
    sp: NDArray[np.float64],
    name: str,
) -> Volume:
    """Wrap ``mask`` (centres at ``axes``) in a Volume whose foreground centroid is at 0."""
    if not mask.any():
        raise _NoVoxelError(
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


def _rasterize(
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
    sp, axes, counts = _grid(lo, hi, spacing=spacing, margin=margin, name=name)
    x, y, z = np.ix_(*axes)
    mask = np.broadcast_to(inside(x, y, z), tuple(int(c) for c in counts))
    return _centred_volume(mask, axes, sp, name)


class _Part(NamedTuple):
    """A solid for :func:`_compose`: an inside test and a box (mm) that contains it."""

    inside: Inside
    lo: NDArray[np.float64]
    hi: NDArray[np.float64]


def _compose(
    parts: Sequence[_Part],
    *,
    minus: Sequence[_Part] = (),
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
    sp, axes, counts = _grid(lo, hi, spacing=spacing, margin=margin, name=name)
    mask = np.zeros(tuple(int(c) for c in counts), dtype=bool)

    def block(part: _Part) -> tuple[tuple[slice, ...], NDArray[np.bool_]] | None:
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
    return _centred_volume(mask, axes, sp, name)


def _in_box(
    x: NDArray, y: NDArray, z: NDArray, lo: ArrayLike, hi: ArrayLike
) -> NDArray[np.bool_]:
    lo = np.asarray(lo, dtype=np.float64)
    hi = np.asarray(hi, dtype=np.float64)
    # Half-open, like a Python slice: a face on a row of voxel centres keeps the
    # row below it, so a box of size L on a grid of spacing s holds L / s voxels
    # whenever s divides L, wherever the faces fall.
    return (x >= lo[0]) & (x < hi[0]) & (y >= lo[1]) & (y < hi[1]) & (z >= lo[2]) & (z < hi[2])


def _in_capsule(
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


# -- primitives ---------------------------------------------------------------------
def sphere(radius: float = 40.0, *, spacing: Spacing = 1.0, margin: int = 3) -> Volume:
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
    r = _positive(radius, "radius")
    return _rasterize(
        lambda x, y, z: x * x + y * y + z * z <= r * r,
        (-r, -r, -r), (r, r, r), spacing=spacing, margin=margin, name="sphere",
    )


def ellipsoid(
    radii: Sequence[float] = (40.0, 30.0, 20.0), *, spacing: Spacing = 1.0, margin: int = 3
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
    a, b, c = _triple(radii, "radii")
    return _rasterize(
        lambda x, y, z: (x / a) ** 2 + (y / b) ** 2 + (z / c) ** 2 <= 1.0,
        (-a, -b, -c), (a, b, c), spacing=spacing, margin=margin, name="ellipsoid",
    )


def torus(
    major: float = 30.0, minor: float = 10.0, *, spacing: Spacing = 1.0, margin: int = 3
) -> Volume:
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
    big = _positive(major, "major")
    small = _positive(minor, "minor")
    if small >= big:
        raise OptionError(
            f"torus minor radius ({small} mm) must be smaller than its major radius ({big} mm)"
        )
    outer = big + small
    return _rasterize(
        lambda x, y, z: (np.sqrt(x * x + y * y) - big) ** 2 + z * z <= small * small,
        (-outer, -outer, -small), (outer, outer, small),
        spacing=spacing, margin=margin, name="torus",
    )


def box(
    size: Sequence[float] = (60.0, 40.0, 30.0), *, spacing: Spacing = 1.0, margin: int = 3
) -> Volume:
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
    h = np.array(_triple(size, "size")) / 2.0
    return _rasterize(
        lambda x, y, z: _in_box(x, y, z, -h, h),
        -h, h, spacing=spacing, margin=margin, name="box",
    )


# -- composites ---------------------------------------------------------------------
def two_spheres(
    radius: float = 20.0, distance: float = 60.0, *, spacing: Spacing = 1.0, margin: int = 3
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
    r = _positive(radius, "radius")
    d = _positive(distance, "distance") / 2.0

    def inside(x: NDArray, y: NDArray, z: NDArray) -> NDArray[np.bool_]:
        yz = y * y + z * z
        return ((x - d) ** 2 + yz <= r * r) | ((x + d) ** 2 + yz <= r * r)

    return _rasterize(
        inside, (-d - r, -r, -r), (d + r, r, r), spacing=spacing, margin=margin,
        name="two_spheres",
    )


def y_branch(
    trunk_length: float = 50.0,
    branch_length: float = 50.0,
    spread: float = 30.0,
    radius: float = 8.0,
    *,
    spacing: Spacing = 1.0,
    margin: int = 3,
) -> Volume:
    """A tube along z that splits into two arms (a bifurcating vessel or airway).

    The trunk runs up the z axis from ``z = 0`` to ``z = trunk_length``; two arms
    run from the top of the trunk to ``(±spread, 0, trunk_length +
    branch_length)``. Each part is a capsule of radius ``radius``.

    Parameters
    ----------
    trunk_length : float, default 50
        Length of the trunk axis, mm.
    branch_length : float, default 50
        Height the arms rise above the trunk, mm.
    spread : float, default 30
        Distance of each arm's end from the trunk axis along x, mm; the arms'
        ends are apart when ``spread > radius``.
    radius : float, default 8
        Tube radius, mm.
    spacing, margin
        As for :func:`sphere`.

    Returns
    -------
    Volume
        Foreground centroid at world (0, 0, 0).
    """
    trunk = _positive(trunk_length, "trunk_length")
    rise = _positive(branch_length, "branch_length")
    side = _positive(spread, "spread")
    r = _positive(radius, "radius")
    fork = (0.0, 0.0, trunk)

    def inside(x: NDArray, y: NDArray, z: NDArray) -> NDArray[np.bool_]:
        return (
            _in_capsule(x, y, z, (0.0, 0.0, 0.0), fork, r)
            | _in_capsule(x, y, z, fork, (side, 0.0, trunk + rise), r)
            | _in_capsule(x, y, z, fork, (-side, 0.0, trunk + rise), r)
        )

    return _rasterize(
        inside, (-side - r, -r, -r), (side + r, r, trunk + rise + r),
        spacing=spacing, margin=margin, name="y_branch",
    )


def chair(
    seat_width: float = 40.0,
    seat_depth: float = 40.0,
    seat_thickness: float = 5.0,
    leg_height: float = 40.0,
    leg_width: float = 5.0,
    back_height: float = 45.0,
    back_thickness: float = 5.0,
    *,
    style: str | None = None,
    seed: int | None = None,
    spacing: Spacing = 1.0,
    margin: int = 3,
) -> Volume:
    """A chair of boxes: a seat slab, a back and four legs, optionally with arms.

    The legs (square, ``leg_width`` wide) stand at the seat's corners from
    ``z = 0`` to ``z = leg_height``; the seat lies on them; the back rises from
    the seat along its back edge (``+y``). Any z-plane below the seat cuts the
    four legs as four separate squares.

    Styles: ``"plain"`` (a solid back slab), ``"armchair"`` (plus an arm post
    and rest on each side, 35–50 % of the back's height: two loops) and
    ``"slat_back"`` (the back is two posts, a top rail and one to three
    vertical slats, with gaps at least ``leg_width`` wide).

    Parameters
    ----------
    seat_width, seat_depth, seat_thickness : float, default 40, 40, 5
        Seat size along x, y, z, mm.
    leg_height : float, default 40
        Height of the legs below the seat, mm.
    leg_width : float, default 5
        Side of the legs' square cross-section, mm; less than half the seat
        width and depth.
    back_height, back_thickness : float, default 45, 5
        Height of the back above the seat and its thickness along y, mm.
    style : {"plain", "armchair", "slat_back"}, optional
        Default: drawn from ``seed`` (``"plain"`` without a seed).
    seed : int, optional
        Seed of the structure: style, arm height, number of slats. None gives
        the canonical (plain) chair.
    spacing, margin
        As for :func:`sphere`.

    Returns
    -------
    Volume
        Foreground centroid at world (0, 0, 0).
    """
    draws = _Draws(seed)
    kind = _style(style, CHAIR_STYLES, draws, "chair")
    w = _positive(seat_width, "seat_width") / 2.0
    d = _positive(seat_depth, "seat_depth") / 2.0
    t = _positive(seat_thickness, "seat_thickness")
    legs_h = _positive(leg_height, "leg_height")
    leg = _positive(leg_width, "leg_width")
    back_h = _positive(back_height, "back_height")
    back_t = _positive(back_thickness, "back_thickness")
    if leg >= min(w, d):
        raise OptionError(
            f"leg_width ({leg} mm) must be less than half the seat width and depth "
            f"({2 * w} x {2 * d} mm), or the legs would touch"
        )
    if back_t > 2 * d:
        raise OptionError(f"back_thickness ({back_t} mm) exceeds the seat depth ({2 * d} mm)")
    seat_top = legs_h + t
    parts = [
        ((-w, -d, legs_h), (w, d, seat_top)),
        ((-w, d - back_t, seat_top), (w, d, seat_top + back_h)),
    ]
    for sx in (-1.0, 1.0):
        for sy in (-1.0, 1.0):
            cx, cy = sx * (w - leg / 2.0), sy * (d - leg / 2.0)
            parts.append(((cx - leg / 2, cy - leg / 2, 0.0), (cx + leg / 2, cy + leg / 2, legs_h)))
    if kind != "plain":
        top = seat_top + back_h
        if kind == "armchair":
            arm = seat_top + back_h * draws.uniform(0.35, 0.5, 0.4)
            for sx in (-1.0, 1.0):
                x0, x1 = sorted((sx * w, sx * (w - leg)))
                parts.append(((x0, -d, seat_top), (x1, -d + leg, arm)))  # post
                parts.append(((x0, -d, arm - leg), (x1, d - back_t, arm)))  # rest
        else:  # slat back: replace the slab by posts, a top rail and slats
            parts.pop(1)
            rail = max(leg, 0.2 * back_h)
            parts.append(((-w, d - back_t, top - rail), (w, d, top)))
            for x0, x1 in ((-w, -w + leg), (w - leg, w)):
                parts.append(((x0, d - back_t, seat_top), (x1, d, top)))
            inner = 2 * w - 2 * leg
            most = max(1, min(3, int((inner - leg) // (2 * leg))))  # gaps >= leg
            n = most if not draws.seeded else int(draws.rng.integers(1, most + 1))
            gap = (inner - n * leg) / (n + 1)
            for k in range(n):
                x0 = -w + leg + gap + k * (leg + gap)
                parts.append(((x0, d - back_t, seat_top), (x0 + leg, d, top - rail)))
        boxes = [_Part(functools.partial(_in_box, lo=lo, hi=hi), _vec(lo), _vec(hi))
                 for lo, hi in parts]
        return _compose(boxes, spacing=spacing, margin=margin, name="chair")

    def inside(x: NDArray, y: NDArray, z: NDArray) -> NDArray[np.bool_]:
        out = np.zeros(np.broadcast_shapes(x.shape, y.shape, z.shape), dtype=bool)
        for lo, hi in parts:
            out |= _in_box(x, y, z, lo, hi)
        return out

    return _rasterize(
        inside, (-w, -d, 0.0), (w, d, seat_top + back_h),
        spacing=spacing, margin=margin, name="chair",
    )


CHAIR_STYLES = ("plain", "armchair", "slat_back")


# -- building blocks of the procedural families -------------------------------------
_STRUCTURE_STREAM = 0x5EED5
"""Entropy mixed into a shape's seed for its structure (style, noise), apart from its sizes."""


def _check_seed(seed: object) -> int | None:
    if seed is None:
        return None
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise OptionError(f"seed must be a whole number >= 0 or None (got {seed!r})")
    return int(seed)


class _Draws:
    """Random structural choices of a shape: drawn from a seed, canonical without one.

    ``uniform`` and ``choice`` return their canonical value when the seed is
    None; ``rng`` (for noise patterns) is then a fixed generator, so the
    canonical shape is deterministic too.
    """

    def __init__(self, seed: object) -> None:
        checked = _check_seed(seed)
        self.seeded = checked is not None
        entropy = [_STRUCTURE_STREAM] if checked is None else [_STRUCTURE_STREAM, checked]
        self.rng = np.random.default_rng(entropy)

    def uniform(self, low: float, high: float, canonical: float) -> float:
        return float(self.rng.uniform(low, high)) if self.seeded else float(canonical)

    def choice(self, options: Sequence[str], canonical: str) -> str:
        return str(options[int(self.rng.integers(len(options)))]) if self.seeded else canonical


def _style(style: object, choices: tuple[str, ...], draws: _Draws, name: str) -> str:
    """Validate an explicit ``style`` or draw one (the first choice is canonical)."""
    if style is None:
        return draws.choice(choices, choices[0])
    if style not in choices:
        raise OptionError(f"{name} style must be one of {', '.join(choices)} (got {style!r})")
    return str(style)


def _count(value: object, name: str, low: int, high: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int | np.integer) or not (
        low <= value <= high
    ):
        raise OptionError(f"{name} must be a whole number from {low} to {high} (got {value!r})")
    return int(value)


def _vec(v: ArrayLike) -> NDArray[np.float64]:
    return np.asarray(v, dtype=np.float64)


def _capsule(start: ArrayLike, end: ArrayLike, radius: float, end_radius: float | None = None
             ) -> _Part:
    """Points closer to segment ``start``-``end`` than a radius varying linearly along it."""
    p0, p1 = _vec(start), _vec(end)
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
    return _Part(inside, np.minimum(p0, p1) - reach, np.maximum(p0, p1) + reach)


def _frustum(start: ArrayLike, end: ArrayLike, radius: float, end_radius: float | None = None
             ) -> _Part:
    """A solid truncated cone (cylinder when the radii agree) with flat caps."""
    p0, p1 = _vec(start), _vec(end)
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
    return _Part(inside, np.minimum(p0, p1) - reach, np.maximum(p0, p1) + reach)


def _ellipsoid(centre: ArrayLike, radii: ArrayLike, rotation: ArrayLike | None = None) -> _Part:
    """An ellipsoid; ``rotation`` (3x3) holds its semi-axis directions as columns."""
    c = _vec(centre)
    r = _vec(radii)
    rot = np.eye(3) if rotation is None else _vec(rotation)

    def inside(x: NDArray, y: NDArray, z: NDArray) -> NDArray[np.bool_]:
        rel = (x - c[0], y - c[1], z - c[2])
        total: Any = 0.0
        for j in range(3):
            u = rel[0] * rot[0, j] + rel[1] * rot[1, j] + rel[2] * rot[2, j]
            total = total + (u / r[j]) ** 2
        return total <= 1.0

    half = np.sqrt(((rot * r) ** 2).sum(axis=1))
    return _Part(inside, c - half, c + half)


def _rounded_box(lo: ArrayLike, hi: ArrayLike, radius: float) -> _Part:
    """An axis-aligned box ``[lo, hi]`` with edges and corners rounded by ``radius``."""
    lo_, hi_ = _vec(lo), _vec(hi)
    c = 0.5 * (lo_ + hi_)
    h = 0.5 * (hi_ - lo_)
    rad = min(float(radius), float(h.min()))
    core = h - rad

    def inside(x: NDArray, y: NDArray, z: NDArray) -> NDArray[np.bool_]:
        total: Any = 0.0
        for a, coord in enumerate((x, y, z)):
            total = total + np.maximum(np.abs(coord - c[a]) - core[a], 0.0) ** 2
        return total <= rad * rad

    return _Part(inside, lo_, hi_)


def _prism(polygon: ArrayLike, axis: int, low: float, high: float) -> _Part:
    """A convex polygon in the plane of the two other axes, extruded from ``low`` to ``high``.

    ``polygon`` is (M, 2): coordinates along the two remaining axes in
    increasing order (for ``axis=1``: x and z).
    """
    poly = _vec(polygon)
    area2 = float(np.sum(poly[:, 0] * np.roll(poly[:, 1], -1) - np.roll(poly[:, 0], -1)
                         * poly[:, 1]))
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
    return _Part(inside, lo, hi)


def _frame(direction: NDArray[np.float64]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Two unit vectors perpendicular to ``direction`` and to each other."""
    d = direction / np.linalg.norm(direction)
    helper = np.array([1.0, 0.0, 0.0]) if abs(d[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    u = np.cross(d, helper)
    u /= np.linalg.norm(u)
    return u, np.cross(d, u)


def _rotation(rng: np.random.Generator) -> NDArray[np.float64]:
    """A uniformly random 3x3 rotation matrix."""
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def _why(name: str, condition: bool, message: str) -> None:
    if condition:
        raise OptionError(f"{name}: {message}")


# -- furniture ----------------------------------------------------------------------
TABLE_STYLES = ("legs", "pedestal", "trestle")


def table(
    top_width: float = 90.0,
    top_depth: float = 60.0,
    top_thickness: float = 5.0,
    height: float = 70.0,
    leg_width: float = 6.0,
    *,
    style: str | None = None,
    seed: int | None = None,
    spacing: Spacing = 1.0,
    margin: int = 3,
) -> Volume:
    """A table: a top slab on four legs, a central pedestal or two trestle ends.

    Parameters
    ----------
    top_width, top_depth, top_thickness : float, default 90, 60, 5
        Size of the top along x, y, z, mm.
    height : float, default 70
        Height of the top surface above the floor (``z = 0``), mm.
    leg_width : float, default 6
        Side of the square legs (``"legs"``), radius scale of the column
        (``"pedestal"``) and thickness of the end boards (``"trestle"``), mm.
    style : {"legs", "pedestal", "trestle"}, optional
        Default: drawn from ``seed`` (``"legs"`` without a seed).
    seed : int, optional
        Seed of the structure: style, leg inset, base size. None gives the
        canonical table.
    spacing, margin
        As for :func:`sphere`.

    Returns
    -------
    Volume
        Foreground centroid at world (0, 0, 0).
    """
    w = _positive(top_width, "top_width") / 2.0
    d = _positive(top_depth, "top_depth") / 2.0
    t = _positive(top_thickness, "top_thickness")
    h = _positive(height, "height")
    leg = _positive(leg_width, "leg_width")
    draws = _Draws(seed)
    kind = _style(style, TABLE_STYLES, draws, "table")
    _why("table", t >= h, f"top_thickness ({t} mm) must be less than height ({h} mm)")
    _why("table", leg >= min(w, d),
         f"leg_width ({leg} mm) must be less than half the top width and depth")
    under = h - t
    parts = [_rounded_box((-w, -d, under), (w, d, h), min(t / 2.0, 2.0))]
    if kind == "legs":
        inset = draws.uniform(0.0, 0.12, 0.05)
        cx = w - leg / 2.0 - inset * (w - leg)
        cy = d - leg / 2.0 - inset * (d - leg)
        for sx in (-1.0, 1.0):
            for sy in (-1.0, 1.0):
                parts.append(_rounded_box(
                    (sx * cx - leg / 2, sy * cy - leg / 2, 0.0),
                    (sx * cx + leg / 2, sy * cy + leg / 2, under + t / 2), leg / 4,
                ))
    elif kind == "pedestal":
        column = max(leg, 0.12 * min(w, d))
        foot = draws.uniform(0.5, 0.8, 0.65) * min(w, d)
        parts.append(_frustum((0.0, 0.0, 0.0), (0.0, 0.0, t), foot, 0.9 * foot))
        parts.append(_frustum((0.0, 0.0, t / 2), (0.0, 0.0, under + t / 2), column))
    else:  # trestle: two end boards joined by a stretcher
        end_x = w * draws.uniform(0.6, 0.85, 0.75)
        board_d = d * draws.uniform(0.6, 0.9, 0.8)
        for sx in (-1.0, 1.0):
            parts.append(_rounded_box(
                (sx * end_x - leg / 2, -board_d, 0.0),
                (sx * end_x + leg / 2, board_d, under + t / 2), leg / 4,
            ))
        bar = 0.3 * under
        parts.append(_rounded_box((-end_x, -leg / 2, bar), (end_x, leg / 2, bar + leg), leg / 4))
    return _compose(parts, spacing=spacing, margin=margin, name="table")


LAMP_STYLES = ("floor", "desk")


def lamp(
    base_radius: float = 22.0,
    base_height: float = 6.0,
    pole_height: float = 70.0,
    pole_radius: float = 3.5,
    shade_radius: float = 20.0,
    shade_height: float = 22.0,
    *,
    style: str | None = None,
    seed: int | None = None,
    spacing: Spacing = 1.0,
    margin: int = 3,
) -> Volume:
    """A lamp: a round base, a pole and a solid conical shade.

    ``"floor"``: the shade sits on top of a straight pole. ``"desk"``: the
    pole bends into an arm, and the shade hangs tilted from the arm's end.

    Parameters
    ----------
    base_radius, base_height : float, default 22, 6
        Disc-shaped base on the floor (``z = 0``), mm.
    pole_height, pole_radius : float, default 70, 3.5
        Pole above the base, mm.
    shade_radius, shade_height : float, default 20, 22
        Wide radius and height of the shade (its narrow end is 0.35 to 0.6
        times as wide), mm.
    style : {"floor", "desk"}, optional
        Default: drawn from ``seed`` (``"floor"`` without a seed).
    seed : int, optional
        Seed of the structure: style, shade taper, arm angle.
    spacing, margin
        As for :func:`sphere`.

    Returns
    -------
    Volume
        Foreground centroid at world (0, 0, 0).
    """
    rb = _positive(base_radius, "base_radius")
    hb = _positive(base_height, "base_height")
    hp = _positive(pole_height, "pole_height")
    rp = _positive(pole_radius, "pole_radius")
    rs = _positive(shade_radius, "shade_radius")
    hs = _positive(shade_height, "shade_height")
    draws = _Draws(seed)
    kind = _style(style, LAMP_STYLES, draws, "lamp")
    _why("lamp", rp >= min(rb, rs) / 2, "pole_radius must be under half the base and shade radii")
    narrow = rs * draws.uniform(0.35, 0.6, 0.5)
    parts = [_frustum((0.0, 0.0, 0.0), (0.0, 0.0, hb), rb, 0.85 * rb)]
    if kind == "floor":
        top = hb + hp
        parts.append(_capsule((0.0, 0.0, hb / 2), (0.0, 0.0, top), rp))
        parts.append(_frustum((0.0, 0.0, top - 0.6 * hs), (0.0, 0.0, top + 0.4 * hs), rs, narrow))
    else:
        top = hb + 0.65 * hp
        angle = math.radians(draws.uniform(15.0, 50.0, 30.0))
        arm = 0.6 * hp
        end = np.array([arm * math.cos(angle), 0.0, top + arm * math.sin(angle)])
        parts.append(_capsule((0.0, 0.0, hb / 2), (0.0, 0.0, top), rp))
        parts.append(_capsule((0.0, 0.0, top), end, rp))
        tilt = math.radians(draws.uniform(10.0, 40.0, 25.0))
        axis = np.array([math.sin(tilt), 0.0, -math.cos(tilt)])
        # a ball joint fills the wedge between arm and shade (no pinched voxels there)
        parts.append(_capsule(end, end, narrow))
        parts.append(_frustum(end, end + hs * axis, narrow, rs))
    return _compose(parts, spacing=spacing, margin=margin, name="lamp")


SOFA_STYLES = ("two_arms", "one_arm", "no_arms", "chaise")


def sofa(
    width: float = 160.0,
    depth: float = 80.0,
    seat_height: float = 40.0,
    back_height: float = 40.0,
    arm_width: float = 16.0,
    arm_height: float = 20.0,
    *,
    style: str | None = None,
    seed: int | None = None,
    spacing: Spacing = 1.0,
    margin: int = 3,
) -> Volume:
    """A sofa of rounded blocks: seat base, back, armrests and an optional chaise.

    Parameters
    ----------
    width, depth : float, default 160, 80
        Footprint of the seat base along x, y, mm; the back stands along ``+y``.
    seat_height : float, default 40
        Height of the seat above the floor (``z = 0``), mm.
    back_height : float, default 40
        Height of the back above the seat, mm.
    arm_width, arm_height : float, default 16, 20
        Thickness of the armrests along x and their height above the seat, mm.
    style : {"two_arms", "one_arm", "no_arms", "chaise"}, optional
        ``"chaise"`` adds an L-shaped extension in front of one end (with two
        arms). Default: drawn from ``seed`` (``"two_arms"`` without a seed).
    seed : int, optional
        Seed of the structure: style, back thickness and tilt, chaise side.
    spacing, margin
        As for :func:`sphere`.

    Returns
    -------
    Volume
        Foreground centroid at world (0, 0, 0).
    """
    w = _positive(width, "width") / 2.0
    d = _positive(depth, "depth") / 2.0
    hs = _positive(seat_height, "seat_height")
    hb = _positive(back_height, "back_height")
    aw = _positive(arm_width, "arm_width")
    ah = _positive(arm_height, "arm_height")
    draws = _Draws(seed)
    kind = _style(style, SOFA_STYLES, draws, "sofa")
    _why("sofa", 2 * aw >= w, f"arm_width ({aw} mm) must be under a quarter of the width")
    rad = 0.1 * min(hs, d)
    back_t = d * draws.uniform(0.35, 0.6, 0.45)
    lean = back_t * draws.uniform(0.0, 0.5, 0.2)
    parts = [_rounded_box((-w, -d, 0.0), (w, d, hs), rad)]
    back = [(d - back_t, hs - rad), (d, hs - rad), (d + lean, hs + hb),
            (d - back_t + lean, hs + hb)]
    parts.append(_prism(back, 0, -w, w))
    side = 1.0 if draws.uniform(0.0, 1.0, 0.7) > 0.5 else -1.0
    arms = {"two_arms": (-1.0, 1.0), "chaise": (-1.0, 1.0), "one_arm": (side,), "no_arms": ()}
    for sx in arms[kind]:
        x0, x1 = sorted((sx * w, sx * (w - aw)))
        parts.append(_rounded_box((x0, -d, 0.0), (x1, d + lean / 2, hs + ah), rad))
    if kind == "chaise":
        length = 2 * d * draws.uniform(0.6, 1.0, 0.8)
        x0, x1 = sorted((side * w, side * (w - 0.45 * w)))
        parts.append(_rounded_box((x0, -d - length, 0.0), (x1, -d + rad * 2, hs), rad))
    return _compose(parts, spacing=spacing, margin=margin, name="sofa")


# -- vehicles and objects -----------------------------------------------------------
def airplane(
    length: float = 100.0,
    wingspan: float = 100.0,
    fuselage_radius: float = 6.0,
    wing_chord: float = 20.0,
    wing_thickness: float = 4.0,
    *,
    seed: int | None = None,
    spacing: Spacing = 1.0,
    margin: int = 3,
) -> Volume:
    """An airplane: a tapered fuselage, swept wings, a tailplane, a fin and engines.

    The nose points to ``+x``, the wings span y, the fin rises along ``+z``.

    Parameters
    ----------
    length : float, default 100
        Fuselage length along x, mm.
    wingspan : float, default 100
        Tip-to-tip span along y, mm.
    fuselage_radius : float, default 6
        Fuselage radius at its widest, mm.
    wing_chord, wing_thickness : float, default 20, 4
        Wing chord at the root and thickness, mm; the tail surfaces are as thick.
    seed : int, optional
        Seed of the structure: sweep, taper, wing position (low or mid),
        T-tail or conventional tail, 0, 2 or 4 engines.
    spacing, margin
        As for :func:`sphere`.

    Returns
    -------
    Volume
        Foreground centroid at world (0, 0, 0).
    """
    half = _positive(length, "length") / 2.0
    span = _positive(wingspan, "wingspan") / 2.0
    rf = _positive(fuselage_radius, "fuselage_radius")
    chord = _positive(wing_chord, "wing_chord")
    th = _positive(wing_thickness, "wing_thickness")
    draws = _Draws(seed)
    _why("airplane", rf >= half / 2, "fuselage_radius must be under a quarter of the length")
    _why("airplane", th >= 2 * rf, "wing_thickness must be under the fuselage diameter")
    sweep = math.tan(math.radians(draws.uniform(0.0, 35.0, 25.0)))
    taper = draws.uniform(0.3, 0.7, 0.4)
    wing_z = -0.5 * rf if draws.uniform(0.0, 1.0, 0.0) > 0.5 else 0.0
    le_root = half * draws.uniform(0.05, 0.3, 0.15) + chord / 2
    parts = [
        _capsule((-half + 0.5 * rf, 0.0, 0.3 * rf), (0.0, 0.0, 0.0), 0.5 * rf, rf),
        _capsule((0.0, 0.0, 0.0), (half - 0.8 * rf, 0.0, 0.0), rf, 0.8 * rf),
    ]

    def wing(root_le: float, root_chord: float, tip: float, z0: float) -> list[_Part]:
        out = []
        for sy in (-1.0, 1.0):
            tip_le = root_le - tip * sweep
            poly = [(root_le, 0.0), (root_le - root_chord, 0.0),
                    (tip_le - root_chord * taper, sy * tip), (tip_le, sy * tip)]
            out.append(_prism(poly, 2, z0 - th / 2, z0 + th / 2))
        return out

    parts += wing(le_root, chord, span, wing_z)
    tail_chord = 0.45 * chord
    tail_le = -half + 1.2 * tail_chord
    fin_h = 2.2 * rf + 0.15 * span
    fin = [(tail_le, 0.0), (-half + 0.3 * rf, 0.0), (-half + 0.3 * rf - 0.2 * fin_h, fin_h),
           (-half + 0.3 * rf - 0.2 * fin_h + 0.6 * tail_chord, fin_h)]
    parts.append(_prism(fin, 1, -th / 2, th / 2))
    t_tail = draws.uniform(0.0, 1.0, 0.0) > 0.6
    tail_z = fin_h - th / 2 if t_tail else 0.0
    tail_root = tail_le - (0.2 * fin_h if t_tail else 0.0)
    parts += wing(tail_root, tail_chord, 0.35 * span, tail_z)
    engines = int(draws.rng.integers(0, 3)) * 2 if draws.seeded else 2
    for k in range(engines // 2):
        ye = span * (0.35 + 0.3 * k)
        local_chord = chord * (1.0 - (1.0 - taper) * ye / span)
        mid = le_root - ye * sweep - local_chord / 2
        re = 0.45 * rf
        ze = wing_z - th / 2 - 0.4 * re
        for sy in (-1.0, 1.0):
            nacelle = ((mid - 0.12 * half, sy * ye, ze), (mid + 0.12 * half, sy * ye, ze))
            parts.append(_capsule(*nacelle, re))
    return _compose(parts, spacing=spacing, margin=margin, name="airplane")


CAR_STYLES = ("sedan", "hatchback", "pickup")


def car(
    length: float = 100.0,
    width: float = 45.0,
    body_height: float = 18.0,
    cabin_height: float = 15.0,
    wheel_radius: float = 10.0,
    wheel_width: float = 8.0,
    *,
    style: str | None = None,
    seed: int | None = None,
    spacing: Spacing = 1.0,
    margin: int = 3,
) -> Volume:
    """A car: a rounded body, a trapezoidal cabin and four wheels.

    Parameters
    ----------
    length, width : float, default 100, 45
        Body size along x (front at ``+x``) and y, mm.
    body_height, cabin_height : float, default 18, 15
        Height of the body block and of the cabin on top of it, mm.
    wheel_radius, wheel_width : float, default 10, 8
        Wheels (cylinders along y, standing on ``z = 0``), mm.
    style : {"sedan", "hatchback", "pickup"}, optional
        Cabin layout. Default: drawn from ``seed`` (``"sedan"`` without a seed).
    seed : int, optional
        Seed of the structure: style, wheelbase, cabin position and slopes.
    spacing, margin
        As for :func:`sphere`.

    Returns
    -------
    Volume
        Foreground centroid at world (0, 0, 0).
    """
    half = _positive(length, "length") / 2.0
    hw = _positive(width, "width") / 2.0
    hb = _positive(body_height, "body_height")
    hc = _positive(cabin_height, "cabin_height")
    rw = _positive(wheel_radius, "wheel_radius")
    ww = _positive(wheel_width, "wheel_width")
    draws = _Draws(seed)
    kind = _style(style, CAR_STYLES, draws, "car")
    _why("car", ww >= hw, "wheel_width must be under half the width")
    _why("car", rw >= half / 2, "wheel_radius must be under a quarter of the length")
    z0 = 0.6 * rw
    top = z0 + hb
    parts = [_rounded_box((-half, -hw, z0), (half, hw, top), 0.25 * min(hb, hw))]
    wheelbase = half * draws.uniform(0.55, 0.7, 0.62)
    for sx in (-1.0, 1.0):
        for sy in (-1.0, 1.0):
            y0, y1 = sorted((sy * hw, sy * (hw - ww)))
            parts.append(_frustum((sx * wheelbase, y0, rw), (sx * wheelbase, y1, rw), rw))
    front_slope = hc * draws.uniform(0.8, 1.6, 1.2)
    rear_slope = hc * draws.uniform(0.4, 1.2, 0.8)
    if kind == "sedan":
        x0, x1 = -0.5 * half, 0.35 * half
    elif kind == "hatchback":
        x0, x1 = -0.9 * half, 0.3 * half
        rear_slope *= 0.3
    else:
        x0, x1 = -0.05 * half, 0.4 * half
        rear_slope *= 0.2
    limit = 0.7 * (x1 - x0)
    if front_slope + rear_slope > limit:  # keep the cabin's roof a proper edge
        scale = limit / (front_slope + rear_slope)
        front_slope, rear_slope = front_slope * scale, rear_slope * scale
    shift = half * draws.uniform(-0.05, 0.05, 0.0)
    x0, x1 = x0 + shift, x1 + shift
    cabin = [(x0, top - 1.0), (x1, top - 1.0), (x1 - front_slope, top + hc),
             (x0 + rear_slope, top + hc)]
    parts.append(_prism(cabin, 1, -0.85 * hw, 0.85 * hw))
    return _compose(parts, spacing=spacing, margin=margin, name="car")


def rifle(
    length: float = 110.0,
    stock_height: float = 20.0,
    barrel_radius: float = 3.5,
    thickness: float = 10.0,
    *,
    seed: int | None = None,
    spacing: Spacing = 1.0,
    margin: int = 3,
) -> Volume:
    """A rifle: barrel, receiver, stock, pistol grip, magazine and an optional scope.

    The muzzle points to ``+x``; the rifle lies in the x–z plane, ``thickness``
    thick along y.

    Parameters
    ----------
    length : float, default 110
        Overall length along x, mm.
    stock_height : float, default 20
        Height of the stock at the butt, mm.
    barrel_radius : float, default 3.5
        Barrel radius, mm.
    thickness : float, default 10
        Thickness of receiver, stock and grip along y, mm.
    seed : int, optional
        Seed of the structure: barrel share of the length, grip angle,
        magazine length and curvature, scope or not.
    spacing, margin
        As for :func:`sphere`.

    Returns
    -------
    Volume
        Foreground centroid at world (0, 0, 0).
    """
    half = _positive(length, "length") / 2.0
    hs = _positive(stock_height, "stock_height")
    rb = _positive(barrel_radius, "barrel_radius")
    ht = _positive(thickness, "thickness") / 2.0
    draws = _Draws(seed)
    _why("rifle", rb >= 2 * ht, "barrel_radius must be under the thickness")
    rh = max(0.35 * hs, 1.2 * rb)  # receiver half height
    rec0 = -half + half * draws.uniform(0.7, 0.9, 0.8)
    rec1 = rec0 + half * draws.uniform(0.4, 0.6, 0.5)
    parts = [
        _capsule((rec1 - rb, 0.0, 0.3 * rh), (half - rb, 0.0, 0.3 * rh), rb),
        _rounded_box((rec0, -ht, -rh), (rec1, ht, rh), 0.3 * ht),
        _prism([(rec0 + 1.0, rh), (rec0 + 1.0, -0.5 * rh), (-half, rh - hs), (-half, rh)],
               1, -0.9 * ht, 0.9 * ht),
    ]
    grip_len = 1.1 * hs
    grip_angle = math.radians(draws.uniform(10.0, 30.0, 20.0))
    gx = rec0 + 0.2 * (rec1 - rec0)
    gw = 0.45 * hs
    dx, dz = grip_len * math.sin(grip_angle), grip_len * math.cos(grip_angle)
    parts.append(_prism([(gx, -rh + 1.0), (gx + gw, -rh + 1.0), (gx + gw - dx, -rh - dz),
                         (gx - dx, -rh - dz)], 1, -0.8 * ht, 0.8 * ht))
    mag_len = hs * draws.uniform(1.0, 2.2, 1.5)
    mag_lean = mag_len * draws.uniform(0.0, 0.5, 0.2)
    mx = rec0 + 0.6 * (rec1 - rec0)
    mw = 0.5 * hs
    parts.append(_prism([(mx, -rh + 1.0), (mx + mw, -rh + 1.0), (mx + mw + mag_lean, -rh - mag_len),
                         (mx + mag_lean, -rh - mag_len)], 1, -0.7 * ht, 0.7 * ht))
    if draws.uniform(0.0, 1.0, 0.0) > 0.5:
        sz = rh + 1.6 * rb + 0.3 * hs
        rs = 0.8 * rb + 0.1 * hs
        for fx in (0.2, 0.8):
            x = rec0 + fx * (rec1 - rec0)
            parts.append(_rounded_box((x - rb, -rb, rh - 1.0), (x + rb, rb, sz), 0.5))
        parts.append(_capsule((rec0 - 0.1 * half, 0.0, sz), (rec1 + 0.1 * half, 0.0, sz), rs))
    return _compose(parts, spacing=spacing, margin=margin, name="rifle")


GUITAR_STYLES = ("acoustic", "electric")


def guitar(
    body_length: float = 48.0,
    body_width: float = 38.0,
    body_thickness: float = 10.0,
    neck_length: float = 45.0,
    neck_width: float = 6.0,
    head_length: float = 16.0,
    *,
    style: str | None = None,
    seed: int | None = None,
    spacing: Spacing = 1.0,
    margin: int = 3,
) -> Volume:
    """A guitar: a body of two bouts, a neck and a headstock, lying flat (thickness along z).

    Parameters
    ----------
    body_length, body_width, body_thickness : float, default 48, 38, 10
        Body size along x (kept between 1.15 and 1.85 times the bouts' mean
        diameter, so that the bouts overlap) and y (at the lower bout), and
        its thickness, mm.
    neck_length, neck_width : float, default 45, 6
        Neck beyond the body along ``+x``, mm (the neck is ``0.7 *
        body_thickness`` thick, at least ``neck_width``).
    head_length : float, default 16
        Headstock length, mm (1.6 times the neck's width).
    style : {"acoustic", "electric"}, optional
        ``"electric"`` cuts two horns into the upper bout. Default: drawn from
        ``seed`` (``"acoustic"`` without a seed).
    seed : int, optional
        Seed of the structure: style, upper-bout size, headstock angle.
    spacing, margin
        As for :func:`sphere`.

    Returns
    -------
    Volume
        Foreground centroid at world (0, 0, 0).
    """
    bl = _positive(body_length, "body_length")
    rl = _positive(body_width, "body_width") / 2.0
    bt = _positive(body_thickness, "body_thickness") / 2.0
    nl = _positive(neck_length, "neck_length")
    nw = _positive(neck_width, "neck_width") / 2.0
    hl = _positive(head_length, "head_length")
    draws = _Draws(seed)
    kind = _style(style, GUITAR_STYLES, draws, "guitar")
    _why("guitar", 1.6 * nw >= rl, "neck_width must be well under the body width")
    ru = rl * draws.uniform(0.65, 0.85, 0.78)
    # centre distance of the bouts, kept so that they overlap into one body
    apart = float(np.clip(bl - rl - ru, 0.3 * (rl + ru), 0.85 * (rl + ru)))
    xl = -(rl + ru + apart) / 2 + rl
    xu = xl + apart
    parts = [
        _frustum((xl, 0.0, -bt), (xl, 0.0, bt), rl),
        _frustum((xu, 0.0, -bt), (xu, 0.0, bt), ru),
    ]
    neck_t = max(1.4 * bt, 2 * nw)
    end = xu + ru + nl
    parts.append(_rounded_box((xu, -nw, bt - neck_t), (end + 1.0, nw, bt), 0.3 * nw))
    head_t = 0.7 * neck_t
    drop = hl * math.tan(math.radians(draws.uniform(0.0, 15.0, 8.0)))
    head = [(end, bt - head_t), (end, bt), (end + hl, bt - drop), (end + hl, bt - drop - head_t)]
    parts.append(_prism(head, 1, -1.6 * nw, 1.6 * nw))
    minus = []
    if kind == "electric":
        for sy, size in ((1.0, 0.5), (-1.0, 0.4)):
            rc = size * ru
            minus.append(_frustum((xu + 0.6 * ru, sy * (ru + 0.2 * rc), -2 * bt),
                                  (xu + 0.6 * ru, sy * (ru + 0.2 * rc), 2 * bt), rc))
    return _compose(parts, minus=minus, spacing=spacing, margin=margin, name="guitar")


# -- anatomy-like -------------------------------------------------------------------
def brain(
    radii: Sequence[float] = (60.0, 75.0, 52.0),
    fold_depth: float = 5.0,
    fissure_depth: float = 12.0,
    *,
    seed: int | None = None,
    spacing: Spacing = 1.0,
    margin: int = 3,
) -> Volume:
    """A brain-like folded blob: an ellipsoid whose radius is modulated by gyri.

    The surface is ``|p / radii| = 1 + g(u)`` along each direction ``u`` from
    the centre: ``g`` is ``fold_depth * tanh(1.5 n)`` for a sum ``n`` of 24
    random plane waves on the unit sphere (3 to 5.5 cycles over a half
    circle, unit variance) — rounded gyri and sulci — minus a midline
    groove between the hemispheres on the upper half. The shape is
    star-shaped about its centre, so it is one solid without holes or
    cavities for any seed.

    Parameters
    ----------
    radii : sequence of 3 floats, default (60, 75, 52)
        Semi-axes along x (left-right), y (anterior-posterior), z, mm.
    fold_depth : float, default 5
        Amplitude of the gyri, mm (at most a fifth of the smallest radius).
    fissure_depth : float, default 12
        Depth of the interhemispheric groove at the top, mm (at most half the
        smallest radius).
    seed : int, optional
        Seed of the fold pattern. None gives a fixed canonical pattern.
    spacing, margin
        As for :func:`sphere`.

    Returns
    -------
    Volume
        Foreground centroid at world (0, 0, 0).
    """
    a, b, c = _triple(radii, "radii")
    fold = _positive(fold_depth, "fold_depth")
    groove = _positive(fissure_depth, "fissure_depth")
    small = min(a, b, c)
    _why("brain", fold > small / 5, f"fold_depth ({fold} mm) exceeds a fifth of the radii")
    _why("brain", groove > small / 2, f"fissure_depth ({groove} mm) exceeds half the radii")
    rng = _Draws(seed).rng
    n_waves = 24
    dirs = rng.normal(size=(n_waves, 3))
    dirs /= np.linalg.norm(dirs, axis=1, keepdims=True)
    freqs = rng.uniform(6.0, 11.0, size=n_waves) * math.pi / 2
    phases = rng.uniform(0.0, 2 * math.pi, size=n_waves)
    weights = rng.uniform(0.5, 1.0, size=n_waves)
    weights /= math.sqrt(float(np.sum(weights**2)) / 2.0)  # the wave sum has unit variance
    amp = fold / float(np.mean([a, b, c]))
    gap = groove / a
    dirs32, freqs32, phases32, weights32 = (
        v.astype(np.float32) for v in (dirs, freqs, phases, weights)
    )

    def inside(x: NDArray, y: NDArray, z: NDArray) -> NDArray[np.bool_]:
        shape = np.broadcast_shapes(x.shape, y.shape, z.shape)
        qx, qy, qz = (np.broadcast_to(q, shape).ravel() for q in (x / a, y / b, z / c))
        rho = np.sqrt(qx * qx + qy * qy + qz * qz)
        safe = np.maximum(rho, 1e-12)
        ux, uy, uz = qx / safe, qy / safe, qz / safe
        surface = 1.0 - gap * np.exp(-((ux / 0.06) ** 2)) * np.clip(uz + 0.2, 0.0, 1.0)
        # the folds move the surface by at most amp: decide the rest without the waves
        bound = amp
        out = rho <= surface - bound
        near = np.flatnonzero(~out & (rho <= surface + bound))
        un = [u[near].astype(np.float32) for u in (ux, uy, uz)]  # float32: twice as fast
        g = np.zeros(near.size, dtype=np.float32)
        for d, f, ph, wt in zip(dirs32, freqs32, phases32, weights32, strict=True):
            arg = un[0] * (f * d[0])
            arg += un[1] * (f * d[1])
            arg += un[2] * (f * d[2])
            arg += ph
            g += wt * np.cos(arg)
        out[near] = rho[near] <= surface[near] + amp * np.tanh(1.5 * g)
        return out.reshape(shape)

    reach = 1.0 + fold / small
    part = _Part(inside, -reach * np.array([a, b, c]), reach * np.array([a, b, c]))
    return _compose([part], spacing=spacing, margin=margin, name="brain")


def kidney(
    length: float = 110.0,
    width: float = 55.0,
    thickness: float = 40.0,
    *,
    seed: int | None = None,
    spacing: Spacing = 1.0,
    margin: int = 3,
) -> Volume:
    """A kidney (bean): a bent ellipsoid with a notch (hilum) in its concave side.

    The long axis is x; the ends bend towards ``+y``, where the hilum opens.

    Parameters
    ----------
    length, width, thickness : float, default 110, 55, 40
        Extent of the unbent ellipsoid along x, y, z, mm.
    seed : int, optional
        Seed of the structure: bend and hilum size.
    spacing, margin
        As for :func:`sphere`.

    Returns
    -------
    Volume
        Foreground centroid at world (0, 0, 0).
    """
    a = _positive(length, "length") / 2.0
    b = _positive(width, "width") / 2.0
    c = _positive(thickness, "thickness") / 2.0
    draws = _Draws(seed)
    bend = b * draws.uniform(0.2, 0.6, 0.4)
    hilum = draws.uniform(0.8, 1.2, 1.0)

    def inside(x: NDArray, y: NDArray, z: NDArray) -> NDArray[np.bool_]:
        yb = y - bend * (x / a) ** 2
        return (x / a) ** 2 + (yb / b) ** 2 + (z / c) ** 2 <= 1.0

    body = _Part(inside, np.array([-a, -b, -c]), np.array([a, b + bend, c]))
    notch = _ellipsoid((0.0, b, 0.0), (0.22 * a * hilum, 0.45 * b * hilum, 0.35 * c * hilum))
    return _compose([body], minus=[notch], spacing=spacing, margin=margin, name="kidney")


def lung(
    height: float = 120.0,
    width: float = 60.0,
    depth: float = 90.0,
    fissure_gap: float = 8.0,
    *,
    seed: int | None = None,
    spacing: Spacing = 1.0,
    margin: int = 3,
) -> Volume:
    """A two-lobed lung: a half dome on a domed diaphragm, split by an oblique fissure.

    The side wall rises straight for 15 % of the height and then curves
    (elliptically) to the apex; the base is hollowed upwards by the
    diaphragm (a paraboloid dome inside the footprint).

    The apex points to ``+z``; the medial (flat) side faces ``-x``. The
    fissure, a slab ``fissure_gap`` thick, separates an upper from a lower
    lobe everywhere except in a posterior strip of the medial side, where
    they stay joined (the hilum), so the lung is one solid without tunnels.
    A cardiac notch is cut into the medial side in front.

    Parameters
    ----------
    height : float, default 120
        Base-to-apex height along z, mm.
    width, depth : float, default 60, 90
        Extent of the base along x (lateral) and y (anterior-posterior), mm.
    fissure_gap : float, default 8
        Width of the fissure between the lobes, mm. Wide enough to stay open
        (at least two voxels) on a 32-voxel grid; a narrower gap sampled by
        coarse voxels leaves bridges across the fissure, which add tunnels.
    seed : int, optional
        Seed of the structure: fissure height and tilt, diaphragm dome,
        cardiac notch size.
    spacing, margin
        As for :func:`sphere`.

    Returns
    -------
    Volume
        Foreground centroid at world (0, 0, 0).
    """
    h = _positive(height, "height")
    a = _positive(width, "width") / 2.0
    b = _positive(depth, "depth") / 2.0
    gap = _positive(fissure_gap, "fissure_gap")
    draws = _Draws(seed)
    _why("lung", gap >= 0.2 * h, "fissure_gap must be under a fifth of the height")
    dome = h * draws.uniform(0.1, 0.25, 0.18)
    medial = -a * draws.uniform(0.45, 0.65, 0.55)

    wall = 0.15 * h  # the side wall rises straight this high before curving to the apex
    # the diaphragm's dome: an elliptic paraboloid hollowing the base, centred in the
    # medially cut footprint and inside it, so that the hollow is a closed bowl
    dome_x = 0.5 * (medial + a)
    dome_a = 0.4 * (a - medial)
    dome_b = 0.8 * b

    def body(x: NDArray, y: NDArray, z: NDArray) -> NDArray[np.bool_]:
        r2 = (x / a) ** 2 + (y / b) ** 2
        zz = np.clip((z - wall) / (h - wall), 0.0, None)
        hollow = dome * np.maximum(1.0 - ((x - dome_x) / dome_a) ** 2 - (y / dome_b) ** 2, 0.0)
        return (r2 + zz * zz <= 1.0) & (z >= hollow) & (x >= medial)

    parts = [_Part(body, np.array([medial, -b, 0.0]), np.array([a, b, h]))]
    tilt = math.radians(draws.uniform(20.0, 40.0, 30.0))
    normal = np.array([0.0, -math.sin(tilt), math.cos(tilt)])  # descends to the front (-y)
    # the fissure passes above the diaphragm's hollow (or it would open a window into it)
    above_hollow = dome + gap / (2 * math.cos(tilt)) + dome_b * math.tan(tilt) + 0.05 * h
    z_fissure = max(h * draws.uniform(0.4, 0.55, 0.45), above_hollow)
    bridge = medial + 0.35 * (a - medial)

    def fissure(x: NDArray, y: NDArray, z: NDArray) -> NDArray[np.bool_]:
        dist = y * normal[1] + (z - z_fissure) * normal[2]
        return (np.abs(dist) < gap / 2) & ((x > bridge) | (y < -0.1 * b))

    # the cardiac notch stays anterior (y < -b/4) and above the base, clear of the
    # hilum (x < bridge, y > -b/10) that joins the lobes, so it opens no tunnel
    notch_r = a * draws.uniform(0.35, 0.55, 0.45)
    notch_z = dome + 0.25 * h + 1.2 * notch_r
    minus = [
        _Part(fissure, np.array([medial, -b, 0.0]), np.array([a, b, h])),
        _ellipsoid((medial, -0.5 * b, notch_z), (notch_r, 0.25 * b, 1.2 * notch_r)),
    ]
    return _compose(parts, minus=minus, spacing=spacing, margin=margin, name="lung")


def vessel_tree(
    trunk_length: float = 45.0,
    trunk_radius: float = 7.0,
    *,
    generations: int = 3,
    seed: int | None = None,
    spacing: Spacing = 1.0,
    margin: int = 3,
) -> Volume:
    """A branching vessel tree of tapered capsules with shrinking radii.

    The trunk rises along ``+z`` from the origin. Each segment splits into
    two children, ``generations`` times: each child is 65–85 % as long and
    70–85 % as wide as its parent (about Murray's law), 25–45° off the
    parent's direction, the pair on opposite sides; each segment tapers by
    10 % along its length. No segment is thinner than 9 % of the trunk
    length, so that the tree stays connected on a grid of 32 voxels across.

    Parameters
    ----------
    trunk_length : float, default 45
        Length of the trunk, mm.
    trunk_radius : float, default 7
        Radius at the root, mm.
    generations : int, default 3
        Number of bifurcation levels (1 to 6); the tree has
        ``2 ** (generations + 1) - 1`` segments.
    seed : int, optional
        Seed of the branching angles, lengths and radii. None gives a
        symmetric tree whose branching planes turn by 90° per generation.
    spacing, margin
        As for :func:`sphere`.

    Returns
    -------
    Volume
        Foreground centroid at world (0, 0, 0).

    Notes
    -----
    Branches of different sub-trees are not checked for collisions; for
    unusual seeds two of them may touch, which adds a loop.
    """
    length = _positive(trunk_length, "trunk_length")
    radius = _positive(trunk_radius, "trunk_radius")
    levels = _count(generations, "generations", 1, 6)
    draws = _Draws(seed)
    _why("vessel_tree", radius >= length / 2, "trunk_radius must be under half trunk_length")
    parts: list[_Part] = []
    thinnest = min(0.09 * length, radius)

    def grow(start: NDArray, direction: NDArray, seg_len: float, r: float, level: int,
             roll: float) -> None:
        end = start + seg_len * direction
        r_end = max(0.9 * r, thinnest)
        parts.append(_capsule(start, end, r, r_end))
        if level == levels:
            return
        u, v = _frame(direction)
        base_azimuth = roll + draws.uniform(-0.6, 0.6, 0.0)
        for k in range(2):
            theta = math.radians(draws.uniform(25.0, 45.0, 35.0))
            phi = base_azimuth + k * math.pi + draws.uniform(-0.3, 0.3, 0.0)
            side = math.cos(phi) * u + math.sin(phi) * v
            child = math.cos(theta) * direction + math.sin(theta) * side
            r_child = max(r_end * draws.uniform(0.7, 0.85, 0.79), thinnest)
            grow(end, child / np.linalg.norm(child), seg_len * draws.uniform(0.65, 0.85, 0.75),
                 r_child, level + 1, roll + math.pi / 2)

    grow(np.zeros(3), np.array([0.0, 0.0, 1.0]), length, radius, 0, 0.0)
    return _compose(parts, spacing=spacing, margin=margin, name="vessel_tree")


# -- holes --------------------------------------------------------------------------
def genus2(
    major: float = 25.0,
    minor: float = 8.0,
    *,
    seed: int | None = None,
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
    big = _positive(major, "major")
    small = _positive(minor, "minor")
    _why("genus2", small >= big / 2, f"minor ({small} mm) must be under half of major ({big} mm)")
    draws = _Draws(seed)
    d = big + draws.uniform(0.3, 0.8, 0.5) * small
    tilt = math.radians(draws.uniform(-10.0, 10.0, 0.0))
    cos_t, sin_t = math.cos(tilt), math.sin(tilt)

    def ring(cx: float, tilted: bool) -> _Part:
        def inside(x: NDArray, y: NDArray, z: NDArray) -> NDArray[np.bool_]:
            px = x - cx
            if tilted:  # rotate about the y axis through the ring's centre
                px, pz = cos_t * px - sin_t * z, sin_t * px + cos_t * z
            else:
                pz = z
            return (np.sqrt(px * px + y * y) - big) ** 2 + pz * pz <= small * small

        reach = big + small
        return _Part(inside, np.array([cx - reach, -reach, -reach]),
                     np.array([cx + reach, reach, reach]))

    return _compose([ring(-d, False), ring(d, True)], spacing=spacing, margin=margin,
                    name="genus2")


def plate_with_holes(
    size: Sequence[float] = (100.0, 50.0, 12.0),
    hole_radius: float = 9.0,
    *,
    holes: int = 2,
    seed: int | None = None,
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
    sx, sy, sz = _triple(size, "size")
    rh = _positive(hole_radius, "hole_radius")
    n = _count(holes, "holes", 1, 8)
    draws = _Draws(seed)
    pitch = sx / n
    _why("plate_with_holes", 3 * rh > pitch or 3 * rh > sy,
         f"hole_radius ({rh} mm) must be at most a third of the plate depth and of the "
         f"hole pitch ({pitch:.3g} mm)")
    plate = _rounded_box((-sx / 2, -sy / 2, -sz / 2), (sx / 2, sy / 2, sz / 2), min(sz, sy) / 4)
    minus = []
    for k in range(n):
        r = rh * draws.uniform(0.8, 1.0, 1.0)
        slack_x = pitch / 2 - 1.5 * rh
        slack_y = sy / 2 - 1.5 * rh
        cx = -sx / 2 + pitch * (k + 0.5) + draws.uniform(-1.0, 1.0, 0.0) * slack_x
        cy = draws.uniform(-1.0, 1.0, 0.0) * slack_y
        minus.append(_frustum((cx, cy, -sz), (cx, cy, sz), r))
    return _compose([plate], minus=minus, spacing=spacing, margin=margin,
                    name="plate_with_holes")


# -- several components -------------------------------------------------------------
def blobs(
    extent: float = 80.0,
    blob_radius: float = 14.0,
    *,
    count: int = 4,
    seed: int | None = None,
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
    side = _positive(extent, "extent")
    r = _positive(blob_radius, "blob_radius")
    n = _count(count, "count", 1, 32)
    draws = _Draws(seed)
    gap = r / 2
    separation = 2 * r + gap
    parts = []
    if not draws.seeded:
        ring = 0.0 if n == 1 else separation / (2 * math.sin(math.pi / n))
        for k in range(n):
            ang = 2 * math.pi * k / n
            centre = (ring * math.cos(ang), ring * math.sin(ang), 0.3 * r * (-1) ** k)
            parts.append(_ellipsoid(centre, (r, 0.8 * r, 0.65 * r)))
        return _compose(parts, spacing=spacing, margin=margin, name="blobs")
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
        parts.append(_ellipsoid(middle, radii, _rotation(rng)))
    return _compose(parts, spacing=spacing, margin=margin, name="blobs")


# -- registry -----------------------------------------------------------------------
SHAPES: dict[str, Callable[..., Volume]] = {
    "sphere": sphere,
    "ellipsoid": ellipsoid,
    "torus": torus,
    "box": box,
    "two_spheres": two_spheres,
    "y_branch": y_branch,
    "chair": chair,
    "table": table,
    "lamp": lamp,
    "sofa": sofa,
    "airplane": airplane,
    "car": car,
    "rifle": rifle,
    "guitar": guitar,
    "brain": brain,
    "kidney": kidney,
    "lung": lung,
    "vessel_tree": vessel_tree,
    "genus2": genus2,
    "plate_with_holes": plate_with_holes,
    "blobs": blobs,
}
"""Shape functions by name. The parameters before ``*`` of each are sizes in mm; the
keyword-only ones besides ``spacing`` and ``margin`` are options (``seed``, ``style``,
counts)."""

FAMILIES: dict[str, tuple[str, ...]] = {
    "primitives": ("sphere", "ellipsoid", "box"),
    "furniture": ("chair", "table", "lamp", "sofa"),
    "objects": ("airplane", "car", "rifle", "guitar"),
    "anatomy": ("brain", "kidney", "lung", "vessel_tree", "y_branch"),
    "holes": ("torus", "genus2", "plate_with_holes"),
    "multi_component": ("two_spheres", "blobs"),
}
"""Shape families: family name → registered shape names. Every shape is in exactly one."""


def family_of(name: str) -> str:
    """The family (a key of :data:`FAMILIES`) that holds the registered shape ``name``.

    Raises
    ------
    OptionError
        If ``name`` is not a registered shape.
    """
    _lookup(name)
    for family, members in FAMILIES.items():
        if name in members:
            return family
    raise OptionError(f"shape {name!r} belongs to no family; add it to FAMILIES")


def shape_names() -> list[str]:
    """Names of the registered shapes, sorted."""
    return sorted(SHAPES)


def _lookup(name: str) -> Callable[..., Volume]:
    if name not in SHAPES:
        raise OptionError(f"unknown shape {name!r}; choose one of {', '.join(shape_names())}")
    return SHAPES[name]


def _size_parameters(func: Callable[..., Volume]) -> dict[str, Any]:
    """Defaults of a shape function's size parameters (those before ``*``)."""
    return {
        p.name: p.default
        for p in inspect.signature(func).parameters.values()
        if p.kind is inspect.Parameter.POSITIONAL_OR_KEYWORD
    }


def _options(func: Callable[..., Volume]) -> dict[str, Any]:
    """Defaults of a shape function's keyword-only options, besides spacing, margin, seed."""
    return {
        p.name: p.default
        for p in inspect.signature(func).parameters.values()
        if p.kind is inspect.Parameter.KEYWORD_ONLY and p.name not in ("spacing", "margin", "seed")
    }


def _takes_seed(func: Callable[..., Volume]) -> bool:
    return "seed" in inspect.signature(func).parameters


def shape_params(name: str, *, seed: int | None = None, **params: Any) -> dict[str, Any]:
    """The size parameters :func:`make_shape` uses for ``name``.

    Parameters
    ----------
    name : str
        A registered shape (see :func:`shape_names`).
    seed : int, optional
        With a seed, every size parameter (each element of a tuple separately)
        is multiplied by an independent factor drawn from ``U(0.8, 1.2)``
        (:data:`SCALE_RANGE`) by ``numpy.random.default_rng(seed)``. Without one,
        the parameters are returned as given.
    **params
        Sizes overriding the shape's canonical defaults (before scaling).

    Returns
    -------
    dict
        Parameter name → size in mm (a float, or a tuple of floats).

    Raises
    ------
    OptionError
        If ``name`` is unknown or a parameter is not one of the shape's sizes.
    """
    func = _lookup(name)
    defaults = _size_parameters(func)
    unknown = sorted(set(params) - set(defaults))
    if unknown:
        options = ", ".join(["spacing", "margin", *_options(func)])
        raise OptionError(
            f"shape {name!r} has no parameter {', '.join(unknown)}; "
            f"its sizes are {', '.join(defaults)} (plus {options})"
        )
    resolved = {**defaults, **params}
    if seed is None:
        return resolved
    _check_seed(seed)
    rng = np.random.default_rng(seed)
    low, high = SCALE_RANGE
    scaled: dict[str, Any] = {}
    for key, value in resolved.items():
        if isinstance(value, int | float | np.integer | np.floating):
            scaled[key] = float(value) * float(rng.uniform(low, high))
        else:
            values = [float(v) for v in value]
            factors = rng.uniform(low, high, size=len(values))
            scaled[key] = tuple(float(v * f) for v, f in zip(values, factors, strict=True))
    return scaled


def make_shape(
    name: str,
    *,
    seed: int | None = None,
    spacing: Spacing = 1.0,
    margin: int = 3,
    resolution: int | None = None,
    **params: Any,
) -> Volume:
    """Build a registered shape by name, with canonical or seeded random proportions.

    Parameters
    ----------
    name : str
        A registered shape (see :func:`shape_names`).
    seed : int, optional
        Seed of the random proportions (see :func:`shape_params`) and, for
        shapes that take a ``seed`` themselves, of their structure (style,
        branching, noise); the same seed gives the same mask. None gives the
        canonical shape.
    spacing : float or sequence of 3 floats, default 1
        Voxel size, mm. With ``resolution``, only the ratios between the
        three values count (the voxel shape).
    margin : int, default 3
        Empty voxels around the shape on every side.
    resolution : int, optional
        Scale the voxel size (keeping the shape in mm) so that the shape's
        largest extent spans at most, and about, ``resolution`` voxels (within
        about 3 %, 8 to 2048). The grid is then about ``resolution + 2 *
        margin`` voxels along that axis. Thin parts (legs, poles, wings,
        vessel ends) need ``resolution`` of 32 or more to stay connected.
    **params
        Sizes overriding the canonical defaults (before random scaling), and
        keyword options of the shape (``style``, ``count``, ``holes``,
        ``generations``).

    Returns
    -------
    Volume

    Raises
    ------
    OptionError
        If the name or a parameter is unknown, or a size, option, seed or
        resolution is invalid.
    """
    func = _lookup(name)
    option_names = set(_options(func))
    options = {k: v for k, v in params.items() if k in option_names}
    sizes = shape_params(name, seed=seed, **{k: v for k, v in params.items()
                                            if k not in option_names})
    if _takes_seed(func):
        options["seed"] = seed
    if resolution is None:
        return func(**sizes, **options, spacing=spacing, margin=margin)
    if isinstance(resolution, bool) or not isinstance(resolution, int | np.integer) or not (
        8 <= resolution <= 2048
    ):
        raise OptionError(f"resolution must be a whole number of voxels, 8 to 2048 "
                          f"(got {resolution!r})")
    ratio = np.array(_triple(spacing, "spacing"))
    ratio = ratio / ratio.max()

    def extent_mm(step: float) -> NDArray[np.float64]:
        for _ in range(4):
            try:
                probe = func(**sizes, **options, spacing=ratio * step, margin=0)
            except _NoVoxelError:
                step /= 2.0  # every part fell between the probe's voxel centres
                continue
            lo, hi = probe.bounding_box_vox()
            return (hi - lo) * probe.spacing
        raise OptionError(f"{name}: the shape is too small to measure; pass larger sizes")

    # two coarse probes: the second has about 64 voxels across the largest extent
    largest = max(float(np.max(v)) for v in sizes.values())
    extent = extent_mm(largest / 16.0)
    extent = extent_mm(float(np.max(extent / ratio)) / 64.0)
    step = float(np.max(extent / ratio)) / int(resolution)
    for _ in range(8):
        try:
            volume = func(**sizes, **options, spacing=ratio * step, margin=margin)
        except _NoVoxelError:
            raise OptionError(
                f"{name} vanishes at resolution {resolution}: its parts are thinner than a "
                "voxel; use a larger resolution"
            ) from None
        lo, hi = volume.bounding_box_vox()
        if int(np.max(hi - lo)) <= int(resolution):
            return volume
        step *= 1.02
    raise OptionError(  # pragma: no cover - the probe makes this unreachable in practice
        f"could not fit shape {name!r} into {resolution} voxels; report this as a bug"
    )


def analytic_volume(name: str, **params: Any) -> float | None:
    """Exact volume of a shape, mm³, or None where no closed form is provided.

    Closed forms: sphere ``4/3 π r³``, ellipsoid ``4/3 π abc``, torus
    ``2 π² R r²``, box ``abc``, two_spheres (two balls minus their lens-shaped
    overlap when they intersect). The composites (``y_branch``, ``chair`` and
    every procedural family shape) give None.

    Parameters
    ----------
    name : str
        A registered shape.
    **params
        Sizes overriding the canonical defaults, as for :func:`make_shape`
        (pass ``**shape_params(name, seed=s)`` for a seeded shape).

    Returns
    -------
    float or None
    """
    p = shape_params(name, **params)
    if name == "sphere":
        return 4.0 / 3.0 * math.pi * _positive(p["radius"], "radius") ** 3
    if name == "ellipsoid":
        a, b, c = _triple(p["radii"], "radii")
        return 4.0 / 3.0 * math.pi * a * b * c
    if name == "torus":
        big, small = _positive(p["major"], "major"), _positive(p["minor"], "minor")
        return 2.0 * math.pi**2 * big * small**2
    if name == "box":
        a, b, c = _triple(p["size"], "size")
        return a * b * c
    if name == "two_spheres":
        r, d = _positive(p["radius"], "radius"), _positive(p["distance"], "distance")
        overlap = 0.0 if d >= 2 * r else math.pi * (4 * r + d) * (2 * r - d) ** 2 / 12.0
        return 2.0 * 4.0 / 3.0 * math.pi * r**3 - overlap
    return None
