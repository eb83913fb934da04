"""Kept for one release (until 0.3.0): the spring graph (tet edges, shell springs) lives in :mod:`meshing.topology`."""

from volspring._deprecation import moved_names

__getattr__ = moved_names(__name__, "meshing.topology", ("SPRING_KINDS", "SpringTopology", "vector_lengths"))
