"""Warnings as a user reads them: one line each, naming the file they concern.

The command line shows them on stderr as they come (``run``); a batch keeps
each case's own (:func:`collected_warnings`), so that they reach the user
whether the case ran in this process or on a Dask worker, and stay in the
case's ``done.json``.
"""

from __future__ import annotations

import logging
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar

from .io.limits import file_being_read

__all__ = ["WARNING_LOGGERS", "collected_warnings", "collecting", "warning_text"]

WARNING_LOGGERS = ("slicerecon", "pipelines")
"""The loggers whose warnings are the project's."""

_COLLECTING: ContextVar[bool] = ContextVar("slicerecon_collecting_warnings", default=False)


def warning_text(record: logging.LogRecord) -> str:
    """A record's message on one line, naming the file being read when it does not itself."""
    text = " ".join(record.getMessage().split())
    if record.levelno == logging.WARNING:
        read = file_being_read()
        if read is not None and read.name not in text:
            text = f"{read}: {text}"
    return text


class _Keep(logging.Handler):
    def __init__(self, lines: list[str]) -> None:
        super().__init__(logging.WARNING)
        self.lines = lines

    def emit(self, record: logging.LogRecord) -> None:
        if record.levelno == logging.WARNING:
            text = warning_text(record)
            if text not in self.lines:
                self.lines.append(text)


@contextmanager
def collected_warnings() -> Iterator[list[str]]:
    """Keep the project's warnings given inside the block, in order, each once.

    While it lasts, :func:`collecting` is true: the command line then leaves
    them to whoever collects them (a batch prints each case's with its name).

    Yields
    ------
    list of str
        Filled as warnings come (:func:`warning_text`).
    """
    lines: list[str] = []
    handler = _Keep(lines)
    loggers = [logging.getLogger(name) for name in WARNING_LOGGERS]
    levels = [logger.level for logger in loggers]
    for logger in loggers:
        logger.addHandler(handler)
        if logger.getEffectiveLevel() > logging.WARNING:
            logger.setLevel(logging.WARNING)
    token = _COLLECTING.set(True)
    try:
        yield lines
    finally:
        _COLLECTING.reset(token)
        for logger, level in zip(loggers, levels, strict=True):
            logger.removeHandler(handler)
            logger.setLevel(level)


def collecting() -> bool:
    """Whether warnings are being collected (:func:`collected_warnings`) in this context."""
    return _COLLECTING.get()
