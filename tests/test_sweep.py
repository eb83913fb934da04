"""``volspring sweep`` and :func:`volspring.sweep.run_sweep`: serial and on a local Dask cluster of 2 processes.

The runs are the README beam (examples/scenes/beam.toml) at a coarse size and a short duration (about 0.1 s a
run), and a beam read from a mesh file (the scattered input). Checked: the cluster's table equals the serial one
row for row, every value but the times identical as text (floats are written as their repr, so equal text is
the same float); a re-run computes only the runs missing from disk; a failing combination is a row with its error;
a worker killed mid-sweep costs no run; a sweep stopped by Ctrl-C keeps the runs it finished, and the same
command then computes only the others.
"""

import csv
import json
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

from volspring import kernels
from volspring.sweep import TIMING_COLUMNS, run_sweep, sweep_client, sweep_combinations
from volspring.sweep.cli import main

from conftest import cube_mesh

BEAM = Path(__file__).resolve().parents[1] / "examples" / "scenes" / "beam.toml"
COARSE = {"bodies[0].size": [0.1], "duration": [0.2], "integrator.dt": [0.02]}  # 10 steps on 120 nodes
# The README beam's material at three stiffnesses on two rungs: 6 runs that sag by different amounts.
GRID = {**COARSE, "bodies[0].material.E": [1e6, 2e6, 4e6], "bodies[0].model": ["springs", "smoothed"]}
MESH_SCENE = """\
duration = 0.2
[integrator]
name = "implicit_euler"
dt = 0.02
[[bodies]]
mesh = "beam.vtu"
material = { E = 1e6, density = 1100.0 }
[[supports]]
type = "pin"
region = "xmin"
[[fields]]
type = "gravity"
"""


@pytest.fixture(scope="module")
def client():
    with sweep_client(workers=2) as client:
        yield client


@pytest.fixture(scope="module")
def mesh_scene(tmp_path_factory):
    folder = tmp_path_factory.mktemp("mesh_scene")
    cube_mesh((10, 1, 1), size=(1.0, 0.1, 0.1)).write(folder / "beam.vtu")
    (folder / "scene.toml").write_text(MESH_SCENE)
    return folder / "scene.toml"


def table(folder):
    """The rows of folder/results.csv without the times (the only values that differ between executions)."""
    with open(Path(folder) / "results.csv", newline="") as file:
        return [{key: value for key, value in row.items() if key not in TIMING_COLUMNS} for row in csv.DictReader(file)]


@pytest.mark.parametrize("scene, grid", [(BEAM, GRID), ("mesh", {"bodies[0].material.E": [5e5, 1e6],
                                                                 "integrator.name": ["implicit_euler", "verlet"],
                                                                 "integrator.dt": [0.002], "duration": [0.1]})],
                         ids=["shape", "mesh-file"])
def test_the_cluster_table_equals_the_serial_one_row_for_row(client, mesh_scene, scene, grid, tmp_path):
    scene = mesh_scene if scene == "mesh" else scene
    probes = {"tip": [0.5, 0.0, 0.0]}
    serial = run_sweep(scene, grid, tmp_path / "serial", probes=probes)
    cluster = run_sweep(scene, grid, tmp_path / "cluster", client=client, probes=probes)
    rows = table(tmp_path / "serial")
    assert len(rows) == len(sweep_combinations(grid)) and all(row["status"] == "done" for row in rows), rows
    assert table(tmp_path / "cluster") == rows
    # Not a vacuous equality: the runs differ from each other, and sag under gravity.
    assert len({row["displacement_max"] for row in rows}) == len(rows)
    assert all(float(row["tip_uz"]) < 0 for row in rows)
    # The records agree as numbers too (JSON floats are reprs as well), and ran where they should have.
    for one, other in zip(serial.records, cluster.records):
        assert one["measured"] == other["measured"] and one["solver"] == other["solver"]
        assert one["worker"]["pid"] == os.getpid() and other["worker"]["pid"] != os.getpid()
        assert other["worker"]["blas_threads"]["OPENBLAS_NUM_THREADS"] == "1"
        # which code ran (the workers inherit the choice): numba where the fast extra is installed
        assert one["worker"]["kernels"] == other["worker"]["kernels"] == kernels.active()
    assert cluster.executed == len(rows) and cluster.skipped == 0


def test_the_mesh_file_is_scattered_not_read_by_the_workers(client, mesh_scene, tmp_path):
    # The workers read the file from what the client scattered, written once per machine under the temporary
    # folder: a worker on another machine has no access to the client's files.
    result = run_sweep(mesh_scene, {"bodies[0].material.E": [1e6], "duration": [0.02]}, tmp_path, client=client)
    (record,) = result.records
    assert record["status"] == "done" and record["scene"]["bodies"][0]["mesh"] == "beam.vtu"
    digest = record["files"]["beam.vtu"]
    assert (Path(tempfile.gettempdir()) / f"volspring-sweep-{digest[:16]}" / "beam.vtu").is_file()


def test_a_rerun_computes_only_the_runs_missing_from_disk(client, tmp_path):
    done = []
    first = run_sweep(BEAM, GRID, tmp_path, client=client, callback=lambda record, *_: done.append(record["run"]))
    assert first.executed == len(done) == 6 and first.skipped == 0
    kept = table(tmp_path)
    for run in done[1::2]:  # three runs lost, as if the sweep had stopped before them
        for path in (tmp_path / "runs" / run).iterdir():
            path.unlink()
    again = []
    second = run_sweep(BEAM, GRID, tmp_path, client=client, callback=lambda record, *_: again.append(record["run"]))
    assert second.executed == 3 and second.skipped == 3 and sorted(again) == sorted(done[1::2])
    assert table(tmp_path) == kept
    assert run_sweep(BEAM, GRID, tmp_path).executed == 0  # complete: nothing to compute, serially either


def test_a_failing_combination_is_a_row_with_its_error(tmp_path):
    grid = {**COARSE, "bodies[0].material.nu": [0.3, 0.7], "bodies[0].model": ["smoothed"],
            "integrator.dt": [0.02, -1.0]}
    result = run_sweep(BEAM, grid, tmp_path)
    rows = {(row["bodies[0].material.nu"], row["integrator.dt"]): row for row in table(tmp_path)}
    assert rows["0.3", "0.02"]["status"] == "done" and rows["0.3", "0.02"]["error"] == ""
    assert rows["0.7", "0.02"]["status"] == "failed"
    assert rows["0.7", "0.02"]["error"] == "bodies[0].material.nu = 0.7 is not in (-1, 0.5)"
    assert rows["0.3", "-1.0"]["error"] == "integrator.dt = -1.0 is not a finite number > 0"  # refused unresolved
    assert rows["0.7", "0.02"]["displacement_max"] == ""
    assert result.failed == 3 and result.complete
    # A diverged run is a row too, with where it diverged; the sweep goes on past it.
    explicit = {**COARSE, "integrator.name": ["symplectic_euler"], "integrator.guard": ["off"],
                "integrator.dt": [0.005, 1e-4], "duration": [0.2, 0.002]}
    result = run_sweep(BEAM, explicit, tmp_path / "explicit")
    statuses = [(record["parameters"]["integrator.dt"], record["status"]) for record in result.records]
    assert (0.005, "diverged") in statuses and (1e-4, "done") in statuses
    diverged = next(record for record in result.records if record["status"] == "diverged")
    assert diverged["error"].startswith("simulation diverged at step") and diverged["solver"]["steps"] > 0


def test_a_worker_killed_mid_sweep_costs_no_run(tmp_path):
    killed = []
    with sweep_client(workers=2) as client:
        pids = client.run(os.getpid)  # worker address -> process id

        def kill_once(record, done, total):
            if not killed:  # after the first run: both workers are busy with the next ones
                address = next(address for address, pid in pids.items() if pid != record["worker"]["pid"])
                busy = client.processing()[address]  # the runs it holds, started or queued
                os.kill(pids[address], signal.SIGKILL)
                killed.append((pids[address], busy))

        grid = {**COARSE, "bodies[0].material.E": list(np.linspace(1e6, 4e6, 10)), "duration": [0.4]}
        result = run_sweep(BEAM, grid, tmp_path, client=client, callback=kill_once)
    (victim, busy), = killed
    assert busy and result.complete and result.executed == 10  # the runs it held were run again elsewhere
    assert all(record["status"] == "done" for record in result.records)
    assert len(table(tmp_path)) == 10 and all(row["error"] == "" for row in table(tmp_path))
    with pytest.raises(ProcessLookupError):  # it was killed indeed (the nanny starts a new process instead)
        os.kill(victim, 0)


def test_ctrl_c_keeps_the_runs_finished_and_the_same_command_computes_the_others(tmp_path):
    out = tmp_path / "sweep"
    command = [sys.executable, "-m", "volspring", "sweep", str(BEAM), "--set", "bodies[0].size=0.1", "--set",
               "integrator.dt=0.02", "--set", "duration=0.6", "--grid", "bodies[0].material.E=" + ",".join(
                   str(E) for E in np.linspace(1e6, 4e6, 12)), "--workers", "2", "--out", str(out), "--no-progress"]
    sweep = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120  # the cluster starts in ~5 s and a run takes ~0.3 s [measured]
    while len(list(out.glob("runs/*/run.json"))) < 2 and time.monotonic() < deadline and sweep.poll() is None:
        time.sleep(0.05)
    sweep.send_signal(signal.SIGINT)
    _, err = sweep.communicate(timeout=120)
    finished = {path.parent.name for path in out.glob("runs/*/run.json")}
    assert sweep.returncode == 130, err
    assert "interrupted by SIGINT (Ctrl-C)" in err and "run the same command to compute the others" in err, err
    assert 2 <= len(finished) < 12  # stopped mid-sweep, the runs done before the signal on disk
    assert len(table(out)) == len(finished)  # the table holds them: written on the way out
    again = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert again.returncode == 0, again.stderr
    assert f"({12 - len(finished)} computed, {len(finished)} already in" in again.stdout
    assert len(table(out)) == 12 and all(row["status"] == "done" for row in table(out))


def test_random_draws_depend_on_the_seed_alone():
    ranges = {"bodies[0].material.E": (1e5, 1e6), "integrator.newton_iterations": (0, 2)}
    draws = sweep_combinations(random=ranges, samples=50, seed=7)
    assert draws == sweep_combinations(random=ranges, samples=50, seed=7)
    assert draws != sweep_combinations(random=ranges, samples=50, seed=8)
    E = [draw["bodies[0].material.E"] for draw in draws]
    assert 1e5 <= min(E) and max(E) < 1e6
    assert {draw["integrator.newton_iterations"] for draw in draws} == {0, 1, 2}  # whole numbers, ends included
    grid = sweep_combinations({"duration": [0.1, 0.2]}, random=ranges, samples=3, seed=7)
    assert len(grid) == 6 and [point["bodies[0].material.E"] for point in grid[3:]] == E[:3]


def test_the_command_runs_a_sweep_and_says_so(tmp_path, capsys):
    argv = [BEAM, "--set", "bodies[0].size=0.1", "--set", "duration=0.04", "--grid", "integrator.dt=0.02",
            "--random", "bodies[0].material.E=1e6:4e6", "--samples", "2", "--seed", "3", "--probe", "tip=0.5,0,0",
            "--workers", "0", "--out", tmp_path, "--no-progress"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    assert out.startswith("sweep: 2 runs (2 computed, 0 already in") and out.strip().endswith("results.csv")
    assert {"tip_ux", "tip_uy", "tip_uz", "bodies[0].material.E"} <= set(table(tmp_path)[0])
    assert json.loads((tmp_path / "sweep.json").read_text())["seed"] == 3
    assert main(argv) == 0 and "(0 computed, 2 already in" in capsys.readouterr().out


@pytest.mark.parametrize("extra, message", [
    (["--grid", "bodies[0].sise=0.1"], "bodies[0].sise is not a known key; did you mean size?"),
    (["--grid", "duration"], "--grid 'duration' is not KEY.PATH=V1,V2,..."),
    (["--random", "duration=0.1:0.2"], "--random needs --samples N"),
    (["--random", "duration=a:b", "--samples", "2"], "is not KEY.PATH=LOW:HIGH with two numbers"),
    (["--grid", "duration=0.1", "--probe", "tip=1,2"], "--probe 'tip=1,2' is not NAME=X,Y,Z"),
    (["--grid", "duration=0.1", "--workers", "-1"], "--workers -1 is not >= 0"),
    (["--grid", "duration=0.1", "--frequencies", "-1"], "--frequencies -1 is not >= 0"),
    ([], "nothing to sweep"),
    (["--set", "duration=0.1", "--grid", "duration=0.1,0.2"], "duration is given twice (--set, --grid)"),
])
def test_bad_input_is_one_line_and_status_2(tmp_path, capsys, extra, message):
    assert main([BEAM, "--out", tmp_path / "out", "--workers", "0", *extra]) == 2
    err = capsys.readouterr().err
    assert err.startswith("volspring-sweep: error: ") and message in err and err.count("\n") == 1, err


def test_a_missing_scene_file_is_refused_before_any_cluster(tmp_path, capsys):
    assert main([tmp_path / "none.toml", "--grid", "duration=0.1", "--out", tmp_path / "out"]) == 2
    assert "no scene file at" in capsys.readouterr().err
