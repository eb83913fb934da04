"""Where an implicit step's time goes, down to the parts of one AMG V-cycle, in sparse mat-vecs of the same run.

The README beam (1 m x 0.2 m x 0.2 m, structured cells 5k x k x k, pinned at x = 0, gravity; E = 1e7 Pa,
nu = 0.45; springs) stepped with implicit Euler at the README's dt = 0.01 s. After a few steps the script prints
the median step split into forces, assembly, AMG set-up and the CG solve (with its iterations and the cost of one
iteration), then one application of the kept V-cycle and, per level, one pre- and one post-smoothing sweep, a
product with the level's matrix and with its restriction and prolongation, and the coarsest level's direct solve: every figure
as a multiple of one mat-vec with the step's own system matrix, timed in the same process (CPU time). It is the
measuring stick for issue 15's levers (smoothers, coarsening, near-null space, assembly).

Run (numpy/scipy threads are held to one before numpy is imported)::

    python benchmarks/bench_vcycle.py              # k = 12: about 10k nodes
    python benchmarks/bench_vcycle.py --cells 6 20
    python benchmarks/bench_vcycle.py --smoother block_gauss_seidel gauss_seidel   # both, one after the other

This is a script, not a test.
"""

import os

for _variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "VECLIB_MAXIMUM_THREADS"):
    os.environ[_variable] = "1"

import argparse  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402

from meshing import structured_box  # noqa: E402
from volspring import Gravity, Material, Model, Pins, Scene  # noqa: E402
from volspring.integrators.implicit import ImplicitEuler  # noqa: E402
from volspring.solvers.amg import SMOOTHERS, _Triangles  # noqa: E402

MATERIAL = Material(1e7, 0.45, 1000.0)
DT = 0.01  # [s], the README's step


def per_call(function, seconds=0.3):
    """CPU seconds of one call of ``function``, repeated for at least ``seconds``."""
    start, count = time.process_time(), 0
    while time.process_time() - start < seconds or count < 3:
        function()
        count += 1
    return (time.process_time() - start) / count


def measure(k: int, steps: int, smoother: str) -> None:
    mesh = structured_box((5 * k, k, k), (1.0, 0.2, 0.2))
    model = Model.from_mesh(mesh, MATERIAL)
    scene = Scene(model, forces=[Gravity()], pins=Pins(np.flatnonzero(mesh.points[:, 0] == 0)))
    integrator = ImplicitEuler(timer=time.process_time, smoother=smoother)
    state, rows = scene.initial_state(), []
    for _ in range(steps):
        start = time.process_time()
        state = integrator.step(scene, state, DT)
        info = integrator.last_solve
        rows.append((time.process_time() - start, info.forces_seconds, info.assembly_seconds, info.setup_seconds,
                     info.solve_seconds, info.iterations))
    matrix = integrator.linear_system(scene, state, DT)[0]
    ones = np.ones(matrix.shape[0])
    mv = per_call(lambda: matrix @ ones)
    step, forces, assembly, setup, solve, iterations = np.median(np.array(rows[3:]), axis=0)
    print(f"\n{model.node_count} nodes (cells {5 * k} x {k} x {k}), smoother {smoother}, one mat-vec "
          f"{1e3 * mv:.3f} ms; median of {steps - 3} steps after 3 (the first step's AMG set-up {rows[0][3] / mv:.0f} mv):")
    print(f"  step {step / mv:.0f} mv = forces {forces / mv:.1f} + assembly {assembly / mv:.1f} + AMG set-up "
          f"{setup / mv:.1f} + solve {solve / mv:.1f} + the rest {(step - forces - assembly - setup - solve) / mv:.1f}")
    print(f"  solve: {iterations:.0f} CG iterations, {solve / iterations / mv:.1f} mv each")
    hierarchy, cycle = integrator.cache.solver._hierarchy, integrator.cache.solver._cycle
    generator = np.random.default_rng(0)
    residual = generator.standard_normal(matrix.shape[0])
    print(f"  one V-cycle {per_call(lambda: cycle(residual)) / mv:.1f} mv; levels (unknowns, nonzeros, block):")
    for index, level in enumerate(hierarchy.levels[:-1]):
        # The guess in the level's own type, as the cycle's z (the finest level sweeps in single precision).
        vector, guess = generator.standard_normal(level.A.shape[0]), np.zeros(level.A.shape[0], dtype=level.A.dtype)
        # R and P take vectors of their own type, as in the cycle (a single-precision P or R given a double vector
        # would be copied to double first).
        residual, coarse = vector.astype(level.R.dtype), np.ones(level.P.shape[1], dtype=level.P.dtype)
        head = f"    {index}: {level.A.shape[0]:>7} {level.A.nnz:>9} {str(getattr(level.A, 'blocksize', None) or (1, 1)):>7}:"
        if isinstance(level.A, _Triangles):  # what the cycle runs: a sweep from zero and -U z, then a full sweep
            smoothing = (f" sweep from zero + residual {per_call(lambda: level.A.forward_from_zero(vector)) / mv:.2f} mv,"
                         f" post-smoothing {per_call(lambda: level.postsmoother(level.A, guess, vector)) / mv:.2f}")
        else:
            smoothing = (f" pre-smoothing {per_call(lambda: level.presmoother(level.A, guess, vector)) / mv:.2f} mv,"
                         f" post-smoothing {per_call(lambda: level.postsmoother(level.A, guess, vector)) / mv:.2f},"
                         f" A x {per_call(lambda: level.A @ vector) / mv:.2f}")
        print(head + smoothing + f", R x {per_call(lambda: level.R @ residual) / mv:.2f}, "
              f"P x {per_call(lambda: level.P @ coarse) / mv:.2f}")
    last = hierarchy.levels[-1]
    vector = generator.standard_normal(last.A.shape[0])
    print(f"    coarsest: {last.A.shape[0]:>7} {last.A.nnz:>9}: direct solve "
          f"{per_call(lambda: hierarchy.coarse_solver(last.A, vector)) / mv:.2f} mv")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, nargs="+", default=[12], help="k of the 5k x k x k cells")
    parser.add_argument("--steps", type=int, default=13, help="steps per size (the first 3 are not counted)")
    parser.add_argument("--smoother", nargs="+", choices=SMOOTHERS, default=[SMOOTHERS[0]],
                        help="the AMG smoothers to measure, one after the other at each size (default: %(default)s)")
    args = parser.parse_args()
    for k in args.cells:
        for smoother in args.smoother:
            measure(k, args.steps, smoother)


if __name__ == "__main__":
    main()
