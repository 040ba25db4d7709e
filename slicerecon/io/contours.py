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
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, ClassVar

import numpy as np
from numpy.typing import NDArray
from pydantic import (
    AfterValidator,
    AllowInfNan,
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    Strict,
    ValidationError,
    ValidatorFunctionWrapHandler,
    WrapValidator,
    field_validator,
    model_validator,
)
from pydantic_core import ErrorDetails, PydanticCustomError

from ..errors import FormatError, InputError, OptionError, SlicereconError
from ..sections import CrossSections
from .atomic import atomic_path
from .limits import DEFAULT_MEMORY_BUDGET_GB
from .polygons import polygons_from_sections, sections_from_polygons

__all__ = [
    "CONTOUR_FORMAT",
    "CONTOUR_VERSION",
    "CSV_COLUMNS",
    "ContourFile",
    "ContourGrid",
    "ContourPlane",
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


def _kind(value: Any) -> str:
    """How a JSON value is named in messages: ``a string``, ``a list``, ``true/false``, ..."""
    names = {dict: "an object", list: "a list", str: "a string", bool: "true/false"}
    if value is None:
        return "null"
    return names.get(type(value), type(value).__name__)


def _closed(points: NDArray[np.float64], path: Path, where: str) -> NDArray[np.float64]:
    if points.shape[0] > 1 and np.array_equal(points[0], points[-1]):
        points = points[:-1]
    if points.shape[0] < 3:
        raise _fail(path, where, f"needs at least 3 points (got {points.shape[0]})")
    return points


# ----------------------------------------------------------------------------- JSON schema
def _refuse(message: str) -> PydanticCustomError:
    """A schema error whose text is ours (shown after the JSON path)."""
    return PydanticCustomError("slicerecon", "{message}", {"message": message})


def _expect(what: str, length: int | None = None) -> WrapValidator:
    """A list of ``length`` items (any length when None), checked before its items."""

    def validate(value: Any, handler: ValidatorFunctionWrapHandler) -> Any:
        if not isinstance(value, list) or (length is not None and len(value) != length):
            got = _kind(value) + (f" of length {len(value)}" if isinstance(value, list) else "")
            raise _refuse(f"expected {what} (got {got})")
        return handler(value)

    return WrapValidator(validate)


def _not_null(what: str) -> BeforeValidator:
    """An optional key may be left out, but not given as null."""

    def validate(value: Any) -> Any:
        if value is None:
            raise _refuse(f"expected {what} (got null)")
        return value

    return BeforeValidator(validate)


def _polygon_points(points: list[list[float]]) -> list[list[float]]:
    if len(points) > 1 and points[0] == points[-1]:
        points = points[:-1]  # closed implicitly: a repeated first point is dropped
    if len(points) < 3:
        raise _refuse(f"needs at least 3 points (got {len(points)})")
    return points


def _non_zero(normal: list[float]) -> list[float]:
    if not any(normal):
        raise _refuse("must not be the zero vector")
    return normal


def _homogeneous(rows: list[list[float]]) -> list[list[float]]:
    affine = np.array(rows)
    if not np.allclose(affine[3], [0, 0, 0, 1]):
        raise _refuse("the last row must be [0, 0, 0, 1]")
    if abs(np.linalg.det(affine[:3, :3])) < 1e-12:
        raise _refuse("is singular (a voxel axis has zero length)")
    return rows


def _grid_shape(value: Any, handler: ValidatorFunctionWrapHandler) -> Any:
    try:
        return handler(value)
    except ValidationError:
        raise _refuse(f"expected 3 positive integers (got {value!r})") from None


Number = Annotated[float, Strict(), AllowInfNan(False)]
"""A finite JSON number (an integer is accepted; true/false and strings are not)."""
Point = Annotated[list[Number], _expect("[x, y, z]", 3)]
Polygon = Annotated[
    list[Point], _expect("a list of [x, y, z] points"), AfterValidator(_polygon_points)
]
Normal = Annotated[list[Number], _expect("[nx, ny, nz]", 3), AfterValidator(_non_zero)]
AffineRow = Annotated[list[Number], _expect("4 numbers", 4)]
Affine = Annotated[list[AffineRow], _expect("4 rows of 4 numbers", 4), AfterValidator(_homogeneous)]
GridShape = Annotated[
    list[Annotated[int, Field(gt=0)]],
    Field(min_length=3, max_length=3),
    WrapValidator(_grid_shape),
]


class _JsonObject(BaseModel):
    """A JSON object with exactly the keys of the model's fields (in this order)."""

    model_config = ConfigDict(
        extra="forbid", strict=True, frozen=True, use_attribute_docstrings=True
    )
    _not_an_object: ClassVar[str] = "expected an object"

    @model_validator(mode="before")
    @classmethod
    def _known_keys(cls, data: Any) -> Any:
        if not isinstance(data, dict):
            raise _refuse(f"{cls._not_an_object} (got {_kind(data)})")
        unknown = sorted(set(data) - set(cls.model_fields))
        if unknown:
            allowed = ", ".join(cls.model_fields)
            raise _refuse(f"unknown key {unknown[0]!r} (allowed: {allowed})")
        return data


class ContourGrid(_JsonObject):
    """``grid``: the voxel grid to rasterize on."""

    affine: Affine
    """Voxel index → world mm, 4 rows of 4 numbers, last row ``[0, 0, 0, 1]``, not singular."""
    shape: GridShape
    """``[I, J, K]``, positive integers."""


class ContourPlane(_JsonObject):
    """``planes[i]``: the polygons of one plane."""

    position: Annotated[Number | None, _not_null("a number")] = None
    """Position along the file's ``normal``, mm (checked against the polygons when given)."""
    polygons: Annotated[list[Polygon], _expect("a list")]
    """Closed polygons, each at least 3 ``[x, y, z]`` points in world mm."""


class ContourFile(_JsonObject):
    """A JSON contour file (``docs/formats.md``); ``model_json_schema()`` gives its schema."""

    _not_an_object: ClassVar[str] = "the top level must be a JSON object"

    format: Annotated[Any, Field(json_schema_extra={"const": CONTOUR_FORMAT})]
    """The string ``"slicerecon-contours"``."""
    version: Annotated[int, Field(json_schema_extra={"const": CONTOUR_VERSION})]
    """The integer 1."""
    units: Annotated[Any, Field(json_schema_extra={"const": "mm"})]
    """The string ``"mm"``."""
    label: Annotated[str | None, _not_null("a string")] = None
    """A name for the structure (informative)."""
    normal: Annotated[Normal | None, _not_null("[nx, ny, nz]")] = None
    """The plane normal, any non-zero length."""
    grid: Annotated[ContourGrid | None, _not_null("an object")] = None
    """The voxel grid to rasterize on."""
    planes: Annotated[list[ContourPlane], _expect("a list of planes")]
    """The planes, each with its polygons."""

    @field_validator("format", mode="after")
    @classmethod
    def _format(cls, value: Any) -> Any:
        if value != CONTOUR_FORMAT:
            raise _refuse(f"expected {CONTOUR_FORMAT!r} (got {value!r}): not a contour file")
        return value

    @field_validator("version", mode="after")
    @classmethod
    def _version(cls, value: int) -> int:
        if value != CONTOUR_VERSION:
            raise _refuse(
                f"version {value} is not supported; this slicerecon reads version {CONTOUR_VERSION}"
            )
        return value

    @field_validator("units", mode="after")
    @classmethod
    def _units(cls, value: Any) -> Any:
        if value != "mm":
            raise _refuse(f'must be "mm" (got {value!r}); convert the coordinates to millimetres')
        return value


def _json_path(loc: tuple[int | str, ...]) -> str:
    """``("planes", 3, "polygons", 1)`` → ``planes[3].polygons[1]``."""
    out = ""
    for part in loc:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out


def _schema_error(error: ErrorDetails, path: Path) -> FormatError:
    """One pydantic error as our message: the file, the JSON path, what was wrong."""
    loc, kind, value = tuple(error["loc"]), error["type"], error.get("input")
    if kind == "missing":
        hint = "" if len(loc) > 1 else "; see docs/formats.md"
        return _fail(path, _json_path(loc[:-1]), f"missing key {loc[-1]!r}{hint}")
    if kind == "slicerecon":
        message = str((error.get("ctx") or {}).get("message", error["msg"]))
    elif kind == "finite_number":
        message = f"must be finite (got {value})"
    elif kind == "float_type" and isinstance(value, int) and not isinstance(value, bool):
        message = f"must be finite (got an integer of {len(str(value))} digits)"
    elif kind in ("float_type", "float_parsing"):
        message = f"expected a number (got {_kind(value)})"
    elif kind in ("int_type", "int_parsing"):
        message = f"expected an integer (got {_kind(value)})"
    elif kind == "string_type":
        message = f"expected a string (got {_kind(value)})"
    else:  # not reached by the schema above; pydantic's own words, still with the path
        message = error["msg"]
    return _fail(path, _json_path(loc), message)


def _parse_json(text: str, path: Path) -> _Parsed:
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise FormatError(
            f"{path} is not valid JSON: {exc.msg} at line {exc.lineno}, column {exc.colno}"
        ) from exc
    except (ValueError, RecursionError) as exc:  # 4,301-digit integers, 100,000-deep nesting
        raise FormatError(
            f"{path} is not valid JSON: {type(exc).__name__}: {str(exc)[:200]}"
        ) from exc
    try:
        model = ContourFile.model_validate(doc)
    except ValidationError as exc:
        raise _schema_error(exc.errors()[0], path) from None

    # the rules that join several fields: positions against polygons, empty planes
    parsed = _Parsed(n_planes=len(model.planes))
    if model.normal is not None:
        normal = np.array(model.normal)
        parsed.normal = normal / np.linalg.norm(normal)
    if model.grid is not None:
        shape = model.grid.shape
        parsed.grid = (np.array(model.grid.affine), (shape[0], shape[1], shape[2]))
    for p, plane in enumerate(model.planes):
        where = f"planes[{p}]"
        if not plane.polygons:
            if plane.position is None or parsed.normal is None:
                raise _fail(
                    path,
                    where,
                    'a plane without polygons needs a "position" and the file a top-level "normal"',
                )
            parsed.empty_positions.append(plane.position)
            continue
        for q, polygon in enumerate(plane.polygons):
            pname = f"{where}.polygons[{q}]"
            points = np.array(polygon, dtype=np.float64)
            if plane.position is not None and parsed.normal is not None:
                at = float(points.mean(axis=0) @ parsed.normal)
                if abs(at - plane.position) > max(0.01, 1e-6 * abs(plane.position)):
                    raise _fail(
                        path,
                        pname,
                        f"lies at {at:.6g} mm along the normal but the "
                        f"plane's position is {plane.position:.6g} mm",
                    )
            parsed.polygons.append(points)
            parsed.names.append(pname)
    return parsed


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
        logger.warning("%d planes without foreground are not written: CSV cannot hold them", empty)
    target = Path(path)
    with atomic_path(target) as tmp:
        tmp.write_text(buffer.getvalue(), encoding="utf-8")
    logger.info("wrote contours of %d planes to %s", sections.n_planes - empty, target)
    return target
