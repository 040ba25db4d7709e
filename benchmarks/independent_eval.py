"""Scores of a reconstructed mesh against a ground-truth mask, independent of slicerecon.metrics.

Used by ``benchmarks/real_anatomy.py``. Nothing here calls
:mod:`slicerecon.metrics` or the library's rasterizer, so a bug there cannot
hide in the benchmark's numbers. Only numpy, scipy and scikit-image's
marching cubes are used.

* **Volume IoU.** The mesh is rasterized onto the ground-truth grid
  (extended to the mesh's bounding box, so that nothing outside the grid is
  lost) by its winding number at every voxel centre, counted along rays
  parallel to each of the three grid axes (signed crossings, summed along
  the ray). A voxel is inside when the winding number is non-zero for at
  least two of the three axes; for a closed mesh all three agree, and the
  vote keeps a small hole from smearing a streak through the grid.
* **Chamfer-L1 and HD95 (mm).** The ground-truth surface is the marching-cubes
  surface of the mask at level 0.5 (padded by one voxel, so closed), in world
  mm through the affine. The distance of each of ``n_query`` area-uniform
  random points of one surface to the other surface is the exact
  point-to-triangle distance to the nearest of the triangles that carry its
  8 nearest neighbours among the other surface's triangle centroids and
  ``n_reference`` random points on it (a k-d tree finds them): never below
  the true distance, and equal to it whenever the nearest triangle is among
  the candidates (a surface scored against itself gets Chamfer-L1 below
  0.001 mm). Chamfer-L1 is the mean of the two directed mean distances; HD95
  is the larger of the two directed 95th percentiles (the MONAI / medpy
  convention).
* **Watertight.** Every undirected edge is shared by exactly two triangles
  and the two use it in opposite directions (closed and consistently oriented).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy.spatial import cKDTree
from skimage.measure import marching_cubes

__all__ = [
    "Scores",
    "Truth",
    "boundary_surface",
    "is_watertight",
    "rasterize_mesh",
    "sample_surface",
    "score_mesh",
    "surface_distances",
]

_RAY_SHIFT = np.array([1.2345e-7, 2.7183e-7, 3.1416e-7])
"""Tiny irrational-looking offsets of the rays, voxels: no ray passes exactly through an edge."""


@dataclass(frozen=True)
class Scores:
    """Scores of one mesh against one mask."""

    volume_iou: float
    """Intersection over union of the rasterized mesh and the mask (voxel counts)."""
    chamfer_l1_mm: float
    """Mean of the two directed mean surface distances, mm."""
    hd95_mm: float
    """Larger of the two directed 95th-percentile surface distances, mm."""
    watertight: bool
    """Closed and consistently oriented."""
    volume_ratio: float
    """Rasterized mesh voxels / mask voxels."""


def is_watertight(faces: NDArray[np.integer]) -> bool:
    """True when each edge of ``faces``, ndarray of shape (F, 3), joins two opposite sides."""
    f = np.asarray(faces, dtype=np.int64)
    if f.size == 0:
        return False
    directed = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
    key = directed[:, 0] * (int(directed.max()) + 1) + directed[:, 1]
    reverse = directed[:, 1] * (int(directed.max()) + 1) + directed[:, 0]
    key.sort()
    if np.any(key[1:] == key[:-1]):
        return False  # a directed edge used twice: non-manifold or flipped triangle
    reverse.sort()  # each edge used once each way: the reversed edges are the same set
    return bool(np.array_equal(key, reverse))


def _winding_along(
    tri: NDArray[np.float64], sign: float, shape: tuple[int, int, int], axis: int
) -> NDArray[np.bool_]:
    """Voxel centres with a non-zero winding number, counted along rays parallel to ``axis``.

    ``tri`` holds the triangles in voxel-index coordinates, ndarray of shape
    (F, 3, 3); ``sign`` is +1 when the index frame keeps the world's handedness.
    """
    u, v = (axis + 1) % 3, (axis + 2) % 3  # (u, v, axis) is a right-handed cycle
    pu = tri[:, :, u] - _RAY_SHIFT[u]
    pv = tri[:, :, v] - _RAY_SHIFT[v]
    pw = tri[:, :, axis]
    area = (pu[:, 1] - pu[:, 0]) * (pv[:, 2] - pv[:, 0]) - (pu[:, 2] - pu[:, 0]) * (
        pv[:, 1] - pv[:, 0]
    )  # twice the signed area of the projection: the normal's `axis` component
    u0 = np.maximum(np.ceil(pu.min(axis=1)), 0).astype(np.int64)
    u1 = np.minimum(np.floor(pu.max(axis=1)), shape[u] - 1).astype(np.int64)
    v0 = np.maximum(np.ceil(pv.min(axis=1)), 0).astype(np.int64)
    v1 = np.minimum(np.floor(pv.max(axis=1)), shape[v] - 1).astype(np.int64)
    nu = np.maximum(u1 - u0 + 1, 0)
    nv = np.maximum(v1 - v0 + 1, 0)
    keep = (area != 0) & (nu > 0) & (nv > 0)
    idx = np.flatnonzero(keep)
    counts = nu[idx] * nv[idx]
    acc = np.zeros(shape[u] * shape[v] * (shape[axis] + 1), dtype=np.int64)
    chunk = 2_000_000  # candidate (triangle, ray) pairs per batch: bounded memory
    starts = np.concatenate([[0], np.cumsum(counts)])
    t = 0
    while t < len(idx):
        stop = int(np.searchsorted(starts, starts[t] + chunk, side="right")) - 1
        stop = max(stop, t + 1)
        sel = idx[t:stop]
        cnt = counts[t:stop]
        owner = np.repeat(np.arange(len(sel)), cnt)
        local = np.arange(int(cnt.sum())) - np.repeat(starts[t:stop] - starts[t], cnt)
        tri_i = sel[owner]
        ru = u0[tri_i] + local // nv[tri_i]
        rv = v0[tri_i] + local % nv[tri_i]
        # barycentric coordinates of the ray (ru, rv) in the projected triangle
        a_u, a_v = pu[tri_i, 0], pv[tri_i, 0]
        b_u, b_v = pu[tri_i, 1], pv[tri_i, 1]
        c_u, c_v = pu[tri_i, 2], pv[tri_i, 2]
        w0 = (b_u - ru) * (c_v - rv) - (c_u - ru) * (b_v - rv)
        w1 = (c_u - ru) * (a_v - rv) - (a_u - ru) * (c_v - rv)
        w2 = (a_u - ru) * (b_v - rv) - (b_u - ru) * (a_v - rv)
        ar = area[tri_i]
        inside = np.where(
            ar > 0, (w0 >= 0) & (w1 >= 0) & (w2 >= 0), (w0 <= 0) & (w1 <= 0) & (w2 <= 0)
        )
        tri_i, ru, rv = tri_i[inside], ru[inside], rv[inside]
        w0, w1, w2, ar = w0[inside], w1[inside], w2[inside], ar[inside]
        depth = (w0 * pw[tri_i, 0] + w1 * pw[tri_i, 1] + w2 * pw[tri_i, 2]) / ar
        # the crossing toggles every voxel centre beyond it: the first is floor(depth) + 1
        k = np.clip(np.floor(depth).astype(np.int64) + 1, 0, shape[axis])
        # entering a closed surface (normal against the ray) adds +1
        step = -np.sign(ar).astype(np.int64) * int(sign)
        flat = (ru * shape[v] + rv) * (shape[axis] + 1) + k
        acc += np.bincount(flat, weights=step, minlength=acc.size).astype(np.int64)
        t = stop
    winding = np.cumsum(acc.reshape(shape[u], shape[v], shape[axis] + 1), axis=2)[:, :, :-1]
    return np.moveaxis(winding != 0, (0, 1, 2), (u, v, axis))


def rasterize_mesh(
    vertices_mm: NDArray[np.floating],
    faces: NDArray[np.integer],
    affine: NDArray[np.floating],
    shape: tuple[int, int, int],
) -> NDArray[np.bool_]:
    """Voxel centres of a grid inside a mesh (winding number, majority of three ray axes).

    Parameters
    ----------
    vertices_mm : ndarray of shape (V, 3)
        World mm.
    faces : ndarray of shape (F, 3)
        Triangles, outward normals by the right-hand rule.
    affine : ndarray of shape (4, 4)
        Voxel index → world mm of the grid.
    shape : tuple of int
        Grid shape ``(I, J, K)``.

    Returns
    -------
    ndarray of shape ``shape``, bool
    """
    inv = np.linalg.inv(np.asarray(affine, dtype=np.float64))
    q = np.asarray(vertices_mm, dtype=np.float64) @ inv[:3, :3].T + inv[:3, 3]
    tri = q[np.asarray(faces, dtype=np.int64)]
    sign = float(np.sign(np.linalg.det(np.asarray(affine, dtype=np.float64)[:3, :3])))
    votes = np.zeros(shape, dtype=np.int8)
    for axis in range(3):
        votes += _winding_along(tri, sign, shape, axis)
    return votes >= 2


def boundary_surface(
    mask: NDArray[np.bool_], affine: NDArray[np.floating]
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Marching-cubes surface (level 0.5) of a mask, padded so closed, in world mm.

    Returns
    -------
    vertices : ndarray of shape (V, 3), mm
    faces : ndarray of shape (F, 3)
    """
    padded = np.pad(np.asarray(mask, dtype=np.float32), 1)
    verts, faces, _, _ = marching_cubes(padded, level=0.5)
    verts = verts.astype(np.float64) - 1.0
    a = np.asarray(affine, dtype=np.float64)
    return verts @ a[:3, :3].T + a[:3, 3], faces.astype(np.int64)


def sample_surface(
    vertices: NDArray[np.floating],
    faces: NDArray[np.integer],
    n: int,
    rng: np.random.Generator,
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """``n`` points uniformly distributed by area on a triangle mesh.

    Returns
    -------
    points : ndarray of shape (n, 3)
    triangle : ndarray of shape (n,)
        Index of the triangle each point lies on.
    """
    tri = np.asarray(vertices, dtype=np.float64)[np.asarray(faces, dtype=np.int64)]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    pick = rng.choice(len(tri), size=n, p=area / area.sum())
    r1, r2 = rng.random(n), rng.random(n)
    s = np.sqrt(r1)
    a, b, c = 1.0 - s, s * (1.0 - r2), s * r2
    t = tri[pick]
    return a[:, None] * t[:, 0] + b[:, None] * t[:, 1] + c[:, None] * t[:, 2], pick


def _point_triangle_distance(
    p: NDArray[np.float64],
    a: NDArray[np.float64],
    b: NDArray[np.float64],
    c: NDArray[np.float64],
) -> NDArray[np.float64]:
    """Distance from points to triangles, row by row (Ericson's closest-point regions)."""

    def dot(x: NDArray[np.float64], y: NDArray[np.float64]) -> NDArray[np.float64]:
        return np.einsum("...i,...i->...", x, y)

    ab, ac, ap, bp, cp = b - a, c - a, p - a, p - b, p - c
    d1, d2, d3, d4, d5, d6 = (
        dot(ab, ap),
        dot(ac, ap),
        dot(ab, bp),
        dot(ac, bp),
        dot(ab, cp),
        dot(ac, cp),
    )
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):  # degenerate cases are never picked
        denom = va + vb + vc
        v_in, w_in = vb / denom, vc / denom
        t_ab = d1 / (d1 - d3)
        t_ac = d2 / (d2 - d6)
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        choices = [
            a,
            b,
            a + t_ab[..., None] * ab,
            c,
            a + t_ac[..., None] * ac,
            b + t_bc[..., None] * (c - b),
        ]
        closest = a + v_in[..., None] * ab + w_in[..., None] * ac  # inside the face
    conditions = [
        (d1 <= 0) & (d2 <= 0),  # vertex a
        (d3 >= 0) & (d4 <= d3),  # vertex b
        (vc <= 0) & (d1 >= 0) & (d3 <= 0),  # edge ab
        (d6 >= 0) & (d5 <= d6),  # vertex c
        (vb <= 0) & (d2 >= 0) & (d6 <= 0),  # edge ac
        (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0),  # edge bc
    ]
    for cond, choice in zip(reversed(conditions), reversed(choices), strict=True):
        closest = np.where(cond[..., None], choice, closest)  # earlier regions win
    with np.errstate(invalid="ignore"):
        dist = np.linalg.norm(p - closest, axis=-1)
    corner = np.min(np.stack([np.linalg.norm(p - x, axis=-1) for x in (a, b, c)]), axis=0)
    return np.where(np.isfinite(dist), np.minimum(dist, corner), corner)  # degenerate triangles


class _Surface:
    """A triangle surface with a k-d tree of dense samples, to find nearby triangles fast."""

    def __init__(self, vertices: NDArray, faces: NDArray, n: int, rng: np.random.Generator):
        self.tri = np.asarray(vertices, dtype=np.float64)[np.asarray(faces, dtype=np.int64)]
        points, owner = sample_surface(vertices, faces, n, rng)
        # every triangle's centroid too, so that small triangles are never missed
        self.owner = np.concatenate([np.arange(len(self.tri)), owner])
        points = np.concatenate([self.tri.mean(axis=1), points])
        self.tree = cKDTree(points)

    def distance(self, query: NDArray[np.float64], k: int = 8) -> NDArray[np.float64]:
        """Distance of each query point to the surface, mm: the nearest of the triangles
        that carry its ``k`` nearest samples (exact whenever the nearest triangle is one
        of them; never below the true distance)."""
        _, near = self.tree.query(query, k=k)
        cand = self.owner[near]  # (Q, k) triangle indices
        t = self.tri[cand]  # (Q, k, 3, 3)
        d = _point_triangle_distance(query[:, None, :], t[:, :, 0], t[:, :, 1], t[:, :, 2])
        return d.min(axis=1)


class Truth:
    """A ground-truth mask prepared once for scoring many meshes against it.

    Parameters
    ----------
    mask : ndarray of shape (I, J, K), bool
        Ground truth.
    affine : ndarray of shape (4, 4)
        Voxel index → world mm of ``mask``.
    seed : int, default 0
        Seed of the truth's surface samples.
    n_query, n_reference : int, default 30 000 and 100 000
        Surface samples whose distance is measured, and extra samples in the
        k-d tree that finds candidate triangles (see :func:`surface_distances`).
    """

    def __init__(
        self,
        mask: NDArray[np.bool_],
        affine: NDArray[np.floating],
        *,
        seed: int = 0,
        n_query: int = 30_000,
        n_reference: int = 100_000,
    ):
        self.mask = np.asarray(mask, dtype=bool)
        self.affine = np.asarray(affine, dtype=np.float64)
        self.n_query, self.n_reference = int(n_query), int(n_reference)
        rng = np.random.default_rng(seed)
        self.surface = boundary_surface(self.mask, self.affine)
        self.query, _ = sample_surface(*self.surface, self.n_query, rng)
        self.reference = _Surface(*self.surface, self.n_reference, rng)


def surface_distances(
    pred: tuple[NDArray, NDArray],
    truth: Truth,
    rng: np.random.Generator,
) -> tuple[float, float]:
    """Chamfer-L1 and HD95 between a triangle surface and the truth's boundary, mm.

    Parameters
    ----------
    pred : tuple of (vertices ndarray of shape (V, 3), faces ndarray of shape (F, 3))
        Surface in world mm.
    truth : Truth
        The ground truth, with its boundary surface and samples.
    rng : numpy.random.Generator
        Source of the samples of ``pred``: ``truth.n_query`` area-uniform points
        whose distance to the truth is measured, and ``truth.n_reference``
        more that, with the triangle centroids, find candidate triangles.

    Returns
    -------
    chamfer_l1_mm, hd95_mm : float
    """
    query_p, _ = sample_surface(*pred, truth.n_query, rng)
    d_pt = truth.reference.distance(query_p)  # prediction → truth
    d_tp = _Surface(*pred, truth.n_reference, rng).distance(truth.query)  # truth → prediction
    chamfer = 0.5 * (float(d_pt.mean()) + float(d_tp.mean()))
    hd95 = max(float(np.percentile(d_pt, 95)), float(np.percentile(d_tp, 95)))
    return chamfer, hd95


def score_mesh(
    vertices_mm: NDArray[np.floating],
    faces: NDArray[np.integer],
    truth: Truth,
    *,
    seed: int | np.random.Generator = 0,
) -> Scores:
    """All the scores of one mesh against a ground truth.

    Parameters
    ----------
    vertices_mm : ndarray of shape (V, 3)
        Mesh vertices, world mm.
    faces : ndarray of shape (F, 3)
        Mesh triangles.
    truth : Truth
        The ground truth (mask, affine and boundary samples).
    seed : int or numpy.random.Generator, default 0
        Seed of the mesh's surface samples.

    Returns
    -------
    Scores
    """
    rng = np.random.default_rng(seed)
    affine, mask = truth.affine, truth.mask
    verts = np.asarray(vertices_mm, dtype=np.float64)
    faces = np.asarray(faces, dtype=np.int64)
    # extend the grid to the mesh's bounding box (integer voxel steps, geometry kept)
    inv = np.linalg.inv(affine)
    q = verts @ inv[:3, :3].T + inv[:3, 3]
    lo = np.minimum(np.floor(q.min(axis=0)).astype(np.int64) - 1, 0)
    hi = np.maximum(np.ceil(q.max(axis=0)).astype(np.int64) + 2, mask.shape)
    grid = tuple(int(n) for n in hi - lo)
    big = np.zeros(grid, dtype=bool)
    big[tuple(slice(int(-a), int(-a + n)) for a, n in zip(lo, mask.shape, strict=True))] = mask
    shift = np.eye(4)
    shift[:3, 3] = lo
    pred = rasterize_mesh(verts, faces, affine @ shift, grid)
    inter = int(np.count_nonzero(pred & big))
    union = int(np.count_nonzero(pred | big))
    chamfer, hd95 = surface_distances((verts, faces), truth, rng)
    return Scores(
        volume_iou=inter / union if union else 1.0,
        chamfer_l1_mm=chamfer,
        hd95_mm=hd95,
        watertight=is_watertight(faces),
        volume_ratio=int(np.count_nonzero(pred)) / max(int(np.count_nonzero(mask)), 1),
    )
