"""``volspring-mesh``: a closed surface or a built-in shape in, a tetrahedral mesh file and a summary out.

Examples
--------
``volspring-mesh box:1,0.1,0.1 -o beam.vtu --size 0.025``
``volspring-mesh bunny.obj -o bunny.msh --size 0.005 --method delaunay --seed 1 --shells 2 --shell-thickness 0.002``
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

__all__ = ["main"]

PROG = "volspring-mesh"


class _UsageError(Exception):
    pass


class _Parser(argparse.ArgumentParser):
    def error(self, message):  # one line, not argparse's usage block
        raise _UsageError(message)


def _parser() -> argparse.ArgumentParser:
    from meshing.shapes import SHAPE_NAMES
    from meshing.tetrahedralize import METHODS

    parser = _Parser(prog=PROG, description="Fill a closed surface or a built-in shape with tetrahedra.")
    parser.add_argument("input", help=f"a surface file (stl, obj, ply, off, ...) or a shape such as box:1,0.1,0.1 "
                                      f"({', '.join(SHAPE_NAMES)})")
    parser.add_argument("-o", "--output", required=True, type=Path,
                        help="the tet mesh file to write; its extension names the format (vtu, msh, xdmf, mesh, ...)")
    parser.add_argument("--size", required=True, type=float, help="target tet edge length, in the input's units")
    parser.add_argument("--method", choices=METHODS, default="gmsh", help="meshing backend (default gmsh)")
    parser.add_argument("--shells", type=int, default=0, metavar="N", help="number of virtual shell layers")
    parser.add_argument("--shell-thickness", type=float, default=None, metavar="T", help="offset between layers")
    parser.add_argument("--seed", type=int, default=None, help="random seed (Delaunay lattice jitter, gmsh)")
    parser.add_argument("--verbose", action="store_true", help="log the repairs and steps, and gmsh's output")
    return parser


def _output_format(path: Path) -> str:
    """The meshio format for the output's extension, checked before any meshing is done."""
    from volspring.mesh import mesh_file_format

    try:
        return mesh_file_format(path)
    except ValueError:
        raise ValueError(f"cannot tell the mesh format of output {str(path)!r} from its extension "
                         f"{path.suffix!r}; use e.g. .vtu, .msh, .xdmf or .mesh") from None


def _read_input(text: str):
    """A Shape for a built-in spec, else a checked surface; and the body's own volume."""
    from meshing.shapes import looks_like_shape, parse_shape
    from meshing.surface import load_surface

    path = Path(text)
    if not path.exists() and looks_like_shape(text):
        shape = parse_shape(text)
        return shape, shape.volume, f"built-in {shape.spec()} (exact volume)"
    surface = load_surface(path)
    return surface, float(surface.volume), f"{path.name}: {len(surface.vertices)} vertices, {len(surface.faces)} faces"


def _run(args) -> str:
    from volspring import SpringTopology

    from meshing.quality import quality_summary
    from meshing.tetrahedralize import tetrahedralize

    file_format = _output_format(args.output)
    if not args.size > 0:
        raise ValueError(f"--size = {args.size} is not a positive length")
    if args.shells < 0:
        raise ValueError(f"--shells = {args.shells} is negative; expected a number of layers >= 0")
    if args.shells and args.shell_thickness is None:
        raise ValueError(f"--shells {args.shells} needs --shell-thickness")
    body, surface_volume, described = _read_input(args.input)
    start = time.perf_counter()
    mesh = tetrahedralize(body, size=args.size, method=args.method, seed=args.seed, verbose=args.verbose)
    elapsed = time.perf_counter() - start
    if args.shells:
        from meshing.shells import add_shells

        topology = add_shells(mesh, layers=args.shells, thickness=args.shell_thickness)
    else:
        topology = SpringTopology.from_mesh(mesh)
    quality = quality_summary(mesh)
    mesh.write(args.output, file_format=file_format)

    relative = (mesh.volume - surface_volume) / surface_volume
    springs = ", ".join(f"{count} {kind}" for kind, count in topology.kind_counts().items() if count)
    lines = [
        f"input: {described}",
        f"method: {args.method}, size {args.size:g}" + (f", seed {args.seed}" if args.seed is not None else "")
        + f" ({elapsed:.2f} s)",
        f"nodes: {mesh.node_count} mesh" + (f" + {topology.shell_node_count} shell in {args.shells} layer(s)"
                                            if args.shells else ""),
        f"tets: {mesh.tet_count}",
        f"springs: {topology.spring_count} ({springs})",
        f"volume: tets {mesh.volume:.6g}, surface {surface_volume:.6g}, relative difference {relative:+.3e}",
        str(quality),
        f"wrote {args.output} ({file_format}" + ("; the tet mesh only, not the shell nodes and springs)"
                                                 if args.shells else ")"),
    ]
    return "\n".join(lines)


def main(argv=None) -> int:
    """Run ``volspring-mesh`` with ``argv`` (default: the command line); returns the exit code.

    Bad input prints one line ``volspring-mesh: error: ...`` on stderr and returns 2 (usage) or 1
    (anything else); no output file is left behind.
    """
    try:
        args = _parser().parse_args(argv)
    except _UsageError as error:
        print(f"{PROG}: error: {error}", file=sys.stderr)
        return 2
    if args.verbose:
        logging.basicConfig(level=logging.INFO, format="%(name)s: %(message)s")
    try:
        print(_run(args))
    except (ValueError, OSError, RuntimeError) as error:
        message = " ".join(str(error).split())
        print(f"{PROG}: error: {message}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
