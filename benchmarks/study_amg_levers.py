"""Issue 15's solver levers, measured: the implicit step under variants of the AMG hierarchy, in mat-vecs.

A gmsh beam of the README's rubber (1 m x 0.2 m x 0.2 m, E = 1e7 Pa, nu = 0.45, density 1100, springs, pinned at
its x-min face, gravity) stepped with implicit Euler at the README's dt = 0.01 s, once per variant of how
:class:`volspring.solvers.amg.AMGConjugateGradient` builds its hierarchy (its ``_construct`` replaced for the
run): the median step after two, as a multiple of one mat-vec with the step's matrix (CPU time, same process),
the CG iterations, the operator complexity and the first levels' (unknowns, nonzeros). The variants:

==================  ===============================================================================
``base``            as the package builds it (six rigid-body modes, block Gauss-Seidel, smoothed P)
``translations``    the three translation modes only as near-null space
``coarse_jacobi``   Jacobi instead of Gauss-Seidel on the coarse levels
``unsmoothed_p``    tentative prolongation, not smoothed
``filtered_p``      prolongation smoothing with the strength-filtered matrix (``filter_entries``)
``max_coarse_3000`` level 1 solved directly (up to 3000 coarse unknowns)
``theta_0.2``       strength threshold 0.2 instead of 0.05
``float32``         the base hierarchy copied to float32 (matrices, smoothers, coarse LU), CG in float64
==================  ===============================================================================

Run (numpy/scipy threads held to one before numpy is imported)::

    python benchmarks/study_amg_levers.py                         # about 10k target nodes, every variant
    python benchmarks/study_amg_levers.py --nodes 40000 --variants base float32

A study, not a test: each variant runs in this process one after the other.
"""

import os

for _variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "VECLIB_MAXIMUM_THREADS"):
    os.environ[_variable] = "1"

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
import pyamg  # noqa: E402

import volspring.solvers.amg as amg  # noqa: E402
from meshing.shapes import parse_shape  # noqa: E402
from meshing.tetrahedralize import tetrahedralize  # noqa: E402
from volspring import Gravity, Material, Model, Pins, Scene  # noqa: E402
from volspring.integrators.implicit import ImplicitEuler  # noqa: E402

VARIANTS = ("base", "translations", "coarse_jacobi", "unsmoothed_p", "filtered_p", "max_coarse_3000", "theta_0.2",
            "float32")
BUILD = amg.AMGConjugateGradient._construct


def variant_build(variant):
    """A replacement for ``AMGConjugateGradient._construct`` building the hierarchy of ``variant``."""
    def construct(self):
        if variant in ("base", "float32"):
            BUILD(self)
            if variant == "float32":
                _to_float32(self)
            return
        source = self._source
        options = dict(B=source.near_null_space, symmetry="hermitian",
                       presmoother=("block_gauss_seidel", {"sweep": "forward"}),
                       postsmoother=("block_gauss_seidel", {"sweep": "backward"}),
                       smooth=("jacobi", {"omega": amg.PROLONGATION_OMEGA, "weighting": "local"}),
                       max_coarse=self.max_coarse, improve_candidates=None, coarse_solver="splu")
        theta = self.strength_theta
        if variant == "translations":
            options["B"] = source.near_null_space[:, :3]
        elif variant == "coarse_jacobi":
            options["presmoother"] = [options["presmoother"], ("jacobi", {"omega": 0.6})]
            options["postsmoother"] = [options["postsmoother"], ("jacobi", {"omega": 0.6})]
        elif variant == "unsmoothed_p":
            options["smooth"] = None
        elif variant == "filtered_p":
            options["smooth"] = ("jacobi", {"omega": amg.PROLONGATION_OMEGA, "weighting": "local",
                                            "filter_entries": True})
        elif variant == "max_coarse_3000":
            options["max_coarse"] = 3000
        elif variant == "theta_0.2":
            theta = 0.2
        hierarchy = pyamg.smoothed_aggregation_solver(source.matrix, strength=("symmetric", {"theta": theta}),
                                                      **options)
        cycle = amg._v_cycle(hierarchy)
        cycle(np.zeros(source.matrix.shape[0]))
        self._hierarchy, self._cycle = hierarchy, cycle
        self.build_count += 1
    return construct


def _to_float32(solver):
    """The solver's hierarchy copied to float32, applied to float64 residuals (cast in and out)."""
    from pyamg.multilevel import coarse_grid_solver
    from pyamg.relaxation.smoothing import change_smoothers

    hierarchy = solver._hierarchy
    for level in hierarchy.levels:
        for name in ("A", "P", "R"):
            if hasattr(level, name):
                setattr(level, name, getattr(level, name).astype(np.float32))
    change_smoothers(hierarchy, ("block_gauss_seidel", {"sweep": "forward"}),
                     ("block_gauss_seidel", {"sweep": "backward"}))
    hierarchy.coarse_solver = coarse_grid_solver("splu")
    cycle = hierarchy._MultilevelSolver__solve

    def apply(residual):
        single = residual.astype(np.float32)
        correction = np.zeros_like(single)
        cycle(0, correction, single, "V")
        return correction.astype(np.float64)

    apply(np.zeros(hierarchy.levels[0].A.shape[0]))
    solver._cycle = apply


def measure(scene, variant, steps):
    amg.AMGConjugateGradient._construct = variant_build(variant)
    try:
        integrator = ImplicitEuler(timer=time.process_time)
        state, seconds, iterations = scene.initial_state(), [], []
        for _ in range(steps):
            start = time.process_time()
            state = integrator.step(scene, state, 0.01)
            seconds.append(time.process_time() - start)
            iterations.append(integrator.last_solve.iterations)
    finally:
        amg.AMGConjugateGradient._construct = BUILD
    matrix = integrator.linear_system(scene, state, 0.01)[0]
    ones, count, start = np.ones(matrix.shape[0]), 0, time.process_time()
    while time.process_time() - start < 0.5:
        matrix @ ones
        count += 1
    mv = (time.process_time() - start) / count
    hierarchy = integrator.cache.solver._hierarchy
    levels = [(level.A.shape[0], level.A.nnz) for level in hierarchy.levels[:3]]
    print(f"{variant:>16}: step {np.median(seconds[2:]) / mv:5.0f} mv, CG iterations {iterations[2:]}, operator "
          f"complexity {hierarchy.operator_complexity():.2f}, levels {levels}", flush=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--nodes", type=int, default=10000, help="target node count of the gmsh beam")
    parser.add_argument("--steps", type=int, default=12, help="steps per variant (the first two not counted)")
    parser.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=VARIANTS)
    args = parser.parse_args()
    size = (0.04 * 1.3 / args.nodes) ** (1 / 3)  # gmsh gives about 1.3 / size^3 nodes per m^3 of a box
    mesh = tetrahedralize(parse_shape("box:1,0.2,0.2"), size=size, method="gmsh", seed=0)
    model = Model.from_mesh(mesh, Material(1e7, 0.45, 1100.0))
    pins = Pins(np.flatnonzero(mesh.points[:, 0] < mesh.points[:, 0].min() + 1e-9))
    scene = Scene(model, forces=[Gravity()], pins=pins)
    print(f"gmsh beam: {mesh.node_count} nodes, implicit Euler at dt = 0.01 s, median of {args.steps - 2} steps")
    for variant in args.variants:
        measure(scene, variant, args.steps)


if __name__ == "__main__":
    main()
