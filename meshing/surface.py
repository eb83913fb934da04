"""Closed triangle surfaces: load, repair what can be repaired, refuse what cannot, and inside tests.

:func:`load_surface` returns a ``trimesh.Trimesh`` that is usable as the boundary of a solid:
finite coordinates, no degenerate or duplicate faces, every edge shared by exactly two faces,
every vertex a single fan of faces, consistent winding with outward normals, and no
self-intersection between faces that share no vertex.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

import numpy as np

from meshing.geometry import signed_volumes
from meshing.tolerances import CONTACT_NUDGE, LARGEST_COORDINATE, ZERO_VOLUME
from meshing.units import length_factor, scaled_points, warn_if_large

__all__ = ["SURFACE_EXTENSIONS", "SurfaceError", "contains_points", "load_surface", "winding_numbers"]

logger = logging.getLogger(__name__)

#: File extensions read as triangle surfaces (through trimesh).
SURFACE_EXTENSIONS = (".stl", ".obj", ".ply", ".off", ".glb", ".gltf")


class SurfaceError(ValueError):
    """A surface that cannot bound a solid, with what is wrong and where."""


def load_surface(source, *, name: str | None = None, units: str = "m", scale=None):
    """Load a triangle surface and make sure it bounds a solid, repairing what trimesh can.

    Repairs (each logged at INFO level with counts): merging vertices at the same position
    (texture or normal seams), dropping degenerate and duplicate faces and unused vertices,
    making the winding consistent, turning normals outward.

    Parameters
    ----------
    source : path-like or trimesh.Trimesh
        A surface file (see :data:`SURFACE_EXTENSIONS`) or an in-memory mesh (not modified; a
        repaired copy is returned).
    name : str, optional
        How to call the surface in messages (default: the file name).
    units : {"m", "cm", "mm"}
        The length unit of the coordinates; they are converted to metres.
    scale : float, optional
        A further factor on the coordinates; the factor to metres is ``UNITS[units] * scale``
        (:func:`meshing.units.length_factor`).

    Returns
    -------
    trimesh.Trimesh
        Closed, consistently wound, outward normals, no degenerate faces; coordinates [m].

    Raises
    ------
    ValueError
        For bad ``units`` or ``scale`` (checked before the file is opened).
    SurfaceError
        For a missing or empty file, an unknown extension, no triangles, non-finite coordinates or
        coordinates so large that volumes overflow float64, open edges (holes), non-manifold edges or
        vertices, a non-orientable surface, or faces that cut through each other; the message names
        the counts and the first offender. Also when making the winding consistent needs networkx
        and it is not installed.

    Warns
    -----
    UserWarning
        When a file read in metres with no explicit ``scale`` is more than 10 m across: probably
        millimetres (:func:`meshing.units.warn_if_large`). In-memory meshes are not warned about.

    Examples
    --------
    >>> import trimesh
    >>> surface = load_surface(trimesh.creation.icosphere(subdivisions=2))
    >>> surface.is_watertight, len(surface.faces)
    (True, 320)
    """
    import trimesh

    factor = length_factor(units, scale)
    if isinstance(source, trimesh.Trimesh):
        name = name or "the surface"
        mesh = trimesh.Trimesh(np.array(source.vertices, dtype=np.float64), np.array(source.faces), process=False)
    else:
        path = Path(source)
        name = name or os.fspath(path)
        mesh = _read(path, name)
    _check_finite(mesh, name)
    if factor != 1.0:
        try:
            mesh.vertices = scaled_points(mesh.vertices, factor, name=name)
        except ValueError as error:
            raise SurfaceError(str(error)) from None
        _check_finite(mesh, name)
    if not isinstance(source, trimesh.Trimesh):
        warn_if_large(mesh.vertices, units=units, scale=scale, name=name)
    _repair(mesh, name)
    _check_closed_manifold(mesh, name)
    _orient(mesh, name)
    _check_self_intersection(mesh, name)
    return mesh


def _read(path: Path, name: str):
    import trimesh

    suffix = path.suffix.lower()
    if suffix not in SURFACE_EXTENSIONS:
        raise SurfaceError(f"{name}: unknown surface file extension {path.suffix!r}; known: "
                           f"{', '.join(SURFACE_EXTENSIONS)}")
    if not path.is_file():
        raise SurfaceError(f"{name}: no such file")
    if path.stat().st_size == 0:
        raise SurfaceError(f"{name}: the file is empty")
    try:
        # process=False: keep the file's vertices as stored so that the repairs below can be reported.
        loaded = trimesh.load(path, process=False, force="mesh")
    except Exception as error:  # trimesh raises many types for malformed files
        raise SurfaceError(f"{name}: cannot read it as a {suffix[1:]} surface: {error}") from error
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise SurfaceError(f"{name}: the file holds no triangles")
    return trimesh.Trimesh(np.asarray(loaded.vertices, dtype=np.float64), np.asarray(loaded.faces), process=False)


def _check_finite(mesh, name):
    if len(mesh.faces) == 0:
        raise SurfaceError(f"{name}: the surface has no triangles")
    bad = ~np.isfinite(mesh.vertices).all(axis=1)
    if bad.any():
        first = np.flatnonzero(bad)[0]
        raise SurfaceError(f"{name}: {bad.sum()} vertex(es) have non-finite coordinates, first is vertex {first} "
                           f"at {mesh.vertices[first].tolist()}")
    magnitude = np.abs(mesh.vertices).max(axis=1)
    if magnitude.max() > LARGEST_COORDINATE:  # volumes, products of three coordinates, would overflow
        first = int(np.argmax(magnitude))
        raise SurfaceError(f"{name}: coordinates are too large: the largest absolute coordinate is "
                           f"{magnitude[first]:.3g} (vertex {first}), and volumes must be finite in float64 "
                           f"(below {np.finfo(np.float64).max:.3g}): expected coordinates below about "
                           f"{LARGEST_COORDINATE:.3g}; are they in the right units?")


def _repair(mesh, name):
    before = len(mesh.vertices)
    mesh.merge_vertices(merge_tex=True, merge_norm=True)
    merged = before - len(mesh.vertices)
    if merged:
        logger.info("%s: merged %d duplicate vertices (%d -> %d): the file has seams of coincident vertices",
                    name, merged, before, len(mesh.vertices))
    for what, keep in (("degenerate", mesh.nondegenerate_faces), ("duplicate", mesh.unique_faces)):
        mask = keep()
        if not mask.all():
            logger.info("%s: dropped %d %s face(s)", name, (~mask).sum(), what)
            mesh.update_faces(mask)
    if len(mesh.faces) == 0:
        raise SurfaceError(f"{name}: no triangle is left after dropping degenerate faces")
    before = len(mesh.vertices)
    mesh.remove_unreferenced_vertices()
    if len(mesh.vertices) < before:
        logger.info("%s: dropped %d vertex(es) used by no face", name, before - len(mesh.vertices))


def _check_closed_manifold(mesh, name):
    edges = mesh.edges_sorted
    n = len(mesh.vertices)
    edge_key, counts = np.unique(edges[:, 0] * n + edges[:, 1], return_counts=True)
    unique = np.stack([edge_key // n, edge_key % n], axis=1)
    for count_test, what in ((counts == 1, "open edge(s): the surface has holes"),
                             (counts > 2, "non-manifold edge(s) shared by more than two faces")):
        if count_test.any():
            first = unique[np.flatnonzero(count_test)[0]]
            raise SurfaceError(
                f"{name}: {count_test.sum()} {what}; first is edge {first.tolist()} from "
                f"{mesh.vertices[first[0]].tolist()} to {mesh.vertices[first[1]].tolist()}"
            )
    # Each vertex of a 2-manifold is one fan: the face corners at a vertex, joined across shared edges,
    # form one connected group. Two cones touching at their tips pass the edge test but fail this one.
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    faces = mesh.faces
    pairs = mesh.face_adjacency  # (p, 2) faces sharing an edge
    shared = mesh.face_adjacency_edges  # (p, 2) the shared edge's vertices
    rows, cols = [], []
    for end in (0, 1):
        vertex = shared[:, end]
        corner_a = pairs[:, 0] * 3 + np.argmax(faces[pairs[:, 0]] == vertex[:, None], axis=1)
        corner_b = pairs[:, 1] * 3 + np.argmax(faces[pairs[:, 1]] == vertex[:, None], axis=1)
        rows.append(corner_a)
        cols.append(corner_b)
    rows, cols = np.concatenate(rows), np.concatenate(cols)
    graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(faces.size, faces.size))
    _, labels = connected_components(graph, directed=False)
    fan_key = np.unique(faces.ravel() * faces.size + labels)
    fans = np.bincount(fan_key // faces.size, minlength=len(mesh.vertices))
    bad = fans > 1
    if bad.any():
        first = np.flatnonzero(bad)[0]
        raise SurfaceError(f"{name}: {bad.sum()} non-manifold vertex(es) where separate sheets touch; first is "
                           f"vertex {first} at {mesh.vertices[first].tolist()}")


def _orient(mesh, name):
    import trimesh

    if not mesh.is_winding_consistent:
        try:
            trimesh.repair.fix_winding(mesh)
        except ImportError as error:  # trimesh walks the face graph with networkx, a soft dependency of its own
            raise SurfaceError(f"{name}: making the face winding consistent needs the package networkx "
                               f"(pip install networkx): {error}") from error
        if not mesh.is_winding_consistent:
            raise SurfaceError(f"{name}: the surface is not orientable (no consistent winding exists)")
        logger.info("%s: made the face winding consistent", name)
    if mesh.body_count > 1:
        signs = [np.sign(part.volume) for part in mesh.split(only_watertight=False)]
        if min(signs) < 0:
            trimesh.repair.fix_normals(mesh, multibody=True)
            logger.info("%s: turned the normals of %d of %d bodies outward", name, signs.count(-1), len(signs))
    elif mesh.volume < 0:
        mesh.invert()
        logger.info("%s: turned the normals outward (the faces were wound inward)", name)
    if not mesh.volume > 0:
        raise SurfaceError(f"{name}: the enclosed volume is {mesh.volume:.3g}, expected > 0")


def _check_self_intersection(mesh, name):
    """Refuse faces that cut through each other (faces sharing a vertex are not tested).

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
        return
    a, b = np.concatenate(a_list), np.concatenate(b_list)
    pair_key = np.unique(np.minimum(a, b) * len(tri) + np.maximum(a, b))  # 1D keys: np.unique(axis=0) is slow
    pairs = np.stack([pair_key // len(tri), pair_key % len(tri)], axis=1)
    fa, fb = mesh.faces[pairs[:, 0]], mesh.faces[pairs[:, 1]]
    disjoint = ~(fa[:, :, None] == fb[:, None, :]).any(axis=(1, 2))
    overlap = (low[pairs[:, 0]] <= high[pairs[:, 1]]).all(1) & (low[pairs[:, 1]] <= high[pairs[:, 0]]).all(1)
    pairs = pairs[disjoint & overlap]
    if len(pairs) == 0:
        return
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
        hit[between] = first_move & np.isin(body_pair, overlapping)
    if hit.any():
        first = pairs[np.flatnonzero(hit)[0]]
        raise SurfaceError(f"{name}: {hit.sum()} pair(s) of faces cut through each other; first are faces "
                           f"{first[0]} and {first[1]} near {tri[first[0]].mean(axis=0).tolist()}")


#: The directions of the moves that decide exact contacts (their size is meshing.tolerances.CONTACT_NUDGE):
#: three fixed generic ones (the rows of a rotation parallel to no axis or
#: diagonal of a hand-made surface), each also taken the other way round.
_NUDGE_DIRECTIONS = np.linalg.qr(np.array([[0.9134, 0.2331, -0.3337], [-0.1822, 0.9614, 0.2061],
                                           [0.3627, -0.1438, 0.9207]]))[0]


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
    rule (:data:`meshing.tolerances.ZERO_VOLUME`): four points are coplanar when the tet they span is flat. An edge that touches the plane with an end, lies in it, or meets the
    triangle exactly on its boundary does not count here (see :func:`_check_self_intersection`).
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


# ---------------------------------------------------------------------- inside tests
# A fixed generic rotation: rays cast along its third axis are parallel to no face or edge of a
# hand-made surface (boxes, grids), so ties on edges have probability zero.
_RAY_FRAME = np.linalg.qr(np.array([[0.8273, 0.1947, -0.3361], [0.2214, 0.9318, 0.1123], [0.3527, -0.0716, 0.9671]]))[0]


def winding_numbers(vertices, faces, points, *, chunk: int = 2_000_000) -> np.ndarray:
    """Winding number of a closed, outward-wound triangle surface around each point.

    Counts signed crossings of a ray from each point (one fixed generic direction), with the
    faces binned on a grid across the ray so that each point meets only the faces in its column.

    Parameters
    ----------
    vertices : (n, 3) float -- surface vertices [m]
    faces : (f, 3) int -- triangles, wound with outward normals
    points : (k, 3) float -- query points [m]
    chunk : int -- largest number of (point, face) candidate pairs handled at once (memory bound)

    Returns
    -------
    (k,) int -- 1 inside a simple closed surface, 0 outside (more inside nested or overlapping bodies)
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


def contains_points(surface, points) -> np.ndarray:
    """(k,) bool -- whether each point lies inside a closed, outward-wound ``trimesh.Trimesh``."""
    return winding_numbers(surface.vertices, surface.faces, points) > 0
