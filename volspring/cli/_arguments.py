"""The command line of ``volspring-sim``: its options, and the checks of their values before any work.

The parser reports a bad command line by raising :class:`UsageError` instead of printing its usage
and exiting, and values that parse but make no sense raise :class:`InputError`, both exit status 2,
each reported by :func:`volspring.cli.main` in one line. The options every command has (``--version``,
``-q``, ``-v``, ``--progress``), the exit statuses and the help layout are those of all of volspring's
commands (:mod:`meshing._command_line`).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

from meshing._command_line import (EXIT_DIVERGED, EXIT_FAILED, EXIT_USAGE, Parser, UsageError,
                                   add_common_options)

__all__ = ["BODY_FLAGS", "EXIT_DIVERGED", "EXIT_FAILED", "EXIT_USAGE", "RUN_FLAGS", "InputError", "UsageError",
           "build_parser", "check_arguments", "given_options",
           "joined_vectors", "region_materials"]

PROG = "volspring-sim"
CHECKPOINT_NAME = "checkpoint.npz"
SERIES_NAME = "frame"
SURFACE_NAME = "surface"
EXIT_INPUT = EXIT_USAGE  # bad input, found before the run: the same status as a bad command line
DEFAULT_NU = 0.45
VECTOR_OPTIONS = ("--pin", "--gravity")  # values that may start with a minus sign (-0.1,-1,-1,... or -9.81)
PIN_FORMS = ("XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX (a box; also box:...), xmin|xmax|ymin|ymax|zmin|zmax (a face of the "
             "body's bounding box), x<V, x>V (a half-space; <=, >= too) or x=V (a plane), any axis")
SCENE_SUFFIX = ".toml"
# With a scene file, a flag given overrides the scene value at its key path (volspring.scene_file): the flags of
# the body (of its only body; refused for several) and those of the run. --gravity, --drag and --pin edit the
# scene's fields and supports (volspring.cli._build.scene_with_flags); --resume, --overwrite, --progress and
# --quiet are not part of a scene.
BODY_FLAGS = {"size": "size", "mesher": "mesher", "seed": "seed", "units": "units", "scale": "scale",
              "model": "model", "alpha": "alpha", "E": "material.E", "nu": "material.nu",
              "density": "material.density", "rule": "rule", "stiffness": "stiffness",
              "damping_ratio": "damping_ratio"}
RUN_FLAGS = {"integrator": "integrator.name", "dt": "integrator.dt", "guard": "integrator.guard",
             "newton_iterations": "integrator.newton_iterations", "runaway_factor": "integrator.runaway_factor",
             "duration": "duration", "frame_dt": "output.frame_dt", "out": "output.folder",
             "blender": "output.blender", "render_surface": "output.render_surface",
             "checkpoint_every": "output.checkpoint_every"}


class InputError(Exception):
    """Bad input found after parsing, reported in one line (exit status 2)."""


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``volspring-sim``.

    Examples
    --------
    >>> args = build_parser().parse_args(["box:1,0.1,0.1", "--pin=xmin", "--dt", "0.01"])
    >>> args.pin, args.dt, args.integrator
    (['xmin'], 0.01, 'implicit_euler')
    """
    from volspring.integrators import INTEGRATORS
    from volspring.ladder import DEFAULT_ALPHA, MODELS
    from volspring.model import STIFFNESS_RULES
    from volspring.simulate import RUNAWAY_CHECKS, RUNAWAY_FACTOR
    from volspring.output.run_folder import MANIFEST_NAME as MANIFEST
    from meshing.units import add_unit_arguments

    parser = Parser(prog=PROG, description="Simulate a volumetric soft body on a tetrahedral mesh, as a mass-spring "
                                           "model or on an upper rung of the model ladder (--model).")
    parser.add_argument("input", metavar="INPUT",
                        help="a volume mesh file (.msh, .vtu, .mesh, ...), a spring topology file from "
                             "volspring-mesh (.vstopo.npz, any .npz: the tet mesh with its shells, which the model "
                             "then has), a built-in shape NAME:D1,D2,... such as box:1,0.1,0.1 or sphere:0.5 [m], "
                             f"or a scene file (*{SCENE_SUFFIX}: bodies, supports, fields, contact, integrator, "
                             "outputs; the flags given override its values)")
    body = parser.add_argument_group("body")
    body.add_argument("--size", type=float, help="tet edge length for a built-in shape, in --units "
                                                 "(default: a tenth of its extent, at most half its smallest side)")
    body.add_argument("--mesher", "--method", dest="mesher", choices=("gmsh", "delaunay"), default="gmsh",
                      help="mesher for a built-in shape (--method: volspring mesh's earlier spelling)")
    body.add_argument("--seed", type=int, help="random seed of the mesher")
    add_unit_arguments(body, applies_to="INPUT (a mesh file's coordinates or a shape's dimensions), --size, the --pin "
                                        "numbers and --render-surface", scale_applies_to="INPUT and --render-surface")
    body.add_argument("--model", choices=MODELS, default="springs",
                      help="the rung of the model ladder: springs (the fastest; ignores nu), springs+volume (springs "
                           "plus a nodal volume term that honours nu from about 0.25 to 0.499) or smoothed (the "
                           "smoothed-strain element: FEM-accurate E and nu, no springs)")
    body.add_argument("--alpha", type=float, default=None,
                      help=f"--model smoothed only: the weight in [0, 1] of its nodal (smoothed) shear (default "
                           f"{DEFAULT_ALPHA:g})")
    body.add_argument("--E", type=float, default=1e6, help="Young's modulus [Pa] (soft rubber)")
    body.add_argument("--nu", type=float, default=None,
                      help=f"Poisson's ratio [-] (default {DEFAULT_NU}); --model springs ignores it: pure springs have "
                           "one effective Poisson ratio whatever nu is asked (the Cauchy limit), and say so when "
                           "--nu is given; --model smoothed and springs+volume honour it")
    body.add_argument("--density", type=float, default=1100.0, help="density [kg/m^3]")
    body.add_argument("--region-material", action="append", default=[], metavar="TAG:E[:NU[:DENSITY]]",
                      help="the material of the tets tagged TAG in the mesh file (gmsh physical groups, Medit "
                           "references, a 'region' cell array), repeatable; NU and DENSITY default to --nu and "
                           "--density; untagged regions take --E, --nu and --density")
    body.add_argument("--rule", choices=STIFFNESS_RULES, default=None,
                      help="spring stiffness rule (default van_gelder; springs and springs+volume only)")
    body.add_argument("--stiffness", type=float, help="the raw spring constant of --rule uniform [N/m]")
    body.add_argument("--damping-ratio", type=float, default=0.05,
                      help="damping ratio [-]: of every spring; on the continuum terms of springs+volume and smoothed, "
                           "Rayleigh stiffness damping with this ratio at the model's highest frequency")
    scene = parser.add_argument_group("scene")
    scene.add_argument("--gravity", default="0,0,-9.81", help="gravity gx,gy,gz [m/s^2], or 'off'")
    scene.add_argument("--drag", type=float, default=0.0, help="global viscous drag rate [1/s]")
    scene.add_argument("--pin", action="append", default=[], metavar="REGION",
                       help=f"pin the nodes in this region, numbers in --units (repeatable): {PIN_FORMS}")
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
    output.add_argument("-o", "--out", type=Path, metavar="DIR",
                        help=f"write the frames there ({SERIES_NAME}.pvd: tets, {SERIES_NAME}_springs.pvd: springs, "
                             "for a model with springs)")
    output.add_argument("--blender", action="store_true",
                        help=f"also write the boundary surface as {SURFACE_NAME}_NNNN.obj and {SURFACE_NAME}.pc2")
    output.add_argument("--render-surface", type=Path, metavar="FILE",
                        help="with --blender: write this surface mesh (.obj, .stl, .ply, ...) carried along by the "
                             "tets instead of their boundary; its vertex order is kept for Blender's Mesh Cache")
    output.add_argument("--checkpoint-every", type=int, metavar="N",
                        help=f"save {CHECKPOINT_NAME} in DIR every N frames and at the end")
    output.add_argument("--resume", type=Path, metavar="CHECKPOINT",
                        help="continue a run from its checkpoint up to --duration; the checkpoint records the "
                             "model, integrator and --dt of its run, and a resume with another INPUT, --model, "
                             "--alpha, material, pins, integrator or --dt is refused, naming what differs (a resumed run is "
                             "bit-identical to one that never stopped)")
    output.add_argument("--overwrite", action="store_true",
                        help="replace the outputs of an earlier run in DIR: only the files its manifest "
                             f"({MANIFEST}) lists are removed, never anything volspring did not write (without "
                             "it, a DIR holding another run's outputs, or files of unknown origin, is refused)")
    add_common_options(parser.add_argument_group("terminal"), prog=PROG,
                       progress="progress of the steps on stderr, with the simulated time and frame")
    scene_file = parser.add_argument_group("scene file")
    scene_file.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", dest="set",
                            help=f"with a scene file INPUT (*{SCENE_SUFFIX}): set the value at a key path, VALUE read "
                                 "as TOML (bodies[1].material.E=2e6, fields[0].g=[0,0,-1]; indices from 0), after "
                                 "the flags; repeatable")
    return parser


def given_options(argv) -> set:
    """The destinations (``"E"``, ``"dt"``, ``"pin"``...) of the options ``argv`` gives, defaults left out.

    >>> sorted(given_options(["beam.toml", "--E", "2e6", "--dt=0.01", "--pin", "-1,0,0,1,1,1"]))
    ['E', 'dt', 'pin']
    """
    parser = build_parser()
    for action in parser._actions:  # argparse's list of options: parse again with every default suppressed
        action.default = argparse.SUPPRESS
    return set(vars(parser.parse_args(joined_vectors(argv)))) - {"input"}


def region_materials(texts) -> dict:
    """``--region-material TAG:E[:NU[:DENSITY]]`` values as ``{tag: (E, nu or None, density or None)}``.

    Raises :class:`InputError` for a value that is not that form, a negative tag or a tag given twice.

    >>> region_materials(["2:5e6", "3:1e5:0.49:900"])
    {2: (5000000.0, None, None), 3: (100000.0, 0.49, 900.0)}
    """
    found = {}
    for text in texts:
        parts = text.split(":")
        try:
            if not 2 <= len(parts) <= 4:
                raise ValueError
            tag, numbers = int(parts[0]), [float(part) for part in parts[1:]]  # E, then nu and density if given
        except ValueError:
            raise InputError(f"--region-material {text!r} is not TAG:E[:NU[:DENSITY]] (an integer tag, then numbers "
                             "in Pa, -, kg/m^3)") from None
        if tag < 0:
            raise InputError(f"--region-material {text!r}: the tag {tag} is negative; expected a tag >= 0")
        if tag in found:
            raise InputError(f"--region-material gives tag {tag} twice")
        found[tag] = tuple(numbers) + (None,) * (3 - len(numbers))
    return found


def joined_vectors(argv) -> list:
    """``--pin -1,0,0,...`` as ``--pin=-1,0,0,...``: argparse takes a value starting with ``-`` for an option.

    Examples
    --------
    >>> joined_vectors(["beam.vtu", "--pin", "-1,-1,-1,0,1,1", "--gravity", "0,0,-1"])
    ['beam.vtu', '--pin=-1,-1,-1,0,1,1', '--gravity=0,0,-1']
    """
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


def check_arguments(args) -> None:
    """Raise :class:`InputError` for option values that parse but make no sense, or options missing
    the option they need, before any work."""
    for name in ("dt", "frame_dt"):
        value = getattr(args, name)
        if not (math.isfinite(value) and value > 0):
            raise InputError(f"--{name.replace('_', '-')} = {value:g} s is not a finite number > 0")
    if not (math.isfinite(args.duration) and args.duration >= 0):
        raise InputError(f"--duration = {args.duration:g} s is not a finite number >= 0")
    if args.size is not None and not (math.isfinite(args.size) and args.size > 0):
        raise InputError(f"--size = {args.size:g} m is not a finite number > 0")
    if args.checkpoint_every is not None:
        if args.checkpoint_every < 1:
            raise InputError(f"--checkpoint-every = {args.checkpoint_every} is not >= 1 (frames)")
        if args.out is None:
            raise InputError("--checkpoint-every needs --out DIR to write the checkpoint in")
    if args.blender and args.out is None:
        raise InputError("--blender needs --out DIR to write the surface cache in")
    if args.render_surface is not None and not args.blender:
        raise InputError("--render-surface needs --blender (it is the surface the Blender output carries)")
    if args.rule == "uniform" and args.stiffness is None:
        raise InputError("--rule uniform needs --stiffness (the raw spring constant [N/m])")
    if args.alpha is not None:
        if args.model != "smoothed":
            raise InputError(f"--alpha applies to --model smoothed (the weight of its nodal shear), not --model "
                             f"{args.model}")
        if not (math.isfinite(args.alpha) and 0.0 <= args.alpha <= 1.0):
            raise InputError(f"--alpha = {args.alpha:g} is not in [0, 1]")
    if args.model == "smoothed":
        given = [flag for flag, value in (("--rule", args.rule), ("--stiffness", args.stiffness)) if value is not None]
        if given:
            raise InputError(f"--model smoothed has no springs: {' and '.join(given)} "
                             f"{'do' if len(given) > 1 else 'does'} not apply (use --model springs or springs+volume)")
    if args.model == "springs+volume" and args.rule == "uniform":
        raise InputError("--model springs+volume derives its springs from the material: use --rule van_gelder or "
                         "lloyd, not uniform")
    region_materials(args.region_material)  # a malformed value is refused before any work
    if args.damping_ratio < 0 or not math.isfinite(args.damping_ratio):
        raise InputError(f"--damping-ratio = {args.damping_ratio:g} is not a finite number >= 0")
    if args.newton_iterations < 0:
        raise InputError(f"--newton-iterations = {args.newton_iterations} is not >= 0")
    if args.newton_iterations and args.integrator != "implicit_euler":
        raise InputError(f"--newton-iterations applies to --integrator implicit_euler, not {args.integrator}")
    if args.runaway_factor is not None and not args.runaway_factor > 0:
        raise InputError(f"--runaway-factor = {args.runaway_factor:g} is not > 0 ('inf' turns the check off)")
