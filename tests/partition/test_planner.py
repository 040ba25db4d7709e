"""Planners, plan.json round trips and the visual hull."""

from __future__ import annotations

import json

import numpy as np
import pytest

from slicerecon.errors import EmptyMaskError, GeometryError, OptionError
from slicerecon.partition import planner as planner_module
from slicerecon.partition.planner import Plan, PlanPart, plan_partition, planner_names
from slicerecon.partition.state import Part
from slicerecon.sampling import projections_from_volume, visual_hull
from slicerecon.sections import Box, Volume


def t_shape(n: int = 32) -> np.ndarray:
    occ = np.zeros((n, n, n), dtype=bool)
    occ[4:28, 4:28, 20:26] = True
    occ[13:19, 4:28, 4:20] = True
    return occ


def test_none_planner_is_one_bounding_box() -> None:
    occ = t_shape()
    plan = plan_partition(occ, planner="none")
    assert plan.parts == (PlanPart(Box((4, 4, 4), (28, 28, 26)), None, int(occ.sum())),)
    assert plan.planner == "none" and plan.grid_shape == occ.shape


def test_heuristic_planner_covers_and_respects_max_parts() -> None:
    occ = t_shape()
    plan = plan_partition(occ, planner="heuristic")
    assert len(plan.parts) == 2 and plan.covers(occ)
    assert sum(p.voxels for p in plan.parts) == occ.sum()
    assert plan.parts[0].cut is not None and plan.parts[-1].cut is None
    single = plan_partition(occ, planner="heuristic", max_parts=1)
    assert len(single.parts) == 1 and single.covers(occ)


def test_unknown_planner_lists_the_choices() -> None:
    with pytest.raises(OptionError, match="heuristic, lookahead, none"):
        plan_partition(t_shape(), planner="magic")
    with pytest.raises(OptionError, match="max_parts"):
        plan_partition(t_shape(), max_parts=0)
    with pytest.raises(EmptyMaskError):
        plan_partition(np.zeros((4, 4, 4), dtype=bool))


def test_a_new_planner_is_one_registry_entry(monkeypatch: pytest.MonkeyPatch) -> None:
    def halves(occupancy, *, reconstruct, max_parts, min_remaining, lam):  # noqa: ANN001, ANN202
        box = Box.of_mask(occupancy)
        return [Part(box, int(occupancy.sum()), 0.0, None)]

    monkeypatch.setitem(planner_module.PLANNERS, "policy", halves)
    assert "policy" in planner_names()
    assert plan_partition(t_shape(), planner="policy").planner == "policy"


def test_plan_json_round_trip_and_world_corners() -> None:
    plan = plan_partition(t_shape(), planner="heuristic")
    affine = np.diag([0.5, 0.8, 2.5, 1.0])
    affine[:3, 3] = [-10.0, 4.0, 100.0]
    data = json.loads(json.dumps(plan.to_dict(affine)))
    assert Plan.from_dict(data) == plan
    for part, entry in zip(plan.parts, data["parts"], strict=True):
        lo = np.asarray(part.box.lo) - 0.5
        hi = np.asarray(part.box.hi) - 0.5
        np.testing.assert_allclose(entry["min_mm"], np.diag(affine)[:3] * lo + affine[:3, 3])
        np.testing.assert_allclose(entry["max_mm"], np.diag(affine)[:3] * hi + affine[:3, 3])
        assert len(entry["corners_mm"]) == 8
    assert "corners_mm" not in plan.to_dict()["parts"][0]


def test_visual_hull_recovers_orthogonal_shapes_and_contains_any_shape() -> None:
    occ = t_shape()
    hull = visual_hull(projections_from_volume(Volume(occ)), occ.shape)
    assert np.array_equal(hull, occ)  # the T is its own visual hull
    rng = np.random.default_rng(0)
    blob = rng.random((9, 10, 11)) < 0.3
    hull = visual_hull(projections_from_volume(Volume(blob)), blob.shape)
    assert not (blob & ~hull).any()
    for a in range(3):
        assert np.array_equal(hull.any(axis=a), blob.any(axis=a))


def test_visual_hull_rejects_mismatched_grid() -> None:
    with pytest.raises(GeometryError, match="needs"):
        visual_hull(projections_from_volume(Volume(t_shape())), (32, 32, 31))


def test_a_large_grid_is_planned_on_a_pooled_copy_and_still_covered() -> None:
    from slicerecon.shapes import make_shape

    chair = make_shape("chair", spacing=0.4)  # about 240 voxels tall
    assert max(chair.shape) > 200
    full = plan_partition(chair.mask, planner="heuristic")
    pooled = plan_partition(chair.mask, planner="heuristic", max_grid=100)
    assert pooled.covers(chair.mask) and full.covers(chair.mask)
    assert pooled.grid_shape == chair.shape
    for box in pooled.boxes:  # tightened: every box face touches the occupancy it holds
        assert Box.of_mask(chair.mask[box.slices]).shape == box.shape
    small = plan_partition(chair.mask, planner="heuristic", max_grid=1000)
    assert small.boxes == full.boxes  # no pooling below the limit
