"""What an element set is: a family of elements, each acting on a few nodes (its stencil).

A model is rest positions, masses and a list of element sets (:class:`volspring.Model`). Each
set gives, for positions x [m] and velocities v [m/s] of all n nodes,

- its forces on the nodes (:meth:`ElementSet.forces`, (n, 3) [N]);
- its potential energy (:meth:`ElementSet.energy`, [J]), of which the elastic forces are minus the gradient;
- its Jacobian as dense blocks per element on the element's stencil
  (:meth:`ElementSet.stiffness_blocks`: K_e = -dF/dx restricted to the element, and optionally
  :meth:`ElementSet.damping_blocks`: C_e = -dF/dv).

That is all a new kind of physics writes. Assembly (:class:`volspring.assembly.BlockPattern`)
takes the union of the stencils of all sets as the 3x3 block pattern of the implicit matrix, so
every internal stiffness lands in the matrix that the AMG hierarchy sees; the integrators, the
static and modal solves, the stability estimate and validation then use the set with no other
change. Sign convention, everywhere: blocks are *stiffness* (K = -dF/dx, C = -dF/dv, positive
semi-definite for a stable element), and an assembled implicit matrix is
M + c_D C + c_K K.

A set may store its blocks compactly: :attr:`ElementSet.block_map` says which of its b blocks
per element goes, with which sign, into which (row, column) pair of its stencil (springs keep
one 3x3 block per spring and scatter it four times with signs +, +, -, -). The default is the
full k x k layout of a k-node stencil.

Examples
--------
A per-tet volume penalty written in a few lines is in ``tests/test_element_sets.py``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.sparse as sp
from collections.abc import Callable
__all__ = ["BlockMap", "ElementSet", "Linearization", "OperatorLinearization"]


@dataclass(frozen=True)
class BlockMap:
    """Where an element's blocks go: entry q adds ``sign[q] * blocks[e, block[q]]`` to the matrix
    block (``stencil[e, row[q]]``, ``stencil[e, column[q]]``) of every element e.

    Parameters
    ----------
    row, column : (q,) int
        positions in the stencil
    block : (q,) int
        which of the element's ``block_count`` blocks
    sign : (q,) float
        +1 or -1
    block_count : int
        blocks stored per element, b
    """

    row: np.ndarray
    column: np.ndarray
    block: np.ndarray
    sign: np.ndarray
    block_count: int

    @classmethod
    def full(cls, k: int) -> "BlockMap":
        """The dense k x k layout: block a k + b of an element is its (a, b) block."""
        row, column = np.divmod(np.arange(k * k), k)
        return cls(row, column, np.arange(k * k), np.ones(k * k), k * k)


class Linearization:
    """Forces and scaled blocks c_K K_e + c_D C_e of one element set at one configuration.

    Parameters
    ----------
    forces : (n, 3) float
        the set's forces on the nodes [N]
    blocks : (e, b, 3, 3) float
        c_K K_e + c_D C_e in the set's block layout
    stiffness : (e, b, 3, 3) float
        K_e alone (for products with dF/dx)
    element_set : ElementSet
        whose stencil and block map the blocks follow
    """

    def __init__(self, forces: np.ndarray, blocks: np.ndarray | None, stiffness: np.ndarray | None,
                 element_set: ElementSet):
        self.forces, self.blocks, self.stiffness, self.element_set = forces, blocks, stiffness, element_set

    def dfdx_times(self, u: np.ndarray) -> np.ndarray:
        """(n, 3) float -- dF/dx @ u: the change of the set's forces per unit displacement u [N]."""
        return -_block_product(self.element_set, self.stiffness, u)

    def summed(self, summation: sp.csr_matrix) -> np.ndarray:
        """(m, 9) float -- ``summation @ blocks.reshape(-1, 9)``: the blocks summed into m blocks of a matrix by a sparse
        (m, e b) summation (:class:`volspring.assembly.BlockPattern`'s)."""
        if self.blocks is None:
            raise ValueError(f"the {self.element_set.name or 'element'} set's linearization has no blocks to sum")
        return summation @ np.reshape(self.blocks, (-1, 9))


class OperatorLinearization(Linearization):
    """Forces of a matrix-free element set at one configuration, and its stiffness as a product.

    The implicit solve applies ``c_K K + c_D C`` through :meth:`scaled_times` inside CG instead of
    assembling it, and builds its preconditioner from :meth:`preconditioner_blocks`, a sparser stand-in
    on the set's ``preconditioner_stencil`` (see :attr:`ElementSet.matrix_free`).

    Parameters
    ----------
    forces : (n, 3) float
        the set's forces [N]
    times : callable
        ``times(u) -> K u`` for (n, 3) u [N]
    scale : float
        c_K + c_D b: the product's factor in the system (Rayleigh damping C = b K)
    element_set : ElementSet
    preconditioner : callable
        ``preconditioner() -> (e, b, 3, 3)`` stand-in blocks, already scaled, or None when the set adds nothing to
        the stand-in
    times_many : callable, optional
        ``times_many(U) -> K U`` for (n, 3, k) U, each column the bits of ``times`` (the sparse factors read once
        for all k); default ``times`` column by column
    diagonal : callable, optional
        ``diagonal() -> (n, 3, 3)`` the diagonal blocks of the scaled stiffness, or None when the set does not give
        them
    """

    def __init__(self, forces: np.ndarray, times: Callable[[np.ndarray], np.ndarray], scale: float,
                 element_set: ElementSet, preconditioner: Callable[[], np.ndarray] | None,
                 times_many: Callable[[np.ndarray], np.ndarray] | None = None, *,
                 diagonal: Callable[[], np.ndarray] | None = None):
        super().__init__(forces, None, None, element_set)
        self._times, self.scale, self._preconditioner = times, float(scale), preconditioner
        self._times_many, self._diagonal = times_many, diagonal

    def dfdx_times(self, u: np.ndarray) -> np.ndarray:
        return -self._times(u)

    def scaled_times(self, u: np.ndarray) -> np.ndarray:
        """(n, 3) float -- (c_K K + c_D C) u."""
        return self.scale * self._times(u)

    def scaled_times_many(self, U: np.ndarray) -> np.ndarray:
        """(n, 3, k) float -- (c_K K + c_D C) U, column j the bits of ``scaled_times(U[:, :, j])``."""
        if self._times_many is not None:
            return self.scale * self._times_many(U)
        return self.scaled_times_each(U)

    def scaled_times_each(self, U: np.ndarray) -> np.ndarray:
        """(n, 3, k) float -- :meth:`scaled_times_many` one column after another (each product reads the set's
        factors again)."""
        return self.scale * np.stack([self._times(np.ascontiguousarray(U[:, :, j])) for j in range(U.shape[2])], axis=2)

    def diagonal_blocks(self) -> np.ndarray | None:
        """(n, 3, 3) -- the diagonal blocks of c_K K + c_D C, or None when the set does not give them."""
        return None if self._diagonal is None else self._diagonal()

    def preconditioner_blocks(self) -> np.ndarray | None:
        """The set's stand-in blocks for the preconditioner, already scaled (None: it adds nothing to the stand-in)."""
        if self._preconditioner is None:
            raise ValueError("this linearization was built without a preconditioner (no stand-in blocks)")
        return self._preconditioner()


def _block_product(element_set, blocks, u) -> np.ndarray:
    """(n, 3) float -- (the assembled blocks) @ u, scattered to the nodes."""
    layout, stencil = element_set.block_map, element_set.stencil
    gathered = u[stencil[:, layout.column]]  # (e, q, 3)
    products = np.einsum("eqab,eqb->eqa", blocks[:, layout.block], gathered) * layout.sign[None, :, None]
    out = np.zeros_like(u, dtype=np.float64)
    rows = stencil[:, layout.row].ravel()
    for c in range(3):
        out[:, c] = np.bincount(rows, weights=products[..., c].ravel(), minlength=len(u))
    return out


class ElementSet(ABC):
    """A family of elements of a model (see the module docstring): springs, volume terms, angle springs.

    Subclasses give :attr:`stencil`, :meth:`forces`, :meth:`energy` and :meth:`stiffness_blocks`
    (and :meth:`damping_blocks` when they damp); the rest has working defaults. Element sets are
    immutable: a changed set is a new object.

    Attributes
    ----------
    name : str
        a short label ("springs", "volume") for messages, files and output
    """

    name: str = ""
    #: A set whose blocks are many and cheap to apply without assembling (a smoothed nodal term couples
    #: each node's 2-ring) says so here and gives ``linearize_operator(x, v, *, stiffness_scale,
    #: damping_scale)`` (an :class:`OperatorLinearization`) and ``preconditioner_stencil``; the implicit
    #: solve then applies its stiffness as a product and preconditions with the stand-in blocks.
    matrix_free: bool = False

    @property
    @abstractmethod
    def stencil(self) -> np.ndarray:
        """(e, k) int -- the nodes of each element."""

    @property
    def element_count(self) -> int:
        return len(self.stencil)

    @cached_property
    def block_map(self) -> BlockMap:
        """Where the stored blocks go (:class:`BlockMap`); the full k x k layout by default."""
        return BlockMap.full(self.stencil.shape[1])

    @abstractmethod
    def forces(self, x: np.ndarray, v: np.ndarray | None = None) -> np.ndarray:
        """(n, 3) float -- the set's forces on every node at positions x and velocities v [N]
        (without v: the elastic part only)."""

    @abstractmethod
    def energy(self, x: np.ndarray) -> float:
        """Potential energy of the set at positions x [J]."""

    @abstractmethod
    def stiffness_blocks(self, x: np.ndarray, *, clamp_compression: bool = True) -> np.ndarray:
        """(e, b, 3, 3) float -- K_e = -dF/dx of each element in the block layout [N/m].

        ``clamp_compression`` asks for a positive semi-definite approximation where the exact
        Hessian is indefinite (springs clamp their transverse term); sets without such a
        term ignore it.
        """

    def damping_blocks(self, x: np.ndarray) -> np.ndarray | None:
        """(e, b, 3, 3) float -- C_e = -dF/dv of each element [N s/m], or None when the set does not damp."""
        return None

    def linearize(self, x: np.ndarray, v: np.ndarray | None = None, *, stiffness_scale: float = 1.0,
                  damping_scale: float = 0.0, clamp_compression: bool = True) -> Linearization:
        """Forces and the blocks c_K K_e + c_D C_e in one call (sets with a faster joint pass override it).

        Parameters
        ----------
        x : (n, 3) float
            positions [m]
        v : (n, 3) float, optional
            velocities [m/s]
        stiffness_scale : float
            c_K (h^2 [s^2] in an implicit step, 1 in statics)
        damping_scale : float
            c_D (h [s] in an implicit step)
        clamp_compression : bool
            see :meth:`stiffness_blocks`

        Returns
        -------
        Linearization
        """
        stiffness = self.stiffness_blocks(x, clamp_compression=clamp_compression)
        blocks = stiffness_scale * stiffness
        if damping_scale:
            damping = self.damping_blocks(x)
            if damping is not None:
                blocks = blocks + damping_scale * damping
        return Linearization(self.forces(x, v), blocks, stiffness, self)

    def renumbered(self, node_rank: np.ndarray) -> tuple[ElementSet, np.ndarray] | None:
        """The set in another node numbering, elements reordered for locality, and the element order;
        None (the default) when the set is evaluated in the model's numbering.

        Assembly numbers the free nodes for cache locality (:class:`volspring.assembly.BlockPattern`);
        a set on a hot path (springs) returns ``(renumbered_set, order)`` so that its kernels walk
        memory in order too.
        """
        return None

    def supported(self, held: np.ndarray) -> "ElementSet":
        """The set a scene uses once its supports hold the nodes ``held`` ((n,) bool: all three components
        prescribed); the set itself by default. A set whose discretisation depends on the supports
        (:meth:`volspring.elements.NodalStrain.supported`) returns an adapted copy."""
        return self

    def check(self, node_count: int) -> None:
        """Refuse a stencil that is not (e, k) integer node indices below ``node_count``."""
        stencil = np.asarray(self.stencil)
        if stencil.ndim != 2 or stencil.dtype.kind not in "iu":
            raise ValueError(f"{type(self).__name__}.stencil has shape {stencil.shape} and dtype {stencil.dtype}; "
                             "expected (e, k) integer node indices")
        if stencil.size and (stencil.min() < 0 or stencil.max() >= node_count):
            e = int(np.flatnonzero(((stencil < 0) | (stencil >= node_count)).any(axis=1))[0])
            raise ValueError(f"{type(self).__name__}.stencil[{e}] = {stencil[e].tolist()} indexes a node outside "
                             f"[0, {node_count - 1}] (the model has {node_count} nodes)")
