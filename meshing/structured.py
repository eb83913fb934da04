"""Structured box meshes: a grid of cells, each split into six tets (tests, benchmarks, validation cases).

Every cell of an ``nx x ny x nz`` grid is cut into Kuhn's six tets around one of its diagonals,
so the mesh has exactly ``(nx + 1)(ny + 1)(nz + 1)`` nodes; the box spans
``[0, lx] x [0, ly] x [0, lz]`` from ``origin``. Two patterns, both conforming across cells:

``"mirrored"`` (the default)
    The split of cell (i, j, k) is reflected in x when i is odd, in y when j is odd, in z when k
    is odd, so the cells' diagonals alternate and the mesh has the mirror symmetries of the box
    on average. A spring network takes the anisotropy of its mesh: on ``"kuhn"`` a bar hanging
    along z sways sideways by half its stretch (2.2 mm sideways for 4.7 mm down, measured on the
    hanging-bar case), because every cell's springs lean along the same diagonal and couple axial
    stretch to shear. Linear FEM elements do not care (1e-5 of it).
``"kuhn"``
    The same diagonal 000 -> 111 in every cell (the usual structured tet grid).

Examples
--------
>>> from meshing import structured_box
>>> mesh = structured_box((10, 1, 1), (1.0, 0.1, 0.1))
>>> mesh.node_count, mesh.tet_count, round(mesh.volume, 12)
(44, 60, 0.01)
"""

from __future__ import annotations

import numpy as np
from collections.abc import Sequence

from meshing.geometry import signed_tet_volumes
from meshing.mesh import TetMesh

__all__ = ["KUHN_PATHS", "jittered_cube", "structured_box"]

#: Kuhn's six tets of a cell, as corner numbers a*4 + b*2 + c of the corner (a, b, c) in {0, 1}^3.
KUHN_PATHS = ((0, 4, 6, 7), (0, 4, 5, 7), (0, 2, 6, 7), (0, 2, 3, 7), (0, 1, 5, 7), (0, 1, 3, 7))


def structured_box(cells: Sequence[int], size: Sequence[float], *, origin: Sequence[float] = (0.0, 0.0, 0.0),
                   pattern: str = "mirrored") -> TetMesh:
    """A box of ``cells`` grid cells, six Kuhn tets per cell.

    Parameters
    ----------
    cells : (3,) int
        cells along x, y, z, each >= 1
    size : (3,) float
        box edge lengths [m], each > 0
    origin : (3,) float
        the corner with the smallest coordinates [m]
    pattern : {"mirrored", "kuhn"}
        how the cells' splits are oriented (module docstring)

    Returns
    -------
    TetMesh
        ``prod(cells + 1)`` nodes, ``6 prod(cells)`` positively oriented tets

    Raises
    ------
    ValueError
        For a cell count below 1, a size that is not positive and finite, or an unknown pattern.
    """
    if pattern not in ("mirrored", "kuhn"):
        raise ValueError(f"pattern = {pattern!r} is not 'mirrored' or 'kuhn'")
    cells = tuple(int(c) for c in cells)
    size = tuple(float(s) for s in size)
    if len(cells) != 3 or min(cells) < 1:
        raise ValueError(f"cells = {cells} must be three counts >= 1")
    if len(size) != 3 or not all(np.isfinite(s) and s > 0 for s in size):
        raise ValueError(f"size = {size} m must be three positive finite lengths")
    nx, ny, nz = cells
    axes = [origin[d] + np.linspace(0.0, size[d], cells[d] + 1) for d in range(3)]
    points = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    index = np.arange(len(points)).reshape(nx + 1, ny + 1, nz + 1)
    i, j, k = (a.ravel() for a in np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij"))
    if pattern == "mirrored":
        flip_i, flip_j, flip_k = i % 2, j % 2, k % 2
    else:
        flip_i = flip_j = flip_k = np.zeros_like(i)
    corner = [index[i + (a ^ flip_i), j + (b ^ flip_j), k + (c ^ flip_k)]
              for a in (0, 1) for b in (0, 1) for c in (0, 1)]
    tets = np.concatenate([np.stack([corner[p] for p in path], axis=1) for path in KUHN_PATHS])
    # Half of Kuhn's paths, and every mirrored cell, number their tets the other way round: orient each
    # tet here, where that is by construction (TetMesh.oriented refuses mixed orientations as tangles).
    negative = signed_tet_volumes(points, tets) < 0
    tets[negative, 2:] = tets[negative, 3:1:-1]
    return TetMesh(points, tets)


def jittered_cube(points_per_side: int = 5, *, jitter: float = 0.08, seed: int = 11) -> TetMesh:
    """The unit cube as Delaunay tets of a grid whose interior points are moved at random: no two tets alike.

    An unstructured mesh with a known shape, for patch tests and calibration studies. Interior points move
    by up to ``jitter`` times four cell sizes over the grid spacing (``jitter`` of the cube at five points a
    side), drawn from ``numpy.random.default_rng(seed)``; the flat tets Delaunay leaves between coplanar
    boundary points are dropped and the rest oriented positively.

    >>> mesh = jittered_cube()
    >>> mesh.node_count, round(mesh.volume, 12)
    (125, 1.0)
    """
    from scipy.spatial import Delaunay

    rng = np.random.default_rng(seed)
    grid = np.stack(np.meshgrid(*[np.linspace(0, 1, points_per_side)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    interior = ((grid > 0) & (grid < 1)).all(axis=1)
    grid[interior] += rng.uniform(-jitter, jitter, (interior.sum(), 3)) * 4 / (points_per_side - 1)
    tets = Delaunay(grid).simplices
    volumes = signed_tet_volumes(grid, tets)
    keep = np.abs(volumes) > 1e-6 / (points_per_side - 1) ** 3
    tets, volumes = tets[keep].copy(), volumes[keep]
    tets[volumes < 0, 2:] = tets[volumes < 0, 3:1:-1]
    return TetMesh.compact(grid, tets)
