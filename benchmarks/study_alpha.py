"""The smoothed rung's alpha against P2 on the held-out shapes: the study behind ``DEFAULT_ALPHA``.

For each held-out case (torus, capsule, L-bracket, bunny: ``validation.heldout``) and nu, prints the
displacement of the node P2 moves most (along P2's direction there) as a ratio to same-mesh P2, for
P1, springs, springs+volume and the smoothed rung at each alpha, and the linearised volume change
(integral of div u) as a ratio to P2's. In bending the net volume change nearly cancels, so its ratio
is only meaningful where the body is compressed as a whole (the bunny on its base).

Run::

    OMP_NUM_THREADS=1 python benchmarks/study_alpha.py --alpha 0.6 0.65 0.7 0.75 --nu 0.3 0.45 0.49 0.499

This is a study script, not a test (about 2 minutes).
"""

from __future__ import annotations

import argparse

import numpy as np


def main():
    from validation.fem import solve_fem_static
    from validation.heldout import HELDOUT_CASE_NAMES, build_heldout_case
    from validation.springs import spring_static
    from volspring import Model
    from volspring.elements.tet_kinematics import TetGradients

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--alpha", type=float, nargs="+", default=[0.6, 0.65, 0.7])
    parser.add_argument("--nu", type=float, nargs="+", default=[0.3, 0.49])
    args = parser.parse_args()
    for name in HELDOUT_CASE_NAMES:
        for nu in args.nu:
            case = build_heldout_case(name, nu=nu)
            # AMG-CG to 1e-10: the direct solve's residual check trips on P2 at nu 0.499 (condition number).
            solve = dict(case.fem_arguments(), solver="amg", tolerance=1e-10)
            p2 = solve_fem_static(case.mesh, case.material_tuple, element="P2", **solve)
            p1 = solve_fem_static(case.mesh, case.material_tuple, element="P1", **solve)
            k = int(np.argmax(np.linalg.norm(p2.displacement, axis=1)))
            direction = p2.displacement[k] / np.linalg.norm(p2.displacement[k])
            reference = p2.displacement[k] @ direction
            kinematics = TetGradients.at_rest(case.mesh.points, case.mesh.tets)
            line = f"{name:18s} nu {nu:5.3f} nodes {case.mesh.node_count:4d} P1 {p1.displacement[k] @ direction / reference:.3f}"
            rungs = [("springs", None), ("springs+volume", None)] + [("smoothed", a) for a in args.alpha]
            for rung, alpha in rungs:
                try:
                    model = Model.from_mesh(case.mesh, case.material, model=rung, alpha=alpha)
                except ValueError:
                    line += f" | {rung} refused"
                    continue
                u = spring_static(case, model).displacement
                volume = float(kinematics.volumes @ np.trace(kinematics.deformation(u), axis1=1, axis2=2))
                label = rung if alpha is None else f"a={alpha:g}"
                line += f" | {label} {u[k] @ direction / reference:.3f} dV {volume / p2.volume_change:.3g}"
            print(line, flush=True)


if __name__ == "__main__":
    main()
