"""validation: the spring model against a linear-elastic finite-element reference (scikit-fem)."""

from validation.boundary import Box, Clamp, Traction
from validation.fem import ModalSolution, StaticSolution, solve_fem_modes, solve_fem_static

__all__ = [
    "Box",
    "Clamp",
    "ModalSolution",
    "StaticSolution",
    "Traction",
    "solve_fem_modes",
    "solve_fem_static",
]


def __getattr__(name):
    # 0.1 names that clashed with volspring's own static and modal solves (volspring.statics, volspring.modes).
    from volspring._deprecation import deprecated_alias

    return deprecated_alias(__name__, name, {"solve_static": ("validation.solve_fem_static", solve_fem_static),
                                             "solve_modes": ("validation.solve_fem_modes", solve_fem_modes)})
