"""Triangle kernels: area normals, vertex normals, and closest points on triangles and triangle sets.

- :func:`triangle_area_normals`: twice the area times the unit normal of each triangle.
- :func:`area_weighted_vertex_normals`: unit vertex normals, area-weighted over the triangles around.
- :func:`closest_points_on_triangles`: the closest point on each triangle to each point, pairwise
  (Ericson's Voronoi regions).
- :func:`nearest_surface_points`: the exact nearest point of a triangle set, through a k-d tree over the
  face centroids.

Re-exported by :mod:`meshing.geometry`, the path callers import them from; the tolerances are
:mod:`meshing.tolerances`.
"""

from __future__ import annotations

import numpy as np

from meshing.tolerances import CANCELLED
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from numpy.typing import ArrayLike
    from scipy.spatial import cKDTree

__all__ = ["area_weighted_vertex_normals", "closest_points_on_triangles", "nearest_surface_points",
           "triangle_area_normals"]

# Point-triangle pairs evaluated at once in nearest_surface_points (~100 MB of temporaries).
_PAIRS_PER_CHUNK = 500_000


def _dot(a, b):
    return np.einsum("...i,...i->...", a, b)


def triangle_area_normals(points: ArrayLike, faces: ArrayLike) -> np.ndarray:
    """(f, 3) float -- ``(x1 - x0) x (x2 - x0)`` per triangle: twice its area [m^2] times its right-hand unit normal.

    Examples
    --------
    >>> import numpy as np
    >>> triangle_area_normals(np.array([[0., 0, 0], [2, 0, 0], [0, 1, 0]]), np.array([[0, 1, 2]]))
    array([[0., 0., 2.]])
    """
    x = np.asarray(points)[np.asarray(faces)]
    return np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])


def area_weighted_vertex_normals(points: np.ndarray, faces: ArrayLike, *, node_count: int | None = None) -> np.ndarray:
    """Unit vertex normals, each the area-weighted mean of the normals of the triangles around the vertex.

    Parameters
    ----------
    points : (n, 3) float
        Vertex positions [m].
    faces : (f, 3) int
        Triangles, wound outward (right-hand normals point out).
    node_count : int, optional
        Rows of the result (default ``len(points)``).

    Returns
    -------
    (node_count, 3) float
        Unit normals; zero rows for vertices on no triangle, and for vertices whose triangles' normals cancel
        (summed length at most :data:`meshing.tolerances.CANCELLED` of their summed areas), which have none.

    Examples
    --------
    >>> import numpy as np
    >>> points = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    >>> faces = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])   # a tet's outward faces
    >>> (area_weighted_vertex_normals(points, faces)[0] * np.sqrt(3)).round(12)   # the corner points away
    array([-1., -1., -1.])
    """
    faces = np.asarray(faces)
    node_count = len(points) if node_count is None else node_count
    cross = triangle_area_normals(points, faces)
    corner_vertex = faces.ravel()
    summed = np.stack([np.bincount(corner_vertex, np.repeat(cross[:, axis], 3), node_count) for axis in range(3)],
                      axis=1)
    length = np.linalg.norm(summed, axis=1)
    area = np.bincount(corner_vertex, np.repeat(np.linalg.norm(cross, axis=1), 3), node_count)
    has_normal = (length > CANCELLED * area)[:, None]
    return np.divide(summed, length[:, None], out=np.zeros_like(summed), where=has_normal)


def closest_points_on_triangles(p: np.ndarray, a: np.ndarray, b: np.ndarray,
                                c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closest point on each triangle to each point, pairwise (Ericson, Real-Time Collision Detection 5.1.5).

    Parameters
    ----------
    p : (k, 3) float
        Query points [m].
    a, b, c : (k, 3) float
        Triangle corners [m].

    Returns
    -------
    closest : (k, 3) float
        Closest points [m].
    barycentric : (k, 3) float
        Their weights on (a, b, c); exactly 0 outside the face region (two zeros: a corner; one zero: an edge).

    Examples
    --------
    >>> import numpy as np
    >>> a, b, c = np.array([[0., 0, 0]]), np.array([[1., 0, 0]]), np.array([[0., 1, 0]])
    >>> closest_points_on_triangles(np.array([[0.2, 0.2, 1.0]]), a, b, c)[0]   # above the face
    array([[0.2, 0.2, 0. ]])
    >>> closest_points_on_triangles(np.array([[2.0, -1.0, 0.0]]), a, b, c)[1]   # beyond corner b
    array([[0., 1., 0.]])
    """
    ab, ac, ap, bp, cp = b - a, c - a, p - a, p - b, p - c
    d1, d2, d3, d4, d5, d6 = _dot(ab, ap), _dot(ac, ap), _dot(ab, bp), _dot(ac, bp), _dot(ab, cp), _dot(ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = va + vb + vc
        bary = np.stack([va / denom, vb / denom, vc / denom], axis=1)  # face region
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
    # A degenerate (zero-area) triangle leaves NaN in the face branch only if no region matched.
    bary = np.where(np.isfinite(bary).all(axis=1, keepdims=True), bary, (1.0, 0.0, 0.0))
    closest = bary[:, :1] * a + bary[:, 1:2] * b + bary[:, 2:] * c
    return closest, bary


def nearest_surface_points(points: ArrayLike, vertices: ArrayLike, faces: ArrayLike, *,
                           tree: cKDTree | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Exact nearest point of a triangle set to each query point.

    A k-d tree over the triangle centroids proposes the ``k`` nearest triangles; a point is settled once its
    ``k``-th centroid is farther than (best distance found + the largest centroid-to-corner radius), since no
    triangle outside the ``k`` can then be closer. ``k`` grows fourfold for the points not yet settled: the
    loop runs over rounds, never over points.

    Parameters
    ----------
    points : (q, 3) float
        Query points [m].
    vertices : (v, 3) float
        Triangle corners [m].
    faces : (f, 3) int
        Triangles.
    tree : scipy.spatial.cKDTree, optional
        A prebuilt tree over the face centroids (static surfaces).

    Returns
    -------
    face : (q,) int64
        The nearest triangle.
    closest : (q, 3) float
        The nearest point on it [m].
    barycentric : (q, 3) float
        Its weights on the triangle's corners.
    distance : (q,) float
        ``|closest - point|`` [m].

    Examples
    --------
    >>> import numpy as np
    >>> vertices = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    >>> faces = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])
    >>> face, closest, _, distance = nearest_surface_points(np.array([[0.2, 0.2, -0.5]]), vertices, faces)
    >>> face.tolist(), closest.round(12).tolist(), distance.tolist()
    ([3], [[0.2, 0.2, 0.0]], [0.5])
    """
    from scipy.spatial import cKDTree

    points = np.asarray(points, dtype=np.float64)
    faces = np.asarray(faces)
    corners = np.asarray(vertices, dtype=np.float64)[faces]
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
