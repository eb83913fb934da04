"""``volspring-validate``: the ladder of models (springs, springs+volume, smoothed) against linear-elastic
FEM, as a report.

Examples
--------
Everything, on coarse meshes, in about half a minute (the held-out shapes only in the full run)::

    volspring validate --quick --out validation-report

Your own mesh, clamped at its lowest z, under gravity, on every rung of the ladder::

    volspring validate --mesh part.vtu --clamp zmin --E 2e6 --nu 0.4 --density 1100 --out part-report

Only some rungs (``--model``, comma-separated; default all of :data:`volspring.ladder.MODELS`) and some
spring stiffness rules (``--rule``, comma-separated; default all of :data:`validation.compare.RULES`)::

    volspring validate --quick --model springs,smoothed --rule van_gelder --out validation-report

A sweep of your own scene (``volspring sweep``, its scene with a ``[compare]`` table) as a trade curve, error
against FEM over cost, after the ladder (``--sweep`` alone runs no case: the ladder's constants and the
sweep; :mod:`validation.report.trade`)::

    volspring validate --sweep beam_trade --out trade-report

``volspring-validate`` is the same command; its options, exit statuses and progress follow the convention of
all of volspring's commands (:mod:`meshing._command_line`).

Writes ``OUT/report.html``, ``OUT/results.json`` and ``OUT/vtu/*.vtu``, and lists them in
``OUT/volspring-run.json`` (a :class:`volspring.output.RunFolder`). Running the same command again
replaces that report (its listed files are removed first); a different command is refused on a
folder holding another run's report, and on a non-empty folder that holds no ``volspring-run.json``,
unless ``--overwrite`` is given (which removes only the files the old manifest lists, never anything
else).

Exit status: 0 done; 1 a failure while computing or writing (the output folder that cannot be set up
included); 2 a bad command line or bad input, found before any work (options, the mesh, the output and
cache folders), with one line ``volspring-validate: error: ...``; 3 a simulation of a study diverged;
130 on Ctrl-C and 143 on SIGTERM (129 on SIGHUP), with one line ``volspring-validate: interrupted by
SIGTERM; ...``, no temporary file left and the run marked interrupted in its manifest.
"""

from __future__ import annotations

import contextlib
import logging
import sys
import time
import warnings

import numpy as np

from meshing._command_line import (EXIT_DIVERGED, EXIT_DONE, EXIT_FAILED, EXIT_USAGE, Parser, UsageError,
                                   add_common_options, advance_to, error_line, progress_bar, progress_mode,
                                   stderr_line)
from meshing._signals import Interrupted, exit_status, handle_termination, interruption_name
from collections.abc import Sequence

__all__ = ["main"]

PROG = "volspring-validate"


def _parser():
    from validation.report import BUILT_IN, HELDOUT, STUDIES
    from meshing.units import add_unit_arguments
    from validation.compare import RULES
    from validation.springs import VALIDATED_MODELS

    parser = Parser(
        prog=PROG, description="Compare the ladder of models (springs, springs+volume, smoothed) with linear-elastic\n"
                               "FEM (scikit-fem, P2) on the same meshes and write report.html, results.json and VTU "
                               "files.")
    parser.add_argument("cases", nargs="*", metavar="CASE",
                        help=f"cases and studies to run: {', '.join(BUILT_IN + HELDOUT + STUDIES)} (default: all, "
                             "the held-out shapes not with --quick; only your mesh with --mesh)")
    parser.add_argument("--model", default=",".join(VALIDATED_MODELS), metavar="NAME[,NAME...]",
                        help=f"models to validate: the ladder's rungs and the lattice, {', '.join(VALIDATED_MODELS)} "
                             "(default: all)")
    parser.add_argument("--rule", default=",".join(RULES), metavar="NAME[,NAME...]",
                        help=f"spring stiffness rules to compare: {', '.join(RULES)} (default: all)")
    parser.add_argument("--quick", action="store_true", help="coarse meshes and short runs (about a minute)")
    parser.add_argument("-o", "--out", required=True, metavar="DIR",
                        help="output folder; the same command run again replaces its report there")
    parser.add_argument("--overwrite", action="store_true",
                        help="replace the outputs of another run in --out (only the files its volspring-run.json "
                             "lists are removed), or write into a non-empty folder without one (nothing removed)")
    parser.add_argument("--mesh", metavar="FILE", help="your tet mesh (any format meshio reads)")
    add_unit_arguments(parser, applies_to="the coordinates of --mesh")
    parser.add_argument("--clamp", action="append", metavar="REGION",
                        help="region of --mesh held in place: xmin|xmax|ymin|ymax|zmin|zmax, x<VALUE, z>VALUE, "
                             "box:x0,y0,z0,x1,y1,z1, values in metres after --units and --scale (repeat to hold "
                             "several)")
    parser.add_argument("--E", type=float, default=1e6, help="Young's modulus of --mesh [Pa] (default 1e6)")
    parser.add_argument("--nu", type=float, default=0.3, help="Poisson ratio of --mesh, < 0.5 (default 0.3)")
    parser.add_argument("--density", type=float, default=1000.0, help="density of --mesh [kg/m^3] (default 1000)")
    parser.add_argument("--gravity", default="0,0,-9.81", metavar="GX,GY,GZ",
                        help="gravity on --mesh [m/s^2] (default 0,0,-9.81)")
    parser.add_argument("--workers", type=int, metavar="N",
                        help="run the cases and studies at the same time on a local cluster of N worker processes "
                             "(as volspring sweep; default: one after the other in this process, which keeps the "
                             "speed study's wall times clean)")
    parser.add_argument("--scheduler", metavar="ADDRESS",
                        help="run the cases and studies on the Dask cluster of this scheduler (tcp://HOST:8786)")
    parser.add_argument("--sweep", action="append", default=[], metavar="DIR",
                        help="a volspring sweep's --out folder: its runs' error against FEM over their cost, in a "
                             "section after the ladder (repeatable; alone, no case is run)")
    parser.add_argument("--cache", metavar="DIR", help="FEM cache folder (default $VOLSPRING_CACHE or "
                                                       "~/.cache/volspring/fem)")
    add_common_options(parser, progress="progress of the cases and studies on stderr")
    return parser


class _BadInput(ValueError):
    pass


def _own_case(args):
    from meshing.mesh import TetMesh
    from validation.cases import own_mesh_case, parse_region
    from volspring.material import Material

    if not args.clamp:
        raise _BadInput("--mesh needs --clamp REGION: without a clamp every rigid motion is free and the problem "
                        "is singular")
    try:
        gravity = np.array([float(v) for v in args.gravity.split(",")])
    except ValueError:
        raise _BadInput(f"--gravity {args.gravity!r} is not three numbers GX,GY,GZ") from None
    if gravity.shape != (3,) or not np.isfinite(gravity).all():
        raise _BadInput(f"--gravity {args.gravity!r} is not three finite numbers GX,GY,GZ")
    try:
        with warnings.catch_warnings():
            # A body read too large is also logged by meshing.units: shown once, by the log handler.
            warnings.simplefilter("ignore", UserWarning)
            mesh = TetMesh.read(args.mesh, units=args.units, scale=args.scale)
    except (OSError, ValueError) as error:
        raise _BadInput(str(error)) from None
    regions = [parse_region(text, mesh) for text in args.clamp]

    def clamp(points):
        return np.any([region(points) for region in regions], axis=0)

    clamp.__name__ = " or ".join(args.clamp)
    material = Material(E=args.E, nu=args.nu, density=args.density)
    return own_mesh_case(mesh, clamp, material=material, gravity=None if not gravity.any() else gravity,
                         source=str(args.mesh))


def _check(args):
    from validation.ladder import parse_models
    from validation.report import BUILT_IN, HELDOUT, STUDIES

    known = BUILT_IN + HELDOUT + STUDIES
    unknown = [name for name in args.cases if name not in known]
    if unknown:
        raise _BadInput(f"unknown case {unknown[0]!r}; known: {', '.join(known)}")
    try:
        args.models = parse_models(args.model)
    except ValueError as error:
        raise _BadInput(f"--model {args.model!r}: {error}") from None
    args.rules = _parse_rules(args.rule)
    if not args.nu < 0.5:
        raise _BadInput(f"--nu {args.nu:g} is not < 0.5 (nu = 0.5 is incompressible: the bulk modulus is infinite "
                        "and linear elasticity has no displacement-only solution)")
    if not args.nu > -1.0:
        raise _BadInput(f"--nu {args.nu:g} is not > -1")
    if not (np.isfinite(args.E) and args.E > 0):
        raise _BadInput(f"--E {args.E:g} Pa is not > 0")
    if not (np.isfinite(args.density) and args.density > 0):
        raise _BadInput(f"--density {args.density:g} kg/m^3 is not > 0")
    if args.clamp and not args.mesh:
        raise _BadInput("--clamp applies to --mesh FILE, which is missing")
    if not args.mesh and (args.units != "m" or args.scale is not None):
        raise _BadInput("--units and --scale apply to --mesh FILE, which is missing")
    if args.scale is not None and not (np.isfinite(args.scale) and args.scale > 0):
        raise _BadInput(f"--scale {args.scale:g} is not a finite number > 0")
    if args.workers is not None and args.workers < 1:
        raise _BadInput(f"--workers {args.workers} is not >= 1")
    if args.workers is not None and args.scheduler is not None:
        raise _BadInput("--workers sets a local cluster; --scheduler runs on an existing one: give one of them")
    _check_folders(args)


def _parse_rules(text) -> tuple:
    """Spring stiffness rules from ``"NAME[,NAME...]"``, in :data:`validation.compare.RULES`'s order, each once."""
    from validation.compare import RULES

    names = [name.strip() for name in text.split(",")]
    unknown = [name for name in names if name not in RULES]
    if unknown:
        raise _BadInput(f"--rule {text!r}: unknown rule {unknown[0]!r}; known: {', '.join(RULES)} (comma-separated)")
    return tuple(rule for rule in RULES if rule in names)


@contextlib.contextmanager
def _client(args):
    """A Dask client for ``--workers N`` or ``--scheduler ADDRESS`` (:func:`volspring.sweep.sweep_client`), or
    None: the cases and studies run in this process."""
    if args.workers is None and args.scheduler is None:
        yield None
        return
    from volspring.sweep import sweep_client

    with sweep_client(workers=args.workers, scheduler=args.scheduler) as client:
        yield client


def _check_folders(args) -> None:
    """The output and cache folders exist as writable folders or can be created: checked before any work."""
    from validation.cache import default_folder
    from volspring.output import check_output_folder

    try:
        check_output_folder(args.out, label="--out")
        if args.cache is not None:
            check_output_folder(args.cache, label="--cache")
    except OSError as error:
        raise _BadInput(str(error)) from None
    if args.cache is None:
        try:
            check_output_folder(default_folder(), label="the FEM cache folder")
        except OSError as error:
            raise _BadInput(f"{error}; choose another with --cache DIR or $VOLSPRING_CACHE") from None


def _error(error, status: int) -> int:
    return error_line(PROG, error, status)


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``volspring validate`` (``volspring-validate``); returns the exit status (module docstring)."""
    try:
        args = _parser().parse_args(argv)
    except UsageError as error:
        return _error(error, EXIT_USAGE)
    except SystemExit as done:  # --help, --version
        return done.code if isinstance(done.code, int) else EXIT_DONE
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, stream=sys.stderr,
                        format="%(levelname)s %(name)s: %(message)s")
    command = [PROG] + [str(word) for word in (sys.argv[1:] if argv is None else argv)]
    bar = progress_bar(progress_mode(args), total=1.0, desc="validate", scale=True)

    def progress(fraction, message):
        advance_to(bar, min(max(float(fraction), 0.0), 1.0), str(message)[:60])

    run = None
    with handle_termination():
        try:
            from meshing._io import remove_stale_temporaries
            from validation.cache import default_folder
            from validation.report import validate
            from validation.report.trade import read_sweep
            from volspring.output import RunFolder

            try:
                _check(args)
                own = _own_case(args) if args.mesh else None
                sweeps = [read_sweep(folder) for folder in args.sweep]
                # The folder is claimed before the work: a refusal comes now, not after minutes of computing.
                run = RunFolder.open(args.out, command=command, overwrite=args.overwrite, replace_same_command=True,
                                     flags={"overwrite": "--overwrite"})
            except ValueError as error:  # _BadInput, RunFolderRefused, parse_region, Material, ...
                return _error(error, EXIT_USAGE)
            except OSError as error:  # the folder was fine but could not be set up (a file that would not go)
                return _error(error, EXIT_FAILED)
            with contextlib.suppress(OSError):  # leftovers of killed runs; a cache that cannot be cleaned still works
                remove_stale_temporaries(args.cache or default_folder())
            start = time.perf_counter()
            with run:
                try:
                    with _client(args) as client:
                        validate(args.out, cases=args.cases, quick=args.quick, own_case=own, models=args.models,
                                 rules=args.rules, folder=args.cache, progress=progress, command=command,
                                 record=run.record, sweeps=sweeps, client=client)
                except (ValueError, ArithmeticError, RuntimeError, OSError) as error:
                    run.finish("failed")
                    bar.close()
                    # The input was checked before the work: what fails now is the run (a diverged study: 3).
                    return _error(error, EXIT_DIVERGED if isinstance(error, FloatingPointError) else EXIT_FAILED)
        except (KeyboardInterrupt, Interrupted) as stop:
            bar.close()
            if run is not None:
                with contextlib.suppress(OSError):
                    run.finish("interrupted")
            stderr_line(PROG, f"interrupted by {interruption_name(stop)}; {_left_behind(run)}")
            return exit_status(stop)
    bar.close()
    if args.quiet:
        return EXIT_DONE
    replaced = f" (replacing the {len(run.removed)} file(s) of the previous run)" if run.removed else ""
    written = [f"{args.out}/report.html", f"{args.out}/results.json"]
    written += [f"{args.out}/vtu/"] if any(file.startswith("vtu/") for file in run.files) else []
    print(f"wrote {', '.join(written[:-1])} and {written[-1]} in {time.perf_counter() - start:.0f} s{replaced}")
    return EXIT_DONE


def _left_behind(run) -> str:
    """What an interrupted run leaves, for its one-line message."""
    if run is None:
        return "nothing was written"
    written = [file for file in run.files if (run.path / file).is_file()]
    if not written:
        return f"nothing was written to {run.path} ({run.manifest_path} marks the run interrupted)"
    return (f"{run.path} holds {len(written)} complete file(s) of the report, listed in {run.manifest_path} "
            "(marked interrupted); run the command again to redo it")


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
