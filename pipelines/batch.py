"""Reconstruct every case of a directory on Dask, with failure isolation and resume.

This is slicerecon's one runner of cases. :func:`run_batch` finds the cases of
``INDIR`` (:func:`pipelines.discover.discover_cases`) and hands them to
:func:`run_cases`, which reconstructs each one into ``OUTDIR/<case>/`` with
:func:`slicerecon.reconstruct.run_case`, one task per case, writes
``OUTDIR/summary.csv`` and then the HTML report
(:func:`slicerecon.report.write_report`). Given several named configurations,
:func:`run_cases` runs every case with each of them into
``OUTDIR/<case>/<name>/`` (that is what ``slicerecon evaluate-dataset`` does,
:mod:`pipelines.evaluate`). What a case leaves on disk, and the
:class:`~slicerecon.results.CaseResult` and ``error.json`` records, are
:mod:`slicerecon.results`.

Where the cases run
-------------------
* ``scheduler="tcp://host:8786"``: on an existing Dask cluster. Its workers
  need slicerecon installed and the same paths to ``INDIR`` and ``OUTDIR``
  (a shared filesystem); ``workers`` is then ignored.
* ``workers=N`` (N >= 1, default: the number of CPUs, at most one per case
  to compute): on a ``distributed.LocalCluster`` of N worker processes with one
  thread each, started for this batch and closed after it.
* ``workers=0``: in this process, one case after the other, without Dask (no
  start-up cost; tracebacks and debuggers work as usual).

On Dask, cases are submitted one per free worker thread rather than all at
once (see :func:`pipelines.cluster.run_on_dask`), so a case that kills its
worker cannot take cases queued behind it down with it.

Failures, resume and atomic outputs
-----------------------------------
A case that raises writes ``OUTDIR/<case>/error.json`` (a
:class:`~slicerecon.results.FailureRecord`: ``case``, ``input``, ``kind``,
``error``, ``type``, ``method``, ``planner``, ``traceback``) and never stops the
others. A finished case writes ``OUTDIR/<case>/done.json`` last; it holds the
case's *key*, the SHA-256 of its input bytes (for a folder: every file's name
and bytes), of every :class:`~slicerecon.reconstruct.ReconstructConfig` field
and of the slicerecon version (:func:`~pipelines.runner.case_key`). A later
run skips a case whose ``done.json`` holds the key it would compute (and whose
mesh is there); ``force=True`` recomputes it.

Each case is computed in a hidden staging folder ``OUTDIR/.<case>.partial-*``
and renamed to ``OUTDIR/<case>`` when complete (:mod:`pipelines.publish`), so
``OUTDIR/<case>/`` is always one whole result (or one ``error.json``). A
worker that dies (out of memory, killed) leaves only a staging folder; Dask
runs the case again on another worker (up to ``retries`` more times), and that
attempt and the end of the batch remove the leftovers.

Symbolic links in ``INDIR`` that point outside it are not read unless
``follow_symlinks=True``; each is recorded as a failed case saying why (see
:mod:`pipelines.discover`).

Interruption
------------
Ctrl-C (SIGINT) raises :class:`KeyboardInterrupt` in the calling process only:
the worker processes of the local cluster are started with SIGINT blocked, so
the signal a terminal sends to its whole process group reaches the client
alone. :func:`run_batch` then stops the workers (each gets about a second,
then is killed: the cases in flight are abandoned), closes the cluster,
removes the staging folders of those cases, and re-raises; ``summary.csv``
keeps its previous contents, every finished ``OUTDIR/<case>/`` stays, and the
next run resumes. Workers log nothing once they are shutting down (see
:func:`pipelines.cluster.dask_setup`). A Ctrl-C that comes while the cluster
starts or closes, or while a case folder is being renamed into place, takes
effect once that step is done. (On a cluster given by ``scheduler`` the
running cases go on there and publish their results whole; the next run finds
them.)
"""

from __future__ import annotations

import logging
import os
import time
import traceback
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

from slicerecon.errors import InputError, OptionError
from slicerecon.results import (
    KEY_METRICS,
    SUMMARY_COLUMNS,
    CaseResult,
    ResultsLayout,
    write_summary,
)

from .cluster import dask_setup, reach_scheduler, run_on_dask
from .discover import Case, SkippedInput, discover, safe_case_name
from .publish import clear_stale, sigint_deferred
from .runner import (
    Job,
    case_key,
    failure_result,
    finished_result,
    process_case,
    record_failed_job,
)

if TYPE_CHECKING:  # imported where used: the worker processes preload this package
    from slicerecon.reconstruct import ReconstructConfig

__all__ = [
    "KEY_METRICS",
    "SUMMARY_COLUMNS",
    "BatchResult",
    "CaseResult",
    "Progress",
    "case_key",
    "check_dirs",
    "config_for",
    "dask_setup",
    "process_case",
    "run_batch",
    "run_cases",
    "write_summary",
]

logger = logging.getLogger(__name__)

Progress = Callable[[CaseResult, int, int], None]
"""``progress(result, n_done, n_total)``, called after each case."""


@dataclass(frozen=True)
class BatchResult:
    """What :func:`run_batch` / :func:`run_cases` did.

    Attributes
    ----------
    outdir : Path
        The output directory.
    cases : tuple of CaseResult
        One per case (and configuration), in case (sorted input) order.
    summary_csv : Path
        ``OUTDIR/summary.csv``.
    report : Path or None
        The HTML report, when one was written.
    report_error : str
        Why the report failed (empty when it did not fail).
    seconds : float
        Wall time of the whole batch, s.
    skipped_inputs : tuple of SkippedInput
        The entries of INDIR that are not cases, each with the reason
        (:func:`pipelines.discover.discover`; empty for :func:`run_cases`).
    """

    outdir: Path
    cases: tuple[CaseResult, ...]
    summary_csv: Path
    report: Path | None = None
    report_error: str = ""
    seconds: float = 0.0
    skipped_inputs: tuple[SkippedInput, ...] = ()

    def count(self, status: str) -> int:
        """Number of cases with ``status`` (ok, failed or skipped)."""
        return sum(1 for c in self.cases if c.status == status)

    @property
    def n_ok(self) -> int:
        """Cases computed in this run without error."""
        return self.count("ok")

    @property
    def n_failed(self) -> int:
        """Cases that failed."""
        return self.count("failed")

    @property
    def n_skipped(self) -> int:
        """Cases finished by an earlier run."""
        return self.count("skipped")

    @property
    def ok(self) -> bool:
        """True when no case failed."""
        return self.n_failed == 0


def _write_report(outdir: Path) -> tuple[Path | None, str]:
    """Call ``slicerecon.report.write_report(outdir)`` (the cases of ``summary.csv``, this
    run's); never raise."""
    try:
        from slicerecon.report import write_report

        written = write_report(outdir)
    except Exception as exc:  # noqa: BLE001 - the report is optional; the batch stands
        logger.warning(
            "the HTML report failed (%s: %s); summary.csv is complete",
            type(exc).__name__,
            exc,
            exc_info=True,
        )
        return None, f"{type(exc).__name__}: {exc}"
    return (Path(written) if isinstance(written, str | os.PathLike) else None), ""


def _named_configs(
    config: ReconstructConfig | Mapping[str, ReconstructConfig],
) -> dict[str | None, ReconstructConfig]:
    """``{None: config}`` for one configuration; the checked mapping for several."""
    from slicerecon.reconstruct import ReconstructConfig

    if isinstance(config, ReconstructConfig):
        return {None: config}
    if not isinstance(config, Mapping) or not config:
        raise OptionError(
            "config must be a ReconstructConfig or a non-empty mapping of names "
            f"to ReconstructConfig (got {type(config).__name__})"
        )
    named: dict[str | None, ReconstructConfig] = {}
    for name, value in config.items():
        if not isinstance(value, ReconstructConfig):
            raise OptionError(
                f"config {name!r} must be a ReconstructConfig (got {type(value).__name__})"
            )
        if not isinstance(name, str) or safe_case_name(name) != name:
            raise OptionError(
                f"configuration names become folder names: use letters, digits, "
                f"'-' and '_' only (got {name!r})"
            )
        named[name] = value
    return named


SPARSE_KINDS = ("contours", "rtstruct")
"""Case kinds that hold their own planes: ``slices`` / ``every`` do not apply to them."""


def config_for(case: Case, config: ReconstructConfig) -> ReconstructConfig:
    """The options ``case`` runs with: ``config``, without ``slices`` / ``every`` for a
    contour file or RTSTRUCT (its planes are the ones drawn), and with ``dense_only``
    (a sparse label map leaves them out too, with a note), so that one batch may mix
    dense masks and annotations."""
    if case.kind in SPARSE_KINDS and (config.slices is not None or config.every is not None):
        config = replace(config, slices=None, every=None)
    return replace(config, dense_only=True)


def check_dirs(indir: Path, outdir: Path) -> None:
    """Refuse ``outdir == indir``: the outputs would be read back as inputs.

    Raises
    ------
    OptionError
        If the two resolve to the same folder.
    """
    if outdir.resolve() == indir.resolve():
        raise OptionError(
            f"OUTDIR must differ from INDIR ({indir.resolve()}): the outputs (JSON files among "
            "them) would be read back as inputs; pass another -o"
        )


def run_cases(
    cases: Sequence[Case],
    outdir: str | os.PathLike[str],
    config: ReconstructConfig | Mapping[str, ReconstructConfig],
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    force: bool = False,
    progress: Progress | None = None,
    retries: int = 2,
    report: bool = True,
) -> BatchResult:
    """Reconstruct discovered cases into ``outdir``: the runner behind :func:`run_batch`.

    Parameters
    ----------
    cases : sequence of Case
        The cases (:func:`~pipelines.discover.discover_cases`, possibly a
        subset); a case with an ``error`` is recorded as failed, never opened.
    outdir : path-like
        Output folder: ``<case>/`` per case (``<case>/<name>/`` per named
        configuration), ``summary.csv``, the report.
    config : ReconstructConfig or mapping of str to ReconstructConfig
        The options of every case; or several named configurations, each run
        on every case into ``OUTDIR/<case>/<name>/`` (names: letters, digits,
        ``-`` and ``_``).
    workers, scheduler, force, progress, retries, report
        As for :func:`run_batch`.

    Returns
    -------
    BatchResult
        One result per case and configuration; ``CaseResult.case`` is the
        case folder relative to ``outdir`` (``<case>`` or ``<case>/<name>``).

    Raises
    ------
    OptionError
        If ``workers`` or ``retries`` is negative, a configuration is not a
        ``ReconstructConfig`` or has a bad name, or the scheduler cannot be reached.
    KeyboardInterrupt
        On Ctrl-C (see "Interruption" above).
    """
    if workers is not None and workers < 0:
        raise OptionError(f"--workers must be 0 (in-process) or more (got {workers})")
    if retries < 0:
        raise OptionError(f"retries must be 0 or more (got {retries})")
    configs = _named_configs(config)
    start = time.perf_counter()
    if scheduler is not None:
        reach_scheduler(scheduler)
    out = Path(outdir).resolve()
    out.mkdir(parents=True, exist_ok=True)
    layout = ResultsLayout(out)
    jobs = [
        Job(case, case.name if name is None else f"{case.name}/{name}", config_for(case, value))
        for case in cases
        for name, value in configs.items()
    ]
    total = len(jobs)
    results: dict[str, CaseResult] = {}

    def finish(job: Job, result: CaseResult) -> None:
        results[job.folder] = result
        if progress is not None:
            progress(result, len(results), total)

    todo: list[Job] = []
    for job in jobs:
        if job.case.error:  # a symbolic link that is not followed: recorded, never opened
            failed = failure_result(job, InputError(job.case.error))
            record_failed_job(out, job, failed, "")
            finish(job, failed)
            continue
        try:
            job = job._replace(key=case_key(job.case, job.config))
        except InputError as exc:
            failed = failure_result(job, exc)
            record_failed_job(out, job, failed, traceback.format_exc())
            finish(job, failed)
            continue
        previous = None if force else finished_result(out, job)
        if previous is not None:
            finish(job, previous)
        else:
            todo.append(job)
    logger.info(
        "%d case(s): %d to compute, %d finished before", total, len(todo), total - len(todo)
    )

    def clear(pending: Sequence[Job]) -> None:
        for job in pending:
            final = out / job.folder
            clear_stale(final.parent, final.name)

    try:
        if todo and scheduler is None and workers == 0:
            for job in todo:
                finish(job, process_case(job.case, out, job.config, job.key, folder=job.folder))
        elif todo:
            n_workers = workers if workers is not None else min(os.cpu_count() or 1, len(todo))
            run_on_dask(
                todo, out, workers=n_workers, scheduler=scheduler, retries=retries, on_done=finish
            )
    except KeyboardInterrupt:
        logger.info(
            "interrupted: %d of %d case(s) done; summary.csv not rewritten", len(results), total
        )
        if scheduler is None:  # the local workers are gone: nothing writes to OUTDIR now
            with sigint_deferred():
                clear(todo)
        raise
    clear(todo)

    ordered = tuple(results[job.folder] for job in jobs)
    summary = write_summary(ordered, layout.summary_csv)
    report_path, report_error = _write_report(out) if report else (None, "")
    result = BatchResult(
        out, ordered, summary, report_path, report_error, time.perf_counter() - start
    )
    logger.info(
        "batch done: %d ok, %d failed, %d skipped in %.1f s",
        result.n_ok,
        result.n_failed,
        result.n_skipped,
        result.seconds,
    )
    return result


def run_batch(
    indir: str | os.PathLike[str],
    outdir: str | os.PathLike[str],
    config: ReconstructConfig | Mapping[str, ReconstructConfig],
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    force: bool = False,
    progress: Progress | None = None,
    retries: int = 2,
    report: bool = True,
    follow_symlinks: bool = False,
) -> BatchResult:
    """Reconstruct every case in ``indir`` into ``outdir``.

    Parameters
    ----------
    indir : path-like
        Folder of inputs (see :mod:`pipelines.discover` for what counts as a case).
    outdir : path-like
        Output folder: ``<case>/`` per case, ``summary.csv``, the report. It
        may lie inside ``indir`` (it is then not searched).
    config : ReconstructConfig or mapping of str to ReconstructConfig
        Reconstruction options, the same for every case; or several named
        configurations, each run on every case into ``OUTDIR/<case>/<name>/``.
    workers : int, optional
        Worker processes of the local Dask cluster (default: CPUs, at most one
        per case to compute); 0 runs the cases in this process without Dask.
        Ignored with ``scheduler``.
    scheduler : str, optional
        Address of a running Dask scheduler (``tcp://host:8786``).
    force : bool
        Recompute cases already finished with the same inputs and options.
    progress : callable, optional
        Called as ``progress(result, n_done, n_total)`` after each case.
    retries : int
        How often a case whose worker died is run again elsewhere (and a task
        that raised inside Dask is retried). For a cluster given by
        ``scheduler``, re-runs after a worker's death follow that scheduler's
        ``distributed.scheduler.allowed-failures``.
    report : bool
        After ``summary.csv``, write the HTML report with
        ``slicerecon.report.write_report(outdir)``. A report that fails is
        logged (and kept in ``BatchResult.report_error``); it never fails the batch.
    follow_symlinks : bool
        Read symbolic links in ``indir`` that point outside it. By default
        they are not read: each is a failed case whose error says why (links
        that stay inside ``indir`` are always read).

    Returns
    -------
    BatchResult

    Raises
    ------
    InputError
        If ``indir`` is missing or holds no case.
    OptionError
        If ``workers`` or ``retries`` is negative, ``outdir`` is ``indir``, or
        the scheduler cannot be reached.
    KeyboardInterrupt
        On Ctrl-C, after the local cluster is closed and the staging folders
        of the cases in flight are removed (see "Interruption" above).
    """
    if workers is not None and workers < 0:
        raise OptionError(f"--workers must be 0 (in-process) or more (got {workers})")
    if retries < 0:
        raise OptionError(f"retries must be 0 or more (got {retries})")
    _named_configs(config)  # checked before the inputs are searched
    start = time.perf_counter()
    src, out = Path(indir).resolve(), Path(outdir).resolve()
    check_dirs(src, out)
    cases, skipped = discover(src, exclude=[out], follow_symlinks=follow_symlinks)
    if not cases:
        left_out = ""
        if skipped:
            first = skipped[0]
            more = f" (and {len(skipped) - 1} more, listed with -v)" if len(skipped) > 1 else ""
            left_out = f"; left out: {first.relpath}: {first.reason}{more}"
        raise InputError(
            f"no cases found in {src}: expected label maps (.nii/.nii.gz, .nrrd/.seg.nrrd, "
            ".vti), contour files (.json/.csv), DICOM series folders, DICOM SEG or RTSTRUCT "
            f"files{left_out}"
        )
    result = run_cases(
        cases,
        out,
        config,
        workers=workers,
        scheduler=scheduler,
        force=force,
        progress=progress,
        retries=retries,
        report=report,
    )
    return replace(result, seconds=time.perf_counter() - start, skipped_inputs=tuple(skipped))
