"""volspring.solvers on its own: the V-cycle adapter against pyamg's public preconditioner, the
timer, pickling, the two-level cycle, and agreement of the three methods.

The systems are the implicit-step matrix M + h^2 K of a spring network on a structured box, built
here from the mesh edges (axial springs, 3x3 blocks in BSR), so these tests see only the solvers.
"""

import pickle
import time

import numpy as np
import pyamg
import pytest
import scipy.sparse as sp
from conftest import cube_mesh

from meshing.geometry import rigid_body_modes
from volspring import solvers
from volspring.errors import SolverNotConverged
from volspring.solvers import AMGConjugateGradient, DirectSolver, JacobiConjugateGradient, make_linear_solver
from volspring.solvers import amg
from volspring.solvers.amg import SMOOTHERS, _Triangles
from volspring.solvers.krylov import Deflation, conjugate_gradient


def spring_system(cells, *, h_omega=50.0):
    """(BSR matrix M + h^2 K with h omega ~ ``h_omega``, rigid-body modes, rest points) of a box.

    Unit masses and unit axial springs along every tet edge; the end x = 0 is held by springs to
    the ground (its diagonal blocks get an extra k I), so K is SPD even without M.
    """
    mesh = cube_mesh(cells, (1.0, 0.2, 0.2))
    points, tets = mesh.points, mesh.tets
    pairs = ((0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3))
    edges = np.unique(np.sort(np.concatenate([tets[:, pair] for pair in pairs]), axis=1), axis=0)
    direction = points[edges[:, 1]] - points[edges[:, 0]]
    direction /= np.linalg.norm(direction, axis=1, keepdims=True)
    blocks = direction[:, :, None] * direction[:, None, :]              # (s, 3, 3) k r r^T, k = 1
    n = len(points)
    rows = np.concatenate([edges[:, 0], edges[:, 1], edges[:, 0], edges[:, 1]])
    cols = np.concatenate([edges[:, 0], edges[:, 1], edges[:, 1], edges[:, 0]])
    data = np.concatenate([blocks, blocks, -blocks, -blocks])
    held = np.flatnonzero(points[:, 0] < 1e-9)
    rows, cols = np.concatenate([rows, held]), np.concatenate([cols, held])
    data = np.concatenate([data, np.broadcast_to(np.eye(3), (len(held), 3, 3))])
    # Sum duplicate blocks through a scalar COO (BSR construction does not sum them).
    r = (3 * rows[:, None, None] + np.arange(3)[None, :, None]).repeat(3, axis=2)
    c = (3 * cols[:, None, None] + np.arange(3)[None, None, :]).repeat(3, axis=1)
    stiffness = sp.coo_matrix((data.ravel(), (r.ravel(), c.ravel())), shape=(3 * n, 3 * n)).tocsr()
    omega_squared = float(abs(stiffness).sum(axis=1).max())               # Gershgorin, unit masses
    h_squared = h_omega**2 / omega_squared
    stiffness = (stiffness + stiffness.T) / 2  # exactly symmetric (the sums above round in different orders)
    matrix = (sp.identity(3 * n, format="csr") + h_squared * stiffness).tobsr(blocksize=(3, 3))
    return matrix, rigid_body_modes(points), points


@pytest.fixture(scope="module")
def system():
    return spring_system((24, 5, 5))   # 900 nodes, 2,700 unknowns: two AMG levels (three with max_coarse=20)


@pytest.fixture(scope="module")
def rhs(system):
    return np.random.default_rng(0).standard_normal(system[0].shape[0])


def test_spring_system_is_spd():
    matrix = spring_system((8, 2, 2))[0].toarray()  # the fixture's construction, small enough for a dense check
    np.testing.assert_array_equal(matrix, matrix.T)
    assert np.linalg.eigvalsh(matrix)[0] >= 1.0 - 1e-9  # M + h^2 K with K >= 0 and M = I


@pytest.mark.parametrize("smoother", [name for name in SMOOTHERS if name != "gauss_seidel"])
def test_v_cycle_adapter_equals_pyamg_public_preconditioner_bit_for_bit(system, rhs, smoother):
    """On levels held as whole matrices the cycle is pyamg's arithmetic, step for step."""
    matrix, modes, _ = system
    solver = AMGConjugateGradient(smoother=smoother)
    solver.build(matrix, modes)
    assert len(solver.hierarchy.levels) > 1
    public = solver.hierarchy.aspreconditioner(cycle="V")
    assert solver.precondition(rhs).tobytes() == public.matvec(rhs).tobytes()
    # And so the whole CG solve: the same iterates, the same answer.
    x, info = solver.solve(matrix, rhs)
    y, iterations, _, _ = solvers.conjugate_gradient(matrix.__matmul__, rhs, preconditioner=public.matvec,
                                                     rtol=solver.rtol, maxiter=solver.maxiter)
    assert x.tobytes() == y.tobytes() and info.iterations == iterations


def test_the_coarse_solve_is_pyamgs_sparse_lu_bit_for_bit_with_empty_columns_left_out():
    """The coarsest level is factorised and solved by index where pyamg's LU solver multiplies by a selection matrix
    and its transpose: the same numbers as pyamg's in the same column order, also when the coarsest matrix has empty
    rows and columns (a candidate an aggregate cannot carry), which both leave out of the factors and answer with
    zeros."""
    from types import SimpleNamespace

    from pyamg.multilevel import MultilevelSolver, coarse_grid_solver

    generator = np.random.default_rng(6)
    root = generator.standard_normal((12, 12))
    dense = root @ root.T + 12 * np.eye(12)
    dense[[3, 8], :] = dense[:, [3, 8]] = 0.0
    level = MultilevelSolver.Level()
    level.A = sp.csr_matrix(dense)
    hierarchy = SimpleNamespace(levels=[level], coarse_solver=amg._CoarseLU(level.A))  # a coarsest level's solver
    # Dense: the envelope of the 10 x 10 kept holds 45 of its 100 entries, so its own order.
    theirs = coarse_grid_solver(("splu", {"permc_spec": "NATURAL"}))
    b = generator.standard_normal(12)
    ours = amg._coarse_solve(hierarchy)(b)
    assert ours.tobytes() == theirs(level.A, b).tobytes() and ours[3] == ours[8] == 0.0
    assert hierarchy.coarse_solver(level.A, b).tobytes() == ours.tobytes()  # called as pyamg calls it
    kept = [i for i in range(12) if i not in (3, 8)]
    np.testing.assert_allclose(dense[np.ix_(kept, kept)] @ ours[kept], b[kept], rtol=1e-12)  # and it solves


def test_a_banded_coarsest_level_is_factorised_in_its_own_order_and_a_shuffled_one_is_not(system):
    """The test beam's nodes are numbered along it (a structured grid; an implicit step's pattern numbers them by
    reverse Cuthill-McKee) and its aggregates follow them, so its coarsest matrix is banded: factorised in its own
    order (cheaper than SuperLU's COLAMD, amg._column_order), with no more fill than COLAMD gives it. The same matrix
    shuffled keeps COLAMD, where its own order would give more fill than the banded one has."""
    import scipy.sparse.linalg as spla

    matrix, modes, _ = system
    solver = AMGConjugateGradient()
    solver.build(matrix, modes)
    coarse = solver.hierarchy.coarse_solver
    assert len(solver.hierarchy.levels) > 1 and coarse.kept is None
    order = coarse.LU.perm_c
    assert np.array_equal(order, np.arange(len(order)))  # COLAMD's would not be the identity
    coarsest = sp.csc_matrix(solver.hierarchy.levels[-1].A)
    coarsest.eliminate_zeros()  # as _CoarseLU factorises it
    assert coarse.LU.L.nnz <= spla.splu(coarsest, permc_spec="COLAMD").L.nnz
    shuffle = np.random.default_rng(2).permutation(coarsest.shape[0])
    shuffled = sp.csc_matrix(coarsest[shuffle][:, shuffle])
    assert amg._column_order(shuffled) == "COLAMD"
    assert spla.splu(shuffled, permc_spec="NATURAL").L.nnz > coarse.LU.L.nnz


def test_a_blocked_coarsest_level_is_factorised_as_its_scalar_form():
    """The coarsest level comes as BSR and is taken to CSC through its transpose (cheaper than scipy's way through
    CSR): the same factors, so the same solution bit for bit as from its CSC form, on a matrix that is not symmetric
    (where the transpose would be the wrong matrix) and has an empty row and column (left out of the factorisation)."""
    rng = np.random.default_rng(4)
    dense = rng.standard_normal((12, 12)) + 12 * np.eye(12)
    dense[5, :] = dense[:, 5] = 0.0
    blocked = sp.bsr_matrix(dense, blocksize=(3, 3))
    b = rng.standard_normal(12)
    x = amg._CoarseLU(blocked).solve(b)
    assert x.tobytes() == amg._CoarseLU(sp.csc_matrix(dense)).solve(b).tobytes()
    kept = np.arange(12) != 5
    # Rounding: a diagonally dominant 11 x 11 system solved by LU (condition number about 2), far above 1e-16.
    np.testing.assert_allclose(dense[np.ix_(kept, kept)] @ x[kept], b[kept], atol=1e-12)
    assert x[5] == 0.0


def test_a_singular_coarsest_level_falls_back_to_the_pseudo_inverse(system):
    """Where SuperLU finds the coarsest matrix singular (statics of a barely held body), the level is solved by
    pyamg's pseudo-inverse instead, and the cycle stays finite. Here two of its rows and columns are made equal, so
    that the elimination meets an exact zero pivot."""
    from pyamg.multilevel import coarse_grid_solver

    matrix, modes, _ = system
    solver = AMGConjugateGradient()
    solver.build(matrix, modes)
    hierarchy = solver.hierarchy
    coarsest = hierarchy.levels[-1].A
    dense = coarsest.toarray()
    dense[1, :], dense[:, 1] = dense[0, :], dense[:, 0]
    singular = sp.bsr_matrix(dense, blocksize=coarsest.blocksize)
    with pytest.raises(RuntimeError, match="singular"):
        amg._CoarseLU(singular)
    hierarchy.levels[-1].A = singular
    solver._adopt(hierarchy)
    assert not isinstance(hierarchy.coarse_solver, amg._CoarseLU)
    b = singular @ np.random.default_rng(3).standard_normal(singular.shape[0])  # in the range: a solution exists
    x = amg._coarse_solve(hierarchy)(b)
    expected = coarse_grid_solver("pinv")(singular, b)
    assert x.tobytes() == expected.tobytes()
    # It solves: the pseudo-inverse's residual is rounding (measured 2.7e-15 relative; 1e-10 catches a wrong solver).
    assert np.linalg.norm(singular @ x - b) <= 1e-10 * np.linalg.norm(b)
    assert np.isfinite(solver.precondition(np.ones(matrix.shape[0]))).all()


@pytest.mark.parametrize("smoother", SMOOTHERS)
def test_every_smoother_makes_a_symmetric_positive_definite_v_cycle(system, smoother):
    """CG needs an SPD preconditioner: each forward sweep before the coarse correction is undone by a backward
    one after it (point-wise on the finest level, by blocks below, for the default)."""
    matrix, modes, _ = system
    solver = AMGConjugateGradient(smoother=smoother)
    solver.build(matrix, modes)
    u, v = np.random.default_rng(1).standard_normal((2, matrix.shape[0]))
    # Symmetric to round-off: measured 1e-14 to 2e-14 relative on this system for the three smoothers in double
    # precision; the default's finest level sweeps in single precision (unit round-off 6e-8): measured 8.6e-8.
    rounding = 1e-6 if smoother == "gauss_seidel" else 1e-10
    assert np.dot(u, solver.precondition(v)) == pytest.approx(np.dot(v, solver.precondition(u)), rel=rounding)
    assert np.dot(u, solver.precondition(u)) > 0 and np.dot(v, solver.precondition(v)) > 0


def test_default_smoother_sweeps_the_finest_level_point_wise_on_the_current_matrix(system, rhs, monkeypatch):
    """The default keeps the finest level as CSR (pyamg sweeps a BSR matrix by blocks, at 3.5 times the
    cost of a point-wise sweep) holding the built matrix in single precision, and after refresh() the refreshed
    one."""
    matrix, modes, _ = system
    solver = AMGConjugateGradient()
    solver.build(matrix, modes)
    finest = solver.hierarchy.levels[0].A
    assert isinstance(finest, _Triangles) and finest.format == "csr" and finest.lower.data.dtype == np.float32
    assert (finest.whole() != matrix.astype(np.float32)).nnz == 0
    # Its P in single precision as CSR, R the transpose as a view of P's arrays (no copy), both equal to the built
    # double P rounded (that P, built again in double, is the reference).
    # The levels are the kept copy (a pickle carries them): the near-null space is not kept.
    assert solver._source.near_null_space is None and solver.hierarchy.levels[0].B is None
    level = solver.hierarchy.levels[0]
    assert level.P.format == "csr" and level.P.dtype == np.float32 and amg._transposed(level)
    assert (level.R != level.P.T).nnz == 0
    with monkeypatch.context() as patch:
        patch.setattr(amg, "FINEST_DTYPE", np.float64)
        double = AMGConjugateGradient()
        double.build(matrix, modes)
    built = double.hierarchy.levels[0].P
    assert built.format == "bsr" and (level.P != built.astype(np.float32)).nnz == 0
    assert all(level.A.format == "bsr" for level in solver.hierarchy.levels[1:])
    stiffer = (matrix + sp.identity(matrix.shape[0], format="bsr")).tobsr(blocksize=(3, 3))
    before = solver.precondition(rhs)
    solver.refresh(stiffer)
    finest = solver.hierarchy.levels[0].A
    assert finest.format == "csr" and (finest.whole() != stiffer.astype(np.float32)).nnz == 0
    assert not np.array_equal(solver.precondition(rhs), before)
    # A CG solve on the refreshed system reaches its target (the hierarchy below is the built one).
    x, info = solver.solve(stiffer, rhs)
    assert info.converged and np.linalg.norm(stiffer @ x - rhs) <= solver.rtol * np.linalg.norm(rhs)


@pytest.mark.parametrize("smoother", SMOOTHERS)
def test_restore_puts_the_built_matrix_back_after_a_refresh(system, rhs, smoother):
    """refresh() then restore() gives the preconditioner of the build bit for bit (what a resumed run has)."""
    matrix, modes, _ = system
    solver = AMGConjugateGradient(smoother=smoother)
    solver.build(matrix, modes)
    built = solver.precondition(rhs)
    solver.restore()  # nothing refreshed: nothing to do
    assert solver.precondition(rhs).tobytes() == built.tobytes()
    solver.refresh((matrix + sp.identity(matrix.shape[0], format="bsr")).tobsr(blocksize=(3, 3)))
    assert not np.array_equal(solver.precondition(rhs), built)
    solver.restore()
    assert solver.precondition(rhs).tobytes() == built.tobytes()
    # And the same as a hierarchy rebuilt from the pickled solver's source.
    assert pickle.loads(pickle.dumps(solver)).precondition(rhs).tobytes() == built.tobytes()


def _level_dense(matrix) -> np.ndarray:
    """A level's matrix as a dense array: triangles (whose halves share the diagonal, or its blocks) or sparse."""
    if not isinstance(matrix, _Triangles):
        return matrix.toarray()
    lower, upper = matrix.lower.toarray().astype(np.float64), matrix.upper.toarray().astype(np.float64)
    size = 1 if matrix.inverse is None else matrix.blocksize[0]
    shared = np.kron(np.eye(lower.shape[0] // size), np.ones((size, size)))
    return lower + upper - lower * shared


@pytest.mark.parametrize("smoother", SMOOTHERS)
def test_update_gives_the_levels_above_the_coarsest_the_change_and_restore_takes_it_back(system, rhs, smoother):
    """update(C) (contact's change since the build): the finest level holds the built matrix plus C, the first coarse
    level its own plus P^T C P with the built P, the coarsest its own (UPDATE_DEPTH = 2: its factorisation would
    cost as much as the rest). A second update replaces the first; restore() and a pickle taken during an update
    give the build's preconditioner bit for bit (what a resumed run has)."""
    matrix, modes, _ = system
    solver = AMGConjugateGradient(smoother=smoother, max_coarse=20)
    solver.build(matrix, modes)
    levels = solver.hierarchy.levels
    assert len(levels) == 3 and amg.UPDATE_DEPTH == 2
    built = [_level_dense(level.A) for level in levels]
    coarsest, before = levels[2].A, solver.precondition(rhs)
    change = _contact_like_change(matrix.shape[0], np.random.default_rng(8))
    solver.update(2.0 * change)
    given = change.copy()
    given.data[0] = 0.0  # an explicit zero, which the update drops from its own copy only
    kept = given.copy()
    solver.update(given)
    assert np.array_equal(given.data, kept.data) and np.array_equal(given.indices, kept.indices)
    change = given
    # The levels are made when the solver first preconditions: a solve that its guess already meets leaves them.
    changed = sp.bsr_matrix(matrix + change, blocksize=(3, 3))
    exact = np.linalg.solve(changed.toarray(), rhs)
    assert solver.solve(changed, rhs, x0=exact)[1].iterations == 0
    assert all(np.array_equal(_level_dense(level.A), dense) for level, dense in zip(levels, built))
    solver.precondition(rhs)
    fine, first = _level_dense(levels[0].A), _level_dense(levels[1].A)
    # The finest level in single precision with the default smoother (unit round-off 6e-8 of entries of order 50).
    rounding = 1e-6 if smoother == "gauss_seidel" else 1e-12
    assert np.abs(fine - (built[0] + change.toarray())).max() <= rounding * np.abs(built[0]).max()
    P = levels[0].P.toarray().astype(np.float64)
    expected = built[1] + P.T @ change.toarray() @ P
    # The same products summed in another order: rounding of double precision.
    assert np.abs(first - expected).max() <= 1e-12 * np.abs(expected).max()
    assert np.abs(P.T @ change.toarray() @ P).max() > 1e-3 * np.abs(built[1]).max()  # the change is seen there
    assert levels[2].A is coarsest
    updated = solver.precondition(rhs)
    assert not np.array_equal(updated, before)
    assert pickle.loads(pickle.dumps(solver)).precondition(rhs).tobytes() == before.tobytes()
    solver.restore()
    assert solver.precondition(rhs).tobytes() == before.tobytes()
    assert all(np.array_equal(_level_dense(level.A), dense) for level, dense in zip(levels, built))
    # A refresh after an update starts from the built levels too, and drops a change not yet made.
    solver.update(change)
    solver.precondition(rhs)
    solver.refresh(matrix)
    assert np.array_equal(_level_dense(levels[1].A), built[1])
    solver.update(change)
    solver.refresh(matrix)
    solver.precondition(rhs)
    assert np.array_equal(_level_dense(levels[1].A), built[1])


def test_update_and_refresh_refuse_what_they_cannot_apply(system):
    """Before a build, with a matrix or change of another shape, or on a two-level hierarchy: a clear error."""
    matrix, modes, _ = system
    size = matrix.shape[0]
    with pytest.raises(ValueError, match=r"not built: call build"):
        AMGConjugateGradient().update(sp.identity(size, format="csr"))
    solver = AMGConjugateGradient()
    solver.build(matrix, modes)
    shapes = rf"change has shape \(30, 30\); the hierarchy was built for \({size}, {size}\)"
    with pytest.raises(ValueError, match=shapes):
        solver.update(sp.identity(30, format="csr"))
    with pytest.raises(ValueError, match=rf"matrix has shape \(30, 30\); the hierarchy was built for"):
        solver.refresh(sp.identity(30, format="csr"))
    prolongation = sp.csr_matrix(np.repeat(np.eye(size // 30), 30, axis=0))  # 30 unknowns per coarse one
    two_level = AMGConjugateGradient()
    two_level.build(matrix, np.ones((size // 30, 1)), prolongation=prolongation)
    with pytest.raises(ValueError, match=r"update\(\) applies to a hierarchy built on the matrix itself"):
        two_level.update(sp.identity(size, format="csr"))


def test_block_triangles_plus_a_change_invert_their_diagonal_blocks_as_pyamg_does():
    """A coarse level's 6x6 diagonal block can have empty rows (an aggregate whose candidates are dependent): the
    triangles of that level plus a change take the pseudo-inverses of their diagonal blocks, as pyamg and the
    triangles' own constructor do, where np.linalg.inv raised "Singular matrix"."""
    from pyamg.util.utils import get_block_diag

    rng = np.random.default_rng(4)
    factor = rng.normal(size=(24, 24))
    dense = factor @ factor.T + 24 * np.eye(24)
    dense[10:12, :] = dense[:, 10:12] = 0.0  # the second block's last two unknowns: empty rows and columns
    triangles = _Triangles(sp.bsr_matrix(dense, blocksize=(6, 6)))
    change = np.zeros((24, 24))
    vector = np.zeros(24)
    vector[[0, 13]] = 1.0, -1.0  # a contact-like coupling of the first and third blocks
    change += 5.0 * np.outer(vector, vector)
    updated = triangles.plus(sp.csr_matrix(change))
    expected = get_block_diag(sp.bsr_matrix(dense + change, blocksize=(6, 6)), blocksize=6, inv_flag=True)
    # pinv of the same blocks: the same arithmetic to rounding (entries of order 1/24).
    np.testing.assert_allclose(updated.inverse, expected, rtol=0, atol=1e-12)
    np.testing.assert_allclose(_level_dense(updated), dense + change, rtol=0, atol=1e-12)
    x = np.zeros(24)
    updated.forward(x, np.ones(24))
    assert np.isfinite(x).all() and x[10] == x[11] == 0.0


def test_an_update_beyond_single_precision_holds_the_finest_level_in_double(system, rhs):
    """The finest level's triangles are single precision within SINGLE_PRECISION_RANGE; a change beyond it (a
    contact stiffness 1e20 times the matrix's) is added in double, not rounded to infinity."""
    matrix, modes, _ = system
    solver = AMGConjugateGradient()
    solver.build(matrix, modes)
    change = 1e20 * _contact_like_change(matrix.shape[0], np.random.default_rng(8))
    assert np.abs(change.data).max() > amg.SINGLE_PRECISION_RANGE
    solver.update(change)
    assert np.isfinite(solver.precondition(rhs)).all()
    finest = solver.hierarchy.levels[0].A
    assert finest.dtype == np.float64 and finest.lower.dtype == np.float64
    expected = matrix.astype(np.float32).toarray().astype(np.float64) + change.toarray()
    assert np.abs(_level_dense(finest) - expected).max() <= 1e-15 * np.abs(expected).max()
    assert np.isfinite(solver.precondition(rhs)).all()


def _contact_like_change(size, rng):
    """(size, size) CSR: a symmetric positive semi-definite coupling of two 3-unknown nodes far apart, as contact
    adds (k (u_a - u_b)(u_a - u_b)^T along a random direction), with a stiffness near the matrix's diagonal."""
    direction = rng.normal(size=3)
    direction /= np.linalg.norm(direction)
    a, b = 3 * 7, size - 3 * 11  # two nodes at the ends of the bar
    rows = np.r_[a:a + 3, b:b + 3]
    vector = np.r_[direction, -direction]
    dense = 50.0 * np.outer(vector, vector)
    change = sp.coo_matrix((dense.ravel(), (np.repeat(rows, 6), np.tile(rows, 6))), shape=(size, size))
    return change.tocsr()


def test_the_finest_prolongator_is_smoothed_without_the_excluded_couplings(system, monkeypatch):
    """build(matrix, aggregation=A0), matrix = A0 + C: the finest level's aggregates and the smoothing of its
    prolongator come from A0 (to rounding: A0 is recovered as matrix - (matrix - A0)), the Galerkin product from
    the matrix with C. (The finest level in double, so that P is the one built, not its single-precision copy.)"""
    monkeypatch.setattr(amg, "FINEST_DTYPE", np.float64)
    matrix, modes, _ = system
    change = _contact_like_change(matrix.shape[0], np.random.default_rng(6))
    with_change = sp.bsr_matrix(matrix + change, blocksize=(3, 3))
    plain, given = AMGConjugateGradient(), AMGConjugateGradient()
    plain.build(matrix, modes)
    given.build(with_change, modes, aggregation=matrix)
    P, expected = given.hierarchy.levels[0].P.toarray(), plain.hierarchy.levels[0].P.toarray()
    # Rounding of (A0 + C) - C against A0, entries of order one in P (measured 0 to 1e-16).
    assert P.shape == expected.shape and np.abs(P - expected).max() <= 1e-12
    coarse = given.hierarchy.levels[1].A
    coarse = (coarse.whole() if isinstance(coarse, _Triangles) else coarse).toarray()
    galerkin = P.T @ with_change.toarray() @ P
    assert np.abs(coarse - galerkin).max() <= 1e-12 * np.abs(galerkin).max()  # the same sums, another order
    # The excluded couplings travel with a pickle: the rebuilt hierarchy preconditions bit for bit as the built one.
    rhs = np.random.default_rng(7).normal(size=matrix.shape[0])
    assert pickle.loads(pickle.dumps(given)).precondition(rhs).tobytes() == given.precondition(rhs).tobytes()


@pytest.mark.parametrize("theta", [0.05, 0.0])
def test_aggregation_by_the_matrix_itself_builds_the_same_hierarchy(system, rhs, theta):
    """build(aggregation=A) measures the couplings by the 3x3 blocks' Frobenius norms, as pyamg does for a BSR
    matrix: given the matrix itself, the same aggregates, the same cycle bit for bit (theta 0: every block)."""
    matrix, modes, _ = system
    plain, given = AMGConjugateGradient(strength_theta=theta), AMGConjugateGradient(strength_theta=theta)
    plain.build(matrix, modes)
    given.build(matrix, modes, aggregation=matrix.tocsr())
    assert given.precondition(rhs).tobytes() == plain.precondition(rhs).tobytes()
    # And after pickling (nothing is excluded: the pickle rebuilds the plain hierarchy).
    assert pickle.loads(pickle.dumps(given)).precondition(rhs).tobytes() == plain.precondition(rhs).tobytes()
    with pytest.raises(ValueError, match="aggregation must have the matrix's shape"):
        AMGConjugateGradient().build(matrix, modes, aggregation=matrix.tocsr()[:30, :30])
    far = sp.csr_matrix(([1.5], ([0], [matrix.shape[0] - 1])), shape=matrix.shape)  # the bar's two ends
    with pytest.raises(ValueError, match=rf"does not store, entry \(0, {matrix.shape[0] - 1}\) = 1.5"):
        AMGConjugateGradient().build(matrix, modes, aggregation=matrix + far)


@pytest.mark.parametrize("theta", [0.0, 0.05])
@pytest.mark.parametrize("max_coarse", [300, 20])
def test_the_hierarchy_is_pyamgs_smoothed_aggregation_to_rounding(system, theta, max_coarse):
    """The set-up done here (prolongation smoothing by the rows of A T, the Galerkin products, the block norms by
    einsum) builds the hierarchy ``pyamg.smoothed_aggregation_solver`` builds with the same options: on this
    system the same aggregates on every level (two and three levels), the same prolongators and coarse matrices
    to rounding."""
    from volspring.solvers.amg import PROLONGATION_OMEGA, _smoothed_aggregation

    matrix, modes, _ = system
    ours = _smoothed_aggregation(matrix, modes, theta=theta, excluded=None, max_coarse=max_coarse).levels
    theirs = pyamg.smoothed_aggregation_solver(
        matrix.copy(), B=modes, symmetry="hermitian", strength=("symmetric", {"theta": theta}),
        smooth=("jacobi", {"omega": PROLONGATION_OMEGA, "weighting": "local"}), improve_candidates=None,
        max_coarse=max_coarse, coarse_solver="splu").levels
    assert len(ours) == len(theirs) == (2 if max_coarse == 300 else 3)
    for mine, pyamgs in zip(ours[:-1], theirs[:-1]):
        for name in ("P", "R"):
            a, b = getattr(mine, name), getattr(pyamgs, name)
            assert a.shape == b.shape and a.blocksize == b.blocksize
            # Same entries in another order of operations: measured 2.5e-16 of the largest entry on this system.
            assert abs(a - b).max() <= 1e-13 * abs(b).max()
            # Held in an array of exactly its blocks (scipy's T - C kept room for T's blocks too: 23% more at 45k).
            assert a.data.base is None or a.data.base.size == a.data.size
    for mine, pyamgs in zip(ours[1:], theirs[1:]):
        # Sums of about a hundred products each: measured 5.3e-16 of the largest entry (level 1).
        assert abs(mine.A - pyamgs.A).max() <= 1e-12 * abs(pyamgs.A).max()
        np.testing.assert_allclose(mine.B, pyamgs.B, rtol=0, atol=1e-12 * abs(pyamgs.B).max())


def test_the_default_cycle_on_triangles_is_the_textbook_v_cycle_to_rounding(system, rhs, monkeypatch):
    """The default holds the levels as triangles and takes the residual after a sweep from zero as -U z. The same
    hierarchy with its whole matrices, swept by pyamg (point-wise on the finest level, by blocks below) and cycled by
    pyamg's public preconditioner, gives the same z up to rounding, and CG the same iterations. (In double precision
    throughout, to see the algebra's rounding alone; the single-precision finest level is checked below.)"""
    from pyamg.relaxation.smoothing import change_smoothers

    monkeypatch.setattr(amg, "FINEST_DTYPE", np.float64)
    matrix, modes, _ = system
    solver = AMGConjugateGradient(max_coarse=20)  # three levels: triangles swept point-wise and by blocks
    solver.build(matrix, modes)
    levels = solver.hierarchy.levels
    assert all(isinstance(level.A, _Triangles) for level in levels[:-1]) and len(levels) >= 3
    textbook = pyamg.multilevel.MultilevelSolver(levels, coarse_solver="splu")
    textbook.levels = [type(level)() for level in levels]
    for copy, level in zip(textbook.levels, levels):
        copy.__dict__.update(level.__dict__)
        copy.A = level.A.whole() if isinstance(level.A, _Triangles) else level.A
    textbook.levels[0].A = textbook.levels[0].A.tocsr()
    change_smoothers(textbook, [("gauss_seidel", {"sweep": "forward"}), ("block_gauss_seidel", {"sweep": "forward"})],
                     [("gauss_seidel", {"sweep": "backward"}), ("block_gauss_seidel", {"sweep": "backward"})])
    public = textbook.aspreconditioner(cycle="V")
    expected = public.matvec(rhs)
    # Rounding only: the residual -U z instead of r - A z, and r - L z before the backward sweep; measured 2e-16 to
    # 8e-16 relative on this system and on 10k and 45k-node beams, so 1e-13 leaves room and catches a wrong term.
    assert np.linalg.norm(solver.precondition(rhs) - expected) <= 1e-13 * np.linalg.norm(expected)
    # pyamg's own cycle on the triangles (their forward and backward sweeps from any x) agrees too.
    own = solver.hierarchy.aspreconditioner(cycle="V").matvec(rhs)
    assert np.linalg.norm(own - expected) <= 1e-13 * np.linalg.norm(expected)
    _, info = solver.solve(matrix, rhs)
    _, iterations, _, _ = solvers.conjugate_gradient(matrix.__matmul__, rhs, preconditioner=public.matvec,
                                                     rtol=solver.rtol, maxiter=solver.maxiter)
    assert info.iterations == iterations


def test_the_single_precision_finest_level_costs_no_cg_iteration(system, rhs, monkeypatch):
    """The finest level held and swept in single precision (the default) against the same hierarchy in double: CG
    meets the same targets, loose and tight, in as many iterations, and its true residual meets them."""
    matrix, modes, _ = system
    iterations = {}
    for dtype in (np.float32, np.float64):
        monkeypatch.setattr(amg, "FINEST_DTYPE", dtype)
        for rtol in (1e-3, 1e-10):
            solver = AMGConjugateGradient(rtol=rtol)
            x, info = solver.solve(matrix, rhs, near_null_space=modes)
            assert solver.hierarchy.levels[0].A.lower.data.dtype == dtype
            # The recursive residual CG stops on is the true one to rounding: 1% of the target leaves room for it.
            assert np.linalg.norm(matrix @ x - rhs) <= 1.01 * rtol * np.linalg.norm(rhs)
            iterations[dtype, rtol] = info.iterations
    # Measured equal here (6 and 19 iterations), and on 10k and 45k-node beams at rtol 1e-3, 1e-6 and 1e-9.
    assert all(iterations[np.float32, rtol] == iterations[np.float64, rtol] for rtol in (1e-3, 1e-10)), iterations


@pytest.mark.parametrize("matrix_scale, rhs_scale", [(1e36, 1.0), (1e-39, 1.0), (1.0, 1e-42), (1.0, 1e39)])
def test_a_scaled_system_solves_as_the_plain_one_beyond_single_precision(system, rhs, matrix_scale, rhs_scale):
    """A scaled matrix or right-hand side only scales the solution, also where single precision ends: the finest
    level is held in double outside :data:`amg.SINGLE_PRECISION_RANGE` (entries of 7e38 overflow it, of 1e-37 lose
    their digits), and the residual is scaled by a power of two before it is swept (of 1e-42 it would be subnormal,
    of 1e39 infinite)."""
    matrix, modes, _ = system
    plain, plain_info = AMGConjugateGradient(rtol=1e-8).solve(matrix, rhs, near_null_space=modes)
    scaled, info = AMGConjugateGradient(rtol=1e-8).solve(matrix_scale * matrix, rhs_scale * rhs, near_null_space=modes)
    assert info.converged and info.iterations == plain_info.iterations
    # The same iterations on a scaled copy of the system: the answers agree to CG's target (1e-8) times the
    # matrix's condition number here (about 10), with room.
    np.testing.assert_allclose(scaled * matrix_scale / rhs_scale, plain, rtol=0, atol=1e-6 * np.abs(plain).max())


@pytest.mark.parametrize("chunks", [8, 7, 1])
def test_the_galerkin_product_by_row_blocks_is_the_whole_product(system, monkeypatch, chunks):
    """R A P made a few block rows of R at a time (the build's peak memory) is the whole product's arrays, bit for
    bit: each row of a scipy product comes from that row of the left factor alone."""
    matrix, modes, _ = system
    monkeypatch.setattr(amg, "GALERKIN_CHUNKS", chunks)
    monkeypatch.setattr(amg, "GALERKIN_CHUNK_ROWS", 2)  # this system's R has fewer block rows than a piece's least
    level = amg._smoothed_aggregation(matrix, modes, theta=0.05, excluded=None, max_coarse=300).levels[0]
    assert level.R.shape[0] // level.R.blocksize[0] >= 2 * 8  # enough block rows to be split
    whole, pieces = level.R @ matrix @ level.P, amg._galerkin(level.R, matrix, level.P)
    assert pieces.format == "bsr" and pieces.blocksize == whole.blocksize and pieces.shape == whole.shape
    assert all(np.array_equal(getattr(pieces, part), getattr(whole, part)) for part in ("data", "indices", "indptr"))


def test_a_small_galerkin_product_is_made_whole(system, monkeypatch):
    """Fewer than two pieces' worth of block rows (:data:`amg.GALERKIN_CHUNK_ROWS`) take two products, not two per
    piece: each piece pays scipy's fixed costs, which cost a 1k-node build 8% in eight pieces."""
    matrix, modes, _ = system
    level = amg._smoothed_aggregation(matrix, modes, theta=0.05, excluded=None, max_coarse=300).levels[0]
    products = []
    product = amg._product
    monkeypatch.setattr(amg, "_product", lambda left, right: products.append(1) or product(left, right))
    rows = level.R.shape[0] // level.R.blocksize[0]
    for least, expected in ((rows // 2 + 1, 2), (rows // 3, 2 * 3)):
        monkeypatch.setattr(amg, "GALERKIN_CHUNK_ROWS", least)
        products.clear()
        amg._galerkin(level.R, matrix, level.P)
        assert len(products) == expected, (least, rows)


@pytest.mark.parametrize("duplicates", [False, True])
def test_block_duplicates_are_summed_as_scipy_sums_them(duplicates):
    """The solver's own BSR canonical form (scipy's is a Python loop over the blocks) gives scipy's arrays bit for
    bit: a Galerkin product's unsorted columns, and blocks stored twice or three times in one row."""
    generator = np.random.default_rng(5)
    rows, columns = generator.integers(0, 40, 400), generator.integers(0, 40, 400)
    if not duplicates:
        keys = np.unique(rows * 40 + columns)
        rows, columns = keys // 40, keys % 40
        order = generator.permutation(len(rows))  # unsorted within rows, as a product leaves them
        rows, columns = rows[order], columns[order]
    order = np.argsort(rows, kind="stable")
    indptr = np.concatenate([[0], np.cumsum(np.bincount(rows, minlength=40))]).astype(np.int32)
    data = generator.standard_normal((len(rows), 3, 6))
    ours = sp.bsr_matrix((data[order], columns[order].astype(np.int32), indptr), shape=(120, 240))
    theirs = ours.copy()
    assert not ours.has_sorted_indices
    amg._sum_duplicates(ours)
    theirs.sum_duplicates()
    assert ours.has_canonical_format
    assert len(ours.indices) < len(rows) if duplicates else len(ours.indices) == len(rows)
    for part in ("data", "indices", "indptr"):
        assert np.array_equal(getattr(ours, part), getattr(theirs, part)) and \
            getattr(ours, part).dtype == getattr(theirs, part).dtype, part


def _blocks_with_zeros(matrix):
    """``matrix`` (BSR) with a few stored entries set to zero, on and off the diagonal blocks (they must survive)."""
    copy = matrix.copy()
    copy.sum_duplicates()  # canonical, as the solver keeps it (the fixture's blocks are in first-seen order)
    copy.data[::7, 0, 2] = 0.0
    copy.data[::5, 1, 0] = 0.0
    return copy


@pytest.mark.parametrize("kind", ["point-wise BSR", "block BSR", "CSR"])
def test_triangles_give_their_matrix_back_entry_for_entry_and_sweep_as_pyamg(system, rhs, kind):
    """What a rebuild starts from (the kept triangles' whole matrix) is the built matrix, explicit zeros and block
    layout included; a forward sweep from zero is pyamg's sweep on the whole matrix bit for bit (the entries right of
    the diagonal meet x = 0), and its residual and the sweeps from any x are pyamg's to rounding."""
    from pyamg.relaxation.relaxation import block_gauss_seidel, gauss_seidel

    matrix = _blocks_with_zeros(system[0])
    if kind == "CSR":
        matrix = matrix.tocsr()
        matrix.sort_indices()
    triangles = _Triangles(matrix, point_wise=kind == "point-wise BSR")
    whole = triangles.whole()
    assert whole.format == matrix.format and whole.shape == matrix.shape and whole.nnz == matrix.nnz
    for name in ("data", "indices", "indptr"):
        assert getattr(whole, name).tobytes() == getattr(matrix, name).tobytes(), name
    assert triangles.lower.nnz + triangles.upper.nnz < 1.15 * matrix.nnz  # two halves, not two copies

    def sweep(x, b, direction):
        if kind == "block BSR":
            block_gauss_seidel(matrix, x, b, sweep=direction, blocksize=3)
        else:
            gauss_seidel(matrix.tocsr(), x, b, sweep=direction)

    expected = np.zeros_like(rhs)
    sweep(expected, rhs, "forward")
    z, residual = triangles.forward_from_zero(rhs)
    assert z.tobytes() == expected.tobytes()
    # Rounding: r - (D + L) z is zero only to rounding (measured 1e-16 relative to r); 1e-12 catches a missing term.
    np.testing.assert_allclose(residual, rhs - matrix @ z, rtol=0, atol=1e-12 * np.abs(rhs).max())
    np.testing.assert_allclose(triangles @ z, matrix @ z, rtol=0, atol=1e-12 * np.abs(matrix @ z).max())
    start = np.random.default_rng(2).standard_normal(len(rhs))
    for direction, method in (("forward", triangles.forward), ("backward", triangles.backward)):
        ours, theirs = start.copy(), start.copy()
        method(ours, rhs)
        sweep(theirs, rhs, direction)
        # The same sweep with its sum split in two: rounding only (measured 1e-16 relative).
        np.testing.assert_allclose(ours, theirs, rtol=0, atol=1e-12 * np.abs(theirs).max())


@pytest.mark.parametrize("method", ["amg", "jacobi"])
def test_a_given_first_residual_saves_its_product_and_changes_nothing(system, rhs, method, monkeypatch):
    """r0 = b - A x0 from the caller (the implicit step has it from its warm start): the same iterates bit for bit,
    one product with the matrix fewer."""
    from volspring.solvers import krylov

    matrix, modes, _ = system
    x0 = np.linalg.solve(np.diag(matrix.diagonal()), rhs)  # a rough guess: a few iterations still to go
    products, product = [], krylov.times

    def counting(operand, vectors):  # every product CG takes with the system, compiled (the fast extra) or scipy's
        if operand is counted:
            products.append(1)
        return product(operand, vectors)

    monkeypatch.setattr(krylov, "times", counting)
    counted = matrix.copy()
    answers = {}
    for given in (None, rhs - matrix @ x0):
        solver = make_linear_solver(method, rtol=1e-8)
        if method == "amg":
            solver.build(matrix, modes)
        products.clear()
        answers[given is None] = solver.solve(counted, rhs, x0=x0, r0=given)
        answers[given is None] += (len(products),)
    (x, info, without), (y, info_given, given_count) = answers[True], answers[False]
    assert x.tobytes() == y.tobytes() and info.iterations == info_given.iterations > 0
    assert given_count == without - 1


@pytest.mark.parametrize("cells", [(24, 5, 5), (2, 1, 1)])
def test_build_leaves_the_given_matrix_alone_and_keeps_its_own_copy(system, cells, rhs):
    """pyamg builds from the caller's canonical matrix without a copy (peak memory), but the caller's matrix gets
    none of pyamg's cached attributes, and changing it in place afterwards changes nothing in the solver, with
    several levels (kept as triangles) and with one (kept as a copy)."""
    matrix, modes, _ = spring_system(cells)
    matrix.sum_duplicates()
    attributes = set(vars(matrix))
    solver = AMGConjugateGradient()
    solver.build(matrix, modes)
    assert set(vars(matrix)) == attributes
    b = rhs[:matrix.shape[0]]
    before = solver.precondition(b)
    matrix.data *= 2.0
    assert solver.precondition(b).tobytes() == before.tobytes()
    assert pickle.loads(pickle.dumps(solver)).precondition(b).tobytes() == before.tobytes()  # a rebuild, too


def _near_slow_modes(rng):
    """A stiff box's dense matrix (624 unknowns: the dense checks stay cheap) and W near its five slowest modes, as the
    implicit step's past velocity changes are near its slow motion, with W^T A W diagonal as the step's guess makes
    it: (A, W, its diagonal)."""
    matrix, _, _ = spring_system((12, 3, 3), h_omega=1000.0)
    A = matrix.toarray()
    slowest = np.linalg.eigh(A)[1][:, :5]  # eigenvalues 17.6 to 482; the sixth is 930, the largest 6.6e5
    W = slowest + 0.02 * rng.standard_normal(slowest.shape) / np.sqrt(len(A))
    energies, directions = np.linalg.eigh(W.T @ A @ W)
    return A, W @ directions, energies


def test_deflated_cg_searches_a_orthogonally_to_its_subspace_and_converges_sooner():
    """CG deflated by W near the slowest modes, from the Galerkin guess on W (then it is Saad et al.'s deflated CG):
    every search direction is A-orthogonal to W, so CG no longer re-finds those modes, and it needs fewer iterations
    than plain CG from the same guess."""
    rng = np.random.default_rng(2)
    A, W, energies = _near_slow_modes(rng)
    deflation = Deflation(np.ascontiguousarray(W.T), np.ascontiguousarray((A @ W).T), energies)
    b = rng.standard_normal(len(A))
    x0 = W @ (W.T @ b / energies)
    solution = np.linalg.solve(A, b)
    searched: dict = {"plain": [], "deflated": []}

    def solve(key, **options):
        def apply(p):
            searched[key].append(p.copy())
            return A @ p
        return conjugate_gradient(apply, b, x0=x0, preconditioner=(1.0 / A.diagonal()).__mul__, rtol=1e-8,
                                  maxiter=2000, **options)

    plain, deflated = solve("plain"), solve("deflated", deflation=deflation)
    for x, *_ in (plain, deflated):  # rtol 1e-8 on the residual; the condition number 3.8e4 leaves 1e-8 * 3.8e4
        assert np.abs(x - solution).max() <= 4e-4 * np.abs(solution).max()

    def largest_cosine(key):  # |cos| between the directions' products A p and W's columns
        products = A @ np.array(searched[key][1:]).T  # the first product is CG's first residual's
        return (np.abs(W.T @ products) / np.linalg.norm(W, axis=0)[:, None] / np.linalg.norm(products, axis=0)).max()

    # Measured 5e-16 over 123 directions (rounding; each direction is projected afresh) against 0.013 for plain CG.
    assert largest_cosine("deflated") <= 1e-12 < 1e-3 <= largest_cosine("plain")
    # Measured 123 against 207 iterations (0.59): 0.75 leaves room for rounding yet fails if W is not deflated.
    assert deflated[1] <= 0.75 * plain[1], (deflated[1], plain[1])


def test_deflation_that_rounding_has_spoiled_still_converges_to_the_answer():
    """Rounding leaves the step's (A W)^T and W^T r0 off by much more than 1e-16 when A is stiff and W soft (a hair
    strand: 1e-7 and 3e-6, measured). The deflation's preconditioner corrects the residual's part along W (Q r)
    instead of leaving it, so CG still reaches rtol, in about as many iterations as without the deflation."""
    rng = np.random.default_rng(3)
    A, W, energies = _near_slow_modes(rng)
    spoiled = (A @ W) * (1.0 + 1e-5 * rng.standard_normal(W.shape))  # (A W) off by 1e-5: worse than measured
    deflation = Deflation(np.ascontiguousarray(W.T), np.ascontiguousarray(spoiled.T), energies)
    b = rng.standard_normal(len(A))
    x0 = W @ (W.T @ b / energies) + 1e-3 * rng.standard_normal(len(A))  # W^T r0 far from 0
    inverse = (1.0 / A.diagonal()).__mul__
    plain = conjugate_gradient(lambda p: A @ p, b, x0=x0, preconditioner=inverse, rtol=1e-8, maxiter=2000)
    deflated = conjugate_gradient(lambda p: A @ p, b, x0=x0, preconditioner=inverse, rtol=1e-8, maxiter=2000,
                                  deflation=deflation)
    # The true residual, not CG's recursive one, within 10x rtol (the recursion drifts by rounding; measured 8.8e-9).
    # Deflated CG without the correction (z - W E^-1 (A W)^T z) breaks down here (r . z reaches 0: a division by 0).
    assert np.linalg.norm(b - A @ deflated[0]) <= 1e-7 * np.linalg.norm(b)
    # Measured 198 against 216: the spoiled deflation still pays a little, and must not cost iterations.
    assert deflated[1] <= plain[1], (deflated[1], plain[1])


def test_the_three_methods_agree(system, rhs):
    matrix, modes, _ = system
    exact = sp.linalg.spsolve(matrix.tocsc(), rhs)
    for method in ("direct", "amg", "jacobi"):
        solver = make_linear_solver(method, **({} if method == "direct" else {"rtol": 1e-10, "maxiter": 5000}))
        x, info = solver.solve(matrix, rhs, **({"near_null_space": modes} if method == "amg" else {}))
        assert info.method == method and info.converged
        # The matrix is well conditioned (eigenvalues in [1, 2.5e3]): a 1e-10 residual is an error below
        # 1e-10 * cond = 2.5e-7 of |x|; LU is at round-off.
        np.testing.assert_allclose(x, exact, atol=1e-6 * np.abs(exact).max())


def test_amg_needs_far_fewer_iterations_than_jacobi(system, rhs):
    matrix, modes, _ = system
    amg = AMGConjugateGradient(rtol=1e-6).solve(matrix, rhs, near_null_space=modes)[1]
    jacobi = JacobiConjugateGradient(rtol=1e-6, maxiter=5000).solve(matrix, rhs)[1]
    # Measured 10 against 150 at h omega = 50; a factor of 5 fails a regression to a broken hierarchy.
    assert 0 < 5 * amg.iterations < jacobi.iterations


class _Ticks:
    """A timer that advances one second per call: every *_seconds figure must come from it."""

    def __init__(self):
        self.calls = 0

    def __call__(self):
        self.calls += 1
        return float(self.calls)


@pytest.mark.parametrize("method", ["direct", "amg", "jacobi"])
def test_every_seconds_figure_comes_from_the_solver_timer(monkeypatch, system, rhs, method):
    matrix, modes, _ = system
    assert not hasattr(solvers, "clock")  # no module-level timer to reassign: each solver has its own
    timer = _Ticks()
    solver = make_linear_solver(method, timer=timer)
    assert solver.timer is timer
    _, info = solver.solve(matrix, rhs, **({"near_null_space": modes} if method == "amg" else {}))
    assert timer.calls >= 3
    # Whole numbers of ticks: nothing timed by another clock slipped in.
    for seconds in (info.setup_seconds, info.solve_seconds):
        assert seconds >= 0 and seconds == int(seconds)
    assert info.setup_seconds >= 1 and info.solve_seconds >= 1


def test_default_timer_is_perf_counter_and_a_bad_timer_is_refused():
    assert AMGConjugateGradient().timer is time.perf_counter
    assert DirectSolver().timer is time.perf_counter
    with pytest.raises(TypeError, match="timer = 1.0 is not callable"):
        JacobiConjugateGradient(timer=1.0)


@pytest.mark.parametrize("method", ["direct", "amg", "amg:block_gauss_seidel", "jacobi"])
def test_solver_round_trips_through_pickle_and_solves_to_the_same_answer(system, rhs, method):
    matrix, modes, _ = system
    method, _, smoother = method.partition(":")
    options = {} if method == "direct" else {"rtol": 1e-8, "timer": time.process_time}
    solver = make_linear_solver(method, **options, **({"smoother": smoother} if smoother else {}))
    extra = {"near_null_space": modes} if method == "amg" else {}
    before, info_before = solver.solve(matrix, rhs, **extra)
    copy = pickle.loads(pickle.dumps(solver))
    assert type(copy) is type(solver) and copy.rtol == solver.rtol and copy.timer is solver.timer
    if method == "amg":
        # The pyamg hierarchy does not pickle (closures): dropped, then put together again on the next solve.
        assert copy.hierarchy is None and solver.hierarchy is not None
    after, info_after = copy.solve(matrix, rhs)  # no near_null_space: nothing is built from scratch
    assert after.tobytes() == before.tobytes()  # the same hierarchy again: the same bits, not just close
    assert info_after.iterations == info_before.iterations
    if method == "amg":
        # The default's levels travel in the pickle (its finest level is kept rounded to single precision, so the
        # matrix they were built from is gone); with another smoother the hierarchy is rebuilt from the kept matrix.
        rebuilt = smoother != ""
        assert info_after.rebuilt == rebuilt and copy.build_count == solver.build_count + rebuilt
        assert len(copy.hierarchy.levels) == len(solver.hierarchy.levels)
        # A restriction held as a view of its prolongator is one again (not a second copy from the pickle).
        assert amg._transposed(copy.hierarchy.levels[0]) == amg._transposed(solver.hierarchy.levels[0]) != rebuilt
        # A second pickle of the unpickled solver, and one of a solver never built, work too.
        assert pickle.loads(pickle.dumps(copy)).solve(matrix, rhs)[0].tobytes() == before.tobytes()
        assert pickle.loads(pickle.dumps(AMGConjugateGradient())).hierarchy is None
        # And one pickled again before its first use (the levels still waiting to be put together).
        twice = pickle.loads(pickle.dumps(pickle.loads(pickle.dumps(solver))))
        assert twice.solve(matrix, rhs)[0].tobytes() == before.tobytes()


def test_unbuilt_amg_refuses_to_precondition_or_solve_without_modes(system, rhs):
    matrix, modes, _ = system
    solver = AMGConjugateGradient()
    with pytest.raises(ValueError, match="not built"):
        solver.precondition(rhs)
    with pytest.raises(ValueError, match="near_null_space"):
        solver.solve(matrix, rhs)
    with pytest.raises(ValueError, match=r"near_null_space has shape \(5, 6\), expected \(2700, k\)"):
        solver.build(matrix, modes[:5])


def test_two_level_cycle_on_a_galerkin_coarse_space(system, rhs):
    """prolongation P: AMG on P^T A P, Gauss-Seidel on A around it; CG still converges to the answer."""
    matrix, _, points = system
    # Coarse space: every other node along x, interpolated linearly in x (a 1D geometric P per component).
    xs = np.unique(points[:, 0])
    coarse_x = xs[::2]
    keys = np.round(points[:, 1:] * 1e6).astype(np.int64)
    _, line = np.unique(keys, axis=0, return_inverse=True)
    line = line.ravel()
    coarse_points = np.array([[x, *points[line == k][0, 1:]] for k in range(line.max() + 1) for x in coarse_x])
    coarse_index = {(k, i): k * len(coarse_x) + i for k in range(line.max() + 1) for i in range(len(coarse_x))}
    rows, cols, vals = [], [], []
    for node, (x, k) in enumerate(zip(points[:, 0], line)):
        i = min(np.searchsorted(coarse_x, x, side="right") - 1, len(coarse_x) - 2)
        t = (x - coarse_x[i]) / (coarse_x[i + 1] - coarse_x[i])
        for j, w in ((i, 1 - t), (i + 1, t)):
            if w:
                for c in range(3):
                    rows.append(3 * node + c), cols.append(3 * coarse_index[k, j] + c), vals.append(w)
    prolongation = sp.csr_matrix((vals, (rows, cols)), shape=(matrix.shape[0], 3 * len(coarse_points)))
    solver = AMGConjugateGradient(rtol=1e-8, maxiter=300)
    x, info = solver.solve(matrix, rhs, near_null_space=rigid_body_modes(coarse_points), prolongation=prolongation)
    exact = sp.linalg.spsolve(matrix.tocsc(), rhs)
    np.testing.assert_allclose(x, exact, atol=1e-5 * np.abs(exact).max())  # 1e-8 residual x cond 2.5e3, with margin
    assert solver.hierarchy.levels[0].A.shape == (prolongation.shape[1],) * 2
    # The preconditioner is symmetric (forward sweep, coarse correction, backward sweep), as CG needs.
    u, v = np.random.default_rng(1).standard_normal((2, matrix.shape[0]))
    assert np.dot(u, solver.precondition(v)) == pytest.approx(np.dot(v, solver.precondition(u)), rel=1e-10)
    # And it pickles like the plain one.
    assert pickle.loads(pickle.dumps(solver)).solve(matrix, rhs)[0].tobytes() == x.tobytes()
    with pytest.raises(ValueError, match="prolongation has shape"):
        AMGConjugateGradient().build(matrix, rigid_body_modes(coarse_points), prolongation=prolongation[:10])


def test_a_solve_that_stops_short_raises_or_warns_with_the_residual(system, rhs):
    matrix, modes, _ = system
    with pytest.raises(SolverNotConverged, match=r"stopped after 2 iterations at relative residual [0-9.e-]+"):
        AMGConjugateGradient(rtol=1e-12, maxiter=2).solve(matrix, rhs, near_null_space=modes)
    with pytest.warns(RuntimeWarning, match="stopped after 2 iterations"):
        x, info = JacobiConjugateGradient(rtol=1e-12, maxiter=2, on_failure="warn").solve(matrix, rhs)
    assert not info.converged and info.residual > 1e-12


def test_implicit_integrator_with_a_built_hierarchy_pickles_and_continues_bit_for_bit():
    """What the solver's pickling is for: an integrator (with its scene and state) sent to a worker."""
    from volspring import Gravity, Material, Model, Pins, Scene
    from volspring.integrators.implicit import ImplicitEuler

    model = Model.from_mesh(cube_mesh((12, 3, 3), (1.0, 0.2, 0.2)), Material(1e6, 0.45, 1100.0))
    scene = Scene(model, forces=[Gravity()], pins=Pins(np.flatnonzero(model.rest_positions[:, 0] < 1e-9)))
    integrator = ImplicitEuler()
    state = scene.initial_state()
    for _ in range(2):
        state = integrator.step(scene, state, 0.01)
    assert integrator.solver.hierarchy is not None
    scene_copy, integrator_copy, state_copy = pickle.loads(pickle.dumps((scene, integrator, state)))
    for _ in range(2):
        state = integrator.step(scene, state, 0.01)
        state_copy = integrator_copy.step(scene_copy, state_copy, 0.01)
    assert state.x.tobytes() == state_copy.x.tobytes() and state.v.tobytes() == state_copy.v.tobytes()
