"""The fixed 3x3 block sparsity pattern of the implicit system and its refill.

For a spring model and a set of free nodes the matrix

    A = M - h dF/dv - h^2 dF/dx

has one 3x3 diagonal block per free node and one off-diagonal block per spring each way
(springs with both ends free). With the per-spring block W_e = h^2 H_e + h D_e
(``H`` from :func:`volspring.springs.spring_stiffness_blocks`, ``D`` from
:func:`volspring.springs.damper_blocks`), spring e = (i, j) adds +W_e to the diagonal blocks
of i and j and -W_e to the blocks (i, j) and (j, i); the mass adds m_i I to block (i, i).

:class:`BlockPattern` builds this pattern and a scatter map once per model and pin set; each
step only refills the BSR data array with one sparse-times-dense product, no COO rebuild.
Pinned (and prescribed) nodes are eliminated: the pattern spans the free nodes only
(``3 * free_count`` unknowns) and their coupling to prescribed motion goes into the
right-hand side (:meth:`BlockPattern.boundary_coupling`).

Free unknowns are ordered node-major: unknown ``3 k + c`` is component c of free node
``free_nodes[k]``, so ``vector.reshape(-1, 3)`` gives per-node rows. The free nodes are
numbered by reverse Cuthill-McKee by default (cache locality), not by node index.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import scipy.sparse as sp

from volspring.errors import SpringCollapsed
from volspring.model import SpringModel
from volspring.springs import spring_linearization

__all__ = ["BlockPattern", "linearize_springs", "rigid_body_modes", "stiffness_matrix", "stiffness_times"]


class BlockPattern:
    """BSR pattern of the implicit system over the free nodes, and its scatter map.

    Parameters
    ----------
    model : SpringModel
    free : (n,) bool, optional -- nodes that are unknowns; all nodes when omitted
    ordering : {"rcm", "natural"} -- numbering of the free nodes: reverse Cuthill-McKee on the
        spring graph (for cache locality, see :meth:`_reorder`) or increasing node index

    Attributes
    ----------
    free_nodes : (f,) int -- model node index of each free node, in unknown order
    node_order : (n,) int -- model node of each local node: the free nodes, then the fixed ones
    node_rank : (n,) int -- local index of each model node (inverse of ``node_order``)
    spring_order : (s,) int -- model spring of each local spring (sorted by first free end)
    springs : (s, 2) int -- local node indices of each local spring
    node_index : (n,) int -- free index of each model node, -1 for fixed nodes
    size : int -- number of unknowns, 3 f
    boundary_springs : (b,) int -- springs with exactly one free end

    Examples
    --------
    >>> import numpy as np
    >>> from volspring import SpringModel
    >>> from volspring.assembly import BlockPattern
    >>> chain = SpringModel.from_arrays([[0, 0, 0], [1, 0, 0], [2, 0, 0]], [1.0, 1.0, 1.0],
    ...                                 [[0, 1], [1, 2]], stiffness=10.0)
    >>> pattern = BlockPattern(chain, free=np.array([False, True, True]), ordering="natural")
    >>> blocks = np.broadcast_to(np.eye(3), (2, 3, 3))
    >>> pattern.matrix(blocks, chain.masses[pattern.free_nodes]).toarray()[0, :4]
    array([ 3.,  0.,  0., -1.])
    """

    def __init__(self, model, free=None, *, ordering="rcm"):
        n = model.node_count
        free = np.ones(n, dtype=bool) if free is None else np.asarray(free, dtype=bool)
        if free.shape != (n,):
            raise ValueError(f"free must have shape ({n},), got {free.shape}")
        if ordering not in ("rcm", "natural"):
            raise ValueError(f"ordering = {ordering!r}, expected 'rcm' or 'natural'")
        self.model = model
        self.free = free.copy()
        self.ordering = ordering
        self.free_nodes = np.flatnonzero(free)
        self.node_index = np.full(n, -1, dtype=np.int64)
        self.node_index[self.free_nodes] = np.arange(len(self.free_nodes))
        f = len(self.free_nodes)
        self.size = 3 * f
        if ordering == "rcm" and f > 1:
            self._reorder()

        # Local numbering: free nodes first (in unknown order), then the fixed ones; springs
        # sorted by their first free end, so that every per-spring pass and the scatter into the
        # block rows walk memory nearly in order.
        fixed = np.flatnonzero(~free)
        self.node_order = np.concatenate([self.free_nodes, fixed])
        self.node_rank = np.empty(n, dtype=np.int64)
        self.node_rank[self.node_order] = np.arange(n)
        local = self.node_rank[model.springs]
        self.spring_order = np.argsort(local.min(axis=1), kind="stable")
        springs = local[self.spring_order]
        self.springs = springs
        # The same network in the local numbering: the spring kernels run on it directly.
        order = self.spring_order
        self.local_model = SpringModel(model.rest_positions[self.node_order], model.masses[self.node_order],
                                       springs, model.stiffness[order], model.damping[order],
                                       model.rest_lengths[order], model.kinds[order])
        self.incidence = self.local_model.incidence
        self.difference = self.local_model.difference
        s = model.spring_count
        spring_ids = np.arange(s)

        a, b = (np.where(springs < f, springs, -1)).T
        both = (a >= 0) & (b >= 0)
        self.boundary_springs = np.flatnonzero((a >= 0) != (b >= 0))
        # (row, col, spring, sign) of every block contribution of every spring.
        rows = np.concatenate([a, b, a[both], b[both]])
        cols = np.concatenate([a, b, b[both], a[both]])
        owner = np.concatenate([spring_ids, spring_ids, spring_ids[both], spring_ids[both]])
        sign = np.concatenate([np.ones(2 * s), -np.ones(2 * both.sum())])
        keep = rows >= 0
        rows, cols, owner, sign = rows[keep], cols[keep], owner[keep], sign[keep]
        # Every free node has a diagonal block even when no spring touches it (mass only).
        rows = np.concatenate([np.arange(f), rows])
        cols = np.concatenate([np.arange(f), cols])
        key = rows * max(f, 1) + cols
        unique_keys, block_of = np.unique(key, return_inverse=True)
        block_rows, block_cols = unique_keys // max(f, 1), unique_keys % max(f, 1)
        self.block_count = len(unique_keys)
        self.indices = block_cols.astype(np.int32)
        self.indptr = np.searchsorted(block_rows, np.arange(f + 1)).astype(np.int32)
        self.diagonal_blocks = block_of[:f]
        # Scatter map: block data (nnzb, 9) = summation (nnzb, s) @ spring blocks (s, 9).
        self.summation = sp.csr_matrix((sign, (block_of[f:], owner)), shape=(self.block_count, s))
        self.summation.sum_duplicates()
        # Flat positions of the diagonal entries of the diagonal blocks in the data array.
        self.diagonal_entries = (9 * self.diagonal_blocks[:, None] + np.array([0, 4, 8])).ravel()

    def _reorder(self):
        """Number the free nodes by reverse Cuthill-McKee on the spring graph.

        Mesh generators number nodes with little locality (a 50k-node gmsh beam: bandwidth
        48455); RCM brings it to about a thousand, which made the BSR mat-vec and the block
        Gauss-Seidel sweeps 1.5-2.5x faster (cache reuse of the vector entries).
        """
        from scipy.sparse.csgraph import reverse_cuthill_mckee

        f = len(self.free_nodes)
        a, b = self.node_index[self.model.springs.T]
        both = (a >= 0) & (b >= 0)
        graph = sp.csr_matrix((np.ones(2 * both.sum()), (np.concatenate([a[both], b[both]]),
                                                         np.concatenate([b[both], a[both]]))), shape=(f, f))
        order = reverse_cuthill_mckee(graph, symmetric_mode=True)
        self.free_nodes = self.free_nodes[order]
        self.node_index[self.free_nodes] = np.arange(f)

    @property
    def free_count(self) -> int:
        return len(self.free_nodes)

    def data(self, spring_blocks, diagonal=None, *, out=None) -> np.ndarray:
        """The BSR data array, (nnzb, 3, 3), for the given blocks.

        Parameters
        ----------
        spring_blocks : (s, 3, 3) float -- W_e of every spring, in the pattern's spring order
            (``spring_order[k]`` is the model spring of row k; as :func:`linearize_springs` gives them)
        diagonal : (f,) or (f, 3) or (f, 3, 3) float, optional -- added to the diagonal block of
            each free node: a scalar times I (e.g. the masses), a diagonal, or a full block
        out : (nnzb, 3, 3) float, optional -- written in place
        """
        data = (self.summation @ spring_blocks.reshape(-1, 9)).reshape(-1, 3, 3)
        if diagonal is not None:
            diagonal = np.asarray(diagonal, dtype=np.float64)
            if diagonal.ndim == 3:
                data[self.diagonal_blocks] += diagonal
            else:
                flat = data.reshape(-1)
                if diagonal.ndim == 1:
                    diagonal = np.repeat(diagonal, 3)
                flat[self.diagonal_entries] += diagonal.ravel()
        if out is not None:
            out[...] = data
            return out
        return data

    def matrix(self, spring_blocks, diagonal=None) -> sp.bsr_matrix:
        """(3f, 3f) BSR matrix with block size 3 sharing this pattern's index arrays."""
        return self.wrap(self.data(spring_blocks, diagonal))

    def wrap(self, data) -> sp.bsr_matrix:
        """A BSR matrix around a data array of this pattern (no copy, no format check)."""
        matrix = sp.bsr_matrix((data, self.indices, self.indptr), shape=(self.size, self.size), copy=False)
        return matrix

    def restrict(self, vectors) -> np.ndarray:
        """(3f,) float -- the free nodes' rows of a per-node array (n, 3), flattened."""
        return np.ascontiguousarray(vectors[self.free_nodes]).ravel()

    def free_dofs(self) -> np.ndarray:
        """(3f,) int -- model unknown index (3 node + component) of every free unknown."""
        return (3 * self.free_nodes[:, None] + np.arange(3)).ravel()

    def boundary_coupling(self, spring_blocks, prescribed) -> np.ndarray:
        """(n, 3) float -- -A_fp u_p: what prescribed values on fixed nodes add to the right-hand side.

        Parameters
        ----------
        spring_blocks : (s, 3, 3) float -- W_e of every spring, in the pattern's spring order
        prescribed : (n, 3) float -- values on the fixed nodes (rows of free nodes are ignored)

        Only the free nodes' rows of the result are meaningful.
        """
        n, f = self.model.node_count, self.free_count
        out = np.zeros((n, 3))
        e = self.boundary_springs
        if e.size == 0:
            return out
        i, j = self.springs[e].T
        u = prescribed[self.node_order]
        u[:f] = 0.0
        coupling = np.einsum("eab,eb->ea", spring_blocks[e], u[j] - u[i])
        np.add.at(out, i, coupling)
        np.add.at(out, j, -coupling)
        return out[self.node_rank]


def linearize_springs(pattern, x, v=None, *, stiffness_scale, damping_scale=0.0, clamp_compression=True):
    """:func:`volspring.springs.spring_linearization` in the pattern's local numbering.

    Per-spring arrays come out in the pattern's spring order (``pattern.spring_order[k]`` is the
    model spring of row k), ready for :meth:`BlockPattern.data`; the forces are per model node.
    The local numbering keeps every per-spring pass and the scatter walking memory nearly in order.

    Parameters
    ----------
    pattern : BlockPattern -- of the model
    x : (n, 3) float -- positions [m]
    v : (n, 3) float, optional -- velocities [m/s]; without them the dampers exert no force
    stiffness_scale, damping_scale, clamp_compression -- as for ``spring_linearization``

    Returns
    -------
    SpringLinearization
    """
    p = pattern
    try:
        local = spring_linearization(p.local_model, x[p.node_order], None if v is None else v[p.node_order],
                                     stiffness_scale=stiffness_scale, damping_scale=damping_scale,
                                     clamp_compression=clamp_compression)
    except SpringCollapsed as collapsed:
        spring = int(p.spring_order[collapsed.spring])
        raise SpringCollapsed(spring, *p.model.springs[spring]) from None
    return replace(local, forces=local.forces[p.node_rank])


def stiffness_matrix(model, x=None, *, free=None, clamp_compression=True) -> sp.csr_matrix:
    """(3f, 3f) CSR -- the springs' stiffness K = -dF/dx over the free nodes' dofs [N/m].

    Free node k (in the order of ``np.flatnonzero(free)``) owns dofs 3 k, 3 k + 1, 3 k + 2; the
    couplings to fixed nodes are left out.

    Parameters
    ----------
    model : SpringModel
    x : (n, 3) float, optional -- configuration [m]; default the rest shape
    free : (n,) bool, optional -- default all nodes
    clamp_compression : bool -- clamp the transverse term under compression (see ``volspring.springs``)

    Examples
    --------
    >>> from volspring import SpringModel
    >>> pair = SpringModel.from_arrays([[0, 0, 0], [1, 0, 0]], [1.0, 1.0], [[0, 1]], stiffness=5.0)
    >>> stiffness_matrix(pair).toarray()[0]
    array([ 5.,  0.,  0., -5.,  0.,  0.])
    """
    pattern = BlockPattern(model, free, ordering="natural")
    x = model.rest_positions if x is None else x
    springs = linearize_springs(pattern, x, stiffness_scale=1.0, clamp_compression=clamp_compression)
    return pattern.matrix(springs.blocks).tocsr()


def stiffness_times(pattern, linearization, u) -> np.ndarray:
    """(n, 3) float -- dF/dx @ u for the springs at a linearization (forces per unit u) [N].

    H_e (u_j - u_i) = (k - k_t) r (r . du) + k_t du with k_t the transverse coefficient, added
    to node i and subtracted from node j.
    """
    lin = linearization
    du = pattern.difference @ u[pattern.node_order]
    along = (lin.axial - lin.transverse) * np.einsum("ij,ij->i", lin.directions, du)
    per_spring = along[:, None] * lin.directions + lin.transverse[:, None] * du
    return (pattern.incidence @ per_spring)[pattern.node_rank]


def rigid_body_modes(points) -> np.ndarray:
    """(3p, 6) float -- translations and infinitesimal rotations of the given points.

    Columns: unit translations along x, y, z, then rotations about axes through the centroid,
    scaled to the points' spread so all six columns have comparable norms (the near-null space
    ``B`` handed to smoothed aggregation).
    """
    p = np.asarray(points, dtype=np.float64)
    q = p - p.mean(axis=0)
    scale = np.sqrt((q * q).sum(axis=1).mean()) or 1.0
    q = q / scale
    modes = np.zeros((len(p), 3, 6))
    modes[:, [0, 1, 2], [0, 1, 2]] = 1.0
    # omega x q for omega = e_x, e_y, e_z
    modes[:, 1, 3], modes[:, 2, 3] = -q[:, 2], q[:, 1]
    modes[:, 0, 4], modes[:, 2, 4] = q[:, 2], -q[:, 0]
    modes[:, 0, 5], modes[:, 1, 5] = -q[:, 1], q[:, 0]
    return modes.reshape(-1, 6)
