"""A batch of every input kind `run` reads: discovery, what is left out, resume."""

from __future__ import annotations

import csv
import importlib.util
import json
import sys
from pathlib import Path

import dicom_factory as factory  # tests/io, on pytest's pythonpath
import numpy as np
import trimesh

import pipelines.batch
from pipelines.batch import CaseResult
from pipelines.discover import discover
from slicerecon.cli import main
from slicerecon.io import detect_kind
from slicerecon.io.labelmap import write_label_map
from slicerecon.io.nifti import write_nifti
from slicerecon.io.nrrd_writer import write_seg_nrrd
from slicerecon.labels import Structure
from slicerecon.shapes import make_shape

TESTS = Path(__file__).resolve().parents[1]
ORGANS = (Structure(1, "liver"), Structure(2, "kidney"), Structure(3, "spleen"))


def _vti_writer():
    name = "slicerecon_tests_vti"
    if name not in sys.modules:
        spec = importlib.util.spec_from_file_location(name, TESTS / "io" / "test_vti.py")
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        spec.loader.exec_module(module)
    return sys.modules[name].write_vti


def _labels() -> np.ndarray:
    labels = np.zeros((30, 24, 20), np.uint8)
    labels[4:14, 4:18, 3:16] = 1
    labels[14:26, 4:18, 3:16] = 2
    labels[8:22, 18:22, 5:14] = 3
    return labels


def _write_inputs(indir: Path) -> None:
    """One case of every kind, a corrupt file and two files that are not inputs."""
    indir.mkdir(parents=True)
    write_nifti(make_shape("sphere", radius=6.0), indir / "single.nii.gz")
    affine = np.diag([1.0, 1.0, 2.0, 1.0])
    write_label_map(_labels(), affine, indir / "multi.nii.gz")
    write_seg_nrrd(_labels(), affine, ORGANS, indir / "organs.seg.nrrd")
    _vti_writer()(indir / "abdomen.vti", _labels(), spacing=(1.0, 1.0, 2.0))
    # a CT series with an RTSTRUCT of three ROIs beside it
    ct = factory.affine_from_geometry([1, 0, 0], [0, 1, 0], [1, 1], [0, 0, 2], [0, 0, 0])
    files = factory.write_series(
        indir / "patient", np.full((40, 40, 12), 1000, np.uint16), ct, modality="CT"
    )
    uids = factory.read_uids(files)
    rois = {}
    for number, (name, centre, radius) in enumerate(
        [("GTV", (12, 12), 5.0), ("Liver", (27, 12), 6.0), ("Cord", (20, 28), 4.0)], start=1
    ):
        rois[(number, name)] = [
            factory.contour_item(
                factory.circle(radius - 0.4 * abs(k - 6), centre, 2.0 * k), image_uid=uids[k]
            )
            for k in range(3, 10)
        ]
    factory.write_rtstruct(indir / "patient" / "rs.dcm", rois)
    (indir / "corrupt.nii.gz").write_bytes((indir / "single.nii.gz").read_bytes()[:40])
    (indir / "notes.txt").write_text("not an input")
    trimesh.creation.icosphere().export(indir / "truth.stl")


def _snapshot(outdir: Path) -> dict[str, int]:
    """Every file below ``outdir``'s case folders and its modification time."""
    return {
        p.relative_to(outdir).as_posix(): p.stat().st_mtime_ns
        for p in outdir.rglob("*")
        if p.is_file() and p.parent != outdir and "report_assets" not in p.parts
    }


def test_discovery_takes_every_format_run_reads_and_says_what_it_left_out(tmp_path):
    _write_inputs(tmp_path / "in")
    found = discover(tmp_path / "in")
    kinds = {c.relpath: c.kind for c in found.cases}
    assert kinds == {
        "abdomen.vti": "vti",
        "corrupt.nii.gz": "nifti",
        "multi.nii.gz": "nifti",
        "organs.seg.nrrd": "nrrd",
        "patient/rs.dcm": "rtstruct",
        "single.nii.gz": "nifti",
    }
    for case in found.cases:  # discovery and `run` agree on every kind
        if case.kind != "rtstruct":
            assert detect_kind(case.path).kind == case.kind
    assert {c.name for c in found.cases} >= {"organs", "abdomen", "patient__rs"}
    reasons = {s.relpath: s.reason for s in found.skipped}
    assert set(reasons) == {"notes.txt", "truth.stl"}
    assert "mesh" in reasons["truth.stl"] and "not an input" in reasons["notes.txt"]


def test_a_mixed_batch_rerun_recomputes_nothing(tmp_path, capsys, monkeypatch):
    _write_inputs(tmp_path / "in")
    out = tmp_path / "out"
    args = ["batch", str(tmp_path / "in"), "-o", str(out), "--workers", "0", "--slices", "6"]
    assert main(args) == 1  # the corrupt file fails
    printed = capsys.readouterr()
    assert "6 cases: 5 ok, 1 failed, 0 skipped" in printed.out
    assert "2 entries of INDIR left out" in printed.err
    assert "left out notes.txt: not an input format" in printed.err
    assert "left out truth.stl: a mesh" in printed.err

    with open(out / "summary.csv", newline="") as fh:
        rows = {row["case"]: row for row in csv.DictReader(fh)}
    several = {"multi": 3, "organs": 3, "abdomen": 3, "patient__rs": 3}
    for case, n in several.items():
        assert rows[case]["status"] == "ok" and rows[case]["watertight"] == "true"
        done = json.loads((out / case / "done.json").read_text())
        assert len(done["meshes"]) == n and all(m.startswith("meshes/") for m in done["meshes"])
        for mesh in done["meshes"]:
            assert trimesh.load(out / case / mesh).is_watertight
    assert json.loads((out / "single" / "done.json").read_text())["meshes"] == ["mesh.stl"]
    assert rows["patient__rs"]["kind"] == "rtstruct"  # --slices does not apply to contours
    assert rows["corrupt"]["status"] == "failed" and rows["corrupt"]["error_type"] == "FormatError"

    before = _snapshot(out)

    computed = []

    def process_case(case, outdir, config, key, *, folder):
        computed.append(folder)
        return CaseResult(case=folder, status="failed", error="not run in this test")

    monkeypatch.setattr(pipelines.batch, "process_case", process_case)
    assert main(args) == 1
    assert "6 cases: 0 ok, 1 failed, 5 skipped" in capsys.readouterr().out
    assert computed == ["corrupt"]  # only the failed case is tried again
    assert _snapshot(out) == before  # no file of a finished case was touched
