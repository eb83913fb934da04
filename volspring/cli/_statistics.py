"""What a run of ``volspring sim`` records about itself: solver statistics per step, and where its time went.

:class:`StepStatistics` watches an integrator for the length of a run (every step's
:class:`~volspring.integrators.implicit.ImplicitStepInfo`, when the integrator keeps one) and sums it up
for the run manifest (:mod:`volspring.output.run_manifest`, entry ``"solver"``); :class:`RunTimings`
adds up the run's phases (entry ``"timings"``). Both are plain bookkeeping: the numbers the run computes
do not depend on them.
"""

from __future__ import annotations

import time
from contextlib import contextmanager

import numpy as np

__all__ = ["RunTimings", "StepStatistics"]


class StepStatistics:
    """The linear solves of every step of a run: CG iterations, AMG rebuilds, time per phase.

    Attributes
    ----------
    steps : int
        Steps taken while watching.
    iterations : list of int
        CG iterations of each step, over its linearised solve and its Newton iterations (0 for the
        direct solver); empty for an explicit integrator.
    rebuilds : int
        Steps that (re)built the AMG hierarchy.
    seconds : dict of str to float
        Time in the phases an implicit step reports (forces, assembly, setup, solve) [s].

    Examples
    --------
    >>> from volspring import Gravity, Model, Pins, Scene
    >>> from volspring.integrators import make_integrator
    >>> from volspring.simulate import simulate
    >>> chain = Model.from_arrays([[0, 0, 0], [0, 0, -1]], [1.0, 1.0], [[0, 1]], stiffness=100.0)
    >>> scene, integrator = Scene(chain, forces=[Gravity()], pins=Pins([0])), make_integrator("implicit_euler")
    >>> statistics = StepStatistics()
    >>> with statistics.watching(integrator):
    ...     _ = simulate(scene, integrator, duration=0.05, dt=0.01)
    >>> statistics.record()["steps"], "step" in vars(integrator)
    (5, False)
    """

    def __init__(self):
        self.steps = 0
        self.iterations = []
        self.rebuilds = 0
        self.seconds = {"forces": 0.0, "assembly": 0.0, "setup": 0.0, "solve": 0.0}
        self.integrator_name = None

    @contextmanager
    def watching(self, integrator):
        """Count the steps of ``integrator`` inside the ``with`` block.

        The integrator's own ``step`` is shadowed by a counting one on the instance for the block only,
        so that ``simulate`` and the checkpoints see the same integrator object (a checkpoint records its
        scalar options, which this leaves alone).

        Parameters
        ----------
        integrator : Integrator
            The integrator the run steps with.
        """
        step = integrator.step
        self.integrator_name = integrator.name

        def counted(*args, **kwargs):
            new = step(*args, **kwargs)
            self._add(getattr(integrator, "last_solve", None))
            return new

        integrator.step = counted
        try:
            yield self
        finally:
            del integrator.step

    def _add(self, info) -> None:
        self.steps += 1
        if info is None:
            return
        self.iterations.append(int(sum(solve.iterations for solve in info.solves)) if info.solves
                               else int(info.iterations))
        self.rebuilds += bool(info.rebuilt)
        for phase in self.seconds:
            self.seconds[phase] += float(getattr(info, f"{phase}_seconds", 0.0))

    def record(self, *, frames=None) -> dict:
        """The statistics as the run manifest's ``"solver"`` entry.

        Parameters
        ----------
        frames : int, optional
            Frames written, recorded beside the steps.

        Returns
        -------
        dict
            ``integrator``, ``steps`` (and ``frames``); for an implicit integrator also ``cg_iterations``
            (``mean``, ``max``, ``total`` over the steps), ``hierarchy_rebuilds`` and ``seconds`` per phase [s].
        """
        record = {"integrator": self.integrator_name, "steps": self.steps,
                  **({} if frames is None else {"frames": int(frames)})}
        if self.iterations:
            counts = np.asarray(self.iterations)
            record["cg_iterations"] = {"mean": round(float(counts.mean()), 3), "max": int(counts.max()),
                                       "total": int(counts.sum())}
            record["hierarchy_rebuilds"] = self.rebuilds
            record["seconds"] = {phase: round(value, 6) for phase, value in self.seconds.items()}
        return record


class RunTimings:
    """Wall time of a run's phases [s]: building the model and scene, stepping, writing frames, and a scene
    file's comparison (``compare_seconds``, only when there is one).

    ``stepping_seconds`` is the time in :func:`~volspring.simulate.simulate` less the frames' writing,
    which the frame callback adds with :meth:`writing`.

    Examples
    --------
    >>> timings = RunTimings()
    >>> with timings.phase("build"):
    ...     pass
    >>> sorted(timings.record())
    ['build_seconds', 'stepping_seconds', 'wall_seconds', 'writing_seconds']
    """

    def __init__(self, clock=time.perf_counter):
        self.clock = clock
        self.started = clock()
        self.phases = {"build": 0.0, "stepping": 0.0, "writing": 0.0}

    @contextmanager
    def phase(self, name):
        """Add the time of the ``with`` block to phase ``name`` ("build", "stepping", "writing" or "compare")."""
        self.phases.setdefault(name, 0.0)
        start = self.clock()
        try:
            yield
        finally:
            self.phases[name] += self.clock() - start

    def record(self) -> dict:
        """The timings as the run manifest's ``"timings"`` entry, in seconds, rounded to microseconds.

        Returns
        -------
        dict
            ``wall_seconds`` (from this object's creation) and ``build_seconds``, ``stepping_seconds`` (the
            stepping less the writing inside it), ``writing_seconds``, and ``compare_seconds`` after a comparison.
        """
        stepping = self.phases["stepping"] - self.phases["writing"]
        extra = {f"{name}_seconds": round(self.phases[name], 6) for name in self.phases
                 if name not in ("build", "stepping", "writing")}
        return {"wall_seconds": round(self.clock() - self.started, 6),
                "build_seconds": round(self.phases["build"], 6),
                "stepping_seconds": round(max(stepping, 0.0), 6),
                "writing_seconds": round(self.phases["writing"], 6), **extra}
