"""The ladder on shapes the project's beams never saw (torus, capsule, L-bracket, the bunny).

Same-mesh P2 is the reference; on these meshes P1 is 33-66% short of it (tests/test_heldout_cases.py).
The bounds below are what the smoothed rung achieves today (benchmarks/study_alpha.py), a regression
floor: the issue's goal (3%) is not met on every shape yet, see the README's ladder section.
"""

import numpy as np
import pytest

from validation.fem import solve_fem_static
from validation.heldout import HELDOUT_CASE_NAMES, build_heldout_case
from validation.springs import spring_static
from volspring import Model


def _ratios(name, nu):
    case = build_heldout_case(name, nu=nu)
    p2 = solve_fem_static(case.mesh, case.material_tuple, element="P2", **case.fem_arguments())
    k = int(np.argmax(np.linalg.norm(p2.displacement, axis=1)))
    direction = p2.displacement[k] / np.linalg.norm(p2.displacement[k])
    ratios = {}
    for rung in ("springs", "smoothed"):
        u = spring_static(case, Model.from_mesh(case.mesh, case.material, model=rung)).displacement
        ratios[rung] = float(u[k] @ direction / (p2.displacement[k] @ direction))
    return ratios


@pytest.mark.parametrize("name", HELDOUT_CASE_NAMES)
@pytest.mark.parametrize("nu", [0.3, 0.49])
def test_smoothed_rung_tracks_p2_where_springs_do_not(name, nu):
    ratios = _ratios(name, nu)
    # Measured at alpha 0.65: 0.958-1.052 over these 8 runs; springs 0.67-0.81.
    assert abs(ratios["smoothed"] - 1) < 0.06
    assert abs(ratios["smoothed"] - 1) < 0.5 * abs(ratios["springs"] - 1)
