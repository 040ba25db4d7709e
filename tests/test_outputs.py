"""What a run writes for a clinical workflow: label maps, a Slicer segmentation, SEG, RTSTRUCT."""

from __future__ import annotations

import json
import math
from pathlib import Path

import dicom_factory as factory  # tests/io, on pytest's pythonpath
import nibabel as nib
import numpy as np
import pytest

from slicerecon.cli import main
from slicerecon.io.nrrd import read_nrrd_label_map
from slicerecon.io.rtstruct import read_rtstruct_structures


def _ct(root: Path) -> np.ndarray:
    affine = factory.affine_from_geometry(
        [1, 0, 0], [0, 1, 0], [1.0, 1.0], [0, 0, 3.0], [-31.5, -23.5, 0.0]
    )
    factory.write_series(root, np.zeros((64, 48, 21), np.uint16), affine, modality="CT")
    return affine


def _rings(radius: float, centre: tuple[float, float], centre_z: float) -> list:
    zs = [3.0 * k for k in range(21) if k % 2 == 0]  # every other CT slice
    return [
        factory.contour_item(factory.circle(math.sqrt(radius**2 - (z - centre_z) ** 2), centre, z))
        for z in zs
        if abs(z - centre_z) < radius
    ]


def _nifti_labels(path: Path) -> tuple[np.ndarray, np.ndarray]:
    image = nib.load(path)
    return np.asarray(image.dataobj), image.affine


def test_rtstruct_beside_its_series_writes_seg_and_rtstruct_that_read_back(tmp_path: Path) -> None:
    _ct(tmp_path / "ct")
    factory.write_rtstruct(
        tmp_path / "ct" / "rs.dcm",
        {
            (3, "Left"): _rings(12.0, (-14.0, 0.0), 30.0),
            (7, "Right"): _rings(9.0, (15.0, 0.0), 27.0),
        },
        on_series=tmp_path / "ct",
    )
    out = tmp_path / "out"
    assert main(["run", str(tmp_path / "ct"), "-o", str(out), "-q"]) == 0
    for name in ("labels.nii.gz", "labels.seg.nrrd", "seg.dcm", "rtstruct.dcm"):
        assert (out / name).is_file(), name
    record = json.loads((out / "structures.json").read_text())
    assert record["outputs"]["skipped"] == {}
    labels, _ = _nifti_labels(out / "labels.nii.gz")
    voxel_mm3 = 1.0 * 1.0 * 3.0
    volumes = {v: float(np.count_nonzero(labels == v)) * voxel_mm3 for v in (3, 7)}
    assert min(volumes.values()) > 0

    # the DICOM SEG: highdicom reads the same segments, names and label values
    import highdicom as hd

    seg = hd.seg.segread(out / "seg.dcm")
    names = {seg.get_segment_description(n).SegmentLabel for n in seg.segment_numbers}
    assert names == {"Left", "Right"}
    import pydicom

    image = pydicom.dcmread(sorted((tmp_path / "ct").glob("slice_*.dcm"))[0])
    assert seg.FrameOfReferenceUID == image.FrameOfReferenceUID
    assert seg.ReferencedSeriesSequence[0].SeriesInstanceUID == image.SeriesInstanceUID

    # read back by slicerecon beside its series, the SEG keeps the label values and colours
    # of the map it was written from (it gave 1 and 2, without colours)
    back = tmp_path / "back"
    back.mkdir()
    for path in (tmp_path / "ct").glob("slice_*.dcm"):
        (back / path.name).write_bytes(path.read_bytes())
    coded = pydicom.dcmread(out / "seg.dcm")
    for item in coded.SegmentSequence:  # an input SEG that says what its segments are
        if item.SegmentLabel == "Left":
            item.SegmentedPropertyCategoryCodeSequence[0].CodeValue = "123037004"
            item.SegmentedPropertyCategoryCodeSequence[0].CodeMeaning = "Anatomical Structure"
            item.SegmentedPropertyTypeCodeSequence[0].CodeValue = "10200004"
            item.SegmentedPropertyTypeCodeSequence[0].CodeMeaning = "Liver"
    coded.save_as(back / "seg.dcm")
    assert main(["run", str(back), "-o", str(tmp_path / "again"), "-q"]) == 0
    # its seg.dcm keeps those codes (every segment was written "Tissue")
    kept = {
        item.SegmentLabel: item.SegmentedPropertyTypeCodeSequence[0].CodeMeaning
        for item in pydicom.dcmread(tmp_path / "again" / "seg.dcm").SegmentSequence
    }
    assert kept == {"Left": "Liver", "Right": "Tissue"}
    again = json.loads((tmp_path / "again" / "structures.json").read_text())["structures"]
    first = record["structures"]
    assert [(r["value"], r["name"], r["colour"]) for r in again] == [
        (r["value"], r["name"], r["colour"]) for r in first
    ]
    relabelled, _ = _nifti_labels(tmp_path / "again" / "labels.nii.gz")
    assert sorted(np.unique(relabelled)) == [0, 3, 7]

    # the RTSTRUCT: read back by slicerecon into the same structures (volumes within 2 %)
    structures, sections, _ = read_rtstruct_structures(
        out / "rtstruct.dcm", image_dir=tmp_path / "ct"
    )
    by_name = {s.name: (s, own) for s, own in zip(structures, sections, strict=True)}
    assert set(by_name) == {"Left", "Right"}
    for value, name in ((3, "Left"), (7, "Right")):
        structure, own = by_name[name]
        assert structure.value == value and own is not None
        thickness = abs(float(own.normal @ own.affine[:3, 2]))
        read_mm3 = sum(own.area_mm2(p) for p in range(own.n_planes)) * thickness
        assert read_mm3 == pytest.approx(volumes[value], rel=0.02)

    # the Slicer segmentation holds the same label map, names and values
    seg_nrrd = read_nrrd_label_map(out / "labels.seg.nrrd")
    assert {s.name for s in seg_nrrd.structures} == {"Left", "Right"}
    np.testing.assert_array_equal(np.sort(np.unique(seg_nrrd.labels)), [0, 3, 7])
    assert int(np.count_nonzero(seg_nrrd.labels == 3)) == int(np.count_nonzero(labels == 3))


def test_a_nifti_label_map_gets_a_slicer_segmentation_and_no_dicom(tmp_path: Path) -> None:
    i, j, k = np.ogrid[:40, :36, :30]
    labels = np.zeros((40, 36, 30), np.uint8)
    labels[(i - 12) ** 2 + (j - 18) ** 2 + (k - 15) ** 2 <= 64] = 2
    labels[(i - 28) ** 2 + (j - 18) ** 2 + (k - 15) ** 2 <= 49] = 5
    affine = np.diag([0.8, 0.8, 1.5, 1.0])
    path = tmp_path / "labels.nii.gz"
    nib.save(nib.Nifti1Image(labels, affine), str(path))
    out = tmp_path / "out"
    assert main(["run", str(path), "--slices", "8", "-o", str(out), "-q"]) == 0
    assert not (out / "seg.dcm").exists() and not (out / "rtstruct.dcm").exists()
    written, written_affine = _nifti_labels(out / "labels.nii.gz")
    seg_nrrd = read_nrrd_label_map(out / "labels.seg.nrrd")
    assert seg_nrrd.labels.shape == written.shape
    np.testing.assert_array_equal(np.sort(np.unique(seg_nrrd.labels)), [0, 2, 5])
    for value in (2, 5):
        assert int(np.count_nonzero(seg_nrrd.labels == value)) == int(
            np.count_nonzero(written == value)
        )
    # the same world geometry: the Slicer file is LPS, the NIfTI RAS
    ras = (
        np.diag([-1.0, -1.0, 1.0, 1.0]) @ seg_nrrd.affine
        if seg_nrrd.coordinates == "LPS"
        else seg_nrrd.affine
    )
    np.testing.assert_allclose(ras, written_affine, atol=1e-5)
    # the meshes are RAS, and say so as 3D Slicer reads it (untagged, it reads LPS: a
    # NIfTI's meshes came out mirrored in x and y there)
    for mesh in (out / "meshes").iterdir():
        assert mesh.read_bytes()[:80].rstrip() == b"SPACE=RAS"
    assert main(["run", str(path), "--format", "ply", "-o", str(tmp_path / "ply"), "-q"]) == 0
    header = (tmp_path / "ply" / "meshes" / "2.ply").read_bytes()[:200]
    assert b"\ncomment SPACE=RAS\n" in header


def test_non_ascii_names_survive_every_output_of_a_run(tmp_path: Path) -> None:
    """'Tête fémorale' crashed labels.seg.nrrd after the whole computation."""
    _ct(tmp_path / "ct")
    factory.write_rtstruct(
        tmp_path / "ct" / "rs.dcm",
        {
            (3, "Tête fémorale"): _rings(12.0, (-14.0, 0.0), 30.0),
            (7, "GTV"): _rings(9.0, (15.0, 0.0), 27.0),
        },
        on_series=tmp_path / "ct",
    )
    out = tmp_path / "out"
    assert main(["run", str(tmp_path / "ct"), "-o", str(out), "-q"]) == 0
    record = json.loads((out / "structures.json").read_text(encoding="utf-8"))
    assert record["outputs"]["skipped"] == {}
    assert {s["name"] for s in record["structures"]} == {"Tête fémorale", "GTV"}
    assert (out / "meshes" / "3_Tête_fémorale.stl").is_file()
    assert {s.name for s in read_nrrd_label_map(out / "labels.seg.nrrd").structures} == {
        "Tête fémorale",
        "GTV",
    }
    import pydicom

    seg = pydicom.dcmread(out / "seg.dcm")
    assert {str(s.SegmentLabel) for s in seg.SegmentSequence} == {"Tête fémorale", "GTV"}
    rt = pydicom.dcmread(out / "rtstruct.dcm")
    assert {str(r.ROIName) for r in rt.StructureSetROISequence} == {"Tête fémorale", "GTV"}


def test_an_roi_in_another_frame_of_reference_is_left_out_and_the_others_written(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """One ROI naming another FrameOfReferenceUID (registered from another study) was
    placed on the CT anyway (exit 0), and seg.dcm and rtstruct.dcm of every ROI were
    dropped with a warning blaming the whole RTSTRUCT. Now that ROI is left out in one
    line, refused when chosen, and the others keep their DICOM outputs."""
    import pydicom

    _ct(tmp_path / "ct")
    path = factory.write_rtstruct(
        tmp_path / "ct" / "rs.dcm",
        {
            (3, "Left"): _rings(12.0, (-14.0, 0.0), 30.0),
            (7, "GTV"): _rings(9.0, (15.0, 0.0), 27.0),
        },
        on_series=tmp_path / "ct",
    )
    ds = pydicom.dcmread(path)
    ds.StructureSetROISequence[1].ReferencedFrameOfReferenceUID = pydicom.uid.generate_uid()
    ds.save_as(path)
    out = tmp_path / "out"
    assert main(["run", str(tmp_path / "ct"), "-o", str(out)]) == 0
    said = capsys.readouterr().err
    assert "ROI 7 (GTV) lies in frame of reference" in said and "left out" in said
    record = json.loads((out / "structures.json").read_text())
    assert [s["name"] for s in record["structures"]] == ["Left"]
    assert record["outputs"]["skipped"] == {}
    rt = pydicom.dcmread(out / "rtstruct.dcm")
    assert [str(r.ROIName) for r in rt.StructureSetROISequence] == ["Left"]
    labels, _ = _nifti_labels(out / "labels.nii.gz")
    assert set(np.unique(labels)) == {0, 3}
    assert main(["run", str(tmp_path / "ct"), "--roi", "GTV", "-o", str(tmp_path / "x")]) == 2
    said = capsys.readouterr().err.strip().splitlines()
    assert len(said) == 1 and "choose ROIs of the set's frame" in said[0]


@pytest.mark.parametrize(
    ("rtstruct", "reason"),
    [
        ({"on_series": True, "patient_id": "ANOTHER-PATIENT"}, "of patient 'ANOTHER-PATIENT'"),
        ({"on_series": False}, "frame of reference"),  # same patient, its own frame
    ],
    ids=["another-patient", "another-frame"],
)
def test_an_rtstruct_beside_another_subjects_series_gets_no_dicom_output(
    tmp_path: Path, rtstruct: dict, reason: str
) -> None:
    """seg.dcm was written labelled with the series' patient; the frame was never compared.
    The reconstruction stands; no DICOM object refers to images it does not belong to."""
    _ct(tmp_path / "ct")
    factory.write_rtstruct(
        tmp_path / "ct" / "rs.dcm",
        {(3, "Left"): _rings(12.0, (-14.0, 0.0), 30.0)},
        on_series=tmp_path / "ct" if rtstruct["on_series"] else None,
        patient_id=rtstruct.get("patient_id"),
    )
    out = tmp_path / "out"
    assert main(["run", str(tmp_path / "ct"), "-o", str(out), "-q"]) == 0
    assert not (out / "seg.dcm").exists() and not (out / "rtstruct.dcm").exists()
    assert (out / "labels.nii.gz").is_file() and (out / "labels.seg.nrrd").is_file()
    skipped = json.loads((out / "structures.json").read_text())["outputs"]["skipped"]
    assert set(skipped) == {"seg", "rtstruct"}
    assert all(reason in why for why in skipped.values())


def test_a_series_with_a_slice_of_another_study_is_refused_naming_both(
    tmp_path: Path, capsys
) -> None:
    """highdicom raised ValueError when writing seg.dcm (exit 1, a traceback)."""
    import pydicom

    _ct(tmp_path / "ct")
    stray = sorted((tmp_path / "ct").glob("slice_*.dcm"))[4]
    ds = pydicom.dcmread(stray)
    ds.StudyInstanceUID = pydicom.uid.generate_uid()
    ds.SeriesDescription = "Head 5mm"
    ds.save_as(stray)
    factory.write_rtstruct(
        tmp_path / "ct" / "rs.dcm",
        {(3, "Left"): _rings(12.0, (-14.0, 0.0), 30.0)},
        on_series=tmp_path / "ct",
    )
    assert main(["run", str(tmp_path / "ct"), "-o", str(tmp_path / "out"), "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:")
    assert "2 studies" in err[0] and "CT 'Head 5mm'" in err[0] and stray.name in err[0]
    assert "20 images of CT (no SeriesDescription)" in err[0]


def test_a_series_without_type_2_patient_and_study_attributes_still_gets_its_seg(
    tmp_path: Path,
) -> None:
    """Research series often lack PatientBirthDate, StudyID ...: seg.dcm is written anyway."""
    import pydicom

    _ct(tmp_path / "ct")
    for path in (tmp_path / "ct").iterdir():
        ds = pydicom.dcmread(path)
        for name in ("PatientBirthDate", "PatientSex", "StudyID", "AccessionNumber"):
            if name in ds:
                delattr(ds, name)
        ds.save_as(path)
    factory.write_rtstruct(
        tmp_path / "ct" / "rs.dcm",
        {(1, "Ball"): _rings(12.0, (0.0, 0.0), 30.0)},
        on_series=tmp_path / "ct",
    )
    out = tmp_path / "out"
    assert main(["run", str(tmp_path / "ct"), "-o", str(out), "-q"]) == 0
    assert json.loads((out / "structures.json").read_text())["outputs"]["skipped"] == {}
    seg = pydicom.dcmread(out / "seg.dcm")
    assert "PatientBirthDate" in seg and seg.PatientBirthDate == ""


def test_a_run_into_an_earlier_runs_folder_leaves_nothing_of_it(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Outputs of the earlier run that this run does not write are removed, and it is said."""
    x, y, z = np.meshgrid(*[np.arange(40)] * 3, indexing="ij")
    ball = ((x - 20) ** 2 + (y - 20) ** 2 + (z - 20) ** 2 < 100).astype(np.uint8)
    three = ball.copy()
    three[(x > 20) & (ball > 0)] = 2
    three[(x < 14) & (ball > 0)] = 5
    sparse = ball * (z % 4 == 0)
    for name, data in (("three", three), ("sparse", sparse)):
        nib.save(nib.Nifti1Image(data.astype(np.uint8), np.eye(4)), tmp_path / f"{name}.nii.gz")
    out = tmp_path / "out"
    assert main(["run", str(tmp_path / "three.nii.gz"), "-o", str(out), "-q"]) == 0
    (out / "notes.txt").write_text("mine")
    assert {p.name for p in (out / "meshes").iterdir()} == {"1.stl", "2.stl", "5.stl"}
    assert (out / "metrics.json").is_file()  # a dense mask is its own ground truth
    capsys.readouterr()
    assert main(["run", str(tmp_path / "sparse.nii.gz"), "-o", str(out)]) == 0
    err = [line for line in capsys.readouterr().err.splitlines() if "earlier run" in line]
    assert len(err) == 1 and "metrics.json" in err[0] and "meshes/5.stl" in err[0]
    assert not (out / "metrics.json").exists() and not (out / "meshes").exists()
    assert (out / "mesh.stl").is_file() and (out / "notes.txt").read_text() == "mine"


def test_a_run_interrupted_while_writing_leaves_the_earlier_run_whole(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """Ctrl-C while a rerun wrote its files left the folder a mix of the two runs (the new
    structures.json and meshes beside the old plan.json and stale meshes)."""
    import slicerecon.case_outputs as outputs

    x, y, z = np.meshgrid(*[np.arange(40)] * 3, indexing="ij")
    ball = ((x - 20) ** 2 + (y - 20) ** 2 + (z - 20) ** 2 < 100).astype(np.uint8)
    three = ball.copy()
    three[(x > 20) & (ball > 0)] = 2
    three[(x < 14) & (ball > 0)] = 5
    nib.save(nib.Nifti1Image(three, np.eye(4)), tmp_path / "three.nii.gz")
    out = tmp_path / "out"
    assert main(["run", str(tmp_path / "three.nii.gz"), "-o", str(out), "-q"]) == 0
    before = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}

    def interrupted(*args: object, **kwargs: object) -> None:
        raise KeyboardInterrupt

    monkeypatch.setattr(outputs, "_write_preview", interrupted)  # after meshes and maps
    run = ["run", str(tmp_path / "three.nii.gz"), "--label", "1,2", "--slices", "6"]
    assert main([*run, "-o", str(out), "-q"]) == 130
    after = {p.relative_to(out): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert after == before  # nothing of the interrupted run, no staging folder


def test_an_input_in_the_output_folder_is_never_removed(tmp_path: Path) -> None:
    """A SEG named seg.dcm, reconstructed into its own folder twice: the input stays."""
    x, y, z = np.meshgrid(*[np.arange(24)] * 3, indexing="ij")
    ball = (x - 12) ** 2 + (y - 12) ** 2 + (z - 12) ** 2 < 64
    affine = factory.affine_from_geometry(
        [1, 0, 0], [0, 1, 0], [1.0, 1.0], [0, 0, 1.0], [0.0, 0.0, 0.0]
    )
    study = tmp_path / "study"
    study.mkdir()
    seg = factory.write_seg(study / "seg.dcm", {1: ball}, affine, labels={1: "Ball"})
    for _ in range(2):  # the second run finds the first one's plan.json
        assert main(["run", str(seg), "-o", str(study), "-q"]) == 0
        assert seg.is_file() and (study / "mesh.stl").is_file()
