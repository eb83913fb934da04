"""Node regions: where a body is pinned, clamped or loaded, as three types and one text form.

A region picks nodes by their rest position: ``region.nodes(points)`` (or ``region(points)``) is the
(n,) bool mask of the (n, 3) points [m] inside it, its boundary included. The same regions serve
``volspring-sim --pin``, :class:`volspring.Pins` (which takes the mask), the supports and loads of the
validation (:class:`validation.Clamp`, :class:`validation.Traction`) and ``volspring-validate --clamp``.

=========================  ==========================================  ===============================
type                       selects the points p with                   text (:func:`parse_region`)
=========================  ==========================================  ===============================
``Box(lower, upper)``      ``lower <= p <= upper`` on every axis; a    ``x0,y0,z0,x1,y1,z1``,
                           None or infinite bound leaves a side open   ``box:x0,y0,z0,x1,y1,z1``,
                                                                       ``x=V`` (``Box.plane``)
``HalfSpace(point, n)``    ``(p - point) . n <= 0``: the side the      ``x<V``, ``x<=V``, ``z>V``,
                           normal points away from                     ``z>=V`` (any axis)
``Face(axis, side)``       ``p`` on that face of the bounding box of   ``xmin``, ``xmax``, ``ymin``,
                           the points tested                           ``ymax``, ``zmin``, ``zmax``
=========================  ==========================================  ===============================

Every side has a slack, ``tolerance`` [m], so that a side placed on a row of nodes catches them
despite round-off: by default :data:`meshing.tolerances.ON_SURFACE` (1e-9) times the diagonal of the
bounding box of the points tested. For that reason ``x<V`` and ``x<=V`` select the same nodes.
:class:`HalfSpace` uses the sign convention of the obstacle :class:`volspring.HalfSpace`: the
region is the side that obstacle fills.

The text form, case and whitespace ignored, each number finite and in units of ``unit`` metres::

    region := axis ("min" | "max")                        a face of the bounding box
            | axis ("<" | "<=" | ">" | ">=") number        a half-space
            | axis "=" number                             a plane (a flat box)
            | ["box:"] number "," number "," ... number   a box: six numbers x0,y0,z0,x1,y1,z1
    axis   := "x" | "y" | "z"

Examples
--------
>>> import numpy as np
>>> from volspring.regions import Box, Face, HalfSpace, parse_region
>>> points = np.array([[0.0, 0, 0], [0.5, 0, 0], [1.0, 0, 0], [1.0, 1, 0]])
>>> Box((None, None, None), (0.5, None, None)).nodes(points)
array([ True,  True, False, False])
>>> Face("x", "max").nodes(points)
array([False, False,  True,  True])
>>> HalfSpace((0, 0.5, 0), (0, -1, 0)).nodes(points)   # y >= 0.5
array([False, False, False,  True])
>>> parse_region("x > 0.5").nodes(points)
array([False,  True,  True,  True])
>>> parse_region("box:-1,-1,-1,0.5,1,1") == Box((-1, -1, -1), (0.5, 1, 1))
True
>>> parse_region("x<0.2", unit=0.001)   # in millimetres
HalfSpace(point=(0.0002, 0.0, 0.0), normal=(1.0, 0.0, 0.0), tolerance=None)
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field

import numpy as np

from meshing.tolerances import ON_SURFACE

__all__ = ["AXES", "FACE_NAMES", "Box", "Face", "HalfSpace", "Region", "describe_bounds", "parse_region"]

#: The axis names, in coordinate order.
AXES = ("x", "y", "z")
#: The faces of a bounding box by name, as :class:`Face` and :func:`parse_region` take them.
FACE_NAMES = tuple(axis + side for axis in AXES for side in ("min", "max"))


class Region:
    """What the region types share: the mask of the points inside, with a slack on every side.

    A subclass implements ``_select(points, slack) -> (n,) bool`` on checked points and holds a
    ``tolerance`` field ([m], or None for the default slack).
    """

    tolerance: float | None

    def nodes(self, points) -> np.ndarray:
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

    def __call__(self, points) -> np.ndarray:
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
    def plane(cls, axis, value: float, **options) -> "Box":
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


# ---------------------------------------------------------------------- the text form
_FACE = re.compile(r"([xyz])(min|max)")
_SOME_FACE = re.compile(r"(\w*)(min|max)")
_COMPARISON = re.compile(r"([xyz])(<=|>=|<|>|=)(.*)")
_FORMS = ("xmin, xmax, ymin, ymax, zmin, zmax (a face of the bounding box), x<V, x<=V, x>V, x>=V (a half-space), "
          "x=V (a plane), the same with y or z, or x0,y0,z0,x1,y1,z1 or box:x0,y0,z0,x1,y1,z1 (a box)")


def parse_region(text: str, *, unit: float = 1.0, tolerance: float | None = None, label: str = "region") -> Region:
    """The region written as ``text``, in the grammar of the module docstring.

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


def describe_bounds(points) -> str:
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


# ---------------------------------------------------------------------- checks at the edge
def as_points(points) -> np.ndarray:
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


def axis_index(axis) -> int:
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


def _text_number(part: str, unit: float, where: str) -> float:
    """A number of the text form, in metres."""
    try:
        number = float(part)
    except ValueError:
        raise ValueError(f"{where}: {part!r} is not a number") from None
    if not math.isfinite(number * unit):
        raise ValueError(f"{where}: {part!r} is not a finite number")
    return number * unit


def _shown(values) -> str:
    """Numbers as ``(0, 1.5, inf)`` for messages."""
    try:
        return "(" + ", ".join(f"{float(v):g}" for v in values) + ")"
    except (TypeError, ValueError):
        return repr(values)
