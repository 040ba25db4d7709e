"""The command-line contract: outputs of ``run``, one-line errors, exit codes."""

from __future__ import annotations

import gzip
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh

from slicerecon.cli import main
from slicerecon.io.nifti import write_nifti
from slicerecon.sections import Volume
from slicerecon.shapes import make_shape


@pytest.fixture(scope="module")
def chair_nii(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("in") / "chair.nii.gz"
    write_nifti(make_shape("chair"), path)
    return path


def _one_error_line(capsys: pytest.CaptureFixture[str]) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith("error: ")
    assert "Traceback" not in err[0]
    return err[0]


def test_help_lists_the_commands(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["--help"]) == 0
    out = capsys.readouterr().out
    for command in ("run", "info", "evaluate"):
        assert command in out


def test_run_writes_all_outputs_in_world_mm(
    chair_nii: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "chair"
    assert main(["run", str(chair_nii), "-o", str(out), "--slices", "12"]) == 0
    for name in ("mesh.stl", "plan.json", "metrics.json", "preview.png"):
        assert (out / name).stat().st_size > 0, name
    mesh = trimesh.load(out / "mesh.stl")
    assert mesh.is_watertight and mesh.is_winding_consistent
    truth = make_shape("chair")
    lo, hi = truth.bounding_box_mm()
    # The mesh overlays the mask in world coordinates (within two voxels).
    np.testing.assert_allclose(mesh.bounds[0], lo, atol=2.0)
    np.testing.assert_allclose(mesh.bounds[1], hi, atol=2.0)
    plan = json.loads((out / "plan.json").read_text())
    assert plan["sections"]["n_planes"] == 12
    assert len(plan["parts"]) >= 1
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["volume_iou"] > 0.8
    assert not list(out.glob("*.tmp*")), "temporary files left behind"


def test_run_every_k_and_other_format(chair_nii: Path, tmp_path: Path) -> None:
    out = tmp_path / "ply"
    code = main(
        [
            "run",
            str(chair_nii),
            "-o",
            str(out),
            "--every",
            "8",
            "--format",
            "ply",
            "--planner",
            "none",
            "--axis",
            "z",
        ]
    )
    assert code == 0
    assert trimesh.load(out / "mesh.ply").is_watertight
    plan = json.loads((out / "plan.json").read_text())
    indices = np.diff(plan["sections"]["plane_indices"])
    assert np.all(indices[:-1] == 8)


def test_info_reports_grid_and_labels(chair_nii: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["info", str(chair_nii), "--json"]) == 0
    details = json.loads(capsys.readouterr().out)
    assert details["format"] == "nifti"
    assert details["spacing_mm"] == [1.0, 1.0, 1.0]
    assert details["labels"] == {"1": int(make_shape("chair").mask.sum())}


def test_evaluate_prints_metrics_json(
    chair_nii: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["evaluate", str(chair_nii), str(chair_nii), "--n-points", "5000"]) == 0
    metrics = json.loads(capsys.readouterr().out)
    assert metrics["volume_iou"] == pytest.approx(1.0)
    assert metrics["chamfer_l1_mm"] == pytest.approx(0.0, abs=1e-9)


def test_scores_compare_files_of_either_world_frame(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """One off-centre ball as a NIfTI (RAS) and as an LPS NRRD: a run's LPS mesh scored
    against the NIfTI got volume IoU 0.39 (mirrored), and ``run --gt`` of the NRRD with the
    NIfTI as truth scored mirrored too, exit 0. Every score is now taken in one frame."""
    import nrrd

    ijk = np.indices((40, 36, 30)).astype(float)
    ball = ((ijk[0] - 28) ** 2 + (ijk[1] - 20) ** 2 + ((ijk[2] - 15) * 2) ** 2) < 9**2
    affine = np.diag([1.0, 1.0, 2.0, 1.0])
    affine[:3, 3] = [10.0, 30.0, -20.0]  # RAS
    write_nifti(Volume(ball, affine), tmp_path / "ball.nii.gz")
    lps = np.diag([-1.0, -1.0, 1.0, 1.0]) @ affine
    header = {
        "space": "left-posterior-superior",
        "space directions": lps[:3, :3].T,
        "space origin": lps[:3, 3],
    }
    nrrd.write(str(tmp_path / "ball.nrrd"), ball.astype(np.uint8), header)
    out = tmp_path / "out"
    truth = str(tmp_path / "ball.nii.gz")
    args = ["run", str(tmp_path / "ball.nrrd"), "--slices", "8", "--gt", truth, "-o", str(out)]
    assert main([*args, "-q"]) == 0
    scored = json.loads((out / "metrics.json").read_text())
    assert scored["volume_iou"] > 0.9, scored
    # a --gt of another shape scores that shape (it was passed over for the input itself)
    other = np.zeros_like(ball)
    other[2:8, 2:8, 2:8] = True
    write_nifti(Volume(other, affine), tmp_path / "other.nii.gz")
    args[-3] = str(tmp_path / "other.nii.gz")
    assert main([*args[:-1], str(tmp_path / "other"), "-q"]) == 0
    assert json.loads((tmp_path / "other" / "metrics.json").read_text())["volume_iou"] < 0.1
    capsys.readouterr()
    for prediction in (out / "mesh.stl", out / "labels.seg.nrrd"):
        assert main(["evaluate", str(prediction), truth, "--n-points", "2000"]) == 0
        assert json.loads(capsys.readouterr().out)["volume_iou"] > 0.9, prediction


# ------------------------------------------------------------------ bad input
def test_missing_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["run", str(tmp_path / "nope.nii.gz"), "-o", str(tmp_path / "o")]) == 2
    assert "nope.nii.gz" in _one_error_line(capsys)
    assert not (tmp_path / "o").exists()


def test_corrupt_nifti_header(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "bad.nii.gz"
    bad.write_bytes(gzip.compress(b"this is not a nifti header" * 20))
    assert main(["info", str(bad)]) == 2
    assert "bad.nii.gz" in _one_error_line(capsys)


def test_empty_mask(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = tmp_path / "empty.nii.gz"
    write_nifti(Volume(np.zeros((8, 8, 8), bool), np.eye(4)), path)
    assert main(["run", str(path), "-o", str(tmp_path / "o")]) == 2
    assert "empty" in _one_error_line(capsys).lower()


def test_missing_label(chair_nii: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["run", str(chair_nii), "--label", "7", "-o", str(tmp_path / "o")]) == 2
    assert "7" in _one_error_line(capsys)


def test_conflicting_options(
    chair_nii: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = ["run", str(chair_nii), "--slices", "8", "--every", "2", "-o", str(tmp_path / "o")]
    assert main(args) == 2
    assert "--every" in _one_error_line(capsys)


def test_non_parallel_contours(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    square = [[-5.0, -5.0], [5.0, -5.0], [5.0, 5.0], [-5.0, 5.0]]
    flat = [[x, y, 0.0] for x, y in square]
    tilted = [[x, y, 10.0 + 0.5 * x] for x, y in square]
    path = tmp_path / "tilted.json"
    path.write_text(
        json.dumps(
            {
                "format": "slicerecon-contours",
                "version": 1,
                "units": "mm",
                "planes": [{"polygons": [flat]}, {"polygons": [tilted]}],
            }
        )
    )
    assert main(["run", str(path), "-o", str(tmp_path / "o")]) == 2
    assert "parallel" in _one_error_line(capsys)


def test_failed_run_keeps_earlier_outputs(
    chair_nii: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "keep"
    assert main(["run", str(chair_nii), "-o", str(out), "--slices", "6"]) == 0
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    capsys.readouterr()
    empty = tmp_path / "empty.nii.gz"
    write_nifti(Volume(np.zeros((8, 8, 8), bool), np.eye(4)), empty)
    assert main(["run", str(empty), "-o", str(out)]) == 2
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


def test_console_script_exit_code_and_debug_traceback(tmp_path: Path) -> None:
    missing = str(tmp_path / "missing.nii")
    plain = subprocess.run(
        [sys.executable, "-m", "slicerecon.cli", "info", missing], capture_output=True, text=True
    )
    assert plain.returncode == 2
    assert plain.stderr.strip().count("\n") == 0 and "Traceback" not in plain.stderr
    debug = subprocess.run(
        [sys.executable, "-m", "slicerecon.cli", "--debug", "info", missing],
        capture_output=True,
        text=True,
    )
    # the traceback, and the exit code of bad input all the same (it was 1; docs/cli.md)
    assert debug.returncode == 2 and "Traceback" in debug.stderr
    assert debug.stderr.strip().splitlines()[-1].startswith("error: ")


def test_policy_planner_with_shipped_weights(chair_nii: Path, tmp_path: Path) -> None:
    out = tmp_path / "policy"
    args = ["run", str(chair_nii), "-o", str(out), "--planner", "policy", "--slices", "8"]
    assert main(args) == 0
    assert trimesh.load(out / "mesh.stl").is_watertight
    assert json.loads((out / "plan.json").read_text())["planner"] == "policy"


def test_weights_need_the_policy_planner(
    chair_nii: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["run", str(chair_nii), "--weights", "w.safetensors", "-o", str(tmp_path)]) == 2
    assert "policy" in _one_error_line(capsys)


def test_the_read_as_line_is_one_line_when_piped(tmp_path, capsys):
    """However long, the line saying how the input was read is not wrapped (grep finds it)."""
    import nibabel as nib
    import numpy as np

    x, y, z = np.meshgrid(*[np.arange(40)] * 3, indexing="ij")
    ball = ((x - 20) ** 2 + (y - 20) ** 2 + (z - 20) ** 2 < 144) & (z % 3 == 0)
    ball |= ((x - 20) ** 2 + (y - 20) ** 2 + (z - 20) ** 2 < 144) & np.isin(x, [14, 26])
    nib.save(nib.Nifti1Image(ball.astype(np.uint8), np.eye(4)), tmp_path / "views.nii.gz")
    assert main(["run", str(tmp_path / "views.nii.gz"), "-o", str(tmp_path / "out")]) == 0
    lines = [line for line in capsys.readouterr().out.splitlines() if line.startswith("read as:")]
    assert len(lines) == 1 and len(lines[0]) > 80 and lines[0].rstrip().endswith("mm")


def _documented_warning_inputs(root: Path) -> dict[str, tuple[list[str], str]]:
    """Inputs that give each warning docs/formats.md promises, with the words it says."""
    import dicom_factory as factory  # tests/io, on pytest's pythonpath
    import nibabel as nib

    x, y, z = np.meshgrid(*[np.arange(32)] * 3, indexing="ij")
    ball = (x - 16) ** 2 + (y - 16) ** 2 + (z - 16) ** 2 < 100
    affine = factory.affine_from_geometry(
        [1, 0, 0], [0, 1, 0], [1.0, 1.0], [0, 0, 2.0], [0.0, 0.0, 0.0]
    )
    flat = np.zeros((20, 20, 9), bool)
    flat[5:15, 5:15, 4] = True
    one_frame = factory.write_seg(root / "one.dcm", {1: flat}, affine, labels={1: "Flat"})
    both = factory.write_seg(
        root / "nested.dcm",
        {1: ball, 2: (x - 16) ** 2 + (y - 16) ** 2 + (z - 16) ** 2 < 25},
        affine,
        labels={1: "Organ", 2: "Lesion"},
    )
    thin = ball.astype(np.uint8)
    thin[2:5, 2:5, 14:16] = 2  # two slices between the kept planes
    nib.save(nib.Nifti1Image(thin, np.eye(4)), root / "thin.nii.gz")
    ring = [factory.contour_item(factory.circle(8.0, (0.0, 0.0), z)) for z in (0.0, 4.0, 8.0)]
    alone = factory.write_rtstruct(root / "rs.dcm", {(1, "Ball"): ring})
    return {
        "one plane": ([str(one_frame)], "one plane"),
        "no plane crosses it": ([str(root / "thin.nii.gz"), "--slices", "4"], "between"),
        "overlapping segments": ([str(both)], "overlap on"),
        "DICOM output skipped": ([str(alone)], "rtstruct.dcm and seg.dcm not written"),
        "SEG output skipped": ([str(both)], "seg.dcm not written"),
    }


@pytest.mark.parametrize(
    "name", ["one plane", "no plane crosses it", "DICOM output skipped", "SEG output skipped"]
)
def test_every_documented_warning_reaches_stderr_without_v(
    name: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv, words = _documented_warning_inputs(tmp_path)[name]
    assert main(["run", *argv, "-o", str(tmp_path / "out")]) == 0
    err = capsys.readouterr().err.splitlines()
    assert any(line.startswith("warning: ") and words in line for line in err), err
    assert main(["run", *argv, "-o", str(tmp_path / "quiet"), "-q"]) == 0
    assert capsys.readouterr().err == ""  # -q silences them


def test_overlapping_structures_are_said_with_the_summary_not_warned(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Nested ROIs (BODY > organ > GTV) are in every structure set: their overlap was a
    warning on every RT case (and in every batch's warnings column); it is how the label
    map holds them, said in the summary."""
    argv, words = _documented_warning_inputs(tmp_path)["overlapping segments"]
    assert main(["run", *argv, "-o", str(tmp_path / "out")]) == 0
    said = capsys.readouterr()
    warned = [line for line in said.err.splitlines() if line.startswith("warning")]
    # (the 9-plane lesion keeps all its planes under the default 16: said, and not here)
    unrelated = ("seg.dcm not written", "was kept")
    assert [line for line in warned if not any(u in line for u in unrelated)] == []
    (line,) = [x for x in said.out.splitlines() if x.startswith("overlaps: ")]
    assert words in line and "the smallest on top" in line


def test_a_run_that_keeps_every_plane_says_its_scores_test_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A dense mask spanning fewer planes than the default 16 kept them all and printed
    volume IoU 1 without a word (a 48-voxel torus of ``dataset make``)."""
    x, y, z = np.indices((30, 30, 14)) - np.array([14.5, 14.5, 6.5])[:, None, None, None]
    ball = (x / 12) ** 2 + (y / 10) ** 2 + (z / 5.5) ** 2 < 1  # 10 planes along z
    write_nifti(Volume(ball, np.eye(4)), tmp_path / "ball.nii.gz")
    assert main(["run", str(tmp_path / "ball.nii.gz"), "-o", str(tmp_path / "all")]) == 0
    said = [line for line in capsys.readouterr().err.splitlines() if "was kept" in line]
    assert len(said) == 1 and "every one of the 10 planes" in said[0] and "--slices" in said[0]
    run = ["run", str(tmp_path / "ball.nii.gz"), "--slices", "5", "-o", str(tmp_path / "five")]
    assert main(run) == 0
    assert "was kept" not in capsys.readouterr().err


def test_a_sparse_annotation_is_refused_as_a_ground_truth(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``evaluate`` scored a reconstruction against an annotation on every 3rd slice:
    volume IoU 0.33 where the true one was 0.985, exit 0. A ground truth that reads as a
    sparse annotation is refused in one line, by ``evaluate`` and by ``run --gt``."""
    x, y, z = np.indices((30, 30, 30)) - 14.5
    ball = x**2 + (y / 0.8) ** 2 + (z / 1.1) ** 2 < 12**2
    sparse = ball & (np.arange(30) % 3 == 0)[None, None, :]
    write_nifti(Volume(ball, np.eye(4)), tmp_path / "dense.nii.gz")
    write_nifti(Volume(sparse, np.eye(4)), tmp_path / "sparse.nii.gz")
    dense, drawn = str(tmp_path / "dense.nii.gz"), str(tmp_path / "sparse.nii.gz")
    assert main(["evaluate", dense, dense]) == 0
    capsys.readouterr()
    for argv in (
        ["evaluate", dense, drawn],
        ["run", drawn, "--gt", drawn, "-o", str(tmp_path / "o")],
    ):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "sparse annotation" in err[0] and "no ground truth" in err[0]
    assert not (tmp_path / "o").exists()


def test_info_describes_a_sparse_structure_as_an_annotation(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``info --label`` called a structure drawn on 5 axial and 1 sagittal slice a "voxel
    mask" with 19 occupied planes along z, and its drawn voxels its volume (3,743 mm³
    against 12,554)."""
    x, y, z = np.indices((40, 40, 30))
    ball = (x - 20) ** 2 + (y - 20) ** 2 + ((z - 15) * 1.2) ** 2 < 144
    drawn = np.zeros(ball.shape, bool)
    drawn[:, :, ::4], drawn[20] = True, True
    write_nifti(Volume(ball & drawn, np.eye(4)), tmp_path / "drawn.nii.gz")
    assert main(["info", str(tmp_path / "drawn.nii.gz"), "--label", "1", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    selected, (row,) = info["selected"], info["structures"]
    assert selected["kind"] == "sparse annotation" and "volume_mm3" not in selected
    assert "5 planes along z" in selected["read_as"] and "1 plane along x" in selected["read_as"]
    assert selected["drawn_volume_mm3"] == row["drawn_volume_mm3"] == (ball & drawn).sum()
