"""Contour files (JSON and CSV): round trips, holes, and strict validation."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from slicerecon.errors import EmptyMaskError, FormatError, GeometryError, InputError
from slicerecon.io.contours import read_contours, write_contours_csv, write_contours_json
from slicerecon.sections import CrossSections


def _sections(affine, *, planes=(1, 2, 4.5, 7, 9), empty_last=True):
    """Ellipses on fractional, irregular planes; odd planes get a hole; maybe one empty plane."""
    i, j = np.mgrid[0:40, 0:30]
    masks = []
    for k in range(len(planes)):
        m = (i - 20) ** 2 / (100 + 10 * k) + (j - 15) ** 2 / 60 < 1
        if k % 2:
            m &= (i - 20) ** 2 + (j - 15) ** 2 >= 9
        masks.append(m)
    if empty_last:
        masks[-1] = np.zeros_like(masks[-1])
    return CrossSections(np.array(masks), list(planes), 2, affine, (40, 30, 12))


def _affine(spacing=(0.8, 0.7, 2.5), origin=(-10.0, 5.0, 3.0)):
    affine = np.diag([*spacing, 1.0])
    affine[:3, 3] = origin
    return affine


def _json_doc(planes, **extra):
    doc = {"format": "slicerecon-contours", "version": 1, "units": "mm", "planes": planes}
    doc.update(extra)
    return doc


def _write_json(tmp_path, doc, name="c.json"):
    path = tmp_path / name
    path.write_text(json.dumps(doc) if not isinstance(doc, str) else doc)
    return path


def _circle(radius, centre, n=720):
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    pts = np.zeros((n, 3)) + np.asarray(centre, float)
    pts[:, 0] += radius * np.cos(t)
    pts[:, 1] += radius * np.sin(t)
    return pts


TRIANGLE = [[0.0, 0.0, 1.0], [4.0, 0.0, 1.0], [0.0, 4.0, 1.0]]


def test_json_round_trip_is_exact(tmp_path):
    rotation = np.array([[0.0, -1.0, 0.0], [0.6, 0.0, -0.8], [0.8, 0.0, 0.6]])
    for affine in (
        _affine(),
        _affine() @ np.block([[rotation, np.zeros((3, 1))], [np.zeros((1, 3)), np.ones((1, 1))]]),
    ):
        original = _sections(affine)
        path = write_contours_json(original, tmp_path / "out" / "c.json", label="lesion")
        back = read_contours(path)
        assert back.axis == original.axis and back.grid_shape == original.grid_shape
        np.testing.assert_array_equal(back.masks, original.masks)  # empty plane kept too
        np.testing.assert_allclose(back.positions, original.positions, atol=1e-6)
        np.testing.assert_allclose(back.indices, original.indices, atol=1e-9)
        np.testing.assert_allclose(back.normal, original.normal, atol=1e-12)
    doc = json.loads(path.read_text())
    assert doc["label"] == "lesion" and doc["units"] == "mm" and doc["version"] == 1
    assert not list(tmp_path.joinpath("out").glob(".*"))  # no temporary file left


def test_json_with_pixel_spacing_resamples_instead_of_using_the_grid(tmp_path):
    original = _sections(_affine(spacing=(0.5, 0.5, 2.0)), empty_last=False)
    path = write_contours_json(original, tmp_path / "c.json")
    back = read_contours(path, pixel_spacing=0.25)
    np.testing.assert_allclose(back.spacing[:2], 0.25)
    np.testing.assert_allclose(back.positions, original.positions, atol=1e-6)
    for p in range(original.n_planes):  # polygons follow the 0.5 iso-line: area within 2 %
        assert back.area_mm2(p) == pytest.approx(original.area_mm2(p), rel=0.02)


def test_hole_is_empty_and_ring_area_is_analytic(tmp_path):
    outer, hole = _circle(20.0, (1.0, 2.0, 5.0)), _circle(7.5, (3.0, 1.0, 5.0))
    doc = _json_doc(
        [
            {"position": 5.0, "polygons": [outer.tolist(), hole.tolist()]},
            {"polygons": [(outer + [0, 0, 2]).tolist()]},
        ],
        normal=[0, 0, 1],
    )
    cs = read_contours(_write_json(tmp_path, doc), pixel_spacing=0.1)
    n = 720
    ngon = 0.5 * n * np.sin(2.0 * np.pi / n)
    assert cs.area_mm2(0) == pytest.approx(ngon * (20.0**2 - 7.5**2), rel=0.01)
    assert cs.area_mm2(1) == pytest.approx(ngon * 20.0**2, rel=0.01)
    centre = np.round(np.linalg.inv(cs.affine) @ [3.0, 1.0, 5.0, 1.0]).astype(int)
    assert not cs.masks[0][centre[0], centre[1]] and cs.masks[1][centre[0], centre[1]]


@pytest.mark.parametrize(
    ("second", "words"),
    [
        (_circle(10.0, (8.0, 0.0, 5.0)), "cross each other"),  # the lens is a hole
        (_circle(10.0, (0.0, 0.0, 5.0)), "are the same contour"),  # it cancels out
    ],
)
def test_contours_that_cross_or_repeat_on_a_plane_are_warned_about(tmp_path, capsys, second, words):
    from slicerecon.cli import main

    first = _circle(10.0, (0.0, 0.0, 5.0))
    doc = _json_doc(
        [
            {"polygons": [first.tolist(), second.tolist()]},
            {"polygons": [(first + [0, 0, 4]).tolist()]},
        ]
    )
    path = _write_json(tmp_path, doc, name="drawn.json")
    assert main(["run", str(path), "-o", str(tmp_path / "out")]) == 0
    err = [line for line in capsys.readouterr().err.splitlines() if "even-odd" in line]
    assert len(err) == 1 and err[0].startswith(f"warning: {path}: planes[0].polygons[0]")
    assert words in err[0] and "too small" not in capsys.readouterr().err
    # a hole nested inside is what the rule is for: no warning
    doc["planes"][0]["polygons"][1] = _circle(4.0, (1.0, 0.0, 5.0)).tolist()
    _write_json(tmp_path, doc, name="drawn.json")
    assert main(["run", str(path), "-o", str(tmp_path / "o2")]) == 0
    assert "even-odd" not in capsys.readouterr().err


def test_repeated_first_point_is_accepted(tmp_path):
    square = [[0, 0, 0], [10, 0, 0], [10, 10, 0], [0, 10, 0], [0, 0, 0]]
    cs = read_contours(
        _write_json(tmp_path, _json_doc([{"polygons": [square]}])), pixel_spacing=1.0
    )
    assert cs.area_mm2(0) == pytest.approx(100.0)


def test_csv_round_trip_gives_the_same_pixels_in_world_space(tmp_path):
    original = _sections(_affine(spacing=(0.6, 0.6, 2.5)))
    path = write_contours_csv(original, tmp_path / "c.csv")
    assert path.read_text().splitlines()[0] == "plane,polygon,x,y,z"
    back = read_contours(path, pixel_spacing=0.6)
    kept = [p for p in range(original.n_planes) if original.masks[p].any()]
    assert back.n_planes == len(kept)  # CSV cannot hold the empty plane
    np.testing.assert_allclose(back.positions, original.positions[kept], atol=1e-6)
    np.testing.assert_allclose(back.normal, original.normal, atol=1e-12)
    for new, old in enumerate(kept):
        world_old = original.plane_to_world(old, np.argwhere(original.masks[old]))
        world_new = back.plane_to_world(new, np.argwhere(back.masks[new]))
        np.testing.assert_allclose(world_new, world_old, atol=1e-6)


def test_csv_columns_in_any_order_with_comments(tmp_path):
    path = tmp_path / "c.csv"
    path.write_text(
        "# made by hand\nx, y, z, polygon, plane\n0,0,2,7,3\n10,0,2,7,3\n"
        "\n10,10,2,7,3\n0,10,2,7,3\n"
    )
    cs = read_contours(path, pixel_spacing=1.0)
    assert cs.n_planes == 1 and cs.area_mm2(0) == pytest.approx(100.0)


def test_non_parallel_planes_raise_geometry_error(tmp_path):
    tilted = [[0, 0, 5], [10, 0, 5], [10, 10, 8], [0, 10, 8]]
    doc = _json_doc([{"polygons": [TRIANGLE]}, {"polygons": [tilted]}])
    tilt = r"not on parallel planes: planes\[\d\]\.polygons\[0\] is tilted"
    with pytest.raises(GeometryError, match=tilt):
        read_contours(_write_json(tmp_path, doc))


@pytest.mark.parametrize(
    ("doc", "message"),
    [
        ("{not json", r"not valid JSON: .* line 1, column 2"),
        ([], "top level must be a JSON object"),
        ({"format": "slicerecon-contours", "version": 1, "units": "mm"}, "missing key 'planes'"),
        (_json_doc([]) | {"format": "other"}, "not a contour file: \"format\" is 'other'"),
        ({"cases": []}, 'not a contour file: no "format" key'),
        (
            {"format": "slicerecon-dataset", "version": 1, "cases": []},
            "the manifest of a dataset .* pass its folder to 'slicerecon batch'",
        ),
        (_json_doc([]) | {"version": 3}, "version: version 3 is not supported"),
        (_json_doc([]) | {"units": "cm"}, 'units: must be "mm"'),
        (_json_doc([]) | {"colour": "red"}, "unknown key 'colour'"),
        (_json_doc([]) | {"coordinates": "XYZ"}, 'coordinates: must be "RAS" or "LPS"'),
        (
            _json_doc([]) | {"coordinates": None},
            r'coordinates: expected "RAS" or "LPS" \(got null\)',
        ),
        (_json_doc({"polygons": []}), "planes: expected a list of planes"),
        (_json_doc([{"polygons": [TRIANGLE]}, {"poly": []}]), r"planes\[1\]: unknown key 'poly'"),
        (_json_doc([{"position": 1.0}]), r"planes\[0\]: missing key 'polygons'"),
        (
            _json_doc([{"polygons": [TRIANGLE, TRIANGLE[:2]]}]),
            r"planes\[0\]\.polygons\[1\]: needs at least 3 points \(got 2\)",
        ),
        (
            _json_doc([{"polygons": [[[0, 0, 1], [1, 0], [0, 1, 1]]]}]),
            r"planes\[0\]\.polygons\[0\]\[1\]: expected \[x, y, z\] \(got a list of length 2\)",
        ),
        (
            _json_doc([{"polygons": [[[0, 0, 1], [1, 0, "1"], [0, 1, 1]]]}]),
            r"planes\[0\]\.polygons\[0\]\[1\]\[2\]: expected a number \(got a string\)",
        ),
        (
            _json_doc([{"polygons": [[[0, 0, 1], [1, 0, float("nan")], [0, 1, 1]]]}]),
            r"planes\[0\]\.polygons\[0\]\[1\]\[2\]: must be finite \(got nan\)",
        ),
        (
            _json_doc([{"polygons": [[[0, 0, 1], [1, 0, True], [0, 1, 1]]]}]),
            r"\[1\]\[2\]: expected a number \(got true/false\)",
        ),
        (
            _json_doc([{"position": "1", "polygons": [TRIANGLE]}]),
            r"planes\[0\]\.position: expected a number",
        ),
        (
            _json_doc([{"position": 3.0, "polygons": [TRIANGLE]}], normal=[0, 0, 1]),
            r"planes\[0\]\.polygons\[0\]: lies at 1 mm along the normal but the plane's position",
        ),
        (_json_doc([{"polygons": []}]), r"planes\[0\]: a plane without polygons needs"),
        (_json_doc([{"polygons": [TRIANGLE]}], normal=[0, 0, 0]), "normal: must not be the zero"),
        (
            _json_doc([{"polygons": [TRIANGLE]}], grid={"affine": np.eye(4).tolist()}),
            "grid: missing key 'shape'",
        ),
        (
            _json_doc(
                [{"polygons": [TRIANGLE]}], grid={"affine": np.eye(4).tolist(), "shape": [4, 0, 4]}
            ),
            r"grid\.shape: expected 3 positive integers",
        ),
        (
            _json_doc(
                [{"polygons": [TRIANGLE]}, {"polygons": [[[5, 5, 1], [9, 5, 1], [5, 9, 1]]]}]
            ),
            "lists 2 planes but its polygons lie at 1 distinct positions",
        ),
        (
            _json_doc([{"polygons": [TRIANGLE, [[0, 0, 3], [4, 0, 3], [0, 4, 3]]]}]),
            "lists 1 planes but its polygons lie at 2 distinct positions",
        ),
    ],
)
def test_malformed_json_raises_format_error(tmp_path, doc, message):
    path = _write_json(tmp_path, doc)
    with pytest.raises(FormatError, match=message) as info:
        read_contours(path)
    assert str(path) in str(info.value)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", "is empty: expected a header plane,polygon,x,y,z"),
        ("plane,polygon,x,y\n0,0,1,2\n", "line 1: the header must name the columns"),
        ("0,0,0,0,1\n", "line 1: the header must name the columns"),
        ("plane,polygon,x,y,z\n0,0,0,0,1\n0,0,1,0\n", "line 3: expected 5 values, got 4"),
        ("plane,polygon,x,y,z\n0,a,0,0,1\n", "line 2: polygon must be an integer id"),
        ("plane,polygon,x,y,z\n0,0,0,zero,1\n", "line 2: y must be a number"),
        ("plane,polygon,x,y,z\n0,0,0,0,nan\n", "line 2: z must be finite"),
        (
            "plane,polygon,x,y,z\n0,0,0,0,1\n0,0,1,0,1\n0,1,0,0,1\n0,1,1,0,1\n0,1,0,1,1\n"
            "0,0,1,1,1\n",
            "line 7: the rows of plane 0, polygon 0 are not contiguous",
        ),
        (
            "plane,polygon,x,y,z\n0,0,0,0,1\n0,0,1,0,1\n",
            r"line 2 \(plane 0, polygon 0\): needs at least 3 points",
        ),
    ],
)
def test_malformed_csv_raises_format_error(tmp_path, text, message):
    path = tmp_path / "c.csv"
    path.write_text(text)
    with pytest.raises(FormatError, match=message):
        read_contours(path)


def test_file_errors(tmp_path):
    with pytest.raises(InputError, match="contour file not found"):
        read_contours(tmp_path / "missing.json")
    with pytest.raises(InputError, match="is a directory"):
        read_contours(tmp_path)
    (tmp_path / "c.txt").write_text("x")
    with pytest.raises(InputError, match=r"must end in \.json or \.csv"):
        read_contours(tmp_path / "c.txt")
    (tmp_path / "bad.json").write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(FormatError, match="not UTF-8"):
        read_contours(tmp_path / "bad.json")
    with pytest.raises(EmptyMaskError, match="no contours given"):
        read_contours(_write_json(tmp_path, _json_doc([])))
    (tmp_path / "h.csv").write_text("plane,polygon,x,y,z\n")
    with pytest.raises(EmptyMaskError):
        read_contours(tmp_path / "h.csv")


def test_writers_refuse_empty_sections(tmp_path):
    empty = CrossSections(np.zeros((1, 4, 4), bool), [0], 2, np.eye(4), (4, 4, 1))
    with pytest.raises(EmptyMaskError):
        write_contours_json(empty, tmp_path / "e.json")
    assert not (tmp_path / "e.json").exists()


@pytest.mark.parametrize(
    ("doc", "message"),
    [
        (
            _json_doc([{"polygons": [TRIANGLE]}], label=None),
            r"label: expected a string \(got null\)",
        ),
        (
            _json_doc([{"position": None, "polygons": [TRIANGLE]}]),
            r"planes\[0\]\.position: expected a number \(got null\)",
        ),
        (
            _json_doc([{"polygons": [[[0, 0, 10**400], [1, 0, 1], [0, 1, 1]]]}]),
            r"planes\[0\]\.polygons\[0\]\[0\]\[2\]: must be finite "
            r"\(got an integer of 401 digits\)",
        ),
        (
            _json_doc(
                [{"polygons": [TRIANGLE]}],
                grid={"affine": np.eye(4).tolist(), "shape": [4, 4, 4], "origin": [0, 0, 0]},
            ),
            r"grid: unknown key 'origin' \(allowed: affine, shape\)",
        ),
        (
            _json_doc(
                [{"polygons": [TRIANGLE]}],
                grid={"affine": np.zeros((4, 4)).tolist(), "shape": [4, 4, 4]},
            ),
            r"grid\.affine: the last row must be \[0, 0, 0, 1\]",
        ),
        (
            _json_doc([{"polygons": [TRIANGLE]}], version="1"),
            "version: expected an integer \\(got a string\\)",
        ),
        (_json_doc([{"polygons": [TRIANGLE]}, 5]), r"planes\[1\]: expected an object \(got int\)"),
    ],
)
def test_schema_errors_name_the_json_path(tmp_path, doc, message):
    path = _write_json(tmp_path, doc)
    with pytest.raises(FormatError, match=message) as info:
        read_contours(path)
    assert str(info.value).startswith(f"{path}: ")


def test_the_schema_is_published_as_json_schema():
    from slicerecon.io.contours import ContourFile

    schema = ContourFile.model_json_schema()
    assert schema["required"] == ["format", "version", "units", "planes"]
    assert schema["additionalProperties"] is False
    assert schema["properties"]["format"]["const"] == "slicerecon-contours"


@pytest.mark.parametrize("end", ["line", "point"])
def test_a_structures_end_drawn_as_a_line_or_a_point_is_a_plane_where_it_is_absent(
    tmp_path, capsys, end
):
    """An ellipsoid whose apex contours are a stroke (3 collinear points) or one point
    clicked 3 times: the file was refused ("lists 10 planes but its polygons lie at 8
    distinct positions", "needs at least 3 points (got 2)")."""
    from slicerecon.cli import main

    t = np.linspace(0, 2 * np.pi, 48, endpoint=False)
    planes = []
    for z in np.arange(-18.0, 18.1, 4.0):
        r = np.sqrt(max(0.0, 1 - (z / 18) ** 2))
        ring = np.stack([20 * r * np.cos(t), 14 * r * np.sin(t), np.full(t.size, z)], 1)
        apex = [[-3.0, 0.0, z], [0.0, 0.0, z], [3.0, 0.0, z]] if end == "line" else [[0, 0, z]] * 3
        planes.append({"position": z, "polygons": [apex if abs(z) == 18 else ring.tolist()]})
    path = _write_json(tmp_path, _json_doc(planes, normal=[0, 0, 1]))
    assert main(["run", str(path), "-o", str(tmp_path / "o")]) == 0
    said = [line for line in capsys.readouterr().err.splitlines() if "no area" in line]
    assert len(said) == 1 and "planes[0].polygons[0], planes[9].polygons[0]" in said[0]
    mesh = trimesh.load(tmp_path / "o" / "mesh.stl")
    assert mesh.volume == pytest.approx(4 / 3 * np.pi * 20 * 14 * 18, rel=0.04)
    sections = read_contours(path)
    assert sections.n_planes == 10 and not sections.masks[0].any()


def test_the_read_line_says_when_contour_planes_are_irregularly_spaced(tmp_path):
    """Planes 2, 2, 5, 2 mm apart read as "spacing 2 mm" (the median) and nothing else;
    label maps said ", irregular"."""
    from slicerecon.io.contours import read_contour_annotation

    zs = [0.0, 2.0, 4.0, 9.0, 11.0]
    planes = [{"polygons": [_circle(5.0, (0, 0, z), n=64).tolist()]} for z in zs]
    described = read_contour_annotation(_write_json(tmp_path, _json_doc(planes))).describe()
    assert described == "5 planes along z, spacing 2 mm, irregular"
    jittered = [
        {"polygons": [_circle(5.0, (0, 0, z + 0.004 * (n % 2)), n=64).tolist()]}
        for n, z in enumerate((0.0, 4.0, 8.0, 12.0))
    ]
    described = read_contour_annotation(
        _write_json(tmp_path, _json_doc(jittered), "j.json")
    ).describe()
    assert described == "4 planes along z, spacing 4 mm"


def test_info_calls_planes_jittered_within_the_plane_tolerance_uniformly_spaced(tmp_path):
    """Planes 4 mm apart, each off by up to 0.004 mm (an export's rounding): info said
    uniform_spacing false, though positions within 0.01 mm count as one elsewhere."""
    from slicerecon.io.describe import describe_sections

    zs = [0.0, 4.004, 7.996, 12.004]
    planes = [{"polygons": [_circle(5.0, (0, 0, z), n=64).tolist()]} for z in zs]
    described = describe_sections(read_contours(_write_json(tmp_path, _json_doc(planes))))
    assert described["uniform_spacing"]
    planes = [{"polygons": [_circle(5.0, (0, 0, z), n=64).tolist()]} for z in (0, 2, 4, 9)]
    assert not describe_sections(read_contours(_write_json(tmp_path, _json_doc(planes))))[
        "uniform_spacing"
    ]
