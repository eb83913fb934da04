"""Position constraints projected after each step: distances and strain limits.

Both follow the scene's projection protocol (see :class:`volspring.Scene`), as does the obstacle
:class:`~volspring.collision.obstacles.HalfSpace` (defined there, with the other obstacles, and
still importable from here):
``project(x, v, x_start, t, dt, free)`` moves the free nodes' positions ``x`` and fixes their
velocities ``v`` in place after a step from ``x_start``. Pinned nodes (``free`` False) never
move: they count as infinitely heavy. Prescribed motion is :class:`volspring.Pins`' job.

Velocities. A projection that moves a node by dx also changes its velocity by dx / dt, so that
velocity-based integrators (Euler, RK) see the same motion as the positions. For the Verlet
family the history is positions (the previous positions in ``State.memory``), so the projected x
alone carries the correction; the velocity update then only keeps ``v`` consistent for outputs.

Distance constraints and strain limits are solved by Gauss-Seidel relaxation, vectorised by graph
colouring: the constraints are split into colours whose constraints share no node, and each colour
is projected at once (a batch of independent updates, so exactly Gauss-Seidel), colour after
colour, sweep after sweep. Corrections are mass-weighted (inverse masses w = 1/m, 0 if pinned), so
a projection never changes the momentum of the free nodes.
"""

from __future__ import annotations

import logging
import math
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from volspring.collision.obstacles import HalfSpace  # re-exported: volspring.constraints.HalfSpace keeps working

if TYPE_CHECKING:
    from numpy.typing import ArrayLike
    from volspring.model import Model

__all__ = ["HalfSpace", "DistanceConstraints", "StrainLimit", "RelaxationReport", "constraint_colors"]

logger = logging.getLogger(__name__)


# ---------------------------------------------------------------------------- colouring
def constraint_colors(pairs: ArrayLike, *, node_count: int | None = None, seed: int = 0) -> np.ndarray:
    """Colour node pairs so that no two pairs of one colour share a node.

    Each colour is a maximal matching built by Luby's rounds, vectorised: among the pairs still
    free to join the colour, those whose random priority is the smallest at both their nodes join
    it, until no pair can. Greedy matchings need at most 2 d - 1 colours (d the largest node
    degree); tet meshes get close to d.

    Parameters
    ----------
    pairs : (s, 2) int
        node pairs
    node_count : int, optional
        number of nodes (default: largest index + 1)
    seed : int
        seed of the random priorities (the colouring is deterministic given it)

    Returns
    -------
    (s,) int
        colour of each pair, 0 .. colours - 1

    Examples
    --------
    >>> from volspring.constraints import constraint_colors
    >>> colors = constraint_colors([[0, 1], [1, 2], [2, 3]])  # a chain: 2 colours alternate
    >>> bool(colors[0] != colors[1] and colors[1] != colors[2])
    True
    """
    pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    count = len(pairs)
    colors = np.full(count, -1, dtype=np.int64)
    if count == 0:
        return colors
    n = int(pairs.max()) + 1 if node_count is None else int(node_count)
    if pairs.min() < 0 or pairs.max() >= n:
        raise ValueError(f"pairs index nodes in [{pairs.min()}, {pairs.max()}], expected [0, {n - 1}]")
    if (pairs[:, 0] == pairs[:, 1]).any():
        raise ValueError(f"pair {np.flatnonzero(pairs[:, 0] == pairs[:, 1])[0]} joins a node to itself")
    priority = np.random.default_rng(seed).permutation(count)
    remaining = np.arange(count)
    color = 0
    while remaining.size:
        used = np.zeros(n, dtype=bool)
        candidates = remaining
        while candidates.size:
            a, b = pairs[candidates].T
            best = np.full(n, count, dtype=np.int64)
            np.minimum.at(best, a, priority[candidates])
            np.minimum.at(best, b, priority[candidates])
            wins = (best[a] == priority[candidates]) & (best[b] == priority[candidates])
            colors[candidates[wins]] = color
            used[a[wins]] = True
            used[b[wins]] = True
            candidates = candidates[~(used[a] | used[b])]
        remaining = remaining[colors[remaining] < 0]
        color += 1
    return colors


# ---------------------------------------------------------------------------- relaxation
_XYZ = np.arange(3)
_TINY = 1e-300  # [m], guards the division by a zero length


class RelaxationReport(NamedTuple):
    """What one relaxation did.

    Attributes
    ----------
    sweeps : int
        Gauss-Seidel sweeps over all colours
    violation : float
        largest relative violation |l - target| / l0 met in the last sweep, before that sweep corrected it (an upper
        estimate of what is left)
    """

    sweeps: int
    violation: float


class _PairProjection:
    """Mass-weighted projection of node pairs onto target lengths, coloured Gauss-Seidel."""

    def __init__(self, masses, pairs, lengths, *, iterations, stiffness, tolerance):
        masses = np.asarray(masses, dtype=np.float64)
        if masses.ndim != 1 or not (np.isfinite(masses).all() and (masses > 0).all()):
            raise ValueError(f"masses must be (n,) finite and > 0 [kg], got shape {masses.shape}")
        pairs = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
        lengths = np.broadcast_to(np.asarray(lengths, dtype=np.float64), (len(pairs),))
        bad = ~np.isfinite(lengths) | (lengths <= 0)
        if bad.any():
            first = int(np.flatnonzero(bad)[0])
            raise ValueError(f"lengths[{first}] = {lengths[first]} m is not finite and > 0")
        if not (isinstance(iterations, (int, np.integer)) and iterations >= 1):
            raise ValueError(f"iterations = {iterations!r} is not an integer >= 1")
        if not (0.0 < stiffness <= 1.0):
            raise ValueError(f"stiffness = {stiffness} is not in (0, 1]")
        if not (math.isfinite(tolerance) and tolerance >= 0):
            raise ValueError(f"tolerance = {tolerance} is not finite and >= 0")
        self.inverse_masses = 1.0 / masses
        self.pairs = pairs
        self.lengths = lengths.copy()
        self.iterations = int(iterations)
        self.stiffness = float(stiffness)
        self.tolerance = float(tolerance)
        self.colors = constraint_colors(pairs, node_count=len(masses))
        order = np.argsort(self.colors, kind="stable")
        bounds = np.searchsorted(self.colors[order], np.arange(self.color_count + 1))
        self._batches = [order[start:stop] for start, stop in zip(bounds[:-1], bounds[1:])]
        for array in (self.inverse_masses, self.pairs, self.lengths, self.colors):
            array.setflags(write=False)

    @property
    def constraint_count(self) -> int:
        return len(self.pairs)

    @property
    def color_count(self) -> int:
        return int(self.colors.max()) + 1 if len(self.colors) else 0

    def __repr__(self) -> str:
        return (f"{type(self).__name__}({self.constraint_count} constraints in {self.color_count} colours, "
                f"iterations={self.iterations})")

    def _targets(self, length, rest):
        """Target lengths for current lengths ``length`` and rest lengths ``rest`` [m]."""
        raise NotImplementedError

    def violations(self, x: np.ndarray) -> np.ndarray:
        """(s,) float -- relative violation (l - target) / l0 of every constraint at positions x."""
        i, j = self.pairs.T
        length = np.linalg.norm(x[j] - x[i], axis=1)
        return (length - self._targets(length, self.lengths)) / self.lengths

    def relax(self, x: np.ndarray, free: np.ndarray | None = None, *,
              iterations: int | None = None) -> RelaxationReport:
        """Project x in place: Gauss-Seidel sweeps, colour by colour, until the tolerance is met.

        Parameters
        ----------
        x : (n, 3) float
            positions [m], changed in place
        free : (n,) bool, optional
            nodes that may move (default all); the others are infinitely heavy
        iterations : int, optional
            the largest number of sweeps (default: ``self.iterations``)

        Returns
        -------
        RelaxationReport
        """
        weights = self.inverse_masses if free is None else np.where(free, self.inverse_masses, 0.0)
        sweeps = self.iterations if iterations is None else int(iterations)
        # One gather of both ends per colour (np.take, several times faster than x[i] fancy indexing
        # of (n, 3) rows) and one scatter through flat indices; pairs of one colour share no node, so
        # plain writes are exact. Few numpy calls per colour: on small models their overhead dominates.
        flat = x.reshape(-1) if x.flags.c_contiguous else np.ascontiguousarray(x).reshape(-1)
        points = flat.reshape(-1, 3)
        batches = []
        for batch in self._batches:
            ends = self.pairs[batch].T  # (2, k)
            w = weights[ends]
            total = w[0] + w[1]
            share = np.divide(self.stiffness, total, out=np.zeros_like(total), where=total > 0)
            signed = np.stack([w[0] * share, -w[1] * share])[:, :, None]  # (2, k, 1)
            rest = self.lengths[batch]
            batches.append((ends, (3 * ends[:, :, None] + _XYZ).ravel(), signed, rest, 1.0 / rest))
        violation, done = 0.0, 0
        for done in range(1, sweeps + 1):
            track = self.tolerance > 0 or done == sweeps
            violation = 0.0
            for ends, flat_ends, signed, rest, inverse_rest in batches:
                both = np.take(points, ends, axis=0)  # (2, k, 3)
                d = both[1] - both[0]
                length = np.sqrt(np.einsum("ij,ij->i", d, d))
                error = length - self._targets(length, rest)
                if track:
                    violation = max(violation, float(np.max(np.abs(error) * inverse_rest)))
                # d = 0 only for coincident nodes: no direction to move them, and 0 * (error / tiny) = 0.
                step = (error / np.maximum(length, _TINY))[:, None] * d
                np.put(flat, flat_ends, both + signed * step)
            if track and violation <= self.tolerance:
                break
        if not np.shares_memory(flat, x):
            x[...] = points
        return RelaxationReport(done, violation)

    def project(self, x: np.ndarray, v: np.ndarray, x_start: np.ndarray, t: float, dt: float, free: np.ndarray) -> None:
        before = x.copy()
        report = self.relax(x, free)
        v += (x - before) / dt
        logger.debug("%s: %d sweep(s), violation %.3g", type(self).__name__, report.sweeps, report.violation)


class DistanceConstraints(_PairProjection):
    """Keep node pairs at fixed distances: |x_j - x_i| = l_ij, projected after each step.

    Meant for the Verlet family (step, then project). Each Gauss-Seidel update moves a pair along
    its direction r = (x_j - x_i) / l by the mass-weighted shares of k C, C = l - l_ij:
    x_i += k w_i / (w_i + w_j) C r, x_j -= k w_j / (w_i + w_j) C r, with w = 1/m (0 for pinned
    nodes) and k = ``stiffness``. The constraints are coloured so that each colour's updates are
    independent and done at once; see the module docstring. Velocities change by the same
    displacement over dt.

    Parameters
    ----------
    masses : (n,) float
        node masses [kg] (``model.masses``)
    pairs : (s, 2) int
        constrained node pairs
    lengths : float or (s,) float
        target distances l_ij [m], > 0
    iterations : int
        Gauss-Seidel sweeps per projection, >= 1 (keyword-only)
    stiffness : float
        k in (0, 1], the fraction of the violation removed per update (PBD stiffness: the effective stiffness depends on
        ``iterations``; 1 is a hard constraint)
    tolerance : float
        stop sweeping once the largest relative violation met in a sweep is at most this [-] (default 0: always
        ``iterations`` sweeps)

    Examples
    --------
    >>> import numpy as np
    >>> from volspring.constraints import DistanceConstraints
    >>> rod = DistanceConstraints([1.0, 1.0], [[0, 1]], 1.0, iterations=1)
    >>> x = np.array([[0.0, 0, 0], [1.2, 0, 0]])
    >>> _ = rod.relax(x)
    >>> x.round(12).tolist()  # equal masses: each end moves half of the 0.2 m excess
    [[0.1, 0.0, 0.0], [1.1, 0.0, 0.0]]
    """

    def __init__(self, masses: ArrayLike, pairs: ArrayLike, lengths: float | ArrayLike, *, iterations: int = 10,
                 stiffness: float = 1.0, tolerance: float = 0.0):
        super().__init__(masses, pairs, lengths, iterations=iterations, stiffness=stiffness, tolerance=tolerance)

    @classmethod
    def from_model(cls, model: Model, *, springs: np.ndarray | None = None, iterations: int = 10,
                   stiffness: float = 1.0, tolerance: float = 0.0) -> DistanceConstraints:
        """Distance constraints on a model's springs, at their rest lengths.

        Parameters
        ----------
        model : Model
        springs : (k,) int or (s,) bool, optional
            which springs to constrain (default all)
        iterations, stiffness, tolerance : as for the constructor
        """
        select = slice(None) if springs is None else np.asarray(springs)
        return cls(model.masses, model.springs[select], model.rest_lengths[select], iterations=iterations,
                   stiffness=stiffness, tolerance=tolerance)

    def _targets(self, length, rest):
        return rest


class StrainLimit(_PairProjection):
    """Provot's strain limiting: springs stretched beyond (1 + tau) l0 are pulled back to it.

    After each step, every spring longer than (1 + tau) l0 (and, with ``compression``, shorter
    than (1 - compression) l0) is projected to that bound, mass-weighted and iterated over colours
    exactly like :class:`DistanceConstraints` with k = 1; springs within the band are left alone
    (Provot, "Deformation constraints in a mass-spring model to describe rigid cloth behavior",
    Graphics Interface 1995). Velocities change by the same displacement over dt.

    Parameters
    ----------
    model : Model
    tau : float
        largest allowed stretch (l - l0) / l0 [-], > 0 (Provot used 0.1)
    compression : float, optional
        largest allowed shortening (l0 - l) / l0 [-], in (0, 1)
    iterations : int
        Gauss-Seidel sweeps per projection, >= 1 (keyword-only)
    tolerance : float
        stop once no spring exceeds its bound by more than this [-] (relative)
    springs : (k,) int or (s,) bool, optional
        which of the model's springs to limit (default all; cloth limits its structural and shear springs,
        :func:`volspring.structures.cloth_strain_limit`)

    Examples
    --------
    >>> import numpy as np
    >>> from volspring import Model
    >>> from volspring.constraints import StrainLimit
    >>> pair = Model.from_arrays([[0, 0, 0], [1, 0, 0]], [1.0, 1.0], [[0, 1]], stiffness=1.0)
    >>> x = np.array([[0.0, 0, 0], [1.5, 0, 0]])
    >>> _ = StrainLimit(pair, 0.1, iterations=1).relax(x)
    >>> float(np.linalg.norm(x[1] - x[0]))  # capped at 1.1 l0
    1.1
    """

    def __init__(self, model: Model, tau: float, *, compression: float | None = None, iterations: int = 10,
                 tolerance: float = 0.0, springs: ArrayLike | None = None):
        if not (math.isfinite(tau) and tau > 0):
            raise ValueError(f"tau = {tau} is not > 0")
        if compression is not None and not (0.0 < compression < 1.0):
            raise ValueError(f"compression = {compression} is not in (0, 1)")
        self.tau = float(tau)
        self.compression = None if compression is None else float(compression)
        select = slice(None) if springs is None else np.asarray(springs)
        super().__init__(model.masses, model.springs[select], model.rest_lengths[select], iterations=iterations,
                         stiffness=1.0, tolerance=tolerance)

    def _targets(self, length, rest):
        low = 0.0 if self.compression is None else 1.0 - self.compression
        return np.clip(length, low * rest, (1.0 + self.tau) * rest)
