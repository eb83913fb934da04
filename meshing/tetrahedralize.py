"""Closed surfaces to tetrahedral meshes: gmsh (quality meshing) or Delaunay of Steiner points (the seed's method).

Both backends return a :class:`meshing.TetMesh` with positively oriented tets and no unused nodes. This
module checks the request (method, size, the tet-count cap) and loads the surface; the backends are
:mod:`meshing.tetrahedralize_gmsh` and :mod:`meshing.tetrahedralize_delaunay`.
"""

from __future__ import annotations

import logging
import math
import os

from meshing.mesh import TetMesh
from meshing.tetrahedralize_delaunay import _delaunay_tets
from meshing.tetrahedralize_gmsh import _gmsh_tets
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from meshing.shapes import Shape
    import trimesh

__all__ = ["MAX_TETS", "METHODS", "TETS_PER_CUBIC_SIZE", "estimated_tet_count", "excess_volume_fraction",
           "tetrahedralize"]

logger = logging.getLogger(__name__)

#: The backends :func:`tetrahedralize` knows.
METHODS = ("gmsh", "delaunay")
#: Refuse a request whose estimated tet count exceeds this (about 1.5 GB of mesh arrays and hours of gmsh).
MAX_TETS = 5_000_000
#: Tets per size^3 of volume used for that estimate: a BCC lattice of cube edge ``size`` gives 12, gmsh's
#: meshes at MeshSizeMax = size measured 5 to 8 on the built-in shapes; the larger keeps the estimate safe.
TETS_PER_CUBIC_SIZE = 12.0


def estimated_tet_count(volume: float, size: float) -> float:
    """Rough number of tets a mesh of edge ``size`` [m] needs for ``volume`` [m^3]."""
    return TETS_PER_CUBIC_SIZE * volume / size**3


def excess_volume_fraction(mesh: TetMesh, body: Shape | trimesh.Trimesh | float) -> float:
    """How much more volume the tets hold than the body, relative to the body's: ``(V_mesh - V_body) / V_body``.

    With the Delaunay backend's enclosing band this is the band's extra volume net of the chords' deficit;
    without it, or with gmsh, it is usually negative (inscribed facets cut the curved parts).

    Parameters
    ----------
    mesh : TetMesh
        the tets
    body : meshing.shapes.Shape, trimesh.Trimesh or float
        the body: a built-in shape (its exact volume), a closed surface (its enclosed volume) or the volume itself [m^3]

    Examples
    --------
    >>> from meshing.shapes import sphere
    >>> shape = sphere(0.5)
    >>> 0 < excess_volume_fraction(tetrahedralize(shape, size=0.1, method="delaunay", seed=0), shape) < 0.05
    True
    """
    volume = float(body) if isinstance(body, (int, float)) else float(body.volume)
    if not (math.isfinite(volume) and volume > 0):
        raise ValueError(f"the body's volume = {volume} is not a positive finite volume")
    return (mesh.volume - volume) / volume


def tetrahedralize(surface: trimesh.Trimesh | Shape | str | os.PathLike[str], *, size: float, method: str = "gmsh",
                   seed: int | None = None, feature_angle: float = 40.0, enclosing_band: bool | None = None,
                   verbose: bool = False) -> TetMesh:
    """Fill a closed surface with tetrahedra of edge length about ``size``.

    Parameters
    ----------
    surface : trimesh.Trimesh, meshing.shapes.Shape or path-like
        the body; files and meshes go through :func:`meshing.surface.load_surface` (checked and repaired)
    size : float
        target tet edge length [m]
    method : {"gmsh", "delaunay"}
        ``"gmsh"``: gmsh's Delaunay mesher with Netgen optimisation. A triangle surface is first
        classified (split at edges sharper than ``feature_angle``) and re-created as geometry so
        that gmsh remeshes it at ``size``; a built-in shape goes through gmsh's OCC kernel, so a box
        comes out exact. ``"delaunay"``: the seed's simple method. A BCC lattice of cube edge ``size``,
        jittered by a seeded random generator, is kept inside the surface and away from it; with the
        surface vertices and a band of points just outside, scipy's Delaunay triangulates everything;
        tets whose centroid lies inside the surface are kept, so every surface vertex is a mesh node.
        Flat and sliver tets on the boundary are peeled off (logged), and boundary edges or vertices
        that are not manifold are fixed by adding the band tets around them (logged). With
        ``enclosing_band`` (the default for built-in shapes) the surface vertices first move outward by about the chord
        sag of their facets, so that the tets' boundary lies in a thin sheet above the smooth surface
        and a finer render surface of the same shape lies inside the tets (:func:`excess_volume_fraction`
        reports the sheet's volume; it is logged too).
    seed : int, optional
        random seed (the lattice jitter; gmsh's ``Mesh.RandomSeed``)
    feature_angle : float
        dihedral angle [degrees] above which an edge is a sharp feature: gmsh, triangle surfaces: kept as such;
        delaunay: a crease the enclosing band does not round (faces meeting at a smaller angle sample a curved surface).
        A smooth scan with coarse facets wants 180.
    enclosing_band : bool, optional
        delaunay only: move the surface vertices outward by 1.5 x the estimated chord sag of their facets (the height
        of their PN patches, from normals; flat facets and creases do not move), so that the tets enclose the smooth
        shape the facets are chords of, and split the curved edges whose flipped diagonal Delaunay took under that
        shape; ``False`` keeps the surface vertices on the input surface (the tets' boundary is then the input
        facets). Default (None): on for built-in shapes, off for loaded surfaces (on the coarse bunny it keeps the OBJ's
        vertices inside the tets but adds 11% of volume: its sag estimate on coarse facets is large). gmsh's meshes are
        not affected.
    verbose : bool
        let gmsh print its progress

    Returns
    -------
    TetMesh
        positively oriented tets, no unused nodes

    Raises
    ------
    ValueError
        For an unknown method, a size that is not positive and finite, or a size so small that the
        mesh would need more than :data:`MAX_TETS` tets; :class:`meshing.surface.SurfaceError` for a
        surface that cannot bound a solid.

    Examples
    --------
    >>> from meshing.shapes import box
    >>> mesh = tetrahedralize(box(1.0, 0.1, 0.1), size=0.05)
    >>> abs(mesh.volume - 0.01) < 1e-12
    True
    """
    from meshing.shapes import Shape
    from meshing.surface import load_surface

    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; expected one of {', '.join(METHODS)}")
    try:
        size = float(size)
    except (TypeError, ValueError):
        raise ValueError(f"size = {size!r} is not a number") from None
    if not (math.isfinite(size) and size > 0):
        raise ValueError(f"size = {size} is not a positive finite length")
    if not isinstance(surface, Shape):
        import trimesh

        if not isinstance(surface, (trimesh.Trimesh, str, os.PathLike)):
            raise TypeError(f"surface must be a trimesh.Trimesh, a Shape or a path, got {type(surface).__name__}")
        surface = load_surface(surface)
    volume = surface.volume
    estimate = estimated_tet_count(volume, size)
    if estimate > MAX_TETS:
        raise ValueError(
            f"size = {size:g} is too small for a body of volume {volume:.4g}: about {estimate:.3g} tets "
            f"({TETS_PER_CUBIC_SIZE:g} x volume / size^3), more than the cap of {MAX_TETS:,}; "
            f"use size >= {(TETS_PER_CUBIC_SIZE * volume / MAX_TETS) ** (1 / 3):.3g}"
        )
    if method == "gmsh":
        points, tets = _gmsh_tets(surface, size, seed, feature_angle, verbose)
    else:
        shape = isinstance(surface, Shape)
        if enclosing_band is None:
            enclosing_band = shape
        if isinstance(surface, Shape):
            surface = surface.surface(size=size)
        points, tets = _delaunay_tets(surface, size, seed, movable_surface=shape, enclosing_band=enclosing_band,
                                      feature_angle=feature_angle)
    mesh = TetMesh.compact(points, tets)
    logger.info("%s: %d nodes, %d tets, volume %.6g (surface %.6g, %+.2f%%)", method, mesh.node_count,
                mesh.tet_count, mesh.volume, volume, 100 * excess_volume_fraction(mesh, volume))
    return mesh
