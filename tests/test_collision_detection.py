"""Vertex-in-tet detection by spatial hashing equals brute force; static obstacles match analytic answers."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from conftest import cube_mesh
from meshing.tolerances import ON_SURFACE
from volspring import HalfSpace
from volspring.collision import (
    CollisionBodies,
    SpatialHash,
    StaticTriangleMesh,
    detect_collisions,
    obstacle_contacts,
)

# A pair whose smallest barycentric weight is within 1e-9 (ON_SURFACE, the detection's own slack) of zero
# is on a tet face to round-off: the hash (adjugate inverse) and the brute force (LU solve) may legitimately
# disagree there, so such pairs are left out of the comparison. Random configurations put almost none there (checked below).
AMBIGUOUS = ON_SURFACE


def brute_force(bodies, x, *, self_collision):
    """Every vertex against every tet, one tet at a time, with np.linalg.solve: ``(inside, ambiguous)`` sets."""
    inside, ambiguous = set(), set()
    for tet in range(bodies.tet_count):
        nodes = bodies.tets[tet]
        corners = x[nodes]
        matrix = (corners[1:] - corners[0]).T
        beta = np.linalg.solve(matrix, (x - corners[0]).T).T
        weights = np.column_stack([1 - beta.sum(axis=1), beta])
        smallest = weights.min(axis=1)
        for vertex in np.flatnonzero(smallest > -AMBIGUOUS):
            if vertex in nodes:
                continue
            if bodies.node_body[vertex] == bodies.tet_body[tet] and not self_collision:
                continue
            (ambiguous if smallest[vertex] < AMBIGUOUS else inside).add((int(vertex), tet))
    return inside, ambiguous


def random_scene(seed, *, fold=0.0):
    """Three boxes, randomly sized, rotated and jittered, all overlapping near the origin.

    ``fold`` is the node jitter in units of the grid spacing; above ~0.3 tets of one body overlap.
    """
    rng = np.random.default_rng(seed)
    meshes, positions = [], []
    for body in range(3):
        size = rng.uniform(0.6, 1.2, 3)
        mesh = cube_mesh((3, 3, 3), tuple(size))
        rotation = Rotation.random(random_state=seed * 10 + body).as_matrix()
        x = (mesh.points - size / 2) @ rotation.T + rng.uniform(-0.3, 0.3, 3)
        x += rng.normal(scale=fold * size.min() / 3, size=x.shape)
        meshes.append(mesh)
        positions.append(x)
    bodies = CollisionBodies(meshes)
    return bodies, bodies.stack_positions(positions)


def contact_set(contacts):
    return set(zip(contacts.vertex.tolist(), contacts.tet.tolist()))


@pytest.mark.parametrize("seed", range(5))
def test_detection_equals_brute_force(seed):
    bodies, x = random_scene(seed, fold=0.05)
    contacts = detect_collisions(bodies, x)
    inside, ambiguous = brute_force(bodies, x, self_collision=False)
    assert len(inside) > 50, "the scene must overlap for the comparison to mean anything"
    assert len(ambiguous) <= 2
    assert contact_set(contacts) - ambiguous == inside
    assert (contacts.vertex_body != contacts.tet_body).all()
    # The weights reproduce the vertex: sum 1, non-negative up to the inside test's slack for a vertex on a
    # face (ON_SURFACE), and sum w_i x_i = p to round-off (1e-12 m on ~1 m).
    assert np.allclose(contacts.barycentric.sum(axis=1), 1.0, atol=1e-12)
    assert (contacts.barycentric >= -ON_SURFACE).all()
    rebuilt = np.einsum("ki,kij->kj", contacts.barycentric, x[bodies.tets[contacts.tet]])
    assert np.allclose(rebuilt, x[contacts.vertex], atol=1e-12)


@pytest.mark.parametrize("seed", range(3))
def test_self_collision_equals_brute_force(seed):
    bodies, x = random_scene(seed, fold=0.4)  # folded enough that each body overlaps itself
    contacts = detect_collisions(bodies, x, self_collision=True)
    inside, ambiguous = brute_force(bodies, x, self_collision=True)
    self_pairs = {(v, t) for v, t in inside if bodies.node_body[v] == bodies.tet_body[t]}
    assert len(self_pairs) > 10, "the folded bodies must self-intersect for the test to mean anything"
    assert contact_set(contacts) - ambiguous == inside
    # Off by default: the same scene reports only the pairs between bodies.
    between = detect_collisions(bodies, x)
    assert contact_set(between) - ambiguous == inside - self_pairs


def test_single_body_without_self_collision_generates_nothing(caplog):
    bodies, x = random_scene(1, fold=0.4)
    one = CollisionBodies(bodies.meshes[:1])
    with caplog.at_level("DEBUG", logger="volspring.collision.spatial_hash"):
        contacts = detect_collisions(one, x[: one.node_count])
    assert contacts.count == 0
    # Not even candidates: the broad phase leaves no vertex and no tet to hash.
    assert "0 active vertices, 0 active tets, 0 candidates" in caplog.text


@pytest.mark.parametrize("table_size", [1, 2, 13])
def test_tiny_hash_table_gives_the_exact_answer(table_size):
    bodies, x = random_scene(7, fold=0.4)
    reference = detect_collisions(bodies, x, self_collision=True)
    tiny = detect_collisions(bodies, x, self_collision=True, table_size=table_size)
    assert reference.count > 50
    np.testing.assert_array_equal(tiny.vertex, reference.vertex)
    np.testing.assert_array_equal(tiny.tet, reference.tet)
    np.testing.assert_array_equal(tiny.barycentric, reference.barycentric)


@pytest.mark.parametrize("table_size", [1, 5, 2_147_483_647])
@pytest.mark.parametrize("rule", ["all", "other", "same"])
def test_spatial_hash_box_pairs_equal_brute_force(table_size, rule):
    rng = np.random.default_rng(3)
    lo_a = rng.uniform(-2, 2, (60, 3))
    hi_a = lo_a + rng.uniform(0, 0.8, (60, 3))
    lo_b = rng.uniform(-2, 2, (80, 3))
    hi_b = lo_b + rng.uniform(0, 0.8, (80, 3))  # boxes up to 2 cells wide: pairs meet in several cells
    group_a, group_b = rng.integers(0, 3, 60), rng.integers(0, 3, 80)
    grid = SpatialHash.build(lo_b, hi_b, cell_size=0.4, table_size=table_size, item_group=group_b)
    query, item = grid.query(lo_a, hi_a, query_group=group_a, rule=rule)
    overlap = ((lo_a[:, None] <= hi_b[None]) & (hi_a[:, None] >= lo_b[None])).all(axis=2)
    same = group_a[:, None] == group_b[None]
    overlap &= {"all": True, "other": ~same, "same": same}[rule]
    pairs = list(zip(query.tolist(), item.tolist()))
    assert len(pairs) == len(set(pairs)), "each pair exactly once"
    assert set(pairs) == set(zip(*np.nonzero(overlap)))


def test_bad_input_is_named():
    bodies, x = random_scene(0)
    with pytest.raises(ValueError, match=r"expected \(" + str(bodies.node_count)):
        detect_collisions(bodies, x[:-1])
    with pytest.raises(ValueError, match="table_size = 0"):
        detect_collisions(bodies, x, table_size=0)
    with pytest.raises(ValueError, match="band = None"):
        StaticTriangleMesh(np.eye(3), [[0, 1, 2]])


# ---------------------------------------------------------------------------------------------- obstacles
def test_half_space():
    rng = np.random.default_rng(0)
    points = rng.uniform(-1, 1, (500, 3))
    normal = np.array([1.0, 2.0, 2.0]) / 3.0
    contacts = obstacle_contacts([HalfSpace(point=(0.1, 0, 0), normal=normal * 5)], points)
    height = (points - [0.1, 0, 0]) @ normal
    np.testing.assert_array_equal(contacts.vertex, np.flatnonzero(height < 0))
    np.testing.assert_allclose(contacts.depth, -height[height < 0], atol=1e-15)  # one dot product of round-off
    np.testing.assert_allclose(contacts.closest @ normal, 0.1 * normal[0], atol=1e-15)


@pytest.mark.parametrize("flip", [False, True])
def test_closed_mesh_box_matches_the_analytic_depth(flip):
    import trimesh

    box = trimesh.creation.box(extents=(2.0, 2.0, 2.0))
    faces = box.faces[:, ::-1] if flip else box.faces  # inward winding is re-wound on construction
    obstacle = StaticTriangleMesh.from_trimesh(trimesh.Trimesh(box.vertices, faces, process=False))
    assert obstacle.closed
    rng = np.random.default_rng(1)
    points = rng.uniform(-1.4, 1.4, (2000, 3))  # many outside near edges and corners: the pseudo-normal cases
    contacts = obstacle_contacts([obstacle], points)
    inside = np.flatnonzero((np.abs(points) < 1).all(axis=1))
    np.testing.assert_array_equal(contacts.vertex, inside)
    p = points[inside]
    axis = np.abs(p).argmax(axis=1)
    np.testing.assert_allclose(contacts.depth, 1 - np.abs(p).max(axis=1), atol=1e-12)  # round-off on unit sizes
    expected = np.zeros_like(p)
    expected[np.arange(len(p)), axis] = np.sign(p[np.arange(len(p)), axis])
    np.testing.assert_allclose(contacts.direction, expected, atol=1e-12)


def test_open_mesh_bowl_band_and_rim():
    import trimesh

    box = trimesh.creation.box(extents=(2.0, 2.0, 2.0))
    keep = box.face_normals[:, 2] < 0.5  # drop the lid: an open box, a square bowl
    bowl = StaticTriangleMesh(box.vertices, box.faces[keep][:, ::-1], band=0.2)  # normals into the cavity
    assert not bowl.closed
    points = np.array([
        [0.0, 0.0, -1.05],   # 0.05 into the floor: contact, pushed up
        [1.05, 0.2, 0.0],    # 0.05 into a wall: contact, pushed in (-x)
        [0.3, 0.3, -1.5],    # below the floor by more than the band: none
        [0.5, 0.5, 0.0],     # in the cavity: none
        [0.0, 0.0, 1.3],     # above the opening, nearest the rim: none
        [1.05, 0.0, 1.1],    # outside, beside the rim: none
    ])
    contacts = obstacle_contacts([bowl], points)
    assert contacts.vertex.tolist() == [0, 1]
    np.testing.assert_allclose(contacts.depth, [0.05, 0.05], atol=1e-12)
    np.testing.assert_allclose(contacts.direction, [[0, 0, 1], [-1, 0, 0]], atol=1e-12)


@pytest.mark.parametrize("table_size", [1, 5, 2_147_483_647])  # 1 and 5 are below the grid's cells: the hash
@pytest.mark.parametrize("rule", ["all", "other", "same"])
@pytest.mark.parametrize("points", [False, True])
def test_dense_grid_pairs_equal_the_hash(table_size, rule, points):
    from volspring.collision.spatial_hash import box_pairs

    rng = np.random.default_rng(4)
    lo_a = rng.uniform(-1, 1, (200, 3))
    hi_a = lo_a + rng.uniform(0, 0.8, (200, 3))
    lo_b = rng.uniform(-1, 1, (300, 3))
    hi_b = lo_b if points else lo_b + rng.uniform(0, 0.8, (300, 3))  # boxes span several cells, points one
    group_a, group_b = rng.integers(0, 3, 200), rng.integers(0, 3, 300)
    query, item = box_pairs(lo_b, hi_b, lo_a, hi_a, cell_size=0.4, table_size=table_size, item_group=group_b,
                            query_group=group_a, rule=rule)
    grid = SpatialHash.build(lo_b, hi_b, cell_size=0.4, table_size=table_size, item_group=group_b)
    expected = grid.query(lo_a, hi_a, query_group=group_a, rule=rule)
    assert len(expected[0]) > 50, "the boxes must overlap for the comparison to mean anything"
    assert sorted(zip(query.tolist(), item.tolist())) == sorted(zip(*(e.tolist() for e in expected)))
    if rule == "same":  # the same order too: the depths keep the first of equally deep surface hits
        np.testing.assert_array_equal(query, expected[0])
        np.testing.assert_array_equal(item, expected[1])


def test_dense_grid_falls_back_to_the_hash_for_scattered_items(monkeypatch):
    from volspring.collision import spatial_hash

    # Two points 10^4 cells apart: a dense grid would need 10^12 cells, so the hash answers.
    items = np.array([[0.0, 0.0, 0.0], [1e3, 1e3, 1e3]])
    built, build = [], SpatialHash.build.__func__
    monkeypatch.setattr(spatial_hash.SpatialHash, "build",
                        classmethod(lambda cls, *a, **k: built.append(1) or build(cls, *a, **k)))
    query, item = spatial_hash.box_pairs(items, items, items - 0.05, items + 0.05, cell_size=0.1)
    assert built and query.tolist() == [0, 1] and item.tolist() == [0, 1]
