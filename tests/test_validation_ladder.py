"""The ladder in the validation: every rung on a case, its errors, constants, cost and matrix size; the report
puts it first; ``--model`` selects rungs."""

import json

import numpy as np
import pytest

import validation.report.runner
from validation.cases import cantilever_gravity, uniaxial_compression
from validation.cli import main
from validation.compare import compare_static
from validation.ladder import parse_models, run_ladder, rung_constants
from validation.springs import deformed_volume_change, spring_static
from volspring import Model, kernels
from validation.springs import VALIDATED_MODELS
from volspring.ladder import MODELS


@pytest.fixture
def cache_folder(tmp_path):
    return tmp_path / "fem-cache"


@pytest.fixture(scope="module")
def cube_ladder(tmp_path_factory):
    """Every rung on the 2^3 compressed cube at nu 0.3 (27 nodes): about 1 s."""
    case = uniaxial_compression(cells=2, nu=0.3)
    return case, run_ladder([case], cells=2, steps=2, folder=tmp_path_factory.mktemp("cache"))


def test_every_rung_has_a_row_with_its_errors_cost_and_matrix_size(cube_ladder):
    case, ladder = cube_ladder
    rows = {row["rung"]: row for row in ladder["rows"]}
    assert list(rows) == list(VALIDATED_MODELS) and ladder["models"] == list(VALIDATED_MODELS)
    for row in rows.values():
        assert row["case"] == "uniaxial_compression" and row["node_count"] == case.mesh.node_count == 27
        for key in ("tip_deflection_error", "volume_change_error_vs_fem", "E_effective_ratio", "nu_effective",
                    "step_seconds", "step_cost_vs_springs"):
            assert np.isfinite(row[key]), key
        assert row["nonzero_count"] == 9 * row["block_count"]
        # Unknowns: 3 per node with a free component; held whole are only the two nodes on the edge y = z = 0
        # (planes y = 0 and z = 0 slide, x = 0 and x = 1 hold x), 25 of the 27 nodes stay.
        assert row["unknown_count"] == 3 * (case.mesh.node_count - 2)
    assert rows["springs"]["step_cost_vs_springs"] == 1.0  # the baseline, divided by itself
    assert ladder["kernels"] == kernels.active()  # the code that ran the timed steps (it sets their cost)
    # Stencils over the free nodes: springs couple the 1-ring (a diagonal block per node, two per edge); a
    # nodal strain term couples the 2-ring, a superset.
    points, edges = case.mesh.points, case.mesh.edges
    free = ~((points[:, 1] == 0) & (points[:, 2] == 0) & np.isin(points[:, 0], (0.0, 1.0)))
    assert rows["springs"]["block_count"] == free.sum() + 2 * free[edges].all(axis=1).sum()
    for rung in ("springs+volume", "smoothed"):
        assert rows[rung]["block_count"] > rows["springs"]["block_count"]
    assert rows["springs+volume"]["block_count"] == rows["smoothed"]["block_count"]


def test_smoothed_rung_has_the_asked_constants_and_beats_springs_on_the_cube(cube_ladder):
    _, ladder = cube_ladder
    rows = {row["rung"]: row for row in ladder["rows"]}
    # The smoothed rung passes the patch test: exact E and nu on any mesh, up to the O(strain) = 1e-3
    # nonlinearity of the uniaxial test (measured 3e-4 at nu 0.49); 0.01 leaves room for solver tolerance.
    assert rows["smoothed"]["nu_effective"] == pytest.approx(0.3, abs=0.01)
    assert rows["smoothed"]["E_effective_ratio"] == pytest.approx(1.0, abs=0.01)
    # Uniaxial stress is a linear field, which the smoothed rung represents exactly: measured 0.2% (tip) and
    # 0.3% (volume) from P2 on this 2^3 cube; springs are 42% and 77% off (their nu is about 0.17, not 0.3).
    assert abs(rows["smoothed"]["tip_deflection_error"]) < 0.01
    assert abs(rows["smoothed"]["volume_change_error_vs_fem"]) < 0.01
    assert abs(rows["springs"]["volume_change_error_vs_fem"]) > 0.3


def test_constants_once_per_rung_and_nu_with_the_refusal_below_the_networks_nu():
    constants = rung_constants(MODELS, (0.05, 0.45, 0.49), cells=2)
    assert set(constants) == set(MODELS) and all(set(by_nu) == {"0.05", "0.45", "0.49"} for by_nu in constants.values())
    for nu in ("0.05", "0.45", "0.49"):
        # See the test above: the patch test, to the O(strain) nonlinearity of the measurement.
        assert constants["smoothed"][nu]["nu_effective"] == pytest.approx(float(nu), abs=0.01)
    # Springs: one nu whatever is asked (the Cauchy limit), bit for bit since their rules use E only.
    assert constants["springs"]["0.05"]["nu_effective"] == constants["springs"]["0.49"]["nu_effective"]
    assert "cannot reach nu = 0.05" in constants["springs+volume"]["0.05"]["refused"]
    assert constants["springs+volume"]["0.45"]["nu_effective"] > constants["springs"]["0.45"]["nu_effective"]


def test_smoothed_deflection_error_is_smaller_than_springs_on_the_cantilever(cache_folder):
    case = cantilever_gravity(per_height=1)  # 44 nodes, the --quick beam
    results = compare_static(case, rules=(), models=("springs", "smoothed"), elements=("P2",),
                             folder=cache_folder).results
    errors = {rung: results["models"][rung]["tip_deflection_error"] for rung in ("springs", "smoothed")}
    # Measured -61% (springs) and -39% (smoothed, one tet layer across the beam): strictly better, not close.
    assert abs(errors["smoothed"]) < abs(errors["springs"]) - 0.1
    assert results["springs"] == {}  # no rule asked: the rung's answer comes from models= alone


def test_a_rung_that_refuses_the_material_is_a_row_not_a_crash(cache_folder):
    case = uniaxial_compression(cells=2, nu=0.05)
    comparison = compare_static(case, rules=(), models=MODELS, elements=("P2",), folder=cache_folder)
    answers = comparison.results["models"]
    assert set(answers["springs+volume"]) == {"refused"}
    assert "'springs+volume' cannot reach nu = 0.05" in answers["springs+volume"]["refused"]
    assert "\n" not in answers["springs+volume"]["refused"]
    assert np.isfinite(answers["smoothed"]["tip_deflection_error"])
    assert "model_springs+volume" not in comparison.fields["displacement"]


def test_volume_change_is_the_moved_mesh_volume_from_volspring_own_solve(cache_folder):
    case = uniaxial_compression(cells=2, nu=0.45)
    comparison = compare_static(case, rules=(), models=("smoothed",), elements=("P2",), folder=cache_folder)
    u = spring_static(case, Model.from_mesh(case.mesh, case.material, model="smoothed")).displacement
    # The same model through the same Newton solve (to 1e-7 of the load): the same nodal volume change.
    assert comparison.results["models"]["smoothed"]["volume_change_m3"] == pytest.approx(
        deformed_volume_change(case.mesh, u), rel=1e-6)
    assert np.array_equal(comparison.fields["displacement"]["model_smoothed"], u)


def test_model_names_are_parsed_in_the_ladders_order():
    assert parse_models("smoothed,springs,smoothed") == ("springs", "smoothed")
    assert parse_models(" springs+volume ") == ("springs+volume",)
    assert parse_models(list(VALIDATED_MODELS)) == VALIDATED_MODELS
    with pytest.raises(ValueError, match=r"unknown model 'spring'; known: springs, springs\+volume, smoothed"):
        parse_models("spring")


@pytest.fixture
def no_work(monkeypatch):
    def run_validation(**kwargs):
        raise AssertionError("the validation ran before the bad input was reported")

    monkeypatch.setattr(validation.report.runner, "run_validation", run_validation)


@pytest.mark.parametrize("value, expected", [
    ("foo", "--model 'foo': unknown model 'foo'; known: springs, springs+volume, smoothed"),
    ("springs,fem", "--model 'springs,fem': unknown model 'fem'"),
    ("", "--model '': unknown model ''"),
])
def test_an_unknown_model_is_refused_before_any_work(value, expected, tmp_path, no_work, capsys):
    status = main(["--quick", "--model", value, "--out", str(tmp_path / "out"), "--cache", str(tmp_path / "cache"),
                   "--no-progress"])
    error = capsys.readouterr().err.strip()
    assert status == 2
    assert error.startswith(f"volspring-validate: error: {expected}") and "\n" not in error
    assert not (tmp_path / "out" / "results.json").exists()


def test_results_hold_the_ladder_and_the_report_shows_it_first(tmp_path):
    out = tmp_path / "report"
    status = main(["hanging_bar", "--quick", "--model", "smoothed,springs", "--out", str(out),
                   "--cache", str(tmp_path / "cache"), "--no-progress"])
    assert status == 0
    results = json.loads((out / "results.json").read_text())
    assert results["models"] == ["springs", "smoothed"]
    ladder = results["ladder"]
    assert [(row["case"], row["rung"]) for row in ladder["rows"]] == [("hanging_bar", "springs"),
                                                                     ("hanging_bar", "smoothed")]
    assert set(ladder["constants"]) == {"springs", "smoothed"}
    assert set(results["cases"]["hanging_bar"]["models"]) == {"springs", "smoothed"}
    page = (out / "report.html").read_text()
    first_table = page.index("<table")
    assert page.index("<h2 id='ladder'>") < first_table < page.index("<h2", page.index("<h2 id='ladder'>") + 1)
    assert page.index("<h2 id='ladder'>") == page.index("<h2")  # the first section of the page
    assert "measured from the nodal displacements" in page and "Per-tet volumes mislead" in page


def test_every_rung_runs_on_your_mesh_and_a_refusal_is_reported(tmp_path):
    from meshing import structured_box

    mesh_file = tmp_path / "beam.vtu"
    structured_box((4, 1, 1), (1.0, 0.25, 0.25)).write(mesh_file)
    out = tmp_path / "own"
    status = main(["--mesh", str(mesh_file), "--clamp", "xmin", "--E", "1e8", "--nu", "0.05", "--out", str(out),
                   "--cache", str(tmp_path / "cache"), "--no-progress"])
    assert status == 0  # a rung that refuses nu = 0.05 is a result, not a failure
    rows = {row["rung"]: row for row in json.loads((out / "results.json").read_text())["ladder"]["rows"]}
    assert list(rows) == list(VALIDATED_MODELS)  # the ladder's rungs and the lattice on the same nodes
    assert "cannot reach nu = 0.05" in rows["springs+volume"]["refused"]
    assert np.isfinite(rows["smoothed"]["tip_deflection_error"])
    assert "refused: model &#x27;springs+volume&#x27; cannot reach nu = 0.05" in (out / "report.html").read_text()


def test_held_out_shapes_are_measured_against_taylor_hood(cache_folder):
    """At nu 0.49 the held-out rows use the locking-free Taylor-Hood reference, and P2 beside it is stiffer
    (by 1% on the L-bracket: validation.ladder.STATIC_REFERENCE)."""
    from validation.heldout import build_heldout_case

    ladder = run_ladder([build_heldout_case("l_bracket_gravity", nu=0.49)], models=("smoothed",), steps=1,
                        folder=cache_folder)
    (row,) = ladder["rows"]
    assert row["reference"] == "TH"
    # Measured 0.993 of TH at alpha 0.65 (benchmarks/study_alpha.py); 3% is the deflection goal.
    assert abs(row["tip_deflection_error"]) < 0.03


def test_the_lattice_is_validated_beside_the_rungs_on_box_cases_and_refused_elsewhere(cube_ladder, cache_folder):
    """The lattice body (volspring.lattice) on the same nodes as the box cases: its nu is the cubic lattice's
    Cauchy limit, 1/4, whatever is asked (0.3 here); a held-out shape's mesh is no grid, so its row says why."""
    from validation.heldout import build_heldout_case

    _, ladder = cube_ladder
    lattice = {row["rung"]: row for row in ladder["rows"]}["lattice"]
    # E exact and nu = 1/4 by the rule (tests/test_lattice.py); 2e-3 is the geometric nonlinearity of the
    # cube's 1e-3 strain.
    assert lattice["nu_effective"] == pytest.approx(0.25, abs=2e-3)
    assert lattice["E_effective_ratio"] == pytest.approx(1.0, abs=2e-3)
    held_out = run_ladder([build_heldout_case("l_bracket_gravity", nu=0.3)], models=("lattice",), steps=1,
                          folder=cache_folder)
    (row,) = held_out["rows"]
    assert "refused" in row and "not a structured box of cubic cells" in row["refused"]
