"""Datasets of shape masks on disk: one NIfTI per case and a ``manifest.json``.

:func:`make_dataset` writes procedural shapes (:mod:`slicerecon.shapes`),
``per_shape`` seeded variants of each, and optionally real shapes
(:mod:`slicerecon.realshapes`, one case each), as ``<outdir>/<case>.nii.gz``
masks (0/1, ``uint8``, affine in mm) plus ``<outdir>/manifest.json``::

    {"format": "slicerecon-dataset", "version": 1, "slicerecon": "0.1.0",
     "options": {"shapes": [...], "per_shape": 4, "seed": 0, "size": 64,
                 "spacing": [1.0, 1.0, 1.0], "margin": 3},
     "cases": [{"case": "chair_000", "file": "chair_000.nii.gz", "shape": "chair",
                "family": "furniture", "seed": 123456789, "params": {...},
                "grid": [70, 70, 70], "spacing_mm": [...], "voxels": 12345,
                "volume_mm3": 67890.0, "analytic_volume_mm3": null}, ...]}

Case seeds are derived from ``(seed, shape name, index)`` with
:class:`numpy.random.SeedSequence`, so datasets made with different ``seed``
values share no case, and ``make_shape(shape, seed=case_seed,
resolution=size, spacing=spacing, margin=margin)`` rebuilds any case exactly.
Every file is written atomically; the manifest is written last, so a
directory with a manifest is complete.
"""

from __future__ import annotations

import json
import logging
import os
import zlib
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from . import __version__
from .errors import FormatError, InputError, OptionError
from .io.atomic import atomic_path
from .shapes import (
    FAMILIES,
    SHAPES,
    analytic_volume,
    family_of,
    make_shape,
    shape_names,
    shape_params,
)

__all__ = [
    "MANIFEST",
    "DATASET_FORMAT",
    "case_seed",
    "load_manifest",
    "make_dataset",
    "resolve_shapes",
]

logger = logging.getLogger(__name__)

MANIFEST = "manifest.json"
"""Name of the manifest file in a dataset directory."""

DATASET_FORMAT = "slicerecon-dataset"
"""Value of the manifest's ``format`` key."""

_VERSION = 1
REAL_FAMILY = "real"
"""Pseudo-family naming every real shape whose source package is installed."""

Progress = Callable[[int, int, str], None]
"""Callback ``(cases done, cases in all, case name)`` called after each case."""


def case_seed(seed: int, shape: str, index: int) -> int:
    """The seed of case ``index`` of ``shape`` in a dataset made with ``seed``.

    Parameters
    ----------
    seed : int
        The dataset seed (>= 0).
    shape : str
        Shape name.
    index : int
        Case number of that shape, from 0.

    Returns
    -------
    int
        A seed in ``[0, 2**32)``, a function of all three arguments.
    """
    entropy = [int(seed), zlib.crc32(shape.encode("utf-8")), int(index)]
    return int(np.random.SeedSequence(entropy).generate_state(1, dtype=np.uint32)[0])


def resolve_shapes(shapes: str | Sequence[str] | None) -> list[str]:
    """Expand shape and family names into registered shape names, in order, without repeats.

    Parameters
    ----------
    shapes : str, sequence of str or None
        Shape names (:data:`slicerecon.shapes.SHAPES`), family names
        (:data:`slicerecon.shapes.FAMILIES`), real shape names
        (:data:`slicerecon.realshapes.REAL_SHAPES`) or ``"real"`` (every real
        shape whose package is installed). A string may hold several,
        comma-separated. None: every procedural shape.

    Returns
    -------
    list of str

    Raises
    ------
    OptionError
        If a name is unknown or nothing is selected.
    """
    from .realshapes import REAL_SHAPES, available_real_shapes

    if shapes is None:
        return shape_names()
    items = shapes.split(",") if isinstance(shapes, str) else list(shapes)
    out: list[str] = []
    for raw in items:
        if not isinstance(raw, str):
            raise OptionError(f"shape names must be strings (got {raw!r})")
        item = raw.strip()
        if not item:
            continue
        if item in FAMILIES:
            names: Sequence[str] = FAMILIES[item]
        elif item == REAL_FAMILY:
            names = available_real_shapes()
        elif item in SHAPES or item in REAL_SHAPES:
            names = [item]
        else:
            raise OptionError(
                f"unknown shape or family {item!r}; families: {', '.join(FAMILIES)}, "
                f"{REAL_FAMILY}; run `slicerecon dataset list` for the shapes"
            )
        out.extend(n for n in names if n not in out)
    if not out:
        raise OptionError("no shape selected; pass shape or family names")
    return out


def load_manifest(directory: str | os.PathLike[str]) -> dict[str, Any]:
    """Read and check the manifest of a dataset directory.

    Parameters
    ----------
    directory : path-like
        A directory written by :func:`make_dataset`.

    Returns
    -------
    dict
        The manifest (``format``, ``version``, ``options``, ``cases``).

    Raises
    ------
    InputError
        If the directory or its manifest does not exist.
    FormatError
        If the manifest is not valid JSON or not a slicerecon dataset manifest.
    """
    folder = Path(directory)
    path = folder / MANIFEST
    if not folder.is_dir():
        raise InputError(f"dataset directory not found: {folder}")
    if not path.is_file():
        raise InputError(f"{folder} is not a slicerecon dataset: it has no {MANIFEST}")
    try:
        manifest = json.loads(path.read_text(encoding="utf-8"))
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise FormatError(f"{path} is not valid JSON ({exc}); re-make the dataset") from exc
    if not isinstance(manifest, dict) or manifest.get("format") != DATASET_FORMAT:
        raise FormatError(
            f"{path} is not a slicerecon dataset manifest (no format {DATASET_FORMAT!r})"
        )
    if not isinstance(manifest.get("cases"), list):
        raise FormatError(f"{path} has no list of cases")
    return manifest


def _check_int(value: object, name: str, low: int, high: int | None = None) -> int:
    if (
        isinstance(value, bool)
        or not isinstance(value, int | np.integer)
        or value < low
        or (high is not None and value > high)
    ):
        upper = "" if high is None else f" and <= {high}"
        raise OptionError(f"{name} must be a whole number >= {low}{upper} (got {value!r})")
    return int(value)


def _prepare(folder: Path, overwrite: bool) -> list[str]:
    """Check that ``folder`` may be written; return the case files of an old dataset there."""
    if folder.exists() and not folder.is_dir():
        raise InputError(f"{folder} exists and is not a directory")
    if not folder.exists() or not any(folder.iterdir()):
        return []
    if (folder / MANIFEST).is_file():
        try:
            old = load_manifest(folder)
        except FormatError:
            if not overwrite:
                raise
            return []
        return [str(c.get("file")) for c in old["cases"] if isinstance(c, dict)]
    if not overwrite:
        raise InputError(
            f"{folder} is not empty and is not a slicerecon dataset; pick an empty or new "
            "directory, or pass overwrite=True (--overwrite) to write into it anyway"
        )
    return []


def make_dataset(
    outdir: str | os.PathLike[str],
    *,
    shapes: str | Sequence[str] | None = None,
    per_shape: int = 1,
    seed: int = 0,
    size: int | None = None,
    spacing: float | Sequence[float] = 1.0,
    margin: int = 3,
    overwrite: bool = False,
    progress: Progress | None = None,
) -> Path:
    """Write a dataset of shape masks: ``<outdir>/<case>.nii.gz`` and ``manifest.json``.

    Parameters
    ----------
    outdir : path-like
        Output directory; created if needed. It must be new, empty or a
        previous dataset (whose case files are then replaced), unless
        ``overwrite`` is set.
    shapes : str, sequence of str or None
        Shapes, families, real shapes or ``"real"`` (see :func:`resolve_shapes`).
        Default: every procedural shape.
    per_shape : int, default 1
        Seeded variants per procedural shape (1 to 100000). Real shapes give
        one case each.
    seed : int, default 0
        Dataset seed; case seeds follow from it (:func:`case_seed`).
    size : int, optional
        Largest extent of each shape in voxels (8 to 2048); the voxel size
        follows, keeping the shape in mm (``resolution`` of
        :func:`slicerecon.shapes.make_shape`; for real shapes, the resolution
        of their loader). Default: ``spacing`` as given, real shapes at their
        own resolution.
    spacing : float or sequence of 3 floats, default 1
        Voxel size, mm (with ``size``: only the voxel shape).
    margin : int, default 3
        Background voxels around each shape.
    overwrite : bool, default False
        Write into a non-empty directory that is not a dataset (files there
        are left alone unless a case has the same name).
    progress : callable, optional
        Called as ``progress(done, total, case)`` after each case.

    Returns
    -------
    Path
        The manifest file.

    Raises
    ------
    InputError
        If ``outdir`` is a file, or a non-empty non-dataset directory without
        ``overwrite``.
    OptionError
        If a shape name or an option is invalid.
    DependencyError
        If a requested real shape's package is missing.
    """
    from .io.nifti import write_nifti
    from .realshapes import REAL_SHAPES, real_shape

    folder = Path(outdir)
    names = resolve_shapes(shapes)
    count = _check_int(per_shape, "per_shape", 1, 100_000)
    base_seed = _check_int(seed, "seed", 0)
    margin = _check_int(margin, "margin", 0)
    if size is not None:
        size = _check_int(size, "size", 8, 2048)
    if isinstance(spacing, int | float | np.integer | np.floating):
        spacing_list = [float(spacing)] * 3
    else:
        spacing_list = [float(s) for s in spacing]
    if len(spacing_list) != 3 or not all(np.isfinite(spacing_list)) or min(spacing_list) <= 0:
        raise OptionError(f"spacing must be one or three positive sizes in mm (got {spacing!r})")
    stale = _prepare(folder, bool(overwrite))
    folder.mkdir(parents=True, exist_ok=True)

    plan: list[tuple[str, str, int | None]] = []
    for name in names:
        if name in SHAPES:
            plan += [(f"{name}_{k:03d}", name, case_seed(base_seed, name, k)) for k in range(count)]
        else:
            plan.append((name, name, None))
    cases: list[dict[str, Any]] = []
    for done, (case, name, case_seed_) in enumerate(plan, start=1):
        if name in REAL_SHAPES:
            options: dict[str, Any] = {"margin": margin}
            if size is not None:
                options["resolution"] = size
            volume = real_shape(name, **options)
            family, params, exact = "real", options, None
        else:
            volume = make_shape(
                name, seed=case_seed_, spacing=tuple(spacing_list), margin=margin, resolution=size
            )
            family = family_of(name)
            params = shape_params(name, seed=case_seed_)
            exact = analytic_volume(name, **params)
        file = f"{case}.nii.gz"
        write_nifti(volume, folder / file)
        cases.append(
            {
                "case": case,
                "file": file,
                "shape": name,
                "family": family,
                "seed": case_seed_,
                "params": _jsonable(params),
                "grid": [int(n) for n in volume.shape],
                "spacing_mm": [round(float(s), 9) for s in volume.spacing],
                "voxels": int(np.count_nonzero(volume.mask)),
                "volume_mm3": round(float(volume.volume_mm3), 6),
                "analytic_volume_mm3": None if exact is None else round(float(exact), 6),
            }
        )
        logger.info("case %d/%d: %s (%s)", done, len(plan), case, "x".join(map(str, volume.shape)))
        if progress is not None:
            progress(done, len(plan), case)

    written = {c["file"] for c in cases}
    for old in stale:
        old_path = folder / old
        if old not in written and old_path.parent == folder and old_path.is_file():
            old_path.unlink()
    manifest = {
        "format": DATASET_FORMAT,
        "version": _VERSION,
        "slicerecon": __version__,
        "options": {
            "shapes": names,
            "per_shape": count,
            "seed": base_seed,
            "size": size,
            "spacing": spacing_list,
            "margin": margin,
        },
        "cases": cases,
    }
    target = folder / MANIFEST
    with atomic_path(target) as tmp:
        tmp.write_text(json.dumps(manifest, indent=2) + "\n", encoding="utf-8")
    logger.info("wrote %d cases and %s", len(cases), target)
    return target


def _jsonable(params: dict[str, Any]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in params.items():
        if isinstance(value, tuple | list | np.ndarray):
            out[key] = [round(float(v), 9) for v in value]
        elif isinstance(value, float | np.floating):
            out[key] = round(float(value), 9)
        else:
            out[key] = value
    return out
