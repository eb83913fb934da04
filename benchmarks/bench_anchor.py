"""Benchmark barycentric anchoring: a render surface 4x finer than a ~50k-tet mesh.

The tet mesh is scipy's Delaunay of a jittered lattice filling the unit box (points on the box's faces kept on
them, so its boundary is the box). Three render surfaces:

- ``sphere``: an icosphere of radius 0.4 inside the box with at least 4x the tet mesh's *node count* in vertices
  (every vertex inside some tet);
- ``box``: the unit box's surface as a grid with at least 4x the tet mesh's *boundary vertex count*, every vertex
  on the tet mesh's boundary (no vertex is deep inside a tet: many go through the exhaustive grid search);
- ``box grown 1%``: the same surface scaled by 1.01 about the centre, so every vertex is a hair outside and goes
  through the grid search and then the nearest-boundary-face search.

Prints wall and CPU times (best of a few runs), counts and the rest and affine-exactness errors. Run from the
repository root (or after ``pip install .``, without PYTHONPATH)::

    OMP_NUM_THREADS=1 PYTHONPATH=. python benchmarks/bench_anchor.py [--cells 20] [--repeat 3]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import trimesh
from scipy.spatial import Delaunay

from meshing import TetMesh, anchor
from meshing.geometry import signed_tet_volumes


def lattice_mesh(cells: int, *, seed: int = 0) -> TetMesh:
    """Delaunay of a (cells + 1)^3 lattice on [0, 1]^3, jittered by up to a quarter spacing along every axis a
    point is not bound to (points on the box's faces stay on them, so the boundary is the box)."""
    rng = np.random.default_rng(seed)
    axis = np.linspace(0.0, 1.0, cells + 1)
    points = np.stack(np.meshgrid(axis, axis, axis, indexing="ij"), -1).reshape(-1, 3)
    free = (points > 0) & (points < 1)
    points += free * rng.uniform(-0.25, 0.25, points.shape) / cells
    tets = Delaunay(points).simplices
    volumes = np.abs(signed_tet_volumes(points, tets))
    # Coplanar points on the box's faces give flat tets there; drop those below 1e-6 of the mean volume.
    keep = volumes > 1e-6 * volumes.mean()
    return TetMesh.compact(points, tets[keep])


def fine_box(target_vertices: int) -> trimesh.Trimesh:
    """The unit box's surface as an n x n grid of squares (two triangles each) per side, with n the smallest
    giving at least ``target_vertices`` vertices (6 n^2 + 2)."""
    n = int(np.ceil(np.sqrt(max(target_vertices - 2, 6) / 6)))
    u, v = (a.ravel() for a in np.meshgrid(np.linspace(0, 1, n + 1), np.linspace(0, 1, n + 1), indexing="ij"))
    index = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = index[:-1, :-1].ravel(), index[1:, :-1].ravel(), index[1:, 1:].ravel(), index[:-1, 1:].ravel()
    square = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    vertices, faces = [], []
    for axis in range(3):
        for side in (0.0, 1.0):
            plane = np.insert(np.stack([u, v], 1), axis, side, axis=1)
            faces.append(square + sum(len(block) for block in vertices))
            vertices.append(plane)
    surface = trimesh.Trimesh(np.concatenate(vertices), np.concatenate(faces), process=True)
    trimesh.repair.fix_normals(surface)
    return surface


def icosphere(target_vertices: int) -> trimesh.Trimesh:
    """An icosphere of radius 0.4 about the box centre with at least ``target_vertices`` vertices."""
    subdivisions = 0
    while 10 * 4**subdivisions + 2 < target_vertices:
        subdivisions += 1
    sphere = trimesh.creation.icosphere(subdivisions=subdivisions, radius=0.4)
    sphere.apply_translation((0.5, 0.5, 0.5))
    return sphere


def best_time(function, repeat: int):
    """Best wall time and best CPU time of this process over ``repeat`` runs [s], and the last result.

    Both are printed: on a machine shared with other jobs the wall time includes waiting for a core."""
    wall, cpu, result = [], [], None
    for _ in range(repeat):
        start, start_cpu = time.perf_counter(), time.process_time()
        result = function()
        wall.append(time.perf_counter() - start)
        cpu.append(time.process_time() - start_cpu)
    return min(wall), min(cpu), result


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, default=20, help="lattice cells per side (20 gives 54k tets)")
    parser.add_argument("--repeat", type=int, default=3, help="runs per timing; the best is printed")
    args = parser.parse_args(argv)

    start = time.perf_counter()
    mesh = lattice_mesh(args.cells)
    print(f"tet mesh: {mesh.tet_count} tets, {mesh.node_count} nodes, {len(mesh.boundary_nodes)} boundary nodes "
          f"(built in {time.perf_counter() - start:.2f} s)")
    rng = np.random.default_rng(1)
    affine, shift = np.eye(3) + 0.3 * rng.normal(size=(3, 3)), rng.normal(size=3)
    box = fine_box(4 * len(mesh.boundary_nodes))
    grown = box.copy()
    grown.apply_scale(1.01)
    grown.apply_translation(-0.005 * np.ones(3))
    cases = [
        ("sphere, 4x node count", icosphere(4 * mesh.node_count)),
        ("box, 4x boundary vertex count", box),
        ("box grown 1%, all outside", grown),
    ]
    for name, surface in cases:
        seconds, cpu_seconds, bound = best_time(lambda: anchor(mesh, surface), args.repeat)
        deform_seconds, _, moved = best_time(lambda: bound.deform(mesh.points @ affine.T + shift), args.repeat)
        error = np.abs(moved - (surface.vertices @ affine.T + shift)).max()
        rest = np.abs(bound.deform(mesh.points) - surface.vertices).max()
        print(f"{name}: {bound.point_count} vertices anchored in {seconds:.3f} s wall, {cpu_seconds:.3f} s CPU "
              f"({cpu_seconds / bound.point_count * 1e6:.2f} us CPU per vertex); {bound.outside_count} outside "
              f"(max distance {bound.max_outside_distance:.3g}, min weight {bound.min_weight:.3g}); "
              f"deform {deform_seconds * 1e3:.2f} ms; rest error {rest:.1e}, affine error {error:.1e}")


if __name__ == "__main__":
    main()
