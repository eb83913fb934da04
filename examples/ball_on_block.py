"""A soft ball dropped on a soft block, written for ParaView.

Both bodies are meshed by gmsh, assembled into one model (:meth:`volspring.Model.from_bodies`), and
stepped by implicit Euler with gravity and the penalty contact of consistent penetration depths
(:class:`ContactForce`, whose Jacobian enters the implicit system). The block is pinned at its
bottom face. Output: ``OUTPUT/ball_on_block.pvd`` with one VTU per frame (tets, point data
``displacement`` and ``velocity``, cell data ``volume_ratio``).

Run::

    python examples/ball_on_block.py OUTPUT            # 1 s simulated, 51 frames, about 15 s of wall time
    python examples/ball_on_block.py OUTPUT --quick    # coarse meshes, 0.15 s simulated, 2 s

then open ``OUTPUT/ball_on_block.pvd`` in ParaView (File > Open), press Apply and play; colour by
``displacement`` or ``volume_ratio`` (the points are already the deformed positions: no warp needed).
"""

from __future__ import annotations

import argparse
import logging
import time
from dataclasses import dataclass

import numpy as np

#: Default and quick settings: mesh edge length [m], simulated time [s], step [s], frame interval [s].
SETTINGS = {
    "default": {"size": 0.02, "duration": 1.0, "dt": 2e-3, "frame_dt": 0.02},
    "quick": {"size": 0.035, "duration": 0.15, "dt": 5e-3, "frame_dt": 0.025},
}


@dataclass
class BallOnBlock:
    """The scene and what a caller checks: the model of both bodies (block 0, ball 1), its initial
    velocities, the contact force, the ball's weight."""

    scene: object
    model: object
    velocities: object
    contact: object
    ball_weight: float


def build(*, size, radius=0.05, block=(0.2, 0.2, 0.06), gap=0.01, ball_material=None, block_material=None,
          stiffness_factor=1.0, friction=0.5, damping_ratio=0.05):
    """The ball above the block, the block pinned at its bottom face, gravity and contact.

    Parameters
    ----------
    size : float -- target tet edge length of both meshes [m]
    radius : float -- ball radius [m]
    block : (3,) float -- block dimensions [m]; its top face is at z = 0
    gap : float -- initial distance between the ball and the block [m]
    ball_material, block_material : Material, optional -- default E = 1e5 Pa, nu = 0.3, 1000 kg/m^3
    stiffness_factor : float -- alpha of the contact stiffness rule k_c = alpha E_eff l
    friction : float -- Coulomb coefficient between ball and block (frictionless contact on coarse
        meshes lets the ball wander: the interpolated normals are not exactly vertical)
    damping_ratio : float -- spring damping ratio of both bodies

    Returns
    -------
    BallOnBlock
    """
    from meshing.shapes import box, sphere
    from meshing.tetrahedralize import tetrahedralize
    from volspring import Gravity, Material, Model, Pins, Scene
    from volspring.bodies import Body, initial_velocities
    from volspring.collision import ContactForce

    soft = Material(E=1e5, nu=0.3, density=1000.0)
    ball_material = ball_material or soft
    block_material = block_material or soft
    ball = tetrahedralize(sphere(radius), size=size, seed=1)
    slab = tetrahedralize(box(*block), size=size, seed=1)
    bodies = [
        Body(slab, block_material, translation=(0.0, 0.0, -block[2] / 2), damping_ratio=damping_ratio,
             name="block"),
        Body(ball, ball_material, translation=(0.0, 0.0, radius + gap), damping_ratio=damping_ratio, name="ball"),
    ]
    model = Model.from_bodies(bodies)
    block_nodes = model.body_nodes(0)
    bottom = block_nodes[model.rest_positions[block_nodes, 2] < -block[2] + 1e-9]
    contact = ContactForce(model, stiffness_factor=stiffness_factor, friction=friction)
    scene = Scene(model, forces=[Gravity(), contact], pins=Pins(bottom))
    weight = float(model.body_masses[1] * 9.81)
    return BallOnBlock(scene, model, initial_velocities(bodies, model), contact, weight)


def run(output, *, quick=False, size=None, duration=None, dt=None, frame_dt=None):
    """Simulate and write ``output/ball_on_block.pvd``; returns ``(BallOnBlock, SimulationResult)``."""
    from volspring.integrators import make_integrator
    from volspring.output import ParaViewWriter
    from volspring.simulate import simulate

    settings = dict(SETTINGS["quick" if quick else "default"])
    for key, value in (("size", size), ("duration", duration), ("dt", dt), ("frame_dt", frame_dt)):
        if value is not None:
            settings[key] = value
    setup = build(size=settings["size"])
    writer = ParaViewWriter(output, setup.model, name="ball_on_block", springs=False)
    result = simulate(setup.scene, make_integrator("implicit_euler"), duration=settings["duration"],
                      dt=settings["dt"], frame_dt=settings["frame_dt"], callback=writer,
                      state=setup.scene.initial_state(v=setup.velocities), guard="off")
    return setup, result


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("output", help="folder for ball_on_block.pvd and its VTU frames")
    parser.add_argument("--quick", action="store_true", help="coarse meshes and a short run (for tests)")
    parser.add_argument("--size", type=float, help="tet edge length [m]")
    parser.add_argument("--duration", type=float, help="simulated time [s]")
    parser.add_argument("--dt", type=float, help="time step [s]")
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.WARNING)
    start = time.perf_counter()
    setup, result = run(args.output, quick=args.quick, size=args.size, duration=args.duration, dt=args.dt)
    depth = setup.contact.contacts(result.state.x).max_depth
    edge = float(setup.contact.bodies.mean_edge_lengths.min())
    print(f"{setup.model}: {result.steps_taken} steps, {result.frame_count} frames in "
          f"{time.perf_counter() - start:.1f} s")
    print(f"deepest contact at the end: {depth * 1e3:.3f} mm = {depth / edge:.3f} edge lengths")
    print(f"open {args.output}/ball_on_block.pvd in ParaView")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
