"""Regular lattices filling a closed surface: voxel cells, their springs' node pairs, trilinear anchoring.

The geometry of the lattice body (the seed's volumetric model 1); the physics (stiffness, masses) is
:mod:`volspring.lattice`.

Cells. A uniform grid of cubes of edge ``cell_size`` covers the surface's bounding box, centred on it (a
box whose edges are multiples of the cell size is covered exactly). A cell belongs to the lattice when part
of it lies inside: its inside volume fraction is sampled on ``samples^3`` points (the centres of a regular
sub-grid) in every cell near the surface, and is 0 or 1 elsewhere (the cell centre's inside test). Cells
near the surface are those within h / (2 sqrt 3) (along each axis) of a vertex of the surface subdivided to
edges of half a cell (``trimesh.remesh.subdivide_to_size``): every cell the surface crosses is sampled. Inside tests are
winding numbers (:func:`meshing.surface_winding.contains_points`). The lattice's volume
``sum(fractions) * cell_size^3`` is the midpoint rule on the sub-grid: exact for a box on the grid, and
within a small fraction of the boundary layer otherwise (a sphere of 10 cells across: 0.1%, measured in
tests/test_lattice.py).

Nodes are the corners of the kept cells, numbered in lexicographic order of their grid index (i, j, k):
on a box they are the nodes of :func:`meshing.structured_box` of the same cells, in the same order.

Springs (node pairs, :meth:`Lattice.pairs`): ``structural`` along the cell edges, ``face`` and ``body``
diagonals (the shear springs), ``bend`` between nodes two edges apart along a grid line (skip-one
neighbours), and right-angle joints (:meth:`Lattice.joints`) for angle springs. Each carries a weight, its
share of the cells it belongs to: sum over its cells of fraction / (cells sharing such an element in the
infinite lattice: 4 per edge, 2 per face diagonal or face, 1 per body diagonal), so 1 inside the body, 1/2
on a face of it, 1/4 on an edge of it. A bend spring's weight is the mean of its two edges'.

Anchoring (:func:`anchor_lattice`): every render-surface vertex takes the trilinear weights of its point in
the cell holding it; vertices in no kept cell take the nearest kept cell and extrapolated weights. Trilinear
weights reproduce any affine map of the nodes exactly, inside the cell or outside it.

Examples
--------
>>> import trimesh
>>> from meshing.lattice import voxelize
>>> lattice = voxelize(trimesh.creation.box(extents=(1.0, 0.5, 0.5)), 0.25)
>>> lattice.cell_count, lattice.node_count, round(lattice.volume, 12)
(16, 45, 0.25)
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from meshing.anchoring import WeightedAnchor, _surface_arrays
from typing import TYPE_CHECKING, SupportsInt

if TYPE_CHECKING:
    from collections.abc import Iterable

    from numpy.typing import ArrayLike
    import trimesh

__all__ = ["CORNERS", "LATTICE_FAMILIES", "Lattice", "LatticeAnchor", "anchor_lattice", "box_lattice", "voxelize"]

logger = logging.getLogger(__name__)

#: Cell corners (a, b, c) in {0, 1}^3, numbered a*4 + b*2 + c (the numbering of :data:`meshing.structured.KUHN_PATHS`).
CORNERS = np.array([[a, b, c] for a in (0, 1) for b in (0, 1) for c in (0, 1)], dtype=np.int64)
#: The spring families of a lattice, in the order of their codes in ``Lattice.pairs``.
LATTICE_FAMILIES = ("structural", "face", "body", "bend")
#: Relative slack on the number of cells along an axis: an extent of 10.000000001 cells is 10 cells, not 11
#: (round-off of a box built as a multiple of the cell size is ~1e-15 relative).
GRID_SNAP = 1e-9
#: Tolerance on the local cell coordinates in [0, 1] of an anchored vertex before it counts as outside
#: (round-off of vertices on cell faces).
ON_CELL_FACE = 1e-9

# Corner pairs of one cell by how many coordinates they differ in: 1 edges (12), 2 face diagonals (12), 3 body
# diagonals (4). Sharing of each in the infinite lattice: 4, 2, 1 cells.
_DIFFER = (CORNERS[:, None, :] != CORNERS[None, :, :]).sum(axis=2)
_CORNER_PAIRS = {d: np.argwhere(np.triu(_DIFFER == d)) for d in (1, 2, 3)}
_SHARING = {1: 4.0, 2: 2.0, 3: 1.0}


def _face_joints() -> np.ndarray:
    """(24, 3) int -- the right-angle corners (i, j, k) of a cell's 6 faces, j the vertex, as corner numbers."""
    joints = []
    for normal in range(3):
        in_plane = [axis for axis in range(3) if axis != normal]
        for side in (0, 1):
            for corner in np.flatnonzero(CORNERS[:, normal] == side):
                first, second = corner ^ (4 >> in_plane[0]), corner ^ (4 >> in_plane[1])
                joints.append((first, corner, second))
    return np.array(joints, dtype=np.int64)


_JOINTS = _face_joints()


@dataclass(frozen=True, eq=False)
class Lattice:
    """Cubic cells of a grid that overlap a body, with their inside volume fractions (immutable).

    Parameters
    ----------
    origin : (3,) float
        position of grid node (0, 0, 0) [m]
    cell_size : float
        edge of the cubic cells [m]
    cells : (c, 3) int64
        grid index (i, j, k) of each cell's lowest corner, lexicographically sorted
    fractions : (c,) float64
        inside volume fraction of each cell, in (0, 1]
    """

    origin: np.ndarray
    cell_size: float
    cells: np.ndarray
    fractions: np.ndarray

    def __post_init__(self):
        origin = np.asarray(self.origin, dtype=np.float64).reshape(3)
        cells = np.asarray(self.cells, dtype=np.int64).reshape(-1, 3)
        fractions = np.asarray(self.fractions, dtype=np.float64).reshape(-1)
        if not (np.isfinite(self.cell_size) and self.cell_size > 0):
            raise ValueError(f"cell_size = {self.cell_size!r} m is not a positive finite length")
        if len(cells) == 0:
            raise ValueError("the lattice has no cell: the body lies inside no cell of the grid")
        if fractions.shape != (len(cells),):
            raise ValueError(f"len(cells) = {len(cells)}, but fractions have shape {fractions.shape}")
        bad = ~((fractions > 0) & (fractions <= 1))
        if bad.any():
            first = int(np.flatnonzero(bad)[0])
            raise ValueError(f"fractions[{first}] = {fractions[first]} is not in (0, 1] ({bad.sum()} bad cells)")
        if cells.min() < 0:
            raise ValueError(f"cells hold a negative grid index {cells.min()}; expected indices >= 0")
        keys = self._keys(cells, cells.max(axis=0) + 2)
        if (np.diff(keys) <= 0).any():
            raise ValueError("cells are not unique and lexicographically sorted by (i, j, k)")
        object.__setattr__(self, "cell_size", float(self.cell_size))
        for name, array in (("origin", origin), ("cells", cells), ("fractions", fractions)):
            array.setflags(write=False)
            object.__setattr__(self, name, array)

    @staticmethod
    def _keys(index, shape) -> np.ndarray:
        return (index[..., 0] * shape[1] + index[..., 1]) * shape[2] + index[..., 2]

    @cached_property
    def _node_shape(self) -> np.ndarray:
        return self.cells.max(axis=0) + 2

    @cached_property
    def _node_table(self) -> tuple:
        """(node keys sorted, node grid indices (n, 3), cell_nodes (c, 8))."""
        corner_index = self.cells[:, None, :] + CORNERS[None, :, :]  # (c, 8, 3)
        keys = self._keys(corner_index, self._node_shape)
        unique, inverse = np.unique(keys.ravel(), return_inverse=True)
        shape = self._node_shape
        index = np.stack([unique // (shape[1] * shape[2]), (unique // shape[2]) % shape[1], unique % shape[2]], axis=1)
        for array in (unique, index):
            array.setflags(write=False)
        cell_nodes = inverse.reshape(-1, 8).astype(np.int64)
        cell_nodes.setflags(write=False)
        return unique, index, cell_nodes

    @property
    def node_index(self) -> np.ndarray:
        """(n, 3) int64 -- grid index of every node, lexicographically sorted."""
        return self._node_table[1]

    @property
    def cell_nodes(self) -> np.ndarray:
        """(c, 8) int64 -- the nodes at each cell's corners, in the order of :data:`CORNERS`."""
        return self._node_table[2]

    @cached_property
    def points(self) -> np.ndarray:
        """(n, 3) float64 -- rest positions of the nodes [m]."""
        points = self.origin + self.cell_size * self.node_index
        points.setflags(write=False)
        return points

    @property
    def cell_count(self) -> int:
        return len(self.cells)

    @property
    def node_count(self) -> int:
        return len(self._node_table[0])

    @property
    def volume(self) -> float:
        """The body's volume as the lattice sees it, sum(fractions) * cell_size^3 [m^3]."""
        return float(self.fractions.sum() * self.cell_size**3)

    @cached_property
    def node_volumes(self) -> np.ndarray:
        """(n,) float64 -- an eighth of the inside volume of every cell at each node [m^3]; sums to :attr:`volume`."""
        volumes = np.bincount(self.cell_nodes.ravel(), weights=np.repeat(self.fractions * self.cell_size**3 / 8, 8),
                              minlength=self.node_count)
        volumes.setflags(write=False)
        return volumes

    def node_of(self, index: ArrayLike) -> np.ndarray:
        """(k,) int64 -- the node at each grid index (k, 3), -1 where the lattice has none."""
        index = np.asarray(index, dtype=np.int64).reshape(-1, 3)
        keys, shape = self._node_table[0], self._node_shape
        valid = np.all((index >= 0) & (index < shape), axis=1)
        query = self._keys(np.where(valid[:, None], index, 0), shape)
        where = np.minimum(np.searchsorted(keys, query), len(keys) - 1)
        return np.where(valid & (keys[where] == query), where, -1)

    def cell_of(self, index: ArrayLike) -> np.ndarray:
        """(k,) int64 -- the cell with each grid index (k, 3) (its lowest corner), -1 where none is kept."""
        index = np.asarray(index, dtype=np.int64).reshape(-1, 3)
        shape = self._node_shape
        keys = self._keys(self.cells, shape)
        valid = np.all((index >= 0) & (index < shape), axis=1)
        query = self._keys(np.where(valid[:, None], index, 0), shape)
        where = np.minimum(np.searchsorted(keys, query), len(keys) - 1)
        return np.where(valid & (keys[where] == query), where, -1)

    # ------------------------------------------------------------------ springs and joints
    def pairs(self, *, shear: bool = True, bend: bool = True) -> tuple:
        """The spring node pairs, family by family (module docstring).

        Parameters
        ----------
        shear : bool
            include the face and body diagonals
        bend : bool
            include the skip-one (bend) springs

        Returns
        -------
        pairs : (s, 2) int64
            node pairs (i < j), grouped by family in the order of :data:`LATTICE_FAMILIES`
        family : (s,) int8
            index into :data:`LATTICE_FAMILIES`
        weights : (s,) float64
            each spring's share of cells (1 inside the body)
        bend_slots : (s,) float64
            for structural springs, how many of the two bend springs that would cover the edge in an unbounded lattice
            are missing (0, 1 or 2), times the edge's weight; 0 for the rest
        """
        families = [self._cell_pairs(1)] + ([self._cell_pairs(2), self._cell_pairs(3)] if shear else [])
        edges, edge_weights = families[0]
        missing = np.zeros(len(edges))
        parts = [(pairs, np.full(len(pairs), code, dtype=np.int8), weights)
                 for code, (pairs, weights) in zip((0, 1, 2), families)]
        if bend:
            bends, bend_weights, covered = self._bends(edges, edge_weights)
            missing = edge_weights * (2.0 - np.bincount(covered.ravel(), minlength=len(edges)))
            parts.append((bends, np.full(len(bends), 3, dtype=np.int8), bend_weights))
        pairs = np.concatenate([part[0] for part in parts]).reshape(-1, 2)
        family = np.concatenate([part[1] for part in parts])
        weights = np.concatenate([part[2] for part in parts])
        slots = np.zeros(len(pairs))
        slots[: len(edges)] = missing
        return pairs, family, weights, slots

    def _cell_pairs(self, differ: int) -> tuple:
        """Unique node pairs (i < j) of one kind of cell corner pair, with their summed cell shares."""
        corner_pairs = _CORNER_PAIRS[differ]
        nodes = self.cell_nodes[:, corner_pairs]  # (c, p, 2)
        share = np.repeat(self.fractions / _SHARING[differ], len(corner_pairs))
        return _unique_pairs(nodes.reshape(-1, 2), share, self.node_count)

    def _bends(self, edges, edge_weights) -> tuple:
        """Bend pairs (a, c) along grid lines where edges a-b and b-c both exist, their weights, covered edges."""
        index = self.node_index
        direction = index[edges[:, 1]] - index[edges[:, 0]]  # one unit vector per edge (i < j: positive)
        axis = np.argmax(direction, axis=1)
        # Edge starting at each node along each axis: key node * 3 + axis.
        start_keys = edges[:, 0] * 3 + axis
        order = np.argsort(start_keys)
        follow_keys = edges[:, 1] * 3 + axis
        where = np.minimum(np.searchsorted(start_keys, follow_keys, sorter=order), len(edges) - 1)
        following = order[where]
        has_next = start_keys[following] == follow_keys
        first = np.flatnonzero(has_next)
        second = following[has_next]
        bends = np.stack([edges[first, 0], edges[second, 1]], axis=1)
        weights = 0.5 * (edge_weights[first] + edge_weights[second])
        return bends, weights, np.stack([first, second], axis=1)

    def joints(self) -> tuple:
        """Right-angle joints (i, j, k) of the cell faces, j the vertex, with their cell shares.

        Returns
        -------
        triples : (e, 3) int64
            each joint once (i < k)
        weights : (e,) float64
            share of the cells holding the face: 1 inside the body, 1/2 on its boundary
        """
        triples = self.cell_nodes[:, _JOINTS]  # (c, 24, 3)
        triples = triples.reshape(-1, 3)
        low, high = np.minimum(triples[:, 0], triples[:, 2]), np.maximum(triples[:, 0], triples[:, 2])
        n = self.node_count
        keys = (low * n + triples[:, 1]) * n + high
        unique, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
        weights = np.bincount(inverse.ravel(), weights=np.repeat(self.fractions / 2.0, len(_JOINTS)),
                              minlength=len(unique))
        chosen = triples[first]
        ordered = np.stack([np.minimum(chosen[:, 0], chosen[:, 2]), chosen[:, 1],
                            np.maximum(chosen[:, 0], chosen[:, 2])], axis=1)
        return ordered, weights

    def __repr__(self) -> str:
        return (f"Lattice({self.cell_count} cells of {self.cell_size:.6g} m, {self.node_count} nodes, "
                f"volume {self.volume:.6g} m^3)")


def _unique_pairs(pairs, weights, node_count) -> tuple:
    """Unique node pairs (i < j), sorted, with the weights of their repeats summed."""
    low, high = pairs.min(axis=1), pairs.max(axis=1)
    unique, inverse = np.unique(low * node_count + high, return_inverse=True)
    summed = np.bincount(inverse.ravel(), weights=weights, minlength=len(unique))
    return np.stack([unique // node_count, unique % node_count], axis=1), summed


def box_lattice(cells: Iterable[SupportsInt], size: ArrayLike, *, origin: ArrayLike = (0.0, 0.0, 0.0)) -> Lattice:
    """The full lattice of a box of ``cells`` cubic cells: the nodes of ``structured_box(cells, size)``, in order.

    Parameters
    ----------
    cells : (3,) int
        cells along x, y, z, each >= 1
    size : (3,) float
        box edges [m]; ``size / cells`` must be one cell size (cubic cells)
    origin : (3,) float
        the box's lowest corner [m]
    """
    cells = np.array([int(c) for c in cells], dtype=np.int64)
    size = np.asarray(size, dtype=np.float64)
    if cells.shape != (3,) or cells.min() < 1:
        raise ValueError(f"cells = {cells.tolist()} must be three counts >= 1")
    edges = size / cells
    if not np.allclose(edges, edges[0], rtol=1e-9, atol=0):
        raise ValueError(f"size / cells = {edges.tolist()} m: the cells are not cubes (lattice rules need cubes)")
    grid = np.stack(np.meshgrid(*[np.arange(c) for c in cells], indexing="ij"), axis=-1).reshape(-1, 3)
    return Lattice(np.asarray(origin, dtype=np.float64), float(edges[0]), grid, np.ones(len(grid)))


def voxelize(surface: trimesh.Trimesh, cell_size: float, *, samples: int = 4) -> Lattice:
    """The lattice of cubic cells overlapping the inside of a closed surface (module docstring).

    Parameters
    ----------
    surface : trimesh.Trimesh
        closed, outward-wound [m]
    cell_size : float
        edge of the cells [m]
    samples : int
        sub-grid points per axis that sample each boundary cell's inside fraction (>= 1; the fraction's resolution is
        1 / samples^3)

    Returns
    -------
    Lattice

    Raises
    ------
    ValueError
        For a cell size that is not positive and finite, samples < 1, a surface without faces, or a body
        that overlaps no cell.
    """
    import trimesh

    from meshing.surface_winding import contains_points

    if not (isinstance(cell_size, (int, float, np.floating)) and np.isfinite(cell_size) and cell_size > 0):
        raise ValueError(f"cell_size = {cell_size!r} m is not a positive finite length")
    if int(samples) != samples or samples < 1:
        raise ValueError(f"samples = {samples!r} is not an integer >= 1")
    points, faces = _surface_arrays(surface)
    if faces is None or len(faces) == 0:
        raise ValueError("the surface has no faces: a lattice needs a closed triangle surface")
    h, samples = float(cell_size), int(samples)
    low, high = points.min(axis=0), points.max(axis=0)
    counts = np.maximum(np.ceil((high - low) / h - GRID_SNAP), 1).astype(np.int64)
    origin = 0.5 * (low + high) - 0.5 * h * counts
    longest = float(np.linalg.norm(np.diff(points[faces][:, [0, 1, 2, 0]], axis=1), axis=2).max())
    iterations = int(np.ceil(np.log2(max(longest / (0.5 * h), 1.0)))) + 2
    fine, _ = trimesh.remesh.subdivide_to_size(points, faces, max_edge=0.5 * h, max_iter=iterations)
    # A point of a triangle with edges <= h/2 lies within h / (2 sqrt 3) of one of its vertices, so the cells
    # that the box of that half-width around each vertex overlaps hold every cell the surface crosses.
    near = np.zeros(counts, dtype=bool)
    reach = 0.5 * h / np.sqrt(3.0) * (1.0 + GRID_SNAP)
    for corner in CORNERS:
        shifted = fine + reach * (2 * corner - 1)
        touched = np.clip(np.floor((shifted - origin) / h).astype(np.int64), 0, counts - 1)
        near[tuple(touched.T)] = True

    fractions = np.zeros(counts)
    far = np.argwhere(~near)
    if len(far):
        fractions[tuple(far.T)] = contains_points(surface, origin + h * (far + 0.5))
    close = np.argwhere(near)
    offsets = (np.stack(np.meshgrid(*[np.arange(samples)] * 3, indexing="ij"), axis=-1).reshape(-1, 3) + 0.5) / samples
    # Sample in batches of cells to bound memory (about 8 M points each).
    batch = max(1, 8_000_000 // len(offsets))
    for begin in range(0, len(close), batch):
        part = close[begin:begin + batch]
        probes = origin + h * (part[:, None, :] + offsets[None, :, :])
        inside = contains_points(surface, probes.reshape(-1, 3)).reshape(len(part), len(offsets))
        fractions[tuple(part.T)] = inside.mean(axis=1)
    kept = np.argwhere(fractions > 0)  # argwhere is lexicographic: the cells come sorted
    if len(kept) == 0:
        raise ValueError(f"no cell of {h} m overlaps the inside of the surface (bounds {low.tolist()} to "
                         f"{high.tolist()} m): is it closed and outward-wound?")
    return Lattice(origin, h, kept, fractions[tuple(kept.T)])


# ---------------------------------------------------------------------------- anchoring
@dataclass(frozen=True, eq=False, repr=False)
class LatticeAnchor(WeightedAnchor):
    """A render surface bound to a lattice by trilinear weights (the interface of :class:`meshing.Anchor`).

    Parameters
    ----------
    cell_index : (p,) int64
        the lattice cell each surface vertex is bound to
    nodes : (p, 8) int64
        that cell's corner nodes (``lattice.cell_nodes[cell_index]``)
    weights : (p, 8) float64
        trilinear weights in that cell; each row sums to 1, entries outside [0, 1] only for vertices outside every kept
        cell (extrapolated)
    points : (p, 3) float64
        the surface vertices at rest [m]
    faces : (k, 3) int64 or None
        the render surface's triangles, if it was given as a mesh
    outside : (p,) bool
        vertices in no kept cell
    outside_distance : (p,) float64
        distance from each vertex to its cell [m]; 0 inside
    node_count : int
        nodes of the lattice, checked by :meth:`deform`
    """

    cell_index: np.ndarray
    nodes: np.ndarray
    weights: np.ndarray
    points: np.ndarray
    faces: np.ndarray | None
    outside: np.ndarray
    outside_distance: np.ndarray
    node_count: int

    node_owner = "the lattice's"


def anchor_lattice(lattice: Lattice, surface: trimesh.Trimesh | np.ndarray) -> LatticeAnchor:
    """Bind every vertex of a render surface to the lattice cell holding it, by trilinear weights.

    Parameters
    ----------
    lattice : Lattice
    surface : trimesh.Trimesh or (p, 3) float
        the render surface or bare vertex positions [m]

    Returns
    -------
    LatticeAnchor
        A vertex on a face shared by two kept cells takes either (the weights agree there). A vertex in no
        kept cell takes the kept cell nearest to it (by cell centre) with extrapolated weights, which still
        sum to 1 and reproduce the vertex at rest; these are counted and logged.

    Examples
    --------
    >>> import numpy as np
    >>> from meshing.lattice import anchor_lattice, box_lattice
    >>> lattice = box_lattice((2, 1, 1), (2.0, 1.0, 1.0))
    >>> bound = anchor_lattice(lattice, np.array([[0.5, 0.5, 0.5], [2.5, 0.5, 0.5]]))
    >>> bound.outside.tolist(), np.allclose(bound.deform(3 * lattice.points), 3 * bound.points)
    ([False, True], True)
    """
    from scipy.spatial import cKDTree

    points, faces = _surface_arrays(surface)
    h = lattice.cell_size
    local = (points - lattice.origin) / h
    cell = lattice.cell_of(np.floor(local).astype(np.int64))
    # A vertex on a grid plane floors into the upper cell; if that one is not kept, try the lower neighbours.
    for axis in range(3):
        missing = cell < 0
        if not missing.any():
            break
        on_plane = missing & (np.abs(local[:, axis] - np.round(local[:, axis])) <= ON_CELL_FACE)
        if on_plane.any():
            shifted = np.floor(local[on_plane]).astype(np.int64)
            shifted[:, axis] -= 1
            cell[on_plane] = lattice.cell_of(shifted)
    missing = cell < 0
    if missing.any():
        centres = lattice.origin + h * (lattice.cells + 0.5)
        cell[missing] = cKDTree(centres).query(points[missing])[1]
    coordinates = local - lattice.cells[cell]  # (p, 3) in [0, 1] inside the cell
    excess = np.maximum(coordinates - 1.0, 0.0) + np.maximum(-coordinates, 0.0)
    outside = (excess > ON_CELL_FACE).any(axis=1)
    distance = np.where(outside, h * np.linalg.norm(excess, axis=1), 0.0)
    factors = np.where(CORNERS[None, :, :] == 1, coordinates[:, None, :], 1.0 - coordinates[:, None, :])
    weights = factors.prod(axis=2)
    result = LatticeAnchor(cell, lattice.cell_nodes[cell], weights, points, faces, outside, distance,
                           lattice.node_count)
    if result.outside_count:
        logger.info("%d of %d surface vertices lie in no lattice cell (up to %.3g away, cell size %.3g): anchored "
                    "to the nearest cell by extrapolated weights", result.outside_count, len(points),
                    result.max_outside_distance, h)
    return result
