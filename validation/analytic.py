"""Closed-form linear-elastic answers the FEM reference and the spring model are checked against.

All in SI units. Beams are prismatic with a rectangular section ``width x height`` and bend in
the direction of ``height``; formulas are from REFERENCE.md section 6 (Timoshenko & Goodier,
Timoshenko beam theory with the rectangle's shear coefficient 5/6).

Examples
--------
>>> from validation.analytic import cantilever_self_weight_deflection, hanging_bar_elongation
>>> round(cantilever_self_weight_deflection(1.0, 0.1, 0.1, E=1e9, nu=0.3, density=1000.0, gravity=9.81), 9)
0.001486804
>>> hanging_bar_elongation(1.0, E=1e6, density=1000.0, gravity=10.0)
0.005
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import brentq

__all__ = [
    "SHEAR_COEFFICIENT_RECTANGLE",
    "bulk_modulus",
    "cantilever_end_load_deflection",
    "cantilever_frequencies",
    "cantilever_self_weight_deflection",
    "cantilever_wavenumbers",
    "hanging_bar_elongation",
    "hanging_bar_volume_change",
    "shear_modulus",
    "uniaxial_lateral_strain",
    "uniaxial_volume_strain",
]

#: Timoshenko shear coefficient kappa of a rectangular section.
SHEAR_COEFFICIENT_RECTANGLE = 5.0 / 6.0


def shear_modulus(E: float, nu: float) -> float:
    """G = E / (2 (1 + nu)) [Pa]."""
    return E / (2.0 * (1.0 + nu))


def bulk_modulus(E: float, nu: float) -> float:
    """K = E / (3 (1 - 2 nu)) [Pa]; under a pressure p, dV/V = -p / K."""
    return E / (3.0 * (1.0 - 2.0 * nu))


def _beam_terms(width, height, E, nu):
    area = width * height
    second_moment = width * height**3 / 12.0
    shear_stiffness = SHEAR_COEFFICIENT_RECTANGLE * shear_modulus(E, nu) * area
    return area, E * second_moment, shear_stiffness


def cantilever_end_load_deflection(length: float, width: float, height: float, *, E: float, nu: float,
                                   force: float, shear: bool = True) -> float:
    """Tip deflection of a cantilever under an end force: P L^3 / (3 E I) + P L / (kappa G A).

    Parameters
    ----------
    length, width, height : float
        beam length and section [m]; bending is along ``height``
    E : float
        Young's modulus [Pa]
    nu : float
        Poisson ratio [-] (enters the shear term only)
    force : float
        end force across the beam, along ``height`` [N]
    shear : bool
        add Timoshenko's shear term; False gives Euler-Bernoulli

    Returns
    -------
    float
        tip deflection along the force [m]
    """
    _, bending, shear_stiffness = _beam_terms(width, height, E, nu)
    return force * length**3 / (3.0 * bending) + (force * length / shear_stiffness if shear else 0.0)


def cantilever_self_weight_deflection(length: float, width: float, height: float, *, E: float, nu: float,
                                      density: float, gravity: float, shear: bool = True) -> float:
    """Tip deflection of a cantilever under its own weight q = rho g A per length:
    q L^4 / (8 E I) + q L^2 / (2 kappa G A).

    Parameters
    ----------
    length, width, height : float
        [m]; bending is along ``height``
    E : float
        [Pa]
    nu : float
        [-]
    density : float
        [kg/m^3]
    gravity : float
        magnitude of g, across the beam along ``height`` [m/s^2]
    shear : bool
        add Timoshenko's shear term; False gives Euler-Bernoulli

    Returns
    -------
    float
        tip deflection [m]
    """
    area, bending, shear_stiffness = _beam_terms(width, height, E, nu)
    q = density * gravity * area
    return q * length**4 / (8.0 * bending) + (q * length**2 / (2.0 * shear_stiffness) if shear else 0.0)


def hanging_bar_elongation(length: float, *, E: float, density: float, gravity: float) -> float:
    """Elongation rho g L^2 / (2 E) [m] of a prismatic bar hanging from its top under its own weight."""
    return density * gravity * length**2 / (2.0 * E)


def hanging_bar_volume_change(length: float, area: float, *, E: float, nu: float, density: float,
                              gravity: float) -> float:
    """Volume change (1 - 2 nu) A rho g L^2 / (2 E) [m^3] of the hanging bar (linearised, uniaxial stress)."""
    return (1.0 - 2.0 * nu) * area * hanging_bar_elongation(length, E=E, density=density, gravity=gravity)


def uniaxial_lateral_strain(strain: float, nu: float) -> float:
    """Lateral strain -nu eps [-] under uniaxial stress with axial strain ``strain``."""
    return -nu * strain


def uniaxial_volume_strain(strain: float, nu: float) -> float:
    """Linearised volume strain dV/V = (1 - 2 nu) eps [-] under uniaxial stress."""
    return (1.0 - 2.0 * nu) * strain


def cantilever_wavenumbers(count: int) -> np.ndarray:
    """(count,) float -- beta_n L, the roots of cos x cosh x = -1: 1.8751, 4.6941, 7.8548, ..."""
    # Root n lies within (n - 1/2) pi +- 0.5 (they approach (n - 1/2) pi fast); bracket and polish.
    # cos x + 1/cosh x = 0 is the same equation, scaled to stay O(1).
    roots = [brentq(lambda x: np.cos(x) + 1.0 / np.cosh(x), (n - 0.5) * np.pi - 0.5, (n - 0.5) * np.pi + 0.5,
                    xtol=1e-14) for n in range(1, count + 1)]
    return np.array(roots)


def cantilever_frequencies(length: float, width: float, height: float, *, E: float, density: float,
                           count: int = 3) -> np.ndarray:
    """Euler-Bernoulli bending frequencies f_n = (beta_n L)^2 / (2 pi L^2) sqrt(E I / (rho A)).

    Parameters
    ----------
    length, width, height : float
        [m]; bending along ``height`` (the ``width`` direction has its own family with width and height swapped)
    E : float
        [Pa]
    density : float
        [kg/m^3]
    count : int
        number of frequencies

    Returns
    -------
    (count,) float
        [Hz]; they neglect shear and rotary inertia, so they run high by about (beta_n h / L)^2 relative terms, which
        grows with n.
    """
    area, bending, _ = _beam_terms(width, height, E, 0.0)
    return cantilever_wavenumbers(count) ** 2 / (2.0 * np.pi * length**2) * np.sqrt(bending / (density * area))
