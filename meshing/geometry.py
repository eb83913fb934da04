"""Geometric kernels shared by meshing and by volspring's collision code, each written once and vectorised.

- Volumes: :func:`signed_volumes` of point quadruples, :func:`signed_tet_volumes` of a mesh's tets.
- Barycentric coordinates in tets: :func:`barycentric_frames` precomputes, per tet, the map from a point to
  its four weights (:class:`BarycentricFrames`); :meth:`BarycentricFrames.contains` is the one inside test of
  anchoring and collision detection.
- Triangles: :func:`triangle_area_normals`, :func:`area_weighted_vertex_normals`,
  :func:`closest_points_on_triangles` (Ericson's Voronoi regions) and :func:`nearest_surface_points` (exact
  nearest point of a triangle set, through a k-d tree over the face centroids).
- :func:`rigid_body_modes`: the six infinitesimal rigid motions of a set of points, the null space of a free
  elastic body's stiffness (the near-null space smoothed aggregation needs).

Every tolerance comes from :mod:`meshing.tolerances`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from meshing.tolerances import CANCELLED, ON_SURFACE, ZERO_VOLUME

__all__ = ["BarycentricFrames", "area_weighted_vertex_normals", "barycentric_frames", "closest_points_on_triangles",
           "nearest_surface_points", "rigid_body_modes", "signed_tet_volumes", "signed_volumes", "triangle_area_normals"]

# Point-triangle pairs evaluated at once in nearest_surface_points (~100 MB of temporaries).
_PAIRS_PER_CHUNK = 500_000


def _dot(a, b):
    return np.einsum("...i,...i->...", a, b)


# ---------------------------------------------------------------------------------------------- volumes
def signed_volumes(a, b, c, d) -> np.ndarray:
    """Signed volume of the tet (a, b, c, d) for each row.

    Parameters
    ----------
    a, b, c, d : (k, 3) float
        The four corners [m].

    Returns
    -------
    (k,) float
        ``det[b - a, c - a, d - a] / 6`` [m^3]: positive when d lies on the side of the plane abc that its
        right-hand normal points to.

    Examples
    --------
    >>> import numpy as np
    >>> o, x, y, z = np.zeros((1, 3)), np.array([[1., 0, 0]]), np.array([[0., 1, 0]]), np.array([[0., 0, 1]])
    >>> signed_volumes(o, x, y, z) * 6, signed_volumes(o, y, x, z) * 6
    (array([1.]), array([-1.]))
    """
    return np.einsum("ij,ij->i", b - a, np.cross(c - a, d - a)) / 6.0


def signed_tet_volumes(points, tets) -> np.ndarray:
    """Signed volume of each tet of a mesh.

    Parameters
    ----------
    points : (n, 3) float
        Node positions [m].
    tets : (m, 4) int
        Node indices of each tet.

    Returns
    -------
    (m,) float
        ``det[x1 - x0, x2 - x0, x3 - x0] / 6`` [m^3]; positive for a positively oriented tet.

    Examples
    --------
    >>> import numpy as np
    >>> corners = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    >>> signed_tet_volumes(corners, np.array([[0, 1, 2, 3], [0, 2, 1, 3]])) * 6
    array([ 1., -1.])
    """
    x = np.asarray(points)[np.asarray(tets)]
    return signed_volumes(x[:, 0], x[:, 1], x[:, 2], x[:, 3])


# ---------------------------------------------------------------------------------------------- barycentric
@dataclass(frozen=True, eq=False)
class BarycentricFrames:
    """Per tet, the affine map from a point to its barycentric weights (built by :func:`barycentric_frames`).

    The weights of point p in tet t are ``(1 - sum(beta), beta)`` with ``beta = inverse[t] @ (p - origin[t])``.

    Parameters
    ----------
    inverse : (m, 3, 3) float
        ``A^-1`` for ``A = [x1 - x0, x2 - x0, x3 - x0]`` (edges as columns) [1/m]; zero for flat tets.
    origin : (m, 3) float
        ``x0`` of each tet [m].
    flat : (m,) bool
        Tets with ``|V| <= ZERO_VOLUME * l^3`` (:data:`meshing.tolerances.ZERO_VOLUME`), which contain nothing.
    """

    inverse: np.ndarray
    origin: np.ndarray
    flat: np.ndarray

    def weights(self, points, tets) -> np.ndarray:
        """(q, 4) float -- weights of ``points[i]`` ((q, 3) [m]) in tet ``tets[i]`` ((q,) int), extrapolated outside.

        Each row sums to 1 and reproduces the point: ``sum_j w_j x_j = p`` (to round-off) for a tet that is not flat.
        """
        beta = np.einsum("qij,qj->qi", self.inverse[tets], points - self.origin[tets])
        return np.concatenate([1.0 - beta.sum(axis=1, keepdims=True), beta], axis=1)

    def contains(self, points, tets, *, tolerance: float = ON_SURFACE):
        """Whether ``points[i]`` lies in tet ``tets[i]``: all four weights ``>= -tolerance`` and the tet not flat.

        Parameters
        ----------
        points : (q, 3) float
            Points [m].
        tets : (q,) int
            Index of the tet each point is tested against.
        tolerance : float
            Barycentric slack, so that a point on a face shared by two tets is found in at least one despite
            round-off (default :data:`meshing.tolerances.ON_SURFACE`).

        Returns
        -------
        inside : (q,) bool
        weights : (q, 4) float
            As :meth:`weights`.
        """
        weights = self.weights(points, tets)
        floor = -tolerance
        # Column by column: several times faster than weights.min(axis=1) over rows of four.
        inside = ~self.flat[tets] & (weights[:, 0] >= floor) & (weights[:, 1] >= floor)
        inside &= (weights[:, 2] >= floor) & (weights[:, 3] >= floor)
        return inside, weights


def barycentric_frames(corners) -> BarycentricFrames:
    """The barycentric maps of a set of tets, by the adjugate of their edge matrices.

    Parameters
    ----------
    corners : (m, 4, 3) float
        The corners of each tet [m], e.g. ``points[tets]``; any orientation, flat tets allowed (a deformed
        mesh may hold some): they get zero maps and ``flat = True``.

    Returns
    -------
    BarycentricFrames

    Examples
    --------
    >>> import numpy as np
    >>> corners = np.array([[[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]])
    >>> frames = barycentric_frames(corners)
    >>> frames.weights(np.array([[0.25, 0.25, 0.25], [1.0, 0.0, 0.0]]), np.array([0, 0]))
    array([[0.25, 0.25, 0.25, 0.25],
           [0.  , 1.  , 0.  , 0.  ]])
    >>> frames.contains(np.array([[0.5, 0.5, 0.5]]), np.array([0]))[0]   # beyond the face x + y + z = 1
    array([False])
    """
    corners = np.asarray(corners, dtype=np.float64)
    origin = corners[:, 0]
    a, b, c = corners[:, 1] - origin, corners[:, 2] - origin, corners[:, 3] - origin
    adjugate = np.stack([np.cross(b, c), np.cross(c, a), np.cross(a, b)], axis=1)  # rows of det * A^-1
    det = np.einsum("ij,ij->i", a, adjugate[:, 0])
    extent = (corners.max(axis=1) - corners.min(axis=1)).max(axis=1)
    flat = np.abs(det) / 6.0 <= ZERO_VOLUME * extent**3
    inverse = np.where(flat[:, None, None], 0.0, adjugate / np.where(flat, 1.0, det)[:, None, None])
    return BarycentricFrames(inverse, origin, flat)


# ---------------------------------------------------------------------------------------------- triangles
def triangle_area_normals(points, faces) -> np.ndarray:
    """(f, 3) float -- ``(x1 - x0) x (x2 - x0)`` per triangle: twice its area [m^2] times its right-hand unit normal.

    Examples
    --------
    >>> import numpy as np
    >>> triangle_area_normals(np.array([[0., 0, 0], [2, 0, 0], [0, 1, 0]]), np.array([[0, 1, 2]]))
    array([[0., 0., 2.]])
    """
    x = np.asarray(points)[np.asarray(faces)]
    return np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0])


def area_weighted_vertex_normals(points, faces, *, node_count=None) -> np.ndarray:
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


def closest_points_on_triangles(p, a, b, c) -> tuple[np.ndarray, np.ndarray]:
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


def nearest_surface_points(points, vertices, faces, *, tree=None):
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
    corners = np.asarray(vertices, dtype=np.float64)[np.asarray(faces)]
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


# ---------------------------------------------------------------------------------------------- rigid motions
def rigid_body_modes(points, *, components=None, centre=None, scale=None) -> np.ndarray:
    """The six infinitesimal rigid motions (translations, rotations) of a set of points, as displacement columns.

    Columns: unit translations along x, y, z, then rotations ``e_axis x (p - centre) / scale`` about x, y, z
    through ``centre``. Dividing by a length of the body's size gives all six columns comparable norms (the
    near-null space ``B`` handed to smoothed aggregation; the modes a support must hold).

    Parameters
    ----------
    points : (p, 3) float
        Positions [m]: of the nodes (``components=None``) or of each degree of freedom.
    components : (p,) int, optional
        The displacement component (0, 1, 2 for x, y, z) each row of ``points`` is a degree of freedom of.
        By default every point has all three, in node order (rows ``3 k, 3 k + 1, 3 k + 2`` for point k).
    centre : (3,) float, optional
        The point the rotations turn about [m]; default the mean of ``points``.
    scale : float, optional
        The length the rotations are divided by [m]; default the root-mean-square distance of the points
        from ``centre`` (1 if that is 0).

    Returns
    -------
    (3p, 6) float, or (p, 6) float with ``components``
        Dimensionless.

    Raises
    ------
    ValueError
        For points not of shape (p, 3), components not of shape (p,) or outside {0, 1, 2}, or a scale not > 0.

    Examples
    --------
    >>> import numpy as np
    >>> modes = rigid_body_modes(np.array([[1., 0, 0], [-1, 0, 0]]))
    >>> modes.shape, modes[:3, 5] + 0.0   # node 0 turns about z through the centre: it moves along +y
    ((6, 6), array([0., 1., 0.]))
    >>> rigid_body_modes(np.array([[1., 0, 0]]), components=[1], centre=np.zeros(3), scale=1.0) + 0.0
    array([[0., 1., 0., 0., 0., 1.]])
    """
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points must have shape (p, 3), got {points.shape}")
    if centre is None:
        centre = points.mean(axis=0) if len(points) else np.zeros(3)
    q = points - np.asarray(centre, dtype=np.float64)
    if scale is None:
        scale = np.sqrt((q * q).sum(axis=1).mean()) if len(q) else 0.0
        scale = scale or 1.0
    if not (np.isfinite(scale) and scale > 0):
        raise ValueError(f"scale = {scale!r} is not a finite length > 0 [m]")
    q = q / scale
    modes = np.zeros((len(points), 3, 6))
    modes[:, [0, 1, 2], [0, 1, 2]] = 1.0
    # omega x q for omega = e_x, e_y, e_z
    modes[:, 1, 3], modes[:, 2, 3] = -q[:, 2], q[:, 1]
    modes[:, 0, 4], modes[:, 2, 4] = q[:, 2], -q[:, 0]
    modes[:, 0, 5], modes[:, 1, 5] = -q[:, 1], q[:, 0]
    if components is None:
        return modes.reshape(-1, 6)
    components = np.asarray(components)
    if components.shape != (len(points),) or not np.isin(components, (0, 1, 2)).all():
        raise ValueError(f"components must be {len(points)} values in {{0, 1, 2}} (one per row of points), got "
                         f"shape {components.shape} with values {np.unique(components)[:6].tolist()}")
    return modes[np.arange(len(points)), components.astype(np.int64)]
