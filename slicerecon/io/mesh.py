"""Surface meshes: read and write STL / PLY / OBJ / OFF, and voxelize closed meshes.

Meshes are in world millimetres. Reading keeps geometry only: every file is
reduced to one triangle mesh (a multi-object scene is concatenated) whose
coincident vertices are merged, so texture seams and per-corner normals do not
open a closed surface. Colours, normals and textures are dropped.
"""

from __future__ import annotations

import logging
import math
import os
from pathlib import Path

import numpy as np
import trimesh

from ..errors import EmptyMaskError, FormatError, GeometryError, InputError, OptionError
from ..rasterize import edge_face_counts, mesh_to_mask, require_closed
from ..sections import Volume
from .atomic import atomic_path

__all__ = [
    "MESH_FORMATS",
    "mesh_file_closed",
    "mesh_frame",
    "read_mesh",
    "write_mesh",
    "voxelize_mesh",
    "read_mesh_volume",
]

logger = logging.getLogger(__name__)

MESH_FORMATS: dict[str, str] = {".stl": "stl", ".ply": "ply", ".obj": "obj", ".off": "off"}
"""File suffix → trimesh file type, for reading and writing."""

_MAX_VOXELS = 2**29
"""Largest grid :func:`voxelize_mesh` builds (about 512 MiB as bool)."""


def _format_list() -> str:
    return ", ".join(MESH_FORMATS)


def read_mesh(path: str | os.PathLike[str]) -> trimesh.Trimesh:
    """Read a triangle mesh from an STL, PLY, OBJ or OFF file.

    Parameters
    ----------
    path : path-like
        Mesh file; the format is taken from the suffix (case-insensitive).

    Returns
    -------
    trimesh.Trimesh
        All triangles of the file in one mesh (quads are split, scene parts
        concatenated), coincident vertices merged, coordinates in file units
        (world mm by convention).

    Raises
    ------
    InputError
        If the file does not exist.
    FormatError
        If the suffix is not a supported mesh format, or the file cannot be
        parsed, or it holds no triangle.
    """
    p = Path(path)
    if not p.exists():
        raise InputError(f"mesh file not found: {p}")
    if p.is_dir():
        raise InputError(f"{p} is a directory, not a mesh file ({_format_list()})")
    file_type = MESH_FORMATS.get(p.suffix.lower())
    if file_type is None:
        raise FormatError(f"{p.name}: unsupported mesh format; use one of {_format_list()}")
    try:
        loaded = trimesh.load(p, file_type=file_type, force="mesh", process=False)
    except Exception as exc:  # trimesh's parsers raise many types on bad input
        raise FormatError(
            f"cannot read {p} as {file_type.upper()} ({exc.__class__.__name__}: "
            f"{str(exc).strip()[:200] or 'no details'}); the file is corrupt or not a mesh"
        ) from exc
    faces = getattr(loaded, "faces", None)
    if not isinstance(loaded, trimesh.Trimesh) or faces is None or len(faces) == 0:
        raise FormatError(
            f"{p} holds no triangles: the file is empty, corrupt or only a point cloud"
        )
    vertices = np.asarray(loaded.vertices, dtype=np.float64)
    if not np.all(np.isfinite(vertices)):
        raise FormatError(f"{p} has NaN or infinite vertex coordinates")
    mesh = trimesh.Trimesh(vertices, np.asarray(loaded.faces), process=True)
    logger.info("read %s: %d vertices, %d faces", p, len(mesh.vertices), len(mesh.faces))
    return mesh


def write_mesh(
    mesh: trimesh.Trimesh,
    path: str | os.PathLike[str],
    *,
    file_format: str | None = None,
    coordinates: str | None = None,
) -> Path:
    """Write a triangle mesh atomically as STL (binary), PLY (binary), OBJ or OFF.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Mesh in world mm.
    path : path-like
        Target file. Parent directories are created; the file appears complete
        or not at all.
    file_format : {"stl", "ply", "obj", "off"}, optional
        Output format; default from the suffix of ``path``.
    coordinates : {"RAS", "LPS"}, optional
        The world frame of the vertices, recorded as 3D Slicer records it
        (``SPACE=RAS`` in the STL header, a PLY or OBJ comment; OFF has no
        place for it). Slicer reads a mesh without it as LPS.

    Returns
    -------
    Path
        The written file.

    Raises
    ------
    InputError
        If ``mesh`` is not a Trimesh or has no faces.
    OptionError
        If the format is unknown, cannot be told from the suffix, or
        contradicts the suffix.

    Notes
    -----
    STL stores coordinates as float32 (about 1e-7 relative); PLY, OBJ and OFF
    keep at least 8 significant digits.
    """
    if not isinstance(mesh, trimesh.Trimesh):
        raise InputError(f"write_mesh needs a trimesh.Trimesh (got {type(mesh).__name__})")
    if len(mesh.faces) == 0:
        raise InputError("refusing to write a mesh with no faces")
    p = Path(path)
    from_suffix = MESH_FORMATS.get(p.suffix.lower())
    if file_format is None:
        if from_suffix is None:
            raise OptionError(
                f"cannot tell the mesh format of {p.name!r}; use a suffix among "
                f"{_format_list()} or pass file_format"
            )
        fmt = from_suffix
    else:
        fmt = str(file_format).lower().lstrip(".")
        if fmt not in MESH_FORMATS.values():
            raise OptionError(
                f"unknown mesh format {file_format!r}; use one of "
                f"{', '.join(MESH_FORMATS.values())}"
            )
        if from_suffix is not None and from_suffix != fmt:
            raise OptionError(
                f"file_format {fmt!r} contradicts the suffix of {p.name!r}; make them agree"
            )
    options = {"include_texture": False} if fmt == "obj" else {}
    if coordinates not in (None, "RAS", "LPS"):
        raise OptionError(f"coordinates must be RAS or LPS (got {coordinates!r})")
    with atomic_path(p) as tmp:
        mesh.export(tmp, file_type=fmt, **options)
        if coordinates is not None:
            _tag_space(Path(tmp), fmt, coordinates)
    logger.info("wrote %s (%s, %d faces)", p, fmt, len(mesh.faces))
    return p


def _tag_space(path: Path, fmt: str, coordinates: str) -> None:
    """Record the world frame in a written mesh file the way 3D Slicer reads it."""
    tag = f"SPACE={coordinates}".encode()
    if fmt == "stl":  # binary: an 80-byte free header (never starting with "solid")
        with path.open("r+b") as handle:
            handle.write(tag.ljust(80, b" "))
    elif fmt in ("ply", "obj"):
        data = path.read_bytes()
        if fmt == "ply":
            line_end = data.index(b"\n", data.index(b"\nformat ") + 1) + 1
            data = data[:line_end] + b"comment " + tag + b"\n" + data[line_end:]
        else:
            data = b"# " + tag + b"\n" + data
        path.write_bytes(data)


def mesh_frame(path: str | os.PathLike[str]) -> str | None:
    """The world frame a mesh file states, as 3D Slicer records it (:func:`write_mesh`):
    ``"RAS"`` or ``"LPS"`` from ``SPACE=`` in a binary STL header, a PLY comment or an
    OBJ comment at its top; None when it states none (OFF, an ASCII STL, a file
    written elsewhere)."""
    with Path(path).open("rb") as handle:
        head = handle.read(4096)
    fmt = MESH_FORMATS.get(Path(path).suffix.lower())
    if fmt == "stl":
        lines = [head[:80]]
    elif fmt == "ply":
        lines = head.split(b"end_header")[0].splitlines()
    elif fmt == "obj":
        lines = [line for line in head.splitlines()[:8] if line.startswith(b"#")]
    else:
        return None
    for line in lines:
        for frame in ("RAS", "LPS"):
            if f"SPACE={frame}".encode() in line:
                return frame
    return None


def mesh_file_closed(path: str | os.PathLike[str]) -> bool:
    """Whether a written mesh file is closed as a reader sees it: every edge in two faces.

    The file is read back and vertices with identical coordinates in it are
    merged (as every mesh tool does), so what is checked is the file, not the
    mesh in memory: vertices that the format's precision makes coincide (STL
    stores float32) are one vertex here, and a surface they pinch fails.

    Parameters
    ----------
    path : path-like
        A mesh file (STL, PLY, OBJ or OFF).

    Returns
    -------
    bool

    Raises
    ------
    InputError, FormatError
        As :func:`read_mesh`.
    """
    p = Path(path)
    file_type = MESH_FORMATS.get(p.suffix.lower())
    if not p.is_file() or file_type is None:
        read_mesh(p)  # raises the reader's error
    try:
        loaded = trimesh.load(p, file_type=file_type, force="mesh", process=False)
    except Exception as exc:  # trimesh's parsers raise many types on bad input
        raise FormatError(f"cannot read {p} back as {file_type}: {exc}") from exc
    vertices = np.asarray(loaded.vertices, dtype=np.float64)
    faces = np.asarray(loaded.faces, dtype=np.int64)
    if len(faces) == 0:
        return False
    order = np.lexsort((vertices[:, 2], vertices[:, 1], vertices[:, 0]))
    ordered = vertices[order]
    first = np.ones(len(order), dtype=bool)
    first[1:] = np.any(ordered[1:] != ordered[:-1], axis=1)
    merged = np.empty(len(order), dtype=np.int64)
    merged[order] = np.cumsum(first) - 1  # each vertex → its group of equal coordinates
    _, counts = edge_face_counts(merged[faces], int(first.sum()))
    closed = bool(counts.size) and bool(np.all(counts == 2))
    if not closed:
        logger.warning(
            "%s is not closed as written: %d open edges, %d edges in more than two faces",
            p,
            int(np.count_nonzero(counts == 1)),
            int(np.count_nonzero(counts > 2)),
        )
    return closed


def voxelize_mesh(
    mesh: trimesh.Trimesh,
    *,
    pitch: float | None = None,
    resolution: int = 128,
    pad: int = 2,
) -> Volume:
    """Rasterize a closed mesh onto an isotropic, world-aligned voxel grid.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        Closed surface in world mm.
    pitch : float, optional
        Voxel size, mm. Default: the longest side of the mesh's bounding box
        divided by ``resolution``.
    resolution : int
        Voxels across the longest side when ``pitch`` is not given.
    pad : int
        Background voxels kept around the mesh's bounding box on every side.

    Returns
    -------
    Volume
        Mask of the voxel centres inside the mesh, with affine
        ``diag(pitch, pitch, pitch)`` plus the grid origin (world axes, no
        rotation). The grid is centred on the mesh's bounding box.

    Raises
    ------
    GeometryError
        If the mesh is not closed (the message counts the open edges) or flat.
    OptionError
        If ``pitch``, ``resolution`` or ``pad`` is out of range, or the grid
        would exceed 2**29 voxels.
    EmptyMaskError
        If no voxel centre falls inside the mesh (the mesh is thinner than
        ``pitch``).
    """
    require_closed(mesh)
    if isinstance(pad, bool) or not isinstance(pad, int | np.integer) or pad < 0:
        raise OptionError(f"pad must be an integer >= 0 (got {pad!r})")
    lo, hi = np.asarray(mesh.bounds, dtype=np.float64)
    extent = hi - lo
    if extent.max() <= 0:
        raise GeometryError("the mesh is flat: its bounding box has zero size")
    if pitch is None:
        if (
            isinstance(resolution, bool)
            or not isinstance(resolution, int | np.integer)
            or resolution < 1
        ):
            raise OptionError(f"resolution must be a positive integer (got {resolution!r})")
        step = float(extent.max()) / int(resolution)
    else:
        step = float(pitch)
        if not math.isfinite(step) or step <= 0:
            raise OptionError(f"pitch must be a positive number of mm (got {pitch!r})")
    core = np.maximum(np.ceil(extent / step - 1e-9).astype(np.int64), 1)
    shape = core + 2 * int(pad)
    n_voxels = int(np.prod(shape))
    if n_voxels > _MAX_VOXELS:
        raise OptionError(
            f"a {step:g} mm grid over this mesh needs {tuple(int(n) for n in shape)} voxels "
            f"({n_voxels:,}); pass a larger pitch or a smaller resolution"
        )
    # centres of the first core voxel: the core's voxels just cover [lo, hi]
    first_centre = (lo + hi) / 2.0 - (core - 1) / 2.0 * step
    affine = np.diag([step, step, step, 1.0])
    affine[:3, 3] = first_centre - pad * step
    grid = (int(shape[0]), int(shape[1]), int(shape[2]))
    mask = mesh_to_mask(mesh, affine, grid)
    if not mask.any():
        raise EmptyMaskError(
            f"no voxel centre of the {step:g} mm grid lies inside the mesh; pass a smaller "
            "pitch or a larger resolution"
        )
    logger.info("voxelized mesh on a %s grid, pitch %.4g mm", grid, step)
    return Volume(mask, affine)


def read_mesh_volume(
    path: str | os.PathLike[str],
    *,
    pitch: float | None = None,
    resolution: int = 128,
) -> Volume:
    """Read a closed mesh file and voxelize it (see :func:`read_mesh`, :func:`voxelize_mesh`)."""
    return voxelize_mesh(read_mesh(path), pitch=pitch, resolution=resolution)
