"""Scene: pins, gravity, drag and what a scene computes when it asks for nothing else."""

import numpy as np
import pytest

from volspring import Drag, Gravity, Material, Pins, Scene, Model
from volspring.springs import spring_forces

from conftest import cube_mesh

RUBBER = Material(E=1e5, nu=0.3, density=1000.0)


@pytest.fixture
def model():
    return Model.from_mesh(cube_mesh((2, 1, 1), size=(0.2, 0.1, 0.1)), RUBBER)


def test_scene_without_forces_computes_springs_only(model):
    scene = Scene(model)
    rng = np.random.default_rng(1)
    x = model.rest_positions + 1e-3 * rng.standard_normal(model.rest_positions.shape)
    v = rng.standard_normal(x.shape)
    assert np.array_equal(scene.forces_at(x, v, 0.0), spring_forces(model, x, v))


def test_gravity_force_and_potential(model):
    g = (0.0, -9.81, 0.0)
    scene = Scene(model, forces=[Gravity(g=g)])
    x = model.rest_positions
    forces = scene.forces_at(x, np.zeros_like(x), 0.0)
    # Springs at rest add nothing; the net force is the weight m_total g to round-off.
    assert np.allclose(forces.sum(axis=0), model.total_mass * np.array(g), rtol=1e-12)
    shifted = x + np.array([0.0, 2.0, 0.0])
    # Raising the body by 2 m costs m g h of potential energy, exactly (springs unchanged).
    assert scene.potential_energy(shifted) - scene.potential_energy(x) == pytest.approx(
        model.total_mass * 9.81 * 2.0, rel=1e-12)


def test_drag_force_and_jacobian(model):
    drag = Drag(rate=0.5)
    v = np.ones((model.node_count, 3))
    out = np.zeros_like(v)
    drag.accumulate(model, None, v, 0.0, out)
    assert np.allclose(out, -0.5 * model.masses[:, None] * v)
    _, dFdv = drag.jacobian(model, None, v, 0.0)
    assert np.allclose(dFdv @ v.ravel(), out.ravel())
    with pytest.raises(ValueError, match="drag rate = -1"):
        Drag(rate=-1.0)


def test_pins_hold_rest_or_follow_prescribed_motion(model):
    nodes = np.flatnonzero(model.rest_positions[:, 0] == 0.0)
    still = Scene(model, pins=Pins(nodes))
    state = still.initial_state(x=model.rest_positions + 0.01)
    assert np.array_equal(state.x[nodes], model.rest_positions[nodes])
    assert np.array_equal(state.v[nodes], np.zeros((len(nodes), 3)))
    assert still.accelerations(state.x, state.v, 0.0)[nodes].max() == 0.0

    lift = Pins(nodes, motion=lambda t: model.rest_positions[nodes] + [0.0, 0.0, 0.3 * t**2])
    moving = Scene(model, pins=lift)
    state = moving.initial_state(t=2.0)
    assert np.allclose(state.x[nodes, 2], model.rest_positions[nodes, 2] + 1.2)
    # d/dt (0.3 t^2) = 1.2 m/s at t = 2; central difference of a quadratic is exact up to
    # round-off of (f(t+h) - f(t-h)) / 2h with h = 1e-6: about 1e-16 / 1e-6 = 1e-10 relative.
    assert np.allclose(state.v[nodes, 2], 1.2, rtol=1e-8)


def test_bad_pins_are_refused(model):
    with pytest.raises(ValueError, match="pinned node 999"):
        Scene(model, pins=Pins([999]))
    with pytest.raises(ValueError, match="at least one node"):
        Pins([])
    scene = Scene(model, pins=Pins([0, 1], motion=lambda t: np.zeros((3, 3))))
    with pytest.raises(ValueError, match=r"must return finite values of shape \(2, 3\)"):
        scene.initial_state()


def test_pins_take_a_boolean_mask_checked_against_the_model(model):
    mask = model.rest_positions[:, 0] == 0.0
    pins = Pins(mask)
    assert np.array_equal(pins.nodes, np.flatnonzero(mask))
    assert Scene(model, pins=pins).free.sum() == model.node_count - mask.sum()
    # A mask used to be read as the indices 0 and 1: [True, False] pinned nodes 0 and 1.
    assert Pins([True, False]).nodes.tolist() == [0]
    with pytest.raises(ValueError, match=r"boolean mask of 11 entries, but the model has 12 nodes"):
        Scene(model, pins=Pins(mask[:-1]))
    with pytest.raises(ValueError, match=r"the mask's 12 entries are all False"):
        Pins(np.zeros(model.node_count, dtype=bool))
    with pytest.raises(ValueError, match=r"boolean mask of shape \(3, 4\); expected shape \(n,\)"):
        Pins(mask.reshape(3, 4))


def test_pins_refuse_indices_they_would_misread():
    with pytest.raises(TypeError, match=r"Pins nodes are float64 values, not integer node indices; convert "
                                        r"integer-valued floats with np.asarray\(nodes, dtype=int\)"):
        Pins(np.array([0.0, 3.0]))  # e.g. what np.loadtxt reads
    with pytest.raises(TypeError, match=r"Pins nodes\[1\] = nan is not an integer node index"):
        Pins([1.0, np.nan])
    with pytest.raises(TypeError, match=r"are not integer node indices or a boolean mask \(got dtype <U1\)"):
        Pins(["3"])
    with pytest.raises(ValueError, match=r"Pins nodes\[2\] = -3 is negative"):
        Pins(np.array([4, 5, -3]))


def test_moving_pins_follow_the_order_given(model):
    # motion(t) gives row k for nodes[k]; the nodes used to be sorted, swapping the rows.
    rest = model.rest_positions
    order = [5, 2]
    lift = Pins(order, motion=lambda t: rest[order] + [[0.0, 0.0, 1.0], [0.0, 0.0, 2.0]])
    state = Scene(model, pins=lift).initial_state()
    assert lift.nodes.tolist() == order
    assert state.x[5, 2] == rest[5, 2] + 1.0 and state.x[2, 2] == rest[2, 2] + 2.0  # exact: one addition
    with pytest.raises(ValueError, match=r"Pins nodes\[2\] = 5 is listed twice; with motion= each node must appear once"):
        Pins([5, 2, 5], motion=lambda t: np.zeros((3, 3)))
    with pytest.raises(ValueError, match="velocity= was given without motion="):
        Pins([5], velocity=lambda t: np.zeros((1, 3)))
    with pytest.raises(TypeError, match=r"Pins motion = .* is not callable; expected motion\(t\) -> \(p, 3\)"):
        Pins([5], motion=np.zeros((1, 3)))


def test_scene_refuses_what_it_cannot_use(model):
    gravity = Gravity()
    with pytest.raises(TypeError, match="model must be a volspring Model, got TetMesh"):
        Scene(cube_mesh((1, 1, 1)))
    with pytest.raises(TypeError, match=r"pins = \[0, 1\] is not a volspring Pins; expected e.g. pins=Pins\(\[0, 1\]\)"):
        Scene(model, pins=[0, 1])
    with pytest.raises(TypeError, match=r"forces is a single Gravity; expected a sequence, e.g. forces=\[...\]"):
        Scene(model, forces=gravity)
    with pytest.raises(TypeError, match=r"forces\[1\] = 9.81 has no accumulate\(model, x, v, t, out\) method"):
        Scene(model, forces=[gravity, 9.81])
    with pytest.raises(TypeError, match=r"obstacles\[0\] = 'floor' has no project\(x, v, x_start, t, dt, free\) method"):
        Scene(model, obstacles=["floor"])
    with pytest.raises(ValueError, match=r"forces\[1\] \(Drag\) has 3 masses, but the model has 12 nodes"):
        Scene(model, forces=[gravity, Drag(masses=[1.0, 1.0, 1.0], rate=1.0)])


def test_gravity_and_drag_check_their_input(model):
    with pytest.raises(ValueError, match=r"g = \[0, 0, nan\] is not a finite 3-vector"):
        Gravity(g=[0, 0, np.nan])
    with pytest.raises(ValueError, match=r"masses\[1\] = -1.0 kg is not finite and >= 0"):
        Gravity(masses=[1.0, -1.0])
    with pytest.raises(ValueError, match=r"masses must have shape \(n,\) with n > 0, got \(2, 6\)"):
        Drag(masses=model.masses.reshape(2, 6), rate=1.0)
    with pytest.raises(ValueError, match="drag rate = nan 1/s is not finite and >= 0"):
        Drag(rate=float("nan"))
    # A zero mass exempts a node (e.g. gravity on one body of several); lists are taken, and they
    # override the model's masses (1 kg each here).
    pair = Model.from_arrays([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]], [1.0, 1.0], [], stiffness=1.0)
    partial = Gravity(masses=[0.0, 2.0], g=(0, 0, -1))
    out = np.zeros((2, 3))
    partial.accumulate(pair, None, None, 0.0, out)
    assert out.tolist() == [[0.0, 0.0, 0.0], [0.0, 0.0, -2.0]]


def test_initial_state_and_check_state_refuse_what_does_not_fit(model):
    scene = Scene(model)
    with pytest.raises(ValueError, match=r"^x has shape \(12, 2\), but the scene's model has 12 nodes: expected \(12, 3\)"):
        scene.initial_state(x=model.rest_positions[:, :2])
    with pytest.raises(ValueError, match=r"^v has shape \(3,\)"):
        scene.initial_state(v=[0.0, 0.0, 1.0])
    with pytest.raises(ValueError, match=r"^x\[0\] = \[nan, 0.0, 0.0\] m is not finite \(the position of node 0"):
        scene.initial_state(x=np.where(np.arange(12)[:, None] == 0, [np.nan, 0, 0], model.rest_positions))
    with pytest.raises(TypeError, match=r"^v = array\(shape=\(12, 3\), dtype=<U1\) does not hold real numbers"):
        scene.initial_state(v=np.full((12, 3), "0"))
    with pytest.raises(ValueError, match="t = inf s is not a finite time"):
        scene.initial_state(t=np.inf)
    state = scene.initial_state()
    with pytest.raises(TypeError, match="state must be a volspring State, got tuple"):
        scene.check_state((state.x, state.v))
    with pytest.raises(ValueError, match="state.t = nan s is not a finite time"):
        scene.check_state(state.replace(t=float("nan")))
