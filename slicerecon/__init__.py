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
from .sections import AXIS_NAMES, Box, Contour, CrossSections, Projection, Projections, Volume

__version__ = "0.1.0"

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
