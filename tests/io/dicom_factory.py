"""Write small synthetic DICOM files for tests: image series of a mask and DICOM SEG.

Nothing here is downloaded; every file is built with pydicom from an array and an
affine, so a test knows the exact geometry it should read back.

Geometry convention (the one :mod:`slicerecon.io.dicom` reads)
---------------------------------------------------------------
``mask`` has array axes ``(I, J, K)`` = (DICOM column index, row index, slice
index), and ``affine`` maps ``(i, j, k, 1)`` to DICOM patient coordinates (LPS, mm):

* ``affine[:3, 0] = row_cosine * PixelSpacing[1]`` (step from one column to the next),
* ``affine[:3, 1] = column_cosine * PixelSpacing[0]`` (step from one row to the next),
* ``affine[:3, 2]`` = step from one slice's ImagePositionPatient to the next,
* ``affine[:3, 3]`` = ImagePositionPatient of slice 0.

Slice ``k`` is stored with ``pixel_array = mask[:, :, k].T`` (shape ``(J, I)`` =
``(Rows, Columns)``). The reader sorts slices along ``cross(row, column)``; a
round trip gives the same arrays back only when ``affine[:3, 2]`` points to that
side (``det(affine[:3, :3]) > 0``); otherwise the reader returns the same world
geometry with the slice axis reversed.

Use from a test module: ``tests/io`` is on pytest's ``pythonpath``
(``pyproject.toml``), so ``import dicom_factory as factory``.

Public API
----------
``write_series(directory, mask, affine, *, ...) -> list[Path]``
    One file per slice, returned in slice-index order.
``write_seg(path, segments, affine, *, labels, ...) -> Path``
    One multi-frame DICOM SEG (BINARY or FRACTIONAL).
``affine_from_geometry(row_cosine, column_cosine, pixel_spacing, slice_step, origin)``
    Build the affine above from DICOM terms.
``read_uids(paths) -> list[str]``
    The SOPInstanceUIDs of files (e.g. those ``write_series`` returned).
``write_rtstruct(path, rois, *, preamble=True) -> Path``
    An RT Structure Set; ``contour_item`` and ``circle`` build its contours.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pydicom
from numpy.typing import ArrayLike, NDArray
from pydicom.datadict import tag_for_keyword
from pydicom.dataset import Dataset, FileMetaDataset
from pydicom.pixels import pack_bits
from pydicom.sequence import Sequence as DicomSequence
from pydicom.uid import ExplicitVRLittleEndian, generate_uid

__all__ = [
    "CT_IMAGE_STORAGE",
    "MR_IMAGE_STORAGE",
    "RTSTRUCT_STORAGE",
    "SEG_STORAGE",
    "affine_from_geometry",
    "circle",
    "contour_item",
    "read_uids",
    "write_rtstruct",
    "write_seg",
    "write_series",
]

MR_IMAGE_STORAGE = "1.2.840.10008.5.1.4.1.1.4"
CT_IMAGE_STORAGE = "1.2.840.10008.5.1.4.1.1.2"
SEG_STORAGE = "1.2.840.10008.5.1.4.1.1.66.4"
_SOP_CLASS_BY_MODALITY = {"MR": MR_IMAGE_STORAGE, "CT": CT_IMAGE_STORAGE}


def affine_from_geometry(
    row_cosine: ArrayLike,
    column_cosine: ArrayLike,
    pixel_spacing: ArrayLike,
    slice_step: ArrayLike,
    origin: ArrayLike,
) -> NDArray[np.float64]:
    """Build the voxel → LPS mm affine from DICOM terms.

    Parameters
    ----------
    row_cosine, column_cosine : array_like of shape (3,)
        The two halves of ImageOrientationPatient (normalised here).
    pixel_spacing : array_like of shape (2,)
        DICOM PixelSpacing ``[between rows, between columns]``, mm.
    slice_step : array_like of shape (3,)
        ImagePositionPatient[k + 1] - ImagePositionPatient[k], mm.
    origin : array_like of shape (3,)
        ImagePositionPatient of slice 0, mm.

    Returns
    -------
    ndarray of shape (4, 4)
    """
    row = np.asarray(row_cosine, dtype=np.float64)
    col = np.asarray(column_cosine, dtype=np.float64)
    spacing = np.asarray(pixel_spacing, dtype=np.float64)
    affine = np.eye(4)
    affine[:3, 0] = row / np.linalg.norm(row) * spacing[1]
    affine[:3, 1] = col / np.linalg.norm(col) * spacing[0]
    affine[:3, 2] = np.asarray(slice_step, dtype=np.float64)
    affine[:3, 3] = np.asarray(origin, dtype=np.float64)
    return affine


def _ds(values: ArrayLike) -> list[str]:
    """Format floats as DICOM DS strings (at most 16 characters each)."""
    out = []
    for value in np.asarray(values, dtype=np.float64).ravel():
        text = f"{value:.10g}"
        if len(text) > 16:
            text = f"{value:.8e}"
        out.append(text)
    return out


def _orientation(affine: NDArray[np.float64]) -> tuple[NDArray, NDArray, NDArray]:
    """Row cosine, column cosine and PixelSpacing ``[rows, columns]`` of an affine."""
    col0, col1 = affine[:3, 0], affine[:3, 1]
    s0, s1 = float(np.linalg.norm(col0)), float(np.linalg.norm(col1))
    if abs(float(np.dot(col0 / s0, col1 / s1))) > 1e-6:
        raise ValueError("affine's first two columns must be orthogonal (DICOM pixels are square)")
    return col0 / s0, col1 / s1, np.array([s1, s0])


def _file_meta(sop_class: str, sop_instance: str) -> FileMetaDataset:
    meta = FileMetaDataset()
    meta.MediaStorageSOPClassUID = sop_class
    meta.MediaStorageSOPInstanceUID = sop_instance
    meta.TransferSyntaxUID = ExplicitVRLittleEndian
    meta.ImplementationClassUID = generate_uid(entropy_srcs=["slicerecon-tests"])
    return meta


def _patient_study(
    ds: Dataset, study_uid: str, frame_of_reference_uid: str, patient_id: str = "SLICERECON-TEST"
) -> None:
    ds.PatientName = "Synthetic^Phantom"
    ds.PatientID = patient_id
    ds.PatientBirthDate = ""
    ds.PatientSex = "O"
    ds.StudyInstanceUID = study_uid
    ds.StudyDate = "20240101"
    ds.StudyTime = "120000"
    ds.StudyID = "1"
    ds.AccessionNumber = ""
    ds.ReferringPhysicianName = ""
    ds.FrameOfReferenceUID = frame_of_reference_uid
    ds.PositionReferenceIndicator = ""


def read_uids(paths: Sequence[Path]) -> list[str]:
    """Return the SOPInstanceUID of each file, in the order given."""
    return [
        str(
            pydicom.dcmread(
                p, stop_before_pixels=True, specific_tags=["SOPInstanceUID"]
            ).SOPInstanceUID
        )
        for p in paths
    ]


def write_series(
    directory: str | Path,
    mask: ArrayLike,
    affine: ArrayLike,
    *,
    modality: str = "MR",
    irregular_positions: Sequence[float] | None = None,
    instance_numbers: Sequence[int] | None = None,
    file_names: Sequence[str] | None = None,
    orientation_overrides: Mapping[int, Sequence[float]] | None = None,
    rescale: tuple[float, float] | None = None,
    series_uid: str | None = None,
    study_uid: str | None = None,
    frame_of_reference_uid: str | None = None,
    series_description: str | None = None,
    patient_id: str = "SLICERECON-TEST",
) -> list[Path]:
    """Write ``mask`` as a single-frame image series, one file per slice.

    Parameters
    ----------
    directory : path-like
        Created if missing. Files are written into it directly.
    mask : array_like of shape (I, J, K)
        Boolean or integer values (label maps are fine); stored as unsigned 16-bit
        pixels, ``Rows = J``, ``Columns = I``.
    affine : array_like of shape (4, 4)
        Voxel → LPS mm, see the module docstring. Columns 0 and 1 must be orthogonal.
    modality : {"MR", "CT"}
        Modality and SOP class (MR / CT Image Storage).
    irregular_positions : sequence of K floats, optional
        Distance of each slice from slice 0 along ``affine[:3, 2]``, mm: slice ``k``
        gets ``IPP = origin + irregular_positions[k] * unit(affine[:3, 2])``.
        Default: ``IPP = origin + k * affine[:3, 2]``.
    instance_numbers : sequence of K ints, optional
        InstanceNumber of each slice (default ``1..K``); pass a permutation to
        check that readers do not sort by it.
    file_names : sequence of K str, optional
        File name of each slice (default ``slice_0000.dcm``, ...).
    orientation_overrides : mapping of int to 6 floats, optional
        Replace ImageOrientationPatient of the given slices (to build bad series).
    rescale : (slope, intercept), optional
        Write RescaleSlope / RescaleIntercept; stored pixels are
        ``round((value - intercept) / slope)`` and must fit in ``[0, 65535]``.
    series_uid, study_uid, frame_of_reference_uid : str, optional
        UIDs to use (default: fresh ones). Give the same ``study_uid`` and
        ``frame_of_reference_uid`` to put two series in one study.
    series_description : str, optional
        SeriesDescription (default: none written).
    patient_id : str
        PatientID.

    Returns
    -------
    list of Path
        The files, in slice-index order ``k = 0 .. K-1``.
    """
    values = np.asarray(mask)
    if values.ndim != 3:
        raise ValueError(f"mask must be 3-D (got shape {values.shape})")
    aff = np.asarray(affine, dtype=np.float64)
    n_cols, n_rows, n_slices = values.shape
    row_cos, col_cos, pixel_spacing = _orientation(aff)
    iop = np.concatenate([row_cos, col_cos])
    step = aff[:3, 2]
    if irregular_positions is None:
        ipps = [aff[:3, 3] + k * step for k in range(n_slices)]
    else:
        if len(irregular_positions) != n_slices:
            raise ValueError("irregular_positions needs one value per slice")
        unit = step / np.linalg.norm(step)
        ipps = [aff[:3, 3] + float(d) * unit for d in irregular_positions]
    numbers = (
        list(instance_numbers) if instance_numbers is not None else list(range(1, n_slices + 1))
    )
    names = (
        list(file_names)
        if file_names is not None
        else [f"slice_{k:04d}.dcm" for k in range(n_slices)]
    )
    if len(numbers) != n_slices or len(names) != n_slices:
        raise ValueError("instance_numbers and file_names need one entry per slice")
    overrides = dict(orientation_overrides or {})

    if rescale is not None:
        slope, intercept = rescale
        raw = np.rint((values.astype(np.float64) - intercept) / slope)
    else:
        raw = values.astype(np.float64)
    if raw.min() < 0 or raw.max() > 65535:
        raise ValueError("stored pixel values must fit in unsigned 16 bits")
    raw16 = raw.astype(np.uint16)

    sop_class = _SOP_CLASS_BY_MODALITY[modality]
    series_uid = series_uid or generate_uid()
    study_uid = study_uid or generate_uid()
    frame_of_reference_uid = frame_of_reference_uid or generate_uid()
    out_dir = Path(directory)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    for k in range(n_slices):
        sop_uid = generate_uid()
        ds = Dataset()
        ds.file_meta = _file_meta(sop_class, sop_uid)
        ds.SOPClassUID = sop_class
        ds.SOPInstanceUID = sop_uid
        ds.Modality = modality
        _patient_study(ds, study_uid, frame_of_reference_uid, patient_id)
        ds.SeriesInstanceUID = series_uid
        if series_description is not None:
            ds.SeriesDescription = series_description
        ds.SeriesNumber = 1
        ds.InstanceNumber = int(numbers[k])
        ds.ImageType = ["DERIVED", "PRIMARY"]
        ds.ImagePositionPatient = _ds(ipps[k])
        ds.ImageOrientationPatient = _ds(overrides.get(k, iop))
        ds.PixelSpacing = _ds(pixel_spacing)
        ds.SliceThickness = _ds([np.linalg.norm(step)])[0]
        ds.SliceLocation = _ds([np.dot(ipps[k], np.cross(row_cos, col_cos))])[0]
        ds.Rows = n_rows
        ds.Columns = n_cols
        ds.SamplesPerPixel = 1
        ds.PhotometricInterpretation = "MONOCHROME2"
        ds.BitsAllocated = 16
        ds.BitsStored = 16
        ds.HighBit = 15
        ds.PixelRepresentation = 0
        if rescale is not None:
            ds.RescaleSlope = _ds([rescale[0]])[0]
            ds.RescaleIntercept = _ds([rescale[1]])[0]
            ds.RescaleType = "US"
        ds.PixelData = np.ascontiguousarray(raw16[:, :, k].T).tobytes()
        path = out_dir / names[k]
        ds.save_as(path, enforce_file_format=True)
        paths.append(path)
    return paths


def write_seg(
    path: str | Path,
    segments: Mapping[int, ArrayLike],
    affine: ArrayLike,
    *,
    labels: Mapping[int, str],
    fractional: bool = False,
    omit_empty_frames: bool = True,
    dimension_index: bool = True,
    series_uid: str | None = None,
    study_uid: str | None = None,
    frame_of_reference_uid: str | None = None,
) -> Path:
    """Write a multi-frame DICOM SEG (Segmentation Storage) file.

    Parameters
    ----------
    path : path-like
        Output file; its directory is created if missing.
    segments : mapping of int to array_like of shape (I, J, K)
        Segment number (1, 2, ...) → mask on the grid of ``affine``. Boolean for
        BINARY; for ``fractional=True`` floats in ``[0, 1]`` (stored as ``round(255 v)``).
    affine : array_like of shape (4, 4)
        Voxel → LPS mm, see the module docstring.
    labels : mapping of int to str
        SegmentLabel of each segment number.
    fractional : bool
        Write SegmentationType FRACTIONAL (8-bit, MaximumFractionalValue 255)
        instead of BINARY (1-bit packed frames).
    omit_empty_frames : bool
        Skip frames with no foreground, as most SEG writers do (so a segment's
        frames need not cover every slice).
    dimension_index : bool
        Write the Multi-frame Dimension module (DimensionIndexSequence indexing
        frames by ReferencedSegmentNumber and ImagePositionPatient), as the
        standard requires and highdicom, dcmqi and 3D Slicer write it. False
        leaves it out, as some older exporters do.
    series_uid, study_uid, frame_of_reference_uid : str, optional
        UIDs to use (default: fresh ones).

    Returns
    -------
    Path
        The file written. Frames are ordered by segment number, then slice index;
        per-frame PlanePositionSequence holds ``origin + k * affine[:3, 2]``.
    """
    aff = np.asarray(affine, dtype=np.float64)
    arrays = {int(n): np.asarray(a) for n, a in segments.items()}
    shapes = {a.shape for a in arrays.values()}
    if len(shapes) != 1 or len(next(iter(shapes))) != 3:
        raise ValueError(f"segments must be 3-D arrays of one shape (got {shapes})")
    n_cols, n_rows, n_slices = next(iter(shapes))
    row_cos, col_cos, pixel_spacing = _orientation(aff)
    step = aff[:3, 2]
    normal = np.cross(row_cos, col_cos)

    frames: list[NDArray] = []
    per_frame = []
    for number in sorted(arrays):
        values = arrays[number].astype(np.float64)
        for k in range(n_slices):
            frame = values[:, :, k].T
            if omit_empty_frames and not np.any(frame > 0):
                continue
            if fractional:
                frames.append(np.rint(np.clip(frame, 0, 1) * 255).astype(np.uint8))
            else:
                frames.append((frame > 0).astype(np.uint8))
            item = Dataset()
            ident = Dataset()
            ident.ReferencedSegmentNumber = number
            item.SegmentIdentificationSequence = DicomSequence([ident])
            position = Dataset()
            position.ImagePositionPatient = _ds(aff[:3, 3] + k * step)
            item.PlanePositionSequence = DicomSequence([position])
            content = Dataset()
            content.DimensionIndexValues = [number, k + 1]
            item.FrameContentSequence = DicomSequence([content])
            per_frame.append(item)
    if not frames:
        raise ValueError("no frame to write: every segment is empty")

    sop_uid = generate_uid()
    ds = Dataset()
    ds.file_meta = _file_meta(SEG_STORAGE, sop_uid)
    ds.SOPClassUID = SEG_STORAGE
    ds.SOPInstanceUID = sop_uid
    ds.Modality = "SEG"
    _patient_study(ds, study_uid or generate_uid(), frame_of_reference_uid or generate_uid())
    ds.SeriesInstanceUID = series_uid or generate_uid()
    ds.SeriesNumber = 100
    ds.InstanceNumber = 1
    ds.ImageType = ["DERIVED", "PRIMARY"]
    ds.ContentLabel = "SYNTHETIC"
    ds.ContentDescription = "slicerecon test segmentation"
    ds.ContentCreatorName = "slicerecon^tests"
    ds.SegmentationType = "FRACTIONAL" if fractional else "BINARY"
    if fractional:
        ds.SegmentationFractionalType = "PROBABILITY"
        ds.MaximumFractionalValue = 255

    seg_items = []
    for number in sorted(arrays):
        item = Dataset()
        item.SegmentNumber = number
        item.SegmentLabel = labels[number]
        item.SegmentAlgorithmType = "MANUAL"
        category = Dataset()
        category.CodeValue = "T-D000A"
        category.CodingSchemeDesignator = "SRT"
        category.CodeMeaning = "Anatomical Structure"
        item.SegmentedPropertyCategoryCodeSequence = DicomSequence([category])
        kind = Dataset()
        kind.CodeValue = "T-D0050"
        kind.CodingSchemeDesignator = "SRT"
        kind.CodeMeaning = "Tissue"
        item.SegmentedPropertyTypeCodeSequence = DicomSequence([kind])
        seg_items.append(item)
    ds.SegmentSequence = DicomSequence(seg_items)

    shared = Dataset()
    orientation = Dataset()
    orientation.ImageOrientationPatient = _ds(np.concatenate([row_cos, col_cos]))
    shared.PlaneOrientationSequence = DicomSequence([orientation])
    measures = Dataset()
    measures.PixelSpacing = _ds(pixel_spacing)
    measures.SliceThickness = _ds([abs(np.dot(step, normal))])[0]
    measures.SpacingBetweenSlices = _ds([abs(np.dot(step, normal))])[0]
    shared.PixelMeasuresSequence = DicomSequence([measures])
    ds.SharedFunctionalGroupsSequence = DicomSequence([shared])
    ds.PerFrameFunctionalGroupsSequence = DicomSequence(per_frame)
    if dimension_index:
        organization = generate_uid()
        dimension_items = []
        for index, group in (
            ("ReferencedSegmentNumber", "SegmentIdentificationSequence"),
            ("ImagePositionPatient", "PlanePositionSequence"),
        ):
            item = Dataset()
            item.DimensionOrganizationUID = organization
            item.DimensionIndexPointer = tag_for_keyword(index)
            item.FunctionalGroupPointer = tag_for_keyword(group)
            dimension_items.append(item)
        ds.DimensionIndexSequence = DicomSequence(dimension_items)
        organization_item = Dataset()
        organization_item.DimensionOrganizationUID = organization
        ds.DimensionOrganizationSequence = DicomSequence([organization_item])

    ds.NumberOfFrames = len(frames)
    ds.Rows = n_rows
    ds.Columns = n_cols
    ds.SamplesPerPixel = 1
    ds.PhotometricInterpretation = "MONOCHROME2"
    ds.PixelRepresentation = 0
    ds.LossyImageCompression = "00"
    stack = np.stack(frames)
    if fractional:
        ds.BitsAllocated = 8
        ds.BitsStored = 8
        ds.HighBit = 7
        ds.PixelData = stack.tobytes()
    else:
        ds.BitsAllocated = 1
        ds.BitsStored = 1
        ds.HighBit = 0
        ds.PixelData = pack_bits(stack.ravel(), pad=True)

    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    ds.save_as(out, enforce_file_format=True)
    return out


RTSTRUCT_STORAGE = "1.2.840.10008.5.1.4.1.1.481.3"


def contour_item(
    points: ArrayLike, *, kind: str = "CLOSED_PLANAR", image_uid: str | None = None
) -> Dataset:
    """One ContourSequence item: ``points`` of shape (N, 3), LPS mm."""
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    item = Dataset()
    item.ContourGeometricType = kind
    item.NumberOfContourPoints = len(pts)
    item.ContourData = _ds(pts)
    if image_uid:
        ref = Dataset()
        ref.ReferencedSOPClassUID = MR_IMAGE_STORAGE
        ref.ReferencedSOPInstanceUID = image_uid
        item.ContourImageSequence = DicomSequence([ref])
    return item


def circle(radius: float, centre: Sequence[float], z: float, n: int = 180) -> NDArray:
    """A counter-clockwise ``n``-gon of radius ``radius`` mm on the axial plane ``z``."""
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    return np.c_[centre[0] + radius * np.cos(t), centre[1] + radius * np.sin(t), np.full(n, z)]


def write_rtstruct(
    path: str | Path,
    rois: Mapping[tuple[int, str], Sequence[Dataset] | None],
    *,
    modality: str = "RTSTRUCT",
    preamble: bool = True,
    on_series: str | Path | None = None,
    patient_id: str | None = None,
) -> Path:
    """Write an RTSTRUCT; ``rois`` maps (ROINumber, ROIName) to contour items, or None
    for an ROI without a ContourSequence. ``preamble=False`` writes a bare dataset
    without the 128-byte preamble and file meta, as older systems do.

    ``on_series`` (a directory written by :func:`write_series`): take its patient,
    study and FrameOfReferenceUID, as an RTSTRUCT drawn on that series has; otherwise
    they are fresh. ``patient_id`` overrides the PatientID. Names that are not ASCII
    are written in UTF-8 (SpecificCharacterSet ISO_IR 192)."""
    sop_uid = generate_uid()
    ds = Dataset()
    ds.file_meta = _file_meta(RTSTRUCT_STORAGE, sop_uid)
    if any(not name.isascii() for _, name in rois):
        ds.SpecificCharacterSet = "ISO_IR 192"
    ds.SOPClassUID = RTSTRUCT_STORAGE
    ds.SOPInstanceUID = sop_uid
    ds.Modality = modality
    ds.PatientName = "Synthetic^Phantom"
    ds.PatientID = "SLICERECON-TEST"
    ds.StudyInstanceUID = generate_uid()
    frame_uid = generate_uid()
    if on_series is not None:
        image = next(
            ds
            for ds in (
                pydicom.dcmread(f, stop_before_pixels=True)
                for f in sorted(Path(on_series).glob("*.dcm"))
            )
            if "ImagePositionPatient" in ds
        )
        ds.PatientName, ds.PatientID = image.PatientName, image.PatientID
        ds.StudyInstanceUID = image.StudyInstanceUID
        frame_uid = image.FrameOfReferenceUID
    if patient_id is not None:
        ds.PatientID = patient_id
    ds.SeriesInstanceUID = generate_uid()
    ds.StructureSetLabel = "test"
    roi_items, contour_items = [], []
    for (number, name), contours in rois.items():
        roi = Dataset()
        roi.ROINumber = number
        roi.ReferencedFrameOfReferenceUID = frame_uid
        roi.ROIName = name
        roi.ROIGenerationAlgorithm = "MANUAL"
        roi_items.append(roi)
        holder = Dataset()
        holder.ReferencedROINumber = number
        holder.ROIDisplayColor = [255, 0, 0]
        if contours is not None:
            holder.ContourSequence = DicomSequence(list(contours))
        contour_items.append(holder)
    ds.StructureSetROISequence = DicomSequence(roi_items)
    ds.ROIContourSequence = DicomSequence(contour_items)
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    if preamble:
        ds.save_as(out, enforce_file_format=True)
    else:
        del ds.file_meta
        ds.save_as(out, implicit_vr=True, little_endian=True)
    return out
