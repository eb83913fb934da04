"""``volspring sweep``: run a scene file once per combination of parameter values, on a local Dask cluster.

``volspring sweep SCENE.toml [--set KEY.PATH=VALUE] --grid KEY.PATH=V1,V2,... [--random KEY.PATH=LOW:HIGH
--samples N --seed S] --out DIR [--workers N | --scheduler ADDRESS]`` (or ``volspring sweep SWEEP.toml``, a sweep
file that names its scene and values: :mod:`volspring.sweep._file`) runs every combination
(:func:`volspring.sweep.run_sweep`) and writes ``DIR/results.csv`` (one row per run) and
``DIR/runs/RUN_ID/run.json``. Runs already in ``DIR`` are not computed again, so an interrupted sweep is resumed by
running the same command; a failing run is a row with its error, and the sweep goes on. By default the runs go to
a local cluster of ``--workers`` processes (one BLAS thread each); ``--scheduler ADDRESS`` sends them to a running
Dask scheduler (``dask scheduler``, ``dask worker``); ``--workers 0`` runs them one after the other in this
process.

Exit status, as every volspring command (:mod:`meshing._command_line`): 0 every run has its row (failed runs
included: the summary counts them), 1 some runs were lost to the cluster (run the command again), 2 a bad command
line or bad input (the scene, the parameters, the folder), 130 Ctrl-C (143 SIGTERM, 129 SIGHUP): the runs finished
are on disk. Every failure is one line on stderr.

Examples
--------
>>> import tempfile
>>> from pathlib import Path
>>> from volspring.sweep.cli import main
>>> beam = Path(__file__).parents[2] / "examples" / "scenes" / "beam.toml"
>>> main([beam, "--grid", "bodies[0].size=0.1", "--grid", "duration=0.02", "--grid", "integrator.dt=0.01,0.02",
...       "--workers", "0", "--out", tempfile.mkdtemp(), "--quiet"])
0
"""

from __future__ import annotations

import logging
import os
import sys
from collections.abc import Sequence
from pathlib import Path

from meshing._command_line import (EXIT_DONE, EXIT_FAILED, EXIT_USAGE, Parser, UsageError, add_common_options,
                                   advance_to, error_line, progress_bar, progress_mode, stderr_line)

__all__ = ["build_parser", "main"]

PROG = "volspring-sweep"


def build_parser() -> Parser:
    """The options of ``volspring sweep``."""
    parser = Parser(prog=PROG, description="Run a scene file once per combination of parameter values (a grid, or "
                                           "random draws from ranges), on a local Dask cluster or an existing one; "
                                           "one row per run in OUT/results.csv.")
    parser.add_argument("scene", metavar="SCENE", type=Path,
                        help="a scene file (.toml), as volspring sim takes it, or a sweep file (.toml: scene = "
                             "\"...\" with [grid], [random], [set], [probes]), which the options below add to")
    values = parser.add_argument_group("parameters")
    values.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE",
                        help="a value of the scene for every run, as volspring sim --set (repeatable)")
    values.add_argument("--grid", action="append", default=[], metavar="KEY.PATH=V1,V2,...",
                        help="values of a key path, as --set takes one; the runs are the product of every --grid "
                             "(repeatable; a value with commas goes in a TOML array: KEY=[\"a,b\", \"c,d\"])")
    values.add_argument("--random", action="append", default=[], metavar="KEY.PATH=LOW:HIGH",
                        help="a range of a key path, --samples draws from it (uniform; whole numbers when both ends "
                             "are); with --grid, every grid point is run with every draw (repeatable)")
    values.add_argument("--samples", type=int, metavar="N", help="draws of the --random ranges")
    values.add_argument("--seed", type=int, metavar="S", help="seed of the --random draws (default: the sweep "
                                                              "file's, else 0)")
    values.add_argument("--frequencies", type=int, metavar="N",
                        help="also measure the scene's N lowest natural frequencies at rest (columns frequency_1_hz, "
                             "...; default: the sweep file's, else none)")
    values.add_argument("--probe", action="append", default=[], metavar="NAME=X,Y,Z",
                        help="also measure the displacement of the node nearest the point X,Y,Z [m] (columns "
                             "NAME_ux, NAME_uy, NAME_uz; repeatable)")
    where = parser.add_argument_group("where")
    where.add_argument("-o", "--out", type=Path, required=True, metavar="DIR",
                       help="the sweep's folder: results.csv, sweep.json, runs/RUN_ID/run.json; runs already in it "
                            "are not computed again")
    where.add_argument("--workers", type=int, metavar="N",
                       help="worker processes of the local cluster, one thread each (default: the CPU count); 0 runs "
                            "the sweep in this process, one run after the other")
    where.add_argument("--scheduler", metavar="ADDRESS",
                       help="run on the Dask cluster of this scheduler (tcp://HOST:8786) instead of a local one")
    where.add_argument("--rerun-failed", action="store_true", help="compute again the runs recorded as failed")
    add_common_options(parser.add_argument_group("terminal"), prog=PROG, progress="the runs done on stderr")
    return parser


def main(argv: Sequence[str | os.PathLike[str]] | None = None) -> int:
    """Run ``volspring sweep`` with ``argv`` (default ``sys.argv[1:]``); returns the exit status."""
    argv = sys.argv[1:] if argv is None else [str(token) for token in argv]
    try:
        args = build_parser().parse_args(argv)
    except UsageError as error:
        return error_line(PROG, error, EXIT_USAGE)
    except SystemExit as done:  # --help, --version
        return done.code if isinstance(done.code, int) else 0
    if args.verbose:
        logging.basicConfig(level=logging.INFO, format="%(name)s: %(message)s", stream=sys.stderr)
    else:  # a run's warnings are in its record (column warnings), not on the terminal, one per run
        logging.getLogger("volspring").addHandler(logging.NullHandler())
    from meshing._signals import Interrupted, exit_status, handle_termination, interruption_name

    try:
        options = _options(args)
    except ValueError as error:
        return error_line(PROG, error, EXIT_USAGE)
    bar = progress_bar(progress_mode(args), total=1, desc="sweep", unit="runs")
    counts = {"failed": 0}

    def show(record, done, total):
        counts["failed"] += record["status"] != "done"
        bar.total = total
        advance_to(bar, done, f"{counts['failed']} failed" if counts["failed"] else "")

    try:
        with handle_termination():
            result = _sweep(args, options, show)
    except (ValueError, OSError) as error:  # SceneFileError, bad parameters, an unwritable folder: before the runs
        return error_line(PROG, error, EXIT_USAGE)
    except (KeyboardInterrupt, Interrupted) as stop:
        bar.close()
        stderr_line(PROG, f"interrupted by {interruption_name(stop)}; the runs finished are in {args.out}: run the "
                          "same command to compute the others")
        return exit_status(stop)
    except Exception as error:  # the cluster could not be started or reached
        return error_line(PROG, f"{type(error).__name__}: {error}", EXIT_FAILED)
    finally:
        bar.close()
    if not args.quiet:
        computed = f"{result.executed} computed, {result.skipped} already in {args.out}"
        failed = f"; {result.failed} failed (their rows say why)" if result.failed else ""
        print(f"sweep: {len(result.records)} runs ({computed}){failed}: {result.table}")
    if result.missing:
        return error_line(PROG, f"{len(result.missing)} runs were lost to the cluster and have no row; run the same "
                                "command again to compute them", EXIT_FAILED)
    return EXIT_DONE


def _options(args) -> dict:
    """run_sweep's keywords from the command line; ValueError naming the option for a bad value."""
    from volspring.output import check_output_folder
    from volspring.scene_file import load_toml, parse_assignment
    from volspring.sweep import is_sweep_file, parse_grid, parse_range, read_sweep_file

    sweep_file = None
    if args.scene.suffix.lower() == ".toml" and is_sweep_file(load_toml(args.scene)):
        sweep_file = read_sweep_file(args.scene)
        args.scene = sweep_file.scene
    given = {key: [value] for key, value in map(parse_assignment, args.set)}
    for key, values in map(parse_grid, args.grid):
        if key in given:
            raise ValueError(f"{key} is given twice (--set, --grid); give it once")
        given[key] = values
    given_random = dict(parse_range(text) for text in args.random)
    # A key path on the command line replaces the sweep file's, as a grid or as a range.
    grid = {key: values for key, values in (sweep_file.grid if sweep_file else {}).items()
            if key not in given and key not in given_random} | given
    random = {key: bounds for key, bounds in (sweep_file.random if sweep_file else {}).items()
              if key not in given} | given_random
    if sweep_file is not None:
        args.samples = sweep_file.samples if args.samples is None else args.samples
        args.seed = sweep_file.seed if args.seed is None else args.seed
        args.frequencies = sweep_file.frequencies if args.frequencies is None else args.frequencies
        args.probe = [f"{name}={','.join(map(repr, point))}" for name, point in sweep_file.probes.items()] + args.probe
    args.seed = 0 if args.seed is None else args.seed
    args.frequencies = 0 if args.frequencies is None else args.frequencies
    if args.frequencies < 0:
        raise ValueError(f"--frequencies {args.frequencies} is not >= 0")
    if random and args.samples is None:
        raise ValueError("--random needs --samples N, the number of draws")
    if args.samples is not None and not random:
        raise ValueError(f"--samples {args.samples} needs a --random range to draw from")
    if args.workers is not None and args.workers < 0:
        raise ValueError(f"--workers {args.workers} is not >= 0")
    if args.workers is not None and args.scheduler is not None:
        raise ValueError("--workers sets the local cluster; --scheduler runs on an existing one: give one of them")
    if args.scene.suffix.lower() != ".toml":
        raise ValueError(f"SCENE {args.scene} is not a scene file (*.toml)")
    load_toml(args.scene)  # a missing file or bad TOML: before any cluster is started
    probes = {}
    for text in args.probe:  # the sweep file's first: a name given again on the command line replaces it
        name, equals, point = text.partition("=")
        try:
            coordinates = [float(value) for value in point.split(",")]
        except ValueError:
            coordinates = []
        if not equals or not name.isidentifier() or len(coordinates) != 3:
            raise ValueError(f"--probe {text!r} is not NAME=X,Y,Z (a name and a point [m], e.g. tip=0.5,0,0)")
        probes[name] = coordinates
    check_output_folder(args.out, label="--out")
    return {"parameters": grid, "random": random, "samples": args.samples, "seed": args.seed, "probes": probes,
            "frequencies": args.frequencies, "rerun_failed": args.rerun_failed}


def _sweep(args, options, callback):
    from volspring.sweep import run_sweep, sweep_client

    if args.workers == 0:
        return run_sweep(args.scene, out=args.out, callback=callback, **options)
    from volspring.sweep import sweep_combinations

    # The combinations are checked before a cluster is started: a bad parameter costs no worker.
    sweep_combinations(options["parameters"], random=options["random"], samples=options["samples"],
                       seed=options["seed"])
    with sweep_client(workers=args.workers, scheduler=args.scheduler) as client:
        return run_sweep(args.scene, out=args.out, client=client, callback=callback, **options)


if __name__ == "__main__":
    sys.exit(main())
