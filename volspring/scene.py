"""A scene: a spring model plus exactly the forces, pins and obstacles it asks for, and the state.

The data path is ``Scene(model, forces=..., pins=...)`` -> ``scene.initial_state()`` ->
``integrator.step(scene, state, dt)`` -> next ``State``. The scene is static; the state changes.

A *force* is any object with

``accumulate(x, v, t, out)``
    add its forces [N], shape (n, 3), into ``out``;

and optionally

``jacobian(x, v, t) -> (dF_dx, dF_dv)``
    each a (3n, 3n) scipy sparse matrix or None, for the implicit integrator
    (a force without it is treated explicitly there);
``potential_energy(x, t) -> float``
    its potential [J], for energy diagnostics (forces without one are non-conservative).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Callable

import numpy as np
import scipy.sparse as sp

from volspring.model import SpringModel
from volspring.springs import spring_energy, spring_forces

__all__ = ["State", "Pins", "Gravity", "Drag", "Scene"]


@dataclass(frozen=True, eq=False)
class State:
    """The changing part of a simulation. Treat its arrays as read-only.

    Parameters
    ----------
    x : (n, 3) float -- positions [m]
    v : (n, 3) float -- velocities [m/s]
    t : float -- time [s]
    step : int -- number of steps taken to reach this state
    memory : dict -- what an integrator carries from step to step (previous positions and step of
        the Verlet family, the implicit solver's warm start); part of the state so that a
        checkpoint of the state resumes bit-identically
    """

    x: np.ndarray
    v: np.ndarray
    t: float = 0.0
    step: int = 0
    memory: dict = field(default_factory=dict)

    def replace(self, **changes) -> "State":
        return replace(self, **changes)


@dataclass(frozen=True, eq=False)
class Pins:
    """Nodes whose motion is prescribed exactly: held at rest, or moved by ``motion``.

    Parameters
    ----------
    nodes : (p,) int -- pinned node indices
    motion : callable, optional -- ``motion(t) -> (p, 3)`` positions [m] at time t [s];
        without it the nodes stay at their rest positions
    velocity : callable, optional -- ``velocity(t) -> (p, 3)`` [m/s]; without it a central
        difference of ``motion`` with step 1e-6 s is used
    """

    nodes: np.ndarray
    motion: Callable | None = None
    velocity: Callable | None = None

    def __post_init__(self):
        nodes = np.unique(np.asarray(self.nodes, dtype=np.int64).ravel())
        if nodes.size == 0:
            raise ValueError("Pins need at least one node")
        nodes.setflags(write=False)
        object.__setattr__(self, "nodes", nodes)

    def positions(self, rest_positions, t) -> np.ndarray:
        """(p, 3) float -- where the pinned nodes are at time t [m]."""
        if self.motion is None:
            return rest_positions[self.nodes]
        return self._checked(self.motion(t), "motion", t)

    def velocities(self, t) -> np.ndarray:
        """(p, 3) float -- velocities of the pinned nodes at time t [m/s]."""
        if self.motion is None:
            return np.zeros((len(self.nodes), 3))
        if self.velocity is not None:
            return self._checked(self.velocity(t), "velocity", t)
        h = 1e-6  # central difference: O(h^2) error, far below any simulation step
        ahead, behind = (self._checked(self.motion(t + d), "motion", t) for d in (h, -h))
        return (ahead - behind) / (2 * h)

    def _checked(self, value, name, t):
        value = np.asarray(value, dtype=np.float64)
        if value.shape != (len(self.nodes), 3) or not np.isfinite(value).all():
            raise ValueError(f"Pins.{name}({t}) must return finite values of shape ({len(self.nodes)}, 3), "
                             f"got shape {value.shape}")
        return value


@dataclass(frozen=True, eq=False)
class Gravity:
    """Uniform gravity f_i = m_i g.

    Parameters
    ----------
    masses : (n,) float -- node masses [kg] (``model.masses``)
    g : (3,) float -- acceleration [m/s^2], default (0, 0, -9.81)
    """

    masses: np.ndarray
    g: tuple = (0.0, 0.0, -9.81)

    def accumulate(self, x, v, t, out):
        out += self.masses[:, None] * np.asarray(self.g)

    def potential_energy(self, x, t) -> float:
        return float(-np.dot(self.masses, x @ np.asarray(self.g)))


@dataclass(frozen=True, eq=False)
class Drag:
    """Global viscous drag f_i = -c m_i v_i (a mass-proportional damping rate c [1/s])."""

    masses: np.ndarray
    rate: float

    def __post_init__(self):
        if not np.isfinite(self.rate) or self.rate < 0:
            raise ValueError(f"drag rate = {self.rate} 1/s is not finite and >= 0")

    def accumulate(self, x, v, t, out):
        out -= self.rate * self.masses[:, None] * v

    def jacobian(self, x, v, t):
        return None, sp.diags(np.repeat(-self.rate * self.masses, 3))


@dataclass(frozen=True, eq=False)
class Scene:
    """A spring model with the forces, pins, obstacles and constraints a simulation asks for.

    Parameters
    ----------
    model : SpringModel
    forces : sequence of force objects (see the module docstring), e.g. ``Gravity``, ``Drag``
    pins : Pins, optional
    obstacles : sequence -- non-penetration obstacles, projected after each step
    constraints : sequence -- position projections (distance constraints, strain limiting; meant
        for the Verlet family), projected after each step

    Obstacles and constraints have ``project(x, v, x_start, t, dt, free)``: after a step from
    ``x_start`` they move the free nodes' positions ``x`` (and fix velocities ``v``) in place.
    """

    model: SpringModel
    forces: tuple = ()
    pins: Pins | None = None
    obstacles: tuple = ()
    constraints: tuple = ()

    def __post_init__(self):
        object.__setattr__(self, "forces", tuple(self.forces))
        object.__setattr__(self, "obstacles", tuple(self.obstacles))
        object.__setattr__(self, "constraints", tuple(self.constraints))
        if self.pins is not None and self.pins.nodes.max() >= self.model.node_count:
            raise ValueError(f"pinned node {self.pins.nodes.max()} does not exist "
                             f"(the model has {self.model.node_count} nodes)")

    @cached_property
    def free(self) -> np.ndarray:
        """(n,) bool -- nodes whose motion the integrator computes."""
        free = np.ones(self.model.node_count, dtype=bool)
        if self.pins is not None:
            free[self.pins.nodes] = False
        return free

    def initial_state(self, x=None, v=None, t=0.0) -> State:
        """A state at rest (or at the given x, v), with the pins where they belong at t."""
        x = np.array(self.model.rest_positions if x is None else x, dtype=np.float64)
        v = np.zeros_like(x) if v is None else np.array(v, dtype=np.float64)
        if x.shape != self.model.rest_positions.shape or v.shape != x.shape:
            raise ValueError(f"x and v must have shape {self.model.rest_positions.shape}, got {x.shape} and {v.shape}")
        self.enforce_pins(x, v, t)
        return State(x, v, float(t))

    def enforce_pins(self, x, v, t) -> None:
        """Set the pinned nodes' positions and velocities at time t, in place."""
        if self.pins is not None:
            x[self.pins.nodes] = self.pins.positions(self.model.rest_positions, t)
            v[self.pins.nodes] = self.pins.velocities(t)

    def project(self, x, v, x_start, t, dt) -> None:
        """After a step: project constraints, then obstacles, then put pinned nodes back, in place."""
        for item in self.constraints + self.obstacles:
            item.project(x, v, x_start, t, dt, self.free)
        self.enforce_pins(x, v, t)

    def forces_at(self, x, v, t) -> np.ndarray:
        """(n, 3) float -- total force on every node [N]: springs, dampers and the scene's forces."""
        total = spring_forces(self.model, x, v)
        for force in self.forces:
            force.accumulate(x, v, t, total)
        return total

    def accelerations(self, x, v, t) -> np.ndarray:
        """(n, 3) float -- F / m [m/s^2], 0 on pinned nodes (their motion is set by ``enforce_pins``)."""
        a = self.forces_at(x, v, t) / self.model.masses[:, None]
        if self.pins is not None:
            a[self.pins.nodes] = 0.0
        return a

    def potential_energy(self, x, t=0.0) -> float:
        """Spring energy plus the potential of every conservative force [J]."""
        return spring_energy(self.model, x) + sum(
            force.potential_energy(x, t) for force in self.forces if hasattr(force, "potential_energy"))

    def kinetic_energy(self, v) -> float:
        return float(0.5 * np.dot(self.model.masses, np.einsum("ij,ij->i", v, v)))
