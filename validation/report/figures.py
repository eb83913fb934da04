"""The report's matplotlib figures, as SVG data URIs for embedding in report.html.

:func:`render_figures` draws what the results hold: the deflection profiles of the beams, the
refinement study, the volume change of the compression sweep, the speed-accuracy plane of the
integrators (each point labelled with its step) and the Cauchy limit. SVG stays crisp at any zoom and
on high-density screens (a PNG at 110 dpi was blurred). matplotlib is imported inside the functions
(Agg backend), so importing :mod:`validation.report` does not load it.
"""

from __future__ import annotations

import base64
import io
import math

import numpy as np
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from matplotlib.artist import Artist
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

__all__ = ["log_ticks", "model_label", "render_figures", "svg_uri"]


def svg_uri(figure: Figure) -> str:
    """The figure as an SVG data URI (closed afterwards); no date in it, so that a report depends on its numbers only."""
    import matplotlib.pyplot as plt

    buffer = io.BytesIO()
    with plt.rc_context({"svg.hashsalt": "volspring"}):  # fixed element ids: the same numbers, the same file
        figure.savefig(buffer, format="svg", bbox_inches="tight", metadata={"Date": None})
    plt.close(figure)
    return "data:image/svg+xml;base64," + base64.b64encode(buffer.getvalue()).decode("ascii")


def log_ticks(axes: Axes) -> None:
    """Readable log axes: no labels on the minor ticks (matplotlib labels them when an axis spans
    few decades, and "2x10^-1 3x10^-1 ..." overlap); an axis that holds fewer than two powers of ten
    gets majors at 1, 2 and 5 x 10^k, labelled as plain numbers, so it still has labels. Call after
    plotting: it reads the autoscaled limits."""
    from matplotlib import ticker

    for axis, scale, limits in ((axes.xaxis, axes.get_xscale(), axes.get_xlim()),
                                (axes.yaxis, axes.get_yscale(), axes.get_ylim())):
        if scale != "log":
            continue
        low, high = sorted(limits)
        if math.floor(math.log10(high)) - math.ceil(math.log10(low)) + 1 < 2:
            axis.set_major_locator(ticker.LogLocator(base=10.0, subs=(1.0, 2.0, 5.0)))
            axis.set_major_formatter(ticker.FuncFormatter(lambda value, position: f"{value:g}"))
        axis.set_minor_formatter(ticker.NullFormatter())


def model_label(model: str) -> str:
    """Display name of a model key: ``"fem_P2"`` -> ``"FEM P2 (reference)"``,
    ``"springs_lloyd"`` -> ``"springs: lloyd"``, ``"model_smoothed"`` -> ``"rung: smoothed"``."""
    if model.startswith("model_"):
        return "rung: " + model[len("model_"):]
    return {"fem_P2": "FEM P2 (reference)", "fem_P1": "FEM P1"}.get(model, model.replace("springs_", "springs: "))


def render_figures(results: dict) -> dict:
    """Every figure the results hold data for.

    Parameters
    ----------
    results : dict
        The results of :func:`validation.report.runner.run_validation`.

    Returns
    -------
    dict
        Figure key (``"profile_<case>"``, ``"refinement"``, ``"volume"``, ``"speed"``, ``"cauchy"``, ``"sweep_<i>"``)
        -> ``data:image/svg+xml;base64,...`` URI; a figure without data is left out.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    figures = {}
    for name in ("cantilever_gravity", "cantilever_end_load"):
        profile = results["cases"].get(name, {}).get("beam_profile")
        if not profile:
            continue
        figure, axes = plt.subplots(figsize=(6.4, 3.8))
        x = np.array(profile["x_m"])
        axes.plot(x, 1e3 * np.array(profile["beam_theory_m"]), "k--", label="beam theory (Timoshenko)")
        for key, values in profile.items():
            if key in ("x_m", "beam_theory_m"):
                continue
            model = key[:-2]
            axes.plot(x, 1e3 * np.array(values), "o-" if model == "fem_P2" else ".-", ms=3, label=model_label(model))
        axes.set_xlabel("x along the beam [m]")
        axes.set_ylabel("deflection [mm]")
        axes.set_title(results["cases"][name]["title"])
        axes.legend(fontsize=8)
        axes.grid(alpha=0.3)
        figures[f"profile_{name}"] = svg_uri(figure)
    refinement = results["studies"].get("refinement")
    if refinement:
        figure, axes = plt.subplots(figsize=(6.4, 4.2))
        n = np.array(refinement["node_counts"])
        for model, errors in refinement["tip_deflection_error"].items():
            rate = refinement["rates_per_node_count"][model]
            label = f"{model_label(model)} (slope {rate:.2f})" if rate is not None else model_label(model)
            axes.loglog(n, np.maximum(np.abs(errors), 1e-16), "o-", label=label)
        axes.set_xlabel("nodes")
        axes.set_ylabel("|tip deflection error| vs converged P2")
        axes.set_title("Cantilever under gravity: refinement")
        axes.legend(fontsize=8)
        axes.grid(alpha=0.3, which="both")
        log_ticks(axes)
        axes.set_xticks(n, [str(count) for count in n])  # the node counts studied, not powers of ten
        figures["refinement"] = svg_uri(figure)
    sweep = results["cases"].get("uniaxial_compression", {}).get("sweep")
    if sweep:
        figure, axes = plt.subplots(figsize=(6.4, 4.2))
        rows = sweep["rows"]
        strains = sorted({row["strain"] for row in rows})
        line = np.array([min(strains), 0.0])
        for index, nu in enumerate(sorted({row["nu"] for row in rows})):
            color = f"C{index}"
            mine = [row for row in rows if row["nu"] == nu]
            axes.plot(100 * line, 100 * (1 - 2 * nu) * line, "-", color=color, lw=1, label=f"exact, nu = {nu:g}")
            axes.plot([100 * r["strain"] for r in mine], [100 * r["fem_P2_volume_strain"] for r in mine], "o",
                      color=color, mfc="none", label=f"FEM P2, nu = {nu:g}")
        for index, rule in enumerate(results["rules"]):
            mine = [row for row in rows if row["nu"] == rows[0]["nu"]]
            axes.plot([100 * r["strain"] for r in mine], [100 * r[f"springs_{rule}_volume_strain"] for r in mine],
                      "s--", color=f"C{index + 5}", label=f"springs: {rule} (any nu)")
        axes.set_xlabel("axial strain [%]")
        axes.set_ylabel("volume change dV/V [%]")
        axes.set_title("Uniaxial compression: volume change")
        axes.legend(fontsize=7, ncol=2)
        axes.grid(alpha=0.3)
        figures["volume"] = svg_uri(figure)
    speed = results["studies"].get("speed")
    if speed:
        figure, panels = plt.subplots(1, 2, figsize=(11, 4.2))
        for axes, key, title in ((panels[0], "first_frequency_error", "first frequency"),
                                 (panels[1], "settled_deflection_error", "settled deflection")):
            names = list(dict.fromkeys(run["integrator"] for run in speed["runs"]))
            for index, name in enumerate(names):
                runs = [r for r in speed["runs"] if r["integrator"] == name and r.get(key) is not None]
                if not runs:
                    continue
                unit = "dt_crit" if runs[0]["step_unit"] == "critical step" else "2/omega_max"
                x = [r["wall_seconds_per_simulated_second"] for r in runs]
                y = [max(abs(r[key]), 1e-9) for r in runs]
                axes.loglog(x, y, "o", color=f"C{index}", label=f"{name} (step in {unit})")
                # Each point says its step; integrators whose points fall together (the Verlet family at one
                # step) put their labels on different corners of the point.
                corner = ((4, 3), (4, -9), (-16, 3), (-16, -9))[index % 4]
                for run, point_x, point_y in zip(runs, x, y):
                    axes.annotate(f"{run['step_factor']:g}", (point_x, point_y), xytext=corner,
                                  textcoords="offset points", fontsize=7, color=f"C{index}")
            front = sorted((r for r in speed["runs"] if key in r.get("pareto", [])),
                           key=lambda r: r["wall_seconds_per_simulated_second"])
            if front:
                axes.plot([r["wall_seconds_per_simulated_second"] for r in front],
                          [max(abs(r[key]), 1e-9) for r in front], "k-", lw=1, label="Pareto front")
            model_error = abs(speed["model_frequency_error" if key == "first_frequency_error"
                                    else "model_deflection_error"])
            axes.axhline(model_error, color="grey", ls=":", label="springs vs FEM P2 (model error)")
            axes.set_xlabel("wall time per simulated second [s]")
            axes.set_ylabel(f"|{title} error|\nvs the spring model's own answer")
            axes.set_title(f"Speed vs accuracy: {title}")
            axes.grid(alpha=0.3, which="both")
            log_ticks(axes)
        # One legend for both panels, below them: inside a panel it hides the points.
        legend: dict[str, Artist] = {}
        for axes in panels:
            for handle, label in zip(*axes.get_legend_handles_labels()):
                legend.setdefault(label, handle)
        figure.legend(legend.values(), legend.keys(), loc="upper center", bbox_to_anchor=(0.5, 0.0), ncol=4,
                      fontsize=8, frameon=False)
        figure.tight_layout()
        figures["speed"] = svg_uri(figure)
    cauchy = results["studies"].get("cauchy")
    if cauchy:
        figure, axes = plt.subplots(figsize=(6.4, 4.2))
        asked = sorted({m["nu_asked"] for m in cauchy["measurements"]})
        axes.plot(asked, asked, "k--", label="asked")
        rule_colors = {rule: f"C{index}" for index, rule in enumerate(dict.fromkeys(
            key.split("/")[1] for key in cauchy["summary"]))}
        for key in cauchy["summary"]:
            pattern, rule = key.split("/")
            mine = [m for m in cauchy["measurements"] if m["pattern"] == pattern and m["rule"] == rule]
            axes.plot([m["nu_asked"] for m in mine], [m["nu_effective"] for m in mine], "o-" if pattern == "mirrored"
                      else "x:", color=rule_colors[rule], label=f"{rule} ({pattern} mesh)")
        axes.set_xlabel("nu asked")
        axes.set_ylabel("effective nu of the spring network")
        axes.set_title("The Cauchy limit: one nu whatever is asked")
        axes.legend(fontsize=7)
        axes.grid(alpha=0.3)
        figures["cauchy"] = svg_uri(figure)
    for index, sweep in enumerate(results.get("sweeps", [])):  # a user's sweeps: validation.report.trade
        from validation.report.trade import sweep_figure

        uri = sweep_figure(sweep)
        if uri is not None:
            figures[f"sweep_{index}"] = uri
    return figures

