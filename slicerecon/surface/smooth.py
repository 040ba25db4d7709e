"""Taubin smoothing of closed meshes (volume-preserving low-pass filtering).

Lofted and marching-cubes surfaces show the pixel staircase of the contours
and the facets of sparse planes. Taubin's λ|μ filter (Taubin 1995) alternates
a shrinking Laplacian step (``+λ``) with an inflating one (``μ < -λ``), which
smooths without the shrinkage of plain Laplacian smoothing. Only vertex
positions move, so a watertight manifold stays watertight and manifold.
"""

from __future__ import annotations

import logging

import numpy as np
import trimesh
from trimesh.smoothing import filter_taubin

from ..errors import InputError, OptionError

__all__ = ["taubin_smooth"]

logger = logging.getLogger(__name__)


def taubin_smooth(
    mesh: trimesh.Trimesh, *, iterations: int = 10, lamb: float = 0.5, mu: float = -0.53
) -> trimesh.Trimesh:
    """Taubin-smooth a copy of a mesh.

    Parameters
    ----------
    mesh : trimesh.Trimesh
        The mesh (world mm); left unchanged.
    iterations : int, default 10
        Number of λ|μ pairs (each pair is one shrinking and one inflating
        umbrella-Laplacian step); 0 returns an unchanged copy.
    lamb : float, default 0.5
        Shrinking step factor, ``0 < lamb < 1``.
    mu : float, default -0.53
        Inflating step factor, ``-1 < mu < -lamb`` (Taubin's condition for a
        low-pass filter without shrinkage).

    Returns
    -------
    trimesh.Trimesh
        The smoothed copy: same faces (connectivity and winding), moved
        vertices.

    Raises
    ------
    InputError
        If ``mesh`` is not a ``trimesh.Trimesh``.
    OptionError
        If an option is out of range.
    """
    if not isinstance(mesh, trimesh.Trimesh):
        raise InputError(f"taubin_smooth needs a trimesh.Trimesh (got {type(mesh).__name__})")
    if isinstance(iterations, bool) or not isinstance(iterations, int | np.integer):
        raise OptionError(f"iterations must be an integer (got {iterations!r})")
    if iterations < 0:
        raise OptionError(f"iterations must be >= 0 (got {iterations})")
    lamb, mu = float(lamb), float(mu)
    if not 0.0 < lamb < 1.0:
        raise OptionError(f"lamb must lie in (0, 1) (got {lamb})")
    if not -1.0 < mu < -lamb:
        raise OptionError(
            f"mu must lie in (-1, -lamb) = (-1, {-lamb}) for Taubin smoothing (got {mu})"
        )
    out = mesh.copy()
    if iterations == 0 or len(out.faces) == 0:
        return out
    before = float(out.volume)
    # trimesh counts single steps and takes the inflation factor as a positive number.
    filter_taubin(out, lamb=lamb, nu=-mu, iterations=2 * int(iterations))
    logger.debug(
        "Taubin smoothing (%d pairs, lambda %.3g, mu %.3g): volume %.6g -> %.6g",
        iterations,
        lamb,
        mu,
        before,
        float(out.volume),
    )
    return out
