"""``volspring-sim``: a minimal simulation from the command line.

A mesh file (any volume format meshio reads) or a built-in shape (``box:1,0.1,0.1``), a
material, pins by box regions, gravity, an integrator and a step; frames written as a ParaView
series (and optionally a Blender surface cache), checkpoints to resume from, a progress bar on
stderr and a summary on stdout. A fuller scene format is for a later version.

Exit status: 0 success, 1 bad input or failed run (one ``volspring-sim: error: ...`` line on
stderr), 2 bad command line, 3 the simulation diverged (the output folder then holds only the
complete frames before it), 130 Ctrl-C and 143 SIGTERM (129 SIGHUP): one line saying where the
run stopped, its last checkpoint and the command that resumes it; no traceback, no temporary file.

Examples
--------
>>> import tempfile
>>> from volspring.cli import main
>>> main(["box:0.2,0.05,0.05", "--size", "0.05", "--pin", "-0.1,-1,-1,-0.1,1,1",
...       "--duration", "0.01", "--dt", "0.005", "--out", tempfile.mkdtemp(), "--quiet"])
0
"""

from __future__ import annotations

import argparse
import math
import shlex
import sys
import time
import warnings
from pathlib import Path

import numpy as np

__all__ = ["main", "build_parser"]

PROG = "volspring-sim"
CHECKPOINT_NAME = "checkpoint.npz"
SERIES_NAME = "frame"
SURFACE_NAME = "surface"
# Relative tolerance of pin boxes: a box face placed on a row of nodes catches them despite round-off.
PIN_TOLERANCE = 1e-9
EXIT_INPUT, EXIT_USAGE, EXIT_DIVERGED = 1, 2, 3
DEFAULT_NU = 0.45
VECTOR_OPTIONS = ("--pin", "--gravity")  # comma-separated numbers that may start with a minus sign


class _UsageError(Exception):
    """A bad command line (argparse's complaint), reported in one line."""


class _InputError(Exception):
    """Bad input found after parsing, reported in one line."""


class _Diverged(FloatingPointError):
    """The simulation diverged; the message also says which frames the output folder holds."""


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # argparse would print the usage and exit; we report one line
        raise _UsageError(message)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``volspring-sim``."""
    from volspring.integrators import INTEGRATORS
    from volspring.model import STIFFNESS_RULES
    from volspring.simulate import RUNAWAY_CHECKS, RUNAWAY_FACTOR
    from volspring.output.run_folder import MANIFEST_NAME as MANIFEST
    from volspring.units import add_unit_arguments

    parser = _Parser(prog=PROG, description="Simulate a volumetric soft body as a tetrahedral mass-spring model.",
                     formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    parser.add_argument("input", metavar="INPUT",
                        help="a volume mesh file (.msh, .vtu, .mesh, ...) or a built-in shape NAME:D1,D2,... "
                             "such as box:1,0.1,0.1 or sphere:0.5 [m]")
    body = parser.add_argument_group("body")
    body.add_argument("--size", type=float, help="tet edge length for a built-in shape, in --units "
                                                 "(default: a tenth of its extent, at most half its smallest side)")
    body.add_argument("--mesher", choices=("gmsh", "delaunay"), default="gmsh", help="mesher for a built-in shape")
    body.add_argument("--seed", type=int, help="random seed of the mesher")
    add_unit_arguments(body, applies_to="INPUT (a mesh file's coordinates or a shape's dimensions), --size, --pin "
                                        "boxes and --render-surface", scale_applies_to="INPUT and --render-surface")
    body.add_argument("--E", type=float, default=1e6, help="Young's modulus [Pa] (soft rubber)")
    body.add_argument("--nu", type=float, default=None,
                      help=f"Poisson's ratio [-] (default {DEFAULT_NU}); the spring rules ignore it: pure springs have "
                           "one effective Poisson ratio whatever nu is asked (the Cauchy limit), and say so when "
                           "--nu is given")
    body.add_argument("--density", type=float, default=1100.0, help="density [kg/m^3]")
    body.add_argument("--rule", choices=STIFFNESS_RULES, default="van_gelder", help="spring stiffness rule")
    body.add_argument("--stiffness", type=float, help="the raw spring constant of --rule uniform [N/m]")
    body.add_argument("--damping-ratio", type=float, default=0.05, help="damping ratio of every spring [-]")
    scene = parser.add_argument_group("scene")
    scene.add_argument("--gravity", default="0,0,-9.81", help="gravity gx,gy,gz [m/s^2], or 'off'")
    scene.add_argument("--drag", type=float, default=0.0, help="global viscous drag rate [1/s]")
    scene.add_argument("--pin", action="append", default=[], metavar="XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX",
                       help="pin the nodes inside this box, in --units (repeatable)")
    run = parser.add_argument_group("run")
    run.add_argument("--integrator", choices=tuple(INTEGRATORS), default="implicit_euler")
    run.add_argument("--dt", type=float, default=1e-3, help="time step [s]")
    run.add_argument("--duration", type=float, default=1.0, help="end time of the run [s]")
    run.add_argument("--frame-dt", type=float, default=0.04, help="time between frames [s]")
    run.add_argument("--guard", choices=("warn", "raise", "off"), default="warn",
                     help="what a step beyond an explicit integrator's stability limit does")
    run.add_argument("--newton-iterations", type=int, default=0, metavar="N",
                     help="implicit_euler: Newton iterations on the nonlinear step after the linearised one "
                          "(0: Baraff-Witkin); more follow large rotations more closely at large --dt")
    run.add_argument("--runaway-factor", type=float, default=None, metavar="F",
                     help="divergence check: the run has diverged when its energy exceeds the start energy plus "
                          "the work of forces and moving pins by more than F times the start's energy scale and "
                          f"keeps growing over {RUNAWAY_CHECKS} checks (default {RUNAWAY_FACTOR:g}); 'inf' turns the "
                          "energy check off (NaN and Inf are always caught)")
    output = parser.add_argument_group("output")
    output.add_argument("--out", type=Path, metavar="DIR",
                        help=f"write the frames there ({SERIES_NAME}.pvd: tets, {SERIES_NAME}_springs.pvd: springs)")
    output.add_argument("--blender", action="store_true",
                        help=f"also write the boundary surface as {SURFACE_NAME}_NNNN.obj and {SURFACE_NAME}.pc2")
    output.add_argument("--render-surface", type=Path, metavar="FILE",
                        help="with --blender: write this surface mesh (.obj, .stl, .ply, ...) carried along by the "
                             "tets instead of their boundary; its vertex order is kept for Blender's Mesh Cache")
    output.add_argument("--checkpoint-every", type=int, metavar="N",
                        help=f"save {CHECKPOINT_NAME} in DIR every N frames and at the end")
    output.add_argument("--resume", type=Path, metavar="CHECKPOINT",
                        help="continue a run from its checkpoint up to --duration; the checkpoint records the "
                             "model, integrator and --dt of its run, and a resume with another INPUT, material, "
                             "pins, integrator or --dt is refused, naming what differs (a resumed run is "
                             "bit-identical to one that never stopped)")
    output.add_argument("--overwrite", action="store_true",
                        help="replace the outputs of an earlier run in DIR: only the files its manifest "
                             f"({MANIFEST}) lists are removed, never anything volspring did not write (without "
                             "it, a DIR holding another run's outputs, or files of unknown origin, is refused)")
    output.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                        help="progress bar on stderr (default: when stderr is a terminal)")
    output.add_argument("-q", "--quiet", action="store_true", help="no progress bar and no summary")
    return parser


def main(argv=None) -> int:
    """Run ``volspring-sim`` with ``argv`` (default ``sys.argv[1:]``); returns the exit status."""
    from volspring.errors import SolverNotConverged

    try:
        args = build_parser().parse_args(_joined_vectors(sys.argv[1:] if argv is None else argv))
    except _UsageError as error:
        return _fail(error, EXIT_USAGE)
    except SystemExit as done:  # --help
        return done.code if isinstance(done.code, int) else 0
    from volspring._signals import Interrupted, exit_status, handle_termination, interruption_name

    where = _RunProgress()
    try:
        with warnings.catch_warnings(), handle_termination():
            warnings.showwarning = _show_warning  # one line each, on stderr, from the first check on
            return _run(args, where, sys.argv[1:] if argv is None else [str(token) for token in argv])
    except FloatingPointError as error:  # SimulationDiverged, or a spring collapsed to zero length
        return _fail(error, EXIT_DIVERGED)
    except (_InputError, ValueError, OSError, SolverNotConverged, Warning) as error:
        return _fail(error, EXIT_INPUT)
    except (KeyboardInterrupt, Interrupted) as stop:  # Ctrl-C, SIGTERM, SIGHUP: one line, no traceback
        argv = sys.argv[1:] if argv is None else [str(token) for token in argv]
        print(f"{PROG}: interrupted by {interruption_name(stop)}{where.describe(argv)}", file=sys.stderr)
        return exit_status(stop)


class _RunProgress:
    """Where a run has got to, for the line printed when it is interrupted."""

    def __init__(self):
        self.state = None
        self.checkpoint = None  # (path, t) of the last checkpoint written

    def describe(self, argv) -> str:
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


def _joined_vectors(argv) -> list:
    """``--pin -1,0,0,...`` as ``--pin=-1,0,0,...``: argparse takes a value starting with ``-`` for an option."""
    argv, joined = [str(token) for token in argv], []
    index = 0
    while index < len(argv):
        token = argv[index]
        if token in VECTOR_OPTIONS and index + 1 < len(argv):
            joined.append(f"{token}={argv[index + 1]}")
            index += 2
        else:
            joined.append(token)
            index += 1
    return joined


def _fail(message, status) -> int:
    text = " ".join(str(message).split())  # one line, whatever the message holds
    print(f"{PROG}: error: {text}", file=sys.stderr)
    return status


# ---------------------------------------------------------------------- steps of a run
def _run(args, where: _RunProgress, argv) -> int:
    """Check, open the output folder, then build, run and report; the folder's manifest ends with the
    run's status (finished, failed, interrupted)."""
    _check_numbers(args)
    if args.out is None:
        return _run_in(args, where, None)
    from volspring.output import RunFolder, check_output_folder

    check_output_folder(args.out, label="--out")  # a file, below a file, not writable: before any work

    # Claimed before any work: a refused folder costs nothing, and every file is listed before it exists.
    run = RunFolder.open(args.out, command=[PROG, *argv], overwrite=args.overwrite, resume=args.resume is not None,
                         flags={"overwrite": "--overwrite", "resume": "--resume CHECKPOINT"})
    with run:
        return _run_in(args, where, run)


def _run_in(args, where: _RunProgress, run) -> int:
    from volspring.checkpoint import load_checkpoint, save_checkpoint
    from volspring.integrators import make_integrator
    from volspring.simulate import simulate

    started = time.perf_counter()
    mesh, origin = _load_mesh(args)
    model = _build_model(args, mesh)
    scene = _build_scene(args, model)
    integrator = make_integrator(args.integrator, **({"newton_iterations": args.newton_iterations}
                                                     if args.newton_iterations else {}))

    state, first_frame = scene.initial_state(), 0
    total_steps = max(int(math.ceil(args.duration / args.dt - 1e-9)), 0)
    if args.resume is not None:
        state = load_checkpoint(args.resume, scene=scene, integrator=integrator, dt=args.dt)
        where.checkpoint = (args.resume, state.t)
        if state.step >= total_steps:
            raise _InputError(f"the checkpoint {args.resume} is at step {state.step} (t = {state.t:.6g} s), "
                              f"already at --duration {args.duration:g} s ({total_steps} steps)")
        first_frame = _frames_before(args, state.t)
    # Steps are counted from the run's start, so a resumed run ends on the same step as an
    # uninterrupted one (no round-off from t).
    remaining = total_steps - state.step

    writers = _writers(args, model, first_frame, None if run is None else run.record)
    checks = {} if args.runaway_factor is None else {"runaway_factor": args.runaway_factor}
    progress = _Progress(enabled=_progress_enabled(args), start=state.t, end=state.t + remaining * args.dt)
    last = {"frames": 0, "state": state}

    def on_frame(frame_index, current):
        if run is not None:  # the frame's files listed in one manifest write, before any is written
            run.record(*(path for writer in writers for path in writer.frame_paths()))
        for writer in writers:
            writer(frame_index, current)
        if args.checkpoint_every and frame_index and frame_index % args.checkpoint_every == 0:
            run.record(args.out / CHECKPOINT_NAME)
            save_checkpoint(args.out / CHECKPOINT_NAME, current, scene=scene, integrator=integrator, dt=args.dt)
            where.checkpoint = (args.out / CHECKPOINT_NAME, current.t)
        last["frames"] += 1
        last["state"] = where.state = current
        progress.update(current.t, first_frame + frame_index)

    try:
        result = simulate(scene, integrator, duration=remaining * args.dt, dt=args.dt, state=state,
                          frame_dt=args.frame_dt, callback=on_frame, guard=args.guard, **checks)
    except FloatingPointError as error:  # SimulationDiverged, or a spring collapsed to zero length
        progress.close()
        kept = ""
        if args.out is not None:
            kept = (f"; {args.out} holds {first_frame + last['frames']} complete frame(s)"
                    + (f", the last at t = {last['state'].t:.6g} s" if last["frames"] else ""))
        raise _Diverged(f"{error}{kept}") from error
    finally:
        progress.close()
    if args.checkpoint_every:
        run.record(args.out / CHECKPOINT_NAME)
        save_checkpoint(args.out / CHECKPOINT_NAME, result.state, scene=scene, integrator=integrator, dt=args.dt)
    if not args.quiet:
        _summary(args, origin, mesh, model, scene, integrator, result, first_frame, time.perf_counter() - started)
    return 0


def _check_numbers(args) -> None:
    for name in ("dt", "frame_dt"):
        value = getattr(args, name)
        if not (math.isfinite(value) and value > 0):
            raise _InputError(f"--{name.replace('_', '-')} = {value:g} s is not a finite number > 0")
    if not (math.isfinite(args.duration) and args.duration >= 0):
        raise _InputError(f"--duration = {args.duration:g} s is not a finite number >= 0")
    if args.size is not None and not (math.isfinite(args.size) and args.size > 0):
        raise _InputError(f"--size = {args.size:g} m is not a finite number > 0")
    if args.checkpoint_every is not None:
        if args.checkpoint_every < 1:
            raise _InputError(f"--checkpoint-every = {args.checkpoint_every} is not >= 1 (frames)")
        if args.out is None:
            raise _InputError("--checkpoint-every needs --out DIR to write the checkpoint in")
    if args.blender and args.out is None:
        raise _InputError("--blender needs --out DIR to write the surface cache in")
    if args.render_surface is not None and not args.blender:
        raise _InputError("--render-surface needs --blender (it is the surface the Blender output carries)")
    if args.rule == "uniform" and args.stiffness is None:
        raise _InputError("--rule uniform needs --stiffness (the raw spring constant [N/m])")
    if args.damping_ratio < 0 or not math.isfinite(args.damping_ratio):
        raise _InputError(f"--damping-ratio = {args.damping_ratio:g} is not a finite number >= 0")
    if args.newton_iterations < 0:
        raise _InputError(f"--newton-iterations = {args.newton_iterations} is not >= 0")
    if args.newton_iterations and args.integrator != "implicit_euler":
        raise _InputError(f"--newton-iterations applies to --integrator implicit_euler, not {args.integrator}")
    if args.runaway_factor is not None and not args.runaway_factor > 0:
        raise _InputError(f"--runaway-factor = {args.runaway_factor:g} is not > 0 ('inf' turns the check off)")


def _load_mesh(args):
    """The tet mesh and a description of where it came from."""
    path = Path(args.input)
    if path.is_file():
        if args.size is not None:
            raise _InputError(f"--size applies to built-in shapes only; {path} is already a tet mesh")
        return _read_mesh(path, args.units, args.scale), str(path)
    from meshing.shapes import SHAPE_NAMES, Shape, looks_like_shape, parse_shape  # an application may use meshing
    from volspring.units import UNITS, length_factor

    if not looks_like_shape(args.input):
        raise _InputError(f"INPUT {args.input!r} is neither a mesh file nor a built-in shape NAME:D1,D2,... "
                          f"(shapes: {', '.join(SHAPE_NAMES)})")
    from meshing.tetrahedralize import tetrahedralize

    shape = parse_shape(args.input)
    factor = length_factor(args.units, args.scale)
    if factor != 1.0:
        shape = Shape(shape.name, tuple(dimension * factor for dimension in shape.dimensions))
    low, high = shape.bounds
    size = (args.size * UNITS[args.units] if args.size is not None
            else min(shape.extent / 10.0, float((high - low).min()) / 2.0))
    try:
        mesh = tetrahedralize(shape, size=size, method=args.mesher, seed=args.seed)
    except ValueError:
        raise
    except Exception as error:  # gmsh raises bare Exceptions
        raise _InputError(f"meshing {shape.spec()} at --size {size:g} with {args.mesher} failed: {error}") from error
    return mesh, f"{shape.spec()} meshed by {args.mesher} at size {size:g} m"


def _read_mesh(path, units, scale):
    from volspring.mesh import TetMesh

    try:
        return TetMesh.read(path, units=units, scale=scale)
    except (ValueError, FileNotFoundError) as error:
        raise _InputError(str(error)) from error


def _build_model(args, mesh):
    from volspring.material import Material
    from volspring.model import NU_IGNORING_RULES, SpringModel

    material = Material(E=args.E, nu=DEFAULT_NU if args.nu is None else args.nu, density=args.density)
    if args.nu is not None and args.rule in NU_IGNORING_RULES:
        warnings.warn(f"--nu {args.nu:g} is ignored by --rule {args.rule}: pure springs have one effective Poisson "
                      "ratio whatever nu is asked (the Cauchy limit; volspring-validate cauchy measures it)",
                      UserWarning, stacklevel=2)
    return SpringModel.from_mesh(mesh, material, rule=args.rule, stiffness=args.stiffness,
                                 damping_ratio=args.damping_ratio)


def _build_scene(args, model):
    from volspring.scene import Drag, Gravity, Pins, Scene

    forces = []
    gravity = _gravity(args.gravity)
    if gravity is not None:
        forces.append(Gravity(model.masses, tuple(gravity)))
    if args.drag:
        forces.append(Drag(model.masses, args.drag))
    from volspring.units import UNITS

    pins = _pinned_nodes(args.pin, model.rest_positions, UNITS[args.units])
    return Scene(model, forces=forces, pins=None if pins is None else Pins(pins))


def _gravity(text):
    if text.strip().lower() in ("off", "none", "0"):
        return None
    g = _numbers(text, 3, "--gravity", "gx,gy,gz")
    return None if not g.any() else g


def _numbers(text, count, option, form) -> np.ndarray:
    try:
        values = np.array([float(part) for part in text.split(",")])
    except ValueError:
        raise _InputError(f"{option} {text!r} is not {count} numbers {form}") from None
    if len(values) != count or not np.isfinite(values).all():
        raise _InputError(f"{option} {text!r} is not {count} finite numbers {form}")
    return values


def _pinned_nodes(boxes, points, unit=1.0):
    """Nodes inside any of the boxes (faces included, up to round-off), or None without boxes.

    ``points`` are in metres, the boxes' numbers in a unit of ``unit`` metres."""
    if not boxes:
        return None
    low_all, high_all = points.min(axis=0), points.max(axis=0)
    slack = PIN_TOLERANCE * float(np.linalg.norm(high_all - low_all))
    selected = np.zeros(len(points), dtype=bool)
    for text in boxes:
        box = _numbers(text, 6, "--pin", "xmin,ymin,zmin,xmax,ymax,zmax") * unit
        low, high = box[:3], box[3:]
        if (low > high).any():
            axis = "xyz"[int(np.flatnonzero(low > high)[0])]
            raise _InputError(f"--pin {text}: {axis}min > {axis}max")
        inside = ((points >= low - slack) & (points <= high + slack)).all(axis=1)
        if not inside.any():
            spans = " x ".join(f"[{a:.6g}, {b:.6g}]" for a, b in zip(low_all, high_all))
            raise _InputError(f"--pin {text} selects no node; the mesh spans {spans} m")
        selected |= inside
    return np.flatnonzero(selected)


def _frames_before(args, t) -> int:
    """How many frames of an earlier run come before time t (the resumed run rewrites from t on)."""
    from volspring.output import read_pvd

    if args.out is None:
        return 0
    pvd = args.out / f"{SERIES_NAME}.pvd"
    if not pvd.is_file():
        return 0
    return sum(1 for time, _ in read_pvd(pvd) if time < t - 1e-6 * args.dt)


def _writers(args, model, first_frame, record):
    from volspring.output import BlenderWriter, ParaViewWriter

    if args.out is None:
        return []
    writers = [ParaViewWriter(args.out, model, name=SERIES_NAME, first_frame=first_frame, record=record)]
    if args.blender:
        surface = (model if args.render_surface is None
                   else _anchored_surface(args.render_surface, model, args.units, args.scale))
        pc2 = args.out / f"{SURFACE_NAME}.pc2"
        writers.append(BlenderWriter(args.out, surface, name=SURFACE_NAME,
                                     first_frame=first_frame if pc2.is_file() else 0, record=record))
    return writers


def _anchored_surface(path, model, units, scale):
    """A render surface file bound to the model's tet mesh, vertices in the file's order."""
    import trimesh

    from meshing import anchor
    from volspring.units import length_factor

    if not path.is_file():
        raise _InputError(f"no render surface file at {path}")
    try:
        # process=False: no merging or reordering, so the PC2 matches the file Blender imports.
        surface = trimesh.load(path, force="mesh", process=False)
    except Exception as error:  # trimesh raises a variety of errors for unreadable files
        raise _InputError(f"cannot read {path} as a surface mesh: {error}") from error
    if len(getattr(surface, "vertices", ())) == 0:
        raise _InputError(f"{path} holds no surface vertices")
    surface.vertices = surface.vertices * length_factor(units, scale)  # drawn with INPUT, in its units
    return anchor(model.topology.mesh, surface)


# ---------------------------------------------------------------------- terminal
def _show_warning(message, category, filename, lineno, file=None, line=None):
    print(f"{PROG}: warning: {' '.join(str(message).split())}", file=sys.stderr)


def _progress_enabled(args) -> bool:
    if args.quiet:
        return False
    return sys.stderr.isatty() if args.progress is None else args.progress


class _Progress:
    """A one-line progress bar on stderr, redrawn with a carriage return at most 10 times a second."""

    WIDTH = 30

    def __init__(self, *, enabled, start, end):
        self.enabled, self.start, self.end = enabled, start, end
        self.drawn, self.width = False, 0
        self.last_draw = -math.inf
        self.clock = time.perf_counter()

    def update(self, t, frame) -> None:
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
        if self.drawn:
            sys.stderr.write("\n")
            sys.stderr.flush()
            self.drawn = False


def _summary(args, origin, mesh, model, scene, integrator, result, first_frame, seconds) -> None:
    state = result.state
    displacement = np.linalg.norm(state.x - model.rest_positions, axis=1)
    pinned = 0 if scene.pins is None else len(scene.pins.nodes)
    lines = [
        f"body: {origin}: {mesh.node_count} nodes, {mesh.tet_count} tets, {model.spring_count} springs, "
        f"mass {model.total_mass:.6g} kg, {pinned} pinned node(s)",
        f"run: {integrator.name}, dt = {args.dt:g} s, {result.steps_taken} steps to t = {state.t:.6g} s "
        f"in {seconds:.2f} s wall time",
        f"end: max displacement {displacement.max():.6g} m (node {int(displacement.argmax())}), "
        f"kinetic energy {result.kinetic_energy[-1]:.6g} J, total energy {result.total_energy[-1]:.6g} J",
        f"tets: {result.inverted_tets[-1]} of {mesh.tet_count} inverted at the end, at most "
        f"{result.inverted_tets.max()} at a frame; worst volume ratio {np.nanmin(result.worst_volume_ratio):.3g}",
    ]
    if args.out is not None:
        lines.append(f"output: {first_frame + result.frame_count} frame(s) in {args.out} "
                     f"({SERIES_NAME}.pvd, {SERIES_NAME}_springs.pvd"
                     + (f", {SURFACE_NAME}_NNNN.obj, {SURFACE_NAME}.pc2" if args.blender else "")
                     + (f", {CHECKPOINT_NAME}" if args.checkpoint_every else "") + ")")
    print("\n".join(lines))


if __name__ == "__main__":
    sys.exit(main())
