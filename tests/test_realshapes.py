"""Tests of the real shapes read from installed packages (nilearn, pyvista, pymeshlab)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest
import trimesh
from scipy import ndimage

from slicerecon import realshapes
from slicerecon.errors import (
    DependencyError,
    EmptyMaskError,
    GeometryError,
    InputError,
    OptionError,
)
from slicerecon.realshapes import (
    FROG_TISSUES,
    REAL_SHAPES,
    available_real_shapes,
    downsample,
    frog_tissue,
    frog_tissues_path,
    mni152,
    pymeshlab_mesh,
    pymeshlab_sample_dir,
    real_shape,
    real_shape_names,
)
from slicerecon.sections import Volume

FULL = np.ones((3, 3, 3), dtype=bool)


def _have_frog() -> bool:
    try:
        frog_tissues_path()
    except DependencyError:
        return False
    return True


needs_frog = pytest.mark.skipif(not _have_frog(), reason="pyvista >= 0.44 not installed")


def _write_label_vti(path: Path, labels: np.ndarray, spacing: tuple[float, float, float]) -> Path:
    """A minimal ASCII .vti label map (point data, x fastest)."""
    nx, ny, nz = labels.shape
    values = " ".join(str(int(v)) for v in labels.ravel(order="F"))
    path.write_text(
        '<?xml version="1.0"?>\n<VTKFile type="ImageData" version="0.1">\n'
        f'<ImageData WholeExtent="0 {nx - 1} 0 {ny - 1} 0 {nz - 1}" Origin="5 6 7" '
        f'Spacing="{spacing[0]} {spacing[1]} {spacing[2]}">\n'
        f'<Piece Extent="0 {nx - 1} 0 {ny - 1} 0 {nz - 1}"><PointData Scalars="MetaImage">\n'
        f'<DataArray type="UInt8" Name="MetaImage" format="ascii">{values}</DataArray>\n'
        "</PointData></Piece></ImageData></VTKFile>\n"
    )
    return path


def test_downsample_majority_and_geometry() -> None:
    mask = np.zeros((8, 8, 8), dtype=bool)
    mask[2:6, 2:6, 2:6] = True  # a 4-cube: exactly the block (1, 1, 1) at factor 4
    affine = np.diag([0.5, 0.5, 2.0, 1.0])
    affine[:3, 3] = (10.0, 20.0, 30.0)
    vol = Volume(mask, affine)
    half = downsample(vol, 2)
    assert half.shape == (4, 4, 4)
    assert int(half.mask.sum()) == 8 and half.volume_mm3 == pytest.approx(vol.volume_mm3)
    centroid = lambda v: v.index_to_world(np.argwhere(v.mask)).mean(axis=0)  # noqa: E731
    np.testing.assert_allclose(centroid(half), centroid(vol))
    np.testing.assert_allclose(half.spacing, [1.0, 1.0, 4.0])
    quarter = downsample(vol, 4)  # no block is more than half full: 8 of 64 voxels at most
    assert not quarter.mask.any()
    assert downsample(vol, 1) is vol
    with pytest.raises(OptionError):
        downsample(vol, 0)


def test_registry_and_errors() -> None:
    assert real_shape_names() == sorted(REAL_SHAPES)
    assert set(available_real_shapes()) <= set(REAL_SHAPES)
    assert {f"frog_{t}" for t in FROG_TISSUES} <= set(REAL_SHAPES)
    assert {"mni152_brain", "mni152_gm", "mni152_wm", "pymeshlab_bunny"} <= set(REAL_SHAPES)
    with pytest.raises(OptionError, match="choose one of .*mni152_brain"):
        real_shape("frog_tail")
    with pytest.raises(OptionError, match="tissue must be one of"):
        mni152("csf")
    with pytest.raises(OptionError, match="unknown frog tissue"):
        frog_tissue("tail")
    with pytest.raises(OptionError, match="resolution"):
        mni152("brain", resolution=3)


def test_missing_packages_raise_dependency_errors(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(realshapes, "_package_dir", lambda package: None)
    with pytest.raises(DependencyError, match="pip install .*pyvista"):
        real_shape("frog_heart")
    with pytest.raises(DependencyError, match="pip install pymeshlab"):
        real_shape("pymeshlab_cow")
    assert available_real_shapes() == []
    monkeypatch.setitem(sys.modules, "nilearn", None)  # makes `import nilearn` fail
    with pytest.raises(DependencyError, match="nilearn"):
        real_shape("mni152_brain")


def test_frog_reader_on_a_small_label_file(tmp_path: Path) -> None:
    labels = np.zeros((20, 16, 12), dtype=np.uint8)
    labels[4:12, 3:11, 2:8] = FROG_TISSUES["kidney"]  # 8 x 8 x 6 organ
    labels[15, 14, 10] = FROG_TISSUES["kidney"]  # a stray speck
    labels[16:18, 2:4, 2:4] = FROG_TISSUES["heart"]
    path = _write_label_vti(tmp_path / "frog.vti", labels, (1.0, 1.0, 1.5))
    kidney = frog_tissue("kidney", path=path, margin=2)
    assert int(kidney.mask.sum()) == 8 * 8 * 6  # the speck (1 voxel < 5 %) is dropped
    assert kidney.volume_mm3 == pytest.approx(8 * 8 * 6 * 1.5)
    lo, hi = kidney.bounding_box_vox()
    assert np.all(lo == 2) and np.all(np.asarray(kidney.shape) - hi == 2)
    np.testing.assert_allclose(kidney.index_to_world(lo.astype(float)), [5 + 4, 6 + 3, 7 + 3])
    with_speck = frog_tissue("kidney", path=path, min_fraction=0.0)
    assert int(with_speck.mask.sum()) == 8 * 8 * 6 + 1
    with pytest.raises(EmptyMaskError, match="absent"):
        frog_tissue("liver", path=path)
    with pytest.raises(OptionError, match="min_fraction"):
        frog_tissue("kidney", path=path, min_fraction=2.0)


@needs_frog
@pytest.mark.parametrize(("tissue", "pieces"), [("heart", 1), ("lung", 2)])
def test_frog_organs(tissue: str, pieces: int) -> None:
    organ = real_shape(f"frog_{tissue}")
    assert int(ndimage.label(organ.mask, structure=FULL)[1]) == pieces
    np.testing.assert_allclose(organ.spacing, [1.0, 1.0, 1.5])
    small = real_shape(f"frog_{tissue}", resolution=32)
    lo, hi = small.bounding_box_vox()
    assert int(np.max(hi - lo)) <= 32
    assert small.volume_mm3 == pytest.approx(organ.volume_mm3, rel=0.15)


@needs_frog
@pytest.mark.slow
def test_every_frog_tissue_loads() -> None:
    for tissue in FROG_TISSUES:
        organ = real_shape(f"frog_{tissue}", resolution=48)
        assert organ.mask.any()


def test_mni152_brain_mask() -> None:
    pytest.importorskip("nilearn")
    brain = mni152("brain")
    np.testing.assert_allclose(brain.spacing, 1.0)
    assert 1.2e6 < brain.volume_mm3 < 2.2e6  # an adult brain with its CSF: 1.2-2.2 litres
    assert int(ndimage.label(brain.mask, structure=FULL)[1]) == 1
    coarse = mni152("brain", resolution=48)
    lo, hi = coarse.bounding_box_vox()
    assert 40 <= int(np.max(hi - lo)) <= 48
    assert coarse.volume_mm3 == pytest.approx(brain.volume_mm3, rel=0.05)


@pytest.mark.slow
def test_mni152_tissue_masks_nest() -> None:
    pytest.importorskip("nilearn")
    brain, gm, wm = (mni152(t) for t in ("brain", "gm", "wm"))
    assert wm.volume_mm3 < gm.volume_mm3 < brain.volume_mm3
    inside = np.round(brain.world_to_index(wm.index_to_world(np.argwhere(wm.mask)))).astype(int)
    assert brain.mask[tuple(inside.T)].mean() > 0.99


def test_pymeshlab_cow_volume_matches_the_mesh() -> None:
    folder = pymeshlab_sample_dir()
    cow = trimesh.load(folder / "cow.obj", force="mesh")
    scale = 100.0 / float(np.max(cow.extents))
    exact = abs(float(cow.volume)) * scale**3
    voxels = pymeshlab_mesh("cow", resolution=96)
    assert voxels.volume_mm3 == pytest.approx(exact, rel=0.03)
    lo, hi = voxels.bounding_box_vox()
    assert 94 <= int(np.max(hi - lo)) <= 96
    assert int(ndimage.label(voxels.mask, structure=FULL)[1]) == 1


def test_pymeshlab_open_and_missing_meshes() -> None:
    with pytest.raises(GeometryError, match="not closed"):
        pymeshlab_mesh("bunny10k_textured.obj", resolution=32)
    with pytest.raises(InputError, match="no sample mesh"):
        pymeshlab_mesh("teapot.obj")
    with pytest.raises(OptionError, match="extent_mm"):
        pymeshlab_mesh("cow", extent_mm=-1.0)


@pytest.mark.slow
def test_every_pymeshlab_mesh_voxelizes() -> None:
    for name in ("pymeshlab_bunny", "pymeshlab_airplane", "pymeshlab_bone"):
        volume = real_shape(name, resolution=64)
        assert int(ndimage.label(volume.mask, structure=FULL)[1]) >= 1
        assert volume.volume_mm3 > 0
