"""Reconstruction from planes along several axes: every drawn view used at once.

An annotator may draw a structure on a few axial slices and on one or two
sagittal and coronal ones. The planes of one orientation form a **view**. The
view with the most planes (when it has two or more, or is the only view) is
**complete**: it is interpolated across its planes as shape-based
interpolation does (:func:`slicerecon.surface.across_planes.fill_between`: the
in-plane signed distances, linear or monotone cubic along the view's normal),
and the structure ends beyond its outer planes by half a voxel (a label map's
slice, a contour on its image's slice) or, for contours read without an image,
half the structure's own plane spacing (each contour standing for the slab
half-way to its neighbours; :attr:`~slicerecon.annotation.Annotation.gap_ends`).

Every other view **corrects** that interpolation: on each of its planes the
*residual* is the drawn in-plane signed distance less the complete view's
field there, and the view's field is the complete one plus the residual of its
nearest plane, carried along its normal. The views are blended voxel by voxel
with weights ``(D_min / D) ** p``, ``D`` the distance to the view's nearest
plane and ``D_min`` the nearest view's (inverse-distance weighting, Shepard
1968; ``p`` = :data:`VIEW_WEIGHT_EXPONENT`), so the result is the complete
view's interpolation moved, near each other plane, by what that plane shows it
got wrong:

* on a drawn plane its own view has ``D = 0``, so the result's section there is
  the drawn mask (the zero level lies half-way between pixel centres, as in
  every signed-distance surface here);
* between the complete view's planes it dominates, near a sagittal plane the
  sagittal correction does, and where the complete view ends, a sagittal plane
  that shows the structure going on moves the end;
* where other views draw the structure well beyond the complete view's first or
  last plane (:func:`~slicerecon.surface.view_planes.carried_ends`), that end is
  carried on to their drawings, weighing :data:`BEYOND_PENALTY` times less
  there, so that their corrections shape it between their planes (it ended half
  a voxel past its plane, and only their planes showed the rest: thin slabs).

With no complete view (a radial set of single planes through one axis) each
view is its own interpolation, extruded beyond its outer planes, where it weighs
:data:`BEYOND_PENALTY` times less. Between two planes of one view and nothing
else, the result is that view's own interpolation: a single-axis annotation
gives shape-based interpolation. This is not a union of per-axis results (ITK's
morphological contour interpolation takes one), and every view constrains
every point. Measured choices (``benchmarks/annotations.py --half dev``):
carrying the nearest plane's residual beats interpolating the residuals between
the view's planes, and beats blending the views' own interpolations.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from ..annotation import Annotation, window
from ..errors import EmptyMaskError, GeometryError
from ..io.limits import check_grid
from ..sections import Volume, in_plane_axes
from .across_planes import fill_between
from .drift import join_drifting_regions
from .marching import march_field
from .sdf import SdfField, plane_signed_distance
from .view_planes import (
    END_REACH,
    Carry,
    ObliqueView,
    carried_ends,
    end_reach,
    views_of,
)

__all__ = ["VIEW_WEIGHT_EXPONENT", "ViewsSurface", "views_field", "views_surface"]


VIEW_WEIGHT_EXPONENT = 6.0
"""``p`` of the views' inverse-distance weights (chosen on the development shapes)."""
BEYOND_PENALTY = 2.0
"""Factor on the distance of a sample beyond the outer planes of a view that is
extruded there (no complete view to correct; chosen on the development shapes), or of
the complete view where its end is carried on to other views' drawings."""
RESIDUAL_BAND = 6.0
"""How far (pixels of the plane) a plane's residual reaches around where the plane and the
complete view disagree on inside and outside (chosen on the development shapes)."""
CROP_PAD = 3
"""Voxels kept around the drawn foreground."""
_EPS_MM = 1e-3


@dataclass
class ViewsSurface:
    """A structure reconstructed from several views.

    Attributes
    ----------
    mesh : trimesh.Trimesh
        Closed, outward, world mm.
    occupancy : Volume or None
        The voxel centres inside, on the crop of the reference grid (None when
        the main axis is sampled finer than its voxels: rasterize the mesh).
    field : SdfField
        The blended signed-distance field (padded), for a joint resolution.
    """

    mesh: object
    occupancy: Volume | None
    field: SdfField


def views_field(
    annotation: Annotation,
    value: int,
    *,
    interpolation: str = "pchip",
    join_drift: bool = True,
    exponent: float = VIEW_WEIGHT_EXPONENT,
) -> SdfField:
    """The blended signed-distance field of one structure drawn in several views.

    Parameters
    ----------
    annotation : Annotation
        Planes of any orientation: slices of its reference grid are
        interpolated on the grid's own voxels, other planes through their
        projections (bilinear in-plane, linear along their normal).
    value : int
        The structure.
    interpolation : {"pchip", "linear"}
        Across each view's planes.
    join_drift : bool
        Join regions of consecutive planes of a view that overlap nothing on
        the other plane (:mod:`slicerecon.surface.drift`).
    exponent : float
        ``p`` of the inverse-distance weights.

    Returns
    -------
    SdfField
        mm, negative inside, on the crop of the reference grid around the
        drawn foreground (finer along the main axis, :func:`views_upsample`),
        padded by one positive sample.

    Raises
    ------
    EmptyMaskError
        The structure is drawn nowhere.
    MemoryBudgetError
        The field's samples would exceed the default memory budget.
    """
    views, oblique = views_of(annotation, value)
    inverse = np.linalg.inv(annotation.affine)
    lo = np.full(3, np.iinfo(np.int64).max, dtype=np.int64)
    hi = np.full(3, np.iinfo(np.int64).min, dtype=np.int64)
    for axis, planes in views.items():
        a, b = in_plane_axes(axis)
        for index, mask in planes:
            if not mask.any():
                continue
            rows = np.flatnonzero(mask.any(axis=1))
            cols = np.flatnonzero(mask.any(axis=0))
            k = int(round(index))
            lo[a], hi[a] = min(lo[a], rows[0]), max(hi[a], rows[-1] + 1)
            lo[b], hi[b] = min(lo[b], cols[0]), max(hi[b], cols[-1] + 1)
            lo[axis], hi[axis] = min(lo[axis], k), max(hi[axis], k + 1)
    for view in oblique:
        for _, pose, mask in view.planes:
            if not mask.any():
                continue
            pixels = np.argwhere(mask)
            ends = pose.to_world(
                np.array(
                    [
                        [r, c]
                        for r in (pixels[:, 0].min(), pixels[:, 0].max())
                        for c in (pixels[:, 1].min(), pixels[:, 1].max())
                    ],
                    dtype=np.float64,
                )
            )
            index = ends @ inverse[:3, :3].T + inverse[:3, 3]
            lo = np.minimum(lo, np.floor(index.min(axis=0)).astype(np.int64))
            hi = np.maximum(hi, np.ceil(index.max(axis=0)).astype(np.int64) + 1)
    if np.any(hi <= lo):
        raise EmptyMaskError(f"structure {value} is drawn on no plane")
    counts = {axis: len(planes) for axis, planes in views.items()}
    counts.update({-1 - n: len(view.planes) for n, view in enumerate(oblique)})
    main = max(counts, key=lambda key: counts[key])

    def complete(key: int) -> bool:
        # the main view, of two planes or more (or the only view): a radial set of
        # single planes has no complete view, and the extra views of an axial stack
        # do not span the structure along their normals
        return key == main and (counts[key] >= 2 or len(counts) == 1)

    spacing = np.linalg.norm(annotation.affine[:3, :3], axis=0)
    own_gap = value in annotation.gap_ends
    # how far a complete view's structure goes on beyond its first and last planes
    reach: dict[int, tuple[float, float] | None] = {
        axis: end_reach([i for i, m in planes if m.any()], END_REACH, own_gap)
        if complete(axis)
        else None
        for axis, planes in views.items()
    }
    oblique_reach: list[tuple[float, float] | None] = [
        end_reach([o for o, _, m in view.planes if m.any()], END_REACH * spacing.min(), own_gap)
        if complete(-1 - n)
        else None
        for n, view in enumerate(oblique)
    ]
    # sides where the main view's end is carried on to where other views show the structure
    ends_carried: tuple[Carry | None, Carry | None] = (None, None)
    if complete(main) and len(counts) > 1:
        ends = reach[main] if main >= 0 else oblique_reach[-1 - main]
        ends_carried = carried_ends(
            annotation, views, oblique, main, ends, float(spacing.min()), value
        )
    pad = np.full(3, CROP_PAD, dtype=np.int64)
    carried = max([carry.reach for carry in ends_carried if carry is not None], default=0.0)
    for axis, extent in reach.items():
        if extent is not None:
            pad[axis] += int(np.ceil(max(*extent, carried if axis == main else 0.0)))
    extra_mm = max([max(r) for r in oblique_reach if r is not None], default=0.0)
    extra_mm = max(extra_mm, carried if main < 0 else 0.0)
    pad += np.ceil(extra_mm / spacing).astype(np.int64)
    # not clipped to the grid: a structure may reach beyond a grid that holds only
    # its drawn slices (a SEG of one frame); what lies outside is not written
    lo = lo - pad
    hi = hi + pad
    along = _main_grid_axis(annotation)
    upsample = views_upsample(annotation)
    size = [int(v) for v in hi - lo]
    size[along] *= upsample
    check_grid(size, what="the views' field")
    # sample positions along the main axis, in voxel index units (planes stay on samples)
    positions = lo[along] - 0.5 + (np.arange(size[along]) + 0.5) / upsample
    far = np.float32(np.linalg.norm(np.asarray(hi - lo) * spacing) + spacing.max())
    # the complete view first: every other view corrects its field near their planes
    keys = sorted(counts, key=lambda key: key != main)
    base = None
    fields, distances = [], []
    for key in keys:
        if key >= 0:
            own, distance = _view(
                views[key],
                key,
                lo,
                hi,
                spacing,
                far,
                interpolation,
                join_drift,
                reach[key],
                along,
                positions,
                base,
                upsample,
                ends_carried if key == main else (None, None),
            )
        else:
            own, distance = _oblique_view(
                oblique[-1 - key],
                annotation.affine,
                lo,
                size,
                along,
                positions,
                far,
                oblique_reach[-1 - key],
                base,
                upsample,
                ends_carried if key == main else (None, None),
            )
        if key == main and complete(main):
            base = own
        fields.append(own)
        distances.append(distance)
    # weights relative to the nearest view's distance: (D_min / D) ** p, never overflowing
    nearest = np.minimum.reduce(distances) + np.float32(_EPS_MM)
    numerator = np.zeros(size, dtype=np.float32)
    denominator = np.zeros(size, dtype=np.float32)
    for own, distance in zip(fields, distances, strict=True):
        weight = np.power(nearest / (distance + np.float32(_EPS_MM)), exponent, dtype=np.float32)
        numerator += weight * own
        denominator += weight
    values = numerator / denominator
    padded = np.full(tuple(n + 2 for n in size), far, dtype=np.float32)
    padded[1:-1, 1:-1, 1:-1] = values
    to_index = np.eye(4)
    to_index[:3, 3] = lo - 1.0
    to_index[along, along] = 1.0 / upsample
    to_index[along, 3] = lo[along] - 0.5 + (0.5 - 1) / upsample
    affine = annotation.affine @ to_index
    return SdfField(padded, affine, (int(lo[0]), int(lo[1]), int(lo[2])), upsample, along)


def _view(
    planes: list[tuple[float, NDArray]],
    axis: int,
    lo: NDArray[np.int64],
    hi: NDArray[np.int64],
    spacing: NDArray[np.float64],
    far: np.float32,
    interpolation: str,
    join_drift: bool,
    reach: tuple[float, float] | None,
    along: int,
    positions: NDArray[np.float64],
    base: NDArray[np.float32] | None = None,
    upsample: int = 1,
    ends_carried: tuple[Carry | None, Carry | None] = (None, None),
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """One view's field and each sample's distance (mm) to its nearest plane.

    Both on the crop in grid axis order, sampled at ``positions`` (voxel index
    units) along axis ``along`` and at the voxels along the others. ``reach``:
    how far (index units) a complete view's structure goes on beyond its first
    and last planes; None: an incomplete view, extruded beyond them. ``ends_carried``:
    on each side, the regions of the outer section carried on to other views'
    drawings, and how far (:func:`~slicerecon.surface.view_planes.carried_ends`); the
    view weighs less beyond its outer plane there (:data:`BEYOND_PENALTY`). Without ``base`` the
    field is the view's interpolation across its planes; with ``base`` (the
    complete view's field, on the same samples) it is ``base`` corrected by the
    nearest plane's residual (:func:`_corrected`).
    """
    a, b = in_plane_axes(axis)
    pixel = spacing[[a, b]]
    indices = np.array([p[0] for p in planes], dtype=np.float64)
    distances = {
        n: plane_signed_distance(window(mask, lo[[a, b]], hi[[a, b]]), pixel)
        for n, (_, mask) in enumerate(planes)
    }
    samples = positions if axis == along else np.arange(lo[axis], hi[axis], dtype=np.float64)
    penalised = reach is None and base is None
    nearest = _nearest_mm(
        samples, indices, float(spacing[axis]), penalised=penalised, sides=ends_carried
    )
    distance = np.broadcast_to(
        np.expand_dims(nearest, tuple(d for d in range(3) if d != axis)),
        tuple(len(positions) if d == along else int(hi[d] - lo[d]) for d in range(3)),
    )
    if base is not None:
        field = _corrected(
            distances, indices, samples, pixel, axis, lo, far, base, along, positions, upsample
        )
        return field, distance
    field = np.full((samples.size, hi[a] - lo[a], hi[b] - lo[b]), far, dtype=np.float32)
    used = np.arange(len(planes))
    fill_between(field, samples, indices, used, distances, interpolation)
    if join_drift and len(planes) > 1:
        masks = np.stack([window(mask, lo[[a, b]], hi[[a, b]]) for _, mask in planes])
        join_drifting_regions(
            field, samples, indices, used, masks, pixel, float(spacing[axis]), plane_signed_distance
        )
    for n, index in enumerate(indices):  # a plane's own samples hold its distances
        field[np.isclose(samples, index, atol=1e-9)] = np.minimum(distances[n], far)
    for side, n in ((0, 0), (1, len(planes) - 1)):
        base_n = np.minimum(distances[n], far)
        if reach is not None:
            # at and beyond the outer plane the structure ends ``reach`` beyond it:
            # max(d, distance past the end), which keeps the plane's own section
            beyond = samples <= indices[n] + 1e-9 if side == 0 else samples >= indices[n] - 1e-9
            past = np.abs(samples[beyond] - indices[n]).astype(np.float32)
            step = np.float32(spacing[axis])
            drawn = planes[n][1]
            carry = ends_carried[side] if drawn.any() else None
            if carry is not None:  # the rest of its section ends as the view
                rest = window(drawn & ~carry.regions, lo[[a, b]], hi[[a, b]])
                base_n = np.minimum(plane_signed_distance(rest, pixel), far)
            ended = np.maximum(base_n[None], ((past - reach[side]) * step)[:, None, None])
            if carry is not None:  # its continued regions go further
                regions = window(drawn & carry.regions, lo[[a, b]], hi[[a, b]])
                further = np.maximum(
                    np.minimum(plane_signed_distance(regions, pixel), far)[None],
                    ((past - carry.reach) * step)[:, None, None],
                )
                ended = np.minimum(ended, further)
            field[beyond] = ended
        else:
            beyond = samples < indices[n] if side == 0 else samples > indices[n]
            field[beyond] = base_n[None]
    field = np.minimum(np.nan_to_num(field, posinf=float(far)), far)
    out = np.moveaxis(field, 0, axis)
    if axis != along:  # from the voxels along ``along`` to its samples, linearly
        out = _resample(out, along, lo[along], positions)
    return out, distance


def _nearest_mm(
    samples: NDArray[np.float64],
    indices: NDArray[np.float64],
    step: float,
    *,
    penalised: bool,
    sides: tuple[object, object] = (None, None),
) -> NDArray[np.float32]:
    """Each sample's distance (mm) to a view's nearest plane, :data:`BEYOND_PENALTY` times
    beyond its outer planes where the view is extruded (``penalised``: an incomplete
    view, not correcting a complete one) or its end carried on (``sides``: before its
    first plane, after its last)."""
    nearest = np.min(np.abs(samples[:, None] - indices[None, :]), axis=1) * step
    # an extruded or carried-on view weighs less beyond its outer planes
    nearest[(samples < indices.min()) & (penalised or sides[0] is not None)] *= BEYOND_PENALTY
    nearest[(samples > indices.max()) & (penalised or sides[1] is not None)] *= BEYOND_PENALTY
    return nearest.astype(np.float32)


def _corrected(
    distances: dict[int, NDArray[np.float32]],
    indices: NDArray[np.float64],
    samples: NDArray[np.float64],
    pixel: NDArray[np.float64],
    axis: int,
    lo: NDArray[np.int64],
    far: np.float32,
    base: NDArray[np.float32],
    along: int,
    positions: NDArray[np.float64],
    upsample: int,
) -> NDArray[np.float32]:
    """An incomplete view's field as a correction of the complete view's ``base``.

    On each of the view's planes the **residual** (:func:`_residual`) is what
    turns ``base`` there into the drawn section; every sample takes ``base``
    plus the residual of the view's nearest plane, carried along the view's
    normal: the complete view's interpolation moved by what the plane showed it
    got wrong.
    """
    # ``base`` at the voxel centres along ``along`` (an odd upsampling: a voxel's middle sample)
    voxels = np.take(base, np.arange((upsample - 1) // 2, base.shape[along], upsample), axis=along)
    residuals = []
    for n, index in enumerate(indices):
        layer = int(np.clip(round(index) - lo[axis], 0, voxels.shape[axis] - 1))
        drawn = np.minimum(np.nan_to_num(distances[n], posinf=float(far)), far)
        residuals.append(_residual(drawn, np.take(voxels, layer, axis=axis), pixel))
    nearest = np.argmin(np.abs(samples[:, None] - indices[None, :]), axis=1)
    carried = np.moveaxis(np.stack(residuals)[nearest], 0, axis)
    if axis != along:
        carried = _resample(carried, along, lo[along], positions)
    return np.minimum(base + carried, far)


def _resample(
    values: NDArray[np.float32], axis: int, first: int, positions: NDArray[np.float64]
) -> NDArray[np.float32]:
    """``values`` (voxel layers ``first, first + 1, ...`` along ``axis``) at ``positions``."""
    n = values.shape[axis]
    where = np.clip(positions - first, 0, n - 1)
    below = np.floor(where).astype(np.int64)
    above = np.minimum(below + 1, n - 1)
    t = (where - below).astype(np.float32)
    shape = [1, 1, 1]
    shape[axis] = t.size
    t = t.reshape(shape)
    return (1 - t) * np.take(values, below, axis=axis) + t * np.take(values, above, axis=axis)


def _main_grid_axis(annotation: Annotation) -> int:
    """The grid axis most planes are perpendicular to (2 when none is)."""
    try:
        return annotation.main_axis()
    except GeometryError:
        return 2


def _oblique_view(
    view: ObliqueView,
    affine: NDArray[np.float64],
    lo: NDArray[np.int64],
    size: list[int],
    along: int,
    positions: NDArray[np.float64],
    far: np.float32,
    reach_mm: tuple[float, float] | None,
    base: NDArray[np.float32] | None = None,
    upsample: int = 1,
    ends_carried: tuple[Carry | None, Carry | None] = (None, None),
) -> tuple[NDArray[np.float32], NDArray[np.float32]]:
    """One oblique view's field and distances (mm) on the crop's samples, slab by slab.

    A sample between two planes of the view takes their in-plane signed
    distances at its projections onto them (bilinear), blended linearly along
    the normal; beyond its first and last planes the view ends ``reach_mm`` past
    them (a complete view; ``ends_carried`` as in :func:`_view`) or is extruded
    (None). With ``base`` (the complete view's field on the same samples) a
    sample takes ``base`` plus the residual of the view's nearest plane at its
    projection (:func:`_corrected`, the drawn
    distance less ``base`` on the plane; none beyond the plane's pixels).
    """
    from scipy import ndimage

    offsets = np.array([offset for offset, _, _ in view.planes])
    images = [
        plane_signed_distance(mask, pose.pixel_spacing) if mask.any() else None
        for _, pose, mask in view.planes
    ]
    to_pixels = [np.linalg.inv(pose.affine) for _, pose, _ in view.planes]
    # where its end is carried on (:func:`_view`): an outer plane's section less its
    # continued regions (None: nothing left), and those regions
    split: dict[int, tuple[NDArray[np.float32] | None, NDArray[np.float32] | None]] = {}
    for side, n in ((0, 0), (1, len(view.planes) - 1)):
        carry, (_, pose, mask) = ends_carried[side], view.planes[n]
        if carry is not None and mask.any():
            rest = mask & ~carry.regions
            split[side] = (
                plane_signed_distance(rest, pose.pixel_spacing) if rest.any() else None,
                plane_signed_distance(mask & carry.regions, pose.pixel_spacing),
            )
    field = np.empty(size, dtype=np.float32)
    distance = np.empty(size, dtype=np.float32)
    grids = [np.arange(lo[d], lo[d] + size[d], dtype=np.float64) for d in range(3)]
    grids[along] = positions
    other = [d for d in range(3) if d != along]
    mesh_a, mesh_b = np.meshgrid(grids[other[0]], grids[other[1]], indexing="ij")

    residuals = (
        None
        if base is None
        else _oblique_residuals(view, images, base, affine, lo, along, upsample, far)
    )

    def sample_image(
        image: NDArray[np.float32] | None, n: int, world: NDArray[np.float64]
    ) -> NDArray[np.float32]:
        if image is None:
            return np.full(world.shape[0], far, dtype=np.float32)
        pix = world @ to_pixels[n][:3, :3].T + to_pixels[n][:3, 3]
        values = ndimage.map_coordinates(
            image, [pix[:, 0], pix[:, 1]], order=1, mode="constant", cval=float(far)
        )
        return np.minimum(values, far).astype(np.float32)

    def sample(n: int, world: NDArray[np.float64]) -> NDArray[np.float32]:
        return sample_image(images[n], n, world)

    def interpolated(world: NDArray[np.float64], u: NDArray[np.float64]) -> NDArray[np.float32]:
        values = np.empty(u.size, dtype=np.float32)
        slot = np.searchsorted(offsets, u)  # planes slot - 1 and slot bracket u
        for j in np.unique(slot):
            sel = np.flatnonzero(slot == j)
            if j == 0 or j == len(offsets):
                n = 0 if j == 0 else len(offsets) - 1
                side = int(j > 0)
                if reach_mm is None:
                    values[sel] = sample(n, world[sel])
                    continue
                past = np.abs(u[sel] - offsets[n]).astype(np.float32)
                # a carried end: the rest of the section ends as the view, its continued
                # regions go further
                rest, further = split.get(side, (images[n], None))
                values[sel] = np.maximum(
                    sample_image(rest, n, world[sel]), past - np.float32(reach_mm[side])
                )
                if further is not None:
                    carry = ends_carried[side]
                    assert carry is not None
                    ended = np.maximum(
                        sample_image(further, n, world[sel]), past - np.float32(carry.reach)
                    )
                    values[sel] = np.minimum(values[sel], ended)
                continue
            t = ((u[sel] - offsets[j - 1]) / (offsets[j] - offsets[j - 1])).astype(np.float32)
            values[sel] = (1 - t) * sample(j - 1, world[sel]) + t * sample(j, world[sel])
        return values

    def carried(
        world: NDArray[np.float64],
        u: NDArray[np.float64],
        below: NDArray[np.float32],
        residuals: list[NDArray[np.float32] | None],
    ) -> NDArray[np.float32]:
        values = below.astype(np.float32, copy=True)
        closest = np.argmin(np.abs(u[:, None] - offsets[None, :]), axis=1)
        for n in np.unique(closest):
            sel = np.flatnonzero(closest == n)
            image = residuals[n]
            if image is None:  # the structure is absent from that plane
                values[sel] = far
                continue
            pix = world[sel] @ to_pixels[n][:3, :3].T + to_pixels[n][:3, 3]
            values[sel] += ndimage.map_coordinates(
                image, [pix[:, 0], pix[:, 1]], order=1, mode="constant", cval=0.0
            )
        return values

    for k, position in enumerate(grids[along]):
        index = np.empty((mesh_a.size, 3))
        index[:, other[0]] = mesh_a.ravel()
        index[:, other[1]] = mesh_b.ravel()
        index[:, along] = position
        world = index @ affine[:3, :3].T + affine[:3, 3]
        u = world @ view.normal
        block = [slice(None)] * 3
        block[along] = k
        if base is None or residuals is None:
            values = interpolated(world, u)
        else:
            values = carried(world, u, base[tuple(block)].ravel(), residuals)
        nearest = _nearest_mm(
            u, offsets, 1.0, penalised=reach_mm is None and base is None, sides=ends_carried
        )
        field[tuple(block)] = values.reshape(mesh_a.shape)
        distance[tuple(block)] = nearest.reshape(mesh_a.shape)
    return np.minimum(field, far), distance


def _residual(
    drawn: NDArray[np.float32], below: NDArray[np.float32], pixel: NDArray[np.float64]
) -> NDArray[np.float32]:
    """What a plane's drawn signed distance says the complete view's ``below`` got wrong.

    ``drawn − below`` where the two disagree on inside and outside; around there
    the same difference of both clipped to the band, fading to zero over
    :data:`RESIDUAL_BAND` pixels (clipped: an empty plane of the complete view
    holds a large stand-in distance, which carried along the normal made
    islands). ``below + residual``
    has the drawn section's sign everywhere on the plane (where they agree it is
    a blend of two values of one sign), and the two fields' different metrics
    (in-plane distances of planes of two orientations) are not carried where
    the plane only confirms the complete view: carried in full, the residual
    extrudes the plane's section along its normal.
    """
    from scipy import ndimage

    disagree = (drawn < 0) != (below < 0)
    if not disagree.any():
        return np.zeros(drawn.shape, dtype=np.float32)
    band = RESIDUAL_BAND * float(np.min(pixel))
    apart = ndimage.distance_transform_edt(~disagree, sampling=pixel)
    fade = np.clip(1.0 - apart / band, 0.0, 1.0)
    agreed = np.clip(drawn, -band, band) - np.clip(below, -band, band)
    return np.where(disagree, drawn - below, agreed * fade).astype(np.float32)


def _oblique_residuals(
    view: ObliqueView,
    images: list[NDArray[np.float32] | None],
    base: NDArray[np.float32],
    affine: NDArray[np.float64],
    lo: NDArray[np.int64],
    along: int,
    upsample: int,
    far: np.float32,
) -> list[NDArray[np.float32] | None]:
    """Each oblique plane's residual image (:func:`_residual`) against ``base`` (on the
    crop's samples) at its pixels; None for a plane where the structure is absent."""
    from scipy import ndimage

    to_voxel = np.linalg.inv(affine)
    out: list[NDArray[np.float32] | None] = []
    for (_, pose, _), image in zip(view.planes, images, strict=True):
        if image is None:
            out.append(None)
            continue
        rows, cols = np.indices(image.shape)
        world = pose.to_world(np.column_stack([rows.ravel(), cols.ravel()]).astype(np.float64))
        index = world @ to_voxel[:3, :3].T + to_voxel[:3, 3] - lo
        index[:, along] = (index[:, along] + 0.5) * upsample - 0.5  # voxel → sample
        here = ndimage.map_coordinates(base, index.T, order=1, mode="nearest")
        drawn = np.minimum(image, far).astype(np.float32)
        below = here.reshape(image.shape).astype(np.float32)
        out.append(_residual(drawn, below, pose.pixel_spacing))
    return out


def views_upsample(annotation: Annotation) -> int:
    """Field samples per voxel along the annotation's main axis (:meth:`Annotation.main_axis`).

    As :func:`slicerecon.inputs.axis_upsample`: when the main view's planes
    lie fewer than four voxels apart, or one plane is drawn, and the axis's
    voxels are longer than the in-plane pixels, the axis is sampled about as
    finely as the pixels (an odd factor, so that planes stay on samples; at
    most 9); else one sample per voxel.
    """
    try:
        along = annotation.main_axis()
    except GeometryError:
        return 1  # no plane is a slice of the grid
    indices = np.sort(annotation.cross_sections(axis=along).indices)
    if indices.size > 1 and float(np.median(np.diff(indices))) >= 4.0:
        return 1
    spacing = np.linalg.norm(annotation.affine[:3, :3], axis=0)
    a, b = in_plane_axes(along)
    factor = max(1, int(np.ceil(float(spacing[along] / min(spacing[a], spacing[b])) - 1e-6)))
    factor += 1 - factor % 2
    return int(min(factor, 9))


def views_surface(
    annotation: Annotation,
    value: int,
    *,
    interpolation: str = "pchip",
    join_drift: bool = True,
    exponent: float = VIEW_WEIGHT_EXPONENT,
) -> ViewsSurface:
    """Mesh and occupancy of one structure drawn in several views (:func:`views_field`).

    Returns
    -------
    ViewsSurface

    Raises
    ------
    EmptyMaskError
        Nothing inside.
    """
    field = views_field(
        annotation,
        value,
        interpolation=interpolation,
        join_drift=join_drift,
        exponent=exponent,
    )
    values = field.values
    if not np.any(values < 0):
        raise EmptyMaskError(f"structure {value}: the blended views hold no inside sample")
    step = float(np.min(np.linalg.norm(field.affine[:3, :3], axis=0)))
    nudge = np.float32(1e-3 * step)
    flat = values.reshape(-1)
    near = np.flatnonzero(np.abs(flat) < nudge)
    flat[near] = np.where(flat[near] < 0, -nudge, nudge)
    mesh = march_field(values, field.affine)
    occupancy = None
    if field.upsample == 1:
        occupancy_affine = field.affine.copy()
        occupancy_affine[:3, 3] = field.affine[:3, :3] @ np.ones(3) + field.affine[:3, 3]
        occupancy = Volume(values[1:-1, 1:-1, 1:-1] < 0, occupancy_affine)
    return ViewsSurface(mesh, occupancy, field)
