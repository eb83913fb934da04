"""Sweep files: a scene file plus the values to sweep, written down as TOML.

A sweep file names its scene (relative to the sweep file) and the values per key path: a grid of values, ranges
to draw from with a seed, values shared by every run, and probes. ``volspring sweep trade.toml`` runs one; the
command line's ``--grid``, ``--random``, ``--set``, ``--probe``, ``--samples`` and ``--seed`` add to it (a key path
given on the command line replaces the file's)::

    scene = "beam_vs_fem.toml"          # the scene file, relative to this file
    description = "the speed/accuracy trade of the beam"

    [set]                               # one value for every run, as --set
    duration = 1.5
    integrator.dt = 0.02                # a dotted key (or an inline table) sets each key path it names

    [grid]                              # one run per combination, as --grid; a key path with brackets is quoted
    "bodies[0].model" = ["springs", "springs+volume", "smoothed"]
    integrator.dt = [0.01, 0.02, 0.05]  # a dotted key: the key path integrator.dt

    [random]                            # samples draws from [low, high) per key path, as --random
    "bodies[0].material.E" = [1e6, 1e7]

    samples = 4                         # draws of [random] (required with it)
    seed = 1

    [probes]                            # name = a point [m], as --probe
    tip = [0.5, 0, 0]

and ``frequencies = N`` (a top-level key) measures each run's N lowest natural frequencies at rest, as
``--frequencies``.

(The top-level keys ``samples`` and ``seed`` must come before the first table in TOML.) Errors name the key path
in the file (``grid."bodies[0].model" = "springs" is not a list of values``) and refuse unknown keys with the closest
known one suggested, as scene files do (:mod:`volspring.scene_file`).

Examples
--------
>>> import tempfile
>>> from pathlib import Path
>>> folder = Path(tempfile.mkdtemp())
>>> _ = (folder / "trade.toml").write_text('''
... scene = "beam.toml"
... seed = 1
... [grid]
... "bodies[0].model" = ["springs", "smoothed"]
... integrator.dt = [0.01, 0.02]
... [set]
... duration = 0.5
... ''')
>>> sweep = read_sweep_file(folder / "trade.toml")
>>> sweep.scene.name, sweep.grid, sweep.seed
('beam.toml', {'duration': [0.5], 'bodies[0].model': ['springs', 'smoothed'], 'integrator.dt': [0.01, 0.02]}, 1)
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import os

__all__ = ["SweepFile", "is_sweep_file", "read_sweep_file"]

#: The top-level keys of a sweep file, and what each holds.
KEYS = {
    "scene": "the scene file (.toml), relative to the sweep file",
    "description": "free text",
    "set": "a table: key path = one value for every run (as --set)",
    "grid": "a table: key path = [values] (as --grid)",
    "random": "a table: key path = [low, high] (as --random)",
    "samples": "draws of the [random] ranges",
    "seed": "seed of the [random] draws",
    "probes": "a table: name = [x, y, z] [m] (as --probe)",
    "frequencies": "the scene's lowest natural frequencies measured per run, this many (as --frequencies)",
}


@dataclass(frozen=True)
class SweepFile:
    """A sweep file, read: :func:`volspring.sweep.run_sweep`'s arguments.

    Parameters
    ----------
    path : Path
        The sweep file.
    scene : Path
        The scene file it names (resolved against the sweep file's folder).
    grid : dict of str to list
        Key path -> values: ``[set]`` values first (one each), then ``[grid]``.
    random : dict of str to (low, high)
    samples : int or None
    seed : int
    probes : dict of str to [x, y, z]
    description : str
    frequencies : int
    """

    path: Path
    scene: Path
    grid: dict = field(default_factory=dict)
    random: dict = field(default_factory=dict)
    samples: int | None = None
    seed: int = 0
    probes: dict = field(default_factory=dict)
    description: str = ""
    frequencies: int = 0


def is_sweep_file(table: dict) -> bool:
    """Whether a TOML file's contents are a sweep file (no ``bodies``, and a ``scene`` or a table of values), not a
    scene file."""
    return "bodies" not in table and any(key in table for key in ("scene", "grid", "random", "set", "probes"))


def read_sweep_file(path: str | os.PathLike[str]) -> SweepFile:
    """Read and check a sweep file (module docstring).

    Raises
    ------
    SceneFileError
        For a file that is not valid TOML or not a sweep file, naming the key path of a bad value.
    FileNotFoundError
        For a missing sweep file.
    """
    from volspring.scene_file import SceneFileError, load_toml
    from volspring.scene_file._schema import unknown_key

    path = Path(path)
    table = load_toml(path)
    for name in table:
        if name not in KEYS:
            raise unknown_key("", name, list(KEYS))
    if not isinstance(table.get("scene"), str):
        raise SceneFileError(f"{path}: scene is missing or not a string; expected the scene file it sweeps, e.g. "
                             "scene = \"beam.toml\"")
    for name in ("set", "grid", "random", "probes"):
        if not isinstance(table.get(name, {}), dict):
            raise SceneFileError(f"{name} is {type(table[name]).__name__}; expected a table ([{name}])")
    grid = {key: [value] for key, value in _flattened(table.get("set", {})).items()}
    for key, values in _flattened(table.get("grid", {})).items():
        if not isinstance(values, list):
            raise SceneFileError(f"grid.{_quoted(key)} = {values!r} is not a list of values; expected [v1, v2, ...]")
        if key in grid:
            raise SceneFileError(f"grid.{_quoted(key)} is also in [set]; give it once")
        grid[key] = values
    random = {}
    for key, bounds in _flattened(table.get("random", {})).items():
        if not (isinstance(bounds, list) and len(bounds) == 2
                and all(isinstance(end, numbers.Real) and not isinstance(end, bool) for end in bounds)):
            raise SceneFileError(f"random.{_quoted(key)} = {bounds!r} is not a range; expected [low, high]")
        random[key] = tuple(bounds)
    probes = {}
    for name, point in table.get("probes", {}).items():
        if not (name.isidentifier() and isinstance(point, list) and len(point) == 3
                and all(isinstance(value, numbers.Real) and not isinstance(value, bool) for value in point)):
            raise SceneFileError(f"probes.{name} = {point!r} is not a point; expected a name and [x, y, z] [m]")
        probes[name] = [float(value) for value in point]
    for name in ("samples", "seed", "frequencies"):
        if name in table and (isinstance(table[name], bool) or not isinstance(table[name], int)):
            raise SceneFileError(f"{name} = {table[name]!r} is not a whole number")
    return SweepFile(path, (path.parent / table["scene"]), grid, random, table.get("samples"), table.get("seed", 0),
                     probes, table.get("description", ""), table.get("frequencies", 0))


def _flattened(table: dict, prefix: str = "") -> dict[str, Any]:
    """``{"integrator": {"dt": [...]}}`` (a dotted TOML key) -> ``{"integrator.dt": [...]}``."""
    flat: dict[str, Any] = {}
    for key, value in table.items():
        if isinstance(value, dict):
            flat.update(_flattened(value, f"{prefix}{key}."))
        else:
            flat[f"{prefix}{key}"] = value
    return flat


def _quoted(key: str) -> str:
    """A key path as TOML writes it in a table: quoted when it holds brackets."""
    return f'"{key}"' if "[" in key else key
