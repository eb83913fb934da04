"""Faces of a closed triangle surface that cut through each other: the self-intersection test of
:func:`meshing.surface.load_surface`, which refuses such a surface.

A broad phase bins the faces on a grid of cells about one face across and keeps the pairs of faces
that share a cell and no vertex and whose bounding boxes overlap; the exact tests then run on those
pairs at once (:func:`_faces_cross`, and for exact contacts between bodies the nudges of
:data:`_NUDGE_DIRECTIONS`). Signed volumes are :func:`meshing.geometry.signed_volumes`, the flat-tet
rule and the nudge size :mod:`meshing.tolerances`.
"""

from __future__ import annotations

import numpy as np

from meshing.geometry import signed_volumes
from meshing.tolerances import CONTACT_NUDGE, ZERO_VOLUME

__all__: list[str] = []

#: The directions of the moves that decide exact contacts (their size is meshing.tolerances.CONTACT_NUDGE):
#: three fixed generic ones (the rows of a rotation parallel to no axis or
#: diagonal of a hand-made surface), each also taken the other way round.
_NUDGE_DIRECTIONS = np.linalg.qr(np.array([[0.9134, 0.2331, -0.3337], [-0.1822, 0.9614, 0.2061],
                                           [0.3627, -0.1438, 0.9207]]))[0]


def _crossing_face_pairs(mesh) -> np.ndarray:
    """(k, 2) int64 -- the pairs of faces of ``mesh`` (a ``trimesh.Trimesh``) that cut through each other,
    in increasing order; faces sharing a vertex are not tested.

    Two tests, on the pairs of faces whose bounding boxes overlap:

    - An edge of one face passing strictly through the other (:func:`_edges_cross`): any crossing in
      general position, within one body or between bodies.
    - Between two bodies (connected parts), exact contacts decided by nudging: boxes offset by half their
      size cross only on the diagonals that split their square sides, and overlapping boxes can share
      side planes, where no crossing is strict. Each body pair is tested again with one body moved by
      :data:`~meshing.tolerances.CONTACT_NUDGE` of the pair's size, along each of :data:`_NUDGE_DIRECTIONS`
      and their opposites. An overlap of some volume survives every such move; bodies that only touch (a side
      lying against a side) come apart under at least one, and pass.
    """
    tri = mesh.triangles
    low, high = tri.min(axis=1), tri.max(axis=1)
    cell = float(np.median((high - low).max(axis=1))) or 1.0
    origin = low.min(axis=0)
    first_cell = np.floor((low - origin) / cell).astype(np.int64)
    span = np.floor((high - origin) / cell).astype(np.int64) - first_cell + 1
    # Broad phase: each face goes into every grid cell its bounding box covers.
    count = span.prod(axis=1)
    face = np.repeat(np.arange(len(tri)), count)
    local = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
    sx, sy = np.repeat(span[:, 0], count), np.repeat(span[:, 1], count)
    ijk = np.repeat(first_cell, count, axis=0) + np.stack([local % sx, (local // sx) % sy, local // (sx * sy)], 1)
    dims = ijk.max(axis=0) + 1
    key = np.ravel_multi_index(ijk.T, dims)
    order = np.lexsort((face, key))
    key, face = key[order], face[order]
    # Candidate pairs: faces in the same cell (within runs of equal keys).
    starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
    sizes = np.diff(np.r_[starts, len(key)])
    a_list, b_list = [], []
    for offset in range(1, int(sizes.max()) if len(sizes) else 1):
        same = np.flatnonzero(np.r_[key[offset:] == key[:-offset], np.zeros(offset, bool)])
        a_list.append(face[same])
        b_list.append(face[same + offset])
    if not a_list:
        return np.zeros((0, 2), dtype=np.int64)
    a, b = np.concatenate(a_list), np.concatenate(b_list)
    pair_key = np.unique(np.minimum(a, b) * len(tri) + np.maximum(a, b))  # 1D keys: np.unique(axis=0) is slow
    pairs = np.stack([pair_key // len(tri), pair_key % len(tri)], axis=1)
    fa, fb = mesh.faces[pairs[:, 0]], mesh.faces[pairs[:, 1]]
    disjoint = ~(fa[:, :, None] == fb[:, None, :]).any(axis=(1, 2))
    overlap = (low[pairs[:, 0]] <= high[pairs[:, 1]]).all(1) & (low[pairs[:, 1]] <= high[pairs[:, 0]]).all(1)
    pairs = pairs[disjoint & overlap]
    if len(pairs) == 0:
        return np.zeros((0, 2), dtype=np.int64)
    first_tri, second_tri = tri[pairs[:, 0]], tri[pairs[:, 1]]
    hit = _faces_cross(first_tri, second_tri)
    body = _body_labels(mesh)
    between = np.flatnonzero(body[pairs[:, 0]] != body[pairs[:, 1]])
    if not hit.any() and len(between):
        first_body, second_body = body[pairs[between, 0]], body[pairs[between, 1]]
        body_pair = np.minimum(first_body, second_body) * (body.max() + 1) + np.maximum(first_body, second_body)
        # Move the body with the larger label by `step` relative to the other; `size` is the pair's extent.
        sign = np.sign(first_body - second_body).astype(np.float64)
        size = np.ptp(np.concatenate([first_tri[between], second_tri[between]], axis=1), axis=1).max(axis=1)
        overlapping, first_move = np.unique(body_pair), None
        for direction in np.concatenate([_NUDGE_DIRECTIONS, -_NUDGE_DIRECTIONS]):  # six moves, not a loop over faces
            step = (CONTACT_NUDGE * sign * size)[:, None, None] * direction
            crossing = _faces_cross(first_tri[between] + step, second_tri[between])
            overlapping = np.intersect1d(overlapping, body_pair[crossing])
            first_move = crossing if first_move is None else first_move
        assert first_move is not None  # set by the first of the six moves
        hit[between] = first_move & np.isin(body_pair, overlapping)
    return pairs[hit]


def _body_labels(mesh) -> np.ndarray:
    """(f,) int -- the connected part (faces joined across edges) each face belongs to."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    adjacency = mesh.face_adjacency
    graph = coo_matrix((np.ones(len(adjacency)), (adjacency[:, 0], adjacency[:, 1])),
                       shape=(len(mesh.faces), len(mesh.faces)))
    return connected_components(graph, directed=False)[1]


def _faces_cross(first, second):
    """(p,) bool -- whether an edge of either triangle of each pair passes strictly through the other."""
    return _edges_cross(first, second) | _edges_cross(second, first)


def _edges_cross(edge_triangles, triangles):
    """(p,) bool -- whether an edge of ``edge_triangles[i]`` passes strictly through ``triangles[i]``.

    Strictly: its ends lie on opposite sides of the triangle's plane and the line through it passes
    each edge of the triangle on the same turning side, all with signed volumes beyond the flat-tet
    rule (:data:`meshing.tolerances.ZERO_VOLUME`): four points are coplanar when the tet they span is flat.
    An edge that touches the plane with an end, lies in it, or meets the triangle exactly on its boundary
    does not count here (see :func:`_crossing_face_pairs`).
    """
    a, b, c = triangles[:, 0], triangles[:, 1], triangles[:, 2]
    corners = np.concatenate([edge_triangles, triangles], axis=1)
    tolerance = ZERO_VOLUME * np.ptp(corners, axis=1).max(axis=1) ** 3
    hit = np.zeros(len(triangles), dtype=bool)
    for start, end in ((0, 1), (1, 2), (2, 0)):  # the three edges, not a loop over faces
        p, q = edge_triangles[:, start], edge_triangles[:, end]
        side_p, side_q = signed_volumes(a, b, c, p), signed_volumes(a, b, c, q)
        through_plane = ((side_p > tolerance) & (side_q < -tolerance)) | ((side_p < -tolerance) & (side_q > tolerance))
        turns = np.stack([signed_volumes(p, q, a, b), signed_volumes(p, q, b, c), signed_volumes(p, q, c, a)])
        inside = (turns > tolerance).all(axis=0) | (turns < -tolerance).all(axis=0)
        hit |= through_plane & inside
    return hit
