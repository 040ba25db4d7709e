"""Find the cases of a batch in an input directory and give each a safe name.

A *case* is one input that :func:`slicerecon.reconstruct.run_case` reconstructs
on its own. :func:`discover_cases` walks ``INDIR`` (recursively, in sorted
order, skipping hidden files and folders) and finds:

* NIfTI masks: ``*.nii``, ``*.nii.gz``;
* contour files: ``*.json``, ``*.csv``;
* DICOM SEG files: one case each;
* DICOM RTSTRUCT files: one case each. When the RTSTRUCT lies in a folder that
  also holds an image series, the contours are read on that series' voxel grid
  (the images are its reference, not a case of their own);
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
meshes, and an output directory inside ``INDIR`` must not be read back as
input. Other files are ignored.

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
inside ``OUTDIR``. Names that collide (compared case-insensitively) or
that a batch output uses (:data:`RESERVED_NAMES`) get ``-2``, ``-3``, ... in
sorted input order.
"""

from __future__ import annotations

import dataclasses
import hashlib
import logging
import os
import re
import unicodedata
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path, PurePosixPath, PureWindowsPath

from slicerecon.errors import InputError
from slicerecon.io.dicom.sniff import DICOM_SUFFIXES, dicom_role

__all__ = ["CASE_KINDS", "RESERVED_NAMES", "Case", "discover_cases", "safe_case_name"]

logger = logging.getLogger(__name__)

CASE_KINDS = (
    "nifti",
    "contours",
    "dicom-series",
    "dicom-seg",
    "rtstruct",
    "dicom-unreadable",
    "symlink",
)
"""The kinds of case :func:`discover_cases` reports (``symlink``: a link that is not
followed; see :attr:`Case.error`)."""

NIFTI_SUFFIXES = (".nii.gz", ".nii")
CONTOUR_SUFFIXES = (".json", ".csv")
MESH_SUFFIXES = (".stl", ".ply", ".obj", ".off")
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
    lower = name.lower()
    for suffix in (*NIFTI_SUFFIXES, *CONTOUR_SUFFIXES, *DICOM_SUFFIXES):
        if lower.endswith(suffix) and len(name) > len(suffix):
            return name[: -len(suffix)]
    return name


def _relpath(path: Path, root: Path) -> str:
    return path.relative_to(root).as_posix()


def _folder_cases(
    folder: Path, files: list[Path], root: Path, *, dicom_files: bool = True
) -> list[tuple[str, Case]]:
    """Cases in one folder (not recursing), keyed by their unsanitised base name.

    With ``dicom_files=False`` only NIfTI and contour files make cases (the
    folder's DICOM files are not opened).
    """
    found: list[tuple[str, Case]] = []
    dicom: dict[str, list[Path]] = {}
    for f in files:
        lower = f.name.lower()
        rel = _relpath(f, root)
        if lower.endswith(NIFTI_SUFFIXES):
            found.append((_strip_suffix(rel), Case("", f, "nifti", rel, (f,), f.parent)))
            continue
        if lower.endswith(CONTOUR_SUFFIXES):
            found.append((_strip_suffix(rel), Case("", f, "contours", rel, (f,), f.parent)))
            continue
        if not dicom_files:
            continue
        role = dicom_role(f)
        if role is not None:
            dicom.setdefault(role, []).append(f)
    images = dicom.get("image", [])
    annotations = dicom.get("seg", []) + dicom.get("rtstruct", [])
    # files whose bytes define a series folder: every readable or DICOM-named file in it
    series_files = tuple(
        sorted(images + dicom.get("unreadable", []) + dicom.get("other", []) + annotations)
    )
    if images and not annotations:
        rel = _relpath(folder, root) if folder != root else folder.name
        found.append((rel, Case("", folder, "dicom-series", rel, series_files, folder)))
    elif not images:
        for f in dicom.get("unreadable", []):
            rel = _relpath(f, root)
            found.append((_strip_suffix(rel), Case("", f, "dicom-unreadable", rel, (f,), folder)))
    for f in dicom.get("seg", []):
        rel = _relpath(f, root)
        found.append((_strip_suffix(rel), Case("", f, "dicom-seg", rel, (f,), folder)))
    reference = tuple(sorted(images + dicom.get("unreadable", []))) if images else ()
    for f in dicom.get("rtstruct", []):
        rel = _relpath(f, root)
        case = Case("", f, "rtstruct", rel, (f, *reference), folder, folder if images else None)
        found.append((_strip_suffix(rel), case))
    return found


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


def _within(path: Path, folder: Path) -> bool:
    return path == folder or folder in path.parents


OUTPUT_MARKER = "plan.json"
"""A folder holding this file is a case slicerecon wrote (its ``labels.nii.gz``
and meshes are outputs): it and its subfolders are not searched for inputs."""


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
        if OUTPUT_MARKER in names:  # a case folder slicerecon wrote: outputs, not inputs
            logger.debug("not searching %s: it holds a reconstruction's outputs", folder)
            dirs[:] = []
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


def _link_cases(folder: _Folder, root: Path) -> tuple[list[tuple[str, Case]], bool]:
    """Cases for the links of ``folder`` that were not followed, and whether some
    of them may be DICOM files (then the folder's DICOM files make no case)."""
    found: list[tuple[str, Case]] = []
    grouped: list[_Link] = []
    for link in folder.links:
        rel = _relpath(link.path, root)
        lower = link.path.name.lower()
        hint = FOLLOW_HINT
        if link.kind == "folder":
            why = (
                f"{rel} is a symbolic link to a folder outside INDIR ({link.target}); "
                "it was not searched"
            )
        elif link.kind == "broken":
            if not lower.endswith(NIFTI_SUFFIXES + CONTOUR_SUFFIXES + DICOM_SUFFIXES):
                logger.info("ignoring %s: a broken symbolic link to %s", link.path, link.target)
                continue
            why = f"{rel} is a broken symbolic link: its target {link.target} does not exist"
            hint = "fix or remove the link"
        elif lower.endswith(MESH_SUFFIXES):
            continue  # never a case
        elif lower.endswith(NIFTI_SUFFIXES + CONTOUR_SUFFIXES):
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
    return found, bool(grouped)


def discover_cases(
    indir: str | os.PathLike[str],
    *,
    exclude: Iterable[str | os.PathLike[str]] = (),
    follow_symlinks: bool = False,
) -> list[Case]:
    """List the cases in ``indir`` in a stable, sorted order.

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
    list of Case
        Sorted by relative input path; names unique (case-insensitively).

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
    for folder in _walk(root, [Path(p) for p in exclude], follow_symlinks=follow_symlinks):
        refused, some_dicom = _link_cases(folder, root)
        found.extend(refused)
        found.extend(_folder_cases(folder.path, folder.files, root, dicom_files=not some_dicom))
    found.sort(key=lambda item: item[1].relpath)
    cases: list[Case] = []
    taken: set[str] = {name.casefold() for name in RESERVED_NAMES}
    for base, case in found:
        name = safe_case_name(base)
        unique, n = name, 1
        while unique.casefold() in taken:
            n += 1
            unique = f"{name}-{n}"
        taken.add(unique.casefold())
        if unique != base:
            logger.debug("case %s is named %s", case.relpath, unique)
        cases.append(dataclasses.replace(case, name=unique))
    logger.info("found %d case(s) in %s", len(cases), root)
    return cases
