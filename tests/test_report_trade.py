"""A user's sweep in the validation report: error against FEM over cost, a curve per model, the Pareto front.

``volspring validate --sweep DIR`` reads the table a ``volspring sweep`` wrote (nothing is run again). Checked:
the front holds exactly the runs no other run beats on both cost and error, curves group the runs by their text
values and order them by cost, constant swept values label nothing, a run without numbers (failed, or a scene
without ``[compare]``) is in the table but on no curve, and the command end to end, from a sweep to the page.
"""

import itertools
import json

import numpy as np

from validation.cli import main as validate_main
from validation.report.trade import read_sweep, trade_curve
from volspring.sweep import run_sweep

from test_scene_compare import EXAMPLE


def rows_of(costs, errors, models, dts, statuses=None):
    statuses = statuses or ["done"] * len(costs)
    return [{"run": str(k), "duration": "1.0", "bodies[0].model": model, "integrator.dt": repr(dt), "status": status,
             "t_end": "2.0", "stepping_seconds": repr(2 * float(cost)), "compare_rms_error": repr(float(error)),
             "compare_peak_ratio": "1.0"}
            for k, (cost, error, model, dt, status) in enumerate(zip(costs, errors, models, dts, statuses))]


def test_the_front_is_exactly_the_runs_no_other_run_beats():
    generator = np.random.default_rng(7)
    costs, errors = generator.uniform(0.1, 3, 40), generator.uniform(0.01, 0.2, 40)
    models = ["springs", "smoothed"] * 20
    sweep = trade_curve(rows_of(costs, errors, models, [0.01] * 40), ["duration", "bodies[0].model", "integrator.dt"])
    # Brute force: dominated when another run is no costlier and strictly more accurate, or cheaper and as accurate.
    dominated = {k for k, j in itertools.product(range(40), repeat=2)
                 if (costs[j] <= costs[k] and errors[j] < errors[k])
                 or (costs[j] < costs[k] and errors[j] <= errors[k])}
    assert sorted(sweep["pareto"]) == sorted(set(range(40)) - dominated)
    assert [sweep["runs"][k]["cost_s_per_s"] for k in sweep["pareto"]] == sorted(costs[sweep["pareto"]])


def test_curves_group_by_the_varying_text_values_ordered_by_cost():
    rows = rows_of([3.0, 1.0, 2.0, 0.5], [0.1, 0.2, 0.05, 0.3], ["smoothed", "springs", "smoothed", "springs"],
                   [0.01, 0.01, 0.02, 0.02])
    sweep = trade_curve(rows, ["duration", "bodies[0].model", "integrator.dt"])
    assert sweep["varying"] == ["bodies[0].model", "integrator.dt"]  # duration is the same in every run
    assert sweep["labels"] == ["bodies[0].model"]
    assert sweep["curves"] == {"bodies[0].model=springs": [3, 1], "bodies[0].model=smoothed": [2, 0]}
    assert sweep["runs"][0]["cost_s_per_s"] == 3.0  # stepping seconds over the simulated time


def test_runs_without_numbers_are_in_the_table_but_on_no_curve():
    rows = rows_of([1.0, 2.0], [0.1, 0.05], ["springs", "smoothed"], [0.01, 0.01], statuses=["failed", "done"])
    sweep = trade_curve(rows, ["bodies[0].model"])
    assert len(sweep["runs"]) == 2 and sweep["curves"] == {"bodies[0].model=smoothed": [1]} and sweep["pareto"] == [1]
    for row in rows:
        del row["compare_rms_error"]
    plain = trade_curve(rows, ["bodies[0].model"])
    assert not plain["has_error"] and plain["curves"] == {} and plain["pareto"] == []


def test_a_sweep_becomes_a_report_section_with_its_figure(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("VOLSPRING_CACHE", str(tmp_path / "fem"))
    result = run_sweep(EXAMPLE, {"bodies[0].size": [0.1], "duration": [0.4], "bodies[0].model": ["springs", "smoothed"],
                                 "integrator.dt": [0.02, 0.05]}, tmp_path / "sweep")
    assert [record["status"] for record in result.records] == ["done"] * 4
    status = validate_main(["--sweep", str(tmp_path / "sweep"), "--out", str(tmp_path / "report"), "--quiet",
                            "--no-progress"])
    assert status == 0, capsys.readouterr().err
    results = json.loads((tmp_path / "report" / "results.json").read_text())
    assert results["cases"] == {} and len(results["sweeps"]) == 1  # --sweep alone runs no case
    sweep = results["sweeps"][0]
    assert sweep == json.loads(json.dumps(read_sweep(tmp_path / "sweep")))  # the table's numbers, not new runs
    assert sorted(run["rms_error"] for run in sweep["runs"]) == sorted(
        record["measured"]["compare_rms_error"] for record in result.records)
    assert len(sweep["curves"]) == 2 and sweep["pareto"]
    page = (tmp_path / "report" / "report.html").read_text()
    assert "id='sweep_0'" in page and "Pareto front" in page and "data:image/svg+xml" in page


def test_a_folder_without_a_sweep_is_refused_before_any_work(tmp_path, capsys):
    status = validate_main(["--sweep", str(tmp_path), "--out", str(tmp_path / "report")])
    err = capsys.readouterr().err
    assert status == 2 and "no results.csv there; expected the --out folder of a volspring sweep" in err, err
    assert not (tmp_path / "report").exists()
