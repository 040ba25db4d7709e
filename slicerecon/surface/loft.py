"""Lofting: a closed surface through the contours of consecutive section planes.

The paper's surface step: within one part (a :class:`~slicerecon.sections.Box`),
contours of consecutive planes are matched by centre and size, matched
contours are joined by a triangle band, unmatched ones are closed off, and the
ends are capped. The exact algorithm, with its costs and thresholds, is in
``docs/method.md``; in short:

1. **Regions.** Each plane's mask, cropped to the box (plus a one-pixel margin),
   is split into foreground regions (4-connected) and holes (8-connected
   background enclosed by foreground). Each has one outer polygon: the
   pixel-centre 0.5 iso-contour (marching squares), counter-clockwise.
2. **Correspondence** between planes ``k`` and ``k+1`` (regions with regions,
   holes with holes): pairs whose masks overlap by at least
   :data:`OVERLAP_MIN` of the smaller one are linked, and every region is
   linked to the partner it overlaps most; the rest are paired 1-to-1 by a
   Hungarian assignment on ``|c_i - c_j| / (r_i + r_j) + AREA_WEIGHT *
   |ln(A_i / A_j)|`` (centroids ``c``, equivalent radii ``r = sqrt(A / pi)``,
   areas ``A``, all in mm), accepted up to :data:`MATCH_COST_MAX`.
3. **Branching.** A region linked to several partners is split among them by
   nearest partner (each pixel goes to the partner at the smallest in-plane
   distance, mm), each piece grown by one pixel inside the region so that
   neighbouring pieces overlap; every link is lofted piece to piece.
4. **Bands.** Two polygons are joined by merging their arc-length parameters
   (after choosing the start vertex of the upper polygon that minimises the
   squared distance between the centred, size-normalised outlines), which
   uses every original vertex, so neighbouring slabs share their caps
   exactly. Caps are triangulated with manifold3d.
5. **Appearing / vanishing** regions (no partner) become a cone from the
   contour to the region's deepest pixel half-way to the neighbouring plane.
6. **Holes** are lofted the same way, lengthened by a tiny
   :data:`HOLE_OVERSHOOT` beyond the slab, and subtracted from the slab.
7. **Ends.** Without a box, the first and last planes are capped flat (a
   single plane becomes a slab half a voxel thick each side). With a box and
   ``extend_to_box``, the first / last plane inside the box is carried to the
   box face: as a prism, or, given the visual ``hull``, through one ring per
   layer whose extent changes (:mod:`~slicerecon.surface.extension`); a box
   holding no plane is filled with the slab of the planes either side of it.
8. All solids are united with manifold3d (exact, robust to the coplanar caps
   of consecutive slabs) and intersected with the box.

Geometry is built in *plane coordinates* ``(u, v, w)``: the in-plane index
coordinates along :attr:`CrossSections.plane_axes` and the index along the
section axis; the solid is permuted to voxel index coordinates ``(i, j, k)``
and mapped to world mm through the affine at the end (manifold3d and
:func:`~slicerecon.surface.merge.from_manifold` keep faces outward for
mirroring maps).
"""

from __future__ import annotations

import logging
from typing import NamedTuple

import manifold3d
import numpy as np
import trimesh
from numpy.typing import NDArray
from scipy import ndimage
from scipy.optimize import linear_sum_assignment
from skimage.measure import find_contours

from ..errors import EmptyMaskError, InputError, OptionError
from ..sections import Box, CrossSections
from .extension import LayerMap, check_hull, extension_maps, identity_map
from .merge import from_manifold, solid_from_arrays, union_solids

__all__ = [
    "AREA_WEIGHT",
    "HOLE_OVERSHOOT",
    "MATCH_COST_MAX",
    "OVERLAP_MIN",
    "correspondence_is_simple",
    "loft",
    "loft_solid",
]

logger = logging.getLogger(__name__)

OVERLAP_MIN = 0.1
"""Overlap (pixels in both masks) over the smaller area that links two regions outright."""

MATCH_COST_MAX = 1.5
"""Largest accepted cost of a non-overlapping pair (see the module docstring)."""

AREA_WEIGHT = 0.5
"""Weight of ``|ln(area ratio)|`` in the matching cost."""

HOLE_OVERSHOOT = 1e-2
"""How far (index units along the axis) hole solids reach beyond their slab."""

_ALIGN_SAMPLES = 64
"""Points per outline when choosing the start vertex of a band."""

_CROP_MARGIN = 1
"""Pixels kept around the box in-plane; the solid is clipped to the box afterwards."""

_FOUR = ndimage.generate_binary_structure(2, 1)
_EIGHT = ndimage.generate_binary_structure(2, 2)


# -- data -------------------------------------------------------------------------------
class _Window(NamedTuple):
    """In-plane crop of the reference grid, with the in-plane pixel size."""

    u0: int
    v0: int
    spacing: NDArray[np.float64]  # (2,) mm along u, v


class _Region(NamedTuple):
    """One foreground region (or hole) of one plane."""

    label: int
    polygon: NDArray[np.float64]  # (N, 2) counter-clockwise, plane coordinates (u, v)
    area_mm2: float
    centroid_mm: NDArray[np.float64]  # (2,)


class _Plane(NamedTuple):
    """A plane's regions and holes, with their label images on the crop."""

    w: float
    labels: NDArray[np.int32]
    regions: list[_Region]
    hole_labels: NDArray[np.int32]
    holes: list[_Region]


# -- public API -------------------------------------------------------------------------
def loft(
    sections: CrossSections,
    *,
    box: Box | None = None,
    extend_to_box: bool = False,
    hull: NDArray[np.bool_] | None = None,
) -> trimesh.Trimesh:
    """Loft a closed surface through the contours of the section planes.

    Parameters
    ----------
    sections : CrossSections
        Binary masks on parallel planes.
    box : Box, optional
        Restrict the reconstruction to this cuboid of the reference grid
        (in continuous index coordinates it spans ``[lo - 0.5, hi - 0.5]``).
        Planes outside the box along the axis are not used.
    extend_to_box : bool, default False
        With a box: carry the first and last plane inside the box to the box
        faces (prisms, or following ``hull``), and fill a box holding no
        plane with the slab between the planes either side of it (clipped to
        the box). Ignored without a box.
    hull : ndarray of shape sections.grid_shape, bool, optional
        The visual hull of the projections. With ``extend_to_box``, the
        extensions to the box faces follow its extent layer by layer
        (:mod:`~slicerecon.surface.extension`) instead of being prisms.

    Returns
    -------
    trimesh.Trimesh
        Closed, outward-oriented mesh in world mm (``is_volume``).

    Raises
    ------
    InputError
        If ``sections`` is not a CrossSections or ``box`` not a Box.
    EmptyMaskError
        If no plane used holds foreground (inside the box, when given).
    """
    solid = loft_solid(sections, box=box, extend_to_box=extend_to_box, hull=hull)
    if solid is None:
        where = "inside the box" if box is not None else "on any plane"
        raise EmptyMaskError(f"no section foreground {where}: nothing to loft")
    return from_manifold(solid, transform=sections.affine)


def loft_solid(
    sections: CrossSections,
    *,
    box: Box | None = None,
    extend_to_box: bool = False,
    hull: NDArray[np.bool_] | None = None,
) -> manifold3d.Manifold | None:
    """The lofted solid in voxel index coordinates, or None when there is nothing to loft.

    Same parameters as :func:`loft`, and ``hull``: the visual hull on the
    reference grid (shape ``sections.grid_shape``), which the extensions to
    the box faces follow (:mod:`~slicerecon.surface.extension`); without it
    they are prisms. The solid is in continuous index
    coordinates ``(i, j, k)`` of the reference grid; map it to world mm with
    ``from_manifold(solid, transform=sections.affine)``. Solids of several
    parts of the same sections are united in these coordinates, where shared
    box faces are exactly coplanar.

    Returns
    -------
    manifold3d.Manifold or None
        None when no used plane holds foreground inside the box, or the
        result encloses no volume.
    """
    if not isinstance(sections, CrossSections):
        raise InputError(f"loft needs CrossSections (got {type(sections).__name__})")
    if box is not None and not isinstance(box, Box):
        raise InputError(f"box must be a slicerecon Box (got {type(box).__name__})")
    if not isinstance(extend_to_box, bool | np.bool_):
        raise OptionError(f"extend_to_box must be True or False (got {extend_to_box!r})")
    check_hull(hull, sections.grid_shape)

    a, b = sections.plane_axes
    grid = sections.grid_shape
    if box is not None:
        inside = box.intersect(Box((0, 0, 0), grid))
        if inside is None:
            raise OptionError(f"box {box.to_dict()} lies outside the reference grid {grid}")
        box = inside
    if box is None:
        rows = (0, grid[a])
        cols = (0, grid[b])
        span = None
    else:
        rows = (max(box.lo[a] - _CROP_MARGIN, 0), min(box.hi[a] + _CROP_MARGIN, grid[a]))
        cols = (max(box.lo[b] - _CROP_MARGIN, 0), min(box.hi[b] + _CROP_MARGIN, grid[b]))
        span = (box.lo[sections.axis] - 0.5, box.hi[sections.axis] - 0.5)
    window = _Window(rows[0], cols[0], sections.spacing[[a, b]])
    masks = sections.masks[:, rows[0] : rows[1], cols[0] : cols[1]]
    w_all = sections.indices

    chosen = np.arange(sections.n_planes) if box is None else sections.planes_in(box)
    crossing = chosen.size == 0 and box is not None and extend_to_box
    if crossing:
        # A box between planes: the slab of the planes either side, clipped below.
        assert box is not None
        chosen = sections.planes_in(box, bridge=True)
        if chosen.size == 0:
            return None
    if not _has_foreground(masks[chosen], box, rows, cols, (a, b)):
        return None
    planes = [_plane(masks[p], float(w_all[p]), window) for p in chosen]

    ends: tuple[list[LayerMap] | None, list[LayerMap] | None] = (None, None)
    if crossing:
        pass  # the crossing slab is cut at the box faces below
    elif span is not None and extend_to_box:
        assert box is not None
        ends = (
            extension_maps(hull, box, sections.axis, planes[0].w, 0)
            if planes[0].w > span[0] + 1e-9
            else None,
            extension_maps(hull, box, sections.axis, planes[-1].w, 1)
            if planes[-1].w < span[1] - 1e-9
            else None,
        )
    elif len(planes) == 1:
        ends = ([identity_map(planes[0].w - 0.5)], [identity_map(planes[0].w + 0.5)])

    parts = _solids(planes, window, ends, hole=False)
    solid = union_solids(parts)
    if any(p.holes for p in planes):
        holes = _solids(planes, window, ends, hole=True)
        if holes:
            solid = solid - union_solids(holes)
    if crossing:
        # Only the slab crossing the box reaches beyond its faces along the axis.
        lo = np.array([rows[0] - 1.0, cols[0] - 1.0, span[0]])  # type: ignore[index]
        hi = np.array([rows[1] + 1.0, cols[1] + 1.0, span[1]])  # type: ignore[index]
        solid = solid ^ manifold3d.Manifold.cube(hi - lo).translate(lo)
    if solid.is_empty() or solid.volume() <= 0:
        return None
    solid = solid.transform(_plane_to_index(sections.axis))
    logger.debug(
        "lofted %d planes from %d solids: %d triangles, %.4g voxel volume",
        len(planes),
        len(parts),
        solid.num_tri(),
        solid.volume(),
    )
    return solid


def correspondence_is_simple(sections: CrossSections, box: Box) -> bool:
    """Whether lofting is well posed for the planes inside ``box``.

    True when, between every two consecutive planes inside the box, each
    region is linked to at least one region of the other plane (nothing
    appears or vanishes) and no link joins two regions that both branch
    (no many-to-many merging): the cases the bands and branch pieces of the
    loft are built for. Folded shapes whose contours split, merge and appear
    from plane to plane (cortex, white matter) fail this test; the
    ``"hybrid"`` method reconstructs such parts by signed-distance
    interpolation instead.

    Parameters
    ----------
    sections : CrossSections
        All cross-sections of the shape.
    box : Box
        The part's cuboid on the reference grid.

    Returns
    -------
    bool
    """
    if not isinstance(sections, CrossSections) or not isinstance(box, Box):
        raise InputError("correspondence_is_simple needs CrossSections and a Box")
    a, b = sections.plane_axes
    inside = box.intersect(Box((0, 0, 0), sections.grid_shape))
    if inside is None:
        return True
    w_all = sections.indices
    chosen = sections.planes_in(inside)
    if chosen.size < 2:
        return True
    window = _Window(inside.lo[a], inside.lo[b], sections.spacing[[a, b]])
    masks = sections.masks[:, inside.lo[a] : inside.hi[a], inside.lo[b] : inside.hi[b]]
    planes = [_plane(masks[p], float(w_all[p]), window) for p in chosen]
    for lower, upper in zip(planes[:-1], planes[1:], strict=True):
        if not lower.regions or not upper.regions:
            if lower.regions or upper.regions:
                return False
            continue
        links = _match(lower.regions, lower.labels, upper.regions, upper.labels)
        degree_lo = np.bincount([i for i, _ in links], minlength=len(lower.regions))
        degree_up = np.bincount([j for _, j in links], minlength=len(upper.regions))
        if (degree_lo == 0).any() or (degree_up == 0).any():
            return False
        if any(degree_lo[i] >= 2 and degree_up[j] >= 2 for i, j in links):
            return False
    return True


def _plane_to_index(axis: int) -> NDArray[np.float64]:
    """The 3×4 permutation taking plane coordinates ``(u, v, w)`` to indices ``(i, j, k)``.

    manifold3d reverses the winding itself when the permutation is odd.
    """
    a, b = (ax for ax in range(3) if ax != axis)
    perm = np.zeros((3, 4))
    perm[a, 0] = perm[b, 1] = perm[axis, 2] = 1.0
    return perm


# -- planes and regions -----------------------------------------------------------------
def _has_foreground(
    masks: NDArray[np.bool_],
    box: Box | None,
    rows: tuple[int, int],
    cols: tuple[int, int],
    axes: tuple[int, int],
) -> bool:
    """Whether the cropped masks hold foreground inside the box proper (not the margin)."""
    if box is None:
        return bool(masks.any())
    a, b = axes
    r0, r1 = box.lo[a] - rows[0], box.hi[a] - rows[0]
    c0, c1 = box.lo[b] - cols[0], box.hi[b] - cols[0]
    return bool(masks[:, r0:r1, c0:c1].any())


def _plane(mask: NDArray[np.bool_], w: float, window: _Window) -> _Plane:
    """Regions and holes of one cropped plane mask."""
    labels, n = ndimage.label(mask, structure=_FOUR)
    regions = _regions(labels, n, window, hole=False)
    padded, _ = ndimage.label(np.pad(~mask, 1, constant_values=True), structure=_EIGHT)
    background = padded[1:-1, 1:-1]
    outside = padded[0, 0]
    holes_mask = (background > 0) & (background != outside)
    if holes_mask.any():
        hole_labels, n_holes = ndimage.label(holes_mask, structure=_EIGHT)
        holes = _regions(hole_labels, n_holes, window, hole=True)
    else:
        hole_labels = np.zeros_like(labels)
        holes = []
    return _Plane(w, labels.astype(np.int32), regions, hole_labels.astype(np.int32), holes)


def _regions(labels: NDArray[np.integer], n: int, window: _Window, *, hole: bool) -> list[_Region]:
    """One :class:`_Region` per label ``1..n`` (those with a usable polygon)."""
    if n == 0:
        return []
    index = np.arange(1, n + 1)
    counts = np.bincount(labels.ravel(), minlength=n + 1)[1:]
    centres = np.asarray(ndimage.center_of_mass(labels > 0, labels, index)).reshape(n, 2)
    pixel = float(np.prod(window.spacing))
    out: list[_Region] = []
    for label, bbox in enumerate(ndimage.find_objects(labels), start=1):
        if bbox is None:
            continue
        polygon = _outer_polygon(labels[bbox] == label, hole=hole)
        if polygon is None:
            continue
        polygon += (bbox[0].start + window.u0, bbox[1].start + window.v0)
        centre = (centres[label - 1] + (window.u0, window.v0)) * window.spacing
        out.append(_Region(label, polygon, float(counts[label - 1]) * pixel, centre))
    return out


def _outer_polygon(mask: NDArray[np.bool_], *, hole: bool) -> NDArray[np.float64] | None:
    """Outer boundary of a connected mask: the 0.5 iso-contour, counter-clockwise.

    Foreground regions are 4-connected and holes 8-connected, as in
    :meth:`CrossSections.contours` (scikit-image resolves saddles with the
    background fully connected); a hole is traced as the "high" side with
    ``fully_connected="high"`` so that the same saddle choice is made.
    """
    padded = np.pad(mask.astype(np.float64), 1)
    contours = find_contours(padded, 0.5, fully_connected="high" if hole else "low")
    best: NDArray[np.float64] | None = None
    best_area = 0.0
    for contour in contours:
        pts = contour[:-1] if np.allclose(contour[0], contour[-1]) else contour
        area = _signed_area(pts)
        if abs(area) > abs(best_area):
            best, best_area = pts, area
    if best is None or abs(best_area) < 1e-9:
        return None
    pts = best - 1.0
    if best_area < 0:
        pts = pts[::-1]
    pts = _drop_collinear(pts)
    if pts.shape[0] < 3:
        return None
    return np.ascontiguousarray(pts)


def _signed_area(pts: NDArray[np.float64]) -> float:
    """Shoelace area of a closed polygon (positive when counter-clockwise in (u, v))."""
    x, y = pts[:, 0], pts[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))


def _drop_collinear(pts: NDArray[np.float64]) -> NDArray[np.float64]:
    """Remove repeated vertices and vertices in the middle of straight runs (exactly)."""
    keep = np.any(pts != np.roll(pts, 1, axis=0), axis=1)
    pts = pts[keep]
    if pts.shape[0] < 3:
        return pts
    prev = pts - np.roll(pts, 1, axis=0)
    nxt = np.roll(pts, -1, axis=0) - pts
    cross = prev[:, 0] * nxt[:, 1] - prev[:, 1] * nxt[:, 0]
    return pts[np.abs(cross) > 1e-12]


def _centroid(pts: NDArray[np.float64]) -> NDArray[np.float64]:
    """Area centroid of a simple polygon, ndarray of shape (2,)."""
    x, y = pts[:, 0], pts[:, 1]
    xn, yn = np.roll(x, -1), np.roll(y, -1)
    cross = x * yn - xn * y
    area = cross.sum() / 2.0
    if abs(area) < 1e-12:
        return pts.mean(axis=0)
    return np.array([((x + xn) * cross).sum(), ((y + yn) * cross).sum()]) / (6.0 * area)


# -- correspondence ---------------------------------------------------------------------
def _match(
    lower: list[_Region],
    lower_labels: NDArray[np.int32],
    upper: list[_Region],
    upper_labels: NDArray[np.int32],
) -> list[tuple[int, int]]:
    """Links ``(i, j)`` between regions of two planes (positions in the lists)."""
    n_lo, n_up = len(lower), len(upper)
    if n_lo == 0 or n_up == 0:
        return []
    # Map label images to list positions (a label whose polygon was unusable maps to -1).
    map_lo = np.full(lower_labels.max() + 1, -1, dtype=np.int64)
    map_lo[[r.label for r in lower]] = np.arange(n_lo)
    map_up = np.full(upper_labels.max() + 1, -1, dtype=np.int64)
    map_up[[r.label for r in upper]] = np.arange(n_up)
    pos_lo = map_lo[lower_labels]
    pos_up = map_up[upper_labels]
    both = (pos_lo >= 0) & (pos_up >= 0)
    overlap = (
        np.bincount(pos_lo[both] * n_up + pos_up[both], minlength=n_lo * n_up)
        .reshape(n_lo, n_up)
        .astype(np.float64)
    )
    size_lo = np.bincount(pos_lo[pos_lo >= 0], minlength=n_lo).astype(np.float64)
    size_up = np.bincount(pos_up[pos_up >= 0], minlength=n_up).astype(np.float64)
    relative = overlap / np.maximum(np.minimum.outer(size_lo, size_up), 1.0)
    linked = relative >= OVERLAP_MIN
    rows = np.flatnonzero(overlap.max(axis=1) > 0)
    linked[rows, overlap[rows].argmax(axis=1)] = True
    cols = np.flatnonzero(overlap.max(axis=0) > 0)
    linked[overlap[:, cols].argmax(axis=0), cols] = True

    free_lo = np.flatnonzero(~linked.any(axis=1))
    free_up = np.flatnonzero(~linked.any(axis=0))
    if free_lo.size and free_up.size:
        c_lo = np.array([lower[i].centroid_mm for i in free_lo])
        c_up = np.array([upper[j].centroid_mm for j in free_up])
        a_lo = np.array([lower[i].area_mm2 for i in free_lo])
        a_up = np.array([upper[j].area_mm2 for j in free_up])
        dist = np.linalg.norm(c_lo[:, None, :] - c_up[None, :, :], axis=2)
        radii = np.sqrt(a_lo / np.pi)[:, None] + np.sqrt(a_up / np.pi)[None, :]
        cost = dist / radii + AREA_WEIGHT * np.abs(np.log(a_lo[:, None] / a_up[None, :]))
        for r, c in zip(*linear_sum_assignment(cost), strict=True):
            if cost[r, c] <= MATCH_COST_MAX:
                linked[free_lo[r], free_up[c]] = True
    pairs = np.argwhere(linked)
    return [(int(i), int(j)) for i, j in pairs]


def _pieces(
    region: _Region,
    labels: NDArray[np.int32],
    partners: list[_Region],
    partner_labels: NDArray[np.int32],
    window: _Window,
    *,
    hole: bool,
) -> list[list[NDArray[np.float64]]]:
    """Split a region among its partners; the outer polygons of each piece, per partner.

    Each pixel of the region goes to the partner nearest to it in the plane
    (Euclidean distance in mm to the partner's pixels); each piece is then
    grown by one pixel inside the region so that neighbouring pieces overlap
    and their lofts fuse instead of touching along a line.
    """
    if len(partners) == 1:
        return [[region.polygon]]
    mask = labels == region.label
    distances = np.stack(
        [
            ndimage.distance_transform_edt(partner_labels != p.label, sampling=window.spacing)
            for p in partners
        ]
    )
    nearest = np.argmin(distances[:, mask], axis=0)
    out: list[list[NDArray[np.float64]]] = []
    structure = _EIGHT if hole else _FOUR
    for k in range(len(partners)):
        piece = np.zeros_like(mask)
        piece[mask] = nearest == k
        piece = ndimage.binary_dilation(piece, structure=_EIGHT) & mask
        piece_labels, n = ndimage.label(piece, structure=structure)
        polygons = [r.polygon for r in _regions(piece_labels, n, window, hole=hole)]
        out.append(polygons)
    return out


# -- solids -----------------------------------------------------------------------------
def _solids(
    planes: list[_Plane],
    window: _Window,
    ends: tuple[list[LayerMap] | None, list[LayerMap] | None],
    *,
    hole: bool,
) -> list[manifold3d.Manifold]:
    """Closed solids whose union is the lofted shape (or, with ``hole``, its holes).

    Regions linked one-to-one across consecutive planes are chained into one
    tube through all their planes (no Boolean needed between slabs);
    branching links become piece-to-piece lofts, unmatched regions cones.
    ``ends`` are the maps (in increasing ``w``) that carry the first / last
    plane's chains to the box faces (None: capped flat at the plane); each
    map adds a ring, the plane's polygon mapped onto its layer. Hole solids reach
    :data:`HOLE_OVERSHOOT` beyond their end planes so that they open the caps.
    """
    eps = HOLE_OVERSHOOT if hole else 0.0

    def items(plane: _Plane) -> tuple[list[_Region], NDArray[np.int32]]:
        return (plane.holes, plane.hole_labels) if hole else (plane.regions, plane.labels)

    solids: list[manifold3d.Manifold | None] = []
    following: list[dict[int, int]] = [{} for _ in planes]
    continued: list[set[int]] = [set() for _ in planes]
    for k in range(len(planes) - 1):
        (lower, lower_labels), (upper, upper_labels) = items(planes[k]), items(planes[k + 1])
        w0, w1 = planes[k].w, planes[k + 1].w
        links = _match(lower, lower_labels, upper, upper_labels)
        partners_lo: dict[int, list[int]] = {}
        partners_up: dict[int, list[int]] = {}
        for i, j in links:
            partners_lo.setdefault(i, []).append(j)
            partners_up.setdefault(j, []).append(i)
        for i, j in links:
            if len(partners_lo[i]) == 1 and len(partners_up[j]) == 1:
                following[k][i] = j
                continued[k + 1].add(j)
                continue
            pieces_lo = _pieces(
                lower[i],
                lower_labels,
                [upper[q] for q in partners_lo[i]],
                upper_labels,
                window,
                hole=hole,
            )[partners_lo[i].index(j)]
            pieces_up = _pieces(
                upper[j],
                upper_labels,
                [lower[q] for q in partners_up[j]],
                lower_labels,
                window,
                hole=hole,
            )[partners_up[j].index(i)]
            for p in pieces_lo:
                for q in pieces_up:
                    solids.append(_tube([(w0 - eps, p), (w1 + eps, q)]))
        mid = 0.5 * (w0 + w1)
        for i, region in enumerate(lower):
            if i not in partners_lo:
                apex = _deepest_point(lower_labels, region.label, window)
                solids.append(_cone(region.polygon, w0 - eps, apex, mid))
        for j, region in enumerate(upper):
            if j not in partners_up:
                apex = _deepest_point(upper_labels, region.label, window)
                solids.append(_cone(region.polygon, w1 + eps, apex, mid))

    last = len(planes) - 1
    for k, plane in enumerate(planes):
        for i, region in enumerate(items(plane)[0]):
            if i in continued[k]:
                continue
            rings = [(plane.w, region.polygon)]
            kk, ii = k, i
            while ii in following[kk]:
                ii, kk = following[kk][ii], kk + 1
                rings.append((planes[kk].w, items(planes[kk])[0][ii].polygon))
            # Rings mapped from one polygon keep its vertices in order: no re-alignment.
            aligned: set[int] = set()
            if k == 0 and ends[0] is not None:
                first = rings[0][1]
                rings[:0] = [(m.w, m.forward(first)) for m in ends[0]]
                aligned.update(range(len(ends[0])))
            if kk == last and ends[1] is not None:
                final = rings[-1][1]
                aligned.update(range(len(rings) - 1, len(rings) - 1 + len(ends[1])))
                rings.extend((m.w, m.forward(final)) for m in ends[1])
            if len(rings) < 2:
                continue
            rings[0] = (rings[0][0] - eps, rings[0][1])
            rings[-1] = (rings[-1][0] + eps, rings[-1][1])
            solids.append(_tube(rings, aligned))
    return [s for s in solids if s is not None]


def _deepest_point(labels: NDArray[np.int32], label: int, window: _Window) -> NDArray[np.float64]:
    """Plane coordinates (u, v) of the region pixel farthest from its boundary."""
    rows, cols = np.nonzero(labels == label)
    bbox = (slice(rows.min(), rows.max() + 1), slice(cols.min(), cols.max() + 1))
    sub = np.pad(labels[bbox] == label, 1)
    depth = ndimage.distance_transform_edt(sub, sampling=window.spacing)
    r, c = np.unravel_index(int(np.argmax(depth)), depth.shape)
    return np.array(
        [r - 1 + bbox[0].start + window.u0, c - 1 + bbox[1].start + window.v0], dtype=np.float64
    )


def _cap(polygon: NDArray[np.float64]) -> NDArray[np.int64]:
    """Triangles (counter-clockwise in (u, v)) filling a counter-clockwise polygon."""
    return np.asarray(manifold3d.triangulate([polygon]), dtype=np.int64).reshape(-1, 3)


def _arc_parameters(polygon: NDArray[np.float64]) -> NDArray[np.float64]:
    """Normalised arc length at vertices ``0..N`` (closing vertex included), shape (N + 1,)."""
    closed = np.vstack([polygon, polygon[:1]])
    lengths = np.linalg.norm(np.diff(closed, axis=0), axis=1)
    cumulative = np.concatenate([[0.0], np.cumsum(lengths)])
    return cumulative / cumulative[-1]


def _resample(polygon: NDArray[np.float64], count: int) -> NDArray[np.float64]:
    """``count`` points equally spaced by arc length from vertex 0, shape (count, 2)."""
    params = _arc_parameters(polygon)
    closed = np.vstack([polygon, polygon[:1]])
    t = np.arange(count) / count
    return np.column_stack([np.interp(t, params, closed[:, 0]), np.interp(t, params, closed[:, 1])])


def _normalised(polygon: NDArray[np.float64]) -> NDArray[np.float64]:
    """Polygon centred on its centroid and scaled to unit area."""
    scale = np.sqrt(max(abs(_signed_area(polygon)), 1e-12))
    return (polygon - _centroid(polygon)) / scale


def _align_start(lower: NDArray[np.float64], upper: NDArray[np.float64]) -> int:
    """Index of the upper vertex to start the band at (least twist against lower[0])."""
    k = _ALIGN_SAMPLES
    p = _resample(_normalised(lower), k)
    q = _resample(_normalised(upper), k)
    sq = (p * p).sum(1)[:, None] + (q * q).sum(1)[None, :] - 2.0 * p @ q.T  # (k, k)
    shifts = (np.arange(k)[:, None] + np.arange(k)[None, :]) % k
    cost = sq[np.arange(k)[:, None], shifts].sum(axis=0)
    target = float(np.argmin(cost)) / k
    params = _arc_parameters(upper)[:-1]
    gap = np.abs(params - target)
    return int(np.argmin(np.minimum(gap, 1.0 - gap)))


def _band(
    lower: NDArray[np.float64], upper: NDArray[np.float64], *, aligned: bool = False
) -> NDArray[np.int64]:
    """Triangles joining two counter-clockwise polygons, lower below upper.

    Indices ``0..n-1`` are the lower vertices and ``n..n+m-1`` the upper ones
    (in their given order). The upper polygon is read from the vertex chosen
    by :func:`_align_start` (from vertex 0 when ``aligned``: the upper polygon
    is the lower one mapped, vertex for vertex); the arc-length parameters of both polygons are
    merged in increasing order and each step advances on one polygon, adding
    one triangle, so every vertex of both is used.
    """
    n, m = lower.shape[0], upper.shape[0]
    start = 0 if aligned or upper is lower else _align_start(lower, upper)
    s = _arc_parameters(lower)
    t = _arc_parameters(np.roll(upper, -start, axis=0))
    params = np.concatenate([s[1:], t[1:]])
    on_lower = np.concatenate([np.ones(n, dtype=bool), np.zeros(m, dtype=bool)])
    order = np.lexsort((~on_lower, params))
    step_lower = on_lower[order]
    i = np.cumsum(step_lower) - step_lower
    j = np.cumsum(~step_lower) - ~step_lower
    up = n + (start + j) % m
    up_next = n + (start + j + 1) % m
    return np.where(
        step_lower[:, None],
        np.column_stack([i % n, (i + 1) % n, up]),
        np.column_stack([i % n, up_next, up]),
    )


def _tube(
    rings: list[tuple[float, NDArray[np.float64]]], aligned: set[int] | None = None
) -> manifold3d.Manifold | None:
    """Closed solid through counter-clockwise polygons at increasing ``w``, capped at both ends.

    ``aligned`` holds the ``k`` whose rings ``k`` and ``k + 1`` correspond
    vertex for vertex (see :func:`_band`).
    """
    sizes = [poly.shape[0] for _, poly in rings]
    offsets = np.concatenate([[0], np.cumsum(sizes)])
    verts = np.vstack([np.column_stack([poly, np.full(poly.shape[0], w)]) for w, poly in rings])
    faces = []
    for k in range(len(rings) - 1):
        band = _band(rings[k][1], rings[k + 1][1], aligned=aligned is not None and k in aligned)
        n = sizes[k]
        faces.append(np.where(band < n, band + offsets[k], band - n + offsets[k + 1]))
    faces.append(_cap(rings[0][1])[:, ::-1] + offsets[0])
    faces.append(_cap(rings[-1][1]) + offsets[-2])
    solid = solid_from_arrays(verts, np.vstack(faces))
    if solid is None:
        logger.warning("skipped a lofted tube that is not a closed manifold (%d rings)", len(rings))
    return solid


def _cone(
    polygon: NDArray[np.float64], w: float, apex: NDArray[np.float64], w_apex: float
) -> manifold3d.Manifold | None:
    """Closed cone from a counter-clockwise polygon at ``w`` to a point at ``w_apex``."""
    n = polygon.shape[0]
    verts = np.vstack(
        [
            np.column_stack([polygon, np.full(n, w)]),
            [[apex[0], apex[1], w_apex]],
        ]
    )
    idx = np.arange(n)
    sides = np.column_stack([idx, (idx + 1) % n, np.full(n, n)])
    faces = np.vstack([sides, _cap(polygon)[:, ::-1]])
    if w_apex < w:
        faces = faces[:, ::-1]
    solid = solid_from_arrays(verts, faces)
    if solid is None:
        logger.warning("skipped a cap cone that is not a closed manifold (%d vertices)", n)
    return solid
