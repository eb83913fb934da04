"""Spatial hashing of boxes (Teschner et al. 2003), and vertex-in-tet detection built on it.

The hash table of the paper is replaced by a sort: every item (a vertex, a triangle) is entered
in each grid cell its bounding box covers, under the key ``hash(cell) * G + group``; the keys are
sorted once, and a query box looks up each of its cells with two binary searches. Cells whose
hashes collide share a key range, so every candidate is checked against its real cell before any
geometric test: a tiny table is slow, never wrong. When the grid over the items' cells is small (a
few cells per entry, and no more than the table size), vertex-in-tet detection and the depths'
edge-surface search use that grid itself as a table without collisions (:func:`box_pairs`): one
lookup per column of a query's cells. The geometric test is the barycentric inside test of
:func:`meshing.geometry.barycentric_frames`, the one anchoring uses too.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from meshing.geometry import barycentric_frames
from volspring.collision.bodies import CollisionBodies
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

__all__ = ["HASH_PRIMES", "DEFAULT_TABLE_SIZE", "SpatialHash", "VertexTetContacts", "box_pairs", "cell_hash",
           "detect_collisions"]

logger = logging.getLogger(__name__)

HASH_PRIMES = (73856093, 19349663, 83492791)
# 2^31 - 1 is prime; with sorting in place of a table the size costs no memory, and a large
# table keeps different cells from sharing keys (which would only cost time, see the module doc).
DEFAULT_TABLE_SIZE = 2_147_483_647
_GROUP_RULES = ("all", "other", "same")


def cell_hash(cells: ArrayLike, table_size: int = DEFAULT_TABLE_SIZE) -> np.ndarray:
    """Teschner's hash of integer cells: ``(i p1 xor j p2 xor k p3) mod table_size``.

    Parameters
    ----------
    cells : (k, 3) int64
        cell coordinates ``floor(x / cell_size)``
    table_size : int
        number of hash buckets, ``1 <= table_size <= 2**31 - 1``

    Returns
    -------
    (k,) int64
        hashes in ``[0, table_size)``; products wrap in int64 (still deterministic) and ``np.mod`` with a positive
        divisor never returns a negative value.
    """
    cells = np.asarray(cells, dtype=np.int64)
    mixed = (cells[:, 0] * HASH_PRIMES[0]) ^ (cells[:, 1] * HASH_PRIMES[1]) ^ (cells[:, 2] * HASH_PRIMES[2])
    return np.mod(mixed, np.int64(table_size))


def expand_ranges(starts, counts) -> tuple[np.ndarray, np.ndarray]:
    """Flatten ranges ``[starts[r], starts[r] + counts[r])``: ``(owner, index)``, both ``(sum(counts),) int64``."""
    counts = np.asarray(counts, dtype=np.int64)
    owner = np.repeat(np.arange(len(counts), dtype=np.int64), counts)
    first = np.cumsum(counts) - counts
    index = np.arange(len(owner), dtype=np.int64) - first[owner] + np.asarray(starts, dtype=np.int64)[owner]
    return owner, index


def _all3(flags) -> np.ndarray:
    """``flags.all(axis=1)`` for (k, 3) bool, column by column (several times faster for small rows)."""
    return flags[:, 0] & flags[:, 1] & flags[:, 2]


def _box_cells(cell_lo, cell_hi):
    """Every cell of each integer box: ``(owner (K,), cells (K, 3))``, variable sizes expanded by np.repeat."""
    size = cell_hi - cell_lo + 1
    owner, local = expand_ranges(np.zeros(len(size), dtype=np.int64), size[:, 0] * size[:, 1] * size[:, 2])
    ny, nz = size[owner, 1], size[owner, 2]
    offset = np.stack([local // (ny * nz), (local // nz) % ny, local % nz], axis=1)
    return owner, cell_lo[owner] + offset


def _check_table_size(table_size):
    if not 1 <= int(table_size) <= DEFAULT_TABLE_SIZE:
        raise ValueError(f"table_size = {table_size} is not in [1, {DEFAULT_TABLE_SIZE}]")
    return int(table_size)


@dataclass(frozen=True, eq=False)
class SpatialHash:
    """Axis-aligned boxes entered in a hashed uniform grid, queried by other boxes.

    Build with :meth:`build`; :meth:`query` returns every (query box, item box) pair whose boxes
    overlap, each pair once.

    Examples
    --------
    >>> import numpy as np
    >>> points = np.array([[0.1, 0.1, 0.1], [2.5, 0.0, 0.0]])
    >>> grid = SpatialHash.build(points, points, cell_size=1.0)
    >>> grid.query(np.zeros((1, 3)), np.full((1, 3), 0.5))
    (array([0]), array([0]))
    """

    cell_size: float
    table_size: int
    group_count: int
    item_lo: np.ndarray  # (k, 3) float
    item_hi: np.ndarray  # (k, 3) float
    item_cell_lo: np.ndarray  # (k, 3) int64
    keys: np.ndarray  # (K,) int64, sorted hash * group_count + group
    entry_item: np.ndarray  # (K,) int64, item of each sorted entry
    entry_cell: np.ndarray  # (K, 3) int64, real cell of each sorted entry

    @classmethod
    def build(cls, item_lo: np.ndarray, item_hi: np.ndarray, *, cell_size: float | None,
              table_size: int = DEFAULT_TABLE_SIZE, item_group: np.ndarray | None = None) -> "SpatialHash":
        """Enter boxes ``[item_lo, item_hi]`` ((k, 3) float [m]) in every cell they cover.

        ``item_group`` ((k,) int, default all 0) tags each item, e.g. with its body id, so that
        queries can keep only items of another group (or of the same group) without generating
        the rest.
        """
        if cell_size is None or not np.isfinite(cell_size) or cell_size <= 0:
            raise ValueError(f"cell_size = {cell_size} is not a positive length")
        table_size = _check_table_size(table_size)
        item_lo = np.asarray(item_lo, dtype=np.float64)
        item_hi = np.asarray(item_hi, dtype=np.float64)
        group = np.zeros(len(item_lo), dtype=np.int64) if item_group is None else np.asarray(item_group, np.int64)
        group_count = int(group.max()) + 1 if len(group) else 1
        cell_lo = np.floor(item_lo / cell_size).astype(np.int64)
        owner, cells = _box_cells(cell_lo, np.floor(item_hi / cell_size).astype(np.int64))
        keys = cell_hash(cells, table_size) * group_count + group[owner]
        order = np.argsort(keys, kind="stable")
        return cls(float(cell_size), table_size, group_count, item_lo, item_hi, cell_lo,
                   keys[order], owner[order], cells[order])

    def query(self, query_lo: ArrayLike, query_hi: ArrayLike, *, query_group: ArrayLike | None = None,
              rule: str = "all") -> tuple[np.ndarray, np.ndarray]:
        """All overlapping (query, item) box pairs.

        Parameters
        ----------
        query_lo, query_hi : (q, 3) float
            query boxes [m]
        query_group : (q,) int, optional
            group of each query (default 0)
        rule : {"all", "other", "same"}
            which items a query may pair with: any, only those of another group (e.g. another body), or only those of
            its own group

        Returns
        -------
        (query, item) : two (p,) int64 arrays
            each overlapping pair exactly once, in no set order
        """
        if rule not in _GROUP_RULES:
            raise ValueError(f"rule = {rule!r} is not one of {_GROUP_RULES}")
        query_lo = np.asarray(query_lo, dtype=np.float64)
        query_hi = np.asarray(query_hi, dtype=np.float64)
        groups = np.zeros(len(query_lo), dtype=np.int64) if query_group is None else np.asarray(query_group, np.int64)
        q_cell_lo = np.floor(query_lo / self.cell_size).astype(np.int64)
        owner, cells = _box_cells(q_cell_lo, np.floor(query_hi / self.cell_size).astype(np.int64))
        base = cell_hash(cells, self.table_size) * self.group_count
        g = groups[owner]

        def search(key: np.ndarray) -> np.ndarray:
            return np.searchsorted(self.keys, key)

        # Most query cells are empty: find the whole bucket first and look inside only non-empty ones.
        first, stop = search(base), search(base + self.group_count)
        busy = np.flatnonzero(stop > first)
        owner, cells, base, g, first, stop = owner[busy], cells[busy], base[busy], g[busy], first[busy], stop[busy]
        if rule == "all":
            ranges = [(first, stop)]
        elif rule == "same":
            ranges = [(search(base + g), search(base + g + 1))]
        else:
            own_lo, own_hi = search(base + g), search(base + g + 1)
            ranges = [(first, own_lo), (own_hi, stop)]
        pieces = []
        for lo, hi in ranges:  # one or two ranges per query cell, never a loop over items
            cell_index, entry = expand_ranges(lo, np.maximum(hi - lo, 0))
            pieces.append((owner[cell_index], cells[cell_index], entry))
        q = np.concatenate([p[0] for p in pieces])
        qcell = np.concatenate([p[1] for p in pieces])
        entry = np.concatenate([p[2] for p in pieces])
        item = self.entry_item[entry]
        # Hash collisions: keep an entry only if it is really in the cell that was looked up, and report
        # each pair only in one cell, the low corner of the overlap of the two cell ranges.
        keep = _all3(self.entry_cell[entry] == qcell)
        keep &= _all3(np.maximum(q_cell_lo[q], self.item_cell_lo[item]) == qcell)
        q, item = q[keep], item[keep]
        overlap = _all3((self.item_lo[item] <= query_hi[q]) & (self.item_hi[item] >= query_lo[q]))
        return q[overlap], item[overlap]


# A dense grid over the items' cells replaces the hash when it has at most this many cells per entry (times
# the groups), plus a floor for tiny sets: its memory and its one pass over the cells stay O(entries).
_DENSE_CELLS_PER_ENTRY = 8
_DENSE_CELLS_FLOOR = 4096


def box_pairs(item_lo: np.ndarray, item_hi: np.ndarray, query_lo: np.ndarray, query_hi: np.ndarray, *,
             cell_size: float, table_size: int = DEFAULT_TABLE_SIZE, item_group: np.ndarray | None = None,
             query_group: np.ndarray | None = None, rule: str = "all") -> tuple[np.ndarray, np.ndarray]:
    """All overlapping (query, item) box pairs: ``SpatialHash.build(item_lo, item_hi, ...).query(query_lo, ...)``.

    The same pairs, each once, in the same order for ``rule="same"`` (by query, then by the cell at the low
    corner of the two boxes' overlap, then by item); for ``"other"`` and ``"all"`` with several groups, by
    query and group first. When the grid over the items' cells fits in ``table_size`` buckets (and in a few
    cells per entry), that grid is the table, without collisions: an entry's key is ``group * cells + cell``,
    the cells numbered along z fastest, so the entries of one group in one (x, y) column of a query's cells are
    one run of the sorted keys, read from a cumulative count: two lookups per column instead of binary
    searches per cell. Otherwise the hash is used.

    Parameters
    ----------
    item_lo, item_hi : (k, 3) float
        item boxes [m]
    query_lo, query_hi : (q, 3) float
        query boxes [m]
    cell_size : float
        grid cell edge [m]
    table_size : int
        hash buckets; the dense grid is used only if it has no more cells than this
    item_group, query_group : (k,) and (q,) int, optional
        group of each box (default 0)
    rule : {"all", "other", "same"}
        as for :meth:`SpatialHash.query`

    Returns
    -------
    (query, item) : two (p,) int64 arrays
    """
    if rule not in _GROUP_RULES:
        raise ValueError(f"rule = {rule!r} is not one of {_GROUP_RULES}")
    if cell_size is None or not np.isfinite(cell_size) or cell_size <= 0:
        raise ValueError(f"cell_size = {cell_size} is not a positive length")
    table_size = _check_table_size(table_size)
    item_group = np.zeros(len(item_lo), dtype=np.int64) if item_group is None else np.asarray(item_group, np.int64)
    query_group = np.zeros(len(query_lo), dtype=np.int64) if query_group is None else np.asarray(query_group, np.int64)
    if len(item_lo) == 0 or len(query_lo) == 0:
        return np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int64)
    item_cell_lo = np.floor(item_lo / cell_size).astype(np.int64)
    item_cell_hi = item_cell_lo if item_hi is item_lo else np.floor(item_hi / cell_size).astype(np.int64)
    corner = item_cell_lo.min(axis=0)
    size = item_cell_hi.max(axis=0) - corner + 1
    group_count = int(max(item_group.max(), query_group.max())) + 1
    cells = int(np.prod(size))
    item_cell_lo, item_cell_hi = item_cell_lo - corner, item_cell_hi - corner
    single = item_hi is item_lo or bool((item_cell_lo == item_cell_hi).all())  # a pair then meets in one cell
    owner, entry_cell = (np.arange(len(item_lo)), item_cell_lo) if single else _box_cells(item_cell_lo, item_cell_hi)
    if group_count * cells > min(table_size, _DENSE_CELLS_PER_ENTRY * len(owner) + _DENSE_CELLS_FLOOR):
        grid = SpatialHash.build(item_lo, item_hi, cell_size=cell_size, table_size=table_size, item_group=item_group)
        return grid.query(query_lo, query_hi, query_group=query_group, rule=rule)
    key = item_group[owner] * cells + (entry_cell[:, 0] * size[1] + entry_cell[:, 1]) * size[2] + entry_cell[:, 2]
    order = np.argsort(key, kind="stable")
    entry_item, entry_cell = owner[order], entry_cell[order]
    start = np.zeros(group_count * cells + 1, dtype=np.int64)
    np.cumsum(np.bincount(key, minlength=group_count * cells), out=start[1:])
    # The queries' cell ranges, clipped to the grid (no item lies outside it).
    lo = np.maximum(np.floor(query_lo / cell_size).astype(np.int64) - corner, 0)
    hi = np.minimum(np.floor(query_hi / cell_size).astype(np.int64) - corner, size - 1)
    span = hi - lo + 1
    query = np.flatnonzero(_all3(span > 0))
    # One row per (query, group searched): its own group, the others, or all of them.
    if rule == "same":
        group = query_group[query]
    else:
        searched = group_count - 1 if rule == "other" else group_count
        query = np.repeat(query, searched)
        shift = np.tile(np.arange(searched), len(query) // max(searched, 1))
        group = (query_group[query] + 1 + shift) % group_count if rule == "other" else shift
    # One row per (query, group, column of its cells along z), the entries of the column one run.
    row_query, column = expand_ranges(np.zeros(len(query), dtype=np.int64), span[query, 0] * span[query, 1])
    query, group = query[row_query], group[row_query]
    i = lo[query, 0] + column // span[query, 1]
    j = lo[query, 1] + column % span[query, 1]
    first_key = group * cells + (i * size[1] + j) * size[2] + lo[query, 2]
    first = start[first_key]
    row, entry = expand_ranges(first, start[first_key + span[query, 2]] - first)
    query, item = query[row], entry_item[entry]
    for axis in range(3) if not single else ():  # one coordinate at a time, each on the survivors of the last
        # Report a pair only in the cell at the low corner of the overlap of the two cell ranges.
        keep = entry_cell[:, axis][entry] == np.maximum(lo[:, axis][query], item_cell_lo[:, axis][item])
        query, item, entry = query[keep], item[keep], entry[keep]
    for axis in range(3):
        overlap = item_lo[:, axis][item] <= query_hi[:, axis][query]
        overlap &= item_hi[:, axis][item] >= query_lo[:, axis][query]
        query, item = query[overlap], item[overlap]
    return query, item


@dataclass(frozen=True, eq=False)
class VertexTetContacts:
    """Vertices found inside tets, sorted by (vertex, tet); all ids global (see CollisionBodies).

    Attributes
    ----------
    vertex : (k,) int64
        the penetrating vertex
    tet : (k,) int64
        the tet it is inside
    barycentric : (k, 4) float
        weights of the tet's four nodes at the vertex (sum 1, all >= -meshing.tolerances.ON_SURFACE, the slack for a
        vertex on a face): the response distributes the reaction on the tet's nodes with them
    vertex_body, tet_body : (k,) int64
        body ids (equal only for self-collisions)
    """

    vertex: np.ndarray
    tet: np.ndarray
    barycentric: np.ndarray
    vertex_body: np.ndarray
    tet_body: np.ndarray

    @property
    def count(self) -> int:
        return len(self.vertex)

    @property
    def colliding_vertices(self) -> np.ndarray:
        """(c,) int64 -- sorted unique vertices inside at least one tet."""
        return np.unique(self.vertex)


def detect_collisions(bodies: CollisionBodies, positions: ArrayLike, *, cell_size: float | None = None,
                      table_size: int = DEFAULT_TABLE_SIZE, self_collision: bool = False) -> VertexTetContacts:
    """Find every vertex inside a tet of another body (Teschner et al. 2003).

    Pass 1 hashes every vertex into the grid cell it lies in; pass 2 visits the cells covered by
    each tet's bounding box, takes the vertices found there, and keeps those inside the box and
    then inside the tet (all barycentric weights ``>= -ON_SURFACE``, :mod:`meshing.tolerances`; flat
    tets of a deformed mesh contain nothing).

    Parameters
    ----------
    bodies : CollisionBodies
        the topology of every deformable body
    positions : (N, 3) float or sequence of (n_b, 3) float
        current node positions [m]
    cell_size : float, optional
        grid cell edge [m]; default the mean rest edge length
    table_size : int
        hash buckets; smaller only adds candidates, never changes the result
    self_collision : bool
        also report a vertex inside a non-incident tet of its own body. Off by default: pairs within a body are then
        never generated (nor is a tet whose box misses every other body), so a scene without self-collision does not pay
        for it.

    Returns
    -------
    VertexTetContacts

    Examples
    --------
    >>> import numpy as np
    >>> from meshing import TetMesh
    >>> from volspring.collision import CollisionBodies, detect_collisions
    >>> tet = TetMesh(np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]), np.array([[0, 1, 2, 3]]))
    >>> bodies = CollisionBodies((tet, tet))
    >>> contacts = detect_collisions(bodies, [tet.points, tet.points + 0.1])
    >>> contacts.vertex.tolist(), contacts.tet.tolist(), contacts.barycentric.round(2).tolist()
    ([4], [0], [[0.7, 0.1, 0.1, 0.1]])
    """
    x = bodies.stack_positions(positions)
    cell_size = bodies.mean_edge_length if cell_size is None else float(cell_size)
    corners = x[bodies.tets]
    c = [corners[:, i] for i in range(4)]  # pairwise min/max: faster than a reduce over an axis of 4
    tet_lo = np.minimum(np.minimum(c[0], c[1]), np.minimum(c[2], c[3]))
    tet_hi = np.maximum(np.maximum(c[0], c[1]), np.maximum(c[2], c[3]))
    active_vertex = np.ones(bodies.node_count, dtype=bool)
    active_tet = np.ones(bodies.tet_count, dtype=bool)
    if not self_collision:
        # Broad phase per body: only vertices and tets inside the box of the other bodies can pair.
        body_lo = np.minimum.reduceat(x, bodies.node_offsets[:-1], axis=0)
        body_hi = np.maximum.reduceat(x, bodies.node_offsets[:-1], axis=0)
        itself = np.eye(bodies.body_count, dtype=bool)[:, :, None]
        others_lo = np.where(itself, np.inf, body_lo[None]).min(axis=1)
        others_hi = np.where(itself, -np.inf, body_hi[None]).max(axis=1)
        nb, tb = bodies.node_body, bodies.tet_body
        active_vertex = _all3((x >= others_lo[nb]) & (x <= others_hi[nb]))
        active_tet = _all3((tet_hi >= others_lo[tb]) & (tet_lo <= others_hi[tb]))
    vertices = np.flatnonzero(active_vertex)
    tets = np.flatnonzero(active_tet)
    points = x[vertices]
    local_tet, local_vertex = box_pairs(points, points, tet_lo[tets], tet_hi[tets], cell_size=cell_size,
                                       table_size=table_size, item_group=bodies.node_body[vertices],
                                       query_group=bodies.tet_body[tets], rule="all" if self_collision else "other")
    tet, vertex = tets[local_tet], vertices[local_vertex]
    if self_collision:
        own = (bodies.tets[tet] == vertex[:, None]).any(axis=1)
        tet, vertex, local_tet = tet[~own], vertex[~own], local_tet[~own]
    # Barycentric test with the map of each active tet precomputed (one 3x3 adjugate each).
    inside, weights = barycentric_frames(corners[tets]).contains(x[vertex], local_tet)
    tet, vertex, barycentric = tet[inside], vertex[inside], weights[inside]
    order = np.lexsort((tet, vertex))
    tet, vertex, barycentric = tet[order], vertex[order], barycentric[order]
    logger.debug("detection: %d active vertices, %d active tets, %d candidates, %d contacts",
                 len(vertices), len(tets), len(local_tet), len(vertex))
    return VertexTetContacts(vertex, tet, barycentric, bodies.node_body[vertex], bodies.tet_body[tet])
