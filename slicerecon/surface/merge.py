"""Exact union of closed meshes with manifold3d.

The parts of a reconstruction are closed solids that touch or overlap (they
share box faces, and lofts of neighbouring slabs share their cap polygons).
:func:`union_meshes` merges them into one watertight, manifold mesh with
manifold3d's exact Boolean union, which handles coincident and coplanar
faces by symbolic perturbation instead of tolerances.

Two small converters are public because the lofting code works with
manifold3d solids directly: :func:`to_manifold` (``trimesh`` → ``Manifold``,
double precision) and :func:`from_manifold` (``Manifold`` → ``trimesh``,
optionally through an affine map, with the face winding kept outward).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence

import manifold3d
import numpy as np
import trimesh
from numpy.typing import ArrayLike, NDArray

from ..errors import EmptyMaskError, GeometryError, InputError

__all__ = [
    "check_closed",
    "from_manifold",
    "solid_from_arrays",
    "to_manifold",
    "union_meshes",
    "union_solids",
]

logger = logging.getLogger(__name__)


def to_manifold(mesh: trimesh.Trimesh) -> manifold3d.Manifold:
    """Convert a closed triangle mesh to a manifold3d solid (double precision).

    Parameters
    ----------
    mesh : trimesh.Trimesh
        A closed, consistently wound mesh. An inward-wound mesh (negative
        volume) is inverted.

    Returns
    -------
    manifold3d.Manifold

    Raises
    ------
    InputError
        If ``mesh`` is not a ``trimesh.Trimesh``.
    GeometryError
        If the mesh is not an oriented 2-manifold (open edges, edges shared by
        more than two faces, inconsistent winding).
    """
    if not isinstance(mesh, trimesh.Trimesh):
        raise InputError(f"expected a trimesh.Trimesh (got {type(mesh).__name__})")
    faces = np.asarray(mesh.faces, dtype=np.int64)
    vertices = np.asarray(mesh.vertices)
    solid = solid_from_arrays(vertices, faces) if len(faces) else None
    if solid is None:
        raise GeometryError(
            f"the mesh ({len(mesh.vertices)} vertices, {len(mesh.faces)} faces) is not a "
            "closed oriented manifold; repair it (e.g. fill holes, merge vertices) first"
        )
    if solid.volume() < 0:
        solid = solid_from_arrays(vertices, faces[:, ::-1])
    return solid  # type: ignore[return-value]


def solid_from_arrays(vertices: ArrayLike, faces: ArrayLike) -> manifold3d.Manifold | None:
    """Build a manifold3d solid from vertex and face arrays, or None if they are not manifold.

    Parameters
    ----------
    vertices : ndarray of shape (V, 3)
        Vertex positions (any unit).
    faces : ndarray of shape (F, 3), int
        Triangles, counter-clockwise seen from outside.

    Returns
    -------
    manifold3d.Manifold or None
        None when manifold3d rejects the mesh (not an oriented 2-manifold).
    """
    verts = np.ascontiguousarray(vertices, dtype=np.float64)
    tris = np.ascontiguousarray(faces, dtype=np.uint64)
    solid = manifold3d.Manifold(manifold3d.Mesh64(vert_properties=verts, tri_verts=tris))
    if solid.status() != manifold3d.Error.NoError:
        logger.debug("manifold3d rejected a mesh: %s", solid.status())
        return None
    return solid


def from_manifold(
    solid: manifold3d.Manifold, *, transform: ArrayLike | None = None
) -> trimesh.Trimesh:
    """Convert a manifold3d solid to a ``trimesh.Trimesh``.

    Parameters
    ----------
    solid : manifold3d.Manifold
        The solid.
    transform : ndarray of shape (4, 4), optional
        Affine map applied to the vertices (e.g. plane coordinates → world
        mm). When its determinant is negative (a mirroring map) the face
        winding is reversed, so that normals keep pointing outward.

    Returns
    -------
    trimesh.Trimesh
        Vertices merged by position (``process=True``). Empty (no faces) when
        the solid is empty.
    """
    mesh64 = solid.to_mesh64()
    verts = np.asarray(mesh64.vert_properties, dtype=np.float64)[:, :3]
    faces = np.asarray(mesh64.tri_verts, dtype=np.int64).reshape(-1, 3)
    if transform is not None:
        mat = np.asarray(transform, dtype=np.float64)
        verts = verts @ mat[:3, :3].T + mat[:3, 3]
        if np.linalg.det(mat[:3, :3]) < 0:
            faces = faces[:, ::-1]
    verts = _separate_pinches(verts, faces)
    return trimesh.Trimesh(vertices=verts, faces=faces, process=True)


PINCH_GAP_MM = 1e-3
"""How far apart :func:`from_manifold` pulls vertices that touch at one position."""

PINCH_RADIUS_MM = 1e-4
"""Distinct vertices closer than this are taken as touching: welding tools and the
float32 coordinates of STL would merge them."""


def _separate_pinches(verts: NDArray[np.float64], faces: NDArray[np.int64]) -> NDArray[np.float64]:
    """Pull apart distinct vertices that share a position.

    manifold3d keeps a solid 2-manifold where it touches itself along an edge
    or at a point by giving the touching sheets separate vertices at the same
    position. File formats without connectivity (STL) merge them, which makes
    edges shared by four faces. Each such vertex is moved by
    :data:`PINCH_GAP_MM` towards the centre of its own neighbours, so the
    sheets separate by a few micrometres and the mesh stays manifold after
    any merge by position.
    """
    if len(verts) == 0:
        return verts
    from scipy.spatial import cKDTree

    # Vertices closer than PINCH_RADIUS_MM would be merged by tools that weld by
    # position (trimesh, STL readers): treat them as touching.
    pairs = cKDTree(verts).query_pairs(PINCH_RADIUS_MM, output_type="ndarray")
    pinched = np.unique(pairs)
    if pinched.size == 0:
        return verts
    verts = verts.copy()
    edges = np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]])
    edges = edges[np.isin(edges[:, 0], pinched)]  # only the pinched vertices' edges
    for v in pinched:
        neighbours = edges[edges[:, 0] == v, 1]
        if neighbours.size == 0:
            continue
        direction = verts[neighbours].mean(axis=0) - verts[v]
        length = float(np.linalg.norm(direction))
        if length > 0:
            verts[v] += direction * min(PINCH_GAP_MM / length, 0.25)
    # Copies whose fans lie on the same side moved together: push each such
    # pair apart along the line between their fans' centres.
    for _ in range(3):
        close = cKDTree(verts[pinched]).query_pairs(PINCH_RADIUS_MM, output_type="ndarray")
        if close.size == 0:
            break
        for i, j in pinched[close]:
            centre_i = verts[edges[edges[:, 0] == i, 1]].mean(axis=0)
            centre_j = verts[edges[edges[:, 0] == j, 1]].mean(axis=0)
            apart = centre_i - centre_j
            length = float(np.linalg.norm(apart))
            if length > 0:
                verts[i] += apart / length * PINCH_GAP_MM
    logger.debug("separated %d pinched vertices", pinched.size)
    return verts


def union_solids(solids: Sequence[manifold3d.Manifold]) -> manifold3d.Manifold:
    """Exact union of manifold3d solids (an empty solid for no input)."""
    kept = [s for s in solids if s is not None and not s.is_empty()]
    if not kept:
        return manifold3d.Manifold()
    if len(kept) == 1:
        return kept[0]
    return manifold3d.Manifold.batch_boolean(kept, manifold3d.OpType.Add)


def union_meshes(meshes: Sequence[trimesh.Trimesh]) -> trimesh.Trimesh:
    """Exact Boolean union of closed meshes into one watertight manifold mesh.

    Parameters
    ----------
    meshes : sequence of trimesh.Trimesh
        Closed meshes in the same coordinates (world mm), any winding.
        ``None`` entries, meshes without faces and closed meshes enclosing no
        volume are dropped (logged at debug level).

    Returns
    -------
    trimesh.Trimesh
        The union: watertight, consistently outward-wound, possibly with
        several connected components.

    Raises
    ------
    InputError
        If an entry is not a ``trimesh.Trimesh``.
    GeometryError
        If an input mesh is not a closed oriented manifold.
    EmptyMaskError
        If no mesh with a volume is left to merge.
    """
    solids: list[manifold3d.Manifold] = []
    for number, mesh in enumerate(meshes):
        if mesh is None:
            continue
        if not isinstance(mesh, trimesh.Trimesh):
            raise InputError(f"mesh {number} is a {type(mesh).__name__}, not a trimesh.Trimesh")
        if len(mesh.faces) == 0:
            logger.debug("union_meshes: dropped mesh %d (no faces)", number)
            continue
        try:
            solid = to_manifold(mesh)
        except GeometryError as exc:
            raise GeometryError(f"mesh {number}: {exc}") from None
        if solid.is_empty() or solid.volume() <= 0:
            logger.debug("union_meshes: dropped mesh %d (encloses no volume)", number)
            continue
        solids.append(solid)
    if not solids:
        raise EmptyMaskError("no mesh enclosing a volume was given to merge")
    merged = from_manifold(union_solids(solids))
    check_closed(merged, "union_meshes")
    return merged


def check_closed(mesh: trimesh.Trimesh, what: str) -> bool:
    """Whether ``mesh`` is a watertight, outward volume; logs a warning naming ``what`` if not.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        The mesh to check.
    what : str
        Name of the operation that made it, for the log message.

    Returns
    -------
    bool
    """
    if not (mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0):
        logger.warning(
            "%s: result is not a clean closed volume (watertight=%s, volume=%.4g); "
            "coincident geometry may have pinched it",
            what,
            mesh.is_watertight,
            mesh.volume,
        )
        return False
    return True
