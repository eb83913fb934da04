"""Vectorised triangle geometry: normals, segment hits and closest points on triangle sets."""

from __future__ import annotations

import numpy as np

__all__ = [
    "area_weighted_vertex_normals",
    "closest_points_on_triangles",
    "nearest_surface_points",
    "segment_triangle_intersections",
]

# Barycentric slack of a segment-triangle hit: a segment through a shared edge or vertex of two
# triangles must hit at least one of them despite round-off (|u| ~ 1e-16 there); 1e-10 is far
# above round-off and far below any meaningful fraction of a triangle.
HIT_TOLERANCE = 1e-10


# Point-triangle pairs evaluated at once in nearest_surface_points (~100 MB of temporaries).
_PAIRS_PER_CHUNK = 500_000


def _dot(a, b):
    return np.einsum("...i,...i->...", a, b)


def area_weighted_vertex_normals(points, faces, *, node_count=None) -> np.ndarray:
    """Unit vertex normals, each the area-weighted mean of the normals of the faces around it.

    Parameters
    ----------
    points : (n, 3) float -- node positions [m]
    faces : (f, 3) int -- outward-wound triangles
    node_count : int, optional -- rows of the result (default ``len(points)``)

    Returns
    -------
    (n, 3) float -- unit normals; zero rows for nodes on no face
    """
    node_count = len(points) if node_count is None else node_count
    x = points[faces]
    doubled_area_normal = np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])  # |.| = 2 * area
    normals = np.zeros((node_count, 3))
    for axis in range(3):  # three bincounts, one per coordinate
        normals[:, axis] = np.bincount(faces.ravel(), np.repeat(doubled_area_normal[:, axis], 3), node_count)
    length = np.linalg.norm(normals, axis=1, keepdims=True)
    return np.divide(normals, length, out=np.zeros_like(normals), where=length > 0)


def segment_triangle_intersections(start, end, v0, v1, v2, *, tolerance=HIT_TOLERANCE):
    """Moeller-Trumbore intersection of segments with triangles, pairwise.

    Parameters
    ----------
    start, end : (k, 3) float -- segment end points [m]
    v0, v1, v2 : (k, 3) float -- triangle corners [m]
    tolerance : float -- barycentric slack for hits on triangle edges (dimensionless)

    Returns
    -------
    hit : (k,) bool -- the segment meets the triangle (parallel segments never hit)
    t : (k,) float -- hit parameter along the segment, 0 at ``start``, 1 at ``end``
    barycentric : (k, 3) float -- weights of v0, v1, v2 at the hit point
    """
    direction = end - start
    e1, e2 = v1 - v0, v2 - v0
    p = np.cross(direction, e2)
    det = _dot(e1, p)
    # Parallel: |det| is |direction| |e1| |e2| times a sine; below 1e-12 of that product is round-off.
    scale = np.linalg.norm(direction, axis=1) * np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1)
    ok = np.abs(det) > 1e-12 * scale
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = start - v0
    u = _dot(s, p) * inv
    q = np.cross(s, e1)
    v = _dot(direction, q) * inv
    t = _dot(e2, q) * inv
    hit = ok & (u >= -tolerance) & (v >= -tolerance) & (u + v <= 1 + tolerance) & (t >= 0) & (t <= 1)
    return hit, t, np.stack([1.0 - u - v, u, v], axis=1)


def closest_points_on_triangles(p, a, b, c) -> tuple[np.ndarray, np.ndarray]:
    """Closest point on each triangle to each point, pairwise (Ericson, Real-Time Collision Detection 5.1.5).

    Parameters
    ----------
    p : (k, 3) float -- query points [m]
    a, b, c : (k, 3) float -- triangle corners [m]

    Returns
    -------
    closest : (k, 3) float -- closest points [m]
    barycentric : (k, 3) float -- their weights on (a, b, c); exactly 0 for a corner or edge region
        (two zeros: a corner; one zero: an edge)
    """
    ab, ac, ap, bp, cp = b - a, c - a, p - a, p - b, p - c
    d1, d2, d3, d4, d5, d6 = _dot(ab, ap), _dot(ac, ap), _dot(ab, bp), _dot(ac, bp), _dot(ab, cp), _dot(ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = va + vb + vc
        bary = np.stack([va / denom, vb / denom, vc / denom], axis=1)  # interior region
        # Regions in reverse order of Ericson's tests, so that his first matching test wins.
        w = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        region = (va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0)
        bary[region] = np.stack([0 * w, 1 - w, w], axis=1)[region]
        w = d2 / (d2 - d6)
        region = (vb <= 0) & (d2 >= 0) & (d6 <= 0)
        bary[region] = np.stack([1 - w, 0 * w, w], axis=1)[region]
        bary[(d6 >= 0) & (d5 <= d6)] = (0.0, 0.0, 1.0)
        v = d1 / (d1 - d3)
        region = (vc <= 0) & (d1 >= 0) & (d3 <= 0)
        bary[region] = np.stack([1 - v, v, 0 * v], axis=1)[region]
        bary[(d3 >= 0) & (d4 <= d3)] = (0.0, 1.0, 0.0)
        bary[(d1 <= 0) & (d2 <= 0)] = (1.0, 0.0, 0.0)
    # A degenerate (zero-area) triangle leaves NaN in the interior branch only if no region matched.
    bary = np.where(np.isfinite(bary).all(axis=1, keepdims=True), bary, (1.0, 0.0, 0.0))
    closest = bary[:, :1] * a + bary[:, 1:2] * b + bary[:, 2:] * c
    return closest, bary


def nearest_surface_points(points, vertices, faces, *, tree=None):
    """Exact nearest point of a triangle set to each query point.

    A KD-tree over the triangle centroids proposes the ``k`` nearest triangles; a point is settled
    once its ``k``-th centroid is farther than (best distance found + the largest centroid-to-corner
    radius), since no triangle outside the ``k`` can then be closer. ``k`` grows fourfold for the
    points not yet settled: the loop runs over rounds, never over points.

    Parameters
    ----------
    points : (k, 3) float -- query points [m]
    vertices : (v, 3) float -- triangle corners [m]
    faces : (f, 3) int -- triangles
    tree : scipy.spatial.cKDTree, optional -- prebuilt tree over the face centroids (static meshes)

    Returns
    -------
    face : (k,) int64 -- the nearest triangle
    closest : (k, 3) float -- the nearest point on it [m]
    barycentric : (k, 3) float -- its weights on the triangle's corners
    distance : (k,) float -- ``|closest - point|`` [m]
    """
    from scipy.spatial import cKDTree

    points = np.asarray(points, dtype=np.float64)
    corners = vertices[faces]
    centroids = corners.mean(axis=1)
    radius = np.linalg.norm(corners - centroids[:, None], axis=2).max()
    tree = cKDTree(centroids) if tree is None else tree
    face = np.zeros(len(points), dtype=np.int64)
    closest = np.zeros((len(points), 3))
    barycentric = np.zeros((len(points), 3))
    distance = np.zeros(len(points))
    todo = np.arange(len(points))
    k = min(8, len(faces))
    while len(todo):
        unsettled = []
        chunk = max(1, _PAIRS_PER_CHUNK // k)
        for begin in range(0, len(todo), chunk):  # bounded memory: chunks of points, not one point at a time
            rows = todo[begin:begin + chunk]
            centroid_distance, candidate = tree.query(points[rows], k=k)
            centroid_distance = centroid_distance.reshape(len(rows), k)
            flat = candidate.reshape(-1)
            query = np.repeat(points[rows], k, axis=0)
            near, bary = closest_points_on_triangles(query, *(corners[flat, i] for i in range(3)))
            dist = np.linalg.norm(near - query, axis=1).reshape(len(rows), k)
            best = dist.argmin(axis=1)
            best_distance = dist[np.arange(len(rows)), best]
            pick = np.arange(len(rows)) * k + best
            settled = (k == len(faces)) | (centroid_distance[:, -1] > best_distance + radius)
            done = rows[settled]
            face[done] = flat[pick[settled]]
            closest[done] = near[pick[settled]]
            barycentric[done] = bary[pick[settled]]
            distance[done] = best_distance[settled]
            unsettled.append(rows[~settled])
        todo = np.concatenate(unsettled)
        k = min(4 * k, len(faces))
    return face, closest, barycentric, distance
