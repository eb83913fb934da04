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


@pytest.mark.xfail(strict=True, reason="issue 11's deflection goal is not met: the capsule reads 1.045 of the "
                   "reference at nu 0.3 and the torus 0.968 at 0.49, and no single alpha brings both within 3% "
                   "(docs/ladder-studies.md, 'The default alpha'). When this passes, make it a plain test")
def test_smoothed_rung_meets_the_deflection_goal_on_every_held_out_shape():
    """The issue's goal itself, beside the regression floor above: within 3% of the reference on every shape."""
    misses = {(name, nu): _ratios(name, nu)["smoothed"] - 1 for name in HELDOUT_CASE_NAMES for nu in (0.3, 0.49)}
    # 3% is the goal (against converged P2; the same-mesh Taylor-Hood reference here is within 0.5-1.4% of
    # it on the torus, capsule and L-bracket, module docstring).
    assert max(abs(miss) for miss in misses.values()) < 0.03, misses


@pytest.mark.parametrize("name", HELDOUT_CASE_NAMES)
def test_no_locking_from_nu_045_to_0499(name):
    """The issue's goal: the deflection ratio moves by less than 3% from nu 0.45 to 0.499 (P1 loses over 40%).
    Measured with volume on node pairs given to the free nodes (the scene's supports) and lambda above 20 mu on
    merged pairs (volspring.ladder.PAIR_BULK_CAP): torus +0.4%, capsule +0.5%, L-bracket -0.3%, bunny -0.7%. With
    all of lambda on pairs the bunny moved -5.0% (the others -0.8%, -2.5%, -1.5%), and with volume on single nodes
    the torus -4.2% and the L-bracket -6.9% against the converged reference."""
    drift = _ratios(name, 0.499)["smoothed"] / _ratios(name, 0.45)["smoothed"] - 1
    assert abs(drift) < 0.03, drift


@functools.lru_cache(maxsize=None)
def _volume_comparison(name, nu, folder):
    from validation.compare import compare_static

    case = build_heldout_case(name, nu=nu)
    return compare_static(case, rules=(), models=("springs+volume", "smoothed"), elements=("TH",),
                          folder=folder).results


@pytest.mark.parametrize("name, nu", [("bunny_gravity", 0.45), ("bunny_gravity", 0.49), ("l_bracket_gravity", 0.49)])
def test_volume_change_matches_the_reference_where_it_is_not_a_cancellation(name, nu, tmp_path_factory):
    """The issue's goals: the smoothed rung's volume change within 5% of the reference's, the volume rung's within 10%
    at nu 0.49, as the report measures them (validation.compare): a rung's moved mesh (it is geometrically exact)
    against Taylor-Hood's integral of div u. Taylor-Hood's is converged there: the bunny refined once moves it by
    0.4% and 0.7% (scratch study, stop 33). Measured: smoothed 1.002 and 1.000 on the bunny, 0.994 on the L-bracket;
    springs+volume 1.017, 1.045 and 1.041. Against Taylor-Hood's moved mesh instead, which grows by O(rotation^2)
    where the ears turn (1.48 and 3.46 times its net change at nu 0.45 and 0.49), the bunny read 0.68 at nu 0.45
    and none at 0.49; the integral of div u of the rung's own answer, which shrinks by as much where it turns, read
    1.06 and 1.24."""
    results = _volume_comparison(name, nu, str(tmp_path_factory.getbasetemp() / "fem-cache"))
    smoothed, volume_rung = results["models"]["smoothed"], results["models"]["springs+volume"]
    assert abs(smoothed["volume_change_error_vs_fem"]) < 0.05, smoothed["volume_change_error_vs_fem"]
    if nu == 0.49:
        assert abs(volume_rung["volume_change_error_vs_fem"]) < 0.10, volume_rung["volume_change_error_vs_fem"]


@pytest.mark.parametrize("name", ["torus_gravity", "capsule_gravity"])
def test_bending_shapes_have_no_volume_reference(name, tmp_path_factory):
    """The torus and the capsule bend: Taylor-Hood's net volume change is 0.1-0.5% of its gross one, and no two
    references agree on it (same-mesh P2 0.29-1.28 times it; the capsule refined once 0.54-0.59 times), so the
    comparison gives no relative error there rather than one that measures the reference."""
    results = _volume_comparison(name, 0.49, str(tmp_path_factory.getbasetemp() / "fem-cache"))
    assert results["models"]["smoothed"]["volume_change_error_vs_fem"] is None
    fem = results["fem"]["TH"]
    assert abs(fem["volume_change_m3"]) < 0.01 * fem["gross_volume_change_m3"]
