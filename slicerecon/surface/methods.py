"""The surface methods: one registry of names and what each method does and needs.

Every ``--method`` value is a :class:`MethodEntry` in :data:`METHODS`. Per-part
methods (``sdf``, ``loft``, ``hybrid``) reconstruct each part of a plan
(:mod:`slicerecon.surface.part`); whole-shape methods (``poisson``,
``sdf-hull``, ``itk-mci``) reconstruct all the sections at once and skip the
planner and the carve (:mod:`slicerecon.surface.baselines`, whose functions
are named here and imported only when used). Add a method by adding an entry
(and, for a per-part method, its branch in :mod:`slicerecon.surface.part`).
This module imports nothing heavy, so the command line can validate names.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from ..errors import OptionError

__all__ = [
    "METHODS",
    "MethodEntry",
    "method_entry",
    "method_names",
    "register_method",
]


@dataclass(frozen=True)
class MethodEntry:
    """A surface method and its capabilities.

    Attributes
    ----------
    name : str
        The ``--method`` value.
    per_part : bool
        Reconstructs each part of the planner's partition (else the whole
        shape at once, with no planner).
    carved : bool
        ``--carve`` applies (intersection with the visual hull).
    implicit_carve : bool
        The carve happens in the signed-distance field (one marching cubes)
        instead of by a mesh Boolean.
    needs_itk : bool
        Needs the optional ``itk`` extra.
    function : str
        For whole-shape methods: ``"module:function"`` of its implementation,
        ``function(sections, projections, **options) -> trimesh.Trimesh``.
    summary : str
        One line for help texts.
    """

    name: str
    per_part: bool
    carved: bool
    implicit_carve: bool = False
    needs_itk: bool = False
    function: str = ""
    summary: str = ""

    def load(self) -> Callable[..., Any]:
        """The whole-shape implementation (imported now)."""
        if not self.function:
            raise OptionError(f"method {self.name!r} reconstructs per part; it has no function")
        module, _, name = self.function.partition(":")
        return getattr(importlib.import_module(module), name)  # type: ignore[no-any-return]


METHODS: dict[str, MethodEntry] = {}
"""Registered surface methods by name, in the order help texts list them."""


def register_method(entry: MethodEntry) -> MethodEntry:
    """Add a method to :data:`METHODS` (replacing one of the same name); return it."""
    METHODS[entry.name] = entry
    return entry


def method_entry(name: str) -> MethodEntry:
    """The entry of ``name``.

    Raises
    ------
    OptionError
        For an unknown name (the message lists the registered ones).
    """
    key = name.strip().lower() if isinstance(name, str) else name
    if key not in METHODS:
        raise OptionError(f"method must be one of {', '.join(METHODS)} (got {name!r})")
    return METHODS[key]


def method_names(*, per_part: bool | None = None) -> tuple[str, ...]:
    """Registered names, all or only the per-part (``True``) / whole-shape (``False``) ones."""
    return tuple(n for n, e in METHODS.items() if per_part is None or e.per_part == per_part)


_BASELINES = "slicerecon.surface.baselines"

register_method(
    MethodEntry(
        "sdf",
        per_part=True,
        carved=True,
        implicit_carve=True,
        summary="signed-distance interpolation across planes (the default)",
    )
)
register_method(
    MethodEntry("loft", per_part=True, carved=True, summary="contour lofting, the paper's method")
)
register_method(
    MethodEntry(
        "hybrid",
        per_part=True,
        carved=True,
        summary="loft where contours correspond simply, sdf elsewhere",
    )
)
register_method(
    MethodEntry(
        "poisson",
        per_part=False,
        carved=False,
        function=f"{_BASELINES}:poisson",
        summary="screened Poisson reconstruction of the contour points",
    )
)
register_method(
    MethodEntry(
        "sdf-hull",
        per_part=False,
        carved=False,
        function=f"{_BASELINES}:sdf_hull",
        summary="signed-distance interpolation intersected with the visual hull",
    )
)
register_method(
    MethodEntry(
        "itk-mci",
        per_part=False,
        carved=False,
        needs_itk=True,
        function=f"{_BASELINES}:itk_mci",
        summary="ITK morphological contour interpolation (3D Slicer's Fill between slices)",
    )
)
