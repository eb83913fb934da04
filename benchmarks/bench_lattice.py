"""Cost of an implicit Euler step: lattice body vs tet springs on the same shape, at a similar node count.

Two pairs, each run in this process one after the other:

- a beam 1 x 0.2 x 0.2 m of 40 x 8 x 8 cells: the lattice (structural, shear, bend springs) and the Van
  Gelder tet springs of ``structured_box`` on the very same nodes;
- the coarse bunny (tests/data/coarse_bunny.obj, mm): its stored tet mesh (coarse_bunny.mesh, 699 nodes)
  against a lattice whose cell size gives about as many nodes;
- the beam's lattice with angle springs at the cells' right-angle joints against the springs-only lattice,
  both at nu = 0.1 (angle springs carry stiffness only below nu = 1/4).

Each scene is pinned at one end (the beam at x = 0, the bunny at its top) under gravity, stepped from rest
with ``ImplicitEuler`` (AMG-CG, default options) at the same dt; the CPU time per step is the median over
the steps after the first (which builds the AMG hierarchy). Printed: nodes, springs, CG iterations, the
time per step and the ratio lattice / tets measured in this run.

Run (numpy/scipy threads held to one before numpy is imported)::

    python benchmarks/bench_lattice.py
    python benchmarks/bench_lattice.py --steps 10

This is a script, not a test: the timings depend on the machine and its load.
"""

import os

for _variable in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "VECLIB_MAXIMUM_THREADS"):
    os.environ[_variable] = "1"

import argparse  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

from meshing import load_surface, structured_box  # noqa: E402
from meshing.mesh_io import read_tet_mesh  # noqa: E402
from volspring import Gravity, Material, Model, Pins, Scene  # noqa: E402
from volspring.integrators.implicit import ImplicitEuler  # noqa: E402
from volspring.lattice import box_lattice_model, lattice_body  # noqa: E402

DATA = Path(__file__).resolve().parents[1] / "tests" / "data"
MATERIAL = Material(E=1e6, nu=0.3, density=1000.0)
CLOCK = time.process_time


def step_seconds(model, pinned, dt, steps):
    """Median CPU seconds per step after the first, and the median CG iterations."""
    scene = Scene(model, forces=[Gravity()], pins=Pins(np.flatnonzero(pinned)))
    integrator = ImplicitEuler()
    state = scene.initial_state()
    seconds, iterations = [], []
    for _ in range(steps):
        start = CLOCK()
        state = integrator.step(scene, state, dt)
        seconds.append(CLOCK() - start)
        iterations.append(integrator.last_solve.iterations)
    return float(np.median(seconds[1:])), float(np.median(iterations[1:]))


def compare(label, lattice_model, lattice_pins, tet_model, tet_pins, dt, steps):
    rows = []
    for name, model, pins in (("lattice", lattice_model, lattice_pins), ("tet springs", tet_model, tet_pins)):
        seconds, iterations = step_seconds(model, pins, dt, steps)
        rows.append(seconds)
        print(f"  {label:6s} {name:12s} {model.node_count:6d} nodes {model.spring_count:7d} springs "
              f"({model.spring_count / model.node_count:4.1f} per node)  {iterations:5.1f} CG iterations  "
              f"{1e3 * seconds:8.2f} ms/step")
    print(f"  {label:6s} ratio lattice / tet springs: {rows[0] / rows[1]:.2f}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20, help="implicit steps per model (default 20)")
    args = parser.parse_args(argv)
    print(f"implicit Euler, AMG-CG, one thread, median CPU time per step over {args.steps - 1} steps")

    beam = structured_box((40, 8, 8), (1.0, 0.2, 0.2))
    lattice = box_lattice_model(beam, MATERIAL).model
    tets = Model.from_mesh(beam, MATERIAL, rule="van_gelder")
    clamped = beam.points[:, 0] <= 1e-9
    compare("beam", lattice, clamped, tets, clamped, 1e-3, args.steps)

    bunny_tets = read_tet_mesh(DATA / "coarse_bunny.mesh", units="mm")
    tets = Model.from_mesh(bunny_tets, MATERIAL, rule="van_gelder")
    surface = load_surface(DATA / "coarse_bunny.obj", units="mm")
    cell = 0.015  # 714 lattice nodes, about as many as the stored tet mesh (699)
    lattice = lattice_body(surface, cell, MATERIAL).model

    def top(x, size):
        return x[:, 1] >= x[:, 1].max() - size

    compare("bunny", lattice, top(lattice.rest_positions, 0.5 * cell), tets, top(tets.rest_positions, 0.01),
            1e-3, args.steps)

    soft = Material(E=1e6, nu=0.1, density=1000.0)
    times = {}
    for name, options in (("springs", {}), ("angles", {"angles": True})):
        model = box_lattice_model(beam, soft, **options).model
        times[name], iterations = step_seconds(model, clamped, 1e-3, args.steps)
        joints = sum(len(e.stencil) for e in model.elements if e.name == "angles")
        print(f"  beam   lattice {name:8s} {model.node_count:6d} nodes {joints:7d} angle joints  "
              f"{iterations:5.1f} CG iterations  {1e3 * times[name]:8.2f} ms/step")
    print(f"  beam   ratio angles / springs-only lattice: {times['angles'] / times['springs']:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
