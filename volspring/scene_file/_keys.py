"""The known keys of a scene file, one table per section, and the check of a scene against them.

Each table maps a key to a :class:`~volspring.scene_file._schema.Key`: the kind of value it takes, its default,
and where it goes in the API (``maps``). Only the checks no volspring constructor makes are here (kinds, the few
ranges of the run itself, which key needs which); the values themselves are checked where they enter the API
(:class:`~volspring.Material`, the forces, :meth:`Model.from_bodies <volspring.Model.from_bodies>`,
:func:`~volspring.regions.parse_region`), and their messages are prefixed with the key path by
:func:`volspring.scene_file._assemble.at`.

:func:`resolved` checks a scene (a dict, as :mod:`tomllib` reads it) against :data:`SCENE` and returns it
with every default filled in: the scene a run records in its manifest.
"""

from __future__ import annotations

import math

from meshing.units import UNITS
from volspring.scene_file._schema import Key, Table, check_table

__all__ = ["BODY_KINDS", "SCENE", "resolved"]


# ---------------------------------------------------------------------- checks no constructor makes
def _positive(value):
    return None if math.isfinite(value) and value > 0 else "is not a finite number > 0"


def _at_least(low):
    def check(value):
        return None if math.isfinite(value) and value >= low else f"is not a finite number >= {low}"
    return check


def _positive_or_inf(value):  # the runaway check: inf turns it off, as --runaway-factor inf does
    return None if value > 0 else "is not > 0 (inf turns the energy check off)"


def _exactly_one(table, names, expected):
    """None when ``table`` gives exactly one of ``names``, else the end of a message saying what it gives."""
    given = [name for name in names if name in table]
    if len(given) == 1:
        return None
    return f"gives {' and '.join(given) or 'neither ' + ' nor '.join(names)}; expected {expected}"


def _one_source(body):
    refused = _exactly_one(body, ("mesh", "shape"), "one of mesh (a file) or shape")
    if refused is None and "size" in body and "mesh" in body:
        return "gives size with mesh; size is the tet edge length of a shape (a mesh file is already meshed)"
    return refused


def _one_surface(body):
    """A lattice body fills one closed surface: a mesh file or a built-in shape."""
    return _exactly_one(body, ("mesh", "shape"), "one of mesh (a closed surface file) or shape")


def _grid_or_mesh(cloth):
    """A cloth is a grid (width, height, nx, ny) or a triangle mesh file, not both."""
    grid = [name for name in ("width", "height", "nx", "ny") if name in cloth]
    if "mesh" in cloth:
        extra = grid + [name for name in ("origin", "axes", "shear_stiffness") if name in cloth]
        return f"gives mesh with {extra[0]}; {extra[0]} is a key of a grid cloth (no mesh)" if extra else None
    missing = [name for name in ("width", "height", "nx", "ny") if name not in cloth]
    if missing:
        return f"gives no {', '.join(missing)}; expected a grid (width, height, nx, ny) or mesh (a triangle file)"
    return None


def _one_selection(support):
    return _exactly_one(support, ("region", "nodes"), "one of region (by position) or nodes (by number)")


def _fraction(value):
    return None if 0 < value < 1 else "is not in (0, 1)"


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

# Structures (volspring.structures, volspring.lattice): keys named as their builders' keywords, which check the
# values (one of a pair of alternatives, > 0, ...); their messages come back with the key path in front.
_STRUCTURE = {
    "name": Key("string", maps="the body's name (Model.body_names)"),
    "velocity": Key("vector", maps="initial velocity of every node [m/s]"),
}
STRING = Table({
    **_STRUCTURE,
    "start": Key("vector", required=True, maps="string(start) [m]: node 0"),
    "end": Key("vector", maps="string(end=) [m]: the last node (or length along direction)"),
    "length": Key("number", maps="string(length=) [m], along direction"),
    "direction": Key("vector", maps="string(direction=); default down, (0, 0, -1)"),
    "count": Key("integer", required=True, maps="string(count=): nodes, >= 2"),
    "linear_density": Key("number", maps="string(linear_density=) [kg/m] (or mass)"),
    "mass": Key("number", maps="string(mass=) [kg]"),
    "axial_stiffness": Key("number", maps="string(axial_stiffness=) EA [N] (or stiffness)"),
    "stiffness": Key("number", maps="string(stiffness=) k of every segment [N/m]"),
    "tension": Key("number", maps="string(tension=) [N] as built (or rest_length)"),
    "rest_length": Key("number", maps="string(rest_length=) [m]"),
    "damping": Key("number", maps="string(damping=) k_d of every segment [N s/m]"),
    "pluck": Key("vector", maps="initial displacement [m] of the node nearest pluck_at, tapering linearly to 0 at "
                                "both ends (a triangle)"),
    "pluck_at": Key("number", check=_fraction, maps="where the pluck's apex is, as a fraction of the string; "
                                                    "default 0.5"),
})
HAIR = Table({
    **_STRUCTURE,
    "start": Key("vector", required=True, maps="strand_points(start) [m]: the root, node 0"),
    "direction": Key("vector", required=True, maps="strand_points(direction): the strand's (the helix axis)"),
    "length": Key("number", required=True, maps="strand_points(length) [m], arc length"),
    "count": Key("integer", required=True, maps="strand_points(count): nodes, >= 3"),
    "curl_radius": Key("number", maps="strand_points(curl_radius=) [m]; default 0, straight"),
    "curl_pitch": Key("number", maps="strand_points(curl_pitch=) [m] per turn, with curl_radius"),
    "bending_stiffness": Key("number", required=True, maps="hair(bending_stiffness=) EI [N m^2]"),
    "axial_stiffness": Key("number", required=True, maps="hair(axial_stiffness=) EA [N]"),
    "linear_density": Key("number", maps="hair(linear_density=) [kg/m] (or mass)"),
    "mass": Key("number", maps="hair(mass=) [kg]"),
    "torsional_stiffness": Key("number", maps="hair(torsional_stiffness=) GJ [N m^2]; default EI / 1.3"),
    "damping": Key("number", maps="hair(damping=) k_d of every segment [N s/m]"),
    "root": Key("string", "clamped", choices=("clamped", "free"),
                maps="hair(root=): clamped (pin nodes 0 and 1 with a support) or free"),
})
STRAIN_LIMIT = Table({
    "tau": Key("number", required=True, maps="cloth_strain_limit(tau): largest stretch (l - l0) / l0 [-]"),
    "iterations": Key("integer", maps="cloth_strain_limit(iterations=); default 20"),
    "tolerance": Key("number", maps="cloth_strain_limit(tolerance=) [-]"),
    "compression": Key("number", maps="cloth_strain_limit(compression=) [-]"),
})
SELF_CONTACT = Table({
    "thickness": Key("number", required=True, maps="ClothSelfContactForce(thickness=) [m]"),
    "stiffness": Key("number", required=True, maps="ClothSelfContactForce(stiffness=) k_c [N/m]"),
    "friction": Key("number", maps="ClothSelfContactForce(friction=) mu"),
    "damping_ratio": Key("number", maps="ClothSelfContactForce(damping_ratio=)"),
})
CLOTH = Table({
    **_STRUCTURE,
    "width": Key("number", maps="cloth_grid(width) [m]"),
    "height": Key("number", maps="cloth_grid(height) [m]"),
    "nx": Key("integer", maps="cloth_grid(nx): cells along the width"),
    "ny": Key("integer", maps="cloth_grid(ny): cells along the height"),
    "origin": Key("vector", maps="cloth_grid(origin=) [m]: corner node 0"),
    "axes": Key("rows", maps="cloth_grid(axes=): [[width direction], [height direction]]"),
    "mesh": Key("string", maps="cloth_mesh(points, triangles) of a triangle surface file, relative to the scene"),
    "units": Key("string", "m", choices=tuple(UNITS), maps="length unit of mesh"),
    "scale": Key("number", check=_positive, maps="a further factor on mesh"),
    "areal_density": Key("number", maps="areal_density= [kg/m^2] (or mass)"),
    "mass": Key("number", maps="mass= [kg]"),
    "membrane_stiffness": Key("number", maps="membrane_stiffness= E t [N/m] (or stretch_stiffness)"),
    "stretch_stiffness": Key("number", maps="stretch_stiffness= k of every structural spring [N/m]"),
    "shear_stiffness": Key("number", maps="cloth_grid(shear_stiffness=) [N/m], with stretch_stiffness"),
    "bend_stiffness": Key("number", maps="bend_stiffness= [N/m]"),
    "damping": Key("number", maps="damping= k_d of every spring [N s/m]"),
    "strain_limit": Key("table", table=STRAIN_LIMIT, maps="Scene(constraints=[cloth_strain_limit(...)])"),
    "self_contact": Key("table", table=SELF_CONTACT, maps="ClothSelfContactForce(model, triangles, ...)"),
}, check=_grid_or_mesh)
LATTICE = Table({
    **_STRUCTURE,
    "shape": Key("string", maps="lattice_body(Shape) of a built-in shape NAME:D1,D2,..., in units"),
    "mesh": Key("string", maps="lattice_body(surface) of a closed surface file, relative to the scene file"),
    "units": Key("string", "m", choices=tuple(UNITS), maps="length unit of mesh/shape, cell_size, surface_size"),
    "scale": Key("number", check=_positive, maps="a further factor on mesh/shape"),
    "cell_size": Key("number", required=True, check=_positive, maps="lattice_body(cell_size) in units"),
    "material": Key("table", {}, table=MATERIAL, maps="Material(E=, nu=, density=)"),
    "shear": Key("bool", maps="lattice_body(shear=); default true"),
    "bend": Key("bool", maps="lattice_body(bend=); default true"),
    "angles": Key("bool", maps="lattice_body(angles=); default false (nu_eff = 1/4)"),
    "samples": Key("integer", maps="lattice_body(samples=)"),
    "damping_ratio": Key("number", maps="lattice_body(damping_ratio=); default none"),
    "surface_size": Key("number", check=_positive, maps="lattice_body(surface_size=) of a shape, in units"),
    "translation": Key("vector", maps="x' = R x + translation [m], of the surface before it is filled"),
    "rotation": Key("vector", maps="R: angles [deg] about x, then y, then z (fixed axes)"),
}, check=_one_surface)
#: kind -> the keys of a body of that kind; "tet" (the default) is a meshed body (Body, Model.from_bodies).
BODY_KINDS = {"tet": BODY, "string": STRING, "hair": HAIR, "cloth": CLOTH, "lattice": LATTICE}

_WHERE = {  # where a support acts: the nodes of a region (as --pin takes it), of one body or of all
    "region": Key("regions", maps="parse_region(text) of each; their union (or nodes)"),
    "nodes": Key("indices", maps="node numbers: of bodies[body] as its builder numbers them (a string's from its "
                                 "start, a cloth grid's j (nx + 1) + i), or of the scene without body"),
    "body": Key("integer", maps="only this body's nodes (bodies[body]); default all"),
    "units": Key("string", "m", choices=tuple(UNITS), maps="unit of the region's numbers"),
}
_MOTION = {
    "displacement": Key("vector", maps="the held nodes sit at rest + displacement [m]"),
    "velocity": Key("vector", maps="... + velocity * t [m/s]"),
}
SUPPORT_TYPES = {
    "pin": Table({**_WHERE, **_MOTION}, check=_one_selection),
    "sliding": Table({**_WHERE, "normal": Key("string", required=True, maps="Sliding(nodes, normal): x, y or z")},
                     check=_one_selection),
    "prescribed": Table({**_WHERE, "components": Key("string", required=True, maps="Prescribed(components=): "
                                                                                     "letters of xyz"), **_MOTION},
                        check=_one_selection),
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
_THICKNESS = Key("number", maps="ObstacleContactForce(thickness=) [m]: contact layer of thin bodies (a cloth's "
                                "half-thickness, a string's radius); penalty only")
OBSTACLE_TYPES = {
    "plane": Table({
        "point": Key("vector", [0.0, 0.0, 0.0], maps="HalfSpace(point=) [m]"),
        "normal": Key("vector", [0.0, 0.0, 1.0], maps="HalfSpace(normal=), towards the free side"),
        "response": Key("string", "penalty", choices=("penalty", "projection"),
                        maps="ObstacleContactForce (penalty) or Scene(obstacles=) (projection)"),
        "restitution": Key("number", maps="HalfSpace(restitution=), projection only"),
        "thickness": _THICKNESS,
        **_PENALTY,
    }),
    "shape": Table({
        "shape": Key("string", required=True, maps="a built-in shape NAME:D1,D2,... as a rigid StaticTriangleMesh"),
        "size": Key("number", check=_positive, maps="Shape.surface(size=): edge length, in units; default a "
                                                    "twentieth of the extent"),
        "units": Key("string", "m", choices=tuple(UNITS), maps="length unit of shape and size"),
        "translation": Key("vector", maps="where the shape's centre is [m]"),
        "thickness": _THICKNESS,
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

THIN_CONTACT = Table({  # ThinContactForce keywords
    "thickness": Key("number", required=True, maps="ThinContactForce(thickness=) [m]"),
    **_PENALTY,
    "friction_velocity": Key("number", maps="ThinContactForce(friction_velocity=) [m/s]"),
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

COMPARE = Table({
    "case": Key("string", required=True, maps="a comparison of the entry-point group volspring.comparisons: "
                                             "static_fem (validation: the FEM static answer of the same body)"),
    "body": Key("integer", 0, maps="the tet body compared (bodies[body])"),
    "element": Key("string", choices=("TH", "P2", "P1"), maps="static_fem(element=): the FEM element; default TH "
                                                             "(P2 for nu <= 0)"),
    "cache": Key("bool", True, maps="static_fem(cache=): keep the reference in $VOLSPRING_CACHE "
                                    "(~/.cache/volspring/fem)"),
})

SCENE = Table({
    "description": Key("string", maps="free text"),
    "duration": Key("number", 1.0, check=_at_least(0), maps="simulate(duration=) [s]; --duration default"),
    "bodies": Key("tables", required=True, table=BODY, types=BODY_KINDS, tag="kind", tag_default="tet",
                  maps="Model.from_bodies([Body(...), ...]), then structures.combine with strings, hair, cloths "
                       "and lattices (tet bodies first)"),
    "supports": Key("tables", [], types=SUPPORT_TYPES, maps="Scene(pins=, supports=)"),
    "fields": Key("tables", [], types=FIELD_TYPES, maps="Scene(forces=[...])"),
    "obstacles": Key("tables", [], types=OBSTACLE_TYPES, maps="ObstacleContactForce or Scene(obstacles=)"),
    "contact": Key("table", table=CONTACT, maps="ContactForce(model, ...) between (and within) bodies"),
    "thin_contact": Key("table", table=THIN_CONTACT, maps="ThinContactForce(model, ...): strings, hair, cloths "
                                                         "and lattices against the tet bodies"),
    "integrator": Key("table", {}, table=INTEGRATOR),
    "output": Key("table", {}, table=OUTPUT),
    "compare": Key("table", table=COMPARE, maps="after the run, the body against a reference (volspring.comparisons)"),
})


def resolved(scene: dict) -> dict:
    """The scene checked against :data:`SCENE`, with every default filled in (a new dict).

    Raises
    ------
    SceneFileError
        An unknown key (the closest known one suggested), a value of the wrong kind or out of range,
        a required key missing; the message starts with the key path.
    """
    return check_table(scene, SCENE, "")
