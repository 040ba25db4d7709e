"""DICOM RT Structure Set (RTSTRUCT): the closed planar contours of one ROI.

An RTSTRUCT lists its regions of interest in StructureSetROISequence
(ROINumber, ROIName) and their contours in ROIContourSequence: each item names
its ROI by ReferencedROINumber and holds a ContourSequence whose items carry a
ContourGeometricType and ContourData, a flat list ``x1, y1, z1, x2, ...`` in
DICOM patient coordinates (LPS, mm). Only CLOSED_PLANAR contours bound areas;
POINT, OPEN_PLANAR and OPEN_NONPLANAR ones are skipped with a warning.

Coordinates stay in LPS mm (nothing is flipped), like the DICOM image readers,
so a reconstruction overlays the images the structure set was drawn on. With
the image series (``image_dir``) the contours are rasterized on its voxel grid;
without it, on a grid built from the contours alone
(:func:`slicerecon.io.polygons.sections_from_polygons`). See
``docs/formats.md``.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..annotation import Annotation, annotation_from_sections
from ..errors import (
    EmptyMaskError,
    FormatError,
    InputError,
    OptionError,
    SlicereconError,
)
from ..labels import Structure
from ..sections import CrossSections
from ..selection import choose_structure, parse_selector
from .dicom.derived import roi_frames
from .dicom.series import dicom_series_geometry, referenced_series
from .dicom.sniff import PARSE_ERRORS, object_kind, read_dicom_header
from .limits import DEFAULT_MEMORY_BUDGET_GB, reading
from .plane_groups import annotation_from_polygons, grid_axis_of, orientation_count
from .polygons import encloses_area, polygon_normal, sections_from_polygons

__all__ = [
    "list_rois",
    "read_rtstruct",
    "read_rtstruct_annotation",
    "read_rtstruct_structures",
    "roi_contours",
]

logger = logging.getLogger(__name__)


def _read_dataset(path: str | os.PathLike[str]) -> tuple[Any, Path]:
    """The RTSTRUCT dataset, or InputError / FormatError."""
    p = Path(path)
    if not p.exists():
        raise InputError(f"RTSTRUCT file not found: {p}")
    if not p.is_file():
        raise InputError(f"{p} is a directory; pass the RTSTRUCT file itself")
    ds = read_dicom_header(p, stop_before_pixels=True)
    modality = str(ds.get("Modality", "") or "")
    if object_kind(ds) != "rtstruct" or "StructureSetROISequence" not in ds:
        raise FormatError(
            f"{p} is not a DICOM RTSTRUCT (Modality {modality or 'missing'}"
            + ("" if "StructureSetROISequence" in ds else ", no StructureSetROISequence")
            + "); pass an RT Structure Set file"
        )
    return ds, p


def _rois(ds: Any, path: Path) -> list[tuple[int, str]]:
    out = []
    for n, item in enumerate(ds.StructureSetROISequence):
        try:
            number = int(item.ROINumber)
        except PARSE_ERRORS as exc:
            raise FormatError(
                f"{path}: StructureSetROISequence[{n}] has no valid ROINumber"
            ) from exc
        out.append((number, str(item.get("ROIName", "") or "")))
    return out


def list_rois(path: str | os.PathLike[str]) -> list[tuple[int, str]]:
    """The regions of interest of an RTSTRUCT.

    Parameters
    ----------
    path : path-like
        An RTSTRUCT file.

    Returns
    -------
    list of (int, str)
        ``(ROINumber, ROIName)`` in the file's order (name ``""`` when absent).

    Raises
    ------
    InputError
        Missing file.
    FormatError
        Not a DICOM RTSTRUCT.
    """
    ds, p = _read_dataset(path)
    return _rois(ds, p)


def _choose_roi(rois: list[tuple[int, str]], roi: int | str | None, path: Path) -> tuple[int, str]:
    if not rois:
        raise EmptyMaskError(f"{path} holds no ROI (its StructureSetROISequence is empty)")
    names = dict(rois)
    number = choose_structure(names, parse_selector(roi), kind="ROI", source=path)
    return number, names[number]


def _contour_points(item: Any, where: str, path: Path) -> NDArray[np.float64]:
    try:
        data = np.asarray([float(v) for v in item.ContourData], dtype=np.float64)
    except PARSE_ERRORS as exc:
        raise FormatError(f"{path}: {where} has no valid ContourData ({exc})") from exc
    if data.size % 3 or not np.all(np.isfinite(data)):
        raise FormatError(
            f"{path}: {where}: ContourData must hold finite x, y, z triplets "
            f"(got {data.size} values)"
        )
    points = data.reshape(-1, 3)
    declared = item.get("NumberOfContourPoints")
    if declared is not None and int(declared) != points.shape[0]:
        logger.warning(
            "%s: %s declares %d points but ContourData holds %d; using ContourData",
            path,
            where,
            int(declared),
            points.shape[0],
        )
    return points


def _roi_polygons(
    ds: Any, number: int, name: str, path: Path
) -> tuple[list[NDArray[np.float64]], list[str], set[str]]:
    """Closed planar polygons of ROI ``number``, their names, referenced image UIDs."""
    label = f"ROI {number} ({name or 'no name'})"
    items = [
        item
        for item in ds.get("ROIContourSequence", [])
        if "ReferencedROINumber" in item and int(item.ReferencedROINumber) == number
    ]
    contours = [c for item in items for c in item.get("ContourSequence", [])]
    if not contours:
        raise EmptyMaskError(f"{path}: {label} has no contours")
    polygons: list[NDArray[np.float64]] = []
    names: list[str] = []
    image_uids: set[str] = set()
    skipped: dict[str, int] = {}
    flat: list[str] = []  # contours that enclose no area
    for n, contour in enumerate(contours, start=1):  # numbered as ContourSequence items
        where = f"{label} contour {n}"
        kind = str(contour.get("ContourGeometricType", "") or "").strip().upper()
        if kind != "CLOSED_PLANAR":
            skipped[kind or "(missing type)"] = skipped.get(kind or "(missing type)", 0) + 1
            continue
        points = _contour_points(contour, where, path)
        if points.shape[0] > 1 and np.array_equal(points[0], points[-1]):
            points = points[:-1]
        if points.shape[0] < 3 or not encloses_area(points):
            flat.append(str(n))
            continue
        polygons.append(points)
        names.append(where)
        for ref in contour.get("ContourImageSequence", []):
            uid = str(ref.get("ReferencedSOPInstanceUID", "") or "")
            if uid:
                image_uids.add(uid)
    if flat:
        logger.warning(
            "%s: %s contour%s %s enclose%s no area (a point or a line); skipped",
            path,
            label,
            "s" if len(flat) > 1 else "",
            ", ".join(flat),
            "" if len(flat) > 1 else "s",
        )
    listed = ", ".join(f"{count} {kind}" for kind, count in skipped.items())
    if not polygons:  # one line: what it has instead (a POINT isocentre marker)
        instead = f" ({listed} contours skipped: only CLOSED_PLANAR bound an area)"
        raise EmptyMaskError(
            f"{path}: {label} has no closed planar contour{instead * bool(listed)}"
        )
    if skipped:
        logger.warning(
            "%s: %s: skipped %s contours (only CLOSED_PLANAR bound an area)", path, label, listed
        )
    return polygons, names, image_uids


def roi_contours(
    path: str | os.PathLike[str],
) -> list[tuple[int, str, list[NDArray[np.float64]], str]]:
    """Every ROI of an RTSTRUCT with its closed planar contours, refusing none.

    Parameters
    ----------
    path : path-like
        An RTSTRUCT file.

    Returns
    -------
    list of (number, name, polygons, note)
        In the file's order: ROINumber, ROIName, the closed planar polygons
        (each an ndarray of shape (N, 3), LPS mm) and, when there are none, a
        note saying why (``""`` otherwise).

    Raises
    ------
    InputError, FormatError
        Missing file, not an RTSTRUCT, malformed ContourData.
    """
    ds, p = _read_dataset(path)
    out: list[tuple[int, str, list[NDArray[np.float64]], str]] = []
    for number, name in _rois(ds, p):
        try:
            polygons, _, _ = _roi_polygons(ds, number, name, p)
        except EmptyMaskError as exc:
            out.append((number, name, [], str(exc).rsplit(" has ", 1)[-1]))
        else:
            out.append((number, name, polygons, ""))
    return out


def read_rtstruct(
    path: str | os.PathLike[str],
    *,
    roi: int | str | None = None,
    image_dir: str | os.PathLike[str] | None = None,
    pixel_spacing: float | None = None,
    allow_irregular: bool = False,
    memory_budget_gb: float = DEFAULT_MEMORY_BUDGET_GB,
) -> CrossSections:
    """Read the closed planar contours of one ROI of an RTSTRUCT as cross-sections.

    Parameters
    ----------
    path : path-like
        An RTSTRUCT file.
    roi : int or str, optional
        ROINumber, or ROIName (exact, else case- and space-insensitive; a
        string of digits that names no ROI is taken as a number). Default: the
        only ROI of the file.
    image_dir : path-like, optional
        Directory of the image series the structure set refers to. The
        contours are then rasterized on its voxel grid
        (:func:`slicerecon.io.dicom.dicom_series_geometry`) and the plane
        indices are slice numbers of that series.
    pixel_spacing : float, optional
        In-plane pixel size, mm, of the grid built from the contours when no
        ``image_dir`` is given (default: longest in-plane extent / 256).
        Ignored, with a warning, with ``image_dir``.
    allow_irregular : bool
        Accept an image series with uneven slice spacing
        (:func:`slicerecon.io.dicom.dicom_series_geometry`).
    memory_budget_gb : float
        Refuse contours whose grid would not fit this budget, GiB, before any
        plane is rasterized (:func:`slicerecon.io.limits.check_grid`).

    Returns
    -------
    CrossSections
        One plane per contoured slice position, in LPS mm geometry. Contours
        of one plane are combined by the even-odd rule (a contour inside
        another is a hole).

    Raises
    ------
    InputError
        Missing file.
    FormatError
        Not an RTSTRUCT, or malformed ContourData.
    LabelError
        ``roi`` absent, or not given while the file has several ROIs (the
        message lists ``number: name`` pairs).
    EmptyMaskError
        The ROI has no closed planar contour.
    GeometryError
        Contours not on parallel planes, or not fitting the image grid.
    """
    ds, p = _read_dataset(path)
    number, name = _choose_roi(_rois(ds, p), roi, p)
    polygons, names, image_uids = _roi_polygons(ds, number, name, p)
    reference = None
    if image_dir is not None:
        affine, shape, series_uids = dicom_series_geometry(
            image_dir, allow_irregular=allow_irregular
        )
        _say_unnamed(p, image_uids, image_dir, series_uids)
        reference = (affine, shape)
        if pixel_spacing is not None:
            logger.warning("pixel_spacing ignored: the grid of %s is used", image_dir)
            pixel_spacing = None
    try:
        sections = sections_from_polygons(
            polygons,
            pixel_spacing=pixel_spacing,
            reference=reference,
            polygon_names=names,
            memory_budget_gb=memory_budget_gb,
            own_planes=True,
        )
    except OptionError:
        raise
    except SlicereconError as exc:
        raise type(exc)(f"{p}: {exc}") from exc
    logger.info(
        "%s: ROI %d (%s): %d contours on %d planes",
        p,
        number,
        name,
        len(polygons),
        sections.n_planes,
    )
    return sections


def _roi_colours(ds: Any) -> dict[int, tuple[int, int, int]]:
    """ROIDisplayColor of each ROI that has one (RGB 0-255)."""
    colours: dict[int, tuple[int, int, int]] = {}
    for item in ds.get("ROIContourSequence", []):
        try:
            number = int(item.ReferencedROINumber)
            rgb = [int(v) for v in item.get("ROIDisplayColor", [])]
        except PARSE_ERRORS:
            continue
        if len(rgb) == 3:
            colours[number] = (rgb[0], rgb[1], rgb[2])
    return colours


def read_rtstruct_structures(
    path: str | os.PathLike[str],
    *,
    rois: Sequence[int | str] = (),
    image_dir: str | os.PathLike[str] | None = None,
    pixel_spacing: float | None = None,
    allow_irregular: bool = False,
    memory_budget_gb: float = DEFAULT_MEMORY_BUDGET_GB,
) -> tuple[list[Structure], list[CrossSections | None], CrossSections]:
    """Every ROI of an RTSTRUCT (or those chosen) as cross-sections on one shared grid.

    The grid is the one :func:`read_rtstruct` would build for all the chosen
    ROIs' contours together (the image series' grid with ``image_dir``, its
    slice axis rebuilt on the contour planes when they lie between slices), so
    that every ROI is rasterized on the same voxels and they can be resolved
    against each other.

    Parameters
    ----------
    path : path-like
        An RTSTRUCT file.
    rois : sequence of int or str
        ROINumbers or ROINames to keep (default: every ROI).
    image_dir, pixel_spacing, allow_irregular, memory_budget_gb
        As for :func:`read_rtstruct`.

    Returns
    -------
    structures : list of Structure
        Every chosen ROI (number, name, ROIDisplayColor), in the file's order.
    sections : list of CrossSections or None
        Each ROI's planes on the shared grid; None for an ROI without closed
        planar contours (reported with a warning).
    union : CrossSections
        All the chosen ROIs' planes together on that grid.

    Raises
    ------
    InputError, FormatError, GeometryError
        As :func:`read_rtstruct`.
    EmptyMaskError
        No chosen ROI has a closed planar contour.
    """
    with reading(path):
        return _read_structures(
            path, rois, image_dir, pixel_spacing, allow_irregular, memory_budget_gb
        )


def _frames_apart(ds: Any) -> tuple[str, dict[int, str]]:
    """The frame of reference of a structure set, and its ROIs that name another one
    (ROINumber → FrameOfReferenceUID).

    The set's frame is the first of its ReferencedFrameOfReferenceSequence when an
    ROI names it (the frame its images are checked against), else the frame most ROIs
    name. An ROI in another frame (registered from another study) cannot be placed on
    the set's grid without the registration, which is not read.
    """
    frames = roi_frames(ds)
    if not frames:
        return "", {}
    named = list(frames.values())
    listed = ds.get("ReferencedFrameOfReferenceSequence", None) or []
    first = str(listed[0].get("FrameOfReferenceUID", "") or "") if len(listed) else ""
    frame = first if first in named else max(named, key=named.count)
    return frame, {number: uid for number, uid in frames.items() if uid != frame}


def _say_orphans(ds: Any, listed: set[int], p: Path) -> None:
    """One warning per ROIContourSequence item whose ReferencedROINumber names no ROI of
    the StructureSetROISequence: its contours belong to no structure and are not read."""
    for n, item in enumerate(ds.get("ROIContourSequence", None) or [], start=1):
        try:
            number = int(item.ReferencedROINumber)
        except (AttributeError, *PARSE_ERRORS):
            number = None
        if number not in listed:
            logger.warning(
                "%s: ROIContourSequence item %d refers to ROI %s, which the "
                "StructureSetROISequence does not list: its contours are not read",
                p,
                n,
                "(none)" if number is None else number,
            )


def _label_values(numbers: list[int], p: Path, names: dict[int, str]) -> dict[int, int]:
    """Each ROINumber's label value: itself, or for an ROINumber of 0 or below (valid
    DICOM; 0 is a label map's background) the next value above every ROINumber, said
    in one warning line."""
    values = {number: number for number in numbers}
    top = max([0, *numbers])
    for number in sorted(n for n in numbers if n <= 0):
        top += 1
        values[number] = top
        logger.warning(
            "%s: ROI %d (%s) has label value %d in the outputs (label values are positive, 0 "
            "is the background)",
            p,
            number,
            names[number] or "no name",
            top,
        )
    return values


def _chosen_polygons(
    ds: Any, p: Path, rois: Sequence[int | str]
) -> tuple[list[Structure], list[list[NDArray[np.float64]]]]:
    """The chosen ROIs of a read RTSTRUCT and each one's closed planar polygons (LPS mm).

    An ROI without closed planar contours keeps an empty list and is reported
    with a warning; :class:`EmptyMaskError` when no chosen ROI has any. An ROI in
    another frame of reference than the set's (:func:`_frames_apart`) is left out
    with a warning, or refused (:class:`InputError`) when chosen by name or number.
    """
    available = _rois(ds, p)
    if not available:
        raise EmptyMaskError(f"{p} holds no ROI (its StructureSetROISequence is empty)")
    chosen = [_choose_roi(available, r, p) for r in rois] if rois else available
    frame, apart = _frames_apart(ds)
    for number, name in chosen:
        if number in apart:
            said = (
                f"{p}: ROI {number} ({name}) lies in frame of reference {apart[number]}, the "
                f"structure set in {frame}: its coordinates are of another space (a "
                "registration, which is not read)"
            )
            if rois:
                raise InputError(f"{said}; choose ROIs of the set's frame")
            logger.warning("%s; it is left out", said)
    chosen = [(number, name) for number, name in chosen if number not in apart]
    if not rois:
        _say_orphans(ds, {number for number, _ in available}, p)
    colours = _roi_colours(ds)
    values = _label_values([number for number, _ in available], p, dict(available))
    structures = [Structure(values[number], name, colours.get(number)) for number, name in chosen]
    polygons: list[list[NDArray[np.float64]]] = []
    for number, name in chosen:
        try:
            polygons.append(_roi_polygons(ds, number, name, p)[0])
        except EmptyMaskError as exc:
            logger.warning("%s", exc)
            polygons.append([])
    if not any(polygons):
        raise EmptyMaskError(f"{p}: no chosen ROI has a closed planar contour")
    return structures, polygons


def _read_structures(
    path: str | os.PathLike[str],
    rois: Sequence[int | str],
    image_dir: str | os.PathLike[str] | None,
    pixel_spacing: float | None,
    allow_irregular: bool,
    memory_budget_gb: float,
) -> tuple[list[Structure], list[CrossSections | None], CrossSections]:
    ds, p = _read_dataset(path)
    structures, polygons = _chosen_polygons(ds, p, rois)
    reference = _series_reference(p, ds, image_dir, allow_irregular)
    sections, union = _shared_grid_sections(p, polygons, reference, pixel_spacing, memory_budget_gb)
    return structures, sections, union


def _say_unnamed(
    p: Path, named: set[str], image_dir: str | os.PathLike[str], uids: Sequence[str]
) -> None:
    """One warning when the contours name images (``named``, SOPInstanceUIDs) and none of
    them is the series' (``uids``: drawn on another reconstruction of the study): they
    are still placed on that grid by their coordinates."""
    if named and not named & set(uids):
        logger.warning(
            "%s: its contours name none of the images in %s (drawn on another series of the "
            "study?); they are placed on that grid by their coordinates",
            p,
            image_dir,
        )


def _series_reference(
    p: Path, ds: Any, image_dir: str | os.PathLike[str] | None, allow_irregular: bool
) -> tuple[NDArray[np.float64], tuple[int, int, int]] | None:
    """The grid of the image series the contours go on (None without one), read once;
    one warning when the contours name none of its images (:func:`_say_unnamed`)."""
    if image_dir is None:
        return None
    affine, shape, uids = dicom_series_geometry(image_dir, allow_irregular=allow_irregular)
    _say_unnamed(p, referenced_series(ds)[1], image_dir, uids)
    return affine, shape


def _shared_grid_sections(
    p: Path,
    polygons: list[list[NDArray[np.float64]]],
    reference: tuple[NDArray[np.float64], tuple[int, int, int]] | None,
    pixel_spacing: float | None,
    memory_budget_gb: float,
) -> tuple[list[CrossSections | None], CrossSections]:
    """Each ROI's parallel polygons rasterized on the grid of all of them (or the series',
    ``reference``: then ``pixel_spacing`` is not used)."""
    everything = [poly for group in polygons for poly in group]
    try:
        union = sections_from_polygons(
            everything,
            pixel_spacing=None if reference is not None else pixel_spacing,
            reference=reference,
            memory_budget_gb=memory_budget_gb,
            own_planes=True,
            one_structure=False,
        )
        sections = [
            None
            if not group
            else sections_from_polygons(
                group,
                reference=(union.affine, union.grid_shape),
                memory_budget_gb=memory_budget_gb,
            )
            for group in polygons
        ]
    except OptionError:
        raise
    except SlicereconError as exc:
        raise type(exc)(f"{p}: {exc}") from exc
    return sections, union


def _oblique_to(
    polygons: list[NDArray[np.float64]],
    reference: tuple[NDArray[np.float64], tuple[int, int, int]] | None,
) -> bool:
    """Whether parallel contours lie on planes oblique to their image series' slices
    (drawn on a tilted reformat): then read as planes of any orientation on its grid."""
    if reference is None or not polygons:
        return False
    normal = max((polygon_normal(p) for p in polygons), key=lambda found: found[1])[0]
    return grid_axis_of(reference[0], normal) is None


def read_rtstruct_annotation(
    path: str | os.PathLike[str],
    *,
    rois: Sequence[int | str] = (),
    image_dir: str | os.PathLike[str] | None = None,
    pixel_spacing: float | None = None,
    allow_irregular: bool = False,
    memory_budget_gb: float = DEFAULT_MEMORY_BUDGET_GB,
) -> tuple[Annotation, tuple[Structure, ...]]:
    """Every ROI of an RTSTRUCT (or those chosen) as an annotation, contours of any orientation.

    Contours on parallel planes are read as :func:`read_rtstruct_structures`
    reads them (one shared grid, each ROI on its own planes). Contours on
    several orientations (axial plus sagittal contours; a radial set of planes
    through an organ's axis; tilted views) are grouped into planes by normal
    and offset and rasterized each in its own plane
    (:func:`slicerecon.io.plane_groups.annotation_from_polygons`), on the image
    series' grid when ``image_dir`` is given.

    Parameters
    ----------
    path, rois, image_dir, pixel_spacing, allow_irregular, memory_budget_gb
        As for :func:`read_rtstruct_structures`.

    Returns
    -------
    annotation : Annotation
        The ROIs with contours; not a partition (ROIs may overlap or nest), LPS mm.
    missing : tuple of Structure
        The chosen ROIs without closed planar contours (each reported with a warning).

    Raises
    ------
    InputError, FormatError, GeometryError
        As :func:`read_rtstruct_structures`.
    EmptyMaskError
        No chosen ROI has a closed planar contour.
    """
    with reading(path):
        ds, p = _read_dataset(path)
        structures, polygons = _chosen_polygons(ds, p, rois)
        everything = [poly for group in polygons for poly in group]
        missing = tuple(s for s, group in zip(structures, polygons, strict=True) if not group)
        drawn = [(s, group) for s, group in zip(structures, polygons, strict=True) if group]
        reference = _series_reference(p, ds, image_dir, allow_irregular)
        oblique = _oblique_to(everything, reference)
        if orientation_count(everything) <= 1 and not oblique:
            sections, _ = _shared_grid_sections(
                p, polygons, reference, pixel_spacing, memory_budget_gb
            )
            own = [(s, x) for s, x in zip(structures, sections, strict=True) if x is not None]
            annotation = annotation_from_sections(
                [s for s, _ in own],
                [x for _, x in own],
                shared=False,
                coordinates="LPS",
                exclusive=False,
            )
            return annotation, missing
        try:
            annotation = annotation_from_polygons(
                [s for s, _ in drawn],
                [group for _, group in drawn],
                reference=reference,
                pixel_spacing=pixel_spacing,
                coordinates="LPS",
                exclusive=False,
                memory_budget_gb=memory_budget_gb,
            )
        except SlicereconError as exc:
            raise type(exc)(f"{p}: {exc}") from exc
        if oblique:  # not on the image's slices: each stands for half-way to its neighbours
            annotation = replace(annotation, gap_ends=frozenset(annotation.values))
        return annotation, missing
