"""Every script in examples/ runs as a user would run it and leaves what it promises."""

from __future__ import annotations

import csv
import subprocess
import sys
from pathlib import Path

import pytest
import trimesh

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def _run(script: str, outdir: Path, timeout: float = 300.0) -> str:
    done = subprocess.run(
        [sys.executable, str(EXAMPLES / script), str(outdir)],
        capture_output=True,
        text=True,
        timeout=timeout,
        cwd=outdir,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    return done.stdout


def test_single_case(tmp_path):
    out = _run("single_case.py", tmp_path)
    assert "watertight: True" in out and "volume_iou" in out
    assert trimesh.load(tmp_path / "mesh.stl").is_watertight
    for name in ("mask.nii.gz", "plan.json", "metrics.json", "preview.png"):
        assert (tmp_path / name).is_file()
    iou = float(next(line for line in out.splitlines() if "volume_iou" in line).split()[-1])
    assert iou > 0.8


def test_rtstruct_to_mesh(tmp_path):
    out = _run("rtstruct_to_mesh.py", tmp_path)
    assert "9 planes" in out and "watertight: True" in out
    mesh = trimesh.load(tmp_path / "lesion.stl")
    assert mesh.is_watertight
    # the ball of radius 15 mm cut at z = ±12 mm holds 13 345 mm³
    assert mesh.volume == pytest.approx(13345.5, rel=0.1)
    lo, hi = mesh.bounds
    assert lo[2] == pytest.approx(-12.0, abs=3.0) and hi[2] == pytest.approx(12.0, abs=3.0)


@pytest.mark.slow
def test_batch_directory(tmp_path):
    out = _run("batch_directory.py", tmp_path)
    assert "corrupt: FormatError" in out
    with open(tmp_path / "results" / "summary.csv", newline="") as fh:
        rows = {row["case"]: row for row in csv.DictReader(fh)}
    assert len(rows) == 7 and rows["corrupt"]["status"] == "failed"
    finished = [name for name, row in rows.items() if row["status"] == "ok"]
    assert len(finished) >= 5
    for name in finished:
        assert trimesh.load(tmp_path / "results" / name / "mesh.stl").is_watertight
    again = _run("batch_directory.py", tmp_path)  # resume: nothing left to compute
    assert f"0 ok, {7 - len(finished)} failed, {len(finished)} skipped" in again
