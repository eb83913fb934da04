"""Several bodies in one model: placement, the body id of every node, the material of every body.

A :class:`~volspring.Model` holds one body or many: besides rest positions, masses and element
sets it has ``node_body`` (the body of every node), ``materials`` (one per body) and
``body_names``. A model built from one mesh or from arrays is one body (``node_body`` all 0).
Several placed bodies give one model through :meth:`Model.from_bodies
<volspring.Model.from_bodies>`, whose work is done here::

    bodies = [Body(block_mesh, foam), Body(ball_mesh, rubber, translation=(0, 0, 0.3), velocity=(0, 0, -1))]
    model = Model.from_bodies(bodies)                               # one Model, node_body 0 and 1
    scene = Scene(model, forces=[Gravity(), ContactForce(model)])   # contact splits the bodies by node_body
    state = scene.initial_state(v=initial_velocities(bodies, model))

Node numbering of the assembled model: the mesh nodes of every body first, body after body, then
the shell nodes of every body, body after body. The mesh nodes therefore come first as
:class:`~meshing.topology.SpringTopology` requires, and the topology's mesh is the union of the
placed tet meshes. Shell nodes belong to their body (``node_body``) but lie outside its tet mesh.

Each body is built with :meth:`Model.from_mesh <volspring.Model.from_mesh>` from its own, unplaced
mesh (masses and spring constants do not change under a rigid motion), then its nodes are moved
by ``x' = rotation @ x + translation``; rest lengths are measured on the placed nodes, so the
assembled model starts exactly at rest. Initial velocities are initial conditions, not part of the
static model: :func:`initial_velocities` turns each body's ``velocity`` and ``angular_velocity``
into an ``(n, 3)`` array for ``scene.initial_state(v=...)``.

Examples
--------
>>> import numpy as np
>>> from meshing import TetMesh
>>> from volspring import Material, Model
>>> from volspring.bodies import Body, initial_velocities
>>> tet = TetMesh(np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]), np.array([[0, 1, 2, 3]]))
>>> rubber, foam = Material(E=1e5, nu=0.3, density=1000.0), Material(E=2e4, nu=0.3, density=50.0)
>>> bodies = [Body(tet, rubber, name="left"), Body(tet, foam, translation=(2, 0, 0), velocity=(-1, 0, 0))]
>>> model = Model.from_bodies(bodies)
>>> model.node_count, model.body_count, model.node_body.tolist(), model.material is None
(8, 2, [0, 0, 0, 0, 1, 1, 1, 1], True)
>>> [material.E for material in model.materials], model.body_names
([100000.0, 20000.0], ('left', ''))
>>> initial_velocities(bodies, model)[:, 0].tolist()
[0.0, 0.0, 0.0, 0.0, -1.0, -1.0, -1.0, -1.0]
"""

from __future__ import annotations

from dataclasses import KW_ONLY, dataclass

import numpy as np

from meshing.mesh import TetMesh
from meshing.tolerances import ORTHONORMAL
from meshing.topology import SpringTopology
from volspring.elements import Springs
from volspring.material import Material, _shown
from collections.abc import Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from volspring.model import Model

__all__ = ["Body", "initial_velocities"]


@dataclass(frozen=True, eq=False)
class Body:
    """One deformable body of a scene: shape, material, placement and initial motion.

    Parameters
    ----------
    body : TetMesh or SpringTopology
        The body in its own coordinates (a topology with shells).
    material : Material
    model : {"springs", "springs+volume", "smoothed"}
        The body's rung of the ladder (:mod:`volspring.ladder`); bodies of one scene may differ.
    alpha : float, optional
        The smoothed rung's weight (:meth:`Model.from_mesh <volspring.Model.from_mesh>`).
    rule : {"van_gelder", "lloyd", "uniform"}
        Stiffness rule (:meth:`Model.from_mesh <volspring.Model.from_mesh>`).
    stiffness : float, optional
        The raw constant of ``rule="uniform"``.
    damping_ratio : float, optional
        zeta per spring.
    damping : float, optional
        k_d [N s/m] per spring, instead of ``damping_ratio``.
    translation : (3,) float
        Where the body's origin goes [m].
    rotation : (3, 3) float or scipy Rotation, optional
        Applied about the body's origin first.
    velocity : (3,) float
        Initial velocity of the body's centre of mass [m/s] (see :func:`initial_velocities`).
    angular_velocity : (3,) float
        Initial spin about the centre of mass [rad/s].
    name : str
        A label for messages and output (``Model.body_names``).
    """

    body: TetMesh | SpringTopology
    material: Material
    _: KW_ONLY
    model: str = "springs"
    alpha: float | None = None
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


# ---------------------------------------------------------------------- the body fields of a Model
def checked_body_fields(node_body, materials, body_names, material, node_count):
    """The body fields of a :class:`~volspring.Model`, checked, with their defaults filled in.

    Parameters
    ----------
    node_body : (n,) int or None
        body id of every node; None: all 0
    materials : sequence of Material or None, or None
        one per body; None: ``material`` for every body
    body_names : sequence of str or None
        one per body; None: all ""
    material : Material or None
        the model's single material
    node_count : int
        n

    Returns
    -------
    node_body : (n,) int64, read-only
    materials : tuple, one per body
    body_names : tuple of str, one per body
    material : Material or None
        the materials' common value, None when they differ

    Raises
    ------
    TypeError
        Body ids that are not integers, materials that are not Material or None, names that are not str.
    ValueError
        ``node_body`` of the wrong length, a negative id, an id past the materials, a body with no
        node, ``materials`` or ``body_names`` of the wrong length, ``material`` not the materials'
        common value; each naming the value.
    """
    if node_body is None:
        ids = np.zeros(node_count, dtype=np.int64)
    else:
        ids = np.asarray(node_body)
        if ids.dtype == bool or not np.issubdtype(ids.dtype, np.integer):
            raise TypeError(f"node_body has dtype {ids.dtype}; expected integer body ids")
        if ids.shape != (node_count,):
            raise ValueError(f"len(rest_positions) = {node_count}, but node_body has shape {ids.shape}; "
                             "expected one body id per node")
        ids = ids.astype(np.int64)  # a copy: the caller's array is not frozen
        if (ids < 0).any():
            node = int(np.flatnonzero(ids < 0)[0])
            raise ValueError(f"node_body[{node}] = {ids[node]} is not a body id >= 0")
    if isinstance(materials, Material):
        raise TypeError("materials is a single Material; expected one per body, e.g. materials=(rubber,)")
    if materials is None:
        body_count = int(ids.max()) + 1
        materials = (material,) * body_count
        source = "node_body"
    else:
        materials = tuple(materials)
        body_count = len(materials)
        if body_count == 0:
            raise ValueError("materials is empty; expected one Material (or None) per body")
        if ids.max() >= body_count:
            node = int(np.flatnonzero(ids >= body_count)[0])
            raise ValueError(f"node_body[{node}] = {ids[node]} is not a body id in [0, {body_count - 1}]: "
                             f"len(materials) = {body_count}, one material per body")
        source = "len(materials)"
    counts = np.bincount(ids, minlength=body_count)
    if (counts == 0).any():
        empty = np.flatnonzero(counts == 0)
        raise ValueError(f"body {empty[0]} has no node: node_body holds ids {np.flatnonzero(counts).tolist()}, "
                         f"but {source} gives {body_count} bodies ({len(empty)} without a node); "
                         f"expected every body id in [0, {body_count - 1}] on some node")
    for index, value in enumerate(materials):
        if value is not None and not isinstance(value, Material):
            raise TypeError(f"materials[{index}] = {_shown(value)} is not a volspring Material or None")
    common = materials[0] if all(value == materials[0] for value in materials) else None
    if material is not None and material != common:
        raise ValueError(f"material = {material!r}, but the bodies' materials differ from it "
                         f"(materials = {materials!r}); give material=None when bodies differ")
    names = ("",) * body_count if body_names is None else tuple(body_names)
    if len(names) != body_count:
        raise ValueError(f"len(body_names) = {len(names)}, but the model has {body_count} bodies")
    for index, name in enumerate(names):
        if not isinstance(name, str):
            raise TypeError(f"body_names[{index}] = {_shown(name)} is not a str")
    ids.setflags(write=False)
    return ids, materials, names, common


# ---------------------------------------------------------------------- placement and assembly
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
    # A rotation matrix is orthonormal to round-off; ORTHONORMAL (1e-9) admits one stored in 10 digits.
    error = float(np.abs(matrix @ matrix.T - np.eye(3)).max())
    if error > ORTHONORMAL or np.linalg.det(matrix) <= 0:
        raise ValueError(f"bodies[{index}].rotation is not a proper rotation (|R R^T - I| = {error:.3g}, "
                         f"det = {np.linalg.det(matrix):.6g}); expected an orthonormal matrix with det +1")
    return matrix


def _checked_bodies(bodies) -> tuple:
    bodies = tuple(bodies)
    if not bodies:
        raise ValueError("Model.from_bodies needs at least one Body, got none")
    for index, body in enumerate(bodies):
        if not isinstance(body, Body):
            raise TypeError(f"bodies[{index}] must be a volspring.bodies.Body, got {type(body).__name__}")
    return bodies


def assemble(model_class, bodies):
    """One model from several placed bodies: the work of :meth:`Model.from_bodies <volspring.Model.from_bodies>`.

    Parameters
    ----------
    model_class : type
        :class:`~volspring.Model` (or a subclass)
    bodies : sequence of Body

    Returns
    -------
    Model
        node numbering in the module docstring; ``rule`` and ``rung`` the bodies' common rule and rung, or "mixed"; one
        spring set for all springs, and each body's continuum sets placed (kept per body: each has its own Rayleigh
        damping time)
    """
    bodies = _checked_bodies(bodies)
    parts = []
    for index, body in enumerate(bodies):  # a loop over bodies, not over nodes
        topology = body.topology
        single = model_class.from_mesh(topology, body.material, model=body.model, alpha=body.alpha, rule=body.rule,
                                       stiffness=body.stiffness, damping_ratio=body.damping_ratio, damping=body.damping)
        rotation = _rotation_matrix(body.rotation, index=index)
        points = topology.points @ rotation.T + _vector(body.translation, "translation", index=index)
        for name in ("velocity", "angular_velocity"):  # refused now rather than when the run starts
            _vector(getattr(body, name), name, index=index)
        parts.append((topology, single, points))

    mesh_counts = np.array([topology.mesh.node_count for topology, _, _ in parts])
    shell_counts = np.array([topology.shell_node_count for topology, _, _ in parts])
    mesh_offsets = np.concatenate([[0], np.cumsum(mesh_counts)])
    shell_offsets = mesh_offsets[-1] + np.concatenate([[0], np.cumsum(shell_counts)])
    node_count = int(shell_offsets[-1])
    # Local node i of body b -> model node (mesh nodes first, then shell nodes; both monotone).
    maps = [np.concatenate([mesh_offsets[b] + np.arange(mesh_counts[b]),
                            shell_offsets[b] + np.arange(shell_counts[b])]) for b in range(len(parts))]

    def gather(values, width=None):
        shape = (node_count,) if width is None else (node_count, width)
        out = np.zeros(shape, dtype=np.asarray(values[0]).dtype)
        for node_map, value in zip(maps, values):
            out[node_map] = value
        return out

    points = gather([p for _, _, p in parts], 3)
    masses = gather([single.masses for _, single, _ in parts])
    shell_layer = gather([topology.shell_layer for topology, _, _ in parts])
    node_body = gather([np.full(len(m), b, dtype=np.int64) for b, m in enumerate(maps)])
    springs = np.concatenate([node_map[single.springs] for node_map, (_, single, _) in zip(maps, parts)])
    kinds = np.concatenate([single.kinds for _, single, _ in parts])
    triangles = np.concatenate([node_map[topology.shell_triangles] for node_map, (topology, _, _) in zip(maps, parts)])
    mesh = TetMesh(points[: mesh_offsets[-1]],
                   np.concatenate([topology.mesh.tets + offset for (topology, _, _), offset in zip(parts, mesh_offsets)]))
    topology = SpringTopology(mesh, points, springs, kinds, triangles, shell_layer,
                              max(topology.shell_thickness for topology, _, _ in parts))
    spring_set = Springs(node_count, topology.springs, np.concatenate([single.stiffness for _, single, _ in parts]),
                         np.concatenate([single.damping for _, single, _ in parts]), topology.rest_lengths, kinds)
    continuum = [element_set.placed(points, node_map) for node_map, (_, single, _) in zip(maps, parts)
                 for element_set in single.elements if not isinstance(element_set, Springs)]
    elements = ((spring_set,) if spring_set.spring_count or not continuum else ()) + tuple(continuum)
    rules = {single.rule for _, single, _ in parts}
    rungs = {single.rung for _, single, _ in parts}
    return model_class(points, masses, elements, topology=topology, rule=rules.pop() if len(rules) == 1 else "mixed",
                       node_body=node_body, materials=tuple(body.material for body in bodies),
                       body_names=tuple(body.name for body in bodies),
                       rung=rungs.pop() if len(rungs) == 1 else "mixed")


# ---------------------------------------------------------------------- initial conditions
def initial_velocities(bodies: Sequence[Body], model: Model) -> np.ndarray:
    """(n, 3) float -- the bodies' initial velocities at every node of their model [m/s].

    Node i of body b moves with ``velocity_b + angular_velocity_b x (x_i - c_b)``, c_b the body's
    centre of mass at rest, so body b has linear momentum ``M_b velocity_b`` and spins about c_b.

    Parameters
    ----------
    bodies : sequence of Body
        those the model was built from (:meth:`Model.from_bodies <volspring.Model.from_bodies>`), in the same order
    model : Model
        gives the nodes of each body (``node_body``), their masses and rest positions

    Returns
    -------
    (n, 3) float
        for ``scene.initial_state(v=...)`` [m/s]

    Raises
    ------
    ValueError
        When ``len(bodies)`` is not the model's body count, or a velocity is not 3 finite numbers.
    """
    bodies = _checked_bodies(bodies)
    if len(bodies) != model.body_count:
        raise ValueError(f"len(bodies) = {len(bodies)}, but the model has {model.body_count} bodies; "
                         "expected the bodies it was built from")
    x, masses = model.rest_positions, model.masses
    velocities = np.zeros_like(x)
    for index, body in enumerate(bodies):  # a loop over bodies, not over nodes
        nodes = model.body_nodes(index)
        centre = masses[nodes] @ x[nodes] / masses[nodes].sum()
        velocities[nodes] = _vector(body.velocity, "velocity", index=index) + np.cross(
            _vector(body.angular_velocity, "angular_velocity", index=index), x[nodes] - centre)
    return velocities
