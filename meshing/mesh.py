"""The tetrahedral mesh container shared by meshing, the spring model and the FEM reference.

:class:`TetMesh` holds node positions and positively oriented tets, refuses bad input with counts and the
first offender, and caches what is derived from them (volumes, unique edges, outward boundary faces).
The numbering of a tet (:data:`TET_EDGES`, :data:`TET_FACES`) and the work :meth:`TetMesh.oriented` and
:meth:`TetMesh.compact` do on raw arrays are :mod:`meshing.mesh_orientation`; reading and writing files is
:mod:`meshing.mesh_io` (``TetMesh.read`` and ``TetMesh.write`` call it); the geometric kernels are
:mod:`meshing.geometry`, the tolerances :mod:`meshing.tolerances`.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

# _used_nodes is re-exported for meshing.mesh_io.
from meshing.mesh_orientation import (TET_EDGES, TET_FACES, _compact_arrays, _oriented_arrays,  # noqa: F401
                                      _used_nodes, _volumes_and_extents, boundary_face_mask, tet_edges)
from meshing.tolerances import ZERO_VOLUME
from collections.abc import Mapping
import os
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import meshio
    from numpy.typing import ArrayLike

__all__ = ["TET_EDGES", "TET_FACES", "TetMesh", "boundary_face_mask", "tet_edges"]

@dataclass(frozen=True, eq=False)
class TetMesh:
    """An immutable tetrahedral mesh with positively oriented tets.

    Parameters
    ----------
    points : (n, 3) float64
        node positions [m]
    tets : (m, 4) int64
        node indices of each tet, positively oriented (``det[x1 - x0, x2 - x0, x3 - x0] > 0``)

    Raises
    ------
    ValueError
        For wrong shapes, non-finite coordinates, coordinates so large or small that tet
        volumes overflow or underflow float64, indices out of range, nodes used by no tet,
        or tets that are inverted or of zero volume (:meth:`oriented` flips a mesh whose
        every tet is inverted; :meth:`compact` orders each tet of a mesher's output).

    Examples
    --------
    >>> import numpy as np
    >>> from meshing import TetMesh
    >>> mesh = TetMesh(np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]), np.array([[0, 1, 2, 3]]))
    >>> round(mesh.volume, 6), mesh.edges.shape, mesh.boundary_faces.shape
    (0.166667, (6, 2), (4, 3))
    """

    points: np.ndarray
    tets: np.ndarray

    def __post_init__(self):
        points = np.array(self.points, dtype=np.float64, copy=True)
        tets = np.asarray(self.tets)
        if points.ndim != 2 or points.shape[1] != 3:
            raise ValueError(f"points must have shape (n, 3), got {points.shape}")
        if tets.ndim != 2 or tets.shape[1] != 4:
            raise ValueError(f"tets must have shape (m, 4), got {tets.shape}")
        if len(points) == 0 or len(tets) == 0:
            raise ValueError(f"a TetMesh needs nodes and tets, got {len(points)} nodes and {len(tets)} tets")
        if not np.issubdtype(tets.dtype, np.integer):
            raise ValueError(f"tets must hold integer node indices, got dtype {tets.dtype}")
        tets = tets.astype(np.int64, copy=True)
        bad = ~np.isfinite(points).all(axis=1)
        if bad.any():
            raise ValueError(f"{bad.sum()} node(s) have non-finite coordinates, first is node {np.flatnonzero(bad)[0]}")
        if tets.min() < 0 or tets.max() >= len(points):
            raise ValueError(f"tet node indices must lie in [0, {len(points) - 1}], got [{tets.min()}, {tets.max()}]")
        unused = np.bincount(tets.ravel(), minlength=len(points)) == 0
        if unused.any():
            raise ValueError(
                f"{unused.sum()} node(s) are used by no tet, first is node {np.flatnonzero(unused)[0]} "
                "(drop them with TetMesh.compact)"
            )
        volumes, extent = _volumes_and_extents(points, tets)
        flat = np.abs(volumes) <= ZERO_VOLUME * extent**3
        if flat.any():
            raise ValueError(f"{flat.sum()} tet(s) have zero volume, first is tet {np.flatnonzero(flat)[0]}")
        inverted = volumes < 0
        if inverted.any():
            first = np.flatnonzero(inverted)[0]
            raise ValueError(
                f"{inverted.sum()} of {len(tets)} tet(s) are negatively oriented, first is tet {first} with signed "
                f"volume {volumes[first]:.3g} m^3; expected det[x1 - x0, x2 - x0, x3 - x0] > 0 (TetMesh.oriented "
                "flips a mesh whose every tet is inverted, TetMesh.compact puts each tet of a mesher's output in "
                "positive order)"
            )
        points.setflags(write=False)
        tets.setflags(write=False)
        object.__setattr__(self, "points", points)
        object.__setattr__(self, "tets", tets)
        self._volumes: np.ndarray  # (m,) float: not a field, set here (frozen, hence object.__setattr__)
        object.__setattr__(self, "_volumes", volumes)

    # ------------------------------------------------------------------ constructors
    @classmethod
    def oriented(cls, points: np.ndarray, tets: np.ndarray) -> "TetMesh":
        """Build a mesh whose tets are all positively oriented, or all negatively (then flipped).

        Some file formats and meshers number every tet the other way round: such a mesh is flipped
        (the last two nodes of each tet swapped) and that is logged at INFO level. A mesh in which
        only some tets are inverted is refused: that is what a node pushed through its neighbours
        looks like, and flipping would count the volume the inverted tets fold over twice.

        Parameters
        ----------
        points : (n, 3) float
            Node positions [m].
        tets : (m, 4) int
            Node indices of each tet, all in one orientation.

        Returns
        -------
        TetMesh

        Raises
        ------
        ValueError
            For a mesh where some but not all tets are inverted, naming how many of how many and the
            first (index and signed volume), and whether the mesh is tangled (two tets on the same side
            of a face they share) or only numbered in mixed orientations (then :meth:`compact` builds
            it); and for anything :class:`TetMesh` refuses.

        Examples
        --------
        >>> import numpy as np
        >>> corners = np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
        >>> TetMesh.oriented(corners, [[0, 2, 1, 3]]).tets   # the one tet, numbered the other way round
        array([[0, 2, 3, 1]])
        """
        return cls(*_oriented_arrays(points, tets))

    @classmethod
    def compact(cls, points: np.ndarray, tets: ArrayLike) -> "TetMesh":
        """Build a mesh from a mesher's output: unused nodes dropped, each tet put in positive order.

        Meant for tets that come in arbitrary orientation by construction (scipy's ``Delaunay``
        simplices, hand-numbered cells). The nodes the tets use are kept and renumbered in their
        original order; every negatively oriented tet is flipped (its last two nodes swapped). The
        flipped mesh must not be tangled: two tets sharing a face must lie on opposite sides of it.

        Parameters
        ----------
        points : (n, 3) float
            Node positions [m]; nodes no tet uses are dropped.
        tets : (m, 4) int
            Node indices of each tet, in any orientation.

        Returns
        -------
        TetMesh

        Raises
        ------
        ValueError
            For a tangled mesh (naming how many faces have both their tets on one side, and the first),
            and for anything :class:`TetMesh` refuses.

        Examples
        --------
        >>> import numpy as np
        >>> corners = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], dtype=float)
        >>> kuhn = [[0, 4, 6, 7], [0, 4, 5, 7], [0, 2, 6, 7], [0, 2, 3, 7], [0, 1, 5, 7], [0, 1, 3, 7]]
        >>> round(TetMesh.compact(corners, kuhn).volume, 12)   # three of the six are numbered inverted
        1.0
        """
        return cls(*_compact_arrays(points, tets))

    # ------------------------------------------------------------------ sizes
    @property
    def node_count(self) -> int:
        return len(self.points)

    @property
    def tet_count(self) -> int:
        return len(self.tets)

    # ------------------------------------------------------------------ geometry
    @property
    def tet_volumes(self) -> np.ndarray:
        """(m,) float -- volume of each tet [m^3], all positive."""
        return self._volumes

    @cached_property
    def volume(self) -> float:
        """Total volume [m^3]."""
        return float(self._volumes.sum())

    @cached_property
    def bounds(self) -> np.ndarray:
        """(2, 3) float -- lower and upper corners of the bounding box [m]."""
        return np.array([self.points.min(axis=0), self.points.max(axis=0)])

    # ------------------------------------------------------------------ topology
    def _tet_edge_pairs(self) -> np.ndarray:
        """(6 m, 2) int64 -- every tet's edges, in ``TET_EDGES`` order, each as (i, j) with i < j."""
        return np.sort(self.tets[:, TET_EDGES].reshape(-1, 2), axis=1)

    @cached_property
    def edges(self) -> np.ndarray:
        """(e, 2) int64 -- each unique tet edge once, as (i, j) with i < j, sorted."""
        return np.ascontiguousarray(tet_edges(self.tets))

    @property
    def tet_edge_index(self) -> np.ndarray:
        """(m, 6) int64 -- index into :attr:`edges` of each tet's edges, in ``TET_EDGES`` order. Made on each access
        (searched in the sorted edges), not kept: 48 bytes a tet, for a table a model reads once."""
        n = np.int64(self.node_count)
        keys = self.edges[:, 0] * n + self.edges[:, 1]  # increasing: the edges are sorted by (i, j)
        pairs = self._tet_edge_pairs()
        return np.searchsorted(keys, pairs[:, 0] * n + pairs[:, 1]).reshape(-1, 6)

    @cached_property
    def edge_lengths(self) -> np.ndarray:
        """(e,) float -- rest length of each edge [m]."""
        return np.linalg.norm(self.points[self.edges[:, 1]] - self.points[self.edges[:, 0]], axis=1)

    @cached_property
    def _face_table(self):
        faces = self.tets[:, TET_FACES].reshape(-1, 3)
        _, first, counts = np.unique(np.sort(faces, axis=1), axis=0, return_index=True, return_counts=True)
        if counts.max() > 2:
            raise ValueError(f"the tet mesh is non-manifold: a face is shared by {counts.max()} tets")
        once = np.sort(first[counts == 1])
        return faces[once], once // 4

    @property
    def boundary_faces(self) -> np.ndarray:
        """(f, 3) int64 -- faces that belong to one tet only, wound with outward normals."""
        return self._face_table[0]

    @property
    def boundary_face_tets(self) -> np.ndarray:
        """(f,) int64 -- the tet each boundary face belongs to."""
        return self._face_table[1]

    @cached_property
    def boundary_nodes(self) -> np.ndarray:
        """(b,) int64 -- sorted indices of the nodes on the boundary."""
        return np.unique(self.boundary_faces)

    def node_volumes(self) -> np.ndarray:
        """(n,) float -- a quarter of the volume of every tet around each node [m^3]."""
        return np.bincount(self.tets.ravel(), weights=np.repeat(self._volumes / 4.0, 4), minlength=self.node_count)

    def with_points(self, points: np.ndarray) -> "TetMesh":
        """A copy with other node positions (same tets); raises if that inverts a tet."""
        return TetMesh(points, self.tets)

    # ------------------------------------------------------------------ files (meshing.mesh_io)
    def to_meshio(self, *, point_data: Mapping[str, np.ndarray] | None = None,
                  cell_data: Mapping[str, np.ndarray] | None = None) -> meshio.Mesh:
        """A ``meshio.Mesh`` with one ``tetra`` block; ``cell_data`` values are (m,) arrays."""
        from meshing.mesh_io import tet_mesh_to_meshio

        return tet_mesh_to_meshio(self, point_data=point_data, cell_data=cell_data)

    @classmethod
    def from_meshio(cls, mesh: meshio.Mesh) -> "TetMesh":
        """Take the ``tetra`` cells of a ``meshio.Mesh`` (:func:`meshing.mesh_io.tet_mesh_from_meshio`)."""
        from meshing.mesh_io import tet_mesh_from_meshio

        return tet_mesh_from_meshio(mesh)

    @classmethod
    def read(cls, path: str | os.PathLike[str], *, units: str = "m", scale: float | None = None) -> "TetMesh":
        """Read any volume mesh format meshio knows (.vtu, .msh, .mesh, .xdmf, ...), in metres.

        ``units`` ({"m", "cm", "mm"}) is the length unit of the file's coordinates and ``scale`` a further
        factor on them (:func:`meshing.units.length_factor`). Raises ``FileNotFoundError`` for no file, and
        ``ValueError`` for bad units or scale, an unreadable file, no tets or a mesh :meth:`from_meshio`
        refuses; warns when a body read in metres is over 10 m across. See
        :func:`meshing.mesh_io.read_tet_mesh`.
        """
        from meshing.mesh_io import read_tet_mesh

        return read_tet_mesh(path, units=units, scale=scale, stacklevel=4)  # the warning points at our caller

    def write(self, path: str | os.PathLike[str], *, point_data: Mapping[str, np.ndarray] | None = None,
              cell_data: Mapping[str, np.ndarray] | None = None, file_format: str | None = None) -> Path:
        """Write the mesh in the format its extension names, atomically; returns ``path``.

        ``point_data`` and ``cell_data`` map names to (n, ...) values per node and (m, ...) per tet;
        ``file_format`` is meshio's format name (default from the extension). XDMF is written as a
        ``.xdmf`` + ``.h5`` pair. See :func:`meshing.mesh_io.write_tet_mesh`.
        """
        from meshing.mesh_io import write_tet_mesh

        return write_tet_mesh(self, path, point_data=point_data, cell_data=cell_data, file_format=file_format)

    def __repr__(self) -> str:
        return f"TetMesh({self.node_count} nodes, {self.tet_count} tets, volume {self.volume:.6g})"
