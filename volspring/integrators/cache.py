"""What an implicit integrator keeps between the steps of one scene: an explicit solver cache.

The integrator object holds only its options; the block pattern of the scene's model and
supports, the linear solver with its AMG hierarchy and the record of the state that hierarchy was
built from live in a :class:`SolverCache`. Pass one cache per scene
(``integrator.step(scene, state, dt, cache=cache)``) to step several scenes with one integrator;
without one, the integrator's own default cache is used (one scene at a time).

Nothing a resumed run needs lives here: the rebuild policy reads ``state.memory`` (the step, time,
dt, positions and velocities the hierarchy was built from), so a cache that is empty -- new,
unpickled, or after a checkpoint -- rebuilds the very same hierarchy from that record and the run
continues bit-identically. A cache pickles without its pattern and hierarchy (they are rebuilt),
so integrators and scenes can be sent to other processes.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np

from volspring.assembly import BlockPattern
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from volspring.scene import Scene
    from volspring.solvers.krylov import _LinearSolver

__all__ = ["SolverCache"]


@dataclass(eq=False)
class SolverCache:
    """The block pattern, the linear solver (with its hierarchy) and the hierarchy's build record.

    Parameters
    ----------
    solver : a linear solver of :mod:`volspring.solvers`
        (holds the AMG hierarchy once built)
    pattern : BlockPattern or None
        of the last scene stepped
    record : tuple or None
        (pattern, step, t, dt, x, v) the current hierarchy was built from
    matrix_free : bool
        patterns apply the sets that offer it as products (:class:`BlockPattern`)
    folded : (f, 3) float or None
        the scene forces' diagonal Jacobian term folded into the matrix at the last build (None without one; rebuilt
        with the hierarchy, not pickled): a step whose term differs updates the hierarchy's levels
    extra : sparse matrix or None
        the scene forces' other Jacobian terms (contact between bodies) over the free unknowns at the last build (None
        without; rebuilt with the hierarchy, not pickled): the hierarchy's levels get their change at each step
    """

    solver: _LinearSolver
    pattern: BlockPattern | None = None
    record: tuple | None = None
    matrix_free: bool = False
    folded: np.ndarray | None = None
    extra: object = None

    def pattern_for(self, scene: Scene) -> BlockPattern:
        """The block pattern of ``scene``'s model and free nodes: kept while they are the same, else rebuilt
        (and the hierarchy record dropped)."""
        cached = self.pattern
        if cached is None or cached.model is not scene.model or not np.array_equal(cached.free, scene.free):
            cached = self.pattern = BlockPattern(scene.model, scene.free, matrix_free=self.matrix_free)
            self.record = self.folded = self.extra = None
        return cached

    def built(self, pattern: BlockPattern, step: int, t: float, dt: float, x: np.ndarray, v: np.ndarray) -> None:
        """Note that the solver's hierarchy was just built from this state."""
        self.record = (pattern, int(step), float(t), float(dt), x.copy(), v.copy())

    def matches(self, pattern: BlockPattern, step: int, t: float, dt: float, x: np.ndarray, v: np.ndarray) -> bool:
        """Whether the hierarchy held was built from exactly this pattern and recorded state."""
        record = self.record
        if record is None or getattr(self.solver, "hierarchy", None) is None or record[0] is not pattern:
            return False
        return (record[1] == int(step) and record[2] == float(t) and record[3] == float(dt)
                and np.array_equal(record[4], x) and np.array_equal(record[5], v))

    def __getstate__(self):
        solver = copy.copy(self.solver)
        if getattr(solver, "hierarchy", None) is not None:
            setattr(solver, "hierarchy", None)  # a solver with a hierarchy (AMG's): not pickled
        return {"solver": solver, "pattern": None, "record": None, "matrix_free": self.matrix_free, "folded": None,
                "extra": None}
