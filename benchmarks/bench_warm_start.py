"""CG's first guess in the implicit step: how many previous velocity changes it is made from, against CG iterations
and the step's cost in sparse mat-vecs.

The README beam (1 m x 0.2 m x 0.2 m, structured cells 5k x k x k, pinned at x = 0, gravity; E = 1e7 Pa,
nu = 0.45; springs) stepped with implicit Euler from rest, once per ``warm_start`` depth (0: CG from zero; 1: the
last change, optimally scaled; m: the combination of the last m changes closest to the step's solution in the
system's energy norm, :func:`volspring.integrators.implicit._projected_guess`). For each depth the script prints
the mean CG iterations and the median step (AMG set-up left out) over the steps after the first ``--settle``, as a
multiple of one mat-vec with the step's matrix (CPU time, same process), and every step's iterations.

Run (numpy/scipy threads are held to one before numpy is imported)::

    python benchmarks/bench_warm_start.py                       # k = 12: about 10k nodes, depths 0 1 2 3 5 8
    python benchmarks/bench_warm_start.py --cells 6 20 --depth 3 5

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

MATERIAL = Material(1e7, 0.45, 1000.0)


def matvec_seconds(matrix, seconds=0.5):
    """CPU seconds of one product with ``matrix``, repeated for at least ``seconds``."""
    vector, start, count = np.ones(matrix.shape[0]), time.process_time(), 0
    while time.process_time() - start < seconds:
        matrix @ vector
        count += 1
    return (time.process_time() - start) / count


def measure(k: int, depths, steps: int, settle: int, dt: float) -> None:
    mesh = structured_box((5 * k, k, k), (1.0, 0.2, 0.2))
    model = Model.from_mesh(mesh, MATERIAL)
    scene = Scene(model, forces=[Gravity()], pins=Pins(np.flatnonzero(mesh.points[:, 0] == 0)))
    mv = matvec_seconds(ImplicitEuler().linear_system(scene, scene.initial_state(), dt)[0])
    print(f"\n{model.node_count} nodes (cells {5 * k} x {k} x {k}), dt = {dt:g} s, one mat-vec {1e3 * mv:.3f} ms; "
          f"steps {settle + 1} to {steps}:")
    for depth in depths:
        integrator = ImplicitEuler(warm_start=depth, timer=time.process_time)
        state, seconds, iterations = scene.initial_state(), [], []
        for _ in range(steps):
            start = time.process_time()
            state = integrator.step(scene, state, dt)
            seconds.append(time.process_time() - start - integrator.last_solve.setup_seconds)
            iterations.append(integrator.last_solve.iterations)
        print(f"  warm_start {depth}: {np.mean(iterations[settle:]):4.2f} CG iterations, step "
              f"{np.median(seconds[settle:]) / mv:5.1f} mv; iterations per step {iterations}", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, nargs="+", default=[12], help="k of the 5k x k x k cells")
    parser.add_argument("--depth", type=int, nargs="+", default=[0, 1, 2, 3, 5, 8],
                        help="warm_start depths to compare (default: %(default)s)")
    parser.add_argument("--steps", type=int, default=40, help="steps per run")
    parser.add_argument("--settle", type=int, default=10, help="first steps left out of the figures")
    parser.add_argument("--dt", type=float, default=0.01, help="time step [s] (the README's)")
    args = parser.parse_args()
    for k in args.cells:
        measure(k, args.depth, args.steps, args.settle, args.dt)


if __name__ == "__main__":
    main()
