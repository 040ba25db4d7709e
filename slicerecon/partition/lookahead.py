"""One-step lookahead on the heuristic expert: a better teacher where the ground truth is known.

In training the shape ``O`` is known, so each of the expert's candidate cuts
can be scored by what it leads to: take the cut, then let the heuristic
expert (:func:`~slicerecon.partition.heuristic.expert_cut`) finish the
episode, and read the IoU of the whole reconstruction with ``O`` (the
``gain`` reward's potential, :meth:`PartitionState.potential`). Stopping is
scored by the potential of the state as it is (the remaining region
reconstructed as one last part). :func:`lookahead_cut` returns the best of
these, and the expert's own cut unless another choice is better by more than
``margin``.

This is the rollout algorithm of approximate dynamic programming with the
heuristic as base policy (Bertsekas, Tsitsiklis and Wu, "Rollout Algorithms
for Combinatorial Optimization", Journal of Heuristics 3, 1997): on the
states it is applied to, its episode is never worse than the base policy's.
It needs ``O`` and is only a teacher: the learned planner is trained to
imitate it from the observation alone (``TrainConfig.demo_lookahead``),
since at inference ``O`` is what is being reconstructed.
"""

from __future__ import annotations

import logging
from typing import NamedTuple

from ..errors import OptionError
from .cuts import Cut
from .heuristic import expert_cuts, run_expert
from .state import PartitionState

__all__ = ["Lookahead", "expert_value", "lookahead_cut"]

logger = logging.getLogger(__name__)


class Lookahead(NamedTuple):
    """What :func:`lookahead_cut` chose.

    Attributes
    ----------
    cut : Cut or None
        The chosen cut; None to stop (the remaining region is one last part).
    value : float
        IoU with ``O`` of the reconstruction the choice leads to.
    expert_value : float
        The same for the heuristic expert's own choice at this state.
    candidates : int
        Choices scored (cuts and the stop).
    """

    cut: Cut | None
    value: float
    expert_value: float
    candidates: int


def expert_value(state: PartitionState) -> float:
    """IoU with ``O`` after the heuristic expert finishes ``state`` (``state`` is left as it is).

    The expert cuts until it has no cut left or the episode ends; the
    remaining region is then one last part (the potential).

    Raises
    ------
    OptionError
        If ``state`` has no ``reconstruct`` function (no potential).
    """
    return run_expert(state.copy()).potential()


def lookahead_cut(
    state: PartitionState, *, candidates: int = 4, margin: float = 0.002
) -> Lookahead:
    """The best of the expert's first ``candidates`` cuts and the stop, each followed by the expert.

    Parameters
    ----------
    state : PartitionState
        A running episode with a ``reconstruct`` function (its potential is
        the IoU of the whole reconstruction with its occupancy ``O``).
    candidates : int, optional
        Cuts scored: the expert's first ones, best first
        (:func:`~slicerecon.partition.heuristic.expert_cuts`); the first is
        the expert's own cut.
    margin : float, optional
        Another choice replaces the expert's only when its IoU is higher by
        more than this (volume IoU), so that the teacher does not move for
        differences the learner cannot see.

    Returns
    -------
    Lookahead
        ``cut`` None means stop. Without any splitting segment the expert
        stops too, and so does this.

    Raises
    ------
    OptionError
        For ``candidates < 1``, ``margin < 0``, a finished episode or one
        without a ``reconstruct`` function.
    """
    if int(candidates) < 1:
        raise OptionError(f"candidates must be >= 1 (got {candidates})")
    if not margin >= 0:
        raise OptionError(f"margin must be >= 0 (got {margin})")
    if state.done:
        raise OptionError("the episode is over: nothing to choose")
    stop_value = state.potential()
    cuts = expert_cuts(state, int(candidates))
    if not cuts:
        return Lookahead(None, stop_value, stop_value, 1)
    values = []
    for cut in cuts:
        branch = state.copy()
        branch.apply_cut(cut)
        values.append(expert_value(branch))
    best_cut, best_value = cuts[0], values[0]
    for cut, value in zip(cuts[1:], values[1:], strict=True):
        if value > best_value + margin:
            best_cut, best_value = cut, value
    chosen: Cut | None = best_cut
    if stop_value > best_value + margin:
        chosen, best_value = None, stop_value
    logger.debug(
        "lookahead: %s (%.4f; expert %.4f, stop %.4f)",
        "stop" if chosen is None else chosen,
        best_value,
        values[0],
        stop_value,
    )
    return Lookahead(chosen, best_value, values[0], len(cuts) + 1)
