"""Real shapes shipped with nilearn: the MNI152 masks and the fsaverage5 surfaces."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import DependencyError, OptionError
from ..sections import Volume
from . import installed
from .installed import REAL_EXTRA
from .masks import check_resolution, fit, voxelize_surface

logger = logging.getLogger(__name__)

MNI152_TISSUES: tuple[str, ...] = ("brain", "gm", "wm")
"""MNI152 masks: whole brain, grey matter, white matter."""

FSAVERAGE5_SURFACES: tuple[str, ...] = ("pial", "white")
"""fsaverage5 surfaces registered as real shapes (both closed, per hemisphere)."""

HEMISPHERES: tuple[str, ...] = ("left", "right")
"""Hemisphere names used in real-shape names."""


def mni152(tissue: str = "brain", *, resolution: int | None = None, margin: int = 3) -> Volume:
    """The MNI152 (2009a) brain, grey-matter or white-matter mask shipped with nilearn.

    Parameters
    ----------
    tissue : {"brain", "gm", "wm"}, default "brain"
        Whole-brain, grey-matter or white-matter mask (nilearn's template
        probability maps thresholded at 0.2).
    resolution : int, optional
        Downsample (majority of ``f³`` blocks, integer ``f``) so that the
        largest extent spans at most about ``resolution`` voxels. Default:
        nilearn's 1 mm grid.
    margin : int, default 3
        Background voxels kept around the mask (the grid is cropped).

    Returns
    -------
    Volume
        In MNI space (RAS+ mm).

    Raises
    ------
    DependencyError
        If nilearn is not installed.
    OptionError
        If ``tissue`` or ``resolution`` is invalid.
    """
    if tissue not in MNI152_TISSUES:
        raise OptionError(
            f"MNI152 tissue must be one of {', '.join(MNI152_TISSUES)} (got {tissue!r})"
        )
    res = check_resolution(resolution)
    try:
        from nilearn import datasets
    except ImportError as exc:
        raise DependencyError(
            f"the MNI152 masks come with nilearn, which is not installed; {REAL_EXTRA} "
            "(or pip install nilearn)"
        ) from exc
    loader = {
        "brain": datasets.load_mni152_brain_mask,
        "gm": datasets.load_mni152_gm_mask,
        "wm": datasets.load_mni152_wm_mask,
    }[tissue]
    img = loader()
    volume = Volume(np.asarray(img.dataobj) > 0, np.asarray(img.affine, dtype=np.float64))
    logger.info("loaded nilearn MNI152 %s mask %s", tissue, volume.shape)
    return fit(volume, res, margin)


def fsaverage5_path(surface: str = "pial", hemi: str = "left") -> Path:
    """Path of an fsaverage5 surface (GIfTI) inside the installed nilearn package.

    Parameters
    ----------
    surface : {"pial", "white"}, default "pial"
    hemi : {"left", "right"}, default "left"

    Raises
    ------
    OptionError
        If ``surface`` or ``hemi`` is unknown.
    DependencyError
        If nilearn is not installed or lacks the file.
    """
    if surface not in FSAVERAGE5_SURFACES:
        raise OptionError(
            f"fsaverage5 surface must be one of {', '.join(FSAVERAGE5_SURFACES)} (got {surface!r})"
        )
    if hemi not in HEMISPHERES:
        raise OptionError(f"hemi must be one of {', '.join(HEMISPHERES)} (got {hemi!r})")
    package = installed.package_dir("nilearn")
    if package is None:
        raise DependencyError(
            f"the fsaverage5 surfaces come with nilearn, which is not installed; {REAL_EXTRA} "
            "(or pip install nilearn)"
        )
    path = package / "datasets" / "data" / "fsaverage5" / f"{surface}_{hemi}.gii.gz"
    if not path.is_file():
        raise DependencyError(f"{path} is missing: this nilearn ships without fsaverage5")
    return path


def fsaverage5_surface(
    surface: str = "pial", hemi: str = "left", *, resolution: int = 128, margin: int = 3
) -> Volume:
    """One hemisphere's fsaverage5 pial or white surface (nilearn's package data), voxelized.

    Parameters
    ----------
    surface : {"pial", "white"}, default "pial"
        Outer (pial) or grey/white boundary surface; both are closed
        (10242 vertices, 20480 triangles).
    hemi : {"left", "right"}, default "left"
    resolution : int, default 128
        Voxels across the surface's longest side (isotropic voxels, about
        1.4 mm for a pial surface).
    margin : int, default 3
        Background voxels around the shape.

    Returns
    -------
    Volume
        In fsaverage (MNI305) mm, world-aligned isotropic grid.

    Raises
    ------
    DependencyError, OptionError
        As :func:`fsaverage5_path`, and for an invalid ``resolution``.
    """
    import nibabel as nib

    path = fsaverage5_path(surface, hemi)
    gifti: Any = nib.load(path)  # a GiftiImage
    vertices = next(
        a.data
        for a in gifti.darrays
        if a.data.ndim == 2 and a.data.shape[1] == 3 and np.issubdtype(a.data.dtype, np.floating)
    )
    faces = next(a.data for a in gifti.darrays if np.issubdtype(a.data.dtype, np.integer))
    logger.info("fsaverage5 %s %s: %d vertices", surface, hemi, len(vertices))
    return voxelize_surface(vertices, faces, resolution, margin)
