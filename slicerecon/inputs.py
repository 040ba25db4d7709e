"""From a loaded input to what a reconstruction needs: sections, projections, ground truth.

:func:`prepare_inputs` crops a dense mask, samples its planes (it is then its own
ground truth) or takes sparse inputs as they are, and makes the projections;
:func:`looks_sparse` tells a mask annotated on some planes from a dense one;
:func:`axis_upsample` says how finely the ``sdf`` surface samples the section
axis. Every grid is checked against the memory budget before anything is
allocated on it. :mod:`slicerecon.reconstruct` re-exports these names.
"""

from __future__ import annotations

import logging
import math
import os
from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from .errors import InputError, OptionError
from .io.limits import DEFAULT_MEMORY_BUDGET_GB, check_grid
from .io.projections import read_projection_files
from .plane_detection import detect_planes
from .sampling import projections_from_sections, projections_from_volume, sample_sections
from .sections import AXIS_NAMES, CrossSections, Projections, Volume, axis_index

__all__ = [
    "DEFAULT_SLICES",
    "GT_NEEDS_DENSE",
    "MAX_AXIS_UPSAMPLE",
    "PROJECTION_SOURCES",
    "axis_upsample",
    "looks_sparse",
    "prepare_inputs",
    "refuse_plane_options",
    "sparse_sections",
]

logger = logging.getLogger(__name__)

PROJECTION_SOURCES = ("auto", "gt", "sections")
"""Where projections come from (besides silhouette files)."""
DEFAULT_SLICES = 16
"""Planes kept from a dense mask when neither ``slices`` nor ``every`` is given."""


def sparse_sections(volume: Volume, axis: int, planes: ArrayLike) -> CrossSections:
    """The annotated slices ``planes`` (indices along ``axis``) of a mask, as cross-sections."""
    full = sample_sections(volume, every=1, axis=axis)
    keep = np.flatnonzero(np.isin(full.indices.astype(np.int64), np.asarray(planes)))
    return full.select(keep)


def looks_sparse(volume: Volume, axis: int) -> bool:
    """Whether a mask is annotated on some planes along ``axis`` alone.

    The rule of :func:`slicerecon.plane_detection.detect_planes`: the mask is
    a set of sheets (annotated slices, at any density: every 2nd slice
    included) rather than a solid, and its annotated planes are all
    perpendicular to ``axis``.
    """
    reading = detect_planes(volume.mask)
    return not reading.dense and reading.axes == (axis_index(axis),)


def refuse_plane_options(slices: int | None, every: int | None, why: str) -> None:
    """Refuse ``--slices`` / ``--every`` (the planes of a dense mask) for an input that
    already holds its planes; ``why`` says what it is.

    Raises
    ------
    OptionError
        ``slices`` or ``every`` given.
    """
    if slices is not None or every is not None:
        raise OptionError(f"--slices/--every apply to dense masks; {why}")


GT_NEEDS_DENSE = "--projections gt needs a dense mask as input; use --projections sections"
"""The refusal of ``--projections gt`` for sparse input (no dense mask to project)."""


def prepare_inputs(
    data: Volume | CrossSections,
    *,
    slices: int | None = None,
    every: int | None = None,
    axis: int | str = "z",
    projections: str | Sequence[str | os.PathLike[str]] = "auto",
    memory_budget_gb: float = DEFAULT_MEMORY_BUDGET_GB,
    annotation: str | tuple[int, ...] = "auto",
) -> tuple[CrossSections, Projections, Volume | None]:
    """Turn a loaded input into cross-sections, projections and (maybe) ground truth.

    A dense volume is cropped to its foreground (plus a margin), sampled at
    ``slices`` / ``every`` planes and kept as ground truth. A volume annotated
    on some planes of one axis (:func:`slicerecon.plane_detection.detect_planes`,
    or as ``annotation`` states) and contour inputs are used as they are,
    without ground truth: ``slices`` / ``every`` are refused for them, and
    ``axis`` (the axis dense masks are cut along) is not used. A volume
    annotated along several axes is refused here:
    :func:`slicerecon.case.reconstruct_structures` reconstructs it.

    ``projections`` is ``"gt"`` (from the dense mask), ``"sections"``
    (derived from the sections), ``"auto"`` (``gt`` when there is a dense
    mask), or one to three NIfTI silhouette files, as a sequence of paths or
    one comma-separated string (:mod:`slicerecon.io.projections`).

    The grid the reconstruction will work on (the cropped mask, or the
    sections' grid, refined along the axis as :func:`axis_upsample` says) is
    checked against ``memory_budget_gb``, GiB
    (:func:`slicerecon.io.limits.check_grid`), before anything is allocated on it.

    Returns
    -------
    sections : CrossSections
    projections : Projections
    ground_truth : Volume or None

    Raises
    ------
    OptionError
        ``--slices`` / ``--every`` on a sparse input; a mask annotated along
        several axes; projections that cannot be had.
    InputError
        ``data`` is neither a Volume nor CrossSections.
    """

    if isinstance(projections, str):
        files = (
            []
            if projections in PROJECTION_SOURCES
            else [f.strip() for f in projections.split(",") if f.strip()]
        )
    else:
        files = [os.fspath(f) for f in projections]
    if not files and projections not in PROJECTION_SOURCES:
        raise OptionError(f"projections must be one of {PROJECTION_SOURCES} or silhouette files")
    ax = axis_index(axis)
    truth: Volume | None = None
    if isinstance(data, Volume):
        volume = data.crop(pad=3)
        check_grid(volume.shape, what="the reconstruction grid", memory_budget_gb=memory_budget_gb)
        reading = detect_planes(volume.mask, annotation)
        if not reading.dense:
            if len(reading.axes) != 1:
                raise OptionError(
                    f"the mask is a {reading.describe(volume.spacing)}: several views are "
                    "reconstructed by slicerecon run (slicerecon.case.reconstruct_structures)"
                )
            if not reading.stated:  # a stated reading is the caller's (load_case says it)
                logger.info("the mask is a %s", reading.describe(volume.spacing))
            (only,) = reading.axes
            refuse_plane_options(
                slices, every, f"this input is already sparse ({reading.describe(volume.spacing)})"
            )

            sections = sparse_sections(volume, only, reading.planes[only])
        else:
            spanned = int(volume.occupied_planes(ax).size)
            if slices is None and every is None:
                slices = min(DEFAULT_SLICES, spanned)
            if slices is not None and slices > spanned:
                raise OptionError(
                    f"--slices {slices} asks for more planes than the {spanned} the structure "
                    f"spans along {AXIS_NAMES[ax]}; ask for at most {spanned}"
                )
            if spanned == 1:  # a structure on one plane: that plane, a one-slice slab
                logger.warning(
                    "the structure lies on one plane along %s: the reconstruction "
                    "is a slab one slice thick",
                    AXIS_NAMES[ax],
                )
                slices, every = None, 1
            sections = sample_sections(volume, n=slices, every=every, axis=ax)
            truth = volume
    elif isinstance(data, CrossSections):
        sections = data
        refuse_plane_options(slices, every, "this input is already sparse")
    else:
        raise InputError(
            f"prepare_inputs takes a Volume or CrossSections (got {type(data).__name__}): "
            "read a file with slicerecon.io.load_input, or wrap an array with "
            "slicerecon.Volume(mask, affine)"
        )
    sections.require_foreground()
    samples = list(sections.grid_shape)
    samples[sections.axis] *= axis_upsample(sections)  # the sdf surface's field samples
    check_grid(samples, what="the reconstruction grid", memory_budget_gb=memory_budget_gb)
    if files:
        return sections, read_projection_files(files, sections), truth
    source = projections
    if source == "auto":
        source = "gt" if truth is not None else "sections"
    if source == "gt":
        if truth is None:
            raise OptionError(GT_NEEDS_DENSE)
        proj = projections_from_volume(truth)
    else:
        proj = projections_from_sections(sections)
    return sections, proj, truth


MAX_AXIS_UPSAMPLE = 9
"""Largest number of signed-distance samples per voxel along the section axis."""


def axis_upsample(sections: CrossSections) -> int:
    """Field samples per voxel along the section axis for the ``sdf`` surface.

    A grid whose slice step is the gap between planes (contours read on their
    own, or an RTSTRUCT on a slice axis of its own) has no voxel layer between
    two planes, so a field sampled per voxel could only be interpolated
    linearly, by marching cubes, between planes. When the median gap holds
    fewer than four voxel layers, the axis is sampled about as finely as the
    in-plane pixels instead (an odd factor, so that the planes stay on
    samples; at most :data:`MAX_AXIS_UPSAMPLE`). Dense masks sampled at a few
    planes keep one sample per voxel.

    Returns
    -------
    int
        Odd, in ``[1, MAX_AXIS_UPSAMPLE]``.
    """
    if sections.n_planes < 2 or float(np.median(np.diff(sections.indices))) >= 4.0:
        return 1
    spacing = sections.spacing
    a, b = sections.plane_axes
    ratio = float(spacing[sections.axis] / min(spacing[a], spacing[b]))
    factor = max(1, math.ceil(ratio - 1e-6))
    factor += 1 - factor % 2  # odd: the planes stay on samples
    return int(min(factor, MAX_AXIS_UPSAMPLE))
