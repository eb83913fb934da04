"""Conjugate gradients, the direct and Jacobi-CG solvers, and what every solve reports (:class:`SolveInfo`)."""

from __future__ import annotations

import logging
import time
import warnings
from dataclasses import dataclass

import numpy as np
import scipy.sparse.linalg as sla

from volspring.errors import SolverNotConverged
from volspring.kernels import compiled, unsigned
from typing import TYPE_CHECKING, Any
from collections.abc import Callable

if TYPE_CHECKING:
    from numpy.typing import ArrayLike
    from scipy import sparse

__all__ = ["SolveInfo", "Deflation", "conjugate_gradient", "DirectSolver", "JacobiConjugateGradient", "LINEAR_SOLVERS",
           "times"]

logger = logging.getLogger(__name__)

LINEAR_SOLVERS = ("amg", "jacobi", "direct")


@dataclass(frozen=True)
class SolveInfo:
    """What one linear solve did.

    Parameters
    ----------
    method : str
        ``"amg"``, ``"jacobi"`` or ``"direct"``.
    iterations : int
        CG iterations (0 for the direct solver).
    residual : float
        Relative residual ||b - A x|| / ||b|| reached [-].
    converged : bool
        Whether ``residual <= rtol``.
    rtol : float
        The tolerance asked for [-].
    initial_residual : float
        Relative residual of the starting guess [-].
    setup_seconds : float
        Time spent building the preconditioner or factorisation in this solve [s].
    solve_seconds : float
        Time spent iterating (or in the triangular solves) [s].
    rebuilt : bool
        Whether the AMG hierarchy was (re)built for this solve.
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


@dataclass(frozen=True, eq=False)
class Deflation:
    """A subspace W whose directions CG need not search again: the first guess settled them (deflation).

    CG is then preconditioned by P^T M^-1 + Q instead of M^-1, with Q = W E^-1 W^T, P = I - A Q and E = W^T A W:
    the "A-DEF2" two-level preconditioner of Tang, Nabben, Vuik and Erlangga (2009, J. Sci. Comput. 39). From a
    guess that leaves W^T r0 = 0 (the Galerkin projection onto W, as the implicit step's guess from its previous
    velocity changes is) it is deflated CG (Saad, Yeung, Erhel and Guyomarc'h 2000): every search direction is
    A-orthogonal to W. Unlike deflated CG it also corrects what rounding leaves of the residual along W, which deflated
    CG can never reduce: on a very stiff hair strand that made deflated CG diverge. It costs three products with a
    (k, N) array an iteration.

    Attributes
    ----------
    vectors : (k, N) float
        W^T, one direction a row
    products : (k, N) float
        (A W)^T
    energies : (k,) float
        W^T A W, which must be diagonal: > 0
    """

    vectors: np.ndarray
    products: np.ndarray
    energies: np.ndarray

    def corrected(self, z: np.ndarray, r: np.ndarray) -> np.ndarray:
        """(P^T M^-1 + Q) r from z = M^-1 r: z - W E^-1 ((A W)^T z - W^T r)."""
        return z - ((self.products @ z - self.vectors @ r) / self.energies) @ self.vectors


def conjugate_gradient(apply: Callable[..., Any], b: ArrayLike, *, x0: ArrayLike | None = None,
                       preconditioner: Callable[..., Any] | None = None, rtol: float = 1e-3,
                       maxiter: int = 200, r0: ArrayLike | None = None,
                       deflation: Deflation | None = None) -> tuple[np.ndarray, int, float, float]:
    """Preconditioned conjugate gradients for an SPD operator.

    Parameters
    ----------
    apply : callable
        ``apply(p) -> A p`` for (N,) float vectors.
    b : (N,) float
        Right-hand side.
    x0 : (N,) float, optional
        Starting guess (warm start); zeros when omitted.
    preconditioner : callable, optional
        ``preconditioner(r) -> z`` approximating A^-1 r (SPD).
    rtol : float
        Stop when ||r|| <= rtol ||b||.
    maxiter : int
        At most this many iterations (one product with A each).
    r0 : (N,) float, optional
        b - A x0, when the caller has it already (one product fewer); used only with ``x0``, and trusted.
    deflation : Deflation, optional
        precondition with its W taken out (see :class:`Deflation`); ``x0`` should leave W^T r0 = 0 (the Galerkin
        projection of the solution onto W): then every search direction is A-orthogonal to W

    Returns
    -------
    x : (N,) float
    iterations : int
    residual : float
        ||r|| / ||b|| at exit (recursive residual; 0 when b = 0).
    initial_residual : float
        ||b - A x0|| / ||b||.

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
        r = b - apply(x) if r0 is None else np.array(r0, dtype=np.float64)
    norm_r = float(np.linalg.norm(r))
    initial = norm_r / norm_b
    target = rtol * norm_b
    iterations = 0
    if norm_r <= target:
        return x, 0, initial, initial

    def precondition(r):  # z = M^-1 r, or (P^T M^-1 + Q) r with the deflation
        z = preconditioner(r) if preconditioner is not None else r
        return z if deflation is None else deflation.corrected(z, r)

    z = precondition(r)
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
        z = precondition(r)
        rz_new = float(np.dot(r, z))
        p *= rz_new / rz
        p += z
        rz = rz_new
    return x, iterations, norm_r / norm_b, initial


def times(matrix: sparse.spmatrix, vectors: np.ndarray) -> np.ndarray:
    """``matrix @ vectors`` for (N,) or (N, k) float ``vectors``; a float64 BSR matrix of 3 x 3 blocks (the implicit
    step's system) by the compiled kernel where it runs (:mod:`volspring.kernels`), with scipy's result bit for bit.
    scipy's block product runs loops of run-time length over each block and carries one row's sum at a time; the
    kernel's loops are unrolled and carry a block row's three sums at once, and it reads each block once for all k
    vectors, which it takes as the rows of a (k, N) array (CG's guess keeps its past changes so: ``vectors`` is then
    their transpose, and no copy is made). One vector costs 0.50, 0.50 and 0.69 of scipy's product, five 1.75-1.89
    against scipy's 4.3-4.8 mat-vecs, at 1k, 10k and 50k nodes (``python benchmarks/bench_implicit.py``, which
    prints both)."""
    kernels = compiled()
    if kernels is None or matrix.format != "bsr" or matrix.blocksize != (3, 3) or matrix.dtype != np.float64 or \
            vectors.dtype != np.float64 or vectors.ndim not in (1, 2) or vectors.shape[0] != matrix.shape[1]:
        return matrix @ vectors
    rows = np.ascontiguousarray(vectors.reshape(1, -1) if vectors.ndim == 1 else vectors.T)
    out = np.zeros((rows.shape[0], matrix.shape[0]))
    kernels.block_times(unsigned(matrix.indptr), unsigned(matrix.indices), matrix.data, rows, out)
    # In scipy's layout, C-ordered (N, k): BLAS sums a product with an F-ordered array in another order.
    return out[0] if vectors.ndim == 1 else np.ascontiguousarray(out.T)


def _operator(matrix, extra):
    if extra is None:
        return lambda p: times(matrix, p)
    return lambda p: times(matrix, p) + extra @ p


class _LinearSolver:
    """Shared options: tolerance, iteration cap, what to do when a solve stops short, the timer."""

    method = ""

    def __init__(self, *, rtol: float = 1e-3, maxiter: int = 500, on_failure: str = "raise",
                 timer: Callable[[], float] = time.perf_counter):
        if not (np.isfinite(rtol) and 0 < rtol < 1):
            raise ValueError(f"rtol = {rtol!r} is not in (0, 1)")
        if int(maxiter) < 1:
            raise ValueError(f"maxiter = {maxiter!r} is not >= 1")
        if on_failure not in ("raise", "warn"):
            raise ValueError(f"on_failure = {on_failure!r}, expected 'raise' or 'warn'")
        if not callable(timer):
            raise TypeError(f"timer = {timer!r} is not callable (expected e.g. time.perf_counter)")
        self.rtol, self.maxiter, self.on_failure = float(rtol), int(maxiter), on_failure
        self.timer = timer

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

    def solve(self, matrix, rhs, *, x0=None, extra=None, r0=None, deflation=None):  # pragma: no cover - interface
        raise NotImplementedError


class DirectSolver(_LinearSolver):
    """Sparse LU factorisation of ``matrix + extra`` (``scipy.sparse.linalg.splu``).

    Its answer is checked: the relative residual must be below ``rtol`` (default 1e-8, far above
    round-off for the well conditioned implicit systems, far below any iterative tolerance).
    ``timer`` times the factorisation (``setup_seconds``) and the triangular solves.
    """

    method = "direct"

    def __init__(self, *, rtol: float = 1e-8, on_failure: str = "raise",
                 timer: Callable[[], float] = time.perf_counter):
        super().__init__(rtol=rtol, maxiter=1, on_failure=on_failure, timer=timer)

    def solve(self, matrix: sparse.spmatrix, rhs: np.ndarray, *, x0: np.ndarray | None = None,
              extra: sparse.spmatrix | None = None, r0: np.ndarray | None = None,
              deflation: Deflation | None = None) -> tuple[np.ndarray, SolveInfo]:
        start = self.timer()
        full = matrix.tocsc() if extra is None else (matrix + extra).tocsc()
        try:
            lu = sla.splu(full)
        except RuntimeError as error:
            raise SolverNotConverged(f"direct solve failed: {error} (the matrix is singular)") from error
        setup = self.timer() - start
        x = lu.solve(rhs)
        norm_b = float(np.linalg.norm(rhs)) or 1.0
        residual = float(np.linalg.norm(rhs - full @ x)) / norm_b
        info = SolveInfo("direct", 0, residual, bool(residual <= self.rtol), self.rtol, 1.0,
                         setup, self.timer() - start - setup)
        return self._finish(x, info)


class JacobiConjugateGradient(_LinearSolver):
    """CG preconditioned with the inverse of the diagonal of ``matrix + extra``."""

    method = "jacobi"

    def solve(self, matrix: sparse.spmatrix, rhs: np.ndarray, *, x0: np.ndarray | None = None,
              extra: sparse.spmatrix | None = None, r0: np.ndarray | None = None,
              deflation: Deflation | None = None) -> tuple[np.ndarray, SolveInfo]:
        start = self.timer()
        diagonal = matrix.diagonal() if extra is None else matrix.diagonal() + extra.diagonal()
        if not (diagonal > 0).all():
            raise SolverNotConverged(f"Jacobi-CG needs a positive diagonal, found {diagonal.min():.3g}")
        inverse = 1.0 / diagonal
        setup = self.timer() - start
        x, iterations, residual, initial = conjugate_gradient(
            _operator(matrix, extra), rhs, x0=x0, preconditioner=inverse.__mul__, rtol=self.rtol,
            maxiter=self.maxiter, r0=r0, deflation=deflation)
        info = SolveInfo("jacobi", iterations, residual, bool(residual <= self.rtol), self.rtol, initial,
                         setup, self.timer() - start - setup)
        return self._finish(x, info)
