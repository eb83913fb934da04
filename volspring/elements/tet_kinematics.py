"""Deformation gradients of linear tets, their nodal averages, and the corotational kernel.

Shared by the continuum element sets (:mod:`volspring.elements.continuum`).

- A linear tet t with rest corners X_a has shape-function gradients g_ta (rest frame, sum over
  a is zero) and a constant deformation gradient F_t = sum_a x_a g_ta^T.
- A *smoothing domain* is a node together with the tets around it that share one material
  region (a node on a material interface has one domain per region). Its rest volume is
  V_d = sum V_t / 4 over those tets, its averaged gradient Fbar_d = sum (V_t / 4 V_d) F_t =
  sum_a x_a gbar_da^T is linear in the positions of the domain's *ring* (the nodes of its
  tets), and its current volume v_d = sum v_t / 4 sums to the body's volume over all domains.
- The corotational energy density psi(F) = |F - R|^2, R the rotation of F's polar
  decomposition (taken from a rotation-preserving SVD, F = U diag(s) V^T with det U = det V = 1,
  so an inverted F has s_3 < 0 and is pushed back), reduces to |eps|^2 at small strain, eps the
  linear strain. Its gradient is 2 (F - R); its Hessian (Smith, de Goes, Kim 2019, "Analytic
  eigensystems for isotropic distortion energies") is 2 (I - sum_r c_r q_r q_r^T) with the three
  twist directions q_r = U (e_i e_j^T - e_j e_i^T) V^T / sqrt(2) and c_r = 2 / (s_i + s_j); it
  is positive semi-definite exactly when every c_r <= 1, so the projection clamps c_r to 1.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from typing import TYPE_CHECKING

from meshing.mesh import TET_FACES, boundary_face_mask, tet_edges
from volspring.kernels import compiled, unsigned

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

__all__ = ["SmoothingDomains", "TetGradients", "corotated", "corotational", "domain_pairs", "merged_pairs",
           "pair_nodes", "rotation_preserving_svd", "twist_directions", "twist_rows"]

_TWIST_PAIRS = ((0, 1), (0, 2), (1, 2))
_HALF_ROOT = 1.0 / np.sqrt(2.0)


@dataclass(frozen=True, eq=False)
class TetGradients:
    """Rest volumes and shape-function gradients of a set of linear tets.

    Parameters
    ----------
    tets : (T, 4) int
        corner nodes
    volumes : (T,) float
        rest volumes [m^3], > 0
    gradients : (T, 4, 3) float
        g_ta [1/m]
    """

    tets: np.ndarray
    volumes: np.ndarray
    gradients: np.ndarray

    @classmethod
    def at_rest(cls, rest_positions: ArrayLike, tets: ArrayLike, *, owner: str = "tets") -> "TetGradients":
        """The gradients of ``tets`` at ``rest_positions``; a ValueError names the first tet that is not
        positively oriented with a non-zero volume (``owner`` names the array in the message)."""
        tets = np.asarray(tets, dtype=np.int64)
        corners = np.asarray(rest_positions, dtype=np.float64)[tets]
        edges = np.transpose(corners[:, 1:] - corners[:, :1], (0, 2, 1))  # columns x_a - x_0
        volumes = np.linalg.det(edges) / 6.0
        scale = np.abs(edges).max(axis=(1, 2)) ** 3 if len(tets) else np.zeros(0)
        from meshing.tolerances import ZERO_VOLUME

        bad = ~(volumes > ZERO_VOLUME * scale)
        if bad.any():
            t = int(np.flatnonzero(bad)[0])
            raise ValueError(f"{owner}[{t}] = {tets[t].tolist()} has rest volume {volumes[t]:.6g} m^3; expected a "
                             f"positively oriented tet with volume > 0 ({int(bad.sum())} such tet(s); "
                             "meshing.TetMesh.oriented fixes the orientation)")
        inverse = np.linalg.inv(edges)
        gradients = np.empty((len(tets), 4, 3))
        gradients[:, 1:] = inverse
        gradients[:, 0] = -inverse.sum(axis=1)
        return cls(tets, volumes, gradients)

    @cached_property
    def _columns(self):
        """Three (T, n) CSR matrices G_j with rows g_t.[j] on each tet's corners, and their transposes (CSR):
        F_t[:, j] = (G_j x)_t. Sparse products gather and scatter several times faster than einsum over
        x[tets] and bincount (0.5 ms against 4.5 ms for F on 15,360 tets)."""
        import scipy.sparse as sp

        T = len(self.tets)
        shape = (T, int(self.tets.max()) + 1 if T else 0)
        indptr = np.arange(0, 4 * T + 1, 4)
        matrices = tuple(sp.csr_matrix((self.gradients[:, :, j].ravel(), self.tets.ravel(), indptr), shape=shape)
                         for j in range(3))
        return matrices, tuple(matrix.T.tocsr() for matrix in matrices)

    @cached_property
    def _kernel_columns(self):
        """:attr:`_columns` as the arrays of a compiled kernel: the three G_j's, then their transposes'."""
        matrices, transposed = self._columns
        return _kernel_arrays(matrices), _kernel_arrays(transposed)

    def deformation(self, x: np.ndarray) -> np.ndarray:
        """(T, 3, 3) float -- F_t at positions x."""
        x = np.asarray(x, dtype=np.float64)
        matrices, _ = self._columns
        if len(x) < matrices[0].shape[1]:
            raise ValueError(f"positions have {len(x)} rows; the tets index node {matrices[0].shape[1] - 1}")
        x = x[:matrices[0].shape[1]]
        kernels = compiled()
        if kernels is not None:  # the same sums, compiled (volspring.kernels)
            out = np.empty((len(self.tets), 3, 3))
            kernels.gathered(*self._kernel_columns[0], _node_rows(x, matrices[0].shape[1]), out)
            return out
        return np.stack([G @ x for G in matrices], axis=2)

    def spread(self, stress: np.ndarray, node_count: int) -> np.ndarray:
        """(n, 3) float -- sum_t stress_t g_ta per node a, for (T, 3, 3) ``stress`` (the transpose of
        :meth:`deformation`: a tet set's forces are ``-spread(V_t P_t)``)."""
        _, transposed = self._columns
        out = np.zeros((node_count, 3))
        kernels = compiled()
        if kernels is not None and len(self.tets):  # the same sums, compiled (volspring.kernels)
            stress = _stress_array(stress, len(self.tets))
            kernels.spread(*self._kernel_columns[1], stress, out[:transposed[0].shape[0]])
            return out
        if len(self.tets):
            out[:transposed[0].shape[0]] = sum(Gt @ np.ascontiguousarray(stress[:, :, j])
                                               for j, Gt in enumerate(transposed))
        return out


#: Condition number sigma_max / sigma_min above which :func:`rotation_preserving_svd` hands an F to LAPACK:
#: the Jacobi path works on F^T F, whose rounding grows as the square of it (1e4 eps = 2e-12 here).
_JACOBI_CONDITION = 100.0
_JACOBI_SWEEPS = 4  # quadratic convergence: 10% random strains reach off-diagonals of 1e-22 in 4 sweeps
_JACOBI_MAX_SWEEPS = 8
_JACOBI_ROTATIONS = ((0, 1, 2), (0, 2, 1), (1, 2, 0))
_ROTATION_TABLE = np.array(_JACOBI_ROTATIONS)  # for the compiled kernel
_UPPER = ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2))  # its order of a symmetric matrix's entries


def _symmetric(i, j):
    return (i, j) if i <= j else (j, i)


def _jacobi_eigh(C, sweeps=_JACOBI_SWEEPS):
    """Eigenvalues (m, 3) and eigenvectors (m, 3, 3) of symmetric 3x3 matrices by cyclic Jacobi rotations,
    and whether each converged (off-diagonal below 1e-15 of the trace): :func:`_jacobi_rows`' results by matrix."""
    entries, vectors, converged = _jacobi_rows(C, sweeps)
    m = entries.shape[1]
    return np.ascontiguousarray(entries[[0, 3, 5]].T), np.ascontiguousarray(vectors.T).reshape(m, 3, 3), converged


def _jacobi_rows(C, sweeps=_JACOBI_SWEEPS):
    """The eigensystems of symmetric 3x3 matrices by cyclic Jacobi rotations, as rows over the matrices: the upper
    triangle's entries (6, m) in :data:`_UPPER`'s order once diagonalised (the eigenvalues at rows 0, 3 and 5), the
    eigenvectors (9, m) (row 3 i + j: entry (i, j), the eigenvectors as columns), and whether each converged
    (off-diagonal below 1e-15 of the trace).

    The entries are kept as separate contiguous arrays (one per matrix entry), so each rotation is a few
    dozen vector operations over all m matrices: about eight times faster than ``np.linalg.eigh`` or
    ``np.linalg.svd`` on 15,000 matrices, which call LAPACK once per matrix. ``C`` is (m, 3, 3), or a dict of
    the upper triangle's entries {(i, j): (m,) array, i <= j}, or those entries as rows (6, m) in :data:`_UPPER`'s
    order (either taken over and changed).
    """
    as_rows = isinstance(C, np.ndarray) and C.ndim == 2
    if as_rows:
        a = dict(zip(_UPPER, C))
    else:
        a = C if isinstance(C, dict) else {(i, j): C[:, i, j].copy() for i in range(3) for j in range(i, 3)}
    m = len(a[0, 0])
    kernels = compiled()
    if kernels is not None:  # the same rotations in the same order, compiled (volspring.kernels)
        entries = C if as_rows else np.array([a[key] for key in _UPPER], dtype=np.float64)
        vectors = np.empty((9, m))
        converged = kernels.jacobi_eigh(entries, sweeps, _JACOBI_MAX_SWEEPS, _ROTATION_TABLE, vectors)
        return entries, vectors, converged
    V = [[np.full(m, float(i == j)) for j in range(3)] for i in range(3)]  # V[row][column]
    scale = (np.abs(a[0, 0]) + np.abs(a[1, 1]) + np.abs(a[2, 2])) * 1e-15
    for sweep in range(_JACOBI_MAX_SWEEPS):
        if sweep >= sweeps:
            off = np.sqrt(a[0, 1] ** 2 + a[0, 2] ** 2 + a[1, 2] ** 2)
            if (off <= scale).all():
                break
        for p, q, r in _JACOBI_ROTATIONS:
            apq = a[p, q]
            with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                tau = (a[q, q] - a[p, p]) / (2.0 * apq)
                t = np.copysign(1.0, tau) / (np.abs(tau) + np.sqrt(1.0 + tau * tau))
            t[~np.isfinite(t) | (apq == 0.0)] = 0.0  # already diagonal in (p, q), or tau overflowed
            c = 1.0 / np.sqrt(1.0 + t * t)
            s = t * c
            a[p, p] = a[p, p] - t * apq
            a[q, q] = a[q, q] + t * apq
            a[p, q] = np.zeros(m)
            rp, rq = _symmetric(r, p), _symmetric(r, q)
            a[rp], a[rq] = c * a[rp] - s * a[rq], s * a[rp] + c * a[rq]
            for row in V:
                row[p], row[q] = c * row[p] - s * row[q], s * row[p] + c * row[q]
    converged = np.sqrt(a[0, 1] ** 2 + a[0, 2] ** 2 + a[1, 2] ** 2) <= scale
    return np.array([a[key] for key in _UPPER]), np.array([V[i][j] for i in range(3) for j in range(3)]), converged


def rotation_preserving_svd(F: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """F = U diag(s) V^T with det U = det V = 1 for (m, 3, 3) F; an inverted F has s_3 < 0.

    Well-conditioned F with det F > 0 (nearly every tet of a simulation) take the fast path: V and s^2
    from Jacobi rotations on F^T F (:func:`_jacobi_rows`), U = F V / s (:func:`_polar_fast`, or the
    compiled kernel with the same operations). The rest (inverted, nearly flat, condition above
    :data:`_JACOBI_CONDITION`, or unconverged) take LAPACK's SVD with the smallest singular value's sign
    flipped where a reflection must be undone. Singular values are in no particular order on the fast path
    and descending on LAPACK's.
    """
    F = np.ascontiguousarray(F, dtype=np.float64)
    m = len(F)
    U, s, Vt = np.empty((m, 3, 3)), np.empty((m, 3)), np.empty((m, 3, 3))
    kernels = compiled()
    if kernels is not None:  # the same operations, compiled: F^T F's entries straight from F, in the Jacobi's rows
        gram = np.empty((6, m))
        kernels.gram_entries(F, gram)
        entries, vectors, converged = _jacobi_rows(gram)
        fast = kernels.polar_fast(F, entries, vectors, converged, _JACOBI_CONDITION**2, U, s, Vt)
    else:
        rows = np.ascontiguousarray(F.transpose(1, 2, 0))  # rows[k, i] = F_ki over all matrices
        entries, vectors, converged = _jacobi_rows(_gram_entries(rows))
        fast = _polar_fast(rows, entries, vectors, converged, U, s, Vt)
    slow = np.flatnonzero(~fast)
    if len(slow):
        U_s, s_s, Vt_s = np.linalg.svd(F[slow])
        flip_u = np.linalg.det(U_s) < 0
        flip_v = np.linalg.det(Vt_s) < 0
        U_s[flip_u, :, 2] *= -1.0
        s_s[flip_u, 2] *= -1.0
        Vt_s[flip_v, 2, :] *= -1.0
        s_s[flip_v, 2] *= -1.0
        U[slow], s[slow], Vt[slow] = U_s, s_s, Vt_s
    return U, s, Vt


def _polar_fast(rows, entries, vectors, converged, U, s, Vt):
    """(m,) bool -- which F take :func:`rotation_preserving_svd`'s fast path; writes its U, s and V^T for every F
    (those of the others are LAPACK's afterwards) from F's entries as rows ((3, 3, m), ``rows[k, i]`` = F_ki) and the
    Jacobi rotations' rows (:func:`_jacobi_rows`).

    Fast: converged, det F > 0 and the eigenvalues of F^T F within :data:`_JACOBI_CONDITION` squared of each other.
    s = sqrt(max(eigenvalue, 0)), V the eigenvectors (a product of plane rotations, so det V = 1, and det U = det F /
    prod(s) > 0), U = F V / s, each entry's sum in a fixed order: the kernel does the same operations
    (:func:`volspring._compiled.polar_fast`).
    """
    values = entries[[0, 3, 5]]  # (3, m)
    fast = converged & (_det3(rows.transpose(2, 0, 1)) > 0.0) & \
        (values.min(axis=0) * _JACOBI_CONDITION**2 > values.max(axis=0))
    roots = np.sqrt(np.maximum(values, 0.0))
    s[...] = roots.T
    divisor = np.where(fast, roots, 1.0)
    V = vectors.reshape(3, 3, -1)  # V[i, j]: entry (i, j) of every matrix
    for k in range(3):
        for c in range(3):
            U[:, k, c] = ((rows[k, 0] * V[0, c] + rows[k, 1] * V[1, c]) + rows[k, 2] * V[2, c]) / divisor[c]
    Vt[...] = V.transpose(2, 1, 0)
    return fast


def _gram_entries(rows):
    """The upper triangle of F^T F as {(i, j): (m,) array}, from F's entries laid out as (3, 3, m) rows (``rows[k, i]``
    = F_ki over all matrices): 1.2 ms for the stacked product on 15,360 matrices (its transposed operand is strided),
    0.3 this way."""
    return {(i, j): rows[0, i] * rows[0, j] + rows[1, i] * rows[1, j] + rows[2, i] * rows[2, j]
            for i in range(3) for j in range(i, 3)}


def _det3(M):
    """(m,) determinants of (m, 3, 3) matrices, by the rule of Sarrus (vectorised; LAPACK loops per matrix)."""
    return (M[:, 0, 0] * (M[:, 1, 1] * M[:, 2, 2] - M[:, 1, 2] * M[:, 2, 1])
            - M[:, 0, 1] * (M[:, 1, 0] * M[:, 2, 2] - M[:, 1, 2] * M[:, 2, 0])
            + M[:, 0, 2] * (M[:, 1, 0] * M[:, 2, 1] - M[:, 1, 1] * M[:, 2, 0]))


def corotational(F: np.ndarray, *, project: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The corotational density psi = |F - R|^2 of each F, its gradient and Hessian pieces.

    Parameters
    ----------
    F : (m, 3, 3) float
    project : bool
        clamp the twist coefficients so that the Hessian is positive semi-definite

    Returns
    -------
    psi : (m,) float
    P : (m, 3, 3) float
        d psi / dF = 2 (F - R)
    twists : (m, 3, 3, 3) float
        q_r, r = 0..2, unit 3x3 directions (:func:`twist_directions`)
    coefficients : (m, 3) float
        c_r; the Hessian is 2 (I - sum_r c_r q_r q_r^T)
    """
    U, Vt, psi, P, coefficients = corotated(F, project=project)
    return psi, P, twist_directions(U, Vt), coefficients


def corotated(F: np.ndarray, *, project: bool = True) -> tuple[np.ndarray, ...]:
    """What :func:`corotational` returns, with the rotations of the SVD F = U diag(s) V^T in place of the twists.

    Returns
    -------
    U, Vt : (m, 3, 3) float
        the twists are :func:`twist_directions` (U, Vt), their products with vectors
        :func:`twist_rows` (U, Vt, vectors)
    psi, P, coefficients
        as for :func:`corotational`
    """
    F = np.ascontiguousarray(F, dtype=np.float64)
    U, s, Vt = rotation_preserving_svd(F)
    m = len(F)
    psi, P, coefficients = np.empty(m), np.empty((m, 3, 3)), np.empty((m, 3))
    kernels = compiled()
    if kernels is not None:  # the same operations per matrix, compiled
        kernels.corotated_parts(F, U, s, Vt, project, psi, P, coefficients)
        return U, Vt, psi, P, coefficients
    d = s - 1.0
    psi[:] = (d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]) + d[:, 2] * d[:, 2]
    # R = U V^T: U's columns times V^T's rows, summed in order (the kernel's order), on rows over the matrices
    # ((3, 3, m) arrays; 0.7 of the time of the same sums broadcast over (m, 3, 3) ones: scratch cor42.py, stop 42)
    U_columns = np.ascontiguousarray(U.transpose(2, 1, 0))  # U_columns[i, c] = U[:, c, i]
    Vt_rows = np.ascontiguousarray(Vt.transpose(1, 2, 0))  # Vt_rows[i, k] = Vt[:, i, k]
    R = (U_columns[0, :, None] * Vt_rows[0, None] + U_columns[1, :, None] * Vt_rows[1, None]) + \
        U_columns[2, :, None] * Vt_rows[2, None]
    P[...] = (2.0 * (F.transpose(1, 2, 0) - R)).transpose(2, 0, 1)
    for r, (i, j) in enumerate(_TWIST_PAIRS):
        total = s[:, i] + s[:, j]
        if project:
            # c = 2 / (s_i + s_j) <= 1 keeps 1 - c >= 0; s_i + s_j <= 0 (inverted) also clamps to 1.
            coefficients[:, r] = np.where(total > 2.0, 2.0 / np.where(total > 2.0, total, 1.0), 1.0)
        else:
            # At s_i + s_j = 0 (a tet reflected in the twist plane) R jumps and the Hessian does not
            # exist: take the projected value there rather than an infinite one.
            coefficients[:, r] = np.divide(2.0, total, out=np.ones_like(total), where=total != 0.0)
    return U, Vt, psi, P, coefficients


def twist_directions(U: np.ndarray, Vt: np.ndarray) -> np.ndarray:
    """(m, 3, 3, 3) -- the twists q_r = (u_i v_j^T - u_j v_i^T) / sqrt 2, (i, j) = (0, 1), (0, 2), (1, 2), of the
    rotations U, V^T (m, 3, 3): unit directions of F along which the rotation R turns."""
    result = np.empty(U.shape[:1] + (3, 3, 3))
    kernels = compiled()
    if kernels is not None:  # the same operations per matrix, compiled (volspring.kernels)
        kernels.twist_directions(np.ascontiguousarray(U, dtype=np.float64), np.ascontiguousarray(Vt, dtype=np.float64),
                                 np.sqrt(2.0), result)
        return result
    for r, (i, j) in enumerate(_TWIST_PAIRS):
        result[:, r] = (U[:, :, i, None] * Vt[:, None, j, :] - U[:, :, j, None] * Vt[:, None, i, :]) / np.sqrt(2.0)
    return result


def twist_rows(U: np.ndarray, Vt: np.ndarray, vectors: np.ndarray, scale: np.ndarray | None = None) -> np.ndarray:
    """(m, 3, k, 3) -- q_r a of each twist q_r of :func:`twist_directions` (U, Vt) and each of the k vectors a of
    ``vectors`` (m, k, 3), without forming q_r: q_r a = (u_i (v_j . a) - u_j (v_i . a)) / sqrt 2, each v . a summed
    in a fixed order, so that the compiled kernel (:func:`volspring._compiled.twist_rows`) makes the same bits;
    each times ``scale[:, r]`` when it is given ((m, 3): the kernel scales the rows as it makes them, numpy after)."""
    U, Vt = np.ascontiguousarray(U, dtype=np.float64), np.ascontiguousarray(Vt, dtype=np.float64)
    vectors = np.ascontiguousarray(vectors, dtype=np.float64)
    m, k = vectors.shape[:2]
    out = np.empty((m, 3, k, 3))
    kernels = compiled()
    if kernels is not None:
        factors = np.empty((0, 3)) if scale is None else np.ascontiguousarray(scale, dtype=np.float64)
        if factors.shape not in ((0, 3), (m, 3)):  # the kernel does not check its indices
            raise ValueError(f"scale has shape {factors.shape}; expected ({m}, 3), one factor per twist")
        kernels.twist_rows(U, Vt, vectors, _HALF_ROOT, factors, out)
        return out
    # The same operations on rows over the m matrices: U, V^T and the vectors as (3, 3, m) and (3, k, m), the rows made
    # as (r, c, k, m) and put in place by one copy. Read and written by matrix, the columns of (m, ...) arrays are
    # strided: 0.66-0.70 of the time on the README beam's 15,360 tets (scratch tr42b.py, stop 42).
    U_rows, Vt_rows = np.ascontiguousarray(U.transpose(1, 2, 0)), np.ascontiguousarray(Vt.transpose(1, 2, 0))
    x, y, z = np.ascontiguousarray(vectors.transpose(2, 1, 0))
    along = [((x * Vt_rows[c, 0] + y * Vt_rows[c, 1]) + z * Vt_rows[c, 2]) * _HALF_ROOT
             for c in range(3)]  # (k, m): v_c . a / sqrt 2
    rows = np.empty((3, 3, k, m))
    for r, (i, j) in enumerate(_TWIST_PAIRS):
        for c in range(3):
            np.subtract(along[j] * U_rows[c, i], along[i] * U_rows[c, j], out=rows[r, c])
        if scale is not None:
            rows[r] *= np.asarray(scale, dtype=np.float64)[:, r]
    out[...] = rows.transpose(3, 0, 2, 1)
    return out


def sparse_layout(indices: np.ndarray, indptr: np.ndarray, columns: int) -> tuple[np.ndarray, np.ndarray]:
    """A CSR layout made once and filled at every linearisation, in the index type scipy keeps it in (int32 while the
    counts fit): given int64, scipy converts both arrays on every ``csr_matrix((data, indices, indptr))``, 0.9 ms for
    the twist rows of 15,360 tets."""
    largest = max(int(columns), len(indptr), int(indptr[-1]) if len(indptr) else 0)
    dtype = np.int32 if largest < np.iinfo(np.int32).max else np.int64
    return np.ascontiguousarray(indices, dtype=dtype), np.ascontiguousarray(indptr, dtype=dtype)


class SmoothingDomains:
    """The smoothing domains of a tet mesh (see the module docstring), grouped by region.

    Parameters
    ----------
    gradients : TetGradients
    node_count : int
    regions : (T,) int, optional
        material region of every tet (domains never cross regions)
    clusters : (n,) int, optional
        a cluster label per node: a domain is then a cluster of nodes (within one region) and the tets around any of
        them, e.g. :func:`pair_nodes`; default one node per domain
    held : (n,) bool, optional
        nodes the supports hold in place: the domains are then the free nodes'. A tet's volume is shared equally among
        its free corners (a held corner gives nothing, and sits in the domain of its tet's first free corner only to
        keep the arrays' shape); a tet with no free corner keeps quarter shares, in domains of its own nodes that no
        free node is part of. Why: a domain of held nodes can change its volume only through the free nodes around it,
        so its constraint falls on them on top of their own, and a clamped end locks (``benchmarks/study_locking.py``)

    Attributes
    ----------
    node : (d,) int
        the node of each domain (its cluster label with ``clusters``; past every label for the domains of tets with no
        free corner, with ``held``)
    region : (d,) int
        its region
    volumes : (d,) float
        V_d [m^3]
    ring_domain, ring_node : (r,) int
        the ring entries: domain and ring node, sorted by domain
    ring_gradient : (r, 3) float
        gbar_da of each ring entry [1/m]
    corner_entry : (T, 4, 4) int
        ring entry of (domain of corner c of tet t, node of corner a)
    corner_domain : (T, 4) int
        domain of corner c of tet t
    corner_share : (T, 4) float
        the share of tet t's volume that corner c gives its domain (1/4 each unless nodes are ``held``; every row sums
        to 1)
    """

    def __init__(self, gradients: TetGradients, node_count: int, regions: ArrayLike | None = None,
                 clusters: ArrayLike | None = None, held: ArrayLike | None = None):
        tets = gradients.tets
        T = len(tets)
        regions = np.zeros(T, dtype=np.int64) if regions is None else np.asarray(regions, dtype=np.int64)
        region_count = int(regions.max()) + 1 if T else 1
        owners = tets if clusters is None else np.asarray(clusters, dtype=np.int64)[tets]
        self.corner_share = np.full((T, 4), 0.25)
        if held is not None:
            free = ~np.asarray(held, dtype=bool)[tets]
            touched = free.any(axis=1)
            self.corner_share[touched] = free[touched] / free[touched].sum(axis=1, keepdims=True)
            first_free = owners[np.arange(T), np.argmax(free, axis=1)]
            held_only = owners.max(initial=-1) + 1 + tets  # labels no cluster uses
            owners = np.where(free, owners, np.where(touched[:, None], first_free[:, None], held_only))
        keys = owners * region_count + regions[:, None]  # (T, 4): domain key of each corner
        domain_keys, corner_domain = np.unique(keys, return_inverse=True)
        self.corner_domain = corner_domain.reshape(T, 4)
        self.node, self.region = np.divmod(domain_keys, region_count)
        self.volumes = np.bincount(self.corner_domain.ravel(), weights=(gradients.volumes[:, None] *
                                                                        self.corner_share).ravel(),
                                   minlength=len(domain_keys))
        # Ring entries: (domain of corner c, node of corner a) for every tet, corner pair.
        domain_of = np.broadcast_to(self.corner_domain[:, :, None], (T, 4, 4))
        node_of = np.broadcast_to(tets[:, None, :], (T, 4, 4))
        entry_keys = domain_of.astype(np.int64) * node_count + node_of
        unique_entries, corner_entry = np.unique(entry_keys, return_inverse=True)
        self.corner_entry = corner_entry.reshape(T, 4, 4)
        self.ring_domain, self.ring_node = np.divmod(unique_entries, node_count)
        weights = (gradients.volumes[:, None] * self.corner_share / self.volumes[self.corner_domain])[:, :, None, None]
        self.ring_gradient = self.sum_to_ring(weights * gradients.gradients[:, None, :, :])
        self.node_count = node_count

    @property
    def domain_count(self) -> int:
        return len(self.node)

    def sum_to_ring(self, per_corner_pair: np.ndarray) -> np.ndarray:
        """(r, 3) float -- the sum of (T, 4, 4, 3) values per (domain corner, ring corner) into ring entries."""
        flat = np.broadcast_to(per_corner_pair, self.corner_entry.shape + (3,)).reshape(-1, 3)
        entries = self.corner_entry.ravel()
        return np.stack([np.bincount(entries, weights=flat[:, c], minlength=len(self.ring_node))
                         for c in range(3)], axis=1)

    @cached_property
    def _averaging(self):
        import scipy.sparse as sp

        shape = (self.domain_count, self.node_count)
        return tuple(sp.csr_matrix((self.ring_gradient[:, k], (self.ring_domain, self.ring_node)), shape=shape)
                     for k in range(3))

    @cached_property
    def _spreading(self):
        return tuple(G.T.tocsr() for G in self._averaging)

    @cached_property
    def averaging_layout(self) -> tuple:
        """The three averaging matrices (d, n) of :meth:`averaged` as the arrays of a compiled kernel: indptr and
        indices of each (unsigned) and their data, in that order."""
        return _kernel_arrays(self._averaging)

    @cached_property
    def spreading_layout(self) -> tuple:
        """The three spreading matrices (n, d) of :meth:`spread` (the averaging ones transposed) as
        :attr:`averaging_layout`."""
        return _kernel_arrays(self._spreading)

    def averaged(self, x: np.ndarray) -> np.ndarray:
        """(d, 3, 3) float -- Fbar_d at positions x."""
        kernels = compiled()
        if kernels is not None:  # the same sums, compiled (volspring.kernels)
            out = np.empty((self.domain_count, 3, 3))
            kernels.gathered(*self.averaging_layout, _node_rows(x, self.node_count), out)
            return out
        return self.averaged_many(np.reshape(x, (-1, 3, 1)))[0]

    def spread(self, stress: np.ndarray) -> np.ndarray:
        """(n, 3) float -- sum_d stress_d gbar_da per node a, for (d, 3, 3) ``stress`` (the transpose of
        :meth:`averaged`: forces are ``-spread(V_d P_d)``)."""
        kernels = compiled()
        if kernels is not None:  # the same sums, compiled (volspring.kernels)
            out = np.empty((self.node_count, 3))
            kernels.spread(*self.spreading_layout, _stress_array(stress, self.domain_count), out)
            return out
        return self.spread_many(stress[..., None])[:, :, 0]

    def averaged_many(self, U: np.ndarray) -> list[np.ndarray]:
        """k (d, 3, 3) float arrays -- :meth:`averaged` of each column of (n, 3, k) ``U``, each averaging matrix read
        once for all columns (each column's sums as alone)."""
        n, _, k = U.shape
        F = np.stack([(G @ U.reshape(n, 3 * k)).reshape(-1, 3, k) for G in self._averaging], axis=2)  # (d, i, c, j)
        return [np.ascontiguousarray(F[..., j]) for j in range(k)]

    def spread_many(self, stress: np.ndarray) -> np.ndarray:
        """(n, 3, k) float -- :meth:`spread` of each (d, 3, 3) ``stress[..., j]``, each spreading matrix read once
        for all columns (each column's sums as alone)."""
        d, _, _, k = stress.shape
        total = sum(Gt @ np.ascontiguousarray(stress[:, :, c, :]).reshape(d, 3 * k)
                    for c, Gt in enumerate(self._spreading))
        return total.reshape(-1, 3, k)

    @cached_property
    def volume_layout(self) -> tuple:
        """(indices, indptr) of a (d, 3 n) CSR matrix with one row per domain and the three unknowns of
        each ring node in it, in ring-entry order (ring entries are sorted by domain)."""
        counts = np.bincount(self.ring_domain, minlength=self.domain_count)
        indices = (3 * self.ring_node[:, None] + np.arange(3)).ravel()
        indptr = np.concatenate([[0], 3 * np.cumsum(counts)])
        return sparse_layout(indices, indptr, 3 * self.node_count)

    @cached_property
    def pairs(self) -> tuple:
        """(first, second) : (p,) int -- every ordered pair of ring entries of one domain, grouped by domain."""
        counts = np.bincount(self.ring_domain, minlength=self.domain_count)
        return domain_pairs(counts)


def _node_rows(x, count) -> np.ndarray:
    """(count, 3) float64, C-ordered -- positions or displacements per node for a compiled kernel, which does not check
    the indices it reads with: a ValueError for any other shape."""
    x = np.ascontiguousarray(x, dtype=np.float64)
    if x.shape != (count, 3):
        raise ValueError(f"expected ({count}, 3) values, one row per node; got shape {x.shape}")
    return x


def _stress_array(stress, count) -> np.ndarray:
    """(count, 3, 3) float64 -- one 3x3 matrix per tet or domain for a compiled kernel (a ValueError otherwise)."""
    stress = np.asarray(stress, dtype=np.float64)
    if stress.shape != (count, 3, 3):
        raise ValueError(f"expected ({count}, 3, 3) matrices, one per tet or domain; got shape {stress.shape}")
    return stress


def _kernel_arrays(matrices) -> tuple:
    """(indptr, indices, data) of three CSR matrices of one pattern for a compiled kernel: the shared index arrays
    (viewed unsigned) and the data side by side, (e, 3), so that a kernel reads each row's indices once for the
    three. A ValueError if their patterns differ."""
    first = matrices[0]
    if not all(np.array_equal(m.indptr, first.indptr) and np.array_equal(m.indices, first.indices)
               for m in matrices[1:]):
        raise ValueError("the three matrices of a compiled gather or spread must share one sparsity pattern")
    return (unsigned(first.indptr), unsigned(first.indices),
            np.ascontiguousarray(np.stack([m.data for m in matrices], axis=1)))


def pair_nodes(points: ArrayLike, tets: ArrayLike) -> np.ndarray:
    """(n,) int -- a cluster label per node: nodes matched in pairs along tet edges, the shortest edges first.

    Rounds of mutual proposals (every unmatched node proposes along its shortest edge to an unmatched
    node; mutual proposals pair up) until no two unmatched nodes share an edge; a node left over joins
    the cluster of its nearest neighbour. Each round is a few vectorised passes over the edges, and the
    result depends on the mesh only (ties go to the lower edge index). A cluster's label is its lowest node.

    Why: one volume constraint per node locks partially on coarse meshes whose nodes are mostly on the
    boundary (fewer than three free unknowns per constraint); a constraint per pair of nodes halves
    their number and keeps the patch test (``benchmarks/study_locking.py``).
    """
    points = np.asarray(points, dtype=np.float64)
    tets = np.asarray(tets, dtype=np.int64)
    n = len(points)
    edges = tet_edges(tets)
    lengths = np.linalg.norm(points[edges[:, 1]] - points[edges[:, 0]], axis=1)
    order = np.lexsort((np.arange(len(edges)), lengths))  # shortest first, ties by edge index
    edges = edges[order]
    label = np.full(n, -1, dtype=np.int64)
    while True:
        open_edges = np.flatnonzero((label[edges[:, 0]] < 0) & (label[edges[:, 1]] < 0))
        if not len(open_edges):
            break
        # Each node's proposal: its first open edge in length order (the lowest index: open_edges is sorted).
        none = np.iinfo(np.int64).max
        choice = np.full(n, none)
        np.minimum.at(choice, edges[open_edges].T.ravel(), np.tile(open_edges, 2))
        a, b = edges[open_edges, 0], edges[open_edges, 1]
        mutual = open_edges[(choice[a] == open_edges) & (choice[b] == open_edges)]
        pair = edges[mutual]
        label[pair[:, 0]] = label[pair[:, 1]] = pair.min(axis=1)
    left = np.flatnonzero(label < 0)
    if len(left):
        # A node whose neighbours are all paired joins its nearest neighbour's cluster (edges are sorted).
        none = np.iinfo(np.int64).max
        nearest = np.full(n, none)
        np.minimum.at(nearest, edges.T.ravel(), np.tile(np.arange(len(edges)), 2))
        for_left = nearest[left]
        has = for_left < none
        neighbour = np.where(edges[for_left[has], 0] == left[has], edges[for_left[has], 1], edges[for_left[has], 0])
        label[left[has]] = label[neighbour]
        label[left[~has]] = left[~has]  # a node on no tet: its own cluster
    return label


def merged_pairs(points: ArrayLike, tets: ArrayLike) -> np.ndarray:
    """(n,) int -- the clusters of :func:`pair_nodes`, each one without an interior node merged into a neighbouring
    cluster that has one (the lowest label among them; a cluster with no such neighbour stays as it is).

    Why: the smoothed rung puts the part of lambda above :data:`volspring.ladder.PAIR_BULK_CAP` mu on these
    coarser domains (:func:`volspring.ladder.smoothed_elements`). With all of lambda on pairs, the coarse bunny's
    deflection fell 5% from nu 0.45 to 0.499 (volume locking); with the part above the cap on merged pairs it
    moves by less than 1% on every held-out shape (``benchmarks/study_locking.py``).
    """
    tets = np.asarray(tets, dtype=np.int64)
    label = pair_nodes(points, tets)
    n = len(label)
    surface = np.zeros(n, dtype=bool)
    surface[tets[:, TET_FACES][boundary_face_mask(tets)].ravel()] = True
    interior = np.zeros(n, dtype=bool)  # per cluster label (a cluster's label is one of its nodes)
    np.logical_or.at(interior, label, ~surface)
    a, b = label[tet_edges(tets)].T
    none = np.iinfo(np.int64).max
    target = np.full(n, none)
    for x, y in ((a, b), (b, a)):
        joins = (x != y) & ~interior[x] & interior[y]
        np.minimum.at(target, x[joins], y[joins])
    moved = target[label] < none
    return np.where(moved, target[label], label)


def domain_pairs(counts: np.ndarray) -> tuple:
    """All ordered pairs (p, q) of entries within each group, for groups of ``counts`` consecutive entries.

    >>> [a.tolist() for a in domain_pairs(np.array([2, 1]))]
    [[0, 0, 1, 1, 2], [0, 1, 0, 1, 2]]
    """
    counts = np.asarray(counts, dtype=np.int64)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    per_entry = np.repeat(counts, counts)  # group size of each entry
    entry = np.arange(counts.sum())
    first = np.repeat(entry, per_entry)
    group_start = np.repeat(np.repeat(starts, counts), per_entry)
    offsets = np.arange(len(first)) - np.repeat(np.cumsum(per_entry) - per_entry, per_entry)
    return first, group_start + offsets
