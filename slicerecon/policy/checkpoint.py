"""Training checkpoints on disk, read without running code from the file.

A checkpoint (``OUT/checkpoint.pt``, written by :func:`slicerecon.policy.train.train`)
is a :func:`torch.save` file of plain data only: tensors, dicts, lists,
strings, numbers and booleans (network and optimizer states, both replay
buffers, counters, the log rows and the RNG states; numpy's generator state is
a dict of Python ints). :func:`load_checkpoint` reads it with
``torch.load(..., weights_only=True)``, whose unpickler rebuilds only those
types and refuses every other Python object *before* creating it. A file that
holds anything else (a checkpoint pickled with arbitrary objects, a file that
was tampered with, a truncated or foreign file) is refused with a
:class:`~slicerecon.errors.FormatError` that names it; no code from it runs.
"""

from __future__ import annotations

import logging
import os
import re
from pathlib import Path
from typing import Any

import torch

from ..errors import FormatError, InputError
from ..io.atomic import atomic_path

__all__ = ["CHECKPOINT_KEYS", "load_checkpoint", "save_checkpoint"]

logger = logging.getLogger(__name__)

CHECKPOINT_KEYS: dict[str, type | tuple[type, ...]] = {
    "config": dict,
    "agent": dict,
    "demos": dict,
    "replay": dict,
    "rows": list,
    "env_steps": int,
    "heuristic_eval_iou": (int, float),
    "elapsed_s": (int, float),
    "rng": dict,
}
"""Top-level entries of a checkpoint and their types."""
RNG_KEYS: dict[str, type] = {
    "torch": torch.Tensor,
    "numpy": dict,
    "env": dict,
    "sample": torch.Tensor,
}
"""Entries of ``checkpoint["rng"]``: torch and sampler generator states (byte
tensors), numpy and environment bit-generator states (dicts)."""

_WHAT_TO_DO = (
    "it cannot be resumed; start a new run with another --out (or delete the file "
    "to restart in this one)"
)


def save_checkpoint(state: dict[str, Any], path: str | os.PathLike[str]) -> Path:
    """Write ``state`` to ``path`` atomically (complete, or not at all).

    Parameters
    ----------
    state : dict
        The entries of :data:`CHECKPOINT_KEYS`, made of plain data only
        (what :func:`load_checkpoint` accepts).
    path : path-like
        Target file (``OUT/checkpoint.pt``).

    Returns
    -------
    Path
    """
    target = Path(path)
    with atomic_path(target) as tmp:
        torch.save(state, tmp)
    return target


def _reason(exc: BaseException) -> str:
    """A short reason from torch's (long, multi-line) refusal message."""
    text = " ".join(str(exc).split())
    found = re.search(r"GLOBAL ([\w.]+)", text)
    if found:
        return f"it holds the Python object {found.group(1)}, which is not plain data"
    if isinstance(exc, EOFError) or not text:
        return "the file is empty or truncated"
    found = re.search(r"WeightsUnpickler error: (.+?)(?: Check the documentation|$)", text)
    if found:
        return f"not a torch checkpoint: {found.group(1).strip()}"
    return text[:200] + ("..." if len(text) > 200 else "")


def load_checkpoint(path: str | os.PathLike[str]) -> dict[str, Any]:
    """Read a training checkpoint safely (tensors and plain data only).

    Parameters
    ----------
    path : path-like
        The checkpoint file (``OUT/checkpoint.pt``).

    Returns
    -------
    dict
        The entries of :data:`CHECKPOINT_KEYS`, tensors on the CPU.

    Raises
    ------
    InputError
        If the file cannot be read.
    FormatError
        If the file holds other Python objects than tensors and plain data
        (an old pickled checkpoint, a tampered file: refused before any object
        of it is built, so no code from it runs), is not a torch file, or lacks
        an entry of a slicerecon checkpoint.
    """
    p = Path(path)
    try:
        state = torch.load(p, map_location="cpu", weights_only=True)
    except FileNotFoundError as exc:
        raise InputError(f"checkpoint not found: {p}") from exc
    except IsADirectoryError as exc:
        raise InputError(f"{p} is a directory, not a checkpoint file") from exc
    except PermissionError as exc:
        raise InputError(f"cannot read the checkpoint {p}: permission denied") from exc
    except Exception as exc:  # noqa: BLE001 - torch raises UnpicklingError, RuntimeError, EOFError, ...
        logger.debug("refusing checkpoint %s", p, exc_info=True)
        raise FormatError(
            f"{p} cannot be loaded safely ({_reason(exc)}): a checkpoint is read as "
            f"tensors and plain data only, never as Python objects or code; {_WHAT_TO_DO}"
        ) from exc
    if not isinstance(state, dict):
        raise FormatError(
            f"{p} is not a slicerecon training checkpoint (it holds a "
            f"{type(state).__name__}, not a dict); {_WHAT_TO_DO}"
        )
    problems = [
        name
        for name, kind in CHECKPOINT_KEYS.items()
        if not isinstance(state.get(name), kind) or isinstance(state.get(name), bool)
    ]
    rng = state.get("rng")
    if isinstance(rng, dict):
        problems += [
            f"rng.{name}" for name, kind in RNG_KEYS.items() if not isinstance(rng.get(name), kind)
        ]
    if problems:
        raise FormatError(
            f"{p} is not a complete slicerecon training checkpoint (missing or wrong: "
            f"{', '.join(problems)}); {_WHAT_TO_DO}"
        )
    return state
