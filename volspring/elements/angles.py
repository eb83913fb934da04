"""Angle springs: bending of node chains (strings, hair), vectorised over all joints.

Each element is a joint (i, j, k) with edges a = x_j - x_i and b = x_k - x_j. Its angle at j
between j->i and j->k is theta (pi when straight); the code works with the turning angle
phi = pi - theta = atan2(|a x b|, a . b) (0 when straight). The energy is

    E = k / 2 (theta - theta0)^2 = k / 2 (phi - phi0)^2,    k [N m / rad^2 = J / rad^2].

With u = a / |a|, w = b / |b|, c = cos phi = u . w and q = (phi - phi0) / sin phi (so dE/dc = -k q),
the edge gradients are dE/da = -k q (w - c u) / |a| and dE/db = -k q (u - c w) / |b|; the forces are
minus these, taken from the edges to the nodes by a = x_j - x_i, b = x_k - x_j.

**The Hessian in the joint's frame.** Let n be the unit normal of the joint's plane (u x w / sin phi),
p_a = n x u the unit vector normal to a in the plane (towards b) and p_b = w x n (normal to b, towards
a), and measure each edge's change in units of its length, xi_a = da / |a|, xi_b = db / |b|. Then
dphi/dxi = -(p_a, p_b), and with delta = phi - phi0 the 6 x 6 Hessian of E in xi,
k (grad phi grad phi^T + delta d2phi), splits into three 2 x 2 blocks whose eigenpairs are known:

- in the plane, phi is the polar angle of b minus that of a, whose Hessian in a is
  (u p_a^T + p_a u^T) / |a|^2 (and in b, (w p_b^T + p_b w^T) / |b|^2; no cross term). In the
  orthonormal pairs "both edges alike" ((u, w), (p_a, p_b)) / sqrt 2 and "opposite"
  ((u, -w), (p_a, -p_b)) / sqrt 2 this is k [[0, delta], [delta, 2]] (eigenvalues
  k (1 +- sqrt(1 + delta^2))) and k [[0, delta], [delta, 0]] (eigenvalues +-k delta);
- out of the plane, tilting the edges by t_a, t_b (xi = t n) gives
  cos phi' = (c + t_a t_b)(1 - (t_a^2 + t_b^2) / 2) to second order, so d2phi = [[c, -1], [-1, c]] /
  sin phi, and E has the eigenvalues -k (1 - c) q on (n, n) / sqrt 2 and k (1 + c) q on (n, -n) / sqrt 2.

Back in the edges' coordinates,

    H_aa = k / |a|^2 [g00 u u^T + g01 (u p_a^T + p_a u^T) + g11 p_a p_a^T + m n n^T],  H_bb the same with (w, p_b),
    H_ab = k / (|a| |b|) [h00 u w^T + h01 (u p_b^T + p_a w^T) + h11 p_a p_b^T + m' n n^T],

where (in units of k) g = (S + A) / 2 and h = (S - A) / 2 from the in-plane blocks S ("alike") and A ("opposite"),
and m, m' = (mu_alike +- mu_opposite) / 2 from the out-of-plane eigenvalues. Exactly, g = [[0, delta],
[delta, 1]], h = [[0, 0], [0, 1]], m = c q, m' = -q: the chain rule's d2E/dc2 grad c grad c^T +
dE/dc hess c through c, rearranged.

**The projection** (``clamp_compression=True``, the implicit step) clamps the negative eigenvalues
of these three 2 x 2 blocks at 0: it is the nearest positive semi-definite matrix to the Hessian in
the Frobenius norm of xi, in closed form (no ``eigh``): with r = sqrt(1 + delta^2) the in-plane
blocks become k / (2 r) [[delta^2, delta (1 + r)], [delta (1 + r), (1 + r)^2]] and
k |delta| / 2 [[1, sign delta], [sign delta, 1]], and the out-of-plane eigenvalues max(., 0).
The node blocks K = D^T H D (D the 6 x 9 map from node to edge displacements, of rank 6, times the
length scaling) are then positive semi-definite, symmetric, and the exact Hessian wherever that is
positive semi-definite, which for an angle spring is where delta = 0 (at rest: k grad phi grad phi^T;
any delta != 0 gives the in-plane eigenvalue -k |delta|). Elsewhere it differs from the projection of the
9 x 9 node Hessian in the Euclidean norm of node positions (which needs an eigen-decomposition per
joint); both are nearest PSD matrices, in different norms, and equal at rest. ``clamp_compression=False``
keeps every eigenvalue: the exact Hessian (statics, modes).

A straight rest (theta0 = pi) is smooth: q = phi / sin phi -> 1 is evaluated by its series below
phi = 1e-3, so a straight strand at rest has the transverse stiffness k / |a|^2 and no 0 / 0. Where
sin phi = 0 the plane is undefined and any n normal to u serves (the Hessian is isotropic about u
there when phi0 = 0). A joint whose rest is bent (phi0 > 0) has, like any energy of the unsigned
angle, a cone point where it is straight (every bending direction is as good) and another where it
folds back (theta = 0); there sin phi is floored at 1e-12 so nothing is NaN, but forces and stiffness
are those of a cone tip (large, of no definite direction). A bent rest fixes the magnitude of the
turn, not its plane: the dihedral (twist) between joints is held by other elements
(``volspring.structures.hair`` adds span springs across three edges for that).

For a rod of bending stiffness EI [N m^2], joint stiffness k = EI / l_j with l_j = (|a0| + |b0|) / 2
the rest length the joint stands for (the discrete bending energy EI / 2 sum (phi / l_j)^2 l_j;
Bergou et al. 2008 use 2 tan(phi / 2) in place of phi, the same to second order).

Each joint stores its full 3 x 3 grid of node blocks (:meth:`volspring.elements.BlockMap.full`),
formed from its three edge blocks H_aa, H_ab, H_bb; :class:`_JointLinearization` applies dF/dx
through the edge blocks. The kernels hold vectors component-major, (3, e), so that every numpy
loop runs over the joints. The set has no dampers: damp a strand with its springs' dampers or a
``Drag`` force.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from volspring.elements.base import ElementSet, Linearization
from volspring.elements.springs import per_item_array
from volspring.material import _real_array, _shown
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

__all__ = ["AngleSprings", "DihedralSprings", "dihedral_angles", "joint_angles"]

#: Below this turning angle [rad], phi / sin phi and (sin phi - phi cos phi) / sin^3 phi come from
#: their series (dropped terms phi^4 ~ 1e-12 relative; the direct formulas lose 1e-16 / phi^3 there).
SERIES_BELOW = 1e-3
#: Floor on sin phi at the cone points of a bent rest (see the module docstring).
SINE_FLOOR = 1e-12
#: Joints per chunk when the node blocks are formed (:func:`_node_blocks`): 1024 x 81 values stay in cache.
NODE_BLOCK_CHUNK = 1024

def joint_angles(x: np.ndarray, triples: ArrayLike) -> np.ndarray:
    """(e,) float -- the angle theta at j between j->i and j->k of each triple (i, j, k) [rad], pi when straight.

    >>> import numpy as np
    >>> joint_angles(np.array([[1.0, 0, 0], [0, 0, 0], [0, 1, 0]]), np.array([[0, 1, 2]])).round(12).tolist()
    [1.570796326795]
    """
    x = np.asarray(x, dtype=np.float64)
    triples = np.asarray(triples)
    first, second = x[triples[:, 0]] - x[triples[:, 1]], x[triples[:, 2]] - x[triples[:, 1]]
    return np.arctan2(np.linalg.norm(np.cross(first, second), axis=1), np.einsum("ij,ij->i", first, second))


@dataclass(frozen=True, eq=False)
class AngleSprings(ElementSet):
    """Bending springs at joints (i, j, k) of node chains (see the module docstring).

    Parameters
    ----------
    node_count : int
        nodes of the model the joints belong to
    triples : (e, 3) int
        joints (i, j, k), three different nodes each; j is the vertex
    stiffness : (e,) float
        k [N m / rad^2], >= 0 (EI / l_j for a rod, see the module docstring)
    rest_angles : (e,) float
        theta0 [rad] in [0, pi]; pi is straight

    Notes
    -----
    Numbers broadcast. A ValueError names the first bad joint (nodes outside the model or
    repeated, a stiffness < 0 or a rest angle outside [0, pi]).

    Examples
    --------
    A right angle bent to 0.6 pi rad pushes back with the torque k (theta - theta0):

    >>> import numpy as np
    >>> from volspring.elements import AngleSprings
    >>> joint = AngleSprings(3, [[0, 1, 2]], stiffness=2.0, rest_angles=np.pi / 2)
    >>> x = np.array([[1.0, 0, 0], [0, 0, 0], [np.cos(0.6 * np.pi), np.sin(0.6 * np.pi), 0]])
    >>> round(joint.energy(x), 12) == round(0.5 * 2.0 * (0.1 * np.pi) ** 2, 12)
    True
    >>> torque = np.cross(x[2] - x[1], joint.forces(x)[2])[2]   # about the vertex, on the k side
    >>> round(float(torque), 12) == round(-2.0 * 0.1 * np.pi, 12)
    True
    """

    node_count: int
    triples: np.ndarray
    stiffness: np.ndarray
    rest_angles: np.ndarray

    name = "angles"

    if TYPE_CHECKING:  # what the constructor takes: numbers broadcast, arrays are checked and stored (__post_init__)
        def __init__(self, node_count: int, triples: ArrayLike, stiffness: float | ArrayLike,
                     rest_angles: float | ArrayLike) -> None: ...

    def __post_init__(self):
        node_count = int(self.node_count)
        _freeze_joints(self, "triples", _checked_triples(self.triples, node_count), (0.0, np.pi),
                       "[0, pi] (pi is straight)")

    @classmethod
    def at_rest(cls, positions: ArrayLike, triples: ArrayLike, stiffness: float | ArrayLike) -> "AngleSprings":
        """Joints whose rest angles are the angles in ``positions`` (n, 3) [m] (the rest shape)."""
        positions = np.asarray(positions, dtype=np.float64)
        triples = _checked_triples(triples, len(positions))
        return cls(len(positions), triples, stiffness, joint_angles(positions, triples))

    # ------------------------------------------------------------------ the element-set interface
    @property
    def stencil(self) -> np.ndarray:
        return self.triples

    @property
    def joint_count(self) -> int:
        return len(self.triples)

    def angles(self, x: np.ndarray) -> np.ndarray:
        """(e,) float -- theta of every joint at positions x [rad]."""
        return np.pi - self._kinematics(x)[-1]

    def energy(self, x: np.ndarray) -> float:
        """Bending energy sum k / 2 (theta - theta0)^2 [J]."""
        phi = self._kinematics(x)[-1]
        return float(0.5 * np.dot(self.stiffness, (phi - (np.pi - self.rest_angles)) ** 2))

    def forces(self, x: np.ndarray, v: np.ndarray | None = None) -> np.ndarray:
        """(n, 3) float -- bending forces on the nodes [N] (``v`` is not used: no dampers)."""
        return self._evaluate(x, hessian=False)[0]

    def stiffness_blocks(self, x: np.ndarray, *, clamp_compression: bool = True) -> np.ndarray:
        """(e, 9, 3, 3) float -- the Hessian of every joint [N/m], projected to PSD when ``clamp_compression``."""
        return _node_blocks(*self._evaluate(x, hessian=True, project=clamp_compression)[1])

    def linearize(self, x: np.ndarray, v: np.ndarray | None = None, *, stiffness_scale: float = 1.0,
                  damping_scale: float = 0.0, clamp_compression: bool = True) -> Linearization:
        forces, edge_blocks = self._evaluate(x, hessian=True, project=clamp_compression)
        return _JointLinearization(forces, edge_blocks, stiffness_scale, self)

    # ------------------------------------------------------------------ kernels (component-major: (3, e) vectors)
    def _kinematics(self, x):
        """Unit edges u, w (3, e), lengths |a|, |b| (e,), u x w (3, e), sin phi, cos phi and phi (e,)."""
        xt = np.ascontiguousarray(np.asarray(x, dtype=np.float64).T)
        i, j, k = self._columns
        # np.take keeps the (3, e) result component-major (xt[:, j] would be element-major, and so all that follows).
        xi, xj, xk = (np.take(xt, column, axis=1) for column in (i, j, k))
        a, b = xj - xi, xk - xj
        la, lb = np.sqrt(_dot(a, a)), np.sqrt(_dot(b, b))
        if la.size and not min(la.min(), lb.min()) > 0.0:
            e = int(np.argmin(np.minimum(la, lb)))
            raise FloatingPointError(f"angle spring {e} at nodes {self.triples[e].tolist()} has an edge of zero "
                                     "length: its angle is undefined")
        u, w = a / la, b / lb
        normal = _cross(u, w)
        sine, cosine = np.sqrt(_dot(normal, normal)), _dot(u, w)
        return u, w, la, lb, normal, sine, cosine, np.arctan2(sine, cosine)

    @cached_property
    def _columns(self) -> np.ndarray:
        """(3, e) int -- the triples' columns i, j, k, each contiguous."""
        return np.ascontiguousarray(self.triples.T)

    def _evaluate(self, x, *, hessian, project=False):
        """Forces (n, 3) and, with ``hessian``, the edge blocks (H_aa, H_ab, H_bb), each (3, 3, e) [N/m], at x."""
        u, w, la, lb, normal, sine, c, phi = self._kinematics(x)
        k, turn0 = self.stiffness, np.pi - self.rest_angles
        s = np.maximum(sine, SINE_FLOOR)
        # q = (phi - phi0) / sin phi = -(dE/dc) / k; phi / sin phi by its series where phi is small.
        q = np.where(phi < SERIES_BELOW, 1.0 + phi**2 / 6.0, phi / s) - turn0 / s
        de_da = (-k * q / la) * (w - c * u)  # dE/da = dE/dc (w - c u) / |a|
        de_db = (-k * q / lb) * (u - c * w)
        forces = _scatter_columns(self._columns, (de_da, de_db - de_da, -de_db), self.node_count)
        if not hessian:
            return forces, None
        # The joint's frame: n normal to the plane, p_a = n x u and p_b = w x n in it (module docstring).
        # A straight joint (sin phi = 0) has no plane: any n normal to u serves.
        flat = ~(sine > 0.0)
        if flat.any():
            normal = normal.copy()
            normal[:, flat] = _cross(u[:, flat], np.eye(3)[np.argmin(np.abs(u[:, flat]), axis=0)].T)
        n_a, n_b = _unit(normal - _dot(normal, u) * u), _unit(normal - _dot(normal, w) * w)
        p_a, p_b = _cross(n_a, u), _cross(w, n_b)
        # Coefficients of the same-edge (g) and cross-edge (h) blocks in the in-plane (radial, normal to the
        # edge) basis and out of the plane (m), in units of k / (length x length): the module docstring.
        turn = phi - turn0
        if project:
            root = np.hypot(1.0, turn)
            sym00, sym01, sym11 = turn**2 / (2 * root), turn * (1 + root) / (2 * root), (1 + root)**2 / (2 * root)
            anti_diagonal, anti01 = 0.5 * np.abs(turn), 0.5 * turn
            g00, g01, g11 = 0.5 * (sym00 + anti_diagonal), 0.5 * (sym01 + anti01), 0.5 * (sym11 + anti_diagonal)
            h00, h01, h11 = 0.5 * (sym00 - anti_diagonal), 0.5 * (sym01 - anti01), 0.5 * (sym11 - anti_diagonal)
            together = np.maximum(-2.0 * np.sin(0.5 * phi)**2 * q, 0.0)  # (n, n): -(1 - cos phi) q
            apart = np.maximum(2.0 * np.cos(0.5 * phi)**2 * q, 0.0)      # (n, -n): (1 + cos phi) q
            m_same, m_cross = 0.5 * (together + apart), 0.5 * (together - apart)
        else:
            g00, g01, g11, h00, h01, h11 = 0.0, turn, 1.0, 0.0, 0.0, 1.0
            m_same, m_cross = c * q, -q
        # H_aa = k / |a|^2 [g00 u u^T + g01 (u p_a^T + p_a u^T) + g11 p_a p_a^T + m_same n_a n_a^T], H_bb
        # likewise with (w, p_b, n_b), and across
        # H_ab = k / (|a| |b|) [h00 u w^T + h01 (u p_b^T + p_a w^T) + h11 p_a p_b^T + m_cross n_a n_b^T].
        aa = _frame_block((u, p_a, n_a), (u, p_a, n_a), k / la**2, g00, g01, g11, m_same, symmetric=True)
        bb = _frame_block((w, p_b, n_b), (w, p_b, n_b), k / lb**2, g00, g01, g11, m_same, symmetric=True)
        ab = _frame_block((u, p_a, n_a), (w, p_b, n_b), k / (la * lb), h00, h01, h11, m_cross)
        return forces, (aa, ab, bb)


class _JointLinearization(Linearization):
    """Forces and blocks of :class:`AngleSprings` at one configuration, with each joint's three edge blocks.

    dF/dx @ u goes through the edge blocks H_aa, H_ab, H_bb (four 3 x 3 products per joint instead of
    nine); the node blocks ``stiffness`` (e, 9, 3, 3) are built only when asked for.

    Parameters
    ----------
    forces : (n, 3) float
        the joints' forces [N]
    edge_blocks : tuple of three (3, 3, e) float
        H_aa, H_ab, H_bb [N/m], component-major
    stiffness_scale : float
        c_K: ``blocks`` are c_K K
    element_set : AngleSprings
    """

    element_set: AngleSprings

    def __init__(self, forces, edge_blocks, stiffness_scale, element_set):
        self.forces, self.element_set, self.edge_blocks = forces, element_set, edge_blocks
        self.blocks = _node_blocks(*edge_blocks, scale=stiffness_scale)

    # A cached_property is writable like the base's attribute (it lives in the instance __dict__); mypy takes it
    # for a read-only property.
    @cached_property
    def stiffness(self) -> np.ndarray:  # type: ignore[override]
        """(e, 9, 3, 3) float -- K_e alone [N/m]."""
        return _node_blocks(*self.edge_blocks)

    def dfdx_times(self, u) -> np.ndarray:
        aa, ab, bb = self.edge_blocks
        ut = np.ascontiguousarray(np.asarray(u, dtype=np.float64).T)
        i, j, k = self.element_set._columns
        ui, uj, uk = (np.take(ut, column, axis=1) for column in (i, j, k))
        da, db = uj - ui, uk - uj
        fa = _times(aa, da) + _times(ab, db)
        fb = _times(ab.transpose(1, 0, 2), da) + _times(bb, db)
        return _scatter_columns(self.element_set._columns, (fa, fb - fa, -fb), len(u))


def _dot(p, q) -> np.ndarray:
    """(e,) float -- p . q for (3, e) p and q."""
    return p[0] * q[0] + p[1] * q[1] + p[2] * q[2]


def _cross(p, q) -> np.ndarray:
    """(3, e) float -- p x q for (3, e) p and q."""
    return np.stack([p[1] * q[2] - p[2] * q[1], p[2] * q[0] - p[0] * q[2], p[0] * q[1] - p[1] * q[0]])


def _unit(p) -> np.ndarray:
    return p / np.sqrt(_dot(p, p))


def _frame_block(row_frame, column_frame, scale, c00, c01, c11, c22, *, symmetric=False) -> np.ndarray:
    """(3, 3, e) float -- scale [c00 r0 s0^T + c01 (r0 s1^T + r1 s0^T) + c11 r1 s1^T + c22 r2 s2^T] for the
    frames (r0, r1, r2) and (s0, s1, s2) of (3, e) vectors; ``symmetric`` (the same frame twice) forms the
    upper triangle and mirrors it, so the block is exactly symmetric."""
    (r0, r1, r2), (s0, s1, s2) = row_frame, column_frame
    first, second, third = scale * (c00 * s0 + c01 * s1), scale * (c01 * s0 + c11 * s1), (scale * c22) * s2
    out = np.empty((3, 3, r0.shape[-1]))
    for row in range(3):
        for column in range(row if symmetric else 0, 3):
            entry = out[row, column]
            np.multiply(r0[row], first[column], out=entry)
            entry += r1[row] * second[column]
            entry += r2[row] * third[column]
            if symmetric and column != row:
                out[column, row] = entry
    return out


def _times(blocks, p) -> np.ndarray:
    """(3, e) float -- blocks @ p for (3, 3, e) blocks and (3, e) p."""
    return blocks[:, 0] * p[0] + blocks[:, 1] * p[1] + blocks[:, 2] * p[2]


def _scatter_columns(columns, per_node, node_count) -> np.ndarray:
    """(n, 3) float -- the vectors (3, e) on the nodes ``columns`` (k, e), one per column, summed onto the nodes."""
    nodes = columns.ravel()
    values = np.concatenate(per_node, axis=1)  # (3, k e), the columns' vectors one after the other
    return np.stack([np.bincount(nodes, weights=values[c], minlength=node_count) for c in range(3)], axis=1)


def _node_blocks(aa, ab, bb, *, scale=1.0) -> np.ndarray:
    """(e, 9, 3, 3) float -- scale times the node blocks of joints (i, j, k) from their edge blocks (3, 3, e)
    (a = x_j - x_i, b = x_k - x_j): K_ii = H_aa, K_ij = H_ab - H_aa, K_ik = -H_ab, K_jj = H_aa + H_bb -
    H_ab - H_ba, K_jk = H_ab - H_bb, K_kk = H_bb, and K_ji = K_ij^T, K_ki = K_ik^T, K_kj = K_jk^T.

    Formed component-major a chunk of joints at a time and transposed while the chunk is in cache
    (twice as fast as forming all and transposing once)."""
    if scale != 1.0:
        aa, ab, bb = scale * aa, scale * ab, scale * bb
    e = aa.shape[-1]
    out = np.empty((e, 81))
    work = np.empty((3, 3, 3, 3, min(e, NODE_BLOCK_CHUNK)))  # node row, node column, component row, column, joint
    for start in range(0, e, NODE_BLOCK_CHUNK):
        chunk = slice(start, start + NODE_BLOCK_CHUNK)
        a, c, b = aa[..., chunk], ab[..., chunk], bb[..., chunk]
        d = c.transpose(1, 0, 2)  # H_ba
        blocks = work[..., :a.shape[-1]]
        blocks[0, 0] = a
        np.subtract(c, a, out=blocks[0, 1])
        np.negative(c, out=blocks[0, 2])
        np.subtract(d, a, out=blocks[1, 0])
        np.add(a, b, out=blocks[1, 1])
        blocks[1, 1] -= c + d
        np.subtract(c, b, out=blocks[1, 2])
        np.negative(d, out=blocks[2, 0])
        np.subtract(d, b, out=blocks[2, 1])
        blocks[2, 2] = b
        out[chunk] = blocks.reshape(81, -1).T
    return out.reshape(-1, 9, 3, 3)


def _freeze_joints(joints, name, chains, bounds, interval) -> None:
    """Check a joint set's stiffness and rest angles against its checked ``chains`` and store all three read-only
    (``rest_angles`` must lie in ``bounds``, described as ``interval`` in the message)."""
    e = len(chains)
    stiffness = per_item_array("stiffness", joints.stiffness, e, allow_zero=True)
    rest = _real_array("rest_angles", joints.rest_angles)
    try:
        rest = np.broadcast_to(rest, (e,)).copy()
    except ValueError:
        raise ValueError(f"rest_angles has shape {rest.shape}; expected a number or shape ({e},)") from None
    bad = ~np.isfinite(rest) | (rest < bounds[0]) | (rest > bounds[1])
    if bad.any():
        first = int(np.flatnonzero(bad)[0])
        raise ValueError(f"rest_angles[{first}] = {rest[first]} rad is not in {interval}")
    object.__setattr__(joints, "node_count", int(joints.node_count))
    for key, array in ((name, chains), ("stiffness", stiffness), ("rest_angles", rest)):
        array.setflags(write=False)
        object.__setattr__(joints, key, array)


def _checked_triples(triples, node_count) -> np.ndarray:
    """(e, 3) int64 -- joints: integers in [0, node_count), three different nodes each."""
    return _checked_chains("triples", triples, node_count, 3)


def _checked_chains(name, chains, node_count, k) -> np.ndarray:
    """(e, k) int64 -- node chains: integers in [0, node_count), k different nodes each."""
    try:
        array = np.asarray(chains)
    except ValueError as error:
        raise ValueError(f"{name} = {_shown(chains)} is not a regular (e, {k}) array: {error}") from None
    if array.size == 0:
        return np.zeros((0, k), dtype=np.int64)
    if array.dtype.kind not in "iu":
        raise TypeError(f"{name} have dtype {array.dtype}; expected integer node indices")
    if array.ndim != 2 or array.shape[1] != k:
        raise ValueError(f"{name} have shape {array.shape}; expected (e, {k}), {k} nodes per row")
    array = array.astype(np.int64)
    outside = ((array < 0) | (array >= node_count)).any(axis=1)
    if outside.any():
        e = int(np.flatnonzero(outside)[0])
        raise ValueError(f"{name}[{e}] = {array[e].tolist()} indexes a node outside [0, {node_count - 1}] "
                         f"(the model has {node_count} nodes)")
    ordered = np.sort(array, axis=1)
    repeated = (ordered[:, 1:] == ordered[:, :-1]).any(axis=1)
    if repeated.any():
        e = int(np.flatnonzero(repeated)[0])
        raise ValueError(f"{name}[{e}] = {array[e].tolist()} repeats a node; expected {k} different nodes")
    return array


def dihedral_angles(x: np.ndarray, quads: ArrayLike) -> np.ndarray:
    """(e,) float -- the signed dihedral angle psi of each (h, i, j, k) about the edge i -> j [rad], in (-pi, pi]:
    the angle from the plane (h, i, j) to the plane (i, j, k), 0 when h and k are on one side (a planar C)."""
    x = np.asarray(x, dtype=np.float64)
    quads = np.asarray(quads)
    b1, b2, b3 = (x[quads[:, c + 1]] - x[quads[:, c]] for c in range(3))
    n1, n2 = np.cross(b1, b2), np.cross(b2, b3)
    return np.arctan2(np.linalg.norm(b2, axis=1) * np.einsum("ij,ij->i", b1, n2), np.einsum("ij,ij->i", n1, n2))


@dataclass(frozen=True, eq=False)
class DihedralSprings(ElementSet):
    """Twist springs on the dihedral angle psi of node chains (h, i, j, k): E = k / 2 (psi - psi0)^2.

    psi is the signed angle about the middle edge i -> j between the planes (h, i, j) and (i, j, k)
    (:func:`dihedral_angles`); with the joint angles (:class:`AngleSprings`) and the lengths it fixes a
    chain's shape, as bond lengths, bond angles and dihedrals do a molecule's. For a rod of torsional
    rigidity GJ [N m^2], k = GJ / |x_j - x_i| at rest (a twist psi over that edge: torsion psi / l).
    psi - psi0 is taken in (-pi, pi].

    Forces are the exact gradient (Blondel and Karplus 1996): with b1, b2, b3 the three edges and
    n1 = b1 x b2, n2 = b2 x b3, dpsi/dx_h = -|b2| n1 / |n1|^2, dpsi/dx_k = |b2| n2 / |n2|^2 and the
    middle nodes from translation and rotation invariance. The stiffness blocks are Gauss-Newton,
    k grad psi grad psi^T (positive semi-definite, exact where psi = psi0, i.e. at rest; the dropped
    term is k (psi - psi0) d2psi/dx2), whatever ``clamp_compression`` asks. psi is undefined where
    a plane degenerates (h, i, j or i, j, k in a line): give these springs only to bent joints.

    Parameters
    ----------
    node_count : int
    quads : (e, 4) int
        chains (h, i, j, k), four different nodes each
    stiffness : (e,) float
        k [N m / rad^2], >= 0
    rest_angles : (e,) float
        psi0 [rad] in [-pi, pi]
    """

    node_count: int
    quads: np.ndarray
    stiffness: np.ndarray
    rest_angles: np.ndarray

    name = "dihedrals"

    if TYPE_CHECKING:  # what the constructor takes: numbers broadcast, arrays are checked and stored (__post_init__)
        def __init__(self, node_count: int, quads: ArrayLike, stiffness: float | ArrayLike,
                     rest_angles: float | ArrayLike) -> None: ...

    def __post_init__(self):
        node_count = int(self.node_count)
        _freeze_joints(self, "quads", _checked_chains("quads", self.quads, node_count, 4), (-np.pi, np.pi),
                       "[-pi, pi]")

    @classmethod
    def at_rest(cls, positions: ArrayLike, quads: ArrayLike, stiffness: float | ArrayLike) -> "DihedralSprings":
        """Springs whose rest angles are the dihedral angles in ``positions`` (n, 3) [m]."""
        positions = np.asarray(positions, dtype=np.float64)
        quads = _checked_chains("quads", quads, len(positions), 4)
        return cls(len(positions), quads, stiffness, dihedral_angles(positions, quads))

    @property
    def stencil(self) -> np.ndarray:
        return self.quads

    def _twist(self, x):
        """(e,) psi - psi0 in (-pi, pi] and (e, 4, 3) grad psi."""
        x = np.asarray(x, dtype=np.float64)
        b1, b2, b3 = (x[self.quads[:, c + 1]] - x[self.quads[:, c]] for c in range(3))
        n1, n2 = np.cross(b1, b2), np.cross(b2, b3)
        length = np.linalg.norm(b2, axis=1)
        area1, area2 = np.einsum("ij,ij->i", n1, n1), np.einsum("ij,ij->i", n2, n2)
        if length.size and not min(area1.min(), area2.min()) > 0.0:
            e = int(np.argmin(np.minimum(area1, area2)))
            raise FloatingPointError(f"dihedral spring {e} at nodes {self.quads[e].tolist()} has three nodes in a "
                                     "line: its angle is undefined")
        psi = np.arctan2(length * np.einsum("ij,ij->i", b1, n2), np.einsum("ij,ij->i", n1, n2))
        change = np.angle(np.exp(1j * (psi - self.rest_angles)))
        g0 = -(length / area1)[:, None] * n1
        g3 = (length / area2)[:, None] * n2
        s1 = (np.einsum("ij,ij->i", b1, b2) / length**2)[:, None]
        s3 = (np.einsum("ij,ij->i", b3, b2) / length**2)[:, None]
        g1 = -(s1 + 1.0) * g0 + s3 * g3
        g2 = s1 * g0 - (s3 + 1.0) * g3
        return change, np.stack([g0, g1, g2, g3], axis=1)

    def angles(self, x: np.ndarray) -> np.ndarray:
        """(e,) float -- psi of every spring at positions x [rad]."""
        return dihedral_angles(x, self.quads)

    def energy(self, x: np.ndarray) -> float:
        change, _ = self._twist(x)
        return float(0.5 * np.dot(self.stiffness, change**2))

    def forces(self, x: np.ndarray, v: np.ndarray | None = None) -> np.ndarray:
        """(n, 3) float -- twist forces on the nodes [N] (no dampers)."""
        change, gradient = self._twist(x)
        return _scatter(self.quads, -(self.stiffness * change)[:, None, None] * gradient, self.node_count)

    def stiffness_blocks(self, x: np.ndarray, *, clamp_compression: bool = True) -> np.ndarray:
        """(e, 16, 3, 3) float -- the Gauss-Newton blocks k grad psi grad psi^T [N/m]."""
        _, gradient = self._twist(x)
        blocks = self.stiffness[:, None, None, None, None] * gradient[:, :, None, :, None] * gradient[:, None, :, None, :]
        return blocks.reshape(-1, 16, 3, 3)


def _scatter(stencil, per_node, node_count) -> np.ndarray:
    """(n, 3) float -- per-element node vectors (e, k, 3) summed onto the nodes."""
    out = np.zeros((node_count, 3))
    nodes = stencil.ravel()
    for component in range(3):
        out[:, component] = np.bincount(nodes, weights=per_node[..., component].ravel(), minlength=node_count)
    return out
