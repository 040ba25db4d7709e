"""Seeded mutations of the fuzz seeds (``fuzz_seeds``) for ``tests/test_fuzz.py``.

:func:`make_mutant` turns ``(run seed, index)`` into one mutated input: a copy
of a seed changed by one to three mutations. Mutant ``index`` depends only on
``(run seed, index)`` and the seed files, never on the mutants before it, so
any mutant can be rebuilt alone (``benchmarks/fuzz_inputs.py --only INDEX``).

Mutations are byte-level (bit flips, inserted / deleted / duplicated chunks,
truncation, runs of 0x00 / 0xFF, interesting integers), structure-aware
(NIfTI header fields; DICOM element values, value multiplicity, VR and length
fields, sequences, transfer syntax and the files of a series; JSON nodes: deep
nesting, huge integers, NaN/Infinity, 1e308 coordinates, wrong types, missing
keys; CSV cells, columns and lines; VTI attributes and array payloads: text in
numbers, absurd spacing / extent / origin, broken base64 and zlib headers; NRRD
header fields (type, sizes, encoding, space directions, line and byte skips,
3D Slicer ``Segment<N>_*`` fields) and the voxel data after the header), and
valid-but-awkward replacements (``fuzz_seeds.write_edge_case``).
"""

from __future__ import annotations

import base64
import contextlib
import gzip
import json
import re
import shutil
import struct
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import nibabel as nib
import numpy as np
import pydicom
from fuzz_seeds import FORMATS, Seed, write_edge_case
from pydicom.dataelem import DataElement, RawDataElement
from pydicom.dataset import Dataset
from pydicom.sequence import Sequence as DicomSequence

__all__ = ["Mutant", "make_mutant", "seed_cases"]

DEFAULT_METHOD_FRACTION = 0.1
"""Share of mutants reconstructed with the default method (the rest: the cheap SDF path)."""
GRIDLESS_SPACING = 1.0
"""In-plane spacing, mm, given to ``load_input`` for most mutants of contours without a grid
(their default, extent / 256, makes every case take ~0.5 s)."""
DEFAULT_SPACING_FRACTION = 0.1
"""Share of those mutants read with the reader's default spacing instead (SDF path only)."""
EDGE_FRACTION = 0.2
"""Share of mutants that start from a valid but awkward input (``write_edge_case``)."""


@dataclass(frozen=True)
class Mutant:
    """One mutated input.

    Attributes
    ----------
    index : int
        Its number: mutant ``index`` of a run with a given seed.
    format : str
        One of :data:`FORMATS`.
    seed : str
        Name of the seed it was made from.
    path : Path
        What ``load_input`` is given (a file or a directory).
    mutations : tuple of str
        What was done, in order (``"family:detail"``).
    method : str
        ``"sdf"`` (``planner="none"``, no carving: the cheap path) or ``"default"``.
    pixel_spacing : float or None
        ``pixel_spacing`` given to ``load_input`` (None: the reader's default).
    """

    index: int
    format: str
    seed: str
    path: Path
    mutations: tuple[str, ...]
    method: str
    pixel_spacing: float | None = None


# ----------------------------------------------------------------------------- bytes
_INTERESTING = (
    0,
    1,
    -1,
    2,
    7,
    8,
    16,
    127,
    128,
    255,
    256,
    0x7FFF,
    0x8000,
    0xFFFF,
    0x10000,
    0x7FFFFFFF,
    0x80000000,
    0xFFFFFFFF,
    2**62,
    2**63 - 1,
)
_Op = Callable[[np.random.Generator, bytes], tuple[bytes, str]]


def _pos(rng: np.random.Generator, data: bytes | bytearray) -> int:
    return int(rng.integers(0, max(len(data), 1)))


def _flip(rng: np.random.Generator, data: bytes) -> tuple[bytes, str]:
    buf = bytearray(data)
    n = int(rng.integers(1, 9))
    for _ in range(n):
        if buf:
            buf[_pos(rng, buf)] ^= 1 << int(rng.integers(0, 8))
    return bytes(buf), f"flip {n} bits"


def _set_bytes(rng: np.random.Generator, data: bytes) -> tuple[bytes, str]:
    buf = bytearray(data)
    value = int(rng.choice([0x00, 0xFF, int(rng.integers(0, 256))]))
    start, n = _pos(rng, buf), int(rng.choice([1, 2, 4, 16, 64]))
    buf[start : start + n] = bytes([value]) * len(buf[start : start + n])
    return bytes(buf), f"set {n} bytes at {start} to 0x{value:02x}"


def _insert(rng: np.random.Generator, data: bytes) -> tuple[bytes, str]:
    start, n = _pos(rng, data), int(rng.choice([1, 3, 16, 64, 1000]))
    return data[:start] + rng.bytes(n) + data[start:], f"insert {n} bytes at {start}"


def _delete(rng: np.random.Generator, data: bytes) -> tuple[bytes, str]:
    start, n = _pos(rng, data), int(rng.choice([1, 2, 4, 16, 128]))
    return data[:start] + data[start + n :], f"delete {n} bytes at {start}"


def _truncate(rng: np.random.Generator, data: bytes) -> tuple[bytes, str]:
    end = _pos(rng, data)
    return data[:end], f"truncate to {end} bytes"


def _duplicate(rng: np.random.Generator, data: bytes) -> tuple[bytes, str]:
    start, n = _pos(rng, data), int(rng.choice([4, 32, 256, 4096]))
    chunk, at = data[start : start + n], _pos(rng, data)
    return data[:at] + chunk + data[at:], f"duplicate {len(chunk)} bytes from {start} at {at}"


def _integer(rng: np.random.Generator, data: bytes) -> tuple[bytes, str]:
    value = int(rng.choice(_INTERESTING))
    width = int(rng.choice([1, 2, 4, 8]))
    order: Literal["little", "big"] = "little" if rng.random() < 0.7 else "big"
    raw = (value & ((1 << (8 * width)) - 1)).to_bytes(width, order)
    start = _pos(rng, data)
    return data[:start] + raw + data[start + width :], f"int {value} ({width}B {order}) at {start}"


BYTE_OPS: dict[str, _Op] = {
    "flip": _flip,
    "set": _set_bytes,
    "insert": _insert,
    "delete": _delete,
    "truncate": _truncate,
    "duplicate": _duplicate,
    "int": _integer,
}


def _byte_mutation(rng: np.random.Generator, path: Path) -> str:
    name = str(rng.choice(list(BYTE_OPS)))
    data, detail = BYTE_OPS[name](rng, path.read_bytes())
    path.write_bytes(data)
    return f"bytes.{name}:{detail}"


# ----------------------------------------------------------------------------- NIfTI
_NIFTI_FLOATS = (
    0.0,
    -0.0,
    -1.0,
    1e-30,
    1e30,
    3.4e38,
    float("nan"),
    float("inf"),
    float("-inf"),
    0.5,
    2.0,
)
_NIFTI_DATATYPES = (
    0,
    1,
    2,
    4,
    8,
    16,
    32,
    64,
    128,
    256,
    512,
    768,
    1024,
    1280,
    1536,
    1792,
    2048,
    2304,
    999,
    -1,
)
_NIFTI_FIELDS = (
    "dim",
    "dim",
    "dim",
    "pixdim",
    "pixdim",
    "datatype",
    "datatype",
    "bitpix",
    "vox_offset",
    "vox_offset",
    "scl_slope",
    "scl_inter",
    "qform_code",
    "sform_code",
    "quatern_b",
    "quatern_c",
    "quatern_d",
    "qoffset_x",
    "srow_x",
    "srow_y",
    "srow_z",
    "magic",
    "sizeof_hdr",
    "intent_code",
    "xyzt_units",
    "extension",
    "data",
)


def _nifti_value(rng: np.random.Generator, kind: str, itemsize: int, size: int):
    if kind == "f":
        return float(rng.choice(_NIFTI_FLOATS))
    bits = 8 * itemsize
    pool = [
        0,
        1,
        -1,
        2,
        3,
        4,
        5,
        8,
        9,
        100,
        1000,
        32767,
        -32768,
        size,
        size + 1,
        size - 1,
        2**31 - 1,
        -(2**31),
        2**40,
        2**62,
    ]
    lo, hi = -(2 ** (bits - 1)), 2 ** (bits - 1) - 1
    return int(np.clip(int(rng.choice(pool)), lo, hi))


def _nifti_struct(rng: np.random.Generator, data: bytes) -> tuple[bytes, str]:
    """Set one header field (or the extension flag, or voxel values) of a NIfTI file."""
    n2 = data[:4] in (b"\x1c\x02\x00\x00", b"\x00\x00\x02\x1c")
    dtype = nib.nifti2.header_dtype if n2 else nib.nifti1.header_dtype
    size = dtype.itemsize
    if len(data) < size:
        return _flip(rng, data)
    header = np.frombuffer(bytearray(data[:size]), dtype=dtype.newbyteorder("<"))[0]
    buf = bytearray(header.tobytes())
    field = str(rng.choice(_NIFTI_FIELDS))
    rest = data[size:]
    if field == "extension":
        ext = struct.pack("<4B", 1, 0, 0, 0) + struct.pack(
            "<ii", int(rng.choice([0, 8, 16, 7, 2**31 - 1, -16])), int(rng.integers(0, 50))
        )
        return bytes(buf) + ext + rest[4:], "nifti.extension"
    if field == "data":
        offset = int(header["vox_offset"]) if np.isfinite(header["vox_offset"]) else size + 4
        offset = min(max(offset, size), len(data))
        payload = bytearray(data[offset:])
        if payload:
            start = int(rng.integers(0, len(payload)))
            fill = rng.choice(
                [
                    b"\xff\xff\xff\x7f",
                    b"\x00\x00\xc0\x7f",
                    b"\x00\x00\x80\x7f",
                    b"\x00\x00\x00\x3f",
                    b"\x01",
                ]
            )
            payload[start : start + len(fill)] = fill[: len(payload) - start]
        return data[:offset] + bytes(payload), "nifti.data"
    view = np.frombuffer(buf, dtype=dtype.newbyteorder("<"))
    target = view[field]
    if field == "magic":
        view[field] = rng.choice([b"ni1", b"n+1", b"n+2", b"xyz", b""])
        detail = repr(view[field][0])
    elif target.dtype.kind == "S":
        view[field] = rng.bytes(3)
        detail = "random"
    elif target.ndim == 2:  # dim, pixdim, srow_*
        i = int(rng.integers(0, target.shape[1]))
        value = _nifti_value(rng, target.dtype.kind, target.dtype.itemsize, len(data))
        if field == "datatype":
            value = int(rng.choice(_NIFTI_DATATYPES))
        target[0, i] = value
        detail = f"[{i}]={value}"
    else:
        value = _nifti_value(rng, target.dtype.kind, target.dtype.itemsize, len(data))
        if field == "datatype":
            value = int(rng.choice(_NIFTI_DATATYPES))
        target[0] = value
        detail = f"={value}"
    return bytes(buf) + rest, f"nifti.{field}:{field}{detail}"


def _nifti_mutation(rng: np.random.Generator, path: Path, *, gz: bool) -> str:
    if gz and rng.random() < 0.25:
        return "gz." + _byte_mutation(rng, path)  # damage the gzip stream itself
    raw = path.read_bytes()
    data = gzip.decompress(raw) if gz else raw
    if rng.random() < 0.65:
        data, detail = _nifti_struct(rng, data)
    else:
        name = str(rng.choice(list(BYTE_OPS)))
        data, detail = BYTE_OPS[name](rng, data)
        detail = f"bytes.{name}:{detail}"
    path.write_bytes(gzip.compress(data, mtime=0) if gz else data)
    return detail


# ----------------------------------------------------------------------------- DICOM
@contextlib.contextmanager
def _lenient_pydicom() -> Iterator[None]:
    """pydicom without value validation; the previous settings are restored after."""
    settings = pydicom.config.settings
    saved = settings.reading_validation_mode, settings.writing_validation_mode
    settings.reading_validation_mode = pydicom.config.IGNORE
    settings.writing_validation_mode = pydicom.config.IGNORE
    try:
        yield
    finally:
        settings.reading_validation_mode, settings.writing_validation_mode = saved


_DICOM_KEYWORDS = {
    "dicom-series": (
        "Rows",
        "Columns",
        "PixelSpacing",
        "ImagePositionPatient",
        "ImageOrientationPatient",
        "SliceThickness",
        "BitsAllocated",
        "BitsStored",
        "HighBit",
        "PixelRepresentation",
        "SamplesPerPixel",
        "PhotometricInterpretation",
        "RescaleSlope",
        "RescaleIntercept",
        "SeriesInstanceUID",
        "Modality",
        "SOPClassUID",
        "PixelData",
        "SliceLocation",
        "InstanceNumber",
        "SOPInstanceUID",
    ),
    "dicom-seg": (
        "NumberOfFrames",
        "Rows",
        "Columns",
        "BitsAllocated",
        "BitsStored",
        "SegmentationType",
        "MaximumFractionalValue",
        "SegmentSequence",
        "SegmentNumber",
        "SegmentLabel",
        "PerFrameFunctionalGroupsSequence",
        "ReferencedSegmentNumber",
        "ImagePositionPatient",
        "ImageOrientationPatient",
        "PixelSpacing",
        "SliceThickness",
        "SpacingBetweenSlices",
        "PixelData",
        "SharedFunctionalGroupsSequence",
        "PlanePositionSequence",
        "PlaneOrientationSequence",
        "PixelMeasuresSequence",
        "SegmentIdentificationSequence",
        "SOPClassUID",
    ),
    "rtstruct": (
        "ContourData",
        "ContourData",
        "ContourData",
        "NumberOfContourPoints",
        "ContourGeometricType",
        "ROINumber",
        "ReferencedROINumber",
        "ROIName",
        "StructureSetROISequence",
        "ROIContourSequence",
        "ContourSequence",
        "ReferencedSOPInstanceUID",
        "ContourImageSequence",
        "Modality",
        "SOPClassUID",
    ),
}
_DICOM_ADD = {  # elements a mutation may add where the seed has none
    "dicom-series": (
        "NumberOfFrames",
        "SpacingBetweenSlices",
        "RescaleSlope",
        "ModalityLUTSequence",
        "PixelPaddingValue",
        "WindowCenter",
    ),
    "dicom-seg": (
        "SpacingBetweenSlices",
        "MaximumFractionalValue",
        "PixelSpacing",
        "ImagePositionPatient",
    ),
    "rtstruct": ("ContourData", "NumberOfFrames"),
}
_VALUES: dict[str, tuple[bytes, ...]] = {
    "DS": (
        b"0",
        b"-1",
        b"nan",
        b"inf",
        b"-inf",
        b"1e308",
        b"-1e308",
        b"1e999",
        b"abc",
        b"",
        b"1e-320",
        b"1,5",
        b"0\\0",
        b"1\\2\\3\\4\\5\\6\\7",
        b"-0",
        b"99999999999999",
    ),
    "IS": (
        b"0",
        b"-1",
        b"2147483647",
        b"-2147483648",
        b"99999999999",
        b"abc",
        b"",
        b"1.5",
        b"1\\2",
        b"65536",
    ),
    "US": tuple(struct.pack("<H", v) for v in (0, 1, 2, 3, 7, 8, 12, 16, 32, 32767, 32768, 65535))
    + (b"", b"\x01", b"\x01\x00\x02"),
    "SS": tuple(struct.pack("<h", v) for v in (0, -1, -32768, 32767)),
    "UL": tuple(struct.pack("<I", v) for v in (0, 1, 2**31 - 1, 2**32 - 1)),
    "SL": tuple(struct.pack("<i", v) for v in (0, -1, -(2**31))),
    "FL": tuple(struct.pack("<f", v) for v in (0.0, float("nan"), float("inf"), 3.4e38)),
    "FD": tuple(struct.pack("<d", v) for v in (0.0, float("nan"), float("inf"), 1e308)),
    "UI": (
        b"",
        b"1.2.3\x00",
        b"1.2.840.10008.5.1.4.1.1.66.4\x00",
        b"1.2.840.10008.5.1.4.1.1.481.3\x00",
        b"1.2.840.10008.5.1.4.1.1.2\x00",
        b"\xff\xfe",
    ),
    "CS": (
        b"",
        b"LABELMAP",
        b"FRACTIONAL",
        b"BINARY",
        b"CLOSED_PLANAR",
        b"POINT",
        b"OPEN_PLANAR",
        b"RTSTRUCT",
        b"SEG",
        b"CT",
        b"MONOCHROME1",
        b"RGB",
        b"PALETTE COLOR",
        b"YBR_FULL",
        b"\\\\\\",
        b"X" * 300,
    ),
    "text": (b"", b"X" * 300, b"\x00\xff\xfe", b"Ball\\Core", b"\x1b$B", b"1"),
}
_VRS = (
    "AE",
    "AS",
    "AT",
    "CS",
    "DA",
    "DS",
    "DT",
    "FL",
    "FD",
    "IS",
    "LO",
    "LT",
    "OB",
    "OD",
    "OF",
    "OL",
    "OW",
    "PN",
    "SH",
    "SL",
    "SQ",
    "SS",
    "ST",
    "SV",
    "TM",
    "UC",
    "UI",
    "UL",
    "UN",
    "UR",
    "US",
    "UT",
    "UV",
    "XX",
    "\x00\x00",
    "ob",
)
_TRANSFER_SYNTAXES = (
    "1.2.840.10008.1.2",
    "1.2.840.10008.1.2.2",
    "1.2.840.10008.1.2.1.99",
    "1.2.840.10008.1.2.4.50",
    "1.2.840.10008.1.2.5",
    "1.2.840.10008.1.2.4.90",
    "1.2.3",
    "",
)


def _walk(ds: Dataset, parent: str = "") -> Iterator[tuple[Dataset, DataElement, str]]:
    """(owning dataset, element, dotted keyword path) of every element, depth first."""
    for elem in list(ds):
        name = f"{parent}{elem.keyword or elem.tag}"
        yield ds, elem, name
        if elem.VR == "SQ":
            for i, item in enumerate(elem.value):
                yield from _walk(item, f"{name}[{i}].")


def _raw(elem_tag: int, vr: str, value: bytes) -> RawDataElement:
    if len(value) % 2:
        value += b"\x00" if vr in ("UI", "OB", "UN") or vr not in _VALUES else b" "
    return RawDataElement(pydicom.tag.Tag(elem_tag), vr, len(value), value, 0, False, True)


def _pool(vr: str) -> tuple[bytes, ...]:
    if vr in _VALUES:
        return _VALUES[vr]
    if vr in ("OB", "OW", "UN", "OF", "OD", "OL"):
        return ()
    return _VALUES["text"]


def _dicom_value(rng: np.random.Generator, ds: Dataset, elem, name: str) -> str:
    vr = str(elem.VR)
    if vr == "SQ":
        items = list(elem.value)
        op = str(rng.choice(["empty", "drop", "duplicate", "blank-item", "reverse"]))
        if op == "empty" or not items:
            elem.value = DicomSequence([])
        elif op == "drop":
            items.pop(int(rng.integers(0, len(items))))
            elem.value = DicomSequence(items)
        elif op == "duplicate":
            items.append(items[int(rng.integers(0, len(items)))])
            elem.value = DicomSequence(items)
        elif op == "blank-item":
            items.insert(int(rng.integers(0, len(items) + 1)), Dataset())
            elem.value = DicomSequence(items)
        else:
            elem.value = DicomSequence(items[::-1])
        return f"dicom.sq:{name} {op}"
    pool = _pool(vr)
    if not pool:  # OB / OW: pixel data and the like
        value = elem.value if isinstance(elem.value, bytes) else b""
        op = str(rng.choice(["truncate", "double", "empty", "random", "ones"]))
        new = {
            "truncate": value[: len(value) // 2],
            "double": value * 2,
            "empty": b"",
            "random": rng.bytes(len(value)),
            "ones": b"\xff" * len(value),
        }[op]
        ds[elem.tag] = _raw(elem.tag, vr, new)
        return f"dicom.bytes:{name} {op}"
    if vr in ("DS", "IS") and elem.VM > 1 and rng.random() < 0.6:
        parts = [str(v) for v in elem.value]
        i = int(rng.integers(0, len(parts)))
        op = str(rng.choice(["one", "drop", "extra"]))
        if op == "one":
            parts[i] = rng.choice(pool).decode("latin-1")
        elif op == "drop":
            parts.pop(i)
        else:
            parts.append(parts[i])
        value = "\\".join(parts).encode("latin-1")
        ds[elem.tag] = _raw(elem.tag, vr, value)
        return f"dicom.value:{name}={value[:60]!r}"
    value = pool[int(rng.integers(0, len(pool)))]
    ds[elem.tag] = _raw(elem.tag, vr, value)
    return f"dicom.value:{name}={value[:60]!r}"


def _dicom_struct(rng: np.random.Generator, path: Path, fmt: str) -> str:
    """Change, delete or add one element of a DICOM file (pydicom, no validation)."""
    with _lenient_pydicom():
        ds = pydicom.dcmread(path, force=True)
        elements = list(_walk(ds))
        keywords = _DICOM_KEYWORDS[fmt]
        liked = [e for e in elements if getattr(e[1], "keyword", "") in keywords]
        pick = liked if liked and rng.random() < 0.75 else elements
        owner, elem, name = pick[int(rng.integers(0, len(pick)))]
        op = rng.random()
        if op < 0.15:
            del owner[elem.tag]
            detail = f"dicom.delete:{name}"
        elif op < 0.22:
            keyword = str(rng.choice(_DICOM_ADD[fmt]))
            tag = pydicom.datadict.tag_for_keyword(keyword)
            assert tag is not None
            vr = pydicom.datadict.dictionary_VR(tag).split(" or ")[0]
            pool = _pool(vr) or (b"\x00" * 4,)
            target = owner if rng.random() < 0.5 else ds
            if vr == "SQ":
                target[tag] = DataElement(tag, "SQ", DicomSequence([Dataset()]))
            else:
                target[tag] = _raw(tag, vr, pool[int(rng.integers(0, len(pool)))])
            detail = f"dicom.add:{keyword}"
        else:
            detail = _dicom_value(rng, owner, elem, name)
        try:
            ds.save_as(path, enforce_file_format=False)
        except Exception as exc:  # noqa: BLE001 - an unwritable mutation: damage bytes instead
            return f"{_byte_mutation(rng, path)} (after unwritable {detail}: {type(exc).__name__})"
    return detail


def _element_offsets(data: bytes) -> list[int]:
    """Offsets of what look like explicit-VR element headers (tag, then a known VR)."""
    vrs = b"|".join(v.encode() for v in _VRS[:-3])
    offsets = []
    for match in re.finditer(rb"(?=(.{4})(?:" + vrs + rb"))", data, flags=re.DOTALL):
        group = struct.unpack("<H", match.group(1)[:2])[0]
        if match.start() >= 132 and group % 2 == 0 and 0x0002 <= group <= 0x7FE0:
            offsets.append(match.start())
    return offsets


def _dicom_vr(rng: np.random.Generator, path: Path) -> str:
    """Replace the VR (or the length) of one explicit-VR element in the file's bytes."""
    data = bytearray(path.read_bytes())
    offsets = _element_offsets(bytes(data))
    if not offsets:
        return _byte_mutation(rng, path)
    at = offsets[int(rng.integers(0, len(offsets)))]
    group, element = struct.unpack_from("<HH", data, at)
    old = data[at + 4 : at + 6].decode("latin-1")
    if rng.random() < 0.6:
        new = str(rng.choice(_VRS))
        data[at + 4 : at + 6] = new.encode("latin-1")[:2].ljust(2, b"\x00")
        detail = f"dicom.vr:({group:04X},{element:04X}) {old}->{new!r}"
    else:
        long = old in ("OB", "OD", "OF", "OL", "OW", "SQ", "UC", "UN", "UR", "UT", "SV", "UV")
        pool = (0, 1, 0xFFFF, 0xFFFFFFFF, 0x7FFFFFFF, 1000, 3) if long else (0, 1, 3, 0xFFFF, 999)
        value = int(rng.choice(pool))
        if long:
            struct.pack_into("<I", data, at + 8, value & 0xFFFFFFFF)
        else:
            struct.pack_into("<H", data, at + 6, value & 0xFFFF)
        detail = f"dicom.length:({group:04X},{element:04X}) {old} length={value}"
    path.write_bytes(bytes(data))
    return detail


def _dicom_syntax(rng: np.random.Generator, path: Path) -> str:
    """Declare another transfer syntax in the file meta (the data stays as it is)."""
    data = path.read_bytes()
    at = data.find(b"\x02\x00\x10\x00UI")
    if at < 0:
        return _byte_mutation(rng, path)
    (length,) = struct.unpack_from("<H", data, at + 6)
    uid = str(rng.choice(_TRANSFER_SYNTAXES)).encode()
    if len(uid) % 2:
        uid += b"\x00"
    new = data[: at + 6] + struct.pack("<H", len(uid)) + uid + data[at + 8 + length :]
    path.write_bytes(new)
    return f"dicom.syntax:{uid.rstrip(bytes(1)).decode()}"


def _dicom_file_mutation(rng: np.random.Generator, path: Path, fmt: str) -> str:
    r = rng.random()
    if r < 0.55:
        return _dicom_struct(rng, path, fmt)
    if r < 0.7:
        return _dicom_vr(rng, path)
    if r < 0.75:
        return _dicom_syntax(rng, path)
    return _byte_mutation(rng, path)


def _files(directory: Path) -> list[Path]:
    return sorted(p for p in directory.iterdir() if p.is_file())


def _series_mutation(rng: np.random.Generator, directory: Path, target: str | None) -> str:
    """Mutate one file of a series directory, or the set of files itself."""
    files = _files(directory)
    images = [f for f in files if f.name != target]
    r = rng.random()
    if r < 0.12 and images:
        victim = images[int(rng.integers(0, len(images)))]
        if target is not None and rng.random() < 0.3:
            for f in images:
                f.unlink()
            return "series.drop-all-images"
        victim.unlink()
        return f"series.drop:{victim.name}"
    if r < 0.2 and files:
        source = files[int(rng.integers(0, len(files)))]
        shutil.copyfile(source, directory / f"copy_{source.name}")
        return f"series.duplicate:{source.name}"
    if r < 0.25:
        name = str(rng.choice(["junk.dcm", "notes.txt", "DICOMDIR", "empty.dcm", "x"]))
        (directory / name).write_bytes(b"" if name == "empty.dcm" else rng.bytes(200))
        return f"series.add:{name}"
    if target is not None and rng.random() < 0.65:
        chosen = directory / target
        fmt = "rtstruct"
    else:
        pool = images or files
        chosen = pool[int(rng.integers(0, len(pool)))]
        fmt = "dicom-series"
    return _dicom_file_mutation(rng, chosen, fmt)


# ----------------------------------------------------------------------------- JSON
_JSON_TOKENS = (
    "NaN",
    "Infinity",
    "-Infinity",
    "1e308",
    "-1e308",
    "1.7976931348623157e308",
    "1e309",
    "5e-324",
    "-0.0",
    "1e-300",
    "0",
    "-1",
    "1e6",
    "1e12",
    "100000000000000000000",
    "1" + "0" * 400,
    "9" * 5000,
    "-" + "9" * 400,
    "1.5",
    "true",
    "false",
    "null",
    '""',
    '"1.0"',
    '"mm"',
    "[]",
    "{}",
    "[[]]",
    "[0, 0]",
    "[1, 2, 3, 4]",
    '{"a": 1}',
    '"slicerecon-contours"',
    "2",
    "1.0",
)
_PLACEHOLDER = "\u2603FUZZ\u2603"


def _json_nodes(node, path=()) -> Iterator[tuple]:
    yield path
    if isinstance(node, dict):
        for key, value in node.items():
            yield from _json_nodes(value, (*path, key))
    elif isinstance(node, list):
        for i, value in enumerate(node):
            yield from _json_nodes(value, (*path, i))


def _get(node, path):
    for key in path:
        node = node[key]
    return node


def _json_struct(rng: np.random.Generator, text: str) -> tuple[str, str]:
    try:
        doc = json.loads(text)
    except (ValueError, RecursionError):
        return text, "json.unparseable"
    nodes = list(_json_nodes(doc))
    path = nodes[int(rng.integers(0, len(nodes)))]
    where = "".join(f"[{k!r}]" for k in path) or "<root>"
    op = str(
        rng.choice(
            [
                "token",
                "token",
                "token",
                "nest",
                "delete",
                "duplicate",
                "shift",
                "scale",
                "flatten",
                "unknown-key",
            ]
        )
    )
    token = None
    if op == "nest" or (op == "token" and not path):
        depth = int(rng.choice([50, 999, 5000, 100_000]))
        opener = "[" if rng.random() < 0.7 else '{"a":'
        closer = "]" if opener == "[" else "}"
        token = opener * depth + "0" + closer * depth
        op = f"nest depth {depth}"
    elif op == "token":
        token = str(rng.choice(_JSON_TOKENS))
        op = f"token {token[:24]}{'...' if len(token) > 24 else ''}"
    elif op == "delete" and path:
        parent = _get(doc, path[:-1])
        del parent[path[-1]]
    elif op == "duplicate" and path and isinstance(_get(doc, path[:-1]), list):
        parent = _get(doc, path[:-1])
        parent.insert(path[-1], json.loads(json.dumps(parent[path[-1]])))
    elif op in ("shift", "scale"):
        amount = float(rng.choice([1e6, 1e12, 1e300, -1e300, 1e-9, 0.0]))
        target = _get(doc, path)

        def change(node):
            if isinstance(node, list):
                if len(node) == 3 and all(isinstance(v, float | int) for v in node):
                    node[2] = node[2] + amount if op == "shift" else node[2] * amount
                else:
                    for v in node:
                        change(v)
            elif isinstance(node, dict):
                for v in node.values():
                    change(v)

        change(target)
        op = f"{op} {amount:g}"
    elif op == "flatten" and isinstance(_get(doc, path), list):
        target = _get(doc, path)
        target[:] = [[0.0, 0.0, 0.0]] * max(len(target), 3)
    elif op == "unknown-key" and isinstance(_get(doc, path), dict):
        _get(doc, path)["extra"] = 1
    else:
        token = str(rng.choice(_JSON_TOKENS))
        op = f"token {token[:24]}"
    if token is not None:
        if path:
            _get(doc, path[:-1])[path[-1]] = _PLACEHOLDER
            text = json.dumps(doc).replace(json.dumps(_PLACEHOLDER), token)
        else:
            text = token
    else:
        text = json.dumps(doc, allow_nan=True)
    return text, f"json.{op.split()[0]}:{where} {op}"


def _json_mutation(rng: np.random.Generator, path: Path) -> str:
    if rng.random() < 0.7:
        text, detail = _json_struct(rng, path.read_text(encoding="utf-8"))
        path.write_text(text, encoding="utf-8")
        return detail
    return _byte_mutation(rng, path)


# ----------------------------------------------------------------------------- CSV
_CSV_CELLS = (
    "",
    "abc",
    "nan",
    "inf",
    "-inf",
    "1e308",
    "-1e308",
    "1e309",
    "1e6",
    "1e12",
    "-1e12",
    "1e-300",
    "0x10",
    "1_000",
    "\u0661\u0662",
    " 1 ",
    "9" * 400,
    "-0",
    "+5",
    "1.5",
    "2.5e2",
    "99999999999999999999",
    "-1",
    '"1"',
    "1;2",
    "\x00",
    "\u00e9",
)


def _csv_mutation(rng: np.random.Generator, path: Path) -> str:
    if rng.random() < 0.25:
        return _byte_mutation(rng, path)
    lines = path.read_text(encoding="utf-8").splitlines()
    if not lines:
        return _byte_mutation(rng, path)
    i = int(rng.integers(1, len(lines))) if len(lines) > 1 else 0
    op = str(
        rng.choice(
            [
                "cell",
                "cell",
                "cell",
                "far-plane",
                "drop-column",
                "add-column",
                "drop-line",
                "duplicate-line",
                "swap-lines",
                "header",
                "long-line",
                "blank-comment",
                "bom-crlf",
                "single-point",
            ]
        )
    )
    detail = op
    if op == "cell":
        cells = lines[i].split(",")
        j = int(rng.integers(0, len(cells)))
        value = str(rng.choice(_CSV_CELLS))
        cells[j] = value
        lines[i] = ",".join(cells)
        detail = f"line {i + 1} cell {j} = {value[:24]!r}"
    elif op == "far-plane":
        plane = lines[i].split(",")[0]
        amount = float(rng.choice([1e5, 1e6, 1e9, 1e15, -1e6, 1e300]))
        for k, line in enumerate(lines[1:], start=1):
            cells = line.split(",")
            if cells[0] == plane and len(cells) == 5:
                with contextlib.suppress(ValueError):
                    cells[4] = repr(float(cells[4]) + amount)
                lines[k] = ",".join(cells)
        detail = f"plane {plane} z += {amount:g}"
    elif op == "drop-column":
        j = int(rng.integers(0, 5))
        lines = [",".join(c for k, c in enumerate(line.split(",")) if k != j) for line in lines]
        detail = f"column {j}"
    elif op == "add-column":
        lines = [line + ",1" for line in lines]
    elif op == "drop-line":
        del lines[i]
        detail = f"line {i + 1}"
    elif op == "duplicate-line":
        lines.insert(i, lines[i])
        detail = f"line {i + 1}"
    elif op == "swap-lines":
        j = int(rng.integers(1, len(lines))) if len(lines) > 1 else 0
        lines[i], lines[j] = lines[j], lines[i]
        detail = f"lines {i + 1}, {j + 1}"
    elif op == "header":
        lines[0] = str(
            rng.choice(
                [
                    "x,y,z,plane,polygon",
                    "plane,polygon,x,y",
                    "PLANE,Polygon,X,Y,Z",
                    "plane,plane,x,y,z",
                    "",
                    "plane;polygon;x;y;z",
                ]
            )
        )
        detail = repr(lines[0])
    elif op == "long-line":
        lines.insert(i, ",".join(["1"] * int(rng.choice([6, 1000, 100_000]))))
    elif op == "blank-comment":
        lines.insert(i, str(rng.choice(["", "# comment", "   ", "#"])))
    elif op == "bom-crlf":
        path.write_text("\ufeff" + "\r\n".join(lines), encoding="utf-8")
        return "csv.bom-crlf"
    elif op == "single-point":
        plane, polygon = lines[i].split(",")[:2] if lines[i].count(",") >= 1 else ("0", "0")
        lines = [
            line
            for k, line in enumerate(lines)
            if k == 0 or k == i or line.split(",")[:2] != [plane, polygon]
        ]
        detail = f"plane {plane} polygon {polygon} keeps one point"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return f"csv.{op}:{detail}"


# ----------------------------------------------------------------------------- VTI
_VTI_NUMBERS = (
    "abc",
    "nan",
    "inf",
    "-inf",
    "1e300",
    "-1e300",
    "1e-300",
    "0",
    "-5",
    "99999999999",
    "1.5",
    "2147483647",
    "",
    "1e999",
    "0x10",
    "1,5",
)
_VTI_ATTRS: dict[str, tuple[str, ...]] = {
    "WholeExtent": (
        "0 100000 0 100000 0 100000",
        "0 -5 0 3 0 3",
        "5 0 0 3 0 3",
        "0 0 0 0 0 0",
        "0 1e9 0 1 0 1",
        "0 2000 0 2000 0 2000",
    ),
    "Extent": (
        "0 100000 0 100000 0 100000",
        "0 -5 0 3 0 3",
        "0 8 0 7 0 6 0 1",
        "0 1290 0 1290 0 1290",
        "0 0 0 0 0 0",
        "-2147483648 2147483647 0 1 0 1",
    ),
    "Origin": ("1e308 0 0", "-1.7e308 1.7e308 0", "nan 0 0", "0 0"),
    "Spacing": ("1e300 1 1", "0 0 0", "-1 1 1", "1e-300 1 1", "nan 1 1", "1 1", "1e-9 1e-9 1e-9"),
    "Direction": (
        "0 0 0 0 0 0 0 0 0",
        "1 0 0 1 0 0 0 0 1",
        "1e300 0 0 0 1 0 0 0 1",
        "1 0 0 0 1 0 0 0",
    ),
    "type": ("Float16", "Int128", "Bit", "String", "", "Float64", "Int64", "UInt16", "Float32"),
    "NumberOfComponents": ("0", "3", "abc", "-1", "99999999999"),
    "format": ("ascii", "binary", "appended", "raw", ""),
    "offset": ("abc", "-1", "99999999", "1e3", "", "3"),
    "header_type": ("UInt16", "Int32", "UInt64", "UInt32", ""),
    "compressor": ("vtkLZ4DataCompressor", "vtkZLibDataCompressor", "vtkLZMADataCompressor", ""),
    "byte_order": ("BigEndian", "LittleEndian", "Middle"),
    "encoding": ("base64", "raw", "hex"),
    "Scalars": ("missing", ""),
    "Name": ("", "other"),
    "type_root": ("PolyData", "UnstructuredGrid", ""),
}


def _vti_attribute(rng: np.random.Generator, data: bytes) -> tuple[bytes, str]:
    head_end = data.find(b"<AppendedData")
    head = data if head_end < 0 else data[:head_end]
    names = [
        m
        for m in re.finditer(rb'\b([A-Za-z_]+)="([^"]*)"', head)
        if m.group(1).decode() in _VTI_ATTRS or m.group(1) == b"type"
    ]
    if not names:
        return _flip(rng, data)
    m = names[int(rng.integers(0, len(names)))]
    attr = m.group(1).decode()
    key = "type_root" if attr == "type" and m.group(2) == b"ImageData" else attr
    if rng.random() < 0.12:  # drop the attribute
        new, detail = b"", f"drop {attr}"
    else:
        old = m.group(2).decode()
        numbers = old.split()
        if (
            key in ("WholeExtent", "Extent", "Origin", "Spacing", "Direction")
            and numbers
            and rng.random() < 0.5
        ):
            k = int(rng.integers(0, len(numbers)))
            numbers[k] = str(rng.choice(_VTI_NUMBERS))
            value = " ".join(numbers)
        else:
            value = str(rng.choice(_VTI_ATTRS[key]))
        new, detail = f'{attr}="{value}"'.encode(), f'{attr}="{value[:40]}"'
    return data[: m.start()] + new + data[m.end() :], f"vti.attr:{detail}"


def _vti_payload_mutation(rng: np.random.Generator, data: bytes) -> tuple[bytes, str]:
    """Damage the array payload: its text, base64, binary header or compressed blocks."""
    inline = re.search(rb'format="(ascii|binary)"[^>]*>([^<]*)</DataArray>', data)
    if inline is not None and inline.group(1) == b"ascii":
        words = inline.group(2).split()
        if not words:
            return _flip(rng, data)
        k = int(rng.integers(0, len(words)))
        token = str(
            rng.choice(
                ["abc", "nan", "1e400", "-1", "300", "99999999999999999999", "1.5", "inf", "0x1"]
            )
        )
        words[k] = token.encode()
        op = rng.random()
        if op < 0.2:
            words = words[: len(words) // 2]
            token = "half the values"
        body = b" ".join(words)
        return data[: inline.start(2)] + body + data[inline.end(2) :], f"vti.ascii:{token}"
    if inline is not None:
        text = inline.group(2).strip()
        if rng.random() < 0.35:
            k = int(rng.integers(0, max(len(text), 1)))
            junk = rng.choice([b"!", b"=", b"==", b"A", b"", b"\xff", b"===="])
            body = text[:k] + junk + text[k + (1 if junk == b"" else 0) :]
            return data[: inline.start(2)] + body + data[inline.end(2) :], "vti.base64:corrupt"
        try:
            payload = base64.b64decode(text)
        except ValueError:
            return _flip(rng, data)
        payload, detail = _vti_binary_header(rng, payload, data)
        body = base64.b64encode(payload)
        return data[: inline.start(2)] + body + data[inline.end(2) :], detail
    marker = data.find(b"_", data.find(b"<AppendedData"))
    end = data.rfind(b"</AppendedData>")
    if marker < 0 or end < marker:
        return _flip(rng, data)
    payload = data[marker + 1 : end].rstrip()
    is_b64 = b'encoding="base64"' in data
    if is_b64:
        try:
            payload = base64.b64decode(payload)
        except ValueError:
            return _flip(rng, data)
    payload, detail = _vti_binary_header(rng, payload, data)
    if is_b64:
        payload = base64.b64encode(payload)
    return data[: marker + 1] + payload + b"\n" + data[end:], detail


def _vti_binary_header(rng: np.random.Generator, payload: bytes, data: bytes) -> tuple[bytes, str]:
    width = 8 if b'header_type="UInt64"' in data else 4
    order = ">" if b'byte_order="BigEndian"' in data else "<"
    code = order + ("u8" if width == 8 else "u4")
    n_ints = max(1, min(len(payload) // width, 4))
    k = int(rng.integers(0, n_ints))
    if rng.random() < 0.3 and len(payload) > n_ints * width:  # damage the blocks instead
        start = int(rng.integers(n_ints * width, len(payload)))
        buf = bytearray(payload)
        buf[start] ^= 0xFF
        return bytes(buf), "vti.block:flip a data byte"
    value = int(rng.choice([0, 1, 2, 3, 1000, 2**31 - 1, 2**32 - 1, 2**40, 2**63 - 1]))
    if width == 4:
        value &= 0xFFFFFFFF
    buf = bytearray(payload.ljust(n_ints * width, b"\x00"))
    buf[k * width : (k + 1) * width] = np.array([value], dtype=code).tobytes()
    return bytes(buf), f"vti.header:int {k} = {value}"


def _vti_mutation(rng: np.random.Generator, path: Path) -> str:
    data = path.read_bytes()
    r = rng.random()
    if r < 0.5:
        data, detail = _vti_attribute(rng, data)
    elif r < 0.75:
        data, detail = _vti_payload_mutation(rng, data)
    else:
        name = str(rng.choice(list(BYTE_OPS)))
        data, detail = BYTE_OPS[name](rng, data)
        detail = f"bytes.{name}:{detail}"
    path.write_bytes(data)
    return detail


# ----------------------------------------------------------------------------- NRRD
_NRRD_VALUES: dict[str, tuple[str, ...]] = {
    "type": ("uchar", "short", "ushort", "int", "uint", "int64", "float", "double", "block", "?"),
    "dimension": ("0", "1", "2", "3", "4", "5", "-3", "99999999999"),
    "encoding": ("raw", "gzip", "gz", "bzip2", "bz2", "ascii", "hex", "txt", "zip", ""),
    "endian": ("little", "big", "middle", ""),
    "sizes": ("1 1 1", "0 4 4", "-4 4 4", "4 4", "4 4 4 4", "65536 65536 65536", "1 1 99999999999"),
    "space": (
        "left-posterior-superior",
        "right-anterior-superior",
        "left-anterior-superior",
        "scanner-xyz",
        "3D-right-handed",
        "right-anterior-superior-time",
        "nowhere",
    ),
    "space directions": (
        "(1,0,0) (0,1,0)",
        "(1,0,0) (0,1,0) (0,0,1) (1,1,1)",
        "none (1,0,0) (0,1,0)",
        "(0,0,0) (0,1,0) (0,0,1)",
        "(nan,0,0) (0,1,0) (0,0,1)",
        "(1e300,0,0) (0,1,0) (0,0,1)",
        "(1,0) (0,1) (0,0)",
        "(1,0,0) (1,0,0) (0,0,1)",
        "none none none",
    ),
    "space origin": ("(0,0,0)", "(nan,0,0)", "(1e308,0,0)", "(0,0)", "none"),
    "kinds": ("domain domain domain", "list domain domain domain", "space space", "???"),
    "space units": ('"mm" "mm" "mm"', '"cm" "cm" "cm"', '"furlong" "mm" "mm"', '"mm"'),
    "spacings": ("1 1 1", "0 1 1", "nan 1 1", "1e300 1 1", "1 1"),
    "line skip": ("0", "1", "3", "-1", "1000000000", "1" * 31),
    "byte skip": ("0", "-1", "5", "-2", "1000000000", "9" * 25),
}
"""Interesting values per NRRD field (any field may also get one of :data:`_NRRD_ANY`)."""
_NRRD_ANY = ("", "0", "-1", "nan", "1e308", "1" * 31, "abc", "Tête", "\\", "(1,2,3)")
_SEGMENT_FIELDS: dict[str, tuple[str, ...]] = {
    "LabelValue": ("0", "1", "2", "5", "255", "256", "-1", "99999999999", "one", ""),
    "Layer": ("0", "1", "2", "-1", "7", ""),
    "Extent": ("0 -1 0 -1 0 -1", "0 0 0 0 0 0", "1 3 1 3 1 3", "0 1", "-5 99 -5 99 -5 99", ""),
    "Name": ("", "Tête fémorale", "a\\nb", "x" * 300, "\\\\"),
    "Color": ("1 0 0", "nan 0 0", "2 -1 0", "", "1 0"),
    "ID": ("", "Segment_1", "dup"),
}


def _nrrd_parts(data: bytes) -> tuple[list[str], bytes]:
    head, sep, body = data.partition(b"\n\n")
    return head.decode("utf-8", "replace").split("\n"), body if sep else b""


def _nrrd_header_mutation(rng: np.random.Generator, lines: list[str]) -> tuple[list[str], str]:
    fields = [
        i for i, line in enumerate(lines) if i > 0 and not line.startswith("#") and ":" in line
    ]
    r = rng.random()
    if r < 0.12 and fields:
        i = int(rng.choice(fields))
        return lines[:i] + lines[i + 1 :], f"delete {lines[i].split(':')[0]!r}"
    if r < 0.2 and fields:
        i = int(rng.choice(fields))
        return lines[: i + 1] + lines[i:], f"duplicate {lines[i].split(':')[0]!r}"
    if r < 0.35:
        key = str(rng.choice(["line skip", "byte skip", "space units", "data file", "endian"]))
        values = _NRRD_VALUES.get(key, ("x.raw", "/etc/hostname"))
        line = f"{key}: {rng.choice(values)}"
        at = int(rng.integers(1, len(lines) + 1))
        return lines[:at] + [line] + lines[at:], f"add {line!r}"
    if r < 0.45:
        n, field = int(rng.integers(0, 5)), str(rng.choice(list(_SEGMENT_FIELDS)))
        line = f"Segment{n}_{field}:={rng.choice(_SEGMENT_FIELDS[field])}"
        return lines + [line], f"add {line!r}"
    if not fields:
        return lines, "no field"
    i = int(rng.choice(fields))
    key, sep, _ = lines[i].partition(":=" if ":=" in lines[i] else ":")
    segment = re.match(r"Segment\d+_(\w+)$", key)
    if segment and segment.group(1) in _SEGMENT_FIELDS and rng.random() < 0.8:
        value = str(rng.choice(_SEGMENT_FIELDS[segment.group(1)]))
    elif key in _NRRD_VALUES and rng.random() < 0.8:
        value = str(rng.choice(_NRRD_VALUES[key]))
    else:
        value = str(rng.choice(_NRRD_ANY))
    sep = sep + ("" if sep == ":=" else " ")
    lines = [*lines[:i], f"{key}{sep}{value}", *lines[i + 1 :]]
    return lines, f"{key} = {value!r}"[:120]


def _nrrd_mutation(rng: np.random.Generator, path: Path) -> str:
    data = path.read_bytes()
    lines, body = _nrrd_parts(data)
    r = rng.random()
    if r < 0.6:
        lines, detail = _nrrd_header_mutation(rng, lines)
        detail = f"nrrd.header:{detail}"
    elif r < 0.85 and body:
        name = str(rng.choice(list(BYTE_OPS)))
        body, detail = BYTE_OPS[name](rng, body)
        detail = f"nrrd.data.{name}:{detail}"
    else:
        name = str(rng.choice(list(BYTE_OPS)))
        data, detail = BYTE_OPS[name](rng, data)
        path.write_bytes(data)
        return f"bytes.{name}:{detail}"
    path.write_bytes(("\n".join(lines) + "\n\n").encode("utf-8") + body)
    return detail


# ----------------------------------------------------------------------------- mutants
def _mutate(rng: np.random.Generator, seed: Seed, path: Path) -> str:
    fmt = seed.format
    if fmt in ("nifti", "nifti-gz"):
        return _nifti_mutation(rng, path, gz=fmt == "nifti-gz")
    if fmt in ("dicom-series", "rtstruct-series"):
        return _series_mutation(rng, path, seed.target)
    if fmt == "dicom-seg":
        return _dicom_file_mutation(rng, path, "dicom-seg")
    if fmt == "rtstruct":
        return _dicom_file_mutation(rng, path, "rtstruct")
    if fmt == "json":
        return _json_mutation(rng, path)
    if fmt == "csv":
        return _csv_mutation(rng, path)
    if fmt in ("nrrd", "seg-nrrd"):
        return _nrrd_mutation(rng, path)
    return _vti_mutation(rng, path)


def make_mutant(
    seeds: list[Seed],
    index: int,
    *,
    seed: int,
    directory: str | Path,
    edge_fraction: float = EDGE_FRACTION,
    default_method_fraction: float = DEFAULT_METHOD_FRACTION,
) -> Mutant:
    """Build mutant ``index`` of the run ``seed`` from a copy of one seed.

    Parameters
    ----------
    seeds : list of Seed
        From ``fuzz_seeds.write_seeds``.
    index : int
        Mutant number; the format is ``FORMATS[index % len(FORMATS)]``.
    seed : int
        Run seed; mutant ``(seed, index)`` is always the same.
    directory : path-like
        Where the mutant is written (as ``<index>-<format>/<name>``).
    edge_fraction : float
        Share of mutants that start from ``write_edge_case``.
    default_method_fraction : float
        Share of mutants reconstructed with the default method.

    Returns
    -------
    Mutant
    """
    rng = np.random.default_rng([seed, index])
    fmt = FORMATS[index % len(FORMATS)]
    candidates = [s for s in seeds if s.format == fmt]
    origin = candidates[int(rng.integers(0, len(candidates)))]
    case_dir = Path(directory) / f"{index:06d}-{fmt}"
    if case_dir.exists():
        shutil.rmtree(case_dir)
    case_dir.mkdir(parents=True)
    target = case_dir / origin.path.name
    if origin.path.is_dir():
        shutil.copytree(origin.path, target)
    else:
        shutil.copyfile(origin.path, target)
    n = int(rng.choice([1, 1, 1, 1, 1, 1, 2, 2, 2, 3]))
    mutations: list[str] = []
    gridless = origin.gridless
    with warnings.catch_warnings(), _lenient_pydicom():
        warnings.simplefilter("ignore")
        if rng.random() < edge_fraction:
            mutations.append(write_edge_case(rng, origin, target))
            gridless = origin.format in ("json", "csv", "rtstruct")
            n = int(rng.choice([0, 0, 1, 2]))
        for _ in range(n):
            try:
                mutations.append(_mutate(rng, origin, target))
            except Exception as exc:  # noqa: BLE001 - an earlier mutation broke the structure
                victim = (
                    target
                    if target.is_file()
                    else next((p for p in sorted(target.rglob("*")) if p.is_file()), None)
                )
                if victim is None:
                    break
                mutations.append(
                    f"{_byte_mutation(rng, victim)} (structure unreadable: {type(exc).__name__})"
                )
    method = "default" if rng.random() < default_method_fraction else "sdf"
    spacing = None
    if gridless and (method == "default" or rng.random() >= DEFAULT_SPACING_FRACTION):
        spacing = GRIDLESS_SPACING  # the default method on a 256 x 256 grid takes 10-40 s
    return Mutant(index, fmt, origin.name, target, tuple(mutations), method, spacing)


def seed_cases(seeds: list[Seed]) -> list[Mutant]:
    """The seeds themselves as (unmutated) cases, numbered -1, -2, ..."""
    return [
        Mutant(
            -1 - i, s.format, s.name, s.path, (), "sdf", GRIDLESS_SPACING if s.gridless else None
        )
        for i, s in enumerate(seeds)
    ]
