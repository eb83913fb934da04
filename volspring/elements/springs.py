"""Edge springs with dampers: forces, energy and Jacobian blocks, vectorised over all springs.

For spring e = (i, j) with r = (x_j - x_i) / l, l = |x_j - x_i|:

- spring force on i: f = k_e (l - l0) r; on j: -f (momentum is conserved exactly);
- damper force on i: f_d = -k_d ((v_i - v_j) . r) r; on j: -f_d;
- stiffness block H = k_e [r r^T + (1 - l0/l) (I - r r^T)], so dF_i/dx_i = -H, dF_i/dx_j = +H;
  the transverse term is negative under compression (l < l0), so it is clamped at 0 by
  default to keep the assembled matrix positive semi-definite (Baraff & Witkin 1998);
- damper block D = k_d r r^T, dF_i/dv_i = -D, dF_i/dv_j = +D.

Each spring stores one block W = c_K H + c_D D and scatters it four times (+W on the diagonal
blocks of i and j, -W on (i, j) and (j, i)): :attr:`Springs.block_map`. Forces and blocks come
out of one pass (:meth:`Springs.linearize`), the fast path of every implicit step.

Where the stiffness constants come from (material rules, shells) is :mod:`volspring.model`.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
import scipy.sparse as sp

from volspring.elements.base import BlockMap, ElementSet, Linearization
from volspring.errors import SpringCollapsed
from volspring.kernels import compiled, unsigned
from volspring.material import _real_array, _shown
from meshing.topology import SPRING_KINDS, vector_lengths
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

__all__ = ["SpringLinearization", "Springs"]


@dataclass(frozen=True, eq=False)
class Springs(ElementSet):
    """Springs and dampers along node pairs (see the module docstring).

    Parameters
    ----------
    node_count : int
        nodes of the model the springs belong to
    pairs : (s, 2) int
        node pairs (i, j), two different nodes each
    stiffness : (s,) float
        effective linear stiffness k_e [N/m], >= 0
    damping : (s,) float
        damper coefficient k_d [N s/m], >= 0
    rest_lengths : (s,) float
        l0 [m], > 0
    kinds : (s,) int
        index into ``SPRING_KINDS`` (what each spring models: tet edge, shell...)

    Notes
    -----
    Numbers broadcast (``damping=0.0``). Input is checked: a TypeError for what is not numbers or
    for non-integer pairs, a ValueError for wrong shapes, values out of range and pairs outside
    the nodes or joining a node to itself, naming the first offender.

    Examples
    --------
    >>> import numpy as np
    >>> from volspring.elements import Springs
    >>> pair = Springs(2, [[0, 1]], stiffness=100.0, damping=0.0, rest_lengths=1.0, kinds=0)
    >>> pair.forces(np.array([[0.0, 0, 0], [1.5, 0, 0]]))[0].tolist()   # stretched 0.5 m: 50 N towards j
    [50.0, 0.0, 0.0]
    """

    node_count: int
    pairs: np.ndarray
    stiffness: np.ndarray
    damping: np.ndarray
    rest_lengths: np.ndarray
    kinds: np.ndarray

    name = "springs"

    if TYPE_CHECKING:  # what the constructor takes: numbers broadcast, arrays are checked and stored (__post_init__)
        def __init__(self, node_count: int, pairs: ArrayLike, stiffness: ArrayLike, damping: ArrayLike,
                     rest_lengths: ArrayLike, kinds: ArrayLike) -> None: ...

    def __post_init__(self):
        pairs = checked_pairs(self.pairs, int(self.node_count))
        s = len(pairs)
        values = {
            "stiffness": per_item_array("stiffness", self.stiffness, s, allow_zero=True),
            "damping": per_item_array("damping", self.damping, s, allow_zero=True),
            "rest_lengths": per_item_array("rest_lengths", self.rest_lengths, s, allow_zero=False),
        }
        kinds = np.broadcast_to(np.asarray(self.kinds, dtype=np.int8), (s,)).copy()
        if s and (kinds.min() < 0 or kinds.max() >= len(SPRING_KINDS)):
            raise ValueError(f"kinds hold {kinds.min()} to {kinds.max()}; expected indices into SPRING_KINDS, "
                             f"0 to {len(SPRING_KINDS) - 1}")
        object.__setattr__(self, "node_count", int(self.node_count))
        for name, array in (("pairs", pairs), ("kinds", kinds), *values.items()):
            array.setflags(write=False)
            object.__setattr__(self, name, array)

    # ------------------------------------------------------------------ the element-set interface
    @property
    def stencil(self) -> np.ndarray:
        return self.pairs

    @cached_property
    def block_map(self) -> BlockMap:
        # (i, i) +W, (j, j) +W, (i, j) -W, (j, i) -W
        return BlockMap(np.array([0, 1, 0, 1]), np.array([0, 1, 1, 0]), np.zeros(4, dtype=np.int64),
                        np.array([1.0, 1.0, -1.0, -1.0]), 1)

    def forces(self, x: np.ndarray, v: np.ndarray | None = None) -> np.ndarray:
        """(n, 3) float -- spring (and damper, with ``v``) forces on the nodes [N]."""
        r, length = self._directions(x)
        return self.incidence @ (self._magnitudes(r, length, v)[:, None] * r)

    def energy(self, x: np.ndarray) -> float:
        """Elastic energy sum 1/2 k_e (l - l0)^2 [J]."""
        _, length = self._directions(x)
        return float(0.5 * np.dot(self.stiffness, (length - self.rest_lengths) ** 2))

    def strains(self, x: np.ndarray) -> np.ndarray:
        """(s,) float -- engineering strain (l - l0) / l0 of each spring [-]."""
        _, length = self._directions(x)
        return length / self.rest_lengths - 1.0

    def stiffness_blocks(self, x: np.ndarray, *, clamp_compression: bool = True) -> np.ndarray:
        """(s, 3, 3) float -- H of each spring [N/m] (see the module docstring)."""
        return self.linearize(x, clamp_compression=clamp_compression).blocks

    def damping_blocks(self, x: np.ndarray) -> np.ndarray:
        """(s, 3, 3) float -- D = k_d r r^T of each spring [N s/m]."""
        r, _ = self._directions(x)
        return self.damping[:, None, None] * r[:, :, None] * r[:, None, :]

    def linearize(self, x: np.ndarray, v: np.ndarray | None = None, *, stiffness_scale: float = 1.0,
                  damping_scale: float = 0.0, clamp_compression: bool = True) -> "SpringLinearization":
        """Forces and the blocks c_K H_e + c_D D_e in one pass over the springs.

        Parameters
        ----------
        x : (n, 3) float
            positions [m]
        v : (n, 3) float, optional
            velocities [m/s]; without them the dampers exert no force
        stiffness_scale : float
            c_K (h^2 [s^2] for an implicit step, 1 for statics)
        damping_scale : float
            c_D (h [s] for an implicit step)
        clamp_compression : bool
            clamp the transverse term (1 - l0/l) at 0
        """
        kernels = compiled()
        if kernels is not None:
            return self._compiled_linearization(kernels, x, v, float(stiffness_scale), float(damping_scale),
                                                bool(clamp_compression))
        r, length = self._directions(x)
        forces = self.incidence @ (self._magnitudes(r, length, v)[:, None] * r)
        transverse = 1.0 - self.rest_lengths / length
        if clamp_compression:
            np.maximum(transverse, 0.0, out=transverse)
        transverse *= self.stiffness
        along = stiffness_scale * (self.stiffness - transverse)
        if damping_scale:
            along += damping_scale * self.damping
        return SpringLinearization(forces, self, r, length, self.stiffness, transverse, along, stiffness_scale)

    def _compiled_linearization(self, kernels, x, v, stiffness_scale, damping_scale, clamp_compression):
        """:meth:`linearize` by the compiled kernel (:mod:`volspring.kernels`): the same numbers, one pass."""
        n, s = self.node_count, self.spring_count
        x = _node_array("x", x, n)
        v = _NO_VELOCITIES if v is None or not self._damped else _node_array("v", v, n)
        forces, r = np.empty((n, 3)), np.empty((s, 3))
        length, transverse, along = np.empty(s), np.empty(s), np.empty(s)
        incidence = self.incidence
        if kernels.spring_linearization(x, v, unsigned(self.pairs), self.stiffness, self.damping, self.rest_lengths,
                                        stiffness_scale, damping_scale, clamp_compression, unsigned(incidence.indptr),
                                        unsigned(incidence.indices), incidence.data, forces, along, r, length,
                                        transverse):
            e = int(np.argmin(length))  # the spring numpy's check names (_directions)
            raise SpringCollapsed(e, *self.pairs[e])
        return SpringLinearization(forces, self, r, length, self.stiffness, transverse, along, stiffness_scale)

    @cached_property
    def _damped(self) -> bool:
        """Whether any damper has a coefficient: without one, velocities change no force."""
        return bool(self.damping.any())

    def renumbered(self, node_rank: np.ndarray, node_count: int | None = None) -> tuple:
        """The same springs in another node numbering, sorted by their first node there.

        Parameters
        ----------
        node_rank : (n,) int
            new index of every node
        node_count : int, optional
            nodes in the new numbering (default n)

        Returns
        -------
        springs : Springs
            in the new numbering
        order : (s,) int
            which spring of ``self`` each new spring is
        """
        local = node_rank[self.pairs]
        order = np.argsort(local.min(axis=1), kind="stable")
        renumbered = Springs(len(node_rank) if node_count is None else node_count, local[order],
                             self.stiffness[order], self.damping[order], self.rest_lengths[order], self.kinds[order])
        return renumbered, order

    # ------------------------------------------------------------------ derived data
    @property
    def spring_count(self) -> int:
        return len(self.pairs)

    @cached_property
    def incidence(self) -> sp.csr_matrix:
        """(n, s) sparse -- +1 at (i, e) and -1 at (j, e) for spring e = (i, j).

        ``incidence @ f`` scatters per-spring forces on i, shape (s, 3), to node forces (n, 3).
        """
        s = self.spring_count
        rows = self.pairs.T.ravel()
        values = np.concatenate([np.ones(s), -np.ones(s)])
        return sp.csr_matrix((values, (rows, np.tile(np.arange(s), 2))), shape=(self.node_count, s))

    @property
    def difference(self) -> sp.csr_matrix:
        """(s, n) sparse -- -1 at (e, i) and +1 at (e, j): ``difference @ x`` is x_j - x_i per spring.

        Made on each access: the springs' own products gather by the incidence's transpose, a CSC view of the same
        arrays (x_i - x_j, the sign folded into what follows), as fast as this CSR copy (1.28 against 1.40 ms at 45k
        nodes) without holding it (0.18 KiB per node). A sparse product gathers the spring vectors several times
        faster than fancy indexing.
        """
        return (-self.incidence.T).tocsr()

    @cached_property
    def _gathering(self) -> sp.csc_matrix:
        """(s, n) -- the incidence's transpose, a CSC view of its arrays, made once: scipy makes a new matrix object
        and checks its arrays on every ``.T``, 10 us of a 32 us gather on the 936-node README beam, twice a step."""
        return self.incidence.T

    def _gathered(self, x: np.ndarray) -> np.ndarray:
        """(s, 3) float -- x_i - x_j per spring (i, j) = ``pairs[e]``: minus :attr:`difference` @ x, bit for bit."""
        return self._gathering @ x

    def _directions(self, x):
        d = self._gathered(x)  # x_i - x_j
        length = vector_lengths(d)
        if length.size and not length.min() > 0.0:
            e = int(np.argmin(length))
            raise SpringCollapsed(e, *self.pairs[e])
        d /= -length[:, None]  # r = (x_j - x_i) / l
        return d, length

    def _magnitudes(self, r, length, v):
        """(s,) float -- spring plus damper force along r on each spring's node i [N]."""
        magnitude = self.stiffness * (length - self.rest_lengths)
        if v is not None and self._damped:
            # the stretch rate (v_j - v_i) . r, as -(v_i - v_j) . r
            magnitude -= self.damping * np.einsum("ij,ij->i", self._gathered(v), r)
        return magnitude

    def __repr__(self) -> str:
        return f"Springs({self.spring_count} springs on {self.node_count} nodes)"


class SpringLinearization(Linearization):
    """The springs' forces and blocks at one configuration (from :meth:`Springs.linearize`).

    Attributes
    ----------
    forces : (n, 3) float
        spring (and damper, if velocities were given) forces on the nodes [N]
    blocks : (s, 3, 3) float
        W_e = c_K H_e + c_D D_e = along_e r r^T + c_K transverse_e I, made at the first access: the implicit step sums
        them into its matrix without storing them where the compiled kernels run (:meth:`summed`)
    directions : (s, 3) float
        unit vectors r_e from i to j
    lengths : (s,) float
        current lengths [m]
    axial : (s,) float
        k_e, coefficient of r r^T in H_e [N/m]
    transverse : (s,) float
        k_e (1 - l0/l), clamped if asked: coefficient of the transverse projector I - r r^T in H_e [N/m]
    along : (s,) float
        c_K (k_e - transverse_e) + c_D k_d, the coefficient of r r^T in W_e [N/m]
    stiffness_scale : float
        c_K
    """

    element_set: Springs
    _blocks: np.ndarray | None

    def __init__(self, forces: np.ndarray, element_set: Springs, directions: np.ndarray, lengths: np.ndarray,
                 axial: np.ndarray, transverse: np.ndarray, along: np.ndarray, stiffness_scale: float):
        super().__init__(forces, None, None, element_set)
        self.directions, self.lengths, self.axial, self.transverse = directions, lengths, axial, transverse
        self.along, self.stiffness_scale = along, float(stiffness_scale)

    @property
    def blocks(self) -> np.ndarray:
        if self._blocks is None:
            # einsum forms the outer products r (along r)^T in 0.7 of the broadcast product's time (65k springs)
            blocks = np.einsum("ij,ik->ijk", self.directions, self.along[:, None] * self.directions)
            blocks.reshape(-1, 9)[:, ::4] += (self.stiffness_scale * self.transverse)[:, None]
            self._blocks = blocks
        return self._blocks

    @blocks.setter
    def blocks(self, value: np.ndarray | None) -> None:
        self._blocks = value

    def summed(self, summation: sp.csr_matrix) -> np.ndarray:
        """``summation @ blocks.reshape(-1, 9)``; where the compiled kernels run and the blocks were not made, each
        block is made where it is summed (:func:`volspring._compiled.spring_block_sum`, the same bits): the step's
        matrix is then assembled without the springs' 72 bytes each beside it (its peak memory)."""
        kernels = compiled()
        if kernels is None or self._blocks is not None:
            return super().summed(summation)
        summation = sp.csr_matrix(summation)
        if summation.shape[1] != len(self.along):  # the kernel does not check its indices
            raise ValueError(f"the summation has {summation.shape[1]} columns; expected {len(self.along)}, one per "
                             "spring")
        out = np.empty((summation.shape[0], 9))
        kernels.spring_block_sum(unsigned(summation.indptr), unsigned(summation.indices),
                                 np.asarray(summation.data, dtype=np.float64), self.directions, self.along,
                                 self.transverse, self.stiffness_scale, out)
        return out

    def dfdx_times(self, u: np.ndarray) -> np.ndarray:
        """(n, 3) float -- dF/dx @ u [N]: H_e (u_j - u_i) = (k - k_t) r (r . du) + k_t du, added
        to node i and subtracted from node j."""
        springs = self.element_set
        kernels = compiled()
        if kernels is not None:
            out = np.empty((springs.node_count, 3))
            incidence = springs.incidence
            kernels.spring_stiffness_times(_node_array("u", u, springs.node_count), unsigned(springs.pairs),
                                           self.directions, self.axial, self.transverse, unsigned(incidence.indptr),
                                           unsigned(incidence.indices), incidence.data, out)
            return out
        du = springs._gathered(u)  # u_i - u_j: the signs below make H_e (u_j - u_i) of it exactly
        along = np.einsum("ij,ij->i", self.directions, du)
        along *= self.transverse - self.axial
        du *= -self.transverse[:, None]  # in place: one (s, 3) temporary fewer
        du += along[:, None] * self.directions
        return springs.incidence @ du


# ---------------------------------------------------------------------------- input checks
_NO_VELOCITIES = np.zeros((0, 3))  # what the compiled kernel takes for "no velocities"
_NO_VELOCITIES.setflags(write=False)


def _node_array(name, value, node_count) -> np.ndarray:
    """(n, 3) C-contiguous float64 -- positions or velocities for the compiled kernel, whose indexing is not bounds-
    checked: the wrong shape is refused here (numpy's sparse product refuses it on the other path)."""
    array = np.ascontiguousarray(value, dtype=np.float64)
    if array.shape != (node_count, 3):
        raise ValueError(f"{name} has shape {array.shape}; expected ({node_count}, 3), one row per node")
    return array


def _immutable(value, dtype, shape) -> bool:
    """Whether ``value`` is a C-contiguous ``dtype`` array of ``shape`` that nothing can write to: read-only, and so is
    every array it views (a read-only view of a writeable array is not)."""
    if not isinstance(value, np.ndarray) or value.dtype != dtype or value.shape != tuple(shape) or \
            not value.flags.c_contiguous:
        return False
    while isinstance(value, np.ndarray):
        if value.flags.writeable:
            return False
        value = value.base
    return value is None


def per_item_array(name, value, count, *, allow_zero) -> np.ndarray:
    """(count,) float -- a number or array of numbers broadcast to one per spring (or node), checked."""
    if _immutable(value, np.float64, (count,)):
        array = value  # shared, not copied: nothing can change it (a model's springs share their topology's)
    else:
        array = _real_array(name, value)
        try:
            array = np.broadcast_to(array, (count,)).copy()
        except ValueError:
            raise ValueError(f"{name} has shape {array.shape}; expected a number or shape ({count},)") from None
    bad = ~np.isfinite(array) | (array < 0) | ((array == 0) & (not allow_zero))
    if bad.any():
        first = np.flatnonzero(bad)[0]
        expected = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"{name}[{first}] = {array[first]} is not finite and {expected}")
    return array


def checked_pairs(springs, node_count) -> np.ndarray:
    """(s, 2) int64 -- node pairs: integers in [0, node_count), each joining two different nodes."""
    try:
        array = np.asarray(springs)
    except ValueError as error:  # ragged nested sequences
        raise ValueError(f"springs = {_shown(springs)} is not a regular (s, 2) array: {error}") from None
    if array.size == 0:
        return np.zeros((0, 2), dtype=np.int64)
    if array.dtype.kind not in "iu":
        raise TypeError(f"springs have dtype {array.dtype}; expected integer node indices (first pair "
                        f"{array.reshape(-1)[:2].tolist()}; integer-valued floats convert with "
                        "np.asarray(springs, dtype=int))")
    if array.ndim != 2 or array.shape[1] != 2:
        raise ValueError(f"springs have shape {array.shape}; expected (s, 2), one node pair per spring "
                         "(e.g. [[0, 1]] for one spring)")
    if not _immutable(springs, np.int64, array.shape):
        array = array.astype(np.int64)
    outside = ((array < 0) | (array >= node_count)).any(axis=1)
    if outside.any():
        e = int(np.flatnonzero(outside)[0])
        raise ValueError(f"springs[{e}] = {array[e].tolist()} indexes a node outside [0, {node_count - 1}] "
                         f"(the model has {node_count} nodes; {int(outside.sum())} spring(s) affected)")
    loops = array[:, 0] == array[:, 1]
    if loops.any():
        e = int(np.flatnonzero(loops)[0])
        raise ValueError(f"springs[{e}] = {array[e].tolist()} joins node {array[e, 0]} to itself; "
                         "expected two different nodes")
    return array
