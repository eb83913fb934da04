"""Force fields: formulas at hand-picked points, impulse = momentum change, Jacobians, user callables."""

import numpy as np
import pytest

from volspring import Material, Scene, Model
from volspring.forces import CallableForce, PointAttractor, PointRepulser, Vortex, Wind
from volspring.springs import spring_forces

from conftest import cube_mesh

RUBBER = Material(E=1e5, nu=0.3, density=1000.0)


@pytest.fixture(scope="module")
def model():
    return Model.from_mesh(cube_mesh((2, 2, 2), size=(0.1, 0.1, 0.1)), RUBBER, damping_ratio=0.05)


def particles(x, masses):
    """A model of free particles at x with these masses (no springs): what a field is evaluated on."""
    return Model.from_arrays(x, masses, [], stiffness=1.0)


def forces_of(field, model, x, v=None, t=0.0):
    out = np.zeros_like(x)
    field.accumulate(model, x, np.zeros_like(x) if v is None else v, t, out)
    return out


# ---------------------------------------------------------------------------- formulas
def test_wind_is_drag_towards_the_gusting_wind_velocity():
    masses = np.array([1.0, 2.0])
    pair = particles(np.zeros((2, 3)), masses)
    wind = Wind(direction=(0.0, 3.0, 4.0), speed=2.0, rate=0.5, gusts=[(1.0, 0.25, 0.0), (0.5, 1.0, np.pi / 2)])
    v = np.array([[0.0, 0.0, 0.0], [1.0, -1.0, 2.0]])
    # At t = 1 s: speed 2 + 1 sin(pi/2) + 0.5 sin(2 pi + pi/2) = 3.5 m/s along (0, 0.6, 0.8).
    w = np.array([0.0, 2.1, 2.8])
    expected = 0.5 * masses[:, None] * (w - v)
    # Exact arithmetic up to a few ulps of the sines.
    assert np.allclose(forces_of(wind, pair, np.zeros((2, 3)), v, t=1.0), expected, rtol=1e-14, atol=1e-14)
    gusty = Wind(direction=(1.0, 0.0, 0.0), speed=lambda t: 3.0 * t, rate=2.0)
    assert np.allclose(forces_of(gusty, pair, np.zeros((2, 3)), t=0.5), [[3.0, 0, 0], [6.0, 0, 0]], rtol=1e-15)
    with pytest.raises(ValueError, match=r"speed\(0.0\) returned"):
        Wind(direction=(1, 0, 0), speed=lambda t: [1.0, 2.0], rate=1.0).accumulate(
            pair, np.zeros((2, 3)), np.zeros((2, 3)), 0.0, np.zeros((2, 3)))


@pytest.mark.parametrize("cls, sign", [(PointAttractor, 1.0), (PointRepulser, -1.0)])
def test_point_fields_inverse_square_and_linear(cls, sign):
    masses = np.array([2.0, 1.0, 1.0])
    x = np.array([[4.0, 1.0, 1.0], [1.0, 1.0, 1.0], [1.0, 1.0, 9.0]])
    # Node 0 at distance 3 from the centre (1, 1, 1); with R = 4, (r^2 + R^2)^(3/2) = 125:
    # a = S d / 125 = 250 * (-3, 0, 0) / 125 = (-6, 0, 0), f = m a = (-12, 0, 0).
    three = particles(x, masses)
    field = cls(centre=(1.0, 1.0, 1.0), strength=250.0, falloff="inverse_square", radius=4.0)
    f = forces_of(field, three, x)
    assert np.allclose(f[0], sign * np.array([-12.0, 0, 0]), rtol=1e-15)
    assert np.array_equal(f[1], np.zeros(3))  # at the centre: d = 0, softened, no force
    # Node 2 at 8 from the centre: a = 250 * 8 / (64 + 16)^1.5 along -z.
    assert np.allclose(f[2], sign * np.array([0, 0, -250.0 * 8 / 80**1.5]), rtol=1e-14)

    linear = cls(centre=(1.0, 1.0, 1.0), strength=10.0, falloff="linear", radius=5.0)
    f = forces_of(linear, three, x)
    # r = 3 < R = 5: |a| = 10 (1 - 3/5) = 4 towards the centre; r = 0 and r = 8 >= R: nothing.
    assert np.allclose(f, sign * np.array([[-8.0, 0, 0], [0, 0, 0], [0, 0, 0]]), rtol=1e-15)


def test_vortex_is_tangential_with_its_peak_at_the_core_radius():
    vortex = Vortex(point=(1.0, 1.0, 0.0), axis=(0.0, 0.0, 2.0), strength=5.0, radius=1.0)
    x = np.array([[1.0, 3.0, 7.0], [2.0, 1.0, -4.0]])
    # Node 0: rho = (0, 2, 0), a x rho = (-2, 0, 0), factor 2 R / (rho^2 + R^2) = 2/5:
    # f = 1 * 5 * 2/5 * (-2, 0, 0) = (-4, 0, 0). Node 1: rho = R = 1, |f| = m S = 15 along +y.
    f = forces_of(vortex, particles(x, [1.0, 3.0]), x)
    assert np.allclose(f, [[-4.0, 0, 0], [0, 15.0, 0]], rtol=1e-15)
    rng = np.random.default_rng(0)
    points = rng.standard_normal((50, 3))
    swirl = Vortex(point=(0.3, -0.2, 0.1), axis=(1.0, 2.0, -1.0), strength=2.0, radius=0.5)
    f = forces_of(swirl, particles(points, np.ones(50)), points)
    axis = np.array([1.0, 2.0, -1.0]) / np.sqrt(6.0)
    # Tangential: no component along the axis nor towards it (round-off of unit-sized numbers).
    assert np.abs(f @ axis).max() < 1e-14
    assert np.abs(np.einsum("ij,ij->i", f, points - swirl.point)).max() < 1e-14
    assert np.linalg.norm(f, axis=1).max() <= 2.0 * (1 + 1e-12)  # never beyond m S


@pytest.mark.parametrize("falloff", ["inverse_square", "linear"])
@pytest.mark.parametrize("cls", [PointAttractor, PointRepulser])
def test_point_field_force_is_minus_gradient_of_its_potential(cls, falloff):
    rng = np.random.default_rng(2)
    x = rng.uniform(-1, 1, (20, 3))
    cloud = particles(x, rng.uniform(0.5, 2, 20))
    field = cls(centre=(0.1, 0.2, -0.1), strength=3.0, falloff=falloff, radius=1.2)
    h = 1e-6
    gradient = np.zeros_like(x)
    for axis in range(3):  # central differences of the total potential, moving one node at a time
        shift = np.zeros(3)
        shift[axis] = h
        up = [field.potential_energy(cloud, x + shift * (np.arange(20) == k)[:, None], 0) for k in range(20)]
        down = [field.potential_energy(cloud, x - shift * (np.arange(20) == k)[:, None], 0) for k in range(20)]
        gradient[:, axis] = (np.array(up) - np.array(down)) / (2 * h)
    # Central differences: O(h^2) truncation plus ~1e-16/h cancellation, both far below 1e-7.
    assert np.allclose(forces_of(field, cloud, x), -gradient, atol=1e-7)


# ---------------------------------------------------------------------------- Jacobians
def finite_difference_jacobian(field, model, x, v, *, wrt, h=1e-6):
    n = x.size
    columns = []
    for k in range(n):
        delta = np.zeros(n)
        delta[k] = h
        delta = delta.reshape(x.shape)
        if wrt == "x":
            up, down = forces_of(field, model, x + delta, v), forces_of(field, model, x - delta, v)
        else:
            up, down = forces_of(field, model, x, v + delta), forces_of(field, model, x, v - delta)
        columns.append(((up - down) / (2 * h)).ravel())
    return np.array(columns).T


@pytest.mark.parametrize("falloff", ["inverse_square", "linear"])
@pytest.mark.parametrize("cls", [PointAttractor, PointRepulser])
def test_point_field_jacobian_matches_finite_differences(cls, falloff):
    rng = np.random.default_rng(3)
    x = rng.uniform(-1, 1, (8, 3))
    cloud = particles(x, rng.uniform(0.5, 2, 8))
    exact = cls(centre=(0.0, 0.1, 0.0), strength=2.0, falloff=falloff, radius=1.5, clamp_jacobian=False)
    dFdx, dFdv = exact.jacobian(cloud, x, None, 0.0)
    assert dFdv is None and dFdx.shape == (24, 24)
    # Central differences of a smooth field: error ~h^2 |f'''| + 1e-16/h, well below 1e-6.
    assert np.allclose(dFdx.toarray(), finite_difference_jacobian(exact, cloud, x, None, wrt="x"), atol=1e-6)

    clamped = cls(centre=(0.0, 0.1, 0.0), strength=2.0, falloff=falloff,
                  radius=1.5).jacobian(cloud, x, None, 0.0)[0].toarray()
    # Clamped: symmetric and negative semi-definite (eigenvalues <= 0 up to round-off of O(10) entries).
    assert np.allclose(clamped, clamped.T, atol=1e-14)
    assert np.linalg.eigvalsh(clamped).max() < 1e-12
    # ... and it keeps exactly the non-positive part of each block's spectrum.
    for k in range(8):
        block = slice(3 * k, 3 * k + 3)
        values, vectors = np.linalg.eigh(dFdx.toarray()[block, block])
        assert np.allclose(clamped[block, block], (vectors * np.minimum(values, 0)) @ vectors.T, atol=1e-12)


def test_wind_jacobian_matches_finite_differences():
    rng = np.random.default_rng(4)
    x, v = rng.standard_normal((5, 3)), rng.standard_normal((5, 3))
    cloud = particles(x, rng.uniform(0.5, 2, 5))
    wind = Wind(direction=(1.0, 1.0, 0.0), speed=3.0, rate=0.7, gusts=[(0.5, 2.0, 0.3)])
    dFdx, dFdv = wind.jacobian(cloud, x, v, 0.3)
    assert dFdx is None
    # The force is linear in v: central differences are exact up to round-off ~1e-16/h * |f|.
    assert np.allclose(dFdv.toarray(), finite_difference_jacobian(wind, cloud, x, v, wrt="v"), atol=1e-8)


# ---------------------------------------------------------------------------- momentum and impulse
def run_symplectic_euler(scene, field, *, steps, dt, v0=None):
    """Symplectic Euler; returns the momentum change and the field's impulse sum_k dt F(x_k, v_k, t_k)."""
    masses = scene.model.masses
    x = scene.model.rest_positions.copy()
    v = np.zeros_like(x) if v0 is None else v0.copy()
    p0 = masses @ v
    impulse = np.zeros(3)
    for k in range(steps):
        t = k * dt
        impulse += dt * forces_of(field, scene.model, x, v, t).sum(axis=0)
        v = v + dt * scene.accelerations(x, v, t)
        x = x + dt * v
    return masses @ v - p0, impulse


@pytest.mark.parametrize("make_field", [
    lambda: Wind(direction=(1.0, 0.0, 0.5), speed=2.0, rate=3.0, gusts=[(1.0, 5.0, 0.0)]),
    lambda: PointAttractor(centre=(0.3, 0.0, 0.0), strength=0.5, radius=0.05),
    lambda: PointRepulser(centre=(0.0, -0.2, 0.0), strength=2.0, falloff="linear", radius=0.5),
    lambda: Vortex(point=(0.2, 0.2, 0.0), axis=(0.0, 1.0, 1.0), strength=4.0, radius=0.1),
], ids=["wind", "attractor", "repulser", "vortex"])
def test_external_fields_change_momentum_by_exactly_their_impulse(model, make_field):
    field = make_field()
    scene = Scene(model, forces=[field])
    v0 = np.tile([0.1, -0.2, 0.3], (model.node_count, 1))
    change, impulse = run_symplectic_euler(scene, field, steps=200, dt=2e-4, v0=v0)
    assert np.linalg.norm(impulse) > 1e-4  # the field did push
    # Springs and dampers cancel pairwise, so only the field changes momentum: equality up to the
    # round-off of 200 steps of sums over 27 nodes of O(1e-1) momenta (~1e-15 each).
    assert np.allclose(change, impulse, rtol=1e-10, atol=1e-13)


def test_steady_wind_brings_a_body_to_its_speed_as_predicted(model):
    wind = Wind(direction=(0.0, 1.0, 0.0), speed=4.0, rate=5.0)
    scene = Scene(model, forces=[wind])
    dt, steps = 1e-3, 300
    change, _ = run_symplectic_euler(scene, wind, steps=steps, dt=dt)
    # dP/dt = c (M w - P), discretised by the explicit velocity update: P_N = M w (1 - (1 - c dt)^N)
    # exactly, up to round-off (the continuous answer 1 - exp(-c t) differs by O(c dt) = 0.5%).
    predicted = model.total_mass * 4.0 * (1.0 - (1.0 - 5.0 * dt) ** steps)
    assert change == pytest.approx([0.0, predicted, 0.0], rel=1e-12, abs=1e-15)


# ---------------------------------------------------------------------------- user fields, scenes
def test_callable_force_checks_what_the_user_returns():
    x = np.zeros((4, 3))
    out = np.zeros_like(x)
    four = particles(x, np.ones(4))
    CallableForce(lambda x, v, t: np.ones_like(x) * t).accumulate(four, x, x, 2.0, out)
    assert np.array_equal(out, np.full((4, 3), 2.0))

    def short(x, v, t):
        return np.zeros((3, 3))

    with pytest.raises(ValueError, match=r"short\(x, v, t=0.5\) returned shape \(3, 3\), expected \(4, 3\)"):
        CallableForce(short).accumulate(four, x, x, 0.5, out)
    bad = np.zeros((4, 3))
    bad[2, 1] = np.nan
    with pytest.raises(ValueError, match=r"at node 2"):
        CallableForce(lambda x, v, t: bad, name="field").accumulate(four, x, x, 0.0, out)
    with pytest.raises(ValueError, match=r"returned str, not an \(n, 3\) array"):
        CallableForce(lambda x, v, t: "north").accumulate(four, x, x, 0.0, out)
    with pytest.raises(TypeError, match="is not callable"):
        CallableForce(3.0)
    assert np.array_equal(out, np.full((4, 3), 2.0))  # failed calls added nothing


def test_a_scene_pays_only_for_the_fields_it_names(model):
    calls = []

    def counted(x, v, t):
        calls.append(t)
        return np.zeros_like(x)

    rng = np.random.default_rng(5)
    x = model.rest_positions + 1e-3 * rng.standard_normal(model.rest_positions.shape)
    v = rng.standard_normal(x.shape)
    plain = Scene(model)
    with_field = Scene(model, forces=[CallableForce(counted)])
    assert np.array_equal(plain.forces_at(x, v, 0.0), spring_forces(model, x, v))
    assert calls == []
    with_field.forces_at(x, v, 0.25)
    assert calls == [0.25]  # exactly one call per force evaluation


@pytest.mark.parametrize("build, message", [
    (lambda: Wind(direction=(0, 0, 0), speed=1.0, rate=1.0), r"direction = \(0, 0, 0\) has zero length"),
    (lambda: Wind(direction=(1, 0, 0), speed=1.0, rate=-1.0), "rate = -1.0 is not finite and >= 0"),
    (lambda: Wind(direction=(1, 0, 0), speed=np.nan, rate=1.0), "speed = nan is not a finite number"),
    (lambda: PointAttractor(centre=(0, 0, 0), strength=1.0, radius=0.0), "radius = 0.0 is not finite and > 0"),
    (lambda: PointAttractor(centre=(0, 0, 0), strength=-1.0, radius=1.0), "strength = -1.0 is not finite and >= 0"),
    (lambda: PointRepulser(centre=(0, 0, 0), strength=1.0, radius=1.0, falloff="cubic"),
     "falloff = 'cubic' is not one of"),
    (lambda: Vortex(masses=[1.0, -2.0], point=(0, 0, 0), axis=(0, 0, 1), strength=1.0, radius=1.0),
     r"masses\[1\] = -2.0 kg"),
    (lambda: Vortex(point=(0, 0), axis=(0, 0, 1), strength=1.0, radius=1.0),
     r"point = \(0, 0\) is not a finite 3-vector"),
    # gusts are rows (A, f, phi): a flat list used to be cut into rows of 3, whatever it meant
    (lambda: Wind(direction=(1, 0, 0), speed=1.0, rate=1.0, gusts=[1.0, 0.5, 0.0, 2.0, 1.0, 0.0]),
     r"gusts = .* have shape \(6,\); expected \(k, 3\)"),
    (lambda: Wind(direction=(1, 0, 0), speed=1.0, rate=1.0, gusts=[(1.0, 0.5)]),
     r"have shape \(1, 2\); expected \(k, 3\)"),
    (lambda: Wind(direction=(1, 0, 0), speed=1.0, rate=1.0, gusts=2.0),
     r"gusts = 2.0 have shape \(\); expected \(k, 3\)"),
    (lambda: Wind(direction=(1, 0, 0), speed=1.0, rate=np.inf), "rate = inf is not finite and >= 0"),
    (lambda: Wind(direction=(1, 0, np.nan), speed=1.0, rate=1.0),
     r"direction = \(1, 0, nan\) is not a finite 3-vector"),
    (lambda: Wind(masses=[[1.0, 2.0]], direction=(1, 0, 0), speed=1.0, rate=1.0),
     r"masses must have shape \(n,\) with n > 0, got \(1, 2\)"),
    (lambda: PointAttractor(masses=[np.nan], centre=(0, 0, 0), strength=1.0, radius=1.0),
     r"masses\[0\] = nan kg is not finite and > 0"),
    (lambda: PointAttractor(centre=(0, 0, 0, 0), strength=1.0, radius=1.0),
     r"centre = \(0, 0, 0, 0\) is not a finite 3-vector"),
    (lambda: PointAttractor(centre=(0, 0, 0), strength=np.nan, radius=1.0), "strength = nan is not finite and >= 0"),
    (lambda: Vortex(point=(0, 0, 0), axis=(0, 0, 1), strength=np.inf, radius=1.0),
     "strength = inf is not a finite number"),
    (lambda: Vortex(point=(0, 0, 0), axis=(0, 0, 1), strength=1.0, radius=-1.0), "radius = -1.0 is not finite and > 0"),
])
def test_fields_refuse_nonsense(build, message):
    with pytest.raises(ValueError, match=message):
        build()


@pytest.mark.parametrize("build, message", [
    (lambda: Wind(direction=("1", 0, 0), speed=1.0, rate=1.0), r"direction = \('1', 0, 0\) does not hold real numbers"),
    (lambda: Wind(direction=(1, 0, 0), speed="3", rate=1.0), r"speed = '3' is not a real number \(got str\)"),
    (lambda: Wind(direction=(1, 0, 0), speed=1.0, rate=1.0, gusts=[(True, 1.0, 0.0)]),
     r"gusts = .* holds a bool \(item 0\)"),
    (lambda: PointAttractor(masses=["1"], centre=(0, 0, 0), strength=1.0, radius=1.0),
     r"masses = \['1'\] does not hold real numbers"),
    (lambda: PointAttractor(centre=(0, 0, 0), strength=1.0, radius=1.0, falloff=2), "falloff = 2 is not one of"),
    (lambda: Vortex(point=(0, 0, 0), axis=(True, False, False), strength=1.0, radius=1.0),
     r"axis = .* \(got dtype bool\)"),
])
def test_fields_refuse_what_is_not_numbers(build, message):
    with pytest.raises((TypeError, ValueError), match=message) as error:
        build()
    # falloff is a choice among names, so a wrong one is a value error; the rest are type errors
    assert error.type is (ValueError if "falloff" in message else TypeError)


def test_a_scene_refuses_a_field_built_for_another_model(model):
    wind = Wind(masses=model.masses[:-1], direction=(1, 0, 0), speed=1.0, rate=1.0)
    with pytest.raises(ValueError, match=rf"forces\[0\] \(Wind\) has {model.node_count - 1} masses, but the model "
                                         rf"has {model.node_count} nodes"):
        Scene(model, forces=[wind])
