"""The record a case is read into: its annotation, its ground truth, where it is written.

:func:`slicerecon.case_inputs.load_case` makes it from any input,
:func:`slicerecon.combine.combine_cases` from several; :mod:`slicerecon.case`
reconstructs from it.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .annotation import Annotation
from .io import InputKind
from .labels import LabelMap, Structure, StructureMasks
from .sections import CrossSections

__all__ = ["CaseInput"]


@dataclass(frozen=True, eq=False)
class CaseInput:
    """What a case reconstructs from, and what it is scored against.

    Attributes
    ----------
    annotation : Annotation
        The annotated planes of every structure, on the shared grid (the
        input's grid cropped around all the structures, or the contours' grid).
    labels : LabelMap or None
        A dense input on the shared grid: each structure's silhouettes come
        from it, and it is each structure's ground truth. None for sparse inputs.
    truth : LabelMap, Volume, trimesh.Trimesh or None
        A separate ground truth (``--gt``): a label map holding the
        structures' values, or one shape for a one-structure case.
    input_path : Path
        The input.
    kind : InputKind
        What the input is.
    output_affine : ndarray of shape (4, 4)
        Voxel index → world mm of the grid the label map is written on (the
        input's own grid for label maps).
    output_shape : tuple of 3 int
        Shape of that grid.
    crop_lo : ndarray of shape (3,), int
        Where the shared grid starts on the output grid.
    missing : tuple of Structure
        Structures the input lists but nothing was drawn for (RTSTRUCT ROIs
        without closed contours): reported, not reconstructed.
    inputs : tuple of Path
        Every input of a case combined from several (:func:`slicerecon.combine.combine_cases`);
        empty for one input.
    drawn_by : mapping of int to tuple of Path
        In a combined case, the inputs that draw each structure (see :meth:`source_of`).
    """

    annotation: Annotation
    labels: LabelMap | StructureMasks | None
    input_path: Path
    kind: InputKind
    output_affine: NDArray[np.float64]
    output_shape: tuple[int, int, int]
    crop_lo: NDArray[np.int64]
    truth: Any = None
    missing: tuple[Structure, ...] = ()
    inputs: tuple[Path, ...] = ()
    drawn_by: Mapping[int, tuple[Path, ...]] = field(default_factory=dict)

    def source_of(self, value: int) -> str:
        """The input that draws structure ``value`` (of a combined case: those that do),
        for messages about that structure."""
        return " and ".join(str(p) for p in self.drawn_by.get(value, (self.input_path,)))

    @property
    def named(self) -> str:
        """The input, or every input of a combined case, for messages."""
        return ", ".join(str(p) for p in self.inputs) if self.inputs else str(self.input_path)

    @property
    def dense(self) -> bool:
        """True when the input was a dense mask (sampled here, its own ground truth)."""
        return self.labels is not None

    @property
    def has_truth(self) -> bool:
        """True when the case can be scored (a dense input, or a separate ground truth)."""
        return self.labels is not None or self.truth is not None

    @property
    def shared(self) -> CrossSections:
        """Every structure's planes together, on the shared grid."""
        return self.annotation.cross_sections()
