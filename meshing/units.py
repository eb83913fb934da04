"""Length units of input files: what a coordinate of 1 means, turned into metres on read.

Everything inside volspring is SI (metres). Meshes and surfaces drawn in CAD or scanned often use
millimetres or centimetres, and nothing in a file says so: the readers
(:meth:`meshing.TetMesh.read`, :func:`meshing.load_surface`) take ``units`` and ``scale`` and multiply
the coordinates by ``UNITS[units] * scale`` (:func:`length_factor`). A body read in metres with no
explicit scale that is more than :data:`LARGE_BODY_DIAGONAL` across was most likely drawn in millimetres:
:func:`warn_if_large` says so.

Examples
--------
>>> length_factor("mm"), length_factor("cm", 2.0), length_factor("m")
(0.001, 0.02, 1.0)
"""

from __future__ import annotations

import logging
import math
import numbers
import warnings

import numpy as np
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from numpy.typing import ArrayLike
    import argparse

__all__ = ["LARGE_BODY_DIAGONAL", "UNITS", "add_unit_arguments", "length_factor", "scaled_points", "warn_if_large"]

logger = logging.getLogger(__name__)
# The warning reaches users through warnings.warn; the log record is for applications that configure logging.
# Without a handler of its own, logging's last-resort handler would print it a second time on stderr.
logger.addHandler(logging.NullHandler())

#: Length units an input file's coordinates may be in, as metres per unit.
UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}

#: Bounding-box diagonal [m] above which a body read in metres without an explicit scale is suspected of
#: being in millimetres or centimetres (a soft body of 10 m is rare; a 160 mm part read as 160 m is not).
LARGE_BODY_DIAGONAL = 10.0


def length_factor(units: str = "m", scale: float | None = None) -> float:
    """The factor that turns input coordinates into metres: ``UNITS[units] * scale``.

    Parameters
    ----------
    units : {"m", "cm", "mm"}
        The unit of the input's coordinates (default metres).
    scale : float, optional
        A further factor applied to the coordinates, e.g. 2 for a model twice the size of the
        file (default 1). When both are given, the factor is their product: ``units="mm", scale=2``
        reads a coordinate of 1 as 2 mm.

    Returns
    -------
    float
        Metres per input coordinate unit, finite and > 0.

    Raises
    ------
    ValueError
        For a unit not in :data:`UNITS` (naming the value and the choices), or a scale that is not a
        finite number > 0.
    """
    if not isinstance(units, str) or units not in UNITS:
        choices = ", ".join(repr(name) for name in UNITS)
        raise ValueError(f"units = {units!r} is not a known length unit; expected one of {choices}")
    if scale is None:
        return UNITS[units]
    if isinstance(scale, bool) or not isinstance(scale, numbers.Real) or not (math.isfinite(scale) and scale > 0):
        raise ValueError(f"scale = {scale!r} is not a finite number > 0")
    return UNITS[units] * float(scale)


def scaled_points(points: ArrayLike, factor: float, *, name: str) -> np.ndarray:
    """Input coordinates times ``factor`` (from :func:`length_factor`), refusing a product that overflows.

    Parameters
    ----------
    points : (n, 3) float
        Coordinates in the input's units.
    factor : float
        Metres per input unit.
    name : str
        How to call the input in messages (e.g. its file name).

    Returns
    -------
    (n, 3) float64
        Coordinates [m] (the input itself, as float64, when ``factor`` is 1).

    Raises
    ------
    ValueError
        When a finite coordinate becomes infinite (beyond float64's 1.8e308) once scaled.
    """
    points = np.asarray(points, dtype=np.float64)
    if factor == 1.0:
        return points
    with np.errstate(over="ignore"):
        scaled = points * factor
    overflow = np.isinf(scaled) & np.isfinite(points)
    if overflow.any():
        largest = float(np.abs(points[np.isfinite(points)]).max())
        raise ValueError(f"{name}: scaling by {factor:g} makes coordinates overflow float64: the largest absolute "
                         f"coordinate is {largest:.3g}; expected coordinates x scale below {np.finfo(float).max:.3g}")
    return scaled


def warn_if_large(points: ArrayLike, *, units: str, scale: float | None, name: str, stacklevel: int = 3) -> None:
    """Warn (``UserWarning``, and log) when a body read in metres with no explicit scale is over 10 m across.

    Parameters
    ----------
    points : (n, 3) float
        The body's coordinates [m], already converted.
    units : str
        The ``units`` the body was read with; only ``"m"`` can warn.
    scale : float or None
        The ``scale`` it was read with; any explicit scale (even 1) says the size is meant.
    name : str
        How to call the body in the message (e.g. its file name).
    stacklevel : int
        Passed to :func:`warnings.warn`: 3 points at the caller of the reader that calls this.
    """
    if units != "m" or scale is not None:
        return
    points = np.asarray(points, dtype=np.float64)
    if len(points) == 0:
        return
    diagonal = float(np.linalg.norm(np.ptp(points, axis=0)))
    if not diagonal > LARGE_BODY_DIAGONAL:
        return
    message = (f"{name} is {diagonal:.3g} m across (bounding-box diagonal), more than {LARGE_BODY_DIAGONAL:g} m: "
               f'if its coordinates are in millimetres or centimetres, read it with units="mm" or units="cm" '
               f"(on the command line: --units mm); give scale=1 (--scale 1) if it really is in metres")
    logger.warning(message)
    warnings.warn(message, UserWarning, stacklevel=stacklevel)


def add_unit_arguments(parser: argparse.ArgumentParser | argparse._ArgumentGroup, *, applies_to: str,
                       scale_applies_to: str | None = None) -> None:
    """Add ``--units {m,cm,mm}`` and ``--scale FACTOR`` to an ``argparse`` parser.

    Their values go straight to the readers: ``TetMesh.read(path, units=args.units, scale=args.scale)``
    or ``load_surface(path, units=args.units, scale=args.scale)``; :func:`length_factor` checks them.

    Parameters
    ----------
    parser : argparse.ArgumentParser
    applies_to : str
        What ``--units`` is the unit of, for the help text (e.g. ``"the input mesh's coordinates"``).
    scale_applies_to : str, optional
        What ``--scale`` multiplies, for the help text (default: ``applies_to``).
    """
    parser.add_argument("--units", choices=tuple(UNITS), default="m",
                        help=f"the length unit of {applies_to} (default m); everything is converted to metres")
    parser.add_argument("--scale", type=float, default=None, metavar="FACTOR",
                        help=f"multiply {scale_applies_to or applies_to} by FACTOR, on top of --units (the factor "
                             f"to metres is units x FACTOR); giving it also silences the warning for a body over "
                             f"{LARGE_BODY_DIAGONAL:g} m across read in metres")
