"""Reconstruct every case of a directory on Dask, with failure isolation and resume.

:func:`run_batch` finds the cases of ``INDIR`` (:func:`pipelines.discover.discover_cases`),
reconstructs each one into ``OUTDIR/<case>/`` with
:func:`slicerecon.reconstruct.run_case`, one Dask task per case, and writes
``OUTDIR/summary.csv`` (then the HTML report, when :mod:`slicerecon.report`
provides ``write_report``).

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
once (see :func:`_run_on_dask`), so a case that kills its worker cannot take
cases queued behind it down with it.

Failures, resume and atomic outputs
-----------------------------------
A case that raises writes ``OUTDIR/<case>/error.json`` (``case``, ``input``,
``error``, ``type``, ``traceback``) and never stops the others. A finished case
writes ``OUTDIR/<case>/done.json`` last; it holds the case's *key*, the
SHA-256 of its input bytes (for a folder: every file's name and bytes), of
every :class:`~slicerecon.reconstruct.ReconstructConfig` field and of the
slicerecon version. A later run skips a case whose ``done.json`` holds the key
it would compute (and whose mesh is there); ``force=True`` recomputes it.

Each case is computed in a hidden staging folder ``OUTDIR/.<case>.partial-*``
and renamed to ``OUTDIR/<case>`` when complete, so ``OUTDIR/<case>/`` is
always one whole result (or one ``error.json``). A worker that dies (out of
memory, killed) leaves only a staging folder; Dask runs the case again on
another worker (up to ``retries`` more times), and that attempt and the end of
the batch remove the leftovers.

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
:func:`dask_setup`). A Ctrl-C that comes while the cluster starts or closes,
or while a case folder is being renamed into place, takes effect once that
step is done. (On a cluster given by ``scheduler`` the running cases go on
there and publish their results whole; the next run finds them.)
"""

from __future__ import annotations

import asyncio
import contextlib
import csv
import hashlib
import json
import logging
import os
import shutil
import signal
import threading
import time
import traceback
import uuid
import weakref
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import TYPE_CHECKING, Any

from slicerecon import __version__
from slicerecon.errors import InputError, OptionError
from slicerecon.io.atomic import atomic_path

from .discover import Case, discover_cases

if TYPE_CHECKING:  # imported where used: the worker processes preload this module
    from slicerecon.reconstruct import ReconstructConfig

__all__ = [
    "KEY_METRICS",
    "SUMMARY_COLUMNS",
    "BatchResult",
    "CaseResult",
    "case_key",
    "dask_setup",
    "process_case",
    "run_batch",
    "write_summary",
]

logger = logging.getLogger(__name__)

STATUSES = ("ok", "failed", "skipped")
KEY_METRICS = (
    "volume_iou",
    "dice",
    "surface_iou",
    "chamfer_l1_mm",
    "hd95_mm",
    "assd_mm",
    "volume_error",
)
"""Metrics copied into ``summary.csv`` (when ground truth is known)."""
SUMMARY_COLUMNS = (
    "case",
    "input",
    "kind",
    "status",
    "error",
    "error_type",
    "parts",
    "planes",
    "watertight",
    *KEY_METRICS,
    "seconds",
)
"""Columns of ``summary.csv``, in order."""
DONE_FILE = "done.json"
ERROR_FILE = "error.json"
SUMMARY_FILE = "summary.csv"
_CHUNK = 1 << 20


@dataclass(frozen=True)
class CaseResult:
    """The outcome of one case (one row of ``summary.csv``).

    Attributes
    ----------
    case : str
        Case name (``OUTDIR/<case>/``).
    input : str
        Input path relative to INDIR.
    kind : str
        Input kind (see :data:`pipelines.discover.CASE_KINDS`).
    status : {"ok", "failed", "skipped"}
        ``skipped``: finished by an earlier run with the same key.
    error, error_type : str
        Message and exception class name of a failed case (else empty).
    parts, planes : int or None
        Number of cuboid parts and of section planes used.
    watertight : bool or None
        Whether the mesh is closed.
    metrics : dict of str to float
        The :data:`KEY_METRICS` known (empty without ground truth).
    seconds : float
        Wall time of the reconstruction, s (for a skipped case: of the run
        that made its outputs).
    """

    case: str
    input: str
    kind: str
    status: str
    error: str = ""
    error_type: str = ""
    parts: int | None = None
    planes: int | None = None
    watertight: bool | None = None
    metrics: dict[str, float] = field(default_factory=dict)
    seconds: float = 0.0

    def to_row(self) -> dict[str, Any]:
        """The ``summary.csv`` row: one value per :data:`SUMMARY_COLUMNS` entry."""
        row: dict[str, Any] = {
            "case": self.case,
            "input": self.input,
            "kind": self.kind,
            "status": self.status,
            "error": self.error.replace("\n", " ").strip(),
            "error_type": self.error_type,
            "parts": "" if self.parts is None else self.parts,
            "planes": "" if self.planes is None else self.planes,
            "watertight": "" if self.watertight is None else str(self.watertight).lower(),
            "seconds": f"{self.seconds:.3f}",
        }
        for name in KEY_METRICS:
            value = self.metrics.get(name)
            row[name] = "" if value is None else f"{value:.6g}"
        return row


@dataclass(frozen=True)
class BatchResult:
    """What :func:`run_batch` did.

    Attributes
    ----------
    outdir : Path
        The output directory.
    cases : tuple of CaseResult
        One per case, in case (sorted input) order.
    summary_csv : Path
        ``OUTDIR/summary.csv``.
    report : Path or None
        The HTML report, when :mod:`slicerecon.report` wrote one.
    report_error : str
        Why the report failed (empty when it did not fail).
    seconds : float
        Wall time of the whole batch, s.
    """

    outdir: Path
    cases: tuple[CaseResult, ...]
    summary_csv: Path
    report: Path | None = None
    report_error: str = ""
    seconds: float = 0.0

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


# ------------------------------------------------------------------------------ keys
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
    folder keeps its key), of every field of ``config``, of the bytes of the
    policy weights file when ``config.weights`` is set, and of the slicerecon
    version.

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
    digest.update(json.dumps(asdict(config), sort_keys=True, default=str).encode() + b"\0")
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


# --------------------------------------------------------------------- case folders
@contextlib.contextmanager
def _sigint_deferred() -> Iterator[None]:
    """Hold a Ctrl-C (SIGINT) back until the block is done, then deliver it.

    Two things happen. In the main thread, the Python handler is swapped for
    one that only notes the signal; it is put back afterwards and a noted
    signal raised again (so the usual :class:`KeyboardInterrupt` comes after
    the block, whichever thread the kernel gave the signal to). And SIGINT is
    blocked in this thread's signal mask: threads and processes started inside
    the block inherit that mask and keep it, so SIGINT never reaches them. That
    is how the local cluster's worker processes, spawned from its event-loop
    thread, ignore the Ctrl-C a terminal sends to its whole process group. The
    mask part is skipped where POSIX signal masks do not exist (Windows).
    """
    in_main = threading.current_thread() is threading.main_thread()
    noted: list[int] = []
    previous: Any = None
    if in_main and signal.getsignal(signal.SIGINT) is not None:  # None: set outside Python
        previous = signal.signal(signal.SIGINT, lambda signum, frame: noted.append(signum))
    mask = None
    if hasattr(signal, "pthread_sigmask"):
        mask = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        if previous is not None:
            signal.signal(signal.SIGINT, previous)
        if mask is not None:
            signal.pthread_sigmask(signal.SIG_SETMASK, mask)
        if noted:
            signal.raise_signal(signal.SIGINT)


def _write_json(path: Path, payload: dict[str, Any]) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(payload, indent=2, default=str) + "\n")


def _clear_stale(outdir: Path, name: str) -> None:
    """Remove staging folders a killed attempt at case ``name`` left behind.

    A process killed between the two renames of :func:`_publish` leaves the
    previous result as ``.<name>.old-*`` and no ``<name>``: that result is put
    back rather than deleted.
    """
    final = outdir / name
    if not (final.exists() or final.is_symlink()):
        olds = sorted(outdir.glob(f".{name}.old-*"), key=lambda p: p.stat().st_mtime_ns)
        if olds:
            logger.info("restoring %s from %s", final, olds[-1])
            os.replace(olds[-1], final)
    for stale in outdir.glob(f".{name}.*"):
        logger.debug("removing leftover %s", stale)
        if stale.is_dir() and not stale.is_symlink():
            shutil.rmtree(stale, ignore_errors=True)
        else:
            with contextlib.suppress(FileNotFoundError):
                stale.unlink()


def _publish(staging: Path, final: Path) -> None:
    """Put the complete folder ``staging`` in place of ``final`` (renames only;
    a Ctrl-C in between is held back until both are done)."""
    old = None
    with _sigint_deferred():
        if final.exists() or final.is_symlink():
            old = final.with_name(f".{final.name}.old-{uuid.uuid4().hex[:12]}")
            os.replace(final, old)
        os.replace(staging, final)
    if old is not None:
        if old.is_dir() and not old.is_symlink():
            shutil.rmtree(old, ignore_errors=True)
        else:
            old.unlink()


def _failure(case: Case, exc: BaseException, seconds: float = 0.0) -> dict[str, Any]:
    return {
        "case": case.name,
        "input": case.relpath,
        "kind": case.kind,
        "status": "failed",
        "error": str(exc) or type(exc).__name__,
        "error_type": type(exc).__name__,
        "seconds": round(seconds, 3),
    }


def _error_payload(case: Case, row: dict[str, Any], tb: str) -> dict[str, Any]:
    return {
        "case": case.name,
        "input": str(case.path),
        "error": row["error"],
        "type": row["error_type"],
        "traceback": tb,
        "slicerecon_version": __version__,
    }


def _record_failure(outdir: Path, case: Case, row: dict[str, Any], tb: str) -> None:
    """Replace ``OUTDIR/<case>/`` by a folder holding only ``error.json``."""
    staging = outdir / f".{case.name}.partial-{uuid.uuid4().hex[:12]}"
    staging.mkdir(parents=True)
    _write_json(staging / ERROR_FILE, _error_payload(case, row, tb))
    _publish(staging, outdir / case.name)


def process_case(
    case: Case, outdir: str | os.PathLike[str], config: ReconstructConfig, key: str
) -> dict[str, Any]:
    """Reconstruct one case into ``OUTDIR/<case>/`` (the body of one Dask task).

    Never raises for a bad case: a failure is written to ``error.json`` and
    returned as a row with status ``failed``.

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

    Returns
    -------
    dict
        The fields of a :class:`CaseResult` (small: no arrays, no meshes).
    """
    from slicerecon.reconstruct import run_case

    out = Path(outdir)
    out.mkdir(parents=True, exist_ok=True)
    _clear_stale(out, case.name)
    staging = out / f".{case.name}.partial-{uuid.uuid4().hex[:12]}"
    start = time.perf_counter()
    try:
        try:
            summary = run_case(case.path, staging, config, image_dir=case.image_dir)
        except Exception as exc:  # noqa: BLE001 - every failure is recorded, none stops the batch
            row = _failure(case, exc, time.perf_counter() - start)
            logger.info("case %s failed: %s: %s", case.name, row["error_type"], row["error"])
            shutil.rmtree(staging, ignore_errors=True)
            staging.mkdir(parents=True)
            _write_json(staging / ERROR_FILE, _error_payload(case, row, traceback.format_exc()))
        else:
            metrics = summary.get("metrics") or {}
            row = {
                "case": case.name,
                "input": case.relpath,
                "kind": case.kind,
                "status": "ok",
                "parts": int(summary["parts"]),
                "planes": int(summary["planes"]),
                "watertight": bool(summary["watertight"]),
                "metrics": {k: float(metrics[k]) for k in KEY_METRICS if k in metrics},
                "seconds": round(time.perf_counter() - start, 3),
            }
            done = {
                "case": case.name,
                "input": str(case.path),
                "key": key,
                "slicerecon_version": __version__,
                "mesh": f"mesh.{config.mesh_format}",
                "finished_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
                "result": row,
            }
            _write_json(staging / DONE_FILE, done)  # last: marks the folder complete
        _publish(staging, out / case.name)
    finally:
        if staging.exists():
            shutil.rmtree(staging, ignore_errors=True)
    return row


def _finished(outdir: Path, case: Case, key: str) -> CaseResult | None:
    """The stored result of a case finished with ``key``, or None."""
    folder = outdir / case.name
    try:
        done = json.loads((folder / DONE_FILE).read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(done, dict) or done.get("key") != key:
        return None
    if not (folder / str(done.get("mesh", ""))).is_file():
        return None
    stored = done.get("result")
    if not isinstance(stored, dict):
        return None
    return _to_result({**stored, "case": case.name, "input": case.relpath, "status": "skipped"})


def _to_result(row: dict[str, Any]) -> CaseResult:
    names = {f.name for f in fields(CaseResult)}
    return CaseResult(**{k: v for k, v in row.items() if k in names})


# --------------------------------------------------------------------------- summary
def write_summary(results: Iterable[CaseResult], path: str | os.PathLike[str]) -> Path:
    """Write ``summary.csv`` atomically: complete, or not at all.

    Parameters
    ----------
    results : iterable of CaseResult
        One row each, in the order given.
    path : path-like
        Target file; an existing one is replaced only by a complete table.

    Returns
    -------
    Path
    """
    target = Path(path)
    with atomic_path(target) as tmp:
        with open(tmp, "w", newline="", encoding="utf-8") as fh:
            writer = csv.DictWriter(fh, fieldnames=list(SUMMARY_COLUMNS))
            writer.writeheader()
            for result in results:
                writer.writerow(result.to_row())
    return target


def _write_report(outdir: Path) -> tuple[Path | None, str]:
    """Call ``slicerecon.report.write_report(outdir)`` if it exists; never raise."""
    import importlib.util

    try:
        if importlib.util.find_spec("slicerecon.report") is None:
            logger.debug("slicerecon.report is not available: no HTML report")
            return None, ""
        from slicerecon.report import write_report  # type: ignore[attr-defined]
    except ImportError as exc:
        logger.warning("no HTML report: cannot import slicerecon.report.write_report (%s)", exc)
        return None, f"{type(exc).__name__}: {exc}"
    try:
        written = write_report(outdir)
    except Exception as exc:  # noqa: BLE001 - the report is optional; the batch stands
        logger.warning("the HTML report failed (%s: %s); summary.csv is complete",
                       type(exc).__name__, exc, exc_info=True)
        return None, f"{type(exc).__name__}: {exc}"
    return (Path(written) if isinstance(written, str | os.PathLike) else None), ""


# ------------------------------------------------------------------------ scheduling
_CLOSING = frozenset({"closing", "closing_gracefully", "closed", "failed"})


class _SilentWhileClosing(logging.Filter):
    """Drop the log records of a worker that is shutting down."""

    def __init__(self, worker: Any) -> None:
        super().__init__()
        self._worker = weakref.ref(worker)

    def filter(self, record: logging.LogRecord) -> bool:
        worker = self._worker()
        return worker is not None and getattr(worker.status, "name", "") not in _CLOSING


def dask_setup(worker: Any) -> None:
    """Prepare a worker process of the batch's local cluster (Dask's preload hook).

    Dask calls it in each worker process as it starts (the cluster is created
    with ``preload=["pipelines.batch"]``). The worker ignores SIGINT: a Ctrl-C is
    for the client to handle (the signal mask the process was spawned with
    already holds it back; this keeps it so should anything unblock it). And
    once the worker is shutting down (the end of a batch, or the client closing
    the cluster after a Ctrl-C while a case runs), its log records are dropped:
    cancelled tasks and lost connections are expected then, and would otherwise
    print warnings and tracebacks after the batch has ended.
    """
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    silent = _SilentWhileClosing(worker)
    for handler in logging.getLogger("distributed").handlers:
        handler.addFilter(silent)


def _stop_workers_now(cluster: Any, grace_s: float = 1.0) -> None:
    """Stop the local cluster's worker processes within about ``grace_s`` seconds.

    After a Ctrl-C the cases in flight are abandoned: rather than wait for them
    (a closing cluster gives each worker 5 s), each worker gets ``grace_s`` to
    stop and is then killed. Its staging folder is removed afterwards.
    """

    async def stop() -> None:
        await asyncio.gather(
            *(nanny.close(timeout=grace_s, reason="slicerecon-batch-interrupted")
              for nanny in list(cluster.workers.values())),
            return_exceptions=True,
        )

    try:
        cluster.sync(stop)
    except Exception:  # noqa: BLE001 - cluster.close() below finishes the job
        logger.debug("stopping the workers at once failed", exc_info=True)


def _start_resource_tracker() -> None:
    """Start multiprocessing's resource tracker now, outside :func:`_sigint_deferred`.

    It is started by the first process spawn, and it unblocks SIGINT in the
    thread that starts it: were that the cluster's event-loop thread, the worker
    processes spawned after it would receive Ctrl-C again.
    """
    try:
        from multiprocessing import resource_tracker
    except ImportError:  # pragma: no cover - not on every platform
        return
    resource_tracker.ensure_running()


def _import_distributed() -> None:
    """Import :mod:`distributed`, keeping a level the caller set on its logger.

    Its first import sets the ``distributed`` logger to the level of its config
    (INFO), which would undo e.g. the CLI's "errors only".
    """
    log = logging.getLogger("distributed")
    chosen = log.level
    import distributed  # noqa: F401

    if chosen != logging.NOTSET:
        log.setLevel(chosen)


@contextlib.contextmanager
def _dask_client(workers: int, scheduler: str | None, retries: int) -> Iterator[Any]:
    _import_distributed()
    import dask
    from distributed import Client, LocalCluster

    if scheduler is not None:
        try:
            remote = Client(scheduler, timeout=20)
        except (OSError, TimeoutError) as exc:
            raise OptionError(
                f"cannot reach the Dask scheduler at {scheduler} ({exc}); check the address "
                "and that `dask scheduler` is running there"
            ) from exc
        with remote:
            yield remote
        return
    # Workers log at the level the caller set for "distributed" (the CLI: errors
    # only), at least WARNING; LocalCluster's own default would reset it to WARNING.
    quiet = max(logging.getLogger("distributed").getEffectiveLevel(), logging.WARNING)
    _start_resource_tracker()
    cluster: Any = None
    client: Any = None
    interrupted = False
    try:
        # SIGINT is blocked while the cluster starts: its event-loop thread, and
        # the worker processes that thread spawns (now and on restarts), keep the
        # blocked mask for good, so a Ctrl-C reaches this thread only. The
        # assignments happen inside the block, so `finally` always sees them.
        with _sigint_deferred():
            with dask.config.set({"distributed.scheduler.allowed-failures": retries}):
                cluster = LocalCluster(
                    n_workers=workers,
                    processes=True,
                    threads_per_worker=1,
                    dashboard_address=None,
                    silence_logs=quiet,
                    preload=[__name__],  # runs dask_setup in each worker process
                )
            client = Client(cluster)
        yield client
    except KeyboardInterrupt:
        interrupted = True
        raise
    finally:
        with _sigint_deferred():  # a second Ctrl-C does not break the shutdown
            _close_local(client, cluster, interrupted=interrupted)


def _close_local(client: Any, cluster: Any, *, interrupted: bool) -> None:
    """Close the client, then the local cluster.

    After a Ctrl-C the workers are stopped at once (:func:`_stop_workers_now`)
    and a failing step is logged rather than raised: the interruption is what
    the user is told about.
    """
    steps: list[Callable[[], Any]] = []
    if client is not None:
        steps.append(client.close)
    if cluster is not None:
        if interrupted:
            steps.append(lambda: _stop_workers_now(cluster))
        steps.append(cluster.close)
    for step in steps:
        try:
            step()
        except Exception:
            if not interrupted:
                raise
            logger.debug("shutting the local cluster down after a Ctrl-C", exc_info=True)


def _run_on_dask(
    todo: Sequence[tuple[Case, str]],
    outdir: Path,
    config: ReconstructConfig,
    *,
    workers: int,
    scheduler: str | None,
    retries: int,
    on_done: Callable[[Case, dict[str, Any]], None],
) -> None:
    """Run ``todo`` on Dask, keeping about as many cases in flight as there are threads.

    Submitting every case at once would queue several on each worker; when a
    worker dies, Dask counts each case queued on it as a suspect, so a case that
    keeps killing workers could fail innocent ones too. Feeding the cluster one
    case per free thread avoids that (and keeps the scheduler small for long
    batches); the thread count is read again after every case, so workers that
    join later are used.
    """
    _import_distributed()
    from distributed import as_completed
    from distributed.scheduler import KilledWorker

    token = uuid.uuid4().hex[:8]
    pending = list(todo)
    with _dask_client(workers, scheduler, retries) as client:
        running: dict[Any, Case] = {}
        finished = as_completed(with_results=True, raise_errors=False)

        def fill() -> None:
            limit = max(1, sum(client.nthreads().values()))
            while pending and len(running) < limit:
                case, key = pending.pop(0)
                future = client.submit(
                    process_case,
                    case,
                    str(outdir),
                    config,
                    key,
                    key=f"slicerecon-case-{case.name}-{token}",
                    pure=False,
                    retries=retries,
                )
                running[future] = case
                finished.add(future)

        fill()
        for future, outcome in finished:
            case = running.pop(future)
            if future.status == "finished":
                row = outcome
            else:  # with raise_errors=False an error comes as (type, exception, traceback)
                exc = outcome[1] if isinstance(outcome, tuple) else outcome
                if not isinstance(exc, BaseException):
                    exc = RuntimeError(f"Dask task ended as {future.status}")
                row = _failure(case, exc)
                if isinstance(exc, KilledWorker):
                    row["error"] = (
                        "every worker process that ran this case died (out of memory, "
                        f"killed or crashed): {exc}"
                    )
                logger.warning("case %s failed on Dask: %s", case.name, row["error"])
                _record_failure(outdir, case, row, "".join(traceback.format_exception(exc)))
            future.release()
            on_done(case, row)
            fill()


def run_batch(
    indir: str | os.PathLike[str],
    outdir: str | os.PathLike[str],
    config: ReconstructConfig,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    force: bool = False,
    progress: Callable[[CaseResult, int, int], None] | None = None,
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
    config : ReconstructConfig
        Reconstruction options, the same for every case.
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
        ``slicerecon.report.write_report(outdir)`` when that exists. A report
        that fails is logged (and kept in ``BatchResult.report_error``); it
        never fails the batch.
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
        If ``workers`` or ``retries`` is negative, or the scheduler cannot be reached.
    KeyboardInterrupt
        On Ctrl-C, after the local cluster is closed and the staging folders
        of the cases in flight are removed (see "Interruption" above).
    """
    if workers is not None and workers < 0:
        raise OptionError(f"--workers must be 0 (in-process) or more (got {workers})")
    if retries < 0:
        raise OptionError(f"retries must be 0 or more (got {retries})")
    from slicerecon.reconstruct import ReconstructConfig

    if not isinstance(config, ReconstructConfig):
        raise OptionError(f"config must be a ReconstructConfig (got {type(config).__name__})")
    start = time.perf_counter()
    src = Path(indir).resolve()
    out = Path(outdir).resolve()
    if out == src:
        raise OptionError(
            f"OUTDIR must differ from INDIR ({src}): the outputs (JSON files among them) "
            "would be read back as inputs; pass another -o"
        )
    cases = discover_cases(src, exclude=[out], follow_symlinks=follow_symlinks)
    if not cases:
        raise InputError(
            f"no cases found in {src}: expected NIfTI masks (.nii/.nii.gz), contour files "
            "(.json/.csv), DICOM series folders, DICOM SEG or RTSTRUCT files"
        )
    out.mkdir(parents=True, exist_ok=True)
    total = len(cases)
    results: dict[str, CaseResult] = {}

    def finish(case: Case, row: dict[str, Any]) -> None:
        result = _to_result(row)
        results[case.name] = result
        if progress is not None:
            progress(result, len(results), total)

    todo: list[tuple[Case, str]] = []
    for case in cases:
        if case.error:  # a symbolic link that is not followed: recorded, never opened
            row = _failure(case, InputError(case.error))
            _record_failure(out, case, row, "")
            finish(case, row)
            continue
        try:
            key = case_key(case, config)
        except InputError as exc:
            row = _failure(case, exc)
            _record_failure(out, case, row, traceback.format_exc())
            finish(case, row)
            continue
        previous = None if force else _finished(out, case, key)
        if previous is not None:
            results[case.name] = previous
            if progress is not None:
                progress(previous, len(results), total)
        else:
            todo.append((case, key))
    logger.info("%d case(s): %d to compute, %d finished before", total, len(todo),
                total - len(todo))

    try:
        if todo and scheduler is None and workers == 0:
            for case, key in todo:
                finish(case, process_case(case, out, config, key))
        elif todo:
            n_workers = workers if workers is not None else min(os.cpu_count() or 1, len(todo))
            _run_on_dask(
                todo, out, config, workers=n_workers, scheduler=scheduler, retries=retries,
                on_done=finish,
            )
    except KeyboardInterrupt:
        logger.info("interrupted: %d of %d case(s) done; summary.csv not rewritten",
                    len(results), total)
        if scheduler is None:  # the local workers are gone: nothing writes to OUTDIR now
            with _sigint_deferred():
                for case, _ in todo:
                    _clear_stale(out, case.name)
        raise
    for case, _ in todo:
        _clear_stale(out, case.name)

    ordered = tuple(results[case.name] for case in cases)
    summary = write_summary(ordered, out / SUMMARY_FILE)
    report_path, report_error = _write_report(out) if report else (None, "")
    result = BatchResult(out, ordered, summary, report_path, report_error,
                         time.perf_counter() - start)
    logger.info("batch done: %d ok, %d failed, %d skipped in %.1f s",
                result.n_ok, result.n_failed, result.n_skipped, result.seconds)
    return result
