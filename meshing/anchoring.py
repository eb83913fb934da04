"""Barycentric anchoring: a (possibly much finer) render surface carried along by a tet mesh.

Every render-surface vertex is bound to one tet by its four barycentric weights, so the deformed surface is
``sum_j w_j x_j`` over that tet's deformed nodes. Weights are affine-exact: under any affine map of the nodes the
surface follows the same map, also for vertices outside the mesh, whose weights are extrapolated from the nearest tet.

Point location is a uniform grid over the tets' bounding boxes (the spatial hashing of Teschner et al. 2003, with
a sorted key array in place of a hash table), candidates tested in batches; vertices found in no tet go to their
nearest boundary face (:func:`meshing.geometry.nearest_surface_points`) and take that face's tet. The barycentric
maps and the inside test are :func:`meshing.geometry.barycentric_frames`, shared with collision detection.
"""

from __future__ import annotations

import dataclasses
import logging
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from meshing.geometry import BarycentricFrames, barycentric_frames, nearest_surface_points
from meshing.mesh import TetMesh
from meshing.tolerances import ON_SURFACE
from typing import TYPE_CHECKING, Any, ClassVar

if TYPE_CHECKING:
    import trimesh

__all__ = ["Anchor", "anchor"]

logger = logging.getLogger(__name__)

# Candidate (vertex, tet) pairs tested per batch: about 300 bytes each, so a few hundred MB at most.
PAIR_BATCH = 1_000_000
# Tets tried first for each vertex, those of its 4 nearest centroids: on benchmarks/bench_anchor.py this finds
# the tet of 94% of the vertices inside and was fastest overall (4, 8, 16 tried); the rest go to the grid.
NEAREST_CENTROIDS = 4
# Average number of grid cells a tet may register in before the grid is coarsened (a cell of one median tet
# size gives about 8; coarsening only guards against a few huge tets).
GRID_REGISTRATIONS = 16


class WeightedAnchor:
    """What every render-surface binding shares: each vertex a weighted sum of a few model nodes.

    For frozen dataclasses with the fields ``nodes`` (p, k), ``weights`` (p, k), ``points``, ``faces``,
    ``outside``, ``outside_distance`` and ``node_count`` (:class:`Anchor`: the 4 nodes of a tet by barycentric
    weights; :class:`meshing.lattice.LatticeAnchor`: the 8 corners of a cell by trilinear weights).
    """

    #: What the nodes are, in messages.
    node_owner = "the model's"

    # The fields every subclass has (declared here for the methods below; not fields of this class).
    __dataclass_fields__: ClassVar[dict[str, dataclasses.Field[Any]]]
    nodes: np.ndarray
    weights: np.ndarray
    points: np.ndarray
    faces: np.ndarray | None
    outside: np.ndarray
    outside_distance: np.ndarray
    node_count: int

    def __post_init__(self):
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if isinstance(value, np.ndarray):
                value = np.array(value, copy=True)
                value.setflags(write=False)
                object.__setattr__(self, field.name, value)

    @property
    def point_count(self) -> int:
        return len(self.nodes)

    @property
    def outside_count(self) -> int:
        """Number of surface vertices outside the body (anchored by extrapolation)."""
        return int(self.outside.sum())

    @property
    def max_outside_distance(self) -> float:
        """Largest distance from a surface vertex to the body [m]; 0 when all are inside."""
        return float(self.outside_distance.max(initial=0.0))

    @property
    def min_weight(self) -> float:
        """Smallest weight: below 0 only for vertices outside (how far they extrapolate)."""
        return float(self.weights.min(initial=0.0))

    @cached_property
    def matrix(self):
        """(p, n) scipy.sparse.csr_matrix -- the linear map from node positions to surface positions."""
        from scipy.sparse import csr_matrix

        rows = np.repeat(np.arange(self.point_count), self.nodes.shape[1])
        return csr_matrix((self.weights.ravel(), (rows, self.nodes.ravel())), shape=(self.point_count, self.node_count))

    def deform(self, x: np.ndarray) -> np.ndarray:
        """Surface vertex positions for deformed node positions.

        Parameters
        ----------
        x : (n, 3) or (..., n, 3) float
            node positions [m]; leading axes are a batch (e.g. frames)

        Returns
        -------
        (p, 3) or (..., p, 3) float
            the surface vertices [m]
        """
        x = np.asarray(x, dtype=np.float64)
        if x.ndim < 2 or x.shape[-2:] != (self.node_count, 3):
            raise ValueError(f"x must have shape (..., {self.node_count}, 3) ({self.node_owner} nodes), got {x.shape}")
        return np.einsum("pj,...pjd->...pd", self.weights, x[..., self.nodes, :])

    def __repr__(self) -> str:
        return (f"{type(self).__name__}({self.point_count} vertices, {self.outside_count} outside, "
                f"max distance outside {self.max_outside_distance:.3g}, min weight {self.min_weight:.3g})")


@dataclass(frozen=True, eq=False, repr=False)
class Anchor(WeightedAnchor):
    """A render surface bound to a tet mesh by barycentric weights (immutable).

    Parameters
    ----------
    tet_index : (p,) int64
        the tet each surface vertex is bound to
    nodes : (p, 4) int64
        that tet's node indices (``tet_mesh.tets[tet_index]``)
    weights : (p, 4) float64
        barycentric weights in that tet; each row sums to 1, negative entries only for vertices outside the mesh
        (extrapolated)
    points : (p, 3) float64
        the surface vertices at rest [m]
    faces : (k, 3) int64 or None
        the render surface's triangles, if it was given as a mesh
    outside : (p,) bool
        vertices inside no tet (within the barycentric tolerance)
    outside_distance : (p,) float64
        distance from each vertex to the tet mesh [m]; 0 inside
    node_count : int
        number of nodes of the tet mesh, checked by :meth:`deform`
    """

    tet_index: np.ndarray
    nodes: np.ndarray
    weights: np.ndarray
    points: np.ndarray
    faces: np.ndarray | None
    outside: np.ndarray
    outside_distance: np.ndarray
    node_count: int

    node_owner = "the tet mesh's"


def anchor(tet_mesh: TetMesh, surface: trimesh.Trimesh | np.ndarray, *, tolerance: float = ON_SURFACE,
           max_distance: float | None = None) -> Anchor:
    """Bind every vertex of a render surface to the tet containing it, by barycentric weights.

    Parameters
    ----------
    tet_mesh : TetMesh
        the volumetric body at rest
    surface : trimesh.Trimesh or (p, 3) float
        the render surface (its ``vertices`` and ``faces``) or bare vertex positions [m]
    tolerance : float
        a vertex counts as inside a tet when all its barycentric weights are >= -tolerance (round-off of vertices on
        faces); default :data:`meshing.tolerances.ON_SURFACE` (1e-9)
    max_distance : float or None
        refuse vertices farther than this outside the tet mesh [m]; None (default) anchors every vertex, however far,
        and logs a warning past one mean tet size

    Returns
    -------
    Anchor
        Vertices inside several tets (on shared faces) take one of them, the deepest of those tested. Vertices
        outside every tet take the tet of the nearest boundary face (the nearest tet) with extrapolated weights
        that still sum to 1 and reproduce the vertex at rest; they are counted (``outside``, ``outside_count``,
        ``max_outside_distance``) and logged.

    Raises
    ------
    ValueError
        For no vertices, vertices of the wrong shape or non-finite, a negative tolerance or ``max_distance``, or
        vertices farther outside than ``max_distance``.

    Examples
    --------
    >>> import numpy as np
    >>> from meshing import TetMesh, anchor
    >>> mesh = TetMesh(np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]), np.array([[0, 1, 2, 3]]))
    >>> bound = anchor(mesh, np.array([[0.1, 0.2, 0.3], [0.5, 0.5, 0.5]]))
    >>> bound.outside.tolist(), np.allclose(bound.deform(2 * mesh.points), 2 * bound.points)
    ([False, True], True)
    """
    points, faces = _surface_arrays(surface)
    if not (isinstance(tolerance, (int, float, np.floating)) and np.isfinite(tolerance) and tolerance >= 0):
        raise ValueError(f"tolerance = {tolerance!r} is not >= 0 and finite; expected a barycentric tolerance")
    if max_distance is not None and not (isinstance(max_distance, (int, float, np.floating)) and max_distance >= 0):
        raise ValueError(f"max_distance = {max_distance!r} is not >= 0; expected a distance [m] or None")
    frames = barycentric_frames(tet_mesh.points[tet_mesh.tets])
    tet_index = _locate(tet_mesh, points, frames, tolerance)
    outside = tet_index < 0
    distance = np.zeros(len(points))
    if outside.any():
        face, _, _, distance[outside] = nearest_surface_points(points[outside], tet_mesh.points,
                                                               tet_mesh.boundary_faces)
        tet_index[outside] = tet_mesh.boundary_face_tets[face]
    weights = frames.weights(points, tet_index)
    # One step of iterative refinement: the residual of sum w x against the vertex, mapped back to weights.
    nodes = tet_mesh.tets[tet_index]
    residual = points - np.einsum("pj,pjd->pd", weights, tet_mesh.points[nodes])
    step = np.einsum("pij,pj->pi", frames.inverse[tet_index], residual)
    weights[:, 1:] += step
    weights[:, 0] -= step.sum(axis=1)

    result = Anchor(tet_index, nodes, weights, points, faces, outside, distance, tet_mesh.node_count)
    if result.outside_count:
        size = np.cbrt(tet_mesh.volume / tet_mesh.tet_count)
        if max_distance is not None and result.max_outside_distance > max_distance:
            far = distance > max_distance
            raise ValueError(
                f"{far.sum()} surface vertices lie farther than max_distance = {max_distance} outside the tet mesh "
                f"(up to {result.max_outside_distance:.6g}, first is vertex {np.flatnonzero(far)[0]})"
            )
        level = logging.WARNING if result.max_outside_distance > size else logging.INFO
        logger.log(
            level,
            "%d of %d surface vertices lie outside every tet (up to %.3g away, mean tet size %.3g, min weight %.3g): "
            "anchored to the nearest tet by extrapolated weights",
            result.outside_count, len(points), result.max_outside_distance, size, result.min_weight,
        )
    return result


def _surface_arrays(surface):
    """Vertices (p, 3) float64 and faces (k, 3) int64 or None of a trimesh-like mesh or a bare array."""
    faces = None
    if hasattr(surface, "vertices"):
        points = np.asarray(surface.vertices, dtype=np.float64)
        if getattr(surface, "faces", None) is not None:
            faces = np.asarray(surface.faces, dtype=np.int64).reshape(-1, 3)
    else:
        try:
            points = np.asarray(surface, dtype=np.float64)
        except (TypeError, ValueError) as error:
            raise ValueError(
                f"surface must be a trimesh.Trimesh or a (p, 3) array of vertices, got {type(surface).__name__}"
            ) from error
    if points.ndim != 2 or points.shape[1] != 3 or len(points) == 0:
        raise ValueError(f"surface vertices must have shape (p, 3) with p > 0, got {points.shape}")
    bad = ~np.isfinite(points).all(axis=1)
    if bad.any():
        raise ValueError(
            f"{bad.sum()} surface vertices have non-finite coordinates, first is vertex {np.flatnonzero(bad)[0]}"
        )
    return points, faces


def _locate(mesh: TetMesh, points, frames: BarycentricFrames, tolerance) -> np.ndarray:
    """(p,) int64 -- a tet containing each point (the deepest of those tested), -1 where none does.

    Two stages: the tets of the ``NEAREST_CENTROIDS`` nearest centroids (cheap, resolves most inside points),
    then, for the points left, every tet whose bounding box overlaps the point's grid cell (exhaustive).
    """
    from scipy.spatial import cKDTree

    corners = mesh.points[mesh.tets]
    k = min(NEAREST_CENTROIDS, mesh.tet_count)
    _, nearest = cKDTree(corners.mean(axis=1)).query(points, k=k)
    found = _deepest_inside(np.repeat(np.arange(len(points)), k), nearest.ravel(), len(points),
                            points, frames, tolerance)
    left = np.flatnonzero(found < 0)
    if len(left):
        found[left] = _locate_in_grid(corners, points[left], frames, tolerance)
    return found


def _deepest_inside(point_of, tet, point_count, points, frames: BarycentricFrames, tolerance) -> np.ndarray:
    """(point_count,) int64 -- per point the candidate tet where it is deepest, if inside it; -1 otherwise.

    ``point_of`` (c,) and ``tet`` (c,) are the candidate pairs, ``point_of`` non-decreasing.
    """
    found = np.full(point_count, -1, dtype=np.int64)
    if len(point_of) == 0:
        return found
    depth = frames.weights(points[point_of], tet).min(axis=1)
    # The deepest candidate of each point without sorting: the group maxima by reduceat over the runs of
    # ``point_of``, then the first pair of each point that reaches its maximum.
    starts = np.flatnonzero(np.r_[True, point_of[1:] != point_of[:-1]])
    group_max = np.maximum.reduceat(depth, starts)
    run = np.repeat(np.arange(len(starts)), np.diff(np.r_[starts, len(point_of)]))
    best = np.flatnonzero(depth >= group_max[run])
    best = best[np.r_[True, run[best][1:] != run[best][:-1]]]
    inside = best[depth[best] >= -tolerance]
    found[point_of[inside]] = tet[inside]
    return found


def _locate_in_grid(corners, points, frames: BarycentricFrames, tolerance) -> np.ndarray:
    """(q,) int64 -- like :func:`_locate`, testing every tet whose bounding box overlaps the point's cell."""
    low, high = corners.min(axis=1), corners.max(axis=1)
    grid_origin = low.min(axis=0)
    # Cells of one typical tet (the median bounding-box extent): a tet registers in about 8 cells, a point meets
    # about 8 times the tets whose box holds it (half-size cells measured slower on benchmarks/bench_anchor.py).
    # Coarsen while a few huge tets would register in too many cells (more than GRID_REGISTRATIONS per tet).
    cell = float(np.median((high - low).max(axis=1)))
    while True:
        first, last = (np.floor((bound - grid_origin) / cell).astype(np.int64) for bound in (low, high))
        span = last - first + 1
        per_tet = span.prod(axis=1)
        if per_tet.sum() <= GRID_REGISTRATIONS * len(corners):
            break
        cell *= 2.0
    shape = last.max(axis=0) + 1
    tet_of = np.repeat(np.arange(len(corners)), per_tet)
    offset = np.arange(len(tet_of)) - np.repeat(np.cumsum(per_tet) - per_tet, per_tet)
    span_of = span[tet_of]
    first_of = first[tet_of]
    keys = _cell_keys(
        first_of[:, 0] + offset % span_of[:, 0],
        first_of[:, 1] + (offset // span_of[:, 0]) % span_of[:, 1],
        first_of[:, 2] + offset // (span_of[:, 0] * span_of[:, 1]),
        shape,
    )
    order = np.argsort(keys)
    keys, tet_of = keys[order], tet_of[order]

    point_cells = np.floor((points - grid_origin) / cell).astype(np.int64)
    in_grid = ((point_cells >= 0) & (point_cells < shape)).all(axis=1)
    cell_i, cell_j, cell_k = np.where(in_grid[:, None], point_cells, 0).T
    point_keys = _cell_keys(cell_i, cell_j, cell_k, shape)
    start = np.searchsorted(keys, point_keys, side="left")
    count = np.where(in_grid, np.searchsorted(keys, point_keys, side="right") - start, 0)

    found = np.full(len(points), -1, dtype=np.int64)
    # Batches of whole points, each with about PAIR_BATCH candidate pairs, to bound the memory.
    total = np.cumsum(count)
    bounds = np.searchsorted(total, np.arange(PAIR_BATCH, total[-1] + PAIR_BATCH, PAIR_BATCH), side="right")
    for begin, end in zip(np.concatenate([[0], bounds[:-1]]), bounds):
        batch_count = count[begin:end]
        point_of = np.repeat(np.arange(end - begin), batch_count)
        run_start = np.repeat(start[begin:end] - np.cumsum(batch_count) + batch_count, batch_count)
        slot = run_start + np.arange(len(point_of))
        found[begin:end] = _deepest_inside(point_of, tet_of[slot], end - begin, points[begin:end],
                                           frames, tolerance)
    return found


def _cell_keys(i, j, k, shape) -> np.ndarray:
    """Linear index of grid cells (i, j, k) in a grid of ``shape`` cells."""
    return i + shape[0] * (j + shape[1] * k)
