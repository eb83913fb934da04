"""validation: the spring model against a linear-elastic finite-element reference (scikit-fem)."""

from validation.fem import Box, Clamp, ModalSolution, StaticSolution, Traction, solve_modes, solve_static

__all__ = [
    "Box",
    "Clamp",
    "ModalSolution",
    "StaticSolution",
    "Traction",
    "solve_modes",
    "solve_static",
]
