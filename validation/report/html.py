"""The report page: one self-contained HTML file (tables, figures as base64 PNG, no script, no links out).

:func:`render_html` lays out the results of :func:`validation.report.runner.run_validation`: first the
ladder of models (each rung's error against P2 beside its cost per step and matrix size), then the
headline errors, the Cauchy limit, one section per case, the refinement and speed studies and the
VTU files for ParaView, with the figures of :func:`validation.report.figures.render_figures`.
"""

from __future__ import annotations

import html

import numpy as np

from validation.report.figures import model_label

__all__ = ["render_html"]


def _fmt(value, kind="number") -> str:
    """A table cell: None as a dash, text escaped, ``kind`` "percent" / "percent_small" as signed percents."""
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


def _table(header, rows, *, extra="") -> str:
    """A table of ready cells; ``extra``: more rows as HTML (a refusal spanning the row)."""
    head = "".join(f"<th>{html.escape(str(h))}</th>" for h in header)
    body = "".join("<tr>" + "".join(f"<td>{cell}</td>" for cell in row) + "</tr>" for row in rows)
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}{extra}</tbody></table>"


def _answers(case):
    """(label, values) of each spring rule, then of each rung of the ladder that answered."""
    for rule, values in case["springs"].items():
        yield f"springs: {rule}", values
    for rung, values in case.get("models", {}).items():
        if "refused" not in values:
            yield f"rung: {rung}", values


def _refusals(case, width) -> str:
    return "".join(_refused_row([f"rung: {html.escape(rung)}"], values["refused"], width)
                   for rung, values in case.get("models", {}).items() if "refused" in values)


def _refused_row(labels, message, width) -> str:
    """A table row: the cells ``labels`` (ready HTML), then the refusal ``message`` across ``width`` columns."""
    return ("<tr>" + "".join(f"<td>{label}</td>" for label in labels)
            + f"<td colspan='{width}' class='warn' style='text-align: left'>refused: {html.escape(message)}</td></tr>")


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
        for label, values in _answers(case):
            rows.append([label] + [_fmt(f) for f in values["frequencies_hz"]]
                        + [_fmt(values["first_frequency_error"], "percent")])
        count = len(fem["frequencies_hz"])
        parts.append(_table(["model"] + [f"f{k + 1} [Hz]" for k in range(count)] + ["f1 error vs P2"], rows,
                            extra=_refusals(case, count + 1)))
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
    for label, values in _answers(case):
        rows.append([f"{label} ({values['solver']})", _fmt(1e3 * values["tip_deflection_m"]),
                     _fmt(values["tip_deflection_error"], "percent"), _fmt(values["rms_displacement_error"], "percent"),
                     _fmt(values["max_displacement_error"], "percent"), _fmt(values["volume_change_m3"]),
                     _fmt(values["volume_change_error_vs_fem"], "percent"),
                     _fmt(values["volume_change_error_vs_analytic"], "percent")])
    parts.append(_table(["model", "tip [mm]", "tip error", "RMS error", "max error", "volume change [m^3]",
                         "volume vs FEM", "volume vs exact"], rows, extra=_refusals(case, 7)))
    theory = ", ".join(f"{k} = {_fmt(v)}" for k, v in analytic.items())
    parts.append(f"<p class='small'>Closed form: {theory}. Errors are relative to FEM P2 on the same mesh; RMS and max "
                 "nodal errors relative to the reference's RMS and max displacement.</p>")
    parts.append(_image(figures, f"profile_{name}", f"deflection along the beam, {name}"))
    if name == "uniaxial_compression":
        parts.append(_image(figures, "volume", "volume change against strain"))
    return "".join(parts)


def _blocks(row) -> str:
    """The system's 3x3 blocks, and in parentheses those assembled per step when fewer (matrix-free sets)."""
    assembled = row.get("assembled_block_count")
    if assembled is None or assembled == row["block_count"]:
        return _fmt(row["block_count"])
    return f"{_fmt(row['block_count'])} ({_fmt(assembled)})"


def _ladder_html(ladder) -> str:
    """The ladder section: one row per case and rung, then the rungs' effective constants."""
    header = ["case", "rung", "nodes", "tip [mm] (reference)", "tip error", "volume change error",
              "f1 / f2 / f3 error", "E_eff / E", "nu_eff (asked)", "ms per step", "cost x springs",
              "CG iterations", "3x3 blocks (assembled)", "nonzeros"]
    body, previous = [], None
    for row in ladder["rows"]:
        case = html.escape(row["case"]) if row["case"] != previous else ""
        previous = row["case"]
        if "refused" in row:
            body.append(_refused_row([case, html.escape(row["rung"])], row["refused"], len(header) - 2))
            continue
        static = row["kind"] != "modes"
        tip = (f"{_fmt(1e3 * row['tip_deflection_m'])} ({html.escape(row.get('reference', 'P2'))} "
               f"{_fmt(1e3 * row['reference_tip_deflection_m'])})" if static else None)
        frequencies = None if static else " / ".join(_fmt(e, "percent") for e in row["frequency_errors"])
        cells = [case, html.escape(row["rung"]), _fmt(row["node_count"]), _fmt(tip),
                 _fmt(row.get("tip_deflection_error"), "percent"),
                 _fmt(row.get("volume_change_error_vs_fem"), "percent"),
                 frequencies or "&ndash;", _fmt(row.get("E_effective_ratio")),
                 f"{_fmt(row.get('nu_effective'))} ({_fmt(row['nu'])})", _fmt(1e3 * row["step_seconds"]),
                 _fmt(row["step_cost_vs_springs"]), _fmt(row["cg_iterations"]), _blocks(row),
                 _fmt(row["nonzero_count"])]
        body.append("<tr>" + "".join(f"<td>{cell}</td>" for cell in cells) + "</tr>")
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    table = f"<table><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"
    constants, width = [], 4
    for rung, by_nu in ladder["constants"].items():
        for values in by_nu.values():
            label = f"{html.escape(rung)}, nu = {_fmt(values['nu_asked'])}"
            if "refused" in values:
                constants.append(_refused_row([label], values["refused"], width))
            else:
                cells = [label, _fmt(values["E_ratio"]), _fmt(values["nu_effective"]),
                         _fmt(values["volume_strain_per_axial_strain"]), _fmt(1.0 - 2.0 * values["nu_asked"])]
                constants.append("<tr>" + "".join(f"<td>{cell}</td>" for cell in cells) + "</tr>")
    constants_table = _table(["rung, nu asked", "E_eff / E", "nu_eff", "dV/(V eps)", "exact 1 - 2 nu"], [],
                             extra="".join(constants))
    return (
        "<h2 id='ladder'>The ladder: accuracy against cost</h2>"
        "<p><b>Each rung of the model ladder on each case, through volspring's own solvers, against FEM on "
        "the same mesh</b> (the springs rung by the default rule, "
        f"{html.escape(ladder['rule'])}): P2 on the project's cases, and on the held-out shapes Taylor-Hood "
        "P2-P1 (TH), which does not lock, where P2 is 1-5% too stiff at nu 0.45-0.499. Errors are signed and "
        "relative to that reference (named in the tip column); the modal case compares the "
        "first three frequencies in ascending order. E_eff and nu_eff: uniaxial stress on a cube of "
        f"{ladder['constants_cells']}<sup>3</sup> cells, at the case's nu. Cost: the median wall time of one "
        f"implicit Euler step (AMG-preconditioned CG) at dt = {_fmt(ladder['dt_s'])} s over {ladder['steps']} "
        f"steps (after {ladder['warmup_steps']} warm-up steps), and its ratio to the springs rung on the same mesh "
        "and dt, timed alternately in this run; matrix size: the 3x3 blocks of the implicit matrix over the free "
        "nodes (nonzeros = 9 x blocks), and in parentheses the blocks the integrator assembles per step where it "
        "applies the upper rungs' continuum sets as products and assembles only their 1-ring stand-in for the "
        "preconditioner).</p>"
        "<p>Volume change is measured from the nodal displacements: the total volume of the mesh with its nodes "
        "moved, the same measure for every rung and for P2 (whose midside nodes it ignores). Per-tet volumes "
        "mislead: the volume terms of the upper rungs hold volume over the patch of tets around each node, not "
        "in each tet, so single tets may swell and shrink in a pattern that cancels over a patch, and P2's "
        "volume strain varies inside a tet; the mesh's total is what every model, and a renderer, sees. Where P2's "
        "moved mesh changes volume more by rotation (the O(|grad u|<sup>2</sup>) growth of a linear field in "
        "bending) than its linearised volume change, the integral of div u, no relative error is shown: it "
        "would measure the reference's geometry, not the material.</p>"
        + table + "<h3>Effective elastic constants of each rung</h3>" + constants_table)


def render_html(results: dict, figures: dict) -> str:
    """The whole report page.

    Parameters
    ----------
    results : dict
        The results of :func:`validation.report.runner.run_validation`, with ``files`` and
        ``command`` as :func:`validation.report.outputs.write_outputs` completes them.
    figures : dict
        Figure key -> base64 PNG text (:func:`validation.report.figures.render_figures`).

    Returns
    -------
    str
        The HTML document.
    """
    parts = []
    ladder = results.get("ladder")
    ladder_section = _ladder_html(ladder) if ladder and ladder["rows"] else ""
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
            rows.append([model_label(model)] + [_fmt(e, "percent") for e in errors]
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
<h1>volspring: the ladder of models against linear-elastic FEM</h1>
<p class="small">{html.escape(results['created'])} &middot; {'quick' if results['quick'] else 'full'} run
&middot; <code>{html.escape(command)}</code><br>{html.escape(versions_text)}</p>
{ladder_section}
<ul class="small">{notes}</ul>
{''.join(parts)}
</body></html>
"""

