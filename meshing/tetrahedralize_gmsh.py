"""The gmsh backend of :func:`meshing.tetrahedralize.tetrahedralize`: gmsh's Delaunay mesher with Netgen optimisation.

A built-in shape goes through gmsh's OCC kernel, so a box comes out exact. A triangle surface is
classified (split at edges sharper than the feature angle) and re-created as geometry, one gmsh
volume per closed body, so that gmsh remeshes it at the requested size; a feature angle at which
gmsh's reparametrisation fails is retried at others. gmsh's global state stays inside
:func:`meshing._gmsh.gmsh_session`.
"""

from __future__ import annotations

import logging
import math

import numpy as np

__all__: list[str] = []

# The logger of tetrahedralize(), which this backend serves: one name to configure for both.
logger = logging.getLogger("meshing.tetrahedralize")


def _gmsh_tets(surface, size, seed, feature_angle, verbose):
    """(points, tets) filling ``surface`` (a ``Shape`` or a checked ``trimesh.Trimesh``) with tets of edge about
    ``size`` [m], one gmsh volume per closed body."""
    from meshing._gmsh import gmsh_session
    from meshing.shapes import Shape

    if isinstance(surface, Shape):
        with gmsh_session(verbose=verbose) as gmsh:
            surface.add_to_gmsh()
            return _gmsh_generate(gmsh, size, seed)
    bodies = surface.split(only_watertight=False) if surface.body_count > 1 else [surface]
    parts = []
    for body in bodies:  # one gmsh volume per closed body (a handful), not a loop over mesh entities
        # Feature angles to try in turn: gmsh's reparametrisation fails on some patch layouts, and a
        # failure at one angle often succeeds at another (the coarse bunny fails at 30..120 degrees).
        angles = list(dict.fromkeys([feature_angle, 180.0, 20.0]))
        for attempt, angle in enumerate(angles):
            try:
                with gmsh_session(verbose=verbose) as gmsh:
                    _gmsh_add_triangles(gmsh, body, angle)
                    parts.append(_gmsh_generate(gmsh, size, seed))
                break
            except Exception as error:  # gmsh raises bare Exception
                if attempt == len(angles) - 1:
                    raise ValueError(
                        f"gmsh could not remesh the surface at feature angles {angles}: {error}") from error
                logger.info("gmsh failed at feature angle %g degrees (%s); trying %g", angle, error,
                            angles[attempt + 1])
    offsets = np.cumsum([0] + [len(points) for points, _ in parts[:-1]])
    return (np.concatenate([points for points, _ in parts]),
            np.concatenate([tets + offset for (_, tets), offset in zip(parts, offsets)]))


def _gmsh_add_triangles(gmsh, surface, feature_angle):
    """Turn a triangle surface into gmsh geometry bounding one volume (gmsh tutorial t13)."""
    gmsh.model.addDiscreteEntity(2, 1)
    gmsh.model.mesh.addNodes(2, 1, np.arange(1, len(surface.vertices) + 1), surface.vertices.ravel())
    gmsh.model.mesh.addElementsByType(1, 2, [], (surface.faces + 1).ravel())  # element type 2: 3-node triangle
    # Without classify + createGeometry gmsh keeps the input triangles and ignores the size (REFERENCE s.7).
    gmsh.model.mesh.classifySurfaces(math.radians(feature_angle), True, True, math.pi)
    gmsh.model.mesh.createGeometry()
    loop = gmsh.model.geo.addSurfaceLoop([tag for _, tag in gmsh.model.getEntities(2)])
    gmsh.model.geo.addVolume([loop])
    gmsh.model.geo.synchronize()


def _gmsh_generate(gmsh, size, seed):
    gmsh.option.setNumber("Mesh.MeshSizeMin", 0.0)
    gmsh.option.setNumber("Mesh.MeshSizeMax", size)
    # Sizes attached to geometry points (for a triangle surface: its own edge lengths) would override `size`.
    gmsh.option.setNumber("Mesh.MeshSizeFromPoints", 0)
    gmsh.option.setNumber("Mesh.Optimize", 1)
    gmsh.option.setNumber("Mesh.OptimizeNetgen", 1)
    if seed is not None:
        gmsh.option.setNumber("Mesh.RandomSeed", int(seed) % 2**31)
    gmsh.model.mesh.generate(3)
    tags, coords, _ = gmsh.model.mesh.getNodes()
    _, element_nodes = gmsh.model.mesh.getElementsByType(4)  # element type 4: 4-node tet
    if len(element_nodes) == 0:
        raise ValueError("gmsh produced no tets")
    lookup = np.zeros(int(tags.max()) + 1, dtype=np.int64)
    lookup[tags.astype(np.int64)] = np.arange(len(tags))
    return coords.reshape(-1, 3), lookup[element_nodes.astype(np.int64).reshape(-1, 4)]
