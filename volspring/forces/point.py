"""Point fields: attractors, repulsers and vortices, mass-proportional (f_i = m_i a(x_i)).

Masses are read from the model at every evaluation (``masses=`` overrides them).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from volspring.forces._checks import (MassProportional, block_diagonal, finite, flag, masses_or_none,
                                      radial_blocks, vector)
from volspring.forces.protocol import legacy_positional
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from scipy import sparse
    from volspring.model import Model

__all__ = ["POINT_FALLOFFS", "PointAttractor", "PointRepulser", "Vortex"]

POINT_FALLOFFS = ("inverse_square", "linear")


# ---------------------------------------------------------------------------- point fields
@legacy_positional("masses", "centre", "strength")
@dataclass(frozen=True, eq=False, kw_only=True)
class PointAttractor(MassProportional):
    """A pull of every node towards a centre c, mass-proportional, with a falloff.

    With d = c - x_i, r = |d|, and S = ``strength`` (``sign`` = +1 here, -1 for
    :class:`PointRepulser`):

    ``falloff="inverse_square"`` (Plummer softening, R = ``radius``)
        f_i = sign S m_i d / (r^2 + R^2)^(3/2), S in [m^3/s^2] (like G M);
        potential U_i = -sign S m_i / sqrt(r^2 + R^2). R keeps the force finite at the centre
        (its largest magnitude, 2 S / (3 sqrt(3) R^2), is at r = R / sqrt(2)).
    ``falloff="linear"``
        f_i = sign S m_i (1 - r/R) d / r for r < R, 0 beyond, S in [m/s^2] (the acceleration
        at the centre); potential U_i = -sign S m_i (R - r)^2 / (2 R) for r < R, 0 beyond. The
        direction is undefined at r = 0, where the force is set to 0.

    Parameters
    ----------
    centre : (3,) float
        the centre c [m]
    strength : float
        S >= 0, units above
    falloff : {"inverse_square", "linear"}
    radius : float
        R > 0 [m]: softening length or range, see above
    clamp_jacobian : bool
        clamp the Jacobian's eigenvalues at 0 (default True)
    masses : (n,) float, optional
        node masses [kg] instead of the model's

    Notes
    -----
    The Jacobian dF/dx is block diagonal, each block ``m_i (a_r r r^T + a_t (I - r r^T))``. Its
    eigenvalues a_r, a_t are positive in some direction whatever the sign (tidal stretching
    for an attractor, sideways spreading for a repulser), which would make the implicit
    integrator's matrix M - h^2 dF/dx indefinite at large steps. As with the springs' transverse
    term under compression, those eigenvalues are clamped at 0 by default: the implicit integrator
    then treats the stabilising part implicitly and the rest explicitly. ``clamp_jacobian=False``
    gives the exact derivative.

    Examples
    --------
    >>> import numpy as np
    >>> from volspring import Model, PointAttractor
    >>> one = Model.from_arrays([[1.0, 0, 0]], [2.0], [], stiffness=1.0)
    >>> pull = PointAttractor(centre=(0, 0, 0), strength=8.0, falloff="linear", radius=2.0)
    >>> out = np.zeros((1, 3))
    >>> pull.accumulate(one, one.rest_positions, None, 0.0, out)
    >>> out.tolist()  # 2 kg * 8 m/s^2 * (1 - 1/2) towards the centre
    [[-8.0, 0.0, 0.0]]
    """

    centre: np.ndarray
    strength: float
    falloff: str = "inverse_square"
    radius: float
    clamp_jacobian: bool = True
    masses: np.ndarray | None = None

    sign = 1.0  # a class constant, not a field: -1 for PointRepulser

    def __post_init__(self):
        if not isinstance(self.falloff, str) or self.falloff not in POINT_FALLOFFS:
            raise ValueError(f"falloff = {self.falloff!r} is not one of {', '.join(POINT_FALLOFFS)}")
        object.__setattr__(self, "masses", masses_or_none(self.masses))
        object.__setattr__(self, "centre", vector("centre", self.centre))
        object.__setattr__(self, "strength", finite("strength", self.strength, nonnegative=True))
        object.__setattr__(self, "radius", finite("radius", self.radius, positive=True))
        object.__setattr__(self, "clamp_jacobian", flag("clamp_jacobian", self.clamp_jacobian))

    def _geometry(self, x):
        d = self.centre - x
        r = np.sqrt(np.einsum("ij,ij->i", d, d))
        return d, r

    def accelerations(self, x: np.ndarray) -> np.ndarray:
        """(n, 3) float -- the field's acceleration at positions x (n, 3) [m/s^2]."""
        d, r = self._geometry(x)
        S, R = self.sign * self.strength, self.radius
        if self.falloff == "inverse_square":
            scale = S / (r * r + R * R) ** 1.5
        else:
            inside = (r < R) & (r > 0)
            scale = np.zeros_like(r)
            scale[inside] = S * (1.0 / r[inside] - 1.0 / R)
        return scale[:, None] * d

    def accumulate(self, model: Model, x: np.ndarray, v: np.ndarray | None, t: float, out: np.ndarray) -> None:
        out += self.masses_of(model)[:, None] * self.accelerations(x)

    def potential_energy(self, model: Model, x: np.ndarray, t: float) -> float:
        _, r = self._geometry(x)
        S, R = self.sign * self.strength, self.radius
        if self.falloff == "inverse_square":
            per_mass = -S / np.sqrt(r * r + R * R)
        else:
            per_mass = -S * np.maximum(R - r, 0.0) ** 2 / (2.0 * R)
        return float(np.dot(self.masses_of(model), per_mass))

    def jacobian(self, model: Model, x: np.ndarray, v: np.ndarray, t: float) -> tuple[sparse.spmatrix, None]:
        d, r = self._geometry(x)
        S, R = self.sign * self.strength, self.radius
        safe = np.where(r > 0, r, 1.0)
        direction = d / safe[:, None]  # any unit vector would do at r = 0 (blocks are isotropic there)
        if self.falloff == "inverse_square":
            s2 = r * r + R * R
            transverse = -S / s2**1.5                      # d a / d x across the radius
            radial = S * (3.0 * r * r / s2 - 1.0) / s2**1.5  # d a / d x along it
        else:
            inside = (r < R) & (r > 0)
            transverse = np.where(inside, -S * (1.0 / safe - 1.0 / R), 0.0)
            radial = np.where(inside, S / R, 0.0)
        if self.clamp_jacobian:
            radial, transverse = np.minimum(radial, 0.0), np.minimum(transverse, 0.0)
        blocks = radial_blocks(direction, radial, transverse) * self.masses_of(model)[:, None, None]
        return block_diagonal(blocks), None


class PointRepulser(PointAttractor):
    """A push of every node away from a centre: :class:`PointAttractor` with the opposite sign.

    Same parameters, formulas and units as :class:`PointAttractor` with ``sign = -1``:
    ``f_i = -S m_i d / (r^2 + R^2)^(3/2)`` for the inverse square falloff, d = c - x_i.

    Examples
    --------
    >>> import numpy as np
    >>> from volspring import Model, PointRepulser
    >>> one = Model.from_arrays([[0, 0.5, 0]], [1.0], [], stiffness=1.0)
    >>> push = PointRepulser(centre=(0, 0, 0), strength=4.0, falloff="linear", radius=1.0)
    >>> out = np.zeros((1, 3))
    >>> push.accumulate(one, one.rest_positions, None, 0.0, out)
    >>> out.tolist()
    [[0.0, 2.0, 0.0]]
    """

    sign = -1.0


# ---------------------------------------------------------------------------- vortex
@legacy_positional("masses", "point", "axis", "strength")
@dataclass(frozen=True, eq=False, kw_only=True)
class Vortex(MassProportional):
    """A swirl around an axis: a tangential force, mass-proportional.

    With the axis through p along the unit vector a, the offset from the axis
    rho_i = (x_i - p) - ((x_i - p) . a) a, rho = |rho_i|, and S = ``strength``, R = ``radius``:

        f_i = m_i S (2 R / (rho^2 + R^2)) (a x (x_i - p)),

    tangential (counter-clockwise about a for S > 0), of magnitude m_i S 2 R rho / (rho^2 + R^2):
    0 on the axis, growing linearly near it like a rigid rotation, largest (m_i S) at rho = R, and
    falling off as 1/rho far away like a free vortex. S [m/s^2] is that peak acceleration.

    Parameters
    ----------
    point : (3,) float
        a point p on the axis [m]
    axis : (3,) float
        axis direction a [-], normalised here
    strength : float
        S [m/s^2], signed: negative turns clockwise about a
    radius : float
        R > 0 [m], the core radius
    masses : (n,) float, optional
        node masses [kg] instead of the model's

    Notes
    -----
    A force, not a flow: without drag a body in a vortex keeps spinning up. The field has no
    potential (its curl is not zero) and no ``jacobian``: dF/dx is not symmetric, so an
    implicit integrator treats the vortex explicitly.

    Examples
    --------
    >>> import numpy as np
    >>> from volspring import Model, Vortex
    >>> one = Model.from_arrays([[1.0, 0, 5.0]], [1.0], [], stiffness=1.0)
    >>> swirl = Vortex(point=(0, 0, 0), axis=(0, 0, 1), strength=3.0, radius=1.0)
    >>> out = np.zeros((1, 3))
    >>> swirl.accumulate(one, one.rest_positions, None, 0.0, out)
    >>> out.tolist()  # at rho = R: magnitude m S, along a x rho = +y
    [[0.0, 3.0, 0.0]]
    """

    point: np.ndarray
    axis: np.ndarray
    strength: float
    radius: float
    masses: np.ndarray | None = None

    def __post_init__(self):
        object.__setattr__(self, "masses", masses_or_none(self.masses))
        object.__setattr__(self, "point", vector("point", self.point))
        object.__setattr__(self, "axis", vector("axis", self.axis, unit=True))
        object.__setattr__(self, "strength", finite("strength", self.strength))
        object.__setattr__(self, "radius", finite("radius", self.radius, positive=True))

    def accelerations(self, x: np.ndarray) -> np.ndarray:
        """(n, 3) float -- the field's acceleration at positions x (n, 3) [m/s^2]."""
        offset = x - self.point
        swirl = np.cross(self.axis, offset)  # a x (x - p) = a x rho, |a x rho| = rho
        rho2 = np.einsum("ij,ij->i", swirl, swirl)
        return (self.strength * 2.0 * self.radius / (rho2 + self.radius**2))[:, None] * swirl

    def accumulate(self, model: Model, x: np.ndarray, v: np.ndarray | None, t: float, out: np.ndarray) -> None:
        out += self.masses_of(model)[:, None] * self.accelerations(x)
