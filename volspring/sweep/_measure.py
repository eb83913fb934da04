"""One run of a sweep: a resolved scene assembled, stepped as ``volspring sim`` steps it, and measured.

:func:`run_scene` is what a worker executes. It takes the resolved scene (a plain dict, cheap to send), builds
it with :func:`volspring.scene_file.assemble_scene`, steps it with :func:`volspring.simulate` with the values
``volspring-sim`` passes (``ceil(duration / dt)`` steps, ``output.frame_dt``, ``integrator.guard``,
``integrator.runaway_factor``) under the same solver bookkeeping (:class:`~volspring.cli._statistics.StepStatistics`),
writes no frames, and returns a record (a JSON-serialisable dict). A run that fails (its scene refused, the
simulation diverged, a solver that did not converge) returns a record with its error instead of raising, so the
sweep goes on; only an error outside the run (a lost worker) reaches the caller.

The measured quantities, all of the final state (the set is small on purpose; :data:`MEASURED`):

==========================  ====================================================================================
``t_end``                   the time reached [s]
``displacement_max``        max over the nodes of |x - X|, X the rest positions [m]
``displacement_max_node``   the node where it is
``volume_change``           total signed tet volume / rest volume - 1 [-] (None for a scene without tets)
``inverted_tets``           tets turned inside out (signed volume <= 0)
``kinetic_energy``          sum 1/2 m |v|^2 [J]
``potential_energy``        elastic energy plus the conservative fields' potential [J]
==========================  ====================================================================================

for each probe ``NAME`` (a point [m]: the node nearest it at rest), ``NAME_node`` and its displacement
``NAME_ux``, ``NAME_uy``, ``NAME_uz`` [m]; and for a scene with a ``[compare]`` table, the comparison's numbers
prefixed ``compare_`` (``static_fem``: ``compare_peak_ratio``, ``compare_rms_error``, ...,
:mod:`validation.scene_comparison`): the error against the FEM reference of each run, the accuracy axis of a
speed/accuracy trade. Their time is ``seconds["compare"]``, not part of ``stepping``. With ``frequencies=N``, the
scene's N lowest natural frequencies at rest, ``frequency_1_hz`` ... (time ``seconds["modes"]``).
"""

from __future__ import annotations

import json
import logging
import math
import os
import time
import warnings
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["MEASURED", "SOLVER", "reference_key", "reference_of", "run_scene"]

logger = logging.getLogger(__name__)

#: The measured quantities of every run, in the table's order (see the module docstring).
MEASURED = ("t_end", "displacement_max", "displacement_max_node", "volume_change", "inverted_tets",
            "kinetic_energy", "potential_energy")
#: The solver statistics of every run: steps, and CG iterations per step (empty for explicit integrators).
SOLVER = ("steps", "cg_iterations_mean", "cg_iterations_max", "cg_iterations_total")


def run_scene(scene: dict, *, base: str | os.PathLike[str] = ".", probes: Mapping[str, Sequence[float]] | None = None,
              frequencies: int = 0, reference: Any = None) -> dict:
    """Assemble, step and measure one resolved scene; never raises for a failure of the run itself.

    Parameters
    ----------
    scene : dict
        A resolved scene (:func:`volspring.scene_file.read_scene`); its ``output`` table gives ``frame_dt``
        only (no frames are written).
    base : path-like
        The folder the scene's file names are relative to.
    probes : mapping of str to (3,) float, optional
        Name -> a point [m]; the node nearest it at rest is measured.
    frequencies : int
        Also measure the scene's lowest natural frequencies at rest, this many (``frequency_1_hz``, ...:
        :func:`volspring.modes.solve_modes`, with the scene's supports; deterministic); 0 measures none.
    reference : object, optional
        The ``[compare]`` comparison's reference answer, made once for the runs of one body
        (:func:`reference_of`); None: the comparison makes its own.

    Returns
    -------
    dict
        ``status`` ("done", "diverged" or "failed"), ``error`` (one line, or None), ``solver`` (the
        :data:`SOLVER` values), ``measured`` (:data:`MEASURED` and the probes' values), ``seconds``
        (``wall``, ``build``, ``stepping``) and ``warnings`` (their messages).

    Examples
    --------
    >>> from pathlib import Path
    >>> from volspring.scene_file import read_scene
    >>> path = Path(__file__).parents[2] / "examples" / "scenes" / "beam.toml"
    >>> scene = read_scene(path, overrides=["bodies[0].size=0.1", "duration=0.05"])
    >>> record = run_scene(scene, base=path.parent, probes={"tip": [0.5, 0.0, 0.0]})
    >>> record["status"], record["solver"]["steps"], record["measured"]["tip_uz"] < 0
    ('done', 5, True)
    """
    from volspring.cli._statistics import StepStatistics
    from volspring.scene_file import assemble_scene
    from volspring.simulate import simulate

    started = time.perf_counter()
    seconds: dict[str, float | None] = {"wall": None, "build": None, "stepping": None}
    measured: dict[str, Any] = {}
    record: dict[str, Any] = {"status": "done", "error": None, "error_type": None, "solver": dict.fromkeys(SOLVER),
                              "measured": measured, "seconds": seconds, "warnings": []}
    statistics = StepStatistics()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            built = assemble_scene(scene, base=Path(base))
            seconds["build"] = time.perf_counter() - started
            dt, integrator = scene["integrator"]["dt"], scene["integrator"]
            steps = max(int(math.ceil(scene["duration"] / dt - 1e-9)), 0)  # as volspring-sim counts them
            runaway = integrator.get("runaway_factor")
            checks = {} if runaway is None else {"runaway_factor": runaway}
            stepping = time.perf_counter()
            with statistics.watching(built.integrator):
                result = simulate(built.scene, built.integrator, duration=steps * dt, dt=dt, state=built.state,
                                  frame_dt=scene["output"]["frame_dt"], guard=integrator["guard"], **checks)
            seconds["stepping"] = time.perf_counter() - stepping
            measured.update(_measured(built.scene, result.state, probes or {}))
            if built.comparison is not None:  # the scene's [compare]: its numbers are measured quantities too
                from volspring.scene_file import compare_final_state

                comparing = time.perf_counter()
                numbers = compare_final_state(scene, built.comparison, result.state.x, reference=reference)
                record["reference"] = "shared" if reference is not None else "own"
                measured.update({f"compare_{name}": value for name, value in numbers.items()})
                seconds["compare"] = time.perf_counter() - comparing
            if frequencies:
                from volspring.modes import solve_modes

                solving = time.perf_counter()
                modes = solve_modes(built.scene, count=int(frequencies))
                measured.update({f"frequency_{k + 1}_hz": float(value) for k, value in enumerate(modes.frequencies)})
                seconds["modes"] = time.perf_counter() - solving
        except FloatingPointError as error:  # SimulationDiverged, or a spring collapsed to zero length
            record.update(status="diverged", error=_one_line(error), error_type=type(error).__name__)
        except Exception as error:  # a value the scene or the API refuses, a solver that failed: the run's row
            record.update(status="failed", error=_one_line(error), error_type=type(error).__name__)
    solver = statistics.record()
    iterations = solver.get("cg_iterations", {})
    record["solver"] = {"steps": solver["steps"], "cg_iterations_mean": iterations.get("mean"),
                        "cg_iterations_max": iterations.get("max"), "cg_iterations_total": iterations.get("total")}
    record["warnings"] = list(dict.fromkeys(_one_line(warning.message) for warning in caught))
    seconds["wall"] = time.perf_counter() - started
    return record


def reference_of(scene: dict, *, base: str | os.PathLike[str] = ".") -> Any:
    """The reference answer of a resolved scene's ``[compare]`` (the FEM answer of its body: made once and shared by
    the runs that :func:`reference_key` groups), or None: no ``[compare]``, no reference apart, or one that cannot
    be made (each run then meets the error itself, as its row)."""
    from volspring.scene_file import assemble_scene, comparison_reference

    if "compare" not in scene:
        return None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the runs report the scene's warnings
            built = assemble_scene(scene, base=Path(base))
            return None if built.comparison is None else comparison_reference(scene, built.comparison)
    except Exception as error:  # the runs will fail on it, each with its row
        logger.info("no shared reference (%s: %s); each run makes its own", type(error).__name__, error)
        return None


#: The keys of a body that change its model but not its static problem (mesh, material, held nodes, gravity).
MODEL_ONLY_KEYS = ("model", "alpha", "rule", "stiffness", "damping_ratio", "velocity", "angular_velocity", "name")


def reference_key(scene: dict) -> str | None:
    """What a ``[compare]`` reference depends on, as text: runs with equal keys share one (None without
    ``[compare]``). It leaves out the integrator, the duration, the outputs and the compared body's model keys
    (:data:`MODEL_ONLY_KEYS`), so a sweep over steps, integrators or rungs solves the reference once; anything else
    that differs (the material, the mesh, the supports, gravity) gives another key."""
    if "compare" not in scene:
        return None
    table = scene["compare"]
    body = {key: value for key, value in scene["bodies"][table["body"]].items() if key not in MODEL_ONLY_KEYS}
    fields = [field for field in scene["fields"] if field["type"] == "gravity"]
    return json.dumps({"compare": table, "body": body, "supports": scene["supports"], "fields": fields},
                      sort_keys=True, default=str)


def _measured(scene, state, probes) -> dict:
    """The quantities of :data:`MEASURED` (and the probes') of the final ``state``."""
    from meshing.geometry import signed_tet_volumes
    from volspring.diagnostics import tet_inversion

    model = scene.model
    displacement = state.x - model.rest_positions
    length = np.linalg.norm(displacement, axis=1)
    worst = int(np.argmax(length))
    mesh = None if model.topology is None else model.topology.mesh
    volume_change = None
    if mesh is not None and mesh.tet_count:
        volume = signed_tet_volumes(state.x[: mesh.node_count], mesh.tets).sum()
        volume_change = float(volume / mesh.tet_volumes.sum() - 1.0)
    measured = {"t_end": float(state.t), "displacement_max": float(length[worst]), "displacement_max_node": worst,
                "volume_change": volume_change, "inverted_tets": int(tet_inversion(scene, state.x).count),
                "kinetic_energy": float(scene.kinetic_energy(state.v)),
                "potential_energy": float(scene.potential_energy(state.x, state.t))}
    for name, point in probes.items():
        node = int(np.argmin(np.linalg.norm(model.rest_positions - np.asarray(point, dtype=np.float64), axis=1)))
        measured[f"{name}_node"] = node
        for axis, value in zip("xyz", displacement[node]):
            measured[f"{name}_u{axis}"] = float(value)
    return measured


def _one_line(message) -> str:
    return " ".join(str(message).split())
