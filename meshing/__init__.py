"""meshing: closed surfaces in, clean tetrahedral meshes out (gmsh or Delaunay of Steiner points),
with virtual shell layers, barycentric anchoring of a render surface and mesh quality."""

from meshing.anchoring import Anchor, anchor
from meshing.shells import add_shells

__all__ = [
    "Anchor",
    "add_shells",
    "anchor",
]
