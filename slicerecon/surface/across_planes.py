"""Interpolation across planes: in-plane signed distances filled in between their planes.

Between two section planes the signed distance of a pixel is interpolated
along the plane normal: linearly slab by slab (classic shape-based
interpolation, Raya & Udupa 1990), or by the monotone piecewise cubic through
every plane (PCHIP, Fritsch & Carlson 1980), which never overshoots the
planes' values. Used by :mod:`slicerecon.surface.sdf`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

__all__ = ["INTERPOLATIONS", "fill_between", "is_empty_distance", "pchip_fill", "pchip_slopes"]

INTERPOLATIONS = ("linear", "pchip")
"""How the in-plane signed distances are interpolated across planes."""


def fill_between(
    field: NDArray[np.float32],
    samples: NDArray[np.float64],
    w: NDArray[np.float64],
    used: NDArray[np.int64],
    distances: dict[int, NDArray[np.float32]],
    interpolation: str = "linear",
) -> None:
    """Interpolate the used planes' distances into ``field`` (axis first) between them.

    ``"linear"``: each slab between consecutive planes on its own (classic
    shape-based interpolation). ``"pchip"``: per pixel, the piecewise cubic
    Hermite interpolant through all used planes whose slopes keep each slab
    monotone (Fritsch & Carlson 1980, scipy's ``PchipInterpolator``): smooth
    across planes, never overshooting the planes' values, so a pixel is inside
    between two planes that both hold it, and the plane masks are reproduced.
    With two planes it is the linear interpolation.

    An empty plane's distance is taken as the constant depth of the deepest
    region of its non-empty neighbour (linear: of the slab's other plane; pchip:
    the deeper of both neighbours), so that their regions close off towards it.
    """
    order = [int(p) for p in used]
    if interpolation == "pchip" and len(order) > 2:
        values = {p: distances[p] for p in order}
        for i, p in enumerate(order):
            if is_empty_distance(values[p]):
                depths = [
                    -float(distances[q].min())
                    for q in order[max(i - 1, 0) : i + 2]
                    if not is_empty_distance(distances[q])
                ]
                if depths:
                    values[p] = np.full_like(values[p], max(depths))
        if not any(is_empty_distance(values[p]) for p in order):
            pchip_fill(field, samples, w[order], [values[p] for p in order])
            return
    for p, q in zip(order[:-1], order[1:], strict=True):
        lower, upper = distances[p], distances[q]
        if is_empty_distance(lower) and is_empty_distance(upper):
            continue
        if is_empty_distance(lower):
            lower = np.full_like(upper, -float(upper.min()))
        elif is_empty_distance(upper):
            upper = np.full_like(lower, -float(lower.min()))
        last = q == order[-1]
        sel = np.flatnonzero((samples >= w[p]) & ((samples <= w[q]) if last else (samples < w[q])))
        if sel.size == 0:
            continue
        t = ((samples[sel] - w[p]) / (w[q] - w[p])).astype(np.float32)[:, None, None]
        field[sel] = (1.0 - t) * lower[None] + t * upper[None]


def pchip_slopes(x: NDArray[np.float64], y: NDArray[np.float64]) -> NDArray[np.float64]:
    """Fritsch-Carlson slopes of the monotone cubic through ``y`` at ``x`` (axis 0).

    The same rule as scipy's ``PchipInterpolator``: zero where the secant
    slopes change sign or one is zero, else their weighted harmonic mean; the
    end slopes by the shape-preserving three-point formula (Moler,
    *Numerical Computing with MATLAB*, 3.6). ``x`` of shape (P,), ``y`` of
    shape (P, ...), P >= 3.
    """
    shape = (-1,) + (1,) * (y.ndim - 1)
    h = np.diff(x).reshape(shape)
    m = np.diff(y, axis=0) / h
    d = np.zeros_like(y)
    w1 = 2 * h[1:] + h[:-1]
    w2 = h[1:] + 2 * h[:-1]
    flat = (np.sign(m[1:]) != np.sign(m[:-1])) | (m[1:] == 0) | (m[:-1] == 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        inner = (w1 + w2) / (w1 / m[:-1] + w2 / m[1:])
    d[1:-1] = np.where(flat, 0.0, inner)
    for end, (h0, h1, m0, m1) in (
        (0, (h[0], h[1], m[0], m[1])),
        (-1, (h[-1], h[-2], m[-1], m[-2])),
    ):
        e = ((2 * h0 + h1) * m0 - h0 * m1) / (h0 + h1)
        e = np.where(np.sign(e) != np.sign(m0), 0.0, e)
        e = np.where((np.sign(m0) != np.sign(m1)) & (np.abs(e) > 3 * np.abs(m0)), 3 * m0, e)
        d[end] = e
    return d


def pchip_fill(
    field: NDArray[np.float32],
    samples: NDArray[np.float64],
    w: NDArray[np.float64],
    planes: Sequence[NDArray[np.float32]],
) -> None:
    """The monotone cubic through the planes' distances, written into ``field`` layer by layer.

    Cubic Hermite on each slab with :func:`pchip_slopes`; the extra memory is
    two stacks of the planes (values and slopes), never the whole grid.
    """
    y = np.stack(planes).astype(np.float64)
    slopes = pchip_slopes(w, y)
    inside = np.flatnonzero((samples >= w[0]) & (samples <= w[-1]))
    slab = np.clip(np.searchsorted(w, samples[inside], side="right") - 1, 0, len(w) - 2)
    for k, i in zip(inside, slab, strict=True):
        h = w[i + 1] - w[i]
        t = (samples[k] - w[i]) / h
        t2, t3 = t * t, t * t * t
        h00, h10 = 2 * t3 - 3 * t2 + 1, t3 - 2 * t2 + t
        h01, h11 = -2 * t3 + 3 * t2, t3 - t2
        field[k] = h00 * y[i] + h10 * h * slopes[i] + h01 * y[i + 1] + h11 * h * slopes[i + 1]


def is_empty_distance(distance: NDArray[np.float32]) -> bool:
    """Whether a plane distance comes from an empty mask (all ``+inf``)."""
    return bool(np.isinf(distance.flat[0]))
