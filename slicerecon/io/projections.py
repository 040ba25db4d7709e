"""Orthographic projections (silhouettes) read from image files.

The method takes up to three silhouettes of the shape, seen along the three
axes of the section grid. When they were acquired separately (for example
as three NIfTI images exported from a viewer, or rendered from a model),
:func:`read_projection_files` puts them on the grid of the cross-sections:

* Each file is a NIfTI image (``.nii`` / ``.nii.gz``) whose data are 2-D, or
  3-D with exactly one axis of length 1. Its affine places it in world mm;
  the viewing direction is the world direction of its missing (length-1)
  axis, i.e. the image plane's normal.
* That direction must be parallel, within 0.5°, to one axis of the section
  grid; each grid axis takes at most one file. Non-zero pixels are the
  silhouette.
* Each pixel of the grid's view plane is mapped through the affines to the
  nearest pixel of the file (nearest neighbour; outside the image counts as
  background), so files of any resolution and extent can be combined.
* A grid axis without a file gets the view derived from the sections
  (:func:`slicerecon.sampling.projections_from_sections`).
"""

from __future__ import annotations

import logging
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ..errors import EmptyMaskError, FormatError, GeometryError, InputError
from ..sampling import projections_from_sections
from ..sections import AXIS_NAMES, CrossSections, Projection, Projections, in_plane_axes

__all__ = ["PARALLEL_TOLERANCE_DEG", "read_projection_files"]

logger = logging.getLogger(__name__)

PARALLEL_TOLERANCE_DEG = 0.5
"""Largest angle between a file's viewing direction and a grid axis."""


def _load(path: Path) -> tuple[NDArray[np.bool_], NDArray[np.float64], int]:
    """Silhouette as a 3-D array with one length-1 axis, its affine and that axis."""
    import nibabel as nib

    if not path.is_file():
        raise InputError(f"projection file not found: {path}")
    try:
        image: Any = nib.load(str(path))
        data = np.asarray(image.dataobj)
    except Exception as exc:  # nibabel raises many types for bad files
        raise FormatError(f"{path}: cannot read it as a NIfTI image ({exc})") from exc
    if data.ndim == 2:
        data = data[:, :, None]
    if data.ndim == 4 and data.shape[3] == 1:
        data = data[..., 0]
    flat = [a for a in range(3) if data.shape[a] == 1] if data.ndim == 3 else []
    if len(flat) != 1:
        raise FormatError(
            f"{path}: a projection must be a 2-D image (or 3-D with one axis of length 1); "
            f"got shape {data.shape}"
        )
    if not np.all(np.isfinite(data)):
        raise FormatError(f"{path}: the projection holds NaN or infinite values")
    mask = data != 0
    if not mask.any():
        raise EmptyMaskError(f"{path}: the projection is empty (no non-zero pixel)")
    return mask, np.asarray(image.affine, dtype=np.float64), flat[0]


def read_projection_files(
    paths: Sequence[str | os.PathLike[str]], sections: CrossSections
) -> Projections:
    """Read up to three silhouette images onto the grid of ``sections``.

    Parameters
    ----------
    paths : sequence of path-like
        One to three NIfTI silhouettes (see the module docstring).
    sections : CrossSections
        The cross-sections whose grid the projections are placed on.

    Returns
    -------
    Projections
        ``source="file"`` (views without a file are derived from the sections).

    Raises
    ------
    InputError
        No file, more than three, or a missing file.
    FormatError
        A file that is not a 2-D NIfTI silhouette.
    GeometryError
        A viewing direction not parallel to a grid axis, or two files for
        one axis.
    EmptyMaskError
        A silhouette without foreground.
    """

    files = [Path(p) for p in paths]
    if not 1 <= len(files) <= 3:
        raise InputError(f"give one to three projection files (got {len(files)})")
    grid_affine = sections.affine
    grid_dirs = grid_affine[:3, :3] / np.linalg.norm(grid_affine[:3, :3], axis=0)
    cos_tol = np.cos(np.deg2rad(PARALLEL_TOLERANCE_DEG))
    derived = projections_from_sections(sections)
    views: list[Projection] = list(derived.views)
    taken: dict[int, Path] = {}
    for path in files:
        mask, affine, flat = _load(path)
        normal = affine[:3, flat] / np.linalg.norm(affine[:3, flat])
        cosines = np.abs(grid_dirs.T @ normal)
        axis = int(np.argmax(cosines))
        if cosines[axis] < cos_tol:
            angle = float(np.rad2deg(np.arccos(min(1.0, cosines[axis]))))
            raise GeometryError(
                f"{path}: its viewing direction is {angle:.2f} degrees off the nearest grid "
                f"axis ({AXIS_NAMES[axis]}); projections must look along a grid axis"
            )
        if axis in taken:
            raise GeometryError(
                f"{path} and {taken[axis]} both look along {AXIS_NAMES[axis]}; give one per axis"
            )
        taken[axis] = path
        rows, cols = in_plane_axes(axis)
        shape = (sections.grid_shape[rows], sections.grid_shape[cols])
        index = np.zeros((shape[0], shape[1], 3))
        index[..., rows] = np.arange(shape[0])[:, None]
        index[..., cols] = np.arange(shape[1])[None, :]
        world = index @ grid_affine[:3, :3].T + grid_affine[:3, 3]
        inverse = np.linalg.inv(affine)
        pixel = np.rint(world @ inverse[:3, :3].T + inverse[:3, 3]).astype(np.int64)
        pixel[..., flat] = 0
        inside = np.all((pixel >= 0) & (pixel < np.array(mask.shape)), axis=-1)
        image = np.zeros(shape, dtype=bool)
        image[inside] = mask[tuple(pixel[inside].T)]
        if not image.any():
            raise EmptyMaskError(
                f"{path}: the silhouette does not overlap the sections' grid; check its affine"
            )
        views[axis] = Projection(image, axis, grid_affine)
        logger.info("projection along %s from %s", AXIS_NAMES[axis], path)
    return Projections((views[0], views[1], views[2]), source="file")
