"""validation: the spring model against a linear-elastic finite-element reference (scikit-fem)."""

from validation.boundary import Box, Clamp, Traction
from validation.fem import ModalSolution, StaticSolution, solve_modes, solve_static

__all__ = [
    "Box",
    "Clamp",
    "ModalSolution",
    "StaticSolution",
    "Traction",
    "solve_modes",
    "solve_static",
]
