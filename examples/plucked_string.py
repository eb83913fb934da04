"""A plucked string: a taut chain of masses and springs, written for ParaView and Blender.

The string (:func:`volspring.structures.string`) is pinned at both ends under tension T, given a
triangular pluck, and stepped by implicit Euler. Its fundamental is f1 = c / (2 L), c = sqrt(T / rho).
Output in OUTPUT: ``string_springs.pvd`` (a VTU per frame: the springs as lines, point data
``displacement`` and ``velocity``, cell data ``strain``) and ``string.pc2`` (the node positions per frame,
Blender's point cache).

Run::

    python examples/plucked_string.py OUTPUT            # 0.2 s simulated (2 periods), 101 frames
    python examples/plucked_string.py OUTPUT --quick    # 0.02 s, for the tests

then open ``OUTPUT/string_springs.pvd`` in ParaView (File > Open, Apply, play).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

#: Default and quick settings: nodes, simulated time [s], step [s], frame interval [s].
SETTINGS = {
    "default": {"count": 51, "duration": 0.2, "dt": 2e-4, "frame_dt": 2e-3},
    "quick": {"count": 21, "duration": 0.02, "dt": 1e-3, "frame_dt": 5e-3},
}


class Points:
    """The nodes themselves as a Blender point set (no faces): ``BlenderWriter(..., obj=False)``."""

    faces = None

    def deform(self, x):
        return np.asarray(x, dtype=np.float64)


def run(output, *, quick=False, length=1.0, density=0.01, tension=10.0, pluck=0.02):
    """Simulate and write the files; returns ``(model, SimulationResult, f1 [Hz])``."""
    from volspring import Pins, Scene
    from volspring.output import BlenderWriter, ParaViewWriter
    from volspring.simulate import simulate
    from volspring.structures import string

    settings = SETTINGS["quick" if quick else "default"]
    count = settings["count"]
    model = string([0, 0, 0], [length, 0, 0], count=count, linear_density=density, axial_stiffness=1e4,
                   tension=tension)
    scene = Scene(model, pins=Pins([0, count - 1]))
    x = model.rest_positions.copy()
    x[:, 2] = pluck * (1 - np.abs(2 * x[:, 0] / length - 1))  # triangular pluck at the middle
    paraview = ParaViewWriter(output, model, name="string")
    blender = BlenderWriter(output, Points(), name="string", obj=False)

    def write(frame, state):
        paraview(frame, state)
        blender(frame, state)

    result = simulate(scene, "implicit_euler", duration=settings["duration"], dt=settings["dt"],
                      frame_dt=settings["frame_dt"], callback=write, state=scene.initial_state(x=x))
    return model, result, np.sqrt(tension / density) / (2 * length)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("output", help="folder for string_springs.pvd, its VTU frames and string.pc2")
    parser.add_argument("--quick", action="store_true", help="a short, coarse run (for tests)")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    model, result, f1 = run(args.output, quick=args.quick)
    print(f"{model.node_count} nodes, f1 = c / (2 L) = {f1:.3g} Hz: {result.steps_taken} steps, "
          f"{result.frame_count} frames in {time.perf_counter() - start:.1f} s")
    print(f"open {args.output}/string_springs.pvd in ParaView")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
