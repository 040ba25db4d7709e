"""One case: read an input into an annotation, reconstruct every structure, score it.

This is the one case pipeline, for one structure and for many:

1. **read** (:func:`slicerecon.case_inputs.load_case`): the input becomes a
   :class:`~slicerecon.annotation.Annotation`. A dense label map (NIfTI, NRRD,
   VTI, DICOM mask series, SEG; a mesh, voxelised) is cropped to all its
   structures together and its planes are chosen **once** over their union
   (``--slices`` / ``--every``, :func:`slicerecon.inputs.prepare_inputs`); it is
   then each structure's ground truth. A sparse label map keeps the planes it
   annotates. An RTSTRUCT gives each ROI on its own contour planes, a contour
   file one structure.
2. **reconstruct** (:func:`reconstruct_case`): each structure from its own
   planes on its own crop, with :func:`slicerecon.reconstruct.reconstruct`
   and one :class:`~slicerecon.options.ReconstructOptions`. The structures of
   a label map (a partition) are then resolved jointly on their
   signed-distance fields (:func:`slicerecon.surface.joint.resolve`): no
   voxel belongs to two, touching structures share their interface. RTSTRUCT
   ROIs may overlap or nest and are reconstructed independently: an ROI
   inside another is never given away.
3. **score** (:func:`score_case`): each structure against its own ground
   truth, when there is one.
4. **write** (:func:`slicerecon.case_outputs.write_case`), one on-disk schema
   whatever the number of structures.

:func:`run_case` does the four; :func:`reconstruct_structures` is the Python
entry point for a label map given as a path, a
:class:`~slicerecon.labels.LabelMap`, or an array with its affine.
"""

from __future__ import annotations

import logging
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, fields, replace
from typing import Any, cast

import numpy as np
import trimesh
from numpy.typing import NDArray
from scipy import ndimage

from .annotated_planes import nested_apart
from .annotation import Annotation
from .case_inputs import CaseInput, case_from_label_map, load_case
from .case_outputs import check_outdir, write_case
from .crossings import warn_views_disagree
from .errors import InputError, OptionError
from .evaluation import score_case
from .inputs import GT_NEEDS_DENSE, axis_upsample
from .io.limits import PIPELINE_BYTES_PER_VOXEL, check_bytes
from .io.projections import read_projection_files
from .labels import LabelMap, Structure, StructureMasks, check_label_values, labels_dtype
from .messages import collected_warnings
from .metrics.inputs import place
from .options import ReconstructOptions
from .partition.planner import Plan, PlanPart
from .rasterize import mesh_to_mask
from .reconstruct import ReconstructConfig, reconstruct
from .sampling import projections_from_sections, projections_from_volume
from .sections import Box, CrossSections, Projections, Volume, crop_affine
from .surface.joint import cut_nested, fields_bytes, keep_drawn_sections, resolve
from .surface.smooth import taubin_smooth
from .surface.views import views_surface, views_upsample

__all__ = [
    "NOT_RECONSTRUCTED",
    "NO_CONTOURS",
    "NO_PLANE",
    "CaseInput",
    "CaseReconstruction",
    "StructureResult",
    "case_from_label_map",
    "crop_to_structure",
    "load_case",
    "reconstruct_case",
    "reconstruct_structures",
    "run_case",
    "score_case",
]

logger = logging.getLogger(__name__)

RECONSTRUCTED = "reconstructed"
"""Status of a structure that has a mesh."""
NO_PLANE = "no kept plane crosses it"
"""Status of a structure the chosen planes miss."""
NOT_RECONSTRUCTED = "every voxel went to a neighbour"
"""Status of a structure whose reconstruction lost every voxel to other structures."""
NO_CONTOURS = "no closed planar contours"
"""Status of an RTSTRUCT ROI that holds no contour."""
CROP_PAD = 3
"""Voxels kept around a structure's extent when it is reconstructed on its own crop."""

Progress = Callable[[str], None]


# ------------------------------------------------------------------------ reconstruct
@dataclass
class StructureResult:
    """One structure of a case.

    Attributes
    ----------
    structure : Structure
        Value, name and colour.
    status : str
        ``"reconstructed"``, or why it was not (:data:`NO_PLANE`,
        :data:`NOT_RECONSTRUCTED`, :data:`NO_CONTOURS`).
    mesh : trimesh.Trimesh or None
        Its watertight surface, world mm.
    planes : int
        Annotated planes that hold it.
    occupancy : Volume or None
        Its voxels, when known without rasterizing, on its own crop of the
        grid (for a partition of several structures, its share's box on the
        shared grid; ``occupancy.affine`` places it).
    plan : Plan or None
        The partition its reconstruction used.
    metrics : dict or None
        Its metrics against its ground truth (:func:`score_case`).
    sections, projections : CrossSections, Projections or None
        What it was reconstructed from, on its own crop of the shared grid.
        Drawn in several views, it was reconstructed from every plane
        (:mod:`slicerecon.surface.views`) and ``sections`` holds the planes
        of the main view only.
    volume_mm3 : float
        Volume of its voxels in the written label map's grid, mm³ (before any
        overlap is resolved in that one file).
    """

    structure: Structure
    status: str
    mesh: trimesh.Trimesh | None = None
    planes: int = 0
    occupancy: Volume | None = None
    plan: Any = None
    metrics: dict[str, Any] | None = None
    sections: CrossSections | None = None
    projections: Projections | None = None
    volume_mm3: float = 0.0
    field: Any = None

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready record (``structures.json``)."""
        return {
            **self.structure.to_dict(),
            "status": self.status,
            "planes": self.planes,
            "volume_mm3": round(self.volume_mm3, 3),
            "parts": None if self.plan is None else len(self.plan.parts),
        }


@dataclass
class CaseReconstruction:
    """Every structure of a case, reconstructed.

    Attributes
    ----------
    results : list of StructureResult
        One per structure, in the annotation's order (then the ones with nothing drawn).
    labels : ndarray of shape output_shape, integer
        The reconstructed label map on the output grid (the input's grid for
        label maps), with the structures' values. Where structures overlap (an
        annotation that is not a partition) the smallest is written.
    affine : ndarray of shape (4, 4)
        Voxel index → world mm of :attr:`labels`.
    sections : CrossSections
        Every structure's planes together, on the shared grid (along the axis
        most planes are perpendicular to, when they lie along several).
    truth : LabelMap or None
        Each structure's ground truth on the shared grid (dense inputs).
    crop_lo : ndarray of shape (3,)
        Where the shared grid starts on the grid of :attr:`labels`.
    coordinates : {"RAS", "LPS"}
    exclusive : bool
        Whether the structures were resolved as a partition.
    overlap_voxels : int
        Voxels claimed by several structures (0 for a partition).
    timings : dict of str to float
    layers : ndarray of shape (L, I, J, K), integer, or None
        Where structures overlap: a layered label map on the grid of
        :attr:`labels` that holds every structure whole (each layer a label map
        of structures that do not overlap; a value lies in one layer), what
        ``labels.seg.nrrd``, ``seg.dcm`` and ``rtstruct.dcm`` are written from.
        None when no voxel is claimed twice.
    warnings : list of str
        What :func:`reconstruct_structures` warned of, one line each, as ``run``
        prints them (also logged on the ``slicerecon`` logger).
    """

    results: list[StructureResult]
    labels: NDArray[np.integer]
    affine: NDArray[np.float64]
    sections: CrossSections
    truth: LabelMap | StructureMasks | None
    crop_lo: NDArray[np.int64]
    coordinates: str = "RAS"
    exclusive: bool = True
    overlap_voxels: int = 0
    timings: dict[str, float] = field(default_factory=dict)
    layers: NDArray[np.integer] | None = None
    warnings: list[str] = field(default_factory=list)

    @property
    def reconstructed(self) -> list[StructureResult]:
        """The structures that have a mesh."""
        return [r for r in self.results if r.mesh is not None]

    def truth_mask(self, value: int) -> Volume:
        """A structure's own ground-truth mask on the shared grid (dense inputs only)."""
        if self.truth is None:
            raise OptionError("this case has no dense ground truth")
        return self.truth.mask(value)


def crop_to_structure(
    own: CrossSections, mask: NDArray[np.bool_] | None
) -> tuple[CrossSections, Projections, NDArray[np.int64]]:
    """A structure's sections on the crop of the shared grid around it, its silhouettes,
    and where the crop starts on the shared grid.

    Parameters
    ----------
    own : CrossSections
        The structure's planes on the shared grid.
    mask : ndarray of shape own.grid_shape, bool, or None
        Its dense mask (a dense input: the crop is its bounding box and its
        silhouettes come from it), or None (the crop is the extent of its
        planes; silhouettes derived from them).

    Returns
    -------
    sections : CrossSections
        On the crop, :data:`CROP_PAD` voxels around the structure.
    projections : Projections
    lo : ndarray of shape (3,), int
    """
    axis = own.axis
    a, b = own.plane_axes
    grid = np.asarray(own.grid_shape)
    if mask is not None:
        lo, hi = Volume(mask, own.affine).bounding_box_vox()
    else:
        rows = np.flatnonzero(own.masks.any(axis=(0, 2)))
        cols = np.flatnonzero(own.masks.any(axis=(0, 1)))
        drawn = own.indices[own.masks.any(axis=(1, 2))]
        lo, hi = np.zeros(3, np.int64), np.zeros(3, np.int64)
        lo[a], hi[a] = rows[0], rows[-1] + 1
        lo[b], hi[b] = cols[0], cols[-1] + 1
        lo[axis] = int(np.floor(drawn.min() + 0.5))
        hi[axis] = int(np.ceil(drawn.max() + 0.5))
    lo = np.maximum(lo - CROP_PAD, 0)
    hi = np.minimum(hi + CROP_PAD, grid)
    keep = np.flatnonzero((own.indices >= lo[axis] - 0.5) & (own.indices <= hi[axis] - 0.5))
    sub = CrossSections(
        own.masks[keep][:, lo[a] : hi[a], lo[b] : hi[b]],
        own.indices[keep] - lo[axis],
        axis,
        crop_affine(own.affine, lo),
        tuple(int(v) for v in hi - lo),
    )
    if mask is not None:
        crop = mask[lo[0] : hi[0], lo[1] : hi[1], lo[2] : hi[2]]
        projections = projections_from_volume(Volume(crop, sub.affine))
    else:
        projections = projections_from_sections(sub)
    return sub, projections, lo


def _projections(
    config: ReconstructConfig, sub: CrossSections, derived: Projections, *, dense: bool, many: bool
) -> Projections:
    """A structure's silhouettes as ``--projections`` asks (``derived``: from its dense
    mask when the input is dense, else from its sections)."""
    source = config.projections
    if source == "auto":
        source = "gt" if dense else "sections"
    if source == "gt":
        if not dense:
            raise OptionError(
                "--projections gt needs a dense mask as input; use --projections sections"
            )
        return derived
    if source == "sections":
        return derived if not dense else projections_from_sections(sub)
    if many:
        raise OptionError(
            "silhouette files (--projections FILE) describe one structure; choose one with --label"
        )

    return read_projection_files(config.projection_files, sub)


def reconstruct_case(
    case: CaseInput, config: ReconstructConfig, *, progress: Progress | None = None
) -> CaseReconstruction:
    """Reconstruct every structure of a case.

    Each structure is reconstructed from its own planes on its own crop of the
    shared grid (:func:`crop_to_structure`), as a run on that structure alone
    would, so ``N`` structures cost about the sum of ``N`` single runs. The
    structures of a partition are then resolved jointly on their
    signed-distance fields; the others keep their own surfaces.

    Parameters
    ----------
    case : CaseInput
    config : ReconstructConfig
        Its :attr:`~slicerecon.reconstruct.ReconstructConfig.options` apply to
        every structure; ``projections`` says where silhouettes come from.
    progress : callable, optional
        Called with a short stage text (``"reconstruct 2/4: 2_Liver"``).

    Returns
    -------
    CaseReconstruction

    Raises
    ------
    OptionError
        A partition of several structures with a method that has no field to
        resolve them on; silhouette files with several structures.
    """
    annotation = case.annotation
    sparse = not case.dense
    options = config.options
    options = options.with_changes(planner=options.resolved_planner(sparse=sparse))
    one_axis = annotation.grid_axis() is not None
    # A sparse annotation in one part (the default: a partition measured no better on
    # sparse input) is reconstructed from all its views at once (surface.views); for
    # one view that is the implicit surface of one part, uncarved.
    views = (
        sparse
        and not options.planner_entry.partitions
        and options.method_entry.implicit
        and config.projections in ("auto", "sections")
    )
    shared = _shared_sections(annotation, one_axis)
    drawn = annotation.structures
    joint = annotation.exclusive and len(drawn) > 1
    if joint and not options.method_entry.implicit:
        raise OptionError(
            f"several structures of a label map are resolved on their signed distances: "
            f"use --method sdf (got {options.method!r}), or choose one structure with "
            "--label, or --union"
        )
    if sparse and config.projections == "gt":
        raise OptionError(GT_NEEDS_DENSE)
    if not one_axis and sparse and config.projections not in ("auto", "sections"):
        raise OptionError(
            "silhouette files (--projections) apply to planes along one axis; planes along "
            "several axes are their own views: leave --projections out"
        )
    if not one_axis and not views:
        raise OptionError(
            "planes along several axes are reconstructed in one part on their signed "
            f"distances: use --planner auto or none and --method sdf (got --planner "
            f"{options.planner}, --method {options.method}), or --annotation to read one axis"
        )
    per_structure = options.with_changes(smooth=False) if joint else options
    upsample = axis_upsample(shared) if not views else 1
    if joint:  # every structure's field is held, beside the grid, until they are resolved
        sampling = views_upsample(annotation) if views else upsample
        held = fields_bytes(annotation, sampling, CROP_PAD)
        check_bytes(
            held + PIPELINE_BYTES_PER_VOXEL * int(np.prod(annotation.grid_shape)),
            what=f"resolving {len(drawn)} structures together (their fields and the grid)",
            memory_budget_gb=config.max_memory_gb,
        )
    timings: dict[str, float] = {}
    results: list[StructureResult] = []
    fields: list[Any] = []
    for n, structure in enumerate(drawn, start=1):
        if progress is not None:
            progress(f"reconstruct {n}/{len(drawn)}: {structure.label}")
        crossed = sum(
            1 for p in annotation.planes_of(structure.value) if structure.value in p.masks
        )
        if not crossed:
            logger.warning(
                "%s: structure %s %s: not reconstructed",
                case.source_of(structure.value),
                structure.label,
                "lies between the kept planes" if case.dense else "is drawn on no plane",
            )
            results.append(StructureResult(structure, NO_PLANE))
            fields.append(None)
            continue
        if crossed == 1 and sparse:
            alone = len(annotation.planes_of(structure.value)) == 1
            logger.warning(
                "%s: structure %s is drawn on one plane only: %s",
                case.source_of(structure.value),
                structure.label,
                "its reconstruction is a slab one slice thick"
                if alone
                else "it ends towards the planes beside it, where it is absent",
            )
        start = time.perf_counter()
        if views:
            results.append(_from_views(case, structure, per_structure, crossed))
            fields.append(results[-1].field)
            timings["reconstruct"] = timings.get("reconstruct", 0.0) + time.perf_counter() - start
            continue
        own = annotation.cross_sections(structure.value)
        mask = None if case.labels is None else case.labels.mask(structure.value).mask
        sub, derived, offset = crop_to_structure(own, mask)
        projections = _projections(config, sub, derived, dense=case.dense, many=len(drawn) > 1)
        result = reconstruct(sub, projections, per_structure, keep_field=joint, upsample=upsample)
        for stage, seconds in result.timings.items():
            timings[stage] = timings.get(stage, 0.0) + seconds
        timings["reconstruct"] = timings.get("reconstruct", 0.0) + time.perf_counter() - start
        item = StructureResult(
            structure,
            RECONSTRUCTED,
            mesh=result.mesh,
            planes=crossed,
            occupancy=result.occupancy,
            plan=result.plan,
            sections=sub,
            projections=projections,
        )
        results.append(item)
        if joint:
            field = result.field
            fields.append(
                field._replace(lo=tuple(int(a + b) for a, b in zip(field.lo, offset, strict=True)))
            )
    if joint:
        start = time.perf_counter()
        _resolve(results, fields, annotation, smooth=options.smooth, source=case.named)
        timings["resolve"] = time.perf_counter() - start
    results += [StructureResult(s, NO_CONTOURS) for s in case.missing]
    labels, overlap, layers = _label_map(case, results)
    logger.info(
        "%d structure(s): %d reconstructed",
        len(results),
        sum(r.mesh is not None for r in results),
    )
    return CaseReconstruction(
        results,
        labels,
        case.output_affine,
        shared,
        case.labels,
        case.crop_lo,
        annotation.coordinates,
        annotation.exclusive,
        overlap,
        timings,
        layers,
    )


def _from_views(
    case: CaseInput, structure: Structure, options: ReconstructOptions, crossed: int
) -> StructureResult:
    """A structure drawn in one or several views (:mod:`slicerecon.surface.views`), in one
    part: its plan records that part's box. A structure with a grid of its own
    (:meth:`~slicerecon.annotation.Annotation.of_structure`) is reconstructed there; its
    voxels on the written grid are then its mesh rasterized."""
    annotation = case.annotation.of_structure(structure.value)
    own_grid = annotation is not case.annotation
    warn_views_disagree(
        annotation, structure.value, case.source_of(structure.value), structure.label
    )
    made = views_surface(
        annotation,
        structure.value,
        interpolation=options.interpolation,
        join_drift=options.join_drift,
    )
    mesh = taubin_smooth(made.mesh) if options.smooth else made.mesh
    field = made.field
    size = np.asarray(field.values.shape) - 2
    size[field.axis] //= field.upsample
    lo = np.maximum(np.asarray(field.lo), 0)
    hi = np.minimum(np.asarray(field.lo) + size, annotation.grid_shape)
    box = Box(tuple(int(v) for v in lo), tuple(int(v) for v in np.maximum(hi, lo + 1)))
    voxels = (  # inside samples, counted on the grid's voxels (the field may be finer)
        int(np.count_nonzero(made.occupancy.mask))
        if made.occupancy is not None
        else round(np.count_nonzero(field.values < 0) / field.upsample)
    )
    return StructureResult(
        structure,
        RECONSTRUCTED,
        mesh=mesh,
        planes=crossed,
        occupancy=None if options.smooth or own_grid else made.occupancy,
        plan=Plan("none", (PlanPart(box, None, voxels),), annotation.grid_shape),
        sections=(own := _main_sections(annotation, structure.value)),
        projections=None if own is None else projections_from_sections(own),
        field=field,
    )


def _main_sections(annotation: Annotation, value: int | None) -> CrossSections | None:
    """The planes (of structure ``value``, or all) that are slices of the annotation's main
    grid axis (the one most of its drawings lie on: drawn on sagittal and coronal slices
    only beside others' axial ones, it was refused), or None when no plane is a slice of
    the grid (a radial set)."""
    planes = annotation.planes if value is None else annotation.planes_of(value)
    counts = [0, 0, 0]
    for plane in planes:
        if value is not None and not plane.mask(value).any():
            continue
        axis = annotation.axis_of(plane.pose)
        if axis is not None and annotation.grid_shift(plane.pose, axis) is not None:
            counts[axis] += 1
    if not any(counts):
        return None
    return annotation.cross_sections(value, axis=int(np.argmax(counts)))


def _shared_sections(annotation: Annotation, one_axis: bool) -> CrossSections | None:
    if one_axis:
        return annotation.cross_sections()
    return _main_sections(annotation, None)


def _resolve(
    results: list[StructureResult],
    fields: list[Any],
    annotation: Annotation,
    *,
    smooth: bool,
    source: str | os.PathLike[str],
) -> None:
    """Resolve a partition's structures on their fields: meshes and shares (each on its
    own box: on the whole grid, 80 structures of a 512 x 512 x 200 map held 2 GiB of
    masks) in place. A structure drawn inside another on planes of its own is cut out
    of it (said in one line: the other's drawn pixels around it change hands)."""
    values = [r.structure.value for r in results]
    nested = nested_apart(annotation)
    if nested:
        label = {r.structure.value: r.structure.label for r in results}
        logger.warning(
            "%s: structure(s) %s drawn on planes of their own: each is cut out of the "
            "structure around it, also on that structure's own planes (a label map holds "
            "one structure per voxel); to keep both whole, save them as overlapping "
            "segments (.seg.nrrd layers or DICOM SEG)",
            source,
            ", ".join(f"{label[i]} inside {label[o]}" for i, o in nested.items()),
        )
    keep_drawn_sections(fields, values, annotation, nested)
    cut_nested(fields, values, nested)
    joint = resolve(fields, annotation.grid_shape)
    boxes = ndimage.find_objects(joint.labels + 1, max_label=len(results))
    for i, item in enumerate(results):
        if fields[i] is None:
            continue
        box = boxes[i]
        mesh = joint.meshes[i]
        if mesh is None or box is None:
            item.status, item.mesh, item.occupancy = NOT_RECONSTRUCTED, None, None
            logger.warning(
                "structure %s: %s (its neighbours are closer everywhere)",
                item.structure.label,
                NOT_RECONSTRUCTED,
            )
            continue
        item.mesh = taubin_smooth(mesh) if smooth else mesh
        corner = [b.start for b in box]
        item.occupancy = Volume(joint.labels[box] == i, crop_affine(annotation.affine, corner))


def _label_map(
    case: CaseInput, results: list[StructureResult]
) -> tuple[NDArray[np.integer], int, NDArray[np.integer] | None]:
    """The structures as one label map on the output grid, the voxels claimed twice, and
    the layered label map that keeps each structure whole (None without overlap).

    A partition's shares never overlap. Overlapping structures (ROIs) are
    painted largest first, so the smallest is on top; the count says how many
    voxels some structure lost in that one map. Each goes whole into the first
    layer where it overlaps nothing (3D Slicer's segmentation layers). Each
    structure's ``volume_mm3`` is set from its own voxels.
    """
    values = [r.structure.value for r in results] or [0]
    dtype = labels_dtype(values)
    labels = np.zeros(case.output_shape, dtype=dtype)
    voxel = float(abs(np.linalg.det(case.output_affine[:3, :3])))
    claimed = np.zeros(case.output_shape, dtype=bool)
    overlap = 0
    layers: list[NDArray[np.integer]] = []
    painted = [r for r in results if r.mesh is not None]
    painted.sort(key=lambda r: -_size(r))
    for item in painted:
        inside = _voxels(item, case.output_affine, case.output_shape)
        overlap += int(np.count_nonzero(inside & claimed))
        claimed |= inside
        labels[inside] = item.structure.value
        item.volume_mm3 = float(np.count_nonzero(inside)) * voxel
        free = next((layer for layer in layers if not layer[inside].any()), None)
        if free is None:
            free = np.zeros(case.output_shape, dtype=dtype)
            layers.append(free)
        free[inside] = item.structure.value
    return labels, overlap, np.stack(layers) if overlap else None


def _voxels(
    item: StructureResult, affine: NDArray[np.float64], shape: tuple[int, int, int]
) -> NDArray[np.bool_]:
    """A structure's voxels on a grid: its occupancy moved by whole voxels when it lies on
    the grid's lattice, else its mesh rasterized there."""

    occupancy = item.occupancy
    if occupancy is not None and np.allclose(occupancy.affine[:3, :3], affine[:3, :3]):
        offset = np.linalg.solve(affine[:3, :3], occupancy.affine[:3, 3] - affine[:3, 3])
        lo = np.rint(offset).astype(np.int64)
        if np.allclose(offset, lo, atol=1e-6):
            return place(occupancy.mask, -lo, shape)
    return mesh_to_mask(item.mesh, affine, shape)


def _size(item: StructureResult) -> float:
    if item.occupancy is not None:
        return float(np.count_nonzero(item.occupancy.mask)) * item.occupancy.voxel_volume
    return float(abs(item.mesh.volume)) if item.mesh is not None else 0.0


# ------------------------------------------------------------------------------- run
def run_case(
    input_path: str | os.PathLike[str] | Sequence[str | os.PathLike[str]],
    outdir: str | os.PathLike[str],
    config: ReconstructConfig,
    *,
    ground_truth: str | os.PathLike[str] | None = None,
    image_dir: str | os.PathLike[str] | None = None,
    progress: Progress | None = None,
) -> dict[str, Any]:
    """Reconstruct one case and write its outputs: the one pipeline of ``slicerecon run``.

    ``input_path`` is one input, or several sparse inputs of one study
    (:func:`slicerecon.combine.combine_cases`).

    Writes into ``outdir`` (:func:`slicerecon.case_outputs.write_case`, every
    file atomically): ``mesh.<format>`` for one structure or
    ``meshes/<value>_<name>.<format>`` for several, ``labels.nii.gz`` and
    ``labels.seg.nrrd`` on the input's grid (and ``seg.dcm`` / ``rtstruct.dcm``
    for DICOM inputs with their series), ``structures.json``, ``plan.json``,
    ``metrics.json`` (when a ground truth is known) and ``preview.png``.

    Returns
    -------
    dict
        The case summary: output paths, mean metrics (or None), structures,
        timings, part and plane counts, whether every written mesh is watertight.
    """

    def say(stage: str) -> None:
        if progress is not None:
            progress(stage)

    out = check_outdir(outdir)
    timings: dict[str, float] = {}
    say("read")
    start = time.perf_counter()
    case = load_case(input_path, config, ground_truth=ground_truth, image_dir=image_dir)
    timings["read"] = time.perf_counter() - start
    say("reconstruct")
    result = reconstruct_case(case, config, progress=say)
    timings.update(result.timings)
    metrics = None
    if case.has_truth:
        say("evaluate")
        start = time.perf_counter()
        metrics = score_case(case, result, config)
        timings["metrics"] = time.perf_counter() - start
    say("write")
    return write_case(
        out,
        case,
        result,
        metrics,
        config,
        ground_truth=ground_truth,
        image_dir=image_dir,
        timings=timings,
    )


def reconstruct_structures(
    source: str | os.PathLike[str] | Sequence[str | os.PathLike[str]] | LabelMap | Volume | Any,
    config: ReconstructConfig | None = None,
    *,
    score: bool = False,
    **changes: Any,
) -> CaseReconstruction:
    """Reconstruct every structure of an input: the Python entry point of ``slicerecon run``.

    Parameters
    ----------
    source : path-like, list of path-like, LabelMap, Volume, nibabel image or (array, affine)
        Any input ``slicerecon run`` reads (a label map file, a DICOM SEG or
        RTSTRUCT, a DICOM folder, a contour file; :func:`load_case`), several
        sparse inputs of one study (``run A B``), a
        :class:`~slicerecon.labels.LabelMap`, a
        :class:`~slicerecon.sections.Volume` (one structure), a nibabel image
        (its ``dataobj`` and ``affine``, RAS), or an integer array of shape
        (I, J, K) with its 4×4 voxel → world mm affine (RAS). 0 is
        background; every other value is one structure.
    config : ReconstructConfig, optional
        Plane choice, structures and reconstruction options (default: the defaults).
    score : bool
        Score each structure against its ground truth, as ``run`` does
        (:func:`score_case`; a dense input is its own, a sparse one has none):
        its :attr:`StructureResult.metrics` (volume IoU, Dice, surface IoU,
        Chamfer and HD95 in mm).
    **changes
        Fields of :class:`~slicerecon.reconstruct.ReconstructConfig` to change
        (``slices=12``, ``method="loft"``, ``label="2,5"`` ...).

    Returns
    -------
    CaseReconstruction
        Each structure's mesh (world mm), occupancy and status, the label map
        on the input's grid, and each structure's ground truth when the input
        was dense (:meth:`CaseReconstruction.truth_mask`).

    Raises
    ------
    InputError
        An unreadable file, an array that is not a 3-D integer label map.
    OptionError
        A bad option.
    """
    config = _config_of(config, changes)
    # a library user sees the warnings without setting up logging
    with collected_warnings() as said:
        case = _case_of(source, config)
        result = reconstruct_case(case, config)
        if score:
            score_case(case, result, config)
    result.warnings = list(said)
    return result


def _config_of(config: Any, changes: dict[str, Any]) -> ReconstructConfig:
    """The configuration :func:`reconstruct_structures` is given, or an OptionError."""
    if isinstance(config, ReconstructOptions) and not isinstance(config, ReconstructConfig):
        config = ReconstructConfig(**config.to_dict())  # the options bundle alone
    if config is not None and not isinstance(config, ReconstructConfig):
        raise OptionError(
            f"config must be a ReconstructConfig (got {type(config).__name__}); give "
            "options as keywords: reconstruct_structures(source, slices=12)"
        )
    known = {f.name for f in fields(ReconstructConfig)}
    unknown = sorted(set(changes) - known)
    if unknown:
        listed = ", ".join(sorted(known))
        raise OptionError(f"not an option: {', '.join(unknown)} (options: {listed})")
    return replace(config or ReconstructConfig(), **changes)


def _case_of(source: Any, config: ReconstructConfig) -> CaseInput:
    """The case of what :func:`reconstruct_structures` is given."""
    paths = isinstance(source, list | tuple) and all(
        isinstance(p, str | os.PathLike) for p in source
    )
    if isinstance(source, str | os.PathLike) or (paths and source):
        return load_case(source, config)  # one input, or several of one study
    chosen = config.union or bool(config.selectors)
    if config.pixel_spacing is not None:  # refused for a label map file too
        raise OptionError(
            "pixel_spacing applies to contours without a grid; a label map keeps its voxels"
        )
    if isinstance(source, Volume):
        source = (source.mask.astype(np.uint8), source.affine)
    elif hasattr(source, "dataobj") and hasattr(source, "affine"):  # a nibabel image
        data = np.asarray(source.dataobj)
        while data.ndim > 3 and data.shape[-1] == 1:  # (X, Y, Z, 1), as a file is read
            data = data[..., 0]
        source = (data, np.asarray(source.affine))
    if isinstance(source, LabelMap):
        check_label_values(source.labels, source="the label map", chosen=chosen)
        return case_from_label_map(source, config)
    if not isinstance(source, tuple | list) or len(source) != 2:
        raise InputError(
            "reconstruct_structures takes a path, several paths, a LabelMap, a Volume, a "
            f"nibabel image, or (array, affine) (got {type(source).__name__}"
            + (f" of {len(source)} items)" if isinstance(source, tuple | list) else ")")
        )
    array, affine = cast(tuple[Any, Any], source)
    check_label_values(np.asarray(array), source="the array", chosen=chosen)
    label_map = LabelMap.from_array(array, affine)
    return case_from_label_map(label_map, config)
