"""Angle springs: bending of node chains (strings, hair), vectorised over all joints.

Each element is a joint (i, j, k) with edges a = x_j - x_i and b = x_k - x_j. Its angle at j
between j->i and j->k is theta (pi when straight); the code works with the turning angle
phi = pi - theta = atan2(|a x b|, a . b) (0 when straight). The energy is

    E = k / 2 (theta - theta0)^2 = k / 2 (phi - phi0)^2,    k [N m / rad^2 = J / rad^2].

With u = a / |a|, w = b / |b| and c = cos phi = u . w, E is a function of c, and

- dE/dc = -k (phi - phi0) / sin phi,  d2E/dc2 = k [sin phi - (phi - phi0) cos phi] / sin^3 phi;
- dc/da = (w - c u) / |a|,  dc/db = (u - c w) / |b|;
- d2c/da2 = -[u (w - c u)^T + (w - c u) u^T + c (I - u u^T)] / |a|^2 (and a <-> b, u <-> w),
  d2c/da db = [I - w w^T - u (u - c w)^T] / (|a| |b|);

the Hessian is d2E/dc2 grad c grad c^T + dE/dc hess c, taken from the edges to the nodes by
a = x_j - x_i, b = x_k - x_j. A straight rest (theta0 = pi) is smooth: phi / sin phi -> 1 and
d2E/dc2 -> k / 3, evaluated by their series below phi = 1e-3, so a straight strand at rest has
the transverse stiffness k / |a|^2 and no 0 / 0. A joint whose rest is bent (phi0 > 0) has,
like any energy of the unsigned angle, a cone point where it is straight (every bending
direction is as good) and another where it folds back (theta = 0); there sin phi is floored at
1e-12 so nothing is NaN, but forces and stiffness are those of a cone tip (large, of no
definite direction). A bent rest fixes the magnitude of the turn, not its plane: the dihedral
(twist) between joints is held by other elements (``volspring.structures.hair`` adds span
springs across three edges for that).

For a rod of bending stiffness EI [N m^2], joint stiffness k = EI / l_j with l_j = (|a0| + |b0|) / 2
the rest length the joint stands for (the discrete bending energy EI / 2 sum (phi / l_j)^2 l_j;
Bergou et al. 2008 use 2 tan(phi / 2) in place of phi, the same to second order).

Each joint stores its full 3 x 3 grid of node blocks (:meth:`volspring.elements.BlockMap.full`).
With ``clamp_compression=True`` (the implicit step) the 9 x 9 element Hessian is projected onto
the positive semi-definite cone (eigenvalues clamped at 0, one batched ``eigh``); with False it
is exact (statics, modes). The set has no dampers: damp a strand with its springs' dampers or a
``Drag`` force.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from volspring.elements.base import ElementSet, Linearization
from volspring.elements.springs import per_item_array
from volspring.material import _real_array, _shown

__all__ = ["AngleSprings", "DihedralSprings", "dihedral_angles", "joint_angles"]

#: Below this turning angle [rad], phi / sin phi and (sin phi - phi cos phi) / sin^3 phi come from
#: their series (dropped terms phi^4 ~ 1e-12 relative; the direct formulas lose 1e-16 / phi^3 there).
SERIES_BELOW = 1e-3
#: Floor on sin phi at the cone points of a bent rest (see the module docstring).
SINE_FLOOR = 1e-12

# Node-from-edge incidence: a = x_j - x_i, b = x_k - x_j, so d/dx_(i, j, k) = D @ d/d(a, b).
_NODE_EDGE = np.array([[-1.0, 0.0], [1.0, -1.0], [0.0, 1.0]])


def joint_angles(x, triples) -> np.ndarray:
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
    node_count : int -- nodes of the model the joints belong to
    triples : (e, 3) int -- joints (i, j, k), three different nodes each; j is the vertex
    stiffness : (e,) float -- k [N m / rad^2], >= 0 (EI / l_j for a rod, see the module docstring)
    rest_angles : (e,) float -- theta0 [rad] in [0, pi]; pi is straight

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

    def __post_init__(self):
        node_count = int(self.node_count)
        triples = _checked_triples(self.triples, node_count)
        e = len(triples)
        stiffness = per_item_array("stiffness", self.stiffness, e, allow_zero=True)
        rest = _real_array("rest_angles", self.rest_angles)
        try:
            rest = np.broadcast_to(rest, (e,)).copy()
        except ValueError:
            raise ValueError(f"rest_angles has shape {rest.shape}; expected a number or shape ({e},)") from None
        bad = ~np.isfinite(rest) | (rest < 0) | (rest > np.pi)
        if bad.any():
            first = int(np.flatnonzero(bad)[0])
            raise ValueError(f"rest_angles[{first}] = {rest[first]} rad is not in [0, pi] (pi is straight)")
        object.__setattr__(self, "node_count", node_count)
        for name, array in (("triples", triples), ("stiffness", stiffness), ("rest_angles", rest)):
            array.setflags(write=False)
            object.__setattr__(self, name, array)

    @classmethod
    def at_rest(cls, positions, triples, stiffness) -> "AngleSprings":
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

    def angles(self, x) -> np.ndarray:
        """(e,) float -- theta of every joint at positions x [rad]."""
        return np.pi - self._kinematics(x)[-1]

    def energy(self, x) -> float:
        """Bending energy sum k / 2 (theta - theta0)^2 [J]."""
        phi = self._kinematics(x)[-1]
        return float(0.5 * np.dot(self.stiffness, (phi - (np.pi - self.rest_angles)) ** 2))

    def forces(self, x, v=None) -> np.ndarray:
        """(n, 3) float -- bending forces on the nodes [N] (``v`` is not used: no dampers)."""
        return self._evaluate(x, hessian=False)[0]

    def stiffness_blocks(self, x, *, clamp_compression=True) -> np.ndarray:
        """(e, 9, 3, 3) float -- the Hessian of every joint [N/m], projected to PSD when ``clamp_compression``."""
        return self._evaluate(x, hessian=True, project=clamp_compression)[1]

    def linearize(self, x, v=None, *, stiffness_scale=1.0, damping_scale=0.0, clamp_compression=True):
        forces, stiffness = self._evaluate(x, hessian=True, project=clamp_compression)
        return Linearization(forces, stiffness_scale * stiffness, stiffness, self)

    # ------------------------------------------------------------------ kernels
    def _kinematics(self, x):
        x = np.asarray(x, dtype=np.float64)
        i, j, k = self.triples.T
        a, b = x[j] - x[i], x[k] - x[j]
        la, lb = np.linalg.norm(a, axis=1), np.linalg.norm(b, axis=1)
        if la.size and not min(la.min(), lb.min()) > 0.0:
            e = int(np.argmin(np.minimum(la, lb)))
            raise FloatingPointError(f"angle spring {e} at nodes {self.triples[e].tolist()} has an edge of zero "
                                     "length: its angle is undefined")
        u, w = a / la[:, None], b / lb[:, None]
        sine = np.linalg.norm(np.cross(u, w), axis=1)
        cosine = np.einsum("ij,ij->i", u, w)
        return u, w, la, lb, sine, cosine, np.arctan2(sine, cosine)

    def _evaluate(self, x, *, hessian, project=False):
        """Forces (n, 3) and, with ``hessian``, the blocks (e, 9, 3, 3) at x."""
        u, w, la, lb, sine, c, phi = self._kinematics(x)
        k, rest = self.stiffness, np.pi - self.rest_angles
        small = phi < SERIES_BELOW
        s = np.maximum(sine, SINE_FLOOR)
        phi_over_sine = np.where(small, 1.0 + phi**2 / 6.0, phi / s)
        dE_dc = -k * (phi_over_sine - rest / s)
        grad_a = (w - c[:, None] * u) / la[:, None]
        grad_b = (u - c[:, None] * w) / lb[:, None]
        edge_gradients = dE_dc[:, None, None] * np.stack([grad_a, grad_b], axis=1)  # (e, 2, 3)
        node_gradients = np.einsum("pr,erx->epx", _NODE_EDGE, edge_gradients)
        forces = _scatter(self.triples, -node_gradients, self.node_count)
        if not hessian:
            return forces, None
        # d2E/dc2 = k [(sin phi - phi cos phi) + phi0 cos phi] / sin^3 phi; the first part by its series when small.
        bent = np.where(small, 1.0 / 3.0 + 2.0 * phi**2 / 15.0, (s - phi * c) / s**3)
        d2E_dc2 = k * (bent + rest * c / s**3)
        eye = np.eye(3)
        outer = lambda p, q: p[:, :, None] * q[:, None, :]  # noqa: E731
        ta, tb = w - c[:, None] * u, u - c[:, None] * w
        hess_aa = -(outer(u, ta) + outer(ta, u) + c[:, None, None] * (eye - outer(u, u))) / (la**2)[:, None, None]
        hess_bb = -(outer(w, tb) + outer(tb, w) + c[:, None, None] * (eye - outer(w, w))) / (lb**2)[:, None, None]
        hess_ab = (eye - outer(w, w) - outer(u, tb)) / (la * lb)[:, None, None]
        edge_hessian = np.stack([np.stack([hess_aa, hess_ab], axis=1),
                                 np.stack([np.swapaxes(hess_ab, 1, 2), hess_bb], axis=1)], axis=1)  # (e, 2, 2, 3, 3)
        grads = np.stack([grad_a, grad_b], axis=1)
        edge_hessian = (dE_dc[:, None, None, None, None] * edge_hessian
                        + d2E_dc2[:, None, None, None, None] * grads[:, :, None, :, None] * grads[:, None, :, None, :])
        blocks = np.einsum("pr,qs,ersxy->epqxy", _NODE_EDGE, _NODE_EDGE, edge_hessian)  # (e, 3, 3, 3, 3)
        if project:
            blocks = _projected(blocks)
        return forces, blocks.reshape(-1, 9, 3, 3)


def _projected(blocks) -> np.ndarray:
    """(e, 3, 3, 3, 3) float -- each element's 9 x 9 matrix with its negative eigenvalues set to 0."""
    e = len(blocks)
    matrices = blocks.transpose(0, 1, 3, 2, 4).reshape(e, 9, 9)
    matrices = 0.5 * (matrices + matrices.transpose(0, 2, 1))
    values, vectors = np.linalg.eigh(matrices)
    if not (values < 0).any():
        return blocks
    matrices = (vectors * np.maximum(values, 0.0)[:, None, :]) @ vectors.transpose(0, 2, 1)
    return matrices.reshape(e, 3, 3, 3, 3).transpose(0, 1, 3, 2, 4)


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


def dihedral_angles(x, quads) -> np.ndarray:
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
    quads : (e, 4) int -- chains (h, i, j, k), four different nodes each
    stiffness : (e,) float -- k [N m / rad^2], >= 0
    rest_angles : (e,) float -- psi0 [rad] in [-pi, pi]
    """

    node_count: int
    quads: np.ndarray
    stiffness: np.ndarray
    rest_angles: np.ndarray

    name = "dihedrals"

    def __post_init__(self):
        node_count = int(self.node_count)
        quads = _checked_chains("quads", self.quads, node_count, 4)
        e = len(quads)
        stiffness = per_item_array("stiffness", self.stiffness, e, allow_zero=True)
        rest = _real_array("rest_angles", self.rest_angles)
        try:
            rest = np.broadcast_to(rest, (e,)).copy()
        except ValueError:
            raise ValueError(f"rest_angles has shape {rest.shape}; expected a number or shape ({e},)") from None
        bad = ~np.isfinite(rest) | (np.abs(rest) > np.pi)
        if bad.any():
            first = int(np.flatnonzero(bad)[0])
            raise ValueError(f"rest_angles[{first}] = {rest[first]} rad is not in [-pi, pi]")
        object.__setattr__(self, "node_count", node_count)
        for name, array in (("quads", quads), ("stiffness", stiffness), ("rest_angles", rest)):
            array.setflags(write=False)
            object.__setattr__(self, name, array)

    @classmethod
    def at_rest(cls, positions, quads, stiffness) -> "DihedralSprings":
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

    def angles(self, x) -> np.ndarray:
        """(e,) float -- psi of every spring at positions x [rad]."""
        return dihedral_angles(x, self.quads)

    def energy(self, x) -> float:
        change, _ = self._twist(x)
        return float(0.5 * np.dot(self.stiffness, change**2))

    def forces(self, x, v=None) -> np.ndarray:
        """(n, 3) float -- twist forces on the nodes [N] (no dampers)."""
        change, gradient = self._twist(x)
        return _scatter(self.quads, -(self.stiffness * change)[:, None, None] * gradient, self.node_count)

    def stiffness_blocks(self, x, *, clamp_compression=True) -> np.ndarray:
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
