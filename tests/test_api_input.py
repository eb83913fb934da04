"""Inputs the public API used to misread: each is now refused with a message naming the value.

One test per report of the issue (negative and float pins, a state of another model, NaN start
velocities, a 2-vector gravity, numpy scalars refused by Material), then the same classes of input
tried on every constructor that takes numbers. The finer cases live next to each class's own
tests (test_scene.py, test_fields.py, test_model.py).
"""

import numpy as np
import pytest

from volspring import (CallableForce, Drag, Gravity, Material, PointAttractor, PointRepulser, Pins, Scene,
                       Model, Vortex, Wind)
from volspring.integrators import INTEGRATORS, make_integrator

from conftest import cube_mesh

RUBBER = Material(E=1e5, nu=0.3, density=1000.0)


@pytest.fixture(scope="module")
def model():
    return Model.from_mesh(cube_mesh((2, 1, 1), size=(0.2, 0.1, 0.1)), RUBBER)  # 12 nodes


@pytest.fixture(scope="module")
def smaller_model():
    return Model.from_mesh(cube_mesh((1, 1, 1), size=(0.1, 0.1, 0.1)), RUBBER)  # 8 nodes


# ---------------------------------------------------------------------------- the reports
def test_negative_pin_is_refused_not_read_from_the_end(model):
    with pytest.raises(ValueError, match=r"Pins nodes\[1\] = -1 is negative; expected node indices >= 0"):
        Pins([0, -1])


def test_float_pin_is_refused_not_truncated():
    with pytest.raises(TypeError, match=r"Pins nodes\[0\] = 0.7 is not an integer node index"):
        Pins([0.7])


def test_pin_beyond_the_model_names_the_index_and_the_node_count(model):
    with pytest.raises(ValueError, match=r"pinned node 12 does not exist: the model has 12 nodes \(indices 0 to 11\)"):
        Scene(model, pins=Pins([3, 12]))


@pytest.mark.parametrize("name", sorted(INTEGRATORS))
def test_step_refuses_a_state_of_another_model(model, smaller_model, name):
    scene = Scene(model, forces=[Gravity()])
    foreign = Scene(smaller_model).initial_state()
    with pytest.raises(ValueError, match=r"state.x has shape \(8, 3\), but the scene's model has 12 nodes: "
                                         r"expected \(12, 3\)"):
        make_integrator(name).step(scene, foreign, 1e-4)


@pytest.mark.parametrize("name", ["symplectic_euler", "implicit_euler"])
def test_step_takes_numpy_step_sizes_and_refuses_bools(model, name):
    scene = Scene(model, forces=[Gravity()])
    state = scene.initial_state()
    stepper = make_integrator(name)
    assert stepper.step(scene, state, np.float32(1e-4)).step == 1
    with pytest.raises(TypeError, match=r"dt = True is not a real number \(got bool\)"):
        stepper.step(scene, state, True)  # True used to be a step of 1 s
    with pytest.raises(ValueError, match="dt = -0.001 s is not a finite number > 0"):
        stepper.step(scene, state, -1e-3)
    with pytest.raises(TypeError, match="scene must be a volspring Scene, got Model"):
        stepper.step(model, state, 1e-4)


def test_check_state_names_the_first_non_finite_node_and_what_is_bad(model):
    scene = Scene(model)
    good = scene.initial_state()
    v = good.v.copy()
    v[[4, 7], 1] = np.nan
    with pytest.raises(ValueError, match=r"state.v\[4\] = \[0.0, nan, 0.0\] m/s is not finite "
                                         r"\(the velocity of node 4; 2 node\(s\) have a NaN or Inf velocity\)"):
        scene.check_state(good.replace(v=v))
    x = good.x.copy()
    x[9, 2] = np.inf
    with pytest.raises(ValueError, match=r"state.x\[9\] = .* m is not finite \(the position of node 9"):
        scene.check_state(good.replace(x=x))
    scene.check_state(good.replace(x=x), finite=False)  # what step does: shapes only
    scene.check_state(good)  # a good state passes


def test_nan_start_velocity_is_refused_before_the_solver_sees_it(model):
    # It used to reach the implicit solver and come back as "matrix not positive definite".
    scene = Scene(model, forces=[Gravity()])
    v = np.zeros((model.node_count, 3))
    v[5, 0] = np.nan
    with pytest.raises(ValueError, match=r"v\[5\] = \[nan, 0.0, 0.0\] m/s is not finite \(the velocity of node 5"):
        scene.initial_state(v=v)


def test_gravity_refuses_a_two_vector(model):
    with pytest.raises(ValueError, match=r"g = \(0, 0\) is not a finite 3-vector \(got shape \(2,\)\)"):
        Gravity(g=(0, 0))


def test_material_takes_numpy_scalars():
    material = Material(E=np.float32(1e6), nu=np.float64(0.3), density=np.int64(1000))
    # 1e6 < 2**24 is exactly representable in float32, so the conversion is exact
    assert (material.E, material.nu, material.density) == (1e6, 0.3, 1000.0)
    assert all(type(value) is float for value in (material.E, material.nu, material.density))


# ---------------------------------------------------------------------------- every number-taking API
NUMPY_SCALARS = [np.float32(2.0), np.float64(2.0), np.int64(2), np.array(2.0)]


@pytest.mark.parametrize("number", NUMPY_SCALARS, ids=lambda value: type(value).__name__)
def test_numpy_scalars_are_numbers_everywhere(model, number):
    assert Material(E=number * 1e5, nu=0.25, density=number).density == 2.0
    assert Drag(rate=number).rate == 2.0
    assert Wind(direction=(1, 0, 0), speed=number, rate=number).rate == 2.0
    assert PointAttractor(centre=(0, 0, 0), strength=number, radius=number).radius == 2.0
    assert Vortex(point=(0, 0, 0), axis=(0, 0, 1), strength=number, radius=number).strength == 2.0
    assert Gravity(g=(0, 0, -number)).g.tolist() == [0.0, 0.0, -2.0]
    uniform = Model.from_mesh(cube_mesh((1, 1, 1)), RUBBER, rule="uniform", stiffness=number,
                                    damping_ratio=number * 0.25)
    assert (uniform.stiffness == 2.0).all()
    pair = Model.from_arrays([[0, 0, 0], [1, 0, 0]], [number, number], np.array([[0, 1]], dtype=np.int32),
                                   stiffness=number, damping=number)
    assert (pair.stiffness[0], pair.damping[0], pair.masses[0]) == (2.0, 2.0, 2.0)
    scene = Scene(pair)
    assert scene.initial_state(t=number).t == 2.0


@pytest.mark.parametrize("bad", [True, "2.0"], ids=["bool", "str"])
@pytest.mark.parametrize("build, name", [
    (lambda bad: Material(E=bad, nu=0.3, density=1.0), "E"),
    (lambda bad: Material(E=1.0, nu=0.3, density=bad), "density"),
    (lambda bad: Drag(rate=bad), "drag rate"),
    (lambda bad: Wind(direction=(1, 0, 0), speed=bad, rate=1.0), "speed"),
    (lambda bad: Wind(direction=(1, 0, 0), speed=1.0, rate=bad), "rate"),
    (lambda bad: PointAttractor(centre=(0, 0, 0), strength=bad, radius=1.0), "strength"),
    (lambda bad: PointRepulser(centre=(0, 0, 0), strength=1.0, radius=bad), "radius"),
    (lambda bad: Vortex(point=(0, 0, 0), axis=(0, 0, 1), strength=bad, radius=1.0), "strength"),
    (lambda bad: Gravity(g=(0, 0, bad)), "g"),
    (lambda bad: Gravity(masses=[bad]), "masses"),
    (lambda bad: Model.from_mesh(cube_mesh((1, 1, 1)), RUBBER, rule="uniform", stiffness=bad), "stiffness"),
    (lambda bad: Model.from_mesh(cube_mesh((1, 1, 1)), RUBBER, damping_ratio=bad), "damping_ratio"),
    (lambda bad: Model.from_arrays(np.eye(3), np.ones(3), [[0, 1]], stiffness=bad), "stiffness"),
    (lambda bad: Model.from_arrays(np.eye(3), np.ones(3), [[0, 1]], stiffness=1.0, damping=bad), "damping"),
    (lambda bad: Model.from_arrays(np.eye(3), [1.0, bad, 1.0], [[0, 1]], stiffness=1.0), "masses"),
])
def test_bools_and_strings_are_refused_naming_the_parameter(build, name, bad):
    with pytest.raises(TypeError, match=rf"^{name} = .* (is not a real number|does not hold real numbers|holds a bool)"):
        build(bad)


def test_pins_take_numpy_integers():
    assert Pins(np.int64(2)).nodes.tolist() == [2]
    assert Pins([np.int32(4), 1]).nodes.tolist() == [1, 4]
    assert Pins(np.array([[5, 1]], dtype=np.uint16)).nodes.tolist() == [1, 5]


def test_bools_are_refused_where_integers_are_taken(model):
    with pytest.raises(TypeError, match=r"Pins nodes\[0\] = True is a bool among integers"):
        Pins([True, 3])
    with pytest.raises(TypeError, match="Pins nodes = True is a bool"):
        Pins(True)
    with pytest.raises(TypeError, match=r"springs have dtype bool; expected integer node indices"):
        Model.from_arrays(np.eye(3), np.ones(3), [[True, False]], stiffness=1.0)
    with pytest.raises(TypeError, match="clamp_jacobian = 'no' is not a bool"):
        PointAttractor(centre=(0, 0, 0), strength=1.0, radius=1.0, clamp_jacobian="no")
    with pytest.raises(TypeError, match="name = 3 is not a str"):
        CallableForce(lambda x, v, t: 0 * x, name=3)
