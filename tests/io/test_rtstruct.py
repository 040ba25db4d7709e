"""DICOM RTSTRUCT: ROI listing and selection, contours on the image grid or their own grid."""

from __future__ import annotations

import logging
from pathlib import Path

import dicom_factory as factory  # tests/io, on pytest's pythonpath
import numpy as np
import pydicom
import pytest
from pydicom.dataset import Dataset, FileMetaDataset
from pydicom.sequence import Sequence as DicomSequence
from pydicom.uid import ExplicitVRLittleEndian, generate_uid

from slicerecon.errors import EmptyMaskError, FormatError, GeometryError, InputError, LabelError
from slicerecon.io import load_input
from slicerecon.io.rtstruct import list_rois, read_rtstruct, read_rtstruct_annotation

RTSTRUCT_STORAGE = "1.2.840.10008.5.1.4.1.1.481.3"
N_VERTICES = 720
RADIUS, HOLE = 12.0, 5.0
CENTRE, HOLE_CENTRE = np.array([2.0, -3.0]), np.array([3.0, -2.0])
TUMOUR_SLICES = range(3, 11)
HOLE_SLICES = (5, 6)


def _ds(values) -> list[str]:
    return [f"{v:.10g}" for v in np.asarray(values, dtype=np.float64).ravel()]


def _ring(radius, centre_uv, affine, k, n=N_VERTICES):
    """A counter-clockwise n-gon on slice k of the grid.

    ``centre_uv`` is the centre's in-plane offset, mm, from the slice's first voxel centre
    along the row and column directions.
    """
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    u = affine[:3, 0] / np.linalg.norm(affine[:3, 0])
    v = affine[:3, 1] / np.linalg.norm(affine[:3, 1])
    on_slice = affine[:3, 3] + k * affine[:3, 2]
    uv = centre_uv + radius * np.c_[np.cos(t), np.sin(t)]
    return on_slice + uv[:, :1] * u + uv[:, 1:] * v


def _contour_item(points, kind="CLOSED_PLANAR", image_uid=None):
    item = Dataset()
    item.ContourGeometricType = kind
    item.NumberOfContourPoints = len(points)
    item.ContourData = _ds(points)
    if image_uid:
        ref = Dataset()
        ref.ReferencedSOPClassUID = "1.2.840.10008.5.1.4.1.1.4"
        ref.ReferencedSOPInstanceUID = image_uid
        item.ContourImageSequence = DicomSequence([ref])
    return item


def write_rtstruct(path, rois, *, modality="RTSTRUCT"):
    """Write an RTSTRUCT; ``rois`` maps (number, name) to a list of contour items or None."""
    sop_uid = generate_uid()
    meta = FileMetaDataset()
    meta.MediaStorageSOPClassUID = RTSTRUCT_STORAGE
    meta.MediaStorageSOPInstanceUID = sop_uid
    meta.TransferSyntaxUID = ExplicitVRLittleEndian
    ds = Dataset()
    ds.file_meta = meta
    ds.SOPClassUID = RTSTRUCT_STORAGE
    ds.SOPInstanceUID = sop_uid
    ds.Modality = modality
    ds.PatientName = "Synthetic^Phantom"
    ds.PatientID = "SLICERECON-TEST"
    ds.StudyInstanceUID = generate_uid()
    ds.SeriesInstanceUID = generate_uid()
    ds.StructureSetLabel = "test"
    frame_uid = generate_uid()
    roi_items, contour_items = [], []
    for (number, name), contours in rois.items():
        roi = Dataset()
        roi.ROINumber = number
        roi.ReferencedFrameOfReferenceUID = frame_uid
        roi.ROIName = name
        roi.ROIGenerationAlgorithm = "MANUAL"
        roi_items.append(roi)
        holder = Dataset()
        holder.ReferencedROINumber = number
        holder.ROIDisplayColor = [255, 0, 0]
        if contours is not None:
            holder.ContourSequence = DicomSequence(contours)
        contour_items.append(holder)
    ds.StructureSetROISequence = DicomSequence(roi_items)
    ds.ROIContourSequence = DicomSequence(contour_items)
    ds.save_as(path, enforce_file_format=True)
    return path


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    """An MR series on an axial LPS grid and an RTSTRUCT with three ROIs drawn on it."""
    root = tmp_path_factory.mktemp("rt")
    affine = factory.affine_from_geometry(
        [1, 0, 0], [0, 1, 0], [0.7, 0.7], [0, 0, 2.0], [-40.0, -35.0, -20.0]
    )
    shape = (120, 110, 16)
    files = factory.write_series(root / "series", np.zeros(shape, np.uint16), affine)
    uids = factory.read_uids(files)
    centre, hole_centre = CENTRE - affine[:2, 3], HOLE_CENTRE - affine[:2, 3]  # axial grid
    tumour = []
    for k in TUMOUR_SLICES:
        tumour.append(_contour_item(_ring(RADIUS, centre, affine, k), image_uid=uids[k]))
        if k in HOLE_SLICES:
            tumour.append(_contour_item(_ring(HOLE, hole_centre, affine, k)))
    tumour.append(_contour_item(_ring(1.0, centre, affine, 12, n=1), kind="POINT"))
    tumour.append(_contour_item(_ring(3.0, centre, affine, 13, n=5), kind="OPEN_PLANAR"))
    lo, hi = -20.05, -14.05
    cord = [
        _contour_item(np.array([[lo, lo, z], [hi, lo, z], [hi, hi, z], [lo, hi, z]]))
        for z in (-16.0, -14.0, -12.0)
    ]
    rois = {(7, "Tumour"): tumour, (2, "Cord"): cord, (9, "Empty"): None}
    path = write_rtstruct(root / "series" / "rtstruct.dcm", rois)
    return {
        "path": path,
        "series": root / "series",
        "affine": affine,
        "shape": shape,
        "root": root,
        "files": files,
    }


def _expected(affine, shape, k):
    """Analytic disk (minus hole) at the pixel centres of slice k, and an 'unsure' band."""
    i, j = np.mgrid[0 : shape[0], 0 : shape[1]]
    x = affine[0, 3] + affine[0, 0] * i - CENTRE[0]
    y = affine[1, 3] + affine[1, 1] * j - CENTRE[1]
    r = np.hypot(x, y)
    inside = r < RADIUS
    unsure = np.abs(r - RADIUS) < 1e-3  # the 720-gon lies within 1.1e-4 mm of the circle
    if k in HOLE_SLICES:
        rh = np.hypot(x + CENTRE[0] - HOLE_CENTRE[0], y + CENTRE[1] - HOLE_CENTRE[1])
        inside &= rh >= HOLE
        unsure |= np.abs(rh - HOLE) < 1e-3
    return inside, unsure


def test_list_rois(case):
    assert list_rois(case["path"]) == [(7, "Tumour"), (2, "Cord"), (9, "Empty")]


def test_read_on_the_image_grid(case, caplog):
    with caplog.at_level(logging.WARNING, logger="slicerecon.io.rtstruct"):
        cs = read_rtstruct(case["path"], roi="Tumour", image_dir=case["series"])
    assert "skipped 1 POINT, 1 OPEN_PLANAR contours" in caplog.text
    assert cs.axis == 2 and cs.grid_shape == case["shape"]
    np.testing.assert_allclose(cs.affine, case["affine"], atol=1e-9)
    np.testing.assert_array_equal(cs.indices, list(TUMOUR_SLICES))
    np.testing.assert_allclose(cs.positions, [-20.0 + 2.0 * k for k in TUMOUR_SLICES], atol=1e-6)
    for p, k in enumerate(TUMOUR_SLICES):
        inside, unsure = _expected(case["affine"], case["shape"], k)
        np.testing.assert_array_equal(cs.masks[p][~unsure], inside[~unsure])
    assert not cs.masks[HOLE_SLICES[0] - TUMOUR_SLICES[0]][61, 47]  # (3.0, -1.9) mm: hole
    assert cs.masks[0][61, 47]


def test_read_without_the_image_series(case):
    cs = read_rtstruct(case["path"], roi=7, pixel_spacing=0.1)
    np.testing.assert_allclose(cs.normal, [0.0, 0.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(cs.positions, [-20.0 + 2.0 * k for k in TUMOUR_SLICES], atol=1e-6)
    np.testing.assert_array_equal(cs.indices, np.arange(len(TUMOUR_SLICES)))
    ngon = 0.5 * N_VERTICES * np.sin(2.0 * np.pi / N_VERTICES)
    for p, k in enumerate(TUMOUR_SLICES):
        area = ngon * (RADIUS**2 - (HOLE**2 if k in HOLE_SLICES else 0.0))
        assert cs.area_mm2(p) == pytest.approx(area, rel=0.01)


@pytest.mark.parametrize("roi", [2, "Cord", " cord ", "2"])
def test_roi_selection_by_number_or_name(case, roi):
    cs = read_rtstruct(case["path"], roi=roi, image_dir=case["series"])
    np.testing.assert_array_equal(cs.indices, [2, 3, 4])
    # square from -20.05 to -14.05 mm: x = -40 + 0.7 i for i = 29 .. 37,
    # y = -35 + 0.7 j for j = 22 .. 29
    expected = np.zeros(case["shape"][:2], bool)
    expected[29:38, 22:30] = True
    for p in range(3):
        np.testing.assert_array_equal(cs.masks[p], expected)


def test_load_input_finds_the_rtstruct_beside_its_series(case):
    cs = load_input(case["series"], roi="Tumour")
    assert cs.grid_shape == case["shape"]
    np.testing.assert_array_equal(cs.indices, list(TUMOUR_SLICES))


def test_oblique_image_grid(tmp_path):
    angle = np.deg2rad(20.0)
    row, col = [1.0, 0.0, 0.0], [0.0, np.cos(angle), np.sin(angle)]
    normal = np.cross(row, col)
    affine = factory.affine_from_geometry(row, col, [0.8, 0.8], 2.5 * normal, [-30, -30, 5])
    factory.write_series(tmp_path / "s", np.zeros((80, 80, 10), np.uint16), affine)
    contours = [_contour_item(_ring(RADIUS, [32.0, 30.0], affine, k)) for k in (2, 3, 7)]
    path = write_rtstruct(tmp_path / "rt.dcm", {(1, "Lesion"): contours})
    cs = read_rtstruct(path, image_dir=tmp_path / "s")
    np.testing.assert_array_equal(cs.indices, [2, 3, 7])
    np.testing.assert_allclose(cs.normal, normal, atol=1e-9)
    ngon = 0.5 * N_VERTICES * np.sin(2.0 * np.pi / N_VERTICES) * RADIUS**2
    assert cs.area_mm2(0) == pytest.approx(ngon, rel=0.02)


def test_roi_errors(case):
    with pytest.raises(LabelError, match="holds 3 ROIs \\(7: Tumour, 2: Cord, 9: Empty\\)"):
        read_rtstruct(case["path"])
    with pytest.raises(LabelError, match="ROI 'Liver' is not in .*: 7: Tumour, 2: Cord"):
        read_rtstruct(case["path"], roi="Liver")
    with pytest.raises(LabelError, match="ROI 5 is not in"):
        read_rtstruct(case["path"], roi=5)
    with pytest.raises(EmptyMaskError, match="ROI 9 \\(Empty\\) has no contours"):
        read_rtstruct(case["path"], roi="Empty")


def test_only_non_closed_contours_is_empty(tmp_path):
    affine = np.eye(4)
    path = write_rtstruct(
        tmp_path / "rt.dcm",
        {(1, "Marker"): [_contour_item(_ring(1.0, [0, 0], affine, 0, n=1), kind="POINT")]},
    )
    with pytest.raises(EmptyMaskError, match="no closed planar contour"):
        read_rtstruct(path)


def test_contours_not_parallel_to_the_image_grid(case, tmp_path):
    c, s = np.cos(np.deg2rad(30.0)), np.sin(np.deg2rad(30.0))
    tilted = np.array(
        [
            [-10, -10 * c, -10 * s],
            [10, -10 * c, -10 * s],
            [10, 10 * c, 10 * s],
            [-10, 10 * c, 10 * s],
        ]
    )
    path = write_rtstruct(
        tmp_path / "rt.dcm",
        {(1, "Tilted"): [_contour_item(tilted + [0, 0, z]) for z in (0.0, 3.0)]},
    )
    with pytest.raises(GeometryError, match="not parallel to any slice direction .* 30°"):
        read_rtstruct(path, image_dir=case["series"], roi=1)
    cs = read_rtstruct(path, pixel_spacing=1.0)  # on their own grid they are fine
    np.testing.assert_allclose(cs.normal, [0.0, -s, c], atol=1e-9)
    # the pipeline reads them beside their series as planes of any orientation on its grid
    # (drawn on a tilted reformat: the run was refused, "do not belong to this image")
    annotation, _ = read_rtstruct_annotation(path, image_dir=case["series"])
    assert annotation.grid_axis() is None and annotation.gap_ends == {1}
    assert np.allclose(annotation.affine, case["affine"])


def test_file_errors(case, tmp_path):
    with pytest.raises(InputError, match="RTSTRUCT file not found"):
        read_rtstruct(tmp_path / "missing.dcm")
    with pytest.raises(FormatError, match="not a DICOM RTSTRUCT \\(Modality MR"):
        read_rtstruct(case["files"][0])
    (tmp_path / "junk.dcm").write_bytes(b"not dicom at all")
    with pytest.raises(FormatError, match="corrupt or not a DICOM file"):
        list_rois(tmp_path / "junk.dcm")
    other = write_rtstruct(tmp_path / "ct.dcm", {(1, "A"): None}, modality="CT")
    with pytest.raises(FormatError, match="not a DICOM RTSTRUCT"):
        list_rois(other)
    ds = pydicom.dcmread(case["path"])
    del ds.StructureSetROISequence
    ds.save_as(tmp_path / "noroi.dcm")
    with pytest.raises(FormatError, match="no StructureSetROISequence"):
        read_rtstruct(tmp_path / "noroi.dcm")


@pytest.mark.parametrize("keep", [0.3, 0.6, 0.9])
def test_truncated_file_is_one_clear_error(case, tmp_path, keep):
    data = Path(case["path"]).read_bytes()
    cut = tmp_path / "truncated.dcm"
    cut.write_bytes(data[: int(len(data) * keep)])
    with pytest.raises((FormatError, InputError)) as info:
        read_rtstruct(cut, roi="Tumour", image_dir=case["series"])
    assert str(cut) in str(info.value) or "truncated" in str(info.value)


def test_contours_that_enclose_no_area_are_named_once_by_roi_and_item(tmp_path, caplog):
    """A clicked point and a stroke were said in two ways ("contour 0 has 1 points",
    "polygon 7 encloses no area"): numbered differently, one without its ROI, each said
    again for every grid the ROIs are rasterized on."""
    affine = np.eye(4)
    rings = [_contour_item(_ring(8.0, [0, 0], affine, k)) for k in range(0, 12, 3)]
    point = _contour_item(np.array([[0.0, 0.0, 12.0]]))
    line = _contour_item(np.array([[-2.0, 0, -3.0], [0.0, 0, -3.0], [2.0, 0, -3.0]]))
    other = [_contour_item(_ring(4.0, [30, 0], affine, k)) for k in range(0, 12, 2)]
    path = write_rtstruct(
        tmp_path / "rt.dcm", {(1, "Org"): [point, *rings, line], (2, "Other"): other}
    )
    with caplog.at_level("WARNING"):
        annotation, _ = read_rtstruct_annotation(path)
    said = [r.getMessage() for r in caplog.records if "no area" in r.getMessage()]
    assert len(said) == 1 and "ROI 1 (Org) contours 1, 6 enclose no area" in said[0]
    assert len(annotation.planes_of(1)) == 4


def test_roi_number_zero_and_contours_of_no_roi_are_said(tmp_path, caplog):
    """ROINumber 0 (valid DICOM) was refused after the whole reconstruction, by the
    writer: "structures need distinct non-zero values (got [1, 0])". Contours whose
    ReferencedROINumber names no ROI were dropped without a word."""
    affine = np.eye(4)
    rings = [_contour_item(_ring(8.0, [0, 0], affine, k)) for k in range(0, 12, 3)]
    other = [_contour_item(_ring(4.0, [30, 0], affine, k)) for k in range(0, 12, 3)]
    path = write_rtstruct(tmp_path / "rt.dcm", {(1, "Organ"): rings, (0, "GTV"): other})
    ds = pydicom.dcmread(path)
    ds.ROIContourSequence[1].ReferencedROINumber = 99  # the GTV's contours: of no ROI
    ds.save_as(tmp_path / "orphan.dcm")
    with caplog.at_level("WARNING"):
        annotation, _ = read_rtstruct_annotation(path)
    assert sorted(s.value for s in annotation.structures) == [1, 2]
    assert "ROI 0 (GTV) has label value 2 in the outputs" in caplog.text
    caplog.clear()
    with caplog.at_level("WARNING"):
        annotation, missing = read_rtstruct_annotation(tmp_path / "orphan.dcm")
    assert "ROIContourSequence item 2 refers to ROI 99" in caplog.text
    assert [s.name for s in missing] == ["GTV"]
