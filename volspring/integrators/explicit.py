"""Explicit one-step integrators: explicit Euler, symplectic Euler, midpoint (RK2) and RK4.

All four solve x' = v, v' = a(x, v, t) = F(x, v, t) / m with accelerations from
:meth:`Scene.accelerations` (0 on pinned nodes), vectorised over all nodes; :meth:`Integrator.step`
then projects constraints and obstacles and puts pinned nodes exactly where their motion says.
Intermediate stages of the Runge-Kutta schemes put pinned nodes where they are at the stage time,
so prescribed motion enters every force evaluation exactly.

Stability for an undamped spring of angular frequency omega (REFERENCE.md section 3), as
``stability_limit`` = the largest stable h * omega; the critical step of a whole network is
``stability_limit / omega_max`` (see :mod:`volspring.stability`):

=================  =====  ==========================================================
scheme             order  stable when
=================  =====  ==========================================================
explicit Euler     1      never (amplitude x sqrt(1 + (h omega)^2) per step): limit 0
symplectic Euler   1      h omega < 2
midpoint (RK2)     2      never (amplitude x (1 + (h omega)^4 / 4)^(1/2)): limit 0
RK4                4      h omega <= 2 sqrt(2)
=================  =====  ==========================================================

Dampers and drag shift these limits (explicit Euler is stable for h omega < 2 zeta with damping
ratio zeta; heavy damping lowers the others), which the limits above leave out.
"""

from __future__ import annotations

import math

import numpy as np

from volspring.integrators.base import Integrator
from volspring.scene import Scene, State

__all__ = ["ExplicitEuler", "SymplecticEuler", "Midpoint", "RK4"]


def _stage_accelerations(scene: Scene, x, v, t) -> np.ndarray:
    """Accelerations at an intermediate stage, with pinned nodes where they are at time t.

    ``x`` and ``v`` are stage arrays owned by the caller; the pinned rows are overwritten.
    """
    scene.enforce_supports(x, v, t)
    return scene.accelerations(x, v, t)


class ExplicitEuler(Integrator):
    """Forward Euler: x_{n+1} = x_n + h v_n, v_{n+1} = v_n + h a(x_n, v_n, t_n).

    First order; one force evaluation per step. Unstable for any step on an undamped spring
    (each mode's amplitude grows by sqrt(1 + (h omega)^2) per step), hence ``stability_limit = 0``;
    usable only with enough damping (h omega < 2 zeta). Kept for comparisons.

    Examples
    --------
    >>> from volspring import Scene, Model
    >>> from volspring.integrators import ExplicitEuler
    >>> scene = Scene(Model.from_arrays([[0, 0, 0], [1, 0, 0]], [1.0, 1.0], [[0, 1]], stiffness=100.0))
    >>> state = ExplicitEuler().step(scene, scene.initial_state(v=[[0, 0, 0], [1, 0, 0]]), 1e-3)
    >>> float(state.x[1, 0]), state.step
    (1.001, 1)
    """

    name = "explicit_euler"
    order = 1
    explicit = True
    stability_limit = 0.0

    def advance(self, scene: Scene, state: State, dt: float) -> State:
        a = scene.accelerations(state.x, state.v, state.t)
        return State(state.x + dt * state.v, state.v + dt * a, state.t + dt, state.step + 1, {})


class SymplecticEuler(Integrator):
    """Semi-implicit (symplectic) Euler: v_{n+1} = v_n + h a(x_n, v_n, t_n), x_{n+1} = x_n + h v_{n+1}.

    First order (global error O(h) in positions and velocities), one force evaluation per step,
    stable for h omega < 2. Symplectic: energy oscillates without drift, and for central pair
    forces (springs, dampers) linear and angular momentum are conserved to round-off.
    """

    name = "symplectic_euler"
    order = 1
    explicit = True
    stability_limit = 2.0

    def advance(self, scene: Scene, state: State, dt: float) -> State:
        v = state.v + dt * scene.accelerations(state.x, state.v, state.t)
        return State(state.x + dt * v, v, state.t + dt, state.step + 1, {})


class Midpoint(Integrator):
    """Explicit midpoint rule (RK2): a half Euler step, then a full step with the midpoint slope.

    x_m = x_n + h/2 v_n, v_m = v_n + h/2 a(x_n, v_n, t_n);
    x_{n+1} = x_n + h v_m, v_{n+1} = v_n + h a(x_m, v_m, t_n + h/2).

    Second order, two force evaluations per step. On an undamped spring the amplitude grows by
    (1 + (h omega)^4 / 4)^(1/2) per step: unstable for any step, but slowly
    (``stability_limit = 0``).
    """

    name = "midpoint"
    order = 2
    explicit = True
    stability_limit = 0.0

    def advance(self, scene: Scene, state: State, dt: float) -> State:
        x, v, t = state.x, state.v, state.t
        a = scene.accelerations(x, v, t)
        x_mid, v_mid = x + 0.5 * dt * v, v + 0.5 * dt * a
        a_mid = _stage_accelerations(scene, x_mid, v_mid, t + 0.5 * dt)
        return State(x + dt * v_mid, v + dt * a_mid, t + dt, state.step + 1, {})


class RK4(Integrator):
    """The classical fourth-order Runge-Kutta scheme on (x, v).

    Fourth order, four force evaluations per step. Its stability region meets the imaginary axis
    at h omega = 2 sqrt(2) (about 2.83; on the negative real axis, which heavy damping approaches,
    the limit is 2.785). Inside it the scheme slightly damps every mode (|R| < 1).
    """

    name = "rk4"
    order = 4
    explicit = True
    stability_limit = 2.0 * math.sqrt(2.0)

    def advance(self, scene: Scene, state: State, dt: float) -> State:
        x, v, t = state.x, state.v, state.t
        half = 0.5 * dt
        a1 = scene.accelerations(x, v, t)
        x2, v2 = x + half * v, v + half * a1
        a2 = _stage_accelerations(scene, x2, v2, t + half)
        x3, v3 = x + half * v2, v + half * a2
        a3 = _stage_accelerations(scene, x3, v3, t + half)
        x4, v4 = x + dt * v3, v + dt * a3
        a4 = _stage_accelerations(scene, x4, v4, t + dt)
        sixth = dt / 6.0
        x_new = x + sixth * (v + 2.0 * (v2 + v3) + v4)
        v_new = v + sixth * (a1 + 2.0 * (a2 + a3) + a4)
        return State(x_new, v_new, t + dt, state.step + 1, {})
