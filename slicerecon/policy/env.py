"""The cut environment in torch: many partition episodes stepped at once.

:class:`CutEnv` runs ``B`` episodes of the partition process of
:class:`~slicerecon.partition.state.PartitionState` side by side. The rules
(snapping an action to corners, the cut's sides and the part ``W_i`` it
separates, no-ops, the reward, the end of an episode) are written once, in
:mod:`slicerecon.partition.cuts` and :mod:`slicerecon.partition.state`, as
functions vectorised over a batch of episodes (``docs/method.md``, section 3);
this module calls them with all its episodes at once and keeps only what
needs the voxels on the device: counting the remaining voxels on each side of
each cut, masking ``W_i``, its bounding box, and the IoU counts.

The episodes (shapes scaled into ``G^3`` cubes, their sections and visual
hull) come from :mod:`slicerecon.partition.episodes`. The reward's
reconstruction ``S_i`` is the part surface inference makes
(:mod:`slicerecon.policy.reward`, the default), or its batched torch surrogate
(:mod:`slicerecon.policy.surrogate`; agreement measured in ``docs/policy.md``).

Corners are the library's numpy :func:`~slicerecon.corners.harris_corners` of
each changed silhouette (on the CPU), so snapping is exactly the planner's.

Observations
------------
:class:`~slicerecon.policy.observation.Observation` and its encoders live in
:mod:`slicerecon.policy.observation` (re-exported here).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
import torch
from numpy.typing import ArrayLike, NDArray

from ..errors import EmptyMaskError, InputError, OptionError
from ..partition.cuts import SnappedCuts, choose_sides, line_sides, snap_actions, view_shapes
from ..partition.episodes import ShapePool, episode_sections, occupancy_hull
from ..partition.heuristic import expert_action, expert_cuts
from ..partition.state import (
    NOOP_REWARD,
    REWARD_KINDS,
    PartitionState,
    count_iou,
    episode_done,
    gain_rewards,
    part_rewards,
)
from ..sections import Box, CrossSections
from .observation import (
    ADVICE_WIDTH,
    Observation,
    advice_rows,
    observe_state,
    padded_corners,
    resize_views,
)
from .reward import REWARD_SURFACES, mask_distances, part_surface_voxels, plane_distances
from .surrogate import surrogate_parts

__all__ = [
    "Observation",
    "EnvStep",
    "StepRecord",
    "CutEnv",
    "resize_views",
    "advice_rows",
    "observe_state",
]

logger = logging.getLogger(__name__)

_NO_SIDE = 2
"""A side no pixel has (sides are -1, 0, +1): the part of a no-op step is empty."""


class EnvStep(NamedTuple):
    """What :meth:`CutEnv.step` returns (one entry per episode).

    Attributes
    ----------
    obs : Observation
        The next state; for an episode that just ended, the first state of the
        episode that replaced it (automatic reset).
    reward : Tensor of shape (B,), float32
    done : Tensor of shape (B,), bool
        The step ended its episode.
    noop : Tensor of shape (B,), bool
        The action was degenerate or removed nothing.
    episode_return : Tensor of shape (B,), float32
        Sum of rewards of the episodes that ended (NaN elsewhere).
    final_iou : Tensor of shape (B,), float32
        For the episodes that ended: voxel IoU between ``O`` and the union of the
        parts' reconstructions ``S_i``, the leftover region counted as a last part
        (as :meth:`PartitionState.finish`); NaN elsewhere.
    n_parts : Tensor of shape (B,), int64
        Parts of the ended episodes including the leftover (0 elsewhere).
    """

    obs: Observation
    reward: torch.Tensor
    done: torch.Tensor
    noop: torch.Tensor
    episode_return: torch.Tensor
    final_iou: torch.Tensor
    n_parts: torch.Tensor


class StepRecord(NamedTuple):
    """What the last :meth:`CutEnv.step` did in each episode, before any reset.

    Attributes
    ----------
    cuts : SnappedCuts
        The snapped cuts (:func:`~slicerecon.partition.cuts.snap_actions`).
    removes_nothing : ndarray of shape (B,), bool
        The cut's line left one side of the remaining region empty.
    noop : ndarray of shape (B,), bool
        Degenerate or removes nothing: no part.
    part : Tensor of shape (B, G, G, G), bool
        ``W_i`` (empty for no-ops).
    lo, hi : ndarray of shape (B, 3), int64
        The part's box (``hi`` exclusive; zeros for no-ops).
    iou_part, iou_reconstruction : ndarray of shape (B,), float64
        The reward's two terms (NaN for no-ops).
    reward : ndarray of shape (B,), float64
    """

    cuts: SnappedCuts
    removes_nothing: NDArray[np.bool_]
    noop: NDArray[np.bool_]
    part: torch.Tensor
    lo: NDArray[np.int64]
    hi: NDArray[np.int64]
    iou_part: NDArray[np.float64]
    iou_reconstruction: NDArray[np.float64]
    reward: NDArray[np.float64]


class CutEnv:
    """``B`` partition episodes stepped together (Gymnasium-style, automatic reset).

    Parameters
    ----------
    pool : ShapePool
        Shapes the episodes are drawn from (uniformly, with replacement).
    n_envs : int
        Episodes run side by side, ``B``.
    resolution : int, optional
        Side ``R`` of the observed silhouettes.
    max_corners : int, optional
        Corners per view, ``K`` (the strongest Harris responses).
    max_steps : int, optional
        Cuts per episode.
    min_remaining : float, optional
        The episode ends when fewer than this fraction of ``|O|`` remains.
    lam : float, optional
        Weight of the reconstruction term of the reward.
    planes : tuple of int, optional
        ``(min, max)`` number of section planes of an episode (along z), drawn
        per episode (:func:`~slicerecon.partition.episodes.episode_sections`).
    augment : bool, optional
        Randomly permute and flip the grid axes of each drawn shape.
    reward : {"paper", "gain"}, optional
        What a step's reward measures
        (:data:`~slicerecon.partition.state.REWARD_KINDS`): the paper's
        ``IoU(W_i, O) + lam IoU(S_i, W_i)``, or the change of the IoU of the
        whole reconstruction with ``O`` (the remaining region counted as a
        last part), whose return is the episode's final IoU less one part's.
    reward_surface : {"exact", "surrogate"}, optional
        The reward's reconstruction ``S_i``: ``"exact"`` (the default) is the
        part surface of inference
        (:func:`~slicerecon.policy.reward.part_surface_voxels`, numpy on the
        CPU, a few ms per part); ``"surrogate"`` its batched torch
        approximation (:mod:`slicerecon.policy.surrogate`), for a GPU.
    candidates : int, optional
        Observations carry the heuristic expert's first ``candidates`` cuts at
        each state (:attr:`Observation.advice`), for actors that choose among
        them; 0: none.
    device : str or torch.device, optional
    seed : int, optional
        Seed of the episode draws.
    """

    def __init__(
        self,
        pool: ShapePool,
        *,
        n_envs: int,
        resolution: int = 64,
        max_corners: int = 16,
        max_steps: int = 8,
        min_remaining: float = 0.02,
        lam: float = 1.0,
        planes: tuple[int, int] = (8, 16),
        augment: bool = True,
        reward: str = "paper",
        reward_surface: str = "exact",
        candidates: int = 0,
        device: str | torch.device = "cpu",
        seed: int = 0,
    ) -> None:
        if len(pool) == 0:
            raise OptionError("the shape pool is empty")
        if int(n_envs) < 1:
            raise OptionError(f"n_envs must be >= 1 (got {n_envs})")
        if int(resolution) < 8:
            raise OptionError(f"resolution must be >= 8 (got {resolution})")
        if int(max_corners) < 2:
            raise OptionError(f"max_corners must be >= 2 (got {max_corners})")
        if int(max_steps) < 1:
            raise OptionError(f"max_steps must be >= 1 (got {max_steps})")
        if not 0.0 <= float(min_remaining) < 1.0:
            raise OptionError(f"min_remaining must be in [0, 1) (got {min_remaining})")
        if not np.isfinite(lam) or lam < 0:
            raise OptionError(f"lam must be a finite number >= 0 (got {lam})")
        lo_p, hi_p = (int(p) for p in planes)
        if not 1 <= lo_p <= hi_p:
            raise OptionError(f"planes must be (min, max) with 1 <= min <= max (got {planes})")
        if reward not in REWARD_KINDS:
            raise OptionError(f"reward must be one of {', '.join(REWARD_KINDS)} (got {reward!r})")
        if reward_surface not in REWARD_SURFACES:
            raise OptionError(
                f"reward_surface must be one of {', '.join(REWARD_SURFACES)} "
                f"(got {reward_surface!r})"
            )
        self.pool = pool
        self.n_envs = int(n_envs)
        self.grid = pool.grid
        self.image_shapes = view_shapes((self.grid,) * 3)
        self.resolution = int(resolution)
        self.max_corners = int(max_corners)
        self.max_steps = int(max_steps)
        self.min_remaining = float(min_remaining)
        self.lam = float(lam)
        self.planes = (lo_p, hi_p)
        self.augment = bool(augment)
        self.reward_kind = reward
        self.reward_surface = reward_surface
        if isinstance(candidates, bool) or int(candidates) < 0:
            raise OptionError(f"candidates must be an integer >= 0 (got {candidates!r})")
        self.candidates = int(candidates)
        self.device = torch.device(device)
        self.rng = np.random.default_rng(seed)
        b, g, k = self.n_envs, self.grid, self.max_corners
        dev = self.device
        # Voxels on the device.
        self.occupancy = torch.zeros((b, g, g, g), dtype=torch.bool, device=dev)
        self.remaining = torch.zeros_like(self.occupancy)
        self.recon = torch.zeros_like(self.occupancy)
        self.hull = torch.zeros_like(self.occupancy)
        self.plane_index = torch.zeros((b, hi_p), dtype=torch.int64, device=dev)
        self.plane_valid = torch.zeros((b, hi_p), dtype=torch.bool, device=dev)
        self.plane_dist = torch.zeros((b, hi_p, g, g), dtype=torch.float32, device=dev)
        self._silhouettes = torch.zeros((b, 3, g, g), dtype=torch.bool, device=dev)
        self._arange = torch.arange(g, device=dev)
        # Per-episode numbers on the CPU, where the rules are evaluated.
        self.n_occupied = np.ones(b, dtype=np.int64)
        self._steps = np.zeros(b, dtype=np.int64)
        self.returns = np.zeros(b, dtype=np.float64)
        self.potential = np.zeros(b, dtype=np.float64)
        self.n_parts = np.zeros(b, dtype=np.int64)
        self.corner_px = np.zeros((b, 3, k, 2), dtype=np.float64)
        self.corner_norm = np.zeros((b, 3, k, 2), dtype=np.float64)
        self.corner_valid = np.zeros((b, 3, k), dtype=bool)
        self.shape_id = np.zeros(b, dtype=np.int64)
        self._sections: list[CrossSections | None] = [None] * b
        self._hulls: list[NDArray[np.bool_] | None] = [None] * b
        self._expert: list[NDArray[np.float64] | None | bool] = [False] * b
        self._candidates: list[NDArray[np.float32] | None] = [None] * b
        self._orient: list[tuple[int, tuple[int, ...], tuple[int, ...]] | None] = [None] * b
        self._plane_cache: dict[tuple[int, int], tuple[NDArray[np.float32], NDArray[np.bool_]]] = {}
        self.last_step: StepRecord | None = None

    @property
    def step_count(self) -> torch.Tensor:
        """Steps taken in each running episode (no-ops included), Tensor of shape (B,), int64."""
        return torch.from_numpy(self._steps.copy())

    # -- episodes -------------------------------------------------------------------------
    def _draw(self, env: int, shape: int | None) -> NDArray[np.bool_]:
        idx = int(self.rng.integers(len(self.pool))) if shape is None else int(shape)
        self.shape_id[env] = idx
        occ = self.pool.occupancies[idx]
        perm: tuple[int, ...] = (0, 1, 2)
        flips: tuple[int, ...] = ()
        if self.augment and shape is None:
            perm = tuple(int(a) for a in self.rng.permutation(3))
            occ = np.transpose(occ, perm)
            flips = tuple(int(a) for a in np.flatnonzero(self.rng.random(3) < 0.5))
            if flips:
                occ = np.flip(occ, axis=flips)
        self._orient[env] = (idx, perm, flips)
        return np.ascontiguousarray(occ)

    def _plane_distances(self, env: int, sections: CrossSections) -> NDArray[np.float32]:
        """:func:`plane_distances` of an episode's sections, from a per-shape cache.

        The distance of a plane of a pool shape (along an axis of its original
        orientation) is computed the first time an episode uses it; an
        augmented episode's planes are those planes transposed and flipped
        (a distance transform commutes with both exactly).
        """
        orient = self._orient[env]
        if orient is None:
            return plane_distances(sections)
        idx, perm, flips = orient
        axis = perm[2]
        entry = self._plane_cache.get((idx, axis))
        if entry is None:
            g = self.grid
            entry = (np.zeros((g, g, g), dtype=np.float32), np.zeros(g, dtype=bool))
            self._plane_cache[(idx, axis)] = entry
        stack, known = entry
        k = sections.indices.astype(np.int64)
        if 2 in flips:
            k = self.grid - 1 - k
        missing = k[~known[k]]
        if missing.size:
            masks = np.moveaxis(self.pool.occupancies[idx], axis, 0)[missing]
            stack[missing] = mask_distances(masks)
            known[missing] = True
        dist = stack[k]
        if perm[0] > perm[1]:
            dist = dist.transpose(0, 2, 1)
        if 0 in flips:
            dist = dist[:, ::-1, :]
        if 1 in flips:
            dist = dist[:, :, ::-1]
        return np.ascontiguousarray(dist)

    def _start(
        self,
        envs: Sequence[int],
        occupancies: Sequence[NDArray[np.bool_]],
        n_planes: Sequence[int] | None = None,
    ) -> None:
        """Begin new episodes in ``envs`` on the given grids."""
        for i, (env, occ) in enumerate(zip(envs, occupancies, strict=True)):
            if n_planes is None:
                count = int(self.rng.integers(self.planes[0], self.planes[1] + 1))
            else:
                count = int(n_planes[i])
            sections = episode_sections(occ, count)
            hull = occupancy_hull(occ)
            planes = sections.indices.astype(np.int64)
            t = torch.from_numpy(occ).to(self.device)
            self.occupancy[env] = t
            self.remaining[env] = t
            self.recon[env] = False
            self.hull[env] = torch.from_numpy(hull).to(self.device)
            self.plane_valid[env] = False
            self.plane_index[env] = 0
            self.plane_index[env, : planes.size] = torch.from_numpy(planes).to(self.device)
            self.plane_valid[env, : planes.size] = True
            if self.reward_surface == "surrogate":
                dist = torch.from_numpy(self._plane_distances(env, sections)).to(self.device)
                self.plane_dist[env, : planes.size] = dist
            self._sections[env], self._hulls[env] = sections, hull
            self.n_occupied[env] = int(np.count_nonzero(occ))
            self._steps[env] = 0
            self.returns[env] = 0.0
            self.n_parts[env] = 0
        if self.reward_kind == "gain":
            idx = torch.tensor(list(envs), device=self.device)
            self.potential[list(envs)] = self._potentials(idx, self.remaining[idx], self.recon[idx])
        self._refresh_corners(list(envs))

    def reset(self, seed: int | None = None, *, shapes: Sequence[int] | None = None) -> Observation:
        """Start a new episode in every slot.

        Parameters
        ----------
        seed : int, optional
            Reseed the episode draws.
        shapes : sequence of int, optional
            Pool indices, one per slot (no augmentation); default: random draws.

        Returns
        -------
        Observation
        """
        if seed is not None:
            self.rng = np.random.default_rng(seed)
        if shapes is not None and len(shapes) != self.n_envs:
            raise OptionError(f"give one shape per env ({self.n_envs}), got {len(shapes)}")
        envs = list(range(self.n_envs))
        grids = [self._draw(e, None if shapes is None else shapes[e]) for e in envs]
        self._start(envs, grids)
        return self.observation()

    def load(
        self, occupancies: Sequence[ArrayLike], *, n_planes: Sequence[int] | None = None
    ) -> Observation:
        """Start episodes on given ``G^3`` grids (one per slot), e.g. to compare with numpy."""
        if len(occupancies) != self.n_envs:
            raise OptionError(f"give one grid per env ({self.n_envs}), got {len(occupancies)}")
        grids = []
        for occ in occupancies:
            arr = np.ascontiguousarray(np.asarray(occ, dtype=bool))
            if arr.shape != (self.grid,) * 3:
                raise InputError(f"grids must be {self.grid}^3 (got {arr.shape})")
            if not arr.any():
                raise EmptyMaskError("an occupancy grid is empty")
            grids.append(arr)
        self._orient = [None] * self.n_envs
        self._start(list(range(self.n_envs)), grids, n_planes)
        return self.observation()

    # -- observation ----------------------------------------------------------------------
    def silhouettes(self) -> torch.Tensor:
        """Projections of the remaining regions, Tensor of shape (B, 3, G, G), bool."""
        u = self.remaining.view(torch.uint8)  # amax on uint8 is much faster than any() on CPU
        return torch.stack([u.amax(dim=1), u.amax(dim=2), u.amax(dim=3)], dim=1) > 0

    def _refresh_corners(self, envs: list[int], *, force: bool = True) -> None:
        """Recompute the corners of the views of ``envs`` whose silhouette changed."""
        if not envs:
            return
        sil = self.silhouettes()[envs]
        changed = torch.ones(sil.shape[:2], dtype=torch.bool, device=self.device)
        if not force:
            changed = (sil != self._silhouettes[envs]).flatten(2).any(dim=2)
        self._silhouettes[envs] = sil
        sil_np = sil.cpu().numpy()
        changed_np = changed.cpu().numpy()
        for i, env in enumerate(envs):
            self._expert[env] = False
            self._candidates[env] = None
            for v in np.flatnonzero(changed_np[i]):
                px, norm, valid = padded_corners(sil_np[i, v], self.max_corners)
                self.corner_px[env, v] = px
                self.corner_norm[env, v] = norm
                self.corner_valid[env, v] = valid

    def observation(self) -> Observation:
        """The current states."""
        b, g, r = self.n_envs, self.grid, self.resolution
        views = resize_views(self.silhouettes().reshape(b * 3, g, g), r).reshape(b, 3, r, r)
        step = torch.from_numpy(self._steps / self.max_steps).to(torch.float32).unsqueeze(1)
        corners = torch.from_numpy(self.corner_norm).to(torch.float32)
        mask = torch.from_numpy(self.corner_valid).to(torch.float32)
        dev = self.device
        advice = None
        if self.candidates:
            advice = torch.from_numpy(self.expert_candidates()).to(dev)
        return Observation(views, step.to(dev), corners.to(dev), mask.to(dev), advice)

    def episode(self, env: int) -> tuple[NDArray[np.bool_], CrossSections, NDArray[np.bool_]]:
        """The running episode of slot ``env``: its occupancy ``O``, sections and visual hull."""
        sections, hull = self._sections[env], self._hulls[env]
        if sections is None or hull is None:
            raise OptionError("no episode has started: call reset() or load() first")
        return self.occupancy[env].cpu().numpy(), sections, hull

    def state_of(self, env: int) -> PartitionState:
        """A numpy :class:`PartitionState` whose remaining region is this episode's.

        Its occupancy is the remaining region (enough for the heuristic expert,
        which looks at the remaining region only); the corners are shared.
        """
        rem = self.remaining[env].cpu().numpy().copy()
        state = PartitionState(rem, max_corners=self.max_corners, max_steps=self.max_steps)
        valid = self.corner_valid[env]
        px = self.corner_px[env]
        state._corners = tuple(px[v][valid[v]] for v in range(3))  # noqa: SLF001
        return state

    def expert_actions(self) -> tuple[NDArray[np.float32], NDArray[np.bool_]]:
        """The heuristic expert's action ``pi^h(s)`` of every episode (cached per state).

        Returns
        -------
        actions : ndarray of shape (B, 5), float32
            :func:`~slicerecon.partition.heuristic.expert_action`; 0 where invalid.
        valid : ndarray of shape (B,), bool
            False where the expert has no useful cut.
        """
        if self.candidates:  # the expert's action is its first cut, listed there already
            first = self.expert_candidates()[:, 0]
            valid = first[:, 5] > 0.5
            return np.where(valid[:, None], first[:, :5], np.float32(0.0)), valid
        actions = np.zeros((self.n_envs, 5), dtype=np.float32)
        valid = np.zeros(self.n_envs, dtype=bool)
        for env in range(self.n_envs):
            cached = self._expert[env]
            if cached is False:
                cached = expert_action(self.state_of(env))
                self._expert[env] = cached
            if cached is not None and cached is not True:
                actions[env] = cached
                valid[env] = True
        return actions, valid

    def expert_candidates(self) -> NDArray[np.float32]:
        """The expert's first ``candidates`` cuts of every episode (cached per state).

        Returns
        -------
        ndarray of shape (B, C, 6), float32
            :func:`~slicerecon.policy.observation.advice_rows` of
            :func:`~slicerecon.partition.heuristic.expert_cuts`.
        """
        out = np.zeros((self.n_envs, self.candidates, ADVICE_WIDTH), dtype=np.float32)
        for env in range(self.n_envs):
            cached = self._candidates[env]
            if cached is None:
                cuts = expert_cuts(self.state_of(env), self.candidates)
                cached = advice_rows(cuts, self.image_shapes, self.candidates)
                self._candidates[env] = cached
            out[env] = cached
        return out

    # -- voxel work on the device ---------------------------------------------------------
    def _column_counts(self, view: torch.Tensor) -> torch.Tensor:
        """Remaining voxels per pixel of each episode's view, (B, G, G) int64."""
        counts = torch.zeros(
            (self.n_envs, self.grid, self.grid), dtype=torch.int64, device=self.device
        )
        for v in range(3):
            sel = view == v
            if bool(sel.any()):
                counts[sel] = self.remaining[sel].sum(dim=v + 1)
        return counts

    @staticmethod
    def _extrude(pixels: torch.Tensor, view: torch.Tensor) -> torch.Tensor:
        """Pixel masks (B, G, G) of each episode's view extruded along it, (B, G, G, G)."""
        v = view[:, None, None, None]
        return torch.where(
            v == 0,
            pixels[:, None, :, :],
            torch.where(v == 1, pixels[:, :, None, :], pixels[:, :, :, None]),
        )

    def _boxes(self, mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Bounding boxes (:meth:`Box.of_mask`) of masks (n, G, G, G): lo, hi (n, 3); 0 if empty."""
        a = self._arange
        u = mask.view(torch.uint8)
        los, his = [], []
        for dims in ((2, 3), (1, 3), (1, 2)):
            occ = u.amax(dim=dims[1]).amax(dim=dims[0]) > 0  # (n, G)
            lo = torch.where(occ, a, torch.full_like(a, self.grid)).min(dim=1).values
            hi = torch.where(occ, a, torch.full_like(a, -1)).max(dim=1).values + 1
            empty = ~occ.any(dim=1)
            los.append(torch.where(empty, 0, lo))
            his.append(torch.where(empty, 0, hi))
        return torch.stack(los, 1), torch.stack(his, 1)

    def _reconstruct(self, envs: torch.Tensor, lo: torch.Tensor, hi: torch.Tensor) -> torch.Tensor:
        """``S_i`` of parts with boxes ``[lo, hi)`` in episodes ``envs``, (n, G, G, G) bool."""
        if self.reward_surface == "surrogate":
            return surrogate_parts(
                self.plane_dist[envs],
                self.plane_index[envs],
                self.plane_valid[envs],
                self.hull[envs],
                lo,
                hi,
            )
        out = torch.zeros((len(envs), *(self.grid,) * 3), dtype=torch.bool, device=self.device)
        lo_np, hi_np = lo.cpu().numpy(), hi.cpu().numpy()
        for i, env in enumerate(envs.tolist()):
            _, sections, hull = self.episode(env)
            box = Box(tuple(int(v) for v in lo_np[i]), tuple(int(v) for v in hi_np[i]))  # type: ignore[arg-type]
            voxels = part_surface_voxels(sections, hull, box)
            out[(i, *box.slices)] = torch.from_numpy(voxels).to(self.device)
        return out

    # -- transition -----------------------------------------------------------------------
    def step(self, actions: torch.Tensor | ArrayLike) -> EnvStep:
        """Apply one action per episode.

        Parameters
        ----------
        actions : Tensor or ndarray of shape (B, 5)
            ``(x1, y1, x2, y2, c)``; values are clipped to ``[0, 1]``.

        Returns
        -------
        EnvStep
        """
        act = torch.as_tensor(actions).detach().cpu().numpy().astype(np.float64)
        if act.shape != (self.n_envs, 5):
            raise OptionError(
                f"actions must have shape ({self.n_envs}, 5) (got {tuple(act.shape)})"
            )
        b, g, dev = self.n_envs, self.grid, self.device
        # The rules (numpy, all episodes at once): snap, sides of the line.
        cuts = snap_actions(act, self.corner_px, self.corner_valid, self.image_shapes)
        sides = torch.from_numpy(line_sides(cuts.p1, cuts.p2, (g, g))).to(dev)
        view = torch.from_numpy(cuts.view).to(dev)
        # Voxel counts on the device, the choice of side by the rules.
        counts = self._column_counts(view)
        n_side = (
            torch.stack(
                [(counts * (sides > 0)).sum(dim=(1, 2)), (counts * (sides < 0)).sum(dim=(1, 2))]
            )
            .cpu()
            .numpy()
        )
        keep, removes_nothing = choose_sides(n_side[0], n_side[1])
        noop = cuts.degenerate | removes_nothing
        keep = np.where(noop, _NO_SIDE, keep).astype(np.int8)
        chosen = sides == torch.from_numpy(keep).to(dev)[:, None, None]
        w = self.remaining & self._extrude(chosen, view)
        # The part's box and reconstruction; the reward's counts.
        lo, hi = self._boxes(w)
        parts = torch.from_numpy(np.flatnonzero(~noop)).to(dev)
        s = torch.zeros_like(w)
        if parts.numel():
            s[parts] = self._reconstruct(parts, lo[parts], hi[parts])
        sums = (
            torch.stack(
                [w.sum(dim=(1, 2, 3)), (s & w).sum(dim=(1, 2, 3)), (s | w).sum(dim=(1, 2, 3))]
            )
            .cpu()
            .numpy()
        )
        iou_part = count_iou(sums[0], self.n_occupied)
        iou_rec = count_iou(sums[1], sums[2])
        if self.reward_kind == "gain":
            after = self.potential.copy()
            if parts.numel():
                after[~noop] = self._potentials(
                    parts, self.remaining[parts] & ~w[parts], self.recon[parts] | s[parts]
                )
            reward = np.where(noop, NOOP_REWARD, gain_rewards(self.potential, after))
            self.potential = after
        else:
            reward = np.where(noop, NOOP_REWARD, part_rewards(iou_part, iou_rec, lam=self.lam))
        self.last_step = StepRecord(
            cuts,
            removes_nothing,
            noop,
            w,
            lo.cpu().numpy(),
            hi.cpu().numpy(),
            np.where(noop, np.nan, iou_part),
            np.where(noop, np.nan, iou_rec),
            reward,
        )
        # Bookkeeping and the end of episodes (the rules again).
        self.remaining = self.remaining & ~w
        self.recon = self.recon | s
        self._steps += 1
        self.returns += reward
        self.n_parts += ~noop
        left = self.remaining.sum(dim=(1, 2, 3)).cpu().numpy()
        done = episode_done(
            left,
            self.n_occupied,
            self._steps,
            max_steps=self.max_steps,
            min_remaining=self.min_remaining,
        )
        ended = [int(e) for e in np.flatnonzero(done)]
        episode_return = np.full(b, np.nan)
        final_iou = np.full(b, np.nan)
        n_parts = np.zeros(b, dtype=np.int64)
        if ended:
            final_iou[ended], n_parts[ended] = self._finish(ended)
            episode_return[ended] = self.returns[ended]
            self._start(ended, [self._draw(e, None) for e in ended])
        changed = [int(e) for e in np.flatnonzero(~noop & ~done)]
        self._refresh_corners(changed, force=False)
        return EnvStep(
            self.observation(),
            torch.from_numpy(reward.astype(np.float32)).to(dev),
            torch.from_numpy(done).to(dev),
            torch.from_numpy(noop).to(dev),
            torch.from_numpy(episode_return.astype(np.float32)).to(dev),
            torch.from_numpy(final_iou.astype(np.float32)).to(dev),
            torch.from_numpy(n_parts).to(dev),
        )

    def _potentials(
        self, envs: torch.Tensor, remaining: torch.Tensor, recon: torch.Tensor
    ) -> NDArray[np.float64]:
        """IoU with ``O`` of ``recon`` and the remaining region's reconstruction as one part.

        ``Phi`` of :data:`~slicerecon.partition.state.REWARD_KINDS` for episodes
        ``envs`` (n,), given their remaining regions and parts' union (n, G, G, G).
        """
        lo, hi = self._boxes(remaining)
        left = remaining.flatten(1).any(dim=1)
        union = recon.clone()
        rows = torch.nonzero(left).flatten()
        if rows.numel():
            union[rows] |= self._reconstruct(envs[rows], lo[rows], hi[rows])
        occ = self.occupancy[envs]
        sums = (
            torch.stack([(union & occ).sum(dim=(1, 2, 3)), (union | occ).sum(dim=(1, 2, 3))])
            .cpu()
            .numpy()
        )
        return count_iou(sums[0], sums[1])

    def _finish(self, envs: list[int]) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
        """IoU of ``∪ S_i`` with ``O`` for ended episodes, the leftover region a last part."""
        idx = torch.tensor(envs, device=self.device)
        rem = self.remaining[idx]
        left = rem.flatten(1).any(dim=1).cpu().numpy()
        if self.reward_kind == "gain":  # the potential is that IoU already
            return self.potential[envs].copy(), self.n_parts[envs] + left
        return self._potentials(idx, rem, self.recon[idx]), self.n_parts[envs] + left
