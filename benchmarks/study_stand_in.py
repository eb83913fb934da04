"""The preconditioner's correction for a stand-in matrix: CG iterations against its weight omega.

Where element sets are applied as products (the volume and smoothed rungs), the AMG hierarchy is built from a 1-ring
stand-in for their stiffness, and the preconditioner adds omega [D^-1 - D_s^-1]_+ to its V-cycle, D and D_s the 3 x 3
diagonal blocks of the operator CG iterates on and of the stand-in
(:func:`volspring.solvers.amg.stand_in_correction`). This script steps the README beam (1 m x 0.2 m x 0.2 m,
structured cells 40 x 8 x 8, 3,321 nodes, pinned at x = 0, gravity, E = 1e7 Pa) from rest with implicit Euler, once
per rung, Poisson ratio and omega (:data:`volspring.solvers.amg.STAND_IN_CORRECTION`, set for each run and put
back), and prints the mean CG iterations a step over steps 3 to ``--steps``, and each ratio to omega = 0 (no
correction). Iteration counts only: they need no quiet machine (about 3 minutes with the ``fast`` extra).

Stop 42's run (``python benchmarks/study_stand_in.py``), mean CG iterations a step over steps 3-22 at dt = 0.01 s, and
the ratio to no correction:

================  =====  ============  ============  ============  ============  ============
rung              nu     omega 0       0.15          0.3           0.5           1
================  =====  ============  ============  ============  ============  ============
smoothed          0.3    3.95          3.50 (0.89)   3.50 (0.89)   3.55 (0.90)   3.80 (0.96)
smoothed          0.45   6.45          5.55 (0.86)   5.45 (0.84)   5.45 (0.84)   5.85 (0.91)
smoothed          0.49   12.25         11.20 (0.91)  10.55 (0.86)  10.30 (0.84)  10.40 (0.85)
smoothed          0.499  27.95         28.00 (1.00)  28.00 (1.00)  27.65 (0.99)  27.60 (0.99)
springs+volume    0.3    3.55          3.50 (0.99)   3.50 (0.99)   3.60 (1.01)   3.70 (1.04)
springs+volume    0.45   6.25          6.05 (0.97)   6.00 (0.96)   6.05 (0.97)   6.30 (1.01)
springs+volume    0.49   11.90         11.75 (0.99)  11.60 (0.97)  11.50 (0.97)  11.25 (0.95)
springs+volume    0.499  26.90         26.90 (1.00)  26.90 (1.00)  26.90 (1.00)  26.90 (1.00)
================  =====  ============  ============  ============  ============  ============

omega = 0.3 (the default) is within 0.02 of the best ratio in every row, and nowhere worse than no correction by more
than rounding (nu 0.499, where the counts move by a few tenths with the last bits of the system). At dt =
0.001 and 0.1 s (``--nu 0.3 0.45 --weights 0 0.3 --dt 0.001``) it gives 0.84 / 0.82 and 0.90 / 0.80 on the smoothed
rung at nu 0.3 / 0.45, 0.98 / 0.94 and 0.99 / 0.97 on the volume rung. The springs' hierarchy is built from their own matrix, so they have no correction (with the same
term made from their exact diagonal, 2.95 iterations became 3.10 at omega 0.15: scratch ``addj42.py``).

``--build-cost`` prints instead what the correction costs on the smoothed rung's first step (CPU time, medians of
five): one AMG build without it, the operator's diagonal blocks, the correction's blocks (their eigen-decompositions),
one application of the correction and one V-cycle. Stop 42, with the ``fast`` extra: 48 ms, 29-37 ms, 15 ms, 0.10-0.11
ms and 2.0 ms.

Run::

    python benchmarks/study_stand_in.py
    python benchmarks/study_stand_in.py --nu 0.45 --weights 0 0.3 --dt 0.001
    python benchmarks/study_stand_in.py --build-cost
"""

import os

for _variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "VECLIB_MAXIMUM_THREADS"):
    os.environ[_variable] = "1"

import argparse  # noqa: E402
import sys  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_ladder import build  # noqa: E402

from volspring.integrators.implicit import ImplicitEuler  # noqa: E402
from volspring.solvers import amg  # noqa: E402


def iterations(rung: str, nu: float, weight: float, *, cells, dt: float, steps: int) -> list[int]:
    """CG iterations of each step from rest, with the correction's weight set to ``weight`` for the run."""
    scene = build(rung, cells, nu=nu)
    saved = amg.STAND_IN_CORRECTION
    amg.STAND_IN_CORRECTION = weight
    try:
        integrator = ImplicitEuler()
        state = scene.initial_state()
        counts = []
        for _ in range(steps):
            state = integrator.step(scene, state, dt)
            counts.append(integrator.last_solve.iterations)
    finally:
        amg.STAND_IN_CORRECTION = saved
    return counts


def build_cost(cells, dt: float) -> None:
    """CPU times of the correction's parts on the smoothed rung's first-step system (see the module docstring)."""
    import time

    from meshing.geometry import rigid_body_modes

    scene = build("smoothed", cells)
    integrator = ImplicitEuler()
    cache = integrator.new_cache()
    state = scene.initial_state()
    pattern = cache.pattern_for(scene)
    system = integrator._assemble(scene, pattern, state.x, state.v, state.t, dt)
    whole, modes = system.whole, rigid_body_modes(state.x[pattern.free_nodes])

    def median_ms(function, repeats=5):
        function()
        times = []
        for _ in range(repeats):
            start = time.process_time()
            function()
            times.append(time.process_time() - start)
        return 1e3 * float(np.median(times))

    def exact_diagonal():
        system.__dict__.pop("exact_diagonal", None)  # a cached property: made again each time
        return system.exact_diagonal

    solver = cache.solver
    print(f"smoothed rung, beam {tuple(cells)} cells, dt = {dt:g} s (CPU time, medians of five)")
    print(f"  AMG build without the correction    {median_ms(lambda: solver.build(whole, modes)):8.2f} ms")
    print(f"  the operator's diagonal blocks      {median_ms(exact_diagonal):8.2f} ms")
    diagonal = exact_diagonal()
    print(f"  the correction's blocks             {median_ms(lambda: amg.stand_in_correction(whole, diagonal)):8.2f} ms")
    correction = amg.stand_in_correction(whole, diagonal)
    r = np.random.default_rng(0).standard_normal(whole.shape[0])
    print(f"  one application of the correction   {median_ms(lambda: correction @ r, 201):8.3f} ms")
    print(f"  one V-cycle                         {median_ms(lambda: solver.precondition(r), 51):8.3f} ms")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rungs", nargs="+", default=["smoothed", "springs+volume"])
    parser.add_argument("--nu", type=float, nargs="+", default=[0.3, 0.45, 0.49, 0.499])
    parser.add_argument("--weights", type=float, nargs="+", default=[0.0, 0.15, 0.3, 0.5, 1.0])
    parser.add_argument("--cells", type=int, nargs=3, default=[40, 8, 8])
    parser.add_argument("--dt", type=float, default=0.01)
    parser.add_argument("--steps", type=int, default=22, help="steps from rest; the mean is over steps 3 to this")
    parser.add_argument("--build-cost", action="store_true", help="time the correction's parts instead")
    args = parser.parse_args(argv)
    if args.build_cost:
        build_cost(args.cells, args.dt)
        return
    if args.steps < 3:
        parser.error(f"--steps {args.steps}: expected at least 3 (the mean is over steps 3 to --steps)")
    print(f"beam {tuple(args.cells)} cells, dt = {args.dt:g} s; mean CG iterations a step over steps 3-{args.steps} "
          f"(ratio to omega = {args.weights[0]:g}); default omega {amg.STAND_IN_CORRECTION:g}")
    print(f"{'rung':16s} {'nu':>6s}  " + "  ".join(f"{'omega ' + format(w, 'g'):>16s}" for w in args.weights))
    for rung in args.rungs:
        for nu in args.nu:
            means = [float(np.mean(iterations(rung, nu, weight, cells=args.cells, dt=args.dt,
                                               steps=args.steps)[2:])) for weight in args.weights]
            print(f"{rung:16s} {nu:6g}  " + "  ".join(f"{mean:9.2f} ({mean / means[0]:.2f})" for mean in means),
                  flush=True)


if __name__ == "__main__":
    main()
