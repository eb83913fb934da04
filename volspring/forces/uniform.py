"""Gravity, drag and wind: forces that act on every node in proportion to its mass.

Mass-proportional, ``f_i = m_i a_i``: a refined mesh of the same body feels the same force per
kilogram and no surface area is needed. External forces: they do not obey Newton's third law,
and the momentum of a body changes by exactly their impulse (the element sets add none).
Masses are read from the model at every evaluation (``masses=`` overrides them, e.g. with 0 to
exempt a node).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Callable

import numpy as np
import scipy.sparse as sp

from volspring.forces._checks import MassProportional, finite, masses_or_none, vector
from volspring.forces.protocol import legacy_positional
from volspring.material import _real_array, _real_number, _shown

if TYPE_CHECKING:
    from scipy import sparse
    from volspring.model import Model

__all__ = ["Drag", "Gravity", "Wind"]


@legacy_positional("masses", "g")
@dataclass(frozen=True, eq=False, kw_only=True)
class Gravity(MassProportional):
    """Uniform gravity f_i = m_i g.

    Parameters
    ----------
    g : (3,) float
        Acceleration [m/s^2], default (0, 0, -9.81); stored as a read-only array.
    masses : (n,) float, optional
        Node masses [kg], finite and >= 0, instead of the model's (a 0 exempts a node).

    Raises
    ------
    TypeError
        Masses or g that are not numbers (bools, strings).
    ValueError
        ``g = (0, 0) is not a finite 3-vector (got shape (2,))``; a negative or non-finite mass.

    Examples
    --------
    >>> import numpy as np
    >>> from volspring import Gravity, Model
    >>> pair = Model.from_arrays([[0, 0, 0], [1, 0, 0]], [1.0, 2.0], [[0, 1]], stiffness=1.0)
    >>> out = np.zeros((2, 3))
    >>> Gravity(g=(0, 0, -10)).accumulate(pair, pair.rest_positions, None, 0.0, out)
    >>> out[:, 2].tolist()
    [-10.0, -20.0]
    """

    g: tuple = (0.0, 0.0, -9.81)
    masses: np.ndarray | None = None

    def __post_init__(self):
        object.__setattr__(self, "masses", masses_or_none(self.masses, allow_zero=True))
        object.__setattr__(self, "g", vector("g", self.g))

    def accumulate(self, model: Model, x: np.ndarray, v: np.ndarray | None, t: float, out: np.ndarray) -> None:
        out += self.masses_of(model)[:, None] * self.g

    def potential_energy(self, model: Model, x: np.ndarray, t: float) -> float:
        return float(-np.dot(self.masses_of(model), x @ self.g))


@legacy_positional("masses", "rate")
@dataclass(frozen=True, eq=False, kw_only=True)
class Drag(MassProportional):
    """Global viscous drag f_i = -c m_i v_i (a mass-proportional damping rate c [1/s]).

    Parameters
    ----------
    rate : float
        Damping rate c [1/s], finite and >= 0.
    masses : (n,) float, optional
        Node masses [kg], finite and >= 0, instead of the model's (a 0 exempts a node).
    """

    rate: float
    masses: np.ndarray | None = None

    def __post_init__(self):
        object.__setattr__(self, "masses", masses_or_none(self.masses, allow_zero=True))
        rate = _real_number("drag rate", self.rate)
        if not (math.isfinite(rate) and rate >= 0):
            raise ValueError(f"drag rate = {rate} 1/s is not finite and >= 0")
        object.__setattr__(self, "rate", rate)

    def accumulate(self, model: Model, x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray) -> None:
        out -= self.rate * self.masses_of(model)[:, None] * v

    def jacobian(self, model: Model, x: np.ndarray, v: np.ndarray, t: float) -> tuple[None, sparse.spmatrix]:
        return None, sp.diags(np.repeat(-self.rate * self.masses_of(model), 3), format="csr")


@legacy_positional("masses", "direction", "speed")
@dataclass(frozen=True, eq=False, kw_only=True)
class Wind(MassProportional):
    """Wind as relative-velocity drag: ``f_i = c m_i (w(t) - v_i)``.

    Every node relaxes towards the wind velocity w(t) at the rate c: a free particle reaches the
    wind's speed with time constant 1/c. The wind velocity is

        w(t) = (speed(t) + sum_k A_k sin(2 pi f_k t + phi_k)) * direction,

    a mean speed (a constant, or a callable of t for any gust profile) plus sinusoidal gusts.

    Parameters
    ----------
    direction : (3,) float
        direction the wind blows towards [-], normalised here
    speed : float or callable
        mean wind speed [m/s], or ``speed(t) -> float`` [m/s] at time t [s]
    rate : float
        coupling rate c [1/s], >= 0
    gusts : (k, 3) float
        one row (A, f, phi) per gust: amplitude [m/s], frequency [Hz], phase [rad] (a single gust is ``[(A, f, phi)]``)
    masses : (n,) float, optional
        node masses [kg] instead of the model's

    Notes
    -----
    Jacobian: dF/dx = 0, dF/dv = -c M (diagonal), so an implicit integrator treats the drag part
    implicitly exactly as it treats :class:`~volspring.Drag`. The field is non-conservative (no
    potential energy). Total force on the body: c (M w(t) - P) with M the total mass and P the
    momentum, so a body at rest in a steady wind has P(t) = M w (1 - exp(-c t)).

    Examples
    --------
    >>> import numpy as np
    >>> from volspring import Model, Wind
    >>> pair = Model.from_arrays([[0, 0, 0], [1, 0, 0]], [1.0, 2.0], [[0, 1]], stiffness=1.0)
    >>> wind = Wind(direction=(1, 0, 0), speed=3.0, rate=0.5, gusts=[(1.0, 0.25, 0.0)])
    >>> out = np.zeros((2, 3))
    >>> wind.accumulate(pair, pair.rest_positions, np.zeros((2, 3)), 1.0, out)
    >>> out[:, 0].tolist()  # c m (3 + sin(pi/2)) = 0.5 * m * 4
    [2.0, 4.0]
    """

    direction: np.ndarray
    speed: float | Callable = 0.0
    rate: float
    gusts: tuple = field(default=())
    masses: np.ndarray | None = None

    def __post_init__(self):
        object.__setattr__(self, "masses", masses_or_none(self.masses))
        object.__setattr__(self, "direction", vector("direction", self.direction, unit=True))
        if not callable(self.speed):
            object.__setattr__(self, "speed", finite("speed", self.speed))
        object.__setattr__(self, "rate", finite("rate", self.rate, nonnegative=True))
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

    def wind_speed(self, t: float) -> float:
        """The wind speed |w(t)| along ``direction`` at time t [m/s] (may be negative)."""
        if callable(self.speed):
            mean = np.asarray(self.speed(t), dtype=np.float64)
            if mean.shape != () or not np.isfinite(mean):
                raise ValueError(f"Wind speed({t}) returned {mean!r}; expected a finite number [m/s]")
            mean = float(mean)
        else:
            mean = self.speed
        if len(self.gusts):
            amplitude, frequency, phase = np.asarray(self.gusts).T  # (k, 3) since __post_init__
            mean += float(np.sum(amplitude * np.sin(2.0 * np.pi * frequency * t + phase)))
        return mean

    def wind_velocity(self, t: float) -> np.ndarray:
        """(3,) float -- the wind velocity w(t) [m/s]."""
        return self.wind_speed(t) * self.direction

    def accumulate(self, model: Model, x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray) -> None:
        out += (self.rate * self.masses_of(model))[:, None] * (self.wind_velocity(t) - v)

    def jacobian(self, model: Model, x: np.ndarray, v: np.ndarray, t: float) -> tuple[None, sparse.spmatrix]:
        return None, sp.diags(np.repeat(-self.rate * self.masses_of(model), 3), format="csr")
