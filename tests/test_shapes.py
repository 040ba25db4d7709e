"""Tests of slicerecon.shapes: volumes, centring, topology and seeded determinism."""

from __future__ import annotations

import inspect

import numpy as np
import pytest
from scipy import ndimage

from slicerecon.errors import OptionError
from slicerecon.sections import Volume
from slicerecon.shapes import (
    SHAPES,
    analytic_volume,
    blobs,
    chair,
    ellipsoid,
    make_shape,
    shape_names,
    shape_params,
    sphere,
    y_branch,
)
from slicerecon.shapes.params import checked

PRIMITIVES = ["sphere", "ellipsoid", "torus", "box", "two_spheres"]
ANISOTROPIC = (0.8, 0.8, 2.0)
FULL = np.ones((3, 3), dtype=bool)  # 8-connectivity in a plane


def _components(plane: np.ndarray) -> int:
    return int(ndimage.label(plane, structure=FULL)[1])


def _plane_at(volume: Volume, z_above_bottom_mm: float) -> np.ndarray:
    """The z-plane ``z_above_bottom_mm`` above the lowest foreground voxel centre."""
    first = int(volume.occupied_planes(2)[0])
    return volume.mask[:, :, first + round(z_above_bottom_mm / volume.spacing[2])]


@pytest.mark.parametrize("spacing", [1.0, ANISOTROPIC])
@pytest.mark.parametrize("name", PRIMITIVES)
def test_voxel_volume_matches_analytic(name: str, spacing: float | tuple[float, ...]) -> None:
    volume = make_shape(name, spacing=spacing)
    np.testing.assert_allclose(volume.spacing, np.broadcast_to(spacing, 3))
    exact = analytic_volume(name)
    assert exact is not None
    assert volume.volume_mm3 == pytest.approx(exact, rel=0.02)


@pytest.mark.parametrize("name", ["sphere", "ellipsoid", "torus", "two_spheres"])
def test_seeded_voxel_volume_matches_analytic(name: str) -> None:
    params = shape_params(name, seed=11)
    volume = make_shape(name, seed=11)
    assert volume.volume_mm3 == pytest.approx(analytic_volume(name, **params), rel=0.02)


def test_box_holds_a_whole_number_of_voxels_per_side() -> None:
    for seed in range(4):
        size = shape_params("box", seed=seed)["size"]
        volume = make_shape("box", seed=seed, spacing=ANISOTROPIC)
        lo, hi = volume.bounding_box_vox()
        assert volume.volume_mm3 == pytest.approx(np.prod((hi - lo) * volume.spacing))
        for extent, length, step in zip(hi - lo, size, ANISOTROPIC, strict=True):
            assert np.floor(length / step) <= extent <= np.ceil(length / step)


def test_exact_box_and_overlapping_spheres() -> None:
    assert make_shape("box", spacing=ANISOTROPIC).volume_mm3 == pytest.approx(60 * 40 * 30)
    merged = make_shape("two_spheres", radius=20.0, distance=25.0)
    exact = analytic_volume("two_spheres", distance=25.0)
    assert merged.volume_mm3 == pytest.approx(exact, rel=0.02)
    assert analytic_volume("chair") is None and analytic_volume("y_branch") is None


@pytest.mark.parametrize("name", sorted(SHAPES))
def test_shapes_are_centred_with_margin(name: str) -> None:
    for seed, spacing in [(None, 1.0), (3, ANISOTROPIC)]:
        volume = make_shape(name, seed=seed, spacing=spacing, margin=4)
        centroid = volume.index_to_world(np.argwhere(volume.mask)).mean(axis=0)
        assert np.all(np.abs(centroid) < 1e-6)
        lo, hi = volume.bounding_box_vox()
        assert np.all(lo >= 4) and np.all(np.asarray(volume.shape) - hi >= 4)
        # no more than one superfluous empty layer (a curved boundary may miss the outer centres)
        assert np.all(lo <= 5) and np.all(np.asarray(volume.shape) - hi <= 5)


@pytest.mark.parametrize("name", sorted(SHAPES))
def test_seed_is_deterministic_and_varies(name: str) -> None:
    a, b = make_shape(name, seed=5), make_shape(name, seed=5)
    np.testing.assert_array_equal(a.mask, b.mask)
    np.testing.assert_array_equal(a.affine, b.affine)
    c = make_shape(name, seed=6)
    assert a.shape != c.shape or not np.array_equal(a.mask, c.mask)
    canonical = make_shape(name)
    np.testing.assert_array_equal(canonical.mask, SHAPES[name]().mask)
    for key, value in shape_params(name, seed=5).items():
        base = np.asarray(shape_params(name)[key], dtype=float)
        ratio = np.asarray(value, dtype=float) / base
        assert np.all((ratio >= 0.8) & (ratio <= 1.2))


@pytest.mark.parametrize("seed", [None, 0, 1, 2])
def test_chair_legs_are_separate_below_the_seat(seed: int | None) -> None:
    params = shape_params("chair", seed=seed)
    volume = chair(**params)
    low = _plane_at(volume, 0.5 * params["leg_height"])
    assert _components(low) == 4
    seat = _plane_at(volume, params["leg_height"] + 0.5 * params["seat_thickness"])
    assert _components(seat) == 1


@pytest.mark.parametrize("seed", [None, 0, 1, 2])
def test_y_branch_splits_in_two(seed: int | None) -> None:
    params = shape_params("y_branch", seed=seed)
    volume = y_branch(**params)
    r = params["radius"]
    low = _plane_at(volume, r + 0.5 * params["trunk_length"])
    high = _plane_at(volume, r + params["trunk_length"] + 0.8 * params["branch_length"])
    assert _components(low) == 1
    assert _components(high) == 2


def test_torus_has_a_hole_along_z() -> None:
    volume = make_shape("torus")
    middle = volume.mask[:, :, volume.shape[2] // 2]
    assert _components(middle) == 1
    assert _components(~middle) == 2  # the outside and the hole


def test_registry_and_errors() -> None:
    assert shape_names() == sorted(SHAPES)
    assert {"sphere", "ellipsoid", "torus", "box", "y_branch", "chair"} <= set(shape_names())
    with pytest.raises(OptionError, match="choose one of .*sphere"):
        make_shape("dodecahedron")
    with pytest.raises(OptionError, match="no parameter colour"):
        make_shape("sphere", colour=3)
    with pytest.raises(OptionError, match="smaller than its major"):
        make_shape("torus", major=10.0, minor=12.0)
    with pytest.raises(OptionError, match="positive"):
        make_shape("sphere", radius=-1.0)
    with pytest.raises(OptionError, match="spacing"):
        make_shape("sphere", spacing=(1.0, 0.0, 1.0))
    with pytest.raises(OptionError, match="legs would touch"):
        make_shape("chair", leg_width=25.0)
    with pytest.raises(OptionError, match="coarser spacing"):
        make_shape("sphere", spacing=0.01)
    with pytest.raises(OptionError, match="finer spacing"):
        make_shape("sphere", radius=0.3)
    with pytest.raises(OptionError, match="margin"):
        make_shape("box", margin=-1)


def test_parameter_checks_come_from_the_signature() -> None:
    # the signature stays the function's own: the registry reads the sizes from it
    sizes = [
        p.name
        for p in inspect.signature(chair).parameters.values()
        if p.kind is inspect.Parameter.POSITIONAL_OR_KEYWORD
    ]
    assert sizes == list(shape_params("chair"))
    with pytest.raises(OptionError, match="radius must be a number of mm"):
        sphere("large")
    with pytest.raises(OptionError, match=r"radii\[1\] must be a positive finite size"):
        ellipsoid((10.0, -1.0, 5.0))
    with pytest.raises(OptionError, match="count must be a whole number from 1 to 32"):
        blobs(count=0)
    with pytest.raises(OptionError, match="seed must be a whole number"):
        blobs(seed=-3)
    small = blobs(np.float32(40.0), np.int64(6), count=np.int64(2), seed=np.int64(1))
    np.testing.assert_array_equal(small.mask, blobs(40.0, 6.0, count=2, seed=1).mask)
    with pytest.raises(TypeError, match="declare no check"):

        @checked
        def slab(thickness: float = 1.0) -> Volume:
            raise AssertionError("never defined")
