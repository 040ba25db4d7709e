"""A case on disk: the records of :mod:`slicerecon.results` and reading a results folder.

Folders are written by hand here (no reconstruction), so every expected value
is the one put in.
"""

from __future__ import annotations

import csv
import json
import os
from pathlib import Path

import pytest

from slicerecon.errors import InputError
from slicerecon.results import (
    SUMMARY_COLUMNS,
    CaseFiles,
    CaseResult,
    FailureRecord,
    ResultsLayout,
    collect_results,
    read_case,
    write_summary,
)

PLAN = {
    "parts": [
        {"box": {"lo": [0, 0, 0], "hi": [4, 4, 4]}},
        {"box": {"lo": [4, 0, 0], "hi": [8, 4, 4]}},
    ],
    "sections": {"axis": "z", "n_planes": 7},
    "input": "/data/ball.nii.gz",
    "ground_truth": None,
    "config": {"method": "loft", "planner": "heuristic", "label": None},
    "timings_s": {"read": 0.25, "plan": 0.5, "surface": 1.25},
}
METRICS = {"volume_iou": 0.91, "chamfer_l1_mm": 0.5, "n_points": 5000}


def _finished(folder: Path, *, done: dict | None = None) -> Path:
    folder.mkdir(parents=True)
    (folder / "plan.json").write_text(json.dumps(PLAN))
    (folder / "metrics.json").write_text(json.dumps(METRICS))
    (folder / "mesh.ply").write_bytes(b"ply")
    (folder / "preview.png").write_bytes(b"png")
    if done is not None:
        (folder / "done.json").write_text(json.dumps(done))
    return folder


def _failed(folder: Path, payload: dict) -> Path:
    folder.mkdir(parents=True)
    (folder / "error.json").write_text(json.dumps(payload))
    return folder


def test_a_finished_case_reads_back_every_field(tmp_path):
    folder = _finished(tmp_path / "ball")
    case = read_case(folder)
    assert case.case == "ball" and case.status == "ok" and case.ok
    assert (case.method, case.planner, case.group) == ("loft", "heuristic", "loft/heuristic")
    assert case.planes == 7 and case.parts == 2
    assert case.metrics == METRICS and isinstance(case.metrics["n_points"], int)
    assert case.stage_seconds == 2.0  # 0.25 + 0.5 + 1.25, exact in binary
    assert case.seconds is None and case.watertight is None  # only the runner knows these
    assert case.input == case.input_path == "/data/ball.nii.gz"
    assert case.mesh_path == folder / "mesh.ply" and case.preview_path == folder / "preview.png"
    assert case.error == case.error_text == ""


def test_done_json_adds_what_the_runner_measured(tmp_path):
    done = {
        "key": "k",
        "result": {
            "input": "ball.nii.gz",
            "kind": "nifti",
            "watertight": True,
            "seconds": 3.5,
            "parts": 2,
        },
    }
    case = read_case(_finished(tmp_path / "ball", done=done))
    assert (case.input, case.kind, case.watertight, case.seconds) == (
        "ball.nii.gz",
        "nifti",
        True,
        3.5,
    )
    assert case.input_path == "/data/ball.nii.gz"  # what the reconstruction read


def test_the_one_error_json_format_round_trips(tmp_path):
    record = FailureRecord.from_exception(
        ValueError("bad spacing"),
        case="a/loft",
        input="/d/a.nii.gz",
        kind="nifti",
        method="loft",
        planner="heuristic",
        traceback="Traceback ...",
    )
    path = record.write(tmp_path)
    payload = json.loads(path.read_text())
    assert payload["type"] == "ValueError" and payload["error"] == "bad spacing"
    assert {
        "case",
        "input",
        "kind",
        "error",
        "type",
        "method",
        "planner",
        "traceback",
        "slicerecon_version",
    } == set(payload)
    assert FailureRecord.from_json(payload) == record
    assert record.text == "ValueError: bad spacing"
    assert FailureRecord.from_exception(KeyError(), case="x", input=None).error == "KeyError"


@pytest.mark.parametrize(
    ("payload", "text", "method"),
    [
        # written by evaluate-dataset before the runner owned it: the type inside the message
        (
            {
                "case": "b/loft",
                "input": "b.nii.gz",
                "method": "loft",
                "planner": "heuristic",
                "error": "InputError: not found",
            },
            "InputError: not found",
            "loft",
        ),
        # written by batch before: "type", no method
        (
            {"case": "c", "input": "c.nii.gz", "error": "truncated gzip", "type": "FormatError"},
            "FormatError: truncated gzip",
            None,
        ),
        # "error_type" and a config object (documented by the report)
        (
            {"error": "boom", "error_type": "RuntimeError", "config": {"method": "sdf"}},
            "RuntimeError: boom",
            "sdf",
        ),
    ],
)
def test_older_error_json_formats_are_read(tmp_path, payload, text, method):
    case = read_case(_failed(tmp_path / "case", payload), name="case")
    assert case.status == "failed" and not case.ok
    assert case.error_text == text and case.method == method
    assert case.input == payload.get("input")


def test_the_newer_of_plan_and_error_wins(tmp_path):
    folder = _finished(tmp_path / "ball")
    (folder / "error.json").write_text(json.dumps({"error": "later failure", "type": "E"}))
    os.utime(folder / "plan.json", (1_000_000, 1_000_000))
    assert read_case(folder).error_text == "E: later failure"
    os.utime(folder / "error.json", (500_000, 500_000))
    assert read_case(folder).ok


def test_unreadable_files_give_failed_cases(tmp_path):
    folder = _finished(tmp_path / "ball")
    (folder / "metrics.json").write_text("{ nope")
    case = read_case(folder)
    assert not case.ok and "unreadable metrics.json" in case.error
    assert case.method == "loft"  # still known from plan.json
    bad = _failed(tmp_path / "bad", {})
    (bad / "error.json").write_text("[1, 2]")
    assert "unreadable error.json" in read_case(bad).error


def test_collect_results_walks_the_layout(tmp_path):
    root = tmp_path / "results"
    _finished(root / "ball" / "loft")
    _finished(root / "ball" / "sdf")
    _failed(root / "corrupt", {"error": "x"})
    _finished(root / ".ball.partial-0123")  # a running batch's staging folder
    _finished(root / "report_assets" / "cases")  # never a case
    (root / "ball" / "notes").mkdir()  # neither plan nor error: not a case
    cases = collect_results(root)
    assert [c.case for c in cases] == ["ball/loft", "ball/sdf", "corrupt"]
    layout = ResultsLayout(root)
    assert layout.case("ball/loft") == CaseFiles(root / "ball" / "loft")
    assert layout.case_name(root / "ball" / "loft") == "ball/loft"
    assert layout.case("ball/loft").find_mesh() == root / "ball" / "loft" / "mesh.ply"
    assert (layout.summary_csv.name, layout.metrics_csv.name, layout.report_html.name) == (
        "summary.csv",
        "metrics.csv",
        "report.html",
    )
    with pytest.raises(InputError, match="not found"):
        collect_results(tmp_path / "absent")
    with pytest.raises(InputError, match="not a directory"):
        collect_results(root / "ball" / "loft" / "plan.json")


def test_summary_rows(tmp_path):
    ok = CaseResult(
        "a",
        "a.nii.gz",
        "nifti",
        "ok",
        parts=2,
        planes=8,
        watertight=True,
        metrics={"volume_iou": 0.123456789, "n_points": 10},
        seconds=1.23456,
    )
    failed = CaseResult(
        "b", "b.nii.gz", "nifti", "failed", error="line one\nline two", error_type="FormatError"
    )
    path = write_summary([ok, failed], tmp_path / "summary.csv")
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert list(rows[0]) == list(SUMMARY_COLUMNS)
    assert rows[0]["volume_iou"] == "0.123457" and rows[0]["seconds"] == "1.235"
    assert rows[0]["watertight"] == "true" and rows[0]["dice"] == ""
    assert rows[1]["error"] == "line one line two" and rows[1]["seconds"] == ""
    assert failed.error_text == "FormatError: line one\nline two"
    with pytest.raises(ValueError, match="status"):
        CaseResult("c", status="done")  # type: ignore[arg-type]
