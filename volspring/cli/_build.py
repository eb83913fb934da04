"""From ``volspring-sim``'s parsed arguments to a scene: the tet mesh, the model, gravity, drag and pins.

The data path of the command: INPUT (a mesh file, a spring topology file with shells, or a built-in shape,
in ``--units``) -> :func:`load_mesh` -> :func:`build_model` (material, stiffness rule, damping) -> :func:`build_scene`
(gravity, drag, ``--pin`` regions read by :func:`volspring.regions.parse_region`). The model is on the rung of
``--model`` (:mod:`volspring.ladder`), with a material per region tag of the mesh file for ``--region-material``
(:func:`meshing.mesh_io.read_tet_regions`). Bad values raise
:class:`~volspring.cli._arguments.InputError` or ValueError, naming the option and the value.

A scene file INPUT (``*.toml``) takes the other road: :func:`read_scene_file` (the file, the flags given,
``--set``) -> :func:`volspring.scene_file.assemble_scene`; :func:`build_run` is where the two meet.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from volspring.cli._arguments import (BODY_FLAGS, DEFAULT_NU, RUN_FLAGS, SCENE_SUFFIX, InputError, given_options,
                                      region_materials)

if TYPE_CHECKING:
    from volspring.comparisons import StaticProblem
    from volspring.integrators.base import Integrator
    from volspring.model import Model
    from volspring.scene import Scene, State

__all__ = ["BuiltRun", "anchored_surface", "build_model", "build_run", "build_scene", "gravity_vector",
           "is_scene_file", "load_mesh", "pinned_nodes", "model_record", "read_scene_file", "scene_with_flags",
           "tet_regions"]


class BuiltRun(NamedTuple):
    """What a run steps, from the flags or from a scene file."""

    origin: str  # where the body (bodies) came from, for the summary
    model: Model
    record: dict  # the model's description, for the manifest
    summary_record: dict | None  # the same for the summary's model line (one body), or None
    scene: Scene
    integrator: Integrator
    state: State  # the initial state
    triangles: np.ndarray | None = None  # a scene's cloth triangles (model node numbers), for the surface series
    render_surface: object = None  # a scene's surface for Blender when it has structures; None: the model's boundary
    comparison: StaticProblem | None = None  # a scene's [compare] body (volspring.comparisons), or None


def build_run(args, note=None) -> BuiltRun:
    """Mesh, model, scene, integrator and initial state of the flags, or of ``args.scene`` (a resolved scene
    file); ``note(key, value)`` records the model (and the scene) in the run manifest."""
    from volspring.integrators import make_integrator

    note = note or (lambda key, value: None)
    if args.scene is None:
        body, origin = load_mesh(args)  # a TetMesh, or a SpringTopology with shells
        model = build_model(args, body)
        record = model_record(args, model)
        note("model", record)
        scene = build_scene(args, model)
        integrator = make_integrator(args.integrator, **({"newton_iterations": args.newton_iterations}
                                                         if args.newton_iterations else {}))
        return BuiltRun(origin, model, record, record, scene, integrator, scene.initial_state())
    from volspring.scene_file import assemble_scene

    note("scene", args.scene)
    built = assemble_scene(args.scene, base=Path(args.input).parent)
    for index in args.ignored_nu:  # after the materials are checked: no warning about a value then refused
        warnings.warn(f"bodies[{index}].material.nu = {args.scene['bodies'][index]['material']['nu']:g} is ignored "
                      "by model \"springs\": pure springs have one effective Poisson ratio whatever nu is asked (the "
                      "Cauchy limit); model \"smoothed\" honours nu (springs+volume too, for nu from about 0.25)",
                      UserWarning, stacklevel=2)
    records = [_body_record(spec) for spec in args.scene["bodies"]]
    element_sets = [_described(element_set) for element_set in built.model.elements]
    if len(records) == 1:
        record = {**records[0], "element_sets": element_sets}
        origin = built.origins[0]
        if "kind" in records[0]:  # a string, hair, cloth or lattice: the body line says what it is
            return BuiltRun(origin, built.model, record, None, built.scene, built.integrator, built.state,
                            built.triangles, built.render_surface, built.comparison)
    else:
        record = {"rung": built.model.rung, "bodies": records, "element_sets": element_sets}
        origin = f"{args.input}, {len(records)} bodies (" + "; ".join(
            f"{spec.get('name') or index}: {where}" for index, (spec, where) in
            enumerate(zip(args.scene["bodies"], built.origins))) + ")"
    note("model", record)
    return BuiltRun(origin, built.model, record, record if len(records) == 1 else None, built.scene,
                    built.integrator, built.state, built.triangles, built.render_surface, built.comparison)


def _body_record(spec) -> dict:
    """The model record of one body of a scene file, as :func:`model_record` gives it for the flags; for a
    string, hair, cloth or lattice its kind (the manifest's scene has its every value)."""
    from volspring.ladder import DEFAULT_ALPHA

    if spec["kind"] != "tet":
        return {"kind": spec["kind"], **({"material": spec["material"]} if "material" in spec else {})}
    record = {"rung": spec["model"], **spec["material"], "damping_ratio": spec["damping_ratio"]}
    if spec["model"] == "smoothed":
        record["alpha"] = spec.get("alpha", DEFAULT_ALPHA)
    else:
        record["rule"] = spec.get("rule") or "van_gelder"
        if "stiffness" in spec:
            record["stiffness"] = spec["stiffness"]
    return record


# ---------------------------------------------------------------------- a scene file
def is_scene_file(text) -> bool:
    """Whether INPUT names a scene file (``*.toml``, any case)."""
    return Path(str(text)).suffix.lower() == SCENE_SUFFIX


def read_scene_file(args, argv) -> dict:
    """The resolved scene of INPUT: the file, then the flags ``argv`` gives (:func:`scene_with_flags`),
    then ``--set``; the run's values (step, duration, folder...) are copied onto ``args``."""
    from volspring.scene_file import load_toml, parse_assignment, resolve_scene, set_value

    raw = load_toml(args.input)
    scene_with_flags(raw, args, given_options(argv))
    for text in args.set:
        set_value(raw, *parse_assignment(text))
    scene = resolve_scene(raw)
    _copy_run_values(args, scene)
    # A nu the file gives to a pure-spring body (its resolved nu is filled in either way), for build_run to say so.
    args.ignored_nu = [index for index, body in enumerate(raw["bodies"]) if "nu" in body.get("material", {})
                       and scene["bodies"][index].get("model") == "springs"]
    return scene


def scene_with_flags(raw, args, given) -> None:
    """Apply the flags ``given`` (destinations, :func:`~volspring.cli._arguments.given_options`) to the
    unresolved scene ``raw`` in place: body flags to its only body, run flags to their key paths
    (:data:`~volspring.cli._arguments.BODY_FLAGS`, :data:`~volspring.cli._arguments.RUN_FLAGS`),
    ``--gravity`` and ``--drag`` replace those fields, ``--pin`` replaces the supports."""
    from volspring.scene_file import set_value

    if "region_material" in given:
        raise InputError("--region-material does not apply to a scene file (its bodies have one material each)")
    body_flags = [dest for dest in BODY_FLAGS if dest in given]
    if body_flags:
        bodies = raw.get("bodies")
        count = len(bodies) if isinstance(bodies, list) else 0
        if count != 1:
            flag = "--" + body_flags[0].replace("_", "-")
            raise InputError(f"{flag} is ambiguous: {args.input} has {count} bodies; set one body's value with "
                             f"--set bodies[N].{BODY_FLAGS[body_flags[0]]}=VALUE (N from 0)")
        for dest in body_flags:
            set_value(raw, f"bodies[0].{BODY_FLAGS[dest]}", getattr(args, dest))
    for dest, key in RUN_FLAGS.items():
        if dest in given:
            value = getattr(args, dest)
            if dest == "render_surface":
                value = str(value.resolve())  # the scene's file names are relative to the scene file
            set_value(raw, key, str(value) if isinstance(value, Path) else value)
    fields = raw.get("fields", [])
    if isinstance(fields, list) and ("gravity" in given or "drag" in given):
        kept = [field for field in fields if not (isinstance(field, dict) and (
            ("gravity" in given and field.get("type") == "gravity") or ("drag" in given and field.get("type") == "drag")))]
        gravity = gravity_vector(args.gravity) if "gravity" in given else None
        raw["fields"] = ([{"type": "gravity", "g": gravity.tolist()}] if gravity is not None else []) + kept + (
            [{"type": "drag", "rate": args.drag}] if "drag" in given and args.drag else [])
    if "pin" in given:
        raw["supports"] = [{"type": "pin", "region": list(args.pin), "units": args.units}]


def _copy_run_values(args, scene) -> None:
    """The run's values of a resolved scene onto ``args``, where the run and the summary read them."""
    integrator, output = scene["integrator"], scene["output"]
    args.integrator, args.dt, args.guard = integrator["name"], integrator["dt"], integrator["guard"]
    args.newton_iterations, args.runaway_factor = integrator["newton_iterations"], integrator.get("runaway_factor")
    args.duration, args.frame_dt = scene["duration"], output["frame_dt"]
    args.out = None if output.get("folder") is None else Path(output["folder"])
    args.blender, args.checkpoint_every = output["blender"], output.get("checkpoint_every")
    args.render_surface = None
    if output.get("render_surface") is not None:
        if len(scene["bodies"]) != 1:
            raise InputError(f"output.render_surface is drawn in the units of its body; {args.input} has "
                             f"{len(scene['bodies'])} bodies (one body only)")
        args.render_surface = Path(args.input).parent / output["render_surface"]
        args.units, args.scale = scene["bodies"][0]["units"], scene["bodies"][0].get("scale")


def load_mesh(args):
    """The body [m] of INPUT and a description of where it came from.

    Returns
    -------
    body : TetMesh or SpringTopology
        A SpringTopology (the tet mesh with its shells) for a topology file (``*.npz``,
        :func:`meshing.topology_io.is_topology_path`), else the tet mesh.
    origin : str
    """
    from meshing.topology_io import is_topology_path

    path = Path(args.input)
    if path.is_file():
        if args.size is not None:
            raise InputError(f"--size applies to built-in shapes only; {path} is already a tet mesh")
        if is_topology_path(path):
            return _read_topology(path, args.units, args.scale), str(path)
        return _read_mesh(path, args.units, args.scale), str(path)
    from meshing.shapes import SHAPE_NAMES, Shape, looks_like_shape, parse_shape
    from meshing.units import UNITS, length_factor

    if not looks_like_shape(args.input):
        raise InputError(f"INPUT {args.input!r} is neither a mesh file nor a built-in shape NAME:D1,D2,... "
                         f"(shapes: {', '.join(SHAPE_NAMES)})")
    from meshing.tetrahedralize import tetrahedralize

    shape = parse_shape(args.input)
    factor = length_factor(args.units, args.scale)
    if factor != 1.0:
        shape = Shape(shape.name, tuple(dimension * factor for dimension in shape.dimensions))
    low, high = shape.bounds
    size = (args.size * UNITS[args.units] if args.size is not None
            else min(shape.extent / 10.0, float((high - low).min()) / 2.0))
    try:
        mesh = tetrahedralize(shape, size=size, method=args.mesher, seed=args.seed,
                              verbose=getattr(args, "verbose", False))
    except ValueError:
        raise
    except Exception as error:  # gmsh raises bare Exceptions
        raise InputError(f"meshing {shape.spec()} at --size {size:g} with {args.mesher} failed: {error}") from error
    return mesh, f"{shape.spec()} meshed by {args.mesher} at size {size:g} m"


def _read_mesh(path, units, scale):
    from meshing import TetMesh

    try:
        return TetMesh.read(path, units=units, scale=scale)
    except (ValueError, FileNotFoundError) as error:
        raise InputError(str(error)) from error


def _read_topology(path, units, scale):
    from meshing.topology_io import read_topology

    try:
        return read_topology(path, units=units, scale=scale)
    except (ValueError, FileNotFoundError) as error:
        raise InputError(str(error)) from error


def build_model(args, mesh):
    """The model of ``mesh`` (a TetMesh, or a SpringTopology whose shells the model keeps) on the rung of
    ``--model``, with the material, region materials, rule and damping of the arguments."""
    from volspring.material import Material
    from volspring.model import Model

    if args.model == "smoothed" and getattr(mesh, "shell_node_count", 0):
        raise InputError(f"--model smoothed takes a tet mesh without shells (shells are springs); {args.input} has "
                         f"{mesh.shell_node_count} shell nodes: give the tet mesh file, or use --model springs or "
                         "springs+volume")
    nu = DEFAULT_NU if args.nu is None else args.nu
    material = Material(E=args.E, nu=nu, density=args.density)
    regions, materials = tet_regions(args, mesh, material)
    asked_nu = args.nu is not None or any(given is not None for _, given, _ in
                                           region_materials(args.region_material).values())
    if args.model == "springs" and asked_nu:
        what = f"--nu {nu:g}" if args.nu is not None else "the nu of --region-material"
        warnings.warn(f"{what} is ignored by --model springs (--rule {args.rule or 'van_gelder'}): pure "
                      "springs have one effective Poisson ratio whatever nu is asked (the Cauchy limit; volspring-validate "
                      "cauchy measures it); --model smoothed honours nu (springs+volume too, for nu from about 0.25)",
                      UserWarning, stacklevel=2)
    try:
        return Model.from_mesh(mesh, material, model=args.model, rule=args.rule or "van_gelder",
                               stiffness=args.stiffness, damping_ratio=args.damping_ratio, alpha=args.alpha,
                               regions=regions, materials=materials)
    except ValueError as error:
        raise InputError(str(error)) from error


def model_record(args, model) -> dict:
    """What the run's model is, for the run manifest and the summary: rung, alpha, material, rule, damping, regions."""
    from volspring.ladder import DEFAULT_ALPHA

    record = {"rung": model.rung, "E": args.E, "nu": DEFAULT_NU if args.nu is None else args.nu,
              "density": args.density, "damping_ratio": args.damping_ratio}
    if model.rung == "smoothed":
        record["alpha"] = DEFAULT_ALPHA if args.alpha is None else args.alpha
    else:
        record["rule"] = args.rule or "van_gelder"
        if args.stiffness is not None:
            record["stiffness"] = args.stiffness
    if args.region_material:
        record["region_materials"] = {str(tag): {"E": E, "nu": nu, "density": density}
                                      for tag, (E, nu, density) in region_materials(args.region_material).items()}
    record["element_sets"] = [_described(element_set) for element_set in model.elements]
    return record


def _described(element_set) -> str:
    """``"61 springs"``, ``"24 corotated tets"``, ``"nodal strain on 20 smoothing domains"``."""
    from volspring.elements import CorotatedTets, NodalStrain, Springs

    if isinstance(element_set, Springs):
        return f"{element_set.spring_count} springs"
    if isinstance(element_set, CorotatedTets):
        return f"{element_set.element_count} corotated tets"
    if isinstance(element_set, NodalStrain):
        what = "nodal volume term" if not element_set.shear.any() else "nodal strain"
        return f"{what} on {element_set.domains.domain_count} smoothing domains"
    return f"{element_set.element_count} {type(element_set).__name__}"


def tet_regions(args, mesh, material):
    """``(regions, materials)`` for ``Model.from_mesh`` from ``--region-material``: the mesh file's region tag
    of every tet and a Material per tag given; ``(None, None)`` without the option."""
    from meshing.mesh_io import REGION_TAG_NAMES, read_tet_regions
    from meshing.topology_io import is_topology_path
    from volspring.material import Material

    given = region_materials(args.region_material)
    if not given:
        return None, None
    path = Path(args.input)
    if not path.is_file() or is_topology_path(path):
        what = "a spring topology file" if path.is_file() else "a built-in shape"
        raise InputError(f"--region-material needs a mesh file whose tets carry region tags; INPUT is {what}")
    try:
        regions = read_tet_regions(path)
    except (ValueError, FileNotFoundError) as error:
        raise InputError(str(error)) from error
    if regions is None:
        raise InputError(f"--region-material: {path} has no region tags on its tets (looked for the cell data "
                         f"{', '.join(REGION_TAG_NAMES)})")
    if len(regions) != mesh.tet_count:  # read_tet_regions follows TetMesh.read's tet order; a guard all the same
        raise InputError(f"{path} has {len(regions)} region tags for {mesh.tet_count} tets")
    present = np.unique(regions)
    missing = sorted(set(given) - set(present.tolist()))
    if missing:
        raise InputError(f"--region-material names tag(s) {', '.join(map(str, missing))}, but no tet of {path} has "
                         f"them (tags present: {', '.join(map(str, present.tolist()))})")
    materials = {}
    for tag, (E, nu, density) in given.items():
        try:
            materials[tag] = Material(E=E, nu=material.nu if nu is None else nu,
                                      density=material.density if density is None else density)
        except ValueError as error:
            raise InputError(f"--region-material {tag}: {error}") from error
    return regions, materials


def build_scene(args, model):
    """The scene of ``model``: gravity, drag and the pinned nodes of the arguments."""
    from meshing.units import UNITS
    from volspring import Drag, Gravity, Pins, Scene

    forces: list = []
    gravity = gravity_vector(args.gravity)
    if gravity is not None:
        forces.append(Gravity(g=tuple(gravity)))
    if args.drag:
        forces.append(Drag(rate=args.drag))
    pins = pinned_nodes(args.pin, model.rest_positions, UNITS[args.units])
    return Scene(model, forces=forces, pins=None if pins is None else Pins(pins))


def gravity_vector(text):
    """(3,) float [m/s^2] of ``--gravity gx,gy,gz``, or None for ``off`` (or a zero vector)."""
    if text.strip().lower() in ("off", "none", "0"):
        return None
    try:
        g = np.array([float(part) for part in text.split(",")])
    except ValueError:
        raise InputError(f"--gravity {text!r} is not 3 numbers gx,gy,gz") from None
    if len(g) != 3 or not np.isfinite(g).all():
        raise InputError(f"--gravity {text!r} is not 3 finite numbers gx,gy,gz")
    return None if not g.any() else g


def pinned_nodes(regions, points, unit=1.0):
    """(p,) int -- the nodes in any of the ``--pin`` regions, or None without one.

    Parameters
    ----------
    regions : list of str
        ``--pin`` values, in the grammar of :func:`volspring.regions.parse_region`.
    points : (n, 3) float
        Rest positions [m].
    unit : float
        Metres per unit of the numbers in ``regions`` (``--units``).

    Raises
    ------
    InputError
        For a region that selects no node, with the mesh's extent.
    ValueError
        For a region that does not parse.
    """
    from volspring.regions import describe_bounds, parse_region

    if not regions:
        return None
    selected = np.zeros(len(points), dtype=bool)
    for text in regions:
        inside = parse_region(text, unit=unit, label="--pin").nodes(points)
        if not inside.any():
            raise InputError(f"--pin {text} selects no node; the mesh spans {describe_bounds(points)} m")
        selected |= inside
    return np.flatnonzero(selected)


def anchored_surface(path, model, units, scale):
    """A render surface file bound to the model's tet mesh, vertices in the file's order."""
    import trimesh

    from meshing import anchor
    from meshing.units import length_factor

    if not path.is_file():
        raise InputError(f"no render surface file at {path}")
    try:
        # process=False: no merging or reordering, so the PC2 matches the file Blender imports.
        surface = trimesh.load(path, force="mesh", process=False)
    except Exception as error:  # trimesh raises a variety of errors for unreadable files
        raise InputError(f"cannot read {path} as a surface mesh: {error}") from error
    if not isinstance(surface, trimesh.Trimesh) or len(surface.vertices) == 0:
        raise InputError(f"{path} holds no surface vertices")
    surface.vertices = surface.vertices * length_factor(units, scale)  # drawn with INPUT, in its units
    return anchor(model.topology.mesh, surface)
