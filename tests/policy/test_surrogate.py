"""The reward's part surface (inference's) and its batched torch surrogate."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from slicerecon.options import ReconstructOptions
from slicerecon.partition.episodes import ShapePool, episode_sections, occupancy_hull
from slicerecon.partition.state import PartitionState, iou
from slicerecon.policy.reward import (
    SURFACE_INTERPOLATION,
    SURFACE_JOIN_DRIFT,
    SURFACE_METHOD,
    episode_reconstruction,
    part_surface_voxels,
    plane_distances,
)
from slicerecon.policy.surrogate import surrogate_parts, surrogate_reconstruction
from slicerecon.reconstruct import ReconstructConfig
from slicerecon.sections import Box, CrossSections
from slicerecon.surface.drift import consecutive_drifting_pairs
from slicerecon.surface.part import part_voxels

PCHIP_PRISMS = ReconstructOptions(interpolation="pchip", join_drift=False)
"""The surrogate's surface: PCHIP across planes, drifting regions not joined."""


@pytest.fixture(scope="module")
def pool() -> ShapePool:
    return ShapePool.build(("chair", "two_spheres", "y_branch", "lamp", "torus"), [4], grid=28)


def _random_parts(
    occ: np.ndarray, rng: np.random.Generator, episodes: int = 2
) -> list[tuple[Box, np.ndarray]]:
    """(box, W) of the parts of random episodes, leftovers included."""
    parts = []
    for _ in range(episodes):
        state = PartitionState(occ, max_steps=6)
        while not state.done:
            before = state.remaining
            result = state.step(rng.random(5))
            if result.part is not None:
                parts.append((result.part.box, before & ~state.remaining))
        if state.remaining.any():
            parts.append((Box.of_mask(state.remaining), state.remaining.copy()))
    return parts


def test_the_reward_surface_is_inference_default() -> None:
    config = ReconstructConfig()
    assert (config.method, config.interpolation, config.carve, config.join_drift) == (
        SURFACE_METHOD,
        SURFACE_INTERPOLATION,
        True,
        SURFACE_JOIN_DRIFT,
    )


def test_part_surface_is_part_voxels_carved_by_the_hull(pool: ShapePool) -> None:
    occ = pool.occupancies[0]
    recon, sections, hull = episode_reconstruction(occ, 9)
    box = Box.of_mask(occ)
    expected = part_voxels(
        sections,
        box,
        ReconstructOptions(method="sdf", interpolation="pchip", join_drift=True),
        hull=hull,
    )
    np.testing.assert_array_equal(recon(box), expected & hull[box.slices])
    np.testing.assert_array_equal(part_surface_voxels(sections, hull, box), recon(box))


def test_surrogate_equals_the_library_on_the_whole_shape(pool: ShapePool) -> None:
    """A box with a free border whose ends are planes, and no region that drifts
    (the surrogate does not join those): no approximation applies."""
    compared = 0
    for occ in pool.occupancies:
        for n in (2, 7, 12):
            recon, sections, hull = episode_reconstruction(occ, n)
            if _drifts(sections):
                continue
            box = Box.of_mask(occ)
            np.testing.assert_array_equal(surrogate_reconstruction(sections, hull)(box), recon(box))
            compared += 1
    assert compared >= 2 * len(pool.occupancies)


def _drifts(sections: CrossSections) -> bool:
    spacing = sections.spacing[list(sections.plane_axes)]
    axis_mm = float(sections.spacing[sections.axis])
    return bool(consecutive_drifting_pairs(sections.masks, sections.indices, spacing, axis_mm))


def test_surrogate_differs_from_prism_extensions_only_by_outside_distances(
    pool: ShapePool,
) -> None:
    """Against the library with prism extensions, parts of random episodes agree to 1e-3."""
    rng = np.random.default_rng(0)
    differ = total = 0
    for occ in pool.occupancies:
        sections, hull = episode_sections(occ, 10), occupancy_hull(occ)
        surrogate = surrogate_reconstruction(sections, hull)
        for box, _ in _random_parts(occ, rng):
            prism = part_voxels(sections, box, PCHIP_PRISMS, hull=None)
            differ += int(np.count_nonzero(surrogate(box) != (prism & hull[box.slices])))
            total += int(np.prod(box.shape))
    assert differ <= 1e-3 * total


def test_surrogate_rewards_agree_with_the_exact_ones(pool: ShapePool) -> None:
    rng = np.random.default_rng(1)
    exact, approx = [], []
    for occ in pool.occupancies:
        recon, sections, hull = episode_reconstruction(occ, int(rng.integers(8, 17)))
        surrogate = surrogate_reconstruction(sections, hull)
        for box, w in _random_parts(occ, rng):
            exact.append(iou(recon(box), w[box.slices]))
            approx.append(iou(surrogate(box), w[box.slices]))
    exact_a, approx_a = np.array(exact), np.array(approx)
    assert len(exact) >= 20
    assert np.mean(np.abs(exact_a - approx_a)) < 0.01
    assert np.corrcoef(exact_a, approx_a)[0, 1] > 0.98


def test_surrogate_handles_empty_planes_and_boxes_between_planes() -> None:
    """Two blobs stacked along z with empty planes between them; boxes without a plane."""
    occ = np.zeros((16, 16, 24), dtype=bool)
    occ[3:9, 3:9, 2:9] = True
    occ[6:13, 5:12, 13:22] = True
    sections = episode_sections(occ, 8)
    hull = occupancy_hull(occ)
    assert not sections.masks.any(axis=(1, 2)).all()  # some planes are empty
    surrogate = surrogate_reconstruction(sections, hull)
    gaps = np.diff(sections.indices)
    z = int(sections.indices[int(np.argmax(gaps))]) + 1  # a z-range holding no plane
    boxes = [
        Box.of_mask(occ),
        Box((2, 2, 1), (14, 14, 12)),
        Box((0, 0, z), (16, 16, z + 1)),
        Box((5, 4, 10), (13, 12, 23)),
    ]
    for box in boxes:
        prism = part_voxels(sections, box, PCHIP_PRISMS, hull=None) & hull[box.slices]
        np.testing.assert_array_equal(surrogate(box), prism)


def test_batched_surrogate_equals_one_part_at_a_time(pool: ShapePool) -> None:
    rng = np.random.default_rng(2)
    rows = []
    for occ in pool.occupancies:
        sections, hull = episode_sections(occ, int(rng.integers(8, 17))), occupancy_hull(occ)
        for box, _ in _random_parts(occ, rng, episodes=1)[:3]:
            rows.append((sections, hull, box))
    p = max(s.n_planes for s, _, _ in rows)
    g = pool.grid
    dist = torch.full((len(rows), p, g, g), float("inf"))
    planes = torch.zeros((len(rows), p), dtype=torch.int64)
    valid = torch.zeros((len(rows), p), dtype=torch.bool)
    for i, (sections, _, _) in enumerate(rows):
        dist[i, : sections.n_planes] = torch.from_numpy(plane_distances(sections))
        planes[i, : sections.n_planes] = torch.from_numpy(sections.indices.astype(np.int64))
        valid[i, : sections.n_planes] = True
    hulls = torch.from_numpy(np.stack([h for _, h, _ in rows]))
    lo = torch.tensor([b.lo for _, _, b in rows])
    hi = torch.tensor([b.hi for _, _, b in rows])
    batch = surrogate_parts(dist, planes, valid, hulls, lo, hi).numpy()
    for i, (sections, hull, box) in enumerate(rows):
        alone = np.zeros_like(batch[i])
        alone[box.slices] = surrogate_reconstruction(sections, hull)(box)
        np.testing.assert_array_equal(batch[i], alone)
