"""Continuum element sets on a tet mesh: corotated tets and smoothed nodal strain and volume.

Two sets build the upper rungs of the model ladder (:mod:`volspring.ladder`):

:class:`CorotatedTets`
    Per tet, ``V_t mu_t |F_t - R_t|^2``: linear elasticity's shear energy ``mu |eps|^2`` at small
    strain, rotation-invariant at any strain (see :mod:`volspring.elements.tet_kinematics`).
:class:`NodalStrain`
    Per smoothing domain d (a node, or a cluster of nodes with ``clusters=``, and the tets of one
    region around it):
    ``V_d mu_d |Fbar_d - R_d|^2 + (kappa_d / 2) V_d (J_d - 1)^2``, Fbar_d the volume-weighted mean
    of the tets' F, J_d = v_d / V_d the domain's volume ratio (so the volume terms of all domains
    measure exactly the body's volume). With mu_d = 0 it is a pure nodal volume term.

The node-based selective smoothed element (alpha-FEM, Liu, Nguyen-Thoi, Lam 2008; NS-FEM, Liu et
al. 2009; the volumetric part on nodal volumes as in Bonet & Burton 1998) is
``CorotatedTets(mu (1 - a)) + NodalStrain(mu a, 0) + NodalStrain(0, lambda, clusters=pairs)`` (the volume
on pairs of nodes, like F-bar patches, against partial locking); springs plus a volume term are
``Springs + NodalStrain(0, kappa)``.

Both sets are matrix-free in the implicit step (:attr:`ElementSet.matrix_free`): CG applies their stiffness
as a product and the preconditioner is built from per-tet stand-in blocks on the 1-ring.

Forces are the exact gradient of the energy. :meth:`stiffness_blocks` is its exact Hessian with
``clamp_compression=False`` and a positive semi-definite approximation otherwise: the twist
coefficients of the corotational Hessian clamped (exact in the twist-free directions and at
rest), and the volume term's Gauss-Newton part ``kappa_d / V_d (dv_d/dx)(dv_d/dx)^T`` (its
dropped part is proportional to J_d - 1). A nodal term couples each node's ring with itself, so
its blocks cover the 2-ring of every node: they are stored as one block per ordered pair of ring
nodes of a domain (stencil (p, 2)), which assembly sums into the fixed block pattern.

Damping is Rayleigh's stiffness-proportional part: ``stiffness_damping`` b [s] gives the damping
force ``-b K(x) v`` (K the projected stiffness at x) and the damping blocks ``b K``; the
mass-proportional part is :class:`volspring.forces.Drag`.
"""

from __future__ import annotations

from abc import abstractmethod
from functools import cached_property, partial

import numpy as np
import scipy.sparse as sp

from volspring.elements.base import BlockMap, ElementSet, Linearization, OperatorLinearization
from volspring.elements.tet_kinematics import (_UPPER, SmoothingDomains, TetGradients, corotated, corotational,
                                              merged_pairs, pair_nodes, sparse_layout, twist_directions, twist_rows)
from volspring.material import _real_array, _real_number
from volspring.kernels import compiled, unsigned
from typing import TYPE_CHECKING, Self

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

__all__ = ["CLUSTER_RULES", "CorotatedTets", "NodalStrain"]

#: The rules a NodalStrain's ``clusters`` may be named by: name -> (rest positions, tets) -> a label per node.
CLUSTER_RULES = {"pairs": pair_nodes, "merged pairs": merged_pairs}


def _per_tet(name, value, count, *, allow_zero=True) -> np.ndarray:
    """(count,) float -- a number or one value per item, finite and >= 0 (> 0 without ``allow_zero``)."""
    array = _real_array(name, value)
    if array.ndim == 0:
        array = np.full(count, float(array))
    if array.shape != (count,):
        raise ValueError(f"{name} must be a number or have shape ({count},), got {array.shape}")
    bad = ~np.isfinite(array) | (array < 0) | ((array == 0) & (not allow_zero))
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise ValueError(f"{name}[{i}] = {array[i]!r} is not finite and {'>=' if allow_zero else '>'} 0")
    array.setflags(write=False)
    return array


def _damping_time(value) -> float:
    b = _real_number("stiffness_damping", value)
    if not (np.isfinite(b) and b >= 0):
        raise ValueError(f"stiffness_damping = {b} s is not finite and >= 0")
    return b


def _twist_vectors(twists, coefficients, vectors):
    """(m, 3, 3), (m, 3, 3) -- rows q_r a and c_r q_r a of each (m, 3) vector a: the twist part of a block
    (a, b) is ``scaled[a]^T @ plain[b]`` = sum_r c_r (q_r a)(q_r b)^T."""
    plain = np.matmul(twists, vectors[:, None, :, None])[..., 0]  # (m, r, i)
    return plain, coefficients[:, :, None] * plain


def _hessian_times(entries, coefficients, dF):
    """(m, 3, 3) -- the corotational Hessian (without its factor 2) applied to dF: dF - sum_r c_r <q_r, dF> q_r, each
    sum in a fixed order (<q, dF> over the entries row by row, then over r), so that the compiled product
    (:func:`volspring._compiled.nodal_shear_times`) makes the same bits. ``entries``: the twists q_r as
    :func:`_twist_entries` lays them out (r, i, j, m); the operations run on contiguous rows over the m matrices."""
    F = np.ascontiguousarray(np.moveaxis(dF, 0, -1))  # (i, j, m)
    inner = entries[:, 0, 0] * F[0, 0]  # (r, m)
    for i, j in _ENTRIES[1:]:
        inner = inner + entries[:, i, j] * F[i, j]
    projections = inner * coefficients.T
    correction = (projections[0] * entries[0] + projections[1] * entries[1]) + projections[2] * entries[2]
    return np.moveaxis(F - correction, -1, 0)


def _twist_entries(twists):
    """(3, 3, 3, m) -- the (m, 3, 3, 3) twists q_r[i, j] of m matrices as rows over the matrices (r, i, j, m)."""
    return np.ascontiguousarray(np.moveaxis(twists, 0, -1))


_ENTRIES = tuple((i, j) for i in range(3) for j in range(3))  # a 3x3 matrix's entries, row by row


class _TetContinuum(ElementSet):
    """What the continuum sets share: Rayleigh stiffness damping, and the matrix-free protocol on the tets
    (:attr:`ElementSet.matrix_free`: the implicit solve applies the stiffness as a product and builds its
    preconditioner from :meth:`preconditioner_blocks` on the tets' 1-ring)."""

    matrix_free = True
    kinematics: TetGradients
    stiffness_damping: float  # Rayleigh b [s]

    @abstractmethod
    def preconditioner_blocks(self, x: np.ndarray) -> np.ndarray | None:
        """(T, 16, 3, 3) -- per tet, stand-in blocks of the stiffness at x to build a preconditioner from; None when
        the set has none (a stand-in of zeros)."""

    @property
    def preconditioner_stencil(self) -> np.ndarray:
        """(T, 4) int -- the tets: the stand-in blocks of :meth:`preconditioner_blocks` couple the 1-ring only."""
        return self.kinematics.tets

    @abstractmethod
    def diagonal_blocks(self, x: np.ndarray) -> np.ndarray:
        """(n, 3, 3) -- the diagonal blocks of the projected stiffness at x (those of :meth:`stiffness_blocks`
        assembled), without the rest of it: what the preconditioner compares its stand-in's with."""

    def damping_blocks(self, x: np.ndarray) -> np.ndarray | None:
        if not self.stiffness_damping:
            return None
        return self.stiffness_damping * self.stiffness_blocks(x)

    def _scale(self, stiffness_scale, damping_scale) -> float:
        """c_K + c_D b: the factor of K in the system (the damping blocks are b K)."""
        return stiffness_scale + damping_scale * self.stiffness_damping

    def _operator(self, forces, times, x, stiffness_scale, damping_scale, times_many, diagonal) -> OperatorLinearization:
        """The linearisation; ``diagonal``: () -> (n, 3, 3) the diagonal blocks of K, from the linearisation's own
        state (:meth:`diagonal_blocks` without its kinematics)."""
        scale = self._scale(stiffness_scale, damping_scale)
        def preconditioner():
            blocks = self.preconditioner_blocks(x)
            return None if blocks is None else scale * blocks

        return OperatorLinearization(forces, times, scale, self, preconditioner, times_many,
                                     diagonal=lambda: scale * diagonal())

    def with_stiffness_damping(self, b: float) -> Self:
        """A copy with Rayleigh stiffness damping b [s] (the kinematics and domains are shared)."""
        copy = object.__new__(type(self))
        copy.__dict__.update(self.__dict__)
        copy.stiffness_damping = _damping_time(b)
        return copy


class CorotatedTets(_TetContinuum):
    """Per-tet corotational shear energy ``V_t mu_t |F_t - R_t|^2`` (see the module docstring).

    Parameters
    ----------
    rest_positions : (n, 3) float
        [m]
    tets : (T, 4) int
        positively oriented tets
    shear : float or (T,) float
        mu_t [Pa], >= 0 (the shear modulus times the tet's weight)
    stiffness_damping : float
        Rayleigh b [s], >= 0

    Examples
    --------
    >>> import numpy as np
    >>> from volspring.elements import CorotatedTets
    >>> corners = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    >>> tet = CorotatedTets(corners, [[0, 1, 2, 3]], shear=1e6)
    >>> turn = np.array([[0., -1, 0], [1, 0, 0], [0, 0, 1]])      # a rigid rotation: no energy, no force
    >>> float(tet.energy(corners @ turn.T)), float(abs(tet.forces(corners @ turn.T)).max()) < 1e-9
    (0.0, True)
    """

    name = "corotated tets"

    def __init__(self, rest_positions: ArrayLike, tets: ArrayLike, shear: float | ArrayLike, *,
                 stiffness_damping: float = 0.0):
        rest = np.asarray(rest_positions, dtype=np.float64)
        self.node_count = len(rest)
        self.kinematics = TetGradients.at_rest(rest, tets)
        self.shear = _per_tet("shear", shear, len(self.kinematics.tets))
        self.stiffness_damping = _damping_time(stiffness_damping)

    @classmethod
    def from_kinematics(cls, kinematics: TetGradients, node_count: int, shear: float | ArrayLike, *,
                        stiffness_damping: float = 0.0) -> "CorotatedTets":
        """The set on tets whose :class:`TetGradients` are already computed (shared, not copied)."""
        tets = object.__new__(cls)
        tets.node_count, tets.kinematics = int(node_count), kinematics
        tets.shear = _per_tet("shear", shear, len(kinematics.tets))
        tets.stiffness_damping = _damping_time(stiffness_damping)
        return tets

    @property
    def stencil(self) -> np.ndarray:
        return self.kinematics.tets

    def _weights(self):
        return self.kinematics.volumes * self.shear

    def energy(self, x: np.ndarray) -> float:
        psi, *_ = corotational(self.kinematics.deformation(np.asarray(x, dtype=np.float64)))
        return float(self._weights() @ psi)

    def _forces_from(self, P):
        return -self.kinematics.spread(self._weights()[:, None, None] * P, self.node_count)

    def forces(self, x: np.ndarray, v: np.ndarray | None = None) -> np.ndarray:
        x = np.asarray(x, dtype=np.float64)
        _, P, twists, coefficients = corotational(self.kinematics.deformation(x))
        forces = self._forces_from(P)
        if v is not None and self.stiffness_damping:
            forces += self._damping_forces(twists, coefficients, v)
        return forces

    def _damping_forces(self, twists, coefficients, v):
        dP = 2.0 * _hessian_times(_twist_entries(twists), coefficients,
                                  self.kinematics.deformation(np.asarray(v, dtype=np.float64)))
        return self.stiffness_damping * self._forces_from(dP)

    def _blocks(self, twists, coefficients):
        g = self.kinematics.gradients
        T = len(g)
        plain, scaled = _twist_vectors(np.repeat(twists, 4, axis=0), np.repeat(coefficients, 4, axis=0),
                                       g.reshape(-1, 3))
        plain, scaled = plain.reshape(T, 4, 3, 3), scaled.reshape(T, 4, 3, 3)
        twist = np.matmul(np.swapaxes(scaled, -1, -2)[:, :, None], plain[:, None, :])  # (T, a, b, 3, 3)
        dots = np.matmul(g, np.swapaxes(g, 1, 2))  # (T, a, b)
        blocks = dots[..., None, None] * np.eye(3) - twist
        return (2.0 * self._weights())[:, None, None, None, None] * blocks

    def stiffness_blocks(self, x: np.ndarray, *, clamp_compression: bool = True) -> np.ndarray:
        _, _, twists, coefficients = corotational(self.kinematics.deformation(np.asarray(x, dtype=np.float64)),
                                                  project=clamp_compression)
        return self._blocks(twists, coefficients).reshape(-1, 16, 3, 3)

    def diagonal_blocks(self, x: np.ndarray) -> np.ndarray:
        """(n, 3, 3) -- the diagonal blocks of the projected stiffness at x: per tet corner a, 2 w_t ((g_a . g_a) I
        - sum_r c_r (q_r g_a)(q_r g_a)^T), summed over each node's tets."""
        rows, signs = self._twist_rows(np.asarray(x, dtype=np.float64))[:2]
        return self._diagonal(rows, signs)

    def _twist_rows(self, x):
        """(rows, signs, U, V^T, P, coefficients) at x: the rows (T, 3, 4, 3) sqrt(2 w |c_r|) q_r g_a of the
        twist part of K and their signs (T, 3), with the corotation they are made from."""
        U, Vt, _, P, coefficients = corotated(self.kinematics.deformation(x))
        scale = np.sqrt(2.0 * self._weights()[:, None] * np.abs(coefficients))
        return twist_rows(U, Vt, self.kinematics.gradients, scale), np.sign(coefficients), U, Vt, P, coefficients

    def _diagonal(self, rows, signs):
        """(n, 3, 3) -- the diagonal blocks of K = L - Q^T diag(signs) Q from its twist rows: L's diagonal times I,
        less sum_r sign_r (rows_r a)(rows_r a)^T of each tet corner a, summed over each node's tets."""
        R = np.ascontiguousarray(np.reshape(rows, (-1, 3, 4, 3)).transpose(1, 3, 0, 2))  # (r, i, T, a)
        S = R * signs.T[:, None, :, None]
        twist = [(S[0, i] * R[0, j] + S[1, i] * R[1, j]) + S[2, i] * R[2, j] for i, j in _UPPER]
        return self._scalar_part.diagonal()[:, None, None] * np.eye(3) - \
            _node_sums(self.kinematics.tets.ravel(), [entry.ravel() for entry in twist], self.node_count)

    def linearize(self, x: ArrayLike, v: np.ndarray | None = None, *, stiffness_scale: float = 1.0,
                  damping_scale: float = 0.0, clamp_compression: bool = True) -> Linearization:
        x = np.asarray(x, dtype=np.float64)
        F = self.kinematics.deformation(x)
        _, P, twists, coefficients = corotational(F, project=clamp_compression)
        forces = self._forces_from(P)
        stiffness = self._blocks(twists, coefficients).reshape(-1, 16, 3, 3)
        if v is not None and self.stiffness_damping:
            projected = corotational(F)[2:] if not clamp_compression else (twists, coefficients)
            forces += self._damping_forces(*projected, v)
        return Linearization(forces, self._scale(stiffness_scale, damping_scale) * stiffness, stiffness, self)

    def placed(self, rest_positions: np.ndarray, node_map: ArrayLike) -> "CorotatedTets":
        """The same tets and coefficients in another node numbering (``node_map[i]``: the new index of node i)
        and on other rest positions (the body moved rigidly into a scene)."""
        return CorotatedTets(rest_positions, np.asarray(node_map)[self.kinematics.tets], self.shear,
                             stiffness_damping=self.stiffness_damping)

    # ------------------------------------------------------------------ matrix-free
    def preconditioner_blocks(self, x: np.ndarray) -> np.ndarray:
        """(T, 16, 3, 3) -- the projected stiffness blocks themselves (already on the 1-ring)."""
        return self.stiffness_blocks(x)

    def linearize_operator(self, x: np.ndarray, v: np.ndarray | None = None, *, stiffness_scale: float = 1.0,
                           damping_scale: float = 0.0) -> OperatorLinearization:
        """Forces at (x, v) and the projected stiffness as a product (:class:`OperatorLinearization`).

        The blocks are K_ab = 2 w (g_a . g_b) I - sum_r 2 w c_r (q_r g_a)(q_r g_b)^T (w = V_t mu_t): a constant
        scalar matrix L (the 1-ring, built once) times each component, minus a rank-3-per-tet part
        Q^T diag(sign c) Q, Q the (3 T, 3 n) rows sqrt(2 w |c_r|) q_r g_a filled in a fixed layout at each
        linearisation. K u = L u - Q^T (sign c * (Q u)): three sparse products (the twist projection of
        every tet by dF = G u and a spread took six and a Hessian per tet, about three times as long). With the
        ``fast`` extra the same sums run tet by tet (:func:`volspring._compiled.corotated_times`), and Q is never
        made as a sparse matrix."""
        x = np.asarray(x, dtype=np.float64)
        rows, signs, U, Vt, P, coefficients = self._twist_rows(x)  # rows (T, r, a, i) = sqrt(2 w |c_r|) (q_r g_a)_i
        forces = self._forces_from(P)
        if v is not None and self.stiffness_damping:
            forces += self._damping_forces(twist_directions(U, Vt), coefficients, v)
        L = self._scalar_part
        diagonal = partial(self._diagonal, rows, signs)
        kernels = compiled()
        if kernels is not None:  # the same sums compiled, tet by tet (volspring._compiled.corotated_times)
            n, tets = self.node_count, self._kernel_tets
            scalar_indptr, scalar_indices = unsigned(L.indptr), unsigned(L.indices)
            rows = rows.reshape(-1, 3, 12)

            def compiled_times_many(U):
                U = np.ascontiguousarray(U, dtype=np.float64)
                if U.ndim != 3 or U.shape[:2] != (n, 3):  # the kernel does not check its indices
                    raise ValueError(f"u has {len(U)} rows; expected {n}, one per node")
                out = np.empty(U.shape)
                kernels.corotated_times(scalar_indptr, scalar_indices, L.data, tets, rows, signs, U, out)
                return out

            def compiled_times(u):
                return compiled_times_many(np.reshape(u, (-1, 3, 1)))[:, :, 0]

            return self._operator(forces, compiled_times, x, stiffness_scale, damping_scale, compiled_times_many,
                                  diagonal)

        indices, indptr = self._twist_layout
        signs = signs.ravel()
        Q = sp.csr_matrix((rows.ravel(), indices, indptr), shape=(len(indptr) - 1, 3 * self.node_count))
        Qt = Q.T

        def times_many(U):  # (n, 3, k): each matrix read once for all columns, each column's sums as alone
            n, _, k = U.shape
            U = np.asarray(U, dtype=np.float64)
            return (L @ U.reshape(n, 3 * k)).reshape(n, 3, k) - \
                (Qt @ (signs[:, None] * (Q @ U.reshape(3 * n, k)))).reshape(n, 3, k)

        def times(u):
            return times_many(np.reshape(u, (-1, 3, 1)))[:, :, 0]

        return self._operator(forces, times, x, stiffness_scale, damping_scale, times_many, diagonal)

    @cached_property
    def _kernel_tets(self):
        """(T, 4) unsigned -- the tets' corners as the compiled product indexes them (:func:`unsigned`)."""
        return unsigned(np.ascontiguousarray(self.kinematics.tets))

    @cached_property
    def _twist_layout(self):
        """(indices, indptr) of the (3 T, 3 n) twist rows: row (t, r) holds the 12 unknowns of tet t's corners."""
        tets = self.kinematics.tets
        T = len(tets)
        columns = (3 * np.repeat(tets, 3, axis=1) + np.tile(np.arange(3), 4)).reshape(T, 1, 12)
        return sparse_layout(np.broadcast_to(columns, (T, 3, 12)).ravel(), np.arange(0, 36 * T + 1, 12),
                             3 * self.node_count)

    @cached_property
    def _scalar_part(self):
        """(n, n) CSR -- 2 w_t (g_ta . g_tb) summed over tets: the constant part of K, per component."""
        tets, g = self.kinematics.tets, self.kinematics.gradients
        values = 2.0 * self._weights()[:, None, None] * np.matmul(g, np.swapaxes(g, 1, 2))
        rows = np.broadcast_to(tets[:, :, None], values.shape)
        columns = np.broadcast_to(tets[:, None, :], values.shape)
        return sp.csr_matrix((values.ravel(), (rows.ravel(), columns.ravel())),
                             shape=(self.node_count, self.node_count))

    def __repr__(self) -> str:
        return f"CorotatedTets({self.element_count} tets, b={self.stiffness_damping:g} s)"


class NodalStrain(_TetContinuum):
    """Smoothed nodal shear and volume energy on the smoothing domains of a tet mesh (module docstring).

    Parameters
    ----------
    rest_positions : (n, 3) float
        [m]
    tets : (T, 4) int
        positively oriented tets
    shear : float or (T,) float
        mu [Pa] >= 0, per tet (a domain takes its region's value)
    bulk : float or (T,) float
        kappa [Pa] >= 0, the volume term's coefficient, per tet
    regions : (T,) int, optional
        material region of each tet; domains never cross regions, and every tet of one region must have the same
        ``shear`` and ``bulk``
    clusters : (n,) int, "pairs" or "merged pairs", optional
        a cluster label per node: each domain is then a cluster of nodes and the tets around them; ``"pairs"``: the
        pairs of :func:`~volspring.elements.tet_kinematics.pair_nodes`, ``"merged pairs"``: those pairs with the ones
        that have no interior node merged into a neighbour (:func:`~volspring.elements.tet_kinematics.merged_pairs`);
        a scene gives the domains of either rule to the free nodes (:meth:`supported`); default one domain per node
    held : (n,) bool, optional
        nodes held in place: the domains are the free nodes' (a tet's volume is shared among its free corners;
        :class:`~volspring.elements.tet_kinematics.SmoothingDomains`)
    stiffness_damping : float
        Rayleigh b [s], >= 0
    stand_in_bulk : float or (T,) float, optional
        the per-tet volume coefficient of the preconditioner's stand-in (:meth:`preconditioner_blocks`), >= 0; default
        ``bulk``. It changes no force or product, only the implicit solve's preconditioner: the model ladder caps it
        at :data:`~volspring.ladder.STAND_IN_BULK_CAP` times the tet's shear modulus

    Examples
    --------
    A cube squeezed uniformly by 1% loses 3% of its volume (J = 0.99^3) whatever the mesh:

    >>> import numpy as np
    >>> from meshing import structured_box
    >>> from volspring.elements import NodalStrain
    >>> cube = structured_box((2, 2, 2), (1.0, 1.0, 1.0))
    >>> volume = NodalStrain(cube.points, cube.tets, shear=0.0, bulk=1e6)
    >>> round(volume.energy(0.99 * cube.points) / (0.5e6 * (0.99**3 - 1) ** 2), 12)
    1.0
    """

    name = "nodal strain"
    #: Weight of the per-tet volume term in the preconditioner's stand-in (see :meth:`preconditioner_blocks`).
    PRECONDITIONER_BULK = 1.0

    def __init__(self, rest_positions: ArrayLike, tets: ArrayLike, shear: float | ArrayLike, bulk: float | ArrayLike,
                 *, regions: ArrayLike | None = None, clusters: ArrayLike | str | None = None,
                 held: ArrayLike | None = None, stiffness_damping: float = 0.0,
                 stand_in_bulk: float | ArrayLike | None = None):
        rest = np.array(rest_positions, dtype=np.float64)
        rest.setflags(write=False)
        self.node_count = len(rest)
        self.rest_positions = rest
        self.kinematics = TetGradients.at_rest(rest, tets)
        T = len(self.kinematics.tets)
        shear, bulk = _per_tet("shear", shear, T), _per_tet("bulk", bulk, T)
        self.stand_in_bulk = bulk if stand_in_bulk is None else _per_tet("stand_in_bulk", stand_in_bulk, T)
        if regions is not None:
            regions = np.asarray(regions)
            if regions.shape != (T,) or regions.dtype.kind not in "iu" or (T and regions.min() < 0):
                raise ValueError(f"regions must be ({T},) integers >= 0, one per tet; got shape {regions.shape}, "
                                 f"dtype {regions.dtype}")
        #: The rule that made the clusters ("pairs" or "merged pairs": they follow the supports), else None.
        self.cluster_rule = None
        if isinstance(clusters, str):
            if clusters not in CLUSTER_RULES:
                raise ValueError(f"clusters = {clusters!r}: expected one of {', '.join(map(repr, CLUSTER_RULES))} or a "
                                 "cluster label per node")
            self.cluster_rule = clusters
            clusters = CLUSTER_RULES[clusters](rest, self.kinematics.tets)
        if clusters is not None:
            clusters = np.asarray(clusters)
            if clusters.shape != (self.node_count,) or clusters.dtype.kind not in "iu" or \
                    (self.node_count and clusters.min() < 0):
                raise ValueError(f"clusters must be ({self.node_count},) integer labels >= 0, one per node; got shape "
                                 f"{clusters.shape}, dtype {clusters.dtype}")
            clusters = clusters.astype(np.int64)
            clusters.setflags(write=False)
        if held is not None:
            held = np.array(held)
            if held.shape != (self.node_count,) or held.dtype != bool:
                raise ValueError(f"held must be ({self.node_count},) bool, one entry per node; got shape {held.shape}, "
                                 f"dtype {held.dtype}")
            held.setflags(write=False)
        self.clusters, self.held = clusters, held
        self.domains = SmoothingDomains(self.kinematics, self.node_count, regions, clusters, held)
        corner = self.domains.corner_domain
        self.shear = np.zeros(self.domains.domain_count)
        self.bulk = np.zeros(self.domains.domain_count)
        self.shear[corner.ravel()] = np.repeat(shear, 4)
        self.bulk[corner.ravel()] = np.repeat(bulk, 4)
        for name, per_tet, per_domain in (("shear", shear, self.shear), ("bulk", bulk, self.bulk)):
            mixed = per_domain[corner] != per_tet[:, None]
            if mixed.any():
                t = int(np.flatnonzero(mixed.any(axis=1))[0])
                raise ValueError(f"{name} differs between tets of one region around a node (tet {t}: {per_tet[t]!r}); "
                                 "give every tet of a region the same value, or tag the tets with regions=")
        self.stiffness_damping = _damping_time(stiffness_damping)

    # ------------------------------------------------------------------ layout
    @cached_property
    def stencil(self) -> np.ndarray:
        first, second = self.domains.pairs
        nodes = self.domains.ring_node
        return np.stack([nodes[first], nodes[second]], axis=1)

    @cached_property
    def block_map(self) -> BlockMap:
        one = np.zeros(1, dtype=np.int64)
        return BlockMap(one, one + 1, one, np.ones(1), 1)

    @cached_property
    def _pair_domain(self):
        return self.domains.ring_domain[self.domains.pairs[0]]

    @cached_property
    def _identity_blocks(self):
        """(p, 3, 3) -- the shear blocks' constant part 2 mu_d V_d (gbar_a . gbar_b) I of every pair."""
        first, second = self.domains.pairs
        gradient = self.domains.ring_gradient
        weights = 2.0 * (self.shear * self.domains.volumes)[self._pair_domain]
        dots = weights * np.einsum("pi,pi->p", gradient[first], gradient[second])
        return dots[:, None, None] * np.eye(3)

    # ------------------------------------------------------------------ kinematics
    def _state(self, x, project, *, volume=None):
        """Everything forces and blocks need at x: the volume kinematics when the set has a volume term (or
        ``volume`` asks for them), the smoothed rotation when it has shear."""
        state: dict[str, np.ndarray] = {}
        if self.bulk.any() if volume is None else volume:
            F = self.kinematics.deformation(x)
            cof = _cofactor(F)
            state.update(F=F, cof=cof, J=self._volume_ratios(F, cof))
        if self.shear.any():
            psi, P, twists, coefficients = corotational(self.domains.averaged(x), project=project)
            state.update(psi=psi, P=P, twists=twists, coefficients=coefficients)
        return state

    def _volume_ratios(self, F, cof):
        """(d,) -- each domain's volume ratio J_d = sum of V_t det F_t over its tets' corners, weighted by the corners'
        shares, over V_d. det F = cof(F) : F / 3 with its nine products summed in row order, and the corners summed in
        the order of the tets and their corners (np.bincount's), so that the compiled kernel
        (:func:`volspring._compiled.volume_ratios`) makes the same bits."""
        domains = self.domains
        kernels = compiled()
        if kernels is not None:
            J = np.zeros(domains.domain_count)
            kernels.volume_ratios(np.ascontiguousarray(F), cof, self.kinematics.volumes, domains.corner_domain,
                                  domains.corner_share, domains.volumes, J)
            return J
        products = (cof * F).reshape(-1, 9)
        det = products[:, 0] + products[:, 1]
        for k in range(2, 9):
            det += products[:, k]
        det /= 3.0
        current = np.bincount(domains.corner_domain.ravel(),
                              weights=((self.kinematics.volumes * det)[:, None] * domains.corner_share).ravel(),
                              minlength=domains.domain_count)
        return current / domains.volumes

    def energy(self, x: np.ndarray) -> float:
        state = self._state(np.asarray(x, dtype=np.float64), True)
        V = self.domains.volumes
        total = 0.5 * float((self.bulk * V) @ (state["J"] - 1.0) ** 2) if "J" in state else 0.0
        if "psi" in state:
            total += float((self.shear * V) @ state["psi"])
        return total

    def _volume_gradients(self, state):
        """(T, 4, 3) -- dv_t/dx_a = V_t cof(F_t) g_ta, entry by entry in a fixed order, so that the compiled kernel
        (:func:`volspring._compiled.volume_gradients`, 4.3 -> 0.4 ms on 15,360 tets) makes the same bits."""
        g, cof, volumes = self.kinematics.gradients, np.ascontiguousarray(state["cof"]), self.kinematics.volumes
        out = np.empty(g.shape)
        kernels = compiled()
        if kernels is not None:
            kernels.volume_gradients(g, cof, volumes, out)
            return out
        for i in range(3):
            out[:, :, i] = (g[:, :, 0] * cof[:, i, 0, None] + g[:, :, 1] * cof[:, i, 1, None]) + \
                g[:, :, 2] * cof[:, i, 2, None]
        out *= volumes[:, None, None]
        return out

    def _forces(self, state):
        forces = np.zeros((self.node_count, 3))
        if self.bulk.any():
            # dv_t/dx_a = V_t cof(F_t) g_ta: the pressure forces spread V_t pbar_t cof(F_t) like a stress.
            forces -= self.kinematics.spread(self._pressure_stress(state), self.node_count)
        if "P" in state:
            forces -= self.domains.spread((self.shear * self.domains.volumes)[:, None, None] * state["P"])
        return forces

    def forces(self, x: np.ndarray, v: np.ndarray | None = None) -> np.ndarray:
        x = np.asarray(x, dtype=np.float64)
        state = self._state(x, True)
        forces = self._forces(state)
        if v is not None and self.stiffness_damping:
            forces -= self.stiffness_damping * self._stiffness_times(state, np.asarray(v, dtype=np.float64))
        return forces

    def _ring_volume_gradients(self, state):
        """(r, 3) -- dv_d/dx_a for every ring entry (d, a): each tet corner's dv_t/dx_a times the share of the
        tet's volume in the domain of each of its corners, summed by one sparse product."""
        gradients = self._volume_gradients(state).reshape(-1, 3)
        kernels = compiled()
        if kernels is not None:  # the same sums compiled (scipy's product with three columns: 2.8 ms a step)
            total = self._ring_sum
            out = np.empty((total.shape[0], 3))
            kernels.csr_times(unsigned(total.indptr), unsigned(total.indices), total.data,
                              np.ascontiguousarray(gradients), out)
            return out
        return self._ring_sum @ gradients

    @cached_property
    def _ring_sum(self):
        """(r, 4 T) sparse -- sums corner_share[t, c] x (row 4 t + a) into the ring entry of (domain of c, a)."""
        domains = self.domains
        T = len(domains.corner_entry)
        corner_rows = np.broadcast_to((4 * np.arange(T)[:, None] + np.arange(4))[:, None, :], (T, 4, 4))
        shares = np.broadcast_to(domains.corner_share[:, :, None], (T, 4, 4))
        total = sp.csr_matrix((shares.ravel(), (domains.corner_entry.ravel(), corner_rows.ravel())),
                              shape=(len(domains.ring_node), 4 * T))
        total.sum_duplicates()
        return total

    def _mean_pressure(self, pressure):
        """(T,) -- pbar_t: the pressures of the domains of a tet's corners, weighted by the corners' shares and summed
        corner after corner (:func:`volspring._compiled.pressure_stress`'s order)."""
        p, share = pressure[self.domains.corner_domain], self.domains.corner_share
        return ((p[:, 0] * share[:, 0] + p[:, 1] * share[:, 1]) + p[:, 2] * share[:, 2]) + p[:, 3] * share[:, 3]

    def _pressure_stress(self, state):
        """(T, 3, 3) -- V_t pbar_t cof(F_t), what the pressure forces spread (pressures kappa_d (J_d - 1))."""
        pressure = self.bulk * (state["J"] - 1.0)
        kernels = compiled()
        if kernels is not None:
            stress = np.empty(state["cof"].shape)
            kernels.pressure_stress(pressure, self.domains.corner_domain, self.domains.corner_share,
                                    self.kinematics.volumes, state["cof"], stress)
            return stress
        return (self._mean_pressure(pressure) * self.kinematics.volumes)[:, None, None] * state["cof"]

    def _stiffness_times(self, state, u):
        """(n, 3) -- K u with the projected K at ``state``, without forming K."""
        return self._stiffness_times_many(state, u.reshape(-1, 3, 1))[:, :, 0]

    def _volume_rows(self, state):
        """(W, W^T) -- the (d, 3 n) rows dv_d/dx at ``state`` (CSR) and their transpose (a CSC view: no conversion),
        made once per state and kept in it: CG applies the product many times at one state."""
        if "volume_rows" not in state:
            indices, indptr = self.domains.volume_layout
            W = sp.csr_matrix((self._ring_volume_gradients(state).ravel(), indices, indptr),
                              shape=(self.domains.domain_count, 3 * self.node_count))
            state["volume_rows"] = W, W.T
        return state["volume_rows"]

    def _product_factors(self, state):
        """(kappa_d / V_d as a (d, 1) column, mu_d V_d (d,)) -- what the product weighs each domain's volume rate and
        shear stress by, None for a term the set has not; made once per state (CG applies the product many times at
        one state, and a set's product takes a fraction of a millisecond)."""
        if "product_factors" not in state:
            domains = self.domains
            bulk = (self.bulk / domains.volumes)[:, None] if self.bulk.any() else None
            weights = self.shear * domains.volumes if "P" in state else None
            state["product_factors"] = bulk, weights
        return state["product_factors"]

    def _stiffness_times_many(self, state, U):
        """(n, 3, k) -- K U, column j the bits of ``_stiffness_times(state, U[:, :, j])``: the sparse factors (the
        domains' volume rows, averaging and spreading) are read once for all columns."""
        domains = self.domains
        n, _, k = U.shape
        result = np.zeros((n, 3, k))
        bulk, weights = self._product_factors(state)
        if bulk is not None:
            W, Wt = self._volume_rows(state)
            rate = W @ U.reshape(3 * n, k)
            result += (Wt @ (bulk * rate)).reshape(n, 3, k)
        if weights is not None:
            kernels = compiled()
            if kernels is not None:  # the same sums compiled, column by column (each column's sums are as alone)
                if n != self.node_count:  # the kernel does not check its indices
                    raise ValueError(f"u has {n} rows; expected {self.node_count}, one per node")
                averaging, spreading = domains.averaging_layout, domains.spreading_layout
                twists, coefficients = state["twists"], state["coefficients"]
                for j in range(k):
                    column = np.ascontiguousarray(U[:, :, j])
                    spread = np.empty((n, 3))
                    kernels.nodal_shear_times(*averaging, column, twists, coefficients, weights, *spreading, spread)
                    result[:, :, j] += spread
                return result
            if "twist_entries" not in state:  # made once per state: CG applies the product many times at one
                state["twist_entries"] = _twist_entries(state["twists"])
            dP = [weights[:, None, None] * (2.0 * _hessian_times(state["twist_entries"], state["coefficients"], dF))
                  for dF in domains.averaged_many(U)]
            result += domains.spread_many(np.stack(dP, axis=-1))
        return result

    def _blocks(self, state, exact):
        first, second = self.domains.pairs
        V = self.domains.volumes
        blocks = np.zeros((len(first), 3, 3))
        if "J" in state:
            w = self._ring_volume_gradients(state) * np.sqrt(self.bulk / V)[self.domains.ring_domain][:, None]
            blocks += w[first][:, :, None] * w[second][:, None, :]
        if "P" in state:
            # Per ring entry, the twist rows weighted by sqrt(2 mu_d V_d); the constant part is cached.
            entry_domain = self.domains.ring_domain
            root = np.sqrt(2.0 * self.shear * V)[entry_domain][:, None, None]
            plain, scaled = _twist_vectors(state["twists"][entry_domain], state["coefficients"][entry_domain],
                                           self.domains.ring_gradient)
            blocks -= np.matmul(np.swapaxes(root * scaled, 1, 2)[first], (root * plain)[second])
            blocks += self._identity_blocks
        if exact and "J" in state:
            blocks += self._volume_curvature(state)
        return blocks[:, None]

    def _volume_curvature(self, state):
        """(p, 3, 3) -- sum_t pbar_t d^2 v_t / dx_a dx_b, put on the pairs of the domain of each tet's corner 0."""
        domains, g = self.domains, self.kinematics.gradients
        pressure = self.bulk * (state["J"] - 1.0)
        mean_pressure = self._mean_pressure(pressure)
        # d^2 v / dx_a dx_b = -V [F (g_a x g_b)]_x  (the skew matrix of that vector)
        cross = np.cross(g[:, :, None, :], g[:, None, :, :])  # (T, 4, 4, 3)
        vector = np.einsum("tij,tabj->tabi", state["F"], cross) * (-(mean_pressure * self.kinematics.volumes))[
            :, None, None, None]
        skew = np.zeros(vector.shape + (3,))
        skew[..., 0, 1], skew[..., 0, 2], skew[..., 1, 2] = -vector[..., 2], vector[..., 1], -vector[..., 0]
        skew[..., 1, 0], skew[..., 2, 0], skew[..., 2, 1] = vector[..., 2], -vector[..., 1], vector[..., 0]
        # Pair index of (entry of a, entry of b) within the domain of corner 0.
        counts = np.bincount(domains.ring_domain, minlength=domains.domain_count)
        ring_start = np.concatenate([[0], np.cumsum(counts)[:-1]])
        pair_start = np.concatenate([[0], np.cumsum(counts**2)[:-1]])
        d0 = domains.corner_domain[:, 0]
        local = domains.corner_entry[:, 0, :] - ring_start[d0][:, None]  # (T, 4)
        pair = pair_start[d0][:, None, None] + local[:, :, None] * counts[d0][:, None, None] + local[:, None, :]
        out = np.zeros((len(domains.pairs[0]), 9))
        flat = skew.reshape(-1, 9)
        for k in range(9):
            out[:, k] = np.bincount(pair.ravel(), weights=flat[:, k], minlength=len(out))
        return out.reshape(-1, 3, 3)

    def stiffness_blocks(self, x: np.ndarray, *, clamp_compression: bool = True) -> np.ndarray:
        state = self._state(np.asarray(x, dtype=np.float64), clamp_compression)
        return self._blocks(state, not clamp_compression)

    def diagonal_blocks(self, x: np.ndarray) -> np.ndarray:
        """(n, 3, 3) -- the diagonal blocks of the projected stiffness at x: those of :meth:`stiffness_blocks` that
        join a ring entry to itself (a domain's ring holds each node once), summed over each node's domains."""
        return self._diagonal(self._state(np.asarray(x, dtype=np.float64), True))

    def _diagonal(self, state):
        """:meth:`diagonal_blocks` at a linearisation's ``state``: per ring entry a of domain d, kappa_d / V_d
        (dv_d/dx_a)(dv_d/dx_a)^T and 2 mu_d V_d ((gbar_a . gbar_a) I - sum_r c_r (q_r gbar_a)(q_r gbar_a)^T)."""
        domains = self.domains
        domain, V = domains.ring_domain, domains.volumes
        entries = [np.zeros(len(domain)) for _ in _UPPER]  # entry (i, j) of every ring entry's block
        if "J" in state:
            w = np.ascontiguousarray((self._ring_volume_gradients(state) * np.sqrt(self.bulk / V)[domain][:, None]).T)
            for entry, (i, j) in zip(entries, _UPPER):
                entry += w[i] * w[j]
        if "P" in state:
            if "twist_entries" not in state:
                state["twist_entries"] = _twist_entries(state["twists"])
            twists = state["twist_entries"][..., domain]  # (r, i, j, a): the twists of each entry's domain
            g = np.ascontiguousarray(domains.ring_gradient.T)
            plain = (twists[..., 0, :] * g[0] + twists[..., 1, :] * g[1]) + twists[..., 2, :] * g[2]  # q_r gbar_a
            scaled = state["coefficients"][domain].T[:, None, :] * plain
            weight = (2.0 * self.shear * V)[domain]
            dots = (g[0] * g[0] + g[1] * g[1]) + g[2] * g[2]
            for entry, (i, j) in zip(entries, _UPPER):
                twist = (scaled[0, i] * plain[0, j] + scaled[1, i] * plain[1, j]) + scaled[2, i] * plain[2, j]
                entry += weight * ((dots if i == j else 0.0) - twist)
        return _node_sums(domains.ring_node, entries, self.node_count)

    def linearize(self, x: ArrayLike, v: ArrayLike | None = None, *, stiffness_scale: float = 1.0,
                  damping_scale: float = 0.0, clamp_compression: bool = True) -> Linearization:
        x = np.asarray(x, dtype=np.float64)
        state = self._state(x, clamp_compression)
        forces = self._forces(state)
        stiffness = self._blocks(state, not clamp_compression)
        if v is not None and self.stiffness_damping:
            damped = state if clamp_compression else self._state(x, True)
            forces -= self.stiffness_damping * self._stiffness_times(damped, np.asarray(v, dtype=np.float64))
        return Linearization(forces, self._scale(stiffness_scale, damping_scale) * stiffness, stiffness, self)

    # ------------------------------------------------------------------ matrix-free
    @cached_property
    def _tet_shear(self) -> CorotatedTets:
        """Per tet, the corotated shear with the shear coefficient of its region's domains."""
        corner = self.domains.corner_domain[:, 0]
        return CorotatedTets.from_kinematics(self.kinematics, self.node_count, self.shear[corner])

    def preconditioner_blocks(self, x: np.ndarray) -> np.ndarray | None:
        """(T, 16, 3, 3) -- a 1-ring stand-in for the projected stiffness, to build a preconditioner from (None for a
        set with neither shear nor stand-in bulk).

        Per tet, the corotated shear ``V_t mu |F_t - R_t|^2`` and the Gauss-Newton part of a per-tet
        volume term ``(c kappa_s / 2) V_t (J_t - 1)^2`` (c = :attr:`PRECONDITIONER_BULK`), with the
        domains' mu and the tet's ``stand_in_bulk`` kappa_s (kappa unless capped, see the constructor). Why a
        cap: the per-tet term locks, so where kappa >> mu it is far stiffer than the nodal term in most volume
        changes. On the smoothed and volume rungs of a 3,321-node beam over 20 steps from rest, CG took with
        kappa_s = kappa, 10 mu and 5 mu: 1054, 909 and 897 iterations (smoothed) and 973, 855 and 854 (volume rung)
        at nu 0.499; 384, 353 and 355 and 360, 334 and 331 at nu 0.49; 179, 179 and 173 and 175, 175 and 167 at nu
        0.45 (kappa 9 and 8 mu); with 3 mu, 177 and 165 there, and with 20 mu 941 on the smoothed rung at nu 0.499.

        By convexity (Fbar is a mean of F_t) the per-tet shear bounds the smoothed one from above, so the stand-in
        is stiffer in shear; the per-tet volume term is stiffer in the volumetric modes that the nodal term leaves
        soft (that is what locking is), which only costs CG iterations. It has the springs' sparsity (a sixth of the
        2-ring's 3x3 blocks): on a 3,321-node beam at nu 0.45, dt 0.01 s, an AMG hierarchy built from it needed 13
        CG iterations to rtol 1e-3 where one built from the exact 2-ring matrix needed 7, at a quarter of the cost
        per V-cycle (c = 0: 21 iterations, 0.2: 15).
        """
        x = np.asarray(x, dtype=np.float64)
        tets, bulk = self._tet_shear, self.stand_in_bulk
        if not (tets.shear.any() or bulk.any()):
            return None  # the smoothed rung's merged pairs: the pairs' stand-in stands in for both
        blocks = tets.stiffness_blocks(x) if tets.shear.any() else np.zeros((len(bulk), 16, 3, 3))
        if bulk.any():
            state = {"cof": _cofactor(self.kinematics.deformation(x))}
            w = self._volume_gradients(state)  # (T, 4, 3) dv_t / dx_a
            w = w * np.sqrt(self.PRECONDITIONER_BULK * bulk / self.kinematics.volumes)[:, None, None]
            blocks += (w[:, :, None, :, None] * w[:, None, :, None, :]).reshape(-1, 16, 3, 3)
        return blocks

    def linearize_operator(self, x: np.ndarray, v: np.ndarray | None = None, *, stiffness_scale: float = 1.0,
                           damping_scale: float = 0.0) -> OperatorLinearization:
        """Forces at (x, v) and the projected stiffness as a product (:class:`OperatorLinearization`)."""
        x = np.asarray(x, dtype=np.float64)
        state = self._state(x, True)
        forces = self._forces(state)
        if v is not None and self.stiffness_damping:
            forces -= self.stiffness_damping * self._stiffness_times(state, np.asarray(v, dtype=np.float64))
        return self._operator(forces, lambda u: self._stiffness_times(state, np.asarray(u, dtype=np.float64)), x,
                              stiffness_scale, damping_scale,
                              lambda U: self._stiffness_times_many(state, np.asarray(U, dtype=np.float64)),
                              partial(self._diagonal, state))

    def per_tet(self) -> dict:
        """The constructor's per-tet inputs back: ``shear``, ``bulk``, ``regions`` and ``stand_in_bulk`` (T,) arrays.

        Every corner of a tet lies in a domain of the tet's region with the tet's coefficients (the
        constructor checks it), so corner 0's domain gives them exactly.
        """
        corner = self.domains.corner_domain[:, 0]
        return {"shear": self.shear[corner], "bulk": self.bulk[corner],
                "regions": np.asarray(self.domains.region[corner], dtype=np.int64),
                "stand_in_bulk": np.asarray(self.stand_in_bulk, dtype=np.float64)}

    def placed(self, rest_positions: np.ndarray, node_map: ArrayLike) -> "NodalStrain":
        """The same set in another node numbering (``node_map[i]``: the new index of node i) and on other
        rest positions (the body moved rigidly into a scene); clusters follow their nodes."""
        node_map = np.asarray(node_map, dtype=np.int64)
        clusters = None
        if self.clusters is not None:
            clusters = np.arange(len(rest_positions), dtype=np.int64)
            clusters[node_map[:len(self.clusters)]] = node_map[self.clusters]
        held = None
        if self.held is not None:
            held = np.zeros(len(rest_positions), dtype=bool)
            held[node_map[:len(self.held)]] = self.held
        return self._with(rest_positions, node_map[self.kinematics.tets], clusters, held)

    def supported(self, held: ArrayLike) -> "NodalStrain":
        """With clusters made by a rule (``"pairs"``, ``"merged pairs"``), the set whose domains are the free nodes'
        when the supports hold the nodes ``held`` ((n,) bool; those of a set of other nodes need not be held); any
        other set is itself.

        Measured (``benchmarks/study_locking.py``, deflection against Taylor-Hood on the same mesh from nu
        0.45 to 0.499): a clamped capsule's fell 7.8% with plain pairs, 2.5% with the free nodes' domains.
        """
        held = np.asarray(held, dtype=bool)[:self.node_count]
        held = held if held.any() else None
        if self.cluster_rule is None or (held is None and self.held is None) or \
                (held is not None and self.held is not None and np.array_equal(held, self.held)):
            return self
        return self._with(self.rest_positions, self.kinematics.tets, self.clusters, held)

    def _with(self, rest_positions, tets, clusters, held) -> "NodalStrain":
        """The same coefficients, damping and cluster rule on other rest positions, tets, clusters or held nodes."""
        inputs = self.per_tet()
        result = NodalStrain(rest_positions, tets, inputs["shear"], inputs["bulk"], regions=inputs["regions"],
                             clusters=clusters, held=held, stiffness_damping=self.stiffness_damping,
                             stand_in_bulk=inputs["stand_in_bulk"])
        result.cluster_rule = self.cluster_rule
        return result

    def volume_ratios(self, x: np.ndarray) -> np.ndarray:
        """(d,) float -- J_d = v_d / V_d of every smoothing domain at positions x."""
        return self._state(np.asarray(x, dtype=np.float64), True, volume=True)["J"]

    def __repr__(self) -> str:
        return (f"NodalStrain({self.domains.domain_count} domains, {self.element_count} ring pairs, "
                f"b={self.stiffness_damping:g} s)")


def _node_sums(nodes, entries, node_count) -> np.ndarray:
    """(node_count, 3, 3) -- e symmetric blocks summed by their ``nodes`` (e,), from their upper triangles' entries
    (six (e,) arrays in the order of :data:`volspring.elements.tet_kinematics._UPPER`)."""
    sums = np.empty((node_count, 3, 3))
    for entry, (i, j) in zip(entries, _UPPER):
        sums[:, i, j] = sums[:, j, i] = np.bincount(nodes, weights=entry, minlength=node_count)
    return sums


def _cofactor(F) -> np.ndarray:
    """(m, 3, 3) -- cof(F) = det(F) F^-T, defined for singular F too (columns are cross products)."""
    kernels = compiled()
    if kernels is not None:  # np.cross's operations, compiled (volspring.kernels)
        F = np.ascontiguousarray(F, dtype=np.float64)
        cof = np.empty(F.shape)
        kernels.cofactor(F, cof)
        return cof
    cof = np.empty_like(F)
    cof[:, :, 0] = np.cross(F[:, :, 1], F[:, :, 2])
    cof[:, :, 1] = np.cross(F[:, :, 2], F[:, :, 0])
    cof[:, :, 2] = np.cross(F[:, :, 0], F[:, :, 1])
    return cof
