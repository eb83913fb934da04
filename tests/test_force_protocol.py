"""The force protocol: the model at every evaluation, the 0.1 forms behind DeprecationWarnings, the scene's algebra."""

import warnings

import numpy as np
import pytest
import scipy.sparse as sp

from volspring import Drag, Gravity, Material, Model, PointAttractor, PointRepulser, Scene, Vortex, Wind
from volspring.forces import HasJacobian, HasPotential

from conftest import cube_mesh

RUBBER = Material(E=1e5, nu=0.3, density=1000.0)


@pytest.fixture(scope="module")
def model():
    return Model.from_mesh(cube_mesh((2, 1, 1), size=(0.2, 0.1, 0.1)), RUBBER, damping_ratio=0.1)


@pytest.fixture(scope="module")
def motion(model):
    """Positions, velocities and a time away from rest, so that every term of every field is non-zero."""
    rng = np.random.default_rng(11)
    x = model.rest_positions + 0.01 * rng.standard_normal(model.rest_positions.shape)
    return x, rng.standard_normal(x.shape), 0.37


def evaluated(force, model, x, v, t):
    """accumulate, and where the force has them, jacobian (dense) and potential_energy."""
    out = np.zeros_like(x)
    force.accumulate(model, x, v, t, out)
    jacobian = None
    if isinstance(force, HasJacobian):
        jacobian = tuple(None if part is None else part.toarray() for part in force.jacobian(model, x, v, t))
    potential = force.potential_energy(model, x, t) if isinstance(force, HasPotential) else None
    return out, jacobian, potential


def assert_same(first, second):
    """Bit-identical forces, Jacobians and potentials (the same arithmetic on the same numbers)."""
    assert np.array_equal(first[0], second[0])
    assert (first[1] is None) == (second[1] is None)
    if first[1] is not None:
        for a, b in zip(first[1], second[1]):
            assert (a is None and b is None) or np.array_equal(a, b)
    assert first[2] == second[2]


# ---------------------------------------------------------------------------- (a) 0.1 positional forms
LEGACY_FORMS = {
    "gravity": (lambda m: Gravity(m), lambda: Gravity()),
    "gravity_g": (lambda m: Gravity(m, (0.0, -2.0, -9.0)), lambda: Gravity(g=(0.0, -2.0, -9.0))),
    "drag": (lambda m: Drag(m, 0.5), lambda: Drag(rate=0.5)),
    "wind": (lambda m: Wind(m, (1, 0, 0), 2.0, rate=1.0), lambda: Wind(direction=(1, 0, 0), speed=2.0, rate=1.0)),
    "gusty_wind": (lambda m: Wind(m, (1, 2, 0), 2.0, rate=1.0, gusts=[(0.5, 3.0, 0.2)]),
                   lambda: Wind(direction=(1, 2, 0), speed=2.0, rate=1.0, gusts=[(0.5, 3.0, 0.2)])),
    "attractor": (lambda m: PointAttractor(m, (0.1, 0.3, 0.0), 2.0, radius=0.05),
                  lambda: PointAttractor(centre=(0.1, 0.3, 0.0), strength=2.0, radius=0.05)),
    "linear_attractor": (lambda m: PointAttractor(m, (0.1, 0.0, 0.0), 2.0, radius=0.3, falloff="linear"),
                         lambda: PointAttractor(centre=(0.1, 0.0, 0.0), strength=2.0, radius=0.3, falloff="linear")),
    "repulser": (lambda m: PointRepulser(m, (0.1, 0.3, 0.0), 2.0, radius=0.05),
                 lambda: PointRepulser(centre=(0.1, 0.3, 0.0), strength=2.0, radius=0.05)),
    "vortex": (lambda m: Vortex(m, (0.1, 0.0, 0.0), (0.0, 1.0, 1.0), 3.0, radius=0.05),
               lambda: Vortex(point=(0.1, 0.0, 0.0), axis=(0.0, 1.0, 1.0), strength=3.0, radius=0.05)),
}


@pytest.mark.parametrize("legacy, current", LEGACY_FORMS.values(), ids=LEGACY_FORMS.keys())
def test_positional_forms_warn_and_give_the_same_forces(model, motion, legacy, current):
    with pytest.warns(DeprecationWarning, match=r"with positional arguments is deprecated.*pass keywords"):
        old = legacy(model.masses)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the keyword form warns about nothing
        new = current()
    assert new.masses is None and np.array_equal(old.masses, model.masses)
    assert_same(evaluated(old, model, *motion), evaluated(new, model, *motion))
    # ... and the same total force in a scene.
    x, v, t = motion
    assert np.array_equal(Scene(model, forces=[old]).forces_at(x, v, t), Scene(model, forces=[new]).forces_at(x, v, t))


def test_positional_forms_warn_at_the_callers_line_and_refuse_what_they_cannot_map(model):
    with pytest.warns(DeprecationWarning) as caught:
        Gravity(model.masses)
    assert caught[0].filename == __file__  # stacklevel: the warning points at the call
    with pytest.raises(TypeError, match=r"Drag\(\) takes at most 2 positional arguments"):
        Drag(model.masses, 0.5, 1.0)
    with pytest.raises(TypeError, match=r"got 'masses' both by position and by keyword"), \
            pytest.warns(DeprecationWarning):
        Gravity(model.masses, masses=model.masses)


def test_the_masses_keyword_overrides_the_models_masses(model, motion):
    x, v, t = motion
    heavier = 3.0 * model.masses
    scaled = evaluated(Wind(masses=heavier, direction=(0, 1, 0), speed=1.0, rate=2.0), model, x, v, t)
    plain = evaluated(Wind(direction=(0, 1, 0), speed=1.0, rate=2.0), model, x, v, t)
    # Linear in the masses: three times the force and the Jacobian, to round-off of one product.
    assert np.allclose(scaled[0], 3.0 * plain[0], rtol=1e-15, atol=0)
    assert np.allclose(scaled[1][1], 3.0 * plain[1][1], rtol=1e-15, atol=0)


# ---------------------------------------------------------------------------- (b) 0.1 user forces
class Anchor:
    """A spring to fixed anchors with a viscous damper: f = -k (x - a) - c v, U = k |x - a|^2 / 2."""

    k, c = 40.0, 0.3

    def __init__(self, anchors):
        self.anchors = anchors

    def force(self, x, v):
        return -self.k * (x - self.anchors) - self.c * v

    def matrices(self, n):
        return -self.k * sp.identity(3 * n, format="csr"), -self.c * sp.identity(3 * n, format="csr")

    def energy(self, x):
        return 0.5 * self.k * float(np.sum((x - self.anchors) ** 2))


class OldAnchor(Anchor):
    """The force written for volspring 0.1: no model argument."""

    def accumulate(self, x, v, t, out):
        out += self.force(x, v)

    def jacobian(self, x, v, t):
        return self.matrices(len(x))

    def potential_energy(self, x, t):
        return self.energy(x)


class NewAnchor(Anchor):
    """The same force under the current protocol."""

    def accumulate(self, model, x, v, t, out):
        out += self.force(x, v)

    def jacobian(self, model, x, v, t):
        return self.matrices(model.node_count)

    def potential_energy(self, model, x, t):
        return self.energy(x)


def test_an_old_style_user_force_warns_once_and_acts_as_written_in_the_new_form(model, motion):
    x, v, t = motion
    anchors = model.rest_positions + 0.02
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        old = Scene(model, forces=[Gravity(), OldAnchor(anchors)])
    deprecations = [w for w in caught if issubclass(w.category, DeprecationWarning)]
    assert len(deprecations) == 1  # once, at construction, for the one old force
    assert "forces[1] (OldAnchor) has accumulate(x, v, t, out) without the model" in str(deprecations[0].message)
    assert deprecations[0].filename == __file__  # it points at the Scene(...) line, so default filters show it
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # nothing more: not per evaluation, not for the new form
        new = Scene(model, forces=[Gravity(), NewAnchor(anchors)])
        assert np.array_equal(old.forces_at(x, v, t), new.forces_at(x, v, t))
        assert np.array_equal(old.external_forces(x, v, t), new.external_forces(x, v, t))
        for old_part, new_part in zip(old.external_jacobian(x, v, t), new.external_jacobian(x, v, t)):
            assert np.array_equal(old_part.toarray(), new_part.toarray())
        assert old.potential_energy(x, t) == new.potential_energy(x, t)
        assert old.external_potential(x, t) == new.external_potential(x, t)
        assert old.conservative and new.conservative
    # The force acted (else the comparison proves nothing): its Jacobian is the -k I, -c I written above.
    dfdx, dfdv = new.external_jacobian(x, v, t)
    assert np.array_equal(dfdx.diagonal(), np.full(3 * model.node_count, -Anchor.k))
    assert np.array_equal(dfdv.diagonal(), np.full(3 * model.node_count, -Anchor.c))


def test_an_old_style_force_without_jacobian_or_potential_stays_without():
    class Push:
        def accumulate(self, x, v, t, out):
            out[:, 0] += 1.0

    pair = Model.from_arrays([[0, 0, 0], [1, 0, 0]], [1.0, 2.0], [[0, 1]], stiffness=1.0)
    with pytest.warns(DeprecationWarning, match=r"forces\[0\] \(Push\) has accumulate\(x, v, t, out\)"):
        scene = Scene(pair, forces=[Push()])
    assert not isinstance(scene.forces[0], HasJacobian) and not scene.conservative
    assert scene.external_jacobian(pair.rest_positions, np.zeros((2, 3)), 0.0) == (None, None)
    assert scene.external_forces(pair.rest_positions, np.zeros((2, 3)), 0.0)[:, 0].tolist() == [1.0, 1.0]


# ---------------------------------------------------------------------------- (c) masses read per evaluation
def test_a_field_reads_the_masses_of_the_model_it_is_evaluated_on():
    positions = [[0.0, 0.0, 0.0], [0.3, 0.1, 0.0], [0.0, 0.4, 0.2]]
    light = Model.from_arrays(positions, [1.0, 2.0, 3.0], [], stiffness=1.0)
    heavy = Model.from_arrays(positions, [5.0, 0.5, 7.0], [], stiffness=1.0)
    x, v = light.rest_positions, np.ones((3, 3))
    gravity, drag = Gravity(g=(0.0, 0.0, -2.0)), Drag(rate=0.25)
    attractor = PointAttractor(centre=(1.0, 1.0, 1.0), strength=3.0, radius=0.5)
    assert gravity.masses is None and drag.masses is None and attractor.masses is None  # no copy held
    # Interleaved: each evaluation uses the model it is given, not one seen before.
    for model in (light, heavy, light):
        m = model.masses
        out = np.zeros((3, 3))
        gravity.accumulate(model, x, v, 0.0, out)
        assert out.tolist() == [[0.0, 0.0, -2.0 * mass] for mass in m]  # exact: one product each
        assert gravity.potential_energy(model, x, 0.0) == pytest.approx(2.0 * float(m @ x[:, 2]), rel=1e-15)
        out = np.zeros((3, 3))
        drag.accumulate(model, x, v, 0.0, out)
        assert np.array_equal(out, -0.25 * m[:, None] * v)
        assert np.array_equal(drag.jacobian(model, x, v, 0.0)[1].diagonal(), np.repeat(-0.25 * m, 3))
        out = np.zeros((3, 3))
        attractor.accumulate(model, x, v, 0.0, out)
        assert np.array_equal(out, m[:, None] * attractor.accelerations(x))
    # Two scenes sharing one field: each weighs with its own model's masses.
    ratio = heavy.masses / light.masses
    light_forces = Scene(light, forces=[gravity]).external_forces(x, v, 0.0)
    heavy_forces = Scene(heavy, forces=[gravity]).external_forces(x, v, 0.0)
    assert np.allclose(heavy_forces, ratio[:, None] * light_forces, rtol=1e-15, atol=0)


# ---------------------------------------------------------------------------- (d) conservative
@pytest.mark.parametrize("forces, conservative", [
    ([], True),
    ([Gravity()], True),
    ([Gravity(), PointAttractor(centre=(0, 0, 0), strength=1.0, radius=1.0)], True),
    ([Drag(rate=0.5)], False),
    ([Gravity(), Drag(rate=0.5)], False),
    ([Gravity(), Wind(direction=(1, 0, 0), speed=1.0, rate=1.0)], False),
    ([Vortex(point=(0, 0, 0), axis=(0, 0, 1), strength=1.0, radius=1.0)], False),
], ids=["none", "gravity", "gravity+attractor", "drag", "gravity+drag", "gravity+wind", "vortex"])
def test_a_scene_is_conservative_iff_every_force_has_a_potential(model, forces, conservative):
    assert Scene(model, forces=forces).conservative is conservative


def test_external_forces_split_into_conservative_and_nonconservative_parts(model, motion):
    x, v, t = motion
    scene = Scene(model, forces=[Gravity(), Drag(rate=0.5), Wind(direction=(1, 0, 0), speed=2.0, rate=0.3)])
    drag_and_wind = Scene(model, forces=[Drag(rate=0.5), Wind(direction=(1, 0, 0), speed=2.0, rate=0.3)])
    assert np.array_equal(scene.external_forces(x, v, t, conservative=False), drag_and_wind.external_forces(x, v, t))
    assert np.array_equal(scene.external_forces(x, v, t, conservative=True),
                          Scene(model, forces=[Gravity()]).external_forces(x, v, t))


# ---------------------------------------------------------------------------- (e) external Jacobian
def test_the_external_jacobian_is_the_sum_of_the_forces_jacobians(model, motion):
    x, v, t = motion
    attractor = PointAttractor(centre=(0.1, 0.2, 0.0), strength=2.0, radius=0.1, clamp_jacobian=False)
    repulser = PointRepulser(centre=(0.0, -0.1, 0.1), strength=1.0, radius=0.2, falloff="linear")
    drag, wind = Drag(rate=0.5), Wind(direction=(0, 0, 1), speed=3.0, rate=0.7)
    for pair in ((attractor, repulser), (drag, wind), (attractor, drag)):
        dfdx, dfdv = Scene(model, forces=[Gravity(), *pair]).external_jacobian(x, v, t)  # Gravity has none
        parts = [force.jacobian(model, x, v, t) for force in pair]
        for total, terms in ((dfdx, [p[0] for p in parts]), (dfdv, [p[1] for p in parts])):
            terms = [term.toarray() for term in terms if term is not None]
            if not terms:
                assert total is None
                continue
            # Sparse sums of the same entries in the same order: equal to the last bit.
            assert np.array_equal(total.toarray(), sum(terms[1:], terms[0]))
        assert dfdx is not None or dfdv is not None
    # Both attractors contribute: the sum differs from either alone.
    both = Scene(model, forces=[attractor, repulser]).external_jacobian(x, v, t)[0].toarray()
    alone = attractor.jacobian(model, x, v, t)[0].toarray()
    assert np.abs(both - alone).max() > 1e-3 * np.abs(alone).max()
    # Only forces without a Jacobian: nothing.
    assert Scene(model, forces=[Gravity()]).external_jacobian(x, v, t) == (None, None)
