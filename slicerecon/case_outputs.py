"""What a case leaves on disk: one schema whatever the number of structures.

:func:`write_case` writes a reconstructed case into its folder (every file
atomically; the layout is :mod:`slicerecon.results`'s):

``mesh.<format>`` or ``meshes/<value>_<name>.<format>``
    One watertight mesh per reconstructed structure, world mm: ``mesh.<format>``
    when the case has one structure, ``meshes/`` when it has several.
``labels.nii.gz``, ``labels.seg.nrrd`` (and ``seg.dcm``, ``rtstruct.dcm``)
    The label map on the input's grid (:func:`slicerecon.io.outputs.write_label_outputs`).
``structures.json``
    Every structure: value, name, colour, status, planes, volume (mm³), parts,
    and its mesh's path relative to the case folder; how the input was read;
    the world frame of the meshes (``coordinates``: RAS, or LPS for DICOM).
``plan.json``
    Each structure's plan (cuboid parts and cuts), all parts together under
    ``parts``, the planes, the configuration, the timings.
``metrics.json`` (when a ground truth is known)
    The case's metrics at the top level (the mean over the structures: the
    structure's own for one), each structure's under ``structures``, and the
    mean again under ``mean``.
``preview.png``
    What the reconstruction was made from and what it made.
"""

from __future__ import annotations

import logging
import os
import shutil
import tempfile
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from .annotation import AnnotatedPlane, Annotation, window
from .errors import OptionError
from .io.atomic import write_json
from .io.mesh import mesh_file_closed, write_mesh
from .io.outputs import LABEL_OUTPUT_FILES, dicom_image_series, write_label_outputs
from .preview import PreviewStructure, display_colour, write_preview
from .reconstruct import ReconstructConfig
from .results import (
    MESH_SUFFIXES,
    MESHES_DIR,
    METRICS_FILE,
    PLAN_FILE,
    PREVIEW_FILE,
    STRUCTURES_FILE,
    mesh_file,
)
from .sections import AXIS_NAMES

if TYPE_CHECKING:
    from .case import CaseInput, CaseReconstruction

__all__ = ["check_outdir", "write_case"]

logger = logging.getLogger(__name__)


def check_outdir(outdir: str | os.PathLike[str]) -> Path:
    """Make sure a case's output folder can be written, before any work; create nothing.

    Parameters
    ----------
    outdir : path-like
        The folder (it and its missing parents are created when the case is written).

    Returns
    -------
    Path

    Raises
    ------
    OptionError
        The path, or one of its parents, is a file; or the folder (or its
        nearest existing parent, where it would be created) cannot be written.
    """
    out = Path(outdir)
    if out.exists() and not out.is_dir():
        raise OptionError(f"the output folder {out} is a file; give -o a folder")
    existing = out
    while not existing.exists():
        if existing.parent == existing:
            break
        existing = existing.parent
    if existing.exists() and not existing.is_dir():
        raise OptionError(f"cannot create the output folder {out}: {existing} is a file")
    try:  # a real write: permission bits alone do not tell (root, read-only mounts)
        with tempfile.NamedTemporaryFile(dir=existing, prefix=".slicerecon-write-check-"):
            pass
    except OSError as exc:
        reason = exc.strerror or type(exc).__name__
        raise OptionError(f"cannot write the output folder {out} ({existing}: {reason})") from None
    return out


def _plan_record(case: CaseInput, result: CaseReconstruction) -> dict[str, Any]:
    """``plan.json`` without the configuration and timings."""
    annotation = case.annotation
    items = [r for r in result.results if r.structure in annotation.structures]
    one = items[0] if len(items) == 1 and items[0].plan is not None else None
    sections = one.sections if one is not None and one.sections is not None else result.sections
    parts: list[dict[str, Any]] = []
    structures = []
    for item in result.results:
        plan = None
        if item.plan is not None:
            affine = annotation.affine if item.sections is None else item.sections.affine
            plan = item.plan.to_dict(affine=affine)
            parts += [{**p, "structure": item.structure.value} for p in plan["parts"]]
        structures.append({**item.structure.to_dict(), "plan": plan})
    views = [
        {"normal": [round(float(c), 6) for c in normal], "n_planes": len(members)}
        for normal, members in annotation.orientations()
    ]
    planes: dict[str, Any] = {"n_planes": len(annotation.planes), "views": views}
    if sections is not None and len(views) == 1 and sections.n_planes == len(annotation.planes):
        planes.update(
            axis="xyz"[sections.axis],
            n_planes=sections.n_planes,
            plane_indices=sections.indices.tolist(),
            positions_mm=sections.positions.tolist(),
        )
    grid = one.plan.grid_shape if one is not None else annotation.grid_shape
    record: dict[str, Any] = {
        "planner": one.plan.planner if one is not None else case_planner(result),
        "grid_shape": list(grid),
        "parts": parts,
        "structures": structures,
        "sections": planes,
        "annotation": annotation.source,
    }
    if one is not None and one.projections is not None:
        record["projections"] = one.projections.source
    return record


def case_planner(result: CaseReconstruction) -> str:
    """The planner that made the case's plans (the first structure's; ``none`` for a
    reconstruction from views, which is one part)."""
    return next((r.plan.planner for r in result.results if r.plan is not None), "none")


def write_case(
    outdir: Path,
    case: CaseInput,
    result: CaseReconstruction,
    metrics: dict[str, Any] | None,
    config: ReconstructConfig,
    *,
    ground_truth: str | os.PathLike[str] | None = None,
    image_dir: str | os.PathLike[str] | None = None,
    timings: dict[str, float] | None = None,
) -> dict[str, Any]:
    """Write a reconstructed case into ``outdir``, one schema for any number of structures.

    Parameters
    ----------
    outdir : Path
        The case folder (:func:`check_outdir` made sure it is writable).
    case : CaseInput
    result : CaseReconstruction
    metrics : dict or None
        :func:`slicerecon.case.score_case`'s record.
    config : ReconstructConfig
    ground_truth, image_dir : path-like, optional
        As given to :func:`slicerecon.case.run_case` (recorded; ``image_dir``
        is the DICOM series DICOM outputs refer to).
    timings : dict of str to float, optional
        Seconds per stage so far; ``write`` is added.

    Returns
    -------
    dict
        The case summary (what ``slicerecon run`` prints).

    Every file is written into a hidden staging folder inside ``outdir`` first
    and moved into place only when all are written: a run interrupted or
    failing while it writes leaves an earlier run's outputs as they were, never
    a mix of the two (the staging folder is removed).
    """
    outdir.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=".slicerecon-writing-", dir=outdir))
    try:
        summary, files = _write_case_files(
            staging, outdir, case, result, metrics, config, ground_truth, image_dir, timings
        )
        earlier_run = (outdir / PLAN_FILE).is_file()  # a folder slicerecon wrote before
        moved = _commit(staging, outdir, files)
        if earlier_run:
            inputs = [case.input_path, case.kind.path, *case.inputs]
            _remove_stale(outdir, moved + [Path(p) for p in inputs])
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return summary


def _commit(staging: Path, outdir: Path, files: list[Path]) -> list[Path]:
    """Move the staged ``files`` into ``outdir`` (same relative paths); their new paths."""
    moved = []
    for path in files:
        target = outdir / path.relative_to(staging)
        target.parent.mkdir(parents=True, exist_ok=True)
        os.replace(path, target)
        moved.append(target)
    return moved


def _write_case_files(
    outdir: Path,
    final: Path,
    case: CaseInput,
    result: CaseReconstruction,
    metrics: dict[str, Any] | None,
    config: ReconstructConfig,
    ground_truth: str | os.PathLike[str] | None,
    image_dir: str | os.PathLike[str] | None,
    timings: dict[str, float] | None,
) -> tuple[dict[str, Any], list[Path]]:
    """Every output of a case written into ``outdir`` (the staging folder), and the
    summary naming them as they will lie in ``final``."""

    import time

    times = dict(timings or {})
    start = time.perf_counter()
    several = len(case.annotation.structures) > 1
    records = []
    written: list[Path] = []
    for item in result.results:
        record = item.to_dict()
        if item.mesh is not None:
            name = mesh_file(item.structure.label, config.mesh_format, several=several)
            write_mesh(item.mesh, outdir / name, coordinates=result.coordinates)
            record["mesh"] = name
            written.append(outdir / name)
        if item.metrics is not None:
            record["metrics"] = item.metrics
        records.append(record)
    kind = case.kind
    outputs = write_label_outputs(
        outdir,
        result.labels,
        result.affine,
        [item.structure for item in result.results],
        coordinates=result.coordinates,
        series=dicom_image_series(
            kind.kind, kind.path, image_dir if image_dir is not None else kind.image_dir
        ),
        rtstruct=kind.path if kind.kind == "rtstruct" else None,
        seg=kind.path if kind.kind == "dicom-seg" else None,
        allow_irregular=config.allow_irregular,
        source=kind.path if kind.kind == "nifti" else None,
        layers=result.layers,
    )
    overlap = None
    if result.overlap_voxels:
        # ROIs that nest (BODY > organ > GTV) are ordinary input: said with the summary,
        # not as a warning (one on every structure set taught users to skip warnings)
        whole = ["the meshes", "labels.seg.nrrd (in layers)"]
        whole += [f"{name}.dcm" for name in ("seg", "rtstruct") if name in outputs.written]
        overlap = (
            f"structures overlap on {result.overlap_voxels} voxels; labels.nii.gz holds one "
            f"structure per voxel (the smallest on top); {', '.join(whole)} keep each whole"
        )
        logger.info("%s: %s", case.named, overlap)
    write_json(
        outdir / STRUCTURES_FILE,
        {
            "structures": records,
            "annotation": case.annotation.source,
            "coordinates": result.coordinates,
            "overlap": {
                "exclusive": result.exclusive,
                "voxels": result.overlap_voxels,
                "rule": "a partition: no voxel in two structures"
                if result.exclusive
                else "structures may overlap; labels.nii.gz holds the smallest on top, "
                "labels.seg.nrrd holds each whole in layers",
            },
            "outputs": outputs.to_dict(),
        },
    )
    mean = None if metrics is None else metrics["mean"]
    if metrics is not None:
        write_json(outdir / METRICS_FILE, {**metrics["mean"], **metrics})
    _write_preview(outdir / PREVIEW_FILE, case, result, config)
    times["write"] = time.perf_counter() - start
    plan = _plan_record(case, result)
    plan["input"] = str(case.input_path)
    plan["inputs"] = [str(p) for p in case.inputs or (case.input_path,)]
    plan["ground_truth"] = None if ground_truth is None else str(ground_truth)
    # the configuration as it ran: ``auto`` resolved to the planner the input chose
    plan["config"] = {**config.to_dict(), "planner": config.resolved_planner(sparse=not case.dense)}
    if not case.dense:  # the planes were drawn: options that choose a dense mask's were not used
        plan["config"].update(dict.fromkeys(("slices", "every", "axis")))
    plan["timings_s"] = {k: round(v, 4) for k, v in times.items()}
    write_json(outdir / PLAN_FILE, plan)
    files = [*written, outdir / STRUCTURES_FILE, outdir / PREVIEW_FILE, outdir / PLAN_FILE]
    files += [Path(p) for p in outputs.written.values()]
    if metrics is not None:
        files.append(outdir / METRICS_FILE)
    mesh_path = (
        final / mesh_file(result.results[0].structure.label, config.mesh_format, several=False)
        if not several
        else final / "meshes"
    )
    summary = {
        "input": str(case.input_path),
        "mesh": str(mesh_path),
        "parts": len(plan["parts"]),
        "planes": plan["sections"]["n_planes"],
        "watertight": bool(written) and all([mesh_file_closed(p) for p in written]),
        "metrics": mean,
        "missing": [] if metrics is None else metrics.get("missing", []),
        "structures": records,
        "annotation": case.annotation.source,
        "overlap": overlap,
        "timings_s": plan["timings_s"],
    }
    return summary, files


def _remove_stale(outdir: Path, written: list[Path]) -> None:
    """Remove what an earlier run left in a case folder that this run did not write.

    Only for a folder that held an earlier run's ``plan.json``, and only the
    names a case writes (``plan.json``, ``metrics.json``, meshes, label maps,
    DICOM outputs, ...), never a file in ``written`` (this run's, and its
    inputs); any other file stays. Said in one line: a results folder never
    mixes two runs.
    """
    keep = {p.resolve() for p in written}
    names = [PLAN_FILE, METRICS_FILE, PREVIEW_FILE, STRUCTURES_FILE, *LABEL_OUTPUT_FILES]
    names += [mesh_file("", suffix.lstrip("."), several=False) for suffix in MESH_SUFFIXES]
    found = [outdir / name for name in names]
    meshes = outdir / MESHES_DIR
    if meshes.is_dir():
        found += [p for p in meshes.iterdir() if p.suffix.lower() in MESH_SUFFIXES]
    stale = [p for p in found if p.is_file() and p.resolve() not in keep]
    for path in stale:
        path.unlink()
    if meshes.is_dir() and not any(meshes.iterdir()):
        meshes.rmdir()
    if stale:
        logger.warning(
            "%s held outputs of an earlier run that this run does not write; removed: %s",
            outdir,
            ", ".join(str(p.relative_to(outdir)) for p in stale),
        )


def _planes_in_words(annotation: Annotation) -> str:
    """``12 planes along z`` or ``16 planes in 3 orientations``, for the preview's title."""
    n = len(annotation.planes)
    axis = annotation.grid_axis()
    if axis is not None:
        return f"{n} plane{'s' * (n != 1)} along {AXIS_NAMES[axis]}"
    return f"{n} planes in {len(annotation.orientations())} orientations"


def _on_annotation_grid(result: CaseReconstruction, annotation: Annotation) -> NDArray[Any]:
    """The written label map on the annotation's grid: its window there (it may reach past
    the written grid), or, written more finely along an axis (contours on a grid of their
    own), the voxels whose centres are the annotation's."""
    labels = result.labels
    inverse = np.linalg.inv(result.affine) @ annotation.affine
    steps = np.diag(inverse[:3, :3])
    if np.allclose(steps, 1.0) or not np.allclose(inverse[:3, :3], np.diag(steps), atol=1e-6):
        lo = np.asarray(result.crop_lo)
        return window(labels, lo, lo + annotation.grid_shape)
    out = np.zeros(annotation.grid_shape, dtype=labels.dtype)
    index = [
        np.rint(steps[a] * np.arange(n) + inverse[a, 3]).astype(np.int64)
        for a, n in enumerate(annotation.grid_shape)
    ]
    valid = [(i >= 0) & (i < labels.shape[a]) for a, i in enumerate(index)]
    out[np.ix_(*valid)] = labels[np.ix_(*(i[v] for i, v in zip(index, valid, strict=True)))]
    return out


def _write_preview(
    path: Path, case: CaseInput, result: CaseReconstruction, config: ReconstructConfig
) -> None:
    """The preview (:mod:`slicerecon.preview`): the result in 3-D beside the annotated planes."""
    sections = result.sections
    annotation = case.annotation
    planes: list[AnnotatedPlane] = []
    if sections is not None:
        axis = sections.axis
        order = np.argsort(annotation.plane_indices(axis), kind="stable")
        planes = [
            plane
            for plane in (annotation.planes[int(n)] for n in order)
            if annotation.axis_of(plane.pose) == axis
            and annotation.grid_shift(plane.pose, axis) is not None
        ]
        if len(planes) != sections.n_planes:
            planes = []
    items = result.results
    structures = []
    for index, item in enumerate(items):
        colour = display_colour(item.structure, index, len(items))
        annotated = (
            np.stack([annotation.grid_mask(p, item.structure.value, sections.axis) for p in planes])
            if planes
            else None
        )
        structure = item.structure
        structures.append(
            PreviewStructure(structure.value, structure.label, colour, item.mesh, annotated)
        )
    one = items[0] if len(items) == 1 and items[0].plan is not None else None
    n_parts = sum(len(r.plan.boxes) for r in items if r.plan is not None)
    drawn = sum(r.mesh is not None for r in items)
    title = (
        f"{case.input_path.name}: {drawn} of {len(items)} structure(s) reconstructed from "
        f"{_planes_in_words(annotation)}; {config.method}, "
        f"planner {case_planner(result)}, {n_parts} part(s)"
    )
    write_preview(
        path,
        structures=structures,
        sections=sections,
        result=_on_annotation_grid(result, annotation),
        title=title,
        frame=result.coordinates,
        boxes=one.plan.boxes if one is not None else (),
        box_affine=one.sections.affine if one is not None and one.sections is not None else None,
    )
