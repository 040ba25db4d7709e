"""Parameter checks of the shape functions, declared once, in their signatures.

A shape parameter's annotation says how it is checked: ``radius: Mm`` is a
positive finite size in mm, ``radii: MmXYZ`` three of them (or one for all
three), ``seed: Seed`` a whole number >= 0 or None, and ``holes:
Annotated[int, between(1, 8)]`` a whole number in a range. :func:`checked`
reads these annotations once, when the shape function is defined, and then
validates and converts every argument (sizes to ``float``, triples to
tuples of floats) before the body runs, raising
:class:`~slicerecon.errors.OptionError` for a bad one. A body thus only
checks relations between parameters (a leg narrower than the seat), with
:func:`reject_if`. ``spacing`` and ``margin`` are checked where the grid is
built (:mod:`slicerecon.shapes.grid`).
"""

from __future__ import annotations

import functools
import inspect
import math
import typing
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Annotated, Any, ParamSpec, TypeVar

import numpy as np

from ..errors import OptionError

P = ParamSpec("P")
R = TypeVar("R")


def positive_mm(value: object, name: str) -> float:
    """``value`` as a float, if it is a positive finite number (a size in mm)."""
    try:
        out = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise OptionError(f"{name} must be a number of mm (got {value!r})") from None
    if not math.isfinite(out) or out <= 0.0:
        raise OptionError(f"{name} must be a positive finite size in mm (got {value!r})")
    return out


def sizes_xyz(value: object, name: str) -> tuple[float, float, float]:
    """Three sizes along x, y, z in mm, from three positive numbers or one for all three."""
    if isinstance(value, int | float | np.integer | np.floating):
        v = positive_mm(value, name)
        return v, v, v
    try:
        items = list(value)  # type: ignore[call-overload]
    except TypeError:
        raise OptionError(f"{name} must be one size or three sizes in mm (got {value!r})") from None
    if len(items) != 3:
        raise OptionError(f"{name} must hold 3 sizes (x, y, z) in mm (got {len(items)})")
    a, b, c = (positive_mm(v, f"{name}[{i}]") for i, v in enumerate(items))
    return a, b, c


def whole_number(value: object, name: str, *, low: int, high: int) -> int:
    """``value`` as an int, if it is a whole number from ``low`` to ``high``."""
    if (
        isinstance(value, bool)
        or not isinstance(value, int | np.integer)
        or not (low <= value <= high)
    ):
        raise OptionError(f"{name} must be a whole number from {low} to {high} (got {value!r})")
    return int(value)


def check_seed(seed: object, name: str = "seed") -> int | None:
    """``seed`` as an int, if it is a whole number >= 0, or None."""
    if seed is None:
        return None
    if isinstance(seed, bool) or not isinstance(seed, int | np.integer) or seed < 0:
        raise OptionError(f"{name} must be a whole number >= 0 or None (got {seed!r})")
    return int(seed)


def check_margin(margin: object) -> int:
    """``margin`` as an int, if it is a whole number of voxels >= 0."""
    if isinstance(margin, bool) or not isinstance(margin, int | np.integer) or margin < 0:
        raise OptionError(f"margin must be a whole number of voxels >= 0 (got {margin!r})")
    return int(margin)


@dataclass(frozen=True)
class Check:
    """Annotation metadata: ``convert(value, name)`` validates a parameter and returns it."""

    convert: Callable[[object, str], Any]


Mm = Annotated[float, Check(positive_mm)]
"""A size: a positive finite number of millimetres (the body gets a float)."""

MmXYZ = Annotated[Sequence[float], Check(sizes_xyz)]
"""Sizes along x, y, z, mm: three positive numbers, or one for all three (the body gets a
tuple of 3 floats)."""

Seed = Annotated[int | None, Check(check_seed)]
"""Seed of a shape's structure: a whole number >= 0, or None for the canonical shape."""


def between(low: int, high: int) -> Check:
    """Check of a whole number from ``low`` to ``high`` (holes, blobs, generations)."""
    return Check(functools.partial(whole_number, low=low, high=high))


def checked(func: Callable[P, R]) -> Callable[P, R]:
    """Wrap a shape function so that its arguments are checked by their annotations.

    Every parameter annotated ``Annotated[..., Check(...)]`` is validated and
    converted before ``func`` runs, defaults included. The signature (as
    :func:`inspect.signature` reports it) is ``func``'s own.

    Raises
    ------
    TypeError
        At definition, if a size parameter (one before ``*``) declares no check.
    """
    signature = inspect.signature(func)
    hints = typing.get_type_hints(func, include_extras=True)
    checks = {
        name: meta.convert
        for name, hint in hints.items()
        if name in signature.parameters
        for meta in getattr(hint, "__metadata__", ())
        if isinstance(meta, Check)
    }
    unchecked = [
        p.name
        for p in signature.parameters.values()
        if p.kind is inspect.Parameter.POSITIONAL_OR_KEYWORD and p.name not in checks
    ]
    if unchecked:
        raise TypeError(f"{func.__name__}: size parameters {unchecked} declare no check")

    @functools.wraps(func)
    def wrapper(*args: P.args, **kwargs: P.kwargs) -> R:
        bound = signature.bind(*args, **kwargs)
        bound.apply_defaults()
        for name, convert in checks.items():
            bound.arguments[name] = convert(bound.arguments[name], name)
        return func(*bound.args, **bound.kwargs)

    return wrapper


def reject_if(shape: str, condition: bool, message: str) -> None:
    """Raise ``OptionError("<shape>: <message>")`` when ``condition`` holds.

    For relations between a shape's parameters, which their own checks cannot see.
    """
    if condition:
        raise OptionError(f"{shape}: {message}")
