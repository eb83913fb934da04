"""Tet kernels: signed volumes, and the barycentric frames that locate points in tets.

- :func:`signed_volumes` of point quadruples, :func:`signed_tet_volumes` of a mesh's tets: the sign is the
  orientation convention of :class:`meshing.TetMesh`.
- :func:`barycentric_frames` precomputes, per tet, the map from a point to its four weights
  (:class:`BarycentricFrames`); :meth:`BarycentricFrames.contains` is the one inside test of anchoring and
  collision detection.

Re-exported by :mod:`meshing.geometry`, the path callers import them from; the tolerances are
:mod:`meshing.tolerances`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from meshing.tolerances import ON_SURFACE, ZERO_VOLUME
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

__all__ = ["BarycentricFrames", "barycentric_frames", "signed_tet_volumes", "signed_volumes"]


def signed_volumes(a: np.ndarray, b: np.ndarray, c: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Signed volume of the tet (a, b, c, d) for each row.

    Parameters
    ----------
    a, b, c, d : (k, 3) float
        The four corners [m].

    Returns
    -------
    (k,) float
        ``det[b - a, c - a, d - a] / 6`` [m^3]: positive when d lies on the side of the plane abc that its
        right-hand normal points to.

    Examples
    --------
    >>> import numpy as np
    >>> o, x, y, z = np.zeros((1, 3)), np.array([[1., 0, 0]]), np.array([[0., 1, 0]]), np.array([[0., 0, 1]])
    >>> signed_volumes(o, x, y, z) * 6, signed_volumes(o, y, x, z) * 6
    (array([1.]), array([-1.]))
    """
    return np.einsum("ij,ij->i", b - a, np.cross(c - a, d - a)) / 6.0


def signed_tet_volumes(points: ArrayLike, tets: ArrayLike) -> np.ndarray:
    """Signed volume of each tet of a mesh.

    Parameters
    ----------
    points : (n, 3) float
        Node positions [m].
    tets : (m, 4) int
        Node indices of each tet.

    Returns
    -------
    (m,) float
        ``det[x1 - x0, x2 - x0, x3 - x0] / 6`` [m^3]; positive for a positively oriented tet.

    Examples
    --------
    >>> import numpy as np
    >>> corners = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    >>> signed_tet_volumes(corners, np.array([[0, 1, 2, 3], [0, 2, 1, 3]])) * 6
    array([ 1., -1.])
    """
    x = np.asarray(points)[np.asarray(tets)]
    return signed_volumes(x[:, 0], x[:, 1], x[:, 2], x[:, 3])


@dataclass(frozen=True, eq=False)
class BarycentricFrames:
    """Per tet, the affine map from a point to its barycentric weights (built by :func:`barycentric_frames`).

    The weights of point p in tet t are ``(1 - sum(beta), beta)`` with ``beta = inverse[t] @ (p - origin[t])``.

    Parameters
    ----------
    inverse : (m, 3, 3) float
        ``A^-1`` for ``A = [x1 - x0, x2 - x0, x3 - x0]`` (edges as columns) [1/m]; zero for flat tets.
    origin : (m, 3) float
        ``x0`` of each tet [m].
    flat : (m,) bool
        Tets with ``|V| <= ZERO_VOLUME * l^3`` (:data:`meshing.tolerances.ZERO_VOLUME`), which contain nothing.
    """

    inverse: np.ndarray
    origin: np.ndarray
    flat: np.ndarray

    def weights(self, points: np.ndarray, tets: np.ndarray) -> np.ndarray:
        """(q, 4) float -- weights of ``points[i]`` ((q, 3) [m]) in tet ``tets[i]`` ((q,) int), extrapolated outside.

        Each row sums to 1 and reproduces the point: ``sum_j w_j x_j = p`` (to round-off) for a tet that is not flat.
        """
        beta = np.einsum("qij,qj->qi", self.inverse[tets], points - self.origin[tets])
        return np.concatenate([1.0 - beta.sum(axis=1, keepdims=True), beta], axis=1)

    def contains(self, points: np.ndarray, tets: np.ndarray, *,
                 tolerance: float = ON_SURFACE) -> tuple[np.ndarray, np.ndarray]:
        """Whether ``points[i]`` lies in tet ``tets[i]``: all four weights ``>= -tolerance`` and the tet not flat.

        Parameters
        ----------
        points : (q, 3) float
            Points [m].
        tets : (q,) int
            Index of the tet each point is tested against.
        tolerance : float
            Barycentric slack, so that a point on a face shared by two tets is found in at least one despite
            round-off (default :data:`meshing.tolerances.ON_SURFACE`).

        Returns
        -------
        inside : (q,) bool
        weights : (q, 4) float
            As :meth:`weights`.
        """
        weights = self.weights(points, tets)
        floor = -tolerance
        # Column by column: several times faster than weights.min(axis=1) over rows of four.
        inside = ~self.flat[tets] & (weights[:, 0] >= floor) & (weights[:, 1] >= floor)
        inside &= (weights[:, 2] >= floor) & (weights[:, 3] >= floor)
        return inside, weights


def barycentric_frames(corners: ArrayLike) -> BarycentricFrames:
    """The barycentric maps of a set of tets, by the adjugate of their edge matrices.

    Parameters
    ----------
    corners : (m, 4, 3) float
        The corners of each tet [m], e.g. ``points[tets]``; any orientation, flat tets allowed (a deformed
        mesh may hold some): they get zero maps and ``flat = True``.

    Returns
    -------
    BarycentricFrames

    Examples
    --------
    >>> import numpy as np
    >>> corners = np.array([[[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]])
    >>> frames = barycentric_frames(corners)
    >>> frames.weights(np.array([[0.25, 0.25, 0.25], [1.0, 0.0, 0.0]]), np.array([0, 0]))
    array([[0.25, 0.25, 0.25, 0.25],
           [0.  , 1.  , 0.  , 0.  ]])
    >>> frames.contains(np.array([[0.5, 0.5, 0.5]]), np.array([0]))[0]   # beyond the face x + y + z = 1
    array([False])
    """
    corners = np.asarray(corners, dtype=np.float64)
    origin = corners[:, 0]
    a, b, c = corners[:, 1] - origin, corners[:, 2] - origin, corners[:, 3] - origin
    adjugate = np.stack([np.cross(b, c), np.cross(c, a), np.cross(a, b)], axis=1)  # rows of det * A^-1
    det = np.einsum("ij,ij->i", a, adjugate[:, 0])
    extent = (corners.max(axis=1) - corners.min(axis=1)).max(axis=1)
    flat = np.abs(det) / 6.0 <= ZERO_VOLUME * extent**3
    inverse = np.where(flat[:, None, None], 0.0, adjugate / np.where(flat, 1.0, det)[:, None, None])
    return BarycentricFrames(inverse, origin, flat)
