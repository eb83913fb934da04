"""Force fields of particle systems: wind, point attractors and repulsers, vortices, user callables.

Each field is a force object of the scene protocol (see :mod:`volspring.scene`): it has
``accumulate(x, v, t, out)`` adding its forces [N], shape (n, 3), into ``out``, and where cheap
and useful ``jacobian(x, v, t) -> (dF_dx, dF_dv)`` and ``potential_energy(x, t)``. A scene pays
only for the fields it names: ``Scene(model, forces=[Gravity(m), Wind(m, ...)])``.

All built-in fields are mass-proportional, ``f_i = m_i a(x_i, v_i, t)``, like :class:`Gravity`:
a field prescribes an acceleration, so a refined mesh of the same body feels the same field per
kilogram and no surface area is needed. Fields are external forces: they do not obey Newton's
third law, and the momentum of a body changes by exactly their impulse (springs add none).

Fields
------
:class:`Wind`
    relative-velocity drag towards the wind velocity w(t), ``f_i = c m_i (w(t) - v_i)``.
:class:`PointAttractor`, :class:`PointRepulser`
    a pull towards (push away from) a centre, falling off as a softened inverse square or linearly
    to zero at a radius.
:class:`Vortex`
    a swirl around an axis, tangential, smooth on the axis and decaying as 1/rho far from it.
:class:`CallableForce`
    a user function ``f(x, v, t) -> (n, 3)`` forces [N], checked for shape and finiteness.

Constructors check their input: a TypeError for what is not numbers (bools, strings), a
ValueError for vectors that are not finite 3-vectors, masses that are not a finite, positive
(n,) array, and parameters that are not finite or out of range, each naming the value. Numpy
scalars (``np.float32(2.0)``) count as numbers. A :class:`~volspring.Scene` checks that the
masses have one entry per node of its model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable

import numpy as np
import scipy.sparse as sp

from volspring.material import _real_array, _real_number, _shown

__all__ = ["Wind", "PointAttractor", "PointRepulser", "Vortex", "CallableForce", "POINT_FALLOFFS"]

POINT_FALLOFFS = ("inverse_square", "linear")


# ---------------------------------------------------------------------------- input checks
# Shared by the forces of volspring.scene (Gravity, Drag): TypeError for what is not numbers at
# all (bools, strings, from volspring.material), ValueError for numbers of the wrong shape or
# range, naming the value.
def _masses(masses, *, allow_zero=False) -> np.ndarray:
    """(n,) float, read-only -- node masses, finite and > 0 (>= 0 with ``allow_zero``) [kg]."""
    masses = _real_array("masses", masses)
    if masses.ndim != 1 or masses.size == 0:
        raise ValueError(f"masses must have shape (n,) with n > 0, got {masses.shape}")
    bad = ~np.isfinite(masses) | (masses < 0) | ((masses == 0) & (not allow_zero))
    if bad.any():
        first = int(np.flatnonzero(bad)[0])
        expected = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"masses[{first}] = {masses[first]} kg is not finite and {expected}")
    masses.setflags(write=False)
    return masses


def _vector(name, value, *, unit=False) -> np.ndarray:
    """(3,) float, read-only -- a finite 3-vector (normalised with ``unit``)."""
    vector = _real_array(name, value)
    if vector.shape != (3,) or not np.isfinite(vector).all():
        raise ValueError(f"{name} = {_shown(value)} is not a finite 3-vector (got shape {vector.shape})")
    if unit:
        norm = np.linalg.norm(vector)
        if norm == 0:
            raise ValueError(f"{name} = {_shown(value)} has zero length; expected a direction")
        vector = vector / norm
    vector.setflags(write=False)
    return vector


def _finite(name, value, *, positive=False, nonnegative=False) -> float:
    """A finite real number (> 0 with ``positive``, >= 0 with ``nonnegative``) as a float."""
    value = _real_number(name, value)
    if positive and not (math.isfinite(value) and value > 0):
        raise ValueError(f"{name} = {value} is not finite and > 0")
    if nonnegative and not (math.isfinite(value) and value >= 0):
        raise ValueError(f"{name} = {value} is not finite and >= 0")
    if not math.isfinite(value):
        raise ValueError(f"{name} = {value} is not a finite number")
    return value


def _flag(name, value) -> bool:
    """A bool (Python or numpy); a TypeError naming ``name`` for anything else ("no" is not False)."""
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} = {_shown(value)} is not a bool")
    return bool(value)


def _block_diagonal(blocks) -> sp.csr_matrix:
    """(3n, 3n) sparse matrix with the (n, 3, 3) blocks on its diagonal."""
    n = len(blocks)
    return sp.bsr_matrix((blocks, np.arange(n), np.arange(n + 1)), shape=(3 * n, 3 * n)).tocsr()


def _radial_blocks(direction, radial, transverse) -> np.ndarray:
    """(n, 3, 3) blocks ``radial r r^T + transverse (I - r r^T)`` for unit directions r (n, 3)."""
    outer = direction[:, :, None] * direction[:, None, :]
    blocks = outer * (radial - transverse)[:, None, None]
    blocks[:, [0, 1, 2], [0, 1, 2]] += transverse[:, None]
    return blocks


# ---------------------------------------------------------------------------- wind
@dataclass(frozen=True, eq=False)
class Wind:
    """Wind as relative-velocity drag: ``f_i = c m_i (w(t) - v_i)``.

    Every node relaxes towards the wind velocity w(t) at the rate c: a free particle reaches the
    wind's speed with time constant 1/c. The wind velocity is

        w(t) = (speed(t) + sum_k A_k sin(2 pi f_k t + phi_k)) * direction,

    a mean speed (a constant, or a callable of t for any gust profile) plus sinusoidal gusts.

    Parameters
    ----------
    masses : (n,) float -- node masses [kg] (``model.masses``)
    direction : (3,) float -- direction the wind blows towards [-], normalised here
    speed : float or callable -- mean wind speed [m/s], or ``speed(t) -> float`` [m/s] at time t [s]
    rate : float -- coupling rate c [1/s], >= 0 (keyword-only)
    gusts : (k, 3) float -- one row (A, f, phi) per gust: amplitude [m/s], frequency [Hz],
        phase [rad] (keyword-only; a single gust is ``[(A, f, phi)]``)

    Notes
    -----
    Jacobian: dF/dx = 0, dF/dv = -c M (diagonal), so an implicit integrator treats the drag part
    implicitly exactly as it treats :class:`~volspring.Drag`. The field is non-conservative (no
    potential energy). Total force on the body: c (M w(t) - P) with M the total mass and P the
    momentum, so a body at rest in a steady wind has P(t) = M w (1 - exp(-c t)).

    Examples
    --------
    >>> import numpy as np
    >>> from volspring.fields import Wind
    >>> wind = Wind([1.0, 2.0], (1, 0, 0), 3.0, rate=0.5, gusts=[(1.0, 0.25, 0.0)])
    >>> out = np.zeros((2, 3))
    >>> wind.accumulate(np.zeros((2, 3)), np.zeros((2, 3)), 1.0, out)
    >>> out[:, 0].tolist()  # c m (3 + sin(pi/2)) = 0.5 * m * 4
    [2.0, 4.0]
    """

    masses: np.ndarray
    direction: np.ndarray
    speed: float | Callable = 0.0
    rate: float = field(kw_only=True)
    gusts: tuple = field(default=(), kw_only=True)

    def __post_init__(self):
        object.__setattr__(self, "masses", _masses(self.masses))
        object.__setattr__(self, "direction", _vector("direction", self.direction, unit=True))
        if not callable(self.speed):
            object.__setattr__(self, "speed", _finite("speed", self.speed))
        object.__setattr__(self, "rate", _finite("rate", self.rate, nonnegative=True))
        gusts = _real_array("gusts", self.gusts)
        if gusts.size == 0:
            gusts = np.zeros((0, 3))
        if gusts.ndim != 2 or gusts.shape[1] != 3:
            raise ValueError(f"gusts = {_shown(self.gusts)} have shape {gusts.shape}; expected (k, 3): "
                             "one (amplitude [m/s], frequency [Hz], phase [rad]) per gust, e.g. [(1.0, 0.5, 0.0)]")
        if not np.isfinite(gusts).all():
            raise ValueError(f"gusts = {_shown(self.gusts)} hold non-finite values")
        gusts.setflags(write=False)
        object.__setattr__(self, "gusts", gusts)

    def wind_speed(self, t) -> float:
        """The wind speed |w(t)| along ``direction`` at time t [m/s] (may be negative)."""
        if callable(self.speed):
            mean = np.asarray(self.speed(t), dtype=np.float64)
            if mean.shape != () or not np.isfinite(mean):
                raise ValueError(f"Wind speed({t}) returned {mean!r}; expected a finite number [m/s]")
            mean = float(mean)
        else:
            mean = self.speed
        if len(self.gusts):
            amplitude, frequency, phase = self.gusts.T
            mean += float(np.sum(amplitude * np.sin(2.0 * np.pi * frequency * t + phase)))
        return mean

    def wind_velocity(self, t) -> np.ndarray:
        """(3,) float -- the wind velocity w(t) [m/s]."""
        return self.wind_speed(t) * self.direction

    def accumulate(self, x, v, t, out):
        out += (self.rate * self.masses)[:, None] * (self.wind_velocity(t) - v)

    def jacobian(self, x, v, t):
        return None, sp.diags(np.repeat(-self.rate * self.masses, 3), format="csr")


# ---------------------------------------------------------------------------- point fields
@dataclass(frozen=True, eq=False)
class PointAttractor:
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
    masses : (n,) float -- node masses [kg] (``model.masses``)
    centre : (3,) float -- the centre c [m]
    strength : float -- S >= 0, units above
    falloff : {"inverse_square", "linear"} (keyword-only)
    radius : float -- R > 0 [m]: softening length or range, see above (keyword-only)
    clamp_jacobian : bool -- clamp the Jacobian's eigenvalues at 0 (keyword-only, default True)

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
    >>> from volspring.fields import PointAttractor
    >>> pull = PointAttractor([2.0], (0, 0, 0), 8.0, falloff="linear", radius=2.0)
    >>> out = np.zeros((1, 3))
    >>> pull.accumulate(np.array([[1.0, 0, 0]]), None, 0.0, out)
    >>> out.tolist()  # 2 kg * 8 m/s^2 * (1 - 1/2) towards the centre
    [[-8.0, 0.0, 0.0]]
    """

    masses: np.ndarray
    centre: np.ndarray
    strength: float
    falloff: str = field(default="inverse_square", kw_only=True)
    radius: float = field(kw_only=True)
    clamp_jacobian: bool = field(default=True, kw_only=True)

    sign = 1.0  # a class constant, not a field: -1 for PointRepulser

    def __post_init__(self):
        if not isinstance(self.falloff, str) or self.falloff not in POINT_FALLOFFS:
            raise ValueError(f"falloff = {self.falloff!r} is not one of {', '.join(POINT_FALLOFFS)}")
        object.__setattr__(self, "masses", _masses(self.masses))
        object.__setattr__(self, "centre", _vector("centre", self.centre))
        object.__setattr__(self, "strength", _finite("strength", self.strength, nonnegative=True))
        object.__setattr__(self, "radius", _finite("radius", self.radius, positive=True))
        object.__setattr__(self, "clamp_jacobian", _flag("clamp_jacobian", self.clamp_jacobian))

    def _geometry(self, x):
        d = self.centre - x
        r = np.sqrt(np.einsum("ij,ij->i", d, d))
        return d, r

    def accelerations(self, x) -> np.ndarray:
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

    def accumulate(self, x, v, t, out):
        out += self.masses[:, None] * self.accelerations(x)

    def potential_energy(self, x, t) -> float:
        _, r = self._geometry(x)
        S, R = self.sign * self.strength, self.radius
        if self.falloff == "inverse_square":
            per_mass = -S / np.sqrt(r * r + R * R)
        else:
            per_mass = -S * np.maximum(R - r, 0.0) ** 2 / (2.0 * R)
        return float(np.dot(self.masses, per_mass))

    def jacobian(self, x, v, t):
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
        blocks = _radial_blocks(direction, radial, transverse) * self.masses[:, None, None]
        return _block_diagonal(blocks), None


class PointRepulser(PointAttractor):
    """A push of every node away from a centre: :class:`PointAttractor` with the opposite sign.

    Same parameters, formulas and units as :class:`PointAttractor` with ``sign = -1``:
    ``f_i = -S m_i d / (r^2 + R^2)^(3/2)`` for the inverse square falloff, d = c - x_i.

    Examples
    --------
    >>> import numpy as np
    >>> from volspring.fields import PointRepulser
    >>> push = PointRepulser([1.0], (0, 0, 0), 4.0, falloff="linear", radius=1.0)
    >>> out = np.zeros((1, 3))
    >>> push.accumulate(np.array([[0, 0.5, 0]]), None, 0.0, out)
    >>> out.tolist()
    [[0.0, 2.0, 0.0]]
    """

    sign = -1.0


# ---------------------------------------------------------------------------- vortex
@dataclass(frozen=True, eq=False)
class Vortex:
    """A swirl around an axis: a tangential force, mass-proportional.

    With the axis through p along the unit vector a, the offset from the axis
    rho_i = (x_i - p) - ((x_i - p) . a) a, rho = |rho_i|, and S = ``strength``, R = ``radius``:

        f_i = m_i S (2 R / (rho^2 + R^2)) (a x (x_i - p)),

    tangential (counter-clockwise about a for S > 0), of magnitude m_i S 2 R rho / (rho^2 + R^2):
    0 on the axis, growing linearly near it like a rigid rotation, largest (m_i S) at rho = R, and
    falling off as 1/rho far away like a free vortex. S [m/s^2] is that peak acceleration.

    Parameters
    ----------
    masses : (n,) float -- node masses [kg] (``model.masses``)
    point : (3,) float -- a point p on the axis [m]
    axis : (3,) float -- axis direction a [-], normalised here
    strength : float -- S [m/s^2], signed: negative turns clockwise about a
    radius : float -- R > 0 [m], the core radius (keyword-only)

    Notes
    -----
    A force, not a flow: without drag a body in a vortex keeps spinning up. The field has no
    potential (its curl is not zero) and no ``jacobian``: dF/dx is not symmetric, so an
    implicit integrator treats the vortex explicitly.

    Examples
    --------
    >>> import numpy as np
    >>> from volspring.fields import Vortex
    >>> swirl = Vortex([1.0], (0, 0, 0), (0, 0, 1), 3.0, radius=1.0)
    >>> out = np.zeros((1, 3))
    >>> swirl.accumulate(np.array([[1.0, 0, 5.0]]), None, 0.0, out)
    >>> out.tolist()  # at rho = R: magnitude m S, along a x rho = +y
    [[0.0, 3.0, 0.0]]
    """

    masses: np.ndarray
    point: np.ndarray
    axis: np.ndarray
    strength: float
    radius: float = field(kw_only=True)

    def __post_init__(self):
        object.__setattr__(self, "masses", _masses(self.masses))
        object.__setattr__(self, "point", _vector("point", self.point))
        object.__setattr__(self, "axis", _vector("axis", self.axis, unit=True))
        object.__setattr__(self, "strength", _finite("strength", self.strength))
        object.__setattr__(self, "radius", _finite("radius", self.radius, positive=True))

    def accelerations(self, x) -> np.ndarray:
        """(n, 3) float -- the field's acceleration at positions x (n, 3) [m/s^2]."""
        offset = x - self.point
        swirl = np.cross(self.axis, offset)  # a x (x - p) = a x rho, |a x rho| = rho
        rho2 = np.einsum("ij,ij->i", swirl, swirl)
        return (self.strength * 2.0 * self.radius / (rho2 + self.radius**2))[:, None] * swirl

    def accumulate(self, x, v, t, out):
        out += self.masses[:, None] * self.accelerations(x)


# ---------------------------------------------------------------------------- user field
class CallableForce:
    """A user field: ``function(x, v, t) -> (n, 3)`` forces [N], checked on every call.

    Parameters
    ----------
    function : callable -- ``function(x, v, t)`` with x, v (n, 3) [m], [m/s] and t [s],
        returning forces [N] of shape (n, 3); it must not modify x or v
    name : str, optional -- used in error messages (defaults to the function's name)

    Raises
    ------
    ValueError
        from :meth:`accumulate` if the function returns another shape or a non-finite value,
        naming the shape, the first bad node and the time.

    Examples
    --------
    >>> import numpy as np
    >>> from volspring.fields import CallableForce
    >>> spring_to_origin = CallableForce(lambda x, v, t: -10.0 * x)
    >>> out = np.zeros((1, 3))
    >>> spring_to_origin.accumulate(np.array([[0.1, 0, 0]]), np.zeros((1, 3)), 0.0, out)
    >>> out.tolist()
    [[-1.0, 0.0, 0.0]]
    """

    def __init__(self, function: Callable, *, name: str | None = None):
        if not callable(function):
            raise TypeError(f"function = {_shown(function)} is not callable; expected f(x, v, t) -> (n, 3) forces")
        if name is not None and not isinstance(name, str):
            raise TypeError(f"name = {_shown(name)} is not a str")
        self.function = function
        self.name = name or getattr(function, "__name__", type(function).__name__)

    def __repr__(self) -> str:
        return f"CallableForce({self.name})"

    def accumulate(self, x, v, t, out):
        value = self.function(x, v, t)
        try:
            forces = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError) as error:
            raise ValueError(f"force field {self.name}(x, v, t={t}) returned {type(value).__name__}, "
                             f"not an (n, 3) array of forces [N]: {error}") from error
        if forces.shape != out.shape:
            raise ValueError(f"force field {self.name}(x, v, t={t}) returned shape {forces.shape}, "
                             f"expected {out.shape} (one 3-vector [N] per node)")
        finite = np.isfinite(forces).all(axis=1)
        if not finite.all():
            node = int(np.flatnonzero(~finite)[0])
            raise ValueError(f"force field {self.name}(x, v, t={t}) returned {forces[node].tolist()} at node {node}; "
                             f"expected finite forces [N] ({(~finite).sum()} node(s) affected)")
        out += forces
