"""Seeded procedural shapes as binary volumes, for training and tests.

Every shape is a function ``name(size parameters..., *, spacing=1.0, margin=3)``
returning a :class:`~slicerecon.sections.Volume`. The parameters before the
``*`` are sizes in millimetres; each shape is defined implicitly (an inside
test evaluated at voxel centres; composite shapes are unions of boxes,
spheres and capsules, a capsule being the points closer than its radius to a
segment).

Grid
----
The grid is axis-aligned with voxel size ``spacing`` (mm, one value or one per
axis x, y, z). It covers the shape's bounding box plus ``margin`` empty voxels
on every side; voxel centres are laid out symmetrically about the bounding
box centre (which thus falls on a voxel corner, so that, e.g., a 60 mm box at
1 mm spacing holds exactly 60 voxels along x). The affine's origin is then
chosen so that the centroid of the foreground voxel centres sits at world
``(0, 0, 0)``; for the symmetric primitives this is their analytic centre.

Registry
--------
:data:`SHAPES` maps names to shape functions; :func:`make_shape` builds one by
name, optionally with seeded random proportions (every size parameter scaled
by an independent factor drawn from ``U(0.8, 1.2)``; same seed, same mask).
:func:`analytic_volume` gives the exact volume of the primitives.
"""

from __future__ import annotations

import inspect
import logging
import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import OptionError
from .sections import Volume

__all__ = [
    "SHAPES",
    "SCALE_RANGE",
    "analytic_volume",
    "box",
    "chair",
    "ellipsoid",
    "make_shape",
    "shape_names",
    "shape_params",
    "sphere",
    "torus",
    "two_spheres",
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
    sp = np.array(_triple(spacing, "spacing"))
    margin = _check_margin(margin)
    lo_mm = np.asarray(lo, dtype=np.float64)
    hi_mm = np.asarray(hi, dtype=np.float64)
    centre = 0.5 * (lo_mm + hi_mm)
    half = 0.5 * (hi_mm - lo_mm)
    # Centres sit at +-(k + 1/2) * spacing from the box centre: floor(half / s + 1/2) of
    # them per side lie within the box, so every foreground centre is on the grid.
    per_side = np.maximum(np.floor(half / sp + 0.5 + 1e-9).astype(np.int64), 1)
    counts = 2 * per_side + 2 * margin
    if float(np.prod(counts.astype(np.float64))) > _MAX_VOXELS:
        raise OptionError(
            f"{name}: spacing {tuple(sp)} mm needs a grid of {tuple(counts)} voxels; "
            f"use a coarser spacing (at most {_MAX_VOXELS} voxels)"
        )
    first = centre - 0.5 * (counts - 1) * sp  # world position of voxel 0, before centring
    axes = [first[a] + sp[a] * np.arange(counts[a]) for a in range(3)]
    x, y, z = np.ix_(*axes)
    mask = np.broadcast_to(inside(x, y, z), tuple(counts))
    if not mask.any():
        raise OptionError(
            f"{name}: no voxel centre falls inside the shape at spacing {tuple(sp)} mm; "
            "use a finer spacing or larger sizes"
        )
    ijk = np.nonzero(mask)
    centroid = np.array([axes[a][ijk[a]].mean() for a in range(3)])
    affine = np.diag([*sp, 1.0])
    affine[:3, 3] = first - centroid
    volume = Volume(np.ascontiguousarray(mask), affine)
    logger.debug("%s: %r", name, volume)
    return volume


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
    spacing: Spacing = 1.0,
    margin: int = 3,
) -> Volume:
    """A chair of boxes: a seat slab, a back slab and four legs.

    The legs (square, ``leg_width`` wide) stand at the seat's corners from
    ``z = 0`` to ``z = leg_height``; the seat lies on them; the back rises from
    the seat along its back edge (``+y``). Any z-plane below the seat cuts the
    four legs as four separate squares.

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
    spacing, margin
        As for :func:`sphere`.

    Returns
    -------
    Volume
        Foreground centroid at world (0, 0, 0).
    """
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

    def inside(x: NDArray, y: NDArray, z: NDArray) -> NDArray[np.bool_]:
        out = np.zeros(np.broadcast_shapes(x.shape, y.shape, z.shape), dtype=bool)
        for lo, hi in parts:
            out |= _in_box(x, y, z, lo, hi)
        return out

    return _rasterize(
        inside, (-w, -d, 0.0), (w, d, seat_top + back_h),
        spacing=spacing, margin=margin, name="chair",
    )


# -- registry -----------------------------------------------------------------------
SHAPES: dict[str, Callable[..., Volume]] = {
    "sphere": sphere,
    "ellipsoid": ellipsoid,
    "torus": torus,
    "box": box,
    "two_spheres": two_spheres,
    "y_branch": y_branch,
    "chair": chair,
}
"""Shape functions by name. The parameters before ``*`` of each are sizes in mm."""


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
    defaults = _size_parameters(_lookup(name))
    unknown = sorted(set(params) - set(defaults))
    if unknown:
        raise OptionError(
            f"shape {name!r} has no parameter {', '.join(unknown)}; "
            f"its sizes are {', '.join(defaults)} (plus spacing and margin)"
        )
    resolved = {**defaults, **params}
    if seed is None:
        return resolved
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
    **params: Any,
) -> Volume:
    """Build a registered shape by name, with canonical or seeded random proportions.

    Parameters
    ----------
    name : str
        A registered shape (see :func:`shape_names`).
    seed : int, optional
        Seed of the random proportions (see :func:`shape_params`): the same
        seed gives the same mask. None gives the canonical shape.
    spacing : float or sequence of 3 floats, default 1
        Voxel size, mm.
    margin : int, default 3
        Empty voxels around the shape on every side.
    **params
        Sizes overriding the canonical defaults (before random scaling).

    Returns
    -------
    Volume

    Raises
    ------
    OptionError
        If the name or a parameter is unknown, or a size is invalid.
    """
    func = _lookup(name)
    sizes = shape_params(name, seed=seed, **params)
    return func(**sizes, spacing=spacing, margin=margin)


def analytic_volume(name: str, **params: Any) -> float | None:
    """Exact volume of a shape, mm³, or None where no closed form is provided.

    Closed forms: sphere ``4/3 π r³``, ellipsoid ``4/3 π abc``, torus
    ``2 π² R r²``, box ``abc``, two_spheres (two balls minus their lens-shaped
    overlap when they intersect). The composites ``y_branch`` and ``chair``
    give None.

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
