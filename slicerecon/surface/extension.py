"""Extension slabs: how a part continues from its outermost plane to its box face.

A part's box usually reaches past its first and last section plane: the box
comes from the projections, which say where the part ends, while the nearest
section may lie several voxels inside. No section covers this *extension
slab*. Without more information the outermost contour is extruded unchanged
(a prism). The projections do say more: the visual hull gives, on every layer
of the slab, how far the shape reaches along each in-plane axis inside the
box's footprint. :func:`extension_maps` turns this into one map per layer
that stretches and shifts each in-plane axis so that the hull's extent on the
plane's layer lands on its extent on that layer; the surface methods carry
the outermost contour (:mod:`~slicerecon.surface.loft`) or its signed distance
(:mod:`~slicerecon.surface.sdf`) through these maps.

Where the hull keeps its extent through the slab (a chair leg up to the seat)
every map is the identity and the extension is the prism. Where it narrows or
drifts (a tube that curves or slants toward the box face) the contour follows
it. Layers where the hull is empty inside the footprint keep the map of the
layer before them (the carve removes what lies there,
:mod:`~slicerecon.surface.carve`).

Coordinates are in-plane voxel indices ``(u, v)`` of the reference grid along
:attr:`~slicerecon.sections.CrossSections.plane_axes`; ``w`` is the index
along the section axis.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numpy.typing import NDArray

from ..errors import GeometryError
from ..sections import Box

__all__ = ["LayerMap", "check_hull", "extension_maps", "identity_map", "interpolate_maps"]


class LayerMap(NamedTuple):
    """The map from the outermost plane's in-plane coordinates to one layer's.

    Per in-plane axis, the hull's extent on the plane (``source``) is mapped
    linearly onto its extent on the layer (``target``); points beyond the
    extent move with its nearer edge. Each axis's map is continuous and
    increasing, so a simple counter-clockwise polygon stays simple and
    counter-clockwise.

    Attributes
    ----------
    w : float
        Position of the layer along the section axis, index units.
    source, target : ndarray of shape (2, 2)
        ``[axis] = (low edge, high edge)`` of the extents, index units.
    """

    w: float
    source: NDArray[np.float64]
    target: NDArray[np.float64]

    def forward(self, points: NDArray[np.float64]) -> NDArray[np.float64]:
        """Points ``(..., 2)`` on the plane mapped onto this layer."""
        return _piecewise(points, self.source, self.target)

    def inverse(self, points: NDArray[np.float64]) -> NDArray[np.float64]:
        """Points ``(..., 2)`` on this layer mapped back onto the plane."""
        return _piecewise(points, self.target, self.source)

    def is_identity(self) -> bool:
        """Whether the map leaves every point where it is."""
        return bool(np.array_equal(self.source, self.target))

    def unchanged(self, w: float) -> LayerMap:
        """The identity map with this map's extents, at ``w`` (the plane's own map)."""
        return LayerMap(float(w), self.source, self.source)


def _piecewise(
    points: NDArray[np.float64], source: NDArray[np.float64], target: NDArray[np.float64]
) -> NDArray[np.float64]:
    """Map ``points (..., 2)`` so that each axis's ``source`` edges land on its ``target``
    edges: linear between them, shifted with the nearer edge beyond them."""
    out = np.empty_like(points, dtype=np.float64)
    for ax in (0, 1):
        x = points[..., ax]
        (s0, s1), (d0, d1) = source[ax], target[ax]
        inner = d0 + (x - s0) * ((d1 - d0) / (s1 - s0))
        out[..., ax] = np.where(x < s0, x + (d0 - s0), np.where(x > s1, x + (d1 - s1), inner))
    return out


def interpolate_maps(maps: list[LayerMap], w: float) -> LayerMap:
    """The map at ``w`` between maps of one slab (same ``source``), linear in ``w``.

    ``maps`` must be sorted by ``w``; outside their range the nearest end is used.
    """
    ws = np.array([m.w for m in maps])
    targets = np.stack([m.target for m in maps])
    s = float(np.clip(w, ws[0], ws[-1]))
    target = np.empty((2, 2))
    for ax in (0, 1):
        for edge in (0, 1):
            target[ax, edge] = np.interp(s, ws, targets[:, ax, edge])
    return LayerMap(float(w), maps[0].source, target)


def check_hull(hull: object, grid_shape: tuple[int, int, int]) -> None:
    """Raise :class:`~slicerecon.errors.GeometryError` unless ``hull`` is None or a
    boolean mask of ``grid_shape``."""
    if hull is None:
        return
    if not isinstance(hull, np.ndarray) or hull.dtype != np.bool_:
        raise GeometryError(f"the hull must be a boolean ndarray (got {type(hull).__name__})")
    if hull.shape != tuple(grid_shape):
        raise GeometryError(
            f"the hull has shape {hull.shape} but the sections' grid is {tuple(grid_shape)}"
        )


def identity_map(w: float) -> LayerMap:
    """The map of a prism: every layer a copy of the plane."""
    unit = np.array([[0.0, 1.0], [0.0, 1.0]])
    return LayerMap(float(w), unit, unit)


def _extent(layer: NDArray[np.bool_], axis: int) -> tuple[int, int] | None:
    """Half-open index range ``[first, last + 1)`` of the occupied rows (0) or columns (1)."""
    occupied = np.flatnonzero(layer.any(axis=1 - axis))
    if occupied.size == 0:
        return None
    return int(occupied[0]), int(occupied[-1]) + 1


def _edges(layer: NDArray[np.bool_], origin: tuple[int, int]) -> NDArray[np.float64] | None:
    """Pixel-edge extents ``(2, 2)`` of a layer (the range ``[e0, e1)`` spans
    ``e0 - 0.5 .. e1 - 0.5``), None when it is empty."""
    edges = np.empty((2, 2))
    for ax in (0, 1):
        extent = _extent(layer, ax)
        if extent is None:
            return None
        edges[ax] = (extent[0] + origin[ax] - 0.5, extent[1] + origin[ax] - 0.5)
    return edges


def extension_maps(
    hull: NDArray[np.bool_] | None, box: Box, axis: int, anchor: float, side: int
) -> list[LayerMap]:
    """The layer maps of one extension slab, in increasing ``w``.

    Parameters
    ----------
    hull : ndarray of shape (I, J, K), bool, or None
        The visual hull on the reference grid; None gives the prism (the
        face's identity map).
    box : Box
        The part's box (inside the grid).
    axis : int
        Section axis (0, 1 or 2).
    anchor : float
        Position of the outermost plane inside the box, index units.
    side : {0, 1}
        0: the slab below the anchor, down to the face ``box.lo[axis] - 0.5``;
        1: the slab above it, up to the face ``box.hi[axis] - 0.5``.

    Returns
    -------
    list of LayerMap
        One map per layer centre strictly between the anchor and the face, and
        one for the face itself (the map of the layer next to it); runs of
        equal maps (counting the anchor's identity) are thinned to their
        ends, so a prism is the face's identity map alone. Empty when the
        anchor lies on the face (no slab).

    Raises
    ------
    GeometryError
        If the hull is not 3-D or ``side`` is not 0 or 1.
    """
    if side not in (0, 1):
        raise GeometryError(f"side must be 0 (below) or 1 (above) (got {side!r})")
    lo, hi = box.lo[axis], box.hi[axis]
    face = lo - 0.5 if side == 0 else hi - 0.5
    if (face - anchor) * (1 if side else -1) <= 0:
        return []
    if hull is None:
        return [identity_map(face)]
    if hull.ndim != 3:
        raise GeometryError(f"the hull must be a 3-D mask (got {hull.ndim} dimensions)")
    a, b = (ax for ax in range(3) if ax != axis)
    footprint = np.moveaxis(hull, axis, 0)[:, box.lo[a] : box.hi[a], box.lo[b] : box.hi[b]]
    origin = (box.lo[a], box.lo[b])
    base_layer = int(np.clip(np.floor(anchor + 0.5), lo, hi - 1))
    if side == 0:
        layers = list(range(base_layer - 1, lo - 1, -1))  # from the anchor outward
    else:
        layers = list(range(base_layer + 1, hi))
    source = _edges(footprint[base_layer], origin)
    if source is None:
        return [identity_map(face)]
    maps: list[LayerMap] = []
    previous = LayerMap(float(anchor), source, source)
    for layer in layers:
        target = _edges(footprint[layer], origin)
        previous = LayerMap(float(layer), source, previous.target if target is None else target)
        maps.append(previous)
    maps.append(previous._replace(w=face))
    # Thin from the anchor outward, the anchor's own (identity) map first.
    return sorted(_thin([previous.unchanged(anchor), *maps])[1:], key=lambda m: m.w)


def _thin(maps: list[LayerMap]) -> list[LayerMap]:
    """Drop maps equal to both neighbours (the surface is straight through them)."""
    if len(maps) <= 2:
        return maps

    def same(p: LayerMap, q: LayerMap) -> bool:
        return bool(np.array_equal(p.target, q.target))

    keep = [maps[0]]
    for k in range(1, len(maps) - 1):
        if not (same(maps[k - 1], maps[k]) and same(maps[k], maps[k + 1])):
            keep.append(maps[k])
    keep.append(maps[-1])
    return keep
