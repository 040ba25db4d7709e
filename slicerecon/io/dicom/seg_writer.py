"""Write a label map as a DICOM SEG (Segmentation Storage) that refers to its image series.

The SEG is made by highdicom (:class:`highdicom.seg.Segmentation`): BINARY,
one segment per structure, one frame per image slice a segment covers (empty
frames omitted), each frame referring to its source image
(SourceImageSequence / DerivationImageSequence), in the images' study and
frame of reference. highdicom writes everything the standard requires
(Multi-frame Dimension module, functional groups, referenced series); this
module only chooses what goes in.

Segments
--------
* The standard numbers segments 1, 2, ... without gaps, and highdicom enforces
  it; structures are numbered in the order of their values, so a label map
  with values 1..N keeps them as SegmentNumbers. Each segment's
  SegmentDescription records the label value (``"label value 5"``).
* SegmentLabel: the structure's name, else ``"Segment_<value>"``
  (:func:`~slicerecon.io.dicom.derived.dicom_name`: the name every output
  gives it), in UTF-8 (SpecificCharacterSet ISO_IR 192).
* RecommendedDisplayCIELabValue: the structure's colour (RGB converted to
  CIELab by highdicom), else one of
  :data:`~slicerecon.labels.DEFAULT_COLOURS`.
* SegmentedPropertyCategory / Type: those of the input SEG's segment of the
  same label when the input was a SEG (``reference``: Liver / Organ stays
  Liver / Organ); else SCT 85756007 "Tissue" / SCT 85756007 "Tissue" (3D
  Slicer's code for a segment of unknown kind: slicerecon does not know what a
  structure is).
* SegmentAlgorithmType SEMIAUTOMATIC (the surface is computed from a person's
  cross-sections), algorithm "slicerecon" of family "Artificial Intelligence"
  (CID 7162) with slicerecon's version.

Grid: the label map is placed on the series grid by
:func:`~slicerecon.io.dicom.derived.labels_on_series`.

Overlaps: a layered label map (structures that overlap in different layers)
is written with each segment whole: a SEG's segments may overlap, each has
its own frames.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from ... import __version__
from ...errors import DependencyError, EmptyMaskError, FormatError
from ...labels import Structure
from ..atomic import atomic_path
from .derived import (
    SourceSeries,
    check_label_map,
    dicom_name,
    display_colour,
    layers_on_series,
    load_source_series,
    structure_mask,
)
from .sniff import PARSE_ERRORS, read_dicom_header

__all__ = ["SEG_ALGORITHM_NAME", "write_seg"]

logger = logging.getLogger(__name__)

SEG_ALGORITHM_NAME = "slicerecon"
"""AlgorithmName of every segment written."""


def _reference_codes(reference: str | os.PathLike[str] | None) -> dict[str, tuple[Any, Any]]:
    """The segmented property category and type of each segment of an input SEG, by
    SegmentLabel (none for a SEG whose codes cannot be read: the default is written)."""
    if reference is None:
        return {}
    from highdicom.sr import CodedConcept

    def concept(item: Any) -> Any:
        return CodedConcept(
            str(item.CodeValue), str(item.CodingSchemeDesignator), str(item.CodeMeaning)
        )

    found = {}
    try:
        ds = read_dicom_header(reference)
        for item in ds.get("SegmentSequence", []):
            found[str(item.SegmentLabel)] = (
                concept(item.SegmentedPropertyCategoryCodeSequence[0]),
                concept(item.SegmentedPropertyTypeCodeSequence[0]),
            )
    except (*PARSE_ERRORS, FormatError, ValueError, TypeError, IndexError):
        logger.info("%s: its segments' codes cannot be read; Tissue is written", reference)
        return {}
    return found


def _segment_descriptions(
    structures: Sequence[Structure], codes_of: dict[str, tuple[Any, Any]]
) -> list[Any]:
    from highdicom import AlgorithmIdentificationSequence
    from highdicom.color import CIELabColor
    from highdicom.seg import SegmentDescription
    from pydicom.sr.codedict import codes

    algorithm = AlgorithmIdentificationSequence(
        name=SEG_ALGORITHM_NAME,
        family=codes.cid7162.ArtificialIntelligence,
        version=str(__version__),
    )
    out = []
    for number, structure in enumerate(structures, start=1):
        category, kind = codes_of.get(structure.name, (codes.SCT.Tissue, codes.SCT.Tissue))
        description = SegmentDescription(
            segment_number=number,
            segment_label=dicom_name(structure),
            segmented_property_category=category,
            segmented_property_type=kind,
            algorithm_type="SEMIAUTOMATIC",
            algorithm_identification=algorithm,
            display_color=CIELabColor.from_rgb(*display_colour(structure, number - 1)),
        )
        description.SegmentDescription = f"label value {structure.value}"
        out.append(description)
    return out


def write_seg(
    labels: ArrayLike,
    affine: ArrayLike,
    structures: Sequence[Structure],
    source_images: str | os.PathLike[str] | Sequence[Any] | SourceSeries,
    path: str | os.PathLike[str],
    *,
    allow_irregular: bool = False,
    series_number: int = 901,
    series_description: str = "slicerecon reconstruction",
    reference: str | os.PathLike[str] | None = None,
) -> Path:
    """Write a label map as a BINARY DICOM SEG referring to its image series.

    Parameters
    ----------
    labels : array_like of shape (I, J, K) or (L, I, J, K), integer
        Label values, 0 for background, on the grid of the image series
        (array axes (column, row, slice), as :func:`read_dicom_series` reads
        it), or on a grid sharing its in-plane pixels and slice direction
        (:func:`~slicerecon.io.dicom.derived.labels_on_series`); or a layered
        label map whose structures overlap across layers, each written whole
        (:func:`~slicerecon.io.dicom.derived.check_label_map`).
    affine : array_like of shape (4, 4)
        Voxel index of ``labels`` → DICOM patient LPS mm.
    structures : sequence of Structure
        One per label value (every non-zero value of ``labels`` needs one); a
        structure without voxels becomes a segment without frames.
    source_images : path-like, sequence of pydicom.Dataset or path-like, or SourceSeries
        The image series: its directory, or its images (datasets, headers
        suffice, or file paths) in any order, or the series already loaded
        (:func:`~slicerecon.io.dicom.derived.load_source_series`).
    path : path-like
        Output file, written atomically (temporary file, then rename).
    allow_irregular : bool
        Accept an image series with uneven slice spacing (``--allow-irregular``).
    series_number : int
        SeriesNumber of the new SEG series.
    series_description : str
        SeriesDescription of the new SEG series.
    reference : path-like, optional
        The SEG the structures were read from: each segment keeps the
        category and type codes of its segment of the same label.

    Returns
    -------
    Path
        The file written. Segment ``n`` (1-based) is the ``n``-th structure in
        order of value; see the module docstring for labels, colours and codes.

    Raises
    ------
    OptionError, LabelError
        Bad labels or structures (:func:`~slicerecon.io.dicom.derived.check_label_map`).
    InputError, FormatError, GeometryError
        The image series cannot be read (or mixes studies or patients: see
        :func:`~slicerecon.io.dicom.derived.load_source_series`), the label map
        is not on its grid, or highdicom refuses the images.
    EmptyMaskError
        No structure holds a voxel on the series' images.
    DependencyError
        highdicom is not installed.
    """
    values, aff, chosen = check_label_map(labels, affine, structures)
    try:
        from highdicom.seg import Segmentation
    except ImportError as exc:  # pragma: no cover - highdicom is a dependency
        raise DependencyError("writing a DICOM SEG needs highdicom: pip install highdicom") from exc

    series = load_source_series(source_images, allow_irregular=allow_irregular)
    on_grid = layers_on_series(values, aff, series)[:, :, :, series.planes]
    ordered = sorted(chosen, key=lambda s: s.value)
    if len(on_grid) == 1:
        # one segment number per pixel: highdicom's label-map form of a BINARY SEG
        lut = np.zeros(
            int(max(s.value for s in ordered)) + 1,
            dtype=np.uint8 if len(ordered) < 256 else np.uint16,
        )
        for number, structure in enumerate(ordered, start=1):
            lut[structure.value] = number
        frames = np.ascontiguousarray(lut[on_grid[0]].transpose(2, 1, 0))
        holds = [bool(np.any(frames == n)) for n in range(1, len(ordered) + 1)]
    else:
        # segments that overlap: one binary plane per segment (frames, rows, columns, segments)
        frames = np.stack(
            [structure_mask(on_grid, s.value).transpose(2, 1, 0) for s in ordered], axis=-1
        )
        holds = [bool(frames[..., n].any()) for n in range(len(ordered))]
    if not any(holds):
        raise EmptyMaskError(
            f"no structure holds a voxel on the images of {series.name}: "
            "there is nothing to write in a SEG"
        )
    for structure, held in zip(ordered, holds, strict=True):
        if not held:
            # said only when it has voxels beyond the images (none at all: said upstream)
            say = logger.warning if np.any(values == structure.value) else logger.info
            say(
                "structure %d (%s) holds no voxel on the images; its segment has no frame",
                structure.value,
                structure.name,
            )
    try:
        segmentation = _segmentation(
            Segmentation,
            series,
            frames,
            _segment_descriptions(ordered, _reference_codes(reference)),
            series_number,
            series_description,
        )
    except (ValueError, TypeError, KeyError, AttributeError) as exc:
        raise FormatError(
            f"highdicom cannot make a SEG referring to {series.name} "
            f"({type(exc).__name__}: {' '.join(str(exc).split())[:240]})"
        ) from exc
    target = Path(path)
    with atomic_path(target) as tmp:
        segmentation.save_as(tmp)
    logger.info(
        "wrote DICOM SEG %s: %d segments, %d frames, referring to %s",
        target,
        len(ordered),
        int(segmentation.NumberOfFrames),
        series.name,
    )
    return target


_TYPE2_COPIED = (
    "PatientName",
    "PatientID",
    "PatientBirthDate",
    "PatientSex",
    "StudyID",
    "StudyDate",
    "StudyTime",
    "ReferringPhysicianName",
    "AccessionNumber",
)
"""Patient and study attributes a SEG copies from its source images (Type 2 there and in the
SEG: present, possibly empty)."""


def _with_type2_attributes(images: Sequence[Any]) -> list[Any]:
    """The source headers with every attribute of :data:`_TYPE2_COPIED` present.

    Research series often leave out Type 2 attributes (``PatientBirthDate``,
    ``StudyID``); highdicom reads them from the source images. An absent one is
    written empty on a copy of the header (the files are not touched), as the
    standard allows for Type 2.
    """
    import copy

    out = []
    absent: set[str] = set()
    for ds in images:
        missing = [name for name in _TYPE2_COPIED if name not in ds]
        if missing:
            ds = copy.copy(ds)
            for name in missing:
                setattr(ds, name, "")
            absent.update(missing)
        out.append(ds)
    if absent:
        logger.info("the source images lack %s: empty in the SEG", ", ".join(sorted(absent)))
    return out


def _segmentation(
    segmentation_class: Any,
    series: Any,
    frames: Any,
    descriptions: list[Any],
    series_number: int,
    series_description: str,
) -> Any:
    from pydicom.uid import generate_uid

    from ... import __version__

    return segmentation_class(
        source_images=_with_type2_attributes(series.images),
        pixel_array=frames,
        segmentation_type="BINARY",
        segment_descriptions=descriptions,
        series_instance_uid=generate_uid(),
        series_number=series_number,
        sop_instance_uid=generate_uid(),
        instance_number=1,
        manufacturer="slicerecon",
        manufacturer_model_name="slicerecon",
        software_versions=str(__version__),
        device_serial_number="0",
        content_label="SLICERECON",
        content_description="surface reconstructed from cross-sections",
        content_creator_name="slicerecon^",
        omit_empty_frames=True,
        series_description=series_description,
        specific_character_set="ISO_IR 192",  # UTF-8: names keep their accents
    )
