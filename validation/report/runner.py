"""Run the validation cases and studies and collect their results.

:func:`run_validation` runs the built-in cases (:mod:`validation.cases`, compared by
:mod:`validation.compare`), the ladder of models on them and on the held-out shapes
(:mod:`validation.ladder`), the studies (:mod:`validation.studies`) and optionally a user's own
mesh; it returns the results as plain JSON numbers, every key naming its unit, with the
comparisons the VTU files are made of (written by :mod:`validation.report.outputs`).

results.json layout (units in the key names: ``_m``, ``_m3``, ``_hz``, ``_pa``, ``_s``,
``_n_per_m``; ``*_error`` are signed relative errors, (value - reference) / |reference|, 0.01 = 1%):

- ``schema``, ``created``, ``command``, ``quick``, ``versions`` (python, numpy, scipy, scikit-fem,
  pyamg, meshio, matplotlib, volspring), ``units``, ``notes``, ``rules``, ``models`` (the rungs run);
- ``ladder``: every rung of :data:`volspring.ladder.MODELS` on every case (:func:`validation.ladder.run_ladder`):
  ``models``, ``rule`` (of the springs rung), ``dt_s``, ``steps``, ``warmup_steps``, ``kernels`` (of the cost
  measurement: ``numba`` or ``numpy``, :mod:`volspring.kernels`), ``constants_cells`` and ``constants.<rung>.<nu>`` (effective ``E_pa``, ``E_ratio``,
  ``nu_effective``, ``volume_strain_per_axial_strain`` on the cube, or ``refused``), and ``rows``: one
  per case and rung with ``case``, ``rung``, ``nu``, ``node_count``; static cases ``tip_deflection_m``,
  ``reference_tip_deflection_m`` (P2), ``tip_deflection_error``, ``rms_displacement_error``,
  ``volume_change_m3``, ``reference_volume_change_m3``, ``volume_change_error_vs_fem``; the modal case
  ``frequencies_hz``, ``reference_frequencies_hz``, ``frequency_errors`` (first three); every row
  ``E_effective_ratio``, ``nu_effective``, ``step_seconds``, ``step_cost_vs_springs``, ``cg_iterations``,
  ``block_count``, ``nonzero_count``, ``unknown_count``, ``assembled_block_count``
  (:func:`validation.ladder.step_costs`); a rung that refuses the material: ``refused`` (its message) instead of numbers;
- ``cases.<name>``: ``parameters``, ``mesh`` (node_count, tet_count, cells), ``analytic``,
  ``fem.P2`` / ``fem.P1`` (tip_deflection_m, volume_change_m3, deformed_volume_change_m3, gross_volume_change_m3, ...),
  ``springs.<rule>`` (tip_deflection_m, tip_deflection_error, rms_displacement_error,
  max_displacement_error, volume_change_m3, volume_change_error_vs_fem,
  volume_change_error_vs_analytic, solver, ...), ``models.<rung>`` (the same for each rung, or
  ``refused``), ``beam_profile`` for beams, ``sweep`` for the compression case; modal case:
  ``fem.P2.frequencies_hz``, ``springs.<rule>.frequencies_hz``, ``models.<rung>.frequencies_hz``,
  ``first_frequency_error``; the held-out shapes are in ``ladder`` only;
- ``studies.refinement``, ``studies.speed``, ``studies.cauchy`` (see :mod:`validation.studies`);
- ``sweeps``: a user's sweeps (``volspring validate --sweep DIR``), each as
  :func:`validation.report.trade.read_sweep` reads it (runs with their cost and error against FEM, curves,
  Pareto front);
- ``headline.<rule>``: the figures the README quotes;
- ``files``: the VTU files written and the models in them (added by
  :func:`~validation.report.outputs.write_outputs`).
"""

from __future__ import annotations

import datetime
import platform

from validation import ladder, studies
from validation.cases import build_case, uniaxial_compression
from validation.compare import RULES, compare_modes, compare_static
from validation.heldout import HELDOUT_CASE_NAMES
from validation.springs import VALIDATED_MODELS
from volspring.sweep import run_calls
from typing import TYPE_CHECKING, Any
from collections.abc import Callable
from collections.abc import Sequence
import os

if TYPE_CHECKING:
    from distributed import Client

    from validation._case import Case

__all__ = ["BUILT_IN", "HELDOUT", "NOTES", "SCHEMA", "STATIC_CASES", "STUDIES", "SWEEP_NUS", "SWEEP_STRAINS", "UNITS",
           "run_validation", "versions"]

SCHEMA = "volspring-validate/1"
STATIC_CASES = ("cantilever_gravity", "cantilever_end_load", "hanging_bar", "uniaxial_compression")
BUILT_IN = STATIC_CASES + ("cantilever_modes",)
#: The held-out shapes (:mod:`validation.heldout`): in the ladder of the full run (``--quick`` leaves them out
#: unless named), at nu 0.3 on their stored meshes.
HELDOUT = HELDOUT_CASE_NAMES
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
    "The ladder: every rung of volspring.ladder.MODELS through volspring's own static, modal and implicit solvers; "
    "the springs rung uses the default rule (van_gelder), so its rows are the springs: van_gelder rows.",
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

    found: dict[str, str | None] = {"python": platform.python_version()}
    for name, distribution in (("numpy", "numpy"), ("scipy", "scipy"), ("scikit-fem", "scikit-fem"),
                               ("pyamg", "pyamg"), ("meshio", "meshio"), ("matplotlib", "matplotlib")):
        try:
            found[name] = metadata.version(distribution)
        except metadata.PackageNotFoundError:
            found[name] = None
    import volspring

    found["volspring"] = volspring.__version__
    return found


def _settings(quick: bool) -> dict:
    """What ``--quick`` trims. The speed study runs five periods of the loaded mode with a drag that
    leaves 5e-5 of the motion at the end (a damping ratio of 0.32): its cost is the step count, so
    the full run's finer beam (twice omega_max, half the critical step) gets the same simulated
    time, not more. Measured on 2 cores: quick about 15-25 s, full about 90 s (three quarters of it the
    speed study; up to 3 minutes on a shared machine). The ladder adds about 2 s to the quick run (the
    rungs on the coarse built-in cases; the held-out shapes are in the full run only) and about 15 s to
    the full one."""
    if quick:
        return {"refinement_levels": (1, 2), "reference_level": 4, "speed_per_height": 1,
                "speed_steps": studies.QUICK_INTEGRATOR_STEPS, "speed_periods": 5.0,
                "speed_residual_amplitude": 5e-5, "cauchy_cells": 3}
    return {"refinement_levels": (1, 2, 3, 4), "reference_level": 6, "speed_per_height": 2,
            "speed_steps": studies.INTEGRATOR_STEPS, "speed_periods": 5.0, "speed_residual_amplitude": 5e-5,
            "cauchy_cells": 4}


def run_validation(*, cases: Sequence[str] | None = None, quick: bool = False, own_case: Case | None = None,
                   rules: Sequence[str] = RULES, models: Sequence[str] = VALIDATED_MODELS,
                   folder: str | os.PathLike[str] | None = None, progress: Callable[..., Any] | None = None,
                   sweeps: Sequence[dict] = (), client: Client | None = None) -> tuple:
    """Run cases, the ladder and studies.

    Parameters
    ----------
    cases : sequence of str, optional
        built-in case, held-out case and study names (``BUILT_IN``, ``HELDOUT`` and ``STUDIES``); default all of them
        (the held-out shapes not with ``quick``), or none when ``own_case`` or ``sweeps`` is given
    quick : bool
        coarse meshes and short runs (about half a minute in all)
    own_case : Case, optional
        a user's mesh (:func:`validation.cases.own_mesh_case`)
    rules : sequence of str
        spring stiffness rules
    models : sequence of str
        rungs of the ladder (:data:`volspring.ladder.MODELS`), at least one
    folder : path, optional
        FEM cache folder
    progress : callable, optional
        ``progress(fraction, message)``, fraction in [0, 1]
    sweeps : sequence of dict
        a user's sweeps, read by :func:`validation.report.trade.read_sweep`: shown after the ladder; with sweeps
        and no ``cases`` nor ``own_case``, no case is run
    client : distributed.Client, optional
        run the cases and studies as tasks on this Dask cluster (:func:`volspring.sweep.sweep_client`), at the same
        time; None runs them here, one after the other. The results are the same but for the wall times of the
        speed study, measured while other tasks share the machine; the ladder's step costs are timed here, after
        the tasks, either way

    Returns
    -------
    (results, artefacts)
        results: JSON-ready dict (module docstring); artefacts: the :class:`~validation.compare.Comparison` of each
        case, for VTU files
    """
    known = BUILT_IN + HELDOUT + STUDIES
    if cases is None or len(cases) == 0:
        cases = () if own_case is not None or sweeps else BUILT_IN + (() if quick else HELDOUT) + STUDIES
    unknown = [name for name in cases if name not in known]
    if unknown:
        raise ValueError(f"unknown case {unknown[0]!r}; known: {', '.join(known)}")
    models = ladder.parse_models(models)
    settings = _settings(quick)
    weights = {"cantilever_gravity": 1, "cantilever_end_load": 1, "hanging_bar": 1, "uniaxial_compression": 2,
               "cantilever_modes": 1, "refinement": 4, "speed": 12 if quick else 40, "cauchy": 1, "own_mesh": 3,
               "ladder": 2, **{name: 3 for name in HELDOUT}}
    tasks = list(cases) + (["own_mesh"] if own_case is not None else [])
    total = float(sum(weights[name] for name in tasks) + weights["ladder"])
    done = 0.0
    report = progress or (lambda fraction, message: None)

    def note(message):
        report(min(done / total, 1.0), message)

    results: dict[str, Any] = {
        "schema": SCHEMA, "created": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "quick": bool(quick), "versions": versions(), "units": UNITS,
        "notes": NOTES if tasks else [], "rules": list(rules),
        "models": list(models),
        "settings": {key: value for key, value in settings.items() if key != "speed_steps"},
        "cases": {}, "studies": {}, "sweeps": list(sweeps)}
    results["settings"]["speed_steps"] = {key: list(value) for key, value in settings["speed_steps"].items()}
    # Every case and study is independent: run here one after the other, or as tasks on a Dask cluster (progress
    # then moves as each finishes). The ladder's costs are timed afterwards, here, on their own.
    options = {"quick": quick, "own_case": own_case, "rules": rules, "models": models, "folder": folder,
               "settings": settings, "progress": note if client is None else None}
    calls = {name: (_run_task, (name,), options) for name in tasks}
    parts = _speed_parts(settings) if client is not None and "speed" in calls else {}
    if parts:  # on a cluster the speed study, most of the work, goes as one task per run
        calls.pop("speed")
        calls.update({part: (_run_task, ("speed",), {**options, "settings": {**settings, "speed_steps": steps}})
                      for part, steps in parts.items()})

    def finished(name, output, count, total_count):
        nonlocal done
        done += weights[name] if name in weights else weights["speed"] / len(parts)
        if client is not None:  # run here, each task says what it is doing as it goes
            note(f"{name} done ({count} of {total_count})")

    if client is not None:
        note(f"{len(calls)} cases and studies on the cluster")
    outputs = run_calls(calls, client=client, on_result=finished)
    if parts:
        outputs["speed"] = {"study": studies.merge_speed_studies([outputs.pop(part)["study"] for part in parts])}
    artefacts = {}
    on_ladder, held_out = [], []  # comparisons made with the rungs: the report's cases, then the held-out shapes
    for name, output in outputs.items():
        if "case" in output:
            results["cases"][name] = output["case"]
            artefacts[name] = output["comparison"]
            on_ladder.append(output["comparison"])
        elif "held_out" in output:
            held_out.append(output["held_out"])
        else:
            results["studies"][name] = output["study"]
    results["ladder"] = ladder.run_ladder(comparisons=on_ladder + held_out, models=models, folder=folder,
                                          cells=settings["cauchy_cells"], progress=note)
    results["headline"] = _headline(results, rules)
    report(1.0, "done")
    return results, artefacts


def _speed_parts(settings: dict) -> dict:
    """``speed:NAME:FACTOR`` -> that one step of integrator NAME: the speed study split into one task per run."""
    return {f"speed:{name}:{factor:g}": {name: (factor,)} for name, factors in settings["speed_steps"].items()
            for factor in factors}


def _run_task(name: str, *, quick: bool, own_case: Case | None, rules: Sequence[str], models: Sequence[str],
              folder: str | os.PathLike[str] | None, settings: dict,
              progress: Callable[..., Any] | None = None) -> dict:
    """One case or study of the report (a task of :func:`run_validation`): ``{"case": results, "comparison":
    Comparison}`` for a case of the report, ``{"held_out": Comparison}`` (the rungs only, for the ladder) for a
    held-out shape, ``{"study": results}`` for a study."""
    note = progress or (lambda message: None)
    note(name)
    if name in STATIC_CASES or name == "own_mesh":
        case = own_case if name == "own_mesh" and own_case is not None else build_case(name, quick=quick)
        comparison = compare_static(case, rules=rules, models=models, folder=folder, progress=note)
        if name == "uniaxial_compression":
            comparison.results["sweep"] = _compression_sweep(quick, rules, folder, note)
        return {"case": comparison.results, "comparison": comparison}
    if name == "cantilever_modes":
        comparison = compare_modes(build_case(name, quick=quick), rules=rules, models=models, folder=folder,
                                   progress=note)
        return {"case": comparison.results, "comparison": comparison}
    if name in HELDOUT:
        return {"held_out": ladder.compare_rungs(build_case(name), models=models, folder=folder, progress=note)}
    if name == "refinement":
        return {"study": studies.refinement_study(settings["refinement_levels"],
                                                  reference_level=settings["reference_level"], rules=rules,
                                                  folder=folder, progress=note)}
    if name == "speed":
        return {"study": studies.speed_study(per_height=settings["speed_per_height"], steps=settings["speed_steps"],
                                             periods=settings["speed_periods"],
                                             residual_amplitude=settings["speed_residual_amplitude"], folder=folder,
                                             progress=note)}
    return {"study": studies.cauchy_study(cells=settings["cauchy_cells"], rules=rules)}


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
                         "fem_P2_volume_strain": comparison.results["fem"]["P2"]["volume_change_m3"] / volume,
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

