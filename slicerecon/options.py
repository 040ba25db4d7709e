"""How a structure is reconstructed: the one options bundle.

:class:`ReconstructOptions` holds every choice of the reconstruction itself
(planner, surface method, interpolation across planes, carve and cover by the
projections, drift joining, smoothing, parts and weights), documented once,
with one set of defaults, and validated once against the registries of
planners (:data:`slicerecon.partition.planner.PLANNERS`) and surface methods
(:data:`slicerecon.surface.methods.METHODS`). It is passed whole to the layers
that need it: :func:`slicerecon.reconstruct.reconstruct`, the part surfaces of
:mod:`slicerecon.surface.part`, the planners that score reconstructions, and
the case pipeline (whose :class:`~slicerecon.reconstruct.ReconstructConfig`
adds what a case needs around it: plane choice, structures, outputs).

>>> from slicerecon.options import ReconstructOptions
>>> ReconstructOptions(method="loft").with_changes(interpolation="linear").method
'loft'
"""

from __future__ import annotations

from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import Any

from .errors import OptionError
from .partition.planner import PLANNERS, PlannerEntry, planner_entry, planner_names
from .surface.methods import METHODS, MethodEntry, method_entry

__all__ = [
    "AUTO",
    "INTERPOLATIONS",
    "OPTION_NAMES",
    "PLAIN_SDF",
    "ReconstructOptions",
]

AUTO = "auto"
"""The planner chosen by the input: partitioned when dense, one part when sparse."""
INTERPOLATIONS = ("pchip", "linear")
"""How signed distances are interpolated across planes."""


@dataclass(frozen=True)
class ReconstructOptions:
    """Every choice of one structure's reconstruction (the defaults are the product's).

    Build one with keywords, or change one with :meth:`with_changes`; every
    value is checked when the bundle is made, so a bad name fails before any
    work.

    Raises
    ------
    OptionError
        An unknown planner, method or interpolation; ``max_parts < 1``;
        ``weights`` with a planner that takes none, or a weights file that
        does not exist.
    """

    planner: str = "auto"
    """How the shape is partitioned into cuboid parts: ``auto`` (the default:
    ``heuristic`` when the projections come from a dense mask or from files,
    ``none`` when they are derived from the sections of a sparse input, where
    a partition measured no better, ``docs/results.md`` "Annotations"),
    ``heuristic`` (the paper's expert), ``lookahead`` (the expert checked by a
    one-step lookahead on held-out planes), ``none`` (one part: the paper's
    no-projection baseline) or ``policy`` (a trained actor,
    ``docs/policy.md``); see :data:`slicerecon.partition.planner.PLANNERS`."""
    method: str = "sdf"
    """How each part is reconstructed: ``sdf`` (signed-distance interpolation
    across planes + marching cubes, carved by the hull in the implicit
    domain), ``loft`` (contour lofting, the paper's method) or ``hybrid``
    (``loft`` where the contours of consecutive planes correspond simply,
    ``sdf`` where they split, merge or appear); or a whole-shape baseline that
    skips the planner and the carve: ``poisson``, ``sdf-hull`` or ``itk-mci``
    (needs ``slicerecon[itk]``); see :data:`slicerecon.surface.methods.METHODS`
    and ``docs/baselines.md``."""
    interpolation: str = "pchip"
    """How the signed-distance surfaces interpolate across planes: ``pchip``
    (monotone piecewise cubic through all planes, chosen on the real-anatomy
    development shapes) or ``linear`` (classic shape-based interpolation)."""
    carve: bool = True
    """Intersect the surface with the visual hull of the projections
    (``docs/method.md``, section 7): nothing the silhouettes rule out is kept."""
    cover: bool = True
    """With ``carve`` and an implicit method (``sdf``): also fill the two
    silhouettes whose rays lie in the section planes where the interpolation
    falls short of them. Silhouettes derived from the sections themselves are
    never covered (they add nothing)."""
    join_drift: bool = True
    """With the signed-distance surfaces: join regions of consecutive planes
    that overlap nothing on the other plane, blending their distances along the
    shift between them (:mod:`slicerecon.surface.drift`; a slanted rod stays
    one piece)."""
    smooth: bool = False
    """Taubin-smooth each structure's mesh (the label map is not smoothed)."""
    max_parts: int = 8
    """Upper bound on the number of cuboid parts a planner may make."""
    weights: str | None = None
    """Actor weights file for a planner that takes weights (``policy``;
    default: the shipped actor)."""

    def __post_init__(self) -> None:
        planner = self.planner.strip().lower() if isinstance(self.planner, str) else ""
        if planner != AUTO and planner not in planner_names():
            raise OptionError(
                f"--planner must be auto or one of {', '.join(planner_names())} "
                f"(got {self.planner!r})"
            )
        object.__setattr__(self, "planner", planner)
        if not isinstance(self.method, str) or self.method.strip().lower() not in METHODS:
            raise OptionError(f"--method must be one of {', '.join(METHODS)} (got {self.method!r})")
        object.__setattr__(self, "method", method_entry(self.method).name)
        if self.interpolation not in INTERPOLATIONS:
            raise OptionError(
                f"--interpolation must be one of {', '.join(INTERPOLATIONS)} "
                f"(got {self.interpolation!r})"
            )
        for name in ("carve", "cover", "join_drift", "smooth"):  # "no" is a true string
            value = getattr(self, name)
            if not isinstance(value, bool) and type(value).__name__ != "bool_":  # numpy's
                raise OptionError(f"{name} must be True or False (got {value!r})")
            object.__setattr__(self, name, bool(value))
        if isinstance(self.max_parts, bool) or not isinstance(self.max_parts, int):
            raise OptionError(f"max_parts must be an integer (got {self.max_parts!r})")
        if self.max_parts < 1:
            raise OptionError(f"max_parts must be >= 1 (got {self.max_parts})")
        if self.weights is not None:
            if not self.planner_entry.takes_weights:
                takers = " or ".join(n for n, e in PLANNERS.items() if e.takes_weights)
                raise OptionError(
                    f"--weights apply to --planner {takers} only (planner is {planner!r})"
                )
            object.__setattr__(self, "weights", str(self.weights))
            if not Path(self.weights).is_file():
                raise OptionError(f"policy weights file not found: {self.weights}")

    def resolved_planner(self, *, sparse: bool) -> str:
        """The planner that runs: :attr:`planner`, with ``auto`` resolved.

        Parameters
        ----------
        sparse : bool
            Whether the projections are derived from the sections (a sparse input).
        """
        if self.planner != AUTO:
            return self.planner
        return "none" if sparse else "heuristic"

    @property
    def planner_entry(self) -> PlannerEntry:
        """The registry entry of :attr:`planner` (``auto``: of ``heuristic``, what it
        runs on a dense input)."""
        return planner_entry(self.resolved_planner(sparse=False))

    @property
    def method_entry(self) -> MethodEntry:
        """The registry entry of :attr:`method` (its capabilities)."""
        return method_entry(self.method)

    def with_changes(self, **changes: Any) -> ReconstructOptions:
        """A copy with some options changed (checked like a new bundle).

        Raises
        ------
        OptionError
            A name that is not an option, or a value :class:`ReconstructOptions` refuses.
        """
        unknown = sorted(set(changes) - set(OPTION_NAMES))
        if unknown:
            raise OptionError(
                f"not a reconstruction option: {', '.join(unknown)} "
                f"(options: {', '.join(OPTION_NAMES)})"
            )
        return replace(self, **changes) if changes else self

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (``plan.json``'s ``config``)."""
        return {name: getattr(self, name) for name in OPTION_NAMES}


OPTION_NAMES: tuple[str, ...] = tuple(f.name for f in fields(ReconstructOptions))
"""The names of :class:`ReconstructOptions`' fields."""

PLAIN_SDF = ReconstructOptions(
    planner="none", carve=False, interpolation="linear", join_drift=False
)
"""The baseline every table beats: plain signed-distance (shape-based)
interpolation between the planes, linear across them, one part, no
projections (Raya & Udupa 1990)."""
