"""Several sparse inputs of one study as one annotation, in world mm.

An axial and a sagittal segmentation, a label map and an RTSTRUCT, contour
files: :func:`combine_cases` takes the cases :func:`slicerecon.case_inputs.load_case`
read from each, chooses the reference grid, matches their structures by name or
value, and gives every input's planes to one annotation (``slicerecon run A B``).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from .annotated_planes import (
    NESTED_SHARE,
    check_drawings_meet,
    covering_grid,
    merge_repeated_planes,
    warn_coinciding,
)
from .annotation import AnnotatedPlane, Annotation, PlanePose
from .case_input import CaseInput
from .errors import InputError, OptionError
from .io import DICOM_KINDS, frame_of_reference
from .io.contours import contour_file_frame
from .io.labelmap import LABEL_MAP_KINDS
from .io.limits import DEFAULT_MEMORY_BUDGET_GB, check_grid
from .io.outputs import dicom_image_series
from .labels import LPS_TO_RAS, Structure
from .parallel_inputs import warn_parallel_apart
from .sections import crop_affine
from .selection import name_key

__all__ = ["combine_cases"]

logger = logging.getLogger(__name__)


def combine_cases(
    cases: Sequence[CaseInput], *, memory_budget_gb: float = DEFAULT_MEMORY_BUDGET_GB
) -> CaseInput:
    """Several sparse inputs of one study as one annotation, in world mm.

    The **reference** input is the one with the most planes among those drawn
    on an image (a label map, or contours with their image series; contours
    without one when no input has an image); on a tie, the one with the
    smallest voxels, then by file name. The others are taken by file name, so
    the result is the same in any order. The reference's voxel lattice is the
    reference grid, extended to hold every input's drawn pixels, and the label
    map is written on its output grid, extended only where another input's
    drawing lies beyond it (unless DICOM outputs refer to its image series: then
    a warning says what lies beyond the series). The others' planes keep their
    poses in world mm (a plane that is not a slice of that grid is sampled
    through its projection). Structures are matched by name (case and spaces
    ignored), unnamed ones by value; two names of one value are two structures
    (the later takes the next free value, with a warning); one named in one input and unnamed in
    another is kept apart, with a warning; a structure new to the reference
    keeps its value, or takes the next free one. The structures form a
    partition only when every input is a label map (contours are ROIs, even
    one structure's). Otherwise a structure drawn by one input only, on another
    lattice than the reference's, keeps that input's grid
    (:attr:`Annotation.grids`): it is reconstructed as that input alone would
    reconstruct it, not on the reference's pixels. A structure drawn on one
    plane in two inputs is kept once when both drawings agree; drawn by two
    inputs in places that do not meet, it is warned about, or refused when they
    lie further apart than half its size (:func:`check_drawings_meet`). Two
    structures drawn by different inputs only that coincide where their planes
    cross (one structure valued 1 in one file and 2 in the other) are warned
    about (:func:`slicerecon.annotated_planes.warn_coinciding`).

    Raises
    ------
    OptionError
        A dense input among several (a dense mask is its own case), one
        structure drawn differently on one plane in two inputs, or drawn far
        apart by two inputs.
    MemoryBudgetError
        The grid holding every input exceeds ``memory_budget_gb``.
    """
    for case in cases:
        if case.dense:
            raise OptionError(
                f"{case.input_path} is a dense mask: several inputs combine sparse annotations "
                "of one study; reconstruct a dense mask on its own, or, if it is drawn on "
                "every slice it crosses, state the axis drawn on (--annotation z)"
            )
    _check_frames(cases)
    # the reference first, the others by file name: the same result in any order
    given = list(cases)
    cases = sorted(given, key=_reference_rank)
    cases = [cases[0], *sorted(cases[1:], key=lambda c: str(c.input_path))]
    first = cases[0]
    structures: list[Structure] = list(first.annotation.structures)
    origin = {s.value: first.input_path for s in structures}
    # each input's planes speak for that input's structures only
    own_first = frozenset(first.annotation.values)
    planes: list[AnnotatedPlane] = [
        AnnotatedPlane(p.pose, p.masks, own_first if p.structures is None else p.structures)
        for p in first.annotation.planes
    ]
    # which inputs draw each structure: one drawn by a single other input keeps that
    # input's grid (it is reconstructed as that input alone would reconstruct it)
    drawers: dict[int, set[int]] = {v: {0} for v in own_first}
    grids: dict[int, tuple[NDArray[np.float64], tuple[int, int, int]]] = {}
    gap_ends = set(first.annotation.gap_ends)
    for n, case in enumerate(cases[1:], start=1):
        earlier = list(structures)
        taken = {s.value for s in earlier} | set(case.annotation.values)
        remap: dict[int, int] = {}
        apart: dict[Path, list[str]] = {}
        for structure in case.annotation.structures:
            match = next(
                (
                    s
                    for s in earlier
                    if (structure.name and s.name and name_key(s.name) == name_key(structure.name))
                    or (not structure.name and not s.name and s.value == structure.value)
                ),
                None,
            )
            if match is None:
                clash = next((s for s in earlier if s.value == structure.value), None)
                value = structure.value
                if clash is not None and clash.name and structure.name:
                    # two names, one value: two structures; the later takes a free value
                    value = max(taken) + 1
                    taken.add(value)
                    logger.warning(
                        "structure %d is %r in %s and %r in %s: two structures; %r is "
                        "written as value %d",
                        structure.value,
                        clash.name,
                        origin[clash.value],
                        structure.name,
                        case.input_path,
                        structure.name,
                        value,
                    )
                elif clash is not None:  # one named, one not: kept apart, and said so
                    apart.setdefault(origin[clash.value], []).append(
                        f"{structure.value} ({clash.name or structure.name!r})"
                    )
                    value = max(taken) + 1
                    taken.add(value)
                match = replace(structure, value=value)
                structures.append(match)
                origin[value] = case.input_path
            remap[structure.value] = match.value
            drawers.setdefault(match.value, set()).add(n)
        for other, listed in apart.items():
            logger.warning(
                "%s and %s both hold structure(s) %s, named in one and not in the other: "
                "they are kept as separate structures; name them alike in both (or in "
                "neither) to combine them",
                other,
                case.input_path,
                ", ".join(listed),
            )
        # world mm of the first input's frame: LPS (DICOM, Slicer) and RAS (NIfTI) differ
        # by the sign of x and y
        flip = case.annotation.coordinates != first.annotation.coordinates
        if flip:
            _say_frame_taken(case, first)
        own_affine = LPS_TO_RAS @ case.annotation.affine if flip else case.annotation.affine
        for value in remap.values():
            grids[value] = (own_affine, case.annotation.grid_shape)
        gap_ends |= {remap[v] for v in case.annotation.gap_ends}
        for plane in case.annotation.planes:
            masks = {remap[v]: m for v, m in plane.masks.items()}
            own = (
                frozenset(remap.values())
                if plane.structures is None
                else frozenset(remap[v] for v in plane.structures)
            )
            pose = (
                PlanePose(LPS_TO_RAS @ plane.pose.affine, plane.pose.shape) if flip else plane.pose
            )
            planes.append(AnnotatedPlane(pose, masks, own))
    # contours are ROIs (they may nest) even when a file holds one structure
    exclusive = all(c.annotation.exclusive and c.kind.kind in LABEL_MAP_KINDS for c in cases)
    # a partition is resolved on one grid; elsewhere a structure drawn by one input only,
    # on another lattice than the reference's, keeps that input's grid
    if exclusive:
        _say_coarser(grids, drawers, cases, structures)
    own_grids = grids

    def kept(exclusive: bool) -> dict[int, tuple[NDArray[np.float64], tuple[int, int, int]]]:
        return {
            value: grid
            for value, grid in own_grids.items()
            if not exclusive
            and len(drawers[value]) == 1
            and not _same_lattice(grid[0], first.annotation.affine)
        }

    grids = kept(exclusive)
    origins = [str(c.input_path) for c in cases for _ in c.annotation.planes]
    labels = {s.value: s.label for s in structures}
    check_drawings_meet(planes, origins, labels)
    warn_parallel_apart(planes, origins, labels)
    drawer = [n for n, c in enumerate(cases) for _ in c.annotation.planes]
    warn_coinciding(planes, drawer, [str(c.input_path) for c in cases], labels)
    affine = first.annotation.affine
    lo, hi = covering_grid(planes, affine, first.annotation.grid_shape)
    size = (int(hi[0] - lo[0]), int(hi[1] - lo[1]), int(hi[2] - lo[2]))
    check_grid(size, what="the grid of the inputs together", memory_budget_gb=memory_budget_gb)
    moved = crop_affine(affine, lo)
    annotation = Annotation(
        tuple(planes),
        tuple(structures),
        moved,
        size,
        first.annotation.coordinates,
        exclusive,
        grids=grids,
        # a structure drawn by one contour file only ends as it would alone
        gap_ends=frozenset(v for v in gap_ends if len(drawers[v]) == 1),
    )
    annotation = merge_repeated_planes(annotation, origins, first.crop_lo + lo)
    nested = _drawn_inside(annotation) if exclusive else []
    if nested:
        # label maps are partitions one by one; together they may hold a lesion drawn inside
        # its organ (two SEGs): it was cut out of the organ without a word
        logger.warning(
            "%s drawn inside %s on a plane both inputs draw: the inputs together are "
            "structures that may overlap, each reconstructed whole",
            ", ".join(labels[inner] for inner, _ in nested[:4]),
            ", ".join(dict.fromkeys(labels[outer] for _, outer in nested[:4])),
        )
        annotation = replace(annotation, exclusive=False, grids=kept(False))
    names = ", ".join(str(c.input_path) for c in given)
    annotation = replace(
        annotation,
        source=f"{len(cases)} inputs ({names}), {len(structures)} structure(s): "
        f"{annotation.describe()}",
    )
    missing = tuple(s for c in cases for s in c.missing)
    # the written grid (the reference's, which may sample its annotation grid more finely:
    # contours without an image) grows only where a drawing lies beyond it, not by the
    # padding
    drawn_lo, drawn_hi = covering_grid(planes, first.output_affine, first.output_shape, pad=0)
    output_affine, output_shape, start = _output_holding(
        first, drawn_lo, drawn_hi, memory_budget_gb
    )
    # where the annotation grid's first voxel lies on the written grid
    crop_lo = np.rint(np.linalg.solve(output_affine[:3, :3], moved[:3, 3] - output_affine[:3, 3]))
    return replace(
        first,
        annotation=annotation,
        missing=missing,
        inputs=tuple(Path(c.input_path) for c in given),
        drawn_by={
            v: tuple(Path(cases[n].input_path) for n in sorted(d)) for v, d in drawers.items()
        },
        output_affine=output_affine,
        output_shape=output_shape,
        crop_lo=crop_lo.astype(np.int64),
    )


def _say_frame_taken(case: CaseInput, first: CaseInput) -> None:
    """One warning when a contour file states no frame and is turned into another input's
    (an LPS contour file beside an LPS .seg.nrrd came out mirrored, without a word)."""
    for one, other in ((case, first), (first, case)):
        if one.kind.kind == "contours" and contour_file_frame(one.kind.path) is None:
            logger.warning(
                '%s states no "coordinates": its points are read as RAS, and %s is in %s; '
                'if they are DICOM patient coordinates, add "coordinates": "LPS" to it',
                one.input_path,
                other.input_path,
                other.annotation.coordinates,
            )


def _check_frames(cases: Sequence[CaseInput]) -> None:
    """Refuse DICOM inputs of different frames of reference (their coordinates are of
    different spaces: combined, a sagittal SEG of another study was placed in this one's).

    Raises
    ------
    InputError
        Two DICOM inputs name different FrameOfReferenceUIDs.
    """
    frames = {
        case.input_path: frame_of_reference(Path(case.kind.path), rois=True)
        for case in cases
        if case.kind.kind in DICOM_KINDS
    }
    named = {path: uid for path, uid in frames.items() if uid}
    if len(set(named.values())) > 1:
        listed = "; ".join(f"{path}: {uid}" for path, uid in named.items())
        raise InputError(
            f"the inputs lie in different frames of reference ({listed}): their coordinates "
            "do not match; combine inputs of one study and frame (register them first)"
        )


def _drawn_inside(annotation: Annotation) -> list[tuple[int, int]]:
    """Structures (inner, outer) of which, on a plane, one's drawing lies at least
    :data:`~slicerecon.annotated_planes.NESTED_SHARE` inside the other's: what one
    partition cannot hold, and several inputs together may draw."""
    found: dict[tuple[int, int], None] = {}
    for plane in annotation.planes:
        drawn = {v: m for v, m in plane.masks.items() if m.any()}
        for inner, mask in drawn.items():
            count = int(np.count_nonzero(mask))
            for outer, other in drawn.items():
                if outer != inner and np.count_nonzero(mask & other) >= NESTED_SHARE * count:
                    found[(inner, outer)] = None
    return list(found)


def _say_coarser(
    grids: dict[int, tuple[NDArray[np.float64], tuple[int, int, int]]],
    drawers: dict[int, set[int]],
    cases: Sequence[CaseInput],
    structures: Sequence[Structure],
) -> None:
    """One warning per input whose own structures lose voxels: label maps' structures are
    resolved together on the reference's grid, even those drawn on finer voxels by
    another label map only (a coronal 0.6 mm map's structure on an axial 3 mm one)."""
    reference = cases[0].annotation.affine
    size = float(abs(np.linalg.det(reference[:3, :3])))
    by_input: dict[int, list[str]] = {}
    for s in structures:
        (n,) = drawers[s.value] if len(drawers[s.value]) == 1 else (0,)
        affine = grids.get(s.value, (reference,))[0]
        if n and float(abs(np.linalg.det(affine[:3, :3]))) < size * (1 - 1e-6):
            by_input.setdefault(n, []).append(s.label)
    for n, labels in by_input.items():
        case = cases[n]
        logger.warning(
            "structure(s) %s, drawn in %s only, are reconstructed on the %s mm voxels of %s, "
            "coarser than their own %s mm: the structures of label maps are resolved "
            "together on one grid; reconstruct %s alone for its own voxels",
            ", ".join(labels),
            case.input_path,
            _voxel(cases[0].annotation.affine),
            cases[0].input_path,
            _voxel(case.annotation.affine),
            case.input_path,
        )


def _voxel(affine: NDArray[np.float64]) -> str:
    """``0.6 x 1.2 x 0.6``: a grid's voxel size, mm."""
    return " x ".join(f"{v:.3g}" for v in np.linalg.norm(affine[:3, :3], axis=0))


def _same_lattice(affine: NDArray[np.float64], reference: NDArray[np.float64]) -> bool:
    """Whether a grid's voxel centres are voxel centres of the reference grid."""
    if not np.allclose(affine[:3, :3], reference[:3, :3], atol=1e-6):
        return False
    offset = np.linalg.solve(reference[:3, :3], affine[:3, 3] - reference[:3, 3])
    return bool(np.allclose(offset, np.rint(offset), atol=1e-4))


def _reference_rank(case: CaseInput) -> tuple[bool, int, float, str]:
    """Sorts the reference first: drawn on an image, most planes, smallest voxels, name."""
    voxel = float(abs(np.linalg.det(case.annotation.affine[:3, :3])))
    return (not _on_an_image(case), -len(case.annotation.planes), voxel, str(case.input_path))


def _on_an_image(case: CaseInput) -> bool:
    """Whether an input's grid is an image's (not one made for its contours)."""
    return case.kind.kind in LABEL_MAP_KINDS or _has_series(case)


def _has_series(case: CaseInput) -> bool:
    """Whether DICOM outputs of the input refer to an image series (its slices fix the grid)."""
    kind = case.kind
    return dicom_image_series(kind.kind, kind.path, kind.image_dir) is not None


def _output_holding(
    reference: CaseInput,
    drawn_lo: NDArray[np.int64],
    drawn_hi: NDArray[np.int64],
    memory_budget_gb: float,
) -> tuple[NDArray[np.float64], tuple[int, int, int], NDArray[np.int64]]:
    """The reference input's output grid grown to hold the voxels ``[drawn_lo, drawn_hi)``
    (indices on it): its affine, its shape, and where the old grid's first voxel moved
    (``start``; zeros when it did not grow).

    DICOM outputs refer to the slices of an image series, whose grid cannot grow: a
    warning then says that the label maps hold only the series' extent.
    """
    shape = np.asarray(reference.output_shape, dtype=np.int64)
    start = np.minimum(drawn_lo, 0)
    stop = np.maximum(shape, drawn_hi)
    if not np.any(start < 0) and not np.any(stop > shape):
        return reference.output_affine, reference.output_shape, start
    if _has_series(reference):
        logger.warning(
            "%s: the inputs' drawings reach beyond its image series: the label maps and DICOM "
            "outputs hold the series' extent only, the meshes everything",
            reference.input_path,
        )
        return reference.output_affine, reference.output_shape, np.zeros(3, dtype=np.int64)
    grown = (int(stop[0] - start[0]), int(stop[1] - start[1]), int(stop[2] - start[2]))
    check_grid(
        grown, what="the output grid of the inputs together", memory_budget_gb=memory_budget_gb
    )
    return crop_affine(reference.output_affine, start), grown, start
