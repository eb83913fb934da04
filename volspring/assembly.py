"""The fixed 3x3 block sparsity pattern of the implicit system and its refill.

For a model and a set of free nodes the matrix

    A = M + c_D C + c_K K,   K = -dF/dx, C = -dF/dv of the model's element sets

(c_K = h^2, c_D = h in an implicit step; c_K = 1, c_D = 0 for a stiffness matrix) has one 3x3
diagonal block per free node and one block per pair of free nodes that share an element of any
set: the pattern is the union of the element sets' stencils (:mod:`volspring.elements`). Each
element set stores its blocks compactly (springs: one W_e = h^2 H_e + h D_e per spring, scattered
to (i, i), (j, j) with + and to (i, j), (j, i) with -; a generic k-node element: its k x k blocks).

:class:`BlockPattern` builds this pattern and one scatter matrix per element set once per model
and pin set; each step only refills the BSR data array with one sparse-times-dense product per
set, no COO rebuild. Pinned (and prescribed) nodes are eliminated: the pattern spans the free
nodes only (``3 * free_count`` unknowns) and their coupling to prescribed motion goes into the
right-hand side (:meth:`BlockPattern.boundary_coupling`).

Free unknowns are ordered node-major: unknown ``3 k + c`` is component c of free node
``free_nodes[k]``, so ``vector.reshape(-1, 3)`` gives per-node rows. The free nodes are
numbered by reverse Cuthill-McKee by default (cache locality), not by node index; sets that can
(springs) are evaluated in that numbering too (:meth:`ElementSet.renumbered`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.sparse as sp

from volspring._deprecation import deprecated_alias
from volspring.elements.base import BlockMap, Linearization
from volspring.errors import SpringCollapsed
from typing import TYPE_CHECKING, Any, Protocol, cast

if TYPE_CHECKING:
    from volspring.elements.base import ElementSet, OperatorLinearization
    from scipy import sparse
    from volspring.model import Model
    from scipy.sparse.linalg import LinearOperator

    class _MatrixFree(Protocol):
        """An element set applied as a product (``matrix_free``, see :class:`volspring.elements.ElementSet`)."""

        def linearize_operator(self, x: np.ndarray, v: np.ndarray | None = None, *, stiffness_scale: float = 1.0,
                               damping_scale: float = 0.0) -> OperatorLinearization: ...

__all__ = ["BlockPattern", "ModelLinearization", "eliminate_held", "held_unknowns", "stiffness_matrix"]


def _linearize_springs(pattern, x, v=None, *, stiffness_scale, damping_scale=0.0, clamp_compression=True):
    return pattern.linearize(x, v, stiffness_scale=stiffness_scale, damping_scale=damping_scale,
                             clamp_compression=clamp_compression)


def _stiffness_times(pattern, linearization, u):
    return pattern.dfdx_times(linearization, u)


def __getattr__(name):
    # 0.1 functions that are BlockPattern methods now (every element set, not springs only), and a
    # geometric kernel that lives in meshing.
    from meshing.geometry import rigid_body_modes

    return deprecated_alias(__name__, name, {
        "linearize_springs": ("volspring.assembly.BlockPattern.linearize", _linearize_springs),
        "stiffness_times": ("volspring.assembly.BlockPattern.dfdx_times", _stiffness_times),
        "rigid_body_modes": ("meshing.geometry.rigid_body_modes", rigid_body_modes)})


@dataclass(eq=False)
class _Part:
    """One element set inside a pattern: how it is evaluated and where its blocks go."""

    element_set: ElementSet  # the set as evaluated: renumbered (local) or the model's own
    order: np.ndarray | None  # model element of each evaluated element when renumbered, else None
    summation: sp.csr_matrix = None  # (nnzb, e b): block data = summation @ blocks.reshape(-1, 9)
    coupling: tuple = ()  # (rows, cols, owner, sign): free row, fixed column, block, sign
    operator: bool = False  # applied as a product; ``summation`` places its preconditioner stand-in

    @property
    def local(self) -> bool:
        return self.order is not None


@dataclass(eq=False)
class ModelLinearization:
    """Forces and scaled blocks of every element set of a model at one configuration.

    Attributes
    ----------
    forces : (n, 3) float
        internal forces on the model's nodes [N]
    parts : tuple of Linearization
        one per element set, each in its set's evaluation numbering
    """

    forces: np.ndarray
    parts: tuple

    @property
    def blocks(self) -> np.ndarray:
        """The blocks of a model with one element set (its layout; see :class:`Linearization`)."""
        if len(self.parts) != 1:
            raise ValueError(f"the model has {len(self.parts)} element sets; use the parts' blocks")
        return self.parts[0].blocks


class BlockPattern:
    """BSR pattern of the implicit system over the free nodes, and its scatter maps.

    Parameters
    ----------
    model : Model
    free : (n,) bool, optional
        nodes that are unknowns; all nodes when omitted
    ordering : {"rcm", "natural"}
        numbering of the free nodes: reverse Cuthill-McKee on the graph of the stencils (for cache locality, see
        :meth:`_reorder`) or increasing node index
    matrix_free : bool
        element sets that offer it (:attr:`volspring.elements.ElementSet.matrix_free`) are applied as products
        (:meth:`operator`) instead of assembled: the pattern holds their sparser preconditioner stand-in, which
        :meth:`matrix` adds with ``preconditioner=True``

    Attributes
    ----------
    free_nodes : (f,) int
        model node index of each free node, in unknown order
    node_order : (n,) int
        model node of each local node: the free nodes, then the fixed ones
    node_rank : (n,) int
        local index of each model node (inverse of ``node_order``)
    node_index : (n,) int
        free index of each model node, -1 for fixed nodes
    size : int
        number of unknowns, 3 f

    Examples
    --------
    >>> import numpy as np
    >>> from volspring import Model
    >>> from volspring.assembly import BlockPattern
    >>> chain = Model.from_arrays([[0, 0, 0], [1, 0, 0], [2, 0, 0]], [1.0, 1.0, 1.0],
    ...                           [[0, 1], [1, 2]], stiffness=10.0)
    >>> pattern = BlockPattern(chain, free=np.array([False, True, True]), ordering="natural")
    >>> blocks = np.broadcast_to(np.eye(3), (2, 3, 3))
    >>> pattern.matrix(blocks, chain.masses[pattern.free_nodes]).toarray()[0, :4]
    array([ 3.,  0.,  0., -1.])
    """

    def __init__(self, model: Model, free: np.ndarray | None = None, *, ordering: str = "rcm",
                 matrix_free: bool = False):
        n = model.node_count
        free = np.ones(n, dtype=bool) if free is None else np.asarray(free, dtype=bool)
        if free.shape != (n,):
            raise ValueError(f"free must have shape ({n},), got {free.shape}")
        if ordering not in ("rcm", "natural"):
            raise ValueError(f"ordering = {ordering!r}, expected 'rcm' or 'natural'")
        self.model = model
        self.free = free.copy()
        self.ordering = ordering
        self.matrix_free = bool(matrix_free)
        self.free_nodes = np.flatnonzero(free)
        self.node_index = np.full(n, -1, dtype=np.int64)
        self.node_index[self.free_nodes] = np.arange(len(self.free_nodes))
        f = len(self.free_nodes)
        self.size = 3 * f
        if ordering == "rcm" and f > 1:
            self._reorder()

        # Local numbering: free nodes first (in unknown order), then the fixed ones.
        fixed = np.flatnonzero(~free)
        self.node_order = np.concatenate([self.free_nodes, fixed])
        self.node_rank = np.empty(n, dtype=np.int64)
        self.node_rank[self.node_order] = np.arange(n)

        # (row, col, owner, sign) of every block contribution of every set, in local numbering.
        parts: list[_Part] = []
        entries = []
        for element_set in model.elements:
            if self._applied(element_set):
                part = _Part(element_set, None, operator=True)
                stencil = self.node_rank[element_set.preconditioner_stencil]
                layout = BlockMap.full(stencil.shape[1])
            else:
                renumbered = element_set.renumbered(self.node_rank)
                if renumbered is None:
                    part, stencil = _Part(element_set, None), self.node_rank[element_set.stencil]
                else:
                    part = _Part(*renumbered)
                    stencil = part.element_set.stencil
                layout = element_set.block_map
            e = len(stencil)
            rows, cols = stencil[:, layout.row].ravel(), stencil[:, layout.column].ravel()
            owner = (np.arange(e)[:, None] * layout.block_count + layout.block[None, :]).ravel()
            sign = np.broadcast_to(layout.sign, (e, len(layout.sign))).ravel()
            coupled = (rows < f) & (cols >= f)
            part.coupling = (rows[coupled], cols[coupled], owner[coupled], sign[coupled])
            inside = (rows < f) & (cols < f)
            entries.append((rows[inside], cols[inside], owner[inside], sign[inside], e * layout.block_count))
            parts.append(part)
        self.parts = tuple(parts)

        # Every free node has a diagonal block even when no element touches it (mass only).
        width = max(f, 1)
        keys = np.concatenate([np.arange(f) * (width + 1)] + [rows * width + cols for rows, cols, *_ in entries])
        unique_keys, block_of = np.unique(keys, return_inverse=True)
        block_rows, block_cols = unique_keys // width, unique_keys % width
        self.block_count = len(unique_keys)
        self.indices = block_cols.astype(np.int32)
        self.indptr = np.searchsorted(block_rows, np.arange(f + 1)).astype(np.int32)
        self.diagonal_blocks = block_of[:f].copy()  # a view would keep every contribution's block index alive
        start = f
        for part, (rows, _, owner, sign, stored) in zip(self.parts, entries):
            where = block_of[start:start + len(rows)]
            start += len(rows)
            part.summation = sp.csr_matrix((sign, (where, owner)), shape=(self.block_count, stored))
            part.summation.sum_duplicates()
        self.diagonal_entries = _diagonal_entries(self.diagonal_blocks)

    def _applied(self, element_set) -> bool:
        """Whether ``element_set`` is applied as a product here rather than assembled."""
        return self.matrix_free and getattr(element_set, "matrix_free", False)

    @property
    def has_operator(self) -> bool:
        """Whether some element set is applied as a product (see :meth:`operator`)."""
        return any(part.operator for part in self.parts)

    @property
    def assembles(self) -> bool:
        """Whether some element set is assembled into :meth:`matrix`; when none is (every set applied as a product, the
        smoothed rung), the matrix holds only the diagonal terms on the stand-in's pattern (:meth:`diagonal_part`)."""
        return not all(part.operator for part in self.parts)

    def diagonal_part(self, matrix: sp.bsr_matrix) -> sp.bsr_matrix:
        """(3f, 3f) BSR -- the diagonal blocks of a matrix on this pattern alone, a copy (one block per row)."""
        return self._diagonal_only(np.ascontiguousarray(matrix.data[self.diagonal_blocks]))

    def diagonal_matrix(self, diagonal: np.ndarray) -> sp.bsr_matrix:
        """(3f, 3f) BSR -- ``diagonal`` (as :meth:`data` takes it) alone, one block per row: the bits of
        :meth:`diagonal_part` of :meth:`matrix` where no set is assembled (:attr:`assembles`), without making the
        pattern's blocks of zeros first (3 MB a step on the README beam's smoothed rung: 0.06 against 0.20 ms alone,
        and the step's assembly 2.56 against 2.92 ms, alternating step by step in one run)."""
        blocks = np.arange(self.free_count)
        data = np.zeros((len(blocks), 3, 3))
        _add_diagonal(data, diagonal, blocks, _diagonal_entries(blocks))
        return self._diagonal_only(data)

    def _diagonal_only(self, blocks: np.ndarray) -> sp.bsr_matrix:
        f = self.free_count
        return sp.bsr_matrix((blocks, np.arange(f, dtype=np.int32), np.arange(f + 1, dtype=np.int32)),
                             shape=(self.size, self.size), copy=False)

    def _reorder(self):
        """Number the free nodes by reverse Cuthill-McKee on the graph of the element stencils.

        Mesh generators number nodes with little locality (a 50k-node gmsh beam: bandwidth
        48455); RCM brings it to about a thousand, which made the BSR mat-vec and the block
        Gauss-Seidel sweeps 1.5-2.5x faster (cache reuse of the vector entries).
        """
        from scipy.sparse.csgraph import reverse_cuthill_mckee

        f = len(self.free_nodes)
        rows, cols = [], []
        for element_set in self.model.elements:
            if self._applied(element_set):
                stencil = self.node_index[element_set.preconditioner_stencil]
                layout = BlockMap.full(stencil.shape[1])
            else:
                layout, stencil = element_set.block_map, self.node_index[element_set.stencil]
            off = layout.row != layout.column
            a, b = stencil[:, layout.row[off]].ravel(), stencil[:, layout.column[off]].ravel()
            both = (a >= 0) & (b >= 0)
            rows.append(a[both])
            cols.append(b[both])
        rows, cols = np.concatenate(rows or [np.zeros(0, int)]), np.concatenate(cols or [np.zeros(0, int)])
        graph = sp.csr_matrix((np.ones(2 * len(rows)), (np.concatenate([rows, cols]), np.concatenate([cols, rows]))),
                              shape=(f, f))
        order = reverse_cuthill_mckee(graph, symmetric_mode=True)
        self.free_nodes = self.free_nodes[order]
        self.node_index[self.free_nodes] = np.arange(f)

    @property
    def free_count(self) -> int:
        return len(self.free_nodes)

    # ------------------------------------------------------------------ evaluation
    def linearize(self, x: np.ndarray, v: np.ndarray | None = None, *, stiffness_scale: float,
                  damping_scale: float = 0.0, clamp_compression: bool = True) -> ModelLinearization:
        """Forces and blocks c_K K + c_D C of every element set at (x, v), ready for :meth:`data`.

        Parameters
        ----------
        x : (n, 3) float
            positions [m]
        v : (n, 3) float, optional
            velocities [m/s]; without them dampers exert no force
        stiffness_scale : float
            c_K
        damping_scale : float
            c_D
        clamp_compression : bool
            positive semi-definite blocks where the Hessian is not (see
            :meth:`volspring.elements.ElementSet.stiffness_blocks`)

        Returns
        -------
        ModelLinearization
        """
        options: dict[str, Any] = dict(stiffness_scale=stiffness_scale, damping_scale=damping_scale,
                                       clamp_compression=clamp_compression)
        forces, parts = np.zeros((self.model.node_count, 3)), []
        for part in self.parts:
            if part.operator:
                matrix_free = cast("_MatrixFree", part.element_set)  # the sets applied as products have the method
                linearization = matrix_free.linearize_operator(x, v, stiffness_scale=stiffness_scale,
                                                               damping_scale=damping_scale)
                forces += linearization.forces
            elif part.order is not None:  # part.local
                try:
                    linearization = part.element_set.linearize(
                        x[self.node_order], None if v is None else v[self.node_order], **options)
                except SpringCollapsed as collapsed:
                    spring = int(part.order[collapsed.spring])
                    raise SpringCollapsed(spring, *self.model.springs[spring]) from None
                forces += linearization.forces[self.node_rank]
            else:
                linearization = part.element_set.linearize(x, v, **options)
                forces += linearization.forces
            parts.append(linearization)
        return ModelLinearization(forces, tuple(parts))

    def dfdx_times(self, linearization: ModelLinearization, u: np.ndarray) -> np.ndarray:
        """(n, 3) float -- dF/dx @ u of all element sets at a linearization [N]."""
        out = np.zeros((self.model.node_count, 3))
        for part, lin in zip(self.parts, linearization.parts):
            if part.local:
                out += lin.dfdx_times(u[self.node_order])[self.node_rank]
            else:
                out += lin.dfdx_times(u)
        return out

    def data(self, linearization: ModelLinearization | np.ndarray, diagonal: np.ndarray | None = None, *,
             out: np.ndarray | None = None, preconditioner: bool = False) -> np.ndarray:
        """The BSR data array, (nnzb, 3, 3), for the given blocks.

        Parameters
        ----------
        linearization : ModelLinearization, or the blocks array of a model with one element set
        diagonal : (f,) or (f, 3) or (f, 3, 3) float, optional
            added to the diagonal block of each free node: a scalar times I (e.g. the masses), a diagonal, or a full
            block
        out : (nnzb, 3, 3) float, optional
            written in place
        preconditioner : bool
            add the stand-in blocks of the sets applied as products (the matrix to build a preconditioner from); without
            it they add nothing (see :meth:`operator`)
        """
        # Per set, its linearization (which sums its own blocks: the springs' need not be stored), or blocks, or None.
        blocks = [linearization] if isinstance(linearization, np.ndarray) else \
            [lin if not part.operator else lin.preconditioner_blocks() if preconditioner else None
             for part, lin in zip(self.parts, linearization.parts)]
        if len(blocks) != len(self.parts):
            raise ValueError(f"{len(blocks)} block arrays for a model with {len(self.parts)} element sets")
        products = (part_blocks.summed(part.summation) if isinstance(part_blocks, Linearization) else
                    part.summation @ np.reshape(part_blocks, (-1, 9))
                    for part, part_blocks in zip(self.parts, blocks) if part_blocks is not None)
        data = next(products, None)
        data = np.zeros((self.block_count, 9)) if data is None else data
        for product in products:
            data += product
        data = data.reshape(-1, 3, 3)
        if diagonal is not None:
            _add_diagonal(data, diagonal, self.diagonal_blocks, self.diagonal_entries)
        if out is not None:
            out[...] = data
            return out
        return data

    def matrix(self, linearization: ModelLinearization | np.ndarray, diagonal: np.ndarray | None = None, *,
               preconditioner: bool = False) -> sp.bsr_matrix:
        """(3f, 3f) BSR matrix with block size 3 sharing this pattern's index arrays (``preconditioner``:
        see :meth:`data`)."""
        return self.wrap(self.data(linearization, diagonal, preconditioner=preconditioner))

    def operator(self, linearization: ModelLinearization) -> LinearOperator:
        """The sets applied as products, over the free unknowns: a ``scipy.sparse.linalg.LinearOperator``
        p -> (c_K K + c_D C) p (None when every set is assembled). The system is ``matrix + operator``."""
        from scipy.sparse.linalg import LinearOperator

        applied = [lin for part, lin in zip(self.parts, linearization.parts) if part.operator]
        if not applied:
            return None
        n = self.model.node_count

        dofs = self.free_dof_index

        def times(p):
            u = np.zeros((n, 3))
            u.reshape(-1)[dofs] = np.reshape(p, -1)  # a flat index: a third of the time of the free nodes' rows
            total = applied[0].scaled_times(u)
            for lin in applied[1:]:
                total += lin.scaled_times(u)
            return self.restrict(total)

        def times_many(P):  # (3f, k): each column the bits of times(P[:, j]), the sets' sparse factors read once
            k = P.shape[1]
            U = np.zeros((n, 3, k))
            U.reshape(3 * n, k)[dofs] = np.reshape(P, (-1, k))
            total = applied[0].scaled_times_many(U)
            for lin in applied[1:]:
                total += lin.scaled_times_many(U)
            return np.reshape(total, (3 * n, k))[dofs]

        return LinearOperator((self.size, self.size), matvec=times, rmatvec=times, matmat=times_many,
                              rmatmat=times_many, dtype=np.float64)

    def operator_diagonal(self, linearization: ModelLinearization) -> np.ndarray | None:
        """(f, 3, 3) -- the diagonal blocks of :meth:`operator` over the free nodes, or None when no set is applied as a
        product or one of them does not give its diagonal."""
        applied = [lin for part, lin in zip(self.parts, linearization.parts) if part.operator]
        blocks = [lin.diagonal_blocks() for lin in applied]
        if not blocks or any(block is None for block in blocks):
            return None
        return sum(blocks)[self.free_nodes]

    def wrap(self, data: np.ndarray) -> sp.bsr_matrix:
        """A BSR matrix around a data array of this pattern (no copy, no format check)."""
        matrix = sp.bsr_matrix((data, self.indices, self.indptr), shape=(self.size, self.size), copy=False)
        return matrix

    def restrict(self, vectors: np.ndarray) -> np.ndarray:
        """(3f,) float -- the free nodes' rows of a per-node array (n, 3), flattened (by the flat
        :attr:`free_dof_index`: 11 against 48 us for the free nodes' rows on the README beam, every CG product)."""
        return np.reshape(vectors, -1)[self.free_dof_index]

    @cached_property
    def free_dof_index(self) -> np.ndarray:
        """(3f,) int, read-only -- model unknown index (3 node + component) of every free unknown."""
        index = (3 * self.free_nodes[:, None] + np.arange(3)).ravel()
        index.setflags(write=False)
        return index

    def free_dofs(self) -> np.ndarray:
        """(3f,) int -- model unknown index (3 node + component) of every free unknown."""
        return self.free_dof_index.copy()

    def boundary_coupling(self, linearization: ModelLinearization | np.ndarray, prescribed: np.ndarray) -> np.ndarray:
        """(n, 3) float -- -A_fp u_p: what prescribed values on fixed nodes add to the right-hand side.

        Parameters
        ----------
        linearization : ModelLinearization, or the blocks of a model with one element set
        prescribed : (n, 3) float
            values on the fixed nodes (rows of free nodes are ignored)

        Notes
        -----
        Only the free nodes' rows of the result are meaningful.
        """
        blocks = [linearization] if isinstance(linearization, np.ndarray) else \
            [lin.blocks for lin in linearization.parts]
        u = prescribed[self.node_order]
        out = np.zeros((self.model.node_count, 3))
        for part, part_blocks in zip(self.parts, blocks):
            rows, cols, owner, sign = part.coupling
            if rows.size == 0 or part.operator:
                continue
            flat = np.reshape(part_blocks, (-1, 3, 3))
            contribution = np.einsum("eab,eb->ea", flat[owner], u[cols]) * sign[:, None]
            for c in range(3):
                out[:, c] -= np.bincount(rows, weights=contribution[:, c], minlength=len(out))
        out = out[self.node_rank]
        if self.has_operator:
            if isinstance(linearization, np.ndarray):
                raise ValueError("the model has element sets applied as products: boundary_coupling needs its "
                                 "ModelLinearization, not a blocks array")
            fixed = prescribed.copy()
            fixed[self.free_nodes] = 0.0
            for part, lin in zip(self.parts, linearization.parts):
                if part.operator:
                    out -= lin.scaled_times(fixed)
        return out


def stiffness_matrix(model: Model, x: np.ndarray | None = None, *, free: np.ndarray | None = None,
                     clamp_compression: bool = True) -> sp.csr_matrix:
    """(3f, 3f) CSR -- the stiffness K = -dF/dx of all element sets over the free nodes' dofs [N/m].

    Free node k (in the order of ``np.flatnonzero(free)``) owns dofs 3 k, 3 k + 1, 3 k + 2; the
    couplings to fixed nodes are left out.

    Parameters
    ----------
    model : Model
    x : (n, 3) float, optional
        configuration [m]; default the rest shape
    free : (n,) bool, optional
        default all nodes
    clamp_compression : bool
        clamp the transverse term under compression (see ``volspring.springs``)

    Examples
    --------
    >>> from volspring import Model
    >>> pair = Model.from_arrays([[0, 0, 0], [1, 0, 0]], [1.0, 1.0], [[0, 1]], stiffness=5.0)
    >>> stiffness_matrix(pair).toarray()[0]
    array([ 5.,  0.,  0., -5.,  0.,  0.])
    """
    pattern = BlockPattern(model, free, ordering="natural")
    x = model.rest_positions if x is None else x
    return pattern.matrix(pattern.linearize(x, stiffness_scale=1.0, clamp_compression=clamp_compression)).tocsr()



def held_unknowns(pattern: BlockPattern, held: np.ndarray) -> np.ndarray:
    """(3f,) bool -- which free unknowns of ``pattern`` a support holds (``held``: (n, 3) bool, as
    :attr:`volspring.Scene.held`); all False when only whole nodes are held."""
    return np.ascontiguousarray(held[pattern.free_nodes]).ravel()


def _diagonal_entries(blocks: np.ndarray) -> np.ndarray:
    """(3 f,) int -- the flat positions, in a (nnzb, 3, 3) data array, of the diagonal entries of blocks ``blocks``."""
    return (9 * blocks[:, None] + np.array([0, 4, 8])).ravel()


def _add_diagonal(data: np.ndarray, diagonal, blocks: np.ndarray, entries: np.ndarray) -> None:
    """Add ``diagonal`` ((f,) a scalar times I, (f, 3) a diagonal or (f, 3, 3) a block per free node) to the
    diagonal blocks of ``data`` (nnzb, 3, 3), in place: at block ``blocks[i]``, flat entries ``entries``."""
    diagonal = np.asarray(diagonal, dtype=np.float64)
    if diagonal.ndim == 3:
        data[blocks] += diagonal
    else:
        flat = data.reshape(-1)
        if diagonal.ndim == 1:
            diagonal = np.repeat(diagonal, 3)
        flat[entries] += diagonal.ravel()


def eliminate_held(pattern: BlockPattern, matrix: sparse.spmatrix, held: np.ndarray, *,
                   extra: sparse.spmatrix | None = None) -> tuple[sparse.spmatrix, np.ndarray, sparse.spmatrix | None]:
    """Decouple held unknowns from the system, symmetrically and in place: A' = P A P + (I - P) D.

    Rows and columns of the held unknowns (components of partly held nodes: sliding, prescribed
    components) are zeroed and their diagonal entries kept, so that A' stays symmetric positive
    definite, its spectrum scale unchanged, and the held unknowns solve to d_k x_k = rhs_k. The
    caller moves the coupling to prescribed values into the right-hand side first
    (``rhs -= A @ values``) and sets ``rhs[held] = diagonal[held] * values[held]``.

    Parameters
    ----------
    pattern : BlockPattern
    matrix : (3f, 3f) BSR
        on ``pattern``; its data is changed in place
    held : (3f,) bool
        the held unknowns (:func:`held_unknowns`)
    extra : (3f, 3f) sparse, optional
        a further term of the system, masked the same way

    Returns
    -------
    matrix : the same BSR matrix, eliminated
    diagonal : (3f,) float
        the diagonal of A before elimination
    extra : the masked extra term (or None)
    """
    diagonal = matrix.diagonal()
    if extra is not None:
        diagonal = diagonal + extra.diagonal()
    keep = (~held).astype(np.float64).reshape(-1, 3)
    block_rows = np.repeat(np.arange(pattern.free_count), np.diff(pattern.indptr))
    matrix.data *= keep[block_rows][:, :, None] * keep[pattern.indices][:, None, :]
    matrix.data.reshape(-1)[pattern.diagonal_entries[held]] = diagonal[held]
    if extra is not None:
        projector = sp.diags(keep.ravel())
        extra = (projector @ extra @ projector).tocsr()  # the held rows and columns, diagonal included, go
    return matrix, diagonal, extra
