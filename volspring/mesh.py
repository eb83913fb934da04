"""The tetrahedral mesh container shared by meshing, the spring model and the FEM reference."""

from __future__ import annotations

import contextlib
import io
import logging
import os
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from volspring._io import atomic_path

__all__ = ["TetMesh"]

logger = logging.getLogger(__name__)

# The six edges and four outward faces of a positively oriented tet (v0, v1, v2, v3),
# i.e. one with det[v1 - v0, v2 - v0, v3 - v0] > 0. Each face is wound so that its
# right-hand normal points away from the opposite vertex.
TET_EDGES = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]])
TET_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])


def signed_tet_volumes(points, tets):
    """Signed volume of each tet.

    Parameters
    ----------
    points : (n, 3) float -- node positions [m]
    tets : (m, 4) int -- node indices of each tet

    Returns
    -------
    (m,) float -- det[x1 - x0, x2 - x0, x3 - x0] / 6 [m^3]; positive for a positively oriented tet
    """
    x = points[tets]
    return np.einsum("ij,ij->i", x[:, 1] - x[:, 0], np.cross(x[:, 2] - x[:, 0], x[:, 3] - x[:, 0])) / 6.0


@dataclass(frozen=True, eq=False)
class TetMesh:
    """An immutable tetrahedral mesh with positively oriented tets.

    Parameters
    ----------
    points : (n, 3) float64 -- node positions [m]
    tets : (m, 4) int64 -- node indices of each tet, positively oriented
        (``det[x1 - x0, x2 - x0, x3 - x0] > 0``)

    Raises
    ------
    ValueError
        For wrong shapes, non-finite coordinates, indices out of range, nodes used by
        no tet, or tets that are inverted or of zero volume (use :meth:`oriented` to
        flip inverted tets of an otherwise good mesh).

    Examples
    --------
    >>> import numpy as np
    >>> from volspring import TetMesh
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
        volumes = signed_tet_volumes(points, tets)
        # Zero volume relative to the tet's own size: |V| below 1e-12 l^3 is round-off of a flat tet.
        scale = np.ptp(points[tets], axis=1).max(axis=1) ** 3
        flat = np.abs(volumes) <= 1e-12 * scale
        if flat.any():
            raise ValueError(f"{flat.sum()} tet(s) have zero volume, first is tet {np.flatnonzero(flat)[0]}")
        inverted = volumes < 0
        if inverted.any():
            raise ValueError(
                f"{inverted.sum()} tet(s) are negatively oriented, first is tet {np.flatnonzero(inverted)[0]} "
                "(TetMesh.oriented flips them)"
            )
        points.setflags(write=False)
        tets.setflags(write=False)
        object.__setattr__(self, "points", points)
        object.__setattr__(self, "tets", tets)
        object.__setattr__(self, "_volumes", volumes)

    # ------------------------------------------------------------------ constructors
    @classmethod
    def oriented(cls, points, tets) -> "TetMesh":
        """Build a mesh after flipping negatively oriented tets (swapping their last two nodes)."""
        points = np.asarray(points, dtype=np.float64)
        tets = np.array(tets, dtype=np.int64, copy=True)
        if tets.ndim == 2 and tets.shape[1] == 4 and len(tets) and tets.min() >= 0 and tets.max() < len(points):
            flip = signed_tet_volumes(points, tets) < 0
            if flip.any():
                logger.info("flipped %d negatively oriented tets", flip.sum())
                tets[flip, 2:] = tets[flip, 3:1:-1]
        return cls(points, tets)

    @classmethod
    def compact(cls, points, tets) -> "TetMesh":
        """Build a mesh from the nodes the tets use, renumbered in their original order."""
        points = np.asarray(points, dtype=np.float64)
        tets = np.asarray(tets, dtype=np.int64)
        used, inverse = np.unique(tets.ravel(), return_inverse=True)
        return cls.oriented(points[used], inverse.reshape(tets.shape))

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
    @cached_property
    def _edge_table(self):
        pairs = np.sort(self.tets[:, TET_EDGES].reshape(-1, 2), axis=1)
        edges, inverse = np.unique(pairs, axis=0, return_inverse=True)
        return edges, inverse.reshape(-1, 6)

    @property
    def edges(self) -> np.ndarray:
        """(e, 2) int64 -- each unique tet edge once, as (i, j) with i < j, sorted."""
        return self._edge_table[0]

    @property
    def tet_edge_index(self) -> np.ndarray:
        """(m, 6) int64 -- index into :attr:`edges` of each tet's edges, in ``TET_EDGES`` order."""
        return self._edge_table[1]

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

    def with_points(self, points) -> "TetMesh":
        """A copy with other node positions (same tets); raises if that inverts a tet."""
        return TetMesh(points, self.tets)

    # ------------------------------------------------------------------ meshio
    def to_meshio(self, *, point_data=None, cell_data=None):
        """A ``meshio.Mesh`` with one ``tetra`` block; ``cell_data`` values are (m,) arrays."""
        import meshio

        return meshio.Mesh(
            self.points,
            [("tetra", self.tets)],
            point_data=dict(point_data or {}),
            cell_data={name: [np.asarray(value)] for name, value in (cell_data or {}).items()},
        )

    @classmethod
    def from_meshio(cls, mesh) -> "TetMesh":
        """Take the ``tetra`` cells of a ``meshio.Mesh`` (other cells are ignored).

        Nodes that no tet uses (for example the nodes of lower-dimensional cells only)
        are dropped and the rest renumbered; inverted tets are flipped.
        """
        blocks = [block.data for block in mesh.cells if block.type == "tetra"]
        if not blocks:
            found = sorted({block.type for block in mesh.cells}) or ["no cells"]
            raise ValueError(f"the mesh has no tetra cells (found {', '.join(found)})")
        tets = np.concatenate(blocks)
        points = np.asarray(mesh.points, dtype=np.float64)
        if points.ndim == 2 and points.shape[1] == 2:
            raise ValueError(f"the mesh is 2D (points of shape {points.shape}); a TetMesh needs 3D points")
        dropped = len(points) - len(np.unique(tets))
        if dropped:
            logger.info("dropped %d node(s) used by no tet", dropped)
        return cls.compact(points, tets)

    @classmethod
    def read(cls, path) -> "TetMesh":
        """Read any volume mesh format meshio knows (.vtu, .msh, .mesh, .xdmf, ...)."""
        import meshio

        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"no mesh file at {path}")
        file_format = mesh_file_format(path)
        # meshio prints and calls sys.exit(1) when every reader for an extension fails, and
        # lets a reader's own exceptions through on truncated files: turn both into one error.
        try:
            chatter = io.StringIO()
            with contextlib.redirect_stdout(chatter), contextlib.redirect_stderr(chatter):
                mesh = meshio.read(path, file_format=file_format)
        except (SystemExit, Exception) as error:
            detail = " ".join(chatter.getvalue().split()) or f"{type(error).__name__}: {error}"
            raise ValueError(f"cannot read {path} as a {file_format} mesh ({detail})") from None
        return cls.from_meshio(mesh)

    def write(self, path, *, point_data=None, cell_data=None, file_format=None) -> Path:
        """Write the mesh in the format its extension names, atomically (temp file, then rename)."""
        import meshio

        path = Path(path)
        with atomic_path(path) as tmp:
            meshio.write(tmp, self.to_meshio(point_data=point_data, cell_data=cell_data),
                         file_format=file_format or mesh_file_format(path))
        return path

    def __repr__(self) -> str:
        return f"TetMesh({self.node_count} nodes, {self.tet_count} tets, volume {self.volume:.6g})"


#: meshio lists several formats for some extensions, and not the one users mean first (.msh -> ansys).
PREFERRED_FORMATS = {".msh": "gmsh"}


def mesh_file_format(path) -> str:
    """The meshio format name for a file's extension, or a ValueError naming the known ones.

    >>> mesh_file_format("beam.msh"), mesh_file_format("beam.vtu")
    ('gmsh', 'vtu')
    """
    import meshio

    path = Path(path)
    suffixes = [suffix.lower() for suffix in path.suffixes]
    for candidate in ("".join(suffixes[-2:]), suffixes[-1] if suffixes else ""):
        if candidate in PREFERRED_FORMATS:
            return PREFERRED_FORMATS[candidate]
        if candidate in meshio.extension_to_filetypes:
            return meshio.extension_to_filetypes[candidate][0]
    known = ", ".join(sorted(meshio.extension_to_filetypes))
    raise ValueError(f"unknown mesh file extension {path.suffix!r} for {os.fspath(path)}; known: {known}")
