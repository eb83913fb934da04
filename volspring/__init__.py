"""volspring: volumetric soft bodies as tetrahedral mass-spring models, checked against FEM."""

from volspring.checkpoint import load_checkpoint, save_checkpoint
from volspring.constraints import DistanceConstraints, HalfSpace, StrainLimit
from volspring.fields import CallableForce, PointAttractor, PointRepulser, Vortex, Wind
from volspring.material import Material
from volspring.mesh import TetMesh
from volspring.model import FORCE_LAWS, STIFFNESS_RULES, SpringModel
from volspring.errors import SimulationDiverged, SolverNotConverged, StepTooLarge, StepTooLargeWarning
from volspring.scene import Drag, Gravity, Pins, Scene, State
from volspring.simulate import SimulationResult, simulate
from volspring.topology import SPRING_KINDS, SpringTopology

__version__ = "0.1.0"

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
    "SpringModel",
    "SpringTopology",
    "State",
    "TetMesh",
    "load_checkpoint",
    "save_checkpoint",
    "simulate",
]
