"""Bodies of a scene file that are not meshed: strings, hair, cloths and lattices.

The data path of one such body: its table (``kind = "string"``, ``"hair"``, ``"cloth"`` or
``"lattice"``) -> its builder (:func:`volspring.structures.string`, :func:`~volspring.structures.hair`
on :func:`~volspring.structures.strand_points`, :func:`~volspring.structures.cloth_grid` or
:func:`~volspring.structures.cloth_mesh`, :func:`volspring.lattice.lattice_body`) -> a :class:`Part`:
the model alone, numbered as its builder numbers it, with what the scene adds to it (an initial shape and
velocity, the cloth's triangles, a render surface). :func:`volspring.scene_file.assemble_scene` joins the
parts after the tet bodies with :func:`volspring.structures.combine`, then adds each part's constraints
and forces on the joined model (:func:`part_extras`: the cloth's strain limit and self-contact).

A cloth's triangles go to the ParaView surface series (``ParaViewWriter(triangles=)``) and, with the tet
bodies' boundary and the lattices' anchored surfaces, to the Blender surface (:class:`JoinedSurface`).
Strings and hair have no surface: the spring series shows them.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from volspring.scene_file._assemble import _rotation, at
from volspring.scene_file._schema import SceneFileError

if TYPE_CHECKING:
    from volspring.model import Model

__all__ = ["JoinedSurface", "Part", "build_part", "part_extras"]


@dataclass(frozen=True, eq=False)
class Part:
    """A structure body of a scene, before it is joined to the others.

    Parameters
    ----------
    model : Model
        The body alone; node i is the builder's node i.
    origin : str
        What it is, for the summary (``string of 21 nodes, 1 m``).
    x : (n, 3) float
        Initial positions [m]: the rest positions, or a plucked string's.
    v : (n, 3) float
        Initial velocities [m/s].
    triangles : (f, 3) int or None
        A cloth's triangles, indexing the part's nodes.
    surface : object or None
        A render surface of the part's nodes (``deform(x)`` and ``faces``): the cloth's triangles, a
        lattice's anchored surface; None for strings and hair.
    """

    model: Model
    origin: str
    x: np.ndarray
    v: np.ndarray
    triangles: np.ndarray | None = None
    surface: object = None


def build_part(spec: dict, path: str, base: Path) -> Part:
    """The :class:`Part` of a resolved body table of kind string, hair, cloth or lattice.

    Parameters
    ----------
    spec : dict
        The body's table, resolved (:func:`volspring.scene_file.resolve_scene`).
    path : str
        Its key path (``bodies[1]``), for messages.
    base : Path
        The folder file names are relative to.

    Returns
    -------
    Part

    Raises
    ------
    SceneFileError
        A value the builder refuses, with its message after the key path.
    """
    builders = {"string": _string, "hair": _hair, "cloth": _cloth, "lattice": _lattice}
    with at(path):
        part = builders[spec["kind"]](spec, path, base)
    model = replace(part.model, body_names=(spec.get("name", ""),))
    v = np.broadcast_to(np.asarray(spec.get("velocity", (0.0, 0.0, 0.0))), part.x.shape).copy()
    return replace(part, model=model, v=v)


def _given(spec, *names) -> dict:
    """The keywords of ``names`` the table gives (the builder's defaults for the others)."""
    return {name: spec[name] for name in names if name in spec}


def _string(spec, path, base) -> Part:
    from volspring.structures import string

    model = string(spec["start"], spec.get("end"), count=spec["count"], **_given(
        spec, "length", "direction", "linear_density", "mass", "axial_stiffness", "stiffness", "tension",
        "rest_length", "damping"))
    x = np.array(model.rest_positions)
    if "pluck" in spec:
        # A triangle: 0 at both ends, the full pluck at the node nearest pluck_at.
        fraction = np.linspace(0.0, 1.0, model.node_count)
        apex = fraction[int(round(spec.get("pluck_at", 0.5) * (model.node_count - 1)))]
        if not 0 < apex < 1:
            raise SceneFileError(f"{path}.pluck_at = {spec['pluck_at']} falls on an end node of {model.node_count}; "
                                 "expected a node inside the string")
        weight = np.where(fraction <= apex, fraction / apex, (1.0 - fraction) / (1.0 - apex))
        x += weight[:, None] * np.asarray(spec["pluck"])
    length = float(np.linalg.norm(x[-1] - x[0]))
    return Part(model, f"string of {model.node_count} nodes, {length:g} m", x, x * 0.0)


def _hair(spec, path, base) -> Part:
    from volspring.structures import hair, strand_points

    points = strand_points(spec["start"], spec["direction"], spec["length"], spec["count"],
                           **_given(spec, "curl_radius", "curl_pitch"))
    model = hair(points, bending_stiffness=spec["bending_stiffness"], axial_stiffness=spec["axial_stiffness"],
                 root=spec["root"], **_given(spec, "linear_density", "mass", "torsional_stiffness", "damping"))
    curl = f", curl radius {spec['curl_radius']:g} m" if spec.get("curl_radius") else ""
    x = np.array(model.rest_positions)
    return Part(model, f"hair strand of {model.node_count} nodes, {spec['length']:g} m{curl}", x, x * 0.0)


def _cloth(spec, path, base) -> Part:
    from volspring.output import BoundarySurface
    from volspring.structures import cloth_grid, cloth_mesh, sheet_grid

    options = _given(spec, "areal_density", "mass", "membrane_stiffness", "stretch_stiffness", "bend_stiffness",
                     "damping")
    if "mesh" in spec:
        points, triangles, where = _triangle_file(spec, path, base)
        model = cloth_mesh(points, triangles, **options)
        origin = f"cloth of {where}: {model.node_count} nodes, {len(triangles)} triangles"
    else:
        shape = {"width": spec["width"], "height": spec["height"], "nx": spec["nx"], "ny": spec["ny"],
                 **_given(spec, "origin", "axes")}
        _, triangles = sheet_grid(**shape)
        model = cloth_grid(**shape, **options, **_given(spec, "shear_stiffness"))
        origin = (f"cloth {spec['width']:g} m x {spec['height']:g} m, {spec['nx']} x {spec['ny']} cells, "
                  f"{model.node_count} nodes")
    x = np.array(model.rest_positions)
    surface = BoundarySurface.from_triangles(triangles, model.node_count)
    return Part(model, origin, x, x * 0.0, np.asarray(triangles, dtype=np.int64), surface)


def _triangle_file(spec, path, base):
    """(points [m], triangles, file) of a cloth's triangle surface file, vertices in the file's order."""
    import trimesh

    from meshing.units import length_factor

    file = base / spec["mesh"]
    if not file.is_file():
        raise SceneFileError(f"{path}.mesh = {spec['mesh']!r}: no file at {file}")
    try:
        surface = trimesh.load(file, force="mesh", process=False)  # no merging: node i is the file's vertex i
    except Exception as error:  # trimesh raises a variety of errors for unreadable files
        raise SceneFileError(f"{path}.mesh = {spec['mesh']!r}: cannot read {file} as a triangle surface: "
                             f"{error}") from error
    if not isinstance(surface, trimesh.Trimesh) or len(surface.faces) == 0:
        raise SceneFileError(f"{path}.mesh = {spec['mesh']!r}: {file} holds no triangles")
    factor = length_factor(spec["units"], spec.get("scale"))
    return np.asarray(surface.vertices, dtype=np.float64) * factor, np.asarray(surface.faces), str(file)


def _lattice(spec, path, base) -> Part:
    from meshing.units import UNITS, length_factor
    from volspring.lattice import lattice_body
    from volspring.material import Material

    with at(f"{path}.material"):
        material = Material(**spec["material"])
    unit, factor = UNITS[spec["units"]], length_factor(spec["units"], spec.get("scale"))
    cell_size = spec["cell_size"] * unit
    if "mesh" in spec:
        from meshing import load_surface

        file = base / spec["mesh"]
        if not file.is_file():
            raise SceneFileError(f"{path}.mesh = {spec['mesh']!r}: no file at {file}")
        with at(f"{path}.mesh"):
            surface = load_surface(file, units=spec["units"], scale=spec.get("scale"))
        where = str(file)
    else:
        from meshing.shapes import Shape, parse_shape

        with at(f"{path}.shape"):
            shape = parse_shape(spec["shape"])
        shape = Shape(shape.name, tuple(dimension * factor for dimension in shape.dimensions))
        size = spec["surface_size"] * unit if "surface_size" in spec else 0.25 * cell_size
        surface = shape.surface(size=size)
        where = shape.spec()
    rotation = _rotation(spec.get("rotation"))
    if rotation is not None:
        surface.vertices = surface.vertices @ rotation.T
    surface.vertices = surface.vertices + np.asarray(spec.get("translation", (0.0, 0.0, 0.0)))
    body = lattice_body(surface, cell_size, material, **_given(spec, "shear", "bend", "angles", "samples",
                                                                "damping_ratio"))
    x = np.array(body.model.rest_positions)
    origin = (f"lattice of {where}: {body.lattice.cell_count} cells of {cell_size:g} m, {body.model.node_count} "
              f"nodes, nu_eff {body.effective_nu:g}")
    return Part(body.model, origin, x, x * 0.0, surface=body.anchor)


def part_extras(spec: dict, path: str, part: Part, model, body: int, offset: int):
    """``(constraints, forces)`` a part brings to the joined model: a cloth's strain limit and self-contact.

    Parameters
    ----------
    spec : dict
        The part's resolved body table.
    path : str
        Its key path.
    part : Part
    model : Model
        The joined model; the part's node i is its node ``offset + i``, its body id ``body``.
    body, offset : int

    Returns
    -------
    constraints, forces : list
    """
    constraints, forces = [], []
    if "strain_limit" in spec:
        from volspring.constraints import StrainLimit
        from volspring.structures import cloth_springs

        limit = spec["strain_limit"]
        mine = model.node_body[model.springs[:, 0]] == body
        with at(f"{path}.strain_limit"):
            constraints.append(StrainLimit(model, limit["tau"], compression=limit.get("compression"),
                                           iterations=limit.get("iterations", 20),
                                           tolerance=limit.get("tolerance", 0.0),
                                           springs=cloth_springs(model, "structural", "shear") & mine))
    if "self_contact" in spec:
        from volspring.collision import ClothSelfContactForce

        if part.triangles is None:  # the key table allows self_contact on cloths only, which have triangles
            raise SceneFileError(f"{path}.self_contact applies to a cloth (kind = \"cloth\"), which has triangles")
        with at(f"{path}.self_contact"):
            forces.append(ClothSelfContactForce(model, part.triangles + offset, **spec["self_contact"]))
    return constraints, forces


class JoinedSurface:
    """Several render surfaces over slices of one model's nodes, as one (``deform(x)`` and ``faces``).

    Parameters
    ----------
    parts : sequence of (surface, int, int)
        Each surface (``deform(x_part)`` and ``faces``) with the first and one past the last node of the
        model it is drawn from.
    node_count : int
        The model's nodes.
    """

    def __init__(self, parts, node_count):
        self.parts = tuple(parts)
        self.node_count = int(node_count)
        faces, shift = [], 0
        for surface, _, _ in self.parts:
            faces.append(np.asarray(surface.faces, dtype=np.int64) + shift)
            shift += len(surface.deform(np.zeros((_node_count(surface), 3))))
        self.faces = np.concatenate(faces)
        self.point_count = shift

    def deform(self, x) -> np.ndarray:
        """The surfaces' vertices at node positions ``x``.

        Parameters
        ----------
        x : (n, 3) float
            Positions of the model's nodes [m].

        Returns
        -------
        (p, 3) float
            Every surface's vertices, surface after surface [m].
        """
        x = np.asarray(x, dtype=np.float64)
        if x.shape != (self.node_count, 3):
            raise ValueError(f"x must have shape ({self.node_count}, 3), got {x.shape}")
        return np.concatenate([surface.deform(x[start:stop]) for surface, start, stop in self.parts])


def _node_count(surface) -> int:
    return int(surface.node_count)
