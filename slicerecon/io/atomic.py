"""Atomic file output: write to a temporary file beside the target, then rename.

An interrupted run therefore never leaves a half-written mesh, mask or table
under the final name, and an existing file is only replaced by a complete one.
"""

from __future__ import annotations

import contextlib
import json
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

__all__ = ["atomic_path", "write_json"]


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path to write to; rename it onto ``path`` on success.

    The temporary file lives in the target's directory (so the rename is atomic
    on POSIX) and keeps the target's suffixes (so writers that pick a format by
    extension, such as nibabel or trimesh, still do). On an exception the
    temporary file is removed and ``path`` is left untouched.

    Examples
    --------
    >>> with atomic_path(out / "mesh.stl") as tmp:  # doctest: +SKIP
    ...     mesh.export(tmp)
    """
    target = Path(path)
    target.parent.mkdir(parents=True, exist_ok=True)
    suffix = "".join(target.suffixes)
    fd, tmp_name = tempfile.mkstemp(
        prefix=f".{target.stem}.", suffix=f".tmp{suffix}", dir=target.parent
    )
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        yield tmp
        if tmp.exists():
            # mkstemp creates 0600 files; give the result the permissions a plain
            # open() would (those of the file it replaces, else 0666 minus umask).
            os.chmod(tmp, _mode_for(target))
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            tmp.unlink()
        raise


def _mode_for(target: Path) -> int:
    """File mode for ``target``: its current mode if it exists, else 0o666 & ~umask."""
    try:
        return target.stat().st_mode & 0o777
    except FileNotFoundError:
        umask = os.umask(0)
        os.umask(umask)
        return 0o666 & ~umask


def write_json(path: str | os.PathLike[str], payload: Any) -> Path:
    """Write ``payload`` as indented JSON (a final newline) atomically; return the path."""
    target = Path(path)
    with atomic_path(target) as tmp:
        tmp.write_text(json.dumps(payload, indent=2, sort_keys=False) + "\n")
    return target
