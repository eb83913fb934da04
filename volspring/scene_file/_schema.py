"""How a scene file's tables are described and checked: :class:`Key` and :class:`Table`, and
:func:`check_table`, which checks a table as TOML reads it against its description and fills in the defaults.

The descriptions themselves, one table per section of a scene file, are in
:mod:`volspring.scene_file._keys`; errors are :class:`SceneFileError`, their message starting with the key
path (:func:`joined`) and naming what was expected, an unknown key with the closest known one
(:func:`unknown_key`).
"""

from __future__ import annotations

import difflib
import json
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

__all__ = ["KINDS", "Key", "SceneFileError", "Table", "check_table", "joined", "shown", "unknown_key"]


class SceneFileError(ValueError):
    """A scene file, or an override of one, that is not a valid scene; the message names the key path."""


@dataclass(frozen=True)
class Table:
    """The known keys of one table, and a check of the table as a whole.

    Parameters
    ----------
    keys : dict of str to Key
        The table's keys, in the order a resolved table lists them.
    check : callable, optional
        ``check(table) -> None or str``: the end of a message, after the table's path (``bodies[0] gives
        mesh and shape; ...``), for what no single key can check.
    """

    keys: dict
    check: Callable[[dict], str | None] | None = None


@dataclass(frozen=True)
class Key:
    """One key of a table.

    Parameters
    ----------
    kind : str
        One of :data:`KINDS`: what a TOML value of the key must be.
    default : object
        The value when the key is absent; None: absent (the API's own default applies).
    required : bool
        Whether a table must give the key.
    choices : tuple of str
        The strings allowed, if the API does not check them itself.
    check : callable, optional
        ``check(value) -> None or str``: the end of a message, after ``path = value``.
    table : Table, optional
        The keys of a "table", or of every item of "tables".
    types : dict of str to Table
        For "tables" whose items have a ``tag``: the keys of each value of the tag.
    tag : str
        The key naming an item's type in ``types``: ``type`` for supports, fields and obstacles, ``kind``
        for bodies.
    tag_default : str, optional
        The type of an item without the tag (bodies: ``"tet"``); None: the tag is required.
    maps : str
        Where the value goes in the API (documentation).
    """

    kind: str
    default: object = None
    required: bool = False
    choices: tuple = ()
    check: Callable[[Any], str | None] | None = None
    table: Table | None = None
    types: dict = field(default_factory=dict)
    tag: str = "type"
    tag_default: str | None = None
    maps: str = ""


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


#: kind -> (what a message says is expected, the test of a TOML value)
KINDS = {
    "number": ("a number", _is_number),
    "integer": ("an integer", lambda value: isinstance(value, int) and not isinstance(value, bool)),
    "string": ("a string", lambda value: isinstance(value, str)),
    "bool": ("true or false", lambda value: isinstance(value, bool)),
    "vector": ("3 numbers [x, y, z]", lambda value: isinstance(value, list) and len(value) == 3
               and all(map(_is_number, value))),
    "rows": ("an array of [a, b, c] number triples", lambda value: isinstance(value, list) and all(
        isinstance(row, list) and len(row) == 3 and all(map(_is_number, row)) for row in value)),
    "indices": ("an array of node numbers >= 0", lambda value: isinstance(value, list) and len(value) > 0 and all(
        isinstance(item, int) and not isinstance(item, bool) and item >= 0 for item in value)),
    "regions": ("a region string or an array of them", lambda value: isinstance(value, str) or (
        isinstance(value, list) and len(value) > 0 and all(isinstance(item, str) for item in value))),
    "table": ("a table", lambda value: isinstance(value, dict)),
    "tables": ("an array of tables", lambda value: isinstance(value, list)
               and all(isinstance(item, dict) for item in value)),
}


def shown(value) -> str:
    """A TOML value as a message shows it: ``0.7``, ``"box:1"``, ``true``, ``[0, 0, 1]``, ``{...}``."""
    if isinstance(value, dict):
        return "{...}"
    try:
        text = json.dumps(value)
    except (TypeError, ValueError):
        text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


def _toml_kind(value) -> str:
    for kind, name in ((bool, "a boolean"), (int, "an integer"), (float, "a float"), (str, "a string"),
                       (list, "an array"), (dict, "a table")):
        if isinstance(value, kind):
            return name
    return f"a {type(value).__name__}"


def joined(path: str, name) -> str:
    """``bodies[1]`` + ``material`` -> ``bodies[1].material``; an int gives an index, ``bodies[1]``."""
    if isinstance(name, int):
        return f"{path}[{name}]"
    return f"{path}.{name}" if path else name


def unknown_key(path: str, name: str, known) -> SceneFileError:
    """``bodies[0].materal is not a known key; did you mean material? (known: ...)``, or without a close key
    ``... is not a known key; expected one of: ...``."""
    close = difflib.get_close_matches(name, list(known), n=1)
    listed = ", ".join(known)
    if close:
        return SceneFileError(f"{joined(path, name)} is not a known key; did you mean {close[0]}? (known: {listed})")
    return SceneFileError(f"{joined(path, name)} is not a known key; expected one of: {listed}")


def check_table(table: dict, spec: Table, path: str) -> dict:
    """``table`` checked against ``spec`` (unknown keys refused, kinds and choices checked, defaults filled in),
    as a new dict; ``path`` is its key path, for messages ("" for a whole file)."""
    for name in table:
        if name not in spec.keys:
            raise unknown_key(path, name, spec.keys)
    out = {}
    for name, key in spec.keys.items():
        where = joined(path, name)
        if name in table:
            out[name] = _value(table[name], key, where)
        elif key.required:
            raise SceneFileError(f"{where} is missing; expected {KINDS[key.kind][0]} ({key.maps})")
        elif key.default is not None:
            out[name] = _value(key.default, key, where)  # a copy, filled in like a given value
    problem = spec.check(out) if spec.check else None
    if problem:
        raise SceneFileError(f"{path} {problem}")
    return out


def _value(value, key: Key, path: str):
    expected, test = KINDS[key.kind]
    if not test(value):
        raise SceneFileError(f"{path} = {shown(value)} is {_toml_kind(value)}; expected {expected}")
    if key.choices and value not in key.choices:
        raise SceneFileError(f"{path} = {shown(value)} is not one of {', '.join(key.choices)}")
    if key.kind == "table":
        return check_table(value, _described(key), path)
    if key.kind == "tables":
        return [_typed(item, key, joined(path, index)) for index, item in enumerate(value)]
    if key.kind == "number":
        value = float(value)
    elif key.kind in ("vector", "rows"):
        value = [float(item) for item in value] if key.kind == "vector" else [[float(c) for c in row] for row in value]
    elif key.kind == "regions":
        value = [value] if isinstance(value, str) else list(value)
    problem = key.check(value) if key.check else None
    if problem:
        raise SceneFileError(f"{path} = {shown(value)} {problem}")
    return value


def _typed(item: dict, key: Key, path: str) -> dict:
    if not key.types:
        return check_table(item, _described(key), path)
    kind = item.get(key.tag, key.tag_default)
    if not isinstance(kind, str) or kind not in key.types:
        got = "is missing" if kind is None else f"= {shown(kind)} is not a known {key.tag}"
        close = difflib.get_close_matches(kind, list(key.types), n=1) if isinstance(kind, str) else []
        hint = f"; did you mean {close[0]}?" if close else ""
        raise SceneFileError(f"{path}.{key.tag} {got}{hint} (known: {', '.join(key.types)})")
    rest = {name: value for name, value in item.items() if name != key.tag}
    return {key.tag: kind, **check_table(rest, key.types[kind], path)}


def _described(key: Key) -> Table:
    """The :class:`Table` of a "table" key, or of the items of a "tables" key without types."""
    if key.table is None:
        raise TypeError(f"a {key.kind!r} key needs its table= (the keys its table holds)")
    return key.table
