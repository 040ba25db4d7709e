"""The one DICOM sniffer: content, not names; what a file holds; the batch's view of it."""

from __future__ import annotations

import dicom_factory as factory  # tests/io, on pytest's pythonpath
import numpy as np
import pydicom
import pytest

from slicerecon.errors import FormatError
from slicerecon.io.dicom import (
    dicom_modality,
    dicom_role,
    is_dicom_file,
    object_kind,
    read_dicom_header,
)

AXIAL = factory.affine_from_geometry([1, 0, 0], [0, 1, 0], [1.0, 1.0], [0, 0, 2.0], [0, 0, 0])


@pytest.fixture
def files(tmp_path):
    """One file of each kind the sniffer tells apart."""
    mask = np.zeros((4, 4, 2), bool)
    mask[1:3, 1:3, :] = True
    image = factory.write_series(tmp_path / "series", mask, AXIAL)[0]
    seg = factory.write_seg(tmp_path / "seg.dcm", {1: mask}, AXIAL, labels={1: "A"})
    rtstruct = factory.write_rtstruct(tmp_path / "rs.dcm", {(1, "Ball"): None})
    bare = factory.write_rtstruct(tmp_path / "bare_rtstruct", {(1, "Ball"): None}, preamble=False)
    plan = tmp_path / "plan.dcm"
    ds = pydicom.dcmread(image)
    ds.Modality = "RTPLAN"
    ds.save_as(plan)
    garbage = tmp_path / "garbage.dcm"
    garbage.write_bytes(b"not dicom at all")
    notes = tmp_path / "notes.txt"
    notes.write_text("plain text")
    torn = tmp_path / "torn"  # the DICM marker, then an element pydicom cannot parse
    torn.write_bytes(bytes(128) + b"DICM" + b"\x02\x00\x10\x00ZZ\xff\xff" + b"x" * 20)
    return {
        "image": image,
        "seg": seg,
        "rtstruct": rtstruct,
        "bare": bare,
        "plan": plan,
        "garbage": garbage,
        "notes": notes,
        "torn": torn,
    }


def test_content_decides_not_the_name(files):
    assert is_dicom_file(files["image"]) and is_dicom_file(files["seg"])
    assert is_dicom_file(files["bare"])  # no preamble, no .dcm suffix
    assert files["bare"].read_bytes()[128:132] != b"DICM"
    assert not is_dicom_file(files["garbage"]) and not is_dicom_file(files["notes"])


def test_bare_dataset_is_read_with_force(files):
    ds = read_dicom_header(files["bare"])
    assert ds.Modality == "RTSTRUCT" and ds.StructureSetROISequence[0].ROIName == "Ball"
    with pytest.raises(FormatError, match="garbage.dcm"):
        read_dicom_header(files["garbage"])


@pytest.mark.parametrize(
    ("name", "kind", "modality", "role"),
    [
        ("image", "image", "MR", "image"),
        ("seg", "seg", "SEG", "seg"),
        ("rtstruct", "rtstruct", "RTSTRUCT", "rtstruct"),
        ("bare", "rtstruct", "RTSTRUCT", "rtstruct"),
        ("plan", "other", "RTPLAN", "other"),
    ],
)
def test_one_rule_for_readers_dispatcher_and_batch(files, name, kind, modality, role):
    assert object_kind(read_dicom_header(files[name])) == kind
    assert dicom_modality(files[name]) == modality
    assert dicom_role(files[name]) == role


@pytest.mark.filterwarnings("ignore:Expected implicit VR")  # pydicom, on the torn file
def test_what_is_not_dicom(files, tmp_path):
    assert dicom_modality(files["garbage"]) is None and dicom_modality(files["notes"]) is None
    assert dicom_modality(tmp_path) is None
    assert dicom_role(files["garbage"]) == "unreadable"  # named like DICOM: a failing case
    assert dicom_role(files["torn"]) == "unreadable"  # DICOM by content: a failing case
    assert dicom_modality(files["torn"]) is None
    assert dicom_role(files["notes"]) is None  # anything else is not the batch's business


@pytest.mark.filterwarnings("ignore:Expected implicit VR")  # pydicom, on the torn file
@pytest.mark.parametrize("name", ["garbage", "torn"])
def test_a_dcm_file_that_cannot_be_read_is_said_to_be_one(files, name, tmp_path, capsys):
    """A ``.dcm`` file that is not DICOM got "cannot tell the format ... expected
    .nii/.nii.gz, ..." as if its name were unknown."""
    from slicerecon.cli import main

    path = tmp_path / f"{name}.dcm"
    path.write_bytes(files[name].read_bytes())
    assert main(["run", str(path), "-o", str(tmp_path / "out")]) == 2
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(err) == 1 and "named like a DICOM file but is not one that can be read" in err[0]
