"""Organs of the segmented frog in pyvista's example data (``frog_tissues.vti``)."""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from ..errors import DependencyError, EmptyMaskError, OptionError
from ..io.vti import read_vti
from ..sections import Volume
from . import installed
from .installed import REAL_EXTRA
from .masks import check_fraction, check_resolution, crop, drop_specks, fit

logger = logging.getLogger(__name__)

FROG_TISSUES: dict[str, int] = {
    "blood": 1,
    "brain": 2,
    "duodenum": 3,
    "eye_retina": 4,
    "eye_white": 5,
    "heart": 6,
    "ileum": 7,
    "kidney": 8,
    "l_intestine": 9,
    "liver": 10,
    "lung": 11,
    "nerve": 12,
    "skeleton": 13,
    "spleen": 14,
    "stomach": 15,
}
"""Frog tissue name → label value in ``frog_tissues.vti`` (the VTK examples' frog labels)."""


def frog_tissues_path() -> Path:
    """Path of ``frog_tissues.vti`` inside the installed pyvista package.

    Raises
    ------
    DependencyError
        If pyvista is not installed or its version lacks the file (< 0.44).
    """
    package = installed.package_dir("pyvista")
    if package is None:
        raise DependencyError(
            "the frog organs come from pyvista's example data, and pyvista is not "
            f"installed; {REAL_EXTRA} (or pip install --no-deps 'pyvista>=0.44': "
            "slicerecon reads the file without importing pyvista or VTK)"
        )
    path = package / "examples" / "frog_tissues.vti"
    if not path.is_file():
        raise DependencyError(
            f"{path} is missing: the installed pyvista predates 0.44; "
            "pip install --no-deps 'pyvista>=0.44'"
        )
    return path


def frog_tissue(
    tissue: str,
    *,
    path: str | Path | None = None,
    resolution: int | None = None,
    min_fraction: float = 0.05,
    margin: int = 3,
) -> Volume:
    """One organ of the segmented frog in pyvista's ``frog_tissues.vti``.

    Parameters
    ----------
    tissue : str
        A key of :data:`FROG_TISSUES` (e.g. ``"heart"``, ``"liver"``, ``"lung"``).
    path : path-like, optional
        A ``.vti`` label map with the same labels. Default: the file inside
        the installed pyvista (:func:`frog_tissues_path`).
    resolution : int, optional
        Downsample (majority of ``f³`` blocks) so that the organ's largest
        extent spans at most about ``resolution`` voxels.
    min_fraction : float, default 0.05
        Drop 26-connected pieces smaller than this fraction of the organ's
        largest piece (segmentation specks); 0 keeps all, 1 keeps only the
        largest. Applied at full resolution.
    margin : int, default 3
        Background voxels kept around the organ (the grid is cropped).

    Returns
    -------
    Volume
        In the file's coordinates (voxels 1 × 1 × 1.5, taken as mm).

    Raises
    ------
    DependencyError
        If ``path`` is None and pyvista (>= 0.44) is not installed.
    OptionError
        If ``tissue``, ``min_fraction`` or ``resolution`` is invalid.
    LabelError, FormatError, InputError
        From :func:`slicerecon.io.vti.read_vti`.
    EmptyMaskError
        If the organ's label is absent from the file.
    """

    if tissue not in FROG_TISSUES:
        raise OptionError(
            f"unknown frog tissue {tissue!r}; choose one of {', '.join(FROG_TISSUES)}"
        )
    fraction = check_fraction(min_fraction)
    res = check_resolution(resolution)
    image = read_vti(frog_tissues_path() if path is None else path)
    mask = image.values == FROG_TISSUES[tissue]
    if not mask.any():
        raise EmptyMaskError(f"label {FROG_TISSUES[tissue]} ({tissue}) is absent from the file")
    volume = crop(Volume(mask, image.affine), margin)  # small grid before labelling
    volume = drop_specks(volume, fraction, margin)
    logger.info("frog %s: %d voxels", tissue, int(np.count_nonzero(volume.mask)))
    return fit(volume, res, margin)
