"""``volspring-mesh``: a closed surface or a built-in shape in, a tetrahedral mesh file and a summary out.

Examples
--------
``volspring mesh box:1,0.1,0.1 -o beam.vtu --size 0.025``
``volspring mesh bunny.obj -o bunny.msh --size 0.005 --mesher delaunay --seed 1 --shells 2 --shell-thickness 0.002``
``volspring mesh bunny_in_mm.stl --units mm -o bunny.vtu --size 5``  (5 mm tets; the mesh is written in metres)
``volspring mesh sphere:0.1 -o ball.vstopo.npz --size 0.02 --shells 1 --shell-thickness 0.005``

``volspring-mesh`` is the same command, and ``--output`` and ``--method`` the earlier spellings of ``--out``
and ``--mesher``. The options, exit statuses and progress follow the convention of all of volspring's
commands (:mod:`meshing._command_line`).

Shells have no place in a tet mesh format. An output named ``*.npz`` (by convention ``NAME.vstopo.npz``)
is written as a spring topology file (:mod:`meshing.topology_io`: the tet mesh with its shell nodes,
springs and triangles), which ``volspring-sim`` reads as its INPUT. An output in a mesh format
(``.vtu``, ``.msh``, ...) with ``--shells`` gets that file beside it as well, ``NAME.vstopo.npz``
(:func:`sidecar_path`), so the shells are never lost; without ``--shells`` only the mesh is written.
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import sys
import time
import warnings
from pathlib import Path

from meshing._command_line import (EXIT_DONE, EXIT_FAILED, EXIT_USAGE, Parser, UsageError,
                                   add_common_options, advance_to, error_line, progress_bar, progress_mode,
                                   stderr_line, stdout_to_stderr)
from meshing._signals import Interrupted, exit_status, handle_termination, interruption_name
from collections.abc import Sequence

__all__ = ["main", "sidecar_path"]

PROG = "volspring-mesh"
#: The stages of the progress bar, in order.
STAGES = ("read", "tetrahedralize", "shells", "quality", "write")


class _BadInput(ValueError):
    """Bad input found before the meshing (exit status 2)."""


def _parser() -> argparse.ArgumentParser:
    from meshing.shapes import SHAPE_NAMES
    from meshing.tetrahedralize import METHODS
    from meshing.units import add_unit_arguments

    parser = Parser(prog=PROG, description="Fill a closed surface or a built-in shape with tetrahedra.")
    parser.add_argument("input", help=f"a surface file (stl, obj, ply, off, ...) or a shape such as box:1,0.1,0.1 "
                                      f"({', '.join(SHAPE_NAMES)})")
    parser.add_argument("-o", "--out", "--output", dest="out", required=True, type=Path, metavar="OUT",
                        help="the file to write; its extension names the format: a tet mesh (vtu, msh, xdmf, mesh, "
                             "...), or .npz (by convention NAME.vstopo.npz) for a spring topology file, the tet mesh "
                             "with its shells, which volspring-sim reads. With --shells and a tet mesh format the "
                             "topology file is written beside the mesh too, as NAME.vstopo.npz (--output: the earlier spelling)")
    parser.add_argument("--size", required=True, type=float, help="target tet edge length, in --units")
    parser.add_argument("--mesher", "--method", dest="mesher", choices=METHODS, default="gmsh",
                        help="meshing backend (--method: the earlier spelling)")
    parser.add_argument("--shells", type=int, default=0, metavar="N", help="number of virtual shell layers")
    parser.add_argument("--shell-thickness", type=float, default=None, metavar="T",
                        help="offset between layers, in --units")
    add_unit_arguments(parser, applies_to="the input (a file's coordinates, or a built-in shape's dimensions) and of "
                                          "--size and --shell-thickness",
                       scale_applies_to="the input (a file's coordinates, or a built-in shape's dimensions; not "
                                        "--size or --shell-thickness)")
    parser.add_argument("--seed", type=int, default=None, help="random seed (Delaunay lattice jitter, gmsh)")
    add_common_options(parser, progress="progress of the stages (read, tetrahedralize, shells, quality, write)")
    return parser


def sidecar_path(path: str | os.PathLike[str]) -> Path:
    """The spring topology file written beside a tet mesh output with ``--shells``: ``NAME.vstopo.npz``.

    >>> sidecar_path("out/beam.vtu").as_posix()
    'out/beam.vstopo.npz'
    """
    from meshing.topology_io import TOPOLOGY_SUFFIX

    path = Path(path)
    return path.with_name(path.stem + TOPOLOGY_SUFFIX)


def _output_format(path: Path, *, shells: bool = False):
    """The meshio format for the output's extension (None for a spring topology file), and whether it can be
    written there, checked before any meshing is done."""
    from meshing.mesh_io import mesh_file_format
    from meshing.topology_io import is_topology_path

    if path.is_dir():
        raise ValueError(f"output {path} is a directory; expected a mesh file to write")
    if shells and not is_topology_path(path) and sidecar_path(path).is_dir():
        raise ValueError(f"cannot write the shells of output {path} to {sidecar_path(path)}: it is a directory")
    # The nearest folder that exists: the write creates the missing ones below it.
    existing = next(parent for parent in path.parents if parent.exists() or parent == parent.parent)
    if existing.exists() and not existing.is_dir():
        raise ValueError(f"cannot write output {path}: {existing} is a file, not a directory")
    if existing.is_dir() and not os.access(existing, os.W_OK | os.X_OK):
        raise ValueError(f"cannot write output {path}: no permission to create files in {existing}")
    if is_topology_path(path):
        return None
    try:
        file_format = mesh_file_format(path)
    except ValueError:
        raise ValueError(f"cannot tell the mesh format of output {str(path)!r} from its extension "
                         f"{path.suffix!r}; use e.g. .vtu, .msh, .xdmf or .mesh (or .vstopo.npz for the "
                         "spring topology with shells)") from None
    if file_format == "xdmf" and path.with_suffix(".h5").is_dir():
        raise ValueError(f"cannot write output {path}: its heavy data goes to {path.with_suffix('.h5')}, "
                         "which is a directory")
    return file_format


def _read_input(text: str, units: str, scale):
    """A Shape for a built-in spec, else a checked surface, in metres; the body's own volume; a description."""
    from meshing.shapes import Shape, looks_like_shape, parse_shape
    from meshing.surface import load_surface
    from meshing.units import length_factor

    factor = length_factor(units, scale)
    converted = "" if factor == 1.0 else f" (x{factor:g} to m)"
    path = Path(text)
    if not path.exists() and looks_like_shape(text):
        shape = parse_shape(text)
        if factor != 1.0:
            shape = Shape(shape.name, tuple(dimension * factor for dimension in shape.dimensions))
        return shape, shape.volume, f"built-in {shape.spec()} (exact volume){converted}"
    surface = load_surface(path, units=units, scale=scale)
    return surface, float(surface.volume), (f"{path.name}: {len(surface.vertices)} vertices, "
                                            f"{len(surface.faces)} faces{converted}")


def _run(args, bar) -> str:
    """Check, read, mesh, add shells, measure and write; returns the summary. Bad input raises
    :class:`_BadInput` (exit status 2) before any meshing; a failure of the meshing or the write raises
    anything else."""
    from meshing.quality import quality_summary
    from meshing.tetrahedralize import tetrahedralize
    from meshing.topology import SpringTopology
    from meshing.units import UNITS

    try:
        file_format = _output_format(args.out, shells=args.shells > 0)
        if args.scale is not None and not (math.isfinite(args.scale) and args.scale > 0):
            raise ValueError(f"--scale = {args.scale} is not a finite number > 0")
        if not args.size > 0:
            raise ValueError(f"--size = {args.size} is not a positive length")
        if args.shells < 0:
            raise ValueError(f"--shells = {args.shells} is negative; expected a number of layers >= 0")
        if args.shells and args.shell_thickness is None:
            raise ValueError(f"--shells {args.shells} needs --shell-thickness")
        size = args.size * UNITS[args.units]  # lengths on the command line are in --units, not scaled
        advance_to(bar, 0, STAGES[0])
        body, surface_volume, described = _read_input(args.input, args.units, args.scale)
    except (ValueError, OSError) as error:
        if isinstance(error.__cause__, ImportError):  # a missing package is not the input's fault
            raise RuntimeError(str(error)) from error
        raise _BadInput(str(error)) from error
    advance_to(bar, 1, STAGES[1])
    start = time.perf_counter()
    try:
        with stdout_to_stderr(args.verbose):  # gmsh's log on stderr, the summary alone on stdout
            mesh = tetrahedralize(body, size=size, method=args.mesher, seed=args.seed, verbose=args.verbose)
    except ValueError as error:  # the size for this body, a surface the mesher refuses: the input
        raise _BadInput(str(error)) from error
    except Exception as error:  # gmsh raises bare Exceptions
        raise RuntimeError(f"meshing with {args.mesher} at size {size:g} m failed: {error}") from error
    elapsed = time.perf_counter() - start
    advance_to(bar, 2, STAGES[2])
    if args.shells:
        from meshing.shells import add_shells

        try:
            topology = add_shells(mesh, layers=args.shells, thickness=args.shell_thickness * UNITS[args.units])
        except ValueError as error:
            raise _BadInput(str(error)) from error
    else:
        topology = SpringTopology.from_mesh(mesh)
    advance_to(bar, 3, STAGES[3])
    quality = quality_summary(mesh)
    advance_to(bar, 4, STAGES[4])
    wrote = _write(args.out, file_format, mesh, topology, args.shells)
    advance_to(bar, 5, "done")

    relative = (mesh.volume - surface_volume) / surface_volume
    springs = ", ".join(f"{count} {kind}" for kind, count in topology.kind_counts().items() if count)
    lines = [
        f"input: {described}",
        f"mesher: {args.mesher}, size {size:g} m" + (f", seed {args.seed}" if args.seed is not None else "")
        + f" ({elapsed:.2f} s)",
        f"nodes: {mesh.node_count} mesh" + (f" + {topology.shell_node_count} shell in {args.shells} layer(s)"
                                            if args.shells else ""),
        f"tets: {mesh.tet_count}",
        f"springs: {topology.spring_count} ({springs})",
        f"volume: tets {mesh.volume:.6g} m^3, surface {surface_volume:.6g} m^3, relative difference {relative:+.3e}",
        str(quality),
        wrote,
    ]
    return "\n".join(lines)


def _write(output: Path, file_format, mesh, topology, shells: int) -> str:
    """Write the output (and with shells and a mesh format, the topology file beside it); say what was written.

    Either every file is written or none is left: the topology goes first and is removed if the mesh fails.
    """
    from meshing.topology_io import write_topology

    layers = f"{shells} shell layer(s)" if shells else "no shells"
    if file_format is None:
        write_topology(output, topology)
        return f"wrote {output} (spring topology: the tet mesh and {layers}; volspring-sim reads it)"
    if not shells:
        mesh.write(output, file_format=file_format)
        return f"wrote {output} ({file_format})"
    sidecar = sidecar_path(output)
    write_topology(sidecar, topology)
    try:
        mesh.write(output, file_format=file_format)
    except BaseException:
        sidecar.unlink(missing_ok=True)
        raise
    return (f"wrote {output} ({file_format}; the tet mesh only) and {sidecar} (spring topology: the tet mesh and "
            f"{layers}; volspring-sim reads it)")


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``volspring mesh`` (``volspring-mesh``) with ``argv`` (default: the command line); returns the exit
    status.

    0 done; 2 a bad command line or bad input (a value, the input file, an output that cannot be written
    there), found before any meshing, with one line ``volspring-mesh: error: ...`` on stderr; 1 the meshing or
    the write failed (one line too); 130 Ctrl-C, 143 SIGTERM, 129 SIGHUP. No output file is left behind on
    failure. Warnings (such as a body read in metres that is over 10 m across) print one line each,
    ``volspring-mesh: warning: ...``, on stderr; progress and, with ``-v``, the log and gmsh's output go to
    stderr too, the summary alone to stdout.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> main(["box:1,0.1,0.1", "-o", str(pathlib.Path(tempfile.mkdtemp()) / "beam.vtu"), "--size", "0.05", "-q"])
    0
    """
    try:
        args = _parser().parse_args(argv)
    except UsageError as error:
        return error_line(PROG, error, EXIT_USAGE)
    except SystemExit as done:  # --help, --version
        return done.code if isinstance(done.code, int) else EXIT_DONE
    if args.verbose:
        logging.basicConfig(level=logging.INFO, format="%(name)s: %(message)s", stream=sys.stderr)
    bar = progress_bar(progress_mode(args), total=len(STAGES), desc="mesh", unit="stages")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", UserWarning)
        try:
            with handle_termination():
                summary = _run(args, bar)
        except _BadInput as error:
            bar.close()
            _print_warnings(caught)
            return error_line(PROG, error, EXIT_USAGE)
        except (ValueError, OSError, RuntimeError) as error:
            bar.close()
            _print_warnings(caught)
            return error_line(PROG, error, EXIT_FAILED)
        except (KeyboardInterrupt, Interrupted) as stop:
            bar.close()
            stderr_line(PROG, f"interrupted by {interruption_name(stop)}; no output file was left behind")
            return exit_status(stop)
    bar.close()
    _print_warnings(caught)
    if not args.quiet:
        print(summary)
    return EXIT_DONE


def _print_warnings(caught) -> None:
    for warning in caught:
        stderr_line(PROG, f"warning: {' '.join(str(warning.message).split())}")


if __name__ == "__main__":
    sys.exit(main())
