"""Collision geometry: who collides, how deep and in which direction, as pure functions of positions.

The data path reads one way::

    bodies = CollisionBodies(meshes)                      # static, once per scene
    contacts = detect_collisions(bodies, positions)       # vertex-in-tet pairs (Teschner et al. 2003)
    depths = consistent_penetration_depths(bodies, positions, contacts)   # Heidelberger et al. 2004
    obstacle = obstacle_contacts(obstacles, positions)    # half-spaces and static triangle meshes

Nothing here applies a force: the response turns depths and directions into penalty forces.
"""

from volspring.collision.bodies import CollisionBodies
from volspring.collision.obstacles import HalfSpace, ObstacleContacts, StaticTriangleMesh, obstacle_contacts
from volspring.collision.penetration import (
    PenetrationDepths,
    closest_surface_depths,
    consistent_penetration_depths,
)
from volspring.collision.spatial_hash import SpatialHash, VertexTetContacts, detect_collisions

__all__ = [
    "CollisionBodies",
    "HalfSpace",
    "ObstacleContacts",
    "PenetrationDepths",
    "SpatialHash",
    "StaticTriangleMesh",
    "VertexTetContacts",
    "closest_surface_depths",
    "consistent_penetration_depths",
    "detect_collisions",
    "obstacle_contacts",
]
