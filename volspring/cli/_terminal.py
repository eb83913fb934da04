"""What ``volspring sim`` writes on the terminal: one-line errors and warnings, the progress bar, the summary.

Only the command line prints (the library logs and calls back); everything here writes to
``sys.stderr``, except the summary of a finished run, on ``sys.stdout``.
"""

from __future__ import annotations


import numpy as np

from meshing._command_line import advance_to, error_line, progress_bar, progress_mode, stderr_line
from volspring.cli._arguments import CHECKPOINT_NAME, PROG, SERIES_NAME, SURFACE_NAME

__all__ = ["Progress", "fail", "show_warning", "summary", "summary_lines"]


def fail(message, status) -> int:
    """Print ``volspring-sim: error: MESSAGE`` on one line of stderr and return the exit ``status``."""
    return error_line(PROG, message, status)


def show_warning(message, category, filename, lineno, file=None, line=None):
    """A :func:`warnings.showwarning` that prints one line, ``volspring-sim: warning: ...``, on stderr."""
    stderr_line(PROG, f"warning: {' '.join(str(message).split())}")


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


def summary(*args, **options) -> None:
    """Print :func:`summary_lines` on stdout."""
    print("\n".join(summary_lines(*args, **options)))


def summary_lines(args, origin, model, scene, integrator, result, first_frame, seconds, record=None, *,
                  surface_series=False) -> list:
    """What was run and how it ended: body, model, run, end state, inverted tets, outputs; one line each.

    ``record`` is the model's description (:func:`volspring.cli._build.model_record`), for its line;
    ``surface_series`` says that a cloth's triangles were written (``frame_surface.pvd``). The run prints
    the lines on stdout (unless ``--quiet``) and keeps them in its manifest (``"summary"``).
    """
    state = result.state
    displacement = np.linalg.norm(state.x - model.rest_positions, axis=1)
    pinned = 0 if scene.pins is None else len(scene.pins.nodes)
    topology = model.topology
    mesh = None if topology is None else topology.mesh
    tets = 0 if mesh is None else mesh.tet_count
    nodes = f"{model.node_count if mesh is None else mesh.node_count} nodes"
    springs = f", {model.spring_count} springs" if model.spring_count else ""
    # Past the mesh nodes: shell nodes (layer >= 1), then the nodes of strings, hair, cloths and lattices
    # joined after the tet bodies (layer 0, structures.combine).
    shells = 0 if topology is None else int((topology.shell_layer > 0).sum())
    if shells:  # a topology file with shells: the model has them too
        nodes += f" + {shells} shell nodes in {topology.layer_count} layer(s)"
        counts = model.kind_counts()
        springs += f" ({sum(counts[kind] for kind in ('shell', 'shell_diagonal', 'shell_edge'))} shell springs)"
    if mesh is not None and model.node_count > mesh.node_count + shells:
        nodes += f" + {model.node_count - mesh.node_count - shells} nodes of strings, hair, cloths or lattices"
    lines = [
        f"body: {origin}: {nodes}" + (f", {tets} tets" if mesh is not None else "") + f"{springs}, "
        f"mass {model.total_mass:.6g} kg, {pinned} pinned node(s)",
    ]
    if record is not None:
        lines.append(_model_line(record))
    lines += [
        f"run: {integrator.name}, dt = {args.dt:g} s, {result.steps_taken} steps to t = {state.t:.6g} s "
        f"in {seconds:.2f} s wall time",
        f"end: max displacement {displacement.max():.6g} m (node {int(displacement.argmax())}), "
        f"kinetic energy {result.kinetic_energy[-1]:.6g} J, total energy {result.total_energy[-1]:.6g} J",
    ]
    if tets:
        lines.append(f"tets: {result.inverted_tets[-1]} of {tets} inverted at the end, at most "
                     f"{result.inverted_tets.max()} at a frame; worst volume ratio "
                     f"{np.nanmin(result.worst_volume_ratio):.3g}")
    if args.out is not None:
        series = (([f"{SERIES_NAME}.pvd"] if tets else [])
                  + ([f"{SERIES_NAME}_springs.pvd"] if model.spring_count else [])
                  + ([f"{SERIES_NAME}_surface.pvd"] if surface_series else []))
        lines.append(f"output: {first_frame + result.frame_count} frame(s) in {args.out} ({', '.join(series)}"
                     + (f", {SURFACE_NAME}_NNNN.obj, {SURFACE_NAME}.pc2, {SURFACE_NAME}_blender.py" if args.blender else "")
                     + (f", {CHECKPOINT_NAME}" if args.checkpoint_every else "") + ")")
    return lines


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
