"""Tests of the procedural shape families: registry, seeding, grid fit, topology, sizing."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage
from skimage.measure import euler_number

from slicerecon.errors import OptionError
from slicerecon.sections import Volume
from slicerecon.shapes import (
    FAMILIES,
    SHAPES,
    analytic_volume,
    brain,
    family_of,
    make_shape,
    shape_params,
)

RES = 32  # small grids keep the tests fast; every shape stays connected at this size
SEEDS = (0, 1, 2)
FULL = np.ones((3, 3, 3), dtype=bool)
NEW = [
    "table",
    "lamp",
    "sofa",
    "airplane",
    "car",
    "rifle",
    "guitar",
    "brain",
    "kidney",
    "lung",
    "vessel_tree",
    "genus2",
    "plate_with_holes",
    "blobs",
]


def _components(mask: np.ndarray) -> int:
    return int(ndimage.label(mask, structure=FULL)[1])


def _euler(volume: Volume) -> int:
    """Euler characteristic (26-connected solid, 6-connected background)."""
    return int(euler_number(np.pad(volume.mask, 1), connectivity=3))


def _expected_components(name: str, seed: int) -> int:
    if name == "blobs":
        return 4
    if name == "two_spheres":
        p = shape_params(name, seed=seed)
        return 2 if p["distance"] > 2 * p["radius"] + 2.0 else 1
    return 1


def test_families_cover_every_shape_once() -> None:
    members = [name for names in FAMILIES.values() for name in names]
    assert sorted(members) == sorted(SHAPES)
    assert len(members) == len(set(members))
    assert {"furniture", "objects", "anatomy", "holes", "multi_component"} <= set(FAMILIES)
    assert set(NEW) <= set(SHAPES)
    for family, names in FAMILIES.items():
        assert all(family_of(n) == family for n in names)
    with pytest.raises(OptionError, match="choose one of"):
        family_of("teapot")


@pytest.mark.parametrize("name", sorted(SHAPES))
def test_every_shape_builds_seeded_fits_and_is_deterministic(name: str) -> None:
    masks = []
    for seed in SEEDS:
        volume = make_shape(name, seed=seed, resolution=RES, margin=2)
        assert volume.mask.any()
        lo, hi = volume.bounding_box_vox()
        # exactly (composed shapes) or about (primitives) the margin; never the border
        assert np.all(lo >= 2) and np.all(np.asarray(volume.shape) - hi >= 2)
        assert np.all(lo <= 3) and np.all(np.asarray(volume.shape) - hi <= 3)
        assert RES - 2 <= int(np.max(hi - lo)) <= RES
        assert _components(volume.mask) == _expected_components(name, seed)
        again = make_shape(name, seed=seed, resolution=RES, margin=2)
        np.testing.assert_array_equal(again.mask, volume.mask)
        np.testing.assert_array_equal(again.affine, volume.affine)
        masks.append(volume)
    for a, b in zip(masks, masks[1:], strict=False):
        # at a fixed resolution a scaled sphere is the same mask with other voxel sizes
        same = a.shape == b.shape and np.array_equal(a.mask, b.mask)
        assert not (same and np.allclose(a.affine, b.affine))


@pytest.mark.parametrize("name", NEW)
def test_new_shapes_default_call_is_canonical(name: str) -> None:
    canonical = SHAPES[name](spacing=2.0)
    np.testing.assert_array_equal(make_shape(name, spacing=2.0).mask, canonical.mask)
    np.testing.assert_array_equal(SHAPES[name](spacing=2.0).mask, canonical.mask)
    assert analytic_volume(name) is None


@pytest.mark.parametrize(
    ("name", "expected"),
    [
        ("genus2", -1),
        ("torus", 0),
        ("plate_with_holes", -1),
        ("brain", 1),
        ("kidney", 1),
        ("lung", 1),
        ("sofa", 1),
        ("car", 1),
        ("guitar", 1),
        ("blobs", 4),
    ],
)
def test_topology_euler_characteristic(name: str, expected: int) -> None:
    # chi = components - tunnels + cavities: genus 2 -> -1, torus -> 0, solids -> 1
    for seed in SEEDS:
        assert _euler(make_shape(name, seed=seed, resolution=48)) == expected


@pytest.mark.parametrize("holes", [1, 3])
def test_plate_hole_count_sets_the_genus(holes: int) -> None:
    volume = make_shape("plate_with_holes", seed=4, holes=holes, resolution=48)
    assert _euler(volume) == 1 - holes
    mid = volume.mask[:, :, volume.shape[2] // 2]
    assert int(ndimage.label(~mid)[1]) == 1 + holes  # outside + one region per hole


def test_genus2_has_two_holes_through_z() -> None:
    volume = make_shape("genus2", seed=7, resolution=64)
    mid = volume.mask[:, :, volume.shape[2] // 2]
    assert int(ndimage.label(mid, structure=np.ones((3, 3)))[1]) == 1
    assert int(ndimage.label(~mid)[1]) == 3


def _z_plane(volume: Volume, fraction: float) -> np.ndarray:
    planes = volume.occupied_planes(2)
    return volume.mask[:, :, planes[0] + int(round(fraction * (planes.size - 1)))]


def test_table_styles_and_legs() -> None:
    legs = make_shape("table", style="legs", resolution=48)
    pedestal = make_shape("table", style="pedestal", resolution=48)
    trestle = make_shape("table", style="trestle", resolution=48)
    plane = lambda v: ndimage.label(_z_plane(v, 0.5), structure=np.ones((3, 3)))[1]  # noqa: E731
    assert plane(legs) == 4 and plane(pedestal) == 1 and plane(trestle) == 2
    assert _euler(trestle) == 0  # end boards, stretcher and top close a loop
    with pytest.raises(OptionError, match="style must be one of"):
        make_shape("table", style="round")


def test_chair_styles_keep_the_canonical_chair() -> None:
    plain = make_shape("chair", seed=3, style="plain")
    assert _euler(plain) == 1
    np.testing.assert_array_equal(make_shape("chair").mask, SHAPES["chair"]().mask)
    assert _euler(make_shape("chair", seed=3, style="armchair", resolution=48)) == -1
    slats = make_shape("chair", style="slat_back", resolution=48)  # canonical: 2 slats
    assert _euler(slats) == -2  # three openings in the back
    drawn = {_euler(make_shape("chair", seed=s, resolution=RES)) for s in range(8)}
    assert len(drawn) > 1  # seeds draw different styles
    with pytest.raises(OptionError, match="chair style must be one of"):
        make_shape("chair", style="throne")


def test_car_stands_on_four_wheels() -> None:
    for seed in SEEDS:
        car = make_shape("car", seed=seed, resolution=48)
        low = _z_plane(car, 0.08)
        assert ndimage.label(low, structure=np.ones((3, 3)))[1] == 4


def test_lung_has_two_lobes_joined_medially() -> None:
    lung = make_shape("lung", seed=3, resolution=64)
    lo, hi = lung.bounding_box_vox()
    lateral = lung.mask[int(lo[0] + 0.8 * (hi[0] - lo[0]))]  # a sagittal plane near the side
    assert ndimage.label(lateral, structure=np.ones((3, 3)))[1] == 2
    assert _components(lung.mask) == 1


def test_vessel_tree_branches_upwards() -> None:
    tree = make_shape("vessel_tree", seed=5, resolution=48, generations=2)
    count = lambda f: ndimage.label(_z_plane(tree, f), structure=np.ones((3, 3)))[1]  # noqa: E731
    assert count(0.1) == 1
    assert count(0.97) >= 2
    deeper = make_shape("vessel_tree", seed=5, resolution=48, generations=4)
    assert deeper.mask.sum() != tree.mask.sum()


def test_brain_folds_around_an_ellipsoid() -> None:
    params = shape_params("brain", seed=2)
    a, b, c = params["radii"]
    ellipsoid_mm3 = 4.0 / 3.0 * np.pi * a * b * c
    # same sizes, two fold patterns: about the ellipsoid's volume, different masks
    folded = [brain(**params, seed=s, spacing=3.0) for s in (2, 3)]
    for volume in folded:
        assert volume.volume_mm3 == pytest.approx(ellipsoid_mm3, rel=0.15)
        assert _euler(volume) == 1
    assert not np.array_equal(folded[0].mask, folded[1].mask)
    flat = brain(**{**params, "fold_depth": 0.5}, seed=2, spacing=3.0)
    assert not np.array_equal(flat.mask, folded[0].mask)


def test_blobs_count_and_separation() -> None:
    for count in (1, 2, 6):
        volume = make_shape("blobs", seed=1, count=count, resolution=48)
        assert _components(volume.mask) == count
        assert _euler(volume) == count


def test_resolution_scales_the_voxels_not_the_shape() -> None:
    coarse = make_shape("kidney", seed=3, resolution=24)
    fine = make_shape("kidney", seed=3, resolution=64)
    assert coarse.volume_mm3 == pytest.approx(fine.volume_mm3, rel=0.1)
    assert coarse.spacing[0] / fine.spacing[0] == pytest.approx(64 / 24, rel=0.1)
    aniso = make_shape("car", seed=1, resolution=40, spacing=(1.0, 1.0, 2.0))
    assert aniso.spacing[2] / aniso.spacing[0] == pytest.approx(2.0)
    lo, hi = aniso.bounding_box_vox()
    assert 38 <= int(np.max(hi - lo)) <= 40


def test_option_and_seed_errors() -> None:
    with pytest.raises(OptionError, match="resolution"):
        make_shape("car", resolution=4)
    with pytest.raises(OptionError, match="resolution"):
        make_shape("car", resolution=True)
    with pytest.raises(OptionError, match="seed"):
        make_shape("brain", seed=-1)
    with pytest.raises(OptionError, match="no parameter wings"):
        make_shape("airplane", wings=3)
    with pytest.raises(OptionError, match="holes must be"):
        make_shape("plate_with_holes", holes=0)
    with pytest.raises(OptionError, match="count must be"):
        make_shape("blobs", count=100)
    with pytest.raises(OptionError, match="generations must be"):
        make_shape("vessel_tree", generations=9)
    with pytest.raises(OptionError, match="hole_radius"):
        make_shape("plate_with_holes", hole_radius=30.0)
    with pytest.raises(OptionError, match="vanishes at resolution"):
        make_shape("airplane", seed=1, resolution=12)
