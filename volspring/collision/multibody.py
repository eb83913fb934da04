"""Deprecated (goes in volspring 0.3.0): several bodies are one :class:`~volspring.Model` now.

Old code::

    system = assemble_bodies([Body(block_mesh, foam), Body(ball_mesh, rubber, velocity=(0, 0, -1))])
    scene = Scene(system.model, forces=[Gravity(), ContactForce(system)])
    state = scene.initial_state(v=system.initial_velocities)

New code (:mod:`volspring.bodies`)::

    bodies = [Body(block_mesh, foam), Body(ball_mesh, rubber, velocity=(0, 0, -1))]
    model = Model.from_bodies(bodies)
    scene = Scene(model, forces=[Gravity(), ContactForce(model)])
    state = scene.initial_state(v=initial_velocities(bodies, model))

:func:`assemble_bodies` still works, with a DeprecationWarning: it returns a :class:`MultiBodyModel`
that wraps the new model, every attribute derived from it. The contact forces take either.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from volspring._deprecation import deprecated_alias, warn_deprecated
from volspring.bodies import Body as _Body  # not a module global: the old name warns (__getattr__)
from volspring.bodies import initial_velocities
from volspring.collision.bodies import CollisionBodies
from volspring.model import Model
from collections.abc import Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from volspring.bodies import Body

__all__ = ["MultiBodyModel", "assemble_bodies"]


@dataclass(frozen=True, eq=False)
class MultiBodyModel:
    """Deprecated: the bodies of :func:`assemble_bodies`, around one :class:`~volspring.Model`.

    Attributes
    ----------
    model : Model
        all bodies (``Model.from_bodies``): everything below is derived from it
    collision_bodies : CollisionBodies
        the placed tet meshes, one body each
    collision_nodes : (N,) int64
        model node of each collision global node id
    mesh_nodes : tuple of (n_b,) int64
        model nodes of each body's mesh nodes, in mesh order
    shell_nodes : tuple of (s_b,) int64
        model nodes of each body's shell nodes
    node_body : (n,) int64
        body of every model node, shell nodes included
    initial_velocities : (n, 3) float
        the bodies' initial velocities at every node [m/s]
    youngs_modulus : (b,) float
        E of each body [Pa]
    edge_length : (b,) float
        mean rest tet-edge length of each body [m]
    bodies : tuple of Body
        what was assembled
    """

    model: Model
    collision_bodies: CollisionBodies
    collision_nodes: np.ndarray
    mesh_nodes: tuple
    shell_nodes: tuple
    node_body: np.ndarray
    initial_velocities: np.ndarray
    youngs_modulus: np.ndarray
    edge_length: np.ndarray
    bodies: tuple

    @classmethod
    def wrap(cls, model: Model, bodies: Sequence[Body]) -> "MultiBodyModel":
        """The old view of a model built by ``Model.from_bodies(bodies)``."""
        bodies = tuple(bodies)
        collision_bodies = CollisionBodies.from_model(model)
        assert model.topology is not None  # from_model refuses a model without a tet mesh
        mesh_count = model.topology.mesh.node_count
        nodes = [model.body_nodes(b) for b in range(model.body_count)]
        velocities = initial_velocities(bodies, model)
        velocities.setflags(write=False)
        return cls(model=model, collision_bodies=collision_bodies, collision_nodes=collision_bodies.model_nodes,
                   mesh_nodes=tuple(_frozen(n[n < mesh_count]) for n in nodes),
                   shell_nodes=tuple(_frozen(n[n >= mesh_count]) for n in nodes), node_body=model.node_body,
                   initial_velocities=velocities,
                   youngs_modulus=np.array([body.material.E for body in bodies]),
                   edge_length=collision_bodies.mean_edge_lengths, bodies=bodies)

    @property
    def body_count(self) -> int:
        return len(self.bodies)

    def body_nodes(self, body: int) -> np.ndarray:
        """(n_b + s_b,) int64 -- every model node of one body: mesh nodes, then shell nodes."""
        return np.concatenate([self.mesh_nodes[body], self.shell_nodes[body]])

    @cached_property
    def body_masses(self) -> np.ndarray:
        """(b,) float -- mass of each body [kg]."""
        return self.model.body_masses

    def __repr__(self) -> str:
        return (f"MultiBodyModel({self.body_count} bodies, {self.model.node_count} nodes, "
                f"{self.collision_bodies.tet_count} tets, {self.model.spring_count} springs)")


def assemble_bodies(bodies: Sequence[Body]) -> MultiBodyModel:
    """Deprecated: use ``Model.from_bodies(bodies)`` and ``volspring.bodies.initial_velocities(bodies, model)``.

    Parameters
    ----------
    bodies : sequence of Body

    Returns
    -------
    MultiBodyModel
        wrapping ``Model.from_bodies(bodies)``
    """
    warn_deprecated(f"{__name__}.assemble_bodies",
                    "volspring.Model.from_bodies(bodies) (initial velocities: volspring.bodies.initial_velocities)")
    bodies = tuple(bodies)
    return MultiBodyModel.wrap(Model.from_bodies(bodies), bodies)


def _frozen(array: np.ndarray) -> np.ndarray:
    array.setflags(write=False)
    return array


def __getattr__(name):
    # Body moved to volspring.bodies when several bodies became one Model.
    return deprecated_alias(__name__, name, {"Body": ("volspring.bodies.Body", _Body)})
