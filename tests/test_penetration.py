"""Consistent penetration depths (Heidelberger et al. 2004) against analytic answers, and the naive method's failure."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from conftest import cube_mesh
from meshing import TetMesh
from volspring.collision import (
    PenetrationDepths,
    CollisionBodies,
    closest_surface_depths,
    consistent_penetration_depths,
    detect_collisions,
)

# Against a flat face whose vertex normals are exact (every triangle around them is in that face), the
# method is exact: each border term (x_i - p).n is the height of p below the plane and each propagation
# term (p_j - p).r + d_j telescopes to the same. What remains is round-off on unit-sized coordinates.
ROUND_OFF = 1e-12


def rows(depths, keep):
    """The same result restricted to the rows ``keep`` ((c,) bool), with their intersection edges."""
    fields = ("vertex", "vertex_body", "other_body", "tet", "barycentric", "depth", "direction", "level", "fallback")
    hits = keep[depths.hit_owner]
    new_row = np.cumsum(keep) - 1
    return PenetrationDepths(**{f: getattr(depths, f)[keep] for f in fields}, hit_owner=new_row[depths.hit_owner[hits]],
                             hit_point=depths.hit_point[hits], hit_normal=depths.hit_normal[hits],
                             method=depths.method)


def depths_both(meshes, positions, *, into=None, **options):
    """Consistent and naive depths; with ``into``, only the vertices inside that body (the other way
    round, the big body's corners that poke into the small one also collide)."""
    bodies = CollisionBodies(meshes)
    contacts = detect_collisions(bodies, positions, **options)
    consistent = consistent_penetration_depths(bodies, positions, contacts)
    naive = closest_surface_depths(bodies, positions, contacts)
    if into is not None:
        consistent, naive = rows(consistent, consistent.other_body == into), rows(naive, naive.other_body == into)
    return bodies, consistent, naive


@pytest.mark.parametrize("seed", range(3))
def test_cube_pushed_into_a_block_gets_the_known_overlap(seed):
    """A small cube, tilted, pushed a known distance into a large block's top face."""
    block = cube_mesh((6, 6, 3), (3.0, 3.0, 1.5))
    small = cube_mesh((4, 4, 4), (0.5, 0.5, 0.5))
    # A random rigid motion of the whole scene, and a tilt of the small cube of up to 15 degrees.
    scene = Rotation.random(random_state=seed).as_matrix()
    tilt = Rotation.from_rotvec(np.random.default_rng(seed).uniform(-0.15, 0.15, 3) * np.array([1, 1, 0])).as_matrix()
    push = 0.3  # the small cube's lowest corner ends 0.3 m below the block's top face z = 1.5
    local = (small.points - 0.25) @ tilt.T
    local += [1.5, 1.5, 1.5 - push - local[:, 2].min()]
    x = np.concatenate([block.points, local]) @ scene.T
    bodies, consistent, naive = depths_both((block, small), x, into=0)
    assert consistent.count > 20
    height_below_face = 1.5 - local[consistent.vertex - block.node_count, 2]
    assert height_below_face.max() == pytest.approx(push, rel=1e-12)
    np.testing.assert_allclose(consistent.depth, height_below_face, atol=ROUND_OFF)
    np.testing.assert_allclose(consistent.direction, np.tile(scene[:, 2], (consistent.count, 1)), atol=ROUND_OFF)
    assert consistent.level.max() >= 2, "a push of several cells deep must exercise the propagation"
    assert not consistent.fallback.any()
    # Shallow and well inside the face, the naive depth agrees here; it is the thin slab that breaks it.
    np.testing.assert_allclose(naive.depth, consistent.depth, atol=ROUND_OFF)


def thin_slab_scene():
    """A 0.2 m slab, and a small cube moving down at 20 m/s that is 0.14 m (past halfway) into it."""
    slab = cube_mesh((8, 8, 1), (2.0, 2.0, 0.2))
    small = cube_mesh((3, 3, 3), (0.3, 0.3, 0.3))
    velocity = np.array([0.0, 0.0, -20.0])
    x = [slab.points, small.points + [0.85, 0.85, 0.2 - 0.14]]
    return (slab, small), x, velocity


def test_thin_slab_consistent_depth_pushes_back_the_way_the_body_came():
    meshes, x, velocity = thin_slab_scene()
    bodies, consistent, _ = depths_both(meshes, x, into=0)
    back = -velocity / np.linalg.norm(velocity)
    assert consistent.count > 0
    np.testing.assert_allclose(consistent.direction, np.tile(back, (consistent.count, 1)), atol=ROUND_OFF)
    np.testing.assert_allclose(consistent.depth, 0.2 - x[1][consistent.vertex - meshes[0].node_count, 2],
                               atol=ROUND_OFF)
    assert consistent.depth.max() > 0.1, "the deepest points are past the slab's midplane"


def test_thin_slab_naive_closest_point_depth_points_through_the_slab():
    meshes, x, velocity = thin_slab_scene()
    bodies, consistent, naive = depths_both(meshes, x, into=0)
    heights = x[1][naive.vertex - meshes[0].node_count, 2]
    past_midplane = heights < 0.1
    assert past_midplane.sum() >= 9  # the small cube's bottom layer of 4 x 4 nodes
    # There the nearest surface is the slab's far side: the naive force would push the body on through.
    forward = velocity / np.linalg.norm(velocity)
    assert (naive.direction[past_midplane] @ forward > 0.999).all()  # cos(2.6 deg): straight through
    assert (consistent.direction[past_midplane] @ forward < -0.999).all()
    np.testing.assert_allclose(naive.depth[past_midplane], heights[past_midplane], atol=ROUND_OFF)


def test_body_wholly_inside_another_uses_the_flagged_fallback(caplog):
    block = cube_mesh((4, 4, 4), (2.0, 2.0, 2.0))
    small = cube_mesh((2, 2, 2), (0.4, 0.4, 0.4))
    offset = np.array([0.55, 0.62, 1.03])  # no block node inside the small cube, no tie between nearest faces
    with caplog.at_level("INFO", logger="volspring.collision.penetration"):
        bodies, consistent, naive = depths_both((block, small), [block.points, small.points + offset], into=0)
    assert consistent.count == small.node_count
    assert consistent.fallback.all() and (consistent.level == -1).all() and len(consistent.hit_owner) == 0
    assert "reached by no border point" in caplog.text
    p = small.points + offset
    distance_to_faces = np.concatenate([p, 2.0 - p], axis=1)  # to x=0, y=0, z=0, x=2, y=2, z=2
    np.testing.assert_allclose(consistent.depth, distance_to_faces.min(axis=1), atol=ROUND_OFF)
    nearest = distance_to_faces.argmin(axis=1)
    expected = np.zeros((len(p), 3))
    expected[np.arange(len(p)), nearest % 3] = np.where(nearest < 3, -1.0, 1.0)
    np.testing.assert_allclose(consistent.direction, expected, atol=ROUND_OFF)
    np.testing.assert_allclose(naive.depth, consistent.depth, atol=ROUND_OFF)


def test_edge_crossing_several_faces_keeps_the_hit_nearest_the_outside_end():
    """Q is two stacked slabs (one body); P's edges start inside the lower slab and end above the upper."""
    slab = cube_mesh((4, 4, 1), (1.0, 1.0, 0.2))  # hits land on triangles of interior top nodes: exact normals
    lower, upper = slab.points, slab.points + [0, 0, 0.5]
    two_slabs = TetMesh(np.concatenate([lower, upper]), np.concatenate([slab.tets, slab.tets + slab.node_count]))
    spike = TetMesh(np.array([[0.5, 0.5, 0.1], [0.4, 0.4, 1.0], [0.7, 0.45, 1.0], [0.45, 0.7, 1.0]]),
                    np.array([[0, 1, 2, 3]]))
    bodies, consistent, _ = depths_both((two_slabs, spike), [two_slabs.points, spike.points], into=0)
    assert consistent.vertex.tolist() == [two_slabs.node_count]  # only the tip is inside
    # Each of its 3 edges crosses z = 0.2, 0.5 and 0.7: the kept hit is on z = 0.7.
    assert len(consistent.hit_point) == 3
    np.testing.assert_allclose(consistent.hit_point[:, 2], 0.7, atol=ROUND_OFF)
    assert consistent.depth[0] == pytest.approx(0.6, abs=ROUND_OFF)


def test_results_carry_what_the_response_needs():
    meshes, x, _ = thin_slab_scene()
    bodies, consistent, _ = depths_both(meshes, x)
    stacked = bodies.stack_positions(x)
    # The reaction goes onto the tet of the other body that contains the vertex, with these weights.
    assert (bodies.tet_body[consistent.tet] == consistent.other_body).all()
    rebuilt = np.einsum("ki,kij->kj", consistent.barycentric, stacked[bodies.tets[consistent.tet]])
    np.testing.assert_allclose(rebuilt, stacked[consistent.vertex], atol=ROUND_OFF)
    np.testing.assert_allclose(np.linalg.norm(consistent.direction, axis=1), 1.0, atol=ROUND_OFF)
    assert np.isfinite(consistent.depth).all()
    assert (consistent.level[consistent.is_border] == 0).all()


@pytest.mark.parametrize("seed", range(3))
def test_random_overlaps_are_finite_and_mostly_positive(seed):
    """Randomly rotated, jittered boxes (as in the detection tests), self-collision on."""
    rng = np.random.default_rng(seed)
    meshes, x = [], []
    for body in range(3):
        mesh = cube_mesh((4, 4, 4), (1.0, 1.0, 1.0))
        rotation = Rotation.random(random_state=seed * 10 + body).as_matrix()
        meshes.append(mesh)
        x.append((mesh.points - 0.5) @ rotation.T + rng.uniform(-0.4, 0.4, 3) + rng.normal(0, 0.02, (125, 3)))
    bodies, consistent, naive = depths_both(meshes, x, self_collision=True)
    assert consistent.count > 10
    assert np.isfinite(consistent.depth).all() and np.isfinite(consistent.direction).all()
    np.testing.assert_allclose(np.linalg.norm(consistent.direction, axis=1), 1.0, atol=ROUND_OFF)
    # Depths are propagated, not minimal, and interpolated normals may disagree at a body's corners,
    # so a barely-inside vertex can get a slightly negative depth; never by more than an edge (0.25 m).
    assert consistent.depth.min() > -0.25
    assert (consistent.depth > 0).mean() > 0.9
    # The naive depth is the distance to the nearest surface point: a lower bound on any way out.
    assert (naive.depth >= 0).all()
