"""Harris corner points of projection silhouettes.

Corner points are where the method may cut a silhouette, so they are returned
as points of the *pixel-boundary lattice*: in continuous pixel coordinates a
pixel ``(r, c)`` covers ``[r - 0.5, r + 0.5] x [c - 0.5, c + 0.5]``, and a
rectangle covering pixels ``lo..hi-1`` has its corners at ``lo - 0.5`` and
``hi - 0.5``. Every returned coordinate is therefore a half-integer.

The corner response is the Harris measure ``det(M) - k trace(M)^2`` of the
Gaussian-weighted structure tensor ``M`` of the zero-padded silhouette (Harris
& Stephens 1988), computed as scikit-image's ``corner_harris`` does it (Sobel
derivatives, a Gaussian window truncated at 4 sigma, zero outside the image:
:func:`harris_response` gives the same values), and non-maximum suppressed as
its ``corner_peaks`` does (:func:`skimage.feature.peak.peak_local_max`, then
peaks closer than ``min_distance`` to a stronger one dropped). The response is
written here so that the planner does not import ``skimage.feature`` (which
loads ``scipy.stats``, about a second per process). Each peak pixel is then
snapped to the nearest lattice vertex where the silhouette boundary turns (see
:func:`harris_corners`).
"""

from __future__ import annotations

import logging
from functools import lru_cache

import numpy as np
from numpy.typing import ArrayLike, NDArray

from .errors import InputError, OptionError
from .sections import Projections

__all__ = [
    "harris_corners",
    "harris_response",
    "pad_corners",
    "projection_corners",
    "reference_response",
]

logger = logging.getLogger(__name__)

_SNAP_RADIUS = 1.5
"""Largest distance (pixels, per coordinate) from a peak pixel centre to its snapped vertex."""


def harris_response(image: NDArray[np.float64], *, k: float, sigma: float) -> NDArray[np.float64]:
    """Harris corner response ``det(M) - k trace(M)^2`` of a grey image.

    Parameters
    ----------
    image : ndarray of shape (M, N), float
        The image; values beyond its border count as 0.
    k : float
        Harris sensitivity.
    sigma : float
        Standard deviation of the Gaussian window of the structure tensor, pixels.

    Returns
    -------
    ndarray of shape (M, N), float64
        The response per pixel; equal to ``skimage.feature.corner_harris(image,
        method="k", k=k, sigma=sigma)``.
    """
    from scipy import ndimage

    rows = ndimage.sobel(image, axis=0, mode="constant", cval=0.0)
    cols = ndimage.sobel(image, axis=1, mode="constant", cval=0.0)

    def window(values: NDArray[np.float64]) -> NDArray[np.float64]:
        return ndimage.gaussian_filter(values, sigma, mode="constant", cval=0.0, truncate=4.0)

    arr, arc, acc = window(rows * rows), window(rows * cols), window(cols * cols)
    return arr * acc - arc**2 - k * (arr + acc) ** 2


def _corner_peaks(
    response: NDArray[np.float64], *, min_distance: int, threshold_abs: float, num_peaks: float
) -> NDArray[np.int64]:
    """Peak pixels of a response, as scikit-image's ``corner_peaks`` finds them.

    Local maxima above ``threshold_abs`` at least ``min_distance`` apart
    (:func:`skimage.feature.peak.peak_local_max`), strongest first; then any
    peak within ``min_distance`` of an earlier kept one is dropped, and at
    most ``num_peaks`` remain.
    """
    from scipy.spatial import cKDTree
    from skimage.feature.peak import peak_local_max

    coords = peak_local_max(
        response,
        min_distance=min_distance,
        threshold_abs=threshold_abs,
        threshold_rel=None,
        exclude_border=False,
        num_peaks=np.inf,
    )
    if len(coords):
        tree = cKDTree(coords)
        rejected: set[int] = set()
        for idx, point in enumerate(coords):
            if idx not in rejected:
                near = tree.query_ball_point(point, r=min_distance, p=np.inf)
                rejected.update(i for i in near if i != idx)
        coords = np.delete(coords, tuple(rejected), axis=0)
        if np.isfinite(num_peaks):
            coords = coords[: int(num_peaks)]
    return np.asarray(coords, dtype=np.int64)


@lru_cache(maxsize=32)
def reference_response(k: float, sigma: float) -> float:
    """Harris response of an ideal right-angle corner of a binary silhouette.

    ``threshold_rel`` of :func:`harris_corners` is relative to this value, so
    that the threshold means the same on every image (an image without any
    real corner, such as a disk, then yields none).

    Parameters
    ----------
    k : float
        Harris sensitivity.
    sigma : float
        Standard deviation of the Gaussian window, pixels.

    Returns
    -------
    float
        The peak response of a quarter-plane silhouette.
    """
    half = int(np.ceil(4 * sigma)) + 4
    image = np.zeros((2 * half + 1, 2 * half + 1))
    image[half:, half:] = 1.0
    return float(harris_response(image, k=k, sigma=sigma).max())


def _check_image(image: ArrayLike) -> NDArray[np.bool_]:
    arr = np.asarray(image)
    if arr.ndim != 2:
        raise InputError(f"a silhouette must be a 2-D array (got shape {arr.shape})")
    if 0 in arr.shape:
        raise InputError(f"the silhouette has an empty dimension (shape {arr.shape})")
    if arr.dtype != np.bool_:
        if arr.dtype.kind not in "biuf" or not np.all(np.isin(arr, (0, 1))):
            raise InputError("a silhouette must be boolean (or 0/1 numbers)")
        arr = arr.astype(bool)
    return arr


def _vertex_counts(padded: NDArray[np.bool_]) -> NDArray[np.int64]:
    """Foreground count of the 2x2 pixels around every lattice vertex of a padded image.

    Entry ``[i, j]`` belongs to the vertex between padded pixels ``(i, j)`` and
    ``(i + 1, j + 1)``.
    """
    p = padded.astype(np.int64)
    return p[:-1, :-1] + p[:-1, 1:] + p[1:, :-1] + p[1:, 1:]


def _is_turning(padded: NDArray[np.bool_]) -> NDArray[np.bool_]:
    """Whether the silhouette boundary turns at each lattice vertex (see _vertex_counts).

    One or three foreground pixels of four (a convex or concave corner), or two
    diagonal ones (two corners touching), make a turning vertex.
    """
    counts = _vertex_counts(padded)
    diagonal = (counts == 2) & (padded[:-1, :-1] == padded[1:, 1:])
    return (counts == 1) | (counts == 3) | diagonal


def harris_corners(
    image: ArrayLike,
    *,
    k: float = 0.05,
    sigma: float = 1.0,
    threshold_rel: float = 0.05,
    min_distance: int = 1,
    max_corners: int | None = None,
) -> NDArray[np.float64]:
    """Corner points of a binary silhouette, on the pixel-boundary lattice.

    Parameters
    ----------
    image : ndarray of shape (M, N), bool
        Silhouette; rows and columns are the two image axes.
    k : float, optional
        Harris sensitivity in ``det(M) - k trace(M)^2``; typical values
        0.04-0.06. Larger values suppress edge-like responses more.
    sigma : float, optional
        Standard deviation of the Gaussian window of the structure tensor,
        pixels. Larger values smooth away staircase noise but merge corners
        closer than about ``2 sigma``.
    threshold_rel : float, optional
        Minimum response, as a fraction of the response of an ideal
        right-angle corner (:func:`reference_response`), not of the image's
        maximum: a silhouette without corners (a disk) yields none.
    min_distance : int, optional
        Minimum distance between response peaks, pixels
        (as ``skimage.feature.corner_peaks``).
    max_corners : int, optional
        Keep at most this many corners, the strongest responses first.
        ``None`` keeps all.

    Returns
    -------
    ndarray of shape (K, 2), float64
        Corner points ``(row, col)`` in continuous pixel coordinates; every
        coordinate is a half-integer in ``[-0.5, M - 0.5]`` resp.
        ``[-0.5, N - 0.5]``. Rows are sorted by ``(row, col)`` and unique.

    Notes
    -----
    Each response peak (a pixel) is snapped to a lattice vertex within 1.5
    pixels (per coordinate) of its centre at which the boundary turns (one or
    three of its four pixels are foreground, or two diagonal ones), the
    closest one first, then the one with the larger mean response of its four
    pixels, then the lexicographically smallest. A peak with no such vertex
    nearby is snapped to the adjacent vertex with the largest mean response.
    """
    img = _check_image(image)
    if not k > 0:
        raise OptionError(f"k must be > 0 (got {k})")
    if not sigma > 0:
        raise OptionError(f"sigma must be > 0 (got {sigma})")
    if not threshold_rel >= 0:
        raise OptionError(f"threshold_rel must be >= 0 (got {threshold_rel})")
    if int(min_distance) < 1:
        raise OptionError(f"min_distance must be >= 1 (got {min_distance})")
    if max_corners is not None and int(max_corners) < 0:
        raise OptionError(f"max_corners must be >= 0 or None (got {max_corners})")
    if max_corners == 0 or not img.any():
        return np.zeros((0, 2), dtype=np.float64)

    pad = int(np.ceil(3 * sigma)) + 2
    padded = np.pad(img, pad)
    response = harris_response(padded.astype(np.float64), k=k, sigma=sigma)
    threshold = threshold_rel * reference_response(float(k), float(sigma))
    peaks = _corner_peaks(
        response,
        min_distance=int(min_distance),
        threshold_abs=max(threshold, np.finfo(np.float64).tiny),
        num_peaks=np.inf if max_corners is None else int(max_corners),
    )
    if peaks.size == 0:
        return np.zeros((0, 2), dtype=np.float64)

    turning = _is_turning(padded)  # vertex (i, j) sits at padded coords (i + .5, j + .5)
    p = response
    mean_response = 0.25 * (p[:-1, :-1] + p[:-1, 1:] + p[1:, :-1] + p[1:, 1:])
    reach = int(np.floor(_SNAP_RADIUS))
    snapped: set[tuple[float, float]] = set()
    for r, c in peaks:
        # vertices at padded coords (r + dr, c + dc), dr, dc in {-1.5, -0.5, 0.5, 1.5}
        best: tuple[float, float, int, int] | None = None
        for i in range(r - reach - 1, r + reach + 1):
            for j in range(c - reach - 1, c + reach + 1):
                if not (0 <= i < turning.shape[0] and 0 <= j < turning.shape[1]):
                    continue
                if not turning[i, j]:
                    continue
                dist = float(np.hypot(i + 0.5 - r, j + 0.5 - c))
                key = (dist, -float(mean_response[i, j]), i, j)
                if best is None or key < best:
                    best = key
        if best is None:
            around = [(i, j) for i in (r - 1, r) for j in (c - 1, c)]
            i, j = max(around, key=lambda v: (mean_response[v], -v[0], -v[1]))
        else:
            i, j = best[2], best[3]
        snapped.add((i + 0.5 - pad, j + 0.5 - pad))
    out = np.array(sorted(snapped), dtype=np.float64).reshape(-1, 2)
    logger.debug("harris_corners: %d peaks -> %d lattice corners", len(peaks), len(out))
    return out


def projection_corners(
    projections: Projections,
    **options: float | int | None,
) -> tuple[NDArray[np.float64], NDArray[np.float64], NDArray[np.float64]]:
    """Corner points of the three views of a :class:`~slicerecon.sections.Projections`.

    Parameters
    ----------
    projections : Projections
        ``views[a]`` is the silhouette along grid axis ``a``.
    **options
        Keyword options of :func:`harris_corners`.

    Returns
    -------
    tuple of 3 ndarrays of shape (K_a, 2)
        Corners of view ``a`` in that view's continuous pixel coordinates.
    """
    if not isinstance(projections, Projections):
        raise InputError(f"expected a Projections object (got {type(projections).__name__})")
    a, b, c = (harris_corners(view.image, **options) for view in projections.views)  # type: ignore[arg-type]
    return a, b, c


def pad_corners(
    corners: ArrayLike,
    *,
    n_max: int,
    image_shape: tuple[int, int],
) -> tuple[NDArray[np.float64], NDArray[np.bool_]]:
    """Fixed-length, normalised corner list (the policy's corner state).

    Parameters
    ----------
    corners : ndarray of shape (K, 2)
        Corner points in continuous pixel coordinates of an image of shape
        ``image_shape``.
    n_max : int
        Length of the output list. Corners beyond ``n_max`` are dropped (the
        first ``n_max`` in the given order are kept; pass ``max_corners`` to
        :func:`harris_corners` to keep the strongest instead).
    image_shape : tuple of int
        ``(M, N)`` of the image.

    Returns
    -------
    points : ndarray of shape (n_max, 2), float64
        ``((row + 0.5) / M, (col + 0.5) / N)``, in ``[0, 1]``: the image
        extent maps to ``[0, 1]``. Invalid rows are 0.
    valid : ndarray of shape (n_max,), bool
        True for the rows that hold a corner.
    """
    n = int(n_max)
    if n < 0:
        raise OptionError(f"n_max must be >= 0 (got {n_max})")
    shape = tuple(int(s) for s in image_shape)
    if len(shape) != 2 or min(shape) < 1:
        raise OptionError(f"image_shape must be two positive sizes (got {image_shape})")
    pts = np.asarray(corners, dtype=np.float64).reshape(-1, 2)
    if pts.shape[0] > n:
        logger.debug("pad_corners: dropping %d of %d corners", pts.shape[0] - n, pts.shape[0])
        pts = pts[:n]
    out = np.zeros((n, 2), dtype=np.float64)
    valid = np.zeros(n, dtype=bool)
    scale = np.asarray(shape, dtype=np.float64)
    out[: pts.shape[0]] = np.clip((pts + 0.5) / scale, 0.0, 1.0)
    valid[: pts.shape[0]] = True
    return out, valid
