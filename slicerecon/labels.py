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
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import LabelError
from .sections import Volume, check_affine
from .selection import choose_structures

__all__ = [
    "DEFAULT_COLOURS",
    "GRADUAL_FRACTION",
    "GRADUAL_MIN_VALUES",
    "LPS_TO_RAS",
    "MAX_STRUCTURES",
    "MAX_LABEL_NAME_CHARS",
    "LabelMap",
    "LabelValues",
    "Structure",
    "as_labels",
    "check_label_values",
    "label_values",
    "layer_of_values",
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
        if self.coordinates not in ("RAS", "LPS"):
            raise LabelError(f'coordinates must be "RAS" or "LPS" (got {self.coordinates!r})')
        labels = np.asarray(self.labels)
        if labels.ndim != 3 or labels.dtype.kind not in "iu":
            raise LabelError(
                "a LabelMap holds a 3-D integer array (got "
                f"{labels.dtype} of shape {labels.shape}): make one with LabelMap.from_array"
            )

    @classmethod
    def from_array(
        cls,
        labels: ArrayLike,
        affine: ArrayLike,
        *,
        names: Mapping[int, str] | None = None,
        colours: Mapping[int, tuple[int, int, int]] | None = None,
        coordinates: str = "RAS",
    ) -> LabelMap:
        """A label map of an integer array: one structure per non-zero value.

        The values are copied (a later change to ``labels`` does not reach the
        label map, as for :class:`~slicerecon.sections.Volume`) and read-only.

        Parameters
        ----------
        labels : ndarray of shape (I, J, K)
            Integer (or boolean, or integer-valued float) label values, 0 background.
        affine : ndarray of shape (4, 4)
            Voxel index → world mm.
        names, colours : mapping of int, optional
            Names and display colours (RGB 0-255) by value.
        coordinates : {"RAS", "LPS"}
            The world frame of ``affine``.

        Raises
        ------
        LabelError
            Not a 3-D array of integer values, or values above :data:`MAX_LABEL`.
        GeometryError
            A bad affine.
        """
        data = np.asarray(labels)
        if data.ndim != 3:
            raise LabelError(f"a label map must be a 3-D array (got shape {data.shape})")
        if data.dtype.kind not in "biuf":
            raise LabelError(f"a label map must hold numbers (got dtype {data.dtype})")
        if data.dtype.kind == "f" and (
            not np.all(np.isfinite(data)) or np.any(data != np.round(data))
        ):
            raise LabelError("a label map holds integer values; this array does not")
        if data.size and data.dtype.kind in "iuf" and float(data.max()) > MAX_LABEL:
            raise LabelError(
                f"a label map's values fit 32-bit unsigned integers (at most {MAX_LABEL}); "
                f"this array holds {data.max().item():.10g}: renumber its structures"
            )
        values = as_labels(data.astype(np.uint8) if data.dtype.kind == "b" else data)
        if np.shares_memory(values, data):  # the caller's array stays the caller's
            values = values.copy()
        values.flags.writeable = False
        return cls(values, affine, _structures_of(values, names, colours), coordinates)

    @property
    def shape(self) -> tuple[int, int, int]:
        """Grid shape ``(I, J, K)``."""
        i, j, k = self.labels.shape
        return i, j, k

    def mask(self, value: int) -> Volume:
        """The voxels of one structure."""
        return Volume(self.labels == value, self.affine)

    def in_frame(self, coordinates: str) -> LabelMap:
        """The same label map in world frame ``coordinates`` ("RAS" or "LPS": x and y
        change sign where it is in the other)."""
        if coordinates == self.coordinates:
            return self
        if coordinates not in ("RAS", "LPS"):
            raise LabelError(f'coordinates must be "RAS" or "LPS" (got {coordinates!r})')
        # LPS_TO_RAS is its own inverse
        return LabelMap(self.labels, LPS_TO_RAS @ self.affine, self.structures, coordinates)

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
        by_value = {s.value: s for s in self.structures}
        chosen = [by_value[v] for v in choose_structures(names, selectors, source=source)]
        keep = np.isin(self.labels, [s.value for s in chosen])
        labels = np.where(keep, self.labels, 0).astype(self.labels.dtype, copy=False)
        return LabelMap(labels, self.affine, tuple(chosen), self.coordinates)


@dataclass(frozen=True, eq=False)
class StructureMasks:
    """Structures on one voxel grid that may overlap or nest (SEG segments, RTSTRUCT ROIs).

    Parameters
    ----------
    masks : tuple of ndarray of shape (I, J, K), bool
        One mask per structure, in the order of ``structures``.
    affine : ndarray of shape (4, 4)
        Voxel index → world mm.
    structures : tuple of Structure
    coordinates : {"RAS", "LPS"}
        The world frame of ``affine``.
    """

    masks: tuple[NDArray[np.bool_], ...]
    affine: NDArray[np.float64]
    structures: tuple[Structure, ...]
    coordinates: str = "LPS"

    def __post_init__(self) -> None:
        object.__setattr__(self, "affine", check_affine(self.affine))
        object.__setattr__(self, "masks", tuple(np.asarray(m, dtype=bool) for m in self.masks))
        if len(self.masks) != len(self.structures):
            raise LabelError(f"{len(self.masks)} masks for {len(self.structures)} structures")
        if len({m.shape for m in self.masks}) > 1:
            raise LabelError("every structure's mask must lie on one grid")

    @property
    def shape(self) -> tuple[int, int, int]:
        """Grid shape ``(I, J, K)``."""
        i, j, k = self.masks[0].shape
        return i, j, k

    def mask(self, value: int) -> Volume:
        """The voxels of one structure."""
        for structure, mask in zip(self.structures, self.masks, strict=True):
            if structure.value == value:
                return Volume(mask, self.affine)
        raise LabelError(f"no structure {value}")

    def union(self) -> Volume:
        """Every structure together."""
        return Volume(np.logical_or.reduce(self.masks), self.affine)

    @property
    def overlap_voxels(self) -> int:
        """Voxels held by more than one structure."""
        counts = np.zeros(self.shape, dtype=np.uint16)
        for mask in self.masks:
            counts += mask
        return int(np.count_nonzero(counts > 1))

    def crop(self, region: tuple[slice, slice, slice], affine: ArrayLike) -> StructureMasks:
        """The masks on a sub-grid (``region`` of voxel indices) whose affine is ``affine``."""
        return StructureMasks(
            tuple(m[region] for m in self.masks), affine, self.structures, self.coordinates
        )

    def select(self, selectors: Sequence[int | str], *, source: str | Path) -> StructureMasks:
        """The structures named by ``selectors`` (numbers or names), in the order given.

        Raises
        ------
        LabelError
            A selector names no structure (the message lists them).
        """
        names = {s.value: s.name for s in self.structures}
        chosen = choose_structures(names, selectors, source=source)
        order = [next(n for n, s in enumerate(self.structures) if s.value == v) for v in chosen]
        return StructureMasks(
            tuple(self.masks[n] for n in order),
            self.affine,
            tuple(self.structures[n] for n in order),
            self.coordinates,
        )


def _structures_of(
    labels: NDArray[np.integer],
    names: Mapping[int, str] | None = None,
    colours: Mapping[int, tuple[int, int, int]] | None = None,
) -> tuple[Structure, ...]:
    values = _distinct(labels)
    return tuple(
        Structure(int(v), (names or {}).get(int(v), ""), (colours or {}).get(int(v)))
        for v in values
        if v != 0
    )


def as_labels(values: NDArray[Any]) -> NDArray[np.integer]:
    """Integer labels in the smallest signed or unsigned type that holds them.

    Parameters
    ----------
    values : ndarray, integer, boolean or integer-valued float
        A label map's values.

    Returns
    -------
    ndarray, integer
        The same values (an integer array is returned as it is).
    """
    data = np.asarray(values)
    if data.dtype.kind in "iu":
        return data
    lo, hi = (int(data.min()), int(data.max())) if data.size else (0, 0)
    return data.astype(np.result_type(np.min_scalar_type(lo), np.min_scalar_type(hi)))


MAX_LABEL = 2**32 - 1
"""The largest label value (a ``uint32`` label map's; also what the file readers accept)."""


def labels_dtype(values: Sequence[int]) -> np.dtype[Any]:
    """The smallest integer type holding every one of ``values`` (label values and 0).

    Parameters
    ----------
    values : sequence of int

    Returns
    -------
    numpy.dtype
        ``uint8``, ``uint16`` or ``uint32`` for values that are all >= 0 (a
        label map's: values up to 2**32 - 1, the largest a reader accepts);
        ``int16`` or ``int32`` otherwise.
    """
    lo, hi = min(values, default=0), max(values, default=0)
    if lo >= 0:
        return np.dtype(np.uint8 if hi < 2**8 else np.uint16 if hi < 2**16 else np.uint32)
    return np.dtype(np.int16 if -(2**15) <= lo and hi < 2**15 else np.int32)


# ------------------------------------------------------------------ is it a label map?
MAX_STRUCTURES = 2000
"""Most structures (distinct non-zero values) one label map may hold. The largest
brain parcellations in use have about a thousand (Schaefer 1000, Lausanne 2008
scale 5 with 1015); a CT or MR image has thousands of distinct values."""

GRADUAL_MIN_VALUES = 16
"""A label map of more distinct non-zero values than this is tested for gradual
change (:data:`GRADUAL_FRACTION`). Up to this many values the test is skipped:
a few labels stacked in layers one voxel thick (a tissue segmentation at 3 mm,
nested shells) pass through intermediate labels too."""

GRADUAL_FRACTION = 0.3
"""Share of a map's value changes that pass through an intermediate value above
which it is taken for an intensity image or a probability map. Along a line of
voxels, a value change is a triple of neighbours ``(a, b, c)`` that are not all
equal; it passes through an intermediate value when all three differ. Label maps
change in steps between regions some voxels thick (measured: 1-3 % for
pyvista's frog tissues and the Desikan-Killiany atlas in MNI and six native
spaces, 2-3 % for random 400- and 1000-parcel atlases of the MNI brain, up to
11 % when these are subsampled to every third voxel, 15 % for parcels of only
about 25 voxels); images and probability
maps vary gradually (64-100 %: MNI152 T1 and tissue probability maps as uint8
0-255, CT with noise, MR, smoothed masks). See docs/formats.md."""

_SAMPLE_PLANES = 32
"""Planes along the last axis on which :func:`label_values` measures gradual change."""
_MIN_CHANGES = 200
"""Fewer value changes than this in the sample: too few to tell (the test passes)."""
_BINCOUNT_SPAN = 1 << 22
"""Integer ranges up to this wide are counted with ``bincount`` (else sorted)."""
_CHUNK = 1 << 20


class LabelValues(NamedTuple):
    """What the values of a would-be label map look like (:func:`label_values`).

    Attributes
    ----------
    lo, hi : float
        The smallest and largest value.
    n_values : int
        Distinct non-zero values: the structures the map would hold.
    gradual : float or None
        Share of the value changes along voxel lines that pass through an
        intermediate value (see :data:`GRADUAL_FRACTION`), measured on up to
        32 planes across the last axis; None when there are too few changes to tell.
    """

    lo: float
    hi: float
    n_values: int
    gradual: float | None


def _flat_chunks(data: NDArray[Any]) -> list[NDArray[Any]]:
    flat = data.ravel(order="K")  # a view for C- and Fortran-ordered arrays alike
    return [flat[i : i + _CHUNK] for i in range(0, flat.size, _CHUNK)]


def _distinct(data: NDArray[Any]) -> NDArray[Any]:
    """The distinct values of an integer array, sorted (``bincount`` for narrow ranges)."""
    if data.size == 0:
        return np.zeros(0, dtype=data.dtype)
    lo, hi = data.min(), data.max()
    span = int(hi) - int(lo) + 1
    if data.dtype.kind not in "iub" or span > _BINCOUNT_SPAN:
        return np.unique(data)
    counts = np.zeros(span, dtype=np.int64)
    for chunk in _flat_chunks(data):
        shifted = chunk.astype(np.int64) - int(lo) if int(lo) else chunk
        counts += np.bincount(shifted, minlength=span)
    return (np.flatnonzero(counts) + int(lo)).astype(data.dtype)


def _gradual_share(data: NDArray[Any]) -> float | None:
    """Share of value changes through an intermediate value, on planes across the last axis."""
    n = data.shape[-1]
    picks = np.unique(np.linspace(0, n - 1, min(n, _SAMPLE_PLANES)).round().astype(np.int64))
    planes = data[..., picks]
    changes = between = 0
    for axis in (0, 1):
        a = np.moveaxis(planes, axis, 0)
        if a.shape[0] < 3:
            continue
        left, mid, right = a[:-2], a[1:-1], a[2:]
        step_in, step_out = left != mid, mid != right
        changes += int(np.count_nonzero(step_in | step_out))
        between += int(np.count_nonzero(step_in & step_out & (left != right)))
    return None if changes < _MIN_CHANGES else between / changes


def layer_of_values(layers: NDArray[np.integer]) -> dict[int, int]:
    """Each non-zero value of a layered label map and the layer that holds it.

    Parameters
    ----------
    layers : ndarray of shape (L, I, J, K)
        Integer label layers (a 3-D label map is one layer): a structure's
        value lies in one layer; structures in different layers may overlap.

    Returns
    -------
    dict of int to int
        Value → layer index, for every non-zero value present.

    Raises
    ------
    LabelError
        A value lies in two layers.
    """
    owner: dict[int, int] = {}
    for index, layer in enumerate(layers):
        for value in _present_values(layer) - {0}:
            if value in owner:
                raise LabelError(
                    f"label value {value} lies in layers {owner[value]} and {index}: "
                    "a structure lies in one layer"
                )
            owner[value] = index
    return owner


def _present_values(layer: NDArray[np.integer]) -> set[int]:
    """The values one 3-D integer label map holds (background included)."""
    lo, hi = (int(layer.min()), int(layer.max())) if layer.size else (0, 0)
    if lo >= 0 and hi < 2**16:  # faster than np.unique on a CT-sized grid, slice by slice
        seen = np.zeros(hi + 1, dtype=bool)
        for k in range(layer.shape[2]):
            seen[layer[:, :, k]] = True
        return set(np.flatnonzero(seen).tolist())
    return set(np.unique(layer).tolist())


def label_values(values: ArrayLike) -> LabelValues:
    """Measure the values of a would-be label map (fast: a second for 512 x 512 x 300).

    Parameters
    ----------
    values : ndarray of shape (I, J, K)
        Integer or integer-valued values.

    Returns
    -------
    LabelValues
    """
    data = np.asarray(values)
    if data.size == 0:
        return LabelValues(0.0, 0.0, 0, None)
    present = _distinct(data)
    n_values = int(present.size) - int(bool(np.any(present == 0)))
    gradual = _gradual_share(data) if n_values > GRADUAL_MIN_VALUES and data.ndim == 3 else None
    return LabelValues(float(present[0]), float(present[-1]), n_values, gradual)


def check_label_values(
    values: ArrayLike, *, source: str | Path = "the input", chosen: bool = False
) -> LabelValues:
    """Refuse, before any work, values that are not a label map (an image, a probability map).

    A label map holds 0 (background) and positive whole numbers, one per
    structure. Refused, each with one message that says how to go on:

    * values that are not whole numbers (a probability map in 0..1, a float image);
    * negative values (a CT in Hounsfield units: air is -1000);
    * more than :data:`MAX_STRUCTURES` distinct non-zero values;
    * more than :data:`GRADUAL_MIN_VALUES` distinct values that change
      gradually between neighbouring voxels (:data:`GRADUAL_FRACTION`): an
      intensity image, or a probability map stored as 0..255.

    Parameters
    ----------
    values : ndarray of shape (I, J, K)
        The values as read.
    source : str or path-like
        What to name in the message (the file).
    chosen : bool
        The structures are chosen explicitly (``--label``, ``--union``): only
        whole numbers are required; the user has said which values are structures.

    Returns
    -------
    LabelValues
        The measurements (for a caller that describes the map).

    Raises
    ------
    LabelError
        With the reason and what to do instead.
    """
    data = np.asarray(values)
    if data.dtype.kind == "f":
        for chunk in _flat_chunks(data):
            if not np.all(np.isfinite(chunk)) or np.any(chunk != np.round(chunk)):
                raise LabelError(
                    f"{source} is not a label map: its values are not whole numbers (a "
                    "probability map or an image); threshold it into a mask first (e.g. "
                    "probability > 0.5), or pass the segmentation instead of the image"
                )
        data = as_labels(data)
    if data.dtype.kind not in "biu":
        raise LabelError(f"{source}: a label map must hold numbers (got dtype {data.dtype})")
    if chosen:
        return LabelValues(float(data.min()), float(data.max()) if data.size else 0.0, 0, None)
    lo = data.min() if data.size else 0
    if lo < 0:
        raise LabelError(
            f"{source} is not a label map: it holds negative values (down to {lo:g}), as an "
            "image does (a CT in Hounsfield units); pass the mask or segmentation (for "
            "DICOM, the mask series, not the CT), or threshold the image into a mask first"
        )
    found = label_values(data)
    if found.n_values > MAX_STRUCTURES:
        raise LabelError(
            f"{source} is not a label map: it holds {found.n_values} distinct values, more "
            f"than the {MAX_STRUCTURES} structures a segmentation plausibly has (an image?); "
            "pass the mask or segmentation, threshold the image, or choose the structures "
            "of a large atlas with --label A,B,..."
        )
    if found.gradual is not None and found.gradual > GRADUAL_FRACTION:
        raise LabelError(
            f"{source} looks like an intensity image or a probability map, not a label map: "
            f"its {found.n_values} distinct values change gradually between neighbouring "
            f"voxels ({found.gradual:.0%} of the changes pass through an intermediate value; "
            f"label maps stay under {GRADUAL_FRACTION:.0%}); threshold it into a mask (e.g. "
            "values > 127 of a 0-255 probability map), pass the mask series instead of the "
            "image, or, if it is a label map, choose its structures with --label A,B,..."
        )
    return found
