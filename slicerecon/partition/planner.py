"""Partition planners: turn an occupancy grid into cuboid parts (``plan.json``).

A planner is a :class:`PlannerEntry` in :data:`PLANNERS`, a literal registry
complete at import (as trimesh's engines): its function and its capabilities;
:func:`plan_partition` looks it up by name and behaviour follows the entry's
capabilities, never its name. ``"none"`` is the paper's no-projection baseline
(one part, the bounding box of the shape); ``"heuristic"`` runs the heuristic
expert to the end of an episode; ``"lookahead"`` checks the expert by a
one-step lookahead. The learned planner ``"policy"`` is listed by the name of
its function (``"slicerecon.policy.planner:plan_policy"``), imported with torch
only when it first runs: this package imports nothing of the policy package.

Add a planner by adding its entry to :data:`PLANNERS` (``docs/architecture.md``).
"""

from __future__ import annotations

import importlib
import logging
import os
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import InputError, OptionError
from ..sampling import pool_any
from ..sections import Box
from .cuts import Cut
from .heuristic import run_expert
from .lookahead import PlanningSurface, plan_lookahead
from .state import Part, PartitionState, Reconstruct

__all__ = [
    "PLANNERS",
    "Plan",
    "PlanPart",
    "PlannerEntry",
    "plan_partition",
    "planner_entry",
    "planner_names",
]

logger = logging.getLogger(__name__)


class PlanPart(NamedTuple):
    """One part of a plan.

    Attributes
    ----------
    box : Box
        Voxel box (reconstruction domain of the part).
    cut : Cut or None
        The cut that separated the part; None for a leftover or single part.
    voxels : int
        Voxels of the occupancy the part took.
    """

    box: Box
    cut: Cut | None
    voxels: int


def _box_corners_mm(box: Box, affine: NDArray[np.float64]) -> list[list[float]]:
    lo = np.asarray(box.lo, dtype=np.float64) - 0.5
    hi = np.asarray(box.hi, dtype=np.float64) - 0.5
    ijk = np.array([[(lo, hi)[s][ax] for ax, s in enumerate(bits)] for bits in np.ndindex(2, 2, 2)])
    world = ijk @ affine[:3, :3].T + affine[:3, 3]
    return world.tolist()


@dataclass(frozen=True)
class Plan:
    """The cuboid parts a planner chose.

    Parameters
    ----------
    planner : str
        Name of the planner that made it.
    parts : tuple of PlanPart
        The parts in the order they were cut; their boxes cover the occupancy.
    grid_shape : tuple of int
        ``(I, J, K)`` of the grid the boxes index.
    """

    planner: str
    parts: tuple[PlanPart, ...]
    grid_shape: tuple[int, int, int]

    @property
    def boxes(self) -> tuple[Box, ...]:
        """The parts' boxes."""
        return tuple(p.box for p in self.parts)

    def covers(self, occupancy: ArrayLike) -> bool:
        """Whether every foreground voxel of ``occupancy`` lies in some part's box."""
        occ = np.asarray(occupancy, dtype=bool)
        covered = np.zeros(occ.shape, dtype=bool)
        for box in self.boxes:
            covered[box.slices] = True
        return bool(not np.any(occ & ~covered))

    def to_dict(self, affine: ArrayLike | None = None) -> dict[str, Any]:
        """JSON-ready form for ``plan.json``.

        Parameters
        ----------
        affine : ndarray of shape (4, 4), optional
            Voxel→world affine; when given, each part also has ``"corners_mm"``
            (the 8 corners of its box, ``[lo - .5, hi - .5]`` in index space,
            mapped to world mm, in ``np.ndindex(2, 2, 2)`` order) and
            ``"min_mm"``/``"max_mm"`` (their world-axis-aligned extent).

        Returns
        -------
        dict
            ``{"planner", "grid_shape", "parts": [{"box": {"lo", "hi"}, "cut",
            "voxels", ...}]}``; boxes in voxel indices with ``hi`` exclusive,
            cuts in pixel coordinates of their view (or null).
        """
        aff = None if affine is None else np.asarray(affine, dtype=np.float64)
        if aff is not None and aff.shape != (4, 4):
            raise OptionError(f"affine must be a 4x4 matrix (got shape {aff.shape})")
        parts = []
        for part in self.parts:
            entry: dict[str, Any] = {
                "box": part.box.to_dict(),
                "cut": None if part.cut is None else part.cut.to_dict(),
                "voxels": int(part.voxels),
            }
            if aff is not None:
                corners = _box_corners_mm(part.box, aff)
                entry["corners_mm"] = corners
                entry["min_mm"] = np.min(corners, axis=0).tolist()
                entry["max_mm"] = np.max(corners, axis=0).tolist()
            parts.append(entry)
        return {"planner": self.planner, "grid_shape": list(self.grid_shape), "parts": parts}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Plan:
        """Inverse of :meth:`to_dict` (world-mm fields are ignored)."""
        try:
            parts = tuple(
                PlanPart(
                    Box(tuple(p["box"]["lo"]), tuple(p["box"]["hi"])),
                    None if p["cut"] is None else Cut.from_dict(p["cut"]),
                    int(p["voxels"]),
                )
                for p in data["parts"]
            )
            shape = tuple(int(s) for s in data["grid_shape"])
            return cls(str(data["planner"]), parts, shape)  # type: ignore[arg-type]
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(
                f"not a plan record ({exc}); expected the output of Plan.to_dict"
            ) from exc


SurfaceFactory = Callable[[int], PlanningSurface]
"""``surface(factor) -> PlanningSurface``: the sections, hull and part surface on the
planning grid, the occupancy's grid pooled ``factor`` times (1: the grid itself);
what the planners that need a surface score their choices on."""

PlannerFn = Callable[..., list[Part]]
"""``planner(occupancy, *, reconstruct, max_parts, min_remaining, lam) -> list of Part``."""


def _plan_none(
    occupancy: NDArray[np.bool_],
    *,
    reconstruct: Reconstruct | None,
    max_parts: int,
    min_remaining: float,
    lam: float,
) -> list[Part]:
    """One part: the bounding box of the whole occupancy (the no-projection baseline)."""
    state = PartitionState(occupancy, reconstruct=reconstruct, lam=lam, max_steps=0)
    return state.finish()


def _plan_heuristic(
    occupancy: NDArray[np.bool_],
    *,
    reconstruct: Reconstruct | None,
    max_parts: int,
    min_remaining: float,
    lam: float,
) -> list[Part]:
    """Apply the expert's best cut until the episode ends or no cut is useful, then finish."""
    state = PartitionState(
        occupancy,
        reconstruct=reconstruct,
        lam=lam,
        max_steps=max_parts - 1,
        min_remaining=min_remaining,
    )
    return run_expert(state).finish()


@dataclass(frozen=True)
class PlannerEntry:
    """A registered planner and what it needs.

    Attributes
    ----------
    name : str
        The ``--planner`` value.
    plan : callable or str
        ``plan(occupancy, *, reconstruct, max_parts, min_remaining, lam, **options)
        -> list of Part``, or ``"module:function"`` naming it: imported on first
        use (:meth:`load`), so that an entry whose function needs torch costs
        nothing until it runs.
    partitions : bool
        Whether it may make more than one part (False for the one-part baseline).
    needs_torch : bool
        Whether running it imports torch.
    takes_weights : bool
        Whether it accepts ``weights=`` (a trained actor).
    needs_surface : bool
        Whether it scores its choices on reconstructions: it is called with
        ``surface=`` (a :class:`~slicerecon.partition.lookahead.PlanningSurface`
        on the grid it plans on) and ``reconstruct=None``.
    summary : str
        One line for help texts.
    """

    name: str
    plan: PlannerFn | str
    partitions: bool = True
    needs_torch: bool = False
    takes_weights: bool = False
    needs_surface: bool = False
    summary: str = ""

    def load(self) -> PlannerFn:
        """The planner function (imported now when :attr:`plan` names it)."""
        if callable(self.plan):
            return self.plan
        module, _, name = self.plan.partition(":")
        return getattr(importlib.import_module(module), name)  # type: ignore[no-any-return]

    def __call__(self, occupancy: NDArray[np.bool_], **options: Any) -> list[Part]:
        return self.load()(occupancy, **options)


PLANNERS: dict[str, PlannerEntry] = {
    "none": PlannerEntry(
        "none", _plan_none, partitions=False, summary="one part: the no-projection baseline"
    ),
    "heuristic": PlannerEntry("heuristic", _plan_heuristic, summary="the paper's heuristic expert"),
    "lookahead": PlannerEntry(
        "lookahead",
        plan_lookahead,
        needs_surface=True,
        summary="the heuristic expert with a one-step lookahead scored on held-out planes",
    ),
    "policy": PlannerEntry(
        "policy",
        "slicerecon.policy.planner:plan_policy",
        needs_torch=True,
        takes_weights=True,
        summary="a trained actor (docs/policy.md)",
    ),
}
"""Every planner by name, with its capabilities (:class:`PlannerEntry`)."""


def planner_entry(name: str) -> PlannerEntry:
    """The registry entry of ``name``.

    Raises
    ------
    OptionError
        For an unknown name (the message lists the registered ones).
    """
    key = str(name).strip().lower()
    if key not in PLANNERS:
        raise OptionError(f"unknown planner {name!r}; choose one of: {', '.join(planner_names())}")
    found = PLANNERS[key]
    return found if isinstance(found, PlannerEntry) else PlannerEntry(key, found)


def planner_names() -> list[str]:
    """Names accepted by :func:`plan_partition`, sorted."""
    return sorted(PLANNERS)


def plan_partition(
    occupancy: ArrayLike,
    *,
    planner: str = "heuristic",
    reconstruct: Reconstruct | None = None,
    max_parts: int = 8,
    min_remaining: float = 0.02,
    lam: float = 1.0,
    weights: str | os.PathLike[str] | None = None,
    max_grid: int | None = None,
    surface: SurfaceFactory | None = None,
) -> Plan:
    """Partition an occupancy grid into cuboid parts.

    Parameters
    ----------
    occupancy : ndarray of shape (I, J, K), bool
        The shape (ground truth, or the visual hull of the projections).
    planner : str, optional
        A name in :data:`PLANNERS`: ``"none"``, ``"heuristic"`` or ``"policy"``
        (the learned planner; needs torch).
    reconstruct : callable, optional
        ``reconstruct(box) -> bool array of box.shape``, used for the reward's
        reconstruction term (see :class:`~slicerecon.partition.state.PartitionState`).
    max_parts : int, optional
        At most this many parts (``max_parts - 1`` cuts plus the leftover part).
    min_remaining : float, optional
        Stop cutting when fewer than this fraction of the voxels remain.
    lam : float, optional
        Reward weight of the reconstruction term.
    weights : path-like, optional
        Actor weights of the ``"policy"`` planner (default: the shipped
        ``il_rl`` actor); an error for the other planners.
    max_grid : int, optional
        Plan on a coarser copy of the occupancy when its longest side exceeds
        this many voxels: blocks of ``f = ceil(longest / max_grid)`` voxels per
        side are pooled (a block is occupied when any voxel is), the planner
        runs there, and each part's box is mapped back and tightened around
        the occupancy it holds (:func:`_refine`). The boxes still cover the
        occupancy; cut positions are known to ``f`` voxels. Planning cost falls
        by about ``f³``; grids no larger than ``max_grid`` are planned as they are.
    surface : callable, optional
        :data:`SurfaceFactory`, for the planners that score their choices on
        reconstructions (``PlannerEntry.needs_surface``, e.g. ``"lookahead"``);
        called once with the pooling factor.

    Returns
    -------
    Plan
        Parts whose boxes cover every voxel of ``occupancy``.

    Raises
    ------
    OptionError
        For an unknown planner name, ``max_parts < 1``, or a planner that needs
        a surface without ``surface`` (or with ``reconstruct`` as well).
    EmptyMaskError
        If the occupancy is empty.
    """
    entry = planner_entry(planner)
    name = entry.name
    if isinstance(max_parts, bool) or int(max_parts) < 1:
        raise OptionError(f"max_parts must be >= 1 (got {max_parts})")
    if weights is not None and not entry.takes_weights:
        raise OptionError(f"weights apply to the policy planner only (planner is {name!r})")
    occ = np.asarray(occupancy)
    options: dict[str, Any] = {} if weights is None else {"weights": weights}
    factor = 1
    if max_grid is not None:
        if isinstance(max_grid, bool) or int(max_grid) < 8:
            raise OptionError(f"max_grid must be at least 8 voxels (got {max_grid})")
        factor = max(1, -(-max(occ.shape) // int(max_grid)))
    if entry.needs_surface:
        if surface is None or reconstruct is not None:
            raise OptionError(
                f"planner {name!r} scores its choices on reconstructions: give surface= "
                "(and no reconstruct=)"
            )
        options["surface"] = surface(factor)
    if factor > 1:
        if reconstruct is not None:
            raise OptionError("a reward reconstruction needs the full grid: give max_grid=None")
        coarse = pool_any(occ.astype(bool, copy=False), factor)
        parts = entry(
            coarse,
            reconstruct=None,
            max_parts=int(max_parts),
            min_remaining=float(min_remaining),
            lam=float(lam),
            **options,
        )
        shape = tuple(int(s) for s in occ.shape)
        refined = _refine(parts, occ.astype(bool, copy=False), factor)
        plan = Plan(name, refined, shape)  # type: ignore[arg-type]
        logger.info("planner %s on a %dx coarser grid: %d parts", name, factor, len(plan.parts))
        return plan
    parts = entry(
        occ,
        reconstruct=reconstruct,
        max_parts=int(max_parts),
        min_remaining=float(min_remaining),
        lam=float(lam),
        **options,
    )
    shape = tuple(int(s) for s in occ.shape)
    plan = Plan(name, tuple(PlanPart(p.box, p.cut, p.mask_voxels) for p in parts), shape)  # type: ignore[arg-type]
    logger.info("planner %s: %d parts", name, len(plan.parts))
    return plan


def _refine(parts: list[Part], occupancy: NDArray[np.bool_], factor: int) -> tuple[PlanPart, ...]:
    """Parts planned on a pooled grid, back on the full grid.

    Each box is scaled by ``factor``, clipped to the grid and tightened to the
    bounding box of the occupancy it holds that no earlier part took; cut end
    points go to the centre of their pooled pixel. Every occupied voxel lies in
    the scaled box of a part that took its block, so the boxes still cover the
    occupancy.
    """
    shape = occupancy.shape
    taken = np.zeros(shape, dtype=bool)
    out: list[PlanPart] = []
    for part in parts:
        lo = [min(v * factor, n) for v, n in zip(part.box.lo, shape, strict=True)]
        hi = [min(v * factor, n) for v, n in zip(part.box.hi, shape, strict=True)]
        region = tuple(slice(a, b) for a, b in zip(lo, hi, strict=True))
        own = occupancy[region] & ~taken[region]
        if not own.any():
            continue
        tight = Box.of_mask(own)
        box = Box(
            tuple(a + t for a, t in zip(lo, tight.lo, strict=True)),  # type: ignore[arg-type]
            tuple(a + t for a, t in zip(lo, tight.hi, strict=True)),
        )  # type: ignore[arg-type]
        taken[region] |= own
        cut = part.cut
        if cut is not None:
            half = (factor - 1) / 2.0
            cut = Cut(
                cut.view,
                tuple(v * factor + half for v in cut.p1),  # type: ignore[arg-type]
                tuple(v * factor + half for v in cut.p2),
            )  # type: ignore[arg-type]
        out.append(PlanPart(box, cut, int(np.count_nonzero(own))))
    return tuple(out)
