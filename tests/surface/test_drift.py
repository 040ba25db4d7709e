"""Regions that drift between planes: a slanted rod stays one piece, planes stay exact."""

from __future__ import annotations

import numpy as np
import pytest

from slicerecon.rasterize import mesh_to_mask
from slicerecon.reconstruct import reconstruct
from slicerecon.sampling import projections_from_sections, projections_from_volume
from slicerecon.sections import CrossSections, Volume
from slicerecon.shapes.primitives import slanted_rod
from slicerecon.surface.drift import drifting_pairs
from slicerecon.surface.sdf import sdf_field

RADIUS = 5.0
STEP = 3.0  # voxels the rod's axis moves along x per layer: 12 mm per 4 mm plane
GAP = 4


def _rod() -> Volume:
    """A rod of radius 5 mm along z whose axis moves 3 mm along x per 1 mm layer."""
    return slanted_rod(radius=RADIUS, slope=STEP, shape=(130, 30, 40), start=8.0)


def _sections(volume: Volume) -> CrossSections:
    planes = list(range(4, 37, GAP))
    masks = np.stack([volume.mask[:, :, p] for p in planes])
    return CrossSections(masks, np.asarray(planes, float), 2, volume.affine, volume.shape)


def _iou(mesh, volume: Volume) -> float:  # type: ignore[no-untyped-def]
    pred = mesh_to_mask(mesh, volume.affine, volume.shape)
    return float((pred & volume.mask).sum() / (pred | volume.mask).sum())


def test_consecutive_discs_do_not_overlap() -> None:
    # The premise: each plane's disc misses the next plane's disc entirely.
    sections = _sections(_rod())
    assert not np.any(sections.masks[:-1] & sections.masks[1:])


@pytest.mark.parametrize("source", ["volume", "sections"])
def test_a_slanted_rod_is_one_watertight_piece(source: str) -> None:
    rod = _rod()
    sections = _sections(rod)
    if source == "volume":
        projections = projections_from_volume(rod)
    else:
        projections = projections_from_sections(sections)
    joined = reconstruct(sections, projections)
    apart = reconstruct(sections, projections, join_drift=False)
    assert joined.mesh.is_watertight and joined.mesh.is_volume
    assert len(joined.mesh.split(only_watertight=False)) == 1
    if source == "sections":  # with the dense silhouettes the cover bridges some gaps
        assert len(apart.mesh.split(only_watertight=False)) > 1
    assert _iou(joined.mesh, rod) >= _iou(apart.mesh, rod) + 0.1
    assert _iou(joined.mesh, rod) >= 0.8


def test_planes_are_reproduced_exactly() -> None:
    sections = _sections(_rod())
    field, _ = sdf_field(sections, interpolation="pchip", join_drift=True)
    for mask, w in zip(sections.masks, sections.indices.astype(int), strict=True):
        np.testing.assert_array_equal(field[:, :, w] < 0, mask)


def _disc(centre: tuple[float, float], radius: float, shape=(80, 40)) -> np.ndarray:  # noqa: ANN001
    i, j = np.meshgrid(np.arange(shape[0]), np.arange(shape[1]), indexing="ij")
    return (i - centre[0]) ** 2 + (j - centre[1]) ** 2 <= radius**2


def test_overlapping_regions_are_left_to_the_plain_interpolation() -> None:
    spacing = np.ones(2)
    assert drifting_pairs(_disc((20, 20), 6), _disc((26, 20), 6), spacing, 4.0) == []


def test_regions_far_apart_are_not_joined() -> None:
    # Two regions 20 mm apart edge to edge, planes 4 mm apart: two structures,
    # one ending and one starting, not one structure that moved.
    spacing = np.ones(2)
    assert drifting_pairs(_disc((10, 20), 5), _disc((40, 20), 5), spacing, 4.0) == []


def test_only_mutual_nearest_regions_pair() -> None:
    spacing = np.ones(2)
    lower = _disc((10, 20), 4)
    upper = _disc((20, 20), 4) | _disc((31, 20), 4)
    pairs = drifting_pairs(lower, upper, spacing, 4.0)
    assert len(pairs) == 1
    _, region, shift = pairs[0]
    np.testing.assert_allclose(shift, [10.0, 0.0], atol=1e-9)
    np.testing.assert_array_equal(region, _disc((20, 20), 4))
