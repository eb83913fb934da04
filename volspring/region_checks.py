"""Checks at the edge of the regions: points, axes, corners, vectors and tolerances, refused with the value.

Each check returns its input in the form the region types hold (floats, tuples, a (n, 3) array) or
raises ``ValueError`` naming the value and what was expected. Used by :mod:`volspring.region_types` and
:mod:`volspring.region_text`; :data:`AXES`, :func:`as_points` and :func:`axis_index` are also
importable from :mod:`volspring.regions`.
"""

from __future__ import annotations

import math

import numpy as np
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

__all__ = ["AXES", "as_points", "axis_index"]

#: The axis names, in coordinate order.
AXES = ("x", "y", "z")


def as_points(points: ArrayLike) -> np.ndarray:
    """(n, 3) float64 -- ``points`` checked: three finite coordinates [m] per point."""
    try:
        array = np.asarray(points, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"points must be (n, 3) coordinates [m], got {points!r:.80}") from None
    if array.ndim != 2 or array.shape[1] != 3:
        raise ValueError(f"points has shape {array.shape}, expected (n, 3) coordinates [m]")
    bad = ~np.isfinite(array).all(axis=1)
    if bad.any():
        first = int(np.flatnonzero(bad)[0])
        raise ValueError(f"{int(bad.sum())} point(s) are not finite, the first points[{first}] = "
                         f"{_shown(array[first])}")
    return array


def axis_index(axis: int | str) -> int:
    """0, 1 or 2 for an axis given as ``"x"``, ``"y"``, ``"z"`` (any case) or as that index."""
    if isinstance(axis, str) and axis.lower() in AXES:
        return AXES.index(axis.lower())
    if isinstance(axis, (int, np.integer)) and not isinstance(axis, bool) and 0 <= axis < 3:
        return int(axis)
    raise ValueError(f"axis = {axis!r} is not one of 'x', 'y', 'z' (or 0, 1, 2)")


def _bound(values, name: str, open_value: float) -> tuple:
    """A Box corner as three floats, None entries (or a None corner) open."""
    if values is None:
        return (open_value,) * 3
    try:
        entries = list(values)
    except TypeError:
        raise ValueError(f"Box {name} = {values!r} is not three numbers (x, y, z) [m]") from None
    if len(entries) != 3:
        raise ValueError(f"Box {name} = {_shown(entries)} has {len(entries)} entries, expected 3 (x, y, z) [m]")
    corner = []
    for axis, entry in enumerate(entries):
        if entry is None:
            corner.append(open_value)
            continue
        try:
            value = float(entry)
        except (TypeError, ValueError):
            raise ValueError(f"Box {name}[{axis}] = {entry!r} is not a number") from None
        if math.isnan(value):
            raise ValueError(f"Box {name}[{axis}] = nan is not a number; an open side is None or {open_value}")
        if math.isinf(value) and value != open_value:
            raise ValueError(f"Box {name}[{axis}] = {value} would select nothing; an open side is None or "
                             f"{open_value}")
        corner.append(value)
    return tuple(corner)


def _vector(values, name: str) -> tuple:
    try:
        vector = np.asarray(values, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} = {values!r} is not three numbers") from None
    if vector.shape != (3,) or not np.isfinite(vector).all():
        raise ValueError(f"{name} = {_shown(values)} is not three finite numbers (shape (3,))")
    return tuple(float(c) for c in vector)


def _check_tolerance(tolerance) -> None:
    if tolerance is None:
        return
    value = _finite(tolerance, f"tolerance = {tolerance!r} m")
    if value < 0.0:
        raise ValueError(f"tolerance = {tolerance!r} m is not >= 0")


def _finite(value, what: str) -> float:
    """``value`` as a finite float, or a ValueError starting with ``what``."""
    if isinstance(value, bool):
        raise ValueError(f"{what} is not a number")
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{what} is not a number") from None
    if not math.isfinite(number):
        raise ValueError(f"{what} is not a finite number")
    return number



def _shown(values) -> str:
    """Numbers as ``(0, 1.5, inf)`` for messages."""
    try:
        return "(" + ", ".join(f"{float(v):g}" for v in values) + ")"
    except (TypeError, ValueError):
        return repr(values)
