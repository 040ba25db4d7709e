"""DICOM readers: an image series of a mask, and DICOM SEG (Segmentation Storage).

Coordinates
-----------
Everything stays in DICOM patient coordinates, **LPS millimetres** (x to the
patient's left, y to posterior, z to superior); nothing is converted to RAS, so a
mesh reconstructed from a DICOM input is written in LPS mm and overlays the
source images in LPS-aware viewers. See ``docs/formats.md`` for the user guide.

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
"""

from __future__ import annotations

import logging
import math
import os
import struct
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import (
    EmptyMaskError,
    FormatError,
    GeometryError,
    InputError,
    LabelError,
)
from ..sections import Volume
from .limits import DEFAULT_MEMORY_BUDGET_GB, check_geometry, check_grid, reading
from .selection import choose_structure, parse_selector

__all__ = [
    "SEG_SOP_CLASS_UID",
    "dicom_info",
    "dicom_modality",
    "is_dicom_file",
    "read_dicom_header",
    "dicom_series_geometry",
    "read_dicom_seg",
    "read_dicom_series",
]

logger = logging.getLogger(__name__)

SEG_SOP_CLASS_UID = "1.2.840.10008.5.1.4.1.1.66.4"
"""SOP Class UID of DICOM Segmentation Storage."""

ORIENTATION_TOLERANCE = 1e-4
"""Largest difference between direction cosines of slices that count as parallel."""
POSITION_TOLERANCE_MM = 0.01
"""Absolute position tolerance, mm (duplicates, regular spacing, collinear IPPs)."""
POSITION_TOLERANCE_REL = 1e-3
"""Position tolerance relative to the slice gap (regular spacing, collinear IPPs)."""
MAX_RESAMPLE_FACTOR = 8
"""With ``allow_irregular``, refuse grids with more than this many planes per slice."""
FOREGROUND_EPSILON = 1e-6
"""A pixel is foreground when its rescaled value's magnitude exceeds this."""

_DICOM_SUFFIXES = (".dcm", ".dicom", ".ima")
_DICOMDIR_SOP_CLASS_UID = "1.2.840.10008.1.3.10"
_NON_IMAGE_MODALITIES = frozenset(
    {"RTSTRUCT", "SEG", "RTPLAN", "RTRECORD", "SR", "KO", "PR", "REG", "DOC", "FID", "PLAN"}
)
PARSE_ERRORS: tuple[type[BaseException], ...] = (
    OSError,
    EOFError,
    ValueError,
    TypeError,
    KeyError,
    IndexError,
    AttributeError,
    NotImplementedError,
    OverflowError,
    RuntimeError,
    struct.error,
)
"""What pydicom raises on corrupt or truncated files and malformed values (the
readers turn these into one :class:`~slicerecon.errors.FormatError`)."""


# ----------------------------------------------------------------------------- files
def is_dicom_file(path: str | os.PathLike[str]) -> bool:
    """Whether a file's content is DICOM, from its first bytes (no parsing).

    True for a Part 10 file (the ``DICM`` marker at byte 128) and for a bare
    dataset without the 128-byte preamble, as older systems and pydicom's own
    test files write them: its first element is a little-endian tag of group
    0x0002 (file meta) or 0x0008 (identification) with a plausible VR or length.

    Raises
    ------
    FormatError
        If the file cannot be read at all.
    """
    p = Path(path)
    try:
        with open(p, "rb") as fh:
            head = fh.read(132)
    except OSError as exc:
        raise FormatError(f"cannot read {p}: {exc.strerror or exc}") from exc
    if len(head) == 132 and head[128:132] == b"DICM":
        return True
    if len(head) < 8:
        return False
    group, element = struct.unpack("<HH", head[:4])
    if group not in (0x0002, 0x0008) or element > 0x1FFF:
        return False
    vr = head[4:6]
    if vr.isalpha() and vr.isupper():  # explicit VR
        return True
    (length,) = struct.unpack("<I", head[4:8])  # implicit VR: a modest element length
    return length < 1024


def read_dicom_header(
    path: str | os.PathLike[str],
    *,
    stop_before_pixels: bool = True,
    specific_tags: Sequence[str] | None = None,
) -> Any:
    """Read a DICOM file with pydicom, with or without its preamble.

    Files without the 128-byte preamble and ``DICM`` marker are read with
    ``force=True`` when :func:`is_dicom_file` recognises their content. Pixel
    data, when read, is deferred until it is first used.

    Parameters
    ----------
    path : path-like
        The file.
    stop_before_pixels : bool
        Skip the pixel data.
    specific_tags : sequence of str, optional
        Read only these keywords (a fast sniff).

    Returns
    -------
    pydicom.Dataset

    Raises
    ------
    FormatError
        If the content is not DICOM, or pydicom fails on it (the file is named).
    """
    import pydicom

    p = Path(path)
    if not is_dicom_file(p):
        raise FormatError(f"{p} is corrupt or not a DICOM file: its content is not DICOM")
    marker = _has_dicom_marker(p)
    try:
        return pydicom.dcmread(
            p,
            stop_before_pixels=stop_before_pixels,
            specific_tags=list(specific_tags) if specific_tags is not None else None,
            defer_size=None if stop_before_pixels else "64 KB",
            force=not marker,
        )
    except Exception as exc:  # noqa: BLE001 - every pydicom failure names the file
        raise FormatError(
            f"{p} is corrupt or not a valid DICOM file ({type(exc).__name__}: "
            f"{' '.join(str(exc).split())[:200]}); remove or replace it"
        ) from exc


def dicom_modality(path: str | os.PathLike[str]) -> str | None:
    """``"SEG"``, ``"RTSTRUCT"``, another Modality (``"UNKNOWN"`` when absent), or
    None when the file is not DICOM or cannot be parsed."""
    p = Path(path)
    try:
        if not p.is_file() or not is_dicom_file(p):
            return None
        with reading(p):  # values are parsed lazily, on access
            ds = read_dicom_header(p, specific_tags=["Modality", "SOPClassUID"])
            sop_class = str(getattr(ds, "SOPClassUID", ""))
            modality = str(getattr(ds, "Modality", "") or "")
    except FormatError:
        return None
    if sop_class == SEG_SOP_CLASS_UID:
        return "SEG"
    if not modality and not sop_class:
        return None  # forced parse of something that only began like DICOM
    return modality or "UNKNOWN"


def _has_dicom_marker(path: Path) -> bool:
    """True when ``path`` has the DICOM Part 10 ``DICM`` marker at byte 128."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(132)
    except OSError as exc:
        raise FormatError(f"cannot read {path}: {exc.strerror or exc}") from exc
    return len(head) == 132 and head[128:132] == b"DICM"


def _dcmread(path: Path, *, stop_before_pixels: bool) -> Any:
    """Read a DICOM file, turning every parser failure into a FormatError naming it."""
    return read_dicom_header(path, stop_before_pixels=stop_before_pixels)


def _require_path(path: str | os.PathLike[str], *, want_dir: bool) -> Path:
    p = Path(path)
    if not p.exists():
        raise InputError(f"DICOM input not found: {p}")
    if want_dir and not p.is_dir():
        raise InputError(f"{p} is a file; pass the directory that holds the DICOM image series")
    if not want_dir and not p.is_file():
        raise InputError(f"{p} is a directory; pass the DICOM SEG file itself")
    return p


def _floats(ds: Any, keyword: str, count: int, path: Path) -> NDArray[np.float64]:
    """A numeric multi-valued attribute as ``count`` finite floats, or FormatError."""
    if keyword not in ds:
        raise FormatError(f"{path} lacks {keyword}; it cannot be placed in space")
    try:
        raw = ds[keyword].value
        values = np.asarray([float(v) for v in (raw if isinstance(raw, Sequence)
                                                and not isinstance(raw, str) else [raw])])
    except PARSE_ERRORS as exc:
        raise FormatError(f"{path}: {keyword} is not numeric ({exc})") from exc
    if values.shape != (count,) or not np.all(np.isfinite(values)):
        raise FormatError(
            f"{path}: {keyword} must hold {count} finite numbers (got {values.tolist()})"
        )
    return values


def _optional_float(item: Any, keyword: str) -> float | None:
    try:
        value = float(item[keyword].value) if keyword in item else None
    except PARSE_ERRORS:
        return None
    return value if value is not None and math.isfinite(value) and value > 0 else None


# ----------------------------------------------------------------------------- series
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
    sop_class = str(ds.get("SOPClassUID", ""))
    meta = getattr(ds, "file_meta", None)
    media_class = str(meta.get("MediaStorageSOPClassUID", "")) if meta is not None else ""
    modality = str(ds.get("Modality", "") or "").upper()
    if (
        sop_class == SEG_SOP_CLASS_UID
        or media_class == _DICOMDIR_SOP_CLASS_UID
        or modality in _NON_IMAGE_MODALITIES
    ):
        logger.debug("skipping %s: a %s object, not an image slice", path, modality or "DICOMDIR")
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
        spacing = _floats(ds, "PixelSpacing", 2, path)
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
        position=_floats(ds, "ImagePositionPatient", 3, path),
        orientation=_floats(ds, "ImageOrientationPatient", 6, path),
        rows=rows,
        columns=columns,
        pixel_spacing=spacing,
    )


def _scan_series(directory: Path, *, stop_before_pixels: bool) -> list[_Slice]:
    """Read every image slice in ``directory``; check that they form exactly one series."""
    files = sorted(f for f in directory.iterdir() if f.is_file() and not f.name.startswith("."))
    slices: list[_Slice] = []
    for f in files:
        if not is_dicom_file(f):
            if f.suffix.lower() in _DICOM_SUFFIXES:
                raise FormatError(
                    f"{f} is named like a DICOM file but is not one (neither a 'DICM' marker "
                    "at byte 128 nor a DICOM dataset at its start); remove or replace it"
                )
            logger.debug("skipping %s: not a DICOM file", f)
            continue
        with reading(f):  # pydicom parses values lazily: name the file that fails
            ds = _dcmread(f, stop_before_pixels=stop_before_pixels)
            item = _slice_from(ds, f)
        if item is not None:
            slices.append(item)
    if not slices:
        raise InputError(
            f"no DICOM image files in {directory}; pass a directory holding one image series"
        )
    by_series: dict[str, int] = {}
    for s in slices:
        by_series[s.series_uid] = by_series.get(s.series_uid, 0) + 1
    if len(by_series) > 1:
        listing = "; ".join(f"{uid or '(no UID)'} ({n} files)" for uid, n in by_series.items())
        raise InputError(
            f"{directory} holds {len(by_series)} image series: {listing}. "
            "Move each series into its own directory and pass one of them"
        )
    return slices


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
    return _unit_cosines(first.orientation, first.path)


def _unit_cosines(orientation: NDArray[np.float64], where: Path) -> tuple[NDArray, NDArray]:
    row, col = orientation[:3], orientation[3:]
    n_row, n_col = float(np.linalg.norm(row)), float(np.linalg.norm(col))
    if n_row < 1e-6 or n_col < 1e-6:
        raise FormatError(f"{where}: ImageOrientationPatient has a zero direction")
    row, col = row / n_row, col / n_col
    if abs(float(np.dot(row, col))) > ORIENTATION_TOLERANCE * 10:
        raise GeometryError(
            f"{where}: ImageOrientationPatient row and column directions are not orthogonal"
        )
    return row, col


def _position_tolerance(gap: float) -> float:
    return max(POSITION_TOLERANCE_MM, POSITION_TOLERANCE_REL * gap)


def _line_fit(
    positions: NDArray[np.float64], t: NDArray[np.float64], names: Sequence[str]
) -> NDArray[np.float64]:
    """Direction ``d`` (with ``d · n = 1``) such that ``IPP ≈ IPP[0] + (t - t[0]) d``.

    ``positions`` of shape (N, 3) and ``t`` of shape (N,) are sorted by ``t``.
    """
    extent = float(t[-1] - t[0])
    direction = (positions[-1] - positions[0]) / extent
    predicted = positions[0] + (t - t[0])[:, None] * direction
    residual = np.linalg.norm(positions - predicted, axis=1)
    tol = _position_tolerance(extent / max(len(t) - 1, 1))
    worst = int(np.argmax(residual))
    if residual[worst] > tol:
        raise GeometryError(
            f"slice origins do not lie on one line: {names[worst]} is {residual[worst]:.4g} mm "
            f"off the line through the first and last slice (tolerance {tol:.3g} mm)"
        )
    return direction


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
        direction = _line_fit(positions, t, names)
        extent = float(t[-1] - t[0])
        mean_gap = extent / (n - 1)
        tol = _position_tolerance(mean_gap)
        regular = bool(np.all(np.abs(gaps - mean_gap) <= tol))
        if regular:
            step_t = mean_gap
            sources = np.arange(n, dtype=np.int64)
            own = np.ones(n, dtype=bool)
        elif not allow_irregular:
            raise GeometryError(
                f"slice spacing is irregular: gaps between slices range from {gaps.min():.4g} "
                f"to {gaps.max():.4g} mm (tolerance {tol:.3g} mm). Pass --allow-irregular "
                "(allow_irregular=True) to place the slices on a regular grid whose step is "
                "the smallest gap"
            )
        else:
            step_t, sources, own = _irregular_grid(t, float(gaps.min()))
            logger.warning(
                "irregular slice spacing (gaps %.4g to %.4g mm): %d slices placed on a regular "
                "grid of %d planes, %.4g mm apart; %d planes copied from the nearest slice",
                gaps.min(), gaps.max(), n, sources.size, step_t, int((~own).sum()),
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
        value = _optional_float(ds, keyword)
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
    directory = _require_path(path, want_dir=True)
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
    check_grid(layout.shape, what=str(directory), memory_budget_gb=memory_budget_gb,
               bytes_per_voxel=6)
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
    directory = _require_path(path, want_dir=True)
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
    directory = _require_path(path, want_dir=True)
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
        directory, len(layout.slices), layout.shape,
        np.round(np.linalg.norm(layout.affine[:3, :3], axis=0), 4).tolist(),
    )
    return Volume(mask, layout.affine)


# ----------------------------------------------------------------------------- SEG
@dataclass(frozen=True)
class _SegGeometry:
    """Where each frame of a SEG lies on a regular grid."""

    affine: NDArray[np.float64]
    shape: tuple[int, int, int]
    frame_plane: NDArray[np.int64]
    frame_segment: NDArray[np.int64]


def _read_seg_dataset(path: str | os.PathLike[str], *, stop_before_pixels: bool) -> Any:
    p = _require_path(path, want_dir=False)
    ds = read_dicom_header(p, stop_before_pixels=stop_before_pixels)
    sop_class = str(ds.get("SOPClassUID", ""))
    if sop_class != SEG_SOP_CLASS_UID:
        modality = str(ds.get("Modality", "") or "unknown")
        raise InputError(
            f"{p} is not a DICOM SEG (SOP class {sop_class or 'missing'}, modality "
            f"{modality}); pass a Segmentation Storage file, or the directory of an image series"
        )
    return ds


def _seg_segments(ds: Any, path: Path) -> dict[int, str]:
    """Segment number → SegmentLabel."""
    if "SegmentSequence" not in ds or len(ds.SegmentSequence) == 0:
        raise FormatError(f"{path} has no SegmentSequence: it describes no segment")
    segments: dict[int, str] = {}
    for item in ds.SegmentSequence:
        try:
            number = int(item.SegmentNumber)
        except PARSE_ERRORS as exc:
            raise FormatError(f"{path}: a SegmentSequence item lacks SegmentNumber") from exc
        segments[number] = str(item.get("SegmentLabel", "") or "")
    return segments


def _choose_segment(segments: dict[int, str], segment: int | str | None, path: Path) -> int:
    return choose_structure(segments, parse_selector(segment), kind="segment", source=path)


def _functional(ds: Any, frame_item: Any, sequence: str) -> Any | None:
    """The first item of a functional group, per-frame first, then shared."""
    for holder in (frame_item, _shared(ds)):
        if holder is not None and sequence in holder and len(holder[sequence].value) > 0:
            return holder[sequence].value[0]
    return None


def _shared(ds: Any) -> Any | None:
    if "SharedFunctionalGroupsSequence" in ds and len(ds.SharedFunctionalGroupsSequence) > 0:
        return ds.SharedFunctionalGroupsSequence[0]
    return None


def _seg_geometry(ds: Any, path: Path) -> _SegGeometry:
    """Place every frame of a SEG on one regular grid."""
    try:
        n_frames = int(ds.get("NumberOfFrames", 1) or 1)
        rows, columns = int(ds.Rows), int(ds.Columns)
    except PARSE_ERRORS as exc:
        raise FormatError(f"{path}: NumberOfFrames / Rows / Columns are missing ({exc})") from exc
    per_frame = ds.get("PerFrameFunctionalGroupsSequence")
    if per_frame is None or len(per_frame) != n_frames:
        raise FormatError(
            f"{path}: PerFrameFunctionalGroupsSequence has "
            f"{0 if per_frame is None else len(per_frame)} items for {n_frames} frames"
        )
    orientations, positions, segment_numbers = [], [], []
    spacing: NDArray[np.float64] | None = None
    thickness: float | None = None
    for f, item in enumerate(per_frame):
        orient = _functional(ds, item, "PlaneOrientationSequence")
        plane = _functional(ds, item, "PlanePositionSequence")
        ident = _functional(ds, item, "SegmentIdentificationSequence")
        measures = _functional(ds, item, "PixelMeasuresSequence")
        if orient is None or plane is None or ident is None:
            raise FormatError(
                f"{path}: frame {f + 1} lacks PlaneOrientation, PlanePosition or "
                "SegmentIdentification; the SEG cannot be placed in space"
            )
        where = Path(f"{path} (frame {f + 1})")
        orientations.append(_floats(orient, "ImageOrientationPatient", 6, where))
        positions.append(_floats(plane, "ImagePositionPatient", 3, where))
        try:
            segment_numbers.append(int(ident.ReferencedSegmentNumber))
        except PARSE_ERRORS as exc:
            raise FormatError(f"{where}: ReferencedSegmentNumber is missing") from exc
        if measures is not None and spacing is None:
            spacing = _floats(measures, "PixelSpacing", 2, where)
            thickness = _optional_float(measures, "SpacingBetweenSlices") or _optional_float(
                measures, "SliceThickness"
            )
    if spacing is None:
        raise FormatError(f"{path} has no PixelMeasuresSequence/PixelSpacing")
    if np.any(spacing <= 0):
        raise FormatError(f"{path}: PixelSpacing must be positive (got {spacing.tolist()})")
    orient_arr = np.array(orientations)
    if np.max(np.abs(orient_arr - orient_arr[0])) > ORIENTATION_TOLERANCE:
        raise GeometryError(f"frames of {path} are not parallel: ImageOrientationPatient differs")
    row, col = _unit_cosines(orient_arr[0], path)
    normal = np.cross(row, col)
    pos = np.array(positions)
    t = pos @ normal

    # distinct plane positions over all frames (frames of several segments share planes)
    order = np.argsort(t, kind="stable")
    distinct = [int(order[0])]
    for i in order[1:]:
        if t[i] - t[distinct[-1]] > POSITION_TOLERANCE_MM:
            distinct.append(int(i))
    t_planes = t[distinct]
    if len(distinct) == 1:
        step_t = thickness or 1.0
        direction = normal
    else:
        # spacing from the frame positions (SpacingBetweenSlices is often wrong); frames
        # of empty planes may be omitted, so planes must sit at whole multiples of it
        step_t = float(np.diff(t_planes).min())
        if step_t <= 4 * _position_tolerance(step_t):
            raise GeometryError(
                f"frames of {path} lie only {step_t:.4g} mm apart along the slice normal: "
                "too close to tell planes apart; check the frame positions"
            )
        direction = _line_fit(pos[distinct], t_planes, [f"frame {i + 1}" for i in distinct])
        if thickness is not None and abs(thickness - step_t) > _position_tolerance(step_t):
            logger.debug(
                "%s: SpacingBetweenSlices/SliceThickness %.4g mm differs from the frame "
                "spacing %.4g mm; using the frame spacing", path, thickness, step_t,
            )
    steps = (t - t_planes[0]) / step_t
    off_grid = np.abs(steps - np.rint(steps)) * step_t
    tol = _position_tolerance(step_t)
    if np.any(off_grid > tol):
        worst = int(np.argmax(off_grid))
        raise GeometryError(
            f"frames of {path} are not evenly spaced: frame {worst + 1} lies {off_grid[worst]:.4g} "
            f"mm off the grid of planes {step_t:.4g} mm apart (tolerance {tol:.3g} mm)"
        )
    frame_plane = np.rint(steps).astype(np.int64)
    for f in range(n_frames):  # in-plane origin must follow the same line
        expected = pos[distinct[0]] + steps[f] * step_t * direction
        if np.linalg.norm(pos[f] - expected) > tol:
            raise GeometryError(
                f"frames of {path} do not share one grid: frame {f + 1} is shifted in-plane "
                f"by {np.linalg.norm(pos[f] - expected):.4g} mm"
            )
    seg_arr = np.asarray(segment_numbers, dtype=np.int64)
    keys = frame_plane * (int(seg_arr.max()) + 1) + seg_arr
    if np.unique(keys).size != keys.size:
        raise GeometryError(f"{path} holds two frames of one segment at the same position")

    affine = np.eye(4)
    affine[:3, 0] = row * spacing[1]
    affine[:3, 1] = col * spacing[0]
    affine[:3, 2] = direction * step_t
    affine[:3, 3] = pos[distinct[0]]
    shape = (columns, rows, int(frame_plane.max()) + 1)
    return _SegGeometry(affine, shape, frame_plane, seg_arr)


def _seg_frames(ds: Any, path: Path, n_frames: int) -> NDArray[np.bool_]:
    """Foreground of every frame, shape (frames, Rows, Columns)."""
    seg_type = str(ds.get("SegmentationType", "")).upper()
    if seg_type not in ("BINARY", "FRACTIONAL"):
        raise InputError(
            f"{path}: SegmentationType {seg_type or '(missing)'} is not supported; "
            "slicerecon reads BINARY and FRACTIONAL segmentations"
        )
    try:
        pixels = np.asarray(ds.pixel_array)
    except PARSE_ERRORS as exc:
        raise FormatError(
            f"cannot decode the pixel data of {path} ({type(exc).__name__}: {exc})"
        ) from exc
    rows, columns = int(ds.Rows), int(ds.Columns)
    if pixels.ndim == 2:  # pydicom drops the frame axis when NumberOfFrames is 1
        pixels = pixels[None]
    if pixels.shape != (n_frames, rows, columns):
        raise FormatError(
            f"{path}: pixel data has shape {pixels.shape}, expected ({n_frames}, {rows}, {columns})"
        )
    if seg_type == "BINARY":
        return pixels != 0
    max_value = _optional_float(ds, "MaximumFractionalValue") or 255.0
    return pixels >= 0.5 * max_value


def read_dicom_seg(
    path: str | os.PathLike[str],
    *,
    segment: int | str | None = None,
    memory_budget_gb: float = DEFAULT_MEMORY_BUDGET_GB,
) -> Volume:
    """Read one segment of a DICOM SEG (Segmentation Storage) file as a mask.

    Parameters
    ----------
    path : path-like
        A DICOM SEG file (SOP class 1.2.840.10008.5.1.4.1.1.66.4), BINARY or
        FRACTIONAL (foreground where the value is at least half of
        MaximumFractionalValue).
    segment : int or str, optional
        SegmentNumber or SegmentLabel (exact, then case-insensitive) of the
        segment to read. Default: the only segment; with several, LabelError.
    memory_budget_gb : float
        Refuse files whose grid would not fit this budget, GiB
        (:func:`slicerecon.io.limits.check_grid`), before decoding any frame.

    Returns
    -------
    Volume
        Mask of shape ``(Columns, Rows, planes)``; affine to DICOM patient LPS mm.
        The planes run from the lowest to the highest frame position of *all*
        segments along ``row_cosine × column_cosine``, so every segment of one
        file is read onto the same grid. The plane step is the smallest gap
        between frame positions (SpacingBetweenSlices is only a fallback for a
        single plane); planes whose frames were omitted are empty.

    Raises
    ------
    InputError
        Missing file, not a SEG, unsupported SegmentationType.
    LabelError
        ``segment`` is absent, or None with several segments (they are listed).
    GeometryError
        Frames not parallel, not on evenly spaced planes, or shifted in-plane.
    FormatError
        Corrupt file or missing functional groups.
    EmptyMaskError
        The chosen segment has no foreground pixel.
    """
    p = Path(path)
    ds = _read_seg_dataset(p, stop_before_pixels=False)
    segments = _seg_segments(ds, p)
    number = _choose_segment(segments, segment, p)
    geometry = _seg_geometry(ds, p)
    check_geometry(geometry.affine, geometry.shape, what=str(p))
    check_grid(geometry.shape, what=str(p), memory_budget_gb=memory_budget_gb, bytes_per_voxel=1)
    check_grid((geometry.frame_plane.size, *geometry.shape[:2]), what=f"{p} (frames)",
               memory_budget_gb=memory_budget_gb, bytes_per_voxel=2)
    unknown = sorted(set(geometry.frame_segment.tolist()) - set(segments))
    if unknown:
        raise FormatError(f"{p}: frames refer to segments {unknown} missing from SegmentSequence")
    frames = _seg_frames(ds, p, geometry.frame_plane.size)
    mask = np.zeros(geometry.shape, dtype=bool)
    for f in np.flatnonzero(geometry.frame_segment == number):
        mask[:, :, geometry.frame_plane[f]] |= frames[f].T
    if not mask.any():
        raise EmptyMaskError(
            f"segment {number} ({segments[number] or 'no label'}) of {p} has no foreground pixel"
        )
    logger.info("read DICOM SEG %s segment %d (%s), grid %s", p, number, segments[number],
                geometry.shape)
    return Volume(mask, geometry.affine)


# ----------------------------------------------------------------------------- info
def _spacing_list(affine: NDArray[np.float64]) -> list[float]:
    return [round(float(v), 6) for v in np.linalg.norm(affine[:3, :3], axis=0)]


def _orientation_list(affine: NDArray[np.float64]) -> list[float]:
    cos = affine[:3, :2] / np.linalg.norm(affine[:3, :2], axis=0)
    return [round(float(v), 6) for v in np.concatenate([cos[:, 0], cos[:, 1]])]


def dicom_info(path: str | os.PathLike[str], *, allow_irregular: bool = True) -> dict[str, Any]:
    """Describe a DICOM image-series directory or a DICOM SEG file (headers only).

    Parameters
    ----------
    path : path-like
        A series directory or a SEG file.

    Returns
    -------
    dict
        JSON-ready. Both kinds: ``kind`` ("dicom-series" / "dicom-seg"),
        ``shape`` [I, J, K], ``spacing_mm`` [3], ``orientation`` (the six
        ImageOrientationPatient cosines), ``origin_mm`` [3] and
        ``coordinates`` ("LPS"). Series: ``modality``, ``series_instance_uid``,
        ``n_slices``, ``regular_spacing`` and ``slice_gap_mm`` {min, max} (an
        irregular series is described on the grid ``allow_irregular`` would give).
        SEG: ``segmentation_type``, ``n_frames`` and ``segments``, a list of
        ``{number, label, n_frames}``.

    Raises
    ------
    InputError
        Not a series directory nor a SEG file (or the errors of the readers).
    """
    p = Path(path)
    if p.is_dir():
        slices = _scan_series(p, stop_before_pixels=True)
        layout = _layout(slices, allow_irregular=allow_irregular)
        first = layout.slices[0].dataset
        gaps = layout.gaps_mm
        return {
            "kind": "dicom-series",
            "modality": str(first.get("Modality", "")),
            "series_instance_uid": layout.slices[0].series_uid,
            "n_slices": len(layout.slices),
            "shape": list(layout.shape),
            "spacing_mm": _spacing_list(layout.affine),
            "orientation": _orientation_list(layout.affine),
            "origin_mm": [round(float(v), 6) for v in layout.affine[:3, 3]],
            "regular_spacing": layout.regular,
            "slice_gap_mm": {
                "min": round(float(gaps.min()), 6) if gaps.size else None,
                "max": round(float(gaps.max()), 6) if gaps.size else None,
            },
            "coordinates": "LPS",
        }
    ds = _read_seg_dataset(p, stop_before_pixels=True)
    segments = _seg_segments(ds, p)
    geometry = _seg_geometry(ds, p)
    counts = {n: int(np.count_nonzero(geometry.frame_segment == n)) for n in segments}
    return {
        "kind": "dicom-seg",
        "segmentation_type": str(ds.get("SegmentationType", "")),
        "n_frames": int(geometry.frame_plane.size),
        "shape": list(geometry.shape),
        "spacing_mm": _spacing_list(geometry.affine),
        "orientation": _orientation_list(geometry.affine),
        "origin_mm": [round(float(v), 6) for v in geometry.affine[:3, 3]],
        "segments": [
            {"number": n, "label": segments[n], "n_frames": counts[n]} for n in sorted(segments)
        ],
        "coordinates": "LPS",
    }
