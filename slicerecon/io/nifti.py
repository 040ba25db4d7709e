"""NIfTI label maps: read one label as a :class:`~slicerecon.sections.Volume`, write masks.

Reading keeps ``img.affine`` exactly as nibabel resolves it (the sform when its
code is non-zero, else the qform, else the pixdim scaling), so voxel index →
world millimetres is the same as in 3D Slicer, ITK-SNAP or FSLeyes. Writing
stores the volume's affine in both the sform and the qform with code 1
(``NIFTI_XFORM_SCANNER_ANAT``), as dcm2niix does; NIfTI-1 keeps the affine in
float32, so a round trip preserves it to about 1e-7 relative.
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import nibabel as nib
import numpy as np
from numpy.typing import DTypeLike, NDArray

from ..errors import (
    EmptyMaskError,
    FormatError,
    InputError,
    LabelError,
    OptionError,
    SlicereconError,
)
from ..sections import Volume
from ..selection import parse_selector
from .atomic import atomic_path
from .limits import (
    DEFAULT_MEMORY_BUDGET_GB,
    check_geometry,
    check_grid,
    check_label_range,
    reading,
)

__all__ = ["NiftiInfo", "nifti_labels", "nifti_xform_codes", "read_nifti", "write_nifti"]

logger = logging.getLogger(__name__)

_XFORM_SCANNER_ANAT = 1
"""NIfTI xform code written to sform and qform: scanner-based anatomical coordinates."""


@dataclass(frozen=True, eq=False)
class NiftiInfo:
    """What a NIfTI label map holds, read for ``slicerecon info``.

    Attributes
    ----------
    path : Path
        The file.
    shape : tuple of int
        Grid shape ``(I, J, K)`` (a singleton 4th dimension is dropped).
    affine : ndarray of shape (4, 4)
        Voxel index → world mm, as nibabel resolves it.
    spacing : ndarray of shape (3,)
        Voxel size along the grid axes, mm.
    axcodes : tuple of str
        Anatomical direction each grid axis points to, e.g. ``("R", "A", "S")``.
    dtype : str
        On-disk data type after scaling.
    labels : dict of int to int
        Each non-zero label value and its number of voxels.
    """

    path: Path
    shape: tuple[int, int, int]
    affine: NDArray[np.float64]
    spacing: NDArray[np.float64]
    axcodes: tuple[str, str, str]
    dtype: str
    labels: dict[int, int]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form (lists and plain numbers)."""
        return {
            "path": str(self.path),
            "shape": list(self.shape),
            "affine": self.affine.tolist(),
            "spacing_mm": self.spacing.tolist(),
            "axcodes": "".join(self.axcodes),
            "dtype": self.dtype,
            "labels": {str(k): v for k, v in self.labels.items()},
        }


def _load(path: str | os.PathLike[str]) -> tuple[Path, nib.Nifti1Pair]:
    p = Path(path)
    if not p.exists():
        raise InputError(f"NIfTI file not found: {p}")
    if p.is_dir():
        raise InputError(f"{p} is a directory, not a NIfTI file (.nii / .nii.gz)")
    try:
        img = nib.load(p)
    except Exception as exc:  # nibabel raises many types for damaged files
        raise FormatError(
            f"cannot read {p} as NIfTI ({exc.__class__.__name__}: {_first_line(exc)}); "
            "the file is corrupt, truncated or not a .nii/.nii.gz image"
        ) from exc
    if not isinstance(img, nib.Nifti1Pair):
        raise FormatError(
            f"{p} is a {type(img).__name__}, not a NIfTI image; convert it to .nii/.nii.gz"
        )
    return p, img


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else "no details"


def _grid_shape(p: Path, img: nib.Nifti1Pair) -> tuple[int, int, int]:
    """The 3-D grid shape of ``img``; 4-D and higher only with singleton extra dims."""
    shape = tuple(int(n) for n in img.shape)
    if len(shape) < 3:
        raise InputError(
            f"{p} is a {len(shape)}-D image (shape {shape}); a 3-D label map is needed"
        )
    extra = shape[3:]
    if any(n != 1 for n in extra):
        raise InputError(
            f"{p} is a {len(shape)}-D image (shape {shape}) holding "
            f"{int(np.prod(extra))} volumes; extract the one 3-D label map to use "
            "(e.g. with nibabel.funcs.four_to_three or fslroi) and pass that"
        )
    return shape[0], shape[1], shape[2]


def _read_labels(
    p: Path, img: nib.Nifti1Pair, memory_budget_gb: float = DEFAULT_MEMORY_BUDGET_GB
) -> NDArray[Any]:
    """The voxel values of ``img`` as a 3-D array, checked to be an integer label map.

    The header's geometry and declared size are checked before any voxel is read.
    """
    shape = _grid_shape(p, img)
    check_geometry(img.affine, shape, what=str(p))
    itemsize = np.dtype(img.get_data_dtype()).itemsize
    check_grid(
        shape, what=str(p), memory_budget_gb=memory_budget_gb, bytes_per_voxel=2 * itemsize + 2
    )
    try:
        data = np.asanyarray(img.dataobj)
    except Exception as exc:  # truncated data, bad gzip stream, impossible header
        raise FormatError(
            f"cannot read the voxel data of {p} ({exc.__class__.__name__}: "
            f"{_first_line(exc)}); the file is corrupt or truncated"
        ) from exc
    data = data.reshape(shape)
    kind = data.dtype.kind
    if kind == "f":
        finite = np.isfinite(data)
        if not finite.all():
            raise LabelError(
                f"{p} is not a label map: it holds NaN or infinite values; "
                "pass an integer label map (segmentation), not an intensity image"
            )
        fractional = data != np.round(data)
        if fractional.any():
            example = float(data[fractional].flat[0])
            raise LabelError(
                f"{p} is not a label map: it holds non-integer values (e.g. {example:g}); "
                "pass an integer label map, or threshold the image into a mask first"
            )
    elif kind not in "biu":
        raise LabelError(f"{p} is not a label map: its voxels have data type {data.dtype}")
    check_label_range(data, what=str(p))
    return data


def label_mask(data: NDArray[Any], label: int | str | None, source: Path) -> NDArray[np.bool_]:
    """The voxels of one label of a label map (``None``: every non-zero voxel).

    Shared by the label-map readers (NIfTI, VTK images) so that they select
    labels and report missing ones the same way.

    Raises
    ------
    EmptyMaskError
        If every voxel is 0.
    LabelError
        If ``label`` is absent (the message lists the labels present).
    """
    label = _label_value(label, data, source)
    if label is None:
        mask = data != 0
        if not mask.any():
            raise EmptyMaskError(
                f"{source} is empty: every voxel is 0, there is nothing to reconstruct"
            )
        return mask
    mask = data == label
    if not mask.any():
        present = _label_counts(data)
        if not present:
            raise EmptyMaskError(
                f"{source} is empty: every voxel is 0, so label {label} is absent too"
            )
        listed = ", ".join(str(v) for v in list(present)[:20])
        more = f" (and {len(present) - 20} more)" if len(present) > 20 else ""
        raise LabelError(
            f"label {label} is absent from {source}; labels present: {listed}{more}. "
            "Pick one of these"
        )
    return mask


def _label_value(label: int | str | None, data: NDArray[Any], source: Path) -> int | None:
    """A label map's structures are its values: a name can only be a number in text."""
    selector = parse_selector(label)
    if selector is None or isinstance(selector, int):
        return selector
    present = ", ".join(str(v) for v in list(_label_counts(data))[:20])
    raise LabelError(
        f"label {selector!r} is not in {source}: a label map names its structures by "
        f"value, not by name; labels present: {present or 'none'}"
    )


def _label_counts(data: NDArray[Any]) -> dict[int, int]:
    """Non-zero label values of an integer-valued array and their voxel counts."""
    if data.dtype.kind in "bu" and data.dtype.itemsize <= 2:
        counts = np.bincount(data.ravel().astype(np.int64))
        values = np.flatnonzero(counts)
        counts = counts[values]
    else:
        values, counts = np.unique(data, return_counts=True)
    return {int(v): int(c) for v, c in zip(values, counts, strict=True) if v != 0}


def read_nifti(
    path: str | os.PathLike[str],
    *,
    label: int | str | None = None,
    memory_budget_gb: float = DEFAULT_MEMORY_BUDGET_GB,
) -> Volume:
    """Read one label (or every non-zero voxel) of a NIfTI label map.

    Parameters
    ----------
    path : path-like
        A ``.nii`` or ``.nii.gz`` file (NIfTI-1 or NIfTI-2) holding a 3-D label
        map; a 4-D image whose 4th dimension is 1 is accepted.
    label : int or str, optional
        Label value to keep (a string of digits counts as the number). Default:
        every non-zero voxel is foreground.
    memory_budget_gb : float
        Refuse headers whose declared grid would not fit this budget, GiB
        (:func:`slicerecon.io.limits.check_grid`), before reading any voxel.

    Returns
    -------
    Volume
        Mask of shape ``(I, J, K)`` with the image's affine (voxel index → world mm).

    Raises
    ------
    InputError
        If the file is missing, not 3-D, or a true 4-D series.
    FormatError
        If the file is corrupt, truncated or not NIfTI.
    LabelError
        If ``label`` is absent (the message lists the labels present), is a
        name, or the image is not a label map (non-integer or non-finite values).
    EmptyMaskError
        If the image (or the selected label) holds no foreground voxel.
    GeometryError
        Non-finite or absurd voxel spacing or origin.
    MemoryBudgetError
        The declared grid exceeds ``memory_budget_gb``.
    OptionError
        If ``label`` is neither an integer nor a string.
    """
    if label is not None and (
        isinstance(label, bool) or not isinstance(label, int | np.integer | str)
    ):
        raise OptionError(f"label must be an integer label value or a name (got {label!r})")
    p, img = _load(path)
    mask = label_mask(_read_labels(p, img, memory_budget_gb), label, p)
    volume = Volume(mask, img.affine)
    logger.info(
        "read %s: %s, label %s, %d foreground voxels",
        p,
        "x".join(str(n) for n in volume.shape),
        "any non-zero" if label is None else label,
        int(np.count_nonzero(mask)),
    )
    return volume


def read_label_values(
    path: str | os.PathLike[str], *, memory_budget_gb: float = DEFAULT_MEMORY_BUDGET_GB
) -> tuple[NDArray[Any], NDArray[np.float64]]:
    """The whole label map of a NIfTI file and its affine.

    Parameters
    ----------
    path : path-like
        A ``.nii`` or ``.nii.gz`` label map.
    memory_budget_gb : float
        As for :func:`read_nifti`.

    Returns
    -------
    values : ndarray of shape (I, J, K)
        Integer-valued labels, in the file's data type.
    affine : ndarray of shape (4, 4)
        Voxel index → world mm.

    Raises
    ------
    InputError, FormatError, LabelError, GeometryError, MemoryBudgetError
        As :func:`read_nifti`.
    """
    p, img = _load(path)
    return _read_labels(p, img, memory_budget_gb), np.asarray(img.affine, dtype=np.float64)


def nifti_labels(path: str | os.PathLike[str]) -> NiftiInfo:
    """Describe a NIfTI label map: grid, geometry and the voxel count of each label.

    Parameters
    ----------
    path : path-like
        A ``.nii`` or ``.nii.gz`` label map.

    Returns
    -------
    NiftiInfo
        Shape, affine, spacing (mm), orientation codes, data type and label counts
        (an all-zero image gives an empty ``labels`` dict).

    Raises
    ------
    InputError, FormatError, LabelError
        As :func:`read_nifti`.
    """
    p, img = _load(path)
    data = _read_labels(p, img)
    affine = np.asarray(img.affine, dtype=np.float64)
    i, j, k = nib.aff2axcodes(affine)
    return NiftiInfo(
        path=p,
        shape=(int(data.shape[0]), int(data.shape[1]), int(data.shape[2])),
        affine=affine,
        spacing=np.linalg.norm(affine[:3, :3], axis=0),
        axcodes=(str(i), str(j), str(k)),
        dtype=str(data.dtype),
        labels=_label_counts(data),
    )


def nifti_xform_codes(
    path: str | os.PathLike[str], *, affine: NDArray[np.float64] | None = None
) -> tuple[int, int] | None:
    """The sform and qform codes of a NIfTI file, to write an output in the same space.

    Parameters
    ----------
    path : path-like
        Any input; only a ``.nii`` / ``.nii.gz`` file gives codes.
    affine : ndarray of shape (4, 4), optional
        The output's affine (RAS): codes are given only when it is the file's
        own affine (to 1e-4 mm), i.e. the output lies on the input's grid.

    Returns
    -------
    tuple of (int, int) or None
        ``(sform_code, qform_code)`` (e.g. ``(4, 0)`` for an MNI-coded
        template, ``(1, 1)`` for scanner space), or None for another kind of
        file, an unreadable one, or another grid.
    """
    p = Path(path)
    if not p.name.lower().endswith((".nii", ".nii.gz")) or not p.is_file():
        return None
    try:
        with reading(p):
            _, img = _load(p)
            codes = int(img.header["sform_code"]), int(img.header["qform_code"])
            own = np.asarray(img.affine, dtype=np.float64)
    except SlicereconError:
        return None
    if affine is not None and not np.allclose(own, affine, rtol=0, atol=1e-4):
        return None
    return codes


def write_nifti(
    volume: Volume, path: str | os.PathLike[str], *, dtype: DTypeLike = np.uint8
) -> Path:
    """Write a volume's mask as a 0/1 NIfTI-1 image with the volume's affine.

    Parameters
    ----------
    volume : Volume
        The mask and its geometry.
    path : path-like
        Target file ending in ``.nii`` or ``.nii.gz`` (gzip-compressed). Parent
        directories are created; the file appears atomically (complete or not at all).
    dtype : numpy dtype, optional
        Integer or float voxel type on disk (default ``uint8``).

    Returns
    -------
    Path
        The written file.

    Raises
    ------
    InputError
        If ``volume`` is not a Volume.
    OptionError
        If the suffix is not ``.nii`` / ``.nii.gz`` or ``dtype`` is not numeric.

    Notes
    -----
    sform and qform both hold the affine with code 1 (scanner anatomical). A
    qform cannot hold shear; for a sheared affine it holds the nearest
    rotation, and readers use the exact sform. Units are set to millimetres.
    """
    if not isinstance(volume, Volume):
        raise InputError(f"write_nifti needs a Volume (got {type(volume).__name__})")
    p = Path(path)
    if not p.name.lower().endswith((".nii", ".nii.gz")):
        raise OptionError(f"NIfTI output must end in .nii or .nii.gz (got {p.name!r})")
    try:
        out_dtype = np.dtype(dtype)
    except TypeError as exc:
        raise OptionError(f"dtype must be a numpy integer or float type (got {dtype!r})") from exc
    if out_dtype.kind not in "iuf":
        raise OptionError(f"dtype must be a numpy integer or float type (got {out_dtype})")

    affine = np.asarray(volume.affine, dtype=np.float64)
    img = nib.Nifti1Image(volume.mask.astype(out_dtype), affine)
    img.header.set_data_dtype(out_dtype)
    img.header.set_xyzt_units(xyz="mm")
    img.set_sform(affine, code=_XFORM_SCANNER_ANAT)
    img.set_qform(affine, code=_XFORM_SCANNER_ANAT, strip_shears=True)
    with atomic_path(p) as tmp:
        nib.save(img, tmp)
    logger.info("wrote %s (%s, %s)", p, "x".join(str(n) for n in volume.shape), out_dtype)
    return p
