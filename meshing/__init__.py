"""meshing: closed surfaces in, clean tetrahedral meshes out (gmsh or Delaunay of Steiner points),
with virtual shell layers, barycentric anchoring of a render surface and mesh quality.

The data path: ``load_surface(path)`` or a built-in ``Shape`` -> ``tetrahedralize(surface, size=...)``
-> ``TetMesh`` -> optionally ``add_shells(mesh, layers=..., thickness=...)`` (a ``SpringTopology``) and
``anchor(mesh, render_surface)``.

This is the geometry layer: it imports nothing from ``volspring`` or ``validation`` (tests/test_layers.py).
The tet mesh container is :mod:`meshing.mesh` (files: :mod:`meshing.mesh_io`), the spring graph
:mod:`meshing.topology` (files, shells included: :mod:`meshing.topology_io`), the shared geometric
kernels :mod:`meshing.geometry` and every geometric tolerance :mod:`meshing.tolerances`.
"""

from meshing.anchoring import Anchor, anchor
from meshing.lattice import Lattice, LatticeAnchor, anchor_lattice, voxelize
from meshing.mesh import TetMesh
from meshing.quality import QualitySummary, min_dihedral_angles, quality_summary, radius_ratios
from meshing.shapes import Shape, box, cylinder, ellipsoid, parse_shape, sphere, torus
from meshing.shells import add_shells
from meshing.structured import jittered_cube, structured_box
from meshing.surface import SurfaceError, load_surface
from meshing.tetrahedralize import tetrahedralize
from meshing.topology import SpringTopology
from meshing.topology_io import read_topology, write_topology

__all__ = [
    "Anchor",
    "Lattice",
    "LatticeAnchor",
    "QualitySummary",
    "Shape",
    "SpringTopology",
    "SurfaceError",
    "TetMesh",
    "add_shells",
    "anchor",
    "anchor_lattice",
    "box",
    "cylinder",
    "ellipsoid",
    "load_surface",
    "min_dihedral_angles",
    "parse_shape",
    "quality_summary",
    "radius_ratios",
    "read_topology",
    "sphere",
    "jittered_cube",
    "structured_box",
    "tetrahedralize",
    "torus",
    "voxelize",
    "write_topology",
]
