"""Readers and writers: one entry point for every supported input.

:func:`load_input` looks at a path and returns what it holds:

* a dense :class:`~slicerecon.sections.Volume` for NIfTI label maps, DICOM
  image series of a mask, DICOM SEG files and closed meshes (voxelised);
* sparse :class:`~slicerecon.sections.CrossSections` for contour files
  (JSON / CSV) and DICOM RTSTRUCT.

Format modules are imported on first use, so a missing optional dependency only
fails the format that needs it.
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import FormatError, InputError
from ..sections import CrossSections, Volume

__all__ = ["InputKind", "detect_kind", "load_input", "MESH_SUFFIXES", "NIFTI_SUFFIXES"]

logger = logging.getLogger(__name__)

NIFTI_SUFFIXES = (".nii", ".nii.gz")
MESH_SUFFIXES = (".stl", ".ply", ".obj", ".off")
CONTOUR_SUFFIXES = (".json", ".csv")
DICOM_SUFFIXES = (".dcm", ".dicom", "")


@dataclass(frozen=True)
class InputKind:
    """What a path holds.

    Attributes
    ----------
    kind : str
        One of ``"nifti"``, ``"vti"``, ``"dicom-series"``, ``"dicom-seg"``, ``"rtstruct"``,
        ``"contours"``, ``"mesh"``.
    path : Path
        The file or directory itself.
    image_dir : Path or None
        For an RTSTRUCT lying in a directory beside its image series: that directory.
    """

    kind: str
    path: Path
    image_dir: Path | None = None

    @property
    def is_sparse(self) -> bool:
        """True for inputs that hold only some planes (contours)."""
        return self.kind in ("rtstruct", "contours")


def _suffix(path: Path) -> str:
    name = path.name.lower()
    return ".nii.gz" if name.endswith(".nii.gz") else path.suffix.lower()


def _dicom_modality(path: Path) -> str | None:
    import pydicom
    from pydicom.errors import InvalidDicomError

    try:
        ds = pydicom.dcmread(
            path, stop_before_pixels=True, specific_tags=["Modality", "SOPClassUID"]
        )
    except (InvalidDicomError, OSError, ValueError, EOFError):
        return None
    modality = str(getattr(ds, "Modality", "") or "")
    if str(getattr(ds, "SOPClassUID", "")) == "1.2.840.10008.5.1.4.1.1.66.4":
        return "SEG"
    return modality or "UNKNOWN"


def detect_kind(path: str | os.PathLike[str]) -> InputKind:
    """Tell what kind of input ``path`` is, without reading pixel data.

    Raises
    ------
    InputError
        If the path does not exist or its kind cannot be told.
    """
    p = Path(path)
    if not p.exists():
        raise InputError(f"input not found: {p}")
    if p.is_dir():
        files = sorted(f for f in p.iterdir() if f.is_file() and not f.name.startswith("."))
        if not files:
            raise InputError(f"directory {p} is empty: expected a DICOM series")
        rtstructs = [f for f in files if _dicom_modality(f) == "RTSTRUCT"]
        if len(rtstructs) == 1:
            return InputKind("rtstruct", rtstructs[0], image_dir=p)
        if len(rtstructs) > 1:
            raise InputError(
                f"directory {p} holds {len(rtstructs)} RTSTRUCT files; pass one of them"
            )
        return InputKind("dicom-series", p)
    suffix = _suffix(p)
    if suffix in NIFTI_SUFFIXES:
        return InputKind("nifti", p)
    if suffix in MESH_SUFFIXES:
        return InputKind("mesh", p)
    if suffix == ".vti":
        return InputKind("vti", p)
    if suffix in CONTOUR_SUFFIXES:
        return InputKind("contours", p)
    modality = _dicom_modality(p)
    if modality == "SEG":
        return InputKind("dicom-seg", p)
    if modality == "RTSTRUCT":
        return InputKind("rtstruct", p)
    if modality is not None:
        raise InputError(
            f"{p} is a single DICOM {modality} image; pass the directory of its series"
        )
    raise FormatError(
        f"cannot tell the format of {p}: expected .nii/.nii.gz, a DICOM series directory, "
        "a DICOM SEG or RTSTRUCT file, a contour file (.json/.csv), a VTK image (.vti) "
        "or a mesh (.stl/.ply/.obj/.off)"
    )


def load_input(
    path: str | os.PathLike[str],
    *,
    label: int | None = None,
    roi: int | str | None = None,
    image_dir: str | os.PathLike[str] | None = None,
    allow_irregular: bool = False,
    mesh_resolution: int = 128,
    pixel_spacing: float | None = None,
) -> Volume | CrossSections:
    """Read any supported input.

    Parameters
    ----------
    path : path-like
        NIfTI file, DICOM series directory, DICOM SEG / RTSTRUCT file, contour
        file (``.json`` / ``.csv``) or closed mesh (``.stl`` / ``.ply`` /
        ``.obj`` / ``.off``).
    label : int, optional
        Label value (NIfTI, DICOM series) or segment number (SEG) to keep;
        default: every non-zero voxel / the only segment.
    roi : int or str, optional
        RTSTRUCT ROI number or name; default: the only ROI.
    image_dir : path-like, optional
        The image series an RTSTRUCT refers to; its grid is then used.
    allow_irregular : bool
        Accept DICOM series with uneven slice spacing (see docs/formats.md).
    mesh_resolution : int
        Voxels along the longest side when a mesh is voxelised.
    pixel_spacing : float, optional
        In-plane pixel size, mm, for contour inputs without an image grid.

    Returns
    -------
    Volume or CrossSections
        A dense mask, or the annotated planes of a sparse input.
    """
    kind = detect_kind(path)
    logger.info("reading %s as %s", kind.path, kind.kind)
    if kind.kind == "nifti":
        from .nifti import read_nifti

        return read_nifti(kind.path, label=label)
    if kind.kind == "dicom-series":
        from .dicom import read_dicom_series

        return read_dicom_series(kind.path, allow_irregular=allow_irregular, label=label)
    if kind.kind == "dicom-seg":
        from .dicom import read_dicom_seg

        return read_dicom_seg(kind.path, segment=label)
    if kind.kind == "rtstruct":
        from .rtstruct import read_rtstruct

        return read_rtstruct(
            kind.path,
            roi=roi,
            image_dir=image_dir if image_dir is not None else kind.image_dir,
            pixel_spacing=pixel_spacing,
        )
    if kind.kind == "vti":
        return _vti_volume(kind.path, label=label)
    if kind.kind == "contours":
        from .contours import read_contours

        return read_contours(kind.path, pixel_spacing=pixel_spacing)
    from .mesh import read_mesh_volume

    return read_mesh_volume(kind.path, resolution=mesh_resolution)


def _vti_volume(path: Path, *, label: int | None) -> Volume:
    """A label map in a VTK XML image (``.vti``): one label, or every non-zero voxel."""
    from .nifti import label_mask
    from .vti import read_vti

    image = read_vti(path)
    return Volume(label_mask(np.asarray(image.values), label, path), image.affine)
