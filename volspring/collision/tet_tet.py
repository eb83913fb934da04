"""Tet-tet intersection: the narrow phase that finds bodies crossing with no vertex inside the other.

Vertex-in-tet detection (:func:`~volspring.collision.detect_collisions`) misses two thin parts that
cross like the arms of an X: every vertex of each stays outside the other, only edges pass through
faces. This module decides whether two tets intersect, and where their edges cross their faces.

Touching counts as intersecting: tets are closed sets. Two closed, non-flat tets A and B intersect
exactly when

1. a vertex of one lies in the other (closed: on a face counts), or
2. an edge of one meets a face triangle of the other transversally (the edge not in the face's
   plane; meeting on the triangle's boundary or at the edge's end counts).

Why this is complete: A and B, if they meet, share an extreme point p of the convex set A n B; with
F_A, F_B the faces of A and B whose relative interiors hold p, aff(F_A) n aff(F_B) = {p} (else p
could move both ways inside A n B). So either F_A or F_B is a vertex (case 1), or an edge and a
facet meet at one point (case 2), or two edges meet at one point -- and then the edge of A is in
the plane of at most one of the two facets of B at the other edge, so it crosses the other one
transversally at p, on that facet's boundary (case 2 again). Coplanar edge-face contacts need no
test of their own.

Every test is the sign of an orientation determinant (6 signed volumes): the side of each vertex
of one tet against each face plane of the other (2 x 16), and the Pluecker side products of the
6 x 6 edge pairs, which decide on which side of a triangle's edges a line passes. An edge shared by
two faces enters both faces' tests with one number and opposite signs, so a line through a shared
edge is found in at least one face whatever the round-off (watertight). For points whose
coordinates are small integers or dyadic fractions with a few bits (|x| < 2^6 with 8 fractional
bits) every determinant is exact in float64, and so is the answer, touching cases included;
otherwise it is exact except within round-off (~1e-16 of the tets' size cubed) of touching.

A flat tet (orientation exactly zero) intersects nothing here: it has no inside, and the
argument above needs non-flat tets.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from meshing.mesh import TET_EDGES, TET_FACES

__all__ = ["NEAR_COPLANAR", "EdgeCrossingContacts", "EdgeFaceCrossings", "TetPairs", "crossing_tet_pairs",
           "edge_crossing_contacts", "edge_face_crossings", "tets_intersect"]

# An edge at an angle below NEAR_COPLANAR [rad] to a face's plane is taken as lying in it: not tested against
# that face. Below it the Pluecker signs are round-off (error ~1e-16 / angle of the tets' size l, so a hit
# could be false by that much); skipping can only miss a crossing whose edge stays within angle * l of the
# plane (the argument in the module docstring finds every other one). 1e-8, the geometric mean of float64's
# round-off and 1, bounds both errors by 1e-8 l. Never reached by exact input: on the grids of the module
# docstring a non-zero sine is at least 2^-8 / (|d| |n|) ~ 1e-7.
NEAR_COPLANAR = 1e-8

# Pairs per chunk of the narrow phase: ~1.5 kB of temporaries per pair, so ~100 MB at most.
_CHUNK = 65_536


def _cycles():
    """For face k (``TET_FACES[k] = v0 v1 v2``): the edges v0->v1, v1->v2, v2->v0 as TET_EDGES indices and signs."""
    index = {tuple(edge): e for e, edge in enumerate(TET_EDGES.tolist())}
    edges = np.zeros((4, 3), dtype=np.int64)
    signs = np.zeros((4, 3))
    for k, face in enumerate(TET_FACES.tolist()):  # a loop over the 4 faces of the reference tet, once
        for c in range(3):
            a, b = face[c], face[(c + 1) % 3]
            edges[k, c] = index[(min(a, b), max(a, b))]
            signs[k, c] = 1.0 if a < b else -1.0
    return edges, signs


_CYCLE_EDGES, _CYCLE_SIGNS = _cycles()


def _check_corners(corners, name):
    corners = np.asarray(corners, dtype=np.float64)
    if corners.ndim != 3 or corners.shape[1:] != (4, 3):
        raise ValueError(f"{name} has shape {corners.shape}, expected (m, 4, 3): four corners per tet")
    if not np.isfinite(corners).all():
        bad = int(np.flatnonzero(~np.isfinite(corners).all(axis=(1, 2)))[0])
        raise ValueError(f"{name}[{bad}] has a coordinate that is not finite: {corners[bad].tolist()}")
    return corners


def _face_normals(tet):
    """(m, 4, 3) -- ``n_k``, twice the area vector of face k, oriented so ``n_k . (t_k - t_base) = orientation``."""
    t0, t1, t2, t3 = (tet[:, i] for i in range(4))
    return np.stack([np.cross(t3 - t1, t2 - t1), np.cross(t2 - t0, t3 - t0),
                     np.cross(t3 - t0, t1 - t0), np.cross(t1 - t0, t2 - t0)], axis=1)


def _plane_sides(tet, normals, points):
    """``side[m, v, k]``: the orientation of ``tet`` with its vertex k replaced by ``points[:, v]``, (m, 4, 4).

    It is ``n_k . (x - base_k)`` (:func:`_face_normals`); at ``x = tet[:, k]`` it is the tet's own
    orientation ``det[t1 - t0, t2 - t0, t3 - t0]``.
    """
    base = tet[:, [1, 0, 0, 0]]
    return np.einsum("mkj,mvkj->mvk", normals, points[:, :, None, :] - base[:, None, :, :])


def _orientations(tet):
    """(m,) float -- ``det[t1 - t0, t2 - t0, t3 - t0]``, six times the signed volume."""
    return np.einsum("mj,mj->m", np.cross(tet[:, 1] - tet[:, 0], tet[:, 2] - tet[:, 0]), tet[:, 3] - tet[:, 0])


def _edge_sides(a, b):
    """``S[m, i, j]`` = orient(a_i0, a_i1, b_j0, b_j1) for the TET_EDGES of a and b, (m, 6, 6) (Pluecker)."""
    da = a[:, TET_EDGES[:, 1]] - a[:, TET_EDGES[:, 0]]
    db = b[:, TET_EDGES[:, 1]] - b[:, TET_EDGES[:, 0]]
    ma = np.cross(a[:, TET_EDGES[:, 0]], a[:, TET_EDGES[:, 1]])
    mb = np.cross(b[:, TET_EDGES[:, 0]], b[:, TET_EDGES[:, 1]])
    return np.einsum("mik,mjk->mij", da, mb) + np.einsum("mik,mjk->mij", ma, db)


def _crossings(plane_side, edge_side, edge_tet, face_normals):
    """Transversal edge-face hits (m, 6, 4) of one tet's edges through the other's faces.

    ``plane_side[m, v, k]``: the edge tet's vertices against the face tet's planes; ``edge_side[m, i, j]``:
    Pluecker products, edge tet's edge i against face tet's edge j; ``face_normals`` (m, 4, 3) the
    normals ``n_k`` of :func:`_plane_sides`. Also returns the plane sides of each edge's two ends and the
    signed products (m, 6, 4, 3) of each edge against each face's cycle v0->v1, v1->v2, v2->v0.
    """
    start, end = plane_side[:, TET_EDGES[:, 0]], plane_side[:, TET_EDGES[:, 1]]  # (m, 6, 4)
    # start - end = n_k . (edge's start - end): |d| |n_k| times the sine of the edge's angle to the plane.
    length = np.linalg.norm(edge_tet[:, TET_EDGES[:, 1]] - edge_tet[:, TET_EDGES[:, 0]], axis=2)  # (m, 6)
    steep = np.abs(start - end) > NEAR_COPLANAR * length[:, :, None] * np.linalg.norm(face_normals, axis=2)[:, None]
    transversal = (np.sign(start) * np.sign(end) <= 0) & steep
    cycle = edge_side[:, :, _CYCLE_EDGES] * _CYCLE_SIGNS  # (m, 6, 4, 3)
    through = (cycle >= 0).all(axis=3) | (cycle <= 0).all(axis=3)
    return transversal & through, start, end, cycle


def _predicates(a, b):
    """Everything both public functions need, for one chunk of pairs (origin moved to a's first corner)."""
    origin = a[:, :1]
    a, b = a - origin, b - origin
    normals_a, normals_b = _face_normals(a), _face_normals(b)
    b_against_a = _plane_sides(a, normals_a, b)  # (m, 4 b-vertices, 4 a-faces)
    a_against_b = _plane_sides(b, normals_b, a)
    sigma_a, sigma_b = np.sign(_orientations(a)), np.sign(_orientations(b))
    solid = (sigma_a != 0) & (sigma_b != 0)
    a_in_b = ((sigma_b[:, None, None] * a_against_b >= 0).all(axis=2)) & solid[:, None]  # (m, 4)
    b_in_a = ((sigma_a[:, None, None] * b_against_a >= 0).all(axis=2)) & solid[:, None]
    sides = _edge_sides(a, b)
    a_through_b = _crossings(a_against_b, sides, a, normals_b)
    b_through_a = _crossings(b_against_a, sides.transpose(0, 2, 1), b, normals_a)
    return solid, a_in_b, b_in_a, a_through_b, b_through_a


def _chunks(count):
    return [slice(start, min(start + _CHUNK, count)) for start in range(0, count, _CHUNK)] or [slice(0, 0)]


def tets_intersect(a, b, *, return_vertex_inside=False):
    """Whether each pair of closed tets intersects (touching counts), by vertex-in-tet and edge-through-face.

    Parameters
    ----------
    a, b : (m, 4, 3) float
        Corners of the two tets of each pair [m], either orientation; flat tets intersect nothing.
    return_vertex_inside : bool
        Also return whether a vertex of one tet lies in the other (the pairs vertex-in-tet
        detection finds; the rest meet only through edges crossing faces).

    Returns
    -------
    intersect : (m,) bool
    vertex_inside : (m,) bool
        Only with ``return_vertex_inside``.

    Examples
    --------
    Two thin tets crossing like an X, no vertex of either inside the other; and one touching a corner:

    >>> import numpy as np
    >>> a = np.array([[[-2., 0, 0], [2, 0, 0], [0, 0.25, 1], [0, -0.25, 1]]])
    >>> b = np.array([[[0., -2, 0.5], [0, 2, 0.5], [0.25, 0, -0.5], [-0.25, 0, -0.5]]])
    >>> tets_intersect(a, b, return_vertex_inside=True)
    (array([ True]), array([False]))
    >>> tets_intersect(a, a + [4.0, 0.0, 0.0])  # a's corner (2, 0, 0) is the other's (-2 + 4, 0, 0)
    array([ True])
    """
    a, b = _check_corners(a, "a"), _check_corners(b, "b")
    if a.shape != b.shape:
        raise ValueError(f"a has shape {a.shape} but b has shape {b.shape}; expected the same (m, 4, 3)")
    intersect = np.zeros(len(a), dtype=bool)
    inside = np.zeros(len(a), dtype=bool)
    for part in _chunks(len(a)):  # a loop over chunks of 65536 pairs, to bound memory
        solid, a_in_b, b_in_a, a_through_b, b_through_a = _predicates(a[part], b[part])
        inside[part] = a_in_b.any(axis=1) | b_in_a.any(axis=1)
        crossed = a_through_b[0].any(axis=(1, 2)) | b_through_a[0].any(axis=(1, 2))
        intersect[part] = solid & (inside[part] | crossed)
    return (intersect, inside) if return_vertex_inside else intersect


@dataclass(frozen=True, eq=False)
class EdgeFaceCrossings:
    """Edges of one tet crossing faces of the other, one row per (pair, edge, face).

    Attributes
    ----------
    pair : (k,) int64 -- the pair (row of ``a`` and ``b``)
    edge_in_b : (k,) bool -- True: an edge of ``b`` through a face of ``a``; False: an edge of ``a``
        through a face of ``b``
    edge : (k,) int64 -- the crossing edge, a row of ``meshing.mesh.TET_EDGES`` (local corners)
    face : (k,) int64 -- the face crossed, a row of ``meshing.mesh.TET_FACES`` (the face opposite
        corner ``face``)
    t : (k,) float -- where along the edge, 0 at ``TET_EDGES[edge, 0]``, 1 at the other end
    barycentric : (k, 3) float -- weights of the face's corners ``TET_FACES[face]`` there (>= 0, sum 1)
    point : (k, 3) float -- the crossing point [m]: the closest points of edge and face coincide there
    """

    pair: np.ndarray
    edge_in_b: np.ndarray
    edge: np.ndarray
    face: np.ndarray
    t: np.ndarray
    barycentric: np.ndarray
    point: np.ndarray

    @property
    def count(self) -> int:
        return len(self.pair)


def edge_face_crossings(a, b) -> EdgeFaceCrossings:
    """Every transversal crossing of an edge of one tet with a face of the other, over all pairs.

    A response needs them for the pairs :func:`tets_intersect` finds with no vertex inside (they
    have at least one crossing); for other pairs they are reported too, so the caller chooses.

    Parameters
    ----------
    a, b : (m, 4, 3) float
        Corners of the two tets of each pair [m].

    Returns
    -------
    EdgeFaceCrossings -- sorted by pair, then a's edges before b's, then edge, then face

    Examples
    --------
    The X of :func:`tets_intersect`: a's edge 0 enters b through face 2 and leaves through face 3, and
    b's edge 0 does the same through a:

    >>> import numpy as np
    >>> a = np.array([[[-2., 0, 0], [2, 0, 0], [0, 0.25, 1], [0, -0.25, 1]]])
    >>> b = np.array([[[0., -2, 0.5], [0, 2, 0.5], [0.25, 0, -0.5], [-0.25, 0, -0.5]]])
    >>> hits = edge_face_crossings(a, b)
    >>> hits.edge_in_b.tolist(), hits.edge.tolist(), hits.face.tolist()
    ([False, False, True, True], [0, 0, 0, 0], [2, 3, 2, 3])
    >>> hits.point.tolist()
    [[-0.125, 0.0, 0.0], [0.125, 0.0, 0.0], [0.0, -0.125, 0.5], [0.0, 0.125, 0.5]]
    """
    a, b = _check_corners(a, "a"), _check_corners(b, "b")
    if a.shape != b.shape:
        raise ValueError(f"a has shape {a.shape} but b has shape {b.shape}; expected the same (m, 4, 3)")
    rows = []
    for part in _chunks(len(a)):  # a loop over chunks of pairs, to bound memory
        _, _, _, a_through_b, b_through_a = _predicates(a[part], b[part])
        for in_b, (hit, start, end, cycle), edge_tet, face_tet in ((False, a_through_b, a[part], b[part]),
                                                                  (True, b_through_a, b[part], a[part])):
            pair, edge, face = np.nonzero(hit)
            s, e = start[pair, edge, face], end[pair, edge, face]
            t = s / (s - e)  # s and e are not both 0 (transversal) and not of one strict sign
            # Barycentric weight of v0 is the product against the opposite edge v1->v2, and so on.
            weights = cycle[pair, edge, face][:, [1, 2, 0]]
            weights = weights / weights.sum(axis=1, keepdims=True)
            ends = edge_tet[pair[:, None], TET_EDGES[edge]]  # (k, 2, 3)
            point = ends[:, 0] + t[:, None] * (ends[:, 1] - ends[:, 0])
            rows.append((pair + part.start, np.full(len(pair), in_b), edge, face, t, weights, point))
    columns = [np.concatenate([row[c] for row in rows]) for c in range(7)]
    order = np.lexsort((columns[3], columns[2], columns[1], columns[0]))
    return EdgeFaceCrossings(*(column[order] for column in columns))


# ---------------------------------------------------------------------- bodies
@dataclass(frozen=True, eq=False)
class TetPairs:
    """Intersecting tets of different bodies (or of one body, not sharing a node), each pair once.

    Attributes
    ----------
    tet_a, tet_b : (k,) int64 -- global tet ids, ``tet_a < tet_b``, sorted by (tet_a, tet_b)
    body_a, body_b : (k,) int64 -- their bodies
    vertex_inside : (k,) bool -- a vertex of one tet lies in the other; False where they meet only by
        edges crossing faces, the pairs :func:`~volspring.collision.detect_collisions` misses
    """

    tet_a: np.ndarray
    tet_b: np.ndarray
    body_a: np.ndarray
    body_b: np.ndarray
    vertex_inside: np.ndarray

    @property
    def count(self) -> int:
        return len(self.tet_a)


def crossing_tet_pairs(bodies, positions, *, cell_size=None, table_size=None, self_collision=False) -> TetPairs:
    """Every pair of intersecting tets of different bodies: spatial hash of tet boxes, then :func:`tets_intersect`.

    Parameters
    ----------
    bodies : CollisionBodies
    positions : (N, 3) float or sequence of (n_b, 3) float -- current node positions [m]
    cell_size : float, optional -- hash cell [m]; default the mean rest edge length
    table_size : int, optional -- hash buckets (default that of the vertex-in-tet detection)
    self_collision : bool -- also pairs of one body's tets that share no node

    Returns
    -------
    TetPairs

    Examples
    --------
    Two one-cell-thick slabs crossing like a plus sign: no vertex of either is inside the other, yet
    their tets intersect.

    >>> from meshing import structured_box
    >>> from volspring.collision import CollisionBodies, detect_collisions
    >>> flat = structured_box((4, 4, 1), (4.0, 4.0, 0.25))
    >>> upright = structured_box((1, 6, 1), (0.25, 6.0, 2.0), origin=(1.375, -1.0, -0.5))
    >>> bodies = CollisionBodies((flat, upright))
    >>> detect_collisions(bodies, bodies.rest_positions).count
    0
    >>> pairs = crossing_tet_pairs(bodies, bodies.rest_positions)
    >>> pairs.count > 0, bool(pairs.vertex_inside.any())
    (True, False)
    """
    from volspring.collision.spatial_hash import DEFAULT_TABLE_SIZE, SpatialHash

    x = bodies.stack_positions(positions)
    cell_size = bodies.mean_edge_length if cell_size is None else float(cell_size)
    corners = x[bodies.tets]
    lo, hi = corners.min(axis=1), corners.max(axis=1)
    tets = np.arange(bodies.tet_count)
    if not self_collision:  # only tets in the box of another body can meet it
        body_lo = np.minimum.reduceat(x, bodies.node_offsets[:-1], axis=0)
        body_hi = np.maximum.reduceat(x, bodies.node_offsets[:-1], axis=0)
        itself = np.eye(bodies.body_count, dtype=bool)[:, :, None]
        others_lo = np.where(itself, np.inf, body_lo[None]).min(axis=1)[bodies.tet_body]
        others_hi = np.where(itself, -np.inf, body_hi[None]).max(axis=1)[bodies.tet_body]
        tets = np.flatnonzero(((hi >= others_lo) & (lo <= others_hi)).all(axis=1))
    group = bodies.tet_body[tets]
    grid = SpatialHash.build(lo[tets], hi[tets], cell_size=cell_size, item_group=group,
                             table_size=DEFAULT_TABLE_SIZE if table_size is None else table_size)
    first, second = grid.query(lo[tets], hi[tets], query_group=group, rule="all" if self_collision else "other")
    keep = first < second  # each unordered pair was found from both sides
    tet_a, tet_b = tets[first[keep]], tets[second[keep]]
    if self_collision:
        shared = (bodies.tets[tet_a][:, :, None] == bodies.tets[tet_b][:, None, :]).any(axis=(1, 2))
        tet_a, tet_b = tet_a[~shared], tet_b[~shared]
    intersect, inside = tets_intersect(corners[tet_a], corners[tet_b], return_vertex_inside=True)
    tet_a, tet_b, inside = tet_a[intersect], tet_b[intersect], inside[intersect]
    order = np.lexsort((tet_b, tet_a))
    tet_a, tet_b, inside = tet_a[order], tet_b[order], inside[order]
    return TetPairs(tet_a, tet_b, bodies.tet_body[tet_a], bodies.tet_body[tet_b], inside)


@dataclass(frozen=True, eq=False)
class EdgeCrossingContacts:
    """Boundary edges of one body through boundary faces of another, as penalty contacts (one per edge and body).

    The contact pushes the edge's end on the inner side of the face's plane (``vertex``) out along the face's
    outward normal by ``depth``, and the face back through its nodes with the crossing point's weights.

    Attributes
    ----------
    vertex : (c,) int64 -- the edge's end behind the face (global id); ``other_end`` the edge's other end
    other_end : (c,) int64
    face : (c, 3) int64 -- the face's nodes, wound outward (global ids)
    barycentric : (c, 3) float -- weights of ``face``'s nodes at the crossing point (>= 0, sum 1)
    depth : (c,) float -- distance of ``vertex`` behind the face's plane [m], >= 0
    direction : (c, 3) float -- the face's outward unit normal
    vertex_body, face_body : (c,) int64
    """

    vertex: np.ndarray
    other_end: np.ndarray
    face: np.ndarray
    barycentric: np.ndarray
    depth: np.ndarray
    direction: np.ndarray
    vertex_body: np.ndarray
    face_body: np.ndarray

    @property
    def count(self) -> int:
        return len(self.vertex)


def edge_crossing_contacts(bodies, positions, pairs: TetPairs, *, colliding=None) -> EdgeCrossingContacts:
    """Penalty contacts of boundary edges crossing boundary faces of another body, from intersecting tet pairs.

    Every crossing of a boundary edge of body P with a boundary face of body Q lies in a pair of
    ``pairs`` (the edge's tet and the face's tet intersect there). For each (edge, Q) the crossing
    whose face leaves the least depth is kept: depth is how far the edge's end on the inner side of
    the face's plane is behind it, measured along the face's outward normal; pushing that end out by
    it takes the edge out through that face. For an edge through a thin part of Q this is the nearer
    of the two faces it crosses, the rule that resolves a slab's edge poking a short way through
    another slab. Edges with an end inside Q (``colliding``) are left to the vertex contacts.

    Parameters
    ----------
    bodies : CollisionBodies
    positions : (N, 3) float or sequence of (n_b, 3) float -- current node positions [m]
    pairs : TetPairs -- from :func:`crossing_tet_pairs` at these positions
    colliding : VertexTetContacts, optional -- vertex-in-tet contacts at these positions: an edge
        with an end inside the other body gets no edge contact there

    Returns
    -------
    EdgeCrossingContacts
    """
    x = bodies.stack_positions(positions)
    if not isinstance(pairs, TetPairs):
        raise TypeError(f"pairs must be TetPairs (from crossing_tet_pairs), got {type(pairs).__name__}")
    found = edge_face_crossings(x[bodies.tets[pairs.tet_a]], x[bodies.tets[pairs.tet_b]])
    edge_tet = np.where(found.edge_in_b, pairs.tet_b[found.pair], pairs.tet_a[found.pair])
    face_tet = np.where(found.edge_in_b, pairs.tet_a[found.pair], pairs.tet_b[found.pair])
    keep = bodies.tet_edge_on_boundary[edge_tet, found.edge] & bodies.tet_face_on_boundary[face_tet, found.face]
    ends = bodies.tets[edge_tet[:, None], TET_EDGES[found.edge]][keep]  # (k, 2)
    face = bodies.tets[face_tet[:, None], TET_FACES[found.face]][keep]  # (k, 3), outward wound
    weights, face_body = found.barycentric[keep], bodies.tet_body[face_tet[keep]]
    shared = (ends[:, :, None] == face[:, None, :]).any(axis=(1, 2))  # self-collision: adjacent features
    keep = ~shared
    if colliding is not None and colliding.count:
        inside = np.unique(colliding.vertex * bodies.body_count + colliding.tet_body)
        for end in range(2):  # the two ends of each edge
            keep &= ~np.isin(ends[:, end] * bodies.body_count + face_body, inside)
    ends, face, weights, face_body = ends[keep], face[keep], weights[keep], face_body[keep]
    corners = x[face]
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)  # a boundary face of a crossing is not flat
    height = np.einsum("kej,kj->ke", x[ends] - corners[:, None, 0], normal)  # (k, 2)
    behind = np.argmin(height, axis=1)
    depth = np.maximum(-height[np.arange(len(ends)), behind], 0.0)
    vertex, other_end = ends[np.arange(len(ends)), behind], ends[np.arange(len(ends)), 1 - behind]
    # One contact per (edge, penetrated body): the least depth.
    low, high = np.minimum(vertex, other_end), np.maximum(vertex, other_end)
    key = (low * bodies.node_count + high) * bodies.body_count + face_body
    order = np.lexsort((depth, key))
    first = order[np.r_[True, key[order][1:] != key[order][:-1]]] if len(key) else order
    weights = np.clip(weights[first], 0.0, None)
    weights /= weights.sum(axis=1, keepdims=True)
    return EdgeCrossingContacts(vertex[first], other_end[first], face[first], weights, depth[first], normal[first],
                                bodies.node_body[vertex[first]], face_body[first])
