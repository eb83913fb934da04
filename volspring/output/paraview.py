"""ParaView output: one VTU per frame and a PVD collection with the frames' decimal times.

Layout of a series named ``NAME`` in ``directory``:

``NAME.pvd`` and ``NAME_0000.vtu``, ``NAME_0001.vtu``, ...
    the tet mesh at the deformed positions: point data ``displacement`` [m] and ``velocity``
    [m/s], cell data ``volume_ratio`` (deformed / rest volume of each tet, < 0 when inverted) and
    ``strain`` (|U - I|, the Frobenius norm of the tet's rotation-free Biot strain [-], U the
    stretch of F = R U; the same on every rung of the ladder).
``NAME_springs.pvd`` and ``NAME_springs_0000.vtu``, ...
    every spring as a ``line`` cell over all nodes (shell nodes included): point data
    ``displacement`` and ``velocity``, cell data ``strain`` ((l - l0) / l0 [-]) and ``kind``
    (index into :data:`volspring.SPRING_KINDS`), and the names of those codes as field data: one
    array ``kind=NAME`` holding the code of each kind the model has (``kind=tet_edge`` = 0,
    ``kind=shell`` = 1, ...; ParaView's Information panel lists them beside the arrays). Written
    for a model with springs only: the ``"smoothed"`` rung has none, and its output is the tet
    series alone.

Times. Each VTU carries its time [s] as field data ``TimeValue`` (the one-value Float64 array
VTK's own XML writers add for a time step), equal to its time in the PVD. Both are the frame's
intended decimal time, not the float the integrator reached by adding ``dt`` step after step:
ten steps of 0.1 s are written ``1.0``, not ``0.9999999999999999``, so a ParaView script's
``set_active_time_value(1.0)`` finds the frame.
The writer receives a state's time ``t`` and its step count, not ``dt``; it writes the decimal with
the fewest significant digits within the round-off that ``step`` additions can leave on ``t``
(:func:`_frame_time`). For a step that is a decimal (0.1, 0.003, 1e-5) that is exactly ``step *
dt`` for runs of up to some 10^7 steps; any other time stays within that round-off of ``t``.

Tets and springs are two series rather than one file of mixed cells because ParaView colours a
mixed grid by one cell array covering every cell: a spring strain would need a made-up value on
each tet. Two series open cleanly (File > Open, select both ``.pvd``) and each is coloured by
its own arrays; the time slider follows the PVD times in seconds.

Every file is written atomically (temporary file, then rename), and the PVD is rewritten after
the frame's VTU files are in place, so a run that dies at any point leaves PVD files that list
complete frames only. A state holding NaN or Inf is refused: nothing is written for it.

With ``record=`` (a :meth:`volspring.output.RunFolder.record`), the writer announces the files of
each frame, in one call, before writing any of them: the run folder's manifest lists every file
the run wrote, even after a crash.
"""

from __future__ import annotations

import logging
import math
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from meshing._io import atomic_path
from meshing.geometry import signed_tet_volumes
from meshing.topology import SPRING_KINDS
from collections.abc import Sequence
import os
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from numpy.typing import ArrayLike
    from volspring.model import Model
    from volspring.scene import State

__all__ = ["ParaViewWriter", "read_pvd", "tet_strains", "write_pvd"]

logger = logging.getLogger(__name__)


def write_pvd(path: str | os.PathLike[str], entries: Sequence[tuple[float, str]]) -> Path:
    """Write a PVD collection atomically.

    Parameters
    ----------
    path : path-like
        The ``.pvd`` file.
    entries : sequence of (float, str)
        (time [s], file name relative to the PVD's folder) of each dataset.

    Returns
    -------
    Path
        ``path``.
    """
    root = ET.Element("VTKFile", type="Collection", version="0.1", byte_order="LittleEndian")
    collection = ET.SubElement(root, "Collection")
    for time, file in entries:
        # repr of a float is the shortest decimal that round-trips: the times read back are the times
        # written, and a decimal time (ParaViewWriter's) is written as that decimal ("1.0", "0.021").
        ET.SubElement(collection, "DataSet", timestep=repr(float(time)), group="", part="0", file=str(file))
    ET.indent(root)
    path = Path(path)
    with atomic_path(path) as tmp:
        ET.ElementTree(root).write(tmp, encoding="utf-8", xml_declaration=True)
    return path


def read_pvd(path: str | os.PathLike[str]) -> list:
    """The datasets of a PVD collection.

    Parameters
    ----------
    path : path-like
        A ``.pvd`` file.

    Returns
    -------
    list of (float, Path)
        (time [s], absolute path of the dataset file) of each dataset, in file order.

    Raises
    ------
    ValueError
        If the file is not a VTK collection.
    """
    path = Path(path)
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as error:
        raise ValueError(f"{path} is not valid XML: {error}") from error
    collection = root.find("Collection")
    if root.tag != "VTKFile" or root.get("type") != "Collection" or collection is None:
        raise ValueError(f"{path} is not a VTK collection (expected <VTKFile type=\"Collection\">)")
    datasets = []
    for item in collection.iter("DataSet"):
        timestep, file = item.get("timestep"), item.get("file")
        if timestep is None or file is None:
            raise ValueError(f"{path} has a DataSet without its timestep or file attribute")
        datasets.append((float(timestep), path.parent / file))
    return datasets


def _frame_time(t, steps) -> float:
    """The decimal time [s] a frame at time ``t`` after ``steps`` steps stands for.

    The integrators advance time by ``t + dt`` each step, and the writer is given ``t`` and the
    step count, not ``dt``: so the intended time ``steps * dt`` is recovered from ``t`` alone, as
    the decimal with the fewest significant digits that lies within the round-off ``steps``
    additions can accumulate. That bound: each addition rounds by at most half an ulp of the sum,
    at most ``eps |t| / 2``, and ``dt``'s own representation error, ``steps`` times over, adds
    about the same once more, so ``(steps + 1) eps |t| / 2`` in all; twice that is the slack.
    For a ``dt`` of d decimal places, ``steps * dt`` has d places too, and any other decimal of
    no more significant digits near it is at least 10^-d away: more than the slack, which grows
    as ``steps^2 eps dt`` and reaches 10^-d / 2 only after some 3 10^7 steps. So the decimal
    found is ``steps * dt`` exactly. The slack is also capped at a quarter of the mean step
    ``|t| / steps``, so that frames of a run started at t = 0 keep their order whatever the step
    count. Deterministic in (t, steps): a resumed run writes the same times as an uninterrupted one.

    >>> t = 0.0
    >>> for _ in range(10):
    ...     t += 0.1
    >>> t, _frame_time(t, 10), _frame_time(0.003 * 7, 7), _frame_time(1 / 3, 0) == 1 / 3
    (0.9999999999999999, 1.0, 0.021, True)
    """
    slack = min((steps + 1) * sys.float_info.epsilon * abs(t), abs(t) / (4 * max(steps, 1)))
    for digits in range(1, 18):  # 17 significant digits round-trip any float: the loop always returns
        candidate = float(f"{t:.{digits - 1}e}")
        if abs(candidate - t) <= slack:
            return candidate
    return t


def _add_field_data(path, arrays) -> None:
    """Add a ``<FieldData>`` block of one-value arrays to a VTU file written by meshio.

    meshio (5.3) reads a VTU's field data but its writer drops ``Mesh.field_data``
    (nschloe/meshio#1546), so the block is spliced in at the start of ``<UnstructuredGrid>``,
    where VTK's XML readers and meshio's reader look for it. ASCII arrays: one value each, read
    back exactly (a float written with repr).

    Parameters
    ----------
    path : Path
        The VTU file, rewritten in place (the caller's temporary file).
    arrays : dict of str to float or int
        The arrays: a float as ``Float64``, an int as ``Int32``.
    """
    block = ET.Element("FieldData")
    for name, value in arrays.items():
        array = ET.SubElement(block, "DataArray", type="Float64" if isinstance(value, float) else "Int32",
                              Name=name, NumberOfTuples="1", format="ascii")
        array.text = repr(value)
    text = path.read_bytes()
    tag = b"<UnstructuredGrid>"
    at = text.find(tag)
    if at < 0:
        raise RuntimeError(f"{path}: meshio wrote no {tag.decode()} element; cannot add the field data "
                           f"{', '.join(arrays)}")
    at += len(tag)
    path.write_bytes(text[:at] + b"\n" + ET.tostring(block) + text[at:])


class ParaViewWriter:
    """Write a simulation as VTU frames plus PVD collections; usable as a ``simulate`` callback.

    Parameters
    ----------
    directory : path-like
        Output folder, created if missing.
    model : Model
        The model being simulated; the tet series needs ``model.topology`` (a model built from
        arrays has springs only).
    name : str
        File name prefix (see the module docstring for the layout).
    springs : bool, optional
        Also write the spring series; default: when the model has springs (True for a model
        without springs is refused: the series would be empty).
    first_frame : int
        Resume an earlier series: keep its first ``first_frame`` frames (files and PVD entries)
        and write the next frame as number ``first_frame``; 0 (default) starts afresh. Raises if
        the existing PVD lists fewer frames.
    record : callable, optional
        Called as ``record(*paths)`` with the files of each frame (and the PVD files) before any
        of them is written, such as :meth:`RunFolder.record`; default None.
    triangles : (f, 3) int, optional
        A surface made of the model's own nodes (a cloth's triangles,
        :func:`volspring.structures.sheet_grid`): written as one more series, ``NAME_surface.pvd``.

    Attributes
    ----------
    times : list of float
        The time [s] of each frame written (or kept on resuming), as the PVD lists it.

    Notes
    -----
    Frames are numbered by the writer itself, one per call, whatever frame index the caller
    passes, so a resumed run continues the numbering. The writer returns None; ``simulate``
    only stops on an explicit False. A frame's time is the decimal its step count and ``t``
    stand for (module docstring, "Times").

    Examples
    --------
    >>> import tempfile
    >>> from meshing import TetMesh
    >>> from volspring import Material, Scene, Model
    >>> from volspring.output import ParaViewWriter
    >>> mesh = TetMesh([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], [[0, 1, 2, 3]])
    >>> model = Model.from_mesh(mesh, Material(E=1e5, nu=0.3, density=1000.0))
    >>> writer = ParaViewWriter(tempfile.mkdtemp(), model)
    >>> writer(0, Scene(model).initial_state())
    >>> writer.frame_count, writer.pvd_path.name, writer.times
    (1, 'frame.pvd', [0.0])
    """

    def __init__(self, directory: str | os.PathLike[str], model: Model, *, name: str = "frame",
                 springs: bool | None = None, first_frame: int = 0, record: Callable[..., Any] | None = None,
                 triangles: ArrayLike | None = None):
        self.directory = Path(directory)
        self.model = model
        self.name = str(name)
        if not self.name or "/" in self.name or "\\" in self.name:
            raise ValueError(f"name = {name!r} must be a non-empty file name prefix without path separators")
        self.mesh = model.topology.mesh if model.topology is not None else None
        self.springs = model.spring_count > 0 if springs is None else bool(springs)
        if self.springs and not model.spring_count:
            raise ValueError(f"springs=True, but the model has no springs (its rung is {model.rung!r}): the spring "
                             "series would be empty; leave springs= out to write the tet series only")
        self.triangles = None
        if triangles is not None:
            triangles = np.asarray(triangles)
            if triangles.ndim != 2 or triangles.shape[1] != 3 or triangles.dtype.kind not in "iu":
                raise ValueError(f"triangles have shape {triangles.shape} and dtype {triangles.dtype}; expected (f, 3) "
                                 "integer node indices")
            if triangles.size and (triangles.min() < 0 or triangles.max() >= model.node_count):
                raise ValueError(f"triangles index nodes {triangles.min()} to {triangles.max()}; the model has "
                                 f"{model.node_count} nodes")
            self.triangles = triangles.astype(np.int64)
        if self.mesh is None and not self.springs and self.triangles is None:
            raise ValueError("the model has no tet mesh (built from arrays) and springs=False: nothing to write")
        if self.mesh is not None:
            self._rest_volumes = self.mesh.tet_volumes
            self._rest_inverses = _rest_inverses(self.mesh)
        if self.springs:  # the names of the kind codes, as field data of the spring series
            self._kind_names = {f"kind={SPRING_KINDS[code]}": int(code) for code in np.unique(model.kinds)}
        self._record = record
        self.directory.mkdir(parents=True, exist_ok=True)
        self._entries: dict[str, list[tuple[float, str]]] = {"body": [], "springs": [], "surface": []}
        first_frame = int(first_frame)
        if first_frame < 0:
            raise ValueError(f"first_frame = {first_frame} is not >= 0")
        if first_frame:
            for series in self._series():
                kept = read_pvd(self._pvd(series))[:first_frame]
                if len(kept) < first_frame:
                    raise ValueError(f"cannot resume at frame {first_frame}: {self._pvd(series)} lists "
                                     f"{len(kept)} frame(s)")
                self._entries[series] = [(time, file.name) for time, file in kept]
            self._announce(*(self._pvd(series) for series in self._series()))
            for series in self._series():  # drop frames of the earlier run past the resume point
                write_pvd(self._pvd(series), self._entries[series])
        self.frame_count = first_frame
        self.times = [time for time, _ in self._entries[self._series()[0]]]

    # ------------------------------------------------------------------ paths
    @property
    def pvd_path(self) -> Path:
        """The collection of the tet series (of the spring series for a model without tets)."""
        return self._pvd(self._series()[0])

    @property
    def springs_pvd_path(self) -> Path | None:
        """The collection of the spring series, or None when springs are not written."""
        return self._pvd("springs") if self.springs else None

    def _series(self):
        return ((["body"] if self.mesh is not None else []) + (["springs"] if self.springs else [])
                + (["surface"] if self.triangles is not None else []))

    def _stem(self, series):
        return self.name if series == "body" else f"{self.name}_{series}"

    def _pvd(self, series) -> Path:
        return self.directory / f"{self._stem(series)}.pvd"

    def _vtu(self, series, frame) -> Path:
        return self.directory / f"{self._stem(series)}_{frame:04d}.vtu"

    def frame_paths(self) -> list:
        """The files the next frame writes or rewrites: its VTU files and the PVD collections.

        Returns
        -------
        list of Path
        """
        return ([self._vtu(series, self.frame_count) for series in self._series()]
                + [self._pvd(series) for series in self._series()])

    def _announce(self, *paths) -> None:
        if self._record is not None:
            self._record(*paths)

    # ------------------------------------------------------------------ writing
    def __call__(self, frame_index: int, state: State) -> None:
        """``simulate`` callback: write ``state`` as the next frame (``frame_index`` is not used)."""
        self.write(state)

    def write(self, state: State) -> int:
        """Write ``state`` as the next frame, then rewrite the PVD files.

        Parameters
        ----------
        state : State
            Positions ``x`` (n, 3) [m], velocities ``v`` (n, 3) [m/s], time ``t`` [s] and the
            number of steps ``step`` taken to reach it.

        Returns
        -------
        int
            The number of the frame written.

        Raises
        ------
        ValueError
            If the state does not fit the model, holds NaN or Inf, or its time is not after the
            previous frame's. Nothing is written then.
        """
        x, v, t, steps = _checked_state(state, self.model.node_count, self.frame_count)
        time = _frame_time(t, steps)
        if self.times and not time > self.times[-1]:
            raise ValueError(f"frame {self.frame_count} has t = {t!r} s (written {time!r} s), not after the "
                             f"previous frame's t = {self.times[-1]!r} s")
        displacement = x - self.model.rest_positions
        self._announce(*self.frame_paths())
        files: dict[str, Path] = {}
        try:
            self._write_frame(x, v, displacement, time, files)
        except BaseException:
            for path in files.values():  # complete files of a frame never listed: remove them
                path.unlink(missing_ok=True)
            raise
        for series, file in files.items():
            self._entries[series].append((time, file.name))
            write_pvd(self._pvd(series), self._entries[series])
        self.times.append(time)
        self.frame_count += 1
        logger.debug("wrote frame %d (t = %r s) to %s", self.frame_count - 1, time, self.directory)
        return self.frame_count - 1

    def _write_frame(self, x, v, displacement, time, files):
        from volspring.springs import spring_strains

        if self.mesh is not None:
            n = self.mesh.node_count
            ratio = signed_tet_volumes(x, self.mesh.tets) / self._rest_volumes
            files["body"] = self._write_vtu(
                "body", x[:n], [("tetra", self.mesh.tets)], time,
                point_data={"displacement": displacement[:n], "velocity": v[:n]},
                cell_data={"volume_ratio": [ratio], "strain": [tet_strains(self.mesh.tets, self._rest_inverses, x)]})
        if self.springs:
            strain = spring_strains(self.model, x)
            files["springs"] = self._write_vtu(
                "springs", x, [("line", self.model.springs)], time,
                point_data={"displacement": displacement, "velocity": v},
                cell_data={"strain": [strain], "kind": [self.model.kinds.astype(np.int32)]},
                field_data=self._kind_names)
        if self.triangles is not None:
            files["surface"] = self._write_vtu("surface", x, [("triangle", self.triangles)], time,
                                               point_data={"displacement": displacement, "velocity": v}, cell_data={})

    def _write_vtu(self, series, points, cells, time, *, point_data, cell_data, field_data=None) -> Path:
        import meshio

        path = self._vtu(series, self.frame_count)
        with atomic_path(path) as tmp:
            meshio.write(tmp, meshio.Mesh(points, cells, point_data=point_data, cell_data=cell_data),
                         file_format="vtu")
            _add_field_data(tmp, {"TimeValue": float(time), **(field_data or {})})
        return path


def _rest_inverses(mesh) -> np.ndarray:
    """(T, 3, 3) -- the inverse of each tet's rest edge matrix [x1 - x0, x2 - x0, x3 - x0] (a TetMesh has no flat tet)."""
    corners = mesh.points[mesh.tets]
    return np.linalg.inv(np.transpose(corners[:, 1:] - corners[:, :1], (0, 2, 1)))


def tet_strains(tets: np.ndarray, rest_inverses: np.ndarray, x: np.ndarray) -> np.ndarray:
    """(T,) float -- |U - I| of every tet at positions x: the norm of its Biot strain, free of rotation [-].

    F = R U is each tet's deformation gradient (current edge matrix times ``rest_inverses``); an
    inverted tet (det F < 0) counts its smallest stretch as negative, as the rotation-preserving
    polar decomposition of the continuum rungs does (:func:`volspring.elements.tet_kinematics.corotational`),
    so its strain is above 1.

    >>> import numpy as np
    >>> from meshing import TetMesh
    >>> tet = TetMesh([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], [[0, 1, 2, 3]])
    >>> turn = np.array([[0., -1, 0], [1, 0, 0], [0, 0, 1]])
    >>> stretched = tet.points @ np.diag([1.1, 1.0, 1.0]) @ turn.T      # 10% stretch, then a rotation
    >>> tet_strains(tet.tets, _rest_inverses(tet), stretched).round(12).tolist()
    [0.1]
    """
    x = np.asarray(x, dtype=np.float64)
    if not len(tets):
        return np.zeros(0)
    corners = x[tets]
    F = np.transpose(corners[:, 1:] - corners[:, :1], (0, 2, 1)) @ rest_inverses
    stretches = np.linalg.svd(F, compute_uv=False)
    stretches[:, 2] *= np.where(np.linalg.det(F) < 0, -1.0, 1.0)
    return np.sqrt(((stretches - 1.0) ** 2).sum(axis=1))


def _checked_state(state, node_count, frame):
    """(x, v, t, step) of a state, after checking shapes, the step count and that everything is finite."""
    x = np.asarray(state.x, dtype=np.float64)
    v = np.asarray(state.v, dtype=np.float64)
    t = float(state.t)
    steps = int(state.step)
    if steps < 0:
        raise ValueError(f"frame {frame}: step = {steps} is not >= 0")
    if x.shape != (node_count, 3) or v.shape != (node_count, 3):
        raise ValueError(f"frame {frame}: x and v must have shape ({node_count}, 3), got {x.shape} and {v.shape}")
    if not math.isfinite(t):
        raise ValueError(f"frame {frame}: t = {t} s is not finite; refusing to write it")
    bad = ~(np.isfinite(x).all(axis=1) & np.isfinite(v).all(axis=1))
    if bad.any():
        raise ValueError(f"frame {frame} (t = {t:.6g} s): {int(bad.sum())} node(s) have non-finite positions or "
                         f"velocities, first is node {int(np.flatnonzero(bad)[0])}; refusing to write NaN or Inf")
    return x, v, t, steps
