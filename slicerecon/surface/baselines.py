"""Whole-shape reconstruction baselines: one surface from all the sections at once.

The paper's method cuts the shape into cuboid parts and lofts each part
(:mod:`slicerecon.surface.part`). The baselines here ignore any partition:
each one turns *all* the cross-sections (and, for ``sdf-hull``, the
projections) into one closed surface. They share one signature::

    fn(sections, projections, **options) -> trimesh.Trimesh

and return a closed (watertight), outward-oriented mesh in world millimetres.
:data:`BASELINES` maps the method names used by ``slicerecon run --method``
to these functions; :func:`reconstruct_baseline` dispatches by name.

Methods
-------
``"poisson"`` (:func:`poisson`)
    Screened Poisson surface reconstruction (Kazhdan & Hoppe 2013, via
    pymeshlab) of oriented points: every section contour is sampled (world
    mm) with its in-plane outward normal, and the foreground pixels of the
    first and last non-empty planes are added as cap points with normals
    along ∓ the plane normal, so that the point set describes a closed
    surface. The octree depth follows the grid size (one octree cell about
    one voxel). The Poisson surface is then clipped to the slab between the
    first and the last plane with an exact Boolean (manifold3d), which also
    proves it closed; if Poisson's output is not an oriented 2-manifold, it is
    rasterized instead (its surface is sampled densely into a voxel shell,
    the shell's inside filled, the shell voxels given their signed distance
    to the surface) and re-meshed by marching cubes.
    This is the paper's "Poisson surface reconstruction on the slice points".
``"sdf-hull"`` (:func:`sdf_hull`)
    Signed-distance (shape-based) interpolation between the planes
    (:func:`~slicerecon.surface.sdf.sdf_field` on the whole grid, no
    partition; the first and last planes extended unchanged to the grid
    faces) intersected with the visual hull of the projections in the
    implicit domain: the field is ``max(sdf, d_hull)`` with ``d_hull`` the
    3-D signed distance (mm, negative inside) of the hull, meshed by
    marching cubes. The hull thus also decides where the shape ends along
    the axis. It uses the same prior as the paper's method (the
    projections) without any cut.
``"itk-mci"`` (:func:`itk_mci`)
    ITK's morphological contour interpolation (Zukić et al. 2016, the
    ``itk-morphologicalcontourinterpolation`` package, optional extra
    ``slicerecon[itk]``) between the planes on the reference grid, then
    marching cubes on the interpolated mask. ITK's first call in a process
    loads its wrapped templates and costs about 10 s.

The per-part ``"sdf"`` and ``"loft"`` methods live in
:mod:`slicerecon.surface.part`; with the ``"none"`` planner they are the
paper's "no projection" baselines.

Extent along the section axis: ``poisson`` is clipped exactly to the first
and last plane holding foreground, ``itk-mci`` ends half a voxel beyond them
(marching cubes on the interpolated mask), and ``sdf-hull`` ends where the
visual hull ends (with projections derived from the sections, half a voxel
beyond the end planes; with the ground truth's projections, where the shape
ends).
"""

from __future__ import annotations

import importlib
import logging
import math
import warnings
from collections.abc import Callable
from typing import Any

import manifold3d
import numpy as np
import trimesh
from numpy.typing import NDArray
from scipy import ndimage

from ..errors import DependencyError, EmptyMaskError, GeometryError, InputError, OptionError
from ..sampling import visual_hull
from ..sections import Box, CrossSections, Projections, Volume
from .marching import field_to_mesh, volume_to_mesh
from .merge import from_manifold, solid_from_arrays
from .methods import method_entry, method_names
from .sdf import sdf_field

__all__ = [
    "BASELINES",
    "baseline_names",
    "contour_samples",
    "itk_mci",
    "poisson",
    "reconstruct_baseline",
    "sdf_hull",
    "sections_box",
]

logger = logging.getLogger(__name__)

BaselineFn = Callable[..., trimesh.Trimesh]
"""``fn(sections, projections, **options) -> trimesh.Trimesh`` (closed, outward, world mm)."""

_LEVEL_GAP = 1e-3
"""Smallest distance of a meshed field sample from the zero level, in sample spacings."""

_MIN_DEPTH, _MAX_DEPTH = 5, 10
"""Range of the automatic Poisson octree depth."""

_POISSON_SCALE = 1.5
"""Octree cube side / point bounding-box side. MeshLab's default 1.1 leaves too little
room: the surface bulging past the end caps is cut open by the octree's faces."""

_SHELL_SAMPLES_PER_VOXEL_AREA = 16.0
"""Surface samples per voxel-face area when a Poisson mesh is rasterized (fallback)."""

_MAX_SHELL_SAMPLES = 4_000_000


# -- validation -------------------------------------------------------------------------
def _check_sections(sections: CrossSections, what: str) -> NDArray[np.int64]:
    """Validate the sections; return the numbers of the planes holding foreground."""
    if not isinstance(sections, CrossSections):
        raise InputError(f"{what} needs CrossSections (got {type(sections).__name__})")
    filled = np.flatnonzero(sections.masks.reshape(sections.n_planes, -1).any(axis=1))
    if filled.size == 0:
        raise EmptyMaskError("the cross-sections hold no foreground on any plane")
    return filled.astype(np.int64)


def _check_projections(projections: Projections | None, sections: CrossSections) -> Projections:
    if not isinstance(projections, Projections):
        raise InputError(
            f"sdf-hull needs the projections (a Projections object, got "
            f"{type(projections).__name__}); derive them with "
            "slicerecon.sampling.projections_from_sections if none are known"
        )
    return projections


def _check_bool(value: object, name: str) -> bool:
    if not isinstance(value, bool | np.bool_):
        raise OptionError(f"{name} must be True or False (got {value!r})")
    return bool(value)


def _nudged(field: NDArray[np.floating], step_mm: float) -> NDArray[np.float32]:
    """Push samples closer than :data:`_LEVEL_GAP` sample spacings off the zero level.

    A sample exactly on the level puts vertices of several marching-cubes
    triangles on one grid point and pinches the mesh.
    """
    out = np.asarray(field, dtype=np.float32).copy()
    gap = np.float32(_LEVEL_GAP * step_mm)
    near = np.abs(out) < gap
    out[near] = np.where(out[near] < 0, -gap, gap)
    return out


# -- Poisson ----------------------------------------------------------------------------
def contour_samples(
    sections: CrossSections, *, caps: bool = True
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Oriented points on the section contours (and end caps), world mm.

    Parameters
    ----------
    sections : CrossSections
        Binary masks on parallel planes.
    caps : bool, default True
        Add the foreground pixel centres of the first and last non-empty
        planes, with normals ``-normal`` and ``+normal`` of the planes. A single
        non-empty plane gets both caps, half a voxel either side of it.

    Returns
    -------
    points : ndarray of shape (N, 3), float64
        Contour vertices (pixel-centre iso-contours at 0.5, see
        :meth:`~slicerecon.sections.CrossSections.contours`) and cap points, mm.
    normals : ndarray of shape (N, 3), float64
        Unit outward normals: in the plane and perpendicular to the contour
        for contour points, along the plane normal for cap points.

    Raises
    ------
    EmptyMaskError
        If no plane holds foreground.
    """
    filled = _check_sections(sections, "contour_samples")
    caps = _check_bool(caps, "caps")
    a, b = sections.plane_axes
    in_plane = sections.affine[:3, [a, b]]  # px direction -> world direction
    plane_normal = sections.normal
    points: list[NDArray[np.float64]] = []
    normals: list[NDArray[np.float64]] = []
    for plane in filled:
        mask = sections.masks[plane]
        for contour in sections.contours(int(plane)):
            pts = contour.points_px
            tangent_px = np.roll(pts, -1, axis=0) - np.roll(pts, 1, axis=0)
            # Foreground lies left of every contour (outer CCW, holes CW in (row, col)),
            # so "right of the tangent" points out of the shape in pixel coordinates.
            out_px = np.stack([tangent_px[:, 1], -tangent_px[:, 0]], axis=1)
            sign = _outward_sign(mask, pts, out_px)
            tangent = tangent_px @ in_plane.T
            normal = np.cross(tangent, plane_normal)
            length = np.linalg.norm(normal, axis=1)
            keep = length > 1e-12
            normal = normal[keep] / length[keep, None]
            # The world normal must point to the same side as the pixel-space outward
            # direction (a linear map keeps sides, not right angles).
            side = np.einsum("ij,ij->i", normal, (out_px[keep] @ in_plane.T) * sign)
            normal[side < 0] *= -1.0
            points.append(sections.plane_to_world(int(plane), pts[keep]))
            normals.append(normal)
    if caps:
        step = sections.spacing[sections.axis]
        first, last = int(filled[0]), int(filled[-1])
        shift = 0.5 * step if first == last else 0.0
        for plane, direction in ((first, -1.0), (last, 1.0)):
            pix = np.argwhere(sections.masks[plane]).astype(np.float64)
            world = sections.plane_to_world(plane, pix) + direction * shift * plane_normal
            points.append(world)
            normals.append(np.tile(direction * plane_normal, (len(world), 1)))
    return np.concatenate(points), np.concatenate(normals)


def _outward_sign(
    mask: NDArray[np.bool_], pts: NDArray[np.float64], out_px: NDArray[np.float64]
) -> float:
    """+1 when stepping along ``out_px`` from the contour mostly lands on background, else -1.

    Guards the orientation convention of the contour tracer: a majority vote
    over the contour's points on the mask itself.
    """
    unit = out_px / np.maximum(np.linalg.norm(out_px, axis=1, keepdims=True), 1e-12)
    probe = np.rint(pts + 0.75 * unit).astype(np.int64)
    inside_grid = np.all((probe >= 0) & (probe < np.asarray(mask.shape)), axis=1)
    lands_inside = np.zeros(len(pts), dtype=bool)
    lands_inside[inside_grid] = mask[probe[inside_grid, 0], probe[inside_grid, 1]]
    return -1.0 if np.count_nonzero(lands_inside) > 0.5 * len(pts) else 1.0


def _auto_depth(sections: CrossSections, scale: float = _POISSON_SCALE) -> int:
    """Octree depth whose cells are about one voxel of the sections' bounding box."""
    lo, hi = _foreground_extent(sections)
    extent_mm = (hi - lo + 1.0) * sections.spacing
    cells = scale * float(extent_mm.max()) / float(sections.spacing.min())
    return int(np.clip(math.ceil(math.log2(max(cells, 2.0))), _MIN_DEPTH, _MAX_DEPTH))


def sections_box(sections: CrossSections) -> Box:
    """The voxel box around the sections' foreground (the one part of a whole-shape plan).

    Parameters
    ----------
    sections : CrossSections
        Binary masks on parallel planes.

    Returns
    -------
    Box
        In-plane: the bounding box of the union of the masks. Along the
        section axis: the grid voxels from the first to the last non-empty
        plane (fractional positions rounded outwards), clipped to the grid.

    Raises
    ------
    EmptyMaskError
        If no plane holds foreground.
    """
    lo, hi = _foreground_extent(sections)
    lo_i = np.floor(lo + 1e-9).astype(np.int64)
    hi_i = np.ceil(hi - 1e-9).astype(np.int64) + 1
    shape = np.asarray(sections.grid_shape, dtype=np.int64)
    lo_i = np.clip(lo_i, 0, shape - 1)
    hi_i = np.clip(hi_i, lo_i + 1, shape)
    return Box(tuple(int(v) for v in lo_i), tuple(int(v) for v in hi_i))  # type: ignore[arg-type]


def _foreground_extent(sections: CrossSections) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Index-space bounds (inclusive, voxel centres) of the sections' foreground."""
    filled = _check_sections(sections, "a baseline")
    a, b = sections.plane_axes
    union = np.asarray(sections.masks.any(axis=0), dtype=bool)
    rows = np.flatnonzero(union.any(axis=1))
    cols = np.flatnonzero(union.any(axis=0))
    lo = np.empty(3)
    hi = np.empty(3)
    lo[a], hi[a] = rows[0], rows[-1]
    lo[b], hi[b] = cols[0], cols[-1]
    lo[sections.axis] = sections.indices[filled[0]]
    hi[sections.axis] = sections.indices[filled[-1]]
    return lo, hi


def _import_pymeshlab() -> Any:
    try:
        pymeshlab = importlib.import_module("pymeshlab")
    except ImportError as exc:
        raise DependencyError(
            f"the poisson method needs pymeshlab ({exc}); install it with pip install pymeshlab"
        ) from None
    if not hasattr(pymeshlab.MeshSet(), "generate_surface_reconstruction_screened_poisson"):
        raise DependencyError(
            "this pymeshlab has no screened Poisson filter "
            "(generate_surface_reconstruction_screened_poisson); install pymeshlab>=2022.2"
        )
    return pymeshlab


def poisson(
    sections: CrossSections,
    projections: Projections | None = None,
    *,
    depth: int | None = None,
    point_weight: float = 4.0,
    samples_per_node: float = 1.5,
    threads: int = 1,
) -> trimesh.Trimesh:
    """Screened Poisson reconstruction from the oriented contour points.

    Parameters
    ----------
    sections : CrossSections
        Binary masks on parallel planes.
    projections : Projections, optional
        Unused (accepted for the common baseline signature).
    depth : int, optional
        Octree depth (5..12). Default: ``ceil(log2(1.5 * L))`` clipped to
        [5, 10], with ``L`` the longest side of the sections' bounding box in
        units of the smallest voxel side: the octree cube is 1.5 times the
        points' bounding box (room for the surface to close beyond the end
        caps) and a cell is about one voxel.
    point_weight : float, default 4
        Screening weight (interpolation of the points vs. smoothness), >= 0.
    samples_per_node : float, default 1.5
        Minimum samples per octree node, > 0 (larger: smoother).
    threads : int, default 1
        Threads of the Poisson solver (>= 1). One is the default because the
        solver's threads busy-wait: on a loaded machine two threads ran about
        three times slower than one.

    Returns
    -------
    trimesh.Trimesh
        Closed, outward mesh in world mm, clipped to the slab between the
        first and the last non-empty plane.

    Raises
    ------
    DependencyError
        If pymeshlab or its screened Poisson filter is missing.
    EmptyMaskError
        If no plane holds foreground or Poisson returns nothing inside the slab.
    OptionError
        If an option is out of range.
    """
    filled = _check_sections(sections, "poisson")
    if depth is not None and (
        isinstance(depth, bool) or not isinstance(depth, int | np.integer) or not 5 <= depth <= 12
    ):
        raise OptionError(f"depth must be an integer in [5, 12] (got {depth!r})")
    if not (math.isfinite(float(point_weight)) and float(point_weight) >= 0.0):
        raise OptionError(f"point_weight must be a finite number >= 0 (got {point_weight!r})")
    if not (math.isfinite(float(samples_per_node)) and float(samples_per_node) > 0.0):
        raise OptionError(f"samples_per_node must be a positive number (got {samples_per_node!r})")
    if isinstance(threads, bool) or not isinstance(threads, int | np.integer) or threads < 1:
        raise OptionError(f"threads must be a positive integer (got {threads!r})")
    pymeshlab = _import_pymeshlab()
    octree_depth = _auto_depth(sections) if depth is None else int(depth)
    points, normals = contour_samples(sections, caps=True)
    logger.debug("poisson: %d oriented points, octree depth %d", len(points), octree_depth)

    meshset = pymeshlab.MeshSet()
    meshset.add_mesh(pymeshlab.Mesh(vertex_matrix=points, v_normals_matrix=normals))
    meshset.generate_surface_reconstruction_screened_poisson(
        depth=octree_depth,
        pointweight=float(point_weight),
        samplespernode=float(samples_per_node),
        scale=_POISSON_SCALE,
        preclean=True,
        threads=int(threads),
    )
    out = meshset.current_mesh()
    vertices = np.asarray(out.vertex_matrix(), dtype=np.float64)
    faces = np.asarray(out.face_matrix(), dtype=np.int64)
    if len(faces) == 0:
        raise EmptyMaskError("screened Poisson returned an empty surface")

    # Clip to the slab of the planes in voxel index space, where it is axis-aligned.
    inv = np.linalg.inv(sections.affine)
    verts_idx = vertices @ inv[:3, :3].T + inv[:3, 3]
    axis = sections.axis
    w_first = float(sections.indices[filled[0]])
    w_last = float(sections.indices[filled[-1]])
    if filled.size == 1:
        w_first, w_last = w_first - 0.5, w_last + 0.5
    lo = verts_idx.min(axis=0) - 1.0
    hi = verts_idx.max(axis=0) + 1.0
    lo[axis], hi[axis] = w_first, w_last
    if hi[axis] <= lo[axis]:
        raise EmptyMaskError("the slab between the first and last plane has no thickness")
    solid = _as_solid(verts_idx, faces)
    if solid is not None:
        slab = manifold3d.Manifold.cube(tuple(hi - lo)).translate(tuple(lo))
        clipped = solid ^ slab
        if clipped.is_empty():
            raise EmptyMaskError("the Poisson surface encloses nothing between the planes")
        mesh = from_manifold(clipped, transform=sections.affine)
        if mesh.is_watertight and mesh.volume > 0:
            return mesh
    logger.warning(
        "poisson: the Poisson surface is not a closed oriented manifold; "
        "rasterizing and re-meshing it"
    )
    return _remesh_by_rasterizing(verts_idx, faces, sections, w_first, w_last)


def _as_solid(verts_idx: NDArray[np.float64], faces: NDArray[np.int64]) -> Any:
    """The Poisson mesh as an outward manifold3d solid, or None when it is not manifold."""
    mesh = trimesh.Trimesh(vertices=verts_idx, faces=faces, process=True)
    mesh.remove_unreferenced_vertices()
    solid = solid_from_arrays(mesh.vertices, mesh.faces)
    if solid is None or solid.is_empty():
        return None
    if solid.volume() < 0:
        solid = solid_from_arrays(mesh.vertices, np.asarray(mesh.faces)[:, ::-1])
    return solid


def _remesh_by_rasterizing(
    verts_idx: NDArray[np.float64],
    faces: NDArray[np.int64],
    sections: CrossSections,
    w_first: float,
    w_last: float,
) -> trimesh.Trimesh:
    """Fallback for a non-manifold Poisson surface: voxel shell → signed field → marching cubes.

    The surface (in voxel index coordinates) is sampled densely, each sample
    with the normal of its triangle. The voxels holding a sample between the
    first and last plane, plus lids on these two planes (their masks and
    whatever the surface's trace on them encloses), dilated by one voxel,
    form a closed shell whose inside is filled
    (:func:`scipy.ndimage.binary_fill_holes`). Voxels inside are given -1,
    voxels outside +1, and a shell voxel the signed distance (voxels) of its
    centre to the tangent plane of its nearest sample, so that marching cubes
    puts the surface where the Poisson surface is, between voxel centres.
    Voxels beyond the end planes are outside.
    """
    from scipy.spatial import cKDTree

    shape = np.asarray(sections.grid_shape)
    mesh = trimesh.Trimesh(vertices=verts_idx, faces=faces, process=False)
    n = int(min(max(mesh.area * _SHELL_SAMPLES_PER_VOXEL_AREA, 1000), _MAX_SHELL_SAMPLES))
    pts, face_index = trimesh.sample.sample_surface(mesh, n, seed=0)
    normals = np.asarray(mesh.face_normals)[face_index]
    idx = np.rint(np.vstack([pts, verts_idx])).astype(np.int64) + 2
    grid = np.zeros(tuple(shape + 4), dtype=bool)
    ok = np.all((idx >= 0) & (idx < shape + 4), axis=1)
    grid[tuple(idx[ok].T)] = True
    filled = np.flatnonzero(sections.masks.reshape(sections.n_planes, -1).any(axis=1))
    end_masks = [sections.masks[filled[0]], sections.masks[filled[-1]]]
    along = np.arange(shape[sections.axis] + 4, dtype=np.float64) - 2.0
    outside = (along < w_first - 1e-9) | (along > w_last + 1e-9)
    # Keep the shell between the end planes and seal it with lids on them: a Poisson
    # surface that is open somewhere is most often open beyond the caps.
    view = np.moveaxis(grid, sections.axis, 0)
    view[outside] = False
    for plane in (int(np.argmin(np.abs(along - w_first))), int(np.argmin(np.abs(along - w_last)))):
        ring = ndimage.binary_dilation(view[plane], structure=np.ones((3, 3), dtype=bool))
        view[plane] |= ndimage.binary_fill_holes(ring | np.pad(end_masks.pop(0), 2))
    shell = ndimage.binary_dilation(grid, structure=np.ones((3, 3, 3), dtype=bool))
    inside = ndimage.binary_fill_holes(shell)
    field = np.where(inside, -1.0, 1.0)

    tree = cKDTree(pts)

    def signed(cells: NDArray[np.int64]) -> NDArray[np.float64]:
        centres = cells - 2.0
        _, nearest = tree.query(centres)
        return np.einsum("ij,ij->i", centres - pts[nearest], normals[nearest])

    cells = np.argwhere(shell)
    values = signed(cells)
    # Triangle normals may point inwards (Poisson's winding is not guaranteed on a
    # broken mesh): the interior voxels next to the shell must come out negative.
    rim = np.argwhere(inside & ~shell & ndimage.binary_dilation(shell))
    if len(rim) and float(np.median(signed(rim))) > 0:
        values = -values
    field[tuple(cells.T)] = np.clip(values, -1.5, 1.5)
    field = field[2:-2, 2:-2, 2:-2]
    np.moveaxis(field, sections.axis, 0)[outside[2:-2]] = 1.0
    if not np.any(field < 0):
        raise EmptyMaskError("the Poisson surface encloses no voxel between the planes")
    step = float(sections.spacing.min())
    return field_to_mesh(_nudged(field * step, step), sections.affine, inside="negative")


# -- SDF interpolation carved by the visual hull ----------------------------------------
def _signed_distance_3d(
    mask: NDArray[np.bool_], spacing: NDArray[np.float64]
) -> NDArray[np.float32]:
    """3-D signed distance of a mask's boundary, mm, negative inside (beyond the grid: outside).

    As :func:`~slicerecon.surface.sdf.plane_signed_distance`, in 3-D: the
    distance between voxel centres of the two classes less half the smallest
    voxel side.
    """
    if not mask.any():
        return np.full(mask.shape, np.float32(np.inf), dtype=np.float32)
    half = 0.5 * float(spacing.min())
    padded = np.pad(mask, 1)
    core = (slice(1, -1),) * 3
    inside = ndimage.distance_transform_edt(padded, sampling=spacing)[core]
    outside = ndimage.distance_transform_edt(~padded, sampling=spacing)[core]
    return np.where(mask, half - inside, outside - half).astype(np.float32)


def sdf_hull(
    sections: CrossSections,
    projections: Projections,
    *,
    upsample: int = 1,
) -> trimesh.Trimesh:
    """SDF interpolation between the planes, carved by the projections' visual hull.

    Parameters
    ----------
    sections : CrossSections
        Binary masks on parallel planes.
    projections : Projections
        The three silhouettes on the sections' reference grid.
    upsample : int, default 1
        Samples per reference voxel along the section axis (>= 1), as for
        :func:`~slicerecon.surface.sdf.sdf_field`; the hull is repeated to match.

    Returns
    -------
    trimesh.Trimesh
        Closed, outward mesh of ``{max(sdf, d_hull) < 0}`` in world mm, with
        ``sdf`` interpolated between the planes and extended beyond the end
        planes as prisms (:func:`~slicerecon.surface.sdf.sdf_field` with the
        whole grid as box and ``extend_to_box=True``).

    Raises
    ------
    InputError
        If ``projections`` is not a Projections object.
    GeometryError
        If the projections do not fit the sections' grid.
    EmptyMaskError
        If the interpolation and the hull do not overlap.
    """

    _check_sections(sections, "sdf-hull")
    proj = _check_projections(projections, sections)
    # The first / last plane is extended unchanged to the grid faces (a prism);
    # the hull decides where the shape ends along the axis.
    grid = Box((0, 0, 0), sections.grid_shape)
    field, affine = sdf_field(sections, box=grid, upsample=upsample, extend_to_box=True)
    hull = visual_hull(proj, sections.grid_shape)
    spacing = sections.spacing.copy()
    if upsample > 1:
        hull = np.repeat(hull, int(upsample), axis=sections.axis)
        spacing[sections.axis] /= int(upsample)
    carved = np.maximum(field, _signed_distance_3d(hull, spacing))
    if not np.any(carved < 0):
        raise EmptyMaskError(
            "the visual hull of the projections does not overlap the interpolated sections; "
            "check that the projections belong to these sections"
        )
    step = float(spacing.min())
    logger.debug(
        "sdf-hull: %d of %d interpolated samples kept inside the hull",
        int(np.count_nonzero(carved < 0)),
        int(np.count_nonzero(field < 0)),
    )
    return field_to_mesh(_nudged(carved, step), affine, level=0.0, inside="negative")


# -- ITK morphological contour interpolation --------------------------------------------
_ITK_INSTALL = (
    'pip install "slicerecon[itk]" (or pip install itk-morphologicalcontourinterpolation)'
)


def _import_itk() -> Any:
    import importlib.util

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", DeprecationWarning)
            itk = importlib.import_module("itk")
            found = importlib.util.find_spec("itk.MorphologicalContourInterpolationPython")
    except ImportError as exc:
        raise DependencyError(
            f"the itk-mci method needs ITK ({exc}); install it with {_ITK_INSTALL}"
        ) from None
    if found is None:
        raise DependencyError(
            "the itk-mci method needs ITK's MorphologicalContourInterpolation module, which "
            f"is not installed; install it with {_ITK_INSTALL}"
        )
    return itk


def itk_mci(
    sections: CrossSections,
    projections: Projections | None = None,
    *,
    heuristic_alignment: bool = True,
    use_distance_transform: bool = True,
) -> trimesh.Trimesh:
    """ITK morphological contour interpolation between the planes + marching cubes.

    Parameters
    ----------
    sections : CrossSections
        Binary masks on planes at integer indices of the reference grid.
    projections : Projections, optional
        Unused (accepted for the common baseline signature).
    heuristic_alignment : bool, default True
        ITK's ``HeuristicAlignment``: align the regions of two planes by their
        centroids (fast) instead of an exhaustive search.
    use_distance_transform : bool, default True
        ITK's ``UseDistanceTransform``: find the median contour with distance
        transforms (faster) rather than repeated dilations.

    Returns
    -------
    trimesh.Trimesh
        Closed, outward marching-cubes mesh of the interpolated mask, world mm.

    Raises
    ------
    DependencyError
        If ITK or its MorphologicalContourInterpolation module is missing.
    GeometryError
        If a plane lies between grid indices.
    EmptyMaskError
        If no plane holds foreground.

    Notes
    -----
    ITK treats a plane without foreground as *not annotated*: an empty plane
    between two non-empty ones does not separate them (two objects whose
    regions overlap across the gap are joined). The first call in a process
    costs about 10 s (ITK loads its wrapped filter). The filter runs on one
    thread: on several it corrupts memory; ITK's global default thread count
    is set to 1 during the call and restored after it, so do not run other
    ITK filters in parallel threads meanwhile.
    """
    _check_sections(sections, "itk-mci")
    alignment = _check_bool(heuristic_alignment, "heuristic_alignment")
    distance = _check_bool(use_distance_transform, "use_distance_transform")
    if not sections.is_on_grid:
        raise GeometryError(
            "itk-mci interpolates on the voxel grid, but some planes lie between grid "
            "indices; use --method sdf or loft for such inputs"
        )
    itk = _import_itk()
    volume = sections.to_volume()
    labels = np.ascontiguousarray(volume.mask, dtype=np.uint8)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        # itk.image_from_array reads a C-ordered array as (z, y, x): ITK axis 2 - a
        # is our grid axis a.
        image = itk.image_from_array(labels)
        image.SetSpacing([float(s) for s in sections.spacing[::-1]])
        # The filter corrupts the heap when run on several threads (glibc aborts
        # with "malloc_consolidate(): unaligned fastbin chunk" at exit; seen with
        # itk-morphologicalcontourinterpolation 2.1.2 on spheres): its internal
        # pipelines take the global default thread count, so run them on one thread.
        threads = itk.MultiThreaderBase.GetGlobalDefaultNumberOfThreads()
        itk.MultiThreaderBase.SetGlobalDefaultNumberOfThreads(1)
        try:
            interpolator = itk.MorphologicalContourInterpolator.New(image)
            interpolator.SetAxis(2 - sections.axis)
            interpolator.SetHeuristicAlignment(alignment)
            interpolator.SetUseDistanceTransform(distance)
            interpolator.Update()
            filled = np.asarray(itk.array_from_image(interpolator.GetOutput())) > 0
        finally:
            itk.MultiThreaderBase.SetGlobalDefaultNumberOfThreads(threads)
    if filled.shape != labels.shape:
        raise GeometryError(
            f"ITK returned a grid of shape {filled.shape} for an input of shape {labels.shape}"
        )
    logger.debug(
        "itk-mci: %d annotated voxels -> %d interpolated voxels",
        int(np.count_nonzero(labels)),
        int(np.count_nonzero(filled)),
    )
    return volume_to_mesh(Volume(filled | volume.mask, sections.affine))


# -- registry ---------------------------------------------------------------------------
BASELINES: dict[str, BaselineFn] = {
    name: method_entry(name).load() for name in method_names(per_part=False)
}
"""Whole-shape methods by name: the view of :data:`slicerecon.surface.methods.METHODS`
on the ``--method`` values that bypass the planners."""


def baseline_names() -> list[str]:
    """Names in :data:`BASELINES`, sorted."""
    return sorted(BASELINES)


def reconstruct_baseline(
    sections: CrossSections,
    projections: Projections | None,
    *,
    method: str,
    **options: Any,
) -> trimesh.Trimesh:
    """Run the whole-shape baseline ``method`` on all the sections at once.

    Parameters
    ----------
    sections : CrossSections
        Binary masks on parallel planes.
    projections : Projections or None
        The silhouettes (needed by ``sdf-hull`` only).
    method : {"poisson", "sdf-hull", "itk-mci"}
        A name in :data:`BASELINES`.
    **options
        Keyword options of that method's function.

    Returns
    -------
    trimesh.Trimesh
        Closed, outward mesh in world mm.

    Raises
    ------
    OptionError
        If ``method`` is unknown.
    """
    name = method.strip().lower() if isinstance(method, str) else method
    if name not in BASELINES:
        raise OptionError(
            f"unknown baseline {method!r}; choose one of: {', '.join(baseline_names())}"
        )
    mesh = BASELINES[name](sections, projections, **options)
    if not (mesh.is_watertight and mesh.volume > 0):
        raise GeometryError(
            f"the {name} baseline produced a mesh that is not closed and outward; "
            "please report this input"
        )
    return mesh
