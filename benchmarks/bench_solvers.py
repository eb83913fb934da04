"""The AMG-CG solve through volspring's V-cycle adapter against pyamg's public preconditioner.

``volspring.solvers.amg._v_cycle`` runs pyamg's V-cycle on the hierarchy's levels itself (on levels held as
triangles it sweeps from zero over the lower one and takes the residual from the upper one); pyamg's public
``ml.aspreconditioner(cycle="V")`` runs its cycle inside ``ml.solve(maxiter=1)``, which also takes two residual
norms, i.e. two extra products with the fine matrix, per application. On a gmsh beam (the cantilever of
``bench_implicit.py``, h omega_max = 50) this builds one hierarchy and, for the system's own right-hand side (gravity) and a random one,
solves at rtol 1e-3 and 1e-6 both ways, interleaved, and prints the CG iterations, the median CPU
time of a solve and of one preconditioner application, each also in mat-vecs, and the ratio public
/ adapter, and how far apart the two answers are (rounding: pyamg's cycle takes its residuals from the whole
matrix, the adapter from the triangles).

Run (numpy/scipy threads are held to one before numpy is imported)::

    python benchmarks/bench_solvers.py                 # 10k nodes
    python benchmarks/bench_solvers.py --nodes 1000 10000 50000 --repeats 21

This is a script, not a test: the timings depend on the machine and its load (printed).
"""

import os

for _variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "VECLIB_MAXIMUM_THREADS"):
    os.environ[_variable] = "1"

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
import pyamg  # noqa: E402

from bench_implicit import MATERIAL, beam_mesh, omega_max  # noqa: E402
from meshing.geometry import rigid_body_modes  # noqa: E402
from volspring import Gravity, Model, Pins, Scene  # noqa: E402
from volspring.integrators.implicit import ImplicitEuler  # noqa: E402
from volspring.solvers import AMGConjugateGradient, conjugate_gradient  # noqa: E402

CLOCK = time.process_time  # CPU time of this process: other jobs on a shared machine do not count


def median_seconds(function, repeats):
    times = []
    for _ in range(repeats):
        start = CLOCK()
        function()
        times.append(CLOCK() - start)
    return float(np.median(times))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--nodes", type=int, nargs="+", default=[10000])
    parser.add_argument("--h-omega", type=float, default=50.0, help="h * omega_max of the step")
    parser.add_argument("--repeats", type=int, default=11, help="timed solves per case and variant")
    args = parser.parse_args(argv)
    print(f"pyamg {pyamg.__version__}; load average before: {os.getloadavg()} (cores: {os.cpu_count()})")
    for target in args.nodes:
        mesh = beam_mesh(target)
        model = Model.from_mesh(mesh, MATERIAL)
        scene = Scene(model, forces=[Gravity()],
                      pins=Pins(np.flatnonzero(model.rest_positions[:, 0] < 1e-9)))
        dt = args.h_omega / omega_max(model, scene)
        state = scene.initial_state()
        matrix, _, pattern = ImplicitEuler().linear_system(scene, state, dt)
        solver = AMGConjugateGradient(timer=CLOCK)
        setup = solver.build(matrix, rigid_body_modes(model.rest_positions[pattern.free_nodes]))
        public = solver.hierarchy.aspreconditioner(cycle="V").matvec
        gravity = pattern.restrict(dt * scene.forces_at(state.x, state.v, state.t))
        rhs = {"gravity": gravity, "random": np.random.default_rng(1).standard_normal(matrix.shape[0])}
        vector = rhs["random"]
        matvec = median_seconds(lambda: matrix @ vector, 5 * args.repeats)
        cycles = {"adapter": median_seconds(lambda: solver.precondition(vector), args.repeats),
                  "public": median_seconds(lambda: public(vector), args.repeats)}
        print(f"\nbeam: {model.node_count} nodes, {matrix.shape[0]} unknowns, dt = {dt:.3g} s; "
              f"AMG setup {setup:.3f} s, {len(solver.hierarchy.levels)} levels; mat-vec {matvec * 1e3:.3f} ms")
        print(f"  one V-cycle: adapter {cycles['adapter'] * 1e3:.2f} ms = {cycles['adapter'] / matvec:.1f} mv, "
              f"public {cycles['public'] * 1e3:.2f} ms = {cycles['public'] / matvec:.1f} mv, "
              f"public / adapter {cycles['public'] / cycles['adapter']:.3f}")
        for name, b in rhs.items():
            for rtol in (1e-3, 1e-6):
                solver.rtol = rtol
                answers, iterations, times = {}, {}, {"adapter": [], "public": []}
                for _ in range(args.repeats):  # interleaved, so a change of load hits both alike
                    start = CLOCK()
                    answers["adapter"], info = solver.solve(matrix, b)
                    times["adapter"].append(CLOCK() - start)
                    iterations["adapter"] = info.iterations
                    start = CLOCK()
                    answers["public"], iterations["public"], _, _ = conjugate_gradient(
                        matrix.__matmul__, b, preconditioner=public, rtol=rtol, maxiter=solver.maxiter)
                    times["public"].append(CLOCK() - start)
                seconds = {key: float(np.median(value)) for key, value in times.items()}
                apart = np.linalg.norm(answers["adapter"] - answers["public"]) / np.linalg.norm(answers["public"])
                print(f"  {name:7s} rhs, rtol {rtol:g}: iterations adapter {iterations['adapter']}, public "
                      f"{iterations['public']}; solve adapter {seconds['adapter'] * 1e3:.1f} ms "
                      f"({seconds['adapter'] / matvec:.0f} mv), public {seconds['public'] * 1e3:.1f} ms "
                      f"({seconds['public'] / matvec:.0f} mv), public / adapter "
                      f"{seconds['public'] / seconds['adapter']:.3f}; answers apart {apart:.1e} (relative)", flush=True)
    print(f"load average after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
