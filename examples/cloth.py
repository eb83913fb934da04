"""A flag pinned at its two top corners, in gravity and a gusty wind, held to 10 % stretch by Provot's limit.

The flag is built by :func:`volspring.structures.cloth_grid` (structural, shear and bend springs after
Provot 1995, stiffness from the membrane's E t), pinned at the two top corners, and stepped by implicit
Euler with gravity, a gusting :class:`~volspring.Wind` across it and Provot's strain limit
(:func:`volspring.structures.cloth_strain_limit`) after every step. Output in OUTPUT:

- ``cloth_surface.pvd``: the cloth's triangles (one VTU per frame, point data ``displacement`` and
  ``velocity``): open it in ParaView;
- ``cloth_springs.pvd``: every spring as a line, coloured by ``strain`` and ``kind``;
- ``cloth_0000.obj`` ... and ``cloth.pc2``: the triangle surface for Blender (import the first OBJ with
  Forward Y, Up Z, keep vertex order; add a Mesh Cache modifier reading ``cloth.pc2``).

Run::

    python examples/cloth.py OUTPUT            # 30 x 20 cells, 2 s simulated, 51 frames
    python examples/cloth.py OUTPUT --quick    # 12 x 8 cells, 0.2 s, for the tests
"""

from __future__ import annotations

import argparse
import time

import numpy as np

#: Default and quick settings: cells along the width and height, simulated time [s], step [s], frame interval [s].
SETTINGS = {
    "default": {"nx": 30, "ny": 20, "duration": 2.0, "dt": 5e-3, "frame_dt": 0.04},
    "quick": {"nx": 12, "ny": 8, "duration": 0.2, "dt": 1e-2, "frame_dt": 0.05},
}

#: A light flag: 1.5 m by 1 m, 150 g/m^2, a soft membrane E t = 200 N/m, limited to 10 % stretch.
WIDTH, HEIGHT, AREAL_DENSITY, MEMBRANE, TAU = 1.5, 1.0, 0.15, 200.0, 0.1


def build(*, nx, ny):
    """The flag hanging in the xz plane from its top edge at z = 0, its triangles, and its two top corners."""
    from volspring.structures import cloth_grid, sheet_grid

    shape = {"width": WIDTH, "height": HEIGHT, "nx": nx, "ny": ny, "axes": ((1, 0, 0), (0, 0, -1))}
    _, triangles = sheet_grid(**shape)
    flag = cloth_grid(**shape, areal_density=AREAL_DENSITY, membrane_stiffness=MEMBRANE, bend_stiffness=0.5,
                      damping=0.01)
    return flag, triangles, np.array([0, nx])


def run(output, *, quick=False):
    """Simulate and write the files; returns ``(model, SimulationResult)``."""
    from volspring import Gravity, Pins, Scene, Wind
    from volspring.output import BlenderWriter, ParaViewWriter
    from volspring.output.blender import BoundarySurface
    from volspring.simulate import simulate
    from volspring.structures import cloth_strain_limit

    settings = SETTINGS["quick" if quick else "default"]
    flag, triangles, corners = build(nx=settings["nx"], ny=settings["ny"])
    # Wind across the flag (+y, a little along it), 3 m/s with a 1 Hz gust; coupling rate 2 / s.
    wind = Wind(direction=(0.3, 1.0, 0.0), speed=3.0, rate=2.0, gusts=[(1.5, 1.0, 0.0)])
    scene = Scene(flag, forces=[Gravity(), wind], pins=Pins(corners),
                  constraints=[cloth_strain_limit(flag, TAU, iterations=30, tolerance=1e-3)])
    writers = [ParaViewWriter(output, flag, name="cloth", triangles=triangles),
               BlenderWriter(output, BoundarySurface.from_triangles(triangles, flag.node_count), name="cloth")]

    def write(frame, state):
        for writer in writers:
            writer(frame, state)

    result = simulate(scene, "implicit_euler", duration=settings["duration"], dt=settings["dt"],
                      frame_dt=settings["frame_dt"], callback=write)
    return flag, result


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("output", help="folder for cloth_surface.pvd, cloth_springs.pvd, their VTU frames, OBJ and PC2")
    parser.add_argument("--quick", action="store_true", help="a coarse flag and a short run (for tests)")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    flag, result = run(args.output, quick=args.quick)
    from volspring.springs import spring_strains

    print(f"{flag.node_count} nodes, {flag.spring_count} springs: {result.steps_taken} steps, {result.frame_count} "
          f"frames in {time.perf_counter() - start:.1f} s; largest spring strain "
          f"{spring_strains(flag, result.state.x).max():.3f}")
    print(f"open {args.output}/cloth_surface.pvd in ParaView")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
