"""DICOM readers: an image series of a mask, and DICOM SEG (Segmentation Storage).

Coordinates
-----------
Everything stays in DICOM patient coordinates, **LPS millimetres** (x to the
patient's left, y to posterior, z to superior); nothing is converted to RAS, so a
mesh reconstructed from a DICOM input is written in LPS mm and overlays the
source images in LPS-aware viewers. See ``docs/formats.md`` for the user guide.

Modules
-------
:mod:`.sniff`
    The one place DICOM files are recognised and identified (with or without
    the 128-byte preamble).
:mod:`.geometry`
    Header attributes as numbers, position tolerances, the stacking line.
:mod:`.series`
    Image series: sorting, grid geometry (regular or resampled), pixel values.
:mod:`.seg`
    DICOM SEG: segments decoded by highdicom onto a grid checked here.
:mod:`.info`
    Header-only descriptions for ``slicerecon info``.
:mod:`.derived`
    What a SEG or RTSTRUCT written by slicerecon needs from its image series:
    the images on their grid, and a label map placed on that grid.
:mod:`.seg_writer`
    Writing a label map as a DICOM SEG (made by highdicom) referring to its series.

Importing this package imports neither highdicom nor pixel decoders: the
dispatcher imports it for every input to sniff files.
"""

from __future__ import annotations

from .geometry import ORIENTATION_TOLERANCE, POSITION_TOLERANCE_MM, POSITION_TOLERANCE_REL
from .info import dicom_info
from .seg import read_dicom_seg
from .seg_writer import write_seg
from .series import (
    FOREGROUND_EPSILON,
    MAX_RESAMPLE_FACTOR,
    dicom_series_geometry,
    read_dicom_series,
    read_dicom_series_values,
)
from .sniff import (
    PARSE_ERRORS,
    SEG_SOP_CLASS_UID,
    dicom_modality,
    dicom_role,
    is_dicom_file,
    object_kind,
    read_dicom_header,
)

__all__ = [
    "FOREGROUND_EPSILON",
    "MAX_RESAMPLE_FACTOR",
    "ORIENTATION_TOLERANCE",
    "PARSE_ERRORS",
    "POSITION_TOLERANCE_MM",
    "POSITION_TOLERANCE_REL",
    "SEG_SOP_CLASS_UID",
    "dicom_info",
    "dicom_modality",
    "dicom_role",
    "dicom_series_geometry",
    "is_dicom_file",
    "object_kind",
    "read_dicom_header",
    "read_dicom_seg",
    "read_dicom_series",
    "read_dicom_series_values",
    "write_seg",
]
