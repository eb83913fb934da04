"""The AMG-preconditioned CG solver: pyamg smoothed aggregation on the 3x3 block matrix, one V-cycle per
CG iteration (see :class:`AMGConjugateGradient` for the choices and their measurements)."""

from __future__ import annotations

import copy
import logging
import time
import weakref
from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from volspring.kernels import compiled, unsigned
from volspring.solvers.krylov import Deflation, SolveInfo, _LinearSolver, _operator, conjugate_gradient, times
from typing import TYPE_CHECKING, Any
from collections.abc import Callable

if TYPE_CHECKING:
    from numpy.typing import ArrayLike
    from scipy import sparse

__all__ = ["AMGConjugateGradient", "BLOCK_JACOBI_OMEGA", "FINEST_DTYPE", "PROLONGATION_OMEGA", "SMOOTHERS",
           "STAND_IN_CORRECTION", "StandInCorrection", "stand_in_correction"]

logger = logging.getLogger(__name__)

#: The V-cycle's smoothers (see :class:`AMGConjugateGradient`); the first is the default.
SMOOTHERS = ("gauss_seidel", "block_gauss_seidel", "jacobi")
#: Weight of the Jacobi prolongation smoother under row-wise Gershgorin weights (see
#: :class:`AMGConjugateGradient`: why not pyamg's random-start spectral radius, and the measurements).
PROLONGATION_OMEGA = 2.0
#: Entries of A - C below this share of C's are rounding (see :func:`_smoothed_aggregation`).
_SEPARATION_ROUNDING = 1e-10
#: Weight of the block Jacobi smoother, divided by a Gershgorin bound of D^-1 A on each level.
BLOCK_JACOBI_OMEGA = 2.0 / 3.0
#: The type the finest level's point-wise triangles are held and swept in (see :class:`AMGConjugateGradient`).
FINEST_DTYPE = np.float32
#: Single precision holds a finest level whose stored magnitudes are at most this and whose diagonal's are at least
#: its inverse: with the cycle's residual scaled to a largest entry of 1, the sweeps stay inside single precision's
#: normal range (2^-126 to 2^128). A level outside (no system in SI units comes near) is held in double.
SINGLE_PRECISION_RANGE = 2.0**60
#: Weight omega of the preconditioner's correction for a stand-in matrix (:func:`stand_in_correction`).
STAND_IN_CORRECTION = 0.3
#: The coarsest level is factorised in its own order where its lower envelope holds at most this share of its entries
#: (:func:`_column_order`): the natural order's lower factor then holds at most about 1.5 times the fewest entries
#: any order can give (a lower factor holds at least the lower triangle, about half the entries).
NATURAL_ORDER_ENVELOPE = 0.75


def _v_cycle(hierarchy):
    """The function r -> z applying one V-cycle of ``hierarchy`` from a zero guess, z ~ A^-1 r.

    The cycle of pyamg's ``MultilevelSolver`` (pre-smoothing, residual, restriction, the coarser levels, prolongation,
    post-smoothing), run on its levels without what pyamg's public preconditioner,
    ``hierarchy.aspreconditioner(cycle="V")``, adds around it: ``hierarchy.solve(r, maxiter=1)`` also takes ||r||,
    ||r - A 0|| and ||r - A z||, two products with the fine matrix per application (1.31 times the CPU time per
    application on a 9,741-node gmsh beam; ``python benchmarks/bench_solvers.py``). A level whose matrix is held
    as its triangles (:class:`_Triangles`, the default smoother's levels) sweeps forward from the zero guess over the
    lower triangle only and takes the residual from the upper one, half a mat-vec each instead of one; any other
    level runs pyamg's own arithmetic, so with the other smoothers the cycle gives pyamg's z bit for bit.
    """
    levels = hierarchy.levels
    if len(levels) == 1:
        return hierarchy.aspreconditioner(cycle="V").matvec
    last = len(levels) - 2
    coarse_solve = _coarse_solve(hierarchy)
    finest = _CompiledFinest.of(levels[0])

    def apply(r, index=0):
        level = levels[index]
        matrix = level.A
        if index == 0 and finest is not None:
            halves = finest.down(matrix, r)
            if halves is not None:
                z, coarse = halves
                coarse = coarse.astype(levels[1].A.dtype, copy=False)
                correction = coarse_solve(coarse) if last == 0 else apply(coarse, 1)
                finest.up(matrix, correction, r, z)
                return z
        if isinstance(matrix, _Triangles):
            z, residual = matrix.forward_from_zero(r)
        else:
            z = np.zeros_like(r)
            level.presmoother(matrix, z, r)
            residual = r - matrix @ z
        coarse = (level.R @ residual).astype(levels[index + 1].A.dtype, copy=False)
        correction = coarse_solve(coarse) if index == last else apply(coarse, index + 1)
        z += level.P @ correction.astype(level.P.dtype, copy=False)  # in P's precision: no upcast copy of P
        level.postsmoother(matrix, z, r)
        return z

    def cycle(r):
        if levels[0].A.dtype == r.dtype:
            return apply(r)
        # A finest level held in single precision sweeps in it, on r scaled by a power of two to a largest entry in
        # [1, 2): exact, and no entry of a residual CG has shrunk by 1e-10 under- or overflows there. The cycle is
        # linear, so z scales back exactly.
        largest = max(float(r.max()), -float(r.min()))
        if largest == 0.0:
            return np.zeros_like(r)
        exponent = int(np.frexp(largest)[1]) - 1 if np.isfinite(largest) else 0
        scaled = np.ldexp(r, -exponent).astype(levels[0].A.dtype)  # once here, not in each sweep
        return np.ldexp(apply(scaled).astype(r.dtype), exponent)

    return cycle


class _CompiledFinest:
    """The finest level's two halves of the V-cycle as one compiled pass each (:func:`volspring._compiled.finest_down`
    and :func:`~volspring._compiled.finest_up`), for the default smoother's level: point-wise triangles, a CSR
    prolongator P in their precision and R its transpose (a finest level held in double keeps its BSR P and the
    numpy cycle). The numpy cycle's arithmetic in the same order (the same bits), without its dozen Python calls and
    temporaries per half, and with the products' rows taken three at a time: a V-cycle 5.9 -> 4.5 mat-vecs on the
    1,041-node beam of ``python benchmarks/bench_implicit.py``, 6.1 -> 5.2 on the 9,741-node one (scratch timing,
    stop 35).

    Each half reads the triangles on the level when it runs, as the numpy cycle does: a contact step holds the built
    ones plus the contact's change there (:meth:`AMGConjugateGradient.update`), its triangles in double where the
    change is outside single precision's range, and those the numpy cycle sweeps (the prolongator stays as built)."""

    def __init__(self, kernels, prolongation: sp.csr_matrix):
        self.kernels = kernels
        self.prolongation = (unsigned(prolongation.indptr), unsigned(prolongation.indices), prolongation.data)
        self.dtype = prolongation.dtype
        self.zero = self.dtype.type(0.0)  # the kernels' sums start from a zero of the level's type
        self.coarse_size = prolongation.shape[1]
        # (A weak reference to) the triangles last swept, and their arrays with P's (None: the halves do not apply).
        self._triangles: weakref.ReferenceType | None = None
        self._arrays: tuple | None = None

    @classmethod
    def of(cls, level) -> _CompiledFinest | None:
        """The compiled halves for ``level`` where the kernels run and its transfers are held so, else None."""
        kernels = compiled()
        prolongation = getattr(level, "P", None)
        if kernels is None or prolongation is None or prolongation.format != "csr" or not _transposed(level):
            return None
        return cls(kernels, prolongation)

    def _arrays_of(self, matrix) -> tuple | None:
        """The kernels' arrays of the level's ``matrix`` with P's, or None where the halves do not apply to it."""
        if self._triangles is not None and self._triangles() is matrix:
            return self._arrays
        arrays = None
        if isinstance(matrix, _Triangles) and matrix.inverse is None and matrix.format == "csr" and \
                matrix.dtype == self.dtype:
            lower, upper = matrix.lower, matrix.upper
            arrays = (unsigned(lower.indptr), unsigned(lower.indices), lower.data, unsigned(upper.indptr),
                      unsigned(upper.indices), upper.data, matrix.diagonal) + self.prolongation
        self._triangles, self._arrays = weakref.ref(matrix), arrays
        return arrays

    def down(self, matrix, r: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        """(z, R (r - A z)) for z the forward sweep from zero on A z = r, both in the level's precision; None where
        the halves do not apply to the level's ``matrix``."""
        arrays = self._arrays_of(matrix)
        if arrays is None:
            return None
        r = np.asarray(r, dtype=self.dtype)
        z, coarse = np.zeros(r.shape, dtype=self.dtype), np.zeros(self.coarse_size, dtype=self.dtype)
        self.kernels.finest_down(*arrays, r, z, coarse, self.zero)
        return z, coarse

    def up(self, matrix, correction: np.ndarray, r: np.ndarray, z: np.ndarray) -> None:
        """z += P correction, then the backward sweep on A z = r, in place (after :meth:`down` on ``matrix``)."""
        arrays = self._arrays_of(matrix)
        assert arrays is not None  # down() ran on the same matrix
        correction = np.asarray(correction, dtype=self.dtype)
        self.kernels.finest_up(*arrays, correction, np.asarray(r, dtype=self.dtype), z, self.zero)


def _coarse_solve(hierarchy):
    """b -> the coarsest level's solution, by the hierarchy's factorised coarse solver (:class:`_CoarseLU`'s
    :meth:`~_CoarseLU.solve`, or any other called as pyamg calls it)."""
    solver, coarsest = hierarchy.coarse_solver, hierarchy.levels[-1].A
    if isinstance(solver, _CoarseLU):
        return solver.solve
    return lambda b: solver(coarsest, b)


@dataclass(frozen=True, eq=False)
class StandInCorrection:
    """What the preconditioner adds to its V-cycle where its matrix is a stand-in (:func:`stand_in_correction`):
    ``correction @ r`` = Pi C Pi^T r.

    Attributes
    ----------
    blocks : (N, N) BSR
        C = omega [D^-1 - D_s^-1]_+, block diagonal
    translations : (3, N) float
        T^T, the three translations of all unknowns as rows
    translated : (3, N) float
        (A_s T)^T, the stand-in's products with them
    gram_inverse : (3, 3) float
        (T^T A_s T)^-1
    """

    blocks: sp.bsr_matrix
    translations: np.ndarray
    translated: np.ndarray
    gram_inverse: np.ndarray

    def __matmul__(self, r: np.ndarray) -> np.ndarray:
        """(N,) -- Pi C Pi^T r, Pi = I - T (T^T A_s T)^-1 (A_s T)^T. The (3, N) rows make each of the four small
        products one BLAS call: 0.10-0.11 ms on the README beam (``python benchmarks/study_stand_in.py --build-cost``),
        where stop 42's first version, with sums over an (N / 3, 3) view, took 0.25."""
        z = times(self.blocks, r - (self.gram_inverse @ (self.translations @ r)) @ self.translated)
        return z - (self.gram_inverse @ (self.translated @ z)) @ self.translations


def stand_in_correction(matrix: sparse.spmatrix, exact_diagonal: np.ndarray,
                        weight: float | None = None) -> StandInCorrection:
    """Pi omega [D^-1 - D_s^-1]_+ Pi^T, what the preconditioner adds to its V-cycle where the matrix it was built from
    is a stand-in A_s for the operator CG iterates on: D and D_s are the operator's and the stand-in's 3 x 3 diagonal
    blocks, [.]_+ keeps each block's positive eigenvalues (so the preconditioner V + correction stays SPD), and
    Pi = I - T (T^T A_s T)^-1 T^T A_s, T the three translations of all unknowns together, takes out what the blocks
    would add to the momentum.

    Why: the smoothed rung's stand-in (:meth:`volspring.elements.NodalStrain.preconditioner_blocks`) is stiffer than
    its operator in the modes that vary from tet to tet, where the operator's nodal averaging softens the shear (D^-1
    exceeds D_s^-1 at every node of the README beam), and the V-cycle's Gauss-Seidel sweeps on it correct those modes
    too little. The correction adds the compliance the stand-in lacks there, one block-diagonal product a CG
    iteration, and vanishes where the stand-in is the operator (the springs). On the README beam (3,321 nodes, dt 0.01
    s, steps 3-22 from rest; ``python benchmarks/study_stand_in.py``) CG's iterations a step went from 3.95, 6.45 and
    12.25 to 3.50, 5.45 and 10.55 on the smoothed rung at nu 0.3, 0.45 and 0.49 (27.95 and 28.00 at 0.499), and from
    6.25 to 6.00 on the volume rung at 0.45; omega (:data:`STAND_IN_CORRECTION`) 0.3 was within 0.02 of the best of
    0.15-1 in every case.

    Why Pi: for bodies in free flight the translations are the operator's null space but for the masses (A T = M T),
    and CG then changes the total momentum by the sum of its last residual; the V-cycle alone keeps that to rounding of
    the residual's (two bodies colliding, ``examples/scenes/two_bodies.toml``: 1.9e-8 kg m/s over 75 steps), but
    C r carries momentum of its own (9.2e-5 kg m/s unprojected, against a total of 0.52; 1.3e-8 projected, and 263
    CG iterations over the 75 steps against 313 without the correction). With Pi, Pi^T A T = 0: what the correction
    adds moves no momentum where the residual moves none.

    Parameters
    ----------
    matrix : (N, N) sparse
        the stand-in, SPD with 3 x 3 blocks
    exact_diagonal : (N / 3, 3, 3) float
        the operator's diagonal blocks, symmetric positive definite
    weight : float, optional
        omega, >= 0 (default :data:`STAND_IN_CORRECTION`)

    Raises
    ------
    ValueError
        where a block of ``exact_diagonal`` is not positive definite
    """
    from pyamg.util.utils import get_block_diag

    weight = STAND_IN_CORRECTION if weight is None else weight
    exact = np.asarray(exact_diagonal, dtype=np.float64)
    size = matrix.shape[0]
    if exact.shape != (size // 3, 3, 3) or size % 3:
        raise ValueError(f"exact_diagonal has shape {exact.shape}; expected ({size // 3}, 3, 3) for a "
                         f"{matrix.shape} matrix")
    if not (np.isfinite(weight) and weight >= 0):
        raise ValueError(f"weight = {weight!r} is not a finite number >= 0")
    values, vectors = np.linalg.eigh(exact)
    if not (values[:, 0] > 0).all():
        node = int(np.argmin(values[:, 0]))
        raise ValueError(f"exact_diagonal block {node} has eigenvalue {values[node, 0]:.6g}; expected positive "
                         "definite blocks")
    stand_in = sp.bsr_matrix(matrix, blocksize=(3, 3))
    compliance = np.matmul(vectors / values[:, None, :], np.swapaxes(vectors, 1, 2))  # D^-1
    compliance -= np.linalg.inv(get_block_diag(stand_in, blocksize=3, inv_flag=False))
    values, vectors = np.linalg.eigh(0.5 * (compliance + np.swapaxes(compliance, 1, 2)))
    blocks = np.matmul(vectors * (weight * np.maximum(values, 0.0))[:, None, :], np.swapaxes(vectors, 1, 2))
    count = size // 3
    translations = np.tile(np.eye(3), count)  # T^T: (3, N)
    translated = np.ascontiguousarray((stand_in @ translations.T).T)  # (A_s T)^T, A_s symmetric
    return StandInCorrection(sp.bsr_matrix((blocks, np.arange(count, dtype=np.int32),
                                            np.arange(count + 1, dtype=np.int32)), shape=(size, size)),
                             translations, translated, np.linalg.inv(translated @ translations.T))


class _CoarseLU:
    """The coarsest level's sparse LU: what pyamg's ``coarse_grid_solver("splu")`` does, made cheaper.

    Both factorise the matrix without its empty rows and columns (a level with several candidates per aggregate can
    have some). pyamg selects them by two products with a sparse selection matrix, at the factorisation and around
    every solve; here they are picked and put back by index, the same numbers bit for bit (the selection's entries
    are ones): a V-cycle's coarse solve went from 52 to 30 us on the 936-node README beam (mat-vec 59 us). The
    factorisation's column order is the level's own where it pays (:func:`_column_order`). With both, the
    factorisation of the README beam's coarsest level takes 0.53, 0.61 and 0.75 of pyamg's at 936, 10,309 and
    44,541 nodes, and a solve is no dearer than one by index with pyamg's factors (0.38 against 0.46 mat-vecs at 936
    nodes; ``python benchmarks/bench_amg_build.py``, stop 34). Called as pyamg calls a coarse solver,
    ``solver(A, b)``, it solves with the factors of the matrix it was made from (as pyamg's does after its first
    call).

    Raises RuntimeError where SuperLU finds the matrix singular.
    """

    def __init__(self, matrix: sparse.spmatrix):
        if matrix.format == "bsr":
            # The rows of its transpose are its columns: the same CSC arrays as scipy's conversion through CSR, in
            # 0.15 against 0.26 ms at 1k nodes (a whole build 122.8 -> 117.8 mat-vecs; scratch lu45ab.py, stop 45).
            transposed = matrix.T.tocsr()
            csc = sp.csc_matrix((transposed.data, transposed.indices, transposed.indptr), shape=matrix.shape)
        else:
            csc = sp.csc_matrix(matrix)
        csc.eliminate_zeros()
        self.size = csc.shape[0]
        kept = np.flatnonzero(np.diff(csc.indptr))
        self.kept = None if len(kept) == self.size else kept
        if self.kept is not None:
            csc = csc[kept][:, kept]
        csc.sort_indices()
        self.LU = spla.splu(csc, permc_spec=_column_order(csc))

    def solve(self, b: np.ndarray) -> np.ndarray:
        """(N,) -- the solution of the coarsest system for (N,) ``b`` (0 in the empty rows)."""
        if self.kept is None:
            return self.LU.solve(np.ravel(b))
        y = self.LU.solve(np.ravel(b)[self.kept])
        x = np.zeros(self.size, dtype=y.dtype)
        x[self.kept] = y
        return x

    def __call__(self, matrix: sparse.spmatrix, b: np.ndarray) -> np.ndarray:
        return self.solve(b)

    @staticmethod
    def name() -> str:  # pyamg's MultilevelSolver.__repr__ asks its coarse solver for one
        return "splu"


class _Triangles:
    """A square sparse matrix held as two triangles, for Gauss-Seidel sweeps that cost half a mat-vec from a zero guess.

    ``lower`` holds the matrix's entries on and left of the diagonal, ``upper`` those on and right of it, so
    the diagonal is held twice and nothing else. A forward sweep from x = 0 reads only the lower triangle
    (x_j is still 0 right of the diagonal): it solves (D + L) z = r, and then the residual r - A z is
    -U z = D z - (D + U) z, without the rest of A. Each is half a mat-vec where pyamg's cycle spends one on
    each. A backward sweep reads both: r - L z from ``lower``, then the sweep over ``upper``. The V-cycle of the
    README beam went from 6.3 to 5.1 mat-vecs at 10k nodes and from 13.3 to 10.3 at 45k, the same cycle to
    rounding (``python benchmarks/bench_vcycle.py`` prints a step's parts).

    Parameters
    ----------
    matrix : (N, N) CSR, or BSR with square blocks
        Sorted, no duplicates. CSR is swept point-wise; BSR by blocks, or point-wise (``point_wise``): then the
        triangles are CSR and the diagonal blocks' entries on the other side of the diagonal are stored as zeros
        (the blocks' layout stays whole, so :meth:`whole` gives the BSR matrix back entry for entry).
    point_wise : bool
        Sweep a BSR matrix entry by entry.
    dtype : numpy dtype, optional
        Of the stored triangles (default the matrix's). The sweeps take vectors of any float type and run in this
        one; ``whole`` gives the matrix back rounded to it.

    It stands in for the matrix on a pyamg level: ``shape``, ``nnz``, ``format``, ``dtype``, ``@``, and the level's
    smoothers :meth:`forward` and :meth:`backward` for any x (pyamg's own cycle and ``solve`` run on it too).
    """

    def __init__(self, matrix, *, point_wise: bool = False, dtype=None):
        if not matrix.has_sorted_indices:
            raise ValueError("triangles are made from a matrix with sorted indices")
        self.shape, self.nnz = matrix.shape, matrix.nnz
        self.dtype = np.dtype(matrix.dtype if dtype is None else dtype)
        blocked = matrix.format == "bsr"
        size = matrix.blocksize[0] if blocked else 1
        made = _compiled_point_triangles(matrix, self.dtype) if blocked and point_wise else None
        if made is None:
            halves = []
            for keep, half in _halves(matrix, self.dtype):
                # One half at a time, its block form dropped at once: they are made after a build, at its peak memory.
                halves.append(_scalar_triangle(half, keep) if blocked and point_wise else half)
                del half
            made = (*halves, None)
            del halves
        lower, upper, diagonal = made
        del made
        self.blocksize = (size, size) if blocked else None
        self.inverse = None
        if blocked and not point_wise:
            from pyamg.util.utils import get_block_diag

            self.inverse = get_block_diag(matrix, blocksize=size, inv_flag=True).astype(self.dtype, copy=False)
        self.lower, self.upper = lower, upper
        self.format = lower.format
        if diagonal is None:
            diagonal = _block_diagonal(lower, size) if self.inverse is not None else lower.diagonal()
        self.diagonal = diagonal

    def _diagonal_times(self, x: np.ndarray) -> np.ndarray:
        if self.inverse is None:
            return self.diagonal * x
        size = self.diagonal.shape[1]
        return np.einsum("nij,nj->ni", self.diagonal, x.reshape(-1, size)).reshape(x.shape)

    def _sweep(self, triangle, x: np.ndarray, b: np.ndarray, direction: str) -> None:
        """One sweep over ``triangle`` in place on ``x``, in the triangles' dtype (pyamg's kernels take one type)."""
        from pyamg.relaxation.relaxation import block_gauss_seidel, gauss_seidel

        b = np.asarray(b, dtype=self.dtype)
        swept = x if x.dtype == self.dtype else x.astype(self.dtype)
        if self.inverse is None:
            gauss_seidel(triangle, swept, b, iterations=1, sweep=direction)
        else:
            block_gauss_seidel(triangle, swept, b, iterations=1, sweep=direction, blocksize=len(self.inverse[0]),
                               Dinv=self.inverse)
        if swept is not x:
            x[...] = swept

    def forward_from_zero(self, r: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """z = (D + L)^-1 r, a forward sweep from x = 0, and the residual r - A z = -U z (both in the triangles'
        dtype)."""
        z = np.zeros(r.shape, dtype=self.dtype)
        self._sweep(self.lower, z, r, "forward")
        return z, self._diagonal_times(z) - self.upper @ z

    def forward(self, x: np.ndarray, b: np.ndarray) -> None:
        """One forward Gauss-Seidel sweep on A x = b from any x, in place."""
        self._sweep(self.lower, x, b - (self.upper @ x - self._diagonal_times(x)), "forward")

    def backward(self, x: np.ndarray, b: np.ndarray) -> None:
        """One backward Gauss-Seidel sweep on A x = b from any x, in place."""
        self._sweep(self.upper, x, b - (self.lower @ x - self._diagonal_times(x)), "backward")

    def __matmul__(self, x: np.ndarray) -> np.ndarray:
        return self.lower @ x + (self.upper @ x - self._diagonal_times(x))

    def plus(self, change: sp.spmatrix) -> _Triangles:
        """The triangles of this matrix plus a symmetric ``change`` (sparse, any pattern: its entries on and left of
        the diagonal join ``lower``, those on and right of it ``upper``), as a new object; this one is untouched.
        In this one's dtype, or in double where the change is outside single precision's range (see
        :data:`SINGLE_PRECISION_RANGE`). The sum's triangles keep only its nonzero entries (scipy's sum), so
        :meth:`whole` is for triangles made from a matrix."""
        blocked = self.inverse is not None  # swept by blocks (else point-wise: the change's entries split one by one)
        change = sp.bsr_matrix(change, blocksize=self.blocksize) if blocked else sp.csr_matrix(change)
        if not change.has_canonical_format:
            change = change.copy()  # sorted and summed in place: not the caller's arrays
            _sum_duplicates(change)
        dtype = self.dtype
        if dtype != np.float64 and change.nnz and np.abs(change.data).max() > SINGLE_PRECISION_RANGE:
            dtype = np.dtype(np.float64)
        (_, lower), (_, upper) = _halves(change, dtype)
        new = copy.copy(self)
        new.dtype = dtype
        new.lower = self.lower.astype(dtype, copy=False) + lower
        new.upper = self.upper.astype(dtype, copy=False) + upper
        if blocked:
            from pyamg.util.utils import get_block_diag

            size = change.blocksize[0]
            new.diagonal = _block_diagonal(new.lower, size)
            # Pseudo-inverses, as pyamg's (and __init__): a coarse level can hold a block with empty rows (an aggregate
            # whose candidates are dependent).
            new.inverse = get_block_diag(new.lower, blocksize=size, inv_flag=True).astype(dtype, copy=False)
        else:
            new.diagonal = new.lower.diagonal()
        return new

    def whole(self):
        """The matrix the triangles were made from, entry for entry (BSR for a blocked one, else CSR)."""
        size = 1 if self.blocksize is None else self.blocksize[0]
        lower, upper = self.lower, self.upper
        if self.blocksize is not None and self.inverse is None:  # point-wise triangles of a BSR matrix
            lower, upper = sp.bsr_matrix(lower, blocksize=self.blocksize), sp.bsr_matrix(upper, blocksize=self.blocksize)
        nodes = self.shape[0] // size
        lower_rows = np.repeat(np.arange(nodes), np.diff(lower.indptr))
        upper_rows = np.repeat(np.arange(nodes), np.diff(upper.indptr))
        right = upper.indices > upper_rows  # the diagonal comes from the lower triangle...
        data = np.concatenate([lower.data, upper.data[right]])
        if self.blocksize is not None and self.inverse is None:
            # ...but for point-wise triangles each side holds only its own half of a diagonal block.
            on_diagonal = np.flatnonzero(lower.indices == lower_rows)
            above = np.triu(np.ones(self.blocksize, dtype=bool), 1)
            data[on_diagonal] = np.where(above, upper.data[upper.indices == upper_rows], data[on_diagonal])
        order = np.argsort(np.concatenate([lower_rows, upper_rows[right]]), kind="stable")
        indices = np.concatenate([lower.indices, upper.indices[right]])[order]
        indptr = np.concatenate([[0], np.cumsum(np.bincount(lower_rows, minlength=nodes) +
                                                np.bincount(upper_rows[right], minlength=nodes))])
        kind = sp.bsr_matrix if self.blocksize is not None else sp.csr_matrix
        return kind((data[order], indices.astype(lower.indices.dtype), indptr.astype(lower.indptr.dtype)),
                    shape=self.shape)


def _transposed(level) -> bool:
    """Whether ``level``'s R is a view of its P's arrays (:func:`_single_transfer`)."""
    P, R = getattr(level, "P", None), getattr(level, "R", None)
    return P is not None and R is not None and R.format == "csc" and np.shares_memory(R.data, P.data)


def _single_transfer(level, dtype) -> None:
    """Hold ``level``'s prolongator P as CSR in ``dtype`` (the finest level's single precision) and its restriction R
    as P's transpose, a CSC view of the same arrays, in place of P and R as double BSR: 4 bytes less per entry, an
    index per entry instead of per block, and no second copy for R (0.61 instead of 1.22 KiB per node at 45k nodes),
    for a V-cycle as fast (the products of a single-precision CSR matrix cost about those of a double BSR one: the
    cycle's correction is cast to single before it is prolonged, so that scipy does not upcast a copy of P each
    time; ``python benchmarks/study_amg_levers.py --variants base finest_double``)."""
    prolongation = level.P
    level.R = None  # the BSR transpose goes first (peak memory)
    if prolongation.format == "bsr":  # cast by blocks first: no double-precision CSR copy
        prolongation = sp.bsr_matrix((prolongation.data.astype(dtype), prolongation.indices, prolongation.indptr),
                                     shape=prolongation.shape)
    level.P = sp.csr_matrix(prolongation, dtype=dtype)
    del prolongation
    level.R = level.P.T


def _finest_dtype(matrix) -> np.dtype:
    """:data:`FINEST_DTYPE` when ``matrix`` is within :data:`SINGLE_PRECISION_RANGE`, else its own dtype."""
    data = matrix.data
    largest = max(float(data.max()), -float(data.min())) if data.size else 0.0
    diagonal = np.abs(matrix.diagonal())
    smallest = float(diagonal.min()) if diagonal.size else np.inf
    inside = largest <= SINGLE_PRECISION_RANGE and smallest >= 1 / SINGLE_PRECISION_RANGE
    if not inside:
        logger.debug("finest AMG level held in double precision: largest entry %.3g, smallest diagonal %.3g",
                     largest, smallest)
    return np.dtype(FINEST_DTYPE if inside else matrix.dtype)


def _halves(matrix, dtype):
    """("lower", the entries (or blocks) of a CSR (or BSR) ``matrix`` with sorted indices on and left of the
    diagonal), then ("upper", those on and right of it), as ``dtype``: one at a time (see :class:`_Triangles`)."""
    size = matrix.blocksize[0] if matrix.format == "bsr" else 1
    rows = np.repeat(np.arange(matrix.shape[0] // size, dtype=matrix.indices.dtype), np.diff(matrix.indptr))
    yield "lower", _rows_where(matrix, rows, matrix.indices <= rows, dtype)
    yield "upper", _rows_where(matrix, rows, matrix.indices >= rows, dtype)


def _rows_where(matrix, rows: np.ndarray, where: np.ndarray, dtype=None):
    """The entries (or blocks) of a CSR (or BSR) ``matrix``, in rows ``rows``, where ``where`` holds, as ``dtype``
    (default the matrix's); same format."""
    counts = np.bincount(rows[where], minlength=len(matrix.indptr) - 1)
    indptr = np.concatenate([[0], np.cumsum(counts)]).astype(matrix.indptr.dtype)
    kind = sp.bsr_matrix if matrix.format == "bsr" else sp.csr_matrix
    data = matrix.data[where].astype(matrix.dtype if dtype is None else dtype, copy=False)
    return kind((data, matrix.indices[where], indptr), shape=matrix.shape)


def _scalar_triangle(blocks: sp.bsr_matrix, keep: str) -> sp.csr_matrix:
    """The CSR form of a BSR triangle (every block whole, sorted), zeros stored for its diagonal blocks' entries on the
    other side of the diagonal. The diagonal block is the last of its block row in the lower triangle, the first in
    the upper one, so those entries are found from the row pointers alone (no array per entry: this runs at a
    build's peak memory)."""
    size, count = blocks.blocksize[0], blocks.shape[0] // blocks.blocksize[0]
    ends = blocks.indptr[1:] - 1 if keep == "lower" else blocks.indptr[:-1]
    if not (np.diff(blocks.indptr) > 0).all() or not (blocks.indices[ends] == np.arange(count)).all():
        raise ValueError("every block row needs its diagonal block for Gauss-Seidel")
    scalar = blocks.tocsr()
    other = np.triu(np.ones((size, size), dtype=bool), 1) if keep == "lower" else np.tril(np.ones((size, size), bool), -1)
    within, column = np.nonzero(other)  # row and column inside the block of each entry to clear
    rows = size * np.arange(count)[:, None] + within
    positions = scalar.indptr[rows + 1] - size + column if keep == "lower" else scalar.indptr[rows] + column
    scalar.data[positions.ravel()] = 0.0
    return scalar


def _compiled_point_triangles(blocks: sp.bsr_matrix,
                              dtype) -> tuple[sp.csr_matrix, sp.csr_matrix, np.ndarray] | None:
    """The point-wise triangles of a BSR matrix of square blocks with sorted block columns, in ``dtype``, as
    :func:`_halves` and :func:`_scalar_triangle` make them, and the lower one's diagonal, entry for entry, by one
    compiled pass (:func:`volspring._compiled.point_triangles`) where the kernels run (else None)."""
    kernels = compiled()
    if kernels is None or blocks.blocksize[0] != blocks.blocksize[1]:
        return None
    size, count = blocks.blocksize[0], blocks.shape[0] // blocks.blocksize[0]
    indptr, indices = unsigned(blocks.indptr), unsigned(blocks.indices)
    diagonal = np.empty(count, dtype=np.int64)
    kernels.diagonal_blocks(indptr, indices, diagonal)
    if (diagonal < 0).any():
        raise ValueError("every block row needs its diagonal block for Gauss-Seidel")
    below = int((diagonal - blocks.indptr[:-1]).sum()) + count  # blocks on and left of the diagonal
    above = blocks.indptr[-1] - below + count
    index_type = np.int32 if max(blocks.nnz, blocks.shape[0]) <= np.iinfo(np.int32).max else np.int64  # tocsr's
    halves = []
    for stored in (below, above):
        halves.append((np.empty(size * size * stored, dtype=dtype), np.empty(size * size * stored, dtype=index_type),
                       np.empty(blocks.shape[0] + 1, dtype=index_type)))
    (lower_data, lower_indices, lower_indptr), (upper_data, upper_indices, upper_indptr) = halves
    entries = np.empty(blocks.shape[0], dtype=dtype)
    kernels.point_triangles(indptr, indices, blocks.data, diagonal, unsigned(lower_indptr), unsigned(lower_indices),
                            lower_data, unsigned(upper_indptr), unsigned(upper_indices), upper_data, entries)
    lower, upper = (sp.csr_matrix(half, shape=blocks.shape) for half in halves)
    return lower, upper, entries


def _block_diagonal(matrix: sp.bsr_matrix, size: int) -> np.ndarray:
    """(N / size, size, size) -- the diagonal blocks of a BSR triangle (one per block row, each present)."""
    rows = np.repeat(np.arange(matrix.shape[0] // size), np.diff(matrix.indptr))
    on_diagonal = matrix.indices == rows
    if on_diagonal.sum() != matrix.shape[0] // size:
        raise ValueError("every block row needs its diagonal block for block Gauss-Seidel")
    return matrix.data[on_diagonal]


@dataclass(frozen=True)
class _Source:
    """What a hierarchy is built from: enough to rebuild it bit for bit (after unpickling)."""

    # Frozen copy of the fine matrix. With the default smoother it is the triangles of the hierarchy's finest level
    # (one copy, the same object, in single precision within its range), except for a two-level cycle.
    matrix: sp.spmatrix | _Triangles
    # (N, k) or, with a prolongation, (n, k); None once the default smoother's levels are the kept copy (a pickle
    # carries them: nothing is rebuilt from the source then).
    near_null_space: np.ndarray | None
    prolongation: sp.spmatrix | None = None  # (N, n): coarse space of a two-level cycle
    # The couplings of ``matrix`` that neither decide the aggregates nor smooth the prolongators: the matrix minus the
    # build's ``aggregation`` (contact, a few rows), CSR; None: none.
    excluded: sp.csr_matrix | None = None
    # What the preconditioner adds to the cycle where ``matrix`` stands in for CG's operator (stand_in_correction).
    correction: StandInCorrection | None = None


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
        large mass ratios bring, so it is not offered. With the default every level but the coarsest is
        held as its two triangles (:class:`_Triangles`), which makes each sweep from a zero guess and the
        residual after it half a mat-vec each; the finest level's triangles are also the kept copy of the
        built matrix. They are held and swept in single precision (:data:`FINEST_DTYPE`), and so are the
        finest level's prolongator P (as CSR) and restriction R (P's transpose, a view of the same arrays);
        CG, its products and the coarser levels stay in double. On the README beam at 45k nodes the triangles
        hold 1.08 KiB per node instead of 1.61 and P with R 0.61 instead of 1.22, and a V-cycle costs 9.5-9.9
        mat-vecs instead of 10.3-10.6, for the same CG iterations (``python benchmarks/study_amg_levers.py
        --nodes 45000 --variants base finest_double``); the cycle is then symmetric to single-precision
        rounding (about 1e-7 relative), which left CG's iterations unchanged down to rtol 1e-9 there (0-3%
        more at nu 0.499 on the springs+volume and smoothed rungs, which need 30-290 either way). The
        coarser levels' block products and sweeps are slower in single precision (scipy's and pyamg's
        kernels: 10-25% per product) and stay double.
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
    the default pseudo-inverse spent 1.3 s of a 3.9 s setup in a dense SVD, for the same cycle. It is
    factorised in its own (banded) order where that is cheap to see it pays, else in SuperLU's
    COLAMD order (:func:`_column_order`).
    The candidates B are used as given (pyamg's ``improve_candidates`` is not applied): rigid-body
    modes are already the near-null space, and relaxing them first doubled the setup time for the
    same iteration counts (measured on 10k and 50k-node beams). The levels are built by
    :func:`_smoothed_aggregation` from pyamg's aggregation (its builder's own hierarchy to rounding,
    with fewer copies of the matrix).

    The hierarchy is built from an explicit :meth:`build` call (or the first solve) and kept;
    it is a frozen copy, so later refills of the matrix do not disturb it. The V-cycle is
    applied through :func:`_v_cycle` (pyamg's cycle on its levels, without the two residual norms its
    public preconditioner adds, on triangles where the levels are held so).

    Two-level cycle: :meth:`build` with a ``prolongation`` P (N, n) builds the hierarchy on the
    Galerkin coarse matrix P^T A P (``near_null_space`` then has n rows) and preconditions with
    one forward Gauss-Seidel sweep on A, the V-cycle on the restricted residual, and one backward
    sweep (symmetric, so CG still applies). This is the p-multigrid of the P2 finite-element
    references (:mod:`validation.fem_solvers`), where smoothed aggregation on the P2 matrix itself
    stalled.

    Pickling: a pyamg hierarchy does not pickle (its smoothers and coarse solver are closures), so
    a pickled solver leaves :attr:`hierarchy` at None and the next :meth:`solve` or
    :meth:`precondition` makes it again (counted in ``setup_seconds``). With the default smoother its
    levels travel in the pickle (the finest as the built triangles), since the double-precision matrix
    they were built from is not kept: only the coarse LU is factorised again. With the others the
    pickle keeps the frozen matrix and near-null space, and the hierarchy is rebuilt from them (counted
    in ``build_count`` too). Both are deterministic, so the hierarchy, and every answer, is the same
    bit for bit.

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
        self._levels: list | None = None  # an unpickled hierarchy's levels, until the next use puts them together
        # The built level matrices while refresh()'s or update()'s are held, else None.
        self._built_levels: list | None = None
        self._pending: sp.csr_matrix | None = None  # update()'s change, put on the levels at the next precondition()

    @property
    def hierarchy(self) -> Any:
        """The pyamg ``MultilevelSolver``; None before the first build, and after unpickling until
        the next :meth:`solve` or :meth:`precondition` rebuilds it."""
        return self._hierarchy

    def __getstate__(self):
        state = self.__dict__.copy()
        state["_hierarchy"] = state["_cycle"] = state["_built_levels"] = None  # closures inside: made again on use
        hierarchy, source = self._hierarchy, self._source
        if hierarchy is not None and source is not None and isinstance(source.matrix, _Triangles) \
                and source.prolongation is None:
            # The finest level's triangles are the kept copy, rounded to FINEST_DTYPE: the matrix the levels were
            # built from is gone, so the levels travel (the finest as the built triangles, not a refresh's).
            # A restriction held as a view of its prolongator's arrays travels as None (made again as P^T).
            built = [level.A for level in hierarchy.levels] if self._built_levels is None else self._built_levels
            state["_levels"] = [(None if index == 0 else matrix, getattr(level, "P", None),
                                 None if _transposed(level) else getattr(level, "R", None), level.B)
                                for index, (level, matrix) in enumerate(zip(hierarchy.levels, built))]
        return state

    def __setstate__(self, state):
        self.__dict__.update(state)
        self.__dict__.setdefault("_levels", None)  # pickled before the levels travelled
        self.__dict__.setdefault("_built_levels", None)
        self.__dict__.setdefault("_pending", None)

    def _unpickled(self) -> bool:
        """Make the hierarchy and its cycle again after unpickling: from the pickled levels, or rebuilt from the kept
        matrix (deterministic: the same bits either way). Returns whether it was rebuilt."""
        if self._levels is None:
            self._construct()
            return True
        from pyamg.multilevel import MultilevelSolver

        source, levels = self._source, []
        assert source is not None  # levels travel with their source
        for index, (matrix, prolongation, restriction, candidates) in enumerate(self._levels):
            level = MultilevelSolver.Level()
            level.A, level.B = source.matrix if index == 0 else matrix, candidates
            if prolongation is not None:
                level.P, level.R = prolongation, prolongation.T if restriction is None else restriction
            levels.append(level)
        hierarchy = MultilevelSolver(levels, coarse_solver="splu")
        self._set_triangles(hierarchy, source.matrix)
        self._adopt(hierarchy)
        self._levels = None
        return False

    def build(self, matrix: sparse.spmatrix, near_null_space: ArrayLike, *,
              prolongation: sparse.spmatrix | None = None, aggregation: sparse.spmatrix | None = None,
              exact_diagonal: np.ndarray | None = None) -> float:
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
            The matrix whose couplings decide the aggregates and smooth the prolongators (default ``matrix``),
            equal to ``matrix`` but in a few rows, for couplings that should not join nodes into one aggregate:
            contact between two bodies. Their difference C = ``matrix`` - ``aggregation`` is kept out of every
            level: level k + 1 aggregates and smooths by its Galerkin matrix minus P_k^T C_k P_k. The coarse
            operators are the Galerkin products of ``matrix``, contact included.

            Why: an aggregate across a contact interface makes both sides move as one rigid piece in the coarse
            space, which they do not (they slide and part). On a cube resting on another (729 nodes each), a
            hierarchy aggregated with the contact needed 10-13 CG iterations where the same step without contact
            needed 6, and 5-6 aggregated without it on the finest level (``benchmarks/bench_contact_cg.py``). At
            4,913 nodes a cube the first coarse level's own aggregates crossed the interface: 12 iterations with the
            contact kept out of the finest level only, 8 with it kept out of every level (6 without contact). A
            prolongator smoothed with the contact spreads each aggregate across the interface too.
        exact_diagonal : (N / 3, 3, 3) float, optional
            Where ``matrix`` is a stand-in for the operator CG iterates on (element sets applied as products): that
            operator's diagonal blocks. The preconditioner then adds :func:`stand_in_correction` to its V-cycle.
        """
        start = self.timer()
        correction = None if exact_diagonal is None else stand_in_correction(matrix, exact_diagonal)
        near_null_space = np.ascontiguousarray(near_null_space, dtype=np.float64)
        coarse_size = matrix.shape[0] if prolongation is None else prolongation.shape[1]
        if prolongation is not None and prolongation.shape[0] != matrix.shape[0]:
            raise ValueError(f"prolongation has shape {prolongation.shape}, expected ({matrix.shape[0]}, n) "
                             f"for a {matrix.shape} matrix")
        if near_null_space.ndim != 2 or near_null_space.shape[0] != coarse_size:
            raise ValueError(f"near_null_space has shape {near_null_space.shape}, expected ({coarse_size}, k)")
        if self.smoother == "gauss_seidel" and prolongation is None and matrix.format == "bsr" and \
                matrix.blocksize == (3, 3) and matrix.has_canonical_format:
            # pyamg builds from the matrix as given (it only reads a canonical one), and the kept copy is the
            # triangles made after the build: no third copy at the build's peak (1 KiB per node).
            frozen = matrix
        else:
            frozen = matrix.copy() if matrix.format in ("csr", "bsr") else matrix.tocsr()
            # Canonical (sorted, summed) up front: pyamg sorts the indices in place, and a hierarchy rebuilt
            # from the sorted matrix (after unpickling) would otherwise differ from one built before.
            _sum_duplicates(frozen)
        excluded = None
        if aggregation is not None:
            if prolongation is not None or aggregation.shape != matrix.shape:
                given = " with a prolongation" if prolongation is not None else ""
                raise ValueError(f"aggregation must have the matrix's shape {matrix.shape} and no prolongation; got "
                                 f"shape {aggregation.shape}{given}")
            excluded = sp.csr_matrix(frozen) - sp.csr_matrix(aggregation)  # exact zeros where they agree
            excluded.eliminate_zeros()
            entries = excluded.tocoo()
            outside = np.flatnonzero(_stored_at(frozen, entries.row, entries.col)[0] < 0)
            if len(outside):
                row, column = int(entries.row[outside[0]]), int(entries.col[outside[0]])
                raise ValueError(f"aggregation has a coupling the matrix does not store, entry ({row}, {column}) "
                                 f"= {sp.csr_matrix(aggregation)[row, column]:.6g}; expected couplings within the "
                                 f"matrix's pattern ({len(outside)} such entries)")
            excluded = excluded if excluded.nnz else None
        self._levels = self._built_levels = self._pending = None
        self._source = _Source(frozen, near_null_space,
                               None if prolongation is None else sp.csr_matrix(prolongation), excluded=excluded,
                               correction=correction)
        cached = set(vars(matrix))
        self._construct()
        if frozen is matrix:
            for name in set(vars(matrix)) - cached:  # pyamg's caches (block_D_inv, symmetry) stay off the caller's matrix
                delattr(matrix, name)
            kept_as_given = self._source.matrix is matrix
            if kept_as_given:  # a single level: no triangles replaced it, so keep a copy after all
                copy = matrix.copy()
                self._source = replace(self._source, matrix=copy)
                self._hierarchy.levels[0].A = copy
        seconds = self.timer() - start
        logger.debug("built AMG hierarchy: %s levels, operator complexity %.2f, %.3f s",
                     len(self._hierarchy.levels), self._hierarchy.operator_complexity(), seconds)
        return seconds

    def _construct(self):
        """Build the pyamg hierarchy and its cycle from ``self._source`` (deterministic)."""
        source = self._source
        if source is None:
            raise ValueError("the AMG hierarchy has no source: call build(matrix, near_null_space) first")
        modes = source.near_null_space
        assert modes is not None  # dropped only where the levels are the kept copy, never rebuilt from the source
        matrix = source.matrix
        if source.prolongation is not None:
            matrix = (source.prolongation.T @ matrix @ source.prolongation).tocsr()
        elif isinstance(matrix, _Triangles):  # a rebuild of a solver pickled before its levels travelled
            matrix = matrix.whole().astype(np.float64, copy=False)
        hierarchy = _smoothed_aggregation(matrix, modes, theta=self.strength_theta, excluded=source.excluded,
                                          max_coarse=self.max_coarse)
        if self.strength_theta and hierarchy.operator_complexity() > 2.5:
            # Dropping weak couplings can slow coarsening on odd meshes: fall back to keeping all.
            hierarchy = _smoothed_aggregation(matrix, modes, theta=0.0, excluded=source.excluded,
                                              max_coarse=self.max_coarse)
        del matrix, modes  # the whole matrix made from kept triangles goes once the hierarchy is built (peak memory)
        if self.smoother == "gauss_seidel" and len(hierarchy.levels) > 1:
            finest = hierarchy.levels[0].A
            if isinstance(source.matrix, _Triangles):
                finest = source.matrix
            else:
                # Point-wise sweeps on every matrix of 3x3 blocks: pyamg's block sweep there costs 3.5 times as much.
                finest.sort_indices()  # a two-level cycle's coarse space comes out of a product unsorted
                # Single precision where the triangles become the kept copy (a two-level cycle's are made from it).
                dtype = _finest_dtype(finest) if source.prolongation is None else finest.dtype
                # What shrinks goes first (the build's peak memory): P and R in the finest level's precision, the
                # coarse levels' triangles in place of their matrices; then the finest level's triangles.
                if dtype != hierarchy.levels[1].A.dtype:
                    _single_transfer(hierarchy.levels[0], dtype)
                self._coarse_triangles(hierarchy)
                finest = _Triangles(finest, point_wise=True, dtype=dtype)
                if source.prolongation is None:
                    # A new build: from now on the triangles are the kept copy, and the levels themselves what a
                    # pickle carries, so the near-null space (48 bytes an unknown) is not needed again.
                    source = self._source = replace(source, matrix=finest, near_null_space=None)
                    hierarchy.levels[0].B = None
            self._set_triangles(hierarchy, finest)
        else:
            self._set_smoothers(hierarchy)
        self._adopt(hierarchy)
        self.build_count += 1

    def _adopt(self, hierarchy) -> None:
        """Factorise the coarsest level and make the cycle of ``hierarchy``, now the solver's."""
        self._built_levels = None
        coarsest = hierarchy.levels[-1].A
        try:
            if len(hierarchy.levels) > 1:
                hierarchy.coarse_solver = _CoarseLU(coarsest)
            else:  # a single level's solver is its cycle, pyamg's own: it factorises lazily, so count it here
                hierarchy.coarse_solver(coarsest, np.zeros(coarsest.shape[0]))
        except RuntimeError:  # a singular coarsest matrix (statics of a barely held body): pseudo-inverse
            from pyamg.multilevel import coarse_grid_solver

            hierarchy.coarse_solver = coarse_grid_solver("pinv")
            hierarchy.coarse_solver(coarsest, np.zeros(coarsest.shape[0]))
        self._hierarchy, self._cycle = hierarchy, _v_cycle(hierarchy)

    def _set_smoothers(self, hierarchy) -> None:
        """(Re)make the smoothers from the levels' current matrices: the finest level's point-wise sweeps, every
        level's block sweeps, or block Jacobi weighted by a bound per level (``self.smoother``)."""
        from pyamg.relaxation.smoothing import change_smoothers

        if self.smoother == "gauss_seidel" or len(hierarchy.levels) == 1:
            return  # the point-wise sweeps take the matrix they are given; one level is the coarse solver alone
        if self.smoother == "block_gauss_seidel":
            pre, post = ("block_gauss_seidel", {"sweep": "forward"}), ("block_gauss_seidel", {"sweep": "backward"})
            change_smoothers(hierarchy, [pre], [post])
            return
        weighted = [("block_jacobi", {"omega": BLOCK_JACOBI_OMEGA / _block_jacobi_bound(level.A),
                                      "iterations": 1, "withrho": False})
                    for level in hierarchy.levels[:-1]]
        change_smoothers(hierarchy, weighted, weighted)

    @staticmethod
    def _set_triangles(hierarchy, finest: _Triangles) -> None:
        """Every level but the coarsest held as its triangles, swept by them (see :func:`_v_cycle`): the finest as
        ``finest`` (point-wise), the coarser ones by blocks."""
        levels = hierarchy.levels
        levels[0].A = finest
        AMGConjugateGradient._coarse_triangles(hierarchy)
        for level in levels[:-1]:
            level.presmoother, level.postsmoother = _forward_sweep, _backward_sweep

    @staticmethod
    def _coarse_triangles(hierarchy) -> None:
        """The levels between the finest and the coarsest held as their triangles (swept by blocks)."""
        for level in hierarchy.levels[1:-1]:
            if not isinstance(level.A, _Triangles):
                level.A.sort_indices()  # pyamg's Galerkin products need not sort them
                level.A = _Triangles(level.A)

    def refresh(self, matrix: sparse.spmatrix) -> None:
        """Put ``matrix`` under the hierarchy's finest level (its smoother and residuals), keeping the coarse levels
        as built (an :meth:`update` is undone first).

        For a system whose fine matrix changed in a few rows since the build, as contact changes from
        step to step: the fine smoother then sees the current contact stiffness, while the coarse
        levels (the expensive part of a build) are kept. The implicit integrator gives contact to the hierarchy
        by :meth:`update` instead, which reaches the first coarse level too and costs less than splitting a whole
        matrix into triangles. Measured on two 216-node cubes pressed
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
        built = self._built()
        if isinstance(source.matrix, _Triangles):
            finest = source.matrix
            given = sp.bsr_matrix(matrix, blocksize=finest.blocksize) if finest.blocksize else sp.csr_matrix(matrix)
            if not given.has_canonical_format:
                given = given.copy()
                _sum_duplicates(given)
            held = _Triangles(given, point_wise=True, dtype=_finest_dtype(given))
        else:
            held = sp.bsr_matrix(matrix, blocksize=(3, 3))
        self._hold([held, *built[1:]], built)

    def update(self, change: sparse.spmatrix) -> None:
        """Hold the built matrix plus ``change`` on the finest level and its Galerkin product on the next
        :data:`UPDATE_DEPTH` - 1 levels above the coarsest, keeping the prolongators and the coarsest level as built.
        :meth:`restore` puts the built levels back.

        The levels are made at the next :meth:`precondition` (the built ones are held until then): a solve whose
        starting guess already meets its tolerance, as most steps of a resting contact do, does not pay for them.

        For contact, which changes from step to step in a few rows. The prolongators are made without it (the build's
        ``aggregation``), so the hierarchy sees contact only in its level matrices; with the change in them it is
        the hierarchy a build with this contact would make, less the elastic changes since the build, on the levels
        updated. Measured on two cubes of 4,913 nodes each (``benchmarks/bench_contact_cg.py --cells 16 --steps
        25``; CG from zero, a contact step's iterations over the same step's without contact, median / max): with
        only the finest level given the step's system (:meth:`refresh`, before), pressed 1.50 / 1.67 and drop
        1.50 / 1.83; with the finest and the first coarse level updated, 1.33 / 1.50 and 1.00 / 1.33; with the
        coarsest too, 1.17 / 1.33 and 1.00 / 1.17, but its factorisation costs as much as the rest (74 ms at 1,800
        unknowns). The cost is in the touched rows: their rows of P in the Galerkin product, and one sum per level.

        Parameters
        ----------
        change : (N, N) sparse
            symmetric, and zero outside a few rows and columns (only those rows of P are multiplied): what the system
            gained since the build (contact now minus contact then)
        """
        hierarchy, source = self.hierarchy, self._source
        if hierarchy is None or source is None:
            raise ValueError("the AMG hierarchy is not built: call build(matrix, near_null_space) first")
        if source.prolongation is not None:
            raise ValueError("update() applies to a hierarchy built on the matrix itself, not a two-level one")
        levels = hierarchy.levels
        if change.shape != levels[0].A.shape:
            raise ValueError(f"change has shape {change.shape}; the hierarchy was built for {levels[0].A.shape}")
        self.restore()
        change = sp.csr_matrix(change, dtype=np.float64, copy=True)  # the caller's arrays stay as they are
        change.eliminate_zeros()
        self._pending = change if change.nnz else None

    def _apply_pending(self) -> None:
        """Put :meth:`update`'s change on the levels (see there)."""
        change, self._pending = self._pending, None
        assert change is not None
        levels = self.hierarchy.levels
        built = self._built()
        matrices = list(built)
        for index in range(min(UPDATE_DEPTH, len(levels) - 1)):
            if index:
                blocks = (_blocksize(built[index - 1]), _blocksize(built[index]))
                change = _galerkin_rows(levels[index - 1].P, change, blocks)
                change.eliminate_zeros()
            if not change.nnz:
                break
            matrices[index] = _plus(built[index], change)
        self._hold(matrices, built)

    def _built(self) -> list:
        """The built matrix of every level (the finest as the kept copy), with the built levels back in place."""
        source = self._source
        assert source is not None  # refresh() and update() check for a build first
        self.restore()
        built = [level.A for level in self.hierarchy.levels]
        built[0] = source.matrix
        return built

    def _hold(self, matrices: list, built: list) -> None:
        """Hold ``matrices`` on the hierarchy's levels, ``built`` kept for :meth:`restore`; the cycle reads each level's
        matrix as it runs, and the smoothers of other smoothers than the default are made again."""
        for level, matrix in zip(self.hierarchy.levels, matrices):
            level.A = matrix
        if not isinstance(matrices[0], _Triangles):
            self._set_smoothers(self.hierarchy)
        self._built_levels = None if matrices is built else built

    def restore(self) -> None:
        """Put the built matrices back on the levels after :meth:`refresh` or :meth:`update`, and drop a change
        :meth:`update` has not yet put on them (nothing to do otherwise).

        Why: the preconditioner of a step must depend on the build and that step's own system only. A refresh
        kept after contact ends would make the steps that follow depend on the last contact step, which a run
        resumed from a checkpoint (whose hierarchy is rebuilt from the recorded build) does not have.
        """
        built, self._pending = self._built_levels, None
        if self.hierarchy is not None and built is not None:
            self._hold(built, built)

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
            self._unpickled()  # the same hierarchy again
        if self._pending is not None:
            self._apply_pending()
        source, cycle = self._source, self._cycle
        assert source is not None and cycle is not None  # both set by _construct()
        if source.prolongation is None:
            z = cycle(r)
        else:
            from pyamg.relaxation.relaxation import gauss_seidel

            matrix, prolongation = source.matrix, source.prolongation
            z = np.zeros_like(r)
            gauss_seidel(matrix, z, r, iterations=1, sweep="forward")
            z += prolongation @ cycle(prolongation.T @ (r - matrix @ z))
            gauss_seidel(matrix, z, r, iterations=1, sweep="backward")
        if source.correction is not None:
            z += source.correction @ r
        return z

    def solve(self, matrix: sparse.spmatrix, rhs: np.ndarray, *, x0: np.ndarray | None = None,
              extra: sparse.spmatrix | None = None, near_null_space: np.ndarray | None = None,
              prolongation: sparse.spmatrix | None = None, r0: np.ndarray | None = None,
              deflation: Deflation | None = None) -> tuple[np.ndarray, SolveInfo]:
        """Solve ``(matrix + extra) x = rhs``; returns ``(x, SolveInfo)``.

        Parameters
        ----------
        matrix : (N, N) sparse
            SPD; the hierarchy is built from it when there is none of its size yet.
        rhs : (N,) float
        x0 : (N,) float, optional
            Warm start.
        r0 : (N,) float, optional
            rhs - (matrix + extra) x0, when the caller has it (one product fewer; trusted).
        deflation : Deflation, optional
            W taken out of the preconditioner (:class:`~volspring.solvers.krylov.Deflation`).
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
        elif self._cycle is None:  # unpickled: the same hierarchy again, the same bits
            start = self.timer()
            rebuilt = self._unpickled()
            setup = self.timer() - start
        start = self.timer()
        x, iterations, residual, initial = conjugate_gradient(
            _operator(matrix, extra), rhs, x0=x0, preconditioner=self.precondition, rtol=self.rtol,
            maxiter=self.maxiter, r0=r0, deflation=deflation)
        info = SolveInfo("amg", iterations, residual, bool(residual <= self.rtol), self.rtol, initial,
                         setup, self.timer() - start, rebuilt)
        return self._finish(x, info)


def _blocksize(matrix) -> int:
    """The block size of a level's matrix (triangles, BSR or CSR)."""
    blocksize = getattr(matrix, "blocksize", None)
    return 1 if blocksize is None else blocksize[0]


def _plus(matrix, change: sp.csr_matrix):
    """A level's ``matrix`` (triangles, or BSR or CSR) plus ``change``, as a new one in the same form."""
    if isinstance(matrix, _Triangles):
        return matrix.plus(change)
    if matrix.format == "bsr":
        total = matrix + sp.bsr_matrix(change, blocksize=matrix.blocksize)
        return sp.bsr_matrix(total, blocksize=matrix.blocksize)
    return sp.csr_matrix(matrix + change)


def _sum_duplicates(matrix) -> None:
    """Sort a CSR or BSR matrix's column (block) indices and add up duplicate entries (blocks), in place.

    scipy's CSR form does this in C, its BSR form in a Python loop over every block, which ran on every sorted
    Galerkin product (no duplicates, but scipy cannot know): a build at 10k nodes took 180 mat-vecs with it and 162
    with this (alternating in one process).
    Here the BSR duplicates are found and summed with array operations, in the same order (the same bits); a loop
    runs once per duplicate of a block, not per block."""
    if matrix.format != "bsr" or matrix.has_canonical_format:
        matrix.sum_duplicates()
        return
    matrix.sort_indices()
    indptr, indices = matrix.indptr, matrix.indices
    rows = np.repeat(np.arange(len(indptr) - 1), np.diff(indptr))
    first = np.ones(len(indices), dtype=bool)  # the first stored block of each (row, column)
    first[1:] = (indices[1:] != indices[:-1]) | (rows[1:] != rows[:-1])
    if not first.all():
        starts = np.flatnonzero(first)
        group = np.cumsum(first) - 1  # the (row, column) of each stored block
        rank = np.arange(len(indices)) - starts[group]
        summed = matrix.data[starts]
        for k in range(1, int(rank.max()) + 1):  # left to right, as scipy adds them (np.add.reduceat does not)
            later = np.flatnonzero(rank == k)
            summed[group[later]] += matrix.data[later]
        matrix.data = summed
        matrix.indices = indices[starts]
        matrix.indptr = np.concatenate([[0], np.cumsum(np.bincount(rows[starts], minlength=len(indptr) - 1))]).astype(
            indptr.dtype)
    matrix.has_canonical_format = True


def _block_norms(matrix, blocksize: int = 3) -> sp.csr_matrix:
    """(nodes, nodes) CSR -- the Frobenius norm of every stored block of ``matrix`` (what pyamg's symmetric strength
    of connection measures a block matrix by); blocks of ``blocksize`` squared, or a BSR matrix's own."""
    if matrix.format == "bsr":
        blocksize = matrix.blocksize[0]
    blocks = sp.bsr_matrix(matrix, blocksize=(blocksize, blocksize))
    _sum_duplicates(blocks)
    entries = blocks.data.reshape(len(blocks.data), -1)
    norms = np.sqrt(np.einsum("ij,ij->i", entries, entries))  # pyamg squares a copy of every block first
    nodes = blocks.shape[0] // blocksize
    return sp.csr_matrix((norms, blocks.indices, blocks.indptr), shape=(nodes, nodes))


def _smoothed_aggregation(matrix, near_null_space: np.ndarray, *, theta: float, excluded: sp.csr_matrix | None,
                          max_coarse: int):
    """The smoothed-aggregation hierarchy of ``matrix`` (a pyamg ``MultilevelSolver``, coarse solver sparse LU, no
    smoothers yet): pyamg's aggregation and tentative prolongation, the prolongation smoothing and Galerkin products
    done here.

    Each level: the symmetric strength of connection with ``theta`` between the Frobenius norms of the blocks
    (every block kept at theta 0), pyamg's standard aggregation, the tentative prolongator T fitted to the
    candidates, P = T - omega D^-1 (A T) with D the row sums of |A| (pyamg's ``"local"`` weighting; omega =
    :data:`PROLONGATION_OMEGA`), R = P^T and the coarse matrix R A P, until at most ``max_coarse`` unknowns per
    block size remain (at most ten levels, pyamg's default). With ``excluded`` C (see
    :meth:`AMGConjugateGradient.build`'s ``aggregation``) the strength and the smoothing of P take A - C, and the
    next level's C is P^T C P (:func:`_galerkin_rows`); R A P takes all of A.

    The coarse matrices' block columns are sorted before they are aggregated (pyamg leaves a Galerkin product's
    as they come, and its aggregation visits a node's neighbours in stored order, so on a coarse level the two can
    pick other aggregates; ``tests/test_solvers.py`` compares both hierarchies).

    Why not ``pyamg.smoothed_aggregation_solver`` with the same options (it builds the same hierarchy, to rounding):
    its Jacobi smoother scales a copy of A by D^-1 and then copies it again to scale it by omega, and takes |A|
    as a third copy (a sixth of a build at 45k nodes), where scaling the rows of A T, a third smaller, costs neither;
    its block norms square a copy of A; and it copies R once more and sets up block smoothers the default smoother
    replaces.
    """
    from pyamg.aggregation import fit_candidates, standard_aggregation
    from pyamg.multilevel import MultilevelSolver
    from pyamg.util.utils import get_blocksize

    level = MultilevelSolver.Level()
    level.A, level.B = matrix, near_null_space
    levels = [level]
    while len(levels) < 10 and matrix.shape[0] // get_blocksize(matrix) > max_coarse:
        smoothing, strength = _coarsening(matrix, theta, excluded)
        tentative, candidates = fit_candidates(standard_aggregation(strength)[0], level.B)
        del strength
        level.P = _smoothed_prolongator(smoothing, tentative)
        del smoothing, tentative
        level.R = level.P.T
        coarse = _galerkin(level.R, matrix, level.P)
        excluded = _excluded_below(level.P, excluded)
        level = MultilevelSolver.Level()
        level.A, level.B = coarse, candidates
        levels.append(level)
        matrix = coarse
    return MultilevelSolver(levels, coarse_solver="splu")


#: The levels :meth:`AMGConjugateGradient.update` gives the change to, from the finest (never the coarsest, whose
#: factorisation would be made again); the others keep the build's matrix (see there).
UPDATE_DEPTH = 2
#: The most pieces :func:`_galerkin` splits R's block rows into (1: the whole product at once) ...
GALERKIN_CHUNKS = 8
#: ... each of at least this many block rows. Below that the whole R A is small (about 1.9 KiB per node: 19 MB at
#: 10k nodes) and each piece pays scipy's fixed costs of two products: split into 8 pieces, a build took
#: 140 against 129-131 mat-vecs whole at 1k nodes and 142 against 138 at 10k (median of 6 alternating builds, stop
#: 33; scratch ``build_levers.py``). The 200k-node beam's first coarse level still goes in 8 pieces.
GALERKIN_CHUNK_ROWS = 500


def _galerkin(restriction, matrix, prolongation):
    """(R A) P, computed :data:`GALERKIN_CHUNK_ROWS` or more block rows of R at a time (in at most
    :data:`GALERKIN_CHUNKS` pieces) and the rows put together: the same arrays as the whole product (scipy's products
    make each row from that row of the left factor alone), without R A whole at once (1.9 KiB per node at 45k nodes,
    the build's peak: its rows are the 2-rings of the aggregates)."""
    rows = restriction.shape[0] // restriction.blocksize[0] if restriction.format == "bsr" else 0
    chunks = min(GALERKIN_CHUNKS, rows // max(GALERKIN_CHUNK_ROWS, 1))
    if chunks < 2:
        return _product(_product(restriction, matrix), prolongation)
    bounds = np.linspace(0, rows, chunks + 1).astype(int)
    pieces = []
    for start, stop in zip(bounds[:-1], bounds[1:]):
        first, last = restriction.indptr[start], restriction.indptr[stop]
        chunk = sp.bsr_matrix((restriction.data[first:last], restriction.indices[first:last],
                               restriction.indptr[start:stop + 1] - first),
                              shape=((stop - start) * restriction.blocksize[0], restriction.shape[1]))
        pieces.append(_product(_product(chunk, matrix), prolongation))
        del chunk
    data = np.concatenate([piece.data for piece in pieces])
    indices = np.concatenate([piece.indices for piece in pieces])
    counts = np.concatenate([np.diff(piece.indptr) for piece in pieces])
    del pieces
    indptr = np.concatenate([[0], np.cumsum(counts)]).astype(indices.dtype)
    return sp.bsr_matrix((data, indices, indptr), shape=(restriction.shape[0], prolongation.shape[1]))


def _product(left, right):
    """``left @ right``; for two float64 BSR matrices whose blocks fit, by the compiled kernel
    (:mod:`volspring.kernels`) with scipy's arrays bit for bit: the same block columns in the same order, each block
    summed in the same order. Its loops are unrolled for the build's block sizes, which makes the build's products
    about twice as fast."""
    kernels = compiled()
    if kernels is None or left.format != "bsr" or right.format != "bsr" or left.dtype != np.float64 or \
            right.dtype != np.float64 or left.blocksize[1] != right.blocksize[0] or left.shape[1] != right.shape[0]:
        return left @ right
    (R, N), C = left.blocksize, right.blocksize[1]
    columns = right.shape[1] // C
    indptr = kernels.block_product_rows(unsigned(left.indptr), unsigned(left.indices), unsigned(right.indptr),
                                        unsigned(right.indices), columns)
    count = int(indptr[-1])
    index_type = np.int32 if max(count, columns, len(indptr)) < np.iinfo(np.int32).max else np.int64
    indices, data = np.empty(count, dtype=index_type), np.empty((count, R, C))
    left_blocks = np.ascontiguousarray(left.data).reshape(-1, R * N)
    right_blocks = np.ascontiguousarray(right.data).reshape(-1, N * C)
    kernels.block_product(unsigned(left.indptr), unsigned(left.indices), left_blocks, unsigned(right.indptr),
                          unsigned(right.indices), right_blocks, indptr, unsigned(indices), data.reshape(-1, R * C),
                          R, N, C, columns)
    return sp.bsr_matrix((data, indices, indptr.astype(index_type)), shape=(left.shape[0], right.shape[1]))


def _coarsening(matrix, theta: float, excluded: sp.csr_matrix | None) -> tuple:
    """(the matrix that smooths the level's prolongator, its strength graph): ``matrix`` less ``excluded``, and the
    symmetric strength of connection between its block norms (every stored block at theta 0)."""
    from pyamg.strength import symmetric_strength_of_connection

    smoothing = matrix if excluded is None else _without(matrix, excluded)
    couplings = _block_norms(smoothing) if smoothing.format == "bsr" else sp.csr_matrix(smoothing)
    if excluded is not None:  # drop the couplings that only the excluded part made (from a copy: the block norms
        couplings = couplings.copy()  # share their index arrays with the smoothing matrix)
        couplings.eliminate_zeros()
    strength = symmetric_strength_of_connection(couplings, theta) if theta else \
        sp.csr_matrix((np.ones(couplings.nnz), couplings.indices, couplings.indptr), shape=couplings.shape)
    return smoothing, strength


def _smoothed_prolongator(smoothing, tentative: sp.bsr_matrix) -> sp.bsr_matrix:
    """P = T - omega D^-1 (A T), D the row sums of |A| (pyamg's ``"local"`` weighting), A = ``smoothing``."""
    from pyamg.util.utils import scale_rows

    row_sums = _absolute(smoothing) @ np.ones(smoothing.shape[0])
    weights = np.zeros_like(row_sums)
    np.divide(PROLONGATION_OMEGA, row_sums, out=weights, where=row_sums != 0)
    correction = _product(smoothing, tentative)
    if correction.format != "bsr":
        correction = correction.tobsr(blocksize=tentative.blocksize)
    scale_rows(correction, weights, copy=False)
    return _minus_plus_tentative(correction, tentative)


def _excluded_below(prolongation, excluded: sp.csr_matrix | None) -> sp.csr_matrix | None:
    """The next level's excluded couplings, P^T C P (None when there are none)."""
    if excluded is None:
        return None
    excluded = _galerkin_rows(prolongation, excluded)
    excluded.eliminate_zeros()
    return excluded if excluded.nnz else None


def _minus_plus_tentative(correction: sp.bsr_matrix, tentative: sp.bsr_matrix) -> sp.bsr_matrix:
    """T - C, in place of C when C = omega D^-1 A T holds T's blocks (A has its diagonal; BSR products keep zero
    blocks), else by scipy (a CSR product drops the zeros A T has inside an aggregate of a scalar problem).

    Each block row of T holds at most one block (its node's aggregate), found in C's row by comparing columns.
    scipy's ``T - C`` allocates room for both operands' blocks and keeps it (the prolongator of the README beam
    at 45k nodes was held in an array 23% larger than its blocks), and is one more P-sized array at the build's
    peak."""
    rows = len(correction.indptr) - 1
    aggregate = np.full(rows, -1, dtype=np.int64)  # T's column block in each block row, -1 for none
    holds = np.diff(tentative.indptr) > 0
    aggregate[holds] = tentative.indices[tentative.indptr[:-1][holds]]
    row_of_block = np.repeat(np.arange(rows), np.diff(correction.indptr))
    position = np.flatnonzero(correction.indices == aggregate[row_of_block])
    if len(position) != holds.sum():
        return tentative - correction
    np.negative(correction.data, out=correction.data)
    correction.data[position] += tentative.data[tentative.indptr[:-1][holds]]
    return correction


def _without(matrix, excluded: sp.csr_matrix):
    """``matrix`` - ``excluded`` on ``matrix``'s own pattern (a CSR or BSR copy), for an ``excluded`` stored within it.

    Below the finest level both are Galerkin products, and a coupling that only ``excluded`` made (across a contact
    interface) leaves rounding where the difference is 0: entries below :data:`_SEPARATION_ROUNDING` of the
    excluded one are set to 0 (rounding is about 1e-16 of it, and a coupling that small would not move P)."""
    excluded = excluded.tocoo()
    position, entry = _stored_at(matrix, excluded.row, excluded.col)
    inside = position >= 0  # outside: where a CSR Galerkin product dropped an exact 0 of A (C is rounding there)
    position, entry, values = position[inside], entry[inside], excluded.data[inside]
    data = matrix.data.copy()
    flat = data.reshape(len(data), -1)
    np.subtract.at(flat, (position, entry), values)
    residue = np.abs(flat[position, entry]) <= _SEPARATION_ROUNDING * np.abs(values)
    flat[position[residue], entry[residue]] = 0.0
    kind = sp.bsr_matrix if matrix.format == "bsr" else sp.csr_matrix
    return kind((data, matrix.indices, matrix.indptr), shape=matrix.shape)


def _stored_at(matrix, rows: np.ndarray, columns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where the entries (rows, columns) are stored in a CSR or BSR ``matrix`` (sorted in place if it is not): the
    index of each one's block (or entry) in ``matrix.data``, -1 where it stores none, and its place in the block."""
    if not matrix.has_canonical_format:
        _sum_duplicates(matrix)  # as the block norms would sort it (a Galerkin product's columns come unsorted)
    size = matrix.blocksize[0] if matrix.format == "bsr" else 1
    blocks = len(matrix.indptr) - 1
    keys = np.repeat(np.arange(blocks, dtype=np.int64), np.diff(matrix.indptr)) * blocks + matrix.indices
    wanted = (rows // size).astype(np.int64) * blocks + columns // size
    position = np.minimum(np.searchsorted(keys, wanted), max(len(keys) - 1, 0))  # blocks sorted by (row, column)
    found = keys[position] == wanted if len(keys) else np.zeros(len(wanted), dtype=bool)
    return np.where(found, position, -1), (rows % size) * size + columns % size


def _galerkin_rows(prolongation, change: sp.csr_matrix, blocksize: tuple[int, int] | None = None) -> sp.csr_matrix:
    """P^T C P for a symmetric ``change`` C that is zero outside a few rows (and so columns): the product of the
    rows of P that C touches only (CSR, the coarse level's size), by block products: at 9,826 nodes with 2,811
    contact rows, 9 and 7 mat-vecs on the first two levels against 20 and 17 with CSR ones. A CSR P (the finest
    level's, in single precision) gives its touched rows in double, as blocks of ``blocksize``."""
    if prolongation.format == "bsr":
        blocksize = prolongation.blocksize
    elif blocksize is None:
        raise ValueError("a CSR prolongation is read by blocks of a given blocksize, and none was given")
    size = blocksize[0]
    blocks = np.unique(np.flatnonzero(np.diff(change.indptr)) // size)  # block rows of P that C touches
    rows = (size * blocks[:, None] + np.arange(size)).ravel()
    if prolongation.format == "bsr":  # those block rows of P, without converting all of it
        indptr, picked = _rows_picked(prolongation.indptr, blocks)
        touched = sp.bsr_matrix((prolongation.data[picked], prolongation.indices[picked], indptr),
                                shape=(len(rows), prolongation.shape[1]))
    else:
        touched = sp.bsr_matrix(sp.csr_matrix(prolongation)[rows].astype(np.float64), blocksize=blocksize)
    change = sp.csr_matrix(change)
    position = np.full(change.shape[0], -1, dtype=np.int64)
    position[rows] = np.arange(len(rows))  # C's rows and columns among the touched ones (C is zero elsewhere)
    indptr, picked = _rows_picked(change.indptr, rows)
    sub = sp.csr_matrix((change.data[picked], position[change.indices[picked]], indptr), shape=(len(rows), len(rows)))
    sub = sp.bsr_matrix(sub, blocksize=(size, size))
    return sp.csr_matrix(_product(_product(touched.T.tobsr(), sub), touched))


def _rows_picked(indptr: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(the row pointers of ``rows`` of a compressed matrix with row pointers ``indptr``, the positions of their
    stored entries or blocks in its arrays, row after row)."""
    starts = indptr[rows]
    counts = indptr[rows + 1] - starts
    picked_indptr = np.concatenate([[0], np.cumsum(counts)])
    return picked_indptr, np.arange(picked_indptr[-1]) + np.repeat(starts - picked_indptr[:-1], counts)


def _envelope(matrix) -> int:
    """Entries of the lower envelope of a CSR or CSC matrix with a symmetric pattern: per row, the columns from its
    first entry to the diagonal (rows without an entry left of the diagonal add none). Factorised in its own order
    without row interchanges, the lower factor has no entry outside it (George & Liu, *Computer Solution of Large
    Sparse Positive Definite Systems*, 1981, ch. 4). A CSC matrix's columns are its transpose's rows: the same count."""
    if not matrix.has_sorted_indices:
        matrix = matrix.sorted_indices()  # a copy: the caller's matrix is left as it is
    rows = np.flatnonzero(np.diff(matrix.indptr))
    first = matrix.indices[matrix.indptr[rows]]
    return int(np.maximum(rows - first, 0).sum())


def _column_order(coarsest) -> str:
    """The column ordering sparse LU factorises the coarsest level (CSC) in: its own (``"NATURAL"``) where its lower
    envelope holds at most :data:`NATURAL_ORDER_ENVELOPE` times its entries, else SuperLU's COLAMD (scipy's default).

    The aggregates of a level are numbered in the order of the nodes they grow from, and the pattern numbers the
    nodes by reverse Cuthill-McKee, so the coarsest matrix comes out banded: its envelope holds 0.56-0.59 times its
    entries on the gmsh beams of ``benchmarks/bench_implicit.py`` (468, 324 and 1,326 unknowns at 1k, 10k and 50k
    nodes), 1.46-1.59 times once its rows and columns are shuffled. In its own order the factors there hold 5-11% fewer
    entries than COLAMD's and the factorisation takes 0.65-0.77 of the time (20.8 against 31.9 mat-vecs at 1k nodes,
    1.7 against 2.4 at 10k, 5.2 against 6.8 at 50k), the solves the same or less; COLAMD's own ordering pass is most of
    the difference (SuperLU's partial pivoting interchanged no rows there: the same fill as in its symmetric mode).
    Shuffled, the natural order has 1.4-2.1 times COLAMD's fill and takes 1.6-2.0 times as long (50k and 1k nodes)."""
    return "NATURAL" if _envelope(coarsest) <= NATURAL_ORDER_ENVELOPE * coarsest.nnz else "COLAMD"


def _absolute(matrix):
    """|matrix| entry by entry, sharing its index arrays (a CSR or BSR matrix)."""
    if matrix.format == "bsr":
        return sp.bsr_matrix((np.abs(matrix.data), matrix.indices, matrix.indptr), shape=matrix.shape)
    matrix = sp.csr_matrix(matrix)
    return sp.csr_matrix((np.abs(matrix.data), matrix.indices, matrix.indptr), shape=matrix.shape)


def _forward_sweep(A: _Triangles, x: np.ndarray, b: np.ndarray) -> None:
    """A pyamg pre-smoother on a level held as triangles."""
    A.forward(x, b)


def _backward_sweep(A: _Triangles, x: np.ndarray, b: np.ndarray) -> None:
    """A pyamg post-smoother on a level held as triangles."""
    A.backward(x, b)


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
