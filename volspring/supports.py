"""Supports: which degrees of freedom of which nodes are prescribed, and how they move.

A support holds some components (x, y, z) of some nodes:

:class:`Pins`
    whole nodes, held at rest or moved by ``motion(t)`` -- the shorthand for the common case;
:class:`Prescribed`
    chosen components of nodes, held at rest or moved by ``motion(t)`` (prescribed displacement);
:class:`Sliding`
    one component held at its rest value: the nodes slide in the plane normal to that axis
    (a symmetry plane, a frictionless wall).

A :class:`~volspring.Scene` takes any number of supports (``pins=`` and ``supports=``) and
compiles them into one (n, 3) mask of held components (:attr:`Scene.held`). Every integrator,
the static solve (:func:`volspring.statics.solve_static`) and the modal solve
(:func:`volspring.modes.solve_modes`) honour it: nodes held in all three components are
eliminated from the linear systems; partly held nodes keep their free components only
(:func:`volspring.assembly.eliminate_held`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from volspring.material import _shown

__all__ = ["Pins", "Prescribed", "Sliding", "components_mask"]

AXES = {"x": 0, "y": 1, "z": 2}
_ALL_COMPONENTS = np.ones(3, dtype=bool)
_ALL_COMPONENTS.setflags(write=False)


def components_mask(components: Any, *, label: str = "components") -> np.ndarray:
    """(3,) bool -- which of x, y, z a support holds: from a string ("xz"), axis indices ((0, 2)) or an axis.

    Raises
    ------
    ValueError
        An unknown axis letter or index, or no component at all.
    """
    if isinstance(components, (int, np.integer)) and not isinstance(components, bool):
        components = (int(components),)
    if isinstance(components, str):
        unknown = [c for c in components.lower() if c not in AXES]
        if unknown:
            raise ValueError(f"{label} = {components!r}: {unknown[0]!r} is not an axis; expected letters of 'xyz'")
        indices = [AXES[c] for c in components.lower()]
    else:
        try:
            indices = [int(c) for c in components]
        except (TypeError, ValueError):
            raise ValueError(f"{label} = {_shown(components)} is not axes: expected 'xyz' letters or indices 0-2") from None
        if any(i not in (0, 1, 2) or isinstance(c, bool) for i, c in zip(indices, components)):
            raise ValueError(f"{label} = {_shown(components)} holds an index outside 0, 1, 2")
    mask = np.zeros(3, dtype=bool)
    mask[indices] = True
    if not mask.any():
        raise ValueError(f"{label} = {components!r} names no component; expected at least one of x, y, z")
    mask.setflags(write=False)
    return mask


class _NodeSupport:
    """What every support shares: checked nodes, and positions and velocities of its held components."""

    held: np.ndarray  # (3,) bool, set by each class
    nodes: np.ndarray  # (p,) int64 after _prepare
    # Fields of Pins and Prescribed (Sliding has neither: read them only when `moving`).
    motion: Callable | None
    velocity: Callable | None

    def _prepare(self):
        label = type(self).__name__
        for name in ("motion", "velocity"):
            function = getattr(self, name, None)
            if function is not None and not callable(function):
                raise TypeError(f"{label} {name} = {_shown(function)} is not callable; expected {name}(t) -> (p, 3)")
        if getattr(self, "velocity", None) is not None and getattr(self, "motion", None) is None:
            raise ValueError(f"{label} velocity= was given without motion=; without motion the nodes "
                             "stay at rest, so give motion(t) too")
        nodes, mask_length = _node_indices(self.nodes, label)
        if nodes.size == 0:
            raise ValueError(f"{label} need at least one node" if mask_length is None else
                             f"{label} need at least one node: the mask's {mask_length} entries are all False")
        if getattr(self, "motion", None) is None:
            nodes = np.unique(nodes)
        else:
            unique, first = np.unique(nodes, return_index=True)
            if len(unique) < len(nodes):
                repeat = int(np.flatnonzero(~np.isin(np.arange(len(nodes)), first))[0])
                raise ValueError(f"{label} nodes[{repeat}] = {nodes[repeat]} is listed twice; with motion= each "
                                 "node must appear once (row k of motion(t) is the position of nodes[k])")
        nodes.setflags(write=False)
        object.__setattr__(self, "nodes", nodes)
        object.__setattr__(self, "mask_length", mask_length)

    @property
    def moving(self) -> bool:
        """Whether the held components follow a motion (else they stay at rest)."""
        return getattr(self, "motion", None) is not None

    def positions(self, rest_positions: np.ndarray, t: float) -> np.ndarray:
        """(p, 3) float -- where the nodes are at time t [m] (only the held components are used)."""
        motion = getattr(self, "motion", None)  # what `moving` tests
        if motion is None:
            return rest_positions[self.nodes]
        return self._checked(motion(t), "motion", t)

    def velocities(self, t: float) -> np.ndarray:
        """(p, 3) float -- velocities of the nodes at time t [m/s] (only the held components are used)."""
        motion = getattr(self, "motion", None)  # what `moving` tests
        if motion is None:
            return np.zeros((len(self.nodes), 3))
        if self.velocity is not None:
            return self._checked(self.velocity(t), "velocity", t)
        h = 1e-6  # central difference: O(h^2) error, far below any simulation step
        ahead, behind = (self._checked(motion(t + d), "motion", t) for d in (h, -h))
        return (ahead - behind) / (2 * h)

    def _checked(self, value, name, t):
        value = np.asarray(value, dtype=np.float64)
        if value.shape != (len(self.nodes), 3) or not np.isfinite(value).all():
            raise ValueError(f"{type(self).__name__}.{name}({t}) must return finite values of shape "
                             f"({len(self.nodes)}, 3), got shape {value.shape}")
        return value


@dataclass(frozen=True, eq=False)
class Pins(_NodeSupport):
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
        self._prepare()

    held = _ALL_COMPONENTS


@dataclass(frozen=True, eq=False)
class Prescribed(_NodeSupport):
    """Chosen components of nodes, held at rest or moved by ``motion`` (prescribed displacement).

    Parameters
    ----------
    nodes : (p,) int or (n,) bool
        as for :class:`Pins`
    components : str or sequence of int
        the held components, e.g. ``"x"``, ``"xz"``, ``(0, 2)``
    motion : callable, optional
        ``motion(t) -> (p, 3)`` positions [m]; only the held components are used (the others are free)
    velocity : callable, optional
        ``velocity(t) -> (p, 3)`` [m/s], only with ``motion``

    Examples
    --------
    Stretch a bar by pulling its end face along x while y and z stay free:

    >>> from volspring.supports import Prescribed
    >>> pull = Prescribed([4, 5], "x", motion=lambda t: [[1.0 + 0.01 * t, 0, 0], [1.0 + 0.01 * t, 1, 0]])
    >>> pull.held.tolist()
    [True, False, False]
    """

    nodes: np.ndarray
    components: object = "xyz"
    motion: Callable | None = None
    velocity: Callable | None = None
    mask_length: int | None = field(default=None, init=False, repr=False)

    def __post_init__(self):
        object.__setattr__(self, "held", components_mask(self.components, label="Prescribed components"))
        self._prepare()

    @classmethod
    def at(cls, nodes: np.ndarray, components: Any, positions: np.ndarray) -> "Prescribed":
        """Components held at fixed ``positions`` (p, 3) [m] (e.g. rest positions plus a displacement).

        The motion is a picklable constant, so scenes built this way can be sent to other processes.
        """
        positions = np.array(positions, dtype=np.float64)
        return cls(nodes, components, motion=_Stationary(positions), velocity=_Stationary(np.zeros_like(positions)))


@dataclass(frozen=True, eq=False)
class Sliding(_NodeSupport):
    """Nodes that slide in a plane: the component along ``normal`` is held at its rest value.

    Parameters
    ----------
    nodes : (p,) int or (n,) bool
        as for :class:`Pins`
    normal : {"x", "y", "z"} or {0, 1, 2}
        the axis normal to the plane (the held component)

    Examples
    --------
    >>> from volspring.supports import Sliding
    >>> Sliding([0, 1, 2], "z").held.tolist()   # free in x and y, held in z
    [False, False, True]
    """

    nodes: np.ndarray
    normal: object
    mask_length: int | None = field(default=None, init=False, repr=False)

    def __post_init__(self):
        held = components_mask(self.normal, label="Sliding normal")
        if held.sum() != 1:
            raise ValueError(f"Sliding normal = {self.normal!r} names {int(held.sum())} axes; expected one of x, y, z")
        object.__setattr__(self, "held", held)
        self._prepare()


@dataclass(frozen=True, eq=False)
class _Stationary:
    """A constant function of time (picklable, unlike a lambda)."""

    value: np.ndarray

    def __call__(self, t) -> np.ndarray:
        return self.value


def _node_indices(nodes, label="Pins"):
    """(p,) int64 node indices from what a support was given, and the mask's length (None for indices)."""
    if isinstance(nodes, (bool, np.bool_)):
        raise TypeError(f"{label} nodes = {nodes!r} is a bool; expected node indices or a boolean mask "
                        "with one entry per node")
    try:
        array = np.asarray(nodes)
    except ValueError as error:  # ragged nested sequences
        raise ValueError(f"{label} nodes = {_shown(nodes)} is not a regular array: {error}") from None
    if array.size == 0 and array.dtype.kind != "b":  # [] is a float64 array
        return np.zeros(0, dtype=np.int64), None
    if array.dtype.kind == "b":
        if array.ndim != 1:
            raise ValueError(f"{label} nodes is a boolean mask of shape {array.shape}; expected shape (n,), "
                             "one entry per node")
        return np.flatnonzero(array), len(array)
    if array.dtype.kind in "iu" and not isinstance(nodes, np.ndarray):
        # [True, 2] becomes the integers [1, 2]: refuse a list that mixes bools and integers
        items = np.asarray(nodes, dtype=object).ravel()
        mixed = [k for k, item in enumerate(items) if isinstance(item, (bool, np.bool_))]
        if mixed:
            raise TypeError(f"{label} nodes[{mixed[0]}] = {items[mixed[0]]!r} is a bool among integers; expected "
                            "node indices, or a boolean mask with one entry per node")
    if array.dtype.kind == "f":
        flat = array.ravel()
        fractional = np.flatnonzero(~np.isfinite(flat) | (flat != np.round(flat)))
        if fractional.size:
            k = int(fractional[0])
            raise TypeError(f"{label} nodes[{k}] = {flat[k]} is not an integer node index")
        raise TypeError(f"{label} nodes are {array.dtype} values, not integer node indices; convert "
                        "integer-valued floats with np.asarray(nodes, dtype=int)")
    if array.dtype.kind not in "iu":
        raise TypeError(f"{label} nodes = {_shown(nodes)} are not integer node indices or a boolean mask "
                        f"(got dtype {array.dtype})")
    indices = array.astype(np.int64).ravel()
    negative = np.flatnonzero(indices < 0)
    if negative.size:
        k = int(negative[0])
        raise ValueError(f"{label} nodes[{k}] = {indices[k]} is negative; expected node indices >= 0 "
                         "(they do not count from the end)")
    return indices, None


