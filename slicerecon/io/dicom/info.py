"""Describe a DICOM input from its headers: an image-series directory or a SEG file."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from .seg import seg_info
from .series import series_info

__all__ = ["dicom_info"]


def dicom_info(path: str | os.PathLike[str], *, allow_irregular: bool = True) -> dict[str, Any]:
    """Describe a DICOM image-series directory or a DICOM SEG file (headers only).

    Parameters
    ----------
    path : path-like
        A series directory or a SEG file.
    allow_irregular : bool
        Describe an irregularly spaced series on the grid
        :func:`~slicerecon.io.dicom.read_dicom_series` gives with
        ``allow_irregular=True`` (else such a series raises GeometryError).

    Returns
    -------
    dict
        JSON-ready. Both kinds: ``kind`` ("dicom-series" / "dicom-seg"),
        ``shape`` [I, J, K], ``spacing_mm`` [3], ``orientation`` (the six
        ImageOrientationPatient cosines), ``origin_mm`` [3] and
        ``coordinates`` ("LPS"). Series: ``modality``, ``series_instance_uid``,
        ``n_slices``, ``regular_spacing`` and ``slice_gap_mm`` {min, max} (an
        irregular series is described on the grid ``allow_irregular`` would give).
        SEG: ``segmentation_type``, ``n_frames`` and ``segments``, a list of
        ``{number, label, n_frames}``.

    Raises
    ------
    InputError
        Not a series directory nor a SEG file (or the errors of the readers).
    """
    if Path(path).is_dir():
        return series_info(path, allow_irregular=allow_irregular)
    return seg_info(path)
