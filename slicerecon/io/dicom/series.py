"""DICOM image series of a mask: sorting, grid geometry and pixel values.

The voxel grid follows the NIfTI-from-DICOM convention. With ImageOrientationPatient
``(row_cosine, column_cosine)``, PixelSpacing ``(between rows, between columns)``
and ImagePositionPatient ``IPP[s]`` of the slices sorted along the slice normal
``n = row_cosine × column_cosine``:

* ``mask[c, r, s] = pixels_of_slice_s[r, c]``, i.e. array axes (x, y, z) =
  (column index, row index, slice index);
* ``affine[:3, 0] = row_cosine * PixelSpacing[1]``,
  ``affine[:3, 1] = column_cosine * PixelSpacing[0]``,
  ``affine[:3, 2] =`` the step between consecutive IPPs (it may have an in-plane
  part, e.g. for a CT gantry tilt), ``affine[:3, 3] = IPP[0]``.

Slices are sorted by ``IPP · n``, never by InstanceNumber or file name.

Tolerances
----------
Orientation cosines of all slices must agree within ``1e-4``. Slice positions are
*regular* when every gap along ``n`` differs from the mean gap by at most
``max(0.01 mm, 1e-3 × mean gap)``, and every IPP lies within that distance of the
line through the first and last IPP. Two slices closer than 0.01 mm along ``n``
are duplicates.

Why not a library's series reader
---------------------------------
highdicom's ``get_volume_from_series`` and SimpleITK's ``ImageSeriesReader``
were weighed against what the tests pin (``docs/formats.md``, "Why the series
geometry is ours"): neither keeps a gantry tilt in the affine, neither puts an
irregular series on a regular grid (``allow_irregular``), and neither says which
slice is wrong. The sorting and checks below stay ours; pydicom decodes pixels.
"""

from __future__ import annotations

import logging
import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ...errors import EmptyMaskError, FormatError, GeometryError, InputError, LabelError
from ...sections import Volume
from ...selection import parse_selector
from ..limits import DEFAULT_MEMORY_BUDGET_GB, check_geometry, check_grid, reading
from .geometry import (
    ORIENTATION_TOLERANCE,
    POSITION_TOLERANCE_MM,
    floats,
    line_fit,
    optional_float,
    orientation_list,
    position_tolerance,
    require_path,
    spacing_list,
    unit_cosines,
)
from .sniff import DICOM_SUFFIXES, PARSE_ERRORS, is_dicom_file, object_kind, read_dicom_header

__all__ = [
    "FOREGROUND_EPSILON",
    "MAX_RESAMPLE_FACTOR",
    "check_one_series",
    "dicom_series_geometry",
    "read_dicom_series",
    "read_dicom_series_values",
    "referenced_series",
    "series_info",
    "series_label",
]

logger = logging.getLogger(__name__)

MAX_RESAMPLE_FACTOR = 8
"""With ``allow_irregular``, refuse grids with more than this many planes per slice."""
FOREGROUND_EPSILON = 1e-6
"""A pixel is foreground when its rescaled value's magnitude exceeds this."""


@dataclass(frozen=True)
class _Slice:
    """Header facts of one single-frame image."""

    path: Path
    dataset: Any
    sop_uid: str
    series_uid: str
    position: NDArray[np.float64]
    orientation: NDArray[np.float64]
    rows: int
    columns: int
    pixel_spacing: NDArray[np.float64]
    study_uid: str = ""
    patient_id: str = ""
    label: str = ""


@dataclass(frozen=True)
class _Layout:
    """How sorted slices fill a regular grid.

    ``sources[k]`` is the sorted-slice number whose pixels fill plane ``k``;
    ``own[k]`` is False for planes filled by nearest-neighbour copy (only with
    ``allow_irregular``).
    """

    affine: NDArray[np.float64]
    shape: tuple[int, int, int]
    slices: list[_Slice]
    sources: NDArray[np.int64]
    own: NDArray[np.bool_]
    regular: bool
    gaps_mm: NDArray[np.float64]


def _slice_from(ds: Any, path: Path) -> _Slice | None:
    """Header facts of an image file, or None for non-image objects (RTSTRUCT, SEG, ...)."""
    kind = object_kind(ds)
    if kind != "image":
        logger.debug("skipping %s: a %s object, not an image slice", path, kind)
        return None
    needed = ("Rows", "Columns", "ImagePositionPatient", "ImageOrientationPatient")
    missing = [k for k in needed if k not in ds]
    if missing:
        raise FormatError(
            f"{path} lacks {', '.join(missing)}: it is truncated, or not an image of a "
            "series; remove or replace it"
        )
    frames = ds.get("NumberOfFrames", 1)
    try:
        n_frames = int(frames) if frames not in (None, "") else 1
    except PARSE_ERRORS as exc:
        raise FormatError(f"{path}: NumberOfFrames is not a number ({frames!r})") from exc
    if n_frames > 1:
        raise InputError(
            f"{path} is a multi-frame image ({n_frames} frames); only single-frame image "
            "series are read. Convert it to NIfTI (e.g. with dcm2niix) and pass the .nii.gz"
        )
    if "PixelSpacing" in ds:
        spacing = floats(ds, "PixelSpacing", 2, path)
    else:
        logger.warning("%s has no PixelSpacing; assuming 1 mm pixels", path)
        spacing = np.ones(2)
    if np.any(spacing <= 0):
        raise FormatError(f"{path}: PixelSpacing must be positive (got {spacing.tolist()})")
    try:
        rows, columns = int(ds.Rows), int(ds.Columns)
    except PARSE_ERRORS as exc:
        raise FormatError(f"{path}: Rows/Columns are not numbers ({exc})") from exc
    return _Slice(
        path=path,
        dataset=ds,
        sop_uid=str(ds.get("SOPInstanceUID", "")),
        series_uid=str(ds.get("SeriesInstanceUID", "")),
        study_uid=str(ds.get("StudyInstanceUID", "") or "").strip(),
        patient_id=str(ds.get("PatientID", "") or "").strip(),
        label=series_label(ds),
        position=floats(ds, "ImagePositionPatient", 3, path),
        orientation=floats(ds, "ImageOrientationPatient", 6, path),
        rows=rows,
        columns=columns,
        pixel_spacing=spacing,
    )


def referenced_series(ds: Any) -> tuple[set[str], set[str]]:
    """The images an RTSTRUCT or SEG says it was drawn on.

    Parameters
    ----------
    ds : pydicom Dataset
        An RTSTRUCT (``ReferencedFrameOfReferenceSequence`` > ``RTReferencedStudySequence``
        > ``RTReferencedSeriesSequence``, and each contour's ``ContourImageSequence``)
        or a SEG (``ReferencedSeriesSequence`` and its ``ReferencedInstanceSequence``).

    Returns
    -------
    (series, instances) : tuple of set of str
        The SeriesInstanceUIDs and SOPInstanceUIDs it names; empty when it names none
        (these elements are optional).
    """

    def items(parents: list[Any], *path: str) -> list[Any]:
        """The items at the end of a path of sequences, below every parent."""
        for keyword in path:
            found = []
            for parent in parents:
                try:
                    found += list(parent.get(keyword, None) or [])
                except PARSE_ERRORS:  # a malformed sequence names nothing
                    continue
            parents = found
        return parents

    def uids(found: list[Any], keyword: str) -> set[str]:
        named = set()
        for item in found:
            try:
                named.add(str(item.get(keyword, "") or "").strip())
            except PARSE_ERRORS:
                continue
        return named - {""}

    rt_series = items(
        [ds],
        "ReferencedFrameOfReferenceSequence",
        "RTReferencedStudySequence",
        "RTReferencedSeriesSequence",
    )
    seg_series = items([ds], "ReferencedSeriesSequence")
    series = uids(rt_series + seg_series, "SeriesInstanceUID")
    images = (
        items(rt_series, "ContourImageSequence")
        + items([ds], "ROIContourSequence", "ContourSequence", "ContourImageSequence")
        + items(seg_series, "ReferencedInstanceSequence")
    )
    instances = uids(images, "ReferencedSOPInstanceUID")
    return series, instances


def _referenced_only(
    slices: list[_Slice], drawings: list[tuple[Path, Any]], where: str
) -> list[_Slice]:
    """Of images of several series, those of the one series the folder's one RTSTRUCT or
    SEG names (:func:`referenced_series`), said in one warning line; all of them when
    there is no such one series (:func:`check_one_series` then says what the folder holds)."""
    by_series = _groups(slices, "series_uid")
    if len(by_series) < 2 or len(drawings) != 1:
        return slices
    path, drawing = drawings[0]
    uids, instances = referenced_series(drawing)
    named = [
        key
        for key, group in by_series.items()
        if key in uids or any(item.sop_uid in instances for item in group)
    ]
    if len(named) != 1:
        return slices
    kept = by_series[named[0]]
    rest = {key: group for key, group in by_series.items() if key != named[0]}
    # the drawing's name in the line: said alike by every reader of the folder, so once
    logger.warning(
        "%s holds %d image series: read %d images of %s, the series %s names as its own; "
        "set aside %s",
        where,
        len(by_series),
        len(kept),
        kept[0].label,
        path.name,
        _listing(rest, "series"),
    )
    return kept


def _scan_series(directory: Path, *, stop_before_pixels: bool) -> list[_Slice]:
    """Read every image slice in ``directory``; check that they form exactly one series
    (or that the folder's one RTSTRUCT or SEG names one of them: :func:`_referenced_only`)."""
    files = sorted(f for f in directory.iterdir() if f.is_file() and not f.name.startswith("."))
    slices: list[_Slice] = []
    drawings: list[tuple[Path, Any]] = []
    for f in files:
        if not is_dicom_file(f):
            if f.suffix.lower() in DICOM_SUFFIXES:
                raise FormatError(
                    f"{f} is named like a DICOM file but is not one (neither a 'DICM' marker "
                    "at byte 128 nor a DICOM dataset at its start); remove or replace it"
                )
            logger.debug("skipping %s: not a DICOM file", f)
            continue
        with reading(f):  # pydicom parses values lazily: name the file that fails
            ds = read_dicom_header(f, stop_before_pixels=stop_before_pixels)
            item = _slice_from(ds, f)
            if item is None and object_kind(ds) in ("rtstruct", "seg"):
                drawings.append((f, ds))
        if item is not None:
            slices.append(item)
    if not slices:
        raise InputError(
            f"no DICOM image files in {directory}; pass a directory holding one image series"
        )
    slices = _referenced_only(slices, drawings, str(directory))
    check_one_series(slices, str(directory))
    return slices


def series_label(ds: Any) -> str:
    """How a user knows a series: modality and SeriesDescription (``CT 'Thorax 3 mm'``)."""
    modality = str(ds.get("Modality", "") or "").strip() or "(no modality)"
    description = " ".join(str(ds.get("SeriesDescription", "") or "").split())
    return f"{modality} '{description}'" if description else f"{modality} (no SeriesDescription)"


def _groups(slices: list[_Slice], field: str) -> dict[str, list[_Slice]]:
    groups: dict[str, list[_Slice]] = {}
    for item in slices:
        groups.setdefault(getattr(item, field), []).append(item)
    return groups


def _listing(groups: dict[str, list[_Slice]], what: str) -> str:
    parts = []
    for uid, items in sorted(groups.items(), key=lambda kv: -len(kv[1])):
        names = ", ".join(i.path.name for i in items[:3]) + (", ..." if len(items) > 3 else "")
        count = f"{len(items)} image{'s' if len(items) != 1 else ''}"
        parts.append(f"{count} of {items[0].label} ({what} {uid or '(none)'}: {names})")
    return "; ".join(parts)


def check_one_series(slices: list[_Slice], where: str) -> None:
    """Refuse images of several series, studies or patients, naming each group.

    Groups are named by modality and SeriesDescription (what a viewer shows),
    then by UID and file names.

    Raises
    ------
    InputError
        The images hold several SeriesInstanceUIDs, StudyInstanceUIDs or
        (non-empty) PatientIDs.
    """
    by_series = _groups(slices, "series_uid")
    if len(by_series) > 1:
        raise InputError(
            f"{where} holds {len(by_series)} image series: {_listing(by_series, 'series')}. "
            "Move each series into its own directory and pass one of them"
        )
    by_study = _groups(slices, "study_uid")
    if len(by_study) > 1:
        raise InputError(
            f"{where} mixes images of {len(by_study)} studies under one series: "
            f"{_listing(by_study, 'study')}. Move the images of the other study out"
        )
    by_patient = {k: v for k, v in _groups(slices, "patient_id").items() if k}
    if len(by_patient) > 1:
        raise InputError(
            f"{where} mixes images of {len(by_patient)} patients: "
            f"{_listing(by_patient, 'PatientID')}. Move the images of the other patient out"
        )


def _check_same_grid(slices: list[_Slice]) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Check shared rows/columns/spacing/orientation; return unit row and column cosines."""
    first = slices[0]
    for s in slices[1:]:
        if (s.rows, s.columns) != (first.rows, first.columns):
            raise GeometryError(
                f"slices differ in size: {first.path.name} is {first.rows}x{first.columns} "
                f"(rows x columns), {s.path.name} is {s.rows}x{s.columns}; "
                "a series must have one image size"
            )
        if not np.allclose(s.pixel_spacing, first.pixel_spacing, rtol=1e-4, atol=0):
            raise GeometryError(
                f"slices differ in PixelSpacing: {first.path.name} has "
                f"{first.pixel_spacing.tolist()}, {s.path.name} has {s.pixel_spacing.tolist()}"
            )
        if np.max(np.abs(s.orientation - first.orientation)) > ORIENTATION_TOLERANCE:
            raise GeometryError(
                f"slices are not parallel: ImageOrientationPatient of {s.path.name} "
                f"{np.round(s.orientation, 5).tolist()} differs from {first.path.name} "
                f"{np.round(first.orientation, 5).tolist()}; slicerecon needs parallel sections"
            )
    return unit_cosines(first.orientation, first.path)


def _layout(slices: list[_Slice], *, allow_irregular: bool) -> _Layout:
    """Sort slices along their normal and put them on a regular grid."""
    row, col = _check_same_grid(slices)
    normal = np.cross(row, col)
    t_unsorted = np.array([s.position @ normal for s in slices])
    order = np.argsort(t_unsorted, kind="stable")
    ordered = [slices[i] for i in order]
    t = t_unsorted[order]
    positions = np.array([s.position for s in ordered])
    names = [s.path.name for s in ordered]
    n = len(ordered)
    gaps = np.diff(t)

    if n == 1:
        step_len = _single_slice_step(ordered[0])
        direction = normal
        step_t = step_len
        sources = np.zeros(1, dtype=np.int64)
        own = np.ones(1, dtype=bool)
        regular = True
    else:
        dup = np.flatnonzero(gaps < POSITION_TOLERANCE_MM)
        if dup.size:
            i = int(dup[0])
            raise GeometryError(
                f"duplicate slice positions: {names[i]} and {names[i + 1]} lie "
                f"{gaps[i]:.4g} mm apart along the slice normal; remove the duplicate"
            )
        direction = line_fit(positions, t, names)
        extent = float(t[-1] - t[0])
        mean_gap = extent / (n - 1)
        tol = position_tolerance(mean_gap)
        regular = bool(np.all(np.abs(gaps - mean_gap) <= tol))
        if regular:
            step_t = mean_gap
            sources = np.arange(n, dtype=np.int64)
            own = np.ones(n, dtype=bool)
        elif not allow_irregular:
            wide = int(np.argmax(gaps))
            raise GeometryError(
                f"{ordered[wide].path.parent}: slice spacing is irregular: gaps between slices "
                f"range from {gaps.min():.4g} to {gaps.max():.4g} mm (tolerance {tol:.3g} mm; "
                f"the widest between {names[wide]} and {names[wide + 1]}: a slice missing?). Pass "
                "--allow-irregular (allow_irregular=True) to place the slices on a regular grid "
                "whose step is the smallest gap"
            )
        else:
            step_t, sources, own = _irregular_grid(t, float(gaps.min()))
            logger.warning(
                "irregular slice spacing (gaps %.4g to %.4g mm): %d slices placed on a regular "
                "grid of %d planes, %.4g mm apart; %d planes copied from the nearest slice",
                gaps.min(),
                gaps.max(),
                n,
                sources.size,
                step_t,
                int((~own).sum()),
            )

    first = ordered[0]
    affine = np.eye(4)
    affine[:3, 0] = row * first.pixel_spacing[1]
    affine[:3, 1] = col * first.pixel_spacing[0]
    affine[:3, 2] = direction * step_t
    affine[:3, 3] = first.position
    shape = (first.columns, first.rows, int(sources.size))
    return _Layout(affine, shape, ordered, sources, own, regular, gaps)


def _single_slice_step(item: _Slice) -> float:
    ds = item.dataset
    for keyword in ("SpacingBetweenSlices", "SliceThickness"):
        value = optional_float(ds, keyword)
        if value is not None:
            return value
    logger.warning("%s is a single slice without SliceThickness; assuming 1 mm", item.path)
    return 1.0


def _irregular_grid(
    t: NDArray[np.float64], smallest_gap: float
) -> tuple[float, NDArray[np.int64], NDArray[np.bool_]]:
    """Regular planes from ``t[0]`` to ``t[-1]`` at most ``smallest_gap`` apart.

    Each slice owns the plane nearest to it (distinct planes, since the step does
    not exceed the smallest gap); every other plane copies the nearest slice.
    """
    extent = float(t[-1] - t[0])
    n_steps = max(1, math.ceil(extent / smallest_gap - 1e-6))
    if n_steps + 1 > MAX_RESAMPLE_FACTOR * t.size:
        raise GeometryError(
            f"slice spacing is too irregular to resample: the smallest gap "
            f"({smallest_gap:.4g} mm) would need {n_steps + 1} planes for {t.size} slices; "
            "check the series for stray or misplaced slices"
        )
    step = extent / n_steps
    plane_t = t[0] + step * np.arange(n_steps + 1)
    sources = np.argmin(np.abs(plane_t[:, None] - t[None, :]), axis=1).astype(np.int64)
    own = np.zeros(n_steps + 1, dtype=bool)
    home = np.rint((t - t[0]) / step).astype(np.int64)
    sources[home] = np.arange(t.size)
    own[home] = True
    return step, sources, own


def dicom_series_geometry(
    path: str | os.PathLike[str], *, allow_irregular: bool = False
) -> tuple[NDArray[np.float64], tuple[int, int, int], list[str]]:
    """Grid of a DICOM image series, from headers only (no pixel data is read).

    Parameters
    ----------
    path : path-like
        Directory holding the files of one image series. Non-DICOM files and
        non-image DICOM objects (RTSTRUCT, SEG, ...) in it are skipped, as in
        :func:`read_dicom_series`.
    allow_irregular : bool
        Accept uneven slice spacing and return the resampled grid described in
        :func:`read_dicom_series`.

    Returns
    -------
    affine : ndarray of shape (4, 4)
        Voxel index → DICOM patient coordinates (LPS), mm.
    shape : tuple of int
        Grid shape ``(I, J, K)`` = (Columns, Rows, planes).
    sop_instance_uids : list of str, length K
        ``sop_instance_uids[k]`` is the SOPInstanceUID of the image on plane
        ``k``. With ``allow_irregular``, planes that only copy a neighbouring
        slice hold ``""``, so ``uids.index(uid)`` is each image's own plane.

    Raises
    ------
    InputError
        Missing directory, no DICOM image in it, or several series.
    GeometryError
        Non-parallel slices, duplicates, differing sizes, irregular spacing.
    FormatError
        A file that cannot be parsed (named in the message).
    """
    directory = require_path(path, want_dir=True)
    layout = _layout(
        _scan_series(directory, stop_before_pixels=True), allow_irregular=allow_irregular
    )
    uids = [
        layout.slices[src].sop_uid if own else ""
        for src, own in zip(layout.sources, layout.own, strict=True)
    ]
    return layout.affine, layout.shape, uids


def _slice_values(item: _Slice) -> NDArray[np.float64]:
    """Pixel values of one slice, shape (Rows, Columns), after RescaleSlope/Intercept."""
    from pydicom.pixels import apply_rescale

    ds = item.dataset
    if int(ds.get("SamplesPerPixel", 1) or 1) != 1:
        raise InputError(
            f"{item.path} is a colour image ({ds.SamplesPerPixel} samples per pixel); "
            "a mask series must be greyscale"
        )
    try:
        pixels = ds.pixel_array
        values = np.asarray(apply_rescale(pixels, ds), dtype=np.float64)
    except PARSE_ERRORS as exc:
        raise FormatError(
            f"cannot decode the pixel data of {item.path} ({type(exc).__name__}: {exc}); "
            "the file is corrupt or uses a compression pydicom cannot decode here"
        ) from exc
    if values.shape != (item.rows, item.columns):
        raise FormatError(
            f"{item.path}: pixel data has shape {values.shape}, expected "
            f"({item.rows}, {item.columns}) from Rows/Columns"
        )
    return values


def _checked_layout(directory: Path, allow_irregular: bool, memory_budget_gb: float) -> _Layout:
    """The series' layout, its geometry and size checked before any pixel is decoded."""
    layout = _layout(
        _scan_series(directory, stop_before_pixels=False), allow_irregular=allow_irregular
    )
    check_geometry(layout.affine, layout.shape, what=str(directory))
    check_grid(
        layout.shape, what=str(directory), memory_budget_gb=memory_budget_gb, bytes_per_voxel=6
    )
    return layout


def read_dicom_series_values(
    path: str | os.PathLike[str],
    *,
    allow_irregular: bool = False,
    memory_budget_gb: float = DEFAULT_MEMORY_BUDGET_GB,
) -> tuple[NDArray[np.float32], NDArray[np.float64]]:
    """The pixel values of a DICOM mask series as a label map, with its affine.

    Parameters
    ----------
    path, allow_irregular, memory_budget_gb
        As for :func:`read_dicom_series`.

    Returns
    -------
    values : ndarray of shape (Columns, Rows, planes), float32
        Values after RescaleSlope / RescaleIntercept.
    affine : ndarray of shape (4, 4)
        Voxel index → DICOM patient LPS mm.

    Raises
    ------
    InputError, GeometryError, FormatError, MemoryBudgetError
        As :func:`read_dicom_series`.
    """
    directory = require_path(path, want_dir=True)
    layout = _checked_layout(directory, allow_irregular, memory_budget_gb)
    stacked = np.stack([_slice_values(item).astype(np.float32) for item in layout.slices])
    return np.transpose(stacked[layout.sources], (2, 1, 0)), layout.affine


def read_dicom_series(
    path: str | os.PathLike[str],
    *,
    allow_irregular: bool = False,
    label: int | str | None = None,
    memory_budget_gb: float = DEFAULT_MEMORY_BUDGET_GB,
) -> Volume:
    """Read a binary mask stored as a DICOM image series (one file per slice).

    Parameters
    ----------
    path : path-like
        Directory holding one image series. Non-DICOM files are skipped unless
        named ``*.dcm`` / ``*.dicom`` / ``*.ima``; so are non-image DICOM objects
        (DICOMDIR, and modalities RTSTRUCT, SEG, RTPLAN, SR, KO, PR, REG, ...).
        Any other DICOM file without Rows, Columns, ImagePositionPatient and
        ImageOrientationPatient is reported as truncated (FormatError).
    allow_irregular : bool
        If False (default), slices whose spacing along the normal is uneven raise
        :class:`GeometryError`. If True, the volume is put on a regular grid
        from the first to the last slice whose step is the smallest gap (shrunk
        so that the planes end exactly on the last slice); each slice is written
        to the plane nearest to it (at most half a step away), and every other
        plane copies the nearest slice (nearest-neighbour interpolation along
        the normal). A warning is logged.
    label : int or str, optional
        Keep the pixels whose value (after RescaleSlope / RescaleIntercept) equals
        ``label`` (a string of digits counts as the number). Default: every pixel
        with a non-zero value is foreground.
    memory_budget_gb : float
        Refuse series whose grid would not fit this budget, GiB
        (:func:`slicerecon.io.limits.check_grid`), before decoding any pixel.

    Returns
    -------
    Volume
        Mask of shape ``(Columns, Rows, planes)``; affine to DICOM patient LPS mm
        (see the module docstring).

    Raises
    ------
    InputError
        Missing directory, no DICOM image in it, several series, colour images.
    GeometryError
        Non-parallel slices, duplicate positions, differing image sizes or pixel
        spacing, irregular spacing (without ``allow_irregular``).
    FormatError
        A corrupt or undecodable file (named in the message).
    LabelError
        ``label`` occurs in no slice, or is a name.
    EmptyMaskError
        No foreground pixel at all.
    MemoryBudgetError
        The grid exceeds ``memory_budget_gb``.
    """
    selector = parse_selector(label)
    if isinstance(selector, str):
        raise LabelError(
            f"label {selector!r} is not in {path}: a mask series names its structures by "
            "pixel value, not by name; pass a number"
        )
    label = selector
    directory = require_path(path, want_dir=True)
    layout = _checked_layout(directory, allow_irregular, memory_budget_gb)
    planes: list[NDArray[np.bool_]] = []
    seen: set[float] = set()
    for item in layout.slices:
        values = _slice_values(item)
        if label is None:
            planes.append(np.abs(values) > FOREGROUND_EPSILON)
        else:
            planes.append(np.abs(values - float(label)) <= FOREGROUND_EPSILON)
        if len(seen) <= 32:
            seen.update(np.unique(values)[:33].tolist())
    stacked = np.stack(planes)  # (N, Rows, Columns)
    mask = np.transpose(stacked[layout.sources], (2, 1, 0))
    if not mask.any():
        if label is not None:
            shown = ", ".join(f"{v:g}" for v in sorted(seen)[:16])
            raise LabelError(
                f"label {label} does not occur in the series {directory}; pixel values "
                f"found: {shown}{' ...' if len(seen) > 16 else ''}"
            )
        raise EmptyMaskError(
            f"the DICOM series {directory} holds no foreground: every pixel is 0 after rescale"
        )
    logger.info(
        "read DICOM series %s: %d slices, grid %s, spacing %s mm",
        directory,
        len(layout.slices),
        layout.shape,
        np.round(np.linalg.norm(layout.affine[:3, :3], axis=0), 4).tolist(),
    )
    return Volume(mask, layout.affine)


def series_info(path: str | os.PathLike[str], *, allow_irregular: bool = True) -> dict[str, Any]:
    """Describe a DICOM image-series directory from its headers (see :func:`dicom_info`)."""
    directory = require_path(path, want_dir=True)
    layout = _layout(
        _scan_series(directory, stop_before_pixels=True), allow_irregular=allow_irregular
    )
    first = layout.slices[0].dataset
    gaps = layout.gaps_mm
    return {
        "kind": "dicom-series",
        "modality": str(first.get("Modality", "")),
        "series_instance_uid": layout.slices[0].series_uid,
        "n_slices": len(layout.slices),
        "shape": list(layout.shape),
        "spacing_mm": spacing_list(layout.affine),
        "orientation": orientation_list(layout.affine),
        "origin_mm": [round(float(v), 6) for v in layout.affine[:3, 3]],
        "regular_spacing": layout.regular,
        "slice_gap_mm": {
            "min": round(float(gaps.min()), 6) if gaps.size else None,
            "max": round(float(gaps.max()), 6) if gaps.size else None,
        },
        "coordinates": "LPS",
    }
