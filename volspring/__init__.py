"""volspring: volumetric soft bodies as tetrahedral mass-spring models, checked against FEM."""

from volspring.mesh import TetMesh
from volspring.topology import SPRING_KINDS, SpringTopology

__version__ = "0.1.0"

__all__ = [
    "SPRING_KINDS",
    "SpringTopology",
    "TetMesh",
]
