"""The region types: :class:`Box`, :class:`HalfSpace` and :class:`Face`, and what they share (:class:`Region`).

A region picks nodes by their rest position: ``region.nodes(points)`` (or ``region(points)``) is the
(n,) bool mask of the (n, 3) points [m] inside it, its boundary included up to a slack. The table of
the types, their text form and the slack rule are in :mod:`volspring.regions`, the path callers import
them from; the checks of their fields are :mod:`volspring.region_checks`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from meshing.tolerances import ON_SURFACE
from volspring.region_checks import AXES, _bound, _check_tolerance, _finite, _shown, _vector, as_points, axis_index
from typing import Any

__all__ = ["FACE_NAMES", "Box", "Face", "HalfSpace", "Region"]

#: The faces of a bounding box by name, as :class:`Face` and :func:`~volspring.regions.parse_region` take them.
FACE_NAMES = tuple(axis + side for axis in AXES for side in ("min", "max"))


class Region:
    """What the region types share: the mask of the points inside, with a slack on every side.

    A subclass implements ``_select(points, slack) -> (n,) bool`` on checked points and holds a
    ``tolerance`` field ([m], or None for the default slack).
    """

    tolerance: float | None

    def nodes(self, points: np.ndarray) -> np.ndarray:
        """Which points lie in the region, its boundary included up to the slack.

        Parameters
        ----------
        points : (n, 3) float
            Positions [m], finite.

        Returns
        -------
        (n,) bool
            True for the points inside.

        Raises
        ------
        ValueError
            For points that are not (n, 3) finite numbers, naming the shape or the first bad point.
        """
        points = as_points(points)
        return self._select(points, self.slack(points))

    def __call__(self, points: np.ndarray) -> np.ndarray:
        """The same as :meth:`nodes`: regions are callables on (n, 3) points."""
        return self.nodes(points)

    def slack(self, points: np.ndarray) -> float:
        """The slack [m] on every side for these (n, 3) points: ``tolerance``, or by default
        :data:`~meshing.tolerances.ON_SURFACE` times the diagonal of their bounding box (0 for no point)."""
        if self.tolerance is not None:
            return self.tolerance
        return ON_SURFACE * float(np.linalg.norm(np.ptp(points, axis=0))) if len(points) else 0.0

    def _select(self, points: np.ndarray, slack: float) -> np.ndarray:
        raise NotImplementedError


@dataclass(frozen=True)
class Box(Region):
    """An axis-aligned box, faces included; a side may be open.

    Parameters
    ----------
    lower, upper : (3,) float or None
        Corners [m]. An entry None (or -inf in ``lower``, +inf in ``upper``) leaves that side open,
        and None for a whole corner leaves all three; stored as tuples of floats. ``lower <= upper``
        on every axis.
    tolerance : float, optional
        Slack on every side [m], >= 0 (keyword-only); default: see :meth:`Region.slack`.

    Raises
    ------
    ValueError
        For a corner without three entries, an entry that is not a number or is NaN, an infinite
        bound on the wrong side, or lower > upper, naming the entry.

    Examples
    --------
    >>> Box((0, 0, 0), (1, 1, None)).nodes([[0.5, 0.5, 7.0], [1.5, 0.5, 0.0]])
    array([ True, False])
    >>> Box.plane("x", 0.0)
    Box(lower=(0.0, -inf, -inf), upper=(0.0, inf, inf), tolerance=None)
    """

    lower: tuple = (-math.inf, -math.inf, -math.inf)
    upper: tuple = (math.inf, math.inf, math.inf)
    tolerance: float | None = field(default=None, kw_only=True)

    def __post_init__(self):
        lower = _bound(self.lower, "lower", -math.inf)
        upper = _bound(self.upper, "upper", math.inf)
        for axis, (low, high) in enumerate(zip(lower, upper)):
            if low > high:
                name = AXES[axis]
                raise ValueError(f"{name}min > {name}max ({low:g} > {high:g} m): a Box needs lower <= upper on "
                                 f"every axis, got lower = {_shown(lower)}, upper = {_shown(upper)}")
        object.__setattr__(self, "lower", lower)
        object.__setattr__(self, "upper", upper)
        _check_tolerance(self.tolerance)

    @classmethod
    def plane(cls, axis: int | str, value: float, **options: Any) -> "Box":
        """The plane ``axis = value`` [m], a box flat along ``axis`` and open along the others;
        e.g. ``Box.plane("x", 0.0)`` for the end face x = 0 of a beam. ``options`` go to :class:`Box`."""
        index = axis_index(axis)
        lower, upper = [-math.inf] * 3, [math.inf] * 3
        lower[index] = upper[index] = _finite(value, f"Box.plane value = {value!r}")
        return cls(tuple(lower), tuple(upper), **options)

    def _select(self, points, slack):
        lower, upper = np.array(self.lower), np.array(self.upper)
        return ((points >= lower - slack) & (points <= upper + slack)).all(axis=1)


@dataclass(frozen=True)
class HalfSpace(Region):
    """The points on one side of a plane: ``(p - point) . normal <= 0``, the plane included.

    Parameters
    ----------
    point : (3,) float
        A point on the plane [m].
    normal : (3,) float
        Normal of the plane, pointing out of the region [-]; normalised here, so the slack is a
        distance.
    tolerance : float, optional
        Slack [m], >= 0 (keyword-only); default: see :meth:`Region.slack`.

    Raises
    ------
    ValueError
        For a point or normal that is not three finite numbers, or a zero normal.

    Examples
    --------
    >>> HalfSpace((0, 0, 1), (1, 0, 1)).nodes([[0, 0, 0], [0, 0, 2], [1, 0, 0]])   # x + z <= 1
    array([ True, False,  True])
    """

    point: tuple
    normal: tuple
    tolerance: float | None = field(default=None, kw_only=True)

    def __post_init__(self):
        point = _vector(self.point, "HalfSpace point")
        normal = np.array(_vector(self.normal, "HalfSpace normal"))
        length = float(np.linalg.norm(normal))
        if not length > 0.0:
            raise ValueError(f"HalfSpace normal = {_shown(self.normal)} is zero; expected a direction")
        object.__setattr__(self, "point", point)
        object.__setattr__(self, "normal", tuple(float(c) + 0.0 for c in normal / length))  # + 0.0: no -0.0
        _check_tolerance(self.tolerance)

    def _select(self, points, slack):
        return (points - np.array(self.point)) @ np.array(self.normal) <= slack


@dataclass(frozen=True)
class Face(Region):
    """The points on one face of their own bounding box, e.g. the lowest in x for ``Face("x", "min")``.

    The face is found at each call, from the points given: the same Face picks the bottom of any mesh.

    Parameters
    ----------
    axis : {"x", "y", "z"} or {0, 1, 2}
        The axis across the face; stored as its name.
    side : {"min", "max"}
        The face with the smallest or the largest coordinate.
    tolerance : float, optional
        Slack [m], >= 0 (keyword-only); default: see :meth:`Region.slack`.

    Raises
    ------
    ValueError
        For an unknown axis or side, naming it.

    Examples
    --------
    >>> Face("z", "min").nodes([[0, 0, 1.0], [1, 0, -2.0], [2, 0, -2.0]])
    array([False,  True,  True])
    """

    axis: str
    side: str
    tolerance: float | None = field(default=None, kw_only=True)

    def __post_init__(self):
        object.__setattr__(self, "axis", AXES[axis_index(self.axis)])
        if self.side not in ("min", "max"):
            raise ValueError(f"Face side = {self.side!r} is not 'min' or 'max'")
        _check_tolerance(self.tolerance)

    @property
    def name(self) -> str:
        """The face's name, one of :data:`FACE_NAMES` (``"xmin"``, ...)."""
        return self.axis + self.side

    def _select(self, points, slack):
        values = points[:, AXES.index(self.axis)]
        if not len(values):
            return np.zeros(0, dtype=bool)
        if self.side == "min":
            return values <= values.min() + slack
        return values >= values.max() - slack
