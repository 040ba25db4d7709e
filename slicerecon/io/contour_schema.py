"""The JSON contour file: its schema (pydantic) and the rules that join its fields.

:class:`ContourFile` (with :class:`ContourPlane`, :class:`ContourStructure`
and :class:`ContourGrid`) is the structure of a ``.json`` contour file, both
versions (``docs/formats.md``); ``ContourFile.model_json_schema()`` gives it
as JSON Schema. :func:`parse_json` validates a file against it and then
checks the rules that join several fields (a plane's ``position`` against its
polygons, an empty plane needing ``position`` and ``normal``, which structure
a plane names). Every problem is one :class:`~slicerecon.errors.FormatError`
naming the file and the JSON path. :mod:`slicerecon.io.contours` reads and
writes the files.
"""

from __future__ import annotations

import json
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

from ..errors import FormatError
from ..labels import Structure
from ..selection import name_key
from .plane_groups import ANGLE_TOLERANCE_DEG
from .polygons import polygon_normal

__all__ = [
    "CONTOUR_FORMAT",
    "CONTOUR_VERSION",
    "CONTOUR_VERSIONS",
    "ContourFile",
    "ContourGrid",
    "ContourPlane",
    "ContourStructure",
    "CSV_COLUMNS",
    "Parsed",
    "closed_polygon",
    "fail",
    "kind_of",
    "parse_json",
]

CONTOUR_FORMAT = "slicerecon-contours"
"""Value of the ``"format"`` key of a JSON contour file."""
CONTOUR_VERSION = 1
"""The JSON format version this module writes (one structure on parallel planes)."""
CONTOUR_VERSIONS = (1, 2)
"""The JSON format versions this module reads."""
FRAMES = ("RAS", "LPS")
"""Values of a JSON contour file's ``"coordinates"``: the world frame of its points."""
CSV_COLUMNS = ("plane", "polygon", "x", "y", "z")
"""Columns a CSV contour file must have (in any order)."""


@dataclass
class Parsed:
    """Polygons of a contour file, flattened, with what else the file says."""

    polygons: list[NDArray[np.float64]] = field(default_factory=list)
    names: list[str] = field(default_factory=list)
    n_planes: int = 0
    normal: NDArray[np.float64] | None = None
    empty_positions: list[float] = field(default_factory=list)
    grid: tuple[NDArray[np.float64], tuple[int, int, int]] | None = None
    version: int = 1
    structures: list[Structure] = field(default_factory=list)
    owners: list[int] = field(default_factory=list)  # each polygon's structure value
    coordinates: str | None = None  # "RAS" or "LPS" when the file states it

    def structure_polygons(self) -> list[list[NDArray[np.float64]]]:
        """Each structure's polygons, in the order of :attr:`structures` (possibly none)."""
        return [
            [poly for poly, owner in zip(self.polygons, self.owners, strict=True) if owner == value]
            for value in (s.value for s in self.structures)
        ]


def fail(path: Path, where: str, message: str) -> FormatError:
    return FormatError(f"{path}: {where}: {message}" if where else f"{path}: {message}")


def kind_of(value: Any) -> str:
    """How a JSON value is named in messages: ``a string``, ``a list``, ``true/false``, ..."""
    names = {dict: "an object", list: "a list", str: "a string", bool: "true/false"}
    if value is None:
        return "null"
    return names.get(type(value), type(value).__name__)


def closed_polygon(points: NDArray[np.float64], path: Path, where: str) -> NDArray[np.float64]:
    if points.shape[0] < 3:
        raise fail(path, where, f"needs at least 3 points (got {points.shape[0]})")
    if points.shape[0] > 3 and np.array_equal(points[0], points[-1]):
        points = points[:-1]  # closed implicitly; three points stay three (a line, a point)
    return points


# ----------------------------------------------------------------------------- JSON schema
def _refuse(message: str) -> PydanticCustomError:
    """A schema error whose text is ours (shown after the JSON path)."""
    return PydanticCustomError("slicerecon", "{message}", {"message": message})


def _expect(what: str, length: int | None = None) -> WrapValidator:
    """A list of ``length`` items (any length when None), checked before its items."""

    def validate(value: Any, handler: ValidatorFunctionWrapHandler) -> Any:
        if not isinstance(value, list) or (length is not None and len(value) != length):
            got = kind_of(value) + (f" of length {len(value)}" if isinstance(value, list) else "")
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
    if len(points) < 3:
        raise _refuse(f"needs at least 3 points (got {len(points)})")
    if len(points) > 3 and points[0] == points[-1]:
        points = points[:-1]  # closed implicitly: a repeated first point is dropped
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
            raise _refuse(f"{cls._not_an_object} (got {kind_of(data)})")
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
    """Position along the file's (or, version 2, the plane's) ``normal``, mm (checked
    against the polygons when given)."""
    normal: Annotated[Normal | None, _not_null("[nx, ny, nz]")] = None
    """Version 2: this plane's normal, any non-zero length."""
    structure: Annotated[int | str | None, _not_null("a value or a name")] = None
    """Version 2: the structure drawn on this plane, by value or name."""
    polygons: Annotated[list[Polygon], _expect("a list")]
    """Closed polygons, each at least 3 ``[x, y, z]`` points in world mm."""


class ContourStructure(_JsonObject):
    """``structures[i]`` (version 2): one structure of the file."""

    value: Annotated[int, Field(gt=0)]
    """Its label value, a positive integer."""
    name: Annotated[str | None, _not_null("a string")] = None
    """Its name."""
    colour: Annotated[list[Annotated[int, Field(ge=0, le=255)]] | None, _not_null("[r, g, b]")] = (
        None
    )
    """Its display colour, RGB 0-255."""


class ContourFile(_JsonObject):
    """A JSON contour file (``docs/formats.md``); ``model_json_schema()`` gives its schema."""

    _not_an_object: ClassVar[str] = "the top level must be a JSON object"

    format: Annotated[Any, Field(json_schema_extra={"const": CONTOUR_FORMAT})]
    """The string ``"slicerecon-contours"``."""
    version: Annotated[int, Field(json_schema_extra={"enum": list(CONTOUR_VERSIONS)})]
    """The integer 1, or 2 (planes of any orientation, several structures)."""
    units: Annotated[Any, Field(json_schema_extra={"const": "mm"})]
    """The string ``"mm"``."""
    label: Annotated[str | None, _not_null("a string")] = None
    """A name for the structure (informative)."""
    coordinates: Annotated[
        Any, _not_null('"RAS" or "LPS"'), Field(json_schema_extra={"enum": list(FRAMES)})
    ] = None
    """The points' world frame: ``"RAS"`` (NIfTI's; the default) or ``"LPS"`` (DICOM's)."""
    normal: Annotated[Normal | None, _not_null("[nx, ny, nz]")] = None
    """The plane normal, any non-zero length."""
    grid: Annotated[ContourGrid | None, _not_null("an object")] = None
    """The voxel grid to rasterize on."""
    structures: Annotated[list[ContourStructure] | None, _not_null("a list")] = None
    """Version 2: the structures (default: one, value 1, named ``label``)."""
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
        if value not in CONTOUR_VERSIONS:
            raise _refuse(
                f"version {value} is not supported; this slicerecon reads versions "
                f"{', '.join(str(v) for v in CONTOUR_VERSIONS)}"
            )
        return value

    @field_validator("coordinates", mode="after")
    @classmethod
    def _coordinates(cls, value: Any) -> Any:
        if value not in FRAMES:
            raise _refuse(f'must be "RAS" or "LPS" (got {value!r})')
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
        return fail(path, _json_path(loc[:-1]), f"missing key {loc[-1]!r}{hint}")
    if kind == "slicerecon":
        message = str((error.get("ctx") or {}).get("message", error["msg"]))
    elif kind == "finite_number":
        message = f"must be finite (got {value})"
    elif kind == "float_type" and isinstance(value, int) and not isinstance(value, bool):
        message = f"must be finite (got an integer of {len(str(value))} digits)"
    elif kind in ("float_type", "float_parsing"):
        message = f"expected a number (got {kind_of(value)})"
    elif kind in ("int_type", "int_parsing"):
        message = f"expected an integer (got {kind_of(value)})"
    elif kind == "string_type":
        message = f"expected a string (got {kind_of(value)})"
    else:  # not reached by the schema above; pydantic's own words, still with the path
        message = error["msg"]
    return fail(path, _json_path(loc), message)


def parse_json(text: str, path: Path) -> Parsed:
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
    if isinstance(doc, dict) and doc.get("format") != CONTOUR_FORMAT:
        # another JSON document: say what it is before any key of ours is missing
        if doc.get("format") == "slicerecon-dataset":
            raise FormatError(
                f"{path} is the manifest of a dataset (slicerecon dataset make), not a "
                "contour file: pass its folder to 'slicerecon batch', or one of its masks "
                "to 'slicerecon run'"
            )
        got = f'"format" is {doc["format"]!r}' if "format" in doc else 'no "format" key'
        raise FormatError(
            f"{path} is not a contour file: {got}, where a contour file has "
            f'"format": "{CONTOUR_FORMAT}" (docs/formats.md)'
        )
    try:
        model = ContourFile.model_validate(doc)
    except ValidationError as exc:
        raise _schema_error(exc.errors()[0], path) from None

    # the rules that join several fields: positions against polygons, empty planes
    parsed = Parsed(
        n_planes=len(model.planes), version=model.version, coordinates=model.coordinates
    )
    if model.version == 1:
        newer = next(
            (
                f"planes[{p}].{key}"
                for p, plane in enumerate(model.planes)
                for key in ("normal", "structure")
                if getattr(plane, key) is not None
            ),
            "structures" if model.structures is not None else None,
        )
        if newer is not None:
            raise fail(path, newer, 'belongs to version 2: write "version": 2')
    parsed.structures = _structures(model, path)
    values = {s.value for s in parsed.structures}
    names = {name_key(s.name): s.value for s in parsed.structures if s.name}
    if model.normal is not None:
        normal = np.array(model.normal)
        parsed.normal = normal / np.linalg.norm(normal)
    if model.grid is not None:
        shape = model.grid.shape
        parsed.grid = (np.array(model.grid.affine), (shape[0], shape[1], shape[2]))
    for p, plane in enumerate(model.planes):
        where = f"planes[{p}]"
        owner = _owner(plane.structure, values, names, path, where, len(parsed.structures))
        normal = parsed.normal
        if plane.normal is not None:
            normal = np.array(plane.normal) / np.linalg.norm(plane.normal)
        if not plane.polygons:
            if model.version == 2:
                raise fail(
                    path, where, "a version 2 plane needs polygons (an empty plane: version 1)"
                )
            if plane.position is None or parsed.normal is None:
                raise fail(
                    path,
                    where,
                    'a plane without polygons needs a "position" and the file a top-level "normal"',
                )
            parsed.empty_positions.append(plane.position)
            continue
        for q, polygon in enumerate(plane.polygons):
            pname = f"{where}.polygons[{q}]"
            points = np.array(polygon, dtype=np.float64)
            if model.version == 2 and normal is not None:
                _check_on_normal(points, normal, path, pname)
            if plane.position is not None and normal is not None:
                at = float(points.mean(axis=0) @ normal)
                if abs(at - plane.position) > max(0.01, 1e-6 * abs(plane.position)):
                    raise fail(
                        path,
                        pname,
                        f"lies at {at:.6g} mm along the normal but the "
                        f"plane's position is {plane.position:.6g} mm",
                    )
            parsed.polygons.append(points)
            parsed.names.append(pname)
            parsed.owners.append(owner)
    return parsed


def _check_on_normal(
    points: NDArray[np.float64], normal: NDArray[np.float64], path: Path, where: str
) -> None:
    """Refuse a polygon whose own plane is tilted from the normal its plane declares."""
    own, area = polygon_normal(points)
    if area <= 0.0:
        return  # no area: refused where planes are grouped
    tilt = float(np.degrees(np.arccos(min(1.0, abs(float(own @ normal))))))
    if tilt > ANGLE_TOLERANCE_DEG:
        raise fail(
            path,
            where,
            f"is tilted {tilt:.3g}° from its plane's normal {np.round(normal, 4).tolist()} "
            f"(tolerance {ANGLE_TOLERANCE_DEG:g}°): give the plane's true normal, or none",
        )


def _structures(model: ContourFile, path: Path) -> list[Structure]:
    """The file's structures: version 2's list, or one (value 1, named ``label``)."""
    if model.structures is None:
        return [Structure(1, model.label or "")]
    out: list[Structure] = []
    for n, item in enumerate(model.structures):
        if any(s.value == item.value for s in out):
            raise fail(path, f"structures[{n}].value", f"value {item.value} is listed twice")
        if item.name and any(s.name and name_key(s.name) == name_key(item.name) for s in out):
            raise fail(path, f"structures[{n}].name", f"{item.name!r} names an earlier structure")
        colour = None if item.colour is None else tuple(item.colour)
        if colour is not None and len(colour) != 3:
            raise fail(path, f"structures[{n}].colour", "expected [r, g, b]")
        out.append(Structure(item.value, item.name or "", colour))  # type: ignore[arg-type]
    if not out:
        raise fail(path, "structures", "needs at least one structure")
    return out


def _owner(
    selector: int | str | None,
    values: set[int],
    names: dict[str, int],
    path: Path,
    where: str,
    count: int,
) -> int:
    """The value of the structure a plane names (the only one when it names none)."""
    if selector is None:
        if count > 1:
            raise fail(path, where, 'the file has several structures: give the plane "structure"')
        return next(iter(values))
    if isinstance(selector, int) and selector in values:
        return selector
    if isinstance(selector, str) and name_key(selector) in names:
        return names[name_key(selector)]
    raise fail(path, f"{where}.structure", f"names no structure of the file (got {selector!r})")
