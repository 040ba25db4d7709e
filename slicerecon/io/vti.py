"""VTK XML ImageData (``.vti``) label maps, read without VTK.

A ``.vti`` file is an XML header describing a regular grid (``WholeExtent``,
``Origin``, ``Spacing``, optional ``Direction``) and its point or cell arrays.
Array bytes are stored inline as base64 (``format="binary"``), as ASCII
numbers (``format="ascii"``), or in an ``<AppendedData>`` block at the end of
the file (``format="appended"``, raw bytes or base64). Binary data is preceded
by a header of ``UInt32`` or ``UInt64`` integers (``header_type``): the byte
count for uncompressed data; for compressed data
``[n_blocks, block_size, last_block_size, compressed_size_1 ... _n]``
followed by the independently compressed blocks. zlib
(``vtkZLibDataCompressor``) and LZMA (``vtkLZMADataCompressor``) blocks are
decoded; LZ4 is not.

Grid convention (VTK): values are ordered x fastest; point ``(i, j, k)`` of
an array whose extent starts at ``(i0, j0, k0)`` lies at
``Origin + Direction @ (Spacing * (i0 + i, j0 + j, k0 + k))``, with
``Direction`` given row by row. Cell data sits at cell centres, half a voxel
further along each axis. The returned arrays use slicerecon's index order
``(x, y, z)``.
"""

from __future__ import annotations

import base64
import binascii
import logging
import lzma
import os
import re
import zlib
from pathlib import Path
from typing import NamedTuple
from xml.etree import ElementTree

import numpy as np
from numpy.typing import NDArray

from ..errors import FormatError, InputError, LabelError, OptionError
from .limits import DEFAULT_MEMORY_BUDGET_GB, check_geometry, check_grid

__all__ = ["VtiImage", "read_vti"]

logger = logging.getLogger(__name__)

_TYPES: dict[str, str] = {
    "Int8": "i1",
    "UInt8": "u1",
    "Int16": "i2",
    "UInt16": "u2",
    "Int32": "i4",
    "UInt32": "u4",
    "Int64": "i8",
    "UInt64": "u8",
    "Float32": "f4",
    "Float64": "f8",
    # legacy names written by old VTK versions
    "Char": "i1",
    "UnsignedChar": "u1",
    "Short": "i2",
    "UnsignedShort": "u2",
    "Int": "i4",
    "UnsignedInt": "u4",
    "Long": "i8",
    "UnsignedLong": "u8",
    "Float": "f4",
    "Double": "f8",
}
"""VTK XML data type names → numpy type codes (byte order added per file)."""

_COMPRESSORS = ("vtkZLibDataCompressor", "vtkLZMADataCompressor")


class VtiImage(NamedTuple):
    """One scalar array of a ``.vti`` file on its grid.

    Attributes
    ----------
    values : ndarray of shape (I, J, K)
        Array values in index order ``(x, y, z)``, the file's data type.
    affine : ndarray of shape (4, 4)
        Voxel index → world coordinates (file units, mm by convention), placing
        point data at grid points and cell data at cell centres.
    name : str
        Name of the array (``Name`` attribute, ``""`` when absent).
    association : str
        ``"point"`` or ``"cell"``.
    """

    values: NDArray
    affine: NDArray[np.float64]
    name: str
    association: str


def _floats(text: str | None, count: int, what: str, path: Path) -> NDArray[np.float64]:
    try:
        values = np.array([float(v) for v in (text or "").split()], dtype=np.float64)
    except ValueError:
        raise FormatError(f"{path}: {what} {text!r} is not a list of numbers") from None
    if values.size != count or not np.all(np.isfinite(values)):
        raise FormatError(f"{path}: {what} must hold {count} finite numbers (got {text!r})")
    return values


def _split_header(raw: bytes, path: Path) -> tuple[ElementTree.Element, bytes | None]:
    """Parse the XML part of a .vti file; return its root and the appended raw bytes."""
    start = raw.find(b"<AppendedData")
    appended: bytes | None = None
    if start >= 0:
        close = raw.find(b">", start)
        marker = raw.find(b"_", close)
        end = raw.rfind(b"</AppendedData>")
        if close < 0 or marker < 0 or end < marker:
            raise FormatError(f"{path}: the <AppendedData> block is truncated or malformed")
        appended_tag = raw[start : close + 1]
        encoding = re.search(rb'encoding="([^"]*)"', appended_tag)
        appended = raw[marker + 1 : end]
        if encoding is not None and encoding.group(1) == b"base64":
            appended = b"".join(appended.split())
        tag = appended_tag[:-1].rstrip(b"/") + b"/>"
        raw = raw[:start] + tag + b"</VTKFile>"
    try:
        root = ElementTree.fromstring(raw)
    except ElementTree.ParseError as exc:
        raise FormatError(f"{path}: not a readable VTK XML file ({exc})") from exc
    return root, appended


def _b64_chunks(text: bytes, path: Path) -> bytes:
    """Decode base64 text made of one or more separately padded chunks."""
    text = b"".join(text.split())
    out = []
    try:
        for chunk in re.findall(rb"[^=]*=*", text):
            if chunk:
                out.append(base64.b64decode(chunk, validate=True))
    except (binascii.Error, ValueError) as exc:
        raise FormatError(f"{path}: corrupt base64 array data ({exc})") from exc
    return b"".join(out)


def _decode_binary(
    payload: bytes,
    *,
    header: np.dtype,
    compressor: str | None,
    path: Path,
) -> bytes:
    """Array bytes from header + data (already base64-decoded)."""
    width = header.itemsize

    def ints(offset: int, count: int) -> NDArray[np.int64]:
        if len(payload) < offset + count * width:
            raise FormatError(f"{path}: array data is truncated (header cut short)")
        return np.frombuffer(payload, dtype=header, count=count, offset=offset).astype(np.int64)

    if compressor is None:
        (n_bytes,) = ints(0, 1)
        data = payload[width : width + int(n_bytes)]
        if len(data) != n_bytes:
            raise FormatError(
                f"{path}: array data is truncated ({len(data)} of {n_bytes} bytes present)"
            )
        return data
    n_blocks, block_size, last_size = (int(v) for v in ints(0, 3))
    sizes = ints(3 * width, n_blocks)
    offset = (3 + n_blocks) * width
    decompress = zlib.decompress if compressor == "vtkZLibDataCompressor" else lzma.decompress
    blocks = []
    for b, size in enumerate(sizes):
        chunk = payload[offset : offset + int(size)]
        if len(chunk) != size:
            raise FormatError(f"{path}: compressed block {b} is truncated")
        offset += int(size)
        try:
            block = decompress(chunk)
        except (zlib.error, lzma.LZMAError) as exc:
            raise FormatError(f"{path}: compressed block {b} is corrupt ({exc})") from exc
        expected = last_size if (b == n_blocks - 1 and last_size) else block_size
        if len(block) != expected:
            raise FormatError(
                f"{path}: block {b} holds {len(block)} bytes after decompression, "
                f"the header says {expected}"
            )
        blocks.append(block)
    return b"".join(blocks)


def read_vti(
    path: str | os.PathLike[str],
    *,
    array: str | None = None,
    memory_budget_gb: float = DEFAULT_MEMORY_BUDGET_GB,
) -> VtiImage:
    """Read one scalar array of a VTK XML ImageData (``.vti``) file, without VTK.

    Parameters
    ----------
    path : path-like
        A ``.vti`` file (ASCII, inline base64 or appended raw/base64 data;
        uncompressed, zlib- or LZMA-compressed).
    array : str, optional
        Name of the array to read. Default: the active point scalars
        (``<PointData Scalars=...>``), else the first point array, else the
        first cell array.
    memory_budget_gb : float
        Refuse files whose declared extent would not fit this budget, GiB
        (:func:`slicerecon.io.limits.check_grid`), before decoding any value.

    Returns
    -------
    VtiImage
        Values of shape ``(I, J, K)`` in index order ``(x, y, z)`` and the affine.

    Raises
    ------
    InputError
        If the file does not exist.
    FormatError
        If the file is not ImageData, is truncated or corrupt, uses an
        unsupported compressor or data type, or the array is not scalar.
    LabelError
        If ``array`` is not in the file (the message lists the arrays present).
    GeometryError
        Non-finite or absurd spacing, origin or direction.
    MemoryBudgetError
        The declared extent exceeds ``memory_budget_gb``.
    """
    if array is not None and not isinstance(array, str):
        raise OptionError(f"array must be an array name (got {array!r})")
    p = Path(path)
    if not p.is_file():
        raise InputError(f"VTI file not found: {p}")
    root, appended = _split_header(p.read_bytes(), p)
    if root.tag != "VTKFile" or root.get("type") != "ImageData":
        raise FormatError(
            f"{p}: not a VTK ImageData file (VTKFile type={root.get('type')!r}); "
            "only .vti image data is supported"
        )
    order = "<" if root.get("byte_order", "LittleEndian") == "LittleEndian" else ">"
    header_name = root.get("header_type", "UInt32")
    if header_name not in ("UInt32", "UInt64"):
        raise FormatError(f"{p}: unsupported header_type {header_name!r}")
    header = np.dtype(order + _TYPES[header_name])
    compressor = root.get("compressor") or None
    if compressor is not None and compressor not in _COMPRESSORS:
        raise FormatError(
            f"{p}: data compressed with {compressor}, which slicerecon cannot decode; "
            f"re-save it uncompressed or with zlib ({', '.join(_COMPRESSORS)} are supported)"
        )
    image = root.find("ImageData")
    piece = image.find("Piece") if image is not None else None
    if image is None or piece is None:
        raise FormatError(f"{p}: no <ImageData><Piece> element")
    extent = _floats(piece.get("Extent") or image.get("WholeExtent"), 6, "Extent", p)
    origin = _floats(image.get("Origin", "0 0 0"), 3, "Origin", p)
    spacing = _floats(image.get("Spacing", "1 1 1"), 3, "Spacing", p)
    direction = _floats(image.get("Direction", "1 0 0 0 1 0 0 0 1"), 9, "Direction", p)

    candidates: list[tuple[ElementTree.Element, str]] = []
    default: ElementTree.Element | None = None
    for assoc in ("Point", "Cell"):
        group = piece.find(f"{assoc}Data")
        if group is None:
            continue
        for element in group.findall("DataArray"):
            candidates.append((element, assoc.lower()))
            if default is None and assoc == "Point" and element.get("Name") == group.get("Scalars"):
                default = element
    if not candidates:
        raise FormatError(f"{p}: the file holds no data array")
    if array is None:
        element = default if default is not None else candidates[0][0]
    else:
        found = [e for e, _ in candidates if e.get("Name") == array]
        if not found:
            names = ", ".join(repr(e.get("Name", "")) for e, _ in candidates)
            raise LabelError(f"{p}: no array named {array!r}; arrays present: {names}")
        element = found[0]
    association = next(a for e, a in candidates if e is element)

    type_name = element.get("type", "")
    if type_name not in _TYPES:
        raise FormatError(f"{p}: unsupported data type {type_name!r}")
    dtype = np.dtype(order + _TYPES[type_name])
    if int(element.get("NumberOfComponents", "1")) != 1:
        raise FormatError(
            f"{p}: array {element.get('Name')!r} has "
            f"{element.get('NumberOfComponents')} components; a scalar label array is needed"
        )
    if np.any(extent != np.round(extent)) or np.any(np.abs(extent) > 2**31):
        raise FormatError(f"{p}: Extent must hold 6 integers (got {extent.tolist()})")
    counts = (extent[1::2] - extent[0::2]).astype(np.int64) + 1
    if np.any(counts < 1):
        raise FormatError(f"{p}: Extent {extent.astype(np.int64).tolist()} is empty or reversed")
    if association == "cell":
        counts = np.maximum(counts - 1, 1)
    start = extent[0::2] + (0.5 if association == "cell" else 0.0)
    rot = direction.reshape(3, 3)
    affine = np.eye(4)
    affine[:3, :3] = rot * spacing  # scales the columns
    affine[:3, 3] = origin + rot @ (spacing * start)
    check_geometry(affine, counts.tolist(), what=str(p))
    check_grid(
        counts.tolist(),
        what=str(p),
        memory_budget_gb=memory_budget_gb,
        bytes_per_voxel=3 * dtype.itemsize + 2,
    )
    n_values = int(np.prod(counts))

    fmt = element.get("format", "ascii")
    if fmt == "ascii":
        try:
            values = np.array((element.text or "").split(), dtype=np.float64).astype(dtype)
        except ValueError:
            raise FormatError(f"{p}: ASCII array data holds non-numbers") from None
    else:
        if fmt == "binary":
            payload = _b64_chunks((element.text or "").encode("ascii"), p)
        elif fmt == "appended":
            if appended is None:
                raise FormatError(f"{p}: array refers to appended data but none is present")
            offset = int(element.get("offset", "0"))
            raw_encoding = root.find("AppendedData")
            if raw_encoding is not None and raw_encoding.get("encoding") == "base64":
                later = [
                    int(e.get("offset", "0"))
                    for e, _ in candidates
                    if e.get("format") == "appended" and int(e.get("offset", "0")) > offset
                ]
                stop = min(later) if later else len(appended)
                payload = _b64_chunks(appended[offset:stop], p)
            else:
                payload = appended[offset:]
        else:
            raise FormatError(f"{p}: unknown array format {fmt!r}")
        data = _decode_binary(payload, header=header, compressor=compressor, path=p)
        values = np.frombuffer(data, dtype=dtype)
    if values.size != n_values:
        raise FormatError(
            f"{p}: array {element.get('Name')!r} holds {values.size} values; "
            f"its extent needs {n_values}"
        )
    grid = values.reshape(tuple(int(c) for c in counts), order="F")
    logger.info(
        "read %s: array %r (%s data, %s), grid %s",
        p,
        element.get("Name"),
        association,
        dtype,
        "x".join(str(int(c)) for c in counts),
    )
    return VtiImage(
        np.ascontiguousarray(grid.astype(dtype.newbyteorder("="))),
        affine,
        element.get("Name", ""),
        association,
    )
