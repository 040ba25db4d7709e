"""A small software renderer: shaded meshes in world millimetres, true aspect, numpy only.

The preview of a case (:mod:`slicerecon.preview`) and the 3-D renders of the
HTML report (:mod:`slicerecon.report.renders`) draw with this one renderer, so
what a run shows and what its report shows look the same.

Meshes are projected orthographically with **one scale for all three axes**
(world mm, true aspect: a 2.5 mm slice spacing is 2.5 mm on screen) and
rasterised with a depth buffer, every face shaded by a two-sided Lambert term
with the light over the viewer's left shoulder. Silhouettes and the borders
between structures are darkened so that touching structures stay apart. A
frame (``"RAS"`` or ``"LPS"``) shows the meshes in the same patient
orientation whichever frame they are stored in, and names the axes of the
orientation triad by their anatomical directions.

Everything is numpy (and Pillow for text and lines): no display, no OpenGL,
deterministic pixels. A 256³ case's mesh (a few hundred thousand faces)
renders in a few tenths of a second.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

__all__ = [
    "DEFAULT_VIEW",
    "Camera",
    "Rendered",
    "Surface",
    "cluster",
    "draw_centred",
    "draw_scale_bar",
    "draw_triad",
    "font",
    "nice_length",
    "project",
    "render_surfaces",
    "to_display_frame",
    "view_rotation",
]

DEFAULT_VIEW = (20.0, 120.0)
"""(elevation, azimuth) in degrees of the renders: seen from the patient's front
left, a little from above (in RAS; LPS meshes are turned to match)."""

BACKGROUND = (255, 255, 255)
_LIGHT = np.array([-0.35, 0.55, 0.76])
_LIGHT = _LIGHT / np.linalg.norm(_LIGHT)
_MAX_CANDIDATES = 1 << 22
"""Candidate pixels rasterised per batch (bounds the memory of one step)."""


class Surface(NamedTuple):
    """One mesh to draw.

    Attributes
    ----------
    vertices : ndarray of shape (V, 3)
        World mm (in the display frame, see :func:`to_display_frame`).
    faces : ndarray of shape (F, 3), int
    colour : ndarray of shape (3,) or (F, 3)
        RGB in [0, 1]: one colour, or one per face (shaded either way).
    """

    vertices: NDArray[np.float64]
    faces: NDArray[np.int64]
    colour: NDArray[np.float64]


class Camera(NamedTuple):
    """An orthographic view fitted to a box.

    Attributes
    ----------
    rotation : ndarray of shape (3, 3)
        World → view: rows are the screen's right, up, and the direction
        towards the viewer.
    scale : float
        Pixels per mm (the same along every axis).
    origin : ndarray of shape (2,)
        View coordinates (mm) of the image's top-left corner (x, y).
    size : tuple of int
        ``(width, height)`` in pixels.
    """

    rotation: NDArray[np.float64]
    scale: float
    origin: NDArray[np.float64]
    size: tuple[int, int]


class Rendered(NamedTuple):
    """A rendered image and the camera that made it.

    Attributes
    ----------
    image : ndarray of shape (H, W, 3), uint8
    camera : Camera
    """

    image: NDArray[np.uint8]
    camera: Camera


def view_rotation(elevation: float, azimuth: float) -> NDArray[np.float64]:
    """World → view rotation of a viewer at ``(elevation, azimuth)`` degrees.

    The viewer looks from the direction ``(cos e cos a, cos e sin a, sin e)``
    towards the origin, with world +z up on the screen.
    """
    e, a = math.radians(elevation), math.radians(azimuth)
    toward = np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])
    right = np.array([-math.sin(a), math.cos(a), 0.0])
    up = np.cross(toward, right)
    return np.stack([right, up, toward])


def to_display_frame(points: ArrayLike, frame: str | None) -> NDArray[np.float64]:
    """World points in the renders' frame: RAS (LPS points have x and y negated).

    Parameters
    ----------
    points : array_like of shape (N, 3)
    frame : {"RAS", "LPS"} or None
        The frame of ``points`` (None: taken as RAS).
    """
    out = np.asarray(points, dtype=np.float64)
    if frame == "LPS":
        out = out * np.array([-1.0, -1.0, 1.0])
    return out


def fit_camera(
    lo: ArrayLike,
    hi: ArrayLike,
    size: tuple[int, int],
    *,
    view: tuple[float, float] = DEFAULT_VIEW,
    margin: int = 12,
) -> Camera:
    """The camera that shows the box ``[lo, hi]`` (world mm) whole, at one scale.

    Parameters
    ----------
    lo, hi : array_like of shape (3,)
        Corners of the box to show, mm.
    size : (width, height)
        Image size, pixels.
    view : (elevation, azimuth)
        Degrees (:func:`view_rotation`).
    margin : int
        Pixels kept free on every side.
    """
    rotation = view_rotation(*view)
    lo_, hi_ = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    corners = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], np.float64)
    box = lo_ + corners * (hi_ - lo_)
    seen = box @ rotation[:2].T
    low, high = seen.min(axis=0), seen.max(axis=0)
    extent = np.maximum(high - low, 1e-6)
    width, height = size
    scale = float(min((width - 2 * margin) / extent[0], (height - 2 * margin) / extent[1]))
    centre = (low + high) / 2.0
    origin = np.array([centre[0] - width / 2.0 / scale, centre[1] + height / 2.0 / scale])
    return Camera(rotation, scale, origin, (int(width), int(height)))


def project(camera: Camera, points: ArrayLike) -> NDArray[np.float64]:
    """Pixel coordinates of world points: columns ``x`` (right), ``y`` (down), depth (towards
    the viewer, mm).

    Parameters
    ----------
    camera : Camera
    points : array_like of shape (N, 3)

    Returns
    -------
    ndarray of shape (N, 3)
    """
    view = camera.rotation @ np.asarray(points, np.float64).T  # (3, N): fast in BLAS
    out = np.empty((view.shape[1], 3))
    out[:, 0] = (view[0] - camera.origin[0]) * camera.scale
    out[:, 1] = (camera.origin[1] - view[1]) * camera.scale
    out[:, 2] = view[2]
    return out


def _merge(
    points: NDArray[np.floating], faces: NDArray[np.int64], cell: float
) -> tuple[NDArray[np.float64], NDArray[np.int64], NDArray[np.bool_]]:
    """Merge points into cubes of side ``cell``; the faces that keep three corners.

    Returns the merged points (each cube's mean), the kept faces on them, and
    which of the given faces were kept.
    """
    cells = np.floor((points - points.min(axis=0)) / cell).astype(np.int64)
    span = cells.max(axis=0) + 1
    keys = (cells[:, 0] * span[1] + cells[:, 1]) * span[2] + cells[:, 2]
    _, inverse, counts = np.unique(keys, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    merged = np.stack(
        [np.bincount(inverse, weights=points[:, k]) / counts for k in range(3)], axis=1
    )
    mapped = inverse[faces]
    keep = (
        (mapped[:, 0] != mapped[:, 1])
        & (mapped[:, 1] != mapped[:, 2])
        & (mapped[:, 0] != mapped[:, 2])
    )
    return merged, mapped[keep], keep


def cluster(surface: Surface, cell: float) -> Surface:
    """The surface with its vertices merged into cubes of side ``cell`` mm (for display).

    Faces smaller than a pixel add nothing to an image but time: vertices in
    one cube become one (their mean), faces that collapse are dropped.
    Deterministic; per-face colours follow their faces.
    """
    faces = np.asarray(surface.faces, np.int64)
    if len(faces) == 0 or cell <= 0:
        return surface
    merged, kept, keep = _merge(np.asarray(surface.vertices, np.float64), faces, cell)
    colour = np.asarray(surface.colour, np.float64)
    return Surface(merged, kept, colour[keep] if colour.ndim == 2 else colour)


def _shade(normals: NDArray[np.float64], colour: NDArray[np.float64]) -> NDArray[np.float64]:
    """Face colours in [0, 1]: ``colour`` times two-sided Lambert shading.

    ``normals``: view-space face normals (right, up, towards the viewer), any length.
    """
    length = np.linalg.norm(normals, axis=1)
    light = np.abs(normals @ _LIGHT) / np.where(length > 0, length, 1.0)
    shade = 0.32 + 0.6 * light + 0.12 * light**8  # ambient, diffuse, a little sheen
    colour = np.broadcast_to(np.asarray(colour, np.float64), (len(normals), 3))
    return np.clip(colour * shade[:, None], 0.0, 1.0)


def _rasterise(
    tri: NDArray[np.float64], size: tuple[int, int]
) -> tuple[NDArray[np.int64], NDArray[np.float32], NDArray[np.int64]]:
    """Covered pixels of projected triangles: pixel index, depth and triangle of each hit.

    ``tri``: shape (F, 3, 3), pixel x, y and depth of each corner. A pixel is
    covered when its centre lies inside the triangle (edges included, so that
    neighbouring triangles leave no crack). Triangles are taken in groups of
    like size, each tested against the pixels of its bounding square at once.
    """
    width, height = size
    t = tri.astype(np.float32)
    x, y = t[..., 0] - 0.5, t[..., 1] - 0.5  # pixel (r, c) has its centre at (c, r) now
    x0 = np.ceil(x.min(axis=1)).astype(np.int32)
    y0 = np.ceil(y.min(axis=1)).astype(np.int32)
    span = (
        np.maximum(
            np.floor(x.max(axis=1)).astype(np.int32) - x0,
            np.floor(y.max(axis=1)).astype(np.int32) - y0,
        )
        + 1
    )
    ex1, ey1 = x[:, 1] - x[:, 0], y[:, 1] - y[:, 0]
    ex2, ey2 = x[:, 2] - x[:, 0], y[:, 2] - y[:, 0]
    area = ex1 * ey2 - ex2 * ey1
    visible = (
        (np.abs(area) > 1e-9)
        & (span > 0)
        & (x0 < width)
        & (y0 < height)
        & (x0 + span > 0)
        & (y0 + span > 0)
    )
    pixels, depths, owners = [], [], []
    bound = 1
    largest = int(span[visible].max(initial=0))
    while bound // 2 < largest:
        size_class = (span <= bound) & (span > bound // 2) if bound > 1 else span == 1
        chosen = np.flatnonzero(visible & size_class)
        oy, ox = np.divmod(np.arange(bound * bound, dtype=np.int32), bound)
        per = max(1, _MAX_CANDIDATES // (bound * bound))
        for start in range(0, chosen.size, per):
            ids = chosen[start : start + per]
            cols = x0[ids, None] + ox
            rows = y0[ids, None] + oy
            # barycentric coordinates of each candidate pixel centre
            dx = cols.astype(np.float32) - x[ids, 0, None]
            dy = rows.astype(np.float32) - y[ids, 0, None]
            inv = (1.0 / area[ids])[:, None]
            w1 = (dx * ey2[ids, None] - dy * ex2[ids, None]) * inv
            w2 = (dy * ex1[ids, None] - dx * ey1[ids, None]) * inv
            hit = (w1 >= -1e-6) & (w2 >= -1e-6) & (w1 + w2 <= 1.0 + 1e-6)
            hit &= (cols >= 0) & (cols < width) & (rows >= 0) & (rows < height)
            z0 = t[ids, 0, 2, None]
            depth = z0 + w1 * (t[ids, 1, 2, None] - z0) + w2 * (t[ids, 2, 2, None] - z0)
            pixels.append((rows.astype(np.int64) * width + cols)[hit])
            depths.append(depth[hit].astype(np.float32, copy=False))
            owners.append(np.broadcast_to(ids[:, None], hit.shape)[hit])
        bound *= 2
    if not pixels:
        empty = np.zeros(0, np.int64)
        return empty, np.zeros(0, np.float32), empty
    return np.concatenate(pixels), np.concatenate(depths), np.concatenate(owners)


def _normals(vertices: NDArray[np.float64], faces: NDArray[np.int64]) -> NDArray[np.float64]:
    """Each face's normal, its length twice the face's area."""
    a = vertices[faces[:, 0]]
    return np.cross(vertices[faces[:, 1]] - a, vertices[faces[:, 2]] - a)


def _prepare(surface: Surface, camera: Camera) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """A surface ready to rasterise: its faces' corners in pixels and their shaded colours.

    The vertices are projected once, merged into pixel-sized cubes of view
    space (faces smaller than a pixel add nothing but time), and, when the
    surface encloses a volume, only the faces turned towards the viewer are
    kept: seen from outside, the others are hidden behind it.
    """
    faces = np.asarray(surface.faces, np.int64)
    pixels = project(camera, surface.vertices)
    pixels[:, 2] *= camera.scale  # depth in pixels too: cubes of one pixel
    merged, kept, keep = _merge(pixels, faces, 1.0)
    view = merged * np.array([1.0, -1.0, 1.0])  # right, up, towards the viewer
    normals = _normals(view, kept)
    colour = np.asarray(surface.colour, np.float64)
    colour = colour[keep] if colour.ndim == 2 else colour
    centre = view.mean(axis=0)
    volume = float(np.einsum("ij,ij->", view[kept[:, 0]] - centre, normals)) / 6.0
    extent = np.ptp(view, axis=0)
    if abs(volume) > 1e-3 * float(np.prod(np.maximum(extent, 1e-9))):  # closed: cull
        front = normals[:, 2] * np.sign(volume) > 0
        kept, normals = kept[front], normals[front]
        colour = colour[front] if colour.ndim == 2 else colour
    merged[:, 2] /= camera.scale
    return merged[kept], _shade(normals, colour)


def render_surfaces(
    surfaces: Sequence[Surface],
    *,
    size: tuple[int, int] = (400, 400),
    view: tuple[float, float] = DEFAULT_VIEW,
    bounds: tuple[ArrayLike, ArrayLike] | None = None,
    camera: Camera | None = None,
    outline: bool = True,
) -> Rendered:
    """Render meshes, each in its colour, shaded, at true aspect.

    Parameters
    ----------
    surfaces : sequence of Surface
        What to draw (world mm, display frame).
    size : (width, height)
        Image size, pixels (ignored with ``camera``).
    view : (elevation, azimuth)
        Degrees (ignored with ``camera``).
    bounds : (lo, hi), optional
        The box to fit, mm (default: the surfaces' bounding box).
    camera : Camera, optional
        Draw with this camera (several panels at one scale and view).
    outline : bool
        Darken silhouettes, creases in depth and the borders between surfaces.

    Returns
    -------
    Rendered
        The RGB image (white background) and its camera.
    """
    drawn = [s for s in surfaces if len(s.faces)]
    if camera is None:
        if bounds is None:
            points = (
                np.concatenate([s.vertices[np.unique(s.faces)] for s in drawn])
                if drawn
                else np.zeros((1, 3))
            )
            bounds = (points.min(axis=0), points.max(axis=0))
        camera = fit_camera(bounds[0], bounds[1], size, view=view)
    width, height = camera.size
    image = np.empty((height * width, 3), np.uint8)
    image[:] = BACKGROUND
    if not drawn:
        return Rendered(image.reshape(height, width, 3), camera)
    tris, colours, which = [], [], []
    for k, surface in enumerate(drawn):
        corners, shaded = _prepare(surface, camera)
        tris.append(corners)
        colours.append(shaded)
        which.append(np.full(len(corners), k, np.int32))
    tri = np.concatenate(tris)
    colour = np.concatenate(colours)
    owner_surface = np.concatenate(which)
    pixel, depth, face = _rasterise(tri, camera.size)
    # the depth buffer: per pixel the nearest hit (ties: the later face, deterministically)
    nearest = np.full(width * height, -np.inf, np.float32)
    np.maximum.at(nearest, pixel, depth)
    wins = depth >= nearest[pixel]
    winner = np.full(width * height, -1, np.int64)
    np.maximum.at(winner, pixel[wins], face[wins])
    pixel = np.flatnonzero(winner >= 0)
    face, depth = winner[pixel], nearest[pixel]
    image[pixel] = np.round(colour[face] * 255).astype(np.uint8)
    if outline:
        _outline(image, pixel, depth, owner_surface[face], camera)
    return Rendered(image.reshape(height, width, 3), camera)


def _outline(
    image: NDArray[np.uint8],
    pixel: NDArray[np.int64],
    depth: NDArray[np.float64],
    surface: NDArray[np.int32],
    camera: Camera,
) -> None:
    """Darken pixels at a silhouette, a jump in depth or a border between surfaces."""
    width, height = camera.size
    owner = np.full(width * height, -1, np.int32)
    owner[pixel] = surface
    z = np.full(width * height, -1e12)
    z[pixel] = depth
    owner, z = owner.reshape(height, width), z.reshape(height, width)
    edge = np.zeros((height, width), bool)
    jump = 12.0 / camera.scale  # mm: a fold that hides what lies behind it
    for axis in (0, 1):
        a = [slice(None), slice(None)]
        b = [slice(None), slice(None)]
        a[axis], b[axis] = slice(1, None), slice(None, -1)
        o1, o2 = owner[tuple(a)], owner[tuple(b)]
        differ = (o1 != o2) | (np.abs(z[tuple(a)] - z[tuple(b)]) > jump)
        differ &= (o1 >= 0) | (o2 >= 0)
        edge[tuple(a)] |= differ & (o1 >= 0)
        edge[tuple(b)] |= differ & (o2 >= 0)
    flat = image.reshape(-1, 3)
    marked = edge.reshape(-1)
    flat[marked] = (flat[marked] * 0.45).astype(np.uint8)


def nice_length(limit: float) -> float:
    """The largest 1, 2 or 5 times a power of ten that is at most ``limit`` (mm)."""
    if limit <= 0:
        return 1.0
    power = 10.0 ** math.floor(math.log10(limit))
    return max(s * power for s in (1.0, 2.0, 5.0) if s * power <= limit)


def font(size: int = 12) -> Any:
    """Pillow's default font at ``size`` pixels (its bitmap font on Pillow < 10.1)."""
    from PIL import ImageFont

    try:
        return ImageFont.load_default(size=size)
    except TypeError:  # Pillow < 10.1: one size only
        return ImageFont.load_default()


def draw_scale_bar(draw: Any, scale: float, corner: tuple[int, int], *, max_px: int) -> None:
    """A horizontal bar of a round length in mm, its left end at ``corner`` (pixels).

    Parameters
    ----------
    draw : PIL.ImageDraw.ImageDraw
    scale : float
        Pixels per mm.
    corner : (x, y)
        Left end of the bar.
    max_px : int
        Longest bar, pixels.
    """
    length = nice_length(max_px / scale)
    pixels = int(round(length * scale))
    x, y = corner
    draw.line([(x, y), (x + pixels, y)], fill=(0, 0, 0), width=2)
    draw.line([(x, y - 3), (x, y + 3)], fill=(0, 0, 0), width=1)
    draw.line([(x + pixels, y - 3), (x + pixels, y + 3)], fill=(0, 0, 0), width=1)
    draw.text((x, y + 4), f"{length:g} mm", fill=(0, 0, 0), font=font(11))


def draw_triad(
    draw: Any, rotation: NDArray[np.float64], corner: tuple[int, int], frame: str | None
) -> None:
    """The world axes as three short arrows from ``corner``, named ``x``, ``y``, ``z`` or,
    with a frame, by the anatomical direction each points to (R, A, S)."""
    names = ("R", "A", "S") if frame in ("RAS", "LPS") else ("x", "y", "z")
    colours = ((200, 40, 40), (40, 150, 40), (40, 70, 210))
    cx, cy = corner
    for axis in np.argsort(rotation[2]):  # the farthest first: the nearest arrow on top
        screen = rotation[:2, axis] * np.array([1.0, -1.0]) * 26.0
        end = (cx + screen[0], cy + screen[1])
        draw.line([(cx, cy), end], fill=colours[axis], width=3)
        away = screen / max(float(np.linalg.norm(screen)), 1e-6) * 9.0
        draw_centred(draw, (end[0] + away[0], end[1] + away[1]), names[axis], colours[axis], 13)


def draw_centred(draw: Any, xy: tuple[float, float], text: str, fill: Any, size: int) -> None:
    """Text centred on ``xy`` (pixels)."""
    face = font(size)
    left, top, right, bottom = draw.textbbox((0, 0), text, font=face)
    draw.text((xy[0] - (left + right) / 2, xy[1] - (top + bottom) / 2), text, fill=fill, font=face)
