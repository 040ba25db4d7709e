"""Contour files: closed polygons on parallel planes, as JSON or CSV.

The formats are specified in ``docs/formats.md``. In short:

JSON (``.json``)::

    {"format": "slicerecon-contours", "version": 1, "units": "mm",
     "label": "tumour",                          # optional
     "normal": [0, 0, 1],                        # optional
     "grid": {"affine": [[...], ...], "shape": [I, J, K]},   # optional
     "planes": [{"position": 12.5,               # optional, mm along the normal
                 "polygons": [[[x, y, z], ...], ...]}, ...]}

CSV (``.csv``): a header naming the columns ``plane,polygon,x,y,z`` then one
row per vertex; the rows of one polygon are contiguous and in order.

Polygons are closed implicitly (a repeated first vertex at the end is dropped)
and filled by the even-odd rule, so a polygon inside another is a hole.
Reading goes through :func:`slicerecon.io.polygons.sections_from_polygons`.
"""

from __future__ import annotations

import csv
import io
import json
import logging
import math
import os
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import FormatError, InputError, OptionError, SlicereconError
from ..sections import CrossSections
from .atomic import atomic_path
from .limits import DEFAULT_MEMORY_BUDGET_GB
from .polygons import polygons_from_sections, sections_from_polygons

__all__ = [
    "CONTOUR_FORMAT",
    "CONTOUR_VERSION",
    "CSV_COLUMNS",
    "read_contours",
    "write_contours_csv",
    "write_contours_json",
]

logger = logging.getLogger(__name__)

CONTOUR_FORMAT = "slicerecon-contours"
"""Value of the ``"format"`` key of a JSON contour file."""
CONTOUR_VERSION = 1
"""The JSON format version this module reads and writes."""
CSV_COLUMNS = ("plane", "polygon", "x", "y", "z")
"""Columns a CSV contour file must have (in any order)."""

_TOP_KEYS = ("format", "version", "units", "label", "normal", "grid", "planes")
_PLANE_KEYS = ("position", "polygons")


@dataclass
class _Parsed:
    """Polygons of a contour file, flattened, with what else the file says."""

    polygons: list[NDArray[np.float64]] = field(default_factory=list)
    names: list[str] = field(default_factory=list)
    n_planes: int = 0
    normal: NDArray[np.float64] | None = None
    empty_positions: list[float] = field(default_factory=list)
    grid: tuple[NDArray[np.float64], tuple[int, int, int]] | None = None


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
    parsed = _parse_json(text, p) if suffix == ".json" else _parse_csv(text, p)

    reference = parsed.grid if pixel_spacing is None else None
    if parsed.grid is not None and pixel_spacing is not None:
        logger.info("%s: pixel_spacing given, so the file's grid is not used", p)
    try:
        sections = sections_from_polygons(
            parsed.polygons,
            pixel_spacing=pixel_spacing,
            reference=reference,
            normal=parsed.normal,
            empty_positions=parsed.empty_positions,
            polygon_names=parsed.names,
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
            "each plane entry must hold the polygons of one plane, and no two entries the same"
        )
    return sections


def _fail(path: Path, where: str, message: str) -> FormatError:
    return FormatError(f"{path}: {where}: {message}" if where else f"{path}: {message}")


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool)


def _number(value: Any, path: Path, where: str) -> float:
    if not _is_number(value):
        raise _fail(path, where, f"expected a number (got {_kind(value)})")
    if not math.isfinite(value):
        raise _fail(path, where, f"must be finite (got {value})")
    return float(value)


def _kind(value: Any) -> str:
    names = {dict: "an object", list: "a list", str: "a string", bool: "true/false"}
    if value is None:
        return "null"
    return names.get(type(value), type(value).__name__)


def _numbers(value: Any, count: int, path: Path, where: str, what: str) -> list[float]:
    if not isinstance(value, list) or len(value) != count:
        raise _fail(path, where, f"expected {what} (got {_kind(value)}"
                    + (f" of length {len(value)})" if isinstance(value, list) else ")"))
    return [_number(v, path, f"{where}[{i}]") for i, v in enumerate(value)]


def _check_keys(obj: dict[str, Any], allowed: tuple[str, ...], path: Path, where: str) -> None:
    unknown = sorted(set(obj) - set(allowed))
    if unknown:
        raise _fail(
            path, where,
            f"unknown key {unknown[0]!r} (allowed: {', '.join(allowed)})",
        )


def _parse_json(text: str, path: Path) -> _Parsed:
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise FormatError(
            f"{path} is not valid JSON: {exc.msg} at line {exc.lineno}, column {exc.colno}"
        ) from exc
    if not isinstance(doc, dict):
        raise _fail(path, "", f"the top level must be a JSON object (got {_kind(doc)})")
    _check_keys(doc, _TOP_KEYS, path, "")
    for key in ("format", "version", "units", "planes"):
        if key not in doc:
            raise _fail(path, "", f"missing key {key!r}; see docs/formats.md")
    if doc["format"] != CONTOUR_FORMAT:
        raise _fail(path, "format",
                    f"expected {CONTOUR_FORMAT!r} (got {doc['format']!r}): not a contour file")
    if not (isinstance(doc["version"], int) and not isinstance(doc["version"], bool)):
        raise _fail(path, "version", f"expected an integer (got {_kind(doc['version'])})")
    if doc["version"] != CONTOUR_VERSION:
        raise _fail(path, "version", f"version {doc['version']} is not supported; this "
                    f"slicerecon reads version {CONTOUR_VERSION}")
    if doc["units"] != "mm":
        raise _fail(path, "units", f"must be \"mm\" (got {doc['units']!r}); convert the "
                    "coordinates to millimetres")
    if "label" in doc and not isinstance(doc["label"], str):
        raise _fail(path, "label", f"expected a string (got {_kind(doc['label'])})")

    parsed = _Parsed()
    if "normal" in doc:
        normal = np.array(_numbers(doc["normal"], 3, path, "normal", "[nx, ny, nz]"))
        if not np.any(normal):
            raise _fail(path, "normal", "must not be the zero vector")
        parsed.normal = normal / np.linalg.norm(normal)
    if "grid" in doc:
        parsed.grid = _parse_grid(doc["grid"], path)

    planes = doc["planes"]
    if not isinstance(planes, list):
        raise _fail(path, "planes", f"expected a list of planes (got {_kind(planes)})")
    parsed.n_planes = len(planes)
    for p, plane in enumerate(planes):
        where = f"planes[{p}]"
        if not isinstance(plane, dict):
            raise _fail(path, where, f"expected an object (got {_kind(plane)})")
        _check_keys(plane, _PLANE_KEYS, path, where)
        if "polygons" not in plane:
            raise _fail(path, where, "missing key 'polygons'")
        polygons = plane["polygons"]
        if not isinstance(polygons, list):
            raise _fail(path, f"{where}.polygons", f"expected a list (got {_kind(polygons)})")
        position = (
            _number(plane["position"], path, f"{where}.position") if "position" in plane else None
        )
        if not polygons:
            if position is None or parsed.normal is None:
                raise _fail(path, where, "a plane without polygons needs a \"position\" and "
                            "the file a top-level \"normal\"")
            parsed.empty_positions.append(position)
            continue
        for q, polygon in enumerate(polygons):
            pname = f"{where}.polygons[{q}]"
            points = _parse_polygon(polygon, path, pname)
            if position is not None and parsed.normal is not None:
                at = float(points.mean(axis=0) @ parsed.normal)
                if abs(at - position) > max(0.01, 1e-6 * abs(position)):
                    raise _fail(path, pname, f"lies at {at:.6g} mm along the normal but the "
                                f"plane's position is {position:.6g} mm")
            parsed.polygons.append(points)
            parsed.names.append(pname)
    return parsed


def _parse_polygon(polygon: Any, path: Path, where: str) -> NDArray[np.float64]:
    if not isinstance(polygon, list):
        raise _fail(path, where, f"expected a list of [x, y, z] points (got {_kind(polygon)})")
    points = np.array(
        [_numbers(pt, 3, path, f"{where}[{i}]", "[x, y, z]") for i, pt in enumerate(polygon)],
        dtype=np.float64,
    ).reshape(-1, 3)
    return _closed(points, path, where)


def _closed(points: NDArray[np.float64], path: Path, where: str) -> NDArray[np.float64]:
    if points.shape[0] > 1 and np.array_equal(points[0], points[-1]):
        points = points[:-1]
    if points.shape[0] < 3:
        raise _fail(path, where, f"needs at least 3 points (got {points.shape[0]})")
    return points


def _parse_grid(grid: Any, path: Path) -> tuple[NDArray[np.float64], tuple[int, int, int]]:
    if not isinstance(grid, dict):
        raise _fail(path, "grid", f"expected an object (got {_kind(grid)})")
    _check_keys(grid, ("affine", "shape"), path, "grid")
    for key in ("affine", "shape"):
        if key not in grid:
            raise _fail(path, "grid", f"missing key {key!r}")
    rows = grid["affine"]
    if not isinstance(rows, list) or len(rows) != 4:
        raise _fail(path, "grid.affine", "expected 4 rows of 4 numbers")
    affine = np.array(
        [_numbers(r, 4, path, f"grid.affine[{i}]", "4 numbers") for i, r in enumerate(rows)]
    )
    if not np.allclose(affine[3], [0, 0, 0, 1]):
        raise _fail(path, "grid.affine", "the last row must be [0, 0, 0, 1]")
    if abs(np.linalg.det(affine[:3, :3])) < 1e-12:
        raise _fail(path, "grid.affine", "is singular (a voxel axis has zero length)")
    shape = grid["shape"]
    if (
        not isinstance(shape, list)
        or len(shape) != 3
        or not all(isinstance(s, int) and not isinstance(s, bool) and s > 0 for s in shape)
    ):
        raise _fail(path, "grid.shape", f"expected 3 positive integers (got {shape!r})")
    return affine, (shape[0], shape[1], shape[2])


def _csv_rows(text: str) -> Iterator[tuple[int, list[str]]]:
    """Rows with their 1-based line numbers, skipping blank and ``#`` comment lines."""
    for number, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        yield number, [cell.strip() for cell in next(csv.reader([line]))]


def _parse_csv(text: str, path: Path) -> _Parsed:
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

    parsed = _Parsed()
    for key, points in polygons.items():
        where = f"line {first_line[key]} (plane {key[0]}, polygon {key[1]})"
        parsed.polygons.append(_closed(np.array(points), path, where))
        parsed.names.append(where)
    parsed.n_planes = len({plane for plane, _ in polygons})
    return parsed


# ----------------------------------------------------------------------------- writing
def _check_sections(sections: CrossSections) -> None:
    if not isinstance(sections, CrossSections):
        raise InputError(f"expected CrossSections (got {type(sections).__name__})")
    sections.require_foreground()


def write_contours_json(
    sections: CrossSections, path: str | os.PathLike[str], *, label: str | None = None
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

    Returns
    -------
    Path
        ``path``.
    """
    _check_sections(sections)
    if label is not None and not isinstance(label, str):
        raise OptionError(f"label must be a string (got {type(label).__name__})")
    dump = json.dumps
    lines = [
        "{",
        f'  "format": {dump(CONTOUR_FORMAT)},',
        f'  "version": {CONTOUR_VERSION},',
        '  "units": "mm",',
    ]
    if label is not None:
        lines.append(f'  "label": {dump(label)},')
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
        logger.warning("%d planes without foreground are not written: CSV cannot hold them",
                       empty)
    target = Path(path)
    with atomic_path(target) as tmp:
        tmp.write_text(buffer.getvalue(), encoding="utf-8")
    logger.info("wrote contours of %d planes to %s", sections.n_planes - empty, target)
    return target
