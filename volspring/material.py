"""An isotropic linear-elastic material in SI units.

This leaf module also holds :func:`_real_number` and :func:`_real_array`, the checks every
volspring constructor applies to the numbers it takes (material constants, field parameters,
spring constants, masses).
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

import numpy as np

__all__ = ["Material"]


def _shown(value, limit=80) -> str:
    """``repr(value)`` for an error message, without printing a whole array or a long object."""
    if isinstance(value, np.ndarray) and value.size > 6:
        return f"array(shape={value.shape}, dtype={value.dtype})"
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _real_number(name, value) -> float:
    """``value`` as a float if it is a real number, else a TypeError naming ``name``.

    Real numbers are Python ints and floats, numpy integer and floating scalars (``np.float32``,
    ``np.int64``...) and 0-d arrays of those. Bools (``True`` is not a modulus) and strings
    (``"1e6"`` is text, not a number) are refused. Finiteness and range are the caller's checks.

    Parameters
    ----------
    name : str
        The parameter's name, for the message.
    value : object
        What the caller was given.

    Returns
    -------
    float

    Raises
    ------
    TypeError
        ``E = '1e6' is not a real number (got str)``.
    """
    if isinstance(value, np.ndarray) and value.ndim == 0:
        value = value[()]
    if isinstance(value, (bool, np.bool_)) or not isinstance(value, numbers.Real):
        raise TypeError(f"{name} = {_shown(value)} is not a real number (got {type(value).__name__})")
    return float(value)


def _real_array(name, value) -> np.ndarray:
    """``value`` as a new float64 array if it holds real numbers, else a TypeError naming ``name``.

    Integer and floating arrays, scalars and nested sequences of them are real; bools, strings
    and objects are not (``np.asarray(["1", "2"], dtype=float)`` would read text silently).
    Ragged sequences are a ValueError. Shape and finiteness are the caller's checks.
    """
    try:
        array = np.asarray(value)
    except ValueError as error:  # ragged nested sequences
        raise ValueError(f"{name} = {_shown(value)} is not a regular array of numbers: {error}") from None
    if array.dtype.kind not in "iuf":
        raise TypeError(f"{name} = {_shown(value)} does not hold real numbers (got dtype {array.dtype})")
    if not isinstance(value, np.ndarray) and array.size:
        # numpy turns (0, 0, True) into integers: look at the items of a Python sequence
        items = np.asarray(value, dtype=object).ravel()
        for index, item in enumerate(items):
            if isinstance(item, (bool, np.bool_)):
                raise TypeError(f"{name} = {_shown(value)} holds a bool (item {index}); expected real numbers")
    return np.array(array, dtype=np.float64)


@dataclass(frozen=True)
class Material:
    """Isotropic linear-elastic material.

    Parameters
    ----------
    E : float
        Young's modulus [Pa], > 0
    nu : float
        Poisson's ratio [-], -1 < nu < 0.5
    density : float
        mass density [kg/m^3], > 0

    Raises
    ------
    TypeError
        For a value that is not a real number (a bool, a string), naming the parameter.
    ValueError
        For a value out of its range or not finite, e.g. ``nu = 0.5 is not in (-1, 0.5)``.

    Notes
    -----
    Any real number is taken (Python or numpy scalars) and stored as a float.

    Examples
    --------
    >>> from volspring import Material
    >>> rubber = Material(E=1e6, nu=0.45, density=1100.0)
    >>> round(rubber.shear_modulus), round(rubber.bulk_modulus)
    (344828, 3333333)
    """

    E: float
    nu: float
    density: float

    def __post_init__(self):
        for name in ("E", "nu", "density"):
            value = _real_number(name, getattr(self, name))
            if not math.isfinite(value):
                raise ValueError(f"{name} = {value!r} is not a finite number")
            object.__setattr__(self, name, value)
        if self.E <= 0:
            raise ValueError(f"E = {self.E} Pa is not > 0")
        if not -1.0 < self.nu < 0.5:
            raise ValueError(f"nu = {self.nu} is not in (-1, 0.5)")
        if self.density <= 0:
            raise ValueError(f"density = {self.density} kg/m^3 is not > 0")

    @property
    def shear_modulus(self) -> float:
        """mu = E / (2 (1 + nu)) [Pa] (Lame's second parameter)."""
        return self.E / (2.0 * (1.0 + self.nu))

    @property
    def lame_lambda(self) -> float:
        """lambda = E nu / ((1 + nu)(1 - 2 nu)) [Pa]."""
        return self.E * self.nu / ((1.0 + self.nu) * (1.0 - 2.0 * self.nu))

    @property
    def bulk_modulus(self) -> float:
        """K = E / (3 (1 - 2 nu)) [Pa]."""
        return self.E / (3.0 * (1.0 - 2.0 * self.nu))
