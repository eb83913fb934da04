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
        surface = load_surface(shared_data / "coarse_bunny.obj")
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
