"""Where planes of two orientations meet: drawings that agree, graze, or contradict."""

from __future__ import annotations

import numpy as np

from slicerecon.annotation import AnnotatedPlane, Annotation, PlanePose
from slicerecon.crossings import CONTRADICTION_MM, views_disagreement
from slicerecon.labels import Structure

SEMI_AXES = np.array([20.0, 15.0, 30.0])  # mm, an ellipsoid centred at the origin


def _plane(normal: np.ndarray, u: np.ndarray, centre: np.ndarray, pixel: float) -> AnnotatedPlane:
    """The ellipsoid's exact section on a plane's pixel centres (160 x 160 pixels)."""
    normal, u = normal / np.linalg.norm(normal), u / np.linalg.norm(u)
    v = np.cross(normal, u)
    affine = np.eye(4)
    affine[:3, 0], affine[:3, 1], affine[:3, 2] = pixel * u, pixel * v, normal
    affine[:3, 3] = centre - 79.5 * pixel * (u + v)
    r, c = np.indices((160, 160))
    world = affine[:3, 3] + r[..., None] * affine[:3, 0] + c[..., None] * affine[:3, 1]
    mask = np.sum((world / SEMI_AXES) ** 2, axis=-1) <= 1
    return AnnotatedPlane(PlanePose(affine, (160, 160)), {1: mask})


def _annotation(*planes: AnnotatedPlane) -> Annotation:
    return Annotation(tuple(planes), (Structure(1),), np.eye(4), (64, 64, 64))


def test_exact_sections_meeting_on_a_line_that_grazes_the_structure_agree() -> None:
    """A line that runs along the surface crosses it at a shallow angle: two exact
    sections, each on its own pixels, differ on all of it (10 of 10 points, 4.5 mm),
    though their outlines lie a pixel apart. Radial and tilted contours of the real
    development shapes were said to be "drawn differently" (239 of 548 points)."""
    z0 = 12.0
    half = SEMI_AXES[1] * np.sqrt(1 - (z0 / SEMI_AXES[2]) ** 2)
    y0 = 0.995 * half  # the line y = y0, z = z0 runs along x, grazing the section
    axial = _plane(np.array([0, 0, 1.0]), np.array([1.0, 0, 0]), np.array([0, 0, z0]), 0.7)
    tilt = np.radians(35)
    normal = np.array([0, -np.sin(tilt), np.cos(tilt)])
    tilted = _plane(normal, np.array([1.0, 0, 0]), np.array([0, y0, z0]), 0.45)
    found = views_disagreement(_annotation(axial, tilted), 1)
    assert found.drawn > 0
    assert found.differ == 0 and found.deepest_mm <= 0.7, found


def test_an_empty_plane_across_another_drawing_is_a_contradiction() -> None:
    """A plane marked empty (a contour plane with no polygon) where a crossing plane
    draws the structure 2 × 13 mm across; the same plane drawn agrees."""
    sagittal = _plane(np.array([1.0, 0, 0]), np.array([0, 1.0, 0]), np.zeros(3), 0.5)
    axial = _plane(np.array([0, 0, 1.0]), np.array([1.0, 0, 0]), np.array([0, 0, 15.0]), 0.5)
    empty = AnnotatedPlane(axial.pose, {})
    assert views_disagreement(_annotation(sagittal, empty), 1).deepest_mm > CONTRADICTION_MM
    assert views_disagreement(_annotation(sagittal, axial), 1).deepest_mm <= 0.5
