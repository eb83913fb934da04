"""Stability of explicit integrators: omega_max of a spring network and the critical step.

A linearised network oscillates in modes with omega^2 the eigenvalues of M^-1 K, with K the
stiffness matrix assembled from the spring blocks H_e = k_e [r r^T + (1 - l0/l)(I - r r^T)]
(at rest the transverse term vanishes) and M the lumped masses. Only free dofs count: a pinned
node's row and column are removed (its motion is prescribed, not integrated).

An explicit scheme is stable when h * omega_max stays below its ``stability_limit``
(REFERENCE.md section 3), so its critical step is ``stability_limit / omega_max``.

Estimates of omega_max:

:func:`omega_max_bound`
    Gershgorin on M^-1 K: omega_max^2 <= max over free dofs of (1 / m_i) sum_j |K_ij|. Always
    safe (never below the true value), one pass over the springs, typically 1.5 to 1.8 times
    too high in omega^2 (REFERENCE.md).
:func:`omega_max_estimate`
    The largest eigenvalue of M^-1/2 K M^-1/2 on the free dofs: a dense solve up to
    ``DENSE_DOFS`` dofs, ARPACK Lanczos (``eigsh``) at tolerance ``EXACT_TOL`` up to
    ``exact_dofs`` (exact to that tolerance), and above it Lanczos at the looser ``LANCZOS_TOL``
    with omega multiplied by ``LANCZOS_SAFETY``: a Lanczos Ritz value never exceeds the
    largest eigenvalue and, once converged, lies within ``tol`` of it, so the factor 1.01
    (2% in omega^2, 200 times the tolerance) covers the tolerance and a clustered top of the
    spectrum. The result is capped by the Gershgorin bound; if Lanczos fails, the bound is used.

:class:`StabilityGuard` compares a step with the critical step before a run starts.

Examples
--------
>>> from volspring import Scene, Model
>>> from volspring.stability import critical_step, omega_max_estimate
>>> pair = Model.from_arrays([[0, 0, 0], [1, 0, 0]], [1.0, 1.0], [[0, 1]], stiffness=50.0)
>>> round(omega_max_estimate(Scene(pair)), 12)  # sqrt(k / mu) with mu = 1/2
10.0
>>> critical_step("symplectic_euler", 10.0)
0.2
"""

from __future__ import annotations

import logging
import math
import warnings

import numpy as np
import scipy.sparse as sp

from volspring.assembly import stiffness_matrix
from volspring.errors import StepTooLarge, StepTooLargeWarning
from volspring.model import Model
from volspring.scene import Scene
from volspring.springs import spring_stiffness_blocks
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from volspring.integrators.base import Integrator

__all__ = ["omega_max_bound", "omega_max_estimate", "omega_max", "critical_step", "critical_steps",
           "growth_per_step", "StabilityGuard", "GUARD_ACTIONS"]

logger = logging.getLogger(__name__)

DENSE_DOFS = 300          # up to this many free dofs: dense eigvalsh (exact, and ARPACK needs k < n)
EXACT_DOFS = 30_000       # default ``exact_dofs``: tight Lanczos up to here (under a second)
EXACT_TOL = 1e-12         # ARPACK tolerance of the exact path
LANCZOS_TOL = 1e-4        # ARPACK tolerance of the large-problem path
LANCZOS_SAFETY = 1.01     # factor on omega from the loose path (see the module docstring)
GUARD_ACTIONS = ("warn", "raise", "off")


def _model_and_free(system):
    if isinstance(system, Scene):
        return system.model, system.free
    if isinstance(system, Model):
        return system, np.ones(system.node_count, dtype=bool)
    raise TypeError(f"expected a Scene or Model, got {type(system).__name__}")


def _spring_blocks(model, x):
    x = model.rest_positions if x is None else np.asarray(x, dtype=np.float64)
    if x.shape != model.rest_positions.shape:
        raise ValueError(f"x has shape {x.shape}, expected {model.rest_positions.shape}")
    return spring_stiffness_blocks(model, x)


def omega_max_bound(system: Scene | Model, *, x: np.ndarray | None = None) -> float:
    """Gershgorin bound on the highest angular frequency of the free dofs [rad/s].

    Parameters
    ----------
    system : Scene or Model
        a scene's pinned nodes are left out
    x : (n, 3) float, optional
        configuration of the stiffness blocks [m]; default the rest shape

    Returns
    -------
    float
        omega with omega^2 >= every eigenvalue of M^-1 K on the free dofs
    """
    model, free = _model_and_free(system)
    if not model.elements or not free.any():
        return 0.0
    if any(element_set is not model.spring_elements for element_set in model.elements):
        # Other element sets: Gershgorin on the assembled matrix of all of them.
        K = stiffness_matrix(model, x, free=free)
        rows = np.asarray(abs(K).sum(axis=1)).ravel() / np.repeat(model.masses[free], 3)
        return float(math.sqrt(rows.max()))
    blocks = _spring_blocks(model, x)
    i, j = model.springs.T
    # Diagonal block of node i: sum of H_e over its springs; |row| sums of it per dof.
    diagonal = abs(model.incidence) @ blocks.reshape(-1, 9)
    row = np.abs(diagonal.reshape(-1, 3, 3)).sum(axis=2)
    # Off-diagonal blocks -H_e couple i and j; they only count between free nodes.
    off = np.abs(blocks).sum(axis=2)
    for c in range(3):
        row[:, c] += np.bincount(i, weights=off[:, c] * free[j], minlength=model.node_count)
        row[:, c] += np.bincount(j, weights=off[:, c] * free[i], minlength=model.node_count)
    rate = row[free] / model.masses[free, None]
    return float(math.sqrt(rate.max()))


def _free_stiffness(model, free, x):
    """(f, f) CSR -- M^-1/2 K M^-1/2 on the f free dofs."""
    scale = sp.diags(np.repeat(1.0 / np.sqrt(model.masses[free]), 3))
    return (scale @ stiffness_matrix(model, x, free=free) @ scale).tocsr()


def omega_max_estimate(system: Scene | Model, *, x: np.ndarray | None = None, exact_dofs: int = EXACT_DOFS) -> float:
    """A sharp estimate of the highest angular frequency of the free dofs [rad/s].

    Parameters
    ----------
    system : Scene or Model
        a scene's pinned nodes are left out
    x : (n, 3) float, optional
        configuration of the stiffness blocks [m]; default the rest shape
    exact_dofs : int
        up to this many free dofs the value is exact (dense or tight Lanczos); above it, loose Lanczos times
        ``LANCZOS_SAFETY`` (never below the exact value in practice)

    Returns
    -------
    float
        omega_max [rad/s]
    """
    from scipy.linalg import eigvalsh
    from scipy.sparse.linalg import ArpackError, ArpackNoConvergence, eigsh

    model, free = _model_and_free(system)
    if not model.elements or not free.any():
        return 0.0
    bound = omega_max_bound(system, x=x)
    A = _free_stiffness(model, free, x)
    dofs = A.shape[0]
    if dofs <= DENSE_DOFS:
        return float(math.sqrt(max(eigvalsh(A.toarray())[-1], 0.0)))
    tight = dofs <= exact_dofs
    start = np.random.default_rng(0).standard_normal(dofs)  # fixed: the same answer every call
    try:
        top = eigsh(A, k=1, which="LA", tol=EXACT_TOL if tight else LANCZOS_TOL, v0=start,
                    return_eigenvectors=False, maxiter=max(1000, dofs))[0]
    except (ArpackNoConvergence, ArpackError) as error:
        logger.warning("Lanczos did not converge on %d dofs (%s); using the Gershgorin bound %.6g rad/s",
                       dofs, error, bound)
        return bound
    omega = math.sqrt(max(top, 0.0)) * (1.0 if tight else LANCZOS_SAFETY)
    return float(min(omega, bound))


def omega_max(system: Scene | Model, *, method: str = "estimate", x: np.ndarray | None = None) -> float:
    """omega_max [rad/s] by ``method``: ``"estimate"`` (sharp) or ``"bound"`` (Gershgorin, safe)."""
    if method == "estimate":
        return omega_max_estimate(system, x=x)
    if method == "bound":
        return omega_max_bound(system, x=x)
    raise ValueError(f"method = {method!r}; expected 'estimate' or 'bound'")


def _integrator_class(integrator):
    if isinstance(integrator, str):
        from volspring.integrators import integrator_class
        return integrator_class(integrator)
    return integrator if isinstance(integrator, type) else type(integrator)


def critical_step(integrator: Integrator | type[Integrator] | str, omega_max: float) -> float:
    """Largest stable step ``stability_limit / omega_max`` [s] of an integrator.

    Parameters
    ----------
    integrator : Integrator, Integrator subclass or registered name
    omega_max : float
        highest angular frequency of the free dofs [rad/s]

    Returns
    -------
    float
        0 for schemes unstable at any step (explicit and midpoint Euler), inf for unconditionally stable ones or when
        nothing oscillates (omega_max = 0)
    """
    limit = _integrator_class(integrator).stability_limit
    if not math.isfinite(omega_max) or omega_max < 0:
        raise ValueError(f"omega_max = {omega_max!r} rad/s is not finite and >= 0")
    if omega_max == 0 or math.isinf(limit):
        return math.inf
    return limit / omega_max


def critical_steps(system: Scene | Model, *, method: str = "estimate") -> dict:
    """Critical step [s] of every registered explicit integrator, by name."""
    from volspring.integrators import INTEGRATORS, integrator_class

    omega = omega_max(system, method=method)
    classes = {name: integrator_class(name) for name in INTEGRATORS}
    return {name: critical_step(cls, omega) for name, cls in classes.items() if cls.explicit}


def growth_per_step(integrator: Integrator | type[Integrator] | str, h_omega: float) -> float:
    """Amplitude factor per step of an undamped mode with h * omega = ``h_omega``.

    Exact for the explicit schemes of volspring (the modulus of the largest eigenvalue of the
    scheme's step on x'' = -omega^2 x); for other explicit schemes 1 inside their stability
    limit and inf beyond it.
    """
    cls = _integrator_class(integrator)
    z = float(h_omega)
    if cls.name == "explicit_euler":
        return math.sqrt(1.0 + z * z)
    if cls.name == "midpoint":
        return math.sqrt(1.0 + z**4 / 4.0)
    if cls.name == "rk4":
        return abs(1.0 + 1j * z - z**2 / 2.0 - 1j * z**3 / 6.0 + z**4 / 24.0)
    if cls.name in ("symplectic_euler", "verlet", "time_corrected_verlet"):
        # Eigenvalues solve lambda^2 - (2 - z^2) lambda + 1 = 0: on the unit circle for z <= 2.
        return 1.0 if z <= 2.0 else (z * z - 2.0 + z * math.sqrt(z * z - 4.0)) / 2.0
    return 1.0 if z <= cls.stability_limit else math.inf


class StabilityGuard:
    """Checks a step against an explicit integrator's stability limit before stepping.

    Parameters
    ----------
    scene : Scene
    integrator : Integrator, Integrator subclass or registered name
    action : {"warn", "raise", "off"}
        on a step too large, warn with :class:`~volspring.errors.StepTooLargeWarning`, raise
        :class:`~volspring.errors.StepTooLarge`, or do nothing
    method : {"estimate", "bound"}
        which omega_max (computed once per guard, on the first check)
    growth_limit : float
        for schemes unstable at every step (stability_limit 0), the largest tolerated growth of the fastest undamped
        mode's amplitude over the planned steps
    omega_max : float, optional
        omega_max of the scene's free dofs [rad/s] when the caller knows it already (e.g. from :func:`omega_max`, to
        check many steps or integrators on one scene without estimating it again); ``method`` is then not used

    Notes
    -----
    A step is too large when ``dt > stability_limit / omega_max``, or, for schemes with
    ``stability_limit == 0``, when ``growth_per_step(h omega_max) ** steps > growth_limit``.
    Implicit integrators always pass. Damping is left out (it only helps explicit Euler).

    Examples
    --------
    >>> import warnings
    >>> from volspring import Scene, Model
    >>> from volspring.stability import StabilityGuard
    >>> scene = Scene(Model.from_arrays([[0, 0, 0], [1, 0, 0]], [1.0, 1.0], [[0, 1]], stiffness=50.0))
    >>> guard = StabilityGuard(scene, "symplectic_euler", action="raise")
    >>> guard.check(0.19)
    >>> guard.check(0.21)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    volspring.errors.StepTooLarge: dt = 0.21 s is above the critical step 0.2 s of symplectic_euler ...
    """

    def __init__(self, scene: Scene, integrator: Integrator | type[Integrator] | str, *, action: str = "warn",
                 method: str = "estimate", growth_limit: float = 2.0, omega_max: float | None = None):
        if action not in GUARD_ACTIONS:
            raise ValueError(f"guard action = {action!r}; expected one of {', '.join(map(repr, GUARD_ACTIONS))}")
        if method not in ("estimate", "bound"):
            raise ValueError(f"method = {method!r}; expected 'estimate' or 'bound'")
        if not (growth_limit > 1):
            raise ValueError(f"growth_limit = {growth_limit!r} is not > 1")
        self.scene, self.action, self.method, self.growth_limit = scene, action, method, float(growth_limit)
        self.integrator = _integrator_class(integrator)
        if omega_max is not None and not (math.isfinite(omega_max) and omega_max >= 0):
            raise ValueError(f"omega_max = {omega_max!r} rad/s is not finite and >= 0")
        self._omega_max = None if omega_max is None else float(omega_max)

    @property
    def omega_max(self) -> float:
        """omega_max of the scene's free dofs at rest [rad/s] (as given, or computed by ``method`` once per guard)."""
        if self._omega_max is None:
            self._omega_max = omega_max(self.scene, method=self.method)
            logger.debug("omega_max (%s) = %.6g rad/s", self.method, self._omega_max)
        return self._omega_max

    @property
    def critical_step(self) -> float:
        """stability_limit / omega_max [s]."""
        return critical_step(self.integrator, self.omega_max)

    def check(self, dt: float, *, steps: int = 1) -> None:
        """Warn or raise if ``steps`` steps of ``dt`` [s] would be unstable (see the class docstring)."""
        if self.action == "off" or not self.integrator.explicit:
            return
        cls, omega = self.integrator, self.omega_max
        z = dt * omega
        if cls.stability_limit > 0:
            critical = self.critical_step
            if dt <= critical:
                return
            message = (f"dt = {dt:.6g} s is above the critical step {critical:.6g} s of {cls.name} "
                       f"(h omega_max = {z:.4g} > {cls.stability_limit:.4g}, omega_max = {omega:.6g} rad/s "
                       f"by {self.method}): the run would blow up; use dt <= {critical:.6g} s "
                       "or an implicit integrator")
        else:
            growth = growth_per_step(cls, z) ** max(int(steps), 1)
            if growth <= self.growth_limit:
                return
            message = (f"{cls.name} is unstable for undamped oscillation at any step: at dt = {dt:.6g} s "
                       f"(h omega_max = {z:.4g}, omega_max = {omega:.6g} rad/s by {self.method}) the fastest "
                       f"mode's amplitude would grow by {growth:.4g} over {int(steps)} steps "
                       f"(more than {self.growth_limit:g}); use a smaller dt, damping, or a stable scheme")
        if self.action == "raise":
            raise StepTooLarge(message)
        warnings.warn(message, StepTooLargeWarning, stacklevel=3)
