"""Blender output: the render surface per frame as an OBJ sequence and as one PC2 point cache.

The render surface is either an anchored surface (``meshing.anchor(tet_mesh, surface)``,
anything with ``deform(x) -> (p, 3)`` and ``faces``) or, by default, the boundary surface of
the tet mesh (:class:`BoundarySurface`).

Files in ``directory`` for a writer named ``NAME``:

``NAME_0000.obj``, ``NAME_0001.obj``, ...
    one Wavefront OBJ per frame (vertices and triangles), each written atomically.
``NAME.pc2``
    Blender's point cache: a 32-byte little-endian header ``b"POINTCACHE2\\0"``, int32 version 1,
    int32 point count, float32 start frame, float32 sample rate, int32 sample count, then float32
    x, y, z per point per sample (the layout Blender's Mesh Cache modifier reads, see
    ``MOD_meshcache_pc2.cc``).
``NAME_blender.py``
    with ``frame_dt=`` (the time between frames), Blender's import script: ``blender --python
    NAME_blender.py`` opens the OBJ and the PC2 as an animated scene at the run's frame rate
    (:mod:`volspring.output.blender_import`), written once the writer's first frame is in place.

PC2 validity. The cache is created atomically with zero samples; each frame appends its
samples, flushes them to disk, and only then rewrites the header's sample count. A reader
therefore sees the complete frames only, whenever the run dies; bytes of a frame cut short
lie past the counted samples and are cut off by the next writer that resumes the file. This
keeps every frame of a run that crashes, where a temporary file renamed at the end would keep
none, at the cost of one in-place header update per frame.

Axes. Both files hold volspring's coordinates as they are: z up, metres, which are Blender's
own axes. Blender's default OBJ import assumes y up and turns the object 90 degrees about X
(gravity then points along +Y); import ``NAME_0000.obj`` with Forward = Y, Up = Z instead, the
vertex order kept, and add a Mesh Cache modifier reading ``NAME.pc2`` (its default axes, Forward
Y and Up Z, match) -- or run the import script, which does that.

With ``record=`` (a :meth:`volspring.output.RunFolder.record`), the writer announces the files of
each frame, in one call, before writing them: the run folder's manifest lists every file the run
wrote, even after a crash.
"""

from __future__ import annotations

import logging
import os
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from meshing._io import atomic_path
from volspring.output.blender_import import blender_frame_rate, import_script_path, write_import_script
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, cast

if TYPE_CHECKING:
    from meshing.anchoring import Anchor
    from meshing.mesh import TetMesh
    from volspring.model import Model
    from numpy.typing import ArrayLike
    from volspring.scene import State

__all__ = ["BlenderWriter", "BoundarySurface", "read_pc2"]

logger = logging.getLogger(__name__)

PC2_MAGIC = b"POINTCACHE2\0"
#: magic, file version, point count, start frame, sample rate, sample count
PC2_HEADER = struct.Struct("<12siiffi")
_COUNT_OFFSET = PC2_HEADER.size - 4


@dataclass(frozen=True, eq=False)
class BoundarySurface:
    """The boundary triangles of a tet mesh as a render surface (same interface as an Anchor).

    Parameters
    ----------
    nodes : (p,) int64
        The tet mesh nodes on the boundary, sorted.
    faces : (f, 3) int64
        Boundary triangles indexing ``nodes`` (outward normals).
    node_count : int
        Node count the deformed positions must have.
    """

    nodes: np.ndarray
    faces: np.ndarray
    node_count: int

    @classmethod
    def from_mesh(cls, mesh: TetMesh | Model) -> "BoundarySurface":
        """The boundary surface of a TetMesh (or of a Model's tet mesh)."""
        if hasattr(mesh, "topology"):  # a Model: its mesh nodes come first
            if mesh.topology is None:
                raise ValueError("the model has no tet mesh (built from arrays); give a render surface")
            node_count = mesh.node_count
            mesh = mesh.topology.mesh
        else:
            node_count = mesh.node_count
        nodes = mesh.boundary_nodes
        local = np.full(mesh.node_count, -1, dtype=np.int64)
        local[nodes] = np.arange(len(nodes))
        return cls(nodes, local[mesh.boundary_faces], node_count)

    @classmethod
    def from_triangles(cls, triangles: np.ndarray, node_count: int) -> "BoundarySurface":
        """A surface made of a model's own nodes, ``triangles`` (f, 3) indexing them (a cloth's)."""
        triangles = np.asarray(triangles, dtype=np.int64)
        nodes = np.unique(triangles)
        return cls(nodes, np.searchsorted(nodes, triangles), int(node_count))

    @property
    def point_count(self) -> int:
        return len(self.nodes)

    def deform(self, x: ArrayLike) -> np.ndarray:
        """The surface vertices at node positions ``x``.

        Parameters
        ----------
        x : (n, 3) float
            Node positions [m].

        Returns
        -------
        (p, 3) float
            The positions of the surface's nodes [m].
        """
        x = np.asarray(x, dtype=np.float64)
        if x.shape != (self.node_count, 3):
            raise ValueError(f"x must have shape ({self.node_count}, 3), got {x.shape}")
        return x[self.nodes]


def read_pc2(path: str | os.PathLike[str]) -> tuple[np.ndarray, float, float]:
    """Read a PC2 point cache.

    Parameters
    ----------
    path : path-like
        The ``.pc2`` file.

    Returns
    -------
    samples : (k, p, 3) float32
        The points of each of the header's k samples [m].
    start : float
        Start frame.
    rate : float
        Sample rate (frames per sample).
    """
    path = Path(path)
    data = path.read_bytes()
    if len(data) < PC2_HEADER.size:
        raise ValueError(f"{path} has {len(data)} bytes, fewer than a PC2 header ({PC2_HEADER.size})")
    magic, version, points, start, rate, count = PC2_HEADER.unpack_from(data)
    if magic != PC2_MAGIC:
        raise ValueError(f"{path} is not a PC2 file: it starts with {magic!r}, expected {PC2_MAGIC!r}")
    needed = PC2_HEADER.size + 12 * points * count
    if len(data) < needed:
        raise ValueError(f"{path}: the header counts {count} samples of {points} points ({needed} bytes), "
                         f"but the file has {len(data)} bytes")
    samples = np.frombuffer(data, dtype="<f4", count=3 * points * count, offset=PC2_HEADER.size)
    return samples.reshape(count, points, 3), float(start), float(rate)


class BlenderWriter:
    """Write the render surface of each frame as OBJ files and one PC2 cache; a ``simulate`` callback.

    Parameters
    ----------
    directory : path-like
        Output folder, created if missing.
    surface : Anchor, BoundarySurface, TetMesh or Model
        What to write: anything with ``deform(x) -> (p, 3)`` and ``faces`` ((k, 3) int or
        None); a TetMesh or Model stands for its boundary surface.
    name : str
        File name prefix (see the module docstring).
    obj : bool
        Write the OBJ sequence (needs faces); default True.
    pc2 : bool
        Write the PC2 cache; default True.
    start_frame : float
        PC2 header's start frame, default 0 (Blender's Mesh Cache in its frame mode ignores it;
        the import script shows the first sample at frame 1).
    sample_rate : float
        PC2 header's frames per sample, default 1.
    first_frame : int
        Resume an earlier run: keep its first ``first_frame`` samples and OBJ files, and write
        the next frame as number ``first_frame``; 0 (default) starts afresh.
    record : callable, optional
        Called as ``record(*paths)`` with the files of each frame (OBJ, PC2 and, at the
        writer's first frame, the import script) before they are written, such as
        :meth:`RunFolder.record`; default None.
    frame_dt : float, optional
        Time between frames [s] (``simulate``'s ``frame_dt``, or ``dt`` when every step is a
        frame). Given, the writer also writes the import script ``NAME_blender.py`` with the
        scene's frame rate ``1 / frame_dt`` (needs both ``obj`` and ``pc2``); default None
        writes none.

    Examples
    --------
    >>> import tempfile
    >>> from meshing import TetMesh
    >>> from volspring import State
    >>> from volspring.output import BlenderWriter, read_pc2
    >>> mesh = TetMesh([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], [[0, 1, 2, 3]])
    >>> writer = BlenderWriter(tempfile.mkdtemp(), mesh)
    >>> writer(0, State(mesh.points, 0 * mesh.points))
    >>> read_pc2(writer.pc2_path)[0].shape
    (1, 4, 3)

    With the frame step, a script opens the frames in Blender (``blender --python DIR/frame_blender.py``):

    >>> writer = BlenderWriter(tempfile.mkdtemp(), mesh, frame_dt=0.04)
    >>> writer(0, State(mesh.points, 0 * mesh.points))
    >>> sorted(path.name for path in writer.directory.iterdir())
    ['frame.pc2', 'frame_0000.obj', 'frame_blender.py']
    """

    def __init__(self, directory: str | os.PathLike[str], surface: Anchor | BoundarySurface | TetMesh | Model, *,
                 name: str = "frame", obj: bool = True, pc2: bool = True, start_frame: float = 0.0,
                 sample_rate: float = 1.0,
                 first_frame: int = 0, record: Callable[..., Any] | None = None, frame_dt: float | None = None):
        if not hasattr(surface, "deform"):
            surface = BoundarySurface.from_mesh(surface)
        self.surface = cast("Anchor | BoundarySurface", surface)  # what has deform(x)
        self.directory = Path(directory)
        self.name = str(name)
        if not self.name or "/" in self.name or "\\" in self.name:
            raise ValueError(f"name = {name!r} must be a non-empty file name prefix without path separators")
        self.obj, self.pc2 = bool(obj), bool(pc2)
        if not (self.obj or self.pc2):
            raise ValueError("obj=False and pc2=False: nothing to write")
        faces = getattr(surface, "faces", None)
        if self.obj and faces is None:
            raise ValueError("the surface has no faces (anchored bare points): write pc2 only (obj=False)")
        if self.obj:
            # 1-based vertex indices; the faces never change, so their text is built once.
            faces = np.asarray(faces, dtype=np.int64)
            self._faces_text = ("f %d %d %d\n" * len(faces)) % tuple((faces + 1).ravel().tolist())
        for value, label in ((start_frame, "start_frame"), (sample_rate, "sample_rate")):
            if not np.isfinite(value):
                raise ValueError(f"{label} = {value} is not finite")
        self.start_frame, self.sample_rate = float(start_frame), float(sample_rate)
        self.frame_dt: float | None = None
        if frame_dt is not None:
            if not (self.obj and self.pc2):
                raise ValueError(f"frame_dt = {frame_dt!r} s is for the import script, which needs both the OBJ "
                                 f"and the PC2 (got obj={self.obj}, pc2={self.pc2})")
            self.frame_dt = float(frame_dt)
            blender_frame_rate(self.frame_dt)  # refuses a step Blender cannot express, before any file
        self._script_due = self.frame_dt is not None
        self.directory.mkdir(parents=True, exist_ok=True)
        self.frame_count = int(first_frame)
        if self.frame_count < 0:
            raise ValueError(f"first_frame = {first_frame} is not >= 0")
        self._point_count: int | None = None
        self._record = record
        if self.pc2 and self.frame_count:
            self._announce(self.pc2_path)
            self._resume_pc2()

    @property
    def pc2_path(self) -> Path:
        return self.directory / f"{self.name}.pc2"

    def obj_path(self, frame: int) -> Path:
        return self.directory / f"{self.name}_{frame:04d}.obj"

    @property
    def import_script_path(self) -> Path | None:
        """``NAME_blender.py``, Blender's import script, or None without ``frame_dt``."""
        return None if self.frame_dt is None else import_script_path(self.directory, self.name)

    def frame_paths(self) -> list:
        """The files the next frame writes or extends: its OBJ file, the PC2 cache and, the first
        time, the import script.

        Returns
        -------
        list of Path
        """
        return (([self.obj_path(self.frame_count)] if self.obj else []) + ([self.pc2_path] if self.pc2 else [])
                + ([self.import_script_path] if self._script_due else []))

    def _announce(self, *paths) -> None:
        if self._record is not None:
            self._record(*paths)

    def __call__(self, frame_index: int, state: State) -> None:
        """``simulate`` callback: write ``state`` as the next frame (``frame_index`` is not used)."""
        self.write(state)

    def write(self, state: State) -> int:
        """Write the surface at ``state.x`` as the next frame.

        Parameters
        ----------
        state : State
            Positions ``x`` (n, 3) [m] and time ``t`` [s].

        Returns
        -------
        int
            The number of the frame written.

        Raises
        ------
        ValueError
            If the positions or the deformed surface hold NaN or Inf (nothing is written then).
        """
        x = np.asarray(state.x, dtype=np.float64)
        bad = ~np.isfinite(x).all(axis=1)
        if bad.any():
            raise ValueError(f"frame {self.frame_count} (t = {float(state.t):.6g} s): {int(bad.sum())} node(s) "
                             f"have non-finite positions, first is node {int(np.flatnonzero(bad)[0])}; "
                             "refusing to write NaN or Inf")
        points = np.asarray(self.surface.deform(x), dtype=np.float64)
        if points.ndim != 2 or points.shape[1] != 3 or not np.isfinite(points).all():
            raise ValueError(f"frame {self.frame_count}: the deformed surface must be finite of shape (p, 3), "
                             f"got shape {points.shape}")
        self._announce(*self.frame_paths())
        if self.obj:
            with atomic_path(self.obj_path(self.frame_count)) as tmp:
                # %.9g round-trips float32, the precision Blender keeps.
                vertices = ("v %.9g %.9g %.9g\n" * len(points)) % tuple(points.ravel().tolist())
                tmp.write_text(f"# volspring frame {self.frame_count}, t = {float(state.t)!r} s\n"
                               f"# z up [m]: import with Forward Y, Up Z (Blender's default turns it on its side)\n"
                               + vertices + self._faces_text)
        if self.pc2:
            self._append_pc2(points)
        if self._script_due and self.frame_dt is not None:  # after the frame's files: it names them all
            write_import_script(self.directory, name=self.name, frame_dt=self.frame_dt)
            self._script_due = False
        self.frame_count += 1
        return self.frame_count - 1

    # ------------------------------------------------------------------ PC2
    def _header(self, point_count, sample_count) -> bytes:
        return PC2_HEADER.pack(PC2_MAGIC, 1, point_count, self.start_frame, self.sample_rate, sample_count)

    def _append_pc2(self, points):
        path = self.pc2_path
        if self._point_count is None:  # a fresh cache: created atomically, with no sample yet
            with atomic_path(path) as tmp:
                tmp.write_bytes(self._header(len(points), 0))
            self._point_count = len(points)
        if len(points) != self._point_count:
            raise ValueError(f"frame {self.frame_count} has {len(points)} surface points, "
                             f"the cache {path} holds {self._point_count}")
        sample = points.astype("<f4").tobytes()
        with open(path, "r+b") as file:
            offset = PC2_HEADER.size + self.frame_count * len(sample)
            file.seek(offset)
            file.write(sample)
            file.truncate()
            file.flush()
            os.fsync(file.fileno())
            # Only now count the sample: a crash before this line leaves the previous count valid.
            file.seek(_COUNT_OFFSET)
            file.write(struct.pack("<i", self.frame_count + 1))
            file.flush()

    def _resume_pc2(self):
        path = self.pc2_path
        samples, _, _ = read_pc2(path)
        if len(samples) < self.frame_count:
            raise ValueError(f"cannot resume at frame {self.frame_count}: {path} holds {len(samples)} sample(s)")
        self._point_count = samples.shape[1]
        with open(path, "r+b") as file:
            file.seek(_COUNT_OFFSET)
            file.write(struct.pack("<i", self.frame_count))
            file.truncate(PC2_HEADER.size + 12 * self._point_count * self.frame_count)
