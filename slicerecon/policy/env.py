"""The cut environment in torch: many partition episodes stepped at once.

:class:`CutEnv` runs ``B`` episodes of the partition process of
:class:`~slicerecon.partition.state.PartitionState` side by side, with the voxel
work (cuts, part boxes, rewards, the reconstruction surrogate) done on torch
tensors on the CPU or a GPU. The rules are those of
:mod:`slicerecon.partition.cuts` and :mod:`slicerecon.partition.state`
(``docs/method.md``):

* an action ``(x1, y1, x2, y2, c)`` in ``[0, 1]`` picks view
  ``min(int(3 c), 2)`` and two points snapped to the nearest corner of that
  view (ties to the first corner in ``(row, col)`` order);
* the infinite line through the two corners, extruded along the view axis,
  splits the remaining region; the strictly smaller open side is the part
  ``W_i`` (equal counts: the ``+1`` side), voxels on the line stay;
* a cut whose view has no corner, whose ends snap to the same corner, or whose
  line leaves one side empty is a no-op (reward
  :data:`~slicerecon.partition.state.NOOP_REWARD`; the step still counts);
* ``R_i = IoU(W_i, O) + lam * IoU(S_i, W_i)``; the episode ends after
  ``max_steps`` steps or when fewer than ``min_remaining * |O|`` voxels remain.

Corners are computed with the library's numpy
:func:`~slicerecon.corners.harris_corners` (on the CPU, only for episodes whose
remaining region changed), so snapping is exactly the numpy planner's.

Reconstruction surrogate ``S_i``
--------------------------------
The planner's reward needs a cheap voxel reconstruction of a part from the
cross-sections inside its box. The library's
:func:`~slicerecon.surface.part.part_voxels` linearly blends the planes'
signed distance fields; here each episode keeps ``P`` planes of ``O``
perpendicular to grid axis z (evenly spaced from the first to the last occupied
plane, :func:`~slicerecon.sampling.evenly_spaced_planes`) and ``S_i`` is the
*nearest-plane* extrusion: voxel ``(x, y, z)`` of the box copies ``O[x, y, p]``
where ``p`` is the kept plane inside the box nearest to ``z`` (ties to the lower
plane), or the nearest kept plane overall when the box holds none. This is the
zeroth-order version of the SDF blend (the same on the planes, a step instead
of a ramp between them, the same prism extension to the box faces).
:func:`nearest_plane_voxels` is the numpy reference of the same rule.

Observations
------------
:class:`Observation`: the three silhouettes of the remaining region resized to
``R x R`` (:func:`resize_views`), the step ``t / max_steps``, and per view the
``K`` strongest corners normalised to ``[0, 1]``
(:func:`~slicerecon.corners.pad_corners`) with a validity mask. Grids are
cubes (``G^3``; shapes are centred in them, :func:`fit_to_cube`), so the three
views share one size.
"""

from __future__ import annotations

import logging
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import torch
import torch.nn.functional as F
from numpy.typing import ArrayLike, NDArray

from ..corners import harris_corners
from ..errors import EmptyMaskError, InputError, OptionError
from ..partition.heuristic import expert_action
from ..partition.state import NOOP_REWARD, PartitionState
from ..sampling import evenly_spaced_planes
from ..sections import Box

__all__ = [
    "Observation",
    "EnvStep",
    "ShapePool",
    "CutEnv",
    "resize_views",
    "fit_to_cube",
    "shape_occupancy",
    "section_planes",
    "nearest_plane_voxels",
    "observe_state",
]

logger = logging.getLogger(__name__)

_SECTION_AXIS = 2
"""Grid axis the surrogate's section planes are perpendicular to (z)."""


class Observation(NamedTuple):
    """A batch of policy states.

    Attributes
    ----------
    views : Tensor of shape (B, 3, R, R), float32
        Silhouettes of the remaining region in ``[0, 1]`` (view ``a`` along grid axis ``a``).
    step : Tensor of shape (B, 1), float32
        ``step_count / max_steps``.
    corners : Tensor of shape (B, 3, K, 2), float32
        Corner points per view, ``((row + .5) / M, (col + .5) / N)``; invalid rows 0.
    corner_mask : Tensor of shape (B, 3, K), float32
        1 for the rows that hold a corner.
    """

    views: torch.Tensor
    step: torch.Tensor
    corners: torch.Tensor
    corner_mask: torch.Tensor

    def to(self, device: torch.device | str) -> Observation:
        """The same observation on ``device``."""
        return Observation(*(t.to(device) for t in self))

    def select(self, idx: torch.Tensor | slice) -> Observation:
        """Rows ``idx`` of every field."""
        return Observation(*(t[idx] for t in self))

    @staticmethod
    def cat(parts: Sequence[Observation]) -> Observation:
        """Concatenate batches along the first axis."""
        return Observation(*(torch.cat(fields) for fields in zip(*parts, strict=True)))


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
        parts' surrogates ``S_i``, the leftover region counted as a last part
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


# -- shapes -----------------------------------------------------------------------------
def fit_to_cube(mask: ArrayLike, size: int) -> NDArray[np.bool_]:
    """Centre a 3-D mask's foreground in a ``size^3`` grid.

    Parameters
    ----------
    mask : ndarray of shape (I, J, K), bool
    size : int
        Side of the cube, voxels; must hold the foreground's bounding box.

    Returns
    -------
    ndarray of shape (size, size, size), bool
        The foreground, shifted so that its bounding box is centred (rounded down).
    """
    arr = np.asarray(mask, dtype=bool)
    if arr.ndim != 3:
        raise InputError(f"mask must be 3-D (got shape {arr.shape})")
    if not arr.any():
        raise EmptyMaskError("the mask is empty: nothing to place in the grid")
    box = Box.of_mask(arr)
    if max(box.shape) > size:
        raise OptionError(f"the shape's bounding box {box.shape} does not fit a {size}^3 grid")
    out = np.zeros((size, size, size), dtype=bool)
    lo = [(size - s) // 2 for s in box.shape]
    dst = tuple(slice(a, a + s) for a, s in zip(lo, box.shape, strict=True))
    out[dst] = arr[box.slices]
    return out


def shape_occupancy(name: str, *, seed: int, grid: int, margin: int = 1) -> NDArray[np.bool_]:
    """A seeded procedural shape (:func:`slicerecon.shapes.make_shape`) scaled into ``grid^3``.

    The voxel size is chosen so that the shape's longest side spans
    ``grid - 2 * margin`` voxels; the shape is then centred (:func:`fit_to_cube`).

    Parameters
    ----------
    name : str
        A registered shape family (:func:`slicerecon.shapes.shape_names`).
    seed : int
        Seed of the shape's random proportions.
    grid : int
        Side of the cubic grid, voxels.
    margin : int, optional
        Empty voxels kept on each side.

    Returns
    -------
    ndarray of shape (grid, grid, grid), bool
    """
    from ..shapes import make_shape

    inner = int(grid) - 2 * int(margin)
    if inner < 4:
        raise OptionError(f"grid {grid} is too small for margin {margin}")
    coarse = make_shape(name, seed=seed, spacing=2.0, margin=0)
    lo, hi = coarse.bounding_box_vox()
    extent_mm = float(np.max((hi - lo) * coarse.spacing))
    spacing = extent_mm / inner
    for _ in range(20):
        vol = make_shape(name, seed=seed, spacing=spacing, margin=0)
        lo, hi = vol.bounding_box_vox()
        if int(np.max(hi - lo)) <= inner:
            return fit_to_cube(vol.mask, int(grid))
        spacing *= 1.03
    raise OptionError(f"could not fit shape {name!r} (seed {seed}) into a {grid}^3 grid")


def section_planes(occupancy: ArrayLike, n: int) -> NDArray[np.int64]:
    """``n`` z-planes evenly spaced over the occupied z-range (fewer if the range is short)."""
    occ = np.asarray(occupancy, dtype=bool)
    planes = np.flatnonzero(occ.any(axis=(0, 1)))
    if planes.size == 0:
        raise EmptyMaskError("the occupancy is empty")
    first, last = int(planes[0]), int(planes[-1])
    count = min(int(n), last - first + 1)
    if count < 2:
        return np.array([first], dtype=np.int64)
    return evenly_spaced_planes(first, last, count)


def nearest_plane_voxels(
    occupancy: ArrayLike, planes: ArrayLike, box: Box
) -> NDArray[np.bool_]:
    """Numpy reference of the environment's reconstruction surrogate ``S_i``.

    Parameters
    ----------
    occupancy : ndarray of shape (I, J, K), bool
        The shape ``O`` whose z-planes are the cross-sections.
    planes : ndarray of shape (P,), int
        Kept z-plane indices, increasing.
    box : Box
        The part's box.

    Returns
    -------
    ndarray of shape box.shape, bool
        Voxel ``(x, y, z)`` is ``O[x, y, p]`` with ``p`` the kept plane inside the
        box nearest to ``z`` (ties to the lower one), or the nearest kept plane
        overall when none lies inside the box.
    """
    occ = np.asarray(occupancy, dtype=bool)
    kept = np.asarray(planes, dtype=np.int64).reshape(-1)
    if kept.size == 0:
        raise OptionError("give at least one section plane")
    lo, hi = box.lo[_SECTION_AXIS], box.hi[_SECTION_AXIS]
    inside = kept[(kept >= lo) & (kept < hi)]
    candidates = inside if inside.size else kept
    z = np.arange(lo, hi)
    nearest = candidates[np.argmin(np.abs(z[:, None] - candidates[None, :]), axis=1)]
    return occ[box.slices[0], box.slices[1], :][:, :, nearest]


@dataclass(frozen=True)
class ShapePool:
    """Occupancy grids an environment draws its episodes from.

    Attributes
    ----------
    occupancies : ndarray of shape (N, G, G, G), bool
    names : tuple of str
        Shape family of each grid.
    seeds : tuple of int
        Seed of each grid's proportions.
    """

    occupancies: NDArray[np.bool_]
    names: tuple[str, ...]
    seeds: tuple[int, ...]

    @classmethod
    def build(
        cls, names: Sequence[str], seeds: Sequence[int], *, grid: int
    ) -> ShapePool:
        """Every family in ``names`` with every seed in ``seeds``, on a ``grid^3`` cube."""
        if not names or not seeds:
            raise OptionError("a shape pool needs at least one family and one seed")
        grids, out_names, out_seeds = [], [], []
        for name in names:
            for seed in seeds:
                grids.append(shape_occupancy(name, seed=int(seed), grid=grid))
                out_names.append(str(name))
                out_seeds.append(int(seed))
        logger.info("shape pool: %d grids of %d^3", len(grids), grid)
        return cls(np.stack(grids), tuple(out_names), tuple(out_seeds))

    def __len__(self) -> int:
        return int(self.occupancies.shape[0])

    @property
    def grid(self) -> int:
        """Side ``G`` of the cubic grids."""
        return int(self.occupancies.shape[1])


# -- observation helpers ----------------------------------------------------------------
def resize_views(images: torch.Tensor, resolution: int) -> torch.Tensor:
    """Resize silhouettes to ``resolution x resolution`` (antialiased bilinear).

    Parameters
    ----------
    images : Tensor of shape (B, M, N), bool or float
    resolution : int

    Returns
    -------
    Tensor of shape (B, R, R), float32 in [0, 1]
    """
    x = images.to(torch.float32).unsqueeze(1)
    if tuple(x.shape[-2:]) != (resolution, resolution):
        x = F.interpolate(
            x, size=(resolution, resolution), mode="bilinear", align_corners=False,
            antialias=True,
        )
    return x.squeeze(1).clamp_(0.0, 1.0)


_CORNER_CACHE: OrderedDict[tuple[bytes, tuple[int, ...], int], NDArray[np.float64]] = (
    OrderedDict()
)
_CORNER_CACHE_SIZE = 8192


def _cached_corners(image: NDArray[np.bool_], k: int) -> NDArray[np.float64]:
    """:func:`harris_corners` memoised on the silhouette's bits (episodes repeat shapes)."""
    key = (np.packbits(image).tobytes(), image.shape, k)
    hit = _CORNER_CACHE.get(key)
    if hit is not None:
        _CORNER_CACHE.move_to_end(key)
        return hit
    corners = harris_corners(image, max_corners=k)[:k]
    corners.setflags(write=False)
    _CORNER_CACHE[key] = corners
    if len(_CORNER_CACHE) > _CORNER_CACHE_SIZE:
        _CORNER_CACHE.popitem(last=False)
    return corners


def _padded_corner_array(
    views: Sequence[NDArray[np.bool_]], k: int
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Pixel-coordinate corners (V, K, 2) and validity (V, K) of V silhouettes."""
    pts = np.zeros((len(views), k, 2), dtype=np.float64)
    valid = np.zeros((len(views), k), dtype=bool)
    for v, img in enumerate(views):
        c = _cached_corners(np.asarray(img, dtype=bool), k)
        pts[v, : len(c)] = c
        valid[v, : len(c)] = True
    return pts, valid


# -- environment ------------------------------------------------------------------------
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
        ``(min, max)`` number of section planes of the surrogate ``S_i``,
        drawn per episode.
    augment : bool, optional
        Randomly permute and flip the grid axes of each drawn shape.
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
        self.pool = pool
        self.n_envs = int(n_envs)
        self.grid = pool.grid
        self.resolution = int(resolution)
        self.max_corners = int(max_corners)
        self.max_steps = int(max_steps)
        self.min_remaining = float(min_remaining)
        self.lam = float(lam)
        self.planes = (lo_p, hi_p)
        self.augment = bool(augment)
        self.device = torch.device(device)
        self.rng = np.random.default_rng(seed)
        b, g = self.n_envs, self.grid
        self.occupancy = torch.zeros((b, g, g, g), dtype=torch.bool, device=self.device)
        self.remaining = torch.zeros_like(self.occupancy)
        self.recon = torch.zeros_like(self.occupancy)
        self.n_occupied = torch.ones(b, dtype=torch.float64, device=self.device)
        self.step_count = torch.zeros(b, dtype=torch.int64, device=self.device)
        self.returns = torch.zeros(b, dtype=torch.float64, device=self.device)
        self.n_parts = torch.zeros(b, dtype=torch.int64, device=self.device)
        p_max = hi_p
        self.plane_index = torch.zeros((b, p_max), dtype=torch.int64, device=self.device)
        self.plane_valid = torch.zeros((b, p_max), dtype=torch.bool, device=self.device)
        self.corner_px = torch.zeros((b, 3, self.max_corners, 2), dtype=torch.float64,
                                     device=self.device)
        self.corner_valid = torch.zeros((b, 3, self.max_corners), dtype=torch.bool,
                                        device=self.device)
        self._silhouettes = torch.zeros((b, 3, g, g), dtype=torch.bool, device=self.device)
        self.shape_id = np.zeros(b, dtype=np.int64)
        self._expert: list[NDArray[np.float64] | None | bool] = [False] * b
        self._arange = torch.arange(g, device=self.device)

    # -- episodes -------------------------------------------------------------------------
    def _draw(self, env: int, shape: int | None) -> NDArray[np.bool_]:
        idx = int(self.rng.integers(len(self.pool))) if shape is None else int(shape)
        self.shape_id[env] = idx
        occ = self.pool.occupancies[idx]
        if self.augment and shape is None:
            occ = np.transpose(occ, self.rng.permutation(3))
            flips = tuple(int(a) for a in np.flatnonzero(self.rng.random(3) < 0.5))
            if flips:
                occ = np.flip(occ, axis=flips)
        return np.ascontiguousarray(occ)

    def _start(
        self, envs: Sequence[int], occupancies: Sequence[NDArray[np.bool_]],
        n_planes: Sequence[int] | None = None,
    ) -> None:
        """Begin new episodes in ``envs`` on the given grids."""
        for i, (env, occ) in enumerate(zip(envs, occupancies, strict=True)):
            if n_planes is None:
                count = int(self.rng.integers(self.planes[0], self.planes[1] + 1))
            else:
                count = int(n_planes[i])
            planes = section_planes(occ, count)
            t = torch.from_numpy(occ).to(self.device)
            self.occupancy[env] = t
            self.remaining[env] = t
            self.recon[env] = False
            self.n_occupied[env] = float(np.count_nonzero(occ))
            self.step_count[env] = 0
            self.returns[env] = 0.0
            self.n_parts[env] = 0
            self.plane_valid[env] = False
            self.plane_index[env] = 0
            self.plane_index[env, : planes.size] = torch.from_numpy(planes).to(self.device)
            self.plane_valid[env, : planes.size] = True
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
            for v in np.flatnonzero(changed_np[i]):
                pts, valid = _padded_corner_array([sil_np[i, v]], self.max_corners)
                self.corner_px[env, v] = torch.from_numpy(pts[0]).to(self.device)
                self.corner_valid[env, v] = torch.from_numpy(valid[0]).to(self.device)

    def observation(self) -> Observation:
        """The current states."""
        b, g, r = self.n_envs, self.grid, self.resolution
        views = resize_views(self.silhouettes().reshape(b * 3, g, g), r).reshape(b, 3, r, r)
        step = (self.step_count.to(torch.float32) / self.max_steps).unsqueeze(1)
        corners = ((self.corner_px + 0.5) / g).clamp(0.0, 1.0)
        corners = corners * self.corner_valid.unsqueeze(-1)
        return Observation(
            views, step, corners.to(torch.float32), self.corner_valid.to(torch.float32)
        )

    def state_of(self, env: int) -> PartitionState:
        """A numpy :class:`PartitionState` whose remaining region is this episode's.

        Its occupancy is the remaining region (enough for the heuristic expert,
        which looks at the remaining region only); the corners are shared.
        """
        rem = self.remaining[env].cpu().numpy().copy()
        state = PartitionState(rem, max_corners=self.max_corners, max_steps=self.max_steps)
        valid = self.corner_valid[env].cpu().numpy()
        px = self.corner_px[env].cpu().numpy()
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

    # -- transition -----------------------------------------------------------------------
    def _snap(self, act: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor,
                                                torch.Tensor]:
        """View (B,), canonical end points p1, p2 (B, 2) and degenerate flags (B,)."""
        b = self.n_envs
        rows = torch.arange(b, device=self.device)
        view = torch.clamp((3.0 * act[:, 4]).floor().to(torch.int64), 0, 2)
        pts = self.corner_px[rows, view]  # (B, K, 2)
        valid = self.corner_valid[rows, view]  # (B, K)
        scale = float(self.grid)
        ends = []
        for t in (act[:, 0:2], act[:, 2:4]):
            target = t * scale - 0.5
            d2 = ((pts - target[:, None, :]) ** 2).sum(-1)
            d2 = torch.where(valid, d2, torch.full_like(d2, float("inf")))
            ends.append(torch.argmin(d2, dim=1))
        i1, i2 = ends
        degenerate = (~valid.any(dim=1)) | (i1 == i2)
        p1 = pts[rows, i1]
        p2 = pts[rows, i2]
        swap = (p1[:, 0] > p2[:, 0]) | ((p1[:, 0] == p2[:, 0]) & (p1[:, 1] > p2[:, 1]))
        q1 = torch.where(swap[:, None], p2, p1)
        q2 = torch.where(swap[:, None], p1, p2)
        return view, q1, q2, degenerate

    def _box_mask(self, mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Bounding boxes of masks (B, G, G, G): lo (B, 3), hi (B, 3), box mask (B, G, G, G)."""
        a = self._arange
        u = mask.view(torch.uint8)
        los, his, axes = [], [], []
        for dims in ((2, 3), (1, 3), (1, 2)):
            occ = u.amax(dim=dims[1]).amax(dim=dims[0]) > 0  # (B, G)
            big = torch.where(occ, a, torch.full_like(a, self.grid))
            small = torch.where(occ, a, torch.full_like(a, -1))
            lo = big.min(dim=1).values
            hi = small.max(dim=1).values + 1
            los.append(lo)
            his.append(hi)
            axes.append((a[None, :] >= lo[:, None]) & (a[None, :] < hi[:, None]))
        box = axes[0][:, :, None, None] & axes[1][:, None, :, None] & axes[2][:, None, None, :]
        return torch.stack(los, 1), torch.stack(his, 1), box

    def _surrogate(self, lo_z: torch.Tensor, hi_z: torch.Tensor, box: torch.Tensor
                   ) -> torch.Tensor:
        """``S`` of parts with z-range [lo_z, hi_z) and box mask ``box`` (B, G, G, G)."""
        planes, valid = self.plane_index, self.plane_valid
        inside = valid & (planes >= lo_z[:, None]) & (planes < hi_z[:, None])
        cand = torch.where(inside.any(dim=1, keepdim=True), inside, valid)
        z = self._arange
        dist = (z[None, :, None] - planes[:, None, :]).abs().to(torch.float32)
        dist = torch.where(cand[:, None, :], dist, torch.full_like(dist, float("inf")))
        nearest = torch.gather(planes, 1, dist.argmin(dim=2))  # (B, G)
        g = self.grid
        index = nearest[:, None, None, :].expand(-1, g, g, -1)
        return torch.gather(self.occupancy, 3, index) & box

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
        act = torch.as_tensor(actions, device=self.device).to(torch.float64)
        if act.shape != (self.n_envs, 5):
            raise OptionError(
                f"actions must have shape ({self.n_envs}, 5) (got {tuple(act.shape)})"
            )
        if not bool(torch.isfinite(act).all()):
            raise OptionError("actions hold NaN or infinite values")
        act = act.clamp(0.0, 1.0)
        view, p1, p2, degenerate = self._snap(act)
        g = self.grid
        centres = self._arange.to(torch.float64)
        rows = centres[None, :, None]
        cols = centres[None, None, :]
        r1, c1 = p1[:, 0, None, None], p1[:, 1, None, None]
        r2, c2 = p2[:, 0, None, None], p2[:, 1, None, None]
        side = torch.sign((r2 - r1) * (cols - c1) - (c2 - c1) * (rows - r1)).to(torch.int8)
        rem = self.remaining
        counts = torch.zeros((self.n_envs, g, g), dtype=torch.int64, device=self.device)
        for v in range(3):  # voxels per pixel of each episode's chosen view
            sel_v = view == v
            if bool(sel_v.any()):
                counts[sel_v] = rem[sel_v].sum(dim=v + 1)
        n_pos = (counts * (side > 0)).sum(dim=(1, 2))
        n_neg = (counts * (side < 0)).sum(dim=(1, 2))
        noop = degenerate | (n_pos == 0) | (n_neg == 0)
        keep = torch.where(n_pos <= n_neg, 1, -1).to(torch.int8)
        sel = side == keep[:, None, None]  # (B, G, G) in the view's (row, col)
        view4 = view[:, None, None, None]
        side3 = torch.where(
            view4 == 0,
            sel[:, None, :, :],
            torch.where(view4 == 1, sel[:, :, None, :], sel[:, :, :, None]),
        )
        w = rem & side3 & ~noop[:, None, None, None]
        lo, hi, box = self._box_mask(w)
        s = self._surrogate(lo[:, 2], hi[:, 2], box)
        w_count = w.sum(dim=(1, 2, 3)).to(torch.float64)
        inter = (s & w).sum(dim=(1, 2, 3)).to(torch.float64)
        union = (s | w).sum(dim=(1, 2, 3)).to(torch.float64)
        iou_rec = torch.where(union > 0, inter / union.clamp(min=1.0), torch.ones_like(union))
        reward = torch.where(
            noop, torch.full_like(w_count, NOOP_REWARD), w_count / self.n_occupied
            + self.lam * iou_rec
        )
        self.remaining = rem & ~w
        self.recon = self.recon | s
        self.step_count = self.step_count + 1
        self.returns = self.returns + reward
        self.n_parts = self.n_parts + (~noop).to(torch.int64)
        left = self.remaining.sum(dim=(1, 2, 3)).to(torch.float64)
        done = (left == 0) | (left < self.min_remaining * self.n_occupied) | (
            self.step_count >= self.max_steps
        )
        changed = torch.nonzero(~noop).flatten().tolist()
        ended = torch.nonzero(done).flatten().tolist()
        episode_return = torch.full((self.n_envs,), float("nan"), device=self.device)
        final_iou = torch.full((self.n_envs,), float("nan"), device=self.device)
        n_parts = torch.zeros(self.n_envs, dtype=torch.int64, device=self.device)
        if ended:
            iou, parts = self._finish(ended)
            final_iou[ended] = iou
            n_parts[ended] = parts
            episode_return[ended] = self.returns[ended].to(torch.float32)
            grids = [self._draw(e, None) for e in ended]
            self._start(ended, grids)
        self._refresh_corners([e for e in changed if e not in set(ended)], force=False)
        return EnvStep(
            self.observation(), reward.to(torch.float32), done, noop, episode_return,
            final_iou, n_parts,
        )

    def _finish(self, envs: list[int]) -> tuple[torch.Tensor, torch.Tensor]:
        """Surrogate IoU of ended episodes, the leftover region a last part."""
        rem = self.remaining
        left = rem.any(dim=(1, 2, 3))
        lo, hi, box = self._box_mask(rem)
        s = self._surrogate(lo[:, 2], hi[:, 2], box) & left[:, None, None, None]
        recon = (self.recon | s)[envs]
        occ = self.occupancy[envs]
        inter = (recon & occ).sum(dim=(1, 2, 3)).to(torch.float32)
        union = (recon | occ).sum(dim=(1, 2, 3)).to(torch.float32).clamp(min=1.0)
        return inter / union, self.n_parts[envs] + left[envs].to(torch.int64)


def observe_state(
    state: PartitionState, *, resolution: int, max_corners: int, max_steps: int,
    device: str | torch.device = "cpu",
) -> Observation:
    """The policy's observation of a numpy :class:`PartitionState` (batch of one).

    The same encoding as :meth:`CutEnv.observation`: silhouettes resized to
    ``resolution`` (:func:`resize_views`, each view on its own), the step over
    ``max_steps`` and the padded, normalised corners
    (:meth:`PartitionState.padded_corners`). ``state.max_corners`` should equal
    ``max_corners`` (the strongest corners are kept).
    """
    views = torch.stack(
        [resize_views(torch.from_numpy(np.ascontiguousarray(v))[None], resolution)[0]
         for v in state.projections()]
    )[None]
    pts, valid = state.padded_corners(int(max_corners))
    step = torch.tensor([[state.step_count / max(int(max_steps), 1)]], dtype=torch.float32)
    corners = torch.from_numpy(pts * valid[..., None]).to(torch.float32)[None]
    mask = torch.from_numpy(valid.astype(np.float32))[None]
    return Observation(views, step, corners, mask).to(device)
