"""slicerecon: watertight 3D surfaces and dense label maps from planar cross-sections.

An implementation of *Cut-and-Approximate: 3D Shape Reconstruction from Planar
Cross-sections with Deep Reinforcement Learning*: sections and orthographic
projections in, a partition into cuboid parts planned by a heuristic expert or a
learned policy, a signed-distance surface per part (or the paper's lofting), and
one merged watertight mesh out. Sparse annotations (label maps drawn on some
slices, in one or several views, and contours on planes of any orientation) are
reconstructed from all their planes at once:
:func:`slicerecon.case.reconstruct_structures` reads any input and reconstructs
every structure.
"""

from __future__ import annotations

import logging
from typing import TYPE_CHECKING

from .errors import (
    DependencyError,
    EmptyMaskError,
    FormatError,
    GeometryError,
    InputError,
    LabelError,
    MemoryBudgetError,
    OptionError,
    SlicereconError,
)

if TYPE_CHECKING:  # what type checkers and editors see; imported lazily at run time
    from .case import reconstruct_structures
    from .labels import LabelMap
    from .reconstruct import ReconstructConfig
    from .sections import (
        AXIS_NAMES,
        Box,
        Contour,
        CrossSections,
        Projection,
        Projections,
        Volume,
    )

__version__ = "0.1.0"

_LAZY = {
    **dict.fromkeys(
        ("AXIS_NAMES", "Box", "Contour", "CrossSections", "Projection", "Projections", "Volume"),
        "sections",
    ),
    "LabelMap": "labels",
    "ReconstructConfig": "reconstruct",
    "reconstruct_structures": "case",
}


def __getattr__(name: str) -> object:
    """The data model and the entry point, imported on first use so that ``slicerecon
    --help`` needs no numpy."""
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(f".{_LAZY[name]}", __name__), name)
    raise AttributeError(f"module 'slicerecon' has no attribute {name!r}")


def __dir__() -> list[str]:
    """Every public name, the lazy ones included (tab completion)."""
    return sorted({*globals(), *_LAZY})


logging.getLogger(__name__).addHandler(logging.NullHandler())

__all__ = [
    "AXIS_NAMES",
    "Box",
    "Contour",
    "CrossSections",
    "DependencyError",
    "EmptyMaskError",
    "FormatError",
    "GeometryError",
    "InputError",
    "LabelError",
    "LabelMap",
    "MemoryBudgetError",
    "OptionError",
    "Projection",
    "Projections",
    "ReconstructConfig",
    "SlicereconError",
    "Volume",
    "__version__",
    "reconstruct_structures",
]
