"""The header of a NRRD file: what it declares, checked before any voxel is read.

Type, axes, geometry (space, directions, origin, units), the segments of a 3D
Slicer segmentation, and :func:`nrrd_info`, the description ``slicerecon
info`` shows. Parsing is pynrrd's (:func:`pynrrd_module`); the rules are
documented in :mod:`slicerecon.io.nrrd` and ``docs/formats.md``.
"""

from __future__ import annotations

import logging
import math
import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import numpy as np
from numpy.typing import NDArray

from ..errors import DependencyError, FormatError, GeometryError, InputError, LabelError
from ..sections import check_affine
from .limits import check_geometry, reading

__all__ = [
    "COMPRESSED",
    "MAX_HEADER_BYTES",
    "NrrdInfo",
    "NrrdSegment",
    "header_info",
    "nrrd_info",
    "open_nrrd",
    "pynrrd_module",
    "read_header",
    "escape",
    "unescape",
]

logger = logging.getLogger(__name__)

_MAGIC = b"NRRD000"

_INTEGER_TYPES: dict[str, str] = {
    **dict.fromkeys(("signed char", "int8", "int8_t"), "i1"),
    **dict.fromkeys(("uchar", "unsigned char", "uint8", "uint8_t"), "u1"),
    **dict.fromkeys(
        ("short", "short int", "signed short", "signed short int", "int16", "int16_t"), "i2"
    ),
    **dict.fromkeys(("ushort", "unsigned short", "unsigned short int", "uint16", "uint16_t"), "u2"),
    **dict.fromkeys(("int", "signed int", "int32", "int32_t"), "i4"),
    **dict.fromkeys(("uint", "unsigned int", "uint32", "uint32_t"), "u4"),
    **dict.fromkeys(
        (
            "longlong",
            "long long",
            "long long int",
            "signed long long",
            "signed long long int",
            "int64",
            "int64_t",
        ),
        "i8",
    ),
    **dict.fromkeys(
        ("ulonglong", "unsigned long long", "unsigned long long int", "uint64", "uint64_t"), "u8"
    ),
}
"""NRRD ``type`` names of integer data → numpy type codes (byte order added per file)."""

_FLOAT_TYPES = {"float": "f4", "double": "f8"}

_SPACES: dict[str, str | None] = {
    "right-anterior-superior": "RAS",
    "ras": "RAS",
    "left-anterior-superior": "LAS",
    "las": "LAS",
    "left-posterior-superior": "LPS",
    "lps": "LPS",
    "scanner-xyz": None,
    "3d-right-handed": None,
    "3d-left-handed": None,
}
"""NRRD 3-D ``space`` values → anatomical frame (None: no anatomical meaning)."""

_UNITS_MM = {
    "": 1.0,
    "mm": 1.0,
    "millimeter": 1.0,
    "millimeters": 1.0,
    "millimetre": 1.0,
    "millimetres": 1.0,
    "cm": 10.0,
    "m": 1000.0,
    "um": 1e-3,
    "µm": 1e-3,
    "micron": 1e-3,
    "microns": 1e-3,
}
"""``space units`` → millimetres per unit."""

_SEGMENT_KEY = re.compile(r"^Segment(\d+)_(.+)$")

_LAS_TO_RAS = np.diag([-1.0, 1.0, 1.0, 1.0])

COMPRESSED = {"gzip": "gzip", "gz": "gzip", "bzip2": "bzip2", "bz2": "bzip2"}

MAX_HEADER_BYTES = 16 * 2**20
"""Longest NRRD header read, bytes (3D Slicer writes about 1 kB per segment)."""


def unescape(value: str) -> str:
    """A key/value pair's value as written: ``\\n`` is a newline, ``\\\\`` a backslash."""
    if "\\" not in value:
        return value
    return re.sub(r"\\(.)", lambda m: "\n" if m.group(1) == "n" else m.group(1), value)


def escape(value: str) -> str:
    """The inverse of :func:`unescape`: what a NRRD key/value pair may hold on one line."""
    return value.replace("\\", "\\\\").replace("\n", "\\n")


def pynrrd_module() -> Any:
    try:
        import nrrd
    except ImportError as exc:  # pragma: no cover - pynrrd is a dependency
        raise DependencyError(
            "reading or writing NRRD needs pynrrd: pip install 'pynrrd>=1.0'"
        ) from exc
    return nrrd


@dataclass(frozen=True)
class NrrdSegment:
    """One segment of a Slicer segmentation, as its ``Segment<N>_*`` fields say.

    Attributes
    ----------
    index : int
        ``N`` of the ``Segment<N>_`` keys.
    id : str
        ``Segment<N>_ID`` ("" when absent).
    name : str
        ``Segment<N>_Name``, else the ID.
    colour : tuple of 3 int or None
        ``Segment<N>_Color`` (three numbers 0-1) as RGB 0-255.
    label_value : int
        ``Segment<N>_LabelValue``: the voxel value of the segment in its layer
        (default 1, as Slicer reads files written before label values existed).
    layer : int
        ``Segment<N>_Layer``: the index along the list axis (default ``N`` for
        a 4-D file, 0 for a 3-D file).
    extent : tuple of 6 int or None
        ``Segment<N>_Extent``: ``(i0, i1, j0, j1, k0, k1)``, inclusive file
        indices outside which the segment has no voxel; ``i0 > i1`` means empty.
    label_value_given : bool
        False when the header has no ``Segment<N>_LabelValue`` (1 is assumed).
    """

    index: int
    id: str
    name: str
    colour: tuple[int, int, int] | None
    label_value: int
    layer: int
    extent: tuple[int, int, int, int, int, int] | None
    label_value_given: bool = True

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {
            "index": self.index,
            "id": self.id,
            "name": self.name,
            "colour": None if self.colour is None else list(self.colour),
            "label_value": self.label_value,
            "layer": self.layer,
            "extent": None if self.extent is None else list(self.extent),
        }


@dataclass(frozen=True, eq=False)
class NrrdInfo:
    """What an NRRD header declares, read without any voxel.

    Attributes
    ----------
    path : Path
        The file.
    shape : tuple of 3 int
        The spatial grid ``(I, J, K)``, in the file's axis order.
    layers : int
        Number of 3-D layers (the length of the list axis; 1 for a 3-D file).
    layer_axis : int or None
        The list axis among the file's axes (None for a 3-D file).
    affine : ndarray of shape (4, 4)
        Voxel index → world mm in ``coordinates``.
    coordinates : {"RAS", "LPS"}
        The world frame.
    dtype : numpy.dtype
        The voxel data type, with its byte order.
    segments : tuple of NrrdSegment
        The Slicer segments (empty for a plain label map).
    """

    path: Path
    shape: tuple[int, int, int]
    layers: int
    layer_axis: int | None
    affine: NDArray[np.float64]
    coordinates: str
    dtype: np.dtype[Any]
    segments: tuple[NrrdSegment, ...]

    @property
    def is_segmentation(self) -> bool:
        """True for a Slicer segmentation (``Segment<N>_*`` fields)."""
        return bool(self.segments)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form."""
        return {
            "path": str(self.path),
            "shape": list(self.shape),
            "layers": self.layers,
            "affine": self.affine.tolist(),
            "coordinates": self.coordinates,
            "dtype": str(self.dtype),
            "segments": [s.to_dict() for s in self.segments],
        }


# --------------------------------------------------------------------------- reading


def open_nrrd(path: str | os.PathLike[str]) -> Path:
    p = Path(path)
    if not p.exists():
        raise InputError(f"NRRD file not found: {p}")
    if p.is_dir():
        raise InputError(f"{p} is a directory, not a NRRD file (.nrrd / .seg.nrrd)")
    return p


def _header_lines(p: Path, fh: IO[bytes]) -> list[str]:
    """The header's lines, up to the blank line that ends it; ``fh`` is left just after it.

    Lines are decoded as UTF-8 (what 3D Slicer writes; Latin-1 for files that are
    not UTF-8), so segment names keep their accents (pynrrd would drop them).
    """
    lines: list[str] = []
    size = 0
    while True:
        line = fh.readline(MAX_HEADER_BYTES + 1 - size)
        size += len(line)
        if size > MAX_HEADER_BYTES:
            raise FormatError(
                f"{p}: its header runs past {MAX_HEADER_BYTES // 2**20} MiB without the blank "
                "line that ends a NRRD header; the file is corrupt"
            )
        if not line:
            return lines  # a header without data
        text = line.rstrip(b"\r\n")
        try:
            lines.append(text.decode("utf-8"))
        except UnicodeDecodeError:
            lines.append(text.decode("latin-1"))
        if lines[-1].strip() == "" and len(lines) > 1:
            return lines


def read_header(p: Path, fh: IO[bytes]) -> dict[str, Any]:
    """Parse the header of an open NRRD file; ``fh`` is left at the first byte after it.

    Raises
    ------
    FormatError
        Not a NRRD file, a header over :data:`MAX_HEADER_BYTES`, detached data.
    """
    magic = fh.read(len(_MAGIC))
    if magic != _MAGIC:
        raise FormatError(f"{p} is not a NRRD file: it does not start with 'NRRD000'")
    fh.seek(0)
    header: dict[str, Any] = dict(pynrrd_module().read_header(_header_lines(p, fh)))
    if header.get("data file", header.get("datafile")) is not None:
        raise FormatError(
            f"{p} keeps its voxels in a separate file (data file: "
            f"{header.get('data file', header.get('datafile'))}); save it as one .nrrd "
            "file with attached data"
        )
    return header


def _dtype(p: Path, header: Mapping[str, Any]) -> np.dtype[Any]:
    name = str(header["type"]).strip().lower()
    code = _INTEGER_TYPES.get(name) or _FLOAT_TYPES.get(name)
    if code is None:
        raise LabelError(
            f"{p} is not a label map: its voxels have NRRD type {header['type']!r}; "
            "pass an integer label map"
        )
    dtype = np.dtype(code)
    if dtype.itemsize > 1 and str(header["encoding"]).lower() not in ("ascii", "text", "txt"):
        endian = str(header.get("endian", "")).lower()
        if endian not in ("little", "big"):
            raise FormatError(
                f"{p}: 'endian' must be little or big for {name} data "
                f"(got {header.get('endian')!r})"
            )
        dtype = dtype.newbyteorder("<" if endian == "little" else ">")
    return dtype


def _axes(p: Path, header: Mapping[str, Any]) -> tuple[list[int], int | None]:
    """The three spatial axes of the file and its list axis (None for 3-D)."""
    dimension = int(header["dimension"])
    sizes = [int(s) for s in header["sizes"]]
    if len(sizes) != dimension:
        raise FormatError(f"{p}: 'sizes' lists {len(sizes)} sizes for dimension {dimension}")
    if any(s < 1 for s in sizes):
        raise FormatError(f"{p}: 'sizes' must be positive (got {' '.join(map(str, sizes))})")
    if dimension == 3:
        return [0, 1, 2], None
    if dimension != 4:
        raise InputError(
            f"{p} is a {dimension}-D NRRD image (sizes {' '.join(map(str, sizes))}); a 3-D "
            "label map, or a Slicer segmentation with one list axis, is needed"
        )
    directions = header.get("space directions")
    if directions is not None:
        rows = _direction_rows(p, directions, dimension)
        listed = [a for a in range(4) if not np.all(np.isfinite(rows[a]))]
    else:
        kinds = [str(k).lower() for k in header.get("kinds", [])]
        listed = [a for a, k in enumerate(kinds) if k not in ("domain", "space", "???", "none")]
        if not listed and len(kinds) != 4:
            listed = [a for a in range(4) if sizes[a] == 1][:1]
    if len(listed) != 1:
        raise FormatError(
            f"{p}: a 4-D NRRD needs exactly one non-spatial (list) axis, told by "
            "'space directions: none ...' or 'kinds: list ...'; this header does not say "
            "which axis holds the layers"
        )
    return [a for a in range(4) if a != listed[0]], listed[0]


def _units_mm(p: Path, header: Mapping[str, Any]) -> NDArray[np.float64]:
    units = header.get("space units")
    if units is None:
        return np.ones(3)
    names = [str(u).strip().lower() for u in units]
    unknown = [u for u in names if u not in _UNITS_MM]
    if len(names) != 3 or unknown:
        raise GeometryError(
            f"{p}: 'space units' {units!r} is not a length slicerecon knows "
            f"(use {', '.join(u for u in _UNITS_MM if u)})"
        )
    return np.array([_UNITS_MM[u] for u in names])


def _geometry(
    p: Path, header: Mapping[str, Any], spatial: Sequence[int]
) -> tuple[NDArray[np.float64], str]:
    """Voxel index → world mm and the frame's name, from the header alone."""
    affine = np.eye(4)
    space = header.get("space")
    directions = header.get("space directions")
    if space is None and directions is None:
        spacings = _per_axis(header.get("spacings"), spatial, 1.0)
        origin = _per_axis(header.get("axis mins", header.get("axismins")), spatial, 0.0)
        centers = header.get("centerings", header.get("centers"))
        if isinstance(centers, str):
            centers = centers.split()
        for n, axis in enumerate(spatial):
            if centers is not None and axis < len(centers) and str(centers[axis]) == "cell":
                origin[n] += spacings[n] / 2  # axis mins is the edge of a cell-centred axis
        affine[:3, :3] = np.diag(spacings)
        affine[:3, 3] = origin
        logger.info(
            "%s has no space fields: spacings %s mm along the array axes",
            p,
            ", ".join(f"{s:g}" for s in spacings),
        )
        return affine, "RAS"
    if space is not None:
        key = str(space).strip().lower()
        if key not in _SPACES:
            raise GeometryError(
                f"{p}: space {space!r} is not a 3-D space (time spaces are not label maps); "
                "expected right-anterior-superior, left-posterior-superior, ..."
            )
        frame = _SPACES[key]
    else:
        frame = None
        dimension = header.get("space dimension")
        if dimension is not None and int(dimension) != 3:
            raise GeometryError(f"{p}: space dimension {dimension} is not 3")
    if directions is None:
        raise GeometryError(f"{p}: 'space' is given without 'space directions'")
    rows = _direction_rows(p, directions, int(header["dimension"]))
    affine[:3, :3] = rows[list(spatial)].T
    given = header.get("space origin")
    if given is not None:
        vector = np.asarray(given, dtype=np.float64).ravel()
        if vector.size != 3:
            raise GeometryError(f"{p}: 'space origin' must be a 3-D vector")
        affine[:3, 3] = vector
    affine[:3] *= _units_mm(p, header)[:, None]  # world rows in mm
    if frame == "LAS":
        return _LAS_TO_RAS @ affine, "RAS"
    if frame is None:
        logger.warning(
            "%s: space %s has no anatomical orientation; its coordinates are "
            "used as they are (as RAS)",
            p,
            space if space is not None else "(none)",
        )
        return affine, "RAS"
    return affine, frame


def _direction_rows(p: Path, directions: Any, dimension: int) -> NDArray[np.float64]:
    """``space directions`` as one 3-D row per axis (NaN for ``none``)."""
    rows = np.asarray(directions, dtype=np.float64)
    if rows.ndim != 2 or rows.shape[1] != 3:
        raise GeometryError(f"{p}: 'space directions' must hold 3-D vectors (x,y,z)")
    if rows.shape[0] != dimension:
        raise GeometryError(
            f"{p}: 'space directions' lists {rows.shape[0]} vectors for a {dimension}-D image; "
            "it needs one per axis ('none' for a list axis)"
        )
    return rows


def _per_axis(values: Any, spatial: Sequence[int], default: float) -> NDArray[np.float64]:
    out = np.full(3, default)
    if values is None:
        return out
    array = np.asarray(values, dtype=np.float64).ravel()
    for n, axis in enumerate(spatial):
        if axis < array.size and np.isfinite(array[axis]):
            out[n] = array[axis]
    return out


def _segments(
    p: Path, header: Mapping[str, Any], layers: int, four_d: bool
) -> tuple[NrrdSegment, ...]:
    fields: dict[int, dict[str, str]] = {}
    for key, value in header.items():
        match = _SEGMENT_KEY.match(str(key))
        if match:
            fields.setdefault(int(match.group(1)), {})[match.group(2)] = unescape(
                str(value).strip()
            )
    out = []
    for index in sorted(fields):
        own = fields[index]

        def number(field: str, default: int, own: dict[str, str] = own, index: int = index) -> int:
            text = own.get(field)
            if text is None or text == "":
                return default
            try:
                return int(text)
            except ValueError:
                raise FormatError(
                    f"{p}: Segment{index}_{field} must be an integer (got {text!r})"
                ) from None

        label_value = number("LabelValue", 1)
        if not 0 <= label_value < 2**31:
            raise FormatError(
                f"{p}: Segment{index}_LabelValue must be a voxel value from 0 to 2^31 - 1 "
                f"(got {label_value})"
            )
        layer = number("Layer", index if four_d else 0)
        if not 0 <= layer < layers:
            raise FormatError(
                f"{p}: Segment{index}_Layer is {layer}, but the file holds {layers} "
                f"layer{'s' if layers != 1 else ''}"
            )
        seg_id = own.get("ID", "")
        out.append(
            NrrdSegment(
                index=index,
                id=seg_id,
                name=own.get("Name") or seg_id,
                colour=_colour(p, index, own.get("Color", own.get("DefaultColor"))),
                label_value=label_value,
                layer=layer,
                extent=_extent(p, index, own.get("Extent")),
                label_value_given=bool(own.get("LabelValue")),
            )
        )
    return tuple(out)


def _colour(p: Path, index: int, text: str | None) -> tuple[int, int, int] | None:
    if not text:
        return None
    try:
        values = [float(v) for v in text.split()]
    except ValueError:
        values = []
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        logger.warning(
            "%s: Segment%d_Color %r is not three numbers 0-1; the segment has no colour",
            p,
            index,
            text,
        )
        return None
    r, g, b = (int(round(min(max(v, 0.0), 1.0) * 255)) for v in values)
    return r, g, b


def _extent(p: Path, index: int, text: str | None) -> tuple[int, int, int, int, int, int] | None:
    if not text:
        return None
    try:
        values = [int(v) for v in text.split()]
    except ValueError:
        values = []
    if len(values) != 6:
        raise FormatError(
            f"{p}: Segment{index}_Extent must be 6 integers (i0 i1 j0 j1 k0 k1; got {text!r})"
        )
    i0, i1, j0, j1, k0, k1 = values
    return i0, i1, j0, j1, k0, k1


def header_info(p: Path, header: Mapping[str, Any]) -> NrrdInfo:
    for field in ("dimension", "type", "encoding", "sizes"):
        if field not in header:
            raise FormatError(f"{p}: the NRRD header has no '{field}' field")
    spatial, layer_axis = _axes(p, header)
    sizes = [int(s) for s in header["sizes"]]
    shape = (sizes[spatial[0]], sizes[spatial[1]], sizes[spatial[2]])
    layers = 1 if layer_axis is None else sizes[layer_axis]
    dtype = _dtype(p, header)
    affine, frame = _geometry(p, header, spatial)
    check_geometry(affine, shape, what=str(p))
    affine = np.array(check_affine(affine))
    segments = _segments(p, header, layers, layer_axis is not None)
    return NrrdInfo(p, shape, layers, layer_axis, affine, frame, dtype, segments)


def nrrd_info(path: str | os.PathLike[str]) -> NrrdInfo:
    """Read an NRRD header: grid, geometry, data type and Slicer segments, no voxel.

    Parameters
    ----------
    path : path-like
        A ``.nrrd`` or ``.seg.nrrd`` file.

    Returns
    -------
    NrrdInfo

    Raises
    ------
    InputError
        Missing file; not 3-D (or 4-D with one list axis).
    FormatError
        Not NRRD, a header pynrrd cannot parse, detached data, bad segment fields.
    LabelError
        A non-numeric voxel type.
    GeometryError
        A space that is not 3-D, absurd or non-finite spacing, origin or extent.
    """
    p = open_nrrd(path)
    with reading(p), open(p, "rb") as fh:
        return header_info(p, read_header(p, fh))
