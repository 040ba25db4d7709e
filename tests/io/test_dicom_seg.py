"""DICOM SEG: segment selection, frame placement, fractional masks and clear errors."""

from __future__ import annotations

import dicom_factory as factory  # tests/io, on pytest's pythonpath
import numpy as np
import pydicom
import pytest

from slicerecon.errors import EmptyMaskError, FormatError, GeometryError, InputError, LabelError
from slicerecon.io import load_input
from slicerecon.io.dicom import dicom_info, read_dicom_seg


def _oblique_affine(spacing=(0.7, 1.2, 3.0), origin=(55.0, -80.5, 12.25)):
    """A fixed oblique grid: rotated 30° about z then 20° about x, right-handed."""
    a, b = np.deg2rad(30.0), np.deg2rad(20.0)
    rz = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    rx = np.array([[1, 0, 0], [0, np.cos(b), -np.sin(b)], [0, np.sin(b), np.cos(b)]])
    rot = rx @ rz
    return factory.affine_from_geometry(
        rot[:, 0], rot[:, 1], (spacing[1], spacing[0]), rot[:, 2] * spacing[2], origin
    )


def _two_segments(shape=(9, 8, 6)):
    liver = np.zeros(shape, bool)
    liver[1:6, 2:7, 0:4] = True
    liver[1, 2, 0] = False  # break symmetry
    tumour = np.zeros(shape, bool)
    tumour[5:8, 1:3, 2:6] = True
    return liver, tumour


@pytest.fixture
def two_segment_seg(tmp_path):
    liver, tumour = _two_segments()
    affine = _oblique_affine()
    path = factory.write_seg(
        tmp_path / "seg.dcm", {1: liver, 2: tumour}, affine, labels={1: "Liver", 2: "Tumour"}
    )
    return path, affine, liver, tumour


def test_segments_by_number_and_label_round_trip(two_segment_seg):
    path, affine, liver, tumour = two_segment_seg

    by_number = read_dicom_seg(path, segment=1)
    by_label = read_dicom_seg(path, segment="Tumour")

    np.testing.assert_array_equal(by_number.mask, liver)
    np.testing.assert_array_equal(by_label.mask, tumour)
    np.testing.assert_allclose(by_number.affine, affine, atol=1e-6)
    np.testing.assert_allclose(by_label.affine, affine, atol=1e-6)
    np.testing.assert_array_equal(read_dicom_seg(path, segment="tumour").mask, tumour)


def test_every_frame_lands_on_the_plane_at_its_position(two_segment_seg):
    path, _, liver, tumour = two_segment_seg
    volume = read_dicom_seg(path, segment=2)
    ds = pydicom.dcmread(path)
    frames = ds.pixel_array
    for f, item in enumerate(ds.PerFrameFunctionalGroupsSequence):
        ipp = np.array([float(v) for v in item.PlanePositionSequence[0].ImagePositionPatient])
        k = volume.world_to_index(ipp)
        np.testing.assert_allclose(k, np.rint(k), atol=1e-6)  # exactly on a plane ...
        np.testing.assert_allclose(k[:2], 0, atol=1e-6)  # ... at its first pixel
        plane = int(np.rint(k[2]))
        np.testing.assert_allclose(volume.index_to_world([0, 0, plane]), ipp, atol=1e-6)
        segment = int(item.SegmentIdentificationSequence[0].ReferencedSegmentNumber)
        expected = (liver if segment == 1 else tumour)[:, :, plane]
        np.testing.assert_array_equal(frames[f].T.astype(bool), expected)


def test_several_segments_without_choice_are_listed(two_segment_seg):
    path = two_segment_seg[0]
    with pytest.raises(LabelError, match="1: Liver, 2: Tumour"):
        read_dicom_seg(path)


@pytest.mark.parametrize("segment", [3, "Bone"])
def test_missing_segment_is_refused_with_the_list(two_segment_seg, segment):
    path = two_segment_seg[0]
    with pytest.raises(LabelError, match=r"not in .*1: Liver, 2: Tumour"):
        read_dicom_seg(path, segment=segment)


def test_single_frame_single_segment_is_read_without_a_choice(tmp_path):
    mask = np.zeros((6, 5, 4), bool)
    mask[2:5, 1:3, 2] = True
    affine = _oblique_affine()
    path = factory.write_seg(tmp_path / "one.dcm", {4: mask}, affine, labels={4: "Lesion"})
    assert int(pydicom.dcmread(path).NumberOfFrames) == 1

    volume = read_dicom_seg(path)

    # one plane: the grid holds only that plane, at the frame's position
    assert volume.shape == (6, 5, 1)
    np.testing.assert_array_equal(volume.mask[:, :, 0], mask[:, :, 2])
    np.testing.assert_allclose(
        volume.index_to_world([0, 0, 0]), affine[:3, 3] + 2 * affine[:3, 2], atol=1e-6
    )
    np.testing.assert_allclose(volume.spacing, [0.7, 1.2, 3.0], atol=1e-6)


def test_omitted_empty_frames_leave_empty_planes(tmp_path):
    mask = np.zeros((5, 5, 7), bool)
    mask[1:4, 1:4, [1, 2, 5]] = True  # planes 3 and 4 empty: their frames are omitted
    affine = _oblique_affine()
    path = factory.write_seg(tmp_path / "gap.dcm", {1: mask}, affine, labels={1: "A"})

    volume = read_dicom_seg(path)

    np.testing.assert_array_equal(volume.mask, mask[:, :, 1:6])
    np.testing.assert_allclose(
        volume.index_to_world([0, 0, 0]), affine[:3, 3] + affine[:3, 2], atol=1e-6
    )


def test_frames_off_the_regular_grid_are_refused(tmp_path):
    liver, _ = _two_segments()
    affine = _oblique_affine()
    path = factory.write_seg(tmp_path / "seg.dcm", {1: liver}, affine, labels={1: "Liver"})
    ds = pydicom.dcmread(path)
    position = ds.PerFrameFunctionalGroupsSequence[2].PlanePositionSequence[0]
    ipp = np.array([float(v) for v in position.ImagePositionPatient])
    position.ImagePositionPatient = [f"{v:.6f}" for v in ipp + 0.4 * affine[:3, 2]]
    ds.save_as(path)

    with pytest.raises(GeometryError, match="not evenly spaced"):
        read_dicom_seg(path)


def test_fractional_segmentation_is_thresholded_at_half(tmp_path):
    prob = np.zeros((6, 6, 3))
    prob[1:5, 1:5, :] = 0.3
    prob[2:4, 2:4, :] = 0.7
    path = factory.write_seg(
        tmp_path / "frac.dcm", {1: prob}, _oblique_affine(), labels={1: "P"}, fractional=True
    )

    np.testing.assert_array_equal(read_dicom_seg(path).mask, prob >= 0.5)


def _as_16_bit(path, *, bits=16, maximum=65535):
    """The fractional SEG at ``path`` rewritten with 16-bit values (0..255 -> 0..65535)."""
    ds = pydicom.dcmread(path)
    values = ds.pixel_array.astype(np.uint16) * 257
    ds.BitsAllocated, ds.BitsStored, ds.HighBit = bits, bits, bits - 1
    ds.MaximumFractionalValue = maximum
    ds.PixelData = values.tobytes()
    ds.save_as(path)
    return path


def test_a_16_bit_fractional_segmentation_is_read_as_16_bit(tmp_path, caplog):
    """highdicom cut its values to 8 bits: refused as "no foreground pixel"."""
    prob = np.zeros((6, 6, 3))
    prob[1:5, 1:5, :] = 0.3
    prob[2:4, 2:4, :] = 0.7
    path = factory.write_seg(
        tmp_path / "frac.dcm", {1: prob}, _oblique_affine(), labels={1: "P"}, fractional=True
    )
    _as_16_bit(path)
    with caplog.at_level("WARNING"):
        np.testing.assert_array_equal(read_dicom_seg(path).mask, prob >= 0.5)
    assert "16-bit values is not standard" in caplog.text
    _as_16_bit(path, maximum=0)
    with pytest.raises(FormatError, match="MaximumFractionalValue 0 is not"):
        read_dicom_seg(path)
    _as_16_bit(path, bits=32)
    with pytest.raises(FormatError, match="stores 8-bit values"):
        read_dicom_seg(path)


def test_empty_segment_raises_empty_mask_error(tmp_path):
    liver, _ = _two_segments()
    path = factory.write_seg(
        tmp_path / "seg.dcm",
        {1: liver, 2: np.zeros_like(liver)},
        _oblique_affine(),
        labels={1: "Liver", 2: "Nothing"},
        omit_empty_frames=False,
    )
    with pytest.raises(EmptyMaskError, match="Nothing"):
        read_dicom_seg(path, segment=2)


def test_non_seg_files_are_refused(tmp_path):
    paths = factory.write_series(tmp_path / "series", np.ones((3, 3, 2), bool), _oblique_affine())
    with pytest.raises(InputError, match="not a DICOM SEG"):
        read_dicom_seg(paths[0])
    with pytest.raises(InputError, match="not found"):
        read_dicom_seg(tmp_path / "missing.dcm")


def test_info_and_dispatcher(two_segment_seg):
    path, _, liver, _ = two_segment_seg

    info = dicom_info(path)

    assert info["kind"] == "dicom-seg" and info["segmentation_type"] == "BINARY"
    assert info["shape"] == [9, 8, 6]
    np.testing.assert_allclose(info["spacing_mm"], [0.7, 1.2, 3.0], atol=1e-6)
    assert info["segments"] == [
        {"number": 1, "label": "Liver", "value": 1, "colour": None, "n_frames": 4},
        {"number": 2, "label": "Tumour", "value": 2, "colour": None, "n_frames": 4},
    ]
    assert info["n_frames"] == 8
    np.testing.assert_array_equal(load_input(path, label=1).mask, liver)


# --------------------------------------------------------------------- who decodes
def _frames_path_refused(monkeypatch):
    """Make the pydicom frame-by-frame decoder fail, so a read proves highdicom did it."""
    from slicerecon.io.dicom import seg as seg_module

    def refuse(*args, **kwargs):
        raise AssertionError("decoded frame by frame, not by highdicom")

    monkeypatch.setattr(seg_module, "_mask_by_frames", refuse)


def _highdicom_refused(monkeypatch):
    from slicerecon.io.dicom import seg as seg_module

    monkeypatch.setattr(seg_module, "_mask_by_highdicom", lambda *args, **kwargs: None)


def _layouts():
    """(name, segments, affine, write_seg options, segment to read) covering what tests pin."""
    liver, tumour = _two_segments()
    gap = np.zeros((5, 5, 7), bool)
    gap[1:4, 1:4, [1, 2, 5]] = True
    prob = np.zeros((6, 6, 3))
    prob[1:5, 1:5, :] = 0.3
    prob[2:4, 2:4, 1:] = 0.7
    feet_first = _oblique_affine() @ np.diag([1.0, 1.0, -1.0, 1.0])  # slices run downwards
    return [
        ("two segments, by label", {1: liver, 2: tumour}, _oblique_affine(), {}, "Tumour"),
        ("omitted empty frames", {1: gap}, _oblique_affine(), {}, 1),
        ("fractional", {1: prob}, _oblique_affine(), {"fractional": True}, 1),
        ("feet first", {1: liver, 2: tumour}, feet_first, {}, 1),
        ("single frame", {4: gap[:, :, 2:3]}, _oblique_affine(), {}, 4),
    ]


@pytest.mark.parametrize("layout", _layouts(), ids=[layout[0] for layout in _layouts()])
def test_highdicom_and_the_frame_reader_give_the_same_volume(tmp_path, monkeypatch, layout):
    pytest.importorskip("highdicom")
    _, segments, affine, options, chosen = layout
    labels = {n: f"S{n}" for n in segments} | ({2: "Tumour"} if 2 in segments else {})
    path = factory.write_seg(tmp_path / "seg.dcm", segments, affine, labels=labels, **options)

    with monkeypatch.context() as m:
        _frames_path_refused(m)
        by_highdicom = read_dicom_seg(path, segment=chosen)
    with monkeypatch.context() as m:
        _highdicom_refused(m)
        by_frames = read_dicom_seg(path, segment=chosen)

    np.testing.assert_array_equal(by_highdicom.mask, by_frames.mask)
    np.testing.assert_array_equal(by_highdicom.affine, by_frames.affine)
    assert by_highdicom.mask.any()


def test_seg_without_dimension_index_is_read_as_before(tmp_path, two_segment_seg, monkeypatch):
    """Older exporters leave out DimensionIndexSequence; highdicom refuses them, we do not."""
    _, affine, liver, tumour = two_segment_seg
    path = factory.write_seg(
        tmp_path / "legacy.dcm",
        {1: liver, 2: tumour},
        affine,
        labels={1: "Liver", 2: "Tumour"},
        dimension_index=False,
    )
    assert "DimensionIndexSequence" not in pydicom.dcmread(path)

    volume = read_dicom_seg(path, segment="Tumour")

    np.testing.assert_array_equal(volume.mask, tumour)
    np.testing.assert_allclose(volume.affine, affine, atol=1e-6)


def test_seg_stacked_along_a_tilted_line_keeps_the_shear(tmp_path):
    """Frames of a gantry-tilted CT step sideways: highdicom cannot stack them, we can."""
    affine = factory.affine_from_geometry(
        [1, 0, 0], [0, 1, 0], [0.8, 0.8], [0.0, 0.9, 2.5], [-10.0, -12.0, 4.0]
    )
    mask = np.zeros((8, 9, 5), bool)
    mask[2:6, 3:7, 1:4] = True
    path = factory.write_seg(tmp_path / "tilt.dcm", {1: mask}, affine, labels={1: "Tilted"})

    volume = read_dicom_seg(path)

    np.testing.assert_array_equal(volume.mask, mask[:, :, 1:4])
    np.testing.assert_allclose(volume.affine[:3, 2], [0.0, 0.9, 2.5], atol=1e-6)
    np.testing.assert_allclose(volume.affine[:3, 3], affine[:3, 3] + affine[:3, 2], atol=1e-6)


def test_two_frames_of_one_segment_at_one_position_are_refused(tmp_path):
    liver, _ = _two_segments()
    path = factory.write_seg(
        tmp_path / "seg.dcm", {1: liver}, _oblique_affine(), labels={1: "Liver"}
    )
    ds = pydicom.dcmread(path)
    frames = ds.PerFrameFunctionalGroupsSequence
    frames[1].PlanePositionSequence[0].ImagePositionPatient = (
        frames[0].PlanePositionSequence[0].ImagePositionPatient
    )
    ds.save_as(path)

    with pytest.raises(GeometryError, match="two frames of one segment at the same position"):
        read_dicom_seg(path)


def test_labelmap_segmentation_is_refused(tmp_path):
    liver, _ = _two_segments()
    path = factory.write_seg(
        tmp_path / "seg.dcm", {1: liver}, _oblique_affine(), labels={1: "Liver"}
    )
    ds = pydicom.dcmread(path)
    ds.SegmentationType = "LABELMAP"
    ds.save_as(path)

    with pytest.raises(InputError, match="LABELMAP is not supported"):
        read_dicom_seg(path)


def test_seg_grid_over_the_memory_budget_is_refused_before_decoding(tmp_path, monkeypatch):
    from slicerecon.errors import MemoryBudgetError
    from slicerecon.io.dicom import seg as seg_module

    liver, _ = _two_segments()
    path = factory.write_seg(
        tmp_path / "seg.dcm", {1: liver}, _oblique_affine(), labels={1: "Liver"}
    )
    ds = pydicom.dcmread(path)
    ds.Rows, ds.Columns = 60000, 60000  # declared, never decoded
    ds.save_as(path)
    monkeypatch.setattr(seg_module, "_mask_by_highdicom", None)  # must not be reached

    with pytest.raises(MemoryBudgetError, match="memory budget"):
        read_dicom_seg(path)


def test_a_seg_whose_frames_are_thinner_than_their_gaps_is_an_annotation(tmp_path, capsys):
    """highdicom writes a SEG drawn on every 3rd slice of a 2.5 mm CT with SliceThickness
    2.5 and SpacingBetweenSlices 7.5 (its frames' spacing). Given alone it was read as a
    dense mask of 7.5 mm slices, planned and scored against itself (volume IoU 1.0 in
    metrics.json). Frames thinner than their gaps by a whole factor are slices with
    slices between them: an annotation, as beside its series."""
    from slicerecon.case_inputs import reading_of
    from slicerecon.cli import main

    affine = np.diag([0.8, 0.8, 2.5, 1.0])
    centres = np.indices((40, 36, 32)).reshape(3, -1).T * [0.8, 0.8, 2.5]
    truth = ((((centres - [16, 14, 40]) / [10, 9, 33]) ** 2).sum(axis=1) <= 1).reshape(40, 36, 32)
    drawn = np.zeros_like(truth)
    drawn[:, :, 1::3] = truth[:, :, 1::3]
    path = factory.write_seg(tmp_path / "seg.dcm", {1: drawn}, affine, labels={1: "Organ"})
    ds = pydicom.dcmread(path)
    measures = ds.SharedFunctionalGroupsSequence[0].PixelMeasuresSequence[0]
    measures.SpacingBetweenSlices = "7.5"
    ds.save_as(path)
    assert read_dicom_seg(path).affine[2, 2] == pytest.approx(2.5)
    assert reading_of(path).startswith("sparse annotation")  # info says what run reads
    assert main(["run", str(path), "-o", str(tmp_path / "out")]) == 0
    assert "read as: sparse annotation" in capsys.readouterr().out
    assert not (tmp_path / "out" / "metrics.json").exists()


@pytest.mark.parametrize("slices", [list(range(2, 30, 2)), [2, 4, 7, 10, 14, 17, 19, 23, 26, 28]])
def test_a_seg_drawn_on_some_slices_of_its_series_is_an_annotation(tmp_path, capsys, slices):
    """A SEG drawn on every 2nd CT slice (or on irregular ones) was read on a grid of its
    frames (5 mm apart) as a dense mask and scored against itself (Dice 1), or refused
    as "not evenly spaced". Its planes are now the series' slices (SpacingBetweenSlices),
    the slices between them not annotated, and it is reconstructed as an annotation."""
    from slicerecon.cli import main

    affine = np.diag([0.8, 0.8, 2.5, 1.0])
    centres = np.indices((40, 36, 32)).reshape(3, -1).T * [0.8, 0.8, 2.5]
    truth = ((((centres - [16, 14, 40]) / [10, 9, 33]) ** 2).sum(axis=1) <= 1).reshape(40, 36, 32)
    drawn = np.zeros_like(truth)
    drawn[:, :, slices] = truth[:, :, slices]
    path = factory.write_seg(tmp_path / "seg.dcm", {1: drawn}, affine, labels={1: "Organ"})
    volume = read_dicom_seg(path)
    assert np.allclose(np.linalg.norm(volume.affine[:3, :3], axis=0), [0.8, 0.8, 2.5])
    assert main(["run", str(path), "-o", str(tmp_path / "out")]) == 0
    said = capsys.readouterr().out
    assert "read as: sparse annotation" in said and "quality" not in said
    assert not (tmp_path / "out" / "metrics.json").exists()
    import json

    import trimesh

    from slicerecon.rasterize import mesh_to_mask

    out = tmp_path / "out"
    assert json.loads((out / "structures.json").read_text())["coordinates"] == "LPS"
    result = mesh_to_mask(trimesh.load(out / "mesh.stl"), affine, truth.shape)
    assert np.count_nonzero(result & truth) / np.count_nonzero(result | truth) > 0.9
