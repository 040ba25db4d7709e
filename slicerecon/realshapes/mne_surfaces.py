"""The fsaverage scalp and inner-skull surfaces shipped with mne, voxelized."""

from __future__ import annotations

import logging
from pathlib import Path

from ..errors import DependencyError, OptionError
from ..sections import Volume
from . import installed
from .masks import voxelize_surface

logger = logging.getLogger(__name__)

MNE_SURFACES: dict[str, str] = {
    "head": "fsaverage-head.fif",
    "inner_skull": "fsaverage-inner_skull-bem.fif",
}
"""fsaverage surfaces shipped with mne: name → file in ``mne/data/fsaverage``."""


def mne_fsaverage_path(surface: str = "head") -> Path:
    """Path of an fsaverage BEM surface file inside the installed mne package.

    Raises
    ------
    OptionError
        If ``surface`` is not a key of :data:`MNE_SURFACES`.
    DependencyError
        If mne is not installed or lacks the file.
    """
    if surface not in MNE_SURFACES:
        raise OptionError(
            f"mne fsaverage surface must be one of {', '.join(MNE_SURFACES)} (got {surface!r})"
        )
    package = installed.package_dir("mne")
    if package is None:
        raise DependencyError(
            "the fsaverage head and skull surfaces come with mne, which is "
            "not installed; pip install mne"
        )
    path = package / "data" / "fsaverage" / MNE_SURFACES[surface]
    if not path.is_file():
        raise DependencyError(f"{path} is missing from the installed mne")
    return path


def mne_fsaverage_surface(
    surface: str = "head", *, resolution: int = 128, margin: int = 3
) -> Volume:
    """The fsaverage scalp or inner-skull surface shipped with mne, voxelized.

    Parameters
    ----------
    surface : {"head", "inner_skull"}, default "head"
        Outer skin (2033 vertices) or inner skull (10242 vertices); both closed.
    resolution : int, default 128
        Voxels across the surface's longest side.
    margin : int, default 3
        Background voxels around the shape.

    Returns
    -------
    Volume
        In fsaverage MRI (surface RAS) mm, world-aligned isotropic grid.

    Raises
    ------
    DependencyError, OptionError
        As :func:`mne_fsaverage_path` (mne must also be importable), and for
        an invalid ``resolution``.
    """
    path = mne_fsaverage_path(surface)
    try:
        from mne import read_bem_surfaces
    except ImportError as exc:
        raise DependencyError(f"mne cannot be imported ({exc}); pip install mne") from exc
    (bem,) = read_bem_surfaces(path, verbose=False)[:1]
    logger.info("mne fsaverage %s: %d vertices", surface, len(bem["rr"]))
    return voxelize_surface(1000.0 * bem["rr"], bem["tris"], resolution, margin)  # m -> mm
