"""Episode bookkeeping of the partition process.

One episode partitions a shape ``O`` (a boolean occupancy grid) into parts:
each step applies one cut to the remaining region ``R``, separates the part
``W_i`` (:func:`~slicerecon.partition.cuts.split`) and scores it with the
paper's reward ``R_i = IoU(W_i, O) + lam * IoU(S_i, W_i)`` or, with
``reward="gain"``, with the change the part makes to the IoU of the whole
reconstruction with ``O`` (:data:`REWARD_KINDS`, :func:`gain_rewards`).
``docs/method.md`` (section 3) states the rules.

The reward and the end of an episode are written once, as functions of voxel
counts vectorised over a batch of episodes (:func:`count_iou`,
:func:`part_rewards`, :func:`episode_done`): :class:`PartitionState` calls
them for one episode, the torch training environment
(:mod:`slicerecon.policy.env`) for all of its episodes, with counts it takes
on its device.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..corners import harris_corners, pad_corners
from ..errors import EmptyMaskError, GeometryError, InputError, OptionError
from ..sections import Box
from .cuts import Cut, snap_action, split, view_shapes

__all__ = [
    "Part",
    "StepResult",
    "PartitionState",
    "iou",
    "count_iou",
    "part_rewards",
    "gain_rewards",
    "episode_done",
    "NOOP_REWARD",
    "REWARD_KINDS",
]

logger = logging.getLogger(__name__)

NOOP_REWARD: float = 0.0
"""Reward of a step whose action is degenerate or removes nothing (the step still counts)."""

REWARD_KINDS = ("paper", "gain")
"""What a step's reward measures.

``"paper"``: the part itself, ``R_i = IoU(W_i, O) + lam * IoU(S_i, W_i)``
(Cut-and-Approximate, eq. 1): each part adds up to ``1 + lam``, so the return
grows with the number of parts whatever they do to the result.
``"gain"``: the change of the potential ``Phi = IoU(S_1 ∪ ... ∪ S_i ∪ S_R, O)``,
the IoU with ``O`` of the parts' reconstructions and of the remaining region
``R`` reconstructed as one last part (what :meth:`PartitionState.finish`
would make of it). The return telescopes to the episode's final IoU less the
IoU of one part (potential-based shaping, Ng, Harada & Russell 1999): the
objective the planner is judged by, so a cut that makes the result worse is
punished and stopping (a no-op, reward 0) is worth as much as keeping it.
"""

Reconstruct = Callable[[Box], NDArray[np.bool_]]


class Part(NamedTuple):
    """One cuboid part of a partition.

    Attributes
    ----------
    box : Box
        Bounding box of the part's voxels ``W`` (its reconstruction domain).
    mask_voxels : int
        ``|W|``, the number of voxels the part took from the remaining region.
    reward : float
        ``IoU(W, O) + lam * IoU(S, W)`` (first term only without a reconstructor).
    cut : Cut or None
        The cut that separated it; None for the leftover part of ``finish()``.
    """

    box: Box
    mask_voxels: int
    reward: float
    cut: Cut | None


class StepResult(NamedTuple):
    """What one :meth:`PartitionState.step` did.

    Attributes
    ----------
    part : Part or None
        The new part; None for a no-op step.
    reward : float
        The part's reward, or :data:`NOOP_REWARD`.
    done : bool
        Whether the episode is over (call :meth:`PartitionState.finish`).
    info : dict
        ``"cut"`` (Cut or None), ``"noop"`` (None, ``"degenerate"`` or
        ``"removes_nothing"``), ``"iou_part"`` and ``"iou_reconstruction"``
        (the two reward terms; the second is None without a reconstructor),
        ``"remaining_voxels"``.
    """

    part: Part | None
    reward: float
    done: bool
    info: dict[str, Any]


def count_iou(intersection: ArrayLike, union: ArrayLike) -> NDArray[np.float64]:
    """Intersection over union from voxel counts; 1.0 where the union is empty.

    Parameters
    ----------
    intersection, union : ndarray of shape (B,), int
        ``|A & B|`` and ``|A | B|`` of ``B`` pairs of masks.

    Returns
    -------
    ndarray of shape (B,), float64
    """
    inter = np.asarray(intersection, dtype=np.float64)
    total = np.asarray(union, dtype=np.float64)
    return np.where(total > 0, inter / np.maximum(total, 1.0), 1.0)


def iou(a: NDArray[np.bool_], b: NDArray[np.bool_]) -> float:
    """Voxel intersection over union of two same-shaped masks; 1.0 when both are empty."""
    inter, union = np.count_nonzero(a & b), np.count_nonzero(a | b)
    return float(count_iou([inter], [union])[0])


def part_rewards(
    iou_part: ArrayLike, iou_reconstruction: ArrayLike | None, *, lam: float
) -> NDArray[np.float64]:
    """The reward of new parts, ``R_i = IoU(W_i, O) + lam * IoU(S_i, W_i)``.

    Parameters
    ----------
    iou_part : ndarray of shape (B,)
        ``IoU(W_i, O)`` (``|W_i| / |O|``, as ``W_i`` lies in ``O``).
    iou_reconstruction : ndarray of shape (B,) or None
        ``IoU(S_i, W_i)`` inside the part's box; None: no reconstruction, the
        reward is the first term alone.
    lam : float
        Weight of the reconstruction term.

    Returns
    -------
    ndarray of shape (B,), float64
        The rewards; a no-op step gets :data:`NOOP_REWARD` instead (no part).
    """
    first = np.asarray(iou_part, dtype=np.float64)
    if iou_reconstruction is None:
        return first
    return first + float(lam) * np.asarray(iou_reconstruction, dtype=np.float64)


def gain_rewards(before: ArrayLike, after: ArrayLike) -> NDArray[np.float64]:
    """The ``"gain"`` reward of new parts: the change of the potential ``Phi``.

    Parameters
    ----------
    before, after : ndarray of shape (B,)
        ``Phi`` (see :data:`REWARD_KINDS`) before and after the step.

    Returns
    -------
    ndarray of shape (B,), float64
        ``after - before``; a no-op step gets :data:`NOOP_REWARD` instead.
    """
    return np.asarray(after, dtype=np.float64) - np.asarray(before, dtype=np.float64)


def episode_done(
    remaining_voxels: ArrayLike,
    occupied_voxels: ArrayLike,
    step_count: ArrayLike,
    *,
    max_steps: int,
    min_remaining: float,
) -> NDArray[np.bool_]:
    """Whether episodes are over.

    An episode ends when ``R`` is empty, when ``|R| < min_remaining * |O|``,
    or when ``max_steps`` steps (no-ops included) are spent.

    Parameters
    ----------
    remaining_voxels, occupied_voxels, step_count : ndarray of shape (B,), int
        ``|R|``, ``|O|`` and the steps taken (no-ops included) of each episode.
    max_steps : int
    min_remaining : float

    Returns
    -------
    ndarray of shape (B,), bool
    """
    left = np.asarray(remaining_voxels, dtype=np.float64)
    total = np.asarray(occupied_voxels, dtype=np.float64)
    steps = np.asarray(step_count)
    return (left == 0) | (left < float(min_remaining) * total) | (steps >= int(max_steps))


class PartitionState:
    """The state of one partition episode.

    Parameters
    ----------
    occupancy : ndarray of shape (I, J, K), bool
        The shape ``O`` to partition (ground truth in training, the visual
        hull at inference).
    reconstruct : callable, optional
        ``reconstruct(box) -> ndarray of box.shape, bool``: the voxel
        reconstruction ``S`` of a part from the cross-sections inside ``box``
        (e.g. ``functools.partial(part_voxels, sections)``). None skips the
        second reward term.
    lam : float, optional
        Weight ``lambda`` of the reconstruction term (``reward="paper"``).
    reward : {"paper", "gain"}, optional
        What a step's reward measures (:data:`REWARD_KINDS`); ``"gain"``
        needs ``reconstruct``.
    max_steps : int, optional
        The episode ends after this many steps (no-op steps count).
    min_remaining : float, optional
        The episode ends when fewer than ``min_remaining * |O|`` voxels remain.
    max_corners : int, optional
        Corners kept per view (the strongest Harris responses).

    Attributes
    ----------
    occupancy : ndarray of shape (I, J, K), bool
        ``O``, read-only.
    remaining : ndarray of shape (I, J, K), bool
        ``R``, the voxels of ``O`` not yet in a part, read-only (replaced each step).
    parts : list of Part
        Parts made so far, in order.
    step_count : int
        Steps taken (including no-ops).
    """

    def __init__(
        self,
        occupancy: ArrayLike,
        *,
        reconstruct: Reconstruct | None = None,
        lam: float = 1.0,
        reward: str = "paper",
        max_steps: int = 8,
        min_remaining: float = 0.02,
        max_corners: int = 32,
    ) -> None:
        occ = np.asarray(occupancy)
        if occ.ndim != 3:
            raise InputError(f"occupancy must be a 3-D array (got shape {occ.shape})")
        if occ.dtype != np.bool_:
            if occ.dtype.kind not in "biuf" or not np.all(np.isin(occ, (0, 1))):
                raise InputError("occupancy must be boolean (or 0/1 numbers)")
            occ = occ.astype(bool)
        if not occ.any():
            raise EmptyMaskError("the occupancy is empty: nothing to partition")
        if not np.isfinite(lam) or lam < 0:
            raise OptionError(f"lam must be a finite number >= 0 (got {lam})")
        if reward not in REWARD_KINDS:
            raise OptionError(f"reward must be one of {', '.join(REWARD_KINDS)} (got {reward!r})")
        if reward == "gain" and reconstruct is None:
            raise OptionError('reward="gain" needs a reconstruct function')
        if int(max_steps) < 0:
            raise OptionError(f"max_steps must be >= 0 (got {max_steps})")
        if not 0.0 <= float(min_remaining) < 1.0:
            raise OptionError(f"min_remaining must be in [0, 1) (got {min_remaining})")
        if int(max_corners) < 1:
            raise OptionError(f"max_corners must be >= 1 (got {max_corners})")
        self.occupancy: NDArray[np.bool_] = np.array(occ, dtype=bool)
        self.occupancy.setflags(write=False)
        self.reconstruct = reconstruct
        self.lam = float(lam)
        self.reward_kind = reward
        self.max_steps = int(max_steps)
        self.min_remaining = float(min_remaining)
        self.max_corners = int(max_corners)
        self.n_occupied = int(np.count_nonzero(self.occupancy))
        self.image_shapes = view_shapes(self.occupancy.shape)
        self.remaining: NDArray[np.bool_] = self.occupancy
        self.parts: list[Part] = []
        self.step_count = 0
        self._corners: tuple[NDArray[np.float64], ...] | None = None
        self._finished = False
        self._recon: NDArray[np.bool_] | None = None  # the parts' S, made when needed
        self._potential: float | None = None

    # -- observation ---------------------------------------------------------------
    @property
    def grid_shape(self) -> tuple[int, int, int]:
        """``(I, J, K)``."""
        i, j, k = self.occupancy.shape
        return i, j, k

    @property
    def remaining_voxels(self) -> int:
        """``|R|``."""
        return int(np.count_nonzero(self.remaining))

    @property
    def done(self) -> bool:
        """True when ``|R| < min_remaining * |O|``, ``R`` is empty, or ``max_steps`` are spent."""
        if self._finished:
            return True
        return bool(
            episode_done(
                [self.remaining_voxels],
                [self.n_occupied],
                [self.step_count],
                max_steps=self.max_steps,
                min_remaining=self.min_remaining,
            )[0]
        )

    def projections(self) -> tuple[NDArray[np.bool_], NDArray[np.bool_], NDArray[np.bool_]]:
        """Silhouettes of ``R``: view ``a`` is ``R.any(axis=a)``, shapes (J, K), (I, K), (I, J)."""
        x, y, z = (np.asarray(self.remaining.any(axis=a)) for a in range(3))
        return x, y, z

    def corners(self) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
        """Harris corners of :meth:`projections` (default options), one (K_a, 2) array per view."""
        if self._corners is None:
            self._corners = tuple(
                harris_corners(img, max_corners=self.max_corners) for img in self.projections()
            )
        a, b, c = self._corners
        return a, b, c

    def padded_corners(
        self, n_max: int | None = None
    ) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
        """Corner state for a policy: points (3, n_max, 2) in [0, 1] and validity (3, n_max).

        ``n_max`` defaults to ``max_corners``; see :func:`slicerecon.corners.pad_corners`.
        """
        n = self.max_corners if n_max is None else int(n_max)
        pairs = [
            pad_corners(c, n_max=n, image_shape=shape)
            for c, shape in zip(self.corners(), self.image_shapes, strict=True)
        ]
        return np.stack([p for p, _ in pairs]), np.stack([v for _, v in pairs])

    # -- transitions ---------------------------------------------------------------
    def _reconstruction(self, box: Box) -> NDArray[np.bool_]:
        assert self.reconstruct is not None
        s = np.asarray(self.reconstruct(box))
        if s.shape != box.shape:
            raise GeometryError(
                f"reconstruct(box) returned shape {s.shape}, expected the box shape {box.shape}"
            )
        return s.astype(bool, copy=False)

    def _union(self) -> NDArray[np.bool_]:
        """The parts' reconstructions so far on the grid (allocated on first use)."""
        if self._recon is None:
            self._recon = np.zeros(self.occupancy.shape, dtype=bool)
        return self._recon

    def potential(self) -> float:
        """``Phi``: IoU with ``O`` of the parts' reconstructions and of ``R`` as a last part.

        The ``"gain"`` reward's potential (:data:`REWARD_KINDS`); after
        :meth:`finish` it is the IoU of the finished partition's reconstruction.

        Raises
        ------
        OptionError
            Without a ``reconstruct`` function.
        """
        if self.reconstruct is None:
            raise OptionError("the potential needs a reconstruct function")
        if self._potential is None:
            self._potential = self._potential_with(self.remaining)
        return self._potential

    def _make_part(self, w: NDArray[np.bool_], cut: Cut | None) -> tuple[Part, dict[str, Any]]:
        """Score the part ``w``; the caller then sets the remaining region without it."""
        box = Box.of_mask(w)
        iou_part = iou(w, self.occupancy)
        if self.reconstruct is None:
            reward = float(part_rewards([iou_part], None, lam=self.lam)[0])
            return Part(box, int(np.count_nonzero(w)), reward, cut), {
                "iou_part": iou_part,
                "iou_reconstruction": None,
            }
        before = self.potential() if self.reward_kind == "gain" else 0.0
        s = self._reconstruction(box)
        iou_rec = iou(s, w[box.slices])
        self._union()[box.slices] |= s
        if self.reward_kind == "gain":
            after = self._potential_without(w)
            reward = float(gain_rewards([before], [after])[0])
        else:
            self._potential = None
            reward = float(part_rewards([iou_part], [iou_rec], lam=self.lam)[0])
        part = Part(box, int(np.count_nonzero(w)), reward, cut)
        return part, {"iou_part": iou_part, "iou_reconstruction": iou_rec}

    def _potential_without(self, w: NDArray[np.bool_]) -> float:
        """``Phi`` once ``w`` has left the remaining region (its ``S`` already counted)."""
        self._potential = self._potential_with(self.remaining & ~w)
        return self._potential

    def _potential_with(self, rest: NDArray[np.bool_]) -> float:
        """IoU with ``O`` of the parts' union and ``rest`` reconstructed as one more part."""
        return iou(self._union_with(rest), self.occupancy)

    def _union_with(self, rest: NDArray[np.bool_]) -> NDArray[np.bool_]:
        """The parts' union and ``rest`` reconstructed as one more part (a new array)."""
        union = self._union().copy()
        if rest.any():
            box = Box.of_mask(rest)
            union[box.slices] |= self._reconstruction(box)
        return union

    def reconstruction(self) -> NDArray[np.bool_]:
        """The reconstruction the potential scores: the parts' ``S`` and ``R`` as a last part.

        Returns
        -------
        ndarray of shape (I, J, K), bool
            A new array; after :meth:`finish`, the finished partition's reconstruction.

        Raises
        ------
        OptionError
            Without a ``reconstruct`` function.
        """
        if self.reconstruct is None:
            raise OptionError("the reconstruction needs a reconstruct function")
        return self._union_with(self.remaining)

    def _set_remaining(self, rest: NDArray[np.bool_]) -> None:
        rest.setflags(write=False)
        self.remaining = rest
        self._corners = None

    def apply_cut(self, cut: Cut | None) -> StepResult:
        """Take one step with an already snapped cut (None = degenerate action).

        Raises
        ------
        OptionError
            If the episode is already done.
        """
        if self.done:
            raise OptionError("the episode is over: call finish(), then start a new state")
        self.step_count += 1
        info: dict[str, Any] = {"cut": cut, "noop": None}
        result = None if cut is None else split(self.remaining, cut)
        if result is None:
            info["noop"] = "degenerate" if cut is None else "removes_nothing"
            info.update(iou_part=None, iou_reconstruction=None)
            info["remaining_voxels"] = self.remaining_voxels
            logger.debug("step %d: no-op (%s)", self.step_count, info["noop"])
            return StepResult(None, NOOP_REWARD, self.done, info)
        w, rest = result
        part, scores = self._make_part(w, cut)
        info.update(scores)
        self.parts.append(part)
        self._set_remaining(rest)
        info["remaining_voxels"] = self.remaining_voxels
        logger.debug("step %d: part %s, reward %.4f", self.step_count, part.box, part.reward)
        return StepResult(part, part.reward, self.done, info)

    def step(self, action: ArrayLike) -> StepResult:
        """Snap ``action`` (5 numbers in [0, 1]) to a cut on the current corners and apply it.

        See :func:`~slicerecon.partition.cuts.snap_action` and :meth:`apply_cut`.
        """
        cut = snap_action(action, self.corners(), self.image_shapes)
        return self.apply_cut(cut)

    def copy(self) -> PartitionState:
        """An independent copy of this episode: stepping it leaves this one as it is.

        The occupancy, the remaining region and the corners are shared (they
        are read-only and replaced, never written); the parts' union is copied.
        """
        other = object.__new__(PartitionState)
        other.__dict__.update(self.__dict__)
        other.parts = list(self.parts)
        if self._recon is not None:
            other._recon = self._recon.copy()
        return other

    def finish(self) -> list[Part]:
        """End the episode: any leftover ``R`` becomes a last part (its bounding box, no cut).

        After this the parts' boxes cover every voxel of ``O``. Idempotent.

        Returns
        -------
        list of Part
            All parts, in order.
        """
        if not self._finished and self.remaining.any():
            part, _ = self._make_part(np.asarray(self.remaining), None)
            self.parts.append(part)
            self._set_remaining(np.zeros_like(self.occupancy))
        self._finished = True
        return list(self.parts)
