"""Structures and label maps: several structures on one voxel grid.

A :class:`Structure` is one structure of an input (value, name, colour): a
label value of a label map, a segment of a DICOM SEG or Slicer segmentation,
an ROI of an RTSTRUCT. A :class:`LabelMap` is an integer array (0 is
background) with its affine and the structures it holds; it is a partition:
no voxel belongs to two structures. Readers (:mod:`slicerecon.io`) produce
these types and writers consume them; this module knows no file format.
"""

from __future__ import annotations

import unicodedata
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .sections import Volume, check_affine
from .selection import choose_structure, parse_selector

__all__ = [
    "DEFAULT_COLOURS",
    "LPS_TO_RAS",
    "MAX_LABEL_NAME_CHARS",
    "LabelMap",
    "Structure",
    "structure_colour",
    "structure_name",
]

MAX_LABEL_NAME_CHARS = 48
"""Characters of a structure's name kept in its file names (:attr:`Structure.label`): at
most 4 bytes each in UTF-8, so a file name stays under the 255 bytes file systems allow."""

LPS_TO_RAS = np.diag([-1.0, -1.0, 1.0, 1.0])
"""DICOM patient LPS → RAS (x and y negated); its own inverse."""


DEFAULT_COLOURS: tuple[tuple[int, int, int], ...] = (
    (230, 25, 75),
    (60, 180, 75),
    (255, 225, 25),
    (0, 130, 200),
    (245, 130, 48),
    (145, 30, 180),
    (70, 240, 240),
    (240, 50, 230),
    (210, 245, 60),
    (250, 190, 212),
    (0, 128, 128),
    (220, 190, 255),
    (170, 110, 40),
    (128, 0, 0),
    (170, 255, 195),
    (128, 128, 0),
)
"""Display colours (RGB 0-255) of structures that have none, in turn (Trubetskoy's
16 distinct colours without black, white and greys): the one palette of every
written segmentation (``labels.seg.nrrd``, ``seg.dcm``, ``rtstruct.dcm``)."""


def structure_name(structure: Structure) -> str:
    """A structure's name in every written output: its own, else ``Segment_<value>``.

    One rule for ``labels.seg.nrrd``, ``seg.dcm`` and ``rtstruct.dcm``: an
    unnamed structure is called as 3D Slicer calls an unnamed segment.

    Parameters
    ----------
    structure : Structure

    Returns
    -------
    str
        The name without leading or trailing white space (accents and any
        script kept), or ``Segment_<value>``.
    """
    return structure.name.strip() or f"Segment_{structure.value}"


def structure_colour(structure: Structure, index: int) -> tuple[int, int, int]:
    """A structure's display colour: its own, else the ``index``-th of :data:`DEFAULT_COLOURS`.

    Parameters
    ----------
    structure : Structure
    index : int
        Its position among the structures written (0-based).

    Returns
    -------
    tuple of 3 int
        RGB, 0-255.
    """
    if structure.colour is not None:
        r, g, b = (int(np.clip(round(float(c)), 0, 255)) for c in structure.colour)
        return r, g, b
    return DEFAULT_COLOURS[index % len(DEFAULT_COLOURS)]


@dataclass(frozen=True)
class Structure:
    """One structure of an input.

    Attributes
    ----------
    value : int
        Its label value (label maps), SegmentNumber (SEG) or ROINumber (RTSTRUCT).
    name : str
        Its name ("" when the input has none).
    colour : tuple of 3 int or None
        Display colour, RGB 0-255, when the input has one.
    """

    value: int
    name: str = ""
    colour: tuple[int, int, int] | None = None

    @property
    def label(self) -> str:
        """``"<value>_<name>"`` (or the value alone), safe as a file name.

        Letters and digits of any script are kept, accents included (``Tête
        fémorale`` → ``1_Tête_fémorale``), in Unicode NFC form so that one name
        gives one file name on every system; any other character becomes ``_``.
        The name part is cut to :data:`MAX_LABEL_NAME_CHARS` characters, so the
        file name stays within what file systems allow.
        """
        name = unicodedata.normalize("NFC", self.name.strip())[:MAX_LABEL_NAME_CHARS]
        safe = "".join(c if c.isalnum() or c in "-." else "_" for c in name)
        return f"{self.value}_{safe}" if safe else str(self.value)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {
            "value": self.value,
            "name": self.name,
            "colour": None if self.colour is None else list(self.colour),
        }


@dataclass(frozen=True, eq=False)
class LabelMap:
    """Structures on one voxel grid.

    Parameters
    ----------
    labels : ndarray of shape (I, J, K), integer
        The value of the structure holding each voxel, 0 for background.
    affine : ndarray of shape (4, 4)
        Voxel index → world mm.
    structures : tuple of Structure
        The structures, one per non-zero value present (in value order).
    coordinates : {"RAS", "LPS"}
        The world frame of ``affine``.
    """

    labels: NDArray[np.integer]
    affine: NDArray[np.float64]
    structures: tuple[Structure, ...]
    coordinates: str = "RAS"

    def __post_init__(self) -> None:
        object.__setattr__(self, "affine", check_affine(self.affine))

    @property
    def shape(self) -> tuple[int, int, int]:
        """Grid shape ``(I, J, K)``."""
        i, j, k = self.labels.shape
        return i, j, k

    def mask(self, value: int) -> Volume:
        """The voxels of one structure."""
        return Volume(self.labels == value, self.affine)

    def union(self) -> Volume:
        """Every structure together (``--union``)."""
        return Volume(self.labels != 0, self.affine)

    def select(self, selectors: Sequence[int | str], *, source: str | Path) -> LabelMap:
        """The structures named by ``selectors`` (numbers or names), in the order given.

        Raises
        ------
        LabelError
            A selector names no structure (the message lists them).
        """
        names = {s.value: s.name for s in self.structures}
        chosen: list[Structure] = []
        for selector in selectors:
            value = choose_structure(names, parse_selector(selector), kind="label", source=source)
            found = next(s for s in self.structures if s.value == value)
            if found not in chosen:
                chosen.append(found)
        keep = np.isin(self.labels, [s.value for s in chosen])
        labels = np.where(keep, self.labels, 0).astype(self.labels.dtype, copy=False)
        return LabelMap(labels, self.affine, tuple(chosen), self.coordinates)
