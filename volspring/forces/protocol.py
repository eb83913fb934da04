"""The force protocol: what the scene asks of an external force, and nothing more.

A force is any object with

``accumulate(model, x, v, t, out)``
    add its forces [N], shape (n, 3), into ``out`` (x [m], v [m/s] of all n nodes, t [s]);

and, where it has them,

``jacobian(model, x, v, t) -> (dF_dx, dF_dv)``
    each a (3n, 3n) scipy sparse matrix or None: the implicit integrator and the static solve use
    it (a force without one is treated explicitly there);
``potential_energy(model, x, t) -> float``
    its potential [J]: energy diagnostics and the static solve's line search use it (a force
    without one is non-conservative).

The model is passed at every evaluation, so a field reads the masses (or anything else of the
model) when it is evaluated instead of holding a copy. :class:`~volspring.Scene` sorts its forces
by these protocols once (:func:`isinstance` with the runtime-checkable :class:`Force`,
:class:`HasJacobian`, :class:`HasPotential`) and owns the algebra: total external force, its
Jacobian and potential. Nothing else loops over forces.

Forces written for volspring 0.1 (``accumulate(x, v, t, out)`` without the model) keep working
for one release through :func:`as_force`, with a DeprecationWarning.
"""

from __future__ import annotations

import functools
import inspect
import warnings
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

from volspring._deprecation import REMOVED_IN
import numpy as np

if TYPE_CHECKING:
    from scipy import sparse
    from volspring.model import Model

__all__ = ["Force", "HasJacobian", "HasPotential", "as_force"]


@runtime_checkable
class Force(Protocol):
    """An external force: ``accumulate(model, x, v, t, out)`` adds its (n, 3) forces [N] into ``out``."""

    def accumulate(self, model: Model, x: np.ndarray, v: np.ndarray, t: float, out: np.ndarray) -> None: ...


@runtime_checkable
class HasJacobian(Protocol):
    """A force with ``jacobian(model, x, v, t) -> (dF_dx, dF_dv)``, (3n, 3n) sparse or None each."""

    def jacobian(self, model: Model, x: np.ndarray, v: np.ndarray,
                 t: float) -> tuple[sparse.spmatrix | None, sparse.spmatrix | None]: ...


@runtime_checkable
class HasPotential(Protocol):
    """A conservative force with ``potential_energy(model, x, t) -> float`` [J]."""

    def potential_energy(self, model: Model, x: np.ndarray, t: float) -> float: ...


def _takes_model(method) -> bool:
    """Whether a bound ``accumulate`` has the model parameter (5 arguments) or is 0.1's (4)."""
    try:
        parameters = inspect.signature(method).parameters.values()
    except (TypeError, ValueError):  # builtins without a signature: assume the current protocol
        return True
    positional = [p for p in parameters if p.kind in (p.POSITIONAL_ONLY, p.POSITIONAL_OR_KEYWORD)]
    return len(positional) != 4 or any(p.kind == p.VAR_POSITIONAL for p in parameters)


class _ModelFreeForce:
    """A 0.1 force (no model argument) behind the current protocol."""

    def __init__(self, force):
        self.force = force
        if callable(getattr(force, "jacobian", None)):
            self.jacobian = lambda model, x, v, t: force.jacobian(x, v, t)
        if callable(getattr(force, "potential_energy", None)):
            self.potential_energy = lambda model, x, t: force.potential_energy(x, t)

    def accumulate(self, model, x, v, t, out):
        self.force.accumulate(x, v, t, out)

    def __repr__(self) -> str:
        return repr(self.force)


def as_force(force: Any, *, name: str = "force") -> Force:
    """``force`` under the current protocol: itself, or a 0.1 force wrapped with a DeprecationWarning.

    Raises
    ------
    TypeError
        An object without a callable ``accumulate``.
    """
    if not callable(getattr(force, "accumulate", None)):
        raise TypeError(f"{name} = {force!r} has no accumulate(model, x, v, t, out) method")
    if _takes_model(force.accumulate):
        return force
    warnings.warn(f"{name} ({type(force).__name__}) has accumulate(x, v, t, out) without the model: this form is "
                  f"deprecated and will be removed in volspring {REMOVED_IN}; use accumulate(model, x, v, t, out) "
                  "(and jacobian(model, x, v, t), potential_energy(model, x, t))", DeprecationWarning, stacklevel=4)
    return _ModelFreeForce(force)


def legacy_positional(*names):
    """Class decorator: accept 0.1's positional arguments (``masses`` first) with a DeprecationWarning.

    The built-in fields take keywords only and read the masses from the model; a call with
    positional arguments is the 0.1 form ``Gravity(model.masses)``, ``Wind(masses, direction,
    speed, rate=...)``, mapped onto the keywords ``names`` in order.
    """
    def decorate(cls):
        init = cls.__init__

        @functools.wraps(init)
        def __init__(self, *args, **keywords):
            if args:
                if len(args) > len(names):
                    raise TypeError(f"{cls.__name__}() takes at most {len(names)} positional arguments in its "
                                    f"deprecated form ({', '.join(names)}), got {len(args)}")
                warnings.warn(f"{cls.__name__}({', '.join(names[:len(args)])}, ...) with positional arguments is "
                              f"deprecated and will be removed in volspring {REMOVED_IN}: pass keywords, and leave "
                              "masses out (they are read from the model)", DeprecationWarning, stacklevel=2)
                clash = sorted(set(names[:len(args)]) & set(keywords))
                if clash:
                    raise TypeError(f"{cls.__name__}() got {clash[0]!r} both by position and by keyword")
                keywords.update(zip(names, args))
            init(self, **keywords)

        cls.__init__ = __init__
        return cls

    return decorate
