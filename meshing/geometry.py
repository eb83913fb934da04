"""Geometric kernels shared by meshing and by volspring's collision code, each written once and vectorised.

- Volumes: :func:`signed_volumes` of point quadruples, :func:`signed_tet_volumes` of a mesh's tets.
- Barycentric coordinates in tets: :func:`barycentric_frames` precomputes, per tet, the map from a point to
  its four weights (:class:`BarycentricFrames`); :meth:`BarycentricFrames.contains` is the one inside test of
  anchoring and collision detection.
- Triangles: :func:`triangle_area_normals`, :func:`area_weighted_vertex_normals`,
  :func:`closest_points_on_triangles` (Ericson's Voronoi regions) and :func:`nearest_surface_points` (exact
  nearest point of a triangle set, through a k-d tree over the face centroids).
- :func:`rigid_body_modes`: the six infinitesimal rigid motions of a set of points, the null space of a free
  elastic body's stiffness (the near-null space smoothed aggregation needs).

This module is where they are imported from; they are written in :mod:`meshing.geometry_tets` (volumes and
barycentric frames), :mod:`meshing.geometry_triangles` and :mod:`meshing.geometry_rigid_modes`. Every
tolerance comes from :mod:`meshing.tolerances`.
"""

from meshing.geometry_rigid_modes import rigid_body_modes
from meshing.geometry_tets import BarycentricFrames, barycentric_frames, signed_tet_volumes, signed_volumes
from meshing.geometry_triangles import (area_weighted_vertex_normals, closest_points_on_triangles,
                                        nearest_surface_points, triangle_area_normals)

__all__ = ["BarycentricFrames", "area_weighted_vertex_normals", "barycentric_frames", "closest_points_on_triangles",
           "nearest_surface_points", "rigid_body_modes", "signed_tet_volumes", "signed_volumes", "triangle_area_normals"]
