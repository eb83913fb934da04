"""volspring.regions: the region types on points with known answers, the one text grammar, every spelling
the command lines and the validation took before it (same nodes as their old code), and bad input."""

import math
import re

import numpy as np
import pytest

from volspring.regions import FACE_NAMES, Box, Face, HalfSpace, describe_bounds, parse_region

from conftest import cube_mesh

# The 27 nodes of a 2 x 2 x 2 grid on [0, 2] x [0, 1] x [0, 1]: 9 on every face, 3 on every edge.
GRID = np.array([[x, y, z] for x in (0.0, 1.0, 2.0) for y in (0.0, 0.5, 1.0) for z in (0.0, 0.5, 1.0)])


def count(region, points=GRID) -> int:
    return int(region.nodes(points).sum())


# ---------------------------------------------------------------------- the types
def test_box_selects_its_inside_and_its_faces():
    assert count(Box((0, 0, 0), (1, 1, 1))) == 2 * 3 * 3  # x in {0, 1}: the faces count as inside
    assert count(Box((0.5, 0.25, 0.25), (1.5, 0.75, 0.75))) == 1  # only the centre (1, 0.5, 0.5)
    assert count(Box((5, 5, 5), (6, 6, 6))) == 0


@pytest.mark.parametrize("lower, upper", [((None, None, None), (1.0, None, None)),
                                          ((-math.inf,) * 3, (1.0, math.inf, math.inf)),
                                          (None, (1.0, None, None))])
def test_box_sides_open_by_none_or_infinity(lower, upper):
    box = Box(lower, upper)
    assert count(box) == 18  # x <= 1
    assert box == Box(upper=(1.0, math.inf, math.inf))  # stored as floats, so equal however written
    assert count(Box()) == len(GRID)  # all sides open


def test_box_plane_and_its_slack():
    assert count(Box.plane("x", 2.0)) == 9 and count(Box.plane(1, 0.5)) == 9
    # Round-off: nodes 1e-13 off the plane are on it (default slack 1e-9 x the diagonal, 2.4e-9 m here);
    # 1e-6 off they are not, unless the tolerance says so.
    moved = GRID + np.where(GRID[:, :1] == 2.0, 1e-13, 0.0) * [1, 0, 0]
    assert count(Box.plane("x", 2.0), moved) == 9
    moved = GRID + np.where(GRID[:, :1] == 2.0, 1e-6, 0.0) * [1, 0, 0]
    assert count(Box.plane("x", 2.0), moved) == 0
    assert count(Box.plane("x", 2.0, tolerance=1e-5), moved) == 9


def test_half_space_axis_aligned_and_tilted():
    assert count(HalfSpace((1, 0, 0), (1, 0, 0))) == 18  # x <= 1, the plane included
    assert count(HalfSpace((1, 0, 0), (-3, 0, 0))) == 18  # x >= 1; the normal's length does not matter
    tilted = HalfSpace((0, 0, 1), (1, 0, 1))  # x + z <= 1
    expected = GRID[:, 0] + GRID[:, 2] <= 1 + 1e-12
    np.testing.assert_array_equal(tilted.nodes(GRID), expected)
    assert tilted.normal == pytest.approx((2**-0.5, 0.0, 2**-0.5), rel=1e-15)  # normalised: the slack is a distance


@pytest.mark.parametrize("name", FACE_NAMES)
def test_each_face_of_the_bounding_box_holds_nine_grid_nodes(name):
    face = Face(name[0], name[1:])
    mask = face.nodes(GRID)
    assert mask.sum() == 9 and face.name == name
    axis = "xyz".index(name[0])
    extreme = GRID[:, axis].min() if name.endswith("min") else GRID[:, axis].max()
    assert (GRID[mask, axis] == extreme).all()


def test_a_face_is_found_on_the_points_given():
    face = Face("z", "min")
    assert count(face, GRID + [0, 0, -7.5]) == 9  # the same Face picks the bottom of a moved body
    assert Face(2, "min") == face  # an axis index is stored as its name


def test_regions_are_callables_and_take_no_points():
    for region in (Box(), HalfSpace((0, 0, 0), (0, 0, 1)), Face("x", "min")):
        np.testing.assert_array_equal(region(GRID), region.nodes(GRID))
        empty = region.nodes(np.zeros((0, 3)))
        assert empty.shape == (0,) and empty.dtype == bool


def test_describe_bounds_names_the_extent():
    assert describe_bounds(GRID) == "[0, 2] x [0, 1] x [0, 1]"


# ---------------------------------------------------------------------- the text form
@pytest.mark.parametrize("text, expected", [
    ("xmin", Face("x", "min")),
    ("ZMAX", Face("z", "max")),
    (" y min ", Face("y", "min")),
    ("x<0.5", HalfSpace((0.5, 0, 0), (1, 0, 0))),
    ("x <= 0.5", HalfSpace((0.5, 0, 0), (1, 0, 0))),
    ("z>1.2", HalfSpace((0, 0, 1.2), (0, 0, -1))),
    ("y >= -3e-1", HalfSpace((0, -0.3, 0), (0, -1, 0))),
    ("x=0", Box.plane("x", 0.0)),
    ("box:-1,-1,-1,0,1,1", Box((-1, -1, -1), (0, 1, 1))),
    ("BOX: -1, -1, -1, 0, 1, 1", Box((-1, -1, -1), (0, 1, 1))),
    ("-1,-1,-1,0,1,1", Box((-1, -1, -1), (0, 1, 1))),
])
def test_parse_region_spellings(text, expected):
    assert parse_region(text) == expected


def test_parse_region_units_scale_the_numbers_not_the_faces():
    assert parse_region("-1000,-1000,-1000,0,1000,1000", unit=0.001) == Box((-1, -1, -1), (0, 1, 1))
    assert parse_region("x<500", unit=0.001) == HalfSpace((0.5, 0, 0), (1, 0, 0))
    assert parse_region("xmax", unit=0.001) == Face("x", "max")
    assert parse_region("xmin", tolerance=0.1).tolerance == 0.1


# ---------------------------------------------------------------------- old spellings, same nodes
def _old_cli_pin(text, points, unit=1.0):
    """``volspring-sim --pin`` before volspring.regions (volspring/cli.py, _pinned_nodes)."""
    box = np.array([float(part) for part in text.split(",")]) * unit
    slack = 1e-9 * float(np.linalg.norm(points.max(axis=0) - points.min(axis=0)))
    return ((points >= box[:3] - slack) & (points <= box[3:] + slack)).all(axis=1)


def _old_validation_region(text, points):
    """``volspring-validate --clamp`` before volspring.regions (validation/cases.py, parse_region)."""
    spec = text.strip().lower().replace(" ", "")
    tolerance = 1e-6 * float(np.linalg.norm(np.ptp(points, axis=0)))
    lower, upper = np.full(3, -np.inf), np.full(3, np.inf)
    if match := re.match(r"^([xyz])(min|max)$", spec):
        axis = "xyz".index(match[1])
        lower[axis] = upper[axis] = points[:, axis].min() if match[2] == "min" else points[:, axis].max()
    elif match := re.match(r"^([xyz])\s*([<>])=?\s*(.+)$", spec):
        (upper if match[2] == "<" else lower)["xyz".index(match[1])] = float(match[3])
    else:
        values = [float(v) for v in spec.removeprefix("box:").split(",")]
        lower, upper = np.array(values[:3]), np.array(values[3:])
    return ((points >= lower - tolerance) & (points <= upper + tolerance)).all(axis=1)


@pytest.fixture(scope="module")
def nodes_near_boundaries():
    # A beam's nodes plus nodes just inside and outside its faces and the planes used below, at offsets
    # either side of both old slacks (1e-9 and 1e-6 of the diagonal, ~2e-10 and ~2e-7 m here).
    rng = np.random.default_rng(7)
    points = cube_mesh((4, 1, 1), size=(0.2, 0.05, 0.05)).points
    near = np.repeat(points, 4, axis=0) + np.tile([1e-12, -1e-12, 1e-8, -1e-8], len(points))[:, None] * \
        rng.choice([-1.0, 0.0, 1.0], size=(4 * len(points), 3))
    return np.vstack([points, near, rng.uniform(-0.01, 0.21, size=(200, 3))])


@pytest.mark.parametrize("text", ["-1,-1,-1,0,1,1", "-0.1,-1,-1,-0.1,1,1", "0.05,0,0,0.15,0.05,0.05",
                                  "5,5,5,6,6,6", "-1,-1,-1,0.06,1,1"])
def test_old_cli_pin_boxes_select_the_same_nodes(text, nodes_near_boundaries):
    points = nodes_near_boundaries
    np.testing.assert_array_equal(parse_region(text, label="--pin").nodes(points), _old_cli_pin(text, points))
    millimetres = ",".join(str(float(v) * 1000) for v in text.split(","))
    np.testing.assert_array_equal(parse_region(millimetres, unit=0.001).nodes(points),
                                  _old_cli_pin(millimetres, points, unit=0.001))


@pytest.mark.parametrize("text", ["xmin", "xmax", "ymin", "zmax", "x < 0.05", "x<=0.05", "z>0.05", "y>=0.025",
                                  "x<-1", "box:-1,-1,-1,0,1,1", "box:0.05,0,0,0.1,0.05,0.05"])
def test_old_validation_regions_select_the_same_nodes(text, nodes_near_boundaries):
    from validation.cases import parse_region as validation_parse_region

    points = nodes_near_boundaries
    mesh = cube_mesh((4, 1, 1), size=(0.2, 0.05, 0.05))
    np.testing.assert_array_equal(validation_parse_region(text, mesh)(mesh.points),
                                  _old_validation_region(text, mesh.points))
    # On other points with the slack the mesh gave (the faces are those of the points tested).
    tolerance = 1e-6 * float(np.linalg.norm(np.ptp(mesh.points, axis=0)))
    old = _old_validation_region(text, points) if "min" not in text and "max" not in text else None
    if old is not None:
        np.testing.assert_array_equal(parse_region(text, tolerance=tolerance).nodes(points), old)


def test_old_box_selects_the_same_nodes(nodes_near_boundaries):
    points = nodes_near_boundaries
    for lower, upper in [((0.0, -np.inf, -np.inf), (0.0, np.inf, np.inf)), ((0, 0, 0), (0.1, 0.05, 0.05)),
                         ((-np.inf,) * 3, (0.2, np.inf, 0.025))]:
        slack = 1e-9 * float(np.linalg.norm(np.ptp(points, axis=0)))  # validation.boundary.Box before
        old = ((points >= np.array(lower) - slack) & (points <= np.array(upper) + slack)).all(axis=1)
        np.testing.assert_array_equal(Box(lower, upper)(points), old)


def test_validation_keeps_box_importable_and_takes_any_region():
    import validation
    import validation.boundary
    from validation.boundary import Clamp, resolve_clamps

    assert validation.Box is Box and validation.boundary.Box is Box
    mesh = cube_mesh((2, 1, 1), size=(2.0, 1.0, 1.0))
    by_face = resolve_clamps(mesh, Clamp(Face("x", "min")))
    by_text = resolve_clamps(mesh, Clamp(parse_region("x<0")))
    np.testing.assert_array_equal(by_face.node_mask, by_text.node_mask)
    assert by_face.node_mask.all(axis=1).sum() == 4


def test_cli_pins_by_any_spelling(tmp_path, capsys):
    from volspring.cli import main

    mesh = tmp_path / "beam.vtu"
    cube_mesh((4, 1, 1), size=(0.2, 0.05, 0.05)).write(mesh)
    pinned = {}
    for text in ("-1,-1,-1,0,1,1", "box:-1,-1,-1,0,1,1", "xmin", "x<0", "x<=0.01", "x=0"):
        assert main([str(mesh), "--pin", text, "--dt", "0.01", "--duration", "0.01", "--no-progress"]) == 0
        pinned[text] = re.search(r"(\d+) pinned node", capsys.readouterr().out).group(1)
    assert set(pinned.values()) == {"4"}, pinned  # the four nodes of the end face x = 0


# ---------------------------------------------------------------------- bad input, named
@pytest.mark.parametrize("text, message", [
    ("wmin", "region 'wmin': unknown face 'wmin'; the faces are xmin, xmax, ymin, ymax, zmin, zmax"),
    ("left", "region 'left' is not one of the region forms xmin"),
    ("", "region '' is not one of the region forms"),
    ("x<abc", "region 'x<abc': 'abc' is not a number"),
    ("x<inf", "region 'x<inf': 'inf' is not a finite number"),
    ("z>nan", "region 'z>nan': 'nan' is not a finite number"),
    ("box:1,2,3", "region 'box:1,2,3' is not 6 finite numbers xmin,ymin,zmin,xmax,ymax,zmax: got 3 values"),
    ("1,2,nan,4,5,6", "region '1,2,nan,4,5,6' is not 6 finite numbers .*: 'nan' is not a finite number"),
    ("0,0,0,-1,1,1", r"region '0,0,0,-1,1,1': xmin > xmax \(0 > -1 m\)"),
    ("0,2,0,1,1,1", r"ymin > ymax \(2 > 1 m\)"),
])
def test_parse_region_refuses_bad_text_naming_it(text, message):
    with pytest.raises(ValueError, match=message):
        parse_region(text)


def test_parse_region_names_its_label_and_checks_its_options():
    with pytest.raises(ValueError, match=r"^--pin '1,1,1' is not 6 finite numbers"):
        parse_region("1,1,1", label="--pin")
    with pytest.raises(ValueError, match=r"unit = 0 m is not > 0"):
        parse_region("xmin", unit=0)
    with pytest.raises(ValueError, match=r"unit = nan m is not a finite number"):
        parse_region("xmin", unit=float("nan"))
    with pytest.raises(TypeError, match="region = None is not text"):
        parse_region(None)


@pytest.mark.parametrize("build, message", [
    (lambda: Box((1, 0, 0), (0, 1, 1)), r"xmin > xmax \(1 > 0 m\): a Box needs lower <= upper on every axis, "
                                        r"got lower = \(1, 0, 0\), upper = \(0, 1, 1\)"),
    (lambda: Box((0, 0, float("nan")), (1, 1, 1)), r"Box lower\[2\] = nan is not a number; an open side is None"),
    (lambda: Box((math.inf, 0, 0), None), r"Box lower\[0\] = inf would select nothing; an open side is None or -inf"),
    (lambda: Box(None, (0, -math.inf, 0)), r"Box upper\[1\] = -inf would select nothing"),
    (lambda: Box((0, 0), (1, 1, 1)), r"Box lower = \(0, 0\) has 2 entries, expected 3"),
    (lambda: Box((0, "a", 0), (1, 1, 1)), r"Box lower\[1\] = 'a' is not a number"),
    (lambda: Box(5.0, (1, 1, 1)), r"Box lower = 5.0 is not three numbers"),
    (lambda: Box((0, 0, 0), (1, 1, 1), tolerance=-1.0), r"tolerance = -1.0 m is not >= 0"),
    (lambda: Box.plane("w", 0.0), r"axis = 'w' is not one of 'x', 'y', 'z'"),
    (lambda: Box.plane("x", float("inf")), r"Box.plane value = inf is not a finite number"),
    (lambda: HalfSpace((0, 0), (1, 0, 0)), r"HalfSpace point = \(0, 0\) is not three finite numbers"),
    (lambda: HalfSpace((0, 0, 0), (0, 0, 0)), r"HalfSpace normal = \(0, 0, 0\) is zero"),
    (lambda: HalfSpace((0, 0, 0), (1, math.nan, 0)), r"HalfSpace normal = \(1, nan, 0\) is not three finite"),
    (lambda: Face("w", "min"), r"axis = 'w' is not one of 'x', 'y', 'z'"),
    (lambda: Face("x", "top"), r"Face side = 'top' is not 'min' or 'max'"),
    (lambda: Face("x", "min", tolerance=math.inf), r"tolerance = inf m is not a finite number"),
])
def test_constructors_refuse_bad_values_naming_them(build, message):
    with pytest.raises(ValueError, match=message):
        build()


@pytest.mark.parametrize("points, message", [
    (np.zeros((4, 2)), r"points has shape \(4, 2\), expected \(n, 3\)"),
    (np.zeros(3), r"points has shape \(3,\), expected \(n, 3\)"),
    ([[0, 0, 0], [1, np.nan, 0]], r"1 point\(s\) are not finite, the first points\[1\] = \(1, nan, 0\)"),
    ([["a", 0, 0]], r"points must be \(n, 3\) coordinates"),
])
def test_nodes_refuse_points_that_are_not_n_by_3_finite(points, message):
    for region in (Box(), HalfSpace((0, 0, 0), (1, 0, 0)), Face("x", "min")):
        with pytest.raises(ValueError, match=message):
            region.nodes(points)
