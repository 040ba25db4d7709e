"""The surface methods: one literal registry of names, what each does and what it needs.

Every ``--method`` value is a :class:`MethodEntry` in :data:`METHODS`, complete
at import. Per-part methods reconstruct each part of a plan
(:mod:`slicerecon.surface.part`): ``sdf`` as one signed-distance field
(``implicit``), ``loft`` and ``hybrid`` as one solid per part (``part_solid``
names the function), united. Whole-shape methods (``poisson``, ``sdf-hull``,
``itk-mci``) reconstruct all the sections at once and skip the planner and
the carve (``function`` names their implementation in
:mod:`slicerecon.surface.baselines`). Implementations are named as
``"module:function"`` and imported only when used, so this module imports
nothing heavy and the command line can validate names. Callers choose what to
do by an entry's capabilities, never by its name.

Add a method by adding its entry to :data:`METHODS` and writing the function it
names (``docs/architecture.md``).
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
    implicit : bool
        The surface is the zero level set of one signed-distance field over
        all the parts: carved (and covered) in the field, its occupancy known
        without rasterizing, and several structures resolved jointly on their
        fields (:mod:`slicerecon.surface.joint`).
    needs_itk : bool
        Needs the optional ``itk`` extra.
    part_solid : str
        For per-part methods that are not implicit: ``"module:function"`` of
        ``function(sections, box, *, extend_to_box, hull, interpolation,
        join_drift) -> manifold3d.Manifold or None``, one part's solid in
        voxel index coordinates.
    function : str
        For whole-shape methods: ``"module:function"`` of its implementation,
        ``function(sections, projections, **options) -> trimesh.Trimesh``.
    summary : str
        One line for help texts.
    """

    name: str
    per_part: bool
    carved: bool
    implicit: bool = False
    needs_itk: bool = False
    part_solid: str = ""
    function: str = ""
    summary: str = ""

    def load(self) -> Callable[..., Any]:
        """The whole-shape implementation (imported now)."""
        if not self.function:
            raise OptionError(f"method {self.name!r} reconstructs per part; it has no function")
        return _load(self.function)

    def load_part_solid(self) -> Callable[..., Any]:
        """The per-part solid function of a method that is not implicit (imported now)."""
        if not self.part_solid:
            raise OptionError(f"method {self.name!r} makes no per-part solid")
        return _load(self.part_solid)


def _load(reference: str) -> Callable[..., Any]:
    module, _, name = reference.partition(":")
    return getattr(importlib.import_module(module), name)  # type: ignore[no-any-return]


_BASELINES = "slicerecon.surface.baselines"
_PART = "slicerecon.surface.part"

METHODS: dict[str, MethodEntry] = {
    "sdf": MethodEntry(
        "sdf",
        per_part=True,
        carved=True,
        implicit=True,
        summary="signed-distance interpolation across planes (the default)",
    ),
    "loft": MethodEntry(
        "loft",
        per_part=True,
        carved=True,
        part_solid=f"{_PART}:loft_part_solid",
        summary="contour lofting, the paper's method",
    ),
    "hybrid": MethodEntry(
        "hybrid",
        per_part=True,
        carved=True,
        part_solid=f"{_PART}:hybrid_part_solid",
        summary="loft where contours correspond simply, sdf elsewhere",
    ),
    "poisson": MethodEntry(
        "poisson",
        per_part=False,
        carved=False,
        function=f"{_BASELINES}:poisson",
        summary="screened Poisson reconstruction of the contour points",
    ),
    "sdf-hull": MethodEntry(
        "sdf-hull",
        per_part=False,
        carved=False,
        function=f"{_BASELINES}:sdf_hull",
        summary="signed-distance interpolation intersected with the visual hull",
    ),
    "itk-mci": MethodEntry(
        "itk-mci",
        per_part=False,
        carved=False,
        needs_itk=True,
        function=f"{_BASELINES}:itk_mci",
        summary="ITK morphological contour interpolation (3D Slicer's Fill between slices)",
    ),
}
"""Every surface method by name, in the order help texts list them."""


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
