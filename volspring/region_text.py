"""The text form of regions (``xmin``, ``x<0.01``, ``x=0``, ``box:x0,y0,z0,x1,y1,z1``), as command lines take them.

:func:`parse_region` reads it in the grammar of :mod:`volspring.regions`; :func:`describe_bounds` writes
the bounding box of points for messages about a region that selects nothing. Both are imported from
:mod:`volspring.regions`.
"""

from __future__ import annotations

import math
import re

from volspring.region_checks import AXES, _finite, as_points
from volspring.region_types import FACE_NAMES, Box, Face, HalfSpace, Region
import numpy as np

__all__ = ["describe_bounds", "parse_region"]

_FACE = re.compile(r"([xyz])(min|max)")
_SOME_FACE = re.compile(r"(\w*)(min|max)")
_COMPARISON = re.compile(r"([xyz])(<=|>=|<|>|=)(.*)")
_FORMS = ("xmin, xmax, ymin, ymax, zmin, zmax (a face of the bounding box), x<V, x<=V, x>V, x>=V (a half-space), "
          "x=V (a plane), the same with y or z, or x0,y0,z0,x1,y1,z1 or box:x0,y0,z0,x1,y1,z1 (a box)")


def parse_region(text: str, *, unit: float = 1.0, tolerance: float | None = None, label: str = "region") -> Region:
    """The region written as ``text``, in the grammar of :mod:`volspring.regions`.

    Parameters
    ----------
    text : str
        ``xmin`` .. ``zmax``, ``x<V`` (``<=``, ``>``, ``>=``, any axis), ``x=V``,
        ``x0,y0,z0,x1,y1,z1`` or ``box:x0,y0,z0,x1,y1,z1``; case and whitespace ignored.
    unit : float, optional
        Metres per unit of the numbers in ``text`` (keyword-only; 0.001 for millimetres).
    tolerance : float, optional
        Slack of the region [m] (keyword-only); default: see :meth:`Region.slack`.
    label : str, optional
        What ``text`` is, for error messages (keyword-only): ``"--pin"``, ``"--clamp"``, ...

    Returns
    -------
    Region
        A :class:`Face`, :class:`HalfSpace` or :class:`Box`.

    Raises
    ------
    ValueError
        For text in none of the forms, an unknown face, a number that is not finite, a box without
        six numbers or with a lower corner above its upper one; the message starts with ``label``
        and the text.

    Examples
    --------
    >>> parse_region("Z MIN")
    Face(axis='z', side='min', tolerance=None)
    >>> parse_region("-1,-1,-1,0,1,1")
    Box(lower=(-1.0, -1.0, -1.0), upper=(0.0, 1.0, 1.0), tolerance=None)
    >>> parse_region("wmin", label="--pin")
    Traceback (most recent call last):
    ...
    ValueError: --pin 'wmin': unknown face 'wmin'; the faces are xmin, xmax, ymin, ymax, zmin, zmax
    """
    if not isinstance(text, str):
        raise TypeError(f"{label} = {text!r} is not text such as 'xmin', 'x<0.01' or 'box:0,0,0,1,1,1'")
    if not _finite(unit, f"unit = {unit!r} m") > 0.0:
        raise ValueError(f"unit = {unit!r} m is not > 0")
    unit = float(unit)
    where = f"{label} {text!r}"
    spec = "".join(text.split()).lower()
    options = {"tolerance": tolerance}
    if match := _FACE.fullmatch(spec):
        return Face(match[1], match[2], **options)
    if _SOME_FACE.fullmatch(spec):
        raise ValueError(f"{where}: unknown face {spec!r}; the faces are {', '.join(FACE_NAMES)}")
    if match := _COMPARISON.fullmatch(spec):
        axis, relation, value = match[1], match[2], _text_number(match[3], unit, where)
        if relation == "=":
            return Box.plane(axis, value, **options)
        point, normal = [0.0] * 3, [0.0] * 3
        point[AXES.index(axis)] = value
        normal[AXES.index(axis)] = 1.0 if relation.startswith("<") else -1.0
        return HalfSpace(tuple(point), tuple(normal), **options)
    if spec.startswith("box:") or "," in spec:
        parts = spec.removeprefix("box:").split(",")
        form = "6 finite numbers xmin,ymin,zmin,xmax,ymax,zmax"
        if len(parts) != 6:
            raise ValueError(f"{where} is not {form}: got {len(parts)} values")
        try:
            values = [_text_number(part, unit, where) for part in parts]
        except ValueError as error:
            raise ValueError(f"{where} is not {form}: {str(error).removeprefix(where + ': ')}") from None
        try:
            return Box(tuple(values[:3]), tuple(values[3:]), **options)
        except ValueError as error:
            raise ValueError(f"{where}: {error}") from None
    raise ValueError(f"{where} is not one of the region forms {_FORMS}")


def describe_bounds(points: np.ndarray) -> str:
    """The bounding box of (n, 3) points as ``"[x0, x1] x [y0, y1] x [z0, z1]"`` [m], for messages
    about a region that selects nothing.

    Examples
    --------
    >>> describe_bounds([[0, 0, 0], [0.2, 0.05, 0.05]])
    '[0, 0.2] x [0, 0.05] x [0, 0.05]'
    """
    points = as_points(points)
    if not len(points):
        return "nothing (no point)"
    return " x ".join(f"[{a:.6g}, {b:.6g}]" for a, b in zip(points.min(axis=0), points.max(axis=0)))


def _text_number(part: str, unit: float, where: str) -> float:
    """A number of the text form, in metres."""
    try:
        number = float(part)
    except ValueError:
        raise ValueError(f"{where}: {part!r} is not a number") from None
    if not math.isfinite(number * unit):
        raise ValueError(f"{where}: {part!r} is not a finite number")
    return number * unit
