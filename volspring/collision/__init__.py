"""Collision geometry: who collides, how deep and in which direction, as pure functions of positions.

The data path reads one way::

    bodies = CollisionBodies(meshes)                      # static, once per scene
    contacts = detect_collisions(bodies, positions)       # vertex-in-tet pairs (Teschner et al. 2003)
    depths = consistent_penetration_depths(bodies, positions, contacts)   # Heidelberger et al. 2004
    obstacle = obstacle_contacts(obstacles, positions)    # volspring.HalfSpace and static triangle meshes

and the response turns depths and directions into penalty forces::

    system = assemble_bodies([Body(mesh, material, translation=...), ...])   # one model, many bodies
    scene = Scene(system.model, forces=[Gravity(...), ContactForce(system), ObstacleContactForce(system, [floor])])
"""

from volspring.collision.bodies import CollisionBodies
from volspring.collision.contact import ContactForce, ObstacleContactForce, PenaltyContacts
from volspring.collision.multibody import Body, MultiBodyModel, assemble_bodies
from volspring.collision.obstacles import ObstacleContacts, StaticTriangleMesh, obstacle_contacts
from volspring.collision.penetration import (
    PenetrationDepths,
    closest_surface_depths,
    consistent_penetration_depths,
)
from volspring.collision.spatial_hash import SpatialHash, VertexTetContacts, detect_collisions

__all__ = [
    "Body",
    "CollisionBodies",
    "ContactForce",
    "MultiBodyModel",
    "ObstacleContactForce",
    "PenaltyContacts",
    "ObstacleContacts",
    "PenetrationDepths",
    "SpatialHash",
    "StaticTriangleMesh",
    "VertexTetContacts",
    "assemble_bodies",
    "closest_surface_depths",
    "consistent_penetration_depths",
    "detect_collisions",
    "obstacle_contacts",
]
