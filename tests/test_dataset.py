"""Tests of slicerecon.dataset and `slicerecon dataset make|list`."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from slicerecon.cli import main
from slicerecon.dataset import (
    MANIFEST,
    case_seed,
    load_manifest,
    make_dataset,
    resolve_shapes,
)
from slicerecon.errors import FormatError, InputError, OptionError
from slicerecon.io.nifti import read_nifti
from slicerecon.shapes import FAMILIES, SHAPES, make_shape


def test_make_via_cli_writes_masks_and_manifest(tmp_path: Path) -> None:
    out = tmp_path / "ds"
    code = main(
        [
            "dataset",
            "make",
            str(out),
            "--shapes",
            "holes,chair",
            "--per-shape",
            "2",
            "--size",
            "24",
            "--seed",
            "7",
            "--margin",
            "2",
        ]
    )
    assert code == 0
    manifest = load_manifest(out)
    assert manifest["options"]["shapes"] == ["torus", "genus2", "plate_with_holes", "chair"]
    cases = manifest["cases"]
    assert [c["case"] for c in cases][:2] == ["torus_000", "torus_001"]
    assert len(cases) == 8 and len({c["seed"] for c in cases}) == 8
    assert sorted(p.name for p in out.iterdir()) == sorted([MANIFEST] + [c["file"] for c in cases])
    for case in cases:
        volume = read_nifti(out / case["file"])
        assert int(volume.mask.sum()) == case["voxels"]
        assert volume.volume_mm3 == pytest.approx(case["volume_mm3"], rel=1e-5)
        assert case["family"] == ("furniture" if case["shape"] == "chair" else "holes")
        assert case["seed"] == case_seed(7, case["shape"], int(case["case"][-3:]))
        # the manifest rebuilds the case exactly
        again = make_shape(case["shape"], seed=case["seed"], resolution=24, margin=2)
        np.testing.assert_array_equal(again.mask, volume.mask)
        np.testing.assert_allclose(again.affine, volume.affine, atol=1e-4)
        if case["shape"] == "torus":
            assert case["analytic_volume_mm3"] == pytest.approx(case["volume_mm3"], rel=0.1)
        else:
            assert case["analytic_volume_mm3"] is None


def test_seeds_are_reproducible_and_distinct(tmp_path: Path) -> None:
    a = make_dataset(tmp_path / "a", shapes=["kidney"], per_shape=3, seed=1, size=16)
    b = make_dataset(tmp_path / "b", shapes="kidney", per_shape=3, seed=1, size=16)
    c = make_dataset(tmp_path / "c", shapes="kidney", per_shape=3, seed=2, size=16)
    assert json.loads(a.read_text()) == json.loads(b.read_text())
    seeds_a = {case["seed"] for case in load_manifest(a.parent)["cases"]}
    seeds_c = {case["seed"] for case in load_manifest(c.parent)["cases"]}
    assert not seeds_a & seeds_c


def test_remaking_a_dataset_replaces_its_cases(tmp_path: Path) -> None:
    out = tmp_path / "ds"
    make_dataset(out, shapes="sphere,box", size=16)
    make_dataset(out, shapes="box", per_shape=2, size=16)
    names = sorted(p.name for p in out.iterdir())
    assert names == ["box_000.nii.gz", "box_001.nii.gz", MANIFEST]


def test_refuses_a_foreign_directory(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("keep me")
    assert main(["dataset", "make", str(out), "--shapes", "sphere", "--size", "16"]) == 2
    err = capsys.readouterr().err
    assert "not a slicerecon dataset" in err and "--overwrite" in err
    assert len(err.strip().splitlines()) == 1
    assert (
        main(["dataset", "make", str(out), "--shapes", "sphere", "--size", "16", "--overwrite"])
        == 0
    )
    assert (out / "notes.txt").read_text() == "keep me"
    assert (out / "sphere_000.nii.gz").is_file()
    assert main(["dataset", "make", str(tmp_path / "x"), "--shapes", "teapot"]) == 2
    assert "unknown shape or family 'teapot'" in capsys.readouterr().err


def test_anisotropic_spacing_and_real_shapes(tmp_path: Path) -> None:
    out = tmp_path / "ds"
    assert (
        main(
            [
                "dataset",
                "make",
                str(out),
                "--shapes",
                "car,pymeshlab_cow",
                "--size",
                "24",
                "--spacing",
                "0.8,0.8,2",
            ]
        )
        == 0
    )
    cases = {c["shape"]: c for c in load_manifest(out)["cases"]}
    car = cases["car"]["spacing_mm"]
    assert car[2] / car[0] == pytest.approx(2.5)
    cow = cases["pymeshlab_cow"]
    assert cow["case"] == "pymeshlab_cow" and cow["family"] == "real" and cow["seed"] is None
    assert max(cow["grid"]) <= 24 + 2 * 3


def test_list_command(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["dataset", "list"]) == 0
    text = capsys.readouterr().out
    for family, names in FAMILIES.items():
        assert f"{family}: {', '.join(names)}" in text
    assert main(["dataset", "list", "--json"]) == 0
    listing = json.loads(capsys.readouterr().out)
    assert sorted(n for names in listing["families"].values() for n in names) == sorted(SHAPES)
    assert listing["real"]["pymeshlab_cow"] is True


def test_resolve_and_manifest_errors(tmp_path: Path) -> None:
    assert resolve_shapes(None) == sorted(SHAPES)
    assert resolve_shapes("holes, torus ,sphere") == [
        "torus",
        "genus2",
        "plate_with_holes",
        "sphere",
    ]
    with pytest.raises(OptionError, match="no shape selected"):
        resolve_shapes(" , ")
    with pytest.raises(OptionError, match="per_shape"):
        make_dataset(tmp_path / "z", shapes="sphere", per_shape=0)
    with pytest.raises(OptionError, match="spacing"):
        make_dataset(tmp_path / "z", shapes="sphere", spacing=(1.0, 0.0, 1.0))
    with pytest.raises(InputError, match="no manifest.json"):
        load_manifest(tmp_path)
    with pytest.raises(InputError, match="not found"):
        load_manifest(tmp_path / "nowhere")
    (tmp_path / MANIFEST).write_text("{not json")
    with pytest.raises(FormatError, match="not valid JSON"):
        load_manifest(tmp_path)
    (tmp_path / MANIFEST).write_text('{"format": "other"}')
    with pytest.raises(FormatError, match="not a slicerecon dataset"):
        load_manifest(tmp_path)
