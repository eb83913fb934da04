"""A scene: a model plus exactly the forces, pins and obstacles it asks for, and the state.

The data path is ``Scene(model, forces=..., pins=...)`` -> ``scene.initial_state()`` ->
``integrator.step(scene, state, dt)`` -> next ``State``. The scene is static; the state changes.

Forces follow the protocol of :mod:`volspring.forces.protocol` (``accumulate(model, x, v, t,
out)``, optional ``jacobian`` and ``potential_energy``). The scene owns the algebra: total
force (:meth:`Scene.forces_at`: the model's element sets plus the external forces), the
external forces' Jacobian (:meth:`Scene.external_jacobian`) and the potential energy
(:meth:`Scene.potential_energy`). Integrators, statics and diagnostics call these and never
loop over forces themselves.

Input is checked where it enters: constructors refuse what is not numbers (TypeError) and numbers
of the wrong shape, range or finiteness (ValueError), naming the value; a scene refuses pins and
mass arrays that do not fit its model; :meth:`Scene.check_state` refuses a state that does not
(an integrator's ``step`` checks its shapes at every step).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from volspring.forces import HasJacobian, HasPotential, as_force
from volspring.forces._checks import MassProportional
from volspring.material import _real_array, _real_number, _shown
from volspring.supports import Pins, Prescribed, Sliding
from volspring.model import Model
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from collections.abc import Iterable

    from numpy.typing import ArrayLike

__all__ = ["State", "Pins", "Scene"]


@dataclass(frozen=True, eq=False)
class State:
    """The changing part of a simulation. Treat its arrays as read-only.

    Parameters
    ----------
    x : (n, 3) float
        positions [m]
    v : (n, 3) float
        velocities [m/s]
    t : float
        time [s]
    step : int
        number of steps taken to reach this state
    memory : dict
        what an integrator carries from step to step (previous positions and step of the Verlet family, the implicit
        solver's warm start); part of the state so that a checkpoint of the state resumes bit-identically
    """

    x: np.ndarray
    v: np.ndarray
    t: float = 0.0
    step: int = 0
    memory: dict = field(default_factory=dict)

    def replace(self, **changes: Any) -> "State":
        return replace(self, **changes)


@dataclass(frozen=True, eq=False)
class Scene:
    """A spring model with the forces, pins, obstacles and constraints a simulation asks for.

    Parameters
    ----------
    model : Model
    forces : sequence of force objects
        (see the module docstring), e.g. ``Gravity``, ``Drag``
    pins : Pins, optional
        whole nodes held or moved (the shorthand support)
    obstacles : sequence
        non-penetration obstacles, projected after each step
    constraints : sequence
        position projections (distance constraints, strain limiting; meant for the Verlet family), projected after each
        step
    supports : sequence of Pins, Prescribed or Sliding
        supports per component (:mod:`volspring.supports`), beside ``pins``

    Attributes
    ----------
    held : (n, 3) bool
        the components any support prescribes (read-only)
    free : (n,) bool
        nodes with at least one free component
    model : Model
        the model given, adapted to the nodes the supports hold in all three components (:meth:`Model.supported`): the
        smoothed rung pairs its volume domains anew so that no domain is held whole (a domain of held nodes only would
        lock the free nodes around it); any other model, or a scene without supports, keeps the very model given

    Raises
    ------
    TypeError
        A model that is not a Model, pins that are not a Pins, a single force instead of a
        sequence, a force without ``accumulate`` or an obstacle or constraint without ``project``.
    ValueError
        A pinned node the model does not have, a pin mask of another length, or a built-in force
        (Gravity, Drag, Wind, PointAttractor, PointRepulser, Vortex) whose masses are not one per node.

    Notes
    -----
    Obstacles and constraints have ``project(x, v, x_start, t, dt, free)``: after a step from
    ``x_start`` they move the free nodes' positions ``x`` (and fix velocities ``v``) in place.
    """

    model: Model
    forces: tuple = ()
    pins: Pins | None = None
    obstacles: tuple = ()
    constraints: tuple = ()
    supports: tuple = ()
    held: np.ndarray = field(init=False, repr=False)

    if TYPE_CHECKING:  # what the constructor takes: any iterables, stored as tuples (__post_init__)
        def __init__(self, model: Model, forces: Iterable[Any] = (), pins: Pins | None = None,
                     obstacles: Iterable[Any] = (), constraints: Iterable[Any] = (),
                     supports: Iterable[Pins | Prescribed | Sliding] = ()) -> None: ...

    def __post_init__(self):
        if not isinstance(self.model, Model):
            raise TypeError(f"model must be a volspring Model, got {type(self.model).__name__}")
        n = self.model.node_count
        forces = _sequence("forces", self.forces, "accumulate")
        checked = []
        for index, force in enumerate(forces):  # a loop, not a generator: a 0.1 force's warning points at Scene(...)
            checked.append(as_force(force, name=f"forces[{index}]"))
        object.__setattr__(self, "forces", tuple(checked))
        for name, method, arguments in (("obstacles", "project", "x, v, x_start, t, dt, free"),
                                        ("constraints", "project", "x, v, x_start, t, dt, free")):
            items = _sequence(name, getattr(self, name), method)
            for index, item in enumerate(items):
                if not callable(getattr(item, method, None)):
                    raise TypeError(f"{name}[{index}] = {_shown(item)} has no {method}({arguments}) method")
            object.__setattr__(self, name, items)
        for index, force in enumerate(self.forces):
            if isinstance(force, MassProportional) and force.masses is not None and force.masses.shape != (n,):
                raise ValueError(f"forces[{index}] ({type(force).__name__}) has {len(force.masses)} masses, but the "
                                 f"model has {n} nodes; expected one mass per node (model.masses)")
        if self.pins is not None and not isinstance(self.pins, Pins):
            raise TypeError(f"pins = {_shown(self.pins)} is not a volspring Pins; expected e.g. pins=Pins([0, 1])")
        supports = _sequence("supports", self.supports, "held")
        for index, support in enumerate(supports):
            if not isinstance(support, _SUPPORTS):
                raise TypeError(f"supports[{index}] = {_shown(support)} is not a volspring support; expected "
                                "Pins, Prescribed or Sliding")
        object.__setattr__(self, "supports", supports)
        held = np.zeros((n, 3), dtype=bool)
        for support in self.all_supports:
            label = type(support).__name__
            if support.mask_length is not None and support.mask_length != n:
                raise ValueError(f"{label} were given a boolean mask of {support.mask_length} entries, but the "
                                 f"model has {n} nodes; expected one entry per node")
            if support.nodes.max() >= n:
                what = "pinned node" if isinstance(support, Pins) else f"{label} node"
                raise ValueError(f"{what} {support.nodes.max()} does not exist: the model has {n} "
                                 f"nodes (indices 0 to {n - 1})")
            twice = held[support.nodes] & support.held
            if twice.any():
                node = int(support.nodes[np.flatnonzero(twice.any(axis=1))[0]])
                raise ValueError(f"node {node} is held twice in the same component (by {label} and an earlier "
                                 "support); hold each component of a node by one support")
            held[support.nodes] |= support.held
        held.setflags(write=False)
        object.__setattr__(self, "held", held)
        # The model's discretisation where it depends on the supports (the smoothed rung's volume pairs).
        object.__setattr__(self, "model", self.model.supported(np.all(held, axis=1)))

    @property
    def all_supports(self) -> tuple:
        """The pins (if any) and the other supports, in that order."""
        return ((self.pins,) if self.pins is not None else ()) + tuple(self.supports)

    @cached_property
    def free(self) -> np.ndarray:
        """(n,) bool -- nodes with at least one free component (the unknowns of the linear systems)."""
        return ~np.all(self.held, axis=1)

    @cached_property
    def partly_held(self) -> bool:
        """Whether some node is held in some components but free in others (sliding, prescribed)."""
        return bool((self.held.any(axis=1) & self.free).any())

    def initial_state(self, x: np.ndarray | None = None, v: ArrayLike | None = None, t: float = 0.0) -> State:
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
        self.enforce_supports(x, v, t)
        return State(x, v, t)

    def check_state(self, state: State, *, finite: bool = True) -> None:
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
        >>> from volspring import Scene, Model
        >>> scene = Scene(Model.from_arrays([[0, 0, 0], [1, 0, 0]], [1.0, 1.0], [[0, 1]], stiffness=1.0))
        >>> other = Scene(Model.from_arrays([[0, 0, 0]], [1.0], [], stiffness=1.0))
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

    def support_motion(self, t: float) -> tuple:
        """(positions (n, 3) [m], velocities (n, 3) [m/s]) the supports prescribe at time t; only the
        entries where :attr:`held` is True mean anything (the rest are 0)."""
        positions, velocities = np.zeros((self.model.node_count, 3)), np.zeros((self.model.node_count, 3))
        for support in self.all_supports:
            held = support.held
            positions[support.nodes[:, None], np.flatnonzero(held)] = \
                support.positions(self.model.rest_positions, t)[:, held]
            velocities[support.nodes[:, None], np.flatnonzero(held)] = support.velocities(t)[:, held]
        return positions, velocities

    def enforce_supports(self, x: np.ndarray, v: np.ndarray, t: float) -> None:
        """Set the held components of positions and velocities to what the supports prescribe at t, in place."""
        if not self.all_supports:
            return
        positions, velocities = self.support_motion(t)
        x[self.held] = positions[self.held]
        v[self.held] = velocities[self.held]

    enforce_pins = enforce_supports

    def project(self, x: np.ndarray, v: np.ndarray, x_start: np.ndarray, t: float, dt: float) -> None:
        """After a step: project constraints, then obstacles, then put held components back, in place."""
        for item in self.constraints + self.obstacles:
            item.project(x, v, x_start, t, dt, self.free)
        self.enforce_supports(x, v, t)

    # ------------------------------------------------------------------ the algebra of the forces
    @cached_property
    def conservative(self) -> bool:
        """Whether every external force has a potential (the model's element sets all have one)."""
        return all(isinstance(force, HasPotential) for force in self.forces)

    @cached_property
    def _jacobian_forces(self) -> tuple:
        """The external forces with a Jacobian, found once (a runtime protocol check costs 6 us a force and step)."""
        return tuple(force for force in self.forces if isinstance(force, HasJacobian))

    def external_forces(self, x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray | None = None, *,
                        conservative: bool | None = None) -> np.ndarray:
        """(n, 3) float -- the external forces on every node [N], added into ``out`` when given.

        ``conservative=False`` sums only the forces without a potential (whose work energy
        bookkeeping must track), ``True`` only those with one; ``None`` all.
        """
        out = np.zeros((self.model.node_count, 3)) if out is None else out
        for force in self.forces:
            if conservative is None or isinstance(force, HasPotential) == conservative:
                force.accumulate(self.model, x, v, t, out)
        return out

    def forces_at(self, x: np.ndarray, v: np.ndarray, t: float) -> np.ndarray:
        """(n, 3) float -- total force on every node [N]: the model's element sets and the external forces."""
        return self.external_forces(x, v, t, out=self.model.forces(x, v))

    def external_jacobian(self, x: np.ndarray, v: np.ndarray, t: float) -> tuple:
        """(dF_dx, dF_dv) of the external forces, each (3n, 3n) sparse or None where no force has one.

        Forces without a ``jacobian`` are left out (they are treated explicitly by the implicit
        integrator); the element sets' Jacobians are assembled block by block instead
        (:class:`volspring.assembly.BlockPattern`).
        """
        dfdx = dfdv = None
        for force in self._jacobian_forces:
            jx, jv = force.jacobian(self.model, x, v, t)
            if jx is not None:
                dfdx = jx if dfdx is None else dfdx + jx
            if jv is not None:
                dfdv = jv if dfdv is None else dfdv + jv
        return dfdx, dfdv

    def external_potential(self, x: np.ndarray, t: float = 0.0) -> float:
        """Potential of the conservative external forces [J] (non-conservative ones contribute nothing)."""
        return float(sum(force.potential_energy(self.model, x, t) for force in self.forces
                         if isinstance(force, HasPotential)))

    def accelerations(self, x: np.ndarray, v: np.ndarray, t: float) -> np.ndarray:
        """(n, 3) float -- F / m [m/s^2], 0 on held components (their motion is set by :meth:`enforce_supports`)."""
        a = self.forces_at(x, v, t) / self.model.masses[:, None]
        a[self.held] = 0.0
        return a

    def potential_energy(self, x: np.ndarray, t: float = 0.0) -> float:
        """Energy of the element sets plus the potential of every conservative external force [J]."""
        return self.model.energy(x) + self.external_potential(x, t)

    def kinetic_energy(self, v: np.ndarray) -> float:
        return float(0.5 * np.dot(self.model.masses, np.einsum("ij,ij->i", v, v)))


_SUPPORTS = (Pins, Prescribed, Sliding)


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


def __getattr__(name):
    # Gravity and Drag lived here in 0.1; they are forces now, beside the others.
    from volspring._deprecation import deprecated_alias
    from volspring.forces import Drag, Gravity

    return deprecated_alias(__name__, name, {"Gravity": ("volspring.Gravity", Gravity),
                                             "Drag": ("volspring.Drag", Drag)})
