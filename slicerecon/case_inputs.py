"""Reading a case: any input becomes the annotation its structures are reconstructed from.

:func:`load_case` is the first stage of the one case pipeline
(:mod:`slicerecon.case`): a dense label map (NIfTI, NRRD, VTI, DICOM mask
series, SEG; a mesh, voxelised) is cropped to all its structures together and
its planes are chosen **once** over their union (``--slices`` / ``--every``,
:func:`slicerecon.inputs.prepare_inputs`); it is then each structure's ground
truth. A sparse label map keeps the planes it annotates. An RTSTRUCT gives each
ROI on its own contour planes, a contour file one structure. How the input was
read is stated in one line (:attr:`slicerecon.annotation.Annotation.source`).
"""

from __future__ import annotations

import functools
import logging
import os
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .annotated_planes import nested_apart, planes_of_each_structure
from .annotation import (
    AnnotatedPlane,
    Annotation,
    annotation_from_sections,
    plane_pose,
)
from .case_input import CaseInput
from .combine import _same_lattice, combine_cases
from .errors import EmptyMaskError, OptionError
from .inputs import axis_upsample, prepare_inputs, refuse_plane_options
from .io import InputKind, detect_kind, load_ground_truth, load_input
from .io.contours import contour_file_grid, read_contour_annotation
from .io.dicom import dicom_series_geometry
from .io.labelmap import LABEL_MAP_KINDS, read_label_map, read_seg_masks
from .io.limits import DEFAULT_MEMORY_BUDGET_GB, check_grid
from .io.nrrd import nrrd_info, read_nrrd_masks
from .io.rtstruct import read_rtstruct_annotation
from .labels import LabelMap, Structure, StructureMasks, labels_dtype
from .plane_detection import (
    MIN_GAPS_WARNED,
    PlaneReading,
    empty_runs_inside,
    mixed_reading,
    parse_annotation,
    refuse_sparse_truth,
    structures_reading,
)
from .reconstruct import ReconstructConfig
from .sections import AXIS_NAMES, CrossSections, Volume, axis_index

__all__ = ["CaseInput", "case_from_label_map", "combine_cases", "load_case", "reading_of"]

logger = logging.getLogger(__name__)


def _as_label_map(volume: Volume, structure: Structure | None = None) -> LabelMap:
    s = structure or Structure(1)
    return LabelMap(volume.mask.astype(labels_dtype([s.value])) * s.value, volume.affine, (s,))


def load_case(
    input_path: str | os.PathLike[str] | Sequence[str | os.PathLike[str]],
    config: ReconstructConfig,
    *,
    ground_truth: str | os.PathLike[str] | None = None,
    image_dir: str | os.PathLike[str] | None = None,
) -> CaseInput:
    """Read an input (or several of one study) into the annotation a case reconstructs from.

    Parameters
    ----------
    input_path : path-like or sequence of path-like
        Any input :func:`slicerecon.io.detect_kind` knows; or several sparse
        inputs of one study (an axial and a sagittal annotation, a label map
        and an RTSTRUCT), combined in world mm (:func:`combine_cases`).
    config : ReconstructConfig
        Plane choice (``slices``, ``every``, ``axis``), structures (``label``,
        ``roi``, ``union``), the memory budget, ``allow_irregular``.
    ground_truth : path-like, optional
        A separate ground truth: a closed mesh or mask for a one-structure
        case, or a label map holding the structures' values.
    image_dir : path-like, optional
        The image series of an RTSTRUCT.

    Returns
    -------
    CaseInput

    Raises
    ------
    InputError
        What the readers raise; ``--union`` on an RTSTRUCT; plane options on
        a sparse input.
    """
    if not isinstance(input_path, str | os.PathLike):
        kinds = _once(list(input_path))
        paths = list(kinds)
        if len(paths) == 1:
            return load_case(paths[0], config, ground_truth=ground_truth, image_dir=image_dir)
        drawn = [kind.kind in CONTOUR_KINDS for kind in kinds.values()]
        if all(drawn):
            _refuse_annotation(config, " ".join(map(str, paths)))
        # --annotation states how the label maps among them are read
        cases = [
            load_case(
                path, replace(config, annotation="auto") if d else config, image_dir=image_dir
            )
            for path, d in zip(paths, drawn, strict=True)
        ]
        case = combine_cases(cases, memory_budget_gb=config.max_memory_gb)
        if ground_truth is not None:
            case = _with_ground_truth(case, ground_truth, config)
        logger.info("%s", case.annotation.source)
        return case
    kind = detect_kind(input_path)
    if image_dir is not None and kind.kind not in ("rtstruct", "dicom-seg"):
        raise OptionError(
            f"an image series applies to RTSTRUCT and SEG inputs only; {input_path} is a "
            f"{kind.kind} input"
        )
    if kind.kind in CONTOUR_KINDS:
        _refuse_annotation(config, kind.path)
    if kind.kind == "rtstruct":
        case = _load_rtstruct(kind, config, image_dir)
    elif kind.kind == "contours":
        case = _load_contours(kind, config)
    else:
        series = image_dir if image_dir is not None else kind.image_dir
        if kind.kind == "dicom-seg" and series is not None:
            grid = dicom_series_geometry(series, allow_irregular=config.allow_irregular)[:2]
            case = _on_series(_load_label_map(kind, config, onto=grid), Path(series), grid)
        else:
            case = _load_label_map(kind, config)
    if ground_truth is not None:
        case = _with_ground_truth(case, ground_truth, config)
    logger.info("%s: %s", kind.path, case.annotation.source)
    return case


def _once(paths: list[Any]) -> dict[Any, InputKind]:
    """The inputs, each file once, with their kinds: one given twice (or its folder beside
    it) is read once, said in one warning line (its planes were merged with themselves,
    without a word)."""
    seen: dict[Path, tuple[Any, InputKind]] = {}
    for path in paths:
        kind = detect_kind(path)
        key = Path(kind.path).resolve()
        if key in seen:
            logger.warning("%s and %s are one input (%s): it is read once", seen[key][0], path, key)
            continue
        seen[key] = (path, kind)
    return dict(seen.values())


def _say_stated(
    stated: PlaneReading, rule: PlaneReading, affine: NDArray[np.float64], text: str, path: Path
) -> None:
    """One warning line when ``--annotation`` reads a label map otherwise than the rule would
    (a map drawn on axial slices read along y gives slivers, and was said nowhere)."""
    if stated.dense == rule.dense and (stated.dense or stated.axes == rule.axes):
        return

    def said(reading: PlaneReading) -> str:
        how = reading.describe(affine=affine)  # "sparse annotation (...): 8 planes along z"
        return "a dense mask" if reading.dense else how.split(": ", 1)[-1]

    logger.warning(
        "%s: read as --annotation %s states, %s; by its own rule it reads %s",
        path,
        text,
        said(stated),
        said(rule),
    )


CONTOUR_KINDS = ("rtstruct", "contours")
"""Inputs of drawn polygons: every polygon's plane is an annotated plane."""


def _refuse_annotation(config: ReconstructConfig, what: object) -> None:
    """``--annotation`` stated for contours only: it tells how a label map is read.

    Raises
    ------
    OptionError
        ``config.annotation`` is not ``"auto"``.
    """
    if parse_annotation(config.annotation) != "auto":
        raise OptionError(
            f"--annotation applies to label maps; {what} holds contours, read as drawn (each "
            "polygon's plane is an annotated plane): leave --annotation out"
        )


def _load_label_map(
    kind: InputKind,
    config: ReconstructConfig,
    *,
    onto: tuple[NDArray[np.float64], tuple[int, int, int]] | None = None,
) -> CaseInput:
    """A label map file (or a mesh, voxelised), read whole; a SEG put on the slices of
    its series' grid ``onto`` when it is given (:func:`_on_slices_of`)."""

    def on(label_map: Any) -> Any:
        return label_map if onto is None else _on_slices_of(label_map, onto)

    if config.pixel_spacing is not None:
        raise OptionError(
            "--pixel-spacing applies to contours without a grid (contour files, an RTSTRUCT "
            f"without its image series); {kind.path} is a {kind.kind} input and keeps its voxels"
        )
    selectors = config.selectors
    if kind.kind not in LABEL_MAP_KINDS:  # a mesh, voxelised
        volume = load_input(
            kind.path, label=_one_label(config), memory_budget_gb=config.max_memory_gb
        )
        assert isinstance(volume, Volume)
        return case_from_label_map(_as_label_map(volume), config, kind=kind)
    if kind.kind == "dicom-seg" and selectors and not config.union:
        # chosen segments kept whole (SEG segments may overlap, and the label map of every
        # segment gives overlapping voxels to one of them), read beside every other
        # segment: a segment drawn on each slice beside others drawn on some is sparse
        masks = read_seg_masks(kind.path, memory_budget_gb=config.max_memory_gb)
        return case_from_label_map(on(masks), config, kind=kind)
    # SEG segments, and segments in different layers of a .seg.nrrd, may overlap or
    # nest: kept whole, each reconstructed on its own
    may_overlap = not config.union and (kind.kind == "dicom-seg" or _layered_nrrd(kind))
    if may_overlap:
        if kind.kind == "dicom-seg":
            masks = read_seg_masks(kind.path, memory_budget_gb=config.max_memory_gb)
        else:
            masks = read_nrrd_masks(kind.path, memory_budget_gb=config.max_memory_gb)
        if masks.overlap_voxels:
            logger.info(
                "%s: segments overlap on %d voxels; each is reconstructed whole",
                kind.path,
                masks.overlap_voxels,
            )
            return case_from_label_map(on(masks), config, kind=kind)
    label_map = read_label_map(
        kind.path,
        allow_irregular=config.allow_irregular,
        memory_budget_gb=config.max_memory_gb,
        chosen=bool(selectors) or config.union,
    )
    assert label_map is not None
    return case_from_label_map(on(label_map), config, kind=kind, may_overlap=may_overlap)


def _on_series(
    case: CaseInput, series: Path, grid: tuple[NDArray[np.float64], tuple[int, int, int]]
) -> CaseInput:
    """A SEG's case written on the grid of the image series it was drawn on.

    The SEG's grid spans its frames only (put on the series' slices by
    :func:`_on_slices_of`); its label maps and DICOM outputs go on the series'
    grid, which holds it voxel for voxel. A series it does not fit (other
    pixels, frames off or beyond its slices) is left aside with a warning: the
    outputs then keep the SEG's grid, without DICOM outputs.
    """
    affine, shape = grid
    own = case.output_affine
    offset = np.linalg.solve(affine[:3, :3], own[:3, 3] - affine[:3, 3])
    start = np.rint(offset).astype(np.int64)
    fits = (
        np.allclose(own[:3, :3], affine[:3, :3], atol=1e-3)
        and np.allclose(offset, start, atol=1e-2)
        and bool(np.all(start >= 0))
        and bool(np.all(start + np.asarray(case.output_shape) <= np.asarray(shape)))
    )
    if not fits:
        logger.warning(
            "%s: its frames are not slices of the image series %s (other pixels, or off or "
            "beyond its slices): the outputs keep the SEG's grid, and no DICOM output refers "
            "to the series",
            case.input_path,
            series,
        )
        return replace(case, kind=replace(case.kind, image_dir=None))
    return replace(
        case,
        kind=replace(case.kind, image_dir=series),
        output_affine=affine,
        output_shape=(int(shape[0]), int(shape[1]), int(shape[2])),
        crop_lo=case.crop_lo + start,
    )


def _on_slices_of(
    label_map: LabelMap | StructureMasks, grid: tuple[NDArray[np.float64], tuple[int, int, int]]
) -> LabelMap | StructureMasks:
    """A SEG read on the step of its frames put on the slices of its series when the
    frames lie on every ``m``-th of them (a SEG without SpacingBetweenSlices, drawn on
    every 2nd slice): the slices between are empty, so the annotation is read as one."""
    affine, _ = grid
    own = label_map.affine
    axis = 2
    ratio = np.linalg.norm(own[:3, axis]) / np.linalg.norm(affine[:3, axis])
    m = int(round(ratio))
    offset = np.linalg.solve(affine[:3, :3], own[:3, 3] - affine[:3, 3])
    if (
        m < 2
        or abs(ratio - m) > 1e-3 * m
        or not np.allclose(own[:3, :2], affine[:3, :2], atol=1e-3)
        or not np.allclose(own[:3, axis], m * affine[:3, axis], atol=1e-3 * m)
        or not np.allclose(offset, np.rint(offset), atol=1e-2)
    ):
        return label_map
    moved = own.copy()
    moved[:3, axis] = affine[:3, axis]

    def spread(array: NDArray[Any]) -> NDArray[Any]:
        out = np.zeros((*array.shape[:2], (array.shape[2] - 1) * m + 1), dtype=array.dtype)
        out[:, :, ::m] = array
        return out

    if isinstance(label_map, LabelMap):
        return replace(label_map, labels=spread(label_map.labels), affine=moved)
    return replace(label_map, masks=tuple(spread(mask) for mask in label_map.masks), affine=moved)


def _layered_nrrd(kind: InputKind) -> bool:
    """Whether a NRRD is a Slicer segmentation of several layers (headers only)."""
    if kind.kind != "nrrd":
        return False
    info = nrrd_info(kind.path)
    return bool(info.is_segmentation and info.layers > 1)


def case_from_label_map(
    label_map: LabelMap | StructureMasks,
    config: ReconstructConfig,
    *,
    kind: InputKind | None = None,
    may_overlap: bool = False,
) -> CaseInput:
    """The case of a label map: planes chosen over all its structures when it is dense.

    Parameters
    ----------
    label_map : LabelMap or StructureMasks
        Every structure on the input's grid: a partition (label map), or
        structures that may overlap (SEG segments), reconstructed independently.
    config : ReconstructConfig
        ``slices`` / ``every`` / ``axis`` choose the planes of a dense label
        map; ``label`` / ``union`` choose the structures.
    kind : InputKind, optional
        The file it was read from (default: an array in memory).
    may_overlap : bool
        A partition read from segments that may overlap (SEG, .seg.nrrd layers):
        segments drawn inside others on planes of their own
        (:func:`~slicerecon.annotated_planes.nested_apart`) make it overlapping.

    Returns
    -------
    CaseInput
        A dense label map is its own ground truth; a sparse one (annotated on
        some planes of one or several axes, by the rule of
        :func:`slicerecon.plane_detection.detect_planes` or as ``annotation``
        states) keeps its planes.
    """
    kind = kind if kind is not None else InputKind("array", Path("<array>"))
    # read over every structure of the input, before any is chosen: a lesion drawn on
    # each slice beside organs drawn on every 4th is an annotation also when the lesion
    # alone is asked for (alone it looks dense, and was scored against itself)
    whole = label_map.union()
    if whole.is_empty:
        raise EmptyMaskError(f"{kind.path} holds no foreground")
    whole_box = whole.crop(pad=3)
    reading, every_slice = _read_structures(label_map, whole_box, config, kind.path)
    if config.union:
        if every_slice:
            raise OptionError(
                f"--union merges structures drawn on every slice they cross "
                f"({_named(label_map, every_slice)}) with structures drawn on some: their "
                "union is drawn on neither; choose structures with --label"
            )
        label_map = replace(_as_label_map(label_map.union()), coordinates=label_map.coordinates)
    elif config.selectors:
        label_map = label_map.select(config.selectors, source=kind.path)
    union = label_map.union()
    if union.is_empty:
        raise EmptyMaskError(f"{kind.path} holds no foreground for the chosen structures")
    crop = union.crop(pad=3)
    check_grid(crop.shape, what="the reconstruction grid", memory_budget_gb=config.max_memory_gb)
    if config.union or config.selectors:
        reading = reading.within(_index_of(whole_box.affine, crop.affine), crop.shape)
        every_slice &= frozenset(s.value for s in label_map.structures)
    if not reading.dense:
        _check_sparse_options(reading, config, crop.spacing)
    elif not reading.stated:
        _warn_of_gaps(crop.mask, kind.path)
    stated = "dense" if reading.dense else reading.axes
    if not every_slice and (reading.dense or len(reading.axes) == 1):
        sections, _, cropped = prepare_inputs(
            union,
            slices=config.slices if reading.dense else None,
            every=config.every if reading.dense else None,
            axis=config.axis if reading.dense else "z",
            projections="auto",
            memory_budget_gb=config.max_memory_gb,
            annotation=stated if reading.dense else tuple(reading.axes),
        )
        grid_affine, grid_shape = sections.affine, sections.grid_shape
    else:
        sections, cropped = None, None
        grid_affine, grid_shape = crop.affine, crop.shape
    crop_lo = _index_of(label_map.affine, grid_affine)
    region = tuple(slice(int(a), int(a) + n) for a, n in zip(crop_lo, grid_shape, strict=True))
    exclusive = isinstance(label_map, LabelMap)
    on_planes = _plane_masks(label_map, region)
    if sections is not None:
        planes = np.rint(sections.indices).astype(np.int64)
        drawn = [on_planes(sections.axis, int(index)) for index in planes]
        own = [
            CrossSections(
                np.stack([plane[s.value] for plane in drawn]),
                sections.indices,
                sections.axis,
                sections.affine,
                sections.grid_shape,
            )
            for s in label_map.structures
        ]
        annotation = annotation_from_sections(
            label_map.structures,
            own,
            shared=True,
            coordinates=label_map.coordinates,
            exclusive=exclusive,
        )
    else:
        annotation = _views_annotation(
            label_map, on_planes, grid_affine, grid_shape, reading.planes, exclusive, every_slice
        )
    dense = cropped is not None
    if not dense and may_overlap and exclusive and nested_apart(annotation):
        annotation = replace(annotation, exclusive=False)  # each reconstructed whole
    if not dense:
        annotation = planes_of_each_structure(annotation, kind.path)
    how = "dense mask" if dense else reading.describe(affine=crop.affine)
    if every_slice:
        how += f"; structure(s) {_named(label_map, every_slice)} drawn on every slice they cross"
    annotation = replace(
        annotation,
        source=f"{how}; {len(label_map.structures)} structure(s): {annotation.describe()}",
    )
    dense_labels: LabelMap | StructureMasks | None = None
    if dense and isinstance(label_map, LabelMap):
        dense_labels = LabelMap(
            label_map.labels[region], grid_affine, label_map.structures, label_map.coordinates
        )
    elif dense:
        dense_labels = label_map.crop(region, grid_affine)
    return CaseInput(
        annotation,
        dense_labels,
        kind.path,
        kind,
        label_map.affine,
        label_map.shape,
        crop_lo,
    )


def _read_structures(
    label_map: LabelMap | StructureMasks, crop: Volume, config: ReconstructConfig, source: Path
) -> tuple[PlaneReading, frozenset[int]]:
    """How every structure of a label map is read on ``crop`` (their union's box), by
    :func:`~slicerecon.plane_detection.structures_reading`; one warning line when
    ``--annotation`` states another reading than the rule's."""
    first = _index_of(label_map.affine, crop.affine)
    box = tuple(slice(int(a), int(a) + n) for a, n in zip(first, crop.shape, strict=True))
    values = [s.value for s in label_map.structures]

    # one structure's mask at a time: 25 structures of a 500 x 470 x 136 map held
    # together took 0.8 GB
    def mask_of(value: int) -> NDArray[np.bool_]:
        return label_map.mask(value).mask[box]

    # read one by one at most once, for the stated reading and the rule's
    mixed = functools.cache(lambda: mixed_reading(values, mask_of))
    stated = parse_annotation(config.annotation)
    reading, every_slice = structures_reading(values, mask_of, crop.mask, stated, mixed=mixed)
    if reading.stated:
        rule, _ = structures_reading(values, mask_of, crop.mask, mixed=mixed)
        _say_stated(reading, rule, crop.affine, config.annotation, source)
    return reading, every_slice


def _index_of(affine: NDArray[np.float64], origin: NDArray[np.float64]) -> NDArray[np.int64]:
    """The voxel index, on the grid of ``affine``, of the first voxel of a grid of the same
    spacing whose affine is ``origin``."""
    return np.rint(np.linalg.solve(affine[:3, :3], origin[:3, 3] - affine[:3, 3])).astype(np.int64)


def _named(label_map: LabelMap | StructureMasks, values: frozenset[int]) -> str:
    return ", ".join(s.label for s in label_map.structures if s.value in values)


def _warn_of_gaps(mask: NDArray[np.bool_], source: Any) -> None:
    """Say when a mask read as dense has runs of empty slices inside it along an axis."""
    for axis, runs in empty_runs_inside(mask).items():
        if runs >= MIN_GAPS_WARNED:
            logger.warning(
                "%s: read as a dense mask, but %d runs of empty slices lie inside it along %s: "
                "if it is drawn on groups of slices, pass --annotation %s",
                source,
                runs,
                AXIS_NAMES[axis],
                AXIS_NAMES[axis],
            )


def _check_sparse_options(
    reading: PlaneReading, config: ReconstructConfig, spacing: NDArray[np.float64]
) -> None:
    """Refuse the options that choose planes of a dense mask when the input is annotated.

    Raises
    ------
    OptionError
        ``--slices`` or ``--every`` given, or ``--axis`` naming another axis than the
        annotation's one.
    """
    given = [
        name
        for name, used in (
            ("--slices", config.slices is not None),
            ("--every", config.every is not None),
            ("--axis", config.axis != "z" and reading.axes != (axis_index(config.axis),)),
        )
        if used
    ]
    if given and config.dense_only:
        logger.info("%s left out: this input is already sparse", "/".join(given))
        return
    refuse_plane_options(
        config.slices, config.every, f"this input is already sparse ({reading.describe(spacing)})"
    )
    if given:  # --axis
        raise OptionError(
            f"--axis applies to dense masks; this input is already sparse "
            f"({reading.describe(spacing)}): to read it along {config.axis} only, pass "
            f"--annotation {config.axis}"
        )


def _plane_masks(
    label_map: LabelMap | StructureMasks, region: tuple[slice, ...]
) -> Callable[[int, int], dict[int, NDArray[np.bool_]]]:
    """``masks(axis, index)``: every structure's mask on one slice of ``region`` of a label
    map, ndarray of shape (the slice's), bool, by value; one slice at a time (every
    structure's mask of a 500 x 470 x 136 map held at once took 0.8 GB)."""
    if isinstance(label_map, LabelMap):
        labels = label_map.labels[region]
        values = [s.value for s in label_map.structures]

        # a view of the slice: np.take copied the whole region per call on a view
        # (0.16 s a plane, 6.7 s of 23 on 20 structures of a 512 x 512 x 200 map)
        def of_labels(axis: int, index: int) -> dict[int, NDArray[np.bool_]]:
            plane = np.moveaxis(labels, axis, 0)[index]
            return {v: plane == v for v in values}

        return of_labels
    masks = {s.value: m[region] for s, m in zip(label_map.structures, label_map.masks, strict=True)}

    def of_masks(axis: int, index: int) -> dict[int, NDArray[np.bool_]]:
        return {v: np.moveaxis(m, axis, 0)[index].copy() for v, m in masks.items()}

    return of_masks


def _views_annotation(
    label_map: LabelMap | StructureMasks,
    on_planes: Callable[[int, int], dict[int, NDArray[np.bool_]]],
    affine: NDArray[np.float64],
    shape: tuple[int, int, int],
    planes: dict[int, NDArray[np.int64]],
    exclusive: bool,
    every_slice: frozenset[int] = frozenset(),
) -> Annotation:
    """A label map annotated along several axes: each annotated slice, every structure.

    With ``every_slice`` (structures drawn on every slice,
    :func:`~slicerecon.plane_detection.mixed_reading`), a slice that holds only those
    speaks for them alone: the others were not drawn there.
    """
    drawn = []
    for axis in sorted(planes):
        for index in planes[axis]:
            masks = on_planes(axis, int(index))
            held = frozenset(v for v, m in masks.items() if m.any())
            speaks = every_slice if every_slice and held <= every_slice else None
            pose = plane_pose(affine, shape, axis, float(index))
            drawn.append(AnnotatedPlane(pose, masks, speaks))
    return Annotation(
        tuple(drawn),
        label_map.structures,
        affine,
        shape,
        label_map.coordinates,
        exclusive=exclusive,
    )


def _load_rtstruct(
    kind: InputKind, config: ReconstructConfig, image_dir: str | os.PathLike[str] | None
) -> CaseInput:
    """Every chosen ROI of an RTSTRUCT on its own contour planes, of any orientation."""
    if config.union:
        raise OptionError("--union applies to label maps; choose RTSTRUCT ROIs with --label")
    refuse_plane_options(config.slices, config.every, "contours are already sparse")
    annotation, missing = read_rtstruct_annotation(
        kind.path,
        rois=config.selectors,
        allow_irregular=config.allow_irregular,
        image_dir=image_dir if image_dir is not None else kind.image_dir,
        pixel_spacing=config.pixel_spacing,
        memory_budget_gb=config.max_memory_gb,
    )
    # the reader has said which ROIs have no (closed planar) contour, and why
    series = image_dir if image_dir is not None else kind.image_dir
    case = _contour_input(annotation, kind, config, missing, built=series is None, series=series)
    if series is not None:
        affine, shape, _ = dicom_series_geometry(series, allow_irregular=config.allow_irregular)
        if not _same_lattice(case.output_affine, affine):
            # contours off the series' slices keep their positions; the label maps and
            # DICOM outputs are still written on the series' grid, from the surface
            case = replace(
                case,
                output_affine=affine,
                output_shape=(int(shape[0]), int(shape[1]), int(shape[2])),
                crop_lo=np.zeros(3, dtype=np.int64),
            )
    return case


def _load_contours(kind: InputKind, config: ReconstructConfig) -> CaseInput:
    """A contour file (JSON of either version, or CSV): its structures on their planes."""
    if config.union:
        raise OptionError(
            "--union applies to label maps; choose a contour file's structures with --label"
        )
    refuse_plane_options(config.slices, config.every, "contours are already sparse")
    annotation = read_contour_annotation(
        kind.path, pixel_spacing=config.pixel_spacing, memory_budget_gb=config.max_memory_gb
    )
    if config.selectors:
        annotation = annotation.select(config.selectors, source=kind.path)
    built = config.pixel_spacing is not None or contour_file_grid(kind.path) is None
    return _contour_input(annotation, kind, config, (), built=built)


def _contour_input(
    annotation: Annotation,
    kind: InputKind,
    config: ReconstructConfig,
    missing: tuple[Structure, ...],
    *,
    built: bool = False,
    series: str | os.PathLike[str] | None = None,
) -> CaseInput:
    """The case input of contours read as ``annotation``, its sampled grid inside the budget.

    Contours on parallel planes are reconstructed on a grid sampled along the
    plane normal as finely as in plane (:func:`_upsampled`): that grid, not only
    the rasterized planes, must fit ``--max-memory``. On a grid built on the
    contours (``built``: no image's grid), the label maps are written on that
    sampling too (they hold the surface between the planes, not only the drawn
    slices), and each structure ends half its own plane spacing beyond its end
    planes (:attr:`~slicerecon.annotation.Annotation.gap_ends`)."""
    first = annotation.grid_axis()
    output_affine, output_shape = annotation.affine, annotation.grid_shape
    if first is not None:
        sampled = _upsampled(annotation, first)
        check_grid(
            sampled,
            what=f"{kind.path}: the reconstruction grid",
            memory_budget_gb=config.max_memory_gb,
        )
        factor = sampled[first] // annotation.grid_shape[first]
        if built and factor > 1:
            output_affine = annotation.affine.copy()
            column = annotation.affine[:3, first]
            output_affine[:3, first] = column / factor
            output_affine[:3, 3] = annotation.affine[:3, 3] - column * (factor - 1) / (2 * factor)
            output_shape = (int(sampled[0]), int(sampled[1]), int(sampled[2]))
    annotation = replace(
        annotation,
        source=f"contours{f' on the images in {series}' if series else ''}, "
        f"{len(annotation.structures)} structure(s): {annotation.describe()}"
        f"{annotation.describe_fewer()}",
        gap_ends=annotation.gap_ends | frozenset(annotation.values if built else ()),
    )
    return CaseInput(
        annotation,
        None,
        kind.path,
        kind,
        output_affine,
        output_shape,
        np.zeros(3, np.int64),
        missing=missing,
    )


def _upsampled(annotation: Annotation, axis: int) -> list[int]:
    """The grid's shape sampled along ``axis`` as the signed-distance surface samples it."""
    shape = list(annotation.grid_shape)
    shape[axis] *= axis_upsample(annotation.cross_sections(axis=axis))
    return shape


def _one_label(config: ReconstructConfig) -> int | str | None:
    """The structure ``--label`` names for an input of one (several as one text, which the
    reader refuses naming them)."""
    chosen = config.selectors
    if len(chosen) == 1:
        return chosen[0]
    return ",".join(map(str, chosen)) or None


def _with_ground_truth(
    case: CaseInput, ground_truth: str | os.PathLike[str], config: ReconstructConfig
) -> CaseInput:
    """The case scored against a separate ground truth (``--gt``)."""
    structures = case.annotation.structures
    if len(structures) == 1:
        truth = load_ground_truth(
            ground_truth,
            label=_one_label(config),
            union=config.union,
            allow_irregular=config.allow_irregular,
            memory_budget_gb=config.max_memory_gb,
            frame=case.annotation.coordinates,  # a NIfTI truth of a DICOM input: LPS
            truth=True,
        )
        return replace(case, truth=truth)
    if detect_kind(ground_truth).kind not in LABEL_MAP_KINDS:
        raise OptionError(
            f"the input holds {len(structures)} structures and {ground_truth} is one shape: "
            "give a label map with their values as --gt, or choose one structure with --label"
        )
    truth_map = read_label_map(
        ground_truth,
        allow_irregular=config.allow_irregular,
        memory_budget_gb=config.max_memory_gb,
    )
    assert truth_map is not None
    refuse_sparse_truth(truth_map.labels, truth_map.affine, str(ground_truth))
    return replace(case, truth=truth_map.in_frame(case.annotation.coordinates))


def reading_of(
    path: str | os.PathLike[str],
    *,
    annotation: str = "auto",
    allow_irregular: bool = False,
    memory_budget_gb: float | None = None,
) -> str | None:
    """How ``slicerecon run`` reads a label map, in one line (None for other inputs).

    The line ``run`` prints (:func:`load_case`): ``dense mask; 3 structure(s): ...``
    or ``sparse annotation (detected): 12 planes along z (spacing 5 mm), 2 planes
    along x ...; 1 structure(s): ...``, by the rule of
    :func:`slicerecon.plane_detection.detect_planes` or as ``annotation`` states
    it, a SEG on its image series' slices when the series lies beside it.

    Raises
    ------
    SlicereconError
        What :func:`load_case` raises: the input cannot be read as ``run`` reads it.
    """
    kind = detect_kind(path)
    if kind.kind not in LABEL_MAP_KINDS:
        return None
    config = ReconstructConfig(
        annotation=annotation,
        allow_irregular=allow_irregular,
        max_memory_gb=DEFAULT_MEMORY_BUDGET_GB if memory_budget_gb is None else memory_budget_gb,
    )
    # read as run reads it: overlapping segments whole, a SEG on its series' slices,
    # structures drawn on every slice beside sparse ones
    return load_case(path, config).annotation.source
