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

import functools
import logging
from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import InputError, OptionError
from ..sections import Box, CrossSections
from .cuts import Cut, view_shapes
from .heuristic import expert_cuts, run_expert
from .state import Part, PartitionState, Reconstruct

__all__ = [
    "Lookahead",
    "StateValue",
    "expert_value",
    "lookahead_cut",
    "run_lookahead",
    "held_out_value",
    "silhouette_value",
    "plan_lookahead",
    "PartSurface",
    "PlanningSurface",
    "LOOKAHEAD_VALUES",
    "LOOKAHEAD_MARGINS",
]

StateValue = Callable[[PartitionState], float]
"""``value(state) -> float``: how good a state's reconstruction (parts and ``R`` as a
last part) is; higher is better. :meth:`PartitionState.potential` (IoU with a known
``O``) in training, :func:`held_out_value` or :func:`silhouette_value` at inference."""

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


def expert_value(state: PartitionState, value: StateValue | None = None) -> float:
    """``value`` after the heuristic expert finishes ``state`` (``state`` is left as it is).

    The expert cuts until it has no cut left or the episode ends; the
    remaining region is then one last part. ``value`` defaults to the
    potential (IoU with ``O``).

    Raises
    ------
    OptionError
        If ``state`` has no ``reconstruct`` function (no potential).
    """
    finished = run_expert(state.copy())
    return finished.potential() if value is None else float(value(finished))


def lookahead_cut(
    state: PartitionState,
    *,
    candidates: int = 4,
    margin: float = 0.002,
    value: StateValue | None = None,
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
    value : callable, optional
        What the choices are scored by (:data:`StateValue`); default the
        potential, the IoU with ``O`` (then ``Lookahead.value`` is an IoU).

    Returns
    -------
    Lookahead
        ``cut`` None means stop. Without any splitting segment the expert
        stops too, and so does this. ``value`` and ``expert_value`` are in
        the units of ``value``.

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
    stop_value = state.potential() if value is None else float(value(state))
    cuts = expert_cuts(state, int(candidates))
    if not cuts:
        return Lookahead(None, stop_value, stop_value, 1)
    values = []
    for cut in cuts:
        branch = state.copy()
        branch.apply_cut(cut)
        values.append(expert_value(branch, value))
    best_cut, best_value = cuts[0], values[0]
    for cut, score in zip(cuts[1:], values[1:], strict=True):
        if score > best_value + margin:
            best_cut, best_value = cut, score
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


def run_lookahead(
    state: PartitionState,
    *,
    candidates: int = 4,
    margin: float = 0.002,
    value: StateValue | None = None,
) -> PartitionState:
    """Step ``state`` by :func:`lookahead_cut` until the episode ends or it stops; return it.

    The state is stepped in place (not finished: call ``finish()``). The
    arguments are :func:`lookahead_cut`'s.
    """
    while not state.done:
        choice = lookahead_cut(state, candidates=candidates, margin=margin, value=value)
        if choice.cut is None:
            break
        state.apply_cut(choice.cut)
    return state


PartSurface = Callable[[CrossSections, Box], NDArray[np.bool_]]
"""``part(sections, box) -> bool array of box.shape``: a part's reconstruction from
``sections`` (all planes, or a subset of them) inside ``box``."""


class PlanningSurface(NamedTuple):
    """What the planners that score their choices on reconstructions need, on the planning grid.

    Attributes
    ----------
    sections : CrossSections
        The cross-sections, on the grid the planner works on.
    hull : ndarray of shape sections.grid_shape, bool
        The visual hull of the input's projections on that grid.
    part : callable
        :data:`PartSurface`: the part surface inference makes (at inference
        the signed-distance part carved by the hull).
    """

    sections: CrossSections
    hull: NDArray[np.bool_]
    part: PartSurface


LOOKAHEAD_VALUES = ("planes", "silhouettes")
"""What :func:`plan_lookahead` scores its choices by at inference:
``"planes"`` (:func:`held_out_value`) or ``"silhouettes"`` (:func:`silhouette_value`)."""

LOOKAHEAD_MARGINS: dict[str, float] = {"planes": 0.002, "silhouettes": 0.005}
"""Default ``margin`` of :func:`plan_lookahead` per value, chosen on the development
shapes (``docs/results.md``, "The lookahead planner")."""


def _state_boxes(state: PartitionState) -> list[Box]:
    """The parts' boxes and, while any of it is left, the remaining region's as a last part."""
    boxes = [part.box for part in state.parts]
    if state.remaining.any():
        boxes.append(Box.of_mask(state.remaining))
    return boxes


def held_out_value(sections: CrossSections, part: PartSurface, *, folds: int = 3) -> StateValue:
    """A :data:`StateValue` for inference: how well the partition predicts planes it did not see.

    Cross-validation over the section planes: the interior planes are dealt
    into ``folds`` groups (plane ``i`` into group ``i mod folds``; the first
    and last planes are always kept, so the shape's extent does not change).
    For each group the state's parts (and ``R`` as a last part) are
    reconstructed from the other planes with ``part``, and their union is
    compared with the held-out masks on the grid layers nearest those planes.
    The value is the pooled IoU ``sum |S & M| / sum |S | M|`` over every
    held-out plane. Unlike :func:`silhouette_value` it punishes a
    reconstruction that overfills as well as one that underfills. It needs
    no ground truth: the held-out masks are the reconstruction's input.

    Parameters
    ----------
    sections : CrossSections
        All the cross-sections, on the grid of the states to be scored.
    part : callable
        :data:`PartSurface` (boolean results); they are memoised per (group, box).
    folds : int, optional
        Groups of held-out planes (>= 2).

    Returns
    -------
    callable
        ``value(state) -> float`` in [0, 1]; 1.0 for every state when there
        is no interior plane to hold out (fewer than three planes).

    Raises
    ------
    OptionError
        For ``folds < 2``.
    """
    if int(folds) < 2:
        raise OptionError(f"folds must be >= 2 (got {folds})")
    n = sections.n_planes
    groups: list[tuple[list[int], Callable[[Box], NDArray[np.bool_]]]] = []
    for group in range(int(folds)):
        held = [i for i in range(1, n - 1) if i % int(folds) == group]
        if not held:
            continue
        keep = [i for i in range(n) if i not in held]
        subset = replace(sections, masks=sections.masks[keep], indices=sections.indices[keep])
        groups.append((held, functools.cache(functools.partial(part, subset))))
    layers = np.clip(np.round(sections.indices), 0, sections.grid_shape[sections.axis] - 1)

    def value(state: PartitionState) -> float:
        if state.grid_shape != sections.grid_shape:
            raise InputError(
                f"the state's grid {state.grid_shape} is not the sections' {sections.grid_shape}"
            )
        if not groups:
            return 1.0
        boxes = _state_boxes(state)
        inter = union = 0
        for held, reconstruct in groups:
            recon = np.zeros(sections.grid_shape, dtype=bool)
            for box in boxes:
                recon[box.slices] |= reconstruct(box)
            for i in held:
                layer = np.take(recon, int(layers[i]), axis=sections.axis)
                inter += int(np.count_nonzero(layer & sections.masks[i]))
                union += int(np.count_nonzero(layer | sections.masks[i]))
        return inter / union if union else 1.0

    return value


def silhouette_value(
    silhouettes: Sequence[ArrayLike],
) -> StateValue:
    """A :data:`StateValue` for inference: how well a reconstruction fills the given silhouettes.

    The projections of the state's reconstruction (:meth:`PartitionState.reconstruction`)
    along the three grid axes are compared with ``silhouettes``; the value is
    ``sum_a |P_a & Q_a| / sum_a |P_a | Q_a|`` over the views ``a``. A
    reconstruction carved by the visual hull lies inside it, so the value
    falls where interpolation between planes leaves part of a silhouette
    empty, which the section masks alone do not show, and it never punishes
    overfilling: it favours more parts. It needs no ground truth: the
    silhouettes are the reconstruction's input.

    Parameters
    ----------
    silhouettes : sequence of 3 ndarrays, bool
        View ``a`` along grid axis ``a``: shapes (J, K), (I, K), (I, J) of
        the grid (I, J, K), e.g. ``[hull.any(axis=a) for a in range(3)]``.

    Returns
    -------
    callable
        ``value(state) -> float`` in [0, 1].

    Raises
    ------
    InputError
        If a silhouette is empty or ``silhouettes`` is not three 2-D arrays.
    """
    views = [np.asarray(v, dtype=bool) for v in silhouettes]
    if len(views) != 3 or any(v.ndim != 2 for v in views):
        raise InputError("silhouettes must be three 2-D masks, one per grid axis")
    if not all(v.any() for v in views):
        raise InputError("a silhouette is empty: nothing to compare the reconstruction with")

    def value(state: PartitionState) -> float:
        if tuple(v.shape for v in views) != view_shapes(state.grid_shape):
            raise InputError(
                f"silhouette shapes {[v.shape for v in views]} do not match the grid "
                f"{state.grid_shape}"
            )
        recon = state.reconstruction()
        inter = union = 0
        for axis, view in enumerate(views):
            proj = recon.any(axis=axis)
            inter += int(np.count_nonzero(proj & view))
            union += int(np.count_nonzero(proj | view))
        return inter / union

    return value


def plan_lookahead(
    occupancy: NDArray[np.bool_],
    *,
    reconstruct: Reconstruct | None,
    max_parts: int,
    min_remaining: float,
    lam: float,
    surface: PlanningSurface | None = None,
    value: str = "planes",
    candidates: int = 4,
    margin: float | None = None,
) -> list[Part]:
    """The heuristic expert with a one-step lookahead scored without the ground truth.

    At each step the expert's first ``candidates`` cuts and the stop are each
    followed by the expert to the end of the episode, their reconstructions
    are scored by ``value``, and the best choice replaces the expert's own
    when it is better by more than ``margin`` (:func:`lookahead_cut`). This
    is the rollout algorithm with the heuristic as base policy (Bertsekas,
    Tsitsiklis and Wu, "Rollout Algorithms for Combinatorial Optimization",
    Journal of Heuristics 3, 1997), scored on what the input itself can
    check instead of the unknown shape.

    Parameters
    ----------
    occupancy : ndarray of shape (I, J, K), bool
        The shape to partition (at inference the visual hull, exact on the planes).
    reconstruct : None
        Not used (the part surface comes with ``surface``); accepted for the
        planners' common signature. Must be None.
    max_parts, min_remaining, lam
        As for the other planners (:func:`~slicerecon.partition.planner.plan_partition`).
    surface : PlanningSurface
        The sections, the hull and the part surface on ``occupancy``'s grid.
    value : {"planes", "silhouettes"}, optional
        :func:`held_out_value` (three groups of held-out planes) or
        :func:`silhouette_value` (the hull's three views).
    candidates : int, optional
        The expert's cuts scored at each step, best first.
    margin : float, optional
        IoU (in ``value``'s terms) by which another choice must beat the
        expert's; default :data:`LOOKAHEAD_MARGINS`.

    Returns
    -------
    list of Part
        Parts whose boxes cover the occupancy.

    Raises
    ------
    OptionError
        Without ``surface``, with ``reconstruct``, for an unknown ``value``,
        ``candidates < 1`` or ``margin < 0``.
    InputError
        If ``surface`` is not on ``occupancy``'s grid.
    """
    if surface is None or reconstruct is not None:
        raise OptionError(
            "the lookahead planner needs surface= (the sections, hull and part surface)"
        )
    if value not in LOOKAHEAD_VALUES:
        raise OptionError(f"value must be one of {', '.join(LOOKAHEAD_VALUES)} (got {value!r})")
    occ = np.asarray(occupancy, dtype=bool)
    if occ.shape != surface.sections.grid_shape or surface.hull.shape != occ.shape:
        raise InputError(
            f"the planning surface's grid {surface.sections.grid_shape} is not the "
            f"occupancy's {occ.shape}"
        )
    # held-out planes reconstruct each group's parts themselves; only the silhouettes
    # score the state's own reconstruction (rollouts ask for the same boxes again)
    part = None
    if value == "planes":
        score = held_out_value(surface.sections, surface.part)
    else:
        score = silhouette_value([surface.hull.any(axis=a) for a in range(3)])
        part = functools.cache(functools.partial(surface.part, surface.sections))
    state = PartitionState(
        occ,
        reconstruct=part,
        lam=lam,
        max_steps=int(max_parts) - 1,
        min_remaining=min_remaining,
    )
    step_margin = LOOKAHEAD_MARGINS[value] if margin is None else float(margin)
    return run_lookahead(state, candidates=candidates, margin=step_margin, value=score).finish()
