"""A case on disk: the result records and the layout of a results folder.

This module is the one owner of what a reconstruction leaves on disk. The
runner (:mod:`pipelines.batch`) writes it; the report (:mod:`slicerecon.report`)
and anyone else read it back with :func:`read_case` / :func:`collect_results`.

Layout
------
A *results folder* holds *case folders* at any depth (hidden folders and
``report_assets/`` are not searched)::

    RESULTS/
      summary.csv              one row per case of the last batch (the runner)
      metrics.csv              one row per case, every metric (the report)
      summary.json             statistics per method/planner (the report)
      report.html              the HTML report
      report_assets/           the report's figures as PNG files
      <case>/                  a finished case (what ``slicerecon run`` writes)
        mesh.<fmt> or meshes/<value>_<name>.<fmt>  structures.json  plan.json
        [metrics.json]  labels.nii.gz  labels.seg.nrrd  preview.png  [done.json]
      <case>/                  a failed case
        error.json
      <case>/<config>/         several configurations of one case
                               (``slicerecon evaluate-dataset``): one case folder each

A case folder is one that holds ``plan.json`` (finished) or ``error.json``
(failed); when both are there the newer file wins. A case's *name* is its
folder's path relative to the results folder, with ``/`` separators
(``liver_003`` for a batch, ``liver_003/loft`` for one method of
``evaluate-dataset``). ``done.json`` is the runner's completion marker: it
holds the resume key, the case's mesh files and the :meth:`CaseResult.to_json`
record of the run.

One schema serves one structure and many (:mod:`slicerecon.case_outputs`
writes it): a case of one structure has ``mesh.<fmt>``, a case of several has
``meshes/<value>_<name>.<fmt>``, and ``structures.json`` lists every structure
with its mesh's path; ``metrics.json`` holds the case's metrics at its top
level (the mean over the structures) and each structure's under ``structures``.

Records
-------
* :class:`CaseResult`: one case (status ``ok``, ``failed`` or ``skipped``,
  metrics, timings, paths); one row of ``summary.csv`` (:meth:`CaseResult.to_row`).
* :class:`StructureRecord`: one structure of a case (``structures.json``: name,
  colour, status, mesh, its own metrics), :attr:`CaseResult.structures`.
* :class:`FailureRecord`: the one ``error.json`` format.
* :class:`CaseFiles` / :class:`ResultsLayout`: where the files are.
"""

from __future__ import annotations

from .layout import (
    DONE_FILE,
    ERROR_FILE,
    KEY_METRICS,
    MESH_SUFFIXES,
    MESHES_DIR,
    METRICS_CSV,
    METRICS_FILE,
    PLAN_FILE,
    PREVIEW_FILE,
    REPORT_ASSETS,
    REPORT_FILES,
    REPORT_HTML,
    STATUSES,
    STRUCTURES_FILE,
    SUMMARY_COLUMNS,
    SUMMARY_CSV,
    SUMMARY_JSON,
    CaseFiles,
    ResultsLayout,
    Status,
    mesh_file,
)
from .reading import collect_results, read_case, write_summary
from .records import CaseResult, FailureRecord, StructureRecord

__all__ = [
    "DONE_FILE",
    "ERROR_FILE",
    "KEY_METRICS",
    "MESHES_DIR",
    "MESH_SUFFIXES",
    "METRICS_CSV",
    "METRICS_FILE",
    "PLAN_FILE",
    "PREVIEW_FILE",
    "REPORT_ASSETS",
    "REPORT_FILES",
    "REPORT_HTML",
    "STATUSES",
    "STRUCTURES_FILE",
    "SUMMARY_COLUMNS",
    "SUMMARY_CSV",
    "SUMMARY_JSON",
    "CaseFiles",
    "CaseResult",
    "FailureRecord",
    "StructureRecord",
    "ResultsLayout",
    "Status",
    "collect_results",
    "mesh_file",
    "read_case",
    "write_summary",
]
