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

The region types are :mod:`volspring.region_types`, the text form :mod:`volspring.region_text` and
the checks of their input :mod:`volspring.region_checks`; callers import them all from here.

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

from volspring.region_checks import AXES, as_points, axis_index  # noqa: F401  (as_points, axis_index: helpers)
from volspring.region_text import describe_bounds, parse_region
from volspring.region_types import FACE_NAMES, Box, Face, HalfSpace, Region

__all__ = ["AXES", "FACE_NAMES", "Box", "Face", "HalfSpace", "Region", "describe_bounds", "parse_region"]
