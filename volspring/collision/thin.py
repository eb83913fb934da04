"""Contact of thin bodies (cloth, strings, hair: nodes without a volume) with tet bodies and with themselves.

A thin body's nodes carry no tet, so they cannot be found inside another body by the other body's
tets alone, nor can anything be found inside them. They are given a ``thickness`` instead (the
half-thickness of a cloth, the radius of a string): a node is in contact with a surface when it is
closer than ``thickness`` to it, or behind it. Two forces, both on the penalty response of
:mod:`volspring.collision.penalty` (force law, damping, friction, Jacobian):

:class:`ThinContactForce` -- the nodes of the thin bodies against the tet bodies of the same model
(a cloth or a string joined to ``Model.from_bodies([...])`` by :func:`volspring.structures.combine`).
For each thin node and tet body:

1. inside: the node is in a tet of the body (the spatial hash of
   :mod:`volspring.collision.spatial_hash`, thin nodes hashed, tet boxes queried, the barycentric test);
   its depth is ``thickness + distance`` to the nearest point of the body's boundary surface, its
   direction towards that point;
2. outside: the boundary triangles' boxes, grown by ``thickness``, are hashed and queried by the
   nodes; the nearest triangle closer than ``thickness`` gives depth ``thickness - distance`` and the
   direction away from the nearest point.

Either way the contact's stencil is the node and the three corners of the nearest boundary triangle,
weighted by the nearest point's barycentric coordinates ``b``: ``(p, f0, f1, f2)`` with weights
``(1, -b0, -b1, -b2)``. The reaction acts on the triangle's nodes, equal and opposite (momentum is
conserved to round-off), and ``d ~ d0 - r.(dx_p - sum b_i dx_fi)`` is the exact linearisation of the
distance to a flat face, so the penalty Jacobian of :mod:`volspring.collision.penalty` holds as it is.

:class:`ClothSelfContactForce` -- a cloth against itself: vertex-triangle proximity within
``thickness`` for every vertex and triangle not incident to it (hashed triangle boxes grown by
``thickness``), a penalty on the unsigned distance, ``d = thickness - |p - c|``, direction
``(p - c) / |p - c|`` (along the triangle's normal when c is inside the triangle): pushes vertex and
triangle apart, whichever side the vertex is on. The unsigned distance is the simple, robust choice
(no history, no orientation); what it needs is that a vertex never crosses a layer in one step or
under load, i.e. the penalty stops it inside ``thickness``: keep ``v dt < thickness`` and the static
depth ``F / k_c < thickness`` (measured in ``tests/test_thin_contact.py``). Each vertex has one
contact, with its nearest non-incident triangle (the distance to the rest of the cloth, continuous
across the triangles' shared edges); a vertex pressed between two layers is held by the nearer one
and by the other layer's own vertices against its triangles.

Limits: the closest-surface depth of a node inside a tet body is the naive rule of
:mod:`volspring.collision.penetration` (fine while the penalty keeps nodes within a fraction of the
body's thickness); a string's segment or a cloth's edge that cuts a body's corner with both ends
outside, and edge-edge crossings of a cloth with itself, are not detected (vertex contacts only).
"""

from __future__ import annotations

import logging

import numpy as np

from meshing.geometry import barycentric_frames, closest_points_on_triangles, nearest_surface_points
from meshing.geometry import triangle_area_normals
from volspring.collision.bodies import CollisionBodies
from volspring.collision.contact import _as_model, _body_edge_lengths, _body_moduli
from volspring.collision.penalty import (
    DEFAULT_FRICTION_VELOCITY,
    DEFAULT_STIFFNESS_FACTOR,
    PenaltyContacts,
    _PenaltyResponse,
    _positive,
)
from volspring.collision.spatial_hash import SpatialHash
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from numpy.typing import ArrayLike
    from volspring.model import Model

__all__ = ["ClothSelfContactForce", "ThinContactForce"]

logger = logging.getLogger(__name__)


def _nearest_per_key(key, distance):
    """Indices of the rows with the smallest ``distance`` for each distinct ``key`` ((k,) int64)."""
    order = np.lexsort((distance, key))
    first = np.r_[True, key[order][1:] != key[order][:-1]] if len(key) else np.zeros(0, dtype=bool)
    return order[first]


def _away(p, closest, distance, fallback):
    """Unit ``(p - closest) / distance``; ``fallback`` (unit, (k, 3)) where the distance is exactly 0."""
    zero = distance == 0.0
    return np.where(zero[:, None], fallback, (p - closest) / np.where(zero, 1.0, distance)[:, None])


def _unit_normals(x, triangles):
    normal = triangle_area_normals(x, triangles)
    return normal / np.maximum(np.linalg.norm(normal, axis=1), np.finfo(float).tiny)[:, None]


class ThinContactForce(_PenaltyResponse):
    """Penalty contact of thin bodies' nodes (cloth, strings, hair) with the tet bodies of the same model.

    Parameters
    ----------
    model : Model
        tet bodies and thin bodies in one model, the tet bodies first (:func:`volspring.structures.combine` of
        ``Model.from_bodies([...])`` and cloths or strings)
    thickness : float
        contact layer [m], >= 0: a thin node closer than this to a tet body's surface, or inside it, is in contact
        (module docstring)
    nodes : (k,) int, optional
        the thin nodes; default every node of the bodies with no mesh node
    stiffness : float, optional
        k_c [N/m] of every contact, instead of the rule ``k_c = stiffness_factor 2 E l``: E of the tet body (the thin
        body is taken as rigid across its thickness, as an obstacle is), l the mean spring length of the thin node's
        body
    stiffness_factor, damping_ratio, damping, friction, friction_velocity
        as for :class:`~volspring.collision.ContactForce` (the damping's mass: the node's against the triangle's
        interpolated mass)
    cell_size : float, optional
        hash cell [m]; default the mean tet edge length

    Examples
    --------
    >>> import numpy as np
    >>> from volspring import Material, Model, TetMesh
    >>> from volspring.bodies import Body
    >>> from volspring.structures import combine, string
    >>> tet = TetMesh(np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]), np.array([[0, 1, 2, 3]]))
    >>> block = Model.from_bodies([Body(tet, Material(E=1e5, nu=0.3, density=1000.0))])
    >>> rope = string([0.2, 0.2, -0.05], [0.2, 0.2, 1.5], count=4, mass=0.1, stiffness=50.0)
    >>> model = combine([block, rope])
    >>> contact = ThinContactForce(model, thickness=0.1)
    >>> found = contact.contacts(model.rest_positions)
    >>> found.vertex.tolist(), found.depth.round(3).tolist()   # 5 cm below the bottom face; inside, 7.7 cm deep
    ([4, 5], [0.05, 0.177])
    >>> forces = np.zeros((8, 3))
    >>> contact.accumulate(model, model.rest_positions, np.zeros((8, 3)), 0.0, forces)
    >>> bool(np.abs(forces.sum(axis=0)).max() < 1e-12 * np.abs(forces).max())   # equal and opposite
    True
    """

    def __init__(self, model: Model, *, thickness: float, nodes: ArrayLike | None = None,
                 stiffness: float | None = None, stiffness_factor: float = DEFAULT_STIFFNESS_FACTOR,
                 damping_ratio: float | None = None, damping: float | None = None, friction: float = 0.0,
                 friction_velocity: float = DEFAULT_FRICTION_VELOCITY, cell_size: float | None = None):
        model = _as_model(model)
        super().__init__(model, stiffness=stiffness, stiffness_factor=stiffness_factor, damping_ratio=damping_ratio,
                         damping=damping, friction=friction, friction_velocity=friction_velocity)
        self.thickness = _positive(thickness, "thickness", allow_zero=True)
        self.bodies = CollisionBodies.from_model(model)
        meshed = self.bodies.body_count
        if nodes is None:
            nodes = np.flatnonzero(model.node_body >= meshed)
        self.nodes = np.unique(np.asarray(nodes, dtype=np.int64).ravel())
        n = model.node_count
        if self.nodes.size and (self.nodes[0] < 0 or self.nodes[-1] >= n):
            raise ValueError(f"nodes lie in [{self.nodes[0]}, {self.nodes[-1]}], expected [0, {n - 1}]")
        on_tets = np.isin(self.nodes, self.bodies.model_nodes)
        if on_tets.any():
            node = int(self.nodes[on_tets][0])
            raise ValueError(f"node {node} is a node of tet body {int(model.node_body[node])}; expected thin nodes, "
                             "in no tet (ContactForce collides tet bodies)")
        if not self.nodes.size:
            raise ValueError(f"the model has no thin node: all its {model.body_count} bodies have tets; join a "
                             "cloth or a string with volspring.structures.combine, or give nodes=")
        self.cell_size = self.bodies.mean_edge_length if cell_size is None else _positive(cell_size, "cell_size")
        self._body_modulus = _body_moduli(model)[:meshed]
        self._node_length = _body_edge_lengths(model, self.bodies)[model.node_body]

    def __repr__(self) -> str:
        return (f"ThinContactForce({len(self.nodes)} thin nodes, {self.bodies.body_count} tet bodies, "
                f"thickness={self.thickness:g}, friction={self.friction:g})")

    def _inside(self, p, y):
        """(node row, tet body) of every thin node inside a tet: ``(row (i,), body (i,))``, unique pairs."""
        bodies = self.bodies
        corners = y[bodies.tets]
        tet_lo, tet_hi = corners.min(axis=1), corners.max(axis=1)
        # Broad phase: only tets that reach the thin nodes' box can hold one.
        near = np.flatnonzero(((tet_hi >= p.min(axis=0)) & (tet_lo <= p.max(axis=0))).all(axis=1))
        grid = SpatialHash.build(p, p, cell_size=self.cell_size)
        local_tet, row = grid.query(tet_lo[near], tet_hi[near])
        inside, _ = barycentric_frames(corners[near]).contains(p[row], local_tet)
        keys = np.unique(row[inside] * bodies.body_count + bodies.tet_body[near[local_tet[inside]]])
        return keys // bodies.body_count, keys % bodies.body_count

    def _detect(self, x) -> PenaltyContacts:
        bodies, h = self.bodies, self.thickness
        p, y = x[self.nodes], x[bodies.model_nodes]
        faces, face_body = bodies.boundary_faces, bodies.boundary_face_body
        normals = _unit_normals(y, faces)
        in_row, in_body = self._inside(p, y)
        rows, face, bary, depth, direction = [], [], [], [], []
        # Inside: the nearest point of the body's surface, however far (a loop over bodies, not nodes).
        for body in np.unique(in_body):
            pick = np.flatnonzero(in_body == body)
            body_faces = np.flatnonzero(face_body == body)
            local, closest, weights, distance = nearest_surface_points(p[in_row[pick]], y, faces[body_faces])
            f = body_faces[local]
            rows.append(in_row[pick])
            face.append(f)
            bary.append(weights)
            depth.append(h + distance)
            direction.append(-_away(p[in_row[pick]], closest, distance, -normals[f]))
        # Outside within the thickness: hashed triangle boxes grown by h, the nearest per (node, body).
        corners = y[faces]
        grid = SpatialHash.build(corners.min(axis=1) - h, corners.max(axis=1) + h, cell_size=self.cell_size)
        row, f = grid.query(p, p)
        closest, weights = closest_points_on_triangles(p[row], *(corners[f, i] for i in range(3)))
        distance = np.linalg.norm(p[row] - closest, axis=1)
        key = row * bodies.body_count + face_body[f]
        close = (distance < h) & ~np.isin(key, in_row * bodies.body_count + in_body)
        row, f, closest, weights, distance, key = (a[close] for a in (row, f, closest, weights, distance, key))
        best = _nearest_per_key(key, distance)
        row, f, closest, weights, distance = (a[best] for a in (row, f, closest, weights, distance))
        rows.append(row)
        face.append(f)
        bary.append(weights)
        depth.append(h - distance)
        direction.append(_away(p[row], closest, distance, normals[f]))

        row, f, bary = np.concatenate(rows), np.concatenate(face), np.concatenate(bary)
        depth, direction = np.concatenate(depth), np.concatenate(direction)
        order = np.lexsort((face_body[f], row))  # by node, then body: independent of how they were found
        row, f, bary, depth, direction = row[order], f[order], bary[order], depth[order], direction[order]
        vertex = self.nodes[row]
        nodes = np.concatenate([vertex[:, None], bodies.model_nodes[faces[f]]], axis=1)
        masses = self.model.masses
        face_mass = np.einsum("ck,ck->c", bary, masses[nodes[:, 1:]])
        vertex_mass = masses[vertex]
        other = face_body[f]
        stiffness, damping = self._coefficients(2.0 * self._body_modulus[other], self._node_length[vertex],
                                                vertex_mass * face_mass / (vertex_mass + face_mass))
        if len(depth):
            logger.debug("%d thin contacts (%d inside), deepest %.3g m", len(depth), len(in_row), depth.max())
        return PenaltyContacts(nodes, np.concatenate([np.ones((len(row), 1)), -bary], axis=1),
                               np.maximum(depth, 0.0), direction, stiffness, damping, other)


class ClothSelfContactForce(_PenaltyResponse):
    """Penalty contact of a cloth with itself: vertex-triangle proximity within ``thickness``.

    Parameters
    ----------
    model : Model
        the cloth (or a model holding it, e.g. from :func:`volspring.structures.combine`)
    triangles : (t, 3) int
        the cloth's triangles, model node ids (:func:`volspring.structures.sheet_grid` gives a grid's, shifted by the
        cloth's first node in a combined model)
    thickness : float
        contact distance [m], > 0: less than the rest distance of every vertex to every triangle not incident to it
        (checked: a flat sheet would otherwise push itself apart)
    stiffness : float
        k_c [N/m] of every contact (a cloth has no material for a rule)
    damping_ratio, damping, friction, friction_velocity
        as for :class:`~volspring.collision.ContactForce` (the damping's mass: the vertex's against the triangle's
        interpolated mass)
    cell_size : float, optional
        hash cell [m]; default the mean edge length of the triangles

    Raises
    ------
    ValueError
        A thickness <= 0 or not below the rest distance of a vertex to a non-incident triangle (naming
        both and the distance), triangles of the wrong shape or outside the model's nodes.

    Examples
    --------
    >>> import numpy as np
    >>> from volspring.structures import cloth_grid, sheet_grid
    >>> sheet = cloth_grid(1.0, 1.0, 4, 4, areal_density=0.2, membrane_stiffness=100.0)
    >>> _, triangles = sheet_grid(1.0, 1.0, 4, 4)
    >>> contact = ClothSelfContactForce(sheet, triangles, thickness=0.05, stiffness=100.0)
    >>> x = np.array(sheet.rest_positions)
    >>> x[24] = [0.4, 0.4, -0.03]                # a corner folded 3 cm under the middle of the sheet
    >>> found = contact.contacts(x)
    >>> found.vertex.tolist()                    # the corner, and node 12 close to the corner's stretched triangle
    [12, 24]
    >>> round(float(found.depth[1]), 3), found.direction[1].round(3).tolist()   # 5 cm - 3 cm; down, away from the sheet
    (0.02, [0.0, 0.0, -1.0])
    """

    def __init__(self, model: Model, triangles: ArrayLike, *, thickness: float, stiffness: float,
                 damping_ratio: float | None = None, damping: float | None = None, friction: float = 0.0,
                 friction_velocity: float = DEFAULT_FRICTION_VELOCITY, cell_size: float | None = None):
        model = _as_model(model)
        super().__init__(model, stiffness=stiffness, stiffness_factor=1.0, damping_ratio=damping_ratio,
                         damping=damping, friction=friction, friction_velocity=friction_velocity)
        triangles = np.asarray(triangles)
        if triangles.ndim != 2 or triangles.shape[1] != 3 or not len(triangles) or triangles.dtype.kind not in "iu":
            raise ValueError(f"triangles have shape {triangles.shape} and dtype {triangles.dtype}; expected (t, 3) "
                             "integer node ids, t >= 1")
        n = model.node_count
        if triangles.min() < 0 or triangles.max() >= n:
            raise ValueError(f"triangles index nodes in [{triangles.min()}, {triangles.max()}], expected [0, {n - 1}]")
        self.triangles = triangles.astype(np.int64)
        self.triangles.setflags(write=False)
        self.nodes = np.unique(self.triangles)
        self.thickness = _positive(thickness, "thickness")
        rest = model.rest_positions
        edges = rest[self.triangles] - rest[np.roll(self.triangles, 1, axis=1)]
        self.cell_size = (float(np.linalg.norm(edges, axis=2).mean()) if cell_size is None
                          else _positive(cell_size, "cell_size"))
        vertex, triangle, _, _, distance = self._pairs(rest)
        if len(vertex):
            worst = int(np.argmin(distance))
            raise ValueError(f"thickness = {self.thickness:g} m, but at rest vertex {vertex[worst]} is "
                             f"{distance[worst]:.6g} m from triangle {triangle[worst]} = "
                             f"{self.triangles[triangle[worst]].tolist()}, not incident to it; expected a thickness "
                             "below the rest distance of every vertex to every other triangle")

    def __repr__(self) -> str:
        return (f"ClothSelfContactForce({len(self.triangles)} triangles, thickness={self.thickness:g}, "
                f"friction={self.friction:g})")

    def _pairs(self, x):
        """Vertex-triangle pairs within the thickness, the nearest triangle of each vertex.

        Returns ``(vertex (k,), triangle (k,), closest (k, 3), barycentric (k, 3), distance (k,))``.
        """
        h, triangles = self.thickness, self.triangles
        corners = x[triangles]
        grid = SpatialHash.build(corners.min(axis=1) - h, corners.max(axis=1) + h, cell_size=self.cell_size)
        p = x[self.nodes]
        row, triangle = grid.query(p, p)
        vertex = self.nodes[row]
        own = (triangles[triangle] == vertex[:, None]).any(axis=1)
        vertex, triangle = vertex[~own], triangle[~own]
        closest, bary = closest_points_on_triangles(x[vertex], *(corners[triangle, i] for i in range(3)))
        distance = np.linalg.norm(x[vertex] - closest, axis=1)
        close = distance < h
        vertex, triangle, closest, bary, distance = (a[close] for a in (vertex, triangle, closest, bary, distance))
        # One contact per vertex, with its nearest triangle: the distance to the rest of the cloth is then
        # continuous (a vertex crossing the edge between two triangles changes neither force nor energy).
        first = _nearest_per_key(vertex, distance)
        return vertex[first], triangle[first], closest[first], bary[first], distance[first]

    def _detect(self, x) -> PenaltyContacts:
        vertex, triangle, closest, bary, distance = self._pairs(x)
        normals = _unit_normals(x, self.triangles[triangle])
        nodes = np.concatenate([vertex[:, None], self.triangles[triangle]], axis=1)
        masses = self.model.masses
        triangle_mass = np.einsum("ck,ck->c", bary, masses[nodes[:, 1:]])
        vertex_mass = masses[vertex]
        stiffness, damping = self._coefficients(np.full(len(vertex), np.nan), np.full(len(vertex), np.nan),
                                                vertex_mass * triangle_mass / (vertex_mass + triangle_mass))
        if len(vertex):
            logger.debug("%d cloth self-contacts, closest %.3g m", len(vertex), distance.min())
        return PenaltyContacts(nodes, np.concatenate([np.ones((len(vertex), 1)), -bary], axis=1),
                               self.thickness - distance, _away(x[vertex], closest, distance, normals),
                               stiffness, damping, triangle)
