"""Batch pipelines: discovery, safe names, Dask runs, failure isolation, resume, atomicity."""

from __future__ import annotations

import csv
import importlib.util
import json
import os
import sys
from pathlib import Path

import dicom_factory as factory  # tests/io, on pytest's pythonpath
import nibabel as nib
import numpy as np
import pydicom
import pytest
import trimesh

from pipelines.batch import (
    SUMMARY_COLUMNS,
    CaseResult,
    case_key,
    run_batch,
    write_summary,
)
from pipelines.discover import discover, discover_cases, safe_case_name
from slicerecon.cli import main
from slicerecon.errors import InputError, OptionError
from slicerecon.io.nifti import write_nifti
from slicerecon.reconstruct import ReconstructConfig
from slicerecon.shapes import make_shape

CONFIG = ReconstructConfig(n_points=5000, slices=8)
TESTS = Path(__file__).resolve().parents[1]


def _load(name: str, path: Path):
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, path)
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    return sys.modules[name]


def _shapes() -> dict[str, object]:
    """Six tiny masks (a few hundred to a few thousand voxels each)."""
    return {
        "ball_small": make_shape("sphere", radius=6.0),
        "ball_large": make_shape("sphere", radius=9.0),
        "branch": make_shape(
            "y_branch", trunk_length=12.0, branch_length=12.0, spread=9.0, radius=3.5
        ),
        "egg": make_shape("ellipsoid", radii=(9.0, 6.0, 5.0)),
        "brick": make_shape("box", size=(14.0, 10.0, 8.0)),
    }


def _write_cases(root: Path) -> dict[str, Path]:
    paths = {}
    for name, volume in _shapes().items():
        paths[name] = write_nifti(volume, root / f"{name}.nii.gz")
    corrupt = root / "corrupt.nii.gz"
    corrupt.write_bytes(paths["ball_small"].read_bytes()[:40])  # truncated gzip
    paths["corrupt"] = corrupt
    return paths


def _hidden_or_temporary(root: Path) -> list[Path]:
    return [p for p in root.rglob("*") if p.name.startswith(".") or ".tmp" in p.name]


def _summary(outdir: Path) -> dict[str, dict[str, str]]:
    with open(outdir / "summary.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert rows and list(rows[0]) == list(SUMMARY_COLUMNS)
    return {row["case"]: row for row in rows}


def _mtimes(folder: Path) -> dict[str, int]:
    return {p.name: p.stat().st_mtime_ns for p in folder.iterdir()}


# ---------------------------------------------------------------------------- names
@pytest.mark.parametrize(
    "raw",
    [
        "../../etc/passwd",
        "/etc/passwd",
        "..",
        ".",
        "",
        "a/../../b",
        "C:\\Windows\\system32\\cfg",
        "\\\\server\\share\\x",
        "..\\..\\up",
        "Müller/ÄÖÜ ß",
        "患者/肝臓",
        "name with spaces & $(rm -rf ~)",
        "con",
        "a" * 400,
        "\u202e.nii",
    ],
)
def test_case_names_cannot_escape_outdir(tmp_path, raw):
    name = safe_case_name(raw)
    assert name and len(name) <= 96
    assert set(name) <= set("abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLMNOPQRSTUVWXYZ0123456789-_")
    assert name.lower() not in ("con", "nul")
    target = (tmp_path / name).resolve()
    assert target.parent == tmp_path.resolve()


def test_case_names_keep_what_is_safe_and_differ_where_inputs_differ():
    assert safe_case_name("../../etc/passwd") == "etc__passwd"
    assert safe_case_name("patient 01/ct.v2") == "patient_01__ct_v2"
    assert safe_case_name("Müller") == "Muller"
    assert safe_case_name("患者") != safe_case_name("肝臓")
    assert safe_case_name("a" * 400) != safe_case_name("a" * 399)


def test_discovery_kinds_order_and_unique_names(tmp_path):
    rt = _load("slicerecon_tests_rtstruct", TESTS / "io" / "test_rtstruct.py")
    ball = make_shape("sphere", radius=5.0)
    indir = tmp_path / "in"
    affine = factory.affine_from_geometry([1, 0, 0], [0, 1, 0], [1, 1], [0, 0, 1], [0, 0, 0])
    factory.write_series(indir / "p1", ball.mask.astype(np.uint16), affine)
    files = factory.write_series(indir / "p2", np.zeros((30, 30, 8), np.uint16), affine)
    uids = factory.read_uids(files)
    rings = [
        rt._contour_item(rt._ring(6.0, [15.0, 15.0], affine, k), image_uid=uids[k])
        for k in range(2, 6)
    ]
    rt.write_rtstruct(indir / "p2" / "rtstruct.dcm", {(1, "Lesion"): rings})
    factory.write_seg(indir / "seg.dcm", {1: ball.mask}, affine, labels={1: "ball"})
    for name in ("a.nii.gz", "A.nii", "x.nii", "report_assets.nii.gz", ".hidden.nii.gz"):
        write_nifti(ball, indir / name)
    (indir / "x.json").write_text("{}")
    (indir / "broken.dcm").write_bytes(b"not dicom")
    (indir / "notes.txt").write_text("ignored")
    trimesh.creation.icosphere().export(indir / "mesh.stl")
    write_nifti(ball, indir / "out" / "old.nii.gz")

    cases = discover_cases(indir, exclude=[indir / "out"])
    by_input = {c.relpath: c for c in cases}
    assert [c.relpath for c in cases] == sorted(by_input)
    assert set(by_input) == {
        "A.nii",
        "a.nii.gz",
        "broken.dcm",
        "p1",
        "p2/rtstruct.dcm",
        "report_assets.nii.gz",
        "seg.dcm",
        "x.json",
        "x.nii",
    }
    kinds = {rel: c.kind for rel, c in by_input.items()}
    assert kinds["p1"] == "dicom-series" and kinds["p2/rtstruct.dcm"] == "rtstruct"
    assert kinds["seg.dcm"] == "dicom-seg" and kinds["x.json"] == "contours"
    assert kinds["broken.dcm"] == "dicom-unreadable"
    assert by_input["p2/rtstruct.dcm"].image_dir == indir / "p2"
    assert len(by_input["p2/rtstruct.dcm"].files) == 9  # the RTSTRUCT and its 8 images
    assert len(by_input["p1"].files) == ball.shape[2]
    names = [c.name for c in cases]
    assert len({n.casefold() for n in names}) == len(names)
    # names alike but for the suffix: each named with it, whatever else INDIR holds
    assert by_input["A.nii"].name == "A_nii" and by_input["a.nii.gz"].name == "a_nii_gz"
    assert by_input["x.json"].name == "x_json" and by_input["x.nii"].name == "x_nii"
    assert by_input["report_assets.nii.gz"].name == "report_assets-2"
    assert by_input["p2/rtstruct.dcm"].name == "p2__rtstruct"
    assert discover_cases(indir, exclude=[indir / "out"]) == cases  # stable
    # a new input of the same name renames no case that was there: "x_json" stays x.json's
    (indir / "X.csv").write_text("x,y,z\n")
    again = {c.relpath: c.name for c in discover_cases(indir, exclude=[indir / "out"])}
    assert again["X.csv"] == "X_csv"
    assert all(again[c.relpath] == c.name for c in cases)


def test_dicom_series_and_rtstruct_beside_its_images_reconstruct(tmp_path):
    rt = _load("slicerecon_tests_rtstruct", TESTS / "io" / "test_rtstruct.py")
    ball = make_shape("sphere", radius=6.0)
    affine = factory.affine_from_geometry([1, 0, 0], [0, 1, 0], [1, 1], [0, 0, 2], [0, 0, 0])
    factory.write_series(tmp_path / "in" / "mask", ball.mask.astype(np.uint16), affine)
    files = factory.write_series(tmp_path / "in" / "ct", np.zeros((40, 40, 12), np.uint16), affine)
    uids = factory.read_uids(files)
    rings = [
        rt._contour_item(rt._ring(8.0 - abs(k - 6), [20.0, 20.0], affine, k), image_uid=uids[k])
        for k in range(3, 10)
    ]
    rt.write_rtstruct(tmp_path / "in" / "ct" / "rs.dcm", {(1, "Lesion"): rings})

    result = run_batch(
        tmp_path / "in", tmp_path / "out", ReconstructConfig(n_points=5000), workers=0, report=False
    )
    assert [(c.case, c.kind, c.status) for c in result.cases] == [
        ("ct__rs", "rtstruct", "ok"),
        ("mask", "dicom-series", "ok"),
    ]
    plan = json.loads((tmp_path / "out" / "ct__rs" / "plan.json").read_text())
    assert plan["sections"]["plane_indices"] == list(range(3, 10))  # on the CT's slice grid
    assert result.cases[1].metrics["volume_iou"] > 0.7
    for case in ("ct__rs", "mask"):
        assert trimesh.load(tmp_path / "out" / case / "mesh.stl").is_watertight


def test_an_rtstruct_beside_its_series_in_a_subfolder_is_read_on_that_series(tmp_path):
    """pat1/RS.dcm beside pat1/CT/: one case on the CT's grid, with its DICOM outputs."""
    affine = factory.affine_from_geometry([1, 0, 0], [0, 1, 0], [1, 1], [0, 0, 2], [0, 0, 0])
    patient = tmp_path / "in" / "pat1"
    factory.write_series(patient / "CT", np.zeros((40, 40, 12), np.uint16), affine, modality="CT")
    rings = [
        factory.contour_item(factory.circle(8.0 - abs(k - 6), (20.0, 20.0), 2.0 * k))
        for k in range(3, 10)
    ]
    factory.write_rtstruct(patient / "RS.dcm", {(1, "Lesion"): rings}, on_series=patient / "CT")
    result = run_batch(
        tmp_path / "in", tmp_path / "out", ReconstructConfig(n_points=5000), workers=0, report=False
    )
    assert [(c.case, c.kind, c.status) for c in result.cases] == [("pat1__RS", "rtstruct", "ok")]
    folder = tmp_path / "out" / "pat1__RS"
    assert (folder / "rtstruct.dcm").is_file() and (folder / "seg.dcm").is_file()
    plan = json.loads((folder / "plan.json").read_text())
    assert plan["sections"]["plane_indices"] == list(range(3, 10))  # on the CT's slice grid
    assert main(["run", str(patient), "-o", str(tmp_path / "run"), "-q"]) == 0
    assert (tmp_path / "run" / "rtstruct.dcm").is_file()


def test_a_batch_says_how_the_label_map_holds_nested_rois(tmp_path):
    """run prints "overlaps: ... labels.nii.gz holds one structure per voxel"; a batch said
    it nowhere, and an outer ROI's label map below its mesh was left unexplained."""
    rings = {
        (1, "Organ"): [
            factory.contour_item(factory.circle(9.0, (20.0, 20.0), 2.0 * k)) for k in range(3, 10)
        ],
        (2, "Lesion"): [
            factory.contour_item(factory.circle(3.0, (20.0, 20.0), 2.0 * k)) for k in range(5, 8)
        ],
    }
    factory.write_rtstruct(tmp_path / "in" / "rs.dcm", rings)
    result = run_batch(
        tmp_path / "in", tmp_path / "out", ReconstructConfig(n_points=5000), workers=0, report=False
    )
    (case,) = result.cases
    assert case.status == "ok"
    said = [w for w in case.warnings if w.startswith("overlaps: ")]
    assert len(said) == 1 and "one structure per voxel" in said[0]


def test_plan_json_of_an_annotation_records_no_slices_it_did_not_use(tmp_path):
    """A batch with --slices 8 recorded "slices": 8 in the plan of a sparse label map,
    whose drawn planes were used as they are."""
    ball = make_shape("sphere", radius=8.0)
    drawn = np.zeros(ball.mask.shape, np.uint8)
    drawn[:, :, 4:-4:3] = ball.mask[:, :, 4:-4:3]
    (tmp_path / "in").mkdir()
    nib.save(nib.Nifti1Image(drawn, ball.affine), tmp_path / "in" / "drawn.nii.gz")
    config = ReconstructConfig(slices=8, n_points=5000)
    result = run_batch(tmp_path / "in", tmp_path / "out", config, workers=0, report=False)
    assert [c.status for c in result.cases] == ["ok"]
    plan = json.loads((tmp_path / "out" / "drawn" / "plan.json").read_text())
    assert plan["config"]["slices"] is None and plan["config"]["every"] is None


def _two_series_and_an_rtstruct(root: Path, subfolders: bool, *, names_series: bool = True):
    """A study of a 1 mm and a 3 mm CT series (one frame of reference) and an RTSTRUCT
    drawn on the 1 mm one: in one folder, or as thin/, thick/ and RTSTRUCT/."""
    from pydicom.dataset import Dataset
    from pydicom.sequence import Sequence as DicomSequence
    from pydicom.uid import generate_uid

    study, frame, thin_uid = generate_uid(), generate_uid(), generate_uid()
    thin_dir, thick_dir = (root / "thin", root / "thick") if subfolders else (root, root)
    common = {"modality": "CT", "study_uid": study, "frame_of_reference_uid": frame}
    thin = factory.write_series(
        thin_dir,
        np.zeros((48, 48, 36), np.uint16),
        np.diag([0.8, 0.8, 1.0, 1.0]),
        series_uid=thin_uid,
        series_description="thin",
        file_names=[f"a{k:03d}.dcm" for k in range(36)],
        **common,
    )
    factory.write_series(
        thick_dir,
        np.zeros((48, 48, 12), np.uint16),
        np.diag([0.8, 0.8, 3.0, 1.0]),
        series_description="thick",
        file_names=[f"b{k:03d}.dcm" for k in range(12)],
        **common,
    )
    rings = [
        factory.contour_item(factory.circle(np.sqrt(100.0 - (k - 18) ** 2), (19.0, 19.0), k))
        for k in range(10, 27, 4)
    ]
    path = factory.write_rtstruct(
        (root / "RTSTRUCT" if subfolders else root) / "rs.dcm",
        {(1, "Ball"): rings},
        on_series=thin_dir,
    )
    if names_series:  # the structure set's references, as a planning system writes them
        ds = pydicom.dcmread(path)
        series = Dataset()
        series.SeriesInstanceUID = thin_uid
        study_item = Dataset()
        study_item.RTReferencedSeriesSequence = DicomSequence([series])
        frame_item = Dataset()
        frame_item.FrameOfReferenceUID = frame
        frame_item.RTReferencedStudySequence = DicomSequence([study_item])
        ds.ReferencedFrameOfReferenceSequence = DicomSequence([frame_item])
        ds.save_as(path)
    return path, len(thin)


@pytest.mark.parametrize("subfolders", [False, True], ids=["one folder", "thin/ thick/ RTSTRUCT/"])
def test_of_two_series_of_a_study_the_one_the_rtstruct_names_is_read(tmp_path, capsys, subfolders):
    """A study exported with two series (1 mm and 3 mm) and an RTSTRUCT drawn on the 1 mm
    one was refused ("holds 2 image series", or "no one image series beside it"): the
    RTSTRUCT says which series it was drawn on. Without that reference it still is."""
    study = tmp_path / "in" / "study"
    _, slices = _two_series_and_an_rtstruct(study, subfolders)
    out = tmp_path / "run"
    assert main(["run", str(study), "-o", str(out)]) == 0
    assert nib.load(out / "labels.nii.gz").shape == (48, 48, slices)  # the 1 mm series' grid
    assert (out / "seg.dcm").is_file() and (out / "rtstruct.dcm").is_file()
    warned = [line for line in capsys.readouterr().err.splitlines() if line.startswith("warning")]
    assert len(warned) == 1 and ("thin" in warned[0]) and ("thick" in warned[0])
    if not subfolders:  # the SEG written there names its series too
        import shutil

        seg_study = tmp_path / "seg_study"
        shutil.copytree(study, seg_study, ignore=shutil.ignore_patterns("rs.dcm"))
        shutil.copy(out / "seg.dcm", seg_study / "seg.dcm")
        assert main(["run", str(seg_study), "-o", str(tmp_path / "seg_out"), "-q"]) == 0
        assert nib.load(tmp_path / "seg_out" / "labels.nii.gz").shape == (48, 48, slices)
    result = run_batch(
        tmp_path / "in", tmp_path / "out", ReconstructConfig(n_points=5000), workers=0, report=False
    )
    assert [(c.kind, c.status) for c in result.cases] == [("rtstruct", "ok")]
    assert nib.load(next((tmp_path / "out").glob("*/labels.nii.gz"))).shape == (48, 48, slices)
    if subfolders:  # the 3 mm series is no case of its own (a CT is no label map)
        left = discover(tmp_path / "in").skipped
        assert [(s.relpath, "drawn on study/thin" in s.reason) for s in left] == [
            ("study/thick", True)
        ]
    blind = tmp_path / "blind"
    _two_series_and_an_rtstruct(blind, subfolders, names_series=False)
    assert main(["run", str(blind), "-o", str(tmp_path / "blind_out"), "-q"]) == 2
    assert "series" in capsys.readouterr().err


def test_an_rtstruct_naming_none_of_the_images_beside_it_is_said(tmp_path, capsys):
    """Drawn on a 1.25 mm CT, beside the 3.75 mm one only: its contours name none of those
    images. The warning existed for one ROI read alone, not for run and batch."""
    from pydicom.uid import generate_uid

    affine = factory.affine_from_geometry([1, 0, 0], [0, 1, 0], [1, 1], [0, 0, 2], [0, 0, 0])
    study = tmp_path / "study"
    factory.write_series(study, np.zeros((40, 40, 12), np.uint16), affine, modality="CT")
    rings = [
        factory.contour_item(
            factory.circle(8.0 - abs(k - 6), (20.0, 20.0), 2.0 * k), image_uid=generate_uid()
        )
        for k in range(3, 10)
    ]
    factory.write_rtstruct(study / "rs.dcm", {(1, "GTV"): rings}, on_series=study)
    assert main(["run", str(study), "-o", str(tmp_path / "out")]) == 0
    warned = [x for x in capsys.readouterr().err.splitlines() if x.startswith("warning")]
    assert len(warned) == 1 and "name none of the images" in warned[0]


def test_a_study_with_stray_files_and_a_registered_mr_reads_its_ct(tmp_path, capsys):
    """CT/ holding a .DS_Store, a README and a DICOMDIR beside RTSTRUCT/, and a registered
    MR/ of another frame: a stray file sorted first hid the series ('holds no one image
    series beside it'; in a batch the case was 'ok' on a grid of its own, without DICOM
    outputs), and the MR became a failed case ('not a label map')."""
    from pydicom.fileset import FileSet

    study = tmp_path / "in" / "pat"
    affine = factory.affine_from_geometry([1, 0, 0], [0, 1, 0], [1, 1], [0, 0, 2], [0, 0, 0])
    ct = factory.write_series(study / "CT", np.zeros((40, 40, 12), np.uint16), affine)
    factory.write_series(study / "MR", np.zeros((40, 40, 12), np.uint16), affine, modality="MR")
    rings = [
        factory.contour_item(factory.circle(8.0 - abs(k - 6), (20.0, 20.0), 2.0 * k))
        for k in range(3, 10)
    ]
    factory.write_rtstruct(
        study / "RTSTRUCT" / "RS.dcm", {(1, "GTV"): rings}, on_series=study / "CT"
    )
    (study / "CT" / ".DS_Store").write_bytes(b"\0\0\0\1Bud1" + bytes(100))
    (study / "CT" / "00_README.txt").write_text("exported by PACS\n")
    index = FileSet()
    index.add(pydicom.dcmread(ct[0]))
    index.write(tmp_path / "cd")
    (tmp_path / "cd" / "DICOMDIR").rename(study / "CT" / "DICOMDIR")
    assert main(["run", str(study), "-o", str(tmp_path / "run")]) == 0
    assert nib.load(tmp_path / "run" / "labels.nii.gz").shape == (40, 40, 12)
    warned = [x for x in capsys.readouterr().err.splitlines() if x.startswith("warning")]
    assert len(warned) == 1 and "the one series of its frame of reference" in warned[0]
    result = run_batch(
        tmp_path / "in", tmp_path / "out", ReconstructConfig(n_points=5000), workers=0, report=False
    )
    assert [(c.kind, c.status) for c in result.cases] == [("rtstruct", "ok")]
    assert (tmp_path / "out" / "pat__RTSTRUCT__RS" / "rtstruct.dcm").is_file()
    left = {s.relpath: s.reason for s in discover(tmp_path / "in").skipped}
    assert "another frame" in left["pat/MR"]


def test_a_seg_beside_its_series_and_a_pacs_export_are_read_on_the_series(tmp_path):
    """A folder of CT images and a SEG drawn on every 2nd slice: ``run`` read the CT
    ("not a label map: negative values"), batch the SEG on its own 5 mm grid without
    seg.dcm. A study exported as CT/ beside RTSTRUCT/: "directory is empty", and the
    RTSTRUCT without its series in a batch. Each is now one case on the CT's grid."""
    affine = factory.affine_from_geometry([1, 0, 0], [0, 1, 0], [1, 1], [0, 0, 2], [0, 0, 0])
    ct = np.full((40, 40, 16), -1000, np.int16)
    x, y, z = np.meshgrid(np.arange(40), np.arange(40), np.arange(16) * 2.0, indexing="ij")
    ball = (x - 20) ** 2 + (y - 20) ** 2 + (z - 15) ** 2 < 9**2
    drawn = np.zeros(ball.shape, bool)
    drawn[:, :, ::2] = ball[:, :, ::2]
    seg_study = tmp_path / "in" / "seg_study"
    files = factory.write_series(seg_study, ct, affine, modality="CT", rescale=(1.0, -1024.0))
    frame = str(pydicom.dcmread(files[0], stop_before_pixels=True).FrameOfReferenceUID)
    factory.write_seg(
        seg_study / "seg.dcm", {1: drawn}, affine, labels={1: "Ball"}, frame_of_reference_uid=frame
    )
    other_study = tmp_path / "other" / "study"  # the same SEG beside another study's images
    factory.write_series(other_study, ct, affine, modality="CT", rescale=(1.0, -1024.0))
    factory.write_seg(other_study / "seg.dcm", {1: drawn}, affine, labels={1: "Ball"})
    assert main(["run", str(other_study), "-o", str(tmp_path / "other_out"), "-q"]) == 0
    assert not (tmp_path / "other_out" / "seg.dcm").exists()  # it refers to no other study
    export = tmp_path / "in" / "export"
    factory.write_series(export / "CT", ct, affine, modality="CT", rescale=(1.0, -1024.0))
    rings = [
        factory.contour_item(factory.circle(8.0 - abs(k - 6), (20.0, 20.0), 2.0 * k))
        for k in range(3, 10)
    ]
    factory.write_rtstruct(
        export / "RTSTRUCT" / "RS.dcm", {(1, "Lesion"): rings}, on_series=export / "CT"
    )
    # a SEG that says only its own 4 mm step, its frames on every 2nd slice of that CT
    coarse = affine.copy()
    coarse[:3, 2] *= 2
    older = tmp_path / "older"
    files = factory.write_series(older, ct, affine, modality="CT", rescale=(1.0, -1024.0))
    frame = str(pydicom.dcmread(files[0], stop_before_pixels=True).FrameOfReferenceUID)
    factory.write_seg(
        older / "seg.dcm",
        {1: ball[:, :, ::2]},
        coarse,
        labels={1: "Ball"},
        frame_of_reference_uid=frame,
    )
    assert main(["run", str(older), "-o", str(tmp_path / "older_out"), "-q"]) == 0
    assert nib.load(tmp_path / "older_out" / "labels.nii.gz").shape == ct.shape
    plan = json.loads((tmp_path / "older_out" / "plan.json").read_text())
    assert plan["annotation"].startswith("sparse annotation")  # not a dense 4 mm mask
    for folder in (seg_study, export):
        out = tmp_path / "run" / folder.name
        assert main(["run", str(folder), "-o", str(out), "-q"]) == 0
        assert nib.load(out / "labels.nii.gz").shape == ct.shape  # the CT's grid
        assert (out / "seg.dcm").is_file()
    assert json.loads((tmp_path / "run" / "seg_study" / "plan.json").read_text())[
        "annotation"
    ].startswith("sparse annotation")
    result = run_batch(
        tmp_path / "in", tmp_path / "out", ReconstructConfig(n_points=5000), workers=0, report=False
    )
    assert [(c.case, c.kind, c.status) for c in result.cases] == [
        ("export__RTSTRUCT__RS", "rtstruct", "ok"),
        ("seg_study__seg", "dicom-seg", "ok"),
    ]
    for case in ("export__RTSTRUCT__RS", "seg_study__seg"):
        assert (tmp_path / "out" / case / "seg.dcm").is_file()
        assert nib.load(tmp_path / "out" / case / "labels.nii.gz").shape == ct.shape
    # a second annotator's file beside the first: both keep the series (they lost it, and
    # the CT became a failed case)
    import shutil

    shutil.copy(export / "RTSTRUCT" / "RS.dcm", export / "RTSTRUCT" / "RS2.dcm")
    again = run_batch(
        tmp_path / "in",
        tmp_path / "out2",
        ReconstructConfig(n_points=5000),
        workers=0,
        report=False,
    )
    assert [(c.case, c.status) for c in again.cases if c.case.startswith("export")] == [
        ("export__RTSTRUCT__RS", "ok"),
        ("export__RTSTRUCT__RS2", "ok"),
    ]
    assert (tmp_path / "out2" / "export__RTSTRUCT__RS2" / "seg.dcm").is_file()


# ------------------------------------------------------------------ batch on Dask
@pytest.fixture(scope="module")
def first_run(tmp_path_factory):
    """Six cases (one corrupt) through the CLI on a 2-process LocalCluster."""
    root = tmp_path_factory.mktemp("batch")
    paths = _write_cases(root / "in")
    outdir = root / "out"
    code = main(
        [
            "batch",
            str(root / "in"),
            "-o",
            str(outdir),
            "--workers",
            "2",
            "--slices",
            "8",
            "--no-report",
        ]
    )
    return {
        "root": root,
        "in": root / "in",
        "out": outdir,
        "code": code,
        "paths": paths,
        "config": ReconstructConfig(slices=8),
    }


def test_batch_records_failures_and_finishes_every_good_case(first_run):
    assert first_run["code"] == 1  # one case failed
    outdir = first_run["out"]
    rows = _summary(outdir)
    assert sorted(rows) == sorted(["ball_small", "ball_large", "branch", "egg", "brick", "corrupt"])
    for name, volume in _shapes().items():
        row = rows[name]
        assert row["status"] == "ok" and row["error"] == ""
        assert row["watertight"] == "true" and int(row["planes"]) == 8
        assert int(row["parts"]) >= 1 and float(row["seconds"]) > 0
        assert float(row["volume_iou"]) > 0.7, (name, row["volume_iou"])
        mesh = trimesh.load(outdir / name / "mesh.stl")
        assert mesh.is_watertight
        assert mesh.volume == pytest.approx(volume.volume_mm3, rel=0.3)
        done = json.loads((outdir / name / "done.json").read_text())
        assert done["key"] == case_key(
            next(c for c in discover_cases(first_run["in"]) if c.name == name), first_run["config"]
        )
    bad = rows["corrupt"]
    assert bad["status"] == "failed" and bad["error_type"] == "FormatError"
    assert "corrupt.nii.gz" in bad["error"] and "corrupt" in bad["error"]
    error = json.loads((outdir / "corrupt" / "error.json").read_text())
    assert {"case", "input", "error", "type"} <= set(error)
    assert error["case"] == "corrupt" and error["type"] == "FormatError"
    assert sorted(p.name for p in (outdir / "corrupt").iterdir()) == ["error.json"]
    assert not _hidden_or_temporary(outdir)


def test_second_run_recomputes_nothing(first_run):
    outdir = first_run["out"]
    before = {name: _mtimes(outdir / name) for name in _shapes()}
    result = run_batch(first_run["in"], outdir, first_run["config"], workers=0, report=False)
    status = {c.case: c.status for c in result.cases}
    assert status == {**{name: "skipped" for name in _shapes()}, "corrupt": "failed"}
    assert {name: _mtimes(outdir / name) for name in _shapes()} == before
    rows = _summary(outdir)
    assert rows["egg"]["status"] == "skipped" and rows["egg"]["volume_iou"] != ""
    assert result.n_failed == 1 and not result.ok


def test_force_recomputes_and_exit_code_is_zero_when_every_case_is_done(tmp_path, capsys):
    write_nifti(make_shape("sphere", radius=5.0), tmp_path / "in" / "ball.nii.gz")
    out = tmp_path / "out"
    args = [
        "batch",
        str(tmp_path / "in"),
        "-o",
        str(out),
        "--workers",
        "0",
        "--slices",
        "6",
        "--format",
        "ply",
        "--no-report",
    ]
    assert main(args) == 0
    assert "1 cases: 1 ok, 0 failed, 0 skipped" in capsys.readouterr().out
    mesh = out / "ball" / "mesh.ply"
    assert trimesh.load(mesh).is_watertight
    stamp = mesh.stat().st_mtime_ns
    assert main(args) == 0
    assert "1 cases: 0 ok, 0 failed, 1 skipped" in capsys.readouterr().out
    assert mesh.stat().st_mtime_ns == stamp
    assert main([*args, "--force"]) == 0
    assert "1 cases: 1 ok, 0 failed, 0 skipped" in capsys.readouterr().out
    assert mesh.stat().st_mtime_ns != stamp
    assert trimesh.load(mesh).is_watertight
    assert not _hidden_or_temporary(out)


def test_key_changes_with_input_bytes_and_options_only(tmp_path):
    write_nifti(make_shape("sphere", radius=5.0), tmp_path / "a" / "ball.nii.gz")
    (case,) = discover_cases(tmp_path / "a")
    key = case_key(case, CONFIG)
    assert case_key(case, ReconstructConfig(n_points=5000, slices=8)) == key
    for other in (
        ReconstructConfig(n_points=5000, slices=6),
        ReconstructConfig(n_points=5000, slices=8, method="loft"),
        ReconstructConfig(n_points=5000, slices=8, seed=1),
        ReconstructConfig(n_points=5000, slices=8, mesh_format="obj"),
    ):
        assert case_key(case, other) != key
    (tmp_path / "a" / "ball.nii.gz").rename(tmp_path / "a" / "renamed.nii.gz")
    (renamed,) = discover_cases(tmp_path / "a")
    assert case_key(renamed, CONFIG) == key  # same bytes, same options: same outputs
    write_nifti(make_shape("sphere", radius=6.0), tmp_path / "a" / "renamed.nii.gz")
    assert case_key(renamed, CONFIG) != key


@pytest.mark.slow
def test_a_killed_worker_is_replaced_and_nothing_is_half_written(tmp_path):
    import dask
    from distributed import Client, LocalCluster, WorkerPlugin

    marker = str(tmp_path / "crashed")

    class Crash(WorkerPlugin):
        """Kill the worker process 0.3 s into case ``crash_me`` (once) or ``doomed`` (always)."""

        name = "crash"

        def transition(self, key, start, finish, **kwargs):
            import threading

            if finish != "executing":
                return
            if "crash_me" in str(key):
                try:
                    with open(marker, "x"):
                        pass
                except FileExistsError:
                    return
            elif "doomed" not in str(key):
                return
            threading.Timer(0.3, os._exit, (1,)).start()

    indir, doomed_dir = tmp_path / "in", tmp_path / "in2"
    write_nifti(make_shape("sphere", radius=14.0), indir / "crash_me.nii.gz")
    write_nifti(make_shape("sphere", radius=14.0), doomed_dir / "doomed.nii.gz")
    for name, radius in (("a", 5.0), ("b", 6.0)):
        write_nifti(make_shape("sphere", radius=radius), indir / f"{name}.nii.gz")
    write_nifti(make_shape("sphere", radius=5.0), doomed_dir / "c.nii.gz")
    out = tmp_path / "out"
    (out / ".crash_me.partial-stale").mkdir(parents=True)  # a leftover of an earlier crash
    (out / ".crash_me.partial-stale" / ".mesh.x.tmp.stl").write_bytes(b"half")
    with dask.config.set({"distributed.scheduler.allowed-failures": 1}):  # 2nd death is final
        cluster = LocalCluster(
            n_workers=2, processes=True, threads_per_worker=1, dashboard_address=None
        )
    with cluster, Client(cluster) as client:
        client.register_plugin(Crash())
        result = run_batch(indir, out, CONFIG, scheduler=cluster.scheduler_address, report=False)
        doomed = run_batch(
            doomed_dir, tmp_path / "out2", CONFIG, scheduler=cluster.scheduler_address, report=False
        )
    assert os.path.exists(marker)  # the worker really died once
    assert [(c.case, c.status) for c in result.cases] == [
        ("a", "ok"),
        ("b", "ok"),
        ("crash_me", "ok"),
    ]
    assert trimesh.load(out / "crash_me" / "mesh.stl").is_watertight
    crashed_at = os.stat(marker).st_mtime_ns + 300_000_000
    assert (out / "crash_me" / "done.json").stat().st_mtime_ns > crashed_at  # made after it
    assert not _hidden_or_temporary(out)
    # a case that kills every worker it runs on fails alone, as KilledWorker
    assert [(c.case, c.status) for c in doomed.cases] == [("c", "ok"), ("doomed", "failed")]
    assert doomed.cases[1].error_type == "KilledWorker" and "died" in doomed.cases[1].error
    error = json.loads((tmp_path / "out2" / "doomed" / "error.json").read_text())
    assert error["type"] == "KilledWorker"
    assert sorted(p.name for p in (tmp_path / "out2" / "doomed").iterdir()) == ["error.json"]
    assert not _hidden_or_temporary(tmp_path / "out2")


# --------------------------------------------------------------- report and atomicity
def test_report_is_written_and_its_failure_does_not_fail_the_batch(tmp_path, monkeypatch):
    write_nifti(make_shape("sphere", radius=5.0), tmp_path / "in" / "ball.nii.gz")
    import slicerecon.report as report

    def broken(results_dir):
        raise RuntimeError("renderer exploded")

    monkeypatch.setattr(report, "write_report", broken)
    result = run_batch(tmp_path / "in", tmp_path / "out", CONFIG, workers=0)
    assert result.ok and result.report is None
    assert "renderer exploded" in result.report_error
    assert _summary(tmp_path / "out")["ball"]["status"] == "ok"

    calls = []
    monkeypatch.setattr(report, "write_report", lambda d: calls.append(Path(d)) or Path(d))
    run_batch(tmp_path / "in", tmp_path / "out", CONFIG, workers=0)
    assert calls == [(tmp_path / "out").resolve()]


def test_how_each_input_was_read_and_its_warnings_reach_summary_and_report(tmp_path):
    """A case read with a warning appeared as a plain "ok" in summary.csv and the report."""
    import nibabel as nib

    labels = np.zeros((30, 30, 24), np.uint8)
    labels[6:24, 6:24, 2:22:3] = 1  # an organ on every 3rd slice
    labels[8:12, 8:12, 12] = 1
    labels[14:20, 14:20, 13] = 2  # a lesion drawn on one slice only: warned about
    (tmp_path / "in").mkdir()
    nib.save(nib.Nifti1Image(labels, np.eye(4)), tmp_path / "in" / "drawn.nii.gz")
    write_nifti(make_shape("sphere", radius=5.0), tmp_path / "in" / "ball.nii.gz")
    assert run_batch(tmp_path / "in", tmp_path / "out", CONFIG, workers=0).ok
    rows = _summary(tmp_path / "out")
    assert rows["drawn"]["read_as"].startswith("sparse annotation (detected)")
    assert "one plane only" in rows["drawn"]["warnings"]
    assert rows["ball"]["read_as"].startswith("dense mask") and rows["ball"]["warnings"] == ""
    page = (tmp_path / "out" / "report.html").read_text()
    assert "Warnings (1 case)" in page and "one plane only" in page


def test_interrupted_summary_write_leaves_no_partial_file(tmp_path):
    target = tmp_path / "summary.csv"
    good = [CaseResult("a", "a.nii.gz", "nifti", "ok", parts=2, planes=8, watertight=True)]
    write_summary(good, target)
    before = target.read_bytes()

    def interrupted():
        yield CaseResult("b", "b.nii.gz", "nifti", "ok")
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        write_summary(interrupted(), target)
    assert target.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["summary.csv"]
    with pytest.raises(KeyboardInterrupt):
        write_summary(interrupted(), tmp_path / "new.csv")
    assert not (tmp_path / "new.csv").exists()


def test_one_case_result_record_for_the_runner_and_the_report():
    import slicerecon.report
    import slicerecon.results

    assert CaseResult is slicerecon.results.CaseResult is slicerecon.report.CaseResult
    assert write_summary is slicerecon.results.write_summary


def test_named_configurations_run_every_case_into_a_folder_each(tmp_path):
    from dataclasses import replace

    from slicerecon.results import collect_results

    write_nifti(make_shape("sphere", radius=5.0), tmp_path / "in" / "ball.nii.gz")
    (tmp_path / "in" / "bad.nii.gz").write_bytes(b"\x1f\x8b not gzip")
    configs = {"loft": replace(CONFIG, method="loft"), "sdf": CONFIG}
    out = tmp_path / "out"
    result = run_batch(tmp_path / "in", out, configs, workers=0, report=False)
    assert [(c.case, c.status, c.method) for c in result.cases] == [
        ("bad/loft", "failed", "loft"),
        ("bad/sdf", "failed", "sdf"),
        ("ball/loft", "ok", "loft"),
        ("ball/sdf", "ok", "sdf"),
    ]
    assert trimesh.load(out / "ball" / "loft" / "mesh.stl").is_watertight
    assert set(_summary(out)) == {"bad/loft", "bad/sdf", "ball/loft", "ball/sdf"}
    # what the runner returns is what a reader of the folders gets back
    stored = {c.case: c for c in collect_results(out)}
    assert set(stored) == {c.case for c in result.cases}
    for case in result.cases:
        again = stored[case.case]
        assert (again.status, again.method, again.error, again.error_type) == (
            case.status,
            case.method,
            case.error,
            case.error_type,
        )
        if case.ok:
            assert (
                again.metrics,
                again.planes,
                again.parts,
                again.watertight,
                again.seconds,
                again.input,
                again.kind,
            ) == (
                case.metrics,
                case.planes,
                case.parts,
                case.watertight,
                case.seconds,
                case.input,
                case.kind,
            )
    rerun = run_batch(tmp_path / "in", out, configs, workers=0, report=False)
    assert [c.status for c in rerun.cases] == ["failed", "failed", "skipped", "skipped"]
    assert rerun.cases[2].metrics == result.cases[2].metrics
    assert not _hidden_or_temporary(out)
    with pytest.raises(OptionError, match="folder names"):
        run_batch(tmp_path / "in", out, {"../up": CONFIG}, workers=0)


# ------------------------------------------------------------------------ invocation
def test_bad_invocations(tmp_path, capsys):
    assert main(["batch", str(tmp_path / "missing"), "-o", str(tmp_path / "o")]) == 2
    assert "input directory not found" in capsys.readouterr().err
    (tmp_path / "empty").mkdir()
    (tmp_path / "empty" / "readme.txt").write_text("no cases here")
    assert main(["batch", str(tmp_path / "empty"), "-o", str(tmp_path / "o")]) == 2
    assert "no cases found" in capsys.readouterr().err
    assert (
        main(["batch", str(tmp_path / "empty"), "-o", str(tmp_path / "o"), "--workers", "-1"]) == 2
    )
    with pytest.raises(InputError, match="no cases found"):
        run_batch(tmp_path / "empty", tmp_path / "o", CONFIG)
    with pytest.raises(OptionError, match="workers"):
        run_batch(tmp_path / "empty", tmp_path / "o", CONFIG, workers=-2)
    with pytest.raises(OptionError, match="OUTDIR must differ from INDIR"):
        run_batch(tmp_path / "empty", tmp_path / "empty", CONFIG)


def test_resume_key_follows_the_weights_file_contents(tmp_path: Path) -> None:
    from pipelines.batch import case_key
    from pipelines.discover import discover_cases
    from slicerecon.io.nifti import write_nifti
    from slicerecon.reconstruct import ReconstructConfig
    from slicerecon.shapes import make_shape

    write_nifti(make_shape("sphere", radius=6.0), tmp_path / "in" / "a.nii.gz")
    (case,) = discover_cases(tmp_path / "in")
    weights = tmp_path / "actor.safetensors"
    weights.write_bytes(b"first")
    config = ReconstructConfig(planner="policy", weights=str(weights))
    first = case_key(case, config)
    assert case_key(case, config) == first
    weights.write_bytes(b"second")
    assert case_key(case, config) != first


def test_batch_checks_the_weights_before_any_case(tmp_path, capsys):
    indir = tmp_path / "in"
    indir.mkdir()
    write_nifti(make_shape("sphere"), indir / "a.nii.gz")
    weights = tmp_path / "actor.safetensors"
    weights.write_bytes(b"stand-in: never read, the planner is not policy")
    out = tmp_path / "o"
    args = ["batch", str(indir), "-o", str(out), "--workers", "0"]
    assert main([*args, "--planner", "policy", "--weights", str(tmp_path / "none.pt")]) == 2
    assert "weights file not found" in capsys.readouterr().err
    assert main([*args, "--weights", str(weights)]) == 2
    assert "policy only" in capsys.readouterr().err
    assert not (out / "a").exists()


# ---------------------------------------------------------------------- symbolic links
def _linked_tree(tmp_path: Path) -> tuple[Path, Path]:
    """INDIR with links inside it, to outside it, a loop, a broken link and a DICOM folder
    with a link to an outside file; OUTSIDE with a mask and a folder of masks."""
    indir, outside = tmp_path / "in", tmp_path / "outside"
    ball = make_shape("sphere", radius=5.0)
    write_nifti(ball, indir / "real.nii.gz")
    write_nifti(ball, outside / "secret.nii.gz")
    write_nifti(make_shape("sphere", radius=6.0), outside / "cohort" / "p1.nii.gz")
    (outside / "cohort" / "back").symlink_to(outside / "cohort")  # a loop out there
    (indir / "inside.nii.gz").symlink_to(indir / "real.nii.gz")
    (indir / "stolen.nii.gz").symlink_to(outside / "secret.nii.gz")
    (indir / "cohort").symlink_to(outside / "cohort")
    (indir / "again").symlink_to(indir)  # a loop inside INDIR
    (indir / "gone.nii.gz").symlink_to(indir / "missing.nii.gz")
    (indir / "notes.txt").symlink_to(indir / "missing.txt")  # broken, not an input: ignored
    affine = factory.affine_from_geometry([1, 0, 0], [0, 1, 0], [1, 1], [0, 0, 1], [0, 0, 0])
    factory.write_series(indir / "series", ball.mask.astype(np.uint16), affine)
    (indir / "series" / "extra.dcm").symlink_to(outside / "secret.nii.gz")
    return indir, outside


def test_links_outside_indir_are_not_followed_but_reported(tmp_path):
    indir, outside = _linked_tree(tmp_path)
    cases = {c.relpath: c for c in discover_cases(indir)}
    assert set(cases) == {
        "real.nii.gz",
        "inside.nii.gz",
        "stolen.nii.gz",
        "cohort",
        "gone.nii.gz",
        "series",
    }
    assert cases["inside.nii.gz"].kind == "nifti" and not cases["inside.nii.gz"].error
    assert cases["real.nii.gz"].kind == "nifti"
    for rel in ("stolen.nii.gz", "cohort", "gone.nii.gz", "series"):
        case = cases[rel]
        assert case.kind == "symlink" and case.files == (), rel
    for rel in ("stolen.nii.gz", "cohort", "series"):
        assert "--follow-symlinks" in cases[rel].error, cases[rel].error
    assert "outside INDIR" in cases["stolen.nii.gz"].error
    assert str(outside / "secret.nii.gz") in cases["stolen.nii.gz"].error
    assert "folder outside INDIR" in cases["cohort"].error
    assert "broken" in cases["gone.nii.gz"].error
    assert "fix or remove the link" in cases["gone.nii.gz"].error
    # the series folder holds a link to an outside file: its DICOM files make no case
    assert "extra.dcm" in cases["series"].error and "DICOM" in cases["series"].error


def test_follow_symlinks_reads_outside_targets_without_looping(tmp_path):
    indir, _ = _linked_tree(tmp_path)
    cases = {c.relpath: c for c in discover_cases(indir, follow_symlinks=True)}
    assert set(cases) == {
        "real.nii.gz",
        "inside.nii.gz",
        "stolen.nii.gz",
        "cohort/p1.nii.gz",
        "gone.nii.gz",
        "series",
    }
    assert cases["stolen.nii.gz"].kind == "nifti" and not cases["stolen.nii.gz"].error
    assert cases["cohort/p1.nii.gz"].kind == "nifti"
    assert cases["series"].kind == "dicom-series"
    assert cases["gone.nii.gz"].kind == "symlink"  # a broken link stays unreadable


def test_batch_records_unfollowed_links_as_failed_without_reading_them(tmp_path, capsys):
    indir, _ = _linked_tree(tmp_path)
    out = tmp_path / "out"
    args = ["batch", str(indir), "-o", str(out), "--workers", "0", "--slices", "6", "--no-report"]
    assert main(args) == 1
    captured = capsys.readouterr()
    assert "6 cases: 2 ok, 4 failed" in captured.out
    assert "failed stolen: InputError" in " ".join(captured.err.split())
    rows = _summary(out)
    assert {k: r["status"] for k, r in rows.items()} == {
        "real": "ok",
        "inside": "ok",
        "stolen": "failed",
        "cohort": "failed",
        "gone": "failed",
        "series": "failed",
    }
    assert rows["stolen"]["kind"] == "symlink" and "outside INDIR" in rows["stolen"]["error"]
    # the target is a good mask: had it been read, the case would have succeeded
    assert sorted(p.name for p in (out / "stolen").iterdir()) == ["error.json"]
    error = json.loads((out / "stolen" / "error.json").read_text())
    assert error["type"] == "InputError" and "--follow-symlinks" in error["error"]

    followed = run_batch(
        indir, tmp_path / "out2", CONFIG, workers=0, report=False, follow_symlinks=True
    )
    status = {c.case: c.status for c in followed.cases}
    assert status["stolen"] == "ok" and status["cohort__p1"] == "ok"
    assert status["gone"] == "failed"


def test_follow_symlinks_option_of_the_batch_command(tmp_path, capsys):
    indir, outside = tmp_path / "in", tmp_path / "outside"
    write_nifti(make_shape("sphere", radius=5.0), outside / "p1.nii.gz")
    indir.mkdir()
    (indir / "p1.nii.gz").symlink_to(outside / "p1.nii.gz")
    args = [
        "batch",
        str(indir),
        "-o",
        str(tmp_path / "out"),
        "--workers",
        "0",
        "--slices",
        "6",
        "--no-report",
    ]
    assert main(args) == 1
    assert "1 cases: 0 ok, 1 failed" in capsys.readouterr().out
    assert main([*args, "--follow-symlinks"]) == 0
    assert "1 cases: 1 ok, 0 failed" in capsys.readouterr().out


# ------------------------------------------------------------------------- interruption
def test_a_ctrl_c_in_a_publish_waits_until_both_renames_are_done():
    import signal

    from pipelines.publish import sigint_deferred as _sigint_deferred

    done = []
    # Python's own Ctrl-C handler, as in a terminal: a job started in the background
    # by a non-interactive shell inherits SIGINT ignored, and Python then keeps it so
    outer = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            with _sigint_deferred():
                signal.raise_signal(signal.SIGINT)
                done.append("after the signal")
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    finally:
        signal.signal(signal.SIGINT, outer)
    assert done == ["after the signal"]


def test_a_result_left_aside_by_a_killed_publish_is_restored(tmp_path):
    from pipelines.publish import clear_stale as _clear_stale

    (tmp_path / ".a.old-123456789abc").mkdir()
    (tmp_path / ".a.old-123456789abc" / "done.json").write_text("{}")
    (tmp_path / ".a.partial-123456789abc").mkdir()
    _clear_stale(tmp_path, "a")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a"]
    assert (tmp_path / "a" / "done.json").read_text() == "{}"


def test_interrupted_in_process_batch_keeps_finished_cases_and_resumes(tmp_path, monkeypatch):
    import slicerecon.case as reconstruct

    indir = tmp_path / "in"
    for name, radius in (("a", 5.0), ("b", 6.0), ("c", 5.5)):
        write_nifti(make_shape("sphere", radius=radius), indir / f"{name}.nii.gz")
    out = tmp_path / "out"
    real_run_case = reconstruct.run_case

    def ctrl_c_on_b(path, staging, *args, **kwargs):
        if Path(path).name == "b.nii.gz":
            Path(staging).mkdir(parents=True, exist_ok=True)
            (Path(staging) / "half.stl").write_bytes(b"half")
            raise KeyboardInterrupt
        return real_run_case(path, staging, *args, **kwargs)

    monkeypatch.setattr(reconstruct, "run_case", ctrl_c_on_b)
    with pytest.raises(KeyboardInterrupt):
        run_batch(indir, out, CONFIG, workers=0, report=False)
    assert sorted(p.name for p in out.iterdir()) == ["a"]  # no b, no staging, no summary
    assert (out / "a" / "done.json").is_file()
    monkeypatch.setattr(reconstruct, "run_case", real_run_case)
    result = run_batch(indir, out, CONFIG, workers=0, report=False)
    assert [(c.case, c.status) for c in result.cases] == [
        ("a", "skipped"),
        ("b", "ok"),
        ("c", "ok"),
    ]
    assert not _hidden_or_temporary(out)


@pytest.mark.slow
@pytest.mark.skipif(sys.platform == "win32", reason="POSIX signals and process groups")
def test_ctrl_c_prints_one_line_exits_130_and_a_rerun_resumes(tmp_path):
    """Ctrl-C as a terminal sends it (SIGINT to the whole process group) while a
    2-worker local cluster computes: one `interrupted` line, exit 130, a clean OUTDIR."""
    import signal
    import subprocess
    import time

    indir, out = tmp_path / "in", tmp_path / "out"
    for name, radius in (("a", 18.0), ("b", 20.0), ("c", 22.0)):
        write_nifti(make_shape("sphere", radius=radius), indir / f"{name}.nii.gz")
    args = ["batch", str(indir), "-o", str(out), "--workers", "2", "--slices", "8", "--no-report"]
    proc = subprocess.Popen(
        [sys.executable, "-m", "slicerecon.cli", *args],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    try:
        deadline = time.monotonic() + 180
        while not (out.is_dir() and any(p.name.startswith(".") for p in out.iterdir())):
            assert proc.poll() is None and time.monotonic() < deadline, "no case started"
            time.sleep(0.05)
        time.sleep(0.5)  # cases in flight, inside the workers
        os.killpg(proc.pid, signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.communicate()
    assert proc.returncode == 130, stderr
    # Rich's transient progress bar leaves an empty line when stderr is not a terminal
    assert [line for line in stderr.splitlines() if line.strip()] == ["interrupted"], stderr
    assert stdout == ""
    assert not _hidden_or_temporary(out)  # no staging folder left
    finished = sorted(p.name for p in out.iterdir())
    assert "summary.csv" not in finished
    for name in finished:  # whatever is there is whole
        assert (out / name / "done.json").is_file() and (out / name / "mesh.stl").is_file()

    result = run_batch(indir, out, ReconstructConfig(slices=8), workers=0, report=False)
    assert {c.case: c.status for c in result.cases} == {
        n: ("skipped" if n in finished else "ok") for n in ("a", "b", "c")
    }
    assert not _hidden_or_temporary(out)


@pytest.mark.parametrize("workers", ["0", "1"])  # in this process, and on a Dask worker
def test_a_cases_warnings_reach_the_user_with_its_name_and_stay_in_done_json(
    tmp_path, capsys, workers
):
    mask = make_shape("sphere", radius=8.0)
    gapped = mask.mask & ((np.arange(mask.mask.shape[2]) % 8) < 4)[None, None, :]
    write_nifti(type(mask)(gapped, mask.affine), tmp_path / "in" / "gapped.nii.gz")
    out = tmp_path / "out"
    args = ["batch", str(tmp_path / "in"), "-o", str(out), "--workers", workers, "--no-report"]
    assert main(args) == 0
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if "runs of empty slices" in line]
    assert len(lines) == 1 and lines[0].startswith("warning: gapped: ")
    done = json.loads((out / "gapped" / "done.json").read_text())
    assert len([w for w in done["result"]["warnings"] if "runs of empty slices" in w]) == 1


def test_a_case_missing_any_of_its_files_is_computed_again(tmp_path):
    write_nifti(make_shape("sphere", radius=5.0), tmp_path / "in" / "ball.nii.gz")
    out = tmp_path / "out"
    assert run_batch(tmp_path / "in", out, CONFIG, workers=0, report=False).n_ok == 1
    (out / "ball" / "labels.nii.gz").unlink()
    again = run_batch(tmp_path / "in", out, CONFIG, workers=0, report=False)
    assert [c.status for c in again.cases] == ["ok"]
    assert (out / "ball" / "labels.nii.gz").is_file()


def test_slices_apply_to_the_dense_cases_of_a_batch_and_leave_annotations_alone(tmp_path):
    ball = make_shape("sphere", radius=8.0)
    sparse = ball.mask & (np.arange(ball.mask.shape[2]) % 4 == 0)[None, None, :]
    write_nifti(ball, tmp_path / "in" / "dense.nii.gz")
    write_nifti(type(ball)(sparse, ball.affine), tmp_path / "in" / "sparse.nii.gz")
    config = ReconstructConfig(n_points=5000, slices=6)
    result = run_batch(tmp_path / "in", tmp_path / "out", config, workers=0, report=False)
    assert {c.case: c.status for c in result.cases} == {"dense": "ok", "sparse": "ok"}
    assert {c.case: c.planes for c in result.cases}["dense"] == 6


def test_an_earlier_batchs_results_inside_indir_are_not_read_as_inputs(tmp_path):
    write_nifti(make_shape("sphere", radius=5.0), tmp_path / "in" / "ball.nii.gz")
    first = run_batch(tmp_path / "in", tmp_path / "in" / "results", CONFIG, workers=0)
    assert first.n_ok == 1 and (tmp_path / "in" / "results" / "summary.csv").is_file()
    second = run_batch(tmp_path / "in", tmp_path / "out", CONFIG, workers=0, report=False)
    assert [c.case for c in second.cases] == ["ball"] and second.ok


def test_the_report_of_a_batch_counts_only_the_cases_of_its_run(tmp_path):
    write_nifti(make_shape("sphere", radius=5.0), tmp_path / "in" / "a.nii.gz")
    write_nifti(make_shape("sphere", radius=6.0), tmp_path / "in" / "b.nii.gz")
    out = tmp_path / "out"
    assert run_batch(tmp_path / "in", out, CONFIG, workers=0).n_ok == 2
    (tmp_path / "in" / "b.nii.gz").unlink()  # its folder stays, from the earlier run
    again = run_batch(tmp_path / "in", out, CONFIG, workers=0)
    assert [c.case for c in again.cases] == ["a"] and (out / "b").is_dir()
    assert json.loads((out / "summary.json").read_text())["n_cases"] == 1


def test_a_dataset_folder_is_a_batch_without_its_manifest(tmp_path, capsys):
    """``slicerecon dataset make`` then ``slicerecon batch`` on its folder (the documented
    workflow) failed one case: the dataset's own manifest.json, read as a contour file."""
    assert main(["dataset", "make", str(tmp_path / "in"), "--shapes", "sphere"]) == 0
    found = discover(tmp_path / "in")
    assert [c.kind for c in found.cases] == ["nifti"]
    left = {s.relpath: s.reason for s in found.skipped}
    assert "dataset's manifest" in left["manifest.json"]
    # named alone, it is refused in one line that says what to pass
    capsys.readouterr()
    assert main(["run", str(tmp_path / "in" / "manifest.json"), "-o", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "pass its folder to 'slicerecon batch'" in err[0]


def test_a_nrrd_header_with_detached_voxels_is_said_to_be_one_in_run_and_batch(tmp_path, capsys):
    """A Slicer .seg.nhdr got "cannot tell the format ... expected NRRD (.nrrd/.seg.nrrd)"
    from run, and "not an input format" from batch."""
    import nrrd

    (tmp_path / "in").mkdir()
    header = tmp_path / "in" / "liver.seg.nhdr"
    nrrd.write(str(header), np.zeros((4, 4, 4), np.uint8), detached_header=True)
    assert main(["run", str(header), "-o", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "save it as one .nrrd file with attached data" in err[0]
    left = {s.relpath: s.reason for s in discover(tmp_path / "in").skipped}
    assert "separate file (.nhdr)" in left["liver.seg.nhdr"]


def test_a_bad_batch_invocation_is_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Piped, the progress bar's live display printed a blank line before the error."""
    (tmp_path / "empty").mkdir()
    assert main(["batch", str(tmp_path / "empty"), "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: no cases found") and err.count("\n") == 1


@pytest.mark.slow
def test_an_unreachable_scheduler_is_refused_before_anything_is_written(tmp_path: Path) -> None:
    """A broken link among the inputs was recorded as a failed case (``error.json``)
    before the connection to the scheduler failed (20 s)."""
    indir = tmp_path / "in"
    indir.mkdir()
    write_nifti(make_shape("sphere", radius=6.0), indir / "ball.nii.gz")
    (indir / "stolen.nii.gz").symlink_to(tmp_path / "absent.nii.gz")
    with pytest.raises(OptionError, match="cannot reach the Dask scheduler"):
        run_batch(indir, tmp_path / "out", CONFIG, scheduler="tcp://127.0.0.1:1", report=False)
    assert not (tmp_path / "out").exists()
