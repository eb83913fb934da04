"""Material, spring model construction, spring forces and their Jacobians."""

import numpy as np
import pytest

from meshing import SpringTopology
from volspring import Material, Model
from volspring.springs import damper_blocks, spring_energy, spring_forces, spring_stiffness_blocks

from conftest import cube_mesh

STEEL_LIKE = Material(E=2e5, nu=0.3, density=1000.0)


@pytest.mark.parametrize("E, nu, density, message", [
    (0.0, 0.3, 1.0, "E = 0.0"), (1.0, 0.5, 1.0, "nu = 0.5"), (1.0, -1.0, 1.0, "nu = -1.0"),
    (1.0, 0.3, -2.0, "density = -2.0"), (float("nan"), 0.3, 1.0, "E = nan"),
])
def test_material_refuses_nonsense(E, nu, density, message):
    with pytest.raises(ValueError, match=message):
        Material(E=E, nu=nu, density=density)


def test_masses_are_density_times_volume():
    mesh = cube_mesh((3, 2, 2), size=(0.3, 0.1, 0.1))
    model = Model.from_mesh(mesh, STEEL_LIKE)
    # Lumping only redistributes: total mass is rho V up to round-off.
    assert model.total_mass == pytest.approx(STEEL_LIKE.density * mesh.volume, rel=1e-12)
    assert model.spring_count == len(mesh.edges)


def test_single_tet_rules_match_their_formulas():
    points = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    mesh = cube_mesh((1, 1, 1)).__class__(points, np.array([[0, 1, 2, 3]]))
    volume = 1 / 6
    van_gelder = Model.from_mesh(mesh, STEEL_LIKE, rule="van_gelder")
    assert np.allclose(van_gelder.stiffness, STEEL_LIKE.E * volume / mesh.edge_lengths**2, rtol=1e-14)
    lloyd = Model.from_mesh(mesh, STEEL_LIKE, rule="lloyd")
    expected = 2 * np.sqrt(2) / 25 * STEEL_LIKE.E * (6 * np.sqrt(2) * volume) ** (1 / 3)
    assert np.allclose(lloyd.stiffness, expected, rtol=1e-14)
    uniform = Model.from_mesh(mesh, STEEL_LIKE, rule="uniform", stiffness=7.0, law="strain")
    assert np.allclose(uniform.stiffness, 7.0 / mesh.edge_lengths, rtol=1e-14)


def test_interior_edge_sums_over_its_tets():
    mesh = cube_mesh((2, 2, 2))
    model = Model.from_mesh(mesh, STEEL_LIKE, rule="van_gelder")
    # Rebuild k_e by an explicit loop over tets: the vectorised scatter must agree.
    expected = np.zeros(len(mesh.edges))
    for tet, edge_ids in zip(range(mesh.tet_count), mesh.tet_edge_index):
        expected[edge_ids] += STEEL_LIKE.E * mesh.tet_volumes[tet] / mesh.edge_lengths[edge_ids] ** 2
    assert np.allclose(model.stiffness, expected, rtol=1e-13)


def test_rule_and_stiffness_are_checked():
    mesh = cube_mesh((1, 1, 1))
    with pytest.raises(ValueError, match="unknown stiffness rule"):
        Model.from_mesh(mesh, STEEL_LIKE, rule="magic")
    with pytest.raises(ValueError, match="required by rule='uniform'"):
        Model.from_mesh(mesh, STEEL_LIKE, rule="uniform")
    with pytest.raises(ValueError, match=r"stiffness\[1\] = -1.0"):
        Model.from_arrays(np.eye(3), np.ones(3), [[0, 1], [1, 2]], stiffness=[1.0, -1.0])
    with pytest.raises(ValueError, match=r"masses\[0\] = 0.0"):
        Model.from_arrays(np.eye(3), [0.0, 1, 1], [[0, 1]], stiffness=1.0)


TRIANGLE = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])


@pytest.mark.parametrize("arguments, error, message", [
    # spring indices: floats used to be truncated, (k, 3) or (2, s) arrays cut into wrong pairs
    ({"springs": [[0, 1.7]]}, TypeError, r"springs have dtype float64; expected integer node indices"),
    ({"springs": [[0, 1, 2], [1, 2, 0]]}, ValueError, r"springs have shape \(2, 3\); expected \(s, 2\)"),
    ({"springs": [0, 1]}, ValueError, r"springs have shape \(2,\); expected \(s, 2\).*\[\[0, 1\]\] for one spring"),
    ({"springs": [[0, 1], [2, -1]]}, ValueError, r"springs\[1\] = \[2, -1\] indexes a node outside \[0, 2\] "
                                                 r"\(the model has 3 nodes; 1 spring\(s\) affected\)"),
    ({"springs": [[0, 3]]}, ValueError, r"springs\[0\] = \[0, 3\] indexes a node outside \[0, 2\]"),
    ({"springs": [[0, 1], [2, 2]], "law": "strain"}, ValueError, r"springs\[1\] = \[2, 2\] joins node 2 to itself"),
    ({"positions": [[0, 0, 0], [0, 0, 0], [0, 1, 0]]}, ValueError,
     r"springs\[0\] = \[0, 1\] joins two nodes at the same position \[0.0, 0.0, 0.0\] m: its rest length would be 0"),
    ({"positions": [[0, 0, 0], [1, np.nan, 0], [0, 1, 0]]}, ValueError, r"positions\[1\] = \[1.0, nan, 0.0\] m is not finite"),
    ({"positions": [[0, 0], [1, 0], [0, 1]]}, ValueError, r"positions must have shape \(n, 3\) with n > 0, got \(3, 2\)"),
    ({"masses": [1.0, np.nan, 1.0]}, ValueError, r"masses\[1\] = nan is not finite and > 0"),
    ({"masses": [1.0, -2.0, 1.0]}, ValueError, r"masses\[1\] = -2.0 is not finite and > 0"),
    ({"masses": [1.0, 1.0]}, ValueError, r"len\(rest_positions\) = 3, but masses have shape \(2,\)"),
    ({"stiffness": np.nan}, ValueError, r"stiffness\[0\] = nan is not finite and >= 0"),
    ({"stiffness": [1.0, 2.0, 3.0]}, ValueError, r"stiffness has shape \(3,\); expected a number or shape \(2,\)"),
    ({"damping": -1.0}, ValueError, r"damping\[0\] = -1.0 is not finite and >= 0"),
    ({"rest_lengths": [1.0, 0.0]}, ValueError, r"rest_lengths\[1\] = 0.0 is not finite and > 0"),
    ({"law": "linear"}, ValueError, "unknown force law 'linear'; known: hooke, strain"),
])
def test_from_arrays_refuses_what_it_would_misread(arguments, error, message):
    given = {"positions": TRIANGLE, "masses": np.ones(3), "springs": [[0, 1], [1, 2]], "stiffness": 10.0, **arguments}
    with pytest.raises(error, match=message):
        Model.from_arrays(given.pop("positions"), given.pop("masses"), given.pop("springs"), **given)


def test_from_mesh_refuses_what_it_would_ignore_or_misread():
    mesh = cube_mesh((1, 1, 1))
    with pytest.raises(TypeError, match="body must be a TetMesh or SpringTopology, got str"):
        Model.from_mesh("cube.msh", STEEL_LIKE)
    with pytest.raises(TypeError, match="material must be a volspring.Material, got dict"):
        Model.from_mesh(mesh, {"E": 1e5})
    # law= reads the raw uniform constant; with a material rule it used to be ignored silently
    with pytest.raises(ValueError, match="law='strain' applies to rule='uniform' only: rule='van_gelder' gives"):
        Model.from_mesh(mesh, STEEL_LIKE, law="strain")
    with pytest.raises(ValueError, match="unknown force law 'strian'"):
        Model.from_mesh(mesh, STEEL_LIKE, rule="uniform", stiffness=1.0, law="strian")
    with pytest.raises(ValueError, match="stiffness = nan is not finite and >= 0"):
        Model.from_mesh(mesh, STEEL_LIKE, rule="uniform", stiffness=float("nan"))
    with pytest.raises(ValueError, match="damping_ratio = -0.1 is not finite and >= 0"):
        Model.from_mesh(mesh, STEEL_LIKE, damping_ratio=-0.1)
    with pytest.raises(ValueError, match=r"damping has shape \(2,\); expected a number or shape \(19,\)"):
        Model.from_mesh(mesh, STEEL_LIKE, damping=[1.0, 2.0])


@pytest.mark.parametrize("bad, error", [(True, TypeError), ("1e5", TypeError), (np.inf, ValueError)])
def test_material_refuses_what_is_not_a_finite_number(bad, error):
    with pytest.raises(error, match=r"^E = .*(is not a real number|is not a finite number)"):
        Material(E=bad, nu=0.3, density=1.0)


def test_damping_ratio_gives_critical_damping_for_one_spring():
    model = Model.from_arrays([[0, 0, 0], [1, 0, 0]], [2.0, 2.0], [[0, 1]], stiffness=50.0)
    topology = SpringTopology.from_mesh(cube_mesh((1, 1, 1)))
    damped = Model.from_mesh(topology, STEEL_LIKE, damping_ratio=1.0)
    m_i, m_j = damped.masses[damped.springs].T
    assert np.allclose(damped.damping, 2 * np.sqrt(damped.stiffness * m_i * m_j / (m_i + m_j)), rtol=1e-14)
    assert model.damping[0] == 0.0


def _random_state(model, seed, amplitude=0.05):
    rng = np.random.default_rng(seed)
    x = model.rest_positions + amplitude * rng.standard_normal(model.rest_positions.shape)
    v = rng.standard_normal(x.shape)
    return x, v


def test_forces_conserve_momentum_and_derive_from_energy():
    mesh = cube_mesh((2, 1, 1))
    model = Model.from_mesh(mesh, STEEL_LIKE, damping_ratio=0.3)
    x, v = _random_state(model, 0)
    forces = spring_forces(model, x, v)
    # Internal forces sum to zero: only round-off of the force magnitudes (~1e-16 relative) remains.
    assert np.abs(forces.sum(axis=0)).max() <= 1e-12 * np.abs(forces).max()
    # Torque too, for springs (central forces) without dampers.
    f = spring_forces(model, x)
    assert np.abs(np.cross(x, f).sum(axis=0)).max() <= 1e-12 * np.abs(np.cross(x, f)).max()
    # F = -grad E, central differences: error O(h^2) ~ 1e-12 relative at h = 1e-6.
    h, node = 1e-6, 3
    for axis in range(3):
        plus, minus = x.copy(), x.copy()
        plus[node, axis] += h
        minus[node, axis] -= h
        gradient = (spring_energy(model, plus) - spring_energy(model, minus)) / (2 * h)
        assert -gradient == pytest.approx(f[node, axis], rel=1e-6)


def test_jacobian_blocks_match_finite_differences():
    model = Model.from_arrays([[0, 0, 0], [1, 0, 0]], [1.0, 1.0], [[0, 1]], stiffness=30.0, damping=2.0)
    x = np.array([[0.0, 0, 0], [1.3, 0.2, -0.1]])  # stretched: the transverse term is positive, no clamp
    v = np.array([[0.1, 0.0, 0.3], [-0.2, 0.5, 0.0]])
    H = spring_stiffness_blocks(model, x)[0]
    D = damper_blocks(model, x)[0]
    h = 1e-7
    for axis in range(3):
        dx = np.zeros_like(x)
        dx[1, axis] = h
        # dF_i/dx_j = +H (column axis); central difference error O(h^2), relative 1e-6 is generous.
        dF = (spring_forces(model, x + dx) - spring_forces(model, x - dx))[0] / (2 * h)
        assert np.allclose(dF, H[:, axis], rtol=1e-6, atol=1e-8 * np.abs(H).max())
        dF = (spring_forces(model, x, v + dx) - spring_forces(model, x, v - dx))[0] / (2 * h)
        assert np.allclose(dF, D[:, axis], rtol=1e-6, atol=1e-8 * np.abs(D).max())


def test_compressed_spring_block_is_clamped_positive_semidefinite():
    model = Model.from_arrays([[0, 0, 0], [1, 0, 0]], [1.0, 1.0], [[0, 1]], stiffness=30.0)
    x = np.array([[0.0, 0, 0], [0.5, 0.1, 0]])
    assert np.linalg.eigvalsh(spring_stiffness_blocks(model, x)[0]).min() >= -1e-12
    assert np.linalg.eigvalsh(spring_stiffness_blocks(model, x, clamp_compression=False)[0]).min() < 0


def test_collapsed_spring_is_an_error_not_nan():
    model = Model.from_arrays([[0, 0, 0], [1, 0, 0]], [1.0, 1.0], [[0, 1]], stiffness=1.0)
    with pytest.raises(FloatingPointError, match="spring 0 between nodes 0 and 1"):
        spring_forces(model, np.zeros((2, 3)))


def _enclosed_volume(points, triangles):
    x = points[triangles]
    return np.einsum("ij,ij->", x[:, 0], np.cross(x[:, 1], x[:, 2])) / 6


@pytest.mark.parametrize("rule", ["van_gelder", "lloyd"])
def test_shells_add_their_own_mass_and_stiffen_every_shell_spring(rule):
    from meshing.shells import add_shells

    mesh = cube_mesh((3, 3, 3))
    thickness = 0.02
    topology = add_shells(mesh, layers=2, thickness=thickness)
    model = Model.from_mesh(topology, STEEL_LIKE, rule=rule)
    body = model.masses[: mesh.node_count]
    # The body's own nodes keep exactly the mass of their tets (the documented rule).
    assert np.allclose(body, STEEL_LIKE.density * mesh.node_volumes(), rtol=1e-14)
    # The shell weighs density x the volume between the mesh boundary and the outer layer.
    # Prisms split into 3 tets do not tile that volume exactly where the side quads of two
    # neighbouring prisms are non-planar (cube corners and edges); at t / L = 0.02 the
    # mismatch measured 0.04% (0.15% at t / L = 0.1), so 1% bounds it with margin.
    outer = topology.shell_triangles[topology.shell_layer[topology.shell_triangles[:, 0]] == 2]
    shell_volume = _enclosed_volume(topology.points, outer) - mesh.volume
    assert model.masses[mesh.node_count:].sum() == pytest.approx(STEEL_LIKE.density * shell_volume, rel=1e-2)
    shell_springs = topology.kinds > 0
    assert (model.stiffness[shell_springs] > 0).all()
    # Tet edges get the same stiffness as without shells: prisms touch only shell springs.
    alone = Model.from_mesh(mesh, STEEL_LIKE, rule=rule)
    assert np.allclose(np.sort(model.stiffness[~shell_springs]), np.sort(alone.stiffness), rtol=1e-14)


def test_a_models_springs_share_their_topologys_arrays_and_copy_what_could_change():
    """The spring set holds the topology's node pairs and rest lengths themselves (read-only arrays of their own, so
    nothing can change them), not copies; an array that could still change (writeable, or a read-only view of a
    writeable one) is copied."""
    from volspring.elements import Springs

    model = Model.from_mesh(cube_mesh(), Material(1e6, 0.3, 1000.0))
    topology, springs = model.topology, model.elements[0]
    assert np.shares_memory(springs.pairs, topology.springs) and np.shares_memory(springs.rest_lengths,
                                                                                  topology.rest_lengths)
    writeable = topology.springs.copy()
    view = writeable.view()
    view.setflags(write=False)
    n, s = model.node_count, topology.spring_count
    for pairs in (writeable, view):
        made = Springs(n, pairs, 1.0, 0.0, topology.rest_lengths, 0)
        assert not np.shares_memory(made.pairs, writeable)
        writeable[0] = [0, 1] if tuple(writeable[0]) != (0, 1) else [0, 2]  # a later change does not reach it
        assert np.array_equal(made.pairs, topology.springs)
        writeable[0] = topology.springs[0]
    assert len(made.stiffness) == s
