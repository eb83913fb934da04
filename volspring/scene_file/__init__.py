"""Scenes as files: a TOML file that names the bodies, supports, fields, obstacles, contact, integrator and outputs.

The data path: a ``.toml`` file -> :func:`load_toml` (a dict, as :mod:`tomllib` reads it) -> overrides by
key path (:func:`set_value`, ``volspring-sim --set bodies[1].material.E=2e6``) -> :func:`resolve_scene`
(every key checked against the tables of :mod:`volspring.scene_file._keys`, defaults filled in) ->
:func:`assemble_scene` (the bodies, model, scene, initial state and integrator, through the API:
:class:`~volspring.bodies.Body`, :meth:`Model.from_bodies <volspring.Model.from_bodies>`,
:mod:`volspring.forces`, :mod:`volspring.supports`, :mod:`volspring.collision`,
:func:`~volspring.integrators.make_integrator`). ``volspring-sim scene.toml`` runs one.

A scene names only what it needs::

    duration = 0.3                      # [s]

    [integrator]
    name = "implicit_euler"
    dt = 5e-3                           # [s]

    [[bodies]]
    name = "block"
    shape = "box:0.2,0.2,0.06"          # or mesh = "block.msh" (relative to this file)
    size = 0.035                        # tet edge length [m]
    translation = [0, 0, -0.03]         # [m]
    material = {E = 1e5, nu = 0.3, density = 1000}

    [[bodies]]
    name = "ball"
    shape = "sphere:0.05"
    translation = [0, 0, 0.06]
    velocity = [0, 0, -0.5]             # [m/s]

    [[supports]]
    type = "pin"                        # pin, sliding or prescribed
    region = "zmin"                     # as --pin takes it
    body = 0                            # bodies[0] only

    [[fields]]
    type = "gravity"                    # gravity, drag, wind, attractor, repulser, vortex

    [contact]                           # bodies collide (ContactForce)
    friction = 0.5

    [output]
    folder = "ball_frames"
    frame_dt = 0.02

A body is meshed (``kind = "tet"``, the default) or a structure, ``kind = "string"``, ``"hair"``, ``"cloth"`` or
``"lattice"``, whose keys are its builder's keywords (:func:`volspring.structures.string`,
:func:`~volspring.structures.hair` on :func:`~volspring.structures.strand_points`,
:func:`~volspring.structures.cloth_grid` or :func:`~volspring.structures.cloth_mesh`,
:func:`volspring.lattice.lattice_body`); supports may select nodes by number, as the builder numbers them::

    [[bodies]]
    kind = "cloth"
    width = 0.8                         # [m]
    height = 0.8
    nx = 16                             # node (i, j) is number j (nx + 1) + i
    ny = 16
    areal_density = 0.2                 # [kg/m^2]
    membrane_stiffness = 100.0          # E t [N/m]
    strain_limit = { tau = 0.1 }        # Provot's limit, a constraint after every step

    [[supports]]
    type = "pin"
    body = 0
    nodes = [0, 16]                     # two corners

Tet bodies come first; the structures are joined after them (:func:`volspring.structures.combine`), and
``[thin_contact]`` (:class:`~volspring.collision.ThinContactForce`) lets them touch the tet bodies. Obstacles are
planes or built-in shapes (``type = "shape"``, a rigid triangle mesh), with a contact ``thickness`` for thin bodies.

Key paths index arrays from 0: ``bodies[1]`` is the second body. Errors name the key path and what was
expected (``bodies[1].material.nu = 0.7 is not in (-1, 0.5)``); an unknown key is refused with the
closest known one suggested. Values are checked where they enter the API, so the messages are the
API's own with the key path in front.

Examples
--------
>>> from pathlib import Path
>>> from volspring.scene_file import assemble_scene, read_scene
>>> path = Path(__file__).parents[2] / "examples" / "scenes" / "beam.toml"
>>> scene = read_scene(path, overrides=["bodies[0].size=0.1", "integrator.dt=0.02"])
>>> scene["bodies"][0]["material"], scene["integrator"]["dt"]
({'E': 1000000.0, 'nu': 0.45, 'density': 1100.0}, 0.02)
>>> assembled = assemble_scene(scene, base=path.parent)
>>> assembled.model.body_count, len(assembled.scene.pins.nodes) > 0
(1, True)
>>> string = assemble_scene(read_scene(path.parent / "plucked_string.toml"), base=path.parent)
>>> string.model.node_count, string.scene.pins.nodes.tolist(), round(float(string.state.x[20, 2]), 6)
(41, [0, 40], 0.005)
>>> assemble_scene(read_scene(path, overrides=["bodies[0].material.nu=0.7"]), base=path.parent)
Traceback (most recent call last):
...
volspring.scene_file._schema.SceneFileError: bodies[0].material.nu = 0.7 is not in (-1, 0.5)
"""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

from volspring.scene_file._assemble import AssembledScene, assemble_scene
from volspring.scene_file._compare import compare_final_state, comparison_line, comparison_reference
from volspring.scene_file._keys import SCENE, resolved
from volspring.scene_file._schema import SceneFileError, joined, unknown_key
from typing import Any
from collections.abc import Sequence
import os

__all__ = ["AssembledScene", "SCENE", "SceneFileError", "assemble_scene", "compare_final_state", "comparison_line",
           "comparison_reference", "load_toml", "parse_assignment", "read_scene", "resolve_scene", "set_value",
           "split_key_path"]

_SEGMENT = re.compile(r"([A-Za-z_][A-Za-z0-9_-]*)((?:\[\d+\])*)")


def load_toml(path: str | os.PathLike[str]) -> dict:
    """The scene file at ``path`` as a dict, unchecked. Raises SceneFileError naming the file for bad TOML."""
    path = Path(path)
    if not path.is_file():
        raise SceneFileError(f"no scene file at {path}")
    try:
        with path.open("rb") as file:
            return tomllib.load(file)
    except tomllib.TOMLDecodeError as error:
        raise SceneFileError(f"{path} is not valid TOML: {error}") from None
    except UnicodeDecodeError as error:
        raise SceneFileError(f"{path} is not UTF-8 text: {error}") from None


def resolve_scene(scene: dict) -> dict:
    """``scene`` checked against :data:`SCENE`, every default filled in (a new dict, JSON-serialisable)."""
    return resolved(scene)


def read_scene(path: str | os.PathLike[str], *, overrides: Sequence[str] = ()) -> dict:
    """Load, override and resolve a scene file.

    Parameters
    ----------
    path : path-like
        A ``.toml`` scene file.
    overrides : sequence of str
        ``KEY.PATH=VALUE`` each (:func:`parse_assignment`), applied in order.

    Returns
    -------
    dict
        The resolved scene (:func:`resolve_scene`).
    """
    scene = load_toml(path)
    for text in overrides:
        set_value(scene, *parse_assignment(text))
    return resolve_scene(scene)


def split_key_path(text: str) -> list:
    """``"bodies[1].material.E"`` -> ``["bodies", 1, "material", "E"]``.

    >>> split_key_path("bodies[1].material.E")
    ['bodies', 1, 'material', 'E']
    """
    parts = []
    for segment in text.strip().split("."):
        match = _SEGMENT.fullmatch(segment)
        if match is None:
            raise SceneFileError(f"{text!r} is not a key path like bodies[1].material.E")
        parts.append(match.group(1))
        parts += [int(index) for index in re.findall(r"\[(\d+)\]", match.group(2))]
    return parts


def parse_assignment(text: str) -> tuple:
    """``"KEY.PATH=VALUE"`` -> ``(key path, value)``, VALUE read as a TOML value (``2e6``, ``true``,
    ``[0, 0, 1]``, ``"text"``), or as a string when it is not one (``box:1,0.1,0.1``).

    >>> parse_assignment("bodies[1].material.E=2e6")
    ('bodies[1].material.E', 2000000.0)
    >>> parse_assignment("bodies[0].shape=box:1,0.1,0.1")
    ('bodies[0].shape', 'box:1,0.1,0.1')
    """
    key, equals, value = text.partition("=")
    if not equals or not key.strip():
        raise SceneFileError(f"--set {text!r} is not KEY=VALUE (e.g. bodies[1].material.E=2e6)")
    split_key_path(key)  # refused now if malformed
    try:
        parsed = tomllib.loads(f"value = {value.strip()}")["value"]
    except tomllib.TOMLDecodeError:
        parsed = value.strip()
    return key.strip(), parsed


def set_value(scene: dict, key_path: str, value: Any) -> None:
    """Set the value at ``key_path`` in ``scene`` (in place), making the tables on the way.

    Raises
    ------
    SceneFileError
        For an array index past the array's end, or a path through a value that is not a table or array.
    """
    parts, where, node = split_key_path(key_path), "", scene
    for part, following in zip(parts, parts[1:] + [None]):
        last = following is None
        if isinstance(part, int):
            if not isinstance(node, list) or part >= len(node):
                count = len(node) if isinstance(node, list) else 0
                span = f": {where}[0] to {where}[{count - 1}]" if count else ""
                raise SceneFileError(f"{joined(where, part)} does not exist (len({where}) = {count}{span})")
        elif not isinstance(node, dict):
            raise SceneFileError(f"{joined(where, part)}: {where} is not a table")
        elif not last and part not in node:
            if where == "" and part not in SCENE.keys:
                raise unknown_key(where, part, SCENE.keys)
            node[part] = [] if isinstance(following, int) else {}
        if last:
            node[part] = value
        else:
            node = node[part]
            where = joined(where, part)
