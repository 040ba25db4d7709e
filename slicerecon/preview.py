"""A quick-look PNG of one reconstruction: ground truth vs result, parts coloured.

Row 1 shows the silhouettes of the ground truth (or, without one, the
projections the planner used) along x, y and z with the section planes marked
in red and the cuboid parts outlined. Row 2 shows the silhouettes of the
reconstructed mesh, each pixel coloured by the first part whose box it falls
in. The image is drawn with numpy and written with Pillow, so a preview costs
milliseconds and no plotting library; large grids are shown at a reduced
scale (at most :data:`MAX_PANEL_PX` pixels across a panel).
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from .io.atomic import atomic_path
from .sampling import pool_any
from .sections import AXIS_NAMES, Box, CrossSections, Projections, Volume, in_plane_axes

if TYPE_CHECKING:
    import trimesh

__all__ = ["MAX_PANEL_PX", "write_preview"]

MAX_PANEL_PX = 320
"""Largest panel side, pixels: bigger grids are rasterised at a coarser step."""

_PALETTE = np.array(
    [  # the ten "tab10" colours
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
_PLANE = np.array((214, 39, 40), dtype=np.uint8)
_TITLE_PX = 16
_GAP_PX = 8


def _step(grid_shape: tuple[int, int, int]) -> int:
    """Voxels per preview pixel, so that no panel is wider than :data:`MAX_PANEL_PX`."""
    return max(1, math.ceil(max(grid_shape) / MAX_PANEL_PX))


def _on_grid(
    volume: Volume, affine: NDArray[np.float64], shape: tuple[int, int, int]
) -> NDArray[np.bool_]:
    """A sub-grid mask (same voxel axes as ``affine``) placed on the whole grid."""
    offset = np.rint(np.linalg.solve(affine[:3, :3], volume.affine[:3, 3] - affine[:3, 3]))
    lo = offset.astype(np.int64)
    out = np.zeros(shape, dtype=bool)
    region = tuple(
        slice(max(a, 0), min(a + n, m)) for a, n, m in zip(lo, volume.shape, shape, strict=True)
    )
    source = tuple(slice(r.start - a, r.stop - a) for r, a in zip(region, lo, strict=True))
    out[region] = volume.mask[source]
    return out


def _scale_px(shape: tuple[int, ...]) -> int:
    """Integer zoom so that small panels are not tiny (about 240 pixels across)."""
    return max(1, 240 // max(max(shape), 1))


def _panel(image: NDArray[np.uint8], zoom: int) -> NDArray[np.uint8]:
    """An (rows, cols, 3) image with rows along the first grid axis, shown with that
    axis to the right and the second upwards (as ``imshow(image.T, origin="lower")``)."""
    shown = np.transpose(image, (1, 0, 2))[::-1]
    return np.repeat(np.repeat(shown, zoom, axis=0), zoom, axis=1)


def _outline(
    image: NDArray[np.uint8], lo: tuple[int, int], hi: tuple[int, int], colour: NDArray[np.uint8]
) -> None:
    """Draw a one-pixel rectangle ``[lo, hi)`` (rows, columns) on ``image`` in place."""
    r0, c0 = max(lo[0], 0), max(lo[1], 0)
    r1, c1 = min(hi[0], image.shape[0]) - 1, min(hi[1], image.shape[1]) - 1
    if r1 < r0 or c1 < c0:
        return
    image[r0 : r1 + 1, [c0, c1]] = colour
    image[[r0, r1], c0 : c1 + 1] = colour


def write_preview(
    path: str | os.PathLike[str],
    *,
    mesh: trimesh.Trimesh,
    boxes: Sequence[Box],
    planner: str,
    sections: CrossSections,
    projections: Projections,
    occupancy: Volume | None = None,
    truth: object = None,
) -> Path:
    """Write the preview image of a reconstruction to ``path`` (PNG, atomically).

    Parameters
    ----------
    path : path-like
        Output file.
    mesh : trimesh.Trimesh
        The reconstructed surface, world mm.
    boxes : sequence of Box
        The parts' boxes, in plan order.
    planner : str
        The planner's name (for the title).
    sections, projections
        What the reconstruction was made from.
    occupancy : Volume, optional
        The voxel centres inside ``mesh`` on a sub-grid of the sections' grid,
        when known (else the mesh is rasterized).
    truth : Volume or trimesh.Trimesh, optional
        Ground truth; a Volume on the sections' grid is shown in row 1 (else
        the projections are).

    Returns
    -------
    Path
        The written file.
    """
    from PIL import Image, ImageDraw

    from .rasterize import mesh_to_mask

    grid = sections.grid_shape
    step = _step(grid)
    coarse_shape = tuple(math.ceil(n / step) for n in grid)
    affine = sections.affine.copy()
    affine[:3, :3] = affine[:3, :3] * step
    affine[:3, 3] = sections.affine[:3, :3] @ np.full(3, (step - 1) / 2.0) + sections.affine[:3, 3]
    if occupancy is not None:
        recon = pool_any(_on_grid(occupancy, sections.affine, grid), step)
    else:
        recon = mesh_to_mask(mesh, affine, coarse_shape)  # type: ignore[arg-type]
    owner = np.full(coarse_shape, -1, dtype=np.int16)
    for i, box in reversed(list(enumerate(boxes))):
        owner[
            tuple(slice(lo // step, -(-hi // step)) for lo, hi in zip(box.lo, box.hi, strict=True))
        ] = i
    same_grid = (
        isinstance(truth, Volume)
        and truth.shape == tuple(grid)
        and np.allclose(truth.affine, sections.affine)
    )
    zoom = _scale_px(coarse_shape)
    coarse_truth = pool_any(truth.mask, step) if same_grid and truth is not None else None
    panels: list[list[NDArray[np.uint8]]] = [[], []]
    titles: list[list[str]] = [[], []]
    for ax_id in range(3):
        rows, cols = in_plane_axes(ax_id)
        if coarse_truth is not None:
            top = coarse_truth.any(axis=ax_id)
            label = "ground truth"
        else:
            view = projections[ax_id].image
            top = pool_any(view[:, :, None], step)[:, :, 0]
            label = f"projection ({projections.source})"
        image = np.full(top.shape + (3,), 255, dtype=np.uint8)
        image[top] = (90, 90, 90)
        if sections.axis != ax_id:
            along = 0 if sections.axis == rows else 1
            for idx in np.round(sections.indices / step).astype(np.int64):
                idx = int(np.clip(idx, 0, image.shape[along] - 1))
                if along == 0:
                    image[idx, :] = (image[idx, :] // 2 + _PLANE // 2).astype(np.uint8)
                else:
                    image[:, idx] = (image[:, idx] // 2 + _PLANE // 2).astype(np.uint8)
        for i, box in enumerate(boxes):
            _outline(
                image,
                (box.lo[rows] // step, box.lo[cols] // step),
                (-(-box.hi[rows] // step), -(-box.hi[cols] // step)),
                _PALETTE[i % len(_PALETTE)],
            )
        panels[0].append(_panel(image, zoom))
        titles[0].append(f"{label} along {AXIS_NAMES[ax_id]}")

        hit = recon.any(axis=ax_id)
        first = np.where(recon, owner, np.int16(np.iinfo(np.int16).max)).min(axis=ax_id)
        image = np.full(hit.shape + (3,), 255, dtype=np.uint8)
        known = hit & (first >= 0) & (first < len(boxes))
        image[known] = _PALETTE[first[known] % len(_PALETTE)]
        image[hit & ~known] = (77, 77, 77)
        panels[1].append(_panel(image, zoom))
        titles[1].append(f"result ({len(boxes)} parts) along {AXIS_NAMES[ax_id]}")

    widths = [
        max(max(p[i].shape[1] for p in panels), 7 * max(len(t[i]) for t in titles))
        for i in range(3)
    ]
    heights = [max(p.shape[0] for p in row) for row in panels]
    width = sum(widths) + _GAP_PX * 4
    height = sum(heights) + (_TITLE_PX + _GAP_PX) * 2 + _TITLE_PX + _GAP_PX
    canvas = Image.new("RGB", (max(width, 480), height), "white")
    draw = ImageDraw.Draw(canvas)
    draw.text(
        (_GAP_PX, 2),
        f"{sections.n_planes} planes along {AXIS_NAMES[sections.axis]} "
        f"(red lines); planner: {planner}",
        fill=(0, 0, 0),
    )
    y = _TITLE_PX + _GAP_PX
    for r in range(2):
        x = _GAP_PX
        for i in range(3):
            draw.text((x, y), titles[r][i], fill=(0, 0, 0))
            canvas.paste(Image.fromarray(panels[r][i]), (x, y + _TITLE_PX))
            x += widths[i] + _GAP_PX
        y += heights[r] + _TITLE_PX + _GAP_PX
    target = Path(path)
    with atomic_path(target) as tmp:
        canvas.save(tmp, format="PNG")
    return target
