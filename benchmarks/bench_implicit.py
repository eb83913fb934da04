"""Benchmark of the implicit Euler step on gmsh beams of about 1k, 10k and 50k nodes.

A cantilever (1 m x 0.2 m x 0.2 m, pinned at x = 0, under gravity) at a stiff setting: dt is
chosen so that h * omega_max = 50 (omega_max^2 = the largest eigenvalue of M^-1 K, computed
here with eigsh), i.e. 25 times the symplectic Euler limit. Per step it prints the time split
(CPU time of this process, so that other jobs on a shared machine do not count; wall time
is printed next to it) into forces (spring forces with their Jacobian blocks, scene forces), assembly (refill of the
fixed pattern and right-hand side), AMG setup (raw: one build; amortised: all builds of the
run over its steps) and solve, the CG iterations, each time also as a multiple of one sparse
mat-vec with the same BSR matrix measured in the same run, and the scaling exponent fitted
over the sizes. Then the same at rtol 1e-6 and Jacobi-CG iteration counts for comparison.

Run (numpy/scipy threads are held to one before numpy is imported)::

    python benchmarks/bench_implicit.py                  # 1k, 10k, 50k nodes
    python benchmarks/bench_implicit.py --nodes 1000 10000 --steps 10

This is a script, not a test: the timings depend on the machine and its load (printed).
"""

import os

for _variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "VECLIB_MAXIMUM_THREADS"):
    os.environ[_variable] = "1"

import argparse  # noqa: E402
import logging  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

import numpy as np  # noqa: E402
import scipy.sparse as sp  # noqa: E402
import scipy.sparse.linalg as sla  # noqa: E402

from meshing import TetMesh  # noqa: E402
from volspring import Gravity, Material, Pins, Scene, Model  # noqa: E402
from volspring.assembly import BlockPattern  # noqa: E402
from volspring.integrators.implicit import ImplicitEuler  # noqa: E402

LENGTH, WIDTH = 1.0, 0.2
MATERIAL = Material(1e7, 0.25, 1000.0)  # stiff rubber-like solid [Pa], [-], [kg/m^3]


def beam_mesh(target_nodes: int) -> TetMesh:
    """A gmsh tet mesh of the beam with about ``target_nodes`` nodes."""
    import gmsh

    volume = LENGTH * WIDTH * WIDTH
    size = (volume / target_nodes) ** (1 / 3)
    for _ in range(3):
        gmsh.initialize(readConfigFiles=False, interruptible=False)
        try:
            gmsh.option.setNumber("General.Terminal", 0)
            gmsh.model.add("beam")
            gmsh.model.occ.addBox(0, 0, 0, LENGTH, WIDTH, WIDTH)
            gmsh.model.occ.synchronize()
            gmsh.option.setNumber("Mesh.MeshSizeMin", size)
            gmsh.option.setNumber("Mesh.MeshSizeMax", size)
            gmsh.model.mesh.generate(3)
            tags, coords, _ = gmsh.model.mesh.getNodes()
            _, element_tags, element_nodes = gmsh.model.mesh.getElements(3)
        finally:
            gmsh.finalize()
        points = np.empty((int(tags.max()) + 1, 3))
        points[tags.astype(np.int64)] = coords.reshape(-1, 3)
        tets = element_nodes[0].astype(np.int64).reshape(-1, 4)
        mesh = TetMesh.compact(points, tets)
        ratio = mesh.node_count / target_nodes
        if 0.95 < ratio < 1.05:
            break
        size *= ratio ** (1 / 3)
    return mesh


def omega_max(model, scene) -> float:
    """sqrt of the largest eigenvalue of M^-1 K over the free nodes [rad/s]."""
    pattern = BlockPattern(model, scene.free)
    stiffness = pattern.matrix(pattern.linearize(model.rest_positions, stiffness_scale=1.0).blocks).tocsr()
    inverse_sqrt_mass = sp.diags(np.repeat(model.masses[pattern.free_nodes], 3) ** -0.5)
    scaled = (inverse_sqrt_mass @ stiffness @ inverse_sqrt_mass).tocsr()
    return float(np.sqrt(sla.eigsh(scaled, k=1, which="LA", tol=1e-4, return_eigenvectors=False)[0]))


# CPU time of this process: on a machine shared with other jobs it counts only our own work
# (single-threaded BLAS), so ratios to the mat-vec stay meaningful; wall time is printed too.
CLOCK = time.process_time


def median_seconds(function, repeats=31, inner=3):
    times = []
    for _ in range(repeats):
        start = CLOCK()
        for _ in range(inner):
            function()
        times.append((CLOCK() - start) / inner)
    return float(np.median(times))


def warm_up() -> None:
    """Step a small beam (525 nodes: two AMG levels) before anything is timed. The compiled kernels (the ``fast``
    extra) are compiled, or loaded from numba's cache, at their first call in a process: 34 ms, which put 560 of the
    first 1k-node build's 766 mat-vecs there, and 28 of its 90 per step amortised over 20 steps (stop 32). That is a
    cost of starting the process, not of a step or a build."""
    from meshing import structured_box

    mesh = structured_box((20, 4, 4), (1.0, 0.2, 0.2))
    model = Model.from_mesh(mesh, MATERIAL)
    scene = Scene(model, forces=[Gravity()], pins=Pins(np.flatnonzero(mesh.points[:, 0] == 0)))
    run(scene, 1e-3, steps=2)


def run(scene, dt, *, steps, **options):
    """Step ``steps`` times from rest; per-step records and one mat-vec time of the last matrix."""
    integrator = ImplicitEuler(timer=CLOCK, **options)  # every *_seconds figure on the same clock
    state = scene.initial_state()
    records = []
    for _ in range(steps):
        start, wall_start = CLOCK(), time.perf_counter()
        state = integrator.step(scene, state, dt)
        cpu, wall = CLOCK() - start, time.perf_counter() - wall_start
        info = integrator.last_solve
        records.append((cpu, wall, info.forces_seconds, info.assembly_seconds, info.setup_seconds,
                        info.solve_seconds, info.iterations, info.rebuilt))
    matrix, _, _ = integrator.linear_system(scene, state, dt)
    vector = np.random.default_rng(0).standard_normal(matrix.shape[0])
    matvec = median_seconds(lambda: matrix @ vector)
    return np.array(records, dtype=float), matvec, state, matrix


def report_products(matrix, matvec):
    """The step's products with its system in mat-vecs (scipy's product with one vector): CG's, one vector, and its
    guess's, the last five velocity changes at once, as the step makes them (``volspring.solvers.krylov.times``: the
    compiled kernel with the ``fast`` extra, else scipy's) and as scipy makes them."""
    from volspring.solvers.krylov import times

    rng = np.random.default_rng(1)
    vector = rng.standard_normal(matrix.shape[0])
    changes = rng.standard_normal((5, matrix.shape[0])).T  # as CG's guess holds them: the transpose of the history
    ours = median_seconds(lambda: times(matrix, vector)) / matvec
    ours_five = median_seconds(lambda: times(matrix, changes)) / matvec
    scipy_five = median_seconds(lambda: matrix @ changes) / matvec
    print(f"    system products (step / scipy): one vector {ours:.2f} / 1 mv, five vectors {ours_five:.2f} / "
          f"{scipy_five:.2f} mv")


def report_case(label, records, matvec, steps):
    cpu, wall, forces, assembly, setup, solve, iterations, rebuilt = records.T
    steady = rebuilt == 0
    builds = setup[rebuilt == 1]
    raw_setup = float(builds.mean()) if builds.size else 0.0
    amortised = float(setup.sum()) / steps
    bare = float(np.median(cpu[steady] if steady.any() else cpu - setup))
    per_step = bare + amortised
    per_step_wall = float(np.median(wall[steady] if steady.any() else wall - setup)) + amortised

    def both(seconds):
        return f"{seconds * 1e3:8.2f} ms {seconds / matvec:7.1f} mv"

    print(f"  {label}")
    print(f"    mat-vec (BSR, block 3)      {matvec * 1e3:8.3f} ms")
    print(f"    forces                      {both(np.median(forces))}")
    print(f"    assembly                    {both(np.median(assembly))}")
    print(f"    forces + assembly           {both(np.median(forces + assembly))}")
    print(f"    AMG setup raw (one build)   {both(raw_setup)}   builds: {int(rebuilt.sum())} in {steps} steps")
    print(f"    AMG setup amortised         {both(amortised)}")
    print(f"    solve                       {both(np.median(solve))}")
    print(f"    CG iterations               median {np.median(iterations):.0f}, min {iterations.min():.0f}, "
          f"max {iterations.max():.0f}, per step {iterations.astype(int).tolist()}")
    print(f"    step without setup (median) {both(bare)}")
    print(f"    step + amortised setup      {both(per_step)}   (wall {per_step_wall * 1e3:.1f} ms)")
    return per_step, float(np.median(solve)), float(np.median(iterations)), bare, matvec


def fitted_exponent(nodes, seconds):
    return float(np.polyfit(np.log(nodes), np.log(seconds), 1)[0])


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--nodes", type=int, nargs="+", default=[1000, 10000, 50000])
    parser.add_argument("--steps", type=int, default=20, help="implicit steps per case")
    parser.add_argument("--h-omega", type=float, default=50.0, help="h * omega_max of the step")
    parser.add_argument("--jacobi-steps", type=int, default=2, help="Jacobi-CG steps for comparison (0: none)")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)

    print(f"load average before: {os.getloadavg()}  (cores: {os.cpu_count()})")
    from volspring import kernels

    print(f"kernels: {kernels.active()} (volspring.kernels; VOLSPRING_KERNELS=numpy or numba chooses)")
    warm_up()
    results = {1e-3: [], 1e-6: []}
    counts = []
    for target in args.nodes:
        start = time.perf_counter()
        mesh = beam_mesh(target)
        model = Model.from_mesh(mesh, MATERIAL)
        pins = Pins(np.flatnonzero(model.rest_positions[:, 0] < 1e-9))
        scene = Scene(model, forces=[Gravity()], pins=pins)
        omega = omega_max(model, scene)
        dt = args.h_omega / omega
        counts.append(model.node_count)
        print(f"\nbeam: {model.node_count} nodes, {model.spring_count} springs, {len(pins.nodes)} pinned; "
              f"omega_max = {omega:.4g} rad/s, dt = {dt:.3g} s, h omega_max = {dt * omega:.1f} "
              f"(mesh + omega_max {time.perf_counter() - start:.1f} s)")
        for rtol in (1e-3, 1e-6):
            records, matvec, state, matrix = run(scene, dt, steps=args.steps, rtol=rtol)
            results[rtol].append(report_case(f"AMG-CG rtol {rtol:g}", records, matvec, args.steps))
        report_products(matrix, matvec)
        tip = state.x[:, 2].min() - model.rest_positions[:, 2].min()
        print(f"    tip displacement after {args.steps} steps: {tip:.4g} m")
        if args.jacobi_steps:  # --jacobi-steps 0 leaves the comparison out
            records, matvec, _, _ = run(scene, dt, steps=args.jacobi_steps, solver="jacobi", rtol=1e-3, maxiter=50000)
            iterations = records[:, 6].astype(int).tolist()
            print(f"  Jacobi-CG rtol 1e-3: iterations per step {iterations}, solve "
                  f"{np.median(records[:, 5]) * 1e3:.1f} ms = {np.median(records[:, 5]) / matvec:.0f} mv")
        sys.stdout.flush()

    if len(counts) > 1:
        print("\nscaling exponents (log time / log nodes):")
        for rtol, rows in results.items():
            step, solve, _, bare, matvec = np.array(rows).T
            print(f"  rtol {rtol:g}: step + amortised setup {fitted_exponent(counts, step):.3f}, step without "
                  f"setup {fitted_exponent(counts, bare):.3f}, solve {fitted_exponent(counts, solve):.3f}, "
                  f"one mat-vec {fitted_exponent(counts, matvec):.3f}, step in mat-vecs "
                  f"{fitted_exponent(counts, bare / matvec):.3f}")
    print("\nsummary (CPU time per step: median without setup / with the setup amortised over the run):")
    for rtol, rows in results.items():
        print("  rtol %-6g" % rtol + "   ".join(f"{n} nodes: {row[3] * 1e3:.1f} / {row[0] * 1e3:.1f} ms "
                                              f"({row[2]:.0f} it)" for n, row in zip(counts, rows)))
    print(f"load average after: {os.getloadavg()}")


if __name__ == "__main__":
    main()
