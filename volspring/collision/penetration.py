"""Penetration depth and direction of colliding vertices: consistent (Heidelberger et al. 2004) and naive.

A colliding point is a vertex of body P inside a tet of body Q. Its depth ``d`` [m] and unit
direction ``r`` say how far and where the vertex must move to leave Q: a penalty force along
``k_c d r`` on the vertex, and its opposite on Q's tet nodes (weights ``barycentric``), resolve it.

The consistent method (:func:`consistent_penetration_depths`) follows the four phases of
Heidelberger, Teschner, Keiser, Mueller and Gross (VMV 2004):

1. colliding points: from :func:`~volspring.collision.spatial_hash.detect_collisions`;
2. border points (colliding, with a non-colliding neighbour along a mesh edge) and their
   intersection edges, cut exactly with Q's boundary triangles; if an edge crosses several
   triangles the hit nearest the non-colliding end is kept; the normal there is interpolated
   barycentrically from Q's area-weighted vertex normals;
3. border depth ``d = sum w_i (x_i - p).n_i / sum w_i``, ``r = normalize(sum w_i n_i)``,
   ``w_i = 1 / |x_i - p|^2``;
4. breadth-first propagation inward, one BFS level at a time (all points of a level at once, from
   the points of earlier levels only, so the result does not depend on an ordering):
   ``d = sum mu_j ((p_j - p).r_j + d_j) / sum mu_j``, ``r = normalize(sum mu_j r_j)``,
   ``mu_j = 1 / |p_j - p|^2``.

Fallback (flagged in :attr:`PenetrationDepths.fallback`): colliding points that no border point
reaches -- a body wholly inside another, or a colliding island with no edge leaving Q -- and the
rare points whose averaged direction cancels to zero get the naive closest-surface-point depth.

The naive method (:func:`closest_surface_depths`) uses the nearest point of Q's boundary surface
for every colliding point. It is exact for shallow contact but, once a vertex has passed more than
halfway through a thin part, the nearest surface is the far side and it pushes the vertex on
through (tunnelling); it is kept to show that failure.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from meshing.geometry import area_weighted_vertex_normals, nearest_surface_points
from meshing.tolerances import CANCELLED, ON_SURFACE
from volspring.collision.bodies import CollisionBodies
from volspring.collision.spatial_hash import DEFAULT_TABLE_SIZE, VertexTetContacts, box_pairs, expand_ranges
from volspring.collision.triangles import segment_triangle_intersections
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

__all__ = ["PenetrationDepths", "closest_surface_depths", "consistent_penetration_depths"]

logger = logging.getLogger(__name__)

# Guard of the 1/|x - p|^2 weights, relative to the cell size: a point closer than ON_SURFACE (1e-9) cell
# sizes to a surface hit or a neighbour is at round-off distance, and its weight is capped at that distance.
_WEIGHT_FLOOR = ON_SURFACE


@dataclass(frozen=True, eq=False)
class PenetrationDepths:
    """Depth and direction of every colliding point, one row per (vertex, penetrated body).

    Attributes
    ----------
    vertex : (c,) int64
        global id of the penetrating vertex (sorted, then by ``other_body``)
    vertex_body : (c,) int64
        its body
    other_body : (c,) int64
        the body it is inside
    tet : (c,) int64
        one tet of ``other_body`` containing the vertex (global id)
    barycentric : (c, 4) float
        the vertex's weights on that tet's nodes: the reaction on ``other_body``
    depth : (c,) float
        penetration depth [m]; may come out slightly negative for a vertex that is barely inside where interpolated
        normals disagree: clamp at 0 in a penalty force
    direction : (c, 3) float
        unit direction that takes the vertex out of ``other_body``
    level : (c,) int64
        0 for border points, ``j`` for the ``j``-th propagation level, -1 for points whose depth came from the closest
        surface point
    fallback : (c,) bool
        depth from the closest surface point because no border point reached the vertex (e.g. a body wholly inside
        another); always False for the naive method
    hit_owner : (h,) int64
        row of the border point owning each intersection edge
    hit_point : (h, 3) float
        where that edge crosses ``other_body``'s surface [m]
    hit_normal : (h, 3) float
        interpolated unit normal of ``other_body`` there
    method : str
        ``"consistent"`` or ``"closest_surface"``
    """

    vertex: np.ndarray
    vertex_body: np.ndarray
    other_body: np.ndarray
    tet: np.ndarray
    barycentric: np.ndarray
    depth: np.ndarray
    direction: np.ndarray
    level: np.ndarray
    fallback: np.ndarray
    hit_owner: np.ndarray
    hit_point: np.ndarray
    hit_normal: np.ndarray
    method: str

    @property
    def count(self) -> int:
        return len(self.vertex)

    @property
    def is_border(self) -> np.ndarray:
        """(c,) bool -- points whose depth came from their own intersection edges."""
        return self.level == 0


def _colliding_points(bodies: CollisionBodies, contacts: VertexTetContacts):
    """Phase 1: one row per (vertex, penetrated body), with the first containing tet of that body."""
    if not isinstance(contacts, VertexTetContacts):
        raise TypeError(f"contacts must be VertexTetContacts (from detect_collisions), got {type(contacts).__name__}")
    keys = contacts.vertex * bodies.body_count + contacts.tet_body
    keys, first = np.unique(keys, return_index=True)
    vertex, other = keys // bodies.body_count, keys % bodies.body_count
    return keys, vertex, other, contacts.tet[first], contacts.barycentric[first]


def _closest_surface(bodies: CollisionBodies, x, vertex, other, normals):
    """Depth and direction towards the nearest boundary point of the penetrated body."""
    depth = np.zeros(len(vertex))
    direction = np.zeros((len(vertex), 3))
    faces, face_body = bodies.boundary_faces, bodies.boundary_face_body
    for body in np.unique(other):  # a loop over penetrated bodies, not over points
        rows = np.flatnonzero(other == body)
        body_faces = faces[face_body == body]
        face, closest, bary, distance = nearest_surface_points(x[vertex[rows]], x, body_faces)
        offset = closest - x[vertex[rows]]
        surface_normal = np.einsum("kj,kji->ki", bary, normals[body_faces[face]])
        # On the surface itself (distance at round-off) the offset has no direction: use the normal.
        on_surface = distance <= _WEIGHT_FLOOR * bodies.mean_edge_length
        direction[rows] = np.where(on_surface[:, None], surface_normal,
                                   offset / np.where(on_surface, 1.0, distance)[:, None])
        depth[rows] = distance
    return depth, _normalized(direction)[0]


def _scatter(index, weights, count):
    """``out[i] = sum of weights[index == i]``, (count,) float64 (also for empty input, where bincount gives int)."""
    return np.bincount(index, weights, count).astype(np.float64, copy=False)


def _normalized(vectors):
    length = np.linalg.norm(vectors, axis=1)
    ok = length > CANCELLED  # sums of unit vectors (summed length >= 1): below CANCELLED they have cancelled
    return np.divide(vectors, length[:, None], out=np.zeros_like(vectors), where=ok[:, None]), ok


def _empty_hits() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return np.zeros(0, dtype=np.int64), np.zeros((0, 3)), np.zeros((0, 3))


def closest_surface_depths(bodies: CollisionBodies, positions: ArrayLike,
                           contacts: VertexTetContacts) -> PenetrationDepths:
    """Naive depths: distance to, and direction towards, the nearest point of the penetrated body's surface.

    Parameters
    ----------
    bodies : CollisionBodies
    positions : (N, 3) float or sequence of (n_b, 3) float
        current positions [m]
    contacts : VertexTetContacts
        from :func:`detect_collisions` at these positions

    Returns
    -------
    PenetrationDepths
        with ``method = "closest_surface"``, ``level = -1``, ``fallback`` all False
    """
    x = bodies.stack_positions(positions)
    _, vertex, other, tet, bary = _colliding_points(bodies, contacts)
    normals = area_weighted_vertex_normals(x, bodies.boundary_faces)
    depth, direction = _closest_surface(bodies, x, vertex, other, normals)
    count = len(vertex)
    return PenetrationDepths(vertex, bodies.node_body[vertex], other, tet, bary, depth, direction,
                             np.full(count, -1, dtype=np.int64), np.zeros(count, dtype=bool), *_empty_hits(),
                             method="closest_surface")


def _edge_surface_hits(bodies, x, start_vertex, end_vertex, body, *, cell_size, table_size, normals):
    """Phase 2 cut: for each segment, the crossing of ``body``'s surface nearest ``end_vertex``.

    Returns ``(segment (h,), point (h, 3), normal (h, 3))`` for the segments that hit.
    """
    if len(start_vertex) == 0:
        return _empty_hits()
    a, b = x[start_vertex], x[end_vertex]
    seg_lo, seg_hi = np.minimum(a, b), np.maximum(a, b)
    faces, face_body = bodies.boundary_faces, bodies.boundary_face_body
    corners = x[faces]
    face_lo, face_hi = corners.min(axis=1), corners.max(axis=1)
    # Only the penetrated bodies' faces that reach the box of all segments can be cut.
    near = np.isin(face_body, np.unique(body))
    near &= ((face_lo <= seg_hi.max(axis=0)) & (face_hi >= seg_lo.min(axis=0))).all(axis=1)
    candidates = np.flatnonzero(near)
    segment, local = box_pairs(face_lo[candidates], face_hi[candidates], seg_lo, seg_hi, cell_size=cell_size,
                               table_size=table_size, item_group=face_body[candidates], query_group=body, rule="same")
    face = candidates[local]
    # A self-collision edge starts or ends on its own body's surface: those faces are not crossings.
    incident = ((faces[face] == start_vertex[segment, None]) | (faces[face] == end_vertex[segment, None])).any(1)
    segment, face = segment[~incident], face[~incident]
    hit, t, bary = segment_triangle_intersections(a[segment], b[segment], *(corners[face, i] for i in range(3)))
    segment, face, t, bary = segment[hit], face[hit], t[hit], bary[hit]
    # Keep, per segment, the hit nearest the non-colliding end (largest t).
    order = np.lexsort((t, segment))
    last = np.flatnonzero(np.r_[segment[order][1:] != segment[order][:-1], True])
    pick = order[last]
    segment, face, t, bary = segment[pick], face[pick], t[pick], bary[pick]
    point = a[segment] + t[:, None] * (b[segment] - a[segment])
    normal, _ = _normalized(np.einsum("kj,kji->ki", bary, normals[faces[face]]))
    return segment, point, normal


def consistent_penetration_depths(bodies: CollisionBodies, positions: ArrayLike, contacts: VertexTetContacts, *,
                                  cell_size: float | None = None,
                                  table_size: int = DEFAULT_TABLE_SIZE) -> PenetrationDepths:
    """Consistent penetration depths of all colliding points (Heidelberger et al. 2004).

    Parameters
    ----------
    bodies : CollisionBodies
    positions : (N, 3) float or sequence of (n_b, 3) float
        current positions [m]
    contacts : VertexTetContacts
        from :func:`detect_collisions` at these positions
    cell_size : float, optional
        hash cell for the edge-triangle search [m]; default mean rest edge length
    table_size : int
        hash buckets of that search

    Returns
    -------
    PenetrationDepths
        with ``method = "consistent"``; see the module docstring for the phases and the flagged fallback

    Examples
    --------
    >>> import numpy as np
    >>> from meshing import TetMesh
    >>> from volspring.collision import CollisionBodies, detect_collisions, consistent_penetration_depths
    >>> tet = TetMesh(np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]), np.array([[0, 1, 2, 3]]))
    >>> bodies = CollisionBodies((tet, tet))
    >>> x = [tet.points, tet.points + [0.1, 0.12, 0.14]]      # body 1 moved into body 0
    >>> depths = consistent_penetration_depths(bodies, x, detect_collisions(bodies, x))
    >>> depths.vertex.tolist(), depths.level.tolist(), depths.direction.round(3).tolist()
    ([4], [0], [[0.55, 0.577, 0.604]])

    The consistent direction points back the way body 1 came; the naive closest-surface depth of
    the same vertex pushes it sideways, out of the nearest face:

    >>> from volspring.collision import closest_surface_depths
    >>> closest_surface_depths(bodies, x, detect_collisions(bodies, x)).direction.tolist()
    [[-1.0, 0.0, 0.0]]
    """
    x = bodies.stack_positions(positions)
    cell_size = bodies.mean_edge_length if cell_size is None else float(cell_size)
    keys, vertex, other, tet, bary = _colliding_points(bodies, contacts)
    count = len(vertex)
    normals = area_weighted_vertex_normals(x, bodies.boundary_faces)
    floor = (_WEIGHT_FLOOR * cell_size) ** 2

    # Phase 2: every mesh edge of each colliding point, split into edges to colliding points
    # (for the propagation) and intersection edges (to points outside the same body).
    indptr, neighbour_index = bodies.neighbours
    owner, slot = expand_ranges(indptr[vertex], indptr[vertex + 1] - indptr[vertex])
    neighbour = neighbour_index[slot]
    neighbour_key = neighbour * bodies.body_count + other[owner]
    row = np.minimum(np.searchsorted(keys, neighbour_key), max(count - 1, 0))
    colliding = keys[row] == neighbour_key  # empty when nothing collides
    cut = ~colliding
    segment, hit_point, hit_normal = _edge_surface_hits(
        bodies, x, vertex[owner[cut]], neighbour[cut], other[owner[cut]],
        cell_size=cell_size, table_size=table_size, normals=normals)
    hit_owner = owner[cut][segment]

    # Phase 3: border depth and direction, 1/|x_i - p|^2 weights.
    offset = hit_point - x[vertex[hit_owner]]
    weight = 1.0 / np.maximum(np.einsum("ij,ij->i", offset, offset), floor)
    total = _scatter(hit_owner, weight, count)
    depth = _scatter(hit_owner, weight * np.einsum("ij,ij->i", offset, hit_normal), count)
    direction = np.stack([_scatter(hit_owner, weight * hit_normal[:, i], count) for i in range(3)], axis=1)
    border = total > 0
    depth = np.divide(depth, total, out=np.zeros(count), where=border)
    direction, ok = _normalized(direction)
    done = border & ok
    level = np.where(done, 0, -1).astype(np.int64)

    # Phase 4: breadth-first propagation, one level per iteration, from earlier levels only.
    target, source = owner[colliding], row[colliding]
    step = 0
    while True:
        frontier = done[source] & ~done[target]
        if not frontier.any():
            break
        step += 1
        t, s = target[frontier], source[frontier]
        delta = x[vertex[s]] - x[vertex[t]]
        mu = 1.0 / np.maximum(np.einsum("ij,ij->i", delta, delta), floor)
        total = _scatter(t, mu, count)
        new = (total > 0) & ~done
        summed = _scatter(t, mu * (np.einsum("ij,ij->i", delta, direction[s]) + depth[s]), count)
        r = np.stack([_scatter(t, mu * direction[s, i], count) for i in range(3)], axis=1)
        r, ok = _normalized(r)
        depth[new] = summed[new] / total[new]
        direction[new] = r[new]
        level[new] = step
        # A point whose neighbours' directions cancel is left to the fallback, not re-tried forever.
        done |= new & ok
        level[new & ~ok] = -1
        target_ok = ~(new & ~ok)
        keep = target_ok[target]
        target, source = target[keep], source[keep]

    fallback = ~done
    if fallback.any():
        rows = np.flatnonzero(fallback)
        depth[rows], direction[rows] = _closest_surface(bodies, x, vertex[rows], other[rows], normals)
        logger.info("%d of %d colliding points reached by no border point: closest-surface depth used",
                    len(rows), count)
    return PenetrationDepths(vertex, bodies.node_body[vertex], other, tet, bary, depth, direction, level,
                             fallback, hit_owner, hit_point, hit_normal, method="consistent")
