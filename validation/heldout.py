"""Held-out validation shapes: a torus, a capsule, an L-bracket and the Stanford bunny under their own weight.

The project's own cases are beams on structured grids (:mod:`validation.cases`); these four are shapes
the models were not tuned on, each on a coarse unstructured tet mesh stored in ``validation/data``
(how each was made: ``validation/data/README.md`` and :data:`MESH_RECIPES`), so that a case is the
same on every machine and every gmsh version. The meshes are coarse on purpose: linear P1
tetrahedra are still 20% or more off P2 on the same mesh (they lock in bending), so a model that only
matches P1 is visibly wrong there.

Every case is linear-range: E is chosen so that P2's largest displacement is 0.2-0.5% of the body's
largest extent, at nu = 0.3 and 0.49 alike. All in SI units, density 1000 kg/m^3, g = 9.81 m/s^2.

``torus_gravity``
    A torus around z (R = 0.3 m, tube r = 0.06 m) clamped on a short segment of its ring (the tube
    where |y| <= r on the side x < 0), gravity along -z: the ring bends out of its plane and twists.
``capsule_gravity``
    A capsule along z (r = 0.05 m, 0.5 m between the hemispheres' centres) held by its top cap
    (z >= 0.25 m), its axis horizontal: gravity along -x bends it as a cantilever. With
    ``hanging=True`` it hangs from that cap instead (gravity along -z, along its axis): a stretch
    that P1 gets within 1-9%, so that variant is not one where P1 is 20% off.
``l_bracket_gravity``
    An L-bracket (legs 0.4 m along x and 0.3 m along y, 0.05 x 0.05 m square sections, an L-shaped
    polygon extruded along z) hanging from the clamped end face of its y leg (y = 0.15 m), gravity
    along -y: the x leg sticks out sideways and bends, and bends the y leg with it.
``bunny_gravity``
    The coarse Stanford bunny of the test data (read in millimetres: 16 cm across; y is up) clamped
    on the band of nodes within 5% of its height from its base, gravity along -y: the ears bend.

Examples
--------
>>> from validation.heldout import torus_gravity
>>> case = torus_gravity(nu=0.49)
>>> case.name, case.mesh.node_count, case.material_tuple
('torus_gravity', 599, (250000000.0, 0.49, 1000.0))
"""

from __future__ import annotations

from pathlib import Path

from meshing import TetMesh
from validation._case import Case
from validation.boundary import Clamp
from volspring.material import Material
from volspring.regions import Box
from typing import Any

__all__ = [
    "DATA_FOLDER",
    "HELDOUT",
    "HELDOUT_CASE_NAMES",
    "MESH_FILES",
    "MESH_RECIPES",
    "build_heldout_case",
    "bunny_gravity",
    "capsule_gravity",
    "generate_mesh",
    "heldout_mesh",
    "l_bracket_gravity",
    "torus_gravity",
]

#: The folder of the stored meshes (package data of ``validation``).
DATA_FOLDER = Path(__file__).resolve().parent / "data"

#: Each stored mesh's file in :data:`DATA_FOLDER` and the length unit of its coordinates.
MESH_FILES = {
    "torus": ("heldout_torus.mesh", "m"),
    "capsule": ("heldout_capsule.mesh", "m"),
    "l_bracket": ("heldout_l_bracket.mesh", "m"),
    "bunny": ("coarse_bunny.mesh", "mm"),  # tests/data/coarse_bunny.mesh, unchanged: made by others
}

#: How the project's own meshes were made: ``tetrahedralize(parse_shape(shape), size=size_m, seed=seed)``
#: with gmsh (:func:`generate_mesh`); the version of gmsh that wrote the stored files.
MESH_RECIPES: dict[str, dict[str, Any]] = {
    "torus": {"shape": "torus:0.3,0.06", "size_m": 0.04, "seed": 1, "gmsh": "4.15.2"},
    "capsule": {"shape": "capsule:0.05,0.5", "size_m": 0.035, "seed": 1, "gmsh": "4.15.2"},
    "l_bracket": {"shape": "l_bracket:0.4,0.3,0.05,0.05", "size_m": 0.025, "seed": 1, "gmsh": "4.15.2"},
}

#: Material and load of each shape: E [Pa] chosen for a largest P2 displacement of 0.2-0.5% of the size.
HELDOUT = {
    "torus": {"E_pa": 2.5e8, "density_kg_per_m3": 1000.0, "gravity_m_per_s2": 9.81},
    "capsule": {"E_pa": 1e8, "density_kg_per_m3": 1000.0, "gravity_m_per_s2": 9.81},
    "l_bracket": {"E_pa": 3e8, "density_kg_per_m3": 1000.0, "gravity_m_per_s2": 9.81},
    "bunny": {"E_pa": 2e6, "density_kg_per_m3": 1000.0, "gravity_m_per_s2": 9.81},
}

#: The case names, as :data:`validation.cases.CASE_NAMES` lists them.
HELDOUT_CASE_NAMES = ("torus_gravity", "capsule_gravity", "l_bracket_gravity", "bunny_gravity")

#: Share of the bunny's height, from its lowest node, that its clamp band holds.
BUNNY_CLAMP_BAND = 0.05


def heldout_mesh(name: str) -> TetMesh:
    """The stored mesh of a held-out shape, in metres.

    Parameters
    ----------
    name : {"torus", "capsule", "l_bracket", "bunny"}

    Raises
    ------
    ValueError
        For an unknown name; FileNotFoundError when the package was installed without its data.
    """
    if name not in MESH_FILES:
        raise ValueError(f"unknown held-out mesh {name!r}; known: {', '.join(MESH_FILES)}")
    file_name, units = MESH_FILES[name]
    path = DATA_FOLDER / file_name
    if not path.is_file():
        raise FileNotFoundError(f"no mesh file at {path}: the validation package was installed without its "
                                "data folder (validation/data)")
    return TetMesh.read(path, units=units)


def generate_mesh(name: str) -> TetMesh:
    """Make a held-out shape's mesh anew from its recipe (:data:`MESH_RECIPES`), as the stored file was made.

    The same gmsh version on the same platform gives the stored mesh; another version may move nodes
    or change counts, which is why the cases read the stored files (:func:`heldout_mesh`).
    Writing the result with ``mesh.write(DATA_FOLDER / MESH_FILES[name][0])`` remakes the file.

    Parameters
    ----------
    name : {"torus", "capsule", "l_bracket"}
        the bunny was not made here and has no recipe
    """
    from meshing import parse_shape, tetrahedralize

    if name not in MESH_RECIPES:
        raise ValueError(f"no recipe for {name!r} (the bunny is a mesh made by others); recipes: "
                         f"{', '.join(MESH_RECIPES)}")
    recipe = MESH_RECIPES[name]
    return tetrahedralize(parse_shape(recipe["shape"]), size=recipe["size_m"], method="gmsh", seed=recipe["seed"])


def _material(name: str, nu: float) -> Material:
    values = HELDOUT[name]
    return Material(E=values["E_pa"], nu=nu, density=values["density_kg_per_m3"])


def _parameters(name: str, material: Material, **details) -> dict:
    parameters = {"mesh_file": MESH_FILES[name][0], "mesh_units": MESH_FILES[name][1],
                  **({"shape": MESH_RECIPES[name]["shape"], "mesh_size_m": MESH_RECIPES[name]["size_m"]}
                     if name in MESH_RECIPES else {}),
                  "E_pa": material.E, "nu": material.nu, "density_kg_per_m3": material.density,
                  "gravity_m_per_s2": HELDOUT[name]["gravity_m_per_s2"]}
    parameters.update(details)
    return parameters


def _gravity(name: str, axis: int) -> tuple:
    gravity = [0.0, 0.0, 0.0]
    gravity[axis] = -HELDOUT[name]["gravity_m_per_s2"]
    return tuple(gravity)


def torus_gravity(*, nu: float = 0.3) -> Case:
    """The torus (R = 0.3 m, r = 0.06 m) clamped on the tube segment |y| <= r, x <= 0; gravity along -z.

    Parameters
    ----------
    nu : float
        Poisson ratio (E, density: :data:`HELDOUT`)
    """
    mesh = heldout_mesh("torus")
    material = _material("torus", nu)
    tube = 0.06
    clamp = Box((None, -tube, None), (0.0, tube, None))
    return Case("torus_gravity", "Torus clamped on a short arc, under its own weight", "static", mesh, material,
                (Clamp(clamp),), gravity=_gravity("torus", 2),
                parameters=_parameters("torus", material, clamp="tube segment |y| <= 0.06 m on the side x <= 0",
                                       load="gravity along -z (out of the ring's plane)"))


def capsule_gravity(*, nu: float = 0.3, hanging: bool = False) -> Case:
    """The capsule (r = 0.05 m, 0.5 m between its hemispheres' centres, along z) held by its top cap.

    Parameters
    ----------
    nu : float
        Poisson ratio (E, density: :data:`HELDOUT`)
    hanging : bool
        False (default): gravity along -x, across the axis, a cantilever that bends; True: gravity along -z, the capsule
        hangs from its cap and stretches (P1 is within 1-9% of P2 there, so it is not a case where P1 is visibly wrong)
    """
    mesh = heldout_mesh("capsule")
    material = _material("capsule", nu)
    top = 0.25  # the centre of the top hemisphere: length / 2
    clamp = Box((None, None, top), (None, None, None))
    if hanging:
        title, gravity, load = ("Capsule hanging from its top cap", _gravity("capsule", 2),
                                "gravity along -z (along the axis: hanging)")
    else:
        title, gravity, load = ("Capsule held by one end cap, axis horizontal", _gravity("capsule", 0),
                                "gravity along -x (across the axis: bending)")
    return Case("capsule_gravity", title, "static", mesh, material, (Clamp(clamp),), gravity=gravity,
                parameters=_parameters("capsule", material, clamp="top cap z >= 0.25 m", load=load,
                                       hanging=bool(hanging)))


def l_bracket_gravity(*, nu: float = 0.3) -> Case:
    """The L-bracket hanging from the clamped end face y = 0.15 m of its y leg; gravity along -y.

    Parameters
    ----------
    nu : float
        Poisson ratio (E, density: :data:`HELDOUT`)
    """
    mesh = heldout_mesh("l_bracket")
    material = _material("l_bracket", nu)
    return Case("l_bracket_gravity", "L-bracket hanging from one leg's end, the other leg out", "static", mesh,
                material, (Clamp(Box.plane("y", 0.15)),), gravity=_gravity("l_bracket", 1),
                parameters=_parameters("l_bracket", material, clamp="end face y = 0.15 m of the y leg",
                                       load="gravity along -y (the x leg sticks out sideways and bends)"))


def bunny_gravity(*, nu: float = 0.3) -> Case:
    """The coarse Stanford bunny (made by others; y up) clamped on its base band; gravity along -y.

    The band: the nodes within :data:`BUNNY_CLAMP_BAND` of the bunny's height above its lowest node.

    Parameters
    ----------
    nu : float
        Poisson ratio (E, density: :data:`HELDOUT`)
    """
    mesh = heldout_mesh("bunny")
    material = _material("bunny", nu)
    low, high = mesh.points[:, 1].min(), mesh.points[:, 1].max()
    band = float(low + BUNNY_CLAMP_BAND * (high - low))
    return Case("bunny_gravity", "Stanford bunny clamped on its base, under its own weight", "static", mesh,
                material, (Clamp(Box((None, None, None), (None, band, None))),), gravity=_gravity("bunny", 1),
                parameters=_parameters("bunny", material, clamp=f"base band y <= {band:.6g} m "
                                       f"({BUNNY_CLAMP_BAND:g} of the height)",
                                       load="gravity along -y (y is the bunny's up)",
                                       source="Stanford Bunny, coarse tet mesh of "
                                              "dilevin/CSC417-a3-finite-elements-3d"))


_BUILDERS = {"torus_gravity": torus_gravity, "capsule_gravity": capsule_gravity,
             "l_bracket_gravity": l_bracket_gravity, "bunny_gravity": bunny_gravity}


def build_heldout_case(name: str, *, nu: float | None = None) -> Case:
    """A held-out case by name (one of :data:`HELDOUT_CASE_NAMES`), at ``nu`` (default 0.3)."""
    if name not in _BUILDERS:
        raise ValueError(f"unknown held-out case {name!r}; known: {', '.join(HELDOUT_CASE_NAMES)}")
    return _BUILDERS[name](nu=0.3 if nu is None else nu)
