"""Static obstacles: half-spaces and rigid triangle meshes, closed (a box, a rock) or open (a ramp, a bowl).

A :class:`HalfSpace` serves twice: as a scene projection (``Scene(..., obstacles=[...])``: after
each step a node below the plane is put back on it, with restitution and Coulomb friction) and,
like a :class:`StaticTriangleMesh`, as a source of penalty contacts for
:class:`~volspring.collision.ObstacleContactForce`.

A static obstacle never moves and is infinitely stiff, so for it the depth of a vertex is simply
its distance to the nearest point of the obstacle's surface, in the direction of that point. This
is the closest-point rule that fails for two thin deformable bodies (see
:mod:`volspring.collision.penetration`); for a rigid obstacle it is acceptable as long as the time
step keeps a vertex from travelling more than half the obstacle's thickness in one step, because
a vertex only ever enters from the near side.

Inside/outside of a closed mesh uses the angle-weighted pseudo-normal at the nearest point
(Baerentzen and Aanaes 2005), exact for a closed, outward-wound, manifold surface.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np

from meshing.geometry import nearest_surface_points, signed_volumes, triangle_area_normals
from collections.abc import Sequence
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from numpy.typing import ArrayLike
    import trimesh

__all__ = ["HalfSpace", "ObstacleContacts", "StaticTriangleMesh", "obstacle_contacts"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class HalfSpace:
    """A rigid obstacle filling the half-space below a plane: ``(x - point) . normal < 0``.

    After a step, every free node found below the plane is

    1. projected onto it along the normal (its penetration depth removed);
    2. if it approaches (v_n = v . n < 0), given the normal velocity -e v_n (e = ``restitution``;
       0 is a perfectly inelastic contact, 1 a perfect bounce): a normal impulse per unit mass
       dv_n = (1 + e) |v_n|;
    3. slowed tangentially by Coulomb friction: the tangential speed |v_t| is reduced by
       mu dv_n (mu = ``friction``), and to 0 if it is smaller (static friction). Its position is
       moved back by dt times the velocity removed, so that position and velocity agree.

    Over a step of resting contact on a plane tilted by theta, gravity gives dv_n = g cos(theta) dt
    and dv_t = g sin(theta) dt, so the node sticks iff tan(theta) <= mu and otherwise slides with
    acceleration g (sin(theta) - mu cos(theta)), exactly Coulomb's law. This is exact for
    symplectic Euler (x_1 = x_0 + dt v_1) and for Verlet with the backward-difference velocity
    (x_1 - x_0) / dt; integrators must pass their end-of-step velocity. A Verlet integrator that
    ignored the corrected ``v`` would still get the friction (from the corrected x) but see every
    contact as inelastic; volspring's rebuild their history from ``v`` and keep the restitution.

    Parameters
    ----------
    point : (3,) float
        a point on the plane [m]
    normal : (3,) float
        outward normal, pointing into the free side [-], normalised here
    restitution : float
        e in [0, 1] (keyword-only)
    friction : float
        Coulomb coefficient mu >= 0 (keyword-only)

    Examples
    --------
    >>> import numpy as np
    >>> from volspring import HalfSpace
    >>> ground = HalfSpace((0, 0, 0), (0, 0, 1), friction=0.5)
    >>> x, v = np.array([[0.0, 0.0, -0.01]]), np.array([[1.0, 0.0, -1.0]])
    >>> ground.project(x, v, np.zeros((1, 3)), 0.0, 0.01, np.ones(1, dtype=bool))
    >>> x.round(6).tolist(), v.tolist()  # on the plane; tangential speed 1 - 0.5 * 1
    ([[-0.005, 0.0, 0.0]], [[0.5, 0.0, 0.0]])
    """

    point: np.ndarray
    normal: np.ndarray
    restitution: float = field(default=0.0, kw_only=True)
    friction: float = field(default=0.0, kw_only=True)

    def __post_init__(self):
        point = np.array(self.point, dtype=np.float64)
        normal = np.array(self.normal, dtype=np.float64)
        if point.shape != (3,) or not np.isfinite(point).all():
            raise ValueError(f"point = {point.tolist()} is not a finite 3-vector [m]")
        length = np.linalg.norm(normal) if normal.shape == (3,) else np.nan
        if not (np.isfinite(length) and length > 0):
            raise ValueError(f"normal = {normal.tolist()} is not a finite non-zero 3-vector")
        if not (0.0 <= self.restitution <= 1.0):
            raise ValueError(f"restitution = {self.restitution} is not in [0, 1]")
        if not (math.isfinite(self.friction) and self.friction >= 0):
            raise ValueError(f"friction = {self.friction} is not finite and >= 0")
        normal = normal / length
        for array in (point, normal):
            array.setflags(write=False)
        for name, value in (("point", point), ("normal", normal), ("restitution", float(self.restitution)),
                            ("friction", float(self.friction))):
            object.__setattr__(self, name, value)

    def signed_distances(self, x: np.ndarray) -> np.ndarray:
        """(n,) float -- height of each node above the plane [m] (negative below)."""
        return (x - self.point) @ self.normal

    def contacts(self, points: ArrayLike, *,
                 thickness: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Points below the plane, or less than ``thickness`` above it, for penalty contact
        (``volspring.collision.ObstacleContactForce``).

        Returns
        -------
        vertex : (k,) int
            indices of the points below ``thickness`` above the plane
        depth : (k,) float
            how far below that level [m]: ``thickness - height``
        direction : (k, 3) float
            the way out (the normal)
        closest : (k, 3) float
            nearest points on the plane [m]
        face : (k,) int
            -1 (a plane has no faces)
        """
        points = np.asarray(points, dtype=np.float64)
        height = self.signed_distances(points)
        vertex = np.flatnonzero(height < thickness)
        depth = thickness - height[vertex]
        direction = np.broadcast_to(self.normal, (len(vertex), 3)).copy()
        closest = points[vertex] - height[vertex, None] * self.normal
        return vertex, depth, direction, closest, np.full(len(vertex), -1, dtype=np.int64)

    def project(self, x: np.ndarray, v: np.ndarray, x_start: np.ndarray, t: float, dt: float, free: np.ndarray) -> None:
        depth = -self.signed_distances(x)
        nodes = np.flatnonzero(free & (depth > 0))
        if nodes.size == 0:
            return
        n = self.normal
        x[nodes] += depth[nodes, None] * n
        velocity = v[nodes]
        normal_speed = velocity @ n
        tangential = velocity - normal_speed[:, None] * n
        approaching = normal_speed < 0
        impulse = np.where(approaching, -(1.0 + self.restitution) * normal_speed, 0.0)  # dv_n >= 0
        normal_speed = np.where(approaching, -self.restitution * normal_speed, normal_speed)
        speed = np.linalg.norm(tangential, axis=1)
        kept = np.zeros_like(speed)
        moving = speed > self.friction * impulse
        kept[moving] = 1.0 - self.friction * impulse[moving] / speed[moving]
        removed = tangential * (1.0 - kept)[:, None]
        v[nodes] = tangential - removed + normal_speed[:, None] * n
        x[nodes] -= dt * removed
        logger.debug("HalfSpace: %d node(s) in contact, deepest %.3g m", nodes.size, depth[nodes].max())


def _unit(vector, name):
    vector = np.asarray(vector, dtype=np.float64)
    if vector.shape != (3,) or not np.isfinite(vector).all():
        raise ValueError(f"{name} must be 3 finite numbers, got {vector!r}")
    length = np.linalg.norm(vector)
    if length == 0:
        raise ValueError(f"{name} = {vector.tolist()} has zero length; expected a direction")
    return vector / length


@dataclass(frozen=True, eq=False)
class StaticTriangleMesh:
    """A rigid, static triangle surface.

    Parameters
    ----------
    vertices : (v, 3) float
        corner positions [m]
    faces : (f, 3) int
        triangles; a closed mesh is re-wound outward if it comes inward
    band : float, optional
        for an open mesh, how far below its surface (on the side opposite the faces' right-hand normals) a vertex still
        counts as penetrating [m]; required for open meshes (a ramp has no inside), ignored for closed ones

    Notes
    -----
    Closed means every edge is shared by exactly two faces. For an open mesh a vertex is in contact
    when its nearest surface point is not on the open rim and its signed distance lies in
    ``(-band, 0)``: vertices beyond the rim are beside the sheet, not under it. Use
    :meth:`from_trimesh` to pass a ``trimesh.Trimesh`` (trimesh is not imported here).
    """

    vertices: np.ndarray
    faces: np.ndarray
    band: float | None = None
    closed: bool = field(init=False)

    def __post_init__(self):
        vertices = np.array(self.vertices, dtype=np.float64)
        faces = np.array(self.faces)
        if vertices.ndim != 2 or vertices.shape[1] != 3 or not np.isfinite(vertices).all():
            raise ValueError(f"vertices must be a finite (v, 3) array, got shape {vertices.shape}")
        if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0 or not np.issubdtype(faces.dtype, np.integer):
            raise ValueError(f"faces must be a non-empty (f, 3) integer array, got shape {faces.shape}, {faces.dtype}")
        if faces.min() < 0 or faces.max() >= len(vertices):
            raise ValueError(f"face indices must lie in [0, {len(vertices) - 1}], got [{faces.min()}, {faces.max()}]")
        faces = faces.astype(np.int64)
        _, counts = np.unique(np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1), axis=0, return_counts=True)
        closed = bool((counts == 2).all())
        if closed:
            x = vertices[faces]  # the enclosed volume: a sum of tets from the origin to each face
            volume = signed_volumes(np.zeros_like(x[:, 0]), x[:, 0], x[:, 1], x[:, 2]).sum()
            if volume < 0:
                faces = faces[:, ::-1].copy()
        elif self.band is None or not np.isfinite(self.band) or self.band <= 0:
            raise ValueError(f"band = {self.band} for an open mesh: expected a positive length [m], how far "
                             "below the surface a vertex still counts as penetrating")
        vertices.setflags(write=False)
        faces.setflags(write=False)
        object.__setattr__(self, "vertices", vertices)
        object.__setattr__(self, "faces", faces)
        object.__setattr__(self, "closed", closed)

    @classmethod
    def from_trimesh(cls, mesh: trimesh.Trimesh, *, band: float | None = None) -> "StaticTriangleMesh":
        """Take ``mesh.vertices`` and ``mesh.faces`` of a ``trimesh.Trimesh`` (or anything with both)."""
        return cls(np.asarray(mesh.vertices), np.asarray(mesh.faces), band=band)

    # ------------------------------------------------------------------ cached static geometry
    @cached_property
    def _edges(self):
        """Unique edges ``(e, 2)``, each face's edge ids ``(f, 3)`` (edge k joins corners k, k+1), face counts."""
        half = np.sort(self.faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
        edges, inverse, counts = np.unique(half, axis=0, return_inverse=True, return_counts=True)
        return edges, inverse.reshape(-1, 3), counts

    @cached_property
    def face_normals(self) -> np.ndarray:
        """(f, 3) float -- unit right-hand normals (outward for a closed mesh)."""
        normal = triangle_area_normals(self.vertices, self.faces)
        return normal / np.linalg.norm(normal, axis=1, keepdims=True)

    @cached_property
    def _pseudo_normals(self):
        """Angle-weighted vertex normals (v, 3) and edge normals (e, 3), unnormalised."""
        x = self.vertices[self.faces]
        angles = np.empty((len(self.faces), 3))
        for k in range(3):  # three corners per face
            u = x[:, (k + 1) % 3] - x[:, k]
            w = x[:, (k + 2) % 3] - x[:, k]
            cos = np.einsum("ij,ij->i", u, w) / (np.linalg.norm(u, axis=1) * np.linalg.norm(w, axis=1))
            angles[:, k] = np.arccos(np.clip(cos, -1.0, 1.0))
        weighted = (angles[:, :, None] * self.face_normals[:, None, :]).reshape(-1, 3)
        vertex = np.stack([np.bincount(self.faces.ravel(), weighted[:, i], len(self.vertices)) for i in range(3)], 1)
        edges, face_edges, _ = self._edges
        repeated = np.repeat(self.face_normals, 3, axis=0)
        edge = np.stack([np.bincount(face_edges.ravel(), repeated[:, i], len(edges)) for i in range(3)], 1)
        return vertex, edge

    @cached_property
    def _rim(self):
        """Open rim: ``(vertex flags (v,), edge flags (e,))`` of edges used by one face only, and their ends."""
        edges, _, counts = self._edges
        rim_edge = counts == 1
        rim_vertex = np.zeros(len(self.vertices), dtype=bool)
        rim_vertex[edges[rim_edge].ravel()] = True
        return rim_vertex, rim_edge

    @cached_property
    def _tree(self):
        from scipy.spatial import cKDTree

        return cKDTree(self.vertices[self.faces].mean(axis=1))

    @cached_property
    def bounds(self) -> np.ndarray:
        """(2, 3) float -- bounding box of the vertices [m]."""
        return np.array([self.vertices.min(axis=0), self.vertices.max(axis=0)])

    # ------------------------------------------------------------------ queries
    def _feature_normal(self, face, barycentric):
        """Pseudo-normal at the nearest point: of the face, the edge or the corner its weights select."""
        zeros = barycentric == 0.0
        zero_count = zeros.sum(axis=1)
        vertex_normals, edge_normals = self._pseudo_normals
        _, face_edges, _ = self._edges
        normal = self.face_normals[face].copy()
        on_edge = zero_count == 1
        edge = face_edges[face, (np.argmax(zeros, axis=1) + 1) % 3]  # zero weight on corner k: edge k+1
        normal[on_edge] = edge_normals[edge[on_edge]]
        on_corner = zero_count == 2
        corner = self.faces[face, np.argmax(barycentric, axis=1)]
        normal[on_corner] = vertex_normals[corner[on_corner]]
        rim_vertex, rim_edge = self._rim
        on_rim = (on_edge & rim_edge[edge]) | (on_corner & rim_vertex[corner])
        return normal / np.linalg.norm(normal, axis=1, keepdims=True), on_rim

    def contacts(self, points: ArrayLike, *,
                 thickness: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Vertices in contact: ``(vertex (k,), depth (k,) [m], direction (k, 3), closest (k, 3) [m], face (k,))``.

        A vertex is in contact when it is inside (below, for an open mesh) or outside and closer than
        ``thickness`` [m] to the surface; its depth is ``thickness + distance`` inside and
        ``thickness - distance`` outside. ``direction`` is the unit vector that takes the vertex out of
        that layer: towards its nearest surface point from inside, away from it from outside (for a
        vertex exactly on the surface, the surface's pseudo-normal). On an open mesh a vertex outside
        near the rim is pushed away from the rim (the rim is rounded by the thickness); one below it
        is beside the sheet, not under it, and is left alone.
        """
        points = np.asarray(points, dtype=np.float64)
        band = 0.0 if self.closed or self.band is None else self.band  # an open mesh has one (__post_init__)
        margin = band + thickness
        lo, hi = self.bounds[0] - margin, self.bounds[1] + margin
        near = np.flatnonzero(((points >= lo) & (points <= hi)).all(axis=1))
        face, closest, bary, distance = nearest_surface_points(points[near], self.vertices, self.faces, tree=self._tree)
        normal, on_rim = self._feature_normal(face, bary)
        offset = closest - points[near]
        signed = -np.einsum("ij,ij->i", offset, normal)  # (p - c).n: negative below / inside
        inside = signed < 0
        if not self.closed:
            inside &= ~on_rim & (distance < self.band)
        outside = (signed >= 0) & (distance < thickness)
        keep = np.flatnonzero(inside | outside)
        sign = np.where(inside[keep], 1.0, -1.0)  # towards the surface from inside, away from it outside
        # The pseudo-normal sign is exact; |p - c| > 0 whenever signed < 0, so only a vertex exactly on
        # the surface (outside, distance 0) has no offset direction: it takes the pseudo-normal.
        on_surface = distance[keep] == 0.0
        direction = np.where(on_surface[:, None], normal[keep],
                             sign[:, None] * offset[keep] / np.where(on_surface, 1.0, distance[keep])[:, None])
        depth = thickness + sign * distance[keep]
        return near[keep], depth, direction, closest[keep], face[keep]


@dataclass(frozen=True, eq=False)
class ObstacleContacts:
    """Vertices inside static obstacles, one row per (vertex, obstacle).

    Attributes
    ----------
    vertex : (k,) int64
        global node id
    obstacle : (k,) int64
        index of the obstacle in the list given to :func:`obstacle_contacts`
    depth : (k,) float
        depth in the contact layer [m], > 0: the distance to the surface inside, plus the thickness; the thickness minus
        the distance outside
    direction : (k, 3) float
        unit direction that takes the vertex out (towards ``closest`` from inside, away from it outside)
    closest : (k, 3) float
        nearest surface point, a natural anchor for friction [m]
    face : (k,) int64
        triangle of ``closest``; -1 for a half-space
    """

    vertex: np.ndarray
    obstacle: np.ndarray
    depth: np.ndarray
    direction: np.ndarray
    closest: np.ndarray
    face: np.ndarray

    @property
    def count(self) -> int:
        return len(self.vertex)


def obstacle_contacts(obstacles: Sequence[HalfSpace | StaticTriangleMesh], positions: ArrayLike, *,
                      thickness: float = 0.0) -> ObstacleContacts:
    """Every vertex inside any static obstacle, or closer than ``thickness`` to its surface.

    Parameters
    ----------
    obstacles : sequence of HalfSpace or StaticTriangleMesh
    positions : (N, 3) float
        current node positions of all bodies, stacked [m]
    thickness : float
        contact layer over each obstacle's surface [m], >= 0: the half-thickness of a cloth or a string's radius (0:
        contact only inside)

    Returns
    -------
    ObstacleContacts
        sorted by obstacle, then vertex

    Examples
    --------
    >>> import numpy as np
    >>> from volspring import HalfSpace
    >>> floor = HalfSpace(point=(0, 0, 0), normal=(0, 0, 1))
    >>> hits = obstacle_contacts([floor], np.array([[0.0, 0, -0.1], [0, 0, 0.2]]))
    >>> hits.vertex.tolist(), hits.obstacle.tolist()
    ([0], [0])
    """
    positions = np.asarray(positions, dtype=np.float64)
    if positions.ndim != 2 or positions.shape[1] != 3:
        raise ValueError(f"positions must have shape (N, 3), got {positions.shape}")
    if not (np.isfinite(thickness) and thickness >= 0):
        raise ValueError(f"thickness = {thickness} m is not finite and >= 0")
    thickness = float(thickness)
    parts = []
    for index, obstacle in enumerate(obstacles):  # a loop over obstacles, not over vertices
        if not isinstance(obstacle, (HalfSpace, StaticTriangleMesh)):
            raise TypeError(f"obstacles[{index}] must be a HalfSpace or StaticTriangleMesh, "
                            f"got {type(obstacle).__name__}")
        vertex, depth, direction, closest, face = obstacle.contacts(positions, thickness=thickness)
        parts.append((vertex, np.full(len(vertex), index, dtype=np.int64), depth, direction, closest, face))
    if not parts:
        parts = [(np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)),
                  np.zeros(0, np.int64))]
    return ObstacleContacts(*(np.concatenate(column) for column in zip(*parts)))
