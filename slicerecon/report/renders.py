"""Per-case 3-D renders: ground truth | reconstruction | reconstruction coloured by error.

The error colour of a drawn face is the distance (mm) from its centre to the
full-resolution ground-truth surface. Meshes are decimated for display only.
matplotlib's Agg backend draws; PNGs depend on the inputs only.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from ..io import detect_kind, load_input
from ..results import CaseResult
from ..sections import Volume
from .figures import png_bytes, pyplot

if TYPE_CHECKING:
    import trimesh

__all__ = ["RENDER_FACES", "RENDER_GRID", "TruthCache", "decimate", "render_case"]

RENDER_FACES = 4000
"""Faces drawn per surface in a render (larger meshes are decimated)."""
RENDER_GRID = 128
"""Marching-cubes samples along the longest side of a ground-truth mask for renders."""


def decimate(
    vertices: NDArray[np.float64], faces: NDArray[np.int64], max_faces: int
) -> tuple[NDArray[np.float64], NDArray[np.int64]]:
    """Vertex-clustering decimation to at most ``max_faces`` faces (for display only).

    Vertices are snapped to a uniform grid (cell size grown until few enough
    faces remain), each cell's vertices replaced by their mean, and faces that
    collapse or repeat are dropped. Deterministic; the result is not
    guaranteed to stay watertight.

    Parameters
    ----------
    vertices : ndarray of shape (V, 3)
        Vertex positions, mm.
    faces : ndarray of shape (F, 3)
        Vertex indices of each triangle.
    max_faces : int
        Most faces to keep.

    Returns
    -------
    vertices : ndarray of shape (V', 3)
    faces : ndarray of shape (F', 3)
        ``F' <= max_faces`` (unless 20 growth steps did not suffice).
    """
    if len(faces) <= max_faces:
        return vertices, faces
    lo = vertices.min(axis=0)
    area = float(
        np.linalg.norm(
            np.cross(
                vertices[faces[:, 1]] - vertices[faces[:, 0]],
                vertices[faces[:, 2]] - vertices[faces[:, 0]],
            ),
            axis=1,
        ).sum()
        / 2.0
    )
    cell = math.sqrt(max(area, 1e-12) / max_faces)
    new_v, new_f = vertices, faces
    for _ in range(20):
        keys = np.floor((vertices - lo) / cell).astype(np.int64)
        _, inverse = np.unique(keys, axis=0, return_inverse=True)
        inverse = inverse.reshape(-1)
        counts = np.bincount(inverse)
        sums = np.zeros((counts.size, 3))
        np.add.at(sums, inverse, vertices)
        new_v = sums / counts[:, None]
        f = inverse[faces]
        f = f[(f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])]
        _, first = np.unique(np.sort(f, axis=1), axis=0, return_index=True)
        new_f = f[np.sort(first)]
        if len(new_f) <= max_faces:
            break
        cell *= 1.3
    return new_v, new_f


def _resolve(path_text: str, roots: Sequence[Path]) -> Path | None:
    path = Path(path_text)
    if path.is_absolute():
        return path if path.exists() else None
    for candidate in (path, *(root / path for root in roots)):
        if candidate.exists():
            return candidate
    return None


class TruthCache:
    """The last ground-truth surface read (cases of one input are adjacent in sorted order)."""

    def __init__(self) -> None:
        self.key: tuple[str, Any, Any] | None = None
        self.mesh: trimesh.Trimesh | None = None

    def get(self, case: CaseResult, root: Path) -> tuple[trimesh.Trimesh | None, str]:
        """The case's ground-truth surface (world mm) or None, and a note on where it came from.

        Parameters
        ----------
        case : CaseResult
            A finished case. Its ground truth is ``case.ground_truth`` or, without
            it, ``case.input_path``; only for cases with metrics.
        root : Path
            The results folder: relative paths are tried from the working
            directory, ``root`` and the case folder.

        Returns
        -------
        mesh : trimesh.Trimesh or None
        note : str
        """
        if case.metrics is None:
            return None, "no ground truth (sparse input)"
        source = case.ground_truth or case.input_path
        if source is None:
            return None, "plan.json names no input"
        roots = (root,) if case.directory is None else (root, case.directory)
        path = _resolve(source, roots)
        if path is None:
            return None, f"ground truth {source} not found"
        key = (str(path.resolve()), case.config.get("label"), case.config.get("roi"))
        if key != self.key:
            self.key, self.mesh = key, None
            self.mesh = _truth_surface(path, case.config)
        return self.mesh, f"ground truth: {Path(source).name}"


def _truth_surface(path: Path, config: Any) -> trimesh.Trimesh | None:
    from ..io.mesh import read_mesh
    from ..surface.marching import volume_to_mesh

    if detect_kind(path).kind == "mesh":
        return read_mesh(path)
    data = load_input(
        path,
        label=config.get("label"),
        roi=config.get("roi"),
        allow_irregular=bool(config.get("allow_irregular", False)),
        union=config.get("label") is None and config.get("roi") is None,
    )
    if not isinstance(data, Volume):
        return None
    cropped = data.crop(pad=1)
    step = max(1, math.ceil(max(cropped.shape) / RENDER_GRID))
    return volume_to_mesh(cropped, step_size=step)


def _face_shading(vertices: NDArray[np.float64], faces: NDArray[np.int64]) -> NDArray[np.float64]:
    """Two-sided Lambert shading in [0.35, 1] of each face, light from the upper front."""
    tri = vertices[faces]
    normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    normals = normals / np.where(length > 0, length, 1.0)
    light = np.array([0.4, -0.6, 0.7])
    light /= np.linalg.norm(light)
    return 0.35 + 0.65 * np.abs(normals @ light)


def _draw_surface(
    ax: Any, vertices: NDArray[np.float64], faces: NDArray[np.int64], colours: NDArray[np.float64]
) -> None:
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    collection = Poly3DCollection(
        vertices[faces], facecolors=colours, edgecolors="none", linewidths=0.0
    )
    ax.add_collection3d(collection)


def _frame(ax: Any, lo: NDArray[np.float64], hi: NDArray[np.float64], title: str) -> None:
    centre = (lo + hi) / 2.0
    half = float(np.max(hi - lo)) / 2.0 or 1.0
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(centre[2] - half, centre[2] + half)
    ax.set_box_aspect((1.0, 1.0, 1.0), zoom=1.3)
    ax.view_init(elev=22, azim=-60)
    ax.set_axis_off()
    ax.set_title(title, fontsize=9)


def render_case(case: CaseResult, truth: trimesh.Trimesh | None) -> tuple[bytes, dict[str, float]]:
    """3-D render: ground truth | reconstruction | reconstruction coloured by error (mm).

    Parameters
    ----------
    case : CaseResult
        A finished case with a ``mesh_path``.
    truth : trimesh.Trimesh or None
        Its ground-truth surface (world mm); None draws the reconstruction alone.

    Returns
    -------
    png : bytes
    stats : dict of str to float
        ``mean_mm``, ``p95_mm``, ``max_mm``: the face-centre distances of the
        error panel (empty without ground truth).

    Raises
    ------
    ValueError
        If the case has no mesh.
    """
    import trimesh as tm
    from matplotlib import colormaps
    from matplotlib.colors import Normalize

    from ..io.mesh import read_mesh

    if case.mesh_path is None:
        raise ValueError(f"case {case.case} has no mesh to render")
    recon = read_mesh(case.mesh_path)
    rv, rf = decimate(
        np.asarray(recon.vertices, np.float64), np.asarray(recon.faces, np.int64), RENDER_FACES
    )
    lo, hi = rv.min(axis=0), rv.max(axis=0)
    panels = 3 if truth is not None else 1
    plt = pyplot()
    fig = plt.figure(figsize=(3.3 * panels + (0.5 if truth is not None else 0.0), 3.4))
    stats: dict[str, float] = {}
    recon_shade = _face_shading(rv, rf)[:, None]
    recon_colour = np.clip(recon_shade * np.array([[0.95, 0.55, 0.25]]), 0, 1)
    if truth is None:
        ax = fig.add_subplot(1, 1, 1, projection="3d")
        _draw_surface(ax, rv, rf, recon_colour)
        _frame(ax, lo, hi, f"reconstruction ({len(recon.faces)} faces)")
        fig.subplots_adjust(left=0.0, right=1.0, bottom=0.0, top=0.9)
        return png_bytes(fig), stats
    gv, gf = decimate(
        np.asarray(truth.vertices, np.float64), np.asarray(truth.faces, np.int64), RENDER_FACES
    )
    lo, hi = np.minimum(lo, gv.min(axis=0)), np.maximum(hi, gv.max(axis=0))
    # Distance of each drawn reconstruction face centre to the full-resolution truth surface.
    _, dist, _ = tm.proximity.closest_point(truth, rv[rf].mean(axis=1))
    dist = np.asarray(dist, dtype=np.float64)
    stats = {
        "mean_mm": float(dist.mean()),
        "p95_mm": float(np.percentile(dist, 95)),
        "max_mm": float(dist.max()),
    }
    vmax = max(float(np.percentile(dist, 99)), 1e-3)
    norm = Normalize(vmin=0.0, vmax=vmax)
    cmap = colormaps["viridis"]
    error_colour = np.clip(cmap(norm(dist))[:, :3] * (0.55 + 0.45 * recon_shade), 0, 1)
    truth_colour = np.clip(_face_shading(gv, gf)[:, None] * np.array([[0.55, 0.65, 0.85]]), 0, 1)
    width = 3.3 * 3 + 0.5
    axes = [
        fig.add_axes((i * 3.3 / width, 0.0, 3.3 / width, 0.9), projection="3d") for i in range(3)
    ]
    _draw_surface(axes[0], gv, gf, truth_colour)
    _frame(axes[0], lo, hi, "ground truth")
    _draw_surface(axes[1], rv, rf, recon_colour)
    _frame(axes[1], lo, hi, "reconstruction")
    _draw_surface(axes[2], rv, rf, error_colour)
    _frame(axes[2], lo, hi, f"distance to truth (mean {stats['mean_mm']:.2f} mm)")
    cax = fig.add_axes((9.9 / width, 0.12, 0.12 / width, 0.66))
    bar = fig.colorbar(plt.cm.ScalarMappable(norm=norm, cmap=cmap), cax=cax)
    bar.ax.set_title("mm", fontsize=8)
    bar.ax.tick_params(labelsize=7)
    return png_bytes(fig), stats
