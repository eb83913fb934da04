"""Loading surfaces: repairs that are made and logged, and defects that are refused with a located error."""

import logging

import numpy as np
import pytest
import trimesh

from meshing.shapes import sphere
from meshing.surface import SurfaceError, contains_points, load_surface, winding_numbers


def _box():
    return trimesh.creation.box(extents=(1.0, 1.0, 1.0))


def test_bunny_seams_are_merged_and_reported(shared_data, caplog):
    with caplog.at_level(logging.INFO, logger="meshing.surface"):
        surface = load_surface(shared_data / "coarse_bunny.obj", scale=1.0)  # the file's own units, as the README
    # Figures from tests/data/README.md: 502 vertices once positions are merged, genus 0, ~8.37e5.
    assert len(surface.vertices) == 502 and len(surface.faces) == 1000
    assert surface.is_watertight and surface.is_winding_consistent and surface.euler_number == 2
    assert surface.volume == pytest.approx(8.37e5, rel=1e-3)  # README gives 3 digits
    assert "merged 2498 duplicate vertices (3000 -> 502)" in caplog.text


def test_in_memory_mesh_is_not_modified():
    inverted = _box()
    inverted.invert()
    faces = inverted.faces.copy()
    surface = load_surface(inverted)
    assert surface.volume == pytest.approx(1.0, rel=1e-12)  # a unit box, up to round-off
    np.testing.assert_array_equal(inverted.faces, faces)


@pytest.mark.parametrize("damage, message", [
    ("inverted", "turned the normals outward"),
    ("inconsistent", "made the face winding consistent"),
    ("degenerate", "dropped 1 degenerate face"),
    ("duplicate", "dropped 1 duplicate face"),
])
def test_repairs_are_logged(damage, message, caplog):
    box = _box()
    vertices, faces = box.vertices.copy(), box.faces.copy()
    if damage == "inverted":
        faces = faces[:, ::-1]
    elif damage == "inconsistent":
        faces[:2] = faces[:2, ::-1]
    elif damage == "degenerate":
        faces = np.vstack([faces, [[0, 0, 1]]])
    elif damage == "duplicate":
        faces = np.vstack([faces, faces[:1]])
    with caplog.at_level(logging.INFO, logger="meshing.surface"):
        surface = load_surface(trimesh.Trimesh(vertices, faces, process=False))
    assert message in caplog.text
    assert surface.is_watertight and surface.volume == pytest.approx(1.0, rel=1e-12)


def _offset_box(offset):
    other = _box()
    other.apply_translation(offset)
    return trimesh.util.concatenate([_box(), other])


@pytest.mark.parametrize("make, fragment", [
    (lambda: trimesh.Trimesh(_box().vertices, _box().faces[1:], process=False),
     "3 open edge(s): the surface has holes"),
    (lambda: _offset_box([1, 1, 0]), "non-manifold edge(s) shared by more than two faces; first is edge"),
    (lambda: _offset_box([1, 1, 1]), "non-manifold vertex(es) where separate sheets touch; first is vertex"),
    (lambda: _offset_box([0.5, 0.3, 0.2]), "pair(s) of faces cut through each other; first are faces"),
])
def test_unrepairable_surfaces_are_refused(make, fragment):
    with pytest.raises(SurfaceError, match=fragment.replace("(", r"\(").replace(")", r"\)")):
        load_surface(make())


def test_nan_coordinates_in_a_file(tmp_path):
    path = tmp_path / "nan.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 nan\nf 1 3 2\nf 1 2 4\nf 2 3 4\nf 1 4 3\n")
    with pytest.raises(SurfaceError, match=r"1 vertex\(es\) have non-finite coordinates, first is vertex 3"):
        load_surface(path)


def test_empty_file(tmp_path):
    path = tmp_path / "empty.stl"
    path.touch()
    with pytest.raises(SurfaceError, match="the file is empty"):
        load_surface(path)


def test_unknown_extension(tmp_path):
    path = tmp_path / "body.xyz"
    path.write_text("0 0 0\n")
    with pytest.raises(SurfaceError, match="unknown surface file extension '.xyz'"):
        load_surface(path)


def test_file_without_triangles(tmp_path):
    path = tmp_path / "text.obj"
    path.write_text("hello\n")
    with pytest.raises(SurfaceError, match="holds no triangles"):
        load_surface(path)


def test_missing_file(tmp_path):
    with pytest.raises(SurfaceError, match="no such file"):
        load_surface(tmp_path / "missing.stl")


def test_errors_are_value_errors():
    assert issubclass(SurfaceError, ValueError)


def test_round_trip_through_stl(tmp_path):
    surface = sphere(0.5).surface(size=0.2)
    path = tmp_path / "ball.stl"
    surface.export(path)
    loaded = load_surface(path)  # STL stores each triangle's corners apart: merging rebuilds the mesh
    assert len(loaded.vertices) == len(surface.vertices)
    assert loaded.volume == pytest.approx(surface.volume, rel=1e-6)  # STL stores float32: ~1e-7 relative


def test_winding_numbers_match_the_exact_sphere():
    surface = sphere(0.5).surface(size=0.05)
    points = np.random.default_rng(0).uniform(-0.6, 0.6, size=(20000, 3))
    radius = np.linalg.norm(points, axis=1)
    winding = winding_numbers(surface.vertices, surface.faces, points)
    assert set(np.unique(winding)) <= {0, 1}
    # Away from the surface band (the polyhedron is inscribed: its faces sit at most r (1 - cos) ~ 2e-3
    # inside the sphere at this size), inside and outside must be exact.
    clear = np.abs(radius - 0.5) > 5e-3
    np.testing.assert_array_equal(winding[clear] == 1, radius[clear] < 0.5)
    np.testing.assert_array_equal(contains_points(surface, points), winding > 0)


# ---------------------------------------------------------------------- self-intersection at exact degeneracies
def test_cubes_crossing_exactly_on_diagonals_are_refused():
    # Every crossing of these two boxes lies at the centre of a square side, on the diagonal that splits it
    # into two triangles: a test that is strict on both triangles misses all of them (and the body meshes
    # to volume 2 instead of the union's 1.875).
    with pytest.raises(SurfaceError, match=r"pair\(s\) of faces cut through each other; first are faces"):
        load_surface(_offset_box([0.5, 0.5, 0.5]))


@pytest.mark.parametrize("offset", [[0.5, 0.5, 0.0], [0.5, 0.0, 0.0], [0.25, 0.5, 0.75]])
def test_other_overlaps_through_edges_and_corners_are_refused(offset):
    with pytest.raises(SurfaceError, match="cut through each other"):
        load_surface(_offset_box(offset))


@pytest.mark.parametrize("offset", [[2.0, 0.0, 0.0], [1.5, 1.5, 1.5], [1.0, 0.5, 0.5]])
def test_separate_or_touching_bodies_pass(offset):
    # Apart, or (the last) one box's side lying against the other's: they touch, they do not cut.
    surface = load_surface(_offset_box(offset))
    assert surface.body_count == 2 and surface.volume == pytest.approx(2.0, rel=1e-12)  # two unit boxes


def test_smooth_closed_shapes_pass():
    from meshing.shapes import torus

    for shape in (sphere(0.5), torus(0.5, 0.15)):
        surface = shape.surface(size=0.05)
        assert load_surface(surface).volume == pytest.approx(surface.volume, rel=1e-12)  # nothing repaired


# ---------------------------------------------------------------------- units
def test_surface_in_millimetres(shared_data, recwarn):
    surface = load_surface(shared_data / "coarse_bunny.obj", units="mm")
    assert len(recwarn) == 0
    # The data README's volume 8.37e5 (3 digits) in mm^3, in m^3.
    assert surface.volume == pytest.approx(8.37e5 * 1e-9, rel=1e-3)
    both = load_surface(shared_data / "coarse_bunny.obj", units="cm", scale=0.5)
    assert both.volume == pytest.approx(8.37e5 * 0.005**3, rel=1e-3)  # units x scale, README's 3 digits


def test_bunny_read_in_metres_warns(shared_data):
    with pytest.warns(UserWarning, match=r"coarse_bunny.obj is 262 m across .*units=\"mm\""):
        load_surface(shared_data / "coarse_bunny.obj")


def test_in_memory_surfaces_are_scaled_but_never_warned_about(recwarn):
    big = _box()
    big.apply_scale(100.0)
    assert load_surface(big).volume == pytest.approx(1e6, rel=1e-12)  # 100 m box, round-off only
    assert load_surface(big, units="mm").volume == pytest.approx(1e-3, rel=1e-12)  # the 100 mm box
    assert len(recwarn) == 0


@pytest.mark.parametrize("options, fragment", [
    ({"units": "ft"}, "units = 'ft' is not a known length unit"),
    ({"scale": -2}, "scale = -2 is not a finite number > 0"),
])
def test_bad_units_are_refused(options, fragment):
    with pytest.raises(ValueError, match=fragment):
        load_surface(_box(), **options)


def test_coordinates_whose_volume_overflows_are_refused(tmp_path):
    path = tmp_path / "huge.obj"
    path.write_text("v 0 0 0\nv 1e150 0 0\nv 0 1e150 0\nv 0 0 1e150\nf 1 3 2\nf 1 2 4\nf 2 3 4\nf 1 4 3\n")
    with pytest.raises(SurfaceError, match=r"coordinates are too large: the largest absolute coordinate is "
                                           r"1e\+150"):
        load_surface(path)
