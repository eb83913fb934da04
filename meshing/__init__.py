"""meshing: closed surfaces in, clean tetrahedral meshes out (gmsh or Delaunay of Steiner points),
with virtual shell layers, barycentric anchoring of a render surface and mesh quality."""

__all__ = []
