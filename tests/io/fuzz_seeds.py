"""Seed inputs for fuzzing the readers (``tests/test_fuzz.py``): tiny valid files of every format.

:func:`write_seeds` writes a few variants of every input format (a few kB each,
so one case runs in milliseconds); ``fuzz_mutations.make_mutant`` copies one
and damages it. :func:`write_edge_case` replaces a seed's content with a valid
but awkward input of the same format (an empty or one-voxel mask, a single
plane, a sheared or extremely anisotropic grid, planes 1 µm or 500 m apart,
self-intersecting or 5000-point polygons, tilted planes, ...): well-formed
files that mostly pass the readers and stress what comes after reading (some,
like an empty mask or a singular affine, must be refused).

Use from a test module: ``tests/io`` is on pytest's ``pythonpath``, so
``import fuzz_seeds``; ``benchmarks/fuzz_inputs.py`` puts ``tests/io`` on
``sys.path`` itself.
"""

from __future__ import annotations

import base64
import bz2
import gzip
import json
import lzma
import zlib
from pathlib import Path
from typing import Any, NamedTuple

import dicom_factory as factory
import nibabel as nib
import numpy as np

__all__ = ["FORMATS", "Seed", "write_edge_case", "write_seeds", "write_vti"]

FORMATS: tuple[str, ...] = (
    "nifti",
    "nifti-gz",
    "dicom-series",
    "dicom-seg",
    "rtstruct",
    "rtstruct-series",
    "json",
    "csv",
    "vti",
    "nrrd",
    "seg-nrrd",
)
"""Input formats, in the order mutant indices cycle through them."""


class Seed(NamedTuple):
    """A valid input that mutants are made from.

    Attributes
    ----------
    format : str
        One of :data:`FORMATS`.
    name : str
        The variant, e.g. ``"zlib-appended"``.
    path : Path
        The file, or the directory of a series.
    target : str or None
        For a directory: the file most worth mutating (the RTSTRUCT beside its
        series); None to pick any file.
    gridless : bool
        Contours without an image grid of their own: read with the default
        in-plane spacing (extent / 256) they take ~0.5 s, so most mutants are
        read with a given ``pixel_spacing`` (``fuzz_mutations``).
    """

    format: str
    name: str
    path: Path
    target: str | None = None
    gridless: bool = False


# ----------------------------------------------------------------------------- seeds
def _ball(shape: tuple[int, int, int], radii: tuple[float, float, float]) -> np.ndarray:
    grid = np.indices(shape, dtype=np.float64)
    centre = (np.asarray(shape, dtype=np.float64) - 1) / 2
    r2 = sum(((g - c) / r) ** 2 for g, c, r in zip(grid, centre, radii, strict=True))
    return r2 <= 1.0


def _nifti_seeds(root: Path) -> list[Seed]:
    mask = _ball((12, 11, 9), (4.5, 4.0, 3.5))
    labels = mask.astype(np.int16) + (_ball((12, 11, 9), (2.0, 2.0, 2.0)) & mask)
    oblique = np.array(
        [[0.0, -0.9, 0.1, 10.0], [0.8, 0.0, 0.0, -20.0], [0.0, 0.05, 1.5, 5.0], [0, 0, 0, 1]]
    )
    seeds = []
    specs = [
        ("uint8", nib.Nifti1Image(mask.astype(np.uint8), np.diag([1.0, 1.0, 2.0, 1.0]))),
        ("int16-labels", nib.Nifti1Image(labels, oblique)),
        ("float32", nib.Nifti1Image(mask.astype(np.float32), np.diag([0.7, 0.7, 1.5, 1.0]))),
        ("nifti2", nib.Nifti2Image(mask.astype(np.uint8), np.diag([1.0, 1.2, 2.0, 1.0]))),
    ]
    for name, image in specs:
        image.header.set_xyzt_units("mm")
        for fmt, suffix in (("nifti", ".nii"), ("nifti-gz", ".nii.gz")):
            path = root / f"{name}{suffix}"
            nib.save(image, path)
            seeds.append(Seed(fmt, name, path))
    return seeds


def _dicom_seeds(root: Path) -> list[Seed]:
    mask = _ball((10, 9, 9), (3.5, 3.0, 4.0)).astype(np.uint16)
    axial = factory.affine_from_geometry(
        [1, 0, 0], [0, 1, 0], [0.8, 0.8], [0, 0, 2.0], [-4.0, -3.6, 10.0]
    )
    c, s = np.cos(0.3), np.sin(0.3)
    oblique = factory.affine_from_geometry(
        [c, s, 0], [0, 0, -1], [1.0, 0.9], np.cross([c, s, 0], [0, 0, -1]) * 1.5, [5.0, -2.0, 30.0]
    )
    seeds = [
        Seed(
            "dicom-series",
            "axial",
            factory.write_series(root / "series-axial", mask, axial)[0].parent,
        ),
        Seed(
            "dicom-series",
            "oblique-rescaled",
            factory.write_series(
                root / "series-oblique", mask * 3, oblique, modality="CT", rescale=(0.5, -1.0)
            )[0].parent,
        ),
    ]
    seeds += [
        Seed(
            "dicom-seg",
            "binary",
            factory.write_seg(root / "seg-binary.dcm", {1: mask > 0}, axial, labels={1: "Ball"}),
        ),
        Seed(
            "dicom-seg",
            "fractional",
            factory.write_seg(
                root / "seg-fractional.dcm",
                {1: mask * 0.8},
                oblique,
                labels={1: "Ball"},
                fractional=True,
            ),
        ),
        Seed(
            "dicom-seg",
            "every-frame",
            factory.write_seg(
                root / "seg-every-frame.dcm",
                {1: mask > 0},
                axial,
                labels={1: "Ball"},
                omit_empty_frames=False,
            ),
        ),
        Seed(
            "dicom-seg",
            "overlapping",
            factory.write_seg(
                root / "seg-overlapping.dcm",
                {
                    1: mask > 0,
                    2: _ball(mask.shape, (2.0, 2.0, 2.5)),
                    3: _ball(mask.shape, (4.5, 1.0, 1.0)),
                },
                oblique,
                labels={1: "Ball", 2: "Kern", 3: "Tête"},
            ),
        ),
    ]
    return seeds


def _rtstruct(
    path: Path, contours: list, *, preamble: bool = True, on_series: Path | None = None
) -> Path:
    """An RTSTRUCT holding one ROI, "Ball", with the given contour items (drawn on
    ``on_series``: its patient, study and frame of reference)."""
    return factory.write_rtstruct(
        path, {(1, "Ball"): contours}, preamble=preamble, on_series=on_series
    )


def _ring(centre: np.ndarray, radius: float, z: float, n: int = 10) -> np.ndarray:
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    return np.c_[centre[0] + radius * np.cos(t), centre[1] + radius * np.sin(t), np.full(n, z)]


def _rtstruct_seeds(root: Path) -> list[Seed]:
    affine = factory.affine_from_geometry(
        [1, 0, 0], [0, 1, 0], [1.0, 1.0], [0, 0, 2.0], [-8.0, -8.0, 0.0]
    )
    series = root / "rt-series"
    files = factory.write_series(series, np.zeros((16, 16, 8), np.uint16), affine)
    uids = factory.read_uids(files)
    centre = np.array([0.0, 0.0])
    on_grid = [
        factory.contour_item(_ring(centre, 5.0 - abs(k - 3.5), 2.0 * k), image_uid=uids[k])
        for k in range(1, 7)
    ]
    _rtstruct(series / "rtstruct.dcm", on_grid, on_series=series)
    free = [
        factory.contour_item(_ring(centre + 1.5, 6.0 - abs(z - 7.0) / 2, z, n=12))
        for z in (1.5, 4.0, 6.5, 9.0, 11.5)
    ]
    return [
        Seed("rtstruct", "own-grid", _rtstruct(root / "rtstruct-alone.dcm", free), gridless=True),
        Seed(
            "rtstruct", "on-grid", _rtstruct(root / "rtstruct-ongrid.dcm", on_grid), gridless=True
        ),
        Seed(
            "rtstruct",
            "no-preamble",
            _rtstruct(root / "rtstruct-bare.dcm", free, preamble=False),
            gridless=True,
        ),
        Seed("rtstruct-series", "with-series", series, target="rtstruct.dcm"),
    ]


def _square(z: float, half: float, centre: tuple[float, float] = (0.0, 0.0)) -> list:
    cx, cy = centre
    return [
        [cx - half, cy - half, z],
        [cx + half, cy - half, z],
        [cx + half, cy + half, z],
        [cx - half, cy + half, z],
    ]


def _contour_seeds(root: Path) -> list[Seed]:
    from slicerecon.io.contours import write_contours_csv, write_contours_json
    from slicerecon.reconstruct import prepare_inputs
    from slicerecon.sections import Volume

    volume = Volume(_ball((14, 12, 11), (5.0, 4.5, 4.0)), np.diag([1.0, 1.0, 2.0, 1.0]))
    sections, _, _ = prepare_inputs(volume, slices=5)
    seeds = [
        Seed("json", "written", write_contours_json(sections, root / "written.json", label="Ball")),
        Seed("csv", "written", write_contours_csv(sections, root / "written.csv"), gridless=True),
    ]
    planes: list[dict[str, Any]] = [
        {"position": z, "polygons": [_square(z, 4.0 - abs(z - 4.0) / 2)]}
        for z in (0.0, 2.0, 4.0, 6.0, 8.0)
    ]
    planes[2]["polygons"].append(_square(4.0, 0.8, (6.0, 6.0)))
    minimal = {
        "format": "slicerecon-contours",
        "version": 1,
        "units": "mm",
        "normal": [0.0, 0.0, 1.0],
        "grid": {
            "affine": [[0.5, 0, 0, -8.0], [0, 0.5, 0, -8.0], [0, 0, 2.0, 0.0], [0, 0, 0, 1]],
            "shape": [34, 34, 6],
        },
        "planes": planes + [{"position": 10.0, "polygons": []}],
    }
    path = root / "minimal.json"
    path.write_text(json.dumps(minimal), encoding="utf-8")
    seeds.append(Seed("json", "hand-grid", path))
    bare = {
        "format": "slicerecon-contours",
        "version": 1,
        "units": "mm",
        "planes": [{"polygons": [_square(z, 3.0)]} for z in (0.0, 1.5, 3.0)],
    }
    path = root / "bare.json"
    path.write_text(json.dumps(bare), encoding="utf-8")
    seeds.append(Seed("json", "bare", path, gridless=True))
    rows = ["plane,polygon,x,y,z"]
    for p, z in enumerate((0.0, 2.5, 5.0)):
        for q, centre in enumerate(((0.0, 0.0), (9.0, 0.0))):
            rows += [f"{p},{q},{x},{y},{zz}" for x, y, zz in _square(z, 3.0, centre)]
    path = root / "hand.csv"
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")
    seeds.append(Seed("csv", "hand", path, gridless=True))
    # planes of other orientations: sagittal, coronal and oblique (one orientation per file)
    rings = [(z, [_circle(4.0 - abs(z - 3.0) / 2, 10)]) for z in (0.0, 1.5, 3.0, 4.5, 6.0)]
    frames = {
        "sagittal": np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]),
        "coronal": np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]),
        "oblique": _rotation(np.array([0.4, -0.7, 0.6]), 0.9),
    }
    for name, frame in frames.items():
        json_path = write_contour_file(root / f"{name}.json", rings, frame)
        seeds.append(Seed("json", name, json_path, gridless=True))
        csv_path = write_contour_file(root / f"{name}.csv", rings, frame)
        seeds.append(Seed("csv", name, csv_path, gridless=True))
    # version 2: a tumour nested in a body, on axial, sagittal and tilted planes in one file
    seeds.append(Seed("json", "v2-views-nested", _views_file(root / "views.json"), gridless=True))
    return seeds


def _views_file(path: Path) -> Path:
    """A version 2 contour file: two nested structures, planes of three orientations."""
    tilted = _rotation(np.array([1.0, 0.0, 0.0]), np.radians(40))
    frames = [
        (np.eye(3), (-4.0, 0.0, 4.0)),  # axial
        (np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]]), (-2.0, 2.0)),  # sagittal
        (tilted, (0.0,)),
    ]
    planes = []
    for frame, offsets in frames:
        u, v, n = frame[0], frame[1], frame[2]
        for offset in offsets:
            for name, radius in (("Body", 7.0), ("Tumour", 3.0)):
                r = float(np.sqrt(max(radius**2 - offset**2, 0.0)))
                if r < 1.0:
                    continue
                ring = [
                    offset * n + r * (np.cos(t) * u + np.sin(t) * v)
                    for t in np.linspace(0, 2 * np.pi, 12, endpoint=False)
                ]
                planes.append(
                    {
                        "position": offset,
                        "normal": n.tolist(),
                        "structure": name,
                        "polygons": [[[round(float(c), 4) for c in p] for p in ring]],
                    }
                )
    document = {
        "format": "slicerecon-contours",
        "version": 2,
        "units": "mm",
        "structures": [
            {"value": 1, "name": "Body", "colour": [200, 150, 120]},
            {"value": 2, "name": "Tumour"},
        ],
        "planes": planes,
    }
    path.write_text(json.dumps(document), encoding="utf-8")
    return path


def _vti_payload(raw: bytes, *, compressor: str | None, header: str, block: int = 64) -> bytes:
    """Header + data bytes of one binary array, as VTK writes them."""
    if compressor is None:
        return np.array([len(raw)], dtype=header).tobytes() + raw
    pack = zlib.compress if compressor == "vtkZLibDataCompressor" else lzma.compress
    chunks = [raw[i : i + block] for i in range(0, len(raw), block)]
    packed = [pack(c) for c in chunks]
    last = len(chunks[-1]) if len(chunks[-1]) != block else 0
    head = [len(packed), block, last, *[len(p) for p in packed]]
    return np.array(head, dtype=header).tobytes() + b"".join(packed)


def write_vti(
    path: Path,
    values: np.ndarray,
    *,
    fmt: str,
    compressor: str | None = None,
    header: str = "UInt32",
    big_endian: bool = False,
    cell: bool = False,
    encoding: str = "raw",
    origin: str = "-3 2.5 10",
    spacing: str = "0.8 0.9 1.7",
    direction: str = "0 1 0 -1 0 0 0 0 1",
) -> Path:
    """Write a uint8 label map ``values`` (x, y, z) as a small ``.vti`` file."""
    order = ">" if big_endian else "<"
    raw = np.asarray(values, dtype=np.uint8).ravel(order="F").tobytes()
    payload = _vti_payload(
        raw, compressor=compressor, header=order + ("u4" if header == "UInt32" else "u8")
    )
    counts = np.asarray(values.shape) + (1 if cell else 0)
    extent = " ".join(f"{s} {s + n - 1}" for s, n in zip((2, 0, -1), counts, strict=True))
    attrs = f'type="UInt8" Name="labels" format="{fmt}"'
    appended = b""
    if fmt == "ascii":
        body = " ".join(str(v) for v in values.ravel(order="F"))
    elif fmt == "binary":
        body = base64.b64encode(payload).decode()
    else:
        attrs += ' offset="0"'
        body = ""
        data = base64.b64encode(payload) if encoding == "base64" else payload
        appended = (
            f'  <AppendedData encoding="{encoding}">\n   _'.encode()
            + data
            + b"\n  </AppendedData>\n"
        )
    group = "CellData" if cell else "PointData"
    comp = f' compressor="{compressor}"' if compressor else ""
    text = (
        (
            '<?xml version="1.0"?>\n'
            f'<VTKFile type="ImageData" version="1.0" byte_order='
            f'"{"BigEndian" if big_endian else "LittleEndian"}" header_type="{header}"{comp}>\n'
            f'  <ImageData WholeExtent="{extent}" Origin="{origin}" Spacing="{spacing}" '
            f'Direction="{direction}">\n'
            f'    <Piece Extent="{extent}">\n'
            f'      <{group} Scalars="labels">\n'
            f"        <DataArray {attrs}>{body}</DataArray>\n"
            f"      </{group}>\n"
            "    </Piece>\n  </ImageData>\n"
        ).encode()
        + appended
        + b"</VTKFile>\n"
    )
    path.write_bytes(text)
    return path


def _vti_seeds(root: Path) -> list[Seed]:
    values = _ball((9, 8, 10), (3.5, 3.0, 4.0)).astype(np.uint8) * 3
    specs: list[tuple[str, dict]] = [
        ("ascii", {"fmt": "ascii"}),
        ("binary", {"fmt": "binary"}),
        ("binary-zlib", {"fmt": "binary", "compressor": "vtkZLibDataCompressor"}),
        ("appended-raw", {"fmt": "appended"}),
        (
            "appended-base64-lzma",
            {"fmt": "appended", "encoding": "base64", "compressor": "vtkLZMADataCompressor"},
        ),
        (
            "appended-zlib-uint64-be",
            {
                "fmt": "appended",
                "header": "UInt64",
                "big_endian": True,
                "compressor": "vtkZLibDataCompressor",
            },
        ),
        ("cell-binary", {"fmt": "binary", "cell": True}),
    ]
    return [Seed("vti", name, write_vti(root / f"{name}.vti", values, **kw)) for name, kw in specs]


_NRRD_TYPES = {"u1": "uchar", "i2": "short", "u2": "ushort", "i4": "int", "f4": "float"}


def write_nrrd(
    path: Path,
    data: np.ndarray,
    fields: list[str],
    *,
    encoding: str = "gzip",
    big_endian: bool = False,
) -> Path:
    """Write ``data`` (NRRD axis order: the first axis varies fastest) with header ``fields``.

    ``fields`` are the lines after ``type``, ``dimension``, ``sizes``, ``endian`` and
    ``encoding``, which are written from ``data`` (byte for byte what the tests need).
    """
    code = data.dtype.str[1:]
    dtype = data.dtype.newbyteorder(">" if big_endian else "<")
    raw = np.asarray(data, dtype=dtype).tobytes(order="F")
    lines = [
        "NRRD0004",
        "# written by slicerecon's fuzz seeds",
        f"type: {_NRRD_TYPES[code]}",
        f"dimension: {data.ndim}",
        "sizes: " + " ".join(str(n) for n in data.shape),
        *([f"endian: {'big' if big_endian else 'little'}"] if data.dtype.itemsize > 1 else []),
        f"encoding: {encoding}",
        *fields,
    ]
    if encoding == "gzip":
        body = gzip.compress(raw)
    elif encoding == "bzip2":
        body = bz2.compress(raw)
    elif encoding == "ascii":
        body = (" ".join(str(v) for v in np.asarray(data).ravel(order="F")) + "\n").encode()
    else:
        body = raw
    path.write_bytes(("\n".join(lines) + "\n\n").encode("utf-8") + body)
    return path


def _nrrd_space(affine: np.ndarray, *, list_axis: bool = False) -> list[str]:
    vectors = " ".join("(" + ",".join(f"{v:.17g}" for v in affine[:3, a]) + ")" for a in range(3))
    origin = "(" + ",".join(f"{v:.17g}" for v in affine[:3, 3]) + ")"
    return [
        "space: left-posterior-superior",
        f"space directions: {'none ' if list_axis else ''}{vectors}",
        f"kinds: {'list ' if list_axis else ''}domain domain domain",
        f"space origin: {origin}",
    ]


def _segment_fields(segments: list[tuple[str, int, int, str]]) -> list[str]:
    """``Segment<N>_*`` lines of (name, label value, layer, extent) as Slicer writes them."""
    lines = [
        "Segmentation_MasterRepresentation:=Binary labelmap",
        "Segmentation_ContainedRepresentationNames:=Binary labelmap|",
        "Segmentation_ReferenceImageExtentOffset:=0 0 0",
    ]
    for n, (name, value, layer, extent) in enumerate(segments):
        lines += [
            f"Segment{n}_ID:=Segment_{n + 1}",
            f"Segment{n}_Name:={name}",
            f"Segment{n}_Color:=0.{n + 2} 0.5 0.{9 - n}",
            f"Segment{n}_LabelValue:={value}",
            f"Segment{n}_Layer:={layer}",
            f"Segment{n}_Extent:={extent}",
            f"Segment{n}_Tags:=",
        ]
    return lines


def _extent(mask: np.ndarray) -> str:
    hits = np.argwhere(mask)
    lo, hi = hits.min(axis=0), hits.max(axis=0)
    return " ".join(f"{a} {b}" for a, b in zip(lo.tolist(), hi.tolist(), strict=True))


def _nrrd_seeds(root: Path) -> list[Seed]:
    shape = (11, 10, 8)
    ball = _ball(shape, (4.5, 4.0, 3.0))
    core = _ball(shape, (2.0, 2.0, 1.5))
    labels = ball.astype(np.uint8) + core
    c, s = np.cos(0.4), np.sin(0.4)
    oblique = np.array(
        [
            [0.9 * c, -0.9 * s, 0, -20.0],
            [0.9 * s, 0.9 * c, 0, 15.5],
            [0, 0, 2.5, 40.0],
            [0, 0, 0, 1],
        ]
    )
    seeds = [
        Seed(
            "nrrd",
            "raw-lps",
            write_nrrd(root / "raw.nrrd", labels, _nrrd_space(oblique), encoding="raw"),
        ),
        Seed(
            "nrrd",
            "gzip-int16-be",
            write_nrrd(
                root / "gzip.nrrd",
                labels.astype(np.int16) * 300,
                _nrrd_space(np.diag([0.8, 0.8, 2.0, 1.0])),
                big_endian=True,
            ),
        ),
        Seed(
            "nrrd",
            "bzip2-spacings",
            write_nrrd(
                root / "bzip2.nrrd",
                labels,
                ["spacings: 0.7 0.7 3", "axis mins: -5 -5 10"],
                encoding="bzip2",
            ),
        ),
        Seed(
            "nrrd",
            "ascii",
            write_nrrd(root / "ascii.nrrd", labels, _nrrd_space(np.eye(4)), encoding="ascii"),
        ),
    ]
    # 3D Slicer segmentations: one layer, and two overlapping layers
    three_d = _segment_fields(
        [("Ball", 1, 0, _extent(labels == 1)), ("Tête", 2, 0, _extent(labels == 2))]
    )
    tumour = _ball(shape, (2.5, 3.0, 2.0)) & ~core
    layers = np.stack([labels, tumour.astype(np.uint8) * 1])  # list axis first
    four_d = _segment_fields(
        [
            ("Ball", 1, 0, _extent(labels == 1)),
            ("Core", 2, 0, _extent(labels == 2)),
            ("Tumour", 1, 1, _extent(tumour)),
        ]
    )
    seeds += [
        Seed(
            "seg-nrrd",
            "slicer-3d",
            write_nrrd(root / "three.seg.nrrd", labels, _nrrd_space(oblique) + three_d),
        ),
        Seed(
            "seg-nrrd",
            "slicer-layers",
            write_nrrd(
                root / "layers.seg.nrrd",
                layers,
                _nrrd_space(oblique, list_axis=True) + four_d,
            ),
        ),
    ]
    return seeds


def write_seeds(directory: str | Path) -> list[Seed]:
    """Write the seed inputs of every format into ``directory``.

    Returns
    -------
    list of Seed
        Several variants per format of :data:`FORMATS`.
    """
    root = Path(directory)
    root.mkdir(parents=True, exist_ok=True)
    seeds = (
        _nifti_seeds(root)
        + _dicom_seeds(root)
        + _rtstruct_seeds(root)
        + _contour_seeds(root)
        + _vti_seeds(root)
        + _nrrd_seeds(root)
    )
    assert {s.format for s in seeds} == set(FORMATS)
    return seeds


# ----------------------------------------------------------------------------- edge cases
_EDGE_MASKS = (
    "empty",
    "one-voxel",
    "one-plane",
    "two-planes",
    "column",
    "full",
    "shell",
    "noise",
    "every-other-plane",
    "two-blobs",
    "sheet-x",
    "tiny-grid",
    "long",
    "big",
    "checker",
    "many-labels",
)
_EDGE_AFFINES = (
    "identity",
    "flipped",
    "rotated",
    "anisotropic",
    "tiny",
    "huge",
    "tilted-slices",
    "permuted",
    "far-origin",
    "singular",
    "sheared",
)
_EDGE_PLANES = (
    "single-plane",
    "collinear",
    "duplicate-points",
    "bowtie",
    "holes",
    "many-points",
    "tiny",
    "huge",
    "close-planes",
    "far-planes",
    "uneven",
    "many-planes",
    "disjoint",
    "touching",
    "triangles",
    "clockwise-mix",
)


def _edge_mask(rng: np.random.Generator) -> tuple[str, np.ndarray]:
    """An awkward label map (uint16, axes x, y, z)."""
    kind = str(rng.choice(_EDGE_MASKS))
    shape = (9, 8, 10)
    mask = np.zeros(shape, np.uint16)
    disk = _ball((9, 8, 1), (3.5, 3.0, 1.0))[:, :, 0]
    if kind == "one-voxel":
        mask[4, 4, 5] = 1
    elif kind == "one-plane":
        mask[:, :, 5] = disk
    elif kind == "two-planes":
        mask[:, :, 4] = mask[:, :, 5] = disk
    elif kind == "column":
        mask[4, 4, :] = 1
    elif kind == "full":
        mask[:] = 1
    elif kind == "shell":
        mask[:] = 1
        mask[1:-1, 1:-1, 1:-1] = 0
    elif kind == "noise":
        mask = (rng.random(shape) < 0.5).astype(np.uint16)
    elif kind == "every-other-plane":
        mask[:, :, ::2] = _ball(shape, (3.5, 3.0, 4.0))[:, :, ::2]
    elif kind == "two-blobs":
        mask[:, :, 1] = mask[:, :, 2] = mask[:, :, 8] = disk
    elif kind == "sheet-x":
        mask[4, :, :] = 1
    elif kind == "tiny-grid":
        mask = np.ones(tuple(int(n) for n in rng.integers(1, 3, size=3)), np.uint16)
    elif kind == "long":
        mask = np.zeros((3, 3, 60), np.uint16)
        mask[1, 1, 5:55] = 1
    elif kind == "big":
        mask = _ball((48, 48, 48), (20.0, 20.0, 20.0)).astype(np.uint16)
    elif kind == "checker":
        mask = (np.indices(shape).sum(axis=0) % 2).astype(np.uint16)
    elif kind == "many-labels":
        mask = rng.integers(0, 250, size=shape).astype(np.uint16)
    return kind, mask


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    a = axis / np.linalg.norm(axis)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def _edge_affine(rng: np.random.Generator, *, square_pixels: bool) -> tuple[str, np.ndarray]:
    """An awkward voxel → world affine; ``square_pixels``: columns 0 and 1 orthogonal (DICOM)."""
    kinds = [k for k in _EDGE_AFFINES if not (square_pixels and k in ("singular", "sheared"))]
    kind = str(rng.choice(kinds))
    affine = np.eye(4)
    if kind == "flipped":
        affine[:3, :3] = np.diag([-1.0, 1.0, -2.0])
    elif kind == "rotated":
        affine[:3, :3] = _rotation(np.array([0.3, 0.5, 0.8]), 0.7) * [0.7, 0.7, 2.5]
    elif kind == "anisotropic":
        affine[:3, :3] = np.diag([0.01, 0.01, 50.0])
    elif kind == "tiny":
        affine[:3, :3] = np.diag([1e-3, 1e-3, 1e-3])
    elif kind == "huge":
        affine[:3, :3] = np.diag([500.0, 500.0, 500.0])
    elif kind == "tilted-slices":
        affine[:3, 2] = [0.0, 0.6, 1.5]
    elif kind == "permuted":
        affine[:3, :3] = [[0, 0, 2.0], [1.0, 0, 0], [0, 1.0, 0]]
    elif kind == "far-origin":
        affine[:3, 3] = [9e5, -9e5, 9e5]
    elif kind == "singular":
        affine[:3, 2] = 0.0
    elif kind == "sheared":
        affine[:3, :3] = [[1.0, 0.8, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    return kind, affine


def _vti_geometry(affine: np.ndarray) -> dict[str, str]:
    spacing = np.linalg.norm(affine[:3, :3], axis=0)
    direction = affine[:3, :3] / np.where(spacing > 0, spacing, 1.0)
    return {
        "spacing": " ".join(f"{v:.17g}" for v in spacing),
        "direction": " ".join(f"{v:.17g}" for v in direction.ravel()),
        "origin": " ".join(f"{v:.17g}" for v in affine[:3, 3]),
    }


def _write_edge_volume(rng: np.random.Generator, seed: Seed, path: Path) -> str:
    kind, mask = _edge_mask(rng)
    aname, affine = _edge_affine(rng, square_pixels=seed.format.startswith("dicom"))
    if seed.format in ("nifti", "nifti-gz"):
        image_class = nib.Nifti2Image if rng.random() < 0.2 else nib.Nifti1Image
        dtypes = (np.uint8, np.int16, np.uint16, np.int32, np.float32, np.float64)
        dtype = dtypes[int(rng.integers(0, len(dtypes)))]
        try:
            image = image_class(mask.astype(dtype), affine)
        except nib.spatialimages.HeaderDataError:  # no qform for this affine: sform only
            header = image_class.header_class()
            header.set_sform(affine, code=1)
            image = image_class(mask.astype(dtype), None, header=header)
        nib.save(image, path)
    elif seed.format == "dicom-series":
        for old in path.iterdir():
            old.unlink()
        positions = None
        if rng.random() < 0.15 and mask.shape[2] > 2:
            gaps = rng.choice([0.5, 1.0, 3.0, 1e-3], size=mask.shape[2] - 1)
            positions = np.concatenate([[0.0], np.cumsum(gaps)]).tolist()
            aname += "+irregular"
        factory.write_series(path, mask, affine, irregular_positions=positions)
    elif seed.format == "dicom-seg":
        factory.write_seg(
            path,
            {1: mask > 0},
            affine,
            labels={1: "Edge"},
            fractional=bool(rng.random() < 0.3),
            omit_empty_frames=bool(mask.any() and rng.random() < 0.7),
        )
    elif seed.format in ("nrrd", "seg-nrrd"):
        values = np.minimum(mask, 255).astype(np.uint8)
        fields = _nrrd_space(affine)
        if seed.format == "seg-nrrd":
            present = [int(v) for v in np.unique(values) if v]
            fields += _segment_fields([(f"S{v}", v, 0, _extent(values == v)) for v in present[:12]])
        encoding = str(rng.choice(["raw", "gzip", "bzip2"]))
        write_nrrd(path, values, fields, encoding=encoding)
        aname += f"+{encoding}"
    else:
        fmt = str(rng.choice(["ascii", "binary", "appended"]))
        geometry = _vti_geometry(affine)
        write_vti(
            path,
            np.minimum(mask, 255).astype(np.uint8),
            fmt=fmt,
            origin=geometry["origin"],
            spacing=geometry["spacing"],
            direction=geometry["direction"],
        )
    return f"edge.{kind}:{aname}"


def _circle(radius: float, n: int, centre: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    return np.c_[centre[0] + radius * np.cos(t), centre[1] + radius * np.sin(t)]


def _edge_planes(rng: np.random.Generator) -> tuple[str, list[tuple[float, list[np.ndarray]]]]:
    """Awkward planes: (position along the normal, in-plane polygons of shape (N, 2)), mm."""
    kind = str(rng.choice(_EDGE_PLANES))
    ring = _circle(5.0, 12)
    positions = [0.0, 2.0, 4.0]
    polygons: list[np.ndarray] = [ring]
    if kind == "single-plane":
        positions = [0.0]
    elif kind == "collinear":
        polygons = [np.c_[np.linspace(-5, 5, 6), np.linspace(-5, 5, 6)]]
    elif kind == "duplicate-points":
        polygons = [np.repeat(ring, 3, axis=0)]
    elif kind == "bowtie":
        polygons = [np.array([[-5.0, -5.0], [5.0, 5.0], [5.0, -5.0], [-5.0, 5.0]])]
    elif kind == "holes":
        polygons = [ring, _circle(3.0, 12)[::-1], _circle(1.0, 8)]
    elif kind == "many-points":
        polygons = [_circle(5.0, 5000)]
    elif kind == "tiny":
        polygons = [ring * 2e-4]
        positions = [0.0, 1e-3, 2e-3]
    elif kind == "huge":
        polygons = [ring * 2e4]
    elif kind == "close-planes":
        positions = [0.0, 1e-3, 2e-3, 2.0]
    elif kind == "far-planes":
        positions = [0.0, 2.0, 5e5]
    elif kind == "uneven":
        positions = [0.0, 0.5, 7.0, 7.2, 30.0]
    elif kind == "many-planes":
        positions = [0.5 * k for k in range(300)]
    elif kind == "disjoint":
        polygons = [ring, _circle(5.0, 12, (500.0, 0.0))]
    elif kind == "touching":
        square = np.array([[0.0, 0.0], [4.0, 0.0], [4.0, 4.0], [0.0, 4.0]])
        polygons = [square, square + [4.0, 0.0]]
    elif kind == "triangles":
        polygons = [np.array([[0.0, 0.0], [3.0, 0.0], [0.0, 3.0]])]
    elif kind == "clockwise-mix":
        polygons = [ring, _circle(2.0, 12, (9.0, 0.0))[::-1]]
    return kind, [(z, polygons) for z in positions]


def _frame(rng: np.random.Generator) -> tuple[str, np.ndarray]:
    """In-plane axes u, v and the normal n as the rows of a rotation (or the identity)."""
    r = rng.random()
    if r < 0.6:
        return "axial", np.eye(3)
    if r < 0.8:
        return "tilted", _rotation(np.array([1.0, 0.0, 0.0]), 0.6435)  # normal (0, -0.6, 0.8)
    axis = rng.normal(size=3)
    return "oblique", _rotation(axis, float(rng.uniform(0.1, 3.0)))


def write_contour_file(
    path: Path,
    planes: list[tuple[float, list[np.ndarray]]],
    frame: np.ndarray,
    *,
    normal: bool = True,
) -> Path:
    """Write planes of in-plane polygons as a JSON or CSV contour file (by suffix)."""
    u, v, n = frame
    world = [(z, [p[:, :1] * u + p[:, 1:] * v + z * n for p in polys]) for z, polys in planes]
    if path.suffix == ".csv":
        rows = ["plane,polygon,x,y,z"]
        for k, (_, polys) in enumerate(world):
            for q, points in enumerate(polys):
                rows += [f"{k},{q},{x!r},{y!r},{z!r}" for x, y, z in points.tolist()]
        path.write_text("\n".join(rows) + "\n", encoding="utf-8")
        return path
    doc: dict = {"format": "slicerecon-contours", "version": 1, "units": "mm"}
    if normal:
        doc["normal"] = n.tolist()
    doc["planes"] = [
        {**({"position": z} if normal else {}), "polygons": [p.tolist() for p in polys]}
        for z, polys in world
    ]
    path.write_text(json.dumps(doc), encoding="utf-8")
    return path


def _write_edge_contours(rng: np.random.Generator, seed: Seed, path: Path) -> str:
    kind, planes = _edge_planes(rng)
    fname, frame = _frame(rng)
    if seed.format in ("json", "csv"):
        write_contour_file(path, planes, frame, normal=bool(rng.random() < 0.7))
        return f"edge.{kind}:{fname}"
    u, v, n = frame
    offset = np.array([0.0, 0.0, 3.0]) if seed.format == "rtstruct-series" else np.zeros(3)
    items = [
        factory.contour_item(p[:, :1] * u + p[:, 1:] * v + z * n + offset)
        for z, polys in planes
        for p in polys
    ]
    target = path / (seed.target or "rtstruct.dcm") if path.is_dir() else path
    _rtstruct(target, items, on_series=path if path.is_dir() else None)
    return f"edge.{kind}:{fname}"


def write_edge_case(rng: np.random.Generator, seed: Seed, path: Path) -> str:
    """Replace the copy of ``seed`` at ``path`` with a valid but awkward input of its format.

    Returns
    -------
    str
        ``"edge.<what>:<geometry>"``, e.g. ``"edge.one-plane:anisotropic"``.
    """
    if seed.format in ("json", "csv", "rtstruct", "rtstruct-series"):
        return _write_edge_contours(rng, seed, path)
    return _write_edge_volume(rng, seed, path)
