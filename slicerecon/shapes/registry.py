"""The registry of shapes: names, families, seeded proportions, :func:`make_shape`."""

from __future__ import annotations

import inspect
import math
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import OptionError
from ..sections import Volume
from .anatomy import brain, kidney, lung, vessel_tree, y_branch
from .furniture import chair, lamp, sofa, table
from .grid import NoVoxelError, Spacing
from .holes import genus2, plate_with_holes, torus
from .multi_component import blobs, two_spheres
from .objects import airplane, car, guitar, rifle
from .params import check_seed, positive_mm, sizes_xyz
from .primitives import box, ellipsoid, sphere

SCALE_RANGE: tuple[float, float] = (0.8, 1.2)
"""Range of the random factor applied to each size parameter by a seeded :func:`make_shape`."""


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
    check_seed(seed)
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
    sizes = shape_params(
        name, seed=seed, **{k: v for k, v in params.items() if k not in option_names}
    )
    if _takes_seed(func):
        options["seed"] = seed
    if resolution is None:
        return func(**sizes, **options, spacing=spacing, margin=margin)
    if (
        isinstance(resolution, bool)
        or not isinstance(resolution, int | np.integer)
        or not (8 <= resolution <= 2048)
    ):
        raise OptionError(
            f"resolution must be a whole number of voxels, 8 to 2048 (got {resolution!r})"
        )
    ratio = np.array(sizes_xyz(spacing, "spacing"))
    ratio = ratio / ratio.max()

    def extent_mm(step: float) -> NDArray[np.float64]:
        for _ in range(4):
            try:
                probe = func(**sizes, **options, spacing=ratio * step, margin=0)
            except NoVoxelError:
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
        except NoVoxelError:
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
        return 4.0 / 3.0 * math.pi * positive_mm(p["radius"], "radius") ** 3
    if name == "ellipsoid":
        a, b, c = sizes_xyz(p["radii"], "radii")
        return 4.0 / 3.0 * math.pi * a * b * c
    if name == "torus":
        big, small = positive_mm(p["major"], "major"), positive_mm(p["minor"], "minor")
        return 2.0 * math.pi**2 * big * small**2
    if name == "box":
        a, b, c = sizes_xyz(p["size"], "size")
        return a * b * c
    if name == "two_spheres":
        r, d = positive_mm(p["radius"], "radius"), positive_mm(p["distance"], "distance")
        overlap = 0.0 if d >= 2 * r else math.pi * (4 * r + d) * (2 * r - d) ** 2 / 12.0
        return 2.0 * 4.0 / 3.0 * math.pi * r**3 - overlap
    return None
