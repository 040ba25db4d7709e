"""The one renderer of previews and reports: true aspect in mm, depth order, colours, frames."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from slicerecon.render import (
    Surface,
    nice_length,
    project,
    render_surfaces,
    to_display_frame,
    view_rotation,
)

FRONT = (0.0, 90.0)
"""Seen from +y (the patient's front in RAS): world x to the left, z up."""


def _box(extents, centre=(0.0, 0.0, 0.0), colour=(0.8, 0.5, 0.3)) -> Surface:
    mesh = trimesh.creation.box(extents=extents)
    mesh.apply_translation(centre)
    return Surface(np.asarray(mesh.vertices), np.asarray(mesh.faces), np.asarray(colour))


def _extent_px(image: np.ndarray) -> tuple[int, int]:
    drawn = ~(image == 255).all(axis=2)
    rows, cols = np.flatnonzero(drawn.any(axis=1)), np.flatnonzero(drawn.any(axis=0))
    return int(cols[-1] - cols[0] + 1), int(rows[-1] - rows[0] + 1)


def test_one_scale_for_every_axis_true_aspect() -> None:
    # a phantom 20 mm wide and 50 mm tall, as 2.5 mm slices make it: never squashed
    box = _box((20.0, 10.0, 50.0))
    rendered = render_surfaces([box], size=(300, 300), view=FRONT, outline=False)
    width, height = _extent_px(rendered.image)
    assert width / height == pytest.approx(20.0 / 50.0, rel=0.03)
    assert height == pytest.approx(50.0 * rendered.camera.scale, abs=2)


def test_the_nearer_surface_hides_the_farther_and_colours_are_kept() -> None:
    red = _box((10, 10, 10), (0, 20, 0), (1.0, 0.0, 0.0))  # nearer the viewer at +y
    blue = _box((30, 10, 30), (0, 0, 0), (0.0, 0.0, 1.0))
    rendered = render_surfaces([blue, red], size=(200, 200), view=FRONT, outline=False)
    image = rendered.image
    centre = project(rendered.camera, [[0.0, 20.0, 0.0]])[0]
    x, y = np.round(centre[:2]).astype(int)
    assert image[y, x, 0] > 100 and image[y, x, 2] < 60  # red in front
    corner = project(rendered.camera, [[12.0, 5.0, 12.0]])[0]
    x, y = np.round(corner[:2]).astype(int)
    assert image[y, x, 2] > 100 and image[y, x, 0] < 60  # blue where red is not


def test_lps_meshes_are_shown_as_ras() -> None:
    points = np.array([[10.0, 20.0, 30.0]])
    np.testing.assert_array_equal(to_display_frame(points, "LPS"), [[-10.0, -20.0, 30.0]])
    np.testing.assert_array_equal(to_display_frame(points, "RAS"), points)


def test_rotation_is_orthonormal_with_z_up() -> None:
    rotation = view_rotation(20.0, 120.0)
    np.testing.assert_allclose(rotation @ rotation.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(rotation) == pytest.approx(1.0)
    assert rotation[1, 2] > 0.9  # world up is screen up


def test_dense_meshes_render_without_holes_and_deterministically() -> None:
    sphere = trimesh.creation.icosphere(subdivisions=6, radius=50.0)  # 82k faces, sub-pixel
    surface = Surface(np.asarray(sphere.vertices), np.asarray(sphere.faces), np.ones(3) * 0.7)
    first = render_surfaces([surface], size=(200, 200), outline=False)
    again = render_surfaces([surface], size=(200, 200), outline=False)
    np.testing.assert_array_equal(first.image, again.image)
    centre = project(first.camera, np.zeros((1, 3)))[0]
    radius = 50.0 * first.camera.scale * 0.97
    rows, cols = np.mgrid[:200, :200]
    inside = (cols + 0.5 - centre[0]) ** 2 + (rows + 0.5 - centre[1]) ** 2 < radius**2
    assert not (first.image[inside] == 255).all(axis=1).any()


def test_round_scale_bar_lengths() -> None:
    assert [nice_length(x) for x in (0.7, 3.0, 9.99, 45.0, 180.0)] == [0.5, 2.0, 5.0, 20.0, 100.0]
