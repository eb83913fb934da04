"""Which nodes are joined by springs, before any material is given: tet edges and shell springs alike."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from meshing.mesh import TetMesh
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

__all__ = ["SPRING_KINDS", "SpringTopology", "TOPOLOGY_KINDS", "kind_counts", "vector_lengths"]

#: Labels of the spring kinds, in the order of their integer codes in ``SpringTopology.kinds``.
#: What each spring models; lattice bodies (meshing.lattice) add one kind per lattice family, in its order, and
#: cloth (volspring.structures) its three Provot families.
SPRING_KINDS = ("tet_edge", "shell", "shell_diagonal", "shell_edge", "lattice_structural", "lattice_face",
                "lattice_body", "lattice_bend", "cloth_structural", "cloth_shear", "cloth_bend")
#: The kinds a spring topology (a tet mesh and its virtual shells) is made of.
TOPOLOGY_KINDS = SPRING_KINDS[:4]


def kind_counts(kinds: ArrayLike) -> dict:
    """Number of springs of each kind, by label: every kind of a topology (:data:`TOPOLOGY_KINDS`, zero where
    absent) and any other kind present."""
    counts = np.bincount(np.asarray(kinds, dtype=np.int64), minlength=len(SPRING_KINDS))
    return {name: int(count) for name, count in zip(SPRING_KINDS, counts) if name in TOPOLOGY_KINDS or count}


def vector_lengths(vectors: np.ndarray) -> np.ndarray:
    """(k,) float -- Euclidean length of each row of a (k, 3) array.

    Rest lengths and current lengths both come from here, so that forces at the rest shape are
    exactly zero (``np.linalg.norm`` rounds differently, and is several times slower).
    """
    return np.sqrt(np.einsum("ij,ij->i", vectors, vectors))


@dataclass(frozen=True, eq=False)
class SpringTopology:
    """Nodes and springs of a volumetric body: a tet mesh plus optional virtual shell layers.

    The first ``mesh.node_count`` nodes are the mesh nodes, in mesh order; shell nodes follow,
    layer by layer. Springs are pairs ``(i, j)`` with ``i < j``, each with a kind code.

    Parameters
    ----------
    mesh : TetMesh
        the volumetric body
    points : (n, 3) float
        rest positions of all nodes, mesh nodes first [m]
    springs : (s, 2) int
        node pairs joined by a spring
    kinds : (s,) int
        index into :data:`SPRING_KINDS` of each spring
    shell_triangles : (f, 3) int
        triangles of every shell layer (global node indices), used to give shell nodes a mass; empty without shells
    shell_layer : (n,) int
        0 for mesh nodes, k for nodes of the k-th shell layer
    shell_thickness : float
        offset between consecutive layers [m]; 0 without shells

    Examples
    --------
    >>> import numpy as np
    >>> from meshing import SpringTopology, TetMesh
    >>> mesh = TetMesh(np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]), np.array([[0, 1, 2, 3]]))
    >>> topology = SpringTopology.from_mesh(mesh)
    >>> topology.spring_count, topology.kind_counts()["tet_edge"]
    (6, 6)
    """

    mesh: TetMesh
    points: np.ndarray
    springs: np.ndarray
    kinds: np.ndarray
    shell_triangles: np.ndarray
    shell_layer: np.ndarray
    shell_thickness: float = 0.0

    def __post_init__(self):
        # Arrays of their own (shaped before they are copied, so that none is a view), read-only below: a model's
        # element sets share them instead of copying them.
        points = np.array(self.points, dtype=np.float64, copy=True)
        springs = np.array(np.reshape(self.springs, (-1, 2)), dtype=np.int64, copy=True)
        kinds = np.array(np.ravel(self.kinds), dtype=np.int8, copy=True)
        triangles = np.array(np.reshape(self.shell_triangles, (-1, 3)), dtype=np.int64, copy=True)
        layer = np.array(np.ravel(self.shell_layer), dtype=np.int64, copy=True)
        n = len(points)
        if points.ndim != 2 or points.shape[1] != 3:
            raise ValueError(f"points must have shape (n, 3), got {points.shape}")
        if n < self.mesh.node_count or not np.array_equal(points[: self.mesh.node_count], self.mesh.points):
            raise ValueError("the first mesh.node_count points must be the mesh's own nodes, in order")
        if not np.isfinite(points).all():
            raise ValueError("points hold non-finite coordinates")
        if len(kinds) != len(springs):
            raise ValueError(f"len(springs) = {len(springs)}, but len(kinds) = {len(kinds)}")
        if len(layer) != n:
            raise ValueError(f"len(points) = {n}, but len(shell_layer) = {len(layer)}")
        for name, index in (("springs", springs), ("shell_triangles", triangles)):
            if index.size and (index.min() < 0 or index.max() >= n):
                raise ValueError(f"{name} index nodes in [{index.min()}, {index.max()}], expected [0, {n - 1}]")
        if kinds.size and (kinds.min() < 0 or kinds.max() >= len(SPRING_KINDS)):
            raise ValueError(f"kinds must lie in [0, {len(SPRING_KINDS) - 1}], got [{kinds.min()}, {kinds.max()}]")
        if (springs[:, 0] == springs[:, 1]).any():
            raise ValueError(f"spring {np.flatnonzero(springs[:, 0] == springs[:, 1])[0]} joins a node to itself")
        springs.sort(axis=1)
        if len(np.unique(springs, axis=0)) != len(springs):
            raise ValueError("springs hold duplicate node pairs")
        lengths = vector_lengths(points[springs[:, 1]] - points[springs[:, 0]])
        if springs.size and lengths.min() <= 0:
            raise ValueError(f"spring {np.argmin(lengths)} has zero rest length")
        if self.shell_thickness < 0:
            raise ValueError(f"shell_thickness = {self.shell_thickness} is negative")
        for array in (points, springs, kinds, triangles, layer):
            array.setflags(write=False)
        object.__setattr__(self, "points", points)
        object.__setattr__(self, "springs", springs)
        object.__setattr__(self, "kinds", kinds)
        object.__setattr__(self, "shell_triangles", triangles)
        object.__setattr__(self, "shell_layer", layer)
        object.__setattr__(self, "shell_thickness", float(self.shell_thickness))

    @classmethod
    def from_mesh(cls, mesh: TetMesh) -> "SpringTopology":
        """One ``tet_edge`` spring per unique edge of the mesh, no shells."""
        return cls(
            mesh=mesh,
            points=mesh.points,
            springs=mesh.edges,
            kinds=np.zeros(len(mesh.edges), dtype=np.int8),
            shell_triangles=np.empty((0, 3), dtype=np.int64),
            shell_layer=np.zeros(mesh.node_count, dtype=np.int64),
        )

    @property
    def node_count(self) -> int:
        return len(self.points)

    @property
    def spring_count(self) -> int:
        return len(self.springs)

    @property
    def shell_node_count(self) -> int:
        return self.node_count - self.mesh.node_count

    @property
    def layer_count(self) -> int:
        return int(self.shell_layer.max())

    @cached_property
    def rest_lengths(self) -> np.ndarray:
        """(s,) float -- rest length of each spring [m] (read-only, as the springs)."""
        lengths = vector_lengths(self.points[self.springs[:, 1]] - self.points[self.springs[:, 0]])
        lengths.setflags(write=False)
        return lengths

    def kind_mask(self, kind: str) -> np.ndarray:
        """(s,) bool -- the springs of one kind, by label."""
        if kind not in SPRING_KINDS:
            raise ValueError(f"unknown spring kind {kind!r}; known: {', '.join(SPRING_KINDS)}")
        return self.kinds == SPRING_KINDS.index(kind)

    def kind_counts(self) -> dict:
        """Number of springs of each kind, by label (:func:`kind_counts`)."""
        return kind_counts(self.kinds)

    def __repr__(self) -> str:
        kinds = ", ".join(f"{count} {name}" for name, count in self.kind_counts().items() if count)
        return f"SpringTopology({self.node_count} nodes, {self.spring_count} springs: {kinds})"
