"""Evaluation reports: ``write_report`` outputs, ``slicerecon report`` and ``evaluate-dataset``.

The report is meant to be opened in a browser. No browser is available in the
test environment, so "the page loads and its images decode" is checked the way
a browser would start: the HTML is parsed with :mod:`html.parser` and every
``<img src="data:...">`` is base64-decoded and opened with Pillow, then checked
for a plausible size and non-blank content.
"""

from __future__ import annotations

import ast
import base64
import csv
import io
import json
import re
import shutil
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from slicerecon.case import run_case
from slicerecon.cli import main
from slicerecon.io.mesh import read_mesh
from slicerecon.io.nifti import write_nifti
from slicerecon.reconstruct import ReconstructConfig
from slicerecon.report import collect_results, write_report
from slicerecon.shapes import make_shape
from slicerecon.surface.marching import volume_to_mesh

SHAPES = {  # name: (shape, planes kept)
    "sphere": (lambda: make_shape("sphere", radius=8.0), 8),
    "box": (lambda: make_shape("box", size=(16.0, 12.0, 10.0)), 5),
}
METHODS = ("loft", "sdf")
FAILURE = "InputError: input <missing.nii.gz> & its friends were not found"


class _Page(HTMLParser):
    """Collects image sources, table rows and the visible text of an HTML page."""

    def __init__(self) -> None:
        super().__init__(convert_charrefs=True)
        self.images: list[str] = []
        self.text: list[str] = []
        self.figcaptions: list[str] = []
        self._in_caption = False
        self.open_tags: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        if tag == "img":
            self.images.append(dict(attrs)["src"] or "")
        if tag == "figcaption":
            self._in_caption = True
            self.figcaptions.append("")

    def handle_endtag(self, tag: str) -> None:
        if tag == "figcaption":
            self._in_caption = False

    def handle_data(self, data: str) -> None:
        self.text.append(data)
        if self._in_caption:
            self.figcaptions[-1] += data


def _parse(path: Path) -> _Page:
    page = _Page()
    page.feed(path.read_text(encoding="utf-8"))
    page.close()
    return page


def _decode(src: str) -> Image.Image:
    prefix = "data:image/png;base64,"
    assert src.startswith(prefix), src[:40]
    image = Image.open(io.BytesIO(base64.b64decode(src[len(prefix) :], validate=True)))
    image.load()
    return image


@pytest.fixture(scope="module")
def results(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two shapes x two methods reconstructed with run_case, plus one failed case."""
    base = tmp_path_factory.mktemp("report")
    root = base / "results"
    for name, (make, planes) in SHAPES.items():
        mask = base / f"{name}.nii.gz"
        write_nifti(make(), mask)
        for method in METHODS:
            config = ReconstructConfig(method=method, slices=planes, n_points=5000)
            run_case(mask, root / name / method, config)
    failed = root / "broken" / "loft"
    failed.mkdir(parents=True)
    (failed / "error.json").write_text(
        json.dumps(
            {
                "case": "broken/loft",
                "input": "missing.nii.gz",
                "method": "loft",
                "planner": "heuristic",
                "error": FAILURE,
            }
        )
    )
    return root


@pytest.fixture(scope="module")
def report(results: Path) -> Path:
    return write_report(results, title="Spheres & boxes <test>")


def test_collect_results_reads_every_case(results: Path) -> None:
    cases = collect_results(results)
    assert [c.case for c in cases] == [
        "box/loft",
        "box/sdf",
        "broken/loft",
        "sphere/loft",
        "sphere/sdf",
    ]
    by_name = {c.case: c for c in cases}
    assert by_name["sphere/sdf"].method == "sdf"
    assert by_name["sphere/sdf"].planner == "heuristic"
    assert by_name["sphere/sdf"].planes == 8
    assert by_name["box/loft"].planes == 5
    assert by_name["sphere/loft"].metrics is not None
    assert by_name["sphere/loft"].mesh_path is not None
    assert by_name["broken/loft"].error == FAILURE
    assert by_name["broken/loft"].method == "loft"
    assert not by_name["broken/loft"].ok and by_name["box/sdf"].ok


def test_metrics_csv_has_one_row_per_case(report: Path, results: Path) -> None:
    with (results / "metrics.csv").open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert [r["case"] for r in rows] == [c.case for c in collect_results(results)]
    for row in rows:
        if row["case"] == "broken/loft":
            assert row["status"] == "failed"
            assert row["volume_iou"] == ""
            assert row["error"] == FAILURE
            continue
        stored = json.loads((results / row["case"] / "metrics.json").read_text())
        assert row["status"] == "ok"
        assert row["method"] == row["case"].split("/")[1]
        assert int(row["planes"]) == SHAPES[row["case"].split("/")[0]][1]
        for key in ("volume_iou", "surface_iou", "chamfer_l1_mm", "hd95_mm"):
            assert float(row[key]) == stored[key]
        assert float(row["seconds"]) > 0
        # Sanity of the reconstructions themselves: small shapes, coarse sampling.
        assert 0.6 < float(row["volume_iou"]) <= 1.0


def test_summary_json_groups_per_method(report: Path, results: Path) -> None:
    summary = json.loads((results / "summary.json").read_text())
    assert summary["n_cases"] == 5 and summary["n_failures"] == 1
    groups = {(g["method"], g["planner"]): g for g in summary["groups"]}
    assert set(groups) == {("loft", "heuristic"), ("sdf", "heuristic")}
    assert groups[("loft", "heuristic")]["count"] == 3
    assert groups[("loft", "heuristic")]["failures"] == 1
    assert groups[("sdf", "heuristic")]["count"] == 2
    assert groups[("sdf", "heuristic")]["failures"] == 0
    for method in METHODS:
        values = [
            json.loads((results / s / method / "metrics.json").read_text())["volume_iou"]
            for s in SHAPES
        ]
        stats = groups[(method, "heuristic")]["metrics"]["volume_iou"]
        assert stats["n"] == 2
        assert stats["mean"] == pytest.approx(np.mean(values), rel=1e-12)
        assert stats["median"] == pytest.approx(np.median(values), rel=1e-12)
        assert stats["std"] == pytest.approx(np.std(values, ddof=1), rel=1e-9, abs=1e-15)
    planes = {(g["method"], g["planes"]) for g in summary["by_planes"]}
    assert planes == {(m, n) for m in METHODS for _, n in SHAPES.values()}
    assert summary["failures"][0]["case"] == "broken/loft"


def test_html_parses_and_every_image_decodes(report: Path, results: Path) -> None:
    assert report == results / "report.html"
    page = _parse(report)
    # box plots, IoU against planes (two plane counts), one render per finished case
    assert len(page.images) == 2 + 4
    for src in page.images:
        image = _decode(src)
        assert image.width >= 250 and image.height >= 200, image.size
        pixels = np.asarray(image.convert("RGB"), dtype=np.float64)
        assert pixels.std() > 10.0, "blank image"
        assert len(np.unique(pixels.reshape(-1, 3), axis=0)) > 20
    # No external resources: the page can be mailed.
    raw = report.read_text(encoding="utf-8")
    assert not re.search(r"""src=["'](?!data:)""", raw)
    assert (results / "report_assets" / "boxplots.png").is_file()
    assert len(list((results / "report_assets" / "cases").glob("*.png"))) == 4


def test_html_lists_the_failure_escaped(report: Path) -> None:
    raw = report.read_text(encoding="utf-8")
    text = "".join(_parse(report).text)
    assert FAILURE in text  # shown to the reader, verbatim
    assert "<missing.nii.gz>" not in raw  # but escaped in the markup
    assert "Spheres &amp; boxes &lt;test&gt;" in raw
    assert "Failures (1)" in text


def test_renders_colour_the_error_against_ground_truth(report: Path) -> None:
    captions = [c for c in _parse(report).figcaptions if "planes" in c and "/" in c]
    assert len(captions) == 4
    for caption in captions:
        assert "ground truth: " in caption
        mean, _, top = _distances(caption)
        # Reconstructions of these shapes lie within a voxel (1 mm) of the truth on average
        # (the axis-aligned box is reproduced exactly: 0 mm).
        assert 0.0 <= mean < 1.0 and top < 2.0


def _distances(caption: str) -> tuple[float, float, float]:
    """Mean, 95th percentile and max distance (mm) quoted in a render's caption."""
    match = re.search(
        r"distance to truth mean ([0-9.]+) mm, 95th percentile ([0-9.]+) mm, max ([0-9.]+) mm",
        caption,
    )
    assert match, caption
    mean, p95, top = (float(g) for g in match.groups())
    return mean, p95, top


def test_error_colours_measure_millimetres(results: Path, tmp_path: Path) -> None:
    """A reconstruction shifted by 3 mm along x is up to 3 mm from the truth (at the poles)."""
    case = tmp_path / "shifted" / "sphere" / "sdf"
    shutil.copytree(results / "sphere" / "sdf", case)
    mesh = read_mesh(case / "mesh.stl")
    mesh.apply_translation((3.0, 0.0, 0.0))
    mesh.export(case / "mesh.stl")
    page = _parse(write_report(tmp_path / "shifted"))
    (caption,) = [c for c in page.figcaptions if "sphere/sdf" in c]
    mean, p95, top = _distances(caption)
    assert 2.4 < top < 3.6
    assert 0.8 < mean < 2.4 and mean < p95 <= top


def test_report_is_deterministic(report: Path, results: Path) -> None:
    before = {n: (results / n).read_bytes() for n in ("report.html", "metrics.csv", "summary.json")}
    write_report(results, title="Spheres & boxes <test>")
    for name, data in before.items():
        assert (results / name).read_bytes() == data, name


def test_no_renders_and_unreadable_plan(results: Path, tmp_path: Path) -> None:
    copy = tmp_path / "copy"
    shutil.copytree(
        results, copy, ignore=shutil.ignore_patterns("report*", "*.csv", "summary.json")
    )
    bad = copy / "sphere" / "bad"
    bad.mkdir()
    (bad / "plan.json").write_text("{ not json")
    batch_style = copy / "liver_007"  # as pipelines/batch writes it: no method, a type
    batch_style.mkdir()
    (batch_style / "error.json").write_text(
        json.dumps(
            {
                "case": "liver_007",
                "input": "liver_007.nii.gz",
                "error": "truncated gzip",
                "type": "FormatError",
            }
        )
    )
    path = write_report(copy, renders=False)
    page = _parse(path)
    assert len(page.images) == 2  # the summary figures only
    text = "".join(page.text)
    assert "unreadable plan.json" in text
    assert "FormatError: truncated gzip" in text
    summary = json.loads((copy / "summary.json").read_text())
    assert summary["n_failures"] == 3
    assert {f["case"] for f in summary["failures"]} == {"broken/loft", "liver_007", "sphere/bad"}


def test_cli_report_prints_the_path_and_rejects_empty_dirs(
    results: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    copy = tmp_path / "copy"
    shutil.copytree(results / "box", copy / "box")
    assert main(["report", str(copy), "--title", "CLI", "--no-renders"]) == 0
    out = capsys.readouterr().out.strip()
    assert Path(out) == copy / "report.html" and Path(out).is_file()
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["report", str(empty)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and "no cases" in err and len(err.splitlines()) == 1
    assert main(["report", str(tmp_path / "absent")]) == 2
    assert "not found" in capsys.readouterr().err


def test_cli_evaluate_dataset_runs_every_mask_and_records_failures(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    data = tmp_path / "data"
    write_nifti(make_shape("sphere", radius=6.0), data / "ball.nii.gz")
    (data / "corrupt.nii").write_bytes(b"this is not a NIfTI file")
    (data / "manifest.json").write_text("{}")
    out = tmp_path / "out"
    args = [
        "evaluate-dataset",
        str(data),
        "-o",
        str(out),
        "--method",
        "loft,sdf",
        "--n-points",
        "2000",
        "--slices",
        "6",
        "--no-renders",
    ]
    assert main(args) == 0
    assert Path(capsys.readouterr().out.strip()) == out / "report.html"
    for method in METHODS:
        plan = json.loads((out / "ball" / method / "plan.json").read_text())
        assert plan["config"]["method"] == method
        assert plan["sections"]["n_planes"] == 6
        error = json.loads((out / "corrupt" / method / "error.json").read_text())
        assert error["method"] == method and error["error"]
    with (out / "metrics.csv").open(newline="") as handle:
        rows = {r["case"]: r["status"] for r in csv.DictReader(handle)}
    assert rows == {
        "ball/loft": "ok",
        "ball/sdf": "ok",
        "corrupt/loft": "failed",
        "corrupt/sdf": "failed",
    }
    # Re-running skips cases finished with the same options.
    stamp = (out / "ball" / "loft" / "mesh.stl").stat().st_mtime_ns
    assert main(args) == 0
    assert (out / "ball" / "loft" / "mesh.stl").stat().st_mtime_ns == stamp
    capsys.readouterr()
    assert main(["evaluate-dataset", str(data), "-o", str(out), "--method", "loft,nope"]) == 2
    assert "--method" in capsys.readouterr().err
    assert main(["evaluate-dataset", str(tmp_path / "out"), "-o", str(tmp_path / "o2")]) == 2
    assert "no NIfTI" in capsys.readouterr().err


def test_evaluate_two_files_still_prints_metrics(
    results: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    mask = results.parent / "sphere.nii.gz"
    mesh = results / "sphere" / "sdf" / "mesh.stl"
    assert main(["evaluate", str(mesh), str(mask), "--n-points", "2000"]) == 0
    metrics = json.loads(capsys.readouterr().out)
    assert metrics["volume_iou"] > 0.6


def test_renders_of_sparse_input_with_and_without_a_mesh_ground_truth(tmp_path: Path) -> None:
    ball = make_shape("sphere", radius=7.0)
    sparse = np.zeros_like(ball.mask)
    sparse[:, :, ::3] = ball.mask[:, :, ::3]  # only every third plane annotated
    write_nifti(ball.with_mask(sparse), tmp_path / "sparse.nii.gz")
    volume_to_mesh(ball).export(tmp_path / "truth.stl")
    root = tmp_path / "results"
    config = ReconstructConfig(n_points=2000)
    run_case(tmp_path / "sparse.nii.gz", root / "alone", config)
    run_case(
        tmp_path / "sparse.nii.gz", root / "with_gt", config, ground_truth=tmp_path / "truth.stl"
    )
    page = _parse(write_report(root))
    alone, with_gt = (
        next(c for c in page.figcaptions if c.startswith(name)) for name in ("alone", "with_gt")
    )
    assert "no ground truth" in alone
    assert "ground truth: truth.stl" in with_gt
    mean, _, top = _distances(with_gt)
    assert 0.0 < mean < top < 3.0
    # The last two images are the renders, by case name: reconstruction alone (one
    # panel), then ground truth | reconstruction | error (three panels).
    single, triple = (_decode(src) for src in page.images[-2:])
    assert single.width * 2 < triple.width


# ------------------------------------------------------------------ the report only reads
REPORT_PACKAGE = Path(__file__).resolve().parents[1] / "slicerecon" / "report"
RUNNING = ("slicerecon.reconstruct", "slicerecon.partition", "slicerecon.policy", "pipelines")


def test_report_modules_import_nothing_that_reconstructs() -> None:
    """No module of slicerecon.report imports the reconstruction, the planners or the runner,
    nor names run_case / reconstruct."""
    modules = sorted(REPORT_PACKAGE.glob("*.py"))
    assert {m.name for m in modules} >= {
        "__init__.py",
        "tables.py",
        "figures.py",
        "renders.py",
        "page.py",
        "writer.py",
    }
    for module in modules:
        tree = ast.parse(module.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                # relative imports resolve inside slicerecon (level 2: ..name)
                base = node.module or ""
                target = base if node.level < 2 else ".".join(filter(None, ("slicerecon", base)))
                names = [target, *(f"{target}.{a.name}" for a in node.names)]
            elif isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            else:
                if isinstance(node, ast.Name | ast.Attribute):
                    name = node.id if isinstance(node, ast.Name) else node.attr
                    assert name not in ("run_case", "reconstruct"), (module.name, name)
                continue
            for name in names:
                assert not name.startswith(RUNNING), (module.name, name)


def test_writing_a_report_runs_no_reconstruction(results: Path, tmp_path: Path) -> None:
    """In a fresh interpreter, a report with a render leaves the reconstruction unimported."""
    copy = tmp_path / "copy"
    shutil.copytree(results / "sphere", copy / "sphere")
    code = (
        "import sys\n"
        "from slicerecon.report import write_report\n"
        f"write_report({str(copy)!r}, max_renders=1)\n"
        f"print(sorted(m for m in sys.modules if m.startswith({RUNNING!r})))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=300
    )
    assert done.stdout.strip() == "[]"
    page = _parse(copy / "report.html")
    assert len(page.images) == 1 + 1  # the box plots (one plane count) and one render
    assert any("ground truth: sphere.nii.gz" in c for c in page.figcaptions)  # the mask was read


def test_evaluate_dataset_uses_the_runner_and_its_records(tmp_path: Path) -> None:
    """evaluate-dataset goes through pipelines' runner: summary.csv, done.json, one error.json
    format (with the exception's type), and the report reads it back as the runner saw it."""
    from pipelines.evaluate import evaluate_dataset

    data = tmp_path / "data"
    write_nifti(make_shape("sphere", radius=6.0), data / "ball.nii.gz")
    (data / "corrupt.nii.gz").write_bytes(b"\x1f\x8b not gzip")
    out = tmp_path / "out"
    seen = []
    config = ReconstructConfig(slices=6, n_points=2000)
    report = evaluate_dataset(
        data,
        out,
        methods=["loft", "sdf"],
        config=config,
        renders=False,
        progress=lambda r, done, total: seen.append((r.case, r.status)),
    )
    assert report == out / "report.html"
    assert sorted(seen) == [
        ("ball/loft", "ok"),
        ("ball/sdf", "ok"),
        ("corrupt/loft", "failed"),
        ("corrupt/sdf", "failed"),
    ]
    with (out / "summary.csv").open(newline="") as handle:
        rows = {r["case"]: r for r in csv.DictReader(handle)}
    assert rows["ball/sdf"]["status"] == "ok" and rows["ball/sdf"]["input"] == "ball.nii.gz"
    assert rows["corrupt/loft"]["error_type"] == "FormatError"
    assert (out / "ball" / "loft" / "done.json").is_file()
    error = json.loads((out / "corrupt" / "sdf" / "error.json").read_text())
    assert error["type"] == "FormatError" and error["method"] == "sdf" and error["traceback"]
    by_name = {c.case: c for c in collect_results(out)}
    assert by_name["corrupt/sdf"].error_text.startswith("FormatError: ")
    assert by_name["ball/loft"].watertight is True and by_name["ball/loft"].kind == "nifti"
    seen.clear()
    evaluate_dataset(
        data,
        out,
        methods=["loft", "sdf"],
        config=config,
        renders=False,
        progress=lambda r, done, total: seen.append((r.case, r.status)),
    )
    assert sorted(seen)[:2] == [("ball/loft", "skipped"), ("ball/sdf", "skipped")]
