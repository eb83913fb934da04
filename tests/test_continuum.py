"""The continuum element sets of the ladder's upper rungs (volspring.elements.continuum) and the ladder.

Checked against calculus (forces are minus the energy's gradient, blocks its Hessian), against
invariance (rigid motions are free), against the patch test (a homogeneous strain is reproduced
exactly, so E and nu come out exact on any mesh) and against the FEM reference's frequencies.
"""

import numpy as np
import pytest
from conftest import dense_blocks, energy_gradient

from meshing import TetMesh, structured_box
from volspring import Material, Model, Scene
from volspring.elements import CorotatedTets, NodalStrain
from volspring.elements.base import _block_product
from volspring.elements.tet_kinematics import merged_pairs, pair_nodes
from volspring.ladder import MODELS, network_moduli, network_poisson_ratio

RNG_SEED = 11


def _rotation(seed):
    q, _ = np.linalg.qr(np.random.default_rng(seed).standard_normal((3, 3)))
    return q * np.sign(np.linalg.det(q))


@pytest.fixture(scope="module")
def cube():
    return structured_box((2, 2, 2), (1.0, 1.0, 1.0))


@pytest.fixture(scope="module")
def irregular():
    """A Delaunay mesh of jittered grid points: no two tets alike (an unstructured mesh for the patch test)."""
    from scipy.spatial import Delaunay

    rng = np.random.default_rng(RNG_SEED)
    grid = np.stack(np.meshgrid(*[np.linspace(0, 1, 5)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    interior = ((grid > 0) & (grid < 1)).all(axis=1)
    grid[interior] += rng.uniform(-0.08, 0.08, (interior.sum(), 3))
    tets = Delaunay(grid).simplices
    corners = grid[tets]
    volumes = np.linalg.det(corners[:, 1:] - corners[:, :1]) / 6
    tets = tets[np.abs(volumes) > 1e-6]  # Delaunay leaves flat tets between coplanar boundary points
    return _oriented(grid, tets)


def _oriented(points, tets):
    corners = points[tets]
    negative = np.linalg.det(corners[:, 1:] - corners[:, :1]) < 0
    tets = tets.copy()
    tets[negative, 2:] = tets[negative, 3:1:-1]
    return TetMesh.compact(points, tets)


def _sets(mesh):
    regions = (mesh.points[mesh.tets].mean(axis=1)[:, 0] > 0.5).astype(np.int64)
    return {
        "corotated": CorotatedTets(mesh.points, mesh.tets, 1.0),
        "nodal": NodalStrain(mesh.points, mesh.tets, 0.6, 2.0),
        "nodal_regions": NodalStrain(mesh.points, mesh.tets, np.where(regions, 0.6, 1.0), np.where(regions, 2.0, 5.0),
                                     regions=regions),
        "volume_only": NodalStrain(mesh.points, mesh.tets, 0.0, 3.0),
        "clustered": NodalStrain(mesh.points, mesh.tets, 0.6, 2.0, clusters=pair_nodes(mesh.points, mesh.tets)),
        "held_pairs": NodalStrain(mesh.points, mesh.tets, 0.6, 2.0, clusters="pairs", held=mesh.points[:, 0] < 0.3),
        "held_merged": NodalStrain(mesh.points, mesh.tets, 0.0, 2.0, clusters="merged pairs",
                                   held=mesh.points[:, 0] < 0.3),
    }


# A deformation of 15% of the cell size at random: large strains, some tets near inversion.
@pytest.mark.parametrize("name", ["corotated", "nodal", "nodal_regions", "volume_only", "clustered", "held_pairs",
                                  "held_merged"])
def test_forces_are_the_energy_gradient_and_blocks_its_hessian(cube, name):
    element_set = _sets(cube)[name]
    rng = np.random.default_rng(RNG_SEED)
    x = cube.points + 0.15 * rng.standard_normal(cube.points.shape)
    h = 1e-6
    gradient = energy_gradient(element_set, x, h)
    forces = element_set.forces(x)
    # Central differences at h = 1e-6 on O(1) energies: truncation h^2 ~ 1e-12, round-off 1e-16 / h ~ 1e-10.
    assert np.abs(forces + gradient).max() <= 1e-8 * np.abs(forces).max()
    u = rng.standard_normal(x.shape)
    exact = _block_product(element_set, element_set.stiffness_blocks(x, clamp_compression=False), u)
    differenced = -(element_set.forces(x + h * u) - element_set.forces(x - h * u)) / (2 * h)
    assert np.abs(exact - differenced).max() <= 1e-8 * np.abs(differenced).max()


@pytest.mark.parametrize("name", ["corotated", "nodal", "nodal_regions", "volume_only", "clustered", "held_pairs",
                                  "held_merged"])
def test_projected_blocks_are_symmetric_positive_semidefinite(cube, name):
    element_set = _sets(cube)[name]
    x = cube.points + 0.2 * np.random.default_rng(RNG_SEED + 1).standard_normal(cube.points.shape)
    A = dense_blocks(element_set, element_set.stiffness_blocks(x), cube.node_count)
    eigenvalues = np.linalg.eigvalsh(A)
    # Exact zero eigenvalues (rigid modes, twist directions clamped to 0) come out at round-off: 1e-12 relative.
    assert np.abs(A - A.T).max() <= 1e-12 * np.abs(A).max()
    assert eigenvalues.min() >= -1e-12 * eigenvalues.max()


@pytest.mark.parametrize("rung", MODELS)
def test_rigid_motion_costs_no_energy_on_any_rung(cube, rung):
    model = Model.from_mesh(cube, Material(E=1e6, nu=0.45, density=1000.0), model=rung)
    x = cube.points @ _rotation(3).T + np.array([0.3, -2.0, 5.0])
    # Energies are E * strain^2 * V ~ 1e6 at unit strain; a rotation leaves round-off of ~1e-16 in F.
    assert model.energy(x) <= 1e-20 * 1e6
    assert np.abs(model.forces(x)).max() <= 1e-8


def test_an_inverted_tet_is_pushed_back_with_finite_forces(cube):
    model = Model.from_mesh(cube, Material(E=1e6, nu=0.45, density=1000.0), model="smoothed")
    x = cube.points.copy()
    centre = np.argmin(np.abs(cube.points - 0.5).sum(axis=1))
    x[centre, 2] += 0.9  # the middle node pushed through the top layer: tets below it stretch, above invert
    volumes = np.linalg.det(np.transpose(x[cube.tets[:, 1:]] - x[cube.tets[:, :1]], (0, 2, 1)))
    assert (volumes < 0).any()
    forces = model.forces(x)
    assert np.isfinite(forces).all() and np.isfinite(model.energy(x))
    assert forces[centre, 2] < 0  # back down, towards the rest shape
    # The energy falls along the force (it is a descent direction).
    assert model.energy(x + 1e-9 * forces) < model.energy(x)


@pytest.mark.parametrize("nu", [0.25, 0.3, 0.45, 0.49, 0.499])
def test_smoothed_rung_passes_the_patch_test_on_an_unstructured_mesh(irregular, nu):
    """A homogeneous strain: zero force on every interior node, energy exactly V (mu |eps|^2 + lambda/2 tr^2)."""
    material = Material(E=2e6, nu=nu, density=1000.0)
    model = Model.from_mesh(irregular, material, model="smoothed")
    eps = 1e-6 * np.array([[1.0, 0.3, -0.2], [0.3, -0.5, 0.4], [-0.2, 0.4, 0.7]])
    x = irregular.points + irregular.points @ eps.T
    interior = np.setdiff1d(np.arange(irregular.node_count), irregular.boundary_nodes)
    forces = model.forces(x)
    scale = np.abs(forces[irregular.boundary_nodes]).max()
    assert np.abs(forces[interior]).max() <= 1e-8 * scale  # round-off of the force sums: 1e-8 of a boundary force
    mu, lam = material.shear_modulus, material.lame_lambda
    linear = irregular.volume * (mu * (eps**2).sum() + 0.5 * lam * np.trace(eps) ** 2)
    # The nonlinear energy differs from the linear one at O(strain^3): 1e-6 relative.
    assert model.energy(x) == pytest.approx(linear, rel=1e-5)


def test_springs_fail_the_patch_test(irregular):
    """What the smoothed rung fixes: springs leave forces on interior nodes under a homogeneous strain."""
    model = Model.from_mesh(irregular, Material(E=2e6, nu=0.3, density=1000.0))
    x = irregular.points * np.array([1 + 1e-6, 1.0, 1.0])
    interior = np.setdiff1d(np.arange(irregular.node_count), irregular.boundary_nodes)
    forces = model.forces(x)
    assert np.abs(forces[interior]).max() > 1e-2 * np.abs(forces[irregular.boundary_nodes]).max()


@pytest.fixture(scope="module")
def probe_meshes(irregular):
    return {"structured 4^3": structured_box((4, 4, 4), (1.0, 1.0, 1.0)), "unstructured": irregular}


@pytest.mark.parametrize("nu", [0.25, 0.3, 0.45, 0.49])
def test_smoothed_rung_has_exact_e_and_nu_under_uniaxial_stress(probe_meshes, nu):
    from validation.springs import effective_constants

    material = Material(E=1e6, nu=nu, density=1000.0)
    for mesh in probe_meshes.values():
        found = effective_constants(mesh, Model.from_mesh(mesh, material, model="smoothed"))
        # The goal: E and nu within 1% on any mesh (measured: E 0.3-0.4% soft, nu within 0.002).
        assert found["E_pa"] == pytest.approx(material.E, rel=0.01)
        assert found["nu"] == pytest.approx(nu, rel=0.01)


def test_volume_rung_moves_nu_towards_the_asked_value(probe_meshes):
    """Springs keep their own nu (about 0.16); the volume term brings it near the asked one at high nu."""
    from validation.springs import effective_constants

    for mesh in probe_meshes.values():
        springs_nu = effective_constants(mesh, Model.from_mesh(mesh, Material(E=1e6, nu=0.3, density=1000.0)))["nu"]
        for nu in (0.3, 0.45, 0.49):
            found = effective_constants(mesh, Model.from_mesh(mesh, Material(E=1e6, nu=nu, density=1000.0),
                                                              model="springs+volume"))
            assert abs(found["nu"] - nu) < abs(springs_nu - nu)
        # At 0.49 within the goal's 0.03 (the goal at every nu and mesh: tests/test_volume_rung.py).
        assert found["nu"] == pytest.approx(0.49, abs=0.03)
        # The volume change per axial strain (exact 1 - 2 nu = 0.02) within the goal's 10% (measured 0.96-1.00x
        # since the axes-only network probes; 1.25-1.42x before; springs alone: 32-35x).
        assert abs(found["volume_strain_per_axial_strain"] / 0.02 - 1) < 0.1


def test_volume_rung_refuses_a_poisson_ratio_below_the_springs(irregular):
    mu_s, bulk_s = network_moduli(irregular, Model.from_mesh(irregular, Material(E=1.0, nu=0.3, density=1.0)).spring_elements)
    own = network_poisson_ratio(mu_s, bulk_s)
    assert 0.1 < own < 0.3  # the Cauchy limit: about 1/4 for a tet network (REFERENCE.md section 2)
    with pytest.raises(ValueError, match=r"nu = 0\.05.*model='smoothed'"):
        Model.from_mesh(irregular, Material(E=1e6, nu=0.05, density=1000.0), model="springs+volume")


def test_model_names_and_parameters_are_checked(cube):
    material = Material(E=1e6, nu=0.3, density=1000.0)
    with pytest.raises(ValueError, match="unknown model 'fem'; known: springs, springs\\+volume, smoothed"):
        Model.from_mesh(cube, material, model="fem")
    with pytest.raises(ValueError, match="alpha = 1.5 is not in"):
        Model.from_mesh(cube, material, model="smoothed", alpha=1.5)
    with pytest.raises(ValueError, match="alpha= is the smoothed rung's"):
        Model.from_mesh(cube, material, model="springs", alpha=0.5)
    with pytest.raises(ValueError, match="rule=, stiffness= and damping= do not apply"):
        Model.from_mesh(cube, material, model="smoothed", rule="lloyd")


def test_materials_per_region_on_every_rung(cube):
    """Two regions, the soft one twice as soft: the mass and stiffness follow each tet's material."""
    soft, hard = Material(E=1e6, nu=0.3, density=1000.0), Material(E=2e6, nu=0.3, density=3000.0)
    regions = (cube.points[cube.tets].mean(axis=1)[:, 0] > 0.5).astype(np.int64)
    for rung in MODELS:
        tagged = Model.from_mesh(cube, soft, model=rung, regions=regions, materials={1: hard})
        assert tagged.total_mass == pytest.approx(0.5 * 1000.0 + 0.5 * 3000.0)
        # Stretching along y is parallel to the interface: the stiffnesses add, 1.5x the soft body's.
        x = cube.points * np.array([1.0, 1.0 + 1e-6, 1.0])
        uniform = Model.from_mesh(cube, soft, model=rung)
        assert tagged.energy(x) / uniform.energy(x) == pytest.approx(1.5, rel=0.05 if rung != "smoothed" else 1e-4)
    with pytest.raises(ValueError, match="no tet has that tag"):
        Model.from_mesh(cube, soft, regions=regions, materials={7: hard})


@pytest.mark.parametrize("nu", [0.3, 0.49])
def test_smoothed_frequencies_match_p2_without_spurious_modes(nu):
    """The first ten free-vibration frequencies of a clamped beam against P2 on the same mesh; at nu 0.49 with
    lambda above PAIR_BULK_CAP mu on merged pairs, whose coarser domains must not bring soft modes."""
    from validation.cases import cantilever_modes
    from validation.fem import solve_fem_modes
    from validation.springs import held_nodes, spring_frequencies

    case = cantilever_modes(per_height=2, count=10)
    material = Material(E=case.material.E, nu=nu, density=case.material.density)
    reference = solve_fem_modes(case.mesh, (material.E, nu, material.density), clamp=list(case.clamps), count=10)
    model = Model.from_mesh(case.mesh, material, model="smoothed")
    assert len(model.elements) == (4 if nu == 0.49 else 3)
    frequencies, _ = spring_frequencies(model, held_nodes(case), count=10)
    ratio = frequencies / reference.frequencies
    print("smoothed / P2 frequencies:", np.round(ratio, 4))
    # No spurious low modes: every frequency within the band the discretisation error allows; measured 0.95-1.01
    # on this 20 x 2 x 2 beam at nu 0.3 with the volume on node pairs (0.99-1.06 on single nodes), 0.94-0.99 at
    # 0.49 (0.94-1.00 with all of lambda on pairs; same-mesh P2 is itself about 1% stiff there, study_locking.py).
    assert ratio.min() > 0.9 and ratio.max() < 1.15
    # The goal for the first three: within 3% (measured 0.996, 1.008, 0.987 at nu 0.3; 0.981, 0.994,
    # 0.975 at 0.49).
    assert np.abs(ratio[:3] - 1).max() < 0.03


def test_symplectic_euler_conserves_energy_below_the_critical_step(cube):
    from volspring.integrators import make_integrator
    from volspring.stability import critical_step, omega_max_estimate

    model = Model.from_mesh(cube, Material(E=1e5, nu=0.45, density=1000.0), model="smoothed")
    scene = Scene(model)
    dt = 0.5 * critical_step("symplectic_euler", omega_max_estimate(scene))
    rng = np.random.default_rng(RNG_SEED)
    state = scene.initial_state(v=0.05 * rng.standard_normal(cube.points.shape))
    integrator = make_integrator("symplectic_euler")
    energies = []
    for _ in range(2000):
        state = integrator.step(scene, state, dt)
        energies.append(model.energy(state.x) + 0.5 * (model.masses[:, None] * state.v**2).sum())
    energies = np.array(energies)
    # Symplectic Euler keeps a shadow energy: the true energy oscillates by O(h omega) without drift.
    assert energies.std() / energies.mean() < 0.05
    assert abs(energies[-200:].mean() / energies[:200].mean() - 1) < 0.01


def test_damping_ratio_damps_the_highest_mode_by_zeta(cube):
    """Rayleigh stiffness damping b = 2 zeta / omega_max: the highest mode decays at zeta omega_max = 2 zeta / b."""
    from volspring.integrators import make_integrator
    from volspring.stability import omega_max_estimate

    material = Material(E=1e5, nu=0.45, density=1000.0)
    damped = Model.from_mesh(cube, material, model="smoothed", damping_ratio=0.1)
    omega = omega_max_estimate(Model.from_mesh(cube, material, model="smoothed"))
    for element_set in damped.elements:
        assert element_set.stiffness_damping == pytest.approx(2 * 0.1 / omega, rel=1e-12)
    v0 = 0.05 * np.random.default_rng(RNG_SEED).standard_normal(cube.points.shape)

    def energy_after(model, steps=50):
        scene = Scene(model)
        state = scene.initial_state(v=v0)
        integrator = make_integrator("symplectic_euler")  # conserves energy undamped: the loss is the damping's
        for _ in range(steps):
            state = integrator.step(scene, state, 0.2 / omega)
        return model.energy(state.x) + 0.5 * (model.masses[:, None] * state.v**2).sum()

    undamped = energy_after(Model.from_mesh(cube, material, model="smoothed"))
    # Measured 0.78 after 50 steps; without damping the ratio is 1 up to the shadow energy's O(h omega) wobble.
    assert energy_after(damped) < 0.9 * undamped


def test_fast_rotation_preserving_svd_agrees_with_lapack():
    """The Jacobi path (well-conditioned F) and the LAPACK fallback (inverted, flat, ill-conditioned) both give
    F = U diag(s) V^T with rotations U, V and the same rotation U V^T and sorted |s| as numpy's SVD."""
    from volspring.elements.tet_kinematics import rotation_preserving_svd

    rng = np.random.default_rng(7)
    turn = np.linalg.qr(rng.standard_normal((3, 3)))[0]
    turn *= np.sign(np.linalg.det(turn))
    F = np.concatenate([
        np.eye(3)[None] + 0.3 * rng.standard_normal((400, 3, 3)),  # large strains, some inverted
        np.eye(3)[None] + 1e-6 * rng.standard_normal((50, 3, 3)),  # near rest
        np.broadcast_to(turn, (5, 3, 3)),                          # rigid rotation: repeated s = 1
        np.broadcast_to(np.diag([2.0, 2.0, 0.5]), (5, 3, 3)),      # a repeated pair
        np.broadcast_to(np.diag([1.0, 1.0, 1e-4]), (5, 3, 3)),     # nearly flat: the fallback
        np.broadcast_to(np.diag([1.0, 1.0, -0.5]), (5, 3, 3)),     # inverted: the fallback
        np.zeros((2, 3, 3)),                                       # collapsed to a point
    ])
    U, s, Vt = rotation_preserving_svd(F)
    # Rounding: the Jacobi path works on F^T F, at most 1e4 eps relative (condition <= 100 there).
    scale = np.abs(F).max(axis=(1, 2), keepdims=True) + 1.0
    assert np.abs(U * s[:, None, :] @ Vt - F).max() < 1e-11 * scale.max()
    for Q in (U, np.swapaxes(Vt, 1, 2)):
        assert np.abs(np.swapaxes(Q, 1, 2) @ Q - np.eye(3)).max() < 1e-12
        assert np.allclose(np.linalg.det(Q), 1.0, atol=1e-12)
    reference = np.sort(np.linalg.svd(F, compute_uv=False), axis=1)
    assert np.allclose(np.sort(np.abs(s), axis=1), reference, rtol=0, atol=1e-12)
    inverted = np.linalg.det(F) < 0
    assert ((s < 0).sum(axis=1) == inverted).all()  # one negative singular value exactly where F is inverted


def test_twist_rows_are_the_twists_times_the_vectors():
    """twist_rows(U, Vt, a) = q_r a without forming q_r (the smoothed rung's product rows), and the twists are an
    orthonormal set orthogonal to the stretch directions u_i v_i^T (what makes them the rotation's directions)."""
    from volspring.elements.tet_kinematics import corotated, twist_directions, twist_rows

    rng = np.random.default_rng(3)
    F = np.eye(3)[None] + 0.3 * rng.standard_normal((200, 3, 3))
    vectors = rng.standard_normal((200, 4, 3))
    U, Vt, *_ = corotated(F)
    q = twist_directions(U, Vt)
    expected = np.einsum("mrij,mkj->mrki", q, vectors)
    # The same products in another order: round-off of a few eps of |a|.
    assert np.abs(twist_rows(U, Vt, vectors) - expected).max() < 1e-14 * np.abs(vectors).max()
    gram = np.einsum("mrij,msij->mrs", q, q)
    assert np.abs(gram - np.eye(3)).max() < 1e-13
    stretch = np.einsum("mic,mcj->mcij", U, Vt)  # u_c v_c^T, c = 0..2
    assert np.abs(np.einsum("mrij,mcij->mrc", q, stretch)).max() < 1e-13


def test_node_pairs_cover_every_node_along_edges(irregular):
    """pair_nodes: every node in one cluster of 2 (or 3 where a node is left over), its members joined by tet
    edges, the same labels every time (no random draw)."""
    labels = pair_nodes(irregular.points, irregular.tets)
    assert np.array_equal(labels, pair_nodes(irregular.points, irregular.tets))
    _, inverse, sizes = np.unique(labels, return_inverse=True, return_counts=True)
    assert set(sizes.tolist()) <= {2, 3} and (sizes == 2).sum() > 0.8 * len(sizes)
    edges = {tuple(sorted(e)) for t in irregular.tets.tolist() for e in
             ((t[0], t[1]), (t[0], t[2]), (t[0], t[3]), (t[1], t[2]), (t[1], t[3]), (t[2], t[3]))}
    for cluster in np.flatnonzero(sizes == 2):
        a, b = np.flatnonzero(inverse == cluster)
        assert (a, b) in edges


def test_merged_pairs_join_the_surface_pairs_to_a_neighbour_with_an_interior_node(irregular):
    """merged_pairs: a pair (pair_nodes) with an interior node keeps its label; a pair without one joins the
    lowest-labelled neighbouring pair (sharing a tet edge) that has one, or stays alone when none does. Checked
    pair by pair against that rule, written out here with Python sets."""
    pairs = pair_nodes(irregular.points, irregular.tets)
    merged = merged_pairs(irregular.points, irregular.tets)
    assert np.array_equal(merged, merged_pairs(irregular.points, irregular.tets))  # no random draw
    interior = np.ones(irregular.node_count, dtype=bool)
    interior[irregular.boundary_nodes] = False
    has_interior = {int(p) for p in pairs[interior]}
    neighbours = {}
    for a, b in irregular.edges.tolist():
        if pairs[a] != pairs[b]:
            neighbours.setdefault(int(pairs[a]), set()).add(int(pairs[b]))
            neighbours.setdefault(int(pairs[b]), set()).add(int(pairs[a]))
    expected = {}
    for p in map(int, np.unique(pairs)):
        inner = sorted(q for q in neighbours.get(p, ()) if q in has_interior)
        expected[p] = p if p in has_interior or not inner else inner[0]
    assert np.array_equal(merged, [expected[int(p)] for p in pairs])
    assert len(np.unique(merged)) < len(np.unique(pairs))  # this mesh has surface pairs to merge


def test_clustered_volume_keeps_the_patch_test(irregular):
    """Volume on pairs of nodes measures the body's volume exactly, so a uniform strain is exact too."""
    clusters = pair_nodes(irregular.points, irregular.tets)
    volume = NodalStrain(irregular.points, irregular.tets, 0.0, 1.0, clusters=clusters)
    strain = np.diag([0.01, -0.004, 0.002])
    x = irregular.points @ (np.eye(3) + strain).T
    J = np.linalg.det(np.eye(3) + strain)
    np.testing.assert_allclose(volume.volume_ratios(x), J, rtol=0, atol=1e-14)
    assert volume.domains.domain_count < 0.6 * irregular.node_count


def test_free_node_domains_keep_the_patch_test_and_every_tet(irregular):
    """With held nodes, the domains are the free nodes': a tet's volume goes to its free corners, each tet counted
    once, and a uniform strain is still exact in every domain."""
    held = irregular.points[:, 2] < 0.2
    volume = NodalStrain(irregular.points, irregular.tets, 0.0, 1.0, clusters="pairs", held=held)
    domains = volume.domains
    np.testing.assert_allclose(domains.corner_share.sum(axis=1), 1.0, rtol=0, atol=1e-15)
    tet_held = held[irregular.tets]
    touched = (~tet_held).any(axis=1)
    assert touched.any() and (~touched).any()  # the clamp has tets of held nodes only, and tets beside them
    assert (domains.corner_share[touched][tet_held[touched]] == 0).all()
    # Every domain with a free node holds only free nodes' shares; the body's volume is counted once.
    np.testing.assert_allclose(domains.volumes.sum(), volume.kinematics.volumes.sum(), rtol=1e-14)
    strain = np.array([[0.01, 0.003, 0.0], [0.0, -0.004, 0.002], [0.001, 0.0, 0.002]])
    x = irregular.points @ (np.eye(3) + strain).T
    np.testing.assert_allclose(volume.volume_ratios(x), np.linalg.det(np.eye(3) + strain), rtol=0, atol=1e-14)


def test_a_scene_gives_the_volume_pairs_to_its_free_nodes(cube):
    """Scene(model, pins=...) adapts the smoothed rung's volume pairs to the nodes its supports hold; a scene
    without supports, and any other rung, keeps the very model it was given."""
    from volspring import Pins, Scene

    material = Material(E=1e6, nu=0.45, density=1000.0)
    smoothed = Model.from_mesh(cube, material, model="smoothed")
    clamp = np.flatnonzero(cube.points[:, 0] == 0)
    scene = Scene(smoothed, pins=Pins(clamp))
    volume = scene.model.elements[2]
    assert smoothed.elements[2].held is None and volume.held[clamp].all() and volume.held.sum() == len(clamp)
    assert scene.model.elements[:2] == smoothed.elements[:2]  # the shear sets do not depend on the supports
    assert Scene(smoothed).model is smoothed
    assert Scene(scene.model).model.elements[2].held is None  # adapted back when the supports go
    springs = Model.from_mesh(cube, material)
    assert Scene(springs, pins=Pins(clamp)).model is springs
    # The adapted model is what a model file and a checkpoint store: it comes back bit for bit.
    import tempfile
    from pathlib import Path

    from volspring.model_io import load_model, save_model

    loaded = load_model(save_model(Path(tempfile.mkdtemp()) / "cube.vsmodel.npz", scene.model))
    assert np.array_equal(loaded.elements[2].held, volume.held) and loaded.elements[2].cluster_rule == "pairs"
    x = cube.points + 0.01 * np.random.default_rng(RNG_SEED).standard_normal(cube.points.shape)
    assert np.array_equal(loaded.forces(x), scene.model.forces(x))


def test_above_the_pair_cap_lambda_is_split_onto_merged_pairs_that_follow_the_supports(irregular):
    """At nu 0.499 the smoothed rung's volume is two sets, pairs with min(lambda, PAIR_BULK_CAP mu) and merged pairs
    with the rest: their bulk sums to lambda in every tet, a scene gives both to its free nodes, and a model file
    keeps both rules."""
    import tempfile
    from pathlib import Path

    from volspring import Pins, Scene
    from volspring.ladder import PAIR_BULK_CAP
    from volspring.model_io import load_model, save_model

    material = Material(E=1e6, nu=0.499, density=1000.0)
    nu = material.nu
    mu, lam = material.E / (2 * (1 + nu)), material.E * nu / ((1 + nu) * (1 - 2 * nu))
    model = Model.from_mesh(irregular, material, model="smoothed")
    pairs, merged = model.elements[2:]
    assert (pairs.cluster_rule, merged.cluster_rule) == ("pairs", "merged pairs")
    np.testing.assert_allclose(pairs.per_tet()["bulk"], PAIR_BULK_CAP * mu, rtol=1e-15)
    np.testing.assert_allclose(pairs.per_tet()["bulk"] + merged.per_tet()["bulk"], lam, rtol=1e-15)
    clamp = np.flatnonzero(irregular.points[:, 0] == 0)
    scene = Scene(model, pins=Pins(clamp))
    assert all(element_set.held.sum() == len(clamp) and element_set.held[clamp].all()
               for element_set in scene.model.elements[2:])
    loaded = load_model(save_model(Path(tempfile.mkdtemp()) / "body.vsmodel.npz", scene.model))
    assert [element_set.cluster_rule for element_set in loaded.elements[2:]] == ["pairs", "merged pairs"]
    x = irregular.points + 0.01 * np.random.default_rng(RNG_SEED).standard_normal(irregular.points.shape)
    assert np.array_equal(loaded.forces(x), scene.model.forces(x))
    # Below the cap (nu 0.47: lambda = 15.7 mu) the rung is the three sets it always was.
    assert len(Model.from_mesh(irregular, Material(E=1e6, nu=0.47, density=1000.0), model="smoothed").elements) == 3
    from volspring.ladder import TetMaterials, smoothed_elements

    materials = TetMaterials.of(len(irregular.tets), material)
    assert len(smoothed_elements(irregular, materials, pair_bulk_cap=np.inf)) == 3  # all of lambda on the pairs
    for bad in (0.0, -1.0, np.nan):
        with pytest.raises(ValueError, match="pair_bulk_cap"):
            smoothed_elements(irregular, materials, pair_bulk_cap=bad)


def test_the_stand_in_bulk_changes_the_preconditioner_only(irregular):
    """NodalStrain's stand_in_bulk enters the preconditioner's stand-in blocks and nothing else: forces, energy and
    the product are those of the bulk; the stand-in's volume part scales with it; the default is the bulk."""
    rng = np.random.default_rng(RNG_SEED)
    x = irregular.points + 0.02 * rng.standard_normal(irregular.points.shape)
    u = rng.standard_normal(x.shape)
    plain = NodalStrain(irregular.points, irregular.tets, 0.0, 3.0)
    capped = NodalStrain(irregular.points, irregular.tets, 0.0, 3.0, stand_in_bulk=0.75)
    assert np.array_equal(plain.stand_in_bulk, np.full(len(irregular.tets), 3.0))
    assert np.array_equal(capped.forces(x), plain.forces(x)) and capped.energy(x) == plain.energy(x)
    assert np.array_equal(capped.linearize_operator(x).scaled_times(u), plain.linearize_operator(x).scaled_times(u))
    # A pure volume stand-in is linear in its coefficient: a quarter of the bulk, a quarter of the blocks
    # (to rounding: the coefficient goes in under a square root).
    assert np.allclose(capped.preconditioner_blocks(x), 0.25 * plain.preconditioner_blocks(x), rtol=1e-12, atol=0)
    # It follows the set wherever the set goes (another numbering, the supports' domains).
    held = irregular.points[:, 0] < 0.3
    paired = NodalStrain(irregular.points, irregular.tets, 0.0, 3.0, clusters="pairs", stand_in_bulk=0.75)
    assert np.array_equal(paired.supported(held).stand_in_bulk, paired.stand_in_bulk)
    order = np.arange(irregular.node_count)[::-1]
    assert np.array_equal(capped.placed(irregular.points[np.argsort(order)], order).stand_in_bulk, capped.stand_in_bulk)
    with pytest.raises(ValueError, match=r"stand_in_bulk\[0\] = .*-1\.0.* is not finite and >= 0"):
        NodalStrain(irregular.points, irregular.tets, 0.0, 3.0, stand_in_bulk=np.r_[-1.0, np.ones(len(irregular.tets) - 1)])


@pytest.mark.parametrize("rung", ["springs+volume", "smoothed"])
def test_the_ladder_caps_the_volume_stand_in_at_five_shear_moduli(irregular, rung):
    """The volume term's stand-in bulk is min(kappa, STAND_IN_BULK_CAP mu) per tet: the bulk itself at nu 0.4 (kappa
    at most 4 mu), capped at nu 0.499. The smoothed rung's stand-in is its pairs' set's (the merged pairs', which
    take lambda above PAIR_BULK_CAP mu, have none)."""
    from volspring.ladder import STAND_IN_BULK_CAP

    for nu, capped in ((0.4, False), (0.499, True)):
        material = Material(E=1e6, nu=nu, density=1000.0)
        model = Model.from_mesh(irregular, material, model=rung)
        volume = model.elements[2] if rung == "smoothed" else model.elements[-1]
        mu = material.E / (2 * (1 + nu))
        bulk = volume.per_tet()["bulk"]
        assert np.array_equal(volume.stand_in_bulk, np.minimum(bulk, STAND_IN_BULK_CAP * mu))
        assert (volume.stand_in_bulk < bulk).all() == capped and (volume.stand_in_bulk > 0).all()
        if rung == "smoothed":
            assert len(model.elements) == (4 if capped else 3)
            for element_set in model.elements[3:]:  # no stand-in: no block array to make and sum each step
                assert (element_set.stand_in_bulk == 0).all()
                assert element_set.preconditioner_blocks(irregular.points) is None
                assert element_set.linearize_operator(irregular.points).preconditioner_blocks() is None


def test_the_capped_stand_in_takes_fewer_cg_iterations_at_nu_0499():
    """What the cap is for, on the smoothed rung of a small beam from rest (the README beam's figures are in
    volspring.ladder.STAND_IN_BULK_CAP's comment): fewer CG iterations over the first steps than with the stand-in at
    the full bulk, for the same answer to CG's tolerance."""
    from dataclasses import replace

    from volspring import Gravity, Pins
    from volspring.integrators.implicit import ImplicitEuler

    mesh = structured_box((20, 4, 4), (1.0, 0.2, 0.2))
    capped = Model.from_mesh(mesh, Material(E=1e7, nu=0.499, density=1000.0), model="smoothed")
    full = []  # the volume sets (pairs, merged pairs) with the stand-in at their bulk: lambda in all
    for volume in capped.elements[2:]:
        inputs = volume.per_tet()
        full.append(NodalStrain(mesh.points, mesh.tets, inputs["shear"], inputs["bulk"], regions=inputs["regions"],
                                clusters=volume.cluster_rule))
    uncapped = replace(capped, elements=capped.elements[:2] + tuple(full))
    pins = Pins(np.flatnonzero(mesh.points[:, 0] == 0))
    totals, tips = {}, {}
    for name, model in (("capped", capped), ("full", uncapped)):
        scene, integrator = Scene(model, forces=[Gravity()], pins=pins), ImplicitEuler()
        state, total = scene.initial_state(), 0
        for _ in range(20):
            state = integrator.step(scene, state, 0.01)
            total += integrator.last_solve.iterations
        totals[name], tips[name] = total, state.x[:, 2].min()
    # Measured: 763 against 996 iterations (-23%; 842 against 1029, -18%, with all of lambda on pairs; -15% over 20
    # steps of the 3,321-node README beam then). 0.9: the cap must save at least 10%, about two thirds of the
    # smallest of these, or it is not worth a stand-in of its own.
    assert totals["capped"] < 0.9 * totals["full"], totals
    # Both solve the same system to CG's rtol of 1e-3 each step: the lowest point agrees to that share of its sag
    # (measured 3.5e-4; 1.5e-4 with all of lambda on pairs).
    sag = abs(tips["full"] - mesh.points[:, 2].min())
    assert sag > 0 and abs(tips["capped"] - tips["full"]) < 1e-3 * sag, (tips, sag)
