"""What ``volspring sim`` writes on the terminal: one-line errors and warnings, the progress bar, the summary.

Only the command line prints (the library logs and calls back); everything here writes to
``sys.stderr``, except the summary of a finished run, on ``sys.stdout``.
"""

from __future__ import annotations

import sys

import numpy as np

from meshing._command_line import advance_to, error_line, progress_bar, progress_mode
from volspring.cli._arguments import CHECKPOINT_NAME, PROG, SERIES_NAME, SURFACE_NAME

__all__ = ["Progress", "fail", "show_warning", "summary"]


def fail(message, status) -> int:
    """Print ``volspring-sim: error: MESSAGE`` on one line of stderr and return the exit ``status``."""
    return error_line(PROG, message, status)


def show_warning(message, category, filename, lineno, file=None, line=None):
    """A :func:`warnings.showwarning` that prints one line, ``volspring-sim: warning: ...``, on stderr."""
    print(f"{PROG}: warning: {' '.join(str(message).split())}", file=sys.stderr)


class Progress:
    """The steps of a run on stderr (tqdm, :func:`meshing._command_line.progress_bar`): on a terminal a bar with
    the step rate and the time left, in a log a line every few seconds at most; the simulated time and frame
    after it.

    Parameters
    ----------
    args : argparse.Namespace
        ``--progress``/``--no-progress`` and ``--quiet`` (keyword-only, as the others).
    first_step, last_step : int
        The step counts of 0 % and 100 % (a resumed run starts past 0).
    """

    def __init__(self, *, args, first_step, last_step):
        self.first_step = first_step
        self.bar = progress_bar(progress_mode(args), total=max(last_step - first_step, 0), desc="sim", unit="steps")

    def update(self, state, frame) -> None:
        """Move to ``state`` (its step count and time ``t`` [s]) at frame number ``frame``."""
        advance_to(self.bar, state.step - self.first_step, f"t = {state.t:.4g} s, frame {frame}")

    def close(self) -> None:
        """End the bar's line, if one was drawn."""
        self.bar.close()


def summary(args, origin, model, scene, integrator, result, first_frame, seconds, record=None) -> None:
    """Print what was run and how it ended on stdout: body, model, run, end state, inverted tets, outputs.

    ``record`` is the model's description (:func:`volspring.cli._build.model_record`), for its line.
    """
    state = result.state
    displacement = np.linalg.norm(state.x - model.rest_positions, axis=1)
    pinned = 0 if scene.pins is None else len(scene.pins.nodes)
    topology = model.topology
    mesh = topology.mesh
    nodes = f"{mesh.node_count} nodes"
    springs = f", {model.spring_count} springs" if model.spring_count else ""
    if topology.shell_node_count:  # a topology file with shells: the model has them too
        nodes += f" + {topology.shell_node_count} shell nodes in {topology.layer_count} layer(s)"
        springs += f" ({model.spring_count - model.kind_counts()['tet_edge']} shell springs)"
    lines = [
        f"body: {origin}: {nodes}, {mesh.tet_count} tets{springs}, "
        f"mass {model.total_mass:.6g} kg, {pinned} pinned node(s)",
    ]
    if record is not None:
        lines.append(_model_line(record))
    lines += [
        f"run: {integrator.name}, dt = {args.dt:g} s, {result.steps_taken} steps to t = {state.t:.6g} s "
        f"in {seconds:.2f} s wall time",
        f"end: max displacement {displacement.max():.6g} m (node {int(displacement.argmax())}), "
        f"kinetic energy {result.kinetic_energy[-1]:.6g} J, total energy {result.total_energy[-1]:.6g} J",
        f"tets: {result.inverted_tets[-1]} of {mesh.tet_count} inverted at the end, at most "
        f"{result.inverted_tets.max()} at a frame; worst volume ratio {np.nanmin(result.worst_volume_ratio):.3g}",
    ]
    if args.out is not None:
        lines.append(f"output: {first_frame + result.frame_count} frame(s) in {args.out} ({SERIES_NAME}.pvd"
                     + (f", {SERIES_NAME}_springs.pvd" if model.spring_count else "")
                     + (f", {SURFACE_NAME}_NNNN.obj, {SURFACE_NAME}.pc2, {SURFACE_NAME}_blender.py" if args.blender else "")
                     + (f", {CHECKPOINT_NAME}" if args.checkpoint_every else "") + ")")
    print("\n".join(lines))


def _model_line(record) -> str:
    """``model: smoothed (alpha 0.6), E 1e+06 Pa, nu 0.45 (honoured), ...`` from a model record."""
    rung = record["rung"]
    detail = f"alpha {record['alpha']:g}" if "alpha" in record else f"rule {record['rule']}"
    nu = f"nu {record['nu']:g}" + (" (not used by springs)" if rung == "springs" else "")
    regions = record.get("region_materials")
    text = (f"model: {rung} ({detail}), E {record['E']:g} Pa, {nu}, density {record['density']:g} kg/m^3, "
            f"damping ratio {record['damping_ratio']:g}")
    if regions:
        text += f", {len(regions)} region material(s) (tags {', '.join(regions)})"
    return text + "; " + ", ".join(record["element_sets"])
