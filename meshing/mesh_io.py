"""Tet mesh files: reading and writing a :class:`~meshing.mesh.TetMesh` in every volume format meshio knows.

meshio is the plug-in layer (``.vtu``, ``.msh``, ``.mesh``, ``.xdmf``, ...); this module adds what it
lacks: the format meshio's users mean for an extension (:func:`mesh_file_format`), length units on
read (:mod:`meshing.units`), one error for every way a file fails to read, atomic writes
(:func:`meshing._io.atomic_path`) and an XDMF pair (``.xdmf`` + ``.h5``) that can be moved together.
``TetMesh.read``, ``TetMesh.write``, ``TetMesh.to_meshio`` and ``TetMesh.from_meshio`` call these
functions; meshio is imported only when they run.

Examples
--------
>>> import tempfile
>>> from pathlib import Path
>>> import numpy as np
>>> from meshing import TetMesh
>>> mesh = TetMesh(np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]), np.array([[0, 1, 2, 3]]))
>>> path = write_tet_mesh(mesh, Path(tempfile.mkdtemp()) / "tet.vtu")
>>> read_tet_mesh(path)
TetMesh(4 nodes, 1 tets, volume 0.166667)
"""

from __future__ import annotations

import contextlib
import io
import logging
import os
from pathlib import Path

import numpy as np

from meshing._io import atomic_path
from meshing.mesh import TetMesh, _used_nodes
from meshing.units import length_factor, scaled_points, warn_if_large
from collections.abc import Mapping
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import meshio

__all__ = [
    "PREFERRED_FORMATS",
    "mesh_file_format",
    "REGION_TAG_NAMES",
    "read_tet_mesh",
    "read_tet_regions",
    "tet_mesh_from_meshio",
    "tet_mesh_to_meshio",
    "write_tet_mesh",
]

logger = logging.getLogger(__name__)

#: meshio lists several formats for some extensions, and not the one users mean first (.msh -> ansys).
PREFERRED_FORMATS = {".msh": "gmsh"}
#: The cell data that tags tets by region, in the order looked for: gmsh's physical groups, Medit's
#: references, and a plain ``region`` array (what :func:`write_tet_mesh` writes with ``cell_data``).
REGION_TAG_NAMES = ("gmsh:physical", "medit:ref", "region")


def tet_mesh_to_meshio(mesh: TetMesh, *, point_data: Mapping[str, np.ndarray] | None = None,
                       cell_data: Mapping[str, np.ndarray] | None = None) -> meshio.Mesh:
    """A ``meshio.Mesh`` with one ``tetra`` block.

    Parameters
    ----------
    mesh : TetMesh
    point_data : dict of str to (n, ...) array, optional
        Values per node.
    cell_data : dict of str to (m, ...) array, optional
        Values per tet.

    Returns
    -------
    meshio.Mesh
    """
    import meshio

    return meshio.Mesh(
        mesh.points,
        [("tetra", mesh.tets)],
        point_data=dict(point_data or {}),
        cell_data={name: [np.asarray(value)] for name, value in (cell_data or {}).items()},
    )


def tet_mesh_from_meshio(mesh: meshio.Mesh) -> TetMesh:
    """Take the ``tetra`` cells of a ``meshio.Mesh`` (other cells are ignored).

    Nodes that no tet uses (for example the nodes of lower-dimensional cells only) are dropped
    and the rest renumbered; the tets then go through :meth:`TetMesh.oriented`: a mesh whose every
    tet is inverted is flipped, one where only some are is refused as tangled.

    Parameters
    ----------
    mesh : meshio.Mesh
        Points (n, 3) [m] and cells.

    Returns
    -------
    TetMesh

    Raises
    ------
    ValueError
        For no tetra cells (naming the cell types found), 2D points, or anything
        :meth:`TetMesh.oriented` refuses.
    """
    blocks = [block.data for block in mesh.cells if block.type == "tetra"]
    if not blocks:
        found = sorted({block.type for block in mesh.cells}) or ["no cells"]
        raise ValueError(f"the mesh has no tetra cells (found {', '.join(found)})")
    tets = np.concatenate(blocks)
    points = np.asarray(mesh.points, dtype=np.float64)
    if points.ndim == 2 and points.shape[1] == 2:
        raise ValueError(f"the mesh is 2D (points of shape {points.shape}); a TetMesh needs 3D points")
    points, used = _used_nodes(points, tets)
    if len(points) < len(mesh.points):
        logger.info("dropped %d node(s) used by no tet", len(mesh.points) - len(points))
    return TetMesh.oriented(points, used)


def read_tet_mesh(path: str | os.PathLike[str], *, units: str = "m", scale: float | None = None,
                  stacklevel: int = 3) -> TetMesh:
    """Read any volume mesh format meshio knows (.vtu, .msh, .mesh, .xdmf, ...); ``TetMesh.read`` calls it.

    Parameters
    ----------
    path : path-like
        The mesh file; its extension names the format (``.msh`` is gmsh's).
    units : {"m", "cm", "mm"}
        The length unit of the file's coordinates; they are converted to metres.
    scale : float, optional
        A further factor on the coordinates; the factor to metres is ``UNITS[units] * scale``
        (:func:`meshing.units.length_factor`).
    stacklevel : int
        Where the warning about a large body points (:func:`meshing.units.warn_if_large`): 3 is the
        caller of this function.

    Returns
    -------
    TetMesh
        Node positions in metres.

    Raises
    ------
    ValueError
        For bad ``units`` or ``scale`` (checked before the file is opened), a file meshio cannot
        read, no tets, or a mesh :func:`tet_mesh_from_meshio` refuses (tangled, too large, ...).
    FileNotFoundError
        When there is no file at ``path``.

    Warns
    -----
    UserWarning
        When read in metres with no explicit ``scale`` and more than 10 m across: probably
        millimetres (:func:`meshing.units.warn_if_large`).
    """
    factor = length_factor(units, scale)
    mesh = _read_meshio(path)
    mesh.points = scaled_points(mesh.points, factor, name=os.fspath(path))
    result = tet_mesh_from_meshio(mesh)
    warn_if_large(result.points, units=units, scale=scale, name=os.fspath(path), stacklevel=stacklevel)
    return result


def _read_meshio(path):
    """The ``meshio.Mesh`` of a file, with one ValueError for every way the read fails."""
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
            return meshio.read(path, file_format=file_format)
    except (SystemExit, Exception) as error:
        detail = " ".join(chatter.getvalue().split()) or f"{type(error).__name__}: {error}"
        raise ValueError(f"cannot read {path} as a {file_format} mesh ({detail})") from None


def read_tet_regions(path: str | os.PathLike[str], *, name: str | None = None) -> np.ndarray | None:
    """The region tag of every tet of a mesh file, in the order of :func:`read_tet_mesh`'s tets, or None.

    The tags are the file's cell data on its ``tetra`` blocks: gmsh physical groups
    (``gmsh:physical``), Medit references (``medit:ref``) or a ``region`` array, the first of
    :data:`REGION_TAG_NAMES` present (or ``name``). :func:`read_tet_mesh` keeps the tets in the
    file's order (the ``tetra`` blocks one after the other; turning an inverted mesh the right way
    round renumbers corners within a tet, never the tets), so tag ``t`` belongs to tet ``t`` of the
    mesh read from the same file.

    Parameters
    ----------
    path : path-like
        A mesh file (any volume format meshio reads).
    name : str, optional
        The cell data to read; default the first of :data:`REGION_TAG_NAMES` that the file has.

    Returns
    -------
    (T,) int64 or None
        None when the file has no such cell data (or ``name`` is not there).

    Raises
    ------
    ValueError
        For a file that cannot be read, no tets, tags that are not integers or are negative.
    FileNotFoundError
        When there is no file at ``path``.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> from meshing import structured_box
    >>> box = structured_box((2, 1, 1), (2.0, 1.0, 1.0))
    >>> tags = (box.points[box.tets].mean(axis=1)[:, 0] > 1.0).astype(int) + 1   # 1 left, 2 right
    >>> path = write_tet_mesh(box, Path(tempfile.mkdtemp()) / "two.mesh", cell_data={"medit:ref": tags})
    >>> read_tet_regions(path).tolist() == tags.tolist()
    True
    """
    mesh = _read_meshio(path)
    blocks = [index for index, block in enumerate(mesh.cells) if block.type == "tetra"]
    if not blocks:
        found = sorted({block.type for block in mesh.cells}) or ["no cells"]
        raise ValueError(f"{path} has no tetra cells (found {', '.join(found)})")
    names = (name,) if name is not None else REGION_TAG_NAMES
    key = next((candidate for candidate in names if candidate in mesh.cell_data), None)
    if key is None:
        return None
    tags = np.concatenate([np.asarray(mesh.cell_data[key][index]).reshape(-1) for index in blocks])
    if tags.dtype.kind == "f" and np.all(tags == np.round(tags)):
        tags = tags.astype(np.int64)  # some formats store integer tags as floats
    if tags.dtype.kind not in "iu":
        raise ValueError(f"{path}: its region tags {key!r} have dtype {tags.dtype}; expected integers")
    tags = tags.astype(np.int64)
    if len(tags) and tags.min() < 0:
        raise ValueError(f"{path}: its region tags {key!r} hold {int(tags.min())}; expected tags >= 0")
    return tags


def write_tet_mesh(mesh: TetMesh, path: str | os.PathLike[str], *, point_data: Mapping[str, np.ndarray] | None = None,
                   cell_data: Mapping[str, np.ndarray] | None = None, file_format: str | None = None) -> Path:
    """Write a mesh in the format its extension names, atomically (temporary names, then renames).

    ``TetMesh.write`` calls it. XDMF (``.xdmf``, ``.xmf``) is two files: the XML ``stem.xdmf`` and its
    heavy data ``stem.h5`` beside it, which the XML names by that relative file name, so the pair can be
    moved together. Both are written under a temporary folder beside ``path`` and renamed into place, the
    ``.h5`` first; a rewrite replaces the pair and leaves nothing else behind.

    Parameters
    ----------
    mesh : TetMesh
    path : path-like
        The file to write; missing parent folders are created.
    point_data : dict of str to (n, ...) array, optional
        Values per node.
    cell_data : dict of str to (m, ...) array, optional
        Values per tet.
    file_format : str, optional
        meshio's format name (default: from the extension, :func:`mesh_file_format`).

    Returns
    -------
    Path
        ``path``.
    """
    import meshio

    path = Path(path)
    file_format = file_format or mesh_file_format(path)
    data = tet_mesh_to_meshio(mesh, point_data=point_data, cell_data=cell_data)
    if file_format == "xdmf":
        _write_xdmf(path, data)
        return path
    with atomic_path(path) as tmp:
        meshio.write(tmp, data, file_format=file_format)
    return path


def _write_xdmf(path: Path, mesh) -> None:
    """Write ``stem.xdmf`` and ``stem.h5`` atomically, the XML naming the heavy data by its relative name.

    meshio names the ``.h5`` after the ``.xdmf`` it writes and refers to it by file name: writing both
    under their final names inside a temporary folder beside ``path``, then renaming them out (the
    ``.h5`` first, so the new XML never names missing data), gives a pair that refers to each other
    correctly, on the same file system as the target, and leaves no temporary file behind.
    """
    import shutil
    import tempfile

    import meshio

    heavy = path.with_suffix(".h5")
    path.parent.mkdir(parents=True, exist_ok=True)
    folder = Path(tempfile.mkdtemp(prefix=f".{path.stem}.", suffix=".xdmf-tmp", dir=path.parent))
    try:
        meshio.write(folder / path.name, mesh, file_format="xdmf")
        os.replace(folder / heavy.name, heavy)
        os.replace(folder / path.name, path)
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def mesh_file_format(path: str | os.PathLike[str]) -> str:
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
