"""Bad input gets one clear line; real files are read; contours keep their planes.

One test (or parametrised family) per kind of fault of ``../shared/robustness``:
usage errors of every command, structures chosen by number or name, parser
failures as FormatError, geometry and memory checked before allocation, contour
planes between the image's slices, options reaching every reader, ``info``
describing every structure, files without a DICOM preamble, single-plane
structures. The inputs are built here, small and synthetic.
"""

from __future__ import annotations

import gzip
import json
import math
from pathlib import Path
from typing import Any

import dicom_factory as factory  # tests/io, on pytest's pythonpath
import nibabel as nib
import numpy as np
import pytest
import trimesh
import typer

from slicerecon.cli import DEFAULT_MAX_MEMORY_GB, app, main
from slicerecon.errors import FormatError, GeometryError, LabelError, MemoryBudgetError
from slicerecon.io import load_input
from slicerecon.io.limits import DEFAULT_MEMORY_BUDGET_GB
from slicerecon.io.nifti import write_nifti
from slicerecon.sections import Volume


def _one_error_line(capsys: pytest.CaptureFixture[str]) -> str:
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(err) == 1, err
    assert err[0].startswith("error: ") and "Traceback" not in err[0]
    return err[0]


def _ball(radius: float = 8.0, n: int = 24, spacing: tuple[float, ...] = (1, 1, 2)) -> Volume:
    x, y, z = np.meshgrid(*[np.arange(n)] * 3, indexing="ij")
    c = (n - 1) / 2
    mask = ((x - c) * spacing[0]) ** 2 + ((y - c) * spacing[1]) ** 2 + (
        (z - c) * spacing[2]
    ) ** 2 < radius**2
    return Volume(mask, np.diag([*spacing, 1.0]))


@pytest.fixture(scope="module")
def small_nii(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("usage") / "ball.nii.gz"
    write_nifti(_ball(), path)
    return path


# -- 1. the CLI contract: every usage error of every command is one line, exit 2 ---------
def _commands() -> list[tuple[list[str], Any]]:
    """Every leaf command of the CLI with its path, e.g. (["dataset", "make"], cmd).

    Typed ``Any``: typer may run on a click of its own, so its classes are not
    the installed ``click``'s and are matched by their attributes.
    """
    root = typer.main.get_command(app)
    out: list[tuple[list[str], Any]] = []

    def walk(prefix: list[str], command: Any) -> None:
        subcommands = getattr(command, "commands", None)
        if subcommands:
            for name, sub in subcommands.items():
                walk([*prefix, name], sub)
        else:
            out.append((prefix, command))

    walk([], root)
    return out


def _required_arguments(command: Any, value: str) -> list[str]:
    return [value for p in command.params if p.param_type_name == "argument" and p.required]


def _numeric(param: Any) -> bool:
    """Whether an option takes a number (typer's descriptor, or click's type name)."""
    descriptor = getattr(param, "type_descriptor", None)
    if descriptor is not None:
        return descriptor.annotation in (int, float)
    return getattr(getattr(param, "type", None), "name", "") in ("integer", "float")


def _usage_cases() -> list[tuple[str, list[str]]]:
    cases: list[tuple[str, list[str]]] = [
        ("unknown command", ["no-such-command"]),
        ("no command", []),
    ]
    for path, command in _commands():
        args = _required_arguments(command, "{input}")
        name = " ".join(path)
        cases.append((f"{name}: unknown option", [*path, *args, "--no-such-option"]))
        if args:
            cases.append((f"{name}: missing argument", path))
        for param in command.params:
            if param.param_type_name != "option" or param.is_flag or param.hidden:
                continue
            if _numeric(param):
                flag = max(param.opts, key=len)
                cases.append((f"{name} {flag}: not a number", [*path, *args, flag, "abc"]))
        valued = [p for p in command.params if p.param_type_name == "option" and not p.is_flag]
        if valued:
            cases.append(
                (f"{name}: option without its value", [*path, *args, max(valued[0].opts, key=len)])
            )
    return cases


USAGE_CASES = _usage_cases()


def test_every_command_has_usage_cases() -> None:
    commands = {" ".join(p) for p, _ in _commands()}
    assert {"run", "info", "batch", "evaluate", "report", "train", "dataset make"} <= commands
    covered = {label.split(":")[0].split(" --")[0] for label, _ in USAGE_CASES}
    assert commands <= covered
    labels = {label for label, _ in USAGE_CASES}
    assert {
        "run --slices: not a number",
        "run --max-memory: not a number",
        "train --steps: not a number",
        "run: missing argument",
    } <= labels


@pytest.mark.parametrize(("label", "argv"), USAGE_CASES, ids=[c[0] for c in USAGE_CASES])
def test_usage_errors_are_one_line_and_exit_2(
    label: str, argv: list[str], small_nii: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    argv = [a.replace("{input}", str(small_nii)) for a in argv]
    assert main(argv) == 2, label
    _one_error_line(capsys)


def test_max_memory_default_matches_the_library() -> None:
    assert DEFAULT_MAX_MEMORY_GB == DEFAULT_MEMORY_BUDGET_GB


@pytest.mark.parametrize("command", ["run", "batch"])
def test_every_shared_option_has_the_librarys_default(command: str) -> None:
    """run and batch spell their options out (typer); their defaults are the options bundle's."""
    import dataclasses
    import inspect

    from slicerecon.cli import cases
    from slicerecon.reconstruct import ReconstructConfig

    library = {f.name: f.default for f in dataclasses.fields(ReconstructConfig)}
    parameters = inspect.signature(getattr(cases, command)).parameters
    shared = {"max_memory_gb" if n == "max_memory" else n: p.default for n, p in parameters.items()}
    common = sorted(set(shared) & set(library))
    assert len(common) >= 15, common
    for name in common:
        assert shared[name] == library[name], name


# -- 2. structures by number or name ---------------------------------------------------
@pytest.fixture(scope="module")
def two_segments(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("seg")
    affine = factory.affine_from_geometry(
        [1, 0, 0], [0, 1, 0], [1.0, 1.0], [0, 0, 2.0], [-15.5, -15.5, 0.0]
    )
    x, y, z = np.meshgrid(np.arange(32), np.arange(32), np.arange(20), indexing="ij")
    big = (x - 15.5) ** 2 + (y - 15.5) ** 2 + ((z - 10) * 2) ** 2 < 12**2
    small = (x - 15.5) ** 2 + (y - 15.5) ** 2 + ((z - 10) * 2) ** 2 < 6**2
    return factory.write_seg(
        root / "seg.dcm", {1: big, 2: small}, affine, labels={1: "Liver", 2: "Lesion"}
    )


def test_seg_segment_by_label_or_number(two_segments: Path, tmp_path: Path) -> None:
    by_name = load_input(two_segments, label="lesion")
    by_number = load_input(two_segments, label="2")
    assert isinstance(by_name, Volume) and isinstance(by_number, Volume)
    np.testing.assert_array_equal(by_name.mask, by_number.mask)
    assert by_name.volume_mm3 < load_input(two_segments, label="Liver").volume_mm3  # type: ignore[union-attr]
    out = tmp_path / "out"
    assert main(["run", str(two_segments), "--label", "Lesion", "-o", str(out)]) == 0
    assert trimesh.load(out / "mesh.stl").is_watertight


def test_unknown_name_lists_what_there_is(
    two_segments: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(LabelError, match="1: Liver, 2: Lesion"):
        load_input(two_segments, label="Kidney")
    assert main(["run", str(two_segments), "--label", "Kidney"]) == 2
    assert "Liver" in _one_error_line(capsys)


def test_label_maps_are_chosen_by_value(small_nii: Path) -> None:
    assert isinstance(load_input(small_nii, label="1"), Volume)
    with pytest.raises(LabelError, match="by value, not by name; labels present: 1"):
        load_input(small_nii, label="tumour")


def test_rtstruct_roi_by_label_or_roi(tmp_path: Path) -> None:
    rings = [factory.contour_item(factory.circle(10, (0, 0), z)) for z in (0.0, 3.0, 6.0)]
    path = factory.write_rtstruct(tmp_path / "rs.dcm", {(1, "Body"): rings, (4, "GTV"): rings})
    by_label = load_input(path, label="gtv")
    by_roi = load_input(path, roi="4")
    assert by_label.n_planes == by_roi.n_planes == 3  # type: ignore[union-attr]
    with pytest.raises(Exception, match="disagree"):
        load_input(path, label="GTV", roi="Body")


# -- 3. third-party parser failures become FormatError naming the file ------------------
@pytest.mark.parametrize(
    "content",
    [
        "[" * 100_000 + "]" * 100_000,  # RecursionError
        '{"format": "slicerecon-contours", "version": 1, "planes": [{"polygons": '
        "[[[0, 0, 0], [1, 0, 0], [0, 1, " + "9" * 4400 + "]]]}]}",  # int too long
        '{"format": "slicerecon-contours", "version": 1, "planes": [{"polygons": '
        "[[[0, 0, 0], [1, 0, 0], [0, 1, 1" + "0" * 400 + "]]]}]}",  # int -> float overflow
    ],
    ids=["deep nesting", "4400-digit integer", "integer beyond float"],
)
def test_json_parser_failures(content: str, tmp_path: Path) -> None:
    path = tmp_path / "c.json"
    path.write_text(content)
    with pytest.raises(FormatError, match=str(path.name)):
        load_input(path)


def test_dicom_value_representation_flip_names_the_file(tmp_path: Path) -> None:
    files = factory.write_series(tmp_path / "ct", _ball().mask, np.diag([1.0, 1.0, 2.0, 1.0]))
    raw = bytearray(files[3].read_bytes())
    at = raw.find(b"\x08\x00\x60\x00CS")  # (0008,0060) Modality, explicit VR
    raw[at + 4 : at + 6] = b"C\xd3"
    files[3].write_bytes(bytes(raw))
    with pytest.raises(FormatError, match=files[3].name):
        load_input(tmp_path / "ct")


def test_vti_text_where_a_number_belongs(tmp_path: Path) -> None:
    path = tmp_path / "bad.vti"
    path.write_text(
        '<VTKFile type="ImageData" version="1.0"><ImageData WholeExtent="0 1 0 1 0 1" '
        'Origin="0 0 0" Spacing="1 1 1"><Piece Extent="0 1 0 1 0 1"><PointData '
        'Scalars="l"><DataArray type="UInt8" Name="l" format="appended" offset="abc"/>'
        '</PointData></Piece></ImageData><AppendedData encoding="raw">_xxxx</AppendedData>'
        "</VTKFile>"
    )
    with pytest.raises(FormatError, match="bad.vti"):
        load_input(path)


# -- 4. geometry and memory before allocation --------------------------------------------
def test_absurd_spacing_is_refused_by_the_reader(tmp_path: Path) -> None:
    path = tmp_path / "huge.vti"
    path.write_text(
        '<VTKFile type="ImageData" version="1.0"><ImageData WholeExtent="0 1 0 1 0 1" '
        'Origin="0 0 0" Spacing="1e300 1e300 1e300"><Piece Extent="0 1 0 1 0 1"><PointData '
        'Scalars="l"><DataArray type="UInt8" Name="l" format="ascii">1 1 1 1 1 1 1 1'
        "</DataArray></PointData></Piece></ImageData></VTKFile>"
    )
    with pytest.raises(GeometryError, match="header is corrupt"):
        load_input(path)


def test_a_far_plane_is_refused_before_allocating(tmp_path: Path) -> None:
    rows = ["plane,polygon,x,y,z"]
    for plane, z in enumerate((0.0, 2.0, 5.0e5)):  # one plane 500 m away
        rows += [f"{plane},0,{x},{y},{z}" for x, y in ((0, 0), (10, 0), (10, 10), (0, 10))]
    path = tmp_path / "far.csv"
    path.write_text("\n".join(rows) + "\n")
    with pytest.raises(MemoryBudgetError, match=r"GiB, over the memory budget of 8 GiB"):
        load_input(path)


def test_declared_size_is_bounded_not_the_file_size(tmp_path: Path) -> None:
    # A 2048^3 uint8 header with almost no data: a few hundred bytes on disk.
    header = nib.Nifti1Header()
    header.set_data_shape((2048, 2048, 2048))
    header.set_data_dtype(np.uint8)
    path = tmp_path / "bomb.nii.gz"
    with gzip.open(path, "wb") as fh:
        fh.write(header.binaryblock + b"\0" * 4)
    assert path.stat().st_size < 2000
    with pytest.raises(MemoryBudgetError, match="2048 x 2048 x 2048"):
        load_input(path)


def test_max_memory_lowers_and_raises_the_budget(
    small_nii: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["run", str(small_nii), "-o", str(tmp_path / "a"), "--max-memory", "1e-5"]) == 2
    line = _one_error_line(capsys)
    assert "memory budget of 1e-05 GiB" in line and "--max-memory" in line
    assert main(["run", str(small_nii), "-o", str(tmp_path / "b"), "--max-memory", "0.5"]) == 0
    assert main(["run", str(small_nii), "-o", str(tmp_path / "c"), "--max-memory", "-1"]) == 2


# -- 5 and 6. contours between the image's slices; options reach every reader -----------
def _ct(root: Path, positions: list[float] | None = None) -> list[Path]:
    shape = (48, 48, 21 if positions is None else len(positions))
    affine = factory.affine_from_geometry(
        [1, 0, 0], [0, 1, 0], [1.0, 1.0], [0, 0, 3.0], [-23.5, -23.5, 0.0]
    )
    return factory.write_series(
        root, np.zeros(shape, np.uint16), affine, modality="CT", irregular_positions=positions
    )


def _sphere_rings(radius: float, centre_z: float, zs: list[float]) -> list:
    return [
        factory.contour_item(
            factory.circle(math.sqrt(radius**2 - (z - centre_z) ** 2), (0.0, 0.0), z)
        )
        for z in zs
        if abs(z - centre_z) < radius
    ]


def test_contours_between_ct_slices_keep_their_planes(tmp_path: Path) -> None:
    zs = [11.5 + 3 * k for k in range(13)]  # half a slice off every CT plane (0, 3, ...)
    rings = _sphere_rings(20.0, 30.0, zs)
    _ct(tmp_path / "ct")
    factory.write_rtstruct(tmp_path / "ct" / "rs.dcm", {(1, "Ball"): rings})
    factory.write_rtstruct(tmp_path / "alone" / "rs.dcm", {(1, "Ball"): rings})
    sections = load_input(tmp_path / "ct")
    np.testing.assert_allclose(sections.positions, zs, atol=1e-6)  # type: ignore[union-attr]
    meshes = {}
    for name, source in (("ct", tmp_path / "ct"), ("alone", tmp_path / "alone" / "rs.dcm")):
        assert main(["run", str(source), "-o", str(tmp_path / f"out-{name}")]) == 0
        meshes[name] = trimesh.load(tmp_path / f"out-{name}" / "mesh.stl")
        assert meshes[name].is_watertight
    z0, z1 = meshes["ct"].bounds[:, 2]
    assert z0 == pytest.approx(zs[0] - 1.5, abs=0.25) and z1 == pytest.approx(
        zs[-1] + 1.5, abs=0.25
    )
    assert meshes["ct"].volume == pytest.approx(meshes["alone"].volume, rel=0.02)


def test_contours_on_some_slices_a_little_off_them_give_what_on_them_gives(
    tmp_path: Path,
) -> None:
    """Contours on every 3rd CT slice gave a ball 36 % smaller than the same contours
    0.5 mm off those slices: off them, the slice axis was rebuilt with the contours' 9 mm
    gap, so the ends grew by half of it instead of half a slice."""
    volumes = []
    for shift in (0.0, 0.5):
        zs = [12.0 + shift + 9 * k for k in range(5)]
        folder = tmp_path / f"ct{shift}"
        _ct(folder)
        factory.write_rtstruct(folder / "rs.dcm", {(1, "Ball"): _sphere_rings(20.0, 30.0, zs)})
        assert main(["run", str(folder), "-o", str(tmp_path / f"out{shift}"), "-q"]) == 0
        mesh = trimesh.load(tmp_path / f"out{shift}" / "mesh.stl")
        assert mesh.is_watertight
        labels = nib.load(tmp_path / f"out{shift}" / "labels.nii.gz")  # on the CT's grid
        assert labels.shape == (48, 48, 21) and labels.affine[2, 3] == pytest.approx(0.0)
        assert mesh.bounds[0, 2] == pytest.approx(zs[0] - 1.5, abs=0.25)  # half a slice
        volumes.append(mesh.volume)
    assert volumes[1] == pytest.approx(volumes[0], rel=0.03)


def test_allow_irregular_reaches_the_series_of_an_rtstruct(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    positions = [0, 3, 6, 9, 15, 18, 21, 27, 30, 33, 36, 42, 45, 48, 51, 54]
    _ct(tmp_path / "ct", [float(p) for p in positions])
    rings = _sphere_rings(20.0, 27.0, [float(p) for p in positions[2:-2]])
    factory.write_rtstruct(tmp_path / "ct" / "rs.dcm", {(1, "Ball"): rings})
    assert main(["run", str(tmp_path / "ct"), "-o", str(tmp_path / "a")]) == 2
    assert "--allow-irregular" in _one_error_line(capsys)
    assert main(["run", str(tmp_path / "ct"), "--allow-irregular", "-o", str(tmp_path / "b")]) == 0
    assert trimesh.load(tmp_path / "b" / "mesh.stl").is_watertight
    # the read line names the series the contours were placed on
    assert f"read as: contours on the images in {tmp_path / 'ct'}," in capsys.readouterr().out


# -- 7 and 8. info describes; real files as they exist -----------------------------------
def test_info_lists_every_roi_and_accepts_what_run_accepts(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    _ct(tmp_path / "ct")
    rings = _sphere_rings(10.0, 30.0, [24.0, 27.0, 30.0, 33.0, 36.0])
    factory.write_rtstruct(
        tmp_path / "ct" / "rs.dcm", {(1, "Ball"): rings, (2, "Ghost"): [], (3, "NoSeq"): None}
    )
    assert main(["info", str(tmp_path / "ct"), "--json"]) == 0
    details = json.loads(capsys.readouterr().out)
    rois = {r["name"]: r for r in details["rois"]}
    assert set(rois) == {"Ball", "Ghost", "NoSeq"}
    assert rois["Ball"]["contours"] == 5 and rois["Ball"]["planes"] == 5
    assert rois["Ghost"]["contours"] == 0 and "no contours" in rois["Ghost"]["note"]
    assert details["image_series"]["n_slices"] == 21


def test_info_lists_every_label_of_a_label_map(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    labels = np.zeros((20, 20, 10), np.uint8)
    labels[2:8, 2:8, 1:4] = 3
    labels[10:18, 10:18, 5:9] = 7
    path = tmp_path / "labels.nii.gz"
    nib.save(nib.Nifti1Image(labels, np.diag([0.5, 0.5, 2.0, 1.0])), path)
    assert main(["info", str(path), "--json"]) == 0
    structures = json.loads(capsys.readouterr().out)["structures"]
    assert [s["value"] for s in structures] == [3, 7]
    assert structures[0]["voxels"] == 6 * 6 * 3
    assert structures[0]["volume_mm3"] == pytest.approx(6 * 6 * 3 * 0.5)
    assert structures[1]["planes"] == {"axis": "z", "count": 4, "first": 5, "last": 8}


def test_dicom_without_preamble_is_read(tmp_path: Path) -> None:
    rings = _sphere_rings(10.0, 0.0, [-6.0, -3.0, 0.0, 3.0, 6.0])
    path = factory.write_rtstruct(tmp_path / "bare.dcm", {(1, "Ball"): rings}, preamble=False)
    assert path.read_bytes()[128:132] != b"DICM"
    assert load_input(path).n_planes == 5  # type: ignore[union-attr]


def test_pydicoms_own_rtstruct_is_described(capsys: pytest.CaptureFixture[str]) -> None:
    from pydicom.data import get_testdata_file

    assert main(["info", str(get_testdata_file("rtstruct.dcm")), "--json"]) == 0
    names = [r["name"] for r in json.loads(capsys.readouterr().out)["rois"]]
    assert names == ["patient", "Isocenter 1", "Isocenter 2"]


def test_a_structure_on_one_plane_is_a_one_slice_slab(tmp_path: Path) -> None:
    mask = np.zeros((20, 20, 9), bool)
    mask[5:15, 5:15, 4] = True
    affine = factory.affine_from_geometry(
        [1, 0, 0], [0, 1, 0], [1.0, 1.0], [0, 0, 3.0], [0.0, 0.0, 0.0]
    )
    path = factory.write_seg(tmp_path / "one.dcm", {1: mask}, affine, labels={1: "Flat"})
    out = tmp_path / "out"
    assert main(["run", str(path), "-o", str(out)]) == 0
    mesh = trimesh.load(out / "mesh.stl")
    assert mesh.is_watertight
    z0, z1 = mesh.bounds[:, 2]
    assert z0 == pytest.approx(12.0 - 1.5) and z1 == pytest.approx(12.0 + 1.5)  # one slice
    # 10 x 10 pixels, 3 mm thick; marching cubes rounds the square's corners
    assert mesh.volume == pytest.approx(100 * 3.0, rel=0.12)
