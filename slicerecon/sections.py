"""The data model: volumes, parallel cross-sections and orthographic projections.

Axis order is declared once, here. A voxel grid has array axes ``(0, 1, 2)``,
named ``("x", "y", "z")`` after the NIfTI index axes ``(i, j, k)``. A 4×4
``affine`` maps a voxel index ``(i, j, k, 1)`` to world millimetres
``(x, y, z, 1)``, exactly as in NIfTI (RAS+ for NIfTI files, LPS for DICOM
files; slicerecon never flips axes on its own, so meshes written in world mm
overlay their source image).

Cross-sections are planes perpendicular to one grid axis. In-plane images keep
the two remaining grid axes in increasing order, so a plane perpendicular to
``z`` is an ``(x, y)`` image. Plane positions are stored as (possibly
fractional) index coordinates along the axis; their world positions along the
plane normal follow from the affine. Spacing between planes need not be uniform.

Every object here is a frozen dataclass whose arrays are read-only: they can be
shared between threads and tasks without copies.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import EmptyMaskError, GeometryError, InputError, OptionError

__all__ = [
    "AXIS_NAMES",
    "axis_index",
    "in_plane_axes",
    "crop_affine",
    "line_ends",
    "world_bounds",
    "Volume",
    "Box",
    "Contour",
    "CrossSections",
    "Projection",
    "Projections",
]

AXIS_NAMES: tuple[str, str, str] = ("x", "y", "z")
"""Names of the grid axes 0, 1, 2 (voxel index axes i, j, k)."""


def axis_index(axis: int | str) -> int:
    """Return the grid axis number ``0, 1, 2`` for ``axis`` given as a number or name.

    Parameters
    ----------
    axis : int or {"x", "y", "z"}
        Axis number or name. Negative numbers count from the end (``-1`` is z).

    Returns
    -------
    int
        The axis number in ``{0, 1, 2}``.
    """
    if isinstance(axis, str):
        name = axis.strip().lower()
        if name not in AXIS_NAMES:
            raise OptionError(f"axis must be one of x, y, z (got {axis!r})")
        return AXIS_NAMES.index(name)
    if isinstance(axis, bool) or not isinstance(axis, int | np.integer):
        raise OptionError(f"axis must be 0, 1, 2 or x, y, z (got {axis!r})")
    if not -3 <= int(axis) <= 2:
        raise OptionError(f"axis must be 0, 1, 2 or x, y, z (got {axis})")
    return int(axis) % 3


def in_plane_axes(axis: int) -> tuple[int, int]:
    """Return the two grid axes spanning a plane perpendicular to ``axis``, increasing."""
    a, b = (ax for ax in range(3) if ax != axis)
    return a, b


def _readonly(array: ArrayLike, dtype: type | np.dtype | None = None) -> NDArray:
    out = np.array(array, dtype=dtype, copy=True)
    out.setflags(write=False)
    return out


def check_affine(affine: ArrayLike) -> NDArray[np.float64]:
    """A read-only float copy of a voxel→world affine, or GeometryError (not 4×4,
    non-finite, last row not ``[0, 0, 0, 1]``, singular)."""
    aff = np.asarray(affine, dtype=np.float64)
    if aff.shape != (4, 4):
        raise GeometryError(f"affine must be a 4x4 matrix (got shape {aff.shape})")
    if not np.all(np.isfinite(aff)):
        raise GeometryError("affine holds NaN or infinite values")
    if not np.allclose(aff[3], [0.0, 0.0, 0.0, 1.0]):
        raise GeometryError(f"affine's last row must be [0, 0, 0, 1] (got {aff[3].tolist()})")
    if abs(np.linalg.det(aff[:3, :3])) < 1e-12:
        raise GeometryError("affine is singular: a voxel axis has zero length or axes coincide")
    return _readonly(aff, np.float64)


def crop_affine(affine: NDArray[np.float64], lo: ArrayLike) -> NDArray[np.float64]:
    """The affine (4, 4) of a grid whose first voxel is voxel ``lo`` (3 indices, any
    sign) of the grid of ``affine``: the same voxel axes, the origin moved."""
    moved = np.array(affine, dtype=np.float64)
    moved[:3, 3] = moved[:3, :3] @ np.asarray(lo, dtype=np.float64) + moved[:3, 3]
    return moved


def world_bounds(
    mask: NDArray[np.bool_], affine: NDArray[np.float64], first: ArrayLike = (0, 0, 0)
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """World-axis-aligned bounds ``(min, max)``, mm, of the centres of a mask's foreground
    voxels, ``mask`` being the box of the grid of ``affine`` that starts at voxel
    ``first``. Exact on an oblique grid too: there the corners of the voxels' index box
    reach beyond the voxels (19 mm on a liver of a grid turned 20°), so each column's
    first and last voxel is taken (a world coordinate is linear along a column).

    Raises
    ------
    EmptyMaskError
        The mask holds no foreground.
    """
    ends = line_ends(mask)
    if not ends.size:
        raise EmptyMaskError("the mask is empty: it has no bounds")
    ijk = ends + np.asarray(first, dtype=np.float64)
    world = ijk @ np.asarray(affine)[:3, :3].T + np.asarray(affine)[:3, 3]
    return world.min(axis=0), world.max(axis=0)


def line_ends(mask: NDArray[np.bool_]) -> NDArray[np.int64]:
    """The indices, shape (2 N, mask.ndim), of the first and last foreground element of
    each of the N lines along the mask's last axis that hold any: where a function
    linear in the indices is least and greatest over the foreground (the bounds of
    :func:`world_bounds`, a plane's reach along a normal)."""
    lines = np.nonzero(mask.any(axis=-1))
    held = mask[lines]
    top = held.shape[-1] - 1
    last = np.concatenate([held.argmax(axis=-1), top - held[:, ::-1].argmax(axis=-1)])
    return np.column_stack([*(np.tile(index, 2) for index in lines), last])


def _spacing(affine: NDArray[np.float64]) -> NDArray[np.float64]:
    return np.linalg.norm(affine[:3, :3], axis=0)


def _apply(affine: NDArray[np.float64], points: ArrayLike) -> NDArray[np.float64]:
    pts = np.asarray(points, dtype=np.float64)
    if pts.shape[-1] != 3:
        raise OptionError(f"points must have 3 coordinates in the last axis (got {pts.shape})")
    return pts @ affine[:3, :3].T + affine[:3, 3]


def _as_mask(mask: ArrayLike, ndim: int, what: str) -> NDArray[np.bool_]:
    arr = np.asarray(mask)
    if arr.ndim != ndim:
        raise InputError(f"{what} must be a {ndim}-D array (got {arr.ndim}-D, shape {arr.shape})")
    if arr.dtype != np.bool_:
        if arr.dtype.kind not in "biuf":
            raise InputError(f"{what} must be boolean or numeric (got dtype {arr.dtype})")
        values = np.unique(arr)
        if not np.all(np.isin(values, (0, 1))):
            shown = ", ".join(str(v) for v in values[:8])
            raise InputError(
                f"{what} must be binary (0/1); found values {shown}"
                f"{' ...' if values.size > 8 else ''}. Pick one label first."
            )
        arr = arr.astype(bool)
    if 0 in arr.shape:
        raise InputError(f"{what} has an empty dimension (shape {arr.shape})")
    return _readonly(arr, np.bool_)


@dataclass(frozen=True, eq=False)
class Volume:
    """A binary mask on a voxel grid, with its geometry.

    Parameters
    ----------
    mask : ndarray of shape (I, J, K), bool
        Foreground voxels. A 0/1 numeric array is accepted and converted.
    affine : ndarray of shape (4, 4)
        Voxel index ``(i, j, k, 1)`` → world millimetres ``(x, y, z, 1)``.
        Columns may be scaled (anisotropic voxels) and rotated (oblique grids).

    Notes
    -----
    Arrays are copied on construction and stored read-only.
    """

    mask: NDArray[np.bool_]
    affine: NDArray[np.float64] = field(default_factory=lambda: np.eye(4))

    def __post_init__(self) -> None:
        object.__setattr__(self, "mask", _as_mask(self.mask, 3, "volume mask"))
        object.__setattr__(self, "affine", check_affine(self.affine))

    # -- geometry -----------------------------------------------------------------
    @property
    def shape(self) -> tuple[int, int, int]:
        """Grid shape ``(I, J, K)`` in voxels."""
        i, j, k = self.mask.shape
        return i, j, k

    @property
    def spacing(self) -> NDArray[np.float64]:
        """Voxel size along the grid axes, mm, ndarray of shape (3,)."""
        return _spacing(self.affine)

    @property
    def voxel_volume(self) -> float:
        """Volume of one voxel, mm³."""
        return float(abs(np.linalg.det(self.affine[:3, :3])))

    @property
    def volume_mm3(self) -> float:
        """Foreground volume (voxel count × voxel volume), mm³."""
        return float(np.count_nonzero(self.mask)) * self.voxel_volume

    @property
    def is_empty(self) -> bool:
        """True when no voxel is foreground."""
        return not bool(self.mask.any())

    @property
    def is_oblique(self) -> bool:
        """True when the grid axes are not aligned with the world axes."""
        directions = np.abs(self.affine[:3, :3] / self.spacing)
        return not np.allclose(directions.max(axis=0), 1.0, atol=1e-6)

    def index_to_world(self, ijk: ArrayLike) -> NDArray[np.float64]:
        """Map voxel indices, ndarray of shape (..., 3), to world mm, same shape."""
        return _apply(self.affine, ijk)

    def world_to_index(self, xyz: ArrayLike) -> NDArray[np.float64]:
        """Map world mm, ndarray of shape (..., 3), to fractional voxel indices."""
        return _apply(np.linalg.inv(self.affine).astype(np.float64), xyz)

    def bounding_box_vox(self) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """Index bounds ``(lo, hi)`` of the foreground, ``hi`` exclusive.

        Raises
        ------
        EmptyMaskError
            If the mask is empty.
        """
        if self.is_empty:
            raise EmptyMaskError("the mask is empty: no foreground voxel")
        lo = np.empty(3, dtype=np.int64)
        hi = np.empty(3, dtype=np.int64)
        for ax in range(3):
            other = tuple(a for a in range(3) if a != ax)
            occupied = np.flatnonzero(self.mask.any(axis=other))
            lo[ax], hi[ax] = occupied[0], occupied[-1] + 1
        return lo, hi

    def bounding_box_mm(self) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
        """World-axis-aligned bounds ``(min, max)`` of the foreground voxel centres, mm
        (:func:`world_bounds`)."""
        lo, hi = self.bounding_box_vox()
        box = self.mask[lo[0] : hi[0], lo[1] : hi[1], lo[2] : hi[2]]
        return world_bounds(box, self.affine, lo)

    def occupied_planes(self, axis: int | str = 2) -> NDArray[np.int64]:
        """Indices of the planes perpendicular to ``axis`` that hold foreground."""
        ax = axis_index(axis)
        other = in_plane_axes(ax)
        return np.flatnonzero(self.mask.any(axis=other)).astype(np.int64)

    # -- derived volumes ---------------------------------------------------------
    def with_mask(self, mask: ArrayLike) -> Volume:
        """Return a volume with the same geometry and another mask of the same shape."""
        new = Volume(np.asarray(mask), self.affine)
        if new.shape != self.shape:
            raise InputError(f"mask shape {new.shape} differs from the volume's {self.shape}")
        return new

    def crop(self, pad: int = 1) -> Volume:
        """Crop to the foreground bounding box plus ``pad`` voxels (clipped to the grid).

        The affine is shifted so that every kept voxel keeps its world position.
        """
        if pad < 0:
            raise OptionError(f"pad must be >= 0 (got {pad})")
        lo, hi = self.bounding_box_vox()
        lo = np.maximum(lo - pad, 0)
        hi = np.minimum(hi + pad, self.shape)
        return self.subgrid(lo, hi)

    def subgrid(self, lo: ArrayLike, hi: ArrayLike) -> Volume:
        """Return the sub-volume ``mask[lo:hi]`` (indices, ``hi`` exclusive) with its affine."""
        lo_i = np.asarray(lo, dtype=np.int64)
        hi_i = np.asarray(hi, dtype=np.int64)
        sub = self.mask[lo_i[0] : hi_i[0], lo_i[1] : hi_i[1], lo_i[2] : hi_i[2]]
        affine = self.affine.copy()
        affine[:3, 3] = self.index_to_world(lo_i.astype(np.float64))
        return Volume(sub, affine)

    def pad(self, width: int) -> Volume:
        """Pad the grid with ``width`` background voxels on every side, geometry kept."""
        if width < 0:
            raise OptionError(f"width must be >= 0 (got {width})")
        mask = np.pad(self.mask, width)
        affine = self.affine.copy()
        affine[:3, 3] = self.index_to_world(np.full(3, -float(width)))
        return Volume(mask, affine)

    def __repr__(self) -> str:
        sp = ", ".join(f"{s:.3g}" for s in self.spacing)
        return (
            f"Volume(shape={self.shape}, spacing=({sp}) mm, "
            f"foreground={int(np.count_nonzero(self.mask))} voxels)"
        )


@dataclass(frozen=True)
class Box:
    """An axis-aligned cuboid of voxels on a grid: ``mask[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]]``.

    Parameters
    ----------
    lo : tuple of int
        First voxel index along x, y, z (inclusive).
    hi : tuple of int
        One past the last voxel index along x, y, z (exclusive).

    Notes
    -----
    Voxel centres sit at integer indices, so in continuous index coordinates
    the box spans ``[lo - 0.5, hi - 0.5]`` along each axis.
    """

    lo: tuple[int, int, int]
    hi: tuple[int, int, int]

    def __post_init__(self) -> None:
        lo = tuple(int(v) for v in self.lo)
        hi = tuple(int(v) for v in self.hi)
        if len(lo) != 3 or len(hi) != 3:
            raise GeometryError(f"a box needs 3 lower and 3 upper bounds (got {lo}, {hi})")
        if any(h <= low for low, h in zip(lo, hi, strict=True)):
            raise GeometryError(f"box upper bounds must exceed lower bounds (got {lo}, {hi})")
        object.__setattr__(self, "lo", lo)
        object.__setattr__(self, "hi", hi)

    @classmethod
    def of_mask(cls, mask: ArrayLike) -> Box:
        """The tightest box around the foreground of a 3-D mask."""
        lo, hi = Volume(np.asarray(mask)).bounding_box_vox()
        return cls(tuple(lo), tuple(hi))  # type: ignore[arg-type]

    @property
    def shape(self) -> tuple[int, int, int]:
        """Box size in voxels along x, y, z."""
        a, b, c = (h - low for low, h in zip(self.lo, self.hi, strict=True))
        return a, b, c

    @property
    def n_voxels(self) -> int:
        """Number of voxels inside the box."""
        return int(np.prod(self.shape))

    @property
    def slices(self) -> tuple[slice, slice, slice]:
        """Index slices selecting the box from a grid-shaped array."""
        a, b, c = (slice(low, h) for low, h in zip(self.lo, self.hi, strict=True))
        return a, b, c

    def intersect(self, other: Box) -> Box | None:
        """The common box of two boxes, or None when they do not overlap."""
        lo = tuple(max(a, b) for a, b in zip(self.lo, other.lo, strict=True))
        hi = tuple(min(a, b) for a, b in zip(self.hi, other.hi, strict=True))
        if any(h <= low for low, h in zip(lo, hi, strict=True)):
            return None
        return Box(lo, hi)  # type: ignore[arg-type]

    def contains_index(self, ijk: ArrayLike) -> NDArray[np.bool_]:
        """Whether (possibly fractional) indices, ndarray of shape (..., 3), lie in the box."""
        pts = np.asarray(ijk, dtype=np.float64)
        lo = np.asarray(self.lo) - 0.5
        hi = np.asarray(self.hi) - 0.5
        return np.all((pts >= lo) & (pts <= hi), axis=-1)

    def to_dict(self) -> dict[str, list[int]]:
        """JSON-ready form ``{"lo": [...], "hi": [...]}`` (voxel indices, hi exclusive)."""
        return {"lo": list(self.lo), "hi": list(self.hi)}


class Contour(NamedTuple):
    """One closed polygon on a plane.

    Attributes
    ----------
    points_px : ndarray of shape (N, 2)
        Vertices in in-plane index coordinates (the plane's two grid axes, in
        increasing axis order), not repeating the first vertex at the end.
    is_hole : bool
        True when the polygon bounds a hole (its inside is background).
    """

    points_px: NDArray[np.float64]
    is_hole: bool


@dataclass(frozen=True, eq=False)
class CrossSections:
    """Binary masks on parallel planes perpendicular to one grid axis.

    Parameters
    ----------
    masks : ndarray of shape (P, M, N), bool
        One in-plane mask per plane. ``(M, N)`` are the sizes of the grid axes
        other than ``axis``, in increasing axis order.
    indices : ndarray of shape (P,)
        Plane positions as index coordinates along ``axis`` of the reference
        grid; strictly increasing, possibly fractional and non-uniform.
    axis : int
        Grid axis the planes are perpendicular to (0, 1 or 2).
    affine : ndarray of shape (4, 4)
        Voxel→world affine of the reference grid, mm.
    grid_shape : tuple of int
        Shape ``(I, J, K)`` of the reference grid. Along ``axis`` it bounds the
        region a reconstruction is made on.
    """

    masks: NDArray[np.bool_]
    indices: NDArray[np.float64]
    axis: int
    affine: NDArray[np.float64]
    grid_shape: tuple[int, int, int]

    def __post_init__(self) -> None:
        axis = axis_index(self.axis)
        object.__setattr__(self, "axis", axis)
        masks = _as_mask(self.masks, 3, "cross-section masks")
        object.__setattr__(self, "masks", masks)
        indices = np.asarray(self.indices, dtype=np.float64).reshape(-1)
        if indices.shape[0] != masks.shape[0]:
            raise GeometryError(
                f"{masks.shape[0]} plane masks but {indices.shape[0]} plane positions"
            )
        if not np.all(np.isfinite(indices)):
            raise GeometryError("plane positions hold NaN or infinite values")
        if indices.size > 1 and np.any(np.diff(indices) <= 0):
            raise GeometryError("plane positions must be strictly increasing (duplicate planes?)")
        object.__setattr__(self, "indices", _readonly(indices, np.float64))
        object.__setattr__(self, "affine", check_affine(self.affine))
        shape = tuple(int(s) for s in self.grid_shape)
        if len(shape) != 3 or min(shape) < 1:
            raise GeometryError(f"grid_shape must be three positive sizes (got {self.grid_shape})")
        object.__setattr__(self, "grid_shape", shape)
        a, b = in_plane_axes(axis)
        if masks.shape[1:] != (shape[a], shape[b]):
            raise GeometryError(
                f"in-plane mask shape {masks.shape[1:]} does not match grid axes "
                f"{AXIS_NAMES[a]}, {AXIS_NAMES[b]} of shape {(shape[a], shape[b])}"
            )

    # -- geometry -----------------------------------------------------------------
    @property
    def n_planes(self) -> int:
        """Number of planes ``P``."""
        return int(self.masks.shape[0])

    @property
    def plane_axes(self) -> tuple[int, int]:
        """The two grid axes spanning each plane, increasing."""
        return in_plane_axes(self.axis)

    @property
    def spacing(self) -> NDArray[np.float64]:
        """Reference grid voxel size along axes x, y, z, mm, ndarray of shape (3,)."""
        return _spacing(self.affine)

    @property
    def normal(self) -> NDArray[np.float64]:
        """Unit plane normal in world coordinates (direction of increasing index)."""
        a, b = self.plane_axes
        n = np.cross(self.affine[:3, a], self.affine[:3, b])
        n /= np.linalg.norm(n)
        if np.dot(n, self.affine[:3, self.axis]) < 0:
            n = -n
        return n

    @property
    def positions(self) -> NDArray[np.float64]:
        """Plane positions along :attr:`normal`, world mm, ndarray of shape (P,)."""
        ijk = np.zeros((self.n_planes, 3))
        ijk[:, self.axis] = self.indices
        return _apply(self.affine, ijk) @ self.normal

    @property
    def gaps(self) -> NDArray[np.float64]:
        """Distances between consecutive planes, mm, ndarray of shape (P - 1,)."""
        return np.diff(self.positions)

    @property
    def is_on_grid(self) -> bool:
        """True when every plane lies on an integer index of the reference grid."""
        return bool(np.allclose(self.indices, np.round(self.indices), atol=1e-6))

    def planes_in(self, box: Box, *, bridge: bool = False) -> NDArray[np.int64]:
        """Indices of the planes inside ``box`` along the section axis.

        The box spans ``[lo - 0.5, hi - 0.5]`` in continuous index coordinates;
        planes on its faces count as inside.

        Parameters
        ----------
        box : Box
            A box on the reference grid.
        bridge : bool, default False
            When the box holds no plane, return the nearest plane on either
            side of it instead (none when it lies beyond the first or last
            plane): the slab that crosses the box.

        Returns
        -------
        ndarray of shape (n,), int64
            Increasing plane indices.
        """
        w = self.indices
        lo, hi = box.lo[self.axis] - 0.5, box.hi[self.axis] - 0.5
        inside = np.flatnonzero((w >= lo - 1e-9) & (w <= hi + 1e-9))
        if inside.size or not bridge:
            return inside.astype(np.int64)
        below, above = np.flatnonzero(w < lo), np.flatnonzero(w > hi)
        if below.size == 0 or above.size == 0:
            return np.zeros(0, dtype=np.int64)
        return np.array([below[-1], above[0]], dtype=np.int64)

    def plane_to_world(self, plane: int, points_px: ArrayLike) -> NDArray[np.float64]:
        """Map in-plane index coordinates on plane ``plane`` to world mm.

        Parameters
        ----------
        plane : int
            Plane number in ``[0, P)``.
        points_px : ndarray of shape (N, 2)
            In-plane coordinates along :attr:`plane_axes`.

        Returns
        -------
        ndarray of shape (N, 3)
        """
        pts = np.asarray(points_px, dtype=np.float64).reshape(-1, 2)
        ijk = np.empty((pts.shape[0], 3))
        a, b = self.plane_axes
        ijk[:, a] = pts[:, 0]
        ijk[:, b] = pts[:, 1]
        ijk[:, self.axis] = self.indices[plane]
        return _apply(self.affine, ijk)

    def area_mm2(self, plane: int) -> float:
        """Foreground area of one plane, mm²."""
        a, b = self.plane_axes
        pixel = float(np.linalg.norm(np.cross(self.affine[:3, a], self.affine[:3, b])))
        return float(np.count_nonzero(self.masks[plane])) * pixel

    def contours(self, plane: int) -> list[Contour]:
        """Closed polygons bounding the foreground of one plane.

        Contours follow pixel centres at the 0.5 iso-level of the mask
        (:func:`skimage.measure.find_contours` on a zero-padded copy, so every
        polygon is closed). Outer boundaries are counter-clockwise and holes
        clockwise in ``(row, column)`` coordinates.

        Returns
        -------
        list of Contour
        """
        from skimage.measure import find_contours

        if not 0 <= plane < self.n_planes:
            raise OptionError(f"plane must be in [0, {self.n_planes}) (got {plane})")
        padded = np.pad(self.masks[plane].astype(np.float64), 1)
        out: list[Contour] = []
        for poly in find_contours(padded, 0.5, positive_orientation="high"):
            pts = poly[:-1] if np.allclose(poly[0], poly[-1]) else poly
            if pts.shape[0] < 3:
                continue
            pts = pts - 1.0
            x, y = pts[:, 0], pts[:, 1]
            signed_area = 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))
            # With positive_orientation="high", outer boundaries wind counter-clockwise
            # (positive area) around the foreground and hole boundaries clockwise.
            out.append(Contour(np.ascontiguousarray(pts), signed_area < 0))
        return out

    # -- conversions -------------------------------------------------------------
    def to_volume(self) -> Volume:
        """Put the planes back into an otherwise empty mask on the reference grid.

        Raises
        ------
        GeometryError
            If a plane lies between grid indices (see :attr:`is_on_grid`) or
            outside the grid.
        """
        if not self.is_on_grid:
            raise GeometryError("planes lie between grid indices; resample them first")
        idx = np.round(self.indices).astype(np.int64)
        if idx.min() < 0 or idx.max() >= self.grid_shape[self.axis]:
            raise GeometryError("a plane lies outside the reference grid")
        mask = np.zeros(self.grid_shape, dtype=bool)
        view = np.moveaxis(mask, self.axis, 0)
        view[idx] = self.masks
        return Volume(mask, self.affine)

    def select(self, planes: Sequence[int] | NDArray[np.integer]) -> CrossSections:
        """Return the sub-set of planes ``planes`` (numbers in ``[0, P)``), in order."""
        sel = np.unique(np.asarray(planes, dtype=np.int64))
        if sel.size == 0:
            raise OptionError("select at least one plane")
        if sel.min() < 0 or sel.max() >= self.n_planes:
            raise OptionError(f"plane numbers must be in [0, {self.n_planes})")
        return CrossSections(
            self.masks[sel], self.indices[sel], self.axis, self.affine, self.grid_shape
        )

    def require_foreground(self) -> None:
        """Raise :class:`EmptyMaskError` if no plane holds any foreground."""
        if not self.masks.any():
            raise EmptyMaskError("the cross-sections hold no foreground on any plane")

    def __repr__(self) -> str:
        return (
            f"CrossSections(planes={self.n_planes}, axis={AXIS_NAMES[self.axis]}, "
            f"in-plane={self.masks.shape[1:]}, grid={self.grid_shape})"
        )


@dataclass(frozen=True, eq=False)
class Projection:
    """An orthographic silhouette of a shape along one grid axis.

    Parameters
    ----------
    image : ndarray of shape (M, N), bool
        Silhouette. Rows and columns run along the two grid axes other than
        ``axis``, in increasing order (the same layout as a cross-section
        perpendicular to ``axis``).
    axis : int
        The grid axis the shape was projected along (the viewing direction).
    affine : ndarray of shape (4, 4)
        Voxel→world affine of the reference grid, mm.
    """

    image: NDArray[np.bool_]
    axis: int
    affine: NDArray[np.float64]

    def __post_init__(self) -> None:
        object.__setattr__(self, "axis", axis_index(self.axis))
        object.__setattr__(self, "image", _as_mask(self.image, 2, "projection image"))
        object.__setattr__(self, "affine", check_affine(self.affine))

    @property
    def image_axes(self) -> tuple[int, int]:
        """Grid axes along the image rows and columns."""
        return in_plane_axes(self.axis)

    @property
    def pixel_spacing(self) -> NDArray[np.float64]:
        """Pixel size along rows and columns, mm, ndarray of shape (2,)."""
        sp = _spacing(self.affine)
        a, b = self.image_axes
        return np.array([sp[a], sp[b]])

    @property
    def area_mm2(self) -> float:
        """Silhouette area, mm²."""
        return float(np.count_nonzero(self.image)) * float(np.prod(self.pixel_spacing))


@dataclass(frozen=True, eq=False)
class Projections:
    """The three orthographic silhouettes of a shape, one per grid axis.

    Parameters
    ----------
    views : tuple of Projection
        ``views[a]`` is the projection along grid axis ``a`` (x, y, z).
    source : str
        Where the silhouettes came from: ``"volume"`` (a dense mask, the
        paper's prior), ``"sections"`` (derived from the cross-sections alone)
        or ``"file"``.
    """

    views: tuple[Projection, Projection, Projection]
    source: str = "volume"

    def __post_init__(self) -> None:
        views = tuple(self.views)
        if len(views) != 3 or [v.axis for v in views] != [0, 1, 2]:
            raise GeometryError("Projections needs one view along each of x, y, z, in order")
        object.__setattr__(self, "views", views)

    def __getitem__(self, axis: int | str) -> Projection:
        return self.views[axis_index(axis)]

    def __iter__(self):  # type: ignore[no-untyped-def]
        return iter(self.views)

    def __len__(self) -> int:
        return 3
