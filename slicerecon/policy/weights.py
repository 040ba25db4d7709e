"""Actor weights on disk: safetensors files with the network sizes in their metadata.

A weights file holds the actor's ``state_dict`` (float32 tensors) and, as
string metadata, the :class:`~slicerecon.policy.networks.NetConfig` sizes and
the environment settings the actor was trained with (``grid``,
``max_steps``), so that :func:`load_actor` rebuilds the network without
any other file. Shipped weights live in ``slicerecon/policy/weights/``
(:func:`shipped_weights`).
"""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path
from typing import Any

import torch

from ..errors import DependencyError, FormatError, InputError, OptionError
from ..io.atomic import atomic_path
from .networks import Actor, NetConfig

__all__ = ["SHIPPED", "shipped_weights", "save_actor", "load_actor"]

logger = logging.getLogger(__name__)

SHIPPED = ("il_rl", "il", "ddpg")
"""Names of the shipped actors (the three training configs)."""

_WEIGHTS_DIR = Path(__file__).with_name("weights")


def _safetensors() -> Any:
    try:
        import safetensors.torch as st
    except ImportError as exc:  # pragma: no cover - declared dependency
        raise DependencyError(
            "reading policy weights needs the 'safetensors' package: pip install safetensors"
        ) from exc
    return st


def shipped_weights(name: str = "il_rl") -> Path:
    """Path of a shipped actor, ``slicerecon/policy/weights/<name>.safetensors``."""
    if name not in SHIPPED:
        raise OptionError(f"no shipped weights {name!r}; choose one of {', '.join(SHIPPED)}")
    path = _WEIGHTS_DIR / f"{name}.safetensors"
    if not path.is_file():
        raise InputError(
            f"the shipped weights {path.name} are missing from the installation; "
            "reinstall slicerecon or pass a weights file"
        )
    return path


def save_actor(
    actor: Actor, path: str | os.PathLike[str], *, extra: dict[str, Any] | None = None
) -> Path:
    """Write an actor's weights (atomically) with its sizes as metadata.

    Parameters
    ----------
    actor : Actor
    path : path-like
        Target ``.safetensors`` file.
    extra : dict, optional
        More JSON-serialisable metadata (e.g. ``grid``, ``max_steps``, ``config``).

    Returns
    -------
    Path
    """

    st = _safetensors()
    meta = {"net": json.dumps(actor.config.to_dict()), "format": "slicerecon-actor-1"}
    for key, value in (extra or {}).items():
        meta[str(key)] = json.dumps(value)
    tensors = {k: v.detach().cpu().contiguous() for k, v in actor.state_dict().items()}
    target = Path(path)
    with atomic_path(target) as tmp:
        st.save_file(tensors, str(tmp), metadata=meta)
    return target


def load_actor(
    path: str | os.PathLike[str], *, device: str | torch.device = "cpu"
) -> tuple[Actor, dict[str, Any]]:
    """Rebuild an actor from :func:`save_actor`'s file.

    Returns
    -------
    actor : Actor
        In eval mode on ``device``.
    metadata : dict
        The decoded metadata (``net`` and any extras).

    Raises
    ------
    InputError
        If the file is missing.
    FormatError
        If it is not a slicerecon actor file.
    """
    st = _safetensors()
    p = Path(path)
    if not p.is_file():
        raise InputError(f"weights file not found: {p}")
    try:
        from safetensors import safe_open

        with safe_open(str(p), framework="pt") as f:
            raw = f.metadata() or {}
        tensors = st.load_file(str(p), device="cpu")
    except Exception as exc:  # safetensors raises its own error types
        raise FormatError(f"{p} is not a readable safetensors file ({exc})") from exc
    if raw.get("format") != "slicerecon-actor-1" or "net" not in raw:
        raise FormatError(f"{p} is not a slicerecon actor weights file (no 'net' metadata)")
    meta = {k: (v if k == "format" else json.loads(v)) for k, v in raw.items()}
    try:
        actor = Actor(NetConfig(**meta["net"]))
    except (TypeError, ValueError, OptionError) as exc:
        raise FormatError(
            f"{p}: its network sizes {meta['net']} are not this version's ({exc})"
        ) from exc
    try:
        actor.load_state_dict(tensors)
    except RuntimeError as exc:
        raise FormatError(f"{p}: the weights do not fit the stored network sizes ({exc})") from exc
    actor.to(device).eval()
    logger.debug("loaded actor %s (%s)", p, meta["net"])
    return actor, meta
