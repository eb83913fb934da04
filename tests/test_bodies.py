"""One Model for one body or many: node_body, materials, body names, Model.from_bodies, initial velocities."""

import pickle

import numpy as np
import pytest

from conftest import cube_mesh
from volspring import Material, Model, Scene
from volspring.bodies import Body, initial_velocities

SOFT = Material(E=1e5, nu=0.3, density=1000.0)
HARD = Material(E=4e5, nu=0.25, density=2500.0)


def two_bodies():
    """A 0.1 m soft cube (2 x 2 x 2 cells) and a 0.2 x 0.1 x 0.05 m hard block (3 x 2 x 1) beside it."""
    cube = cube_mesh((2, 2, 2), (0.1, 0.1, 0.1))
    block = cube_mesh((3, 2, 1), (0.2, 0.1, 0.05))
    bodies = [Body(cube, SOFT, velocity=(1.0, 0, 0), name="cube"),
              Body(block, HARD, translation=(0.3, 0, 0), angular_velocity=(0, 0, 2.0), rule="lloyd", name="block")]
    return bodies, Model.from_bodies(bodies), (cube, block)


def test_a_single_body_needs_nothing_new():
    model = Model.from_mesh(cube_mesh((2, 2, 2)), SOFT)
    assert model.body_count == 1 and model.materials == (SOFT,) and model.material is SOFT
    assert model.body_names == ("",) and model.node_body.tolist() == [0] * model.node_count
    assert model.node_body.dtype == np.int64 and not model.node_body.flags.writeable
    assert model.body_masses.tolist() == [model.total_mass]
    arrays = Model.from_arrays([[0, 0, 0], [1, 0, 0]], [1.0, 2.0], [[0, 1]], stiffness=1.0)
    assert arrays.materials == (None,) and arrays.material is None and arrays.body_count == 1


def test_from_bodies_gives_one_model_with_node_body_materials_and_masses():
    bodies, model, (cube, block) = two_bodies()
    assert type(model) is Model and model.body_count == 2
    assert model.node_body.tolist() == [0] * cube.node_count + [1] * block.node_count
    assert model.materials == (SOFT, HARD) and model.material is None  # bodies differ: no single material
    assert model.body_names == ("cube", "block") and model.rule == "mixed"
    # Lumping only redistributes within each body: body b weighs density_b x volume_b to round-off.
    expected = [SOFT.density * cube.volume, HARD.density * block.volume]
    np.testing.assert_allclose(model.body_masses, expected, rtol=1e-12)
    np.testing.assert_allclose([model.masses[model.body_nodes(b)].sum() for b in (0, 1)], expected, rtol=1e-12)
    # The topology's mesh is the union of the placed meshes.
    mesh = model.topology.mesh
    assert mesh.tet_count == cube.tet_count + block.tet_count
    np.testing.assert_array_equal(mesh.points[model.body_nodes(1)], block.points + [0.3, 0, 0])
    assert "2 bodies" in repr(model)
    same = Model.from_bodies([Body(cube, SOFT), Body(cube, SOFT, translation=(1, 0, 0))])
    assert same.material is SOFT and same.rule == "van_gelder"  # one material for every body


def test_a_model_of_two_bodies_pickles_and_round_trips():
    _, model, _ = two_bodies()
    back = pickle.loads(pickle.dumps(model))
    for name in ("rest_positions", "masses", "node_body", "springs", "stiffness", "damping", "rest_lengths"):
        np.testing.assert_array_equal(getattr(back, name), getattr(model, name))
    assert back.materials == model.materials and back.body_names == model.body_names and back.material is None
    x = model.rest_positions + np.random.default_rng(0).normal(scale=1e-3, size=model.rest_positions.shape)
    np.testing.assert_array_equal(back.forces(x), model.forces(x))
    # A copy with more element sets (dataclasses.replace) keeps and re-checks the body fields.
    copy = model.with_elements()
    assert copy.materials == model.materials and copy.material is None
    np.testing.assert_array_equal(copy.node_body, model.node_body)
    # The constructor takes the fields back as they are.
    rebuilt = Model(model.rest_positions, model.masses, model.elements, topology=model.topology,
                    node_body=model.node_body, materials=model.materials, body_names=model.body_names)
    np.testing.assert_array_equal(rebuilt.body_masses, model.body_masses)


def test_initial_velocities_move_and_spin_each_body_about_its_centre_of_mass():
    bodies, model, _ = two_bodies()
    v = initial_velocities(bodies, model)
    assert v.shape == (model.node_count, 3)
    cube, block = model.body_nodes(0), model.body_nodes(1)
    np.testing.assert_array_equal(v[cube], np.broadcast_to([1.0, 0, 0], (len(cube), 3)))
    # Body 1 only spins: no linear momentum (round-off of a sum of ~40 terms of 1e-1 kg m/s), and its
    # angular momentum about its centre is I omega with I_zz = M (a^2 + b^2) / 12 up to the lumping.
    momentum = model.masses[block] @ v[block]
    assert np.abs(momentum).max() < 1e-14 * model.body_masses[1]
    x = model.rest_positions[block]
    centre = model.masses[block] @ x / model.body_masses[1]
    np.testing.assert_allclose(v[block], np.cross([0, 0, 2.0], x - centre), rtol=0, atol=1e-15)
    with pytest.raises(ValueError, match=r"len\(bodies\) = 1, but the model has 2 bodies"):
        initial_velocities(bodies[:1], model)
    with pytest.raises(ValueError, match=r"bodies\[0\]\.angular_velocity = \(0, 1\)"):
        initial_velocities([Body(cube_mesh(), SOFT, angular_velocity=(0, 1)), bodies[1]], model)


def test_a_multi_body_model_goes_through_scene_stability_diagnostics_and_output(tmp_path):
    from volspring.diagnostics import linear_momentum
    from volspring.output import BlenderWriter, BoundarySurface
    from volspring.stability import omega_max_bound, omega_max_estimate

    bodies, model, (cube, block) = two_bodies()
    scene = Scene(model)
    state = scene.initial_state(v=initial_velocities(bodies, model))
    # Momentum of the whole model: the cube's M v; the block's spin adds none (round-off only).
    np.testing.assert_allclose(linear_momentum(scene, state), [model.body_masses[0], 0, 0], atol=1e-14)
    # Two bodies not joined by springs: omega_max is that of the stiffer one alone.
    alone = [Model.from_mesh(cube, SOFT), Model.from_mesh(block, HARD, rule="lloyd")]
    assert omega_max_estimate(model) == pytest.approx(max(omega_max_estimate(m) for m in alone), rel=1e-9)
    assert omega_max_bound(model) >= omega_max_estimate(model)
    surface = BoundarySurface.from_mesh(model)
    assert surface.point_count == len(cube.boundary_nodes) + len(block.boundary_nodes)
    writer = BlenderWriter(tmp_path, model)
    writer(0, state)
    assert writer.obj_path(0).is_file()


@pytest.mark.parametrize("fields, error, message", [
    ({"node_body": [0, 0, 1]}, ValueError, r"len\(rest_positions\) = 4, but node_body has shape \(3,\)"),
    ({"node_body": [0, 0, 2, 2]}, ValueError, r"body 1 has no node: node_body holds ids \[0, 2\], but node_body "
                                              r"gives 3 bodies"),
    ({"node_body": [0, 0, 1, 1], "materials": (SOFT,)}, ValueError,
     r"node_body\[2\] = 1 is not a body id in \[0, 0\]: len\(materials\) = 1"),
    ({"node_body": [0, 0, 1, 1], "materials": (SOFT, SOFT, HARD)}, ValueError,
     r"body 2 has no node: .* but len\(materials\) gives 3 bodies"),
    ({"materials": (SOFT, HARD)}, ValueError, r"body 1 has no node"),
    ({"node_body": [0, -1, 0, 0]}, ValueError, r"node_body\[1\] = -1 is not a body id >= 0"),
    ({"node_body": [0.0, 0, 1, 1]}, TypeError, r"node_body has dtype float64; expected integer body ids"),
    ({"node_body": [0, 0, 1, 1], "materials": (SOFT, "steel")}, TypeError,
     r"materials\[1\] = 'steel' is not a volspring Material or None"),
    ({"materials": SOFT}, TypeError, r"materials is a single Material"),
    ({"node_body": [0, 0, 1, 1], "body_names": ("a",)}, ValueError, r"len\(body_names\) = 1, but the model has 2"),
    ({"body_names": (3,)}, TypeError, r"body_names\[0\] = 3 is not a str"),
    ({"node_body": [0, 0, 1, 1], "materials": (SOFT, HARD), "material": SOFT}, ValueError,
     r"material = Material\(.*\), but the bodies' materials differ from it"),
])
def test_model_refuses_bad_body_fields_naming_the_value(fields, error, message):
    points = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    with pytest.raises(error, match=message):
        Model(points, np.ones(4), (), **fields)


def test_a_model_of_bodies_from_arrays_is_the_same_type():
    points = np.array([[0.0, 0, 0], [1, 0, 0], [5, 0, 0], [6, 0, 0]])
    pair = Model.from_arrays(points, np.ones(4), [[0, 1], [2, 3]], stiffness=10.0)
    two = Model(pair.rest_positions, pair.masses, pair.elements, node_body=[0, 0, 1, 1], materials=(SOFT, None),
                body_names=("left", "right"))
    assert type(two) is Model and two.body_count == 2 and two.material is None
    assert two.body_nodes(1).tolist() == [2, 3] and two.body_masses.tolist() == [2.0, 2.0]
    with pytest.raises(ValueError, match=r"body = 2 is not a body id in \[0, 1\]"):
        two.body_nodes(2)


@pytest.mark.parametrize("rungs", [("smoothed", "springs+volume"), ("smoothed", "smoothed"), ("springs", "smoothed")])
def test_bodies_on_any_rung_feel_the_forces_of_their_own_models(rungs):
    """A placed, rotated body of a multi-body model pushes exactly as its own model does in its own frame:
    F_model[body] = R F_body(local positions) for the rotation-invariant energies of every rung."""
    from scipy.spatial.transform import Rotation

    from volspring.elements import Springs

    rubber = Material(E=1e6, nu=0.45, density=1000.0)
    mesh = cube_mesh((2, 2, 2), (0.1, 0.1, 0.1))
    turn = Rotation.from_rotvec([0.3, -0.5, 0.9]).as_matrix()
    bodies = [Body(mesh, rubber, model=rungs[0], damping_ratio=0.05, name="a"),
              Body(mesh, rubber, model=rungs[1], translation=(0.5, 0.0, 0.0), rotation=turn, name="b")]
    model = Model.from_bodies(bodies)
    assert model.rung == (rungs[0] if rungs[0] == rungs[1] else "mixed")
    assert sum(not isinstance(e, Springs) for e in model.elements) == sum(
        sum(not isinstance(e, Springs) for e in Model.from_mesh(mesh, rubber, model=rung).elements) for rung in rungs)
    assert np.abs(model.forces(model.rest_positions)).max() < 1e-9  # placed at rest
    rng = np.random.default_rng(5)
    local = [mesh.points + 0.01 * rng.standard_normal(mesh.points.shape) for _ in bodies]
    x = np.concatenate([local[0], local[1] @ turn.T + [0.5, 0.0, 0.0]])
    forces = model.forces(x)
    n = mesh.node_count
    for index, (body, positions) in enumerate(zip(bodies, local)):
        own = Model.from_mesh(mesh, rubber, model=body.model, damping_ratio=body.damping_ratio).forces(positions)
        rotation = np.eye(3) if index == 0 else turn
        # Round-off of the rotation and of sums over a few dozen tets: 1e-10 of the force scale.
        np.testing.assert_allclose(forces[index * n:(index + 1) * n], own @ rotation.T, rtol=0,
                                   atol=1e-10 * abs(own).max())
