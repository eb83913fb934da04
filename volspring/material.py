"""An isotropic linear-elastic material in SI units."""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["Material"]


@dataclass(frozen=True)
class Material:
    """Isotropic linear-elastic material.

    Parameters
    ----------
    E : float -- Young's modulus [Pa], > 0
    nu : float -- Poisson's ratio [-], -1 < nu < 0.5
    density : float -- mass density [kg/m^3], > 0

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
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ValueError(f"{name} = {value!r} is not a finite number")
            object.__setattr__(self, name, float(value))
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
