"""Which planes of a label map were annotated: along every grid axis, at any density.

A clinician who annotates a few slices and saves them as a label map leaves
every other slice empty. Those slices can lie along one axis (every 2nd, 5th or
irregularly chosen axial slice) or along several (axial slices plus a few
sagittal and coronal ones). :func:`detect_planes` finds them with one stated
rule, and says when the mask is dense instead.

The rule
--------
An annotated plane is a **sheet**: along the axis it is perpendicular to, its
voxels have at most :data:`MAX_SHEET_RUN` foreground voxels in a row (the
slices beside it are empty there). So:

1. for each axis ``a``, the foreground voxels whose run of consecutive
   foreground voxels along ``a`` is at most :data:`MAX_SHEET_RUN` long, and
   no longer than their runs along the two other axes, are its sheet voxels
   (where a sagittal plane crosses an empty axial slice it is thinnest along
   x, not z);
2. the axes are taken greedily, the one whose planes hold the most foreground
   first: a slice perpendicular to ``a`` is an **annotated plane** when at
   least :data:`MIN_SHEET_FRACTION` of its foreground that no plane taken
   so far holds is sheet voxels along ``a``. (A slice that only crosses the
   planes of another axis, or only their rims, holds nothing new and is not
   one.)
3. a plane whose foreground lies almost all (:data:`EXPLAINED`) in the
   planes of the other axes is dropped: it is where they cross an empty slice;
4. the mask is **sparse** when the annotated planes of all axes hold at least
   :data:`MIN_COVERED` of its foreground (what they do not hold is where a
   structure is thin, or noise); otherwise it is **dense** (a full mask: the
   paper's setting, sampled by ``--slices``).

A slice annotated on every slice (no empty slice between) is a dense mask:
nothing tells the two apart, and both are read the same way. The constants
were chosen on the development shapes (``docs/results.md``, "Annotations").
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import InputError, OptionError
from .sections import AXIS_NAMES, in_plane_axes

__all__ = [
    "ANNOTATION_CHOICES",
    "MAX_SHEET_RUN",
    "EXPLAINED",
    "MIN_COVERED",
    "MIN_GAPS_WARNED",
    "MIN_SHEET_FRACTION",
    "PlaneReading",
    "detect_planes",
    "has_gaps",
    "mixed_reading",
    "structures_reading",
    "parse_annotation",
    "refuse_sparse_truth",
]

MAX_SHEET_RUN = 3
"""Longest run of foreground voxels across a sheet: three annotated slices in a row
still read as three planes (an annotator who skips irregularly)."""
MIN_SHEET_FRACTION = 0.5
"""Share of a slice's foreground that must be sheet voxels for it to be an annotated plane."""
EXPLAINED = 0.95
"""A plane whose foreground lies this much in the planes of other axes adds nothing: it is
where those planes cross an empty slice, not a plane of its own, and is dropped."""
MIN_COVERED = 0.98
"""Share of the foreground the annotated planes must hold for the mask to be sparse."""
MAX_DEEP_SHARE = 0.5
"""A mask more than half of whose voxels have foreground two voxels away on both sides
along every axis is a solid, read as dense without measuring its runs: annotated
planes only hold such voxels where they cross."""
MIN_GAPS_WARNED = 2
"""Runs of empty slices inside a dense-read mask along one axis from which a warning says
that it may be drawn on groups of slices (one gap: two pieces, which dense masks have)."""
ANNOTATION_CHOICES = ("auto", "dense", "x", "y", "z")
"""``--annotation``: ``auto`` (the rule), ``dense``, or the axes (``z``, ``xz``, ``x,y,z``)."""

_CAP = MAX_SHEET_RUN + 1


@dataclass(frozen=True)
class PlaneReading:
    """How a mask was read: dense, or annotated on some planes of some axes.

    Attributes
    ----------
    dense : bool
        A full mask (sample its planes), not an annotation.
    planes : dict of int to ndarray of int
        Sparse masks: each axis's annotated slice indices (only axes that have some).
    covered : float
        Share of the foreground the annotated planes hold.
    stated : bool
        The reading was stated (``--annotation``), not detected.
    """

    dense: bool
    planes: dict[int, NDArray[np.int64]] = field(default_factory=dict)
    covered: float = 0.0
    stated: bool = False

    @property
    def axes(self) -> tuple[int, ...]:
        """The axes that have annotated planes, increasing."""
        return tuple(sorted(a for a, p in self.planes.items() if p.size))

    def within(self, first: ArrayLike, shape: tuple[int, ...]) -> PlaneReading:
        """The reading on a box of the grid it was made on: the box's first voxel at
        index ``first`` (shape (3,), int) and its ``shape``; planes outside it left out."""
        if self.dense:
            return self
        offset = np.asarray(first, dtype=np.int64)
        planes = {a: p - offset[a] for a, p in self.planes.items()}
        planes = {a: p[(p >= 0) & (p < shape[a])] for a, p in planes.items()}
        return replace(self, planes={a: p for a, p in planes.items() if p.size})

    def describe(self, spacing: ArrayLike | None = None, affine: ArrayLike | None = None) -> str:
        """One line: dense, or how many planes along which axes and their spacing.

        With the grid's ``affine`` (voxel index → world mm, shape (4, 4)) the spacing
        is measured along the planes' normal, and planes whose normal is not the world
        axis of their grid axis's name say so: ``the grid's z (world x)`` (a sagittal
        acquisition's slices), or ``the grid's z`` (oblique ones). ``--annotation``
        names the grid's axes.
        """
        how = "stated" if self.stated else "detected"
        if self.dense:
            return f"dense mask ({how})"
        names = list(AXIS_NAMES)
        if affine is not None:
            columns = np.asarray(affine, dtype=np.float64)[:3, :3]
            # the planes' normal names them, and their spacing is measured along it (a
            # sheared grid's column, as after a CT gantry tilt, is longer)
            spacing = np.empty(3)
            for axis in range(3):
                a, b = in_plane_axes(axis)
                normal = np.cross(columns[:, a], columns[:, b])
                unit = np.abs(normal) / np.linalg.norm(normal)
                spacing[axis] = abs(columns[:, axis] @ normal) / np.linalg.norm(normal)
                world = int(np.argmax(unit))
                if unit.max() < 1 - 1e-6:
                    names[axis] = f"the grid's {AXIS_NAMES[axis]}"
                elif world != axis:
                    names[axis] = f"the grid's {AXIS_NAMES[axis]} (world {AXIS_NAMES[world]})"
        parts = []
        for axis in self.axes:
            planes = self.planes[axis]
            text = f"{planes.size} plane{'s' * (planes.size != 1)} along {names[axis]}"
            if planes.size > 1:
                gaps = np.diff(planes)
                step = float(np.median(gaps))
                if spacing is not None:
                    step *= float(np.asarray(spacing, dtype=np.float64)[axis])
                    text += f" (spacing {step:.3g} mm"
                else:
                    text += f" (every {step:.3g} slices"
                text += ", irregular)" if np.ptp(gaps) else ")"
            parts.append(text)
        return f"sparse annotation ({how}): " + ", ".join(parts)


def parse_annotation(text: str | None) -> str | tuple[int, ...]:
    """``--annotation``: ``"auto"``, ``"dense"`` or the stated axes as numbers.

    Raises
    ------
    OptionError
        Anything else (the message lists the choices).
    """
    value = "auto" if text is None else str(text).strip().lower()
    if value in ("auto", "dense"):
        return value
    axes = [c for c in value.replace(",", "").replace(" ", "")]
    if not axes or any(c not in "xyz" for c in axes) or len(set(axes)) != len(axes):
        raise OptionError(
            f"--annotation must be auto, dense, or the annotated axes such as z, xz, x,y,z "
            f"(got {text!r})"
        )
    return tuple(sorted("xyz".index(c) for c in axes))


def _runs(mask: NDArray[np.bool_], axis: int) -> NDArray[np.uint8]:
    """Each voxel's run of consecutive foreground voxels along ``axis`` (capped), 0 outside."""
    moved = np.moveaxis(mask, axis, 0)
    forward = np.zeros(moved.shape, dtype=np.uint8)
    backward = np.zeros(moved.shape, dtype=np.uint8)
    count = np.zeros(moved.shape[1:], dtype=np.uint8)
    for k in range(moved.shape[0]):
        count = np.where(moved[k], np.minimum(count + 1, _CAP), 0).astype(np.uint8)
        forward[k] = count
    count = np.zeros(moved.shape[1:], dtype=np.uint8)
    for k in range(moved.shape[0] - 1, -1, -1):
        count = np.where(moved[k], np.minimum(count + 1, _CAP), 0).astype(np.uint8)
        backward[k] = count
    run = np.minimum(forward.astype(np.int16) + backward - 1, _CAP)
    run[~moved] = 0
    return np.moveaxis(run.astype(np.uint8), 0, axis)


def detect_planes(mask: ArrayLike, annotation: str | tuple[int, ...] = "auto") -> PlaneReading:
    """Read a mask as dense or as annotated planes, by the module's rule or as stated.

    Parameters
    ----------
    mask : ndarray of shape (I, J, K), bool
        Every structure's foreground together.
    annotation : "auto", "dense" or tuple of int
        ``"auto"``: the rule decides. ``"dense"``: a full mask. Axes: the
        annotated planes are the slices the rule finds along those axes (for
        one axis, every slice holding foreground along it).

    Returns
    -------
    PlaneReading
    """
    data = np.asarray(mask, dtype=bool)
    if annotation == "dense":
        return PlaneReading(True, stated=True)
    total = int(np.count_nonzero(data))
    if total == 0:
        return PlaneReading(True)
    if isinstance(annotation, tuple) and len(annotation) == 1:
        (only,) = annotation
        other = in_plane_axes(only)
        occupied = np.flatnonzero(data.any(axis=other)).astype(np.int64)
        return PlaneReading(False, {only: occupied}, 1.0, stated=True)
    if annotation == "auto" and _deep_share(data) > MAX_DEEP_SHARE:
        return PlaneReading(True)  # a solid: most voxels lie deep along every axis
    runs = [_runs(data, a) for a in range(3)]
    sheets = {}
    for a in range(3):
        b, c = in_plane_axes(a)
        sheets[a] = data & (runs[a] <= MAX_SHEET_RUN) & (runs[a] <= runs[b]) & (runs[a] <= runs[c])
    todo = list(range(3)) if annotation == "auto" else list(annotation)
    planes: dict[int, NDArray[np.int64]] = {}
    covered = np.zeros(data.shape, dtype=bool)
    while todo:
        best: tuple[int, int, NDArray[np.int64]] | None = None
        for a in todo:
            b, c = in_plane_axes(a)
            new = data & ~covered
            per_slice = new.sum(axis=(b, c))
            sheet_slice = (sheets[a] & ~covered).sum(axis=(b, c))
            chosen = np.flatnonzero(
                (per_slice > 0) & (sheet_slice >= MIN_SHEET_FRACTION * per_slice)
            ).astype(np.int64)
            gain = int(per_slice[chosen].sum())
            if gain and (best is None or gain > best[1]):
                best = (a, gain, chosen)
        if best is None:
            break
        a, _, chosen = best
        planes[a] = chosen
        view = np.moveaxis(covered, a, 0)
        view[chosen] |= np.moveaxis(data, a, 0)[chosen]
        todo.remove(a)
    planes = _drop_explained(data, planes)
    covered = _covered(data, planes)
    share = float(np.count_nonzero(covered)) / total
    if annotation != "auto":
        return PlaneReading(False, planes, share, stated=True)
    if planes and share >= MIN_COVERED:
        return PlaneReading(False, planes, share)
    return PlaneReading(True, {}, share)


def empty_runs_inside(mask: ArrayLike) -> dict[int, int]:
    """Runs of empty slices inside a mask's extent, per axis.

    Parameters
    ----------
    mask : ndarray of shape (I, J, K), bool

    Returns
    -------
    dict of int to int
        Axis → how many runs of slices without foreground lie between its
        first and last slice holding some (axes without any are left out). A
        dense organ has none; slabs of slices drawn with gaps between them
        (4 slices on, 6 off) have one per gap.
    """
    data = np.asarray(mask, dtype=bool)
    out: dict[int, int] = {}
    for axis in range(3):
        held = data.any(axis=in_plane_axes(axis))
        inside = held[np.argmax(held) : len(held) - np.argmax(held[::-1])] if held.any() else held
        starts = int(np.count_nonzero(~inside[1:] & inside[:-1])) if inside.size > 1 else 0
        if starts:
            out[axis] = starts
    return out


def _covered(data: NDArray[np.bool_], planes: dict[int, NDArray[np.int64]]) -> NDArray[np.bool_]:
    """The foreground that the given planes hold."""
    covered = np.zeros(data.shape, dtype=bool)
    for a, chosen in planes.items():
        view = np.moveaxis(covered, a, 0)
        view[chosen] |= np.moveaxis(data, a, 0)[chosen]
    return covered


def _drop_explained(
    data: NDArray[np.bool_], planes: dict[int, NDArray[np.int64]]
) -> dict[int, NDArray[np.int64]]:
    """The planes without those whose foreground the other axes' planes already hold."""
    kept = dict(planes)
    for a in sorted(planes):
        others = _covered(data, {b: p for b, p in kept.items() if b != a})
        slices = np.moveaxis(data, a, 0)
        inside = np.moveaxis(others, a, 0)
        keep = [
            k
            for k in kept[a]
            if np.count_nonzero(slices[k] & inside[k]) < EXPLAINED * np.count_nonzero(slices[k])
        ]
        kept[a] = np.asarray(keep, dtype=np.int64)
    return {a: p for a, p in kept.items() if p.size}


def _deep_share(data: NDArray[np.bool_]) -> float:
    """Share of the foreground with foreground 1 and 2 voxels away on both sides, all axes."""
    deep = data.copy()
    for axis in range(3):
        n = data.shape[axis]
        for step in (1, 2):
            if n <= 2 * step:
                return 0.0
            ahead = [slice(None)] * 3
            behind = [slice(None)] * 3
            ahead[axis], behind[axis] = slice(step, None), slice(None, -step)
            deep[tuple(behind)] &= data[tuple(ahead)]
            deep[tuple(ahead)] &= data[tuple(behind)]
            edge = [slice(None)] * 3
            edge[axis] = slice(None, step)
            deep[tuple(edge)] = False
            edge[axis] = slice(n - step, None)
            deep[tuple(edge)] = False
    return float(np.count_nonzero(deep)) / max(int(np.count_nonzero(data)), 1)


def has_gaps(mask: NDArray[np.bool_]) -> bool:
    """Whether a mask has :data:`MIN_GAPS_WARNED` runs of empty slices inside it along an
    axis (what ``slicerecon run`` warns of)."""
    return any(runs >= MIN_GAPS_WARNED for runs in empty_runs_inside(mask).values())


def structures_reading(
    values: Sequence[int],
    mask_of: Callable[[int], NDArray[np.bool_]],
    union: NDArray[np.bool_],
    annotation: str | tuple[int, ...] = "auto",
    *,
    mixed: Callable[[], tuple[PlaneReading, frozenset[int]] | None] | None = None,
) -> tuple[PlaneReading, frozenset[int]]:
    """How a label map of several structures is read: their union by
    :func:`detect_planes` (or as ``annotation`` states), and structures drawn on every
    slice they cross beside others drawn on some by :func:`mixed_reading`.

    A stated axis keeps the second rule: the lesion drawn on each slice is still not
    drawn on behalf of the organs (``--annotation z`` on organs drawn on every 4th
    axial slice and a lesion on each slice erased the organs on the lesion's slices).

    Parameters
    ----------
    values : sequence of int
        The structures' label values.
    mask_of : callable
        ``mask_of(value)``: a structure's mask, ndarray of shape (I, J, K), bool.
    union : ndarray of shape (I, J, K), bool
        Every structure's foreground, on the same box.
    annotation : str or tuple of int
        ``"auto"`` (the rule), ``"dense"`` or the annotated axes
        (:func:`parse_annotation`).
    mixed : callable, optional
        Gives :func:`mixed_reading` of ``values`` (a caller reading both as stated and
        by the rule reads the structures one by one once); default: it is called.

    Returns
    -------
    (PlaneReading, frozenset of int)
        The reading, and the values of the structures drawn on every slice they cross
        (empty unless the others are drawn on planes of one axis).
    """
    reading = detect_planes(union, annotation)
    if len(values) < 2:
        return reading, frozenset()
    if reading.stated:
        if reading.dense or len(reading.axes) != 1:
            return reading, frozenset()
    elif reading.dense and not has_gaps(union):
        return reading, frozenset()
    one_by_one = mixed() if mixed is not None else mixed_reading(values, mask_of)
    if one_by_one is None:
        return reading, frozenset()
    if reading.stated:
        if one_by_one[0].axes != reading.axes:
            return reading, frozenset()
        return replace(one_by_one[0], stated=True), one_by_one[1]
    return one_by_one


def mixed_reading(
    values: Sequence[int], mask_of: Callable[[int], NDArray[np.bool_]]
) -> tuple[PlaneReading, frozenset[int]] | None:
    """A label map of several structures read one by one: some drawn on planes of one
    axis with slices between them, the others on every slice they cross (a lesion
    contoured on each slice, the organs on every 4th). Read together, such a map looks
    dense, or sparse with the lesion's slices as planes of every structure.

    Parameters
    ----------
    values : sequence of int
        The structures.
    mask_of : callable
        ``mask_of(value)``: a structure's mask, ndarray of shape (I, J, K), bool, on one
        box for all of them (asked for one at a time, each more than once).

    Returns
    -------
    (PlaneReading, frozenset of int) or None
        The planes of the structures drawn on some slices (read together), and the values
        drawn on every slice; None when no structure, or every one, reads as sparse, or
        the sparse ones are not planes of one axis with a slice between two of them.
    """
    own: dict[int, PlaneReading] = {}
    held: dict[int, list[NDArray[np.bool_]]] = {}  # value -> slices holding it, per axis
    for value in values:
        mask = mask_of(value)
        if mask.any():
            own[value] = detect_planes(_boxed(mask))
            held[value] = [mask.any(axis=in_plane_axes(a)) for a in range(3)]
    sparse = [v for v, r in own.items() if not r.dense]
    if not sparse:
        return None
    if len(sparse) == len(values):
        # each is drawn on planes, all together are not (a lesion drawn on the two slices
        # between two of the organs' planes): every structure's own planes, read alone
        axes = {a for r in own.values() for a in r.axes}
        if len(axes) != 1:
            return None
        axis = axes.pop()
        union = np.logical_or.reduce([h[axis] for h in held.values()])
        return PlaneReading(False, {axis: np.flatnonzero(union).astype(np.int64)}, 1.0), frozenset()
    together = mask_of(sparse[0]).copy()
    for value in sparse[1:]:
        together |= mask_of(value)
    reading = detect_planes(together)
    if reading.dense or len(reading.axes) != 1:
        return None
    axis = reading.axes[0]
    if np.all(np.diff(reading.planes[axis]) <= 1):  # no slice between: not an annotation
        return None
    rest = frozenset(values) - frozenset(sparse)
    drawn = [held[v][axis] for v in rest if v in held]
    slices = np.flatnonzero(np.logical_or.reduce(drawn)) if drawn else np.empty(0, np.int64)
    planes = np.union1d(reading.planes[axis], slices).astype(np.int64)
    return replace(reading, planes={axis: planes}), rest


def _boxed(mask: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """A mask cropped to its foreground with one empty voxel around it."""
    lo = [int(np.flatnonzero(mask.any(axis=in_plane_axes(a)))[0]) for a in range(3)]
    hi = [int(np.flatnonzero(mask.any(axis=in_plane_axes(a)))[-1]) + 1 for a in range(3)]
    return np.pad(mask[lo[0] : hi[0], lo[1] : hi[1], lo[2] : hi[2]], 1)


def refuse_sparse_truth(mask: ArrayLike, affine: ArrayLike, what: str) -> None:
    """Refuse a ground truth that reads as a sparse annotation (:func:`detect_planes`).

    Scored against its few drawn planes, a good reconstruction looked bad (volume
    IoU 0.33 where it was 0.985) and a sparse input scored against itself looked
    perfect, without a word.

    Parameters
    ----------
    mask : array_like of shape (I, J, K)
        The ground truth's foreground (every structure).
    affine : array_like of shape (4, 4)
        Its voxel index → world mm, for the message.
    what : str
        The ground truth, for the message.

    Raises
    ------
    InputError
        When the mask reads as a sparse annotation.
    """
    reading = detect_planes(np.asarray(mask) != 0)
    if not reading.dense:
        spacing = np.linalg.norm(np.asarray(affine, dtype=np.float64)[:3, :3], axis=0)
        raise InputError(
            f"{what} is a {reading.describe(spacing, affine)}, not a dense mask: it is no "
            "ground truth to score against; pass the dense mask or a closed mesh"
        )
