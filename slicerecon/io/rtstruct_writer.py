"""Write a label map as a DICOM RT Structure Set (RTSTRUCT) on its image series.

Each structure becomes one ROI (ROINumber = its value, ROIName, ROIDisplayColor)
whose contours are the boundary of its voxels on every image slice it crosses:

* the polygons are the 0.5 iso-lines of the slice mask
  (:meth:`slicerecon.sections.CrossSections.contours`), in DICOM patient LPS
  mm, CLOSED_PLANAR, the first point not repeated; points in the middle of a
  straight run are left out (the polygon is unchanged);
* holes are separate contours inside their outer contour, and islands in holes
  separate contours again: the even-odd rule that slicerecon's reader
  (:func:`slicerecon.io.rtstruct.read_rtstruct`) and most planning systems
  apply. Rasterized on the image grid by that rule, the contours give the
  slice masks back exactly (no pixel gained or lost);
* each contour refers to the image of its slice (ContourImageSequence), and
  the structure set to the series, its study and frame of reference
  (ReferencedFrameOfReferenceSequence / RTReferencedStudySequence /
  RTReferencedSeriesSequence, listing every image).

With ``reference`` (the RTSTRUCT the reconstruction was made from), the
patient and study identifiers are copied from it, and each ROI keeps the
reference's ROIName, ROIDisplayColor, ROIDescription and RT ROI observation
(RTROIInterpretedType, ROIInterpreter) when the reference has that ROINumber;
the reference is listed as PredecessorStructureSetSequence. Otherwise they
come from the images.

The file is written in Implicit VR Little Endian, the transfer syntax every
DICOM application reads and the one planning systems write structure sets in:
in an explicit-VR file a DS element holds at most 64 KiB, about 5,000 contour
points, and a body outline on a 512 × 512 slice can have more.

Why pydicom and not rt-utils
----------------------------
rt-utils (MIT; PyPI release 1.2.7, with later fixes unreleased) was weighed:
it traces contours with OpenCV through the *centres* of the boundary pixels,
so every structure shrinks by half a pixel all round (a disk of radius 10
pixels loses 11 % of its area, a one-pixel-wide part vanishes); the
released version swaps row and column spacing for non-square pixels; it
places slices at the mean spacing along the normal (a gantry tilt is lost);
it numbers ROIs 1..N (the input's ROINumbers are lost); and it pulls in
opencv-python (~190 MB). The structure set itself is a few dozen attributes
that pydicom writes directly, so slicerecon writes it here, with its own
contours and geometry. See ``docs/formats.md``.
"""

from __future__ import annotations

import datetime as dt
import logging
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .. import __version__
from ..errors import EmptyMaskError, FormatError, InputError
from ..labels import Structure
from ..sections import CrossSections
from .atomic import atomic_path
from .dicom.derived import (
    SourceSeries,
    check_label_map,
    check_same_subject,
    dicom_name,
    display_colour,
    layers_on_series,
    load_source_series,
    structure_mask,
)
from .dicom.sniff import PARSE_ERRORS, object_kind, read_dicom_header

__all__ = ["RTSTRUCT_SOP_CLASS_UID", "write_rtstruct"]

logger = logging.getLogger(__name__)

RTSTRUCT_SOP_CLASS_UID = "1.2.840.10008.5.1.4.1.1.481.3"
"""SOP Class UID of RT Structure Set Storage."""
STUDY_REFERENCE_SOP_CLASS_UID = "1.2.840.10008.3.1.2.3.1"
"""ReferencedSOPClassUID of RTReferencedStudySequence items, as planning systems write it."""

_PATIENT = ("PatientName", "PatientID", "IssuerOfPatientID", "PatientBirthDate", "PatientSex")
_STUDY = (
    "StudyInstanceUID",
    "StudyDate",
    "StudyTime",
    "ReferringPhysicianName",
    "StudyID",
    "AccessionNumber",
    "StudyDescription",
)
_TYPE2 = {
    "PatientName",
    "PatientID",
    "PatientBirthDate",
    "PatientSex",
    "StudyDate",
    "StudyTime",
    "ReferringPhysicianName",
    "StudyID",
    "AccessionNumber",
}


def _ds_text(value: float) -> str:
    """A DS string (at most 16 characters) holding ``value`` to about 10 significant digits."""
    if abs(value) < 1e-9:
        return "0"
    for digits in range(10, 5, -1):
        text = f"{value:.{digits}g}"
        if len(text) <= 16:
            return text
    return f"{value:.6g}"  # pragma: no cover - unreachable for coordinates below 1e6 mm


def _drop_collinear(points: NDArray[np.float64]) -> NDArray[np.float64]:
    """A closed polygon without the vertices in the middle of straight runs."""
    before = points - np.roll(points, 1, axis=0)
    after = np.roll(points, -1, axis=0) - points
    cross = before[:, 0] * after[:, 1] - before[:, 1] * after[:, 0]
    straight = (np.abs(cross) <= 1e-9) & (np.einsum("ij,ij->i", before, after) > 0)
    kept = points[~straight]
    return kept if kept.shape[0] >= 3 else points


def _roi_polygons(
    mask: NDArray[np.bool_], series: SourceSeries
) -> list[tuple[int, NDArray[np.float64]]]:
    """Boundary polygons of ``mask`` on every image slice: ``(image number, (N, 3) LPS mm)``."""
    occupied = [n for n, k in enumerate(series.planes) if mask[:, :, k].any()]
    if not occupied:
        return []
    planes = series.planes[occupied]
    sections = CrossSections(
        np.moveaxis(mask[:, :, planes], 2, 0),
        planes.astype(np.float64),
        2,
        series.affine,
        series.shape,
    )
    out: list[tuple[int, NDArray[np.float64]]] = []
    for p, n in enumerate(occupied):
        for contour in sections.contours(p):
            out.append((n, series.image_to_world(n, _drop_collinear(contour.points_px))))
    return out


def _sequence(items: Sequence[Any]) -> Any:
    from pydicom.sequence import Sequence as DicomSequence

    return DicomSequence(list(items))


def _image_reference(image: Any) -> Any:
    from pydicom.dataset import Dataset

    item = Dataset()
    item.ReferencedSOPClassUID = str(image.SOPClassUID)
    item.ReferencedSOPInstanceUID = str(image.SOPInstanceUID)
    return item


def _contour_item(number: int, image: Any, points: NDArray[np.float64]) -> Any:
    from pydicom.dataset import Dataset

    item = Dataset()
    item.ContourImageSequence = _sequence([_image_reference(image)])
    item.ContourGeometricType = "CLOSED_PLANAR"
    item.NumberOfContourPoints = int(points.shape[0])
    item.ContourNumber = number
    item.ContourData = [_ds_text(float(v)) for v in points.ravel()]
    return item


def _read_reference(reference: Any) -> Any:
    """The reference RTSTRUCT dataset (from a dataset or a path)."""
    if isinstance(reference, (str, os.PathLike)):
        path = Path(reference)
        if not path.is_file():
            raise InputError(f"reference RTSTRUCT not found: {path}")
        ds = read_dicom_header(path, stop_before_pixels=True)
        where = str(path)
    else:
        ds, where = reference, "the reference dataset"
    if object_kind(ds) != "rtstruct":
        raise InputError(
            f"{where} is not an RTSTRUCT (Modality "
            f"{ds.get('Modality', '') or 'missing'}); pass the input structure set"
        )
    return ds


def _reference_name(reference: Any) -> str:
    if isinstance(reference, (str, os.PathLike)):
        return f"the reference RTSTRUCT {Path(reference)}"
    return "the reference RTSTRUCT"


def _reference_rois(
    ref: Any,
) -> tuple[dict[int, Any], dict[int, tuple[int, int, int]], dict[int, Any]]:
    """The reference's StructureSetROI items, colours and RT ROI observations by ROINumber."""
    try:
        rois = {
            int(item.ROINumber): item
            for item in ref.get("StructureSetROISequence", [])
            if "ROINumber" in item
        }
        colours: dict[int, tuple[int, int, int]] = {}
        for item in ref.get("ROIContourSequence", []):
            colour = item.get("ROIDisplayColor")
            if "ReferencedROINumber" in item and colour is not None and len(colour) == 3:
                r, g, b = (int(c) for c in colour)
                colours[int(item.ReferencedROINumber)] = (r, g, b)
        observations = {
            int(item.ReferencedROINumber): item
            for item in ref.get("RTROIObservationsSequence", [])
            if "ReferencedROINumber" in item
        }
    except PARSE_ERRORS as exc:
        raise FormatError(f"the reference RTSTRUCT has malformed ROI items ({exc})") from exc
    return rois, colours, observations


def _copy_identifiers(ds: Any, source: Any) -> None:
    for keyword in (*_PATIENT, *_STUDY):
        try:
            value = source[keyword].value if keyword in source else None
        except PARSE_ERRORS as exc:
            raise FormatError(
                f"{keyword} of {getattr(source, 'filename', None) or 'the source'} cannot be "
                f"read ({type(exc).__name__}: {exc})"
            ) from exc
        if value not in (None, ""):
            setattr(ds, keyword, value)
        elif keyword in _TYPE2:
            setattr(ds, keyword, "")


def write_rtstruct(
    labels: ArrayLike,
    affine: ArrayLike,
    structures: Sequence[Structure],
    source_images: str | os.PathLike[str] | Sequence[Any] | SourceSeries,
    path: str | os.PathLike[str],
    *,
    reference: Any = None,
    allow_irregular: bool = False,
    series_number: int = 902,
    series_description: str = "slicerecon reconstruction",
    structure_set_label: str = "SLICERECON",
) -> Path:
    """Write a label map as an RTSTRUCT: one ROI per structure, contours on every image slice.

    Parameters
    ----------
    labels : array_like of shape (I, J, K) or (L, I, J, K), integer
        Label values, 0 for background, on the grid of the image series
        (array axes (column, row, slice), as :func:`read_dicom_series` reads
        it), or on a grid sharing its in-plane pixels and slice direction
        (:func:`~slicerecon.io.dicom.derived.labels_on_series`); or a layered
        label map whose structures overlap across layers: each ROI is
        contoured whole (:func:`~slicerecon.io.dicom.derived.check_label_map`).
    affine : array_like of shape (4, 4)
        Voxel index of ``labels`` → DICOM patient LPS mm.
    structures : sequence of Structure
        One per label value (every non-zero value of ``labels`` needs one), in
        the order the ROIs are listed. ROINumber is the value; ROIName the
        name (else ``"Segment_<value>"``, as in every output:
        :func:`~slicerecon.io.dicom.derived.dicom_name`); ROIDisplayColor the colour (else
        one of :data:`~slicerecon.labels.DEFAULT_COLOURS`). A
        structure without voxels becomes an ROI without contours.
    source_images : path-like, sequence of pydicom.Dataset or path-like, or SourceSeries
        The image series: its directory, or its images (datasets, headers
        suffice, or file paths) in any order, or the series already loaded
        (:func:`~slicerecon.io.dicom.derived.load_source_series`).
    path : path-like
        Output file, written atomically (temporary file, then rename).
    reference : pydicom.Dataset or path-like, optional
        The RTSTRUCT the structures were read from: its patient and study
        identifiers are copied, and its ROIName, ROIDisplayColor,
        ROIDescription and RT ROI observation win for the ROINumbers it has.
        It must be of the images' patient (PatientID) and frame of reference.
    allow_irregular : bool
        Accept an image series with uneven slice spacing (``--allow-irregular``).
    series_number : int
        SeriesNumber of the new RTSTRUCT series.
    series_description : str
        SeriesDescription of the new RTSTRUCT series.
    structure_set_label : str
        StructureSetLabel (at most 16 characters).

    Returns
    -------
    Path
        The file written.

    Raises
    ------
    OptionError, LabelError
        Bad labels or structures (:func:`~slicerecon.io.dicom.derived.check_label_map`).
    InputError, FormatError, GeometryError
        The image series or the reference cannot be read, the reference is of
        another patient or frame of reference than the images
        (:func:`~slicerecon.io.dicom.derived.check_same_subject`), or the label
        map is not on the series' grid.
    EmptyMaskError
        No structure holds a voxel on the series' images.
    """
    from pydicom.dataset import Dataset, FileMetaDataset
    from pydicom.uid import UID, ImplicitVRLittleEndian, generate_uid

    values, aff, chosen = check_label_map(labels, affine, structures)
    series = load_source_series(source_images, allow_irregular=allow_irregular)
    ref = None if reference is None else _read_reference(reference)
    if ref is not None:
        check_same_subject(
            ref, series, what=_reference_name(reference), rois=[s.value for s in chosen]
        )
    on_grid = layers_on_series(values, aff, series)

    ref_rois, ref_colours, ref_observations = (
        _reference_rois(ref) if ref is not None else ({}, {}, {})
    )
    now = dt.datetime.now()
    date, time = now.strftime("%Y%m%d"), now.strftime("%H%M%S.%f")
    sop_uid = generate_uid()
    ds = Dataset()
    ds.file_meta = FileMetaDataset()
    ds.file_meta.MediaStorageSOPClassUID = UID(RTSTRUCT_SOP_CLASS_UID)
    ds.file_meta.MediaStorageSOPInstanceUID = sop_uid
    ds.file_meta.TransferSyntaxUID = ImplicitVRLittleEndian
    ds.SpecificCharacterSet = "ISO_IR 192"
    ds.InstanceCreationDate, ds.InstanceCreationTime = date, time
    ds.SOPClassUID = RTSTRUCT_SOP_CLASS_UID
    ds.SOPInstanceUID = sop_uid
    _copy_identifiers(ds, ref if ref is not None else series.first)
    if ref is not None and str(ds.StudyInstanceUID) != series.study_instance_uid:
        logger.warning(
            "the reference RTSTRUCT is in study %s, the images in study %s; the "
            "structure set takes the reference's",
            ds.StudyInstanceUID,
            series.study_instance_uid,
        )
    ds.Modality = "RTSTRUCT"
    ds.SeriesInstanceUID = generate_uid()
    ds.SeriesNumber = series_number
    ds.SeriesDescription = series_description
    ds.SeriesDate, ds.SeriesTime = date, time
    ds.OperatorsName = ""
    ds.Manufacturer = "slicerecon"
    ds.ManufacturerModelName = "slicerecon"
    ds.SoftwareVersions = str(__version__)
    ds.InstanceNumber = 1
    ds.StructureSetLabel = structure_set_label[:16]
    ds.StructureSetName = "slicerecon reconstruction"
    ds.StructureSetDescription = "surfaces reconstructed from cross-sections, on every image slice"
    ds.StructureSetDate, ds.StructureSetTime = date, time

    frame_uid = series.frame_of_reference_uid
    # the Frame of Reference module (Type 1 UID, Type 2 indicator) of the RT Structure Set IOD
    ds.FrameOfReferenceUID = frame_uid
    ds.PositionReferenceIndicator = str(series.first.get("PositionReferenceIndicator", "") or "")
    if ref is not None:
        predecessor = Dataset()
        predecessor.ReferencedSOPClassUID = str(ref.get("SOPClassUID", RTSTRUCT_SOP_CLASS_UID))
        predecessor.ReferencedSOPInstanceUID = str(ref.get("SOPInstanceUID", ""))
        if predecessor.ReferencedSOPInstanceUID:
            ds.PredecessorStructureSetSequence = _sequence([predecessor])

    referenced_series = Dataset()
    referenced_series.SeriesInstanceUID = series.series_instance_uid
    referenced_series.ContourImageSequence = _sequence(
        [_image_reference(image) for image in series.images]
    )
    referenced_study = Dataset()
    referenced_study.ReferencedSOPClassUID = STUDY_REFERENCE_SOP_CLASS_UID
    referenced_study.ReferencedSOPInstanceUID = series.study_instance_uid
    referenced_study.RTReferencedSeriesSequence = _sequence([referenced_series])
    frame = Dataset()
    frame.FrameOfReferenceUID = frame_uid
    frame.RTReferencedStudySequence = _sequence([referenced_study])
    ds.ReferencedFrameOfReferenceSequence = _sequence([frame])

    roi_items, contour_items, observation_items = [], [], []
    written = 0
    for index, structure in enumerate(chosen):
        number = structure.value
        ref_roi = ref_rois.get(number)
        ref_name = str(ref_roi.get("ROIName", "") or "") if ref_roi is not None else ""
        name = ref_name or dicom_name(structure)
        colour = ref_colours.get(number) or display_colour(structure, index)

        roi = Dataset()
        roi.ROINumber = number
        roi.ReferencedFrameOfReferenceUID = frame_uid
        roi.ROIName = name
        if ref_roi is not None and ref_roi.get("ROIDescription"):
            roi.ROIDescription = ref_roi.ROIDescription
        roi.ROIGenerationAlgorithm = "SEMIAUTOMATIC"
        roi.ROIGenerationDescription = (
            f"slicerecon {__version__}: surface reconstructed from cross-sections"
        )
        roi_items.append(roi)

        holder = Dataset()
        holder.ROIDisplayColor = list(colour)
        polygons = _roi_polygons(structure_mask(on_grid, number), series)
        if polygons:
            holder.ContourSequence = _sequence(
                [
                    _contour_item(c, series.images[n], points)
                    for c, (n, points) in enumerate(polygons, start=1)
                ]
            )
            written += 1
        else:
            # a structure without any voxel (an input ROI without contours) was said by
            # whoever made the label map; one with voxels beyond the images is news
            say = logger.warning if np.any(values == number) else logger.info
            say(
                "structure %d (%s) holds no voxel on the images; its ROI has no contour",
                number,
                name,
            )
        holder.ReferencedROINumber = number
        contour_items.append(holder)

        observation = Dataset()
        observation.ObservationNumber = number
        observation.ReferencedROINumber = number
        ref_observation = ref_observations.get(number)
        observation.RTROIInterpretedType = (
            ""
            if ref_observation is None
            else str(ref_observation.get("RTROIInterpretedType", "") or "")
        )
        observation.ROIInterpreter = (
            "" if ref_observation is None else (ref_observation.get("ROIInterpreter", "") or "")
        )
        observation_items.append(observation)
    if not written:
        raise EmptyMaskError(
            f"no structure holds a voxel on the images of {series.name}: "
            "there is nothing to write in an RTSTRUCT"
        )
    ds.StructureSetROISequence = _sequence(roi_items)
    ds.ROIContourSequence = _sequence(contour_items)
    ds.RTROIObservationsSequence = _sequence(observation_items)
    ds.ApprovalStatus = "UNAPPROVED"

    target = Path(path)
    with atomic_path(target) as tmp:
        ds.save_as(tmp, enforce_file_format=True)
    logger.info(
        "wrote RTSTRUCT %s: %d ROIs (%d with contours) on %s",
        target,
        len(roi_items),
        written,
        series.name,
    )
    return target
