"""One AMG build in sparse mat-vecs: pyamg's smoothed-aggregation builder against the set-up done here, one run.

The README beam (1 m x 0.2 m x 0.2 m, structured cells 5k x k x k, pinned at x = 0, gravity; E = 1e7 Pa, nu = 0.45;
springs), the system of its first implicit step at the README's dt = 0.01 s. Per size, alternating ``--rounds``
times in this process (CPU time, one thread):

- ``pyamg``: ``pyamg.smoothed_aggregation_solver`` with the options the solver used before (six rigid-body modes,
  symmetric strength 0.05, Jacobi prolongation smoothing with local weights, sparse LU on the coarsest level);
- ``ours``: :func:`volspring.solvers.amg._smoothed_aggregation`, the same hierarchy to rounding;
- ``build()``: the whole :meth:`AMGConjugateGradient.build` (the set-up, the levels' triangles, the coarse LU),
  what a step that rebuilds pays;
- ``coarse LU``: the factorisation of the coarsest level by pyamg's ``coarse_grid_solver("splu")`` (what the solver
  used before) against the solver's own (``amg._CoarseLU``: its empty rows left out by index, in the level's own
  column order where that pays), and one solve with each factorisation (both picking b's rows by index);

each as the median over the rounds in mat-vecs with the same matrix, and the share of ``ours`` spent in scipy's
block sparse products (the prolongation smoothing's A T and the Galerkin products R A P; none when the compiled
kernels of :mod:`volspring.kernels` make them, ``--kernels``).

Run (numpy/scipy threads are held to one before numpy is imported)::

    python benchmarks/bench_amg_build.py                 # k = 5, 12, 20: about 1k, 10k and 45k nodes
    python benchmarks/bench_amg_build.py --cells 34 --rounds 2
    python benchmarks/bench_amg_build.py --kernels numpy numba   # scipy's block products against the compiled ones

This is a script, not a test.
"""

import os

for _variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "VECLIB_MAXIMUM_THREADS"):
    os.environ[_variable] = "1"

import argparse  # noqa: E402
import statistics  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
import pyamg  # noqa: E402
import scipy.sparse as sp  # noqa: E402
import scipy.sparse._bsr as scipy_bsr  # noqa: E402

from bench_warm_start import MATERIAL, matvec_seconds  # noqa: E402
from meshing import structured_box  # noqa: E402
from meshing.geometry import rigid_body_modes  # noqa: E402
from volspring import Gravity, Model, Pins, Scene  # noqa: E402
from volspring.integrators.implicit import ImplicitEuler  # noqa: E402
from volspring.solvers import PROLONGATION_OMEGA, AMGConjugateGradient  # noqa: E402
from volspring.solvers.amg import _CoarseLU, _coarse_solve, _smoothed_aggregation  # noqa: E402


def pyamg_builder(matrix, modes):
    gauss_seidel = ("block_gauss_seidel", {"sweep": "forward"}), ("block_gauss_seidel", {"sweep": "backward"})
    return pyamg.smoothed_aggregation_solver(
        matrix, B=modes, symmetry="hermitian", strength=("symmetric", {"theta": 0.05}),
        smooth=("jacobi", {"omega": PROLONGATION_OMEGA, "weighting": "local"}), improve_candidates=None,
        presmoother=gauss_seidel[0], postsmoother=gauss_seidel[1], max_coarse=300, coarse_solver="splu")


def ours(matrix, modes):
    return _smoothed_aggregation(matrix, modes, theta=0.05, excluded=None, max_coarse=300)


def whole_build(matrix, modes):
    AMGConjugateGradient(timer=time.process_time).build(matrix, modes)


def by_index(solver):
    """b -> pyamg's sparse LU solution with its kept rows picked and put back by index (how the solver applied
    pyamg's factors before it made its own), not by pyamg's two products with its selection matrix."""
    kept = sp.csc_matrix(solver.LU_Map).indices

    def apply(b):
        x = np.zeros(len(b))
        x[kept] = solver.LU.solve(b[kept])
        return x

    return apply


def coarse_lu_seconds(coarsest, rounds):
    """Median CPU seconds of the coarsest level's factorisation and of one solve with it: pyamg's sparse LU and
    ours, alternating."""
    from types import SimpleNamespace

    from pyamg.multilevel import coarse_grid_solver

    vector = np.random.default_rng(0).standard_normal(coarsest.shape[0])
    ways = {"pyamg": lambda: coarse_grid_solver("splu"), "ours": lambda: _CoarseLU(coarsest)}
    factor, solve = {way: [] for way in ways}, {way: [] for way in ways}
    for _ in range(rounds):
        for way, make in ways.items():
            start = time.process_time()
            solver = make()
            solver(coarsest, vector)  # pyamg's factorises at its first call
            factor[way].append(time.process_time() - start)
            apply = by_index(solver) if way == "pyamg" else \
                _coarse_solve(SimpleNamespace(coarse_solver=solver, levels=[SimpleNamespace(A=coarsest)]))
            start = time.process_time()
            for _ in range(20):
                apply(vector)
            solve[way].append((time.process_time() - start) / 20)
    return {way: (statistics.median(factor[way]), statistics.median(solve[way])) for way in ways}


class ProductClock:
    """CPU seconds spent in scipy's block sparse product while installed."""

    def __init__(self):
        self.seconds, self._product = 0.0, scipy_bsr.bsr_matmat

    def __enter__(self):
        def timed(*args):
            start = time.process_time()
            try:
                return self._product(*args)
            finally:
                self.seconds += time.process_time() - start

        scipy_bsr.bsr_matmat = timed
        return self

    def __exit__(self, *exc):
        scipy_bsr.bsr_matmat = self._product


def main():
    from volspring import kernels

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, nargs="+", default=[5, 12, 20], help="k of the 5k x k x k cells")
    parser.add_argument("--rounds", type=int, default=4, help="alternating builds per variant")
    parser.add_argument("--kernels", nargs="+", choices=["auto", "numba", "numpy"], default=["auto"],
                        help="what ours runs (volspring.kernels), one row each, timed in the same rounds: "
                             "--kernels numpy numba compares scipy's block products with the compiled ones")
    args = parser.parse_args()
    print(f"{'nodes':>8} {'kernels':>8} {'pyamg':>10} {'ours':>10} {'ratio':>6} {'build()':>10} "
          f"{'scipy products in ours':>23}   coarse LU, pyamg's / ours: factorisation, one solve")
    for k in args.cells:
        mesh = structured_box((5 * k, k, k), (1.0, 0.2, 0.2))
        model = Model.from_mesh(mesh, MATERIAL)
        scene = Scene(model, forces=[Gravity()], pins=Pins(np.flatnonzero(mesh.points[:, 0] == 0)))
        matrix, _, pattern = ImplicitEuler().linear_system(scene, scene.initial_state(), 0.01)
        modes = rigid_body_modes(model.rest_positions[pattern.free_nodes])
        mv = matvec_seconds(matrix)
        variants = [("pyamg", pyamg_builder, None)] + [(f"{name} {choice}", build, choice) for choice in args.kernels
                                                       for name, build in (("ours", ours), ("build", whole_build))]
        seconds = {name: [] for name, _, _ in variants}
        products = {choice: [] for choice in args.kernels}
        for _ in range(args.rounds):
            for name, build, choice in variants:
                if choice is not None:
                    kernels.select(choice)
                given = matrix.copy()  # pyamg caches on the matrix it is given
                with ProductClock() as clock:
                    start = time.process_time()
                    build(given, modes)
                    seconds[name].append(time.process_time() - start)
                if name.startswith("ours"):
                    products[choice].append(clock.seconds / seconds[name][-1])
        pyamg_mv = statistics.median(seconds["pyamg"]) / mv
        solver = AMGConjugateGradient()
        solver.build(matrix, modes)
        coarse = coarse_lu_seconds(solver.hierarchy.levels[-1].A, max(args.rounds, 5))
        (theirs, their_solve), (own, own_solve) = coarse["pyamg"], coarse["ours"]
        coarse_text = (f"   {theirs / mv:.1f} / {own / mv:.1f} mv ({own / theirs:.2f}), "
                       f"{their_solve / mv:.2f} / {own_solve / mv:.2f} mv")
        for choice in args.kernels:
            kernels.select(choice)
            ours_mv, build_mv = (statistics.median(seconds[f"{name} {choice}"]) / mv for name in ("ours", "build"))
            print(f"{len(mesh.points):>8} {kernels.active():>8} {pyamg_mv:>7.0f} mv {ours_mv:>7.0f} mv "
                  f"{ours_mv / pyamg_mv:>6.2f} {build_mv:>7.0f} mv {100 * statistics.median(products[choice]):>22.0f}%"
                  + coarse_text, flush=True)


if __name__ == "__main__":
    main()
