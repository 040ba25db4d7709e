"""DICOM image series of a mask: geometry round trips, sorting and clear errors."""

from __future__ import annotations

from pathlib import Path

import dicom_factory as factory  # tests/io, on pytest's pythonpath
import numpy as np
import pydicom
import pytest

from slicerecon.errors import (
    EmptyMaskError,
    FormatError,
    GeometryError,
    InputError,
    LabelError,
)
from slicerecon.io import load_input
from slicerecon.io.dicom import dicom_info, dicom_series_geometry, read_dicom_series


def _rotation(seed: int) -> np.ndarray:
    q, r = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def _oblique_affine(spacing=(0.6, 0.9, 2.5), origin=(-120.5, 33.25, 71.0), seed=7):
    """Oblique, anisotropic, right-handed grid: slice step along +row × column."""
    rot = _rotation(seed)
    return factory.affine_from_geometry(
        rot[:, 0], rot[:, 1], (spacing[1], spacing[0]), rot[:, 2] * spacing[2], origin
    )


def _blob(shape=(7, 9, 5), seed=0) -> np.ndarray:
    """An asymmetric mask: a random blob, so any axis flip or transpose is caught."""
    rng = np.random.default_rng(seed)
    mask = rng.random(shape) > 0.6
    mask[0, 0, 0] = True
    mask[-1, -1, -1] = False
    return mask


def _ipp(path: Path) -> np.ndarray:
    ds = pydicom.dcmread(path, stop_before_pixels=True)
    return np.array([float(v) for v in ds.ImagePositionPatient])


def test_oblique_anisotropic_round_trip(tmp_path):
    mask = _blob()
    affine = _oblique_affine()
    paths = factory.write_series(tmp_path / "series", mask, affine)

    volume = read_dicom_series(tmp_path / "series")

    assert volume.shape == mask.shape
    np.testing.assert_array_equal(volume.mask, mask)
    np.testing.assert_allclose(volume.affine, affine, atol=1e-6)
    np.testing.assert_allclose(volume.spacing, [0.6, 0.9, 2.5], atol=1e-6)
    for k, path in enumerate(paths):
        np.testing.assert_allclose(volume.index_to_world([0, 0, k]), _ipp(path), atol=1e-6)
    # pixel (row r, column c) of slice k is voxel (c, r, k)
    ds = pydicom.dcmread(paths[2])
    np.testing.assert_array_equal(ds.pixel_array.astype(bool), volume.mask[:, :, 2].T)


def test_geometry_only_matches_reader_and_lists_uids_in_slice_order(tmp_path):
    mask = _blob(seed=1)
    affine = _oblique_affine(seed=11)
    paths = factory.write_series(tmp_path, mask, affine)

    geo_affine, shape, uids = dicom_series_geometry(tmp_path)

    assert shape == mask.shape
    np.testing.assert_allclose(geo_affine, read_dicom_series(tmp_path).affine, atol=0)
    assert uids == factory.read_uids(paths)


def test_sorted_by_position_not_instance_number_or_file_name(tmp_path):
    mask = _blob(shape=(6, 5, 8), seed=2)
    affine = _oblique_affine(seed=3)
    rng = np.random.default_rng(5)
    names = [f"img{n:03d}.dcm" for n in rng.permutation(8)]
    numbers = list(rng.permutation(8) + 1)
    paths = factory.write_series(tmp_path, mask, affine, file_names=names, instance_numbers=numbers)
    assert sorted(p.name for p in paths) != [p.name for p in paths]

    volume = read_dicom_series(tmp_path)

    np.testing.assert_array_equal(volume.mask, mask)
    np.testing.assert_allclose(volume.affine, affine, atol=1e-6)


def test_reversed_slice_axis_keeps_world_geometry(tmp_path):
    """A grid stepping against row × column is read sorted along it: same voxels in space."""
    mask = _blob(seed=4)
    affine = _oblique_affine(seed=5)
    affine[:3, 2] *= -1
    factory.write_series(tmp_path, mask, affine)

    volume = read_dicom_series(tmp_path)

    np.testing.assert_array_equal(volume.mask, mask[:, :, ::-1])
    np.testing.assert_allclose(
        _world_points(volume.mask, volume.affine), _world_points(mask, affine), atol=1e-6
    )


def _world_points(mask: np.ndarray, affine: np.ndarray) -> np.ndarray:
    """World mm of the foreground voxel centres, sorted lexicographically, shape (N, 3)."""
    world = np.argwhere(mask).astype(float) @ affine[:3, :3].T + affine[:3, 3]
    return world[np.lexsort(np.round(world, 4).T[::-1])]


def test_gantry_tilt_shear_is_kept_in_the_affine(tmp_path):
    mask = _blob(shape=(5, 6, 6), seed=6)
    affine = factory.affine_from_geometry(
        [1, 0, 0], [0, 1, 0], [0.8, 0.7], [0.0, 0.9, 3.0], [10.0, -20.0, 5.0]
    )
    paths = factory.write_series(tmp_path, mask, affine)

    volume = read_dicom_series(tmp_path)

    np.testing.assert_array_equal(volume.mask, mask)
    for k, path in enumerate(paths):
        np.testing.assert_allclose(volume.index_to_world([0, 0, k]), _ipp(path), atol=1e-6)


def test_rescale_slope_intercept_is_applied(tmp_path):
    mask = _blob(seed=8)
    values = np.where(mask, 3.0, 0.0)
    # real value 0 is stored as raw 2: ignoring the rescale would make every voxel foreground
    factory.write_series(tmp_path, values, _oblique_affine(), rescale=(0.5, -1.0))

    volume = read_dicom_series(tmp_path)

    np.testing.assert_array_equal(volume.mask, mask)


def test_label_selects_one_value_and_missing_label_is_named(tmp_path):
    labels = np.zeros((6, 6, 4), dtype=np.uint16)
    labels[1:3, 1:4, 1:3] = 1
    labels[3:5, 2:5, 0:4] = 2
    factory.write_series(tmp_path, labels, _oblique_affine())

    np.testing.assert_array_equal(read_dicom_series(tmp_path, label=2).mask, labels == 2)
    np.testing.assert_array_equal(read_dicom_series(tmp_path).mask, labels > 0)
    with pytest.raises(LabelError, match=r"label 7 .*found: 0, 1, 2"):
        read_dicom_series(tmp_path, label=7)


def test_irregular_spacing_is_refused_with_a_pointer_to_allow_irregular(tmp_path):
    factory.write_series(tmp_path, _blob(), _oblique_affine(), irregular_positions=[0, 2, 4, 7, 9])
    with pytest.raises(GeometryError, match="allow-irregular") as raised:
        read_dicom_series(tmp_path)
    # the folder, and the two files around the widest gap (a slice missing between them)
    assert str(raised.value).startswith(f"{tmp_path}: slice spacing is irregular")
    names = sorted(p.name for p in tmp_path.glob("*.dcm"))
    assert f"the widest between {names[2]} and {names[3]}" in str(raised.value)
    with pytest.raises(GeometryError, match="irregular"):
        dicom_series_geometry(tmp_path)


def test_allow_irregular_places_each_slice_on_its_nearest_plane(tmp_path):
    positions = [0.0, 2.0, 4.0, 7.0, 9.0]  # smallest gap 2 mm -> 5 steps of 1.8 mm
    mask = np.zeros((6, 5, 5), dtype=bool)
    for k in range(5):  # slice k: a single row of k + 1 voxels, to tell slices apart
        mask[: k + 1, 2, k] = True
    affine = _oblique_affine(spacing=(0.6, 0.9, 1.0), seed=9)
    paths = factory.write_series(tmp_path, mask, affine, irregular_positions=positions)
    uids = factory.read_uids(paths)

    volume = read_dicom_series(tmp_path, allow_irregular=True)
    geo_affine, shape, plane_uids = dicom_series_geometry(tmp_path, allow_irregular=True)

    assert volume.shape == shape == (6, 5, 6)
    np.testing.assert_allclose(volume.spacing, [0.6, 0.9, 1.8], atol=1e-6)
    np.testing.assert_allclose(geo_affine, volume.affine)
    home = [0, 1, 2, 4, 5]
    assert plane_uids == [uids[0], uids[1], uids[2], "", uids[3], uids[4]]
    for k, plane in enumerate(home):
        np.testing.assert_array_equal(volume.mask[:, :, plane], mask[:, :, k])
        offset = np.linalg.norm(volume.index_to_world([0, 0, plane]) - _ipp(paths[k]))
        assert offset <= 0.9 + 1e-6  # within half a step of the slice's own position
    # plane 3 (5.4 mm) copies the nearest slice (4 mm, slice 2)
    np.testing.assert_array_equal(volume.mask[:, :, 3], mask[:, :, 2])
    np.testing.assert_allclose(volume.index_to_world([0, 0, 5]), _ipp(paths[4]), atol=1e-6)


def test_non_parallel_slices_are_refused(tmp_path):
    affine = _oblique_affine(seed=2)
    row, col = affine[:3, 0] / 0.9, affine[:3, 1] / 0.6
    angle = np.deg2rad(5.0)
    normal = np.cross(row, col)
    tilted_col = np.cos(angle) * col + np.sin(angle) * normal
    factory.write_series(tmp_path, _blob(), affine, orientation_overrides={2: [*row, *tilted_col]})
    with pytest.raises(GeometryError, match="not parallel"):
        read_dicom_series(tmp_path)


def test_duplicate_positions_are_refused(tmp_path):
    factory.write_series(tmp_path, _blob(), _oblique_affine(), irregular_positions=[0, 2, 2, 4, 6])
    with pytest.raises(GeometryError, match="duplicate"):
        read_dicom_series(tmp_path)


def test_differing_image_sizes_are_refused(tmp_path):
    uids = {
        "series_uid": pydicom.uid.generate_uid(),
        "study_uid": pydicom.uid.generate_uid(),
        "frame_of_reference_uid": pydicom.uid.generate_uid(),
    }
    affine = _oblique_affine()
    factory.write_series(tmp_path, _blob(shape=(7, 9, 3)), affine, **uids)
    shifted = affine.copy()
    shifted[:3, 3] += 3 * affine[:3, 2]
    factory.write_series(
        tmp_path, _blob(shape=(7, 8, 2)), shifted, file_names=["b0.dcm", "b1.dcm"], **uids
    )
    with pytest.raises(GeometryError, match="differ in size"):
        read_dicom_series(tmp_path)


def test_two_series_in_one_directory_are_named(tmp_path):
    affine = _oblique_affine()
    factory.write_series(tmp_path, _blob(), affine, series_uid="1.2.3.4.100")
    factory.write_series(
        tmp_path,
        _blob(),
        affine,
        series_uid="1.2.3.4.200",
        file_names=[f"other{k}.dcm" for k in range(5)],
    )
    with pytest.raises(InputError, match=r"1\.2\.3\.4\.100.*1\.2\.3\.4\.200|1\.2\.3\.4\.200.*100"):
        read_dicom_series(tmp_path)


@pytest.mark.parametrize("cut", [300, -10], ids=["in-header", "in-pixel-data"])
def test_truncated_file_raises_format_error_naming_it(tmp_path, cut):
    paths = factory.write_series(tmp_path, _blob(), _oblique_affine())
    paths[3].write_bytes(paths[3].read_bytes()[:cut])
    with pytest.raises(FormatError, match=paths[3].name):
        read_dicom_series(tmp_path)


def test_garbage_named_like_dicom_raises_format_error(tmp_path):
    factory.write_series(tmp_path, _blob(), _oblique_affine())
    (tmp_path / "broken.dcm").write_bytes(b"not a dicom file at all" * 10)
    with pytest.raises(FormatError, match="broken.dcm"):
        read_dicom_series(tmp_path)


def test_unrelated_files_and_non_image_objects_are_skipped(tmp_path):
    mask = _blob(seed=3)
    factory.write_series(tmp_path, mask, _oblique_affine())
    (tmp_path / "README.txt").write_text("exported by a scanner")
    rt = pydicom.Dataset()
    rt.file_meta = pydicom.dataset.FileMetaDataset()
    rt.file_meta.MediaStorageSOPClassUID = "1.2.840.10008.5.1.4.1.1.481.3"
    rt.file_meta.MediaStorageSOPInstanceUID = pydicom.uid.generate_uid()
    rt.file_meta.TransferSyntaxUID = pydicom.uid.ExplicitVRLittleEndian
    rt.SOPClassUID = "1.2.840.10008.5.1.4.1.1.481.3"
    rt.SOPInstanceUID = rt.file_meta.MediaStorageSOPInstanceUID
    rt.Modality = "RTSTRUCT"
    rt.SeriesInstanceUID = pydicom.uid.generate_uid()
    rt.save_as(tmp_path / "rtstruct.dcm", enforce_file_format=True)

    np.testing.assert_array_equal(read_dicom_series(tmp_path).mask, mask)


def test_empty_mask_raises_empty_mask_error(tmp_path):
    factory.write_series(tmp_path, np.zeros((4, 4, 3), bool), _oblique_affine())
    with pytest.raises(EmptyMaskError):
        read_dicom_series(tmp_path)


def test_missing_or_wrong_paths_raise_input_error(tmp_path):
    with pytest.raises(InputError, match="not found"):
        read_dicom_series(tmp_path / "nope")
    (tmp_path / "notes.txt").write_text("hello")
    with pytest.raises(InputError, match="no DICOM image"):
        read_dicom_series(tmp_path)
    with pytest.raises(InputError, match="directory"):
        read_dicom_series(tmp_path / "notes.txt")


def test_single_slice_takes_its_thickness_as_step(tmp_path):
    mask = np.zeros((5, 4, 1), bool)
    mask[1:4, 1:3, 0] = True
    affine = _oblique_affine(spacing=(0.6, 0.9, 3.0))
    factory.write_series(tmp_path, mask, affine)

    volume = read_dicom_series(tmp_path)

    np.testing.assert_array_equal(volume.mask, mask)
    np.testing.assert_allclose(volume.affine, affine, atol=1e-6)


def test_info_and_dispatcher(tmp_path):
    mask = _blob()
    factory.write_series(tmp_path / "a", mask, _oblique_affine(), modality="CT")
    factory.write_series(
        tmp_path / "b", mask, _oblique_affine(), irregular_positions=[0, 2, 4, 7, 9]
    )

    info = dicom_info(tmp_path / "a")
    assert info["kind"] == "dicom-series" and info["modality"] == "CT"
    assert info["shape"] == [7, 9, 5] and info["n_slices"] == 5
    np.testing.assert_allclose(info["spacing_mm"], [0.6, 0.9, 2.5], atol=1e-6)
    assert info["regular_spacing"] is True and info["coordinates"] == "LPS"
    irregular = dicom_info(tmp_path / "b")
    assert irregular["regular_spacing"] is False
    assert irregular["slice_gap_mm"] == {"min": 2.0, "max": 3.0}

    volume = load_input(tmp_path / "a")
    np.testing.assert_array_equal(volume.mask, mask)


def test_info_says_run_refuses_an_irregular_series(tmp_path, capsys):
    """info described a series with a slice missing on the grid --allow-irregular gives,
    with a warning saying slices were "placed on a regular grid", and exit 0; run
    refuses the same series. info now says so."""
    from slicerecon.cli import main

    factory.write_series(tmp_path, _blob(), _oblique_affine(), irregular_positions=[0, 2, 4, 7, 9])
    assert main(["info", str(tmp_path)]) == 0
    said = capsys.readouterr().err
    assert "slicerecon run refuses this series (irregular slice spacing)" in said
    assert main(["info", str(tmp_path), "--allow-irregular"]) == 0
    assert "run refuses this series" not in capsys.readouterr().err
