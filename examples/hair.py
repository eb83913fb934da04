"""Curly hair: a few helical strands clamped at their roots, falling under gravity and swaying.

Each strand is built by :func:`volspring.structures.hair` (stretch springs, angle springs for EI,
dihedral springs for GJ, rest shape a helix from :func:`volspring.structures.strand_points`), the
strands joined into one model, the two root nodes of each pinned, and the scene stepped by implicit
Euler with gravity and air drag. Output in OUTPUT: ``hair_springs.pvd`` (the segments as lines, one
VTU per frame) and ``hair.pc2`` (node positions per frame for Blender).

Run::

    python examples/hair.py OUTPUT            # 5 strands, 1 s simulated, 51 frames
    python examples/hair.py OUTPUT --quick    # 2 strands, 0.1 s, for the tests
"""

from __future__ import annotations

import argparse
import time

import numpy as np

#: Default and quick settings: strands, nodes per strand, simulated time [s], step [s], frame interval [s].
SETTINGS = {
    "default": {"strands": 5, "count": 61, "duration": 1.0, "dt": 2e-3, "frame_dt": 0.02},
    "quick": {"strands": 2, "count": 31, "duration": 0.1, "dt": 5e-3, "frame_dt": 0.05},
}

#: A thick curly hair: E = 4 GPa, radius 40 um, 1300 kg/m^3, 10 cm long; curl radius 5 mm, pitch 10 mm.
E, RADIUS, DENSITY, LENGTH = 4e9, 40e-6, 1300.0, 0.1


class Points:
    """The nodes themselves as a Blender point set (no faces): ``BlenderWriter(..., obj=False)``."""

    faces = None

    def deform(self, x):
        return np.asarray(x, dtype=np.float64)


def build(*, strands, count):
    """One model of ``strands`` curls rooted 1 cm apart along x, and the root nodes (two per strand)."""
    from volspring import Model
    from volspring.elements import AngleSprings, DihedralSprings, Springs
    from volspring.structures import hair, strand_points

    area, inertia = np.pi * RADIUS**2, np.pi * RADIUS**4 / 4
    parts = [hair(strand_points([0.01 * s, 0, 0], [0, 0.3, -1], LENGTH, count, curl_radius=5e-3,
                                curl_pitch=10e-3),
                  bending_stiffness=E * inertia, axial_stiffness=E * area, linear_density=DENSITY * area)
             for s in range(strands)]
    # Join the strands: offset each one's node indices and concatenate every element set's arrays.
    offsets = np.arange(strands) * count
    n = strands * count
    sets = {type(element_set): [] for element_set in parts[0].elements}
    for offset, part in zip(offsets, parts):
        for element_set in part.elements:
            sets[type(element_set)].append((offset, element_set))
    springs = sets[Springs]
    elements = [Springs(n, np.concatenate([o + s.pairs for o, s in springs]),
                        np.concatenate([s.stiffness for _, s in springs]),
                        np.concatenate([s.damping for _, s in springs]),
                        np.concatenate([s.rest_lengths for _, s in springs]), 0)]
    angles = sets[AngleSprings]
    elements.append(AngleSprings(n, np.concatenate([o + a.triples for o, a in angles]),
                                 np.concatenate([a.stiffness for _, a in angles]),
                                 np.concatenate([a.rest_angles for _, a in angles])))
    if DihedralSprings in sets:
        twists = sets[DihedralSprings]
        elements.append(DihedralSprings(n, np.concatenate([o + t.quads for o, t in twists]),
                                        np.concatenate([t.stiffness for _, t in twists]),
                                        np.concatenate([t.rest_angles for _, t in twists])))
    model = Model(np.concatenate([p.rest_positions for p in parts]), np.concatenate([p.masses for p in parts]),
                  elements)
    roots = (offsets[:, None] + np.arange(2)).ravel()
    return model, roots


def run(output, *, quick=False):
    """Simulate and write the files; returns ``(model, SimulationResult)``."""
    from volspring import Drag, Gravity, Pins, Scene
    from volspring.output import BlenderWriter, ParaViewWriter
    from volspring.simulate import simulate

    settings = SETTINGS["quick" if quick else "default"]
    model, roots = build(strands=settings["strands"], count=settings["count"])
    scene = Scene(model, forces=[Gravity(), Drag(rate=5.0)], pins=Pins(roots))
    paraview = ParaViewWriter(output, model, name="hair")
    blender = BlenderWriter(output, Points(), name="hair", obj=False)

    def write(frame, state):
        paraview(frame, state)
        blender(frame, state)

    result = simulate(scene, "implicit_euler", duration=settings["duration"], dt=settings["dt"],
                      frame_dt=settings["frame_dt"], callback=write)
    return model, result


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("output", help="folder for hair_springs.pvd, its VTU frames and hair.pc2")
    parser.add_argument("--quick", action="store_true", help="fewer strands and a short run (for tests)")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    model, result = run(args.output, quick=args.quick)
    print(f"{model.node_count} nodes: {result.steps_taken} steps, {result.frame_count} frames in "
          f"{time.perf_counter() - start:.1f} s")
    print(f"open {args.output}/hair_springs.pvd in ParaView")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
