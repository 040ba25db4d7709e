"""NRRD label maps and 3D Slicer segmentations (slicerecon.io.nrrd): read, write, run."""

from __future__ import annotations

import bz2
import gzip
import json
import logging
from pathlib import Path

import nibabel as nib
import numpy as np
import pytest
import trimesh

from slicerecon.cli import main
from slicerecon.errors import (
    EmptyMaskError,
    FormatError,
    GeometryError,
    InputError,
    LabelError,
    MemoryBudgetError,
    OptionError,
)
from slicerecon.io import detect_kind, load_input
from slicerecon.io.describe import describe_input
from slicerecon.io.labelmap import read_label_map
from slicerecon.io.nrrd import nrrd_info, read_nrrd_label_map
from slicerecon.io.nrrd_writer import write_seg_nrrd
from slicerecon.labels import Structure

nrrd = pytest.importorskip("nrrd")

LPS_TO_RAS = np.diag([-1.0, -1.0, 1.0, 1.0])


def _oblique_affine() -> np.ndarray:
    """An oblique, anisotropic voxel → world affine (rotation about z and x)."""
    a, b = np.radians(25.0), np.radians(-10.0)
    rz = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    rx = np.array([[1, 0, 0], [0, np.cos(b), -np.sin(b)], [0, np.sin(b), np.cos(b)]])
    affine = np.eye(4)
    affine[:3, :3] = rz @ rx @ np.diag([0.7, 0.9, 2.5])
    affine[:3, 3] = [-80.25, 31.5, 112.0]
    return affine


def _labels() -> np.ndarray:
    labels = np.zeros((9, 8, 7), dtype=np.uint8)
    labels[1:4, 2:6, 1:3] = 1
    labels[5:8, 1:3, 2:6] = 2
    labels[4, 6, 5] = 5
    return labels


def _space_header(affine: np.ndarray, space: str = "left-posterior-superior") -> dict:
    return {
        "space": space,
        "space directions": affine[:3, :3].T,
        "space origin": affine[:3, 3],
        "kinds": ["domain"] * 3,
        "encoding": "gzip",
    }


def _write(path: Path, data: np.ndarray, header: dict) -> Path:
    nrrd.write(str(path), data, header, index_order="F")
    return path


def _raw_file(path: Path, header_lines: list[str], data: bytes = b"") -> Path:
    path.write_bytes(("\n".join(["NRRD0004", *header_lines]) + "\n\n").encode() + data)
    return path


# --------------------------------------------------------------------------- plain label maps


def test_detect_kind_for_nrrd_and_seg_nrrd(tmp_path: Path) -> None:
    for name in ("labels.nrrd", "labels.seg.nrrd", "UPPER.NRRD"):
        path = _write(tmp_path / name, _labels(), _space_header(np.eye(4)))
        assert detect_kind(path).kind == "nrrd"


def test_plain_label_map_keeps_values_and_lps_oblique_geometry(tmp_path: Path) -> None:
    affine = _oblique_affine()
    path = _write(tmp_path / "l.nrrd", _labels(), _space_header(affine))
    label_map = read_nrrd_label_map(path)
    np.testing.assert_array_equal(label_map.labels, _labels())
    np.testing.assert_allclose(label_map.affine, affine, rtol=0, atol=1e-12)
    assert label_map.coordinates == "LPS"
    assert [(s.value, s.name, s.colour) for s in label_map.structures] == [
        (1, "", None),
        (2, "", None),
        (5, "", None),
    ]
    # the voxel (i, j, k) of the file is at origin + i d0 + j d1 + k d2
    world = label_map.affine @ [4, 6, 5, 1]
    np.testing.assert_allclose(world[:3], affine[:3, 3] + affine[:3, :3] @ [4, 6, 5])


@pytest.mark.parametrize(
    ("space", "frame", "flip"),
    [
        ("right-anterior-superior", "RAS", np.eye(4)),
        ("RAS", "RAS", np.eye(4)),
        ("LPS", "LPS", np.eye(4)),
        ("left-anterior-superior", "RAS", np.diag([-1.0, 1.0, 1.0, 1.0])),
    ],
)
def test_space_field_gives_the_frame(
    tmp_path: Path, space: str, frame: str, flip: np.ndarray
) -> None:
    affine = _oblique_affine()
    path = _write(tmp_path / "l.nrrd", _labels(), _space_header(affine, space))
    info = nrrd_info(path)
    assert info.coordinates == frame
    np.testing.assert_allclose(info.affine, flip @ affine, atol=1e-12)


def test_no_space_fields_gives_spacings_and_axis_mins(tmp_path: Path) -> None:
    path = _write(
        tmp_path / "l.nrrd",
        _labels(),
        {"spacings": [0.5, 0.75, 3.0], "axis mins": [10.0, -4.0, 2.0], "encoding": "raw"},
    )
    info = nrrd_info(path)
    np.testing.assert_allclose(
        info.affine, [[0.5, 0, 0, 10], [0, 0.75, 0, -4], [0, 0, 3.0, 2.0], [0, 0, 0, 1]]
    )
    assert info.coordinates == "RAS"
    bare = nrrd_info(_write(tmp_path / "bare.nrrd", _labels(), {"encoding": "raw"}))
    np.testing.assert_array_equal(bare.affine, np.eye(4))


def test_space_units_are_converted_to_mm(tmp_path: Path) -> None:
    header = {**_space_header(np.diag([0.1, 0.1, 0.2, 1.0])), "space units": ["cm"] * 3}
    info = nrrd_info(_write(tmp_path / "l.nrrd", _labels(), header))
    np.testing.assert_allclose(np.diag(info.affine), [1.0, 1.0, 2.0, 1.0])


@pytest.mark.parametrize("encoding", ["raw", "gzip", "bzip2", "ascii"])
@pytest.mark.parametrize("dtype", ["<u2", ">i2", ">u4", "<i8", "u1"])
def test_every_encoding_and_byte_order(tmp_path: Path, encoding: str, dtype: str) -> None:
    labels = _labels().astype(dtype) * 300 if np.dtype(dtype).itemsize > 1 else _labels()
    header = {**_space_header(np.eye(4)), "encoding": encoding}
    path = _write(tmp_path / "l.nrrd", labels, header)
    back = read_nrrd_label_map(path).labels
    np.testing.assert_array_equal(back, labels)
    assert back.dtype.isnative


def test_float_label_map_with_whole_values_is_read(tmp_path: Path) -> None:
    path = _write(tmp_path / "f.nrrd", _labels().astype(np.float32), _space_header(np.eye(4)))
    label_map = read_nrrd_label_map(path)
    np.testing.assert_array_equal(label_map.labels, _labels())
    assert label_map.labels.dtype.kind in "iu"


# --------------------------------------------------------------------------- Slicer segmentations


def _segmentation(tmp_path: Path, *, four_d: bool = True, extra: dict | None = None) -> Path:
    """Three segments in two layers (as Slicer writes overlapping segments)."""
    data = np.zeros((2, 10, 9, 8), dtype=np.uint8)
    data[0, 1:5, 1:5, 1:4] = 1  # liver, layer 0, value 1
    data[0, 6:9, 6:8, 4:7] = 2  # spleen, layer 0, value 2
    data[1, 3:7, 3:6, 2:5] = 1  # tumour, layer 1, value 1: overlaps the liver
    affine = _oblique_affine()
    directions = np.vstack([np.full(3, np.nan), affine[:3, :3].T])
    header = {
        "space": "left-posterior-superior",
        "space directions": directions,
        "space origin": affine[:3, 3],
        "kinds": ["list", "domain", "domain", "domain"],
        "encoding": "gzip",
        "Segmentation_MasterRepresentation": "Binary labelmap",
        "Segmentation_ContainedRepresentationNames": "Binary labelmap|",
        "Segmentation_ReferenceImageExtentOffset": "0 0 0",
        "Segment0_ID": "Segment_1",
        "Segment0_Name": "liver",
        "Segment0_Color": "0.866667 0.509804 0.396078",
        "Segment0_LabelValue": "1",
        "Segment0_Layer": "0",
        "Segment0_Extent": "1 4 1 4 1 3",
        "Segment1_ID": "Segment_2",
        "Segment1_Name": "spleen",
        "Segment1_Color": "0.615686 0.423529 0.635294",
        "Segment1_LabelValue": "2",
        "Segment1_Layer": "0",
        "Segment1_Extent": "6 8 6 7 4 6",
        "Segment2_ID": "Segment_3",
        "Segment2_Name": "tumour",
        "Segment2_Color": "1 1 0",
        "Segment2_LabelValue": "1",
        "Segment2_Layer": "1",
        "Segment2_Extent": "3 6 3 5 2 4",
        **(extra or {}),
    }
    if not four_d:
        data = data[:1]
        header.update({"space directions": affine[:3, :3].T, "kinds": ["domain"] * 3})
        for key in [k for k in header if k.startswith("Segment2_")]:
            del header[key]
    return _write(tmp_path / "case.seg.nrrd", data if four_d else data[0], header)


def test_segmentation_layers_are_flattened_later_layer_wins(tmp_path: Path, caplog) -> None:
    path = _segmentation(tmp_path)
    with caplog.at_level(logging.WARNING, logger="slicerecon.io.nrrd"):
        label_map = read_nrrd_label_map(path)
    assert "share label values" in caplog.text
    assert "overlap on 8 voxels" in caplog.text  # liver ∩ tumour: 2 x 2 x 2
    assert [(s.value, s.name, s.colour) for s in label_map.structures] == [
        (1, "liver", (221, 130, 101)),
        (2, "spleen", (157, 108, 162)),
        (3, "tumour", (255, 255, 0)),
    ]
    liver = np.zeros((10, 9, 8), bool)
    liver[1:5, 1:5, 1:4] = True
    tumour = np.zeros_like(liver)
    tumour[3:7, 3:6, 2:5] = True
    assert int(np.count_nonzero(liver & tumour)) == 8
    np.testing.assert_array_equal(label_map.labels == 3, tumour)
    np.testing.assert_array_equal(label_map.labels == 1, liver & ~tumour)
    assert int(np.count_nonzero(label_map.labels == 2)) == 3 * 2 * 3
    assert label_map.coordinates == "LPS"
    np.testing.assert_allclose(label_map.affine, _oblique_affine(), atol=1e-12)


def test_unique_label_values_are_kept(tmp_path: Path) -> None:
    path = _segmentation(tmp_path, extra={"Segment2_LabelValue": "7"})
    data, header = nrrd.read(str(path))
    data[1][data[1] == 1] = 7
    _write(path, data, header)
    label_map = read_nrrd_label_map(path)
    assert [(s.value, s.name) for s in label_map.structures] == [
        (1, "liver"),
        (2, "spleen"),
        (7, "tumour"),
    ]


def test_three_d_segmentation_keeps_label_values(tmp_path: Path) -> None:
    label_map = read_label_map(_segmentation(tmp_path, four_d=False))
    assert [(s.value, s.name) for s in label_map.structures] == [(1, "liver"), (2, "spleen")]


def test_zero_and_empty_segments_are_skipped_with_a_warning(tmp_path: Path, caplog) -> None:
    extra = {
        "Segment3_ID": "bg",
        "Segment3_Name": "background",
        "Segment3_LabelValue": "0",
        "Segment3_Layer": "0",
        "Segment4_ID": "e",
        "Segment4_Name": "empty",
        "Segment4_LabelValue": "9",
        "Segment4_Layer": "1",
        "Segment4_Extent": "0 -1 0 -1 0 -1",
    }
    with caplog.at_level(logging.WARNING, logger="slicerecon.io.nrrd"):
        label_map = read_nrrd_label_map(_segmentation(tmp_path, extra=extra))
    assert "segment 3 (background) has label value 0" in caplog.text
    assert "segment 4 (empty) holds no voxel" in caplog.text
    assert [s.name for s in label_map.structures] == ["liver", "spleen", "tumour"]


def test_voxels_outside_a_segments_extent_are_left_out_with_a_warning(
    tmp_path: Path, caplog
) -> None:
    """As 3D Slicer does, but never silently: the warning says how many voxels."""
    path = _segmentation(tmp_path, four_d=False, extra={"Segment0_Extent": "1 2 1 4 1 3"})
    with caplog.at_level(logging.WARNING, logger="slicerecon.io.nrrd"):
        label_map = read_nrrd_label_map(path)
    assert int(np.count_nonzero(label_map.labels == 1)) == 2 * 4 * 3
    assert "24 of the 48 voxels of segment 0 (liver) lie outside its extent" in caplog.text


def test_a_segment_its_extent_excludes_is_reported(tmp_path: Path, caplog) -> None:
    path = _segmentation(tmp_path, four_d=False, extra={"Segment0_Extent": "0 0 0 0 0 0"})
    with caplog.at_level(logging.WARNING, logger="slicerecon.io.nrrd"):
        label_map = read_nrrd_label_map(path)
    assert [s.name for s in label_map.structures] == ["spleen"]
    assert "all of the 48 voxels of segment 0 (liver) lie outside its extent" in caplog.text
    assert "the segment is skipped" in caplog.text


@pytest.mark.parametrize(
    ("extra", "drop", "four_d", "match"),
    [
        # a LabelValue the voxels lack, while the voxels of its value belong to no segment
        ({"Segment1_LabelValue": "5"}, (), False, r"segment 1 \(spleen\) claims label value 5"),
        # no LabelValue: 1 is assumed, as Slicer does, and the liver has 1 already
        ({}, ("Segment1_LabelValue",), False, "LabelValue is missing: 1 is assumed"),
        # the tumour said to be in layer 0, where the liver has its value
        ({"Segment2_Layer": "0"}, (), True, "both claim label value 1 of layer 0"),
        # the tumour (value 7 in layer 1) said to be in layer 0: its voxels are unclaimed
        ({"Segment2_Layer": "0", "Segment2_LabelValue": "7"}, (), True, "layer 1: 1"),
    ],
    ids=["label-value-absent", "label-value-missing", "layer-collides", "layer-wrong"],
)
def test_segments_that_cannot_match_the_voxels_are_refused(
    tmp_path: Path, extra: dict, drop: tuple, four_d: bool, match: str
) -> None:
    path = _segmentation(tmp_path, four_d=four_d, extra=extra)
    if drop:
        data, header = nrrd.read(str(path))
        for key in drop:
            del header[key]
        _write(path, data, header)
    with pytest.raises(FormatError, match=match):
        read_nrrd_label_map(path)
    assert main(["run", str(path), "-o", str(tmp_path / "out")]) == 2
    assert main(["info", str(path)]) == 2  # info reads the voxels too: it agrees with run


def test_values_no_segment_claims_are_ignored_with_a_warning(tmp_path: Path, caplog) -> None:
    path = _segmentation(tmp_path, four_d=False)
    data, header = nrrd.read(str(path))
    data[0, 0, 0] = 42
    _write(path, data, header)
    with caplog.at_level(logging.WARNING, logger="slicerecon.io.nrrd"):
        label_map = read_nrrd_label_map(path)
    assert "values no segment claims (42)" in caplog.text
    assert label_map.labels[0, 0, 0] == 0


def test_load_input_picks_a_segment_by_name_or_value_or_takes_the_union(tmp_path: Path) -> None:
    path = _segmentation(tmp_path)
    union = load_input(path, union=True)
    assert union.mask.sum() == np.count_nonzero(read_nrrd_label_map(path).labels)
    tumour = load_input(path, label="Tumour")
    assert tumour.mask.sum() == 4 * 3 * 3
    assert load_input(path, label=3).mask.sum() == tumour.mask.sum()
    assert load_input(path, roi="spleen").mask.sum() == 18
    with pytest.raises(LabelError, match="1: liver, 2: spleen, 3: tumour"):
        load_input(path, label="kidney")


def test_plain_label_map_names_structures_by_value_only(tmp_path: Path) -> None:
    path = _write(tmp_path / "l.nrrd", _labels(), _space_header(np.eye(4)))
    assert load_input(path, label="2").mask.sum() == 3 * 2 * 4
    with pytest.raises(LabelError, match="numbers, not names"):
        load_input(path, label="liver")
    with pytest.raises(LabelError, match="is not in"):
        load_input(path, label=4)


def test_describe_lists_every_segment_with_name_and_colour(tmp_path: Path) -> None:
    details = describe_input(_segmentation(tmp_path))
    assert details["format"] == "nrrd" and details["coordinates"] == "LPS"
    assert [(s["value"], s["name"], s["colour"]) for s in details["structures"]] == [
        (1, "liver", [221, 130, 101]),
        (2, "spleen", [157, 108, 162]),
        (3, "tumour", [255, 255, 0]),
    ]
    assert [(s["name"], s["layer"], s["label_value"]) for s in details["segments"]] == [
        ("liver", 0, 1),
        ("spleen", 0, 2),
        ("tumour", 1, 1),
    ]
    json.dumps(details)


# --------------------------------------------------------------------------- writing


@pytest.mark.parametrize("coordinates", ["RAS", "LPS"])
def test_seg_nrrd_round_trip(tmp_path: Path, coordinates: str) -> None:
    labels = _labels().astype(np.int16)
    affine = _oblique_affine()
    structures = [
        Structure(1, "left kidney", (200, 10, 30)),
        Structure(2, "spleen", (0, 0, 255)),
        Structure(5, "GTV", (1, 2, 3)),
    ]
    path = write_seg_nrrd(
        labels, affine, structures, tmp_path / "out" / "labels.seg.nrrd", coordinates=coordinates
    )
    assert [p.name for p in path.parent.iterdir()] == ["labels.seg.nrrd"]  # no temp left
    back = read_nrrd_label_map(path)
    np.testing.assert_array_equal(back.labels, labels)
    assert back.structures == tuple(structures)
    assert back.coordinates == "LPS"  # written as Slicer writes: LPS
    expected = LPS_TO_RAS @ affine if coordinates == "RAS" else affine
    np.testing.assert_allclose(back.affine, expected, rtol=0, atol=1e-12)


def test_seg_nrrd_header_is_what_slicer_writes(tmp_path: Path) -> None:
    labels = _labels()
    path = write_seg_nrrd(
        labels,
        np.eye(4),
        [Structure(1, "a", (255, 0, 0)), Structure(2)],
        tmp_path / "labels.seg.nrrd",
        coordinates="RAS",
    )
    header = nrrd.read_header(str(path))
    assert header["dimension"] == 3 and header["space"] == "left-posterior-superior"
    assert header["kinds"] == ["domain"] * 3 and header["encoding"] == "gzip"
    np.testing.assert_array_equal(header["space directions"], np.diag([-1.0, -1.0, 1.0]))
    assert header["Segmentation_MasterRepresentation"] == "Binary labelmap"
    assert header["Segmentation_ContainedRepresentationNames"] == "Binary labelmap|"
    assert header["Segmentation_ReferenceImageExtentOffset"] == "0 0 0"
    assert header["Segment0_ID"] == "Segment_1" and header["Segment0_Name"] == "a"
    assert header["Segment0_Color"] == "1 0 0" and header["Segment0_ColorAutoGenerated"] == "0"
    assert header["Segment0_LabelValue"] == "1" and header["Segment0_Layer"] == "0"
    assert header["Segment0_Extent"] == "1 3 2 5 1 2"
    assert "Segment0_Tags" in header
    # an unnamed structure, and the value 5 that no structure names
    assert header["Segment1_Name"] == "Segment_2" and header["Segment1_NameAutoGenerated"] == "1"
    assert header["Segment1_ColorAutoGenerated"] == "1"
    assert header["Segment2_LabelValue"] == "5" and header["Segment2_Extent"] == "4 4 6 6 5 5"


def test_seg_nrrd_empty_structure_is_an_empty_segment(tmp_path: Path, caplog) -> None:
    path = write_seg_nrrd(
        _labels(),
        np.eye(4),
        [Structure(1), Structure(2), Structure(5), Structure(9, "missed")],
        tmp_path / "labels.seg.nrrd",
    )
    assert nrrd.read_header(str(path))["Segment3_Extent"] == "0 -1 0 -1 0 -1"
    with caplog.at_level(logging.WARNING, logger="slicerecon.io.nrrd"):
        back = read_nrrd_label_map(path)
    assert "segment 3 (missed) holds no voxel" in caplog.text
    assert [s.value for s in back.structures] == [1, 2, 5]


def test_seg_nrrd_opens_in_itk_with_the_geometry_slicer_sees(tmp_path: Path) -> None:
    """Slicer reads .seg.nrrd through ITK's NRRD reader: same grid, LPS, and every field."""
    itk = pytest.importorskip("itk")
    affine = _oblique_affine()
    labels = _labels()
    path = write_seg_nrrd(
        labels,
        affine,
        [Structure(1, "a"), Structure(2, "b"), Structure(5, "c")],
        tmp_path / "labels.seg.nrrd",
        coordinates="RAS",
    )
    image = itk.imread(str(path))
    lps = LPS_TO_RAS @ affine
    spacing = np.linalg.norm(lps[:3, :3], axis=0)
    np.testing.assert_allclose(np.asarray(itk.origin(image)), lps[:3, 3], atol=1e-9)
    np.testing.assert_allclose(np.asarray(itk.spacing(image)), spacing, rtol=1e-12)
    np.testing.assert_allclose(
        itk.array_from_matrix(image.GetDirection()), lps[:3, :3] / spacing, atol=1e-12
    )
    np.testing.assert_array_equal(itk.array_view_from_image(image).T, labels)
    keys = set(image.GetMetaDataDictionary().GetKeys())
    assert {
        "Segment2_Name",
        "Segment2_LabelValue",
        "Segment2_Extent",
        "Segmentation_MasterRepresentation",
    } <= keys


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"path": "labels.nii.gz"}, "seg.nrrd"),
        ({"coordinates": "RAI"}, "RAS"),
        ({"labels": np.zeros((3, 3), np.uint8)}, "3-D .*integer"),
        ({"labels": np.zeros((3, 3, 3), np.float32)}, "3-D .*integer"),
        ({"labels": np.ones((2, 3, 3, 3), np.uint8)}, "lies in layers 0 and 1"),
        ({"structures": [Structure(1), Structure(1)]}, "distinct"),
    ],
)
def test_seg_nrrd_writer_refuses_bad_arguments(tmp_path: Path, kwargs: dict, match: str) -> None:
    arguments = {
        "labels": _labels(),
        "affine": np.eye(4),
        "structures": [Structure(1)],
        "path": "labels.seg.nrrd",
        "coordinates": "RAS",
        **kwargs,
    }
    arguments["path"] = tmp_path / arguments["path"]
    with pytest.raises(OptionError, match=match):
        write_seg_nrrd(
            arguments.pop("labels"),
            arguments.pop("affine"),
            arguments.pop("structures"),
            arguments.pop("path"),
            **arguments,
        )


def test_names_round_trip_in_utf8_as_slicer_writes_them(tmp_path: Path) -> None:
    """Slicer writes key/value pairs in UTF-8; newlines and backslashes escaped (NRRD spec)."""
    structures = [
        Structure(1, "Tête fémorale", (200, 10, 30)),
        Structure(2, "two\nlines \\ and a backslash"),
        Structure(5, ""),
    ]
    path = write_seg_nrrd(_labels(), np.eye(4), structures, tmp_path / "labels.seg.nrrd")
    header = path.read_bytes().split(b"\n\n", 1)[0]
    assert "Segment0_Name:=Tête fémorale\n".encode() in header
    assert b"Segment1_Name:=two\\nlines \\\\ and a backslash\n" in header
    assert b"Segment2_Name:=Segment_5\n" in header  # the one name of an unnamed structure
    back = read_nrrd_label_map(path)
    assert [s.name for s in back.structures] == [
        "Tête fémorale",
        "two\nlines \\ and a backslash",
        "Segment_5",
    ]
    np.testing.assert_array_equal(back.labels, _labels())
    itk = pytest.importorskip("itk")  # what Slicer reads the file with
    image = itk.imread(str(path))  # keep the image: its dictionary dies with it
    assert image.GetMetaDataDictionary()["Segment0_Name"] == "Tête fémorale"


# --------------------------------------------------------------------------- clear errors


def test_declared_grid_over_budget_is_refused_before_reading(tmp_path: Path) -> None:
    path = _raw_file(
        tmp_path / "huge.nrrd",
        [
            "type: unsigned char",
            "dimension: 3",
            "sizes: 4096 4096 4096",
            "encoding: raw",
            "space: left-posterior-superior",
            "space directions: (1,0,0) (0,1,0) (0,0,1)",
        ],
    )
    with pytest.raises(MemoryBudgetError, match="4096 x 4096 x 4096"):
        load_input(path)


def test_more_data_than_declared_is_refused_without_expanding_it(tmp_path: Path) -> None:
    bomb = gzip.compress(bytes(64 * 2**20))  # 64 MiB of zeros in ~64 KiB
    path = _raw_file(
        tmp_path / "bomb.nrrd",
        ["type: unsigned char", "dimension: 3", "sizes: 4 4 4", "encoding: gzip"],
        bomb,
    )
    with pytest.raises(FormatError, match="more voxel data than its header declares"):
        read_nrrd_label_map(path)


def _peak_mib(function) -> float:
    """Peak Python-allocated memory while ``function()`` runs (it must raise), MiB."""
    import tracemalloc

    tracemalloc.start()
    try:
        function()
    except Exception:  # noqa: BLE001 - the caller checks the error itself
        pass
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    return peak / 2**20


@pytest.mark.parametrize("encoding", ["gzip", "bzip2"])
def test_byte_skip_minus_one_does_not_bypass_the_decompression_bound(
    tmp_path: Path, encoding: str
) -> None:
    """``byte skip: -1`` (the data are the last bytes of the stream) used to let pynrrd
    inflate everything: a 64 kB gzip file took 3 GB. The stream may now hold at most
    twice the declared data."""
    zeros = bytes(64 * 2**20)
    body = gzip.compress(zeros, compresslevel=1) if encoding == "gzip" else bz2.compress(zeros)
    assert len(body) < 300_000
    path = _raw_file(
        tmp_path / "bomb.nrrd",
        [
            "type: unsigned char",
            "dimension: 3",
            "sizes: 4 4 4",
            f"encoding: {encoding}",
            "byte skip: -1",
        ],
        body,
    )
    with pytest.raises(FormatError, match="more voxel data than its header declares"):
        read_nrrd_label_map(path)
    assert _peak_mib(lambda: read_nrrd_label_map(path)) < 32


def test_byte_skip_minus_one_reads_the_last_bytes(tmp_path: Path) -> None:
    labels = _labels()
    data = np.ascontiguousarray(labels.T).tobytes()
    for encoding, compress in (("gzip", gzip.compress), ("bzip2", bz2.compress), ("raw", bytes)):
        path = _raw_file(
            tmp_path / f"{encoding}.nrrd",
            [
                "type: unsigned char",
                "dimension: 3",
                "sizes: 9 8 7",
                f"encoding: {encoding}",
                "byte skip: -1",
            ],
            compress(b"a prefix of 23 bytes...." + data),
        )
        np.testing.assert_array_equal(read_nrrd_label_map(path).labels, labels)


def test_byte_skip_counts_against_the_memory_budget(tmp_path: Path) -> None:
    path = _raw_file(
        tmp_path / "skip.nrrd",
        [
            "type: unsigned char",
            "dimension: 3",
            "sizes: 4 4 4",
            "encoding: gzip",
            f"byte skip: {2**40}",
        ],
        gzip.compress(bytes(64)),
    )
    with pytest.raises(MemoryBudgetError, match="byte skip"):
        read_nrrd_label_map(path, memory_budget_gb=0.5)
    raw = _raw_file(
        tmp_path / "raw.nrrd",
        [
            "type: unsigned char",
            "dimension: 3",
            "sizes: 4 4 4",
            "encoding: raw",
            f"byte skip: {10**30}",
        ],
        bytes(64),
    )
    with pytest.raises(FormatError, match="truncated"):
        read_nrrd_label_map(raw)


@pytest.mark.parametrize("line_skip", ["1000000000", "1" * 31, "-3"])
def test_absurd_line_skip_is_refused_at_once(tmp_path: Path, line_skip: str) -> None:
    """``line skip: N`` cost N readline() calls: 1e9 took a quarter of an hour."""
    import time

    path = _raw_file(
        tmp_path / "lines.nrrd",
        [
            "type: unsigned char",
            "dimension: 3",
            "sizes: 4 4 4",
            "encoding: raw",
            f"line skip: {line_skip}",
        ],
        b"one line\n" * 1000 + bytes(64),
    )
    start = time.perf_counter()
    with pytest.raises(FormatError, match="line skip"):
        read_nrrd_label_map(path)
    assert time.perf_counter() - start < 1.0


def test_line_skip_skips_lines(tmp_path: Path) -> None:
    labels = _labels()
    path = _raw_file(
        tmp_path / "lines.nrrd",
        ["type: unsigned char", "dimension: 3", "sizes: 9 8 7", "encoding: gzip", "line skip: 2"],
        b"first\nsecond\n" + gzip.compress(np.ascontiguousarray(labels.T).tobytes()),
    )
    np.testing.assert_array_equal(read_nrrd_label_map(path).labels, labels)


@pytest.mark.parametrize("compress", [gzip.compress, bz2.compress, None])
def test_truncated_data_is_a_format_error(tmp_path: Path, compress) -> None:
    data = bytes(range(60))
    encoding = {gzip.compress: "gzip", bz2.compress: "bzip2", None: "raw"}[compress]
    body = data if compress is None else compress(data)
    path = _raw_file(
        tmp_path / "short.nrrd",
        ["type: unsigned char", "dimension: 3", "sizes: 4 4 4", f"encoding: {encoding}"],
        body if compress is None else body[: len(body) // 2],
    )
    with pytest.raises(FormatError):
        load_input(path)


@pytest.mark.parametrize(
    ("lines", "error", "match"),
    [
        (
            ["type: unsigned char", "dimension: 2", "sizes: 4 4", "encoding: raw"],
            InputError,
            "2-D NRRD",
        ),
        (
            ["type: float", "dimension: 3", "sizes: 1 1 2", "encoding: ascii"],
            LabelError,
            "non-integer",
        ),
        (
            ["type: block", "block size: 2", "dimension: 3", "sizes: 1 1 1", "encoding: raw"],
            LabelError,
            "not a label map",
        ),
        (["type: short", "dimension: 3", "sizes: 1 1 1", "encoding: raw"], FormatError, "endian"),
        (
            [
                "type: unsigned char",
                "dimension: 3",
                "sizes: 1 1 1",
                "encoding: raw",
                "space: left-posterior-superior",
                "space directions: (1e300,0,0) (0,1,0) (0,0,1)",
            ],
            GeometryError,
            "corrupt",
        ),
        (
            [
                "type: unsigned char",
                "dimension: 3",
                "sizes: 1 1 1",
                "encoding: raw",
                "space: left-posterior-superior",
                "space directions: (0.00000001,0,0) (0,1,0) (0,0,1)",
            ],
            GeometryError,
            "spacing",
        ),
        (
            [
                "type: unsigned char",
                "dimension: 3",
                "sizes: 1 1 1",
                "encoding: raw",
                "space: right-anterior-superior-time",
                "space directions: (1,0,0,0) (0,1,0,0) (0,0,1,0)",
            ],
            GeometryError,
            "not a 3-D space",
        ),
        (
            [
                "type: unsigned char",
                "dimension: 3",
                "sizes: 1 1 1",
                "encoding: raw",
                "space: left-posterior-superior",
                "space directions: (1,0,0) (0,1,0) (0,0,1)",
                'space units: "furlong" "mm" "mm"',
            ],
            GeometryError,
            "space units",
        ),
        (
            [
                "type: unsigned char",
                "dimension: 3",
                "sizes: 1 1 1",
                "encoding: raw",
                "data file: /etc/hostname",
            ],
            FormatError,
            "separate file",
        ),
        (
            [
                "type: unsigned char",
                "dimension: 4",
                "sizes: 2 1 1 1",
                "encoding: raw",
                "kinds: domain domain domain domain",
            ],
            FormatError,
            "list",
        ),
        (
            [
                "type: unsigned char",
                "dimension: 4",
                "sizes: 2 1 1 1",
                "encoding: raw",
                "kinds: list domain domain domain",
            ],
            InputError,
            "holding 2 volumes",
        ),
        (
            [
                "type: unsigned char",
                "dimension: 3",
                "sizes: 1 1 1",
                "encoding: raw",
                "Segment0_ID:=a",
                "Segment0_Layer:=1",
            ],
            FormatError,
            "Segment0_Layer is 1",
        ),
        (
            [
                "type: unsigned char",
                "dimension: 3",
                "sizes: 1 1 1",
                "encoding: raw",
                "Segment0_ID:=a",
                "Segment0_Extent:=0 1 2",
            ],
            FormatError,
            "Segment0_Extent",
        ),
        (
            [
                "type: unsigned char",
                "dimension: 3",
                "sizes: 1 1 1",
                "encoding: raw",
                "Segment0_ID:=a",
                "Segment0_LabelValue:=one",
            ],
            FormatError,
            "Segment0_LabelValue",
        ),
        (
            ["type: unsigned char", "dimension: 3", "sizes: 1 1 1", "encoding: rot13"],
            FormatError,
            "cannot read",
        ),
        (
            ["type: unsigned char", "dimension: 3", "sizes: 1 1", "encoding: raw"],
            FormatError,
            "sizes",
        ),
        (
            [
                "type: unsigned char",
                "dimension: 3",
                "sizes: 1 1 1",
                "encoding: raw",
                "space: left-posterior-superior",
                "space directions: (1,0,0) (0,1,0)",
            ],
            GeometryError,
            "lists 2 vectors for a 3-D image",
        ),
        (
            [
                "type: unsigned char",
                "dimension: 4",
                "sizes: 2 1 1 1",
                "encoding: raw",
                "space: left-posterior-superior",
                "space directions: none (1,0,0) (0,1,0)",
                "Segment0_ID:=a",
            ],
            GeometryError,
            "lists 3 vectors for a 4-D image",
        ),
        (
            [
                "type: unsigned char",
                "dimension: 3",
                "sizes: 1 1 1",
                "encoding: raw",
                "Segment0_ID:=a",
                "Segment0_LabelValue:=99999999999999999999",
            ],
            FormatError,
            "Segment0_LabelValue must be a voxel value",
        ),
    ],
)
def test_bad_headers_give_one_clear_error(
    tmp_path: Path, lines: list[str], error: type, match: str
) -> None:
    data = b"0.5 1\n" if "type: float" in lines else bytes(2)
    path = _raw_file(tmp_path / "bad.nrrd", lines, data)
    with pytest.raises(error, match=match):
        load_input(path)
    # info describes a float image's grid and says it is no label map, as for a CT
    assert main(["info", str(path)]) == (0 if match == "non-integer" else 2)


def test_not_nrrd_and_empty_files(tmp_path: Path) -> None:
    fake = tmp_path / "fake.nrrd"
    fake.write_bytes(b"\x89PNG\r\n" + bytes(100))
    with pytest.raises(FormatError, match="not a NRRD file"):
        load_input(fake)
    with pytest.raises(InputError, match="not found"):
        read_nrrd_label_map(tmp_path / "missing.nrrd")
    empty = _write(tmp_path / "zero.nrrd", np.zeros((3, 3, 3), np.uint8), _space_header(np.eye(4)))
    with pytest.raises(EmptyMaskError):
        load_input(empty)
    with pytest.raises(EmptyMaskError):
        read_label_map(empty)
    assert describe_input(empty)["structures"] == []  # info never refuses


# --------------------------------------------------------------------------- ITK MCI examples
# ITK's morphological contour interpolation ships examples/SevenLabels.nrrd (seven labels
# annotated on two planes) and examples/ManyToMany.nrrd (one label whose blobs correspond
# many-to-many between two planes). They are not in the itk-morphologicalcontourinterpolation
# wheel, so these are synthetic equivalents written as ITK writes them (unsigned char, LPS).


def _ellipse(cx: float, cy: float, rx: float, ry: float) -> np.ndarray:
    x, y = np.meshgrid(np.arange(48), np.arange(48), indexing="ij")
    return ((x - cx) / rx) ** 2 + ((y - cy) / ry) ** 2 <= 1.0


PLANES = (3, 14)
MCI_HEADER = {
    "space": "left-posterior-superior",
    "space directions": np.diag([0.6, 0.6, 1.5]),
    "space origin": np.array([-14.0, -14.0, 2.0]),
    "kinds": ["domain"] * 3,
    "encoding": "gzip",
}


@pytest.fixture(scope="module")
def mci_examples(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("mci")
    seven = np.zeros((48, 48, 18), np.uint8)
    centres = [(10, 10), (24, 10), (38, 10), (10, 24), (38, 24), (10, 38), (31, 38)]
    for value, (cx, cy) in enumerate(centres, start=1):
        seven[:, :, PLANES[0]][_ellipse(cx, cy, 5, 4)] = value
        seven[:, :, PLANES[1]][_ellipse(cx + 1, cy + 1, 4, 5.5)] = value
    many = np.zeros((48, 48, 18), np.uint8)  # two bars across, then two bars along:
    many[:, :, PLANES[0]][_ellipse(24, 15, 17, 4.5) | _ellipse(24, 33, 17, 4.5)] = 1
    many[:, :, PLANES[1]][_ellipse(15, 24, 4.5, 17) | _ellipse(33, 24, 4.5, 17)] = 1
    return {
        "SevenLabels": _write(root / "SevenLabels.nrrd", seven, MCI_HEADER),
        "ManyToMany": _write(root / "ManyToMany.nrrd", many, MCI_HEADER),
    }


def _run_meshes(path: Path, out: Path) -> list[trimesh.Trimesh]:
    assert main(["run", str(path), "-o", str(out)]) == 0
    written = nib.load(out / "labels.nii.gz")
    assert written.shape == (48, 48, 18)
    np.testing.assert_allclose(
        written.affine,
        LPS_TO_RAS
        @ np.array([[0.6, 0, 0, -14.0], [0, 0.6, 0, -14.0], [0, 0, 1.5, 2.0], [0, 0, 0, 1]]),
        atol=1e-6,
    )
    files = sorted((out / "meshes").glob("*.stl")) or [out / "mesh.stl"]
    return [trimesh.load(f) for f in files]


@pytest.mark.parametrize(("name", "count"), [("SevenLabels", 7), ("ManyToMany", 1)])
def test_mci_examples_reconstruct(
    mci_examples: dict[str, Path], tmp_path: Path, name: str, count: int
) -> None:
    meshes = _run_meshes(mci_examples[name], tmp_path / name)
    assert len(meshes) == count
    for mesh in meshes:
        assert mesh.is_watertight and mesh.volume > 0
        # in LPS mm, spanning both annotated planes
        lo, hi = mesh.bounds[:, 2]
        assert lo <= 2.0 + 1.5 * PLANES[0] and hi >= 2.0 + 1.5 * PLANES[1]


@pytest.mark.parametrize("name", ["SevenLabels", "ManyToMany"])
def test_mci_examples_are_interpolated_between_the_planes(
    mci_examples: dict[str, Path], tmp_path: Path, name: str
) -> None:
    for mesh in _run_meshes(mci_examples[name], tmp_path / name):
        assert len(mesh.split(only_watertight=False)) == 1  # one body, not two slabs
        middle = 2.0 + 1.5 * (PLANES[0] + PLANES[1]) / 2
        section = mesh.section(plane_origin=[0, 0, middle], plane_normal=[0, 0, 1])
        assert section is not None  # the surface crosses the mid-plane


def test_layered_segmentation_keeps_nested_segments_whole(tmp_path: Path) -> None:
    """Segments that overlap go to separate layers (a 4-D file, as 3D Slicer writes it)
    and come back whole; flattening gives the later layer the shared voxels."""
    from slicerecon.io.nrrd import read_nrrd_masks

    r = np.linalg.norm(np.mgrid[:24, :24, :24] - 11.5, axis=0)
    outer, inner = r < 10, r < 5
    layers = np.stack([np.where(outer, 1, 0), np.where(inner, 2, 0)]).astype(np.uint8)
    path = write_seg_nrrd(
        layers, np.eye(4), [Structure(1, "Body"), Structure(2, "Tumour")], tmp_path / "n.seg.nrrd"
    )
    header = path.read_bytes()[:400].decode()
    assert "dimension: 4" in header and "kinds: list domain domain domain" in header
    masks = read_nrrd_masks(path)
    assert [s.name for s in masks.structures] == ["Body", "Tumour"]
    assert np.array_equal(masks.masks[0], outer) and np.array_equal(masks.masks[1], inner)
    flat = read_nrrd_label_map(path)
    assert np.count_nonzero(flat.labels == 1) == np.count_nonzero(outer & ~inner)


def test_a_written_segmentation_is_the_same_bytes_whatever_its_name(tmp_path: Path) -> None:
    """The gzip header held the temporary file's name: two identical runs wrote
    different labels.seg.nrrd bytes."""
    from slicerecon.io.nrrd_writer import write_seg_nrrd
    from slicerecon.labels import Structure

    labels = np.zeros((6, 5, 4), np.uint8)
    labels[1:4, 1:3, 1:3] = 2
    first = write_seg_nrrd(labels, np.eye(4), [Structure(2, "Liver")], tmp_path / "a.seg.nrrd")
    again = write_seg_nrrd(labels, np.eye(4), [Structure(2, "Liver")], tmp_path / "b.seg.nrrd")
    assert first.read_bytes() == again.read_bytes()
