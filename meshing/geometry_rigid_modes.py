"""The six infinitesimal rigid motions of a set of points: the null space of a free elastic body's stiffness.

:func:`rigid_body_modes` is the near-null space smoothed aggregation needs (the implicit integrator's
and the statics' AMG, the FEM reference) and the set of motions a support must hold. Re-exported by
:mod:`meshing.geometry`, the path callers import it from.
"""

from __future__ import annotations

import numpy as np
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

__all__ = ["rigid_body_modes"]


def rigid_body_modes(points: ArrayLike, *, components: ArrayLike | None = None, centre: ArrayLike | None = None,
                     scale: float | None = None) -> np.ndarray:
    """The six infinitesimal rigid motions (translations, rotations) of a set of points, as displacement columns.

    Columns: unit translations along x, y, z, then rotations ``e_axis x (p - centre) / scale`` about x, y, z
    through ``centre``. Dividing by a length of the body's size gives all six columns comparable norms (the
    near-null space ``B`` handed to smoothed aggregation; the modes a support must hold).

    Parameters
    ----------
    points : (p, 3) float
        Positions [m]: of the nodes (``components=None``) or of each degree of freedom.
    components : (p,) int, optional
        The displacement component (0, 1, 2 for x, y, z) each row of ``points`` is a degree of freedom of.
        By default every point has all three, in node order (rows ``3 k, 3 k + 1, 3 k + 2`` for point k).
    centre : (3,) float, optional
        The point the rotations turn about [m]; default the mean of ``points``.
    scale : float, optional
        The length the rotations are divided by [m]; default the root-mean-square distance of the points
        from ``centre`` (1 if that is 0).

    Returns
    -------
    (3p, 6) float, or (p, 6) float with ``components``
        Dimensionless.

    Raises
    ------
    ValueError
        For points not of shape (p, 3), components not of shape (p,) or outside {0, 1, 2}, or a scale not > 0.

    Examples
    --------
    >>> import numpy as np
    >>> modes = rigid_body_modes(np.array([[1., 0, 0], [-1, 0, 0]]))
    >>> modes.shape, modes[:3, 5] + 0.0   # node 0 turns about z through the centre: it moves along +y
    ((6, 6), array([0., 1., 0.]))
    >>> rigid_body_modes(np.array([[1., 0, 0]]), components=[1], centre=np.zeros(3), scale=1.0) + 0.0
    array([[0., 1., 0., 0., 0., 1.]])
    """
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(f"points must have shape (p, 3), got {points.shape}")
    if centre is None:
        centre = points.mean(axis=0) if len(points) else np.zeros(3)
    q = points - np.asarray(centre, dtype=np.float64)
    if scale is None:
        scale = np.sqrt((q * q).sum(axis=1).mean()) if len(q) else 0.0
        scale = scale or 1.0
    if not (np.isfinite(scale) and scale > 0):
        raise ValueError(f"scale = {scale!r} is not a finite length > 0 [m]")
    q = q / scale
    modes = np.zeros((len(points), 3, 6))
    modes[:, [0, 1, 2], [0, 1, 2]] = 1.0
    # omega x q for omega = e_x, e_y, e_z
    modes[:, 1, 3], modes[:, 2, 3] = -q[:, 2], q[:, 1]
    modes[:, 0, 4], modes[:, 2, 4] = q[:, 2], -q[:, 0]
    modes[:, 0, 5], modes[:, 1, 5] = -q[:, 1], q[:, 0]
    if components is None:
        return modes.reshape(-1, 6)
    components = np.asarray(components)
    if components.shape != (len(points),) or not np.isin(components, (0, 1, 2)).all():
        raise ValueError(f"components must be {len(points)} values in {{0, 1, 2}} (one per row of points), got "
                         f"shape {components.shape} with values {np.unique(components)[:6].tolist()}")
    return modes[np.arange(len(points)), components.astype(np.int64)]
