"""Levers of the AMG hierarchy, measured on the solver as it is: the build, CG, the V-cycle and the implicit step.

The README beam (1 m x 0.2 m x 0.2 m, structured cells 5k x k x k, pinned at x = 0, gravity; E = 1e7 Pa, nu = 0.45;
springs; as ``benchmarks/bench_amg_build.py`` builds it), once per variant of how
:class:`volspring.solvers.amg.AMGConjugateGradient` builds its hierarchy. Each variant changes, for its own
measurements only (put back in a ``finally``), either the module's level builder
:func:`volspring.solvers.amg._smoothed_aggregation` (wrapped, or replaced by :func:`levels`, its loop made of the
package's own steps with the levers in it) or the solver's option defaults. Per variant, in CPU time and one thread:

- ``build``: one whole :meth:`AMGConjugateGradient.build` on the first step's system (dt = 0.01 s), best of 3;
  ``rejected``: the operator complexity of a hierarchy the build threw away (above 2.5, so built again at
  theta 0; its time is in ``build``), else ``-``;
- ``CG``: CG iterations from a zero guess to rtol 1e-3 on that system, right-hand side
  ``np.random.default_rng(0).standard_normal``;
- ``V-cycle``: one :meth:`AMGConjugateGradient.precondition`, median of 20;
- ``op.cx``: the hierarchy's operator complexity, and ``levels``: the unknowns of each level;
- ``step`` and ``step CG``: the median implicit Euler step (everything the step does; the hierarchy is built in the
  first) and the mean CG iterations, over steps 3 to ``--steps`` at dt = 0.01 s; ``builds``: the hierarchies that run
  built (1 unless the iterations grew enough for a rebuild);
- ``P+R``: the memory the levels' prolongators and restrictions hold, KiB per node (shared arrays once);
- ``finest``: the memory the finest level's matrix holds (its triangles with the default smoother), KiB per node;

times as multiples of one mat-vec (``mv``) with the first step's matrix, measured again before each variant (its
time in ``mv [ms]``). The variants:

=====================  ===========================================================================================
``base``               as the package builds it (six rigid-body modes, symmetric strength 0.05, standard
                       aggregation, P = T - omega D^-1 A T on every level, R = P^T, coarse (R A) P, BSR; the
                       finest level's triangles, P and R then held in single precision, P as CSR, R its view)
``finest_double``      the finest level's triangles, P and R held in double precision (BSR P and R), as
                       until stop 26 (``amg.FINEST_DTYPE``)
``galerkin_whole``     the coarse matrices R A P as one product, not :data:`amg.GALERKIN_CHUNKS` row blocks of R
                       at a time (the same matrices; the build's peak memory is the difference)
``coarse_unsmoothed``  P smoothed on the finest level only; the tentative T is P on the coarser levels
``filtered``           P smoothed with A filtered to the strength pattern, as pyamg's ``filter_entries``: only the
                       strong block couplings (and the diagonal) of A in A T and in the row sums D, then the
                       correction's rows projected so that P reproduces the candidates (pyamg's
                       ``satisfy_constraints``)
``naive``              pyamg's ``naive_aggregation`` instead of ``standard_aggregation``
``translations``       the three translations as the whole near-null space (coarse blocks 3 x 3, not 6 x 6)
``coarse_translations`` the six rigid-body modes on the finest level, their three translations below it (the
                       first coarse level's blocks stay 6 x 6, its P's are 6 x 3, the next levels' 3 x 3)
``theta_0``            strength threshold 0: every block coupling is strong (option ``strength_theta``)
``theta_0.2``          strength threshold 0.2 instead of 0.05
``max_coarse_3000``    up to 3000 unknowns on the coarsest level (solved by sparse LU; option ``max_coarse``)
``galerkin_rap``       coarse matrix R (A P) instead of (R A) P
``csr_p``              P built as in ``base`` (BSR products), then held as CSR and R as its transpose, a CSC
                       view (no copy), on every level (``base`` does so on the finest, in single precision)
=====================  ===========================================================================================

The old study's ``float32`` and ``coarse_jacobi`` variants are gone: they swapped pyamg's block Gauss-Seidel
smoothers, which the cycle no longer runs (the default sweeps a level's triangles, ``amg._Triangles``). Its
``unsmoothed_p`` (T on every level) became ``coarse_unsmoothed`` (T below the finest level only), ``filtered_p``
became ``filtered``. Before the variants the script checks that :func:`levels` with no lever gives the package's
levels bit for bit, and stops if not (the package's loop changed: bring :func:`levels` up to date).

Run (numpy/scipy threads are held to one before numpy is imported)::

    python benchmarks/study_amg_levers.py                        # k = 12: 10,309 nodes, every variant
    python benchmarks/study_amg_levers.py --variants base csr_p  # some variants
    python benchmarks/study_amg_levers.py --nodes 45000 --steps 8  # the k nearest 45k nodes (k = 20)

A study, not a test: the variants run one after the other in this process, and the figures are ratios from one run.

Measured in one run on a 2-vCPU machine (``OMP_NUM_THREADS=1 python benchmarks/study_amg_levers.py``, 2 min; 10,309
nodes, 30,420 unknowns, one mat-vec 0.76-0.77 ms)::

    variant             build rejected   CG V-cycle op.cx   step step CG builds     P+R  finest mv [ms]  levels
    base                  190        -    6    5.73  1.66   61.2     4.2      1    0.80    1.04    0.77  30420/3018/222
    finest_double         192        -    6    5.95  1.66   65.5     4.2      1    1.40    1.54    0.77  30420/3018/222
    galerkin_whole        179        -    6    5.47  1.66   61.5     4.2      1    0.80    1.04    0.77  30420/3018/222
    coarse_unsmoothed     150        -    8    5.40  1.65   67.4     5.5      1    0.62    1.04    0.77  30420/3018/222
    filtered              298        -    6    5.42  1.62   58.5     4.4      1    0.65    1.04    0.77  30420/3018/228
    naive                6359    13.64    5   48.99 10.07  201.7     3.8      1    2.69    1.04    0.77  30420/16560/588
    translations          100        -   22    4.27  1.16   77.8    10.9      1    0.36    1.04    0.77  30420/1509/111
    theta_0               150        -    9    5.22  1.53   65.2     6.2      1    0.66    1.04    0.76  30420/2706/72
    theta_0.2             757     5.50    9    5.23  1.53   66.0     6.2      1    0.66    1.04    0.76  30420/2706/72
    max_coarse_3000       279        -    5    5.65  1.63   65.3     3.9      1    0.59    1.04    0.76  30420/3018
    galerkin_rap          181        -    6    5.60  1.66   62.1     4.2      1    0.80    1.04    0.76  30420/3018/222
    csr_p                 228        -    6    5.63  1.66   63.3     4.2      1    0.74    1.04    0.76  30420/3018/222

Iterations, complexities, levels and memory are exact (the same in every run). The times are not: between runs on
this machine a V-cycle moved by up to 20% and a step by up to 40% (assembly and CG; the warm start takes CG from 6 to
3 iterations over the ten steps). ``galerkin_rap`` and ``galerkin_whole`` build ``base``'s levels (to rounding, and
bit for bit), so the gaps between their V-cycles and steps are noise. Read from several runs, the levers that paid
are in ``base``: against ``finest_double`` (the default before) the finest level in single precision holds its
triangles in 1.04 KiB per node instead of 1.54 and every level's P and R in 0.80 instead of 1.40, for a V-cycle
4-9% cheaper at 10k nodes and 45k (``--nodes 45000 --variants base finest_double``: 9.5-9.9 mv against 10.3-10.6)
and the same CG iterations. No other lever is clearly ahead of ``base`` on the step. ``theta_0`` builds 16-23%
faster and ``coarse_unsmoothed`` 3-21%, for 3 and 2 more CG iterations from zero (2 and 1.3 more per step);
``translations`` builds in half the time for 22 CG iterations instead of 6; ``filtered`` builds in 1.5 times the time
for a V-cycle 1-11% cheaper and 0.2 more CG iterations per step; ``max_coarse_3000`` builds in 1.5 times the time for
one CG iteration fewer; ``theta_0.2``'s hierarchy (complexity 5.5) is thrown away and ``theta_0``'s built instead,
about 4 times ``base``'s build in all; ``naive`` coarsens too slowly (complexity 10, about 35 times the build);
``csr_p`` holds the coarser levels' P as CSR too (their R a view) for 0.06 KiB per node less, with scalar products in
place of blocks there.
"""

import os

for _variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "VECLIB_MAXIMUM_THREADS"):
    os.environ[_variable] = "1"

import argparse  # noqa: E402
import contextlib  # noqa: E402
import functools  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402
from pyamg.aggregation import fit_candidates, naive_aggregation, standard_aggregation  # noqa: E402
from pyamg.aggregation.smooth import satisfy_constraints  # noqa: E402
from pyamg.multilevel import MultilevelSolver  # noqa: E402
from pyamg.util.utils import compute_BtBinv, get_blocksize, scale_rows  # noqa: E402

import volspring.solvers.amg as amg  # noqa: E402
from bench_warm_start import MATERIAL, matvec_seconds  # noqa: E402
from meshing import structured_box  # noqa: E402
from meshing.geometry import rigid_body_modes  # noqa: E402
from volspring import Gravity, Model, Pins, Scene  # noqa: E402
from volspring.integrators.implicit import ImplicitEuler  # noqa: E402

DT = 0.01  # the README's step [s]
#: The package's level builder, as imported (the variants replace the module's name for their measurements only).
PACKAGE_LEVELS = amg._smoothed_aggregation


def levels(matrix, near_null_space, *, theta, excluded, max_coarse, aggregate=standard_aggregation,
           smooth_coarse=True, filtered=False, right_first=False, csr_p=False, coarse_modes=None):
    """:func:`volspring.solvers.amg._smoothed_aggregation`'s loop from the package's own steps, with the levers (the
    defaults: none).

    ``aggregate``: pyamg's aggregation function; ``smooth_coarse``: smooth P below the finest level too (else the
    tentative T); ``filtered``: smooth P with the strong part of A (:func:`strong_part`) and project the correction
    as pyamg's ``filter_entries`` does; ``right_first``: the coarse matrix as R (A P); ``csr_p``: P held as CSR and R
    as its CSC transpose; ``coarse_modes``: the first this many candidates (the translations) only, on the levels
    below the first coarse one.
    """
    level = MultilevelSolver.Level()
    level.A, level.B = matrix, near_null_space
    hierarchy = [level]
    while len(hierarchy) < 10 and matrix.shape[0] // get_blocksize(matrix) > max_coarse:
        smoothing, strength = amg._coarsening(matrix, theta, excluded)
        tentative, candidates = fit_candidates(aggregate(strength)[0], level.B)
        if not smooth_coarse and len(hierarchy) > 1:
            level.P = tentative
        elif filtered:
            level.P = filtered_prolongator(strong_part(smoothing, strength), tentative, candidates)
        else:
            level.P = amg._smoothed_prolongator(smoothing, tentative)
        del smoothing, strength, tentative
        level.R = level.P.T
        coarse = level.R @ (matrix @ level.P) if right_first else level.R @ matrix @ level.P
        if csr_p:  # the products above by blocks (scipy's CSR ones cost twice as much); then held as CSR
            level.P = level.P.tocsr()
            level.R = level.P.T
        excluded = amg._excluded_below(level.P, excluded)
        level = MultilevelSolver.Level()
        level.A = coarse
        level.B = candidates if coarse_modes is None else np.ascontiguousarray(candidates[:, :coarse_modes])
        hierarchy.append(level)
        matrix = coarse
    return MultilevelSolver(hierarchy, coarse_solver="splu")


def filtered_prolongator(strong, tentative, candidates):
    """P = T - omega D^-1 (A_s T) with A_s the strong part of A, the correction's rows projected so that P still
    reproduces the candidates (pyamg's ``satisfy_constraints``: A_s no longer annihilates the modes)."""
    row_sums = amg._absolute(strong) @ np.ones(strong.shape[0])
    weights = np.zeros_like(row_sums)
    np.divide(amg.PROLONGATION_OMEGA, row_sums, out=weights, where=row_sums != 0)
    correction = (strong @ tentative).tobsr(blocksize=tentative.blocksize)
    scale_rows(correction, weights, copy=False)
    satisfy_constraints(correction, candidates, compute_BtBinv(candidates, correction))
    return amg._minus_plus_tentative(correction, tentative)


def strong_part(matrix, strength):
    """The blocks of the BSR (or entries of the CSR) ``matrix`` where ``strength`` (its node graph, the diagonal
    included) has an entry: what pyamg's ``filter_entries`` smooths the prolongator with."""
    size = matrix.blocksize[0] if matrix.format == "bsr" else 1
    matrix = matrix if size > 1 else sp.csr_matrix(matrix)
    nodes = matrix.shape[0] // size
    rows = np.repeat(np.arange(nodes, dtype=np.int64), np.diff(matrix.indptr))
    strong = np.repeat(np.arange(nodes, dtype=np.int64), np.diff(strength.indptr)) * nodes + strength.indices
    return amg._rows_where(matrix, rows, np.isin(rows * nodes + matrix.indices, strong))


def translations_only(matrix, near_null_space, **options):
    """The package's levels from the first three columns of the near-null space (the translations)."""
    return PACKAGE_LEVELS(matrix, np.ascontiguousarray(near_null_space[:, :3]), **options)


#: name -> (the level builder put in place of the package's, or None; AMGConjugateGradient option defaults changed;
#: and module constants of volspring.solvers.amg changed)
VARIANTS = {
    "base": (None, {}),
    "finest_double": (None, {}, {"FINEST_DTYPE": np.float64}),
    "galerkin_whole": (None, {}, {"GALERKIN_CHUNKS": 1}),
    "coarse_unsmoothed": (functools.partial(levels, smooth_coarse=False), {}),
    "filtered": (functools.partial(levels, filtered=True), {}),
    "naive": (functools.partial(levels, aggregate=naive_aggregation), {}),
    "translations": (translations_only, {}),
    "coarse_translations": (functools.partial(levels, coarse_modes=3), {}),
    "theta_0": (None, {"strength_theta": 0.0}),
    "theta_0.2": (None, {"strength_theta": 0.2}),
    "max_coarse_3000": (None, {"max_coarse": 3000}),
    "galerkin_rap": (functools.partial(levels, right_first=True), {}),
    "csr_p": (functools.partial(levels, csr_p=True), {}),
}


@contextlib.contextmanager
def lever(variant):
    """``variant``'s level builder and option defaults in place in :mod:`volspring.solvers.amg` while inside; the
    package's back on the way out, whatever happens. Option defaults reach every solver made meanwhile, the
    integrator's too. Yields a list that gets the operator complexity of every set of levels built inside (two per
    build when the package rejects a hierarchy above complexity 2.5 and builds again at theta 0)."""
    builder, options, constants = (VARIANTS[variant] + ({},))[:3]
    builder = PACKAGE_LEVELS if builder is None else builder
    complexities = []

    def recorded(*args, **kwargs):
        hierarchy = builder(*args, **kwargs)
        complexities.append(hierarchy.operator_complexity())
        return hierarchy

    defaults = amg.AMGConjugateGradient.__init__.__kwdefaults__
    saved, saved_constants = dict(defaults), {name: getattr(amg, name) for name in constants}
    try:
        defaults.update(options)
        for name, value in constants.items():
            setattr(amg, name, value)
        amg._smoothed_aggregation = recorded
        yield complexities
    finally:
        amg._smoothed_aggregation = PACKAGE_LEVELS
        defaults.clear()
        defaults.update(saved)
        for name, value in saved_constants.items():
            setattr(amg, name, value)


def check_copy(matrix, modes):
    """Stop unless :func:`levels` without a lever builds the package's levels bit for bit (same P and A per level)."""
    defaults = amg.AMGConjugateGradient.__init__.__kwdefaults__
    options = dict(theta=defaults["strength_theta"], excluded=None, max_coarse=defaults["max_coarse"])
    ours = levels(matrix.copy(), modes, **options).levels
    package = PACKAGE_LEVELS(matrix.copy(), modes, **options).levels
    pairs = [(mine.A, theirs.A) for mine, theirs in zip(ours, package)]
    pairs += [(mine.P, theirs.P) for mine, theirs in zip(ours[:-1], package[:-1])]
    same = len(ours) == len(package) and all(
        type(a) is type(b) and a.shape == b.shape and
        all(np.array_equal(getattr(a, part), getattr(b, part)) for part in ("data", "indices", "indptr"))
        for a, b in pairs)
    if not same:
        raise SystemExit("levels() no longer builds the package's hierarchy: follow amg._smoothed_aggregation's loop")


def transfer_bytes(hierarchy) -> int:
    """Bytes held by the levels' P and R (arrays they share, as R a view of P, counted once)."""
    arrays = {}
    for level in hierarchy.levels[:-1]:
        for matrix in (level.P, level.R):
            for part in (matrix.data, matrix.indices, matrix.indptr):
                root = part
                while isinstance(root.base, np.ndarray):
                    root = root.base
                arrays[id(root)] = root.nbytes
    return sum(arrays.values())


def finest_bytes(hierarchy) -> int:
    """Bytes held by the finest level's matrix (its two triangles with the default smoother)."""
    finest = hierarchy.levels[0].A
    parts = (finest.lower, finest.upper) if isinstance(finest, amg._Triangles) else (finest,)
    return sum(part.data.nbytes + part.indices.nbytes + part.indptr.nbytes for part in parts)


def beam(cells):
    """The README beam of 5k x k x k cells as ``bench_amg_build.py`` builds it: (scene, first step's matrix, modes)."""
    mesh = structured_box((5 * cells, cells, cells), (1.0, 0.2, 0.2))
    model = Model.from_mesh(mesh, MATERIAL)
    scene = Scene(model, forces=[Gravity()], pins=Pins(np.flatnonzero(mesh.points[:, 0] == 0)))
    matrix, _, pattern = ImplicitEuler().linear_system(scene, scene.initial_state(), DT)
    return scene, matrix, rigid_body_modes(model.rest_positions[pattern.free_nodes])


def measure(variant, scene, matrix, modes, steps):
    """One row of the table: ``variant``'s figures (see the module docstring), its lever in place throughout."""
    rhs = np.random.default_rng(0).standard_normal(matrix.shape[0])
    with lever(variant) as complexities:
        mv = matvec_seconds(matrix)
        builds = []
        for _ in range(3):
            given = matrix.copy()  # the build keeps (and pyamg caches on) the matrix it is given
            solver = amg.AMGConjugateGradient(timer=time.process_time, on_failure="warn")
            complexities.clear()
            builds.append(solver.build(given, modes))
        rejected = f"{complexities[0]:.2f}" if len(complexities) > 1 else "-"
        _, info = solver.solve(matrix, rhs)
        cycles = []
        for _ in range(20):
            start = time.process_time()
            solver.precondition(rhs)
            cycles.append(time.process_time() - start)
        hierarchy = solver.hierarchy
        sizes = "/".join(str(level.A.shape[0]) for level in hierarchy.levels)
        transfer = transfer_bytes(hierarchy) / 1024 / scene.model.node_count
        finest = finest_bytes(hierarchy) / 1024 / scene.model.node_count
        integrator = ImplicitEuler(timer=time.process_time, on_failure="warn")
        state, seconds, iterations = scene.initial_state(), [], []
        for _ in range(steps):
            start = time.process_time()
            state = integrator.step(scene, state, DT)
            seconds.append(time.process_time() - start)
            iterations.append(integrator.last_solve.iterations)
    print(f"{variant:<18} {min(builds) / mv:6.0f} {rejected:>8} {info.iterations:4d} {np.median(cycles) / mv:7.2f} "
          f"{hierarchy.operator_complexity():5.2f} {np.median(seconds[2:]) / mv:6.1f} {np.mean(iterations[2:]):7.1f} "
          f"{integrator.solver.build_count:6d} {transfer:7.2f} {finest:7.2f} {1e3 * mv:7.2f}  {sizes}", flush=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    size = parser.add_mutually_exclusive_group()
    size.add_argument("--cells", type=int, default=12, help="k of the 5k x k x k cells (default: %(default)s)")
    size.add_argument("--nodes", type=int, help="the k whose (5k + 1)(k + 1)^2 nodes come nearest this")
    parser.add_argument("--steps", type=int, default=12, help="implicit steps per variant, the first two not counted")
    parser.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=list(VARIANTS), metavar="VARIANT",
                        help=f"any of {', '.join(VARIANTS)} (default: all)")
    args = parser.parse_args()
    if args.steps < 3:
        parser.error("--steps must be at least 3 (the figures are over steps 3 to --steps)")
    cells = args.cells
    if args.nodes is not None:
        counts = (5 * np.arange(1, 200) + 1) * (np.arange(1, 200) + 1) ** 2
        cells = 1 + int(np.argmin(abs(counts - args.nodes)))
    scene, matrix, modes = beam(cells)
    check_copy(matrix, modes)
    print(f"README beam, cells {5 * cells} x {cells} x {cells}: {scene.model.node_count} nodes, {matrix.shape[0]} "
          f"unknowns; dt = {DT} s, steps 3 to {args.steps}; times in mat-vecs (mv) with the first step's matrix")
    print(f"{'variant':<18} {'build':>6} {'rejected':>8} {'CG':>4} {'V-cycle':>7} {'op.cx':>5} {'step':>6} "
          f"{'step CG':>7} {'builds':>6} {'P+R':>7} {'finest':>7} {'mv [ms]':>7}  levels")
    for variant in args.variants:
        measure(variant, scene, matrix, modes, args.steps)


if __name__ == "__main__":
    main()
