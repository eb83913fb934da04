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

Input is checked where it enters: constructors refuse what is not numbers (TypeError) and numbers
of the wrong shape, range or finiteness (ValueError), naming the value; a scene refuses pins and
mass arrays that do not fit its model; :meth:`Scene.check_state` refuses a state that does not
(an integrator's ``step`` checks its shapes at every step).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Callable

import numpy as np
import scipy.sparse as sp

from volspring.fields import PointAttractor, Vortex, Wind, _masses, _vector
from volspring.material import _real_array, _real_number, _shown
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
    nodes : (p,) int or (n,) bool
        Pinned node indices (Python or numpy integers, >= 0), or a boolean mask with one entry
        per node of the model (``rest_positions[:, 0] == 0``), converted to the indices of its
        True entries. Floats are refused, integer-valued or not: ``np.asarray(nodes, dtype=int)``
        converts e.g. what ``np.loadtxt`` read. Indices beyond the model are refused by
        :class:`Scene`, which also checks a mask's length.
    motion : callable, optional
        ``motion(t) -> (p, 3)`` positions [m] at time t [s], row k for ``nodes[k]`` in the order
        given (each node once); without it the nodes stay at their rest positions, and are
        stored sorted with repeats dropped.
    velocity : callable, optional
        ``velocity(t) -> (p, 3)`` [m/s], only with ``motion``; without it a central
        difference of ``motion`` with step 1e-6 s is used.

    Attributes
    ----------
    mask_length : int or None
        The length of the boolean mask ``nodes`` came from (None for indices).

    Raises
    ------
    TypeError
        ``nodes`` that are neither integers nor a boolean mask; ``motion`` or ``velocity`` not callable.
    ValueError
        No node, a negative index, a node listed twice with ``motion``, ``velocity`` without ``motion``.

    Examples
    --------
    >>> import numpy as np
    >>> from volspring import Pins
    >>> Pins([3, 1, 3]).nodes.tolist()
    [1, 3]
    >>> Pins(np.array([True, False, True])).nodes.tolist()
    [0, 2]
    """

    nodes: np.ndarray
    motion: Callable | None = None
    velocity: Callable | None = None
    mask_length: int | None = field(default=None, init=False, repr=False)

    def __post_init__(self):
        for name in ("motion", "velocity"):
            function = getattr(self, name)
            if function is not None and not callable(function):
                raise TypeError(f"Pins {name} = {_shown(function)} is not callable; expected {name}(t) -> (p, 3)")
        if self.velocity is not None and self.motion is None:
            raise ValueError("Pins velocity= was given without motion=; without motion the pinned nodes "
                             "stay at rest, so give motion(t) too")
        nodes, mask_length = _pinned_indices(self.nodes)
        if nodes.size == 0:
            raise ValueError("Pins need at least one node" if mask_length is None else
                             f"Pins need at least one node: the mask's {mask_length} entries are all False")
        if self.motion is None:
            nodes = np.unique(nodes)
        else:
            unique, first = np.unique(nodes, return_index=True)
            if len(unique) < len(nodes):
                repeat = int(np.flatnonzero(~np.isin(np.arange(len(nodes)), first))[0])
                raise ValueError(f"Pins nodes[{repeat}] = {nodes[repeat]} is listed twice; with motion= each "
                                 "node must appear once (row k of motion(t) is the position of nodes[k])")
        nodes.setflags(write=False)
        object.__setattr__(self, "nodes", nodes)
        object.__setattr__(self, "mask_length", mask_length)

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


def _pinned_indices(nodes):
    """(p,) int64 node indices from what ``Pins`` was given, and the mask's length (None for indices)."""
    if isinstance(nodes, (bool, np.bool_)):
        raise TypeError(f"Pins nodes = {nodes!r} is a bool; expected node indices or a boolean mask "
                        "with one entry per node")
    try:
        array = np.asarray(nodes)
    except ValueError as error:  # ragged nested sequences
        raise ValueError(f"Pins nodes = {_shown(nodes)} is not a regular array: {error}") from None
    if array.size == 0 and array.dtype.kind != "b":  # [] is a float64 array
        return np.zeros(0, dtype=np.int64), None
    if array.dtype.kind == "b":
        if array.ndim != 1:
            raise ValueError(f"Pins nodes is a boolean mask of shape {array.shape}; expected shape (n,), "
                             "one entry per node")
        return np.flatnonzero(array), len(array)
    if array.dtype.kind in "iu" and not isinstance(nodes, np.ndarray):
        # [True, 2] becomes the integers [1, 2]: refuse a list that mixes bools and integers
        items = np.asarray(nodes, dtype=object).ravel()
        mixed = [k for k, item in enumerate(items) if isinstance(item, (bool, np.bool_))]
        if mixed:
            raise TypeError(f"Pins nodes[{mixed[0]}] = {items[mixed[0]]!r} is a bool among integers; expected "
                            "node indices, or a boolean mask with one entry per node")
    if array.dtype.kind == "f":
        flat = array.ravel()
        fractional = np.flatnonzero(~np.isfinite(flat) | (flat != np.round(flat)))
        if fractional.size:
            k = int(fractional[0])
            raise TypeError(f"Pins nodes[{k}] = {flat[k]} is not an integer node index")
        raise TypeError(f"Pins nodes are {array.dtype} values, not integer node indices; convert "
                        "integer-valued floats with np.asarray(nodes, dtype=int)")
    if array.dtype.kind not in "iu":
        raise TypeError(f"Pins nodes = {_shown(nodes)} are not integer node indices or a boolean mask "
                        f"(got dtype {array.dtype})")
    indices = array.astype(np.int64).ravel()
    negative = np.flatnonzero(indices < 0)
    if negative.size:
        k = int(negative[0])
        raise ValueError(f"Pins nodes[{k}] = {indices[k]} is negative; expected node indices >= 0 "
                         "(they do not count from the end)")
    return indices, None


@dataclass(frozen=True, eq=False)
class Gravity:
    """Uniform gravity f_i = m_i g.

    Parameters
    ----------
    masses : (n,) float
        Node masses [kg], finite and >= 0 (``model.masses``; a 0 exempts a node).
    g : (3,) float
        Acceleration [m/s^2], default (0, 0, -9.81); stored as a read-only array.

    Raises
    ------
    TypeError
        Masses or g that are not numbers (bools, strings).
    ValueError
        ``g = (0, 0) is not a finite 3-vector (got shape (2,))``; a negative or non-finite mass.
    """

    masses: np.ndarray
    g: tuple = (0.0, 0.0, -9.81)

    def __post_init__(self):
        object.__setattr__(self, "masses", _masses(self.masses, allow_zero=True))
        object.__setattr__(self, "g", _vector("g", self.g))

    def accumulate(self, x, v, t, out):
        out += self.masses[:, None] * self.g

    def potential_energy(self, x, t) -> float:
        return float(-np.dot(self.masses, x @ self.g))


@dataclass(frozen=True, eq=False)
class Drag:
    """Global viscous drag f_i = -c m_i v_i (a mass-proportional damping rate c [1/s]).

    Parameters
    ----------
    masses : (n,) float
        Node masses [kg], finite and >= 0 (``model.masses``; a 0 exempts a node).
    rate : float
        Damping rate c [1/s], finite and >= 0.
    """

    masses: np.ndarray
    rate: float

    def __post_init__(self):
        object.__setattr__(self, "masses", _masses(self.masses, allow_zero=True))
        rate = _real_number("drag rate", self.rate)
        if not math.isfinite(rate) or rate < 0:
            raise ValueError(f"drag rate = {rate} 1/s is not finite and >= 0")
        object.__setattr__(self, "rate", rate)

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

    Raises
    ------
    TypeError
        A model that is not a SpringModel, pins that are not a Pins, a single force instead of a
        sequence, a force without ``accumulate`` or an obstacle or constraint without ``project``.
    ValueError
        A pinned node the model does not have, a pin mask of another length, or a built-in force
        (Gravity, Drag, Wind, PointAttractor, PointRepulser, Vortex) whose masses are not one per node.
    """

    model: SpringModel
    forces: tuple = ()
    pins: Pins | None = None
    obstacles: tuple = ()
    constraints: tuple = ()

    def __post_init__(self):
        if not isinstance(self.model, SpringModel):
            raise TypeError(f"model must be a volspring SpringModel, got {type(self.model).__name__}")
        n = self.model.node_count
        for name, method, arguments in (("forces", "accumulate", "x, v, t, out"),
                                        ("obstacles", "project", "x, v, x_start, t, dt, free"),
                                        ("constraints", "project", "x, v, x_start, t, dt, free")):
            items = _sequence(name, getattr(self, name), method)
            for index, item in enumerate(items):
                if not callable(getattr(item, method, None)):
                    raise TypeError(f"{name}[{index}] = {_shown(item)} has no {method}({arguments}) method")
            object.__setattr__(self, name, items)
        for index, force in enumerate(self.forces):
            if isinstance(force, _MASS_PROPORTIONAL) and force.masses.shape != (n,):
                raise ValueError(f"forces[{index}] ({type(force).__name__}) has {len(force.masses)} masses, but the "
                                 f"model has {n} nodes; expected one mass per node (model.masses)")
        if self.pins is None:
            return
        if not isinstance(self.pins, Pins):
            raise TypeError(f"pins = {_shown(self.pins)} is not a volspring Pins; expected e.g. pins=Pins([0, 1])")
        if self.pins.mask_length is not None and self.pins.mask_length != n:
            raise ValueError(f"Pins were given a boolean mask of {self.pins.mask_length} entries, but the model "
                             f"has {n} nodes; expected one entry per node")
        if self.pins.nodes.max() >= n:
            raise ValueError(f"pinned node {self.pins.nodes.max()} does not exist: the model has {n} nodes "
                             f"(indices 0 to {n - 1})")

    @cached_property
    def free(self) -> np.ndarray:
        """(n,) bool -- nodes whose motion the integrator computes."""
        free = np.ones(self.model.node_count, dtype=bool)
        if self.pins is not None:
            free[self.pins.nodes] = False
        return free

    def initial_state(self, x=None, v=None, t=0.0) -> State:
        """A state at rest (or at the given x, v), with the pins where they belong at t.

        Parameters
        ----------
        x : (n, 3) float, optional
            Positions [m], finite; default the model's rest positions.
        v : (n, 3) float, optional
            Velocities [m/s], finite; default 0.
        t : float
            Time [s], finite.

        Returns
        -------
        State
            New arrays (the arguments are copied), pinned nodes set by the pins at t.

        Raises
        ------
        TypeError
            x, v or t that are not numbers.
        ValueError
            x or v not of shape (n, 3) for this model, or holding NaN or Inf (naming the first
            bad node), or a non-finite t.
        """
        t = _real_number("t", t)
        if not math.isfinite(t):
            raise ValueError(f"t = {t} s is not a finite time")
        x = self.model.rest_positions.copy() if x is None else _real_array("x", x)
        v = np.zeros_like(x) if v is None else _real_array("v", v)
        _check_motion(x, v, self.model.node_count, prefix="", finite=True)
        self.enforce_pins(x, v, t)
        return State(x, v, t)

    def check_state(self, state, *, finite=True) -> None:
        """Refuse a state that does not fit this scene's model, or (with ``finite``) holds NaN or Inf.

        :meth:`Integrator.step <volspring.integrators.Integrator.step>` calls it with
        ``finite=False`` at every step (the shapes only, about a microsecond); the finiteness of
        a state that came out of a step is already checked there, so the full check is needed
        once, on a state from outside, before the first step of a run.

        Parameters
        ----------
        state : State
            The state to check.
        finite : bool
            Also check that x, v and t are finite (one pass over x and v).

        Raises
        ------
        TypeError
            ``state`` is not a :class:`State`.
        ValueError
            ``state.x`` or ``state.v`` not of shape (n, 3) for this model, naming both shapes (a
            state of another model); with ``finite``, NaN or Inf in x or v, naming the first bad
            node and whether it is a position or a velocity, or a non-finite t.

        Examples
        --------
        >>> from volspring import Scene, SpringModel
        >>> scene = Scene(SpringModel.from_arrays([[0, 0, 0], [1, 0, 0]], [1.0, 1.0], [[0, 1]], stiffness=1.0))
        >>> other = Scene(SpringModel.from_arrays([[0, 0, 0]], [1.0], [], stiffness=1.0))
        >>> scene.check_state(other.initial_state())
        Traceback (most recent call last):
        ...
        ValueError: state.x has shape (1, 3), but the scene's model has 2 nodes: expected (2, 3) (a state of another model?)
        """
        if not isinstance(state, State):
            raise TypeError(f"state must be a volspring State, got {type(state).__name__}")
        _check_motion(state.x, state.v, self.model.node_count, prefix="state.", finite=finite)
        if finite and not math.isfinite(state.t):
            raise ValueError(f"state.t = {state.t} s is not a finite time")

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


_MASS_PROPORTIONAL = (Gravity, Drag, Wind, PointAttractor, Vortex)  # forces that hold (n,) masses


def _sequence(name, items, method) -> tuple:
    """``items`` as a tuple; a TypeError for a single object (it has ``method``) or a non-iterable."""
    if hasattr(items, method):
        raise TypeError(f"{name} is a single {type(items).__name__}; expected a sequence, e.g. {name}=[...]")
    try:
        return tuple(items)
    except TypeError:
        raise TypeError(f"{name} = {_shown(items)} is not a sequence") from None


def _check_motion(x, v, n, *, prefix, finite) -> None:
    """Refuse positions x and velocities v not of shape (n, 3), or (with ``finite``) not finite."""
    for name, array in (("x", x), ("v", v)):
        shape = np.shape(array)
        if shape != (n, 3):
            hint = " (a state of another model?)" if prefix == "state." else ""
            raise ValueError(f"{prefix}{name} has shape {shape}, but the scene's model has {n} nodes: "
                             f"expected ({n}, 3){hint}")
    if not finite:
        return
    for name, array, what, unit in (("x", x, "position", "m"), ("v", v, "velocity", "m/s")):
        array = np.asarray(array)
        if np.isfinite(array).all():
            continue
        bad = ~np.isfinite(array).all(axis=1)
        node = int(np.flatnonzero(bad)[0])
        raise ValueError(f"{prefix}{name}[{node}] = {array[node].tolist()} {unit} is not finite (the {what} of "
                         f"node {node}; {int(bad.sum())} node(s) have a NaN or Inf {what})")
