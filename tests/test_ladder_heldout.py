"""The ladder on shapes the project's beams never saw (torus, capsule, L-bracket, the bunny).

The reference is Taylor-Hood P2-P1 on the same mesh (``validation.fem``, ``element="TH"``): it does not
lock, and it is within 0.5-1.4% of the converged answer on the torus, capsule and L-bracket (3.5% on the
coarse bunny), where same-mesh P2 is itself 1-5% too stiff at nu 0.45-0.499 (benchmarks/study_locking.py).
On these meshes P1 is 33-66% short of it (tests/test_heldout_cases.py). The deflection bounds are what the
smoothed rung achieves today (benchmarks/study_alpha.py), a regression floor: the issue's 3% goal is not
met on every shape. The locking goal is met on every shape and checked on each.
"""

import functools

import numpy as np
import pytest

from validation.fem import solve_fem_static
from validation.heldout import HELDOUT_CASE_NAMES, build_heldout_case
from validation.springs import spring_static
from volspring import Model


@functools.lru_cache(maxsize=None)
def _ratios(name, nu):
    case = build_heldout_case(name, nu=nu)
    reference = solve_fem_static(case.mesh, case.material_tuple, element="TH", **case.fem_arguments()).displacement
    k = int(np.argmax(np.linalg.norm(reference, axis=1)))
    direction = reference[k] / np.linalg.norm(reference[k])
    ratios = {}
    for rung in ("springs", "smoothed"):
        u = spring_static(case, Model.from_mesh(case.mesh, case.material, model=rung)).displacement
        ratios[rung] = float(u[k] @ direction / (reference[k] @ direction))
    return ratios


@pytest.mark.parametrize("name", HELDOUT_CASE_NAMES)
@pytest.mark.parametrize("nu", [0.3, 0.49])
def test_smoothed_rung_tracks_the_reference_where_springs_do_not(name, nu):
    ratios = _ratios(name, nu)
    # Measured at alpha 0.65 with the volume domains given to the free nodes and lambda above 20 mu on merged pairs:
    # 0.968-1.045 over these 8 runs (capsule 1.045 at nu 0.3, torus 0.968 at 0.49; 0.961-1.045 with all of lambda
    # on pairs, 0.958-1.063 when clamped nodes kept domains); springs 0.65-0.82.
    # 0.05 is that worst miss, rounded up: a regression floor, not the 3% goal.
    assert abs(ratios["smoothed"] - 1) < 0.05
    assert abs(ratios["smoothed"] - 1) < 0.4 * abs(ratios["springs"] - 1)


@pytest.mark.parametrize("name", HELDOUT_CASE_NAMES)
def test_no_locking_from_nu_045_to_0499(name):
    """The issue's goal: the deflection ratio moves by less than 3% from nu 0.45 to 0.499 (P1 loses over 40%).
    Measured with volume on node pairs given to the free nodes (the scene's supports) and lambda above 20 mu on
    merged pairs (volspring.ladder.PAIR_BULK_CAP): torus +0.4%, capsule +0.5%, L-bracket -0.3%, bunny -0.7%. With
    all of lambda on pairs the bunny moved -5.0% (the others -0.8%, -2.5%, -1.5%), and with volume on single nodes
    the torus -4.2% and the L-bracket -6.9% against the converged reference."""
    drift = _ratios(name, 0.499)["smoothed"] / _ratios(name, 0.45)["smoothed"] - 1
    assert abs(drift) < 0.03, drift
