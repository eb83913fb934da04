"""The known keys of a scene file, one table per section, and the check of a scene against them.

Each table maps a key to a :class:`Key`: the kind of value it takes, its default, and where it goes in
the API (``maps``). Only the checks no volspring constructor makes are here (kinds, the few ranges of
the run itself, which key needs which); the values themselves are checked where they enter the API
(:class:`~volspring.Material`, the forces, :meth:`Model.from_bodies <volspring.Model.from_bodies>`,
:func:`~volspring.regions.parse_region`), and their messages are prefixed with the key path by
:func:`volspring.scene_file._assemble.at`.

:func:`resolved` checks a scene (a dict, as :mod:`tomllib` reads it) against :data:`SCENE` and returns it
with every default filled in: the scene a run records in its manifest.
"""

from __future__ import annotations

import difflib
import json
import math
from dataclasses import dataclass, field

from meshing.units import UNITS

__all__ = ["Key", "SCENE", "SceneFileError", "Table", "resolved"]


class SceneFileError(ValueError):
    """A scene file, or an override of one, that is not a valid scene; the message names the key path."""


@dataclass(frozen=True)
class Table:
    """The known keys of one table, and a check of the table as a whole.

    keys : dict of str to Key
    check : callable, optional -- ``check(table) -> None or str``: the end of a message, after the path
    """

    keys: dict
    check: object = None


@dataclass(frozen=True)
class Key:
    """One key of a table.

    kind : str -- one of :data:`KINDS`
    default : object -- the value when the key is absent; None: absent (the API's own default applies)
    required : bool
    choices : tuple of str -- the strings allowed, if the API does not check them itself
    check : callable, optional -- ``check(value) -> None or str``: the end of a message, after ``path = value``
    table : Table, optional -- the keys of a "table", or of every item of "tables"
    types : dict of str to Table, optional -- "tables" whose items have a ``type``: the keys of each type
    maps : str -- where the value goes in the API (documentation)
    """

    kind: str
    default: object = None
    required: bool = False
    choices: tuple = ()
    check: object = None
    table: Table | None = None
    types: dict = field(default_factory=dict)
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
    "regions": ("a region string or an array of them", lambda value: isinstance(value, str) or (
        isinstance(value, list) and len(value) > 0 and all(isinstance(item, str) for item in value))),
    "table": ("a table", lambda value: isinstance(value, dict)),
    "tables": ("an array of tables", lambda value: isinstance(value, list)
               and all(isinstance(item, dict) for item in value)),
}


# ---------------------------------------------------------------------- checks no constructor makes
def _positive(value):
    return None if math.isfinite(value) and value > 0 else "is not a finite number > 0"


def _at_least(low):
    def check(value):
        return None if math.isfinite(value) and value >= low else f"is not a finite number >= {low}"
    return check


def _positive_or_inf(value):  # the runaway check: inf turns it off, as --runaway-factor inf does
    return None if value > 0 else "is not > 0 (inf turns the energy check off)"


def _one_source(body):
    given = [name for name in ("mesh", "shape") if name in body]
    if len(given) != 1:
        return f"gives {' and '.join(given) or 'neither mesh nor shape'}; expected one of mesh (a file) or shape"
    if "size" in body and "mesh" in body:
        return "gives size with mesh; size is the tet edge length of a shape (a mesh file is already meshed)"
    return None


def _needs_folder(output):
    for name in ("blender", "checkpoint_every"):
        if output.get(name) and output.get("folder") is None:
            return f"gives {name} without folder (or --out DIR) to write it in"
    if output.get("render_surface") is not None and not output.get("blender"):
        return "gives render_surface without blender = true (it is the surface the Blender output carries)"
    return None


# ---------------------------------------------------------------------- the tables
# Defaults of a body and of the run are volspring-sim's own (its --help lists them): the same scene given
# as flags or as a file is the same run (tests/test_scene_file.py checks the defaults agree).
MATERIAL = Table({
    "E": Key("number", 1e6, maps="Material(E=) [Pa]; volspring-sim --E default, a soft rubber"),
    "nu": Key("number", 0.45, maps="Material(nu=) [-]; volspring-sim's DEFAULT_NU"),
    "density": Key("number", 1100.0, maps="Material(density=) [kg/m^3]; volspring-sim --density default"),
})

BODY = Table({
    "name": Key("string", maps="Body(name=)"),
    "mesh": Key("string", maps="a volume mesh or spring topology (.npz) file, relative to the scene file"),
    "shape": Key("string", maps="a built-in shape NAME:D1,D2,... (meshing.shapes.parse_shape), in units"),
    "size": Key("number", check=_positive, maps="tetrahedralize(size=) of a shape, in units; default as --size"),
    "mesher": Key("string", "gmsh", choices=("gmsh", "delaunay"), maps="tetrahedralize(method=)"),
    "seed": Key("integer", maps="tetrahedralize(seed=)"),
    "units": Key("string", "m", choices=tuple(UNITS), maps="length unit of mesh/shape and size"),
    "scale": Key("number", check=_positive, maps="a further factor on mesh/shape (default 1; absent, a mesh over "
                                                 "10 m read in metres gets a warning, as without --scale)"),
    "model": Key("string", "springs", maps="Body(model=): springs, springs+volume or smoothed"),
    "alpha": Key("number", maps="Body(alpha=), smoothed only"),
    "rule": Key("string", maps="Body(rule=): van_gelder (default), lloyd or uniform"),
    "stiffness": Key("number", maps="Body(stiffness=) [N/m] of rule uniform"),
    "damping_ratio": Key("number", 0.05, maps="Body(damping_ratio=); volspring-sim --damping-ratio default"),
    "material": Key("table", {}, table=MATERIAL, maps="Material(E=, nu=, density=)"),
    "translation": Key("vector", maps="Body(translation=) [m]"),
    "rotation": Key("vector", maps="Body(rotation=): angles [deg] about x, then y, then z (fixed axes)"),
    "velocity": Key("vector", maps="Body(velocity=) [m/s]"),
    "angular_velocity": Key("vector", maps="Body(angular_velocity=) [rad/s]"),
}, check=_one_source)

_WHERE = {  # where a support acts: the nodes of a region (as --pin takes it), of one body or of all
    "region": Key("regions", required=True, maps="parse_region(text) of each; their union"),
    "body": Key("integer", maps="only this body's nodes (bodies[body]); default all"),
    "units": Key("string", "m", choices=tuple(UNITS), maps="unit of the region's numbers"),
}
_MOTION = {
    "displacement": Key("vector", maps="the held nodes sit at rest + displacement [m]"),
    "velocity": Key("vector", maps="... + velocity * t [m/s]"),
}
SUPPORT_TYPES = {
    "pin": Table({**_WHERE, **_MOTION}),
    "sliding": Table({**_WHERE, "normal": Key("string", required=True, maps="Sliding(nodes, normal): x, y or z")}),
    "prescribed": Table({**_WHERE, "components": Key("string", required=True, maps="Prescribed(components=): "
                                                                                     "letters of xyz"), **_MOTION}),
}

_POINT_FIELD = Table({
    "centre": Key("vector", required=True, maps="centre= [m]"),
    "strength": Key("number", required=True, maps="strength= S"),
    "radius": Key("number", required=True, maps="radius= R [m]"),
    "falloff": Key("string", maps="falloff=: inverse_square or linear"),
    "clamp_jacobian": Key("bool", maps="clamp_jacobian="),
})
FIELD_TYPES = {  # one per force class of volspring.forces, its keys those of the class
    "gravity": Table({"g": Key("vector", maps="Gravity(g=) [m/s^2]; default (0, 0, -9.81)")}),
    "drag": Table({"rate": Key("number", required=True, maps="Drag(rate=) [1/s]")}),
    "wind": Table({
        "direction": Key("vector", required=True, maps="Wind(direction=)"),
        "speed": Key("number", maps="Wind(speed=) [m/s]"),
        "rate": Key("number", required=True, maps="Wind(rate=) [1/s]"),
        "gusts": Key("rows", maps="Wind(gusts=): [amplitude m/s, frequency Hz, phase rad] each"),
    }),
    "attractor": _POINT_FIELD,
    "repulser": _POINT_FIELD,
    "vortex": Table({
        "point": Key("vector", required=True, maps="Vortex(point=) [m]"),
        "axis": Key("vector", required=True, maps="Vortex(axis=)"),
        "strength": Key("number", required=True, maps="Vortex(strength=) [m/s^2]"),
        "radius": Key("number", required=True, maps="Vortex(radius=) [m]"),
    }),
}

_PENALTY = {  # ContactForce and ObstacleContactForce keywords; the classes check the values
    "friction": Key("number", maps="friction= mu"),
    "stiffness": Key("number", maps="stiffness= k_c [N/m]"),
    "stiffness_factor": Key("number", maps="stiffness_factor= alpha of k_c = alpha E_eff l"),
    "damping_ratio": Key("number", maps="damping_ratio="),
}
OBSTACLE_TYPES = {
    "plane": Table({
        "point": Key("vector", [0.0, 0.0, 0.0], maps="HalfSpace(point=) [m]"),
        "normal": Key("vector", [0.0, 0.0, 1.0], maps="HalfSpace(normal=), towards the free side"),
        "response": Key("string", "penalty", choices=("penalty", "projection"),
                        maps="ObstacleContactForce (penalty) or Scene(obstacles=) (projection)"),
        "restitution": Key("number", maps="HalfSpace(restitution=), projection only"),
        **_PENALTY,
    }),
}

CONTACT = Table({
    **_PENALTY,
    "damping": Key("number", maps="ContactForce(damping=) [N s/m]"),
    "friction_velocity": Key("number", maps="ContactForce(friction_velocity=) [m/s]"),
    "self_collision": Key("bool", maps="ContactForce(self_collision=)"),
    "edges": Key("bool", maps="ContactForce(edges=)"),
    "method": Key("string", maps="ContactForce(method=): consistent or closest_surface"),
})

INTEGRATOR = Table({
    "name": Key("string", "implicit_euler", maps="make_integrator(name); volspring-sim --integrator default"),
    "dt": Key("number", 1e-3, check=_positive, maps="the step [s]; volspring-sim --dt default"),
    "guard": Key("string", "warn", choices=("warn", "raise", "off"), maps="simulate(guard=)"),
    "runaway_factor": Key("number", check=_positive_or_inf, maps="simulate(runaway_factor=)"),
    "newton_iterations": Key("integer", 0, check=_at_least(0), maps="ImplicitEuler(newton_iterations=)"),
    "solver": Key("string", maps="ImplicitEuler(solver=): amg, jacobi or direct"),
    "rtol": Key("number", maps="ImplicitEuler(rtol=)"),
    "maxiter": Key("integer", maps="ImplicitEuler(maxiter=)"),
})

OUTPUT = Table({
    "folder": Key("string", maps="the run folder, relative to the working directory (as --out)"),
    "frame_dt": Key("number", 0.04, check=_positive, maps="simulate(frame_dt=) [s]; --frame-dt default"),
    "blender": Key("bool", False, maps="also the boundary surface as OBJ + PC2 (as --blender)"),
    "render_surface": Key("string", maps="with blender: this surface carried by the tets (one body, its units)"),
    "checkpoint_every": Key("integer", check=_at_least(1), maps="checkpoint.npz every N frames"),
}, check=_needs_folder)

SCENE = Table({
    "description": Key("string", maps="free text"),
    "duration": Key("number", 1.0, check=_at_least(0), maps="simulate(duration=) [s]; --duration default"),
    "bodies": Key("tables", required=True, table=BODY, maps="Model.from_bodies([Body(...), ...])"),
    "supports": Key("tables", [], types=SUPPORT_TYPES, maps="Scene(pins=, supports=)"),
    "fields": Key("tables", [], types=FIELD_TYPES, maps="Scene(forces=[...])"),
    "obstacles": Key("tables", [], types=OBSTACLE_TYPES, maps="ObstacleContactForce or Scene(obstacles=)"),
    "contact": Key("table", table=CONTACT, maps="ContactForce(model, ...) between (and within) bodies"),
    "integrator": Key("table", {}, table=INTEGRATOR),
    "output": Key("table", {}, table=OUTPUT),
})


# ---------------------------------------------------------------------- checking and filling in
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
    """``bodies[0].materal is not a known key; did you mean material? (known: ...)``."""
    close = difflib.get_close_matches(name, list(known), n=1)
    hint = f"did you mean {close[0]}? " if close else ""
    return SceneFileError(f"{joined(path, name)} is not a known key; {hint}(known: {', '.join(known)})")


def resolved(scene: dict) -> dict:
    """The scene checked against :data:`SCENE`, with every default filled in (a new dict).

    Raises
    ------
    SceneFileError
        An unknown key (the closest known one suggested), a value of the wrong kind or out of range,
        a required key missing; the message starts with the key path.
    """
    return _table(scene, SCENE, "")


def _table(table, spec: Table, path: str) -> dict:
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
        return _table(value, key.table, path)
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
        return _table(item, key.table, path)
    kind = item.get("type")
    if kind not in key.types:
        got = "is missing" if kind is None else f"= {shown(kind)} is not a known type"
        close = difflib.get_close_matches(str(kind), list(key.types), n=1) if isinstance(kind, str) else []
        hint = f"; did you mean {close[0]}?" if close else ""
        raise SceneFileError(f"{path}.type {got}{hint} (known: {', '.join(key.types)})")
    rest = {name: value for name, value in item.items() if name != "type"}
    return {"type": kind, **_table(rest, key.types[kind], path)}
