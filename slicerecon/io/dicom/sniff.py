"""Recognise DICOM files and tell what they hold: the one place that does.

Every part of slicerecon that meets a file which might be DICOM asks here: the
input dispatcher (:func:`slicerecon.io.detect_kind`), the image-series and SEG
readers, the RTSTRUCT reader and the batch discovery (``pipelines/discover.py``).

* :func:`is_dicom_file` looks at the first bytes only: a Part 10 file (``DICM``
  at byte 128), or a bare dataset without the 128-byte preamble whose first
  element is a plausible tag of group 0x0002 or 0x0008 (older exports,
  pydicom's own ``rtstruct.dcm``).
* :func:`read_dicom_header` reads such a file with pydicom (``force=True`` for
  the bare datasets) and turns every parser failure into one
  :class:`~slicerecon.errors.FormatError` naming the file.
* :func:`object_kind` tells from a dataset what kind of object it is (image,
  SEG, RTSTRUCT, DICOMDIR or another non-image object), and
  :func:`dicom_modality` / :func:`dicom_role` do the same from a path.
"""

from __future__ import annotations

import os
import struct
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Literal

from ...errors import FormatError
from ..limits import reading

__all__ = [
    "DICOM_SUFFIXES",
    "NON_IMAGE_MODALITIES",
    "PARSE_ERRORS",
    "SEG_SOP_CLASS_UID",
    "dicom_modality",
    "dicom_role",
    "is_dicom_file",
    "object_kind",
    "read_dicom_header",
]

SEG_SOP_CLASS_UID = "1.2.840.10008.5.1.4.1.1.66.4"
"""SOP Class UID of DICOM Segmentation Storage."""
DICOMDIR_SOP_CLASS_UID = "1.2.840.10008.1.3.10"
"""Media Storage SOP Class UID of a DICOMDIR (Media Storage Directory Storage)."""
DICOM_SUFFIXES = (".dcm", ".dicom", ".ima")
"""Names that promise DICOM content: such a file that is not DICOM is an error, not skipped."""
NON_IMAGE_MODALITIES = frozenset(
    {"RTSTRUCT", "SEG", "RTPLAN", "RTRECORD", "SR", "KO", "PR", "REG", "DOC", "FID", "PLAN"}
)
"""Modalities of objects that are not slices of an image series."""

PARSE_ERRORS: tuple[type[BaseException], ...] = (
    OSError,
    EOFError,
    ValueError,
    TypeError,
    KeyError,
    IndexError,
    AttributeError,
    NotImplementedError,
    OverflowError,
    RuntimeError,
    struct.error,
)
"""What pydicom raises on corrupt or truncated files and malformed values (the
readers turn these into one :class:`~slicerecon.errors.FormatError`)."""

ObjectKind = Literal["image", "seg", "rtstruct", "dicomdir", "other"]
"""What a DICOM dataset holds (see :func:`object_kind`)."""


def _head(path: Path) -> bytes:
    try:
        with open(path, "rb") as fh:
            return fh.read(132)
    except OSError as exc:
        raise FormatError(f"cannot read {path}: {exc.strerror or exc}") from exc


def _has_marker(head: bytes) -> bool:
    return len(head) == 132 and head[128:132] == b"DICM"


def _looks_like_dataset(head: bytes) -> bool:
    """A bare dataset: a little-endian tag of group 0x0002 or 0x0008 first."""
    if len(head) < 8:
        return False
    group, element = struct.unpack("<HH", head[:4])
    if group not in (0x0002, 0x0008) or element > 0x1FFF:
        return False
    vr = head[4:6]
    if vr.isalpha() and vr.isupper():  # explicit VR
        return True
    (length,) = struct.unpack("<I", head[4:8])  # implicit VR: a modest element length
    return length < 1024


def is_dicom_file(path: str | os.PathLike[str]) -> bool:
    """Whether a file's content is DICOM, from its first bytes (no parsing).

    True for a Part 10 file (the ``DICM`` marker at byte 128) and for a bare
    dataset without the 128-byte preamble, as older systems and pydicom's own
    test files write them: its first element is a little-endian tag of group
    0x0002 (file meta) or 0x0008 (identification) with a plausible VR or length.

    Raises
    ------
    FormatError
        If the file cannot be read at all.
    """
    head = _head(Path(path))
    return _has_marker(head) or _looks_like_dataset(head)


def read_dicom_header(
    path: str | os.PathLike[str],
    *,
    stop_before_pixels: bool = True,
    specific_tags: Sequence[str] | None = None,
) -> Any:
    """Read a DICOM file with pydicom, with or without its preamble.

    Files without the 128-byte preamble and ``DICM`` marker are read with
    ``force=True`` when :func:`is_dicom_file` recognises their content. Pixel
    data, when read, is deferred until it is first used.

    Parameters
    ----------
    path : path-like
        The file.
    stop_before_pixels : bool
        Skip the pixel data.
    specific_tags : sequence of str, optional
        Read only these keywords (a fast sniff).

    Returns
    -------
    pydicom.Dataset

    Raises
    ------
    FormatError
        If the content is not DICOM, or pydicom fails on it (the file is named).
    """
    import pydicom

    p = Path(path)
    head = _head(p)
    marker = _has_marker(head)
    if not (marker or _looks_like_dataset(head)):
        raise FormatError(f"{p} is corrupt or not a DICOM file: its content is not DICOM")
    try:
        return pydicom.dcmread(
            p,
            stop_before_pixels=stop_before_pixels,
            specific_tags=list(specific_tags) if specific_tags is not None else None,
            defer_size=None if stop_before_pixels else "64 KB",
            force=not marker,
        )
    except Exception as exc:  # noqa: BLE001 - every pydicom failure names the file
        raise FormatError(
            f"{p} is corrupt or not a valid DICOM file ({type(exc).__name__}: "
            f"{' '.join(str(exc).split())[:200]}); remove or replace it"
        ) from exc


def object_kind(ds: Any) -> ObjectKind:
    """What a DICOM dataset holds, from its SOP class and Modality.

    ``"seg"`` (SOPClassUID, else the file meta's MediaStorageSOPClassUID, is
    Segmentation Storage), ``"rtstruct"`` (Modality RTSTRUCT), ``"dicomdir"``,
    ``"other"`` (another non-image object: RTPLAN, SR, KO, PR, REG, ...) or
    ``"image"`` (anything else, including a dataset that names neither).
    """
    meta = getattr(ds, "file_meta", None)
    media_class = str(meta.get("MediaStorageSOPClassUID", "") or "") if meta is not None else ""
    sop_class = str(ds.get("SOPClassUID", "") or "") or media_class
    modality = str(ds.get("Modality", "") or "").upper()
    if sop_class == SEG_SOP_CLASS_UID:
        return "seg"
    if modality == "RTSTRUCT":
        return "rtstruct"
    if media_class == DICOMDIR_SOP_CLASS_UID:
        return "dicomdir"
    if modality in NON_IMAGE_MODALITIES:
        return "other"
    return "image"


def _identify(path: Path) -> tuple[ObjectKind, str, str]:
    """``(object_kind, Modality, SOPClassUID)`` of a file that is DICOM by content.

    Raises FormatError when it cannot be parsed.
    """
    with reading(path):  # values are parsed lazily, on access
        ds = read_dicom_header(path, specific_tags=["Modality", "SOPClassUID"])
        modality = str(ds.get("Modality", "") or "")
        sop_class = str(ds.get("SOPClassUID", "") or "")
        return object_kind(ds), modality, sop_class


def dicom_modality(path: str | os.PathLike[str]) -> str | None:
    """``"SEG"``, ``"RTSTRUCT"``, another Modality (``"UNKNOWN"`` when absent), or
    None when the file is not DICOM or cannot be parsed."""
    p = Path(path)
    try:
        if not p.is_file() or not is_dicom_file(p):
            return None
        _, modality, sop_class = _identify(p)
    except FormatError:
        return None
    if sop_class == SEG_SOP_CLASS_UID:
        return "SEG"
    if not modality and not sop_class:
        return None  # forced parse of something that only began like DICOM
    return modality or "UNKNOWN"


def dicom_role(path: str | os.PathLike[str]) -> str | None:
    """What a file is to a batch: the :func:`object_kind` of a DICOM file, else
    ``"unreadable"`` or None.

    Returns
    -------
    str or None
        ``"image"``, ``"seg"``, ``"rtstruct"``, ``"other"`` (a non-image object
        or a DICOMDIR); ``"unreadable"`` for a file that is DICOM by content but
        cannot be parsed, or that is named like DICOM (``.dcm``, ``.dicom``,
        ``.ima``) but is not (or cannot be opened); None for any other file.
    """
    p = Path(path)
    named_dicom = p.name.lower().endswith(DICOM_SUFFIXES)
    try:
        dicom = is_dicom_file(p)
    except FormatError:  # cannot be opened
        dicom = False
    if not dicom:
        return "unreadable" if named_dicom else None
    try:
        kind, _, _ = _identify(p)
    except FormatError:
        return "unreadable"
    return "other" if kind == "dicomdir" else kind
