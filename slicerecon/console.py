"""What the command line shows and how its process runs.

Deferred Ctrl-C during heavy imports, stage progress, the summary of a run,
and the allocator setting of the console script's own process. The library
never imports this module (progress and colour live in the CLI and pipelines).
"""

from __future__ import annotations

import contextlib
import signal
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

__all__ = ["StageProgress", "ctrl_c_after", "keep_freed_memory", "print_run_summary"]


@contextlib.contextmanager
def ctrl_c_after() -> Iterator[None]:
    """Deliver a Ctrl-C pressed inside the block when it is done.

    trimesh imports its optional dependencies under ``except BaseException`` and
    would swallow a KeyboardInterrupt raised while the heavy modules load.
    """
    noted: list[int] = []
    try:
        previous = signal.signal(signal.SIGINT, lambda signum, frame: noted.append(signum))
    except ValueError:  # not the main thread: nothing to defer
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
        if noted:
            raise KeyboardInterrupt


class StageProgress:
    """Stage progress on stderr, shown only once a run has taken about two seconds.

    Called with each stage name (``"read"``, ``"reconstruct 2/4: 2_Liver"``,
    ``"evaluate"``, ``"write"``). Quick runs print nothing. Once a run has
    taken :attr:`DELAY_S` seconds it shows where it is: in a terminal, a rich
    spinner naming the current stage; when stderr is not a terminal (piped
    into a file or a log), one plain line per stage from then on,
    ``progress: <stage> (<seconds> s)``, which a log keeps and ``grep`` finds.

    Parameters
    ----------
    enabled : bool
        False shows nothing (``run -q``).
    stream : file-like, optional
        Where to write (default: ``sys.stderr`` when the progress is created).
    """

    DELAY_S = 2.0

    def __init__(self, *, enabled: bool, stream: Any = None) -> None:
        import threading

        self._enabled = enabled
        self._stream = sys.stderr if stream is None else stream
        isatty = getattr(self._stream, "isatty", None)
        self._plain = not (callable(isatty) and isatty())
        self._lock = threading.Lock()
        self._status: Any = None
        self._shown = False
        self._stage = "read"
        self._start = time.perf_counter()
        self._timer = threading.Timer(self.DELAY_S, self._show)
        self._timer.daemon = True

    @property
    def plain(self) -> bool:
        """True when stages are written as plain lines (stderr is not a terminal)."""
        return self._plain

    def __enter__(self) -> StageProgress:
        self._start = time.perf_counter()
        if self._enabled:
            self._timer.start()
        return self

    def _line(self) -> None:
        elapsed = time.perf_counter() - self._start
        try:
            self._stream.write(f"progress: {self._stage} ({elapsed:.1f} s)\n")
            self._stream.flush()
        except (OSError, ValueError):  # a closed pipe must not stop the run
            pass

    def _show(self) -> None:
        with self._lock:
            self._shown = True
            if self._plain:
                self._line()
                return
            from rich.console import Console

            self._status = Console(file=self._stream).status(self._stage)
            self._status.start()

    def __call__(self, stage: str) -> None:
        with self._lock:
            if stage == self._stage:
                return
            self._stage = stage
            if not self._shown:
                return
            if self._plain:
                self._line()
            elif self._status is not None:
                self._status.update(stage)

    def __exit__(self, *exc: object) -> None:
        self._timer.cancel()
        with self._lock:
            if self._status is not None:
                self._status.stop()


def print_run_summary(summary: dict[str, Any], outdir: Path) -> None:
    """Print what ``slicerecon run`` made: parts, structures, metrics, times, where."""
    from rich.console import Console
    from rich.table import Table

    console = Console()
    if summary.get("annotation"):
        # one line, however narrow the terminal or the pipe (grep finds it whole)
        console.print(f"read as: {summary['annotation']}", highlight=False, soft_wrap=True)
    if summary.get("overlap"):
        console.print(f"overlaps: {summary['overlap']}", highlight=False, soft_wrap=True)
    console.print(
        f"[bold]{summary['parts']}[/] part(s) from [bold]{summary['planes']}[/] planes -> "
        f"{summary['mesh']} (watertight: {summary['watertight']})",
        soft_wrap=True,
    )
    structures = summary.get("structures") or []
    if len(structures) > 1:
        listing = Table(
            "value", "name", "status", "planes", "volume (mm³)", "mesh", title="structures"
        )
        for record in structures:
            listing.add_row(
                str(record["value"]),
                record["name"],
                record["status"],
                str(record["planes"]),
                f"{record['volume_mm3']:.6g}",
                str(record.get("mesh", "")),
            )
        console.print(listing)
    metrics = summary.get("metrics")
    if metrics:
        table = Table("metric", "value", title="quality vs ground truth")
        for key, value in metrics.items():
            table.add_row(key, f"{value:.4g}" if isinstance(value, float) else str(value))
        if summary.get("missing"):  # the mean is over the scored structures only
            table.add_row("not scored", ", ".join(summary["missing"]))
        console.print(table)
    times = ", ".join(f"{k} {v:.2f}s" for k, v in summary["timings_s"].items())
    console.print(f"time: {times}")
    console.print(f"outputs in {outdir}")


def keep_freed_memory() -> None:
    """Let this process reuse the memory it frees instead of mapping fresh pages.

    glibc serves every allocation over 32 MiB (any large array) from a fresh
    ``mmap`` and unmaps it when freed, so each such array costs a page fault
    per 4 KiB on first touch: on virtual machines that was a fifth of a
    clinical-size run (``docs/results.md``, speed). Serving them from the heap
    and keeping freed memory (``mallopt``: no mmap, no trimming, 256 MiB of top
    padding) lets later arrays reuse pages already touched; the peak memory
    does not grow (it fell slightly in the measurements). Only the console
    script does this, for its own short-lived process; elsewhere (another libc)
    nothing happens.
    """
    import ctypes
    import ctypes.util

    name = ctypes.util.find_library("c")
    if not sys.platform.startswith("linux") or not name:
        return
    try:
        libc = ctypes.CDLL(name)
        mallopt = libc.mallopt
    except (OSError, AttributeError):  # not glibc
        return
    m_trim_threshold, m_top_pad, m_mmap_max = -1, -2, -4
    mallopt(m_mmap_max, 0)
    mallopt(m_trim_threshold, 2**31 - 1)
    mallopt(m_top_pad, 256 * 2**20)
