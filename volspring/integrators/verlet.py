"""The Verlet family: position Verlet (fixed step) and time-corrected Verlet (variable step).

Both advance positions from the two latest ones, with no velocity in the update itself:

- position Verlet: x_{n+1} = 2 x_n - x_{n-1} + h^2 a_n;
- time-corrected Verlet: x_{i+1} = x_i + (h_i / h_{i-1}) (x_i - x_{i-1}) + a_i (h_i + h_{i-1}) / 2 * h_i,
  which is position Verlet when h_i = h_{i-1} and stays second order when the step varies;
- first step (no history): x_1 = x_0 + h v_0 + h^2 / 2 a_0 (a Taylor step, locally third order).

Velocity. The state's velocity is the backward difference v_{n+1} = (x_{n+1} - x_n) / h, not the
central difference (x_{n+1} - x_{n-1}) / (2 h). Why:

- it belongs to the same time as the positions (the central difference is the velocity at t_n,
  one step behind x_{n+1}, so a state would mix two times);
- it is the velocity position-based constraints produce: after a projection moves x, the motion
  from x_n to the projected x *is* the velocity (position-based dynamics);
- with it the state (x, v) carries the whole history, x_n = x_{n+1} - h v_{n+1}, so a state whose
  velocity was set by someone else (an obstacle, a user) still resumes consistently;
- linear and angular momentum computed from (x, v) are then conserved to round-off for central
  pair forces: sum m x_n x x_{n+1} is an exact invariant of the Verlet recursion.

Its cost: it is the exact velocity at t_{n+1/2}, so as a velocity at t_{n+1} it is only first
order (off by h a / 2); kinetic energy inherits that O(h) offset (no drift), and dampers and drag,
which read it, make the scheme first order when they matter. Positions stay second order.

History. ``state.memory`` holds ``verlet_previous_x`` (x_n, the positions one step before the
state) and ``verlet_previous_dt`` (the step that led to the state), so a checkpoint of the state
resumes bit-identically. Consistency with projections: after a step, nodes that a projection
moved without touching their velocity get v = (x - x_n) / h (velocity from positions); nodes
whose velocity was set (obstacles, moving pins, edits) get their history rebuilt from it at the
next step, x_n := x - h v. Nodes nothing touched keep the exact Verlet history.

Stability: h omega < 2, as symplectic Euler (both are the Stoermer-Verlet scheme).
"""

from __future__ import annotations

import math

import numpy as np

from volspring.integrators.base import Integrator
from volspring.scene import Scene, State

__all__ = ["PositionVerlet", "TimeCorrectedVerlet"]

PREVIOUS_X = "verlet_previous_x"
PREVIOUS_DT = "verlet_previous_dt"


def _history(state: State):
    """(x_{n-1}, h_{n-1}) consistent with ``state``, or (None, None) on a first step.

    Where the state's velocity is not the backward difference the previous step produced
    (a projection or a user set it), the history is rebuilt from it: x_{n-1} = x_n - h v_n.
    """
    x_prev, dt_prev = state.memory.get(PREVIOUS_X), state.memory.get(PREVIOUS_DT)
    if x_prev is None or dt_prev is None:
        return None, None
    x_prev = np.asarray(x_prev, dtype=np.float64)
    if x_prev.shape != state.x.shape:
        raise ValueError(f"state.memory[{PREVIOUS_X!r}] has shape {x_prev.shape}, expected {state.x.shape}")
    stale = np.any((state.x - x_prev) / dt_prev != state.v, axis=1)
    if stale.any():
        x_prev = x_prev.copy()
        x_prev[stale] = state.x[stale] - dt_prev * state.v[stale]
    return x_prev, dt_prev


class _VerletFamily(Integrator):
    explicit = True
    order = 2
    stability_limit = 2.0

    def _positions(self, x, x_prev, dt, dt_prev, a) -> np.ndarray:
        raise NotImplementedError

    def advance(self, scene: Scene, state: State, dt: float) -> State:
        x, v, t = state.x, state.v, state.t
        x_prev, dt_prev = _history(state)
        if x_prev is None:
            a = scene.accelerations(x, v, t)
            x_new = x + dt * v + (0.5 * dt * dt) * a
        else:
            # v is the backward difference here: the velocity the dampers and drag see.
            x_new = self._positions(x, x_prev, dt, dt_prev, scene.accelerations(x, v, t))
        v_new = (x_new - x) / dt
        return State(x_new, v_new, t + dt, state.step + 1, {PREVIOUS_X: x, PREVIOUS_DT: float(dt)})

    def project(self, scene: Scene, start: State, new: State, dt: float) -> None:
        """Project as :meth:`Integrator.project`, then keep the history consistent with what moved."""
        if not (scene.constraints or scene.obstacles or scene.pins is not None):
            return
        x_before, v_before = new.x.copy(), new.v.copy()
        scene.project(new.x, new.v, start.x, new.t, dt)
        only_moved = np.any(new.x != x_before, axis=1) & np.all(new.v == v_before, axis=1)
        if only_moved.any():
            # Velocity from positions, by the same expression as advance (the next step's
            # history check then recognises it bit for bit).
            new.v[only_moved] = (new.x[only_moved] - start.x[only_moved]) / dt


class PositionVerlet(_VerletFamily):
    """Position (Stoermer) Verlet with a fixed step: x_{n+1} = 2 x_n - x_{n-1} + h^2 a_n.

    Second order in positions, one force evaluation per step, stable for h omega < 2, symplectic
    and time-reversible. The velocity is the backward difference (x_{n+1} - x_n) / h; see the
    module docstring for why, and for how the history lives in ``state.memory``. Changing the
    step between calls raises: use :class:`TimeCorrectedVerlet` for a variable step.

    Examples
    --------
    >>> from volspring import Scene, Model
    >>> from volspring.integrators import PositionVerlet
    >>> scene = Scene(Model.from_arrays([[0, 0, 0], [1, 0, 0]], [1.0, 1.0], [[0, 1]], stiffness=100.0))
    >>> state = scene.initial_state(v=[[0, 0, 0], [1, 0, 0]])
    >>> for _ in range(3):
    ...     state = PositionVerlet().step(scene, state, 1e-3)
    >>> sorted(state.memory)
    ['verlet_previous_dt', 'verlet_previous_x']
    """

    name = "verlet"

    def _positions(self, x, x_prev, dt, dt_prev, a):
        if not math.isclose(dt, dt_prev, rel_tol=1e-12):
            raise ValueError(f"PositionVerlet needs a fixed step: dt = {dt!r} s after {dt_prev!r} s; "
                             "use TimeCorrectedVerlet (time_corrected_verlet) for a variable step")
        return 2.0 * x - x_prev + (dt * dt) * a


class TimeCorrectedVerlet(_VerletFamily):
    """Time-corrected Verlet for a variable step (Dickinson's correction of position Verlet).

    x_{i+1} = x_i + (h_i / h_{i-1}) (x_i - x_{i-1}) + a_i (h_i + h_{i-1}) / 2 * h_i.

    With the backward-difference velocity this is v_{i+1/2} = v_{i-1/2} + a_i (h_i + h_{i-1}) / 2,
    x_{i+1} = x_i + h_i v_{i+1/2}: the half-step velocities are spaced (h_i + h_{i-1}) / 2 apart in
    time, so the scheme stays second order for any smoothly or abruptly varying step, and equals
    :class:`PositionVerlet` (to round-off) for a constant one. Stable for h_i omega < 2.
    """

    name = "time_corrected_verlet"

    def _positions(self, x, x_prev, dt, dt_prev, a):
        return x + (dt / dt_prev) * (x - x_prev) + (0.5 * (dt + dt_prev) * dt) * a
