"""Several deformable bodies as one spring model: placement, initial motion and the collision numbering.

The data path::

    bodies = [Body(ball_mesh, rubber, translation=(0, 0, 0.3), velocity=(0, 0, -1)),
              Body(block_mesh, foam)]
    system = assemble_bodies(bodies)          # one SpringModel, one CollisionBodies
    scene = Scene(system.model, forces=[Gravity(system.model.masses), ContactForce(system)])
    state = scene.initial_state(v=system.initial_velocities)

Node numbering of the combined model: the mesh nodes of every body first, body after body, then
the shell nodes of every body, body after body. The mesh nodes therefore come first as
:class:`~volspring.topology.SpringTopology` requires, and the global node id of
:class:`~volspring.collision.CollisionBodies` (``node_offsets[b] + i``) *is* the model node index:
``collision_nodes`` is ``arange(N)``. It is kept as an explicit map so that the contact forces
would keep working with any other numbering. Shell nodes are springs-only: they carry mass and
stiffness but take no part in body-body collision (they are outside the tet meshes).

Each body is built with :meth:`SpringModel.from_mesh` from its own, unplaced mesh (masses and
spring constants do not change under a rigid motion), then its nodes are moved by
``x' = rotation @ x + translation``; rest lengths are measured on the placed nodes, so the
assembled body starts exactly at rest.
"""

from __future__ import annotations

from dataclasses import KW_ONLY, dataclass
from functools import cached_property

import numpy as np

from volspring.collision.bodies import CollisionBodies
from volspring.material import Material
from volspring.mesh import TetMesh
from volspring.model import SpringModel
from volspring.topology import SpringTopology

__all__ = ["Body", "MultiBodyModel", "assemble_bodies"]


def _vector(value, name, *, index) -> np.ndarray:
    vector = np.asarray(value, dtype=np.float64)
    if vector.shape != (3,) or not np.isfinite(vector).all():
        raise ValueError(f"bodies[{index}].{name} = {value!r}: expected 3 finite numbers")
    return vector


def _rotation_matrix(rotation, *, index) -> np.ndarray:
    if rotation is None:
        return np.eye(3)
    if hasattr(rotation, "as_matrix"):  # scipy.spatial.transform.Rotation
        rotation = rotation.as_matrix()
    matrix = np.asarray(rotation, dtype=np.float64)
    if matrix.shape != (3, 3) or not np.isfinite(matrix).all():
        raise ValueError(f"bodies[{index}].rotation has shape {matrix.shape}: expected a finite (3, 3) matrix")
    # A rotation matrix is orthonormal to round-off; 1e-9 leaves room for one stored in 10 digits.
    error = float(np.abs(matrix @ matrix.T - np.eye(3)).max())
    if error > 1e-9 or np.linalg.det(matrix) <= 0:
        raise ValueError(f"bodies[{index}].rotation is not a proper rotation (|R R^T - I| = {error:.3g}, "
                         f"det = {np.linalg.det(matrix):.6g}); expected an orthonormal matrix with det +1")
    return matrix


@dataclass(frozen=True, eq=False)
class Body:
    """One deformable body of a scene: shape, material, placement and initial motion.

    Parameters
    ----------
    body : TetMesh or SpringTopology -- the body in its own coordinates (a topology with shells)
    material : Material
    rule : {"van_gelder", "lloyd", "uniform"} -- stiffness rule (:meth:`SpringModel.from_mesh`)
    stiffness : float, optional -- the raw constant of ``rule="uniform"``
    damping_ratio : float, optional -- zeta per spring
    damping : float, optional -- k_d [N s/m] per spring, instead of ``damping_ratio``
    translation : (3,) float -- where the body's origin goes [m]
    rotation : (3, 3) float or scipy Rotation, optional -- applied about the body's origin first
    velocity : (3,) float -- initial velocity of the body's centre of mass [m/s]
    angular_velocity : (3,) float -- initial spin about the centre of mass [rad/s]
    name : str -- a label for messages and output
    """

    body: TetMesh | SpringTopology
    material: Material
    _: KW_ONLY
    rule: str = "van_gelder"
    stiffness: float | None = None
    damping_ratio: float | None = None
    damping: float | None = None
    translation: tuple = (0.0, 0.0, 0.0)
    rotation: object = None
    velocity: tuple = (0.0, 0.0, 0.0)
    angular_velocity: tuple = (0.0, 0.0, 0.0)
    name: str = ""

    @property
    def topology(self) -> SpringTopology:
        if isinstance(self.body, SpringTopology):
            return self.body
        if isinstance(self.body, TetMesh):
            return SpringTopology.from_mesh(self.body)
        raise TypeError(f"Body.body must be a TetMesh or SpringTopology, got {type(self.body).__name__}")


@dataclass(frozen=True, eq=False)
class MultiBodyModel:
    """Several bodies assembled into one spring model (see the module docstring for the numbering).

    Attributes
    ----------
    model : SpringModel -- all bodies; its topology's mesh is the union of the placed tet meshes
    collision_bodies : CollisionBodies -- the placed tet meshes, one body each
    collision_nodes : (N,) int64 -- model node of each collision global node id
    mesh_nodes : tuple of (n_b,) int64 -- model nodes of each body's mesh nodes, in mesh order
    shell_nodes : tuple of (s_b,) int64 -- model nodes of each body's shell nodes
    node_body : (n,) int64 -- body of every model node, shell nodes included
    initial_velocities : (n, 3) float -- the bodies' initial velocities at every node [m/s]
    youngs_modulus : (b,) float -- E of each body [Pa]
    edge_length : (b,) float -- mean rest tet-edge length of each body [m]
    bodies : tuple of Body -- what was assembled
    """

    model: SpringModel
    collision_bodies: CollisionBodies
    collision_nodes: np.ndarray
    mesh_nodes: tuple
    shell_nodes: tuple
    node_body: np.ndarray
    initial_velocities: np.ndarray
    youngs_modulus: np.ndarray
    edge_length: np.ndarray
    bodies: tuple

    @property
    def body_count(self) -> int:
        return len(self.bodies)

    def body_nodes(self, body: int) -> np.ndarray:
        """(n_b + s_b,) int64 -- every model node of one body: mesh nodes, then shell nodes."""
        return np.concatenate([self.mesh_nodes[body], self.shell_nodes[body]])

    @cached_property
    def body_masses(self) -> np.ndarray:
        """(b,) float -- mass of each body [kg]."""
        return np.bincount(self.node_body, weights=self.model.masses, minlength=self.body_count)

    def __repr__(self) -> str:
        return (f"MultiBodyModel({self.body_count} bodies, {self.model.node_count} nodes, "
                f"{self.collision_bodies.tet_count} tets, {self.model.spring_count} springs)")


def assemble_bodies(bodies) -> MultiBodyModel:
    """One spring model and one collision numbering from several placed bodies.

    Parameters
    ----------
    bodies : sequence of Body

    Returns
    -------
    MultiBodyModel -- pass ``initial_velocities`` to ``scene.initial_state(v=...)``

    Examples
    --------
    >>> import numpy as np
    >>> from volspring import Material, TetMesh
    >>> from volspring.collision.multibody import Body, assemble_bodies
    >>> tet = TetMesh(np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]), np.array([[0, 1, 2, 3]]))
    >>> rubber = Material(E=1e5, nu=0.3, density=1000.0)
    >>> system = assemble_bodies([Body(tet, rubber), Body(tet, rubber, translation=(2, 0, 0), velocity=(-1, 0, 0))])
    >>> system.model.node_count, system.mesh_nodes[1].tolist(), system.initial_velocities[4:, 0].tolist()
    (8, [4, 5, 6, 7], [-1.0, -1.0, -1.0, -1.0])
    """
    bodies = tuple(bodies)
    if not bodies:
        raise ValueError("assemble_bodies needs at least one Body, got none")
    parts = []
    for index, body in enumerate(bodies):  # a loop over bodies, not over nodes
        if not isinstance(body, Body):
            raise TypeError(f"bodies[{index}] must be a volspring.collision.Body, got {type(body).__name__}")
        topology = body.topology
        model = SpringModel.from_mesh(topology, body.material, rule=body.rule, stiffness=body.stiffness,
                                      damping_ratio=body.damping_ratio, damping=body.damping)
        rotation = _rotation_matrix(body.rotation, index=index)
        points = topology.points @ rotation.T + _vector(body.translation, "translation", index=index)
        centre = model.masses @ points / model.total_mass
        velocity = _vector(body.velocity, "velocity", index=index) + np.cross(
            _vector(body.angular_velocity, "angular_velocity", index=index), points - centre)
        parts.append((topology, model, points, velocity))

    mesh_counts = np.array([topology.mesh.node_count for topology, *_ in parts])
    shell_counts = np.array([topology.shell_node_count for topology, *_ in parts])
    mesh_offsets = np.concatenate([[0], np.cumsum(mesh_counts)])
    shell_offsets = mesh_offsets[-1] + np.concatenate([[0], np.cumsum(shell_counts)])
    node_count = int(shell_offsets[-1])

    # Local node i of body b -> model node (mesh nodes first, then shell nodes; both monotone).
    maps = [np.concatenate([mesh_offsets[b] + np.arange(mesh_counts[b]),
                            shell_offsets[b] + np.arange(shell_counts[b])]) for b in range(len(parts))]
    mesh_nodes = tuple(m[:count] for m, count in zip(maps, mesh_counts))
    shell_nodes = tuple(m[count:] for m, count in zip(maps, mesh_counts))

    def gather(values, width=None):
        shape = (node_count,) if width is None else (node_count, width)
        out = np.zeros(shape, dtype=np.asarray(values[0]).dtype)
        for node_map, value in zip(maps, values):
            out[node_map] = value
        return out

    points = gather([p for _, _, p, _ in parts], 3)
    velocities = gather([v for *_, v in parts], 3)
    masses = gather([model.masses for _, model, _, _ in parts])
    shell_layer = gather([topology.shell_layer for topology, *_ in parts])
    node_body = gather([np.full(len(m), b) for b, m in enumerate(maps)]).astype(np.int64)
    springs = np.concatenate([node_map[model.springs] for node_map, (_, model, _, _) in zip(maps, parts)])
    stiffness = np.concatenate([model.stiffness for _, model, _, _ in parts])
    damping = np.concatenate([model.damping for _, model, _, _ in parts])
    kinds = np.concatenate([model.kinds for _, model, _, _ in parts])
    triangles = np.concatenate([node_map[topology.shell_triangles] for node_map, (topology, *_) in zip(maps, parts)])

    placed = [TetMesh(p[: topology.mesh.node_count], topology.mesh.tets) for topology, _, p, _ in parts]
    combined_mesh = TetMesh(points[: mesh_offsets[-1]],
                            np.concatenate([m.tets + o for m, o in zip(placed, mesh_offsets)]))
    topology = SpringTopology(combined_mesh, points, springs, kinds, triangles, shell_layer,
                              max(t.shell_thickness for t, *_ in parts))
    materials = {body.material for body in bodies}
    rules = {body.rule for body in bodies}
    model = SpringModel(points, masses, topology.springs, stiffness, damping, topology.rest_lengths, kinds,
                        topology=topology, material=materials.pop() if len(materials) == 1 else None,
                        rule=rules.pop() if len(rules) == 1 else "mixed")
    collision_bodies = CollisionBodies(tuple(placed))
    frozen = [np.arange(collision_bodies.node_count, dtype=np.int64), node_body, velocities]
    for array in (*frozen, *mesh_nodes, *shell_nodes):
        array.setflags(write=False)
    return MultiBodyModel(
        model=model, collision_bodies=collision_bodies, collision_nodes=frozen[0], mesh_nodes=mesh_nodes,
        shell_nodes=shell_nodes, node_body=node_body, initial_velocities=velocities,
        youngs_modulus=np.array([body.material.E for body in bodies]),
        edge_length=np.array([m.edge_lengths.mean() for m in placed]), bodies=bodies)
