"""A user's sweep in the report: error against cost, one curve per model or integrator, the Pareto front marked.

``volspring validate --sweep DIR`` reads a sweep's folder (:mod:`volspring.sweep`: ``DIR/results.csv``, one row
per run, and ``DIR/sweep.json``) with :func:`read_sweep`, which the report shows in a section of its own after the
ladder (:func:`sweep_section`, figure by :func:`sweep_figure`). Nothing is run again: the numbers are the runs'.

- **Error**: ``compare_rms_error``, the run's RMS nodal displacement error against the FEM answer of the same body
  (the scene's ``[compare]`` table, :mod:`validation.scene_comparison`); a sweep of a scene without one has no
  error to plot, and the section says so.
- **Cost**: wall time of the stepping per simulated second (``stepping_seconds / t_end``), the run's own. Runs
  that shared the machine with other workers are slowed alike; compare costs within one sweep.
- **Curves**: the swept key paths whose values are text (``bodies[0].model``, ``integrator.name``) name the
  curves; the numeric ones (``integrator.dt``, ``bodies[0].size``) are the points along each, labelled with their
  values. A sweep with no text key path is one curve.
- **Pareto front**: the runs no other run beats on both cost and error
  (:func:`validation.studies.pareto_front`).

Examples
--------
>>> rows = [{"run": "a", "bodies[0].model": "springs", "integrator.dt": "0.02", "status": "done", "t_end": "1.0",
...          "stepping_seconds": "0.5", "compare_rms_error": "0.08", "compare_peak_ratio": "0.93"},
...         {"run": "b", "bodies[0].model": "smoothed", "integrator.dt": "0.02", "status": "done", "t_end": "1.0",
...          "stepping_seconds": "1.5", "compare_rms_error": "0.02", "compare_peak_ratio": "1.02"}]
>>> sweep = trade_curve(rows, ["bodies[0].model", "integrator.dt"])
>>> sweep["curves"], sweep["pareto"]
({'bodies[0].model=springs': [0], 'bodies[0].model=smoothed': [1]}, [0, 1])
"""

from __future__ import annotations

import csv
import html
import json
import math
from pathlib import Path
from typing import TYPE_CHECKING

from validation.report._cells import fmt, image, table
from validation.studies import pareto_front

if TYPE_CHECKING:
    import os

    from validation.report.sections import Section

__all__ = ["ERROR_COLUMN", "read_sweep", "sweep_figure", "sweep_section", "trade_curve"]

#: The error of a run: its RMS displacement error against FEM (a scene with ``[compare]``).
ERROR_COLUMN = "compare_rms_error"
#: Shown beside it: the peak displacement over FEM's.
PEAK_COLUMN = "compare_peak_ratio"


def read_sweep(folder: str | os.PathLike[str]) -> dict:
    """The trade curve of the sweep in ``folder`` (:func:`trade_curve` of its ``results.csv``).

    Raises
    ------
    ValueError
        When ``folder`` holds no ``results.csv`` of a sweep, naming the folder.
    """
    from volspring.sweep import TABLE_NAME

    folder = Path(folder)
    path = folder / TABLE_NAME
    if not path.is_file():
        raise ValueError(f"--sweep {folder}: no {TABLE_NAME} there; expected the --out folder of a volspring sweep")
    with path.open(newline="") as file:
        rows = list(csv.DictReader(file))
    description = {}
    if (folder / "sweep.json").is_file():
        description = json.loads((folder / "sweep.json").read_text())
    header = list(rows[0]) if rows else []
    parameters = header[1:header.index("status")] if "status" in header else []
    sweep = trade_curve(rows, parameters)
    sweep.update(folder=str(folder), scene_file=description.get("scene_file"))
    return sweep


def trade_curve(rows: list, parameters: list) -> dict:
    """Runs, curves and Pareto front of a sweep's table rows (text cells, as :mod:`csv` reads them).

    Parameters
    ----------
    rows : list of dict
        The rows of ``results.csv``.
    parameters : list of str
        The swept key paths (the columns between ``run`` and ``status``).

    Returns
    -------
    dict
        ``parameters``, ``varying`` (those that take more than one value), ``labels`` (the varying ones with text
        values, naming the curves), ``has_error``, ``runs`` (per row:
        ``parameters``, ``status``, ``error`` message, ``cost_s_per_s``, ``rms_error``, ``peak_ratio``),
        ``curves`` (label -> run indices by ascending cost, done runs with both numbers) and ``pareto`` (run
        indices on the front, by ascending cost).
    """
    def number(text):
        try:
            value = float(text)
        except (TypeError, ValueError):
            return None
        return value if math.isfinite(value) else None

    varying = [key for key in parameters if len({row.get(key) for row in rows}) > 1]
    labels = [key for key in varying if any(row.get(key) not in (None, "") and number(row[key]) is None
                                            for row in rows)]
    runs = []
    for row in rows:
        t_end, stepping = number(row.get("t_end")), number(row.get("stepping_seconds"))
        runs.append({"parameters": {key: row.get(key, "") for key in parameters}, "status": row.get("status"),
                     "error": row.get("error") or None,
                     "cost_s_per_s": stepping / t_end if t_end and stepping is not None else None,
                     "rms_error": number(row.get(ERROR_COLUMN)), "peak_ratio": number(row.get(PEAK_COLUMN))})
    plotted = [index for index, run in enumerate(runs)
               if run["status"] == "done" and run["cost_s_per_s"] is not None and run["rms_error"] is not None]
    curves: dict = {}
    for index in sorted(plotted, key=lambda index: runs[index]["cost_s_per_s"]):
        label = ", ".join(f"{key}={runs[index]['parameters'][key]}" for key in labels) or "all runs"
        curves.setdefault(label, []).append(index)
    front = pareto_front([runs[index]["cost_s_per_s"] for index in plotted],
                         [runs[index]["rms_error"] for index in plotted])
    return {"parameters": list(parameters), "varying": varying, "labels": labels,
            "has_error": any(ERROR_COLUMN in row for row in rows),
            "runs": runs, "curves": curves, "pareto": [plotted[index] for index in front]}


def _point_label(run, sweep) -> str:
    """The numeric swept values of a run that vary: its place along its curve."""
    return ", ".join(run["parameters"][key] for key in sweep["varying"] if key not in sweep["labels"])


def _described(run, sweep) -> str:
    """The varying swept values of a run, ``key=value, ...``."""
    return ", ".join(f"{key}={run['parameters'][key]}" for key in sweep["varying"]) or "the run"


def _percent(value) -> str:
    return "&ndash;" if value is None else f"{100 * value:.2g}%"


def sweep_figure(sweep: dict) -> str | None:
    """The trade curve as an SVG data URI (log-log: cost, error), or None for a sweep with nothing to plot."""
    if not sweep["curves"]:
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from validation.report.figures import log_ticks, svg_uri

    runs = sweep["runs"]
    figure, axes = plt.subplots(figsize=(7.5, 4.6))
    for number, (label, indices) in enumerate(sweep["curves"].items()):
        x = [runs[index]["cost_s_per_s"] for index in indices]
        y = [max(runs[index]["rms_error"], 1e-9) for index in indices]
        axes.loglog(x, y, "o-", color=f"C{number % 10}", lw=1, label=label)
        for index, point_x, point_y in zip(indices, x, y):
            text = _point_label(runs[index], sweep)
            if text:
                axes.annotate(text, (point_x, point_y), xytext=(4, 3), textcoords="offset points", fontsize=7,
                              color=f"C{number % 10}")
    front = sweep["pareto"]
    axes.loglog([runs[index]["cost_s_per_s"] for index in front],
                [max(runs[index]["rms_error"], 1e-9) for index in front], "s", ms=11, mfc="none", mec="k",
                label="Pareto front")
    axes.set_xlabel("wall time of the stepping per simulated second [s]")
    axes.set_ylabel("RMS displacement error vs FEM")
    axes.set_title("Your sweep: error against cost")
    axes.grid(alpha=0.3, which="both")
    log_ticks(axes)
    axes.legend(fontsize=8, loc="upper center", bbox_to_anchor=(0.5, -0.16), ncol=2, frameon=False)
    figure.tight_layout()
    return svg_uri(figure)


def sweep_section(index: int, sweep: dict, figures: dict) -> Section:
    """The sweep's section: what was swept, the cheapest run within each error level, the table, the figure."""
    from validation.report.sections import Section

    anchor, runs = f"sweep_{index}", sweep["runs"]
    scene = Path(sweep["scene_file"]).name if sweep.get("scene_file") else sweep["folder"]
    title = f"Your sweep: error against cost ({scene})"
    done = sum(run["status"] == "done" for run in runs)
    parts = [f"<h2 id='{anchor}'>{html.escape(title)}</h2>",
             f"<p>{len(runs)} runs of <code>{html.escape(str(sweep.get('scene_file') or scene))}</code> "
             f"(folder <code>{html.escape(sweep['folder'])}</code>), {done} done, over "
             f"{html.escape(', '.join(sweep['parameters']))}. Cost: wall time of the stepping per simulated second, "
             "each run's own (runs that shared the machine are slowed alike). Error: RMS nodal displacement error "
             "against the FEM answer of the same body at the end of the run (the scene's <code>[compare]</code>).</p>"]
    if not sweep["has_error"]:
        parts.append("<p class='warn'>The scene has no <code>[compare]</code> table, so its runs have no error "
                     "against FEM to plot: add <code>[compare]</code> <code>case = \"static_fem\"</code> to the "
                     "scene and run the sweep again.</p>")
    elif sweep["pareto"]:
        front = [runs[index] for index in sweep["pareto"]]
        described = "; ".join(f"{html.escape(_described(run, sweep))}: {_percent(run['rms_error'])} at "
                              f"{fmt(run['cost_s_per_s'])} s/s" for run in front)
        parts.append(f"<p><b>Pareto front</b> ({len(front)} of {done} runs, cheapest first): {described}.</p>")
    rows = []
    order = sorted(range(len(runs)), key=lambda k: (runs[k]["cost_s_per_s"] is None, runs[k]["cost_s_per_s"] or 0))
    for k in order:
        run = runs[k]
        rows.append([html.escape(value) for value in run["parameters"].values()]
                    + [fmt(run["status"]), fmt(run["cost_s_per_s"]), _percent(run["rms_error"]),
                       fmt(run["peak_ratio"]), "yes" if k in sweep["pareto"] else "",
                       fmt(run["error"])])
    parts.append(table([*sweep["parameters"], "status", "wall s per simulated s", "RMS error vs FEM",
                        "peak / FEM's", "Pareto", "error"], rows))
    parts.append(image(figures, anchor, "error against cost, one curve per model, the Pareto front marked"))
    return Section(anchor, title, "".join(parts))

