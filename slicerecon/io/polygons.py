"""Closed polygons on parallel planes ↔ :class:`~slicerecon.sections.CrossSections`.

This is the common core of the contour inputs (contour files, DICOM RTSTRUCT):
polygons given in world millimetres are grouped into planes, placed on a voxel
grid and rasterized.

Steps of :func:`sections_from_polygons`
---------------------------------------
1. **Normals.** Each polygon's normal and area come from Newell's method (the
   vector area ``½ Σ p_i × p_{i+1}``). Polygons of (numerically) zero area
   enclose nothing; they are skipped with a warning.
2. **Parallel planes.** Every normal must be parallel (up to sign) to the common
   normal within ``axis_tolerance_deg``. The common normal is the given
   ``normal``, else the sum of the sign-aligned vector areas (so large polygons
   weigh more), oriented so that its largest world component is positive.
3. **Planarity.** Every vertex must lie within
   ``max(plane_tolerance_mm, 1e-4 × polygon diameter)`` of its polygon's own
   plane. The relative term absorbs coordinates written with a fixed number of
   significant digits; the absolute one, coordinates rounded to 0.01 mm.
4. **Planes.** Polygons are grouped by their centroid position along the common
   normal: sorted positions closer than ``plane_tolerance_mm`` to their
   neighbour form one plane, placed at the mean of its polygons' positions.
5. **Grid.** With ``reference = (affine, shape)`` (the image grid the contours
   were drawn on) the planes are perpendicular to the grid axis whose plane
   normal is parallel to the common normal, and plane indices are fractional
   index positions along that axis (snapped to the nearest integer when within
   ``plane_tolerance_mm`` of it). Otherwise a grid is built, see below.
6. **Rasterization.** A pixel is foreground when its *centre* is inside the
   polygons of its plane by the **even-odd rule** over all of them together, so
   nested polygons make holes (and islands in holes), whatever their winding.
   Centres exactly on an edge follow a half-open rule: a polygon spanning
   ``[a, b]`` along a pixel axis covers the centres ``a <= c < b``.

Built grid (no ``reference``)
-----------------------------
* Axis 2 (``k``) runs along the common normal, one step = the smallest gap
  between consecutive planes (1 mm for a single plane); plane ``p`` sits at
  index ``(position_p - position_0) / gap``, fractional for irregular gaps.
* The in-plane axes are the two world axes closest to the plane, projected
  onto it and taken cyclically after the normal's dominant world axis: (y, z)
  for a normal along ±x, (z, x) along ±y, (x, y) along ±z; the second is
  ``normal × first``, so the grid is right-handed, and axis-aligned polygons
  give an axis-aligned grid.
* In-plane pixel size ``pixel_spacing`` mm, by default the longest in-plane
  extent of all polygons / 256 (:data:`DEFAULT_PIXELS_ACROSS`).
* The lowest corner of the polygons' in-plane bounding box falls on a pixel
  *corner*, with a margin of 2 pixels (:data:`MARGIN_PX`) on every side. A
  polygon traced along pixel edges therefore covers whole pixels, and the
  contours of a mask (which run half a pixel outside its outermost pixel
  centres) rasterize back onto the mask's own pixels at the mask's spacing.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import EmptyMaskError, GeometryError, InputError, OptionError
from ..sections import CrossSections, in_plane_axes
from .limits import DEFAULT_MEMORY_BUDGET_GB, check_coordinates, check_grid

__all__ = [
    "DEFAULT_PIXELS_ACROSS",
    "MARGIN_PX",
    "PLANE_TOLERANCE_MM",
    "encloses_area",
    "polygon_normal",
    "polygons_from_sections",
    "rasterize_polygons",
    "sections_from_polygons",
]

logger = logging.getLogger(__name__)

DEFAULT_PIXELS_ACROSS = 256
"""Default in-plane resolution: the longest in-plane extent is split into this many pixels."""
MARGIN_PX = 2
"""Background pixels kept around the polygons on a built grid."""
PLANARITY_REL = 1e-4
"""Allowed distance of a vertex from its polygon's plane, relative to the polygon diameter."""
PLANE_TOLERANCE_MM = 0.01
"""Polygons this close along their normal are on one plane (the default of every reader)."""
DEGENERATE_REL = 1e-9
"""A polygon whose area is below this times its squared diameter is degenerate."""
MAX_PIXELS_PER_AXIS = 16384
"""Refuse built grids with more pixels than this along an in-plane axis."""


@dataclass(frozen=True)
class _Polygon:
    points: NDArray[np.float64]  # (N, 3) world mm
    name: str
    vector_area: NDArray[np.float64]  # (3,) Newell vector area, mm²
    diameter: float  # mm, largest bounding-box diagonal


@dataclass(frozen=True)
class _Grid:
    affine: NDArray[np.float64]
    shape: tuple[int, int, int]
    axis: int


def polygon_normal(points: ArrayLike) -> tuple[NDArray[np.float64], float]:
    """Unit normal and area of a planar polygon by Newell's method.

    Parameters
    ----------
    points : array_like of shape (N, 3)
        Vertices in order, mm; the polygon is closed implicitly.

    Returns
    -------
    normal : ndarray of shape (3,)
        Unit normal; the polygon winds counter-clockwise around it. All zeros
        when the polygon has zero area.
    area : float
        Enclosed area, mm² (for a self-intersecting polygon: the magnitude of
        the vector area).
    """
    pts = np.asarray(points, dtype=np.float64)
    vector = _vector_area(pts)
    area = float(np.linalg.norm(vector))
    return (vector / area if area > 0 else np.zeros(3)), area


def encloses_area(points: ArrayLike) -> bool:
    """Whether a polygon encloses an area: False for collinear points, a repeated point, or
    lobes of opposite turn that cancel (a symmetric figure 8).

    Parameters
    ----------
    points : array_like of shape (N, 3)
        Vertices, mm.

    Returns
    -------
    bool
    """
    pts = np.asarray(points, dtype=np.float64)
    diameter = float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0)))
    return bool(np.linalg.norm(_vector_area(pts)) > DEGENERATE_REL * diameter**2)


def _vector_area(points: NDArray[np.float64]) -> NDArray[np.float64]:
    centred = points - points.mean(axis=0)
    return 0.5 * np.cross(centred, np.roll(centred, -1, axis=0)).sum(axis=0)


def _as_polygons(polygons: Sequence[ArrayLike], names: Sequence[str] | None) -> list[_Polygon]:
    items = list(polygons)
    if names is not None and len(names) != len(items):
        raise OptionError(f"polygon_names has {len(names)} names for {len(items)} polygons")
    out: list[_Polygon] = []
    for number, raw in enumerate(items):
        name = names[number] if names is not None else f"polygon {number}"
        try:
            pts = np.asarray(raw, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise InputError(f"{name}: not an array of numbers ({exc})") from exc
        if pts.ndim != 2 or pts.shape[1] != 3:
            raise InputError(f"{name}: expected an (N, 3) array of x, y, z (got {pts.shape})")
        if pts.shape[0] < 3:
            raise InputError(f"{name}: a polygon needs at least 3 points (got {pts.shape[0]})")
        if not np.all(np.isfinite(pts)):
            raise InputError(f"{name}: holds NaN or infinite coordinates")
        check_coordinates(pts, what=name)
        diameter = float(np.linalg.norm(pts.max(axis=0) - pts.min(axis=0)))
        vector = _vector_area(pts)
        if not encloses_area(pts):
            logger.warning(
                "%s encloses no area (its points are collinear, or it crosses itself into "
                "lobes of opposite turn, a figure 8); skipped",
                name,
            )
            continue
        out.append(_Polygon(pts, name, vector, diameter))
    return out


def _unit(vector: ArrayLike, what: str) -> NDArray[np.float64]:
    try:
        v = np.asarray(vector, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        v = np.zeros(0)
    if v.shape != (3,) or not np.all(np.isfinite(v)) or np.linalg.norm(v) == 0:
        raise OptionError(f"{what} must be a non-zero vector of 3 finite numbers (got {vector!r})")
    return v / np.linalg.norm(v)


def _angle_deg(a: NDArray[np.float64], b: NDArray[np.float64]) -> float:
    """Angle between two lines (unit vectors, sign ignored), degrees."""
    return math.degrees(math.acos(min(1.0, abs(float(np.dot(a, b))))))


def _common_normal(
    polys: list[_Polygon], normal: NDArray[np.float64] | None, tolerance_deg: float
) -> NDArray[np.float64]:
    if normal is None:
        largest = max(polys, key=lambda p: float(np.linalg.norm(p.vector_area)))
        total = np.zeros(3)
        for p in polys:
            sign = 1.0 if np.dot(p.vector_area, largest.vector_area) >= 0 else -1.0
            total += sign * p.vector_area
        common = total / np.linalg.norm(total)
        if common[np.argmax(np.abs(common))] < 0:
            common = -common
        against = "the common normal"
    else:
        common = normal
        against = f"the given normal {np.round(normal, 6).tolist()}"
    tilts = [_angle_deg(p.vector_area / np.linalg.norm(p.vector_area), common) for p in polys]
    worst = int(np.argmax(tilts))
    if tilts[worst] > tolerance_deg:
        raise GeometryError(
            f"contours are not on parallel planes: {polys[worst].name} is tilted "
            f"{tilts[worst]:.3g}° from {against} (tolerance {tolerance_deg:g}°); "
            "slicerecon needs every contour on one stack of parallel planes"
        )
    return common


def _check_planar(polys: list[_Polygon], tolerance_mm: float) -> None:
    for p in polys:
        n = p.vector_area / np.linalg.norm(p.vector_area)
        off = np.abs((p.points - p.points.mean(axis=0)) @ n)
        allowed = max(tolerance_mm, PLANARITY_REL * p.diameter)
        if off.max() > allowed:
            raise GeometryError(
                f"{p.name} is not planar: a vertex lies {off.max():.4g} mm off its plane "
                f"(tolerance {allowed:.3g} mm); contours must be flat"
            )


def _group(positions: NDArray[np.float64], tolerance_mm: float) -> list[NDArray[np.int64]]:
    """Groups of entries whose sorted positions chain within ``tolerance_mm``."""
    order = np.argsort(positions, kind="stable")
    breaks = np.flatnonzero(np.diff(positions[order]) > tolerance_mm) + 1
    return [g.astype(np.int64) for g in np.split(order, breaks)]


def _check_reference(reference: tuple[ArrayLike, Sequence[int]]) -> _Grid:
    try:
        affine_in, shape_in = reference
    except (TypeError, ValueError) as exc:
        raise OptionError("reference must be a pair (affine (4, 4), shape (I, J, K))") from exc
    affine = np.asarray(affine_in, dtype=np.float64)
    if affine.shape != (4, 4) or not np.all(np.isfinite(affine)):
        raise OptionError(f"reference affine must be a finite 4x4 matrix (got {affine.shape})")
    if abs(np.linalg.det(affine[:3, :3])) < 1e-12:
        raise OptionError("reference affine is singular")
    shape = tuple(int(s) for s in shape_in)
    if len(shape) != 3 or min(shape) < 1:
        raise OptionError(f"reference shape must be three positive sizes (got {shape_in})")
    return _Grid(affine, (shape[0], shape[1], shape[2]), axis=-1)


def _grid_axis_normal(affine: NDArray[np.float64], axis: int) -> NDArray[np.float64]:
    """Unit normal of the planes perpendicular to grid ``axis``, towards increasing index."""
    a, b = in_plane_axes(axis)
    n = np.cross(affine[:3, a], affine[:3, b])
    n /= np.linalg.norm(n)
    return n if np.dot(n, affine[:3, axis]) > 0 else -n


def _reference_axis(
    grid: _Grid, normal: NDArray[np.float64], tolerance_deg: float
) -> tuple[_Grid, NDArray[np.float64]]:
    normals = [_grid_axis_normal(grid.affine, ax) for ax in range(3)]
    tilts = [_angle_deg(n, normal) for n in normals]
    axis = int(np.argmin(tilts))
    if tilts[axis] > tolerance_deg:
        raise GeometryError(
            f"the contour planes (normal {np.round(normal, 4).tolist()}) are not parallel to "
            f"any slice direction of the image grid (closest: {tilts[axis]:.3g}° from the "
            f"planes perpendicular to grid axis {axis}); the contours do not belong to this image"
        )
    return _Grid(grid.affine, grid.shape, axis), normals[axis]


def _plane_step(plane_positions: NDArray[np.float64]) -> float:
    """Plane step of a built grid: the smallest gap, 1 mm for a single plane."""
    gaps = np.diff(plane_positions)
    return float(gaps.min()) if gaps.size else 1.0


def _built_indices(plane_positions: NDArray[np.float64], tolerance_mm: float) -> NDArray:
    """Plane indices on a built grid, snapped to integers within ``tolerance_mm``."""
    step = _plane_step(plane_positions)
    return _snap((plane_positions - plane_positions[0]) / step, step, tolerance_mm)


def _built_grid(
    polys: list[_Polygon],
    normal: NDArray[np.float64],
    plane_positions: NDArray[np.float64],
    pixel_spacing: float | None,
    tolerance_mm: float,
) -> _Grid:
    dominant = int(np.argmax(np.abs(normal)))
    first = np.eye(3)[(dominant + 1) % 3]
    u = first - np.dot(first, normal) * normal
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    points = np.concatenate([p.points for p in polys])
    uv = points @ np.stack([u, v], axis=1)
    lo, hi = uv.min(axis=0), uv.max(axis=0)
    extent = float((hi - lo).max())
    spacing = extent / DEFAULT_PIXELS_ACROSS if pixel_spacing is None else pixel_spacing
    sizes = np.ceil((hi - lo) / spacing - 1e-9).astype(np.int64) + 2 * MARGIN_PX
    if sizes.max() > MAX_PIXELS_PER_AXIS:
        raise OptionError(
            f"pixel_spacing {spacing:g} mm gives {int(sizes.max())} pixels across "
            f"{extent:.4g} mm (limit {MAX_PIXELS_PER_AXIS}); choose a larger pixel_spacing"
        )
    gap = _plane_step(plane_positions)
    # Pixel centres of index 0 sit half a pixel plus the margin inside the box corner.
    corner = lo - (MARGIN_PX - 0.5) * spacing
    affine = np.eye(4)
    affine[:3, 0] = u * spacing
    affine[:3, 1] = v * spacing
    affine[:3, 2] = normal * gap
    affine[:3, 3] = corner[0] * u + corner[1] * v + plane_positions[0] * normal
    n_planes = int(math.ceil(_built_indices(plane_positions, tolerance_mm)[-1])) + 1
    logger.debug(
        "built grid: pixel %.4g mm, %d x %d pixels, plane step %.4g mm, %d planes",
        spacing,
        sizes[0],
        sizes[1],
        gap,
        n_planes,
    )
    return _Grid(affine, (int(sizes[0]), int(sizes[1]), n_planes), axis=2)


def rasterize_polygons(
    polygons_px: Sequence[ArrayLike], shape: tuple[int, int]
) -> NDArray[np.bool_]:
    """Fill polygons onto a pixel grid by the even-odd rule at pixel centres.

    Parameters
    ----------
    polygons_px : sequence of array_like of shape (N_i, 2)
        Closed polygons in pixel index coordinates ``(a, b)`` (array axes 0 and
        1; pixel ``[a, b]`` has its centre at integer ``(a, b)``). All polygons
        are filled together: a centre is foreground when a ray from it crosses
        the edges of all polygons an odd number of times, so nested polygons
        make holes. Parts outside the grid are clipped.
    shape : tuple of int
        ``(M, N)``, the mask size.

    Returns
    -------
    ndarray of shape (M, N), bool

    Notes
    -----
    Centres exactly on an edge follow a half-open rule: a polygon spanning
    ``[a0, a1] × [b0, b1]`` covers the centres with ``a0 <= a < a1`` and
    ``b0 <= b < b1``.
    """
    m, n = int(shape[0]), int(shape[1])
    starts: list[NDArray[np.float64]] = []
    ends: list[NDArray[np.float64]] = []
    for poly in polygons_px:
        pts = np.asarray(poly, dtype=np.float64).reshape(-1, 2)
        if pts.shape[0] >= 2:
            starts.append(pts)
            ends.append(np.roll(pts, -1, axis=0))
    if not starts:
        return np.zeros((m, n), dtype=bool)
    p0, p1 = np.concatenate(starts), np.concatenate(ends)
    # An edge crosses row b (centre line b = const) when min(b0, b1) <= b < max(b0, b1).
    b_lo, b_hi = np.minimum(p0[:, 1], p1[:, 1]), np.maximum(p0[:, 1], p1[:, 1])
    first = np.clip(np.ceil(b_lo), 0, n).astype(np.int64)
    stop = np.clip(np.ceil(b_hi), 0, n).astype(np.int64)
    counts = np.maximum(stop - first, 0)
    edge = np.repeat(np.arange(p0.shape[0]), counts)
    offsets = np.arange(edge.size) - np.repeat(np.cumsum(counts) - counts, counts)
    rows = first[edge] + offsets
    t = (rows - p0[edge, 1]) / (p1[edge, 1] - p0[edge, 1])
    a_cross = p0[edge, 0] + t * (p1[edge, 0] - p0[edge, 0])
    # A crossing at a toggles every centre a >= a_cross (ray towards -inf along a).
    col = np.clip(np.ceil(a_cross), 0, m).astype(np.int64)
    mask = np.zeros((m, n), dtype=bool)
    if rows.size == 0:
        return mask
    # Only the block spanned by the crossings can change; uint8 sums keep their parity.
    a0, b0, b1 = int(col.min()), int(rows.min()), int(rows.max()) + 1
    toggles = np.zeros((m + 1 - a0, b1 - b0), dtype=np.uint8)
    np.add.at(toggles, (col - a0, rows - b0), 1)
    parity = np.cumsum(toggles[: m - a0], axis=0, dtype=np.uint8) & 1
    mask[a0:, b0:b1] = parity.astype(bool)
    return mask


def rings_that_cross(
    polygons_px: Sequence[ArrayLike], shape: tuple[int, int]
) -> tuple[int, int, bool] | None:
    """Two polygons of one plane that the even-odd rule reads against their intent.

    Nested polygons (a hole) and disjoint ones are what the rule is for. Two
    polygons that partly overlap make their overlap a hole, and one listed
    twice cancels itself out; both are usually drawing mistakes.

    Parameters
    ----------
    polygons_px : sequence of array_like of shape (N_i, 2)
        As for :func:`rasterize_polygons`.
    shape : tuple of int
        ``(M, N)``, the mask size.

    Returns
    -------
    (i, j, repeated) or None
        The first such pair (indices into ``polygons_px``) and whether they
        cover the same pixel centres (a repeat) rather than partly overlap;
        None when the rule reads every polygon as drawn.
    """
    if len(polygons_px) < 2:
        return None
    masks = [rasterize_polygons([p], shape) for p in polygons_px]
    for i in range(len(masks)):
        for j in range(i + 1, len(masks)):
            both = masks[i] & masks[j]
            if not both.any():
                continue
            if np.array_equal(masks[i], masks[j]):
                return i, j, True
            if not (np.array_equal(both, masks[i]) or np.array_equal(both, masks[j])):
                return i, j, False
    return None


def warn_crossing(names: Sequence[str], pair: tuple[int, int, bool]) -> None:
    """One warning line for the pair :func:`rings_that_cross` found."""
    i, j, repeated = pair
    if repeated:
        logger.warning(
            "%s and %s are the same contour: by the even-odd rule they cancel out (that "
            "area is empty); list each contour once",
            names[i],
            names[j],
        )
    else:
        logger.warning(
            "%s and %s cross each other: by the even-odd rule their overlap is a hole; "
            "draw one outline, or nest a hole inside",
            names[i],
            names[j],
        )


def sections_from_polygons(
    polygons: Sequence[ArrayLike],
    /,
    *,
    pixel_spacing: float | None = None,
    reference: tuple[ArrayLike, Sequence[int]] | None = None,
    normal: ArrayLike | None = None,
    empty_positions: Sequence[float] = (),
    axis_tolerance_deg: float = 0.5,
    plane_tolerance_mm: float = PLANE_TOLERANCE_MM,
    polygon_names: Sequence[str] | None = None,
    memory_budget_gb: float = DEFAULT_MEMORY_BUDGET_GB,
    own_planes: bool = False,
    one_structure: bool = True,
) -> CrossSections:
    """Rasterize closed polygons lying on parallel planes into cross-sections.

    See the module docstring for the full procedure and the built grid.

    Parameters
    ----------
    polygons : sequence of array_like of shape (N_i, 3)
        Closed polygons (first vertex not repeated; a repeat is harmless) in
        world mm, N_i >= 3, in any order; they are grouped into planes by
        position. Nested polygons on one plane make holes (even-odd rule).
    pixel_spacing : float, optional
        In-plane pixel size of a built grid, mm (default: longest in-plane
        extent / 256). Ignored, with a warning, when ``reference`` is given.
    reference : (affine, shape), optional
        An image grid to rasterize on: ``affine`` of shape (4, 4) maps voxel
        indices to the same world mm as the polygons, ``shape`` is ``(I, J, K)``.
        The planes must be parallel to one of its slice directions.
    normal : array_like of shape (3,), optional
        The plane normal, if known; polygons must be parallel to it. It fixes
        the direction positions are measured along (on a built grid, axis 2
        points along it). Default: from the polygons.
    empty_positions : sequence of float
        Positions along ``normal`` (mm, ``position = point · normal``) of planes
        that were annotated but hold no foreground. Requires ``normal``.
    axis_tolerance_deg : float
        Largest angle between a polygon's normal and the common normal (and,
        with ``reference``, between the common normal and the grid's slice
        normal), degrees.
    plane_tolerance_mm : float
        Polygons whose positions along the normal differ by at most this are on
        one plane; also the absolute planarity tolerance, and how far a plane
        may sit from an integer index of ``reference`` and still be snapped to it.
    polygon_names : sequence of str, optional
        Names of the polygons for error messages (default ``"polygon i"``).
    memory_budget_gb : float
        Refuse grids that the reconstruction could not hold in this budget,
        GiB (:func:`slicerecon.io.limits.check_grid`), before rasterizing.
    own_planes : bool
        With ``reference``: when the planes lie between the reference's slices
        (an RTSTRUCT drawn half a slice off its CT), keep their exact
        positions. All the same fraction of a slice off: the reference's
        slices moved by that fraction, so each plane stands for one slice as
        on the reference's own slices. Otherwise keep the reference's in-plane
        pixels but rebuild its slice axis on the planes, with the step of a
        built grid (the reconstruction then ends half a contour spacing
        beyond the end planes, as without the reference). Off (the default),
        planes keep fractional indices on the reference grid (a contour
        file's own grid round-trips exactly).
    one_structure : bool
        The polygons outline one structure: two on one plane that cross or
        repeat are warned about (:func:`rings_that_cross`). False for the
        polygons of several structures together (they may overlap).

    Returns
    -------
    CrossSections
        One plane per distinct position, sorted along the normal. On a built
        grid ``axis == 2`` and the first plane has index 0.

    Raises
    ------
    InputError
        A polygon is not an (N, 3) array of finite numbers with N >= 3.
    EmptyMaskError
        No polygon (or none enclosing any area, or none covering a pixel centre).
    GeometryError
        Non-parallel or non-planar polygons; planes not parallel to any slice
        direction of ``reference``, or outside it; coordinates that are not
        finite or lie beyond :data:`slicerecon.io.limits.MAX_COORDINATE_MM`.
    MemoryBudgetError
        The grid exceeds ``memory_budget_gb``.
    OptionError
        Bad option values.
    """
    if not (math.isfinite(axis_tolerance_deg) and 0 <= axis_tolerance_deg < 90):
        raise OptionError(f"axis_tolerance_deg must be in [0, 90) (got {axis_tolerance_deg})")
    if not (math.isfinite(plane_tolerance_mm) and plane_tolerance_mm >= 0):
        raise OptionError(f"plane_tolerance_mm must be >= 0 (got {plane_tolerance_mm})")
    if pixel_spacing is not None and not (math.isfinite(pixel_spacing) and pixel_spacing > 0):
        raise OptionError(f"pixel_spacing must be a positive number of mm (got {pixel_spacing})")
    given_normal = None if normal is None else _unit(normal, "normal")
    empties = np.asarray(list(empty_positions), dtype=np.float64).reshape(-1)
    if empties.size and given_normal is None:
        raise OptionError("empty_positions are measured along a normal: pass normal too")
    if not np.all(np.isfinite(empties)):
        raise OptionError("empty_positions hold NaN or infinite values")
    grid = _check_reference(reference) if reference is not None else None
    if grid is not None and pixel_spacing is not None:
        logger.warning("pixel_spacing %g mm ignored: the reference grid is used", pixel_spacing)

    if isinstance(polygons, np.ndarray) and polygons.ndim == 2:
        raise InputError(
            "pass a sequence of polygons, each an (N, 3) array (got one 2-D array; "
            "wrap it in a list)"
        )
    items = list(polygons)
    polys = _as_polygons(items, polygon_names)
    if not polys:
        raise EmptyMaskError(
            "no contour encloses any area: there is nothing to reconstruct"
            if items
            else "no contours given: there is nothing to reconstruct"
        )
    common = _common_normal(polys, given_normal, axis_tolerance_deg)
    _check_planar(polys, plane_tolerance_mm)

    if grid is not None:
        grid, along = _reference_axis(grid, common, axis_tolerance_deg)
    else:
        along = common
    # Positions along `along` (the grid's slice normal, or the common normal).
    centroid_pos = np.array([float(p.points.mean(axis=0) @ along) for p in polys])
    if empties.size:
        assert given_normal is not None
        empty_pos = empties * float(np.dot(given_normal, along))
    else:
        empty_pos = np.zeros(0)
    all_pos = np.concatenate([centroid_pos, empty_pos])
    groups = _group(all_pos, plane_tolerance_mm)
    plane_pos = np.array([all_pos[g].mean() for g in groups])
    members = [[int(i) for i in g if i < len(polys)] for g in groups]

    if grid is None:
        grid = _built_grid(polys, along, plane_pos, pixel_spacing, plane_tolerance_mm)
        indices = _built_indices(plane_pos, plane_tolerance_mm)
    else:
        indices = _reference_indices(grid, along, plane_pos, plane_tolerance_mm)
        if own_planes and not np.allclose(indices, np.round(indices)):
            shift = float(indices[0] - np.round(indices[0]))
            step = abs(float(np.dot(grid.affine[:3, grid.axis], along)))
            if np.all(
                np.abs(indices - shift - np.round(indices - shift)) * step <= plane_tolerance_mm
            ):
                # every plane the same fraction of a slice off: the image's slices, moved
                grid = _moved_axis(grid, shift)
                indices = np.round(indices - shift)
            else:
                grid = _contour_axis(grid, along, plane_pos, indices, plane_tolerance_mm)
                indices = _built_indices(plane_pos, plane_tolerance_mm)

    check_grid(grid.shape, what="the contours", memory_budget_gb=memory_budget_gb)
    masks, crossing = _rasterize_planes(polys, members, grid, one_structure)
    if not masks.any():
        raise EmptyMaskError(
            "the contours cover no pixel centre of the image grid: they lie beside it in "
            "its planes, or are smaller than its pixels (contour points are world mm)"
            if reference is not None
            else "the contours cover no pixel centre: they are smaller than a pixel; "
            "choose a smaller pixel_spacing"
        )
    for p, (mask, group) in enumerate(zip(masks, members, strict=True)):
        if group and not mask.any() and p not in crossing:  # else said by warn_crossing
            logger.warning("plane %d: its contours cover no pixel centre (too small)", p)
    logger.info(
        "%d polygons on %d planes, in-plane grid %d x %d",
        len(polys),
        len(groups),
        masks.shape[1],
        masks.shape[2],
    )
    return CrossSections(masks, indices, grid.axis, grid.affine, grid.shape)


def _snap(indices: NDArray[np.float64], step_mm: float, tolerance_mm: float) -> NDArray:
    """Round indices lying within ``tolerance_mm`` of an integer index to it."""
    nearest = np.round(indices)
    return np.where(np.abs(indices - nearest) * abs(step_mm) <= tolerance_mm, nearest, indices)


def _reference_indices(
    grid: _Grid, along: NDArray[np.float64], plane_pos: NDArray[np.float64], tolerance_mm: float
) -> NDArray[np.float64]:
    step = float(np.dot(grid.affine[:3, grid.axis], along))
    indices = _snap(
        (plane_pos - float(np.dot(grid.affine[:3, 3], along))) / step, step, tolerance_mm
    )
    size = grid.shape[grid.axis]
    outside = (indices < -0.5) | (indices > size - 0.5)
    if outside.any():
        bad = float(plane_pos[np.argmax(outside)])
        raise GeometryError(
            f"contours at {bad:.4g} mm lie outside the image grid (index "
            f"{indices[np.argmax(outside)]:.3g}, grid has {size} planes along axis "
            f"{grid.axis}); the contours do not belong to this image"
        )
    return indices


def _moved_axis(grid: _Grid, shift: float) -> _Grid:
    """The reference grid moved by ``shift`` of a slice along its slice axis.

    Contours drawn the same fraction of a slice off the image's slices (an
    RTSTRUCT exported half a slice off its CT) keep their positions and the
    image's slice step, so each stands for one slice, as on the image's own.
    """
    affine = grid.affine.copy()
    affine[:3, 3] = grid.affine[:3, 3] + grid.affine[:3, grid.axis] * shift
    logger.info(
        "the contour planes lie %.3g of a slice off the image's slices: they keep their "
        "positions on the image's slices moved by that much",
        shift,
    )
    return _Grid(affine, grid.shape, grid.axis)


def _contour_axis(
    grid: _Grid,
    along: NDArray[np.float64],
    plane_pos: NDArray[np.float64],
    indices: NDArray[np.float64],
    tolerance_mm: float,
) -> _Grid:
    """The reference grid with its slice axis rebuilt on the contour planes.

    Contours drawn between the image's slices keep their exact positions: the
    in-plane pixels stay the image's, and the slice axis starts on the first
    contour plane with the step of a built grid (the smallest gap between
    contour planes), so that every regularly spaced contour plane falls on a
    whole index, as when the contours are read without the image.
    """
    axis = grid.axis
    column = grid.affine[:3, axis]
    step_along = float(np.dot(column, along))  # mm along the normal per index, > 0
    gap = _plane_step(plane_pos)
    affine = grid.affine.copy()
    affine[:3, 3] = grid.affine[:3, 3] + column * float(indices[0])
    affine[:3, axis] = column * (gap / step_along)
    shape = list(grid.shape)
    shape[axis] = int(math.ceil(_built_indices(plane_pos, tolerance_mm)[-1])) + 1
    logger.info(
        "the contour planes lie between the image's slices (index %.3g): they keep their "
        "positions on a slice axis of their own, %.4g mm apart",
        float(indices[0]),
        gap,
    )
    return _Grid(affine, (shape[0], shape[1], shape[2]), axis)


def _rasterize_planes(
    polys: list[_Polygon], members: list[list[int]], grid: _Grid, check: bool
) -> tuple[NDArray[np.bool_], set[int]]:
    """Each plane's polygons filled by the even-odd rule, and the planes whose polygons
    cross or repeat (warned about)."""
    a, b = in_plane_axes(grid.axis)
    inverse = np.linalg.inv(grid.affine)
    masks = np.zeros((len(members), grid.shape[a], grid.shape[b]), dtype=bool)
    crossing: set[int] = set()
    clipped = 0
    for p, group in enumerate(members):
        rings = []
        for i in group:
            ijk = polys[i].points @ inverse[:3, :3].T + inverse[:3, 3]
            rings.append(ijk[:, [a, b]])
            low, high = ijk[:, [a, b]].min(axis=0), ijk[:, [a, b]].max(axis=0)
            if low.min() < -0.5 or high[0] > grid.shape[a] - 0.5 or high[1] > grid.shape[b] - 0.5:
                clipped += 1
        masks[p] = rasterize_polygons(rings, (grid.shape[a], grid.shape[b]))
        pair = rings_that_cross(rings, (grid.shape[a], grid.shape[b])) if check else None
        if pair is not None:
            warn_crossing([polys[i].name for i in group], pair)
            crossing.add(p)
    if clipped:
        logger.warning("%d contours extend beyond the image grid and are clipped", clipped)
    return masks, crossing


def polygons_from_sections(
    sections: CrossSections,
) -> list[tuple[float, list[NDArray[np.float64]]]]:
    """The boundary polygons of every plane, in world mm.

    Parameters
    ----------
    sections : CrossSections

    Returns
    -------
    list of (position, polygons)
        One entry per plane, in plane order: the plane's position along
        ``sections.normal`` (mm) and its polygons, each an ndarray of shape
        (N, 3) in world mm (first vertex not repeated). The polygons follow the
        0.5 iso-line of the mask (:meth:`CrossSections.contours`), so
        rasterizing them on the same grid by the even-odd rule gives the masks
        back exactly. Planes without foreground have no polygons.
    """
    if not isinstance(sections, CrossSections):
        raise InputError(f"expected CrossSections (got {type(sections).__name__})")
    positions = sections.positions
    out: list[tuple[float, list[NDArray[np.float64]]]] = []
    for plane in range(sections.n_planes):
        rings = [
            sections.plane_to_world(plane, contour.points_px)
            for contour in sections.contours(plane)
        ]
        out.append((float(positions[plane]), rings))
    return out
