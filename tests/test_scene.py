"""Scene: pins, gravity, drag and what a scene computes when it asks for nothing else."""

import numpy as np
import pytest

from volspring import Drag, Gravity, Material, Pins, Scene, SpringModel
from volspring.springs import spring_forces

from conftest import cube_mesh

RUBBER = Material(E=1e5, nu=0.3, density=1000.0)


@pytest.fixture
def model():
    return SpringModel.from_mesh(cube_mesh((2, 1, 1), size=(0.2, 0.1, 0.1)), RUBBER)


def test_scene_without_forces_computes_springs_only(model):
    scene = Scene(model)
    rng = np.random.default_rng(1)
    x = model.rest_positions + 1e-3 * rng.standard_normal(model.rest_positions.shape)
    v = rng.standard_normal(x.shape)
    assert np.array_equal(scene.forces_at(x, v, 0.0), spring_forces(model, x, v))


def test_gravity_force_and_potential(model):
    g = (0.0, -9.81, 0.0)
    scene = Scene(model, forces=[Gravity(model.masses, g)])
    x = model.rest_positions
    forces = scene.forces_at(x, np.zeros_like(x), 0.0)
    # Springs at rest add nothing; the net force is the weight m_total g to round-off.
    assert np.allclose(forces.sum(axis=0), model.total_mass * np.array(g), rtol=1e-12)
    shifted = x + np.array([0.0, 2.0, 0.0])
    # Raising the body by 2 m costs m g h of potential energy, exactly (springs unchanged).
    assert scene.potential_energy(shifted) - scene.potential_energy(x) == pytest.approx(
        model.total_mass * 9.81 * 2.0, rel=1e-12)


def test_drag_force_and_jacobian(model):
    drag = Drag(model.masses, rate=0.5)
    v = np.ones((model.node_count, 3))
    out = np.zeros_like(v)
    drag.accumulate(None, v, 0.0, out)
    assert np.allclose(out, -0.5 * model.masses[:, None] * v)
    _, dFdv = drag.jacobian(None, v, 0.0)
    assert np.allclose(dFdv @ v.ravel(), out.ravel())
    with pytest.raises(ValueError, match="drag rate = -1"):
        Drag(model.masses, rate=-1.0)


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
