"""A user force field: any function of positions, velocities and time, checked on every call."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable

import numpy as np

from volspring.material import _shown

if TYPE_CHECKING:
    from volspring.model import Model

__all__ = ["CallableForce", "PointLoads"]


class CallableForce:
    """A user field: ``function(x, v, t) -> (n, 3)`` forces [N], checked on every call.

    Parameters
    ----------
    function : callable
        ``function(x, v, t)`` with x, v (n, 3) [m], [m/s] and t [s], returning forces [N] of shape (n, 3); it must not
        modify x or v
    name : str, optional
        used in error messages (defaults to the function's name)

    Raises
    ------
    ValueError
        from :meth:`accumulate` if the function returns another shape or a non-finite value,
        naming the shape, the first bad node and the time.

    Examples
    --------
    >>> import numpy as np
    >>> from volspring import CallableForce, Model
    >>> one = Model.from_arrays([[0.1, 0, 0]], [1.0], [], stiffness=1.0)
    >>> spring_to_origin = CallableForce(lambda x, v, t: -10.0 * x)
    >>> out = np.zeros((1, 3))
    >>> spring_to_origin.accumulate(one, one.rest_positions, np.zeros((1, 3)), 0.0, out)
    >>> out.tolist()
    [[-1.0, 0.0, 0.0]]
    """

    def __init__(self, function: Callable, *, name: str | None = None):
        if not callable(function):
            raise TypeError(f"function = {_shown(function)} is not callable; expected f(x, v, t) -> (n, 3) forces")
        if name is not None and not isinstance(name, str):
            raise TypeError(f"name = {_shown(name)} is not a str")
        self.function = function
        self.name = name or getattr(function, "__name__", type(function).__name__)

    def __repr__(self) -> str:
        return f"CallableForce({self.name})"

    def accumulate(self, model: Model, x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray) -> None:
        value = self.function(x, v, t)
        try:
            forces = np.asarray(value, dtype=np.float64)
        except (TypeError, ValueError) as error:
            raise ValueError(f"force field {self.name}(x, v, t={t}) returned {type(value).__name__}, "
                             f"not an (n, 3) array of forces [N]: {error}") from error
        if forces.shape != out.shape:
            raise ValueError(f"force field {self.name}(x, v, t={t}) returned shape {forces.shape}, "
                             f"expected {out.shape} (one 3-vector [N] per node)")
        finite = np.isfinite(forces).all(axis=1)
        if not finite.all():
            node = int(np.flatnonzero(~finite)[0])
            raise ValueError(f"force field {self.name}(x, v, t={t}) returned {forces[node].tolist()} at node {node}; "
                             f"expected finite forces [N] ({(~finite).sum()} node(s) affected)")
        out += forces


@dataclass(frozen=True, eq=False)
class PointLoads:
    """Constant forces on the nodes (tractions lumped to nodes, point loads), with their potential.

    Parameters
    ----------
    forces : (n, 3) float
        force on every node [N] (zero rows for unloaded nodes)

    Examples
    --------
    >>> import numpy as np
    >>> from volspring import Model
    >>> from volspring.forces import PointLoads
    >>> one = Model.from_arrays([[0.0, 0, 0]], [1.0], [], stiffness=1.0)
    >>> load = PointLoads([[0.0, 0.0, -2.0]])
    >>> load.potential_energy(one, np.array([[0.0, 0.0, -1.0]]), 0.0)   # -f . x
    -2.0
    """

    forces: np.ndarray

    def __post_init__(self):
        forces = np.array(self.forces, dtype=np.float64)
        if forces.ndim != 2 or forces.shape[1] != 3 or not np.isfinite(forces).all():
            raise ValueError(f"PointLoads forces have shape {forces.shape} or non-finite values; expected finite (n, 3)")
        forces.setflags(write=False)
        object.__setattr__(self, "forces", forces)

    def accumulate(self, model: Model, x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray) -> None:
        out += self.forces

    def potential_energy(self, model: Model, x: np.ndarray, t: float) -> float:
        return float(-np.sum(self.forces * x))
