"""The run of ``volspring-sim``: exit statuses, the output folder, the stepping loop, frames and checkpoints.

:func:`main` parses, then :func:`run` claims the output folder (its manifest lists every file before
it exists and ends with the run's status), builds the scene (:mod:`volspring.cli._build`), steps it
with :func:`volspring.simulate`, writing frames and checkpoints from the frame callback, and prints
the summary. Ctrl-C, SIGTERM and SIGHUP end the run with one line saying where it stopped and how to
resume it (:class:`RunProgress`).
"""

from __future__ import annotations

import logging
import math
import os
import shlex
import sys
import time
import warnings

from meshing._command_line import stderr_line, stdout_to_stderr
from volspring.cli import _build
from volspring.cli._arguments import (CHECKPOINT_NAME, EXIT_DIVERGED, EXIT_FAILED, EXIT_USAGE, PROG, SERIES_NAME,
                                      SURFACE_NAME, InputError, UsageError, build_parser, check_arguments,
                                      joined_vectors)
from volspring.cli._terminal import Progress, fail, show_warning, summary_lines
from collections.abc import Sequence
from typing import Any

__all__ = ["Diverged", "RunProgress", "main", "run"]


class Diverged(FloatingPointError):
    """The simulation diverged; the message also says which frames the output folder holds."""


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``volspring sim`` (``volspring-sim``) with ``argv`` (default ``sys.argv[1:]``); returns the exit status.

    0 done; 2 a bad command line or bad input (values, files, the output folder, a checkpoint that does
    not fit, a step beyond an explicit integrator's limit with ``--guard raise``), found before the first
    step; 1 the run failed while stepping or writing; 3 the simulation diverged; 130 Ctrl-C, 143 SIGTERM,
    129 SIGHUP. Every failure is one line on stderr.
    """
    from volspring.errors import StepTooLarge

    argv = sys.argv[1:] if argv is None else [str(token) for token in argv]
    try:
        args = build_parser().parse_args(joined_vectors(argv))
    except UsageError as error:
        return fail(error, EXIT_USAGE)
    except SystemExit as done:  # --help, --version
        return done.code if isinstance(done.code, int) else 0
    if args.verbose:
        logging.basicConfig(level=logging.INFO, format="%(name)s: %(message)s", stream=sys.stderr)
    from meshing._signals import Interrupted, exit_status, handle_termination, interruption_name

    where = RunProgress()
    try:
        with warnings.catch_warnings(), handle_termination():
            warnings.showwarning = show_warning  # one line each, on stderr, from the first check on
            return run(args, where, argv)
    except FloatingPointError as error:  # SimulationDiverged, or a spring collapsed to zero length
        return fail(error, EXIT_DIVERGED)
    except (InputError, ValueError, OSError, RuntimeError, Warning) as error:  # RuntimeError: SolverNotConverged...
        # Before the first step the input is at fault (a value, a file, the folder, the checkpoint); after it,
        # the run. A step beyond the stability limit (--guard raise) is refused before the first step.
        bad_input = isinstance(error, (InputError, StepTooLarge)) or not where.running
        return fail(error, EXIT_USAGE if bad_input else EXIT_FAILED)
    except (KeyboardInterrupt, Interrupted) as stop:  # Ctrl-C, SIGTERM, SIGHUP: one line, no traceback
        stderr_line(PROG, f"interrupted by {interruption_name(stop)}{where.describe(argv)}")
        return exit_status(stop)


class RunProgress:
    """Where a run has got to, for the line printed when it is interrupted."""

    def __init__(self):
        self.state = None
        self.checkpoint = None  # (path, t) of the last checkpoint written
        self.running = False  # the stepping has started: a failure from now on is the run's, not the input's

    def describe(self, argv) -> str:
        """`` at t = ... s (step k); the last checkpoint is ...; resume with: volspring-sim ...``."""
        if self.state is None:
            return " before the first step; nothing to resume"
        text = f" at t = {self.state.t:.6g} s (step {self.state.step})"
        if self.checkpoint is None:
            return text + "; no checkpoint was written (--checkpoint-every N makes a run resumable)"
        path, t = self.checkpoint
        kept = [token for index, token in enumerate(argv)
                if token != "--resume" and (index == 0 or argv[index - 1] != "--resume")
                and not token.startswith("--resume=")]
        resume = shlex.join([PROG, *kept, "--resume", str(path)])
        return f"{text}; the last checkpoint is {path} at t = {t:.6g} s; resume with: {resume}"


def run(args, where: RunProgress, argv) -> int:
    """Check, open the output folder, then build, run and report; the folder's manifest ends with the
    run's status (finished, failed, interrupted)."""
    args.scene = None
    if _build.is_scene_file(args.input):  # a scene file: its values, the flags given and --set, checked
        args.scene = _build.read_scene_file(args, argv)
    elif args.set:
        raise InputError(f"--set sets a value of a scene file; INPUT {args.input} is not one (*.toml)")
    else:
        check_arguments(args)
    if args.out is None:
        return _run_in(args, where, None)
    from volspring.output import RunFolder, check_output_folder

    try:
        check_output_folder(args.out, label="--out")  # a file, below a file, not writable: before any work
    except OSError as error:
        raise InputError(str(error)) from None

    # Claimed before any work: a refused folder costs nothing, and every file is listed before it exists.
    folder = RunFolder.open(args.out, command=[PROG, *argv], overwrite=args.overwrite, resume=args.resume is not None,
                            flags={"overwrite": "--overwrite", "resume": "--resume CHECKPOINT"})
    with folder:
        return _run_in(args, where, folder)


def _run_in(args, where: RunProgress, folder) -> int:
    from volspring.checkpoint import load_checkpoint, save_checkpoint
    from volspring.simulate import simulate

    from volspring.cli._statistics import RunTimings, StepStatistics
    from volspring.output.run_manifest import package_versions

    timings, statistics = RunTimings(), StepStatistics()
    started = timings.started
    note = (lambda key, value: None) if folder is None else folder.note
    # How the run was made, before anything can fail: the folder's manifest already holds the command.
    note("working_directory", os.getcwd())
    note("versions", package_versions())
    with stdout_to_stderr(args.verbose), timings.phase("build"):  # with -v, gmsh's log on stderr, not in the summary
        built = _build.build_run(args, note=None if folder is None else folder.note)  # the flags, or the scene file
    model, scene, integrator = built.model, built.scene, built.integrator

    state, first_frame = built.state, 0
    total_steps = max(int(math.ceil(args.duration / args.dt - 1e-9)), 0)
    if args.resume is not None:
        state = load_checkpoint(args.resume, scene=scene, integrator=integrator, dt=args.dt)
        where.checkpoint = (args.resume, state.t)
        if state.step >= total_steps:
            raise InputError(f"the checkpoint {args.resume} is at step {state.step} (t = {state.t:.6g} s), "
                             f"already at --duration {args.duration:g} s ({total_steps} steps)")
        first_frame = _frames_before(args, state.t)
    # Steps are counted from the run's start, so a resumed run ends on the same step as an
    # uninterrupted one (no round-off from t).
    remaining = total_steps - state.step

    writers = _writers(args, built, first_frame, None if folder is None else folder.record)
    checks = {} if args.runaway_factor is None else {"runaway_factor": args.runaway_factor}
    progress = Progress(args=args, first_step=state.step, last_step=total_steps)
    last: dict[str, Any] = {"frames": 0, "state": state}  # frames written by this run, and the latest

    def on_frame(frame_index, current):
        with timings.phase("writing"):
            if folder is not None:  # the frame's files listed in one manifest write, before any is written
                folder.record(*(path for writer in writers for path in writer.frame_paths()))
            for writer in writers:
                writer(frame_index, current)
            if args.checkpoint_every and frame_index and frame_index % args.checkpoint_every == 0:
                folder.record(args.out / CHECKPOINT_NAME)
                save_checkpoint(args.out / CHECKPOINT_NAME, current, scene=scene, integrator=integrator, dt=args.dt)
                where.checkpoint = (args.out / CHECKPOINT_NAME, current.t)
        last["frames"] += 1
        last["state"] = where.state = current
        progress.update(current, first_frame + frame_index)

    where.running = True
    try:
        with statistics.watching(integrator), timings.phase("stepping"):
            result = simulate(scene, integrator, duration=remaining * args.dt, dt=args.dt, state=state,
                              frame_dt=args.frame_dt, callback=on_frame, guard=args.guard, **checks)
    except FloatingPointError as error:  # SimulationDiverged, or a spring collapsed to zero length
        progress.close()
        kept = ""
        if args.out is not None:
            kept = (f"; {args.out} holds {first_frame + last['frames']} complete frame(s)"
                    + (f", the last at t = {last['state'].t:.6g} s" if last["frames"] else ""))
        raise Diverged(f"{error}{kept}") from error
    finally:
        progress.close()
        note("solver", statistics.record(frames=last["frames"]))
    if args.checkpoint_every:
        with timings.phase("writing"):
            folder.record(args.out / CHECKPOINT_NAME)
            save_checkpoint(args.out / CHECKPOINT_NAME, result.state, scene=scene, integrator=integrator,
                            dt=args.dt)
    lines = summary_lines(args, built.origin, model, scene, integrator, result, first_frame,
                          time.perf_counter() - started, built.summary_record,
                          surface_series=built.triangles is not None)
    if built.comparison is not None:  # the scene's [compare]: the end state against the reference
        from volspring.scene_file import compare_final_state, comparison_line

        with timings.phase("compare"):
            numbers = compare_final_state(args.scene, built.comparison, result.state.x)
        note("comparison", {"case": args.scene["compare"]["case"], **numbers})
        lines.append(comparison_line(args.scene, numbers))
    note("timings", timings.record())
    note("summary", lines)
    if not args.quiet:
        print("\n".join(lines))
    return 0


def _frames_before(args, t) -> int:
    """How many frames of an earlier run come before time t (the resumed run rewrites from t on)."""
    from volspring.output import read_pvd

    if args.out is None:
        return 0
    # The first series a ParaViewWriter writes: the tets, or the springs of a model without tets.
    pvd = next((path for path in (args.out / f"{SERIES_NAME}.pvd", args.out / f"{SERIES_NAME}_springs.pvd")
                if path.is_file()), None)
    if pvd is None:
        return 0
    # Half a step: frames are at least a step apart, and the PVD lists decimal times while t is the float the
    # steps added up to, which drifts from the decimal by more than 1e-6 dt after ~3e5 steps.
    return sum(1 for time, _ in read_pvd(pvd) if time < t - 0.5 * args.dt)


def _writers(args, built, first_frame, record):
    from volspring.output import BlenderWriter, ParaViewWriter

    if args.out is None:
        return []
    model = built.model
    writers: list = [ParaViewWriter(args.out, model, name=SERIES_NAME, first_frame=first_frame, record=record,
                              triangles=built.triangles)]
    if args.blender:
        if args.render_surface is not None:
            surface = _build.anchored_surface(args.render_surface, model, args.units, args.scale)
        elif model.topology is None and built.render_surface is None:
            raise InputError("output.blender: strings and hair have no surface for Blender's OBJ files; their "
                             f"springs are in {SERIES_NAME}_springs.pvd (ParaView)")
        else:
            surface = model if built.render_surface is None else built.render_surface
        pc2 = args.out / f"{SURFACE_NAME}.pc2"
        # A frame every step when --frame-dt is below --dt: the import script's fps is one per frame written.
        writers.append(BlenderWriter(args.out, surface, name=SURFACE_NAME,
                                     first_frame=first_frame if pc2.is_file() else 0, record=record,
                                     frame_dt=max(args.frame_dt, args.dt)))
    return writers
