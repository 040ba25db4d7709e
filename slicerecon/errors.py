"""The exceptions slicerecon raises.

Every error a user can cause (a missing file, a corrupt header, an empty mask,
planes that are not parallel, ...) is raised as a subclass of
:class:`SlicereconError` with a message that says what was wrong and what to do.
The command line prints that message on one line and exits non-zero.
"""

from __future__ import annotations

__all__ = [
    "SlicereconError",
    "InputError",
    "FormatError",
    "EmptyMaskError",
    "LabelError",
    "GeometryError",
    "MemoryBudgetError",
    "OptionError",
    "DependencyError",
]


class SlicereconError(Exception):
    """Base class of every error slicerecon raises on purpose."""


class InputError(SlicereconError):
    """An input file or array cannot be used (missing, unreadable, wrong kind)."""


class FormatError(InputError):
    """A file exists but its content is corrupt or not in the expected format."""


class EmptyMaskError(InputError):
    """A mask, label or set of contours holds no foreground at all."""


class LabelError(InputError):
    """A requested label / ROI is absent, or labels are not what was asked for."""


class GeometryError(InputError):
    """Inconsistent geometry: non-parallel planes, irregular spacing, open meshes."""


class MemoryBudgetError(InputError):
    """An input asks for more memory than the budget allows (``--max-memory``)."""


class OptionError(SlicereconError):
    """An option value is out of range or inconsistent with the input."""


class DependencyError(SlicereconError):
    """An optional dependency needed for the requested feature is not installed."""
