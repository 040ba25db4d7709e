"""Evaluation reports over a results folder: HTML, figures, CSV and JSON.

The report only *reads* results: the case folders that ``slicerecon run``,
``batch`` and ``evaluate-dataset`` write (their layout and records are
:mod:`slicerecon.results`). It runs no reconstruction and recomputes no metric.

:func:`write_report` writes into the results folder

* ``metrics.csv``: one row per case (case, method, planner, planes, status,
  every metric, seconds, error);
* ``summary.json``: per method/planner (and per method/planner/planes) the
  number of cases and failures and mean / median / std / min / max of each metric;
* ``report.html``: one self-contained page (figures embedded as base64 PNG
  data URIs) with summary tables, box plots of IoU and Chamfer-L1 per method,
  IoU against the number of planes, per-case 3-D renders (ground truth,
  reconstruction, reconstruction coloured by its distance to the ground-truth
  surface in mm) and the failures;
* ``report_assets/``: the same figures as PNG files, for slides and papers.

Modules: :mod:`~slicerecon.report.tables` (statistics, ``metrics.csv``),
:mod:`~slicerecon.report.figures` (summary plots),
:mod:`~slicerecon.report.renders` (3-D renders), :mod:`~slicerecon.report.page`
(the HTML, from the jinja2 template ``templates/report.html.j2``) and
:mod:`~slicerecon.report.writer` (:func:`write_report`).

Rendering uses matplotlib's Agg backend (no display); every output depends on
the inputs only (no timestamps, no unseeded randomness), so re-running on the
same results gives byte-identical files.
"""

from __future__ import annotations

from ..results import REPORT_FILES, CaseResult, collect_results
from .tables import summarize
from .writer import write_report

__all__ = [
    "REPORT_FILES",
    "CaseResult",
    "collect_results",
    "summarize",
    "write_report",
]
