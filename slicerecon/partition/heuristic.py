"""The heuristic expert of the Cut-and-Approximate paper.

For each view: pair every corner point with its nearest neighbour (in that
view) to get segments; keep the segments whose removal from the silhouette
increases its number of connected components; score each kept segment by the
area its pieces leave empty inside their bounding boxes; sort the segments of
all three views by that score. The expert's action is the best segment that
actually removes something from the remaining region. The expert is a pure
function of the state, so behaviour cloning can query it anywhere
(``pi^h(s)``).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import ndimage

from ..errors import InputError, OptionError
from ..sections import Projections
from .cuts import Cut, cut_to_action, split
from .state import PartitionState

__all__ = [
    "Segment",
    "segment_band",
    "nearest_neighbour_pairs",
    "expert_segments",
    "expert_cuts",
    "expert_cut",
    "run_expert",
    "expert_action",
]

logger = logging.getLogger(__name__)

_EIGHT = np.ones((3, 3), dtype=bool)

Point = tuple[float, float]


class Segment(NamedTuple):
    """A candidate cut of the heuristic expert.

    Attributes
    ----------
    view : int
        Grid axis of the view (0, 1, 2).
    p1, p2 : tuple of float
        End points (corner points, continuous pixel coordinates), ``p1 < p2``.
    cost : float
        ``A``: pixels inside the axis-aligned bounding boxes of the pieces the
        segment splits its silhouette component into that the pieces do not
        cover, summed over the pieces. Lower is better.
    """

    view: int
    p1: Point
    p2: Point
    cost: float


def segment_band(
    p1: Sequence[float], p2: Sequence[float], image_shape: Sequence[int], *, radius: float = 0.75
) -> NDArray[np.bool_]:
    """Pixels whose centre lies within ``radius`` of the segment ``p1 - p2``.

    With the default radius 0.75 the band is 1-2 pixels wide and no pair of
    8-connected pixels can straddle it (their centres are at most sqrt(2) apart
    across the line, less than twice the radius).

    Parameters
    ----------
    p1, p2 : sequence of 2 floats
        End points, continuous pixel coordinates.
    image_shape : tuple of int
        ``(M, N)``.
    radius : float, optional
        Half-width of the band, pixels.

    Returns
    -------
    ndarray of shape (M, N), bool
    """
    m, n = (int(s) for s in image_shape)
    a = np.asarray(p1, dtype=np.float64)
    b = np.asarray(p2, dtype=np.float64)
    band = np.zeros((m, n), dtype=bool)
    lo = np.floor(np.minimum(a, b) - radius).astype(int)
    hi = np.ceil(np.maximum(a, b) + radius).astype(int) + 1
    r0, c0 = max(lo[0], 0), max(lo[1], 0)
    r1, c1 = min(hi[0], m), min(hi[1], n)
    if r0 >= r1 or c0 >= c1:
        return band
    rows, cols = np.mgrid[r0:r1, c0:c1].astype(np.float64)
    d = b - a
    length2 = float(d @ d)
    t = ((rows - a[0]) * d[0] + (cols - a[1]) * d[1]) / length2 if length2 > 0 else 0.0
    t = np.clip(t, 0.0, 1.0)
    dist2 = (rows - a[0] - t * d[0]) ** 2 + (cols - a[1] - t * d[1]) ** 2
    band[r0:r1, c0:c1] = dist2 <= radius * radius + 1e-9
    return band


def nearest_neighbour_pairs(points: ArrayLike) -> list[tuple[int, int]]:
    """Unordered pairs ``(i, j)``, ``i < j``, joining each point to its nearest neighbour.

    Ties go to the lower index. The list is sorted and has no duplicates.

    Parameters
    ----------
    points : ndarray of shape (K, 2)

    Returns
    -------
    list of tuple of int
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    if pts.shape[0] < 2:
        return []
    d2 = np.sum((pts[:, np.newaxis, :] - pts[np.newaxis, :, :]) ** 2, axis=-1)
    np.fill_diagonal(d2, np.inf)
    nearest = np.argmin(d2, axis=1)
    return sorted({(min(i, int(j)), max(i, int(j))) for i, j in enumerate(nearest)})


def _components(image: NDArray[np.bool_], min_px: int) -> tuple[NDArray[np.int32], list[int]]:
    labels, n = ndimage.label(image, structure=_EIGHT)
    sizes = np.bincount(labels.ravel(), minlength=n + 1)
    return labels, [i for i in range(1, n + 1) if sizes[i] >= min_px]


def _waste(piece: NDArray[np.bool_]) -> int:
    rows = np.flatnonzero(piece.any(axis=1))
    cols = np.flatnonzero(piece.any(axis=0))
    box = (rows[-1] - rows[0] + 1) * (cols[-1] - cols[0] + 1)
    return int(box - np.count_nonzero(piece))


def _view_segments(
    view: int, image: NDArray[np.bool_], points: NDArray[np.float64], radius: float, min_px: int
) -> list[Segment]:
    out: list[Segment] = []
    pairs = nearest_neighbour_pairs(points)
    if not pairs:
        return out
    labels, kept = _components(image, min_px)
    for i, j in pairs:
        p1 = (float(points[i, 0]), float(points[i, 1]))
        p2 = (float(points[j, 0]), float(points[j, 1]))
        band = segment_band(p1, p2, image.shape, radius=radius)
        touched = np.unique(labels[band & image])
        touched = touched[touched > 0]
        if touched.size == 0:
            continue
        cut_image = image & ~band
        new_labels, new_kept = _components(cut_image, min_px)
        if len(new_kept) <= len(kept):
            continue
        # The pieces of the components the segment crosses.
        region = np.isin(labels, touched)
        cost = 0
        for lab in new_kept:
            piece = new_labels == lab
            if (piece & region).any():
                cost += _waste(piece)
        out.append(Segment(view, min(p1, p2), max(p1, p2), float(cost)))
    return out


def expert_segments(
    projections: Projections | Sequence[ArrayLike],
    corners: Sequence[ArrayLike],
    *,
    band_radius: float = 0.75,
    min_component_px: int = 4,
) -> list[Segment]:
    """The heuristic expert's candidate cuts, best first.

    Parameters
    ----------
    projections : Projections or sequence of 3 ndarrays of shape (M_a, N_a), bool
        The silhouettes (of the remaining region), view ``a`` along grid axis ``a``.
    corners : sequence of 3 ndarrays of shape (K_a, 2)
        Corner points of each view (:func:`slicerecon.corners.harris_corners`).
    band_radius : float, optional
        Half-width, pixels, of the band a segment removes (:func:`segment_band`).
    min_component_px : int, optional
        Connected components (8-connected) smaller than this many pixels are
        ignored, both when counting components and in the cost, so that slivers
        left at a segment's ends do not count as a split.

    Returns
    -------
    list of Segment
        Segments whose removal increases the number of components, sorted by
        ``(cost, view, p1, p2)``.
    """
    if isinstance(projections, Projections):
        images = [v.image for v in projections.views]
    else:
        images = [np.asarray(img) for img in projections]
    if len(images) != 3 or len(corners) != 3:
        raise InputError("expert_segments needs three silhouettes and three corner arrays")
    if not band_radius > 0:
        raise OptionError(f"band_radius must be > 0 (got {band_radius})")
    if int(min_component_px) < 1:
        raise OptionError(f"min_component_px must be >= 1 (got {min_component_px})")
    segments: list[Segment] = []
    for view, (img, pts) in enumerate(zip(images, corners, strict=True)):
        image = np.asarray(img, dtype=bool)
        if image.ndim != 2:
            raise InputError(f"silhouette {view} must be 2-D (got shape {image.shape})")
        points = np.asarray(pts, dtype=np.float64).reshape(-1, 2)
        segments.extend(
            _view_segments(view, image, points, float(band_radius), int(min_component_px))
        )
    segments.sort(key=lambda s: (s.cost, s.view, s.p1, s.p2))
    logger.debug("expert_segments: %d splitting segments", len(segments))
    return segments


def expert_cuts(state: PartitionState, count: int) -> list[Cut]:
    """The expert's first ``count`` segments (best first) whose cut removes something.

    Parameters
    ----------
    state : PartitionState
    count : int
        At most this many cuts.

    Returns
    -------
    list of Cut
        Empty when no segment splits a silhouette or every splitting
        segment's line leaves one side of the remaining region empty.

    Raises
    ------
    OptionError
        For ``count < 1``.
    """
    if int(count) < 1:
        raise OptionError(f"count must be >= 1 (got {count})")
    cuts: list[Cut] = []
    for seg in expert_segments(state.projections(), state.corners()):
        cut = Cut(seg.view, seg.p1, seg.p2)
        if split(state.remaining, cut) is not None:
            cuts.append(cut)
            if len(cuts) == int(count):
                break
    return cuts


def expert_cut(state: PartitionState) -> Cut | None:
    """The best expert segment (on the current remaining region) that removes something.

    Returns
    -------
    Cut or None
        None when no segment splits a silhouette or every splitting segment's
        line leaves one side of the remaining region empty.
    """
    cuts = expert_cuts(state, 1)
    return cuts[0] if cuts else None


def run_expert(state: PartitionState) -> PartitionState:
    """Apply the expert's cut until the episode ends or it has no useful cut (in place).

    Returns
    -------
    PartitionState
        ``state``, stepped; :meth:`~PartitionState.finish` is left to the caller.
    """
    while not state.done:
        cut = expert_cut(state)
        if cut is None:
            break
        state.apply_cut(cut)
    return state


def expert_action(state: PartitionState) -> NDArray[np.float64] | None:
    """The expert's action ``pi^h(s)``: the normalised 5-tuple of :func:`expert_cut`.

    Returns
    -------
    ndarray of shape (5,) or None
        ``(x1, y1, x2, y2, c)`` in ``[0, 1]``; ``state.step(action)`` applies
        exactly :func:`expert_cut`'s cut. None when nothing useful remains.
    """
    cut = expert_cut(state)
    if cut is None:
        return None
    return cut_to_action(cut, state.image_shapes)
