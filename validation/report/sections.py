"""The report's sections, each from its part of the results: the ladder, the spring rules, the Cauchy
limit, one per case, the refinement and speed studies and the files for ParaView.

:func:`report_sections` returns them in page order as :class:`Section` (anchor, title, HTML), which
:func:`validation.report.html.render_html` lays out under the headline and lists in the contents.
"""

from __future__ import annotations

import html
from typing import NamedTuple

from validation.fem import CANCELLING_SHARE
from validation.report._cells import BENDING_NOTE, fmt, image, refused_row, scroll, table, volume_cell
from validation.report.figures import model_label
from validation.report.summary import bending_dominated

__all__ = ["Section", "report_sections"]


class Section(NamedTuple):
    """One section of the page: its ``anchor`` (the id of its heading), ``title`` (plain text) and ``html``."""

    anchor: str
    title: str
    html: str


def _heading(anchor, title) -> str:
    return f"<h2 id='{anchor}'>{html.escape(title)}</h2>"


def _answers(case):
    """(label, values) of each spring rule, then of each rung of the ladder that answered."""
    for rule, values in case["springs"].items():
        yield f"springs: {rule}", values
    for rung, values in case.get("models", {}).items():
        if "refused" not in values:
            yield f"rung: {rung}", values


def _refusals(case, width) -> str:
    return "".join(refused_row([f"rung: {html.escape(rung)}"], values["refused"], width)
                   for rung, values in case.get("models", {}).items() if "refused" in values)


def case_section(name, case, figures) -> Section:
    """A case: its mesh and parameters, every model's answer against FEM P2, its figures."""
    parts = [_heading(name, case["title"])]
    mesh = case["mesh"]
    parameters = ", ".join(f"{k} = {fmt(v)}" for k, v in case["parameters"].items())
    parts.append(f"<p class='small'>{mesh['node_count']} nodes, {mesh['tet_count']} tets"
                 f"{', cells ' + ' x '.join(map(str, mesh['cells'])) if mesh.get('cells') else ''}. {parameters}</p>")
    if case.get("warning"):
        parts.append(f"<p class='warn'>{html.escape(case['warning'])}</p>")
    if case["kind"] == "modes":
        fem = case["fem"]["P2"]
        rows = [["FEM P2 (reference)"] + [fmt(f) for f in fem["frequencies_hz"]] + ["&ndash;"]]
        for label, values in _answers(case):
            rows.append([label] + [fmt(f) for f in values["frequencies_hz"]]
                        + [fmt(values["first_frequency_error"], "percent")])
        count = len(fem["frequencies_hz"])
        parts.append(table(["model"] + [f"f{k + 1} [Hz]" for k in range(count)] + ["f1 error vs P2"], rows,
                           extra=_refusals(case, count + 1)))
        parts.append(f"<p>Euler-Bernoulli: first bending frequency {fmt(case['analytic']['first_frequency_hz'])} Hz "
                     "(a square section has a degenerate pair, y and z; springs on a coarse mesh split it).</p>")
        return Section(name, case["title"], "".join(parts))
    analytic = case["analytic"]
    reference_volume = case["fem"]["P2"]["volume_change_m3"]
    bending = bending_dominated(case["fem"]["P2"])
    rows = []
    for element, values in case["fem"].items():
        rows.append([f"FEM {element}" + (" (reference)" if element == "P2" else ""),
                     fmt(1e3 * values["tip_deflection_m"]), fmt(values.get("tip_deflection_error"), "percent"),
                     fmt(values.get("rms_displacement_error"), "percent"),
                     fmt(values.get("max_displacement_error"), "percent"),
                     fmt(values["volume_change_m3"]), "&ndash;", "&ndash;"])
    for label, values in _answers(case):
        rows.append([f"{label} ({values['solver']})", fmt(1e3 * values["tip_deflection_m"]),
                     fmt(values["tip_deflection_error"], "percent"), fmt(values["rms_displacement_error"], "percent"),
                     fmt(values["max_displacement_error"], "percent"), fmt(values["volume_change_m3"]),
                     volume_cell(values["volume_change_m3"], reference_volume, not_meaningful=bending),
                     volume_cell(values["volume_change_m3"], analytic.get("volume_change_m3"))])
    parts.append(table(["model", "tip [mm]", "tip error", "RMS error", "max error", "volume change [m^3]",
                        "volume change / FEM P2", "volume change / exact"], rows, extra=_refusals(case, 7)))
    theory = ", ".join(f"{k} = {fmt(v)}" for k, v in analytic.items())
    parts.append(f"<p class='small'>Closed form: {theory}. Errors are relative to FEM P2 on the same mesh; RMS and max "
                 "nodal errors relative to the reference's RMS and max displacement. Volume change: FEM's the "
                 "integral of div u, a model's its moved mesh's (the models are geometrically exact: a rotation adds "
                 "nothing); as a multiple of P2's and of the closed form's: 1&times; is right, 2&times; twice the "
                 "change, a negative ratio the wrong sign.</p>")
    parts.append(image(figures, f"profile_{name}", f"deflection along the beam, {name}"))
    if name == "uniaxial_compression":
        parts.append(image(figures, "volume", "volume change against strain"))
    return Section(name, case["title"], "".join(parts))


def bending_note(cases) -> str:
    """Why bending cases show no volume ratio, with the numbers of the run's first bending case."""
    example = next(((case["title"], case["fem"]["P2"]) for case in cases.values()
                    if case["kind"] != "modes" and bending_dominated(case["fem"]["P2"])), None)
    numbers = ""
    if example is not None:
        title, fem = example
        numbers = (f" ({html.escape(title.lower())}: P2's net change, the integral of div u, is "
                   f"{fmt(fem['volume_change_m3'])} m<sup>3</sup>, its gross change, the integral of |div u|, "
                   f"{fmt(fem['gross_volume_change_m3'])} m<sup>3</sup>)")
    return (f"<p id='{BENDING_NOTE}'><b>Volume change in bending: not meaningful.</b> A bent body's net volume "
            "change is a cancellation: the fibres stretched on one side gain about what those compressed on the "
            "other lose, so the net is a small share of the gross" + numbers + ", and on the held-out shapes that "
            "bend no two references agree on it (same-mesh P2 gives 0.29-1.28 times Taylor-Hood's, a capsule "
            "refined once 0.54-0.59 times). A ratio to it, or a relative error, would measure that, so none is "
            f"shown where the net is below {CANCELLING_SHARE:.0%} of the gross.</p>")


def _blocks(row) -> str:
    """The system's 3x3 blocks, and in parentheses those assembled per step when fewer (matrix-free sets)."""
    assembled = row.get("assembled_block_count")
    if assembled is None or assembled == row["block_count"]:
        return fmt(row["block_count"])
    return f"{fmt(row['block_count'])} ({fmt(assembled)})"


def _kernels_note(ladder) -> str:
    """Which code ran the hot loops of the timed steps (results written before volspring.kernels say nothing)."""
    kernels = ladder.get("kernels")
    if kernels is None:
        return ""
    return (f", with the {html.escape(kernels)} kernels (<code>volspring.kernels</code>: numba's compiled loops "
            "where the fast extra is installed, numpy otherwise; the same numbers, other times)")


def ladder_section(ladder, cases) -> Section:
    """The ladder: one row per case and rung, then the rungs' effective constants."""
    header = ["case", "rung", "nodes", "tip [mm] (reference)", "tip error", "volume change / FEM",
              "f1 / f2 / f3 error", "E_eff / E", "nu_eff (asked)", "ms per step", "cost x springs",
              "CG iterations", "3x3 blocks (assembled)", "nonzeros"]
    body, previous = [], None
    for row in ladder["rows"]:
        case = html.escape(row["case"]) if row["case"] != previous else ""
        previous = row["case"]
        if "refused" in row:
            body.append(refused_row([case, html.escape(row["rung"])], row["refused"], len(header) - 2))
            continue
        static = row["kind"] != "modes"
        tip = (f"{fmt(1e3 * row['tip_deflection_m'])} ({html.escape(row.get('reference', 'P2'))} "
               f"{fmt(1e3 * row['reference_tip_deflection_m'])})" if static else None)
        frequencies = None if static else " / ".join(fmt(e, "percent") for e in row["frequency_errors"])
        # The comparison gives no volume error only where the reference's volume change is bending's
        # cancellation (validation.compare.compare_static): say so rather than leave a blank.
        volume = (volume_cell(row["volume_change_m3"], row["reference_volume_change_m3"],
                              not_meaningful=row.get("volume_change_error_vs_fem") is None
                              and bool(row.get("reference_volume_change_m3"))) if static else "&ndash;")
        cells = [case, html.escape(row["rung"]), fmt(row["node_count"]), fmt(tip),
                 fmt(row.get("tip_deflection_error"), "percent"), volume,
                 frequencies or "&ndash;", fmt(row.get("E_effective_ratio")),
                 f"{fmt(row.get('nu_effective'))} ({fmt(row['nu'])})", fmt(1e3 * row["step_seconds"]),
                 fmt(row["step_cost_vs_springs"]), fmt(row["cg_iterations"]), _blocks(row),
                 fmt(row["nonzero_count"])]
        body.append("<tr>" + "".join(f"<td>{cell}</td>" for cell in cells) + "</tr>")
    head = "".join(f"<th>{html.escape(h)}</th>" for h in header)
    rows_table = scroll(f"<table><thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>")
    constants, width = [], 4
    for rung, by_nu in ladder["constants"].items():
        for values in by_nu.values():
            label = f"{html.escape(rung)}, nu = {fmt(values['nu_asked'])}"
            if "refused" in values:
                constants.append(refused_row([label], values["refused"], width))
            else:
                cells = [label, fmt(values["E_ratio"]), fmt(values["nu_effective"]),
                         fmt(values["volume_strain_per_axial_strain"]), fmt(1.0 - 2.0 * values["nu_asked"])]
                constants.append("<tr>" + "".join(f"<td>{cell}</td>" for cell in cells) + "</tr>")
    constants_table = table(["rung, nu asked", "E_eff / E", "nu_eff", "dV/(V eps)", "exact 1 - 2 nu"], [],
                            extra="".join(constants))
    title = "The ladder: accuracy against cost"
    return Section("ladder", title, (
        _heading("ladder", title)
        + "<p><b>Each rung of the model ladder on each case, through volspring's own solvers, against FEM on "
        "the same mesh</b> (the springs rung by the default rule, "
        f"{html.escape(ladder['rule'])}): P2 on the project's cases, and on the held-out shapes Taylor-Hood "
        "P2-P1 (TH), which does not lock, where P2 is 1-5% too stiff at nu 0.45-0.499. Errors are signed and "
        "relative to that reference (named in the tip column); the modal case compares the "
        "first three frequencies in ascending order. E_eff and nu_eff: uniaxial stress on a cube of "
        f"{ladder['constants_cells']}<sup>3</sup> cells, at the case's nu. Cost: the median wall time of one "
        f"implicit Euler step (AMG-preconditioned CG) at dt = {fmt(ladder['dt_s'])} s over {ladder['steps']} "
        f"steps (after {ladder['warmup_steps']} warm-up steps), and its ratio to the springs rung on the same mesh "
        f"and dt, timed alternately in this run{_kernels_note(ladder)}; matrix size: the 3x3 blocks of the implicit matrix over the free "
        "nodes (nonzeros = 9 x blocks), and in parentheses the blocks the integrator assembles per step where it "
        "applies the upper rungs' continuum sets as products and assembles only their 1-ring stand-in for the "
        "preconditioner).</p>"
        "<p>Volume change is measured from the nodal displacements: the total volume of the mesh with its nodes "
        "moved, the same measure for every rung and for P2 (whose midside nodes it ignores). Per-tet volumes "
        "mislead: the volume terms of the upper rungs hold volume over the patch of tets around each node, not "
        "in each tet, so single tets may swell and shrink in a pattern that cancels over a patch, and P2's "
        "volume strain varies inside a tet; the mesh's total is what every model, and a renderer, sees. It is "
        "shown as a multiple of P2's: 1&times; is right, 2&times; twice the change (too much loss under "
        "compression and too much gain under tension are the same failure), a negative ratio the wrong "
        "sign.</p>"
        + bending_note(cases)
        + rows_table + "<h3>Effective elastic constants of each rung</h3>" + constants_table))


def rules_section(results) -> Section:
    """The spring stiffness rules side by side: the figures the README quotes (``results["headline"]``)."""
    cases, rules, figures_by_rule = results["cases"], results["rules"], results["headline"]
    keys = list(dict.fromkeys(key for row in figures_by_rule.values() for key in row))
    suffix = "_volume_change_error_vs_fem"

    def cell(rule, key):
        if key.endswith(suffix):  # a ratio to FEM, as everywhere on the page
            case = cases[key[:-len(suffix)]]
            return volume_cell(case["springs"][rule]["volume_change_m3"], case["fem"]["P2"]["volume_change_m3"],
                               not_meaningful=bending_dominated(case["fem"]["P2"]))
        return fmt(figures_by_rule[rule].get(key), "number" if key in ("nu_effective", "E_effective_ratio") else "percent")

    header = ["rule"] + [key.replace(suffix, " volume change / FEM").replace("_", " ") for key in keys]
    title = "Spring stiffness rules"
    return Section("rules", title, _heading("rules", title)
                   + "<p>The spring model by each stiffness rule: signed errors against FEM P2 on the same mesh, "
                   "volume change as a multiple of P2's, and the network's effective constants.</p>"
                   + table(header, [[rule] + [cell(rule, key) for key in keys] for rule in rules]))


def cauchy_section(cauchy, figures) -> Section:
    statements = []
    for key, summary in cauchy["summary"].items():
        pattern, rule = key.split("/")
        mine = [m for m in cauchy["measurements"] if m["pattern"] == pattern and m["rule"] == rule]
        statements.append([rule, pattern, fmt(summary["nu_effective_min"]), fmt(summary["nu_effective_max"]),
                           ", ".join(fmt(m["nu_asked"]) for m in mine), fmt(mine[0]["E_ratio"]),
                           fmt(mine[0]["volume_strain_per_axial_strain"])])
    title = "The pure-spring limit (Cauchy)"
    return Section("cauchy", title, (
        _heading("cauchy", title) + "<p><b>A network of central springs has one effective "
        "Poisson ratio whatever nu is asked.</b> Uniaxial stress on a unit cube of "
        f"{cauchy['cells']}<sup>3</sup> cells: the measured effective nu below is the same for every asked nu "
        "(the rules use E only), so volume change under load is wrong for any material that is not near it; "
        "for nearly incompressible materials (nu = 0.45: exact dV/(V eps) = 0.10) springs lose several times "
        "too much volume.</p>"
        + table(["rule", "mesh", "nu effective (min)", "(max)", "nu asked", "E_eff / E",
                 "dV/(V eps) (exact 1 - 2 nu)"], statements)
        + image(figures, "cauchy", "effective nu against asked nu")))


def refinement_section(refinement, figures) -> Section:
    rows = []
    for model, errors in refinement["tip_deflection_error"].items():
        rows.append([model_label(model)] + [fmt(e, "percent") for e in errors]
                    + [fmt(refinement["rates_per_node_count"][model]), fmt(refinement["rates_per_mesh_size"][model])])
    header = ["model"] + [f"{n} nodes" for n in refinement["node_counts"]] + ["slope in N", "rate in h"]
    title = "Refinement: cantilever under gravity"
    return Section("refinement", title, (
        _heading("refinement", title)
        + f"<p>Tip deflection error against P2 on {refinement['reference']['node_count']} nodes "
        f"({fmt(1e3 * refinement['reference_tip_deflection_m'])} mm; beam theory "
        f"{fmt(1e3 * refinement['beam_theory_tip_deflection_m'])} mm). Springs converge to a network, "
        "not to the continuum: their slope says how fast they drift.</p>"
        + table(header, rows) + image(figures, "refinement", "error against node count")))


def speed_section(speed, figures) -> Section:
    rows = []
    for run in speed["runs"]:
        rows.append([run["integrator"], f"{run['step_factor']:g} &times; {html.escape(run['step_unit'])}",
                     fmt(run["dt_s"]), fmt(run["stable"]), fmt(run["wall_seconds_per_simulated_second"]),
                     fmt(run.get("settled_deflection_error"), "percent_small"),
                     fmt(run.get("first_frequency_error"), "percent_small"),
                     fmt(run.get("first_frequency_error_vs_fem"), "percent"),
                     ", ".join(run.get("pareto", [])).replace("_error", "") or ""])
    title = "Speed and accuracy of the integrators"
    return Section("speed", title, (
        _heading("speed", title)
        + f"<p>The spring cantilever ({speed['node_count']} nodes, rule {speed['rule']}) released from rest under "
        f"gravity, {fmt(speed.get('periods'))} periods of the mode gravity loads ({fmt(speed['duration_s'])} s) "
        f"simulated with a drag of {fmt(speed['drag_rate_per_s'])} /s (damping ratio "
        f"{fmt(speed.get('damping_ratio'))}) that leaves {fmt(speed.get('residual_amplitude'))} of the motion "
        "at the end; wall time per simulated second is over the time a run reached (a diverged run stops "
        "early). omega_max = "
        f"{fmt(speed['omega_max_rad_per_s'])} rad/s. Errors against the spring model's own static equilibrium "
        f"({fmt(1e3 * speed['spring_settled_deflection_m'])} mm) and first frequency "
        f"({fmt(speed['spring_first_frequency_hz'])} Hz); the model itself is "
        f"{fmt(speed['model_deflection_error'], 'percent')} (deflection) and "
        f"{fmt(speed['model_frequency_error'], 'percent')} (frequency) from FEM P2. In the figure each stable run "
        "is labelled with its step: a multiple of the integrator's critical step, or of 2 / omega_max for those "
        "without one (the legend says which).</p>"
        + table(["integrator", "step", "dt [s]", "stable", "wall s per simulated s", "settled error",
                 "f1 error", "f1 error vs FEM", "Pareto"], rows)
        + image(figures, "speed", "speed against accuracy, each point labelled with its step")))


def files_section(files) -> Section:
    rows = [[name, ", ".join(info["vtu"]), ", ".join(info["models"])] for name, info in files.items()]
    title = "Files for ParaView"
    return Section("files", title, (
        _heading("files", title) + "<p>Each case's file holds every model's displacement as point "
        "data (Warp By Vector); the side-by-side file holds one copy per model, cell data "
        "<code>model</code> numbering them in the order listed.</p>"
        + table(["case", "files", "models"], rows, wrap_cells=True)))


def report_sections(results: dict, figures: dict) -> list:
    """Every section the results hold data for, in page order.

    Parameters
    ----------
    results : dict
        The results of :func:`validation.report.runner.run_validation` (``files`` added by
        :func:`validation.report.outputs.write_outputs`).
    figures : dict
        Figure key -> data URI (:func:`validation.report.figures.render_figures`).

    Returns
    -------
    list of Section
        The ladder first, then the user's sweeps (``volspring validate --sweep``), the spring rules, the Cauchy
        limit, the cases, the refinement and speed studies and the files.
    """
    sections = []
    ladder = results.get("ladder")
    if ladder and ladder["rows"]:
        sections.append(ladder_section(ladder, results["cases"]))
    if results.get("sweeps"):  # the user's own sweeps: their trade curves, right after the ladder
        from validation.report.trade import sweep_section

        sections += [sweep_section(index, sweep, figures) for index, sweep in enumerate(results["sweeps"])]
    if results.get("headline") and any(results["headline"].values()):
        sections.append(rules_section(results))
    studies = results["studies"]
    if studies.get("cauchy"):
        sections.append(cauchy_section(studies["cauchy"], figures))
    sections += [case_section(name, case, figures) for name, case in results["cases"].items()]
    if studies.get("refinement"):
        sections.append(refinement_section(studies["refinement"], figures))
    if studies.get("speed"):
        sections.append(speed_section(studies["speed"], figures))
    if results.get("files"):
        sections.append(files_section(results["files"]))
    return sections
