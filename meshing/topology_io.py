"""Spring topology files: a :class:`~meshing.topology.SpringTopology` (the tet mesh with its shells) on disk.

A tet mesh file (``.vtu``, ``.msh``, ...) holds the mesh only; the shell nodes, springs and triangles
that :func:`meshing.add_shells` adds have no place in those formats. This file keeps them, so that
``volspring-mesh --shells`` can hand its result to ``volspring-sim``.

The file is a compressed ``.npz`` (numpy, read without pickle), by convention named
``NAME.vstopo.npz`` (:data:`TOPOLOGY_SUFFIX`; the command-line tools take any ``.npz`` name for one).
Format ``"volspring.spring_topology"``, version 1, arrays (lengths in metres):

``format``, ``version``
    ``"volspring.spring_topology"`` and 1, 0-d;
``points`` (n, 3) float64
    all nodes: the tet mesh's nodes first, then the shell nodes layer by layer [m];
``mesh_node_count`` () int64
    how many of ``points`` are the tet mesh's nodes;
``tets`` (m, 4) int64
    the tet mesh's tets (indices below ``mesh_node_count``, positively oriented);
``springs`` (s, 2) int64 and ``kinds`` (s,) int8
    node pairs and the kind code of each, an index into ``kind_names`` (k,) text, the labels of
    :data:`meshing.topology.SPRING_KINDS` when the file was written;
``shell_triangles`` (f, 3) int64, ``shell_layer`` (n,) int64, ``shell_thickness`` () float64 [m]
    as in :class:`~meshing.topology.SpringTopology`.

:func:`write_topology` writes atomically (a failed write leaves no file and an earlier file intact);
:func:`read_topology` checks the format name and version (a newer version is refused naming the
file, the version found and the versions this reader knows), refuses a missing or malformed array
naming the file and the array, and rebuilds the mesh and topology through their own checks. The
arrays come back bit for bit. :func:`topology_arrays` and :func:`topology_from_arrays` are the same
layout under a prefix, for files that hold a topology among other things (``volspring.model_io``).

Examples
--------
>>> import tempfile
>>> from pathlib import Path
>>> from meshing import add_shells, read_topology, structured_box, write_topology
>>> topology = add_shells(structured_box((2, 2, 2), (1.0, 1.0, 1.0)), layers=1, thickness=0.1)
>>> path = write_topology(Path(tempfile.mkdtemp()) / "cube.vstopo.npz", topology)
>>> read_topology(path).kind_counts() == topology.kind_counts()
True
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from meshing._archive import labelled_codes, read_archive, take_array, write_archive
from meshing.mesh import TetMesh
from meshing.topology import SPRING_KINDS, SpringTopology
from meshing.units import length_factor, scaled_points, warn_if_large

__all__ = [
    "TOPOLOGY_FORMAT",
    "TOPOLOGY_SUFFIX",
    "TOPOLOGY_VERSION",
    "is_topology_path",
    "read_topology",
    "topology_arrays",
    "topology_from_arrays",
    "write_topology",
]

TOPOLOGY_FORMAT = "volspring.spring_topology"
#: The format version written; :data:`READABLE_VERSIONS` are those read.
TOPOLOGY_VERSION = 1
READABLE_VERSIONS = (1,)
#: The conventional file name ending of a topology file.
TOPOLOGY_SUFFIX = ".vstopo.npz"


def is_topology_path(path: str | os.PathLike[str]) -> bool:
    """Whether a file name is a topology file's: it ends in ``.npz`` (no tet mesh format uses that).

    >>> is_topology_path("beam.vstopo.npz"), is_topology_path("beam.NPZ"), is_topology_path("beam.vtu")
    (True, True, False)
    """
    return Path(path).suffix.lower() == ".npz"


def topology_arrays(topology: SpringTopology, *, prefix: str = "") -> dict:
    """The arrays of a topology file (module docstring), names prefixed by ``prefix``.

    Parameters
    ----------
    topology : SpringTopology
    prefix : str
        Put before every name (``"topology/"`` in a model file).

    Returns
    -------
    dict of str to ndarray
    """
    if not isinstance(topology, SpringTopology):
        raise TypeError(f"topology must be a meshing.SpringTopology, got {type(topology).__name__}")
    arrays = {
        "points": topology.points,
        "mesh_node_count": np.asarray(topology.mesh.node_count, dtype=np.int64),
        "tets": topology.mesh.tets,
        "springs": topology.springs,
        "kinds": topology.kinds,
        "kind_names": np.asarray(SPRING_KINDS),
        "shell_triangles": topology.shell_triangles,
        "shell_layer": topology.shell_layer,
        "shell_thickness": np.asarray(topology.shell_thickness, dtype=np.float64),
    }
    return {prefix + name: array for name, array in arrays.items()}


def topology_from_arrays(arrays: dict[str, np.ndarray], path: str | os.PathLike[str], *, prefix: str = "",
                         factor: float = 1.0) -> SpringTopology:
    """The topology held by a file's arrays (:func:`topology_arrays`' layout), through its own checks.

    Parameters
    ----------
    arrays : dict of str to ndarray
        As :func:`meshing._archive.read_archive` returns them.
    path : path-like
        The file, for messages.
    prefix : str
        The prefix of the topology's names.
    factor : float
        Metres per unit of the stored lengths (1: stored in metres, as written).

    Returns
    -------
    SpringTopology

    Raises
    ------
    ValueError
        For a missing or malformed array (naming the file and the array), or a mesh or topology
        their constructors refuse (naming the file).
    """
    def take(name, shape, kind):
        return take_array(arrays, prefix + name, path, shape=shape, kind=kind)

    points = take("points", ("n", 3), "f")
    mesh_node_count = int(take("mesh_node_count", (), "i"))
    tets = take("tets", ("m", 4), "i")
    springs = take("springs", ("s", 2), "i")
    kinds = labelled_codes(arrays, path, codes=prefix + "kinds", labels=prefix + "kind_names", known=SPRING_KINDS)
    triangles = take("shell_triangles", ("f", 3), "i")
    layer = take("shell_layer", ("n",), "i")
    thickness = float(take("shell_thickness", (), "f"))
    if not 0 < mesh_node_count <= len(points):
        raise ValueError(f"{path} is damaged: {prefix}mesh_node_count = {mesh_node_count}, expected 1 to "
                         f"len({prefix}points) = {len(points)}")
    points = scaled_points(points, factor, name=os.fspath(path))
    try:
        mesh = TetMesh(points[:mesh_node_count], tets)
        return SpringTopology(mesh=mesh, points=points, springs=springs, kinds=kinds, shell_triangles=triangles,
                              shell_layer=layer, shell_thickness=thickness * factor)
    except ValueError as error:
        raise ValueError(f"{path} holds an invalid spring topology: {error}") from error


def write_topology(path: str | os.PathLike[str], topology: SpringTopology) -> Path:
    """Write a spring topology (tet mesh, shell nodes, springs, shell triangles) to a file, atomically.

    Parameters
    ----------
    path : path-like
        The file, by convention ``NAME.vstopo.npz``; parent folders are created.
    topology : SpringTopology

    Returns
    -------
    Path
        ``path``.
    """
    return write_archive(path, topology_arrays(topology), format_name=TOPOLOGY_FORMAT, version=TOPOLOGY_VERSION)


def read_topology(path: str | os.PathLike[str], *, units: str = "m", scale: float | None = None,
                  stacklevel: int = 3) -> SpringTopology:
    """Read a spring topology file written by :func:`write_topology`.

    Parameters
    ----------
    path : path-like
    units : {"m", "cm", "mm"}
        The unit of the stored lengths (volspring writes metres); they are converted to metres.
    scale : float, optional
        A further factor on the lengths (:func:`meshing.units.length_factor`).
    stacklevel : int
        Where the warning about a large body points (:func:`meshing.units.warn_if_large`): 3 is the
        caller of this function.

    Returns
    -------
    SpringTopology
        Node positions and shell thickness in metres.

    Raises
    ------
    FileNotFoundError
        When there is no file at ``path``.
    ValueError
        Naming the file: not a topology file (truncated, damaged, another format), a format version
        this volspring does not read (naming it and the versions supported), a missing or malformed
        array (naming it), or a topology its own checks refuse.

    Warns
    -----
    UserWarning
        When read in metres with no explicit ``scale`` and more than 10 m across.
    """
    factor = length_factor(units, scale)
    arrays, _ = read_archive(path, format_name=TOPOLOGY_FORMAT, versions=READABLE_VERSIONS, what="spring topology")
    topology = topology_from_arrays(arrays, path, factor=factor)
    warn_if_large(topology.points, units=units, scale=scale, name=os.fspath(path), stacklevel=stacklevel)
    return topology
