"""Cost of an implicit contact step on each rung: a soft cube pressed into a pinned block, from one run.

Two bodies (``Body(model=rung)``: a 12 x 12 x 6-cell block 0.1 x 0.1 x 0.05 m pinned at its bottom and a 6^3-cell
cube of 0.04 m resting on it under gravity, E = 1e5 Pa, nu = 0.3) stepped by implicit Euler at 4 ms with
``ContactForce``; after three warm-up steps the script prints per rung the mean wall time of ten steps, its ratio
to the springs' step, the CG iterations and the contacts at the end.

Run (one thread)::

    OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python benchmarks/bench_contact_rungs.py

This is a script, not a test.
"""

from __future__ import annotations

import time

import numpy as np


def scene_for(rung):
    from meshing import structured_box
    from volspring import Gravity, Material, Model, Pins, Scene
    from volspring.bodies import Body
    from volspring.collision import ContactForce

    soft = Material(E=1e5, nu=0.3, density=1000.0)
    block = structured_box((12, 12, 6), (0.1, 0.1, 0.05))
    cube = structured_box((6, 6, 6), (0.04, 0.04, 0.04))
    model = Model.from_bodies([Body(block, soft, model=rung, damping_ratio=0.3),
                               Body(cube, soft, model=rung, damping_ratio=0.3, translation=(0.0312, 0.0291, 0.0505))])
    contact = ContactForce(model, friction=0.5)
    nodes = model.body_nodes(0)
    pins = Pins(nodes[model.rest_positions[nodes, 2] < 1e-9])
    return Scene(model, forces=[Gravity(), contact], pins=pins), contact


def main():
    from volspring.integrators.implicit import ImplicitEuler
    from volspring.ladder import MODELS

    base = None
    print(f"{'rung':16s} {'ms/step':>9s} {'x springs':>10s} {'CG its':>7s} {'contacts':>9s}")
    for rung in MODELS:
        scene, contact = scene_for(rung)
        integrator = ImplicitEuler()
        state = scene.initial_state()
        for _ in range(3):
            state = integrator.step(scene, state, 4e-3)
        iterations, start = [], time.perf_counter()
        for _ in range(10):
            state = integrator.step(scene, state, 4e-3)
            iterations.append(integrator.last_solve.iterations)
        seconds = (time.perf_counter() - start) / 10
        base = seconds if base is None else base
        print(f"{rung:16s} {1e3 * seconds:9.1f} {seconds / base:10.2f} {np.mean(iterations):7.1f} "
              f"{contact.contacts(state.x).count:9d}")


if __name__ == "__main__":
    main()
