"""A new element set written here, in the test file alone, is used everywhere and checked there.

The set is a per-tet volume penalty, E = sum_t kappa / 2 (V_t - V0_t)^2 / V0_t: forces, energy
and stiffness blocks in ~50 lines, nothing else. With no change to library code it must work in
the forces, the implicit matrix that AMG sees, the static solve, the modal solve, time stepping
and checkpoints, and each use is checked against an independent answer:

- forces against central differences of the energy;
- the implicit system's blocks against central differences of the forces;
- the static solve (AMG-CG Newton) against the same Newton with a direct sparse solve, and, at a
  small load, against one direct sparse solve of the linear system K u = f;
- the modal solve (shift-invert Lanczos) against a dense eigen solve of K and M built by finite
  differences;
- time stepping: energy is conserved by a symplectic scheme with the penalty included.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
import scipy.linalg
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from conftest import cube_mesh
from volspring import Gravity, Material, Model, Pins, Scene
from volspring.elements import ElementSet
from volspring.integrators import make_integrator
from volspring.integrators.implicit import ImplicitEuler
from volspring.modes import solve_modes
from volspring.statics import solve_static
from volspring.supports import Sliding

RUBBER = Material(E=1e5, nu=0.3, density=1000.0)


def _tet_volumes(x, tets):
    e1, e2, e3 = (x[tets[:, k]] - x[tets[:, 0]] for k in (1, 2, 3))
    return np.einsum("ij,ij->i", e1, np.cross(e2, e3)) / 6.0


def _skew(e):
    """(m, 3, 3) cross-product matrices [e]x."""
    out = np.zeros(e.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2], out[..., 1, 2] = -e[..., 2], e[..., 1], -e[..., 0]
    return out - np.swapaxes(out, -1, -2)


@dataclass(frozen=True, eq=False)
class VolumePenalty(ElementSet):
    """E = sum_t kappa / 2 (V_t - V0_t)^2 / V0_t over tets, kappa [Pa]."""

    tets: np.ndarray
    rest_volumes: np.ndarray
    kappa: float

    name = "volume"

    @property
    def stencil(self):
        return self.tets

    def _gradients(self, x):
        """(m,) volumes and (m, 4, 3) dV/dx of each tet's vertices."""
        e1, e2, e3 = (x[self.tets[:, k]] - x[self.tets[:, 0]] for k in (1, 2, 3))
        g = np.stack([np.cross(e2, e3), np.cross(e3, e1), np.cross(e1, e2)], axis=1) / 6.0
        return _tet_volumes(x, self.tets), np.concatenate([-g.sum(axis=1, keepdims=True), g], axis=1)

    def energy(self, x):
        volumes, _ = self._gradients(x)
        return float(0.5 * self.kappa * np.sum((volumes - self.rest_volumes) ** 2 / self.rest_volumes))

    def forces(self, x, v=None):
        volumes, gradients = self._gradients(x)
        pressure = self.kappa * (volumes - self.rest_volumes) / self.rest_volumes
        out = np.zeros_like(x, dtype=float)
        np.add.at(out, self.tets, -pressure[:, None, None] * gradients)
        return out

    def stiffness_blocks(self, x, *, clamp_compression=True):
        volumes, g = self._gradients(x)
        scale = self.kappa / self.rest_volumes
        blocks = scale[:, None, None, None, None] * np.einsum("tai,tbj->tabij", g, g)
        if not clamp_compression:  # + pressure times the Hessian of the volume
            e = [x[self.tets[:, k]] - x[self.tets[:, 0]] for k in (1, 2, 3)]
            hessian_e = np.zeros((len(self.tets), 3, 3, 3, 3))
            for a, b, c, sign in ((0, 1, 2, 1), (1, 2, 0, 1), (2, 0, 1, 1), (1, 0, 2, -1), (2, 1, 0, -1), (0, 2, 1, -1)):
                hessian_e[:, a, b] = -sign * _skew(e[c]) / 6.0
            to_vertices = np.array([[-1.0, -1.0, -1.0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
            hessian = np.einsum("ap,tpqij,bq->tabij", to_vertices, hessian_e, to_vertices)
            blocks += (scale * (volumes - self.rest_volumes))[:, None, None, None, None] * hessian
        return blocks.reshape(len(self.tets), 16, 3, 3)


def penalised_model(cells=(3, 2, 2), size=(1.5, 0.5, 0.5), kappa=3e5):
    mesh = cube_mesh(cells, size)
    springs = Model.from_mesh(mesh, RUBBER)
    penalty = VolumePenalty(mesh.tets, _tet_volumes(mesh.points, mesh.tets), kappa)
    return springs, springs.with_elements(penalty), penalty


def _deformed(model, amplitude=0.04, seed=0):
    rng = np.random.default_rng(seed)
    return model.rest_positions + amplitude * rng.standard_normal(model.rest_positions.shape)


def _finite_difference_stiffness(model, x, dofs, h=1e-6):
    """-dF/dx by central differences, columns for ``dofs`` (model unknown indices) [N/m]."""
    columns = []
    for dof in dofs:
        step = np.zeros(x.size)
        step[dof] = h
        ahead, behind = model.forces(x + step.reshape(-1, 3)), model.forces(x - step.reshape(-1, 3))
        columns.append(-(ahead - behind).ravel() / (2 * h))
    return np.array(columns).T


def test_forces_are_minus_the_gradient_of_the_energy():
    _, model, penalty = penalised_model()
    x = _deformed(model)
    h = 1e-6
    gradient = np.zeros(x.size)
    for dof in range(x.size):
        step = np.zeros(x.size)
        step[dof] = h
        gradient[dof] = (penalty.energy(x + step.reshape(-1, 3)) - penalty.energy(x - step.reshape(-1, 3))) / (2 * h)
    forces = penalty.forces(x).ravel()
    # Central differences: O(h^2) truncation plus round-off eps |E| / h ~ 1e-16 * 1e2 / 1e-6 = 1e-8 of the forces.
    assert np.abs(forces + gradient).max() <= 1e-6 * np.abs(forces).max()
    assert np.abs(forces).max() > 0  # a deformed body: the check is not vacuous


def test_exact_blocks_match_finite_differences_and_the_clamped_ones_are_semidefinite():
    _, model, penalty = penalised_model(cells=(2, 1, 1))
    x = _deformed(model)
    alone = Model(model.rest_positions, model.masses, (penalty,))
    reference = _finite_difference_stiffness(alone, x, range(x.size))
    from volspring.assembly import stiffness_matrix

    exact = stiffness_matrix(alone, x, clamp_compression=False).toarray()
    # Central differences of forces ~ kappa l: O(h^2) truncation, round-off 1e-16 |F| / h; 1e-6 relative is 100x both.
    assert np.abs(exact - reference).max() <= 1e-6 * np.abs(reference).max()
    clamped = stiffness_matrix(alone, x, clamp_compression=True).toarray()
    assert np.linalg.eigvalsh(clamped).min() >= -1e-9 * np.abs(clamped).max()  # Gauss-Newton: g g^T blocks


def test_implicit_matrix_that_amg_sees_holds_the_penalty_blocks():
    springs, model, _ = penalised_model()
    scene = Scene(model, pins=Pins(np.flatnonzero(model.rest_positions[:, 0] == 0)))
    x = _deformed(model, 0.02)
    state = scene.initial_state(x=x)
    h = 1e-3
    integrator = ImplicitEuler(clamp_compression=False)
    matrix, extra, pattern = integrator.linear_system(scene, state, h)
    assert extra is None  # the penalty is an element set, not an extra term applied outside the hierarchy
    dofs = pattern.free_dofs()
    stiffness = (matrix.toarray() - np.diag(np.repeat(model.masses[pattern.free_nodes], 3))) / h**2
    reference = _finite_difference_stiffness(model, state.x, dofs)[dofs]
    assert np.abs(stiffness - reference).max() <= 1e-6 * np.abs(reference).max()  # as above
    # And the penalty changed the matrix: without it the same entries differ by the penalty's share.
    bare = ImplicitEuler(clamp_compression=False).linear_system(Scene(springs, pins=scene.pins), state, h)[0]
    assert np.abs(matrix.toarray() - bare.toarray()).max() > 1e-3 * np.abs(bare.toarray()).max()


@pytest.fixture(scope="module")
def sagging():
    _, model, _ = penalised_model(cells=(6, 2, 2), size=(1.5, 0.25, 0.25), kappa=1e5)
    pins = Pins(np.flatnonzero(model.rest_positions[:, 0] == 0))
    return model, pins


def test_static_solve_with_amg_equals_direct_and_linear_solve_at_small_load(sagging):
    model, pins = sagging
    scene = Scene(model, forces=[Gravity()], pins=pins)
    amg = solve_static(scene, solver="amg", rtol=1e-10)
    direct = solve_static(scene, solver="direct", rtol=1e-10)
    sag = np.abs(direct.x - model.rest_positions).max()
    assert sag > 1e-3  # a visible deflection (mm), so agreement means something
    # Both converge to rtol 1e-10 in force: positions agree far below 1e-8 of the sag.
    assert np.abs(amg.x - direct.x).max() <= 1e-8 * sag

    # At g/1e5 the response is linear to O(load^2): Newton's answer equals one direct sparse solve of K u = f.
    small = Scene(model, forces=[Gravity(g=(0, 0, -9.81e-5))], pins=pins)
    newton = solve_static(small, solver="direct", rtol=1e-12)
    free = np.repeat(small.free, 3)
    K = sp.csr_matrix(_finite_difference_stiffness(model, model.rest_positions, np.flatnonzero(free))[free])
    f = small.external_forces(model.rest_positions, np.zeros_like(model.rest_positions), 0.0).ravel()[free]
    u = spla.spsolve(K.tocsc(), f)
    deflection = (newton.x - model.rest_positions).ravel()[free]
    # The nonlinear part is ~ (sag / length) relative = 6e-5 / 1.5 = 4e-5 at this load (4e-3 was measured at
    # g/1000); the FD stiffness adds ~1e-8. 1e-4 bounds both.
    assert np.abs(deflection - u).max() <= 1e-4 * np.abs(u).max()


def test_modal_solve_equals_a_dense_eigen_solve(sagging):
    model, pins = sagging
    scene = Scene(model, pins=pins)
    lanczos = solve_modes(scene, count=5, dense_dofs=0)  # force the sparse shift-invert path
    free = np.flatnonzero(np.repeat(scene.free, 3))
    K = _finite_difference_stiffness(model, model.rest_positions, free)[free]
    K = 0.5 * (K + K.T)
    dense = scipy.linalg.eigh(K, np.diag(np.repeat(model.masses, 3)[free]), eigvals_only=True)[:5]
    frequencies = np.sqrt(dense) / (2 * np.pi)
    # ARPACK at machine tolerance; the FD stiffness carries ~1e-8 relative error: 1e-6 covers both.
    assert np.allclose(lanczos.frequencies, frequencies, rtol=1e-6)
    without = solve_modes(Scene(Model(model.rest_positions, model.masses, model.elements[:1]), pins=pins), count=5)
    assert not np.allclose(without.frequencies, lanczos.frequencies, rtol=1e-3)  # the penalty is in there


def test_symplectic_stepping_conserves_energy_with_the_penalty():
    _, model, _ = penalised_model(cells=(2, 2, 2), size=(0.5, 0.5, 0.5))
    scene = Scene(model)
    state = scene.initial_state(x=_deformed(model, 0.01, seed=1))
    integrator = make_integrator("verlet")
    start = scene.potential_energy(state.x) + scene.kinetic_energy(state.v)
    energies = []
    for _ in range(400):
        state = integrator.step(scene, state, 2e-5)
        energies.append(scene.potential_energy(state.x) + scene.kinetic_energy(state.v))
    # Verlet's energy error is bounded and O((h omega)^2): h omega_max ~ 0.2 here gives a few percent at most.
    assert np.abs(np.array(energies) - start).max() <= 0.05 * start
    assert scene.kinetic_energy(state.v) > 0.1 * start  # it did move


def test_sliding_support_holds_one_component_in_static_and_implicit_solves():
    _, model, _ = penalised_model(cells=(4, 2, 2), size=(1.0, 0.5, 0.5))
    x0 = model.rest_positions
    base, left = np.flatnonzero(x0[:, 2] == 0), np.flatnonzero(x0[:, 0] == 0)
    corner = np.flatnonzero((x0[:, 2] == 0) & (x0[:, 0] == 0) & (x0[:, 1] == 0))
    # Base on a frictionless floor, left face on a frictionless wall, one corner holding y: no rigid motion left.
    from volspring.supports import Prescribed

    scene = Scene(model, forces=[Gravity()],
                  supports=[Sliding(base, "z"), Sliding(left, "x"), Prescribed(corner, "y")])
    static = solve_static(scene, solver="direct", rtol=1e-10)
    assert np.array_equal(static.x[base, 2], x0[base, 2]) and np.array_equal(static.x[left, 0], x0[left, 0])
    sagged = x0[:, 2].max() - static.x[:, 2].max()
    assert sagged > 0  # the body settled under its weight
    # The base slides: it spreads in x and y (Poisson-like bulging of a squashed block).
    assert np.abs(static.x[base, :2] - x0[base, :2]).max() > 1e-3 * sagged

    state = scene.initial_state()
    integrator = ImplicitEuler(solver="amg")
    for _ in range(5):
        state = integrator.step(scene, state, 1e-2)
    assert np.array_equal(state.x[base, 2], x0[base, 2]) and np.array_equal(state.v[base, 2], np.zeros(len(base)))
    assert np.abs(state.x[base, 0] - x0[base, 0]).max() > 0  # free in x: it moved


def test_a_checkpoint_fingerprint_tells_models_with_and_without_the_penalty_apart():
    from volspring.checkpoint import model_fingerprint

    springs, model, _ = penalised_model()
    assert model_fingerprint(Scene(springs)) != model_fingerprint(Scene(model))
    assert model_fingerprint(Scene(model)) == model_fingerprint(Scene(model))


def test_validation_compression_case_with_the_penalty_matches_its_closed_form():
    """Validation runs volspring's own static solve, so the penalty is validated with no validation code.

    The penalty's energy density kappa / 2 (dV / V)^2 adds kappa to the network's first Lame parameter.
    With the network's own E_n, nu_n (validation's :func:`effective_constants`, at the case's strain), the
    combined solid has lambda = lambda_n + kappa, mu = mu_n and nu = lambda / (2 (lambda + mu)): the
    compression case's lateral strain (its "tip deflection") is -nu eps, and choosing kappa for nu = 0.45
    brings the case's volume loss towards the FEM's.
    """
    from validation.cases import uniaxial_compression
    from validation.compare import tip_deflection
    from validation.springs import deformed_volume_change, effective_constants, spring_model, spring_static

    case = uniaxial_compression(cells=4, nu=0.45)
    eps, edge = case.parameters["strain"], case.mesh.bounds[1][0]
    springs = spring_model(case.mesh, case.material, "lloyd")
    network = effective_constants(case.mesh, springs, strain=eps)
    E_n, nu_n = network["E_pa"], network["nu"]
    lam_n, mu_n = E_n * nu_n / ((1 + nu_n) * (1 - 2 * nu_n)), E_n / (2 * (1 + nu_n))
    for kappa in (1.0 * lam_n, 4.0 * lam_n):
        penalty = VolumePenalty(case.mesh.tets, _tet_volumes(case.mesh.points, case.mesh.tets), kappa)
        u = spring_static(case, springs.with_elements(penalty)).displacement
        nu = (lam_n + kappa) / (2 * (lam_n + kappa + mu_n))
        # The additive closed form assumes the nodes move affinely; interior nodes relax a little
        # otherwise: measured 0.6 % (kappa = lambda_n) and 0.05 % (4 lambda_n) on this 4^3 mesh, 1.8 % on 2^3.
        assert -tip_deflection(case, u) / (eps * edge) == pytest.approx(nu, rel=1e-2)

    # kappa for nu = 0.45: the volume loss the springs alone miss by 440 % comes within 1.1 % (both measured;
    # the rest is the non-affine relaxation above and O(strain) = 1 % nonlinearity): 5 % bounds it.
    lam = 2 * mu_n * 0.45 / (1 - 2 * 0.45)
    penalty = VolumePenalty(case.mesh.tets, _tet_volumes(case.mesh.points, case.mesh.tets), lam - lam_n)
    exact = case.analytic["volume_change_m3"]
    alone = deformed_volume_change(case.mesh, spring_static(case, springs).displacement)
    tuned = deformed_volume_change(case.mesh, spring_static(case, springs.with_elements(penalty)).displacement)
    assert abs(alone / exact - 1) > 1.0
    assert abs(tuned / exact - 1) < 0.05
