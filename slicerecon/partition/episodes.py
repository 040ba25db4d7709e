"""What a partition episode of training is made of: a shape, its sections and its hull.

The learned planner is trained on procedural shapes (:mod:`slicerecon.shapes`)
scaled into cubic grids (:func:`shape_occupancy`, :func:`fit_to_cube`,
:class:`ShapePool`). An episode partitions the ground-truth occupancy ``O``
(``docs/method.md``, section 3); its reward reconstructs each part from
cross-sections of ``O`` (:func:`episode_sections`: the library's own
:func:`~slicerecon.sampling.sample_sections`) guided and carved by the visual
hull of ``O``'s projections (:func:`occupancy_hull`), as inference does with
ground-truth projections. Everything here is numpy; the torch environment
(:mod:`slicerecon.policy.env`) only batches it.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import DependencyError, EmptyMaskError, FormatError, InputError, OptionError
from ..io.atomic import atomic_path
from ..sampling import projections_from_volume, sample_sections, visual_hull
from ..sections import Box, CrossSections, Volume
from ..shapes import make_shape

__all__ = [
    "SECTION_AXIS",
    "REAL_PREFIX",
    "ShapePool",
    "fit_to_cube",
    "shape_occupancy",
    "real_occupancy",
    "episode_sections",
    "occupancy_hull",
]

logger = logging.getLogger(__name__)

SECTION_AXIS = 2
"""Grid axis the training episodes' section planes are perpendicular to (z)."""


def _as_occupancy(occupancy: ArrayLike) -> NDArray[np.bool_]:
    occ = np.asarray(occupancy)
    if occ.ndim != 3:
        raise InputError(f"occupancy must be a 3-D array (got shape {occ.shape})")
    occ = occ.astype(bool, copy=False)
    if not occ.any():
        raise EmptyMaskError("the occupancy is empty")
    return occ


def fit_to_cube(mask: ArrayLike, size: int) -> NDArray[np.bool_]:
    """Centre a 3-D mask's foreground in a ``size^3`` grid.

    Parameters
    ----------
    mask : ndarray of shape (I, J, K), bool
    size : int
        Side of the cube, voxels; must hold the foreground's bounding box.

    Returns
    -------
    ndarray of shape (size, size, size), bool
        The foreground, shifted so that its bounding box is centred (rounded down).
    """
    arr = np.asarray(mask, dtype=bool)
    if arr.ndim != 3:
        raise InputError(f"mask must be 3-D (got shape {arr.shape})")
    if not arr.any():
        raise EmptyMaskError("the mask is empty: nothing to place in the grid")
    box = Box.of_mask(arr)
    if max(box.shape) > size:
        raise OptionError(f"the shape's bounding box {box.shape} does not fit a {size}^3 grid")
    out = np.zeros((size, size, size), dtype=bool)
    lo = [(size - s) // 2 for s in box.shape]
    dst = tuple(slice(a, a + s) for a, s in zip(lo, box.shape, strict=True))
    out[dst] = arr[box.slices]
    return out


def shape_occupancy(name: str, *, seed: int, grid: int, margin: int = 1) -> NDArray[np.bool_]:
    """A seeded procedural shape (:func:`slicerecon.shapes.make_shape`) scaled into ``grid^3``.

    The voxel size is chosen so that the shape's longest side spans
    ``grid - 2 * margin`` voxels; the shape is then centred (:func:`fit_to_cube`).

    Parameters
    ----------
    name : str
        A registered shape family (:func:`slicerecon.shapes.shape_names`).
    seed : int
        Seed of the shape's random proportions.
    grid : int
        Side of the cubic grid, voxels.
    margin : int, optional
        Empty voxels kept on each side.

    Returns
    -------
    ndarray of shape (grid, grid, grid), bool
    """

    inner = int(grid) - 2 * int(margin)
    if inner < 4:
        raise OptionError(f"grid {grid} is too small for margin {margin}")
    coarse = make_shape(name, seed=seed, spacing=2.0, margin=0)
    lo, hi = coarse.bounding_box_vox()
    extent_mm = float(np.max((hi - lo) * coarse.spacing))
    spacing = extent_mm / inner
    for _ in range(20):
        vol = make_shape(name, seed=seed, spacing=spacing, margin=0)
        lo, hi = vol.bounding_box_vox()
        if int(np.max(hi - lo)) <= inner:
            return fit_to_cube(vol.mask, int(grid))
        spacing *= 1.03
    raise OptionError(f"could not fit shape {name!r} (seed {seed}) into a {grid}^3 grid")


def real_occupancy(
    name: str,
    *,
    grid: int,
    stretch: Sequence[float] = (1.0, 1.0, 1.0),
    margin: int = 1,
    mesh_resolution: int = 64,
) -> NDArray[np.bool_]:
    """A real shape (:mod:`slicerecon.realshapes`) resampled into ``grid^3``, optionally stretched.

    The shape is loaded from its installed package, its world extent (mm) is
    multiplied by ``stretch`` per grid axis, and it is resampled (Gaussian
    anti-aliasing, linear interpolation, threshold 0.5) onto isotropic voxels
    sized so that the longest stretched side spans ``grid - 2 * margin``
    voxels; then centred (:func:`fit_to_cube`). Anisotropic ``stretch`` is the
    training augmentation "anisotropic rescaling".

    Parameters
    ----------
    name : str
        A registered real shape (:func:`slicerecon.realshapes.real_shape_names`).
    grid : int
        Side of the cubic grid, voxels.
    stretch : sequence of 3 floats, optional
        Scale factor of each axis (> 0).
    margin : int, optional
        Empty voxels kept on each side.
    mesh_resolution : int, optional
        Voxels across a mesh source's longest side before resampling.

    Returns
    -------
    ndarray of shape (grid, grid, grid), bool

    Raises
    ------
    OptionError
        If ``name`` is unknown, ``stretch`` is not 3 positive numbers or the
        grid is too small.
    DependencyError
        If the shape's source package is not installed.
    EmptyMaskError
        If the shape vanishes at this grid size.
    """
    import inspect

    from scipy import ndimage

    from ..realshapes import REAL_SHAPES, real_shape

    factors = np.asarray(stretch, dtype=np.float64)
    if factors.shape != (3,) or not np.all(np.isfinite(factors)) or np.any(factors <= 0):
        raise OptionError(f"stretch must be 3 positive numbers (got {stretch!r})")
    inner = int(grid) - 2 * int(margin)
    if inner < 4:
        raise OptionError(f"grid {grid} is too small for margin {margin}")
    options: dict[str, object] = {}
    loader = getattr(REAL_SHAPES.get(name), "func", REAL_SHAPES.get(name))
    if loader is not None and "resolution" in inspect.signature(loader).parameters:
        options["resolution"] = int(mesh_resolution)
    volume = real_shape(name, **options)
    box = Box.of_mask(volume.mask)
    field = volume.mask[box.slices].astype(np.float32)
    extent_mm = np.asarray(box.shape, dtype=np.float64) * volume.spacing * factors
    voxel = float(extent_mm.max()) / inner
    for _ in range(20):
        new = np.maximum(np.floor(extent_mm / voxel), 1).astype(np.int64)
        zoom = new / np.asarray(field.shape, dtype=np.float64)
        sigma = np.maximum(0.5, (1.0 / zoom - 1.0) / 2.0)
        blurred = ndimage.gaussian_filter(np.pad(field, 2), sigma, mode="constant")
        padded = np.asarray(blurred.shape) * zoom
        out = (
            ndimage.zoom(
                blurred, padded / blurred.shape, order=1, grid_mode=True, mode="grid-constant"
            )
            > 0.5
        )
        if not out.any():
            raise EmptyMaskError(f"real shape {name!r} vanished in a {grid}^3 grid")
        if max(Box.of_mask(out).shape) <= inner:
            return fit_to_cube(out, int(grid))
        voxel *= 1.03
    raise OptionError(f"could not fit real shape {name!r} into a {grid}^3 grid")


REAL_PREFIX = "real:"
"""What a real shape's name starts with in a :class:`ShapePool`."""


@dataclass(frozen=True)
class ShapePool:
    """Occupancy grids training episodes are drawn from.

    Attributes
    ----------
    occupancies : ndarray of shape (N, G, G, G), bool
    names : tuple of str
        Shape family of each grid.
    seeds : tuple of int
        Seed of each grid's proportions.
    """

    occupancies: NDArray[np.bool_]
    names: tuple[str, ...]
    seeds: tuple[int, ...]

    @classmethod
    def build(
        cls,
        names: Sequence[str],
        seeds: Sequence[int],
        *,
        grid: int,
        real: Sequence[str] = (),
        real_variants: int = 1,
        max_stretch: float = 1.5,
    ) -> ShapePool:
        """Every family in ``names`` with every seed in ``seeds``, on a ``grid^3`` cube.

        ``real`` adds real shapes (:func:`real_occupancy`): each as it is and
        ``real_variants - 1`` copies stretched by factors drawn uniformly in
        ``[1, max_stretch]`` per axis (seeded by the variant number, the
        name ``"real:<name>"`` and seed ``k`` for variant ``k``). A real shape
        whose package is missing is skipped with a warning.
        """

        if not seeds or not (names or real):
            raise OptionError("a shape pool needs at least one family and one seed")
        if int(real_variants) < 1 or not float(max_stretch) >= 1.0:
            raise OptionError("real_variants must be >= 1 and max_stretch >= 1")
        grids, out_names, out_seeds = [], [], []
        skipped: set[str] = set()
        for label, seed in cls.listing(names, seeds, real=real, real_variants=real_variants):
            if not label.startswith(REAL_PREFIX):
                grids.append(shape_occupancy(label, seed=seed, grid=grid))
            else:
                name = label[len(REAL_PREFIX) :]
                if name in skipped:
                    continue
                rng = np.random.default_rng(seed)
                stretch = (1.0, 1.0, 1.0) if seed == 0 else rng.uniform(1.0, max_stretch, 3)
                try:
                    grids.append(real_occupancy(name, grid=grid, stretch=stretch))
                except DependencyError as exc:
                    logger.warning("real shape %s skipped: %s", name, exc)
                    skipped.add(name)
                    continue
            out_names.append(label)
            out_seeds.append(seed)
        if not grids:
            raise OptionError("the shape pool is empty (no family and no installed real shape)")
        logger.info("shape pool: %d grids of %d^3", len(grids), grid)
        return cls(np.stack(grids), tuple(out_names), tuple(out_seeds))

    @staticmethod
    def listing(
        names: Sequence[str],
        seeds: Sequence[int],
        *,
        real: Sequence[str] = (),
        real_variants: int = 1,
    ) -> list[tuple[str, int]]:
        """The (name, seed) of every grid :meth:`build` makes when every real shape is installed.

        Each family with each seed, then each real shape's variants ``0 ..
        real_variants - 1`` named ``"real:<name>"`` (:data:`REAL_PREFIX`), in
        :meth:`build`'s order.
        """
        listed = [(str(name), int(seed)) for name in names for seed in seeds]
        listed += [(f"{REAL_PREFIX}{name}", k) for name in real for k in range(int(real_variants))]
        return listed

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write the pool to an ``.npz`` file (bit-packed grids, names, seeds), atomically.

        For training on a machine without the real shapes' packages
        (``slicerecon train --write-pool`` here, ``--pool`` there).

        Returns
        -------
        Path
            ``path``.
        """

        out = Path(path)
        with atomic_path(out) as tmp, open(tmp, "wb") as fh:
            np.savez_compressed(
                fh,
                bits=np.packbits(self.occupancies, axis=None),
                shape=np.asarray(self.occupancies.shape, dtype=np.int64),
                names=np.asarray(self.names, dtype=str),
                seeds=np.asarray(self.seeds, dtype=np.int64),
            )
        return out

    @classmethod
    def load(cls, path: str | os.PathLike[str]) -> ShapePool:
        """Read a pool written by :meth:`save`.

        Raises
        ------
        InputError
            If the file does not exist.
        FormatError
            If it is not such a pool (missing or inconsistent arrays).
        """

        src = Path(path)
        if not src.is_file():
            raise InputError(f"no shape pool file at {src}")
        try:
            with np.load(src, allow_pickle=False) as data:
                shape = tuple(int(n) for n in data["shape"])
                bits, names, seeds = data["bits"], data["names"], data["seeds"]
        except (OSError, KeyError, ValueError, EOFError) as exc:
            raise FormatError(f"{src} is not a shape pool written by slicerecon") from exc
        if (
            len(shape) != 4
            or min(shape) < 1
            or shape[1:] != (shape[1],) * 3
            or bits.size * 8 < int(np.prod(shape))
            or not (len(names) == len(seeds) == shape[0])
        ):
            raise FormatError(f"{src} is a damaged shape pool (its arrays do not fit together)")
        occ = np.unpackbits(bits, count=int(np.prod(shape))).reshape(shape).astype(bool)
        return cls(occ, tuple(str(n) for n in names), tuple(int(k) for k in seeds))

    def __len__(self) -> int:
        return int(self.occupancies.shape[0])

    @property
    def grid(self) -> int:
        """Side ``G`` of the cubic grids."""
        return int(self.occupancies.shape[1])


def episode_sections(occupancy: ArrayLike, n: int) -> CrossSections:
    """The cross-sections of an episode: ``n`` z-planes of the occupancy, evenly spaced.

    :func:`~slicerecon.sampling.sample_sections` with ``n`` planes from the
    first to the last occupied z-plane (as ``slicerecon run --slices n``), on
    the occupancy's own grid (identity affine: 1 mm voxels); fewer planes when
    the occupied range is shorter than ``n``.

    Parameters
    ----------
    occupancy : ndarray of shape (I, J, K), bool
    n : int
        Planes wanted, ``>= 1``.

    Returns
    -------
    CrossSections
        Planes perpendicular to :data:`SECTION_AXIS`; ``indices`` are integers.
    """
    occ = _as_occupancy(occupancy)
    if int(n) < 1:
        raise OptionError(f"an episode needs at least one section plane (got {n})")
    volume = Volume(occ)
    occupied = np.flatnonzero(occ.any(axis=tuple(a for a in range(3) if a != SECTION_AXIS)))
    count = min(int(n), int(occupied[-1] - occupied[0] + 1))
    if count < 2:  # one plane, the first occupied one (a step past the range)
        span = int(occupied[-1] - occupied[0])
        return sample_sections(volume, every=span + 1, axis=SECTION_AXIS)
    return sample_sections(volume, n=count, axis=SECTION_AXIS)


def occupancy_hull(occupancy: ArrayLike) -> NDArray[np.bool_]:
    """The visual hull of an occupancy's own projections (:func:`~slicerecon.sampling.visual_hull`).

    What inference plans on and carves with when it is given ground-truth
    projections; it contains the occupancy.

    Parameters
    ----------
    occupancy : ndarray of shape (I, J, K), bool

    Returns
    -------
    ndarray of shape (I, J, K), bool
    """
    occ = _as_occupancy(occupancy)
    return visual_hull(projections_from_volume(Volume(occ)), occ.shape)
