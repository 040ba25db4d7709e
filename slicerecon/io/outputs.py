"""The label-map outputs of a run: NIfTI, 3D Slicer segmentation, DICOM SEG and RTSTRUCT.

Every ``slicerecon run`` writes the reconstructed label map twice, on the
input's grid with the input's label values:

* ``labels.nii.gz`` (NIfTI, RAS: :func:`slicerecon.io.labelmap.write_label_map`;
  with the sform/qform codes of a NIfTI input, given as ``source``);
* ``labels.seg.nrrd`` (a 3D Slicer segmentation with the structures' names and
  colours: :func:`slicerecon.io.nrrd_writer.write_seg_nrrd`).

When the input comes with its DICOM image series (a DICOM mask series, an
RTSTRUCT beside its series, or any input given ``image_dir``) it also writes

* ``seg.dcm``: a DICOM SEG made by highdicom referring to that series
  (:func:`slicerecon.io.dicom.seg_writer.write_seg`);

and for an RTSTRUCT input

* ``rtstruct.dcm``: the reconstruction as contours on every image slice it
  crosses, with the input's ROI names and colours
  (:func:`slicerecon.io.rtstruct_writer.write_rtstruct`).

A DICOM output that cannot be made (the series lacks the UIDs a derived object
refers to, mixes studies or patients, the label map is not on its grid; an
RTSTRUCT input of another patient or frame of reference than the series beside
it) is logged as a warning and listed as skipped; the other outputs stand. No
DICOM object is ever written labelled with another patient, or referring to
images in another frame of reference, than its input.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import NDArray

from ..errors import SlicereconError
from ..labels import LPS_TO_RAS, Structure
from .dicom.seg_writer import write_seg
from .labelmap import write_label_map
from .limits import reading, writing
from .nrrd_writer import write_seg_nrrd
from .rtstruct_writer import write_rtstruct

if TYPE_CHECKING:
    from .dicom.derived import SourceSeries

__all__ = ["LABEL_OUTPUT_FILES", "LabelOutputs", "dicom_image_series", "write_label_outputs"]

_NIFTI, _SEG_NRRD, _SEG, _RTSTRUCT = "labels.nii.gz", "labels.seg.nrrd", "seg.dcm", "rtstruct.dcm"
LABEL_OUTPUT_FILES = (_NIFTI, _SEG_NRRD, _SEG, _RTSTRUCT)
"""The names :func:`write_label_outputs` may write in a case folder."""

logger = logging.getLogger(__name__)


@dataclass
class LabelOutputs:
    """What :func:`write_label_outputs` wrote.

    Attributes
    ----------
    written : dict of str to Path
        Output name (``"labels"``, ``"seg_nrrd"``, ``"seg"``, ``"rtstruct"``) → file.
    skipped : dict of str to str
        Output name → why it was not written.
    """

    written: dict[str, Path] = field(default_factory=dict)
    skipped: dict[str, str] = field(default_factory=dict)

    def to_dict(self) -> dict[str, object]:
        """JSON-ready: file names written and reasons for those skipped."""
        return {
            "written": {k: v.name for k, v in self.written.items()},
            "skipped": dict(self.skipped),
        }


def dicom_image_series(
    kind: str, path: str | os.PathLike[str], image_dir: str | os.PathLike[str] | None
) -> Path | None:
    """The DICOM image series an input comes with, if any.

    Parameters
    ----------
    kind : str
        The input's kind (:func:`slicerecon.io.detect_kind`).
    path : path-like
        The input.
    image_dir : path-like or None
        The series directory given with the input (``image_dir``), or found
        beside an RTSTRUCT.

    Returns
    -------
    Path or None
        ``image_dir`` when given; the input itself for a DICOM mask series;
        None otherwise.
    """
    if image_dir is not None:
        return Path(image_dir)
    if kind == "dicom-series":
        return Path(path)
    return None


def write_label_outputs(
    outdir: str | os.PathLike[str],
    labels: NDArray[np.integer],
    affine: NDArray[np.float64],
    structures: Sequence[Structure],
    *,
    coordinates: str = "RAS",
    series: str | os.PathLike[str] | None = None,
    rtstruct: str | os.PathLike[str] | None = None,
    allow_irregular: bool = False,
    source: str | os.PathLike[str] | None = None,
    layers: NDArray[np.integer] | None = None,
    seg: str | os.PathLike[str] | None = None,
) -> LabelOutputs:
    """Write the reconstructed label map in every format the input's workflow reads.

    Parameters
    ----------
    outdir : path-like
        The run's output directory.
    labels : ndarray of shape (I, J, K), integer
        Label values (0 background) on the input's grid.
    affine : ndarray of shape (4, 4)
        Voxel index → world mm in ``coordinates``.
    structures : sequence of Structure
        The structures (values, names, colours) in the order to list them.
    coordinates : {"RAS", "LPS"}
        The frame of ``affine`` (LPS for DICOM inputs).
    series : path-like, optional
        The DICOM image series the input comes with (:func:`dicom_image_series`):
        ``seg.dcm`` is written referring to it.
    rtstruct : path-like, optional
        The RTSTRUCT the structures were read from: ``rtstruct.dcm`` is written
        (needs ``series``), copying its identifiers, ROI names and colours.
    allow_irregular : bool
        Accept uneven slice spacing in ``series`` (``--allow-irregular``).
    source : path-like, optional
        The input file. When it is NIfTI and the labels are on its grid,
        ``labels.nii.gz`` keeps its sform and qform codes (an MNI-coded input
        stays in MNI space; :func:`slicerecon.io.nifti.nifti_xform_codes`);
        otherwise both are 1 (scanner anatomical).
    layers : ndarray of shape (L, I, J, K), integer, optional
        Structures that overlap, each whole, as a layered label map (each layer
        holds structures that do not overlap). ``labels.seg.nrrd`` (one layer
        each), ``seg.dcm`` (overlapping segments) and ``rtstruct.dcm`` are
        written from it; ``labels.nii.gz`` holds ``labels``, one structure per
        voxel.
    seg : path-like, optional
        The DICOM SEG the structures were read from: ``seg.dcm`` keeps each
        segment's category and type codes (without ``series``: not written,
        with a warning, as for an RTSTRUCT).

    Returns
    -------
    LabelOutputs

    Raises
    ------
    SlicereconError
        When ``labels.nii.gz`` or ``labels.seg.nrrd`` cannot be written; DICOM
        outputs that cannot be made are skipped with a warning instead.
    """

    out = Path(outdir)
    result = LabelOutputs()
    codes = None
    if source is not None:
        from .nifti import nifti_xform_codes

        ras = np.asarray(affine, dtype=np.float64)
        codes = nifti_xform_codes(source, affine=LPS_TO_RAS @ ras if coordinates == "LPS" else ras)
    result.written["labels"] = write_label_map(
        labels, affine, out / _NIFTI, coordinates=coordinates, xform_codes=codes
    )
    whole = labels if layers is None else layers
    result.written["seg_nrrd"] = write_seg_nrrd(
        whole, affine, list(structures), out / _SEG_NRRD, coordinates=coordinates
    )
    if series is None:
        if rtstruct is not None:
            result.skipped["rtstruct"] = "the RTSTRUCT's image series was not found beside it"
            logger.warning(
                "%s: rtstruct.dcm and seg.dcm not written: its image series was not found "
                "beside it (pass the folder that holds both, or the series in one subfolder)",
                rtstruct,
            )
        elif seg is not None:
            result.skipped["seg"] = "the SEG's image series was not found beside it"
            logger.warning(
                "%s: seg.dcm not written: its image series was not found beside it (pass "
                "the folder that holds both, or the series in one subfolder)",
                seg,
            )
        return result
    lps = np.asarray(affine, dtype=np.float64)
    if coordinates == "RAS":
        lps = LPS_TO_RAS @ lps
    chosen = [s for s in structures if np.any(whole == s.value)]
    if not chosen:
        result.skipped["seg"] = "no structure holds a voxel"
        return result
    wanted = ["seg"] + (["rtstruct"] if rtstruct is not None else [])
    try:
        with reading(series):
            images = _source_series(series, rtstruct, allow_irregular, structures)
    except SlicereconError as exc:
        logger.warning("%s not written: %s", " and ".join(f"{w}.dcm" for w in wanted), exc)
        result.skipped.update(dict.fromkeys(wanted, str(exc)))
        return result

    try:
        with writing(out / _SEG):
            result.written["seg"] = write_seg(whole, lps, chosen, images, out / _SEG, reference=seg)
    except SlicereconError as exc:
        logger.warning("seg.dcm not written: %s", exc)
        result.skipped["seg"] = str(exc)
    if rtstruct is not None:
        try:
            with writing(out / _RTSTRUCT):
                result.written["rtstruct"] = write_rtstruct(
                    whole,
                    lps,
                    list(structures),
                    images,
                    out / _RTSTRUCT,
                    reference=rtstruct,
                )
        except SlicereconError as exc:
            logger.warning("rtstruct.dcm not written: %s", exc)
            result.skipped["rtstruct"] = str(exc)
    return result


def _source_series(
    series: str | os.PathLike[str],
    rtstruct: str | os.PathLike[str] | None,
    allow_irregular: bool,
    structures: Sequence[Structure],
) -> SourceSeries:
    """The image series the DICOM outputs refer to, checked against the input RTSTRUCT.

    Raises
    ------
    SlicereconError
        The series cannot be read (several studies or patients, missing UIDs,
        ...), or the RTSTRUCT is of another patient or frame of reference
        (:func:`~slicerecon.io.dicom.derived.check_same_subject`).
    """
    from .dicom.derived import check_same_subject, load_source_series
    from .dicom.sniff import read_dicom_header
    from .limits import reading

    source = load_source_series(series, allow_irregular=allow_irregular)
    if rtstruct is not None:
        with reading(rtstruct):
            reference = read_dicom_header(Path(rtstruct), stop_before_pixels=True)
            check_same_subject(
                reference,
                source,
                what=f"the RTSTRUCT {Path(rtstruct)}",
                rois=[s.value for s in structures],
            )
    return source
