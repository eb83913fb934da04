"""The Delaunay backend's enclosing band: the tets hold a finer surface of the same shape, for little extra volume.

The seed's mesh carries a thin sheet above the surface, so that a render surface finer than the tets' boundary
(whose facets are chords of the curved shape) still lies inside them. The finer surface is sampled four times
finer than the surface the tets were built on:

* built-in shapes: ``shape.surface(size=size / 4)``, whose vertices lie on the exact shape;
* the bunny: its OBJ is the only description of the shape, a coarse polyhedron whose vertices sample the
  scanned bunny. Its shape is taken to be the OBJ's PN-triangle surface (Vlachos et al. 2001, the curved
  patches renderers tessellate a coarse mesh into: it interpolates the OBJ's vertices and normals and bulges
  out of the flat facets where the bunny is convex, as the scan did). The tets are built on that surface
  sampled at 2 divisions per OBJ edge, the finer surface samples it at 8: both lie exactly on one smooth
  shape, as for the built-in shapes. It is built from positions and trimesh's normals only, independently of
  the band's own curvature estimate.

Point location is a barycentric test written here (candidate tets by centroid distance, every miss then
checked against every tet), not :mod:`meshing.anchoring`.
"""

import math

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

from meshing.geometry import signed_tet_volumes
from meshing.quality import radius_ratios
from meshing.shapes import parse_shape
from meshing.surface import load_surface
from meshing.tetrahedralize import excess_volume_fraction, tetrahedralize

# Tolerance of the inside test in barycentric units: round-off of a 3x3 solve is ~1e-16 times the tet's
# condition number (below 1e4 for the tets kept here), so 1e-9 only absorbs points on a face, not real misses.
BARYCENTRIC_SLACK = 1e-9
# The acceptance figures of the issue: 99.9% of a four-times-finer surface inside, band volume under 5%.
INSIDE_FRACTION = 0.999
EXCESS_VOLUME = 0.05
# Worst radius ratio: the backend keeps interior slivers (below its 0.05 peeling threshold) to avoid voids.
# Without the band the worst tet of these meshes measured 0.004 (torus), 0.006 (cylinder), 0.015-0.024 (the
# others); with it 0.011-0.021 [measured]. 0.01 asks the band to stay clear of the worst seen without it.
WORST_RADIUS_RATIO = 0.01
# Curved built-in shapes at sizes that give 4-6 edges per radius of curvature, the coarsest the band is
# asked to keep under 5% (its volume goes as (size / radius)^2; see the module docstring of the backend).
CURVED = [
    ("sphere:0.5", 0.1),
    ("torus:0.5,0.15", 0.04),
    ("capsule:0.1,0.4", 0.025),
    ("cylinder:0.2,1", 0.05),
    ("ellipsoid:0.3,0.2,0.1", 0.025),
]
BUNNY_SIZE = 0.015  # about the OBJ's median edge (12 mm after scaling to metres)


def inside_tets(points, tets, queries, *, candidates=16, pairs_per_chunk=2_000_000):
    """(k,) bool -- whether each query point lies in some tet (every barycentric weight >= -slack)."""
    corners = points[tets]  # (m, 4, 3)
    inverse = np.linalg.inv(np.swapaxes(corners[:, 1:] - corners[:, :1], 1, 2))  # (m, 3, 3)

    def holds(point_index, tet_index):  # broadcasting index arrays -> bool of the same shape
        local = np.einsum("...ij,...j->...i", inverse[tet_index], queries[point_index] - corners[tet_index, 0])
        return np.minimum(1 - local.sum(axis=-1), local.min(axis=-1)) >= -BARYCENTRIC_SLACK

    _, nearest = cKDTree(corners.mean(axis=1)).query(queries, k=min(candidates, len(tets)))
    found = holds(np.arange(len(queries))[:, None], nearest).any(axis=1)
    # The candidates are a shortcut: a point none of them holds is checked against every tet.
    missed = np.flatnonzero(~found)
    step = max(1, pairs_per_chunk // len(tets))
    for start in range(0, len(missed), step):  # chunks of points x all tets, not a loop over points
        part = missed[start:start + step]
        found[part] = holds(part[:, None], np.arange(len(tets))[None, :]).any(axis=1)
    return found


def pn_refined(surface, parts=4):
    """The PN-triangle refinement of ``surface`` (trimesh.Trimesh): every triangle's cubic Bezier patch (from its
    corners and trimesh's vertex normals) sampled on a grid of ``parts`` divisions per edge, welded."""
    x = surface.vertices[surface.faces]  # (f, 3, 3)
    n = surface.vertex_normals[surface.faces]

    def control(i, j):  # the edge control point near corner i towards corner j
        w = np.einsum("fj,fj->f", x[:, j] - x[:, i], n[:, i])[:, None]
        return (2 * x[:, i] + x[:, j] - w * n[:, i]) / 3

    b = {(3, 0, 0): x[:, 0], (0, 3, 0): x[:, 1], (0, 0, 3): x[:, 2],
         (2, 1, 0): control(0, 1), (1, 2, 0): control(1, 0), (0, 2, 1): control(1, 2),
         (0, 1, 2): control(2, 1), (1, 0, 2): control(2, 0), (2, 0, 1): control(0, 2)}
    edge_mean = sum(b[k] for k in b if 3 not in k) / 6
    b[(1, 1, 1)] = edge_mean + (edge_mean - (x[:, 0] + x[:, 1] + x[:, 2]) / 3) / 2
    index = {}
    for i in range(parts + 1):
        for j in range(parts + 1 - i):
            index[i, j] = len(index)
    grid = np.array([(i, j, parts - i - j) for i, j in index], dtype=np.float64) / parts
    samples = 0
    for (i, j, k), point in b.items():  # the ten Bernstein terms, each over every face and grid point at once
        weight = math.factorial(3) / (math.factorial(i) * math.factorial(j) * math.factorial(k))
        weight = weight * grid[:, 0] ** i * grid[:, 1] ** j * grid[:, 2] ** k  # (g,)
        samples = samples + weight[None, :, None] * point[:, None, :]
    # The grid's triangles, wound as the face (corner 0 at (1, 0, 0), 1 at (0, 1, 0), 2 at (0, 0, 1)).
    local = [(index[i, j], index[i - 1, j + 1], index[i - 1, j]) for i, j in index if i > 0]
    local += [(index[i, j], index[i, j + 1], index[i - 1, j + 1]) for i, j in index if i > 0 and i + j < parts]
    local = np.array(local)
    triangles = (np.arange(len(x))[:, None, None] * len(grid) + local[None]).reshape(-1, 3)
    refined = trimesh.Trimesh(samples.reshape(-1, 3), triangles, process=False)
    refined.merge_vertices()  # the patches' shared edge curves coincide up to round-off
    return refined


@pytest.fixture(scope="module")
def bunny(shared_data):
    surface = load_surface(shared_data / "coarse_bunny.obj", scale=1.0)  # the file's own units
    surface.apply_scale(0.001)  # about 160 units across -> 0.16 m
    return surface


def finer_surface(spec, size):
    return parse_shape(spec).surface(size=size / 4).vertices


def finer_bunny(bunny):
    """(the surface to tetrahedralize, the surface four times finer): the PN surface of the OBJ sampled at 2
    and at 8 divisions per OBJ edge, so both lie exactly on one smooth shape, as the built-in shapes' do."""
    return pn_refined(bunny, parts=2), pn_refined(bunny, parts=8)


@pytest.mark.parametrize("spec, size", CURVED)
def test_a_finer_surface_of_a_curved_shape_lies_inside_the_tets(spec, size):
    shape = parse_shape(spec)
    fine = shape.surface(size=size / 4).vertices
    mesh = tetrahedralize(shape, size=size, method="delaunay", seed=0)
    inside = inside_tets(mesh.points, mesh.tets, fine)
    assert inside.mean() >= INSIDE_FRACTION, f"{(~inside).sum()} of {len(fine)} finer-surface vertices outside"
    excess = excess_volume_fraction(mesh, shape)
    # The band adds volume (it must lie above the chords); under the 5% at these sizes.
    assert 0 < excess < EXCESS_VOLUME, excess
    assert (signed_tet_volumes(mesh.points, mesh.tets) > 0).all()
    assert radius_ratios(mesh).min() >= WORST_RADIUS_RATIO


@pytest.mark.parametrize("spec, size", CURVED[:3])
def test_without_the_band_the_finer_surface_lies_outside(spec, size):
    # The negative control: the old boundary through the surface vertices leaves the finer surface outside
    # (measured 0% on the sphere and torus, 0.5% on the capsule); so the test above can fail.
    shape = parse_shape(spec)
    fine = shape.surface(size=size / 4).vertices[::40]  # a fortieth shows it; every miss is checked on all tets
    mesh = tetrahedralize(shape, size=size, method="delaunay", seed=0, enclosing_band=False)
    assert inside_tets(mesh.points, mesh.tets, fine).mean() < 0.5
    assert excess_volume_fraction(mesh, shape) < 0


def test_flat_shapes_keep_their_faces():
    # No sag on flat facets: the band moves nothing on a box (its volume stays exact up to the peeled slivers
    # that test_tetrahedralize bounds) and leaves the mesh as it was without the band.
    shape = parse_shape("box:0.2,0.05,0.05")
    with_band = tetrahedralize(shape, size=0.05, method="delaunay", seed=3)
    without = tetrahedralize(shape, size=0.05, method="delaunay", seed=3, enclosing_band=False)
    np.testing.assert_array_equal(with_band.points, without.points)
    np.testing.assert_array_equal(with_band.tets, without.tets)


def test_the_band_is_deterministic():
    shape = parse_shape("torus:0.5,0.15")
    first, again = (tetrahedralize(shape, size=0.08, method="delaunay", seed=5) for _ in range(2))
    np.testing.assert_array_equal(first.points, again.points)
    np.testing.assert_array_equal(first.tets, again.tets)


def test_splitting_edges_keeps_the_surface():
    # The recovery splits any set of edges, so a facet may have one, two or three split edges: the result must stay
    # closed and consistently wound, with the same shape (midpoints on the chords) and the old vertices first.
    from meshing.tetrahedralize_delaunay import _split_edges

    surface = parse_shape("sphere:0.5").surface(size=0.1)
    split = np.random.default_rng(1).random(len(surface.edges_unique)) < 0.3
    refined = _split_edges(surface, split)
    assert refined.is_watertight and refined.is_winding_consistent
    assert len(refined.faces) == len(surface.faces) + 2 * split.sum()
    np.testing.assert_array_equal(refined.vertices[:len(surface.vertices)], surface.vertices)
    assert refined.volume == pytest.approx(surface.volume, rel=1e-12)
    assert refined.area == pytest.approx(surface.area, rel=1e-12)


def test_a_finer_bunny_lies_inside_the_tets(bunny):
    # At the bunny's folds a quadratic sag model missed the PN bulge and Delaunay flipped edges under it (once
    # 134 outside); the band now takes PN patches' heights as the sag and splits the flipped edges under which the
    # modelled surface pokes out [measured 27 of 32002 outside (99.92%) at +4.50%, worst radius ratio 0.018].
    coarse, fine = finer_bunny(bunny)
    # The bunny is a smooth scan: no edge is a crease (feature_angle 180), whatever its facets' angles.
    mesh = tetrahedralize(coarse, size=BUNNY_SIZE, method="delaunay", seed=0, feature_angle=180.0,
                          enclosing_band=True)
    assert excess_volume_fraction(mesh, fine) < EXCESS_VOLUME
    inside = inside_tets(mesh.points, mesh.tets, fine.vertices)
    assert inside.mean() >= INSIDE_FRACTION, f"{(~inside).sum()} of {len(inside)} finer-bunny vertices outside"


def test_the_bunny_band_stays_thin(bunny):
    # The band brings the finer bunny from 31% to over 99.5% inside for under 5% of volume, with tets no worse
    # than the shapes' [measured 30.98% without, 99.92% and +4.50% with].
    coarse, fine = finer_bunny(bunny)
    mesh = tetrahedralize(coarse, size=BUNNY_SIZE, method="delaunay", seed=0, feature_angle=180.0,
                          enclosing_band=True)
    assert 0 < excess_volume_fraction(mesh, fine) < EXCESS_VOLUME
    assert inside_tets(mesh.points, mesh.tets, fine.vertices).mean() >= 0.995
    assert radius_ratios(mesh).min() >= WORST_RADIUS_RATIO


@pytest.mark.parametrize("feature_angle", [40.0, 180.0])
def test_the_band_on_the_raw_bunny_keeps_its_vertices_inside(bunny, feature_angle):
    # At the raw OBJ's folds (edges whose normals differ by 100-150 deg) the sag-weighted direction once moved
    # a vertex into some of its facets' planes, so its fan folded over its old position: 18 of the 502 vertices
    # were outside the tets (6 at feature_angle 180). The vertex now takes the shortest move lifting every
    # one of its triangles by its sag [measured 0 outside at both angles].
    mesh = tetrahedralize(bunny, size=BUNNY_SIZE, method="delaunay", seed=0, feature_angle=feature_angle,
                          enclosing_band=True)
    inside = inside_tets(mesh.points, mesh.tets, bunny.vertices)
    assert inside.all(), f"{(~inside).sum()} of the OBJ's {len(inside)} vertices outside the tets"


@pytest.mark.xfail(strict=True, reason="measured +11.1% volume (+15.4% at feature_angle 180) with the band on the raw "
                   "coarse bunny, whose PN surface is itself +3.0% over the OBJ; the offset surface still holds only "
                   "95.8% of that PN surface (100% at 180): why the band is off by default for loaded surfaces; open")
def test_the_band_on_the_raw_bunny_stays_thin(bunny):
    mesh = tetrahedralize(bunny, size=BUNNY_SIZE, method="delaunay", seed=0, enclosing_band=True)
    assert excess_volume_fraction(mesh, bunny) < EXCESS_VOLUME
