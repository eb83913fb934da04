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

import numpy as np

from volspring.topology import vector_lengths

__all__ = ["spring_forces", "spring_energy", "spring_strains", "spring_stiffness_blocks", "damper_blocks"]


def _directions(model, x):
    d = model.difference @ x
    length = vector_lengths(d)
    if length.size and length.min() == 0.0:
        e = int(np.argmin(length))
        i, j = model.springs[e]
        raise FloatingPointError(f"spring {e} between nodes {i} and {j} has collapsed to zero length")
    return d / length[:, None], length


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
    magnitude = model.stiffness * (length - model.rest_lengths)
    if v is not None and model.damping.any():
        # (v_i - v_j) . r = -(v_j - v_i) . r
        magnitude += model.damping * np.einsum("ij,ij->i", model.difference @ v, r)
    return model.incidence @ (magnitude[:, None] * r)


def spring_energy(model, x) -> float:
    """Elastic energy sum 1/2 k_e (l - l0)^2 [J]."""
    _, length = _directions(model, x)
    return float(0.5 * np.dot(model.stiffness, (length - model.rest_lengths) ** 2))


def spring_strains(model, x) -> np.ndarray:
    """(s,) float -- engineering strain (l - l0) / l0 of each spring [-]."""
    _, length = _directions(model, x)
    return length / model.rest_lengths - 1.0


def spring_stiffness_blocks(model, x, *, clamp_compression=True) -> np.ndarray:
    """(s, 3, 3) float -- stiffness block H of each spring [N/m] (see the module docstring)."""
    r, length = _directions(model, x)
    outer = r[:, :, None] * r[:, None, :]
    transverse = 1.0 - model.rest_lengths / length
    if clamp_compression:
        transverse = np.maximum(transverse, 0.0)
    blocks = outer * (1.0 - transverse)[:, None, None]
    blocks[:, [0, 1, 2], [0, 1, 2]] += transverse[:, None]
    return blocks * model.stiffness[:, None, None]


def damper_blocks(model, x) -> np.ndarray:
    """(s, 3, 3) float -- damper block D = k_d r r^T of each spring [N s/m]."""
    r, _ = _directions(model, x)
    return model.damping[:, None, None] * r[:, :, None] * r[:, None, :]
