"""Inside tests for closed, outward-wound triangle surfaces: winding numbers by ray casting.

:func:`winding_numbers` counts the signed crossings of a ray from each point, the faces binned on a
grid across the ray so that each point meets only the faces of its column; :func:`contains_points`
is its boolean form for a ``trimesh.Trimesh``. Both are re-exported by :mod:`meshing.surface`.
"""

from __future__ import annotations

import numpy as np
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from numpy.typing import ArrayLike
    import trimesh

__all__ = ["contains_points", "winding_numbers"]

# A fixed generic rotation: rays cast along its third axis are parallel to no face or edge of a
# hand-made surface (boxes, grids), so ties on edges have probability zero.
_RAY_FRAME = np.linalg.qr(np.array([[0.8273, 0.1947, -0.3361], [0.2214, 0.9318, 0.1123], [0.3527, -0.0716, 0.9671]]))[0]


def winding_numbers(vertices: ArrayLike, faces: ArrayLike, points: ArrayLike, *, chunk: int = 2_000_000) -> np.ndarray:
    """Winding number of a closed, outward-wound triangle surface around each point.

    Counts signed crossings of a ray from each point (one fixed generic direction), with the
    faces binned on a grid across the ray so that each point meets only the faces in its column.

    Parameters
    ----------
    vertices : (n, 3) float
        surface vertices [m]
    faces : (f, 3) int
        triangles, wound with outward normals
    points : (k, 3) float
        query points [m]
    chunk : int
        largest number of (point, face) candidate pairs handled at once (memory bound)

    Returns
    -------
    (k,) int
        1 inside a simple closed surface, 0 outside (more inside nested or overlapping bodies)
    """
    vertices = np.asarray(vertices, dtype=np.float64) @ _RAY_FRAME
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3) @ _RAY_FRAME
    tri = vertices[np.asarray(faces)]
    low, high = tri[:, :, :2].min(axis=1), tri[:, :, :2].max(axis=1)
    cell = float(np.median((high - low).max(axis=1))) or 1.0
    origin = low.min(axis=0)
    first_cell = np.floor((low - origin) / cell).astype(np.int64)
    span = np.floor((high - origin) / cell).astype(np.int64) - first_cell + 1
    columns = (first_cell + span).max(axis=0)
    count = span.prod(axis=1)
    face = np.repeat(np.arange(len(tri)), count)
    local = np.arange(count.sum()) - np.repeat(np.cumsum(count) - count, count)
    sx = np.repeat(span[:, 0], count)
    column_x = np.repeat(first_cell[:, 0], count) + local % sx
    key = column_x * columns[1] + np.repeat(first_cell[:, 1], count) + local // sx
    order = np.argsort(key, kind="stable")
    key, face = key[order], face[order]

    point_cell = np.floor((points[:, :2] - origin) / cell).astype(np.int64)
    in_grid = ((point_cell >= 0) & (point_cell < columns)).all(axis=1)
    point_key = np.where(in_grid, point_cell[:, 0] * columns[1] + point_cell[:, 1], -1)
    begin = np.searchsorted(key, point_key, side="left")
    end = np.where(in_grid, np.searchsorted(key, point_key, side="right"), begin)
    winding = np.zeros(len(points), dtype=np.int64)
    # Batches of points with at most about `chunk` candidate (point, face) pairs each.
    pair_count = end - begin
    cumulative = np.cumsum(pair_count)
    total = int(cumulative[-1]) if len(points) else 0
    cuts = np.searchsorted(cumulative, np.arange(1, total // chunk + 1) * chunk)
    batch = np.unique(np.r_[0, cuts, len(points)])
    for lo, hi in zip(batch[:-1], batch[1:]):  # a few batches, not a loop over points
        n = pair_count[lo:hi]
        if n.sum() == 0:
            continue
        which = np.repeat(np.arange(lo, hi), n)
        slot = np.repeat(begin[lo:hi], n) + np.arange(n.sum()) - np.repeat(np.cumsum(n) - n, n)
        t = tri[face[slot]]
        p = points[which]
        # 2D barycentric coordinates of the point in the face's projection across the ray.
        a, b, c = t[:, 0], t[:, 1], t[:, 2]
        area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
        w1 = (c[:, 0] - b[:, 0]) * (p[:, 1] - b[:, 1]) - (p[:, 0] - b[:, 0]) * (c[:, 1] - b[:, 1])
        w2 = (a[:, 0] - c[:, 0]) * (p[:, 1] - c[:, 1]) - (p[:, 0] - c[:, 0]) * (a[:, 1] - c[:, 1])
        w3 = area - w1 - w2
        sign = np.sign(area)
        inside = (sign != 0) & (w1 * sign >= 0) & (w2 * sign >= 0) & (w3 * sign >= 0)
        z = (w1 * a[:, 2] + w2 * b[:, 2] + w3 * c[:, 2]) / np.where(area != 0, area, 1.0)
        crossing = inside & (z > p[:, 2])
        # An upward ray leaves the body through faces whose normals point up (positive projected area).
        winding[lo:hi] += np.bincount(which[crossing] - lo, weights=sign[crossing], minlength=hi - lo).astype(np.int64)
    return winding


def contains_points(surface: trimesh.Trimesh, points: np.ndarray) -> np.ndarray:
    """(k,) bool -- whether each point lies inside a closed, outward-wound ``trimesh.Trimesh``."""
    return winding_numbers(surface.vertices, surface.faces, points) > 0
