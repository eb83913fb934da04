"""CG iterations of the deterministic AMG set-up against pyamg's random default, on gmsh beams.

volspring smooths the AMG prolongator with row-wise Gershgorin weights at omega = 2
(``volspring.solvers.PROLONGATION_OMEGA``), which draws no random numbers; pyamg's default scales by a
spectral radius estimated from a random start vector (numpy's global generator), which made runs
irreproducible. This prints, for each beam, material and step, the CG iterations at rtol 1e-3 and 1e-6
with: the random default (omega 4/3 / rho, global seed 0), Gershgorin at omega 4/3, and Gershgorin at
omega 2 (ours), with the same smoother, strength and coarse solver as ``AMGConjugateGradient``.

Run::

    python benchmarks/bench_amg_weighting.py                 # 10k and 50k nodes (about two minutes)
    python benchmarks/bench_amg_weighting.py --nodes 10000
"""

import os

for _variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_variable] = "1"

import argparse  # noqa: E402

import numpy as np  # noqa: E402
import pyamg  # noqa: E402

from bench_implicit import MATERIAL, beam_mesh  # noqa: E402
from meshing.geometry import rigid_body_modes  # noqa: E402
from volspring import Gravity, Material, Pins, Scene, Model  # noqa: E402
from volspring.integrators.implicit import ImplicitEuler  # noqa: E402
from volspring.solvers import PROLONGATION_OMEGA, conjugate_gradient  # noqa: E402

VARIANTS = [("random default", {"omega": 4 / 3, "weighting": "diagonal"}),
            ("Gershgorin 4/3", {"omega": 4 / 3, "weighting": "local"}),
            ("Gershgorin 2 (ours)", {"omega": PROLONGATION_OMEGA, "weighting": "local"})]


def iterations(matrix, modes, smooth) -> tuple:
    np.random.seed(0)  # only the random default draws from it
    ml = pyamg.smoothed_aggregation_solver(
        matrix.copy(), B=modes, symmetry="hermitian", presmoother=("block_gauss_seidel", {"sweep": "forward"}),
        postsmoother=("block_gauss_seidel", {"sweep": "backward"}), max_coarse=300, improve_candidates=None,
        coarse_solver="splu", strength=("symmetric", {"theta": 0.05}), smooth=("jacobi", smooth))
    preconditioner = ml.aspreconditioner(cycle="V")
    rhs = np.random.default_rng(1).standard_normal(matrix.shape[0])
    return tuple(conjugate_gradient(matrix.__matmul__, rhs, preconditioner=preconditioner.__matmul__, rtol=rtol)[1]
                 for rtol in (1e-3, 1e-6))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--nodes", type=int, nargs="+", default=[10000, 50000])
    args = parser.parse_args()
    print("CG iterations at rtol 1e-3 / 1e-6: " + " | ".join(name for name, _ in VARIANTS))
    for target in args.nodes:
        mesh = beam_mesh(target)
        for material in (MATERIAL, Material(1e7, 0.45, 1100.0)):
            model = Model.from_mesh(mesh, material, rule="van_gelder", damping_ratio=0.05)
            scene = Scene(model, forces=[Gravity()],
                          pins=Pins(np.flatnonzero(mesh.points[:, 0] < 1e-9)))
            for dt in (1e-3, 1e-2, 1e-1):
                matrix, _, pattern = ImplicitEuler().linear_system(scene, scene.initial_state(), dt)
                modes = rigid_body_modes(model.rest_positions[pattern.free_nodes])
                counts = [iterations(matrix, modes, smooth) for _, smooth in VARIANTS]
                print(f"{mesh.node_count:6d} nodes, nu {material.nu:.2f}, dt {dt:g} s: "
                      + " | ".join(f"{a} / {b}" for a, b in counts), flush=True)


if __name__ == "__main__":
    main()
