"""Studies across meshes and steps: refinement, the speed/accuracy trade, the Cauchy limit.

:func:`refinement_study`
    The gravity cantilever at several resolutions: tip deflection of the springs (each rule), P1
    and P2 against a converged reference (P2 one level finer than the finest studied), with the
    rates fitted to log(error) against log(node count). A rate p in node count is 3p in the mesh
    size h. Springs do not converge to the continuum: their "rate" only says how fast they drift.
:func:`speed_study`
    The spring cantilever released from rest under gravity for a few periods of the mode gravity
    loads, with a mass-proportional drag (rate c [1/s]) chosen so that the motion settles within
    the run (its amplitude falls to ``residual_amplitude`` of the start). For each integrator and
    each step (a multiple of its critical step; of the symplectic one, 2 / omega_max, for schemes
    without one): the wall time per simulated second (wall time over the simulated time reached),
    the settled tip deflection (end of the run) and the first
    frequency (a damped-oscillation fit of the trajectory's modal coordinate phi^T M (x - x_eq)
    along the mode gravity loads most; the drag's shift is undone, omega^2 = omega_d^2 + c^2 / 4,
    exact for mass-proportional damping; the tip's z motion alone mixes two modes on a coarse
    beam, whose bending axes follow the mesh), each compared with the
    spring model's own exact answer (its static equilibrium and eigenfrequency: the integrator's
    error) and with the FEM P2 reference on the same mesh (the total error). A run that raises
    :class:`volspring.errors.SimulationDiverged` is unstable.
:func:`cauchy_study`
    Effective E, nu and volume change per strain of the pure spring network for each rule and
    several requested nu (:func:`validation.compare.effective_constants`).
"""

from __future__ import annotations

import logging
import math
import time

import numpy as np

from validation import cache
from meshing import structured_box
from validation.cases import cantilever_gravity
from validation.compare import RULES, tip_deflection
from validation.springs import effective_constants, held_nodes, spring_frequencies, spring_model, spring_static
from volspring.material import Material
from typing import TYPE_CHECKING, Any
from collections.abc import Callable
from collections.abc import Sequence
import os

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

__all__ = ["INTEGRATOR_STEPS", "QUICK_INTEGRATOR_STEPS", "cauchy_study", "fit_rate", "merge_speed_studies",
           "pareto_front", "refinement_study", "speed_study"]

logger = logging.getLogger(__name__)

#: Steps of the speed study, as multiples of each integrator's critical step (of 2 / omega_max for
#: those without one: explicit Euler and midpoint are unstable at any step, implicit Euler at none).
#: No run is pointless: a run costs its step count (hundreds of microseconds each). Explicit Euler
#: and midpoint diverge at every step listed (by their growth per step against the drag's decay,
#: midpoint would be held below about 0.1 x, at minutes a run); a quarter of the critical step
#: shows the first-order frequency error of the symplectic family halving, but not for rk4, whose
#: error there is already the fit's.
INTEGRATOR_STEPS = {
    "explicit_euler": (0.05, 0.2, 0.9),
    "midpoint": (0.2, 0.5, 0.9),
    "symplectic_euler": (0.25, 0.5, 0.9, 1.05),
    "rk4": (0.5, 0.9, 1.05),
    "verlet": (0.25, 0.5, 0.9, 1.05),
    "time_corrected_verlet": (0.25, 0.5, 0.9, 1.05),
    "implicit_euler": (1.0, 10.0, 100.0, 1000.0),
}
QUICK_INTEGRATOR_STEPS = {
    "explicit_euler": (0.2,),
    "midpoint": (0.2,),
    "symplectic_euler": (0.5, 0.9, 1.05),
    "rk4": (0.5, 0.9, 1.05),
    "verlet": (0.5, 0.9, 1.05),
    "time_corrected_verlet": (0.5, 0.9, 1.05),
    "implicit_euler": (10.0, 100.0, 1000.0),
}


def fit_rate(node_counts: ArrayLike, errors: ArrayLike) -> float | None:
    """Slope of log|error| against log(node count) by least squares, or None with < 2 usable points."""
    n, e = np.asarray(node_counts, float), np.abs(np.asarray(errors, float))
    keep = (e > 0) & np.isfinite(e)
    if keep.sum() < 2:
        return None
    return float(np.polyfit(np.log(n[keep]), np.log(e[keep]), 1)[0])


def refinement_study(levels: Sequence[int] = (1, 2, 4), *, reference_level: int = 8, rules: Sequence[str] = RULES,
                     folder: str | os.PathLike[str] | None = None, progress: Callable[..., Any] | None = None) -> dict:
    """Tip deflection error of the gravity cantilever against node count.

    Parameters
    ----------
    levels : sequence of int
        cells across the beam's height (1 is 10 x 1 x 1 cells, 44 nodes)
    reference_level : int
        the P2 solution at this level is the converged reference
    rules : sequence of str
    folder : path, optional
        FEM cache folder
    progress : callable, optional
        ``progress(message)``

    Returns
    -------
    dict
        ``node_counts``, ``tip_deflection_m`` and ``tip_deflection_error`` per model (``fem_P1``, ``fem_P2``,
        ``springs_<rule>``), ``rates_per_node_count`` and ``rates_per_mesh_size``, ``reference_tip_deflection_m``,
        ``beam_theory_tip_deflection_m``
    """
    note = progress or (lambda message: None)
    levels = sorted(int(level) for level in levels)
    if reference_level <= levels[-1]:
        raise ValueError(f"reference_level = {reference_level} must be finer than the finest level {levels[-1]}")
    note(f"refinement: P2 reference at {reference_level} cells across")
    reference_case = cantilever_gravity(per_height=reference_level)
    reference = cache.cached_solve_static(reference_case.mesh, reference_case.material_tuple, folder=folder,
                                          element="P2", **reference_case.fem_arguments())
    reference_tip = tip_deflection(reference_case, reference.displacement)
    models = ["fem_P1", "fem_P2"] + [f"springs_{rule}" for rule in rules]
    tips: dict[str, list[float]] = {name: [] for name in models}
    node_counts, cells = [], []
    for level in levels:
        case = cantilever_gravity(per_height=level)
        node_counts.append(case.mesh.node_count)
        assert case.cells is not None  # a structured mesh
        cells.append(list(case.cells))
        for element in ("P1", "P2"):
            note(f"refinement: {element} at {level} cells across ({case.mesh.node_count} nodes)")
            solution = cache.cached_solve_static(case.mesh, case.material_tuple, folder=folder, element=element,
                                                 **case.fem_arguments())
            tips[f"fem_{element}"].append(tip_deflection(case, solution.displacement))
        for rule in rules:
            note(f"refinement: springs ({rule}) at {level} cells across")
            tips[f"springs_{rule}"].append(tip_deflection(case, spring_static(case, spring_model(
                case.mesh, case.material, rule)).displacement))
    errors = {name: [(tip - reference_tip) / reference_tip for tip in values] for name, values in tips.items()}
    rates = {name: fit_rate(node_counts, values) for name, values in errors.items()}
    return {"levels": levels, "cells": cells, "node_counts": node_counts,
            "reference": {"level": reference_level, "node_count": reference_case.mesh.node_count, "element": "P2"},
            "reference_tip_deflection_m": reference_tip,
            "beam_theory_tip_deflection_m": reference_case.analytic["tip_deflection_m"],
            "tip_deflection_m": tips, "tip_deflection_error": errors,
            "rates_per_node_count": rates,
            "rates_per_mesh_size": {name: (None if rate is None else -3.0 * rate) for name, rate in rates.items()}}


def _bending_mode(frequencies, shapes, tip_nodes) -> float:
    """The lowest frequency whose mode moves the tip mostly along z (the FEM's z bending mode)."""
    for frequency, shape in zip(frequencies, shapes):
        motion = np.abs(shape[tip_nodes]).sum(axis=0)
        if motion[2] >= motion.max():
            return float(frequency)
    raise ValueError("no z-bending mode among the computed modes")


def _loaded_mode(frequencies, shapes, load) -> int:
    """Index of the mode that carries most of the static response to ``load`` (n, 3) [N]:
    the largest |phi . f| / omega^2. On a coarse spring beam the bending axes follow the mesh, not
    the section, so gravity along z can load a mode that is not the lowest."""
    omega2 = (2 * np.pi * np.asarray(frequencies)) ** 2
    share = np.abs(np.einsum("kij,ij->k", shapes, load)) / np.maximum(omega2, 1e-300)
    return int(np.argmax(share))


def _trajectory_frequency(times, tip, settled, drag_rate) -> float | None:
    """First (undamped) frequency [Hz] of a decaying tip trajectory.

    A least-squares fit of tip(t) = s + exp(-sigma t) (a cos(omega_d t) + b sin(omega_d t)), started
    from the zero crossings of tip(t) - settled; then omega^2 = omega_d^2 + (c / 2)^2 with the drag
    rate c (exact for mass-proportional damping; the scheme's own numerical damping shows in sigma,
    not in the frequency). None when the run holds fewer than three crossings (a step of the order
    of the period or beyond: nothing oscillates).
    """
    from scipy.optimize import least_squares

    times, signal = np.asarray(times, float), np.asarray(tip, float) - settled
    sign = np.sign(signal)
    crossing = np.flatnonzero(sign[:-1] * sign[1:] < 0)
    if len(crossing) < 3:
        return None
    a, b = signal[crossing], signal[crossing + 1]
    t = times[crossing] + (times[crossing + 1] - times[crossing]) * a / (a - b)
    omega_start = math.pi / float(np.mean(np.diff(t[:7])))

    def residual(p):
        s, sigma, omega, c, d = p
        decay = np.exp(-sigma * times)
        return s + decay * (c * np.cos(omega * times) + d * np.sin(omega * times)) - signal

    scale = max(float(np.abs(signal).max()), 1e-300)
    fit = least_squares(residual, [0.0, drag_rate / 2.0, omega_start, signal[0], 0.0],
                        x_scale=[scale, max(drag_rate, 1.0), omega_start, scale, scale])
    omega_damped = abs(float(fit.x[2]))
    if not 0.5 * omega_start < omega_damped < 2.0 * omega_start:
        logger.warning("trajectory fit moved the damped frequency from %.4g to %.4g rad/s; using the crossings",
                       omega_start, omega_damped)
        omega_damped = omega_start
    return math.sqrt(omega_damped**2 + drag_rate**2 / 4.0) / (2.0 * math.pi)


def pareto_front(times: ArrayLike, errors: ArrayLike) -> list:
    """Indices of the points not dominated in (time, error), both to be minimised, by ascending time."""
    times, errors = np.asarray(times, float), np.asarray(errors, float)
    keep = np.flatnonzero(np.isfinite(times) & np.isfinite(errors))
    front, best = [], math.inf
    for index in keep[np.lexsort((errors[keep], times[keep]))]:
        if errors[index] < best:
            front.append(int(index))
            best = errors[index]
    return front


def _mark_pareto(runs: list) -> None:
    """Mark each run of the speed study on the front of time against each error (its ``pareto`` list), in place."""
    for key in ("first_frequency_error", "settled_deflection_error"):
        times = [run["wall_seconds_per_simulated_second"] if run.get(key) is not None else math.nan for run in runs]
        errors = [abs(run[key]) if run.get(key) is not None else math.nan for run in runs]
        for index in pareto_front(times, errors):
            runs[index].setdefault("pareto", []).append(key)


def merge_speed_studies(parts: Sequence[dict]) -> dict:
    """One speed study from parts run with disjoint ``steps`` (each integrator in a task of its own): the runs in
    the parts' order, the Pareto fronts over them all, the rest (the same in every part) from the first.

    Raises
    ------
    ValueError
        For no part, or parts of different set-ups (another case, rule, duration or drag).
    """
    if not parts:
        raise ValueError("no speed study to merge")
    shared = ("case", "rule", "per_height", "node_count", "duration_s", "drag_rate_per_s")
    for part in parts[1:]:
        if any(part[key] != parts[0][key] for key in shared):
            raise ValueError("speed studies of different set-ups cannot be merged: "
                             + ", ".join(f"{key} {parts[0][key]} / {part[key]}" for key in shared
                                         if part[key] != parts[0][key]))
    runs = [{key: value for key, value in run.items() if key != "pareto"} for part in parts for run in part["runs"]]
    _mark_pareto(runs)
    return {**parts[0], "runs": runs}


def speed_study(*, per_height: int = 1, rule: str = "van_gelder", steps: dict[str, Any] | None = None,
                periods: float = 5.0, duration: float | None = None, residual_amplitude: float = 5e-5,
                drag_rate: float | None = None, frame_dt: float = 1e-3, folder: str | os.PathLike[str] | None = None,
                progress: Callable[..., Any] | None = None) -> dict:
    """Wall time against accuracy for every integrator over a range of steps (module docstring).

    Parameters
    ----------
    per_height : int
        cells across the cantilever (1: 44 nodes)
    rule : str
        stiffness rule of the spring model
    steps : dict, optional
        integrator name -> multiples of its critical step (default :data:`INTEGRATOR_STEPS`)
    periods : float
        simulated time of each run, in periods of the loaded mode (of the spring model's own frequency)
    duration : float, optional
        simulated time of each run [s]; overrides ``periods``
    residual_amplitude : float
        what is left of the free motion at the end of the run, relative to its start: sets the drag when ``drag_rate``
        is not given, c = 2 ln(1 / residual) / duration (5e-5: c T / 2 = 9.9, a damping ratio of 9.9 / (2 pi periods),
        0.32 over 5 periods)
    drag_rate : float, optional
        mass-proportional damping c [1/s]; the motion decays as exp(-c t / 2)
    frame_dt : float
        sampling of the tip trajectory [s] (at least one step)
    folder : path, optional
        FEM cache folder
    progress : callable, optional
        ``progress(message)``

    Returns
    -------
    dict
        parameters, references and ``runs``: one record per (integrator, step), with ``simulated_s`` (the time reached:
        less than the duration when the run diverged) and ``wall_seconds_per_simulated_second`` (wall time over
        simulated time reached)
    """
    if not periods > 0:
        raise ValueError(f"periods = {periods!r} is not > 0")
    if not 0 < residual_amplitude < 1:
        raise ValueError(f"residual_amplitude = {residual_amplitude!r} is not in (0, 1)")
    from volspring.errors import SimulationDiverged
    from volspring.forces import Drag, Gravity
    from volspring.scene import Pins, Scene
    from volspring.simulate import simulate
    from volspring.stability import critical_step, omega_max

    note = progress or (lambda message: None)
    steps = INTEGRATOR_STEPS if steps is None else steps
    case = cantilever_gravity(per_height=per_height)
    held = held_nodes(case)
    assert held is not None and case.gravity is not None  # clamped whole, loaded by gravity
    model = spring_model(case.mesh, case.material, rule)
    note("speed: spring equilibrium and modes")
    equilibrium = spring_static(case, model).displacement
    settled_exact = tip_deflection(case, equilibrium)
    frequencies, shapes = spring_frequencies(model, held, count=4)
    mode = _loaded_mode(frequencies, shapes, model.masses[:, None] * np.asarray(case.gravity))
    frequency_exact = float(frequencies[mode])
    if duration is None:
        duration = periods / frequency_exact
    if drag_rate is None:
        drag_rate = 2.0 * math.log(1.0 / residual_amplitude) / duration
    # The modal coordinate q = phi^T M (x - x_eq) of that mode: exactly one damped oscillator for the
    # linearised network under mass-proportional drag, so its frequency is the integrator's alone.
    weights = model.masses[:, None] * shapes[mode]
    x_equilibrium = model.rest_positions + equilibrium
    note("speed: FEM P2 reference")
    fem_static = cache.cached_solve_static(case.mesh, case.material_tuple, folder=folder, **case.fem_arguments())
    fem_modes = cache.cached_solve_modes(case.mesh, case.material_tuple, folder=folder, clamp=list(case.clamps),
                                         count=4)
    settled_fem = tip_deflection(case, fem_static.displacement)
    frequency_fem = _bending_mode(fem_modes.frequencies, fem_modes.shapes, case.tip_nodes)
    scene = Scene(model, forces=[Gravity(g=tuple(case.gravity)), Drag(rate=drag_rate)],
                  pins=Pins(np.flatnonzero(held)))
    omega = omega_max(scene)
    base_step = 2.0 / omega
    rest_tip = case.mesh.points[case.tip_nodes] @ case.tip_direction
    runs: list[dict[str, Any]] = []
    for name, factors in steps.items():
        critical = critical_step(name, omega)
        unit = critical if 0 < critical < math.inf else base_step
        for factor in factors:
            dt = float(factor * unit)
            note(f"speed: {name} at {factor:g} x {'critical' if unit == critical else '2/omega_max'}")
            times, tips, modal = [], [], []

            def record(index, state):
                times.append(state.t)
                tips.append(float((state.x[case.tip_nodes] @ case.tip_direction - rest_tip).mean()))
                modal.append(float(np.sum(weights * (state.x - x_equilibrium))))

            record_run: dict[str, Any] = {
                "integrator": name, "step_factor": float(factor),
                "step_unit": "critical step" if unit == critical else "2 / omega_max", "dt_s": dt}
            start = time.perf_counter()
            try:
                result = simulate(scene, name, duration=duration, dt=dt, frame_dt=max(frame_dt, dt), callback=record,
                                  guard="off")
                stable = True
            except SimulationDiverged as error:
                stable, result = False, None
                record_run["diverged"] = str(error)
                simulated = max(float(error.time), dt)
            elapsed = time.perf_counter() - start
            if result is not None:  # stable
                simulated = float(result.state.t)
            record_run.update(stable=stable, simulated_s=simulated, wall_seconds=elapsed,
                              wall_seconds_per_simulated_second=elapsed / simulated)
            if result is not None:  # stable
                settled = tips[-1]
                frequency = _trajectory_frequency(np.array(times), np.array(modal), 0.0, drag_rate)
                record_run.update(
                    steps=result.steps_taken, settled_deflection_m=settled,
                    settled_deflection_error=(settled - settled_exact) / settled_exact,
                    settled_deflection_error_vs_fem=(settled - settled_fem) / settled_fem,
                    first_frequency_hz=frequency,
                    first_frequency_error=None if frequency is None else (frequency - frequency_exact) / frequency_exact,
                    first_frequency_error_vs_fem=None if frequency is None else (frequency - frequency_fem) / frequency_fem)
            runs.append(record_run)
            logger.info("speed: %s dt = %.3g s: %s, %.2f s", name, dt, "stable" if stable else "diverged", elapsed)
    _mark_pareto(runs)
    return {"case": "cantilever_gravity", "rule": rule, "per_height": per_height, "node_count": case.mesh.node_count,
            "duration_s": duration, "periods": duration * frequency_exact, "drag_rate_per_s": drag_rate,
            "damping_ratio": drag_rate / (4.0 * math.pi * frequency_exact),
            "residual_amplitude": math.exp(-drag_rate * duration / 2.0), "frame_dt_s": frame_dt,
            "omega_max_rad_per_s": omega, "base_step_s": base_step,
            "spring_settled_deflection_m": settled_exact, "spring_first_frequency_hz": frequency_exact,
            "fem_settled_deflection_m": settled_fem, "fem_first_frequency_hz": frequency_fem,
            "model_deflection_error": (settled_exact - settled_fem) / settled_fem,
            "model_frequency_error": (frequency_exact - frequency_fem) / frequency_fem,
            "runs": runs}


def cauchy_study(*, cells: int = 4, rules: Sequence[str] = RULES, nus: Sequence[float] = (0.0, 0.25, 0.3, 0.45, 0.49),
                 E: float = 1e6, strain: float = 1e-3, patterns: Sequence[str] = ("mirrored", "kuhn")) -> dict:
    """Effective elastic constants of the spring network of a unit cube, per rule, pattern and asked nu.

    Parameters
    ----------
    cells : int
        cells along each edge of the cube
    rules : sequence of str
    nus : sequence of float
        the Poisson ratios asked of the material
    E : float
        Young's modulus asked [Pa]
    strain : float
        axial strain of the test [-]
    patterns : sequence of str
        mesh patterns (:func:`meshing.structured_box`)

    Returns
    -------
    dict
        ``measurements``: one record per (pattern, rule, nu) with ``E_pa``, ``E_ratio`` (E_eff / E), ``nu_effective``,
        ``nu_asked``, ``volume_strain_per_axial_strain`` and its exact value 1 - 2 nu; ``summary`` per (pattern, rule):
        the spread of nu_effective over the asked nu
    """
    measurements, summary = [], {}
    for pattern in patterns:
        mesh = structured_box((cells,) * 3, (1.0, 1.0, 1.0), pattern=pattern)
        for rule in rules:
            values = []
            for nu in nus:
                measured = effective_constants(mesh, spring_model(mesh, Material(E=E, nu=nu, density=1000.0), rule),
                                               strain=strain)
                values.append(measured["nu"])
                measurements.append({"pattern": pattern, "rule": rule, "nu_asked": float(nu),
                                     "E_asked_pa": E, "E_pa": measured["E_pa"], "E_ratio": measured["E_pa"] / E,
                                     "nu_effective": measured["nu"], "nu_y": measured["nu_y"], "nu_z": measured["nu_z"],
                                     "volume_strain_per_axial_strain": measured["volume_strain_per_axial_strain"],
                                     "volume_strain_per_axial_strain_exact": 1.0 - 2.0 * nu})
            summary[f"{pattern}/{rule}"] = {"nu_effective_min": min(values), "nu_effective_max": max(values),
                                            "nu_asked": [float(nu) for nu in nus]}
    return {"cells": cells, "node_count": (cells + 1) ** 3, "strain": strain, "E_asked_pa": E,
            "measurements": measurements, "summary": summary}
