"""Write what a user reads: ``report.html``, ``results.json`` and the VTU files, each atomically.

:func:`write_outputs` writes ``DIR/vtu/*.vtu`` (every model's displacement on the rest mesh, and
the models side by side), ``DIR/results.json`` (layout in :mod:`validation.report.runner`) and
``DIR/report.html`` (:mod:`validation.report.html`, figures from :mod:`validation.report.figures`);
:func:`validate` runs the validation (:func:`~validation.report.runner.run_validation`) and writes
them.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from validation.compare import RULES
from validation.report import figures as report_figures
from validation.report import html as report_html
from validation.report import runner
from meshing._io import atomic_path
from meshing.mesh import TetMesh
from validation.springs import VALIDATED_MODELS
from typing import TYPE_CHECKING, Any
from collections.abc import Callable
from collections.abc import Sequence
import os

if TYPE_CHECKING:
    from validation._case import Case

__all__ = ["read_results", "validate", "write_outputs"]

# The steps are called through their modules (runner.run_validation, report_html.render_html, ...)
# so that replacing one there (a test's monkeypatch) replaces what runs here.


def validate(out: str | os.PathLike[str], *, cases: Sequence[str] | None = None, quick: bool = False,
             own_case: Case | None = None, rules: Sequence[str] = RULES, models: Sequence[str] = VALIDATED_MODELS,
             folder: str | os.PathLike[str] | None = None, progress: Any = None, command: Sequence[str] | None = None,
             record: Callable[..., Any] | None = None, sweeps: Sequence[dict] = (), client: Any = None) -> dict:
    """:func:`~validation.report.runner.run_validation` then :func:`write_outputs` into ``out``; returns the results.

    ``record`` is passed on to :func:`write_outputs`; ``sweeps`` (:func:`validation.report.trade.read_sweep`) and
    ``client`` (a Dask client, :func:`volspring.sweep.sweep_client`) to :func:`~validation.report.runner.run_validation`.
    """
    results, artefacts = runner.run_validation(cases=cases, quick=quick, own_case=own_case, rules=rules,
                                               models=models, folder=folder, progress=progress, sweeps=sweeps,
                                               client=client)
    results["command"] = command
    write_outputs(out, results, artefacts, record=record)
    return results


def write_outputs(out: str | os.PathLike[str], results: dict, artefacts: dict, *,
                  record: Callable[..., Any] | None = None) -> dict:
    """Write ``out/vtu/*.vtu``, ``out/results.json`` and ``out/report.html`` (in that order, each atomic).

    Parameters
    ----------
    out : path-like
        The report folder, created if missing.
    results : dict
        The results of :func:`~validation.report.runner.run_validation`.
    artefacts : dict
        The comparisons of :func:`~validation.report.runner.run_validation`, for the VTU files.
    record : callable, optional
        Called once as ``record(*paths)`` with every file about to be written, before any is
        written (a :meth:`volspring.output.RunFolder.record`, so the run manifest lists them).

    Returns
    -------
    dict
        name -> Path of every file written.
    """
    out = Path(out)
    if record is not None:
        record(*[out / "vtu" / file for name in artefacts for file in _vtu_names(name)],
               out / "results.json", out / "report.html")
    out.mkdir(parents=True, exist_ok=True)
    written = {}
    files = {}
    for name, comparison in artefacts.items():
        paths, models = _write_vtu(out / "vtu", name, comparison)
        written.update(paths)
        files[name] = {"vtu": [str(path.relative_to(out)) for path in paths.values()], "models": models}
    results["files"] = files
    figures = report_figures.render_figures(results)
    with atomic_path(out / "results.json") as tmp:
        tmp.write_text(json.dumps(_clean(results), indent=1, allow_nan=False))
    written["results.json"] = out / "results.json"
    with atomic_path(out / "report.html") as tmp:
        tmp.write_text(report_html.render_html(results, figures), encoding="utf-8")
    written["report.html"] = out / "report.html"
    return written


def _clean(value):
    """JSON-safe: NaN and inf become None, numpy scalars become Python numbers."""
    if isinstance(value, dict):
        return {str(k): _clean(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_clean(v) for v in value]
    if isinstance(value, np.ndarray):
        return _clean(value.tolist())
    if isinstance(value, (np.floating, float)):
        value = float(value)
        return value if math.isfinite(value) else None
    if isinstance(value, np.integer):
        return int(value)
    return value


def _vtu_names(name: str) -> tuple:
    """The VTU files of a case: every model on the rest mesh, and the models side by side."""
    return f"{name}.vtu", f"{name}_side_by_side.vtu"


def _write_vtu(folder: Path, name: str, comparison) -> tuple:
    """One file with every model's displacement as point data on the rest mesh, and one with the
    models side by side (copies offset across the shortest extent, each with its own displacement)."""
    mesh = comparison.case.mesh
    fields = comparison.fields["displacement"]
    models = list(fields)
    point_data = {f"displacement_{model}": np.asarray(u, float) for model, u in fields.items()}
    reference = next(iter(fields.values()))
    for model, u in fields.items():
        if model != models[0]:
            point_data[f"error_{model}"] = np.linalg.norm(np.asarray(u) - reference, axis=1)
    together, side_by_side = _vtu_names(name)
    paths = {together: mesh.write(folder / together, point_data=point_data)}
    extent = np.ptp(mesh.points, axis=0)
    axis = int(np.argmin(extent))
    offset = np.zeros(3)
    offset[axis] = 1.5 * extent[axis]
    points = np.concatenate([mesh.points + k * offset for k in range(len(models))])
    tets = np.concatenate([mesh.tets + k * mesh.node_count for k in range(len(models))])
    side = TetMesh(points, tets)
    displacement = np.concatenate([np.asarray(fields[model], float) for model in models])
    model_index = np.repeat(np.arange(len(models)), mesh.tet_count)
    paths[side_by_side] = side.write(
        folder / side_by_side, point_data={"displacement": displacement},
        cell_data={"model": model_index})
    return paths, models


def read_results(path: str | os.PathLike[str]) -> dict:
    """A ``results.json`` written by :func:`write_outputs`, its schema checked.

    Raises
    ------
    ValueError
        A file that is not JSON, or whose ``schema`` is not this version's (``runner.SCHEMA``), naming the
        file, the schema found and the one expected.
    """
    path = Path(path)
    try:
        results = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as error:
        raise ValueError(f"{path} is not a readable validation results file: {error}") from None
    found = results.get("schema") if isinstance(results, dict) else None
    if found != runner.SCHEMA:
        raise ValueError(f"{path} has schema {found!r}; this volspring reads {runner.SCHEMA!r} "
                         "(written by another version, or not a volspring-validate results file)")
    return results
