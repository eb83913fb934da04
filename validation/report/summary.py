"""What the report's numbers say: the headline sentence and the volume change as a ratio to FEM.

:func:`headline` reads the ladder (each rung's error against FEM and its cost per implicit step) and
the speed study (each integrator's error and wall time per simulated second) and says in two
sentences which model and which integrator give which error at what cost. :func:`volume_ratio`
turns a volume change into a multiple of the reference's: a signed relative error of -74% (too
much loss under compression) and one of +103% (too much gain under tension) are the same failure,
about twice the reference's change, and read as 1.74× and 2.03×. :func:`bending_dominated` says
when no such ratio means anything: in bending, the net volume change is a cancellation.

Examples
--------
>>> from validation.report.summary import volume_ratio
>>> round(volume_ratio(-0.00705, -0.00405), 2)   # springs lose 1.74 times P2's volume in compression
1.74
>>> volume_ratio(1.8e-08, None) is None          # no meaningful reference (bending)
True
"""

from __future__ import annotations

import statistics
from typing import Any

from validation.fem import volume_change_cancels

__all__ = ["FREQUENCY_TOLERANCE", "bending_dominated", "headline", "model_accuracy", "percent", "volume_ratio"]

#: The first-frequency error [relative] under which an integrator "keeps the frequency": 1% is below
#: what an eye notices in an animation and above the speed study's fit error (about 1e-4).
FREQUENCY_TOLERANCE = 0.01


def percent(value: float, *, signed: bool = False) -> str:
    """A relative value as a short percent: two significant digits, whole percents from 10% up.

    >>> percent(0.617), percent(-0.0013, signed=True), percent(1.0297)
    ('62%', '-0.13%', '103%')
    """
    number = 100.0 * value
    text = f"{number:+.0f}" if signed else f"{abs(number):.0f}"
    if abs(number) < 10.0:
        text = f"{number:+.2g}" if signed else f"{abs(number):.2g}"
    return text + "%"


def volume_ratio(value: float, reference: float | None) -> float | None:
    """The volume change ``value`` [m^3] as a multiple of ``reference`` [m^3]; None without a reference.

    A ratio below 0 says the model changes volume the other way (swells where the reference shrinks).
    """
    if value is None or reference is None or reference == 0:
        return None
    return float(value) / float(reference)


def bending_dominated(fem: dict) -> bool:
    """Whether a FEM answer's net volume change is a cancellation (bending), so that no ratio to it means anything.

    ``fem`` holds ``volume_change_m3`` (the net change, the integral of div u) and ``gross_volume_change_m3`` (the
    integral of |div u|). In bending the fibres stretched on one side gain about what those compressed on the other
    lose, and the net is a small share of the gross: :func:`validation.fem.volume_change_cancels`, the test
    :func:`validation.compare.compare_static` makes before it gives a relative error.
    """
    net, gross = fem.get("volume_change_m3"), fem.get("gross_volume_change_m3")
    if net is None or gross is None:
        return False
    return volume_change_cancels(net, gross)


def model_accuracy(rows: list[dict[str, Any]]) -> dict:
    """Each rung's worst error and median cost over the ladder's rows.

    Parameters
    ----------
    rows : list of dict
        ``results["ladder"]["rows"]`` (:func:`validation.ladder.run_ladder`).

    Returns
    -------
    dict
        rung -> ``worst_error`` (the largest |tip deflection error| of the static cases and |first
        frequency error| of the modal one, relative), ``worst_case`` (its case's title),
        ``cost_vs_springs`` (median ratio of its implicit step's wall time to the springs rung's) and
        ``step_seconds`` (median wall time of one implicit Euler step [s]); rungs without an answer left out.
    """
    found: dict[str, dict[str, list[Any]]] = {}
    for row in rows:
        if "refused" in row:
            continue
        error = row.get("tip_deflection_error") if row["kind"] != "modes" else (row.get("frequency_errors") or [None])[0]
        mine = found.setdefault(row["rung"], {"errors": [], "costs": [], "seconds": []})
        if error is not None:
            mine["errors"].append((abs(error), row.get("title", row["case"])))
        mine["costs"].append(row["step_cost_vs_springs"])
        mine["seconds"].append(row["step_seconds"])
    summary = {}
    for rung, mine in found.items():
        if not mine["errors"]:
            continue
        worst, case = max(mine["errors"])
        summary[rung] = {"worst_error": worst, "worst_case": case,
                         "cost_vs_springs": statistics.median(mine["costs"]),
                         "step_seconds": statistics.median(mine["seconds"])}
    return summary


def _seconds(value: float) -> str:
    return f"{value:.2g} s"


def _model_sentence(rows) -> str:
    accuracy = model_accuracy(rows)
    if not accuracy:
        return ""
    best = min(accuracy, key=lambda rung: accuracy[rung]["worst_error"])
    cheapest = min(accuracy, key=lambda rung: accuracy[rung]["cost_vs_springs"])

    def cost(rung):
        mine = accuracy[rung]
        return (f"{mine['cost_vs_springs']:.2g}× the springs rung's cost per implicit Euler step "
                f"(median over the cases, {1e3 * mine['step_seconds']:.2g} ms)")

    mine = accuracy[best]
    within = (f"within {percent(mine['worst_error'])} in tip deflection and first frequency "
              f"(worst: {mine['worst_case'].lower()})")
    if len(accuracy) == 1:
        return (f"Against FEM on the same meshes, the {best} rung is {within}, at "
                f"{1e3 * mine['step_seconds']:.2g} ms per implicit Euler step.")
    text = f"Against FEM on the same meshes, the {best} rung is the most accurate model, {within}"
    if cheapest == best:
        return text + f", and also the cheapest ({1e3 * mine['step_seconds']:.2g} ms per implicit Euler step)."
    other = accuracy[cheapest]
    return (text + f", at {cost(best)}; the {cheapest} rung is the cheapest "
            f"({1e3 * other['step_seconds']:.2g} ms) and off by up to {percent(other['worst_error'])}.")


def _step(run) -> str:
    unit = "the critical step" if run["step_unit"] == "critical step" else run["step_unit"]
    return f"{run['integrator']} at {run['step_factor']:g} × {unit}"


def _integrator_sentence(speed) -> str:
    stable = [run for run in speed["runs"] if run["stable"]]
    if not stable:
        return ""
    cheapest = min(stable, key=lambda run: run["wall_seconds_per_simulated_second"])
    keeping = [run for run in stable if run.get("first_frequency_error") is not None
               and abs(run["first_frequency_error"]) <= FREQUENCY_TOLERANCE]
    faithful = min(keeping, key=lambda run: run["wall_seconds_per_simulated_second"]) if keeping else None

    def errors(run):
        frequency = run.get("first_frequency_error")
        said = f"its settled deflection within {percent(abs(run['settled_deflection_error']))}"
        if frequency is None:
            return said + " but its vibration damped out unmeasured"
        return said + f" and its first frequency {percent(frequency, signed=True)}"

    text = (f"Stepping the springs cantilever ({speed['node_count']} nodes) in time, with errors against the spring "
            f"model's own answer, {_step(cheapest)} is the cheapest stable integrator: "
            f"{_seconds(cheapest['wall_seconds_per_simulated_second'])} of computing per simulated second, "
            f"{errors(cheapest)}")
    if faithful is None:
        return text + f"; no run keeps the first frequency within {percent(FREQUENCY_TOLERANCE)}."
    if faithful is cheapest:
        return text + "."
    return (text + f"; the cheapest that keeps the first frequency within {percent(FREQUENCY_TOLERANCE)} is "
            f"{_step(faithful)}: {_seconds(faithful['wall_seconds_per_simulated_second'])} per simulated second, "
            f"{errors(faithful)}.")


def headline(results: dict) -> str:
    """The report's conclusion in two sentences (plain text): the most accurate and the cheapest model
    of the ladder with their errors and costs, then the cheapest stable integrator and the cheapest
    that keeps the first frequency, with their errors and wall time per simulated second.

    Parameters
    ----------
    results : dict
        The results of :func:`validation.report.runner.run_validation`.

    Returns
    -------
    str
        The sentences; empty when the run has neither ladder rows nor a speed study.
    """
    sentences = [_model_sentence(results.get("ladder", {}).get("rows", []))]
    speed = results.get("studies", {}).get("speed")
    if speed:
        sentences.append(_integrator_sentence(speed))
    return " ".join(sentence for sentence in sentences if sentence)
