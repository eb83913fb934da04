"""Speed-up of a sweep on a local Dask cluster over the same sweep run serially, from one run.

The README beam (examples/scenes/beam.toml: 1 m, clamped, sagging under gravity; implicit Euler) at
``--size`` for ``--duration`` s, swept over 4 stiffnesses x 3 rungs of the ladder x 2 steps = 24 runs, is run
once serially in this process and once on a local cluster of ``--workers`` worker processes (one thread each,
:func:`volspring.sweep.sweep_client`). The script prints both wall times, the speed-up with and without the
cluster's start-up, and checks that both tables are identical apart from the times (row for row, every value
as text, so every float bit for bit). This process pins its own BLAS to one thread too, so the serial run and
each worker compute alike and the ratio measures the parallelism alone; with 2 workers on 2 cores the ideal is 2.

Run::

    python benchmarks/bench_sweep.py
    python benchmarks/bench_sweep.py --workers 4 --size 0.04 --duration 1

This is a script, not a test.
"""

from __future__ import annotations

import os

for _name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):  # before numpy is imported
    os.environ[_name] = "1"

import argparse  # noqa: E402
import csv  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

BEAM = Path(__file__).resolve().parents[1] / "examples" / "scenes" / "beam.toml"


def rows(folder):
    from volspring.sweep import TIMING_COLUMNS

    with open(Path(folder) / "results.csv", newline="") as file:
        return [{key: value for key, value in row.items() if key not in TIMING_COLUMNS} for row in csv.DictReader(file)]


def burn(count=5_000_000) -> float:
    """Seconds of a pure-Python loop: the machine's speed for one process, free of memory traffic."""
    start = time.perf_counter()
    total = 0
    for value in range(count):
        total += value
    return time.perf_counter() - start


def main():
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--workers", type=int, default=2, help="worker processes of the local cluster")
    parser.add_argument("--size", type=float, default=0.05, help="tet edge length of the beam [m]")
    parser.add_argument("--duration", type=float, default=0.5, help="simulated time of each run [s]")
    args = parser.parse_args()

    from volspring.sweep import run_sweep, sweep_client

    grid = {"bodies[0].size": [args.size], "duration": [args.duration],
            "bodies[0].material.E": [1e6, 2e6, 4e6, 8e6], "bodies[0].model": ["springs", "springs+volume", "smoothed"],
            "integrator.dt": [0.01, 0.02]}
    folder = Path(tempfile.mkdtemp(prefix="bench_sweep_"))
    load = os.getloadavg()[0]
    start = time.perf_counter()
    serial = run_sweep(BEAM, grid, folder / "serial")
    serial_seconds = time.perf_counter() - start

    start = time.perf_counter()
    with sweep_client(workers=args.workers) as client:
        ready = time.perf_counter()
        # The machine's own parallelism, on the same worker processes: the loop alone here, then on every
        # worker at once. On cores shared with other work the ceiling is below the worker count.
        alone = min(burn() for _ in range(3))
        together = max(max(client.run(burn).values()) for _ in range(3))
        ceiling = args.workers * alone / together
        sweeping = time.perf_counter()
        cluster = run_sweep(BEAM, grid, folder / "cluster", client=client)
        swept = time.perf_counter()
    startup, cluster_seconds = ready - start, swept - sweeping

    runs = len(serial.records)
    failed = serial.failed
    nodes = "?"
    if serial.records and serial.records[0]["status"] == "done":
        from volspring.scene_file import assemble_scene

        nodes = assemble_scene(serial.records[0]["scene"], base=BEAM.parent).model.node_count
    run_seconds = [record["seconds"]["wall"] for record in serial.records]
    worker_seconds = [record["seconds"]["wall"] for record in cluster.records]
    print(f"sweep of {runs} runs of the README beam ({nodes} nodes at size {args.size:g} m, {args.duration:g} s "
          f"simulated; {failed} failed), {os.cpu_count()} CPUs, load average {load:.1f} before the runs")
    print(f"  a run (serial): {min(run_seconds):.2f}-{max(run_seconds):.2f} s, {sum(run_seconds):.1f} s in all")
    print(f"  serial, this process:               {serial_seconds:7.2f} s")
    print(f"  local cluster, {args.workers} workers:           {cluster_seconds:7.2f} s  (+ {startup:.2f} s to start it)")
    print(f"  the runs' own time on the workers / in this process: {sum(worker_seconds) / sum(run_seconds):.2f} "
          "(above 1: the workers shared their cores, with each other's memory traffic or other processes)")
    print(f"  speed-up: {serial_seconds / cluster_seconds:.2f}x ({serial_seconds / (cluster_seconds + startup):.2f}x "
          f"with the start-up); ideal {min(args.workers, os.cpu_count() or 1)}x")
    print(f"  this machine's ceiling for {args.workers} processes (a pure-Python loop alone, then on every worker "
          f"at once): {ceiling:.2f}x, so the sweep reaches {serial_seconds / cluster_seconds / ceiling:.0%} of it")
    same = rows(folder / "serial") == rows(folder / "cluster")
    print(f"  tables identical apart from the times: {same}")
    if not same or cluster.executed != runs:
        raise SystemExit("the cluster's table differs from the serial one")


if __name__ == "__main__":  # the workers are spawned processes: they import this file, and must not run it
    main()
