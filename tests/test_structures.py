"""Every structure at once: a label map in, one mesh per structure and a label map out."""

from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path

import nibabel as nib
import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

from slicerecon.case import NO_PLANE, reconstruct_structures
from slicerecon.cli import main
from slicerecon.io.labelmap import read_label_map
from slicerecon.metrics.inputs import place
from slicerecon.rasterize import mesh_to_mask
from slicerecon.reconstruct import reconstruct
from slicerecon.sampling import projections_from_volume
from slicerecon.sections import CrossSections

SPACING = (0.8, 0.8, 2.0)


def _four_labels() -> np.ndarray:
    """Two half-balls touching along x = 32 mm, a small ball and a bar (anisotropic voxels)."""
    shape = (80, 70, 40)
    x, y, z = (
        a * s
        for a, s in zip(
            np.meshgrid(*[np.arange(n) for n in shape], indexing="ij"), SPACING, strict=True
        )
    )
    labels = np.zeros(shape, np.uint8)
    ball = (x - 32) ** 2 + (y - 28) ** 2 + (z - 40) ** 2 < 22**2
    labels[ball & (x < 32)] = 1
    labels[ball & (x >= 32)] = 2
    labels[(x - 52) ** 2 + (y - 48) ** 2 + (z - 20) ** 2 < 4**2] = 5
    labels[(np.abs(x - 12) < 6) & (np.abs(y - 50) < 5) & (z > 10) & (z < 70)] = 7
    return labels


@pytest.fixture(scope="module")
def four(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("labels") / "four.nii.gz"
    nib.save(nib.Nifti1Image(_four_labels(), np.diag([*SPACING, 1.0])), path)
    return path


@pytest.fixture(scope="module")
def joint(four: Path):  # noqa: ANN201
    return reconstruct_structures(read_label_map(four), slices=12)


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / (a | b).sum())


def _on_grid(volume, affine: np.ndarray, shape: tuple[int, int, int]) -> np.ndarray:  # noqa: ANN001
    """A structure's voxels (its own crop) on the lattice of ``affine``."""
    lo = np.rint(np.linalg.solve(affine[:3, :3], volume.affine[:3, 3] - affine[:3, 3]))
    return place(volume.mask, -lo.astype(np.int64), shape)


def test_every_structure_gets_a_watertight_mesh_and_no_voxel_two(joint) -> None:  # noqa: ANN001
    assert [r.structure.value for r in joint.results] == [1, 2, 5, 7]
    assert all(r.mesh is not None and r.mesh.is_watertight for r in joint.results)
    # one label per voxel by construction: the label map holds the input's values only
    assert set(np.unique(joint.labels)) == {0, 1, 2, 5, 7}
    grid = joint.sections.affine, joint.sections.grid_shape
    owners = sum(_on_grid(r.occupancy, *grid).astype(int) for r in joint.results)
    assert owners.max() == 1
    # each share is held on its own box, not on the whole grid (80 structures of a
    # 512 x 512 x 200 map held 2 GiB of masks)
    for r in joint.results:
        lo, hi = r.occupancy.bounding_box_vox()
        assert r.occupancy.shape == tuple(int(v) for v in hi - lo)


def test_touching_structures_share_their_interface(joint) -> None:  # noqa: ANN001
    first, second = joint.results[0].mesh, joint.results[1].mesh
    distance, _ = cKDTree(second.vertices).query(first.vertices)
    shared = first.vertices[distance < 1e-9]
    assert len(shared) > 200  # the x = 32 mm face is one surface in both meshes
    assert np.ptp(shared[:, 0]) < 0.5
    # no gap: well inside the ball, the voxels either side of the interface (x = 32 mm
    # is between x indices 39 and 40) all belong to one of the two
    x, y, z = (
        a * s
        for a, s in zip(
            np.meshgrid(*[np.arange(n) for n in (80, 70, 40)], indexing="ij"), SPACING, strict=True
        )
    )
    deep = (x - 32) ** 2 + (y - 28) ** 2 + (z - 40) ** 2 < 16**2
    assert np.all(np.isin(joint.labels[38:42][deep[38:42]], (1, 2)))


def test_each_label_at_least_as_good_as_plain_sdf_on_the_same_planes(joint) -> None:  # noqa: ANN001
    sections = joint.sections
    planes = np.rint(sections.indices).astype(int)
    for item in joint.results:
        truth = joint.truth_mask(item.structure.value)
        own = CrossSections(
            np.moveaxis(truth.mask, 2, 0)[planes],
            sections.indices,
            2,
            sections.affine,
            sections.grid_shape,
        )
        plain = reconstruct(
            own,
            projections_from_volume(truth),
            method="sdf",
            planner="none",
            carve=False,
            interpolation="linear",
        ).mesh
        plain_iou = _iou(mesh_to_mask(plain, sections.affine, sections.grid_shape), truth.mask)
        mine = _on_grid(item.occupancy, sections.affine, sections.grid_shape)
        assert _iou(mine, truth.mask) >= plain_iou - 1e-9, item.structure


def test_run_writes_meshes_labels_and_records(four: Path, tmp_path: Path) -> None:
    out = tmp_path / "all"
    assert main(["run", str(four), "--slices", "12", "-o", str(out)]) == 0
    meshes = sorted(p.name for p in (out / "meshes").iterdir())
    assert meshes == ["1.stl", "2.stl", "5.stl", "7.stl"]
    assert all(trimesh.load(out / "meshes" / m).is_watertight for m in meshes)
    written = nib.load(out / "labels.nii.gz")
    source = nib.load(four)
    assert written.shape == source.shape and np.allclose(written.affine, source.affine)
    assert set(np.unique(np.asanyarray(written.dataobj))) == {0, 1, 2, 5, 7}
    records = json.loads((out / "structures.json").read_text())["structures"]
    assert [r["value"] for r in records] == [1, 2, 5, 7]
    metrics = json.loads((out / "metrics.json").read_text())
    assert set(metrics["structures"]) == {"1", "2", "5", "7"} and "volume_iou" in metrics["mean"]


def test_one_label_writes_mesh_and_union_is_one_structure(four: Path, tmp_path: Path) -> None:
    assert main(["run", str(four), "--label", "2", "-o", str(tmp_path / "two")]) == 0
    assert (tmp_path / "two" / "mesh.stl").is_file()
    values = np.unique(np.asanyarray(nib.load(tmp_path / "two" / "labels.nii.gz").dataobj))
    assert set(values) == {0, 2}
    assert main(["run", str(four), "--union", "-o", str(tmp_path / "union")]) == 0
    union = trimesh.load(tmp_path / "union" / "mesh.stl")
    assert union.is_watertight
    assert main(["run", str(four), "--label", "1,7", "-o", str(tmp_path / "some")]) == 0
    assert sorted(p.name for p in (tmp_path / "some" / "meshes").iterdir()) == ["1.stl", "7.stl"]


def test_a_structure_between_the_planes_is_reported(tmp_path: Path) -> None:
    labels = np.zeros((30, 30, 40), np.uint8)
    labels[5:25, 5:25, 2:38] = 1
    labels[12:18, 12:18, 20:22] = 3  # two slices thick, missed by 4 planes
    path = tmp_path / "thin.nii.gz"
    nib.save(nib.Nifti1Image(labels, np.eye(4)), path)
    result = reconstruct_structures(read_label_map(path), slices=4)
    status = {r.structure.value: r.status for r in result.results}
    assert status[3] == NO_PLANE and status[1] == "reconstructed"
    out = tmp_path / "out"
    assert main(["run", str(path), "--slices", "4", "-o", str(out)]) == 0
    records = json.loads((out / "structures.json").read_text())["structures"]
    assert {r["value"]: r["status"] for r in records}[3] == NO_PLANE


def test_every_roi_of_an_rtstruct_with_its_name_and_colour(tmp_path: Path) -> None:
    import dicom_factory as factory  # tests/io, on pytest's pythonpath

    affine = factory.affine_from_geometry(
        [1, 0, 0], [0, 1, 0], [1.0, 1.0], [0, 0, 3.0], [-31.5, -31.5, 0.0]
    )
    factory.write_series(tmp_path / "ct", np.zeros((64, 64, 21), np.uint16), affine, modality="CT")

    def rings(centre: tuple[float, float]) -> list:
        return [
            factory.contour_item(factory.circle(np.sqrt(144 - (z - 30) ** 2), centre, z))
            for z in np.arange(21) * 3.0
            if abs(z - 30) < 12
        ]

    factory.write_rtstruct(
        tmp_path / "ct" / "rs.dcm",
        {(1, "Left"): rings((-10, 0)), (2, "Right"): rings((10, 0)), (3, "Ghost"): None},
    )
    out = tmp_path / "out"
    assert main(["run", str(tmp_path / "ct"), "-o", str(out)]) == 0
    assert sorted(p.name for p in (out / "meshes").iterdir()) == ["1_Left.stl", "2_Right.stl"]
    records = {
        r["name"]: r for r in json.loads((out / "structures.json").read_text())["structures"]
    }
    assert records["Ghost"]["status"] == "no closed planar contours"
    assert records["Left"]["colour"] == [255, 0, 0]
    sphere = 4 / 3 * np.pi * 12**3
    for name in ("1_Left.stl", "2_Right.stl"):
        mesh = trimesh.load(out / "meshes" / name)
        assert mesh.is_watertight and mesh.volume == pytest.approx(sphere, rel=0.06)


def test_an_rtstruct_whose_sampled_grid_exceeds_the_budget_is_refused_before_work(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Contours 10 mm apart on 0.1 mm pixels are sampled 9 times along z: that grid is checked."""
    import dicom_factory as factory  # tests/io, on pytest's pythonpath

    def rings(centre: tuple[float, float]) -> list:
        return [
            factory.contour_item(factory.circle(np.sqrt(144 - (z - 30) ** 2), centre, z))
            for z in (20.0, 30.0, 40.0)
        ]

    path = factory.write_rtstruct(
        tmp_path / "rs.dcm", {(1, "Left"): rings((-10, 0)), (2, "Right"): rings((10, 0))}
    )
    out = tmp_path / "out"
    args = ["run", str(path), "-o", str(out), "--pixel-spacing", "0.1", "--max-memory", "0.03"]
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "rs.dcm: the reconstruction grid" in err[0]
    assert "x 27 voxels" in err[0] and "over the memory budget of 0.03 GiB" in err[0]
    assert not out.exists()


def test_contours_oblique_to_their_series_give_a_preview_of_the_3d_view(tmp_path: Path) -> None:
    """Radial contours through a ball beside its series: no plane is a slice of the grid."""
    import dicom_factory as factory  # tests/io, on pytest's pythonpath
    from PIL import Image

    affine = factory.affine_from_geometry(
        [1, 0, 0], [0, 1, 0], [1.0, 1.0], [0, 0, 2.0], [-31.5, -31.5, -20.0]
    )
    factory.write_series(tmp_path / "ct", np.zeros((64, 64, 21), np.uint16), affine, modality="CT")
    t = np.linspace(0.0, 2.0 * np.pi, 120, endpoint=False)
    items = []
    for angle in np.radians([10.0, 55.0, 100.0, 145.0]):  # planes through the z axis
        u = np.array([np.cos(angle), np.sin(angle), 0.0])
        points = 12.0 * (np.cos(t)[:, None] * u + np.sin(t)[:, None] * np.array([0, 0, 1.0]))
        items.append(factory.contour_item(points))
    factory.write_rtstruct(tmp_path / "ct" / "rs.dcm", {(1, "Ball"): items})
    out = tmp_path / "out"
    assert main(["run", str(tmp_path / "ct"), "-o", str(out), "-q"]) == 0
    mesh = trimesh.load(out / "mesh.stl")
    assert mesh.is_watertight
    assert mesh.volume == pytest.approx(4 / 3 * np.pi * 12**3, rel=0.15)
    assert Image.open(out / "preview.png").size[0] > 300


def test_batch_and_report_give_one_row_per_structure(four: Path, tmp_path: Path) -> None:
    import csv
    import shutil

    indir = tmp_path / "in"
    indir.mkdir()
    shutil.copy(four, indir / "four.nii.gz")
    out = tmp_path / "batch"
    assert main(["batch", str(indir), "-o", str(out), "--workers", "0", "--slices", "12"]) == 0
    with (out / "metrics.csv").open(newline="") as handle:
        rows = list(csv.DictReader(handle))
    assert [(r["case"], r["structure"]) for r in rows] == [
        ("four", "1"),
        ("four", "2"),
        ("four", "5"),
        ("four", "7"),
        ("four", "mean"),
    ]
    assert all(float(r["volume_iou"]) > 0.9 for r in rows)


def test_evaluate_scores_each_label_of_a_label_map(four: Path, tmp_path: Path) -> None:
    out = tmp_path / "run"
    assert main(["run", str(four), "--slices", "8", "-o", str(out), "-q"]) == 0
    truth = nib.load(four)
    values = sorted(int(v) for v in np.unique(np.asarray(truth.dataobj)) if v)
    for prediction in (out / "labels.nii.gz", out, out / "meshes"):
        buffer = io.StringIO()
        with contextlib.redirect_stdout(buffer):
            assert main(["evaluate", str(prediction), str(four)]) == 0
        scores = json.loads(buffer.getvalue())
        assert sorted(int(k.split("_")[0]) for k in scores["structures"]) == values
        assert scores["missing"] == []
        # each structure against its own mask, not against the union of all labels
        assert min(s["volume_iou"] for s in scores["structures"].values()) > 0.5
        assert scores["mean"]["volume_iou"] == pytest.approx(
            np.mean([s["volume_iou"] for s in scores["structures"].values()])
        )
    # one mesh against a multi-label truth: one clear line, exit 2
    one = next((out / "meshes").glob("*.stl"))
    assert main(["evaluate", str(one), str(four)]) == 2


def test_the_python_entry_point_takes_what_a_library_user_holds(tmp_path) -> None:
    """``slicerecon.reconstruct_structures`` at the top level takes a nibabel image and a
    Volume as it takes (array, affine); they were refused."""
    import slicerecon

    x, y, z = np.mgrid[:40, :40, :40]
    ball = (x - 20) ** 2 + (y - 20) ** 2 + (z - 20) ** 2 < 100
    sparse = (ball & (z % 4 == 0)).astype(np.uint8)
    affine = np.diag([0.8, 0.8, 2.0, 1.0])
    want = slicerecon.reconstruct_structures((sparse, affine)).labels
    for given in (nib.Nifti1Image(sparse, affine), slicerecon.Volume(sparse > 0, affine)):
        got = slicerecon.reconstruct_structures(given)
        assert np.array_equal(got.labels, want) and np.allclose(got.affine, affine)
    with pytest.raises(slicerecon.InputError, match="a Volume, a nibabel image"):
        slicerecon.reconstruct_structures(sparse)


def test_the_python_entry_point_scores_a_dense_input_when_asked() -> None:
    """StructureResult.metrics was always None from reconstruct_structures; scoring
    needed the CaseInput it never returns."""
    import slicerecon

    x, y, z = np.mgrid[:40, :40, :40]
    ball = ((x - 20) ** 2 + (y - 20) ** 2 + (z - 20) ** 2 < 196).astype(np.uint8)
    scored = slicerecon.reconstruct_structures((ball, np.eye(4)), slices=8, score=True)
    assert 0.9 < scored.results[0].metrics["volume_iou"] < 1.0
    assert slicerecon.reconstruct_structures((ball, np.eye(4)), slices=8).results[0].metrics is None
    sparse = ball * (z % 4 == 0)
    assert (
        slicerecon.reconstruct_structures((sparse, np.eye(4)), score=True).results[0].metrics
        is None
    )
