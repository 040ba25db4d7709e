"""Writing DICOM SEG: highdicom and slicerecon read back the same segments and geometry."""

from __future__ import annotations

import logging
import random

import dicom_factory as factory  # tests/io, on pytest's pythonpath
import highdicom as hd
import numpy as np
import pydicom
import pytest

from slicerecon.errors import EmptyMaskError, GeometryError, InputError, LabelError, OptionError
from slicerecon.io.dicom import read_dicom_seg, write_seg
from slicerecon.io.dicom.derived import labels_on_series, load_source_series
from slicerecon.io.labelmap import read_label_map
from slicerecon.labels import DEFAULT_COLOURS, Structure


def _oblique_affine(spacing=(0.7, 1.2, 3.0), origin=(55.0, -80.5, 12.25), tilt=None):
    """A fixed oblique grid (rotated 30° about z, then 20° about x), non-square pixels.

    ``tilt`` adds an in-plane part to the slice step (mm per slice along the row
    direction), as after a CT gantry tilt.
    """
    a, b = np.deg2rad(30.0), np.deg2rad(20.0)
    rz = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    rx = np.array([[1, 0, 0], [0, np.cos(b), -np.sin(b)], [0, np.sin(b), np.cos(b)]])
    rot = rx @ rz
    step = rot[:, 2] * spacing[2] + (0.0 if tilt is None else tilt * rot[:, 1])
    return factory.affine_from_geometry(
        rot[:, 0], rot[:, 1], (spacing[1], spacing[0]), step, origin
    )


def _labels(shape=(24, 20, 10)):
    """Three disjoint structures: a box with a hole, a ball, a one-voxel-wide bar."""
    labels = np.zeros(shape, np.uint8)
    labels[2:12, 3:14, 1:7] = 1
    labels[5:8, 6:9, 2:5] = 0  # a hole through three slices
    i, j, k = np.ogrid[: shape[0], : shape[1], : shape[2]]
    labels[(i - 17) ** 2 + (j - 12) ** 2 + ((k - 5) * 2) ** 2 <= 16] = 2
    labels[3, 16:19, 4:9] = 3
    return labels


STRUCTURES = [
    Structure(1, "Liver", (220, 120, 60)),
    Structure(2, "Tumour", (40, 200, 90)),
    Structure(3, ""),
]


def _place(values, source_affine, affine, shape):
    """Put an array given on ``source_affine``'s grid onto ``(affine, shape)``: the grids
    must differ by whole voxels and a permutation / flip of axes (asserted)."""
    m = np.linalg.inv(affine) @ source_affine
    index = np.indices(values.shape).reshape(3, -1).astype(np.float64)
    target = m[:3, :3] @ index + m[:3, 3:]
    np.testing.assert_allclose(target, np.rint(target), atol=1e-4)
    target = np.rint(target).astype(np.int64)
    inside = np.all((target >= 0) & (target < np.array(shape)[:, None]), axis=0)
    assert not np.any(values.ravel()[~inside]), "foreground outside the grid"
    out = np.zeros(shape, values.dtype)
    out[tuple(target[:, inside])] = values.ravel()[inside]
    return out


@pytest.fixture
def ct_series(tmp_path):
    """A CT series on an oblique grid with non-square pixels, and its label map."""
    labels = _labels()
    affine = _oblique_affine()
    paths = factory.write_series(tmp_path / "ct", np.zeros(labels.shape), affine, modality="CT")
    return tmp_path / "ct", paths, affine, labels


def test_highdicom_reads_the_same_segments_labels_and_colours(ct_series, tmp_path):
    series_dir, _, affine, labels = ct_series

    path = write_seg(labels, affine, STRUCTURES, series_dir, tmp_path / "out" / "seg.dcm")

    seg = hd.seg.segread(path)
    assert seg.SegmentationType == "BINARY"
    assert seg.number_of_segments == 3
    got = {}
    for number in (1, 2, 3):
        description = seg.get_segment_description(number)
        colour = hd.color.CIELabColor.from_dicom_value(
            description.RecommendedDisplayCIELabValue
        ).to_rgb()
        got[number] = (description.segment_label, colour, description.SegmentDescription)
        assert description.segmented_property_category.meaning == "Tissue"
        assert description.segmented_property_type.meaning == "Tissue"
        assert description.algorithm_type.value == "SEMIAUTOMATIC"
        assert description.algorithm_identification[0].AlgorithmName == "slicerecon"
    assert got[1][0] == "Liver" and got[2][0] == "Tumour" and got[3][0] == "Segment_3"
    for number, structure in ((1, STRUCTURES[0]), (2, STRUCTURES[1])):
        assert np.abs(np.subtract(got[number][1], structure.colour)).max() <= 1
    assert np.abs(np.subtract(got[3][1], DEFAULT_COLOURS[2])).max() <= 1
    assert [got[n][2] for n in (1, 2, 3)] == ["label value 1", "label value 2", "label value 3"]


def test_highdicom_volume_is_the_label_map_on_the_series_grid(ct_series, tmp_path):
    series_dir, _, affine, labels = ct_series

    path = write_seg(labels, affine, STRUCTURES, series_dir, tmp_path / "seg.dcm")

    volume = hd.seg.segread(path).get_volume(combine_segments=True, relabel=False)
    array = np.transpose(np.asarray(volume.array), (2, 1, 0))  # (slice, row, col) → ours
    hd_affine = np.asarray(volume.affine)[:, [2, 1, 0, 3]]
    placed = _place(array, hd_affine, affine, labels.shape)
    np.testing.assert_array_equal(placed, labels)


def test_frames_refer_to_their_source_images_in_the_same_frame_of_reference(ct_series, tmp_path):
    series_dir, paths, affine, labels = ct_series
    images = [pydicom.dcmread(p, stop_before_pixels=True) for p in paths]

    path = write_seg(labels, affine, STRUCTURES, series_dir, tmp_path / "seg.dcm")

    seg = pydicom.dcmread(path)
    first = images[0]
    assert seg.FrameOfReferenceUID == first.FrameOfReferenceUID
    assert seg.StudyInstanceUID == first.StudyInstanceUID
    assert seg.PatientID == first.PatientID
    assert seg.SeriesInstanceUID != first.SeriesInstanceUID
    referenced = seg.ReferencedSeriesSequence[0]  # the source series, every image of it
    assert referenced.SeriesInstanceUID == first.SeriesInstanceUID
    assert {i.ReferencedSOPInstanceUID for i in referenced.ReferencedInstanceSequence} == {
        str(ds.SOPInstanceUID) for ds in images
    }
    by_uid = {str(ds.SOPInstanceUID): k for k, ds in enumerate(images)}
    expected = {
        (v, k) for v in (1, 2, 3) for k in range(labels.shape[2]) if np.any(labels[:, :, k] == v)
    }
    frames = set()
    for item in seg.PerFrameFunctionalGroupsSequence:
        source = item.DerivationImageSequence[0].SourceImageSequence[0]
        k = by_uid[str(source.ReferencedSOPInstanceUID)]
        np.testing.assert_allclose(
            [float(v) for v in item.PlanePositionSequence[0].ImagePositionPatient],
            [float(v) for v in images[k].ImagePositionPatient],
            atol=1e-4,
        )
        frames.add((int(item.SegmentIdentificationSequence[0].ReferencedSegmentNumber), k))
    assert frames == expected  # one frame per segment and slice it covers, no empty frame
    assert int(seg.NumberOfFrames) == len(expected)


def test_slicerecon_reads_the_same_masks(ct_series, tmp_path):
    series_dir, _, affine, labels = ct_series

    path = write_seg(labels, affine, STRUCTURES, series_dir, tmp_path / "seg.dcm")

    for structure in STRUCTURES:
        volume = read_dicom_seg(path, segment=structure.value)
        np.testing.assert_array_equal(
            _place(volume.mask, volume.affine, affine, labels.shape), labels == structure.value
        )
    label_map = read_label_map(path)
    assert [(s.value, s.name) for s in label_map.structures] == [
        (1, "Liver"),
        (2, "Tumour"),
        (3, "Segment_3"),
    ]
    np.testing.assert_array_equal(
        _place(label_map.labels, label_map.affine, affine, labels.shape), labels
    )


def test_values_are_numbered_in_order_and_recorded(ct_series, tmp_path):
    series_dir, _, affine, labels = ct_series
    renumbered = np.select([labels == 1, labels == 2, labels == 3], [7, 2, 40], 0).astype(np.uint8)
    structures = [Structure(40, "Bar"), Structure(7, "Box"), Structure(2, "Ball")]

    path = write_seg(renumbered, affine, structures, series_dir, tmp_path / "seg.dcm")

    seg = hd.seg.segread(path)
    described = [
        (d.segment_number, d.segment_label, d.SegmentDescription)
        for d in (seg.get_segment_description(n) for n in (1, 2, 3))
    ]
    assert described == [
        (1, "Ball", "label value 2"),
        (2, "Box", "label value 7"),
        (3, "Bar", "label value 40"),
    ]
    for number, value in ((1, 2), (2, 7), (3, 40)):
        volume = read_dicom_seg(path, segment=number)
        np.testing.assert_array_equal(
            _place(volume.mask, volume.affine, affine, labels.shape), renumbered == value
        )


def test_source_images_as_datasets_or_paths_in_any_order(ct_series, tmp_path):
    series_dir, paths, affine, labels = ct_series
    shuffled = list(paths)
    random.Random(3).shuffle(shuffled)
    datasets = [pydicom.dcmread(p) for p in shuffled]

    by_dir = write_seg(labels, affine, STRUCTURES, series_dir, tmp_path / "a.dcm")
    by_datasets = write_seg(labels, affine, STRUCTURES, datasets, tmp_path / "b.dcm")
    by_paths = write_seg(labels, affine, STRUCTURES, [str(p) for p in shuffled], tmp_path / "c.dcm")

    reference = read_label_map(by_dir).labels
    for other in (by_datasets, by_paths):
        np.testing.assert_array_equal(read_label_map(other).labels, reference)


def test_gantry_tilt_keeps_every_frame_on_its_image(tmp_path):
    labels = _labels()
    affine = _oblique_affine(tilt=0.4)
    factory.write_series(tmp_path / "ct", np.zeros(labels.shape), affine, modality="CT")

    path = write_seg(labels, affine, STRUCTURES, tmp_path / "ct", tmp_path / "seg.dcm")

    for structure in STRUCTURES:
        volume = read_dicom_seg(path, segment=structure.value)
        np.testing.assert_array_equal(
            _place(volume.mask, volume.affine, affine, labels.shape), labels == structure.value
        )


def test_a_label_map_on_some_slices_of_the_series_is_placed_on_them(ct_series, tmp_path):
    """A SEG input is read over the planes that have frames only: written back, each
    plane lands on its own image."""
    series_dir, _, affine, labels = ct_series
    sub = labels[:, :, 1:9]
    sub_affine = affine.copy()
    sub_affine[:3, 3] = affine[:3, 3] + affine[:3, 2]  # plane 0 of `sub` is slice 1

    path = write_seg(sub, sub_affine, STRUCTURES, series_dir, tmp_path / "seg.dcm")

    label_map = read_label_map(path)
    np.testing.assert_array_equal(
        _place(label_map.labels, label_map.affine, affine, labels.shape), labels
    )


def test_labels_on_series_takes_the_nearest_label_plane(ct_series):
    series_dir, _, affine, labels = ct_series
    series = load_source_series(series_dir)
    fine = np.repeat(labels, 3, axis=2)[:, :, 1:]  # three planes per slice, centred
    fine_affine = affine.copy()
    fine_affine[:3, 2] = affine[:3, 2] / 3

    np.testing.assert_array_equal(labels_on_series(fine, fine_affine, series), labels)


def test_a_label_map_on_another_grid_is_refused(ct_series, tmp_path):
    series_dir, _, affine, labels = ct_series
    other = affine.copy()
    other[:3, 0] *= 1.5  # other pixel size

    with pytest.raises(GeometryError, match="not on the grid"):
        write_seg(labels, other, STRUCTURES, series_dir, tmp_path / "seg.dcm")
    shifted = affine.copy()
    shifted[:3, 3] += 0.3 * affine[:3, 0]  # a third of a pixel off
    with pytest.raises(GeometryError, match="fraction of a pixel"):
        write_seg(labels, shifted, STRUCTURES, series_dir, tmp_path / "seg.dcm")
    assert not (tmp_path / "seg.dcm").exists()


def test_bad_labels_and_structures_are_refused(ct_series, tmp_path):
    series_dir, _, affine, labels = ct_series
    out = tmp_path / "seg.dcm"

    with pytest.raises(LabelError, match=r"values \[3\]"):
        write_seg(labels, affine, STRUCTURES[:2], series_dir, out)
    with pytest.raises(OptionError, match="distinct"):
        write_seg(labels, affine, [*STRUCTURES, Structure(1, "again")], series_dir, out)
    with pytest.raises(OptionError, match="integer"):
        write_seg(labels.astype(float), affine, STRUCTURES, series_dir, out)
    with pytest.raises(EmptyMaskError):
        write_seg(np.zeros_like(labels), affine, STRUCTURES, series_dir, out)
    assert not out.exists()


def test_an_empty_structure_becomes_a_segment_without_frames(ct_series, tmp_path, caplog):
    series_dir, _, affine, labels = ct_series
    without_bar = np.where(labels == 3, 0, labels).astype(np.uint8)

    with caplog.at_level(logging.INFO):  # no voxel at all: said by whoever made the map
        path = write_seg(without_bar, affine, STRUCTURES, series_dir, tmp_path / "seg.dcm")

    said = [r for r in caplog.records if "structure 3 () holds no voxel" in r.message]
    assert [r.levelno for r in said] == [logging.INFO]
    seg = pydicom.dcmread(path)
    assert len(seg.SegmentSequence) == 3
    numbers = {
        int(i.SegmentIdentificationSequence[0].ReferencedSegmentNumber)
        for i in seg.PerFrameFunctionalGroupsSequence
    }
    assert numbers == {1, 2}


def test_source_images_of_two_studies_are_refused_naming_each(ct_series, tmp_path):
    """highdicom raised a bare ValueError (a traceback, exit 1) for one stray image."""
    series_dir, paths, affine, labels = ct_series
    images = [pydicom.dcmread(p) for p in paths]
    images[3].StudyInstanceUID = pydicom.uid.generate_uid()
    images[3].SeriesDescription = "Head"
    with pytest.raises(InputError, match=r"2 studies.*1 image of CT 'Head'"):
        write_seg(labels, affine, STRUCTURES, images, tmp_path / "seg.dcm")
    images[3].PatientID = "SOMEONE-ELSE"
    images[3].StudyInstanceUID = images[0].StudyInstanceUID
    with pytest.raises(InputError, match="2 patients"):
        write_seg(labels, affine, STRUCTURES, images, tmp_path / "seg.dcm")
    assert not (tmp_path / "seg.dcm").exists()
