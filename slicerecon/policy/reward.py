"""The reward's per-part reconstruction ``S_i`` in training: the surface inference makes.

The reward ``R_i = IoU(W_i, O) + lam * IoU(S_i, W_i)``
(:func:`~slicerecon.partition.state.part_rewards`) judges a part by how well
its reconstruction ``S_i`` from the cross-sections inside its box matches it.
Inference reconstructs every part with the default surface of
:class:`slicerecon.reconstruct.ReconstructConfig`: signed-distance
interpolation across planes with PCHIP, extended to the box faces following
the visual hull, carved by the hull. :func:`part_surface_voxels` is exactly
that part's voxel occupancy (:func:`slicerecon.surface.part.part_voxels` with
``method="sdf"``, ``interpolation="pchip"``, drifting regions joined and the
hull, intersected with the hull). The torch environment uses it (``reward_surface="exact"``, the
default) or a batched surrogate of it (:mod:`slicerecon.policy.surrogate`)
whose agreement is measured in ``docs/policy.md``
(``benchmarks/reward_agreement.py``).

This module is numpy only (no torch): it composes the library's partition
episode (:mod:`slicerecon.partition.episodes`) and surface
(:mod:`slicerecon.surface`), which training needs for its reward.
"""

from __future__ import annotations

import functools
from collections.abc import Callable

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..errors import OptionError
from ..options import ReconstructOptions
from ..partition.episodes import SECTION_AXIS, episode_sections, occupancy_hull
from ..sections import Box, CrossSections

__all__ = [
    "REWARD_SURFACES",
    "SURFACE_INTERPOLATION",
    "SURFACE_METHOD",
    "SURFACE_OPTIONS",
    "part_surface_voxels",
    "episode_reconstruction",
    "plane_distances",
    "mask_distances",
]

REWARD_SURFACES = ("exact", "surrogate")
"""How the training environment reconstructs a part for the reward."""

SURFACE_OPTIONS = ReconstructOptions()
"""The per-part surface of inference: the defaults of the one options bundle."""
SURFACE_METHOD = SURFACE_OPTIONS.method
"""Its method (``ReconstructOptions.method``'s default)."""
SURFACE_INTERPOLATION = SURFACE_OPTIONS.interpolation
"""Its interpolation across planes (``ReconstructOptions.interpolation``'s default)."""
SURFACE_JOIN_DRIFT = SURFACE_OPTIONS.join_drift
"""Whether drifting regions are joined (``ReconstructOptions.join_drift``'s default)."""


def part_surface_voxels(
    sections: CrossSections, hull: NDArray[np.bool_], box: Box
) -> NDArray[np.bool_]:
    """``S_i``: the voxel occupancy of a part's surface as inference makes it.

    Parameters
    ----------
    sections : CrossSections
        All cross-sections of the shape.
    hull : ndarray of shape sections.grid_shape, bool
        The visual hull of the shape's projections: it guides the extensions
        to the box faces and carves the result.
    box : Box
        The part's box.

    Returns
    -------
    ndarray of shape box.shape, bool
        ``part_voxels(sections, box, method="sdf", hull=hull,
        interpolation="pchip", join_drift=True) & hull[box.slices]``.
    """
    from ..surface.part import part_voxels

    voxels = part_voxels(sections, box, SURFACE_OPTIONS, hull=hull)
    return voxels & hull[box.slices]


def episode_reconstruction(
    occupancy: ArrayLike, n_planes: int
) -> tuple[Callable[[Box], NDArray[np.bool_]], CrossSections, NDArray[np.bool_]]:
    """The reward's reconstruction of a training episode on ``occupancy``.

    Parameters
    ----------
    occupancy : ndarray of shape (I, J, K), bool
        The episode's shape ``O``.
    n_planes : int
        Section planes (:func:`~slicerecon.partition.episodes.episode_sections`).

    Returns
    -------
    reconstruct : callable
        ``reconstruct(box) -> bool array of box.shape``
        (:func:`part_surface_voxels`), the ``reconstruct`` argument of
        :class:`~slicerecon.partition.state.PartitionState`.
    sections : CrossSections
    hull : ndarray of shape (I, J, K), bool
    """
    sections = episode_sections(occupancy, n_planes)
    hull = occupancy_hull(occupancy)
    return functools.partial(part_surface_voxels, sections, hull), sections, hull


def mask_distances(
    masks: NDArray[np.bool_], spacing: tuple[float, float] = (1.0, 1.0)
) -> NDArray[np.float32]:
    """:func:`slicerecon.surface.sdf.plane_signed_distance` of a stack of in-plane masks.

    Parameters
    ----------
    masks : ndarray of shape (P, M, N), bool
    spacing : tuple of 2 floats, optional
        Pixel size along rows and columns, mm.

    Returns
    -------
    ndarray of shape (P, M, N), float32
        Signed distance (negative inside, ``+inf`` on an empty mask).
    """
    from ..surface.sdf import plane_signed_distance

    if len(masks) == 0:
        return np.zeros(np.shape(masks), dtype=np.float32)
    return np.stack([plane_signed_distance(m, np.asarray(spacing)) for m in masks])


def plane_distances(sections: CrossSections) -> NDArray[np.float32]:
    """Signed distance of every section plane over the whole plane (the surrogate's input).

    :func:`mask_distances` of the section masks (mm, negative inside, ``+inf``
    on an empty plane) with the grid's in-plane spacing.

    Parameters
    ----------
    sections : CrossSections
        Planes perpendicular to grid axis z, on the grid.

    Returns
    -------
    ndarray of shape (P, I, J), float32
    """
    if sections.axis != SECTION_AXIS:
        raise OptionError(f"the surrogate needs planes along z (got axis {sections.axis})")
    a, b = sections.plane_axes
    return mask_distances(sections.masks, (float(sections.spacing[a]), float(sections.spacing[b])))
