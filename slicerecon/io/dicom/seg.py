"""DICOM SEG (Segmentation Storage): one segment of a BINARY or FRACTIONAL SEG as a mask.

Who does what
-------------
* **highdicom** decodes the segments into a volume
  (:meth:`highdicom.seg.Segmentation.get_volume`): it maps frames to segments
  through the Multi-frame Dimension module, stacks them by position, leaves
  omitted (empty) frames empty and decodes every transfer syntax it knows.
* **Ours** are the header checks that must come *before* any frame is decoded
  (the grid against the memory budget, the geometry against absurd values) and
  that name what is wrong (which frame is off the grid, by how much): see
  :func:`_seg_geometry`. highdicom's volume is placed on that grid and must
  agree with it plane by plane.
* Files highdicom does not read (no DimensionIndexSequence, no
  SharedFunctionalGroupsSequence, segments without their coded properties,
  frames stacked along a tilted line as after a CT gantry tilt) are decoded
  frame by frame with pydicom and placed by the same grid, so every SEG read
  before is read the same way now. ``docs/formats.md`` lists the cases.

The grid follows the convention of :mod:`.series` (array axes (column, row,
plane), DICOM patient LPS mm); its planes run from the lowest to the highest
frame position of *all* segments along ``row_cosine × column_cosine``, so every
segment of one file is read onto the same grid.
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ...errors import EmptyMaskError, FormatError, GeometryError, InputError
from ...sections import Volume
from ...selection import choose_structure, parse_selector
from ..limits import DEFAULT_MEMORY_BUDGET_GB, check_geometry, check_grid
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
from .sniff import PARSE_ERRORS, SEG_SOP_CLASS_UID, read_dicom_header

__all__ = ["SEGMENTATION_TYPES", "read_dicom_seg", "seg_info"]

logger = logging.getLogger(__name__)

SEGMENTATION_TYPES = ("BINARY", "FRACTIONAL")
MAX_SLICES_BETWEEN_FRAMES = 50
"""Frames further apart than this many declared slice spacings keep the frame spacing."""
"""SegmentationType values read (LABELMAP is refused)."""


@dataclass(frozen=True)
class _SegGeometry:
    """Where each frame of a SEG lies on a regular grid."""

    affine: NDArray[np.float64]
    shape: tuple[int, int, int]
    frame_plane: NDArray[np.int64]
    frame_segment: NDArray[np.int64]
    tolerance_mm: float


def _read_seg_dataset(path: str | os.PathLike[str], *, stop_before_pixels: bool) -> Any:
    p = require_path(path, want_dir=False)
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


VALUE_DESCRIPTION = "label value "
"""How slicerecon's SEG writer records a segment's label value in its SegmentDescription."""


def _segment_extras(ds: Any) -> dict[int, tuple[int, list[int] | None]]:
    """Segment number → (label value, display colour RGB or None).

    The label value is the one slicerecon's writer records (SegmentDescription
    ``"label value 4"``) when every segment records one and no two share it, so a
    ``seg.dcm`` read back keeps its label map's values; otherwise the SegmentNumber.
    The colour is RecommendedDisplayCIELabValue converted to RGB (highdicom).
    """
    from highdicom.color import CIELabColor

    out: dict[int, tuple[int, list[int] | None]] = {}
    recorded: dict[int, int] = {}
    for item in ds.get("SegmentSequence", None) or []:
        try:
            number = int(item.SegmentNumber)
        except PARSE_ERRORS:
            continue
        colour = None
        try:
            lab = item.get("RecommendedDisplayCIELabValue", None)
            if lab is not None and len(lab) == 3:
                colour = [int(c) for c in CIELabColor.from_dicom_value(list(lab)).to_rgb()]
        except (*PARSE_ERRORS, ValueError):  # a malformed colour is no colour
            colour = None
        description = str(item.get("SegmentDescription", "") or "")
        if description.startswith(VALUE_DESCRIPTION):
            try:
                recorded[number] = int(description[len(VALUE_DESCRIPTION) :])
            except ValueError:
                pass
        out[number] = (number, colour)
    values = list(recorded.values())
    if set(recorded) == set(out) and len(set(values)) == len(values) and min(values, default=1) > 0:
        out = {n: (recorded[n], colour) for n, (_, colour) in out.items()}
    return out


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
    between: float | None = None
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
        orientations.append(floats(orient, "ImageOrientationPatient", 6, where))
        positions.append(floats(plane, "ImagePositionPatient", 3, where))
        try:
            segment_numbers.append(int(ident.ReferencedSegmentNumber))
        except PARSE_ERRORS as exc:
            raise FormatError(f"{where}: ReferencedSegmentNumber is missing") from exc
        if measures is not None and spacing is None:
            spacing = floats(measures, "PixelSpacing", 2, where)
            between = optional_float(measures, "SpacingBetweenSlices")
            thickness = optional_float(measures, "SliceThickness")
    if spacing is None:
        raise FormatError(f"{path} has no PixelMeasuresSequence/PixelSpacing")
    if np.any(spacing <= 0):
        raise FormatError(f"{path}: PixelSpacing must be positive (got {spacing.tolist()})")
    orient_arr = np.array(orientations)
    if np.max(np.abs(orient_arr - orient_arr[0])) > ORIENTATION_TOLERANCE:
        raise GeometryError(f"frames of {path} are not parallel: ImageOrientationPatient differs")
    row, col = unit_cosines(orient_arr[0], path)
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
        step_t = between or thickness or 1.0
        direction = normal
    else:
        # spacing from the frame positions (SpacingBetweenSlices is often wrong); frames
        # of empty planes may be omitted, so planes must sit at whole multiples of it
        step_t = float(np.diff(t_planes).min())
        if step_t <= 4 * position_tolerance(step_t):
            raise GeometryError(
                f"frames of {path} lie only {step_t:.4g} mm apart along the slice normal: "
                "too close to tell planes apart; check the frame positions"
            )
        direction = line_fit(pos[distinct], t_planes, [f"frame {i + 1}" for i in distinct])
        # frames on some slices of a series (every 2nd, or irregular): the planes are that
        # series' slices, and those without a frame are not annotated. The series' step is
        # SpacingBetweenSlices, or SliceThickness: a writer may give the frames' own spacing
        # as SpacingBetweenSlices (highdicom does), and frames thinner than their gaps by a
        # whole factor are slices with slices between them
        lattice = next(
            (s for s in (between, thickness) if _drawn_on_some_slices(t_planes, s)), None
        )
        declared = between or thickness
        if lattice is not None:
            step_t = lattice
        elif declared is not None and abs(declared - step_t) > position_tolerance(step_t):
            logger.debug(
                "%s: SpacingBetweenSlices/SliceThickness %.4g mm differs from the frame "
                "spacing %.4g mm; using the frame spacing",
                path,
                declared,
                step_t,
            )
    steps = (t - t_planes[0]) / step_t
    off_grid = np.abs(steps - np.rint(steps)) * step_t
    tol = position_tolerance(step_t)
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
    return _SegGeometry(affine, shape, frame_plane, seg_arr, tol)


def _drawn_on_some_slices(t_planes: NDArray[np.float64], spacing: float | None) -> bool:
    """Whether frames at positions ``t_planes`` (mm along the normal, sorted) lie on slices
    ``spacing`` mm apart (SpacingBetweenSlices, else SliceThickness) with some slices
    between them: a segmentation drawn on some slices of its series."""
    if spacing is None or not spacing > 0:
        return False
    gaps = np.diff(t_planes) / spacing
    if gaps.min() < 1.5 or gaps.max() > MAX_SLICES_BETWEEN_FRAMES:
        return False
    return bool(np.all(np.abs(gaps - np.rint(gaps)) * spacing <= position_tolerance(spacing)))


def _segmentation_type(ds: Any, path: Path) -> str:
    seg_type = str(ds.get("SegmentationType", "")).upper()
    if seg_type not in SEGMENTATION_TYPES:
        raise InputError(
            f"{path}: SegmentationType {seg_type or '(missing)'} is not supported; "
            "slicerecon reads BINARY and FRACTIONAL segmentations"
        )
    return seg_type


def _fractional_bits(ds: Any, path: Path, seg_type: str) -> int:
    """BitsAllocated of a FRACTIONAL SEG (8, or 16 with a warning); 1 for BINARY.

    The standard stores fractional segments in 8 bits; a 16-bit one (whose
    MaximumFractionalValue may reach 65535) is decoded by pydicom as its
    BitsAllocated says, not by highdicom, which would cut its values to 8 bits.

    Raises
    ------
    FormatError
        BitsAllocated not 8 or 16, or a MaximumFractionalValue that is not a
        whole number from 1 to ``2**BitsAllocated - 1``.
    """
    if seg_type != "FRACTIONAL":
        return 1
    try:
        bits = int(ds.get("BitsAllocated", 8) or 8)
    except PARSE_ERRORS as exc:
        raise FormatError(f"{path}: BitsAllocated is not a number ({exc})") from exc
    if bits not in (8, 16):
        raise FormatError(
            f"{path}: a FRACTIONAL SEG stores 8-bit values (BitsAllocated 8), not {bits}-bit ones"
        )
    if bits == 16:
        logger.warning(
            "%s: a FRACTIONAL SEG with 16-bit values is not standard (the standard stores "
            "8 bits); its values are read as 16-bit, against MaximumFractionalValue",
            path,
        )
    try:
        given = ds.get("MaximumFractionalValue")
        maximum = None if given is None or given == "" else float(given)
    except PARSE_ERRORS as exc:
        raise FormatError(f"{path}: MaximumFractionalValue is not a number ({exc})") from exc
    if maximum is not None and not (1 <= maximum < 2**bits and maximum == int(maximum)):
        raise FormatError(
            f"{path}: MaximumFractionalValue {maximum:g} is not a whole number from 1 to "
            f"{2**bits - 1} ({bits}-bit values)"
        )
    return bits


def _foreground(values: NDArray[Any], ds: Any, seg_type: str) -> NDArray[np.bool_]:
    """Stored values → foreground: non-zero (BINARY), at least half the maximum (FRACTIONAL)."""
    if seg_type == "BINARY":
        return values != 0
    max_value = optional_float(ds, "MaximumFractionalValue") or 255.0
    return values >= 0.5 * max_value


def _mask_by_highdicom(
    ds: Any, path: Path, number: int, geometry: _SegGeometry, seg_type: str
) -> NDArray[np.bool_] | None:
    """Segment ``number`` decoded by highdicom onto ``geometry``'s grid, or None.

    None when highdicom is not installed, refuses the dataset (see the module
    docstring), or stacks the frames otherwise than ``geometry`` does; the
    caller then decodes the frames itself. ``ds`` is modified in place.
    """
    try:
        from highdicom.seg import Segmentation
    except ImportError:
        logger.warning(
            "highdicom is not installed; %s is decoded frame by frame with pydicom", path
        )
        return None
    try:
        segmentation = Segmentation.from_dataset(ds, copy=False)
        volume = segmentation.get_volume(
            segment_numbers=[number],
            allow_missing_positions=True,
            rescale_fractional=False,
            atol=geometry.tolerance_mm,
        )
        stored = np.asarray(volume.array)[..., 0]  # (planes, Rows, Columns)
        hd_affine = np.asarray(volume.affine, dtype=np.float64)  # (plane, row, column) → LPS
    except MemoryError:
        raise
    except Exception as exc:  # noqa: BLE001 - a dataset highdicom does not read: decode it here
        logger.debug(
            "highdicom does not read %s (%s: %s); decoding its frames with pydicom",
            path,
            type(exc).__name__,
            exc,
        )
        return None

    affine, (columns, rows, planes) = geometry.affine, geometry.shape
    tol = geometry.tolerance_mm
    # highdicom's row and column steps must be ours, and each of its planes one of ours
    same_pixels = (
        stored.shape[1:] == (rows, columns)
        and np.allclose(hd_affine[:3, 2], affine[:3, 0], rtol=0, atol=1e-6)
        and np.allclose(hd_affine[:3, 1], affine[:3, 1], rtol=0, atol=1e-6)
    )
    origins = hd_affine[:3, 3] + np.arange(stored.shape[0])[:, None] * hd_affine[:3, 0]
    index = (np.linalg.inv(affine) @ np.c_[origins, np.ones(len(origins))].T)[:3].T
    plane = np.rint(index[:, 2]).astype(np.int64)
    world_error = (
        np.linalg.norm(origins - (affine[:3, 3] + plane[:, None] * affine[:3, 2]), axis=1)
        if len(origins)
        else np.zeros(0)
    )
    if not (same_pixels and np.all((plane >= 0) & (plane < planes)) and np.all(world_error <= tol)):
        logger.debug(
            "highdicom stacks the frames of %s otherwise than its frame positions; "
            "decoding its frames with pydicom",
            path,
        )
        return None
    mask = np.zeros(geometry.shape, dtype=bool)
    for k, values in zip(plane, stored, strict=True):
        mask[:, :, k] |= _foreground(values, ds, seg_type).T
    logger.debug("%s decoded by highdicom", path)
    return mask


def _mask_by_frames(
    ds: Any, path: Path, number: int, geometry: _SegGeometry, seg_type: str
) -> NDArray[np.bool_]:
    """Segment ``number`` decoded frame by frame with pydicom and placed by ``geometry``."""
    n_frames = geometry.frame_plane.size
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
    mask = np.zeros(geometry.shape, dtype=bool)
    for f in np.flatnonzero(geometry.frame_segment == number):
        mask[:, :, geometry.frame_plane[f]] |= _foreground(pixels[f], ds, seg_type).T
    return mask


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
        between frame positions, or SpacingBetweenSlices (else SliceThickness)
        for a single plane and when every gap is a whole multiple (2 to 50) of
        it (frames drawn on some slices of a series); planes whose frames were
        omitted are empty.

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
    MemoryBudgetError
        The grid exceeds ``memory_budget_gb``.
    """
    p = Path(path)
    ds = _read_seg_dataset(p, stop_before_pixels=False)
    segments = _seg_segments(ds, p)
    number = _choose_segment(segments, segment, p)
    geometry = _seg_geometry(ds, p)
    check_geometry(geometry.affine, geometry.shape, what=str(p))
    check_grid(geometry.shape, what=str(p), memory_budget_gb=memory_budget_gb, bytes_per_voxel=1)
    check_grid(
        (geometry.frame_plane.size, *geometry.shape[:2]),
        what=f"{p} (frames)",
        memory_budget_gb=memory_budget_gb,
        bytes_per_voxel=2,
    )
    unknown = sorted(set(geometry.frame_segment.tolist()) - set(segments))
    if unknown:
        raise FormatError(f"{p}: frames refer to segments {unknown} missing from SegmentSequence")
    seg_type = _segmentation_type(ds, p)
    mask = None
    if _fractional_bits(ds, p, seg_type) != 16:  # highdicom cuts 16-bit fractional values
        mask = _mask_by_highdicom(ds, p, number, geometry, seg_type)
    if mask is None:  # highdicom changed ds in place: read the file again
        mask = _mask_by_frames(
            _read_seg_dataset(p, stop_before_pixels=False), p, number, geometry, seg_type
        )
    if not mask.any():
        raise EmptyMaskError(
            f"segment {number} ({segments[number] or 'no label'}) of {p} has no foreground pixel"
        )
    logger.info(
        "read DICOM SEG %s segment %d (%s), grid %s", p, number, segments[number], geometry.shape
    )
    return Volume(mask, geometry.affine)


def seg_info(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Describe a DICOM SEG file from its headers (see :func:`dicom_info`)."""
    p = Path(path)
    ds = _read_seg_dataset(p, stop_before_pixels=True)
    segments = _seg_segments(ds, p)
    geometry = _seg_geometry(ds, p)
    counts = {n: int(np.count_nonzero(geometry.frame_segment == n)) for n in segments}
    extras = _segment_extras(ds)
    return {
        "kind": "dicom-seg",
        "segmentation_type": str(ds.get("SegmentationType", "")),
        "n_frames": int(geometry.frame_plane.size),
        "shape": list(geometry.shape),
        "spacing_mm": spacing_list(geometry.affine),
        "orientation": orientation_list(geometry.affine),
        "origin_mm": [round(float(v), 6) for v in geometry.affine[:3, 3]],
        "segments": [
            {
                "number": n,
                "label": segments[n],
                "value": extras.get(n, (n, None))[0],
                "colour": extras.get(n, (n, None))[1],
                "n_frames": counts[n],
            }
            for n in sorted(segments)
        ],
        "coordinates": "LPS",
    }
