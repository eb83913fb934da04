"""Cost of each rung of the model ladder: its implicit step against the springs' step, from one run.

A beam (1 m x 0.2 m x 0.2 m, pinned at x = 0, under gravity, E = 1e7 Pa, nu = 0.45 (``--nu``), dt = 0.01 s,
the README's scene) is built on every rung of :data:`volspring.ladder.MODELS` on the same mesh. Each
rung takes ``--steps`` implicit steps (AMG-preconditioned CG, ``ImplicitEuler()`` defaults) after
two warm-up steps (the hierarchy build); the script prints per rung the median wall time per step,
its ratio to the springs' step, the CG iterations per step, the 3x3 blocks assembled (the continuum
sets are applied as products and only their 1-ring stand-in is assembled, for the preconditioner),
and one product with the system as the step applies it, as a ratio to the springs' mat-vec. Rungs are timed
alternately, ``--rounds`` times, and the median of the rounds is reported, so a drift of the
machine's speed hits every rung alike.

Run (one thread, as every timing in this project)::

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python benchmarks/bench_ladder.py
    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python benchmarks/bench_ladder.py --cells 50 10 10 --steps 10
    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python benchmarks/bench_ladder.py --nu 0.499 --steps 30   # nearly incompressible
    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python benchmarks/bench_ladder.py --kernels numpy numba --steps 30

This is a script, not a test.
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np


def build(rung, cells, nu=0.45):
    from meshing import structured_box
    from volspring import Gravity, Material, Model, Pins, Scene

    mesh = structured_box(tuple(cells), (1.0, 0.2, 0.2))
    model = Model.from_mesh(mesh, Material(E=1e7, nu=nu, density=1000.0), model=rung)
    return Scene(model, forces=[Gravity()], pins=Pins(np.flatnonzero(mesh.points[:, 0] == 0)))


def time_steps(scene, steps, dt):
    from volspring.integrators.implicit import ImplicitEuler

    integrator = ImplicitEuler()
    cache = integrator.new_cache()
    state = scene.initial_state()
    for _ in range(2):
        state = integrator.step(scene, state, dt, cache=cache)
    times, iterations = [], []
    for _ in range(steps):
        start = time.perf_counter()
        state = integrator.step(scene, state, dt, cache=cache)
        times.append(time.perf_counter() - start)
        iterations.append(integrator.last_solve.iterations)
    return statistics.median(times), float(np.mean(iterations))


def matvec_seconds(scene, repeats=20):
    """One product with the implicit system as the step applies it: the assembled matrix plus the sets
    applied as products (matrix-free), and the 3x3 blocks assembled (the matrix AMG is built from)."""
    from volspring.assembly import BlockPattern

    pattern = BlockPattern(scene.model, scene.free, matrix_free=True)
    x = scene.model.rest_positions
    linearization = pattern.linearize(x, stiffness_scale=1e-4)
    matrix = pattern.matrix(linearization, scene.model.masses[pattern.free_nodes])
    operator = pattern.operator(linearization)
    vector = np.ones(matrix.shape[0])
    start = time.perf_counter()
    for _ in range(repeats):
        matrix @ vector if operator is None else matrix @ vector + operator @ vector
    return (time.perf_counter() - start) / repeats, pattern.block_count


def main():
    from volspring.ladder import MODELS

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, nargs=3, default=(40, 8, 8), help="beam cells (default 40 8 8: 3,321 nodes)")
    parser.add_argument("--steps", type=int, default=5)
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--dt", type=float, default=0.01)
    parser.add_argument("--nu", type=float, default=0.45, help="Poisson ratio (the springs ignore it)")
    parser.add_argument("--kernels", nargs="+", choices=["auto", "numba", "numpy"], default=["auto"],
                        help="what the hot loops run (volspring.kernels): one table each, timed alternately in the "
                             "same rounds; --kernels numpy numba compares them (the numba one needs the fast extra)")
    args = parser.parse_args()
    scenes = {rung: build(rung, args.cells, args.nu) for rung in MODELS}
    from volspring import kernels

    print(f"beam {tuple(args.cells)} cells, {scenes['springs'].model.node_count} nodes, nu = {args.nu}, "
          f"dt = {args.dt} s")
    step_times = {(choice, rung): [] for choice in args.kernels for rung in MODELS}
    iterations, matvec = {}, {}
    for _ in range(args.rounds):
        for choice in args.kernels:
            kernels.select(choice)
            for rung, scene in scenes.items():
                seconds, iterations[choice, rung] = time_steps(scene, args.steps, args.dt)
                step_times[choice, rung].append(seconds)
    for choice in args.kernels:
        kernels.select(choice)
        for rung, scene in scenes.items():
            matvec[choice, rung] = matvec_seconds(scene)
    for choice in args.kernels:
        kernels.select(choice)
        base = statistics.median(step_times[choice, "springs"])
        base_mv = matvec[choice, "springs"][0]
        print(f"kernels: {kernels.active()} ({choice})")
        print(f"{'rung':16s} {'ms/step':>9s} {'x springs':>10s} {'CG its':>7s} {'blocks':>9s} {'x springs':>10s} "
              f"{'mat-vec x':>10s}")
        for rung in MODELS:
            seconds = statistics.median(step_times[choice, rung])
            mv, blocks = matvec[choice, rung]
            print(f"{rung:16s} {1e3 * seconds:9.1f} {seconds / base:10.2f} {iterations[choice, rung]:7.1f} "
                  f"{blocks:9d} {blocks / matvec[choice, 'springs'][1]:10.2f} {mv / base_mv:10.2f}")
    if len(args.kernels) == 2:
        first, second = args.kernels
        print(f"step with {second} / with {first}: " + ", ".join(
            f"{rung} {statistics.median(step_times[second, rung]) / statistics.median(step_times[first, rung]):.2f}"
            for rung in MODELS))


if __name__ == "__main__":
    main()
