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
    a JSON string recording the format version, the Python type of every memory entry
    (array, numpy scalar, float, int, bool, str, None, dict), so that a loaded memory has the
    same types as the saved one: ``3`` comes back an int, ``np.float32(3)`` a float32 scalar,
    an empty dict an empty dict; and, when saved with the run's scene, integrator and step
    (format version 2), ``run``: the step ``dt``, the integrator's name and options, the model's
    rung (:data:`volspring.ladder.MODELS`; absent before the ladder: springs), and a
    fingerprint of the model (SHA-256 of its rest positions, springs, rest lengths, stiffness,
    damping, masses and pinned nodes; of its rung and the arrays that define each of its other
    element sets, so the corotated tets and nodal strain of the upper rungs: tets, per-tet shear and
    bulk, regions, stiffness damping; of the supports and bodies where a scene has them), so that
    :func:`load_checkpoint` refuses to resume another model (another rung, alpha, E, nu, ...),
    another integrator or another step, naming what differs.

Arrays are stored with their dtype and values unchanged (npz is lossless), so a run resumed
from a checkpoint takes bit-identical steps to the run that saved it. The file is written to a
temporary name and renamed: a crash while saving leaves the previous checkpoint in place.
"""

from __future__ import annotations

import hashlib
import io
import json
import logging
import zipfile
import zlib
from pathlib import Path

import numpy as np

from meshing._io import atomic_path
from meshing._signals import interruptions_deferred
from volspring.scene import State
import os
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from volspring.integrators.base import Integrator
    from volspring.scene import Scene

__all__ = ["save_checkpoint", "load_checkpoint", "CheckpointMismatch", "model_fingerprint"]

logger = logging.getLogger(__name__)

CHECKPOINT_VERSION = 2
_READABLE_VERSIONS = (1, 2)  # version 1: no run record (nothing to check a resume against)

# What each fingerprinted part of a model says about how it was made (for the refusal message).
_FINGERPRINT_PARTS = {
    "rest positions": "the mesh or its placement",
    "springs": "the mesh or its shells",
    "rest lengths": "the mesh",
    "stiffness": "E, the stiffness rule or the raw stiffness",
    "damping": "the damping ratio or damping",
    "masses": "the density or the mesh",
    "pinned nodes": "the pins",
    "held components": "the supports",
    "node body": "the bodies",
    "body materials": "the bodies' materials",
    "rung": "rung of the ladder",
}
# Any other part is an element set besides the springs (``elements[i] TYPE``).
_ELEMENT_CAUSE = "alpha, E, nu, regions or damping"


class CheckpointMismatch(ValueError):
    """A checkpoint was written by another run than the one asking to resume from it."""
_SEPARATOR = "/"


def model_fingerprint(scene: Scene) -> dict:
    """Short SHA-256 digests of everything that makes a scene's model and supports what they are.

    Parameters
    ----------
    scene : Scene

    Returns
    -------
    dict
        part name ("rest positions", "springs", "rest lengths", "stiffness", "damping", "masses", "pinned nodes", and
        where a scene has them "held components", "node body", "body materials", "rung" (a model off the springs rung)
        and one entry per element set besides the springs, ``"elements[i] TYPE"``) -> 16 hex digits of the SHA-256 of
        its bytes (dtype and shape included), so equal digests mean bit-identical data. An element set is digested by
        the arrays a model file stores for it (:data:`volspring.model_io.ELEMENT_SET_TYPES`), a set of another type by
        its stencil only (its own data are not known here).
    """
    from volspring.model_io import ELEMENT_SET_TYPES

    model = scene.model
    pins = np.zeros(0, dtype=np.int64) if scene.pins is None else scene.pins.nodes
    arrays: dict[str, np.ndarray | dict] = {
        "rest positions": model.rest_positions, "springs": model.springs, "rest lengths": model.rest_lengths,
        "stiffness": model.stiffness, "damping": model.damping, "masses": model.masses, "pinned nodes": pins}
    # Parts that only exist in some scenes are listed only there, so older checkpoints still match.
    if scene.supports:
        arrays["held components"] = scene.held
    if model.body_count > 1:
        arrays["node body"] = model.node_body
        arrays["body materials"] = np.array([[m.E, m.nu, m.density] if m is not None else [np.nan] * 3
                                             for m in model.materials])
    if model.rung != "springs":
        arrays["rung"] = np.asarray(model.rung)
    for index, element_set in enumerate(model.elements):
        if element_set is not model.spring_elements:
            to_arrays = next((to_arrays for kind, to_arrays, _ in ELEMENT_SET_TYPES.values()
                              if type(element_set) is kind), None)
            parts = {"stencil": element_set.stencil} if to_arrays is None else to_arrays(element_set)
            arrays[f"elements[{index}] {type(element_set).__name__}"] = parts
    return {name: _digest(array) for name, array in arrays.items()}


def _digest(value) -> str:
    """16 hex digits of the SHA-256 of an array (dtype, shape and bytes), or of a dict of arrays by name."""
    digest = hashlib.sha256()
    for key, array in (sorted(value.items()) if isinstance(value, dict) else [("", value)]):
        array = np.ascontiguousarray(array)
        digest.update(f"{key}{array.dtype.str}{array.shape}".encode())
        digest.update(array.tobytes())
    return digest.hexdigest()[:16]


def _integrator_record(integrator) -> dict:
    """The integrator's name and its scalar options (public attributes), to compare on resume."""
    options = {key: value for key, value in sorted(vars(integrator).items())
               if not key.startswith("_") and key != "last_solve" and isinstance(value, (bool, int, float, str))}
    return {"name": integrator.name, "options": options}


def save_checkpoint(path: str | os.PathLike[str], state: State, *, scene: Scene | None = None,
                    integrator: Integrator | None = None, dt: float | None = None) -> Path:
    """Save a state (with its integrator memory) to an ``.npz`` file, atomically.

    Parameters
    ----------
    path : path-like
        the file to write; parent folders are created
    state : State
        x (n, 3) [m], v (n, 3) [m/s], t [s], step, and ``memory``: a dict of numpy arrays, numpy scalars, Python floats,
        ints, bools, strings, None, or nested dicts of these
    scene, integrator, dt : optional
        the run that wrote the state (all three or none): recorded so that :func:`load_checkpoint` can refuse to resume
        it with another model, integrator or step

    Returns
    -------
    Path
        ``path``

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
    given = [value is not None for value in (scene, integrator, dt)]
    if any(given) and not all(given):
        raise ValueError("save_checkpoint records a run with scene, integrator and dt together; got only "
                         + ", ".join(name for name, ok in zip(("scene", "integrator", "dt"), given) if ok))
    if scene is not None and integrator is not None and dt is not None:  # all(given)
        manifest["run"] = {"dt": float(dt), "integrator": _integrator_record(integrator), "rung": scene.model.rung,
                           "fingerprint": model_fingerprint(scene)}
    for name in ("x", "v"):
        if arrays[name].dtype == object:
            raise TypeError(f"state.{name} has dtype object; expected a numeric (n, 3) array")
    arrays["__manifest__"] = np.asarray(json.dumps(manifest))
    path = Path(path)
    buffer = io.BytesIO()
    with interruptions_deferred():  # a stop waits for savez: zipfile cut in the middle cannot clean up after itself
        np.savez(buffer, **arrays)  # type: ignore[arg-type]  # numpy's stub: a ** key could be allow_pickle
    with atomic_path(path) as tmp:
        tmp.write_bytes(buffer.getvalue())
    logger.debug("saved checkpoint at step %d (t = %g s) to %s", state.step, state.t, path)
    return path


def load_checkpoint(path: str | os.PathLike[str], *, scene: Scene | None = None, integrator: Integrator | None = None,
                    dt: float | None = None) -> State:
    """Load a state saved by :func:`save_checkpoint`, checking it belongs to the run resuming it.

    Parameters
    ----------
    path : path-like
    scene, integrator, dt : optional
        the run about to resume; each one given is compared with what the checkpoint recorded (a checkpoint saved
        without a run record is not checked)

    Returns
    -------
    State
        with x, v, t (float), step (int) and memory as saved, arrays writeable

    Raises
    ------
    FileNotFoundError
        If there is no file at ``path``.
    ValueError
        If the file is not a readable volspring checkpoint (truncated, corrupt, another kind of
        file) or was written by a newer format version; the message names the file.
    CheckpointMismatch
        If it was written with another step, integrator or model (naming what differs).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no checkpoint file at {path}")
    if not zipfile.is_zipfile(path):
        raise ValueError(f"{path} is not a readable checkpoint: it is not a complete .npz (zip) archive "
                         "(truncated, or another kind of file)")
    try:
        with np.load(path, allow_pickle=False) as archive:
            state, manifest = _read(path, archive)
    except (OSError, EOFError, KeyError, zipfile.BadZipFile, zlib.error, json.JSONDecodeError,
            UnicodeDecodeError) as error:
        raise ValueError(f"{path} is not a readable checkpoint (truncated or corrupt?): "
                         f"{type(error).__name__}: {error}") from error
    except ValueError as error:
        if str(path) in str(error):
            raise
        raise ValueError(f"{path} is not a readable checkpoint (truncated or corrupt?): {error}") from error
    if scene is not None and state.x.shape[0] != scene.model.node_count:
        raise CheckpointMismatch(f"{path} holds {state.x.shape[0]} nodes, the model has {scene.model.node_count}; "
                                 "resume with the mesh and model of the run that wrote it")
    _check_run(path, manifest.get("run"), scene, integrator, dt)
    return state


def _read(path, archive):
    missing = {"x", "v", "t", "step", "__manifest__"} - set(archive.files)
    if missing:
        raise ValueError(f"{path} is not a volspring checkpoint: it lacks {', '.join(sorted(missing))}")
    manifest = json.loads(str(archive["__manifest__"]))
    if manifest.get("version") not in _READABLE_VERSIONS:
        raise ValueError(f"{path} has checkpoint format version {manifest.get('version')!r}; "
                         f"this volspring reads versions {', '.join(map(str, _READABLE_VERSIONS))}")
    x, v = archive["x"], archive["v"]
    if x.ndim != 2 or x.shape[1:] != (3,) or v.shape != x.shape:
        raise ValueError(f"{path}: x and v must have the same shape (n, 3), got {x.shape} and {v.shape}")
    memory = _unflatten(manifest["memory"], "memory", archive)
    return State(x, v, t=float(archive["t"]), step=int(archive["step"]), memory=memory), manifest


def _check_run(path, run, scene, integrator, dt) -> None:
    """Refuse a resume by another run than the one that wrote the checkpoint, naming what differs."""
    if run is None:
        return
    if dt is not None and float(dt) != run["dt"]:
        raise CheckpointMismatch(f"{path} was written with dt = {run['dt']!r} s; this run asks for "
                                 f"dt = {float(dt)!r} s (a resumed run keeps the step of the run it continues)")
    if integrator is not None:
        mine = _integrator_record(integrator)
        if mine != run["integrator"]:
            theirs = run["integrator"]
            if mine["name"] != theirs["name"]:
                what = f"integrator {theirs['name']}; this run uses {mine['name']}"
            else:
                changed = sorted(key for key in set(mine["options"]) | set(theirs["options"])
                                 if mine["options"].get(key) != theirs["options"].get(key))
                what = (f"{theirs['name']} options " + ", ".join(
                    f"{key} = {theirs['options'].get(key)!r} (now {mine['options'].get(key)!r})" for key in changed))
            raise CheckpointMismatch(f"{path} was written with {what}")
    if scene is not None:
        rung = run.get("rung", "springs")  # checkpoints from before the ladder: springs
        if rung != scene.model.rung:
            raise CheckpointMismatch(f"{path} was written for a model on the {rung!r} rung; this run's model is on "
                                     f"the {scene.model.rung!r} rung (resume with the model= of the run that wrote it)")
        mine, theirs = model_fingerprint(scene), run["fingerprint"]
        others = sorted((set(mine) | set(theirs)) - set(_FINGERPRINT_PARTS))
        differ = [name for name in [*_FINGERPRINT_PARTS, *others] if mine.get(name) != theirs.get(name)]
        if differ:
            causes = sorted({_FINGERPRINT_PARTS.get(name, _ELEMENT_CAUSE) for name in differ})
            raise CheckpointMismatch(f"{path} was written for another model: its {', '.join(differ)} differ "
                                     f"(another {'; '.join(causes)}?)")


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
    memory: dict[str, Any] = {}
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
