"""Closed polygons on planes of any orientation → an :class:`~slicerecon.annotation.Annotation`.

Contours drawn in several orientations (an RTSTRUCT with axial plus sagittal
contours; a radial set of planes through an organ's long axis; short-axis plus
tilted long-axis cardiac views) are grouped into planes and rasterized each in
its own plane (:func:`annotation_from_polygons`):

1. **Polygons.** Each polygon's normal and area come from Newell's method
   (:func:`slicerecon.io.polygons.polygon_normal`); polygons of (numerically)
   zero area are skipped with a warning; every vertex must lie within
   ``max(0.01 mm, 1e-4 × diameter)`` of its polygon's plane.
2. **Orientations.** Normals are grouped when parallel (up to sign) within
   :data:`ANGLE_TOLERANCE_DEG`; a group's normal is its first polygon's,
   signed so that its largest world component is positive.
3. **Planes.** Within an orientation, polygons whose centroids lie within
   ``plane_tolerance_mm`` of each other along the normal are one plane.
4. **Reference grid.** The image grid when given (an RTSTRUCT's series);
   otherwise a grid aligned with the world axes around every polygon, with
   cubic voxels of ``pixel_spacing`` mm (default: the longest extent / 256),
   and :data:`~slicerecon.io.polygons.MARGIN_PX` voxels of margin.
5. **Pixels.** A plane perpendicular to a grid axis is rasterized on the
   grid's own pixels (its position along the axis may be fractional). Any
   other plane gets its own pixel grid: in-plane axes ``u`` (the world axis
   most perpendicular to the normal, projected onto the plane) and
   ``v = normal × u``, square pixels of the grid's smallest spacing, covering
   its orientation's polygons with a margin. Polygons are filled by the
   even-odd rule (:func:`slicerecon.io.polygons.rasterize_polygons`).

Every plane annotates the structures drawn on it (an RTSTRUCT's ROIs are
contoured on their own planes); ``exclusive`` says whether the structures are
a partition.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..annotation import AnnotatedPlane, Annotation, PlanePose, plane_pose, smallest_gap
from ..errors import EmptyMaskError, GeometryError
from ..labels import Structure
from ..sections import check_affine, in_plane_axes
from .limits import DEFAULT_MEMORY_BUDGET_GB, check_coordinates, check_grid
from .polygons import (
    DEFAULT_PIXELS_ACROSS,
    MARGIN_PX,
    PLANARITY_REL,
    PLANE_TOLERANCE_MM,
    polygon_normal,
    rasterize_polygons,
    rings_that_cross,
    warn_crossing,
)

__all__ = [
    "ANGLE_TOLERANCE_DEG",
    "annotation_from_polygons",
    "grid_axis_of",
    "orientation_count",
    "plane_count",
]

logger = logging.getLogger(__name__)

ANGLE_TOLERANCE_DEG = 0.5
"""Polygons whose normals differ by less than this (up to sign) share an orientation."""


def _signed(normal: NDArray[np.float64]) -> NDArray[np.float64]:
    """The normal signed so that its largest world component is positive."""
    return normal if normal[int(np.argmax(np.abs(normal)))] > 0 else -normal


def _groups(normals: list[NDArray[np.float64]]) -> list[tuple[NDArray[np.float64], list[int]]]:
    limit = np.sin(np.radians(ANGLE_TOLERANCE_DEG))
    groups: list[tuple[NDArray[np.float64], list[int]]] = []
    for n, normal in enumerate(normals):
        for common, members in groups:
            if np.linalg.norm(np.cross(common, normal)) < limit:
                members.append(n)
                break
        else:
            groups.append((_signed(normal), [n]))
    return groups


def _oriented(
    polygons: Sequence[ArrayLike],
) -> tuple[list[NDArray[np.float64]], list[tuple[NDArray[np.float64], list[int]]]]:
    """The polygons that have an area, and their orientations (:func:`_groups`)."""
    kept, normals = [], []
    for points in polygons:
        normal, area = polygon_normal(points)
        if area > 0:
            kept.append(np.asarray(points, dtype=np.float64))
            normals.append(normal)
    return kept, _groups(normals)


def orientation_count(polygons: Sequence[ArrayLike]) -> int:
    """How many plane orientations a set of polygons has (0 when none has an area)."""
    return len(_oriented(polygons)[1])


def plane_count(
    polygons: Sequence[ArrayLike], plane_tolerance_mm: float = PLANE_TOLERANCE_MM
) -> int:
    """How many planes a set of polygons lies on, as :func:`annotation_from_polygons` groups
    them: by orientation, then by offset along the normal (``plane_tolerance_mm``)."""
    kept, groups = _oriented(polygons)
    count = 0
    for normal, members in groups:
        offsets = np.sort([float(kept[m].mean(axis=0) @ normal) for m in members])
        count += 1 + int(np.count_nonzero(np.diff(offsets) > plane_tolerance_mm))
    return count


def _built_reference(
    points: NDArray[np.float64], pixel_spacing: float | None, reach_mm: float = 0.0
) -> tuple[NDArray[np.float64], tuple[int, int, int]]:
    """An isotropic grid around ``points`` and ``reach_mm`` beyond them (how far a
    structure goes on beyond its end contours), :data:`MARGIN_PX` pixels of margin."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    step = pixel_spacing or float(np.max(hi - lo)) / DEFAULT_PIXELS_ACROSS
    if not np.isfinite(step) or step <= 0:
        raise GeometryError("the contours span no extent: cannot build a grid around them")
    lo, hi = lo - reach_mm, hi + reach_mm
    shape = tuple(int(v) for v in np.ceil((hi - lo) / step) + 1 + 2 * MARGIN_PX)
    affine = np.diag([step, step, step, 1.0])
    affine[:3, 3] = lo - MARGIN_PX * step
    return affine, shape  # type: ignore[return-value]


def _half_gap(items: list[tuple[int, NDArray[np.float64], NDArray[np.float64]]]) -> float:
    """Half the largest of the structures' smallest gaps between their planes, mm, over
    every orientation (``items``: value, points, unit normal)."""
    largest = 0.0
    for value in {v for v, _, _ in items}:
        own = [(p, n) for v, p, n in items if v == value]
        for normal, members in _groups([n for _, n in own]):
            gap = smallest_gap([own[m][0].mean(axis=0) @ normal for m in members])
            largest = max(largest, gap or 0.0)
    return largest / 2


def grid_axis_of(affine: ArrayLike, normal: ArrayLike) -> int | None:
    """The grid axis whose slices are parallel to planes of unit ``normal`` (within
    :data:`ANGLE_TOLERANCE_DEG`), or None: planes oblique to the grid.

    Parameters
    ----------
    affine : array_like of shape (4, 4)
        Voxel index → world mm.
    normal : array_like of shape (3,)
        Unit normal of the planes.

    Returns
    -------
    int or None
    """
    affine = np.asarray(affine, dtype=np.float64)
    normal = np.asarray(normal, dtype=np.float64)
    limit = np.sin(np.radians(ANGLE_TOLERANCE_DEG))
    for axis in range(3):
        a, b = in_plane_axes(axis)
        grid_normal = np.cross(affine[:3, a], affine[:3, b])
        grid_normal /= np.linalg.norm(grid_normal)
        if np.linalg.norm(np.cross(grid_normal, normal)) < limit:
            return axis
    return None


def annotation_from_polygons(
    structures: Sequence[Structure],
    polygons: Sequence[Sequence[ArrayLike]],
    *,
    reference: tuple[ArrayLike, Sequence[int]] | None = None,
    pixel_spacing: float | None = None,
    coordinates: str = "LPS",
    exclusive: bool = False,
    plane_tolerance_mm: float = PLANE_TOLERANCE_MM,
    memory_budget_gb: float = DEFAULT_MEMORY_BUDGET_GB,
    source: str = "",
) -> Annotation:
    """Polygons of several structures, on planes of any orientation, as an annotation.

    Parameters
    ----------
    structures : sequence of Structure
    polygons : sequence of sequence of array_like of shape (N, 3)
        Each structure's closed polygons, world mm (closed implicitly).
    reference : (affine, shape), optional
        The image grid the contours were drawn on (its planes keep its pixels).
    pixel_spacing : float, optional
        Voxel size of a built grid, mm (no ``reference``).
    coordinates : {"LPS", "RAS"}
    exclusive : bool
        Whether the structures form a partition.
    plane_tolerance_mm : float
        Polygons this close along their normal are on one plane.
    memory_budget_gb : float
        The reference grid is checked against it (:func:`slicerecon.io.limits.check_grid`).
    source : str
        How the input was read, in words.

    Returns
    -------
    Annotation

    Raises
    ------
    EmptyMaskError
        No polygon encloses an area.
    GeometryError
        A polygon that is not planar.
    MemoryBudgetError
        A grid over the budget.
    """
    items: list[tuple[int, NDArray[np.float64], NDArray[np.float64]]] = []
    for structure, own in zip(structures, polygons, strict=True):
        for raw in own:
            points = np.asarray(raw, dtype=np.float64).reshape(-1, 3)
            check_coordinates(points, what=f"structure {structure.label}")
            normal, area = polygon_normal(points)
            if area <= 0:
                logger.warning("structure %s: a polygon encloses no area; skipped", structure.label)
                continue
            offsets = (points - points.mean(axis=0)) @ normal
            diameter = float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))
            if np.max(np.abs(offsets)) > max(plane_tolerance_mm, PLANARITY_REL * diameter):
                raise GeometryError(
                    f"a polygon of structure {structure.label} is not planar: a vertex lies "
                    f"{np.max(np.abs(offsets)):.3g} mm off its plane"
                )
            items.append((structure.value, points, normal))
    if not items:
        raise EmptyMaskError("no polygon encloses an area")
    everything = np.concatenate([p for _, p, _ in items])
    if reference is not None:
        affine, shape = check_affine(reference[0]), tuple(int(s) for s in reference[1])
    else:
        # each structure ends half its own plane gap beyond its end contours (gap_ends)
        affine, shape = _built_reference(everything, pixel_spacing, _half_gap(items))
    check_grid(shape, what="the contours' grid", memory_budget_gb=memory_budget_gb)
    planes: list[AnnotatedPlane] = []
    for normal, members in _groups([n for _, _, n in items]):
        chosen = [items[m] for m in members]
        axis = grid_axis_of(affine, normal)
        poses = _plane_poses(chosen, normal, affine, shape, axis, plane_tolerance_mm)
        for pose, polys in poses:
            to_px = np.linalg.inv(pose.affine)
            masks: dict[int, NDArray[np.bool_]] = {}
            for value in dict.fromkeys(v for v, _ in polys):
                own = [(p @ to_px[:3, :3].T + to_px[:3, 3])[:, :2] for v, p in polys if v == value]
                masks[value] = rasterize_polygons(own, pose.shape)
                pair = rings_that_cross(own, pose.shape)
                if pair is not None:
                    where = ", ".join(f"{c:.4g}" for c in pose.affine[:3, 3])
                    names = [
                        f"contour {n + 1} of structure {value} on the plane at {where} mm"
                        for n in range(len(own))
                    ]
                    warn_crossing(names, pair)
            drawn = frozenset(v for v, _ in polys)
            planes.append(AnnotatedPlane(pose, masks, drawn))
    return Annotation(
        tuple(planes),
        tuple(structures),
        affine,
        shape,  # type: ignore[arg-type]
        coordinates,
        exclusive,
        source,
    )


def _plane_poses(
    items: list[tuple[int, NDArray[np.float64], NDArray[np.float64]]],
    normal: NDArray[np.float64],
    affine: NDArray[np.float64],
    shape: Sequence[int],
    axis: int | None,
    tolerance_mm: float,
) -> list[tuple[PlanePose, list[tuple[int, NDArray[np.float64]]]]]:
    """The planes of one orientation: each pose with the polygons ``(value, points)`` on it."""
    offsets = np.array([float(p.mean(axis=0) @ normal) for _, p, _ in items])
    order = np.argsort(offsets, kind="stable")
    planes: list[list[int]] = []
    for n in order:
        if planes and offsets[n] - offsets[planes[-1][-1]] <= tolerance_mm:
            planes[-1].append(int(n))
        else:
            planes.append([int(n)])
    out = []
    if axis is not None:
        inverse = np.linalg.inv(affine)
        for members in planes:
            centre = np.mean([items[m][1].mean(axis=0) for m in members], axis=0)
            index = float((inverse[:3, :3] @ centre + inverse[:3, 3])[axis])
            if abs(index - round(index)) * np.linalg.norm(affine[:3, axis]) <= tolerance_mm:
                index = float(round(index))
            pose = plane_pose(affine, shape, axis, index)
            out.append((pose, [(items[m][0], items[m][1]) for m in members]))
        return out
    step = float(np.min(np.linalg.norm(affine[:3, :3], axis=0)))
    world = np.eye(3)[int(np.argmin(np.abs(normal)))]
    u = world - (world @ normal) * normal
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    projected = np.concatenate([p for _, p, _ in items])
    coords_u, coords_v = projected @ u, projected @ v
    u0 = coords_u.min() - MARGIN_PX * step
    v0 = coords_v.min() - MARGIN_PX * step
    size = (
        int(np.ceil((coords_u.max() - u0) / step)) + MARGIN_PX + 1,
        int(np.ceil((coords_v.max() - v0) / step)) + MARGIN_PX + 1,
    )
    for members in planes:
        offset = float(np.mean([offsets[m] for m in members]))
        pose = np.eye(4)
        pose[:3, 0] = u * step
        pose[:3, 1] = v * step
        pose[:3, 2] = normal
        pose[:3, 3] = u0 * u + v0 * v + offset * normal
        out.append((PlanePose(pose, size), [(items[m][0], items[m][1]) for m in members]))
    return out
