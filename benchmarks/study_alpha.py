"""The smoothed rung's alpha on the held-out shapes: the study behind ``DEFAULT_ALPHA``.

For each held-out case (torus, capsule, L-bracket, bunny: ``validation.heldout``) and nu, prints the
displacement of the node the reference moves most (along its direction there) as a ratio to the
reference, for P2, P1, springs, springs+volume and the smoothed rung at each alpha, and the volume change as a
ratio to the reference's: a rung's is its moved mesh's volume (the rungs are geometrically exact, so a rotation adds
nothing), the reference's its integral of div u. (The integral of div u of a rung's nonlinear answer would shrink by
O(rotation^2) where the body turns: on the bunny it read 1.24 and 3.33 times Taylor-Hood's at nu 0.49 and 0.499,
where the moved volume reads 1.000 and 0.999.) The reference is Taylor-Hood P2-P1
on the same mesh (``--reference TH``, the default): it does not lock, and it is within 0.5-1.4% of the
converged answer on the torus, capsule and L-bracket (3.5% on the coarse bunny), where same-mesh P2 is
1-3% too stiff at nu 0.45 and 2-5% at 0.499 (``benchmarks/study_locking.py``). ``--reference P2``
gives the earlier study's numbers. In bending the net volume change is a cancellation
(:func:`validation.fem.volume_change_cancels`: the torus and the capsule), and its ratio is printed as "cancels".

Run::

    OMP_NUM_THREADS=1 python benchmarks/study_alpha.py --alpha 0.55 0.6 0.65 0.7 --nu 0.25 0.3 0.45 0.49 0.499

This is a study script, not a test (about 2 minutes). ``--workers N`` runs the shapes and Poisson ratios at the same
time on a local Dask cluster, through the path sweeps take (:func:`volspring.sweep.run_calls`); the lines are the
same.
"""

from __future__ import annotations

import argparse

import numpy as np


def main():
    from validation.heldout import HELDOUT_CASE_NAMES
    from volspring.sweep import run_calls, sweep_client

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--alpha", type=float, nargs="+", default=[0.6, 0.65, 0.7])
    parser.add_argument("--nu", type=float, nargs="+", default=[0.3, 0.49])
    parser.add_argument("--reference", choices=("TH", "P2"), default="TH")
    parser.add_argument("--workers", type=int, default=0,
                        help="shapes x nu at the same time on a local Dask cluster of N processes, as volspring "
                             "sweep runs its runs (default 0: one after the other here)")
    args = parser.parse_args()
    calls = {f"{name}-{nu:g}": (study_line, (name, nu, tuple(args.alpha), args.reference), {})
             for name in HELDOUT_CASE_NAMES for nu in args.nu}
    if args.workers:
        with sweep_client(workers=args.workers) as client:
            lines = run_calls(calls, client=client)
    else:  # printed as each is done
        lines = run_calls(calls, on_result=lambda key, line, done, total: print(line, flush=True))
    if args.workers:
        print("\n".join(lines.values()), flush=True)


def study_line(name: str, nu: float, alphas: tuple, reference_element: str) -> str:
    """One line of the study: a held-out shape at one nu, every element and rung as a ratio to the reference."""
    from validation.fem import solve_fem_static, volume_change_cancels
    from validation.heldout import build_heldout_case
    from validation.springs import deformed_volume_change, spring_static
    from volspring import Model

    case = build_heldout_case(name, nu=nu)
    fem = {element: solve_fem_static(case.mesh, case.material_tuple, element=element, **case.fem_arguments())
           for element in ("TH", "P2", "P1")}
    best = fem[reference_element]
    k = int(np.argmax(np.linalg.norm(best.displacement, axis=1)))
    direction = best.displacement[k] / np.linalg.norm(best.displacement[k])
    reference = best.displacement[k] @ direction
    cancels = volume_change_cancels(best.volume_change, best.gross_volume_change)
    line = f"{name:18s} nu {nu:5.3f} nodes {case.mesh.node_count:4d}" + "".join(
        f" {element} {fem[element].displacement[k] @ direction / reference:.3f}"
        for element in ("TH", "P2", "P1") if element != reference_element)
    rungs = [("springs", None), ("springs+volume", None)] + [("smoothed", a) for a in alphas]
    for rung, alpha in rungs:
        try:
            model = Model.from_mesh(case.mesh, case.material, model=rung, alpha=alpha)
        except ValueError:
            line += f" | {rung} refused"
            continue
        u = spring_static(case, model).displacement
        volume = "cancels" if cancels else f"{deformed_volume_change(case.mesh, u) / best.volume_change:.3g}"
        label = rung if alpha is None else f"a={alpha:g}"
        line += f" | {label} {u[k] @ direction / reference:.3f} dV {volume}"
    return line


if __name__ == "__main__":
    main()
