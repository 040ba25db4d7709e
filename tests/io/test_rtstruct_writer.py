"""Writing RTSTRUCT: read back by slicerecon into the same structures, by pydicom and rt-utils."""

from __future__ import annotations

import logging

import dicom_factory as factory  # tests/io, on pytest's pythonpath
import numpy as np
import pydicom
import pytest

from slicerecon.errors import EmptyMaskError, GeometryError, InputError, LabelError
from slicerecon.io.rtstruct import list_rois, read_rtstruct
from slicerecon.io.rtstruct_writer import write_rtstruct
from slicerecon.labels import DEFAULT_COLOURS, Structure


def _oblique_affine(spacing=(0.7, 1.2, 3.0), origin=(55.0, -80.5, 12.25), tilt=0.0):
    """A fixed oblique grid (rotated 30° about z, then 20° about x), non-square pixels;
    ``tilt`` mm per slice along the column direction, as after a CT gantry tilt."""
    a, b = np.deg2rad(30.0), np.deg2rad(20.0)
    rz = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    rx = np.array([[1, 0, 0], [0, np.cos(b), -np.sin(b)], [0, np.sin(b), np.cos(b)]])
    rot = rx @ rz
    return factory.affine_from_geometry(
        rot[:, 0],
        rot[:, 1],
        (spacing[1], spacing[0]),
        rot[:, 2] * spacing[2] + tilt * rot[:, 1],
        origin,
    )


def _labels(shape=(30, 26, 10)):
    """A box with a hole and an island in the hole, a ball, a thin bar touching itself
    diagonally: what the even-odd contours must give back exactly."""
    labels = np.zeros(shape, np.uint8)
    labels[2:16, 3:18, 1:7] = 4
    labels[5:13, 6:15, 2:5] = 0  # a hole ...
    labels[8:10, 9:12, 3] = 4  # ... with an island in it on one slice
    i, j, k = np.ogrid[: shape[0], : shape[1], : shape[2]]
    labels[(i - 22) ** 2 + (j - 13) ** 2 + ((k - 5) * 2) ** 2 <= 25] = 9
    labels[20, 2:6, 6:9] = 2
    labels[21, 6, 6:9] = 2  # touches the bar at a corner only
    return labels


STRUCTURES = [
    Structure(4, "Body", (200, 160, 120)),
    Structure(9, "GTV", (255, 0, 0)),
    Structure(2, ""),
]


@pytest.fixture
def ct_series(tmp_path):
    labels = _labels()
    affine = _oblique_affine()
    paths = factory.write_series(tmp_path / "ct", np.zeros(labels.shape), affine, modality="CT")
    return tmp_path / "ct", paths, affine, labels


def _voxel_volume(affine):
    return abs(float(np.linalg.det(affine[:3, :3])))


def _assert_same_structures(path, series_dir, affine, labels, structures):
    for structure in structures:
        truth = labels == structure.value
        sections = read_rtstruct(path, roi=structure.value, image_dir=series_dir)
        # the same planes: every image slice the structure crosses, and no other
        np.testing.assert_array_equal(sections.indices, np.flatnonzero(truth.any(axis=(0, 1))))
        np.testing.assert_allclose(sections.affine, affine, atol=1e-6)
        # volume within 2 % (here: every voxel the same)
        thickness = abs(float(sections.normal @ affine[:3, 2]))  # slice gap along the normal
        read_mm3 = sum(sections.area_mm2(p) for p in range(sections.n_planes)) * thickness
        truth_mm3 = float(truth.sum()) * _voxel_volume(affine)
        assert read_mm3 == pytest.approx(truth_mm3, rel=0.02)
        np.testing.assert_array_equal(sections.to_volume().mask, truth)


def test_read_back_into_the_same_structures(ct_series, tmp_path):
    series_dir, _, affine, labels = ct_series

    path = write_rtstruct(labels, affine, STRUCTURES, series_dir, tmp_path / "out" / "rt.dcm")

    assert list_rois(path) == [(4, "Body"), (9, "GTV"), (2, "Segment_2")]
    _assert_same_structures(path, series_dir, affine, labels, STRUCTURES)
    ds = pydicom.dcmread(path)
    colours = {
        int(i.ReferencedROINumber): [int(c) for c in i.ROIDisplayColor]
        for i in ds.ROIContourSequence
    }
    assert colours == {4: [200, 160, 120], 9: [255, 0, 0], 2: list(DEFAULT_COLOURS[2])}


@pytest.mark.parametrize("tilt", [0.0, 0.5])
def test_oblique_and_gantry_tilted_series_round_trip(tmp_path, tilt):
    labels = _labels()
    affine = _oblique_affine(spacing=(0.55, 0.9, 2.5), origin=(-120.0, 33.3, -401.7), tilt=tilt)
    factory.write_series(tmp_path / "ct", np.zeros(labels.shape), affine, modality="CT")

    path = write_rtstruct(labels, affine, STRUCTURES, tmp_path / "ct", tmp_path / "rt.dcm")

    _assert_same_structures(path, tmp_path / "ct", affine, labels, STRUCTURES)


def test_contours_are_closed_planar_on_their_images(ct_series, tmp_path):
    series_dir, paths, affine, labels = ct_series
    images = {
        str(ds.SOPInstanceUID): ds
        for ds in (pydicom.dcmread(p, stop_before_pixels=True) for p in paths)
    }
    first = next(iter(images.values()))

    path = write_rtstruct(labels, affine, STRUCTURES, series_dir, tmp_path / "rt.dcm")

    ds = pydicom.dcmread(path)
    assert ds.Modality == "RTSTRUCT" and ds.SOPClassUID == factory.RTSTRUCT_STORAGE
    assert ds.StudyInstanceUID == first.StudyInstanceUID and ds.PatientID == first.PatientID
    frame = ds.ReferencedFrameOfReferenceSequence[0]
    assert frame.FrameOfReferenceUID == first.FrameOfReferenceUID
    study = frame.RTReferencedStudySequence[0]
    assert study.ReferencedSOPInstanceUID == first.StudyInstanceUID
    referenced = study.RTReferencedSeriesSequence[0]
    assert referenced.SeriesInstanceUID == first.SeriesInstanceUID
    assert {i.ReferencedSOPInstanceUID for i in referenced.ContourImageSequence} == set(images)
    assert {int(i.ROINumber) for i in ds.StructureSetROISequence} == {4, 9, 2}
    assert all(
        i.ReferencedFrameOfReferenceUID == first.FrameOfReferenceUID
        for i in ds.StructureSetROISequence
    )
    normal = np.cross(affine[:3, 0], affine[:3, 1])
    normal /= np.linalg.norm(normal)
    holes = 0
    for roi in ds.ROIContourSequence:
        for contour in roi.ContourSequence:
            assert contour.ContourGeometricType == "CLOSED_PLANAR"
            points = np.asarray(contour.ContourData, dtype=float).reshape(-1, 3)
            assert int(contour.NumberOfContourPoints) == len(points) >= 3
            assert not np.allclose(points[0], points[-1])  # closed implicitly
            image = images[contour.ContourImageSequence[0].ReferencedSOPInstanceUID]
            assert contour.ContourImageSequence[0].ReferencedSOPClassUID == image.SOPClassUID
            position = np.asarray(image.ImagePositionPatient, dtype=float) @ normal
            np.testing.assert_allclose(points @ normal, position, atol=1e-5)
        if int(roi.ReferencedROINumber) == 4:  # outer box, hole and island on slice 3
            per_image: dict[str, int] = {}
            for contour in roi.ContourSequence:
                uid = contour.ContourImageSequence[0].ReferencedSOPInstanceUID
                per_image[uid] = per_image.get(uid, 0) + 1
            holes = max(per_image.values())
    assert holes == 3
    observed = {int(i.ReferencedROINumber) for i in ds.RTROIObservationsSequence}
    assert observed == {4, 9, 2}


def _reference(tmp_path, paths):
    """An input RTSTRUCT as a planning system writes it, with its own identifiers."""
    image = pydicom.dcmread(paths[0], stop_before_pixels=True)
    ring = factory.circle(3.0, image.ImagePositionPatient[:2], float(image.ImagePositionPatient[2]))
    path = factory.write_rtstruct(
        tmp_path / "input_rt.dcm",
        {
            (4, "BODY"): [factory.contour_item(ring)],
            (9, "GTV_1"): [factory.contour_item(ring)],
            (12, "Cord"): [factory.contour_item(ring)],
        },
    )
    ds = pydicom.dcmread(path)
    ds.PatientName, ds.PatientID = "Doe^Jane", image.PatientID  # the name as the plan spells it
    ds.StudyInstanceUID = image.StudyInstanceUID
    for item in ds.StructureSetROISequence:
        item.ReferencedFrameOfReferenceUID = image.FrameOfReferenceUID
    ds.StudyID, ds.AccessionNumber = "S17", "ACC-9"
    for item, colour in zip(
        ds.ROIContourSequence, ([10, 20, 30], [255, 255, 0], [0, 0, 255]), strict=True
    ):
        item.ROIDisplayColor = colour
    observations = []
    for number, kind in ((4, "EXTERNAL"), (9, "GTV"), (12, "ORGAN")):
        item = pydicom.Dataset()
        item.ObservationNumber = number
        item.ReferencedROINumber = number
        item.RTROIInterpretedType = kind
        item.ROIInterpreter = "Smith^J"
        observations.append(item)
    ds.RTROIObservationsSequence = observations
    return ds


def test_reference_keeps_identifiers_names_colours_and_numbers(ct_series, tmp_path):
    series_dir, paths, affine, labels = ct_series
    reference = _reference(tmp_path, paths)
    structures = [Structure(4, "whatever"), Structure(9, ""), Structure(2, "Bar")]

    path = write_rtstruct(
        labels, affine, structures, series_dir, tmp_path / "rt.dcm", reference=reference
    )

    ds = pydicom.dcmread(path)
    assert (str(ds.PatientName), ds.PatientID, ds.StudyID, ds.AccessionNumber) == (
        "Doe^Jane",
        reference.PatientID,
        "S17",
        "ACC-9",
    )
    assert ds.StudyInstanceUID == reference.StudyInstanceUID
    assert list_rois(path) == [(4, "BODY"), (9, "GTV_1"), (2, "Bar")]  # Cord was not written
    colours = {
        int(i.ReferencedROINumber): [int(c) for c in i.ROIDisplayColor]
        for i in ds.ROIContourSequence
    }
    assert colours == {4: [10, 20, 30], 9: [255, 255, 0], 2: list(DEFAULT_COLOURS[2])}
    kinds = {
        int(i.ReferencedROINumber): i.RTROIInterpretedType for i in ds.RTROIObservationsSequence
    }
    assert kinds == {4: "EXTERNAL", 9: "GTV", 2: ""}
    assert (
        ds.PredecessorStructureSetSequence[0].ReferencedSOPInstanceUID == reference.SOPInstanceUID
    )
    _assert_same_structures(path, series_dir, affine, labels, structures)


def test_reference_given_as_a_path(ct_series, tmp_path):
    series_dir, paths, affine, labels = ct_series
    reference = _reference(tmp_path, paths)
    reference.save_as(tmp_path / "ref.dcm")

    path = write_rtstruct(
        labels, affine, STRUCTURES, series_dir, tmp_path / "rt.dcm", reference=tmp_path / "ref.dcm"
    )

    assert str(pydicom.dcmread(path).PatientName) == "Doe^Jane"
    with pytest.raises(InputError, match="not an RTSTRUCT"):
        write_rtstruct(
            labels, affine, STRUCTURES, series_dir, tmp_path / "rt.dcm", reference=paths[0]
        )


def test_an_empty_structure_is_an_roi_without_contours(ct_series, tmp_path, caplog):
    series_dir, _, affine, labels = ct_series
    without_bar = np.where(labels == 2, 0, labels).astype(np.uint8)

    with caplog.at_level(logging.INFO):  # no voxel at all: said by whoever made the map
        path = write_rtstruct(without_bar, affine, STRUCTURES, series_dir, tmp_path / "rt.dcm")

    said = [r for r in caplog.records if "structure 2 (Segment_2) holds no voxel" in r.message]
    assert [r.levelno for r in said] == [logging.INFO]
    assert (2, "Segment_2") in list_rois(path)
    with pytest.raises(EmptyMaskError, match="no contours"):
        read_rtstruct(path, roi=2, image_dir=series_dir)


def test_errors(ct_series, tmp_path):
    series_dir, _, affine, labels = ct_series
    out = tmp_path / "rt.dcm"

    with pytest.raises(LabelError, match=r"values \[2\]"):
        write_rtstruct(labels, affine, STRUCTURES[:2], series_dir, out)
    with pytest.raises(EmptyMaskError):
        write_rtstruct(np.zeros_like(labels), affine, STRUCTURES, series_dir, out)
    coarse = affine.copy()
    coarse[:3, 1] *= 2
    with pytest.raises(GeometryError, match="not on the grid"):
        write_rtstruct(labels, coarse, STRUCTURES, series_dir, out)
    with pytest.raises(InputError, match="no DICOM image"):
        write_rtstruct(labels, affine, STRUCTURES, tmp_path, out)
    assert not out.exists()


def test_rt_utils_reads_it(tmp_path):
    rt_utils = pytest.importorskip("rt_utils")
    # rt-utils assumes square pixels and an axial series; give it one
    labels = _labels(shape=(28, 28, 10))
    affine = factory.affine_from_geometry(
        [1, 0, 0], [0, 1, 0], [0.8, 0.8], [0, 0, 2.0], [-11.0, -11.0, 5.0]
    )
    factory.write_series(tmp_path / "ct", np.zeros(labels.shape), affine, modality="CT")
    path = write_rtstruct(labels, affine, STRUCTURES, tmp_path / "ct", tmp_path / "rt.dcm")

    rtstruct = rt_utils.RTStructBuilder.create_from(
        dicom_series_path=str(tmp_path / "ct"), rt_struct_path=str(path)
    )

    assert rtstruct.get_roi_names() == ["Body", "GTV", "Segment_2"]
    for structure in STRUCTURES[:2]:
        # rt-utils rounds vertices to pixel centres and fills the boundary: about a half
        # pixel more all round; masks are (row, column, slice)
        mask = np.transpose(
            rtstruct.get_roi_mask_by_name(structure.name or f"Segment_{structure.value}"),
            (1, 0, 2),
        )
        truth = labels == structure.value
        assert 2 * np.sum(mask & truth) / (mask.sum() + truth.sum()) > 0.85


def test_irregular_series_contours_lie_on_their_own_images(tmp_path):
    """With allow_irregular the grid's planes may lie beside the images (here the image at
    7 mm owns the plane at 7.2 mm): each contour is drawn on its image itself."""
    from slicerecon.io.dicom import dicom_series_geometry

    positions = [0.0, 2.0, 4.0, 7.0, 9.0]
    base = factory.affine_from_geometry(
        [1, 0, 0], [0, 1, 0], [0.8, 0.8], [0, 0, 2.0], [-8.0, -7.2, 0.0]
    )
    paths = factory.write_series(
        tmp_path / "ct", np.zeros((20, 18, 5)), base, modality="CT", irregular_positions=positions
    )
    with pytest.raises(GeometryError, match="irregular"):
        write_rtstruct(
            np.zeros((20, 18, 5), np.uint8),
            base,
            STRUCTURES[:1],
            tmp_path / "ct",
            tmp_path / "rt.dcm",
        )
    affine, shape, uids = dicom_series_geometry(tmp_path / "ct", allow_irregular=True)
    labels = np.zeros(shape, np.uint8)
    for k in range(shape[2]):
        labels[3 + k : 12, 4 : 10 + k, k] = 4  # a different mask on every plane

    path = write_rtstruct(
        labels, affine, STRUCTURES[:1], tmp_path / "ct", tmp_path / "rt.dcm", allow_irregular=True
    )

    z_by_uid = dict(zip(factory.read_uids(paths), positions, strict=True))
    ds = pydicom.dcmread(path)
    seen = set()
    for contour in ds.ROIContourSequence[0].ContourSequence:
        uid = contour.ContourImageSequence[0].ReferencedSOPInstanceUID
        z = np.asarray(contour.ContourData, dtype=float).reshape(-1, 3)[:, 2]
        np.testing.assert_allclose(z, z_by_uid[uid], atol=1e-6)
        seen.add(uid)
    assert seen == set(z_by_uid)  # planes copied from a neighbour get no contour
    sections = read_rtstruct(path, roi=4, pixel_spacing=0.8)  # a grid of the contours alone
    np.testing.assert_allclose(sections.positions, positions, atol=1e-6)
    own = [k for k, uid in enumerate(uids) if uid]
    for p, k in enumerate(own):
        assert sections.masks[p].sum() == np.count_nonzero(labels[:, :, k])


def test_a_reference_of_another_patient_or_frame_is_refused(ct_series, tmp_path):
    """The structure set copies the reference's patient: it must be the images' patient."""
    series_dir, paths, affine, labels = ct_series
    reference = _reference(tmp_path, paths)
    reference.PatientID = "MRN-0042"
    with pytest.raises(InputError, match="of patient 'MRN-0042'"):
        write_rtstruct(
            labels, affine, STRUCTURES, series_dir, tmp_path / "rt.dcm", reference=reference
        )
    reference = _reference(tmp_path, paths)
    reference.StructureSetROISequence[0].ReferencedFrameOfReferenceUID = "1.2.3.4"
    with pytest.raises(InputError, match="frame of reference"):
        write_rtstruct(
            labels, affine, STRUCTURES, series_dir, tmp_path / "rt.dcm", reference=reference
        )
    assert not (tmp_path / "rt.dcm").exists()
