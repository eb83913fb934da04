"""Sweeps: one scene file run once per combination of parameter values, serially or on a Dask cluster.

The data path: a scene file (:mod:`volspring.scene_file`) + values per key path (a grid, or random draws from
ranges with a seed: :func:`sweep_combinations`) -> one resolved scene per combination (the values applied as
``--set`` overrides), identified by the hash of the resolved scene (:func:`run_id`) -> runs, each assembled,
stepped as ``volspring sim`` steps it and measured (:func:`run_scene`), in this process or as Dask tasks
(:func:`sweep_client`: a local cluster of worker processes, one BLAS thread each, or an existing scheduler) ->
``OUT/runs/RUN_ID/run.json`` as each run finishes and ``OUT/results.csv``, one row per run (parameters, solver
statistics, measured quantities, times). Runs already on disk are not computed again; a failing run is a row
with its error. ``volspring sweep`` (:mod:`volspring.sweep.cli`) is the command.

Examples
--------
>>> import tempfile
>>> from pathlib import Path
>>> from volspring.sweep import run_sweep
>>> beam = Path(__file__).parents[2] / "examples" / "scenes" / "beam.toml"
>>> result = run_sweep(beam, {"bodies[0].size": [0.1], "duration": [0.3],
...                           "bodies[0].material.E": [1e6, 4e6]}, tempfile.mkdtemp())
>>> soft, stiff = (record["measured"]["displacement_max"] for record in result.records)
>>> round(soft / stiff, 1) > 1   # four times stiffer, less sag
True
"""

from volspring.sweep._cluster import BLAS_ENVIRONMENT, run_calls, sweep_client
from volspring.sweep._engine import SweepResult, run_id, run_sweep
from volspring.sweep._file import SweepFile, is_sweep_file, read_sweep_file
from volspring.sweep._measure import MEASURED, SOLVER, run_scene
from volspring.sweep._parameters import parse_grid, parse_range, sweep_combinations
from volspring.sweep._table import TABLE_NAME, TIMING_COLUMNS

__all__ = ["BLAS_ENVIRONMENT", "MEASURED", "SOLVER", "SweepFile", "SweepResult", "TABLE_NAME", "TIMING_COLUMNS",
           "is_sweep_file", "parse_grid", "parse_range", "read_sweep_file", "run_calls", "run_id", "run_scene",
           "run_sweep", "sweep_client", "sweep_combinations"]
