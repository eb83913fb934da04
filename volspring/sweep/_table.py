"""A sweep's folder on disk: one ``runs/RUN_ID/run.json`` per run, and ``results.csv``, one row per run.

The run records are the ground truth: each is written atomically (:func:`meshing._io.atomic_path`) as soon as its
run finishes, so a sweep that stops loses nothing finished, and a record on disk is a run that is not computed
again. ``results.csv`` is made from them (:func:`write_table`), rewritten atomically as runs finish and at the end.

Columns (:func:`table_columns`): ``run``, the swept key paths, ``status``, ``error``, the solver statistics
(:data:`~volspring.sweep._measure.SOLVER`), the measured quantities (:data:`~volspring.sweep._measure.MEASURED`,
then the probes', then a comparison's), ``warnings``, and last the times (:data:`TIMING_COLUMNS`), the only values
that change from one execution of the same run to the next. Floats are written as Python's ``repr`` (the shortest
text that reads back to the same float), so a table read back holds the very numbers computed; an empty cell is a
value that does not apply (no CG iterations for an explicit integrator, no measurement for a failed run).
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

from meshing._io import atomic_path
from volspring.sweep._measure import MEASURED, SOLVER

__all__ = ["RUNS_FOLDER", "TABLE_NAME", "TIMING_COLUMNS", "read_record", "record_path", "table_columns", "table_row",
           "write_record", "write_table"]

TABLE_NAME = "results.csv"
RUNS_FOLDER = "runs"
RECORD_NAME = "run.json"
#: Wall time of the run, its building (meshing, model, scene), its stepping, its comparison and its modes (if
#: any) [s].
TIMING_COLUMNS = ("wall_seconds", "build_seconds", "stepping_seconds", "compare_seconds", "modes_seconds")


def record_path(out, run_id: str) -> Path:
    """``OUT/runs/RUN_ID/run.json``."""
    return Path(out) / RUNS_FOLDER / run_id / RECORD_NAME


def write_record(out, record: dict) -> Path:
    """Write a run's record (its ``run`` id names the folder) atomically; returns its path."""
    path = record_path(out, record["run"])
    with atomic_path(path) as temporary:
        temporary.write_text(json.dumps(record, indent=1, allow_nan=True) + "\n")
    return path


def read_record(out, run_id: str):
    """The record of run ``run_id`` on disk, or None when there is none (or it cannot be read: run it again)."""
    path = record_path(out, run_id)
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def table_columns(parameters, probes=(), records=()) -> list:
    """The columns of the table of a sweep over the key paths ``parameters`` with the named ``probes``; a
    measured quantity of ``records`` beyond those (a comparison's ``compare_*``) follows the probes', in the
    order the records first give them."""
    probed = [f"{name}_{what}" for name in probes for what in ("node", "ux", "uy", "uz")]
    known = {*MEASURED, *probed}
    extra = dict.fromkeys(name for record in records for name in record.get("measured", {}) if name not in known)
    return ["run", *parameters, "status", "error", *SOLVER, *MEASURED, *probed, *extra, "warnings", *TIMING_COLUMNS]


def table_row(record: dict, columns) -> dict:
    """The row of ``record`` for :func:`write_table`: every column's value as text."""
    values = {"run": record["run"], **record["parameters"], "status": record["status"], "error": record["error"],
              **record["solver"], **record["measured"], "warnings": " | ".join(record["warnings"]),
              **{f"{name}_seconds": value for name, value in record["seconds"].items()}}
    return {column: _text(values.get(column)) for column in columns}


def write_table(path, records, columns) -> None:
    """Write ``records`` (in order) as a CSV table with ``columns``, atomically."""
    with atomic_path(path) as temporary, temporary.open("w", newline="") as file:
        writer = csv.DictWriter(file, fieldnames=list(columns))
        writer.writeheader()
        for record in records:
            writer.writerow(table_row(record, columns))


def _text(value) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    if isinstance(value, (list, dict)):
        return json.dumps(value)
    return str(value)
