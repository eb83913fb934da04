"""Thin bodies in contact: cloth and strings on obstacles (a thickness), on tet bodies, and a cloth on itself.

Every scene here steps implicit Euler with the contact Jacobians. Depth bounds come from the penalty:
a node pressed by a load F sits F / k_c into its contact layer at rest, so a resting cloth's deepest
node is at most (its weight, or the whole cloth's) / k_c deep, and "no node passes through" is the
stronger check that every depth stays below the thickness (the node never reached the surface).
"""

from __future__ import annotations

import numpy as np
import pytest

from meshing.structured import structured_box
from volspring import Drag, Gravity, HalfSpace, Material, Model, Pins, Scene
from volspring.bodies import Body
from volspring.collision import (
    ClothSelfContactForce,
    ObstacleContactForce,
    StaticTriangleMesh,
    ThinContactForce,
    obstacle_contacts,
)
from volspring.diagnostics import linear_momentum
from volspring.integrators import make_integrator
from volspring.structures import cloth_grid, cloth_mesh, combine, sheet_grid, string

G = 9.81
SHEET = {"areal_density": 0.2, "membrane_stiffness": 100.0}
FOAM = Material(E=1e4, nu=0.3, density=100.0)


def run(scene, state, *, steps, dt, each=None):
    stepper = make_integrator("implicit_euler")
    for _ in range(steps):
        state = stepper.step(scene, state, dt)
        if each is not None:
            each(state)
    return state


def directional_derivative(force, model, x, v, *, dx=None, dv=None, step=1e-7):
    """Central difference of the force along (dx, dv), with the contact set of x held (as the Jacobian does)."""
    def at(sign):
        out = np.zeros_like(x)
        xs, vs = x + sign * step * (0 if dx is None else dx), v + sign * step * (0 if dv is None else dv)
        force.accumulate(model, xs, vs, 0.0, out)
        return out
    return (at(1) - at(-1)) / (2 * step)


# ---------------------------------------------------------------------- 1. obstacles with a thickness
def test_halfspace_contacts_with_a_thickness():
    floor = HalfSpace((0, 0, 0), (0, 0, 1))
    points = np.array([[0.0, 0, 0.03], [0, 0, 0.004], [0, 0, -0.002]])
    vertex, depth, direction, closest, _ = floor.contacts(points, thickness=0.01)
    # Depth = thickness - height, exactly (decimal inputs: round-off of one subtraction).
    assert vertex.tolist() == [1, 2] and np.allclose(depth, [0.006, 0.012], atol=1e-15)
    assert np.allclose(closest[:, 2], 0.0) and np.allclose(direction, [0, 0, 1])
    assert floor.contacts(points)[0].tolist() == [2]  # negative control: without a thickness only the one below
    with pytest.raises(ValueError, match="thickness = -0.1 is not finite and >= 0"):
        ObstacleContactForce(cloth_grid(1, 1, 2, 2, **SHEET), [floor], thickness=-0.1, stiffness=1.0)
    with pytest.raises(ValueError, match="thickness = -0.1 m is not finite and >= 0"):
        obstacle_contacts([floor], points, thickness=-0.1)


@pytest.mark.parametrize("thickness", [0.01, 0.0])
def test_cloth_dropped_on_a_floor_rests_at_its_thickness(thickness):
    cloth = cloth_grid(1.0, 1.0, 10, 10, origin=(0, 0, 0.05), **SHEET)
    k = 100.0
    floor = ObstacleContactForce(cloth, [HalfSpace((0, 0, 0), (0, 0, 1))], thickness=thickness, stiffness=k)
    scene = Scene(cloth, forces=[Gravity(), floor])
    state = run(scene, scene.initial_state(), steps=60, dt=0.01)
    # At rest each node's contact carries its own weight (flat sheet, no membrane load): depth m g / k, so
    # the heights are thickness - m_i g / k to round-off of the implicit solve (measured 1e-12 m).
    expected = thickness - cloth.masses * G / k
    np.testing.assert_allclose(state.x[:, 2], expected, atol=1e-9)
    assert np.abs(state.v).max() < 1e-8  # at rest (measured 7e-12 m/s)


def _ball(radius, centre, cells=6):
    """A closed triangle surface close to a sphere: a box's boundary pushed out onto the sphere."""
    box = structured_box((cells,) * 3, (1.0, 1.0, 1.0), pattern="kuhn")
    used, faces = np.unique(box.boundary_faces, return_inverse=True)
    direction = box.points[used] - 0.5
    return StaticTriangleMesh(centre + radius * direction / np.linalg.norm(direction, axis=1)[:, None],
                              faces.reshape(-1, 3))


def test_cloth_dropped_on_a_ball_drapes_without_passing_through():
    ball = _ball(0.3, np.array([0.4, 0.4, -0.3]))
    cloth = cloth_grid(0.8, 0.8, 16, 16, origin=(0, 0, 0.03), **SHEET)
    k, thickness = 1000.0, 0.01
    contact = ObstacleContactForce(cloth, [ball], thickness=thickness, stiffness=k, friction=0.3)
    scene = Scene(cloth, forces=[Gravity(), contact, Drag(rate=2.0)])
    inside, deepest = [], []
    def watch(state):
        inside.append(ball.contacts(state.x)[0].size)
        deepest.append(contact.contacts(state.x).max_depth)

    state = run(scene, scene.initial_state(), steps=300, dt=0.005, each=watch)
    # No node ever inside the ball: every depth stayed below the thickness.
    assert max(inside) == 0 and max(deepest) < thickness
    # Resting: the contacts hold the cloth's weight M g, none more than all of it, so no depth exceeds
    # M g / k (1.3 mm here; measured 0.1 mm at the end, the impact's 0.7 mm before).
    assert deepest[-1] <= cloth.total_mass * G / k
    # The cloth drapes: its corners hang well below the ball's top (z = 0), its middle rests on it.
    assert state.x[[0, 16, 272, 288], 2].max() < -0.1 and state.x[144, 2] > thickness - cloth.total_mass * G / k
    # Negative control: without the thickness the same drop ends with nodes on the mesh surface or below it.
    bare = ObstacleContactForce(cloth, [ball], stiffness=k, friction=0.3)
    end = run(Scene(cloth, forces=[Gravity(), bare, Drag(rate=2.0)]), scene.initial_state(), steps=300, dt=0.005)
    assert ball.contacts(end.x)[0].size > 0


def test_string_draped_over_a_box():
    cube = structured_box((1, 1, 1), (0.2, 0.2, 0.2), pattern="kuhn")
    box = StaticTriangleMesh(cube.points - [0.1, 0.1, 0.2], cube.boundary_faces)  # top face at z = 0
    rope = string([-0.5, 0, 0.02], [0.5, 0, 0.02], count=41, mass=0.05, stiffness=500.0)
    contact = ObstacleContactForce(rope, [box], thickness=0.01, stiffness=200.0, friction=0.3)
    scene = Scene(rope, forces=[Gravity(), contact, Drag(rate=2.0)])
    inside = []
    state = run(scene, scene.initial_state(), steps=300, dt=0.005,
                each=lambda s: inside.append(box.contacts(s.x)[0].size))
    assert max(inside) == 0
    # Draped: both ends hang down the sides (measured -0.37 m), the middle lies on the top at its thickness,
    # less the weight it carries over k (the hanging ends pull it down: at most the rope's weight, 2.5 mm).
    assert state.x[[0, -1], 2].max() < -0.2
    assert 0.01 - rope.total_mass * G / 200.0 <= state.x[20, 2] <= 0.01


# ---------------------------------------------------------------------- 2. thin bodies on tet bodies
def _block_and_cloth(*, cloth_size, cells, origin_z, offset=0.0):
    mesh = structured_box((4, 4, 2), (0.4, 0.4, 0.2), pattern="kuhn")
    block = Model.from_bodies([Body(mesh, FOAM, translation=(-0.2, -0.2, -0.2))])  # top face at z = 0
    corner = -cloth_size / 2 + offset
    cloth = cloth_grid(cloth_size, cloth_size, cells, cells, origin=(corner, corner, origin_z), **SHEET)
    return block, combine([block, cloth])


def test_combine_keeps_the_tet_bodies_first_and_the_cloth_after():
    block, model = _block_and_cloth(cloth_size=0.3, cells=6, origin_z=0.01)
    n = block.node_count
    assert model.body_count == 2 and model.materials == (FOAM, None)
    assert (model.node_body[:n] == 0).all() and (model.node_body[n:] == 1).all()
    assert model.topology.mesh is block.topology.mesh and model.spring_count == block.spring_count + 156
    assert model.total_mass == pytest.approx(block.total_mass + 0.2 * 0.09, rel=1e-14)
    with pytest.raises(ValueError, match=r"models\[1\] has a tet mesh"):
        combine([model, block])


def test_cloth_dropped_on_a_pinned_block_rests_on_it():
    h = 0.01
    block, model = _block_and_cloth(cloth_size=0.3, cells=12, origin_z=0.03)  # no overhang
    contact = ThinContactForce(model, thickness=h, friction=0.3)
    scene = Scene(model, forces=[Gravity(), contact, Drag(rate=2.0)], pins=Pins(np.arange(block.node_count)))
    inside, deepest = [], []

    def watch(state):
        found = contact.contacts(state.x)
        inside.append(len(contact._inside(state.x[contact.nodes], state.x[contact.bodies.model_nodes])[0]))
        deepest.append(found.max_depth)

    state = run(scene, scene.initial_state(), steps=150, dt=0.005, each=watch)
    # No cloth node ever inside the block: vertex-in-tet finds none at any step and every depth < thickness.
    assert max(inside) == 0 and max(deepest) < h
    # At rest each node carries its weight: depth m g / k_c (k_c = 2 E l, the rule), to the solver's 1e-9 m.
    cloth = model.node_body == 1
    k_c = 2 * FOAM.E * contact._node_length[cloth]
    np.testing.assert_allclose(state.x[cloth, 2], h - model.masses[cloth] * G / k_c, atol=1e-6)
    # Negative control: without the contact the cloth falls into the block (after 0.1 s, 5 cm down).
    free = run(Scene(model, forces=[Gravity()], pins=Pins(np.arange(block.node_count))), scene.initial_state(),
               steps=20, dt=0.005)
    assert len(contact._inside(free.x[contact.nodes], free.x[contact.bodies.model_nodes])[0]) > 0


def test_cloth_draped_over_a_block_edge_ends_outside():
    """Overhanging: the block's edges cut through cloth triangles while the cloth drapes (edges are not
    detected, module docstring of volspring.collision.thin): measured, nodes of the edge rows are pulled in
    by up to 1.6 cm for a few steps and pushed out again; at rest none is inside."""
    h = 0.01
    block, model = _block_and_cloth(cloth_size=0.6, cells=12, origin_z=0.03, offset=0.0125)
    contact = ThinContactForce(model, thickness=h, friction=0.3)
    scene = Scene(model, forces=[Gravity(), contact, Drag(rate=2.0)], pins=Pins(np.arange(block.node_count)))
    state = run(scene, scene.initial_state(), steps=200, dt=0.005)
    assert len(contact._inside(state.x[contact.nodes], state.x[contact.bodies.model_nodes])[0]) == 0
    assert contact.contacts(state.x).max_depth < h
    cloth = state.x[model.node_body == 1]
    assert cloth[:, 2].min() < -0.05  # it drapes over the edges (measured -0.1 m)


def test_free_cloth_and_block_conserve_momentum():
    block, model = _block_and_cloth(cloth_size=0.3, cells=6, origin_z=0.005)
    contact = ThinContactForce(model, thickness=0.01)
    scene = Scene(model, forces=[contact])
    v0 = np.zeros((model.node_count, 3))
    cloth = model.node_body == 1
    v0[cloth, 2] = -0.5
    stepper = make_integrator("implicit_euler", solver="direct")
    state = scene.initial_state(v=v0)
    start, contacts = linear_momentum(scene, state), 0
    for _ in range(100):
        state = stepper.step(scene, state, 2e-4)
        contacts = max(contacts, contact.contacts(state.x).count)
    scale = model.masses[cloth].sum() * 0.5  # the cloth's momentum [kg m/s]
    # The collision happened and moved momentum into the block (the cloth kept under 0.9 of its own) ...
    assert contacts > 0 and model.masses[cloth] @ -state.v[cloth, 2] < 0.9 * scale
    # ... and the total did not change: the stencil's weights sum to zero (measured 2e-17 kg m/s, 1e-15 relative).
    assert np.abs(linear_momentum(scene, state) - start).max() < 1e-12 * scale


def test_thin_contact_jacobian_matches_finite_differences():
    rng = np.random.default_rng(11)
    _, model = _block_and_cloth(cloth_size=0.3, cells=6, origin_z=0.0)
    cloth = model.node_body == 1
    x = np.array(model.rest_positions)
    x[cloth, 2] += rng.uniform(-0.004, 0.004, int(cloth.sum()))  # over the flat top: some inside, some outside
    contact = ThinContactForce(model, thickness=0.01, damping=0.0)
    found = contact.contacts(x)
    assert found.count == cloth.sum() and (found.depth > 0.01).any() and (found.depth < 0.01).any()
    dfdx, _ = contact.jacobian(model, x, np.zeros_like(x), 0.0)
    scale = found.stiffness.max()  # [N/m]
    # Moving the cloth's nodes along the top's normal leaves every nearest point where it is: the whole
    # linearisation is exact (d = h -+ n.(p - c) is linear), to the central difference's round-off.
    # A random move of the cloth's nodes also moves the nearest points over the flat top (the reaction's
    # reweighting, left out of the Jacobian as in ContactForce), but the cloth's rows stay exact. (Moving the
    # block's nodes tilts its faces, and r with them: a rotation the Jacobian leaves out, penalty docstring.)
    normal_move, random_move = np.zeros_like(x), np.zeros_like(x)
    normal_move[cloth, 2] = rng.normal(size=int(cloth.sum()))
    random_move[cloth] = rng.normal(size=(int(cloth.sum()), 3))
    for dx, rows in ((normal_move, slice(None)), (random_move, cloth)):
        expected = directional_derivative(contact, model, x, np.zeros_like(x), dx=dx)
        linear = (dfdx @ dx.ravel()).reshape(-1, 3)
        np.testing.assert_allclose(linear[rows], expected[rows], atol=1e-6 * scale)
        # Momentum-neutral both: forces of any perturbation sum to zero (round-off of k_c-sized entries).
        assert np.abs(linear.sum(axis=0)).max() < 1e-9 * scale and np.abs(expected.sum(axis=0)).max() < 1e-6 * scale
    assert abs(dfdx - dfdx.T).max() <= 1e-12 * abs(dfdx).max()  # symmetric, for CG


def test_thin_contact_refuses_a_model_without_thin_nodes():
    block = Model.from_bodies([Body(structured_box((1, 1, 1), (1, 1, 1), pattern="kuhn"), FOAM)])
    with pytest.raises(ValueError, match="no thin node"):
        ThinContactForce(block, thickness=0.01)
    with pytest.raises(ValueError, match="node 0 is a node of tet body 0"):
        ThinContactForce(block, thickness=0.01, nodes=[0])


# ---------------------------------------------------------------------- 3. a cloth on itself
FLAT, GAP, WIDTH = 0.4, 0.04, 0.2


def _hairpin(nx=40, ny=4):
    """A strip folded back over itself: bottom layer at z = 0 (x in [0, FLAT]), a half circle of diameter
    GAP, the top layer at z = GAP back over the bottom one. Returns points, triangles, arc length of each node."""
    arc = np.pi * GAP / 2
    points, triangles = sheet_grid(2 * FLAT + arc, WIDTH, nx, ny)
    s, r = points[:, 0], GAP / 2
    theta = np.clip((s - FLAT) / arc, 0, 1) * np.pi
    x = np.where(s < FLAT, s, np.where(s > FLAT + arc, FLAT - (s - FLAT - arc), FLAT + r * np.sin(theta)))
    z = np.where(s < FLAT, 0.0, np.where(s > FLAT + arc, GAP, r * (1 - np.cos(theta))))
    return np.column_stack([x, points[:, 1], z]), triangles, s


@pytest.mark.parametrize("self_contact", [True, False])
def test_folded_strip_falls_onto_itself_without_passing_through(self_contact):
    """The bottom layer and the fold held (pinned), the top layer swings down onto the bottom one under gravity."""
    points, triangles, s = _hairpin()
    model = cloth_mesh(points, triangles, **SHEET)
    held = s < FLAT + np.pi * GAP / 2 + 1e-9
    h, k = 0.01, 50.0
    forces = [Gravity(), Drag(rate=1.0)]
    if self_contact:
        contact = ClothSelfContactForce(model, triangles, thickness=h, stiffness=k)
        forces.append(contact)
    scene = Scene(model, forces=forces, pins=Pins(np.flatnonzero(held)))
    lowest = []

    def watch(state):
        # The signed distance of each top-layer node over the bottom layer (flat, z = 0, normal +z).
        top = state.x[~held]
        over = (top[:, 0] > 0) & (top[:, 0] < FLAT) & (top[:, 1] > 0) & (top[:, 1] < WIDTH)
        if over.any():
            lowest.append(top[over, 2].min())

    state = run(scene, scene.initial_state(), steps=200, dt=0.0025, each=watch)
    if self_contact:
        # No top-layer node ever crossed the bottom layer, nor came within the thickness by more than the
        # impact's depth (measured 1.5 mm of 10 mm) ...
        assert min(lowest) > 0
        # ... and at rest it lies at the thickness less its weight over k (4e-5 m): to 1e-4 m for the drag's
        # leftover motion (largest speed 0.03 m/s at 0.5 s).
        top = state.x[~held]
        assert np.abs(top[top[:, 0] < FLAT - 0.05, 2] - h).max() < 1e-4 + model.masses.max() * G / k
    else:
        # Negative control: without self-contact the top layer swings through the bottom one (measured -0.38 m).
        assert min(lowest) < -0.1


def test_self_contact_forces_cancel_and_the_jacobian_matches():
    rng = np.random.default_rng(5)
    points, triangles, s = _hairpin()
    model = cloth_mesh(points, triangles, **SHEET)
    contact = ClothSelfContactForce(model, triangles, thickness=0.01, stiffness=50.0, damping=0.0)
    x = np.array(points)
    top = s > FLAT + np.pi * GAP / 2 + 1e-9
    x[top, 2] = 0.006  # the top layer lowered flat into the thickness: 4 mm deep
    found = contact.contacts(x)
    # Every top vertex over the bottom layer is 6 mm above it: 4 mm deep (the one at the fold is nearer the arc).
    top_depths = found.depth[np.isin(found.vertex, np.flatnonzero(top))]
    assert found.count > 100 and np.median(top_depths) == pytest.approx(0.004)
    forces = np.zeros_like(x)
    x_moved = x + rng.normal(scale=1e-3, size=x.shape)  # and at positions that are not flat
    contact.accumulate(model, x_moved, rng.normal(scale=0.1, size=x.shape), 0.0, forces)
    # Equal and opposite: the stencil weights (1, -b) sum to zero, round-off of sums of ~1e-1 N.
    assert contact.contacts(x_moved).count > 100
    assert np.abs(forces.sum(axis=0)).max() < 1e-14 * np.abs(forces).sum()
    # Moving the top layer along its normal keeps every nearest point on the flat layers: the linearisation is
    # exact there, to the central difference's round-off (1e-6 of k). Near the fold (5 cm) the triangles are
    # tilted and the nearest points move (measured 1 N/m of 100 off: the reweighting the Jacobian leaves out).
    dfdx, _ = contact.jacobian(model, x, np.zeros_like(x), 0.0)
    dx = np.zeros_like(x)
    dx[top, 2] = 1.0
    expected = directional_derivative(contact, model, x, np.zeros_like(x), dx=dx)
    flat = points[:, 0] < FLAT - 0.05
    np.testing.assert_allclose((dfdx @ dx.ravel()).reshape(-1, 3)[flat], expected[flat], atol=1e-6 * 50.0)
    assert np.abs(expected).max() > 1.0  # the layers press on each other: k per metre, not nothing


def test_self_contact_refuses_a_thickness_above_the_rest_spacing():
    points, triangles = sheet_grid(1.0, 1.0, 4, 4)
    sheet = cloth_grid(1.0, 1.0, 4, 4, **SHEET)
    # Vertex (i, j + 1) is 0.25 / sqrt(2) = 0.177 m from the triangle across the cell's diagonal.
    ClothSelfContactForce(sheet, triangles, thickness=0.17, stiffness=1.0)
    with pytest.raises(ValueError, match=r"thickness = 0.18 m, but at rest vertex \d+ is 0.176777 m from triangle"):
        ClothSelfContactForce(sheet, triangles, thickness=0.18, stiffness=1.0)
