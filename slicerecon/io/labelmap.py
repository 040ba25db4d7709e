"""Several structures on one grid: label maps in and out.

A :class:`LabelMap` is an integer array (0 is background) with its affine and
the structures it holds (:class:`Structure`: value, name, colour). It is what
a NIfTI or VTI label map, a DICOM mask series and a DICOM SEG (every segment,
numbered by SegmentNumber) are read as when all their structures are wanted
(:func:`read_label_map`), and what ``slicerecon run`` writes back as
``labels.nii.gz`` (:func:`write_label_map`).

Coordinates: NIfTI and VTI are read in their own world frame (RAS for NIfTI);
DICOM in LPS. :func:`write_label_map` writes NIfTI in RAS, as the format
requires: an LPS affine is turned into RAS (x and y negated), so the file
overlays its DICOM source in any NIfTI viewer.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import EmptyMaskError, LabelError
from ..sections import Volume, check_affine
from .limits import DEFAULT_MEMORY_BUDGET_GB, reading
from .selection import choose_structure, parse_selector

__all__ = [
    "DEFAULT_COLOURS",
    "LABEL_MAP_KINDS",
    "LPS_TO_RAS",
    "LabelMap",
    "Structure",
    "read_label_map",
    "structure_colour",
    "write_label_map",
]

logger = logging.getLogger(__name__)

LABEL_MAP_KINDS = ("nifti", "nrrd", "vti", "dicom-series", "dicom-seg")
"""Input kinds (:func:`slicerecon.io.detect_kind`) that hold dense structures."""

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
        """``"<value>_<name>"`` (or the value alone), safe as a file name."""
        safe = "".join(c if c.isalnum() or c in "-." else "_" for c in self.name.strip())
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


def _structures(
    labels: NDArray[np.integer],
    names: dict[int, str] | None = None,
    colours: dict[int, tuple[int, int, int]] | None = None,
) -> tuple[Structure, ...]:
    values = np.unique(labels)
    return tuple(
        Structure(int(v), (names or {}).get(int(v), ""), (colours or {}).get(int(v)))
        for v in values
        if v != 0
    )


def _as_labels(values: NDArray[Any]) -> NDArray[np.integer]:
    """Integer labels in the smallest signed or unsigned type that holds them."""
    data = np.asarray(values)
    if data.dtype.kind in "iu":
        return data
    lo, hi = (int(data.min()), int(data.max())) if data.size else (0, 0)
    return data.astype(np.result_type(np.min_scalar_type(lo), np.min_scalar_type(hi)))


def read_label_map(
    path: str | os.PathLike[str],
    *,
    allow_irregular: bool = False,
    memory_budget_gb: float = DEFAULT_MEMORY_BUDGET_GB,
) -> LabelMap | None:
    """Every structure of a dense input, or None for inputs that hold one (or contours).

    Parameters
    ----------
    path : path-like
        A NIfTI, NRRD or VTI label map, a Slicer ``.seg.nrrd`` segmentation (names
        and colours kept), a DICOM mask series, a DICOM SEG.
    allow_irregular, memory_budget_gb
        As for :func:`slicerecon.io.load_input`.

    Returns
    -------
    LabelMap or None
        None for contour files, RTSTRUCTs and meshes.

    Raises
    ------
    InputError
        What the readers raise; :class:`EmptyMaskError` when no structure holds a voxel.
    """
    with reading(path):
        return _read_label_map(path, allow_irregular, memory_budget_gb)


def _read_label_map(
    path: str | os.PathLike[str], allow_irregular: bool, memory_budget_gb: float
) -> LabelMap | None:
    from . import detect_kind

    kind = detect_kind(path)
    if kind.kind not in LABEL_MAP_KINDS:
        return None
    if kind.kind == "nifti":
        from .nifti import read_label_values

        values, affine = read_label_values(kind.path, memory_budget_gb=memory_budget_gb)
        labels, frame = _as_labels(values), "RAS"
        result = LabelMap(labels, affine, _structures(labels), frame)
    elif kind.kind == "nrrd":
        from .nrrd import read_nrrd_label_map

        result = read_nrrd_label_map(kind.path, memory_budget_gb=memory_budget_gb)
    elif kind.kind == "vti":
        from .vti import read_vti

        image = read_vti(kind.path, memory_budget_gb=memory_budget_gb)
        labels = _as_labels(np.asarray(image.values))
        result = LabelMap(labels, image.affine, _structures(labels), "RAS")
    elif kind.kind == "dicom-series":
        from .dicom import read_dicom_series_values

        values, affine = read_dicom_series_values(
            kind.path, allow_irregular=allow_irregular, memory_budget_gb=memory_budget_gb
        )
        if np.any(values != np.round(values)):
            raise LabelError(f"{kind.path} is not a label map: its pixel values are not integers")
        labels = _as_labels(np.round(values))
        result = LabelMap(labels, affine, _structures(labels), "LPS")
    else:
        result = _read_seg_segments(kind.path, memory_budget_gb)
    if not result.structures:
        raise EmptyMaskError(f"{kind.path} holds no structure: every voxel is background")
    return result


def _read_seg_segments(path: Path, memory_budget_gb: float) -> LabelMap:
    """Every segment of a DICOM SEG, numbered by SegmentNumber, on one grid.

    Overlapping segments (a SEG may let a voxel belong to several) are made
    disjoint: a voxel goes to the later segment, with a warning.
    """
    from .dicom import dicom_info, read_dicom_seg

    info = dicom_info(path)
    labels: NDArray[np.integer] | None = None
    affine = None
    names: dict[int, str] = {}
    overlap = 0
    for segment in info["segments"]:
        number = int(segment["number"])
        names[number] = str(segment["label"])
        try:
            volume = read_dicom_seg(path, segment=number, memory_budget_gb=memory_budget_gb)
        except EmptyMaskError:
            logger.warning("%s: segment %d (%s) has no foreground", path, number, names[number])
            continue
        if labels is None:
            labels = np.zeros(volume.shape, dtype=np.uint16)
            affine = volume.affine
        overlap += int(np.count_nonzero(labels[volume.mask]))
        labels[volume.mask] = number
    if labels is None or affine is None:
        raise EmptyMaskError(f"{path}: no segment has a foreground pixel")
    if overlap:
        logger.warning(
            "%s: segments overlap on %d voxels; each goes to the later segment", path, overlap
        )
    return LabelMap(labels, affine, _structures(labels, names), "LPS")


def write_label_map(
    labels: NDArray[np.integer],
    affine: NDArray[np.float64],
    path: str | os.PathLike[str],
    *,
    coordinates: str = "RAS",
) -> Path:
    """Write a label map as NIfTI (RAS; an LPS affine is converted), atomically.

    Parameters
    ----------
    labels : ndarray of shape (I, J, K), integer
        Label values, 0 for background.
    affine : ndarray of shape (4, 4)
        Voxel index → world mm in ``coordinates``.
    path : path-like
        ``.nii`` or ``.nii.gz``.
    coordinates : {"RAS", "LPS"}
        The frame of ``affine``.

    Returns
    -------
    Path
    """
    import nibabel as nib

    from .atomic import atomic_path

    values = _as_labels(np.asarray(labels))
    if values.dtype.itemsize > 2 or values.dtype.kind == "i" and values.min() >= 0:
        values = values.astype(np.uint16 if values.max() < 2**16 else np.int32)
    aff = np.asarray(affine, dtype=np.float64)
    if coordinates == "LPS":
        aff = LPS_TO_RAS @ aff
    img = nib.Nifti1Image(values, aff)
    img.header.set_xyzt_units(xyz="mm")
    img.set_sform(aff, code=1)
    img.set_qform(aff, code=1, strip_shears=True)
    target = Path(path)
    with atomic_path(target) as tmp:
        nib.save(img, tmp)
    return target
