"""Tests for slicerecon.io.nifti: label-map reading, mask writing, clear errors."""

from __future__ import annotations

import gzip
import warnings

import nibabel as nib
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from slicerecon.errors import (
    EmptyMaskError,
    FormatError,
    InputError,
    LabelError,
    OptionError,
)
from slicerecon.io.nifti import nifti_labels, read_nifti, write_nifti
from slicerecon.sections import Volume


def _oblique_affine() -> np.ndarray:
    affine = np.eye(4)
    rotation = Rotation.from_euler("xyz", [17.0, -32.0, 58.0], degrees=True).as_matrix()
    affine[:3, :3] = rotation @ np.diag([0.8, 1.1, 2.5])
    affine[:3, 3] = [-101.25, 37.5, 212.125]
    return affine


def _label_map() -> np.ndarray:
    labels = np.zeros((9, 8, 7), dtype=np.int16)
    labels[1:4, 2:6, 1:3] = 1
    labels[5:8, 1:3, 2:6] = 2
    labels[4, 6, 5] = 5
    return labels


def _save(data: np.ndarray, path, affine: np.ndarray | None = None):
    nib.save(nib.Nifti1Image(data, np.eye(4) if affine is None else affine), path)
    return path


@pytest.mark.parametrize("suffix", [".nii", ".nii.gz"])
def test_round_trip_keeps_mask_and_oblique_anisotropic_affine(tmp_path, suffix):
    rng = np.random.default_rng(0)
    mask = rng.random((13, 11, 6)) < 0.3
    volume = Volume(mask, _oblique_affine())
    written = write_nifti(volume, tmp_path / "sub" / f"mask{suffix}")
    assert written == tmp_path / "sub" / f"mask{suffix}"
    assert [p.name for p in written.parent.iterdir()] == [f"mask{suffix}"]  # no temp left
    back = read_nifti(written)
    np.testing.assert_array_equal(back.mask, mask)
    np.testing.assert_allclose(back.affine, volume.affine, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(back.spacing, [0.8, 1.1, 2.5], rtol=1e-6)
    header = nib.load(written).header
    assert int(header["sform_code"]) == 1 and int(header["qform_code"]) == 1
    assert header.get_xyzt_units()[0] == "mm"
    # the qform alone gives the same geometry (readers that ignore the sform agree)
    np.testing.assert_allclose(header.get_qform(), volume.affine, atol=1e-4)
    if suffix == ".nii.gz":
        with gzip.open(written) as fh:
            assert len(fh.read(348)) == 348


def test_sheared_affine_round_trips_through_the_sform(tmp_path):
    affine = np.diag([0.7, 0.7, 3.0, 1.0])
    affine[0, 2] = 0.4  # gantry-tilt-like shear
    volume = Volume(np.ones((3, 4, 5), dtype=bool), affine)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        path = write_nifti(volume, tmp_path / "shear.nii.gz")
    np.testing.assert_allclose(read_nifti(path).affine, affine, atol=1e-6)


def test_write_other_dtype_and_bad_options(tmp_path):
    volume = Volume(np.eye(3, dtype=bool)[:, :, None].repeat(2, axis=2))
    path = write_nifti(volume, tmp_path / "m.nii", dtype=np.int16)
    assert nib.load(path).get_data_dtype() == np.int16
    np.testing.assert_array_equal(read_nifti(path).mask, volume.mask)
    with pytest.raises(OptionError, match=r"\.nii or \.nii\.gz"):
        write_nifti(volume, tmp_path / "m.nrrd")
    with pytest.raises(OptionError, match="dtype"):
        write_nifti(volume, tmp_path / "m.nii", dtype=np.complex64)
    with pytest.raises(InputError, match="needs a Volume"):
        write_nifti(volume.mask, tmp_path / "m.nii")  # type: ignore[arg-type]


def test_label_selection_and_union(tmp_path):
    labels = _label_map()
    path = _save(labels, tmp_path / "labels.nii.gz", _oblique_affine())
    np.testing.assert_array_equal(read_nifti(path, label=2).mask, labels == 2)
    np.testing.assert_array_equal(read_nifti(path, label=np.int64(5)).mask, labels == 5)
    union = read_nifti(path)
    np.testing.assert_array_equal(union.mask, labels != 0)
    np.testing.assert_allclose(union.affine, _oblique_affine(), atol=1e-5)


def test_float_label_map_with_integer_values_is_accepted(tmp_path):
    labels = _label_map().astype(np.float32)
    path = _save(labels, tmp_path / "float_labels.nii")
    np.testing.assert_array_equal(read_nifti(path, label=1).mask, labels == 1)


def test_nifti_labels_reports_geometry_and_counts(tmp_path):
    labels = _label_map()
    path = _save(labels, tmp_path / "labels.nii.gz", _oblique_affine())
    info = nifti_labels(path)
    assert info.shape == (9, 8, 7)
    assert info.labels == {1: 24, 2: 24, 5: 1}
    np.testing.assert_allclose(info.spacing, [0.8, 1.1, 2.5], rtol=1e-6)
    assert info.axcodes == nib.aff2axcodes(_oblique_affine())
    as_dict = info.to_dict()
    assert as_dict["labels"] == {"1": 24, "2": 24, "5": 1}
    assert as_dict["shape"] == [9, 8, 7]


def test_singleton_4d_is_squeezed_and_true_4d_is_refused(tmp_path):
    labels = _label_map()
    path = _save(labels[..., None], tmp_path / "single.nii.gz")
    np.testing.assert_array_equal(read_nifti(path, label=2).mask, labels == 2)
    series = _save(np.stack([labels, labels], axis=-1), tmp_path / "series.nii.gz")
    with pytest.raises(InputError, match=r"4-D image .* holding 2 volumes"):
        read_nifti(series)


def test_missing_file(tmp_path):
    with pytest.raises(InputError, match="not found"):
        read_nifti(tmp_path / "nope.nii.gz")


@pytest.mark.parametrize(
    ("name", "content"),
    [
        ("noise.nii", bytes(np.random.default_rng(1).integers(0, 256, 2000, dtype=np.uint8))),
        ("noise.nii.gz", b"\x1f\x8b not really gzip"),
        ("empty.nii.gz", b""),
    ],
)
def test_corrupt_bytes_raise_format_error(tmp_path, name, content):
    path = tmp_path / name
    path.write_bytes(content)
    with pytest.raises(FormatError, match="corrupt"):
        read_nifti(path)


@pytest.mark.parametrize("suffix", [".nii", ".nii.gz"])
def test_truncated_file_raises_format_error(tmp_path, suffix):
    good = _save(np.ones((20, 20, 20), dtype=np.uint8), tmp_path / f"good{suffix}")
    data = good.read_bytes()
    if suffix == ".nii.gz":
        data = gzip.compress(gzip.decompress(data)[:2000])  # valid gzip, short image
    else:
        data = data[:2000]
    bad = tmp_path / f"bad{suffix}"
    bad.write_bytes(data)
    with pytest.raises(FormatError, match="corrupt or truncated"):
        read_nifti(bad)


def test_non_nifti_image_raises_format_error(tmp_path):
    path = tmp_path / "image.mgz"
    nib.save(nib.MGHImage(_label_map().astype(np.int32), np.eye(4)), path)
    with pytest.raises(FormatError, match="not a NIfTI image"):
        read_nifti(path)


def test_empty_mask(tmp_path):
    path = _save(np.zeros((4, 4, 4), dtype=np.uint8), tmp_path / "zeros.nii.gz")
    with pytest.raises(EmptyMaskError, match="every voxel is 0"):
        read_nifti(path)
    with pytest.raises(EmptyMaskError, match="label 3 is absent"):
        read_nifti(path, label=3)


def test_absent_label_lists_labels_present(tmp_path):
    path = _save(_label_map(), tmp_path / "labels.nii.gz")
    with pytest.raises(LabelError, match=r"label 3 is absent .* labels present: 1, 2, 5"):
        read_nifti(path, label=3)
    with pytest.raises(OptionError, match="integer label"):
        read_nifti(path, label=2.5)  # type: ignore[arg-type]


def test_non_integer_floats_are_not_a_label_map(tmp_path):
    image = np.linspace(0.0, 1.0, 64, dtype=np.float32).reshape(4, 4, 4)
    path = _save(image, tmp_path / "t1.nii.gz")
    with pytest.raises(LabelError, match="not a label map: it holds non-integer values"):
        read_nifti(path)
    image[0, 0, 0] = np.nan
    path = _save(image, tmp_path / "nan.nii.gz")
    with pytest.raises(LabelError, match="NaN"):
        nifti_labels(path)


@pytest.mark.parametrize("codes", [(4, 0), (2, 0), (0, 1), (1, 1)])
def test_labels_keep_the_xform_codes_of_a_nifti_input(tmp_path, codes):
    """labels.nii.gz rewrote an MNI-coded input's codes (4/0 or 2/0) as scanner space (1/1)."""
    from slicerecon.io.outputs import write_label_outputs
    from slicerecon.labels import Structure

    labels = np.zeros((8, 7, 6), np.uint8)
    labels[2:6, 2:5, 1:5] = 3
    affine = np.array([[-1.5, 0, 0, 90.0], [0, 1.5, 0, -126.0], [0, 0, 1.5, -72.0], [0, 0, 0, 1]])
    image = nib.Nifti1Image(labels, affine)
    image.set_sform(affine, code=codes[0])
    image.set_qform(affine, code=codes[1])
    source = tmp_path / "template.nii.gz"
    nib.save(image, source)
    structures = [Structure(3, "GM")]

    write_label_outputs(tmp_path / "same", labels, affine, structures, source=source)
    back = nib.load(tmp_path / "same" / "labels.nii.gz")
    assert (int(back.header["sform_code"]), int(back.header["qform_code"])) == codes
    np.testing.assert_allclose(back.affine, nib.load(source).affine, atol=1e-5)

    # no NIfTI input, or labels on another grid: scanner anatomical, 1 and 1
    write_label_outputs(tmp_path / "none", labels, affine, structures)
    shifted = affine.copy()
    shifted[:3, 3] += 10.0
    write_label_outputs(tmp_path / "other", labels, shifted, structures, source=source)
    for name in ("none", "other"):
        header = nib.load(tmp_path / name / "labels.nii.gz").header
        assert (int(header["sform_code"]), int(header["qform_code"])) == (1, 1)


def test_label_values_beyond_32_bits_are_refused(tmp_path, capsys):
    """A scale factor of 3.4e38 made every label value overflow deep in the pipeline."""
    from slicerecon.cli import main

    mask = np.zeros((6, 6, 4), np.uint8)
    mask[1:5, 1:5, 1:3] = 1
    image = nib.Nifti1Image(mask, np.eye(4))
    image.header.set_slope_inter(3.4e38, 0.0)
    path = tmp_path / "scaled.nii"
    nib.save(image, path)
    with pytest.raises(LabelError, match="beyond the 32-bit integers"):
        read_nifti(path)
    assert main(["run", str(path), "-o", str(tmp_path / "out"), "-q"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "32-bit integers" in err[0]
