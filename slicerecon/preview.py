"""The quick-look PNG of a case: the result in 3-D beside the annotated planes.

Left, a 3-D render of the result (:mod:`slicerecon.render`, the renderer of
the HTML report too): every structure in its colour (the colour of
``labels.seg.nrrd``), in world millimetres at true aspect, seen from the
patient's front left (LPS inputs are turned to match), with the annotated
planes drawn as thin outlines, an orientation triad (R, A, S) and a scale
bar; for one structure, the planner's parts as coloured boxes. Right, up to
six of the annotated planes, evenly chosen: on each, the result's section
filled lightly in each structure's colour and the annotation drawn over it as
a dark contour, in mm at true aspect with a scale bar. Where the result
follows the drawing, the contour hugs the fill.

The whole image is drawn with numpy and Pillow: a 256³ case's preview takes a
few tenths of a second.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
from numpy.typing import NDArray

from .io.atomic import atomic_path
from .labels import Structure, structure_colour
from .render import (
    Surface,
    draw_centred,
    draw_scale_bar,
    draw_triad,
    fit_camera,
    font,
    project,
    render_surfaces,
    to_display_frame,
)
from .sections import AXIS_NAMES, Box, CrossSections, in_plane_axes

if TYPE_CHECKING:
    import trimesh

__all__ = [
    "MAX_PLANES_SHOWN",
    "SINGLE_COLOUR",
    "PreviewStructure",
    "display_colour",
    "write_preview",
]

MAX_PLANES_SHOWN = 6
"""Annotated planes shown beside the 3-D view (evenly chosen among all)."""

_PARTS = np.array(
    [  # the ten "tab10" colours: the planner's parts
        (31, 119, 180),
        (255, 127, 14),
        (44, 160, 44),
        (214, 39, 40),
        (148, 103, 189),
        (140, 86, 75),
        (227, 119, 194),
        (127, 127, 127),
        (188, 189, 34),
        (23, 190, 207),
    ],
    dtype=np.uint8,
)
_VIEW_PX = 440
_PLANE_PX = (176, 176)
_TITLE_PX = 22
_GAP_PX = 10
_CAPTION_PX = 14
_LEGEND_ROW_PX = 14
_BOX_EDGES = [(i, j) for i in range(8) for j in range(i + 1, 8) if bin(i ^ j).count("1") == 1]
"""Pairs of box corners (numbered by their lo/hi bits) that an edge joins."""
SINGLE_COLOUR = (242, 150, 80)
"""A single structure without its own colour is drawn in this warm tone."""


def display_colour(structure: Structure, index: int, count: int) -> tuple[int, int, int]:
    """The colour a structure is drawn in, in previews and reports alike.

    Its own colour, else the ``index``-th of the palette of every written
    segmentation (:func:`slicerecon.labels.structure_colour`); the one
    structure of a case without a colour of its own is drawn in
    :data:`SINGLE_COLOUR`.
    """
    if count == 1 and structure.colour is None:
        return SINGLE_COLOUR
    return structure_colour(structure, index)


class PreviewStructure(NamedTuple):
    """One structure as the preview shows it.

    Attributes
    ----------
    value : int
        Its value in ``result`` (the reconstructed label map).
    name : str
        Its ``<value>_<name>`` (legend).
    colour : tuple of 3 int
        RGB 0-255.
    mesh : trimesh.Trimesh or None
        The reconstructed surface, world mm (None: not reconstructed).
    annotated : ndarray of shape (P, A, B), bool, or None
        Its masks on the planes of ``sections`` (None: it is on none of them).
    """

    value: int
    name: str
    colour: tuple[int, int, int]
    mesh: trimesh.Trimesh | None
    annotated: NDArray[np.bool_] | None


def _plane_outlines(sections: CrossSections) -> list[NDArray[np.float64]]:
    """World corners (4, 3) of each annotated plane's grid rectangle."""
    a, b = in_plane_axes(sections.axis)
    shape = sections.grid_shape
    out = []
    for index in sections.indices:
        ijk = np.zeros((4, 3))
        ijk[:, sections.axis] = float(index)
        ijk[:, a] = [-0.5, shape[a] - 0.5, shape[a] - 0.5, -0.5]
        ijk[:, b] = [-0.5, -0.5, shape[b] - 0.5, shape[b] - 0.5]
        out.append(ijk @ sections.affine[:3, :3].T + sections.affine[:3, 3])
    return out


def _box_corners(box: Box, affine: NDArray[np.float64]) -> NDArray[np.float64]:
    lo = np.asarray(box.lo, np.float64) - 0.5
    hi = np.asarray(box.hi, np.float64) - 0.5
    ijk = np.array([[(lo, hi)[(c >> k) & 1][k] for k in range(3)] for c in range(8)])
    return ijk @ affine[:3, :3].T + affine[:3, 3]


def _three_d(
    structures: Sequence[PreviewStructure],
    sections: CrossSections | None,
    frame: str | None,
    boxes: Sequence[Box],
    box_affine: NDArray[np.float64] | None,
) -> NDArray[np.uint8]:
    """The 3-D panel: structures, plane outlines, parts, triad and scale bar."""
    from PIL import Image, ImageDraw

    single = len(structures) == 1
    surfaces = []
    for item in structures:
        if item.mesh is None or len(item.mesh.faces) == 0:
            continue
        colour = np.asarray(item.colour, np.float64) / 255.0
        vertices = to_display_frame(np.asarray(item.mesh.vertices), frame)
        surfaces.append(Surface(vertices, np.asarray(item.mesh.faces, np.int64), colour))
    outlines = (
        [] if sections is None else [to_display_frame(c, frame) for c in _plane_outlines(sections)]
    )
    if surfaces:
        points = np.concatenate([s.vertices for s in surfaces])
    elif outlines:
        points = np.concatenate(outlines)
    else:
        points = np.zeros((1, 3))
    lo, hi = points.min(axis=0), points.max(axis=0)
    pad = 0.04 * float(np.max(hi - lo))
    camera = fit_camera(lo - pad, hi + pad, (_VIEW_PX, _VIEW_PX), margin=26)
    rendered = render_surfaces(surfaces, camera=camera)
    image = Image.fromarray(rendered.image).convert("RGBA")
    overlay = Image.new("RGBA", image.size, (0, 0, 0, 0))
    draw = ImageDraw.Draw(overlay)
    # the annotated planes, clipped to the shape's extent along their own directions
    for corners in outlines:
        clipped = np.clip(corners, lo - pad, hi + pad)
        xy = project(camera, clipped)[:, :2]
        draw.polygon([tuple(p) for p in xy], outline=(200, 30, 30, 150))
    if single and box_affine is not None:
        for i, box in enumerate(boxes):
            corners = to_display_frame(_box_corners(box, box_affine), frame)
            xy = project(camera, corners)[:, :2]
            colour = tuple(int(c) for c in _PARTS[i % len(_PARTS)]) + (200,)
            for p, q in _BOX_EDGES:
                draw.line([tuple(xy[p]), tuple(xy[q])], fill=colour, width=1)
    image = Image.alpha_composite(image, overlay).convert("RGB")
    draw = ImageDraw.Draw(image)
    draw_triad(draw, camera.rotation, (40, _VIEW_PX - 38), frame)
    draw_scale_bar(draw, camera.scale, (_VIEW_PX - 130, _VIEW_PX - 22), max_px=110)
    return np.asarray(image)


_LETTERS = (("R", "L"), ("A", "P"), ("S", "I"))
"""The anatomical direction of +x, +y, +z (RAS) and of the opposite side."""


class _Orientation(NamedTuple):
    """How a plane is shown: its grid axes across and up, flips, and the edge letters."""

    across: int
    up: int
    flip_across: bool
    flip_up: bool
    letters: tuple[str, str, str, str]  # left, right, top, bottom


def _orientation(sections: CrossSections, frame: str | None) -> _Orientation:
    """Radiological display of the annotated planes, as a clinician reads them.

    Axial planes: the patient's right on the left, anterior at the top; coronal:
    right on the left, superior up; sagittal: anterior on the left, superior up.
    """
    a, b = in_plane_axes(sections.axis)
    directions = to_display_frame(sections.affine[:3, :3].T, frame)  # row i: index axis i
    normal = int(np.argmax(np.abs(directions[sections.axis])))
    prefer = 1 if normal == 0 else 0  # across: world y on sagittal planes, else world x
    across = a if abs(directions[a][prefer]) >= abs(directions[b][prefer]) else b
    up = b if across == a else a
    world_across = int(np.argmax(np.abs(directions[across])))
    world_up = int(np.argmax(np.abs(directions[up])))
    flip_across = bool(directions[across][world_across] > 0)  # + (R or A) to the left
    flip_up = bool(directions[up][world_up] > 0)  # + (A or S) to the top
    left, right = _LETTERS[world_across]
    top, bottom = _LETTERS[world_up]
    if frame not in ("RAS", "LPS"):
        left, right, top, bottom = "", "", "", ""
    return _Orientation(across, up, flip_across, flip_up, (left, right, top, bottom))


def _plane_panel(
    structures: Sequence[PreviewStructure],
    result: NDArray[np.integer],
    sections: CrossSections,
    row: int,
    scale: float,
    shown: _Orientation,
) -> NDArray[np.uint8]:
    """One annotated plane: the result's section filled, the annotation's contour over it."""
    from PIL import Image
    from scipy import ndimage

    axis = sections.axis
    a, _ = in_plane_axes(axis)
    index = int(np.clip(round(float(sections.indices[row])), 0, result.shape[axis] - 1))
    section = np.take(result, index, axis=axis)  # (A, B)
    spacing = np.linalg.norm(sections.affine[:3, :3], axis=0)
    size = (
        max(1, round(result.shape[shown.across] * spacing[shown.across] * scale)),
        max(1, round(result.shape[shown.up] * spacing[shown.up] * scale)),
    )

    def resize(plane: NDArray) -> NDArray:
        image = plane.T if shown.across == a else plane  # rows: up, columns: across
        if shown.flip_across:
            image = image[:, ::-1]
        if shown.flip_up:
            image = image[::-1]
        image = np.ascontiguousarray(image).astype(np.uint8)
        return np.asarray(Image.fromarray(image).resize(size, Image.Resampling.NEAREST))

    image = np.full((size[1], size[0], 3), 255, np.uint8)
    for item in structures:
        colour = np.asarray(item.colour, np.float64)
        filled = resize(section == item.value).astype(bool)
        image[filled] = np.round(255 - 0.4 * (255 - colour)).astype(np.uint8)
    for item in structures:
        if item.annotated is None or not item.annotated[row].any():
            continue
        drawn = resize(item.annotated[row]).astype(bool)
        contour = drawn & ~ndimage.binary_erosion(drawn, iterations=2, border_value=0)
        image[contour] = np.round(np.asarray(item.colour, np.float64) * 0.55).astype(np.uint8)
    return image


def _legend(structures: Sequence[PreviewStructure], width: int) -> list[tuple[str, tuple]]:
    entries = [(item.name or str(item.value), item.colour) for item in structures]
    per_row = max(1, width // 140)
    rows = 3 * per_row
    if len(entries) > rows:
        entries = entries[: rows - 1] + [(f"+{len(entries) - rows + 1} more", (255, 255, 255))]
    return entries


def write_preview(
    path: str | os.PathLike[str],
    *,
    structures: Sequence[PreviewStructure],
    sections: CrossSections | None,
    result: NDArray[np.integer],
    title: str,
    frame: str | None = None,
    boxes: Sequence[Box] = (),
    box_affine: NDArray[np.float64] | None = None,
) -> Path:
    """Write the preview image of a case to ``path`` (PNG, atomically).

    Parameters
    ----------
    path : path-like
        Output file.
    structures : sequence of PreviewStructure
        Every structure, in order (colours, meshes, annotated masks).
    sections : CrossSections or None
        The annotated planes of every structure together, on the grid of
        ``result``; None when no annotated plane is a slice of that grid
        (oblique planes): the preview is then the 3-D view alone.
    result : ndarray of shape (I, J, K), integer
        The reconstructed label map (each structure's value) on the sections' grid.
    title : str
        The first line (what was read and made).
    frame : {"RAS", "LPS"} or None
        The world frame of the meshes and of ``sections.affine``.
    boxes : sequence of Box
        The planner's parts of a single structure (voxel index boxes).
    box_affine : ndarray of shape (4, 4), optional
        Voxel index → world mm of ``boxes``.

    Returns
    -------
    Path
        The written file.
    """
    from PIL import Image, ImageDraw

    view = _three_d(structures, sections, frame, boxes, box_affine)
    n_planes = 0 if sections is None else sections.n_planes
    chosen = (
        np.unique(np.linspace(0, n_planes - 1, min(n_planes, MAX_PLANES_SHOWN)).round()).astype(int)
        if n_planes
        else np.zeros(0, int)
    )
    panels = []
    if sections is not None:
        shown = _orientation(sections, frame)
        spacing = np.linalg.norm(sections.affine[:3, :3], axis=0)
        extent = np.array(
            [result.shape[i] * spacing[i] for i in (shown.across, shown.up)], dtype=np.float64
        )
        scale = float(min(_PLANE_PX[0] / extent[0], _PLANE_PX[1] / extent[1]))
        panels = [_plane_panel(structures, result, sections, int(r), scale, shown) for r in chosen]
    columns = 3 if len(panels) > 4 else 2 if len(panels) > 1 else 1
    cell_w, cell_h = _PLANE_PX[0] + _GAP_PX, _PLANE_PX[1] + _CAPTION_PX + 16 + _GAP_PX
    n_rows = math.ceil(len(panels) / columns) if panels else 0
    width = _GAP_PX + _VIEW_PX + _GAP_PX + columns * cell_w
    legend = _legend(structures, width - 2 * _GAP_PX)
    per_row = max(1, (width - 2 * _GAP_PX) // 140)
    legend_h = math.ceil(len(legend) / per_row) * _LEGEND_ROW_PX + _GAP_PX
    height = _TITLE_PX + max(_VIEW_PX, n_rows * cell_h) + legend_h + _GAP_PX
    canvas = Image.new("RGB", (width, height), "white")
    draw = ImageDraw.Draw(canvas)
    draw.text((_GAP_PX, 4), title, fill=(0, 0, 0), font=font(13))
    canvas.paste(Image.fromarray(view), (_GAP_PX, _TITLE_PX))
    draw.text(
        (_GAP_PX + 4, _TITLE_PX + 4),
        f"3-D, world mm, true aspect; red: the {n_planes} annotated planes"
        if sections is not None
        else "3-D, world mm, true aspect (the annotated planes are oblique to the grid)",
        fill=(90, 90, 90),
        font=font(11),
    )
    left = 2 * _GAP_PX + _VIEW_PX
    for k, (row, panel) in enumerate(zip(chosen, panels, strict=True)):
        assert sections is not None
        x = left + (k % columns) * cell_w
        y = _TITLE_PX + (k // columns) * cell_h
        position = float(sections.positions[row])
        draw.text(
            (x, y),
            f"plane {row + 1}/{n_planes}: {AXIS_NAMES[sections.axis]} = {position:.1f} mm",
            fill=(0, 0, 0),
            font=font(11),
        )
        top = y + _CAPTION_PX
        canvas.paste(Image.fromarray(panel), (x, top))
        draw.rectangle(
            [x - 1, top - 1, x + panel.shape[1], top + panel.shape[0]], outline=(180, 180, 180)
        )
        left_, right_, top_, bottom_ = shown.letters
        h, w = panel.shape[:2]
        for text, at in (
            (left_, (x + 6, top + h / 2)),
            (right_, (x + w - 6, top + h / 2)),
            (top_, (x + w / 2, top + 7)),
            (bottom_, (x + w / 2, top + h - 7)),
        ):
            if text:
                draw_centred(draw, at, text, (120, 120, 120), 11)
        if k == 0:
            draw_scale_bar(draw, scale, (x + 4, top + panel.shape[0] + 6), max_px=70)
    if panels:
        draw.text(
            (left, _TITLE_PX + n_rows * cell_h - 4),
            "fill: the result's section; contour: the annotation",
            fill=(90, 90, 90),
            font=font(11),
        )
    y0 = _TITLE_PX + max(_VIEW_PX, n_rows * cell_h) + 4
    for k, (name, colour) in enumerate(legend):
        x = _GAP_PX + (k % per_row) * 140
        y = y0 + (k // per_row) * _LEGEND_ROW_PX
        draw.rectangle([x, y + 2, x + 10, y + 11], fill=tuple(colour), outline=(60, 60, 60))
        draw.text((x + 14, y), name[:20], fill=(0, 0, 0), font=font(11))
    target = Path(path)
    with atomic_path(target) as tmp:
        canvas.save(tmp, format="PNG", optimize=False)
    return target
