"""The expert's one-step lookahead: never worse than the expert, and it stops when cutting hurts."""

from __future__ import annotations

import numpy as np
import pytest

from slicerecon.errors import InputError, OptionError
from slicerecon.partition.episodes import episode_sections, occupancy_hull, shape_occupancy
from slicerecon.partition.heuristic import expert_cut
from slicerecon.partition.lookahead import (
    LOOKAHEAD_VALUES,
    PlanningSurface,
    expert_value,
    held_out_value,
    lookahead_cut,
    plan_lookahead,
    run_lookahead,
    silhouette_value,
)
from slicerecon.partition.planner import plan_partition
from slicerecon.partition.state import PartitionState, iou
from slicerecon.policy.reward import episode_reconstruction, part_surface_voxels


def _episode(family: str, seed: int, planes: int = 8) -> PartitionState:
    occ = shape_occupancy(family, seed=seed, grid=24)
    recon, _, _ = episode_reconstruction(occ, planes)
    return PartitionState(occ, reconstruct=recon, reward="gain", max_steps=5, max_corners=12)


def _lookahead_episode(state: PartitionState, margin: float) -> float:
    return run_lookahead(state, candidates=3, margin=margin).potential()


@pytest.mark.parametrize(("family", "seed"), [("chair", 1), ("table", 2), ("lamp", 3), ("lung", 4)])
def test_lookahead_is_never_worse_than_the_expert(family: str, seed: int) -> None:
    """The rollout algorithm's guarantee, on whole episodes (margin 0 and the default)."""
    expert = expert_value(_episode(family, seed))
    for margin in (0.0, 0.002):
        assert _lookahead_episode(_episode(family, seed), margin) >= expert - 1e-12


def test_lookahead_stops_where_a_cut_lowers_the_iou() -> None:
    """An ellipsoid the expert would cut: one part reconstructs it better, so it stops."""
    state = _episode("ellipsoid", 1, planes=6)
    assert expert_cut(state) is not None
    before = (state.remaining, state.step_count, state.potential())
    choice = lookahead_cut(state, candidates=4, margin=0.0)
    assert choice.cut is None
    assert choice.value == pytest.approx(state.potential()) and choice.value > choice.expert_value
    # scoring the choices stepped copies only
    assert state.remaining is before[0] and state.step_count == before[1]
    assert state.potential() == before[2] and not state.parts


def test_copy_is_independent() -> None:
    state = _episode("table", 2)
    cut = expert_cut(state)
    assert cut is not None
    branch = state.copy()
    branch.apply_cut(cut)
    assert len(branch.parts) == 1 and not state.parts
    assert state.remaining_voxels > branch.remaining_voxels
    union = state._union()  # noqa: SLF001
    assert not union.any() and branch._union().any()  # noqa: SLF001
    assert np.array_equal(state.occupancy, branch.occupancy)


def test_lookahead_rejects_bad_arguments() -> None:
    state = _episode("box", 0)
    with pytest.raises(OptionError):
        lookahead_cut(state, candidates=0)
    with pytest.raises(OptionError):
        lookahead_cut(state, margin=-1.0)
    with pytest.raises(OptionError):
        lookahead_cut(PartitionState(state.occupancy), candidates=2)  # no reconstruction


# -- the lookahead at inference: scored without the ground truth ------------------------
def _surface(occ: np.ndarray, planes: int) -> PlanningSurface:
    sections = episode_sections(occ, planes)
    hull = occupancy_hull(occ)
    return PlanningSurface(sections, hull, lambda s, box: part_surface_voxels(s, hull, box))


def _prism(height: int = 20) -> np.ndarray:
    occ = np.zeros((16, 16, height + 4), dtype=bool)
    occ[4:12, 3:13, 2 : 2 + height] = True
    return occ


def test_reconstruction_is_what_the_potential_scores() -> None:
    state = _episode("table", 2)
    state.apply_cut(expert_cut(state))
    recon = state.reconstruction()
    assert recon.shape == state.grid_shape
    assert iou(recon, state.occupancy) == pytest.approx(state.potential())
    with pytest.raises(OptionError):
        PartitionState(state.occupancy).reconstruction()


def test_a_prism_predicts_its_held_out_planes_and_fills_its_silhouettes() -> None:
    """Interpolation between identical sections is exact: both values are 1 for any partition."""
    occ = _prism()
    surface = _surface(occ, 8)
    state = PartitionState(occ, reconstruct=lambda box: surface.part(surface.sections, box))
    planes = held_out_value(surface.sections, surface.part)
    silhouettes = silhouette_value([surface.hull.any(axis=a) for a in range(3)])
    assert planes(state) == pytest.approx(1.0) and silhouettes(state) == pytest.approx(1.0)


def test_held_out_planes_see_a_shape_that_changes_between_planes() -> None:
    """A cone's held-out sections are predicted, but not exactly; with two planes there is
    nothing to hold out."""
    z = np.arange(24)[None, None, :]
    i, j = np.meshgrid(np.arange(24), np.arange(24), indexing="ij")
    occ = np.hypot(i - 11.5, j - 11.5)[:, :, None] < 2 + 0.4 * z
    occ[:, :, :2] = occ[:, :, -2:] = False
    surface = _surface(occ, 9)
    state = PartitionState(occ, reconstruct=lambda box: surface.part(surface.sections, box))
    value = held_out_value(surface.sections, surface.part)(state)
    assert 0.8 < value < 1.0
    two = _surface(occ, 2)
    assert held_out_value(two.sections, two.part)(state) == 1.0
    with pytest.raises(OptionError):
        held_out_value(surface.sections, surface.part, folds=1)
    with pytest.raises(InputError):
        held_out_value(surface.sections, surface.part)(PartitionState(occ[:-1]))
    with pytest.raises(InputError):
        silhouette_value([np.zeros((2, 2), bool)] * 3)


@pytest.mark.parametrize("value", LOOKAHEAD_VALUES)
@pytest.mark.parametrize(("family", "seed"), [("table", 2), ("y_branch", 1)])
def test_planned_lookahead_scores_no_lower_than_expert(value: str, family: str, seed: int) -> None:
    """The rollout guarantee in the planner's own terms: its partition scores at least the
    expert's, the planner is that loop, and its boxes cover the occupancy."""
    occ = shape_occupancy(family, seed=seed, grid=24)
    surface = _surface(occ, 8)
    if value == "planes":
        score = held_out_value(surface.sections, surface.part)
    else:
        score = silhouette_value([surface.hull.any(axis=a) for a in range(3)])
    state = PartitionState(
        occ, reconstruct=lambda box: surface.part(surface.sections, box), max_steps=5
    )
    expert = expert_value(state, score)
    run_lookahead(state, candidates=4, margin=0.0, value=score)
    assert score(state) >= expert - 1e-12
    common = {"reconstruct": None, "max_parts": 6, "min_remaining": 0.02, "lam": 1.0}
    parts = plan_lookahead(occ, surface=surface, value=value, margin=0.0, **common)
    assert [p.box for p in parts] == [p.box for p in state.finish()]
    covered = np.zeros(occ.shape, dtype=bool)
    for part in parts:
        covered[part.box.slices] = True
    assert covered[occ].all()


def test_the_lookahead_planner_needs_its_surface() -> None:
    occ = _prism()
    with pytest.raises(OptionError, match="surface"):
        plan_partition(occ, planner="lookahead")
    with pytest.raises(OptionError, match="surface"):
        plan_partition(
            occ,
            planner="lookahead",
            surface=lambda f: _surface(occ, 6),
            reconstruct=lambda box: np.ones(box.shape, bool),
        )
    common = {"reconstruct": None, "max_parts": 4, "min_remaining": 0.02, "lam": 1.0}
    with pytest.raises(OptionError, match="value"):
        plan_lookahead(occ, surface=_surface(occ, 6), value="truth", **common)
    with pytest.raises(InputError, match="grid"):
        plan_lookahead(occ[:-1], surface=_surface(occ, 6), **common)
