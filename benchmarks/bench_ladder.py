"""Cost of each rung of the model ladder: its implicit step against the springs' step, from one run.

A beam (1 m x 0.2 m x 0.2 m, pinned at x = 0, under gravity, E = 1e7 Pa, nu = 0.45 (``--nu``), dt = 0.01 s,
the README's scene) is built on every rung of :data:`volspring.ladder.MODELS` on the same mesh. Each
rung takes ``--steps`` implicit steps (AMG-preconditioned CG, ``ImplicitEuler()`` defaults) after
two warm-up steps (the hierarchy build); the script prints per rung the median wall time per step,
its ratio to the springs' step, the CG iterations per step, the 3x3 blocks assembled (the continuum
sets are applied as products and only their 1-ring stand-in is assembled, for the preconditioner),
and one product with the system as the step applies it, as a ratio to the springs' mat-vec. The rungs (and the
``--kernels`` choices) run side by side and are timed step by step in turn: one step of each, then the next step of
each in the reverse order, so that a drift of the machine's speed hits every rung alike (this 2-core machine's moves
by a third within minutes: at stop 41, a springs run of 30 steps then a smoothed one, in six processes, gave ratios
from 3.25x to 6.51x; timed side by side, a run's five rounds lay within 3.67-4.71x that busy morning, and within
3.90-4.04x on a quiet machine). ``--rounds`` repeats the runs from rest; the medians of the rounds are reported, the
ratio as the median of each round's ratio.

Run (one thread, as every timing in this project)::

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python benchmarks/bench_ladder.py
    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python benchmarks/bench_ladder.py --cells 50 10 10 --steps 10
    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python benchmarks/bench_ladder.py --nu 0.499 --steps 30   # nearly incompressible
    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python benchmarks/bench_ladder.py --kernels numpy numba --steps 30
    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python benchmarks/bench_ladder.py --levers --steps 20 --rounds 5

``--levers`` also times, for the rungs applied as products, CG's first guess applied to the last velocity changes
at once (each sparse factor read once, as the step does) against one change after another (each product then reads
them again), in the same rounds: the guess's products with the sets applied as products, in mat-vecs of the springs'
system (as the table's last column), and the whole step.

This is a script, not a test.
"""

from __future__ import annotations

import argparse
import contextlib
import statistics
import time

import numpy as np


def build(rung, cells, nu=0.45):
    from meshing import structured_box
    from volspring import Gravity, Material, Model, Pins, Scene

    mesh = structured_box(tuple(cells), (1.0, 0.2, 0.2))
    model = Model.from_mesh(mesh, Material(E=1e7, nu=nu, density=1000.0), model=rung)
    return Scene(model, forces=[Gravity()], pins=Pins(np.flatnonzero(mesh.points[:, 0] == 0)))


def time_side_by_side(scenes, steps, dt, choices=(None,)):
    """Runs of every scene (and kernel choice; None: the one selected) from rest, their steps timed in turn: after two
    warm-up steps each (the hierarchy build), step k of every run, in one order for even k and the reverse for odd k.
    Returns {(choice, name): (median seconds per step, mean CG iterations per step)}."""
    from volspring import kernels
    from volspring.integrators.implicit import ImplicitEuler

    runs = {}
    for choice in choices:
        if choice is not None:
            kernels.select(choice)
        for name, scene in scenes.items():
            integrator = ImplicitEuler()
            cache = integrator.new_cache()
            state = scene.initial_state()
            for _ in range(2):
                state = integrator.step(scene, state, dt, cache=cache)
            runs[choice, name] = [scene, integrator, cache, state, [], []]
    keys = list(runs)
    for k in range(steps):
        for key in keys if k % 2 == 0 else keys[::-1]:
            scene, integrator, cache, state, times, iterations = run = runs[key]
            if key[0] is not None:
                kernels.select(key[0])
            start = time.perf_counter()
            run[3] = integrator.step(scene, state, dt, cache=cache)
            times.append(time.perf_counter() - start)
            iterations.append(integrator.last_solve.iterations)
    return {key: (statistics.median(run[4]), float(np.mean(run[5]))) for key, run in runs.items()}


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


#: How CG's first guess makes its products in ``--levers``: as the step does, and as it did before.
WAYS = ("at once", "one by one")


@contextlib.contextmanager
def guess(way):
    """CG's first guess made as the step makes it (``"at once"``: the sets' products with all past changes in one
    pass) or ``"one by one"`` (:meth:`OperatorLinearization.scaled_times_each`, what the step did before)."""
    from volspring.elements.base import OperatorLinearization

    original = OperatorLinearization.scaled_times_many
    if way == "one by one":
        OperatorLinearization.scaled_times_many = OperatorLinearization.scaled_times_each
    try:
        yield
    finally:
        OperatorLinearization.scaled_times_many = original


def guess_products(scene, count, repeats=10):
    """Seconds of ``count`` products with the sets applied as products, as CG's first guess makes them: at once, and
    one by one."""
    from volspring.assembly import BlockPattern

    pattern = BlockPattern(scene.model, scene.free, matrix_free=True)
    operator = pattern.operator(pattern.linearize(scene.model.rest_positions, stiffness_scale=1e-4))
    vectors = np.random.default_rng(0).standard_normal((pattern.size, count))
    seconds = {}
    for way in WAYS:
        with guess(way):
            start = time.perf_counter()
            for _ in range(repeats):
                operator @ vectors
            seconds[way] = (time.perf_counter() - start) / repeats
    return seconds


def levers(scenes, args):
    """The step with the guess's products at once and one by one, alternating in the same rounds (``--levers``)."""
    from volspring.integrators.implicit import WARM_START

    rungs = [rung for rung in scenes if rung != "springs"]
    times = {(rung, way): [] for rung in rungs for way in WAYS}
    for _ in range(args.rounds):
        for rung in rungs:
            for way in WAYS:
                with guess(way):
                    seconds, _ = time_side_by_side({rung: scenes[rung]}, args.steps, args.dt)[None, rung]
                    times[rung, way].append(seconds)
    print(f"\nlever: CG's first guess applies the system to the last {WARM_START} velocity changes at once")
    print(f"{'rung':16s} {'products at once':>17s} {'one by one':>11s} {'ms/step at once':>16s} {'one by one':>11s} "
          f"{'ratio':>6s}   (products: in the springs' mat-vecs)")
    mv = matvec_seconds(scenes["springs"])[0]
    for rung in rungs:
        products = guess_products(scenes[rung], WARM_START)
        at_once, separate = (statistics.median(times[rung, way]) for way in WAYS)
        print(f"{rung:16s} {products['at once'] / mv:17.1f} {products['one by one'] / mv:11.1f} "
              f"{1e3 * at_once:16.1f} {1e3 * separate:11.1f} {at_once / separate:6.2f}")


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
    parser.add_argument("--levers", action="store_true",
                        help="also time CG's first guess applied at once against one product after another")
    args = parser.parse_args()
    scenes = {rung: build(rung, args.cells, args.nu) for rung in MODELS}
    from volspring import kernels

    print(f"beam {tuple(args.cells)} cells, {scenes['springs'].model.node_count} nodes, nu = {args.nu}, "
          f"dt = {args.dt} s")
    step_times = {(choice, rung): [] for choice in args.kernels for rung in MODELS}
    iterations, matvec = {}, {}
    for _ in range(args.rounds):
        for key, (seconds, iterations[key]) in time_side_by_side(scenes, args.steps, args.dt, args.kernels).items():
            step_times[key].append(seconds)
    for choice in args.kernels:
        kernels.select(choice)
        for rung, scene in scenes.items():
            matvec[choice, rung] = matvec_seconds(scene)
    for choice in args.kernels:
        kernels.select(choice)
        springs = step_times[choice, "springs"]
        base_mv = matvec[choice, "springs"][0]
        print(f"kernels: {kernels.active()} ({choice})")
        print(f"{'rung':16s} {'ms/step':>9s} {'x springs':>10s} {'CG its':>7s} {'blocks':>9s} {'x springs':>10s} "
              f"{'mat-vec x':>10s}   x springs in each round")
        for rung in MODELS:
            seconds = statistics.median(step_times[choice, rung])
            ratios = [mine / base for mine, base in zip(step_times[choice, rung], springs)]
            mv, blocks = matvec[choice, rung]
            print(f"{rung:16s} {1e3 * seconds:9.1f} {statistics.median(ratios):10.2f} {iterations[choice, rung]:7.1f} "
                  f"{blocks:9d} {blocks / matvec[choice, 'springs'][1]:10.2f} {mv / base_mv:10.2f}   "
                  + " ".join(f"{ratio:.2f}" for ratio in ratios))
    if len(args.kernels) == 2:
        first, second = args.kernels
        print(f"step with {second} / with {first}: " + ", ".join(
            f"{rung} {statistics.median(step_times[second, rung]) / statistics.median(step_times[first, rung]):.2f}"
            for rung in MODELS))
    if args.levers:
        levers(scenes, args)


if __name__ == "__main__":
    main()
