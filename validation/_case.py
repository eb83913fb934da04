"""The record of one validation case: :class:`Case` (mesh, material, supports, loads, theory) and
:class:`BeamGeometry`.

Plain data that both sides read; the built-in cases that fill it are in :mod:`validation.cases`,
the one for a user's mesh in :func:`validation.cases.own_mesh_case`. Import both names from
:mod:`validation.cases`, their one public home.

Examples
--------
>>> from validation.cases import Case, cantilever_gravity
>>> case = cantilever_gravity(per_height=1)
>>> isinstance(case, Case), case.kind, case.material_tuple
(True, 'static', (300000000.0, 0.3, 1000.0))
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from meshing import TetMesh
from volspring.material import Material

__all__ = ["BeamGeometry", "Case"]


@dataclass(frozen=True)
class BeamGeometry:
    """A prismatic beam along x from 0 to ``length``, bending along z.

    Parameters
    ----------
    length, width, height : float
        [m]; the section spans y in [0, width], z in [0, height]
    """

    length: float
    width: float
    height: float


@dataclass(frozen=True, eq=False)
class Case:
    """One validation problem on one mesh.

    Parameters
    ----------
    name : str
        one of :data:`CASE_NAMES`
    title : str
        one line for the report
    kind : {"static", "modes"}
        static equilibrium or vibration frequencies
    mesh : TetMesh
        rest shape [m]
    material : Material
    clamps : tuple of Clamp
        supports, as :func:`validation.fem.solve_fem_static` takes them
    gravity : (3,) float or None
        [m/s^2]
    tractions : tuple of Traction
        surface loads [Pa]
    tip_nodes : (n,) bool or None
        the nodes whose mean displacement along ``tip_direction`` is the case's "tip deflection"; None to take the node
        the FEM reference moves most
    tip_direction : (3,) float or None
        unit vector; None as for ``tip_nodes``
    analytic : dict
        closed-form values, keys with units (``tip_deflection_m``, ...)
    parameters : dict
        the inputs, keys with units, for results.json
    beam : BeamGeometry or None
        for the deflection profile along the beam
    cells : (3,) int or None
        grid cells of a structured mesh
    """

    name: str
    title: str
    kind: str
    mesh: TetMesh
    material: Material
    clamps: tuple
    gravity: tuple | None = None
    tractions: tuple = ()
    tip_nodes: np.ndarray | None = None
    tip_direction: np.ndarray | None = None
    analytic: dict = field(default_factory=dict)
    parameters: dict = field(default_factory=dict)
    beam: BeamGeometry | None = None
    cells: tuple | None = None

    @property
    def material_tuple(self) -> tuple:
        """(E [Pa], nu, density [kg/m^3]) as :mod:`validation.fem` takes it."""
        return (self.material.E, self.material.nu, self.material.density)

    def fem_arguments(self) -> dict:
        """Keyword arguments of :func:`validation.fem.solve_fem_static` for this case (no mesh, material)."""
        return {"clamp": list(self.clamps), "gravity": self.gravity, "traction": list(self.tractions) or None}
