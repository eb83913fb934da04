"""Implicit Euler: the assembled system, pins, stability far beyond the explicit limit, the
linear solvers (direct, AMG-CG, Jacobi-CG), warm start, AMG scaling, failure reporting,
a sagging beam, Newton iterations and bit-identical resume."""

import copy
import warnings

import numpy as np
import pytest
import scipy.linalg
import scipy.sparse as sp
import scipy.sparse.linalg as sla
from conftest import cube_mesh

from volspring import Drag, Gravity, Material, Pins, Scene, Model
from volspring.assembly import BlockPattern
from volspring.errors import SolverNotConverged
from volspring.integrators.implicit import WARM_START, ImplicitEuler
from volspring.springs import damper_blocks, spring_forces, spring_stiffness_blocks

RUBBER = Material(1e6, 0.25, 1000.0)


def beam(cells, *, material=RUBBER, damping_ratio=0.0, length=1.0):
    """A beam along x, cross-section length/5, pinned at x = 0, under gravity."""
    width = length / 5
    model = Model.from_mesh(cube_mesh(cells, (length, width, width)), material, damping_ratio=damping_ratio)
    pins = Pins(np.flatnonzero(model.rest_positions[:, 0] < 1e-9))
    return Scene(model, forces=[Gravity()], pins=pins)


def omega_max(model, free=None) -> float:
    """sqrt(largest eigenvalue of K v = lambda M v) over the free nodes [rad/s]."""
    pattern = BlockPattern(model, free)
    stiffness = pattern.matrix(pattern.linearize(model.rest_positions, stiffness_scale=1.0).blocks)
    scale = sp.diags(np.repeat(model.masses[pattern.free_nodes], 3) ** -0.5)
    scaled = (scale @ stiffness.tocsr() @ scale).tocsr()
    if scaled.shape[0] <= 1500:
        return float(np.sqrt(scipy.linalg.eigvalsh(scaled.toarray())[-1]))
    # Lanczos to 1e-8: far tighter than any use here (step sizes are set to a few digits).
    return float(np.sqrt(sla.eigsh(scaled, k=1, which="LA", tol=1e-8, return_eigenvectors=False)[0]))


def total_energy(scene, state):
    return scene.kinetic_energy(state.v) + scene.potential_energy(state.x)


class Tether:
    """A test force with a non-diagonal Jacobian: f_a = -c (x_a - x_b), f_b = -f_a."""

    def __init__(self, a, b, c, n):
        self.a, self.b, self.c, self.n = a, b, c, n

    def accumulate(self, model, x, v, t, out):
        f = -self.c * (x[self.a] - x[self.b])
        out[self.a] += f
        out[self.b] -= f

    def jacobian(self, model, x, v, t):
        rows, cols, vals = [], [], []
        for p, q, sign in ((self.a, self.a, -1), (self.a, self.b, 1), (self.b, self.a, 1), (self.b, self.b, -1)):
            rows += [3 * p + c for c in range(3)]
            cols += [3 * q + c for c in range(3)]
            vals += [sign * self.c] * 3
        return sp.csr_matrix((vals, (rows, cols)), shape=(3 * self.n, 3 * self.n)), None

    def potential_energy(self, model, x, t):
        return 0.5 * self.c * float(np.sum((x[self.a] - x[self.b]) ** 2))


def dense_reference_step(scene, state, h):
    """The linearised backward Euler step solved densely on all 3n unknowns, pins by elimination."""
    model, x, v, t = scene.model, state.x, state.v, state.t
    n = model.node_count
    dfdx = np.zeros((3 * n, 3 * n))
    dfdv = np.zeros((3 * n, 3 * n))
    H = spring_stiffness_blocks(model, x)
    D = damper_blocks(model, x)
    for e, (i, j) in enumerate(model.springs):  # a loop is fine for a reference on a tiny mesh
        for p, q, sign in ((i, i, -1), (i, j, 1), (j, i, 1), (j, j, -1)):
            dfdx[3 * p:3 * p + 3, 3 * q:3 * q + 3] += sign * H[e]
            dfdv[3 * p:3 * p + 3, 3 * q:3 * q + 3] += sign * D[e]
    for force in scene.forces:
        if hasattr(force, "jacobian"):
            jx, jv = force.jacobian(model, x, v, t)
            dfdx += 0 if jx is None else jx.toarray()
            dfdv += 0 if jv is None else jv.toarray()
    A = np.diag(np.repeat(model.masses, 3)) - h * dfdv - h * h * dfdx
    b = h * (scene.forces_at(x, v, t).ravel() + h * dfdx @ v.ravel())
    v1 = v.copy()
    nodes = scene.pins.nodes
    v1[nodes] = (scene.pins.positions(model.rest_positions, t + h) - x[nodes]) / h
    dv_fixed = np.zeros(3 * n)
    dv_fixed.reshape(-1, 3)[nodes] = v1[nodes] - v[nodes]
    free = BlockPattern(model, scene.free).free_dofs()  # the solver's unknown order (RCM)
    b = b - A @ dv_fixed
    dv = np.linalg.solve(A[np.ix_(free, free)], b[free])
    v1.reshape(-1)[free] += dv
    return A[np.ix_(free, free)], x + h * v1, v1


@pytest.fixture
def deformed_scene():
    """A small damped cube with a moving pinned face, drag and a tether: every term of the system."""
    model = Model.from_mesh(cube_mesh((2, 2, 2)), RUBBER, damping_ratio=0.3)
    n = model.node_count
    face = np.flatnonzero(model.rest_positions[:, 0] < 1e-9)
    rest = model.rest_positions[face]
    # an accelerating face, so the prescribed velocity change (and its coupling) is not zero
    pins = Pins(face, motion=lambda t: rest + [0.0, 0.0, 2.0 * t * t],
                velocity=lambda t: np.tile([0.0, 0.0, 4.0 * t], (len(face), 1)))
    # tethers between two free nodes and from a pinned node (0) to a free one
    forces = [Gravity(), Drag(rate=2.0), Tether(n - 1, n - 5, 3e4, n), Tether(0, n - 2, 2e4, n)]
    scene = Scene(model, forces=forces, pins=pins)
    rng = np.random.default_rng(1)
    state = scene.initial_state(x=model.rest_positions + 0.04 * rng.standard_normal((n, 3)),
                                v=0.3 * rng.standard_normal((n, 3)), t=0.2)
    return scene, state


def test_assembled_system_matches_dense_reference(deformed_scene):
    scene, state = deformed_scene
    h = 0.01
    integrator = ImplicitEuler(solver="direct")
    matrix, extra, _ = integrator.linear_system(scene, state, h)
    A_dense, x_ref, v_ref = dense_reference_step(scene, state, h)
    A = matrix.toarray() + (0 if extra is None else extra.toarray())
    # Same sums in a different order: agreement to a few ulps of the largest entry.
    assert np.abs(A - A_dense).max() <= 1e-12 * np.abs(A_dense).max()
    assert extra is not None  # the tether's off-diagonal Jacobian stays a separate term
    new = integrator.step(scene, state, h)
    # The direct solve is checked to 1e-8 relative residual; condition ~1e3 leaves ~1e-10 in v.
    free = scene.free
    assert np.abs(new.v[free] - v_ref[free]).max() <= 1e-8 * np.abs(v_ref).max()
    assert np.abs(new.x - x_ref).max() <= 1e-10
    # after the step the pins carry their prescribed velocity (not the difference quotient)
    assert np.array_equal(new.v[~free], scene.pins.velocities(state.t + h))


def test_pinned_nodes_are_eliminated_and_never_move():
    scene = beam((6, 2, 2))
    integrator = ImplicitEuler()
    pattern = integrator.pattern(scene)
    assert pattern.size == 3 * scene.free.sum()
    state = scene.initial_state()
    h = 10.0 / omega_max(scene.model, scene.free)
    for _ in range(20):
        state = integrator.step(scene, state, h)
        assert np.array_equal(state.x[scene.pins.nodes], scene.model.rest_positions[scene.pins.nodes])
        assert not state.v[scene.pins.nodes].any()
    assert state.x[:, 2].min() < -1e-4  # and the rest did move (sag)


@pytest.mark.parametrize("E", [1e2, 1e5, 1e9])
@pytest.mark.parametrize("mass_ratio", [1.0, 1e6])
def test_stable_with_energy_non_increasing_at_1000x_explicit_limit(E, mass_ratio):
    base = Model.from_mesh(cube_mesh((3, 2, 2), (1.5, 1.0, 1.0)), Material(E, 0.25, 1000.0))
    masses = base.masses * np.where(base.rest_positions[:, 0] > 0.75, mass_ratio, 1.0)  # a heavy half
    model = Model.from_arrays(base.rest_positions, masses, base.springs, stiffness=base.stiffness)
    scene = Scene(model, pins=Pins(np.flatnonzero(model.rest_positions[:, 0] < 1e-9)))
    h = 1000 * 2.0 / omega_max(model, scene.free)  # 1000 x the symplectic Euler / Verlet limit
    rng = np.random.default_rng(0)
    shape = model.rest_positions.shape
    # 10 % strains, and velocities that would move a node by a comparable 5 cm in one step
    state = scene.initial_state(x=model.rest_positions + 0.05 * rng.standard_normal(shape),
                                v=(0.05 / h) * rng.standard_normal(shape))
    integrator = ImplicitEuler()
    energies = [total_energy(scene, state)]
    for _ in range(30):
        state = integrator.step(scene, state, h)
        energies.append(total_energy(scene, state))
    energies = np.array(energies)
    # Non-increasing up to 1e-6 of the initial energy: the CG solve at rtol 1e-3 perturbs each
    # step by far less than the scheme's own dissipation, round-off is ~1e-16.
    assert (np.diff(energies) <= 1e-6 * energies[0]).all(), energies
    assert np.abs(state.x - model.rest_positions).max() < 1.0  # bounded: back near rest, not blown up


def test_direct_amg_and_jacobi_agree_to_the_solver_tolerance():
    scene = beam((8, 2, 2), damping_ratio=0.1)
    h = 50.0 / omega_max(scene.model, scene.free)
    rtol = 1e-8
    results = {}
    for solver in ("direct", "amg", "jacobi"):
        integrator = ImplicitEuler(solver=solver, rtol=rtol, maxiter=5000)
        state = scene.initial_state()
        for _ in range(3):
            state = integrator.step(scene, state, h)
        results[solver] = state.v
    scale = np.abs(results["direct"]).max()
    # A relative residual of 1e-8 with a condition number ~1e4 (h omega = 50, masses near uniform)
    # bounds the relative error by ~1e-4; in practice it is far smaller.
    for solver in ("amg", "jacobi"):
        assert np.abs(results[solver] - results["direct"]).max() <= 1e-5 * scale


def test_warm_start_reduces_iterations():
    """CG starts from the combination of the last velocity changes closest to the step's solution (energy norm)."""
    scene = beam((16, 4, 4), material=Material(1e8, 0.25, 1000.0))
    h = 50.0 / omega_max(scene.model, scene.free)
    integrator = ImplicitEuler(rtol=1e-6)
    state = scene.initial_state()
    warm, cold, guesses = 0, 0, []
    for _ in range(20):
        # the same step from the same state, without the previous changes (cold start from zero)
        cold_state = state.replace(memory={k: v for k, v in state.memory.items() if not k.endswith(".dv_history")})
        integrator.step(scene, cold_state, h)
        cold += integrator.last_solve.iterations
        state = integrator.step(scene, state, h)
        warm += integrator.last_solve.iterations
        guesses.append(integrator.last_solve.solves[0].initial_residual)
    assert np.median(guesses[1:]) < 0.05, guesses
    assert warm < cold, (warm, cold)
    # Measured over these 20 steps: 203 iterations from five previous changes, 251 from the last one alone
    # (optimally scaled), 280 from zero; the median initial residual 0.010, 0.23 and 1.
    totals = {}
    for depth in (0, 1, WARM_START):
        integrator, state, totals[depth] = ImplicitEuler(rtol=1e-6, warm_start=depth), scene.initial_state(), 0
        for _ in range(20):
            state = integrator.step(scene, state, h)
            totals[depth] += integrator.last_solve.iterations
    assert totals[WARM_START] < totals[1] < totals[0], totals


def test_the_warm_start_is_the_best_combination_of_the_previous_changes_in_the_energy_norm():
    """x0 = X c with (X^T A X) c = X^T b: no combination of the previous changes is closer to the solution in the A
    norm (not the last change, not the linear extrapolation of the last two, not zero); nearly parallel changes do
    not break it."""
    from types import SimpleNamespace

    from volspring.integrators.implicit import _projected_guess

    generator = np.random.default_rng(4)
    root = generator.standard_normal((30, 30))
    matrix = sp.csr_matrix(root @ root.T + 30 * np.eye(30))
    b = generator.standard_normal(30)
    solution = np.linalg.solve(matrix.toarray(), b)
    history = solution + 0.3 * generator.standard_normal((3, 30))  # three earlier, different solutions

    def error(guess):
        difference = solution - guess
        return float(difference @ (matrix @ difference))

    system = SimpleNamespace(matrix=matrix, products=None)
    guess, residual, deflation = _projected_guess(system, b, history)
    # Its residual comes with it (CG's first, without a product of its own): b - A x0 to rounding.
    np.testing.assert_allclose(residual, b - matrix @ guess, rtol=0, atol=1e-12 * np.abs(b).max())
    assert deflation is None  # an assembled system's hierarchy is built from it: no deflation
    # The best combination, by least squares on A^(1/2): the same up to rounding (1e-12 leaves room for 1e-15).
    coefficients = np.linalg.lstsq(history @ matrix @ history.T, history @ b, rcond=None)[0]
    np.testing.assert_allclose(guess, history.T @ coefficients, rtol=0, atol=1e-12 * np.abs(guess).max())
    for other in (np.zeros(30), history[-1], 2 * history[-1] - history[-2], history.mean(axis=0)):
        assert error(guess) <= error(other)
    # A matrix-free part of the system counts too; a repeated change adds nothing and breaks nothing.
    half = SimpleNamespace(matrix=matrix / 2, products=sla.aslinearoperator(matrix / 2))
    repeated = np.concatenate([history, history[-1:]])
    guess_of_half, residual, deflation = _projected_guess(half, b, repeated)
    np.testing.assert_allclose(guess_of_half, guess, rtol=0, atol=1e-9 * np.abs(guess).max())
    # With a set applied as a product the guess brings CG's deflation: directions W spanning the changes, (A W)^T,
    # W^T A W diagonal, and W^T r0 = 0, which deflated CG needs (each to 1e-12 of the scale of its products).
    W = deflation.vectors.T
    assert np.linalg.matrix_rank(np.concatenate([W, history.T], axis=1)) == 3 == W.shape[1]
    np.testing.assert_allclose(deflation.products, (matrix @ W).T, rtol=0, atol=1e-12 * np.abs(matrix @ W).max())
    energies = W.T @ (matrix @ W)
    np.testing.assert_allclose(energies, np.diag(deflation.energies), rtol=0, atol=1e-12 * energies.max())
    assert np.abs(W.T @ residual).max() <= 1e-12 * np.abs(W).max() * np.abs(b).sum()
    assert _projected_guess(system, b, np.zeros((2, 30))) is None  # a body at rest: start from zero


def test_cg_is_deflated_by_the_changes_its_guess_is_made_from(monkeypatch):
    """The step hands CG the directions its guess projected onto, and CG keeps its search directions A-orthogonal to
    them: over 30 steps of a smoothed bar's fall (its preconditioner is built from a stand-in, so CG has more to
    re-find) it needs fewer iterations than from the same guess without the deflation, for the same motion."""
    import volspring.integrators.implicit as implicit

    mesh = cube_mesh((16, 4, 4), (1.0, 0.2, 0.2))
    model = Model.from_mesh(mesh, Material(1e6, 0.45, 1000.0), model="smoothed")
    scene = Scene(model, forces=[Gravity()], pins=Pins(np.flatnonzero(mesh.points[:, 0] < 1e-9)))
    guess = implicit._projected_guess

    def run():
        integrator, state, total = ImplicitEuler(), scene.initial_state(), 0
        for _ in range(30):
            state = integrator.step(scene, state, 0.01)
            total += integrator.last_solve.iterations
        return state, total

    deflated, with_deflation = run()
    monkeypatch.setattr(implicit, "_projected_guess", lambda *args: None if (made := guess(*args)) is None else
                        (*made[:2], None))
    plain, without = run()
    # Measured 254 against 304 iterations (0.84); 0.92 is half that gain, which no rounding of CG's path gives.
    assert with_deflation <= 0.92 * without, (with_deflation, without)
    # Both are CG at rtol 1e-3 on the same systems: the bar's sag agrees far better than that (measured 1.8e-5).
    sag = mesh.points[:, 2] - plain.x[:, 2]
    assert np.abs(deflated.x[:, 2] - plain.x[:, 2]).max() <= 1e-3 * sag.max()


def test_a_run_resumed_with_a_full_warm_start_history_equals_the_uninterrupted_one(tmp_path):
    """The previous changes CG's guess is made from travel in the state: a checkpoint written after more steps than
    the history holds, loaded into a new integrator (its AMG hierarchy rebuilt from the record), continues bit for
    bit, on a beam above the ~800 nodes where a random AMG set-up once made runs differ."""
    from volspring.checkpoint import load_checkpoint, save_checkpoint

    scene = beam((20, 6, 6))  # 1,029 nodes
    integrator, state = ImplicitEuler(), scene.initial_state()
    for _ in range(WARM_START + 3):
        state = integrator.step(scene, state, 0.01)
    assert state.memory["implicit_euler.dv_history"].shape == (WARM_START, 3 * scene.free.sum())
    run = dict(scene=scene, integrator=integrator, dt=0.01)
    resumed = load_checkpoint(save_checkpoint(tmp_path / "run.npz", state, **run), **run)
    fresh = ImplicitEuler()
    for _ in range(6):
        state, resumed = integrator.step(scene, state, 0.01), fresh.step(scene, resumed, 0.01)
    assert resumed.x.tobytes() == state.x.tobytes() and resumed.v.tobytes() == state.v.tobytes()
    assert fresh.last_solve.iterations == integrator.last_solve.iterations


@pytest.mark.parametrize("depth", [-1, 1.5, True, "5", None])
def test_warm_start_depth_must_be_a_whole_number(depth):
    with pytest.raises((ValueError, TypeError), match="warm_start"):
        ImplicitEuler(warm_start=depth)


def _iterations(scene, h_omega, solver, steps=3, **options):
    h = h_omega / omega_max(scene.model, scene.free)
    integrator = ImplicitEuler(solver=solver, **options)
    state = scene.initial_state()
    counts = []
    for _ in range(steps):
        state = integrator.step(scene, state, h)
        counts.append(integrator.last_solve.iterations)
    return max(counts)


def test_amg_iterations_roughly_independent_of_mesh_size_and_far_below_jacobi():
    # Fixed h omega_max = 50, i.e. a fixed dt / element size ratio; 81 to 1225 nodes.
    sizes = [(8, 2, 2), (16, 4, 4), (24, 6, 6)]
    amg = [_iterations(beam(cells), 50.0, "amg") for cells in sizes]
    # "Roughly independent": the largest count within 1.5x + 2 of the smallest (measured: 7, 7, 7;
    # Jacobi-CG needed 191 on the largest).
    assert max(amg) <= 1.5 * min(amg) + 2, amg
    jacobi = _iterations(beam(sizes[-1]), 50.0, "jacobi", steps=1, maxiter=20000)
    assert jacobi >= 5 * amg[-1], (jacobi, amg)


@pytest.mark.slow
def test_amg_iterations_independent_of_size_1k_to_50k():
    sizes = [(40, 5, 5), (80, 10, 10), (140, 18, 18)]  # 1476, 9801, 50901 nodes; measured 7, 7, 7
    amg = [_iterations(beam(cells), 50.0, "amg", steps=3) for cells in sizes]
    assert max(amg) <= 1.5 * min(amg) + 2, amg


def test_non_convergence_raises_with_the_residual():
    scene = beam((16, 4, 4))  # 1275 unknowns: more than the coarsest AMG level, so not solved exactly
    h = 100.0 / omega_max(scene.model, scene.free)
    with pytest.raises(SolverNotConverged, match=r"residual [0-9.e-]+"):
        ImplicitEuler(rtol=1e-10, maxiter=1).step(scene, scene.initial_state(), h)
    with pytest.raises(SolverNotConverged, match="residual"):
        ImplicitEuler(solver="jacobi", rtol=1e-10, maxiter=1).step(scene, scene.initial_state(), h)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ImplicitEuler(rtol=1e-10, maxiter=1, on_failure="warn").step(scene, scene.initial_state(), h)
    assert any("residual" in str(w.message) for w in caught)


def test_beam_sags_under_gravity_and_settles():
    scene = beam((12, 3, 3), material=Material(1e8, 0.25, 1000.0))
    h = 300.0 / omega_max(scene.model, scene.free)  # h omega_1 ~ 1 for the first bending mode
    integrator = ImplicitEuler()
    state = scene.initial_state()
    energies, speeds, tips = [total_energy(scene, state)], [], []
    for _ in range(100):
        state = integrator.step(scene, state, h)
        energies.append(total_energy(scene, state))
        speeds.append(np.abs(state.v).max())
        tips.append(state.x[:, 2].min())
    energies = np.array(energies)
    assert tips[-1] < -1e-3  # it sags (Euler-Bernoulli estimate q L^4 / 8 E I = 3.7 mm)
    # settles: the fastest node has slowed to < 1e-6 of the peak speed, the tip stopped moving
    assert speeds[-1] < 1e-6 * max(speeds)
    assert abs(tips[-1] - tips[-2]) < 1e-9 * abs(tips[-1])
    # energy decreasing (up to 1e-6 of the energy released: the CG solves stop at rtol 1e-3)
    released = energies[0] - energies.min()
    assert released > 0 and (np.diff(energies) <= 1e-6 * released).all()


def test_newton_iterations_converge_to_the_fully_implicit_answer():
    scene = beam((8, 2, 2), damping_ratio=0.05, material=Material(1e5, 0.25, 1000.0))
    h = 5e-3  # large deflection in one step from rest: the linearisation is visibly off
    state = scene.initial_state()
    integrator = ImplicitEuler(solver="direct", newton_iterations=5)
    new = integrator.step(scene, state, h)
    residuals = integrator.last_solve.newton_residuals
    assert len(residuals) == 6
    # the clamped Hessian makes this a quasi-Newton iteration: still a drop by >= 1e4 over five
    # iterations, down to round-off level
    assert residuals[-1] < 1e-4 * residuals[0], residuals
    # and the answer satisfies the nonlinear backward Euler equation
    model = scene.model
    residual = model.masses[:, None] * (new.v - state.v) - h * scene.forces_at(new.x, new.v, new.t)
    assert np.abs(residual[scene.free]).max() < 1e-4 * np.abs(h * model.masses * 9.81).max()


def test_resume_from_copied_state_is_bit_identical():
    scene = beam((10, 2, 2))
    h = 30.0 / omega_max(scene.model, scene.free)
    options = dict(rebuild_every=3)  # several hierarchy builds on the way
    integrator = ImplicitEuler(**options)
    state = scene.initial_state()
    states = []
    for _ in range(10):
        state = integrator.step(scene, state, h)
        states.append(state)
    checkpoint = copy.deepcopy(states[4])  # as if written to disk and read back
    resumed = ImplicitEuler(**options)
    state = checkpoint
    for k in range(5, 10):
        state = resumed.step(scene, state, h)
        assert np.array_equal(state.x, states[k].x) and np.array_equal(state.v, states[k].v)
    assert resumed.solver.build_count >= 2  # rebuilt from the record, then by the policy


def test_step_does_not_modify_its_input_state():
    scene = beam((6, 2, 2))
    state = ImplicitEuler().step(scene, scene.initial_state(), 1e-3)
    before = copy.deepcopy(state)
    ImplicitEuler().step(scene, state, 1e-3)
    assert np.array_equal(state.x, before.x) and np.array_equal(state.v, before.v)
    assert state.memory.keys() == before.memory.keys()
    assert all(np.array_equal(state.memory[k], before.memory[k]) for k in state.memory)


def test_fused_forces_match_spring_forces():
    model = Model.from_mesh(cube_mesh((2, 2, 2)), RUBBER, damping_ratio=0.2)
    rng = np.random.default_rng(3)
    x = model.rest_positions + 0.05 * rng.standard_normal(model.rest_positions.shape)
    v = rng.standard_normal(x.shape)
    pattern = BlockPattern(model)
    lin = pattern.linearize(x, v, stiffness_scale=2.0, damping_scale=3.0)
    reference = spring_forces(model, x, v)
    assert np.abs(lin.forces - reference).max() <= 1e-12 * np.abs(reference).max()
    blocks = (2.0 * spring_stiffness_blocks(model, x) + 3.0 * damper_blocks(model, x))[pattern.parts[0].order]
    assert np.abs(lin.blocks - blocks).max() <= 1e-12 * np.abs(blocks).max()


def test_springs_gather_by_the_incidence_without_holding_the_difference_matrix():
    """The springs gather x_i - x_j by the incidence's transpose (a CSC view) and fold the sign into what follows:
    the same bits as the x_j - x_i of the CSR ``difference`` they held before (0.18 KiB per node), which is now
    made on request only. Forces with dampers and the dF/dx product are checked against the difference form."""
    model = Model.from_mesh(cube_mesh((3, 2, 2)), RUBBER, damping_ratio=0.2)
    springs = model.spring_elements
    rng = np.random.default_rng(5)
    x = model.rest_positions + 0.05 * rng.standard_normal(model.rest_positions.shape)
    v, u = rng.standard_normal(x.shape), rng.standard_normal(x.shape)
    lin = springs.linearize(x, v)
    difference = springs.difference
    assert "difference" not in vars(springs)  # not cached on the springs
    assert np.array_equal(springs._gathered(x), -(difference @ x))
    from meshing.topology import vector_lengths

    d = difference @ x
    length = vector_lengths(d)  # the package's lengths (np.linalg.norm rounds differently)
    r = d / length[:, None]
    magnitude = springs.stiffness * (length - springs.rest_lengths) + springs.damping * np.einsum(
        "ij,ij->i", difference @ v, r)
    # Exact: negation and the order of two-term sums change no bits (same formula, the sign moved).
    np.testing.assert_array_equal(lin.directions, r)
    np.testing.assert_array_equal(lin.forces, springs.incidence @ (magnitude[:, None] * r))
    du = difference @ u
    along = (lin.axial - lin.transverse) * np.einsum("ij,ij->i", r, du)
    np.testing.assert_array_equal(lin.dfdx_times(u), springs.incidence @ (lin.transverse[:, None] * du +
                                                                          along[:, None] * r))


def test_rcm_numbering_gives_the_same_step_as_natural_numbering(deformed_scene):
    scene, state = deformed_scene
    rcm = BlockPattern(scene.model, scene.free)
    natural = BlockPattern(scene.model, scene.free, ordering="natural")
    assert sorted(rcm.free_nodes) == list(natural.free_nodes)
    masses = scene.model.masses
    matrices = []
    for pattern in (rcm, natural):
        blocks = pattern.linearize(state.x, stiffness_scale=1e-4, damping_scale=1e-2).blocks
        matrix = pattern.matrix(blocks, masses[pattern.free_nodes]).toarray()
        position = np.argsort(pattern.free_dofs())  # back to increasing node index
        matrices.append(matrix[np.ix_(position, position)])
    # the same matrix up to the numbering: the sums only change order (round-off)
    assert np.abs(matrices[0] - matrices[1]).max() <= 1e-14 * np.abs(matrices[1]).max()
    new_rcm = ImplicitEuler(solver="direct").step(scene, state, 0.01)
    integrator = ImplicitEuler(solver="direct")
    integrator.cache.pattern = natural
    new_natural = integrator.step(scene, state, 0.01)
    assert np.abs(new_rcm.v - new_natural.v).max() <= 1e-10 * np.abs(new_natural.v).max()


def test_the_block_pattern_keeps_no_construction_array_alive():
    """Every array the pattern keeps owns its memory or views one of its own size: ``diagonal_blocks`` was a view
    into the block index of every contribution (4 per spring, int64), which kept that alive with the pattern (0.21
    KiB per node at 45k nodes, with the model for the whole run)."""
    scene = beam((8, 2, 2))
    pattern = BlockPattern(scene.model, scene.free)
    for name, value in vars(pattern).items():
        if isinstance(value, np.ndarray):
            root = value
            while isinstance(root.base, np.ndarray):
                root = root.base
            assert root.nbytes <= value.nbytes, (name, root.shape, value.shape)


def test_the_step_lets_the_element_sets_blocks_go_before_its_build_and_solve(monkeypatch):
    """Once they are in the matrix and the right-hand side, nothing the step holds keeps the sets' linearised blocks
    (the springs' 72 bytes each, 0.46 KiB per node on the README beam) through the AMG build and the solve, where
    the step's memory peaks: a weak reference to them is dead by then."""
    import gc
    import weakref

    from volspring.solvers.amg import AMGConjugateGradient

    scene = beam((8, 2, 2))
    references, alive = [], []
    linearize, build, solve = BlockPattern.linearize, AMGConjugateGradient.build, AMGConjugateGradient.solve

    def kept(pattern, *args, **kwargs):
        linearization = linearize(pattern, *args, **kwargs)
        references.append(weakref.ref(linearization.parts[0].blocks))
        return linearization

    def check(method):
        def checked(*args, **kwargs):
            gc.collect()
            alive.append(references[-1]() is not None)
            return method(*args, **kwargs)
        return checked

    monkeypatch.setattr(BlockPattern, "linearize", kept)
    monkeypatch.setattr(AMGConjugateGradient, "build", check(build))
    monkeypatch.setattr(AMGConjugateGradient, "solve", check(solve))
    integrator, state = ImplicitEuler(), scene.initial_state()
    for _ in range(2):  # a step with a build and one without
        state = integrator.step(scene, state, 0.01)
    assert len(alive) == 3 and not any(alive)
