"""The AMG-preconditioned CG solver: pyamg smoothed aggregation on the 3x3 block matrix, one V-cycle per
CG iteration (see :class:`AMGConjugateGradient` for the choices and their measurements)."""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp

from volspring.solvers.krylov import SolveInfo, _LinearSolver, _operator, conjugate_gradient
from typing import TYPE_CHECKING, Any
from collections.abc import Callable

if TYPE_CHECKING:
    from numpy.typing import ArrayLike
    from scipy import sparse

__all__ = ["AMGConjugateGradient", "BLOCK_JACOBI_OMEGA", "PROLONGATION_OMEGA", "PYAMG_CYCLE_VERSIONS", "SMOOTHERS"]

logger = logging.getLogger(__name__)

#: The V-cycle's smoothers (see :class:`AMGConjugateGradient`); the first is the default.
SMOOTHERS = ("gauss_seidel", "block_gauss_seidel", "jacobi")
#: Weight of the Jacobi prolongation smoother under row-wise Gershgorin weights (see
#: :class:`AMGConjugateGradient`: why not pyamg's random-start spectral radius, and the measurements).
PROLONGATION_OMEGA = 2.0
#: Weight of the block Jacobi smoother, divided by a Gershgorin bound of D^-1 A on each level.
BLOCK_JACOBI_OMEGA = 2.0 / 3.0
#: pyamg releases (major, minor), first and last, whose private recursive cycle
#: ``MultilevelSolver.__solve(level, x, b, cycle)`` :func:`_v_cycle` was checked against: the same
#: signature and the same V-cycle arithmetic in 5.0.0, 5.1.0, 5.2.1, 5.3.0 and 5.4.1.
PYAMG_CYCLE_VERSIONS = ((5, 0), (5, 4))


def _v_cycle(hierarchy):
    """The function r -> z applying one V-cycle of ``hierarchy`` from a zero guess, z ~ A^-1 r.

    pyamg's public preconditioner, ``hierarchy.aspreconditioner(cycle="V")``, runs
    ``hierarchy.solve(r, maxiter=1)``, which around the one cycle also takes ||r||, ||r - A 0|| and
    ||r - A z||: two products with the fine matrix per application, on top of the cycle's own three
    to four, and CG applies it once per iteration. For the pyamg versions in
    :data:`PYAMG_CYCLE_VERSIONS` this calls the cycle underneath directly (the private
    ``MultilevelSolver.__solve``); for any other version, or if that method is gone, it returns
    the public operator. Both run the same arithmetic on the same zero guess, so they give the same
    z bit for bit; the public one is slower: on a 9,741-node gmsh beam at h omega_max = 50, 1.31 times
    the CPU time per application and 1.15 to 1.22 times per CG solve (rtol 1e-3 and 1e-6, same
    iterations; ``python benchmarks/bench_solvers.py``).
    """
    import pyamg

    public = hierarchy.aspreconditioner(cycle="V")
    try:
        version = tuple(int(part) for part in pyamg.__version__.split(".")[:2])  # "5.4.1" -> (5, 4)
    except ValueError:  # not a release number: only the public path is safe
        version = None
    first, last = PYAMG_CYCLE_VERSIONS
    cycle = getattr(hierarchy, "_MultilevelSolver__solve", None)
    if version is None or not first <= version <= last or cycle is None or len(hierarchy.levels) == 1:
        return public.matvec

    def apply(r):
        z = np.zeros_like(r)
        cycle(0, z, r, "V")
        return z

    return apply


@dataclass(frozen=True)
class _Source:
    """What a hierarchy is built from: enough to rebuild it bit for bit (after unpickling)."""

    matrix: sp.spmatrix           # frozen copy of the fine matrix
    near_null_space: np.ndarray   # (N, k) or, with a prolongation, (n, k)
    prolongation: sp.spmatrix | None = None  # (N, n): coarse space of a two-level cycle
    # With the point-wise smoother: ``matrix`` is the CSR form of a BSR matrix of this block size, and also the
    # hierarchy's finest level (one copy; pyamg aggregates a BSR form of it by blocks).
    blocksize: tuple[int, int] | None = None
    # (nodes, nodes) Frobenius norms of the 3x3 blocks of the matrix whose couplings decide the finest level's
    # aggregates, when that is not ``matrix`` (build's ``aggregation``); None: ``matrix``'s own.
    aggregation: sp.csr_matrix | None = None


class AMGConjugateGradient(_LinearSolver):
    """CG preconditioned with one smoothed-aggregation V-cycle on the BSR matrix.

    Parameters
    ----------
    rtol : float
        Relative residual target.
    maxiter : int
        CG iteration cap.
    on_failure : {"raise", "warn"}
    smoother : {"gauss_seidel", "block_gauss_seidel", "jacobi"}
        Gauss-Seidel, forward before and backward after the coarse correction (so the V-cycle stays
        symmetric): point-wise on the finest level and by 6x6 blocks below (``"gauss_seidel"``), by
        blocks on every level (``"block_gauss_seidel"``), or block Jacobi. Why point-wise on the
        finest level: pyamg's block sweep on the 3x3-block matrix costs 2.8 sparse mat-vecs, the
        point-wise sweep on a CSR copy 0.8, for the same CG iterations on the README beam: a V-cycle
        10.5 -> 6.4 mat-vecs at 10k nodes
        (``python benchmarks/bench_vcycle.py --smoother block_gauss_seidel gauss_seidel`` prints the
        steps of both). Point-wise on the 6x6-block coarse levels saved nothing. Block Jacobi needs
        twice the iterations; Chebyshev (degree 3, in A) saved one iteration in five at 10k but
        nothing at 50k, and unlike Gauss-Seidel it is not invariant to the diagonal scaling that
        large mass ratios bring, so it is not offered. With the point-wise sweeps the kept copy of the
        built matrix is that CSR copy, which is also the finest level of the hierarchy (pyamg aggregates a
        BSR form of it made for the build): one copy, 3.5 bytes per nonzero more than the BSR one.
    max_coarse : int
        Unknowns on the coarsest level (solved with sparse LU).
    strength_theta : float
        Couplings weaker than theta (symmetric strength measure) are dropped when aggregating;
        0.05 cut CG iterations from 6 to 5 (rtol 1e-3) and 11 to 9 (rtol 1e-6) on a 50k-node gmsh
        beam at h omega_max = 50, for 10 % more work per cycle; a hierarchy with operator
        complexity above 2.5 is rebuilt with theta = 0.
    timer : callable
        ``timer() -> seconds`` behind ``setup_seconds`` and ``solve_seconds`` (default
        :func:`time.perf_counter`).

    Notes
    -----
    The coarsest level (about a thousand unknowns at 50k nodes) is factorised with sparse LU:
    the default pseudo-inverse spent 1.3 s of a 3.9 s setup in a dense SVD, for the same cycle.
    The candidates B are used as given (``improve_candidates=None``): rigid-body modes are
    already the near-null space, and relaxing them first doubled the setup time for the same
    iteration counts (measured on 10k and 50k-node beams).

    The hierarchy is built from an explicit :meth:`build` call (or the first solve) and kept;
    it is a frozen copy, so later refills of the matrix do not disturb it. The V-cycle is
    applied through :func:`_v_cycle` (pyamg's cycle without the two residual norms its public
    preconditioner adds).

    Two-level cycle: :meth:`build` with a ``prolongation`` P (N, n) builds the hierarchy on the
    Galerkin coarse matrix P^T A P (``near_null_space`` then has n rows) and preconditions with
    one forward Gauss-Seidel sweep on A, the V-cycle on the restricted residual, and one backward
    sweep (symmetric, so CG still applies). This is the p-multigrid of the P2 finite-element
    references (:mod:`validation.fem_solvers`), where smoothed aggregation on the P2 matrix itself
    stalled.

    Pickling: a pyamg hierarchy does not pickle (its smoothers and coarse solver are closures), so
    a pickled solver keeps the frozen matrix and near-null space it was built from and leaves
    :attr:`hierarchy` at None; the next :meth:`solve` or :meth:`precondition` rebuilds it (counted
    in ``setup_seconds`` and ``build_count``). The build is deterministic, so the rebuilt
    hierarchy, and every answer, is the same bit for bit.

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

    Examples
    --------
    A 1D Laplacian with the constant as near-null space:

    >>> import numpy as np
    >>> import scipy.sparse as sp
    >>> matrix = sp.diags([-1.0, 2.0, -1.0], [-1, 0, 1], shape=(2000, 2000)).tocsr()
    >>> solver = AMGConjugateGradient(rtol=1e-8, max_coarse=50)
    >>> x, info = solver.solve(matrix, np.ones(2000), near_null_space=np.ones((2000, 1)))
    >>> info.converged, info.rebuilt, len(solver.hierarchy.levels) > 1
    (True, True, True)
    """

    method = "amg"

    def __init__(self, *, rtol: float = 1e-3, maxiter: int = 500, on_failure: str = "raise",
                 smoother: str = "gauss_seidel", max_coarse: int = 300, strength_theta: float = 0.05,
                 timer: Callable[[], float] = time.perf_counter):
        super().__init__(rtol=rtol, maxiter=maxiter, on_failure=on_failure, timer=timer)
        if smoother not in SMOOTHERS:
            raise ValueError(f"smoother = {smoother!r}, expected one of {', '.join(map(repr, SMOOTHERS))}")
        self.smoother, self.max_coarse = smoother, int(max_coarse)
        self.strength_theta = float(strength_theta)
        self.build_count = 0
        self._source: _Source | None = None  # what the hierarchy is built from (pickled)
        self._hierarchy: Any = None  # pyamg MultilevelSolver (not pickled)
        self._cycle: Callable[[np.ndarray], np.ndarray] | None = None  # r -> z, one V-cycle of it (not pickled)
        self._refreshed = False  # the finest level holds a refresh()'s matrix, not the built one

    @property
    def hierarchy(self) -> Any:
        """The pyamg ``MultilevelSolver``; None before the first build, and after unpickling until
        the next :meth:`solve` or :meth:`precondition` rebuilds it."""
        return self._hierarchy

    def __getstate__(self):
        state = self.__dict__.copy()
        state["_hierarchy"] = state["_cycle"] = None  # closures inside: rebuilt from _source on use
        return state

    def build(self, matrix: sparse.spmatrix, near_null_space: ArrayLike, *,
              prolongation: sparse.spmatrix | None = None, aggregation: sparse.spmatrix | None = None) -> float:
        """Build the hierarchy for ``matrix``; returns the seconds it took (by ``timer``).

        Parameters
        ----------
        matrix : (N, N) sparse
            SPD, best as BSR with block size 3.
        near_null_space : (N, k) float
            Rigid-body modes of the unknowns (``rigid_body_modes``, k = 6); with a
            ``prolongation``, of the n coarse unknowns, (n, k).
        prolongation : (N, n) sparse, optional
            Coarse space of a two-level cycle (see the class docstring).
        aggregation : (N, N) sparse, optional
            The matrix whose couplings decide the finest level's aggregates (default ``matrix``), with the same
            3x3 blocks, for couplings that should not join nodes into one aggregate: contact between two bodies.
            An aggregate across a contact interface makes both sides move as one rigid piece in the coarse space,
            which they do not (they slide and part): on a cube resting on another, a hierarchy aggregated with the
            contact needed 10-13 CG iterations where the same step without contact needed 6, and 5-6 aggregated
            without it (``benchmarks/bench_contact_cg.py``). The coarse operators are the Galerkin products of
            ``matrix``, contact included.
        """
        start = self.timer()
        near_null_space = np.ascontiguousarray(near_null_space, dtype=np.float64)
        coarse_size = matrix.shape[0] if prolongation is None else prolongation.shape[1]
        if prolongation is not None and prolongation.shape[0] != matrix.shape[0]:
            raise ValueError(f"prolongation has shape {prolongation.shape}, expected ({matrix.shape[0]}, n) "
                             f"for a {matrix.shape} matrix")
        if near_null_space.ndim != 2 or near_null_space.shape[0] != coarse_size:
            raise ValueError(f"near_null_space has shape {near_null_space.shape}, expected ({coarse_size}, k)")
        frozen = matrix.copy() if matrix.format in ("csr", "bsr") else matrix.tocsr()
        # Canonical (sorted, summed) up front: pyamg sorts the indices in place, and a hierarchy rebuilt
        # from the sorted matrix (after unpickling) would otherwise differ from one built before.
        frozen.sum_duplicates()
        if aggregation is not None:
            if prolongation is not None or aggregation.shape != matrix.shape:
                given = " with a prolongation" if prolongation is not None else ""
                raise ValueError(f"aggregation must have the matrix's shape {matrix.shape} and no prolongation; got "
                                 f"shape {aggregation.shape}{given}")
            aggregation = _block_norms(aggregation)
        self._source = _Source(frozen, near_null_space,
                               None if prolongation is None else sp.csr_matrix(prolongation), aggregation=aggregation)
        self._construct()
        seconds = self.timer() - start
        logger.debug("built AMG hierarchy: %s levels, operator complexity %.2f, %.3f s",
                     len(self._hierarchy.levels), self._hierarchy.operator_complexity(), seconds)
        return seconds

    def _construct(self):
        """Build the pyamg hierarchy and its cycle from ``self._source`` (deterministic)."""
        import pyamg

        source = self._source
        if source is None:
            raise ValueError("the AMG hierarchy has no source: call build(matrix, near_null_space) first")
        matrix = source.matrix
        if source.prolongation is not None:
            matrix = (source.prolongation.T @ matrix @ source.prolongation).tocsr()
        elif source.blocksize is not None:
            matrix = sp.bsr_matrix(matrix, blocksize=source.blocksize)
        # Gauss-Seidel first in every case: it draws nothing at set-up (see the class docstring);
        # block Jacobi gets its deterministic weights once the levels exist.
        gauss_seidel = ("block_gauss_seidel", {"sweep": "forward"}), ("block_gauss_seidel", {"sweep": "backward"})
        options = dict(B=source.near_null_space, symmetry="hermitian",
                       presmoother=gauss_seidel[0], postsmoother=gauss_seidel[1],
                       smooth=("jacobi", {"omega": PROLONGATION_OMEGA, "weighting": "local"}),
                       max_coarse=self.max_coarse, improve_candidates=None, coarse_solver="splu")
        hierarchy = pyamg.smoothed_aggregation_solver(
            matrix, strength=_strength(self.strength_theta, source.aggregation), **options)
        if self.strength_theta and hierarchy.operator_complexity() > 2.5:
            # Dropping weak couplings can slow coarsening on odd meshes: fall back to keeping all.
            hierarchy = pyamg.smoothed_aggregation_solver(matrix, strength=_strength(0.0, source.aggregation),
                                                          **options)
        del matrix  # the BSR form made from a CSR source goes once the hierarchy is built (peak memory)
        if self.smoother == "gauss_seidel":
            if hierarchy.levels[0].A.format == "bsr" and source.blocksize is None:
                # A new build: from now on the kept copy is the CSR form, and the BSR goes.
                source = self._source = replace(source, matrix=_scalar_copy(source.matrix),
                                                blocksize=source.matrix.blocksize)
            # A CSR finest level (a scalar problem, a two-level cycle's coarse space) is swept point-wise as it is.
            self._finest_point_wise(hierarchy, source.matrix if source.blocksize is not None else hierarchy.levels[0].A)
        elif self.smoother != "block_gauss_seidel":
            self._set_smoothers(hierarchy)
        self._refreshed = False
        cycle = _v_cycle(hierarchy)
        size = hierarchy.levels[0].A.shape[0]
        try:
            cycle(np.zeros(size))  # the coarse solver sets up lazily: count it here
        except RuntimeError:  # a singular coarsest matrix (statics of a barely held body): pseudo-inverse
            from pyamg.multilevel import coarse_grid_solver

            hierarchy.coarse_solver = coarse_grid_solver("pinv")
            cycle(np.zeros(size))
        self._hierarchy, self._cycle = hierarchy, cycle
        self.build_count += 1

    def _set_smoothers(self, hierarchy) -> None:
        """(Re)make the smoothers from the levels' current matrices: the finest level's point-wise sweeps, every
        level's block sweeps, or block Jacobi weighted by a bound per level (``self.smoother``)."""
        from pyamg.relaxation.smoothing import change_smoothers

        if self.smoother == "gauss_seidel":  # the finest level's point-wise sweeps take the matrix they are given
            return
        if self.smoother == "block_gauss_seidel":
            pre, post = ("block_gauss_seidel", {"sweep": "forward"}), ("block_gauss_seidel", {"sweep": "backward"})
            change_smoothers(hierarchy, [pre], [post])
            return
        weighted = [("block_jacobi", {"omega": BLOCK_JACOBI_OMEGA / _block_jacobi_bound(level.A),
                                      "iterations": 1, "withrho": False})
                    for level in hierarchy.levels[:-1]]
        change_smoothers(hierarchy, weighted, weighted)

    @staticmethod
    def _finest_point_wise(hierarchy, matrix: sp.csr_matrix) -> None:
        """``matrix`` (CSR, sorted) under the finest level, with point-wise sweeps; the coarse levels keep theirs."""
        finest = hierarchy.levels[0]
        finest.A = matrix
        finest.presmoother, finest.postsmoother = _point_gauss_seidel()

    def refresh(self, matrix: sparse.spmatrix) -> None:
        """Put ``matrix`` under the hierarchy's finest level (its smoother and residuals), keeping the coarse levels.

        For a system whose fine matrix changed in a few rows since the build, as contact changes from
        step to step: the fine smoother then sees the current contact stiffness, while the coarse
        levels (the expensive part of a build) are kept. Measured on two 216-node cubes pressed
        together (``benchmarks/bench_versions.py``'s contact scene): 11 CG iterations per step instead
        of 19 with a hierarchy rebuilt whenever the iterations double, and 23 with the contact
        Jacobian outside the hierarchy. Deterministic: the result depends on ``matrix`` and the
        hierarchy's build only, so a resumed run refreshes to the same operator.

        Parameters
        ----------
        matrix : (N, N) sparse
            the current system, same shape as the built one (made BSR, block size 3)
        """
        hierarchy, source = self.hierarchy, self._source
        if hierarchy is None or source is None:
            raise ValueError("the AMG hierarchy is not built: call build(matrix, near_null_space) first")
        if source.prolongation is not None:
            raise ValueError("refresh() applies to a hierarchy built on the matrix itself, not a two-level one")
        if matrix.shape != hierarchy.levels[0].A.shape:
            raise ValueError(f"matrix has shape {matrix.shape}; the hierarchy was built for {hierarchy.levels[0].A.shape}")
        if self.smoother == "gauss_seidel":
            self._finest_point_wise(hierarchy, _scalar_copy(matrix))
        else:
            hierarchy.levels[0].A = sp.bsr_matrix(matrix, blocksize=(3, 3))
            self._set_smoothers(hierarchy)
        self._refreshed = True

    def restore(self) -> None:
        """Put the built matrix back under the finest level after :meth:`refresh` (nothing to do otherwise).

        Why: the preconditioner of a step must depend on the build and that step's own system only. A refresh
        kept after contact ends would make the steps that follow depend on the last contact step, which a run
        resumed from a checkpoint (whose hierarchy is rebuilt from the recorded build) does not have.
        """
        hierarchy, source = self.hierarchy, self._source
        if hierarchy is None or source is None or not self._refreshed:
            return
        if source.blocksize is not None:
            self._finest_point_wise(hierarchy, source.matrix)
        else:
            hierarchy.levels[0].A = source.matrix
            self._set_smoothers(hierarchy)
        self._refreshed = False

    def precondition(self, r: np.ndarray) -> np.ndarray:
        """One cycle from a zero guess: z ~ A^-1 r (an SPD operator for CG).

        Parameters
        ----------
        r : (N,) float
            Residual.

        Returns
        -------
        (N,) float
        """
        if self._cycle is None:
            if self._source is None:
                raise ValueError("the AMG hierarchy is not built: call build(matrix, near_null_space) first")
            self._construct()  # after unpickling: the same hierarchy again
        source, cycle = self._source, self._cycle
        assert source is not None and cycle is not None  # both set by _construct()
        if source.prolongation is None:
            return cycle(r)
        from pyamg.relaxation.relaxation import gauss_seidel

        matrix, prolongation = source.matrix, source.prolongation
        z = np.zeros_like(r)
        gauss_seidel(matrix, z, r, iterations=1, sweep="forward")
        z += prolongation @ cycle(prolongation.T @ (r - matrix @ z))
        gauss_seidel(matrix, z, r, iterations=1, sweep="backward")
        return z

    def solve(self, matrix: sparse.spmatrix, rhs: np.ndarray, *, x0: np.ndarray | None = None,
              extra: sparse.spmatrix | None = None, near_null_space: np.ndarray | None = None,
              prolongation: sparse.spmatrix | None = None) -> tuple[np.ndarray, SolveInfo]:
        """Solve ``(matrix + extra) x = rhs``; returns ``(x, SolveInfo)``.

        Parameters
        ----------
        matrix : (N, N) sparse
            SPD; the hierarchy is built from it when there is none of its size yet.
        rhs : (N,) float
        x0 : (N,) float, optional
            Warm start.
        extra : (N, N) sparse or LinearOperator, optional
            Added in every product, left out of the hierarchy (a matrix-free term: anything with ``@``).
        near_null_space, prolongation
            As for :meth:`build`; needed only when this solve builds the hierarchy.
        """
        setup = 0.0
        rebuilt = self._source is None or self._source.matrix.shape != matrix.shape
        if rebuilt:
            if near_null_space is None:
                raise ValueError("the first AMG solve needs near_null_space (rigid-body modes)")
            setup = self.build(matrix, near_null_space, prolongation=prolongation)
        elif self._cycle is None:  # unpickled: rebuild from the kept matrix, the same bits
            start = self.timer()
            self._construct()
            setup, rebuilt = self.timer() - start, True
        start = self.timer()
        x, iterations, residual, initial = conjugate_gradient(
            _operator(matrix, extra), rhs, x0=x0, preconditioner=self.precondition, rtol=self.rtol,
            maxiter=self.maxiter)
        info = SolveInfo("amg", iterations, residual, bool(residual <= self.rtol), self.rtol, initial,
                         setup, self.timer() - start, rebuilt)
        return self._finish(x, info)


def _block_norms(matrix) -> sp.csr_matrix:
    """(nodes, nodes) CSR -- the Frobenius norm of every stored 3x3 block of ``matrix`` (what pyamg's symmetric
    strength of connection measures a block matrix by)."""
    blocks = sp.bsr_matrix(matrix, blocksize=(3, 3))
    blocks.sum_duplicates()
    norms = np.sqrt((blocks.data**2).reshape(len(blocks.data), 9).sum(axis=1))
    nodes = blocks.shape[0] // 3
    return sp.csr_matrix((norms, blocks.indices, blocks.indptr), shape=(nodes, nodes))


def _strength(theta: float, aggregation: sp.csr_matrix | None):
    """pyamg's ``strength`` option: the symmetric measure with ``theta`` on every level, the finest level's taken
    from the block norms ``aggregation`` when given (as pyamg takes it from a BSR matrix: all blocks at theta 0)."""
    if aggregation is None:
        return ("symmetric", {"theta": theta})
    from pyamg.strength import symmetric_strength_of_connection

    if theta:
        finest = symmetric_strength_of_connection(aggregation, theta)
    else:
        finest = sp.csr_matrix((np.ones(aggregation.nnz), aggregation.indices, aggregation.indptr),
                               shape=aggregation.shape)
    return [("predefined", {"C": finest}), ("symmetric", {"theta": theta})]


def _scalar_copy(matrix) -> sp.csr_matrix:
    """``matrix`` in CSR form with sorted indices: the point-wise sweeps' format."""
    scalar = sp.csr_matrix(matrix)
    scalar.sort_indices()
    return scalar


def _point_gauss_seidel() -> tuple[Callable, Callable]:
    """pyamg smoothers ``(A, x, b) -> None`` for a CSR level: one forward and one backward point-wise Gauss-Seidel
    sweep (pyamg's own, which on a BSR matrix would sweep by blocks)."""
    from pyamg.relaxation.relaxation import gauss_seidel

    def forward(A, x, b):
        gauss_seidel(A, x, b, iterations=1, sweep="forward")

    def backward(A, x, b):
        gauss_seidel(A, x, b, iterations=1, sweep="backward")

    return forward, backward


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
