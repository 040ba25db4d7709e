"""Which structures each annotated plane speaks for, across structures and inputs.

A label map's annotated plane says that every structure it does not hold is
absent there; an RTSTRUCT's contour plane speaks only for its ROI. When
structures or inputs are drawn on planes of their own, these rules decide
which planes bound which structure (:func:`planes_of_each_structure`), and how
several inputs of one study become one annotation on one grid
(:func:`covering_grid`, :func:`merge_repeated_planes`).
"""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from .annotation import AnnotatedPlane, Annotation, PlanePose, plane_pose, smallest_gap
from .crossings import crossing_points, drawn_at
from .errors import OptionError
from .sections import AXIS_NAMES

__all__ = [
    "COMBINED_PAD",
    "NESTED_SHARE",
    "check_drawings_meet",
    "covering_grid",
    "drawn_box",
    "merge_repeated_planes",
    "nested_apart",
    "planes_of_each_structure",
    "warn_coinciding",
]

logger = logging.getLogger(__name__)

_EPS_MM = 1e-3
"""Planes closer than this (mm) are one plane."""
COMBINED_PAD = 3
"""Voxels kept around every input's drawn pixels on the grid of several inputs."""


def planes_of_each_structure(annotation: Annotation, source: Any) -> Annotation:
    """Which planes of a sparse label map speak for which structure.

    A label map's annotated plane says every structure it does not hold is
    absent there, when the structures were drawn on the same planes; a
    structure missing from planes inside its extent that speak for it is read
    as absent there, with a warning. A plane speaks for fewer structures when
    the structures were drawn in groups on slices of their own and the groups'
    planes interleave (each plane then speaks for its own group: two
    annotators, a lesion drawn on one slice only), with one line saying so;
    when it was added between two regular planes (it speaks for what it holds:
    :func:`_extra_planes`); and, for structures that may overlap, where a
    structure drawn inside another is drawn without it (it says nothing of
    the other there: :func:`_nested_in`).

    Parameters
    ----------
    annotation : Annotation
        Planes that annotate every structure (``structures`` None).
    source : path or str
        The input, for the messages.

    Returns
    -------
    Annotation
        The same planes, each annotating the structures it speaks for.
    """
    values = annotation.values
    if len(values) < 2:
        return annotation
    planes = annotation.planes
    holding = [frozenset(p.masks) for p in planes]
    # structures that may overlap: one drawn inside another (GTV in its organ) on every
    # plane holding both, drawn on a plane without it, says nothing of that other there
    outer = {} if annotation.exclusive else _nested_in(planes, holding)
    silent = [
        frozenset(x for y in held for x in outer.get(y, ()) if x not in held) for held in holding
    ]
    own = {v: [n for n, h in enumerate(holding) if v in h] for v in values}
    # structures drawn together (on a common plane, directly or through others) form a
    # group; a plane speaks for its own group's structures when groups interleave
    groups = _drawn_together(values, holding)
    group = {v: g for g in groups for v in g}

    extra = _extra_planes(planes)
    # structures that may overlap (segments in layers of their own): a plane holding
    # others only speaks for a structure when it lies on the lattice of that structure's
    # own planes (a lesion drawn on every 2nd slice says nothing of the organs drawn on
    # every 4th, in another layer, on the slices between theirs)
    off_lattice = set() if annotation.exclusive else _off_lattice(planes, holding, own)

    def speaks_for(n: int, value: int) -> bool:
        held = holding[n]
        if not planes[n].annotates(value) or value in silent[n] or (n, value) in off_lattice:
            return False
        if n in extra and value not in held:
            return False  # a slice added between two regular ones: for what it holds
        return not held or not interleaved or value in group[next(iter(held))]

    def inside(value: int) -> list[int]:
        # planes inside the value's extent that speak for it and hold others only
        return [
            n
            for n, h in enumerate(holding)
            if value not in h
            and h
            and speaks_for(n, value)
            and _between(planes[n].pose, [planes[k].pose for k in own[value]])
        ]

    interleaved = False
    if len(groups) > 1:  # some plane of one group inside the extent of another's structure
        interleaved = any(not holding[n] <= group[v] for v in values for n in inside(v))
    gaps = {v: len(found) for v in values if (found := inside(v))}
    if interleaved:
        listed = " | ".join(
            ", ".join(annotation.structure(v).label for v in sorted(g)) for g in groups
        )
        logger.warning(
            "%s: structures drawn on planes of their own, in %d groups (%s): each group is "
            "read on its own planes, not as absent from the others'",
            source,
            len(groups),
            listed,
        )
    for value, count in gaps.items():
        logger.warning(
            "%s: structure %s is missing from %d plane(s) inside its extent that hold other "
            "structures: read as absent there (a gap); if it was only not drawn there, draw "
            "it, or reconstruct it alone with --label",
            source,
            annotation.structure(value).label,
            count,
        )
    if not interleaved and not extra and not any(silent) and not off_lattice:
        return annotation
    rebuilt = []
    for n, plane in enumerate(planes):
        speaks = frozenset(v for v in values if speaks_for(n, v))
        rebuilt.append(AnnotatedPlane(plane.pose, plane.masks, speaks))
    return replace(annotation, planes=tuple(rebuilt))


def _off_lattice(
    planes: Sequence[AnnotatedPlane],
    holding: Sequence[frozenset[int]],
    own: dict[int, list[int]],
) -> set[tuple[int, int]]:
    """``(plane, structure)`` pairs where a plane holding others lies off the lattice of
    the structure's own planes (parallel to it, spaced by their smallest gap): more than
    :data:`EXTRA_GAP_TOLERANCE` of a gap from it."""
    found: set[tuple[int, int]] = set()
    for value, mine in own.items():
        if len(mine) < 2:
            continue
        pose = planes[mine[0]].pose
        offsets = [_along(planes[n].pose, pose) for n in mine if planes[n].pose.is_parallel(pose)]
        step = smallest_gap(offsets, _EPS_MM)
        if step is None:
            continue
        for n, held in enumerate(holding):
            other = planes[n].pose
            if value in held or not held or not other.is_parallel(pose):
                continue
            phase = (_along(other, pose) - min(offsets)) / step
            if abs(phase - round(phase)) > EXTRA_GAP_TOLERANCE:
                found.add((n, value))
    return found


EXTRA_GAP_TOLERANCE = 0.25
"""How far (a fraction of the typical gap) the gap around a plane may differ from the
typical gap for the plane to count as added between two regular ones."""


def _extra_planes(planes: Sequence[AnnotatedPlane]) -> set[int]:
    """Planes added between two regularly spaced ones: both gaps to their neighbours
    are short and the gap between their neighbours is the typical (median) gap of
    their orientation, within :data:`EXTRA_GAP_TOLERANCE` (a lesion drawn on one more
    slice of an organ annotated on every 3rd; not a regular plane beside a run of
    slices drawn one after another)."""
    extra: set[int] = set()
    remaining = list(range(len(planes)))
    while remaining:
        first = planes[remaining[0]].pose
        same = [n for n in remaining if planes[n].pose.is_parallel(first)]
        remaining = [n for n in remaining if n not in same]
        if len(same) < 4:
            continue
        offsets = np.array(
            [planes[n].pose.offset_mm * np.sign(planes[n].pose.normal @ first.normal) for n in same]
        )
        order = np.argsort(offsets)
        ranked = offsets[order]
        typical = float(np.median(np.diff(ranked)))
        if typical <= 0:
            continue
        short = (1 - EXTRA_GAP_TOLERANCE) * typical
        for k in range(1, len(ranked) - 1):
            span = ranked[k + 1] - ranked[k - 1]
            splits = ranked[k] - ranked[k - 1] < short and ranked[k + 1] - ranked[k] < short
            if splits and abs(span - typical) <= EXTRA_GAP_TOLERANCE * typical:
                extra.add(same[int(order[k])])
    return extra


def _drawn_together(
    values: Sequence[int], holding: Sequence[frozenset[int]]
) -> list[frozenset[int]]:
    """The structures grouped by the planes that hold them together (connected
    components of "drawn on one plane"), in the order of ``values``."""
    parent = {v: v for v in values}

    def root(v: int) -> int:
        while parent[v] != v:
            parent[v] = parent[parent[v]]
            v = parent[v]
        return v

    for held in holding:
        first, *rest = sorted(held) or [None]
        for v in rest:
            parent[root(v)] = root(first)
    found: dict[int, set[int]] = {}
    for v in values:
        found.setdefault(root(v), set()).add(v)
    return [frozenset(g) for g in found.values()]


def _nested_in(
    planes: Sequence[AnnotatedPlane], holding: Sequence[frozenset[int]]
) -> dict[int, frozenset[int]]:
    """For each structure, the structures it lies inside: on every plane holding both
    (one at least), all its pixels are the other's too."""
    inside: dict[int, set[int]] = {}
    seen: set[tuple[int, int]] = set()
    broken: set[tuple[int, int]] = set()
    for plane, held in zip(planes, holding, strict=True):
        for y in held:
            for x in held:
                if x == y or (y, x) in broken:
                    continue
                seen.add((y, x))
                if np.any(plane.masks[y] & ~plane.masks[x]):
                    broken.add((y, x))
    for y, x in seen - broken:
        inside.setdefault(y, set()).add(x)
    return {y: frozenset(xs) for y, xs in inside.items()}


NESTED_SHARE = 0.9
"""Share of a structure's drawn pixels that must lie inside another's drawings on that
other's planes either side for it to be read as drawn inside it (:func:`nested_apart`)."""


def nested_apart(annotation: Annotation) -> dict[int, int]:
    """Structures drawn inside another on planes of their own: ``{inner: outer}``.

    A lesion drawn on slices of its own inside its organ, drawn on other
    slices: the two are drawn apart (no plane holds both, directly or through
    structures drawn with them), every plane of the inner lies strictly
    between two of the outer's, and at least :data:`NESTED_SHARE` of the
    inner's drawn pixels lie inside the outer's drawings on its nearest planes
    either side. The outer's planes then say nothing of the inner: it is inside
    the outer's interpolation, not beside it. Of several outers the one with
    the fewest drawn pixels is given. Planes of one orientation on the grid's
    slices only (otherwise nothing is found).

    Parameters
    ----------
    annotation : Annotation

    Returns
    -------
    dict of int to int
        The inner structures' values and their outer one's.
    """
    axis = annotation.grid_axis()
    planes = annotation.planes
    holding = [frozenset(v for v, m in p.masks.items() if m.any()) for p in planes]
    groups = _drawn_together(annotation.values, holding)
    if axis is None or len(groups) < 2:
        return {}
    group = {v: g for g in groups for v in g}
    inverse = np.linalg.inv(annotation.affine)
    index = [float((inverse[:3, :3] @ p.pose.affine[:3, 3] + inverse[:3, 3])[axis]) for p in planes]
    own = {
        v: sorted((index[n], n) for n, h in enumerate(holding) if v in h) for v in annotation.values
    }
    masks: dict[tuple[int, int], NDArray[np.bool_]] = {}

    def drawn(n: int, value: int) -> NDArray[np.bool_]:
        if (n, value) not in masks:
            masks[n, value] = annotation.grid_mask(planes[n], value, axis)
        return masks[n, value]

    found: dict[int, tuple[int, int]] = {}
    for inner, mine in own.items():
        for outer, theirs in own.items():
            if not mine or len(theirs) < 2 or outer in group[inner]:
                continue
            if not theirs[0][0] < mine[0][0] <= mine[-1][0] < theirs[-1][0]:
                continue
            inside = total = 0
            for k, n in mine:
                # the outer's nearest planes either side
                above = min((i, m) for i, m in theirs if i > k)[1]
                below = max((i, m) for i, m in theirs if i < k)[1]
                pixels = drawn(n, inner)
                total += int(np.count_nonzero(pixels))
                inside += int(np.count_nonzero(pixels & drawn(below, outer) & drawn(above, outer)))
            size = sum(int(np.count_nonzero(drawn(m, outer))) for _, m in theirs)
            smallest = size < found.get(inner, (0, size + 1))[1]
            if total and inside >= NESTED_SHARE * total and smallest:
                found[inner] = (outer, size)
    return {inner: outer for inner, (outer, _) in found.items()}


def _along(pose: PlanePose, reference: PlanePose) -> float:
    """Where a plane parallel to ``reference`` lies along ``reference``'s normal, mm."""
    return float(pose.offset_mm * np.sign(pose.normal @ reference.normal))


def _between(pose: PlanePose, own: Sequence[PlanePose]) -> bool:
    """Whether a plane lies strictly between two of ``own`` parallel to it."""
    offsets = [_along(p, pose) for p in own if p.is_parallel(pose)]
    if len(offsets) < 2:
        return False
    return bool(min(offsets) + _EPS_MM < pose.offset_mm < max(offsets) - _EPS_MM)


def covering_grid(
    planes: Sequence[AnnotatedPlane],
    affine: NDArray[np.float64],
    shape: Sequence[int],
    *,
    pad: int = COMBINED_PAD,
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """The index range ``[lo, hi)`` of the lattice of ``affine`` that holds ``shape`` and every
    plane's drawn pixels with ``pad`` voxels around them."""
    lo = np.zeros(3, dtype=np.int64)
    hi = np.asarray(shape, dtype=np.int64).copy()
    corners = [c for c in map(_drawn_corners, planes) if c is not None]
    if corners:
        drawn_lo, drawn_hi = _index_range(corners, affine, pad)
        lo, hi = np.minimum(lo, drawn_lo), np.maximum(hi, drawn_hi)
    return lo, hi


def drawn_box(
    annotation: Annotation, value: int, *, pad: int = 0
) -> tuple[NDArray[np.int64], NDArray[np.int64]] | None:
    """The index range ``[lo, hi)`` on the annotation's grid of a structure's drawn pixels
    on all its planes, with ``pad`` voxels around them; None when it is drawn nowhere."""
    corners = [
        c for p in annotation.planes_of(value) if (c := _drawn_corners(p, value)) is not None
    ]
    if not corners:
        return None
    return _index_range(corners, annotation.affine, pad)


def _index_range(
    corners: Sequence[NDArray[np.float64]], affine: NDArray[np.float64], pad: int
) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
    """The index range ``[lo, hi)`` on the lattice of ``affine`` holding world points
    (each an array of shape (N, 3), mm), with ``pad`` voxels around them."""
    inverse = np.linalg.inv(affine)
    index = np.vstack(corners) @ inverse[:3, :3].T + inverse[:3, 3]
    lo = np.floor(index.min(axis=0)).astype(np.int64) - pad
    return lo, np.ceil(index.max(axis=0)).astype(np.int64) + 1 + pad


def _drawn_corners(plane: AnnotatedPlane, value: int | None = None) -> NDArray[np.float64] | None:
    """World mm of the corners of the box of a plane's drawn pixels (of structure ``value``,
    or of all), pixel edges included; None when nothing is drawn."""
    masks = list(plane.masks.values()) if value is None else [plane.masks.get(value)]
    masks = [m for m in masks if m is not None and m.any()]
    if not masks:
        return None
    drawn = np.logical_or.reduce(masks)
    rows = np.flatnonzero(drawn.any(axis=1))
    cols = np.flatnonzero(drawn.any(axis=0))
    corners = [
        [r, c] for r in (rows[0] - 0.5, rows[-1] + 0.5) for c in (cols[0] - 0.5, cols[-1] + 0.5)
    ]
    return plane.pose.to_world(np.asarray(corners, dtype=np.float64))


def check_drawings_meet(
    planes: Sequence[AnnotatedPlane], origins: Sequence[str], labels: dict[int, str]
) -> None:
    """Refuse a structure whose drawings in two inputs lie far apart; warn when they do not meet.

    For each structure drawn by several inputs, the world-mm boxes of each input's
    drawing: two views of one structure overlap, or nearly (an axial plane near its
    top may end short of a sagittal plane). Boxes further apart than half the larger
    one's diagonal cannot be one study in one frame (refused: such a gap gave a mesh
    in dozens of pieces); a smaller gap (more than one pixel) between drawings on
    planes that cross is warned about (two inputs' parallel planes never meet).

    Raises
    ------
    OptionError
        A structure's drawings in two inputs lie further apart than half their size.
    """
    boxes: dict[int, dict[str, tuple[NDArray[np.float64], NDArray[np.float64], float]]] = {}
    poses: dict[str, list[PlanePose]] = {}  # each input's orientations
    for plane, origin in zip(planes, origins, strict=True):
        if not any(plane.pose.is_parallel(q) for q in poses.setdefault(origin, [])):
            poses[origin].append(plane.pose)
        pixel = float(np.max(plane.pose.pixel_spacing))
        for value in plane.masks:
            corners = _drawn_corners(plane, value)
            if corners is None:
                continue
            lo, hi, step = boxes.setdefault(value, {}).get(
                origin, (np.full(3, np.inf), np.full(3, -np.inf), 0.0)
            )
            boxes[value][origin] = (
                np.minimum(lo, corners.min(axis=0)),
                np.maximum(hi, corners.max(axis=0)),
                max(step, pixel),
            )
    for value, by_input in boxes.items():
        names = sorted(by_input)
        for n, a in enumerate(names):
            for b in names[n + 1 :]:
                (alo, ahi, astep), (blo, bhi, bstep) = by_input[a], by_input[b]
                gap = float(np.linalg.norm(np.maximum(0.0, np.maximum(alo - bhi, blo - ahi))))
                size = max(float(np.linalg.norm(ahi - alo)), float(np.linalg.norm(bhi - blo)))
                if gap > size / 2:
                    raise OptionError(
                        f"structure {labels.get(value, value)} is drawn {gap:.0f} mm apart in "
                        f"{a} and {b}, further than half its size ({size:.0f} mm across, "
                        f"half {size / 2:.0f} mm): they are not "
                        "views of one structure in one frame; check that the files belong "
                        "to one study, or give them another structure name"
                    )
                crossing = any(not p.is_parallel(q) for p in poses[a] for q in poses[b])
                if gap > max(astep, bstep) and crossing:
                    logger.warning(
                        "structure %s: its drawings in %s and %s do not meet (%.1f mm apart); "
                        "check that the files belong to one study and frame",
                        labels.get(value, value),
                        a,
                        b,
                        gap,
                    )


def merge_repeated_planes(
    annotation: Annotation, origins: Sequence[str], first_voxel: NDArray[np.int64]
) -> Annotation:
    """One plane where two inputs draw on one plane; refuse a structure drawn there unlike.

    Two planes are one when they are the same slice of the grid, or have the
    same pose and pixels. ``first_voxel``: the grid's first voxel on the first
    input's grid (messages name slices there).

    Raises
    ------
    OptionError
        A structure drawn on one plane by two inputs, differently.
    """
    kept: dict[Any, tuple[AnnotatedPlane, str]] = {}
    indices = {axis: annotation.plane_indices(axis) for axis in range(3)}
    everything = frozenset(annotation.values)

    def speaks(p: AnnotatedPlane) -> frozenset[int]:
        return everything if p.structures is None else p.structures

    for number, (plane, origin) in enumerate(zip(annotation.planes, origins, strict=True)):
        axis = annotation.axis_of(plane.pose)
        shift = None if axis is None else annotation.grid_shift(plane.pose, axis)
        if axis is not None and shift is not None:
            index = float(indices[axis][number])
            key: Any = ("slice", axis, round(index, 3))
        else:
            key = ("pose", plane.pose.shape, tuple(np.round(plane.pose.affine, 3).ravel()))
        if key not in kept:
            kept[key] = (plane, origin)
            continue
        other, first_origin = kept[key]
        common = speaks(other) & speaks(plane)
        on_grid = key[0] == "slice"
        where = (
            f"slice {key[2] + first_voxel[key[1]]:g} along {AXIS_NAMES[key[1]]}"
            if on_grid
            else "one plane"
        )
        for value in sorted(common):
            if on_grid:
                one = annotation.grid_mask(other, value, key[1])
                two = annotation.grid_mask(plane, value, key[1])
            else:
                one, two = other.mask(value), plane.mask(value)
            if not np.array_equal(one, two):
                raise OptionError(
                    f"structure {annotation.structure(value).label} is drawn on {where} in "
                    f"{first_origin} and in {origin}, differently: keep one drawing of it, or "
                    "choose the structures of each input with --label"
                )
        if on_grid:  # both drawings on the grid's pixels of that slice
            pose = plane_pose(annotation.affine, annotation.grid_shape, key[1], key[2])
            values = set(other.masks) | set(plane.masks)
            masks = {
                v: annotation.grid_mask(other, v, key[1]) | annotation.grid_mask(plane, v, key[1])
                for v in values
            }
        else:
            pose, masks = other.pose, {**plane.masks, **other.masks}
        kept[key] = (AnnotatedPlane(pose, masks, speaks(other) | speaks(plane)), first_origin)
    if len(kept) == len(annotation.planes):
        return annotation
    return replace(annotation, planes=tuple(p for p, _ in kept.values()))


COINCIDING_DICE = 0.5
"""Two structures of different inputs coincide when, where their planes cross, their
drawings have at least this Dice: perhaps one structure given two values."""


def warn_coinciding(
    planes: Sequence[AnnotatedPlane],
    drawer: Sequence[int],
    names: Sequence[str],
    labels: dict[int, str],
) -> None:
    """Warn of two structures, drawn by different inputs only, that coincide where their
    planes cross, or on a plane both draw (one structure valued 1 in one label map and
    2 in the other, or named "Right kidney" in one and "kidney_R" in the other, is split
    into two that share its voxels).

    Parameters
    ----------
    planes : sequence of AnnotatedPlane
    drawer : sequence of int
        The input each plane comes from.
    names : sequence of str
        Each input's name (its path).
    labels : dict
        Structure value → its label, for the message.
    """
    by_input: dict[int, set[int]] = {}
    for plane, n in zip(planes, drawer, strict=True):
        by_input.setdefault(n, set()).update(plane.masks)
    both: dict[tuple[int, int], list[int]] = {}  # (x, y) -> [x and y, x, y] on the lines
    normals = np.array([p.pose.normal for p in planes]).reshape(-1, 3)
    to_pixels = [np.linalg.inv(p.pose.affine) for p in planes]
    limit = np.sin(np.radians(0.5))
    for n, a in enumerate(planes):
        for k in range(n + 1, len(planes)):
            b = planes[k]
            if drawer[k] == drawer[n]:
                continue
            parallel = np.linalg.norm(np.cross(normals[n], normals[k])) < limit
            if parallel and not _same_pixels(a.pose, b.pose):
                continue
            pairs = [
                (x, y)
                for x in a.masks
                for y in b.masks
                if x != y
                and y not in by_input[drawer[n]]
                and x not in by_input[drawer[k]]
                and not b.annotates(x)
                and not a.annotates(y)
            ]
            if not pairs:
                continue
            if parallel:  # one plane drawn in both: the drawings themselves
                for x, y in pairs:
                    counts = both.setdefault((x, y), [0, 0, 0])
                    counts[0] += int(np.count_nonzero(a.masks[x] & b.masks[y]))
                    counts[1] += int(np.count_nonzero(a.masks[x]))
                    counts[2] += int(np.count_nonzero(b.masks[y]))
                continue
            world = crossing_points(a, b, to_pixels[n], to_pixels[k])
            if world is None:
                continue
            # each structure sampled once per line; a pair's overlap only where both are
            ones = {x: drawn_at(a, x, to_pixels[n], world) for x, _ in pairs}
            twos = {y: drawn_at(b, y, to_pixels[k], world) for _, y in pairs}
            nx = {x: int(np.count_nonzero(v)) for x, v in ones.items()}
            ny = {y: int(np.count_nonzero(v)) for y, v in twos.items()}
            for x, y in pairs:
                counts = both.setdefault((x, y), [0, 0, 0])
                if nx[x] and ny[y]:
                    counts[0] += int(np.count_nonzero(ones[x] & twos[y]))
                counts[1] += nx[x]
                counts[2] += ny[y]
    found: dict[tuple[int, int], list[tuple[int, int, float]]] = {}  # inputs -> pairs
    for (x, y), (shared, count_x, count_y) in both.items():
        dice = 2 * shared / (count_x + count_y) if count_x + count_y else 0.0
        if dice >= COINCIDING_DICE:
            first = next(n for p, n in zip(planes, drawer, strict=True) if x in p.masks)
            second = next(n for p, n in zip(planes, drawer, strict=True) if y in p.masks)
            found.setdefault((first, second), []).append((x, y, dice))
    for (first, second), pairs in found.items():  # one line per two inputs
        listed = ", ".join(
            f"{labels.get(x, x)} ~ {labels.get(y, y)} (Dice {dice:.2f})"
            for x, y, dice in sorted(pairs)[:6]
        ) + (f" and {len(pairs) - 6} more" if len(pairs) > 6 else "")
        logger.warning(
            "structures of %s and %s coincide where their planes cross or are one: %s; they are "
            "reconstructed as different structures; if they are one, give them one value or "
            "one name in both",
            names[first],
            names[second],
            listed,
        )


def _same_pixels(a: PlanePose, b: PlanePose) -> bool:
    """Whether two plane poses are one plane of the same pixels (within 0.01 mm)."""
    return a.shape == b.shape and bool(np.allclose(a.affine, b.affine, atol=0.01))
