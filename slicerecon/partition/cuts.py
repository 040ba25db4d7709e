"""The cut action: a segment between two corner points of one projection.

A cut lives in the image plane of one view (the projection along grid axis
``view``; rows and columns run along the two other grid axes, increasing). Its
end points are corner points in continuous pixel coordinates (half-integers,
see :mod:`slicerecon.corners`). The straight line through them, extruded along
the viewing axis, divides the voxel grid into two open half-spaces; the
smaller non-empty one (by voxel count of the remaining region) is the part
``W`` that the cut separates. ``docs/method.md`` (section 3) states the rules.

This module is the one implementation of those rules. The batched functions
(:func:`snap_actions`, :func:`line_sides`, :func:`choose_sides`) take a leading
batch axis ``B`` of episodes; the single-cut API (:func:`snap_action`,
:func:`side_image`, :func:`split`) calls them with ``B = 1``, and the torch
training environment (:mod:`slicerecon.policy.env`) calls them for all its
episodes at once, keeping only the voxel counting and masking on its device.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import GeometryError, InputError, OptionError
from ..sections import in_plane_axes

__all__ = [
    "Cut",
    "SnappedCuts",
    "view_shapes",
    "snap_actions",
    "snap_action",
    "cut_to_action",
    "line_sides",
    "side_image",
    "choose_sides",
    "split",
]

logger = logging.getLogger(__name__)

Point = tuple[float, float]


@dataclass(frozen=True)
class Cut:
    """A segment ``p1 -> p2`` in the image plane of one view.

    Parameters
    ----------
    view : int
        Grid axis the view looks along (0, 1, 2 = x, y, z).
    p1, p2 : tuple of float
        End points ``(row, col)`` in continuous pixel coordinates of that view
        (pixel ``(r, c)`` covers ``[r - .5, r + .5] x [c - .5, c + .5]``).
        They must differ. The order does not change what the cut does.
    """

    view: int
    p1: Point
    p2: Point

    def __post_init__(self) -> None:
        if isinstance(self.view, bool) or int(self.view) not in (0, 1, 2):
            raise OptionError(f"a cut's view must be 0, 1 or 2 (got {self.view!r})")
        p1 = tuple(float(v) for v in self.p1)
        p2 = tuple(float(v) for v in self.p2)
        if len(p1) != 2 or len(p2) != 2:
            raise GeometryError(f"cut end points need 2 coordinates (got {self.p1}, {self.p2})")
        if not np.all(np.isfinite(p1 + p2)):
            raise GeometryError("cut end points hold NaN or infinite values")
        if p1 == p2:
            raise GeometryError(f"a cut needs two distinct end points (both are {p1})")
        object.__setattr__(self, "view", int(self.view))
        object.__setattr__(self, "p1", p1)
        object.__setattr__(self, "p2", p2)

    @property
    def image_axes(self) -> tuple[int, int]:
        """Grid axes along the view's rows and columns."""
        return in_plane_axes(self.view)

    def canonical(self) -> Cut:
        """The same cut with its end points in lexicographic order (``p1 < p2``)."""
        if self.p1 <= self.p2:
            return self
        return Cut(self.view, self.p2, self.p1)

    def to_dict(self) -> dict[str, object]:
        """JSON-ready form ``{"view": int, "p1": [r, c], "p2": [r, c]}`` (pixel coordinates)."""
        return {"view": self.view, "p1": list(self.p1), "p2": list(self.p2)}

    @classmethod
    def from_dict(cls, data: dict[str, object]) -> Cut:
        """Inverse of :meth:`to_dict`."""
        try:
            return cls(int(data["view"]), tuple(data["p1"]), tuple(data["p2"]))  # type: ignore[arg-type,call-overload]
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"not a cut record: {data!r} ({exc})") from exc


def view_shapes(
    grid_shape: Sequence[int],
) -> tuple[tuple[int, int], tuple[int, int], tuple[int, int]]:
    """Image shapes ``(M, N)`` of the three views of a grid of shape ``(I, J, K)``."""
    shape = tuple(int(s) for s in grid_shape)
    if len(shape) != 3 or min(shape) < 1:
        raise GeometryError(f"grid_shape must be three positive sizes (got {grid_shape})")
    a, b, c = ((shape[p], shape[q]) for p, q in (in_plane_axes(v) for v in range(3)))
    return a, b, c


def _check_actions(actions: ArrayLike) -> NDArray[np.float64]:
    act = np.asarray(actions, dtype=np.float64)
    if act.ndim != 2 or act.shape[1] != 5:
        raise OptionError(
            f"actions are rows of 5 numbers (x1, y1, x2, y2, c) (got shape {act.shape})"
        )
    if not np.all(np.isfinite(act)):
        raise OptionError("actions hold NaN or infinite values")
    return np.clip(act, 0.0, 1.0)


def _check_shapes(image_shapes: Sequence[Sequence[int]]) -> list[tuple[int, int]]:
    shapes = [tuple(int(s) for s in shp) for shp in image_shapes]
    if len(shapes) != 3 or any(len(s) != 2 or min(s) < 1 for s in shapes):
        raise OptionError(f"image_shapes must be three (M, N) sizes (got {image_shapes})")
    return shapes  # type: ignore[return-value]


class SnappedCuts(NamedTuple):
    """Cuts of a batch of actions (:func:`snap_actions`).

    Attributes
    ----------
    view : ndarray of shape (B,), int64
        View of each cut (``min(int(3 c), 2)``).
    p1, p2 : ndarray of shape (B, 2), float64
        End points snapped to corners, ``(row, col)`` pixel coordinates, in
        the action's order (``p1`` from ``(x1, y1)``); zeros where the view
        has no corner.
    degenerate : ndarray of shape (B,), bool
        The view has no corner, or both ends snapped to the same corner: no cut.
    """

    view: NDArray[np.int64]
    p1: NDArray[np.float64]
    p2: NDArray[np.float64]
    degenerate: NDArray[np.bool_]

    def cut(self, i: int) -> Cut | None:
        """Cut ``i`` as a :class:`Cut` (None when degenerate)."""
        if bool(self.degenerate[i]):
            return None
        p1 = (float(self.p1[i, 0]), float(self.p1[i, 1]))
        p2 = (float(self.p2[i, 0]), float(self.p2[i, 1]))
        return Cut(int(self.view[i]), p1, p2)


def snap_actions(
    actions: ArrayLike,
    corners: ArrayLike,
    valid: ArrayLike,
    image_shapes: Sequence[Sequence[int]],
) -> SnappedCuts:
    """Turn a batch of policy actions into cuts between corner points.

    Parameters
    ----------
    actions : ndarray of shape (B, 5)
        ``(x1, y1, x2, y2, c)`` per episode, in ``[0, 1]`` (values outside are
        clipped). ``view = min(int(3 c), 2)``; ``(x, y)`` maps to the pixel
        point ``(x M - 0.5, y N - 0.5)`` of that view (the inverse of
        :func:`slicerecon.corners.pad_corners`), which is snapped to the
        nearest valid corner (Euclidean, ties to the first corner in order).
    corners : ndarray of shape (B, 3, K, 2)
        Corner points of each episode's views, continuous pixel coordinates;
        rows where ``valid`` is False are ignored.
    valid : ndarray of shape (B, 3, K), bool
        Which rows of ``corners`` hold a corner.
    image_shapes : sequence of 3 tuples of int
        ``(M, N)`` of each view (see :func:`view_shapes`), shared by the batch.

    Returns
    -------
    SnappedCuts

    Raises
    ------
    OptionError
        For actions that are not rows of 5 finite numbers, or arrays whose
        shapes do not match.
    """
    act = _check_actions(actions)
    shapes = np.asarray(_check_shapes(image_shapes), dtype=np.float64)
    pts = np.asarray(corners, dtype=np.float64)
    ok = np.asarray(valid, dtype=bool)
    b = act.shape[0]
    if pts.ndim != 4 or pts.shape[:2] != (b, 3) or pts.shape[3] != 2 or ok.shape != pts.shape[:3]:
        raise OptionError(
            f"corners must be (B, 3, K, 2) and valid (B, 3, K) for {b} actions "
            f"(got {pts.shape} and {ok.shape})"
        )
    if pts.shape[2] == 0:
        raise OptionError("corners need at least one row per view (mark missing rows invalid)")
    rows = np.arange(b)
    view = np.minimum((3.0 * act[:, 4]).astype(np.int64), 2)
    view_pts = pts[rows, view]  # (B, K, 2)
    view_ok = ok[rows, view]  # (B, K)
    scale = shapes[view]  # (B, 2)
    ends = []
    for target in (act[:, 0:2] * scale - 0.5, act[:, 2:4] * scale - 0.5):
        d2 = np.sum((view_pts - target[:, np.newaxis, :]) ** 2, axis=2)
        ends.append(np.argmin(np.where(view_ok, d2, np.inf), axis=1))
    i1, i2 = ends
    no_corner: NDArray[np.bool_] = ~np.any(view_ok, axis=1)
    p1 = np.where(no_corner[:, np.newaxis], 0.0, view_pts[rows, i1])
    p2 = np.where(no_corner[:, np.newaxis], 0.0, view_pts[rows, i2])
    return SnappedCuts(view, p1, p2, no_corner | (i1 == i2))


def snap_action(
    action: ArrayLike,
    corners: Sequence[ArrayLike],
    image_shapes: Sequence[Sequence[int]],
) -> Cut | None:
    """Turn a policy action into a cut between two corner points.

    One episode of :func:`snap_actions`.

    Parameters
    ----------
    action : ndarray of shape (5,)
        ``(x1, y1, x2, y2, c)`` in ``[0, 1]`` (values outside are clipped).
    corners : sequence of 3 ndarrays of shape (K_a, 2)
        Corner points of each view, continuous pixel coordinates.
    image_shapes : sequence of 3 tuples of int
        ``(M, N)`` of each view (see :func:`view_shapes`).

    Returns
    -------
    Cut or None
        None for a degenerate action: the chosen view has no corner, or both
        ends snap to the same corner.
    """
    act = np.asarray(action, dtype=np.float64)
    if act.shape != (5,):
        raise OptionError(f"an action is 5 numbers (x1, y1, x2, y2, c) (got shape {act.shape})")
    if not np.all(np.isfinite(act)):
        raise OptionError(f"an action holds NaN or infinite values: {act.tolist()}")
    if len(corners) != 3:
        raise OptionError(f"corners must hold one array per view (got {len(corners)})")
    views = [np.asarray(c, dtype=np.float64).reshape(-1, 2) for c in corners]
    k = max(1, max(v.shape[0] for v in views))
    pts = np.zeros((1, 3, k, 2))
    ok = np.zeros((1, 3, k), dtype=bool)
    for a, v in enumerate(views):
        pts[0, a, : v.shape[0]] = v
        ok[0, a, : v.shape[0]] = True
    return snap_actions(act[np.newaxis], pts, ok, image_shapes).cut(0)


def cut_to_action(cut: Cut, image_shapes: Sequence[Sequence[int]]) -> NDArray[np.float64]:
    """The action that :func:`snap_action` maps back to ``cut`` (given the same corners).

    Parameters
    ----------
    cut : Cut
        A cut whose end points are corner points.
    image_shapes : sequence of 3 tuples of int
        ``(M, N)`` of each view.

    Returns
    -------
    ndarray of shape (5,)
        ``((r1 + .5) / M, (c1 + .5) / N, (r2 + .5) / M, (c2 + .5) / N, (view + .5) / 3)``.
    """
    shapes = _check_shapes(image_shapes)
    m, n = shapes[cut.view]
    (r1, c1), (r2, c2) = cut.p1, cut.p2
    act = np.array(
        [(r1 + 0.5) / m, (c1 + 0.5) / n, (r2 + 0.5) / m, (c2 + 0.5) / n, (cut.view + 0.5) / 3.0]
    )
    return np.clip(act, 0.0, 1.0)


def line_sides(p1: ArrayLike, p2: ArrayLike, image_shape: Sequence[int]) -> NDArray[np.int8]:
    """Which side of each cut's line every pixel centre of its view lies on.

    Parameters
    ----------
    p1, p2 : ndarray of shape (B, 2)
        End points ``(row, col)`` of ``B`` cuts (pixel coordinates); their
        order does not matter (they are put in lexicographic order first).
    image_shape : tuple of int
        ``(M, N)`` of the cuts' view(s).

    Returns
    -------
    ndarray of shape (B, M, N), int8
        ``+1`` / ``-1`` for pixel centres strictly left / right of the line
        through the canonical (lexicographically ordered) end points, ``0`` on
        the line (and everywhere for equal end points).
    """
    a = np.asarray(p1, dtype=np.float64).reshape(-1, 2)
    b = np.asarray(p2, dtype=np.float64).reshape(-1, 2)
    if a.shape != b.shape:
        raise OptionError(f"p1 and p2 must have the same shape (got {a.shape} and {b.shape})")
    m, n = (int(s) for s in image_shape)
    swap = (a[:, 0] > b[:, 0]) | ((a[:, 0] == b[:, 0]) & (a[:, 1] > b[:, 1]))
    q1 = np.where(swap[:, np.newaxis], b, a)
    q2 = np.where(swap[:, np.newaxis], a, b)
    r1, c1 = q1[:, 0, np.newaxis, np.newaxis], q1[:, 1, np.newaxis, np.newaxis]
    r2, c2 = q2[:, 0, np.newaxis, np.newaxis], q2[:, 1, np.newaxis, np.newaxis]
    rows = np.arange(m, dtype=np.float64)[np.newaxis, :, np.newaxis]
    cols = np.arange(n, dtype=np.float64)[np.newaxis, np.newaxis, :]
    # Exact for half-integer end points and integer centres (small integers in float64).
    cross = (r2 - r1) * (cols - c1) - (c2 - c1) * (rows - r1)
    return np.sign(cross).astype(np.int8)


def side_image(cut: Cut, image_shape: Sequence[int]) -> NDArray[np.int8]:
    """Which side of the cut line each pixel centre of the view lies on.

    One cut of :func:`line_sides`.

    Parameters
    ----------
    cut : Cut
    image_shape : tuple of int
        ``(M, N)`` of the cut's view.

    Returns
    -------
    ndarray of shape (M, N), int8
        ``+1`` / ``-1`` for pixel centres strictly left / right of the line
        through the canonical (lexicographically ordered) end points, ``0`` on
        the line.
    """
    return line_sides(np.array([cut.p1]), np.array([cut.p2]), image_shape)[0]


def choose_sides(n_pos: ArrayLike, n_neg: ArrayLike) -> tuple[NDArray[np.int8], NDArray[np.bool_]]:
    """Which open side of each cut becomes the part ``W``.

    Parameters
    ----------
    n_pos, n_neg : ndarray of shape (B,), int
        Remaining voxels strictly on the ``+1`` / ``-1`` side of each cut
        (:func:`line_sides`; voxels take the side of their pixel).

    Returns
    -------
    keep : ndarray of shape (B,), int8
        The side with fewer remaining voxels, ``+1`` on a tie.
    removes_nothing : ndarray of shape (B,), bool
        Either side holds no remaining voxel: the cut separates nothing.
    """
    pos = np.asarray(n_pos).reshape(-1)
    neg = np.asarray(n_neg).reshape(-1)
    keep = np.where(pos <= neg, 1, -1).astype(np.int8)
    return keep, (pos == 0) | (neg == 0)


def split(remaining: ArrayLike, cut: Cut) -> tuple[NDArray[np.bool_], NDArray[np.bool_]] | None:
    """Separate the smaller side of the remaining region along a cut.

    Parameters
    ----------
    remaining : ndarray of shape (I, J, K), bool
        The region not yet assigned to a part.
    cut : Cut
        The cut; its line, extruded along ``cut.view``, splits the grid.

    Returns
    -------
    (W, rest) : tuple of ndarrays of shape (I, J, K), bool
        ``W`` is the remaining voxels strictly on the side with fewer of them
        (:func:`choose_sides`); ``rest = remaining & ~W`` keeps the other side
        and every voxel whose centre lies exactly on the line. Equal counts:
        ``W`` is the ``+1`` side of :func:`side_image`.
    None
        When either open side holds no remaining voxel (the cut removes
        nothing).
    """
    region = np.asarray(remaining)
    if region.ndim != 3 or region.dtype != np.bool_:
        raise InputError(
            f"remaining must be a 3-D boolean array (got {region.ndim}-D {region.dtype})"
        )
    a, b = cut.image_axes
    sides = side_image(cut, (region.shape[a], region.shape[b]))
    column_counts = np.count_nonzero(region, axis=cut.view)  # (M, N) voxels per pixel
    n_pos = int(column_counts[sides > 0].sum())
    n_neg = int(column_counts[sides < 0].sum())
    keep, removes_nothing = choose_sides([n_pos], [n_neg])
    if removes_nothing[0]:
        return None
    w = region & np.expand_dims(sides == keep[0], axis=cut.view)
    logger.debug("split: view %d, sides %d / %d voxels", cut.view, n_pos, n_neg)
    return w, region & ~w
