"""Where planes of two orientations meet, and whether their drawings agree there.

Two planes that are not parallel meet on a line, and both say there whether a
structure is present: views of one structure that disagree on those lines were
drawn on different studies or frames, or contradict each other (a plane marked
absent across another plane's drawing). Used by the views' warnings
(:func:`warn_views_disagree`) and by the search for one structure given two values
in two inputs (:func:`slicerecon.annotated_planes.warn_coinciding`).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from .annotation import AnnotatedPlane, Annotation, PlanePose
from .sections import AXIS_NAMES

__all__ = [
    "CONTRADICTION_MM",
    "CONTRADICTION_PIXELS",
    "MAX_VIEW_DISAGREEMENT",
    "OUTLINE_TOLERANCE",
    "ViewsDisagreement",
    "crossing_points",
    "drawn_at",
    "views_disagreement",
    "warn_views_disagree",
]

logger = logging.getLogger(__name__)

MAX_VIEW_DISAGREEMENT = 0.2
"""Share of the points where two views' planes meet (of those either draws) on which they
may disagree, farther than :data:`OUTLINE_TOLERANCE` from the nearer outline, before a
warning says they were drawn differently (hand-drawn views differ by a voxel or two at
their edges)."""


@dataclass
class ViewsDisagreement:
    """How the drawings of one structure differ where planes of two orientations meet
    (:func:`views_disagreement`)."""

    differ: int = 0
    """Samples on the lines where the two planes meet at which their drawings differ,
    deeper than :data:`OUTLINE_TOLERANCE`."""
    drawn: int = 0
    """Samples at which either plane draws the structure."""
    deepest_mm: float = 0.0
    """The largest depth (mm) of a sample on which the two drawings differ: its
    distance from the nearer of the two planes' outlines."""
    planes: tuple[PlanePose, PlanePose] | None = None
    """The two planes of that sample."""


OUTLINE_TOLERANCE = 1.0
"""Pixels (of the coarser plane) from the nearer outline within which two drawings may
differ where their planes meet, and not count: a line that grazes the structure runs
along both outlines, and pixels a hair apart differ along much of it."""


def views_disagreement(annotation: Annotation, value: int) -> ViewsDisagreement:
    """Where planes of two orientations meet, how often and how deeply their drawings of
    a structure differ.

    Two planes that are not parallel meet on a line; both say there whether the
    structure is present. The line is sampled at the finer plane's pixel size
    where it crosses both planes' pixels, and each plane is read at its nearest
    pixel: planes of any grid, spacing or orientation are compared. Where the two
    differ, the sample's depth is its distance from the nearer of the two planes'
    outlines (each measured in its own plane, mm; an empty plane has none): how far
    the drawing there would have to move to agree. The length of a differing
    stretch of the line is no measure: a line grazing the structure differs over
    centimetres where both outlines lie a pixel apart; nor is the distance from
    the farther outline, which a plane nearly tangent to the surface puts far away
    (11 mm on exact sections of a frog's kidney, against at most 1.5 mm for the
    nearer outline on the 19 development shapes' exact sections).

    Parameters
    ----------
    annotation : Annotation
    value : int
        The structure.

    Returns
    -------
    ViewsDisagreement
    """
    planes = [p for p in annotation.planes if p.annotates(value)]
    normals = np.array([p.pose.normal for p in planes]).reshape(-1, 3)
    to_pixels = [np.linalg.inv(p.pose.affine) for p in planes]
    outline: dict[int, NDArray[np.float32]] = {}  # per plane: each pixel's distance (mm)

    def depth(n: int, pixels: NDArray[np.int64]) -> NDArray[np.float32]:
        if n not in outline:
            outline[n] = _outline_distance(planes[n].mask(value), planes[n].pose.pixel_spacing)
        return outline[n][pixels[:, 0], pixels[:, 1]]

    limit = np.sin(np.radians(0.5))
    found = ViewsDisagreement()
    for n, a in enumerate(planes):
        crossing = np.linalg.norm(np.cross(normals[n], normals[n + 1 :]), axis=1) >= limit
        for m in np.flatnonzero(crossing):  # parallel planes do not meet
            k = n + 1 + int(m)
            b = planes[k]
            world = crossing_points(a, b, to_pixels[n], to_pixels[k])
            if world is None:
                continue
            at_a, at_b = _pixel_at(a, to_pixels[n], world), _pixel_at(b, to_pixels[k], world)
            one = a.mask(value)[at_a[:, 0], at_a[:, 1]]
            two = b.mask(value)[at_b[:, 0], at_b[:, 1]]
            found.drawn += int(np.count_nonzero(one | two))
            differ = np.flatnonzero(one != two)
            if differ.size == 0:
                continue
            deep = np.minimum(depth(n, at_a[differ]), depth(k, at_b[differ]))
            coarser = max(float(a.pose.pixel_spacing.max()), float(b.pose.pixel_spacing.max()))
            found.differ += int(np.count_nonzero(deep > OUTLINE_TOLERANCE * coarser))
            if deep.max() > found.deepest_mm:
                found.deepest_mm, found.planes = float(deep.max()), (a.pose, b.pose)
    return found


CONTRADICTION_MM = 4.0
"""Two planes contradict each other where one draws the structure and the other does
not, farther than this (mm) and than :data:`CONTRADICTION_PIXELS` of the coarser
plane's pixels from the nearer outline: an absent-marked plane across another plane's
drawing, or a drawing missing from one view (hand-drawn views differ by a voxel or two
at an edge)."""
CONTRADICTION_PIXELS = 3


def warn_views_disagree(annotation: Annotation, value: int, source: str, label: str) -> None:
    """Warn, in one line, when a structure's views disagree where their planes meet
    (:func:`views_disagreement`): on more than :data:`MAX_VIEW_DISAGREEMENT` of the
    points on those lines (they were drawn on different studies or frames), or on one
    point farther than :data:`CONTRADICTION_MM` from the nearer outline (a contour plane
    that says the structure is absent where a sagittal contour draws it 16 mm across
    gave a result cut at that plane with a separate cap above it, and no word).

    Parameters
    ----------
    annotation : Annotation
    value : int
        The structure.
    source : str
        The input(s) drawing it, for the message.
    label : str
        The structure's label, for the message.
    """
    found = views_disagreement(annotation, value)
    if found.planes is None:
        return
    first, second = (_plane_words(pose) for pose in found.planes)
    coarser = max(float(pose.pixel_spacing.max()) for pose in found.planes)
    if found.differ > MAX_VIEW_DISAGREEMENT * found.drawn:
        logger.warning(
            "%s: structure %s is drawn differently by its views where their planes meet "
            "(%d of %d points on those lines differ, up to %.1f mm from the outlines, on "
            "the planes %s and %s): the result blends the drawings between the planes; "
            "check that the views belong to one study and frame",
            source,
            label,
            found.differ,
            found.drawn,
            found.deepest_mm,
            first,
            second,
        )
    elif found.deepest_mm > max(CONTRADICTION_MM, CONTRADICTION_PIXELS * coarser):
        logger.warning(
            "%s: structure %s: the planes %s and %s contradict each other where they meet "
            "(one draws it there, the other not, %.1f mm from the outlines): each "
            "plane's drawing is kept on itself, and the result changes between them; "
            "check both",
            source,
            label,
            first,
            second,
            found.deepest_mm,
        )


def _plane_words(pose: PlanePose) -> str:
    """A plane in words: ``z = 22.0 mm`` on a world axis, else its offset and normal."""
    normal = pose.normal
    axis = int(np.argmax(np.abs(normal)))
    if abs(normal[axis]) > 1 - 1e-6:
        return f"{AXIS_NAMES[axis]} = {float(pose.affine[axis, 3]):.1f} mm"
    towards = ", ".join(f"{c:.2f}" for c in normal + 0.0)
    return f"at {pose.offset_mm:.1f} mm along ({towards})"


def crossing_points(
    a: AnnotatedPlane,
    b: AnnotatedPlane,
    a_inverse: NDArray[np.float64],
    b_inverse: NDArray[np.float64],
) -> NDArray[np.float64] | None:
    """World points (mm) along the line where two non-parallel planes meet, where it
    crosses both planes' pixels, at the finer pixel size; None where it crosses none."""
    direction = np.cross(a.pose.normal, b.pose.normal)
    direction /= np.linalg.norm(direction)
    point = np.linalg.solve(
        np.stack([a.pose.normal, b.pose.normal, direction]),
        [a.pose.offset_mm, b.pose.offset_mm, 0.0],
    )
    span = _line_span(a.pose.shape, a_inverse, point, direction)
    other = _line_span(b.pose.shape, b_inverse, point, direction)
    lo, hi = max(span[0], other[0]), min(span[1], other[1])
    if hi <= lo:
        return None
    step = float(min(a.pose.pixel_spacing.min(), b.pose.pixel_spacing.min()))
    return point + np.arange(lo + step / 2, hi, step)[:, None] * direction


def _line_span(
    shape: tuple[int, int],
    inverse: NDArray[np.float64],
    point: NDArray[np.float64],
    direction: NDArray[np.float64],
) -> tuple[float, float]:
    """The range of ``t`` where ``point + t direction`` (a line in a plane of ``shape``
    pixels, ``inverse`` its world → pixel affine) crosses its pixels (edges included)."""
    start = inverse[:2, :3] @ point + inverse[:2, 3]
    slope = inverse[:2, :3] @ direction
    lo, hi = -np.inf, np.inf
    for axis in range(2):
        edges = np.array([-0.5, shape[axis] - 0.5]) - start[axis]
        if abs(slope[axis]) < 1e-12:
            if not edges[0] <= 0 <= edges[1]:
                return 0.0, 0.0
            continue
        ends = np.sort(edges / slope[axis])
        lo, hi = max(lo, float(ends[0])), min(hi, float(ends[1]))
    return lo, hi


def _pixel_at(
    plane: AnnotatedPlane, inverse: NDArray[np.float64], world: NDArray[np.float64]
) -> NDArray[np.int64]:
    """The plane's pixel nearest each world point, ndarray of shape (n, 2)."""
    pixels = np.rint(world @ inverse[:2, :3].T + inverse[:2, 3]).astype(np.int64)
    return np.clip(pixels, 0, np.asarray(plane.pose.shape) - 1)


def _outline_distance(mask: NDArray[np.bool_], pixel: NDArray[np.float64]) -> NDArray[np.float32]:
    """Each pixel's distance (mm) from the drawing's outline, half-way between pixel
    centres; infinite on a plane with no outline (an empty one)."""
    from scipy import ndimage

    if not mask.any() or mask.all():  # no outline on the plane
        return np.full(mask.shape, np.inf, dtype=np.float32)
    half = 0.5 * float(np.min(pixel))
    inside = ndimage.distance_transform_edt(mask, sampling=pixel)
    outside = ndimage.distance_transform_edt(~mask, sampling=pixel)
    return (np.maximum(inside, outside) - half).astype(np.float32)


def drawn_at(
    plane: AnnotatedPlane, value: int, inverse: NDArray[np.float64], world: NDArray[np.float64]
) -> NDArray[np.bool_]:
    """Whether structure ``value`` is drawn at the plane's pixel nearest each world point
    (``inverse``: the plane's world → pixel affine)."""
    pixels = _pixel_at(plane, inverse, world)
    return plane.mask(value)[pixels[:, 0], pixels[:, 1]]
