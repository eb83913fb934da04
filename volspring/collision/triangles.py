"""Segment-triangle intersections (Moeller-Trumbore), vectorised over pairs.

The other triangle kernels collision uses (closest points, nearest surface points, vertex normals) live in
:mod:`meshing.geometry`, shared with meshing; they are re-exported here for one release. Tolerances come
from :mod:`meshing.tolerances`.
"""

from __future__ import annotations

import numpy as np

# Kept for one release: import these from meshing.geometry.
from meshing.geometry import (  # noqa: F401
    area_weighted_vertex_normals,
    closest_points_on_triangles,
    nearest_surface_points,
)
from meshing.tolerances import ON_SURFACE, PARALLEL

__all__ = ["segment_triangle_intersections"]


def _dot(a, b):
    return np.einsum("...i,...i->...", a, b)


def segment_triangle_intersections(start: np.ndarray, end: np.ndarray, v0: np.ndarray, v1: np.ndarray, v2: np.ndarray,
                                   *, tolerance: float = ON_SURFACE) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Moeller-Trumbore intersection of segments with triangles, pairwise.

    Parameters
    ----------
    start, end : (k, 3) float
        segment end points [m]
    v0, v1, v2 : (k, 3) float
        triangle corners [m]
    tolerance : float
        barycentric slack for hits on triangle edges (dimensionless), so that a segment through an edge or vertex shared
        by two triangles hits at least one despite round-off

    Returns
    -------
    hit : (k,) bool
        the segment meets the triangle (parallel segments never hit)
    t : (k,) float
        hit parameter along the segment, 0 at ``start``, 1 at ``end``
    barycentric : (k, 3) float
        weights of v0, v1, v2 at the hit point
    """
    direction = end - start
    e1, e2 = v1 - v0, v2 - v0
    p = np.cross(direction, e2)
    det = _dot(e1, p)
    # Parallel: |det| is |direction| |e1| |e2| times two sines; below PARALLEL of that product is round-off.
    scale = np.linalg.norm(direction, axis=1) * np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1)
    ok = np.abs(det) > PARALLEL * scale
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = start - v0
    u = _dot(s, p) * inv
    q = np.cross(s, e1)
    v = _dot(direction, q) * inv
    t = _dot(e2, q) * inv
    hit = ok & (u >= -tolerance) & (v >= -tolerance) & (u + v <= 1 + tolerance) & (t >= 0) & (t <= 1)
    return hit, t, np.stack([1.0 - u - v, u, v], axis=1)
