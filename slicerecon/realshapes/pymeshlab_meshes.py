"""Closed sample meshes shipped with pymeshlab, scaled and voxelized."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..errors import DependencyError, InputError, OptionError
from ..sections import Volume
from . import installed
from .masks import check_resolution, crop

PYMESHLAB_MESHES: dict[str, str] = {
    "bunny": "bunny.obj",
    "cow": "cow.obj",
    "airplane": "airplane.obj",
    "bone": "bone.ply",
}
"""Closed pymeshlab sample meshes registered as real shapes: name → file."""


def pymeshlab_sample_dir() -> Path:
    """The ``tests/sample_meshes`` folder of the installed pymeshlab package.

    Raises
    ------
    DependencyError
        If pymeshlab is not installed or its build lacks the sample meshes.
    """
    package = installed.package_dir("pymeshlab")
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
    from ..io.mesh import read_mesh, voxelize_mesh

    res = check_resolution(resolution)
    if res is None:
        raise OptionError("resolution must be given for a mesh")
    folder = pymeshlab_sample_dir()
    path = folder / PYMESHLAB_MESHES.get(mesh, mesh)
    if not path.is_file():
        raise InputError(
            f"no sample mesh {mesh!r} in {folder}; registered ones: {', '.join(PYMESHLAB_MESHES)}"
        )
    surface = read_mesh(path)
    if extent_mm is not None:
        target = float(extent_mm)
        if not math.isfinite(target) or target <= 0:
            raise OptionError(f"extent_mm must be a positive number of mm (got {extent_mm!r})")
        size = float(np.max(surface.extents))
        surface.apply_scale(target / size)
    return crop(voxelize_mesh(surface, resolution=res, pad=0), margin)
