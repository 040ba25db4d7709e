"""Running jobs on Dask: the local cluster, an existing cluster, and Ctrl-C.

* ``scheduler="tcp://host:8786"``: on an existing Dask cluster. Its workers
  need slicerecon installed and the same paths to ``INDIR`` and ``OUTDIR``
  (a shared filesystem).
* otherwise a ``distributed.LocalCluster`` of ``workers`` processes with one
  thread each, started for the batch and closed after it. Its worker
  processes are started with SIGINT blocked (:func:`dask_setup` is their
  preload hook), so a Ctrl-C reaches the client alone.

Jobs are submitted one per free worker thread rather than all at once (see
:func:`run_on_dask`), so a case that kills its worker cannot take cases queued
behind it down with it.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import signal
import threading
import traceback
import uuid
import weakref
from collections.abc import Callable, Iterator, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

from slicerecon.errors import OptionError
from slicerecon.results import CaseResult

from .publish import sigint_deferred
from .runner import Job, failure_result, process_case, record_failed_job

__all__ = ["dask_setup", "reach_scheduler", "run_on_dask"]

logger = logging.getLogger(__name__)

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
    with ``preload=["pipelines.cluster"]``). The worker ignores SIGINT: a Ctrl-C is
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
            *(
                nanny.close(timeout=grace_s, reason="slicerecon-batch-interrupted")
                for nanny in list(cluster.workers.values())
            ),
            return_exceptions=True,
        )

    try:
        cluster.sync(stop)
    except Exception:  # noqa: BLE001 - cluster.close() below finishes the job
        logger.debug("stopping the workers at once failed", exc_info=True)


def _start_resource_tracker() -> None:
    """Start multiprocessing's resource tracker now, outside :func:`sigint_deferred`.

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


def reach_scheduler(scheduler: str) -> None:
    """Connect to the Dask scheduler at ``scheduler`` and leave, before anything is
    written: an unreachable one is refused in one line (a broken link among the inputs
    was already recorded as a failed case when the connection failed).

    Raises
    ------
    OptionError
        The scheduler cannot be reached (20 s).
    """
    with _dask_client(0, scheduler, 0):
        pass


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
        with sigint_deferred():
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
        with sigint_deferred():  # a second Ctrl-C does not break the shutdown
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


def run_on_dask(
    todo: Sequence[Job],
    outdir: Path,
    *,
    workers: int,
    scheduler: str | None,
    retries: int,
    on_done: Callable[[Job, CaseResult], None],
) -> None:
    """Run ``todo`` on Dask, keeping about as many jobs in flight as there are threads.

    Submitting every job at once would queue several on each worker; when a
    worker dies, Dask counts each job queued on it as a suspect, so a case that
    keeps killing workers could fail innocent ones too. Feeding the cluster one
    job per free thread avoids that (and keeps the scheduler small for long
    batches); the thread count is read again after every job, so workers that
    join later are used.

    Parameters
    ----------
    todo : sequence of Job
        The jobs, in the order to submit them.
    outdir : Path
        The batch output directory (absolute).
    workers : int
        Worker processes of the local cluster (ignored with ``scheduler``).
    scheduler : str or None
        Address of a running Dask scheduler.
    retries : int
        Re-runs of a job whose worker died (and of a task that raised inside Dask).
    on_done : callable
        Called as ``on_done(job, result)`` in this process as each job ends.

    Raises
    ------
    OptionError
        If the scheduler cannot be reached.
    KeyboardInterrupt
        On Ctrl-C, after the local cluster is closed.
    """
    _import_distributed()
    from distributed import as_completed
    from distributed.scheduler import KilledWorker

    token = uuid.uuid4().hex[:8]
    pending = list(todo)
    with _dask_client(workers, scheduler, retries) as client:
        running: dict[Any, Job] = {}
        finished = as_completed(with_results=True, raise_errors=False)

        def fill() -> None:
            limit = max(1, sum(client.nthreads().values()))
            while pending and len(running) < limit:
                job = pending.pop(0)
                future = client.submit(
                    process_case,
                    job.case,
                    str(outdir),
                    job.config,
                    job.key,
                    folder=job.folder,
                    key=f"slicerecon-case-{job.folder.replace('/', '--')}-{token}",
                    pure=False,
                    retries=retries,
                )
                running[future] = job
                finished.add(future)

        fill()
        for future, outcome in finished:
            job = running.pop(future)
            if future.status == "finished":
                result = outcome
            else:  # with raise_errors=False an error comes as (type, exception, traceback)
                exc = outcome[1] if isinstance(outcome, tuple) else outcome
                if not isinstance(exc, BaseException):
                    exc = RuntimeError(f"Dask task ended as {future.status}")
                result = failure_result(job, exc)
                if isinstance(exc, KilledWorker):
                    result = replace(
                        result,
                        error=(
                            "every worker process that ran this case died (out of memory, "
                            f"killed or crashed): {exc}"
                        ),
                    )
                logger.warning("case %s failed on Dask: %s", job.folder, result.error)
                record_failed_job(outdir, job, result, "".join(traceback.format_exception(exc)))
            future.release()
            on_done(job, result)
            fill()
