"""Every structure of an input at once: shared planes, joint resolution, one label map.

:func:`reconstruct_structures` takes a :class:`~slicerecon.labels.LabelMap`
(several labels of a label map, or every segment of a SEG) and

1. chooses the planes **once**, over the extent of all the structures together
   (as an annotator marks planes of the scan: :func:`slicerecon.reconstruct.prepare_inputs`
   on their union);
2. reconstructs each structure from its own masks on those planes and its own
   silhouettes, with the default surface (:func:`slicerecon.reconstruct.reconstruct`,
   keeping each signed-distance field); a structure that no kept plane
   crosses is reported (a warning and a record), never silently dropped;
3. resolves them jointly (:func:`slicerecon.surface.joint.resolve`): every
   voxel goes to the structure it is most inside, so no voxel belongs to two
   structures and structures that touch still touch; each structure's mesh is
   made from its share and shares its interface with its neighbours.

The result is a label map on the input's grid and one watertight mesh per
structure. Metrics per structure compare each with its own mask.
"""

from __future__ import annotations

import logging
import os
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import trimesh
from numpy.typing import NDArray

from .errors import InputError, OptionError
from .io.limits import DEFAULT_MEMORY_BUDGET_GB
from .labels import LabelMap, Structure
from .sections import CrossSections, Volume

__all__ = [
    "StructureResult",
    "StructuresReconstruction",
    "reconstruct_sparse_structures",
    "reconstruct_structures",
    "run_structures_case",
]

logger = logging.getLogger(__name__)

NO_PLANE = "no kept plane crosses it"
"""Status of a structure the chosen planes miss."""
NOT_RECONSTRUCTED = "every voxel went to a neighbour"
NO_CONTOURS = "no closed planar contours"
"""Status of an RTSTRUCT ROI that holds no contour."""
"""Status of a structure whose reconstruction lost every voxel to other structures."""


@dataclass
class StructureResult:
    """One structure of a joint reconstruction.

    Attributes
    ----------
    structure : Structure
        Value, name and colour.
    status : str
        ``"reconstructed"``, or why it was not (:data:`NO_PLANE`, :data:`NOT_RECONSTRUCTED`).
    mesh : trimesh.Trimesh or None
        Its watertight surface (world mm) cut by its neighbours.
    planes : int
        Kept planes on which it has foreground.
    occupancy : Volume or None
        Its voxels in the joint label map (on the sections' grid).
    plan : Plan or None
        The partition its reconstruction used.
    """

    structure: Structure
    status: str
    mesh: trimesh.Trimesh | None = None
    planes: int = 0
    occupancy: Volume | None = None
    plan: Any = None

    @property
    def volume_mm3(self) -> float:
        """Volume of its share of the label map, mm³."""
        return 0.0 if self.occupancy is None else self.occupancy.volume_mm3

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
class StructuresReconstruction:
    """The result of :func:`reconstruct_structures`.

    Attributes
    ----------
    results : list of StructureResult
        One per structure, in the label map's order.
    labels : ndarray of shape (I, J, K)
        The reconstructed label map on the **input's** grid (its label values).
    sections : CrossSections
        The union's planes (on the cropped grid all structures share).
    truth : LabelMap or None
        The input, each structure's ground truth, when it was dense (else None).
    crop_lo : ndarray of shape (3,)
        Where the shared grid starts in the grid of :attr:`labels`.
    timings : dict of str to float
    affine : ndarray of shape (4, 4)
        Voxel index → world mm of :attr:`labels`.
    coordinates : {"RAS", "LPS"}
        The world frame of :attr:`affine`.
    """

    results: list[StructureResult]
    labels: NDArray[np.integer]
    sections: CrossSections
    truth: LabelMap | None
    crop_lo: NDArray[np.int64]
    timings: dict[str, float] = field(default_factory=dict)
    affine: NDArray[np.float64] | None = None
    coordinates: str = "RAS"

    def truth_mask(self, value: int) -> Volume:
        """A structure's own mask on the shared (cropped) grid (dense inputs only)."""
        if self.truth is None:
            raise OptionError("contour inputs have no ground truth")
        shape = self.sections.grid_shape
        region = tuple(slice(int(a), int(a) + n) for a, n in zip(self.crop_lo, shape, strict=True))
        return Volume(self.truth.labels[region] == value, self.sections.affine)


def reconstruct_structures(
    label_map: LabelMap,
    *,
    slices: int | None = None,
    every: int | None = None,
    axis: int | str = "z",
    planner: str = "heuristic",
    method: str = "sdf",
    interpolation: str = "pchip",
    carve: bool = True,
    cover: bool = True,
    join_drift: bool = True,
    max_parts: int = 8,
    weights: str | None = None,
    memory_budget_gb: float = DEFAULT_MEMORY_BUDGET_GB,
) -> StructuresReconstruction:
    """Reconstruct every structure of a label map from shared planes, jointly.

    Parameters
    ----------
    label_map : LabelMap
        The structures. Dense: planes are chosen over their union and each
        structure is its own ground truth (silhouettes from its mask). Sparse
        (annotated on some planes only, :func:`slicerecon.inputs.looks_sparse`):
        the annotated planes are the sections, silhouettes are derived from
        each structure's sections, and there is no ground truth.
    slices, every, axis
        Plane choice over the union of the structures
        (:func:`slicerecon.reconstruct.prepare_inputs`).
    planner, interpolation, carve, cover, join_drift, max_parts, weights
        As for :func:`slicerecon.reconstruct.reconstruct`, for every structure.
    method : {"sdf"}
        The joint resolution works on signed distances: ``sdf`` only.
    memory_budget_gb : float
        As for :func:`slicerecon.reconstruct.prepare_inputs`.

    Returns
    -------
    StructuresReconstruction

    Raises
    ------
    OptionError
        A method other than ``sdf``; plane options out of range.
    EmptyMaskError
        No structure holds a voxel.
    """
    from .inputs import prepare_inputs

    if method != "sdf":
        raise OptionError(
            f"several structures are resolved on their signed distances: use --method sdf "
            f"(got {method!r}), or choose one structure with --label, or --union"
        )
    timings: dict[str, float] = {}
    start = time.perf_counter()
    union = label_map.union()
    sections, _, cropped = prepare_inputs(
        union,
        slices=slices,
        every=every,
        axis=axis,
        projections="auto",
        memory_budget_gb=memory_budget_gb,
    )
    # A sparse union (the structures annotate only some planes) has no ground
    # truth: each structure's silhouettes are derived from its own sections.
    dense = cropped is not None
    crop_lo = np.rint(
        np.linalg.solve(label_map.affine[:3, :3], sections.affine[:3, 3] - label_map.affine[:3, 3])
    )
    crop_lo = crop_lo.astype(np.int64)
    region = tuple(
        slice(int(a), int(a) + n) for a, n in zip(crop_lo, sections.grid_shape, strict=True)
    )
    labels_crop = label_map.labels[region]
    plane_index = np.rint(sections.indices).astype(np.int64)
    timings["sections"] = time.perf_counter() - start

    items = []
    for structure in label_map.structures:
        mask = labels_crop == structure.value
        planes = np.moveaxis(mask, sections.axis, 0)[plane_index]
        own = None
        if planes.any():
            own = CrossSections(
                planes, sections.indices, sections.axis, sections.affine, sections.grid_shape
            )
        items.append((structure, own, mask if dense else None))
    results, joint = _reconstruct_jointly(
        items,
        sections,
        timings,
        planner=planner,
        method=method,
        interpolation=interpolation,
        carve=carve,
        cover=cover,
        join_drift=join_drift,
        max_parts=max_parts,
        weights=weights,
    )
    values = np.array([s.structure.value for s in results], dtype=np.int64)
    labels = np.zeros(label_map.shape, dtype=np.result_type(label_map.labels.dtype, np.uint8))
    won = joint.labels >= 0
    labels[region][won] = values[joint.labels[won]]
    return StructuresReconstruction(
        results,
        labels,
        sections,
        label_map if dense else None,
        crop_lo,
        timings,
        label_map.affine,
        label_map.coordinates,
    )


def reconstruct_sparse_structures(
    structures: list[Structure],
    sections: list[CrossSections | None],
    union: CrossSections,
    *,
    coordinates: str = "LPS",
    planner: str = "heuristic",
    method: str = "sdf",
    interpolation: str = "pchip",
    carve: bool = True,
    cover: bool = True,
    join_drift: bool = True,
    max_parts: int = 8,
    weights: str | None = None,
) -> StructuresReconstruction:
    """Reconstruct every ROI of an RTSTRUCT (or contour structures) on their shared grid.

    Parameters
    ----------
    structures : list of Structure
        One per ROI.
    sections : list of CrossSections or None
        Each ROI's planes on the grid of ``union`` (None: no contour).
    union : CrossSections
        All the ROIs' planes together (:func:`slicerecon.io.rtstruct.read_rtstruct_structures`).
    coordinates : {"RAS", "LPS"}
        The world frame of the grid (LPS for DICOM).
    planner, method, interpolation, carve, cover, join_drift, max_parts, weights
        As for :func:`reconstruct_structures`; each ROI's silhouettes are
        derived from its own sections.

    Returns
    -------
    StructuresReconstruction
        The label map on the shared (sections') grid; no ground truth.
    """

    if method != "sdf":
        raise OptionError(
            f"several structures are resolved on their signed distances: use --method sdf "
            f"(got {method!r}), or choose one ROI with --label"
        )
    timings: dict[str, float] = {}
    items = [(structure, own, None) for structure, own in zip(structures, sections, strict=True)]
    results, joint = _reconstruct_jointly(
        items,
        union,
        timings,
        planner=planner,
        method=method,
        interpolation=interpolation,
        carve=carve,
        cover=cover,
        join_drift=join_drift,
        max_parts=max_parts,
        weights=weights,
    )
    for item, own in zip(results, sections, strict=True):
        if own is None:
            item.status = NO_CONTOURS
    values = np.array([r.structure.value for r in results], dtype=np.int64)
    dtype = np.uint8 if values.max(initial=0) < 256 and values.min(initial=0) >= 0 else np.int32
    labels = np.zeros(union.grid_shape, dtype=dtype)
    won = joint.labels >= 0
    labels[won] = values[joint.labels[won]]
    return StructuresReconstruction(
        results, labels, union, None, np.zeros(3, np.int64), timings, union.affine, coordinates
    )


def _reconstruct_jointly(
    items: list[tuple[Structure, CrossSections | None, Any]],
    shared: CrossSections,
    timings: dict[str, float],
    **options: Any,
) -> tuple[list[StructureResult], Any]:
    """Reconstruct each ``(structure, sections, mask)`` keeping its field; resolve.

    All sections lie on the grid of ``shared`` (every structure's planes
    together), whose field sampling every structure uses. Each structure is
    reconstructed on its own crop of that grid (:func:`crop_to_structure`),
    as a run on that structure alone would, so ``N`` structures cost about
    the sum of ``N`` single runs. ``mask`` is the structure's dense mask on the
    shared grid (its silhouettes are taken from it), or None for contours
    (silhouettes derived from its sections).
    """
    from .inputs import axis_upsample
    from .reconstruct import reconstruct
    from .surface.joint import resolve

    upsample = axis_upsample(shared)
    results: list[StructureResult] = []
    fields = []
    for structure, own, mask in items:
        if own is None or not own.masks.any():
            logger.warning(
                "structure %s lies between the kept planes: not reconstructed", structure.label
            )
            results.append(StructureResult(structure, NO_PLANE))
            fields.append(None)
            continue
        crossed = int(np.count_nonzero(own.masks.any(axis=(1, 2))))
        start = time.perf_counter()
        sub, projections, offset = crop_to_structure(own, mask)
        result = reconstruct(sub, projections, keep_field=True, upsample=upsample, **options)
        timings["reconstruct"] = timings.get("reconstruct", 0.0) + time.perf_counter() - start
        results.append(
            StructureResult(structure, "reconstructed", planes=crossed, plan=result.plan)
        )
        field = result.field
        fields.append(
            field._replace(lo=tuple(int(a + b) for a, b in zip(field.lo, offset, strict=True)))
        )
    start = time.perf_counter()
    joint = resolve(fields, shared.grid_shape)
    for i, item in enumerate(results):
        if fields[i] is None:
            continue
        item.mesh = joint.meshes[i]
        inside = joint.labels == i
        if item.mesh is None or not inside.any():
            item.status, item.mesh = NOT_RECONSTRUCTED, None
            continue
        item.occupancy = Volume(inside, shared.affine)
    timings["resolve"] = time.perf_counter() - start
    logger.info(
        "%d structures: %d reconstructed", len(results), sum(r.mesh is not None for r in results)
    )
    return results, joint


CROP_PAD = 3
"""Voxels kept around a structure's extent when it is reconstructed on its own crop."""


def crop_to_structure(
    own: CrossSections, mask: NDArray[np.bool_] | None
) -> tuple[CrossSections, Any, NDArray[np.int64]]:
    """A structure's sections on the crop of the shared grid around it, its silhouettes,
    and where the crop starts on the shared grid."""
    from .sampling import projections_from_sections, projections_from_volume

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
    affine = own.affine.copy()
    affine[:3, 3] = own.affine[:3, :3] @ lo.astype(np.float64) + own.affine[:3, 3]
    sub = CrossSections(
        own.masks[keep][:, lo[a] : hi[a], lo[b] : hi[b]],
        own.indices[keep] - lo[axis],
        axis,
        affine,
        tuple(int(v) for v in hi - lo),
    )
    if mask is not None:
        crop = mask[lo[0] : hi[0], lo[1] : hi[1], lo[2] : hi[2]]
        projections = projections_from_volume(Volume(crop, affine))
    else:
        projections = projections_from_sections(sub)
    return sub, projections, lo


def _mean_metrics(per_structure: dict[str, dict[str, Any]]) -> dict[str, float]:
    """The mean of each numeric metric over the structures."""
    keys = [
        k
        for k, v in next(iter(per_structure.values())).items()
        if isinstance(v, int | float) and not isinstance(v, bool)
    ]
    return {k: float(np.mean([m[k] for m in per_structure.values()])) for k in keys}


def run_structures_case(
    source: LabelMap | tuple[list[Structure], list[CrossSections | None], CrossSections],
    input_path: Any,
    out: Any,
    config: Any,
    *,
    progress: Any = None,
    timings: dict[str, float] | None = None,
    coordinates: str = "LPS",
    image_dir: Any = None,
) -> dict[str, Any]:
    """Reconstruct every structure and write the case's outputs into ``out``.

    ``source`` is a dense :class:`LabelMap` (planes chosen over the union,
    metrics against each structure's mask) or the ROIs of an RTSTRUCT as
    ``(structures, sections, union)`` on their shared grid
    (:func:`slicerecon.io.rtstruct.read_rtstruct_structures`, no metrics).

    Writes ``meshes/<value>_<name>.<format>`` (one watertight mesh per
    reconstructed structure), ``labels.nii.gz`` (the label map on the input's
    grid with its label values, or on the sections' grid for contours),
    ``structures.json`` (every structure: value, name, colour, status, planes
    used, volume in mm³, mesh), ``metrics.json`` (per structure and their
    mean, dense inputs), ``plan.json`` and ``preview.png``; every file
    atomically. ``labels.seg.nrrd``, and for DICOM inputs with their image
    series (``image_dir``, or a DICOM mask series) ``seg.dcm`` and for RTSTRUCT
    inputs ``rtstruct.dcm``, come from :func:`slicerecon.io.outputs.write_label_outputs`.
    Called by :func:`slicerecon.reconstruct.run_case`.

    Returns
    -------
    dict
        The case summary (``metrics`` holds the mean over structures).
    """
    from pathlib import Path

    from .io import detect_kind
    from .io.atomic import write_json
    from .io.mesh import write_mesh
    from .io.outputs import dicom_image_series, write_label_outputs
    from .metrics import evaluate
    from .preview import write_preview
    from .rasterize import is_closed

    def say(stage: str) -> None:
        if progress is not None:
            progress(stage)

    outdir = Path(out)
    times = dict(timings or {})
    say("reconstruct")
    options = {
        "planner": config.planner,
        "method": config.method,
        "interpolation": config.interpolation,
        "carve": config.carve,
        "cover": config.cover,
        "join_drift": config.join_drift,
        "max_parts": config.max_parts,
        "weights": config.weights,
    }
    if isinstance(source, LabelMap):
        result = reconstruct_structures(
            source,
            slices=config.slices,
            every=config.every,
            axis=config.axis,
            memory_budget_gb=config.max_memory_gb,
            **options,
        )
    else:
        if config.slices is not None or config.every is not None:
            raise OptionError("--slices/--every apply to dense masks; contours are already sparse")
        result = reconstruct_sparse_structures(*source, coordinates=coordinates, **options)
    times.update(result.timings)
    say("evaluate")
    start = time.perf_counter()
    metrics: dict[str, dict[str, Any]] = {}
    for item in result.results:
        if item.mesh is None or result.truth is None:
            continue
        truth = result.truth_mask(item.structure.value)
        metrics[item.structure.label] = evaluate(
            item.mesh,
            truth,
            n_points=config.n_points,
            seed=config.seed,
            pred_occupancy=item.occupancy,
        ).to_dict()
    times["metrics"] = time.perf_counter() - start
    say("write")
    start = time.perf_counter()
    records = []
    for item in result.results:
        record = item.to_dict()
        if item.mesh is not None:
            path = write_mesh(
                item.mesh, outdir / "meshes" / f"{item.structure.label}.{config.mesh_format}"
            )
            record["mesh"] = f"meshes/{path.name}"
        records.append(record)
    kind = detect_kind(input_path)
    outputs = write_label_outputs(
        outdir,
        result.labels,
        result.affine,
        [item.structure for item in result.results],
        coordinates=result.coordinates,
        series=dicom_image_series(
            kind.kind, input_path, image_dir if image_dir is not None else kind.image_dir
        ),
        rtstruct=kind.path if kind.kind == "rtstruct" else None,
        allow_irregular=config.allow_irregular,
    )
    write_json(outdir / "structures.json", {"structures": records, "outputs": outputs.to_dict()})
    mean = _mean_metrics(metrics) if metrics else None
    if metrics:
        write_json(outdir / "metrics.json", {"structures": metrics, "mean": mean})
    sections = result.sections
    write_json(
        outdir / "plan.json",
        {
            "structures": [
                {
                    **item.structure.to_dict(),
                    "plan": None
                    if item.plan is None
                    else item.plan.to_dict(affine=sections.affine),
                }
                for item in result.results
            ],
            "sections": {
                "axis": "xyz"[sections.axis],
                "n_planes": sections.n_planes,
                "plane_indices": sections.indices.tolist(),
                "positions_mm": sections.positions.tolist(),
            },
            "input": str(input_path),
            "config": _config_dict(config),
            "timings_s": {k: round(v, 4) for k, v in times.items()},
        },
    )
    meshes = [item.mesh for item in result.results if item.mesh is not None]
    union = Volume(result.labels != 0, result.affine)
    write_preview(
        outdir / "preview.png",
        mesh=trimesh.util.concatenate(meshes),
        boxes=[],
        planner=f"{config.planner}, {len(meshes)} structures",
        sections=sections,
        projections=_union_projections(result),
        occupancy=_crop(union, result),
        truth=None if result.truth is None else Volume(_truth_union(result), sections.affine),
    )
    times["write"] = time.perf_counter() - start
    return {
        "input": str(input_path),
        "mesh": str(outdir / "meshes"),
        "parts": sum(0 if r.plan is None else len(r.plan.parts) for r in result.results),
        "planes": sections.n_planes,
        "watertight": all(is_closed(m) for m in meshes),
        "metrics": mean,
        "structures": records,
        "timings_s": {k: round(v, 4) for k, v in times.items()},
    }


def _config_dict(config: Any) -> dict[str, Any]:
    from dataclasses import asdict

    return asdict(config)


def _truth_union(result: StructuresReconstruction) -> NDArray[np.bool_]:
    shape = result.sections.grid_shape
    region = tuple(slice(int(a), int(a) + n) for a, n in zip(result.crop_lo, shape, strict=True))
    return result.truth.labels[region] != 0


def _crop(volume: Volume, result: StructuresReconstruction) -> Volume:
    shape = result.sections.grid_shape
    region = tuple(slice(int(a), int(a) + n) for a, n in zip(result.crop_lo, shape, strict=True))
    return Volume(volume.mask[region], result.sections.affine)


def _union_projections(result: StructuresReconstruction) -> Any:
    from .sampling import projections_from_sections, projections_from_volume

    if result.truth is None:
        return projections_from_sections(result.sections)
    return projections_from_volume(Volume(_truth_union(result), result.sections.affine))


def _mesh_value(path: Path) -> int | None:
    """The label value a ``meshes/`` file is named for (``<value>_<name>.<fmt>``)."""
    head = path.name.split(".")[0].split("_")[0]
    return int(head) if head.isdigit() else None


def evaluate_structures(
    prediction: str | os.PathLike[str],
    ground_truth: str | os.PathLike[str],
    *,
    n_points: int = 50_000,
    seed: int = 0,
    memory_budget_gb: float = DEFAULT_MEMORY_BUDGET_GB,
) -> dict[str, Any] | None:
    """Score every structure of a label-map ground truth against its own prediction.

    Parameters
    ----------
    prediction : path-like
        A label map with the ground truth's label values (NIfTI, NRRD, VTI,
        DICOM; e.g. a run's ``labels.nii.gz``), or a run's output directory
        holding ``meshes/``, or that ``meshes/`` directory itself
        (``<value>_<name>.<fmt>`` files: each mesh is scored as the exact
        surface of structure ``<value>``).
    ground_truth : path-like
        A dense label map.
    n_points, seed
        As for :func:`slicerecon.metrics.evaluate`.
    memory_budget_gb : float
        As for :func:`slicerecon.io.load_input`.

    Returns
    -------
    dict or None
        None when the ground truth holds fewer than two structures (score it
        as one shape). Otherwise ``{"structures": {"<value>_<name>": metrics},
        "mean": {...}, "missing": [...]}`` as in a run's ``metrics.json``:
        ``missing`` lists the ground-truth structures the prediction does not
        hold (left out of the mean).

    Raises
    ------
    InputError
        A prediction that is a single mesh (it cannot say which structure it
        is: give ``--label``), or a directory without meshes.
    """
    from .io import detect_kind, load_ground_truth
    from .io.labelmap import LABEL_MAP_KINDS, read_label_map
    from .metrics import evaluate

    kind = detect_kind(ground_truth).kind
    if kind not in LABEL_MAP_KINDS:
        return None
    truth = read_label_map(ground_truth, memory_budget_gb=memory_budget_gb)
    if len(truth.structures) < 2:
        return None
    pred_path = Path(prediction)
    meshes: dict[int, Path] = {}
    pred_map: LabelMap | None = None
    if pred_path.is_dir():
        folder = pred_path / "meshes" if (pred_path / "meshes").is_dir() else pred_path
        for file in sorted(folder.iterdir()):
            value = _mesh_value(file)
            if value is not None and file.suffix.lower() in (".stl", ".ply", ".obj", ".off"):
                meshes[value] = file
        if not meshes:
            raise InputError(
                f"{pred_path} holds no <value>_<name> meshes (a run's meshes/ directory) to "
                "score each structure of the ground truth"
            )
    elif detect_kind(pred_path).kind == "mesh":
        raise InputError(
            f"the ground truth {ground_truth} holds {len(truth.structures)} structures and "
            f"{pred_path.name} is one mesh: give --label to score it against one, or pass a "
            "label map or a meshes/ directory"
        )
    else:
        pred_map = read_label_map(pred_path, memory_budget_gb=memory_budget_gb)
    scored: dict[str, dict[str, Any]] = {}
    missing: list[str] = []
    for structure in truth.structures:
        target = truth.mask(structure.value)
        if pred_map is not None:
            found = [s for s in pred_map.structures if s.value == structure.value]
            pred = pred_map.mask(structure.value) if found else None
        else:
            path = meshes.get(structure.value)
            pred = None if path is None else load_ground_truth(path)
        if pred is None:
            missing.append(structure.label)
            continue
        scored[structure.label] = evaluate(pred, target, n_points=n_points, seed=seed).to_dict()
    if not scored:
        raise InputError(
            f"{pred_path} holds none of the {len(truth.structures)} structures of {ground_truth}"
        )
    return {"structures": scored, "mean": _mean_metrics(scored), "missing": missing}
