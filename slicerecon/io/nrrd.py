"""NRRD label maps and 3D Slicer segmentations (``.nrrd``, ``.seg.nrrd``).

Headers are parsed, and files written, by pynrrd (``import nrrd``). Two kinds
of file are read:

* **plain NRRD label maps**: a 3-D image of integer label values (as ITK,
  ITK-SNAP or Slicer's "labelmap volume" export write them); every non-zero
  value is a structure, without a name;
* **Slicer segmentations** (``.seg.nrrd``, any NRRD holding ``Segment<N>_*``
  key/value pairs): each segment has a name, a colour, a label value and a
  layer. A file whose segments overlap has a fourth, ``list`` axis: one 3-D
  layer per group of non-overlapping segments. The layers are flattened into
  one label map (:func:`read_nrrd_label_map`).

Geometry: voxel index ``(i, j, k)`` along the three spatial axes, in the
file's axis order, lies at ``space origin + Σ index · space direction``. The
``space`` field gives the world frame: ``right-anterior-superior`` (RAS) and
``left-posterior-superior`` (LPS, what Slicer writes) are kept as they are,
``left-anterior-superior`` is turned into RAS; spaces without an anatomical
meaning (``scanner-xyz``, ``3D-right-handed``, ...) are used as they are and
called RAS. A file without space fields gets its ``spacings`` (default 1 mm)
along the array axes and its ``axis mins`` (default 0) as origin.

Every check that needs only the header (dimensions, data type, geometry, the
memory budget) runs before a voxel is read. Compressed voxel data (gzip,
bzip2) is decompressed here with a bound: never more bytes than the header
declares, so a small file cannot expand past the memory budget.
"""

from __future__ import annotations

import bz2
import logging
import math
import os
import re
import zlib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import numpy as np
from numpy.typing import NDArray

from ..errors import (
    DependencyError,
    EmptyMaskError,
    FormatError,
    GeometryError,
    InputError,
    LabelError,
)
from ..sections import Volume, check_affine
from .labelmap import LabelMap, Structure
from .limits import DEFAULT_MEMORY_BUDGET_GB, check_geometry, check_grid, reading
from .selection import choose_structure, parse_selector

__all__ = [
    "NrrdInfo",
    "NrrdSegment",
    "labels_dtype",
    "label_values",
    "nrrd_info",
    "pynrrd_module",
    "read_nrrd",
    "read_nrrd_label_map",
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

_LPS_TO_RAS = np.diag([-1.0, -1.0, 1.0, 1.0])
_LAS_TO_RAS = np.diag([-1.0, 1.0, 1.0, 1.0])

_COMPRESSED = {"gzip": "gzip", "gz": "gzip", "bzip2": "bzip2", "bz2": "bzip2"}


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
    """

    index: int
    id: str
    name: str
    colour: tuple[int, int, int] | None
    label_value: int
    layer: int
    extent: tuple[int, int, int, int, int, int] | None

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


def _open(path: str | os.PathLike[str]) -> Path:
    p = Path(path)
    if not p.exists():
        raise InputError(f"NRRD file not found: {p}")
    if p.is_dir():
        raise InputError(f"{p} is a directory, not a NRRD file (.nrrd / .seg.nrrd)")
    return p


def _read_header(p: Path, fh: IO[bytes]) -> dict[str, Any]:
    magic = fh.read(len(_MAGIC))
    if magic != _MAGIC:
        raise FormatError(f"{p} is not a NRRD file: it does not start with 'NRRD000'")
    fh.seek(0)
    header: dict[str, Any] = dict(pynrrd_module().read_header(fh))
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
        rows = np.asarray(directions, dtype=np.float64)
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
    rows = np.asarray(directions, dtype=np.float64)
    if rows.ndim != 2 or rows.shape[1] != 3:
        raise GeometryError(f"{p}: 'space directions' must hold 3-D vectors")
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
            fields.setdefault(int(match.group(1)), {})[match.group(2)] = str(value).strip()
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
                label_value=number("LabelValue", 1),
                layer=layer,
                extent=_extent(p, index, own.get("Extent")),
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


def _info(p: Path, header: Mapping[str, Any]) -> NrrdInfo:
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
    p = _open(path)
    with reading(p), open(p, "rb") as fh:
        return _info(p, _read_header(p, fh))


def _decompress(p: Path, fh: IO[bytes], method: str, limit: int) -> bytearray:
    """At most ``limit`` bytes of a gzip / bzip2 stream; more is a FormatError."""
    decoder: Any = (
        zlib.decompressobj(zlib.MAX_WBITS | 32) if method == "gzip" else bz2.BZ2Decompressor()
    )
    out = bytearray()

    def more(data: bytes) -> None:
        out.extend(decoder.decompress(data, limit + 1 - len(out)))
        if len(out) > limit:
            raise FormatError(
                f"{p} holds more voxel data than its header declares ({limit} bytes); "
                "the file is corrupt"
            )

    def pending() -> bool:  # output held back by the bound, to be drained
        if method == "gzip":
            return bool(decoder.unconsumed_tail)
        return not decoder.needs_input

    while not decoder.eof:
        chunk = fh.read(1 << 22)
        if not chunk:
            break
        more(chunk)
        while not decoder.eof and pending():
            more(decoder.unconsumed_tail if method == "gzip" else b"")
    return out


def _voxels(p: Path, header: Mapping[str, Any], info: NrrdInfo, fh: IO[bytes]) -> NDArray[Any]:
    """Every voxel value, shape ``(layers, I, J, K)``."""
    sizes = [int(s) for s in header["sizes"]]
    count = math.prod(sizes)
    encoding = str(header["encoding"]).lower()
    line_skip = int(header.get("line skip", header.get("lineskip", 0)))
    byte_skip = int(header.get("byte skip", header.get("byteskip", 0)))
    if encoding in _COMPRESSED and line_skip >= 0 and byte_skip >= 0:
        for _ in range(line_skip):
            fh.readline()
        need = count * info.dtype.itemsize
        raw = _decompress(p, fh, _COMPRESSED[encoding], need + byte_skip)
        if len(raw) - byte_skip < need:
            held = max(len(raw) - byte_skip, 0) // info.dtype.itemsize
            raise FormatError(
                f"{p} is truncated: its voxel data holds {held} of the {count} values "
                "the header declares"
            )
        flat = np.frombuffer(raw, dtype=info.dtype, count=count, offset=byte_skip)
    else:
        flat = pynrrd_module().read_data(dict(header), fh, str(p), index_order="C").ravel()
    data = flat.reshape(sizes[::-1]).T  # NRRD's first axis varies fastest
    if info.layer_axis is None:
        return data[np.newaxis]
    return np.moveaxis(data, info.layer_axis, 0)


def _integer_values(p: Path, data: NDArray[Any]) -> NDArray[np.integer]:
    """The voxels as integers: float data must hold whole, finite numbers."""
    if data.dtype.kind in "iu":
        return data.astype(data.dtype.newbyteorder("="), copy=False)
    if not np.all(np.isfinite(data)):
        raise LabelError(f"{p} is not a label map: it holds NaN or infinite values")
    fractional = data != np.round(data)
    if fractional.any():
        raise LabelError(
            f"{p} is not a label map: it holds non-integer values (e.g. "
            f"{float(data[fractional].flat[0]):g}); pass an integer label map"
        )
    lo, hi = (int(data.min()), int(data.max())) if data.size else (0, 0)
    return data.astype(np.result_type(np.min_scalar_type(lo), np.min_scalar_type(hi)))


def labels_dtype(values: Sequence[int]) -> np.dtype[Any]:
    lo, hi = min(values, default=0), max(values, default=0)
    if lo >= 0:
        return np.dtype(np.uint8 if hi < 2**8 else np.uint16 if hi < 2**16 else np.uint32)
    return np.dtype(np.int16 if -(2**15) <= lo and hi < 2**15 else np.int32)


def label_values(layer: NDArray[np.integer]) -> set[int]:
    """The values a label layer holds (0 when any voxel is background)."""
    foreground = layer[layer != 0]  # label maps are mostly background: count only the rest
    found = {0} if foreground.size < layer.size else set()
    if layer.dtype.kind == "u" and layer.dtype.itemsize <= 2:
        return found | {int(v) for v in np.flatnonzero(np.bincount(foreground))}
    return found | {int(v) for v in np.unique(foreground)}


def _flatten(p: Path, info: NrrdInfo, data: NDArray[np.integer]) -> LabelMap:
    """One label map from the segments of every layer; later layers win on overlap."""
    kept: list[NrrdSegment] = []
    for segment in info.segments:
        if segment.label_value == 0:
            logger.warning(
                "%s: segment %d (%s) has label value 0, the background; it is skipped",
                p,
                segment.index,
                segment.name,
            )
            continue
        kept.append(segment)
    values = [s.label_value for s in kept]
    if len(set(values)) == len(values):
        out_value = {s.index: s.label_value for s in kept}
    else:
        out_value = {s.index: n for n, s in enumerate(kept, start=1)}
        logger.warning(
            "%s: segments of different layers share label values; they are numbered in file "
            "order: %s",
            p,
            ", ".join(
                f"{s.name or s.index} (layer {s.layer}, value {s.label_value}) -> "
                f"{out_value[s.index]}"
                for s in kept
            ),
        )
    labels = np.zeros(info.shape, dtype=labels_dtype(list(out_value.values())))
    overlap = 0
    for layer in range(info.layers):
        own = [s for s in kept if s.layer == layer]
        claimed = {s.label_value for s in info.segments if s.layer == layer}
        stray = sorted(label_values(data[layer]) - claimed - {0})
        if stray:
            listed = ", ".join(str(v) for v in stray[:10])
            logger.warning(
                "%s: layer %d holds values no segment claims (%s%s); they are ignored",
                p,
                layer,
                listed,
                ", ..." if len(stray) > 10 else "",
            )
        for segment in sorted(own, key=lambda s: s.index):
            mask = data[layer] == segment.label_value
            if segment.extent is not None:
                mask &= _inside(segment.extent, info.shape)
            overlap += int(np.count_nonzero(labels[mask]))
            labels[mask] = out_value[segment.index]
    if overlap:
        logger.warning(
            "%s: segments of different layers overlap on %d voxels; each goes to "
            "the segment of the later layer",
            p,
            overlap,
        )
    present = label_values(labels)
    structures = []
    for segment in sorted(kept, key=lambda s: out_value[s.index]):
        value = out_value[segment.index]
        if value not in present:
            logger.warning(
                "%s: segment %d (%s) holds no voxel; it is skipped", p, segment.index, segment.name
            )
            continue
        structures.append(Structure(value, segment.name, segment.colour))
    return LabelMap(labels, info.affine, tuple(structures), info.coordinates)


def _inside(extent: Sequence[int], shape: Sequence[int]) -> NDArray[np.bool_]:
    """The voxels of ``shape`` inside an inclusive ``(i0, i1, j0, j1, k0, k1)`` extent."""
    box = np.zeros(tuple(shape), dtype=bool)
    region = tuple(slice(max(extent[2 * a], 0), max(extent[2 * a + 1] + 1, 0)) for a in range(3))
    box[region] = True
    return box


def read_nrrd_label_map(
    path: str | os.PathLike[str],
    *,
    memory_budget_gb: float = DEFAULT_MEMORY_BUDGET_GB,
) -> LabelMap:
    """Every structure of a NRRD label map or Slicer segmentation, on one grid.

    Parameters
    ----------
    path : path-like
        A ``.nrrd`` label map (3-D, integer values, or floats holding whole
        numbers) or a ``.seg.nrrd`` segmentation (3-D, or 4-D with a list axis
        of layers).
    memory_budget_gb : float
        Refuse headers whose declared grid would not fit this budget, GiB
        (:func:`slicerecon.io.limits.check_grid`), before reading any voxel.

    Returns
    -------
    LabelMap
        Labels of shape ``(I, J, K)`` (the file's spatial axes in order), the
        affine in ``coordinates`` (``"LPS"`` or ``"RAS"``, from ``space``).
        A plain label map has one structure per non-zero value, unnamed. A
        segmentation has one per segment that holds a voxel, with its name and
        colour; its value is ``Segment<N>_LabelValue``, unless segments of
        different layers share values: then segments are numbered 1, 2, ... in
        file order (with a warning). Segments with label value 0 or without a
        voxel are skipped with a warning; on overlap the later layer wins.
        A file whose every voxel is background gives no structure.

    Raises
    ------
    InputError
        What :func:`nrrd_info` raises; a plain 4-D image of several volumes.
    FormatError
        Truncated or corrupt voxel data, more data than declared.
    LabelError
        Non-integer or non-finite voxel values.
    MemoryBudgetError
        The declared grid exceeds ``memory_budget_gb``.
    """
    p = _open(path)
    with reading(p), open(p, "rb") as fh:
        header = _read_header(p, fh)
        info = _info(p, header)
        if not info.is_segmentation and info.layers > 1:
            raise InputError(
                f"{p} is a 4-D image holding {info.layers} volumes and no Slicer segment "
                "fields; extract the one 3-D label map to use and pass that"
            )
        check_grid(
            info.shape,
            what=str(p),
            memory_budget_gb=memory_budget_gb,
            bytes_per_voxel=2 * info.layers * info.dtype.itemsize + 5,
        )
        data = _integer_values(p, _voxels(p, header, info, fh))
    if info.is_segmentation:
        result = _flatten(p, info, data)
    else:
        labels = data[0]
        values = sorted(label_values(labels) - {0})
        result = LabelMap(
            labels, info.affine, tuple(Structure(v) for v in values), info.coordinates
        )
    logger.info(
        "read %s: %s, %d structure(s), %s",
        p,
        "x".join(map(str, info.shape)),
        len(result.structures),
        info.coordinates,
    )
    return result


def read_nrrd(
    path: str | os.PathLike[str],
    *,
    label: int | str | None = None,
    memory_budget_gb: float = DEFAULT_MEMORY_BUDGET_GB,
) -> Volume:
    """One structure (or every non-zero voxel) of a NRRD label map or segmentation.

    Parameters
    ----------
    path : path-like
        As for :func:`read_nrrd_label_map`.
    label : int or str, optional
        The structure, by value or, for a segmentation, by segment name
        (:func:`slicerecon.io.selection.choose_structure`). Default: every
        non-zero voxel.
    memory_budget_gb : float
        As for :func:`read_nrrd_label_map`.

    Returns
    -------
    Volume
        The mask and the affine (in the file's frame: see :func:`nrrd_info`).

    Raises
    ------
    EmptyMaskError
        Every voxel is background.
    LabelError
        ``label`` names no structure (the message lists them).
    InputError
        What :func:`read_nrrd_label_map` raises.
    """
    selector = parse_selector(label)
    label_map = read_nrrd_label_map(path, memory_budget_gb=memory_budget_gb)
    if not label_map.structures:
        raise EmptyMaskError(
            f"{path} is empty: every voxel is background, there is nothing to reconstruct"
        )
    if selector is None:
        return label_map.union()
    names = {s.value: s.name for s in label_map.structures}
    kind = "segment" if any(names.values()) else "label"
    return label_map.mask(choose_structure(names, selector, kind=kind, source=Path(path)))
