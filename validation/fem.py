"""Linear-elastic finite-element reference (scikit-fem) on a :class:`meshing.TetMesh`.

The data path reads in one direction, one module per step::

    TetMesh, material, clamps, loads  ->  dof masks and loads on the TetMesh (numpy, validation.boundary)
        ->  MeshTet / Basis / asm (scikit-fem, validation.fem_assembly)
        ->  condensed solve (volspring.solvers: sparse LU, or AMG + CG, via validation.fem_solvers)
        ->  StaticSolution / ModalSolution (arrays on the mesh nodes, here)

P2 tetrahedra are the default reference: P1 tetrahedra lock in bending (a cantilever of
10 x 1 x 1 cells deflects to 0.22 of the converged value, REFERENCE.md section 2). P2 still locks
mildly as nu -> 1/2: on the held-out shapes it is 1-3% too stiff at nu = 0.45 and 2-5% at 0.499
against a converged answer (``benchmarks/study_locking.py``). ``element="TH"`` (Taylor-Hood: P2
displacement, continuous P1 pressure, the mixed u-p form of
:func:`validation.fem_assembly.mixed_matrices`) does not lock: on the same mesh it stays within
0.5-1.4% of converged at every nu (3.5% on the coarse bunny). It is solved by sparse LU only (the
system is indefinite); its modes condense the pressure out.
Points are ``(n, 3)`` everywhere here and become scikit-fem's ``(3, n)`` only in
:func:`validation.fem_assembly.skfem_space`.

Examples
--------
A unit cube (one cell, six tets) on three symmetry planes, pulled by 1 kPa on its face x = 1:
uniaxial stress, so the strain is 1e-3 along x and -nu * 1e-3 across, which P1 reproduces exactly.

>>> import numpy as np
>>> from meshing import TetMesh
>>> from validation.boundary import Box, Clamp, Traction
>>> from validation.fem import solve_fem_static
>>> corners = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], dtype=float)
>>> tets = [[0, 4, 6, 7], [0, 4, 5, 7], [0, 2, 6, 7], [0, 2, 3, 7], [0, 1, 5, 7], [0, 1, 3, 7]]
>>> cube = TetMesh.compact(corners, tets)
>>> symmetry = [Clamp(Box.plane(axis, 0.0), components=axis) for axis in "xyz"]
>>> pull = Traction(Box.plane("x", 1.0), (1e3, 0.0, 0.0))
>>> solution = solve_fem_static(cube, (1e6, 0.3, 1000.0), clamp=symmetry, traction=pull, element="P1")
>>> solution.displacement[7].round(9)   # the corner (1, 1, 1) [m]
array([ 0.001 , -0.0003, -0.0003])
>>> round(solution.volume_change, 9)    # (1 - 2 nu) eps V [m^3]
0.0004

Taylor-Hood keeps it exact when nearly incompressible (P1 and P2 do too here: a uniform strain
does not lock; bending does):

>>> solution = solve_fem_static(cube, (1e6, 0.499, 1000.0), clamp=symmetry, traction=pull, element="TH")
>>> solution.displacement[7].round(9)
array([ 0.001   , -0.000499, -0.000499])
"""

from __future__ import annotations

import dataclasses
import logging
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from skfem import Functional, asm
from skfem.helpers import div
from skfem.models.elasticity import lame_parameters

from meshing.geometry import rigid_body_modes, signed_tet_volumes
from validation.boundary import resolve_clamps, resolve_point_loads, resolve_tractions
from validation.fem_assembly import (ELEMENTS, check_element, fixed_vector, load_vector, mass_matrix, mixed_matrices,
                                     p1_prolongation, pressure_basis, skfem_space, fem_stiffness_matrix)
from validation.fem_solvers import AMG_TOLERANCE, ReferenceInfo, solve_linear, solve_saddle_point
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from meshing.mesh import TetMesh
    from validation.boundary import Traction

__all__ = [
    "CANCELLING_SHARE",
    "ModalSolution",
    "StaticSolution",
    "elastic_constants",
    "error_norms",
    "solve_fem_modes",
    "solve_fem_static",
    "volume_change_cancels",
]

logger = logging.getLogger(__name__)


# ---------------------------------------------------------------------------- inputs
def elastic_constants(material: Any) -> tuple[float, float, float]:
    """Young's modulus, Poisson ratio and density of a material, checked.

    Parameters
    ----------
    material : object with ``.E``, ``.nu``, ``.density``, or a mapping with those keys, or a tuple ``(E, nu, density)``
        E [Pa], nu [-], density [kg/m^3]

    Returns
    -------
    (E, nu, density) : tuple of float

    Raises
    ------
    ValueError
        Unless E > 0, -1 < nu < 0.5 and density > 0.
    """
    if isinstance(material, Mapping):
        values = (material["E"], material["nu"], material["density"])
    elif all(hasattr(material, name) for name in ("E", "nu", "density")):
        values = (material.E, material.nu, material.density)
    elif isinstance(material, Sequence) and len(material) == 3:
        values = tuple(material)
    else:
        raise TypeError(f"material must have E, nu and density (attributes, keys or a 3-tuple), got {material!r}")
    E, nu, density = (float(value) for value in values)
    if not E > 0:
        raise ValueError(f"E = {E:g} Pa is not > 0")
    if not nu < 0.5:
        raise ValueError(f"nu = {nu:g} is not < 0.5 (nu = 0.5 is incompressible: lambda is infinite)")
    if not nu > -1:
        raise ValueError(f"nu = {nu:g} is not > -1 (the shear modulus would not be positive)")
    if not density > 0:
        raise ValueError(f"density = {density:g} kg/m^3 is not > 0")
    return E, nu, density



# ---------------------------------------------------------------------------- static
@dataclass(frozen=True)
class StaticSolution:
    """A linear-elastic static equilibrium.

    Attributes
    ----------
    displacement : (n, 3) float
        displacement of each mesh node [m] (P2, TH: the vertex dofs)
    volume_change : float
        linearised volume change, the integral of div u over the mesh [m^3], exact for the finite-element field (it
        equals the flux of u through the boundary)
    deformed_volume_change : float
        volume of the mesh with its nodes moved by ``displacement`` minus its rest volume [m^3]; it differs from
        ``volume_change`` by O(|grad u|^2) terms, the growth of a rotated linear field among them (a geometrically
        exact model, which does not grow when it rotates, is to be compared with ``volume_change``), and for P2 and TH
        it ignores the edge dofs
    gross_volume_change : float
        the integral of |div u| [m^3] (by the element's quadrature, exact where div u keeps its sign within a tet):
        what the body's parts gain and lose before they cancel; ``volume_change`` is a cancellation where it is a
        small share of this (:func:`volume_change_cancels`)
    reaction_force : (3,) float
        total force the clamps exert on the body [N]; at equilibrium minus the total applied load
    dofs : (N,) float
        the whole finite-element displacement vector, in scikit-fem's dof order [m] (TH: its P2 displacement; the
        pressure is not kept)
    element : str
        ``"P1"``, ``"P2"`` or ``"TH"``
    info : ReferenceInfo
    """

    displacement: np.ndarray
    volume_change: float
    deformed_volume_change: float
    gross_volume_change: float
    reaction_force: np.ndarray
    dofs: np.ndarray
    element: str
    info: ReferenceInfo


def solve_fem_static(mesh: TetMesh, material: Any, *, clamp: Any, gravity: np.ndarray | None = None,
                     traction: Traction | list[Traction] | None = None, point_loads: np.ndarray | str | None = None,
                     body_force: Callable[[np.ndarray], np.ndarray] | None = None, element: str = "P2",
                     solver: str = "auto", tolerance: float = AMG_TOLERANCE) -> StaticSolution:
    """Linear-elastic static displacement of a clamped tet mesh under loads.

    Parameters
    ----------
    mesh : TetMesh
        rest shape; points [m]
    material : (E, nu, density)
        see :func:`elastic_constants`; E [Pa], density [kg/m^3]
    clamp : region, Clamp or list of Clamp
        a region (callable on (k, 3) points -> (k,) bool, :class:`~validation.boundary.Box`, or (2, 3) box corners)
        fixes all components of its nodes to zero; use :class:`~validation.boundary.Clamp` for single components
        (symmetry planes) or prescribed displacements
    gravity : (3,) float, optional
        acceleration of gravity [m/s^2]; body force density * gravity
    traction : Traction or list of Traction, optional
        surface loads [Pa] (:class:`~validation.boundary.Traction`)
    point_loads : (n, 3) float or {node: (3,) float}, optional
        forces at mesh nodes [N] (a point force on a continuum has no finite limit under refinement: use tractions for
        references that must converge)
    body_force : callable (k, 3) float -> (k, 3) float, optional
        extra force per volume [N/m^3]
    element : {"P2", "P1", "TH"}
        displacement P2 or P1 tets, or Taylor-Hood P2-P1 (P2 displacement, continuous P1 pressure: free of volumetric
        locking as nu -> 1/2; needs nu > 0)
    solver : {"auto", "direct", "amg"}
        ``"auto"`` is sparse LU up to :data:`~validation.fem_solvers.DIRECT_DOF_LIMIT` free dofs, else CG preconditioned
        by smoothed-aggregation AMG with the six rigid-body modes as near-null space (for P2 inside a P2 -> P1 two-level
        cycle). TH is indefinite: always sparse LU, and ``"amg"`` is refused.
    tolerance : float
        relative residual at which CG stops

    Returns
    -------
    StaticSolution

    Raises
    ------
    ValueError
        For bad material constants, a clamp or traction region without nodes or faces (naming the
        region and the mesh bounds), clamps that leave a rigid-body mode free, or TH with nu <= 0.
    """
    element = check_element(element, ELEMENTS)
    E, nu, density = elastic_constants(material)
    _check_taylor_hood_nu(element, E, nu)
    start = time.perf_counter()
    fixed = resolve_clamps(mesh, clamp)
    tractions = resolve_tractions(mesh, traction)
    point_forces = resolve_point_loads(mesh, point_loads)
    space = skfem_space(mesh, element)
    load = load_vector(space, density, gravity, body_force, tractions, point_forces)
    is_fixed, u = fixed_vector(space, fixed)
    if element == "TH":
        u, internal, solve, sizes, assembled = _solve_taylor_hood(mesh, space, E, nu, load, is_fixed, u, solver)
    else:
        u, internal, solve, sizes, assembled = _solve_displacement(mesh, space, E, nu, load, is_fixed, u, solver,
                                                                   tolerance)
    reaction = np.bincount(space.components[is_fixed], weights=(internal - load)[is_fixed], minlength=3)
    field = space.basis.interpolate(u)
    volume_change = asm(Functional(lambda w: div(w["u"])), space.basis, u=field)
    gross = asm(Functional(lambda w: np.abs(div(w["u"]))), space.basis, u=field)
    displacement = u[space.node_dofs]
    deformed = signed_tet_volumes(mesh.points + displacement, mesh.tets).sum() - mesh.volume
    info = ReferenceInfo(**dataclasses.asdict(solve), dof_count=sizes[0], free_dof_count=sizes[1],
                         assemble_seconds=assembled - start)
    logger.info("%s static solve: %d dofs, %s, %d iterations, residual %.2g, %.2f s assembly + %.2f s solve",
                element, info.dof_count, info.method, info.iterations, info.residual, info.assemble_seconds,
                info.setup_seconds + info.solve_seconds)
    return StaticSolution(displacement, float(volume_change), float(deformed), float(gross), reaction, u, element, info)


#: The share of the gross volume change (the integral of |div u|) below which a net one (the integral of div u) is a
#: cancellation that no reference gets right. Measured on the held-out shapes (Taylor-Hood, nu 0.3 and 0.49): the net
#: is 0.1-0.2% of the gross on the torus and 0.5% on the capsule, which bend, and there same-mesh P2 gives 0.29-1.28
#: times Taylor-Hood's net and Taylor-Hood on the capsule refined once 0.54-0.59 times its own; it is 4-9% on the
#: L-bracket and 21-86% on the bunny, and there P2 and Taylor-Hood agree within 0.5% and refining the bunny moves
#: Taylor-Hood's by 0.0-0.7%. 2% lies between the two groups.
CANCELLING_SHARE = 0.02


def volume_change_cancels(net: float, gross: float) -> bool:
    """Whether a net volume change ``net`` (the integral of div u) [m^3] is a cancellation: less than
    :data:`CANCELLING_SHARE` of the ``gross`` one (the integral of |div u|) [m^3]. In bending the fibres stretched on
    one side gain about what those compressed on the other lose; a ratio to that net, or a relative error, measures
    mostly the reference's own discretisation error.

    >>> volume_change_cancels(-1.0e-9, 1.2e-6), volume_change_cancels(-5.7e-9, 2.7e-8)
    (True, False)
    """
    return abs(net) < CANCELLING_SHARE * gross


def _solve_displacement(mesh, space, E, nu, load, is_fixed, u, solver, tolerance):
    """P1 or P2: K u = f on the free dofs. Returns (u, K u, SolveInfo, (dofs, free dofs), time assembled)."""
    K = fem_stiffness_matrix(space, E, nu)
    free = ~is_fixed
    K_free = K[free][:, free]
    rhs = load[free] - K[free][:, is_fixed] @ u[is_fixed]
    coarse, prolongation = free, None
    if space.element == "P2":
        coarse = np.zeros_like(free)
        coarse[space.node_dofs] = free[space.node_dofs]
        prolongation = p1_prolongation(mesh, space)[free][:, coarse]
    centre = mesh.points.mean(axis=0)
    modes = rigid_body_modes(space.basis.doflocs.T[coarse], components=space.components[coarse], centre=centre,
                             scale=np.abs(mesh.points - centre).max())
    assembled = time.perf_counter()
    u[free], solve = solve_linear(K_free, rhs, solver=solver, tolerance=tolerance, rigid_modes=modes,
                                  prolongation=prolongation)
    return u, K @ u, solve, (int(K.shape[0]), int(free.sum())), assembled


def _taylor_hood_system(mesh, space, E, nu, free):
    """The condensed, scaled TH matrix ``[[A_ff, -s B_f^T], [-s B_f, -s^2 C / lambda]]`` (free displacement dofs,
    then every pressure dof p / s), the blocks (A, B, C) of :func:`~validation.fem_assembly.mixed_matrices`
    on all dofs, and the scale s [Pa/m]."""
    lam, mu = lame_parameters(E, nu)
    A, B, C = mixed_matrices(space, pressure_basis(space), mu)
    # Unknown p / s with s = mu / h (h the mean edge length), its row times s: then the three blocks A ~ mu h,
    # s B ~ mu h and s^2 C / lambda ~ (mu / lambda) mu h are all forces per length, so LU pivots on comparable
    # entries and the residual check weighs both rows alike (measured LU residuals 1e-11..2e-10 at nu 0.3-0.499).
    scale = mu / np.linalg.norm(np.diff(mesh.points[mesh.edges], axis=1), axis=-1).mean()
    B_free = B[:, free]
    K = sp.bmat([[A[free][:, free], -scale * B_free.T], [-scale * B_free, -(scale**2 / lam) * C]]).tocsr()
    return K, (A, B, C), scale


def _solve_taylor_hood(mesh, space, E, nu, load, is_fixed, u, solver):
    """TH: the mixed system of :func:`~validation.fem_assembly.mixed_matrices` on the free displacement dofs
    and every pressure dof. Returns (u, A u - B^T p, SolveInfo, (dofs, free dofs), time assembled)."""
    free = ~is_fixed
    K, (A, B, C), scale = _taylor_hood_system(mesh, space, E, nu, free)
    rhs = np.concatenate([load[free] - A[free][:, is_fixed] @ u[is_fixed], scale * (B[:, is_fixed] @ u[is_fixed])])
    assembled = time.perf_counter()
    solution, solve = solve_saddle_point(K, rhs, solver=solver)
    u[free] = solution[: free.sum()]
    p = scale * solution[free.sum():]
    sizes = (int(A.shape[0] + C.shape[0]), int(free.sum() + C.shape[0]))
    return u, A @ u - B.T @ p, solve, sizes, assembled


# ---------------------------------------------------------------------------- modal
@dataclass(frozen=True)
class ModalSolution:
    """The lowest free vibrations of a clamped body, K phi = (2 pi f)^2 M phi.

    Attributes
    ----------
    frequencies : (k,) float
        eigenfrequencies, ascending [Hz]
    shapes : (k, n, 3) float
        each mode at the mesh nodes, mass-normalised (phi^T M phi = 1) [kg^-1/2]
    element : str
        ``"P1"``, ``"P2"`` or ``"TH"``
    mass : str
        ``"consistent"`` or ``"lumped"``
    info : ReferenceInfo
        ``residual`` is the largest ||K phi - lambda M phi|| / ||K phi||
    """

    frequencies: np.ndarray
    shapes: np.ndarray
    element: str
    mass: str
    info: ReferenceInfo


def solve_fem_modes(mesh: TetMesh, material: Any, *, clamp: Any, count: int = 6, element: str = "P2",
                    mass: str = "consistent") -> ModalSolution:
    """Lowest eigenfrequencies of a clamped tet mesh (scipy ``eigsh``, shift-invert about 0).

    Parameters
    ----------
    mesh : TetMesh
        rest shape; points [m]
    material : (E, nu, density)
        see :func:`elastic_constants`
    clamp : region, Clamp or list of Clamp
        as for :func:`solve_fem_static`; prescribed displacements are ignored (vibration about the clamped rest shape)
    count : int
        number of modes, lowest first
    element : {"P2", "P1", "TH"}
        for TH the pressure is condensed out: the stiffness is the Schur complement ``A + lambda B^T C^-1 B`` (SPD,
        never formed), applied through the sparse LU of the mixed matrix in the shift-invert step and through a LU of
        the pressure mass C elsewhere
    mass : {"consistent", "lumped"}
        lumped is HRZ: the diagonal of the consistent mass scaled to keep the total mass (row sums would give P2
        vertices negative masses). On affine tets every element's diagonal has the same proportions, so one global scale
        is exact HRZ.

    Returns
    -------
    ModalSolution

    Raises
    ------
    ValueError
        For an unknown element or mass, ``count`` out of range, or TH with nu <= 0.
    """
    element = check_element(element, ELEMENTS)
    if mass not in ("consistent", "lumped"):
        raise ValueError(f"mass = {mass!r} is not 'consistent' or 'lumped'")
    E, nu, density = elastic_constants(material)
    _check_taylor_hood_nu(element, E, nu)
    start = time.perf_counter()
    fixed = resolve_clamps(mesh, clamp)
    space = skfem_space(mesh, element)
    M = mass_matrix(space, density)
    if mass == "lumped":
        diagonal = M.diagonal()
        M = sp.diags(diagonal * (3 * density * mesh.volume / diagonal.sum())).tocsr()
    free = ~fixed_vector(space, fixed)[0]
    M_free = M[free][:, free]
    if not 1 <= count < M_free.shape[0]:
        raise ValueError(f"count = {count} modes is not between 1 and {M_free.shape[0] - 1} (free dofs - 1)")
    inverse = None
    if element == "TH":
        K_free, inverse, dof_count = _taylor_hood_condensed(mesh, space, E, nu, free)
    else:
        K = fem_stiffness_matrix(space, E, nu)
        K_free, dof_count = K[free][:, free].tocsc(), K.shape[0]
    assembled = time.perf_counter()
    # A start vector from a seeded local generator: without v0, ARPACK draws one from a hidden
    # generator whose state persists between calls, so two identical solves differed (by 2e-14).
    initial = np.random.default_rng(0).standard_normal(M_free.shape[0])
    eigenvalues, vectors = spla.eigsh(K_free, k=count, M=M_free.tocsc(), sigma=0.0, which="LM", v0=initial,
                                      OPinv=inverse)
    order = np.argsort(eigenvalues)
    eigenvalues, vectors = eigenvalues[order], vectors[:, order]
    solved = time.perf_counter()
    stiff = K_free @ vectors
    residual = float(np.max(np.linalg.norm(stiff - (M_free @ vectors) * eigenvalues, axis=0)
                            / np.linalg.norm(stiff, axis=0)))
    full = np.zeros((space.basis.N, count))
    full[free] = vectors
    shapes = np.moveaxis(full[space.node_dofs], -1, 0)
    # converged: eigsh raises unless it converged to its tolerance 0, i.e. machine precision.
    info = ReferenceInfo("eigsh", 0, residual, True, 0.0, solve_seconds=solved - assembled, dof_count=int(dof_count),
                         free_dof_count=int(free.sum()), assemble_seconds=assembled - start)
    frequencies = np.sqrt(np.clip(eigenvalues, 0.0, None)) / (2 * np.pi)
    logger.info("%s modes (%s mass): %s Hz, %.2f s assembly + %.2f s solve", element, mass,
                np.array2string(frequencies, precision=4), info.assemble_seconds, info.solve_seconds)
    return ModalSolution(frequencies, shapes, element, mass, info)


def _taylor_hood_condensed(mesh, space, E, nu, free):
    """TH with the pressure condensed: (the Schur complement A_ff + lambda B_f^T C^-1 B_f as a LinearOperator,
    its inverse through the LU of the mixed matrix as a LinearOperator, the dof count u + p)."""
    K, (A, B, C), _ = _taylor_hood_system(mesh, space, E, nu, free)
    lam = lame_parameters(E, nu)[0]
    free_count, pressure_count = int(free.sum()), C.shape[0]
    mixed, mass = spla.splu(K.tocsc()), spla.splu(C.tocsc())
    A_free, B_free = A[free][:, free], B[:, free]
    # Row 2 of the mixed system gives p = -lambda C^-1 B u; row 1 then reads (A + lambda B^T C^-1 B) u = f.
    # Its inverse is the u part of the mixed solve with load (f, 0): the p / s scaling does not change u.
    schur = spla.LinearOperator((free_count, free_count), dtype=float,
                                matvec=lambda u: A_free @ u + lam * (B_free.T @ mass.solve(B_free @ u)))
    inverse = spla.LinearOperator((free_count, free_count), dtype=float,
                                  matvec=lambda f: mixed.solve(np.concatenate([f, np.zeros(pressure_count)]))
                                  [:free_count])
    return schur, inverse, A.shape[0] + pressure_count


def _check_taylor_hood_nu(element, E, nu):
    if element == "TH" and not nu > 0:
        raise ValueError(f"nu = {nu:g} is not > 0, which element 'TH' needs (its pressure equation divides by "
                         f"lambda = {lame_parameters(E, nu)[0]:g} Pa); use element='P2'")


# ---------------------------------------------------------------------------- error norms
def error_norms(mesh: TetMesh, solution: StaticSolution, displacement: Callable,
                gradient: Callable) -> tuple[float, float]:
    """L2 and H1-seminorm error of a finite-element solution against an exact field.

    Parameters
    ----------
    mesh : TetMesh
        the mesh ``solution`` was computed on
    solution : StaticSolution
    displacement : callable (k, 3) float -> (k, 3) float
        exact u [m]
    gradient : callable (k, 3) float -> (k, 3, 3) float
        exact du_a/dx_b [-]

    Returns
    -------
    (l2, h1) : float
        sqrt(int |u_h - u|^2) [m^2.5] and sqrt(int |grad(u_h - u)|^2) [m^1.5], the second equivalent to the energy norm.
        Optimal rates in the mesh size h: P1 h^2 and h, P2 and TH h^3 and h^2.
    """
    space = skfem_space(mesh, solution.element)
    basis = space.with_intorder(2 * space.order + 2)

    @Functional
    def squared_errors(w):
        x = w.x.reshape(3, -1).T
        exact = displacement(x).T.reshape(w.x.shape)
        exact_gradient = np.moveaxis(gradient(x), 0, -1).reshape((3, 3) + w.x.shape[1:])
        field = w["u"]
        return np.stack([((field - exact) ** 2).sum(axis=0),
                         ((field.grad - exact_gradient) ** 2).sum(axis=(0, 1))])

    l2, h1 = np.sqrt(asm(squared_errors, basis, u=basis.interpolate(solution.dofs)))
    return float(l2), float(h1)


def __getattr__(name):
    # 0.1 names that clashed with volspring's (volspring.statics, volspring.modes, volspring.assembly).
    from volspring._deprecation import deprecated_alias

    return deprecated_alias(__name__, name, {"solve_static": ("validation.fem.solve_fem_static", solve_fem_static), "solve_modes": ("validation.fem.solve_fem_modes", solve_fem_modes)})
