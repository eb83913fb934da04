"""Linear solves of the condensed FEM system, with the solvers of :mod:`volspring.solvers`.

The reference is solved by the same solver stack as the model it checks: sparse LU (that of
:class:`~volspring.solvers.DirectSolver`, here with iterative refinement: :func:`solve_direct`), or CG preconditioned by smoothed aggregation with the
six rigid-body modes as near-null space (:class:`~volspring.solvers.AMGConjugateGradient`); for P2
inside a two-level p-multigrid (Gauss-Seidel on P2 around AMG on the Galerkin P1 system, the
solver's ``prolongation``), because smoothed aggregation applied to the P2 matrix itself stalled
(no 1e-8 residual in 300 CG iterations on a 20x2x2 cantilever, 3,000 dofs). A solve that stops
short raises :class:`volspring.errors.SolverNotConverged`. :class:`ReferenceInfo` records how a
reference was computed.

The direct solve (:func:`solve_direct`) is sparse LU followed by up to :data:`DIRECT_REFINEMENT_STEPS`
steps of iterative refinement with the same factors (``u += LU^-1 (f - K u)``), then a residual check
that knows where round-off puts the floor. P2 at nu = 0.499 (lambda = 500 mu) left LU at a relative
residual ||f - K u|| / ||f|| of 1e-8 to 5e-8 on the held-out shapes (above volspring's 1e-8 check,
so the reference raised), and no solver can do much better in double precision: the product K u
itself carries a rounding error of about eps || |K| |u| ||, which there is 3e-8 ||f|| (the entries
lambda div div cancel in K u). Refinement brings LU down to that floor (5.3e-8 -> 2e-8 on the
L-bracket; 8e-9 -> 2e-9 on the capsule), and the check accepts a solve whose residual is either below
:data:`DIRECT_TOLERANCE` relative to ||f|| or below :data:`DIRECT_BACKWARD_ERROR` relative to
|| |K| |u| || + ||f|| (the normwise backward error: the answer is exact for a matrix and load that
much perturbed). The Taylor-Hood system (:func:`solve_saddle_point`) is symmetric but indefinite, so
only LU applies to it.

Examples
--------
>>> import numpy as np
>>> import scipy.sparse as sp
>>> from validation.fem_solvers import solve_linear
>>> K = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(5, 5)).tocsr()   # SPD
>>> u, info = solve_linear(K, np.ones(5), solver="auto", tolerance=1e-10, rigid_modes=None)
>>> info.method, u.round(6)
('direct', array([2.5, 4. , 4.5, 4. , 2.5]))
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import logging
import time

import numpy as np
import scipy.sparse.linalg as spla

from volspring.errors import SolverNotConverged
from volspring.solvers import AMGConjugateGradient, SolveInfo
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from scipy import sparse

__all__ = ["AMG_MAXITER", "AMG_STRENGTH_THETA", "AMG_TOLERANCE", "DIRECT_BACKWARD_ERROR", "DIRECT_DOF_LIMIT",
           "DIRECT_REFINEMENT_STEPS", "DIRECT_TOLERANCE", "ReferenceInfo", "solve_direct", "solve_linear", "solve_saddle_point"]

logger = logging.getLogger(__name__)

#: Problems with at most this many free dofs are solved by sparse LU in ``solver="auto"``, larger
#: ones by AMG + CG: at 19,440 P2 dofs LU took 2-5 s and AMG 1.5 s, and LU fill-in grows fast beyond.
DIRECT_DOF_LIMIT = 20_000
#: Relative residual ||f - K u|| / ||f|| at which CG stops.
AMG_TOLERANCE = 1e-10
#: CG iteration cap: 20 to 40 are needed on the test beams (P1 and P2), so 1000 only stops a stall.
AMG_MAXITER = 1000
#: Strength threshold of the aggregation. The FEM matrices are scalar (CSR, clamped components
#: condensed out), where dropping weak couplings (volspring's 0.05, tuned on 3x3 blocks) raised the
#: operator complexity to 2.2-2.4 and cost time: measured setup + solve 0.70 -> 0.29 s (P1, 80x8x8
#: cells, 19,440 dofs), 4.8 -> 3.3 s (P2, 80x8x8, 139k dofs), 7.5 -> 3.6 s (P1, 160x16x16, 139k
#: dofs) for the same or one or two more iterations.
AMG_STRENGTH_THETA = 0.0
#: Relative residual ||f - K u|| / ||f|| below which a direct solve is accepted: that of
#: :class:`volspring.solvers.DirectSolver`, far below any discretisation error.
DIRECT_TOLERANCE = 1e-8
#: Or the normwise backward error ||f - K u|| / (|| |K| |u| || + ||f||) below which it is accepted: 1e4
#: times double-precision eps, so a solve at the rounding floor passes (measured 1e-15..1e-14 after
#: refinement, P2 at nu = 0.499) and a broken one (a near-singular pivot, a wrong factor: 1e-6 and more) does not.
DIRECT_BACKWARD_ERROR = 1e-12
#: Most steps of iterative refinement after the LU solve: the first brings LU to the rounding floor in the
#: cases measured (P2 and TH, nu 0.3-0.499), the second is margin; each costs two triangular solves.
DIRECT_REFINEMENT_STEPS = 2
#: Relative residual at which refinement stops early (nothing left to gain).
_REFINED_ENOUGH = 1e-14


@dataclass(frozen=True)
class ReferenceInfo(SolveInfo):
    """How a reference was computed: :class:`volspring.solvers.SolveInfo` of its solve, plus the FEM's sizes.

    The other attributes are those of :class:`~volspring.solvers.SolveInfo`.

    Attributes
    ----------
    method : str
        ``"direct"`` (sparse LU), ``"amg"`` (smoothed aggregation + CG) or ``"eigsh"``.
    iterations : int
        CG iterations; for ``"direct"`` the steps of iterative refinement taken.
    residual : float
        Relative residual ||f - K u|| / ||f|| of the condensed system, recomputed from u (0 when
        f = 0); for ``"eigsh"`` the largest ||K phi - lambda M phi|| / ||K phi||.
    dof_count, free_dof_count : int
        All dofs and those not clamped.
    assemble_seconds : float
        Wall time of the assembly [s]; ``setup_seconds`` + ``solve_seconds`` is that of the solve.
    """

    dof_count: int = 0
    free_dof_count: int = 0
    assemble_seconds: float = 0.0


def solve_linear(K: sparse.spmatrix, rhs: np.ndarray, *, solver: str, tolerance: float, rigid_modes: np.ndarray | None,
                 prolongation: sparse.spmatrix | None = None) -> tuple[np.ndarray, SolveInfo]:
    """Solve the condensed SPD system K u = rhs.

    Parameters
    ----------
    K : (N, N) sparse
        Condensed stiffness matrix (free dofs only), SPD.
    rhs : (N,) float
        Condensed load vector.
    solver : {"auto", "direct", "amg"}
        ``"auto"``: sparse LU up to :data:`DIRECT_DOF_LIMIT` dofs, AMG + CG above.
    tolerance : float
        Relative residual at which CG stops.
    rigid_modes : (N, 6) or (n, 6) float
        Rigid-body modes sampled at the dofs AMG coarsens: all of them, or with ``prolongation``
        (P2) the n P1 vertex dofs.
    prolongation : (N, n) sparse, optional
        P1 -> P2 interpolation of the free dofs: solve with the two-level cycle.

    Returns
    -------
    u : (N,) float
    info : SolveInfo
        Of the solve; ``residual`` is recomputed from u as ||rhs - K u|| / ||rhs||.
    """
    if solver == "auto":
        solver = "direct" if K.shape[0] <= DIRECT_DOF_LIMIT else "amg"
    if solver not in ("direct", "amg"):
        raise ValueError(f"solver = {solver!r} is not one of 'auto', 'direct', 'amg'")
    norm = np.linalg.norm(rhs)
    if norm == 0:
        return np.zeros_like(rhs), SolveInfo(solver, 0, 0.0, True, tolerance, 0.0)
    if solver == "direct":
        u, info = solve_direct(K, rhs)
    else:
        amg = AMGConjugateGradient(rtol=tolerance, maxiter=AMG_MAXITER, strength_theta=AMG_STRENGTH_THETA)
        u, info = amg.solve(K, rhs, near_null_space=rigid_modes, prolongation=prolongation)
    # CG stops on its recursive residual; record the true one (they differ by round-off).
    return u, dataclasses.replace(info, residual=float(np.linalg.norm(rhs - K @ u) / norm))


def solve_direct(K: sparse.spmatrix, rhs: np.ndarray, *,
                 refinement_steps: int = DIRECT_REFINEMENT_STEPS) -> tuple[np.ndarray, SolveInfo]:
    """Sparse LU solve of K u = rhs, refined with the same factors, its residual checked.

    Parameters
    ----------
    K : (N, N) sparse
        Non-singular (SPD, or symmetric indefinite as the Taylor-Hood system).
    rhs : (N,) float
    refinement_steps : int
        At most this many steps ``u += LU^-1 (rhs - K u)``; fewer once the relative residual is at
        1e-14 or stops decreasing.

    Returns
    -------
    u : (N,) float
    info : SolveInfo
        ``iterations`` is the refinement steps taken, ``residual`` the relative residual reached and
        ``initial_residual`` that of LU alone.

    Raises
    ------
    SolverNotConverged
        For a singular matrix, or a residual after refinement above both :data:`DIRECT_TOLERANCE` (relative
        to ||rhs||) and :data:`DIRECT_BACKWARD_ERROR` (relative to || |K| |u| || + ||rhs||).

    Examples
    --------
    >>> import numpy as np
    >>> import scipy.sparse as sp
    >>> K = sp.csr_matrix(np.array([[1.0, 2.0], [2.0, 1.0]]))   # symmetric, indefinite
    >>> u, info = solve_direct(K, np.array([3.0, 3.0]))
    >>> u.round(12), info.converged
    (array([1., 1.]), True)
    """
    start = time.perf_counter()
    matrix = K.tocsc()
    try:
        lu = spla.splu(matrix)
    except RuntimeError as error:
        raise SolverNotConverged(f"direct solve failed: {error} (the matrix is singular)") from error
    factorised = time.perf_counter()
    norm = float(np.linalg.norm(rhs)) or 1.0
    u = lu.solve(rhs)
    remainder = rhs - matrix @ u
    initial = residual = float(np.linalg.norm(remainder)) / norm
    steps = 0
    while steps < refinement_steps and residual > _REFINED_ENOUGH:
        refined = u + lu.solve(remainder)
        refined_remainder = rhs - matrix @ refined
        refined_residual = float(np.linalg.norm(refined_remainder)) / norm
        steps += 1
        if not refined_residual < residual:  # at the rounding floor: keep the better iterate
            break
        u, remainder, residual = refined, refined_remainder, refined_residual
    if not np.isfinite(u).all():
        raise SolverNotConverged(f"direct solve produced non-finite values (relative residual {residual:.3g})")
    backward = float(np.linalg.norm(remainder) / (np.linalg.norm(abs(matrix) @ np.abs(u)) + norm))
    if not (residual <= DIRECT_TOLERANCE or backward <= DIRECT_BACKWARD_ERROR):
        raise SolverNotConverged(f"direct solve reached relative residual {residual:.3g} (backward error "
                                 f"{backward:.3g}) after {steps} refinement steps (LU alone: {initial:.3g}), expected "
                                 f"<= {DIRECT_TOLERANCE:.3g} (or a backward error <= {DIRECT_BACKWARD_ERROR:.3g}): "
                                 f"the matrix ({matrix.shape[0]} dofs) is near singular")
    logger.debug("direct solve: residual %.2g from LU, %.2g (backward error %.2g) after %d refinement steps",
                 initial, residual, backward, steps)
    return u, SolveInfo("direct", steps, residual, True, DIRECT_TOLERANCE, initial, factorised - start,
                        time.perf_counter() - factorised)


def solve_saddle_point(K: sparse.spmatrix, rhs: np.ndarray, *, solver: str = "auto") -> tuple[np.ndarray, SolveInfo]:
    """Solve a condensed symmetric indefinite system (the Taylor-Hood u-p system) by sparse LU.

    Parameters
    ----------
    K : (N, N) sparse
        Symmetric, non-singular, indefinite: CG and AMG do not apply.
    rhs : (N,) float
    solver : {"auto", "direct"}
        ``"auto"`` is ``"direct"`` at any size (above :data:`DIRECT_DOF_LIMIT` dofs it logs that LU may be slow).

    Returns
    -------
    u : (N,) float
    info : SolveInfo

    Raises
    ------
    ValueError
        For ``solver="amg"`` (the system is indefinite) or an unknown solver.
    """
    if solver == "amg":
        raise ValueError("solver = 'amg' needs a positive definite system, and the Taylor-Hood (TH) system is "
                         "indefinite: use solver='direct' or 'auto'")
    if solver not in ("auto", "direct"):
        raise ValueError(f"solver = {solver!r} is not one of 'auto', 'direct' (the system is indefinite)")
    if K.shape[0] > DIRECT_DOF_LIMIT:
        logger.info("saddle-point system of %d dofs (above %d) solved by sparse LU: this may be slow",
                    K.shape[0], DIRECT_DOF_LIMIT)
    if np.linalg.norm(rhs) == 0:
        return np.zeros_like(rhs), SolveInfo("direct", 0, 0.0, True, DIRECT_TOLERANCE, 0.0)
    return solve_direct(K, rhs)


def __getattr__(name):
    # SolverInfo (0.1) clashed with volspring.solvers.SolveInfo; a reference solve's record is ReferenceInfo.
    from volspring._deprecation import deprecated_alias

    return deprecated_alias(__name__, name, {"SolverInfo": ("validation.fem_solvers.ReferenceInfo", ReferenceInfo)})
