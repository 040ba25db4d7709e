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
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import EmptyMaskError, LabelError, OptionError
from ..labels import (
    LPS_TO_RAS,
    LabelMap,
    Structure,
    StructureMasks,
    as_labels,
    check_label_values,
    labels_dtype,
)
from . import detect_kind
from .atomic import atomic_path
from .dicom import dicom_info, read_dicom_seg, read_dicom_series_values
from .limits import DEFAULT_MEMORY_BUDGET_GB, check_label_range, reading
from .nrrd import read_nrrd_label_map
from .vti import read_vti

__all__ = [
    "LABEL_MAP_KINDS",
    "read_seg_masks",
    "read_label_map",
    "write_label_map",
]

logger = logging.getLogger(__name__)

LABEL_MAP_KINDS = ("nifti", "nrrd", "vti", "dicom-series", "dicom-seg")
"""Input kinds (:func:`slicerecon.io.detect_kind`) that hold dense structures."""


def read_label_map(
    path: str | os.PathLike[str],
    *,
    allow_irregular: bool = False,
    memory_budget_gb: float = DEFAULT_MEMORY_BUDGET_GB,
    chosen: bool = False,
) -> LabelMap | None:
    """Every structure of a dense input, or None for inputs that hold one (or contours).

    Parameters
    ----------
    path : path-like
        A NIfTI, NRRD or VTI label map, a Slicer ``.seg.nrrd`` segmentation (names
        and colours kept), a DICOM mask series, a DICOM SEG.
    allow_irregular, memory_budget_gb
        As for :func:`slicerecon.io.load_input`.
    chosen : bool
        The caller picks structures explicitly (``--label``, ``--union``):
        values need only be whole numbers. Otherwise values that are not a
        label map (an image, a probability map) are refused before the
        structures are listed (:func:`slicerecon.labels.check_label_values`).

    Returns
    -------
    LabelMap or None
        None for contour files, RTSTRUCTs and meshes.

    Raises
    ------
    InputError
        What the readers raise; :class:`EmptyMaskError` when no structure holds a
        voxel; :class:`LabelError` for values that are not a label map.
    """
    with reading(path):
        return _read_label_map(path, allow_irregular, memory_budget_gb, chosen)


def _read_label_map(
    path: str | os.PathLike[str], allow_irregular: bool, memory_budget_gb: float, chosen: bool
) -> LabelMap | None:

    kind = detect_kind(path)
    if kind.kind not in LABEL_MAP_KINDS:
        return None
    if kind.kind == "nifti":
        from .nifti import read_label_values

        values, affine = read_label_values(kind.path, memory_budget_gb=memory_budget_gb)
        check_label_range(values, what=str(kind.path))
        check_label_values(values, source=kind.path, chosen=chosen)
        result = LabelMap.from_array(values, affine)
    elif kind.kind == "nrrd":
        result = read_nrrd_label_map(kind.path, memory_budget_gb=memory_budget_gb)
        check_label_values(result.labels, source=kind.path, chosen=chosen)
    elif kind.kind == "vti":
        image = read_vti(kind.path, memory_budget_gb=memory_budget_gb)
        check_label_range(image.values, what=str(kind.path))
        check_label_values(image.values, source=kind.path, chosen=chosen)
        result = LabelMap.from_array(np.asarray(image.values), image.affine)
    elif kind.kind == "dicom-series":
        values, affine = read_dicom_series_values(
            kind.path, allow_irregular=allow_irregular, memory_budget_gb=memory_budget_gb
        )
        check_label_values(values, source=kind.path, chosen=chosen)
        if np.any(values != np.round(values)):
            raise LabelError(f"{kind.path} is not a label map: its pixel values are not integers")
        check_label_range(values, what=str(kind.path))
        result = LabelMap.from_array(np.round(values), affine, coordinates="LPS")
    else:
        result = _read_seg_segments(kind.path, memory_budget_gb)
    if not result.structures:
        raise EmptyMaskError(f"{kind.path} holds no structure: every voxel is background")
    return result


def read_seg_masks(
    path: str | os.PathLike[str], *, memory_budget_gb: float = DEFAULT_MEMORY_BUDGET_GB
) -> StructureMasks:
    """Every segment of a DICOM SEG as its own mask, overlaps kept.

    Parameters
    ----------
    path : path-like
        A DICOM SEG file.
    memory_budget_gb : float
        As for :func:`read_label_map`.

    Returns
    -------
    StructureMasks
        One mask per segment with foreground (numbered by SegmentNumber, named
        by SegmentLabel), LPS mm; segments without foreground are reported.

    Raises
    ------
    EmptyMaskError
        No segment has a foreground pixel.
    """
    with reading(path):
        info = dicom_info(path)
        masks, structures, affine = [], [], None
        for segment in info["segments"]:
            number, name = int(segment["number"]), str(segment["label"])
            try:
                volume = read_dicom_seg(path, segment=number, memory_budget_gb=memory_budget_gb)
            except EmptyMaskError:
                logger.warning("%s: segment %d (%s) has no foreground", path, number, name)
                continue
            if affine is not None and volume.shape != masks[0].shape:
                raise EmptyMaskError(f"{path}: segment {number} lies on another grid")
            affine = volume.affine if affine is None else affine
            masks.append(volume.mask)
            structures.append(segment_structure(segment))
        if affine is None:
            raise EmptyMaskError(f"{path}: no segment has a foreground pixel")
        return StructureMasks(tuple(masks), affine, tuple(structures), "LPS")


def _read_seg_segments(path: Path, memory_budget_gb: float) -> LabelMap:
    """Every segment of a DICOM SEG, numbered by SegmentNumber, on one grid.

    Overlapping segments (a SEG may let a voxel belong to several) are made
    disjoint: a voxel goes to the later segment, with a warning.
    """

    info = dicom_info(path)
    labels: NDArray[np.integer] | None = None
    affine = None
    found: list[Structure] = []
    overlap = 0
    for segment in info["segments"]:
        number, structure = int(segment["number"]), segment_structure(segment)
        try:
            volume = read_dicom_seg(path, segment=number, memory_budget_gb=memory_budget_gb)
        except EmptyMaskError:
            logger.warning("%s: segment %d (%s) has no foreground", path, number, structure.name)
            continue
        if labels is None:
            top = max(int(s["value"]) for s in info["segments"])
            labels = np.zeros(volume.shape, dtype=np.uint16 if top < 2**16 else np.uint32)
            affine = volume.affine
        overlap += int(np.count_nonzero(labels[volume.mask]))
        labels[volume.mask] = structure.value
        found.append(structure)
    if labels is None or affine is None:
        raise EmptyMaskError(f"{path}: no segment has a foreground pixel")
    if overlap:
        logger.warning(
            "%s: segments overlap on %d voxels; each goes to the later segment", path, overlap
        )
    return LabelMap.from_array(
        labels,
        affine,
        names={s.value: s.name for s in found},
        colours={s.value: s.colour for s in found if s.colour is not None},
        coordinates="LPS",
    )


def segment_structure(segment: dict[str, Any]) -> Structure:
    """A SEG segment (a record of :func:`slicerecon.io.dicom.dicom_info`'s ``segments``) as a
    structure: its label value (the one slicerecon's writer records, else its
    SegmentNumber), name and colour."""
    colour = segment.get("colour")
    return Structure(
        int(segment.get("value", segment["number"])),
        str(segment["label"]),
        None if colour is None else (int(colour[0]), int(colour[1]), int(colour[2])),
    )


def write_label_map(
    labels: NDArray[np.integer],
    affine: NDArray[np.float64],
    path: str | os.PathLike[str],
    *,
    coordinates: str = "RAS",
    xform_codes: tuple[int, int] | None = None,
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
    xform_codes : (int, int), optional
        ``(sform_code, qform_code)`` to write, e.g. those of the NIfTI input the
        labels are on (:func:`slicerecon.io.nifti.nifti_xform_codes`): an
        MNI-coded input (4 or 2 and 0) keeps its space. Default ``(1, 1)``
        (scanner anatomical), as for a DICOM input.

    Returns
    -------
    Path

    Raises
    ------
    OptionError
        An xform code outside 0-5 (the NIfTI-1 codes, 5 a template).
    """
    import nibabel as nib

    values = as_labels(np.asarray(labels))
    if values.dtype.itemsize > 2 or values.dtype.kind == "i" and values.min() >= 0:
        # the smallest type of at least 16 bits that holds them (2**8 among the values
        # asks for 16 bits, as these maps were written before); above 2**31 uint32, never
        # wrapped
        values = values.astype(labels_dtype([int(values.min()), int(values.max()), 2**8]))
    aff = np.asarray(affine, dtype=np.float64)
    if coordinates == "LPS":
        aff = LPS_TO_RAS @ aff
    sform_code, qform_code = (1, 1) if xform_codes is None else xform_codes
    if not all(isinstance(c, int | np.integer) and 0 <= c <= 5 for c in (sform_code, qform_code)):
        raise OptionError(f"xform_codes must be two NIfTI codes 0-5 (got {xform_codes!r})")
    img = nib.Nifti1Image(values, aff)
    img.header.set_xyzt_units(xyz="mm")
    img.set_sform(aff, code=int(sform_code))
    img.set_qform(aff, code=int(qform_code), strip_shears=True)
    target = Path(path)
    with atomic_path(target) as tmp:
        nib.save(img, tmp)
    return target
