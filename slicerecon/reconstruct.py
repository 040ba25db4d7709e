"""Reconstruct one structure: sections + projections → plan → watertight mesh.

:func:`reconstruct` is the reconstruction of one structure from its
cross-sections and its orthographic projections, with one
:class:`~slicerecon.options.ReconstructOptions` bundle. It holds no geometry of
its own: it composes the planners (:mod:`slicerecon.partition`) and the
surfaces (:mod:`slicerecon.surface`). :class:`ReconstructConfig` is that
bundle plus what a case needs around it (plane choice, structures, outputs,
budget); the case pipeline (:func:`slicerecon.case.run_case`) and the command
line fill it.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from numbers import Integral
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import trimesh

from .errors import GeometryError, InputError, OptionError
from .inputs import (
    DEFAULT_SLICES,
    MAX_AXIS_UPSAMPLE,
    PROJECTION_SOURCES,
    axis_upsample,
    looks_sparse,
    prepare_inputs,
)
from .io.limits import DEFAULT_MEMORY_BUDGET_GB, check_budget
from .options import INTERPOLATIONS, OPTION_NAMES, PLAIN_SDF, ReconstructOptions
from .partition.lookahead import PlanningSurface
from .partition.planner import Plan, PlanPart, plan_partition, planner_names
from .plane_detection import parse_annotation
from .sampling import pool_any, pool_sections, visual_hull
from .sections import AXIS_NAMES, Box, CrossSections, Projections, Volume, axis_index
from .selection import parse_selector
from .surface.methods import method_names
from .surface.smooth import taubin_smooth

if TYPE_CHECKING:
    from .partition.lookahead import PlanningSurface

__all__ = [
    "DEFAULT_SLICES",
    "INTERPOLATIONS",
    "MAX_AXIS_UPSAMPLE",
    "MESH_FORMATS",
    "METHODS",
    "PLAIN_SDF",
    "PLANNERS",
    "PROJECTION_SOURCES",
    "WHOLE_SHAPE_METHODS",
    "ReconstructConfig",
    "ReconstructOptions",
    "Reconstruction",
    "axis_upsample",
    "looks_sparse",
    "prepare_inputs",
    "reconstruct",
]

logger = logging.getLogger(__name__)

PLANNERS = tuple(planner_names())
"""Planner names (:data:`slicerecon.partition.planner.PLANNERS`, complete at import)."""
METHODS = method_names()
"""Surface method names (:data:`slicerecon.surface.methods.METHODS`)."""
WHOLE_SHAPE_METHODS = method_names(per_part=False)
"""Methods that reconstruct all the sections at once, without a partition
(:mod:`slicerecon.surface.baselines`); planners and carving apply to the others only."""
MESH_FORMATS = ("stl", "ply", "obj")

PLANNING_MAX_GRID = 192
"""Planners see at most this many voxels along a side: larger grids are planned on
a pooled copy (:func:`slicerecon.partition.planner.plan_partition`, ``max_grid``)
and the parts mapped back, so planning costs the same at clinical sizes as on a
192-voxel shape; the surface is always made at full resolution."""


@dataclass(frozen=True)
class ReconstructConfig(ReconstructOptions):
    """Everything one case needs: the reconstruction options, and around them the
    plane choice, the structures, the outputs and the budget (what ``slicerecon
    run`` fills in).

    The reconstruction options are those of :class:`~slicerecon.options.ReconstructOptions`
    (documented there once); :attr:`options` is that bundle alone.
    """

    slices: int | None = None
    """Keep N evenly spaced planes of a dense input (default 16 when neither
    ``slices`` nor ``every`` is given)."""
    every: int | None = None
    """Keep every K-th plane of a dense input instead of ``slices``."""
    axis: str = "z"
    """Grid axis the section planes of a dense input are perpendicular to (x, y or z)."""
    dense_only: bool = False
    """``slices``, ``every`` and ``axis`` are meant for the dense inputs among others
    (a batch mixing dense masks and annotations): an annotation leaves them out with a
    note instead of refusing them."""
    annotation: str = "auto"
    """How a label map is read: ``auto`` (dense, or annotated on some planes of
    any axes, by the rule of :mod:`slicerecon.plane_detection`), ``dense``, or
    the annotated axes (``z``, ``xz``, ``x,y,z``) when the rule cannot tell."""
    projections: str = "auto"
    """Where the orthographic projections come from: ``gt`` (the dense input,
    the paper's prior), ``sections`` (derived from the sections alone),
    ``auto`` (``gt`` for dense inputs, ``sections`` for sparse ones), or one
    to three comma-separated NIfTI silhouette files of a one-structure case
    (:func:`slicerecon.io.projections.read_projection_files`)."""
    mesh_format: str = "stl"
    """Output mesh format: stl, ply or obj."""
    label: int | str | Sequence[int | str] | None = None
    """The structures to keep, by number or name, comma-separated (or a list, kept
    as a tuple: a name holding a comma, ``["Kidney, right"]``): label values, SEG
    segment numbers or labels, RTSTRUCT ROI numbers or names (default: every
    structure)."""
    roi: int | str | Sequence[int | str] | None = None
    """RTSTRUCT ROI name or number (another name for ``label``)."""
    union: bool = False
    """Treat every non-zero voxel (every structure) as one structure."""
    allow_irregular: bool = False
    """Accept DICOM series with uneven slice spacing."""
    pixel_spacing: float | None = None
    """In-plane pixel size, mm, of the grid contours are rasterized on when they
    come without one (a contour file without ``grid``, an RTSTRUCT without its
    image series); default: the longest in-plane extent / 256. A contour
    file's own grid is then not used."""
    n_points: int = 50_000
    """Surface samples per mesh for the distance metrics."""
    max_memory_gb: float = DEFAULT_MEMORY_BUDGET_GB
    """Memory budget of one case, GiB: inputs whose grid would need more are
    refused before anything is allocated (:mod:`slicerecon.io.limits`)."""
    seed: int = 0
    """Seed of every random choice (surface sampling)."""

    @property
    def options(self) -> ReconstructOptions:
        """The reconstruction options alone, as one bundle."""
        return ReconstructOptions(**{name: getattr(self, name) for name in OPTION_NAMES})

    @property
    def selectors(self) -> list[int | str]:
        """The structures ``label`` (or ``roi``) names: comma-separated numbers or names."""
        return _selectors(self.label if self.label is not None else self.roi)

    @property
    def projection_files(self) -> list[str]:
        """The silhouette files ``projections`` names (empty for ``auto``, ``gt``, ``sections``)."""
        if self.projections in PROJECTION_SOURCES:
            return []
        return [f.strip() for f in str(self.projections).split(",") if f.strip()]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready form, every field at one level (``plan.json``'s ``config``)."""
        from dataclasses import asdict

        return asdict(self)

    def __post_init__(self) -> None:
        super().__post_init__()
        for name in ("label", "roi"):  # a list of values or names, as Python callers give it
            chosen = getattr(self, name)
            if isinstance(chosen, (list, tuple)):
                object.__setattr__(self, name, tuple(chosen) or None)
        for name in ("slices", "every"):
            count = getattr(self, name)
            if count is not None and (isinstance(count, bool) or not isinstance(count, Integral)):
                raise OptionError(f"--{name} must be a whole number (got {count!r})")
            if count is not None:
                object.__setattr__(self, name, int(count))
        if self.union and (self.label is not None or self.roi is not None):
            raise OptionError("give --label or --union, not both")
        if self.label is not None and self.roi is not None:
            if _selectors(self.label) != _selectors(self.roi):
                raise OptionError(f"--label {self.label} and --roi {self.roi} disagree; give one")
        if self.slices is not None and self.every is not None:
            raise OptionError("give --slices or --every, not both")
        if self.slices is not None and self.slices < 2:
            raise OptionError(f"--slices must be at least 2 (got {self.slices})")
        if self.every is not None and self.every < 1:
            raise OptionError(f"--every must be at least 1 (got {self.every})")
        axis_index(self.axis)
        parse_annotation(self.annotation)
        if self.mesh_format not in MESH_FORMATS:
            raise OptionError(
                f"--format must be one of {', '.join(MESH_FORMATS)} (got {self.mesh_format!r})"
            )
        if not isinstance(self.projections, str) or not self.projections.strip():
            raise OptionError(
                f"--projections must be one of {', '.join(PROJECTION_SOURCES)} or silhouette files"
            )
        for name in self.projection_files:
            if not Path(name).is_file():
                raise OptionError(f"--projections: silhouette file not found: {name}")
        if len(self.projection_files) > 3:
            raise OptionError("--projections takes one to three silhouette files")
        check_budget(self.max_memory_gb)
        if self.pixel_spacing is not None and not (
            np.isfinite(self.pixel_spacing) and self.pixel_spacing > 0
        ):
            raise OptionError(
                f"--pixel-spacing must be a positive number of mm (got {self.pixel_spacing})"
            )
        for name in ("n_points", "seed"):  # checked here, not after the reconstruction
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, Integral):
                raise OptionError(f"{name} must be a whole number (got {value!r})")
        if self.n_points < 1:
            raise OptionError(f"n_points must be >= 1 (got {self.n_points})")
        for name in ("union", "allow_irregular"):
            if not isinstance(getattr(self, name), bool):
                raise OptionError(f"{name} must be True or False (got {getattr(self, name)!r})")


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


def _scale(affine: np.ndarray) -> float:
    """The size of a grid's coordinates (mm): what an affine's tolerance is relative to."""
    return max(1.0, float(np.abs(affine).max()))


def _selectors(chosen: int | str | Sequence[int | str] | None) -> list[int | str]:
    """The structures a ``label`` names: a number, comma-separated numbers or names, or a
    sequence of them (each item one structure, commas and all)."""
    if chosen is None:
        return []
    if isinstance(chosen, int):
        return [chosen]
    if isinstance(chosen, str):
        parts: Sequence[int | str] = chosen.split(",")
    else:
        parts = chosen
    return [v for part in parts if (v := parse_selector(part)) is not None]


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

    return _exact_on_planes(visual_hull(projections, sections.grid_shape), sections)


def _planning_surface(
    sections: CrossSections, hull: np.ndarray, options: ReconstructOptions
) -> Callable[[int], PlanningSurface]:
    """The sections, hull and part surface on the planning grid (a ``SurfaceFactory``).

    For the planners that score their choices on reconstructions
    (:func:`slicerecon.partition.lookahead.plan_lookahead`): the signed-distance
    part surface with the options' interpolation and drift joining, extended
    along the hull and carved by it; on a pooled grid the sections and the
    hull are pooled the same way (:func:`~slicerecon.sampling.pool_sections`).
    """
    from .surface.part import part_voxels

    part_options = options.with_changes(method="sdf")

    def surface(factor: int) -> PlanningSurface:
        grid_hull = pool_any(hull, factor)

        def part(part_sections: CrossSections, box: Box) -> np.ndarray:
            voxels = part_voxels(part_sections, box, part_options, hull=grid_hull)
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
    options: ReconstructOptions | None = None,
    *,
    keep_field: bool = False,
    upsample: int | None = None,
    **changes: Any,
) -> Reconstruction:
    """Reconstruct a watertight surface from cross-sections and projections.

    Parameters
    ----------
    sections : CrossSections
        The planar cross-sections.
    projections : Projections
        Orthographic silhouettes on the same grid (from the dense mask or
        derived from the sections).
    options : ReconstructOptions, optional
        Planner, surface method, interpolation, carve and cover, drift
        joining, smoothing, parts and weights (default: the defaults). Per-part
        methods reconstruct each part of the plan; the whole-shape baselines
        (:data:`WHOLE_SHAPE_METHODS`, :mod:`slicerecon.surface.baselines`) run
        on all the sections at once: no planner runs, the plan records one
        part whose box is the sections' bounding box, and the mesh is not
        carved (``sdf-hull`` intersects with the hull itself). The carve is
        made in the implicit domain for implicit methods (one marching cubes,
        :func:`slicerecon.surface.sdf.sdf_parts_mesh`), by an exact mesh
        Boolean otherwise (:func:`slicerecon.surface.carve.carve`). The cover
        applies only to silhouettes that say something the sections do not:
        never with projections derived from the sections
        (``projections.source == "sections"``).
    keep_field : bool
        Keep an implicit surface's field (:attr:`Reconstruction.field`), e.g. to
        resolve several structures against each other.
    upsample : int, optional
        Field samples per voxel along the section axis for implicit methods
        (default: :func:`axis_upsample`).
    **changes
        Options to change from ``options`` (``method="loft"``, ``planner="none"`` ...).

    Returns
    -------
    Reconstruction

    Raises
    ------
    OptionError
        A bad option.
    EmptyMaskError
        No section holds foreground.
    InputError
        ``sections`` or ``projections`` of another type (given in the wrong order).
    GeometryError
        ``projections`` on another grid than ``sections`` (another affine).
    """
    from .surface.part import reconstruct_surface

    if not isinstance(sections, CrossSections) or not isinstance(projections, Projections):
        raise InputError(
            "reconstruct takes (sections, projections), a CrossSections and Projections "
            f"(got {type(sections).__name__}, {type(projections).__name__}): make them with "
            "slicerecon.reconstruct.prepare_inputs"
        )
    for view in projections:  # same shape but another grid was taken without a word
        if not np.allclose(view.affine, sections.affine, atol=1e-6 * _scale(sections.affine)):
            raise GeometryError(
                f"the projection along {AXIS_NAMES[view.axis]} lies on another grid than the "
                "sections (their affines differ): make both on one grid "
                "(slicerecon.reconstruct.prepare_inputs)"
            )
    options = (options or ReconstructOptions()).with_changes(**changes)
    entry = options.method_entry
    if not entry.per_part:
        return _reconstruct_whole_shape(sections, projections, options)
    options = options.with_changes(
        planner=options.resolved_planner(sparse=projections.source == "sections")
    )
    planner = options.planner_entry
    timings: dict[str, float] = {}
    with _timed(timings, "plan"):
        hull = visual_hull(projections, sections.grid_shape)
        occupancy = _exact_on_planes(hull, sections) if planner.partitions else hull
        guide = hull if planner.partitions else None
        # No planner's choice at inference depends on the reward's reconstruction
        # term (it is what training optimises), so parts are not reconstructed
        # twice: the plan's rewards hold IoU(W_i, O) only.
        surface = _planning_surface(sections, hull, options) if planner.needs_surface else None
        plan = plan_partition(
            occupancy,
            planner=options.planner,
            reconstruct=None,
            max_parts=options.max_parts,
            weights=options.weights,
            max_grid=PLANNING_MAX_GRID,
            surface=surface,
        )
    implicit_carve = options.carve and entry.implicit and not options.smooth
    with _timed(timings, "surface"):
        made = reconstruct_surface(
            sections,
            [part.box for part in plan.parts],
            options,
            extend_to_box=planner.partitions,
            hull=guide,
            carve=hull if implicit_carve else None,
            upsample=(upsample or axis_upsample(sections)) if entry.implicit else 1,
            keep_field=keep_field,
            cover=options.cover and implicit_carve and projections.source != "sections",
        )
        mesh, occupancy_vol = made.mesh, made.occupancy
    if options.carve and entry.carved and not implicit_carve:
        from .surface.carve import carve as carve_by_hull

        with _timed(timings, "carve"):
            mesh = carve_by_hull(mesh, hull, sections.affine)
    return Reconstruction(mesh, plan, sections, projections, timings, occupancy_vol, made.field)


def _reconstruct_whole_shape(
    sections: CrossSections, projections: Projections, options: ReconstructOptions
) -> Reconstruction:
    """A whole-shape baseline on all the sections, recorded as a one-part plan."""
    from .surface.baselines import reconstruct_baseline, sections_box

    timings: dict[str, float] = {}
    with _timed(timings, "plan"):
        box = sections_box(sections)
        voxels = int(np.count_nonzero(planning_occupancy(sections, projections)[box.slices]))
        plan = Plan("none", (PlanPart(box, None, voxels),), sections.grid_shape)
    with _timed(timings, "surface"):
        mesh = reconstruct_baseline(sections, projections, method=options.method)
        if options.smooth:
            mesh = taubin_smooth(mesh)
    return Reconstruction(mesh, plan, sections, projections, timings)
