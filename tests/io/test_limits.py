"""The reading boundary: one clear error, and no Python warnings line on stderr."""

from __future__ import annotations

import logging
import struct
import warnings
from pathlib import Path

import dicom_factory as factory  # tests/io, on pytest's pythonpath
import nibabel as nib
import numpy as np
import pydicom
import pytest

from slicerecon.cli import main
from slicerecon.errors import FormatError, MemoryBudgetError
from slicerecon.io.dicom.seg_writer import write_seg
from slicerecon.io.limits import reading, writing
from slicerecon.labels import Structure


def test_warnings_while_reading_become_log_records(tmp_path: Path, caplog) -> None:
    with warnings.catch_warnings(record=True) as escaped, caplog.at_level(logging.DEBUG):
        warnings.simplefilter("always")
        with reading(tmp_path / "scan.dcm"):
            warnings.warn("Invalid value for VR UI", UserWarning, stacklevel=1)
            warnings.warn("this API is deprecated", DeprecationWarning, stacklevel=1)
    assert escaped == []  # nothing reaches warnings.showwarning (stderr)
    records = {(r.levelname, r.getMessage()) for r in caplog.records}
    assert ("WARNING", f"{tmp_path / 'scan.dcm'}: Invalid value for VR UI") in records
    assert not any(level == "WARNING" and "deprecated" in text for level, text in records)


def test_warnings_before_a_failure_are_debug_records_only(tmp_path: Path, caplog) -> None:
    """The error line says what is wrong: the remarks before it are not repeated."""
    with caplog.at_level(logging.DEBUG), pytest.raises(FormatError, match="ValueError: bad"):
        with reading(tmp_path / "scan.dcm"):
            warnings.warn("Invalid value for VR UI", UserWarning, stacklevel=1)
            raise ValueError("bad")
    assert [r.levelname for r in caplog.records if "Invalid value" in r.getMessage()] == ["DEBUG"]


def test_a_refused_allocation_is_one_memory_error(tmp_path: Path) -> None:
    with pytest.raises(MemoryBudgetError, match="ran out of memory"), reading(tmp_path / "x"):
        raise MemoryError
    with pytest.raises(MemoryBudgetError, match="writing"), writing(tmp_path / "seg.dcm"):
        raise MemoryError


def test_what_nibabel_prints_itself_does_not_reach_stderr(tmp_path: Path, capfd, caplog) -> None:
    """nibabel logs header fixes through its own stderr handler ('sizeof_hdr should be 348')."""
    path = tmp_path / "ball.nii"
    mask = np.zeros((8, 8, 6), np.uint8)
    mask[2:6, 2:6, 1:5] = 1
    nib.save(nib.Nifti1Image(mask, np.diag([1.0, 1.0, 2.0, 1.0])), path)
    data = bytearray(path.read_bytes())
    data[0:4] = struct.pack("<i", 2**31 - 1)  # sizeof_hdr, which nibabel fixes and logs
    path.write_bytes(bytes(data))
    with caplog.at_level(logging.WARNING):
        assert main(["info", str(path)]) == 0
    # not nibabel's own line: ours, once, naming the file
    assert capfd.readouterr().err.splitlines() == [
        f"warning: {path}: sizeof_hdr should be 348; set sizeof_hdr to 348"
    ]
    assert "sizeof_hdr should be 348" in caplog.text
    assert nib.imageglobals.logger.handlers  # nibabel's own handler is given back


def test_a_malformed_frame_of_reference_uid_warns_nothing_while_pairing_files(
    tmp_path: Path,
) -> None:
    """Pairing an RTSTRUCT with its series peeks at FrameOfReferenceUIDs: pydicom checked
    a malformed one when its value was asked for, after the quiet header read, and its
    UserWarning reached stderr (the fuzzer, an RTSTRUCT folder with a mutated UID)."""
    study = tmp_path / "study"
    paths = factory.write_series(study, np.zeros((32, 32, 8), np.uint16), np.eye(4))
    items = [factory.contour_item(factory.circle(6, (15, 15), z)) for z in (2.0, 4.0, 6.0)]
    factory.write_rtstruct(study / "rs.dcm", {(1, "GTV"): items}, on_series=study)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # pydicom warns of the value this test means to write
        for path in [paths[0], study / "rs.dcm"]:
            ds = pydicom.dcmread(path)
            ds.FrameOfReferenceUID = "1.2.826.0.1\xa4\x9a.3"
            ds.save_as(path)
    with warnings.catch_warnings(record=True) as escaped:
        warnings.simplefilter("always")
        main(["run", str(study), "-o", str(tmp_path / "out")])
    assert not [w for w in escaped if "Invalid value" in str(w.message)]


def test_images_with_invalid_uids_are_refused_for_a_seg(tmp_path: Path) -> None:
    """pydicom warned (a stray stderr line) on copying 'ÿÿ' UIDs into seg.dcm."""
    affine = factory.affine_from_geometry([1, 0, 0], [0, 1, 0], [1.0, 1.0], [0, 0, 2.0], [0, 0, 0])
    labels = np.zeros((6, 5, 4), np.uint8)
    labels[1:4, 1:4, 1:3] = 1
    paths = factory.write_series(tmp_path / "ct", np.zeros(labels.shape), affine)
    ds = pydicom.dcmread(paths[2])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # pydicom warns of the value this test means to write
        ds.SOPInstanceUID = "1.2.826\xff\xff.1"
        ds.save_as(paths[2])
    with (
        warnings.catch_warnings(record=True) as escaped,
        pytest.raises(FormatError, match="invalid SOPInstanceUID"),
    ):
        warnings.simplefilter("always")
        write_seg(labels, affine, [Structure(1)], tmp_path / "ct", tmp_path / "seg.dcm")
    assert not [w for w in escaped if "Invalid value" in str(w.message)]
    assert not (tmp_path / "seg.dcm").exists()
