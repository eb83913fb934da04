"""Linear solves of the condensed FEM system, with the solvers of :mod:`volspring.solvers`.

The reference is solved by the same solver stack as the model it checks: sparse LU
(:class:`~volspring.solvers.DirectSolver`), or CG preconditioned by smoothed aggregation with the
six rigid-body modes as near-null space (:class:`~volspring.solvers.AMGConjugateGradient`); for P2
inside a two-level p-multigrid (Gauss-Seidel on P2 around AMG on the Galerkin P1 system, the
solver's ``prolongation``), because smoothed aggregation applied to the P2 matrix itself stalled
(no 1e-8 residual in 300 CG iterations on a 20x2x2 cantilever, 3,000 dofs). A solve that stops
short raises :class:`volspring.errors.SolverNotConverged`. :class:`ReferenceInfo` records how a
reference was computed.

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

import numpy as np

from volspring.solvers import AMGConjugateGradient, DirectSolver, SolveInfo

__all__ = ["AMG_MAXITER", "AMG_STRENGTH_THETA", "AMG_TOLERANCE", "DIRECT_DOF_LIMIT", "ReferenceInfo",
           "solve_linear"]

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


@dataclass(frozen=True)
class ReferenceInfo(SolveInfo):
    """How a reference was computed: :class:`volspring.solvers.SolveInfo` of its solve, plus the FEM's sizes.

    Attributes
    ----------
    method : str
        ``"direct"`` (sparse LU), ``"amg"`` (smoothed aggregation + CG) or ``"eigsh"``.
    residual : float
        Relative residual ||f - K u|| / ||f|| of the condensed system, recomputed from u (0 when
        f = 0); for ``"eigsh"`` the largest ||K phi - lambda M phi|| / ||K phi||.
    dof_count, free_dof_count : int
        All dofs and those not clamped.
    assemble_seconds : float
        Wall time of the assembly [s]; ``setup_seconds`` + ``solve_seconds`` is that of the solve.

    The other attributes are those of :class:`~volspring.solvers.SolveInfo`.
    """

    dof_count: int = 0
    free_dof_count: int = 0
    assemble_seconds: float = 0.0


def solve_linear(K, rhs, *, solver, tolerance, rigid_modes, prolongation=None) -> tuple[np.ndarray, SolveInfo]:
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
        u, info = DirectSolver().solve(K, rhs)
    else:
        amg = AMGConjugateGradient(rtol=tolerance, maxiter=AMG_MAXITER, strength_theta=AMG_STRENGTH_THETA)
        u, info = amg.solve(K, rhs, near_null_space=rigid_modes, prolongation=prolongation)
    # CG stops on its recursive residual; record the true one (they differ by round-off).
    return u, dataclasses.replace(info, residual=float(np.linalg.norm(rhs - K @ u) / norm))


def __getattr__(name):
    # SolverInfo (0.1) clashed with volspring.solvers.SolveInfo; a reference solve's record is ReferenceInfo.
    from volspring._deprecation import deprecated_alias

    return deprecated_alias(__name__, name, {"SolverInfo": ("validation.fem_solvers.ReferenceInfo", ReferenceInfo)})
