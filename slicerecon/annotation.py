"""The annotation: which planes were drawn, where they lie in world mm, and what they hold.

An :class:`Annotation` is what every reader produces and every reconstruction
consumes: a set of :class:`AnnotatedPlane` for any number of structures
(:class:`~slicerecon.labels.Structure`), on a reference voxel grid (the grid the
result is written on). Each plane has its own pose in world millimetres
(:class:`PlanePose`: any orientation), its own in-plane pixel grid, and a 2-D
mask per structure drawn on it. Which planes were annotated is explicit: a
plane that annotates a structure and holds none of it means "the structure is
not here", which is information, not a missing plane. ``structures`` of a
plane says which structures it speaks for (all of the annotation's, for a
label map whose annotator marked whole slices; the ROI drawn on it, for an
RTSTRUCT whose ROIs are contoured on their own slices).

``exclusive`` says how the structures relate: a label map is a partition (no
voxel belongs to two structures, and touching structures share their
interface); RTSTRUCT ROIs and SEG segments may overlap or nest (BODY ⊃ organ ⊃
GTV) and are reconstructed independently.

A stack of planes perpendicular to one axis of the reference grid is the common
case: :meth:`Annotation.cross_sections` gives a structure's planes as
:class:`~slicerecon.sections.CrossSections` (with its positions along that
axis), and :func:`annotation_from_sections` builds the annotation back from
them.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import GeometryError, InputError, LabelError
from .labels import Structure
from .sections import AXIS_NAMES, CrossSections, check_affine, in_plane_axes
from .selection import choose_structures

__all__ = [
    "AnnotatedPlane",
    "Annotation",
    "PlanePose",
    "annotation_from_sections",
    "plane_pose",
    "smallest_gap",
]

ANGLE_TOLERANCE = 1e-3
"""Two plane normals whose cross product is below this (radians, about) are parallel."""
MAX_ORIENTATIONS_LISTED = 3
"""Orientations :meth:`Annotation.describe` lists one by one; more are counted."""


def _readonly(array: ArrayLike, dtype: Any) -> NDArray[Any]:
    out = np.array(array, dtype=dtype, copy=True)
    out.setflags(write=False)
    return out


@dataclass(frozen=True, eq=False)
class PlanePose:
    """Where a plane lies in world mm and how its pixels map there.

    Parameters
    ----------
    affine : ndarray of shape (4, 4)
        Pixel index ``(r, c, 0, 1)`` → world mm ``(x, y, z, 1)``: columns 0
        and 1 are the steps of one pixel along rows and columns (mm), column 2
        is the plane's unit normal, column 3 the centre of pixel ``(0, 0)``.
    shape : tuple of 2 int
        Pixels along rows and columns ``(M, N)``.
    """

    affine: NDArray[np.float64]
    shape: tuple[int, int]

    def __post_init__(self) -> None:
        affine = check_affine(self.affine)
        normal = affine[:3, 2]
        if not np.isclose(np.linalg.norm(normal), 1.0, atol=1e-6):
            raise GeometryError("a plane pose's third column must be its unit normal")
        for column in (0, 1):
            if abs(float(np.dot(affine[:3, column], normal))) > 1e-6 * np.linalg.norm(
                affine[:3, column]
            ):
                raise GeometryError("a plane's pixel axes must lie in the plane")
        object.__setattr__(self, "affine", affine)
        shape = tuple(int(s) for s in self.shape)
        if len(shape) != 2 or min(shape) < 1:
            raise GeometryError(f"a plane needs two positive pixel counts (got {self.shape})")
        object.__setattr__(self, "shape", shape)

    @property
    def normal(self) -> NDArray[np.float64]:
        """Unit normal in world coordinates, ndarray of shape (3,)."""
        return self.affine[:3, 2].copy()

    @property
    def offset_mm(self) -> float:
        """Signed distance of the plane from the world origin along :attr:`normal`, mm."""
        return float(np.dot(self.affine[:3, 3], self.affine[:3, 2]))

    @property
    def pixel_spacing(self) -> NDArray[np.float64]:
        """Pixel size along rows and columns, mm, ndarray of shape (2,)."""
        return np.linalg.norm(self.affine[:3, :2], axis=0)

    def to_world(self, points_px: ArrayLike) -> NDArray[np.float64]:
        """Map pixel coordinates, ndarray of shape (n, 2), to world mm, shape (n, 3)."""
        pts = np.asarray(points_px, dtype=np.float64).reshape(-1, 2)
        return pts @ self.affine[:3, :2].T + self.affine[:3, 3]

    def is_parallel(self, other: PlanePose) -> bool:
        """Whether two planes have the same orientation (normals parallel or opposite)."""
        return float(np.linalg.norm(np.cross(self.normal, other.normal))) < ANGLE_TOLERANCE


@dataclass(frozen=True, eq=False)
class AnnotatedPlane:
    """One drawn plane: its pose and each structure's mask on its pixels.

    Parameters
    ----------
    pose : PlanePose
    masks : mapping of int to ndarray of shape pose.shape, bool
        Structure value → foreground pixels; a structure absent from the
        mapping (or with an empty mask) is not on this plane.
    structures : frozenset of int or None
        The structures this plane annotates (None: every structure of the
        annotation). A plane annotating a structure it holds no pixel of says
        that structure is absent there.
    """

    pose: PlanePose
    masks: Mapping[int, NDArray[np.bool_]] = field(default_factory=dict)
    structures: frozenset[int] | None = None

    def __post_init__(self) -> None:
        masks: dict[int, NDArray[np.bool_]] = {}
        for value, mask in self.masks.items():
            arr = np.asarray(mask)
            if arr.shape != self.pose.shape:
                raise GeometryError(
                    f"structure {value}'s mask has shape {arr.shape}, the plane {self.pose.shape}"
                )
            if arr.any():
                masks[int(value)] = _readonly(arr, bool)
        object.__setattr__(self, "masks", masks)
        if self.structures is not None:
            object.__setattr__(self, "structures", frozenset(int(v) for v in self.structures))

    def annotates(self, value: int) -> bool:
        """Whether this plane speaks for structure ``value`` (holding it or not)."""
        return self.structures is None or value in self.structures

    def mask(self, value: int) -> NDArray[np.bool_]:
        """Structure ``value``'s pixels, ndarray of shape pose.shape, bool (all False if absent)."""
        found = self.masks.get(value)
        return found if found is not None else np.zeros(self.pose.shape, dtype=bool)


@dataclass(frozen=True, eq=False)
class Annotation:
    """Annotated planes of any number of structures, on a reference grid.

    Parameters
    ----------
    planes : tuple of AnnotatedPlane
    structures : tuple of Structure
        Every structure the annotation holds, in order.
    affine : ndarray of shape (4, 4)
        Voxel index → world mm of the reference grid (where results are written).
    grid_shape : tuple of 3 int
        Shape of the reference grid.
    coordinates : {"RAS", "LPS"}
        The world frame of every affine here.
    exclusive : bool
        True for a partition (a label map: structures never overlap); False
        when structures may overlap or nest (RTSTRUCT ROIs, SEG segments).
    source : str
        How the input was read, in words (for the one line ``run`` and ``info`` print).
    grids : mapping of int to (ndarray of shape (4, 4), tuple of 3 int)
        Structures reconstructed on a grid of their own, not the reference
        grid: ``{value: (affine, shape)}``. Several inputs combined give a
        structure drawn by one input only that input's grid
        (:func:`slicerecon.combine.combine_cases`); see :meth:`of_structure`.
    gap_ends : frozenset of int
        Structures whose outer planes stand for half their own plane spacing:
        contours read without an image, each standing for the slab half-way to
        its neighbours, end half the smallest gap between the structure's
        planes beyond its outer ones, whatever the grid's step (several
        structures share a grid as fine as the finest spacing). The others end
        half a voxel of the grid beyond them: a drawn slice stands for its own
        voxels.
    """

    planes: tuple[AnnotatedPlane, ...]
    structures: tuple[Structure, ...]
    affine: NDArray[np.float64]
    grid_shape: tuple[int, int, int]
    coordinates: str = "RAS"
    exclusive: bool = True
    source: str = ""
    grids: Mapping[int, tuple[NDArray[np.float64], tuple[int, int, int]]] = field(
        default_factory=dict
    )
    gap_ends: frozenset[int] = frozenset()

    def __post_init__(self) -> None:
        object.__setattr__(self, "planes", tuple(self.planes))
        object.__setattr__(self, "structures", tuple(self.structures))
        object.__setattr__(self, "affine", check_affine(self.affine))
        shape = tuple(int(s) for s in self.grid_shape)
        if len(shape) != 3 or min(shape) < 1:
            raise GeometryError(f"grid_shape must be three positive sizes (got {self.grid_shape})")
        object.__setattr__(self, "grid_shape", shape)
        values = [s.value for s in self.structures]
        if len(set(values)) != len(values):
            raise InputError(f"structure values must be unique (got {values})")
        grids = {
            int(v): (check_affine(affine), tuple(int(n) for n in shape))
            for v, (affine, shape) in self.grids.items()
        }
        if not set(grids) <= set(values):
            raise InputError(f"grids for structures the annotation does not hold: {sorted(grids)}")
        object.__setattr__(self, "grids", grids)
        gap_ends = frozenset(int(v) for v in self.gap_ends)
        if not gap_ends <= set(values):
            raise InputError(
                f"gap_ends names structures the annotation does not hold: {sorted(gap_ends)}"
            )
        object.__setattr__(self, "gap_ends", gap_ends)

    # -- what it holds -------------------------------------------------------------------
    @property
    def values(self) -> tuple[int, ...]:
        """The structures' values, in order."""
        return tuple(s.value for s in self.structures)

    def structure(self, value: int) -> Structure:
        """The structure of ``value``."""
        for s in self.structures:
            if s.value == value:
                return s
        raise LabelError(f"the annotation holds no structure {value}")

    def planes_of(self, value: int) -> tuple[AnnotatedPlane, ...]:
        """The planes that annotate structure ``value`` (holding it or not)."""
        return tuple(p for p in self.planes if p.annotates(value))

    def of_structure(self, value: int) -> Annotation:
        """Structure ``value`` alone on the grid it is reconstructed on.

        Returns
        -------
        Annotation
            The structure's planes on its own grid (:attr:`grids`) when it has
            one; otherwise this annotation itself (the reference grid).
        """
        if value not in self.grids:
            return self
        affine, shape = self.grids[value]
        planes = tuple(
            AnnotatedPlane(
                p.pose,
                {value: p.mask(value)},
                frozenset({value}),
            )
            for p in self.planes_of(value)
        )
        return Annotation(
            planes,
            (self.structure(value),),
            affine,
            shape,
            self.coordinates,
            self.exclusive,
            self.source,
            gap_ends=self.gap_ends & {value},
        )

    def orientations(self) -> list[tuple[NDArray[np.float64], list[int]]]:
        """The planes grouped by orientation: ``[(unit normal, plane numbers), ...]``."""
        groups: list[tuple[NDArray[np.float64], list[int]]] = []
        for n, plane in enumerate(self.planes):
            for normal, members in groups:
                if float(np.linalg.norm(np.cross(normal, plane.pose.normal))) < ANGLE_TOLERANCE:
                    members.append(n)
                    break
            else:
                groups.append((plane.pose.normal, [n]))
        return groups

    def grid_axis(self) -> int | None:
        """The reference grid axis every plane is a slice of, or None.

        None when the planes have several orientations, one that is not
        perpendicular to a grid axis (oblique planes), or when a plane's
        pixels do not lie on the grid's voxels (another input's grid of
        another pixel size).
        """
        groups = self.orientations()
        if len(groups) != 1:
            return None
        axis = self._axis_of(self.planes[0].pose)
        if axis is None or any(self.grid_shift(p.pose, axis) is None for p in self.planes):
            return None
        return axis

    def grid_shift(self, pose: PlanePose, axis: int) -> NDArray[np.int64] | None:
        """Where a slice of grid ``axis`` has its pixel ``(0, 0)`` on the grid, or None.

        Parameters
        ----------
        pose : PlanePose
        axis : int
            The grid axis the plane is perpendicular to.

        Returns
        -------
        ndarray of shape (2,), int, or None
            The grid's voxel indices along the two in-plane axes
            (:func:`slicerecon.sections.in_plane_axes`) of the plane's first
            pixel, when its rows and columns step as the grid's voxels do and
            start on one of them (a plane of another crop of the same grid);
            None otherwise.
        """
        a, b = in_plane_axes(axis)
        steps = self.affine[:3, [a, b]]
        if not np.allclose(pose.affine[:3, :2], steps, atol=1e-6 * float(np.abs(steps).max())):
            return None
        inverse = np.linalg.inv(self.affine)
        origin = inverse[:3, :3] @ pose.affine[:3, 3] + inverse[:3, 3]
        shift = np.rint(origin[[a, b]]).astype(np.int64)
        return shift if np.allclose(origin[[a, b]], shift, atol=1e-6) else None

    def select(self, selectors: Sequence[int | str], *, source: Any) -> Annotation:
        """The structures named by ``selectors`` (numbers or names), in the order given.

        Raises
        ------
        LabelError
            A selector names no structure (the message lists them).
        """
        names = {s.value: s.name for s in self.structures}
        values = choose_structures(names, selectors, source=source)
        chosen = [self.structure(v) for v in values]
        keep = set(values)
        planes = []
        for plane in self.planes:
            annotated = keep if plane.structures is None else keep & plane.structures
            if not annotated:
                continue
            masks = {v: m for v, m in plane.masks.items() if v in keep}
            planes.append(AnnotatedPlane(plane.pose, masks, plane.structures))
        return Annotation(
            tuple(planes),
            tuple(chosen),
            self.affine,
            self.grid_shape,
            self.coordinates,
            self.exclusive,
            self.source,
            {v: g for v, g in self.grids.items() if v in keep},
            self.gap_ends & keep,
        )

    # -- the parallel case ---------------------------------------------------------------
    def plane_indices(self, axis: int) -> NDArray[np.float64]:
        """Each plane's (possibly fractional) index along grid ``axis``, ndarray of shape (P,)."""
        inverse = np.linalg.inv(self.affine)
        origins = np.array([p.pose.affine[:3, 3] for p in self.planes]).reshape(-1, 3)
        return (origins @ inverse[:3, :3].T + inverse[:3, 3])[:, axis]

    def main_axis(self) -> int:
        """The grid axis most planes are slices of (on the grid's voxels, :meth:`grid_shift`).

        Raises
        ------
        GeometryError
            No plane is a slice of the grid.
        """
        counts = [0, 0, 0]
        for plane in self.planes:
            axis = self._axis_of(plane.pose)
            if axis is not None and self.grid_shift(plane.pose, axis) is not None:
                counts[axis] += 1
        if not any(counts):
            raise GeometryError("no annotated plane is a slice of the grid")
        return int(np.argmax(counts))

    def axis_of(self, pose: PlanePose) -> int | None:
        """The grid axis a plane is perpendicular to, or None (an oblique plane)."""
        return self._axis_of(pose)

    @cached_property
    def _slice_normals(self) -> NDArray[np.float64]:
        """The unit normals of the grid's slices, one row per axis, shape (3, 3)."""
        rows = []
        for axis in range(3):
            a, b = in_plane_axes(axis)
            normal = np.cross(self.affine[:3, a], self.affine[:3, b])
            rows.append(normal / np.linalg.norm(normal))
        return np.array(rows)

    def _axis_of(self, pose: PlanePose) -> int | None:
        # sine of the angle between the normals (asked thousands of times per case: the
        # cross products took 3 s of 23 for 20 structures)
        cosines = np.abs(self._slice_normals @ pose.normal)
        sines = np.sqrt(np.clip(1.0 - cosines**2, 0.0, None))
        for axis in range(3):
            if sines[axis] < ANGLE_TOLERANCE:
                return axis
        return None

    def cross_sections(self, value: int | None = None, *, axis: int | None = None) -> CrossSections:
        """A structure's planes as cross-sections on the reference grid.

        Parameters
        ----------
        value : int, optional
            The structure (default: every structure together, their union).
        axis : int, optional
            Only the slices of this grid axis, on the grid's voxels (a plane
            parallel to them on another input's pixels is left out); default:
            every plane, which must then all be slices of one axis.

        Returns
        -------
        CrossSections
            The planes that annotate the structure, empty ones included, in
            increasing position along the grid axis they are perpendicular to.

        Raises
        ------
        GeometryError
            The planes are not all perpendicular to one grid axis on the
            reference grid's pixels.
        """
        if axis is None:
            axis = self.grid_axis()
            if axis is None:
                raise GeometryError(
                    "the annotated planes are not all perpendicular to one axis of the grid"
                )
        chosen = [
            n
            for n, p in enumerate(self.planes)
            if (value is None or p.annotates(value))
            and self._axis_of(p.pose) == axis
            and self.grid_shift(p.pose, axis) is not None
        ]
        planes = tuple(self.planes[n] for n in chosen)
        indices = self.plane_indices(axis)[chosen]
        order = np.argsort(indices, kind="stable")
        a, b = in_plane_axes(axis)
        masks = np.zeros((len(planes), self.grid_shape[a], self.grid_shape[b]), dtype=bool)
        for row, n in enumerate(order):
            masks[row] = self.grid_mask(planes[int(n)], value, axis)
        return CrossSections(masks, indices[order], axis, self.affine, self.grid_shape)

    def grid_mask(self, plane: AnnotatedPlane, value: int | None, axis: int) -> NDArray[np.bool_]:
        """A slice's pixels of structure ``value`` (None: every structure) on the grid's voxels.

        Returns
        -------
        ndarray of shape (grid_shape[a], grid_shape[b]), bool
            ``a, b`` the in-plane axes of ``axis``; background where the plane
            does not reach.

        Raises
        ------
        GeometryError
            The plane is not a slice of grid ``axis`` on the grid's voxels.
        """
        shift = self.grid_shift(plane.pose, axis) if self._axis_of(plane.pose) == axis else None
        if shift is None:
            raise GeometryError(f"the plane is not a slice of the grid's {AXIS_NAMES[axis]} axis")
        a, b = in_plane_axes(axis)
        size = np.array([self.grid_shape[a], self.grid_shape[b]])
        if value is not None:
            return window(plane.mask(value), -shift, size - shift)
        out = np.zeros(tuple(size), dtype=bool)
        for mask in plane.masks.values():
            out |= window(mask, -shift, size - shift)
        return out

    def describe(self) -> str:
        """One line: how many planes, which orientations, their spacing."""
        parts = []
        groups = self.orientations()
        if len(groups) > MAX_ORIENTATIONS_LISTED:  # a radial set: one plane per orientation
            return f"{len(self.planes)} planes in {len(groups)} orientations"
        for normal, members in groups:
            offsets = np.sort([self.planes[n].pose.offset_mm for n in members])
            gaps = np.diff(offsets)
            spacing = f", spacing {np.median(gaps):.3g} mm" if gaps.size else ""
            if gaps.size and np.ptp(gaps) > max(0.1 * np.median(gaps), 0.05):
                spacing += ", irregular"  # 2, 2, 5 mm: not the median alone
            axis = self._axis_of(self.planes[members[0]].pose)
            towards = "normal (" + ", ".join(f"{c:.2f}" for c in normal + 0.0) + ")"
            if axis is None:
                where = towards
            elif np.max(np.abs(normal)) > 1 - ANGLE_TOLERANCE:  # a world axis: name it
                where = f"along {AXIS_NAMES[int(np.argmax(np.abs(normal)))]}"
            else:  # a grid axis that is no world axis (a grid built on oblique planes)
                where = f"along the grid's {AXIS_NAMES[axis]}, {towards}"
            parts.append(f"{len(members)} plane{'s' * (len(members) != 1)} {where}{spacing}")
        return "; ".join(parts) if parts else "no plane"

    def describe_fewer(self, limit: int = 3) -> str:
        """The structures drawn on fewer of the planes than the annotation holds, in words
        (``"; GTV on 5 of them, spacing 3 mm"``), or ``""`` when each is on every plane.

        For inputs whose structures are drawn each on planes of their own (RTSTRUCT
        ROIs): :meth:`describe` counts the planes of all of them. At most ``limit``
        structures are named, then how many more.
        """
        total = len(self.planes)
        fewer = []
        for structure in self.structures:
            planes = self.planes_of(structure.value)
            if 0 < len(planes) < total:
                offsets = np.sort([p.pose.offset_mm for p in planes])
                orientations = {tuple(np.round(p.pose.normal, 3)) for p in planes}
                gaps = np.diff(offsets) if len(orientations) == 1 else np.empty(0)
                spacing = f", spacing {np.median(gaps):.3g} mm" if gaps.size else ""
                name = structure.name or str(structure.value)
                fewer.append(f"{name} on {len(planes)} of them{spacing}")
        if not fewer:
            return ""
        more = f" and {len(fewer) - limit} more on fewer" if len(fewer) > limit else ""
        return "; " + ", ".join(fewer[:limit]) + more


def smallest_gap(positions: ArrayLike, tolerance: float = 1e-3) -> float | None:
    """The smallest gap between planes at ``positions`` along their normal.

    Parameters
    ----------
    positions : array_like of float
        Plane positions (mm, or grid index units), in any order.
    tolerance : float
        Gaps at most this are one plane, not a gap.

    Returns
    -------
    float or None
        None for fewer than two distinct planes.
    """
    gaps = np.diff(np.sort(np.asarray(positions, dtype=np.float64).ravel()))
    gaps = gaps[gaps > tolerance]
    return float(gaps.min()) if gaps.size else None


def window(mask: NDArray[Any], lo: ArrayLike, hi: ArrayLike) -> NDArray[Any]:
    """``mask[lo[0]:hi[0], lo[1]:hi[1], ...]``, zero where the window leaves the array.

    Parameters
    ----------
    mask : ndarray of shape (M, N) or (M, N, K), any dtype
    lo, hi : array-like of ``mask.ndim`` int
        The window's first and one-past-last index along each axis (may lie
        outside the array).

    Returns
    -------
    ndarray of shape ``hi - lo``, ``mask``'s dtype
    """
    lo = np.asarray(lo, dtype=np.int64)
    hi = np.asarray(hi, dtype=np.int64)
    out = np.zeros(tuple(int(v) for v in hi - lo), dtype=mask.dtype)
    src_lo = np.maximum(lo, 0)
    src_hi = np.minimum(hi, mask.shape)
    if np.all(src_hi > src_lo):
        dst = src_lo - lo
        out[tuple(slice(d, d + h - s) for d, s, h in zip(dst, src_lo, src_hi, strict=True))] = mask[
            tuple(slice(s, h) for s, h in zip(src_lo, src_hi, strict=True))
        ]
    return out


def plane_pose(affine: ArrayLike, shape: Sequence[int], axis: int, index: float) -> PlanePose:
    """The pose of the plane at (fractional) ``index`` along grid ``axis``.

    Its pixels are the grid's voxels along the two other axes, in increasing
    axis order (the layout of :class:`~slicerecon.sections.CrossSections`);
    the normal points along increasing ``axis``.
    """
    aff = np.asarray(affine, dtype=np.float64)
    a, b = in_plane_axes(axis)
    normal = np.cross(aff[:3, a], aff[:3, b])
    normal /= np.linalg.norm(normal)
    if np.dot(normal, aff[:3, axis]) < 0:
        normal = -normal
    ijk = np.zeros(3)
    ijk[axis] = index
    pose = np.eye(4)
    pose[:3, 0] = aff[:3, a]
    pose[:3, 1] = aff[:3, b]
    pose[:3, 2] = normal
    pose[:3, 3] = aff[:3, :3] @ ijk + aff[:3, 3]
    return PlanePose(pose, (int(shape[a]), int(shape[b])))


def annotation_from_sections(
    structures: Sequence[Structure],
    sections: Sequence[CrossSections | None],
    *,
    shared: bool,
    coordinates: str = "RAS",
    exclusive: bool = True,
    source: str = "",
) -> Annotation:
    """An annotation made of each structure's cross-sections on one grid.

    Parameters
    ----------
    structures : sequence of Structure
    sections : sequence of CrossSections or None
        Each structure's planes (None: it was annotated nowhere); all on the
        same grid and axis.
    shared : bool
        True when every plane annotates every structure (a label map's
        planes); False when each structure is drawn on its own planes (the
        ROIs of an RTSTRUCT), so a plane annotates the structures whose
        sections hold it.
    coordinates, exclusive, source
        As :class:`Annotation`.

    Raises
    ------
    GeometryError
        Sections on different grids or axes.
    """
    given = [s for s in sections if s is not None]
    if not given:
        raise InputError("no structure has an annotated plane")
    first = given[0]
    for other in given[1:]:
        if (
            other.axis != first.axis
            or other.grid_shape != first.grid_shape
            or not np.allclose(other.affine, first.affine)
        ):
            raise GeometryError("every structure's sections must lie on one grid and axis")
    by_index: dict[float, tuple[dict[int, NDArray[np.bool_]], set[int]]] = {}
    for structure, own in zip(structures, sections, strict=True):
        if own is None:
            continue
        for plane, index in enumerate(own.indices):
            key = round(float(index), 6)
            masks, annotated = by_index.setdefault(key, ({}, set()))
            masks[structure.value] = own.masks[plane]
            annotated.add(structure.value)
    planes = tuple(
        AnnotatedPlane(
            plane_pose(first.affine, first.grid_shape, first.axis, index),
            masks,
            None if shared else frozenset(annotated),
        )
        for index, (masks, annotated) in sorted(by_index.items())
    )
    return Annotation(
        planes,
        tuple(structures),
        first.affine,
        first.grid_shape,
        coordinates,
        exclusive,
        source,
    )
