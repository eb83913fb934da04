"""Spring forces, energy and blocks of a model: thin functions over its
:class:`~volspring.elements.Springs` (the formulas are in :mod:`volspring.elements.springs`).

Each takes a :class:`~volspring.Model` (its springs) or a :class:`~volspring.elements.Springs`.
"""

from __future__ import annotations

import numpy as np

from volspring.elements.springs import SpringLinearization, Springs
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from volspring.model import Model

__all__ = ["SpringLinearization", "damper_blocks", "spring_energy", "spring_forces", "spring_linearization",
           "spring_stiffness_blocks", "spring_strains"]


def _springs(model) -> Springs:
    return model if isinstance(model, Springs) else model.spring_elements


def spring_forces(model: Model, x: np.ndarray, v: np.ndarray | None = None) -> np.ndarray:
    """(n, 3) float -- forces of all springs (and dampers, when ``v`` is given) [N]."""
    return _springs(model).forces(x, v)


def spring_energy(model: Model, x: np.ndarray) -> float:
    """Elastic energy sum 1/2 k_e (l - l0)^2 [J]."""
    return _springs(model).energy(x)


def spring_strains(model: Model, x: np.ndarray) -> np.ndarray:
    """(s,) float -- engineering strain (l - l0) / l0 of each spring [-]."""
    return _springs(model).strains(x)


def spring_linearization(model: Model, x: np.ndarray, v: np.ndarray | None = None, *, stiffness_scale: float = 1.0,
                         damping_scale: float = 0.0, clamp_compression: bool = True) -> SpringLinearization:
    """Spring forces and the blocks c_K H_e + c_D D_e in one pass (:meth:`Springs.linearize`)."""
    return _springs(model).linearize(x, v, stiffness_scale=stiffness_scale, damping_scale=damping_scale,
                                     clamp_compression=clamp_compression)


def spring_stiffness_blocks(model: Model, x: np.ndarray, *, clamp_compression: bool = True) -> np.ndarray:
    """(s, 3, 3) float -- stiffness block H of each spring [N/m]."""
    return _springs(model).stiffness_blocks(x, clamp_compression=clamp_compression)


def damper_blocks(model: Model, x: np.ndarray) -> np.ndarray:
    """(s, 3, 3) float -- damper block D = k_d r r^T of each spring [N s/m]."""
    return _springs(model).damping_blocks(x)
