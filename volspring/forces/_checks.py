"""Input checks and small kernels shared by the built-in forces.

A TypeError for what is not numbers at all (bools, strings, via :mod:`volspring.material`), a
ValueError for numbers of the wrong shape or range, each naming the value.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse as sp

from volspring.material import _real_array, _real_number, _shown
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from volspring.model import Model


def masses_or_none(masses, *, allow_zero=False):
    """None (read the masses from the model), or (n,) float read-only node masses, finite and > 0
    (>= 0 with ``allow_zero``) [kg]."""
    if masses is None:
        return None
    masses = _real_array("masses", masses)
    if masses.ndim != 1 or masses.size == 0:
        raise ValueError(f"masses must have shape (n,) with n > 0, got {masses.shape}")
    bad = ~np.isfinite(masses) | (masses < 0) | ((masses == 0) & (not allow_zero))
    if bad.any():
        first = int(np.flatnonzero(bad)[0])
        expected = ">= 0" if allow_zero else "> 0"
        raise ValueError(f"masses[{first}] = {masses[first]} kg is not finite and {expected}")
    masses.setflags(write=False)
    return masses


class MassProportional:
    """Mixin of the fields f_i = m_i a_i: the masses given (0.1's form) or else the model's."""

    masses: np.ndarray | None  # a field of every class that mixes this in

    def masses_of(self, model: Model) -> np.ndarray:
        """(n,) float -- the masses this field weighs with [kg]."""
        return model.masses if self.masses is None else self.masses


def vector(name, value, *, unit=False) -> np.ndarray:
    """(3,) float, read-only -- a finite 3-vector (normalised with ``unit``)."""
    array = _real_array(name, value)
    if array.shape != (3,) or not np.isfinite(array).all():
        raise ValueError(f"{name} = {_shown(value)} is not a finite 3-vector (got shape {array.shape})")
    if unit:
        norm = np.linalg.norm(array)
        if norm == 0:
            raise ValueError(f"{name} = {_shown(value)} has zero length; expected a direction")
        array = array / norm
    array.setflags(write=False)
    return array


def finite(name, value, *, positive=False, nonnegative=False) -> float:
    """A finite real number (> 0 with ``positive``, >= 0 with ``nonnegative``) as a float."""
    value = _real_number(name, value)
    if positive and not (math.isfinite(value) and value > 0):
        raise ValueError(f"{name} = {value} is not finite and > 0")
    if nonnegative and not (math.isfinite(value) and value >= 0):
        raise ValueError(f"{name} = {value} is not finite and >= 0")
    if not math.isfinite(value):
        raise ValueError(f"{name} = {value} is not a finite number")
    return value


def flag(name, value) -> bool:
    """A bool (Python or numpy); a TypeError naming ``name`` for anything else ("no" is not False)."""
    if not isinstance(value, (bool, np.bool_)):
        raise TypeError(f"{name} = {_shown(value)} is not a bool")
    return bool(value)


def block_diagonal(blocks) -> sp.csr_matrix:
    """(3n, 3n) sparse matrix with the (n, 3, 3) blocks on its diagonal."""
    n = len(blocks)
    return sp.bsr_matrix((blocks, np.arange(n), np.arange(n + 1)), shape=(3 * n, 3 * n)).tocsr()


def radial_blocks(direction, radial, transverse) -> np.ndarray:
    """(n, 3, 3) blocks ``radial r r^T + transverse (I - r r^T)`` for unit directions r (n, 3)."""
    outer = direction[:, :, None] * direction[:, None, :]
    blocks = outer * (radial - transverse)[:, None, None]
    blocks[:, [0, 1, 2], [0, 1, 2]] += transverse[:, None]
    return blocks
