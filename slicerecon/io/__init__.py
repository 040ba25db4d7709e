"""Readers and writers: one entry point for every supported input.

:func:`load_input` looks at a path and returns what it holds:

* a dense :class:`~slicerecon.sections.Volume` for NIfTI and NRRD label maps
  (Slicer ``.seg.nrrd`` segmentations too), DICOM image series of a mask,
  DICOM SEG files and closed meshes (voxelised);
* sparse :class:`~slicerecon.sections.CrossSections` for contour files
  (JSON / CSV) and DICOM RTSTRUCT.

Format modules are imported on first use, so a missing optional dependency only
fails the format that needs it.
"""

from __future__ import annotations

import logging
import os
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import FormatError, InputError, LabelError, OptionError
from ..labels import LPS_TO_RAS
from ..sections import CrossSections, Volume
from ..selection import parse_selector
from .limits import DEFAULT_MEMORY_BUDGET_GB, check_budget, check_grid, reading

__all__ = [
    "DICOM_KINDS",
    "DETACHED_NRRD",
    "INPUT_SUFFIXES",
    "InputKind",
    "MESH_SUFFIXES",
    "NIFTI_SUFFIXES",
    "detect_kind",
    "frame_of_reference",
    "kind_of_name",
    "load_ground_truth",
    "load_input",
    "same_frame",
    "series_below",
    "world_frame",
    "series_of",
]

logger = logging.getLogger(__name__)

NIFTI_SUFFIXES = (".nii", ".nii.gz")
MESH_SUFFIXES = (".stl", ".ply", ".obj", ".off")
CONTOUR_SUFFIXES = (".json", ".csv")
DICOM_KINDS = ("dicom-series", "dicom-seg", "rtstruct")
"""Input kinds in DICOM patient coordinates (LPS)."""
DICOM_SUFFIXES = (".dcm", ".dicom", "")
DETACHED_NRRD = (
    "a NRRD header whose voxels are in a separate file (.nhdr) is not read; save it as one "
    ".nrrd file with attached data (3D Slicer: Save, file format .seg.nrrd or .nrrd)"
)
"""What is said of a ``.nhdr`` file (run refuses it, batch leaves it out)."""

INPUT_SUFFIXES: tuple[tuple[str, str], ...] = (
    (".nii.gz", "nifti"),
    (".nii", "nifti"),
    (".seg.nrrd", "nrrd"),  # 3D Slicer segmentations
    (".nrrd", "nrrd"),
    (".vti", "vti"),
    (".json", "contours"),
    (".csv", "contours"),
    *((suffix, "mesh") for suffix in MESH_SUFFIXES),
)
"""File-name endings that tell an input's kind (lower case; the longer ending first).
Any other file is DICOM (recognised by content) or not an input."""


@dataclass(frozen=True)
class InputKind:
    """What a path holds.

    Attributes
    ----------
    kind : str
        One of ``"nifti"``, ``"nrrd"``, ``"vti"``, ``"dicom-series"``, ``"dicom-seg"``,
        ``"rtstruct"``, ``"contours"``, ``"mesh"``.
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


def kind_of_name(name: str) -> tuple[str, str] | None:
    """The kind a file's name tells, and the ending that tells it (:data:`INPUT_SUFFIXES`).

    Parameters
    ----------
    name : str
        A file name (case is ignored).

    Returns
    -------
    (kind, suffix) or None
        E.g. ``("nrrd", ".seg.nrrd")``; None for a name that tells nothing
        (DICOM files are recognised by content, see :func:`detect_kind`).
    """
    lower = name.lower()
    for suffix, kind in INPUT_SUFFIXES:
        if lower.endswith(suffix) and len(lower) > len(suffix):
            return kind, suffix
    return None


def series_below(folder: Path, drawing: Path | None = None, *, quiet: bool = False) -> Path | None:
    """The one subfolder of ``folder`` holding DICOM images (an RTSTRUCT beside ``CT/``), or
    None when there is none or several; the rule ``run`` and batch discovery share.

    Of several, the one whose images ``drawing`` (an RTSTRUCT or SEG) names as those it
    was drawn on (:func:`slicerecon.io.dicom.series.referenced_series`), else the one
    of its FrameOfReferenceUID, said in one warning line unless ``quiet`` (batch
    discovery: the case's own read says it)."""
    found = []
    for sub in sorted(d for d in folder.iterdir() if d.is_dir() and not d.name.startswith(".")):
        try:
            if next(_images_in(sub), None) is not None:
                found.append(sub)
        except OSError:  # gone, or not readable: holds no series to take
            continue
    if len(found) > 1 and drawing is not None:
        named, why = _named_by(drawing, found), "the series it names"
        if len(named) != 1:  # a CT beside a registered MR: the one of its frame
            named = [sub for sub in found if same_frame(drawing, sub, known=True, rois=True)]
            why = "the one series of its frame of reference"
        if len(named) == 1 and not quiet:
            listed = ", ".join(sub.name for sub in found[:4]) + (", ..." if len(found) > 4 else "")
            logger.warning(
                "%s: %d folders beside it hold images (%s): read %s, %s",
                drawing,
                len(found),
                listed,
                named[0],
                why,
            )
        if len(named) == 1:
            return named[0]
    return found[0] if len(found) == 1 else None


def _images_in(folder: Path) -> Iterator[Path]:
    """The DICOM image files of a folder, in name order: hidden files, other files
    (a README, a .DS_Store), DICOMDIRs and non-image objects are passed over."""
    from .dicom.sniff import dicom_role

    try:
        files = sorted(folder.iterdir())
    except FileNotFoundError:  # removed while its siblings were looked through
        return
    for f in files:
        if f.is_file() and not f.name.startswith(".") and dicom_role(f) == "image":
            yield f


def _peek(path: Path, tags: list[str] | None = None) -> Any:
    """A DICOM file's header read quietly, or None when it cannot be read (a peek to pair
    files: the real read of the file says what is wrong with it)."""
    from .dicom.sniff import read_dicom_header

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            return read_dicom_header(path, specific_tags=tags)
    except Exception:  # noqa: BLE001 - an unreadable file names nothing
        return None


@contextmanager
def _hushed() -> Iterator[None]:
    """Python warnings ignored: a peek's values are read again, and said, by the real read."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        yield


def _named_by(drawing: Path, folders: list[Path]) -> list[Path]:
    """Those of ``folders`` whose images an RTSTRUCT or SEG names (by SeriesInstanceUID,
    else by SOPInstanceUID): :func:`slicerecon.io.dicom.series.referenced_series`."""
    from .dicom.series import referenced_series

    ds = _peek(drawing)
    if ds is None:
        return []
    named = []
    with _hushed():  # pydicom converts values when they are asked for, and warns then
        series, instances = referenced_series(ds)
        for folder in folders:
            images = _images_in(folder)
            for f in images if instances and not series else [next(images, None)]:
                if f is None:
                    break
                image = _peek(f, ["SeriesInstanceUID", "SOPInstanceUID"])
                if image is not None and (
                    str(image.get("SeriesInstanceUID", "")) in series
                    or str(image.get("SOPInstanceUID", "")) in instances
                ):
                    named.append(folder)
                    break
    return named


def frame_of_reference(path: Path, *, rois: bool = False) -> str:
    """The FrameOfReferenceUID a DICOM object or series names ("" when it names none or
    cannot be read): an image series' (a folder: its first image), a SEG's, an
    RTSTRUCT's in its references, or (``rois``) its first ROI's."""
    if path.is_dir():
        first = next(_images_in(path), None)
        if first is None:
            return ""
        path = first
    ds = _peek(path)
    if ds is None:
        return ""
    with _hushed():  # a malformed UID warned on stderr when its value was asked for
        uid = str(ds.get("FrameOfReferenceUID", "") or "")
        # an RTSTRUCT names it in its references (optional), and in each ROI (``rois``)
        for sequence, keyword in (
            ("ReferencedFrameOfReferenceSequence", "FrameOfReferenceUID"),
            ("StructureSetROISequence", "ReferencedFrameOfReferenceUID"),
        )[: 2 if rois else 1]:
            if not uid and sequence in ds:
                items = ds[sequence].value
                uid = str(items[0].get(keyword, "") or "") if len(items) else ""
    return uid


def same_frame(drawing: Path, series: Path, *, known: bool = False, rois: bool = False) -> bool:
    """Whether an RTSTRUCT or SEG and the first image of a series folder name one
    FrameOfReferenceUID (True when either does not say: nothing tells them apart,
    unless ``known``: then both must name it). ``rois``: an RTSTRUCT without its
    references names it by its ROIs' ReferencedFrameOfReferenceUID (to tell folders
    side by side apart, not to refuse a series)."""
    own, theirs = frame_of_reference(drawing, rois=rois), frame_of_reference(series, rois=rois)
    if known:
        return bool(own) and own == theirs
    return not own or not theirs or own == theirs


def series_of(drawing: Path, *, images_beside: bool | None = None) -> Path | None:
    """The image series an RTSTRUCT or SEG was drawn on: its own folder when that holds
    images, else the one subfolder of it holding images (:func:`series_below`); None
    when there is none, or when the series names another FrameOfReferenceUID (another
    study's images: said in one warning line). Given the file alone (``images_beside``
    None), the images beside it are taken only when they name its FrameOfReferenceUID."""
    folder = drawing.parent
    if images_beside is None:
        candidate = folder if _holds_images(folder) else series_below(folder, drawing)
        if candidate is None and folder.parent != folder and _drawings_only(folder):
            candidate = series_below(folder.parent, drawing)  # RTSTRUCT/ beside CT/
        if candidate is not None and same_frame(drawing, candidate, known=True):
            return candidate
        return None
    series = folder if images_beside else series_below(folder, drawing)
    if series is not None and not same_frame(drawing, series):
        logger.warning(
            "%s: the images in %s are of another frame of reference (another study): it is "
            "read without them",
            drawing,
            series,
        )
        return None
    return series


def _drawings_only(folder: Path) -> bool:
    """Whether every DICOM file of a folder is an RTSTRUCT or SEG, and it holds one (a PACS
    export's RTSTRUCT/; a README or .DS_Store beside them is no DICOM file)."""
    from .dicom.sniff import dicom_role

    files = [f for f in sorted(folder.iterdir()) if f.is_file() and not f.name.startswith(".")]
    roles = [role for role in map(dicom_role, files) if role is not None]
    return bool(roles) and all(role in ("rtstruct", "seg") for role in roles)


def _holds_images(folder: Path) -> bool:
    """Whether a folder holds a DICOM image file (not an RTSTRUCT, SEG or DICOMDIR)."""
    return next(_images_in(folder), None) is not None


def _drawing_below(folder: Path) -> InputKind:
    """A folder of subfolders only, as PACS exports a study (``CT/`` beside
    ``RTSTRUCT/``): its one RTSTRUCT or SEG in a subfolder, with the one image
    series of another subfolder (:func:`series_below`).

    Raises
    ------
    InputError
        Not exactly one RTSTRUCT or SEG, or not exactly one image series of its
        FrameOfReferenceUID: the message says which.
    """
    from .dicom import dicom_modality

    found = []
    for sub in sorted(d for d in folder.iterdir() if d.is_dir() and not d.name.startswith(".")):
        for f in sorted(f for f in sub.iterdir() if f.is_file() and not f.name.startswith(".")):
            modality = dicom_modality(f)
            if modality in ("RTSTRUCT", "SEG"):
                found.append((f, modality))
    if len(found) > 1:
        listed = ", ".join(str(f.relative_to(folder)) for f, _ in found[:4])
        raise InputError(
            f"directory {folder} holds {len(found)} RTSTRUCT or SEG files in its subfolders "
            f"({listed}): pass one of them (its folder's images, or the one series beside "
            "it, are taken with it)"
        )
    if not found:
        raise InputError(
            f"directory {folder} holds no file, and its subfolders no RTSTRUCT or SEG: pass "
            "a DICOM series folder, or a folder holding an RTSTRUCT or SEG and its images"
        )
    path, modality = found[0]
    images = series_below(folder, path)
    if images is None:
        raise InputError(
            f"{path}: directory {folder} holds no one image series beside it (none, or "
            "several subfolders of images and the file names none of them as its own): put "
            "it in one folder with the series it was drawn on, or pass the file alone"
        )
    if not same_frame(path, images):
        raise InputError(
            f"{path}: the images in {images} are of another frame of reference (another "
            "study): pass the file alone, or the folder with the series it was drawn on"
        )
    return InputKind("rtstruct" if modality == "RTSTRUCT" else "dicom-seg", path, image_dir=images)


def detect_kind(path: str | os.PathLike[str]) -> InputKind:
    """Tell what kind of input ``path`` is, without reading pixel data.

    DICOM files are recognised by content (:func:`slicerecon.io.dicom.dicom_modality`),
    with or without the 128-byte preamble.

    Raises
    ------
    InputError
        If the path does not exist or its kind cannot be told.
    """
    from .dicom import dicom_modality

    p = Path(path)
    if not p.exists():
        raise InputError(f"input not found: {p}")
    if p.is_dir():
        files = sorted(f for f in p.iterdir() if f.is_file() and not f.name.startswith("."))
        if not files:
            return _drawing_below(p)
        modalities = {f: dicom_modality(f) for f in files}
        drawings = [f for f in files if modalities[f] in ("RTSTRUCT", "SEG")]
        if len(drawings) == 1:
            images = [f for f, m in modalities.items() if m not in (None, "RTSTRUCT", "SEG")]
            kind = "rtstruct" if modalities[drawings[0]] == "RTSTRUCT" else "dicom-seg"
            series = series_of(drawings[0], images_beside=bool(images))
            return InputKind(kind, drawings[0], image_dir=series)
        if len(drawings) > 1:
            raise InputError(
                f"directory {p} holds {len(drawings)} RTSTRUCT or SEG files "
                f"({', '.join(f.name for f in drawings[:4])}); pass one of them"
            )
        return InputKind("dicom-series", p)
    named = kind_of_name(p.name)
    if named is not None:
        return InputKind(named[0], p)
    modality = dicom_modality(p)
    if modality in ("SEG", "RTSTRUCT"):  # with the images beside it, as its folder is read
        kind = "dicom-seg" if modality == "SEG" else "rtstruct"
        return InputKind(kind, p, image_dir=series_of(p))
    if modality is not None:
        raise InputError(
            f"{p} is a single DICOM {modality} image; pass the directory of its series"
        )
    if p.name.lower().endswith(".nhdr"):
        raise FormatError(f"{p}: {DETACHED_NRRD}")
    if p.name.lower().endswith((".dcm", ".dicom", ".ima")):
        raise FormatError(
            f"{p} is named like a DICOM file but is not one that can be read (no DICOM "
            "header, or a damaged one): export it again from the planning system or viewer"
        )
    raise FormatError(
        f"cannot tell the format of {p}: expected .nii/.nii.gz, a DICOM series directory, "
        "a DICOM SEG or RTSTRUCT file, a contour file (.json/.csv), a VTK image (.vti), "
        "a NRRD label map or Slicer segmentation (.nrrd/.seg.nrrd) or a mesh (.stl/.ply/.obj/.off)"
    )


def load_input(
    path: str | os.PathLike[str],
    *,
    label: int | str | None = None,
    roi: int | str | None = None,
    image_dir: str | os.PathLike[str] | None = None,
    allow_irregular: bool = False,
    mesh_resolution: int = 128,
    pixel_spacing: float | None = None,
    memory_budget_gb: float = DEFAULT_MEMORY_BUDGET_GB,
    union: bool = False,
) -> Volume | CrossSections:
    """Read any supported input as one structure.

    A label map of several structures is never merged silently: give
    ``label`` to take one, ``union=True`` to take every non-zero voxel as one
    structure, or read them all with :func:`slicerecon.io.labelmap.read_label_map`
    (and reconstruct them with :func:`slicerecon.case.reconstruct_structures`).

    This is the reading boundary (:func:`slicerecon.io.limits.reading`):
    whatever a parser raises becomes a :class:`~slicerecon.errors.FormatError`
    naming the file, and every reader checks geometry and the memory budget
    before it allocates a grid.

    Parameters
    ----------
    path : path-like
        NIfTI file, NRRD label map or Slicer segmentation (``.nrrd`` /
        ``.seg.nrrd``), DICOM series directory, DICOM SEG / RTSTRUCT file, contour
        file (``.json`` / ``.csv``), VTK image (``.vti``) or closed mesh
        (``.stl`` / ``.ply`` / ``.obj`` / ``.off``).
    label : int or str, optional
        The structure to keep, by number or name
        (:func:`slicerecon.selection.choose_structure`): a label value (NIfTI,
        NRRD, VTI, DICOM series), a segment name (``.seg.nrrd``), a SegmentNumber
        or SegmentLabel (SEG), a ROINumber or ROIName (RTSTRUCT). Default: the
        only structure (label, segment or ROI) of the input.
    roi : int or str, optional
        Another name for ``label`` (``--roi`` of the command line).
    image_dir : path-like, optional
        The image series an RTSTRUCT refers to; its grid is then used.
    allow_irregular : bool
        Accept DICOM series with uneven slice spacing, read on their own or as
        the image series of an RTSTRUCT (see docs/formats.md).
    mesh_resolution : int
        Voxels along the longest side when a mesh is voxelised.
    pixel_spacing : float, optional
        In-plane pixel size, mm, for contour inputs without an image grid.
    memory_budget_gb : float
        Refuse inputs whose grid would not fit this budget, GiB
        (:func:`slicerecon.io.limits.check_grid`).
    union : bool
        Take every non-zero voxel of a label map as one structure.

    Returns
    -------
    Volume or CrossSections
        A dense mask, or the annotated planes of a sparse input.

    Raises
    ------
    InputError
        Missing input or one whose kind cannot be told; its subclasses for
        what the readers find (FormatError, LabelError, GeometryError,
        EmptyMaskError, MemoryBudgetError). A :class:`LabelError` for a label
        map of several structures without ``label`` or ``union``.
    OptionError
        ``label`` and ``roi`` disagree; ``label`` with ``union``;
        ``image_dir`` for an input that is not an RTSTRUCT.
    """
    check_budget(memory_budget_gb)
    selector = _selector(label, roi)
    if union and selector is not None:
        raise OptionError("give a label or union, not both")
    with reading(path):
        kind = detect_kind(path)
        if image_dir is not None and kind.kind != "rtstruct":
            raise OptionError(
                f"an image series applies to RTSTRUCT inputs only; {path} is a {kind.kind} input"
            )
        logger.info("reading %s as %s", kind.path, kind.kind)
        if selector is None and kind.kind in _WHOLE_LABEL_MAPS:
            return _one_structure(kind, union, allow_irregular, memory_budget_gb)
        return _read(
            kind,
            selector,
            image_dir=image_dir,
            allow_irregular=allow_irregular,
            mesh_resolution=mesh_resolution,
            pixel_spacing=pixel_spacing,
            memory_budget_gb=memory_budget_gb,
        )


def world_frame(path: str | os.PathLike[str]) -> str | None:
    """The world frame of an input's coordinates, ``"RAS"`` or ``"LPS"``, by its kind:
    DICOM is LPS, NIfTI and VTI RAS, NRRD its ``space``, a contour file its
    ``"coordinates"`` (RAS without it), a mesh the frame it states
    (:func:`slicerecon.io.mesh.mesh_frame`; None when it states none).

    Raises
    ------
    InputError
        What :func:`detect_kind` raises.
    """
    with reading(path):
        return _frame_of(detect_kind(path))


def _frame_of(kind: InputKind) -> str | None:
    """:func:`world_frame` of an input whose kind is known."""
    if kind.kind == "mesh":
        from .mesh import mesh_frame

        return mesh_frame(kind.path)
    if kind.kind in DICOM_KINDS:
        return "LPS"
    if kind.kind == "nrrd":
        from .nrrd_header import nrrd_info

        return nrrd_info(kind.path).coordinates
    if kind.kind == "contours":
        from .contours import contour_file_frame

        return contour_file_frame(kind.path) or "RAS"
    return "RAS"


def load_ground_truth(
    path: str | os.PathLike[str],
    *,
    label: int | str | None = None,
    allow_irregular: bool = False,
    memory_budget_gb: float = DEFAULT_MEMORY_BUDGET_GB,
    union: bool = False,
    frame: str | None = None,
    truth: bool = False,
) -> Volume | Any:
    """Read a ground truth (or a prediction) to score against: the one loader for both.

    A closed mesh is kept as the **exact mesh** (``trimesh.Trimesh``, world
    mm), so metrics compare against the surface itself, never a voxelisation
    of it; a label map, DICOM series or SEG becomes the :class:`Volume` of the
    chosen structure (as :func:`load_input`). Contour inputs are not a ground
    truth.

    Parameters
    ----------
    path : path-like
        A mesh (``.stl`` / ``.ply`` / ``.obj`` / ``.off``) or a dense mask.
    label, allow_irregular, memory_budget_gb, union
        As for :func:`load_input`.
    frame : {"RAS", "LPS"}, optional
        The world frame to return it in: from its own (:func:`world_frame`), x
        and y change sign where the two differ (a mesh that states no frame is
        taken as it is). Default: its own frame.
    truth : bool
        It is the ground truth: a mask that reads as a sparse annotation is
        refused (:func:`slicerecon.plane_detection.refuse_sparse_truth`).

    Returns
    -------
    Volume or trimesh.Trimesh

    Raises
    ------
    InputError
        What :func:`load_input` raises; a contour input (sparse planes); with
        ``truth``, a mask that reads as a sparse annotation.
    OptionError
        ``frame`` is neither "RAS" nor "LPS".
    """
    if frame not in (None, "RAS", "LPS"):
        raise OptionError(f'frame must be "RAS" or "LPS" (got {frame!r})')
    with reading(path):
        kind = detect_kind(path)
        own = _frame_of(kind) if frame is not None else None
        flip = own is not None and own != frame
        if kind.kind == "mesh":
            from .mesh import read_mesh

            _single_structure(Path(path), parse_selector(label))
            mesh = read_mesh(path)
            if flip:
                mesh.apply_transform(LPS_TO_RAS)
            return mesh
    data = load_input(
        path,
        label=label,
        allow_irregular=allow_irregular,
        memory_budget_gb=memory_budget_gb,
        union=union,
    )
    if not isinstance(data, Volume):
        raise InputError(
            f"{path} holds contours on some planes; a ground truth must be a dense mask "
            "or a closed mesh"
        )
    if truth:
        from ..plane_detection import refuse_sparse_truth

        refuse_sparse_truth(data.mask, data.affine, str(path))
    if flip:
        return Volume(data.mask, LPS_TO_RAS @ data.affine)
    return data


def _selector(label: int | str | None, roi: int | str | None) -> int | str | None:
    chosen = parse_selector(label)
    alias = parse_selector(roi)
    if chosen is not None and alias is not None and chosen != alias:
        raise OptionError(f"--label {label} and --roi {roi} disagree; give one of them")
    return chosen if chosen is not None else alias


def _read(
    kind: InputKind,
    selector: int | str | None,
    *,
    image_dir: str | os.PathLike[str] | None,
    allow_irregular: bool,
    mesh_resolution: int,
    pixel_spacing: float | None,
    memory_budget_gb: float,
) -> Volume | CrossSections:
    """Dispatch to the reader of ``kind``."""
    budget = {"memory_budget_gb": memory_budget_gb}
    if kind.kind == "nifti":
        from .nifti import read_nifti

        return read_nifti(kind.path, label=selector, **budget)
    if kind.kind == "nrrd":
        from .nrrd import read_nrrd

        return read_nrrd(kind.path, label=selector, **budget)
    if kind.kind == "dicom-series":
        from .dicom import read_dicom_series

        return read_dicom_series(
            kind.path, allow_irregular=allow_irregular, label=selector, **budget
        )
    if kind.kind == "dicom-seg":
        from .dicom import read_dicom_seg

        return read_dicom_seg(kind.path, segment=selector, **budget)
    if kind.kind == "rtstruct":
        from .rtstruct import read_rtstruct

        return read_rtstruct(
            kind.path,
            roi=selector,
            image_dir=image_dir if image_dir is not None else kind.image_dir,
            pixel_spacing=pixel_spacing,
            allow_irregular=allow_irregular,
            **budget,
        )
    if kind.kind == "vti":
        return _vti_volume(kind.path, label=selector, memory_budget_gb=memory_budget_gb)
    if kind.kind == "contours":
        from .contours import read_contours

        _single_structure(kind.path, selector)
        return read_contours(kind.path, pixel_spacing=pixel_spacing, **budget)
    from .mesh import read_mesh_volume

    _single_structure(kind.path, selector)
    check_grid((mesh_resolution,) * 3, what=str(kind.path), memory_budget_gb=memory_budget_gb)
    return read_mesh_volume(kind.path, resolution=mesh_resolution)


_WHOLE_LABEL_MAPS = ("nifti", "nrrd", "vti", "dicom-series")
"""Label-map kinds whose every structure :func:`load_input` reads before it takes one."""


def _one_structure(
    kind: InputKind, union: bool, allow_irregular: bool, memory_budget_gb: float
) -> Volume:
    """The one structure of a label map, or all of them merged when ``union``."""
    from .labelmap import read_label_map

    label_map = read_label_map(
        kind.path, allow_irregular=allow_irregular, memory_budget_gb=memory_budget_gb, chosen=union
    )
    assert label_map is not None
    if len(label_map.structures) > 1 and not union:
        listed = ", ".join(s.label for s in label_map.structures[:12])
        more = (
            f" and {len(label_map.structures) - 12} more" if len(label_map.structures) > 12 else ""
        )
        raise LabelError(
            f"{kind.path} holds {len(label_map.structures)} structures ({listed}{more}): "
            "choose one with --label (label=), merge them with --union (union=True), or "
            "reconstruct them all (slicerecon run, or slicerecon.case.reconstruct_structures)"
        )
    return label_map.union()


def _single_structure(path: Path, selector: int | str | None) -> None:
    """Contour files and meshes hold one structure: a selector other than 1 is an error."""
    if selector is not None and selector != 1:
        raise LabelError(
            f"{path} holds one structure; --label {selector} selects nothing in it "
            "(leave --label out)"
        )


def _vti_volume(path: Path, *, label: int | str | None, memory_budget_gb: float) -> Volume:
    """A label map in a VTK XML image (``.vti``): one label, or every non-zero voxel."""
    from .nifti import label_mask
    from .vti import read_vti

    image = read_vti(path, memory_budget_gb=memory_budget_gb)
    return Volume(label_mask(np.asarray(image.values), label, path), image.affine)
