"""Run a scene for a duration: frames, a callback, recorded energies and momenta, divergence checks.

:func:`simulate` takes ``ceil(duration / dt)`` steps of exactly ``dt`` (a fixed step keeps
position Verlet valid and a resumed run bit-identical to an uninterrupted one), so the last state
may lie up to one step past ``duration``; choose ``duration`` a multiple of ``dt`` to end on it.

Frames. Frame times are the multiples of ``frame_dt`` (absolute times, so a resumed run keeps the
same frames); a frame is taken at the first step whose time reaches the next frame time (within
1e-6 dt of round-off), so with ``frame_dt`` a multiple of ``dt`` frames fall exactly on it. The
start state is frame 0; without ``frame_dt`` every step is a frame. At each frame the result
records time, step, kinetic / potential / total energy, linear momentum and angular momentum
(about the centre of mass), then ``callback(frame_index, state)`` is called (``frame_index``
counts this run's frames from 0). A callback that returns ``False`` (exactly ``False``, not just
a falsy value) stops the run after that frame; ``result.stopped_early`` says so.

Divergence. :meth:`Integrator.step` raises :class:`SimulationDiverged` on NaN or Inf, so no
non-finite state ever reaches the callback. Runaway energy also raises it, checked at every
frame and at least every ``ENERGY_CHECK_INTERVAL`` = 8 steps (an energy costs about one force
evaluation: checking every step would double the cost of a symplectic Euler step, while an
unstable mode needs well over 8 steps to go from visible to overflow) on the total energy
E = kinetic + potential (the model's element sets and forces with a potential):

- with ``energy_limit`` [J]: when E > energy_limit (``math.inf`` turns the check off);
- by default, against what the scene can physically hold: the start energy E_0 plus the work W
  done so far by the scene's forces without a potential (drag, wind, user fields) and by
  prescribed pin motions (trapezoidal rule per step; the pins' work by the work-energy theorem
  on the pinned nodes), with an allowance of ``runaway_factor`` * S, S the energy scale of the
  start, S = kinetic_0 + elastic_0 + L * sum_i |F_ext,i| (L the diagonal of the rest bounding box,
  F_ext the scene's forces at the start: for gravity S includes M g L, the work of falling one
  body size). The run has diverged when the excess E - E_0 - W is above the allowance *and has
  grown* at ``runaway_checks`` = 3 consecutive checks. A conservative run keeps the excess near 0;
  an unstable one grows it geometrically, check after check. A stable scheme can overshoot for a
  step or two without being unstable: linearised implicit Euler at 1000 times the explicit limit
  stretches a flopping beam to 5 kJ of spring energy in its first step (its linearisation of a
  large rotation) and settles on the static answer; an excess that falls again is not a runaway.
  Dampers only remove energy and are not counted. Tracking W costs one more evaluation of the
  non-conservative forces per step, and of all forces on moving pins. With S = 0 (nothing can
  move) the default check is off; NaN detection remains.
The error names the step, time, dt and the node with the largest kinetic energy. Two limits of
the default check: energies are measured with the state's velocity, which for symplectic Euler
and the Verlet family is the half-step one, so a stable run close to the stability limit shows a
kinetic energy up to 1 / (1 - (h omega / 2)^2) times the true one in its fastest modes (10x at
h omega = 1.9), and a body accelerated by a force F shows an O(h F v) offset; pass a larger
``runaway_factor`` or an ``energy_limit`` for runs that live there.

Nothing is printed: progress goes through ``callback``, events to ``logging``.
"""

from __future__ import annotations

import logging
import math
import warnings
from dataclasses import dataclass

import numpy as np

from volspring.diagnostics import angular_momentum, linear_momentum, tet_inversion
from volspring.errors import SimulationDiverged, TetsInvertedWarning
from volspring.integrators import Integrator, make_integrator
from volspring.material import _real_number
from volspring.scene import Scene, State
from volspring.stability import GUARD_ACTIONS, StabilityGuard
from typing import Any
from collections.abc import Callable

__all__ = ["simulate", "SimulationResult", "RUNAWAY_FACTOR", "RUNAWAY_CHECKS", "ENERGY_CHECK_INTERVAL"]

logger = logging.getLogger(__name__)

RUNAWAY_FACTOR = 10.0  # default: energy may exceed its start plus work by 10x the start's energy scale
RUNAWAY_CHECKS = 3     # ... and is a runaway once above that and growing at 3 consecutive checks
ENERGY_CHECK_INTERVAL = 8  # energy checked at every frame and at least every 8 steps (see the docstring)
_FRAME_SLACK = 1e-6    # a step within this fraction of dt of a frame time is on it (round-off of t += dt)


@dataclass(frozen=True, eq=False)
class SimulationResult:
    """What :func:`simulate` returns: the final state and per-frame records.

    Parameters
    ----------
    state : State
        the last state reached
    time : (f,) float
        frame times [s]
    step : (f,) int
        step count of each frame's state
    kinetic_energy, potential_energy, total_energy : (f,) float
        [J]
    linear_momentum : (f, 3) float
        [kg m/s]
    angular_momentum : (f, 3) float
        about the centre of mass [kg m^2/s]
    inverted_tets : (f,) int
        tets turned inside out (signed volume <= 0) at each frame
    worst_volume_ratio : (f,) float
        smallest V / V_rest over the tets at each frame [-] (NaN for a model without tets)
    steps_taken : int
        steps taken by this run
    stopped_early : bool
        the callback returned False
    """

    state: State
    time: np.ndarray
    step: np.ndarray
    kinetic_energy: np.ndarray
    potential_energy: np.ndarray
    total_energy: np.ndarray
    linear_momentum: np.ndarray
    angular_momentum: np.ndarray
    inverted_tets: np.ndarray
    worst_volume_ratio: np.ndarray
    steps_taken: int
    stopped_early: bool

    @property
    def frame_count(self) -> int:
        return len(self.time)


class _EnergyMonitor:
    """Total energy after each step, and the runaway check (see the module docstring)."""

    def __init__(self, scene: Scene, state: State, *, energy_limit, runaway_factor, runaway_checks):
        self.scene = scene
        self.nonconservative = not scene.conservative
        self.kinetic, self.potential = self.energies(state)
        self.latest = state
        self.start = self.kinetic + self.potential
        self.work = 0.0
        self.limit = None if energy_limit == math.inf else energy_limit
        self.active = energy_limit is None
        self.patience = int(runaway_checks)
        self.streak, self.last_excess = 0, -math.inf
        self.moving_pins = scene.pins is not None and scene.pins.motion is not None
        # The moving pins' nodes, for their work (the methods below run only when the pins move).
        self.pinned = scene.pins.nodes if scene.pins is not None else np.zeros(0, dtype=np.int64)
        if energy_limit is None:
            model = scene.model
            external = scene.external_forces(state.x, state.v, state.t)
            size = float(np.linalg.norm(np.ptp(model.rest_positions, axis=0)))
            self.scale = (self.kinetic + model.energy(state.x)
                          + size * float(np.linalg.norm(external, axis=1).sum()))
            self.active = self.scale > 0 and math.isfinite(runaway_factor)
            self.allowance = runaway_factor * self.scale
            if not self.active:
                logger.debug("default energy runaway check off (energy scale %g J)", self.scale)
        self.forces_before = self._nonconservative_forces(state) if self.active else None
        self.pin_forces_before = self._pin_forces(state) if self.active and self.moving_pins else None

    def energies(self, state: State):
        return self.scene.kinetic_energy(state.v), self.scene.potential_energy(state.x, state.t)

    def _nonconservative_forces(self, state):
        if not self.nonconservative:
            return None
        total = self.scene.external_forces(state.x, state.v, state.t, conservative=False)
        total[~self.scene.free] = 0.0
        return total

    def _pin_forces(self, state):
        """(p, 3) every force on the pinned nodes but the pins' own [N]."""
        return self.scene.forces_at(state.x, state.v, state.t)[self.pinned]

    def _pin_work(self, before: State, after: State) -> float:
        """Work the moving pins did on the body over one step [J]: the kinetic energy the pinned
        nodes gained, less the work the other forces did on them (trapezoidal rule)."""
        nodes = self.pinned
        masses = self.scene.model.masses[nodes]
        gained = 0.5 * float(np.sum(masses[:, None] * (after.v[nodes] ** 2 - before.v[nodes] ** 2)))
        forces_after = self._pin_forces(after)
        done = 0.5 * float(np.sum((self.pin_forces_before + forces_after) * (after.x[nodes] - before.x[nodes])))
        self.pin_forces_before = forces_after
        return gained - done

    def recorded(self, state: State):
        """(kinetic, potential) of ``state``, reusing what the last check computed."""
        if self.latest is not state:
            self.kinetic, self.potential = self.energies(state)
            self.latest = state
        return self.kinetic, self.potential

    def after_step(self, before: State, after: State, dt: float, *, check: bool) -> None:
        """Account the step's work; with ``check``, compare the energy with the limit or allowance."""
        if self.active and self.forces_before is not None:
            forces_after = self._nonconservative_forces(after)
            self.work += 0.5 * float(np.sum((self.forces_before + forces_after) * (after.x - before.x)))
            self.forces_before = forces_after
        if self.active and self.pin_forces_before is not None:
            self.work += self._pin_work(before, after)
        if not check or (self.limit is None and not self.active):
            return
        kinetic, potential = self.recorded(after)
        total = kinetic + potential
        if self.limit is not None:
            if total > self.limit:
                self._diverged(after, dt, f"total energy {total:.6g} J is above energy_limit = {self.limit:.6g} J")
            return
        excess = total - self.start - self.work
        if not math.isfinite(excess):
            self._diverged(after, dt, f"the total energy is {total} J")
        growing = excess > self.allowance and excess > self.last_excess
        self.streak = self.streak + 1 if growing else 0
        self.last_excess = excess
        if self.streak >= self.patience:
            self._diverged(after, dt, f"runaway energy: total {total:.6g} J exceeds start {self.start:.6g} J "
                                      f"+ work {self.work:.6g} J by {excess:.6g} J, more than "
                                      f"{self.allowance:.6g} J (runaway_factor x energy scale), and grew at "
                                      f"{self.streak} consecutive checks")

    def _diverged(self, state, dt, reason):
        node_energy = self.scene.model.masses * np.einsum("ij,ij->i", state.v, state.v)
        raise SimulationDiverged(reason, step=state.step, time=state.t, dt=dt, node=int(np.argmax(node_energy)))


def simulate(scene: Scene, integrator: Integrator | str, *, duration: float, dt: float, state: State | None = None,
             frame_dt: float | None = None, callback: Callable[..., Any] | None = None, guard: str = "warn",
             energy_limit: float | None = None, runaway_factor: float = RUNAWAY_FACTOR,
             runaway_checks: int = RUNAWAY_CHECKS) -> SimulationResult:
    """Run ``scene`` for ``duration`` seconds with fixed steps ``dt``.

    Parameters
    ----------
    scene : Scene
    integrator : Integrator or str
        an integrator or a registered name (``make_integrator``)
    duration : float
        simulated time to run [s], >= 0
    dt : float
        time step [s], > 0
    state : State, optional
        where to start (e.g. a checkpoint); default ``scene.initial_state()``
    frame_dt : float, optional
        time between frames [s]; default every step is a frame
    callback : callable, optional
        ``callback(frame_index, state)`` at every frame; return ``False`` to stop the run
    guard : {"warn", "raise", "off"}
        check ``dt`` against an explicit integrator's stability limit before the first step
        (:class:`~volspring.stability.StabilityGuard`)
    energy_limit : float, optional
        total energy [J] above which the run has diverged; default the relative runaway check of the module docstring
    runaway_factor : float
        allowance of the default runaway check, in units of the start's energy scale (``math.inf`` turns the energy
        check off; NaN detection remains)
    runaway_checks : int
        consecutive checks at which the excess must be above the allowance and growing before the run counts as diverged
        (>= 1)

    Returns
    -------
    SimulationResult

    Raises
    ------
    SimulationDiverged
        NaN/Inf or runaway energy, naming step, time, dt and the worst node
    StepTooLarge
        with ``guard="raise"``, before any step

    Examples
    --------
    >>> from volspring import Scene, Model
    >>> from volspring.simulate import simulate
    >>> scene = Scene(Model.from_arrays([[0, 0, 0], [1, 0, 0]], [1.0, 1.0], [[0, 1]], stiffness=100.0))
    >>> result = simulate(scene, "verlet", duration=0.1, dt=0.01, frame_dt=0.05,
    ...                   state=scene.initial_state(v=[[0, 0, 0], [1, 0, 0]]))
    >>> result.time.round(12).tolist(), result.steps_taken
    ([0.0, 0.05, 0.1], 10)
    """
    if isinstance(integrator, str):
        integrator = make_integrator(integrator)
    if not isinstance(integrator, Integrator):
        raise TypeError(f"integrator must be an Integrator or a registered name, got {type(integrator).__name__}")
    dt, duration = _real_number("dt", dt), _real_number("duration", duration)  # numpy scalars too; no bools
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt = {dt!r} s is not a finite number > 0")
    if not (math.isfinite(duration) and duration >= 0):
        raise ValueError(f"duration = {duration!r} s is not a finite number >= 0")
    frame_dt = None if frame_dt is None else _real_number("frame_dt", frame_dt)
    if frame_dt is not None and not (math.isfinite(frame_dt) and frame_dt > 0):
        raise ValueError(f"frame_dt = {frame_dt!r} s is not a finite number > 0")
    if guard not in GUARD_ACTIONS:
        raise ValueError(f"guard = {guard!r}; expected one of {', '.join(map(repr, GUARD_ACTIONS))}")
    if energy_limit is not None and math.isnan(energy_limit):
        raise ValueError("energy_limit = nan J; expected a number or None")
    if not runaway_factor > 0:
        raise ValueError(f"runaway_factor = {runaway_factor!r} is not > 0 (math.inf turns the check off)")
    if isinstance(runaway_checks, bool) or not isinstance(runaway_checks, (int, np.integer)) or runaway_checks < 1:
        raise ValueError(f"runaway_checks = {runaway_checks!r} is not a whole number >= 1")
    state = scene.initial_state() if state is None else state
    scene.check_state(state)  # a State of this model, finite (each step checks its own result after)

    step_count = max(int(math.ceil(duration / dt - 1e-9)), 0)
    if guard != "off":
        StabilityGuard(scene, integrator, action=guard).check(dt, steps=max(step_count, 1))
    logger.info("simulating %d steps of %s, dt = %.6g s, from t = %.6g s", step_count, integrator.name, dt, state.t)

    monitor = _EnergyMonitor(scene, state, energy_limit=energy_limit, runaway_factor=runaway_factor,
                             runaway_checks=runaway_checks)
    records: dict[str, list] = {key: [] for key in ("time", "step", "kinetic", "potential", "linear", "angular",
                                                    "inverted", "ratio")}
    frame_index = 0
    slack = _FRAME_SLACK * dt

    def frame(current: State) -> bool:
        nonlocal frame_index
        records["time"].append(current.t)
        records["step"].append(current.step)
        kinetic, potential = monitor.recorded(current)
        records["kinetic"].append(kinetic)
        records["potential"].append(potential)
        records["linear"].append(linear_momentum(scene, current))
        records["angular"].append(angular_momentum(scene, current))
        inversion = tet_inversion(scene, current.x)
        if inversion.count and not any(records["inverted"]):
            why = ("springs do not resist inversion" if scene.model.rung == "springs"
                   else f"the {scene.model.rung!r} model resists it but was overpowered")
            message = (f"{inversion.count} of {inversion.tet_count} tets are inverted at t = {current.t:.6g} s "
                       f"(worst volume ratio {inversion.worst_volume_ratio:.3g}): {why}; a stiffer material, "
                       "smaller loads or smaller steps keep tets the right way out")
            logger.warning(message)
            warnings.warn(message, TetsInvertedWarning, stacklevel=3)
        records["inverted"].append(inversion.count)
        records["ratio"].append(inversion.worst_volume_ratio)
        keep_going = True if callback is None else callback(frame_index, current) is not False
        frame_index += 1
        return keep_going

    def next_frame_time(t):
        return None if frame_dt is None else (math.floor((t + slack) / frame_dt) + 1) * frame_dt

    stopped = not frame(state)
    upcoming = next_frame_time(state.t)
    taken = 0
    while not stopped and taken < step_count:
        new = integrator.step(scene, state, dt)
        taken += 1
        is_frame = upcoming is None or new.t >= upcoming - slack
        monitor.after_step(state, new, dt, check=is_frame or taken % ENERGY_CHECK_INTERVAL == 0)
        state = new
        if is_frame:
            stopped = not frame(state)
            upcoming = next_frame_time(state.t)
    if stopped:
        logger.info("stopped by the callback at step %d (t = %.6g s)", state.step, state.t)
    logger.info("simulated %d steps to t = %.6g s, %d frames", taken, state.t, frame_index)
    return SimulationResult(
        state=state, time=np.array(records["time"]), step=np.array(records["step"], dtype=np.int64),
        kinetic_energy=np.array(records["kinetic"]), potential_energy=np.array(records["potential"]),
        total_energy=np.array(records["kinetic"]) + np.array(records["potential"]),
        linear_momentum=np.array(records["linear"]).reshape(-1, 3),
        angular_momentum=np.array(records["angular"]).reshape(-1, 3),
        inverted_tets=np.array(records["inverted"], dtype=np.int64), worst_volume_ratio=np.array(records["ratio"]),
        steps_taken=taken, stopped_early=stopped)
