"""Time collision detection and consistent penetration depths per step, at about 1k, 10k and 50k tets.

Two Kuhn-split boxes, the second tilted and pushed a third of its width into the first. For each size
the script prints the colliding points, the time of detection (Teschner et al. 2003) and of the
consistent depths (Heidelberger et al. 2004), the published figures (Pentium 4 1.8 GHz, 2003:
detection 4.3 / 30.4 / 70 / 172.5 ms at 1k / 10k / 20k / 50k tets; depths ~35 us per colliding point),
and, as a yardstick of this machine measured in the same run, the time of one sparse mat-vec with the
3N x 3N spring-stiffness pattern of the same N nodes.

Run: ``OMP_NUM_THREADS=1 python benchmarks/bench_collision.py`` (``--sizes 1000 20000`` to choose).
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import scipy.sparse as sp
from scipy.spatial.transform import Rotation

from volspring import TetMesh
from volspring.collision import CollisionBodies, consistent_penetration_depths, detect_collisions

PUBLISHED_DETECTION_MS = {1_000: 4.3, 10_000: 30.4, 20_000: 70.0, 50_000: 172.5}


def box_mesh(cells, size) -> TetMesh:
    """A box split into cells, each into Kuhn's 6 tets (the same split as tests/conftest.py)."""
    nx, ny, nz = cells
    grid = np.stack(np.meshgrid(*(np.linspace(0, s, c + 1) for s, c in zip(size, cells)), indexing="ij"), -1)
    index = np.arange((nx + 1) * (ny + 1) * (nz + 1)).reshape(nx + 1, ny + 1, nz + 1)
    i, j, k = (a.ravel() for a in np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij"))
    corner = [index[i + a, j + b, k + c] for a in (0, 1) for b in (0, 1) for c in (0, 1)]
    paths = [(0, 4, 6, 7), (0, 4, 5, 7), (0, 2, 6, 7), (0, 2, 3, 7), (0, 1, 5, 7), (0, 1, 3, 7)]
    tets = np.concatenate([np.stack([corner[p] for p in path], axis=1) for path in paths])
    return TetMesh.oriented(grid.reshape(-1, 3), tets)


def scene(total_tets):
    """Two unit boxes of about ``total_tets / 2`` tets each, overlapping by a third of their width."""
    n = max(2, round((total_tets / 12) ** (1 / 3)))
    mesh = box_mesh((n, n, n), (1.0, 1.0, 1.0))
    tilt = Rotation.from_rotvec([0.1, 0.2, 0.05]).as_matrix()
    second = (mesh.points - 0.5) @ tilt.T + [0.5 + 0.67, 0.55, 0.45]
    return CollisionBodies((mesh, mesh)), [mesh.points, second]


def best_time(function, repeat):
    """Smallest wall time of ``repeat`` calls [s] (the least disturbed by the other processes)."""
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        result = function()
        times.append(time.perf_counter() - start)
    return min(times), result


def spmv_time(bodies, repeat):
    """One product with the 3N x 3N matrix of 3x3 blocks on the diagonal and on every tet edge [s]."""
    edges = bodies.edges
    n = bodies.node_count
    rows = np.concatenate([edges[:, 0], edges[:, 1], np.arange(n)])
    cols = np.concatenate([edges[:, 1], edges[:, 0], np.arange(n)])
    pattern = sp.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n))
    matrix = sp.kron(pattern, np.ones((3, 3)), format="csr")
    vector = np.ones(3 * n)
    matrix @ vector  # warm up
    return best_time(lambda: matrix @ vector, repeat * 20)[0], matrix.nnz


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[1_000, 10_000, 50_000], help="total tets")
    parser.add_argument("--repeat", type=int, default=5, help="timed runs per size (the best is kept)")
    args = parser.parse_args(argv)
    print(f"{'tets':>7} {'nodes':>7} {'colliding':>9} {'detect ms':>9} {'paper ms':>8} {'depth ms':>8} "
          f"{'us/point':>8} {'step ms':>8} {'SpMV ms':>8} {'step/SpMV':>9}")
    for size in args.sizes:
        bodies, positions = scene(size)
        x = bodies.stack_positions(positions)
        detect_collisions(bodies, x)  # warm caches (edges, faces, adjacency are built once per scene)
        detect, contacts = best_time(lambda: detect_collisions(bodies, x), args.repeat)
        depth, depths = best_time(lambda: consistent_penetration_depths(bodies, x, contacts), args.repeat)
        spmv, _ = spmv_time(bodies, args.repeat)
        nearest = min(PUBLISHED_DETECTION_MS, key=lambda t: abs(np.log(t / bodies.tet_count)))
        paper = PUBLISHED_DETECTION_MS[nearest] * bodies.tet_count / nearest  # linear in tets, as published
        step = detect + depth
        print(f"{bodies.tet_count:>7} {bodies.node_count:>7} {depths.count:>9} {1e3 * detect:>9.2f} {paper:>8.1f} "
              f"{1e3 * depth:>8.2f} {1e6 * depth / max(depths.count, 1):>8.1f} {1e3 * step:>8.2f} "
              f"{1e3 * spmv:>8.3f} {step / spmv:>9.0f}")
    print("paper ms: Teschner et al. 2003 detection time scaled linearly from the nearest published size; "
          "their depth cost was ~35 us per colliding point (2004).")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
