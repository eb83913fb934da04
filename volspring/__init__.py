"""volspring: volumetric soft bodies as tetrahedral mass-spring models, checked against FEM."""

from volspring.checkpoint import load_checkpoint, save_checkpoint
from volspring.constraints import DistanceConstraints, HalfSpace, StrainLimit
from volspring.forces import CallableForce, Drag, Gravity, PointAttractor, PointRepulser, Vortex, Wind
from volspring.lattice import lattice_body
from volspring.material import Material
from meshing.mesh import TetMesh
from volspring.model import FORCE_LAWS, STIFFNESS_RULES, Model
from volspring.model_io import load_model, save_model
from volspring.errors import SimulationDiverged, SolverNotConverged, StepTooLarge, StepTooLargeWarning
from volspring.scene import Pins, Scene, State
from volspring.simulate import SimulationResult, simulate
from meshing.topology import SPRING_KINDS, SpringTopology

__version__ = "0.1.0"


def __getattr__(name):
    from volspring._deprecation import deprecated_alias

    return deprecated_alias(__name__, name, {"SpringModel": ("volspring.Model", Model)})


__all__ = [
    "CallableForce",
    "DistanceConstraints",
    "HalfSpace",
    "PointAttractor",
    "PointRepulser",
    "StrainLimit",
    "Vortex",
    "Wind",
    "Drag",
    "FORCE_LAWS",
    "Gravity",
    "Material",
    "Pins",
    "SPRING_KINDS",
    "SimulationDiverged",
    "SimulationResult",
    "SolverNotConverged",
    "StepTooLarge",
    "StepTooLargeWarning",
    "STIFFNESS_RULES",
    "Scene",
    "Model",
    "SpringTopology",
    "State",
    "TetMesh",
    "lattice_body",
    "load_checkpoint",
    "load_model",
    "save_checkpoint",
    "save_model",
    "simulate",
]
