"""The penalty response of contact: contact stencils, the force law, the stiffness rule, the Jacobian.

What :class:`~volspring.collision.contact.ContactForce` (between bodies) and
:class:`~volspring.collision.contact.ObstacleContactForce` (against static obstacles) share: given
the contacts found at some positions (:class:`PenaltyContacts`), the penalty, damping and friction
forces and their Jacobians, as a scene force (``accumulate``, ``jacobian``, ``potential_energy``;
see :mod:`volspring.scene`). Finding the contacts is the subclasses' part (``_detect``).

The contact stencil. Every contact joins a penetrating vertex p to the point of the other side it
is pushed away from: for two bodies, the point of the other body's tet that contains p, with the
tet's nodes weighted by p's barycentric coordinates w; for a static obstacle, nothing (the
obstacle does not move). A contact is stored as nodes ``(p, t0, t1, t2, t3)`` with weights
``g = (1, -w0, -w1, -w2, -w3)`` (obstacles: ``(p,)``, ``(1,)``), so the relative velocity is
``u = sum_a g_a v_a`` and the force on node a is ``g_a F``. Because the barycentric weights sum
to one, the forces of a contact sum to zero: total linear momentum is conserved to round-off.

The force of a contact, with depth d (clamped at 0) and unit direction r out of the other side
(consistent penetration depth, :func:`~volspring.collision.consistent_penetration_depths`, or
the obstacle's nearest surface point)::

    s = r.u                         separation speed (> 0 when p moves out)
    lambda = max(k_c d - c_n s, 0)  normal force: penalty plus normal damping, never pulling
    F = lambda r - mu lambda u_t / sqrt(|u_t|^2 + eps^2),    u_t = u - s r

Damping acts in contact whether the bodies approach or separate, but the normal force is
clamped at zero, so a contact never sticks: dampers only remove energy, and the penalty energy
not returned during a fast separation is lost too. The friction term is regularised Coulomb:
for |u_t| >> eps it is mu lambda against the sliding direction, below eps it turns into a
viscosity mu lambda / eps, so a body at rest creeps at speeds ~eps under tangential load. For
explicit integrators that viscosity must stay below the step's limit, h mu lambda / (m eps) < 2
per contact; implicit Euler takes it through the Jacobian.

Penalty stiffness rule. ``k_c = alpha E_eff l`` with ``E_eff = 2 E_a E_b / (E_a + E_b)`` the
harmonic mean of the two bodies' Young's moduli (a rigid obstacle has E = inf, so E_eff = 2 E),
l the mean rest edge length of the penetrating vertex's body, and ``alpha = stiffness_factor``
(default 1). Why: a surface vertex carries the contact pressure p over an area ~l^2, so its
equilibrium depth is d ~ p l^2 / k_c = (p / E_eff) l / alpha: the penalty layer is as compliant as
1 / alpha edge lengths of the material itself, i.e. the depth is a fraction (strain / alpha) of an
edge length, independent of the mesh size. At alpha = 1, k_c is about a third of what the springs
around a vertex give it (~2.8 E l for the Van Gelder rule), so it barely lowers the explicit
stable step; larger alpha keeps contact tighter and is what implicit Euler with the Jacobian is
for. ``stiffness=`` sets k_c [N/m] directly. The damping coefficient is
``c_n = 2 zeta sqrt(k_c m)`` (critical for zeta = 1) with m the reduced mass of p and the
interpolated tet mass (p's own mass against an obstacle), or ``damping=`` c_n [N s/m].

Jacobian (for implicit Euler). With the depth linearised as ``d ~ d0 - r.(sum_b g_b dx_b)``,
and r and the contact set held fixed over the step, a contact contributes
``dF_a/dx_b = -k_c g_a g_b r r^T`` and
``dF_a/dv_b = -g_a g_b [c_n r r^T + mu lambda (P / rho - u_t u_t^T / rho^3)]``
(``P = I - r r^T``, ``rho = sqrt(|u_t|^2 + eps^2)``) for active contacts (lambda > 0): the 5-node
block structure, symmetric and negative semidefinite, so the implicit system stays symmetric
positive definite for CG. Left out (they are not symmetric): the rotation of r, the dependence of
the friction force on lambda, of the damping on x. The linearised depth is exact for a vertex
under a flat part of the surface; the tests compare it with finite differences.

Caching policy. Contacts are detected at the positions of every call (Runge-Kutta stages differ),
but the last contact set is kept with a copy of its positions: ``accumulate``, ``jacobian`` and
``potential_energy`` at the same positions (as the implicit step and the energy monitor call
them) share one detection. The collision numbering and the per-pair stiffness are built once.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from scipy import sparse
    from volspring.model import Model

__all__ = ["PenaltyContacts", "DEFAULT_STIFFNESS_FACTOR", "DEFAULT_DAMPING_RATIO", "DEFAULT_FRICTION_VELOCITY"]

DEFAULT_STIFFNESS_FACTOR = 1.0    # alpha of k_c = alpha E_eff l (see the module docstring)
DEFAULT_DAMPING_RATIO = 0.5       # zeta of c_n = 2 zeta sqrt(k_c m): a bounce keeps ~16% of its speed
DEFAULT_FRICTION_VELOCITY = 0.01  # eps [m/s]: sliding slower than 1 cm/s turns viscous


@dataclass(frozen=True, eq=False)
class PenaltyContacts:
    """The contacts at one set of positions, as stencils over model nodes.

    Attributes
    ----------
    nodes : (c, m) int64
        the penetrating vertex, then the nodes that carry the reaction (m = 5 between bodies, 1 against an obstacle)
    weights : (c, m) float
        1, then minus the barycentric weights
    depth : (c,) float
        penetration depth, clamped at 0 [m]
    direction : (c, 3) float
        unit direction out of the other side
    stiffness : (c,) float
        k_c [N/m]
    damping : (c,) float
        c_n [N s/m]
    other : (c,) int64
        the body (``ContactForce``) or obstacle (``ObstacleContactForce``) penetrated
    """

    nodes: np.ndarray
    weights: np.ndarray
    depth: np.ndarray
    direction: np.ndarray
    stiffness: np.ndarray
    damping: np.ndarray
    other: np.ndarray

    @property
    def count(self) -> int:
        return len(self.depth)

    @property
    def vertex(self) -> np.ndarray:
        """(c,) int64 -- the penetrating model node of each contact."""
        return self.nodes[:, 0]

    @property
    def max_depth(self) -> float:
        """Largest depth [m], 0 without contacts."""
        return float(self.depth.max()) if self.count else 0.0


def _positive(value, name, *, allow_zero=False, allow_none=False):
    if value is None and allow_none:
        return None
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} = {value!r} is not a number") from None
    if not np.isfinite(number) or number < 0 or (number == 0 and not allow_zero):
        raise ValueError(f"{name} = {value!r} is not finite and {'>= 0' if allow_zero else '> 0'}")
    return number


def _stencil_matrix(nodes, weights, blocks, node_count):
    """(3n, 3n) csr: ``sum over contacts of g_a g_b blocks`` at node blocks (nodes[a], nodes[b]).

    The reference form of :class:`_StencilPattern` (which gives the same matrices bit for bit): kept for the tests.
    """
    count, width = nodes.shape
    coefficient = weights[:, :, None] * weights[:, None, :]
    data = coefficient[:, :, :, None, None] * blocks[:, None, None, :, :]
    axis = np.arange(3)
    rows = 3 * nodes[:, :, None, None, None] + axis[:, None]
    cols = 3 * nodes[:, None, :, None, None] + axis
    shape = (count, width, width, 3, 3)
    return sp.csr_matrix((data.ravel(), (np.broadcast_to(rows, shape).ravel(), np.broadcast_to(cols, shape).ravel())),
                         shape=(3 * node_count, 3 * node_count))


class _StencilPattern:
    """The csr structure of ``_stencil_matrix`` for one contact set, shared by the matrices built on it.

    ``csr_matrix((data, (rows, cols)))`` buckets the (c, m, m, 3, 3) entries by row keeping their order, sorts
    each row by column with a sort that compares columns only (so its permutation does not depend on the
    data) and adds duplicates left to right. Those steps are done here once, on entry numbers instead of
    data; :meth:`matrix` then gathers each entry's product ``(g_a g_b) block_ij`` in that order and adds it
    with ``np.add.at``, which also adds left to right: the same sums bit for bit, for dF/dx and dF/dv of a
    step at the cost of one pattern.

    Rows ``3 node + i`` of one node hold the same columns for i = 0, 1, 2 (entries 3 i apart), so only one
    row per node is sorted.
    """

    def __init__(self, nodes: np.ndarray, weights: np.ndarray, node_count: int):
        width = nodes.shape[1]
        flat = nodes.ravel()  # stencil slot (contact, a) -> node
        order = np.argsort(flat, kind="stable")  # scipy's bucketing of the slots by row
        node = flat[order]
        first = np.flatnonzero(np.r_[True, node[1:] != node[:-1]])
        counts = np.zeros(node_count, dtype=np.int64)  # entries of row 3 node: 3 m per slot, (b, j)
        counts[node[first]] = 3 * width * np.diff(np.r_[first, len(flat)])
        j = np.arange(3)
        contact, a = np.divmod(order, width)
        pattern = sp.csr_matrix((np.arange(3 * width * len(flat), dtype=np.float64),
                                 (3 * nodes[contact][:, :, None] + j).ravel(), np.r_[0, np.cumsum(counts)]),
                                shape=(node_count, 3 * node_count))
        pattern.sort_indices()  # scipy's own column sort; the positions it carries are exact in float64
        position = pattern.data.astype(np.int64)
        slot, rest = np.divmod(position, 3 * width)
        contact = contact[slot]
        self._block_index = 9 * contact + rest % 3  # entry (contact, 0, j) of the (c, 3, 3) blocks; + 3 i in row i
        row = np.repeat(np.arange(node_count), counts)
        new = np.r_[True, (pattern.indices[1:] != pattern.indices[:-1]) | (row[1:] != row[:-1])]
        unique = np.cumsum(new) - 1  # stored entry of the node's row each entry is added to
        kept = np.bincount(row[new], minlength=node_count)
        start = np.r_[0, np.cumsum(kept)][:-1]
        base, step = 3 * start[row] + unique - start[row], kept[row]
        self._target = np.concatenate([base, base + step, base + 2 * step])
        self.indices = np.empty(3 * int(kept.sum()), dtype=np.int64)
        self.indices[self._target] = np.tile(pattern.indices, 3)
        self.indptr = np.r_[0, np.cumsum(np.repeat(kept, 3))]
        self.shape = (3 * node_count, 3 * node_count)
        coefficient = weights[:, :, None] * weights[:, None, :]  # g_a g_b, (c, m, m)
        self._coefficient = coefficient.ravel()[width * (width * contact + a[slot]) + rest // 3]

    def matrix(self, blocks: np.ndarray) -> sp.csr_matrix:
        """(3n, 3n) csr: ``sum over contacts of g_a g_b blocks`` (blocks (c, 3, 3)), as ``_stencil_matrix``."""
        flat = blocks.ravel()
        terms = np.concatenate([self._coefficient * flat[self._block_index + 3 * i] for i in range(3)])
        data = np.full(len(self.indices), -0.0)  # -0 + t = t for every t: the sum starts at the first term
        np.add.at(data, self._target, terms)
        return sp.csr_matrix((data, self.indices, self.indptr), shape=self.shape)


class _PenaltyResponse:
    """Penalty, damping and friction on contact stencils: what both contact forces share."""

    def __init__(self, model, *, stiffness, stiffness_factor, damping_ratio, damping, friction, friction_velocity):
        self.model = model
        self.stiffness = _positive(stiffness, "stiffness", allow_none=True)
        self.stiffness_factor = _positive(stiffness_factor, "stiffness_factor")
        if damping is not None and damping_ratio is not None:
            raise ValueError(f"give damping_ratio or damping, not both (damping_ratio={damping_ratio!r}, "
                             f"damping={damping!r})")
        self.damping = _positive(damping, "damping", allow_zero=True, allow_none=True)
        self.damping_ratio = _positive(DEFAULT_DAMPING_RATIO if damping_ratio is None and damping is None
                                       else damping_ratio, "damping_ratio", allow_zero=True, allow_none=True)
        self.friction = _positive(friction, "friction", allow_zero=True)
        self.friction_velocity = _positive(friction_velocity, "friction_velocity")
        self._cache = None

    # ------------------------------------------------------------------ per-contact constants
    def _coefficients(self, E_eff, length, reduced_mass):
        """k_c (c,) [N/m] and c_n (c,) [N s/m] of each contact (see the module docstring)."""
        if self.stiffness is None:
            k = self.stiffness_factor * E_eff * length
            if not np.isfinite(k).all():
                raise ValueError("the model has no material (built from arrays): give stiffness= [N/m]")
        else:
            k = np.full(len(length), self.stiffness)
        c = np.full(len(k), self.damping) if self.damping is not None else \
            2.0 * self.damping_ratio * np.sqrt(k * reduced_mass)
        return k, c

    def contacts(self, x: np.ndarray) -> PenaltyContacts:
        """The contacts at positions ``x`` (n, 3) [m] (cached for repeated calls at the same positions)."""
        x = np.asarray(x, dtype=np.float64)
        if x.shape != (self.model.node_count, 3):
            raise ValueError(f"x has shape {x.shape}, expected ({self.model.node_count}, 3)")
        if self._cache is not None and np.array_equal(self._cache[0], x):
            return self._cache[1]
        found = self._detect(x)
        self._cache = (x.copy(), found)
        return found

    def _detect(self, x) -> PenaltyContacts:  # pragma: no cover - interface
        raise NotImplementedError

    def _response(self, found, v):
        """Normal force lambda (c,), active (c,), force F (c, 3) on the vertex, tangential u_t and rho."""
        u = np.einsum("cm,cmj->cj", found.weights, v[found.nodes])
        r = found.direction
        s = np.einsum("cj,cj->c", u, r)
        lam = found.stiffness * found.depth - found.damping * s
        active = lam > 0
        lam = np.where(active, lam, 0.0)
        force = lam[:, None] * r
        tangential = u - s[:, None] * r
        rho = np.sqrt(np.einsum("cj,cj->c", tangential, tangential) + self.friction_velocity ** 2)
        if self.friction:
            force -= (self.friction * lam / rho)[:, None] * tangential
        return lam, active, force, tangential, rho

    # ------------------------------------------------------------------ the force protocol
    def accumulate(self, model: Model, x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray) -> None:
        """Add the contact forces [N] at (x, v) into ``out`` (n, 3)."""
        found = self.contacts(x)
        if not found.count:
            return
        _, _, force, _, _ = self._response(found, np.asarray(v, dtype=np.float64))
        per_node = found.weights[:, :, None] * force[:, None, :]
        index = found.nodes.ravel()
        for axis in range(3):
            out[:, axis] += np.bincount(index, weights=per_node[:, :, axis].ravel(), minlength=len(out))

    def jacobian(self, model: Model, x: np.ndarray, v: np.ndarray,
                 t: float) -> tuple[sparse.spmatrix | None, sparse.spmatrix | None]:
        """``(dF/dx, dF/dv)``, each a (3n, 3n) csr matrix, or ``(None, None)`` without active contacts."""
        found = self.contacts(x)
        if not found.count:
            return None, None
        lam, active, _, tangential, rho = self._response(found, np.asarray(v, dtype=np.float64))
        if not active.any():
            return None, None
        keep = np.flatnonzero(active)
        r = found.direction[keep]
        normal = np.einsum("ci,cj->cij", r, r)
        dfdx = -found.stiffness[keep, None, None] * normal
        dfdv = -found.damping[keep, None, None] * normal
        if self.friction:
            ut, rh = tangential[keep], rho[keep]
            projector = np.eye(3) - normal
            sliding = projector / rh[:, None, None] - np.einsum("ci,cj->cij", ut, ut) / rh[:, None, None] ** 3
            dfdv -= (self.friction * lam[keep])[:, None, None] * sliding
        nodes, weights, n = found.nodes[keep], found.weights[keep], self.model.node_count
        pattern = _StencilPattern(nodes, weights, n)
        return pattern.matrix(dfdx), pattern.matrix(dfdv)

    def potential_energy(self, model: Model, x: np.ndarray, t: float) -> float:
        """Penalty energy ``sum k_c d^2 / 2`` [J] (exact where the depth is a distance to a flat surface)."""
        found = self.contacts(x)
        return float(0.5 * np.dot(found.stiffness, found.depth ** 2))
