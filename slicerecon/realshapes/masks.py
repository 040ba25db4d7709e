"""Mask operations shared by the real-shape sources: crop, resample, normalise, voxelize.

Every source crops its mask to the foreground (:func:`crop`), may drop
specks (:func:`drop_specks`) and downsample it (:func:`fit`); mesh sources
voxelize a closed surface given in world mm (:func:`voxelize_surface`).
:func:`normalise` brings any real shape to the protocol's grid size.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from ..errors import EmptyMaskError, OptionError
from ..sections import Volume


def check_fraction(min_fraction: object) -> float:
    """``min_fraction`` (of the largest piece, see :func:`drop_specks`) as a float in [0, 1]."""
    fraction = float(min_fraction)  # type: ignore[arg-type]
    if not 0.0 <= fraction <= 1.0:
        raise OptionError(f"min_fraction must be in [0, 1] (got {min_fraction!r})")
    return fraction


def check_resolution(resolution: object) -> int | None:
    if resolution is None:
        return None
    if (
        isinstance(resolution, bool)
        or not isinstance(resolution, int | np.integer)
        or not (8 <= resolution <= 2048)
    ):
        raise OptionError(
            f"resolution must be a whole number of voxels, 8 to 2048 (got {resolution!r})"
        )
    return int(resolution)


def downsample(volume: Volume, factor: int) -> Volume:
    """Downsample a mask by an integer factor per axis: a voxel is set when most of its block is.

    Parameters
    ----------
    volume : Volume
        Mask of shape ``(I, J, K)``.
    factor : int
        Block side, voxels (1 returns ``volume``). The grid is padded with
        background to a multiple of ``factor``.

    Returns
    -------
    Volume
        Mask of shape ``ceil((I, J, K) / factor)``; voxel ``(i, j, k)`` is
        foreground when more than half of block ``factor * (i, j, k) + [0,
        factor)³`` is, and sits at the block's centre in world mm.

    Raises
    ------
    OptionError
        If ``factor`` is not a positive integer.
    """
    if isinstance(factor, bool) or not isinstance(factor, int | np.integer) or factor < 1:
        raise OptionError(f"factor must be a positive whole number (got {factor!r})")
    f = int(factor)
    if f == 1:
        return volume
    shape = np.asarray(volume.shape)
    padded = -(-shape // f) * f
    mask = np.zeros(tuple(int(n) for n in padded), dtype=np.uint8)
    mask[: shape[0], : shape[1], : shape[2]] = volume.mask
    a, b, c = (int(n) // f for n in padded)
    counts = mask.reshape(a, f, b, f, c, f).sum(axis=(1, 3, 5), dtype=np.int64)
    scale = np.diag([f, f, f, 1.0])
    scale[:3, 3] = (f - 1) / 2.0
    return Volume(2 * counts > f**3, volume.affine @ scale)


def fit(volume: Volume, resolution: int | None, margin: int) -> Volume:
    """Downsample to about ``resolution`` voxels across, then crop to the foreground."""
    if resolution is not None:
        lo, hi = volume.bounding_box_vox()
        factor = max(1, math.ceil(int(np.max(hi - lo)) / resolution))
        volume = downsample(volume, factor)
    if volume.is_empty:
        raise EmptyMaskError("the shape vanished when downsampled; pass a larger resolution")
    return crop(volume, margin)


def crop(volume: Volume, margin: int) -> Volume:
    """Crop to the foreground's bounding box plus ``margin`` voxels (padding if needed)."""
    if isinstance(margin, bool) or not isinstance(margin, int | np.integer) or margin < 0:
        raise OptionError(f"margin must be a whole number of voxels >= 0 (got {margin!r})")
    lo, hi = volume.bounding_box_vox()
    start = lo - int(margin)
    stop = hi + int(margin)
    out = np.zeros(tuple(int(n) for n in stop - start), dtype=bool)
    src_lo = np.maximum(start, 0)
    src_hi = np.minimum(stop, volume.shape)
    dst_lo = src_lo - start
    dst = tuple(
        slice(int(a), int(a + (e - s))) for a, s, e in zip(dst_lo, src_lo, src_hi, strict=True)
    )
    out[dst] = volume.mask[
        tuple(slice(int(s), int(e)) for s, e in zip(src_lo, src_hi, strict=True))
    ]
    shift = np.eye(4)
    shift[:3, 3] = start
    return Volume(out, volume.affine @ shift)


def keep_components(mask: NDArray[np.bool_], min_fraction: float) -> NDArray[np.bool_]:
    """Drop 26-connected components smaller than ``min_fraction`` of the largest one."""
    labels, n = ndimage.label(mask, structure=np.ones((3, 3, 3), dtype=bool))
    if n <= 1:
        return mask
    sizes = np.bincount(labels.ravel())[1:]
    keep = np.flatnonzero(sizes >= min_fraction * sizes.max()) + 1
    return np.isin(labels, keep)


def drop_specks(volume: Volume, min_fraction: float, margin: int) -> Volume:
    """Drop pieces smaller than ``min_fraction`` of the largest; crop to the rest plus ``margin``.

    Pieces are 26-connected; ``min_fraction`` 0 returns ``volume`` as it is.
    """
    if min_fraction <= 0:
        return volume
    return crop(Volume(keep_components(volume.mask, min_fraction), volume.affine), margin)


def resample(volume: Volume, scale: float, *, sigma: float | None = None) -> Volume:
    """Resample a mask smoothly by a common factor on every grid axis.

    The mask is blurred with a Gaussian, interpolated linearly at the centres
    of the new grid (:func:`scipy.ndimage.zoom`, ``grid_mode=True``) and
    thresholded at 0.5. Voxel sizes are all divided by about ``scale``, so
    the ratio between them (the source's anisotropy) is kept.

    Parameters
    ----------
    volume : Volume
        Mask of shape ``(I, J, K)``.
    scale : float
        New voxels per old voxel along each axis (> 1 upsamples); the grid
        becomes ``round((I, J, K) * scale)`` voxels.
    sigma : float, optional
        Gaussian width, in old voxels. Default ``max(0.5, (1 / scale - 1) / 2)``:
        anti-aliasing when downsampling, and half a voxel otherwise, which
        rounds off the staircase of an upsampled label map.

    Returns
    -------
    Volume
        The resampled mask. The affine is exact: new voxel ``(i, j, k)``
        covers the same world region as the old voxels it was interpolated from.

    Raises
    ------
    OptionError
        If ``scale`` or ``sigma`` is not a positive finite number (``sigma`` may be 0).
    EmptyMaskError
        If the shape vanishes (thinner than the new voxels).
    """
    factor = float(scale)
    if not math.isfinite(factor) or factor <= 0:
        raise OptionError(f"scale must be a positive number (got {scale!r})")
    width = max(0.5, (1.0 / factor - 1.0) / 2.0) if sigma is None else float(sigma)
    if not math.isfinite(width) or width < 0:
        raise OptionError(f"sigma must be a number of voxels >= 0 (got {sigma!r})")
    pad = int(math.ceil(3 * width)) + 1
    volume = crop(volume, pad)  # room for the blur, and a small array to zoom
    field = volume.mask.astype(np.float32)
    if width > 0:
        field = ndimage.gaussian_filter(field, width, mode="constant")
    old = np.asarray(volume.shape, dtype=np.float64)
    new = np.maximum(np.round(old * factor), 1).astype(np.int64)
    zoomed = ndimage.zoom(field, new / old, order=1, mode="grid-constant", grid_mode=True)
    step = old / new  # old voxels per new voxel, per axis
    scaling = np.diag([*step, 1.0])
    scaling[:3, 3] = step / 2.0 - 0.5  # new voxel 0's centre, in old voxel indices
    out = Volume(zoomed > 0.5, volume.affine @ scaling)
    if out.is_empty:
        raise EmptyMaskError(f"the shape vanished when resampled by {factor:g}; use a larger scale")
    return out


def normalise(
    volume: Volume,
    *,
    min_extent: int = 96,
    max_extent: int = 160,
    min_fraction: float = 0.005,
    margin: int = 3,
) -> Volume:
    """Bring a mask to a grid whose longest foreground extent is in ``[min_extent, max_extent]``.

    A mask already in range is only cropped; a larger or smaller one is
    resampled (:func:`resample`) so that its longest extent becomes
    ``max_extent`` or ``min_extent``. The same factor applies on every axis,
    so anisotropic voxels stay anisotropic. Specks (26-connected pieces
    smaller than ``min_fraction`` of the largest piece, as resampling a
    label map leaves along diagonal joints) are then dropped.

    Parameters
    ----------
    volume : Volume
        Mask of shape ``(I, J, K)``.
    min_extent, max_extent : int, default 96 and 160
        Range of the longest side of the foreground's bounding box, voxels.
    min_fraction : float, default 0.005
        Pieces smaller than this fraction of the largest one are dropped; 0
        keeps all.
    margin : int, default 3
        Background voxels kept around the foreground.

    Returns
    -------
    Volume

    Raises
    ------
    OptionError
        If the range is empty or below 8 voxels, or ``min_fraction`` is not in [0, 1].
    EmptyMaskError
        If the mask is empty.
    """
    lo_ext, hi_ext = int(min_extent), int(max_extent)
    if not 8 <= lo_ext <= hi_ext:
        raise OptionError(
            f"need 8 <= min_extent <= max_extent (got {min_extent!r}, {max_extent!r})"
        )
    fraction = check_fraction(min_fraction)
    lo, hi = volume.bounding_box_vox()
    extent = int(np.max(hi - lo))
    if extent > hi_ext:
        volume = resample(volume, hi_ext / extent)
    elif extent < lo_ext:
        volume = resample(volume, lo_ext / extent)
    return drop_specks(crop(volume, margin), fraction, margin)


def voxelize_surface(vertices: NDArray, faces: NDArray, resolution: int, margin: int) -> Volume:
    """Voxelize a closed surface given in world mm (``resolution`` voxels across)."""
    import trimesh

    from ..io.mesh import voxelize_mesh

    res = check_resolution(resolution)
    if res is None:
        raise OptionError("resolution must be given for a mesh")
    surface = trimesh.Trimesh(
        np.asarray(vertices, dtype=np.float64), np.asarray(faces, dtype=np.int64), process=True
    )
    return crop(voxelize_mesh(surface, resolution=res, pad=0), margin)
