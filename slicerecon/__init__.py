"""slicerecon: watertight 3D surfaces from parallel planar cross-sections.

An implementation of *Cut-and-Approximate: 3D Shape Reconstruction from Planar
Cross-sections with Deep Reinforcement Learning*: sections and orthographic
projections in, a partition into cuboid parts planned by a heuristic expert or a
learned policy, a lofted surface per part, and one merged watertight mesh out.
"""

from __future__ import annotations

import logging

from .errors import (
    DependencyError,
    EmptyMaskError,
    FormatError,
    GeometryError,
    InputError,
    LabelError,
    OptionError,
    SlicereconError,
)

__version__ = "0.1.0"

_SECTIONS = ("AXIS_NAMES", "Box", "Contour", "CrossSections", "Projection", "Projections", "Volume")


def __getattr__(name: str) -> object:
    """The data model, imported on first use so that ``slicerecon --help`` needs no numpy."""
    if name in _SECTIONS:
        from . import sections

        return getattr(sections, name)
    raise AttributeError(f"module 'slicerecon' has no attribute {name!r}")


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
    "OptionError",
    "Projection",
    "Projections",
    "SlicereconError",
    "Volume",
    "__version__",
]
