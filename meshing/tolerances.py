"""Every geometric tolerance of meshing and of volspring's collision geometry, once, with where its number comes from.

All of them are relative: a length, area or volume is compared with a power of a length scale of the same
objects (a tet's extent, the lengths of the vectors involved), never with an absolute number of metres, so
the same rules hold for a bunny drawn in millimetres and for one in metres. The round-off they guard
against is float64's unit round-off, about 1.1e-16 relative per operation.

=========================  ============  ==========================================================
name                       value         rule
=========================  ============  ==========================================================
``ZERO_VOLUME``            1e-12         a tet is flat when ``|V| <= ZERO_VOLUME * l^3``
``PARALLEL``               1e-12         a segment is parallel to a triangle's plane when
                                         ``|det[d, e1, e2]| <= PARALLEL * |d| |e1| |e2|``
``CANCELLED``              1e-12         a sum of vectors has cancelled when it is shorter than
                                         ``CANCELLED`` times the sum of their lengths
``ON_SURFACE``             1e-9          a point within ``ON_SURFACE`` of a length scale of a surface
                                         is on it (barycentric slack, distances to surfaces)
``SAME_PLANE_COSINE``      1e-9          unit normals with ``n1 . n2 > 1 - SAME_PLANE_COSINE`` are
                                         those of one plane
``ORTHONORMAL``            1e-9          a rotation matrix is orthonormal when ``|R^T R - I|`` is
                                         below this
``CONTACT_NUDGE``          1e-6          how far (relative to a pair of faces) bodies are moved to
                                         decide exact contacts between surfaces
``LARGEST_COORDINATE``     ~2.8e102 m    coordinates whose cubes stay finite in float64
``SMALLEST_EXTENT``        ~2.8e-99 m    extents whose ``ZERO_VOLUME * l^3`` stays a normal float64
=========================  ============  ==========================================================

Examples
--------
The flat-tet rule on a tet whose apex lies 1e-13 above its base, in a body 1 m across:

>>> import numpy as np
>>> from meshing.geometry import signed_tet_volumes
>>> from meshing.tolerances import ZERO_VOLUME
>>> corners = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0.5, 0.5, 1e-13]])
>>> volume = signed_tet_volumes(corners, np.array([[0, 1, 2, 3]]))[0]
>>> bool(abs(volume) <= ZERO_VOLUME * 1.0**3)
True
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "CANCELLED",
    "CONTACT_NUDGE",
    "LARGEST_COORDINATE",
    "ON_SURFACE",
    "ORTHONORMAL",
    "PARALLEL",
    "SAME_PLANE_COSINE",
    "SMALLEST_EXTENT",
    "ZERO_VOLUME",
]

#: A tet (or four points) with ``|V| <= ZERO_VOLUME * l^3``, ``l`` its largest coordinate extent, is flat:
#: the round-off of a determinant of edges of length ``l`` is ~1e-16 l^3, so 1e-12 leaves four orders of
#: margin. At that flatness the barycentric map is conditioned ~l^3 / |V| = 1e12, which turns round-off
#: into weight errors of ~1e-4: no inside test on a flatter tet means anything. The one rule for TetMesh's
#: refusal, quality checks, tetrahedralize's sliver removal, coplanarity of surface faces (four points are
#: coplanar exactly when the tet they span is flat) and the barycentric frames of collision detection (which
#: used ``|det| <= 1e-14 s^3``, s the largest edge component, i.e. ``|V| <= 1.7e-15 s^3`` with ``s <= l``:
#: the same round-off argument with a margin nothing needed; the TetMesh rule was kept).
ZERO_VOLUME = 1e-12

#: A segment ``d`` is parallel to a triangle with edges ``e1, e2`` when ``|det[d, e1, e2]|`` (a product of
#: lengths times two sines) is below this fraction of ``|d| |e1| |e2|``: round-off is ~1e-16 of that product,
#: the same four orders of margin as :data:`ZERO_VOLUME`.
PARALLEL = 1e-12

#: A sum of vectors shorter than this fraction of the sum of their lengths has cancelled: its direction is
#: round-off (a boundary vertex whose face normals cancel has no normal; unit vectors summed to nothing have
#: no direction). Round-off of a sum of k terms is ~k 1e-16 of their lengths; 1e-12 leaves the usual margin.
CANCELLED = 1e-12

#: A point closer to a surface than this fraction of the local length scale is on it. In barycentric weights
#: (distance to a face over the tet's height) it is the slack of every inside test: a point on a face shared by
#: two tets, or on an edge shared by two triangles, must be found in at least one despite round-off, which is
#: ~1e-16 times the condition number of the tet's barycentric map (up to ~1e4 for the poorest tets a mesher
#: keeps), so ~1e-12. 1e-9 is far above that and far below any meaningful fraction of an element. Also the
#: distance (over the mean edge length) below which a point counts as on a surface in penetration depths.
#: It replaces two numbers for the same rule: 1e-10 for segment-triangle hits and 0 (no slack) in collision
#: detection, where a vertex on a face shared by two tets could be missed by both.
ON_SURFACE = 1e-9

#: Unit normals whose dot product exceeds ``1 - SAME_PLANE_COSINE`` belong to one plane (angle below
#: sqrt(2e-9) ~ 4.5e-5 rad): normals of faces of one flat facet agree to round-off (~1e-16), while the
#: facets of a tessellated curved surface differ by far more than 1e-4 rad.
SAME_PLANE_COSINE = 1e-9

#: A rotation matrix is orthonormal when ``max |R^T R - I|`` is below this: round-off of a computed one is
#: ~1e-16, and 1e-9 still accepts a matrix stored with 10 significant digits.
ORTHONORMAL = 1e-9

#: How far bodies are moved, relative to the size of a pair of faces, to decide exact contacts between
#: surfaces: far above the coplanar rule (1e-6 l moves a signed volume by ~1e-6 l^3 >> ZERO_VOLUME l^3),
#: far below any feature a surface meant for meshing has.
CONTACT_NUDGE = 1e-6

#: Coordinates up to about this size [m] keep tet volumes (cubes of edge lengths, up to twice the
#: coordinates) below float64's largest number, 1.8e308: the cube root of that, halved.
LARGEST_COORDINATE = float(np.cbrt(np.finfo(np.float64).max) / 2)

#: A mesh must be at least this large across [m] for the zero-volume test (``ZERO_VOLUME * l^3``) not to
#: underflow below float64's smallest normal number.
SMALLEST_EXTENT = float(np.cbrt(np.finfo(np.float64).tiny / ZERO_VOLUME))
