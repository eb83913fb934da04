"""Tet-tet intersection against an independent separating-axis test; crossing slabs found and pushed apart.

The reference (``sat_intersect``) shares nothing with :mod:`volspring.collision.tet_tet` but the
convention that tets are closed sets (touching intersects): two convex polytopes are disjoint
exactly when their projections on one of the face normals of either, or on one of the cross
products of an edge of each, are disjoint intervals. Exactly touching pairs are built on integer
grids (and moved by dyadic steps 2^-8), where every product both sides form is exact in float64, so
the two must agree on every pair, touching ones included.
"""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from meshing import structured_box
from meshing.mesh import TET_EDGES
from volspring.collision import CollisionBodies, detect_collisions
from volspring.collision.tet_tet import edge_face_crossings, tets_intersect

# Dyadic step of the near-touching pairs: 2^-8 on a grid of integers below 2^4, so coordinates keep
# at most 12 significant bits and products of three of them (36 bits) stay exact in float64's 53.
NUDGE = 2.0 ** -8


def sat_intersect(a, b):
    """Separating-axis test over face normals and edge-edge cross products, vectorised over pairs: (m,) bool."""
    def face_normals(t):
        return [np.cross(t[:, j] - t[:, i], t[:, k] - t[:, i]) for i, j, k in ((1, 2, 3), (0, 2, 3), (0, 1, 3),
                                                                              (0, 1, 2))]
    da = [a[:, j] - a[:, i] for i, j in TET_EDGES]
    db = [b[:, j] - b[:, i] for i, j in TET_EDGES]
    axes = face_normals(a) + face_normals(b) + [np.cross(u, w) for u in da for w in db]
    separated = np.zeros(len(a), dtype=bool)
    for axis in axes:  # 44 axes, each over all pairs at once
        usable = np.any(axis != 0, axis=1)  # parallel edges give a zero cross product: no axis
        pa, pb = np.einsum("mvj,mj->mv", a, axis), np.einsum("mvj,mj->mv", b, axis)
        apart = (pa.max(axis=1) < pb.min(axis=1)) | (pb.max(axis=1) < pa.min(axis=1))
        separated |= usable & apart
    return ~separated


def sat_margin(a, b):
    """(m,) float -- the smallest overlap of the projections on the unit axes: the penetration depth when
    positive, minus a lower bound of the distance when negative [same unit as the corners]."""
    da = [a[:, j] - a[:, i] for i, j in TET_EDGES]
    db = [b[:, j] - b[:, i] for i, j in TET_EDGES]
    axes = [np.cross(t[:, j] - t[:, i], t[:, k] - t[:, i]) for t in (a, b)
            for i, j, k in ((1, 2, 3), (0, 2, 3), (0, 1, 3), (0, 1, 2))] + [np.cross(u, w) for u in da for w in db]
    margin = np.full(len(a), np.inf)
    for axis in axes:
        length = np.linalg.norm(axis, axis=1)
        unit = axis / np.where(length > 0, length, 1.0)[:, None]
        pa, pb = np.einsum("mvj,mj->mv", a, unit), np.einsum("mvj,mj->mv", b, unit)
        overlap = np.minimum(pa.max(axis=1) - pb.min(axis=1), pb.max(axis=1) - pa.min(axis=1))
        margin = np.where(length > 0, np.minimum(margin, overlap), margin)
    return margin


def volumes(t):
    return np.einsum("mj,mj->m", np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), t[:, 3] - t[:, 0])


def random_float_pairs(rng, count):
    """Random tets in a unit box, the second shifted so that about half the pairs meet."""
    a = rng.uniform(0, 1, (count, 4, 3))
    b = rng.uniform(0, 1, (count, 4, 3)) + rng.uniform(-0.8, 0.8, (count, 1, 3))
    return a, b


def random_grid_pairs(rng, count):
    """Random tets with corners on the integer grid [-2, 2]^3: shared corners, corners on faces and edges,
    coplanar faces and collinear edges all occur by chance, and exactly."""
    a = rng.integers(-2, 3, (count, 4, 3)).astype(float)
    b = rng.integers(-2, 3, (count, 4, 3)).astype(float)
    solid = (volumes(a) != 0) & (volumes(b) != 0)
    return a[solid], b[solid]


def plane_touching_pairs(rng, count):
    """Tets touching across the plane z = 0, exactly: a has 1-3 corners on it and the rest above, b has 1-3
    on it and the rest below. They touch where the two sets of corners in the plane have overlapping
    hulls: a shared corner, a corner on an edge or in a face, crossing or collinear edges, coplanar faces.
    Then the same integer shear and shift for both (which keeps touching touching, exactly)."""
    def tets(sign):
        t = np.empty((count, 4, 3))
        t[:, :, :2] = rng.integers(-3, 4, (count, 4, 2))
        t[:, :, 2] = sign * rng.integers(1, 4, (count, 4))
        on_plane = np.arange(4) < rng.integers(1, 4, count)[:, None]
        t[:, :, 2] *= ~on_plane
        return t
    a, b = tets(1), tets(-1)
    shear = np.eye(3) + np.triu(rng.integers(-1, 2, (count, 3, 3)), 1)  # unit upper triangular: det 1
    shift = rng.integers(-3, 4, (count, 1, 3))
    a, b = a @ shear.transpose(0, 2, 1) + shift, b @ shear.transpose(0, 2, 1) + shift
    solid = (volumes(a) != 0) & (volumes(b) != 0)
    return a[solid], b[solid], shear[solid]


def rotated_near_touching_pairs(rng, count, gap):
    """Plane-touching pairs rotated at random (not exact) and moved apart (gap > 0) or into each other."""
    a, b, shear = plane_touching_pairs(rng, count)
    up = shear[:, :, 2]  # the image of z: a moved along it leaves the plane z = 0 (sheared) by |gap|
    rotation = Rotation.random(len(a), random_state=int(rng.integers(2 ** 31))).as_matrix()
    a = (a + gap * up[:, None, :]) @ rotation.transpose(0, 2, 1)
    return a, b @ rotation.transpose(0, 2, 1)


def test_reference_sat_knows_the_constructed_answers():
    """The reference itself, on the constructions: touching pairs intersect, pairs moved apart do not."""
    rng = np.random.default_rng(1)
    a, b, shear = plane_touching_pairs(rng, 2000)
    touching = sat_intersect(a, b)
    moved = sat_intersect(a + NUDGE * shear[:, None, :, 2], b)  # a lifted off the plane along the sheared z
    assert not moved.any()
    # Overlapping hulls are common on a 7 x 7 grid: measured 48% of the pairs; ask for a quarter.
    assert touching.mean() > 0.25


def pairs_of_kind(kind):
    """The pairs of one kind, each from its own seeded generator."""
    rng = np.random.default_rng(KINDS.index(kind))
    if kind == "random":
        return random_float_pairs(rng, 4000)
    if kind == "grid":
        return random_grid_pairs(rng, 4000)
    if kind == "touching":
        return plane_touching_pairs(rng, 3000)[:2]
    if kind in ("nudged_apart", "nudged_in"):
        a, b, shear = plane_touching_pairs(rng, 1500)
        return a + (NUDGE if kind == "nudged_apart" else -NUDGE) * shear[:, None, :, 2], b
    # 1e-6 apart or into each other, for tets ~5 across: far above round-off (~1e-16 x 5^3 in a determinant
    # of lengths ~5, i.e. ~1e-15 in a distance), far below the tets' size.
    apart = rotated_near_touching_pairs(rng, 500, 1e-6)
    into = rotated_near_touching_pairs(rng, 500, -1e-6)
    return np.concatenate([apart[0], into[0]]), np.concatenate([apart[1], into[1]])


KINDS = ["random", "grid", "touching", "nudged_apart", "nudged_in", "rotated"]


@pytest.mark.parametrize("kind", KINDS)
def test_tets_intersect_agrees_with_the_separating_axis_test(kind):
    a, b = pairs_of_kind(kind)
    if kind == "rotated":
        # Inexact input: a pair within 1e-8 of the tets' size of touching (tets ~10 across here) is decided
        # by round-off, for both sides (volspring.collision.tet_tet.NEAR_COPLANAR): left out, and counted.
        clear = np.abs(sat_margin(a, b)) > 1e-8 * 10
        assert clear.mean() > 0.95, clear.mean()  # measured 0.99x: pushed-in pairs may still only touch
        a, b = a[clear], b[clear]
    expected = sat_intersect(a, b)
    found, inside = tets_intersect(a, b, return_vertex_inside=True)
    wrong = np.flatnonzero(found != expected)
    assert len(wrong) == 0, (f"{len(wrong)} of {len(a)} disagree, first a = {a[wrong[0]].tolist()}, "
                             f"b = {b[wrong[0]].tolist()}, SAT says {expected[wrong[0]]}")
    # Not vacuous: both answers occur (but where the construction fixes one), and pairs that meet only
    # through an edge crossing a face, what vertex-in-tet misses, are among them.
    if kind != "nudged_apart":
        assert 0.05 < expected.mean() < 0.95, expected.mean()
        assert (found & ~inside).sum() >= 10
    else:
        assert not expected.any()


def test_at_least_ten_thousand_pairs_are_compared():
    counts = {kind: len(pairs_of_kind(kind)[0]) for kind in KINDS}
    assert sum(counts.values()) >= 10_000, counts


def test_flat_tets_intersect_nothing_and_bad_input_is_named():
    tet = np.array([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]])
    flat = np.array([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]]])  # four corners in z = 0
    assert tets_intersect(tet, tet).all() and not tets_intersect(flat, tet).any()
    with pytest.raises(ValueError, match=r"expected \(m, 4, 3\)"):
        tets_intersect(tet[0], tet[0])
    with pytest.raises(ValueError, match="not finite"):
        tets_intersect(tet * np.nan, tet)
    with pytest.raises(ValueError, match="same"):
        tets_intersect(tet, np.concatenate([tet, tet]))


def test_edge_face_crossing_points_lie_on_both_edge_and_face():
    a, b = pairs_of_kind("random")
    hits = edge_face_crossings(a, b)
    found, inside = tets_intersect(a, b, return_vertex_inside=True)
    # Every pair that meets with no vertex inside has a crossing, and only intersecting pairs have any.
    crossed = np.zeros(len(a), dtype=bool)
    crossed[hits.pair] = True
    assert (crossed[found & ~inside]).all() and not crossed[~found].any()
    faces = np.where(hits.edge_in_b[:, None, None], a[hits.pair], b[hits.pair])
    from meshing.mesh import TET_FACES
    on_face = np.einsum("kf,kfj->kj", hits.barycentric, faces[np.arange(hits.count)[:, None], TET_FACES[hits.face]])
    # Two routes to one point (along the edge; weights on the face), for corners ~1 m: round-off ~1e-15
    # over the conditioning of the crossing (1 / sine of the edge's angle to the face); 1e-9 allows 1e6.
    np.testing.assert_allclose(hits.point, on_face, atol=1e-9)
    assert (hits.barycentric >= 0).all() and ((hits.t >= 0) & (hits.t <= 1)).all()


# ---------------------------------------------------------------------- bodies
def crossing_slabs():
    """A flat slab (0.4 x 0.4 x 0.025 m, one cell thick) and an upright one (0.025 x 0.6 x 0.2 m) through it:
    the upright's lower 5 cm pokes through, between the flat's nodes (x = 0.13 to 0.155 inside the flat's
    cell 0.1 to 0.2; y off the flat's grid by 13 mm, so no edge meets another exactly), so no vertex of
    either is inside the other."""
    flat = structured_box((4, 4, 1), (0.4, 0.4, 0.025))
    upright = structured_box((1, 6, 1), (0.025, 0.6, 0.2), origin=(0.13, -0.087, -0.05))
    return flat, upright


def test_crossing_slabs_are_found_by_tet_pairs_and_missed_by_vertex_in_tet():
    from volspring.collision.tet_tet import crossing_tet_pairs, edge_crossing_contacts

    bodies = CollisionBodies(crossing_slabs())
    x = bodies.rest_positions
    assert detect_collisions(bodies, x).count == 0
    pairs = crossing_tet_pairs(bodies, x)
    assert pairs.count > 0 and not pairs.vertex_inside.any()
    contacts = edge_crossing_contacts(bodies, x, pairs)
    # The upright's edges through the flat's top face: their lower ends are 0.05 + 0.025 m behind it.
    upright = contacts.vertex_body == 1
    np.testing.assert_allclose(contacts.depth[upright], 0.075, rtol=1e-12)  # exact geometry, round-off
    np.testing.assert_allclose(contacts.direction[upright], [[0, 0, 1]] * upright.sum(), atol=1e-12)
    # Moved 8.5 cm up, the upright's bottom is 1 cm above the flat's top (0.025 m): nothing.
    lifted = x + np.where(bodies.node_body[:, None] == 1, [0, 0, 0.085], 0.0)
    assert crossing_tet_pairs(bodies, lifted).count == 0


@pytest.mark.parametrize("seed", range(2))
def test_crossing_tet_pairs_equal_all_pairs_brute_force(seed):
    from test_collision_detection import random_scene
    from volspring.collision.tet_tet import crossing_tet_pairs

    bodies, x = random_scene(seed)
    pairs = crossing_tet_pairs(bodies, x)
    first, second = np.triu_indices(bodies.tet_count, 1)
    other = bodies.tet_body[first] != bodies.tet_body[second]
    first, second = first[other], second[other]
    hit = tets_intersect(x[bodies.tets[first]], x[bodies.tets[second]])
    assert set(zip(pairs.tet_a.tolist(), pairs.tet_b.tolist())) == set(zip(first[hit].tolist(), second[hit].tolist()))
    assert hit.sum() > 100  # the three boxes overlap near the origin


def slab_model(**options):
    from volspring import Material, Model
    from volspring.bodies import Body
    from volspring.collision import ContactForce

    soft = Material(E=1e5, nu=0.3, density=1000.0)
    model = Model.from_bodies([Body(mesh, soft) for mesh in crossing_slabs()])
    return model, ContactForce(model, edges=True, **options)


def test_edge_crossing_jacobian_matches_finite_differences():
    rng = np.random.default_rng(3)
    model, contact = slab_model(damping=0.0)
    x = np.array(model.rest_positions)
    still = np.zeros_like(x)
    found = contact.contacts(x)
    assert found.count > 0
    dfdx, _ = contact.jacobian(model, x, still, 0.0)

    def force(positions):
        out = np.zeros_like(x)
        contact.accumulate(model, positions, still, 0.0, out)
        return out

    # Move the edges' ends behind faces that carry no reaction themselves: with the face (so its normal)
    # fixed, the depth is linear in them, and their rows and each body's total force are exact.
    ends = np.setdiff1d(found.vertex, found.nodes[:, 1:])
    dx = np.zeros_like(x)
    dx[ends] = rng.normal(size=(len(ends), 3))
    step = 1e-7  # m, 1e-6 of the 7.5 cm depths (the force is piecewise linear: exact but for round-off)
    expected = (force(x + step * dx) - force(x - step * dx)) / (2 * step)
    linear = (dfdx @ dx.ravel()).reshape(-1, 3)
    scale = found.stiffness.max()  # N/m; round-off of a difference of forces ~k 0.1 m: 1e-16 k 0.1 / 1e-7
    np.testing.assert_allclose(linear[ends], expected[ends], atol=1e-6 * scale)
    for body in range(2):
        rows = model.node_body == body
        np.testing.assert_allclose(linear[rows].sum(axis=0), expected[rows].sum(axis=0), atol=1e-6 * scale)
    # Equal and opposite: the forces, and the Jacobian's response to any move, sum to zero; symmetric.
    total = force(x).sum(axis=0)
    assert np.abs(total).max() <= 1e-12 * np.abs(force(x)).max()
    assert abs(dfdx - dfdx.T).max() <= 1e-12 * abs(dfdx).max()
    moved = (dfdx @ rng.normal(size=3 * len(x))).reshape(-1, 3).sum(axis=0)
    assert np.abs(moved).max() <= 1e-12 * abs(dfdx).max()


def test_crossing_slabs_are_pushed_apart_by_implicit_euler():
    """The upright slab pokes 7.5 cm through the flat one; with edge contacts it leaves upwards (measured:
    crossings gone after 60 steps of 1 ms, from 150 tet pairs; some vertex contacts on the way).

    Without them nothing sees the crossing: no contact, no force (the negative control)."""
    from volspring import Scene
    from volspring.collision import ContactForce
    from volspring.diagnostics import linear_momentum
    from volspring.integrators import make_integrator
    from volspring.collision.tet_tet import crossing_tet_pairs

    model, contact = slab_model()
    assert ContactForce(model).contacts(model.rest_positions).count == 0
    scene = Scene(model, forces=[contact])
    state = scene.initial_state()
    integrator = make_integrator("implicit_euler", solver="direct")
    counts = []
    for _ in range(100):  # 1 ms steps
        state = integrator.step(scene, state, 1e-3)
        counts.append(crossing_tet_pairs(contact.bodies, state.x[contact.bodies.model_nodes]).count)
    assert counts[-20:] == [0] * 20, counts
    height = [state.x[model.node_body == body, 2].mean() for body in range(2)]
    assert height[1] - height[0] > 0.1 + 0.0375  # centres were 0.0375 m apart: the upright went up
    # Equal and opposite forces: momentum stays at round-off of the largest momentum reached.
    momentum = linear_momentum(model, state)
    assert np.abs(momentum).max() <= 1e-9 * (model.masses[:, None] * np.abs(state.v)).sum()


def contact_fields_equal(first, second):
    return all(np.array_equal(getattr(first, name), getattr(second, name)) for name in first.__dataclass_fields__)


@pytest.mark.parametrize("scene", ["slabs", "random0", "random1"])
def test_boundary_broad_phase_gives_the_same_edge_contacts_as_all_pairs(scene, monkeypatch):
    """``crossing_tet_pairs(boundary=True)`` keeps only pairs that can hold a boundary edge through a boundary
    face: a subset of all intersecting pairs, with the same edge contacts (with and without ``colliding``,
    and on both broad phases: each body against the later ones, and all against all)."""
    from test_collision_detection import random_scene
    from volspring.collision import tet_tet
    from volspring.collision.tet_tet import crossing_tet_pairs, edge_crossing_contacts

    if scene == "slabs":
        bodies = CollisionBodies(crossing_slabs())
        x = bodies.rest_positions
    else:
        bodies, x = random_scene(int(scene[-1]))
    hits = detect_collisions(bodies, x)
    every = crossing_tet_pairs(bodies, x)
    boundary = crossing_tet_pairs(bodies, x, boundary=True)
    monkeypatch.setattr(tet_tet, "_ONE_WAY_BODIES", 0)  # the all-against-all hash
    assert contact_fields_equal(every, crossing_tet_pairs(bodies, x))
    assert contact_fields_equal(boundary, crossing_tet_pairs(bodies, x, boundary=True))
    pairs = set(zip(every.tet_a.tolist(), every.tet_b.tolist()))
    assert set(zip(boundary.tet_a.tolist(), boundary.tet_b.tolist())) <= pairs
    for colliding in (None, hits):
        expected = edge_crossing_contacts(bodies, x, every, colliding=colliding)
        assert expected.count > 0
        assert contact_fields_equal(expected, edge_crossing_contacts(bodies, x, boundary, colliding=colliding))
    if scene != "slabs":
        assert boundary.count < every.count and hits.count > 0  # not vacuous: interior pairs were left out
