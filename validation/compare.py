"""The spring model and the ladder's rungs against the FEM reference on the same mesh: deflections, volumes,
frequencies.

For a :class:`~validation.cases.Case`, each stiffness rule (``rules``) and each rung of the ladder
(``models``, :data:`volspring.ladder.MODELS`; the springs rung by its default rule, van Gelder):

- the model's answer from volspring's own solvers (:mod:`validation.springs`: static equilibrium,
  or frequencies), whatever its element sets: one code path for a rule and a rung;
- a rung that refuses the case's material (``"springs+volume"`` below the network's own nu) is
  recorded as ``{"refused": message}``, not raised;
- the FEM answer (P2, the reference, and P1) through the on-disk cache (:mod:`validation.cache`);
- errors relative to the P2 reference: tip deflection (signed), RMS and max nodal displacement
  error; volume change of the model (the mesh's volume moved by its node displacements: the model
  is geometrically exact, so rotation adds nothing) vs FEM's (the integral of div u; none where that
  net change is a cancellation, :func:`validation.fem.volume_change_cancels`) and vs the closed form;
- for modal cases, the model's frequencies against the FEM modal solve.
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass, field

import numpy as np

from validation import cache
from validation.cases import Case
from validation.fem import volume_change_cancels
from validation.springs import (VALIDATED_MODELS, deformed_volume_change, rung_model_or_refusal, spring_frequencies,
                               spring_model, spring_static)
from typing import TYPE_CHECKING, Any
from collections.abc import Callable
from collections.abc import Sequence
import os

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

__all__ = [
    "LADDER_RULE",
    "RULES",
    "Comparison",
    "beam_profile",
    "compare_modes",
    "compare_static",
    "displacement_errors",
    "tip_deflection",
]

logger = logging.getLogger(__name__)

RULES = ("van_gelder", "lloyd", "uniform")
#: The stiffness rule of the ladder's springs rung (volspring's default): its rows are the ``springs_van_gelder`` ones.
LADDER_RULE = "van_gelder"


# ---------------------------------------------------------------------------- measures
def tip_deflection(case: Case, displacement: np.ndarray, *, nodes: np.ndarray | None = None,
                   direction: ArrayLike | None = None) -> float:
    """Mean displacement of the case's tip nodes along its tip direction [m]."""
    nodes = case.tip_nodes if nodes is None else nodes
    direction = case.tip_direction if direction is None else direction
    return float((displacement[nodes] @ np.asarray(direction, float)).mean())


def displacement_errors(displacement: np.ndarray, reference: np.ndarray) -> dict:
    """RMS and max nodal displacement error relative to the reference's RMS and max magnitude [-]."""
    difference = np.linalg.norm(displacement - reference, axis=1)
    size = np.linalg.norm(reference, axis=1)
    return {"rms_displacement_error": float(np.sqrt(np.mean(difference**2)) / np.sqrt(np.mean(size**2))),
            "max_displacement_error": float(difference.max() / size.max())}



def _relative(value, reference):
    if reference is None or reference == 0 or value is None:
        return None
    return float((value - reference) / abs(reference))


def beam_profile(case: Case, displacement: np.ndarray) -> tuple:
    """(x (k,) [m], w (k,) [m]) -- mean deflection along the load at each distinct x of the nodes."""
    x = np.round(case.mesh.points[:, 0], 12)
    stations, index = np.unique(x, return_inverse=True)
    along = displacement @ case.tip_direction
    return stations, np.bincount(index, weights=along) / np.bincount(index)


# ---------------------------------------------------------------------------- comparisons
@dataclass(frozen=True, eq=False)
class Comparison:
    """A case compared: ``results`` (plain JSON numbers, keys with units) and ``fields`` (arrays).

    ``fields["displacement"]`` maps a model name (``fem_P2``, ``fem_P1``, ``springs_<rule>``,
    ``model_<rung>``) to its (n, 3) node displacements [m] (modal cases: the first mode shape, scaled
    to unit max). The springs rung is ``springs_van_gelder`` when that rule is compared too.
    """

    case: Case
    results: dict
    fields: dict = field(default_factory=dict)


def _mesh_summary(case: Case) -> dict:
    return {"node_count": case.mesh.node_count, "tet_count": case.mesh.tet_count,
            "cells": list(case.cells) if case.cells else None, "volume_m3": case.mesh.volume}


def _models(case: Case, rules, models, note):
    """Yield ``(group, name, model)``: ``("springs", rule, Model)`` for each rule, then ``("models", rung, ...)``
    for each rung, where ``...`` is the rung's Model, its refusal message (str), or None for the springs rung
    when :data:`LADDER_RULE` is among the rules (the same model: its answer is reused, not solved again)."""
    unknown = [rung for rung in models if rung not in VALIDATED_MODELS]
    if unknown:
        raise ValueError(f"unknown model {unknown[0]!r}; known: {', '.join(VALIDATED_MODELS)}")
    for rule in rules:
        note(f"{case.name}: springs ({rule})")
        yield "springs", rule, spring_model(case.mesh, case.material, rule)
    for rung in models:
        if rung == "springs" and LADDER_RULE in rules:
            yield "models", rung, None
            continue
        note(f"{case.name}: model {rung}")
        yield "models", rung, rung_model_or_refusal(case.mesh, case.material, rung)


def _field_name(group: str, name: str) -> str:
    return f"springs_{name}" if group == "springs" else f"model_{name}"


def _answers(case: Case, rules, models, note, answer) -> dict:
    """``{"springs": {rule: ...}, "models": {rung: ...}}``: ``answer(field_name, model)`` of every model of
    :func:`_models`, the springs rung's answer reused from the same rule's, a refusal as ``{"refused": message}``."""
    answers: dict[str, dict[str, Any]] = {"springs": {}, "models": {}}
    for group, name, model in _models(case, rules, models, note):
        if model is None:
            answers[group][name] = dict(answers["springs"][LADDER_RULE])
        elif isinstance(model, str):
            answers[group][name] = {"refused": model}
        else:
            answers[group][name] = answer(_field_name(group, name), model)
    return answers


def compare_static(case: Case, *, rules: Sequence[str] = RULES, models: Sequence[str] = (),
                   elements: Sequence[str] = ("P2", "P1"), folder: str | os.PathLike[str] | None = None,
                   progress: Callable[..., Any] | None = None) -> Comparison:
    """Springs (each rule) and the ladder's rungs against the FEM reference (P2) and P1 on the case's mesh.

    Parameters
    ----------
    case : Case
        ``kind == "static"``
    rules : sequence of str
        spring stiffness rules (:data:`RULES`); results in ``results["springs"]``
    models : sequence of str
        of :data:`validation.springs.VALIDATED_MODELS`; results in ``results["models"]`` (a refused rung: ``{"refused":
        message}``)
    elements : sequence of {"P2", "P1"}
        the first is the reference
    folder : path, optional
        FEM cache folder (:func:`validation.cache.default_folder`)
    progress : callable, optional
        ``progress(message)`` before each solve

    Returns
    -------
    Comparison
    """
    note = progress or (lambda message: None)
    fem, displacements = {}, {}
    for element in elements:
        note(f"{case.name}: FEM {element}")
        start = time.perf_counter()
        solution = cache.cached_solve_static(case.mesh, case.material_tuple, folder=folder, element=element,
                                             **case.fem_arguments())
        displacements[f"fem_{element}"] = solution.displacement
        fem[element] = {"volume_change_m3": solution.volume_change,
                        "deformed_volume_change_m3": solution.deformed_volume_change,
                        "gross_volume_change_m3": solution.gross_volume_change,
                        "max_displacement_m": float(np.linalg.norm(solution.displacement, axis=1).max()),
                        "dof_count": solution.info.dof_count, "seconds": time.perf_counter() - start}
    reference = displacements[f"fem_{elements[0]}"]
    tip_nodes, direction = case.tip_nodes, case.tip_direction
    if tip_nodes is None:  # own mesh: the node the reference moves most, along its motion
        worst = int(np.argmax(np.linalg.norm(reference, axis=1)))
        tip_nodes = np.zeros(case.mesh.node_count, bool)
        tip_nodes[worst] = True
        direction = reference[worst] / np.linalg.norm(reference[worst])
    if direction is None:
        raise ValueError(f"case {case.name!r} has tip_nodes but no tip_direction; give both or neither")
    measure = {"nodes": tip_nodes, "direction": direction}
    for element in elements:
        fem[element]["tip_deflection_m"] = tip_deflection(case, displacements[f"fem_{element}"], **measure)
    reference_tip = fem[elements[0]]["tip_deflection_m"]
    # The models are geometrically exact (solved by Newton on their nonlinear forces), so their moved mesh's volume
    # is their volume change, rotation-free; a linear reference's is its integral of div u (its moved mesh also grows
    # by O(rotation^2) wherever it rotates: 1.5-3.5 times the bunny's net change at nu 0.45-0.49). In bending the
    # net is a cancellation (volume_change_cancels): no meaningful relative error.
    reference_volume = fem[elements[0]]["volume_change_m3"]
    if volume_change_cancels(reference_volume, fem[elements[0]]["gross_volume_change_m3"]):
        reference_volume = None
    analytic_volume = case.analytic.get("volume_change_m3")
    for element in elements[1:]:
        fem[element].update(tip_deflection_error=_relative(fem[element]["tip_deflection_m"], reference_tip),
                            **displacement_errors(displacements[f"fem_{element}"], reference))

    def answer(field_name, model):
        solved = spring_static(case, model)
        u = solved.displacement
        displacements[field_name] = u
        tip = tip_deflection(case, u, **measure)
        volume = deformed_volume_change(case.mesh, u)
        return {
            "tip_deflection_m": tip, "tip_deflection_error": _relative(tip, reference_tip),
            **displacement_errors(u, reference),
            "volume_change_m3": volume, "volume_change_error_vs_fem": _relative(volume, reference_volume),
            "volume_change_error_vs_analytic": _relative(volume, analytic_volume),
            "max_displacement_m": float(np.linalg.norm(u, axis=1).max()),
            **({"mean_stiffness_n_per_m": float(model.stiffness.mean())} if model.spring_count else {}),
            "solver": solved.method, "iterations": solved.iterations, "residual": solved.residual,
            "seconds": solved.seconds}

    answers = _answers(case, rules, models, note, answer)
    size = float(np.linalg.norm(np.ptp(case.mesh.points, axis=0)))
    largest = fem[elements[0]]["max_displacement_m"]
    results = {"case": case.name, "title": case.title, "kind": case.kind, "parameters": _jsonable(case.parameters),
               "mesh": _mesh_summary(case), "analytic": dict(case.analytic), "fem": fem, "springs": answers["springs"],
               "tip": {"node_count": int(np.count_nonzero(tip_nodes)), "direction": [float(d) for d in direction]},
               "max_displacement_over_size": largest / size}
    if models:
        results["models"] = answers["models"]
    if largest > 0.02 * size:
        results["warning"] = (f"the largest FEM displacement is {100 * largest / size:.1f}% of the mesh size: "
                              "beyond small deformation, the comparison also measures geometric nonlinearity")
    if case.beam is not None:
        profile = {}
        for name, u in displacements.items():
            stations, w = beam_profile(case, u)
            profile[f"{name}_m"] = w.tolist()
        profile["x_m"] = stations.tolist()
        profile["beam_theory_m"] = _beam_theory(case, stations)
        results["beam_profile"] = profile
    return Comparison(case, results, {"displacement": displacements})


def _beam_theory(case, stations):
    from validation.cases import beam_deflection_profile

    return beam_deflection_profile(case, stations).tolist()


def compare_modes(case: Case, *, rules: Sequence[str] = RULES, models: Sequence[str] = (), count: int = 4,
                  folder: str | os.PathLike[str] | None = None,
                  progress: Callable[..., Any] | None = None) -> Comparison:
    """Frequencies of the spring model (each rule) and of the ladder's rungs (``models``, as for
    :func:`compare_static`) against the FEM P2 modal solve and beam theory."""
    note = progress or (lambda message: None)
    note(f"{case.name}: FEM P2 modes")
    start = time.perf_counter()
    modes = cache.cached_solve_modes(case.mesh, case.material_tuple, folder=folder, clamp=list(case.clamps),
                                     count=count)
    fem_seconds = time.perf_counter() - start
    held = np.zeros(case.mesh.node_count, bool)
    for clamp in case.clamps:
        held |= np.asarray(clamp.region(case.mesh.points), bool)
    fields = {"fem_P2": modes.shapes[0] / np.abs(modes.shapes[0]).max()}

    def answer(field_name, model):
        start = time.perf_counter()
        frequencies, shapes = spring_frequencies(model, held, count=count)
        fields[field_name] = shapes[0] / np.abs(shapes[0]).max()
        return {"frequencies_hz": frequencies.tolist(), "first_frequency_hz": float(frequencies[0]),
                "first_frequency_error": _relative(float(frequencies[0]), float(modes.frequencies[0])),
                "frequency_errors": [(f - r) / r for f, r in zip(frequencies, modes.frequencies)],
                "seconds": time.perf_counter() - start}

    answers = _answers(case, rules, models, note, answer)
    results = {"case": case.name, "title": case.title, "kind": case.kind, "parameters": _jsonable(case.parameters),
               "mesh": _mesh_summary(case), "analytic": dict(case.analytic),
               "fem": {"P2": {"frequencies_hz": modes.frequencies.tolist(),
                              "first_frequency_hz": float(modes.frequencies[0]), "mass": modes.mass,
                              "first_frequency_error_vs_analytic": _relative(
                                  float(modes.frequencies[0]), case.analytic.get("first_frequency_hz")),
                              "dof_count": modes.info.dof_count, "seconds": fem_seconds}},
               "springs": answers["springs"]}
    if models:
        results["models"] = answers["models"]
    return Comparison(case, results, {"displacement": fields})


def _jsonable(value):
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, np.generic):
        return value.item()
    return value
