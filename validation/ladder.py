"""The ladder of models measured: each rung's error against P2 beside its cost per step and its matrix size.

For every case and every rung of :data:`volspring.ladder.MODELS` (the springs rung by volspring's
default rule, van Gelder), all through volspring's own solvers (:mod:`validation.springs`: the
static solve, the modal solve, the implicit integrator; no second implementation):

accuracy (:func:`~validation.compare.compare_static`, :func:`~validation.compare.compare_modes`, ``models=``)
    tip deflection and its signed error against the reference on the same mesh; the volume change (the
    mesh's volume with its nodes moved by the displacements, :func:`validation.springs.deformed_volume_change`:
    the rungs are geometrically exact, so a rotation adds nothing) and its error against the reference's
    integral of div u (none where that is a cancellation, bending: :func:`validation.fem.volume_change_cancels`);
    for the modal case the first :data:`FREQUENCY_COUNT` frequencies and their errors.
elastic constants (:func:`rung_constants`)
    effective E and nu of the rung on the cube of the uniaxial case
    (:func:`validation.springs.effective_constants`), once per rung and Poisson ratio, not per case:
    a row shows those at its case's nu.
cost (:func:`step_costs`)
    the median wall time of :data:`STEP_COUNT` implicit-Euler steps
    (:class:`volspring.integrators.implicit.ImplicitEuler`, its defaults: AMG-preconditioned CG) of the
    case's scene at ``dt`` = :data:`FRAME_STEP_S`, after :data:`WARMUP_STEPS` steps (the AMG hierarchy
    is built in the first), as a ratio to the springs rung on the same mesh and ``dt``, its steps
    timed alternately with the rung's in one run (as ``benchmarks/bench_ladder.py``); and the size of
    the implicit matrix: 3x3 blocks (free nodes and the pairs of free nodes coupled by an element),
    nonzeros (9 per block) and unknowns, and the blocks the integrator assembles per step (fewer
    where it applies a set as a product).

A rung that refuses a material (``"springs+volume"`` below the spring network's own nu, about 0.25)
gives a row ``{"refused": message}`` instead of numbers.

Examples
--------
>>> from validation.cases import uniaxial_compression
>>> from validation.ladder import rung_constants
>>> constants = rung_constants(("smoothed", "springs+volume"), (0.05, 0.3), cells=2)
>>> round(constants["smoothed"]["0.3"]["nu_effective"], 3)   # the smoothed rung passes the patch test
0.3
>>> "refused" in constants["springs+volume"]["0.05"]          # below the network's own nu
True
"""

from __future__ import annotations

import dataclasses
import logging
import statistics
import time

import numpy as np

from validation.cases import CUBE, uniaxial_compression
from validation.compare import LADDER_RULE, compare_modes, compare_static
from validation.springs import VALIDATED_MODELS, case_scene, effective_constants, rung_model_or_refusal
from volspring.material import Material
from typing import TYPE_CHECKING, Any
from collections.abc import Callable
from collections.abc import Sequence
import os

if TYPE_CHECKING:
    from validation._case import Case
    from validation.compare import Comparison

__all__ = ["FRAME_STEP_S", "FREQUENCY_COUNT", "LADDER_NUS", "STATIC_REFERENCE", "STEP_COUNT", "WARMUP_STEPS",
           "case_rows", "compare_rungs", "parse_models", "rung_constants", "run_ladder", "step_costs"]

logger = logging.getLogger(__name__)

#: The step of the cost measurement [s]: an animation frame, the step a user of the implicit integrator takes.
FRAME_STEP_S = 1.0 / 60.0
#: Timed steps per rung (the median is reported: 9 so that a burst of load on a shared machine, which may
#: hold several consecutive steps of one rung, does not move it) and untimed steps before them (the AMG build).
STEP_COUNT = 9
WARMUP_STEPS = 2
#: Frequencies compared per rung on the modal case.
FREQUENCY_COUNT = 3
#: FEM answers of the static cases run here (the held-out shapes), the reference first: Taylor-Hood P2-P1 on
#: the same mesh does not lock (within 0.5-1.4% of the converged answer on the torus, capsule and L-bracket,
#: 3.5% on the bunny) where same-mesh P2 is 1-5% too stiff at nu 0.45-0.499 (benchmarks/study_locking.py).
STATIC_REFERENCE = ("TH", "P2")
#: Poisson ratios at which every rung's effective constants are measured, besides those of the cases: 0.1 is
#: below the springs+volume rung's reach (its refusal shows), 0.49 nearly incompressible.
LADDER_NUS = (0.1, 0.3, 0.45, 0.49)


def parse_models(text: str | Sequence[str]) -> tuple[str, ...]:
    """Rungs from ``"NAME[,NAME...]"`` (or a sequence of names), in the ladder's order, each once.

    Raises
    ------
    ValueError
        For an empty list or a name not in :data:`validation.springs.VALIDATED_MODELS`, naming it.
    """
    names = [name.strip() for name in (text.split(",") if isinstance(text, str) else text)]
    unknown = [name for name in names if name not in VALIDATED_MODELS]
    if unknown:
        raise ValueError(f"unknown model {unknown[0]!r}; known: {', '.join(VALIDATED_MODELS)} (comma-separated)")
    if not names:
        raise ValueError(f"no model named; known: {', '.join(VALIDATED_MODELS)}")
    return tuple(rung for rung in VALIDATED_MODELS if rung in names)


def _models_or_refusals(mesh, material, models) -> dict:
    """rung -> its Model on ``mesh``, or its refusal message (:func:`~validation.springs.rung_model_or_refusal`)."""
    return {rung: rung_model_or_refusal(mesh, material, rung) for rung in models}


def _nu_key(nu: float) -> str:
    return f"{float(nu):g}"


def rung_constants(models: Sequence[str] = VALIDATED_MODELS, nus: Sequence[float] = LADDER_NUS, *, cells: int = 4,
                   strain: float = 1e-3) -> dict:
    """Effective E and nu of each rung on the unit cube of the uniaxial case, for each asked nu.

    Parameters
    ----------
    models : sequence of str
        rungs
    nus : sequence of float
        Poisson ratios asked (E: :data:`validation.cases.CUBE`)
    cells : int
        cells along each edge of the cube
    strain : float
        axial strain of the test [-]

    Returns
    -------
    dict
        ``{rung: {"<nu>": {"E_pa", "E_ratio", "nu_asked", "nu_effective", "volume_strain_per_axial_strain"} or
        {"refused": message}}}``, nu written with ``:g``
    """
    mesh = uniaxial_compression(cells=cells).mesh
    table: dict[str, dict[str, dict[str, Any]]] = {rung: {} for rung in models}
    for nu in dict.fromkeys(float(nu) for nu in nus):
        material = Material(E=CUBE["E_pa"], nu=nu, density=CUBE["density_kg_per_m3"])
        for rung, model in _models_or_refusals(mesh, material, models).items():
            if isinstance(model, str):
                table[rung][_nu_key(nu)] = {"nu_asked": nu, "refused": model}
                continue
            measured = effective_constants(mesh, model, strain=strain)
            table[rung][_nu_key(nu)] = {"nu_asked": nu, "E_pa": measured["E_pa"],
                                        "E_ratio": measured["E_pa"] / material.E, "nu_effective": measured["nu"],
                                        "volume_strain_per_axial_strain": measured["volume_strain_per_axial_strain"]}
    return table


def step_costs(case: Case, models: Sequence[str] = VALIDATED_MODELS, *, dt: float = FRAME_STEP_S,
               steps: int = STEP_COUNT, warmup: int = WARMUP_STEPS) -> dict:
    """Cost of one implicit step of each rung on the case's scene, and the size of its matrix.

    The scene is the case's supports and loads (:func:`validation.springs.case_scene`), with gravity
    along -z when the case has no load (the modal case: a scene at rest would solve nothing). The
    springs rung is always timed, as the baseline, even when ``models`` leaves it out.

    Parameters
    ----------
    case : Case
    models : sequence of str
        rungs
    dt : float
        step [s]
    steps : int
        timed steps per rung, taken alternately across the rungs
    warmup : int
        untimed steps before them

    Returns
    -------
    dict
        ``{rung: {"step_seconds", "step_cost_vs_springs", "cg_iterations", "block_count", "nonzero_count",
        "unknown_count", "assembled_block_count"} or {"refused": message}}`` for every rung of ``models``:
        ``block_count`` counts the 3x3 blocks of the implicit system matrix with every element set assembled
        (:class:`volspring.assembly.BlockPattern`), ``assembled_block_count`` those the integrator assembles in a step
        (fewer when it applies a set as a product, matrix-free, and assembles a stand-in for it)
    """
    from volspring.assembly import BlockPattern
    from volspring.integrators.implicit import ImplicitEuler

    if case.gravity is None and not case.tractions:
        case = dataclasses.replace(case, gravity=(0.0, 0.0, -9.81))
    timed = tuple(dict.fromkeys(("springs",) + tuple(models)))
    runs: dict[str, dict[str, Any]] = {}
    costs: dict[str, dict[str, Any]] = {}
    for rung, model in _models_or_refusals(case.mesh, case.material, timed).items():
        if isinstance(model, str):
            costs[rung] = {"refused": model}
            continue
        scene = case_scene(case, model)
        integrator = ImplicitEuler()
        cache = integrator.new_cache()
        state = scene.initial_state()
        for _ in range(warmup):
            state = integrator.step(scene, state, dt, cache=cache)
        runs[rung] = {"scene": scene, "integrator": integrator, "cache": cache, "state": state, "seconds": [],
                      "iterations": []}
    for _ in range(steps):
        for run in runs.values():
            start = time.perf_counter()
            run["state"] = run["integrator"].step(run["scene"], run["state"], dt, cache=run["cache"])
            run["seconds"].append(time.perf_counter() - start)
            run["iterations"].append(run["integrator"].last_solve.iterations)
    for rung, run in runs.items():
        system = BlockPattern(run["scene"].model, run["scene"].free)  # every set assembled: the system's stencil
        assembled = run["integrator"].pattern(run["scene"], run["cache"])
        costs[rung] = {"step_seconds": statistics.median(run["seconds"]),
                       "cg_iterations": float(np.mean(run["iterations"])), "block_count": int(system.block_count),
                       "nonzero_count": 9 * int(system.block_count), "unknown_count": int(system.size),
                       "assembled_block_count": int(assembled.block_count)}
    base = costs["springs"]["step_seconds"]
    for rung in runs:
        costs[rung]["step_cost_vs_springs"] = costs[rung]["step_seconds"] / base
    return {rung: costs[rung] for rung in models}


def case_rows(comparison: Comparison, costs: dict) -> list:
    """One ladder row per rung of a comparison made with ``models=`` (:mod:`validation.compare`).

    Parameters
    ----------
    comparison : Comparison
        of a static or modal case, its ``results["models"]`` filled
    costs : dict
        :func:`step_costs` of the same case

    Returns
    -------
    list of dict
        ``case``, ``title``, ``kind``, ``rung``, ``nu``, ``node_count`` and either ``refused`` or the accuracy (static:
        ``tip_deflection_m``, ``reference_tip_deflection_m``, ``tip_deflection_error``, ``rms_displacement_error``,
        ``volume_change_m3``, ``reference_volume_change_m3``, ``volume_change_error_vs_fem``; modal: ``frequencies_hz``,
        ``reference_frequencies_hz``, ``frequency_errors``, the first :data:`FREQUENCY_COUNT`) and the cost
        (:func:`step_costs`)
    """
    results = comparison.results
    element = next(iter(results["fem"]))  # the comparison's reference: its first element
    reference = results["fem"][element]
    rows = []
    for rung, answer in results["models"].items():
        row = {"case": results["case"], "title": results["title"], "kind": results["kind"], "rung": rung,
               "nu": float(comparison.case.material.nu), "node_count": results["mesh"]["node_count"],
               "reference": element}
        if "refused" in answer:
            rows.append(row | {"refused": answer["refused"]})
            continue
        if results["kind"] == "modes":
            row.update(frequencies_hz=answer["frequencies_hz"][:FREQUENCY_COUNT],
                       reference_frequencies_hz=reference["frequencies_hz"][:FREQUENCY_COUNT],
                       frequency_errors=[float(e) for e in answer["frequency_errors"][:FREQUENCY_COUNT]])
        else:
            row.update(tip_deflection_m=answer["tip_deflection_m"],
                       reference_tip_deflection_m=reference["tip_deflection_m"],
                       tip_deflection_error=answer["tip_deflection_error"],
                       rms_displacement_error=answer["rms_displacement_error"],
                       volume_change_m3=answer["volume_change_m3"],
                       reference_volume_change_m3=reference["volume_change_m3"],
                       volume_change_error_vs_fem=answer["volume_change_error_vs_fem"])
        row.update({key: value for key, value in costs.get(rung, {}).items() if key != "refused"})
        rows.append(row)
    return rows


def compare_rungs(case: Case, *, models: Sequence[str] = VALIDATED_MODELS,
                  folder: str | os.PathLike[str] | None = None, progress: Callable[..., Any] | None = None
                  ) -> Comparison:
    """The rungs (no spring rules, no P1) on ``case`` against its reference: :data:`STATIC_REFERENCE` for a static
    case (Taylor-Hood, P2 beside it), P2 modes for a modal one; what :func:`run_ladder` does with its ``cases``."""
    if case.kind == "modes":
        return compare_modes(case, rules=(), models=models, folder=folder, progress=progress)
    return compare_static(case, rules=(), models=models, folder=folder, progress=progress, elements=STATIC_REFERENCE)


def run_ladder(cases: Sequence[Case] = (), *, comparisons: Sequence[Comparison] = (),
               models: Sequence[str] = VALIDATED_MODELS, folder: str | os.PathLike[str] | None = None, cells: int = 4,
               dt: float = FRAME_STEP_S, steps: int = STEP_COUNT, progress: Callable[..., Any] | None = None) -> dict:
    """The ladder table: every rung on every case, with the rungs' effective constants.

    Parameters
    ----------
    cases : sequence of Case
        compared here (:func:`~validation.compare.compare_static` or :func:`~validation.compare.compare_modes`, no
        spring rules, no P1): static cases against :data:`STATIC_REFERENCE` (Taylor-Hood, which does not lock; P2 beside
        it), modes against P2
    comparisons : sequence of Comparison
        made already with ``models=`` (the report's own cases): their answers are used, not solved again
    models : sequence of str
        rungs
    folder : path, optional
        FEM cache folder
    cells : int
        cells per edge of the cube of the effective constants
    dt, steps : as for :func:`step_costs`
    progress : callable, optional
        ``progress(message)``

    Returns
    -------
    dict
        ``models``, ``rule`` (of the springs rung), ``dt_s``, ``steps``, ``warmup_steps``, ``constants_cells``,
        ``constants`` (:func:`rung_constants`, at :data:`LADDER_NUS` and every case's nu) and ``rows``
        (:func:`case_rows`, each with ``E_effective_ratio`` and ``nu_effective`` of its rung at its nu)

    Examples
    --------
    >>> import tempfile
    >>> from validation.cases import uniaxial_compression
    >>> from validation.ladder import run_ladder
    >>> ladder = run_ladder([uniaxial_compression(cells=2, nu=0.05)], cells=2, steps=1, folder=tempfile.mkdtemp())
    >>> [(row["rung"], "refused" in row) for row in ladder["rows"]]
    [('springs', False), ('springs+volume', True), ('smoothed', False), ('lattice', False)]
    """
    note = progress or (lambda message: None)
    models = parse_models(models)
    comparisons = list(comparisons) + [compare_rungs(case, models=models, folder=folder, progress=note)
                                       for case in cases]
    rows = []
    for comparison in comparisons:
        note(f"{comparison.case.name}: cost per step of each rung")
        rows += case_rows(comparison, step_costs(comparison.case, models, dt=dt, steps=steps))
    note("ladder: effective constants of each rung")
    nus = tuple(LADDER_NUS) + tuple(row["nu"] for row in rows)
    constants = rung_constants(models, nus, cells=cells)
    for row in rows:
        if "refused" not in row:
            measured = constants[row["rung"]][_nu_key(row["nu"])]
            row.update(E_effective_ratio=measured.get("E_ratio"), nu_effective=measured.get("nu_effective"))
    from volspring.kernels import active

    # The costs depend on which code ran the hot loops (numba's kernels or numpy; never the numbers): say which.
    return {"models": list(models), "rule": LADDER_RULE, "dt_s": dt, "steps": steps, "warmup_steps": WARMUP_STEPS,
            "kernels": active(), "constants_cells": cells, "constants": constants, "rows": rows}
