"""Contour files: closed polygons on planes, as JSON or CSV.

The formats are specified in ``docs/formats.md``. In short:

JSON (``.json``)::

    {"format": "slicerecon-contours", "version": 1, "units": "mm",
     "label": "tumour",                          # optional
     "normal": [0, 0, 1],                        # optional
     "grid": {"affine": [[...], ...], "shape": [I, J, K]},   # optional
     "planes": [{"position": 12.5,               # optional, mm along the normal
                 "polygons": [[[x, y, z], ...], ...]}, ...]}

Version 2 (JSON) adds planes of any orientation and several structures::

    {"format": "slicerecon-contours", "version": 2, "units": "mm",
     "structures": [{"value": 1, "name": "prostate", "colour": [230, 25, 75]}],  # optional
     "planes": [{"normal": [0, 0.38, 0.92],      # optional: the polygons' own otherwise
                 "position": 4.0,                # optional, mm along the plane's normal
                 "structure": "prostate",        # value or name; needed with several
                 "polygons": [[[x, y, z], ...], ...]}, ...]}

Version 1 files keep working unchanged (:func:`read_contours`);
:func:`read_contour_annotation` reads both versions into an annotation.

CSV (``.csv``): a header naming the columns ``plane,polygon,x,y,z`` then one
row per vertex; the rows of one polygon are contiguous and in order.

Polygons are closed implicitly (a repeated first vertex at the end is dropped)
and filled by the even-odd rule, so a polygon inside another is a hole.
Reading goes through :func:`slicerecon.io.polygons.sections_from_polygons`.

Validation
----------
The JSON structure is a pydantic schema (:class:`ContourFile`,
:class:`ContourPlane`, :class:`ContourGrid`): strict types (``true`` is not a
number, ``"1"`` is not a number, null is not a value), finite numbers, no
unknown keys, lists of the right length checked before their items. Its first
error becomes one :class:`~slicerecon.errors.FormatError` naming the file and
the JSON path (``planes[3].polygons[1]: needs at least 3 points (got 2)``).
The rules that join fields (a plane's ``position`` against its polygons, an
empty plane needing ``position`` and ``normal``) are checked after it.

CSV is read line by line: its rules (contiguous rows per polygon, line numbers
in every message) are about the order of rows, which a record schema does not
express, so it keeps its own checks.
"""

from __future__ import annotations

import csv
import io
import json
import logging
import math
import os
from collections.abc import Iterator
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from ..annotation import Annotation, annotation_from_sections
from ..errors import FormatError, GeometryError, InputError, OptionError, SlicereconError
from ..labels import Structure
from ..sections import CrossSections
from .atomic import atomic_path
from .contour_schema import (
    CONTOUR_FORMAT,
    CONTOUR_VERSION,
    CONTOUR_VERSIONS,
    CSV_COLUMNS,
    FRAMES,
    ContourFile,
    ContourGrid,
    ContourPlane,
    ContourStructure,
    Parsed,
    closed_polygon,
    parse_json,
)
from .limits import DEFAULT_MEMORY_BUDGET_GB, check_coordinates, reading
from .plane_groups import annotation_from_polygons, orientation_count
from .polygons import (
    PLANE_TOLERANCE_MM,
    encloses_area,
    polygon_normal,
    polygons_from_sections,
    sections_from_polygons,
)

__all__ = [
    "CONTOUR_FORMAT",
    "CONTOUR_VERSION",
    "CONTOUR_VERSIONS",
    "ContourStructure",
    "CSV_COLUMNS",
    "ContourFile",
    "ContourGrid",
    "ContourPlane",
    "contour_file_frame",
    "contour_file_grid",
    "contour_structures",
    "read_contour_annotation",
    "read_contours",
    "write_contours_csv",
    "write_contours_json",
]

logger = logging.getLogger(__name__)


# ----------------------------------------------------------------------------- reading
def read_contours(
    path: str | os.PathLike[str],
    *,
    pixel_spacing: float | None = None,
    memory_budget_gb: float = DEFAULT_MEMORY_BUDGET_GB,
) -> CrossSections:
    """Read a contour file (``.json`` or ``.csv``) into cross-sections.

    Parameters
    ----------
    path : path-like
        A JSON or CSV contour file (see ``docs/formats.md``).
    pixel_spacing : float, optional
        In-plane pixel size of the grid the polygons are rasterized on, mm.
        Default: the file's ``grid`` when it has one (JSON), else the longest
        in-plane extent / 256. Given, it overrides the file's grid.
    memory_budget_gb : float
        Refuse files whose grid would not fit this budget, GiB, before any
        plane is rasterized (:func:`slicerecon.io.limits.check_grid`).

    Returns
    -------
    CrossSections
        One plane per plane of the file, sorted along the normal.

    Raises
    ------
    InputError
        Missing file, a directory, or an unknown suffix.
    FormatError
        Malformed content; the message names the JSON path (e.g.
        ``planes[3].polygons[1]``) or CSV line of the offending item.
    GeometryError
        Polygons not on parallel planes, or not flat; non-finite or absurd
        coordinates.
    EmptyMaskError
        No polygon in the file.
    MemoryBudgetError
        The grid the contours need exceeds ``memory_budget_gb``.
    """
    p = Path(path)
    parsed = _read_parsed(p)
    if len(parsed.structures) > 1:
        raise FormatError(
            f"{p} holds {len(parsed.structures)} structures: read them with "
            "read_contour_annotation, or choose one with --label (slicerecon run reads "
            "every one)"
        )
    return _parallel_sections(p, parsed, pixel_spacing, memory_budget_gb)


def _parallel_sections(
    p: Path, parsed: Parsed, pixel_spacing: float | None, memory_budget_gb: float
) -> CrossSections:
    """One structure's parsed polygons on parallel planes, rasterized (:func:`read_contours`)."""
    reference = parsed.grid if pixel_spacing is None else None
    if parsed.grid is not None and pixel_spacing is not None:
        logger.info("%s: pixel_spacing given, so the file's grid is not used", p)
    polygons, names, normal, empty = _ends_drawn_as_lines(p, parsed)
    try:
        sections = sections_from_polygons(
            polygons,
            pixel_spacing=pixel_spacing,
            reference=reference,
            normal=normal,
            empty_positions=empty,
            polygon_names=names,
            memory_budget_gb=memory_budget_gb,
        )
    except OptionError:
        raise
    except SlicereconError as exc:
        raise type(exc)(f"{p}: {exc}") from exc
    if sections.n_planes != parsed.n_planes:
        raise FormatError(
            f"{p}: the file lists {parsed.n_planes} planes but its polygons lie at "
            f"{sections.n_planes} distinct positions along the normal (tolerance 0.01 mm); "
            + (
                "each plane id must hold the polygons of one plane, and no two ids the same"
                if p.suffix.lower() == ".csv"
                else "each plane entry must hold the polygons of one plane, and no two "
                "entries the same"
            )
        )
    return sections


def _ends_drawn_as_lines(
    p: Path, parsed: Parsed
) -> tuple[list[NDArray[np.float64]], list[str], NDArray[np.float64] | None, list[float]]:
    """The polygons to rasterize, their names, the normal, and the empty planes: a plane
    whose only polygons enclose no area (a line or a point marking where the structure
    ends) is a plane where it is absent, said in one line; such a polygon beside others
    of its plane is left to :func:`sections_from_polygons` (skipped with a warning)."""
    areas = [polygon_normal(poly) for poly in parsed.polygons]
    kept = [n for n, poly in enumerate(parsed.polygons) if encloses_area(poly)]
    if len(kept) == len(areas) or not kept:
        return parsed.polygons, parsed.names, parsed.normal, parsed.empty_positions
    largest = max(kept, key=lambda n: areas[n][1])
    normal = parsed.normal if parsed.normal is not None else areas[largest][0]
    at = [float(poly.mean(axis=0) @ normal) for poly in parsed.polygons]

    def near(position: float, others: list[float]) -> bool:
        return any(abs(position - o) <= PLANE_TOLERANCE_MM for o in others)

    flat = sorted(set(range(len(areas))) - set(kept), key=lambda n: at[n])
    alone = [n for n in flat if not near(at[n], [at[k] for k in kept])]
    empty = list(parsed.empty_positions)
    said = []
    for n in alone:
        if not near(at[n], empty):
            empty.append(at[n])
            said.append(parsed.names[n])
    if said:
        one = len(said) == 1
        logger.warning(
            "%s: %s %s no area (a line or a point, where the structure ends): read as %s "
            "where the structure is absent",
            p,
            ", ".join(said),
            "encloses" if one else "enclose",
            "a plane" if one else "planes",
        )
    keep = [n for n in range(len(areas)) if n not in alone]
    return [parsed.polygons[n] for n in keep], [parsed.names[n] for n in keep], normal, empty


def read_contour_annotation(
    path: str | os.PathLike[str],
    *,
    pixel_spacing: float | None = None,
    memory_budget_gb: float = DEFAULT_MEMORY_BUDGET_GB,
) -> Annotation:
    """Read a contour file (either JSON version, or CSV) into an annotation.

    One structure on parallel planes is read as :func:`read_contours` reads it
    (annotated empty planes included); planes of several orientations, or
    several structures (version 2), are grouped and rasterized each in its own
    plane (:func:`slicerecon.io.plane_groups.annotation_from_polygons`), on
    the file's ``grid`` when it has one.

    Parameters
    ----------
    path, pixel_spacing, memory_budget_gb
        As for :func:`read_contours`.

    Returns
    -------
    Annotation
        In the file's world frame (its coordinates are taken as they are).

    Raises
    ------
    InputError, FormatError, GeometryError, EmptyMaskError, MemoryBudgetError
        As :func:`read_contours`.
    """
    with reading(path):
        return _read_contour_annotation(Path(path), pixel_spacing, memory_budget_gb)


def contour_file_frame(path: str | os.PathLike[str]) -> str | None:
    """The world frame a contour file states for its points (``"coordinates"``: ``"RAS"``
    or ``"LPS"``), or None when it states none (then they are read as RAS). Raises as
    :func:`contour_file_grid`."""
    return _header(path).coordinates


def contour_file_grid(
    path: str | os.PathLike[str],
) -> tuple[NDArray[np.float64], tuple[int, int, int]] | None:
    """The voxel grid a contour file gives (its ``grid``: affine, shape), or None when the
    grid is built on its contours (CSV files, JSON files without ``grid``).

    Raises
    ------
    InputError, FormatError
        As :func:`read_contours`, for a file that cannot be read.
    """
    return _header(path).grid


def _header(path: str | os.PathLike[str]) -> Parsed:
    with reading(path):
        return _read_parsed(Path(path))


def _read_contour_annotation(
    p: Path, pixel_spacing: float | None, memory_budget_gb: float
) -> Annotation:
    parsed = _read_parsed(p)
    for polygon, name in zip(parsed.polygons, parsed.names, strict=True):
        check_coordinates(polygon, what=f"{p}: {name}")
    reference = parsed.grid if pixel_spacing is None else None
    frame = parsed.coordinates or "RAS"
    simple = len(parsed.structures) == 1 and orientation_count(parsed.polygons) <= 1
    if simple or parsed.version == 1:  # version 1: one structure on parallel planes
        try:
            sections = _parallel_sections(p, parsed, pixel_spacing, memory_budget_gb)
        except GeometryError as exc:
            if "parallel" not in str(exc):
                raise
            raise GeometryError(
                f"{exc} (planes of several orientations: write the file as version 2)"
            ) from exc
        return annotation_from_sections(
            parsed.structures, [sections], shared=True, coordinates=frame, exclusive=True
        )
    try:
        return annotation_from_polygons(
            parsed.structures,
            parsed.structure_polygons(),
            reference=reference,
            pixel_spacing=pixel_spacing,
            coordinates=frame,
            exclusive=False,
            memory_budget_gb=memory_budget_gb,
        )
    except SlicereconError as exc:
        raise type(exc)(f"{p}: {exc}") from exc


def contour_structures(
    path: str | os.PathLike[str],
) -> list[tuple[Structure, list[NDArray[np.float64]]]]:
    """Every structure of a contour file with its polygons, as the file lists them.

    Parameters
    ----------
    path : path-like
        A contour file (JSON of either version, or CSV).

    Returns
    -------
    list of (Structure, list of ndarray of shape (N, 3))
        In the file's order; polygons in world mm (a structure without any
        keeps an empty list).

    Raises
    ------
    InputError, FormatError
        As :func:`read_contours`.
    """
    p = Path(path)
    with reading(p):
        parsed = _read_parsed(p)
    return list(zip(parsed.structures, parsed.structure_polygons(), strict=True))


def _read_parsed(p: Path) -> Parsed:
    """The parsed polygons of a contour file (the checks of :func:`read_contours`)."""
    if not p.exists():
        raise InputError(f"contour file not found: {p}")
    if not p.is_file():
        raise InputError(f"{p} is a directory; pass a contour file (.json or .csv)")
    suffix = p.suffix.lower()
    if suffix not in (".json", ".csv"):
        raise InputError(f"{p}: contour files must end in .json or .csv (got {suffix!r})")
    try:
        text = p.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError as exc:
        raise FormatError(f"{p} is not UTF-8 text ({exc.reason}); is it a contour file?") from exc
    except OSError as exc:
        raise InputError(f"cannot read {p}: {exc.strerror or exc}") from exc
    parsed = parse_json(text, p) if suffix == ".json" else _parse_csv(text, p)
    if not parsed.owners:
        parsed.owners = [1] * len(parsed.polygons)
        parsed.structures = parsed.structures or [Structure(1)]
    return parsed


def _csv_rows(text: str) -> Iterator[tuple[int, list[str]]]:
    """Rows with their 1-based line numbers, skipping blank and ``#`` comment lines."""
    for number, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        yield number, [cell.strip() for cell in next(csv.reader([line]))]


def _parse_csv(text: str, path: Path) -> Parsed:
    rows = _csv_rows(text)
    try:
        header_line, header = next(rows)
    except StopIteration:
        raise FormatError(f"{path} is empty: expected a header {','.join(CSV_COLUMNS)}") from None
    names = [h.lower() for h in header]
    if sorted(names) != sorted(CSV_COLUMNS):
        raise FormatError(
            f"{path}: line {header_line}: the header must name the columns "
            f"{','.join(CSV_COLUMNS)} (got {','.join(header)})"
        )
    column = {name: names.index(name) for name in CSV_COLUMNS}

    polygons: dict[tuple[int, int], list[list[float]]] = {}
    first_line: dict[tuple[int, int], int] = {}
    current: tuple[int, int] | None = None
    for line, cells in rows:
        if len(cells) != len(CSV_COLUMNS):
            raise FormatError(
                f"{path}: line {line}: expected {len(CSV_COLUMNS)} values, got {len(cells)}"
            )
        ids = []
        for name in ("plane", "polygon"):
            cell = cells[column[name]]
            try:
                ids.append(int(cell))
            except ValueError:
                raise FormatError(
                    f"{path}: line {line}: {name} must be an integer id (got {cell!r})"
                ) from None
        xyz = []
        for name in ("x", "y", "z"):
            cell = cells[column[name]]
            try:
                value = float(cell)
            except ValueError:
                raise FormatError(
                    f"{path}: line {line}: {name} must be a number (got {cell!r})"
                ) from None
            if not math.isfinite(value):
                raise FormatError(f"{path}: line {line}: {name} must be finite (got {cell})")
            xyz.append(value)
        key = (ids[0], ids[1])
        if key != current:
            if key in polygons:
                raise FormatError(
                    f"{path}: line {line}: the rows of plane {key[0]}, polygon {key[1]} are "
                    f"not contiguous (it started on line {first_line[key]}); list each "
                    "polygon's points together, in order"
                )
            polygons[key] = []
            first_line[key] = line
            current = key
        polygons[key].append(xyz)

    parsed = Parsed()
    for key, points in polygons.items():
        where = f"line {first_line[key]} (plane {key[0]}, polygon {key[1]})"
        parsed.polygons.append(closed_polygon(np.array(points), path, where))
        parsed.names.append(where)
    parsed.n_planes = len({plane for plane, _ in polygons})
    return parsed


# ----------------------------------------------------------------------------- writing
def _check_sections(sections: CrossSections) -> None:
    if not isinstance(sections, CrossSections):
        raise InputError(f"expected CrossSections (got {type(sections).__name__})")
    sections.require_foreground()


def write_contours_json(
    sections: CrossSections,
    path: str | os.PathLike[str],
    *,
    label: str | None = None,
    coordinates: str | None = None,
) -> Path:
    """Write the boundary polygons of cross-sections as a JSON contour file.

    The file records the normal, each plane's position and the reference grid,
    so :func:`read_contours` gives back identical masks, plane indices and
    positions. Planes without foreground are kept (with no polygons).

    Parameters
    ----------
    sections : CrossSections
        Must hold foreground on at least one plane.
    path : path-like
        Output file; written atomically (temporary file, then rename).
    label : str, optional
        Stored as ``"label"`` (e.g. the structure's name).
    coordinates : {"RAS", "LPS"}, optional
        Stored as ``"coordinates"``: the world frame of ``sections`` (``"LPS"`` for
        sections of DICOM data; without it the file is read as RAS).

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    OptionError
        ``label`` is not a string, or ``coordinates`` neither "RAS" nor "LPS".
    """
    _check_sections(sections)
    if label is not None and not isinstance(label, str):
        raise OptionError(f"label must be a string (got {type(label).__name__})")
    if coordinates is not None and coordinates not in FRAMES:
        raise OptionError(f'coordinates must be "RAS" or "LPS" (got {coordinates!r})')
    dump = json.dumps
    lines = [
        "{",
        f'  "format": {dump(CONTOUR_FORMAT)},',
        f'  "version": {CONTOUR_VERSION},',
        '  "units": "mm",',
    ]
    if label is not None:
        lines.append(f'  "label": {dump(label)},')
    if coordinates is not None:
        lines.append(f'  "coordinates": {dump(coordinates)},')
    lines.append(f'  "normal": {dump(sections.normal.tolist())},')
    lines.append(
        f'  "grid": {{"affine": {dump(sections.affine.tolist())}, '
        f'"shape": {dump(list(sections.grid_shape))}}},'
    )
    lines.append('  "planes": [')
    planes = polygons_from_sections(sections)
    for p, (position, rings) in enumerate(planes):
        head = f'    {{"position": {dump(position)}, "polygons": ['
        tail = "]}" + ("," if p + 1 < len(planes) else "")
        if not rings:
            lines.append(head + tail)
            continue
        lines.append(head)
        for r, ring in enumerate(rings):
            comma = "," if r + 1 < len(rings) else ""
            lines.append(f"      {dump(ring.tolist())}{comma}")
        lines.append("    " + tail)
    lines += ["  ]", "}", ""]
    target = Path(path)
    with atomic_path(target) as tmp:
        tmp.write_text("\n".join(lines), encoding="utf-8")
    logger.info("wrote %d planes of contours to %s", len(planes), target)
    return target


def write_contours_csv(sections: CrossSections, path: str | os.PathLike[str]) -> Path:
    """Write the boundary polygons of cross-sections as a CSV contour file.

    Columns ``plane,polygon,x,y,z`` (world mm, full float precision); ``plane``
    is the plane number in ``sections``, ``polygon`` counts from 0 within a
    plane. CSV holds neither the grid nor empty planes: planes without
    foreground are left out (with a warning), and reading the file back builds
    a grid from the polygons (pass the original ``pixel_spacing`` to get the
    same pixels back).

    Parameters
    ----------
    sections : CrossSections
        Must hold foreground on at least one plane.
    path : path-like
        Output file; written atomically.

    Returns
    -------
    Path
        ``path``.
    """
    _check_sections(sections)
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(CSV_COLUMNS)
    empty = 0
    for plane, (_, rings) in enumerate(polygons_from_sections(sections)):
        empty += not rings
        for number, ring in enumerate(rings):
            for x, y, z in ring.tolist():
                writer.writerow((plane, number, repr(x), repr(y), repr(z)))
    if empty:
        logger.warning("%d planes without foreground are not written: CSV cannot hold them", empty)
    target = Path(path)
    with atomic_path(target) as tmp:
        tmp.write_text(buffer.getvalue(), encoding="utf-8")
    logger.info("wrote contours of %d planes to %s", sections.n_planes - empty, target)
    return target
