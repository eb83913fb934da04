"""Checkpoints: a State saved to one ``.npz`` file and loaded back bit for bit.

Key scheme of the archive:

``x``, ``v``
    positions (n, 3) [m] and velocities (n, 3) [m/s], as stored in the state (dtype kept);
``t``, ``step``
    time [s] and step count, as 0-d arrays;
``memory/KEY``
    each entry of ``state.memory``; a nested dict is flattened with ``/``, so
    ``memory["solver"]["guess"]`` is stored as ``memory/solver/guess``. Memory keys must
    therefore be strings without ``/``;
``__manifest__``
    a JSON string recording the format version and the Python type of every memory entry
    (array, numpy scalar, float, int, bool, str, None, dict), so that a loaded memory has the
    same types as the saved one: ``3`` comes back an int, ``np.float32(3)`` a float32 scalar,
    an empty dict an empty dict.

Arrays are stored with their dtype and values unchanged (npz is lossless), so a run resumed
from a checkpoint takes bit-identical steps to the run that saved it. The file is written to a
temporary name and renamed: a crash while saving leaves the previous checkpoint in place.
"""

from __future__ import annotations

import io
import json
import logging
from pathlib import Path

import numpy as np

from volspring._io import atomic_path
from volspring.scene import State

__all__ = ["save_checkpoint", "load_checkpoint"]

logger = logging.getLogger(__name__)

CHECKPOINT_VERSION = 1
_SEPARATOR = "/"


def save_checkpoint(path, state: State) -> Path:
    """Save a state (with its integrator memory) to an ``.npz`` file, atomically.

    Parameters
    ----------
    path : path-like -- the file to write; parent folders are created
    state : State -- x (n, 3) [m], v (n, 3) [m/s], t [s], step, and ``memory``: a dict of numpy
        arrays, numpy scalars, Python floats, ints, bools, strings, None, or nested dicts of these

    Returns
    -------
    Path -- ``path``

    Raises
    ------
    TypeError
        For a memory entry of another type (a list, an object array, ...), naming its key.
    ValueError
        For a memory key that is not a string or contains ``/``.

    Examples
    --------
    >>> import numpy as np, tempfile, os
    >>> from volspring import State
    >>> from volspring.checkpoint import load_checkpoint, save_checkpoint
    >>> state = State(np.zeros((2, 3)), np.ones((2, 3)), t=0.5, step=5, memory={"x_previous": np.zeros((2, 3))})
    >>> path = save_checkpoint(os.path.join(tempfile.mkdtemp(), "run.npz"), state)
    >>> loaded = load_checkpoint(path)
    >>> loaded.t, loaded.step, sorted(loaded.memory)
    (0.5, 5, ['x_previous'])
    """
    arrays = {
        "x": np.asarray(state.x),
        "v": np.asarray(state.v),
        "t": np.asarray(state.t, dtype=np.float64),
        "step": np.asarray(state.step, dtype=np.int64),
    }
    manifest = {"version": CHECKPOINT_VERSION, "memory": _flatten(state.memory, "memory", arrays)}
    for name in ("x", "v"):
        if arrays[name].dtype == object:
            raise TypeError(f"state.{name} has dtype object; expected a numeric (n, 3) array")
    arrays["__manifest__"] = np.asarray(json.dumps(manifest))
    path = Path(path)
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    with atomic_path(path) as tmp:
        tmp.write_bytes(buffer.getvalue())
    logger.debug("saved checkpoint at step %d (t = %g s) to %s", state.step, state.t, path)
    return path


def load_checkpoint(path) -> State:
    """Load a state saved by :func:`save_checkpoint`.

    Parameters
    ----------
    path : path-like

    Returns
    -------
    State -- with x, v, t (float), step (int) and memory as saved, arrays writeable

    Raises
    ------
    FileNotFoundError
        If there is no file at ``path``.
    ValueError
        If the file is not a volspring checkpoint or was written by a newer format version.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no checkpoint file at {path}")
    try:
        archive = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as error:
        raise ValueError(f"cannot read {path} as a checkpoint (.npz): {error}") from error
    with archive:
        missing = {"x", "v", "t", "step", "__manifest__"} - set(archive.files)
        if missing:
            raise ValueError(f"{path} is not a volspring checkpoint: it lacks {', '.join(sorted(missing))}")
        manifest = json.loads(str(archive["__manifest__"]))
        if manifest.get("version") != CHECKPOINT_VERSION:
            raise ValueError(f"{path} has checkpoint format version {manifest.get('version')!r}; "
                             f"this volspring reads version {CHECKPOINT_VERSION}")
        x, v = archive["x"], archive["v"]
        if x.ndim != 2 or x.shape[1:] != (3,) or v.shape != x.shape:
            raise ValueError(f"{path}: x and v must have the same shape (n, 3), got {x.shape} and {v.shape}")
        memory = _unflatten(manifest["memory"], "memory", archive)
        return State(x, v, t=float(archive["t"]), step=int(archive["step"]), memory=memory)


def _flatten(memory, prefix, arrays) -> dict:
    """Put the entries of ``memory`` into ``arrays`` under ``prefix/key``; return their manifest."""
    if not isinstance(memory, dict):
        raise TypeError(f"{prefix} must be a dict, got {type(memory).__name__}")
    manifest = {}
    for key, value in memory.items():
        if not isinstance(key, str) or not key or _SEPARATOR in key:
            raise ValueError(f"{prefix} key {key!r} must be a non-empty string without {_SEPARATOR!r} "
                             "(it becomes part of a flattened archive name)")
        name = f"{prefix}{_SEPARATOR}{key}"
        if isinstance(value, dict):
            manifest[key] = {"kind": "dict", "items": _flatten(value, name, arrays)}
            continue
        if value is None:
            manifest[key] = {"kind": "none"}
            continue
        if isinstance(value, np.ndarray):
            kind = "array"
        elif isinstance(value, np.generic):
            kind = "numpy_scalar"
        elif isinstance(value, (bool, int, float, str)):
            kind = type(value).__name__  # bool before int: bool is a subclass of int
        else:
            raise TypeError(f"{name} is a {type(value).__name__}; a checkpoint stores numpy arrays, numpy "
                            "scalars, float, int, bool, str, None and dicts of these")
        if kind == "int" and not -(2**63) <= value < 2**63:
            raise TypeError(f"{name} = {value} does not fit a 64-bit integer")
        array = np.asarray(value)
        if array.dtype == object:
            raise TypeError(f"{name} has dtype object, which a checkpoint cannot store without pickling")
        arrays[name] = array
        manifest[key] = {"kind": kind}
    return manifest


def _unflatten(manifest, prefix, archive) -> dict:
    memory = {}
    for key, entry in manifest.items():
        name = f"{prefix}{_SEPARATOR}{key}"
        kind = entry["kind"]
        if kind == "dict":
            memory[key] = _unflatten(entry["items"], name, archive)
        elif kind == "none":
            memory[key] = None
        elif kind == "array":
            memory[key] = archive[name]
        elif kind == "numpy_scalar":
            memory[key] = archive[name][()]
        elif kind in ("float", "int", "bool", "str"):
            memory[key] = {"float": float, "int": int, "bool": bool, "str": str}[kind](archive[name][()])
        else:
            raise ValueError(f"{name} has unknown kind {kind!r} in the checkpoint manifest")
    return memory
