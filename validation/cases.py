"""The validation cases: a mesh, a material, clamps and loads, and what theory says about them.

Each case is a :class:`Case`, plain data that both sides read: the FEM reference
(:mod:`validation.fem`) takes its clamps and loads as they are, the spring model turns full
clamps into :class:`volspring.Pins` and loads into node forces (:mod:`validation.compare`).

Built-in cases (names in :data:`CASE_NAMES`), all in SI units:

``cantilever_gravity``
    A 1 x 0.1 x 0.1 m beam along x, clamped at x = 0, under its own weight along -z.
    E = 3e8 Pa, nu = 0.3, density 1000 kg/m^3: beam theory gives a tip deflection of 4.9 mm,
    0.5% of the length, so linear elasticity is the right reference (geometric nonlinearity
    enters at the square of the rotations, about 1e-4 here).
``cantilever_end_load``
    The same beam without gravity, a shear traction on its end face x = L totalling 40 N along -z
    (5.3 mm at the tip). A traction, not a point force, so the reference converges.
``hanging_bar``
    A 0.1 x 0.1 x 1 m bar along z, clamped at its top z = 1, hanging under its own weight;
    E = 1e6 Pa so it stretches by 4.9 mm (0.5%). Theory: elongation rho g L^2 / (2E) and volume
    change (1 - 2 nu) A times it (uniaxial stress; the clamp holds the top's contraction, a 3D
    effect the FEM on the same mesh includes and the closed form does not).
``uniaxial_compression``
    A unit cube on three sliding symmetry planes (x = 0, y = 0, z = 0 hold one component each),
    its face x = 1 pushed to an axial strain of -1%: uniaxial stress, dV/V = (1 - 2 nu) eps,
    for several nu. The supports hold single components, which :class:`volspring.Pins` cannot,
    so the spring side of this case is the linearised solve (exact in the small-strain limit).
``cantilever_modes``
    The gravity cantilever's lowest vibration frequencies; Euler-Bernoulli gives 8.85 Hz for the
    first bending mode (a square section has a degenerate pair, y and z).
``torus_gravity``, ``capsule_gravity``, ``l_bracket_gravity``, ``bunny_gravity``
    Held-out shapes under their own weight on coarse stored meshes where P1 is 20% or more off P2
    (:mod:`validation.heldout`; ``build_case`` takes their ``nu``, default 0.3).
``own_mesh``
    Any :class:`meshing.TetMesh` with a clamp region and gravity and/or a traction
    (:func:`own_mesh_case`, used by ``volspring-validate --mesh FILE --clamp REGION``; its regions
    are written as text for :func:`parse_region`).

This module is the one public home of the case names; :class:`Case` and :class:`BeamGeometry` are
defined in ``validation/_case.py``, and :func:`own_mesh_case`, :func:`check_held` and
:func:`parse_region` in ``validation/_own_mesh.py``.

Examples
--------
>>> from validation.cases import cantilever_gravity
>>> case = cantilever_gravity(per_height=1)
>>> case.mesh.node_count, round(case.analytic["tip_deflection_m"], 5)
(44, 0.00496)
"""

from __future__ import annotations

import numpy as np

from meshing import structured_box
from validation import analytic
from validation._case import BeamGeometry, Case
from validation._own_mesh import check_held, own_mesh_case, parse_region
from validation.heldout import HELDOUT_CASE_NAMES, build_heldout_case
from validation.boundary import Clamp, Traction
from volspring.material import Material
from volspring.regions import Box
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from numpy.typing import ArrayLike

__all__ = [
    "BEAM",
    "beam_cells",
    "CASE_NAMES",
    "BeamGeometry",
    "Case",
    "beam_deflection_profile",
    "build_case",
    "cantilever_end_load",
    "cantilever_gravity",
    "cantilever_modes",
    "check_held",
    "hanging_bar",
    "own_mesh_case",
    "parse_region",
    "uniaxial_compression",
]

CASE_NAMES = ("cantilever_gravity", "cantilever_end_load", "hanging_bar", "uniaxial_compression",
              "cantilever_modes") + HELDOUT_CASE_NAMES + ("own_mesh",)

#: The beam of the cantilever cases: length, width, height [m], material and loads.
BEAM = {"length_m": 1.0, "width_m": 0.1, "height_m": 0.1, "E_pa": 3e8, "nu": 0.3, "density_kg_per_m3": 1000.0,
        "gravity_m_per_s2": 9.81, "end_force_n": 40.0}
#: The hanging bar: length along z, section, and a softer material so it stretches by 0.5%.
BAR = {"length_m": 1.0, "width_m": 0.1, "E_pa": 1e6, "nu": 0.3, "density_kg_per_m3": 1000.0,
       "gravity_m_per_s2": 9.81}
#: The compressed cube: edge, material (nu varies), axial strain.
CUBE = {"edge_m": 1.0, "E_pa": 1e6, "density_kg_per_m3": 1000.0, "strain": -0.01}


def _beam(per_height: int, **changes) -> tuple:
    cells = beam_cells(BEAM["length_m"], BEAM["height_m"], per_height, width=BEAM["width_m"])
    mesh = structured_box(cells, (BEAM["length_m"], BEAM["width_m"], BEAM["height_m"]))
    geometry = BeamGeometry(BEAM["length_m"], BEAM["width_m"], BEAM["height_m"])
    material = Material(E=BEAM["E_pa"], nu=changes.get("nu", BEAM["nu"]), density=BEAM["density_kg_per_m3"])
    tip = Box.plane("x", BEAM["length_m"])(mesh.points)
    return mesh, cells, geometry, material, tip


def _check_level(per_height):
    if int(per_height) != per_height or per_height < 1:
        raise ValueError(f"per_height = {per_height!r} cells across the beam is not an integer >= 1")


def cantilever_gravity(*, per_height: int = 2) -> Case:
    """The cantilever under its own weight (:data:`BEAM`), ``per_height`` cells across its height."""
    _check_level(per_height)
    mesh, cells, beam, material, tip = _beam(per_height)
    g = BEAM["gravity_m_per_s2"]
    delta = analytic.cantilever_self_weight_deflection(beam.length, beam.width, beam.height, E=material.E,
                                                       nu=material.nu, density=material.density, gravity=g)
    euler = analytic.cantilever_self_weight_deflection(beam.length, beam.width, beam.height, E=material.E,
                                                       nu=material.nu, density=material.density, gravity=g,
                                                       shear=False)
    return Case("cantilever_gravity", "Cantilever under its own weight", "static", mesh, material,
                (Clamp(Box.plane("x", 0.0)),), gravity=(0.0, 0.0, -g), tip_nodes=tip,
                tip_direction=np.array([0.0, 0.0, -1.0]),
                analytic={"tip_deflection_m": delta, "tip_deflection_euler_bernoulli_m": euler},
                parameters=dict(BEAM, per_height=per_height, load="gravity along -z"), beam=beam, cells=cells)


def cantilever_end_load(*, per_height: int = 2) -> Case:
    """The cantilever (:data:`BEAM`, no gravity) under a shear traction on its end face."""
    _check_level(per_height)
    mesh, cells, beam, material, tip = _beam(per_height)
    force = BEAM["end_force_n"]
    traction = Traction(Box.plane("x", beam.length), (0.0, 0.0, -force / (beam.width * beam.height)))
    delta = analytic.cantilever_end_load_deflection(beam.length, beam.width, beam.height, E=material.E,
                                                    nu=material.nu, force=force)
    return Case("cantilever_end_load", "Cantilever with an end load", "static", mesh, material,
                (Clamp(Box.plane("x", 0.0)),), tractions=(traction,), tip_nodes=tip,
                tip_direction=np.array([0.0, 0.0, -1.0]), analytic={"tip_deflection_m": delta},
                parameters=dict(BEAM, per_height=per_height, gravity_m_per_s2=0.0,
                                load="end-face shear traction along -z"),
                beam=beam, cells=cells)


def cantilever_modes(*, per_height: int = 2, count: int = 4) -> Case:
    """The gravity cantilever's lowest ``count`` vibration frequencies (clamped at x = 0)."""
    case = cantilever_gravity(per_height=per_height)
    beam = case.beam
    assert beam is not None  # cantilever_gravity's case has its beam
    frequencies = analytic.cantilever_frequencies(beam.length, beam.width, beam.height, E=case.material.E,
                                                  density=case.material.density, count=2)
    return Case("cantilever_modes", "Bending frequencies of the cantilever", "modes", case.mesh, case.material,
                case.clamps, analytic={"first_frequency_hz": float(frequencies[0]),
                                       "second_bending_frequency_hz": float(frequencies[1])},
                parameters=dict(BEAM, per_height=per_height, mode_count=count, gravity_m_per_s2=0.0,
                                load="none (free vibration)"),
                beam=beam, cells=case.cells)


def hanging_bar(*, per_width: int = 2) -> Case:
    """The bar of :data:`BAR` hanging from its top face under its own weight."""
    _check_level(per_width)
    length, width = BAR["length_m"], BAR["width_m"]
    cells = (per_width, per_width, max(1, round(length / (width / per_width))))
    mesh = structured_box(cells, (width, width, length))
    material = Material(E=BAR["E_pa"], nu=BAR["nu"], density=BAR["density_kg_per_m3"])
    g = BAR["gravity_m_per_s2"]
    elongation = analytic.hanging_bar_elongation(length, E=material.E, density=material.density, gravity=g)
    volume = analytic.hanging_bar_volume_change(length, width * width, E=material.E, nu=material.nu,
                                                density=material.density, gravity=g)
    return Case("hanging_bar", "Bar hanging under its own weight", "static", mesh, material,
                (Clamp(Box.plane("z", length)),), gravity=(0.0, 0.0, -g),
                tip_nodes=Box.plane("z", 0.0)(mesh.points), tip_direction=np.array([0.0, 0.0, -1.0]),
                analytic={"tip_deflection_m": elongation, "volume_change_m3": volume},
                parameters=dict(BAR, per_width=per_width, load="gravity along -z, clamped at the top"),
                cells=cells)


def uniaxial_compression(*, cells: int = 4, nu: float = 0.3, strain: float = CUBE["strain"]) -> Case:
    """A cube on sliding symmetry planes, its face x = edge moved to axial ``strain`` (< 0 compresses)."""
    _check_level(cells)
    edge = CUBE["edge_m"]
    mesh = structured_box((cells, cells, cells), (edge, edge, edge))
    material = Material(E=CUBE["E_pa"], nu=nu, density=CUBE["density_kg_per_m3"])
    clamps = (Clamp(Box.plane("x", 0.0), components="x"), Clamp(Box.plane("y", 0.0), components="y"),
              Clamp(Box.plane("z", 0.0), components="z"),
              Clamp(Box.plane("x", edge), components="x", displacement=(strain * edge, 0.0, 0.0)))
    return Case("uniaxial_compression", "Uniaxial compression: volume change", "static", mesh, material, clamps,
                tip_nodes=Box.plane("y", edge)(mesh.points), tip_direction=np.array([0.0, 1.0, 0.0]),
                analytic={"tip_deflection_m": analytic.uniaxial_lateral_strain(strain, nu) * edge,
                          "volume_change_m3": analytic.uniaxial_volume_strain(strain, nu) * edge**3},
                parameters={"edge_m": edge, "E_pa": material.E, "nu": nu,
                            "density_kg_per_m3": material.density, "strain": strain, "cells": cells,
                            "tip": "lateral displacement of the face y = edge"},
                cells=(cells, cells, cells))


def beam_deflection_profile(case: Case, x: ArrayLike) -> np.ndarray:
    """Timoshenko beam deflection w(x) [m] of a cantilever case along its axis (positive along the load).

    Self-weight q = rho g A: w = q (x^4 - 4 L x^3 + 6 L^2 x^2) / (24 E I) + q (L x - x^2 / 2) / (kappa G A);
    end force P: w = P (3 L x^2 - x^3) / (6 E I) + P x / (kappa G A).

    Parameters
    ----------
    case : Case
        ``cantilever_gravity`` or ``cantilever_end_load``
    x : (k,) float
        positions along the beam [m]

    Returns
    -------
    (k,) float
        [m]
    """
    beam, material = case.beam, case.material
    if beam is None:
        raise ValueError(f"case {case.name!r} is not a beam")
    x = np.asarray(x, dtype=float)
    L, A = beam.length, beam.width * beam.height
    EI = material.E * beam.width * beam.height**3 / 12.0
    kGA = analytic.SHEAR_COEFFICIENT_RECTANGLE * material.shear_modulus * A
    if case.name == "cantilever_end_load":
        P = BEAM["end_force_n"]
        return P * (3 * L * x**2 - x**3) / (6 * EI) + P * x / kGA
    q = material.density * BEAM["gravity_m_per_s2"] * A
    return q * (x**4 - 4 * L * x**3 + 6 * L**2 * x**2) / (24 * EI) + q * (L * x - x**2 / 2) / kGA


def build_case(name: str, *, quick: bool = False, nu: float | None = None) -> Case:
    """A built-in case by name at the default resolution (``quick``: the coarse one).

    Default: 2 cells across the beam (20 x 2 x 2 cells, 189 nodes), a 2 x 2 x 20 bar, a 4^3 cube.
    Quick: 1 cell across (10 x 1 x 1, 44 nodes), 1 x 1 x 10, 3^3. The held-out shapes have one stored
    mesh each (quick or not) and take ``nu`` (default 0.3), as the cube does.
    """
    level = 1 if quick else 2
    if name == "cantilever_gravity":
        return cantilever_gravity(per_height=level)
    if name == "cantilever_end_load":
        return cantilever_end_load(per_height=level)
    if name == "cantilever_modes":
        return cantilever_modes(per_height=level)
    if name == "hanging_bar":
        return hanging_bar(per_width=level)
    if name == "uniaxial_compression":
        return uniaxial_compression(cells=3 if quick else 4, nu=0.3 if nu is None else nu)
    if name in HELDOUT_CASE_NAMES:
        return build_heldout_case(name, nu=nu)
    if name == "own_mesh":
        raise ValueError("the own_mesh case needs a mesh: use own_mesh_case (volspring-validate --mesh FILE)")
    raise ValueError(f"unknown case {name!r}; known: {', '.join(CASE_NAMES)}")


def beam_cells(length: float, height: float, per_height: int, *, width: float | None = None) -> tuple:
    """Cells ``(nx, ny, nz)`` of a beam ``length x width x height`` with ``per_height`` cells across
    its height and cubic cells as near as the lengths allow.

    Parameters
    ----------
    length, height : float
        [m]
    per_height : int
        cells across the height (>= 1)
    width : float, optional
        [m]; default ``height``

    Returns
    -------
    (3,) tuple of int
    """
    width = height if width is None else width
    cell = height / per_height
    return (max(1, round(length / cell)), max(1, round(width / cell)), int(per_height))
