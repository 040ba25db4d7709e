"""One name per structure in every output, accents kept: .seg.nrrd, SEG, RTSTRUCT, file names."""

from __future__ import annotations

from pathlib import Path

import dicom_factory as factory  # tests/io, on pytest's pythonpath
import numpy as np
import pydicom
import pytest

from slicerecon.io.dicom.derived import dicom_name
from slicerecon.io.dicom.seg_writer import write_seg
from slicerecon.io.nrrd import read_nrrd_label_map
from slicerecon.io.nrrd_writer import write_seg_nrrd
from slicerecon.io.rtstruct import list_rois
from slicerecon.io.rtstruct_writer import write_rtstruct
from slicerecon.labels import Structure, structure_name


@pytest.fixture
def written(tmp_path: Path) -> dict[str, Path]:
    affine = factory.affine_from_geometry(
        [1, 0, 0], [0, 1, 0], [1.0, 1.0], [0, 0, 2.0], [-10.0, -8.0, 0.0]
    )
    labels = np.zeros((20, 16, 8), np.uint8)
    labels[2:8, 2:8, 1:5] = 1
    labels[10:18, 6:14, 2:7] = 2
    structures = [Structure(1, "Tête fémorale"), Structure(2, "")]
    factory.write_series(tmp_path / "ct", np.zeros(labels.shape), affine, modality="CT")
    return {
        "seg_nrrd": write_seg_nrrd(labels, affine, structures, tmp_path / "l.seg.nrrd"),
        "seg": write_seg(labels, affine, structures, tmp_path / "ct", tmp_path / "seg.dcm"),
        "rtstruct": write_rtstruct(
            labels, affine, structures, tmp_path / "ct", tmp_path / "rtstruct.dcm"
        ),
    }


def test_every_output_gives_a_structure_the_same_name(written: dict[str, Path]) -> None:
    """An unnamed structure is Segment_<value> everywhere (it was Structure 2 in DICOM)."""
    expected = ["Tête fémorale", "Segment_2"]
    assert [s.name for s in read_nrrd_label_map(written["seg_nrrd"]).structures] == expected
    seg = pydicom.dcmread(written["seg"])
    assert seg.SpecificCharacterSet == "ISO_IR 192"
    assert [str(item.SegmentLabel) for item in seg.SegmentSequence] == expected
    rtstruct = pydicom.dcmread(written["rtstruct"])
    assert rtstruct.SpecificCharacterSet == "ISO_IR 192"
    assert [name for _, name in list_rois(written["rtstruct"])] == expected


def test_the_name_bytes_are_utf8_in_every_file(written: dict[str, Path]) -> None:
    utf8 = "Tête fémorale".encode()
    for path in written.values():
        if path.suffix == ".nrrd":
            assert utf8 in path.read_bytes().split(b"\n\n", 1)[0]
        else:
            assert utf8 in path.read_bytes()


@pytest.mark.parametrize(
    ("name", "dicom"),
    [
        ("", "Segment_7"),
        ("  GTV  ", "GTV"),
        ("left\\right", "left/right"),  # a backslash separates DICOM values
        ("two\nlines\tand a tab", "two lines and a tab"),
        ("x" * 70, "x" * 64),  # LO holds 64 characters
    ],
)
def test_dicom_names_are_valid_long_strings(name: str, dicom: str) -> None:
    assert dicom_name(Structure(7, name)) == dicom
    assert structure_name(Structure(7, name)) == (name.strip() or "Segment_7")


@pytest.mark.parametrize(
    ("name", "label"),
    [
        ("Tête fémorale", "3_Tête_fémorale"),  # accents kept
        ("Te\u0302te", "3_Tête"),  # decomposed accents are composed (NFC): one file name
        ("a/b\\c:d", "3_a_b_c_d"),
        ("", "3"),
        ("é" * 300, "3_" + "é" * 48),
    ],
)
def test_file_names_keep_accents_and_stay_short(name: str, label: str) -> None:
    got = Structure(3, name).label
    assert got == label
    assert len((got + ".stl").encode()) < 255
