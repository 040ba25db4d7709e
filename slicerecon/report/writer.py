"""Write a report into a results folder: tables, figures, renders and the page."""

from __future__ import annotations

import json
import logging
import os
import shutil
import tempfile
from collections.abc import Sequence
from pathlib import Path

from ..errors import InputError, OptionError
from ..io.atomic import atomic_path
from ..results import REPORT_ASSETS, CaseResult, ResultsLayout, collect_results
from .figures import box_plot, planes_plot
from .page import Render, render_page
from .renders import TruthCache, render_case
from .tables import metrics_csv_text, summarize

__all__ = ["write_report"]

logger = logging.getLogger(__name__)


def _slug(case: str) -> str:
    text = "".join(ch if ch.isalnum() or ch in "-_." else "_" for ch in case.replace("/", "__"))
    return text or "case"


def _write_assets(layout: ResultsLayout, files: dict[str, bytes]) -> None:
    """Replace ``report_assets/`` by a folder holding ``files`` (relative name → bytes)."""
    root, target = layout.root, layout.report_assets
    staging = Path(tempfile.mkdtemp(prefix=f".{REPORT_ASSETS}.", dir=root))
    umask = os.umask(0)
    os.umask(umask)
    staging.chmod(0o777 & ~umask)  # mkdtemp makes it private; give it a normal folder's mode
    try:
        for name, data in files.items():
            path = staging / name
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_bytes(data)
        if target.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{REPORT_ASSETS}.old.", dir=root))
            os.replace(target, old / REPORT_ASSETS)
            shutil.rmtree(old, ignore_errors=True)
        os.replace(staging, target)
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise


def _write_text(path: Path, text: str) -> None:

    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def _renders(
    cases: list[CaseResult], root: Path, max_renders: int | None, assets: dict[str, bytes]
) -> tuple[list[Render], str]:
    """Render the finished cases with a mesh (at most ``max_renders``); add their PNGs
    to ``assets``. Returns the renders and a note for the page."""
    rendered: list[Render] = []
    candidates = [c for c in cases if c.ok and c.mesh_path is not None]
    chosen = candidates if max_renders is None else candidates[:max_renders]
    note = ""
    if len(chosen) < len(candidates):
        note = f"Renders of the first {len(chosen)} of {len(candidates)} cases by name."
    truths = TruthCache()
    for case in chosen:
        try:
            truth, where = truths.get(case, root)
            png, stats = render_case(case, truth)
        except Exception as exc:  # one bad case must not stop the report
            logger.warning("cannot render %s: %s", case.case, exc)
            rendered.append(Render(case, None, f"render failed: {type(exc).__name__}: {exc}"))
            continue
        if stats:
            where += (
                f"; vertex distance to truth mean {stats['mean_mm']:.2f} mm, "
                f"95th percentile {stats['p95_mm']:.2f} mm, max {stats['max_mm']:.2f} mm"
            )
        rendered.append(Render(case, png, where))
        asset, k = f"cases/{_slug(case.case)}.png", 2
        while asset in assets:
            asset, k = f"cases/{_slug(case.case)}-{k}.png", k + 1
        assets[asset] = png
        logger.info("rendered %s", case.case)
    return rendered, note


def _summary_cases(root: Path) -> list[str] | None:
    """The case column of a batch's ``summary.csv`` in ``root``, or None without one."""
    import csv

    path = ResultsLayout(root).summary_csv
    try:
        with path.open(newline="", encoding="utf-8") as handle:
            rows = list(csv.DictReader(handle))
    except (OSError, UnicodeDecodeError, csv.Error):
        return None
    if not rows or "case" not in rows[0]:
        return None
    return [row["case"] for row in rows]


def write_report(
    results_dir: str | os.PathLike[str],
    *,
    title: str | None = None,
    renders: bool = True,
    max_renders: int | None = 100,
    only: Sequence[str] | None = None,
) -> Path:
    """Write ``metrics.csv``, ``summary.json``, ``report.html`` and ``report_assets/``.

    Only reads the results folder (:func:`slicerecon.results.collect_results`);
    nothing is reconstructed or re-measured.

    Parameters
    ----------
    results_dir : path-like
        A results folder (see :mod:`slicerecon.results`); the report files
        are written into it, each atomically (``report_assets`` is replaced
        as a whole).
    title : str, optional
        Page title; default ``"slicerecon report: <directory name>"``.
    renders : bool
        Draw the per-case 3-D renders (ground truth, reconstruction,
        distance-coloured reconstruction); about a second per case.
    max_renders : int or None
        Render at most this many finished cases (the first ones by name);
        None renders all.
    only : sequence of str, optional
        Report only these case folders; the others are named in one log line.
        Default: the cases of the folder's ``summary.csv`` when a batch wrote
        one (its last run's, so that a folder an earlier run left for an
        input that is gone is not counted), else every case folder.

    Returns
    -------
    Path
        The ``report.html`` file.

    Raises
    ------
    InputError
        If the directory does not exist or holds no case directory.
    OptionError
        If ``max_renders`` is negative.

    Notes
    -----
    A case whose render fails (missing or unreadable mesh or ground truth) is
    still listed; the reason is shown in place of the render and logged.
    """
    if max_renders is not None and max_renders < 0:
        raise OptionError(f"max_renders must be >= 0 or None (got {max_renders})")
    cases = collect_results(results_dir)
    if only is None:
        only = _summary_cases(Path(results_dir))
    if only is not None:
        wanted = set(only)
        left = [c.case for c in cases if c.case not in wanted]
        cases = [c for c in cases if c.case in wanted]
        if left:
            logger.warning(
                "%s: not in the report, the case folders of an earlier run whose input is not "
                "among this run's cases: %s",
                results_dir,
                ", ".join(left),
            )
    layout = ResultsLayout(Path(results_dir))
    root = layout.root
    if not cases:
        raise InputError(
            f"{root} holds no cases: expected case directories with plan.json (written by "
            "`slicerecon run`, `batch` or `evaluate-dataset`) or error.json"
        )
    if title is None:
        title = f"slicerecon report: {root.resolve().name}"
    summary = summarize(cases)
    assets: dict[str, bytes] = {}
    figures: dict[str, bytes] = {}
    for name, make in (("boxplots", box_plot), ("iou_vs_planes", planes_plot)):
        data = make(cases)
        if data is not None:
            figures[name] = data
            assets[f"{name}.png"] = data
    if renders:
        rendered, note = _renders(cases, root, max_renders, assets)
    else:
        rendered, note = [], "Renders were not requested (--no-renders)."

    _write_assets(layout, assets)
    _write_text(layout.metrics_csv, metrics_csv_text(cases))
    payload = {"title": title, **summary}
    _write_text(layout.summary_json, json.dumps(payload, indent=2, allow_nan=False) + "\n")
    page = render_page(
        title=title,
        cases=cases,
        summary=summary,
        figures=figures,
        renders=rendered,
        root=root,
        render_note=note,
    )
    _write_text(layout.report_html, page)
    logger.info("report of %d case(s) written to %s", len(cases), layout.report_html)
    return layout.report_html
