"""Run fuzzed inputs through ``load_input → prepare_inputs → reconstruct`` in child processes.

Each worker is a fresh Python process (``python fuzz_runner.py --worker``) that
imports slicerecon once, warms it up, limits its own address space
(``RLIMIT_AS``) and then loops: it reads one request (a JSON line on stdin:
the input path and the method), runs the pipeline and writes one JSON line
back on a private copy of its stdout (fd 1 itself is pointed at stderr, so
nothing the library prints can corrupt the protocol). The parent keeps a few
workers busy, gives each case a wall-clock limit, and restarts a worker that
dies or hangs. Per case, the outcome is one of :data:`KINDS`:

``ok``
    the pipeline finished;
``error``
    a :class:`~slicerecon.errors.SlicereconError` (a clear refusal: fine);
``escape``
    any other exception (type, message, the innermost slicerecon frame and the
    tail of the traceback are recorded);
``memory``
    ``MemoryError`` under the address-space limit;
``timeout``
    no answer within the time limit (the worker is killed);
``crash``
    the worker died (a signal, e.g. SIGSEGV, or an exit).

Through the command line (``mode="cli"``: each mutant goes through ``slicerecon
run`` and ``slicerecon info`` in the worker, as the console script runs them,
stdout and stderr captured down to the file descriptors), two more:

``warning``
    a Python ``warnings`` line (``file:line: UserWarning: ...``) reached stderr;
``unclean``
    an exit code other than 0 and 2, a refusal (exit 2) that is not exactly one
    ``error:`` line, or stray lines on stderr after a success.

``escape`` is then a traceback (an exception out of ``main``), and ``timeout``
also a command that took longer than its limit (20 s by default). Every kind
but ``ok`` and ``error`` is a failure. Used by ``tests/test_fuzz.py`` and
``benchmarks/fuzz_inputs.py``.
"""

from __future__ import annotations

import json
import os
import queue
import re
import selectors
import signal
import subprocess
import sys
import threading
import time
from collections import Counter, defaultdict
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any, NamedTuple

__all__ = [
    "FAILURES",
    "KINDS",
    "MODES",
    "Outcome",
    "failure_groups",
    "failure_report",
    "markdown_summary",
    "run_mutants",
    "table",
]

_OUR_WARNING = re.compile(r"^warning: \S")
"""A warning the command line shows by default (``warning: <message>``), not a stray line."""
KINDS = ("ok", "error", "escape", "memory", "timeout", "crash", "warning", "unclean")
"""Outcome kinds, in table order (the last two only through the command line)."""
FAILURES = ("escape", "memory", "timeout", "crash", "warning", "unclean")
"""The outcome kinds that are failures."""
MODES = ("pipeline", "cli")
"""What a worker runs: the library pipeline, or ``slicerecon run`` and ``slicerecon info``."""
_SEVERITY = ("ok", "error", "unclean", "warning", "escape", "memory", "timeout", "crash")
"""Outcome kinds from the mildest: a mutant's outcome is the worst of its commands'."""
_WARNING_LINE = re.compile(r"^(?P<where>\S.*?:\d+): (?P<category>[A-Za-z_]*Warning): (?P<text>.*)$")
"""A line Python's ``warnings`` module prints on stderr (``file:line: Category: message``)."""
_STARTUP_TIMEOUT = 120.0
_THREAD_VARIABLES = (
    "OMP_NUM_THREADS",
    "OPENBLAS_NUM_THREADS",
    "MKL_NUM_THREADS",
    "NUMEXPR_NUM_THREADS",
    "VECLIB_MAXIMUM_THREADS",
)


class Outcome(NamedTuple):
    """What one mutant did.

    Attributes
    ----------
    mutant : Mutant
        The input (``fuzz_mutations.Mutant``).
    kind : str
        One of :data:`KINDS`.
    error : str
        Exception type (``""`` for ok, timeout and crash; the signal for a crash).
    message : str
        Exception message, shortened.
    where : str
        Innermost slicerecon frame, ``slicerecon/io/vti.py:123 in read_vti``
        (``""`` when none).
    raised_at : str
        Innermost frame of all (may be in numpy, pydicom, ...).
    traceback : str
        Tail of the formatted traceback (escapes and memory errors).
    seconds : float
        Wall time of the case, s.
    cause : str
        For a project error raised from another exception (e.g. a reader's
        catch-all boundary wrapping a ValueError): that exception's type and
        innermost slicerecon frame. Not a failure; worth a look.
    """

    mutant: Any
    kind: str
    error: str = ""
    message: str = ""
    where: str = ""
    raised_at: str = ""
    traceback: str = ""
    seconds: float = 0.0
    cause: str = ""

    @property
    def failed(self) -> bool:
        """True for escapes, memory errors, timeouts and crashes."""
        return self.kind in FAILURES


# ----------------------------------------------------------------------------- worker side
def _frame(frame: Any) -> str:
    filename = frame.filename.replace(os.sep, "/")
    cut = filename.rfind("/slicerecon/")
    if cut >= 0:
        filename = filename[cut + 1 :]
    else:
        cut = filename.rfind("site-packages/")
        filename = filename[cut + len("site-packages/") :] if cut >= 0 else filename
    return f"{filename}:{frame.lineno} in {frame.name}"


def _describe(exc: BaseException) -> dict[str, str]:
    import traceback

    frames = traceback.extract_tb(exc.__traceback__)
    ours = [
        f
        for f in frames
        if "/slicerecon/" in f.filename.replace(os.sep, "/")
        and "/tests/" not in f.filename.replace(os.sep, "/")
    ]
    text = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__, limit=-8))
    return {
        "error": type(exc).__name__,
        "message": str(exc)[:400],
        "where": _frame(ours[-1]) if ours else "",
        "raised_at": _frame(frames[-1]) if frames else "",
        "traceback": text[-3000:],
    }


def _pipeline(path: str, method: str, pixel_spacing: float | None, budget_gb: float) -> None:
    from slicerecon.case import reconstruct_case
    from slicerecon.case_inputs import load_case
    from slicerecon.io import detect_kind
    from slicerecon.reconstruct import ReconstructConfig

    # the one case pipeline `slicerecon run` uses: every structure, dense or sparse, planes
    # of any orientation; grid-free contours on the mutant's pixel spacing (--pixel-spacing)
    options: dict[str, Any] = {"max_memory_gb": budget_gb}
    if method == "sdf":
        options.update(method="sdf", planner="none", carve=False)
    if detect_kind(path).is_sparse:
        options["pixel_spacing"] = pixel_spacing
    else:
        options["slices"] = 6
    config = ReconstructConfig(**options)
    reconstruct_case(load_case(path, config), config)


def _cli_command(args: list[str], command_timeout: float) -> dict[str, Any]:
    """Run one ``slicerecon`` command as the console script would; classify what it did."""
    import contextlib
    import io
    import tempfile

    from slicerecon.cli import main

    captured = io.StringIO()
    start = time.perf_counter()
    result: dict[str, Any] = {}
    with tempfile.TemporaryFile() as raw:
        sys.stderr.flush()
        saved = os.dup(2)
        os.dup2(raw.fileno(), 2)  # C-level writes (ITK, libpng, ...) too
        try:
            with contextlib.redirect_stderr(captured), contextlib.redirect_stdout(io.StringIO()):
                code: Any = main(args)
        except SystemExit as exc:
            code = exc.code
        except MemoryError as exc:
            result = {"kind": "memory", **_describe(exc)}
        except KeyboardInterrupt:
            raise
        except BaseException as exc:  # noqa: BLE001 - a traceback is what we look for
            result = {"kind": "escape", **_describe(exc)}
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        raw.seek(0)
        text = captured.getvalue() + raw.read().decode("utf-8", "replace")
    seconds = time.perf_counter() - start
    lines = [line for line in text.splitlines() if line.strip()]
    if result:
        pass
    elif seconds > command_timeout:
        result = {"kind": "timeout", "message": f"took {seconds:.1f} s (limit {command_timeout:g})"}
    elif any(_WARNING_LINE.match(line) for line in lines):
        found = next(m for m in map(_WARNING_LINE.match, lines) if m)
        result = {
            "kind": "warning",
            "error": found.group("category"),
            "message": found.group("text")[:400],
            "where": found.group("where"),
        }
    elif code == 0 and all(_OUR_WARNING.match(line) for line in lines):
        result = {"kind": "ok"}  # warnings the command line shows, one line each
    elif (
        code == 2
        and lines
        and lines[-1].startswith("error: ")
        and all(_OUR_WARNING.match(line) for line in lines[:-1])
    ):
        result = {"kind": "error", "message": lines[-1][len("error: ") :][:400]}
    else:
        result = {
            "kind": "unclean",
            "error": f"exit {code}",
            "message": " | ".join(lines[:4])[:400],
        }
    result["seconds"] = seconds
    return result


def _run_cli(request: dict[str, Any]) -> dict[str, Any]:
    """``slicerecon run`` then ``slicerecon info`` on one input; the worse outcome of the two."""
    import shutil
    import tempfile

    budget = f"{request['budget_gb']:g}"
    options = ["--planner", "none", "--no-carve"] if request["method"] == "sdf" else []
    if request["pixel_spacing"] is not None:  # grid-free contours, as in the pipeline mode
        options += ["--pixel-spacing", f"{request['pixel_spacing']:g}"]
    outdir = tempfile.mkdtemp(prefix="slicerecon-fuzz-out-")
    try:
        results = {
            "run": _cli_command(
                ["run", request["path"], "-o", outdir, "-q", "--max-memory", budget, *options],
                request["command_timeout"],
            ),
            "info": _cli_command(
                ["info", request["path"], "--max-memory", budget], request["command_timeout"]
            ),
        }
    finally:
        shutil.rmtree(outdir, ignore_errors=True)
    command, worst = max(results.items(), key=lambda kv: _SEVERITY.index(kv[1]["kind"]))
    out = dict(worst)
    if out["kind"] not in ("ok", "error"):
        out["error"] = f"{command}: {out.get('error') or out['kind']}"
    out["message"] = "; ".join(
        f"{name} {r['kind']}{': ' + r['message'][:180] if r.get('message') else ''}"
        for name, r in results.items()
    )
    out["seconds"] = sum(r["seconds"] for r in results.values())
    return out


def _run_one(request: dict[str, Any]) -> dict[str, Any]:
    from slicerecon.errors import SlicereconError

    if request.get("mode") == "cli":
        return _run_cli(request)
    start = time.perf_counter()
    result: dict[str, Any] = {"kind": "ok"}
    try:
        _pipeline(
            request["path"], request["method"], request["pixel_spacing"], request["budget_gb"]
        )
    except SlicereconError as exc:
        result = {"kind": "error", "error": type(exc).__name__, "message": str(exc)[:400]}
        cause = exc.__cause__ or exc.__context__
        if cause is not None and not isinstance(cause, SlicereconError):
            described = _describe(cause)
            where = described["where"] or described["raised_at"]
            result["cause"] = f"{described['error']} at {where}"
    except MemoryError as exc:
        result = {"kind": "memory", **_describe(exc)}
    except KeyboardInterrupt:
        raise
    except BaseException as exc:  # noqa: BLE001 - every other exception is what we look for
        result = {"kind": "escape", **_describe(exc)}
    result["seconds"] = time.perf_counter() - start
    return result


def _warm_up() -> None:
    """Import what the pipeline imports lazily, so the memory limit and timings see work only."""
    import numpy as np

    from slicerecon.io import contours, dicom, nifti, rtstruct, vti  # noqa: F401
    from slicerecon.reconstruct import prepare_inputs, reconstruct
    from slicerecon.sections import Volume

    grid = np.indices((12, 12, 10)) - np.array([5.5, 5.5, 4.5])[:, None, None, None]
    volume = Volume((grid**2).sum(axis=0) < 16, np.diag([1.0, 1.0, 2.0, 1.0]))
    sections, projections, _ = prepare_inputs(volume, slices=6)
    reconstruct(sections, projections, method="sdf", planner="none", carve=False)
    reconstruct(sections, projections)


def _warm_up_cli() -> None:
    """Run both commands once on a tiny NIfTI and import the writers' libraries."""
    import contextlib
    import io
    import shutil
    import tempfile

    import highdicom  # noqa: F401 - imported on first use by the DICOM outputs
    import nibabel as nib
    import numpy as np

    from slicerecon.cli import main

    folder = Path(tempfile.mkdtemp(prefix="slicerecon-fuzz-warm-"))
    try:
        grid = np.indices((12, 12, 10)) - np.array([5.5, 5.5, 4.5])[:, None, None, None]
        mask = ((grid**2).sum(axis=0) < 16).astype(np.uint8)
        nib.save(nib.Nifti1Image(mask, np.diag([1.0, 1.0, 2.0, 1.0])), folder / "ball.nii.gz")
        with contextlib.redirect_stderr(io.StringIO()), contextlib.redirect_stdout(io.StringIO()):
            main(["run", str(folder / "ball.nii.gz"), "-o", str(folder / "out"), "-q"])
            main(["info", str(folder / "ball.nii.gz")])
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def _worker_main(memory: int, mode: str = "pipeline") -> None:
    protocol = os.fdopen(os.dup(1), "w", buffering=1, encoding="utf-8")
    os.dup2(2, 1)
    sys.stdout = sys.stderr
    _warm_up()
    if mode == "cli":
        _warm_up_cli()
    if memory > 0:
        import resource

        try:
            resource.setrlimit(resource.RLIMIT_AS, (memory, memory))
        except (ValueError, OSError) as exc:  # e.g. macOS: run without the limit, say so
            print(f"fuzz worker: no address-space limit ({exc})", file=sys.stderr)
    protocol.write(json.dumps({"ready": os.getpid()}) + "\n")
    for line in sys.stdin:
        protocol.write(json.dumps(_run_one(json.loads(line))) + "\n")


# ----------------------------------------------------------------------------- parent side
class _Worker:
    """One child process and the case it is working on."""

    def __init__(
        self,
        number: int,
        *,
        memory: int,
        budget_gb: float,
        log_dir: Path,
        mode: str = "pipeline",
        command_timeout: float = 20.0,
    ) -> None:
        env = dict(os.environ)
        env.update({name: "1" for name in _THREAD_VARIABLES})
        env["PYTHONHASHSEED"] = "0"
        env["MPLBACKEND"] = "Agg"
        import slicerecon

        root = str(Path(slicerecon.__file__).resolve().parents[1])
        env["PYTHONPATH"] = os.pathsep.join(
            [root, *([env["PYTHONPATH"]] if env.get("PYTHONPATH") else [])]
        )
        self.log = open(log_dir / f"worker-{number}.log", "ab")  # noqa: SIM115
        self.proc = subprocess.Popen(
            [sys.executable, str(Path(__file__).resolve()), "--worker", str(memory), mode],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=self.log,
            env=env,
        )
        self.buffer = b""
        self.budget_gb = budget_gb
        self.mode = mode
        self.command_timeout = command_timeout
        self.ready = False
        self.case: Any = None
        self.since = time.monotonic()

    @property
    def fd(self) -> int:
        assert self.proc.stdout is not None
        return self.proc.stdout.fileno()

    def send(self, mutant: Any) -> None:
        assert self.proc.stdin is not None
        self.case = mutant
        self.since = time.monotonic()
        request = {
            "path": str(mutant.path),
            "method": mutant.method,
            "pixel_spacing": mutant.pixel_spacing,
            "budget_gb": self.budget_gb,
            "mode": self.mode,
            "command_timeout": self.command_timeout,
        }
        self.proc.stdin.write((json.dumps(request) + "\n").encode())
        self.proc.stdin.flush()

    def read_lines(self) -> list[dict[str, Any]] | None:
        """Complete lines received so far, or None at end of file (the worker died)."""
        chunk = os.read(self.fd, 1 << 16)
        if not chunk:
            return None
        self.buffer += chunk
        *lines, self.buffer = self.buffer.split(b"\n")
        return [json.loads(line) for line in lines if line.strip()]

    def stop(self) -> int:
        if self.proc.poll() is None:
            self.proc.kill()
        code = self.proc.wait()
        for stream in (self.proc.stdin, self.proc.stdout):
            if stream is not None:
                try:
                    stream.close()
                except OSError:
                    pass
        self.log.close()
        return code


class _Prefetch:
    """Build the next mutants in a thread while the workers run the current ones."""

    _END = object()

    def __init__(self, mutants: Iterable[Any], *, size: int) -> None:
        self._queue: queue.Queue[Any] = queue.Queue(maxsize=size)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._fill, args=(iter(mutants),), daemon=True)
        self._thread.start()

    def _fill(self, mutants: Iterator[Any]) -> None:
        try:
            for mutant in mutants:
                if not self._put(mutant):
                    return
        except BaseException as exc:  # noqa: BLE001 - handed to the consumer
            self._put(exc)
            return
        self._put(self._END)

    def _put(self, item: Any) -> bool:
        while not self._stop.is_set():
            try:
                self._queue.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def next(self) -> Any:
        """The next mutant, or None when there are no more; re-raises a builder's error."""
        item = self._queue.get()
        if item is self._END:
            return None
        if isinstance(item, BaseException):
            raise item
        return item

    def close(self) -> None:
        self._stop.set()
        self._thread.join()


def _signal_name(code: int) -> str:
    if code < 0:
        try:
            return signal.Signals(-code).name
        except ValueError:
            return f"signal {-code}"
    return f"exit {code}"


def run_mutants(
    mutants: Iterable[Any],
    *,
    workers: int = 2,
    timeout: float = 10.0,
    memory: int = 2 << 30,
    budget_gb: float = 0.5,
    log_dir: str | os.PathLike[str],
    mode: str = "pipeline",
    command_timeout: float = 20.0,
) -> Iterator[Outcome]:
    """Run each mutant through the pipeline in worker processes; yield outcomes as they end.

    Parameters
    ----------
    mutants : iterable of Mutant
        Consumed lazily: the next mutant is built when a worker is free.
    workers : int
        Number of worker processes.
    timeout : float
        Wall-clock limit per case, s; a worker over it is killed (``timeout``).
    memory : int
        Address-space limit of each worker, bytes (``RLIMIT_AS``; 0: none).
    budget_gb : float
        ``memory_budget_gb`` given to ``load_input`` and ``prepare_inputs``. Keep
        it well under ``memory``: an input within the budget that still runs out
        of memory is a finding; one over it must be refused.
    log_dir : path-like
        Where each worker's stderr is written (``worker-N.log``).
    mode : {"pipeline", "cli"}
        ``"pipeline"``: ``load_input → prepare_inputs → reconstruct``. ``"cli"``:
        ``slicerecon run`` (``--max-memory budget_gb``) then ``slicerecon info``,
        each with ``command_timeout`` seconds; ``timeout`` then bounds the pair.
    command_timeout : float
        Limit of one command in ``"cli"`` mode, s (a slower one is a ``timeout``).

    Yields
    ------
    Outcome
        In the order cases finish (not the order given).
    """
    log_path = Path(log_dir)
    log_path.mkdir(parents=True, exist_ok=True)
    prefetch = _Prefetch(mutants, size=2 * max(1, workers))
    exhausted = False
    selector = selectors.DefaultSelector()
    pool: dict[int, _Worker] = {}
    started = 0
    failed_starts = 0

    def start() -> None:
        nonlocal started
        worker = _Worker(
            started,
            memory=memory,
            budget_gb=budget_gb,
            log_dir=log_path,
            mode=mode,
            command_timeout=command_timeout,
        )
        started += 1
        pool[worker.fd] = worker
        selector.register(worker.fd, selectors.EVENT_READ)

    def retire(worker: _Worker) -> int:
        selector.unregister(worker.fd)
        del pool[worker.fd]
        return worker.stop()

    try:
        for _ in range(max(1, workers)):
            start()
        while pool:
            for worker in list(pool.values()):
                if worker.ready and worker.case is None:
                    if not exhausted:
                        mutant = prefetch.next()
                        if mutant is None:
                            exhausted = True
                        else:
                            worker.send(mutant)
                    if exhausted and worker.case is None:
                        retire(worker)
            if not pool:
                break
            now = time.monotonic()
            deadlines = [
                w.since + (timeout if w.ready else _STARTUP_TIMEOUT) for w in pool.values()
            ]
            events = selector.select(max(0.0, min(deadlines) - now))
            for key, _ in events:
                worker = pool[key.fd]
                lines = worker.read_lines()
                if lines is None:  # the worker died
                    case = worker.case
                    code = retire(worker)
                    if case is None:
                        failed_starts += 1
                        if failed_starts > 3:
                            raise RuntimeError(
                                f"fuzz workers keep dying at start (last: {_signal_name(code)});"
                                f" see {log_path}"
                            )
                    else:
                        yield Outcome(
                            case,
                            "crash",
                            _signal_name(code),
                            seconds=time.monotonic() - worker.since,
                        )
                    if not exhausted:
                        start()
                    continue
                for line in lines:
                    if "ready" in line:
                        worker.ready = True
                        worker.since = time.monotonic()
                        failed_starts = 0
                        continue
                    case, worker.case = worker.case, None
                    yield Outcome(case, line.pop("kind"), **line)
            now = time.monotonic()
            for worker in list(pool.values()):
                limit = timeout if worker.ready else _STARTUP_TIMEOUT
                if (worker.ready and worker.case is None) or now - worker.since <= limit:
                    continue
                case = worker.case
                retire(worker)
                if case is None:
                    raise RuntimeError(
                        f"a fuzz worker did not start in {limit:.0f} s; see {log_path}"
                    )
                yield Outcome(
                    case,
                    "timeout",
                    message=f"no answer in {timeout:g} s",
                    seconds=now - worker.since,
                )
                if not exhausted:
                    start()
    finally:
        prefetch.close()
        for worker in list(pool.values()):
            retire(worker)
        selector.close()


# ----------------------------------------------------------------------------- reports
def table(outcomes: Iterable[Outcome], formats: Iterable[str]) -> list[list[str]]:
    """Counts per format × outcome kind, with a total row; the first row is the header."""
    counts: dict[str, Counter] = defaultdict(Counter)
    for outcome in outcomes:
        counts[outcome.mutant.format][outcome.kind] += 1
    rows = [["format", *KINDS, "total"]]
    total: Counter = Counter()
    for fmt in formats:
        row = counts.get(fmt, Counter())
        total.update(row)
        rows.append([fmt, *(str(row[k]) for k in KINDS), str(sum(row.values()))])
    rows.append(["total", *(str(total[k]) for k in KINDS), str(sum(total.values()))])
    return rows


def _text_table(rows: list[list[str]]) -> str:
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    return "\n".join(
        "  ".join(
            c.ljust(w) if i == 0 else c.rjust(w)
            for i, (c, w) in enumerate(zip(r, widths, strict=True))
        )
        for r in rows
    )


class FailureGroup(NamedTuple):
    """Failures of one kind, exception type and slicerecon frame."""

    kind: str
    error: str
    where: str
    outcomes: list[Outcome]

    @property
    def formats(self) -> list[str]:
        return sorted({o.mutant.format for o in self.outcomes})

    @property
    def example(self) -> Outcome:
        """The failing input with the fewest bytes."""
        return min(self.outcomes, key=lambda o: (_size(o.mutant.path), o.mutant.index))


def _size(path: Path) -> int:
    try:
        if path.is_dir():
            return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())
        return path.stat().st_size
    except OSError:
        return 1 << 62


def failure_groups(outcomes: Iterable[Outcome]) -> list[FailureGroup]:
    """Failures grouped by (kind, exception type, innermost slicerecon frame), largest first."""
    groups: dict[tuple[str, str, str], list[Outcome]] = defaultdict(list)
    for outcome in outcomes:
        if outcome.failed:
            groups[(outcome.kind, outcome.error, outcome.where)].append(outcome)
    found = [FailureGroup(*key, items) for key, items in groups.items()]
    return sorted(found, key=lambda g: (-len(g.outcomes), g.kind, g.error, g.where))


def failure_report(outcomes: list[Outcome], formats: Iterable[str]) -> str:
    """A compact text report: the count table, then one paragraph per failure group."""
    lines = [_text_table(table(outcomes, formats)), ""]
    for group in failure_groups(outcomes):
        example = group.example
        lines.append(
            f"{len(group.outcomes):4d} x {group.kind} {group.error or ''} at "
            f"{group.where or example.raised_at or '?'} [{', '.join(group.formats)}]"
        )
        lines.append(f"       {example.message.splitlines()[0][:200] if example.message else ''}")
        lines.append(f"       e.g. {example.mutant.path}  ({'; '.join(example.mutant.mutations)})")
    return "\n".join(lines)


def markdown_summary(outcomes: list[Outcome], formats: Iterable[str], *, title: str) -> str:
    """A markdown snippet: the count table and the distinct failures."""
    rows = table(outcomes, formats)
    legend = (
        "ok: reconstructed; error: refused with a SlicereconError (through the command "
        "line: exit 2 and one `error:` line); escape: any other exception (a traceback); "
        "memory: MemoryError under the address-space limit; timeout: no answer in time "
        "(worker killed), or a command over its limit; crash: the worker died; warning: a "
        "Python warnings line on stderr; unclean: another exit code, or stray stderr lines."
    )
    out = [
        title,
        "",
        legend,
        "",
        "| " + " | ".join(rows[0]) + " |",
        "|" + "|".join(["---"] + ["---:"] * (len(rows[0]) - 1)) + "|",
    ]
    out += ["| " + " | ".join(r) + " |" for r in rows[1:]]
    groups = failure_groups(outcomes)
    if groups:
        out += [
            "",
            "| failures | kind | exception | where (innermost slicerecon frame) | formats |",
            "|---:|---|---|---|---|",
        ]
        for g in groups:
            where = g.where or g.example.raised_at or "?"
            out.append(
                f"| {len(g.outcomes)} | {g.kind} | `{g.error}` | `{where}` | "
                f"{', '.join(g.formats)} |"
            )
    return "\n".join(out) + "\n"


if __name__ == "__main__":
    if len(sys.argv) in (3, 4) and sys.argv[1] == "--worker":
        _worker_main(int(sys.argv[2]), *sys.argv[3:])
    else:
        sys.exit("usage: fuzz_runner.py --worker MEMORY_BYTES [MODE] (started by run_mutants)")
