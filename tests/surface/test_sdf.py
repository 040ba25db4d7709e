"""Signed-distance interpolation: planes reproduced, extents as documented, parts seamless."""

from __future__ import annotations

import numpy as np
import pytest

from slicerecon import shapes
from slicerecon.errors import EmptyMaskError, OptionError
from slicerecon.options import ReconstructOptions
from slicerecon.sampling import sample_sections
from slicerecon.sections import Box, CrossSections
from slicerecon.surface.part import part_voxels
from slicerecon.surface.sdf import sdf_interpolate, sdf_mesh, sdf_parts_mesh

LINEAR = ReconstructOptions(interpolation="linear", join_drift=False)
"""Classic signed-distance interpolation: linear across planes, no drift joining."""


def _disc(shape: tuple[int, int], centre: tuple[float, float], radius: float) -> np.ndarray:
    i, j = np.meshgrid(np.arange(shape[0]), np.arange(shape[1]), indexing="ij")
    return (i - centre[0]) ** 2 + (j - centre[1]) ** 2 <= radius**2


def _sections(masks: list[np.ndarray], indices: list[float], depth: int) -> CrossSections:
    rows, cols = masks[0].shape
    return CrossSections(
        np.stack(masks),
        np.asarray(indices, dtype=np.float64),
        2,
        np.eye(4),
        (rows, cols, depth),
    )


def test_every_plane_is_reproduced_exactly() -> None:
    volume = shapes.torus()
    sections = sample_sections(volume, n=9)
    mask = sdf_interpolate(sections).mask
    for plane, w in zip(sections.masks, sections.indices.astype(int), strict=True):
        np.testing.assert_array_equal(mask[:, :, w], plane)


def test_box_with_one_plane_is_a_full_prism_to_its_faces() -> None:
    # A box holding exactly one plane, extended to its faces, is that plane's
    # mask on every layer, the plane's own layer included.
    disc = _disc((40, 40), (20, 20), 9)
    sections = _sections([disc, disc, disc], [5, 20, 35], 41)
    box = Box((0, 0, 14), (40, 40, 27))
    inside = part_voxels(sections, box, LINEAR)
    assert inside.shape == (40, 40, 13)
    for layer in range(inside.shape[2]):
        np.testing.assert_array_equal(inside[:, :, layer], disc)
    mesh = sdf_mesh(sections, box=box, extend_to_box=True)
    assert mesh.is_watertight and mesh.is_volume
    assert len(mesh.split(only_watertight=False)) == 1
    # Cylinder of the disc's area (pixel count) and the box's 13 layers.
    assert mesh.volume == pytest.approx(disc.sum() * 13, rel=0.03)


def test_between_planes_the_radius_varies_linearly() -> None:
    # Concentric discs of radius 6 and 14: the signed distances blend linearly,
    # so half-way the disc has radius 10.
    masks = [_disc((40, 40), (20, 20), r) for r in (6.0, 14.0)]
    sections = _sections(masks, [0, 20], 21)
    mask = sdf_interpolate(sections).mask
    middle = _disc((40, 40), (20, 20), 10.0)
    assert abs(int(mask[:, :, 10].sum()) - int(middle.sum())) <= 0.05 * middle.sum()


def test_without_a_box_the_shape_spans_first_to_last_plane() -> None:
    disc = _disc((30, 30), (15, 15), 8)
    sections = _sections([disc, disc], [10, 20], 40)
    mask = sdf_interpolate(sections).mask
    occupied = np.flatnonzero(mask.any(axis=(0, 1)))
    assert (occupied[0], occupied[-1]) == (10, 20)


def test_box_between_planes_is_filled_by_their_slab() -> None:
    disc = _disc((30, 30), (15, 15), 8)
    sections = _sections([disc, disc], [4, 20], 30)
    inside = part_voxels(sections, Box((0, 0, 8), (30, 30, 14)), LINEAR)
    for layer in range(inside.shape[2]):
        np.testing.assert_array_equal(inside[:, :, layer], disc)


def test_parts_join_without_a_seam() -> None:
    volume = shapes.sphere(20.0)
    sections = sample_sections(volume, n=12)
    whole = Box.of_mask(volume.mask)
    middle = (whole.lo[2] + whole.hi[2]) // 2
    lower = Box(whole.lo, (whole.hi[0], whole.hi[1], middle))
    upper = Box((whole.lo[0], whole.lo[1], middle), whole.hi)
    one = sdf_parts_mesh(sections, [whole])
    two = sdf_parts_mesh(sections, [lower, upper])
    assert two.is_watertight and two.is_volume
    assert len(two.split(only_watertight=False)) == 1
    # Splitting at a face between planes only changes the slab around that face.
    assert two.volume == pytest.approx(one.volume, rel=0.03)


def test_empty_box_and_bad_upsample_are_refused() -> None:
    disc = _disc((30, 30), (8, 8), 4)
    sections = _sections([disc, disc], [4, 20], 30)
    with pytest.raises(EmptyMaskError):
        sdf_mesh(sections, box=Box((20, 20, 0), (30, 30, 30)), extend_to_box=True)
    with pytest.raises(OptionError, match="upsample"):
        sdf_interpolate(sections, upsample=0)
