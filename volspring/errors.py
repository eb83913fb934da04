"""Exceptions and warnings raised while simulating."""

from __future__ import annotations

__all__ = ["SimulationDiverged", "SpringCollapsed", "StepTooLarge", "StepTooLargeWarning", "SolverNotConverged",
           "TetsInvertedWarning"]


class SimulationDiverged(FloatingPointError):
    """The state became non-finite or its energy ran away.

    Attributes name where: ``step``, ``time`` [s], ``dt`` [s] and ``node`` (the worst node).
    """

    def __init__(self, reason: str, *, step: int, time: float, dt: float, node: int | None):
        self.step, self.time, self.dt, self.node = step, time, dt, node
        super().__init__(f"simulation diverged at step {step} (t = {time:.6g} s, dt = {dt:.6g} s), "
                         f"worst node {node}: {reason}")


class SpringCollapsed(FloatingPointError):
    """A spring reached zero length, so its direction is undefined; ``spring`` is its index."""

    def __init__(self, spring: int, i: int, j: int):
        self.spring = spring
        super().__init__(f"spring {spring} between nodes {i} and {j} has collapsed to zero length")


class StepTooLargeWarning(RuntimeWarning):
    """An explicit integrator was asked to step beyond its stability limit (``guard="warn"``)."""


class TetsInvertedWarning(RuntimeWarning):
    """Tets of the body turned inside out during a run (once per run, naming how many and the worst)."""


class StepTooLarge(ValueError):
    """An explicit integrator was asked to step beyond its stability limit (``guard="raise"``)."""


class SolverNotConverged(RuntimeError):
    """A linear or nonlinear solve stopped before reaching its tolerance; the message gives the residual."""
