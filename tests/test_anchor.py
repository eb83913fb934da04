"""Barycentric anchoring of a render surface: exact at rest, affine-exact, every vertex bound, outside ones reported."""

import dataclasses
import logging

import numpy as np
import pytest
import trimesh
from conftest import cube_mesh
from scipy.spatial import Delaunay

import meshing.anchoring as anchor_module
from meshing.anchoring import Anchor, anchor
from meshing import TetMesh

# Tolerances. 1e-10 is the acceptance figure of issue 2 for rest and affine reproduction; the measured errors are
# round-off, 1e-13 or below on these meshes (coordinates up to about 160, weights down to about -10).
EXACT = 1e-10
# Weights sum to 1 by construction (w0 = 1 - w1 - w2 - w3); 1e-12 allows the round-off of that difference.
SUM_TO_ONE = 1e-12


def jittered_mesh(cells: int = 5, seed: int = 3) -> TetMesh:
    """Delaunay of a jittered lattice in the unit box: irregular tets, unlike the Kuhn-split cube."""
    rng = np.random.default_rng(seed)
    axis = np.linspace(0.0, 1.0, cells + 1)
    points = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), -1).reshape(-1, 3)
    points += ((points > 0) & (points < 1)) * rng.uniform(-0.25, 0.25, points.shape) / cells
    tets = Delaunay(points).simplices
    corners = points[tets]
    volumes = np.abs(np.einsum("ij,ij->i", corners[:, 1] - corners[:, 0],
                               np.cross(corners[:, 2] - corners[:, 0], corners[:, 3] - corners[:, 0])))
    # Coplanar points on the box's faces give flat tets there; drop those below 1e-6 of the mean volume.
    return TetMesh.compact(points, tets[volumes > 1e-6 * volumes.mean()])


def brute_force_min_weight(mesh: TetMesh, points) -> np.ndarray:
    """(p,) the largest over all tets of the smallest barycentric weight: >= 0 exactly when inside some tet."""
    corners = mesh.points[mesh.tets]
    frame = np.stack([corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0], corners[:, 3] - corners[:, 0]], -1)
    beta = np.einsum("mij,pmj->pmi", np.linalg.inv(frame), points[:, None, :] - corners[None, :, 0])
    weights = np.concatenate([1.0 - beta.sum(axis=2, keepdims=True), beta], axis=2)
    return weights.min(axis=2).max(axis=1)


def distance_to_tets(mesh: TetMesh, points, tets) -> np.ndarray:
    """(q,) distance from points[i] (q, 3) to tet tets[i] (q,), outside it, by trimesh's closest point on its faces."""
    faces = mesh.points[mesh.tets[tets][:, [[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]]]].reshape(-1, 3, 3)
    repeated = np.repeat(points, 4, axis=0)
    distance = np.linalg.norm(trimesh.triangles.closest_point(faces, repeated) - repeated, axis=1)
    return distance.reshape(-1, 4).min(axis=1)


def random_affine(seed: int):
    rng = np.random.default_rng(seed)
    return np.eye(3) + 0.5 * rng.normal(size=(3, 3)), rng.normal(size=3)


MESHES = {"cube 3x3x3": lambda: cube_mesh((3, 3, 3)), "jittered Delaunay": jittered_mesh}


@pytest.fixture(scope="module")
def bunny(shared_data):
    surface = trimesh.load(shared_data / "coarse_bunny.obj", process=True)
    surface.merge_vertices(merge_tex=True, merge_norm=True)
    return TetMesh.read(shared_data / "coarse_bunny.mesh", scale=1.0), surface  # its own units, as the surface


@pytest.mark.parametrize("name", sorted(MESHES))
def test_points_inside_are_found_in_a_containing_tet(name):
    mesh = MESHES[name]()
    points = np.random.default_rng(0).uniform(0.0, 1.0, (2000, 3))
    bound = anchor(mesh, points)
    assert bound.outside_count == 0 and bound.max_outside_distance == 0.0
    # The chosen tet contains the point: weights >= 0 up to round-off (the default tolerance, 1e-9).
    assert bound.weights.min() >= -1e-9
    assert np.array_equal(bound.nodes, mesh.tets[bound.tet_index])
    np.testing.assert_allclose(bound.weights.sum(axis=1), 1.0, atol=SUM_TO_ONE)
    np.testing.assert_allclose(bound.deform(mesh.points), points, atol=EXACT)


@pytest.mark.parametrize("name", sorted(MESHES))
def test_grid_search_alone_finds_the_same_containment(name, monkeypatch):
    # With one nearest centroid tried first, most points fall through to the exhaustive grid search.
    mesh = MESHES[name]()
    points = np.random.default_rng(1).uniform(-0.05, 1.05, (1500, 3))
    monkeypatch.setattr(anchor_module, "NEAREST_CENTROIDS", 1)
    bound = anchor(mesh, points)
    inside = brute_force_min_weight(mesh, points) >= -1e-9
    assert np.array_equal(~bound.outside, inside)
    assert (bound.weights[inside].min(axis=1) >= -1e-9).all()


@pytest.mark.parametrize("name", sorted(MESHES))
def test_surface_follows_any_affine_map_inside_and_outside(name):
    mesh = MESHES[name]()
    points = np.random.default_rng(2).uniform(-0.3, 1.3, (3000, 3))  # about half of them outside the box
    bound = anchor(mesh, points)
    assert 0 < bound.outside_count < len(points)
    for seed in range(3):
        matrix, shift = random_affine(seed)
        np.testing.assert_allclose(bound.deform(mesh.points @ matrix.T + shift), points @ matrix.T + shift, atol=EXACT)


def test_outside_vertices_take_the_nearest_tet_and_their_distance():
    mesh = cube_mesh((2, 2, 2))
    far = np.array([[5.0, 0.5, 0.5], [-2.0, -2.0, 0.5], [0.5, 0.5, 1.0 + 1e-3], [3.0, 3.0, 3.0]])
    bound = anchor(mesh, far)
    assert bound.outside.all() and bound.outside_count == 4
    # Distances to the unit box, exact: 4; 2 sqrt 2; 1e-3; 2 sqrt 3 (1e-12: round-off of the point-triangle test).
    np.testing.assert_allclose(bound.outside_distance, [4.0, 2 * np.sqrt(2), 1e-3, 2 * np.sqrt(3)], rtol=1e-12)
    assert bound.max_outside_distance == pytest.approx(4.0, rel=1e-12)
    # The chosen tet is a nearest one: its distance is the vertex's distance, and no tet is nearer (brute force).
    to_all = distance_to_tets(mesh, np.repeat(far, mesh.tet_count, axis=0), np.tile(np.arange(mesh.tet_count), 4))
    to_all = to_all.reshape(4, mesh.tet_count)
    np.testing.assert_allclose(distance_to_tets(mesh, far, bound.tet_index), bound.outside_distance, rtol=1e-12)
    np.testing.assert_allclose(to_all.min(axis=1), bound.outside_distance, rtol=1e-12)
    # Weights are extrapolated (negative) but still sum to 1 and reproduce the vertex, also under an affine map.
    assert bound.min_weight < -1.0
    np.testing.assert_allclose(bound.weights.sum(axis=1), 1.0, atol=SUM_TO_ONE)
    matrix, shift = random_affine(7)
    np.testing.assert_allclose(bound.deform(mesh.points @ matrix.T + shift), far @ matrix.T + shift, atol=EXACT)


def test_far_outside_vertices_are_logged_and_can_be_refused(caplog):
    mesh = cube_mesh((2, 2, 2))
    with caplog.at_level(logging.INFO, logger="meshing.anchoring"):
        anchor(mesh, np.array([[0.5, 0.5, 0.5], [5.0, 0.5, 0.5]]))
    assert any(r.levelno == logging.WARNING and "1 of 2 surface vertices lie outside" in r.message
               for r in caplog.records)
    with pytest.raises(ValueError, match=r"1 surface vertices lie farther than max_distance = 1.0 .*up to 4"):
        anchor(mesh, np.array([[0.5, 0.5, 0.5], [5.0, 0.5, 0.5]]), max_distance=1.0)
    assert anchor(mesh, np.array([[1.5, 0.5, 0.5]]), max_distance=1.0).outside_count == 1


def test_finer_render_surface_on_a_cube():
    mesh = cube_mesh((3, 3, 3))
    box = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    box.apply_translation((0.5, 0.5, 0.5))
    box = box.subdivide().subdivide().subdivide()  # 386 vertices on the cube's boundary (the mesh has 56)
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=0.45)  # 642 vertices inside
    sphere.apply_translation((0.5, 0.5, 0.5))
    matrix, shift = random_affine(3)
    for surface in (box, sphere):
        bound = anchor(mesh, surface)
        assert bound.point_count == len(surface.vertices) > 4 * len(mesh.boundary_nodes)
        # On the boundary counts as inside: the default tolerance absorbs round-off of vertices on faces.
        assert bound.outside_count == 0
        assert np.array_equal(bound.faces, surface.faces)
        np.testing.assert_allclose(bound.deform(mesh.points), surface.vertices, atol=EXACT)
        np.testing.assert_allclose(bound.deform(mesh.points @ matrix.T + shift), surface.vertices @ matrix.T + shift,
                                   atol=EXACT)


def test_real_bunny_surface_anchors_into_its_tet_mesh(bunny, caplog):
    mesh, surface = bunny
    assert len(surface.vertices) == 502  # the merged surface of tests/data/README.md
    with caplog.at_level(logging.INFO, logger="meshing.anchoring"):
        bound = anchor(mesh, surface)
    assert bound.point_count == 502 and (bound.tet_index >= 0).all()
    # The data README: about 60% of the vertices a hair outside, barycentric coordinates down to about -0.016.
    # Measured here: 293 outside (58%), min weight -0.020 (the nearest tet, not the same tet as the other tool).
    assert 0.5 < bound.outside_count / bound.point_count < 0.7
    assert -0.05 < bound.min_weight < -0.005
    # "A hair": under 0.1% of the bunny's size (about 160 units) -- measured 0.109 units.
    assert bound.max_outside_distance < 1e-3 * np.ptp(mesh.points, axis=0).max()
    assert f"{bound.outside_count} of 502 surface vertices lie outside every tet" in caplog.text
    # Outside means outside: no tet holds those vertices (brute force over all tets), and every other does lie in one.
    inside = brute_force_min_weight(mesh, surface.vertices) >= -1e-9
    assert np.array_equal(~bound.outside, inside)
    # Their distance is the distance to the tet mesh's boundary, checked with trimesh's closest point on every face.
    outside_points = surface.vertices[bound.outside]
    triangles = mesh.points[mesh.boundary_faces]
    closest = trimesh.triangles.closest_point(
        np.repeat(triangles[None], len(outside_points), axis=0).reshape(-1, 3, 3),
        np.repeat(outside_points, len(triangles), axis=0),
    )
    distance = np.linalg.norm(closest.reshape(len(outside_points), -1, 3) - outside_points[:, None], axis=2).min(axis=1)
    np.testing.assert_allclose(bound.outside_distance[bound.outside], distance, atol=1e-9)  # round-off at 160 units
    # And the tet each is bound to is at that distance: a nearest tet.
    np.testing.assert_allclose(distance_to_tets(mesh, outside_points, bound.tet_index[bound.outside]), distance,
                               atol=1e-9)
    np.testing.assert_allclose(bound.deform(mesh.points), surface.vertices, atol=EXACT)
    for seed in range(3):
        matrix, shift = random_affine(seed)
        shift *= 100.0  # a translation of the bunny's own size
        np.testing.assert_allclose(bound.deform(mesh.points @ matrix.T + shift), surface.vertices @ matrix.T + shift,
                                   atol=EXACT)


def test_batched_deform_and_sparse_matrix_agree_with_single_frames():
    mesh = jittered_mesh()
    points = np.random.default_rng(4).uniform(-0.1, 1.1, (300, 3))
    bound = anchor(mesh, points)
    frames = np.stack([mesh.points @ random_affine(seed)[0].T for seed in range(4)])
    batched = bound.deform(frames)
    assert batched.shape == (4, 300, 3)
    for frame, result in zip(frames, batched):
        # 1e-13: the same products summed in a possibly different order.
        np.testing.assert_allclose(result, bound.deform(frame), atol=1e-13)
        np.testing.assert_allclose(bound.matrix @ frame, result, atol=1e-13)
    assert bound.matrix.shape == (300, mesh.node_count)


def test_anchor_is_immutable():
    bound = anchor(cube_mesh(), np.array([[0.2, 0.3, 0.4]]))
    assert isinstance(bound, Anchor)
    with pytest.raises(dataclasses.FrozenInstanceError):
        bound.weights = np.zeros((1, 4))
    with pytest.raises(ValueError):
        bound.weights[0, 0] = 1.0


@pytest.mark.parametrize(
    ("surface", "options", "message"),
    [
        (np.zeros((4, 2)), {}, r"surface vertices must have shape \(p, 3\) with p > 0, got \(4, 2\)"),
        (np.zeros((0, 3)), {}, r"surface vertices must have shape \(p, 3\) with p > 0, got \(0, 3\)"),
        (np.array([[0.5, 0.5, 0.5]]), {"max_distance": -1.0}, "max_distance = -1.0 is not >= 0"),
        (np.array([[0.5, 0.5, np.nan]]), {}, "1 surface vertices have non-finite coordinates, first is vertex 0"),
        (np.array([[0.5, 0.5, 0.5]]), {"tolerance": -1.0}, "tolerance = -1.0 is not >= 0"),
        (trimesh.Scene(), {}, "surface must be a trimesh.Trimesh or a \\(p, 3\\) array of vertices, got Scene"),
    ],
)
def test_bad_input_is_refused(surface, options, message):
    with pytest.raises(ValueError, match=message):
        anchor(cube_mesh(), surface, **options)


def test_deform_checks_the_node_array_shape():
    mesh = cube_mesh()
    bound = anchor(mesh, np.array([[0.2, 0.3, 0.4]]))
    with pytest.raises(ValueError, match=rf"x must have shape \(\.\.\., {mesh.node_count}, 3\).*got \(5, 3\)"):
        bound.deform(np.zeros((5, 3)))

