"""Run the validation and write what a user reads: report.html, results.json and VTU files.

:func:`run_validation` runs the cases and studies and returns the results (plain JSON numbers,
every key naming its unit) with the arrays for figures and VTU files; :func:`write_outputs`
writes ``DIR/report.html`` (self-contained: tables, matplotlib figures as base64 PNG),
``DIR/results.json`` and ``DIR/vtu/*.vtu``; :func:`validate` does both. All writes are atomic.

results.json layout (units in the key names: ``_m``, ``_m3``, ``_hz``, ``_pa``, ``_s``,
``_n_per_m``; ``*_error`` are signed relative errors, (value - reference) / |reference|, 0.01 = 1%):

- ``schema``, ``created``, ``command``, ``quick``, ``versions`` (python, numpy, scipy, scikit-fem,
  pyamg, meshio, matplotlib, volspring), ``units``, ``notes``;
- ``cases.<name>``: ``parameters``, ``mesh`` (node_count, tet_count, cells), ``analytic``,
  ``fem.P2`` / ``fem.P1`` (tip_deflection_m, volume_change_m3, deformed_volume_change_m3, ...),
  ``springs.<rule>`` (tip_deflection_m, tip_deflection_error, rms_displacement_error,
  max_displacement_error, volume_change_m3, volume_change_error_vs_fem,
  volume_change_error_vs_analytic, solver, ...), ``beam_profile`` for beams, ``sweep`` for the
  compression case; modal case: ``fem.P2.frequencies_hz``, ``springs.<rule>.frequencies_hz``,
  ``first_frequency_error``;
- ``studies.refinement``, ``studies.speed``, ``studies.cauchy`` (see :mod:`validation.studies`);
- ``headline.<rule>``: the figures the README quotes;
- ``files``: the VTU files written and the models in them.
"""

from __future__ import annotations

import base64
import datetime
import html
import io
import json
import logging
import math
import platform
from pathlib import Path

import numpy as np

from validation import studies
from validation.cases import build_case, uniaxial_compression
from validation.compare import RULES, compare_modes, compare_static
from volspring._io import atomic_path
from volspring.mesh import TetMesh

__all__ = ["SCHEMA", "run_validation", "validate", "versions", "write_outputs"]

logger = logging.getLogger(__name__)

SCHEMA = "volspring-validate/1"
STATIC_CASES = ("cantilever_gravity", "cantilever_end_load", "hanging_bar", "uniaxial_compression")
BUILT_IN = STATIC_CASES + ("cantilever_modes",)
STUDIES = ("refinement", "speed", "cauchy")
#: Poisson ratios and axial strains of the compression sweep (volume change against strain).
SWEEP_NUS = (0.0, 0.3, 0.45, 0.49)
SWEEP_STRAINS = (-0.0025, -0.005, -0.01)

UNITS = {"_m": "metre", "_m3": "cubic metre", "_hz": "hertz", "_pa": "pascal", "_s": "second",
         "_n": "newton", "_n_per_m": "newton per metre", "_kg_per_m3": "kilogram per cubic metre",
         "_m_per_s2": "metre per second squared", "_per_s": "1 / second", "_rad_per_s": "radian per second",
         "_error": "relative error (value - reference) / |reference|, dimensionless (0.01 = 1%)",
         "nu": "Poisson ratio, dimensionless", "strain": "dimensionless"}

NOTES = [
    "Spring stiffness rules: van_gelder and lloyd from E (nu is not used by either rule); uniform gives every "
    "spring one constant, the mean van_gelder constant of the same mesh.",
    "Spring statics: Newton on the nonlinear springs (volspring.statics) where the clamps hold whole nodes; the "
    "compression case has sliding supports, which volspring.Pins cannot hold, so its spring side is the "
    "linearised solve with the rest stiffness (exact in the small-strain limit).",
    "FEM reference: P2 tetrahedra on the same mesh (scikit-fem), cached on disk; P1 shown for comparison (it "
    "locks in bending).",
    "Structured meshes split each cell into six Kuhn tets, mirrored in alternate cells: a network on the "
    "unmirrored Kuhn grid couples stretch to shear (a hanging bar sways sideways).",
    "Loads are chosen so that the largest displacement stays about 0.5% of the length: linear elasticity "
    "is the right reference there.",
]


def versions() -> dict:
    """Versions of Python and the libraries the numbers depend on."""
    import importlib.metadata as metadata

    found = {"python": platform.python_version()}
    for name, distribution in (("numpy", "numpy"), ("scipy", "scipy"), ("scikit-fem", "scikit-fem"),
                               ("pyamg", "pyamg"), ("meshio", "meshio"), ("matplotlib", "matplotlib")):
        try:
            found[name] = metadata.version(distribution)
        except metadata.PackageNotFoundError:
            found[name] = None
    import volspring

    found["volspring"] = volspring.__version__
    return found


# ---------------------------------------------------------------------------- running
def _settings(quick: bool) -> dict:
    """What ``--quick`` trims. The speed study runs five periods of the loaded mode with a drag that
    leaves 5e-5 of the motion at the end (a damping ratio of 0.32): its cost is the step count, so
    the full run's finer beam (twice omega_max, half the critical step) gets the same simulated
    time, not more. Measured on 2 cores: quick about 25 s, full about 90 s (three quarters of it the
    speed study; up to 3 minutes on a shared machine)."""
    if quick:
        return {"refinement_levels": (1, 2), "reference_level": 4, "speed_per_height": 1,
                "speed_steps": studies.QUICK_INTEGRATOR_STEPS, "speed_periods": 5.0,
                "speed_residual_amplitude": 5e-5, "cauchy_cells": 3}
    return {"refinement_levels": (1, 2, 3, 4), "reference_level": 6, "speed_per_height": 2,
            "speed_steps": studies.INTEGRATOR_STEPS, "speed_periods": 5.0, "speed_residual_amplitude": 5e-5,
            "cauchy_cells": 4}


def run_validation(*, cases=None, quick: bool = False, own_case=None, rules=RULES, folder=None,
                   progress=None) -> tuple:
    """Run cases and studies.

    Parameters
    ----------
    cases : sequence of str, optional -- built-in case and study names (``BUILT_IN`` and ``STUDIES``);
        default all of them, or none when ``own_case`` is given
    quick : bool -- coarse meshes and short runs (about a minute in all)
    own_case : Case, optional -- a user's mesh (:func:`validation.cases.own_mesh_case`)
    rules : sequence of str -- spring stiffness rules
    folder : path, optional -- FEM cache folder
    progress : callable, optional -- ``progress(fraction, message)``, fraction in [0, 1]

    Returns
    -------
    (results, artefacts) -- results: JSON-ready dict (module docstring); artefacts: the
    :class:`~validation.compare.Comparison` of each case, for VTU files
    """
    if cases is None or len(cases) == 0:
        cases = () if own_case is not None else BUILT_IN + STUDIES
    unknown = [name for name in cases if name not in BUILT_IN + STUDIES]
    if unknown:
        raise ValueError(f"unknown case {unknown[0]!r}; known: {', '.join(BUILT_IN + STUDIES)}")
    settings = _settings(quick)
    weights = {"cantilever_gravity": 1, "cantilever_end_load": 1, "hanging_bar": 1, "uniaxial_compression": 2,
               "cantilever_modes": 1, "refinement": 4, "speed": 12 if quick else 40, "cauchy": 1, "own_mesh": 3}
    tasks = list(cases) + (["own_mesh"] if own_case is not None else [])
    total = float(sum(weights[name] for name in tasks))
    done = 0.0
    report = progress or (lambda fraction, message: None)

    def note(message):
        report(min(done / total, 1.0), message)

    results = {"schema": SCHEMA, "created": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
               "quick": bool(quick), "versions": versions(), "units": UNITS, "notes": NOTES, "rules": list(rules),
               "settings": {key: value for key, value in settings.items() if key != "speed_steps"},
               "cases": {}, "studies": {}}
    results["settings"]["speed_steps"] = {key: list(value) for key, value in settings["speed_steps"].items()}
    artefacts = {}
    for name in tasks:
        note(name)
        if name in STATIC_CASES or name == "own_mesh":
            case = own_case if name == "own_mesh" else build_case(name, quick=quick)
            comparison = compare_static(case, rules=rules, folder=folder, progress=note)
            results["cases"][name] = comparison.results
            artefacts[name] = comparison
            if name == "uniaxial_compression":
                results["cases"][name]["sweep"] = _compression_sweep(quick, rules, folder, note)
        elif name == "cantilever_modes":
            comparison = compare_modes(build_case(name, quick=quick), rules=rules, folder=folder, progress=note)
            results["cases"][name] = comparison.results
            artefacts[name] = comparison
        elif name == "refinement":
            results["studies"]["refinement"] = studies.refinement_study(
                settings["refinement_levels"], reference_level=settings["reference_level"], rules=rules,
                folder=folder, progress=note)
        elif name == "speed":
            results["studies"]["speed"] = studies.speed_study(
                per_height=settings["speed_per_height"], steps=settings["speed_steps"],
                periods=settings["speed_periods"], residual_amplitude=settings["speed_residual_amplitude"],
                folder=folder, progress=note)
        elif name == "cauchy":
            results["studies"]["cauchy"] = studies.cauchy_study(cells=settings["cauchy_cells"], rules=rules)
        done += weights[name]
    results["headline"] = _headline(results, rules)
    report(1.0, "done")
    return results, artefacts


def _compression_sweep(quick, rules, folder, note) -> dict:
    """Volume change against axial strain for several nu: FEM P2, springs (linearised), closed form."""
    cells = 3 if quick else 4
    rows = []
    for nu in SWEEP_NUS:
        for strain in SWEEP_STRAINS:
            note(f"uniaxial_compression: nu = {nu:g}, strain = {strain:g}")
            comparison = compare_static(uniaxial_compression(cells=cells, nu=nu, strain=strain), rules=rules,
                                        elements=("P2",), folder=folder)
            volume = comparison.case.mesh.volume
            rows.append({"nu": nu, "strain": strain, "analytic_volume_strain": (1 - 2 * nu) * strain,
                         "fem_P2_volume_strain": comparison.results["fem"]["P2"]["deformed_volume_change_m3"] / volume,
                         **{f"springs_{rule}_volume_strain": comparison.results["springs"][rule]["volume_change_m3"]
                            / volume for rule in rules}})
    return {"cells": cells, "rows": rows}


def _headline(results, rules) -> dict:
    cases = results["cases"]
    cauchy = results["studies"].get("cauchy")
    headline = {}
    for rule in rules:
        row = {}
        for name in ("cantilever_gravity", "cantilever_end_load", "hanging_bar", "own_mesh"):
            if name in cases:
                row[f"{name}_tip_deflection_error"] = cases[name]["springs"][rule]["tip_deflection_error"]
        for name in ("hanging_bar", "uniaxial_compression", "own_mesh"):
            if name in cases:
                row[f"{name}_volume_change_error_vs_fem"] = cases[name]["springs"][rule]["volume_change_error_vs_fem"]
        if "cantilever_modes" in cases:
            row["first_frequency_error"] = cases["cantilever_modes"]["springs"][rule]["first_frequency_error"]
        if cauchy:
            mirrored = [m for m in cauchy["measurements"] if m["rule"] == rule and m["pattern"] == "mirrored"]
            if mirrored:
                row["nu_effective"] = mirrored[0]["nu_effective"]
                row["E_effective_ratio"] = mirrored[0]["E_ratio"]
        headline[rule] = row
    return headline


# ---------------------------------------------------------------------------- outputs
def validate(out, *, cases=None, quick: bool = False, own_case=None, rules=RULES, folder=None, progress=None,
             command=None, record=None) -> dict:
    """:func:`run_validation` then :func:`write_outputs` into ``out``; returns the results.

    ``record`` is passed on to :func:`write_outputs`.
    """
    results, artefacts = run_validation(cases=cases, quick=quick, own_case=own_case, rules=rules, folder=folder,
                                        progress=progress)
    results["command"] = command
    write_outputs(out, results, artefacts, record=record)
    return results


def write_outputs(out, results: dict, artefacts: dict, *, record=None) -> dict:
    """Write ``out/vtu/*.vtu``, ``out/results.json`` and ``out/report.html`` (in that order, each atomic).

    Parameters
    ----------
    out : path-like
        The report folder, created if missing.
    results : dict
        The results of :func:`run_validation`.
    artefacts : dict
        The comparisons of :func:`run_validation`, for the VTU files.
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
    figures = _figures(results)
    with atomic_path(out / "results.json") as tmp:
        tmp.write_text(json.dumps(_clean(results), indent=1, allow_nan=False))
    written["results.json"] = out / "results.json"
    with atomic_path(out / "report.html") as tmp:
        tmp.write_text(_html(results, figures), encoding="utf-8")
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


# ---------------------------------------------------------------------------- figures
def _png(figure) -> str:
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=110, bbox_inches="tight")
    import matplotlib.pyplot as plt

    plt.close(figure)
    return base64.b64encode(buffer.getvalue()).decode("ascii")


def _log_ticks(axes) -> None:
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


def _label(model: str) -> str:
    return {"fem_P2": "FEM P2 (reference)", "fem_P1": "FEM P1"}.get(model, model.replace("springs_", "springs: "))


def _figures(results: dict) -> dict:
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
            axes.plot(x, 1e3 * np.array(values), "o-" if model == "fem_P2" else ".-", ms=3, label=_label(model))
        axes.set_xlabel("x along the beam [m]")
        axes.set_ylabel("deflection [mm]")
        axes.set_title(results["cases"][name]["title"])
        axes.legend(fontsize=8)
        axes.grid(alpha=0.3)
        figures[f"profile_{name}"] = _png(figure)
    refinement = results["studies"].get("refinement")
    if refinement:
        figure, axes = plt.subplots(figsize=(6.4, 4.2))
        n = np.array(refinement["node_counts"])
        for model, errors in refinement["tip_deflection_error"].items():
            rate = refinement["rates_per_node_count"][model]
            label = f"{_label(model)} (slope {rate:.2f})" if rate is not None else _label(model)
            axes.loglog(n, np.maximum(np.abs(errors), 1e-16), "o-", label=label)
        axes.set_xlabel("nodes")
        axes.set_ylabel("|tip deflection error| vs converged P2")
        axes.set_title("Cantilever under gravity: refinement")
        axes.legend(fontsize=8)
        axes.grid(alpha=0.3, which="both")
        _log_ticks(axes)
        axes.set_xticks(n, [str(count) for count in n])  # the node counts studied, not powers of ten
        figures["refinement"] = _png(figure)
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
        figures["volume"] = _png(figure)
    speed = results["studies"].get("speed")
    if speed:
        figure, panels = plt.subplots(1, 2, figsize=(11, 4.2))
        for axes, key, title in ((panels[0], "first_frequency_error", "first frequency"),
                                 (panels[1], "settled_deflection_error", "settled deflection")):
            names = list(dict.fromkeys(run["integrator"] for run in speed["runs"]))
            for index, name in enumerate(names):
                runs = [r for r in speed["runs"] if r["integrator"] == name and r.get(key) is not None]
                if runs:
                    axes.loglog([r["wall_seconds_per_simulated_second"] for r in runs],
                                [max(abs(r[key]), 1e-9) for r in runs], "o", color=f"C{index}", label=name)
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
            _log_ticks(axes)
        # One legend for both panels, below them: inside a panel it hides the points.
        legend = {}
        for axes in panels:
            for handle, label in zip(*axes.get_legend_handles_labels()):
                legend.setdefault(label, handle)
        figure.legend(legend.values(), legend.keys(), loc="upper center", bbox_to_anchor=(0.5, 0.0), ncol=4,
                      fontsize=8, frameon=False)
        figure.tight_layout()
        figures["speed"] = _png(figure)
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
        figures["cauchy"] = _png(figure)
    return figures


# ---------------------------------------------------------------------------- HTML
def _fmt(value, kind="number") -> str:
    if value is None:
        return "&ndash;"
    if isinstance(value, str):
        return html.escape(value)
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, (list, tuple)):
        return "(" + ", ".join(_fmt(v) for v in value) + ")"
    if kind == "percent":
        return f"{100 * value:+.1f}%"
    if kind == "percent_small":  # two significant digits: integrator errors are often far below 0.1%
        return f"{100 * value:+.2g}%"
    if isinstance(value, (int, np.integer)):
        return str(value)
    return f"{value:.4g}"


def _table(header, rows) -> str:
    head = "".join(f"<th>{html.escape(str(h))}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{cell}</td>" for cell in row) + "</tr>" for row in rows)
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def _image(figures, key, alt) -> str:
    if key not in figures:
        return ""
    return f'<figure><img alt="{html.escape(alt)}" src="data:image/png;base64,{figures[key]}"></figure>'


def _case_html(name, case, figures) -> str:
    parts = [f"<h2 id='{name}'>{html.escape(case['title'])}</h2>"]
    mesh = case["mesh"]
    parameters = ", ".join(f"{k} = {_fmt(v)}" for k, v in case["parameters"].items())
    parts.append(f"<p class='small'>{mesh['node_count']} nodes, {mesh['tet_count']} tets"
                 f"{', cells ' + ' x '.join(map(str, mesh['cells'])) if mesh.get('cells') else ''}. {parameters}</p>")
    if case.get("warning"):
        parts.append(f"<p class='warn'>{html.escape(case['warning'])}</p>")
    if case["kind"] == "modes":
        fem = case["fem"]["P2"]
        rows = [["FEM P2 (reference)"] + [_fmt(f) for f in fem["frequencies_hz"]] + ["&ndash;"]]
        for rule, values in case["springs"].items():
            rows.append([f"springs: {rule}"] + [_fmt(f) for f in values["frequencies_hz"]]
                        + [_fmt(values["first_frequency_error"], "percent")])
        count = len(fem["frequencies_hz"])
        parts.append(_table(["model"] + [f"f{k + 1} [Hz]" for k in range(count)] + ["f1 error vs P2"], rows))
        parts.append(f"<p>Euler-Bernoulli: first bending frequency {_fmt(case['analytic']['first_frequency_hz'])} Hz "
                     "(a square section has a degenerate pair, y and z; springs on a coarse mesh split it).</p>")
        return "".join(parts)
    analytic = case["analytic"]
    rows = []
    for element, values in case["fem"].items():
        rows.append([f"FEM {element}" + (" (reference)" if element == "P2" else ""),
                     _fmt(1e3 * values["tip_deflection_m"]), _fmt(values.get("tip_deflection_error"), "percent"),
                     _fmt(values.get("rms_displacement_error"), "percent"),
                     _fmt(values.get("max_displacement_error"), "percent"),
                     _fmt(values["deformed_volume_change_m3"]), "&ndash;", "&ndash;"])
    for rule, values in case["springs"].items():
        rows.append([f"springs: {rule} ({values['solver']})", _fmt(1e3 * values["tip_deflection_m"]),
                     _fmt(values["tip_deflection_error"], "percent"), _fmt(values["rms_displacement_error"], "percent"),
                     _fmt(values["max_displacement_error"], "percent"), _fmt(values["volume_change_m3"]),
                     _fmt(values["volume_change_error_vs_fem"], "percent"),
                     _fmt(values["volume_change_error_vs_analytic"], "percent")])
    parts.append(_table(["model", "tip [mm]", "tip error", "RMS error", "max error", "volume change [m^3]",
                         "volume vs FEM", "volume vs exact"], rows))
    theory = ", ".join(f"{k} = {_fmt(v)}" for k, v in analytic.items())
    parts.append(f"<p class='small'>Closed form: {theory}. Errors are relative to FEM P2 on the same mesh; RMS and max "
                 "nodal errors relative to the reference's RMS and max displacement.</p>")
    parts.append(_image(figures, f"profile_{name}", f"deflection along the beam, {name}"))
    if name == "uniaxial_compression":
        parts.append(_image(figures, "volume", "volume change against strain"))
    return "".join(parts)


def _html(results: dict, figures: dict) -> str:
    parts = []
    rules = results["rules"]
    headline = results.get("headline", {})
    if headline:
        keys = list(dict.fromkeys(key for row in headline.values() for key in row))
        rows = [[rule] + [_fmt(headline[rule].get(key), "number" if key in ("nu_effective", "E_effective_ratio")
                                else "percent") for key in keys] for rule in rules]
        parts.append("<h2>Headline</h2>" + _table(["rule"] + [key.replace("_", " ") for key in keys], rows))
    cauchy = results["studies"].get("cauchy")
    if cauchy:
        statements = []
        for key, summary in cauchy["summary"].items():
            pattern, rule = key.split("/")
            mine = [m for m in cauchy["measurements"] if m["pattern"] == pattern and m["rule"] == rule]
            statements.append([rule, pattern, _fmt(summary["nu_effective_min"]), _fmt(summary["nu_effective_max"]),
                               ", ".join(_fmt(m["nu_asked"]) for m in mine), _fmt(mine[0]["E_ratio"]),
                               _fmt(mine[0]["volume_strain_per_axial_strain"])])
        parts.append(
            "<h2 id='cauchy'>The pure-spring limit (Cauchy)</h2><p><b>A network of central springs has one effective "
            "Poisson ratio whatever nu is asked.</b> Uniaxial stress on a unit cube of "
            f"{cauchy['cells']}<sup>3</sup> cells: the measured effective nu below is the same for every asked nu "
            "(the rules use E only), so volume change under load is wrong for any material that is not near it; "
            "for nearly incompressible materials (nu = 0.45: exact dV/(V eps) = 0.10) springs lose several times "
            "too much volume.</p>"
            + _table(["rule", "mesh", "nu effective (min)", "(max)", "nu asked", "E_eff / E",
                      "dV/(V eps) (exact 1 - 2 nu)"], statements)
            + _image(figures, "cauchy", "effective nu against asked nu"))
    for name, case in results["cases"].items():
        parts.append(_case_html(name, case, figures))
    refinement = results["studies"].get("refinement")
    if refinement:
        rows = []
        for model, errors in refinement["tip_deflection_error"].items():
            rows.append([_label(model)] + [_fmt(e, "percent") for e in errors]
                        + [_fmt(refinement["rates_per_node_count"][model]),
                           _fmt(refinement["rates_per_mesh_size"][model])])
        header = ["model"] + [f"{n} nodes" for n in refinement["node_counts"]] + ["slope in N", "rate in h"]
        parts.append("<h2 id='refinement'>Refinement: cantilever under gravity</h2>"
                     f"<p>Tip deflection error against P2 on {refinement['reference']['node_count']} nodes "
                     f"({_fmt(1e3 * refinement['reference_tip_deflection_m'])} mm; beam theory "
                     f"{_fmt(1e3 * refinement['beam_theory_tip_deflection_m'])} mm). Springs converge to a network, "
                     "not to the continuum: their slope says how fast they drift.</p>"
                     + _table(header, rows) + _image(figures, "refinement", "error against node count"))
    speed = results["studies"].get("speed")
    if speed:
        rows = []
        for run in speed["runs"]:
            rows.append([run["integrator"], f"{run['step_factor']:g} x {run['step_unit']}", _fmt(run["dt_s"]),
                         _fmt(run["stable"]), _fmt(run["wall_seconds_per_simulated_second"]),
                         _fmt(run.get("settled_deflection_error"), "percent_small"),
                         _fmt(run.get("first_frequency_error"), "percent_small"),
                         _fmt(run.get("first_frequency_error_vs_fem"), "percent"),
                         ", ".join(run.get("pareto", [])).replace("_error", "") or ""])
        parts.append(
            "<h2 id='speed'>Speed and accuracy of the integrators</h2>"
            f"<p>The spring cantilever ({speed['node_count']} nodes, rule {speed['rule']}) released from rest under "
            f"gravity, {_fmt(speed.get('periods'))} periods of the mode gravity loads ({_fmt(speed['duration_s'])} s) "
            f"simulated with a drag of {_fmt(speed['drag_rate_per_s'])} /s (damping ratio "
            f"{_fmt(speed.get('damping_ratio'))}) that leaves {_fmt(speed.get('residual_amplitude'))} of the motion "
            "at the end; wall time per simulated second is over the time a run reached (a diverged run stops "
            "early). omega_max = "
            f"{_fmt(speed['omega_max_rad_per_s'])} rad/s. Errors against the spring model's own static equilibrium "
            f"({_fmt(1e3 * speed['spring_settled_deflection_m'])} mm) and first frequency "
            f"({_fmt(speed['spring_first_frequency_hz'])} Hz); the model itself is "
            f"{_fmt(speed['model_deflection_error'], 'percent')} (deflection) and "
            f"{_fmt(speed['model_frequency_error'], 'percent')} (frequency) from FEM P2.</p>"
            + _table(["integrator", "step", "dt [s]", "stable", "wall s per simulated s", "settled error",
                      "f1 error", "f1 error vs FEM", "Pareto"], rows)
            + _image(figures, "speed", "speed against accuracy"))
    files = results.get("files", {})
    if files:
        rows = [[name, ", ".join(info["vtu"]), ", ".join(info["models"])] for name, info in files.items()]
        parts.append("<h2>Files for ParaView</h2><p>Each case's file holds every model's displacement as point "
                     "data (Warp By Vector); the side-by-side file holds one copy per model, cell data "
                     "<code>model</code> numbering them in the order listed.</p>"
                     + _table(["case", "files", "models"], rows))
    notes = "".join(f"<li>{html.escape(note)}</li>" for note in results.get("notes", []))
    versions_text = ", ".join(f"{k} {v}" for k, v in results["versions"].items())
    command = " ".join(results.get("command") or [])
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>volspring validation</title>
<style>
body {{ font-family: sans-serif; max-width: 1150px; margin: 2em auto; color: #222; }}
table {{ border-collapse: collapse; margin: 0.8em 0; font-size: 0.9em; }}
th, td {{ border: 1px solid #ccc; padding: 0.25em 0.6em; text-align: right; }}
th:first-child, td:first-child {{ text-align: left; }}
thead {{ background: #f0f0f0; }}
img {{ max-width: 100%; }}
.small {{ font-size: 0.85em; color: #555; }}
.warn {{ color: #a00; }}
</style></head><body>
<h1>volspring: springs against linear-elastic FEM</h1>
<p class="small">{html.escape(results['created'])} &middot; {'quick' if results['quick'] else 'full'} run
&middot; <code>{html.escape(command)}</code><br>{html.escape(versions_text)}</p>
<ul class="small">{notes}</ul>
{''.join(parts)}
</body></html>
"""

