"""Vibration modes of a scene about a configuration: K phi = omega^2 M phi over the free components.

K is the stiffness of all element sets (:func:`volspring.assembly.stiffness_matrix`, the exact
Hessian: at the rest shape of springs it is positive semi-definite anyway) plus -dF/dx of the
external forces that have a Jacobian; M holds the lumped masses. Components held by a support
(:attr:`volspring.Scene.held`) are removed from both, so pins, sliding and prescribed supports
all act as fixed boundaries of the eigenproblem.

Up to :data:`DENSE_DOFS` free components the problem is solved densely (``scipy.linalg.eigh``,
all eigenvalues, exact to round-off); above, by ARPACK's shift-invert Lanczos about 0
(``scipy.sparse.linalg.eigsh``) from a seeded start vector, so the same scene gives the same modes
bit for bit.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from volspring.assembly import BlockPattern
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from volspring.scene import Scene

__all__ = ["DENSE_DOFS", "ModalResult", "solve_modes"]

#: Up to this many free components the eigenproblem is solved densely (all eigenvalues, exact).
DENSE_DOFS = 1500


@dataclass(frozen=True, eq=False)
class ModalResult:
    """The lowest modes of a scene (from :func:`solve_modes`).

    Parameters
    ----------
    frequencies : (k,) float
        ascending [Hz]
    eigenvalues : (k,) float
        omega^2 [1/s^2] (may be slightly negative for rigid modes: round-off)
    shapes : (k, n, 3) float
        mass-normalised mode shapes (phi^T M phi = 1), 0 on held components
    """

    frequencies: np.ndarray
    eigenvalues: np.ndarray
    shapes: np.ndarray


def system_matrices(scene, *, x=None, t=0.0):
    """Stiffness K and mass diagonal m over the free components of ``scene`` at x.

    Returns
    -------
    K : (d, d) CSR
        [N/m]
    masses : (d,) float
        [kg]
    dofs : (d,) int
        model unknown (3 node + component) of each free component
    """
    model = scene.model
    x = model.rest_positions if x is None else np.asarray(x, dtype=np.float64)
    pattern = BlockPattern(model, scene.free, ordering="natural")
    K = pattern.matrix(pattern.linearize(x, stiffness_scale=1.0, clamp_compression=False)).tocsr()
    dfdx, _ = scene.external_jacobian(x, np.zeros_like(x), t)
    dofs = pattern.free_dofs()
    if dfdx is not None:
        K = (K - sp.csr_matrix(dfdx)[dofs][:, dofs]).tocsr()
    keep = ~scene.held.reshape(-1)[dofs]
    return K[keep][:, keep], np.repeat(model.masses, 3)[dofs[keep]], dofs[keep]


def solve_modes(scene: Scene, *, count: int = 6, x: np.ndarray | None = None, t: float = 0.0,
                dense_dofs: int = DENSE_DOFS) -> ModalResult:
    """The ``count`` lowest vibration modes of ``scene`` about x (default: the rest shape).

    Parameters
    ----------
    scene : Scene
        model, supports (held components are fixed) and forces (their stiffness counts)
    count : int
        modes wanted, >= 1
    x : (n, 3) float, optional
        configuration [m]
    t : float
        time at which the forces' Jacobians are evaluated [s]
    dense_dofs : int
        up to this many free components, solve densely

    Returns
    -------
    ModalResult

    Raises
    ------
    ValueError
        ``count`` not in 1 .. the number of free components.

    Examples
    --------
    A mass on a spring, the other end pinned: omega = sqrt(k / m).

    >>> import numpy as np
    >>> from volspring import Model, Pins, Scene
    >>> bar = Model.from_arrays([[0, 0, 0], [1, 0, 0]], [1.0, 4.0], [[0, 1]], stiffness=100.0)
    >>> modes = solve_modes(Scene(bar, pins=Pins([0])), count=3)
    >>> round(float(modes.frequencies[-1] * 2 * np.pi), 6)   # axial: sqrt(100 / 4)
    5.0
    """
    K, masses, dofs = system_matrices(scene, x=x, t=t)
    size = K.shape[0]
    if not (isinstance(count, (int, np.integer)) and 1 <= count <= size):
        raise ValueError(f"count = {count!r} modes, expected an integer from 1 to {size} (the free components)")
    if size <= dense_dofs:
        from scipy.linalg import eigh

        values, vectors = eigh(K.toarray(), np.diag(masses), subset_by_index=[0, count - 1])
    else:
        from scipy.sparse.linalg import eigsh

        start = np.random.default_rng(0).standard_normal(size)  # seeded: ARPACK's own start is not
        shift = 0.0 if scene.all_supports else -1e-6 * float(K.diagonal().mean() / masses.mean())
        values, vectors = eigsh(K.tocsc(), k=count, M=sp.diags(masses).tocsc(), sigma=shift, which="LM", v0=start)
        order = np.argsort(values)
        values, vectors = values[order], vectors[:, order]
    shapes = np.zeros((count, 3 * scene.model.node_count))
    shapes[:, dofs] = vectors.T
    return ModalResult(np.sqrt(np.clip(values, 0.0, None)) / (2 * np.pi), values,
                       shapes.reshape(count, -1, 3))
