"""Publishing case folders: staging, atomic renames, failure records, Ctrl-C deferral.

A case is computed in a hidden staging folder beside its final place
(``.<name>.partial-<hex>``) and renamed into place only when complete
(:func:`publish`), so a case folder is always one whole result, one
``error.json``, or absent. A previous result is first renamed aside
(``.<name>.old-<hex>``) and deleted after; :func:`clear_stale` removes the
leftovers of a killed attempt and puts back a result a killed publish left aside.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import shutil
import signal
import threading
import uuid
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from slicerecon.io.atomic import atomic_path
from slicerecon.results import FailureRecord

__all__ = [
    "clear_stale",
    "publish",
    "record_failure",
    "sigint_deferred",
    "staging_dir",
    "write_json",
]

logger = logging.getLogger(__name__)


@contextlib.contextmanager
def sigint_deferred() -> Iterator[None]:
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


def write_json(path: Path, payload: dict[str, Any]) -> None:
    """Write ``payload`` as indented JSON to ``path``, atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(payload, indent=2, default=str) + "\n")


def staging_dir(final: Path) -> Path:
    """A new, empty staging folder for the case folder ``final`` (beside it, hidden)."""
    staging = final.with_name(f".{final.name}.partial-{uuid.uuid4().hex[:12]}")
    staging.mkdir(parents=True)
    return staging


def clear_stale(parent: Path, name: str) -> None:
    """Remove staging folders a killed attempt at case folder ``parent/name`` left behind.

    A process killed between the two renames of :func:`publish` leaves the
    previous result as ``.<name>.old-*`` and no ``<name>``: that result is put
    back rather than deleted.
    """
    if not parent.is_dir():
        return
    final = parent / name
    if not (final.exists() or final.is_symlink()):
        olds = sorted(parent.glob(f".{name}.old-*"), key=lambda p: p.stat().st_mtime_ns)
        if olds:
            logger.info("restoring %s from %s", final, olds[-1])
            os.replace(olds[-1], final)
    for stale in parent.glob(f".{name}.*"):
        logger.debug("removing leftover %s", stale)
        if stale.is_dir() and not stale.is_symlink():
            shutil.rmtree(stale, ignore_errors=True)
        else:
            with contextlib.suppress(FileNotFoundError):
                stale.unlink()


def publish(staging: Path, final: Path) -> None:
    """Put the complete folder ``staging`` in place of ``final`` (renames only;
    a Ctrl-C in between is held back until both are done)."""
    old = None
    with sigint_deferred():
        if final.exists() or final.is_symlink():
            old = final.with_name(f".{final.name}.old-{uuid.uuid4().hex[:12]}")
            os.replace(final, old)
        os.replace(staging, final)
    if old is not None:
        if old.is_dir() and not old.is_symlink():
            shutil.rmtree(old, ignore_errors=True)
        else:
            old.unlink()


def record_failure(final: Path, record: FailureRecord) -> None:
    """Replace the case folder ``final`` by a folder holding only ``error.json``."""
    staging = staging_dir(final)
    try:
        record.write(staging)
        publish(staging, final)
    finally:
        if staging.exists():
            shutil.rmtree(staging, ignore_errors=True)
