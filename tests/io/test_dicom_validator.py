"""The DICOM objects slicerecon writes pass dicom3tools' validator (``dciodvfy``).

``dciodvfy`` checks an object against its IOD: every module, every Type 1 and
Type 2 attribute, every value against its VR and character repertoire. Its
``Error`` lines are what a PACS or a planning system may refuse a file for
(``Warning`` lines are advice). The test is skipped where dicom3tools is not
installed (``apt-get install dicom3tools``; ``.ci/run`` installs it).
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import dicom_factory as factory  # tests/io, on pytest's pythonpath
import numpy as np
import pytest

from slicerecon.io.dicom.seg_writer import write_seg
from slicerecon.io.rtstruct_writer import write_rtstruct
from slicerecon.labels import Structure

DCIODVFY = shutil.which("dciodvfy")

pytestmark = pytest.mark.skipif(DCIODVFY is None, reason="dciodvfy (dicom3tools) is not installed")

STRUCTURES = [
    Structure(1, "Tête fémorale", (200, 10, 10)),  # not ASCII: written in UTF-8
    Structure(2, "GTV"),
    Structure(3, ""),  # unnamed: Segment_3
]


def _errors(path: Path) -> list[str]:
    """The ``Error`` lines dciodvfy prints for a file (it prints everything on stderr)."""
    assert DCIODVFY is not None
    done = subprocess.run([DCIODVFY, str(path)], capture_output=True, check=False, timeout=60)
    text = (done.stdout + done.stderr).decode("utf-8", "replace")
    return [line for line in text.splitlines() if line.startswith("Error")]


@pytest.fixture(params=["partition", "nested"])
def written(tmp_path: Path, request: pytest.FixtureRequest) -> dict[str, Path]:
    """A small synthetic CT, and an RTSTRUCT and a SEG of three structures written on it:
    a partition, or structure 2 nested in structure 1 (a layered label map)."""
    affine = factory.affine_from_geometry(
        [1, 0, 0], [0, 1, 0], [0.9, 0.9], [0, 0, 2.5], [-14.0, -10.5, 20.0]
    )
    labels = np.zeros((32, 24, 10), np.uint8)
    labels[3:10, 4:12, 2:6] = 1
    labels[15:25, 5:15, 3:8] = 2
    labels[20:28, 16:22, 1:4] = 3
    if request.param == "nested":
        outer = np.zeros(labels.shape, np.uint8)
        outer[2:30, 2:22, 1:9] = 1
        labels = np.stack([outer, np.where(labels == 1, 0, labels).astype(np.uint8)])
    series = tmp_path / "ct"
    factory.write_series(
        series, np.zeros(labels.shape[-3:]), affine, modality="CT", series_description="Pelvis"
    )
    return {
        "rtstruct": write_rtstruct(labels, affine, STRUCTURES, series, tmp_path / "rtstruct.dcm"),
        "seg": write_seg(labels, affine, STRUCTURES, series, tmp_path / "seg.dcm"),
    }


@pytest.mark.parametrize("output", ["rtstruct", "seg"])
def test_written_objects_have_no_validator_error(written: dict[str, Path], output: str) -> None:
    assert _errors(written[output]) == []


def test_the_validator_finds_errors_in_a_broken_object(
    written: dict[str, Path], tmp_path: Path
) -> None:
    """The check can fail: without its Frame of Reference module the RTSTRUCT is refused."""
    import pydicom

    ds = pydicom.dcmread(written["rtstruct"])
    del ds.FrameOfReferenceUID
    ds.save_as(tmp_path / "broken.dcm")
    assert any("FrameOfReferenceUID" in line for line in _errors(tmp_path / "broken.dcm"))
