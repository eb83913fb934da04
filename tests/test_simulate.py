"""simulate(): frames and callback, early stop, recorded diagnostics, divergence detection, guard."""

import math
import warnings

import numpy as np
import pytest

from volspring import Drag, Gravity, Material, Pins, Scene, Model
from volspring.errors import SimulationDiverged, StepTooLarge, StepTooLargeWarning, TetsInvertedWarning
from volspring.integrators import make_integrator
from volspring.simulate import SimulationResult, simulate
from volspring.stability import critical_step, omega_max_estimate

from conftest import cube_mesh

SOFT = Material(E=1e5, nu=0.3, density=1000.0)


def pair_scene():
    return Scene(Model.from_arrays([[0, 0, 0], [1, 0, 0]], [1.0, 3.0], [[0, 1]], stiffness=100.0))


def stretched(scene):
    return scene.initial_state(x=[[-0.075, 0, 0], [1.025, 0, 0]])


def test_frames_fall_on_multiples_of_frame_dt():
    scene, seen = pair_scene(), []
    result = simulate(scene, "verlet", duration=0.1, dt=1e-3, frame_dt=0.01, state=stretched(scene),
                      callback=lambda index, state: seen.append((index, state.t, state.step)))
    assert isinstance(result, SimulationResult)
    assert [index for index, _, _ in seen] == list(range(11))
    # t accumulates by t += dt, so frame times match k * frame_dt up to round-off (1e-12 s).
    np.testing.assert_allclose([t for _, t, _ in seen], np.arange(11) * 0.01, rtol=0, atol=1e-12)
    assert [step for _, _, step in seen] == list(range(0, 101, 10))
    np.testing.assert_array_equal(result.time, [t for _, t, _ in seen])
    assert result.steps_taken == 100 and result.state.step == 100 and not result.stopped_early
    assert result.linear_momentum.shape == (11, 3) and result.angular_momentum.shape == (11, 3)
    np.testing.assert_array_equal(result.total_energy, result.kinetic_energy + result.potential_energy)


@pytest.mark.parametrize("energy_limit", [None, math.inf, 1e6])
def test_frame_energies_are_those_of_the_frame_state(energy_limit):
    scene = pair_scene()
    result = simulate(scene, "midpoint", duration=0.05, dt=1e-3, frame_dt=0.01, state=stretched(scene),
                      energy_limit=energy_limit)
    final = result.state
    assert result.kinetic_energy[-1] == scene.kinetic_energy(final.v)  # same computation, same bits
    assert result.potential_energy[-1] == scene.potential_energy(final.x, final.t)
    assert result.potential_energy[0] == pytest.approx(0.5 * 100.0 * 0.1**2, rel=1e-12)  # k u0^2 / 2


def test_every_step_is_a_frame_without_frame_dt_and_odd_frame_dt_takes_the_next_step():
    scene = pair_scene()
    every = simulate(scene, "rk4", duration=0.02, dt=1e-3, state=stretched(scene))
    assert every.frame_count == 21 and np.array_equal(every.step, np.arange(21))
    odd = simulate(scene, "rk4", duration=0.05, dt=1e-3, frame_dt=0.0125, state=stretched(scene))
    # Frames at the first step reaching k * 12.5 ms: steps 13, 25, 38, 50.
    assert odd.step.tolist() == [0, 13, 25, 38, 50]


def test_duration_not_a_multiple_of_dt_ends_one_step_past_it():
    scene = pair_scene()
    result = simulate(scene, "symplectic_euler", duration=0.0105, dt=1e-3, state=stretched(scene))
    assert result.steps_taken == 11 and result.state.t == pytest.approx(0.011, abs=1e-15)


def test_callback_stops_the_run_by_returning_false_only():
    scene = pair_scene()
    result = simulate(scene, "verlet", duration=1.0, dt=1e-3, frame_dt=0.01, state=stretched(scene),
                      callback=lambda index, state: index < 3)
    assert result.stopped_early and result.frame_count == 4 and result.state.step == 30
    # None (or 0) is not False: the run goes on.
    result = simulate(scene, "verlet", duration=0.05, dt=1e-3, frame_dt=0.01, state=stretched(scene),
                      callback=lambda index, state: None)
    assert not result.stopped_early and result.frame_count == 6


def test_resumed_run_is_bit_identical():
    scene = pair_scene()
    straight = simulate(scene, "verlet", duration=0.1, dt=1e-3, state=stretched(scene))
    first = simulate(scene, "verlet", duration=0.05, dt=1e-3, state=stretched(scene))
    second = simulate(scene, "verlet", duration=0.05, dt=1e-3, state=first.state)
    assert np.array_equal(second.state.x, straight.state.x) and np.array_equal(second.state.v, straight.state.v)
    assert second.state.t == straight.state.t and second.state.step == straight.state.step


def falling_body():
    mesh = cube_mesh((2, 2, 2), size=(0.1, 0.1, 0.1))
    model = Model.from_mesh(mesh, SOFT)
    scene = Scene(model, forces=[Gravity()])
    rng = np.random.default_rng(0)
    state = scene.initial_state(v=0.05 * rng.standard_normal((model.node_count, 3)))
    return scene, state, 0.5 * critical_step("verlet", omega_max_estimate(scene))


def test_recorded_energy_of_a_conservative_run():
    scene, state, dt = falling_body()
    result = simulate(scene, "rk4", duration=400 * dt, dt=dt, frame_dt=20 * dt, state=state)
    assert result.frame_count == 21
    scale = result.kinetic_energy[0] + scene.model.total_mass * 9.81 * 0.1  # kinetic + M g (body size)
    # RK4 at h omega_max = 1 loses energy slowly (its |R| < 1 damps the fast modes): measured 0.2% of
    # the scale; 1% would still catch a missing potential term (gravity alone changes 25x the scale).
    assert np.abs(result.total_energy - result.total_energy[0]).max() <= 0.01 * scale
    assert result.potential_energy[-1] < result.potential_energy[0] - 20 * scale  # it did fall


def test_recorded_momenta_of_a_falling_spinning_body():
    scene, state, dt = falling_body()
    result = simulate(scene, "verlet", duration=400 * dt, dt=dt, frame_dt=20 * dt, state=state)
    mass = scene.model.total_mass
    # Gravity changes the momentum by M g t (only z); x and y stay put to round-off. Verlet's velocity
    # is the backward difference, exact at t - h/2 (volspring.integrators.verlet), hence the half step.
    lag = np.where(result.step > 0, 0.5 * dt, 0.0)
    expected_pz = result.linear_momentum[0, 2] - mass * 9.81 * (result.time - lag)
    # Round-off of sums of ~27 terms of size up to M |v| ~ 8 kg m/s: ~1e-14; measured 2.5e-13.
    np.testing.assert_allclose(result.linear_momentum[:, 2], expected_pz, rtol=0, atol=1e-12)
    np.testing.assert_allclose(result.linear_momentum[:, :2], np.broadcast_to(result.linear_momentum[0, :2], (21, 2)),
                               rtol=0, atol=1e-13)
    # Uniform gravity exerts no torque about the centre of mass, and L is an exact Verlet invariant.
    # |L| = 2.3e-4 is small next to the falling body's M |x| |v| ~ 20, so round-off is eps x 20 / 2.3e-4
    # ~ 2e-11 of it (measured 1.8e-11); RK4 here drifts by 8e-4, so 1e-9 separates the two.
    reference = np.abs(result.angular_momentum[0]).max()
    np.testing.assert_allclose(result.angular_momentum, np.broadcast_to(result.angular_momentum[0], (21, 3)),
                               rtol=0, atol=1e-9 * reference)


def blowing_up(factor=1.05):
    mesh = cube_mesh((2, 2, 2), size=(0.1, 0.1, 0.1))
    scene = Scene(Model.from_mesh(mesh, Material(E=1e9, nu=0.3, density=1000.0)))
    v0 = 1e-3 * np.random.default_rng(2).standard_normal((scene.model.node_count, 3))
    return scene, scene.initial_state(v=v0), factor * critical_step("symplectic_euler", omega_max_estimate(scene))


def test_blow_up_raises_simulation_diverged_and_no_nan_reaches_the_callback():
    scene, state, dt = blowing_up()
    seen = []

    def callback(index, current):
        assert np.isfinite(current.x).all() and np.isfinite(current.v).all()
        seen.append(current.step)

    with pytest.raises(SimulationDiverged, match="runaway energy") as caught:
        simulate(scene, "symplectic_euler", duration=1000 * dt, dt=dt, state=state, callback=callback, guard="off")
    error = caught.value
    # Caught by the energy check long before NaN (which takes ~200 steps at 1.05x).
    assert 1 <= error.step < 200 and error.step == seen[-1] + 1
    assert error.time == pytest.approx(error.step * dt, rel=1e-9) and error.dt == dt
    assert 0 <= error.node < scene.model.node_count
    assert f"step {error.step}" in str(error)


def test_runaway_is_caught_between_frames_too():
    scene, state, dt = blowing_up()
    with pytest.raises(SimulationDiverged, match="runaway energy") as caught:
        simulate(scene, "verlet", duration=1000 * dt, dt=dt, state=state, frame_dt=500 * dt, guard="off")
    # Checked every ENERGY_CHECK_INTERVAL = 8 steps between frames, long before NaN (~200 steps).
    assert caught.value.step % 8 == 0 and caught.value.step < 100


def test_nan_is_reported_when_the_energy_check_is_off():
    scene, state, dt = blowing_up()
    with np.errstate(all="ignore"), pytest.raises(SimulationDiverged, match="not finite") as caught:
        simulate(scene, "symplectic_euler", duration=1000 * dt, dt=dt, state=state, guard="off",
                 energy_limit=math.inf)
    assert caught.value.step > 1


def test_energy_limit():
    scene, state, dt = blowing_up(0.5)
    with pytest.raises(SimulationDiverged, match="above energy_limit"):
        simulate(scene, "symplectic_euler", duration=10 * dt, dt=dt, state=state, energy_limit=1e-12)


def test_no_false_runaway_for_a_damped_falling_body_and_drag():
    mesh = cube_mesh((2, 1, 1), size=(0.2, 0.1, 0.1))
    model = Model.from_mesh(mesh, SOFT, damping_ratio=0.1)
    scene = Scene(model, forces=[Gravity(), Drag(rate=5.0)],
                  pins=Pins(np.flatnonzero(mesh.points[:, 0] == 0)))
    dt = 0.5 * critical_step("symplectic_euler", omega_max_estimate(scene))
    result = simulate(scene, "symplectic_euler", duration=300 * dt, dt=dt, frame_dt=100 * dt)
    assert result.steps_taken == 300 and np.isfinite(result.total_energy).all()


def test_guard_stops_before_the_first_step():
    scene, state, dt = blowing_up(1.05)
    calls = []
    with pytest.raises(StepTooLarge, match="above the critical step"):
        simulate(scene, "verlet", duration=10 * dt, dt=dt, state=state, guard="raise",
                 callback=lambda *args: calls.append(args))
    assert calls == []  # nothing ran, not even frame 0
    with pytest.warns(StepTooLargeWarning):
        with pytest.raises(SimulationDiverged):
            simulate(scene, "verlet", duration=1000 * dt, dt=dt, state=state, guard="warn")
    scene, state, dt = blowing_up(0.95)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        simulate(scene, "verlet", duration=10 * dt, dt=dt, state=state, guard="raise")


@pytest.mark.parametrize("options, message", [
    ({"duration": 1.0, "dt": 0.0}, "dt = 0.0 s is not a finite number > 0"),
    ({"duration": -1.0, "dt": 1e-3}, "duration = -1.0 s"),
    ({"duration": 1.0, "dt": 1e-3, "frame_dt": -0.1}, "frame_dt = -0.1 s"),
    ({"duration": 1.0, "dt": 1e-3, "guard": "loud"}, "guard = 'loud'"),
])
def test_bad_arguments_are_named(options, message):
    with pytest.raises(ValueError, match=message):
        simulate(pair_scene(), make_integrator("rk4"), **options)
    with pytest.raises(ValueError, match="unknown integrator 'euler2'"):
        simulate(pair_scene(), "euler2", duration=1.0, dt=1e-3)


def test_inverted_tets_are_reported_per_frame_with_one_warning():
    # A soft hanging beam (E = 1e4 Pa) turns tets inside out: the issue saw 76 of 821 at t = 1 s.
    mesh = cube_mesh((8, 2, 2), size=(1.0, 0.1, 0.1))
    model = Model.from_mesh(mesh, Material(E=1e4, nu=0.45, density=1100.0), damping_ratio=0.05)
    scene = Scene(model, forces=[Gravity()], pins=Pins(np.flatnonzero(mesh.points[:, 0] == 0)))
    with pytest.warns(TetsInvertedWarning, match=r"\d+ of 192 tets are inverted") as caught:
        result = simulate(scene, "implicit_euler", duration=1.0, dt=0.01, frame_dt=0.1)
    assert len([w for w in caught if issubclass(w.category, TetsInvertedWarning)]) == 1  # once per run
    assert result.inverted_tets[0] == 0 and result.worst_volume_ratio[0] == pytest.approx(1.0)
    assert result.inverted_tets.max() > 0 and result.worst_volume_ratio.min() < 0
    # The count is that of the frame's own state.
    from volspring.diagnostics import tet_inversion
    assert tet_inversion(scene, result.state.x).count == result.inverted_tets[-1]


def test_a_stiff_run_reports_no_inverted_tets():
    mesh = cube_mesh((4, 1, 1), size=(0.4, 0.1, 0.1))
    model = Model.from_mesh(mesh, Material(E=1e7, nu=0.3, density=1000.0), damping_ratio=0.05)
    scene = Scene(model, forces=[Gravity()], pins=Pins(np.flatnonzero(mesh.points[:, 0] == 0)))
    with warnings.catch_warnings():
        warnings.simplefilter("error", TetsInvertedWarning)
        result = simulate(scene, "implicit_euler", duration=0.1, dt=0.01)
    assert not result.inverted_tets.any() and result.worst_volume_ratio.min() > 0.9


def test_the_start_state_is_checked_against_the_scene():
    scene = pair_scene()
    other = Scene(Model.from_arrays([[0, 0, 0], [1, 0, 0], [2, 0, 0]], [1.0] * 3, [[0, 1], [1, 2]],
                                          stiffness=1.0))
    with pytest.raises(ValueError, match=r"state.x has shape \(3, 3\), but the scene's model has 2 nodes"):
        simulate(scene, "verlet", duration=0.1, dt=0.01, state=other.initial_state())
    bad = scene.initial_state()
    bad = bad.replace(v=np.array([[0.0, 0.0, 0.0], [np.nan, 0.0, 0.0]]))
    with pytest.raises(ValueError, match=r"state.v\[1\] = \[nan, 0.0, 0.0\] m/s is not finite"):
        simulate(scene, "implicit_euler", duration=0.1, dt=0.01, state=bad)


def test_numpy_steps_are_numbers_and_bools_are_not():
    result = simulate(pair_scene(), "verlet", duration=np.int64(1), dt=np.float32(0.125))  # below the limit 0.17
    assert result.steps_taken == 8
    with pytest.raises(TypeError, match="dt = True is not a real number"):
        simulate(pair_scene(), "verlet", duration=1.0, dt=True)
