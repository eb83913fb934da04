"""Linear solvers for the symmetric positive definite systems of the implicit step and statics.

Three methods share one interface, ``solver.solve(matrix, rhs, x0=..., extra=...) -> (x, info)``:

``"amg"``
    Conjugate gradients preconditioned with one V-cycle of pyamg smoothed aggregation built on
    the 3x3 block (BSR) matrix with the six rigid-body modes as near-null space ``B``
    (REFERENCE.md section 3: 4 / 10 / 14 / 14 iterations at 1 / 10 / 100 / 1000 times the
    explicit limit, against 48 / 205 / 533 / 609 unpreconditioned). The hierarchy is built by
    :meth:`AMGConjugateGradient.build` and reused for later matrices of the same pattern: it then
    preconditions a nearby matrix, which only costs iterations, never accuracy, because CG
    iterates on the current matrix. When to rebuild is the caller's policy (see
    :class:`volspring.integrators.implicit.ImplicitEuler`).
``"jacobi"``
    Conjugate gradients preconditioned with the inverse diagonal, for comparison.
``"direct"``
    Sparse LU (``scipy.sparse.linalg.splu``), for small systems and for checking.

``extra`` is an optional additional sparse term (e.g. a contact or field Jacobian) applied in
every CG product but left out of the AMG hierarchy.

CG stops when ||b - A x|| <= rtol ||b|| (the recursively updated residual; the criterion of
``pyamg.krylov.cg(criteria="rr")`` and of ``scipy.sparse.linalg.cg(rtol=...)``). A solve that
stops short raises :class:`volspring.errors.SolverNotConverged` naming the residual reached, or
warns with it (``on_failure="warn"``); it never returns a wrong answer silently.
"""

from __future__ import annotations

import logging
import time
import warnings
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as sla

from volspring.errors import SolverNotConverged

__all__ = ["SolveInfo", "conjugate_gradient", "DirectSolver", "JacobiConjugateGradient",
           "AMGConjugateGradient", "LINEAR_SOLVERS", "make_linear_solver"]

logger = logging.getLogger(__name__)

LINEAR_SOLVERS = ("amg", "jacobi", "direct")

#: The timer behind every ``*_seconds`` figure of :class:`SolveInfo` and of the implicit step's
#: record. Wall time by default; a benchmark on a shared machine may set ``time.process_time``.
clock = time.perf_counter

#: Weight of the Jacobi prolongation smoother under row-wise Gershgorin weights (see
#: :class:`AMGConjugateGradient`: why not pyamg's random-start spectral radius, and the measurements).
PROLONGATION_OMEGA = 2.0
#: Weight of the block Jacobi smoother, divided by a Gershgorin bound of D^-1 A on each level.
BLOCK_JACOBI_OMEGA = 2.0 / 3.0


@dataclass(frozen=True)
class SolveInfo:
    """What one linear solve did.

    Parameters
    ----------
    method : str -- "amg", "jacobi" or "direct"
    iterations : int -- CG iterations (0 for the direct solver)
    residual : float -- relative residual ||b - A x|| / ||b|| reached [-]
    converged : bool -- whether ``residual <= rtol``
    rtol : float -- the tolerance asked for [-]
    initial_residual : float -- relative residual of the starting guess [-]
    setup_seconds : float -- time spent building the preconditioner or factorisation in this solve [s]
    solve_seconds : float -- time spent iterating (or in the triangular solves) [s]
    rebuilt : bool -- whether the AMG hierarchy was (re)built for this solve
    """

    method: str
    iterations: int
    residual: float
    converged: bool
    rtol: float
    initial_residual: float = np.nan
    setup_seconds: float = 0.0
    solve_seconds: float = 0.0
    rebuilt: bool = False


def conjugate_gradient(apply, b, *, x0=None, preconditioner=None, rtol=1e-3, maxiter=200):
    """Preconditioned conjugate gradients for an SPD operator.

    Parameters
    ----------
    apply : callable -- ``apply(p) -> A p`` for (N,) float vectors
    b : (N,) float -- right-hand side
    x0 : (N,) float, optional -- starting guess (warm start); zeros when omitted
    preconditioner : callable, optional -- ``preconditioner(r) -> z`` approximating A^-1 r (SPD)
    rtol : float -- stop when ||r|| <= rtol ||b||
    maxiter : int -- at most this many iterations (one product with A each)

    Returns
    -------
    x : (N,) float
    iterations : int
    residual : float -- ||r|| / ||b|| at exit (recursive residual; 0 when b = 0)
    initial_residual : float -- ||b - A x0|| / ||b||

    Examples
    --------
    >>> import numpy as np
    >>> A = np.array([[4.0, 1.0], [1.0, 3.0]])
    >>> x, iterations, residual, _ = conjugate_gradient(lambda p: A @ p, np.array([1.0, 2.0]), rtol=1e-12)
    >>> bool(np.allclose(A @ x, [1.0, 2.0])), iterations
    (True, 2)
    """
    b = np.asarray(b, dtype=np.float64)
    norm_b = float(np.linalg.norm(b))
    if norm_b == 0.0:
        return np.zeros_like(b), 0, 0.0, 0.0
    if x0 is None:
        x = np.zeros_like(b)
        r = b.copy()
    else:
        x = np.array(x0, dtype=np.float64)
        r = b - apply(x)
    norm_r = float(np.linalg.norm(r))
    initial = norm_r / norm_b
    target = rtol * norm_b
    iterations = 0
    if norm_r <= target:
        return x, 0, initial, initial
    z = preconditioner(r) if preconditioner is not None else r.copy()
    p = z.copy()
    rz = float(np.dot(r, z))
    while iterations < maxiter:
        q = apply(p)
        curvature = float(np.dot(p, q))
        if not curvature > 0.0:
            raise SolverNotConverged(f"CG met non-positive curvature p.Ap = {curvature:.3g} at iteration "
                                     f"{iterations} (relative residual {norm_r / norm_b:.3g}): the matrix is "
                                     "not positive definite")
        alpha = rz / curvature
        x += alpha * p
        r -= alpha * q
        iterations += 1
        norm_r = float(np.linalg.norm(r))
        if norm_r <= target:
            break
        z = preconditioner(r) if preconditioner is not None else r
        rz_new = float(np.dot(r, z))
        p *= rz_new / rz
        p += z
        rz = rz_new
    return x, iterations, norm_r / norm_b, initial


def _operator(matrix, extra):
    if extra is None:
        return matrix.__matmul__
    return lambda p: matrix @ p + extra @ p


class _LinearSolver:
    """Shared options: tolerance, iteration cap, what to do when a solve stops short."""

    method = ""

    def __init__(self, *, rtol=1e-3, maxiter=500, on_failure="raise"):
        if not (np.isfinite(rtol) and 0 < rtol < 1):
            raise ValueError(f"rtol = {rtol!r} is not in (0, 1)")
        if int(maxiter) < 1:
            raise ValueError(f"maxiter = {maxiter!r} is not >= 1")
        if on_failure not in ("raise", "warn"):
            raise ValueError(f"on_failure = {on_failure!r}, expected 'raise' or 'warn'")
        self.rtol, self.maxiter, self.on_failure = float(rtol), int(maxiter), on_failure

    def _finish(self, x, info):
        if not np.isfinite(x).all():
            raise SolverNotConverged(f"{self.method} solve produced non-finite values "
                                     f"(relative residual {info.residual:.3g})")
        if not info.converged:
            message = (f"{self.method} solve stopped after {info.iterations} iterations at relative residual "
                       f"{info.residual:.3g}, expected <= rtol = {info.rtol:.3g}")
            if self.on_failure == "raise":
                raise SolverNotConverged(message)
            warnings.warn(message, RuntimeWarning, stacklevel=3)
            logger.warning(message)
        return x, info

    def solve(self, matrix, rhs, *, x0=None, extra=None):  # pragma: no cover - interface
        raise NotImplementedError


class DirectSolver(_LinearSolver):
    """Sparse LU factorisation of ``matrix + extra`` (``scipy.sparse.linalg.splu``).

    Its answer is checked: the relative residual must be below ``rtol`` (default 1e-8, far above
    round-off for the well conditioned implicit systems, far below any iterative tolerance).
    """

    method = "direct"

    def __init__(self, *, rtol=1e-8, on_failure="raise"):
        super().__init__(rtol=rtol, maxiter=1, on_failure=on_failure)

    def solve(self, matrix, rhs, *, x0=None, extra=None):
        start = clock()
        full = matrix.tocsc() if extra is None else (matrix + extra).tocsc()
        try:
            lu = sla.splu(full)
        except RuntimeError as error:
            raise SolverNotConverged(f"direct solve failed: {error} (the matrix is singular)") from error
        setup = clock() - start
        x = lu.solve(rhs)
        norm_b = float(np.linalg.norm(rhs)) or 1.0
        residual = float(np.linalg.norm(rhs - full @ x)) / norm_b
        info = SolveInfo("direct", 0, residual, bool(residual <= self.rtol), self.rtol, 1.0,
                         setup, clock() - start - setup)
        return self._finish(x, info)


class JacobiConjugateGradient(_LinearSolver):
    """CG preconditioned with the inverse of the diagonal of ``matrix + extra``."""

    method = "jacobi"

    def solve(self, matrix, rhs, *, x0=None, extra=None):
        start = clock()
        diagonal = matrix.diagonal() if extra is None else matrix.diagonal() + extra.diagonal()
        if not (diagonal > 0).all():
            raise SolverNotConverged(f"Jacobi-CG needs a positive diagonal, found {diagonal.min():.3g}")
        inverse = 1.0 / diagonal
        setup = clock() - start
        x, iterations, residual, initial = conjugate_gradient(
            _operator(matrix, extra), rhs, x0=x0, preconditioner=inverse.__mul__, rtol=self.rtol,
            maxiter=self.maxiter)
        info = SolveInfo("jacobi", iterations, residual, bool(residual <= self.rtol), self.rtol, initial,
                         setup, clock() - start - setup)
        return self._finish(x, info)


class AMGConjugateGradient(_LinearSolver):
    """CG preconditioned with one smoothed-aggregation V-cycle on the BSR matrix.

    Parameters
    ----------
    rtol : float -- relative residual target
    maxiter : int -- CG iteration cap
    on_failure : {"raise", "warn"}
    smoother : {"gauss_seidel", "jacobi"} -- block Gauss-Seidel (forward before, backward after
        the coarse correction, so the V-cycle stays symmetric) or block Jacobi. Measured on a
        10k-node beam: block Jacobi needs twice the iterations; Chebyshev (degree 3, in A) saved
        one iteration in five at 10k but nothing at 50k, and unlike Gauss-Seidel it is not
        invariant to the diagonal scaling that large mass ratios bring, so it is not offered.
    max_coarse : int -- unknowns on the coarsest level (solved with a pseudo-inverse)
    strength_theta : float -- couplings weaker than theta (symmetric strength measure) are
        dropped when aggregating; 0.05 cut CG iterations from 6 to 5 (rtol 1e-3) and 11 to 9
        (rtol 1e-6) on a 50k-node gmsh beam at h omega_max = 50, for 10 % more work per cycle;
        a hierarchy with operator complexity above 2.5 is rebuilt with theta = 0

    The coarsest level (about a thousand unknowns at 50k nodes) is factorised with sparse LU:
    the default pseudo-inverse spent 1.3 s of a 3.9 s setup in a dense SVD, for the same cycle.
    The candidates B are used as given (``improve_candidates=None``): rigid-body modes are
    already the near-null space, and relaxing them first doubled the setup time for the same
    iteration counts (measured on 10k and 50k-node beams).

    The hierarchy is built from an explicit :meth:`build` call (or the first solve) and kept;
    it is a frozen copy, so later refills of the matrix do not disturb it.

    Reproducibility: the build draws no random numbers, so the same matrix gives the same
    hierarchy bit for bit and the caller's global random state is never touched. pyamg's default
    prolongation smoother scales by a spectral radius estimated by Lanczos from a start vector
    drawn from numpy's *global* generator, which made runs above about 800 nodes differ (3e-8 m at
    802 nodes) and a resumed run differ from an uninterrupted one. Here the prolongator is smoothed
    with row-wise Gershgorin weights instead (``weighting="local"``, no estimate at all), with
    omega = :data:`PROLONGATION_OMEGA` = 2: Gershgorin bounds exceed the spectral radius 1.5 to 1.8
    times on these matrices (REFERENCE.md section 3), so 2 under the bound is about pyamg's 4/3
    under the true radius. Measured on 10k and 50k-node gmsh beams (nu 0.25 and 0.45, dt 1e-3, 1e-2,
    1e-1 s): the same CG iteration counts as the random default in 10 of 12 systems at rtol 1e-3
    (one more in 2), within one at rtol 1e-6; with omega = 4/3 it took up to 2 more at rtol 1e-3
    and 4 more at 1e-6 (``python benchmarks/bench_amg_weighting.py``).
    The block Jacobi smoother is weighted by a Gershgorin bound of D^-1 A per level for the same
    reason (pyamg would estimate its spectral radius from a random vector too).
    """

    method = "amg"

    def __init__(self, *, rtol=1e-3, maxiter=500, on_failure="raise", smoother="gauss_seidel",
                 max_coarse=300, strength_theta=0.05):
        super().__init__(rtol=rtol, maxiter=maxiter, on_failure=on_failure)
        if smoother not in ("gauss_seidel", "jacobi"):
            raise ValueError(f"smoother = {smoother!r}, expected 'gauss_seidel' or 'jacobi'")
        self.smoother, self.max_coarse = smoother, int(max_coarse)
        self.strength_theta = float(strength_theta)
        self.hierarchy = None
        self.build_count = 0

    def build(self, matrix, near_null_space) -> float:
        """Build the hierarchy for ``matrix`` (BSR, block size 3); returns the seconds it took.

        Parameters
        ----------
        matrix : (N, N) sparse -- SPD, best as BSR with block size 3
        near_null_space : (N, 6) float -- rigid-body modes of the unknowns (``rigid_body_modes``)
        """
        import pyamg

        start = clock()
        frozen = matrix.copy()
        # Gauss-Seidel first in every case: it draws nothing at set-up (see the class docstring);
        # block Jacobi gets its deterministic weights once the levels exist.
        gauss_seidel = ("block_gauss_seidel", {"sweep": "forward"}), ("block_gauss_seidel", {"sweep": "backward"})
        options = dict(B=np.ascontiguousarray(near_null_space), symmetry="hermitian",
                       presmoother=gauss_seidel[0], postsmoother=gauss_seidel[1],
                       smooth=("jacobi", {"omega": PROLONGATION_OMEGA, "weighting": "local"}),
                       max_coarse=self.max_coarse, improve_candidates=None, coarse_solver="splu")
        self.hierarchy = pyamg.smoothed_aggregation_solver(
            frozen, strength=("symmetric", {"theta": self.strength_theta}), **options)
        if self.strength_theta and self.hierarchy.operator_complexity() > 2.5:
            # Dropping weak couplings can slow coarsening on odd meshes: fall back to keeping all.
            self.hierarchy = pyamg.smoothed_aggregation_solver(frozen, strength="symmetric", **options)
        if self.smoother != "gauss_seidel":
            from pyamg.relaxation.smoothing import change_smoothers

            weighted = [("block_jacobi", {"omega": BLOCK_JACOBI_OMEGA / _block_jacobi_bound(level.A),
                                          "iterations": 1, "withrho": False})
                        for level in self.hierarchy.levels[:-1]]
            change_smoothers(self.hierarchy, weighted, weighted)
        try:
            self.precondition(np.zeros(matrix.shape[0]))  # the coarse solver sets up lazily: count it here
        except RuntimeError:  # a singular coarsest matrix (statics of a barely held body): pseudo-inverse
            from pyamg.multilevel import coarse_grid_solver

            self.hierarchy.coarse_solver = coarse_grid_solver("pinv")
            self.precondition(np.zeros(matrix.shape[0]))
        self.build_count += 1
        seconds = clock() - start
        logger.debug("built AMG hierarchy: %s levels, operator complexity %.2f, %.3f s",
                     len(self.hierarchy.levels), self.hierarchy.operator_complexity(), seconds)
        return seconds

    def precondition(self, r) -> np.ndarray:
        """One V-cycle from a zero guess: z ~ A^-1 r (an SPD operator for CG)."""
        ml = self.hierarchy
        if len(ml.levels) == 1:
            return ml.coarse_solver(ml.levels[0].A, r)
        z = np.zeros_like(r)
        # The private recursive cycle: ml.solve(maxiter=1) would add two residual norms,
        # i.e. two extra fine-level products, per application.
        ml._MultilevelSolver__solve(0, z, r, "V")
        return z

    def solve(self, matrix, rhs, *, x0=None, extra=None, near_null_space=None):
        setup = 0.0
        rebuilt = self.hierarchy is None or self.hierarchy.levels[0].A.shape != matrix.shape
        if rebuilt:
            if near_null_space is None:
                raise ValueError("the first AMG solve needs near_null_space (rigid-body modes)")
            setup = self.build(matrix, near_null_space)
        start = clock()
        x, iterations, residual, initial = conjugate_gradient(
            _operator(matrix, extra), rhs, x0=x0, preconditioner=self.precondition, rtol=self.rtol,
            maxiter=self.maxiter)
        info = SolveInfo("amg", iterations, residual, bool(residual <= self.rtol), self.rtol, initial,
                         setup, clock() - start, rebuilt)
        return self._finish(x, info)


def _block_jacobi_bound(matrix) -> float:
    """max_i sum_j |(D^-1 A)_ij| with D the block diagonal of a BSR ``matrix``: a deterministic
    upper bound of the spectral radius of D^-1 A (Gershgorin), never below it."""
    from pyamg.util.utils import get_block_diag

    matrix = sp.bsr_matrix(matrix)
    size = matrix.blocksize[0]
    inverse = get_block_diag(matrix, blocksize=size, inv_flag=True)
    blocks = np.arange(len(inverse))
    diagonal = sp.bsr_matrix((inverse, blocks, np.arange(len(inverse) + 1)), shape=matrix.shape)
    scaled = (diagonal @ matrix).tocsr()
    return float(abs(scaled).sum(axis=1).max())


def make_linear_solver(method, **options):
    """A solver by name: ``"amg"``, ``"jacobi"`` or ``"direct"`` (options passed on)."""
    kinds = {"amg": AMGConjugateGradient, "jacobi": JacobiConjugateGradient, "direct": DirectSolver}
    if method not in kinds:
        raise ValueError(f"unknown linear solver {method!r}; known: {', '.join(LINEAR_SOLVERS)}")
    return kinds[method](**options)
