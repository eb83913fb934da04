"""Explicit and Verlet integrators: period, convergence order, momenta, stability limits, pins, history."""

import math

import numpy as np
import pytest

from volspring import Gravity, Material, Pins, Scene, Model, State
from volspring.diagnostics import angular_momentum, linear_momentum
from volspring.errors import SimulationDiverged
from volspring.integrators import (INTEGRATORS, RK4, ExplicitEuler, Midpoint, PositionVerlet, SymplecticEuler,
                                   TimeCorrectedVerlet, integrator_class, make_integrator)
from volspring.stability import critical_step, growth_per_step, omega_max_estimate

from conftest import cube_mesh

EXPLICIT = ["explicit_euler", "symplectic_euler", "midpoint", "rk4", "verlet", "time_corrected_verlet"]
BOUNDED = ["symplectic_euler", "verlet", "time_corrected_verlet", "rk4"]  # stability_limit > 0
SOFT = Material(E=1e5, nu=0.3, density=1000.0)
STIFF = Material(E=1e9, nu=0.3, density=1000.0)

# Two masses on one spring along x: u = l - l0 obeys mu u'' = -k u exactly (motion stays on the axis).
M1, M2, K, L0, U0 = 1.0, 3.0, 100.0, 1.0, 0.1
MU = M1 * M2 / (M1 + M2)
OMEGA = math.sqrt(K / MU)


def two_body_scene():
    return Scene(Model.from_arrays([[0, 0, 0], [L0, 0, 0]], [M1, M2], [[0, 1]], stiffness=K))


def two_body_exact(t):
    """Positions at time t for a release at rest with stretch U0 (centre of mass fixed at x = 3/4 L0)."""
    u = U0 * math.cos(OMEGA * t)
    return np.array([[-M2 / (M1 + M2) * u, 0, 0], [L0 + M1 / (M1 + M2) * u, 0, 0]])


def run(integrator, scene, state, steps):
    for dt in steps:
        state = integrator.step(scene, state, dt)
    return state


# ---------------------------------------------------------------- registry
def test_registry_names_classes_and_errors():
    assert [integrator_class(name).name for name in EXPLICIT] == EXPLICIT
    assert isinstance(make_integrator("RK4"), RK4)
    assert isinstance(make_integrator("Time-Corrected-Verlet"), TimeCorrectedVerlet)
    assert isinstance(make_integrator("position_verlet"), PositionVerlet)
    assert "implicit_euler" in INTEGRATORS
    with pytest.raises(ValueError, match="unknown integrator 'leapfrog'; known: explicit_euler, symplectic_euler"):
        make_integrator("leapfrog")
    with pytest.raises(TypeError, match="'rk4' does not take options"):
        make_integrator("rk4", tolerance=1e-3)


def test_class_attributes_follow_the_reference_table():
    # REFERENCE.md section 3, stability table (undamped, h omega).
    table = {ExplicitEuler: (1, 0.0), SymplecticEuler: (1, 2.0), Midpoint: (2, 0.0), RK4: (4, 2 * math.sqrt(2)),
             PositionVerlet: (2, 2.0), TimeCorrectedVerlet: (2, 2.0)}
    for cls, (order, limit) in table.items():
        assert (cls.order, cls.stability_limit, cls.explicit) == (order, limit, True)


# ---------------------------------------------------------------- two masses on one spring
def discrete_period_ratio(name, z):
    """Period of the scheme's discrete oscillation over 2 pi / omega: z / arg(eigenvalue of one step)."""
    if name in ("symplectic_euler", "verlet", "time_corrected_verlet"):
        theta = math.acos(1 - z * z / 2)
    elif name == "explicit_euler":
        theta = math.atan(z)
    elif name == "midpoint":
        theta = math.atan2(z, 1 - z * z / 2)
    else:
        theta = np.angle(1 + 1j * z - z**2 / 2 - 1j * z**3 / 6 + z**4 / 24)
    return z / theta


@pytest.mark.parametrize("name", EXPLICIT)
def test_two_body_period(name):
    scene, integrator = two_body_scene(), make_integrator(name)
    period = 2 * math.pi * math.sqrt(MU / K)
    dt = period / 200
    state = scene.initial_state(x=two_body_exact(0.0))
    times, stretch = [0.0], [U0]
    for _ in range(1000):  # 5 periods
        state = integrator.step(scene, state, dt)
        times.append(state.t)
        stretch.append(state.x[1, 0] - state.x[0, 0] - L0)
    times, stretch = np.array(times), np.array(stretch)
    down = np.flatnonzero((stretch[:-1] > 0) & (stretch[1:] <= 0))
    crossings = times[down] - stretch[down] * dt / (stretch[down + 1] - stretch[down])
    measured = (crossings[-1] - crossings[0]) / (len(crossings) - 1)
    assert len(crossings) == 5
    # Against the physics: the worst scheme here, explicit Euler, runs slow by z^2/3 = 3.3e-4 at z = 2 pi / 200.
    assert measured == pytest.approx(period, rel=5e-4)
    # Against the scheme's own discrete frequency: only the linear interpolation of the zero crossings
    # differs, O(z^3) ~ 3e-5 of a step, i.e. ~1e-7 of a period.
    assert measured / period == pytest.approx(discrete_period_ratio(name, OMEGA * dt), rel=1e-6)


# Step counts per scheme keep h omega in its asymptotic range (0.003-0.46) with errors well above
# round-off (RK4's smallest is 7e-8 m); explicit Euler needs small steps or its growth dominates.
ORDER_CASES = [("explicit_euler", 1, [500, 1000, 2000, 4000]), ("symplectic_euler", 1, [100, 200, 400, 800]),
               ("midpoint", 2, [50, 100, 200, 400]), ("rk4", 4, [25, 50, 100, 200]),
               ("verlet", 2, [50, 100, 200, 400]), ("time_corrected_verlet", 2, [50, 100, 200, 400])]


def fitted_order(steps, errors):
    return np.polyfit(np.log(steps), np.log(errors), 1)[0]


@pytest.mark.parametrize("name, order, counts", ORDER_CASES)
def test_convergence_order(name, order, counts):
    scene, integrator, end = two_body_scene(), make_integrator(name), 1.0
    errors = []
    for count in counts:
        state = run(integrator, scene, scene.initial_state(x=two_body_exact(0.0)), [end / count] * count)
        assert state.t == pytest.approx(end, rel=1e-12)
        errors.append(np.abs(state.x - two_body_exact(end)).max())
    # The fitted slope tends to the order as h -> 0; at these steps the next error term moves it by
    # at most 0.06 (measured 1.02, 1.04, 2.03, 4.06, 2.00, 2.00); 0.15 still rejects any other order.
    assert fitted_order(end / np.array(counts), errors) == pytest.approx(order, abs=0.15)


def test_time_corrected_verlet_stays_second_order_with_varying_steps():
    scene, end = two_body_scene(), 1.0
    errors, sizes = [], []
    for cycles in (20, 40, 80, 160):
        h = end / (3 * cycles)
        steps = np.tile([1.0, 0.5, 1.5], cycles) * h  # the step jumps by factors of 2 and 3
        state = run(TimeCorrectedVerlet(), scene, scene.initial_state(x=two_body_exact(0.0)), steps)
        errors.append(np.abs(state.x - two_body_exact(end)).max())
        sizes.append(h)
    # Same band as the constant-step fit above.
    assert fitted_order(sizes, errors) == pytest.approx(2, abs=0.15)
    with pytest.raises(ValueError, match="PositionVerlet needs a fixed step"):
        run(PositionVerlet(), scene, scene.initial_state(), [1e-3, 2e-3])


@pytest.mark.parametrize("name", ["explicit_euler", "midpoint", "rk4"])
def test_energy_growth_per_step_matches_stability_theory(name):
    # For these schemes one step on mu u'' = -k u is a rotation times growth_per_step(h omega) in the
    # coordinates (omega u, u'), so the energy scales by its square every step, exactly. At z = 0.3,
    # 40 steps, Euler's amplitude grows 5.6x to 0.56 m < L0, so the spring never flips (stays linear).
    scene, z, count = two_body_scene(), 0.3, 40
    state = run(make_integrator(name), scene, scene.initial_state(x=two_body_exact(0.0)), [z / OMEGA] * count)
    energy = scene.kinetic_energy(state.v) + scene.potential_energy(state.x)
    expected = 0.5 * K * U0**2 * growth_per_step(name, z) ** (2 * count)
    assert energy == pytest.approx(expected, rel=1e-10)  # round-off over 40 steps only


# ---------------------------------------------------------------- invariants on a 3D body
def random_body(seed=0, *, damping_ratio=0.05):
    model = Model.from_mesh(cube_mesh((2, 2, 2), size=(0.1, 0.1, 0.1)), SOFT, damping_ratio=damping_ratio)
    rng = np.random.default_rng(seed)
    x = model.rest_positions + 1e-3 * rng.standard_normal((model.node_count, 3))
    v = 0.1 * rng.standard_normal((model.node_count, 3)) + [0.3, -0.2, 0.1]
    return Scene(model), x, v


@pytest.mark.parametrize("name", EXPLICIT)
def test_linear_momentum_is_conserved_without_external_force(name):
    scene, x, v = random_body()
    # 0.1 / omega_max: small enough that explicit Euler grows only by (1.01)^(100/2) = 1.6.
    dt = 0.1 / omega_max_estimate(scene)
    state = scene.initial_state(x=x, v=v)
    start = linear_momentum(scene, state)
    state = run(make_integrator(name), scene, state, [dt] * 100)
    scale = scene.model.masses @ np.linalg.norm(v, axis=1)
    # Forces cancel in pairs up to round-off: measured drift 1e-16 of the momentum scale for the one-step
    # schemes, 4e-14 for the Verlet family (their velocity is a difference of positions, which costs
    # |x| / |h v| ~ 100x in relative precision); 1e-12 leaves 25x on top. A scheme that did not conserve
    # momentum would miss by its truncation error, O(h omega) = 0.1 here.
    assert np.abs(linear_momentum(scene, state) - start).max() <= 1e-12 * scale


@pytest.mark.parametrize("name, conserves", [("symplectic_euler", True), ("verlet", True),
                                             ("time_corrected_verlet", True), ("explicit_euler", False),
                                             ("midpoint", False), ("rk4", False)])
def test_angular_momentum_of_a_spinning_body(name, conserves):
    scene, x, v = random_body(1)
    centre = scene.model.masses @ x / scene.model.total_mass
    v = v + np.cross([0.0, 0.0, 20.0], x - centre)  # spin at 20 rad/s about z
    state = scene.initial_state(x=x, v=v)
    start = angular_momentum(scene, state)
    h = 0.3 / omega_max_estimate(scene)
    steps = [h] * 200 if name != "time_corrected_verlet" else list(np.tile([h, 0.5 * h, 1.5 * h], 67))
    state = run(make_integrator(name), scene, state, steps)
    drift = np.linalg.norm(angular_momentum(scene, state) - start) / np.linalg.norm(start)
    if conserves:
        # Symplectic Euler and the Verlet family conserve sum m x x v exactly for central pair forces
        # (springs and dampers); what is left is round-off: eps x 200 steps x a few terms ~ 1e-13.
        assert drift <= 1e-11
    else:
        # The others change it by O(h^p) per step: measured 1e-3 (Euler) to 1e-7 (RK4) here, so
        # this checks that the test above can tell the difference.
        assert drift > 1e-9


# ---------------------------------------------------------------- stability at the limit
def stiff_scene(pinned):
    mesh = cube_mesh((2, 2, 2), size=(0.1, 0.1, 0.1))
    model = Model.from_mesh(mesh, STIFF)
    pins = Pins(np.flatnonzero(mesh.points[:, 0] == 0)) if pinned else None
    return Scene(model, pins=pins)


@pytest.mark.parametrize("pinned", [False, True])
@pytest.mark.parametrize("name", BOUNDED)
def test_explicit_schemes_are_stable_just_below_the_limit_and_blow_up_just_above(name, pinned):
    scene = stiff_scene(pinned)
    critical = critical_step(name, omega_max_estimate(scene))
    v0 = 1e-3 * np.random.default_rng(2).standard_normal((scene.model.node_count, 3))  # linear regime

    def energies(factor, count=300):
        integrator, state, energy = make_integrator(name), scene.initial_state(v=v0), []
        with np.errstate(all="ignore"):
            for _ in range(count):
                state = integrator.step(scene, state, factor * critical)
                energy.append(scene.kinetic_energy(state.v) + scene.potential_energy(state.x))
        return np.array(energy)

    below = energies(0.95)
    # Inside the limit every mode keeps (or, for RK4, loses) amplitude: the last 100 steps hold no more
    # energy than the first 100, up to the oscillation of the discrete energy between samples (measured
    # ratios 0.2-1.01); 1.5 leaves room for that and is far from geometric growth.
    assert below[-100:].max() <= 1.5 * below[:100].max()
    # Beyond it the fastest mode grows by 1.9 (Verlet family) or 1.4 (RK4) per step: NaN within 300 steps.
    with pytest.raises(SimulationDiverged):
        energies(1.05)


# ---------------------------------------------------------------- pins and projections
@pytest.mark.parametrize("name", EXPLICIT)
def test_pinned_nodes_never_move(name):
    mesh = cube_mesh((3, 1, 1), size=(0.3, 0.1, 0.1))
    model = Model.from_mesh(mesh, SOFT, damping_ratio=0.2)
    pinned = np.flatnonzero(mesh.points[:, 0] == 0)
    scene = Scene(model, forces=[Gravity()], pins=Pins(pinned))
    state = run(make_integrator(name), scene, scene.initial_state(), [0.3 / omega_max_estimate(scene)] * 50)
    assert np.array_equal(state.x[pinned], model.rest_positions[pinned])  # exactly, not approximately
    assert not state.v[pinned].any()
    assert np.abs(state.x[~scene.free] - model.rest_positions[~scene.free]).max() == 0.0
    assert np.abs(state.x - model.rest_positions).max() > 1e-6  # the rest did sag


@pytest.mark.parametrize("name", EXPLICIT)
def test_moving_pins_follow_their_motion_exactly(name):
    mesh = cube_mesh((2, 1, 1), size=(0.2, 0.1, 0.1))
    model = Model.from_mesh(mesh, SOFT)
    pinned = np.flatnonzero(mesh.points[:, 0] == 0)
    rest = model.rest_positions[pinned]
    pins = Pins(pinned, motion=lambda t: rest + [0.0, 0.0, 0.01 * math.sin(30 * t)],
                velocity=lambda t: np.broadcast_to([0.0, 0.0, 0.3 * math.cos(30 * t)], rest.shape))
    scene = Scene(model, pins=pins)
    state = run(make_integrator(name), scene, scene.initial_state(), [0.2 / omega_max_estimate(scene)] * 40)
    assert np.array_equal(state.x[pinned], pins.positions(model.rest_positions, state.t))


class _FloorPositionsOnly:
    """Test obstacle: the plane z = 0, projecting positions and leaving velocities alone."""

    def project(self, x, v, x_start, t, dt, free):
        below = free & (x[:, 2] < 0)
        x[below, 2] = 0.0


class _FloorStopsVelocity(_FloorPositionsOnly):
    """Test obstacle: also sets the normal velocity of projected nodes to 0 (inelastic contact)."""

    def project(self, x, v, x_start, t, dt, free):
        below = free & (x[:, 2] < 0)
        x[below, 2] = 0.0
        v[below, 2] = 0.0


@pytest.mark.parametrize("name", ["verlet", "time_corrected_verlet"])
def test_verlet_history_stays_consistent_after_projection(name):
    model = Model.from_arrays([[0, 0, 0.01], [1, 0, 0.01]], [1.0, 1.0], [[0, 1]], stiffness=10.0)
    dt, integrator = 1e-3, make_integrator(name)
    v_down = [[0.0, 0.0, -20.0], [0.0, 0.0, -20.0]]

    # Positions-only projection: the velocity comes from the projected positions (position-based dynamics).
    scene = Scene(model, obstacles=[_FloorPositionsOnly()])
    state = scene.initial_state(v=v_down)
    before = state
    state = integrator.step(scene, state, dt)  # lands at z = 0.01 - 0.02 < 0, projected to 0
    assert np.array_equal(state.x[:, 2], [0.0, 0.0])
    assert np.array_equal(state.v, (state.x - before.x) / dt)
    # Inelastic floor: the obstacle's velocity (0 in z) is what the next step continues from,
    # so the nodes rest on the floor instead of being pulled back up or down by a stale history.
    scene = Scene(model, obstacles=[_FloorStopsVelocity()])
    state = run(integrator, scene, scene.initial_state(v=v_down), [dt] * 5)
    assert np.array_equal(state.x[:, 2], [0.0, 0.0]) and not state.v[:, 2].any()


def test_verlet_state_resumes_bit_identically_from_a_copy():
    scene, x, v = random_body(3)
    dt, integrator = 0.3 / omega_max_estimate(scene), PositionVerlet()
    straight = run(integrator, scene, scene.initial_state(x=x, v=v), [dt] * 40)
    half = run(integrator, scene, scene.initial_state(x=x, v=v), [dt] * 20)
    # A checkpoint: every array copied, as a writer and reader would.
    copy = State(half.x.copy(), half.v.copy(), half.t, half.step,
                 {key: np.array(value, copy=True) for key, value in half.memory.items()})
    resumed = run(integrator, scene, copy, [dt] * 20)
    assert np.array_equal(resumed.x, straight.x) and np.array_equal(resumed.v, straight.v)


def test_time_corrected_verlet_equals_position_verlet_for_a_constant_step():
    scene, x, v = random_body(4)
    dt = 0.5 / omega_max_estimate(scene)
    a = run(PositionVerlet(), scene, scene.initial_state(x=x, v=v), [dt] * 200)
    b = run(TimeCorrectedVerlet(), scene, scene.initial_state(x=x, v=v), [dt] * 200)
    # Same recursion, operations in a different order: round-off only (eps x |x| ~ 2e-17 m per step,
    # amplified at most linearly by a stable oscillation over 200 steps ~ 1e-14 m).
    assert np.abs(a.x - b.x).max() <= 1e-13


def test_advance_leaves_its_input_state_alone():
    scene, x, v = random_body(5)
    state = run(PositionVerlet(), scene, scene.initial_state(x=x, v=v), [1e-5] * 2)
    frozen = (state.x.copy(), state.v.copy(), {k: np.array(m, copy=True) for k, m in state.memory.items()})
    for name in EXPLICIT:
        make_integrator(name).step(scene, state, 1e-5)
    assert np.array_equal(state.x, frozen[0]) and np.array_equal(state.v, frozen[1])
    assert all(np.array_equal(state.memory[k], frozen[2][k]) for k in frozen[2])


@pytest.mark.parametrize("where, expected", [(("v", 7), 7), (("x", 3), 3), (("x", 9), 9)])
def test_a_non_finite_state_is_refused_naming_its_first_bad_node(where, expected):
    """check_finite, after every step: NaN or Inf in a position or a velocity raises SimulationDiverged naming the
    first node that holds one; a finite state passes."""
    from volspring.integrators.base import check_finite

    x, v = np.zeros((12, 3)), np.ones((12, 3))
    check_finite(State(x.copy(), v.copy(), 0.5, 5), 0.01)
    array, node = where
    (x if array == "x" else v)[node, 1] = np.nan if node != 9 else np.inf
    v[10, 2] = np.inf  # a later bad node is not the one named
    with pytest.raises(SimulationDiverged, match=f"worst node {expected}") as caught:
        check_finite(State(x, v, 0.5, 5), 0.01)
    assert caught.value.node == expected and caught.value.step == 5
