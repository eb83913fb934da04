"""What ``volspring-sim`` writes on the terminal: one-line errors and warnings, the progress bar, the summary.

Only the command line prints (the library logs and calls back); everything here writes to
``sys.stderr``, except the summary of a finished run, on ``sys.stdout``.
"""

from __future__ import annotations

import math
import sys
import time

import numpy as np

from volspring.cli._arguments import CHECKPOINT_NAME, PROG, SERIES_NAME, SURFACE_NAME

__all__ = ["Progress", "fail", "progress_enabled", "show_warning", "summary"]


def fail(message, status) -> int:
    """Print ``volspring-sim: error: MESSAGE`` on one line of stderr and return the exit ``status``."""
    text = " ".join(str(message).split())  # one line, whatever the message holds
    print(f"{PROG}: error: {text}", file=sys.stderr)
    return status


def show_warning(message, category, filename, lineno, file=None, line=None):
    """A :func:`warnings.showwarning` that prints one line, ``volspring-sim: warning: ...``, on stderr."""
    print(f"{PROG}: warning: {' '.join(str(message).split())}", file=sys.stderr)


def progress_enabled(args) -> bool:
    """Whether to draw the progress bar: ``--progress``/``--no-progress``, else when stderr is a terminal."""
    if args.quiet:
        return False
    return sys.stderr.isatty() if args.progress is None else args.progress


class Progress:
    """A one-line progress bar on stderr, redrawn with a carriage return at most 10 times a second.

    Parameters
    ----------
    enabled : bool
        False draws nothing (keyword-only, as the others).
    start, end : float
        Simulated times [s] of 0% and 100%.
    """

    WIDTH = 30

    def __init__(self, *, enabled, start, end):
        self.enabled, self.start, self.end = enabled, start, end
        self.drawn, self.width = False, 0
        self.last_draw = -math.inf
        self.clock = time.perf_counter()

    def update(self, t, frame) -> None:
        """Redraw for simulated time ``t`` [s] at frame number ``frame`` (throttled, except at 100%)."""
        now = time.perf_counter()
        done = 1.0 if self.end <= self.start else min(max((t - self.start) / (self.end - self.start), 0.0), 1.0)
        if not self.enabled or (now - self.last_draw < 0.1 and done < 1.0):
            return
        filled = int(round(done * self.WIDTH))
        bar = "#" * filled + "-" * (self.WIDTH - filled)
        line = f"[{bar}] {100 * done:5.1f}%  t = {t:.4g} s  frame {frame}  {now - self.clock:.1f} s"
        sys.stderr.write("\r" + line.ljust(self.width))  # padded over a longer previous line
        self.width = len(line)
        sys.stderr.flush()
        self.drawn, self.last_draw = True, now

    def close(self) -> None:
        """End the bar's line, if one was drawn."""
        if self.drawn:
            sys.stderr.write("\n")
            sys.stderr.flush()
            self.drawn = False


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
                     + (f", {SURFACE_NAME}_NNNN.obj, {SURFACE_NAME}.pc2" if args.blender else "")
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
