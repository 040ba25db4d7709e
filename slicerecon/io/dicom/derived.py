"""What a derived DICOM object (SEG, RTSTRUCT) needs from the image series it refers to.

A DICOM SEG or RT Structure Set written by slicerecon refers to the images of
one series: their SOPInstanceUIDs, their study, their FrameOfReferenceUID.
This module reads that series (a directory, files, or pydicom datasets; headers
only), puts its images on the grid :func:`~slicerecon.io.dicom.dicom_series_geometry`
defines (array axes (column, row, slice), voxel index → DICOM patient LPS mm),
and places a label map onto that grid.

The grid is the series reader's own (:mod:`.series`): slices sorted along
``row_cosine × column_cosine``, a gantry tilt kept in the affine, an irregular
series accepted only with ``allow_irregular`` (then planes that copy a
neighbouring slice have no image, and nothing is written on them).

Placing a label map on the series grid
--------------------------------------
A label map may come on the series grid itself (a DICOM mask series), on a
grid that covers only some of its slices (a DICOM SEG is read over the planes
that have frames) or whose slice axis is its own (an RTSTRUCT whose contours
lie between the image's slices). :func:`labels_on_series` accepts any grid
whose in-plane pixels are the series' pixels (same row and column steps, a
whole-pixel offset) and whose planes are parallel to the series' slices: each
image slice takes the label plane nearest to it (exactly the one at its
position when the grids agree). Other grids are refused with a
:class:`~slicerecon.errors.GeometryError`: rasterize the reconstruction onto
the series grid first (:func:`slicerecon.rasterize.mesh_to_mask`).
"""

from __future__ import annotations

import logging
import os
import re
import unicodedata
from collections.abc import Collection, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ...errors import FormatError, GeometryError, InputError, LabelError, OptionError
from ...labels import Structure, layer_of_values, structure_colour, structure_name
from ...sections import check_affine
from ..limits import check_geometry
from .geometry import require_path
from .series import _layout, _scan_series, _Slice, _slice_from, check_one_series, series_label
from .sniff import PARSE_ERRORS, read_dicom_header

__all__ = [
    "SourceSeries",
    "check_label_map",
    "check_same_subject",
    "dicom_name",
    "display_colour",
    "labels_on_series",
    "layers_on_series",
    "load_source_series",
    "reference_frames",
    "roi_frames",
    "structure_mask",
]

logger = logging.getLogger(__name__)

LO_MAX_CHARS = 64
"""Longest DICOM LO (Long String) value, characters."""

GRID_TOLERANCE_PX = 0.01
"""How far, in pixels, a label map's in-plane pixels may lie from the series' pixels."""

_UID = re.compile(r"(?=.{1,64}$)[0-9]+(\.[0-9]+)*")
"""A DICOM UID: dot-separated numbers, at most 64 characters (PS3.5 9.1; a leading zero in
a component, which some scanners write, is let through)."""

_REQUIRED_UIDS = (
    "SOPClassUID",
    "SOPInstanceUID",
    "StudyInstanceUID",
    "SeriesInstanceUID",
    "FrameOfReferenceUID",
)


@dataclass(frozen=True, eq=False)
class SourceSeries:
    """The images of one series on their voxel grid.

    Attributes
    ----------
    affine : ndarray of shape (4, 4)
        Voxel index → DICOM patient LPS mm (as :func:`dicom_series_geometry`).
    shape : tuple of int
        ``(I, J, K)`` = (Columns, Rows, planes).
    images : tuple of pydicom.Dataset
        The image of each plane that has one, in plane order (headers only).
    planes : ndarray of shape (N,), int64
        ``planes[n]`` is the plane of ``images[n]`` (all planes, unless the
        series was put on a regular grid with ``allow_irregular``).
    positions : ndarray of shape (N, 3)
        ImagePositionPatient of each image, LPS mm: where its pixel (0, 0) is.
        With ``allow_irregular`` an image may lie up to half a plane step from
        its plane; contours drawn on it must lie on the image itself.
    name : str
        Where the series came from, for messages.
    """

    affine: NDArray[np.float64]
    shape: tuple[int, int, int]
    images: tuple[Any, ...]
    planes: NDArray[np.int64]
    positions: NDArray[np.float64]
    name: str

    def image_to_world(self, n: int, points_px: ArrayLike) -> NDArray[np.float64]:
        """Map pixel coordinates on image ``n`` to LPS mm.

        Parameters
        ----------
        n : int
            Image number in ``[0, N)``.
        points_px : array_like of shape (M, 2)
            ``(column, row)`` index coordinates (array axes 0 and 1 of the grid).

        Returns
        -------
        ndarray of shape (M, 3)
            On the plane of the image itself.
        """
        pts = np.asarray(points_px, dtype=np.float64).reshape(-1, 2)
        return self.positions[n] + pts @ self.affine[:3, :2].T

    @property
    def first(self) -> Any:
        """The first image (patient, study, series and frame of reference are shared)."""
        return self.images[0]

    @property
    def frame_of_reference_uid(self) -> str:
        """FrameOfReferenceUID of the images."""
        return str(self.first.FrameOfReferenceUID)

    @property
    def study_instance_uid(self) -> str:
        """StudyInstanceUID of the images."""
        return str(self.first.StudyInstanceUID)

    @property
    def series_instance_uid(self) -> str:
        """SeriesInstanceUID of the images."""
        return str(self.first.SeriesInstanceUID)


def _slices_from_items(items: Sequence[Any]) -> list[_Slice]:
    from pydicom.dataset import Dataset

    slices: list[_Slice] = []
    for n, item in enumerate(items):
        if isinstance(item, (str, os.PathLike)):
            path = Path(item)
            if not path.is_file():
                raise InputError(f"source image not found: {path}")
            ds = read_dicom_header(path, stop_before_pixels=True)
        elif isinstance(item, Dataset):
            ds = item
            path = Path(str(getattr(item, "filename", "") or f"source_images[{n}]"))
        else:
            raise OptionError(
                f"source_images[{n}] is a {type(item).__name__}: pass pydicom datasets, "
                "paths of image files, or the directory of the series"
            )
        found = _slice_from(ds, path)
        if found is not None:
            slices.append(found)
    if not slices:
        raise InputError(
            "source_images hold no DICOM image: pass the image series the label map was drawn on"
        )
    check_one_series(slices, "source_images")
    return slices


def load_source_series(
    source_images: str | os.PathLike[str] | Sequence[Any] | SourceSeries,
    *,
    allow_irregular: bool = False,
) -> SourceSeries:
    """Read the headers of an image series and put its images on their grid.

    Parameters
    ----------
    source_images : path-like, sequence of pydicom.Dataset or path-like, or SourceSeries
        The directory of the series (non-image objects in it are skipped, as by
        :func:`read_dicom_series`), or its images as datasets or file paths (in
        any order); a SourceSeries already loaded is returned as it is.
    allow_irregular : bool
        Accept uneven slice spacing (the grid of :func:`read_dicom_series`
        with ``allow_irregular=True``).

    Returns
    -------
    SourceSeries

    Raises
    ------
    InputError
        No image, a missing file, images of several series, studies or
        patients (named by modality and SeriesDescription).
    FormatError
        An unreadable file, or images lacking the UIDs a derived object refers to.
    GeometryError
        What the series reader refuses (non-parallel slices, irregular spacing, ...).
    """
    if isinstance(source_images, SourceSeries):
        return source_images
    if isinstance(source_images, (str, os.PathLike)):
        directory = require_path(source_images, want_dir=True)
        slices = _scan_series(directory, stop_before_pixels=True)
        name = str(directory)
    else:
        slices = _slices_from_items(list(source_images))
        name = f"the {len(slices)} source images"
    layout = _layout(slices, allow_irregular=allow_irregular)
    check_geometry(layout.affine, layout.shape, what=name)
    planes = np.flatnonzero(layout.own).astype(np.int64)
    own = [layout.slices[int(layout.sources[k])] for k in planes]
    images = tuple(item.dataset for item in own)
    positions = np.array([item.position for item in own], dtype=np.float64)
    for image, k in zip(images, planes, strict=True):
        try:
            uids = {key: str(image.get(key, "") or "") for key in _REQUIRED_UIDS}
        except PARSE_ERRORS as exc:
            raise FormatError(
                f"{name}: the UIDs of the image of plane {int(k)} cannot be read "
                f"({type(exc).__name__}: {exc}); a SEG or RTSTRUCT cannot refer to it"
            ) from exc
        missing = [key for key, uid in uids.items() if not uid]
        if missing:
            raise FormatError(
                f"{name}: the image of plane {int(k)} lacks {', '.join(missing)}; a SEG or "
                "RTSTRUCT cannot refer to it"
            )
        invalid = [f"{key} {uid!r}" for key, uid in uids.items() if not _UID.fullmatch(uid)]
        if invalid:
            raise FormatError(
                f"{name}: the image of plane {int(k)} has an invalid {', '.join(invalid)} "
                "(a UID is digits and dots, at most 64 characters); a SEG or RTSTRUCT cannot "
                "refer to it"
            )
    frames = {str(image.FrameOfReferenceUID) for image in images}
    if len(frames) > 1:
        raise GeometryError(
            f"{name}: the images have {len(frames)} FrameOfReferenceUIDs; "
            "they are not one series in one frame of reference"
        )
    return SourceSeries(layout.affine, layout.shape, images, planes, positions, name)


def reference_frames(ds: Any, numbers: Collection[int] | None = None) -> tuple[set[str], set[str]]:
    """The FrameOfReferenceUIDs an RTSTRUCT (or any derived object) names.

    ``numbers``: only the frames of these ROIs (by ROINumber) count as its ROIs'
    (the ROIs that were read; one in another frame is left out by the reader).

    Returns
    -------
    rois : set of str
        The frames its ROIs lie in (StructureSetROISequence).
    listed : set of str
        Every frame it names (also FrameOfReferenceUID and
        ReferencedFrameOfReferenceSequence, which may list registered frames).
    """
    rois = {
        str(item.get("ReferencedFrameOfReferenceUID", "") or "")
        for item in ds.get("StructureSetROISequence", None) or []
        if numbers is None or _roi_number(item) in numbers
    }
    listed = rois | {str(ds.get("FrameOfReferenceUID", "") or "")}
    for item in ds.get("ReferencedFrameOfReferenceSequence", None) or []:
        listed.add(str(item.get("FrameOfReferenceUID", "") or ""))
    rois.discard("")
    listed.discard("")
    return rois, listed


def roi_frames(ds: Any) -> dict[int, str]:
    """Each ROI's FrameOfReferenceUID in an RTSTRUCT: ``{ROINumber: ReferencedFrameOfReferenceUID}``
    for the StructureSetROISequence items with a valid ROINumber that name a frame."""
    frames: dict[int, str] = {}
    for item in ds.get("StructureSetROISequence", None) or []:
        number = _roi_number(item)
        uid = str(item.get("ReferencedFrameOfReferenceUID", "") or "")
        if number is not None and uid:
            frames[number] = uid
    return frames


def _roi_number(item: Any) -> int | None:
    try:
        return int(item.ROINumber)
    except PARSE_ERRORS:
        return None


def check_same_subject(
    reference: Any, series: SourceSeries, *, what: str, rois: Collection[int] | None = None
) -> None:
    """Refuse a derived object that belongs to another patient or frame than its images.

    A SEG or RTSTRUCT written from ``reference`` (the input RTSTRUCT) refers to
    the images of ``series``: were they of another patient, or in another frame
    of reference, the new object would be labelled with the wrong patient or
    place its contours in the wrong space.

    Parameters
    ----------
    reference : pydicom.Dataset
        The input object (headers suffice).
    series : SourceSeries
        The images the output will refer to.
    what : str
        The input, for the message.
    rois : collection of int, optional
        The ROINumbers that were read (default: every ROI of ``reference``).

    Raises
    ------
    InputError
        Both have a PatientID and they differ; an ROI of ``reference`` lies in
        another frame of reference than the images; or ``reference`` names
        frames (and no ROI frame) and the images' is not one of them.
    """
    try:
        theirs = str(reference.get("PatientID", "") or "").strip()
        frames_of_rois, listed = reference_frames(reference, rois)
    except PARSE_ERRORS as exc:
        raise FormatError(
            f"{what}: cannot read its patient and frame of reference ({exc})"
        ) from exc
    first = series.first
    ours = str(first.get("PatientID", "") or "").strip()
    label = series_label(first)
    if theirs and ours and theirs != ours:
        raise InputError(
            f"{what} is of patient {theirs!r}, the images it lies on ({label}, {series.name}) of "
            f"patient {ours!r}; a DICOM object referring to those images would be labelled with "
            "the wrong patient"
        )
    frame = series.frame_of_reference_uid
    frames = frames_of_rois - {frame} if frames_of_rois else (set() if frame in listed else listed)
    if frames:
        raise InputError(
            f"{what} lies in frame of reference {', '.join(sorted(frames))}, the images it "
            f"lies on ({label}, {series.name}) in {frame}; their "
            "coordinates do not match, so no DICOM object may refer to both"
        )


def check_label_map(
    labels: ArrayLike, affine: ArrayLike, structures: Sequence[Structure]
) -> tuple[NDArray[np.integer], NDArray[np.float64], list[Structure]]:
    """Validate a label map (or a layered one) and its structures for writing.

    Parameters
    ----------
    labels : array_like of shape (I, J, K) or (L, I, J, K), integer or bool
        Label values, 0 for background; or a layered label map whose layers
        each hold structures that do not overlap (structures that overlap lie
        in different layers, as in 3D Slicer's segmentations), every value in
        one layer only.
    affine : array_like of shape (4, 4)
        Voxel index → LPS mm.
    structures : sequence of Structure
        One per label value to write (positive, distinct values).

    Returns
    -------
    layers : ndarray of shape (L, I, J, K), integer
        The label map as layers (L = 1 for a plain label map).
    affine : ndarray of shape (4, 4)
    structures : list of Structure
        In the order given.

    Raises
    ------
    OptionError
        Not a 3-D or 4-D integer array; no structure, or values not positive and
        distinct.
    LabelError
        Voxels hold a value that no structure describes, or one value lies in
        two layers.
    """
    values = np.asarray(labels)
    if values.dtype == bool:
        values = values.astype(np.uint8)
    if values.ndim not in (3, 4) or values.dtype.kind not in "iu":
        raise OptionError(
            "labels must be a 3-D (or layered 4-D) integer array "
            f"(got {values.dtype} of shape {values.shape})"
        )
    layers = values if values.ndim == 4 else values[np.newaxis]
    aff = check_affine(affine)
    chosen = list(structures)
    if not chosen or not all(isinstance(s, Structure) for s in chosen):
        raise OptionError("structures must be a non-empty sequence of Structure")
    numbers = [s.value for s in chosen]
    if min(numbers) < 1 or len(set(numbers)) != len(numbers):
        raise OptionError(f"structure values must be positive and distinct (got {numbers})")
    owner = layer_of_values(layers)
    unknown = sorted(set(owner) - set(numbers))
    if unknown:
        raise LabelError(
            f"labels hold values {unknown} that no structure describes (structures: "
            f"{sorted(numbers)}); pass a Structure for each value"
        )
    return layers, aff, chosen


def structure_mask(layers: NDArray[np.integer], value: int) -> NDArray[np.bool_]:
    """The voxels of one structure in a layered label map ``(L, I, J, K)``: shape (I, J, K)."""
    if len(layers) == 1:
        return np.asarray(layers[0] == value)
    return np.asarray((layers == value).any(axis=0))


def layers_on_series(
    layers: NDArray[np.integer], affine: NDArray[np.float64], series: SourceSeries
) -> NDArray[np.integer]:
    """:func:`labels_on_series` for each layer of ``(L, I', J', K')``.

    Returns an array of shape ``(L, *series.shape)``.
    """
    return np.stack([labels_on_series(layer, affine, series) for layer in layers])


def dicom_name(structure: Structure) -> str:
    """The structure's name as a DICOM LO value (SegmentLabel, ROIName).

    :func:`~slicerecon.labels.structure_name` (the name every output gives it:
    its own, else ``Segment_<value>``), with what LO cannot hold replaced: a
    backslash (the value separator) by ``/``, control characters by spaces; cut
    to 64 characters with a warning. Accents and other scripts are kept: the
    writers declare SpecificCharacterSet ISO_IR 192 (UTF-8).
    """
    name = structure_name(structure)
    text = "".join(
        "/" if c == "\\" else " " if unicodedata.category(c)[0] == "C" else c for c in name
    )
    text = " ".join(text.split())
    if len(text) > LO_MAX_CHARS:
        logger.warning(
            "structure %d: its name %r is longer than the %d characters DICOM allows; "
            "it is cut to %r in DICOM outputs",
            structure.value,
            name,
            LO_MAX_CHARS,
            text[:LO_MAX_CHARS],
        )
        text = text[:LO_MAX_CHARS].rstrip()
    return text or f"Segment_{structure.value}"


def display_colour(structure: Structure, index: int) -> tuple[int, int, int]:
    """The structure's colour, else the ``index``-th default (``labelmap.structure_colour``)."""
    return structure_colour(structure, index)


def labels_on_series(
    labels: NDArray[np.integer], affine: NDArray[np.float64], series: SourceSeries
) -> NDArray[np.integer]:
    """Place a label map on the grid of an image series.

    Parameters
    ----------
    labels : ndarray of shape (I', J', K'), integer
        A label map whose in-plane pixels are the series' pixels (same row and
        column steps, offset by whole pixels) on planes parallel to its slices.
    affine : ndarray of shape (4, 4)
        Voxel index of ``labels`` → LPS mm.
    series : SourceSeries

    Returns
    -------
    ndarray of shape ``series.shape``, the dtype of ``labels``
        On each image plane, the label plane nearest to it (none beyond half a
        label step outside the label map's planes); voxels outside the label
        map are 0. Foreground that falls outside the series is logged.

    Raises
    ------
    GeometryError
        The label map's grid is not the series' grid in-plane, or its planes
        are not parallel to the series' slices.
    """
    shape = series.shape
    if np.array_equal(np.asarray(labels.shape), shape) and np.allclose(
        affine, series.affine, rtol=0, atol=1e-6 * float(np.abs(series.affine[:3]).max())
    ):
        return labels
    # series index → label index
    m = np.linalg.inv(affine) @ series.affine
    size = float(max(shape[0], shape[1], labels.shape[0], labels.shape[1]))
    in_plane = np.abs(m[:3, :2] - np.eye(3)[:, :2]).max() * size
    if in_plane > GRID_TOLERANCE_PX:
        raise GeometryError(
            f"the label map is not on the grid of {series.name}: its in-plane pixels differ "
            f"(by up to {in_plane:.3g} pixels across the image) or its planes are not "
            "parallel to the image slices; rasterize the reconstruction onto the series' "
            "grid (slicerecon.rasterize.mesh_to_mask with dicom_series_geometry) first"
        )
    out = np.zeros(shape, dtype=labels.dtype)
    lost = int(np.count_nonzero(labels))
    resampled = False
    for k in range(shape[2]):
        i0, j0, kk = m[:3, 2] * k + m[:3, 3]
        di, dj, dk = round(float(i0)), round(float(j0)), round(float(kk))
        if max(abs(i0 - di), abs(j0 - dj)) > GRID_TOLERANCE_PX:
            raise GeometryError(
                f"the label map is not on the grid of {series.name}: on plane {k} its pixels "
                f"are shifted by a fraction of a pixel ({i0 - di:.3g}, {j0 - dj:.3g}); "
                "rasterize the reconstruction onto the series' grid first"
            )
        if not 0 <= dk < labels.shape[2]:
            continue
        resampled |= abs(kk - dk) > GRID_TOLERANCE_PX
        src_i = slice(max(di, 0), min(di + shape[0], labels.shape[0]))
        src_j = slice(max(dj, 0), min(dj + shape[1], labels.shape[1]))
        if src_i.start >= src_i.stop or src_j.start >= src_j.stop:
            continue
        dst = (slice(src_i.start - di, src_i.stop - di), slice(src_j.start - dj, src_j.stop - dj))
        out[dst[0], dst[1], k] = labels[src_i, src_j, dk]
    if resampled:
        logger.info(
            "the label map's planes are not the slices of %s: each image slice takes "
            "the nearest label plane",
            series.name,
        )
    else:
        kept = int(np.count_nonzero(out))
        if kept < lost:
            logger.warning(
                "%d of %d labelled voxels lie outside %s and are not written",
                lost - kept,
                lost,
                series.name,
            )
    return out
