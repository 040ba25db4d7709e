"""What an input may ask for: the reading boundary, sane geometry and the memory budget.

Three rules every reader follows, kept here so that they are written once:

* **The reading boundary** (:func:`reading`). Whatever a third-party parser
  raises while a file is read (pydicom, nibabel, json, zlib, XML, struct, ...)
  becomes one :class:`~slicerecon.errors.FormatError` that names the file. The
  project's own errors pass through unchanged.
* **Sane geometry** (:func:`check_geometry`, :func:`check_coordinates`). Voxel
  sizes, origins and coordinates must be finite and within physical bounds
  (:data:`MIN_SPACING_MM`, :data:`MAX_SPACING_MM`, :data:`MAX_COORDINATE_MM`):
  a header that says a voxel is 1e300 mm wide is corrupt, not a huge image.
* **The memory budget** (:func:`check_grid`). Before any array of a grid is
  allocated, its declared size (planes × rows × columns) is multiplied by what
  the pipeline allocates per voxel (:data:`PIPELINE_BYTES_PER_VOXEL`) and
  compared with the budget (:data:`DEFAULT_MEMORY_BUDGET_GB`, raised with
  ``--max-memory``). The bound is on the *declared* size, never on the file
  size or the compression ratio: real masks compress a thousand-fold.
"""

from __future__ import annotations

import logging
import math
import os
import warnings
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from contextvars import ContextVar
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from ..errors import (
    FormatError,
    GeometryError,
    LabelError,
    MemoryBudgetError,
    OptionError,
    SlicereconError,
)
from ..labels import MAX_LABEL

__all__ = [
    "DEFAULT_MEMORY_BUDGET_GB",
    "MAX_COORDINATE_MM",
    "MAX_LABEL_VALUE",
    "MAX_SPACING_MM",
    "MIN_LABEL_VALUE",
    "MIN_SPACING_MM",
    "PIPELINE_BYTES_PER_VOXEL",
    "check_budget",
    "check_bytes",
    "check_coordinates",
    "check_geometry",
    "check_grid",
    "file_being_read",
    "check_label_range",
    "reading",
    "writing",
]

DEFAULT_MEMORY_BUDGET_GB = 8.0
"""Memory a single case may ask for by default, GiB (``--max-memory`` raises it)."""

PIPELINE_BYTES_PER_VOXEL = 40
"""Bytes the reconstruction pipeline allocates per voxel of its working grid at its
peak (label data, masks, hull, signed-distance fields, carving; measured by
``benchmarks/bench_clinical.py``, rounded up)."""

MIN_SPACING_MM = 1e-4
"""Smallest voxel or plane spacing accepted, mm (0.1 µm)."""
MAX_SPACING_MM = 1e4
"""Largest voxel or plane spacing accepted, mm (10 m)."""
MAX_COORDINATE_MM = 1e6
"""Largest distance of any grid corner or contour vertex from the origin, mm (1 km)."""

_MESSAGE_CHARS = 240

logger = logging.getLogger(__name__)


def check_budget(memory_budget_gb: float) -> float:
    """Validate a memory budget in GiB; return it as a float.

    Raises
    ------
    OptionError
        If the budget is not a positive finite number.
    """
    try:
        value = float(memory_budget_gb)
    except (TypeError, ValueError):
        raise OptionError(
            f"--max-memory must be a number of GiB (got {memory_budget_gb!r})"
        ) from None
    if not (math.isfinite(value) and value > 0):
        raise OptionError(f"--max-memory must be a positive number of GiB (got {value:g})")
    return value


def check_grid(
    shape: Sequence[int],
    *,
    what: str,
    memory_budget_gb: float = DEFAULT_MEMORY_BUDGET_GB,
    bytes_per_voxel: float = PIPELINE_BYTES_PER_VOXEL,
) -> None:
    """Refuse a grid whose arrays would not fit the memory budget, before allocating them.

    Parameters
    ----------
    shape : sequence of int
        The declared grid size in voxels (any number of axes), e.g. ``(I, J, K)``.
    what : str
        What asks for the grid, for the message (e.g. ``"scan.nii.gz"``).
    memory_budget_gb : float
        The budget, GiB.
    bytes_per_voxel : float
        Bytes allocated per voxel of this grid.

    Raises
    ------
    MemoryBudgetError
        If ``prod(shape) * bytes_per_voxel`` exceeds the budget, or a size is
        negative. The message gives the grid, the estimate and the limit.
    """
    budget = check_budget(memory_budget_gb)
    sizes = [int(s) for s in shape]
    if any(s < 0 for s in sizes):
        raise MemoryBudgetError(f"{what} declares a negative grid size {tuple(sizes)}")
    voxels = math.prod(sizes)
    need_gb = voxels * float(bytes_per_voxel) / 2**30
    if need_gb > budget:
        grid = " x ".join(str(s) for s in sizes)
        raise MemoryBudgetError(
            f"{what}: its grid of {grid} voxels needs about {_gib(need_gb)} GiB, over the "
            f"memory budget of {budget:g} GiB; pass --max-memory {math.ceil(need_gb)} "
            "if this machine has that much memory"
        )


def _gib(value: float) -> str:
    """A size in GiB for a message: one decimal from 10 GiB, else three significant digits."""
    return f"{value:,.1f}" if value >= 10 else f"{value:.3g}"


def check_bytes(n_bytes: int, *, what: str, memory_budget_gb: float) -> None:
    """Refuse a declared byte count (e.g. decompressed data to skip) over the memory budget.

    Parameters
    ----------
    n_bytes : int
        The bytes a header asks to be read or produced.
    what : str
        What asks for them, for the message.
    memory_budget_gb : float
        The budget, GiB.

    Raises
    ------
    MemoryBudgetError
        If ``n_bytes`` exceeds the budget; the message gives both.
    """
    budget = check_budget(memory_budget_gb)
    need_gb = int(n_bytes) / 2**30
    if need_gb > budget:
        raise MemoryBudgetError(
            f"{what} asks for {int(n_bytes):,} bytes (about {_gib(need_gb)} GiB), over the "
            f"memory budget of {budget:g} GiB; pass --max-memory {math.ceil(need_gb)} if "
            "this machine has that much memory"
        )


MIN_LABEL_VALUE = -(2**31)
"""Smallest label value accepted (32-bit signed)."""
MAX_LABEL_VALUE = MAX_LABEL
"""Largest label value accepted (32-bit unsigned): a larger one is not a label of a map."""


def check_label_range(values: ArrayLike, *, what: str) -> None:
    """Refuse a label map whose values do not fit 32-bit integers.

    Parameters
    ----------
    values : array_like
        The voxel values (after any scaling the file declares).
    what : str
        The source, for the message.

    Raises
    ------
    LabelError
        A value below :data:`MIN_LABEL_VALUE` or above :data:`MAX_LABEL_VALUE`
        (a scale factor of 3e38 makes every voxel such a value).
    """
    data = np.asarray(values)
    if data.size == 0 or data.dtype.kind not in "iuf":
        return
    lo, hi = float(data.min()), float(data.max())
    if lo < MIN_LABEL_VALUE or hi > MAX_LABEL_VALUE:
        raise LabelError(
            f"{what} is not a label map: its values reach {lo:.4g} to {hi:.4g}, beyond the "
            "32-bit integers label values are (check its scale factor, or pass a segmentation)"
        )


def check_geometry(affine: ArrayLike, shape: Sequence[int], *, what: str) -> None:
    """Refuse non-finite or absurd voxel geometry: spacing, origin, grid extent.

    Parameters
    ----------
    affine : array_like of shape (4, 4)
        Voxel index → world mm.
    shape : sequence of 3 int
        Grid size in voxels.
    what : str
        The source, for the message.

    Raises
    ------
    GeometryError
        Non-finite entries; a voxel spacing outside
        [:data:`MIN_SPACING_MM`, :data:`MAX_SPACING_MM`]; a grid corner farther
        than :data:`MAX_COORDINATE_MM` from the origin.
    """
    aff = np.asarray(affine, dtype=np.float64)
    if aff.shape != (4, 4) or not np.all(np.isfinite(aff)):
        raise GeometryError(f"{what}: the voxel-to-world geometry holds NaN or infinite values")
    if np.abs(aff).max() > MAX_COORDINATE_MM:
        raise GeometryError(
            f"{what}: the voxel-to-world geometry holds {np.abs(aff).max():.3g}, beyond the "
            f"{MAX_COORDINATE_MM:g} mm (1 km) any scanner spans; the header is corrupt"
        )
    spacing = np.linalg.norm(aff[:3, :3], axis=0)
    if (
        not np.all(np.isfinite(spacing))
        or np.any(spacing < MIN_SPACING_MM)
        or np.any(spacing > MAX_SPACING_MM)
    ):
        shown = ", ".join(f"{s:.4g}" for s in spacing)
        raise GeometryError(
            f"{what}: voxel spacing ({shown}) mm is outside "
            f"[{MIN_SPACING_MM:g}, {MAX_SPACING_MM:g}] mm; the header is corrupt"
        )
    sizes = np.asarray([max(int(s) - 1, 0) for s in shape], dtype=np.float64)
    corners = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)]) * sizes
    world = corners @ aff[:3, :3].T + aff[:3, 3]
    check_coordinates(world, what=what)


def check_coordinates(points: ArrayLike, *, what: str) -> None:
    """Refuse world coordinates that are not finite or lie beyond :data:`MAX_COORDINATE_MM`.

    Parameters
    ----------
    points : array_like of shape (..., 3)
        World mm.
    what : str
        The source, for the message.

    Raises
    ------
    GeometryError
    """
    pts = np.asarray(points, dtype=np.float64)
    if pts.size == 0:
        return
    if not np.all(np.isfinite(pts)):
        raise GeometryError(f"{what}: coordinates hold NaN or infinite values")
    far = float(np.abs(pts).max())
    if far > MAX_COORDINATE_MM:
        raise GeometryError(
            f"{what}: coordinates reach {far:.3g} mm, beyond the {MAX_COORDINATE_MM:g} mm "
            "(1 km) any scanner or drawing spans; the file is corrupt or not in mm"
        )


def _short(exc: BaseException) -> str:
    try:
        text = " ".join(str(exc).split())
    except Exception:  # noqa: BLE001 - a message that cannot even be printed
        text = ""
    if len(text) > _MESSAGE_CHARS:
        text = text[: _MESSAGE_CHARS - 3] + "..."
    return f"{type(exc).__name__}: {text}" if text else type(exc).__name__


_CHATTY_LOGGERS = ("nibabel.global",)
"""Third-party loggers that print to stderr by themselves (nibabel adds its own handler)."""


class _Collect(logging.Handler):
    """Keeps the WARNING (and worse) records of other packages' loggers while a file is read."""

    def __init__(self) -> None:
        super().__init__(logging.WARNING)
        self.records: list[logging.LogRecord] = []

    def emit(self, record: logging.LogRecord) -> None:
        if not record.name.startswith("slicerecon"):
            self.records.append(record)


@contextmanager
def _collecting_logs() -> Iterator[_Collect]:
    """Hold back what other packages log (as :class:`_Collect` records) instead of printing it.

    A handler on the root logger takes their records (so Python's last-resort
    handler does not print them on stderr), and loggers with their own stream
    handler (:data:`_CHATTY_LOGGERS`) lose it for the while.
    """
    collect = _Collect()
    root = logging.getLogger()
    saved = {name: logging.getLogger(name).handlers[:] for name in _CHATTY_LOGGERS}
    for name in _CHATTY_LOGGERS:
        logging.getLogger(name).handlers = []
    root.addHandler(collect)
    try:
        yield collect
    finally:
        root.removeHandler(collect)
        for name, handlers in saved.items():
            logging.getLogger(name).handlers = handlers


_NOISE = (DeprecationWarning, PendingDeprecationWarning, FutureWarning, ResourceWarning)
"""Warning categories that speak to developers, not to whoever gave the file."""
_MAX_WARNINGS = 3
"""Distinct warnings logged per file read; more are counted."""


def _log_warnings(
    path: Path,
    caught: list[warnings.WarningMessage],
    *,
    failed: bool,
    records: Sequence[logging.LogRecord] = (),
) -> None:
    """Log what parsers warned about while reading ``path``, as log records, not stderr lines.

    After a failed read the error says what is wrong: every warning is a debug
    record. After a successful one, a parser's remarks on the file (pydicom's
    invalid values, nibabel's header fixes, ...) are warnings naming the file;
    deprecations and numpy's floating-point remarks are debug records. What
    other packages logged (``records``) counts as their warnings.
    """
    seen: set[tuple[type[Warning], str]] = set()
    shown = 0
    messages = [(item.category, item.message) for item in caught] + [
        (UserWarning, record.getMessage()) for record in records
    ]
    for category, message in messages:
        text = " ".join(str(message).split())
        if len(text) > _MESSAGE_CHARS:
            text = text[: _MESSAGE_CHARS - 3] + "..."
        key = (category, text)
        if key in seen:
            continue
        seen.add(key)
        noise = failed or issubclass(category, (*_NOISE, RuntimeWarning))
        if noise or shown >= _MAX_WARNINGS:
            logger.debug("%s: %s: %s", path, category.__name__, text)
            continue
        shown += 1
        logger.warning("%s: %s", path, text)
    hidden = (
        sum(
            1
            for category, _ in seen
            if not (failed or issubclass(category, (*_NOISE, RuntimeWarning)))
        )
        - shown
    )
    if hidden > 0:
        logger.warning("%s: %d more warnings while reading it (see --debug)", path, hidden)


@contextmanager
def reading(path: str | os.PathLike[str]) -> Iterator[None]:
    """Turn any failure of a third-party parser while reading ``path`` into a FormatError.

    The project's own errors (:class:`~slicerecon.errors.SlicereconError`)
    pass through unchanged; ``KeyboardInterrupt`` and ``SystemExit`` too. A
    ``MemoryError`` becomes a :class:`~slicerecon.errors.MemoryBudgetError`
    (the declared sizes passed :func:`check_grid`, yet the machine ran out).

    Python ``warnings`` the parsers emit meanwhile (pydicom, nibabel, numpy,
    pynrrd), and what other packages log (nibabel prints its header fixes on
    stderr itself), never reach stderr as ``file:line: UserWarning`` or bare
    lines: they become log records of this module naming the file
    (:func:`_log_warnings`): debug records when the read fails (the error line
    says what is wrong) or for deprecations; warnings otherwise, at most three
    per file. Like :func:`warnings.catch_warnings`, which it uses, it is meant
    for the main thread.

    Raises
    ------
    FormatError
        Naming the file, the parser's exception type and its message.
    """
    p = Path(path)
    token = _READING.set(p)
    try:
        with _boundary(p), _quiet(p):
            yield
    finally:
        _READING.reset(token)


_READING: ContextVar[Path | None] = ContextVar("slicerecon_reading", default=None)


def file_being_read() -> Path | None:
    """The file a :func:`reading` block is reading now (the innermost), or None.

    The command line names it in a warning that does not name it itself.
    """
    return _READING.get()


@contextmanager
def _quiet(p: Path) -> Iterator[None]:
    """Python warnings and other packages' log records while reading ``p``, as our records."""
    caught: list[warnings.WarningMessage] = []
    with _collecting_logs() as logs:
        try:
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                yield
        except BaseException:
            _log_warnings(p, caught, failed=True, records=logs.records)
            raise
    _log_warnings(p, caught, failed=False, records=logs.records)


@contextmanager
def writing(path: str | os.PathLike[str]) -> Iterator[None]:
    """The boundary of a writer that copies values of its inputs (a SEG, an RTSTRUCT).

    As :func:`reading`, for the values a writer reads from its inputs' headers
    (pydicom parses them lazily) and the libraries it calls (highdicom): their
    warnings become log records, and their exceptions one
    :class:`~slicerecon.errors.FormatError` naming the output, so the caller
    can skip that output with a warning.
    """
    p = Path(path)
    with _boundary(p, verb="write"), _quiet(p):
        yield


@contextmanager
def _boundary(p: Path, *, verb: str = "read") -> Iterator[None]:
    """The exceptions of :func:`reading`: project errors pass, every other becomes one."""
    try:
        yield
    except SlicereconError:
        raise
    except MemoryError as exc:
        raise MemoryBudgetError(
            f"{'writing' if verb == 'write' else 'reading'} {p} ran out of memory: this "
            "machine has less free memory than "
            "the budget (--max-memory) allows; free memory or use a larger machine"
        ) from exc
    except RecursionError as exc:
        raise FormatError(
            f"cannot read {p}: it is nested too deeply to parse ({_short(exc)})"
        ) from exc
    except Exception as exc:  # noqa: BLE001 - the boundary: every parser failure
        if verb == "write":
            raise FormatError(
                f"cannot write {p}: a value of its input cannot be written ({_short(exc)})"
            ) from exc
        what = "a file in it is corrupt" if p.is_dir() else "the file is corrupt"
        raise FormatError(
            f"cannot read {p}: {what} or not what its name says ({_short(exc)})"
        ) from exc
