"""Per-case 3-D renders: ground truth | reconstruction | reconstruction coloured by error.

Drawn by :mod:`slicerecon.render`, the renderer of every case's
``preview.png`` too: the same view, the same colours (each structure in the
colour of its ``labels.seg.nrrd`` segment), world millimetres at true aspect.
A case of several structures shows each of them, from the meshes
``structures.json`` lists, and each is compared with its own ground truth.

The error colour of a drawn vertex is its distance (mm) to the ground-truth
surface of its structure (the nearest of the six truth triangles whose centres
are nearest: exact on the even triangles of a marching-cubes surface). PNGs
depend on the inputs only.
"""

from __future__ import annotations

import io
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from ..io import detect_kind, load_input
from ..io.labelmap import read_label_map
from ..labels import Structure
from ..preview import display_colour
from ..render import (
    Surface,
    cluster,
    draw_centred,
    draw_scale_bar,
    draw_triad,
    fit_camera,
    font,
    render_surfaces,
    to_display_frame,
)
from ..results import CaseResult
from ..sections import Volume

if TYPE_CHECKING:
    import trimesh

__all__ = ["PANEL_PX", "RENDER_GRID", "TruthCache", "case_structures", "render_case"]

PANEL_PX = 300
"""Side of one render panel, pixels."""
RENDER_GRID = 128
"""Marching-cubes samples along the longest side of a ground-truth mask for renders."""
_NEAREST_TRIANGLES = 6
_COLOURBAR_PX = 70
_TITLE_PX = 20
_LEGEND_ROW_PX = 15


class DrawnStructure(NamedTuple):
    """One structure of a case as a render draws it."""

    value: int | None
    label: str
    colour: tuple[int, int, int]
    mesh: trimesh.Trimesh


def case_structures(case: CaseResult) -> list[DrawnStructure]:
    """The reconstructed structures of a case, each with its mesh and display colour.

    Parameters
    ----------
    case : CaseResult
        A finished case: its ``structures`` (``structures.json``), or its one
        ``mesh_path`` for a folder without them.

    Returns
    -------
    list of DrawnStructure
        In the order of ``structures.json``; structures without a mesh are left out.
    """
    from ..io.mesh import read_mesh

    drawn = []
    count = len(case.structures)
    for index, record in enumerate(case.structures):
        if record.mesh_path is not None:
            colour = display_colour(record.structure, index, count)
            drawn.append(
                DrawnStructure(record.value, record.label, colour, read_mesh(record.mesh_path))
            )
    if not drawn and case.mesh_path is not None:
        colour = display_colour(Structure(1), 0, 1)
        drawn.append(DrawnStructure(None, "", colour, read_mesh(case.mesh_path)))
    return drawn


def _resolve(path_text: str, roots: Sequence[Path]) -> Path | None:
    path = Path(path_text)
    if path.is_absolute():
        return path if path.exists() else None
    for candidate in (path, *(root / path for root in roots)):
        if candidate.exists():
            return candidate
    return None


class TruthCache:
    """The last ground-truth surfaces read (cases of one input are adjacent in sorted order)."""

    def __init__(self) -> None:
        self.key: tuple[Any, ...] | None = None
        self.meshes: dict[int | None, trimesh.Trimesh] = {}

    def get(self, case: CaseResult, root: Path) -> tuple[dict[int | None, trimesh.Trimesh], str]:
        """The case's ground-truth surfaces (world mm) by structure value, and a note on
        where they came from.

        Parameters
        ----------
        case : CaseResult
            A finished case. Its ground truth is ``case.ground_truth`` or, without
            it, ``case.input_path``; only for cases with metrics. A case of several
            structures gets one surface per structure value (from the label map);
            a case of one structure one surface, under the key None.
        root : Path
            The results folder: relative paths are tried from the working
            directory, ``root`` and the case folder.

        Returns
        -------
        meshes : dict
            Empty when there is no ground truth.
        note : str
        """
        if case.metrics is None:
            return {}, "no ground truth (sparse input)"
        source = case.ground_truth or case.input_path
        if source is None:
            return {}, "plan.json names no input"
        roots = (root,) if case.directory is None else (root, case.directory)
        path = _resolve(source, roots)
        if path is None:
            return {}, f"ground truth {source} not found"
        values = tuple(s.value for s in case.structures) if case.several else ()
        key = (str(path.resolve()), case.config.get("label"), case.config.get("roi"), values)
        if key != self.key:
            self.key, self.meshes = key, {}
            self.meshes = _truth_surfaces(path, case.config, values)
        return self.meshes, f"ground truth: {Path(source).name}"


def _mask_surface(volume: Volume) -> trimesh.Trimesh:
    from ..surface.marching import volume_to_mesh

    cropped = volume.crop(pad=1)
    step = max(1, math.ceil(max(cropped.shape) / RENDER_GRID))
    return volume_to_mesh(cropped, step_size=step)


def _truth_surfaces(
    path: Path, config: Mapping[str, Any], values: Sequence[int]
) -> dict[int | None, trimesh.Trimesh]:
    from ..io.mesh import read_mesh

    if detect_kind(path).kind == "mesh":
        return {None: read_mesh(path)}
    if values:  # several structures: each from the label map
        label_map = read_label_map(
            path, allow_irregular=bool(config.get("allow_irregular", False)), chosen=True
        )
        if label_map is None:
            return {}
        present = {s.value for s in label_map.structures}
        return {value: _mask_surface(label_map.mask(value)) for value in values if value in present}
    data = load_input(
        path,
        label=config.get("label"),
        roi=config.get("roi"),
        allow_irregular=bool(config.get("allow_irregular", False)),
        union=config.get("label") is None and config.get("roi") is None,
    )
    return {None: _mask_surface(data)} if isinstance(data, Volume) else {}


def _surface(mesh: trimesh.Trimesh, frame: str | None, colour: Any) -> Surface:
    return Surface(
        to_display_frame(np.asarray(mesh.vertices), frame),
        np.asarray(mesh.faces, np.int64),
        np.asarray(colour, np.float64),
    )


def _distances(points: NDArray[np.float64], truth: Surface) -> NDArray[np.float64]:
    """Distance (mm) of each point to the truth surface (its nearest candidate triangles)."""
    from scipy.spatial import cKDTree
    from trimesh.triangles import closest_point

    triangles = truth.vertices[truth.faces]
    k = min(_NEAREST_TRIANGLES, len(triangles))
    _, nearest = cKDTree(triangles.mean(axis=1)).query(points, k=k)
    nearest = np.asarray(nearest).reshape(len(points), k)
    repeated = np.repeat(points, k, axis=0)
    found = closest_point(triangles[nearest.reshape(-1)], repeated)
    return np.linalg.norm(found - repeated, axis=1).reshape(len(points), k).min(axis=1)


def _png(image: Any) -> bytes:
    from PIL import Image

    palette = image.quantize(colors=256, method=Image.Quantize.FASTOCTREE)
    out = io.BytesIO()
    palette.save(out, format="png", optimize=True)
    return out.getvalue()


def _viridis() -> NDArray[np.float64]:
    from matplotlib import colormaps

    return np.asarray(colormaps["viridis"](np.linspace(0.0, 1.0, 256))[:, :3])


def render_case(
    case: CaseResult, truths: Mapping[int | None, trimesh.Trimesh] | None
) -> tuple[bytes, dict[str, float]]:
    """3-D render: ground truth | reconstruction | reconstruction coloured by error (mm).

    Parameters
    ----------
    case : CaseResult
        A finished case with a mesh (one, or one per structure).
    truths : mapping or None
        Ground-truth surfaces (world mm) by structure value (None for the one
        structure of a case); empty or None draws the reconstruction alone.

    Returns
    -------
    png : bytes
    stats : dict of str to float
        ``mean_mm``, ``p95_mm``, ``max_mm``: the vertex distances of the error
        panel (empty without ground truth).

    Raises
    ------
    ValueError
        If the case has no mesh.
    """
    from PIL import Image, ImageDraw

    drawn = case_structures(case)
    if not drawn:
        raise ValueError(f"case {case.case} has no mesh to render")
    frame = case.coordinates
    recon = [_surface(s.mesh, frame, np.asarray(s.colour) / 255.0) for s in drawn]
    own = dict(truths or {})
    if len(drawn) == 1 and None in own:  # a case of one structure: its one truth
        own[drawn[0].value] = own[None]
    truth = {
        s.value: _surface(own[s.value], frame, np.asarray(s.colour) / 255.0)
        for s in drawn
        if s.value in own
    }
    points = np.concatenate([s.vertices for s in [*recon, *truth.values()]])
    lo, hi = points.min(axis=0), points.max(axis=0)
    camera = fit_camera(lo, hi, (PANEL_PX, PANEL_PX), margin=16)
    panels: list[tuple[str, NDArray[np.uint8]]] = []
    stats: dict[str, float] = {}
    if truth:
        panels.append(("ground truth", render_surfaces(list(truth.values()), camera=camera).image))
    panels.append(("reconstruction", render_surfaces(recon, camera=camera).image))
    vmax = 1.0
    if truth:
        errors, coloured = [], []
        for structure, surface in zip(drawn, recon, strict=True):
            small = cluster(surface, 1.0 / camera.scale)
            if structure.value not in truth:
                coloured.append(small._replace(colour=np.full(3, 0.75)))
                errors.append(None)
                continue
            distance = _distances(small.vertices, truth[structure.value])
            errors.append(distance[small.faces].mean(axis=1))
            coloured.append(small)
        every = np.concatenate([e for e in errors if e is not None] or [np.zeros(1)])
        stats = {
            "mean_mm": float(every.mean()),
            "p95_mm": float(np.percentile(every, 95)),
            "max_mm": float(every.max()),
        }
        vmax = max(float(np.percentile(every, 99)), 1e-3)
        lut = _viridis()
        error_surfaces = [
            s if e is None else s._replace(colour=lut[np.clip(e / vmax * 255, 0, 255).astype(int)])
            for s, e in zip(coloured, errors, strict=True)
        ]
        panels.append(
            (
                f"distance to truth (mean {stats['mean_mm']:.2f} mm)",
                render_surfaces(error_surfaces, camera=camera).image,
            )
        )
    legend = [(s.label, s.colour) for s in drawn] if len(drawn) > 1 else []
    per_row = max(1, (len(panels) * PANEL_PX) // 150)
    legend_h = math.ceil(len(legend) / per_row) * _LEGEND_ROW_PX + (6 if legend else 0)
    width = len(panels) * PANEL_PX + (_COLOURBAR_PX if truth else 0)
    canvas = Image.new("RGB", (width, _TITLE_PX + PANEL_PX + legend_h), "white")
    draw = ImageDraw.Draw(canvas)
    for k, (title, image) in enumerate(panels):
        canvas.paste(Image.fromarray(image), (k * PANEL_PX, _TITLE_PX))
        draw_centred(draw, (k * PANEL_PX + PANEL_PX / 2, _TITLE_PX / 2), title, (0, 0, 0), 12)
    draw_triad(draw, camera.rotation, (40, _TITLE_PX + PANEL_PX - 34), frame)
    draw_scale_bar(draw, camera.scale, (PANEL_PX - 110, _TITLE_PX + PANEL_PX - 22), max_px=90)
    if truth:
        _colour_bar(draw, len(panels) * PANEL_PX + 14, _TITLE_PX + 20, vmax)
    for k, (name, colour) in enumerate(legend):
        x = 8 + (k % per_row) * 150
        y = _TITLE_PX + PANEL_PX + 4 + (k // per_row) * _LEGEND_ROW_PX
        draw.rectangle([x, y + 2, x + 10, y + 11], fill=tuple(colour), outline=(60, 60, 60))
        draw.text((x + 14, y), name[:22], fill=(0, 0, 0), font=font(11))
    return _png(canvas), stats


def _colour_bar(draw: Any, x: int, y: int, vmax: float) -> None:
    """The viridis scale from 0 to ``vmax`` mm, ``y`` its top, 0 at the bottom."""
    lut = np.round(_viridis() * 255).astype(int)
    height = PANEL_PX - 50
    for row in range(height):
        colour = tuple(lut[int((height - 1 - row) / max(height - 1, 1) * 255)])
        draw.line([(x, y + row), (x + 12, y + row)], fill=colour)
    draw.rectangle([x, y, x + 12, y + height - 1], outline=(80, 80, 80))
    draw.text((x - 2, y - 16), "mm", fill=(0, 0, 0), font=font(11))
    for fraction in (0.0, 0.5, 1.0):
        at = y + (height - 1) * (1.0 - fraction)
        draw.line([(x + 12, at), (x + 16, at)], fill=(0, 0, 0))
        draw.text((x + 18, at - 6), f"{fraction * vmax:.3g}", fill=(0, 0, 0), font=font(10))
