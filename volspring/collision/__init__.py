"""Collision geometry: who collides, how deep and in which direction, as pure functions of positions.

The data path reads one way::

    bodies = CollisionBodies(meshes)                      # static, once per scene
    contacts = detect_collisions(bodies, positions)       # vertex-in-tet pairs (Teschner et al. 2003)
    depths = consistent_penetration_depths(bodies, positions, contacts)   # Heidelberger et al. 2004
    obstacle = obstacle_contacts(obstacles, positions)    # volspring.HalfSpace and static triangle meshes

Thin bodies (cloth, strings, hair: nodes without tets) collide with a ``thickness``: against obstacles
(``ObstacleContactForce(..., thickness=)``), against tet bodies (:class:`ThinContactForce`) and a cloth
with itself (:class:`ClothSelfContactForce`); :mod:`volspring.collision.thin`.

and the response turns depths and directions into penalty forces::

    model = Model.from_bodies([Body(mesh, material, translation=...), ...])   # one model, many bodies
    scene = Scene(model, forces=[Gravity(), ContactForce(model), ObstacleContactForce(model, [floor])])

(``Body`` is :class:`volspring.bodies.Body`; the old ``Body``, ``assemble_bodies`` and
``MultiBodyModel`` of this package still work until volspring 0.3.0, with a DeprecationWarning.)
"""

from volspring.collision.bodies import CollisionBodies
from volspring.collision.contact import ContactForce, ObstacleContactForce, PenaltyContacts
from volspring.collision.obstacles import ObstacleContacts, StaticTriangleMesh, obstacle_contacts
from volspring.collision.penetration import (
    PenetrationDepths,
    closest_surface_depths,
    consistent_penetration_depths,
)
from volspring.collision.spatial_hash import SpatialHash, VertexTetContacts, detect_collisions
from volspring.collision.thin import ClothSelfContactForce, ThinContactForce

__all__ = [
    "ClothSelfContactForce",
    "CollisionBodies",
    "ContactForce",
    "ObstacleContactForce",
    "PenaltyContacts",
    "ObstacleContacts",
    "PenetrationDepths",
    "SpatialHash",
    "StaticTriangleMesh",
    "ThinContactForce",
    "VertexTetContacts",
    "closest_surface_depths",
    "consistent_penetration_depths",
    "detect_collisions",
    "obstacle_contacts",
]


def __getattr__(name):
    # Several bodies became one volspring.Model (Model.from_bodies); Body moved to volspring.bodies.
    from volspring._deprecation import deprecated_alias
    from volspring.bodies import Body
    from volspring.collision import multibody

    return deprecated_alias(__name__, name, {
        "Body": ("volspring.bodies.Body", Body),
        "assemble_bodies": ("volspring.Model.from_bodies", multibody.assemble_bodies),
        "MultiBodyModel": ("volspring.Model (from Model.from_bodies)", multibody.MultiBodyModel),
    })
