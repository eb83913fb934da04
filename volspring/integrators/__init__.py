"""Time integrators behind one interface, ``integrator.step(scene, state, dt) -> State``, and a registry.

=========================  ============================  =====  ===================================
name                       class                         order  stable when (undamped, h omega_max)
=========================  ============================  =====  ===================================
``explicit_euler``         :class:`ExplicitEuler`        1      never
``symplectic_euler``       :class:`SymplecticEuler`      1      < 2
``midpoint``               :class:`Midpoint`             2      never (slow growth)
``rk4``                    :class:`RK4`                  4      <= 2 sqrt(2)
``verlet``                 :class:`PositionVerlet`       2      < 2
``time_corrected_verlet``  :class:`TimeCorrectedVerlet`  2      < 2 (variable step)
``implicit_euler``         :class:`ImplicitEuler`        1      always
=========================  ============================  =====  ===================================

Examples
--------
>>> from volspring.integrators import make_integrator
>>> make_integrator("rk4").order
4
"""

from __future__ import annotations

import importlib

from volspring.integrators.base import Integrator
from volspring.integrators.explicit import RK4, ExplicitEuler, Midpoint, SymplecticEuler
from volspring.integrators.verlet import PositionVerlet, TimeCorrectedVerlet
from volspring.integrators.implicit import ImplicitEuler  # written alongside, by the implicit-solver work
from typing import Any

__all__ = ["Integrator", "ExplicitEuler", "SymplecticEuler", "Midpoint", "RK4", "PositionVerlet",
           "TimeCorrectedVerlet", "ImplicitEuler", "INTEGRATORS", "integrator_class", "make_integrator"]

#: Registered integrators by name: a class, or "module:Class" imported on first use (for plug-ins).
INTEGRATORS = {
    "explicit_euler": ExplicitEuler,
    "symplectic_euler": SymplecticEuler,
    "midpoint": Midpoint,
    "rk4": RK4,
    "verlet": PositionVerlet,
    "time_corrected_verlet": TimeCorrectedVerlet,
    "implicit_euler": ImplicitEuler,
}

_ALIASES = {"rk2": "midpoint", "position_verlet": "verlet", "backward_euler": "implicit_euler"}


def integrator_class(name: str) -> type[Integrator]:
    """The integrator class registered under ``name`` (case and ``-``/``_`` insensitive).

    Raises
    ------
    ValueError
        for an unknown name, listing the known ones
    """
    if not isinstance(name, str):
        raise TypeError(f"integrator name must be a str, got {type(name).__name__}")
    key = name.strip().lower().replace("-", "_")
    key = _ALIASES.get(key, key)
    if key not in INTEGRATORS:
        raise ValueError(f"unknown integrator {name!r}; known: {', '.join(INTEGRATORS)}")
    entry = INTEGRATORS[key]
    if isinstance(entry, str):
        module, attribute = entry.split(":")
        entry = getattr(importlib.import_module(module), attribute)
    return entry


def make_integrator(name: str, **options: Any) -> Integrator:
    """An integrator by registered name, built with keyword ``options``.

    Parameters
    ----------
    name : str
        one of ``INTEGRATORS`` (aliases: rk2, position_verlet, backward_euler)
    **options
        passed to the class (the explicit and Verlet schemes take none; see :class:`ImplicitEuler` for the solver
        options)

    Raises
    ------
    ValueError
        unknown name
    TypeError
        options the integrator does not take
    """
    cls = integrator_class(name)
    try:
        return cls(**options)
    except TypeError as error:
        if options:
            raise TypeError(f"integrator {cls.name!r} does not take options {sorted(options)}: {error}") from error
        raise
