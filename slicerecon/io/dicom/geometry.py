"""Where DICOM planes lie: header attributes as numbers, tolerances, and the stacking line.

Shared by the image-series reader (:mod:`.series`) and the SEG reader
(:mod:`.seg`): both stack parallel planes given by ImageOrientationPatient and
ImagePositionPatient, in DICOM patient coordinates (LPS, mm).

Tolerances
----------
Orientation cosines of all planes must agree within :data:`ORIENTATION_TOLERANCE`.
Positions are compared with ``max(0.01 mm, 1e-3 × gap)``
(:func:`position_tolerance`): regular spacing, planes on a whole number of
steps, and every origin on the line through the first and last one.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from ...errors import FormatError, GeometryError, InputError
from .sniff import PARSE_ERRORS

__all__ = [
    "ORIENTATION_TOLERANCE",
    "POSITION_TOLERANCE_MM",
    "POSITION_TOLERANCE_REL",
    "floats",
    "line_fit",
    "optional_float",
    "orientation_list",
    "position_tolerance",
    "require_path",
    "spacing_list",
    "unit_cosines",
]

ORIENTATION_TOLERANCE = 1e-4
"""Largest difference between direction cosines of planes that count as parallel."""
POSITION_TOLERANCE_MM = 0.01
"""Absolute position tolerance, mm (duplicates, regular spacing, collinear origins)."""
POSITION_TOLERANCE_REL = 1e-3
"""Position tolerance relative to the plane gap (regular spacing, collinear origins)."""


def require_path(path: str | os.PathLike[str], *, want_dir: bool) -> Path:
    """``path`` as a Path: an existing series directory or SEG file, else InputError."""
    p = Path(path)
    if not p.exists():
        raise InputError(f"DICOM input not found: {p}")
    if want_dir and not p.is_dir():
        raise InputError(f"{p} is a file; pass the directory that holds the DICOM image series")
    if not want_dir and not p.is_file():
        raise InputError(f"{p} is a directory; pass the DICOM SEG file itself")
    return p


def floats(ds: Any, keyword: str, count: int, path: Path) -> NDArray[np.float64]:
    """A numeric multi-valued attribute as ``count`` finite floats, or FormatError."""
    if keyword not in ds:
        raise FormatError(f"{path} lacks {keyword}; it cannot be placed in space")
    try:
        raw = ds[keyword].value
        values = np.asarray(
            [
                float(v)
                for v in (raw if isinstance(raw, Sequence) and not isinstance(raw, str) else [raw])
            ]
        )
    except PARSE_ERRORS as exc:
        raise FormatError(f"{path}: {keyword} is not numeric ({exc})") from exc
    if values.shape != (count,) or not np.all(np.isfinite(values)):
        raise FormatError(
            f"{path}: {keyword} must hold {count} finite numbers (got {values.tolist()})"
        )
    return values


def optional_float(item: Any, keyword: str) -> float | None:
    """A positive finite number, or None when absent or malformed."""
    try:
        value = float(item[keyword].value) if keyword in item else None
    except PARSE_ERRORS:
        return None
    return value if value is not None and np.isfinite(value) and value > 0 else None


def unit_cosines(orientation: NDArray[np.float64], where: Path) -> tuple[NDArray, NDArray]:
    """Row and column direction cosines of ImageOrientationPatient, normalised and checked."""
    row, col = orientation[:3], orientation[3:]
    n_row, n_col = float(np.linalg.norm(row)), float(np.linalg.norm(col))
    if n_row < 1e-6 or n_col < 1e-6:
        raise FormatError(f"{where}: ImageOrientationPatient has a zero direction")
    row, col = row / n_row, col / n_col
    if abs(float(np.dot(row, col))) > ORIENTATION_TOLERANCE * 10:
        raise GeometryError(
            f"{where}: ImageOrientationPatient row and column directions are not orthogonal"
        )
    return row, col


def position_tolerance(gap: float) -> float:
    """How far a position may be from where it should be, mm, for planes ``gap`` mm apart."""
    return max(POSITION_TOLERANCE_MM, POSITION_TOLERANCE_REL * gap)


def line_fit(
    positions: NDArray[np.float64], t: NDArray[np.float64], names: Sequence[str]
) -> NDArray[np.float64]:
    """Direction ``d`` (with ``d · n = 1``) such that ``IPP ≈ IPP[0] + (t - t[0]) d``.

    ``positions`` of shape (N, 3) and ``t`` of shape (N,) are sorted by ``t``.
    The direction may have an in-plane part (a CT gantry tilt).
    """
    extent = float(t[-1] - t[0])
    direction = (positions[-1] - positions[0]) / extent
    predicted = positions[0] + (t - t[0])[:, None] * direction
    residual = np.linalg.norm(positions - predicted, axis=1)
    tol = position_tolerance(extent / max(len(t) - 1, 1))
    worst = int(np.argmax(residual))
    if residual[worst] > tol:
        raise GeometryError(
            f"slice origins do not lie on one line: {names[worst]} is {residual[worst]:.4g} mm "
            f"off the line through the first and last slice (tolerance {tol:.3g} mm)"
        )
    return direction


def spacing_list(affine: NDArray[np.float64]) -> list[float]:
    """Voxel spacing of an affine, mm, rounded for a JSON description."""
    return [round(float(v), 6) for v in np.linalg.norm(affine[:3, :3], axis=0)]


def orientation_list(affine: NDArray[np.float64]) -> list[float]:
    """The six ImageOrientationPatient cosines of an affine, rounded for a JSON description."""
    cos = affine[:3, :2] / np.linalg.norm(affine[:3, :2], axis=0)
    return [round(float(v), 6) for v in np.concatenate([cos[:, 0], cos[:, 1]])]
