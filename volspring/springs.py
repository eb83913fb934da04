"""Spring and damper forces, their energy and Jacobian blocks, vectorised over all springs.

For spring e = (i, j) with r = (x_j - x_i) / l, l = |x_j - x_i|:

- spring force on i: f = k_e (l - l0) r; on j: -f (momentum is conserved exactly);
- damper force on i: f_d = -k_d ((v_i - v_j) . r) r; on j: -f_d;
- stiffness block H = k_e [r r^T + (1 - l0/l) (I - r r^T)], so dF_i/dx_i = -H, dF_i/dx_j = +H;
  the transverse term is negative under compression (l < l0), so it is clamped at 0 by
  default to keep the assembled matrix positive semi-definite (Baraff & Witkin 1998);
- damper block D = k_d r r^T, dF_i/dv_i = -D, dF_i/dv_j = +D.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from volspring.errors import SpringCollapsed
from volspring.topology import vector_lengths

__all__ = ["SpringLinearization", "damper_blocks", "spring_energy", "spring_forces", "spring_linearization",
           "spring_stiffness_blocks", "spring_strains"]


def _directions(model, x):
    d = model.difference @ x
    length = vector_lengths(d)
    if length.size and not length.min() > 0.0:
        e = int(np.argmin(length))
        raise SpringCollapsed(e, *model.springs[e])
    return d / length[:, None], length


def _magnitudes(model, r, length, v):
    """(s,) float -- spring plus damper force along r on each spring's node i [N]."""
    magnitude = model.stiffness * (length - model.rest_lengths)
    if v is not None and model.damping.any():
        # (v_i - v_j) . r = -(v_j - v_i) . r
        magnitude += model.damping * np.einsum("ij,ij->i", model.difference @ v, r)
    return magnitude


def spring_forces(model, x, v=None) -> np.ndarray:
    """Node forces of all springs (and dampers, when ``v`` is given).

    Parameters
    ----------
    model : SpringModel
    x : (n, 3) float -- positions [m]
    v : (n, 3) float, optional -- velocities [m/s]; without it dampers are left out

    Returns
    -------
    (n, 3) float -- forces [N]
    """
    r, length = _directions(model, x)
    return model.incidence @ (_magnitudes(model, r, length, v)[:, None] * r)


def spring_energy(model, x) -> float:
    """Elastic energy sum 1/2 k_e (l - l0)^2 [J]."""
    _, length = _directions(model, x)
    return float(0.5 * np.dot(model.stiffness, (length - model.rest_lengths) ** 2))


def spring_strains(model, x) -> np.ndarray:
    """(s,) float -- engineering strain (l - l0) / l0 of each spring [-]."""
    _, length = _directions(model, x)
    return length / model.rest_lengths - 1.0


@dataclass(frozen=True, eq=False)
class SpringLinearization:
    """The springs' forces and Jacobian blocks at one configuration (from :func:`spring_linearization`).

    Parameters
    ----------
    blocks : (s, 3, 3) float -- W_e = c_K H_e + c_D D_e
    directions : (s, 3) float -- unit vectors r_e from i to j
    lengths : (s,) float -- current lengths [m]
    axial : (s,) float -- k_e, coefficient of r r^T in H_e [N/m]
    transverse : (s,) float -- k_e (1 - l0/l), clamped if asked: coefficient of the transverse
        projector I - r r^T in H_e [N/m]
    forces : (n, 3) float -- spring (and damper, if velocities were given) forces on the nodes [N]
    """

    blocks: np.ndarray
    directions: np.ndarray
    lengths: np.ndarray
    axial: np.ndarray
    transverse: np.ndarray
    forces: np.ndarray


def spring_linearization(model, x, v=None, *, stiffness_scale=1.0, damping_scale=0.0,
                         clamp_compression=True) -> SpringLinearization:
    """Spring forces and the blocks c_K H_e + c_D D_e in one pass over the springs.

    Parameters
    ----------
    model : SpringModel
    x : (n, 3) float -- positions [m]
    v : (n, 3) float, optional -- velocities [m/s]; without them the dampers exert no force
    stiffness_scale : float -- c_K (h^2 [s^2] for an implicit step, 1 for statics)
    damping_scale : float -- c_D (h [s] for an implicit step)
    clamp_compression : bool -- clamp the transverse term (1 - l0/l) at 0
    """
    r, length = _directions(model, x)
    forces = model.incidence @ (_magnitudes(model, r, length, v)[:, None] * r)
    transverse = 1.0 - model.rest_lengths / length
    if clamp_compression:
        np.maximum(transverse, 0.0, out=transverse)
    transverse *= model.stiffness
    along = stiffness_scale * (model.stiffness - transverse)
    if damping_scale:
        along += damping_scale * model.damping
    blocks = r[:, :, None] * (along[:, None] * r)[:, None, :]
    blocks.reshape(-1, 9)[:, ::4] += (stiffness_scale * transverse)[:, None]
    return SpringLinearization(blocks, r, length, model.stiffness, transverse, forces)


def spring_stiffness_blocks(model, x, *, clamp_compression=True) -> np.ndarray:
    """(s, 3, 3) float -- stiffness block H of each spring [N/m] (see the module docstring)."""
    return spring_linearization(model, x, clamp_compression=clamp_compression).blocks


def damper_blocks(model, x) -> np.ndarray:
    """(s, 3, 3) float -- damper block D = k_d r r^T of each spring [N s/m]."""
    r, _ = _directions(model, x)
    return model.damping[:, None, None] * r[:, :, None] * r[:, None, :]
