"""A lattice bunny hanging by its ears: a regular grid of masses with structural, shear and bend springs.

The coarse Stanford bunny (tests/data/coarse_bunny.obj, read in millimetres: 16 cm across) is filled with
cubic cells (:func:`volspring.lattice.lattice_body`), the nodes of its top cells are pinned and the
rest sags under gravity, stepped by implicit Euler with damped springs. Its surface is anchored into the
lattice by trilinear weights, so the output shows the deformed bunny, not the grid.

Output in OUTPUT: ``bunny_0000.obj``, ... and ``bunny.pc2`` (the anchored surface per frame: open the OBJ
sequence in ParaView, or the first OBJ plus the PC2 cache in Blender, see :mod:`volspring.output.blender`),
and ``lattice_springs.pvd`` (the springs as lines, for ParaView).

Run::

    python examples/lattice_bunny.py OUTPUT            # 1 cm cells, 0.5 s simulated, 51 frames
    python examples/lattice_bunny.py OUTPUT --quick    # 2 cm cells, 0.05 s, for the tests
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

BUNNY = Path(__file__).resolve().parents[1] / "tests" / "data" / "coarse_bunny.obj"
#: Default and quick settings: cell size [m], simulated time [s], step [s], frame interval [s].
SETTINGS = {
    "default": {"cell_size": 0.01, "duration": 0.5, "dt": 2e-3, "frame_dt": 1e-2},
    "quick": {"cell_size": 0.02, "duration": 0.05, "dt": 5e-3, "frame_dt": 2.5e-2},
}
#: Soft rubber: sags by a few millimetres under its own weight.
MATERIAL = {"E": 5e4, "nu": 0.3, "density": 1000.0}


def run(output, *, quick=False):
    """Simulate and write the files; returns ``(LatticeBody, SimulationResult)``."""
    import numpy as np

    from meshing import load_surface
    from volspring import Gravity, Material, Pins, Scene
    from volspring.lattice import lattice_body
    from volspring.output import BlenderWriter, ParaViewWriter
    from volspring.simulate import simulate

    settings = SETTINGS["quick" if quick else "default"]
    surface = load_surface(BUNNY, units="mm")
    body = lattice_body(surface, settings["cell_size"], Material(**MATERIAL), damping_ratio=0.05)
    x = body.model.rest_positions
    top = x[:, 1] >= x[:, 1].max() - 0.5 * settings["cell_size"]  # the bunny's up is +y in its file
    scene = Scene(body.model, forces=[Gravity(g=(0.0, -9.81, 0.0))], pins=Pins(np.flatnonzero(top)))
    surface_writer = BlenderWriter(output, body.anchor, name="bunny")
    lattice_writer = ParaViewWriter(output, body.model, name="lattice")

    def write(frame, state):
        surface_writer(frame, state)
        lattice_writer(frame, state)

    result = simulate(scene, "implicit_euler", duration=settings["duration"], dt=settings["dt"],
                      frame_dt=settings["frame_dt"], callback=write)
    return body, result


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("output", help="folder for bunny_*.obj, bunny.pc2 and lattice_springs.pvd")
    parser.add_argument("--quick", action="store_true", help="a short, coarse run (for tests)")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    body, result = run(args.output, quick=args.quick)
    counts = body.family_counts()
    print(f"lattice of {body.lattice.cell_count} cells, {body.model.node_count} nodes, "
          + ", ".join(f"{count} {name}" for name, count in counts.items() if count)
          + f"; {result.steps_taken} steps, {result.frame_count} frames in {time.perf_counter() - start:.1f} s")
    print(f"open {args.output}/bunny_0000.obj (and bunny.pc2) in Blender, or the OBJ series in ParaView")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
