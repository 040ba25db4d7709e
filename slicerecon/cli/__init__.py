"""The ``slicerecon`` command line.

A thin Typer layer: each command fills a config, calls the library and prints.
Heavy modules are imported inside the commands so ``slicerecon --help`` is fast.
Errors the user can fix are printed as one line on stderr with a non-zero exit
code; ``--debug`` shows the full traceback before it (same exit code). The commands live in
:mod:`~slicerecon.cli.cases` (info, run, batch, evaluate, report,
evaluate-dataset) and :mod:`~slicerecon.cli.training` (train, dataset); the
application and the shared options in :mod:`~slicerecon.cli.app`.
"""

from __future__ import annotations

import sys
import traceback

import typer

from ..console import keep_freed_memory
from ..errors import SlicereconError
from . import cases, training
from .app import DEFAULT_MAX_MEMORY_GB, EXIT_INPUT, app

__all__ = ["DEFAULT_MAX_MEMORY_GB", "EXIT_INPUT", "app", "cases", "main", "training"]


def _usage_line(exc: Exception) -> str:
    """One line for a usage error raised by typer's click: the message and where help is."""
    message = exc.format_message() if hasattr(exc, "format_message") else str(exc)
    message = " ".join(str(message).split()) or "a command is required"
    ctx = getattr(exc, "ctx", None)
    if ctx is not None:
        return f"error: {message} (see '{ctx.command_path} --help')"
    return f"error: {message}"


def _click_exceptions() -> tuple[type[BaseException], ...]:
    """The usage-error base classes of the click that typer runs on.

    Recent typer releases bundle their own copy of click, whose exceptions do
    not derive from the installed ``click``'s; older ones use ``click`` itself.
    Both are caught, so every usage error reaches :func:`main`'s one-line rule.
    """
    import typer.exceptions

    bases: list[type[BaseException]] = [typer.exceptions.TyperException]
    try:
        import click
    except ImportError:  # pragma: no cover - typer always brings a click
        pass
    else:
        bases.append(click.ClickException)
    return tuple(bases)


def _exit_code(exc: BaseException) -> int | None:
    """The exit code of a click/typer ``Exit`` (``--help``, ``--version``), else None."""
    code = getattr(exc, "exit_code", None)
    name = type(exc).__name__
    return int(code) if name == "Exit" and code is not None else None


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``slicerecon`` console script.

    Exit codes: 0 success; 2 bad input or usage error (one ``error:`` line on
    stderr); 1 a batch finished with failed cases; 130 interrupted (Ctrl-C).
    Called without ``argv`` (the console script itself), it first tunes the
    process's allocator (:func:`slicerecon.console.keep_freed_memory`).
    """
    if argv is None:
        keep_freed_memory()
    usage_errors = _click_exceptions()
    args = sys.argv[1:] if argv is None else list(argv)
    debug = (
        "--debug"
        in args[: next((i for i, a in enumerate(args) if not a.startswith("-")), len(args))]
    )
    try:
        result = app(args=argv, prog_name="slicerecon", standalone_mode=False)
    except SlicereconError as exc:
        if debug:  # the traceback, then the exit code of bad input all the same
            traceback.print_exc()
        typer.echo(f"error: {' '.join(str(exc).split())}", err=True)
        return EXIT_INPUT
    except KeyboardInterrupt:
        typer.echo("interrupted", err=True)
        return 130
    except (*usage_errors, RuntimeError) as exc:
        code = _exit_code(exc)
        if code is not None:
            return code
        if type(exc).__name__ == "Abort":
            typer.echo("interrupted", err=True)
            return 130
        if not isinstance(exc, usage_errors):
            raise
        if debug:
            traceback.print_exc()
        typer.echo(_usage_line(exc), err=True)
        return EXIT_INPUT
    if result == 130:  # typer turns a KeyboardInterrupt inside a command into Exit(130)
        typer.echo("interrupted", err=True)
        return 130
    return int(result) if isinstance(result, int) else 0
