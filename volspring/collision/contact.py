"""Penalty contact forces between deformable bodies and against static obstacles, with their Jacobians.

Both forces are scene forces (``accumulate``, ``jacobian``, ``potential_energy``; see
:mod:`volspring.scene`) and work with every integrator.

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

Known limits, measured in ``tests/test_contact.py``:

- Frictionless contact is not conservative: the interpolated vertex normals of a coarse surface
  tilt near its rim, so r is not the gradient of d and a body pressed on another can be pushed
  sideways and gain energy (a 2 x 2 x 2-cell cube pressed on a block drifted off and gained more
  energy than the push supplied). Friction holds it; give ``friction`` > 0 for resting contact.
- Contacts are found at the start of a step only: a vertex can enter deep within one step when
  omega_c h > 1 (omega_c = sqrt(k_c / m)); implicit Euler then pushes it out stably, but the
  penalty energy of that first state can be many times the impact's kinetic energy.
- The Jacobian leaves out how the reaction is redistributed over the tet's nodes as the
  barycentric weights change (not symmetric; it moves no momentum and does not touch the
  penetrating vertex's own row).

Caching policy. Contacts are detected at the positions of every call (Runge-Kutta stages differ),
but the last contact set is kept with a copy of its positions: ``accumulate``, ``jacobian`` and
``potential_energy`` at the same positions (as the implicit step and the energy monitor call
them) share one detection. The collision numbering and the per-pair stiffness are built once.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from volspring.collision.bodies import CollisionBodies
from volspring.collision.multibody import MultiBodyModel
from volspring.collision.obstacles import StaticTriangleMesh, obstacle_contacts
from volspring.constraints import HalfSpace
from volspring.collision.penetration import closest_surface_depths, consistent_penetration_depths
from volspring.collision.spatial_hash import detect_collisions
from volspring.model import SpringModel
from volspring.topology import SPRING_KINDS

__all__ = ["ContactForce", "ObstacleContactForce", "PenaltyContacts", "DEFAULT_STIFFNESS_FACTOR",
           "DEFAULT_DAMPING_RATIO", "DEFAULT_FRICTION_VELOCITY", "DEPTH_METHODS"]

logger = logging.getLogger(__name__)

DEFAULT_STIFFNESS_FACTOR = 1.0    # alpha of k_c = alpha E_eff l (see the module docstring)
DEFAULT_DAMPING_RATIO = 0.5       # zeta of c_n = 2 zeta sqrt(k_c m): a bounce keeps ~16% of its speed
DEFAULT_FRICTION_VELOCITY = 0.01  # eps [m/s]: sliding slower than 1 cm/s turns viscous
DEPTH_METHODS = {"consistent": consistent_penetration_depths, "closest_surface": closest_surface_depths}


@dataclass(frozen=True, eq=False)
class PenaltyContacts:
    """The contacts at one set of positions, as stencils over model nodes.

    Attributes
    ----------
    nodes : (c, m) int64 -- the penetrating vertex, then the nodes that carry the reaction
        (m = 5 between bodies, 1 against an obstacle)
    weights : (c, m) float -- 1, then minus the barycentric weights
    depth : (c,) float -- penetration depth, clamped at 0 [m]
    direction : (c, 3) float -- unit direction out of the other side
    stiffness : (c,) float -- k_c [N/m]
    damping : (c,) float -- c_n [N s/m]
    other : (c,) int64 -- the body (``ContactForce``) or obstacle (``ObstacleContactForce``) penetrated
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


def _node_properties(system):
    """``(model, E (n,) [Pa], l (n,) [m])`` of every model node, from a MultiBodyModel or SpringModel."""
    if isinstance(system, MultiBodyModel):
        return system.model, system.youngs_modulus[system.node_body], system.edge_length[system.node_body]
    if isinstance(system, SpringModel):
        n = system.node_count
        E = np.full(n, np.nan if system.material is None else system.material.E)
        edges = system.kinds == SPRING_KINDS.index("tet_edge")
        length = system.rest_lengths[edges].mean() if edges.any() else system.rest_lengths.mean()
        return system, E, np.full(n, length)
    raise TypeError(f"expected a MultiBodyModel (assemble_bodies) or a SpringModel, got {type(system).__name__}")


def _stencil_matrix(nodes, weights, blocks, node_count):
    """(3n, 3n) csr: ``sum over contacts of g_a g_b blocks`` at node blocks (nodes[a], nodes[b])."""
    count, width = nodes.shape
    coefficient = weights[:, :, None] * weights[:, None, :]
    data = coefficient[:, :, :, None, None] * blocks[:, None, None, :, :]
    axis = np.arange(3)
    rows = 3 * nodes[:, :, None, None, None] + axis[:, None]
    cols = 3 * nodes[:, None, :, None, None] + axis
    shape = (count, width, width, 3, 3)
    return sp.csr_matrix((data.ravel(), (np.broadcast_to(rows, shape).ravel(), np.broadcast_to(cols, shape).ravel())),
                         shape=(3 * node_count, 3 * node_count))


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

    def contacts(self, x) -> PenaltyContacts:
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
    def accumulate(self, x, v, t, out):
        """Add the contact forces [N] at (x, v) into ``out`` (n, 3)."""
        found = self.contacts(x)
        if not found.count:
            return
        _, _, force, _, _ = self._response(found, np.asarray(v, dtype=np.float64))
        per_node = found.weights[:, :, None] * force[:, None, :]
        index = found.nodes.ravel()
        for axis in range(3):
            out[:, axis] += np.bincount(index, weights=per_node[:, :, axis].ravel(), minlength=len(out))

    def jacobian(self, x, v, t):
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
        return _stencil_matrix(nodes, weights, dfdx, n), _stencil_matrix(nodes, weights, dfdv, n)

    def potential_energy(self, x, t) -> float:
        """Penalty energy ``sum k_c d^2 / 2`` [J] (exact where the depth is a distance to a flat surface)."""
        found = self.contacts(x)
        return float(0.5 * np.dot(found.stiffness, found.depth ** 2))


class ContactForce(_PenaltyResponse):
    """Penalty contact between deformable bodies: detection, consistent depths, penalty, damping, friction.

    Parameters
    ----------
    system : MultiBodyModel or SpringModel -- the bodies (:func:`assemble_bodies`); a SpringModel
        built from one mesh is one body (useful with ``self_collision=True``)
    stiffness : float, optional -- k_c [N/m] for every contact, instead of the material rule
    stiffness_factor : float -- alpha of ``k_c = alpha E_eff l`` (module docstring)
    damping_ratio : float, optional -- zeta of ``c_n = 2 zeta sqrt(k_c m)``; default 0.5
    damping : float, optional -- c_n [N s/m] for every contact, instead of ``damping_ratio``
    friction : float -- Coulomb coefficient mu [-], 0 for frictionless contact
    friction_velocity : float -- regularisation eps [m/s] of the friction
    self_collision : bool -- also collide each body with itself
    method : {"consistent", "closest_surface"} -- penetration depths (Heidelberger et al. 2004, or
        the naive nearest surface point, kept for comparison)
    cell_size : float, optional -- hash cell [m]; default the mean rest edge length

    Examples
    --------
    >>> import numpy as np
    >>> from volspring import Material, Scene, TetMesh
    >>> from volspring.collision.multibody import Body, assemble_bodies
    >>> tet = TetMesh(np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]), np.array([[0, 1, 2, 3]]))
    >>> rubber = Material(E=1e5, nu=0.3, density=1000.0)
    >>> system = assemble_bodies([Body(tet, rubber), Body(tet, rubber, translation=(0.1, 0.12, 0.14))])
    >>> contact = ContactForce(system)
    >>> forces = np.zeros((8, 3))
    >>> contact.accumulate(system.model.rest_positions, np.zeros((8, 3)), 0.0, forces)
    >>> contact.contacts(system.model.rest_positions).vertex.tolist()  # body 1's corner inside body 0
    [4]
    >>> bool(abs(forces.sum(axis=0)).max() < 1e-15 * abs(forces).max())  # momentum: forces sum to round-off
    True
    """

    def __init__(self, system, *, stiffness=None, stiffness_factor=DEFAULT_STIFFNESS_FACTOR, damping_ratio=None,
                 damping=None, friction=0.0, friction_velocity=DEFAULT_FRICTION_VELOCITY, self_collision=False,
                 method="consistent", cell_size=None):
        model, _, _ = _node_properties(system)
        super().__init__(model, stiffness=stiffness, stiffness_factor=stiffness_factor, damping_ratio=damping_ratio,
                         damping=damping, friction=friction, friction_velocity=friction_velocity)
        if method not in DEPTH_METHODS:
            raise ValueError(f"unknown depth method {method!r}; known: {', '.join(DEPTH_METHODS)}")
        if isinstance(system, MultiBodyModel):
            self.bodies, self.collision_nodes = system.collision_bodies, system.collision_nodes
            E, length = system.youngs_modulus, system.edge_length
        else:
            if model.topology is None:
                raise ValueError("a SpringModel built from arrays has no tet mesh to collide; use assemble_bodies")
            mesh = model.topology.mesh
            self.bodies = CollisionBodies((mesh,))
            self.collision_nodes = np.arange(mesh.node_count)
            E = np.array([np.nan if model.material is None else model.material.E])
            length = np.array([mesh.edge_lengths.mean()])
        # Per (vertex body, penetrated body): k_c = alpha E_eff l_vertex-body (module docstring).
        self._pair_modulus = 2.0 * E[:, None] * E[None, :] / (E[:, None] + E[None, :])
        self._body_length = length
        self.self_collision = bool(self_collision)
        self.method = method
        self.cell_size = None if cell_size is None else _positive(cell_size, "cell_size")

    @property
    def pair_stiffness(self) -> np.ndarray:
        """(b, b) float -- k_c [N/m] of a vertex of body i inside body j (the rule, or ``stiffness``)."""
        if self.stiffness is not None:
            return np.full(self._pair_modulus.shape, self.stiffness)
        return self.stiffness_factor * self._pair_modulus * self._body_length[:, None]

    def __repr__(self) -> str:
        return (f"ContactForce({self.bodies.body_count} bodies, method={self.method!r}, friction={self.friction:g}, "
                f"self_collision={self.self_collision})")

    def penetration_depths(self, x):
        """The :class:`~volspring.collision.PenetrationDepths` at model positions ``x`` (collision ids)."""
        positions = np.asarray(x, dtype=np.float64)[self.collision_nodes]
        hits = detect_collisions(self.bodies, positions, cell_size=self.cell_size, self_collision=self.self_collision)
        depth_method = DEPTH_METHODS[self.method]
        options = {} if self.method == "closest_surface" else {"cell_size": self.cell_size}
        return depth_method(self.bodies, positions, hits, **options)

    def _detect(self, x) -> PenaltyContacts:
        depths = self.penetration_depths(x)
        weights = np.concatenate([np.ones((depths.count, 1)), -depths.barycentric], axis=1)
        nodes = self.collision_nodes[np.concatenate([depths.vertex[:, None], self.bodies.tets[depths.tet]], axis=1)]
        masses = self.model.masses
        vertex_mass = masses[nodes[:, 0]]
        tet_mass = np.einsum("ck,ck->c", depths.barycentric, masses[nodes[:, 1:]])
        stiffness, damping = self._coefficients(
            self._pair_modulus[depths.vertex_body, depths.other_body], self._body_length[depths.vertex_body],
            vertex_mass * tet_mass / (vertex_mass + tet_mass))
        if depths.count:
            logger.debug("%d contacts, deepest %.3g m", depths.count, depths.depth.max())
        return PenaltyContacts(nodes, weights, np.maximum(depths.depth, 0.0), depths.direction, stiffness, damping,
                               depths.other_body)


class ObstacleContactForce(_PenaltyResponse):
    """Penalty contact of model nodes with static half-spaces and triangle meshes.

    Same penalty, damping and friction as :class:`ContactForce`, with the obstacle rigid
    (``E_eff = 2 E`` of the node's body) and not moving: no reaction is applied, so momentum goes
    into the obstacle. Depth and direction come from the nearest obstacle surface point
    (:func:`~volspring.collision.obstacle_contacts`); on a :class:`StaticTriangleMesh` that query is
    exact but slow for nodes deep inside (a KD-tree over face centres, then exact distances): fine
    while contacts stay shallow, as the penalty keeps them.

    Parameters
    ----------
    system : MultiBodyModel or SpringModel
    obstacles : sequence of HalfSpace or StaticTriangleMesh
    nodes : (k,) int, optional -- the model nodes that can touch the obstacles; default all
    stiffness, stiffness_factor, damping_ratio, damping, friction, friction_velocity -- as for
        :class:`ContactForce`

    Examples
    --------
    >>> import numpy as np
    >>> from volspring import SpringModel
    >>> from volspring import HalfSpace
    >>> pair = SpringModel.from_arrays([[0, 0, -0.01], [1, 0, 0.5]], [1.0, 1.0], [[0, 1]], stiffness=100.0)
    >>> floor = ObstacleContactForce(pair, [HalfSpace((0, 0, 0), (0, 0, 1))], stiffness=1e4, damping=0.0)
    >>> forces = np.zeros((2, 3))
    >>> floor.accumulate(pair.rest_positions, np.zeros((2, 3)), 0.0, forces)
    >>> forces[:, 2].round(6).tolist()
    [100.0, 0.0]
    """

    def __init__(self, system, obstacles, *, nodes=None, stiffness=None, stiffness_factor=DEFAULT_STIFFNESS_FACTOR,
                 damping_ratio=None, damping=None, friction=0.0, friction_velocity=DEFAULT_FRICTION_VELOCITY):
        model, E, length = _node_properties(system)
        super().__init__(model, stiffness=stiffness, stiffness_factor=stiffness_factor, damping_ratio=damping_ratio,
                         damping=damping, friction=friction, friction_velocity=friction_velocity)
        self.obstacles = tuple(obstacles)
        for index, obstacle in enumerate(self.obstacles):
            if not isinstance(obstacle, (HalfSpace, StaticTriangleMesh)):
                raise TypeError(f"obstacles[{index}] must be a volspring.HalfSpace or StaticTriangleMesh, "
                                f"got {type(obstacle).__name__}")
        n = model.node_count
        self.nodes = np.arange(n) if nodes is None else np.unique(np.asarray(nodes, dtype=np.int64).ravel())
        if self.nodes.size and (self.nodes[0] < 0 or self.nodes[-1] >= n):
            raise ValueError(f"nodes lie in [{self.nodes[0]}, {self.nodes[-1]}], expected [0, {n - 1}]")
        self._node_modulus, self._node_length = 2.0 * E, length  # rigid obstacle: harmonic mean with inf

    @property
    def node_stiffness(self) -> np.ndarray:
        """(n,) float -- k_c [N/m] of each model node against an obstacle (the rule, or ``stiffness``)."""
        if self.stiffness is not None:
            return np.full(len(self._node_length), self.stiffness)
        return self.stiffness_factor * self._node_modulus * self._node_length

    def __repr__(self) -> str:
        return (f"ObstacleContactForce({len(self.obstacles)} obstacles, {len(self.nodes)} nodes, "
                f"friction={self.friction:g})")

    def _detect(self, x) -> PenaltyContacts:
        hits = obstacle_contacts(self.obstacles, x[self.nodes])
        vertex = self.nodes[hits.vertex]
        stiffness, damping = self._coefficients(self._node_modulus[vertex], self._node_length[vertex],
                                                self.model.masses[vertex])
        return PenaltyContacts(vertex[:, None], np.ones((hits.count, 1)), np.maximum(hits.depth, 0.0),
                               hits.direction, stiffness, damping, hits.obstacle)
