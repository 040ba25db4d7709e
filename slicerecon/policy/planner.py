"""The learned planner: a trained actor run greedily on a numpy partition episode.

:func:`plan_policy` has the signature of the planners in
:data:`slicerecon.partition.planner.PLANNERS` (registered there as
``"policy"`` through a lazy wrapper, so the geometry never imports torch
unless this planner is used). The occupancy is centred in a cube (the
training grids are cubes, so the silhouettes keep their aspect ratio when
resized), each step's observation is encoded as in training
(:func:`~slicerecon.policy.observation.observe_state`), and the actor's action is
applied with :meth:`PartitionState.step` (snapped to the current corners at
the occupancy's own resolution). Parts and cuts are mapped back to the
occupancy's grid.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Callable
from functools import lru_cache
from pathlib import Path

import numpy as np
import torch
from numpy.typing import ArrayLike, NDArray

from ..errors import EmptyMaskError, InputError, OptionError
from ..partition.cuts import Cut
from ..partition.state import Part, PartitionState
from ..sections import Box, in_plane_axes
from .networks import Actor
from .observation import observe_state
from .weights import load_actor, shipped_weights

__all__ = ["plan_policy", "load_policy"]

logger = logging.getLogger(__name__)

Reconstruct = Callable[[Box], NDArray[np.bool_]]


@lru_cache(maxsize=8)
def _cached(path: str, device: str, stamp: tuple[int, int]) -> tuple[Actor, int]:
    actor, meta = load_actor(path, device=device)
    return actor, int(meta.get("max_steps", 8))


def load_policy(
    weights: str | os.PathLike[str] | None = None, *, device: str = "cpu"
) -> tuple[Actor, int]:
    """The actor of a weights file (default: the shipped ``il_rl``) and its training ``max_steps``.

    Loaded actors are cached per (path, device) while the file is unchanged (its
    modification time and size: weights trained again into one folder are read again).
    """
    path = shipped_weights("il_rl") if weights is None else Path(weights)
    if device not in ("cpu", "cuda"):
        raise OptionError(f"device must be cpu or cuda (got {device!r})")
    if device == "cuda" and not torch.cuda.is_available():
        raise OptionError("device cuda was asked for but CUDA is not available; use cpu")
    resolved = Path(path).resolve()
    stamp = (0, -1)  # a missing file: load_actor says so
    if resolved.is_file():
        stamp = (resolved.stat().st_mtime_ns, resolved.stat().st_size)
    return _cached(str(resolved), device, stamp)


def _shift_cut(cut: Cut | None, offset: tuple[int, int, int]) -> Cut | None:
    if cut is None:
        return None
    a, b = in_plane_axes(cut.view)
    d = (float(offset[a]), float(offset[b]))
    return Cut(cut.view, (cut.p1[0] - d[0], cut.p1[1] - d[1]), (cut.p2[0] - d[0], cut.p2[1] - d[1]))


def plan_policy(
    occupancy: ArrayLike,
    *,
    reconstruct: Reconstruct | None,
    max_parts: int,
    min_remaining: float,
    lam: float,
    weights: str | os.PathLike[str] | None = None,
    device: str = "cpu",
) -> list[Part]:
    """Partition ``occupancy`` with a trained actor (greedy, no exploration noise).

    Parameters
    ----------
    occupancy : ndarray of shape (I, J, K), bool
        The shape to partition (the visual hull at inference).
    reconstruct : callable or None
        ``reconstruct(box) -> bool array of box.shape`` for the reward's second
        term (boxes on the occupancy's grid), as for the other planners.
    max_parts : int
        At most ``max_parts - 1`` cuts, then the leftover part.
    min_remaining : float
        Stop when less than this fraction of the voxels remains.
    lam : float
        Weight of the reconstruction term of the rewards recorded in the parts.
    weights : path-like, optional
        Actor weights (:func:`~slicerecon.policy.weights.save_actor`); default
        the shipped ``il_rl`` actor.
    device : {"cpu", "cuda"}, optional

    Returns
    -------
    list of Part
        Parts whose boxes cover the occupancy.
    """
    occ = np.asarray(occupancy)
    if occ.ndim != 3:
        raise InputError(f"occupancy must be a 3-D array (got shape {occ.shape})")
    occ = occ.astype(bool)
    if not occ.any():
        raise EmptyMaskError("the occupancy is empty: nothing to partition")
    if int(max_parts) < 1:
        raise OptionError(f"max_parts must be >= 1 (got {max_parts})")
    actor, train_steps = load_policy(weights, device=device)
    cfg = actor.config
    side = max(occ.shape)
    off = tuple((side - s) // 2 for s in occ.shape)
    cube = np.zeros((side, side, side), dtype=bool)
    cube[tuple(slice(o, o + s) for o, s in zip(off, occ.shape, strict=True))] = occ

    def to_grid(box: Box) -> Box:
        lo = tuple(v - o for v, o in zip(box.lo, off, strict=True))
        hi = tuple(v - o for v, o in zip(box.hi, off, strict=True))
        return Box(lo, hi)  # type: ignore[arg-type]

    recon = None if reconstruct is None else (lambda box: reconstruct(to_grid(box)))
    state = PartitionState(
        cube,
        reconstruct=recon,
        lam=lam,
        max_steps=int(max_parts) - 1,
        min_remaining=min_remaining,
        max_corners=cfg.max_corners,
    )
    with torch.no_grad():
        while not state.done:
            obs = observe_state(
                state,
                resolution=cfg.resolution,
                max_corners=cfg.max_corners,
                max_steps=train_steps,
                candidates=cfg.candidates,
                device=device,
            )
            action = actor(obs)[0].double().cpu().numpy()
            result = state.step(action)
            logger.debug("policy step %d: %s", state.step_count, result.info["noop"] or "cut")
    parts = state.finish()
    return [Part(to_grid(p.box), p.mask_voxels, p.reward, _shift_cut(p.cut, off)) for p in parts]
