"""The validation report's cases and studies on a Dask cluster: the same results as one after the other.

``volspring validate --workers N`` sends every case and study to a local cluster as one task each
(:func:`volspring.sweep.run_calls`, the path sweeps take); the ladder's step costs are timed afterwards in the
calling process. Checked: the results equal the serial run's, every number but the wall times bit for bit, and
the command refuses a cluster it cannot make.
"""

import pytest

from validation.cli import main as validate_main
from validation.report.runner import run_validation
from volspring.sweep import sweep_client

# A case of each kind (static, modal, held-out shape) and two studies, the speed study split per run on
# the cluster, on coarse meshes.
CASES = ["cantilever_gravity", "cantilever_modes", "cauchy", "speed", "torus_gravity"]
# The speed study's cheapest runs of --quick's, two of them diverging: what the cluster does to the study (a task per
# run, merged in order, the Pareto front marked over all) shows on five runs as on eighteen, and the quick study
# took 31 s serially here, its five runs 1.5 s (scratch speed_runs39.py, stop 39).
SPEED_STEPS = {"explicit_euler": (0.2,), "symplectic_euler": (0.9, 1.05), "implicit_euler": (100.0, 1000.0)}


def without_times(value):
    """``value`` with every wall time and cost left out (keys holding "seconds" or "cost"), the run's date, and the
    speed study's Pareto marks (which follow from its wall times)."""
    if isinstance(value, dict):
        return {key: without_times(item) for key, item in value.items()
                if "seconds" not in key and "cost" not in key and key not in ("created", "command", "pareto")}
    if isinstance(value, list):
        return [without_times(item) for item in value]
    return value


def test_the_cluster_gives_the_serial_results(tmp_path, monkeypatch):
    from validation import studies
    from validation.heldout import HELDOUT_CASE_NAMES

    assert "torus_gravity" in HELDOUT_CASE_NAMES
    monkeypatch.setattr(studies, "QUICK_INTEGRATOR_STEPS", SPEED_STEPS)
    serial, serial_artefacts = run_validation(cases=CASES, quick=True, folder=tmp_path / "fem")
    with sweep_client(workers=2) as client:
        clustered, clustered_artefacts = run_validation(cases=CASES, quick=True, folder=tmp_path / "fem",
                                                        client=client)
    assert without_times(clustered) == without_times(serial)
    assert list(clustered_artefacts) == list(serial_artefacts) == ["cantilever_gravity", "cantilever_modes"]
    rows = [(row["case"], row["rung"]) for row in clustered["ladder"]["rows"]]
    assert rows == [(row["case"], row["rung"]) for row in serial["ladder"]["rows"]]  # the held-out shape last
    assert rows[-1][0] == "torus_gravity"
    runs = clustered["studies"]["speed"]["runs"]  # merged from one task per run, in the study's order
    assert [run["integrator"] for run in runs] == [run["integrator"] for run in serial["studies"]["speed"]["runs"]]
    assert [run["integrator"] for run in runs] == [name for name, factors in SPEED_STEPS.items() for _ in factors]
    assert any("pareto" in run for run in runs)


def test_merged_speed_studies_mark_the_front_over_all_their_runs():
    from validation.studies import merge_speed_studies, pareto_front

    def run(name, time, error):
        return {"integrator": name, "wall_seconds_per_simulated_second": time, "settled_deflection_error": error,
                "first_frequency_error": -error, "pareto": ["stale"]}

    setup = {"case": "cantilever_gravity", "rule": "van_gelder", "per_height": 1, "node_count": 44,
             "duration_s": 1.0, "drag_rate_per_s": 2.0}
    parts = [{**setup, "runs": [run("verlet", 1.0, 0.1), run("verlet", 2.0, 0.01)]},
             {**setup, "runs": [run("rk4", 1.5, 0.2), run("rk4", 0.5, 0.3)]}]
    merged = merge_speed_studies(parts)
    times = [r["wall_seconds_per_simulated_second"] for r in merged["runs"]]
    errors = [abs(r["settled_deflection_error"]) for r in merged["runs"]]
    on_front = [k for k, r in enumerate(merged["runs"]) if "settled_deflection_error" in r.get("pareto", [])]
    assert sorted(on_front) == sorted(pareto_front(times, errors)) == [0, 1, 3]
    assert all("stale" not in r.get("pareto", []) for r in merged["runs"])
    with pytest.raises(ValueError, match="different set-ups"):
        merge_speed_studies([parts[0], {**parts[1], "duration_s": 2.0}])


@pytest.mark.parametrize("extra, message", [
    (["--workers", "0"], "--workers 0 is not >= 1"),
    (["--workers", "2", "--scheduler", "tcp://127.0.0.1:1"], "give one of them"),
])
def test_a_cluster_that_cannot_be_made_is_refused_before_any_work(tmp_path, capsys, extra, message):
    assert validate_main(["cauchy", "--quick", "--out", str(tmp_path / "report"), *extra]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1, err
