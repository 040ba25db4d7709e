"""The expert's one-step lookahead: never worse than the expert, and it stops when cutting hurts."""

from __future__ import annotations

import numpy as np
import pytest

from slicerecon.errors import OptionError
from slicerecon.partition.episodes import shape_occupancy
from slicerecon.partition.heuristic import expert_cut
from slicerecon.partition.lookahead import expert_value, lookahead_cut
from slicerecon.partition.state import PartitionState
from slicerecon.policy.reward import episode_reconstruction


def _episode(family: str, seed: int, planes: int = 8) -> PartitionState:
    occ = shape_occupancy(family, seed=seed, grid=24)
    recon, _, _ = episode_reconstruction(occ, planes)
    return PartitionState(occ, reconstruct=recon, reward="gain", max_steps=5, max_corners=12)


def _lookahead_episode(state: PartitionState, margin: float) -> float:
    while not state.done:
        choice = lookahead_cut(state, candidates=3, margin=margin)
        if choice.cut is None:
            break
        state.apply_cut(choice.cut)
    return state.potential()


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
