"""Closed triangle surfaces: load, repair what can be repaired, refuse what cannot.

:func:`load_surface` returns a ``trimesh.Trimesh`` that is usable as the boundary of a solid:
finite coordinates, no degenerate or duplicate faces, every edge shared by exactly two faces,
every vertex a single fan of faces, consistent winding with outward normals, and no
self-intersection between faces that share no vertex (the test is
:mod:`meshing.surface_intersection`). The inside tests, :func:`winding_numbers` and
:func:`contains_points`, are :mod:`meshing.surface_winding`, re-exported here.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

import numpy as np

from meshing.surface_intersection import _crossing_face_pairs
from meshing.surface_winding import contains_points, winding_numbers
from meshing.tolerances import LARGEST_COORDINATE
from meshing.units import length_factor, scaled_points, warn_if_large
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import trimesh

__all__ = ["SURFACE_EXTENSIONS", "SurfaceError", "contains_points", "load_surface", "winding_numbers"]

logger = logging.getLogger(__name__)

#: File extensions read as triangle surfaces (through trimesh).
SURFACE_EXTENSIONS = (".stl", ".obj", ".ply", ".off", ".glb", ".gltf")


class SurfaceError(ValueError):
    """A surface that cannot bound a solid, with what is wrong and where."""


def load_surface(source: str | os.PathLike[str] | trimesh.Trimesh, *, name: str | None = None, units: str = "m",
                 scale: float | None = None) -> trimesh.Trimesh:
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
    """Refuse faces that cut through each other (faces sharing a vertex are not tested; the test is
    :func:`meshing.surface_intersection._crossing_face_pairs`)."""
    crossing = _crossing_face_pairs(mesh)
    if len(crossing):
        first = crossing[0]
        raise SurfaceError(f"{name}: {len(crossing)} pair(s) of faces cut through each other; first are faces "
                           f"{first[0]} and {first[1]} near {mesh.triangles[first[0]].mean(axis=0).tolist()}")
