"""Tests of the VTK XML ImageData (.vti) reader on files written here in every encoding."""

from __future__ import annotations

import base64
import zlib
from pathlib import Path

import numpy as np
import pytest

from slicerecon.errors import FormatError, InputError, LabelError, OptionError
from slicerecon.io.vti import read_vti

RNG = np.random.default_rng(0)
LABELS = RNG.integers(0, 16, size=(7, 5, 4)).astype(np.uint8)  # (x, y, z)


def _blocks(raw: bytes, block: int) -> tuple[list[int], list[bytes]]:
    chunks = [raw[i : i + block] for i in range(0, len(raw), block)] or [b""]
    packed = [zlib.compress(c) for c in chunks]
    return [len(c) for c in chunks], packed


def _payload(
    raw: bytes, *, compressed: bool, header: str, order: str, block: int
) -> tuple[bytes, bytes]:
    """(header bytes, data bytes) of one array as VTK writes them."""
    code = order + ("u4" if header == "UInt32" else "u8")
    if not compressed:
        return np.array([len(raw)], dtype=code).tobytes(), raw
    sizes, packed = _blocks(raw, block)
    head = [len(packed), block, sizes[-1] if sizes[-1] != block else 0, *[len(p) for p in packed]]
    return np.array(head, dtype=code).tobytes(), b"".join(packed)


def write_vti(
    path: Path,
    values: np.ndarray,
    *,
    fmt: str = "appended",
    compressed: bool = False,
    header: str = "UInt32",
    big_endian: bool = False,
    cell: bool = False,
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0),
    spacing: tuple[float, float, float] = (1.0, 1.0, 1.0),
    direction: str | None = None,
    extent_start: tuple[int, int, int] = (0, 0, 0),
    name: str = "labels",
    block: int = 32,
    extra_array: bool = False,
) -> Path:
    """Write ``values`` (x, y, z) as a .vti file in the requested encoding."""
    order = ">" if big_endian else "<"
    data = np.asarray(values)
    raw = data.astype(data.dtype.newbyteorder(order)).ravel(order="F").tobytes()
    counts = np.asarray(data.shape) + (1 if cell else 0)
    ext = " ".join(f"{s} {s + n - 1}" for s, n in zip(extent_start, counts, strict=True))
    vtk_type = {np.uint8: "UInt8", np.int16: "Int16", np.float32: "Float32"}[data.dtype.type]
    attrs = f'type="{vtk_type}" Name="{name}"'
    arrays: list[tuple[str, bytes, bytes]] = [
        (attrs, *_payload(raw, compressed=compressed, header=header, order=order, block=block))
    ]
    if extra_array:
        other = np.zeros_like(data).ravel(order="F").tobytes()
        arrays.append(
            (
                f'type="{vtk_type}" Name="zeros"',
                *_payload(other, compressed=compressed, header=header, order=order, block=block),
            )
        )
    elements, appended, offset = [], b"", 0
    for attr, head, body in arrays:
        if fmt == "ascii":
            text = (
                " ".join(str(v) for v in data.ravel(order="F"))
                if "zeros" not in attr
                else " ".join("0" for _ in range(data.size))
            )
            elements.append(f'<DataArray {attr} format="ascii">{text}</DataArray>')
        elif fmt in ("binary", "binary_joint"):
            # VTK encodes header and data separately; some writers encode them together
            text = (
                base64.b64encode(head + body).decode()
                if fmt == "binary_joint"
                else base64.b64encode(head).decode() + base64.b64encode(body).decode()
            )
            elements.append(f'<DataArray {attr} format="binary">\n  {text}\n</DataArray>')
        else:
            elements.append(f'<DataArray {attr} format="appended" offset="{offset}"/>')
            chunk = (
                head + body
                if fmt == "appended"
                else (base64.b64encode(head) + base64.b64encode(body))
            )  # offsets count characters
            appended += chunk
            offset += len(chunk)
    assoc = "CellData" if cell else "PointData"
    direction_attr = "" if direction is None else f' Direction="{direction}"'
    xml = (
        '<?xml version="1.0"?>\n'
        f'<VTKFile type="ImageData" version="1.0" '
        f'byte_order="{"BigEndian" if big_endian else "LittleEndian"}" header_type="{header}"'
        f"{' compressor=' + chr(34) + 'vtkZLibDataCompressor' + chr(34) if compressed else ''}>\n"
        f'<ImageData WholeExtent="{ext}" Origin="{" ".join(map(str, origin))}" '
        f'Spacing="{" ".join(map(str, spacing))}"{direction_attr}>\n'
        f'<Piece Extent="{ext}">\n<{assoc} Scalars="{name}">\n'
        + "\n".join(elements)
        + f"\n</{assoc}>\n</Piece>\n</ImageData>\n"
    )
    body = xml.encode()
    if fmt.startswith("appended"):
        encoding = b"raw" if fmt == "appended" else b"base64"
        body += b'<AppendedData encoding="' + encoding + b'">\n_' + appended
        body += b"\n</AppendedData>\n"
    body += b"</VTKFile>\n"
    path.write_bytes(body)
    return path


@pytest.mark.parametrize(
    ("fmt", "compressed"),
    [
        ("appended", False),
        ("appended", True),
        ("appended_base64", False),
        ("appended_base64", True),
        ("binary", False),
        ("binary", True),
        ("binary_joint", False),
        ("binary_joint", True),
        ("ascii", False),
    ],
)
def test_round_trip_every_encoding(tmp_path: Path, fmt: str, compressed: bool) -> None:
    path = write_vti(
        tmp_path / "a.vti",
        LABELS,
        fmt=fmt,
        compressed=compressed,
        spacing=(0.5, 0.75, 2.0),
        origin=(10.0, -4.0, 3.0),
        extra_array=True,
    )
    image = read_vti(path)
    np.testing.assert_array_equal(image.values, LABELS)
    assert image.values.dtype == np.uint8 and image.name == "labels"
    assert image.association == "point"
    np.testing.assert_allclose(
        image.affine, [[0.5, 0, 0, 10], [0, 0.75, 0, -4], [0, 0, 2, 3], [0, 0, 0, 1]]
    )
    zeros = read_vti(path, array="zeros")
    assert zeros.values.shape == LABELS.shape and not zeros.values.any()


@pytest.mark.parametrize("block", [7, 32, 1000])
def test_multi_block_zlib_uint64_big_endian(tmp_path: Path, block: int) -> None:
    values = RNG.integers(-300, 300, size=(6, 4, 5)).astype(np.int16)
    path = write_vti(
        tmp_path / "b.vti", values, compressed=True, header="UInt64", big_endian=True, block=block
    )
    np.testing.assert_array_equal(read_vti(path).values, values)


def test_cell_data_direction_and_extent_offset(tmp_path: Path) -> None:
    path = write_vti(
        tmp_path / "c.vti",
        LABELS,
        cell=True,
        spacing=(1.0, 2.0, 3.0),
        direction="0 -1 0 1 0 0 0 0 1",
        extent_start=(2, 0, 1),
    )
    image = read_vti(path)
    assert image.association == "cell"
    np.testing.assert_array_equal(image.values, LABELS)
    # cell (0, 0, 0) is centred half a voxel in from point (2, 0, 1)
    centre = np.array([2.5 * 1.0, 0.5 * 2.0, 1.5 * 3.0])
    rot = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]], dtype=float)
    np.testing.assert_allclose(image.affine[:3, 3], rot @ centre)
    np.testing.assert_allclose(image.affine[:3, :3], rot * [1.0, 2.0, 3.0])


def test_clear_errors(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="not found"):
        read_vti(tmp_path / "missing.vti")
    good = write_vti(tmp_path / "g.vti", LABELS, compressed=True)
    with pytest.raises(LabelError, match="arrays present: 'labels'"):
        read_vti(good, array="density")
    with pytest.raises(OptionError):
        read_vti(good, array=3)  # type: ignore[arg-type]

    raw = good.read_bytes()
    cut = tmp_path / "truncated.vti"
    cut.write_bytes(raw[: raw.index(b"_") + 30] + b"\n</AppendedData></VTKFile>")
    with pytest.raises(FormatError, match="truncated"):
        read_vti(cut)

    start = raw.index(b"_") + 1 + 4 * 4  # past the 4-integer header of one block
    corrupt = tmp_path / "corrupt.vti"
    corrupt.write_bytes(raw[:start] + b"\x00\x01\x02\x03" + raw[start + 4 :])
    with pytest.raises(FormatError, match="corrupt"):
        read_vti(corrupt)

    lz4 = tmp_path / "lz4.vti"
    lz4.write_bytes(raw.replace(b"vtkZLibDataCompressor", b"vtkLZ4DataCompressor"))
    with pytest.raises(FormatError, match="vtkLZ4DataCompressor"):
        read_vti(lz4)

    poly = tmp_path / "poly.vti"
    poly.write_text('<?xml version="1.0"?><VTKFile type="PolyData"></VTKFile>')
    with pytest.raises(FormatError, match="not a VTK ImageData"):
        read_vti(poly)

    garbage = tmp_path / "garbage.vti"
    garbage.write_bytes(b"\x89PNG not xml at all")
    with pytest.raises(FormatError, match="not a readable VTK XML"):
        read_vti(garbage)

    vectors = tmp_path / "vectors.vti"
    vectors.write_bytes(
        write_vti(tmp_path / "v.vti", LABELS, fmt="ascii")
        .read_bytes()
        .replace(b'Name="labels"', b'Name="labels" NumberOfComponents="3"')
    )
    with pytest.raises(FormatError, match="3 components"):
        read_vti(vectors)

    text = write_vti(tmp_path / "s.vti", LABELS, fmt="ascii").read_bytes()
    start = text.index(b'format="ascii">') + len(b'format="ascii">')
    short = tmp_path / "short.vti"
    short.write_bytes(text[:start] + text[start:].split(b" ", 1)[1])  # drop the first value
    with pytest.raises(FormatError, match="holds 139 values; its extent needs 140"):
        read_vti(short)


def test_load_input_reads_a_vti_label_map(tmp_path: Path) -> None:
    from slicerecon.cli import main
    from slicerecon.io import detect_kind, load_input

    labels = np.zeros((12, 10, 8), dtype=np.uint8)
    labels[2:6, 2:5, 1:4] = 3
    labels[7:10, 5:9, 3:7] = 5
    path = write_vti(tmp_path / "organs.vti", labels)
    assert detect_kind(path).kind == "vti"
    assert load_input(path, union=True).mask.sum() == np.count_nonzero(labels)
    assert load_input(path, label=5).mask.sum() == np.count_nonzero(labels == 5)
    with pytest.raises(LabelError, match="label 4"):
        load_input(path, label=4)
    assert main(["info", str(path), "--label", "4"]) == 2
