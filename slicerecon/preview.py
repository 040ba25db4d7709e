"""A quick-look PNG of one reconstruction: ground truth vs result, parts coloured.

Row 1 shows the silhouettes of the ground truth (or, without one, the
projections the planner used) along x, y and z with the section planes marked
and the cuboid parts outlined. Row 2 shows the silhouettes of the reconstructed
mesh rasterised on the same grid, each pixel coloured by the first part whose
box it falls in. Rendering uses matplotlib's Agg backend: no display needed.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .sections import AXIS_NAMES, Volume, in_plane_axes

if TYPE_CHECKING:
    from .reconstruct import Reconstruction

__all__ = ["write_preview"]


def _part_colours(n: int) -> np.ndarray:
    from matplotlib import colormaps

    cmap = colormaps["tab10"]
    return np.array([cmap(i % 10)[:3] for i in range(max(n, 1))])


def write_preview(
    path: str | os.PathLike[str],
    result: Reconstruction,
    truth: Volume | None = None,
    *,
    dpi: int = 90,
) -> Path:
    """Write the preview figure of ``result`` to ``path`` (PNG, atomically).

    Parameters
    ----------
    path : path-like
        Output file.
    result : Reconstruction
        What :func:`slicerecon.reconstruct.reconstruct` returned.
    truth : Volume, optional
        Ground truth on any grid; shown in row 1 when its grid is the sections' grid.
    dpi : int
        Figure resolution.
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt
    from matplotlib.patches import Rectangle

    from .io.atomic import atomic_path
    from .rasterize import mesh_to_mask

    sections = result.sections
    grid_shape = sections.grid_shape
    recon = mesh_to_mask(result.mesh, sections.affine, grid_shape)
    boxes = [part.box for part in result.plan.parts]
    colours = _part_colours(len(boxes))
    owner = np.full(grid_shape, -1, dtype=np.int16)
    for i, box in reversed(list(enumerate(boxes))):
        owner[box.slices] = i
    same_grid = truth is not None and truth.shape == tuple(grid_shape) and np.allclose(
        truth.affine, sections.affine
    )

    fig, axes = plt.subplots(2, 3, figsize=(11, 7.2), constrained_layout=True)
    for ax_id in range(3):
        rows, cols = in_plane_axes(ax_id)
        top = truth.mask.any(axis=ax_id) if same_grid and truth is not None else (
            result.projections[ax_id].image
        )
        a0 = axes[0, ax_id]
        a0.imshow(top.T, origin="lower", cmap="Greys", vmin=0, vmax=1.6, interpolation="nearest")
        for i, box in enumerate(boxes):
            a0.add_patch(
                Rectangle(
                    (box.lo[rows] - 0.5, box.lo[cols] - 0.5),
                    box.shape[rows],
                    box.shape[cols],
                    fill=False,
                    lw=1.5,
                    ec=colours[i],
                )
            )
        if sections.axis != ax_id:
            line_axis = 0 if sections.axis == rows else 1
            for idx in sections.indices:
                if line_axis == 0:
                    a0.axvline(idx, color="tab:red", lw=0.6, alpha=0.6)
                else:
                    a0.axhline(idx, color="tab:red", lw=0.6, alpha=0.6)
        label = "ground truth" if same_grid else f"projection ({result.projections.source})"
        a0.set_title(f"{label}, along {AXIS_NAMES[ax_id]}", fontsize=9)

        hit = recon.any(axis=ax_id)
        first = np.where(recon, owner, np.int16(np.iinfo(np.int16).max)).min(axis=ax_id)
        image = np.ones(hit.shape + (3,))
        known = hit & (first >= 0) & (first < len(boxes))
        image[known] = colours[first[known]]
        image[hit & ~known] = (0.3, 0.3, 0.3)
        a1 = axes[1, ax_id]
        a1.imshow(np.transpose(image, (1, 0, 2)), origin="lower", interpolation="nearest")
        a1.set_title(f"reconstruction, {len(boxes)} part(s), along {AXIS_NAMES[ax_id]}",
                     fontsize=9)
        for a in (a0, a1):
            a.set_xlabel(f"{AXIS_NAMES[rows]} (voxels)", fontsize=8)
            a.set_ylabel(f"{AXIS_NAMES[cols]} (voxels)", fontsize=8)
            a.tick_params(labelsize=7)
    fig.suptitle(
        f"{sections.n_planes} planes along {AXIS_NAMES[sections.axis]} (red lines); "
        f"planner: {result.plan.planner}",
        fontsize=10,
    )
    target = Path(path)
    with atomic_path(target) as tmp:
        fig.savefig(tmp, dpi=dpi, format="png")
    plt.close(fig)
    return target
