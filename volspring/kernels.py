"""Compiled kernels for the implicit step's hot loops: optional, and never a change of result.

The implicit step spends a quarter of its time outside the linear solve, much of it in the springs'
forces, Jacobian blocks and stiffness product, which numpy does as several passes over arrays of the
springs' size (gathers, lengths, outer products, scatters), each with its own temporary; the upper
rungs of the ladder add the polar decomposition of every tet's and node's deformation gradient,
whose Jacobi rotations numpy does as dozens of vector operations a sweep; an AMG build spends
three quarters of its time in scipy's block sparse products, whose loops do not know the block sizes,
and splits the finest level into point-wise triangles in several passes and copies;
and the solve spends its time in scipy's products with the 3x3-block system and in the multigrid
cycle's finest level, a dozen Python calls and temporaries around each of its sweeps.
With numba installed (``pip install 'volspring[fast]'``) the same arithmetic runs in compiled loops
(:mod:`volspring._compiled`).

The compiled kernels give the numpy code's results bit for bit: every sum is taken in the order
numpy and scipy take it (a spring's length as numpy's ``einsum`` sums its three squares, a node's
force in the order of the scatter matrix's rows, a block product's blocks in the order scipy's
``bsr_matmat`` makes and sums them), so a run is the same with or without numba, and a checkpoint
written by one resumes in the other. The tests marked ``fast`` check this on every kernel, on a
multigrid hierarchy and on whole runs.

Which code runs:

- ``auto`` (the default): the kernels when numba imports, numpy otherwise;
- ``numba``: the kernels, and an error if numba is missing;
- ``numpy``: numpy only.

Set it with the environment variable ``VOLSPRING_KERNELS`` (read at the first step) or with
:func:`select` (``select("numpy")`` to time the two against each other in one process). The first
process to use the kernels compiles them (about 3 s here) into numba's cache on disk; later ones load
them from it (0.2 s with numba's import).
"""

from __future__ import annotations

import importlib
import logging
import os
from types import ModuleType

import numpy as np

__all__ = ["CHOICES", "active", "select", "unsigned"]

logger = logging.getLogger(__name__)

CHOICES = ("auto", "numba", "numpy")
ENVIRONMENT_VARIABLE = "VOLSPRING_KERNELS"

_choice: str | None = None  # None: not chosen yet (the environment variable, else auto, at first use)
_module: ModuleType | None = None  # the compiled kernels, once imported
_missing: str | None = None  # why numba did not import, once tried (not tried again on every step)


def select(choice: str) -> str:
    """Choose which code the hot loops run (see the module docstring).

    Parameters
    ----------
    choice : str
        ``"auto"``, ``"numba"`` or ``"numpy"``

    Returns
    -------
    str
        what runs from now on: ``"numba"`` or ``"numpy"``

    Raises
    ------
    ValueError
        for another choice
    ImportError
        for ``"numba"`` when numba does not import
    """
    global _choice
    if choice not in CHOICES:
        raise ValueError(f"kernels = {choice!r}; expected one of {', '.join(map(repr, CHOICES))}")
    if choice == "numba":
        _load(required=True)
    _choice = choice
    return active()


def active() -> str:
    """``"numba"`` or ``"numpy"``: what the hot loops run now."""
    return "numpy" if compiled() is None else "numba"


def compiled() -> ModuleType | None:
    """The compiled kernels (:mod:`volspring._compiled`) when they are to run, else None."""
    global _choice
    if _choice is None:
        requested = os.environ.get(ENVIRONMENT_VARIABLE, "auto").strip().lower() or "auto"
        if requested not in CHOICES:
            raise ValueError(f"{ENVIRONMENT_VARIABLE} = {requested!r}; expected one of "
                             f"{', '.join(map(repr, CHOICES))}")
        if requested == "numba":
            _load(required=True)
        _choice = requested
    if _choice == "numpy":
        return None
    return _load(required=_choice == "numba")


def unsigned(indices: np.ndarray) -> np.ndarray:
    """The same non-negative integer array viewed as unsigned, for a kernel to index with: numba checks every
    signed index for a negative value to wrap around, which made a gather-and-scatter loop 2.2x slower (1.29
    against 0.57 ms for stop 39's per-tet shear product on the README beam's smoothed rung)."""
    return indices.view(np.dtype(f"uint{8 * indices.dtype.itemsize}"))


def _load(*, required: bool) -> ModuleType | None:
    global _module, _missing
    if _module is None and _missing is None:
        try:
            importlib.import_module("numba")
        except ImportError as error:  # absent, or installed but unusable (numba refuses a numpy it does not support)
            _missing = str(error)
            if not (isinstance(error, ModuleNotFoundError) and error.name == "numba"):
                logger.warning("numba is installed but does not import (%s): the hot loops run in numpy", error)
        else:
            _module = importlib.import_module("volspring._compiled")  # an error here is ours: it propagates
    if _module is None and required:
        raise ImportError(f"the numba kernels were asked for ({ENVIRONMENT_VARIABLE} or volspring.kernels.select) "
                          f"but numba does not import ({_missing}); install the fast extra: "
                          "pip install 'volspring[fast]'")
    return _module
