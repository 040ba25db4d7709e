"""One case pipeline for one structure and many: the same functions, one on-disk schema."""

from __future__ import annotations

import json
from pathlib import Path

import nibabel as nib
import numpy as np
import pytest
import trimesh

import slicerecon.case as case_module
import slicerecon.case_outputs as outputs_module
from slicerecon.case import reconstruct_structures, run_case
from slicerecon.cli import main
from slicerecon.errors import LabelError, OptionError
from slicerecon.io import load_input
from slicerecon.labels import LabelMap
from slicerecon.reconstruct import ReconstructConfig

SPACING = (1.0, 1.0, 2.0)


def _grid(shape: tuple[int, int, int] = (40, 36, 24)) -> tuple[np.ndarray, ...]:
    return tuple(
        a * s
        for a, s in zip(
            np.meshgrid(*[np.arange(n) for n in shape], indexing="ij"), SPACING, strict=True
        )
    )


def _labels(n: int) -> np.ndarray:
    """``n`` (1 or 4) balls and bars; the first two touch."""
    x, y, z = _grid()
    labels = np.zeros(x.shape, np.uint8)
    ball = (x - 20) ** 2 + (y - 18) ** 2 + (z - 24) ** 2 < 12**2
    labels[ball & (x < 20)] = 1
    if n > 1:
        labels[ball & (x >= 20)] = 2
        labels[(x - 32) ** 2 + (y - 28) ** 2 + (z - 12) ** 2 < 4**2] = 3
        labels[(np.abs(x - 6) < 3) & (np.abs(y - 30) < 3) & (z > 6) & (z < 40)] = 4
    return labels


def _write(labels: np.ndarray, path: Path) -> Path:
    nib.save(nib.Nifti1Image(labels, np.diag([*SPACING, 1.0])), path)
    return path


@pytest.mark.parametrize("n", [1, 4])
def test_one_and_four_structures_go_through_the_same_functions(
    n: int, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = _write(_labels(n), tmp_path / f"labels{n}.nii.gz")
    calls: list[str] = []

    def spy(module: object, name: str) -> None:
        real = getattr(module, name)

        def wrapped(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
            calls.append(name)
            return real(*args, **kwargs)

        monkeypatch.setattr(module, name, wrapped)

    for name in ("load_case", "reconstruct_case", "score_case", "reconstruct"):
        spy(case_module, name)
    spy(outputs_module, "write_label_outputs")
    out = tmp_path / "out"
    summary = run_case(path, out, ReconstructConfig(slices=8, n_points=2000))
    assert calls[:2] == ["load_case", "reconstruct_case"]
    assert calls.count("reconstruct") == n  # one reconstruction per structure
    assert calls[-2:] == ["score_case", "write_label_outputs"]

    # one schema: the records say where each mesh is, whatever the count
    records = json.loads((out / "structures.json").read_text())["structures"]
    assert [r["value"] for r in records] == list(range(1, n + 1))
    meshes = [out / r["mesh"] for r in records]
    assert meshes == (
        [out / "mesh.stl"] if n == 1 else [out / "meshes" / f"{v}.stl" for v in (1, 2, 3, 4)]
    )
    assert all(trimesh.load(m).is_watertight for m in meshes)
    metrics = json.loads((out / "metrics.json").read_text())
    assert set(metrics["structures"]) == {str(v) for v in range(1, n + 1)}
    assert metrics["volume_iou"] == pytest.approx(
        np.mean([m["volume_iou"] for m in metrics["structures"].values()])
    )
    plan = json.loads((out / "plan.json").read_text())
    assert len(plan["structures"]) == n
    assert len(plan["parts"]) == sum(len(s["plan"]["parts"]) for s in plan["structures"])
    assert summary["parts"] == len(plan["parts"]) and summary["watertight"]


def test_the_python_entry_point_takes_a_path_or_an_array_with_its_affine(tmp_path: Path) -> None:
    labels = _labels(4)
    path = _write(labels, tmp_path / "four.nii.gz")
    from_file = reconstruct_structures(path, slices=8)
    from_array = reconstruct_structures((labels, np.diag([*SPACING, 1.0])), slices=8)
    np.testing.assert_array_equal(from_file.labels, from_array.labels)
    assert [r.structure.value for r in from_array.results] == [1, 2, 3, 4]
    assert all(r.mesh is not None and r.mesh.is_watertight for r in from_array.results)
    # a partition: no voxel in two structures, the input's values on the input's grid
    assert from_array.labels.shape == labels.shape
    assert set(np.unique(from_array.labels)) == {0, 1, 2, 3, 4}
    with pytest.raises(LabelError, match="integer"):
        LabelMap.from_array(labels + 0.5, np.eye(4))


def test_load_input_never_merges_structures_silently(tmp_path: Path) -> None:
    path = _write(_labels(4), tmp_path / "four.nii.gz")
    with pytest.raises(LabelError, match="4 structures"):
        load_input(path)
    assert load_input(path, union=True).mask.sum() == np.count_nonzero(_labels(4))
    assert load_input(path, label=3).mask.sum() == np.count_nonzero(_labels(4) == 3)


def test_every_option_reaches_every_structure_or_is_refused(tmp_path: Path) -> None:
    path = _write(_labels(4), tmp_path / "four.nii.gz")
    smooth = reconstruct_structures(path, slices=8, smooth=True)
    plain = reconstruct_structures(path, slices=8)
    for a, b in zip(smooth.results, plain.results, strict=True):
        assert a.mesh.is_watertight  # each smoothed, still closed
        assert not np.allclose(a.mesh.vertices, b.mesh.vertices)
    with pytest.raises(OptionError, match="--method sdf"):
        reconstruct_structures(path, slices=8, method="loft")
    silhouette = tmp_path / "s.nii.gz"
    silhouette.write_bytes(b"")
    with pytest.raises(OptionError, match="one structure"):
        reconstruct_structures(path, slices=8, projections=str(silhouette))


def test_an_unwritable_output_is_refused_before_any_work(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _write(_labels(1), tmp_path / "one.nii.gz")
    target = tmp_path / "a_file"
    target.write_text("x")
    assert main(["run", str(path), "-o", str(target)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error:") and "is a file" in err[0]
    assert main(["run", str(path), "-o", str(target / "below")]) == 2
    assert "is a file" in capsys.readouterr().err


def test_a_malformed_source_is_one_input_error() -> None:
    from slicerecon.errors import InputError

    labels = np.zeros((8, 8, 8), np.uint8)
    for source in (labels, (labels, np.eye(4), 1)):
        with pytest.raises(
            InputError, match=r"several paths, a LabelMap, a Volume, a nibabel image, or \(array"
        ):
            reconstruct_structures(source)  # type: ignore[arg-type]


@pytest.mark.parametrize("option", [{"slices": 6}, {"every": 2}])
def test_prepare_inputs_refuses_plane_options_for_an_annotation(option: dict) -> None:
    """Asked for 6 planes of a mask annotated on every 4th slice, it says so, not ignores it."""
    from slicerecon.inputs import prepare_inputs
    from slicerecon.sections import Volume

    x, y, z = np.meshgrid(*[np.arange(40)] * 3, indexing="ij")
    sparse = ((x - 20) ** 2 + (y - 20) ** 2 + (z - 20) ** 2 < 144) & (z % 4 == 0)
    with pytest.raises(OptionError, match="apply to dense masks"):
        prepare_inputs(Volume(sparse, np.eye(4)), **option)


def _ball(radius: float, shape: tuple[int, int, int] = (32, 32, 32)) -> np.ndarray:
    ijk = np.indices(shape) - (np.asarray(shape)[:, None, None, None] - 1) / 2
    return ((ijk**2).sum(axis=0) < radius**2).astype(np.uint8)


def test_a_label_map_of_an_array_keeps_its_values_when_the_array_changes() -> None:
    """``LabelMap.from_array`` kept the caller's array: one buffer reused for three cases
    made three label maps of the last one (balls of radius 6, 9 and 12 all came out
    7,066 mm³), and zeroing it emptied them."""
    buffer = _ball(6)
    small = LabelMap.from_array(buffer, np.eye(4))
    buffer[...] = _ball(12)
    assert np.count_nonzero(small.labels) == np.count_nonzero(_ball(6))
    assert not small.labels.flags.writeable
    volume = reconstruct_structures(small, slices=8).reconstructed[0].volume_mm3
    assert volume == pytest.approx(4 / 3 * np.pi * 6**3, rel=0.15)


def test_a_label_map_object_is_checked_as_an_array_is() -> None:
    """An array of CT-like values was refused, but the same values as a ``LabelMap``
    reconstructed the air (-1000) as a structure."""
    ct = np.where(_ball(8) > 0, 40, -1000).astype(np.int16)
    with pytest.raises(LabelError, match="negative"):
        reconstruct_structures((ct, np.eye(4)))
    with pytest.raises(LabelError, match="negative"):
        reconstruct_structures(LabelMap.from_array(ct, np.eye(4)))


def test_several_inputs_of_one_study_reconstruct_from_python_as_run(tmp_path: Path) -> None:
    """``reconstruct_structures([axial, sagittal])`` was refused as "a label map must
    hold numbers"; ``slicerecon run axial sagittal`` combines them."""
    ball = _ball(10)
    axial, sagittal = np.zeros_like(ball), np.zeros_like(ball)
    axial[:, :, 8:25:4] = ball[:, :, 8:25:4]
    sagittal[[11, 20]] = ball[[11, 20]]
    paths = []
    for name, data in (("axial", axial), ("sagittal", sagittal)):
        nib.save(nib.Nifti1Image(data, np.eye(4)), tmp_path / f"{name}.nii.gz")
        paths.append(tmp_path / f"{name}.nii.gz")
    result = reconstruct_structures(paths)
    assert main(["run", *map(str, paths), "-o", str(tmp_path / "out"), "-q"]) == 0
    written = np.asanyarray(nib.load(tmp_path / "out" / "labels.nii.gz").dataobj)
    np.testing.assert_array_equal(result.labels, written)


def test_warnings_reach_a_library_user_on_the_result(tmp_path: Path) -> None:
    """Warnings went to the ``slicerecon`` logger only: in a notebook without logging
    set up, "drawn on one plane only" and the like never appeared. The result now
    carries them, one line each, as ``run`` prints them."""
    thin = _ball(10)
    thin[2:5, 2:5, 14:16] = 2  # two slices between the kept planes
    nib.save(nib.Nifti1Image(thin, np.eye(4)), tmp_path / "thin.nii.gz")
    result = reconstruct_structures(tmp_path / "thin.nii.gz", slices=4)
    assert any("structure 2" in line and "between" in line for line in result.warnings)
    assert reconstruct_structures((_ball(10), np.eye(4)), slices=8).warnings == []


def test_a_structure_named_with_a_comma_is_chosen_by_a_list() -> None:
    """``label=["Kidney, right"]`` was joined with commas and split again: "label
    'Kidney' is not in ..."."""
    labels = _ball(12)
    labels[:, :, :16] *= 2
    kidneys = LabelMap.from_array(labels, np.eye(4), names={1: "Kidney, right", 2: "Kidney, left"})
    result = reconstruct_structures(kidneys, slices=6, label=["Kidney, right"])
    assert [r.structure.name for r in result.results] == ["Kidney, right"]
    assert ReconstructConfig(label="1,2").selectors == [1, 2]  # text is still split


@pytest.mark.parametrize(
    ("changes", "words"),
    [
        ({"slice": 12}, "not an option: slice"),
        ({"carve": "no"}, "carve must be True or False"),
        ({"seed": "a"}, "seed must be a whole number"),
        ({"config": {"slices": 4}}, "config must be a ReconstructConfig"),
        ({"pixel_spacing": 0.5}, "a label map keeps its voxels"),
    ],
)
def test_bad_options_from_python_are_one_option_error_before_any_work(
    changes: dict, words: str
) -> None:
    """A misspelt keyword was a TypeError, ``carve="no"`` meant carve, a bad seed failed
    after the reconstruction when scoring, a dict config an AttributeError, and a pixel
    spacing was ignored for an array but refused for the same data as a file."""
    with pytest.raises(OptionError, match=words):
        reconstruct_structures((_ball(10), np.eye(4)), **changes)


def test_the_options_bundle_and_a_4d_nibabel_image_are_taken_as_a_file_is() -> None:
    from slicerecon.options import ReconstructOptions

    image = nib.Nifti1Image(_ball(10)[..., None], np.eye(4))  # (X, Y, Z, 1)
    result = reconstruct_structures(image, ReconstructOptions(interpolation="linear"), slices=8)
    assert result.reconstructed[0].mesh.is_watertight


def test_a_label_map_made_directly_refuses_what_from_array_refuses() -> None:
    """``LabelMap(...)`` took labels of 0.5 (reconstructed as label 1) and any
    ``coordinates`` text."""
    with pytest.raises(LabelError, match="integer"):
        LabelMap(_ball(6) * 0.5, np.eye(4), ())
    with pytest.raises(LabelError, match="RAS"):
        LabelMap(_ball(6), np.eye(4), (), "XYZ")
