"""Describe an input without refusing it: every structure it holds and what each holds.

:func:`describe_input` is what ``slicerecon info`` prints. It accepts every
input that :func:`slicerecon.io.load_input` reads (an RTSTRUCT beside its image
series included) and never asks the user to choose a structure: it lists them
all, each with its number, name, what it holds (voxels and volume, or contours)
and where (planes, extent in mm). An ROI without contours is listed, not refused.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from ..errors import EmptyMaskError, LabelError
from ..labels import check_label_values
from ..sections import AXIS_NAMES, CrossSections, Volume, world_bounds
from . import detect_kind, load_input
from .contours import contour_structures
from .dicom import dicom_info, read_dicom_seg, read_dicom_series_values
from .limits import DEFAULT_MEMORY_BUDGET_GB, check_budget, reading
from .nrrd import nrrd_info, read_nrrd_label_map
from .plane_groups import orientation_count, plane_count
from .polygons import PLANE_TOLERANCE_MM, polygon_normal
from .rtstruct import roi_contours
from .vti import read_vti

__all__ = ["describe_input", "describe_label_map", "describe_sections", "describe_volume"]

logger = logging.getLogger(__name__)


def _round(values: Any, digits: int = 4) -> list[float]:
    return [round(float(v), digits) for v in np.asarray(values, dtype=np.float64).ravel()]


def _bounds(bounds: tuple[NDArray, NDArray]) -> dict[str, list[float]]:
    """World bounds (mm) as a record."""
    return {"min": _round(bounds[0], 3), "max": _round(bounds[1], 3)}


def _grid(affine: NDArray[np.float64], shape: tuple[int, ...]) -> dict[str, Any]:
    return {
        "shape": [int(s) for s in shape],
        "spacing_mm": _round(np.linalg.norm(affine[:3, :3], axis=0), 6),
        "origin_mm": _round(affine[:3, 3], 4),
    }


def describe_label_map(
    values: NDArray[Any],
    affine: NDArray[np.float64],
    *,
    names: dict[int, str] | None = None,
    axis: int = 2,
) -> list[dict[str, Any]]:
    """One record per non-zero label of a label map.

    Parameters
    ----------
    values : ndarray of shape (I, J, K), integer-valued
        The label map.
    affine : ndarray of shape (4, 4)
        Voxel index → world mm.
    names : dict of int to str, optional
        Names of label values, where the input has them.
    axis : int
        Grid axis along which planes are counted.

    Returns
    -------
    list of dict
        ``value``, ``name``, ``voxels``, ``volume_mm3`` (``drawn_volume_mm3`` for
        a sparse annotation: its drawn voxels), ``planes`` (the number
        of planes along ``axis`` holding the label, and the first and last; for
        a label map read as a sparse annotation, ``{"drawn": {axis name: the
        number of annotated planes holding the label}}``),
        ``extent_mm`` (``min`` / ``max`` of the voxel centres, world mm).
    """
    from ..plane_detection import detect_planes

    voxel = float(abs(np.linalg.det(affine[:3, :3])))
    data = np.asarray(values)
    present, counts = np.unique(data[data != 0], return_counts=True)
    reading, first = None, np.zeros(3, dtype=np.int64)
    if present.size:  # read on the box of every structure together, as run reads it
        union = ndimage.find_objects((data != 0).astype(np.uint8))[0]
        assert union is not None
        reading = detect_planes(data[union] != 0)
        first = np.array([s.start for s in union])
    out: list[dict[str, Any]] = []
    # one structure at a time on the box of all: a whole 512 x 512 x 200 volume per
    # structure and plane made info take 15 minutes on 20 sparse structures
    inside = data[union] if present.size else data
    for value, count in zip(present.tolist(), counts.tolist(), strict=True):
        mask = inside == value
        box = ndimage.find_objects(mask.astype(np.uint8))[0]
        assert box is not None
        lo = np.array([s.start for s in box]) + first
        # the slices holding it along each axis, on the box of all
        held = [mask.any(axis=tuple(a for a in range(3) if a != along)) for along in range(3)]
        planes: dict[str, Any]
        if reading is None or reading.dense:
            slices = np.flatnonzero(held[axis]) + first[axis]
            planes = {
                "axis": AXIS_NAMES[axis],
                "count": int(slices.size),
                "first": int(slices[0]),
                "last": int(slices[-1]),
            }
        else:  # a sparse annotation: the planes it is drawn on, along each axis
            planes = {"drawn": {}}
            for along, indices in sorted(reading.planes.items(), key=lambda item: -item[0]):
                drawn = int(np.count_nonzero(held[along][indices]))
                if drawn:
                    planes["drawn"][AXIS_NAMES[along]] = drawn
        out.append(
            {
                "value": int(value),
                "name": (names or {}).get(int(value), ""),
                "voxels": int(count),
                # a sparse annotation's voxels are its drawn planes, not its volume
                ("volume_mm3" if reading is None or reading.dense else "drawn_volume_mm3"): round(
                    count * voxel, 3
                ),
                "planes": planes,
                "extent_mm": _bounds(world_bounds(mask[box], affine, lo)),
            }
        )
    return out


def _label_values_refused(details: dict[str, Any], values: NDArray[Any], path: Path) -> bool:
    """Whether ``values`` are no label map; then say why in ``details`` instead of
    listing every value as a structure (``not_a_label_map``, ``values``)."""
    try:
        check_label_values(values, source=path)
    except LabelError as exc:
        data = np.asarray(values)
        details["not_a_label_map"] = str(exc)
        details["values"] = {"min": float(data.min()), "max": float(data.max())}
        details["structures"] = []
        return True
    return False


def _not_a_label_map(details: dict[str, Any], exc: LabelError) -> dict[str, Any]:
    """``details`` of a file whose voxels its reader refused as no label map (non-integer
    or non-finite values): its grid and why, as :func:`_label_values_refused` says it."""
    if "is not a label map" not in str(exc):
        raise exc
    details["not_a_label_map"] = str(exc)
    details["structures"] = []
    return details


def describe_volume(volume: Volume) -> dict[str, Any]:
    """Grid and foreground of a voxel mask (shape, spacing, voxels, planes per axis).

    A mask that reads as a sparse annotation
    (:func:`slicerecon.plane_detection.detect_planes`) is described as one:
    ``kind`` "sparse annotation", ``read_as`` its planes, and ``drawn_volume_mm3``
    (its drawn voxels, not the structure's volume) in place of ``volume_mm3``.
    """
    from ..plane_detection import detect_planes

    reading = detect_planes(volume.mask) if not volume.is_empty else None
    sparse = reading is not None and not reading.dense
    info: dict[str, Any] = {
        "kind": "sparse annotation" if sparse else "voxel mask",
        "shape": list(volume.shape),
        "spacing_mm": _round(volume.spacing, 6),
        "oblique": volume.is_oblique,
        "foreground_voxels": int(np.count_nonzero(volume.mask)),
    }
    if sparse:
        assert reading is not None
        info["read_as"] = reading.describe(volume.spacing, volume.affine)
        info["drawn_volume_mm3"] = round(volume.volume_mm3, 3)
    else:
        info["volume_mm3"] = round(volume.volume_mm3, 3)
    if not volume.is_empty:
        lo, hi = volume.bounding_box_mm()
        info["bounding_box_mm"] = {"min": _round(lo, 3), "max": _round(hi, 3)}
        for name, ax in zip(AXIS_NAMES, range(3), strict=True):
            planes = volume.occupied_planes(ax)
            info[f"planes_{name}"] = {
                "occupied": int(planes.size),
                "first": int(planes[0]),
                "last": int(planes[-1]),
            }
    return info


def describe_sections(sections: CrossSections) -> dict[str, Any]:
    """Planes of a sparse input: count, axis, positions (mm), gaps, grid."""
    gaps = sections.gaps
    areas = [sections.area_mm2(p) for p in range(sections.n_planes)]
    return {
        "kind": "cross-sections",
        "planes": sections.n_planes,
        "axis": AXIS_NAMES[sections.axis],
        "positions_mm": _round(sections.positions, 4),
        "gap_mm": None
        if gaps.size == 0
        else {"min": round(float(gaps.min()), 4), "max": round(float(gaps.max()), 4)},
        # positions within the plane tolerance are one plane: gaps within twice it, one spacing
        "uniform_spacing": bool(gaps.size == 0 or np.ptp(gaps) <= 2 * PLANE_TOLERANCE_MM),
        "area_mm2": _round(areas, 2),
        "in_plane_shape": list(sections.masks.shape[1:]),
        "grid_shape": list(sections.grid_shape),
        "spacing_mm": _round(sections.spacing, 6),
    }


def _polygon_record(
    number: int, name: str, polygons: list[NDArray[np.float64]], normal: NDArray[np.float64] | None
) -> dict[str, Any]:
    record: dict[str, Any] = {"number": number, "name": name, "contours": len(polygons)}
    if not polygons:
        return record
    points = np.concatenate(polygons)
    record["extent_mm"] = {
        "min": _round(points.min(axis=0), 3),
        "max": _round(points.max(axis=0), 3),
    }
    if orientation_count(polygons) > 1:  # planes of several orientations (a radial set)
        record["planes"] = plane_count(polygons)
        record["orientations"] = orientation_count(polygons)
    elif normal is not None:
        positions = np.array([float(p.mean(axis=0) @ normal) for p in polygons])
        distinct = np.unique(np.round(positions, 2))
        record["planes"] = int(distinct.size)
        record["positions_mm"] = {
            "first": round(float(distinct[0]), 3),
            "last": round(float(distinct[-1]), 3),
        }
    return record


def _say_refused_by_run(series: dict[str, Any], folder: Path, allow_irregular: bool) -> None:
    """One warning when ``info`` describes a series with irregular slice spacing as
    ``--allow-irregular`` reads it, and ``run`` (without it) refuses the series."""
    if series.get("regular_spacing") is False and not allow_irregular:
        logger.warning(
            "%s: slicerecon run refuses this series (irregular slice spacing) unless "
            "--allow-irregular; it is described here as that option reads it",
            folder,
        )


def _describe_rtstruct(
    path: Path, image_dir: Path | None, allow_irregular: bool = False
) -> dict[str, Any]:

    details: dict[str, Any] = {}
    rois = []
    for number, name, polygons, note in roi_contours(path):
        record = _polygon_record(number, name, polygons, _main_normal(polygons))
        if note:
            record["note"] = note
        rois.append(record)
    details["rois"] = rois
    if image_dir is not None:
        details["image_series"] = {
            "path": str(image_dir),
            **dicom_info(image_dir, allow_irregular=True),
        }
        _say_refused_by_run(details["image_series"], image_dir, allow_irregular)
    return details


def _describe_contours(path: Path) -> dict[str, Any]:
    """Each structure of a contour file: its polygons, planes and extent."""
    structures = []
    everything = []
    for structure, polygons in contour_structures(path):
        normal = _main_normal(polygons)
        record = _polygon_record(structure.value, structure.name, polygons, normal)
        record["value"] = record.pop("number")
        structures.append(record)
        everything.extend(polygons)
    return {"structures": structures, "orientations": orientation_count(everything)}


def _main_normal(polygons: list[NDArray[np.float64]]) -> NDArray[np.float64] | None:
    """The normal of a structure's largest polygon, signed so its largest component is > 0."""
    if not polygons:
        return None
    normal = max((polygon_normal(p) for p in polygons), key=lambda na: na[1])[0]
    return normal if normal[np.argmax(np.abs(normal))] > 0 else -normal


def describe_input(
    path: str | os.PathLike[str],
    *,
    label: int | str | None = None,
    allow_irregular: bool = False,
    memory_budget_gb: float = DEFAULT_MEMORY_BUDGET_GB,
) -> dict[str, Any]:
    """Describe any input :func:`~slicerecon.io.load_input` reads, structure by structure.

    Parameters
    ----------
    path : path-like
        Any supported input.
    label : int or str, optional
        Also describe the planes or voxels of this one structure as they would
        be reconstructed (``selected``).
    allow_irregular : bool
        As for :func:`~slicerecon.io.load_input`.
    memory_budget_gb : float
        As for :func:`~slicerecon.io.load_input`.

    Returns
    -------
    dict
        JSON-ready: ``path``, ``format``, the grid where there is one, and the
        structures: ``structures`` (label maps: value, name, voxels, volume,
        planes, extent), ``segments`` (SEG), ``rois`` (RTSTRUCT: number, name,
        contours, planes, extent, or a note why there is nothing), and for
        single-structure inputs the summary of :func:`describe_volume` or
        :func:`describe_sections`.

    Raises
    ------
    InputError
        What :func:`~slicerecon.io.load_input` raises for unreadable files;
        never for a file that holds several structures or empty ones.
    """

    check_budget(memory_budget_gb)
    with reading(path):
        kind = detect_kind(path)
        details: dict[str, Any] = {"path": str(path), "format": kind.kind}
        if kind.kind == "nifti":
            import nibabel as nib

            from .nifti import read_label_values

            try:
                values, affine = read_label_values(kind.path, memory_budget_gb=memory_budget_gb)
            except LabelError as exc:  # float voxels that are no whole numbers: an image
                header = nib.load(kind.path)
                details["axcodes"] = "".join(str(c) for c in nib.aff2axcodes(header.affine))
                details.update(_grid(header.affine, tuple(header.shape[:3])))
                return _not_a_label_map(details, exc)
            details["axcodes"] = "".join(str(c) for c in nib.aff2axcodes(affine))
            details.update(_grid(affine, values.shape))
            if not _label_values_refused(details, values, kind.path):
                details["structures"] = describe_label_map(values, affine)
                details["labels"] = {str(s["value"]): s["voxels"] for s in details["structures"]}
        elif kind.kind == "nrrd":
            header = nrrd_info(kind.path)
            try:
                label_map = read_nrrd_label_map(kind.path, memory_budget_gb=memory_budget_gb)
            except LabelError as exc:  # float voxels that are no whole numbers: an image
                details["coordinates"] = header.coordinates
                details.update(_grid(header.affine, header.shape))
                return _not_a_label_map(details, exc)
            details["coordinates"] = label_map.coordinates
            details.update(_grid(label_map.affine, label_map.shape))
            if not _label_values_refused(details, label_map.labels, kind.path):
                records = describe_label_map(
                    label_map.labels,
                    label_map.affine,
                    names={s.value: s.name for s in label_map.structures},
                )
                for record, structure in zip(records, label_map.structures, strict=True):
                    colour = structure.colour
                    record["colour"] = None if colour is None else list(colour)
                details["structures"] = records
            if header.is_segmentation:
                details["segments"] = [s.to_dict() for s in header.segments]
        elif kind.kind == "vti":
            image = read_vti(kind.path, memory_budget_gb=memory_budget_gb)
            details.update(_grid(image.affine, image.values.shape))
            if not _label_values_refused(details, np.asarray(image.values), kind.path):
                details["structures"] = describe_label_map(np.asarray(image.values), image.affine)
        elif kind.kind == "dicom-series":
            # described on the grid --allow-irregular would give: info never refuses
            details["dicom"] = dicom_info(kind.path, allow_irregular=True)
            _say_refused_by_run(details["dicom"], kind.path, allow_irregular)
            values, affine = read_dicom_series_values(
                kind.path, allow_irregular=True, memory_budget_gb=memory_budget_gb
            )
            details.update(_grid(affine, values.shape))
            if not _label_values_refused(details, values, kind.path):
                details["structures"] = describe_label_map(values, affine)
        elif kind.kind == "dicom-seg":
            details["dicom"] = dicom_info(kind.path)
            segments = []
            for segment in details["dicom"]["segments"]:
                try:
                    volume = read_dicom_seg(
                        kind.path, segment=segment["number"], memory_budget_gb=memory_budget_gb
                    )
                except EmptyMaskError:
                    segments.append({**segment, "voxels": 0})
                    continue
                record = describe_label_map(volume.mask.astype(np.uint8), volume.affine)[0]
                record.pop("value")
                record.pop("name")
                segments.append({**segment, **record})
            details["segments"] = segments
        elif kind.kind == "rtstruct":
            details.update(_describe_rtstruct(kind.path, kind.image_dir, allow_irregular))
        elif kind.kind == "contours":
            details.update(_describe_contours(kind.path))
        elif kind.kind == "mesh":
            from .mesh import read_mesh

            mesh = read_mesh(kind.path)
            details["mesh"] = {
                "vertices": int(len(mesh.vertices)),
                "faces": int(len(mesh.faces)),
                "watertight": bool(mesh.is_watertight),
                "extent_mm": {"min": _round(mesh.bounds[0], 3), "max": _round(mesh.bounds[1], 3)},
            }
        single = kind.kind == "mesh" or (
            kind.kind == "contours" and details.get("orientations") == 1
        )
        single = single and len(details.get("structures", [None])) == 1
        if single or label is not None:
            data = load_input(
                kind.path,
                label=label,
                allow_irregular=allow_irregular,
                memory_budget_gb=memory_budget_gb,
            )
            summary = describe_volume(data) if isinstance(data, Volume) else describe_sections(data)
            if single:
                details.update(summary)
            else:
                details["selected"] = {"label": label, **summary}
    return details
