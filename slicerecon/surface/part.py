"""Per-part reconstruction: what the pipeline and the planners call.

A planner partitions the shape into cuboid parts (:class:`~slicerecon.sections.Box`);
each part is reconstructed on its own from the cross-sections inside its box
(:func:`reconstruct_part`), and the parts are merged by union
(:func:`reconstruct_parts`). :func:`part_voxels` is a cheap voxel version of
a part's reconstruction for the planner's reward ``IoU(S_i, W_i)``.

Methods
-------
``"loft"``
    Contour lofting (:func:`~slicerecon.surface.loft.loft`), the paper's method.
``"sdf"``
    Signed-distance interpolation + marching cubes
    (:func:`~slicerecon.surface.sdf.sdf_mesh`).
``"hybrid"``
    Per part: ``"loft"`` where the contour correspondence is simple
    (:func:`~slicerecon.surface.loft.correspondence_is_simple`: nothing
    appears, vanishes or merges many-to-many between consecutive planes),
    ``"sdf"`` otherwise.

Which of them runs, and how the signed-distance ones interpolate, is read off
one :class:`~slicerecon.options.ReconstructOptions` bundle passed whole; the
method's capabilities (:data:`slicerecon.surface.methods.METHODS`: ``implicit``
or a ``part_solid`` function) choose the code path, never its name.

Both use the same extent semantics along the section axis (see
``docs/method.md``): with ``extend_to_box=True`` the first / last plane in
the box is extended to the box faces and a box holding no plane is filled by
the slab of the planes either side of it; without it the part spans its
first to last plane. A single call with the bounding box of the sections and
``extend_to_box=False`` is the paper's "no projection" baseline.
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from typing import NamedTuple

import manifold3d
import numpy as np
import trimesh
from numpy.typing import NDArray

from ..errors import EmptyMaskError, InputError, OptionError
from ..options import ReconstructOptions
from ..rasterize import mesh_to_mask
from ..sections import Box, CrossSections, Volume
from .loft import correspondence_is_simple, loft_solid
from .merge import check_closed, from_manifold, to_manifold, union_solids
from .methods import MethodEntry, method_names
from .sdf import SdfField, sdf_field, sdf_mesh, sdf_parts_surface
from .smooth import taubin_smooth

__all__ = [
    "METHODS",
    "Surface",
    "hybrid_part_solid",
    "loft_part_solid",
    "part_voxels",
    "reconstruct_part",
    "reconstruct_parts",
    "reconstruct_surface",
]

logger = logging.getLogger(__name__)

METHODS = method_names(per_part=True)
"""Surface methods of :func:`reconstruct_part` and :func:`reconstruct_parts` (the per-part
entries of :data:`slicerecon.surface.methods.METHODS`)."""

DEFAULT_OPTIONS = ReconstructOptions()


def _per_part(options: ReconstructOptions) -> MethodEntry:
    if not isinstance(options, ReconstructOptions):
        raise OptionError(f"expected ReconstructOptions (got {type(options).__name__})")
    entry = options.method_entry
    if not entry.per_part:
        raise OptionError(
            f"method must be one of {', '.join(METHODS)} (got {options.method!r}: a "
            "whole-shape method, see slicerecon.surface.baselines)"
        )
    return entry


def _check_inputs(sections: CrossSections, box: Box) -> None:
    if not isinstance(sections, CrossSections):
        raise InputError(f"expected CrossSections (got {type(sections).__name__})")
    if not isinstance(box, Box):
        raise InputError(f"expected a slicerecon Box (got {type(box).__name__})")


def loft_part_solid(
    sections: CrossSections,
    box: Box,
    *,
    extend_to_box: bool,
    hull: NDArray[np.bool_] | None,
    options: ReconstructOptions,
) -> manifold3d.Manifold | None:
    """One part of the ``"loft"`` method as a solid in voxel index coordinates (or None)."""
    return loft_solid(sections, box=box, extend_to_box=extend_to_box, hull=hull)


def hybrid_part_solid(
    sections: CrossSections,
    box: Box,
    *,
    extend_to_box: bool,
    hull: NDArray[np.bool_] | None,
    options: ReconstructOptions,
) -> manifold3d.Manifold | None:
    """One part of the ``"hybrid"`` method as a solid in voxel index coordinates (or None).

    Lofted where the contours of consecutive planes correspond simply
    (:func:`~slicerecon.surface.loft.correspondence_is_simple`), else the
    signed-distance surface with the options' interpolation and drift joining.
    """
    if correspondence_is_simple(sections, box):
        return loft_solid(sections, box=box, extend_to_box=extend_to_box, hull=hull)
    try:
        mesh = sdf_mesh(
            sections,
            box=box,
            extend_to_box=extend_to_box,
            hull=hull,
            interpolation=options.interpolation,
            join_drift=options.join_drift,
        )
    except EmptyMaskError:
        return None
    logger.debug("part %s: contours split, merge or appear; signed-distance surface", box.to_dict())
    index_mesh = mesh.copy()
    index_mesh.apply_transform(np.linalg.inv(sections.affine))
    return to_manifold(index_mesh)


def reconstruct_part(
    sections: CrossSections,
    box: Box,
    options: ReconstructOptions = DEFAULT_OPTIONS,
    *,
    extend_to_box: bool = True,
    hull: NDArray[np.bool_] | None = None,
) -> trimesh.Trimesh | None:
    """Reconstruct one part from the sections inside its box.

    Parameters
    ----------
    sections : CrossSections
        All cross-sections of the shape.
    box : Box
        The part's cuboid on the reference grid.
    options : ReconstructOptions, optional
        ``method`` (a per-part one: ``sdf``, ``loft``, ``hybrid``),
        ``interpolation`` and ``join_drift`` apply.
    extend_to_box : bool, default True
        Extend the part to the box faces along the section axis.
    hull : ndarray of shape sections.grid_shape, bool, optional
        The projections' visual hull; the extensions follow its extent
        (:mod:`~slicerecon.surface.extension`). Without it they are prisms.

    Returns
    -------
    trimesh.Trimesh or None
        Closed, outward mesh in world mm, inside the box; None when the box
        holds no section foreground.

    Raises
    ------
    OptionError
        A whole-shape method, or a box outside the grid.
    """
    entry = _per_part(options)
    _check_inputs(sections, box)
    if not entry.implicit:
        solid = entry.load_part_solid()(
            sections, box, extend_to_box=extend_to_box, hull=hull, options=options
        )
        return None if solid is None else from_manifold(solid, transform=sections.affine)
    try:
        return sdf_mesh(
            sections,
            box=box,
            extend_to_box=extend_to_box,
            hull=hull,
            interpolation=options.interpolation,
            join_drift=options.join_drift,
        )
    except EmptyMaskError:
        return None


def part_voxels(
    sections: CrossSections,
    box: Box,
    options: ReconstructOptions = DEFAULT_OPTIONS,
    *,
    extend_to_box: bool = True,
    hull: NDArray[np.bool_] | None = None,
) -> NDArray[np.bool_]:
    """Voxel occupancy of a part's reconstruction on the reference grid, inside its box.

    Parameters
    ----------
    sections : CrossSections
        All cross-sections of the shape.
    box : Box
        The part's cuboid; must lie inside the reference grid.
    options : ReconstructOptions, optional
        An implicit method (``sdf``): its signed-distance field sampled at the
        voxel centres (fast: a few ms for a 100³ box), with the options'
        ``interpolation`` and ``join_drift``. Any other per-part method: its
        mesh rasterized at the voxel centres (slower, exact for that surface).
    extend_to_box, hull
        As for :func:`reconstruct_part`.

    Returns
    -------
    ndarray of shape box.shape, bool
        ``S_i`` restricted to the box; all False when the box holds no
        section foreground.

    Raises
    ------
    OptionError
        A whole-shape method, or a box that does not lie inside the grid.
    """
    entry = _per_part(options)
    _check_inputs(sections, box)
    if any(lo < 0 for lo in box.lo) or any(
        hi > n for hi, n in zip(box.hi, sections.grid_shape, strict=True)
    ):
        raise OptionError(
            f"box {box.to_dict()} must lie inside the reference grid {sections.grid_shape}"
        )
    if entry.implicit:
        field, _ = sdf_field(
            sections,
            box=box,
            extend_to_box=extend_to_box,
            hull=hull,
            interpolation=options.interpolation,
            join_drift=options.join_drift,
        )
        return field < 0

    mesh = reconstruct_part(sections, box, options, extend_to_box=extend_to_box, hull=hull)
    if mesh is None:
        return np.zeros(box.shape, dtype=bool)
    affine = sections.affine.copy()
    affine[:3, 3] = sections.affine[:3, :3] @ np.asarray(box.lo, dtype=np.float64) + affine[:3, 3]
    return mesh_to_mask(mesh, affine, box.shape)


def reconstruct_parts(
    sections: CrossSections,
    boxes: Sequence[Box],
    options: ReconstructOptions = DEFAULT_OPTIONS,
    *,
    extend_to_box: bool = True,
    hull: NDArray[np.bool_] | None = None,
    carve: NDArray[np.bool_] | None = None,
    upsample: int = 1,
    cover: bool = False,
) -> trimesh.Trimesh:
    """Reconstruct every part and merge them into one watertight mesh.

    Parameters
    ----------
    sections : CrossSections
        All cross-sections of the shape.
    boxes : sequence of Box
        The parts' cuboids (they may touch or overlap).
    options : ReconstructOptions, optional
        ``method`` (per part), ``interpolation``, ``join_drift`` and ``smooth``
        (Taubin-smooth the merged mesh, :func:`~slicerecon.surface.smooth.taubin_smooth`)
        apply; the carve is given as a hull here (``carve``), not read off the options.
    extend_to_box, hull
        As for :func:`reconstruct_part`.
    carve : ndarray of shape sections.grid_shape, bool, optional
        Implicit methods only: intersect the union with this visual hull in the
        implicit domain (:func:`~slicerecon.surface.sdf.sdf_parts_mesh`).
    upsample : int, default 1
        Implicit methods only: field samples per voxel along the section axis
        (:func:`~slicerecon.surface.sdf.sdf_field`).
    cover : bool, default False
        Implicit methods with ``carve`` only: also fill the silhouettes whose
        rays lie in the section planes (:func:`~slicerecon.surface.sdf.sdf_parts_mesh`).

    Returns
    -------
    trimesh.Trimesh
        Union of the parts: closed, outward, world mm.

    Raises
    ------
    OptionError
        If ``boxes`` is empty, the method is a whole-shape one, or ``carve``
        is given for a method that is not implicit.
    EmptyMaskError
        If no box holds section foreground.
    """
    return reconstruct_surface(
        sections,
        boxes,
        options,
        extend_to_box=extend_to_box,
        hull=hull,
        carve=carve,
        upsample=upsample,
        cover=cover,
    ).mesh


class Surface(NamedTuple):
    """A reconstruction and, when known for free, its occupancy at the voxel centres.

    Attributes
    ----------
    mesh : trimesh.Trimesh
        Closed, outward union of the parts, world mm.
    occupancy : Volume or None
        Voxel centres inside the mesh on a sub-grid of the reference grid:
        the sign of the field for ``method="sdf"``; None for lofted surfaces
        and smoothed meshes (rasterize the mesh instead).
    field : SdfField or None
        ``method="sdf"`` with ``keep_field``: the signed-distance field the
        mesh was extracted from.
    """

    mesh: trimesh.Trimesh
    occupancy: Volume | None
    field: SdfField | None = None


def reconstruct_surface(
    sections: CrossSections,
    boxes: Sequence[Box],
    options: ReconstructOptions = DEFAULT_OPTIONS,
    *,
    extend_to_box: bool = True,
    hull: NDArray[np.bool_] | None = None,
    carve: NDArray[np.bool_] | None = None,
    upsample: int = 1,
    keep_field: bool = False,
    cover: bool = False,
) -> Surface:
    """As :func:`reconstruct_parts`, with the occupancy when the method gives it for free.

    ``keep_field`` keeps an implicit method's signed-distance field
    (:attr:`Surface.field`). Parameters and errors as :func:`reconstruct_parts`.
    """
    entry = _per_part(options)
    boxes = list(boxes)
    if not boxes:
        raise OptionError("give at least one box (part) to reconstruct")
    for box in boxes:
        _check_inputs(sections, box)
    if carve is not None and not entry.implicit:
        raise OptionError(
            f"an implicit carve applies to implicit methods only (not {options.method!r}); "
            "carve the mesh instead"
        )
    occupancy, field = None, None
    if entry.implicit:
        # Implicit union: the minimum of the parts' signed distances, meshed once.
        surface = sdf_parts_surface(
            sections,
            boxes,
            extend_to_box=extend_to_box,
            hull=hull,
            interpolation=options.interpolation,
            join_drift=options.join_drift,
            carve=carve,
            upsample=upsample,
            keep_field=keep_field,
            cover=cover,
        )
        mesh, occupancy, field = surface.mesh, surface.occupancy, surface.field
    else:
        part_solid = entry.load_part_solid()
        solids = [
            part_solid(sections, b, extend_to_box=extend_to_box, hull=hull, options=options)
            for b in boxes
        ]
        kept = [s for s in solids if s is not None]
        if not kept:
            raise EmptyMaskError("no part's box holds any section foreground")
        # Parts are united in voxel index coordinates, where shared box faces are
        # exactly coplanar, and mapped to world mm once.
        mesh = from_manifold(union_solids(kept), transform=sections.affine)
        check_closed(mesh, "reconstruct_parts")
    logger.debug("merged %d parts (%s): %d faces", len(boxes), options.method, len(mesh.faces))
    if options.smooth:
        mesh, occupancy, field = taubin_smooth(mesh), None, None
    return Surface(mesh, occupancy, field)
