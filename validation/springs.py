"""The spring model's answer on a validation case: statics, frequencies, effective elastic constants.

For a :class:`~validation.cases.Case` and a stiffness rule:

- the static equilibrium (:func:`spring_static`), by :func:`volspring.statics.solve_static`
  (Newton on the nonlinear springs) when every clamp holds whole nodes in place, or else (sliding
  supports, prescribed displacements: :class:`volspring.Pins` holds whole nodes only) the
  linearised solve K u = f with the rest stiffness, exact in the small-strain limit the cases
  live in; tractions become node forces (:func:`traction_forces`);
- the vibration frequencies (:func:`spring_frequencies`), ``eigsh`` of the rest stiffness with the
  lumped masses, pinned dofs removed.

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
import scipy.sparse as sp

from validation.boundary import Box, Clamp
from validation.cases import Case, check_held
from volspring.assembly import stiffness_matrix
from volspring.material import Material
from volspring.mesh import TetMesh, signed_tet_volumes
from volspring.model import SpringModel
from volspring.scene import Gravity, Pins, Scene

__all__ = [
    "NodalLoad",
    "SpringStatic",
    "deformed_volume_change",
    "effective_constants",
    "held_nodes",
    "rest_stiffness_matrix",
    "spring_frequencies",
    "spring_model",
    "spring_static",
    "traction_forces",
    "uniform_stiffness",
]

#: Up to this many free dofs the spring eigenproblem is solved densely (all eigenvalues, exact).
DENSE_EIGEN_DOFS = 1500
#: Up to this many nodes the spring statics use sparse LU in the Newton steps, AMG + CG above.
DIRECT_STATIC_NODES = 5000
#: Target relative force residual of the nonlinear spring solve: far below the percent-level
#: differences measured, and above the round-off floor (about 1e-9 on a 20 x 2 x 2 beam: the
#: residual is a difference of spring forces 1e5 times the load).
STATIC_RTOL = 1e-7


def uniform_stiffness(mesh: TetMesh, material: Material) -> float:
    """The constant of the ``uniform`` rule: the mean Van Gelder spring constant on this mesh [N/m]."""
    return float(SpringModel.from_mesh(mesh, material, rule="van_gelder").stiffness.mean())


def spring_model(mesh: TetMesh, material: Material, rule: str, **options) -> SpringModel:
    """The spring model of ``mesh`` by ``rule`` (``uniform``: :func:`uniform_stiffness`); options go to
    :meth:`SpringModel.from_mesh` (e.g. ``damping_ratio``)."""
    if rule == "uniform":
        return SpringModel.from_mesh(mesh, material, rule="uniform", stiffness=uniform_stiffness(mesh, material),
                                     **options)
    return SpringModel.from_mesh(mesh, material, rule=rule, **options)


def rest_stiffness_matrix(model: SpringModel) -> sp.csr_matrix:
    """(3n, 3n) CSR -- K = -dF/dx of the springs at rest [N/m], dof 3 i + c.

    At rest the transverse term k (1 - l0/l) of each block is zero: K is the sum of k r r^T blocks.
    """
    return stiffness_matrix(model)


def traction_forces(mesh: TetMesh, tractions) -> np.ndarray:
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
        x = mesh.points[loaded]
        area = 0.5 * np.linalg.norm(np.cross(x[:, 1] - x[:, 0], x[:, 2] - x[:, 0]), axis=1)
        share = np.repeat(area / 3.0, 3)
        for c in range(3):
            forces[:, c] += np.bincount(loaded.ravel(), weights=share * traction.vector[c], minlength=mesh.node_count)
    return forces


@dataclass(frozen=True, eq=False)
class NodalLoad:
    """Constant node forces as a scene force (tractions, point loads), with their potential.

    Parameters
    ----------
    forces : (n, 3) float -- [N]
    """

    forces: np.ndarray

    def accumulate(self, x, v, t, out):
        out += self.forces

    def potential_energy(self, x, t) -> float:
        return float(-np.sum(self.forces * x))


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


def _loads(case: Case, model: SpringModel) -> np.ndarray:
    forces = traction_forces(case.mesh, case.tractions)
    if case.gravity is not None:
        forces += model.masses[:, None] * np.asarray(case.gravity, float)
    return forces


@dataclass(frozen=True, eq=False)
class SpringStatic:
    """A spring-model equilibrium: displacement (n, 3) [m], how it was solved, iterations, seconds."""

    displacement: np.ndarray
    method: str
    iterations: int
    residual: float
    seconds: float


def spring_static(case: Case, model: SpringModel, *, method: str = "auto") -> SpringStatic:
    """The spring model's static equilibrium under the case's clamps and loads.

    Parameters
    ----------
    case : Case
    model : SpringModel -- of ``case.mesh``
    method : {"auto", "newton", "linear"} -- ``newton``: :func:`volspring.statics.solve_static`;
        ``linear``: K u = f with the rest stiffness; ``auto``: newton when the clamps hold whole nodes

    Returns
    -------
    SpringStatic
    """
    start = time.perf_counter()
    held = held_nodes(case)
    if method == "auto":
        method = "linear" if held is None else "newton"
    if method == "newton":
        if held is None:
            raise ValueError(f"case {case.name!r} has sliding supports or prescribed displacements, which "
                             "volspring.Pins cannot hold; use method='linear'")
        from volspring.statics import solve_static

        check_held(case.mesh, held)
        forces = [NodalLoad(traction_forces(case.mesh, case.tractions))] if case.tractions else []
        if case.gravity is not None:
            forces.append(Gravity(model.masses, tuple(case.gravity)))
        scene = Scene(model, forces=forces, pins=Pins(np.flatnonzero(held)))
        solver = "direct" if model.node_count <= DIRECT_STATIC_NODES else "amg"
        result = solve_static(scene, rtol=STATIC_RTOL, solver=solver, clamp_compression=False)
        return SpringStatic(result.x - model.rest_positions, "newton", result.iterations, result.residual,
                            time.perf_counter() - start)
    if method != "linear":
        raise ValueError(f"method = {method!r} is not 'auto', 'newton' or 'linear'")
    fixed, values = _clamp_masks(case.mesh, case.clamps)
    K = rest_stiffness_matrix(model)
    free = ~fixed.ravel()
    rhs = _loads(case, model).ravel()[free] - K[free][:, ~free] @ values.ravel()[~free]
    u = values.ravel().copy()
    u[free] = _solve_spd(K[free][:, free], rhs)
    residual = float(np.linalg.norm(K[free][:, free] @ u[free] - rhs) / max(np.linalg.norm(rhs), 1e-300))
    return SpringStatic(u.reshape(-1, 3), "linear", 1, residual, time.perf_counter() - start)


def _solve_spd(K, rhs):
    from scipy.sparse.linalg import splu

    try:
        u = splu(K.tocsc()).solve(rhs)
    except RuntimeError as error:  # "Factor is exactly singular"
        raise ValueError(f"the spring stiffness matrix is singular ({error}): the supports leave a rigid "
                         "motion free") from None
    if not np.isfinite(u).all():
        raise ValueError("the spring stiffness matrix is singular: the supports leave a rigid motion free")
    return u


def spring_frequencies(model: SpringModel, held: np.ndarray, *, count: int = 4) -> tuple:
    """Lowest vibration frequencies of the spring model about its rest shape, held nodes fixed.

    Parameters
    ----------
    model : SpringModel
    held : (n,) bool -- pinned nodes
    count : int

    Returns
    -------
    frequencies : (count,) float -- ascending [Hz]
    shapes : (count, n, 3) float -- mass-normalised mode shapes, zero on held nodes
    """
    K = rest_stiffness_matrix(model)
    free = np.repeat(~held, 3)
    K = K[free][:, free]
    masses = np.repeat(model.masses, 3)[free]
    if K.shape[0] <= DENSE_EIGEN_DOFS:
        from scipy.linalg import eigh

        values, vectors = eigh(K.toarray(), np.diag(masses), subset_by_index=[0, count - 1])
    else:
        from scipy.sparse.linalg import eigsh

        start = np.random.default_rng(0).standard_normal(K.shape[0])  # seeded: ARPACK's own start is not
        values, vectors = eigsh(K.tocsc(), k=count, M=sp.diags(masses).tocsc(), sigma=0.0, which="LM", v0=start)
        order = np.argsort(values)
        values, vectors = values[order], vectors[:, order]
    shapes = np.zeros((count, 3 * model.node_count))
    shapes[:, free] = vectors.T
    return np.sqrt(np.clip(values, 0.0, None)) / (2 * np.pi), shapes.reshape(count, -1, 3)


def deformed_volume_change(mesh: TetMesh, displacement: np.ndarray) -> float:
    """Volume of the mesh with its nodes moved by ``displacement`` minus its rest volume [m^3]."""
    return float(signed_tet_volumes(mesh.points + displacement, mesh.tets).sum() - mesh.volume)


# ---------------------------------------------------------------------------- Cauchy limit
def effective_constants(mesh: TetMesh, model: SpringModel, *, strain: float = 1e-3) -> dict:
    """Effective E and nu of a spring network filling a box, from a uniaxial stress test.

    The mesh's bounding box faces at the lowest x, y, z slide (one component held each); the face
    at the highest x is moved to axial ``strain``; the lateral faces are free. Linearised (rest
    stiffness), so the answer is the network's small-strain elastic constants.

    Parameters
    ----------
    mesh : TetMesh -- a box (its faces lie on its bounding box)
    model : SpringModel -- of ``mesh``
    strain : float -- axial strain [-]

    Returns
    -------
    dict -- ``E_pa`` (reaction / (area strain)), ``nu`` (mean of the two lateral ratios), ``nu_y``,
    ``nu_z``, ``volume_strain_per_axial_strain`` (dV / (V strain); exact: 1 - 2 nu)
    """
    low, high = mesh.bounds
    size = high - low
    tolerance = 1e-6 * float(np.linalg.norm(size))
    planes = [Box.plane(axis, low[a], tolerance=tolerance) for a, axis in enumerate("xyz")]
    top = Box.plane("x", high[0], tolerance=tolerance)
    clamps = [Clamp(plane, components=axis) for plane, axis in zip(planes, "xyz")]
    clamps.append(Clamp(top, components="x", displacement=(strain * size[0], 0.0, 0.0)))
    fixed, values = _clamp_masks(mesh, clamps)
    K = rest_stiffness_matrix(model)
    free = ~fixed.ravel()
    u = values.ravel().copy()
    u[free] = _solve_spd(K[free][:, free], -(K[free][:, ~free] @ u[~free]))
    reaction = (K @ u).reshape(-1, 3)
    on_top = top(mesh.points)
    E = float(reaction[on_top, 0].sum() / (size[1] * size[2] * strain))
    u = u.reshape(-1, 3)
    lateral = [float(u[Box.plane(axis, high[a], tolerance=tolerance)(mesh.points), a].mean() / size[a])
               for a, axis in ((1, "y"), (2, "z"))]
    nu_y, nu_z = (-value / strain for value in lateral)
    volume = deformed_volume_change(mesh, u) / mesh.volume / strain
    return {"E_pa": E, "nu": 0.5 * (nu_y + nu_z), "nu_y": nu_y, "nu_z": nu_z,
            "volume_strain_per_axial_strain": float(volume)}

