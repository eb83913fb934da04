"""An on-disk cache of FEM references, keyed by everything that determines the answer.

A P2 reference costs seconds to minutes (REFERENCE.md: about 6 s to assemble at 1k nodes and 44 s at
10k with scikit-fem's default quadrature), and reports solve the same cases again and again. The key
is a SHA-256 of the mesh (points and tets bytes), the element, the material, the loads and the
clamps *as resolved on the mesh* (fixed-dof masks and values, loaded faces), the modal options, and
the code version (volspring's version and the bytes of every module the FEM answer depends on: the
FEM modules of validation, volspring's solver stack and regions, meshing's kernels and tolerances;
:data:`REFERENCE_MODULES`), so a callable
region is cached by what it selects, and any change to the reference code starts afresh. Files are
``<folder>/<kind>-<key>.npz``, written atomically.

Examples
--------
>>> import tempfile
>>> import numpy as np
>>> from meshing import TetMesh
>>> from validation.cache import cached_solve_static
>>> from validation.boundary import Box
>>> corners = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], dtype=float)
>>> cube = TetMesh.compact(corners, [[0, 4, 6, 7], [0, 4, 5, 7], [0, 2, 6, 7], [0, 2, 3, 7], [0, 1, 5, 7], [0, 1, 3, 7]])
>>> folder = tempfile.mkdtemp()
>>> first = cached_solve_static(cube, (1e6, 0.3, 1e3), clamp=Box.plane("z", 0.0), gravity=(0, 0, -9.81), folder=folder)
>>> again = cached_solve_static(cube, (1e6, 0.3, 1e3), clamp=Box.plane("z", 0.0), gravity=(0, 0, -9.81), folder=folder)
>>> bool(np.array_equal(first.displacement, again.displacement))
True
"""

from __future__ import annotations

import dataclasses
import hashlib
import inspect
import logging
import os
import zipfile
from pathlib import Path

import numpy as np

import volspring
from meshing._io import atomic_path
from meshing import tolerances
from validation import boundary, fem, fem_solvers
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from meshing.mesh import TetMesh

__all__ = ["cache_key", "cached_solve_modes", "cached_solve_static", "default_folder"]

logger = logging.getLogger(__name__)


def default_folder() -> Path:
    """``$VOLSPRING_CACHE`` if set, else ``~/.cache/volspring/fem``."""
    return Path(os.environ.get("VOLSPRING_CACHE") or Path.home() / ".cache" / "volspring" / "fem")


def _modules_used(root, packages=("validation.", "volspring.", "meshing.")) -> tuple:
    """``root`` and every module of ours its functions, classes and imported modules come from, transitively."""
    found, pending = {}, [root]
    while pending:
        module = pending.pop()
        if module.__name__ in found:
            continue
        found[module.__name__] = module
        used = {inspect.getmodule(value) for value in vars(module).values()
                if inspect.isfunction(value) or inspect.isclass(value) or inspect.ismodule(value)}
        pending += [item for item in used if item is not None and item.__name__.startswith(packages)]
    return tuple(found[name] for name in sorted(found))


#: The modules whose code determines a FEM answer (the FEM modules, the solvers, regions and geometric
#: kernels they use, found by following what :mod:`validation.fem` uses): a change to any changes every key.
REFERENCE_MODULES = _modules_used(fem) + (tolerances,)  # numbers, not functions: named, as the walk cannot see them


def _code_version() -> bytes:
    return volspring.__version__.encode() + b"".join(Path(module.__file__).read_bytes()
                                                     for module in REFERENCE_MODULES)


def cache_key(kind: str, mesh: TetMesh, material: Any, *, clamp: Any, gravity: Any = None, traction: Any = None,
              point_loads: Any = None, element: str = "P2", **options: Any) -> str:
    """The hex SHA-256 naming one reference.

    Parameters
    ----------
    kind : {"static", "modes"}
    mesh, material, clamp, gravity, traction, point_loads, element
        As for :func:`validation.fem.solve_fem_static`; clamps and tractions are resolved on the mesh
        first, so equal selections give equal keys however they were written. ``element`` (one of
        :data:`validation.fem_assembly.ELEMENTS`: "P1", "P2", "TH") is part of the key, so a Taylor-Hood
        answer and a P2 one on the same P2 displacement space are stored apart.
    **options
        Further plain values that change the answer (``count``, ``mass`` for modes).

    Raises
    ------
    TypeError
        For a ``body_force`` callable: its values between nodes cannot be hashed; call the solver
        directly instead.
    """
    if options.get("body_force") is not None:
        raise TypeError("a callable body_force cannot be part of a cache key; call validation.fem directly")
    for name in ("body_force", "solver", "tolerance"):
        options.pop(name, None)
    digest = hashlib.sha256()

    def add(*values):
        for value in values:
            array = np.ascontiguousarray(value)
            digest.update(f"{array.dtype}{array.shape}".encode())
            digest.update(array.tobytes())

    add(kind, element, _code_version(), mesh.points, mesh.tets, fem.elastic_constants(material))
    fixed = boundary.resolve_clamps(mesh, clamp)
    add(fixed.node_mask, fixed.node_values, fixed.edge_mask, fixed.edge_values)
    for faces, vector in boundary.resolve_tractions(mesh, traction):
        add(np.sort(faces, axis=1), vector)
    add(boundary.resolve_point_loads(mesh, point_loads),
        np.asarray(gravity if gravity is not None else np.zeros(3), float))
    for name in sorted(options):
        add(name, options[name])
    return digest.hexdigest()


def _save(path: Path, solution) -> None:
    arrays = {}
    for item in dataclasses.fields(solution):
        value = getattr(solution, item.name)
        if dataclasses.is_dataclass(value):
            arrays.update({f"{item.name}.{sub.name}": getattr(value, sub.name) for sub in dataclasses.fields(value)})
        else:
            arrays[item.name] = value
    with atomic_path(path) as tmp:
        np.savez(tmp, **arrays)


def _load(path: Path, cls):
    with np.load(path, allow_pickle=False) as data:
        arrays = {name: data[name] for name in data.files}

    def plain(value):
        return value.item() if value.ndim == 0 else value

    values = {}
    for item in dataclasses.fields(cls):
        if item.name == "info":
            values["info"] = fem_solvers.ReferenceInfo(**{sub.name: plain(arrays[f"info.{sub.name}"])
                                                      for sub in dataclasses.fields(fem_solvers.ReferenceInfo)})
        else:
            values[item.name] = plain(arrays[item.name])
    return cls(**values)


def _cached(kind, solve, cls, mesh, material, folder, arguments):
    path = Path(folder or default_folder()) / f"{kind}-{cache_key(kind, mesh, material, **arguments)}.npz"
    if path.is_file():
        try:
            solution = _load(path, cls)
            logger.info("FEM %s reference from cache %s", kind, path)
            return solution
        except (OSError, KeyError, ValueError, zipfile.BadZipFile) as error:
            logger.warning("ignoring unreadable cache file %s (%s); solving again", path, error)
    solution = solve(mesh, material, **arguments)
    _save(path, solution)
    return solution


def cached_solve_static(mesh: TetMesh, material: Any, *, folder: str | os.PathLike[str] | None = None,
                        **arguments: Any) -> fem.StaticSolution:
    """:func:`validation.fem.solve_fem_static`, read from ``folder`` when solved before (same key).

    Parameters
    ----------
    mesh : TetMesh
        as for :func:`validation.fem.solve_fem_static`
    material : (E, nu, density)
        as for :func:`validation.fem.solve_fem_static`
    folder : path, optional
        cache folder, default :func:`default_folder`
    **arguments
        as for :func:`validation.fem.solve_fem_static` (``solver`` and ``tolerance`` are not part of the key: they
        change the answer only within the solver tolerance)
    """
    return _cached("static", fem.solve_fem_static, fem.StaticSolution, mesh, material, folder, arguments)


def cached_solve_modes(mesh: TetMesh, material: Any, *, folder: str | os.PathLike[str] | None = None,
                       **arguments: Any) -> fem.ModalSolution:
    """:func:`validation.fem.solve_fem_modes`, read from ``folder`` when solved before (same key)."""
    arguments = {"count": 6, "element": "P2", "mass": "consistent"} | arguments  # defaults, so they hash alike
    return _cached("modes", fem.solve_fem_modes, fem.ModalSolution, mesh, material, folder, arguments)
