"""Linear solvers for the symmetric positive definite systems of the implicit step, statics and
the finite-element references of :mod:`validation`.

Three methods share one interface, ``solver.solve(matrix, rhs, x0=..., extra=...) -> (x, info)``:

``"amg"``
    Conjugate gradients preconditioned with one V-cycle of pyamg smoothed aggregation built on
    the 3x3 block (BSR) matrix with the six rigid-body modes as near-null space ``B``
    (REFERENCE.md section 3: 4 / 10 / 14 / 14 iterations at 1 / 10 / 100 / 1000 times the
    explicit limit, against 48 / 205 / 533 / 609 unpreconditioned). The hierarchy is built by
    :meth:`AMGConjugateGradient.build` and reused for later matrices of the same pattern: it then
    preconditions a nearby matrix, which only costs iterations, never accuracy, because CG
    iterates on the current matrix. When to rebuild is the caller's policy (see
    :class:`volspring.integrators.implicit.ImplicitEuler`). With a ``prolongation`` the
    hierarchy is built on a Galerkin coarse space instead (two-level, for P2 finite elements).
``"jacobi"``
    Conjugate gradients preconditioned with the inverse diagonal, for comparison.
``"direct"``
    Sparse LU (``scipy.sparse.linalg.splu``), for small systems and for checking.

``extra`` is an optional additional sparse term (e.g. a contact or field Jacobian) applied in
every CG product but left out of the AMG hierarchy. ``r0`` is ``rhs - (matrix + extra) x0`` when the caller
already has it (the implicit step's warm start does): CG then skips that product. ``deflation``
(:class:`~volspring.solvers.krylov.Deflation`) takes a subspace that ``x0`` was projected on out of the
preconditioner, so that CG's search directions stay A-orthogonal to it (the implicit step's past velocity changes,
where CG adds products to the matrix's: the upper rungs' sets, contact); the direct solve ignores it.

CG stops when ||b - A x|| <= rtol ||b|| (the recursively updated residual; the criterion of
``pyamg.krylov.cg(criteria="rr")`` and of ``scipy.sparse.linalg.cg(rtol=...)``). A solve that
stops short raises :class:`volspring.errors.SolverNotConverged` naming the residual reached, or
warns with it (``on_failure="warn"``); it never returns a wrong answer silently.

Every ``*_seconds`` figure of :class:`SolveInfo` comes from the solver's ``timer`` (keyword of
each solver, default :func:`time.perf_counter`; a benchmark on a shared machine may pass
:func:`time.process_time`). Solvers pickle (integrators and scenes are sent to worker
processes): a built AMG hierarchy does not (pyamg keeps its smoothers and coarse solver in
closures), so it is dropped and rebuilt, bit for bit, from the kept matrix on first use.

Examples
--------
>>> import numpy as np
>>> import scipy.sparse as sp
>>> from volspring.solvers import make_linear_solver
>>> matrix = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(5, 5)).tocsr()   # SPD
>>> x, info = make_linear_solver("direct").solve(matrix, np.ones(5))
>>> x.round(6), info.method, info.converged
(array([2.5, 4. , 4.5, 4. , 2.5]), 'direct', True)
"""

from __future__ import annotations

from volspring.solvers.amg import AMGConjugateGradient, BLOCK_JACOBI_OMEGA, PROLONGATION_OMEGA
from volspring.solvers.krylov import (LINEAR_SOLVERS, DirectSolver, JacobiConjugateGradient, SolveInfo,
                                      conjugate_gradient)
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from volspring.solvers.krylov import _LinearSolver

__all__ = ["SolveInfo", "conjugate_gradient", "DirectSolver", "JacobiConjugateGradient",
           "AMGConjugateGradient", "BLOCK_JACOBI_OMEGA", "LINEAR_SOLVERS", "PROLONGATION_OMEGA",
           "make_linear_solver"]


def make_linear_solver(method: str, **options: Any) -> _LinearSolver:
    """A solver by name: ``"amg"``, ``"jacobi"`` or ``"direct"`` (options passed on)."""
    kinds = {"amg": AMGConjugateGradient, "jacobi": JacobiConjugateGradient, "direct": DirectSolver}
    if method not in kinds:
        raise ValueError(f"unknown linear solver {method!r}; known: {', '.join(LINEAR_SOLVERS)}")
    return kinds[method](**options)
