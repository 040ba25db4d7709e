"""A batched torch surrogate of the reward's part surface, for fast training on a device.

The reward's reconstruction ``S_i`` of a part is the library's default surface
(:func:`slicerecon.policy.reward.part_surface_voxels`): signed-distance
interpolation across the section planes inside the part's box (PCHIP),
extended to the box faces along the visual hull, carved by the hull
(:mod:`slicerecon.surface.sdf`, ``docs/method.md``). It costs a few
milliseconds per part in numpy, too slow for thousands of environment steps
per second. :func:`surrogate_parts` computes the same field for a batch of
parts at once on torch tensors, with three simplifications:

* **In-plane distances** are each plane's signed distance over the whole
  plane (computed once per episode, :func:`slicerecon.policy.reward.plane_distances`),
  corrected for the box: the library computes them on the box's footprint
  grown by one pixel, beyond which everything counts as background. Inside
  the shape that correction is exact (the distance to the crop's border is
  taken into account); outside it the surrogate sees foreground beyond the
  crop that the library does not, so its outside distances can be smaller.
* **Extensions** from the first / last plane in the box to the box faces are
  prisms (the plane's distance repeated) instead of following the hull's
  extent layer by layer; the carve by the hull removes what lies outside it.
* **Drifting regions** (a region that overlaps nothing on the next plane,
  :mod:`slicerecon.surface.drift`) are not joined: between such planes the
  surrogate has the plain blend, which closes both regions off.

Everything else is the library's rule: the planes used (inside the box, or
the two either side of a box that holds none), PCHIP through them with the
Fritsch–Carlson slopes (linear for two planes, the library's float32 linear
blend when a plane's substitute for emptiness is missing), a plane that is
empty inside the crop replaced by the depth of its deepest neighbour, the
sign test of the float32 field, the carve. On a part whose box holds the
whole shape with a free border, whose ends are planes and where no region
drifts, the surrogate equals the library exactly (tested); ``benchmarks/reward_agreement.py``
measures the agreement on random parts (``docs/policy.md``).

Grids have unit voxels (the training episodes' identity affine) and the
section planes are integer z-planes (:data:`~slicerecon.partition.episodes.SECTION_AXIS`).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch
from numpy.typing import NDArray

from ..sections import Box, CrossSections
from .reward import plane_distances

__all__ = ["surrogate_field", "surrogate_parts", "surrogate_reconstruction"]

_HALF = 0.5
"""Half the in-plane voxel size: where :func:`~slicerecon.surface.sdf.plane_signed_distance`
puts the zero level between a foreground and a background pixel centre."""


def _first_true(mask: torch.Tensor) -> torch.Tensor:
    """Index of the first True along the last axis (0 where none)."""
    return torch.argmax(mask.to(torch.uint8), dim=-1)


def _last_true(mask: torch.Tensor) -> torch.Tensor:
    """Index of the last True along the last axis (size - 1 where none)."""
    n = mask.shape[-1]
    return n - 1 - torch.argmax(mask.flip(-1).to(torch.uint8), dim=-1)


def _take(values: torch.Tensor, index: torch.Tensor) -> torch.Tensor:
    """``values[b, index[b, k], ...]`` for values (n, P, ...) and index (n, K)."""
    shape = index.shape + (1,) * (values.ndim - 2)
    expanded = index.reshape(shape).expand(*index.shape, *values.shape[2:])
    return torch.gather(values, 1, expanded)


def _pchip_slopes(z: torch.Tensor, y: torch.Tensor, count: torch.Tensor) -> torch.Tensor:
    """Fritsch–Carlson slopes of the monotone cubics through ``y`` at ``z`` (float64).

    ``z`` (n, P), ``y`` (n, P, I, J); row ``b`` uses its first ``count[b] >= 3``
    knots (the rule of :func:`slicerecon.surface.across_planes.pchip_slopes`, scipy's
    ``PchipInterpolator``). Slopes past ``count`` are meaningless.
    """
    n, p = z.shape
    rows = torch.arange(n, device=z.device)
    h = (z[:, 1:] - z[:, :-1]).clamp(min=1e-12)[:, :, None, None]  # (n, P-1, 1, 1)
    m = (y[:, 1:] - y[:, :-1]) / h
    d = torch.zeros_like(y)
    if p < 3:
        return d
    h0, h1 = h[:, :-1], h[:, 1:]
    m0, m1 = m[:, :-1], m[:, 1:]
    w1 = 2 * h1 + h0
    w2 = h1 + 2 * h0
    flat = (torch.sign(m1) != torch.sign(m0)) | (m1 == 0) | (m0 == 0)
    inner = (w1 + w2) / (w1 / m0 + w2 / m1)
    d[:, 1:-1] = torch.where(flat, torch.zeros_like(inner), inner)

    def end(k0: torch.Tensor, k1: torch.Tensor) -> torch.Tensor:
        """The three-point end slope from secants k0 (at the end) and k1 (next)."""
        ha, hb = h[rows, k0], h[rows, k1]
        ma, mb = m[rows, k0], m[rows, k1]
        e = ((2 * ha + hb) * ma - ha * mb) / (ha + hb)
        e = torch.where(torch.sign(e) != torch.sign(ma), torch.zeros_like(e), e)
        big = (torch.sign(ma) != torch.sign(mb)) & (e.abs() > 3 * ma.abs())
        return torch.where(big, 3 * ma, e)

    last = (count - 1).clamp(min=2, max=p - 1)
    zero = torch.zeros_like(count)
    d[:, 0] = end(zero, zero + 1)
    d[rows, last] = end(last - 1, last - 2)
    return d


def surrogate_field(
    distances: torch.Tensor,
    planes: torch.Tensor,
    plane_valid: torch.Tensor,
    lo: torch.Tensor,
    hi: torch.Tensor,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """The surrogate's interpolated signed distance of ``n`` parts, layer by layer.

    Parameters
    ----------
    distances : Tensor of shape (n, P, I, J), float32
        Each episode's plane signed distances over whole planes
        (:func:`slicerecon.policy.reward.plane_distances`; ``+inf`` on empty planes).
    planes : Tensor of shape (n, P), int64
        z-index of each plane, increasing over the valid entries, which come first.
    plane_valid : Tensor of shape (n, P), bool
    lo, hi : Tensor of shape (n, 3), int64
        The parts' boxes (``hi`` exclusive).

    Returns
    -------
    part, layer : Tensor of shape (M,), int64
        The ``M`` (part, z) pairs of the boxes' z-ranges.
    field : Tensor of shape (M, I, J), float32
        The field (negative inside) on those layers, whole planes (only the
        box's footprint matters); ``+inf`` for parts without a usable plane.
    """
    n, p, size_i, size_j = distances.shape
    dev = distances.device
    inf = torch.tensor(float("inf"), device=dev)
    arange_p = torch.arange(p, device=dev)

    # In-plane crop (the box grown by one pixel, clipped) and distance to its outside.
    def axis_ring(size: int, a: torch.Tensor, b: torch.Tensor) -> tuple[torch.Tensor, ...]:
        idx = torch.arange(size, device=dev)[None, :]
        start = (a - 1).clamp(min=0)[:, None]
        stop = (b + 1).clamp(max=size)[:, None]
        inside = (idx >= start) & (idx < stop)
        ring = torch.minimum(idx - start + 1, stop - idx).to(torch.float32)
        return inside, ring

    in_i, ring_i = axis_ring(size_i, lo[:, 0], hi[:, 0])
    in_j, ring_j = axis_ring(size_j, lo[:, 1], hi[:, 1])
    crop = in_i[:, :, None] & in_j[:, None, :]  # (n, I, J)
    ring = torch.minimum(ring_i[:, :, None], ring_j[:, None, :])

    # The planes used: inside the box's z-range, else the two either side of it,
    # gathered to the front (compact index k = 0 .. count - 1).
    z_lo, z_hi = lo[:, 2:3], hi[:, 2:3]
    inside = plane_valid & (planes >= z_lo) & (planes <= z_hi - 1)
    below = plane_valid & (planes <= z_lo - 1)
    above = plane_valid & (planes >= z_hi)
    has_inside = inside.any(dim=1)
    bridge = ~has_inside & below.any(dim=1) & above.any(dim=1)
    first = torch.where(has_inside, _first_true(inside), _last_true(below))
    last = torch.where(has_inside, _last_true(inside), _first_true(above))
    count = torch.where(has_inside | bridge, last - first + 1, torch.zeros_like(first))
    p_all, p = p, max(int(count.max()), 1) if n else 1  # only as many planes as a part uses
    arange_p = arange_p[:p]
    index = (first[:, None] + arange_p[None, :]).clamp(max=p_all - 1)
    used = arange_p[None, :] < count[:, None]  # (n, P')

    # Crop distances of the used planes: exact inside (the crop's border is
    # background), whole-plane outside; a plane empty in the crop is +inf.
    raw = _take(distances, index)
    inside_px = raw < 0
    y = torch.where(inside_px, torch.maximum(raw, _HALF - ring[:, None]), raw)
    empty = ~(inside_px & crop[:, None]).flatten(2).any(dim=2) & used
    y = torch.where(empty[:, :, None, None], inf, y)
    depth = -torch.where(crop[:, None], y, inf).flatten(2).amin(dim=2)  # (n, P)
    zc = torch.gather(planes, 1, index).to(torch.float64)
    usable = (~empty & used).any(dim=1) & (count > 0)

    # PCHIP through >= 3 planes, an empty plane replaced by its deepest neighbour's depth.
    prev_ok = torch.zeros_like(empty)
    prev_ok[:, 1:] = ~empty[:, :-1] & used[:, :-1]
    next_ok = torch.zeros_like(empty)
    next_ok[:, :-1] = ~empty[:, 1:] & used[:, 1:]
    neg = torch.full_like(depth, -float("inf"))
    prev_depth = torch.cat([neg[:, :1], depth[:, :-1]], dim=1)
    next_depth = torch.cat([depth[:, 1:], neg[:, :1]], dim=1)
    substitute = torch.maximum(
        torch.where(prev_ok, prev_depth, neg), torch.where(next_ok, next_depth, neg)
    )
    has_substitute = prev_ok | next_ok
    pchip = (count >= 3) & ~(empty & ~has_substitute).any(dim=1)
    y_p = torch.where(
        (empty & has_substitute)[:, :, None, None], substitute[:, :, None, None].expand_as(y), y
    )
    y_p = torch.where(used[:, :, None, None], y_p, torch.zeros_like(y_p)).to(torch.float64)
    slopes = _pchip_slopes(zc, y_p, count.clamp(min=3))

    # The (part, layer) samples of the boxes' z-ranges; slab j: zc[j] <= z (< zc[j+1]).
    size_k = int(hi[:, 2].max()) if n else 0
    zs = torch.arange(size_k, device=dev)
    in_box = (zs[None, :] >= z_lo) & (zs[None, :] < z_hi)
    part, layer = torch.nonzero(in_box, as_tuple=True)
    zf = layer.to(torch.float64)
    knots = torch.where(used, zc, torch.full_like(zc, float("inf")))[part]  # (M, P)
    slab = (knots <= zf[:, None]).sum(dim=1) - 1
    slab = torch.minimum(slab.clamp(min=0), (count[part] - 2).clamp(min=0))
    nxt = (slab + 1).clamp(max=p - 1)
    z0, z1 = zc[part, slab], zc[part, nxt]
    h = (z1 - z0).clamp(min=1e-12)
    t = (zf - z0) / h  # (M,) float64

    def rows(values: torch.Tensor, k: torch.Tensor, sel: torch.Tensor) -> torch.Tensor:
        """values[part[sel], k[sel]] as (m, I, J): whole planes copied at once."""
        flat = values.reshape(n * p, size_i, size_j)
        return flat.index_select(0, part[sel] * p + k[sel])

    field = torch.full((part.numel(), size_i, size_j), float("inf"), device=dev)
    cubic = pchip[part] & usable[part]
    if bool(cubic.any()):
        tc = t[cubic]
        t2, t3 = tc * tc, tc * tc * tc
        hc = h[cubic]
        basis = [
            (2 * t3 - 3 * t2 + 1),
            (t3 - 2 * t2 + tc) * hc,
            (-2 * t3 + 3 * t2),
            (t3 - t2) * hc,
        ]  # the library's h00, h10 * h, h01, h11 * h
        terms = [
            rows(y_p, slab, cubic),
            rows(slopes, slab, cubic),
            rows(y_p, nxt, cubic),
            rows(slopes, nxt, cubic),
        ]
        value = basis[0][:, None, None] * terms[0]
        for b, term in zip(basis[1:], terms[1:], strict=True):
            value = value + b[:, None, None] * term
        field[cubic] = value.to(torch.float32)
    lin = ~pchip[part] & usable[part]
    if bool(lin.any()):
        # Slab by slab in float32, an empty end replaced by the other end's depth.
        lower, upper = rows(y, slab, lin), rows(y, nxt, lin)
        e0, e1 = empty[part[lin], slab[lin]], empty[part[lin], nxt[lin]]
        d0, d1 = depth[part[lin], slab[lin]], depth[part[lin], nxt[lin]]
        lower = torch.where(e0[:, None, None], d1[:, None, None].expand_as(lower), lower)
        upper = torch.where(e1[:, None, None], d0[:, None, None].expand_as(upper), upper)
        tl = t[lin].to(torch.float32)[:, None, None]
        value = (1.0 - tl) * lower + tl * upper
        field[lin] = torch.where((e0 & e1)[:, None, None], inf, value)

    # Prism extensions from the end planes to the box faces (their own crop distances).
    end_last = (count - 1).clamp(min=0)
    z_first, z_last = zc[part, 0], zc[part, end_last[part]]
    for sel, k in ((zf <= z_first, torch.zeros_like(part)), (zf >= z_last, end_last[part])):
        sel = sel & usable[part]
        if bool(sel.any()):
            field[sel] = rows(y, k, sel)
    return part, layer, field


def surrogate_parts(
    distances: torch.Tensor,
    planes: torch.Tensor,
    plane_valid: torch.Tensor,
    hull: torch.Tensor,
    lo: torch.Tensor,
    hi: torch.Tensor,
) -> torch.Tensor:
    """The surrogate ``S_i`` of ``n`` parts: inside the field, the hull and the box.

    Parameters
    ----------
    distances, planes, plane_valid, lo, hi
        As for :func:`surrogate_field`.
    hull : Tensor of shape (n, I, J, K), bool
        Each episode's visual hull (:func:`slicerecon.partition.episodes.occupancy_hull`).

    Returns
    -------
    Tensor of shape (n, I, J, K), bool
        ``S_i`` on the whole grid, False outside each part's box.
    """
    n, size_i, size_j, size_k = hull.shape
    inside = torch.zeros((n, size_k, size_i, size_j), dtype=torch.bool, device=hull.device)
    if n == 0:
        return inside.permute(0, 2, 3, 1)
    part, layer, field = surrogate_field(distances, planes, plane_valid, lo, hi)
    inside[part, layer] = field < 0
    axes = []
    for a, size in enumerate((size_i, size_j)):
        idx = torch.arange(size, device=hull.device)[None, :]
        axes.append((idx >= lo[:, a : a + 1]) & (idx < hi[:, a : a + 1]))
    footprint = axes[0][:, :, None] & axes[1][:, None, :]
    return inside.permute(0, 2, 3, 1) & hull & footprint[:, :, :, None]


def surrogate_reconstruction(
    sections: CrossSections, hull: NDArray[np.bool_]
) -> Callable[[Box], NDArray[np.bool_]]:
    """The surrogate of one episode as a ``reconstruct(box)`` callable (one part, CPU).

    The ``reconstruct`` argument of :class:`~slicerecon.partition.state.PartitionState`
    that gives the same ``S_i`` as the environment's ``reward_surface="surrogate"``.

    Parameters
    ----------
    sections : CrossSections
        The episode's sections (:func:`~slicerecon.partition.episodes.episode_sections`).
    hull : ndarray of shape sections.grid_shape, bool
        Its visual hull (:func:`~slicerecon.partition.episodes.occupancy_hull`).

    Returns
    -------
    callable
        ``reconstruct(box) -> ndarray of box.shape, bool``.
    """
    distances = torch.from_numpy(plane_distances(sections))[None]
    planes = torch.from_numpy(sections.indices.astype(np.int64))[None]
    valid = torch.ones_like(planes, dtype=torch.bool)
    hull_t = torch.from_numpy(np.ascontiguousarray(hull))[None]

    def reconstruct(box: Box) -> NDArray[np.bool_]:
        lo, hi = torch.tensor([box.lo]), torch.tensor([box.hi])
        with torch.no_grad():
            s = surrogate_parts(distances, planes, valid, hull_t, lo, hi)[0]
        return s.numpy()[box.slices].copy()

    return reconstruct
