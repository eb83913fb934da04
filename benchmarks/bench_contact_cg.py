"""CG iterations of an implicit contact step against the same step without contact, from one run (issue 15).

Issue 15's goal: the CG iterations of a contact step within 1.5x those of the same step without contact, from the
first contact step on. Each scene is stepped by implicit Euler (AMG-CG defaults, dt = 0.01 s as in the README);
at every step that starts with contacts, the same step is also taken from the same state by a second integrator
(its own solver cache) on the same scene without the contact force: the same assembly, right-hand side formation,
rebuild decision (it reads the same ``state.memory``) and warm start, minus the contact force and its Jacobian.
Its result is thrown away; the contact run goes on from its own step.

Scenes (E = 1e7 Pa, nu = 0.45, 1000 kg/m^3, two 0.2 m cubes of ``--cells`` cells per edge):

- ``pressed``: ``bench_versions.py``'s contact scene, the upper cube 1 mm into the lower one (pinned at its base)
  and pressed by a gravity of 100 m/s^2: contact from step 0;
- ``drop``: the upper cube, moved off centre by (0.03, 0.02) m, falls from 5 cm onto the pinned one under 9.81 m/s^2;
- ``floor``: one cube falls from 5 cm onto a rigid floor (``ObstacleContactForce`` and a ``HalfSpace``, whose
  contact Jacobian is block diagonal and folded into the system matrix).

Per step: the contacts at the step's start, CG iterations with contact and without and their ratio, both as the
step ran them (warm started) and for the same two systems solved again from zero with the same hierarchies (the
preconditioner's share, without the warm start's: the projection onto the last velocity changes guesses a free
fall almost exactly, 0-1 iterations), and
whether the step (re)built the AMG hierarchy (``B`` with contact, ``b`` without); the first contact step is marked.
Summary per scene: median and max ratio over the contact steps, the first contact step's ratio, the steps above 1.5,
and the contact run's CG iterations and hierarchy builds over all its steps (what the run pays; a lever that lowers
the ratios by rebuilding more, or by a costlier step, shows here).

The integrator's contact policy, measured here first (issue 15): the finest level's aggregates follow the
couplings of the system without contact (``AMGConjugateGradient.build(aggregation=)``), the hierarchy is rebuilt
when the scene forces' Jacobian reaches ``rebuild_growth`` times more or fewer unknowns than at the last build
(contact starting, ending, spreading; :data:`volspring.integrators.implicit.CONTACT_REBUILD_SHARE`), and a rigid
obstacle's contact, folded into the matrix's diagonal, reaches the hierarchy like contact between bodies; between
builds, each step gives the finest and the first coarse level the change of the contact Jacobian since the build
(``AMGConjugateGradient.update``; the finest level alone got the step's system before stop 32).
From zero, median / max: before all three (commit 97ad6dc) pressed 1.33 / 2.00, drop 2.00 / 3.75, floor 1.50 /
2.40; with the rebuilds and the floor's refresh (77f4f62) 1.33 / 2.00, 2.17 / 3.00, 1.17 / 1.33; with the
aggregates too (1cbb53c) 1.00 / 1.83, 1.17 / 1.50, 1.17 / 1.33; with the warm start by projection (4cd2ab7, another
trajectory) 1.17 / 1.83, 1.00 / 1.25, 0.83 / 1.25. With the contact kept out of every level's aggregates and of the
prolongators' smoothing (not only the finest level's aggregates): at 8 cells 1.33 / 1.67, 1.33 / 1.50, 0.83 / 1.25,
and the runs' CG iterations 48 -> 51, 135 -> 183 (the drop's last build came at 90 contacts instead of 112, and the
steps after it need 8 iterations from zero instead of 6), 83 -> 83; at 16 cells (4,913 nodes a cube, 24,576 tets,
``--cells 16 --steps 25``), pressed 2.00 / 2.67 -> 1.50 / 1.67 and drop 1.67 / 2.33 -> 1.50 / 1.83, the runs' CG
iterations 101 -> 63 and 146 -> 129 (the floor's contact is diagonal and has nothing to keep out). With the first
coarse level updated (stop 32), at 16 cells pressed 1.50 / 1.67 -> 1.33 / 1.50 and drop 1.50 / 1.83 -> 1.00 / 1.33,
the runs' CG iterations 63 -> 56 and 129 -> 99; at 8 cells the hierarchy has two levels and nothing changes.

Run (the script holds numpy to one thread; about 5 s)::

    python benchmarks/bench_contact_cg.py
    python benchmarks/bench_contact_cg.py --scenes drop floor --cells 10 --steps 60

This is a script, not a test.
"""

from __future__ import annotations

import os

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_name] = "1"  # before numpy loads its BLAS

import argparse  # noqa: E402
import statistics  # noqa: E402

import numpy as np  # noqa: E402

SCENES = ("pressed", "drop", "floor")
LIMIT = 1.5  # issue 15's bound on the ratio


def scene_pair(kind: str, cells: int):
    """(scene with contact, the same scene without the contact force, the contact force)."""
    from meshing import structured_box
    from volspring import Gravity, HalfSpace, Material, Model, Pins, Scene
    from volspring.bodies import Body
    from volspring.collision import ContactForce, ObstacleContactForce

    material = Material(1e7, 0.45, 1000.0)
    cube = structured_box((cells, cells, cells), (0.2, 0.2, 0.2))
    if kind == "floor":
        model = Model.from_bodies([Body(cube, material, translation=(0.0, 0.0, 0.05))])
        gravity = Gravity()
        contact = ObstacleContactForce(model, [HalfSpace((0.0, 0.0, 0.0), (0.0, 0.0, 1.0))])
        return Scene(model, forces=[gravity, contact]), Scene(model, forces=[gravity]), contact
    upper = (0.0, 0.0, 0.199) if kind == "pressed" else (0.03, 0.02, 0.25)
    model = Model.from_bodies([Body(cube, material), Body(cube, material, translation=upper)])
    gravity = Gravity(g=(0.0, 0.0, -100.0 if kind == "pressed" else -9.81))
    contact = ContactForce(model)
    pins = Pins(np.flatnonzero(model.rest_positions[:, 2] == 0))
    return Scene(model, forces=[gravity, contact], pins=pins), Scene(model, forces=[gravity], pins=pins), contact


def count_cold_iterations(integrator) -> None:
    """Make ``integrator``'s AMG-CG also solve every system from zero after the step's own (warm) solve; its iteration
    count goes to ``solver.cold_iterations``. Neither the step's answer nor the hierarchy changes."""
    solver = integrator.cache.solver
    warm_solve = solver.solve

    def solve(matrix, rhs, **options):
        answer = warm_solve(matrix, rhs, **options)
        solver.cold_iterations = warm_solve(matrix, rhs, **{**options, "x0": None})[1].iterations
        return answer

    solver.solve = solve


def run(kind: str, *, cells: int, steps: int, dt: float) -> dict:
    from volspring.integrators.implicit import ImplicitEuler

    scene, free_scene, contact = scene_pair(kind, cells)
    integrator = ImplicitEuler()
    free_integrator = ImplicitEuler()  # its own cache: the hierarchy of the contact-free system
    for each in (integrator, free_integrator):
        count_cold_iterations(each)
    state = scene.initial_state()
    print(f"\n{kind}: {scene.model.node_count} nodes, {steps} steps of {dt:g} s")
    print(f"{'':22} {'warm start (the step)':^20}  {'from zero':^20}")
    print(f"{'step':>4} {'t [s]':>6} {'contacts':>8}   {'CG':>4} {'free':>5} {'ratio':>6}   {'CG':>4} {'free':>5}"
          f" {'ratio':>6} {'AMG':>4}")
    ratios, first = {"warm": [], "cold": []}, None
    iterations = builds = 0  # the contact run's own steps, all of them (what the run pays)
    for _ in range(steps):
        count = contact.contacts(state.x).count
        if count:
            free_integrator.step(free_scene, state, dt)
            free, free_cold = free_integrator.last_solve, free_integrator.solver.cold_iterations
        new = integrator.step(scene, state, dt)
        solve, cold = integrator.last_solve, integrator.solver.cold_iterations
        iterations, builds = iterations + solve.iterations, builds + solve.rebuilt
        built = ("B" if solve.rebuilt else "") + ("b" if count and free.rebuilt else "")
        if not count:
            print(f"{state.step:4d} {state.t:6.2f} {0:8d}   {solve.iterations:4d} {'':12}   {cold:4d} {'':12} {built:>4}")
            state = new
            continue
        ratio = {"warm": solve.iterations / max(free.iterations, 1), "cold": cold / max(free_cold, 1)}
        for name, value in ratio.items():
            ratios[name].append(value)
        mark = "  > 1.5" if ratio["warm"] > LIMIT else ""
        if first is None:
            first, mark = ratio, mark + "  <- first contact step"
        print(f"{state.step:4d} {state.t:6.2f} {count:8d}   {solve.iterations:4d} {free.iterations:5d}"
              f" {ratio['warm']:6.2f}   {cold:4d} {free_cold:5d} {ratio['cold']:6.2f} {built:>4}{mark}")
        state = new
    if first is None:
        print(f"{kind}: no contact in {steps} steps")
        return {}
    summary = {name: {"median": statistics.median(values), "max": max(values), "first": first[name],
                      "over": sum(value > LIMIT for value in values)} for name, values in ratios.items()}
    summary.update(steps=len(ratios["warm"]), iterations=iterations, builds=builds)
    for name, label in (("warm", "warm start"), ("cold", "from zero")):
        figures = summary[name]
        print(f"{kind} ({label}): ratio over {summary['steps']} contact steps: median {figures['median']:.2f}, "
              f"max {figures['max']:.2f}, first contact step {figures['first']:.2f}; {figures['over']} above {LIMIT}")
    return summary


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenes", nargs="+", choices=SCENES, default=list(SCENES))
    parser.add_argument("--cells", type=int, default=8, help="cells per cube edge (default 8: 729 nodes a cube)")
    parser.add_argument("--steps", type=int, default=40, help="steps per scene")
    parser.add_argument("--dt", type=float, default=0.01, help="step [s]")
    args = parser.parse_args(argv)
    results = {kind: run(kind, cells=args.cells, steps=args.steps, dt=args.dt) for kind in args.scenes}
    print(f"\nimplicit Euler, AMG-CG defaults, dt = {args.dt:g} s; CG iterations with contact / without, the same "
          "step")
    print(f"{'':22} {'warm start (the step)':^27}  {'from zero':^27}  {'the run, all steps':^18}")
    print(f"{'scene':>8} {'contact steps':>13}" + f" {'median':>7} {'max':>6} {'first':>6} {'> 1.5':>5}" * 2
          + f"  {'CG iterations':>13} {'builds':>6}")
    for kind, summary in results.items():
        if summary:
            print(f"{kind:>8} {summary['steps']:13d}" + "".join(
                f" {figures['median']:7.2f} {figures['max']:6.2f} {figures['first']:6.2f} {figures['over']:5d}"
                for figures in (summary["warm"], summary["cold"]))
                + f"  {summary['iterations']:13d} {summary['builds']:6d}")


if __name__ == "__main__":
    main()
