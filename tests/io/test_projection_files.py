"""Silhouettes from NIfTI files, placed on the sections' grid through their affines."""

from __future__ import annotations

from pathlib import Path

import nibabel as nib
import numpy as np
import pytest

from slicerecon.errors import GeometryError, InputError
from slicerecon.reconstruct import prepare_inputs, reconstruct
from slicerecon.sampling import projections_from_volume
from slicerecon.shapes import make_shape


def _save_view(volume, axis: int, path: Path, *, zoom: int = 1) -> Path:  # type: ignore[no-untyped-def]
    """Write the exact projection of ``volume`` along ``axis`` as a NIfTI silhouette.

    The file keeps the volume's geometry with the projected axis collapsed to
    one voxel; ``zoom`` > 1 writes it on a grid ``zoom`` times finer.
    """
    image = volume.mask.any(axis=axis)
    image = np.repeat(np.repeat(image, zoom, axis=0), zoom, axis=1)
    data = np.expand_dims(image, axis).astype(np.uint8)
    affine = volume.affine.copy()
    for a in range(3):
        if a != axis:
            affine[:3, a] /= zoom
            affine[:3, 3] -= affine[:3, a] * (zoom - 1) / 2
    nib.save(nib.Nifti1Image(data, affine), str(path))
    return path


@pytest.mark.parametrize("zoom", [1, 2])
def test_files_reproduce_the_volume_projections(tmp_path: Path, zoom: int) -> None:
    chair = make_shape("chair", spacing=(0.8, 1.0, 1.5))
    sections, expected, _ = prepare_inputs(chair, slices=8, projections="gt")
    grid_volume = chair.crop(pad=3)
    files = [_save_view(grid_volume, a, tmp_path / f"view{a}.nii.gz", zoom=zoom) for a in range(3)]
    _, read, _ = prepare_inputs(chair, slices=8, projections=",".join(map(str, files)))
    assert read.source == "file"
    for a in range(3):
        np.testing.assert_array_equal(read[a].image, expected[a].image)


def test_one_file_and_the_rest_from_the_sections(tmp_path: Path) -> None:
    chair = make_shape("chair")
    grid_volume = chair.crop(pad=3)
    top = _save_view(grid_volume, 2, tmp_path / "top.nii.gz")
    sections, read, _ = prepare_inputs(chair, slices=8, projections=[top])
    np.testing.assert_array_equal(read[2].image, projections_from_volume(grid_volume)[2].image)
    result = reconstruct(sections, read)
    assert result.mesh.is_watertight


def test_bad_projection_files(tmp_path: Path) -> None:
    chair = make_shape("chair")
    grid_volume = chair.crop(pad=3)
    with pytest.raises(InputError, match="not found"):
        prepare_inputs(chair, slices=8, projections=str(tmp_path / "missing.nii.gz"))
    a = _save_view(grid_volume, 0, tmp_path / "a.nii.gz")
    b = _save_view(grid_volume, 0, tmp_path / "b.nii.gz")
    with pytest.raises(GeometryError, match="both look along x"):
        prepare_inputs(chair, slices=8, projections=[a, b])
    tilted = grid_volume.mask.any(axis=2)[:, :, None].astype(np.uint8)
    angle = np.deg2rad(10.0)
    rotation = np.eye(4)
    c, s = np.cos(angle), np.sin(angle)
    rotation[:3, :3] = [[1, 0, 0], [0, c, -s], [0, s, c]]
    nib.save(nib.Nifti1Image(tilted, rotation @ grid_volume.affine), str(tmp_path / "t.nii.gz"))
    with pytest.raises(GeometryError, match="off the nearest grid axis"):
        prepare_inputs(chair, slices=8, projections=[tmp_path / "t.nii.gz"])


def test_cli_takes_projection_files(tmp_path: Path) -> None:
    from slicerecon.cli import main
    from slicerecon.io.nifti import write_nifti

    chair = make_shape("chair")
    write_nifti(chair, tmp_path / "chair.nii.gz")
    top = _save_view(chair.crop(pad=3), 2, tmp_path / "top.nii.gz")
    out = tmp_path / "out"
    run = ["run", str(tmp_path / "chair.nii.gz"), "-o", str(out), "--projections"]
    assert main([*run, str(top)]) == 0
    assert (out / "mesh.stl").stat().st_size > 0
    assert main([*run, "nope.nii"]) == 2
