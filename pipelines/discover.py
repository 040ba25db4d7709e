"""Find the cases of a batch in an input directory and give each a safe name.

A *case* is one input that :func:`slicerecon.reconstruct.run_case` reconstructs
on its own. :func:`discover_cases` walks ``INDIR`` (recursively, in sorted
order, skipping hidden files and folders) and finds:

* every file whose name tells a kind :func:`slicerecon.io.detect_kind` reads
  (:data:`slicerecon.io.INPUT_SUFFIXES`): NIfTI (``*.nii``, ``*.nii.gz``),
  NRRD label maps and 3D Slicer segmentations (``*.nrrd``, ``*.seg.nrrd``),
  VTK images (``*.vti``), contour files (``*.json``, ``*.csv``);
* DICOM SEG and RTSTRUCT files: one case each. When one lies in a folder that
  also holds an image series, or whose one subfolder holding images does
  (``pat1/RS.dcm`` beside ``pat1/CT/``), or, alone in its folder, beside one
  folder holding images (``pat1/RTSTRUCT/RS.dcm`` beside ``pat1/CT/``), it is
  read on that series' voxel grid (the images are its reference, not a case of
  their own), unless their FrameOfReferenceUIDs differ;
* DICOM image series: a folder of image files of one series (a mask stored as
  DICOM) is one case, unless the folder also holds an RTSTRUCT or a SEG (then
  the images are the reference those were drawn on);
* a file named like DICOM (``.dcm``, ``.dicom``, ``.ima``) that cannot be read
  in a folder without image files: one case, so that its failure is recorded.

DICOM files are recognised by content, whatever their name, with or without
the 128-byte preamble, by the readers' own sniffer
(:func:`slicerecon.io.dicom.sniff.dicom_role`), so a batch finds exactly the
files ``slicerecon run`` reads.

Meshes (``.stl``, ``.ply``, ``.obj``, ``.off``) are not cases: a batch writes
meshes, and a mesh beside the masks is usually their ground truth. They, the
folders holding a reconstruction's outputs, and every other file that is not
an input are *skipped*: :func:`discover` lists each with the reason
(:class:`SkippedInput`), so nothing is left out without a word. Hidden files
and folders and the excluded folders (``OUTDIR``) are left out by design and
not listed.

Symbolic links
--------------
A link whose target lies inside ``INDIR`` is read like its target (a link to a
folder inside ``INDIR`` is not searched again: that folder is searched anyway,
or deliberately not, when hidden or excluded). A link whose target lies
*outside* ``INDIR`` is not read unless ``follow_symlinks=True`` (nothing under
``INDIR`` may make a batch read files from elsewhere unless asked); it becomes
a case of kind ``"symlink"`` whose :attr:`Case.error` says why, and which a
batch records as failed without opening it:

* a link to a NIfTI or contour file, or to a folder: one such case each;
* links to other files (possibly DICOM): one such case for their folder, and
  that folder's DICOM files make no case (a series without some of its
  slices would be reconstructed wrongly).

A broken link named like an input (NIfTI, contour or DICOM file) is such a case
too. With ``follow_symlinks=True`` every link is read, folders outside
``INDIR`` are searched, and no folder is searched twice (no loops).

Case names
----------
A case's name is its path relative to ``INDIR`` without the format suffix,
made safe by :func:`safe_case_name`: ASCII letters, digits, ``-`` and ``_``
only, folder levels joined by ``__``. A name can therefore never hold a path
separator, ``..``, a dot or a drive, so ``OUTDIR/<name>/`` always lies directly
inside ``OUTDIR``. Inputs whose names without the suffix are the same
(compared case-insensitively: ``liver.nii.gz``, ``liver.csv``) are each named
with their suffix (``liver_nii_gz``, ``liver_csv``), so that adding or removing
one never gives another input's name to a case. Names that still collide, or
that a batch output uses (:data:`RESERVED_NAMES`), get ``-2``, ``-3``, ... in
sorted input order.
"""

from __future__ import annotations

import dataclasses
import hashlib
import logging
import os
import re
import unicodedata
from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path, PurePosixPath, PureWindowsPath
from typing import NamedTuple

from slicerecon.dataset import MANIFEST, load_manifest
from slicerecon.errors import InputError
from slicerecon.io import DETACHED_NRRD, kind_of_name, same_frame, series_below
from slicerecon.io.dicom.sniff import DICOM_SUFFIXES, dicom_role
from slicerecon.results import SUMMARY_COLUMNS, SUMMARY_CSV

__all__ = [
    "CASE_KINDS",
    "RESERVED_NAMES",
    "Case",
    "Discovery",
    "SkippedInput",
    "discover",
    "discover_cases",
    "safe_case_name",
]

logger = logging.getLogger(__name__)

CASE_KINDS = (
    "nifti",
    "nrrd",
    "vti",
    "contours",
    "dicom-series",
    "dicom-seg",
    "rtstruct",
    "dicom-unreadable",
    "symlink",
)
"""The kinds of case :func:`discover_cases` reports (``symlink``: a link that is not
followed; see :attr:`Case.error`)."""

FILE_KINDS = ("nifti", "nrrd", "vti", "contours")
"""Kinds told by a file's name (:func:`slicerecon.io.kind_of_name`) that make one case per file."""
FOLLOW_HINT = (
    "copy the data into INDIR, or pass --follow-symlinks if you trust where the links point"
)
"""How to read a link that was not followed (ends :attr:`Case.error`)."""
MAX_NAME_LENGTH = 96
"""Longest case name; longer ones are cut and get a hash of the full name."""

RESERVED_NAMES = frozenset({"report_assets"})
"""Names of batch-level outputs in OUTDIR (the HTML report's figure folder); a case
that would get one of them is numbered instead (``report_assets-2``)."""
_UNSAFE = re.compile(r"[^A-Za-z0-9_-]+")
_RESERVED = frozenset(
    {"con", "prn", "aux", "nul"} | {f"com{i}" for i in range(10)} | {f"lpt{i}" for i in range(10)}
)


@dataclass(frozen=True)
class Case:
    """One input of a batch.

    Attributes
    ----------
    name : str
        Safe, unique name; outputs go to ``OUTDIR/<name>/``.
    path : Path
        What :func:`~slicerecon.reconstruct.run_case` reads: a file, or the
        folder of a DICOM series.
    kind : str
        One of :data:`CASE_KINDS`.
    relpath : str
        ``path`` relative to the input directory (POSIX separators), as shown
        in ``summary.csv``.
    files : tuple of Path
        Every file whose bytes determine the output (the input file; all
        files of a series folder; an RTSTRUCT and the images of its grid).
        Their names and bytes make the resume key.
    root : Path
        Folder that names in ``files`` are taken relative to when hashing.
    image_dir : Path or None
        For an RTSTRUCT beside an image series: that folder (its voxel grid).
    error : str
        Why the case cannot be read, for a symbolic link that is not followed
        (kind ``symlink``; ``files`` is then empty); empty otherwise.
    """

    name: str
    path: Path
    kind: str
    relpath: str
    files: tuple[Path, ...]
    root: Path
    image_dir: Path | None = None
    error: str = ""


@dataclass(frozen=True)
class SkippedInput:
    """A file or folder of ``INDIR`` that is not a case, and why.

    Attributes
    ----------
    relpath : str
        Its path relative to ``INDIR`` (POSIX separators).
    reason : str
        Why it is not a case, in a few words.
    """

    relpath: str
    reason: str


class Discovery(NamedTuple):
    """What :func:`discover` found: the cases, and every entry left out with its reason."""

    cases: list[Case]
    skipped: list[SkippedInput]


MESH_REASON = "a mesh: meshes are outputs or ground truths, not batch inputs"
NOT_INPUT_REASON = "not an input format (NIfTI, NRRD, VTI, contours or DICOM)"
OTHER_DICOM_REASON = "a DICOM object that is not an image, SEG or RTSTRUCT"
OUTPUT_REASON = "a reconstruction's outputs (it holds plan.json, or a batch's summary.csv)"
MANIFEST_REASON = "the dataset's manifest (slicerecon dataset make), not a contour file"


def safe_case_name(relpath: str | os.PathLike[str]) -> str:
    """Turn a relative input path into a name that is safe as one folder in OUTDIR.

    Parameters
    ----------
    relpath : str or path-like
        Path of the input relative to the input directory, with or without its
        suffix. Absolute paths, drive letters, ``..`` and ``.`` parts are
        accepted and neutralised (dropped), never followed.

    Returns
    -------
    str
        A non-empty name of ASCII letters, digits, ``-`` and ``_``; folder
        levels are joined by ``__``. Accents are dropped (``Müller`` →
        ``Muller``); other characters become ``_``; a part with nothing left
        (e.g. only CJK letters) becomes ``u`` plus 8 hex digits of its hash, so
        different names stay different. Names longer than
        :data:`MAX_NAME_LENGTH` are cut and end in a hash of the full name.

    Examples
    --------
    >>> safe_case_name("../../etc/passwd")
    'etc__passwd'
    >>> safe_case_name("patient 01/ct.v2")
    'patient_01__ct_v2'
    """
    text = os.fspath(relpath)
    parts: list[str] = []
    for raw in PureWindowsPath(text).parts if "\\" in text else PurePosixPath(text).parts:
        raw = raw.strip().strip("/\\")
        if raw in ("", ".", ".."):
            continue
        ascii_text = unicodedata.normalize("NFKD", raw).encode("ascii", "ignore").decode("ascii")
        part = _UNSAFE.sub("_", ascii_text)
        part = re.sub(r"_{2,}", "_", part).strip("_-")
        if not part:
            part = "u" + hashlib.sha256(raw.encode("utf-8", "surrogatepass")).hexdigest()[:8]
        if part.lower() in _RESERVED:
            part = f"_{part}"
        parts.append(part)
    name = "__".join(parts) or "case"
    if len(name) > MAX_NAME_LENGTH:
        digest = hashlib.sha256(text.encode("utf-8", "surrogatepass")).hexdigest()[:8]
        name = f"{name[: MAX_NAME_LENGTH - 9]}-{digest}"
    return name


def _strip_suffix(name: str) -> str:
    named = kind_of_name(PurePosixPath(name).name)
    if named is not None:
        return name[: -len(named[1])]
    lower = name.lower()
    for suffix in DICOM_SUFFIXES:
        if lower.endswith(suffix) and len(name) > len(suffix):
            return name[: -len(suffix)]
    return name


def _relpath(path: Path, root: Path) -> str:
    return path.relative_to(root).as_posix()


def _folder_cases(
    folder: Path, files: list[Path], root: Path, *, dicom_files: bool = True
) -> tuple[list[tuple[str, Case]], list[SkippedInput]]:
    """Cases in one folder (not recursing), keyed by their unsanitised base name, and
    the files of the folder that are not inputs.

    With ``dicom_files=False`` only files whose name tells their kind make cases
    (the folder's other files are not opened; the caller says why).
    """
    found: list[tuple[str, Case]] = []
    skipped: list[SkippedInput] = []
    dicom: dict[str, list[Path]] = {}
    for f in files:
        rel = _relpath(f, root)
        named = kind_of_name(f.name)
        if f.name == MANIFEST and _is_manifest(f):
            skipped.append(SkippedInput(rel, MANIFEST_REASON))
            continue
        if named is not None:
            kind, suffix = named
            if kind in FILE_KINDS:
                found.append((rel[: -len(suffix)], Case("", f, kind, rel, (f,), f.parent)))
            else:
                skipped.append(SkippedInput(rel, MESH_REASON))
            continue
        if not dicom_files:
            continue
        if f.name.lower().endswith(".nhdr"):
            skipped.append(SkippedInput(rel, DETACHED_NRRD))
            continue
        role = dicom_role(f)
        if role is None:
            skipped.append(SkippedInput(rel, NOT_INPUT_REASON))
        else:
            dicom.setdefault(role, []).append(f)
    images = dicom.get("image", [])
    annotations = dicom.get("seg", []) + dicom.get("rtstruct", [])
    # files whose bytes define a series folder: every readable or DICOM-named file in it
    series_files = tuple(
        sorted(images + dicom.get("unreadable", []) + dicom.get("other", []) + annotations)
    )
    # an RTSTRUCT or SEG of another frame of reference (another study) does not take the
    # images: it is read alone, and the images are a case of their own
    paired = [f for f in annotations if not images or same_frame(f, folder)]
    if images and not paired:
        rel = _relpath(folder, root) if folder != root else folder.name
        found.append((rel, Case("", folder, "dicom-series", rel, series_files, folder)))
    elif not images:
        for f in dicom.get("unreadable", []):
            rel = _relpath(f, root)
            found.append((_strip_suffix(rel), Case("", f, "dicom-unreadable", rel, (f,), folder)))
    if not images:
        skipped += [
            SkippedInput(_relpath(f, root), OTHER_DICOM_REASON) for f in dicom.get("other", [])
        ]
    reference = tuple(sorted(images + dicom.get("unreadable", []))) if images else ()
    for kind, role in (("dicom-seg", "seg"), ("rtstruct", "rtstruct")):
        for f in dicom.get(role, []):
            rel = _relpath(f, root)
            on = images and f in paired
            case = Case(
                "", f, kind, rel, (f, *reference) if on else (f,), folder, folder if on else None
            )
            found.append((_strip_suffix(rel), case))
    return found, skipped


def _is_manifest(path: Path) -> bool:
    """Whether ``path`` is a dataset's manifest (``slicerecon dataset make``)."""
    try:
        load_manifest(path.parent)
    except (OSError, ValueError, InputError):
        return False
    return True


def _pair_series_below(
    found: list[tuple[str, Case]], root: Path
) -> tuple[list[tuple[str, Case]], list[SkippedInput]]:
    """An RTSTRUCT or SEG in a folder without images takes the one image series in a
    subfolder of it (``pat1/RS.dcm`` beside ``pat1/CT/``: :func:`slicerecon.io.series_below`,
    as ``slicerecon run pat1`` reads it), or, alone in its folder, the one series in a
    folder beside it (``pat1/RTSTRUCT/RS.dcm`` beside ``pat1/CT/``, as PACS exports a
    study); that series is then its reference, not a case. Of several such series, it
    takes the one it names as its own; the other image series beside it that no file
    takes are skipped (a scout, another reconstruction, a registered MR: images of the
    study, not label maps)."""
    out = list(found)
    claimed: set[int] = set()
    passed_over: dict[int, SkippedInput] = {}
    series_folders = {case.path for _, case in found if case.kind == "dicom-series"}
    for n, (base, case) in enumerate(found):
        if case.kind not in ("rtstruct", "dicom-seg") or case.image_dir is not None:
            continue
        folder = case.path.parent
        below = series_below(folder, case.path, quiet=True)
        # a folder of drawings only (SEG/ or RTSTRUCT/ beside CT/, one file or several)
        drawings_only = folder not in series_folders
        if below is None and drawings_only and folder != root and _within(folder.parent, root):
            below = series_below(folder.parent, case.path, quiet=True)
        if below is not None and not same_frame(case.path, below):
            continue  # another study's images
        if below is not None:
            for m, (_, other) in enumerate(found):
                if (
                    other.kind == "dicom-series"
                    and other.path != below
                    and other.path.parent == below.parent
                ):
                    # a scout, another reconstruction, a registered MR: images of the
                    # study, not masks (a CT or MR read as a label map fails)
                    same = same_frame(case.path, other.path, rois=True)
                    frame = "" if same else " (another frame)"
                    passed_over[m] = SkippedInput(
                        other.relpath,
                        f"another image series{frame} of the study of {case.relpath}, which "
                        f"was drawn on {_relpath(below, root)}",
                    )
        m = next(
            (
                m
                for m, (_, other) in enumerate(found)
                if other.kind == "dicom-series" and other.path == below
            ),
            None,
        )
        if m is None:
            continue
        claimed.add(m)
        images = found[m][1]
        files = (case.path, *images.files)
        out[n] = (base, dataclasses.replace(case, files=files, image_dir=images.path))
    skipped = [item for m, item in passed_over.items() if m not in claimed]
    gone = claimed | set(passed_over)
    return [item for n, item in enumerate(out) if n not in gone], skipped


@dataclass(frozen=True)
class _Link:
    """A symbolic link that was not followed: ``kind`` is file, folder or broken."""

    path: Path
    target: Path
    kind: str


@dataclass(frozen=True)
class _Folder:
    """One searched folder: its files and the links in it that were not followed."""

    path: Path
    files: list[Path]
    links: list[_Link]
    outputs: bool = False


def _within(path: Path, folder: Path) -> bool:
    return path == folder or folder in path.parents


OUTPUT_MARKER = "plan.json"
"""A folder holding this file is a case slicerecon wrote (its ``labels.nii.gz``
and meshes are outputs): it and its subfolders are not searched for inputs; nor
is a batch's results folder (a ``summary.csv`` with the runner's header)."""


def _batch_results(folder: Path, names: list[str]) -> bool:
    """Whether ``folder`` is a batch's results (its ``summary.csv`` has the runner's header)."""
    if SUMMARY_CSV not in names:
        return False
    try:
        with (folder / SUMMARY_CSV).open(encoding="utf-8") as handle:
            header = handle.readline().strip()
    except (OSError, UnicodeDecodeError):
        return False
    return header.split(",")[:4] == list(SUMMARY_COLUMNS[:4])


def _walk(root: Path, skip: Iterable[Path], *, follow_symlinks: bool) -> list[_Folder]:
    """Search ``root`` (sorted, hidden entries skipped) applying the symlink rules."""
    real_root = root.resolve()
    skipped = [p.resolve() for p in skip]
    searched = {real_root}
    out: list[_Folder] = []

    def excluded(real: Path) -> bool:
        return any(_within(real, s) for s in skipped)

    for here, dirs, names in os.walk(root, followlinks=True):
        folder = Path(here)
        if OUTPUT_MARKER in names or _batch_results(folder, names):  # outputs, not inputs
            logger.debug("not searching %s: it holds a reconstruction's outputs", folder)
            dirs[:] = []
            out.append(_Folder(folder, [], [], outputs=True))
            continue
        links: list[_Link] = []
        keep: list[str] = []
        for d in sorted(dirs):
            path = folder / d
            real = path.resolve()
            if d.startswith(".") or excluded(real):
                continue
            if not path.is_symlink():
                searched.add(real)
                keep.append(d)
            elif _within(real, real_root):
                logger.debug("not searching %s again: it links to %s, inside INDIR", path, real)
            elif not follow_symlinks:
                links.append(_Link(path, real, "folder"))
            elif real in searched or any(_within(real, s) for s in searched if s != real_root):
                logger.info("not searching %s: %s is searched already", path, real)
            else:
                searched.add(real)
                keep.append(d)
        dirs[:] = keep
        files: list[Path] = []
        for n in sorted(names):
            path = folder / n
            if n.startswith("."):
                continue
            if path.is_symlink():
                real = Path(os.path.realpath(path))
                if not real.exists():
                    links.append(_Link(path, real, "broken"))
                    continue
                if excluded(real):
                    continue
                if not follow_symlinks and not _within(real, real_root):
                    links.append(_Link(path, real, "file"))
                    continue
            if path.is_file():
                files.append(path)
        out.append(_Folder(folder, files, links))
    return out


def _link_cases(
    folder: _Folder, root: Path
) -> tuple[list[tuple[str, Case]], list[SkippedInput], bool]:
    """Cases for the links of ``folder`` that were not followed, the links that are
    not inputs, and whether some of them may be DICOM files (then the folder's
    DICOM files make no case)."""
    found: list[tuple[str, Case]] = []
    skipped: list[SkippedInput] = []
    grouped: list[_Link] = []
    for link in folder.links:
        rel = _relpath(link.path, root)
        lower = link.path.name.lower()
        named = kind_of_name(link.path.name)
        hint = FOLLOW_HINT
        if link.kind == "folder":
            why = (
                f"{rel} is a symbolic link to a folder outside INDIR ({link.target}); "
                "it was not searched"
            )
        elif link.kind == "broken":
            if (named is None or named[0] == "mesh") and not lower.endswith(DICOM_SUFFIXES):
                logger.info("ignoring %s: a broken symbolic link to %s", link.path, link.target)
                skipped.append(SkippedInput(rel, f"a broken symbolic link to {link.target}"))
                continue
            why = f"{rel} is a broken symbolic link: its target {link.target} does not exist"
            hint = "fix or remove the link"
        elif named is not None and named[0] not in FILE_KINDS:
            skipped.append(SkippedInput(rel, MESH_REASON))  # never a case
            continue
        elif named is not None:
            why = (
                f"{rel} is a symbolic link to a file outside INDIR ({link.target}); it was not read"
            )
        else:
            grouped.append(link)
            continue
        logger.info("not reading %s", why)
        case = Case("", link.path, "symlink", rel, (), link.path.parent, error=f"{why}; {hint}")
        found.append((_strip_suffix(rel), case))
    if grouped:
        rel = _relpath(folder.path, root) if folder.path != root else folder.path.name
        names = ", ".join(link.path.name for link in grouped[:3])
        if len(grouped) > 3:
            names += f" and {len(grouped) - 3} more"
        why = (
            f"{rel} holds {len(grouped)} symbolic link(s) to files outside INDIR ({names}); "
            "they were not read, and the DICOM files of this folder were not used"
        )
        logger.info("not reading %s", why)
        case = Case("", folder.path, "symlink", rel, (), folder.path, error=f"{why}; {FOLLOW_HINT}")
        found.append((rel, case))
    return found, skipped, bool(grouped)


def discover(
    indir: str | os.PathLike[str],
    *,
    exclude: Iterable[str | os.PathLike[str]] = (),
    follow_symlinks: bool = False,
) -> Discovery:
    """The cases in ``indir`` in a stable, sorted order, and what is not a case.

    Parameters
    ----------
    indir : path-like
        The input directory (searched recursively; hidden entries skipped).
    exclude : iterable of path-like
        Folders not to search (e.g. an output directory inside ``indir``).
    follow_symlinks : bool
        Read symbolic links whose target lies outside ``indir`` (and search
        such folders). By default they are not read: each becomes a case of
        kind ``symlink`` with :attr:`Case.error` set (see the module
        docstring). Links that stay inside ``indir`` are always read.

    Returns
    -------
    Discovery
        ``cases``: sorted by relative input path, names unique
        (case-insensitively). ``skipped``: every file (or output folder) of
        ``indir`` that is no case and no part of one, with the reason, sorted
        by path; hidden entries and the ``exclude`` folders are not listed.

    Raises
    ------
    InputError
        If ``indir`` does not exist or is not a directory.
    """
    root = Path(indir)
    if not root.exists():
        raise InputError(f"input directory not found: {root}")
    if not root.is_dir():
        raise InputError(f"{root} is not a directory; pass the folder that holds the cases")
    found: list[tuple[str, Case]] = []
    skipped: list[SkippedInput] = []
    for folder in _walk(root, [Path(p) for p in exclude], follow_symlinks=follow_symlinks):
        if folder.outputs:
            skipped.append(SkippedInput(_relpath(folder.path, root) or ".", OUTPUT_REASON))
            continue
        refused, links_skipped, some_dicom = _link_cases(folder, root)
        found.extend(refused)
        skipped.extend(links_skipped)
        cases_here, skipped_here = _folder_cases(
            folder.path, folder.files, root, dicom_files=not some_dicom
        )
        found.extend(cases_here)
        skipped.extend(skipped_here)
    found, passed_over = _pair_series_below(found, root)
    skipped.extend(passed_over)
    found.sort(key=lambda item: item[1].relpath)
    cases: list[Case] = []
    taken: set[str] = {name.casefold() for name in RESERVED_NAMES}
    names = [safe_case_name(base) for base, _ in found]
    shared = Counter(name.casefold() for name in names)
    for (base, case), name in zip(found, names, strict=True):
        if shared[name.casefold()] > 1:
            # inputs that differ only in their format (liver.nii.gz, liver.csv) are named
            # with it, so adding or removing one never renames another
            name = safe_case_name(case.relpath)
        unique, n = name, 1
        while unique.casefold() in taken:
            n += 1
            unique = f"{name}-{n}"
        taken.add(unique.casefold())
        if unique != base:
            logger.debug("case %s is named %s", case.relpath, unique)
        cases.append(dataclasses.replace(case, name=unique))
    skipped.sort(key=lambda item: item.relpath)
    for item in skipped:
        logger.info("not a case: %s: %s", item.relpath, item.reason)
    logger.info("found %d case(s) in %s; %d entries skipped", len(cases), root, len(skipped))
    return Discovery(cases, skipped)


def discover_cases(
    indir: str | os.PathLike[str],
    *,
    exclude: Iterable[str | os.PathLike[str]] = (),
    follow_symlinks: bool = False,
) -> list[Case]:
    """The cases of :func:`discover` (same parameters), without the skipped entries."""
    return discover(indir, exclude=exclude, follow_symlinks=follow_symlinks).cases
