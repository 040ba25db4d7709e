"""The ``slicerecon`` Typer application, its root options and the options commands share.

One definition and one help text per shared option (``run``, ``batch`` and
``evaluate-dataset`` take the same ones); nothing heavy is imported here, so
``slicerecon --help`` is fast.
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path
from typing import Annotated

import typer

from .. import __version__

app = typer.Typer(
    name="slicerecon",
    help="Reconstruct watertight 3D surfaces from parallel planar cross-sections.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode="rich",
)

EXIT_INPUT = 2
DEFAULT_MAX_MEMORY_GB = 8.0
"""Default of ``--max-memory``; equal to ``slicerecon.io.limits.DEFAULT_MEMORY_BUDGET_GB``
(a test checks it), written here so that ``--help`` imports nothing heavy."""


def _version(value: bool) -> None:
    if value:
        typer.echo(f"slicerecon {__version__}")
        raise typer.Exit()


LOGGERS = ("slicerecon", "pipelines")
"""The loggers whose records the command line shows on stderr."""


class _OneLine(logging.Formatter):
    """``warning: <message>`` on one line (a record's own line breaks become spaces); a
    warning given while a file is read names that file when it does not itself."""

    def format(self, record: logging.LogRecord) -> str:
        from ..messages import warning_text

        text = warning_text(record)
        if record.exc_info and record.levelno >= logging.ERROR:
            text += f" ({record.exc_info[1]})"
        return f"{record.levelname.lower()}: {text}"


class _CliHandler(logging.StreamHandler):  # type: ignore[type-arg]
    """The one handler the command line puts on :data:`LOGGERS` (replaced on each call).

    A message already shown in this invocation is not shown again (a file read
    twice warns once).
    """

    def __init__(self, stream: object) -> None:
        super().__init__(stream)  # type: ignore[arg-type]
        self._seen: set[tuple[int, str]] = set()

    def filter(self, record: logging.LogRecord) -> bool:
        from ..messages import collecting

        if record.levelno == logging.WARNING and collecting():
            return False  # a batch case's: printed with its case name when it finishes
        key = (record.levelno, record.getMessage())
        if key in self._seen:
            return False
        self._seen.add(key)
        return super().filter(record)


def show_messages(level: int) -> None:
    """Show the library's log records of ``level`` and above on stderr, one line each.

    Warnings are shown by default, ``-v`` adds progress (info), ``--debug``
    everything, ``run -q`` errors only. Called on every invocation: the
    handler of an earlier call (in the same process) is replaced, and it
    writes to the ``sys.stderr`` of this call.
    """
    for name in LOGGERS:
        logger = logging.getLogger(name)
        for old in [h for h in logger.handlers if isinstance(h, _CliHandler)]:
            logger.removeHandler(old)
        handler = _CliHandler(sys.stderr)
        handler.setFormatter(_OneLine())
        handler.setLevel(level)
        logger.addHandler(handler)
        if logger.getEffectiveLevel() > level:
            logger.setLevel(level)


@app.callback()
def _root(
    verbose: Annotated[
        bool,
        typer.Option(
            "--verbose",
            "-v",
            help="Also show what each step reads and finds (info messages); a run of "
            "over 2 s shows its stage anyway.",
        ),
    ] = False,
    debug: Annotated[
        bool, typer.Option("--debug", help="Show every message, and tracebacks on errors.")
    ] = False,
    version: Annotated[
        bool, typer.Option("--version", callback=_version, is_eager=True, help="Show version.")
    ] = False,
) -> None:
    """Reconstruct watertight 3D surfaces from parallel planar cross-sections.

    Warnings are printed on stderr, one line each (``run -q`` silences them).
    """
    show_messages(logging.DEBUG if debug else logging.INFO if verbose else logging.WARNING)


MaxMemoryOpt = Annotated[
    float,
    typer.Option(
        "--max-memory",
        help="Memory budget per case, GiB: larger inputs are refused before reading.",
    ),
]


_METHOD_HELP = (
    "Surface method: sdf (default: signed-distance interpolation across planes), loft "
    "(the paper's lofting) or hybrid (loft where contours correspond simply, sdf "
    "elsewhere), per part of the plan; or a whole-shape baseline "
    "that skips the planner and the carve: poisson, sdf-hull or itk-mci "
    '(needs pip install "slicerecon\\[itk]"). See docs/baselines.md.'
)

# Options shared by run, batch and evaluate-dataset (one definition, one help text).
SlicesOpt = Annotated[
    int | None, typer.Option("--slices", help="Keep N evenly spaced planes (default 16).")
]
EveryOpt = Annotated[int | None, typer.Option("--every", help="Keep every K-th plane.")]
AxisOpt = Annotated[
    str,
    typer.Option(
        help="Grid axis a dense mask is cut across: x, y or z, the array's 1st, 2nd or 3rd "
        "index (the read line names the world axis the planes are normal to)."
    ),
]
PlannerOpt = Annotated[
    str,
    typer.Option(
        help="auto (heuristic for a dense mask, none for sparse input), heuristic, lookahead "
        "(the heuristic checked on held-out planes), none or policy (learned planner)."
    ),
]
MethodOpt = Annotated[str, typer.Option(help=_METHOD_HELP)]
InterpolationOpt = Annotated[
    str,
    typer.Option(help="Across planes: pchip (default: monotone cubic) or linear (classic)."),
]
AnnotationOpt = Annotated[
    str,
    typer.Option(
        help="How a label map was annotated: auto (detected: dense, or some planes of any "
        "axes), dense, or the axes, e.g. z or xz."
    ),
]
ProjectionsOpt = Annotated[
    str,
    typer.Option(
        help="gt, sections, auto (gt for dense inputs), or FILE[,FILE...]: 1-3 NIfTI silhouettes."
    ),
]
FormatOpt = Annotated[str, typer.Option("--format", help="stl, ply or obj.")]
SmoothOpt = Annotated[bool, typer.Option("--smooth", help="Taubin-smooth the mesh.")]
CarveOpt = Annotated[
    bool, typer.Option("--carve/--no-carve", help="Cut the surface to the projections' hull.")
]
CoverOpt = Annotated[
    bool,
    typer.Option(
        "--cover/--no-cover",
        help="With --carve (sdf): also fill the silhouettes whose rays lie in the section planes.",
    ),
]
DriftOpt = Annotated[
    bool,
    typer.Option(
        "--join-drift/--no-join-drift",
        help="(sdf) Join regions that overlap nothing on the next plane along their shift.",
    ),
]
LabelOpt = Annotated[
    str | None,
    typer.Option(
        help="Structures to reconstruct (default: all): label values, SEG segments or "
        "an RTSTRUCT ROI, by number or name, comma-separated."
    ),
]
UnionOpt = Annotated[
    bool, typer.Option("--union", help="Every structure together as one (every non-zero voxel).")
]
RoiOpt = Annotated[str | None, typer.Option(help="Another name for --label (RTSTRUCT ROIs).")]
IrregularOpt = Annotated[
    bool, typer.Option("--allow-irregular", help="Accept uneven DICOM slice spacing.")
]
PixelSpacingOpt = Annotated[
    float | None,
    typer.Option(
        "--pixel-spacing",
        help="In-plane pixel size, mm, for contours without a grid (contour files, an RTSTRUCT "
        "without its series; default: extent / 256).",
    ),
]
WeightsOpt = Annotated[
    Path | None, typer.Option(help="Actor weights for --planner policy (default: shipped).")
]
