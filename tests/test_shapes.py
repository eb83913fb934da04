"""Built-in shapes: spec parsing, exact volumes, closed outward surfaces on the exact shape."""

import math

import numpy as np
import pytest

from meshing.shapes import SHAPE_NAMES, Shape, box, cylinder, ellipsoid, parse_shape, sphere, torus

SPECS = ["box:1,0.1,0.1", "sphere:0.5", "cylinder:0.2,1", "torus:0.5,0.15", "ellipsoid:0.3,0.2,0.1"]


def test_exact_volumes_from_formulas():
    # Closed-form volumes; 1e-15 relative is float round-off of a few products.
    assert box(1, 0.1, 0.1).volume == pytest.approx(0.01, rel=1e-15)
    assert sphere(0.5).volume == pytest.approx(4 / 3 * math.pi * 0.125, rel=1e-15)
    assert cylinder(0.2, 1).volume == pytest.approx(math.pi * 0.04, rel=1e-15)
    assert torus(0.5, 0.15).volume == pytest.approx(2 * math.pi**2 * 0.5 * 0.15**2, rel=1e-15)
    assert ellipsoid(0.3, 0.2, 0.1).volume == pytest.approx(4 / 3 * math.pi * 0.006, rel=1e-15)


@pytest.mark.parametrize("spec", SPECS)
def test_parse_round_trip(spec):
    shape = parse_shape(spec)
    assert isinstance(shape, Shape) and shape.name in SHAPE_NAMES
    assert parse_shape(shape.spec()) == shape


@pytest.mark.parametrize("spec", SPECS)
def test_surface_is_closed_outward_and_converges(spec):
    shape = parse_shape(spec)
    errors = []
    for size in (0.1, 0.05):
        surface = shape.surface(size=size)
        assert surface.is_watertight and surface.is_winding_consistent
        assert surface.volume > 0
        # Edges are about `size`: grid diagonals are sqrt(2) size, the torus's outer ones ~1.4 size.
        assert surface.edges_unique_length.max() <= 1.5 * size
        # The surface never leaves the exact bounding box (1e-12: round-off of cos/sin on the rim).
        low, high = shape.bounds
        assert (surface.vertices >= low - 1e-12).all() and (surface.vertices <= high + 1e-12).all()
        errors.append(abs(surface.volume - shape.volume) / shape.volume)
    if shape.name == "box":
        assert errors[-1] < 1e-14  # flat faces: exact up to round-off
    else:
        # Inscribed polyhedra lose volume as O(size^2): halving the size must at least halve the error.
        assert errors[1] < 0.5 * errors[0]


def test_curved_vertices_lie_on_the_shape():
    # Vertices are placed on the exact surface: 1e-12 is round-off at unit scale.
    vertices = sphere(0.5).surface(size=0.1).vertices
    assert np.allclose(np.linalg.norm(vertices, axis=1), 0.5, atol=1e-12)
    vertices = torus(0.5, 0.15).surface(size=0.1).vertices
    tube = np.hypot(np.hypot(vertices[:, 0], vertices[:, 1]) - 0.5, vertices[:, 2])
    assert np.allclose(tube, 0.15, atol=1e-12)


@pytest.mark.parametrize("spec, fragment", [
    ("cube:1", "unknown shape 'cube'"),
    ("box:1,2", "box takes 3 dimension(s)"),
    ("sphere:1,2", "sphere takes 1 dimension(s)"),
    ("sphere:-1", "r = -1.0 is not a positive"),
    ("cylinder:0.2,0", "length = 0.0 is not a positive"),
    ("sphere:nan", "r = nan"),
    ("sphere:abc", "must be numbers"),
    ("sphere", "gives no dimensions"),
    ("torus:0.1,0.2", "must be < major radius"),
])
def test_bad_specs_are_refused(spec, fragment):
    with pytest.raises(ValueError, match=fragment.replace("(", r"\(").replace(")", r"\)")):
        parse_shape(spec)


def test_bad_size_for_a_surface():
    with pytest.raises(ValueError, match="size = 0.0"):
        sphere(1).surface(size=0.0)
