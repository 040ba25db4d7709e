"""Signed-distance interpolation between section planes: the implicit baseline.

Each plane's mask becomes a 2-D signed distance (mm, negative inside); the
distance is interpolated linearly along the section axis to every voxel of
the reference grid (or of a grid ``upsample`` times finer along the axis),
and the shape is where the interpolated distance is negative. This is the
classic shape-based interpolation of medical imaging (Raya & Udupa 1990;
Herman et al. 1992).

Extent along the axis (the same semantics as :func:`~slicerecon.surface.loft.loft`):

* without a box, the shape spans the first to the last plane (a single plane
  is a slab half a voxel thick on each side);
* with a box, only planes inside the box are used; with ``extend_to_box``,
  the first / last plane is extended to the box faces (unchanged, a prism, or
  following the visual hull's extent when a ``hull`` is given:
  :mod:`~slicerecon.surface.extension`), and a box holding no plane is filled
  by interpolating between the planes either side of it.

In-plane distances are computed on the box's crop grown by one pixel (beyond
it counts as background), so that they see the shape just past the box
faces; the field itself covers the box only.

Appearing and vanishing regions: when a plane is empty, its "distance" is
taken as the constant depth of the deepest region of the other plane of the
slab, so that this region closes off half-way between the planes (as the
lofted cones do) and shallower regions sooner.

Meshes
------
A part's field is padded with its mirror image (``+|f|``) one sample beyond
each box face, so its surface crosses the faces half-way, exactly on them.
Several parts are merged *implicitly*: the union of shapes is the minimum of
their signed distances, so :func:`sdf_parts_mesh` takes the minimum of the
parts' padded fields on one grid and runs marching cubes once. No mesh
Boolean is needed, and neighbouring parts join without a seam.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import NamedTuple

import numpy as np
import trimesh
from numpy.typing import NDArray
from scipy import ndimage

from ..errors import EmptyMaskError, InputError, OptionError
from ..sections import Box, CrossSections, Volume
from .across_planes import INTERPOLATIONS, fill_between
from .drift import join_drifting_regions
from .extension import LayerMap, check_hull, extension_maps, interpolate_maps
from .marching import march_field
from .silhouettes import carve_field

__all__ = [
    "INTERPOLATIONS",
    "plane_signed_distance",
    "sdf_field",
    "sdf_interpolate",
    "sdf_mesh",
    "sdf_parts_mesh",
    "sdf_parts_surface",
    "SdfField",
    "SdfSurface",
]

logger = logging.getLogger(__name__)

_LEVEL_GAP = 1e-3
"""Smallest distance from the zero level kept in a meshed field, in sample spacings."""

_MARGIN = 1
"""Pixels around a box seen by the in-plane distance transform."""


def plane_signed_distance(
    mask: NDArray[np.bool_], spacing: tuple[float, float] | NDArray[np.float64]
) -> NDArray[np.float32]:
    """2-D signed distance of a mask to its boundary, mm, negative inside.

    Parameters
    ----------
    mask : ndarray of shape (M, N), bool
        In-plane mask. Pixels beyond its border count as background.
    spacing : sequence of 2 floats
        Pixel size along rows and columns, mm.

    Returns
    -------
    ndarray of shape (M, N), float32
        Distance from each pixel centre to the nearest pixel centre of the
        other class, less half the smaller pixel size (so the zero level sits
        half-way between a foreground and a background centre, the 0.5
        iso-contour). Positive outside, negative inside; all ``+inf`` when the
        mask is empty.
    """
    sp = np.asarray(spacing, dtype=np.float64)
    if not mask.any():
        return np.full(mask.shape, np.inf, dtype=np.float32)
    half = 0.5 * float(sp.min())
    padded = np.pad(mask, 1)
    inside = ndimage.distance_transform_edt(padded, sampling=sp)[1:-1, 1:-1]
    outside = ndimage.distance_transform_edt(~padded, sampling=sp)[1:-1, 1:-1]
    return np.where(mask, half - inside, outside - half).astype(np.float32)


# -- validation -------------------------------------------------------------------------
def _check(
    sections: CrossSections,
    upsample: int,
    extend_to_box: bool,
    hull: object = None,
    interpolation: str = "linear",
) -> int:
    if not isinstance(sections, CrossSections):
        raise InputError(f"SDF interpolation needs CrossSections (got {type(sections).__name__})")
    if isinstance(upsample, bool) or not isinstance(upsample, int | np.integer) or upsample < 1:
        raise OptionError(f"upsample must be a positive integer (got {upsample!r})")
    if not isinstance(extend_to_box, bool | np.bool_):
        raise OptionError(f"extend_to_box must be True or False (got {extend_to_box!r})")
    check_hull(hull, sections.grid_shape)
    if interpolation not in INTERPOLATIONS:
        raise OptionError(
            f"interpolation must be one of {', '.join(INTERPOLATIONS)} (got {interpolation!r})"
        )
    return int(upsample)


def _grid_box(sections: CrossSections, box: Box | None) -> Box:
    """The box clipped to the reference grid (the whole grid for None)."""
    grid = Box((0, 0, 0), sections.grid_shape)
    if box is None:
        return grid
    if not isinstance(box, Box):
        raise InputError(f"box must be a slicerecon Box (got {type(box).__name__})")
    inside = box.intersect(grid)
    if inside is None:
        raise OptionError(
            f"box {box.to_dict()} lies outside the reference grid {sections.grid_shape}"
        )
    return inside


# -- fields -----------------------------------------------------------------------------
def _box_field(
    sections: CrossSections,
    box: Box,
    *,
    bounded: bool,
    upsample: int,
    extend_to_box: bool,
    hull: NDArray[np.bool_] | None = None,
    interpolation: str = "linear",
    join_drift: bool = False,
) -> NDArray[np.float32]:
    """Interpolated signed distance on the samples of ``box``, axis first.

    ``bounded`` says whether the box restricts the planes (a user box) or is
    the whole grid (no box: all planes, no extension). ``hull`` guides the
    extensions to the box faces (:mod:`~slicerecon.surface.extension`).

    Returns
    -------
    ndarray of shape (n_axis, M, N), float32
        ``n_axis = box.shape[axis] * upsample``; ``(M, N)`` the box's in-plane size.
    """
    axis = sections.axis
    a, b = sections.plane_axes
    grid = sections.grid_shape
    rows = (max(box.lo[a] - _MARGIN, 0), min(box.hi[a] + _MARGIN, grid[a]))
    cols = (max(box.lo[b] - _MARGIN, 0), min(box.hi[b] + _MARGIN, grid[b]))
    inner = (
        slice(box.lo[a] - rows[0], box.hi[a] - rows[0]),
        slice(box.lo[b] - cols[0], box.hi[b] - cols[0]),
    )
    spacing = sections.spacing[[a, b]]
    crop = sections.masks[:, rows[0] : rows[1], cols[0] : cols[1]]
    samples = box.lo[axis] - 0.5 + (np.arange(box.shape[axis] * upsample) + 0.5) / upsample
    far = np.float32(np.hypot(*(np.asarray(crop.shape[1:]) * spacing)) + spacing.max())
    field = np.full((samples.size, *crop.shape[1:]), far, dtype=np.float32)

    w = sections.indices
    if not bounded:
        used = np.arange(sections.n_planes)
    else:
        used = sections.planes_in(box, bridge=extend_to_box)
    if used.size and crop[used].any():
        distances = {int(p): plane_signed_distance(crop[p], spacing) for p in used}
        fill_between(field, samples, w, used, distances, interpolation)
        if join_drift:
            join_drifting_regions(
                field,
                samples,
                w,
                used,
                crop,
                spacing,
                float(sections.spacing[axis]),
                plane_signed_distance,
            )
        first, last = int(used[0]), int(used[-1])
        if bounded and extend_to_box:
            # <= and >=: a box holding one plane has no interpolated sample on it.
            for side, plane in ((0, first), (1, last)):
                sel = np.flatnonzero(samples <= w[plane] if side == 0 else samples >= w[plane])
                base = np.minimum(distances[plane], far)
                maps = extension_maps(hull, box, axis, float(w[plane]), side)
                if not maps:  # the plane lies on the face: nothing to extend
                    field[sel] = base
                    continue
                own = maps[0].unchanged(float(w[plane]))
                ordered = [own, *maps] if side == 1 else [*maps, own]
                _extend(field, sel, samples, base, ordered, (rows[0], cols[0]))
        elif used.size == 1:
            near = (samples >= w[first] - 0.5) & (samples < w[first] + 0.5)
            field[near] = np.minimum(distances[first], far)
    return field[:, inner[0], inner[1]]  # a view: callers copy or reduce it once


def _extend(
    field: NDArray[np.float32],
    sel: NDArray[np.int64],
    samples: NDArray[np.float64],
    base: NDArray[np.float32],
    maps: list[LayerMap],
    origin: tuple[int, int],
) -> None:
    """Fill samples ``sel`` with the plane's distance ``base`` carried through ``maps``.

    ``maps`` (one slab's, sorted by ``w``, the plane's own identity first or
    last) are interpolated linearly in ``w``, as the loft's rings are; each
    sample's pixel centres are mapped back onto the plane and ``base`` (on the
    crop starting at in-plane index ``origin``) is read there bilinearly.
    """
    u = np.arange(base.shape[0], dtype=np.float64) + origin[0]
    v = np.arange(base.shape[1], dtype=np.float64) + origin[1]
    grid = np.stack(np.meshgrid(u, v, indexing="ij"), axis=-1)
    for k in sel:
        layer = interpolate_maps(maps, float(samples[k]))
        if layer.is_identity():
            field[k] = base
            continue
        source = layer.inverse(grid) - np.asarray(origin, dtype=np.float64)
        field[k] = ndimage.map_coordinates(
            base, [source[..., 0], source[..., 1]], order=1, mode="nearest"
        )


def _to_index(
    sections: CrossSections, lo: tuple[int, int, int], upsample: int, pad: int
) -> NDArray[np.float64]:
    """Affine from sample indices of a grid starting at box corner ``lo`` to voxel indices.

    ``pad`` samples of padding precede the box on every axis.
    """
    axis = sections.axis
    out = np.eye(4)
    out[:3, 3] = np.asarray(lo, dtype=np.float64) - pad
    out[axis, axis] = 1.0 / upsample
    out[axis, 3] = lo[axis] - 0.5 + (0.5 - pad) / upsample
    return out


def sdf_field(
    sections: CrossSections,
    *,
    box: Box | None = None,
    upsample: int = 1,
    extend_to_box: bool = False,
    hull: NDArray[np.bool_] | None = None,
    interpolation: str = "linear",
    join_drift: bool = False,
) -> tuple[NDArray[np.float32], NDArray[np.float64]]:
    """The interpolated signed distance on the (box of the) reference grid.

    Parameters
    ----------
    sections : CrossSections
        Binary masks on parallel planes.
    box : Box, optional
        Restrict the field to this cuboid of the reference grid (clipped to
        the grid). Planes outside it along the axis are not used.
    upsample : int, default 1
        Samples per reference voxel along the section axis (>= 1). Sample
        ``m`` along the axis sits at index ``lo - 0.5 + (m + 0.5) / upsample``,
        so the samples tile the reference voxels.
    extend_to_box : bool, default False
        With a box: extend the first / last plane to the box faces and fill a
        box holding no plane (see the module docstring). Ignored without a box.
    hull : ndarray of shape sections.grid_shape, bool, optional
        The visual hull of the projections: the extensions to the box faces
        follow its extent layer by layer (:mod:`~slicerecon.surface.extension`)
        instead of repeating the outermost plane.
    interpolation : {"linear", "pchip"}, default "linear"
        Across planes: linear per slab (classic shape-based interpolation), or
        the monotone piecewise cubic through all planes of the box
        (:data:`INTERPOLATIONS`; see ``docs/method.md``).

    Returns
    -------
    field : ndarray of shape (I', J', K'), float32
        Signed distance in mm (negative inside) in the reference axis order
        x, y, z; the section axis has ``(hi - lo) * upsample`` samples, the
        other axes the box's (or grid's) size. Samples outside the shape's
        extent hold a positive distance larger than any in-plane distance.
    affine : ndarray of shape (4, 4)
        Sample index → world mm (the reference affine, shifted to the box and
        with the section-axis column divided by ``upsample``).

    Raises
    ------
    InputError
        If ``sections`` is not a CrossSections or ``box`` not a Box.
    OptionError
        If ``upsample`` is not a positive integer or the box lies outside the grid.
    """
    upsample = _check(sections, upsample, extend_to_box, hull, interpolation)
    region = _grid_box(sections, box)
    field = _box_field(
        sections,
        region,
        bounded=box is not None,
        upsample=upsample,
        extend_to_box=extend_to_box,
        hull=hull,
        interpolation=interpolation,
        join_drift=join_drift,
    )
    out = np.ascontiguousarray(np.moveaxis(field, 0, sections.axis))
    affine = sections.affine @ _to_index(sections, region.lo, upsample, pad=0)
    logger.debug("SDF interpolation onto %s samples (upsample %d)", out.shape, upsample)
    return out, affine


def sdf_interpolate(
    sections: CrossSections,
    *,
    box: Box | None = None,
    upsample: int = 1,
    extend_to_box: bool = False,
    hull: NDArray[np.bool_] | None = None,
    interpolation: str = "linear",
    join_drift: bool = False,
) -> Volume:
    """Shape-based interpolation of the sections onto the (box of the) reference grid.

    Parameters
    ----------
    sections, box, upsample, extend_to_box, hull, interpolation
        As for :func:`sdf_field`.

    Returns
    -------
    Volume
        Mask where the interpolated signed distance is negative, shape as
        :func:`sdf_field`'s field, with its own affine (the box's sub-grid,
        refined along the section axis when ``upsample > 1``). With
        ``upsample=1`` and planes on grid indices, every plane is reproduced
        exactly.
    """
    field, affine = sdf_field(
        sections,
        box=box,
        upsample=upsample,
        extend_to_box=extend_to_box,
        hull=hull,
        interpolation=interpolation,
        join_drift=join_drift,
    )
    return Volume(field < 0, affine)


def sdf_mesh(
    sections: CrossSections,
    *,
    box: Box | None = None,
    upsample: int = 1,
    extend_to_box: bool = False,
    hull: NDArray[np.bool_] | None = None,
    interpolation: str = "linear",
    join_drift: bool = False,
) -> trimesh.Trimesh:
    """Closed surface of the SDF-interpolated shape (marching cubes), world mm.

    Parameters
    ----------
    sections, box, upsample, extend_to_box, hull, interpolation
        As for :func:`sdf_field`.

    Returns
    -------
    trimesh.Trimesh
        Watertight, outward-oriented mesh. Where the shape reaches a face of
        the box (or of the grid), the surface lies on that face.

    Raises
    ------
    EmptyMaskError
        If no sample is inside.
    """
    upsample = _check(sections, upsample, extend_to_box, hull, interpolation)
    region = _grid_box(sections, box)
    field = _box_field(
        sections,
        region,
        bounded=box is not None,
        upsample=upsample,
        extend_to_box=extend_to_box,
        hull=hull,
        interpolation=interpolation,
        join_drift=join_drift,
    )
    return _mesh(sections, _mirror_pad(field), region.lo, upsample)


def sdf_parts_mesh(
    sections: CrossSections,
    boxes: Sequence[Box],
    *,
    upsample: int = 1,
    extend_to_box: bool = True,
    hull: NDArray[np.bool_] | None = None,
    interpolation: str = "linear",
    join_drift: bool = False,
    carve: NDArray[np.bool_] | None = None,
    cover: bool = False,
) -> trimesh.Trimesh:
    """Closed surface of the union of several parts' SDF interpolations, world mm.

    Each part is interpolated in its own box (as :func:`sdf_mesh` with that
    box) and padded with its mirror image beyond the box faces; the union is
    the pointwise minimum of these fields on the boxes' common grid, meshed
    once by marching cubes.

    Parameters
    ----------
    sections : CrossSections
        Binary masks on parallel planes.
    boxes : sequence of Box
        The parts' boxes (clipped to the grid; they may touch or overlap).
    upsample, extend_to_box, hull, interpolation
        As for :func:`sdf_field`.
    carve : ndarray of shape sections.grid_shape, bool, optional
        A visual hull to intersect the union with *implicitly*: at every
        sample outside the hull the field is raised to at least
        :data:`~slicerecon.surface.silhouettes.HULL_LEVEL` of a voxel (positive,
        outside), so one marching cubes
        gives the carved surface, with no mesh Boolean. Samples inside the
        hull keep their values, so where the surface already stops at the
        hull (the end caps) it is not moved; where the hull cuts, the cut lies
        between an inside sample and the outside one, nearer the outside one
        the deeper the inside sample (it never cuts into the hull). The
        samples' occupancy is exactly the intersection.

    Returns
    -------
    trimesh.Trimesh
        Watertight, outward-oriented mesh.

    Raises
    ------
    OptionError
        If ``boxes`` is empty or a box lies outside the grid.
    EmptyMaskError
        If no part holds any inside sample.
    """
    union, lo, _ = _parts_union(
        sections,
        boxes,
        upsample=upsample,
        extend_to_box=extend_to_box,
        hull=hull,
        interpolation=interpolation,
        join_drift=join_drift,
        carve=carve,
        cover=cover,
    )
    return _mesh(sections, np.moveaxis(union, sections.axis, 0), lo, upsample)


def _parts_union(
    sections: CrossSections,
    boxes: Sequence[Box],
    *,
    upsample: int,
    extend_to_box: bool,
    hull: NDArray[np.bool_] | None,
    interpolation: str,
    join_drift: bool,
    carve: NDArray[np.bool_] | None,
    cover: bool = False,
) -> tuple[NDArray[np.float32], tuple[int, int, int], tuple[int, int, int]]:
    """The union of the parts' padded fields (carved), its box ``[lo, hi)`` on the grid."""
    upsample = _check(sections, upsample, extend_to_box, hull, interpolation)
    regions = [_grid_box(sections, b) for b in boxes]
    if not regions:
        raise OptionError("give at least one box (part) to reconstruct")
    axis = sections.axis
    lo = tuple(int(min(r.lo[ax] for r in regions)) for ax in range(3))
    hi = tuple(int(max(r.hi[ax] for r in regions)) for ax in range(3))
    scale = np.ones(3, dtype=np.int64)
    scale[axis] = upsample
    shape = [(h - low) * s + 2 for low, h, s in zip(lo, hi, scale, strict=True)]
    # Inside the parts' boxes the union is the minimum of the parts' fields.
    # Beyond every box, where only the mirror padding reaches, it is the
    # largest padding value: there a neighbour's corner padding (small near
    # its own face) must not pull the surface beyond another part's face.
    if len(regions) == 1:
        part = _box_field(
            sections,
            regions[0],
            bounded=True,
            upsample=upsample,
            extend_to_box=extend_to_box,
            hull=hull,
            interpolation=interpolation,
            join_drift=join_drift,
        )
        if not np.any(part < 0):
            raise EmptyMaskError("no part's box holds any section foreground")
        union = _mirror_pad(np.moveaxis(part, 0, axis))  # C order in grid axes: one copy
        del part
        return carve_field(sections, union, lo, hi, upsample, carve, cover=cover), lo, hi
    inner: NDArray[np.float32] | None = None
    covered = np.zeros(shape, dtype=bool)
    padding = np.full(shape, -1.0, dtype=np.float32)
    far = np.float32(0.0)
    for region in regions:
        part = _box_field(
            sections,
            region,
            bounded=True,
            upsample=upsample,
            extend_to_box=extend_to_box,
            hull=hull,
            interpolation=interpolation,
            join_drift=join_drift,
        )
        if not np.any(part < 0):
            continue
        moved = np.moveaxis(part, 0, axis)
        if inner is None:
            inner = np.full(shape, np.float32(np.inf), dtype=np.float32)
        far = max(far, np.float32(np.abs(part).max()))
        start = [(r - low) * s + 1 for r, low, s in zip(region.lo, lo, scale, strict=True)]
        core = tuple(slice(s0, s0 + n) for s0, n in zip(start, moved.shape, strict=True))
        np.minimum(inner[core], moved, out=inner[core])
        covered[core] = True
        padded = np.moveaxis(_mirror_pad(part), 0, axis)
        where = tuple(slice(s0 - 1, s0 - 1 + n) for s0, n in zip(start, padded.shape, strict=True))
        np.maximum(padding[where], padded, out=padding[where])
    if inner is None:
        raise EmptyMaskError("no part's box holds any section foreground")
    union = np.where(covered, inner, np.where(padding >= 0, padding, far))
    del inner, padding, covered
    logger.debug("merged %d SDF parts on a %s grid", len(regions), tuple(shape))
    return carve_field(sections, union, lo, hi, upsample, carve, cover=cover), lo, hi


class SdfField(NamedTuple):
    """A signed-distance field ready for marching cubes, and where its samples lie.

    Attributes
    ----------
    values : ndarray of shape (I', J', K'), float32
        mm, negative inside, in grid axis order, padded by one positive sample
        on every side (so its zero level is closed).
    affine : ndarray of shape (4, 4)
        Sample index → world mm.
    lo : tuple of int
        The reference-grid voxel of the first unpadded sample's voxel.
    upsample : int
        Samples per voxel along the section axis (1 elsewhere).
    axis : int
        The section axis.
    """

    values: NDArray[np.float32]
    affine: NDArray[np.float64]
    lo: tuple[int, int, int]
    upsample: int
    axis: int


class SdfSurface(NamedTuple):
    """A meshed signed-distance reconstruction and its occupancy at the voxel centres.

    Attributes
    ----------
    mesh : trimesh.Trimesh
        Watertight, outward surface, world mm.
    occupancy : Volume or None
        The voxel centres inside the surface, on the sub-grid of the reference
        grid that the parts' boxes span (exactly the samples of negative field
        the marching cubes separated from the others); None when the field was
        sampled finer than the grid (``upsample > 1``).
    field : SdfField or None
        The field the mesh was extracted from, when asked for (``keep_field``).
    """

    mesh: trimesh.Trimesh
    occupancy: Volume | None
    field: SdfField | None = None


def sdf_parts_surface(
    sections: CrossSections,
    boxes: Sequence[Box],
    *,
    upsample: int = 1,
    extend_to_box: bool = True,
    hull: NDArray[np.bool_] | None = None,
    interpolation: str = "linear",
    join_drift: bool = False,
    carve: NDArray[np.bool_] | None = None,
    keep_field: bool = False,
    cover: bool = False,
) -> SdfSurface:
    """As :func:`sdf_parts_mesh`, also returning the occupancy the mesh encloses.

    The occupancy comes free with the field, so a metric of the reconstruction
    on the reference grid needs no rasterization of the mesh. ``keep_field``
    also returns the field itself (:class:`SdfField`), e.g. to resolve several
    structures jointly (:mod:`slicerecon.surface.joint`).
    """
    union, lo, hi = _parts_union(
        sections,
        boxes,
        upsample=upsample,
        extend_to_box=extend_to_box,
        hull=hull,
        interpolation=interpolation,
        join_drift=join_drift,
        carve=carve,
        cover=cover,
    )
    # _parts_union guarantees an inside sample; the mesh may repair ``union`` in place
    # (march_field), so the occupancy is read after it.
    mesh = _mesh(sections, np.moveaxis(union, sections.axis, 0), lo, upsample, checked=True)
    occupancy = None
    if upsample == 1:
        inside = union[1:-1, 1:-1, 1:-1] < 0
        affine = sections.affine.copy()
        affine[:3, 3] = sections.affine[:3, :3] @ np.asarray(lo, dtype=np.float64) + affine[:3, 3]
        occupancy = Volume(inside, affine)
    field = None
    if keep_field:
        affine = sections.affine @ _to_index(sections, lo, upsample, pad=1)
        field = SdfField(union, affine, lo, upsample, sections.axis)
    return SdfSurface(mesh, occupancy, field)


def _mirror_pad(field: NDArray[np.float32]) -> NDArray[np.float32]:
    """Pad with one layer of ``+|f|`` of the neighbouring sample: the surface meets the faces."""
    padded = np.empty(tuple(n + 2 for n in field.shape), dtype=field.dtype)
    padded[1:-1, 1:-1, 1:-1] = field
    # Edge padding of |f|, one axis at a time (each pass also fills the earlier
    # axes' padding), without an |f| copy of the whole field.
    for axis in range(3):
        for side, source in ((0, 1), (-1, -2)):
            out = [slice(None)] * 3
            out[axis] = side
            inner = [slice(None)] * 3
            inner[axis] = source
            np.abs(padded[tuple(inner)], out=padded[tuple(out)])
    return padded


def _mesh(
    sections: CrossSections,
    padded: NDArray[np.float32],
    lo: tuple[int, ...],
    upsample: int,
    *,
    checked: bool = False,
) -> trimesh.Trimesh:
    """Mesh a padded, axis-first field whose box starts at voxel ``lo``.

    Samples closer to the zero level than :data:`_LEVEL_GAP` sample spacings
    are pushed off it first: a sample on the level puts vertices of several
    triangles on one grid point and pinches the mesh. ``checked``: the caller
    already knows that some sample is inside.
    """
    if not checked and not np.any(padded < 0):
        raise EmptyMaskError("no section foreground in the sampled region: nothing to mesh")
    field = np.ascontiguousarray(np.moveaxis(padded, 0, sections.axis))
    affine = sections.affine @ _to_index(sections, (lo[0], lo[1], lo[2]), upsample, pad=1)
    step = float(np.min(np.linalg.norm(affine[:3, :3], axis=0)))
    nudge = np.float32(_LEVEL_GAP * step)
    near = np.flatnonzero(np.abs(field) < nudge)
    flat = field.reshape(-1)
    flat[near] = np.where(flat[near] < 0, -nudge, nudge)
    # The padded field is finite, closed (positive on every border sample) and
    # off its zero level: marching cubes runs on it as it is, without copies (a
    # contiguous ``padded`` in grid order is ``field`` itself, repaired in place).
    return march_field(field, affine)
