"""What the command line shows while it works: stage progress in a terminal and when piped."""

from __future__ import annotations

import io
import re
import time
from pathlib import Path

import numpy as np
import pytest

from slicerecon.cli import main
from slicerecon.console import StageProgress
from slicerecon.io.labelmap import write_label_map
from slicerecon.io.nifti import write_nifti
from slicerecon.shapes import make_shape

LINE = re.compile(r"^progress: (.+) \((\d+\.\d) s\)$")


@pytest.fixture
def three_organs(tmp_path: Path) -> Path:
    labels = np.zeros((30, 24, 20), np.uint8)
    labels[4:14, 4:18, 3:16] = 1
    labels[14:26, 4:18, 3:16] = 2
    labels[8:22, 18:22, 5:14] = 3
    return write_label_map(labels, np.diag([1.0, 1.0, 2.0, 1.0]), tmp_path / "organs.nii.gz")


def _progress_lines(text: str) -> list[str]:
    return [line for line in text.splitlines() if line.startswith("progress:")]


def test_a_piped_run_prints_one_plain_line_per_stage_and_structure(
    three_organs: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch
) -> None:
    monkeypatch.setattr(StageProgress, "DELAY_S", 0.0)  # as if the run were long
    assert main(["run", str(three_organs), "-o", str(tmp_path / "out"), "--slices", "6"]) == 0
    lines = _progress_lines(capsys.readouterr().err)
    stages = [LINE.match(line).group(1) for line in lines]  # every line has the plain form
    assert {"reconstruct 1/3: 1", "reconstruct 2/3: 2", "reconstruct 3/3: 3", "write"} <= set(
        stages
    )
    assert stages.index("reconstruct 3/3: 3") < stages.index("write")
    assert len(stages) == len(set(stages))  # one line per stage, never repeated
    seconds = [float(LINE.match(line).group(2)) for line in lines]
    assert seconds == sorted(seconds)
    assert not any("\x1b" in line for line in lines)  # no terminal control codes


def test_a_quick_run_prints_no_progress(
    three_organs: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch
) -> None:
    monkeypatch.setattr(StageProgress, "DELAY_S", 600.0)
    assert main(["run", str(three_organs), "-o", str(tmp_path / "out"), "--slices", "6"]) == 0
    assert not _progress_lines(capsys.readouterr().err)


def test_quiet_runs_show_no_progress(
    three_organs: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch
) -> None:
    monkeypatch.setattr(StageProgress, "DELAY_S", 0.0)
    assert main(["run", str(three_organs), "-o", str(tmp_path / "out"), "-q"]) == 0
    assert capsys.readouterr().err == ""


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_in_a_terminal_the_stage_is_a_spinner_not_lines(monkeypatch) -> None:
    monkeypatch.setattr(StageProgress, "DELAY_S", 0.0)
    stream = _Terminal()
    with StageProgress(enabled=True, stream=stream) as progress:
        assert not progress.plain
        time.sleep(0.2)
        progress("reconstruct 1/2: 1_liver")
        time.sleep(0.2)
    assert "progress:" not in stream.getvalue()
    piped = io.StringIO()
    with StageProgress(enabled=True, stream=piped) as progress:
        assert progress.plain
        time.sleep(0.1)
        progress("reconstruct 1/2: 1_liver")
    assert _progress_lines(piped.getvalue())[-1].startswith("progress: reconstruct 1/2: 1_liver")


def test_a_piped_batch_prints_one_line_per_case(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    for name, radius in (("a", 5.0), ("b", 6.0)):
        write_nifti(make_shape("sphere", radius=radius), tmp_path / "in" / f"{name}.nii.gz")
    args = ["batch", str(tmp_path / "in"), "-o", str(tmp_path / "out"), "--workers", "0"]
    assert main([*args, "--slices", "6", "--no-report"]) == 0
    lines = _progress_lines(capsys.readouterr().err)
    assert lines == ["progress: case 1/2 ok: a", "progress: case 2/2 ok: b"]
