"""The divergence check stops true blow-ups and nothing else, at the extremes of step and stiffness.

A run is bounded when its energy stays within what the scene can physically hold: the start energy
plus the work of non-conservative forces and of moving pins. Linearised implicit Euler may overshoot
that for a step or two (its linearisation of a large rotation: 5 kJ of spring energy in the first
step of the README's beam at 1000x the explicit limit) and then settles; an unstable explicit run
grows without end. The check tells the two apart by growth over consecutive checks.
"""

import numpy as np
import pytest

import meshing
from volspring import Gravity, Material, Pins, Scene, SimulationDiverged, Model
from volspring.simulate import simulate
from volspring.stability import critical_step, omega_max_estimate
from volspring.statics import solve_static

MODULI = [1e2, 1e4, 1e6, 1e9, 1e12]  # Pa: a gel to a ceramic
MULTIPLES = [10, 100, 1000, 10000]   # times the explicit limit 2 / omega_max


@pytest.fixture(scope="module")
def beam_mesh():
    # The README's command-line beam: box:1,0.1,0.1 at size 0.05 (258 nodes).
    return meshing.tetrahedralize(meshing.box(1.0, 0.1, 0.1), size=0.05)


def beam_scene(mesh, E, *, motion=None):
    model = Model.from_mesh(mesh, Material(E, 0.45, 1100.0), rule="van_gelder", damping_ratio=0.05)
    clamped = np.flatnonzero(mesh.points[:, 0] < -0.5 + 1e-9)
    return Scene(model, forces=[Gravity()], pins=Pins(clamped, motion=motion))


@pytest.mark.parametrize("E", MODULI)
def test_implicit_euler_far_beyond_the_explicit_limit_is_never_called_diverged(beam_mesh, E):
    scene = beam_scene(beam_mesh, E)
    limit = critical_step("symplectic_euler", omega_max_estimate(scene))
    for multiple in MULTIPLES:
        dt = multiple * limit
        # Every step a frame, so the energy is checked after every step (as volspring-sim does when
        # dt exceeds --frame-dt), the first, overshooting, one included.
        result = simulate(scene, "implicit_euler", duration=40 * dt, dt=dt)
        assert result.steps_taken == 40 and np.isfinite(result.state.x).all()


@pytest.mark.parametrize("E", [1e6, 1e9])
def test_the_readme_beam_settles_on_the_static_answer_at_1000x_and_10000x(beam_mesh, E):
    # The case (E = 1e6, dt = 0.67 s = 1000x) was stopped at step 1 as diverged. At h omega_max
    # >= 2000, implicit Euler damps every mode by 2000x or more a step, so 40 steps leave only the
    # linearisation error: 1.1e-7 m measured against a 0.8 m sag; 1e-5 m allows for other BLAS.
    scene = beam_scene(beam_mesh, E)
    static = solve_static(scene).x
    limit = critical_step("symplectic_euler", omega_max_estimate(scene))
    for multiple in (1000, 10000):
        dt = multiple * limit
        result = simulate(scene, "implicit_euler", duration=40 * dt, dt=dt)
        assert np.abs(result.state.x - static).max() < 1e-5


@pytest.mark.parametrize("E", MODULI)
@pytest.mark.parametrize("integrator", ["symplectic_euler", "verlet"])
def test_explicit_past_its_limit_still_stops_long_before_overflow(beam_mesh, E, integrator):
    scene = beam_scene(beam_mesh, E)
    dt = 1.05 * critical_step(integrator, omega_max_estimate(scene))
    v0 = 1e-3 * np.random.default_rng(2).standard_normal((scene.model.node_count, 3))
    v0[scene.pins.nodes] = 0.0
    with pytest.raises(SimulationDiverged, match="runaway energy") as caught:
        simulate(scene, integrator, duration=2000 * dt, dt=dt, guard="off", state=scene.initial_state(v=v0))
    # Without the check NaN arrives after a few hundred steps; the stops measured here are at steps 9 to
    # 22, so 50 is the bound of "long before overflow" with room for another BLAS.
    assert caught.value.step < 50


def shaken(amplitude, frequency):
    """A pin motion that shakes the clamped end along z (the pins do work on the body)."""
    def motion(t, nodes=None):
        return motion.rest + np.array([0.0, 0.0, amplitude * np.sin(2 * np.pi * frequency * t)])
    return motion


def test_moving_pins_count_their_work(beam_mesh):
    # Shaking the clamp pumps energy in: counted as the pins' work, this is not a runaway
    # (before, the check was simply off whenever pins moved).
    motion = shaken(0.02, 5.0)
    scene = beam_scene(beam_mesh, 1e6, motion=motion)
    motion.rest = scene.model.rest_positions[scene.pins.nodes]
    dt = 0.5 * critical_step("symplectic_euler", omega_max_estimate(scene))
    result = simulate(scene, "symplectic_euler", duration=3000 * dt, dt=dt, frame_dt=100 * dt)
    assert result.steps_taken == 3000
    # ... and a blow-up with moving pins is caught by the energy check, not only by NaN.
    with pytest.raises(SimulationDiverged, match="runaway energy"):
        simulate(scene, "symplectic_euler", duration=3000 * dt, dt=2.1 * dt, frame_dt=100 * dt, guard="off")


@pytest.mark.parametrize("options, message", [
    ({"runaway_factor": 0.0}, "runaway_factor = 0.0 is not > 0"),
    ({"runaway_checks": 0}, "runaway_checks = 0 is not a whole number >= 1"),
    ({"runaway_checks": 2.5}, "runaway_checks = 2.5 is not a whole number >= 1"),
])
def test_bad_check_options_are_named(beam_mesh, options, message):
    with pytest.raises(ValueError, match=message):
        simulate(beam_scene(beam_mesh, 1e6), "implicit_euler", duration=0.01, dt=0.01, **options)
