"""The reconstruction pipeline: input → sections + projections → plan → mesh → metrics.

This module composes the library; it holds no geometry of its own. The command
line (``slicerecon run``) and the batch pipelines fill a
:class:`ReconstructConfig` and call :func:`run_case`; library users call
:func:`reconstruct` with explicit arguments.
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import trimesh
from numpy.typing import NDArray

from . import policy as _policy  # noqa: F401  (registers the "policy" planner, no torch)
from .errors import OptionError
from .inputs import (
    DEFAULT_SLICES,
    MAX_AXIS_UPSAMPLE,
    PROJECTION_SOURCES,
    axis_upsample,
    looks_sparse,
    prepare_inputs,
)
from .io.limits import DEFAULT_MEMORY_BUDGET_GB, check_budget
from .partition.planner import planner_names
from .sections import Box, CrossSections, Projections, Volume, axis_index
from .surface.methods import method_entry, method_names

if TYPE_CHECKING:
    from .partition.lookahead import PlanningSurface

__all__ = [
    "ReconstructConfig",
    "Reconstruction",
    "PLAIN_SDF",
    "PLANNERS",
    "METHODS",
    "WHOLE_SHAPE_METHODS",
    "PROJECTION_SOURCES",
    "INTERPOLATIONS",
    "MESH_FORMATS",
    "DEFAULT_SLICES",
    "MAX_AXIS_UPSAMPLE",
    "axis_upsample",
    "looks_sparse",
    "prepare_inputs",
    "reconstruct",
    "run_case",
]

logger = logging.getLogger(__name__)

PLANNERS = tuple(planner_names())
"""Planner names when this module was imported (the registry of
:mod:`slicerecon.partition.planner`, with the learned planner registered by
:mod:`slicerecon.policy`, which this module imports). :func:`reconstruct`
checks against the registry itself, so planners registered later are accepted."""
METHODS = method_names()
"""Surface method names (:data:`slicerecon.surface.methods.METHODS`)."""
WHOLE_SHAPE_METHODS = method_names(per_part=False)
"""Methods that reconstruct all the sections at once, without a partition
(:mod:`slicerecon.surface.baselines`); planners and carving apply to the others only."""
INTERPOLATIONS = ("pchip", "linear")
MESH_FORMATS = ("stl", "ply", "obj")
PLAIN_SDF: dict[str, Any] = {
    "method": "sdf",
    "planner": "none",
    "carve": False,
    "interpolation": "linear",
    "join_drift": False,
}
"""Keyword arguments of :func:`reconstruct` for the baseline every table beats:
plain signed-distance (shape-based) interpolation between the planes, linear
across them, one part, no projections (Raya & Udupa 1990)."""

PLANNING_MAX_GRID = 192
"""Planners see at most this many voxels along a side: larger grids are planned on
a pooled copy (:func:`slicerecon.partition.planner.plan_partition`, ``max_grid``)
and the parts mapped back, so planning costs the same at clinical sizes as on a
192-voxel shape; the surface is always made at full resolution."""


@dataclass(frozen=True)
class ReconstructConfig:
    """Options of one reconstruction run (what ``slicerecon run`` fills in)."""

    slices: int | None = None
    """Keep N evenly spaced planes of a dense input (default 16 when neither
    ``slices`` nor ``every`` is given)."""
    every: int | None = None
    """Keep every K-th plane of a dense input instead of ``slices``."""
    axis: str = "z"
    """Grid axis the section planes are perpendicular to (x, y or z)."""
    planner: str = "heuristic"
    """How the shape is partitioned into cuboid parts: ``heuristic`` (the
    paper's expert), ``none`` (one part: the no-projection baseline) or
    ``policy`` (the shipped learned planner, ``docs/policy.md``)."""
    method: str = "sdf"
    """How each part is reconstructed: ``sdf`` (the default: signed-distance
    interpolation across planes + marching cubes, carved by the hull in the
    implicit domain), ``loft`` (contour lofting, the paper's method) or
    ``hybrid`` (``loft`` where the contours of consecutive planes correspond
    simply, ``sdf`` where they split, merge or appear); or a whole-shape
    baseline that skips the planner and the carve: ``poisson`` (screened
    Poisson on the contour points), ``sdf-hull`` (signed-distance
    interpolation intersected with the visual hull) or ``itk-mci`` (ITK
    morphological contour interpolation, needs ``slicerecon[itk]``); see
    ``docs/baselines.md``."""
    projections: str = "auto"
    """Where the orthographic projections come from: ``gt`` (the dense input,
    the paper's prior), ``sections`` (derived from the sections alone),
    ``auto`` (``gt`` for dense inputs, ``sections`` for sparse ones), or one
    to three comma-separated NIfTI silhouette files
    (:func:`slicerecon.io.projections.read_projection_files`)."""
    smooth: bool = False
    """Taubin-smooth the merged mesh."""
    carve: bool = True
    """Intersect the surface with the visual hull of the projections
    (``docs/method.md``, section 7): nothing the silhouettes rule out is kept."""
    cover: bool = True
    """With ``carve`` and ``method="sdf"``: also make the surface fill the two
    silhouettes whose rays lie in the section planes, where the interpolation
    between planes falls short of them (``docs/method.md``, section 7; chosen on
    the real-anatomy development half). Silhouettes derived from the sections
    themselves are never covered."""
    join_drift: bool = True
    """With ``method="sdf"``: join regions of consecutive planes that overlap
    nothing on the other plane, blending their distances along the shift between
    them (:mod:`slicerecon.surface.drift`; a slanted rod stays one piece)."""
    mesh_format: str = "stl"
    """Output mesh format: stl, ply or obj."""
    label: int | str | None = None
    """The structure to keep, by number or name: a label value, a SEG segment
    number or label, an RTSTRUCT ROI number or name (default: all non-zero, or
    the only segment / ROI)."""
    roi: str | None = None
    """RTSTRUCT ROI name or number (another name for ``label``)."""
    union: bool = False
    """Treat every non-zero voxel (every structure) as one structure, as
    slicerecon did before it reconstructed structures separately."""
    allow_irregular: bool = False
    """Accept DICOM series with uneven slice spacing."""
    max_parts: int = 8
    """Upper bound on the number of cuboid parts a planner may make."""
    weights: str | None = None
    """Actor weights file for ``planner="policy"`` (default: the shipped
    ``il_rl`` actor)."""
    interpolation: str = "pchip"
    """How ``sdf`` (and ``hybrid``'s sdf parts) interpolate the planes' signed
    distances across planes: ``pchip`` (the default: monotone piecewise cubic
    through all planes, chosen on the real-anatomy development shapes,
    ``docs/results.md``) or ``linear`` (classic shape-based interpolation)."""
    n_points: int = 50_000
    """Surface samples per mesh for the distance metrics."""
    max_memory_gb: float = DEFAULT_MEMORY_BUDGET_GB
    """Memory budget of one case, GiB: inputs whose grid would need more are
    refused before anything is allocated (:mod:`slicerecon.io.limits`)."""
    seed: int = 0
    """Seed of every random choice (surface sampling)."""

    @property
    def selectors(self) -> list[int | str]:
        """The structures ``label`` (or ``roi``) names: comma-separated numbers or names."""
        from .selection import parse_selector

        text = self.label if self.label is not None else self.roi
        if text is None:
            return []
        if isinstance(text, int):
            return [text]
        return [v for part in str(text).split(",") if (v := parse_selector(part)) is not None]

    def __post_init__(self) -> None:
        if self.union and (self.label is not None or self.roi is not None):
            raise OptionError("give --label or --union, not both")
        if self.slices is not None and self.every is not None:
            raise OptionError("give --slices or --every, not both")
        if self.slices is not None and self.slices < 2:
            raise OptionError(f"--slices must be at least 2 (got {self.slices})")
        if self.every is not None and self.every < 1:
            raise OptionError(f"--every must be at least 1 (got {self.every})")
        axis_index(self.axis)
        for name, value, choices in (
            ("planner", self.planner, tuple(planner_names())),
            ("method", self.method, METHODS),
            ("format", self.mesh_format, MESH_FORMATS),
            ("interpolation", self.interpolation, INTERPOLATIONS),
        ):
            if value not in choices:
                raise OptionError(f"--{name} must be one of {', '.join(choices)} (got {value!r})")
        check_budget(self.max_memory_gb)
        if self.max_parts < 1:
            raise OptionError(f"max_parts must be >= 1 (got {self.max_parts})")
        if self.weights is not None:
            if self.planner != "policy":
                raise OptionError(
                    f"--weights apply to --planner policy only (planner is {self.planner!r})"
                )
            if not Path(self.weights).is_file():
                raise OptionError(f"policy weights file not found: {self.weights}")


@dataclass
class Reconstruction:
    """The result of :func:`reconstruct`.

    Attributes
    ----------
    mesh : trimesh.Trimesh
        Watertight surface in world mm.
    plan : Plan
        The cuboid parts (and the cuts that made them).
    sections, projections
        The inputs the reconstruction used.
    timings : dict of str to float
        Seconds spent per stage.
    occupancy : Volume or None
        Voxel centres inside the mesh, when known without rasterizing.
    """

    mesh: trimesh.Trimesh
    plan: Any
    sections: CrossSections
    projections: Projections
    timings: dict[str, float] = field(default_factory=dict)
    occupancy: Volume | None = None
    """The voxel centres of the sections' grid inside :attr:`mesh`, on a sub-grid,
    when the method gives them for free (``sdf``: the field's sign); None
    otherwise. Metrics and previews use it instead of rasterizing the mesh."""
    field: Any = None
    """With ``keep_field=True`` and ``method="sdf"``: the signed-distance field the
    mesh was extracted from (:class:`slicerecon.surface.sdf.SdfField`)."""


@contextmanager
def _timed(timings: dict[str, float], stage: str) -> Iterator[None]:
    start = time.perf_counter()
    try:
        yield
    finally:
        timings[stage] = timings.get(stage, 0.0) + time.perf_counter() - start


def planning_occupancy(sections: CrossSections, projections: Projections) -> np.ndarray:
    """The 3-D occupancy a planner sees: the projections' visual hull, exact on the planes.

    Returns
    -------
    ndarray of shape ``sections.grid_shape``, bool
    """
    from .sampling import visual_hull

    return _exact_on_planes(visual_hull(projections, sections.grid_shape), sections)


def _planning_surface(
    sections: CrossSections, hull: np.ndarray, *, interpolation: str, join_drift: bool
) -> Callable[[int], PlanningSurface]:
    """The sections, hull and part surface on the planning grid (a ``SurfaceFactory``).

    For the planners that score their choices on reconstructions
    (:func:`slicerecon.partition.lookahead.plan_lookahead`): the signed-distance
    part surface with this call's interpolation and drift joining, extended
    along the hull and carved by it; on a pooled grid the sections and the
    hull are pooled the same way (:func:`~slicerecon.sampling.pool_sections`).
    """
    from .partition.lookahead import PlanningSurface
    from .sampling import pool_any, pool_sections
    from .surface.part import part_voxels

    def surface(factor: int) -> PlanningSurface:
        grid_hull = pool_any(hull, factor)

        def part(part_sections: CrossSections, box: Box) -> np.ndarray:
            voxels = part_voxels(
                part_sections,
                box,
                method="sdf",
                hull=grid_hull,
                interpolation=interpolation,
                join_drift=join_drift,
            )
            return voxels & grid_hull[box.slices]

        return PlanningSurface(pool_sections(sections, factor), grid_hull, part)

    return surface


def _exact_on_planes(hull: np.ndarray, sections: CrossSections) -> np.ndarray:
    """A copy of ``hull`` whose section planes hold the section masks."""
    occupancy = hull.copy()
    if sections.is_on_grid:
        view = np.moveaxis(occupancy, sections.axis, 0)
        view[np.round(sections.indices).astype(np.int64)] = sections.masks
    return occupancy


def reconstruct(
    sections: CrossSections,
    projections: Projections,
    *,
    planner: str = "heuristic",
    method: str = "sdf",
    smooth: bool = False,
    carve: bool = True,
    max_parts: int = 8,
    weights: str | os.PathLike[str] | None = None,
    interpolation: str = "pchip",
    keep_field: bool = False,
    upsample: int | None = None,
    cover: bool = True,
    join_drift: bool = True,
) -> Reconstruction:
    """Reconstruct a watertight surface from cross-sections and projections.

    Parameters
    ----------
    sections : CrossSections
        The planar cross-sections.
    projections : Projections
        Orthographic silhouettes on the same grid (from the dense mask or
        derived from the sections).
    planner : {"heuristic", "none", "policy"}
        Partition planner (``policy``: a trained actor, needs torch).
    method : {"sdf", "hybrid", "loft", "poisson", "sdf-hull", "itk-mci"}
        Surface method. ``sdf``, ``hybrid`` and ``loft`` reconstruct each part of the
        plan. The whole-shape baselines (:data:`WHOLE_SHAPE_METHODS`,
        :mod:`slicerecon.surface.baselines`) run on all the sections at once:
        no planner runs (``planner`` and ``max_parts`` are ignored), the plan
        records one part whose box is the sections' bounding box, and the
        mesh is not carved (``sdf-hull`` intersects with the hull itself).
    smooth : bool
        Taubin-smooth the merged mesh.
    carve : bool
        Intersect the surface with the projections' visual hull: in the
        implicit domain for ``sdf`` (one marching cubes,
        :func:`slicerecon.surface.sdf.sdf_parts_mesh`), by an exact mesh
        Boolean otherwise (:func:`slicerecon.surface.carve.carve`); not for
        the whole-shape baselines.
    max_parts : int
        Upper bound on the number of parts.
    weights : path-like, optional
        Actor weights for ``planner="policy"`` (default: the shipped ``il_rl`` actor).
    interpolation : {"pchip", "linear"}
        How the signed-distance parts interpolate across planes
        (:func:`slicerecon.surface.sdf.sdf_field`).
    keep_field : bool
        Keep the ``sdf`` surface's field (:attr:`Reconstruction.field`), e.g. to
        resolve several structures jointly (:mod:`slicerecon.surface.joint`).
    upsample : int, optional
        ``sdf`` field samples per voxel along the section axis (default:
        :func:`axis_upsample`); structures resolved jointly share one.
    cover : bool
        With ``carve`` and the ``sdf`` surface: where a ray of the two views
        whose rays lie in the section planes meets the silhouette but not the
        interpolated shape, add the hull samples the interpolation came
        nearest to (:func:`slicerecon.surface.sdf.sdf_parts_mesh`), so the
        surface fills the silhouettes as well as staying inside them. Only
        silhouettes that say something the sections do not are covered: with
        projections derived from the sections (``projections.source ==
        "sections"``, the choice for contour inputs) there is nothing to add,
        and covering them measured worse (``docs/method.md``, section 7).
    join_drift : bool
        With the signed-distance surfaces: regions of two consecutive planes
        that overlap nothing on the other plane and are each other's nearest
        are joined by a blend that moves along the shift between them
        (:mod:`slicerecon.surface.drift`), so that a structure that drifts by
        more than its width between planes stays one piece.

    Returns
    -------
    Reconstruction
    """
    from .partition.planner import plan_partition, planner_entry
    from .surface.part import reconstruct_surface

    if planner not in planner_names():
        raise OptionError(f"planner must be one of {', '.join(planner_names())} (got {planner!r})")
    entry = method_entry(method)
    if not entry.per_part:
        return _reconstruct_whole_shape(sections, projections, method=method, smooth=smooth)
    timings: dict[str, float] = {}
    from .sampling import visual_hull

    with _timed(timings, "plan"):
        hull = visual_hull(projections, sections.grid_shape)
        occupancy = hull if planner == "none" else _exact_on_planes(hull, sections)

        guide = hull if planner != "none" else None
        # No planner's choice at inference depends on the reward's reconstruction
        # term (it is what training optimises), so parts are not reconstructed
        # twice: the plan's rewards hold IoU(W_i, O) only.
        surface = None
        if planner_entry(planner).needs_surface:
            surface = _planning_surface(
                sections, hull, interpolation=interpolation, join_drift=join_drift
            )
        plan = plan_partition(
            occupancy,
            planner=planner,
            reconstruct=None,
            max_parts=max_parts,
            weights=weights,
            max_grid=PLANNING_MAX_GRID,
            surface=surface,
        )
    implicit_carve = carve and entry.implicit_carve and not smooth
    with _timed(timings, "surface"):
        boxes = [part.box for part in plan.parts]
        surface = reconstruct_surface(
            sections,
            boxes,
            method=method,
            smooth=smooth,
            extend_to_box=planner != "none",
            hull=guide,
            interpolation=interpolation,
            carve=hull if implicit_carve else None,
            upsample=(upsample or axis_upsample(sections)) if entry.implicit_carve else 1,
            keep_field=keep_field,
            cover=cover and implicit_carve and projections.source != "sections",
            join_drift=join_drift,
        )
        mesh, occupancy = surface.mesh, surface.occupancy
    if carve and entry.carved and not implicit_carve:
        from .surface.carve import carve as carve_by_hull

        with _timed(timings, "carve"):
            mesh = carve_by_hull(mesh, hull, sections.affine)
    return Reconstruction(mesh, plan, sections, projections, timings, occupancy, surface.field)


def _reconstruct_whole_shape(
    sections: CrossSections, projections: Projections, *, method: str, smooth: bool
) -> Reconstruction:
    """A whole-shape baseline on all the sections, recorded as a one-part plan."""
    from .partition.planner import Plan, PlanPart
    from .surface.baselines import reconstruct_baseline, sections_box
    from .surface.smooth import taubin_smooth

    timings: dict[str, float] = {}
    with _timed(timings, "plan"):
        box = sections_box(sections)
        voxels = int(np.count_nonzero(planning_occupancy(sections, projections)[box.slices]))
        plan = Plan("none", (PlanPart(box, None, voxels),), sections.grid_shape)
    with _timed(timings, "surface"):
        mesh = reconstruct_baseline(sections, projections, method=method)
        if smooth:
            mesh = taubin_smooth(mesh)
    return Reconstruction(mesh, plan, sections, projections, timings)


def run_case(
    input_path: str | os.PathLike[str],
    outdir: str | os.PathLike[str],
    config: ReconstructConfig,
    *,
    ground_truth: str | os.PathLike[str] | None = None,
    image_dir: str | os.PathLike[str] | None = None,
    progress: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Reconstruct one case and write its outputs.

    Writes ``mesh.<format>`` (world mm), ``plan.json``, ``metrics.json`` (when
    ground truth is known: a dense input, or ``ground_truth``) and
    ``preview.png`` into ``outdir``; every file is written atomically.

    Returns
    -------
    dict
        A summary: output paths, metrics (or None), timings, part count.
    """
    from .io import DICOM_KINDS, detect_kind, load_ground_truth, load_input
    from .io.atomic import write_json
    from .io.labelmap import read_label_map
    from .io.mesh import write_mesh
    from .metrics import evaluate
    from .preview import write_preview
    from .rasterize import is_closed

    def say(stage: str) -> None:
        if progress is not None:
            progress(stage)

    out = Path(outdir)
    timings: dict[str, float] = {}
    say("read")
    value, name = 1, ""
    described = None
    with _timed(timings, "read"):
        label_map = (
            None
            if config.union or ground_truth is not None
            else read_label_map(
                input_path,
                allow_irregular=config.allow_irregular,
                memory_budget_gb=config.max_memory_gb,
            )
        )
    kind = detect_kind(input_path)
    if kind.kind == "rtstruct" and ground_truth is None:
        several, single = _rtstruct_rois(kind, config, image_dir)
        if several is not None:
            from .structures import run_structures_case

            return run_structures_case(
                several,
                input_path,
                out,
                config,
                progress=progress,
                timings=timings,
                coordinates="LPS",
                image_dir=image_dir,
            )
        if single is not None:
            config = replace(config, label=str(single.value), roi=None)
            value, name = single.value, single.name
            described = single
    if label_map is not None:
        if config.selectors:
            label_map = label_map.select(config.selectors, source=input_path)
        if len(label_map.structures) > 1:
            from .structures import run_structures_case

            return run_structures_case(
                label_map,
                input_path,
                out,
                config,
                progress=progress,
                timings=timings,
                image_dir=image_dir,
            )
        only = label_map.structures[0]
        value, name = only.value, only.name
        described = only
        data: Volume | CrossSections = label_map.mask(only.value)
        frame = label_map.coordinates
    else:
        with _timed(timings, "read"):
            data = load_input(
                input_path,
                label=None if config.union else config.label,
                roi=None if config.union else config.roi,
                image_dir=image_dir,
                allow_irregular=config.allow_irregular,
                memory_budget_gb=config.max_memory_gb,
            )
        frame = "LPS" if kind.kind in DICOM_KINDS else "RAS"
    with _timed(timings, "sections"):
        sections, projections, truth = prepare_inputs(
            data,
            slices=config.slices,
            every=config.every,
            axis=config.axis,
            projections=config.projections,
            memory_budget_gb=config.max_memory_gb,
        )
    if ground_truth is not None:
        with _timed(timings, "read"):
            truth = load_ground_truth(
                ground_truth,
                label=config.label,
                allow_irregular=config.allow_irregular,
                memory_budget_gb=config.max_memory_gb,
            )
    say("reconstruct")
    result = reconstruct(
        sections,
        projections,
        planner=config.planner,
        method=config.method,
        smooth=config.smooth,
        carve=config.carve,
        cover=config.cover,
        join_drift=config.join_drift,
        max_parts=config.max_parts,
        weights=config.weights,
        interpolation=config.interpolation,
    )
    timings.update(result.timings)
    metrics = None
    if truth is not None:
        say("evaluate")
        with _timed(timings, "metrics"):
            metrics = evaluate(
                result.mesh,
                truth,
                n_points=config.n_points,
                seed=config.seed,
                pred_occupancy=result.occupancy,
            )
    say("write")
    with _timed(timings, "write"):
        mesh_path = write_mesh(result.mesh, out / f"mesh.{config.mesh_format}")
        plan = result.plan.to_dict(affine=sections.affine)
        plan["sections"] = {
            "axis": "xyz"[sections.axis],
            "n_planes": sections.n_planes,
            "plane_indices": sections.indices.tolist(),
            "positions_mm": sections.positions.tolist(),
        }
        plan["projections"] = projections.source
        plan["input"] = str(input_path)
        plan["ground_truth"] = None if ground_truth is None else str(ground_truth)
        plan["config"] = asdict(config)
        plan["timings_s"] = {k: round(v, 4) for k, v in timings.items()}
        write_json(out / "plan.json", plan)
        if metrics is not None:
            write_json(out / "metrics.json", metrics.to_dict())
        grid = data if isinstance(data, Volume) else None
        labels, labels_affine = _label_grid(result, sections, grid, value)
        from .io.outputs import dicom_image_series, write_label_outputs
        from .labels import Structure

        structure = described if described is not None else Structure(value, name)
        outputs = write_label_outputs(
            out,
            labels,
            labels_affine,
            [structure],
            coordinates=frame,
            series=dicom_image_series(
                kind.kind, input_path, image_dir if image_dir is not None else kind.image_dir
            ),
            rtstruct=kind.path if kind.kind == "rtstruct" else None,
            allow_irregular=config.allow_irregular,
        )
        write_json(
            out / "structures.json",
            {
                "structures": [
                    {
                        **structure.to_dict(),
                        "status": "reconstructed",
                        "planes": int(np.count_nonzero(sections.masks.any(axis=(1, 2)))),
                        "volume_mm3": round(
                            float(np.count_nonzero(labels))
                            * abs(float(np.linalg.det(labels_affine[:3, :3]))),
                            3,
                        ),
                        "parts": len(result.plan.parts),
                        "mesh": mesh_path.name,
                    }
                ],
                "outputs": outputs.to_dict(),
            },
        )
        write_preview(
            out / "preview.png",
            mesh=result.mesh,
            boxes=result.plan.boxes,
            planner=result.plan.planner,
            sections=sections,
            projections=projections,
            occupancy=result.occupancy,
            truth=truth,
        )
    summary: dict[str, Any] = {
        "input": str(input_path),
        "mesh": str(mesh_path),
        "parts": len(result.plan.parts),
        "planes": sections.n_planes,
        "watertight": is_closed(result.mesh),
        "metrics": None if metrics is None else metrics.to_dict(),
        "timings_s": {k: round(v, 4) for k, v in timings.items()},
    }
    return summary


def _rtstruct_rois(kind: Any, config: ReconstructConfig, image_dir: Any) -> tuple[Any, Any]:
    """The ROIs of an RTSTRUCT to reconstruct: ``(several, None)`` when several chosen
    ROIs have contours; ``(None, structure)`` when one does (ROIs without contours
    are reported); ``(None, None)`` to let the one-structure reader decide."""
    from .io.rtstruct import read_rtstruct_structures

    if config.union:
        raise OptionError("--union applies to label maps; choose RTSTRUCT ROIs with --label")
    if len(config.selectors) == 1:
        return None, None
    structures, sections, union = read_rtstruct_structures(
        kind.path,
        rois=config.selectors,
        allow_irregular=config.allow_irregular,
        image_dir=image_dir if image_dir is not None else kind.image_dir,
        memory_budget_gb=config.max_memory_gb,
    )
    drawn = [s for s, own in zip(structures, sections, strict=True) if own is not None]
    if len(drawn) >= 2:
        return (structures, sections, union), None
    for structure, own in zip(structures, sections, strict=True):
        if own is None:
            logger.warning("ROI %s has no contours: nothing to reconstruct", structure.label)
    return None, drawn[0]


def _label_grid(
    result: Reconstruction, sections: CrossSections, grid: Volume | None, value: int
) -> tuple[NDArray[np.integer], NDArray[np.float64]]:
    """The reconstruction as a label map: on the input's grid for a dense input (``grid``),
    else on the sections' grid; ``value`` inside, 0 outside."""
    from .rasterize import mesh_to_mask

    shape = grid.shape if grid is not None else sections.grid_shape
    affine = grid.affine if grid is not None else sections.affine
    dtype = np.uint8 if 0 <= value < 256 else np.int32
    labels = np.zeros(shape, dtype=dtype)
    occupancy = result.occupancy
    if occupancy is not None and np.allclose(occupancy.affine[:3, :3], affine[:3, :3]):
        offset = np.linalg.solve(affine[:3, :3], occupancy.affine[:3, 3] - affine[:3, 3])
        lo = np.rint(offset).astype(np.int64)
        if np.allclose(offset, lo, atol=1e-6):
            region = tuple(
                slice(max(int(a), 0), min(int(a) + n, m))
                for a, n, m in zip(lo, occupancy.shape, shape, strict=True)
            )
            source = tuple(
                slice(r.start - int(a), r.stop - int(a)) for r, a in zip(region, lo, strict=True)
            )
            labels[region][occupancy.mask[source]] = value
            return labels, affine
    labels[mesh_to_mask(result.mesh, affine, shape)] = value
    return labels, affine
