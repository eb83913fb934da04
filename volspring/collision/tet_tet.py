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
from typing import TYPE_CHECKING, Literal, overload

if TYPE_CHECKING:
    from volspring.collision.bodies import CollisionBodies
    from volspring.collision.spatial_hash import VertexTetContacts

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

# Up to this many bodies crossing_tet_pairs hashes each body's tets against the later bodies' (each pair
# found once, b - 1 hashes); beyond, one hash of all, each pair found from both sides.
_ONE_WAY_BODIES = 8


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


# Corner layouts of the struct-of-arrays narrow phase: every array is (3 components, items, pairs), so each
# product below is one ufunc call over contiguous rows. The arithmetic is that of np.cross and of the
# einsum dot products this replaced, operand for operand and in the same order -- einsum sums three
# products as (p0 + p2) + p1 -- so every determinant, and every answer, is the same to the bit.
_FACE_BASE = np.array([1, 0, 0, 0])  # n_k = (t[_FACE_U[k]] - base_k) x (t[_FACE_V[k]] - base_k)
_FACE_U = np.array([3, 2, 3, 1])
_FACE_V = np.array([2, 3, 1, 2])
_EDGE_START, _EDGE_END = TET_EDGES[:, 0], TET_EDGES[:, 1]


def _dot(u, w):
    """``u . w`` over axis 0 (the components), summed as einsum sums them: (u0 w0 + u2 w2) + u1 w1."""
    return (u[0] * w[0] + u[2] * w[2]) + u[1] * w[1]


def _cross(u, w):
    """``u x w`` over axis 0, as np.cross computes it."""
    return np.stack([u[1] * w[2] - u[2] * w[1], u[2] * w[0] - u[0] * w[2], u[0] * w[1] - u[1] * w[0]])


def _norm(u):
    """``|u|`` over axis 0, as np.linalg.norm computes it: sqrt((u0^2 + u1^2) + u2^2)."""
    return np.sqrt((u[0] * u[0] + u[1] * u[1]) + u[2] * u[2])


@dataclass(frozen=True, eq=False)
class _Sides:
    """The determinants of one chunk of pairs that need no edge pair: (3, ...) coordinates, pairs last.

    ``a``, ``b`` (3, 4, m): corners, origin at a's first corner; ``normals_a``, ``normals_b`` (3, 4, m):
    ``n_k``, twice the area vector of face k, oriented so ``n_k . (t_k - base_k) = orientation``
    (``base_k`` = corner 1 for k = 0, else corner 0); ``b_against_a[v, k]`` (4, 4, m): the orientation of
    a with corner k replaced by b's vertex v, ``n_k . (b_v - base_k)``, and ``a_against_b`` likewise; ``solid`` (m,):
    neither tet flat; ``a_in_b`` (4, m), ``b_in_a`` (4, m): vertices (closed) inside the other tet.
    """

    a: np.ndarray
    b: np.ndarray
    normals_a: np.ndarray
    normals_b: np.ndarray
    b_against_a: np.ndarray
    a_against_b: np.ndarray
    solid: np.ndarray
    a_in_b: np.ndarray
    b_in_a: np.ndarray

    def take(self, rows):
        """The same for a subset of the pairs."""
        return _Sides(*(getattr(self, name)[..., rows] for name in self.__dataclass_fields__))


def _soa(corners):
    """(m, 4, 3) -> (3, 4, m), contiguous."""
    return np.ascontiguousarray(corners.transpose(2, 1, 0))


def _sides(a, b):
    """:class:`_Sides` of pairs of tets ``a``, ``b`` (m, 4, 3)."""
    origin = a[:, :1]
    a, b = _soa(a - origin), _soa(b - origin)
    halves = []
    for tet in (a, b):  # the face normals and orientation of each tet of the pairs
        base = tet[:, _FACE_BASE]
        normals = _cross(tet[:, _FACE_U] - base, tet[:, _FACE_V] - base)
        orientation = _dot(normals[:, 3], tet[:, 3] - tet[:, 0])  # n_3 = (t1 - t0) x (t2 - t0)
        halves.append((base, normals, np.sign(orientation)))
    (base_a, normals_a, sigma_a), (base_b, normals_b, sigma_b) = halves
    b_against_a = _dot(normals_a[:, None], b[:, :, None] - base_a[:, None])  # (4 b-vertices, 4 a-faces, m)
    a_against_b = _dot(normals_b[:, None], a[:, :, None] - base_b[:, None])
    solid = (sigma_a != 0) & (sigma_b != 0)
    a_in_b = (sigma_b * a_against_b >= 0).all(axis=1) & solid
    b_in_a = (sigma_a * b_against_a >= 0).all(axis=1) & solid
    return _Sides(a, b, normals_a, normals_b, b_against_a, a_against_b, solid, a_in_b, b_in_a)


def _transversal(plane_side, edge_tet, face_normals):
    """(6, 4, m) bool: an edge of the edge tet (3, 4, m) crosses the plane of a face of the other, not
    within NEAR_COPLANAR of parallel to it; with the plane sides of the edges' starts and ends (6, 4, m)."""
    start, end = plane_side[_EDGE_START], plane_side[_EDGE_END]
    # start - end = n_k . (edge's start - end): |d| |n_k| times the sine of the edge's angle to the plane.
    length = _norm(edge_tet[:, _EDGE_END] - edge_tet[:, _EDGE_START])  # (6, m)
    steep = np.abs(start - end) > NEAR_COPLANAR * length[:, None] * _norm(face_normals)[None]
    return (np.sign(start) * np.sign(end) <= 0) & steep, start, end


def _edge_sides(a, b):
    """``S[i, j]`` = orient(a_i0, a_i1, b_j0, b_j1) for the TET_EDGES of a and b (3, 4, m): (6, 6, m) (Pluecker)."""
    da, db = a[:, _EDGE_END] - a[:, _EDGE_START], b[:, _EDGE_END] - b[:, _EDGE_START]
    ma, mb = _cross(a[:, _EDGE_START], a[:, _EDGE_END]), _cross(b[:, _EDGE_START], b[:, _EDGE_END])
    return _dot(da[:, :, None], mb[:, None]) + _dot(ma[:, :, None], db[:, None])


def _cycle(edge_side):
    """(6, 4, 3, m): the signed products of each edge against each face's cycle v0->v1, v1->v2, v2->v0,
    from ``edge_side[i, j]``, edge tet's edge i against face tet's edge j (6, 6, m)."""
    return edge_side[:, _CYCLE_EDGES] * _CYCLE_SIGNS[:, :, None]


def _through(cycle):
    """(6, 4, m) bool: the edge's line passes through the face triangle (its boundary included)."""
    return (cycle >= 0).all(axis=2) | (cycle <= 0).all(axis=2)


def _chunks(count):
    return [slice(start, min(start + _CHUNK, count)) for start in range(0, count, _CHUNK)] or [slice(0, 0)]


@overload
def tets_intersect(a: np.ndarray, b: np.ndarray, *, return_vertex_inside: Literal[False] = ...) -> np.ndarray: ...
@overload
def tets_intersect(a: np.ndarray, b: np.ndarray, *,
                   return_vertex_inside: Literal[True]) -> tuple[np.ndarray, np.ndarray]: ...
@overload
def tets_intersect(a: np.ndarray, b: np.ndarray, *,
                   return_vertex_inside: bool = ...) -> np.ndarray | tuple[np.ndarray, np.ndarray]: ...
def tets_intersect(a: np.ndarray, b: np.ndarray, *,
                   return_vertex_inside: bool = False) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
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
        sides = _sides(a[part], b[part])
        inside[part] = sides.a_in_b.any(axis=0) | sides.b_in_a.any(axis=0)
        crossed = np.zeros(part.stop - part.start, dtype=bool)
        # Edges through faces decide only pairs with no vertex inside, and only where an edge crosses a plane.
        rest = np.flatnonzero(sides.solid & ~inside[part])
        if len(rest):
            sides = sides.take(rest)
            a_plane = _transversal(sides.a_against_b, sides.a, sides.normals_b)[0]
            b_plane = _transversal(sides.b_against_a, sides.b, sides.normals_a)[0]
            maybe = np.flatnonzero(a_plane.any(axis=(0, 1)) | b_plane.any(axis=(0, 1)))
            edge_side = _edge_sides(sides.a[..., maybe], sides.b[..., maybe])
            a_through_b = a_plane[..., maybe] & _through(_cycle(edge_side))
            b_through_a = b_plane[..., maybe] & _through(_cycle(edge_side.transpose(1, 0, 2)))
            crossed[rest[maybe]] = a_through_b.any(axis=(0, 1)) | b_through_a.any(axis=(0, 1))
        intersect[part] = inside[part] | crossed  # both imply solid
    return (intersect, inside) if return_vertex_inside else intersect


@dataclass(frozen=True, eq=False)
class EdgeFaceCrossings:
    """Edges of one tet crossing faces of the other, one row per (pair, edge, face).

    Attributes
    ----------
    pair : (k,) int64
        the pair (row of ``a`` and ``b``)
    edge_in_b : (k,) bool
        True: an edge of ``b`` through a face of ``a``; False: an edge of ``a`` through a face of ``b``
    edge : (k,) int64
        the crossing edge, a row of ``meshing.mesh.TET_EDGES`` (local corners)
    face : (k,) int64
        the face crossed, a row of ``meshing.mesh.TET_FACES`` (the face opposite corner ``face``)
    t : (k,) float
        where along the edge, 0 at ``TET_EDGES[edge, 0]``, 1 at the other end
    barycentric : (k, 3) float
        weights of the face's corners ``TET_FACES[face]`` there (>= 0, sum 1)
    point : (k, 3) float
        the crossing point [m]: the closest points of edge and face coincide there
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


def edge_face_crossings(a: np.ndarray, b: np.ndarray) -> EdgeFaceCrossings:
    """Every transversal crossing of an edge of one tet with a face of the other, over all pairs.

    A response needs them for the pairs :func:`tets_intersect` finds with no vertex inside (they
    have at least one crossing); for other pairs they are reported too, so the caller chooses.

    Parameters
    ----------
    a, b : (m, 4, 3) float
        Corners of the two tets of each pair [m].

    Returns
    -------
    EdgeFaceCrossings
        sorted by pair, then a's edges before b's, then edge, then face

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
    columns = _edge_face_rows(a, b)
    order = np.lexsort((columns[3], columns[2], columns[1], columns[0]))
    return EdgeFaceCrossings(*(column[order] for column in columns))


def _edge_face_rows(a, b, wanted=None):
    """The columns of :class:`EdgeFaceCrossings` in no set order; ``wanted`` (m, 2, 6, 4) bool, optional:
    only the crossings of a's edges through b's faces (``[:, 0, edge, face]``) and of b's through a's
    (``[:, 1]``) that it marks."""
    rows = []
    for part in _chunks(len(a)):  # a loop over chunks of pairs, to bound memory
        pairs = np.arange(part.start, part.stop)
        if wanted is not None:
            pairs = pairs[wanted[part].any(axis=(1, 2, 3))]
        sides = _sides(a[pairs], b[pairs])
        a_plane, a_start, a_end = _transversal(sides.a_against_b, sides.a, sides.normals_b)
        b_plane, b_start, b_end = _transversal(sides.b_against_a, sides.b, sides.normals_a)
        if wanted is not None:
            a_plane &= wanted[pairs, 0].transpose(1, 2, 0)
            b_plane &= wanted[pairs, 1].transpose(1, 2, 0)
        maybe = np.flatnonzero(a_plane.any(axis=(0, 1)) | b_plane.any(axis=(0, 1)))
        edge_side = _edge_sides(sides.a[..., maybe], sides.b[..., maybe])
        for in_b, plane, start, end, side, edge_tet in ((False, a_plane, a_start, a_end, edge_side, a),
                                                        (True, b_plane, b_start, b_end, edge_side.transpose(1, 0, 2),
                                                         b)):
            cycle = _cycle(side)  # (6, 4, 3, k)
            edge, face, pair = np.nonzero(plane[..., maybe] & _through(cycle))
            s, e = start[edge, face, maybe[pair]], end[edge, face, maybe[pair]]
            t = s / (s - e)  # s and e are not both 0 (transversal) and not of one strict sign
            # Barycentric weight of v0 is the product against the opposite edge v1->v2, and so on.
            weights = cycle[edge, face, :, pair][:, [1, 2, 0]]
            weights = weights / weights.sum(axis=1, keepdims=True)
            pair = pairs[maybe[pair]]
            ends = edge_tet[pair[:, None], TET_EDGES[edge]]  # (k, 2, 3)
            point = ends[:, 0] + t[:, None] * (ends[:, 1] - ends[:, 0])
            rows.append((pair, np.full(len(pair), in_b), edge, face, t, weights, point))
    return [np.concatenate([row[c] for row in rows]) for c in range(7)]


# ---------------------------------------------------------------------- bodies
@dataclass(frozen=True, eq=False)
class TetPairs:
    """Intersecting tets of different bodies (or of one body, not sharing a node), each pair once.

    Attributes
    ----------
    tet_a, tet_b : (k,) int64
        global tet ids, ``tet_a < tet_b``, sorted by (tet_a, tet_b)
    body_a, body_b : (k,) int64
        their bodies
    vertex_inside : (k,) bool
        a vertex of one tet lies in the other; False where they meet only by edges crossing faces, the pairs
        :func:`~volspring.collision.detect_collisions` misses
    """

    tet_a: np.ndarray
    tet_b: np.ndarray
    body_a: np.ndarray
    body_b: np.ndarray
    vertex_inside: np.ndarray

    @property
    def count(self) -> int:
        return len(self.tet_a)


def crossing_tet_pairs(bodies: CollisionBodies, positions: np.ndarray, *, cell_size: float | None = None,
                       table_size: int | None = None, self_collision: bool = False, boundary: bool = False) -> TetPairs:
    """Every pair of intersecting tets of different bodies: spatial hash of tet boxes, then :func:`tets_intersect`.

    Parameters
    ----------
    bodies : CollisionBodies
    positions : (N, 3) float or sequence of (n_b, 3) float
        current node positions [m]
    cell_size : float, optional
        hash cell [m]; default the mean rest edge length
    table_size : int, optional
        hash buckets (default that of the vertex-in-tet detection)
    self_collision : bool
        also pairs of one body's tets that share no node
    boundary : bool
        only the pairs that can hold a boundary edge of one tet crossing a boundary face of the other
        (``bodies.tet_edge_on_boundary``, ``bodies.tet_face_on_boundary``): all that :func:`edge_crossing_contacts`
        uses, so it gives the same contacts from them, at a fraction of the cost (interior tets never enter the hash)

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
    >>> crossing_tet_pairs(bodies, bodies.rest_positions, boundary=True).count <= pairs.count
    True
    """
    from volspring.collision.spatial_hash import DEFAULT_TABLE_SIZE, box_pairs

    x = bodies.stack_positions(positions)
    cell_size = bodies.mean_edge_length if cell_size is None else float(cell_size)
    table_size = DEFAULT_TABLE_SIZE if table_size is None else table_size
    corners = x[bodies.tets]
    lo, hi = corners.min(axis=1), corners.max(axis=1)
    candidate = np.ones(bodies.tet_count, dtype=bool)
    if boundary:  # a tet with a boundary face has boundary edges too
        edged, faced = np.any(bodies.tet_edge_on_boundary, axis=1), np.any(bodies.tet_face_on_boundary, axis=1)
        candidate = edged
    if not self_collision:  # only tets in the box of another body can meet it
        body_lo = np.minimum.reduceat(x, bodies.node_offsets[:-1], axis=0)
        body_hi = np.maximum.reduceat(x, bodies.node_offsets[:-1], axis=0)
        itself = np.eye(bodies.body_count, dtype=bool)[:, :, None]
        others_lo = np.where(itself, np.inf, body_lo[None]).min(axis=1)[bodies.tet_body]
        others_hi = np.where(itself, -np.inf, body_hi[None]).max(axis=1)[bodies.tet_body]
        candidate &= ((hi >= others_lo) & (lo <= others_hi)).all(axis=1)
    tets = np.flatnonzero(candidate)
    group = bodies.tet_body[tets]
    if not self_collision and bodies.body_count <= _ONE_WAY_BODIES:
        # Each pair once: body k's tets against a hash of the later bodies' tets (a query of all against all
        # finds each pair from both sides, twice the work).
        found = []
        for k in range(bodies.body_count - 1):  # a loop over the few bodies
            mine, later = tets[group == k], tets[group > k]
            if len(mine) and len(later):
                first, second = box_pairs(lo[later], hi[later], lo[mine], hi[mine], cell_size=cell_size,
                                          table_size=table_size)
                found.append((mine[first], later[second]))
        tet_a = np.concatenate([np.zeros(0, np.int64)] + [pair[0] for pair in found])
        tet_b = np.concatenate([np.zeros(0, np.int64)] + [pair[1] for pair in found])
    else:
        first, second = box_pairs(lo[tets], hi[tets], lo[tets], hi[tets], cell_size=cell_size, table_size=table_size,
                                  item_group=group, query_group=group, rule="all" if self_collision else "other")
        keep = first < second  # each unordered pair was found from both sides
        tet_a, tet_b = tets[first[keep]], tets[second[keep]]
    if boundary:  # an edge of one through a face of the other
        useful = (edged[tet_a] & faced[tet_b]) | (faced[tet_a] & edged[tet_b])
        tet_a, tet_b = tet_a[useful], tet_b[useful]
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
    vertex : (c,) int64
        the edge's end behind the face (global id); ``other_end`` the edge's other end
    other_end : (c,) int64
    face : (c, 3) int64
        the face's nodes, wound outward (global ids)
    barycentric : (c, 3) float
        weights of ``face``'s nodes at the crossing point (>= 0, sum 1)
    depth : (c,) float
        distance of ``vertex`` behind the face's plane [m], >= 0
    direction : (c, 3) float
        the face's outward unit normal
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


def edge_crossing_contacts(bodies: CollisionBodies, positions: np.ndarray, pairs: TetPairs, *,
                           colliding: VertexTetContacts | None = None) -> EdgeCrossingContacts:
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
    positions : (N, 3) float or sequence of (n_b, 3) float
        current node positions [m]
    pairs : TetPairs
        from :func:`crossing_tet_pairs` at these positions
    colliding : VertexTetContacts, optional
        vertex-in-tet contacts at these positions: an edge with an end inside the other body gets no edge contact there

    Returns
    -------
    EdgeCrossingContacts
    """
    x = bodies.stack_positions(positions)
    if not isinstance(pairs, TetPairs):
        raise TypeError(f"pairs must be TetPairs (from crossing_tet_pairs), got {type(pairs).__name__}")
    # Only boundary edges through boundary faces, of edges with no end inside the face's body (colliding):
    # the narrow phase looks at those (edge, face) combinations alone, in the pairs that have any.
    wanted = np.empty((pairs.count, 2, 6, 4), dtype=bool)
    inside = None
    if colliding is not None and colliding.count:
        inside = np.unique(colliding.vertex * bodies.body_count + colliding.tet_body)
    for side, (edge_tet, face_tet) in enumerate(((pairs.tet_a, pairs.tet_b), (pairs.tet_b, pairs.tet_a))):
        edges = bodies.tet_edge_on_boundary[edge_tet]  # (m, 6)
        if inside is not None:
            keys = bodies.tets[edge_tet][:, TET_EDGES] * bodies.body_count + bodies.tet_body[face_tet][:, None, None]
            edges = edges & ~np.isin(keys, inside).any(axis=2)
        wanted[:, side] = edges[:, :, None] & bodies.tet_face_on_boundary[face_tet][:, None, :]
    corners_a, corners_b = x[bodies.tets[pairs.tet_a]], x[bodies.tets[pairs.tet_b]]
    pair, edge_in_b, edge, face, _, weights, _ = _edge_face_rows(corners_a, corners_b, wanted)
    order = np.lexsort((face, edge, edge_in_b, pair))  # the order edge_face_crossings gives
    pair, edge_in_b, edge, face, weights = pair[order], edge_in_b[order], edge[order], face[order], weights[order]
    edge_tet = np.where(edge_in_b, pairs.tet_b[pair], pairs.tet_a[pair])
    face_tet = np.where(edge_in_b, pairs.tet_a[pair], pairs.tet_b[pair])
    ends = bodies.tets[edge_tet[:, None], TET_EDGES[edge]]  # (k, 2)
    face = bodies.tets[face_tet[:, None], TET_FACES[face]]  # (k, 3), outward wound
    face_body = bodies.tet_body[face_tet]
    keep = ~(ends[:, :, None] == face[:, None, :]).any(axis=(1, 2))  # self-collision: adjacent features
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
