"""The numba kernels behind :mod:`volspring.kernels` (imported only when numba is installed).

Each kernel is one compiled pass that does what a few numpy passes do elsewhere, with the same
floating-point operations in the same order, so that its results are bit for bit numpy's (the
tests marked ``fast`` compare them). numba's ``error_model="numpy"`` makes a division by zero give
inf or NaN as numpy does instead of raising; the callers check for it as they do after numpy.
Compiled code is cached on disk (numba's ``cache=True``): a process pays the compilation once per
machine and installed version, not once per run.
"""

from __future__ import annotations

import numba
import numpy as np

__all__ = ["block_product", "block_product_rows", "block_times", "cofactor", "corotated_parts", "corotated_times",
           "csr_times", "diagonal_blocks", "finest_down", "finest_up", "gathered", "gram_entries", "jacobi_eigh",
           "nodal_shear_times", "point_triangles", "polar_fast", "spread", "spring_block_sum", "spring_linearization",
           "spring_stiffness_times", "twist_directions", "twist_rows", "volume_gradients"]

def _jit(function):
    """``function`` compiled, cached on disk where numba finds a writable place (beside this file, else the user's
    cache folder); where it finds none (a read-only install and home), numba refuses ``cache=True`` outright, and the
    kernels are compiled in every process instead."""
    try:
        return numba.njit(cache=True, nogil=True, error_model="numpy")(function)
    except RuntimeError:  # "cannot cache function ...: no locator available"
        return numba.njit(cache=False, nogil=True, error_model="numpy")(function)


@_jit
def spring_linearization(x, v, pairs, stiffness, damping, rest_lengths, stiffness_scale, damping_scale, clamp,
                         incidence_indptr, incidence_indices, incidence_data, forces, along_out, directions, lengths,
                         transverse):  # pragma: no cover (compiled; the fast tests compare it with numpy)
    """Forces and what makes the blocks of :meth:`volspring.elements.Springs.linearize`, in one pass over the springs.

    ``v`` with no rows means no velocities (the dampers exert no force); ``damping_scale`` 0 leaves the dampers
    out of the blocks. Writes ``forces`` (n, 3), ``along_out`` (s,) (the coefficient of r r^T in a block),
    ``directions`` (s, 3), ``lengths`` and ``transverse`` (s,), as the numpy code computes them (the blocks are
    summed from them by :func:`spring_block_sum`), and returns how many springs have no positive length (whose
    outputs are then inf or NaN, as numpy's would be).
    """
    s = pairs.shape[0]
    along_forces = np.empty((s, 3))
    collapsed = 0
    damped = v.shape[0] > 0
    for e in range(s):
        i, j = pairs[e, 0], pairs[e, 1]
        d0, d1, d2 = x[i, 0] - x[j, 0], x[i, 1] - x[j, 1], x[i, 2] - x[j, 2]
        # meshing.topology.vector_lengths: numpy's einsum sums the three squares as (0 + 2) + 1
        length = np.sqrt((d0 * d0 + d2 * d2) + d1 * d1)
        if not length > 0.0:
            collapsed += 1
        lengths[e] = length
        minus_length = -length
        r0, r1, r2 = d0 / minus_length, d1 / minus_length, d2 / minus_length
        directions[e, 0], directions[e, 1], directions[e, 2] = r0, r1, r2
        magnitude = stiffness[e] * (length - rest_lengths[e])
        if damped:
            w0, w1, w2 = v[i, 0] - v[j, 0], v[i, 1] - v[j, 1], v[i, 2] - v[j, 2]
            magnitude -= damping[e] * ((w0 * r0 + w2 * r2) + w1 * r1)
        along_forces[e, 0], along_forces[e, 1], along_forces[e, 2] = magnitude * r0, magnitude * r1, magnitude * r2
        t = 1.0 - rest_lengths[e] / length
        if clamp and t < 0.0:
            t = 0.0
        t *= stiffness[e]
        transverse[e] = t
        along = stiffness_scale * (stiffness[e] - t)
        if damping_scale != 0.0:
            along += damping_scale * damping[e]
        along_out[e] = along
    csr_times(incidence_indptr, incidence_indices, incidence_data, along_forces, forces)
    return collapsed


@_jit
def spring_block_sum(indptr, indices, signs, directions, along, transverse, stiffness_scale,
                     out):  # pragma: no cover (compiled; the fast tests compare it with numpy)
    """``out = summation @ blocks.reshape(-1, 9)`` for the springs' blocks r (along r)^T + stiffness_scale
    transverse I (:meth:`volspring.elements.springs.SpringLinearization.summed`), each block made where it is summed
    instead of stored: the summation is CSR (``indptr``, ``indices``, ``signs``), rows the pattern's blocks, columns
    the springs; ``out`` is (rows, 9). Each block entry and each row's sum as numpy makes them (the entry
    r_a (along r_b), the diagonal's added after; the row's sum from zero in the entries' order, scipy's)."""
    for row in range(indptr.shape[0] - 1):
        s0 = s1 = s2 = s3 = s4 = s5 = s6 = s7 = s8 = 0.0
        for entry in range(indptr[row], indptr[row + 1]):
            e, sign = indices[entry], signs[entry]
            r0, r1, r2 = directions[e, 0], directions[e, 1], directions[e, 2]
            a = along[e]
            a0, a1, a2 = a * r0, a * r1, a * r2
            diagonal = stiffness_scale * transverse[e]
            s0 += sign * (r0 * a0 + diagonal)
            s1 += sign * (r0 * a1)
            s2 += sign * (r0 * a2)
            s3 += sign * (r1 * a0)
            s4 += sign * (r1 * a1 + diagonal)
            s5 += sign * (r1 * a2)
            s6 += sign * (r2 * a0)
            s7 += sign * (r2 * a1)
            s8 += sign * (r2 * a2 + diagonal)
        out[row, 0], out[row, 1], out[row, 2] = s0, s1, s2
        out[row, 3], out[row, 4], out[row, 5] = s3, s4, s5
        out[row, 6], out[row, 7], out[row, 8] = s6, s7, s8


@_jit
def spring_stiffness_times(u, pairs, directions, axial, transverse, incidence_indptr, incidence_indices,
                           incidence_data, out):  # pragma: no cover (compiled; the fast tests compare it with numpy)
    """:meth:`volspring.elements.springs.SpringLinearization.dfdx_times` in one pass: writes dF/dx @ u to ``out``."""
    s = pairs.shape[0]
    spring_forces = np.empty((s, 3))
    for e in range(s):
        i, j = pairs[e, 0], pairs[e, 1]
        d0, d1, d2 = u[i, 0] - u[j, 0], u[i, 1] - u[j, 1], u[i, 2] - u[j, 2]
        r0, r1, r2 = directions[e, 0], directions[e, 1], directions[e, 2]
        t = transverse[e]
        along = ((r0 * d0 + r2 * d2) + r1 * d1) * (t - axial[e])
        spring_forces[e, 0] = d0 * -t + along * r0
        spring_forces[e, 1] = d1 * -t + along * r1
        spring_forces[e, 2] = d2 * -t + along * r2
    csr_times(incidence_indptr, incidence_indices, incidence_data, spring_forces, out)


@_jit
def csr_times(indptr, indices, data, vectors, out):  # pragma: no cover (compiled; the fast tests compare)
    """``out = A @ vectors`` for a CSR matrix A and (m, 3) ``vectors`` in the order of scipy's CSR product with
    several vectors (each row from zero, entry by entry): the springs' incidence scattering their forces, the
    volume domains' ring summing their tets' volume gradients."""
    for row in range(indptr.shape[0] - 1):
        out[row, 0], out[row, 1], out[row, 2] = _row_times(indptr, indices, data, vectors, row)


@_jit
def _row_times(indptr, indices, data, vectors, row):  # pragma: no cover (compiled)
    """Row ``row`` of a CSR matrix A times the three columns of ``vectors`` (m, 3), as scipy sums it (from zero,
    entry by entry)."""
    f0 = f1 = f2 = 0.0
    for entry in range(indptr[row], indptr[row + 1]):
        column, value = indices[entry], data[entry]
        f0 += value * vectors[column, 0]
        f1 += value * vectors[column, 1]
        f2 += value * vectors[column, 2]
    return f0, f1, f2


@_jit
def block_times(indptr, indices, data, vectors, out):  # pragma: no cover (compiled; compared with scipy by the tests)
    """``out += A @ vectors`` for a BSR matrix A of 3 x 3 blocks (``data`` (nnzb, 3, 3)), with the k vectors as the
    rows of ``vectors`` (k, m) and of ``out`` (k, n), in the order of scipy's ``bsr_matvec`` and ``bsr_matvecs``:
    each entry carried from block to block of its block row, each block's three products added one after another.
    So every vector's product is scipy's with that vector alone, bit for bit. Each block is read once for all the
    vectors; one vector runs with its row's three sums held in registers."""
    k = vectors.shape[0]
    for row in range(indptr.shape[0] - 1):
        first = 3 * row
        if k == 1:
            y0, y1, y2 = out[0, first], out[0, first + 1], out[0, first + 2]
            for entry in range(indptr[row], indptr[row + 1]):
                column = 3 * indices[entry]
                x0, x1, x2 = vectors[0, column], vectors[0, column + 1], vectors[0, column + 2]
                a = data[entry]
                y0 = ((y0 + a[0, 0] * x0) + a[0, 1] * x1) + a[0, 2] * x2
                y1 = ((y1 + a[1, 0] * x0) + a[1, 1] * x1) + a[1, 2] * x2
                y2 = ((y2 + a[2, 0] * x0) + a[2, 1] * x1) + a[2, 2] * x2
            out[0, first], out[0, first + 1], out[0, first + 2] = y0, y1, y2
            continue
        for entry in range(indptr[row], indptr[row + 1]):
            column = 3 * indices[entry]
            a = data[entry]
            a00, a01, a02, a10, a11, a12 = a[0, 0], a[0, 1], a[0, 2], a[1, 0], a[1, 1], a[1, 2]
            a20, a21, a22 = a[2, 0], a[2, 1], a[2, 2]
            for c in range(k):
                x0, x1, x2 = vectors[c, column], vectors[c, column + 1], vectors[c, column + 2]
                out[c, first] = ((out[c, first] + a00 * x0) + a01 * x1) + a02 * x2
                out[c, first + 1] = ((out[c, first + 1] + a10 * x0) + a11 * x1) + a12 * x2
                out[c, first + 2] = ((out[c, first + 2] + a20 * x0) + a21 * x1) + a22 * x2


@numba.njit(nogil=True, inline="always")
def _gauss_seidel_row(indptr, indices, data, x, b, i, zero):  # pragma: no cover (compiled, inlined)
    """pyamg's point-wise Gauss-Seidel update of row i of a CSR matrix (``amg_core.gauss_seidel``): the row's
    off-diagonal products summed in storage order from zero, x_i = (b - sum) / diagonal, x_i left as it is where the
    diagonal is zero or absent."""
    total, diagonal = zero, zero
    for entry in range(indptr[i], indptr[i + 1]):
        j = indices[entry]
        if j == i:
            diagonal = data[entry]
        else:
            total += data[entry] * x[j]
    if diagonal != 0.0:
        x[i] = (b - total) / diagonal


@numba.njit(nogil=True, inline="always")
def _row_sums(indptr, indices, data, x, row, zero):  # pragma: no cover (compiled, inlined)
    """The products of rows ``row``, ``row`` + 1 and ``row`` + 2 of a CSR matrix with x, each summed from zero in
    storage order (scipy's ``csr_matvec``), the three taken side by side so that their additions overlap."""
    first, second, third, end = indptr[row], indptr[row + 1], indptr[row + 2], indptr[row + 3]
    common = min(second - first, third - second, end - third)
    a, b, c = zero, zero, zero
    for k in range(common):
        a += data[first + k] * x[indices[first + k]]
        b += data[second + k] * x[indices[second + k]]
        c += data[third + k] * x[indices[third + k]]
    for entry in range(first + common, second):
        a += data[entry] * x[indices[entry]]
    for entry in range(second + common, third):
        b += data[entry] * x[indices[entry]]
    for entry in range(third + common, end):
        c += data[entry] * x[indices[entry]]
    return a, b, c


@numba.njit(nogil=True, inline="always")
def _row_sum(indptr, indices, data, x, row, zero):  # pragma: no cover (compiled, inlined)
    """Row ``row`` of a CSR matrix times x, summed from zero in storage order."""
    total = zero
    for entry in range(indptr[row], indptr[row + 1]):
        total += data[entry] * x[indices[entry]]
    return total


@numba.njit(nogil=True, inline="always")
def _restrict_row(indptr, indices, data, value, row, coarse):  # pragma: no cover (compiled, inlined)
    """coarse += value times row ``row`` of P: scipy's CSC product with R = P^T adds each fine row's share in order."""
    for entry in range(indptr[row], indptr[row + 1]):
        coarse[indices[entry]] += data[entry] * value


@_jit
def finest_down(lower_indptr, lower_indices, lower_data, upper_indptr, upper_indices, upper_data, diagonal,
                prolongation_indptr, prolongation_indices, prolongation_data, r, z, coarse,
                zero):  # pragma: no cover (compiled; the fast tests compare the cycle with numpy's)
    """The finest level's half of a V-cycle before the coarse correction, on point-wise triangles
    (:class:`volspring.solvers.amg._Triangles`): a forward Gauss-Seidel sweep from ``z`` = 0 over the lower triangle,
    then row by row the residual D z - U z and its restriction ``coarse`` += P^T residual. The same operations in
    the same order as the numpy cycle: pyamg's sweep, scipy's CSR product for U z, and scipy's CSC product for R = P^T
    (each coarse entry summed over the fine rows in order), so the same bits."""
    n = r.shape[0]
    for i in range(n):
        _gauss_seidel_row(lower_indptr, lower_indices, lower_data, z, r[i], i, zero)
    i = 0
    while i + 3 <= n:
        a, b, c = _row_sums(upper_indptr, upper_indices, upper_data, z, i, zero)
        _restrict_row(prolongation_indptr, prolongation_indices, prolongation_data, diagonal[i] * z[i] - a, i, coarse)
        _restrict_row(prolongation_indptr, prolongation_indices, prolongation_data, diagonal[i + 1] * z[i + 1] - b,
                      i + 1, coarse)
        _restrict_row(prolongation_indptr, prolongation_indices, prolongation_data, diagonal[i + 2] * z[i + 2] - c,
                      i + 2, coarse)
        i += 3
    for i in range(i, n):
        residual = diagonal[i] * z[i] - _row_sum(upper_indptr, upper_indices, upper_data, z, i, zero)
        _restrict_row(prolongation_indptr, prolongation_indices, prolongation_data, residual, i, coarse)


@_jit
def finest_up(lower_indptr, lower_indices, lower_data, upper_indptr, upper_indices, upper_data, diagonal,
              prolongation_indptr, prolongation_indices, prolongation_data, correction, r, z,
              zero):  # pragma: no cover (compiled; the fast tests compare the cycle with numpy's)
    """The finest level's half of a V-cycle after the coarse correction: ``z`` += P ``correction``, then a backward
    Gauss-Seidel sweep over the upper triangle on r - (L z - D z), as the numpy cycle makes them (scipy's CSR
    products, pyamg's sweep): the same bits. The products take three rows at a time, each row's sum in its order."""
    n = z.shape[0]
    whole = n - n % 3
    for i in range(0, whole, 3):
        a, b, c = _row_sums(prolongation_indptr, prolongation_indices, prolongation_data, correction, i, zero)
        z[i], z[i + 1], z[i + 2] = z[i] + a, z[i + 1] + b, z[i + 2] + c
    for i in range(whole, n):
        z[i] = z[i] + _row_sum(prolongation_indptr, prolongation_indices, prolongation_data, correction, i, zero)
    right = np.empty_like(z)  # the sweep's right-hand side in a pass of its own: the rows are independent there
    for i in range(0, whole, 3):
        a, b, c = _row_sums(lower_indptr, lower_indices, lower_data, z, i, zero)
        right[i] = r[i] - (a - diagonal[i] * z[i])
        right[i + 1] = r[i + 1] - (b - diagonal[i + 1] * z[i + 1])
        right[i + 2] = r[i + 2] - (c - diagonal[i + 2] * z[i + 2])
    for i in range(whole, n):
        right[i] = r[i] - (_row_sum(lower_indptr, lower_indices, lower_data, z, i, zero) - diagonal[i] * z[i])
    for i in range(n - 1, -1, -1):
        _gauss_seidel_row(upper_indptr, upper_indices, upper_data, z, right[i], i, zero)


@_jit
def diagonal_blocks(indptr, indices, out):  # pragma: no cover (compiled; the fast tests compare with numpy)
    """``out[row]`` = the entry of block row ``row``'s diagonal block in a BSR matrix with sorted block columns, -1
    where the row has none (:func:`point_triangles` needs every one)."""
    for row in range(indptr.shape[0] - 1):
        out[row] = -1
        for entry in range(indptr[row], indptr[row + 1]):
            if indices[entry] == row:
                out[row] = entry
                break


@_jit
def point_triangles(indptr, indices, data, diagonal, lower_indptr, lower_indices, lower_data, upper_indptr,
                    upper_indices, upper_data, entries):  # pragma: no cover (compiled; the fast tests compare)
    """The point-wise lower and upper triangles of a BSR matrix of square blocks with sorted block columns
    (``data`` (nnzb, B, B), ``diagonal`` from :func:`diagonal_blocks`) as CSR arrays in the outputs' types: every
    block on and left (right) of the diagonal whole, in scipy's ``bsr_tocsr`` order, its diagonal block's entries
    on the other side of the diagonal stored as zeros; and the matrix's diagonal ``entries``. What numpy makes of
    the matrix in several passes and two block copies (:class:`volspring.solvers.amg._Triangles`), entry for entry:
    the values are only cast."""
    size = data.shape[1]
    zero = lower_data.dtype.type(0.0)
    low = up = 0
    lower_indptr[0] = upper_indptr[0] = 0
    for row in range(indptr.shape[0] - 1):
        middle = diagonal[row]
        for i in range(size):
            for entry in range(indptr[row], middle + 1):
                first = size * indices[entry]
                for j in range(size):
                    lower_indices[low] = first + j
                    lower_data[low] = zero if entry == middle and j > i else data[entry, i, j]
                    low += 1
            for entry in range(middle, indptr[row + 1]):
                first = size * indices[entry]
                for j in range(size):
                    upper_indices[up] = first + j
                    upper_data[up] = zero if entry == middle and j < i else data[entry, i, j]
                    up += 1
            lower_indptr[size * row + i + 1] = low
            upper_indptr[size * row + i + 1] = up
            entries[size * row + i] = data[middle, i, i]


@_jit
def jacobi_eigh(entries, sweeps, max_sweeps, rotations, vectors):  # pragma: no cover (compiled; see the fast tests)
    """:func:`volspring.elements.tet_kinematics._jacobi_eigh` on (6, m) ``entries`` (the upper triangle's
    (0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2), changed in place) with the same rotations in the same order.

    As in numpy, every matrix takes ``sweeps`` sweeps and then more, all of them together, until every one has
    converged or ``max_sweeps`` are done: a matrix's result does not depend on when it alone converged but on the
    whole batch, exactly as numpy's. Each sweep applies the three rotations (``rotations``, (3, 3) int rows
    (p, q, r)) one after the other to every matrix (:func:`_rotate`). ``vectors`` (9, m) is set to the eigenvectors
    by row and column. Returns whether each matrix converged.
    """
    m = entries.shape[1]
    # index into entries of the symmetric pair (i, j)
    slot = np.array([[0, 1, 2], [1, 3, 4], [2, 4, 5]])
    scale = np.empty(m)
    for k in range(m):
        scale[k] = (np.abs(entries[0, k]) + np.abs(entries[3, k]) + np.abs(entries[5, k])) * 1e-15
        for i in range(3):
            for j in range(3):
                vectors[3 * i + j, k] = 1.0 if i == j else 0.0
    for sweep in range(max_sweeps):
        if sweep >= sweeps:
            done = True
            for k in range(m):
                a01, a02, a12 = entries[1, k], entries[2, k], entries[4, k]
                if not np.sqrt((a01 * a01 + a02 * a02) + a12 * a12) <= scale[k]:
                    done = False
                    break
            if done:
                break
        for rotation in range(3):
            p, q, r = rotations[rotation, 0], rotations[rotation, 1], rotations[rotation, 2]
            _rotate(entries[slot[p, p]], entries[slot[q, q]], entries[slot[p, q]], entries[slot[r, p]],
                    entries[slot[r, q]], vectors[p], vectors[q], vectors[3 + p], vectors[3 + q], vectors[6 + p],
                    vectors[6 + q])
    converged = np.empty(m, dtype=np.bool_)
    for k in range(m):
        a01, a02, a12 = entries[1, k], entries[2, k], entries[4, k]
        converged[k] = np.sqrt((a01 * a01 + a02 * a02) + a12 * a12) <= scale[k]
    return converged


@_jit
def _rotate(app, aqq, apq, arp, arq, v0p, v0q, v1p, v1q, v2p, v2q):  # pragma: no cover (compiled)
    """One Jacobi rotation in the plane (p, q) of every matrix, on the rows of its entries (one loop over the
    matrices without branches, which the compiler vectorises: divisions and square roots dominate)."""
    for k in range(app.shape[0]):
        a = apq[k]
        tau = (aqq[k] - app[k]) / (2.0 * a)
        t = np.copysign(1.0, tau) / (np.abs(tau) + np.sqrt(1.0 + tau * tau))
        t = t if np.isfinite(t) and a != 0.0 else 0.0
        c = 1.0 / np.sqrt(1.0 + t * t)
        s = t * c
        app[k] = app[k] - t * a
        aqq[k] = aqq[k] + t * a
        apq[k] = 0.0
        for first, second in ((arp, arq), (v0p, v0q), (v1p, v1q), (v2p, v2q)):  # unrolled by numba (a tuple)
            xp, xq = first[k], second[k]
            first[k] = c * xp - s * xq
            second[k] = s * xp + c * xq


@_jit
def polar_fast(F, entries, vectors, converged, condition_squared, U, s, Vt):  # pragma: no cover (compiled)
    """:func:`volspring.elements.tet_kinematics._polar_fast` per matrix: writes U, s and V^T of every (m, 3, 3) ``F``
    from the Jacobi rotations' rows (``entries`` (6, m), ``vectors`` (9, m), ``converged``) and returns which F take
    the fast path. The same operations: det F by the rule of Sarrus (``_det3``), the eigenvalues within
    ``condition_squared`` of each other (min * c > max, as every pair: false as numpy's with a NaN), U's entries
    summed in the same order. F is read once per matrix (0.81 against 0.63 ms on 15,360 matrices; medians, scratch
    ``oldnew41.py``)."""
    m = F.shape[0]
    fast = np.empty(m, dtype=np.bool_)
    for k in range(m):
        f00, f01, f02 = F[k, 0, 0], F[k, 0, 1], F[k, 0, 2]
        f10, f11, f12 = F[k, 1, 0], F[k, 1, 1], F[k, 1, 2]
        f20, f21, f22 = F[k, 2, 0], F[k, 2, 1], F[k, 2, 2]
        det = (f00 * (f11 * f22 - f12 * f21) - f01 * (f10 * f22 - f12 * f20) + f02 * (f10 * f21 - f11 * f20))
        values = (entries[0, k], entries[3, k], entries[5, k])
        wide = True
        for low in values:
            for high in values:
                if not low * condition_squared > high:
                    wide = False
        is_fast = converged[k] and det > 0.0 and wide
        fast[k] = is_fast
        for c in range(3):
            value = values[c]
            # np.maximum(value, 0): value where value >= 0 or NaN
            root = np.sqrt(value if value >= 0.0 or np.isnan(value) else 0.0)
            s[k, c] = root
            divisor = root if is_fast else 1.0
            w0, w1, w2 = vectors[c, k], vectors[3 + c, k], vectors[6 + c, k]
            U[k, 0, c] = ((f00 * w0 + f01 * w1) + f02 * w2) / divisor
            U[k, 1, c] = ((f10 * w0 + f11 * w1) + f12 * w2) / divisor
            U[k, 2, c] = ((f20 * w0 + f21 * w1) + f22 * w2) / divisor
            Vt[k, c, 0], Vt[k, c, 1], Vt[k, c, 2] = w0, w1, w2
    return fast


@_jit
def corotated_parts(F, U, s, Vt, project, psi, P, coefficients):  # pragma: no cover (compiled)
    """The rest of :func:`volspring.elements.tet_kinematics.corotated` per matrix, the same operations: psi = |s - 1|^2,
    P = 2 (F - U V^T) and the twist coefficients c_r = 2 / (s_i + s_j) (clamped at 1 with ``project``). V^T and
    the singular values are read once per matrix (0.61 against 0.46 ms on 15,360 matrices; medians, scratch
    ``oldnew41.py``)."""
    for k in range(F.shape[0]):
        s0, s1, s2 = s[k, 0], s[k, 1], s[k, 2]
        d0, d1, d2 = s0 - 1.0, s1 - 1.0, s2 - 1.0
        psi[k] = (d0 * d0 + d1 * d1) + d2 * d2
        v00, v01, v02 = Vt[k, 0, 0], Vt[k, 0, 1], Vt[k, 0, 2]
        v10, v11, v12 = Vt[k, 1, 0], Vt[k, 1, 1], Vt[k, 1, 2]
        v20, v21, v22 = Vt[k, 2, 0], Vt[k, 2, 1], Vt[k, 2, 2]
        for i in range(3):
            u0, u1, u2 = U[k, i, 0], U[k, i, 1], U[k, i, 2]
            P[k, i, 0] = 2.0 * (F[k, i, 0] - ((u0 * v00 + u1 * v10) + u2 * v20))
            P[k, i, 1] = 2.0 * (F[k, i, 1] - ((u0 * v01 + u1 * v11) + u2 * v21))
            P[k, i, 2] = 2.0 * (F[k, i, 2] - ((u0 * v02 + u1 * v12) + u2 * v22))
        for r, total in enumerate((s0 + s1, s0 + s2, s1 + s2)):  # the pairs (0, 1), (0, 2), (1, 2); unrolled
            if project:
                coefficients[k, r] = 2.0 / total if total > 2.0 else 1.0
            else:
                coefficients[k, r] = 2.0 / total if total != 0.0 else 1.0


@_jit
def twist_rows(U, Vt, vectors, half_root, scale, out):  # pragma: no cover (compiled)
    """:func:`volspring.elements.tet_kinematics.twist_rows` per matrix, the same operations: writes q_r a into ``out``
    (m, 3, k, 3) for the k vectors a of each matrix (``vectors`` (m, k, 3)), times ``scale[t, r]`` when ``scale``
    has rows (as numpy multiplies the rows it made). U and V^T are read once per matrix (1.01 against 0.95 ms for
    15,360 tets' four gradients; medians, scratch ``oldnew41.py``)."""
    scaled = scale.shape[0] > 0
    for t in range(vectors.shape[0]):
        s0, s1, s2 = (scale[t, 0], scale[t, 1], scale[t, 2]) if scaled else (1.0, 1.0, 1.0)
        v00, v01, v02 = Vt[t, 0, 0], Vt[t, 0, 1], Vt[t, 0, 2]
        v10, v11, v12 = Vt[t, 1, 0], Vt[t, 1, 1], Vt[t, 1, 2]
        v20, v21, v22 = Vt[t, 2, 0], Vt[t, 2, 1], Vt[t, 2, 2]
        u00, u01, u02 = U[t, 0, 0], U[t, 0, 1], U[t, 0, 2]
        u10, u11, u12 = U[t, 1, 0], U[t, 1, 1], U[t, 1, 2]
        u20, u21, u22 = U[t, 2, 0], U[t, 2, 1], U[t, 2, 2]
        for a in range(vectors.shape[1]):
            g0, g1, g2 = vectors[t, a, 0], vectors[t, a, 1], vectors[t, a, 2]
            along0 = ((g0 * v00 + g1 * v01) + g2 * v02) * half_root
            along1 = ((g0 * v10 + g1 * v11) + g2 * v12) * half_root
            along2 = ((g0 * v20 + g1 * v21) + g2 * v22) * half_root
            # row r = (i, j) of the pairs (0, 1), (0, 2), (1, 2): along_j U[:, i] - along_i U[:, j]
            r00, r01, r02 = along1 * u00 - along0 * u01, along1 * u10 - along0 * u11, along1 * u20 - along0 * u21
            r10, r11, r12 = along2 * u00 - along0 * u02, along2 * u10 - along0 * u12, along2 * u20 - along0 * u22
            r20, r21, r22 = along2 * u01 - along1 * u02, along2 * u11 - along1 * u12, along2 * u21 - along1 * u22
            if scaled:
                r00, r01, r02 = r00 * s0, r01 * s0, r02 * s0
                r10, r11, r12 = r10 * s1, r11 * s1, r12 * s1
                r20, r21, r22 = r20 * s2, r21 * s2, r22 * s2
            out[t, 0, a, 0], out[t, 0, a, 1], out[t, 0, a, 2] = r00, r01, r02
            out[t, 1, a, 0], out[t, 1, a, 1], out[t, 1, a, 2] = r10, r11, r12
            out[t, 2, a, 0], out[t, 2, a, 1], out[t, 2, a, 2] = r20, r21, r22


@_jit
def gram_entries(F, out):  # pragma: no cover (compiled; the fast tests compare it with numpy)
    """The upper triangle of F^T F of each (m, 3, 3) ``F`` into ``out`` (6, m), in the order (0, 0), (0, 1), (0, 2),
    (1, 1), (1, 2), (2, 2), each entry summed as :func:`volspring.elements.tet_kinematics._gram_entries` sums it:
    (F_0i F_0j + F_1i F_1j) + F_2i F_2j. Written out entry by entry: the loop over the triangle (j from i) with a
    running slot compiled to 2.9 times the time (1.09 against 0.37 ms on 15,360 matrices; medians, scratch
    ``oldnew41.py``)."""
    for k in range(F.shape[0]):
        f00, f01, f02 = F[k, 0, 0], F[k, 0, 1], F[k, 0, 2]
        f10, f11, f12 = F[k, 1, 0], F[k, 1, 1], F[k, 1, 2]
        f20, f21, f22 = F[k, 2, 0], F[k, 2, 1], F[k, 2, 2]
        out[0, k] = (f00 * f00 + f10 * f10) + f20 * f20
        out[1, k] = (f00 * f01 + f10 * f11) + f20 * f21
        out[2, k] = (f00 * f02 + f10 * f12) + f20 * f22
        out[3, k] = (f01 * f01 + f11 * f11) + f21 * f21
        out[4, k] = (f01 * f02 + f11 * f12) + f21 * f22
        out[5, k] = (f02 * f02 + f12 * f12) + f22 * f22


@numba.njit(nogil=True, inline="always")
def _gathered_row(indptr, indices, data, x, row):  # pragma: no cover (compiled, inlined)
    """Row ``row`` of the three CSR matrices A_c of one pattern (``data`` (e, 3): entry e of A_c is data[e, c]) times
    (n, 3) ``x``: the nine sums (A_c x)[row, i] as F[i, c], row by row (i), each from zero in the entry order."""
    f00 = f01 = f02 = f10 = f11 = f12 = f20 = f21 = f22 = 0.0
    for entry in range(indptr[row], indptr[row + 1]):
        column = indices[entry]
        a0, a1, a2 = data[entry, 0], data[entry, 1], data[entry, 2]
        x0, x1, x2 = x[column, 0], x[column, 1], x[column, 2]
        f00 += a0 * x0
        f01 += a1 * x0
        f02 += a2 * x0
        f10 += a0 * x1
        f11 += a1 * x1
        f12 += a2 * x1
        f20 += a0 * x2
        f21 += a1 * x2
        f22 += a2 * x2
    return f00, f01, f02, f10, f11, f12, f20, f21, f22


@numba.njit(nogil=True, inline="always")
def _spread_row(indptr, indices, data, stress, row):  # pragma: no cover (compiled, inlined)
    """Row ``row`` of sum(S_c @ stress[:, :, c] for c in range(3)) for the three CSR matrices S_c of one pattern
    (``data`` (e, 3)): each product's sums from zero in the entry order, the three added as ``sum()`` adds them."""
    f00 = f01 = f02 = f10 = f11 = f12 = f20 = f21 = f22 = 0.0
    for entry in range(indptr[row], indptr[row + 1]):
        m = indices[entry]
        s0, s1, s2 = data[entry, 0], data[entry, 1], data[entry, 2]
        f00 += s0 * stress[m, 0, 0]
        f01 += s0 * stress[m, 1, 0]
        f02 += s0 * stress[m, 2, 0]
        f10 += s1 * stress[m, 0, 1]
        f11 += s1 * stress[m, 1, 1]
        f12 += s1 * stress[m, 2, 1]
        f20 += s2 * stress[m, 0, 2]
        f21 += s2 * stress[m, 1, 2]
        f22 += s2 * stress[m, 2, 2]
    return ((0.0 + f00) + f10) + f20, ((0.0 + f01) + f11) + f21, ((0.0 + f02) + f12) + f22


@_jit
def nodal_shear_times(ip, ix, a, u, twists, coefficients, weights, sp, sx, s,
                      out):  # pragma: no cover (compiled; the fast tests compare it with numpy)
    """The smoothed shear's product of :meth:`volspring.elements.NodalStrain._stiffness_times_many` for one (n, 3)
    column ``u``, into ``out`` (n, 3): each domain's dFbar by the three averaging matrices (one CSR pattern ``ip``,
    ``ix``, data ``a`` (e, 3); dFbar[i, c] from matrix c), the corotational Hessian on it (``_hessian_times``'s
    order) times 2 and the domain's weight, spread back by the three spreading matrices (``sp``, ``sx``, ``s``) and
    summed over them as ``sum()`` sums numpy's three products. Every sum from zero in scipy's entry order: the same
    bits. Each row's indices are read once for the three matrices (0.82 ms a product on the README beam's smoothed
    rung, against 1.08 when each matrix had its own: scratch ``nodal40.py``)."""
    d = ip.shape[0] - 1
    stress = np.empty((d, 3, 3))
    dF = np.empty((3, 3))
    for domain in range(d):
        (dF[0, 0], dF[0, 1], dF[0, 2], dF[1, 0], dF[1, 1], dF[1, 2],
         dF[2, 0], dF[2, 1], dF[2, 2]) = _gathered_row(ip, ix, a, u, domain)
        p0 = twists[domain, 0, 0, 0] * dF[0, 0]
        p1 = twists[domain, 1, 0, 0] * dF[0, 0]
        p2 = twists[domain, 2, 0, 0] * dF[0, 0]
        for entry in range(1, 9):
            i, j = entry // 3, entry % 3
            p0 = p0 + twists[domain, 0, i, j] * dF[i, j]
            p1 = p1 + twists[domain, 1, i, j] * dF[i, j]
            p2 = p2 + twists[domain, 2, i, j] * dF[i, j]
        p0, p1, p2 = p0 * coefficients[domain, 0], p1 * coefficients[domain, 1], p2 * coefficients[domain, 2]
        weight = weights[domain]
        for i in range(3):
            for j in range(3):
                correction = (p0 * twists[domain, 0, i, j] + p1 * twists[domain, 1, i, j]) + p2 * twists[domain, 2, i, j]
                stress[domain, i, j] = weight * (2.0 * (dF[i, j] - correction))
    for node in range(out.shape[0]):
        out[node, 0], out[node, 1], out[node, 2] = _spread_row(sp, sx, s, stress, node)


@_jit
def gathered(ip, ix, a, x, out):  # pragma: no cover (compiled; the fast tests compare)
    """``out[:, :, c] = A_c @ x`` for three CSR matrices A_c of one pattern (``ip``, ``ix``, data ``a`` (e, 3)) and
    (n, 3) ``x``, each row's sums as scipy's product makes them (from zero, entry by entry): the deformation gradients
    of tets (:meth:`volspring.elements.tet_kinematics.TetGradients.deformation`) or of smoothing domains
    (:meth:`~volspring.elements.tet_kinematics.SmoothingDomains.averaged`), F[:, i, c] = (G_c x)[:, i]."""
    for row in range(out.shape[0]):
        (out[row, 0, 0], out[row, 0, 1], out[row, 0, 2], out[row, 1, 0], out[row, 1, 1], out[row, 1, 2],
         out[row, 2, 0], out[row, 2, 1], out[row, 2, 2]) = _gathered_row(ip, ix, a, x, row)


@_jit
def spread(sp, sx, s, stress, out):  # pragma: no cover (compiled; the fast tests compare)
    """``out = sum(S_c @ stress[:, :, c] for c in range(3))`` for three CSR matrices S_c of one pattern (``sp``,
    ``sx``, data ``s`` (e, 3); the transposes of :func:`gathered`'s) and (m, 3, 3) ``stress``, into ``out`` (rows
    of S_c, 3): each product's rows as scipy sums them, and the three added as Python's ``sum()`` adds them
    (from 0)."""
    for node in range(out.shape[0]):
        out[node, 0], out[node, 1], out[node, 2] = _spread_row(sp, sx, s, stress, node)


@_jit
def cofactor(F, out):  # pragma: no cover (compiled; the fast tests compare it with numpy)
    """cof(F) of each (m, 3, 3) ``F`` into ``out``: its columns the cross products of F's other two columns, each
    component as ``np.cross`` computes it (a1 b2 - a2 b1, a2 b0 - a0 b2, a0 b1 - a1 b0)."""
    for t in range(F.shape[0]):
        for column in range(3):
            a, b = (column + 1) % 3, (column + 2) % 3
            a0, a1, a2 = F[t, 0, a], F[t, 1, a], F[t, 2, a]
            b0, b1, b2 = F[t, 0, b], F[t, 1, b], F[t, 2, b]
            out[t, 0, column] = a1 * b2 - a2 * b1
            out[t, 1, column] = a2 * b0 - a0 * b2
            out[t, 2, column] = a0 * b1 - a1 * b0


@_jit
def volume_ratios(F, cof, volumes, corner_domain, corner_share, domain_volumes,
                  J):  # pragma: no cover (compiled; the fast tests compare it with numpy)
    """:meth:`volspring.elements.NodalStrain._volume_ratios` into ``J`` (d,), zeros on entry: det F_t = cof(F_t) : F_t
    / 3, its nine products summed in row order; V_t det F_t times each corner's share added to the corner's domain,
    tet after tet and corner after corner (np.bincount's order); then each domain's sum over its volume."""
    for t in range(F.shape[0]):
        total = cof[t, 0, 0] * F[t, 0, 0] + cof[t, 0, 1] * F[t, 0, 1]
        total += cof[t, 0, 2] * F[t, 0, 2]
        total += cof[t, 1, 0] * F[t, 1, 0]
        total += cof[t, 1, 1] * F[t, 1, 1]
        total += cof[t, 1, 2] * F[t, 1, 2]
        total += cof[t, 2, 0] * F[t, 2, 0]
        total += cof[t, 2, 1] * F[t, 2, 1]
        total += cof[t, 2, 2] * F[t, 2, 2]
        weight = volumes[t] * (total / 3.0)
        for c in range(4):
            J[corner_domain[t, c]] += weight * corner_share[t, c]
    for d in range(J.shape[0]):
        J[d] = J[d] / domain_volumes[d]


@_jit
def pressure_stress(pressure, corner_domain, corner_share, volumes, cof,
                    out):  # pragma: no cover (compiled; the fast tests compare it with numpy)
    """:meth:`volspring.elements.NodalStrain._pressure_stress` into ``out`` (T, 3, 3): V_t pbar_t cof(F_t), with pbar_t
    the corners' domain pressures weighted by their shares and summed corner after corner."""
    for t in range(cof.shape[0]):
        p0, p1 = pressure[corner_domain[t, 0]], pressure[corner_domain[t, 1]]
        p2, p3 = pressure[corner_domain[t, 2]], pressure[corner_domain[t, 3]]
        mean = ((p0 * corner_share[t, 0] + p1 * corner_share[t, 1]) + p2 * corner_share[t, 2]) + p3 * corner_share[t, 3]
        weight = mean * volumes[t]
        for i in range(3):
            for j in range(3):
                out[t, i, j] = weight * cof[t, i, j]


@_jit
def twist_directions(U, Vt, root, out):  # pragma: no cover (compiled; the fast tests compare it with numpy)
    """:func:`volspring.elements.tet_kinematics.twist_directions` per matrix, the same operations: q_r[c, k] =
    (U[c, i] V^T[j, k] - U[c, j] V^T[i, k]) / ``root`` (sqrt 2) for the pairs (i, j) = (0, 1), (0, 2), (1, 2)."""
    for m in range(U.shape[0]):
        for r in range(3):
            i, j = (0, 0, 1)[r], (1, 2, 2)[r]
            for c in range(3):
                for k in range(3):
                    out[m, r, c, k] = (U[m, c, i] * Vt[m, j, k] - U[m, c, j] * Vt[m, i, k]) / root


@_jit
def volume_gradients(gradients, cof, volumes, out):  # pragma: no cover (compiled; the fast tests compare it with numpy)
    """:meth:`volspring.elements.NodalStrain._volume_gradients` per tet, the same operations: ``out`` (T, 4, 3) =
    V_t cof(F_t) g_ta for ``gradients`` (T, 4, 3), ``cof`` (T, 3, 3) and ``volumes`` (T,)."""
    for t in range(gradients.shape[0]):
        for a in range(4):
            g0, g1, g2 = gradients[t, a, 0], gradients[t, a, 1], gradients[t, a, 2]
            for i in range(3):
                out[t, a, i] = ((g0 * cof[t, i, 0] + g1 * cof[t, i, 1]) + g2 * cof[t, i, 2]) * volumes[t]


@_jit
def corotated_times(scalar_indptr, scalar_indices, scalar_data, tets, rows, signs, u,
                    out):  # pragma: no cover (compiled; the fast tests compare it with numpy)
    """The product of :meth:`volspring.elements.CorotatedTets.linearize_operator`, L U - Q^T (signs * (Q U)), into
    ``out`` (n, 3, k) for the k columns of ``u`` (n, 3, k), with each of scipy's three sparse products summed in
    scipy's order. Q's three rows of tet t are ``rows[t]`` (3, 12) over the unknowns of its corners ``tets[t]``
    (node by node, component by component): each tet's twelve unknowns are gathered once for its three rows and
    each column, and scattered once. scipy's Q^T w sums each unknown's terms row after row of Q (tet by tet, twist
    by twist), as here; scipy's product reads Q twice and its row indices three times per tet (on the README beam's
    smoothed rung, 2.3 against 1.5 ms a column on a busy day: scratch ``corot40.py``)."""
    n, k = u.shape[0], u.shape[2]
    scattered = np.zeros((n, 3, k))
    for t in range(tets.shape[0]):
        for j in range(k):
            w0 = w1 = w2 = 0.0
            for a in range(4):
                node = tets[t, a]
                for c in range(3):
                    e, value = 3 * a + c, u[node, c, j]
                    w0 += rows[t, 0, e] * value
                    w1 += rows[t, 1, e] * value
                    w2 += rows[t, 2, e] * value
            w0, w1, w2 = signs[t, 0] * w0, signs[t, 1] * w1, signs[t, 2] * w2
            for a in range(4):
                node = tets[t, a]
                for c in range(3):
                    e = 3 * a + c
                    total = scattered[node, c, j]
                    total += rows[t, 0, e] * w0
                    total += rows[t, 1, e] * w1
                    total += rows[t, 2, e] * w2
                    scattered[node, c, j] = total
    for node in range(n):  # L u, less the scattered twist part
        for j in range(k):
            f0 = f1 = f2 = 0.0
            for entry in range(scalar_indptr[node], scalar_indptr[node + 1]):
                column, value = scalar_indices[entry], scalar_data[entry]
                f0 += value * u[column, 0, j]
                f1 += value * u[column, 1, j]
                f2 += value * u[column, 2, j]
            out[node, 0, j] = f0 - scattered[node, 0, j]
            out[node, 1, j] = f1 - scattered[node, 1, j]
            out[node, 2, j] = f2 - scattered[node, 2, j]


@_jit
def block_product_rows(left_indptr, left_indices, right_indptr, right_indices,
                       right_block_columns):  # pragma: no cover (compiled; the fast tests compare it with scipy)
    """(n + 1,) int64 -- the row pointer of the block product of two BSR patterns (the symbolic pass of
    :func:`block_product`): the distinct block columns each block row of the product reaches."""
    rows = left_indptr.shape[0] - 1
    last_row = np.full(right_block_columns, -1, np.int64)
    indptr = np.empty(rows + 1, np.int64)
    indptr[0] = 0
    count = 0
    for row in range(rows):
        for entry in range(left_indptr[row], left_indptr[row + 1]):
            middle = left_indices[entry]
            for other in range(right_indptr[middle], right_indptr[middle + 1]):
                column = right_indices[other]
                if last_row[column] != row:
                    last_row[column] = row
                    count += 1
        indptr[row + 1] = count
    return indptr


@numba.njit(nogil=True, inline="always")
def _multiply_add(left, right, out, R, N, C):  # pragma: no cover (compiled, inlined)
    """out (R x C, flat) += left (R x N) right (N x C), each entry from its stored value by one product after
    another (scipy's ``gemm``). Inlined with literal sizes, the loops unroll."""
    for r in range(R):
        for c in range(C):
            total = out[r * C + c]
            for d in range(N):
                total += left[r * N + d] * right[d * C + c]
            out[r * C + c] = total


@_jit
def block_product(left_indptr, left_indices, left_data, right_indptr, right_indices, right_data, indptr, indices,
                  data, R, N, C, right_block_columns):  # pragma: no cover (compiled; compared with scipy by the tests)
    """The block product of two BSR matrices into ``indices`` and ``data`` ((nnzb, R * C)) on the row pointer of
    :func:`block_product_rows`, as scipy's ``bsr_matmat`` makes it: each block row's columns in the order they are
    first reached, each block summed from zero product by product, in the order of the left row's blocks and then of
    the right row's. ``left_data`` is (nnzb, R * N), ``right_data`` (nnzb, N * C). The block sizes of the multigrid
    build, (R, N, C) = (3, 3, 6), (6, 3, 3), (6, 3, 6) and (6, 6, 6), run with loops the compiler unrolls; others
    run the same arithmetic with loops of run-time length."""
    slot = np.full(right_block_columns, -1, np.int64)
    for row in range(indptr.shape[0] - 1):
        start = count = indptr[row]
        for entry in range(left_indptr[row], left_indptr[row + 1]):
            middle = left_indices[entry]
            for other in range(right_indptr[middle], right_indptr[middle + 1]):
                column = right_indices[other]
                position = slot[column]
                if position < start:  # first reached in this row
                    position = slot[column] = count
                    indices[count] = column
                    data[count, :] = 0.0
                    count += 1
                left, right, out = left_data[entry], right_data[other], data[position]
                if R == 3 and N == 3 and C == 6:
                    _multiply_add(left, right, out, 3, 3, 6)
                elif R == 6 and N == 3 and C == 3:
                    _multiply_add(left, right, out, 6, 3, 3)
                elif R == 6 and N == 3 and C == 6:
                    _multiply_add(left, right, out, 6, 3, 6)
                elif R == 6 and N == 6 and C == 6:
                    _multiply_add(left, right, out, 6, 6, 6)
                else:
                    _multiply_add(left, right, out, R, N, C)
