"""Tet orientation: the numbering of a positively oriented tet, and raw (points, tets) arrays put in that order.

A tet (v0, v1, v2, v3) is positively oriented when ``det[v1 - v0, v2 - v0, v3 - v0] > 0``; :data:`TET_EDGES`
and :data:`TET_FACES` number its edges and outward faces (both re-exported by :mod:`meshing.mesh`, the
path callers import them from). The functions are what :class:`meshing.TetMesh` runs on arrays before it
holds them: signed volumes checked against the range of float64 (:func:`_volumes_and_extents`, which its
constructor uses too), and the arrays :meth:`TetMesh.oriented <meshing.TetMesh.oriented>` (a mesh numbered
the other way round, flipped whole) and :meth:`TetMesh.compact <meshing.TetMesh.compact>` (unused nodes
dropped, each tet in positive order) build from, both refusing tangled meshes (:func:`_tangled_faces`).
Arrays the constructor would refuse are passed through unchanged, so that it names what is wrong.
"""

from __future__ import annotations

import logging

import numpy as np

from meshing.geometry import signed_tet_volumes
from meshing.tolerances import LARGEST_COORDINATE, SMALLEST_EXTENT, ZERO_VOLUME
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

__all__ = ["TET_EDGES", "TET_FACES", "boundary_face_mask", "tet_edges"]

# The logger of TetMesh, whose constructors these functions serve: one name to configure.
logger = logging.getLogger("meshing.mesh")

# The six edges and four outward faces of a positively oriented tet (v0, v1, v2, v3),
# i.e. one with det[v1 - v0, v2 - v0, v3 - v0] > 0. Each face is wound so that its
# right-hand normal points away from the opposite vertex.
TET_EDGES = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]])
TET_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])


def tet_edges(tets: ArrayLike) -> np.ndarray:
    """(e, 2) int64 -- every edge of the (m, 4) ``tets`` once, as (i, j) with i < j, sorted."""
    tets = np.asarray(tets, dtype=np.int64)
    return np.unique(np.sort(tets[:, TET_EDGES].reshape(-1, 2), axis=1), axis=0)


def boundary_face_mask(tets: ArrayLike) -> np.ndarray:
    """(m, 4) bool -- whether face k of each tet (``TET_FACES[k]``) belongs to that tet only: the boundary."""
    tets = np.asarray(tets, dtype=np.int64)
    faces = np.sort(tets[:, TET_FACES].reshape(-1, 3), axis=1)
    _, inverse, counts = np.unique(faces, axis=0, return_inverse=True, return_counts=True)
    return (counts[inverse.ravel()] == 1).reshape(-1, 4)


def _oriented_arrays(points, tets):
    """(points, tets) for :meth:`TetMesh.oriented <meshing.TetMesh.oriented>`: flipped whole when every tet is
    negatively oriented (logged); raises ``ValueError`` when only some are, naming them and whether the mesh
    is tangled."""
    points = np.asarray(points, dtype=np.float64)
    tets = np.array(tets, dtype=np.int64, copy=True)
    if not _geometry_ready(points, tets):
        return points, tets  # let the constructor say what is wrong
    volumes, extent = _volumes_and_extents(points, tets)
    if (np.abs(volumes) <= ZERO_VOLUME * extent**3).any():
        return points, tets  # flat tets: the constructor names them
    negative = volumes < 0
    if negative.all():
        logger.info("all %d tets are negatively oriented (the other orientation convention): flipped them all",
                    len(tets))
        tets[:, 2:] = tets[:, 3:1:-1]
    elif negative.any():
        # Inverted: the tets oriented against the majority (the convention the mesh was made in).
        inverted = negative if negative.sum() <= len(tets) / 2 else ~negative
        first = np.flatnonzero(inverted)[0]
        counts = (f"{inverted.sum()} of {len(tets)} tets are inverted (oriented against the other "
                  f"{len(tets) - inverted.sum()}), first is tet {first} with signed volume "
                  f"{volumes[first]:.3g} m^3")
        if len(_tangled_faces(_positive_order(tets, negative))):
            raise ValueError(
                f"the mesh is tangled: {counts}; they overlap their neighbours, as when a node is pushed "
                "through them. Flipping them would count the volume they fold over twice: untangle or remesh "
                "where the mesh was made"
            )
        raise ValueError(
            f"{counts}; the mesh is not tangled (every face between two tets has them on opposite sides), its "
            "tets are only numbered in mixed orientations: TetMesh.compact(points, tets) puts each tet in "
            "positive order"
        )
    return points, tets


def _compact_arrays(points, tets):
    """(points, tets) for :meth:`TetMesh.compact <meshing.TetMesh.compact>`: the used nodes renumbered, each tet
    in positive order (logged); raises ``ValueError`` for a tangled mesh, naming the first shared face."""
    points, tets = _used_nodes(points, tets)
    if not _geometry_ready(points, tets):
        return points, tets
    volumes, extent = _volumes_and_extents(points, tets)
    if (np.abs(volumes) <= ZERO_VOLUME * extent**3).any():
        return points, tets  # flat tets: the constructor names them
    negative = volumes < 0
    tets = _positive_order(tets, negative)
    tangled = _tangled_faces(tets)
    if len(tangled):
        a, b = tangled[0]
        face = sorted(set(tets[a].tolist()) & set(tets[b].tolist()))
        raise ValueError(
            f"the mesh is tangled: with each tet in positive order, {len(tangled)} face(s) have their two tets on "
            f"the same side (the tets overlap), first are tets {a} and {b} sharing the face of nodes {face} "
            "(after dropping unused nodes), as when a node is pushed through its neighbours"
        )
    if negative.any():
        logger.info("put %d of %d tets in positive order", negative.sum(), len(tets))
    return points, tets


def _geometry_ready(points, tets) -> bool:
    """Whether the arrays have the shapes, index range and finite coordinates the geometry below needs
    (when not, the constructor names what is wrong)."""
    return (points.ndim == 2 and points.shape[1] == 3 and np.issubdtype(tets.dtype, np.integer) and tets.ndim == 2
            and tets.shape[1] == 4 and len(tets) > 0 and tets.min() >= 0 and tets.max() < len(points)
            and bool(np.isfinite(points).all()))


def _volumes_and_extents(points, tets):
    """Signed volumes and largest extents (m,) of the tets, refusing coordinates float64 cannot cube.

    Coordinates around 1e103 make the volumes overflow to inf (or nan), and coordinates around 1e-99
    make them underflow to 0; either way the problem is the scale of the coordinates, not flat tets.
    The arrays must pass :func:`_geometry_ready`.
    """
    with np.errstate(over="ignore", invalid="ignore", under="ignore"):
        volumes = signed_tet_volumes(points, tets)
        extent = np.ptp(points[tets], axis=1).max(axis=1)
        cubed = extent**3
    if not (np.isfinite(volumes).all() and np.isfinite(cubed).all()):
        magnitude = np.abs(points).max(axis=1)
        node = int(np.argmax(magnitude))
        raise ValueError(
            f"coordinates too large: the largest absolute coordinate is {magnitude[node]:.3g} (node {node}), and "
            f"tet volumes must be finite in float64 (below {np.finfo(np.float64).max:.3g} m^3): expected "
            f"coordinates below about {LARGEST_COORDINATE:.3g} m; are they in the right units?"
        )
    across = float(np.ptp(points, axis=0).max())
    if 0 < across < SMALLEST_EXTENT:
        raise ValueError(
            f"coordinates too small: the mesh is {across:.3g} across, and tet volumes underflow float64: expected "
            f"a mesh at least {SMALLEST_EXTENT:.3g} m across; are the coordinates in the right units?"
        )
    return volumes, extent


def _used_nodes(points, tets):
    """The nodes the tets use, renumbered in their original order, and the renumbered tets."""
    points = np.asarray(points, dtype=np.float64)
    tets = np.asarray(tets)
    if not np.issubdtype(tets.dtype, np.integer) or tets.size == 0:
        return points, tets  # the constructor says what is wrong
    used, inverse = np.unique(tets.ravel(), return_inverse=True)
    if used[0] < 0 or used[-1] >= len(points):
        return points, tets  # out of range: the constructor names the range
    return points[used], inverse.reshape(tets.shape).astype(np.int64)


def _positive_order(tets, negative):
    """(m, 4) int64 -- ``tets`` with the last two nodes of the ``negative`` ones swapped."""
    tets = np.array(tets, dtype=np.int64, copy=True)
    tets[negative, 2:] = tets[negative, 3:1:-1]
    return tets


def _tangled_faces(tets) -> np.ndarray:
    """(k, 2) int64 -- pairs of positively oriented tets that lie on the same side of a face they share.

    Each tet winds its faces outward (``TET_FACES``); two tets on opposite sides of a shared face wind it
    in opposite directions, two on the same side (overlapping) in the same one. A face's direction is the
    parity of the permutation that sorts its three nodes.
    """
    faces = tets[:, TET_FACES].reshape(-1, 3)
    parity = ((faces[:, 0] > faces[:, 1]).astype(np.int8) + (faces[:, 0] > faces[:, 2])
              + (faces[:, 1] > faces[:, 2])) % 2
    key = np.sort(faces, axis=1)
    order = np.lexsort(key.T[::-1])
    key, parity = key[order], parity[order]
    same_face = (key[1:] == key[:-1]).all(axis=1)
    same_side = np.flatnonzero(same_face & (parity[1:] == parity[:-1]))
    return np.stack([order[same_side] // 4, order[same_side + 1] // 4], axis=1)
