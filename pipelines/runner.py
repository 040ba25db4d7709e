"""One case, one configuration, one folder: resume keys and the body of a task.

A :class:`Job` is what the runner computes: a discovered
:class:`~pipelines.discover.Case` with one
:class:`~slicerecon.reconstruct.ReconstructConfig`, into one case folder of
``OUTDIR``. :func:`process_case` is the body of one task (in this process or
on a Dask worker); :func:`finished_result` tells whether an earlier run already
made a job's outputs. What a case leaves on disk is :mod:`slicerecon.results`.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import shutil
import time
import traceback
from dataclasses import asdict, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

from slicerecon import __version__
from slicerecon.errors import InputError
from slicerecon.messages import collected_warnings
from slicerecon.results import (
    CaseFiles,
    CaseResult,
    FailureRecord,
    read_case,
)

from .discover import Case
from .publish import clear_stale, publish, record_failure, staging_dir, write_json

if TYPE_CHECKING:  # imported where used: the worker processes preload this package
    from slicerecon.reconstruct import ReconstructConfig

__all__ = [
    "Job",
    "case_key",
    "failure_result",
    "finished_result",
    "process_case",
    "record_failed_job",
]

logger = logging.getLogger(__name__)

_CHUNK = 1 << 20


class Job(NamedTuple):
    """One case to compute with one configuration.

    Attributes
    ----------
    case : Case
        The input.
    folder : str
        The case folder relative to OUTDIR (posix; safe names only): the case
        name, or ``<case>/<config name>`` when several configurations run.
        It is the :attr:`~slicerecon.results.CaseResult.case` of the result.
    config : ReconstructConfig
        The reconstruction options.
    key : str
        :func:`case_key` of ``case`` and ``config`` (empty when it could not
        be computed).
    """

    case: Case
    folder: str
    config: ReconstructConfig
    key: str = ""


def _hash_file(digest: Any, path: Path, name: str) -> None:
    digest.update(name.encode("utf-8", "surrogatepass") + b"\0")
    digest.update(path.stat().st_size.to_bytes(8, "little"))
    with open(path, "rb") as fh:
        while chunk := fh.read(_CHUNK):
            digest.update(chunk)


def case_key(case: Case, config: ReconstructConfig) -> str:
    """The resume key of a case: what its outputs depend on.

    SHA-256 of the bytes of ``case.files`` (and, for a case of several files,
    of their names relative to ``case.root``; so renaming an input file or
    folder keeps its key), of every field of ``config`` but ``dense_only``, of the bytes of the
    policy weights file when ``config.weights`` is set, and of the slicerecon
    version.

    Parameters
    ----------
    case : Case
        The input.
    config : ReconstructConfig
        The options.

    Returns
    -------
    str
        64 hex digits.

    Raises
    ------
    InputError
        If an input file cannot be read.
    """
    digest = hashlib.sha256()
    digest.update(f"slicerecon {__version__}\0".encode())
    # dense_only changes whether an option is refused or left out, never what is written
    fields = {k: v for k, v in asdict(config).items() if k != "dense_only"}
    digest.update(json.dumps(fields, sort_keys=True, default=str).encode() + b"\0")
    digest.update(f"{case.kind}\0".encode())
    if config.weights is not None:
        # A retrained actor at the same path must recompute the cases.
        try:
            _hash_file(digest, Path(config.weights), "weights")
        except OSError as exc:
            raise InputError(f"cannot read the policy weights {config.weights}: {exc}") from exc
    single = case.files == (case.path,)
    for path in case.files:
        try:
            name = "" if single else path.relative_to(case.root).as_posix()
        except ValueError:
            name = path.name
        try:
            _hash_file(digest, path, name)
        except OSError as exc:
            raise InputError(f"cannot read {path}: {exc.strerror or exc}") from exc
    return digest.hexdigest()


def failure_result(job: Job, exc: BaseException, seconds: float = 0.0) -> CaseResult:
    """The :class:`~slicerecon.results.CaseResult` of a job that raised ``exc``."""
    return CaseResult(
        case=job.folder,
        input=job.case.relpath,
        kind=job.case.kind,
        status="failed",
        error=str(exc) or type(exc).__name__,
        error_type=type(exc).__name__,
        seconds=round(seconds, 3),
        method=job.config.method,
        planner=job.config.planner,
        input_path=str(job.case.path),
    )


def _failure_record(job: Job, result: CaseResult, tb: str) -> FailureRecord:
    return FailureRecord(
        case=job.folder,
        input=str(job.case.path),
        error=result.error,
        error_type=result.error_type,
        kind=job.case.kind,
        method=job.config.method,
        planner=job.config.planner,
        traceback=tb,
        slicerecon_version=__version__,
    )


def record_failed_job(outdir: Path, job: Job, result: CaseResult, tb: str) -> None:
    """Replace ``OUTDIR/<job.folder>/`` by a folder holding only its ``error.json``."""
    record_failure(outdir / job.folder, _failure_record(job, result, tb))


def process_case(
    case: Case,
    outdir: str | os.PathLike[str],
    config: ReconstructConfig,
    key: str,
    *,
    folder: str | None = None,
) -> CaseResult:
    """Reconstruct one case into ``OUTDIR/<folder>/`` (the body of one task).

    Never raises for a bad case: a failure is written to ``error.json`` and
    returned as a result with status ``failed``.

    Parameters
    ----------
    case : Case
        The case.
    outdir : path-like
        The batch output directory (absolute on a cluster).
    config : ReconstructConfig
        Reconstruction options.
    key : str
        The case's :func:`case_key`, stored in ``done.json``.
    folder : str, optional
        The case folder relative to ``outdir`` (default: ``case.name``).

    Returns
    -------
    CaseResult
        Status ``ok`` or ``failed`` (small: no arrays, no meshes).
    """
    from slicerecon.case import run_case

    job = Job(case, case.name if folder is None else folder, config, key)
    final = Path(outdir) / job.folder
    final.parent.mkdir(parents=True, exist_ok=True)
    clear_stale(final.parent, final.name)
    staging = staging_dir(final)
    start = time.perf_counter()
    said: list[str] = []
    try:
        try:
            with collected_warnings() as said:
                summary = run_case(case.path, staging, config, image_dir=case.image_dir)
        except Exception as exc:  # noqa: BLE001 - every failure is recorded, none stops the batch
            result = failure_result(job, exc, time.perf_counter() - start)
            logger.info("case %s failed: %s: %s", job.folder, result.error_type, result.error)
            shutil.rmtree(staging, ignore_errors=True)
            staging.mkdir(parents=True)
            _failure_record(job, result, traceback.format_exc()).write(staging)
        else:
            metrics = summary.get("metrics")
            result = CaseResult(
                case=job.folder,
                input=case.relpath,
                kind=case.kind,
                status="ok",
                parts=int(summary["parts"]),
                planes=int(summary["planes"]),
                watertight=bool(summary["watertight"]),
                metrics=None
                if metrics is None
                else {k: v for k, v in metrics.items() if isinstance(v, int | float)},
                seconds=round(time.perf_counter() - start, 3),
                method=config.method,
                planner=config.planner,
                # run prints how labels.nii.gz holds overlapping structures on its own line:
                # a batch says it with the case's warnings (the PTV's label map 23 % below
                # its mesh was explained nowhere)
                warnings=(*said, *([f"overlaps: {summary['overlap']}"] * bool(summary["overlap"]))),
            )
            done = {
                "case": job.folder,
                "input": str(case.path),
                "key": key,
                "slicerecon_version": __version__,
                "meshes": [
                    str(record["mesh"])
                    for record in summary.get("structures") or []
                    if record.get("mesh")
                ],
                "files": sorted(
                    p.relative_to(staging).as_posix() for p in staging.rglob("*") if p.is_file()
                ),
                "finished_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                "result": result.to_json(),
            }
            write_json(CaseFiles(staging).done, done)  # last: marks the folder complete
        publish(staging, final)
    finally:
        if staging.exists():
            shutil.rmtree(staging, ignore_errors=True)
    if result.ok:  # what a reader of the folder sees (paths, config, timings)
        published = read_case(final, name=job.folder)
        if published.ok:
            result = replace(published, warnings=result.warnings)
    return result


def finished_result(outdir: Path, job: Job) -> CaseResult | None:
    """The stored result of a job an earlier run finished with the same key, or None.

    Parameters
    ----------
    outdir : Path
        The batch output directory.
    job : Job
        The job (its :attr:`Job.key` is compared with ``done.json``'s).

    Returns
    -------
    CaseResult or None
        Status ``skipped``, read from the case folder; None when the folder
        has no ``done.json`` with this key or one of its meshes is gone.
    """
    files = CaseFiles(outdir / job.folder)
    try:
        done = json.loads(files.done.read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(done, dict) or done.get("key") != job.key:
        return None
    meshes = done.get("meshes", [done.get("mesh", "")])
    if not isinstance(meshes, list) or not meshes:
        return None
    written = done.get("files", [])  # every file the case wrote (older runs: the meshes)
    if not isinstance(written, list):
        return None
    if not all((files.directory / str(name)).is_file() for name in [*meshes, *written]):
        return None
    stored = read_case(files.directory, name=job.folder)
    if not stored.ok:
        return None
    return replace(stored, status="skipped", input=job.case.relpath, kind=job.case.kind)
