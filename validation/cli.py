"""``volspring-validate``: the spring model against linear-elastic FEM, as a report.

Examples
--------
Everything, on coarse meshes, in about a minute::

    volspring-validate --quick --out validation-report

Your own mesh, clamped at its lowest z, under gravity::

    volspring-validate --mesh part.vtu --clamp zmin --E 2e6 --nu 0.4 --density 1100 --out part-report

Writes ``OUT/report.html``, ``OUT/results.json`` and ``OUT/vtu/*.vtu``. Bad input ends with one line
``volspring-validate: error: ...`` and exit status 2.
"""

from __future__ import annotations

import argparse
import logging
import sys
import time

import numpy as np

__all__ = ["main"]

PROG = "volspring-validate"


class _Bar:
    """A one-line progress bar on stderr, redrawn in place with a carriage return."""

    def __init__(self, stream, *, width: int = 28, enabled: bool = True):
        self.stream, self.width, self.enabled = stream, width, enabled
        self.start = time.perf_counter()

    def __call__(self, fraction: float, message: str) -> None:
        if not self.enabled:
            return
        filled = int(round(self.width * fraction))
        elapsed = time.perf_counter() - self.start
        line = f"[{'#' * filled}{'.' * (self.width - filled)}] {100 * fraction:3.0f}% {elapsed:5.0f} s  {message}"
        self.stream.write("\r" + line[:110].ljust(110))
        self.stream.flush()

    def close(self) -> None:
        if self.enabled:
            self.stream.write("\n")
            self.stream.flush()


def _parser():
    from validation.report import BUILT_IN, STUDIES

    parser = argparse.ArgumentParser(
        prog=PROG, description="Compare the spring model with linear-elastic FEM (scikit-fem, P2) on the same "
                               "meshes and write report.html, results.json and VTU files.")
    parser.add_argument("cases", nargs="*", metavar="CASE",
                        help=f"cases and studies to run: {', '.join(BUILT_IN + STUDIES)} (default: all, or only "
                             "your mesh with --mesh)")
    parser.add_argument("--quick", action="store_true", help="coarse meshes and short runs (about a minute)")
    parser.add_argument("--out", required=True, metavar="DIR", help="output folder")
    parser.add_argument("--mesh", metavar="FILE", help="your tet mesh (any format meshio reads)")
    parser.add_argument("--clamp", action="append", metavar="REGION",
                        help="region of --mesh held in place: xmin|xmax|ymin|ymax|zmin|zmax, x<VALUE, z>VALUE, "
                             "box:x0,y0,z0,x1,y1,z1 (repeat to hold several)")
    parser.add_argument("--E", type=float, default=1e6, help="Young's modulus of --mesh [Pa] (default 1e6)")
    parser.add_argument("--nu", type=float, default=0.3, help="Poisson ratio of --mesh, < 0.5 (default 0.3)")
    parser.add_argument("--density", type=float, default=1000.0, help="density of --mesh [kg/m^3] (default 1000)")
    parser.add_argument("--gravity", default="0,0,-9.81", metavar="GX,GY,GZ",
                        help="gravity on --mesh [m/s^2] (default 0,0,-9.81)")
    parser.add_argument("--cache", metavar="DIR", help="FEM cache folder (default $VOLSPRING_CACHE or "
                                                       "~/.cache/volspring/fem)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("-v", "--verbose", action="store_true", help="log what is computed")
    return parser


class _BadInput(ValueError):
    pass


def _own_case(args):
    from validation.cases import own_mesh_case, parse_region
    from volspring.material import Material
    from volspring.mesh import TetMesh

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
        mesh = TetMesh.read(args.mesh)
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
    from validation.report import BUILT_IN, STUDIES

    unknown = [name for name in args.cases if name not in BUILT_IN + STUDIES]
    if unknown:
        raise _BadInput(f"unknown case {unknown[0]!r}; known: {', '.join(BUILT_IN + STUDIES)}")
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


def main(argv=None) -> int:
    """Run ``volspring-validate``; returns the exit status (0 ok, 2 bad input, 1 failure)."""
    parser = _parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, stream=sys.stderr,
                        format="%(levelname)s %(name)s: %(message)s")
    try:
        _check(args)
        own = _own_case(args) if args.mesh else None
    except ValueError as error:  # _BadInput, and the checks of parse_region, Material, own_mesh_case
        print(f"{PROG}: error: {error}", file=sys.stderr)
        return 2
    from validation.report import validate

    bar = _Bar(sys.stderr, enabled=not args.no_progress)
    command = [PROG] + list(sys.argv[1:] if argv is None else argv)
    start = time.perf_counter()
    try:
        validate(args.out, cases=args.cases, quick=args.quick, own_case=own, folder=args.cache, progress=bar,
                 command=command)
    except (ValueError, ArithmeticError, RuntimeError, OSError) as error:
        bar.close()
        message = " ".join(str(error).split())
        print(f"{PROG}: error: {message}", file=sys.stderr)
        return 2 if isinstance(error, ValueError) else 1
    bar.close()
    print(f"wrote {args.out}/report.html, {args.out}/results.json and {args.out}/vtu/ "
          f"in {time.perf_counter() - start:.0f} s")
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
