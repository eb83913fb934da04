"""Penalty contact forces between deformable bodies and against static obstacles, with their Jacobians.

Both forces are scene forces (``accumulate``, ``jacobian``, ``potential_energy``; see
:mod:`volspring.scene`) and work with every integrator. Both take a :class:`~volspring.Model`, of
one body or many (:meth:`Model.from_bodies <volspring.Model.from_bodies>`): what they need per
body comes from the model, the tet mesh of each body from its topology split by ``node_body``
(:meth:`CollisionBodies.from_model`), E from ``materials[node_body]``.

Each force finds its contacts at the positions it is called with (between bodies: the spatial
hash of :func:`~volspring.collision.detect_collisions`, then penetration depths; against
obstacles: :func:`~volspring.collision.obstacle_contacts`) and hands them to the penalty response
of :mod:`volspring.collision.penalty`, where the contact stencil, the force law, the stiffness
rule and the Jacobian are written out.

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
"""

from __future__ import annotations

import logging

import numpy as np

from volspring.collision.bodies import CollisionBodies
from volspring.collision.multibody import MultiBodyModel
from volspring.collision.obstacles import HalfSpace, StaticTriangleMesh, obstacle_contacts
from volspring.collision.penalty import (
    DEFAULT_DAMPING_RATIO,
    DEFAULT_FRICTION_VELOCITY,
    DEFAULT_STIFFNESS_FACTOR,
    PenaltyContacts,
    _PenaltyResponse,
    _positive,
)
from volspring.collision.penetration import closest_surface_depths, consistent_penetration_depths
from volspring.collision.spatial_hash import detect_collisions
from volspring.collision.tet_tet import EdgeCrossingContacts, crossing_tet_pairs, edge_crossing_contacts
from volspring.model import Model
from meshing.topology import SPRING_KINDS
from typing import TYPE_CHECKING, Any
from collections.abc import Sequence

if TYPE_CHECKING:
    from numpy.typing import ArrayLike
    from volspring.collision.penetration import PenetrationDepths

__all__ = ["ContactForce", "ObstacleContactForce", "PenaltyContacts", "DEFAULT_STIFFNESS_FACTOR",
           "DEFAULT_DAMPING_RATIO", "DEFAULT_FRICTION_VELOCITY", "DEPTH_METHODS"]

logger = logging.getLogger(__name__)

DEPTH_METHODS = {"consistent": consistent_penetration_depths, "closest_surface": closest_surface_depths}


def _as_model(system) -> Model:
    """The Model; the deprecated ``assemble_bodies`` wrapper is unwrapped (until it goes in 0.3.0)."""
    if isinstance(system, MultiBodyModel):
        return system.model
    if isinstance(system, Model):
        return system
    raise TypeError(f"expected a volspring.Model (Model.from_bodies for several bodies), got {type(system).__name__}")


def _body_moduli(model) -> np.ndarray:
    """(b,) float -- E of each body [Pa]; NaN for a body without a material."""
    return np.array([np.nan if material is None else material.E for material in model.materials])


def _body_edge_lengths(model, bodies=None) -> np.ndarray:
    """(b,) float -- mean rest edge length of each body [m]: of its tet mesh; without one (a model from
    arrays, or built from element sets) of the springs that start in it (their tet-edge springs if
    any), or, for a model without springs (the ``"smoothed"`` rung), of the tet edges of its
    continuum element sets."""
    if model.topology is not None:
        # The tet bodies come first (CollisionBodies.from_model); bodies after them have no tet (a cloth or a
        # string joined by volspring.structures.combine) and take the rule below.
        meshed = (CollisionBodies.from_model(model) if bodies is None else bodies).mean_edge_lengths
        if len(meshed) == model.body_count:
            return meshed
        return np.concatenate([meshed, _spring_edge_lengths(model)[len(meshed):]])
    return _spring_edge_lengths(model)


def _spring_edge_lengths(model) -> np.ndarray:
    """(b,) float -- mean rest length of the springs that start in each body (see :func:`_body_edge_lengths`)."""
    if model.spring_count:
        edges = model.kinds == SPRING_KINDS.index("tet_edge")
        if not edges.any():
            edges = np.ones(model.spring_count, dtype=bool)
        pairs, lengths = model.springs[edges], model.rest_lengths[edges]
    else:
        pairs = _continuum_edges(model)
        lengths = np.linalg.norm(np.diff(model.rest_positions[pairs], axis=1)[:, 0], axis=1)
    spring_body = model.node_body[pairs[:, 0]]
    count = np.bincount(spring_body, minlength=model.body_count)
    total = np.bincount(spring_body, weights=lengths, minlength=model.body_count)
    overall = lengths.mean() if len(lengths) else np.nan
    return np.where(count > 0, total / np.maximum(count, 1), overall)


def _continuum_edges(model) -> np.ndarray:
    """(E, 2) int -- the unique tet edges of a model's continuum element sets (the tets they are built on)."""
    from meshing.mesh import TET_EDGES

    tets = [element_set.kinematics.tets for element_set in model.elements if hasattr(element_set, "kinematics")]
    if not tets:
        return np.zeros((0, 2), dtype=np.int64)
    pairs = np.concatenate(tets)[:, np.asarray(TET_EDGES)].reshape(-1, 2)
    return np.unique(np.sort(pairs, axis=1), axis=0)


class ContactForce(_PenaltyResponse):
    """Penalty contact between deformable bodies: detection, consistent depths, penalty, damping, friction.

    Parameters
    ----------
    model : Model
        the bodies (:meth:`Model.from_bodies <volspring.Model.from_bodies>`); a model built from one mesh is one body
        (useful with ``self_collision=True``). The deprecated ``MultiBodyModel`` of ``assemble_bodies`` is taken for its
        ``.model``.
    stiffness : float, optional
        k_c [N/m] for every contact, instead of the material rule
    stiffness_factor : float
        alpha of ``k_c = alpha E_eff l`` (:mod:`volspring.collision.penalty`)
    damping_ratio : float, optional
        zeta of ``c_n = 2 zeta sqrt(k_c m)``; default 0.5
    damping : float, optional
        c_n [N s/m] for every contact, instead of ``damping_ratio``
    friction : float
        Coulomb coefficient mu [-], 0 for frictionless contact
    friction_velocity : float
        regularisation eps [m/s] of the friction
    self_collision : bool
        also collide each body with itself
    method : {"consistent", "closest_surface"}
        penetration depths (Heidelberger et al. 2004, or the naive nearest surface point, kept for comparison)
    cell_size : float, optional
        hash cell [m]; default the mean rest edge length
    edges : bool
        also push apart bodies that cross with no vertex inside the other (two thin slabs crossing like an X):
        intersecting tet pairs from :func:`~volspring.collision.tet_tet.crossing_tet_pairs`, then a contact per boundary
        edge through a boundary face (:func:`~volspring.collision.tet_tet.edge_crossing_contacts`), with the same force
        law and Jacobian. Off by default: it costs 2.5x the vertex detection at 8,748 tets and 8x at 768
        (``benchmarks/bench_collision.py`` prints the ratio)

    Examples
    --------
    >>> import numpy as np
    >>> from volspring import Material, Model, TetMesh
    >>> from volspring.bodies import Body
    >>> tet = TetMesh(np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]), np.array([[0, 1, 2, 3]]))
    >>> rubber = Material(E=1e5, nu=0.3, density=1000.0)
    >>> model = Model.from_bodies([Body(tet, rubber), Body(tet, rubber, translation=(0.1, 0.12, 0.14))])
    >>> contact = ContactForce(model)
    >>> forces = np.zeros((8, 3))
    >>> contact.accumulate(model, model.rest_positions, np.zeros((8, 3)), 0.0, forces)
    >>> contact.contacts(model.rest_positions).vertex.tolist()  # body 1's corner inside body 0
    [4]
    >>> bool(abs(forces.sum(axis=0)).max() < 1e-15 * abs(forces).max())  # momentum: forces sum to round-off
    True
    """

    def __init__(self, model: Model, *, stiffness: float | None = None,
                 stiffness_factor: float = DEFAULT_STIFFNESS_FACTOR, damping_ratio: float | None = None,
                 damping: float | None = None, friction: float = 0.0,
                 friction_velocity: float = DEFAULT_FRICTION_VELOCITY, self_collision: bool = False,
                 method: str = "consistent", cell_size: float | None = None, edges: bool = False):
        model = _as_model(model)
        super().__init__(model, stiffness=stiffness, stiffness_factor=stiffness_factor, damping_ratio=damping_ratio,
                         damping=damping, friction=friction, friction_velocity=friction_velocity)
        if method not in DEPTH_METHODS:
            raise ValueError(f"unknown depth method {method!r}; known: {', '.join(DEPTH_METHODS)}")
        self.bodies = CollisionBodies.from_model(model)
        self.collision_nodes = self.bodies.model_nodes
        E, length = _body_moduli(model), _body_edge_lengths(model, self.bodies)
        # Per (vertex body, penetrated body): k_c = alpha E_eff l_vertex-body (volspring.collision.penalty).
        self._pair_modulus = 2.0 * E[:, None] * E[None, :] / (E[:, None] + E[None, :])
        self._body_length = length
        self.self_collision = bool(self_collision)
        self.method = method
        self.cell_size = None if cell_size is None else _positive(cell_size, "cell_size")
        self.edges = bool(edges)

    @property
    def pair_stiffness(self) -> np.ndarray:
        """(b, b) float -- k_c [N/m] of a vertex of body i inside body j (the rule, or ``stiffness``)."""
        if self.stiffness is not None:
            return np.full(self._pair_modulus.shape, self.stiffness)
        return self.stiffness_factor * self._pair_modulus * self._body_length[:, None]

    def __repr__(self) -> str:
        return (f"ContactForce({self.bodies.body_count} bodies, method={self.method!r}, friction={self.friction:g}, "
                f"self_collision={self.self_collision}, edges={self.edges})")

    def penetration_depths(self, x: np.ndarray) -> PenetrationDepths:
        """The :class:`~volspring.collision.PenetrationDepths` at model positions ``x`` (collision ids)."""
        return self._vertex_contacts(x)[1]

    def _vertex_contacts(self, x):
        positions = np.asarray(x, dtype=np.float64)[self.collision_nodes]
        hits = detect_collisions(self.bodies, positions, cell_size=self.cell_size, self_collision=self.self_collision)
        depth_method = DEPTH_METHODS[self.method]
        options = {} if self.method == "closest_surface" else {"cell_size": self.cell_size}
        return hits, depth_method(self.bodies, positions, hits, **options)

    def edge_crossings(self, x: np.ndarray, hits: Any = None) -> EdgeCrossingContacts:
        """The :class:`~volspring.collision.tet_tet.EdgeCrossingContacts` at model positions ``x`` (collision ids)."""
        positions = np.asarray(x, dtype=np.float64)[self.collision_nodes]
        # Only pairs that can hold a boundary edge of one tet through a boundary face of the other (the same contacts).
        pairs = crossing_tet_pairs(self.bodies, positions, cell_size=self.cell_size, self_collision=self.self_collision,
                                   boundary=True)
        return edge_crossing_contacts(self.bodies, positions, pairs, colliding=hits)

    def _detect(self, x) -> PenaltyContacts:
        hits, depths = self._vertex_contacts(x)
        # Stencils of five nodes: the vertex (or the edge's end behind a face), then the nodes of the reaction.
        vertex, reaction = depths.vertex, self.bodies.tets[depths.tet]
        weights, depth, direction = depths.barycentric, depths.depth, depths.direction
        vertex_body, other_body = depths.vertex_body, depths.other_body
        if self.edges:
            edge = self.edge_crossings(x, hits)
            # The face's three nodes, the last repeated with weight 0 to fill the five-node stencil.
            vertex = np.concatenate([vertex, edge.vertex])
            reaction = np.concatenate([reaction, edge.face[:, [0, 1, 2, 2]]])
            weights = np.concatenate([weights, np.pad(edge.barycentric, ((0, 0), (0, 1)))])
            depth, direction = np.concatenate([depth, edge.depth]), np.concatenate([direction, edge.direction])
            vertex_body = np.concatenate([vertex_body, edge.vertex_body])
            other_body = np.concatenate([other_body, edge.face_body])
            if edge.count:
                logger.debug("%d edge-face crossings, deepest %.3g m", edge.count, edge.depth.max())
        nodes = self.collision_nodes[np.concatenate([vertex[:, None], reaction], axis=1)]
        masses = self.model.masses
        vertex_mass = masses[nodes[:, 0]]
        tet_mass = np.einsum("ck,ck->c", weights, masses[nodes[:, 1:]])
        stiffness, damping = self._coefficients(
            self._pair_modulus[vertex_body, other_body], self._body_length[vertex_body],
            vertex_mass * tet_mass / (vertex_mass + tet_mass))
        if depths.count:
            logger.debug("%d contacts, deepest %.3g m", depths.count, depths.depth.max())
        weights = np.concatenate([np.ones((len(vertex), 1)), -weights], axis=1)
        return PenaltyContacts(nodes, weights, np.maximum(depth, 0.0), direction, stiffness, damping, other_body)


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
    model : Model
        one body or many (E and the edge length of each node's body)
    obstacles : sequence of HalfSpace or StaticTriangleMesh
    nodes : (k,) int, optional
        the model nodes that can touch the obstacles; default all
    thickness : float
        contact layer over the obstacles' surfaces [m], >= 0: a node closer than this to a surface is in contact, with
        depth ``thickness - distance`` (the half-thickness of a cloth, the radius of a string or a hair, whose nodes
        have no volume of their own); 0 (default): contact only inside
    stiffness, stiffness_factor, damping_ratio, damping, friction, friction_velocity
        as for :class:`ContactForce`; a model without a material (a cloth, a string: built from arrays) needs
        ``stiffness``

    Examples
    --------
    >>> import numpy as np
    >>> from volspring import Model
    >>> from volspring import HalfSpace
    >>> pair = Model.from_arrays([[0, 0, -0.01], [1, 0, 0.5]], [1.0, 1.0], [[0, 1]], stiffness=100.0)
    >>> floor = ObstacleContactForce(pair, [HalfSpace((0, 0, 0), (0, 0, 1))], stiffness=1e4, damping=0.0)
    >>> forces = np.zeros((2, 3))
    >>> floor.accumulate(pair, pair.rest_positions, np.zeros((2, 3)), 0.0, forces)
    >>> forces[:, 2].round(6).tolist()
    [100.0, 0.0]
    """

    def __init__(self, model: Model, obstacles: Sequence[HalfSpace | StaticTriangleMesh], *,
                 nodes: ArrayLike | None = None, thickness: float = 0.0, stiffness: float | None = None,
                 stiffness_factor: float = DEFAULT_STIFFNESS_FACTOR, damping_ratio: float | None = None,
                 damping: float | None = None, friction: float = 0.0,
                 friction_velocity: float = DEFAULT_FRICTION_VELOCITY):
        model = _as_model(model)
        self.thickness = _positive(thickness, "thickness", allow_zero=True)
        E, length = _body_moduli(model)[model.node_body], _body_edge_lengths(model)[model.node_body]
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
                f"thickness={self.thickness:g}, friction={self.friction:g})")

    def _detect(self, x) -> PenaltyContacts:
        hits = obstacle_contacts(self.obstacles, x[self.nodes], thickness=self.thickness)
        vertex = self.nodes[hits.vertex]
        stiffness, damping = self._coefficients(self._node_modulus[vertex], self._node_length[vertex],
                                                self.model.masses[vertex])
        return PenaltyContacts(vertex[:, None], np.ones((hits.count, 1)), np.maximum(hits.depth, 0.0),
                               hits.direction, stiffness, damping, hits.obstacle)
