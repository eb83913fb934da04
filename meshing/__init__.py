"""meshing: closed surfaces in, clean tetrahedral meshes out (gmsh or Delaunay of Steiner points),
with virtual shell layers, barycentric anchoring of a render surface and mesh quality.

The data path: ``load_surface(path)`` or a built-in ``Shape`` -> ``tetrahedralize(surface, size=...)``
-> ``volspring.TetMesh`` -> optionally ``add_shells(mesh, layers=..., thickness=...)`` and
``anchor(mesh, render_surface)``.
"""

from meshing.anchoring import Anchor, anchor
from meshing.quality import QualitySummary, min_dihedral_angles, quality_summary, radius_ratios
from meshing.shapes import Shape, box, cylinder, ellipsoid, parse_shape, sphere, torus
from meshing.shells import add_shells
from meshing.structured import structured_box
from meshing.surface import SurfaceError, load_surface
from meshing.tetrahedralize import tetrahedralize

__all__ = [
    "Anchor",
    "QualitySummary",
    "Shape",
    "SurfaceError",
    "add_shells",
    "anchor",
    "box",
    "cylinder",
    "ellipsoid",
    "load_surface",
    "min_dihedral_angles",
    "parse_shape",
    "quality_summary",
    "radius_ratios",
    "sphere",
    "structured_box",
    "tetrahedralize",
    "torus",
]
