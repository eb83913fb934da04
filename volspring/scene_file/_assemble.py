"""From a resolved scene (:func:`volspring.scene_file.read_scene`) to the objects a run steps.

The data path: ``bodies`` -> meshes (a file, or a built-in shape meshed by :func:`meshing.tetrahedralize`)
-> :class:`~volspring.bodies.Body` -> :meth:`Model.from_bodies <volspring.Model.from_bodies>`, then the
strings, hair, cloths and lattices (:mod:`volspring.scene_file._structures`) joined after them by
:func:`volspring.structures.combine`; then
``supports`` (regions as ``--pin`` takes them) -> :class:`~volspring.Pins`,
:class:`~volspring.supports.Sliding`, :class:`~volspring.supports.Prescribed`; ``fields``,
``obstacles``, ``contact`` and ``thin_contact`` -> forces and obstacles -> :class:`~volspring.Scene`; ``integrator`` ->
:func:`~volspring.integrators.make_integrator`. Nothing is re-implemented: a value the API refuses is
refused with the API's message, prefixed with its key path (:func:`at`).
"""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from volspring.scene_file._schema import SceneFileError, joined
import os
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from volspring.comparisons import StaticProblem
    from volspring.integrators.base import Integrator
    from volspring.model import Model
    from volspring.scene import Scene, State

__all__ = ["AssembledScene", "assemble_scene", "at"]


@dataclass(frozen=True, eq=False)
class AssembledScene:
    """What a run of a scene file steps.

    Attributes
    ----------
    bodies : tuple of Body
        The bodies, in the file's order (body i is ``bodies[i]``, ``model.node_body == i``).
    origins : tuple of str
        Where each body's mesh came from, for messages.
    model : Model
    scene : Scene
    state : State
        The initial state, with the bodies' initial velocities.
    integrator : Integrator
    triangles : (f, 3) int or None
        The cloths' triangles in the model's node numbers (for ``ParaViewWriter(triangles=)``), or None.
    render_surface : object or None
        For a scene with structures: the surface of every body that has one (tet boundaries, cloths, lattices'
        anchored surfaces) for ``BlenderWriter``; None for tet bodies alone (the model stands for its boundary).
    comparison : StaticProblem or None
        The static problem of the body ``[compare]`` names (:mod:`volspring.comparisons`), or None.
    """

    bodies: tuple
    origins: tuple
    model: Model
    scene: Scene
    state: State
    integrator: Integrator
    triangles: np.ndarray | None = None
    render_surface: object = None
    comparison: StaticProblem | None = None


@contextmanager
def at(path: str):
    """Re-raise a ValueError or TypeError of the API as a SceneFileError with the key path in front.

    A message that starts with the name of the key (``nu = 0.7 is not in (-1, 0.5)``) becomes
    ``bodies[1].material.nu = 0.7 is not in (-1, 0.5)``; any other gets ``path: `` in front.
    """
    try:
        yield
    except (ValueError, TypeError, FileNotFoundError) as error:
        if isinstance(error, SceneFileError):
            raise
        text = str(error)
        name = text.split(" ", 1)[0]
        if text.startswith(path):  # the API already named it (bodies[0].translation = ...)
            raise SceneFileError(text) from error
        if name.isidentifier() and text[len(name):].startswith(" = "):
            raise SceneFileError(f"{path}.{text}") from error
        raise SceneFileError(f"{path}: {text}") from error


def assemble_scene(scene: dict, *, base: str | os.PathLike[str] = ".") -> AssembledScene:
    """Build the model, scene, initial state and integrator of a resolved scene.

    Parameters
    ----------
    scene : dict
        A scene as :func:`volspring.scene_file.read_scene` returns it (checked, defaults filled in).
    base : path-like
        The folder mesh file names are relative to (the scene file's).

    Raises
    ------
    SceneFileError
        For a value the API refuses, a file that cannot be read, a region that selects no node; the
        message starts with the key path.
    """
    from volspring.bodies import Body, initial_velocities
    from volspring.material import Material
    from volspring.model import Model
    from volspring.scene import Scene

    specs = scene["bodies"]
    tets = [index for index, spec in enumerate(specs) if spec["kind"] == "tet"]
    if tets and tets[-1] >= len(tets):  # combine numbers the meshed nodes first: tet bodies come first
        first = next(index for index, spec in enumerate(specs) if spec["kind"] != "tet")
        raise SceneFileError(f"bodies[{tets[-1]}] is a tet body after bodies[{first}] (kind = "
                             f"\"{specs[first]['kind']}\"); expected the tet bodies first, then strings, hair, "
                             "cloths and lattices")
    # The checks that need no mesh first: a wrong material or field costs no meshing.
    materials = []
    for index in tets:
        with at(f"{joined('bodies', index)}.material"):
            materials.append(Material(**specs[index]["material"]))
    forces = [_field(spec, joined("fields", index)) for index, spec in enumerate(scene["fields"])]
    integrator = _integrator(scene["integrator"])

    bodies, origins = [], []
    for index, material in zip(tets, materials):  # a loop over bodies, not nodes
        spec, path = specs[index], joined("bodies", index)
        mesh, origin = _body_mesh(spec, path, Path(base))
        with at(path):
            bodies.append(Body(mesh, material, model=spec["model"], alpha=spec.get("alpha"),
                               rule=spec.get("rule") or "van_gelder", stiffness=spec.get("stiffness"),
                               damping_ratio=spec["damping_ratio"], translation=spec.get("translation", (0, 0, 0)),
                               rotation=_rotation(spec.get("rotation")), velocity=spec.get("velocity", (0, 0, 0)),
                               angular_velocity=spec.get("angular_velocity", (0, 0, 0)), name=spec.get("name", "")))
        origins.append(origin)
    tet_model = _model(Model, bodies) if bodies else None
    velocities = [] if tet_model is None else [initial_velocities(bodies, tet_model)]
    structures = None if len(tets) == len(specs) else _Structures(specs, len(tets), tet_model, Path(base))
    if structures is not None:
        model = structures.model
        origins += [part.origin for part in structures.parts]
    elif tet_model is not None:
        model = tet_model
    else:
        raise SceneFileError("bodies = [] holds no body; expected at least one [[bodies]] table")

    pins, supports = _supports(scene["supports"], model)
    obstacles = []
    for index, spec in enumerate(scene["obstacles"]):
        obstacle, force = _obstacle(spec, joined("obstacles", index), model)
        obstacles += [obstacle] if obstacle is not None else []
        forces += [force] if force is not None else []
    if "contact" in scene:
        from volspring.collision import ContactForce

        with at("contact"):
            forces.append(ContactForce(model, **scene["contact"]))
    if "thin_contact" in scene:
        from volspring.collision import ThinContactForce

        with at("thin_contact"):
            forces.append(ThinContactForce(model, **scene["thin_contact"]))
    constraints = []
    if structures is not None:
        extra_constraints, extra_forces = structures.extras(specs)
        constraints, forces = extra_constraints, forces + extra_forces
    with at("supports"):
        built = Scene(model, forces=forces, pins=pins, supports=supports, obstacles=obstacles,
                      constraints=constraints)
    comparison = None
    if "compare" in scene:
        from volspring.scene_file._compare import static_problem

        comparison = static_problem(scene, tuple(bodies), built)
    if structures is None:
        with at("bodies"):
            state = built.initial_state(v=velocities[0])
        return AssembledScene(tuple(bodies), tuple(origins), model, built, state, integrator,
                              comparison=comparison)
    x = np.concatenate([model.rest_positions[:structures.offsets[0]]] + [part.x for part in structures.parts])
    v = np.concatenate(velocities + [part.v for part in structures.parts])
    with at("bodies"):
        state = built.initial_state(x=x, v=v)
    return AssembledScene(tuple(bodies), tuple(origins), model, built, state, integrator, structures.triangles,
                          structures.render_surface, comparison)


class _Structures:
    """The strings, hair, cloths and lattices of a scene (``specs[first:]``), joined after the tet model."""

    def __init__(self, specs, first, tet_model, base):
        from volspring.scene_file._structures import build_part
        from volspring.structures import combine

        self.first = first
        self.parts = [build_part(spec, joined("bodies", index), base)
                      for index, spec in enumerate(specs) if index >= first]
        self.tet_model = tet_model
        with at("bodies"):
            self.model = combine(([tet_model] if tet_model is not None else []) + [part.model for part in self.parts])
        counts = [part.model.node_count for part in self.parts]
        self.offsets = np.cumsum([0 if tet_model is None else tet_model.node_count] + counts)

    def extras(self, specs):
        """``(constraints, forces)`` of the parts on the joined model (strain limits, self-contact)."""
        from volspring.scene_file._structures import part_extras

        constraints, forces = [], []
        for k, part in enumerate(self.parts):
            index = self.first + k
            more, pushes = part_extras(specs[index], joined("bodies", index), part, self.model, index,
                                       int(self.offsets[k]))
            constraints += more
            forces += pushes
        return constraints, forces

    @property
    def triangles(self):
        """(f, 3) int -- the cloths' triangles in the joined model's numbers, or None without a cloth."""
        found = [part.triangles + offset for part, offset in zip(self.parts, self.offsets)
                 if part.triangles is not None]
        return np.concatenate(found) if found else None

    @property
    def render_surface(self):
        """The bodies' render surfaces as one :class:`~volspring.scene_file._structures.JoinedSurface`, or None."""
        from volspring.output import BoundarySurface
        from volspring.scene_file._structures import JoinedSurface

        found: list[tuple[object, int, int]] = []  # (surface, first node, end node)
        if self.tet_model is not None:
            found.append((BoundarySurface.from_mesh(self.tet_model), 0, self.tet_model.node_count))
        found += [(part.surface, int(start), int(start) + part.model.node_count)
                  for part, start in zip(self.parts, self.offsets) if part.surface is not None]
        return JoinedSurface(found, self.model.node_count) if found else None


# ---------------------------------------------------------------------- bodies
def _body_mesh(spec, path, base):
    """(TetMesh or SpringTopology [m], origin) of a body's ``mesh`` file or ``shape``."""
    from meshing.units import UNITS, length_factor

    if "mesh" in spec:
        from meshing import TetMesh
        from meshing.topology_io import is_topology_path, read_topology

        file = base / spec["mesh"]
        if not file.is_file():
            raise SceneFileError(f"{path}.mesh = {spec['mesh']!r}: no file at {file}")
        read = read_topology if is_topology_path(file) else TetMesh.read
        with at(f"{path}.mesh"):
            return read(file, units=spec["units"], scale=spec.get("scale")), str(file)
    from meshing.shapes import Shape, parse_shape
    from meshing.tetrahedralize import tetrahedralize

    with at(f"{path}.shape"):
        shape = parse_shape(spec["shape"])
    factor = length_factor(spec["units"], spec.get("scale"))
    if factor != 1.0:
        shape = Shape(shape.name, tuple(dimension * factor for dimension in shape.dimensions))
    low, high = shape.bounds
    # The default size is volspring-sim's: a tenth of the extent, at most half the smallest side.
    size = (spec["size"] * UNITS[spec["units"]] if "size" in spec
            else min(shape.extent / 10.0, float((high - low).min()) / 2.0))
    try:
        mesh = tetrahedralize(shape, size=size, method=spec["mesher"], seed=spec.get("seed"))
    except ValueError as error:
        raise SceneFileError(f"{path}: {error}") from error
    except Exception as error:  # gmsh raises bare Exceptions
        raise SceneFileError(f"{path}: meshing {shape.spec()} at size {size:g} m with {spec['mesher']} failed: "
                             f"{error}") from error
    return mesh, f"{shape.spec()} meshed by {spec['mesher']} at size {size:g} m"


def _rotation(angles):
    """(3, 3) rotation matrix of angles [deg] about x, then y, then z (fixed axes), or None."""
    if angles is None:
        return None
    from scipy.spatial.transform import Rotation

    return Rotation.from_euler("xyz", angles, degrees=True).as_matrix()


def _model(model_class, bodies):
    """Model.from_bodies, naming the body whose options it refuses."""
    try:
        return model_class.from_bodies(bodies)
    except (ValueError, TypeError) as error:
        # Only on the error path: find the body by building each alone (the first refused one).
        culprits = [index for index, body in enumerate(bodies) if len(bodies) == 1 or _refused(model_class, body)]
        with at(joined("bodies", culprits[0]) if culprits else "bodies"):
            raise error


def _refused(model_class, body) -> bool:
    try:
        model_class.from_bodies([body])
    except (ValueError, TypeError):
        return True
    return False


# ---------------------------------------------------------------------- supports
@dataclass(frozen=True, eq=False)
class _Moving:
    """Positions ``start + velocity t`` (p, 3) [m] of supported nodes, picklable for checkpoints."""

    start: np.ndarray
    velocity_vector: np.ndarray

    def position(self, t) -> np.ndarray:
        return self.start + self.velocity_vector * t

    def velocity(self, t) -> np.ndarray:
        return np.broadcast_to(self.velocity_vector, self.start.shape).copy()


def _supports(specs, model):
    """``(pins, supports)``: pins at rest (all of them, one Pins, as ``--pin``) and the others."""
    from volspring.supports import Pins, Prescribed, Sliding

    held = np.zeros(model.node_count, dtype=bool)
    supports: list[Pins | Sliding | Prescribed] = []
    for index, spec in enumerate(specs):
        path = joined("supports", index)
        nodes = _support_nodes(spec, path, model)
        motion = {}
        if "displacement" in spec or "velocity" in spec:
            start = model.rest_positions[nodes] + np.asarray(spec.get("displacement", (0, 0, 0)))
            moving = _Moving(start, np.asarray(spec.get("velocity", (0, 0, 0)), dtype=np.float64))
            motion = {"motion": moving.position, "velocity": moving.velocity}
        with at(path):
            if spec["type"] == "pin" and not motion:
                held[nodes] = True
            elif spec["type"] == "pin":
                supports.append(Pins(nodes, **motion))
            elif spec["type"] == "sliding":
                supports.append(Sliding(nodes, spec["normal"]))
            else:
                supports.append(Prescribed(nodes, spec["components"], **motion))
    return (Pins(np.flatnonzero(held)) if held.any() else None), supports


def _support_nodes(spec, path, model) -> np.ndarray:
    """(p,) int -- the nodes in any of the support's regions, of its body or of all."""
    from meshing.units import UNITS
    from volspring.regions import describe_bounds, parse_region

    candidates = np.arange(model.node_count)
    if "body" in spec:
        if not 0 <= spec["body"] < model.body_count:
            raise SceneFileError(f"{path}.body = {spec['body']} is not a body index in [0, {model.body_count - 1}]")
        candidates = model.body_nodes(spec["body"])
    if "nodes" in spec:
        nodes = np.asarray(spec["nodes"], dtype=np.int64)
        if nodes.max() >= len(candidates):
            where = f"bodies[{spec['body']}]" if "body" in spec else "the scene"
            raise SceneFileError(f"{path}.nodes = {spec['nodes']}: node {int(nodes.max())} is not in {where} "
                                 f"({len(candidates)} nodes, 0 to {len(candidates) - 1})")
        return candidates[nodes]
    points = model.rest_positions[candidates]
    selected = np.zeros(len(candidates), dtype=bool)
    for text in spec["region"]:
        with at(f"{path}.region"):
            inside = parse_region(text, unit=UNITS[spec["units"]], label=f"{path}.region").nodes(points)
        if not inside.any():
            where = f"bodies[{spec['body']}]" if "body" in spec else "the scene"
            raise SceneFileError(f"{path}.region = {text!r} selects no node; {where} spans "
                                 f"{describe_bounds(points)} m")
        selected |= inside
    return candidates[selected]


# ---------------------------------------------------------------------- forces, obstacles, integrator
def _field(spec, path):
    from volspring import forces

    classes = {"gravity": forces.Gravity, "drag": forces.Drag, "wind": forces.Wind,
               "attractor": forces.PointAttractor, "repulser": forces.PointRepulser, "vortex": forces.Vortex}
    options = {name: value for name, value in spec.items() if name != "type"}
    with at(path):
        return classes[spec["type"]](**options)


def _obstacle(spec, path, model):
    """``(obstacle, force)``: a projected HalfSpace, or a penalty ObstacleContactForce on a plane or a shape."""
    from volspring import HalfSpace
    from volspring.collision import ObstacleContactForce

    penalty = {name: spec[name] for name in ("friction", "stiffness", "stiffness_factor", "damping_ratio", "thickness")
               if name in spec}
    with at(path):
        if spec["type"] == "shape":
            return None, ObstacleContactForce(model, [_shape_obstacle(spec, path)], **penalty)
        if spec["response"] == "projection":
            extra = sorted(set(penalty) - {"friction"})
            if extra:
                raise SceneFileError(f"{path}.{extra[0]} applies to response = \"penalty\", not \"projection\"")
            return HalfSpace(spec["point"], spec["normal"], restitution=spec.get("restitution", 0.0),
                             friction=spec.get("friction", 0.0)), None
        if "restitution" in spec:
            raise SceneFileError(f"{path}.restitution applies to response = \"projection\" (a penalty contact's "
                                 "bounce follows from its damping_ratio)")
        return None, ObstacleContactForce(model, [HalfSpace(spec["point"], spec["normal"])], **penalty)


def _shape_obstacle(spec, path):
    """A built-in shape's closed surface, placed, as a rigid StaticTriangleMesh."""
    from meshing.shapes import Shape, parse_shape
    from meshing.units import UNITS
    from volspring.collision import StaticTriangleMesh

    unit = UNITS[spec["units"]]
    with at(f"{path}.shape"):
        shape = parse_shape(spec["shape"])
    shape = Shape(shape.name, tuple(dimension * unit for dimension in shape.dimensions))
    size = spec["size"] * unit if "size" in spec else shape.extent / 20.0
    surface = shape.surface(size=size)
    return StaticTriangleMesh(np.asarray(surface.vertices) + np.asarray(spec.get("translation", (0.0, 0.0, 0.0))),
                              np.asarray(surface.faces))


def _integrator(spec):
    from volspring.integrators import make_integrator

    options = {name: spec[name] for name in ("solver", "rtol", "maxiter") if name in spec}
    if spec["newton_iterations"]:  # as volspring-sim: the explicit schemes take no options at all
        options["newton_iterations"] = spec["newton_iterations"]
    with at("integrator"):
        return make_integrator(spec["name"], **options)
