"""Two inputs of one structure on interleaved parallel planes: do they lie together?

Parallel planes of two files never meet, so what tells drawings of crossing planes
apart (:func:`slicerecon.annotated_planes.check_drawings_meet`) cannot see a file
shifted in its plane. :func:`warn_parallel_apart` compares each section with the
sections of the other file around it.
"""

from __future__ import annotations

import bisect
import logging
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

from .annotation import AnnotatedPlane

__all__ = ["APART_RADII", "warn_parallel_apart"]

logger = logging.getLogger(__name__)


def warn_parallel_apart(
    planes: Sequence[AnnotatedPlane], origins: Sequence[str], labels: dict[int, str]
) -> None:
    """Warn when two inputs draw a structure on interleaved parallel planes and one's
    sections lie away, in their plane, from where the other's sections around them put
    the structure (files of one organ misregistered by 20 or 40 mm gave a wide, lumpy
    mesh and no word: parallel planes never meet, so :func:`check_drawings_meet` cannot
    tell).

    For each section of one input lying between two sections of the other on planes
    parallel to it, the offset in the plane between its centroid and the centroid
    interpolated linearly between those two; warned when the median offset over at
    least two such sections exceeds :data:`APART_RADII` times their median equivalent
    radius (√(area / π)).

    Parameters
    ----------
    planes : sequence of AnnotatedPlane
    origins : sequence of str
        The input each plane comes from.
    labels : dict
        Structure value → its label, for the message.
    """
    drawn: dict[int, dict[str, list[_Section]]] = {}
    for plane, origin in zip(planes, origins, strict=True):
        pixel_area = float(np.prod(plane.pose.pixel_spacing))
        for value, mask in plane.masks.items():
            count = int(np.count_nonzero(mask))
            if count:
                centre = plane.pose.to_world(np.argwhere(mask).mean(axis=0)[None])[0]
                radius = float(np.sqrt(count * pixel_area / np.pi))
                section = (plane.pose.normal, centre, radius)
                drawn.setdefault(value, {}).setdefault(origin, []).append(section)
    for value, by_input in drawn.items():
        names = sorted(by_input)
        for i, a in enumerate(names):
            for b in names[i + 1 :]:
                found = _offsets(by_input[a], by_input[b]) + _offsets(by_input[b], by_input[a])
                if len(found) < 2:
                    continue
                offset = float(np.median([o for o, _ in found]))
                radius = float(np.median([r for _, r in found]))
                if offset > APART_RADII * radius:
                    logger.warning(
                        "structure %s: its sections in %s and %s, on parallel planes between "
                        "each other's, lie %.0f mm apart in their plane (median; the sections "
                        "are %.0f mm in radius): check that the files belong to one study and "
                        "frame",
                        labels.get(value, value),
                        a,
                        b,
                        offset,
                        radius,
                    )


_Section = tuple[NDArray[np.float64], NDArray[np.float64], float]
"""A structure's section on a plane: the plane's unit normal, its centroid (world mm) and
its equivalent radius (mm)."""

APART_RADII = 0.5
"""Two inputs' interleaved sections of a structure lie apart when their centroids are
further apart in the plane than this many times the sections' equivalent radius."""


def _offsets(around: list[_Section], between: list[_Section]) -> list[tuple[float, float]]:
    """For each section of ``between`` lying between two sections of ``around`` on planes
    parallel to it: the in-plane distance (mm) from its centroid to the centroid
    interpolated between those two, and its radius."""
    out = []
    for normal, centre, radius in between:
        along = sorted(
            (float(normal @ c), c) for n, c, _ in around if abs(abs(float(n @ normal)) - 1.0) < 1e-6
        )
        here = float(normal @ centre)
        k = bisect.bisect_left([t for t, _ in along], here)
        if k == 0 or k == len(along) or along[k][0] - along[k - 1][0] < 1e-6:
            continue
        (t0, c0), (t1, c1) = along[k - 1], along[k]
        expected = c0 + (here - t0) / (t1 - t0) * (c1 - c0)
        off = centre - expected
        off -= float(off @ normal) * normal
        out.append((float(np.linalg.norm(off)), radius))
    return out
