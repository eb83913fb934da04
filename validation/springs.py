"""The spring model's (or any rung's) answer on a validation case: statics, frequencies, effective elastic
constants.

Validation builds a volspring scene from a :class:`~validation.cases.Case` (:func:`case_scene`:
clamps become supports, including sliding ones and prescribed displacements; tractions and
gravity become forces) and asks volspring's own solvers: the static equilibrium
(:func:`spring_static`, :func:`volspring.statics.solve_static`: Newton on the nonlinear model)
and the vibration frequencies (:func:`spring_frequencies`, :func:`volspring.modes.solve_modes`).
Whatever element sets the model carries (springs, volume terms, smoothed strain: any rung of
:mod:`volspring.ladder`, built by :func:`rung_model`) are therefore validated here without a line
of validation code.

Stiffness rules: ``van_gelder`` and ``lloyd`` from the material (:mod:`volspring.model`), and
``uniform`` with one constant for every spring, the mean Van Gelder constant of the same mesh
(:func:`uniform_stiffness`): the raw-constant approach of peers, with the same overall stiffness
level on this mesh, for comparison. Its E scales with the mesh size (k / l), so it is not a
material model.

The Cauchy limit (:func:`effective_constants`): a cube on sliding supports, stretched to a
small axial strain; E_eff = axial stress / strain and nu_eff = - lateral strain / axial strain
of the network. Spring rules use E only, so nu_eff is the same whatever nu is asked.

The comparison with the FEM reference is :mod:`validation.compare`.

Examples
--------
>>> from volspring import Material
>>> from meshing import structured_box
>>> from validation.springs import effective_constants, spring_model
>>> cube = structured_box((3, 3, 3), (1.0, 1.0, 1.0))
>>> material = Material(E=1e6, nu=0.3, density=1000.0)
>>> network = effective_constants(cube, spring_model(cube, material, "van_gelder"))
>>> round(network["E_pa"] / material.E, 2), round(network["nu"], 2)   # not the 1 and 0.3 asked
(1.33, 0.15)
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from meshing.geometry import signed_tet_volumes, triangle_area_normals
from meshing.mesh import TetMesh
from validation.boundary import Box, Clamp
from validation.cases import Case, check_held
from volspring.forces import Gravity, PointLoads
from volspring.ladder import MODELS
from volspring.material import Material
from volspring.model import Model
from volspring.modes import solve_modes
from volspring.scene import Scene
from volspring.statics import solve_static
from volspring.supports import Pins, Prescribed
from typing import Any
from collections.abc import Sequence

__all__ = [
    "VALIDATED_MODELS",
    "SpringStatic",
    "case_scene",
    "case_supports",
    "deformed_volume_change",
    "effective_constants",
    "held_nodes",
    "rung_model",
    "rung_model_or_refusal",
    "spring_frequencies",
    "spring_model",
    "spring_static",
    "traction_forces",
    "uniform_stiffness",
]

#: Up to this many nodes the spring statics use sparse LU in the Newton steps, AMG + CG above.
DIRECT_STATIC_NODES = 5000
#: Target relative force residual of the nonlinear spring solve: far below the percent-level
#: differences measured, and above the round-off floor (about 1e-9 on a 20 x 2 x 2 beam: the
#: residual is a difference of spring forces 1e5 times the load).
STATIC_RTOL = 1e-7


def uniform_stiffness(mesh: TetMesh, material: Material) -> float:
    """The constant of the ``uniform`` rule: the mean Van Gelder spring constant on this mesh [N/m]."""
    return float(Model.from_mesh(mesh, material, rule="van_gelder").stiffness.mean())


def spring_model(mesh: TetMesh, material: Material, rule: str, **options: Any) -> Model:
    """The spring model of ``mesh`` by ``rule`` (``uniform``: :func:`uniform_stiffness`); options go to
    :meth:`Model.from_mesh` (e.g. ``damping_ratio``)."""
    if rule == "uniform":
        return Model.from_mesh(mesh, material, rule="uniform", stiffness=uniform_stiffness(mesh, material),
                                     **options)
    return Model.from_mesh(mesh, material, rule=rule, **options)


#: What validation measures: the ladder's rungs and the lattice body (on the box cases; refused elsewhere).
VALIDATED_MODELS = MODELS + ("lattice",)


def rung_model(mesh: TetMesh, material: Material, rung: str, **options: Any) -> Model:
    """The model of ``mesh`` on a rung of the ladder (:data:`volspring.ladder.MODELS`), by
    :meth:`Model.from_mesh` itself (the springs rung with volspring's default rule, van Gelder), or
    ``"lattice"``: the lattice body on the same nodes (:func:`volspring.lattice.box_lattice_model`), the
    seed's first volumetric approach beside the tet springs.

    Raises
    ------
    ValueError
        As :meth:`Model.from_mesh`: an unknown rung, or ``"springs+volume"`` below the network's own nu; for
        ``"lattice"``, a mesh that is not a structured box of cubic cells.
    """
    if rung == "lattice":
        from volspring.lattice import box_lattice_model

        return box_lattice_model(mesh, material, **options).model
    return Model.from_mesh(mesh, material, model=rung, **options)


def rung_model_or_refusal(mesh: TetMesh, material: Material, rung: str) -> Model | str:
    """:func:`rung_model`, or the one-line message of a documented refusal: ``"springs+volume"`` below the
    network's own nu, ``"lattice"`` off a structured box. Any other error is raised."""
    try:
        return rung_model(mesh, material, rung)
    except ValueError as refusal:
        if rung not in ("springs+volume", "lattice"):
            raise
        return " ".join(str(refusal).split())


def traction_forces(mesh: TetMesh, tractions: Sequence[Any]) -> np.ndarray:
    """(n, 3) float -- node forces [N] of uniform tractions: each loaded boundary face gives a third
    of its area times the traction to each of its nodes (the consistent P1 load).

    Raises
    ------
    ValueError
        For a traction whose region holds no boundary face.
    """
    forces = np.zeros((mesh.node_count, 3))
    faces = mesh.boundary_faces
    for traction in tractions:
        loaded = faces[np.asarray(traction.region(mesh.points), bool)[faces].all(axis=1)]
        if len(loaded) == 0:
            raise ValueError(f"traction region {traction.region!r} contains no boundary face of the mesh")
        area = 0.5 * np.linalg.norm(triangle_area_normals(mesh.points, loaded), axis=1)
        share = np.repeat(area / 3.0, 3)
        for c in range(3):
            forces[:, c] += np.bincount(loaded.ravel(), weights=share * traction.vector[c], minlength=mesh.node_count)
    return forces


def _clamp_masks(mesh: TetMesh, clamps) -> tuple:
    """(fixed (n, 3) bool, values (n, 3) float [m]) of a case's clamps on the mesh nodes."""
    fixed, values = np.zeros((mesh.node_count, 3), bool), np.zeros((mesh.node_count, 3))
    for clamp in clamps:
        inside = np.asarray(clamp.region(mesh.points), bool)
        if not inside.any():
            raise ValueError(f"clamp region {clamp.region!r} contains no mesh node")
        shift = clamp.displacement
        shift = np.asarray(shift(mesh.points[inside]) if callable(shift) else np.broadcast_to(shift, (inside.sum(), 3)),
                           dtype=float)
        for c in clamp.component_indices:
            fixed[inside, c] = True
            values[inside, c] = shift[:, c]
    return fixed, values


def held_nodes(case: Case) -> np.ndarray | None:
    """(n,) bool -- nodes held whole and in place by the case's clamps, or None if some clamp holds
    single components or prescribes a displacement (then only the linearised spring solve applies)."""
    held = np.zeros(case.mesh.node_count, bool)
    for clamp in case.clamps:
        if len(clamp.component_indices) != 3 or callable(clamp.displacement) or np.any(clamp.displacement):
            return None
        held |= np.asarray(clamp.region(case.mesh.points), bool)
    return held


def case_supports(mesh: TetMesh, clamps: Any) -> tuple:
    """The clamps of a case as volspring supports, one per distinct set of held components.

    Nodes held in all components at rest become :class:`~volspring.Pins`; the rest (sliding,
    symmetry planes, prescribed displacements) :class:`~volspring.supports.Prescribed` at their
    rest position plus the clamp's displacement. Where two clamps hold the same component of a
    node the later one's displacement counts, as in the FEM reference.
    """
    fixed, values = _clamp_masks(mesh, clamps)
    supports: list[Pins | Prescribed] = []
    for pattern in np.unique(fixed[fixed.any(axis=1)], axis=0):
        nodes = np.flatnonzero((fixed == pattern).all(axis=1))
        if pattern.all() and not values[nodes].any():
            supports.append(Pins(nodes))
        else:
            supports.append(Prescribed.at(nodes, np.flatnonzero(pattern), mesh.points[nodes] + values[nodes]))
    return tuple(supports)


def case_scene(case: Case, model: Model) -> Scene:
    """A volspring scene of the case: its clamps as supports, its tractions and gravity as forces."""
    forces: list[PointLoads | Gravity] = []
    if case.tractions:
        forces.append(PointLoads(traction_forces(case.mesh, case.tractions)))
    if case.gravity is not None:
        forces.append(Gravity(g=tuple(case.gravity)))
    return Scene(model, forces=forces, supports=case_supports(case.mesh, case.clamps))


@dataclass(frozen=True, eq=False)
class SpringStatic:
    """A spring-model equilibrium: displacement (n, 3) [m], how it was solved, iterations, seconds."""

    displacement: np.ndarray
    method: str
    iterations: int
    residual: float
    seconds: float


def spring_static(case: Case, model: Model, *, method: str = "auto") -> SpringStatic:
    """The model's static equilibrium under the case's clamps and loads, by volspring's own solve.

    Parameters
    ----------
    case : Case
    model : Model
        of ``case.mesh`` (any element sets)
    method : {"auto", "newton"}
        Newton on the nonlinear model (:func:`volspring.statics.solve_static`) with sparse LU up to
        ``DIRECT_STATIC_NODES`` nodes and AMG-CG above; the linearised solve of 0.1 is gone, as volspring's solve now
        holds sliding and prescribed supports

    Returns
    -------
    SpringStatic
    """
    if method not in ("auto", "newton"):
        raise ValueError(f"method = {method!r} is not 'auto' or 'newton' (the 'linear' spring solve was removed: "
                         "volspring's static solve takes sliding supports and prescribed displacements)")
    start = time.perf_counter()
    held = held_nodes(case)
    if held is not None:
        check_held(case.mesh, held)
    solver = "direct" if model.node_count <= DIRECT_STATIC_NODES else "amg"
    result = solve_static(case_scene(case, model), rtol=STATIC_RTOL, solver=solver, clamp_compression=False)
    return SpringStatic(result.x - model.rest_positions, "newton", result.iterations, result.residual,
                        time.perf_counter() - start)


def spring_frequencies(model: Model, held: np.ndarray, *, count: int = 4) -> tuple:
    """Lowest vibration frequencies of the model about its rest shape, held nodes fixed
    (:func:`volspring.modes.solve_modes`).

    Parameters
    ----------
    model : Model
    held : (n,) bool
        pinned nodes
    count : int

    Returns
    -------
    frequencies : (count,) float
        ascending [Hz]
    shapes : (count, n, 3) float
        mass-normalised mode shapes, zero on held nodes
    """
    modes = solve_modes(Scene(model, pins=Pins(np.asarray(held, bool))), count=count)
    return modes.frequencies, modes.shapes


def deformed_volume_change(mesh: TetMesh, displacement: np.ndarray) -> float:
    """Volume of the mesh with its nodes moved by ``displacement`` minus its rest volume [m^3]."""
    return float(signed_tet_volumes(mesh.points + displacement, mesh.tets).sum() - mesh.volume)


# ---------------------------------------------------------------------------- Cauchy limit
def effective_constants(mesh: TetMesh, model: Model, *, strain: float = 1e-3) -> dict:
    """Effective E and nu of a spring network filling a box, from a uniaxial stress test.

    The mesh's bounding box faces at the lowest x, y, z slide (one component held each); the face
    at the highest x is moved to axial ``strain``; the lateral faces are free. Solved by
    volspring's static solve at a small strain, so the answer is the network's small-strain
    elastic constants (to O(strain)).

    Parameters
    ----------
    mesh : TetMesh
        a box (its faces lie on its bounding box)
    model : Model
        of ``mesh``
    strain : float
        axial strain [-]

    Returns
    -------
    dict
        ``E_pa`` (reaction / (area strain)), ``nu`` (mean of the two lateral ratios), ``nu_y``, ``nu_z``,
        ``volume_strain_per_axial_strain`` (dV / (V strain); exact: 1 - 2 nu)
    """
    low, high = mesh.bounds
    size = high - low
    tolerance = 1e-6 * float(np.linalg.norm(size))
    planes = [Box.plane(axis, low[a], tolerance=tolerance) for a, axis in enumerate("xyz")]
    top = Box.plane("x", high[0], tolerance=tolerance)
    clamps = [Clamp(plane, components=axis) for plane, axis in zip(planes, "xyz")]
    clamps.append(Clamp(top, components="x", displacement=(strain * size[0], 0.0, 0.0)))
    scene = Scene(model, supports=case_supports(mesh, clamps))
    x = solve_static(scene, solver="direct", rtol=STATIC_RTOL, clamp_compression=False).x
    reaction = -model.forces(x)  # what the supports push with, balancing the network
    on_top = top(mesh.points)
    E = float(reaction[on_top, 0].sum() / (size[1] * size[2] * strain))
    u = x - model.rest_positions
    lateral = [float(u[Box.plane(axis, high[a], tolerance=tolerance)(mesh.points), a].mean() / size[a])
               for a, axis in ((1, "y"), (2, "z"))]
    nu_y, nu_z = (-value / strain for value in lateral)
    volume = deformed_volume_change(mesh, u) / mesh.volume / strain
    return {"E_pa": E, "nu": 0.5 * (nu_y + nu_z), "nu_y": nu_y, "nu_z": nu_z,
            "volume_strain_per_axial_strain": float(volume)}

