"""Linear-elastic finite-element reference (scikit-fem) on a :class:`volspring.TetMesh`.

The data path reads in one direction::

    TetMesh, material, clamps, loads  ->  dof masks and loads on the TetMesh (numpy)
        ->  MeshTet / Basis / asm (scikit-fem)  ->  condensed solve (sparse LU, or AMG + CG)
        ->  StaticSolution / ModalSolution (arrays on the mesh nodes)

P2 tetrahedra are the default reference: P1 tetrahedra lock in bending (a cantilever of
10 x 1 x 1 cells deflects to 0.22 of the converged value, REFERENCE.md section 2).
Points are ``(n, 3)`` everywhere here and become scikit-fem's ``(3, n)`` only in
:func:`_skfem_space`.

Examples
--------
A unit cube (one cell, six tets) on three symmetry planes, pulled by 1 kPa on its face x = 1:
uniaxial stress, so the strain is 1e-3 along x and -nu * 1e-3 across, which P1 reproduces exactly.

>>> import numpy as np
>>> from volspring import TetMesh
>>> from validation.fem import Box, Clamp, Traction, solve_static
>>> corners = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], dtype=float)
>>> tets = [[0, 4, 6, 7], [0, 4, 5, 7], [0, 2, 6, 7], [0, 2, 3, 7], [0, 1, 5, 7], [0, 1, 3, 7]]
>>> cube = TetMesh.oriented(corners, tets)
>>> symmetry = [Clamp(Box.plane(axis, 0.0), components=axis) for axis in "xyz"]
>>> pull = Traction(Box.plane("x", 1.0), (1e3, 0.0, 0.0))
>>> solution = solve_static(cube, (1e6, 0.3, 1000.0), clamp=symmetry, traction=pull, element="P1")
>>> solution.displacement[7].round(9)   # the corner (1, 1, 1) [m]
array([ 0.001 , -0.0003, -0.0003])
>>> round(solution.volume_change, 9)    # (1 - 2 nu) eps V [m^3]
0.0004
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from skfem import (Basis, BilinearForm, ElementTetP1, ElementTetP2, ElementVector, FacetBasis, Functional,
                   LinearForm, MeshTet, asm)
from skfem.helpers import div, dot
from skfem.models.elasticity import lame_parameters, linear_elasticity

from volspring.mesh import signed_tet_volumes

__all__ = [
    "Box",
    "Clamp",
    "ModalSolution",
    "SolverInfo",
    "StaticSolution",
    "Traction",
    "elastic_constants",
    "error_norms",
    "solve_modes",
    "solve_static",
]

logger = logging.getLogger(__name__)

#: Problems with at most this many free dofs are solved by sparse LU in ``solver="auto"``, larger
#: ones by AMG + CG: at 19,440 P2 dofs LU took 2-5 s and AMG 1.5 s, and LU fill-in grows fast beyond.
DIRECT_DOF_LIMIT = 20_000
#: Relative residual ||f - K u|| / ||f|| at which CG stops.
AMG_TOLERANCE = 1e-10
_COMPONENTS = {"x": 0, "y": 1, "z": 2}
_ELEMENTS = {"P1": ElementTetP1, "P2": ElementTetP2}


# ---------------------------------------------------------------------------- inputs
def elastic_constants(material) -> tuple[float, float, float]:
    """Young's modulus, Poisson ratio and density of a material, checked.

    Parameters
    ----------
    material : object with ``.E``, ``.nu``, ``.density``, or a mapping with those keys, or a tuple
        ``(E, nu, density)`` -- E [Pa], nu [-], density [kg/m^3]

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


@dataclass(frozen=True)
class Box:
    """An axis-aligned box region, boundary included; infinite sides are allowed.

    Parameters
    ----------
    lower, upper : (3,) float -- corners [m]
    tolerance : float, optional -- slack on every side [m]; by default 1e-9 times the
        diagonal of the points tested, so that points on a face of the box count as inside.
    """

    lower: tuple = (-np.inf, -np.inf, -np.inf)
    upper: tuple = (np.inf, np.inf, np.inf)
    tolerance: float | None = None

    @classmethod
    def plane(cls, axis: str, value: float, **options) -> "Box":
        """The plane ``axis = value``, e.g. ``Box.plane("x", 0.0)`` for the face x = 0 of a beam."""
        lower, upper = [-np.inf] * 3, [np.inf] * 3
        lower[_COMPONENTS[axis]] = upper[_COMPONENTS[axis]] = float(value)
        return cls(tuple(lower), tuple(upper), **options)

    def __call__(self, points) -> np.ndarray:
        """(k,) bool -- which of the (k, 3) points [m] lie in the box."""
        points = np.asarray(points, dtype=float)
        tolerance = self.tolerance
        if tolerance is None:
            tolerance = 1e-9 * float(np.linalg.norm(np.ptp(points, axis=0))) if len(points) else 0.0
        lower, upper = np.asarray(self.lower, float), np.asarray(self.upper, float)
        return ((points >= lower - tolerance) & (points <= upper + tolerance)).all(axis=1)


@dataclass(frozen=True)
class Clamp:
    """Prescribed displacement of some components on the mesh nodes in a region.

    Parameters
    ----------
    region : callable (k, 3) float -> (k,) bool, or :class:`Box`, or (2, 3) float box corners [m]
    components : str or sequence of int -- the fixed components: ``"xyz"`` (all, the default),
        ``"x"`` for a sliding/symmetry support that fixes u_x only, or indices such as ``(0, 2)``
    displacement : (3,) float or callable (k, 3) float -> (k, 3) float -- prescribed value [m] of
        the fixed components (zero by default); a callable is evaluated at the dof locations

    Notes
    -----
    The region is tested at the mesh nodes. A P2 edge dof is fixed when both end nodes of its
    edge are, so the whole clamped surface is held, not only its vertices (clamping the vertex
    dofs alone leaks: a 12.6% error was seen, REFERENCE.md section 6). For a region that is not
    convex, an edge joining two clamped nodes is clamped even if it leaves the region.
    """

    region: object
    components: object = "xyz"
    displacement: object = (0.0, 0.0, 0.0)

    @property
    def component_indices(self) -> tuple:
        """The fixed components as indices 0, 1, 2."""
        names = self.components
        if isinstance(names, str):
            indices = tuple(_COMPONENTS.get(c, -1) for c in names.lower())
        else:
            indices = tuple(names)
        if not indices or any(i not in (0, 1, 2) for i in indices):
            raise ValueError(f"clamp components must be drawn from x, y, z (0, 1, 2), got {names!r}")
        return indices


@dataclass(frozen=True)
class Traction:
    """A uniform surface traction on the boundary faces lying wholly in a region.

    Parameters
    ----------
    region : as for :class:`Clamp` -- a boundary face is loaded when its three nodes are in it
    vector : (3,) float -- force per area [Pa]
    """

    region: object
    vector: tuple


def _region_mask(region, points: np.ndarray) -> np.ndarray:
    if not callable(region):
        corners = np.asarray(region, dtype=float)
        if corners.shape != (2, 3):
            raise TypeError(f"a region is a callable on (k, 3) points or (2, 3) box corners, got {region!r}")
        region = Box(tuple(corners[0]), tuple(corners[1]))
    mask = np.asarray(region(points), dtype=bool)
    if mask.shape != (len(points),):
        raise ValueError(f"region {_describe(region)} returned shape {mask.shape}, expected ({len(points)},)")
    return mask


def _describe(region) -> str:
    return getattr(region, "__name__", None) or repr(region)


def _bounds_text(points: np.ndarray) -> str:
    low, high = points.min(axis=0), points.max(axis=0)
    return " x ".join(f"[{a:g}, {b:g}]" for a, b in zip(low, high))


def _clamps(clamp) -> list:
    if clamp is None or (isinstance(clamp, Sequence) and len(clamp) == 0):
        raise ValueError("no clamp: all six rigid-body modes (3 translations, 3 rotations) are free, so the "
                         "stiffness matrix is singular; pass clamp=<region> or clamp=[Clamp(...), ...]")
    if isinstance(clamp, Clamp):
        return [clamp]
    if isinstance(clamp, Sequence) and all(isinstance(item, Clamp) for item in clamp):
        return list(clamp)
    return [Clamp(clamp)]


def _evaluate(value, points: np.ndarray) -> np.ndarray:
    """A constant (3,) vector or a callable on (k, 3) points, as (k, 3) values."""
    if callable(value):
        values = np.asarray(value(points), dtype=float)
    else:
        values = np.broadcast_to(np.asarray(value, dtype=float), (len(points), 3))
    if values.shape != (len(points), 3):
        raise ValueError(f"expected a (3,) vector or (k, 3) values, got shape {values.shape}")
    return values


@dataclass(frozen=True)
class _FixedDofs:
    """Clamps reduced to masks and values on the TetMesh nodes and edges (no scikit-fem yet)."""

    node_mask: np.ndarray  # (n, 3) bool
    node_values: np.ndarray  # (n, 3) float [m]
    edge_mask: np.ndarray  # (e, 3) bool, along mesh.edges
    edge_values: np.ndarray  # (e, 3) float [m], at the edge midpoints


def _fixed_dofs(mesh, clamp) -> _FixedDofs:
    points, edges = mesh.points, mesh.edges
    midpoints = points[edges].mean(axis=1)
    node_mask, node_values = np.zeros((len(points), 3), bool), np.zeros((len(points), 3))
    edge_mask, edge_values = np.zeros((len(edges), 3), bool), np.zeros((len(edges), 3))
    for item in _clamps(clamp):
        inside = _region_mask(item.region, points)
        if not inside.any():
            raise ValueError(f"clamp region {_describe(item.region)} contains no mesh node; "
                             f"the mesh spans {_bounds_text(points)} m")
        on_edge = inside[edges].all(axis=1)
        nodes_value = _evaluate(item.displacement, points[inside])
        edges_value = _evaluate(item.displacement, midpoints[on_edge])
        for c in item.component_indices:
            node_mask[inside, c] = True
            node_values[inside, c] = nodes_value[:, c]
            edge_mask[on_edge, c] = True
            edge_values[on_edge, c] = edges_value[:, c]
    _check_rigid_modes(points, node_mask)
    return _FixedDofs(node_mask, node_values, edge_mask, edge_values)


def _rigid_modes(locations: np.ndarray, components: np.ndarray, centre: np.ndarray, scale: float) -> np.ndarray:
    """(k, 6) float -- translations along x, y, z and rotations about x, y, z through ``centre``,
    sampled at k dofs given by their (k, 3) locations [m] and (k,) components; lengths divided by ``scale``."""
    rows = np.arange(len(locations))
    modes = np.zeros((len(locations), 6))
    modes[rows, components] = 1.0
    for axis in range(3):
        modes[:, 3 + axis] = np.cross(np.eye(3)[axis], (locations - centre) / scale)[rows, components]
    return modes


def _check_rigid_modes(points: np.ndarray, node_mask: np.ndarray) -> None:
    """Raise if the fixed node components leave an infinitesimal rigid-body motion free."""
    nodes, components = np.nonzero(node_mask)
    centre = points.mean(axis=0)
    restricted = _rigid_modes(points[nodes], components, centre, np.abs(points - centre).max())
    values, vectors = np.linalg.eigh(restricted.T @ restricted)
    # Entries of the modes are O(1) after scaling, so B^T B has eigenvalues O(fixed dofs) for constrained
    # directions and round-off (1e-16 relative) for free ones; 1e-10 separates the two with room to spare.
    free = values <= 1e-10 * max(values.max(), 1.0)
    if free.any():
        names = ("tx", "ty", "tz", "rx", "ry", "rz")
        modes = "; ".join(" + ".join(f"{v:.2f} {n}" for v, n in zip(vector, names) if abs(v) > 1e-3)
                          for vector in vectors[:, free].T)
        raise ValueError(f"the clamps leave {free.sum()} of the 6 rigid-body modes free (t = translation along, "
                         f"r = rotation about an axis): {modes}; the stiffness matrix is singular, clamp more")


def _tractions(mesh, traction) -> list:
    """[(faces (k, 3) int, vector (3,) float [Pa]), ...] -- the boundary faces each traction loads."""
    if traction is None:
        return []
    items = [traction] if isinstance(traction, Traction) else list(traction)
    loaded = []
    for item in items:
        if not isinstance(item, Traction):
            raise TypeError(f"traction must be a Traction or a list of them, got {item!r}")
        faces = mesh.boundary_faces[_region_mask(item.region, mesh.points)[mesh.boundary_faces].all(axis=1)]
        if len(faces) == 0:
            raise ValueError(f"traction region {_describe(item.region)} contains no boundary face; "
                             f"the mesh spans {_bounds_text(mesh.points)} m")
        vector = np.asarray(item.vector, dtype=float)
        if vector.shape != (3,):
            raise ValueError(f"a traction vector has shape (3,) [Pa], got {vector.shape}")
        loaded.append((faces, vector))
    return loaded


def _point_loads(mesh, point_loads) -> np.ndarray:
    """(n, 3) float nodal forces [N] from an (n, 3) array or a mapping {node: (3,) force}."""
    forces = np.zeros((mesh.node_count, 3))
    if point_loads is None:
        return forces
    if isinstance(point_loads, Mapping):
        for node, force in point_loads.items():
            if not 0 <= int(node) < mesh.node_count:
                raise ValueError(f"point load at node {node}, but the mesh has nodes 0..{mesh.node_count - 1}")
            forces[int(node)] += np.asarray(force, dtype=float)
        return forces
    point_loads = np.asarray(point_loads, dtype=float)
    if point_loads.shape != forces.shape:
        raise ValueError(f"point_loads must be (n, 3) = {forces.shape} nodal forces [N], got {point_loads.shape}")
    return forces + point_loads


def _element_name(element: str) -> str:
    if element not in _ELEMENTS:
        raise ValueError(f"element = {element!r} is not one of {sorted(_ELEMENTS)}")
    return element


# ---------------------------------------------------------------------------- scikit-fem
def _matching_rows(ours: np.ndarray, theirs: np.ndarray) -> np.ndarray:
    """Index into ``theirs`` of each row of ``ours`` (both (k, d) int with sorted rows)."""
    _, inverse = np.unique(np.concatenate([theirs, ours]), axis=0, return_inverse=True)
    inverse = inverse.ravel()
    lookup = np.full(inverse.max() + 1, -1)
    lookup[inverse[: len(theirs)]] = np.arange(len(theirs))
    found = lookup[inverse[len(theirs):]]
    if (found < 0).any():
        raise RuntimeError("scikit-fem's mesh lacks an edge or face of the TetMesh (this is a bug)")
    return found


@dataclass(frozen=True)
class _Space:
    """A vector P1/P2 scikit-fem basis on a TetMesh and where its dofs sit in TetMesh terms."""

    element: str
    basis: Basis
    node_dofs: np.ndarray  # (n, 3) int -- the dof of component c at node i
    edge_dofs: np.ndarray  # (e, 3) int -- the same for each of mesh.edges (P2); (0, 3) for P1
    components: np.ndarray  # (N,) int -- the component (0, 1, 2) of each dof

    @property
    def order(self) -> int:
        return int(self.element[1])

    def with_intorder(self, intorder: int) -> Basis:
        return Basis(self.basis.mesh, self.basis.elem, intorder=intorder)


def _skfem_space(mesh, element: str) -> _Space:
    # The only place where the (n, 3) points become scikit-fem's (3, n).
    skmesh = MeshTet(np.ascontiguousarray(mesh.points.T), np.ascontiguousarray(mesh.tets.T))
    order = int(element[1])
    # Gradients of P_k are P_(k-1) on affine tets, so order 2(k-1) integrates the stiffness exactly and
    # order k a constant body force. Order k costs a tenth of scikit-fem's default 2k for P2 (0.45 s
    # against 5.2 s at 525 nodes) and gives the same matrix to 1e-15.
    basis = Basis(skmesh, ElementVector(_ELEMENTS[element]()), intorder=order)
    node_dofs = basis.nodal_dofs.T
    edge_dofs = np.zeros((0, 3), dtype=np.int64)
    if element == "P2":
        edge_dofs = basis.edge_dofs.T[_matching_rows(mesh.edges, np.sort(skmesh.edges, axis=0).T)]
    components = np.empty(basis.N, dtype=np.int64)
    for dofs in (node_dofs, edge_dofs):
        components[dofs] = np.arange(3)
    return _Space(element, basis, node_dofs, edge_dofs, components)


def _fixed_vector(space: _Space, fixed: _FixedDofs) -> tuple[np.ndarray, np.ndarray]:
    """(N,) bool fixed dofs and (N,) float their values [m]."""
    mask, values = np.zeros(space.basis.N, bool), np.zeros(space.basis.N)
    mask[space.node_dofs[fixed.node_mask]] = True
    values[space.node_dofs[fixed.node_mask]] = fixed.node_values[fixed.node_mask]
    if space.element == "P2":
        mask[space.edge_dofs[fixed.edge_mask]] = True
        values[space.edge_dofs[fixed.edge_mask]] = fixed.edge_values[fixed.edge_mask]
    return mask, values


def _stiffness(space: _Space, E: float, nu: float) -> sp.csr_matrix:
    return asm(linear_elasticity(*lame_parameters(E, nu)), space.basis).tocsr()


def _load_vector(space: _Space, density, gravity, body_force, tractions, point_forces) -> np.ndarray:
    basis = space.basis
    load = np.zeros(basis.N)
    if gravity is not None:
        weight = density * np.asarray(gravity, dtype=float)
        if weight.shape != (3,):
            raise ValueError(f"gravity must be a (3,) vector [m/s^2], got shape {np.shape(gravity)}")
        load += asm(LinearForm(lambda v, w: weight[0] * v[0] + weight[1] * v[1] + weight[2] * v[2]), basis)
    if body_force is not None:
        @LinearForm
        def body(v, w):
            return dot(_evaluate(body_force, w.x.reshape(3, -1).T).T.reshape(w.x.shape), v)

        # A smooth, non-polynomial force: one order above 2k keeps the quadrature error below the
        # discretisation error (the convergence rates in tests/test_fem.py rely on it).
        load += asm(body, space.with_intorder(2 * space.order + 1))
    for faces, vector in tractions:
        facets = _matching_rows(np.sort(faces, axis=1), np.sort(basis.mesh.facets, axis=0).T)
        facet_basis = FacetBasis(basis.mesh, basis.elem, facets=facets, intorder=space.order)
        load += asm(LinearForm(lambda v, w: vector[0] * v[0] + vector[1] * v[1] + vector[2] * v[2]), facet_basis)
    np.add.at(load, space.node_dofs, point_forces)
    return load


def _p1_prolongation(mesh, space: _Space) -> sp.csr_matrix:
    """(N, N) float -- P1 interpolation into the P2 space: vertex dofs map to themselves, an edge dof
    takes the mean of its two end nodes. Only the columns of vertex dofs are non-zero."""
    edge_rows = space.edge_dofs.ravel()
    rows = np.concatenate([space.node_dofs.ravel(), edge_rows, edge_rows])
    columns = np.concatenate([space.node_dofs.ravel()] + [space.node_dofs[mesh.edges[:, k]].ravel() for k in (0, 1)])
    values = np.concatenate([np.ones(space.node_dofs.size), np.full(2 * edge_rows.size, 0.5)])
    return sp.csr_matrix((values, (rows, columns)), shape=(space.basis.N, space.basis.N))


# ---------------------------------------------------------------------------- solvers
@dataclass(frozen=True)
class SolverInfo:
    """How a reference was computed.

    Attributes
    ----------
    method : str -- ``"direct"`` (sparse LU), ``"amg"`` (smoothed aggregation + CG) or ``"eigsh"``
    iterations : int -- CG iterations (0 for a direct solve)
    residual : float -- relative residual ||f - K u|| / ||f|| of the condensed system (0 when f = 0)
    dof_count, free_dof_count : int -- all dofs and those not clamped
    assemble_seconds, solve_seconds : float -- wall time [s]
    """

    method: str
    iterations: int
    residual: float
    dof_count: int
    free_dof_count: int
    assemble_seconds: float
    solve_seconds: float


def _amg_preconditioner(K, *, rigid_modes, prolongation=None) -> spla.LinearOperator:
    """Smoothed aggregation with the rigid-body modes as near-null space, as a CG preconditioner.

    With ``prolongation`` (P2), a two-level p-multigrid: one symmetric Gauss-Seidel sweep on the P2
    system around an AMG V-cycle on the Galerkin P1 system P^T K P. Smoothed aggregation applied to
    the P2 matrix directly stalled (no 1e-8 residual in 300 CG iterations on a 20x2x2 cantilever,
    3,000 dofs); this scheme took 33 iterations there and 39 at 40x4x4 (19,440 dofs).
    """
    import pyamg
    from pyamg.relaxation.relaxation import gauss_seidel

    if prolongation is None:
        return pyamg.smoothed_aggregation_solver(K, B=rigid_modes).aspreconditioner(cycle="V")
    coarse = pyamg.smoothed_aggregation_solver((prolongation.T @ K @ prolongation).tocsr(), B=rigid_modes)

    def apply(residual):
        residual = np.asarray(residual, dtype=float).ravel()
        x = np.zeros_like(residual)
        gauss_seidel(K, x, residual, iterations=1, sweep="forward")
        x += prolongation @ coarse.solve(prolongation.T @ (residual - K @ x), tol=1e-30, maxiter=1, cycle="V")
        gauss_seidel(K, x, residual, iterations=1, sweep="backward")
        return x

    return spla.LinearOperator(K.shape, apply, dtype=float)


def _solve_linear(K, rhs, *, solver, tolerance, rigid_modes, prolongation=None):
    """Solve the condensed SPD system; returns (u, method, iterations, relative residual).

    ``rigid_modes`` are sampled at the dofs AMG coarsens: all of them, or with ``prolongation``
    (P2) the columns of the P1 vertex dofs.
    """
    if solver == "auto":
        solver = "direct" if K.shape[0] <= DIRECT_DOF_LIMIT else "amg"
    if solver not in ("direct", "amg"):
        raise ValueError(f"solver = {solver!r} is not one of 'auto', 'direct', 'amg'")
    norm = np.linalg.norm(rhs)
    if norm == 0:
        return np.zeros_like(rhs), solver, 0, 0.0
    iterations = 0
    if solver == "direct":
        u = spla.splu(K.tocsc()).solve(rhs)
    else:
        preconditioner = _amg_preconditioner(K, rigid_modes=rigid_modes, prolongation=prolongation)

        def count(_):
            nonlocal iterations
            iterations += 1

        u, _ = spla.cg(K, rhs, M=preconditioner, rtol=tolerance, maxiter=1000, callback=count)
    residual = float(np.linalg.norm(rhs - K @ u) / norm)
    # CG stops on its recursive residual; the true one drifts from it by round-off, so allow 100x.
    if solver == "amg" and residual > 100 * tolerance:
        raise RuntimeError(f"AMG + CG stopped at relative residual {residual:.3g} after {iterations} iterations "
                           f"(asked {tolerance:g}); try solver='direct'")
    return u, solver, iterations, residual


# ---------------------------------------------------------------------------- static
@dataclass(frozen=True)
class StaticSolution:
    """A linear-elastic static equilibrium.

    Attributes
    ----------
    displacement : (n, 3) float -- displacement of each mesh node [m] (P2: its vertex dofs)
    volume_change : float -- linearised volume change, the integral of div u over the mesh [m^3],
        exact for the finite-element field (it equals the flux of u through the boundary)
    deformed_volume_change : float -- volume of the mesh with its nodes moved by ``displacement``
        minus its rest volume [m^3]: what a node-based model (springs) measures; it differs from
        ``volume_change`` by O(|grad u|^2) terms, and for P2 it ignores the edge dofs
    reaction_force : (3,) float -- total force the clamps exert on the body [N]; at equilibrium
        minus the total applied load
    dofs : (N,) float -- the whole finite-element vector, in scikit-fem's dof order [m]
    element : str -- ``"P1"`` or ``"P2"``
    info : SolverInfo
    """

    displacement: np.ndarray
    volume_change: float
    deformed_volume_change: float
    reaction_force: np.ndarray
    dofs: np.ndarray
    element: str
    info: SolverInfo


def solve_static(mesh, material, *, clamp, gravity=None, traction=None, point_loads=None, body_force=None,
                 element: str = "P2", solver: str = "auto", tolerance: float = AMG_TOLERANCE) -> StaticSolution:
    """Linear-elastic static displacement of a clamped tet mesh under loads.

    Parameters
    ----------
    mesh : TetMesh -- rest shape; points [m]
    material : (E, nu, density) -- see :func:`elastic_constants`; E [Pa], density [kg/m^3]
    clamp : region, Clamp or list of Clamp -- a region (callable on (k, 3) points -> (k,) bool,
        :class:`Box`, or (2, 3) box corners) fixes all components of its nodes to zero; use
        :class:`Clamp` for single components (symmetry planes) or prescribed displacements
    gravity : (3,) float, optional -- acceleration of gravity [m/s^2]; body force density * gravity
    traction : Traction or list of Traction, optional -- surface loads [Pa]
    point_loads : (n, 3) float or {node: (3,) float}, optional -- forces at mesh nodes [N]
        (a point force on a continuum has no finite limit under refinement: use tractions for
        references that must converge)
    body_force : callable (k, 3) float -> (k, 3) float, optional -- extra force per volume [N/m^3]
    element : {"P2", "P1"}
    solver : {"auto", "direct", "amg"} -- ``"auto"`` is sparse LU up to ``DIRECT_DOF_LIMIT`` free
        dofs, else CG preconditioned by smoothed-aggregation AMG with the six rigid-body modes as
        near-null space (for P2 inside a P2 -> P1 two-level cycle)
    tolerance : float -- relative residual at which CG stops

    Returns
    -------
    StaticSolution

    Raises
    ------
    ValueError
        For bad material constants, a clamp or traction region without nodes or faces (naming the
        region and the mesh bounds), or clamps that leave a rigid-body mode free.
    """
    element = _element_name(element)
    E, nu, density = elastic_constants(material)
    start = time.perf_counter()
    fixed = _fixed_dofs(mesh, clamp)
    tractions = _tractions(mesh, traction)
    point_forces = _point_loads(mesh, point_loads)
    space = _skfem_space(mesh, element)
    K = _stiffness(space, E, nu)
    load = _load_vector(space, density, gravity, body_force, tractions, point_forces)
    is_fixed, u = _fixed_vector(space, fixed)
    free = ~is_fixed
    K_free = K[free][:, free]
    rhs = load[free] - K[free][:, is_fixed] @ u[is_fixed]
    coarse, prolongation = free, None
    if element == "P2":
        coarse = np.zeros_like(free)
        coarse[space.node_dofs] = free[space.node_dofs]
        prolongation = _p1_prolongation(mesh, space)[free][:, coarse]
    centre = mesh.points.mean(axis=0)
    modes = _rigid_modes(space.basis.doflocs.T[coarse], space.components[coarse], centre,
                         np.abs(mesh.points - centre).max())
    assembled = time.perf_counter()
    u[free], method, iterations, residual = _solve_linear(K_free, rhs, solver=solver, tolerance=tolerance,
                                                          rigid_modes=modes, prolongation=prolongation)
    solved = time.perf_counter()
    reaction = np.bincount(space.components[is_fixed], weights=(K @ u - load)[is_fixed], minlength=3)
    volume_change = asm(Functional(lambda w: div(w["u"])), space.basis, u=space.basis.interpolate(u))
    displacement = u[space.node_dofs]
    deformed = signed_tet_volumes(mesh.points + displacement, mesh.tets).sum() - mesh.volume
    info = SolverInfo(method, iterations, residual, int(K.shape[0]), int(free.sum()), assembled - start,
                      solved - assembled)
    logger.info("%s static solve: %d dofs, %s, %d iterations, residual %.2g, %.2f s assembly + %.2f s solve",
                element, info.dof_count, method, iterations, residual, info.assemble_seconds, info.solve_seconds)
    return StaticSolution(displacement, float(volume_change), float(deformed), reaction, u, element, info)


# ---------------------------------------------------------------------------- modal
@dataclass(frozen=True)
class ModalSolution:
    """The lowest free vibrations of a clamped body, K phi = (2 pi f)^2 M phi.

    Attributes
    ----------
    frequencies : (k,) float -- eigenfrequencies, ascending [Hz]
    shapes : (k, n, 3) float -- each mode at the mesh nodes, mass-normalised (phi^T M phi = 1) [kg^-1/2]
    element : str -- ``"P1"`` or ``"P2"``
    mass : str -- ``"consistent"`` or ``"lumped"``
    info : SolverInfo -- ``residual`` is the largest ||K phi - lambda M phi|| / ||K phi||
    """

    frequencies: np.ndarray
    shapes: np.ndarray
    element: str
    mass: str
    info: SolverInfo


def solve_modes(mesh, material, *, clamp, count: int = 6, element: str = "P2",
                mass: str = "consistent") -> ModalSolution:
    """Lowest eigenfrequencies of a clamped tet mesh (scipy ``eigsh``, shift-invert about 0).

    Parameters
    ----------
    mesh : TetMesh -- rest shape; points [m]
    material : (E, nu, density) -- see :func:`elastic_constants`
    clamp : region, Clamp or list of Clamp -- as for :func:`solve_static`; prescribed
        displacements are ignored (vibration about the clamped rest shape)
    count : int -- number of modes, lowest first
    element : {"P2", "P1"}
    mass : {"consistent", "lumped"} -- lumped is HRZ: the diagonal of the consistent mass scaled
        to keep the total mass (row sums would give P2 vertices negative masses). On affine tets
        every element's diagonal has the same proportions, so one global scale is exact HRZ.

    Returns
    -------
    ModalSolution
    """
    element = _element_name(element)
    if mass not in ("consistent", "lumped"):
        raise ValueError(f"mass = {mass!r} is not 'consistent' or 'lumped'")
    E, nu, density = elastic_constants(material)
    start = time.perf_counter()
    fixed = _fixed_dofs(mesh, clamp)
    space = _skfem_space(mesh, element)
    K = _stiffness(space, E, nu)
    # u . v of two P_k functions has degree 2k: integrated exactly by order 2k.
    M = asm(BilinearForm(lambda u, v, w: density * dot(u, v)), space.with_intorder(2 * space.order)).tocsr()
    if mass == "lumped":
        diagonal = M.diagonal()
        M = sp.diags(diagonal * (3 * density * mesh.volume / diagonal.sum())).tocsr()
    free = ~_fixed_vector(space, fixed)[0]
    K_free, M_free = K[free][:, free], M[free][:, free]
    if not 1 <= count < K_free.shape[0]:
        raise ValueError(f"count = {count} modes is not between 1 and {K_free.shape[0] - 1} (free dofs - 1)")
    assembled = time.perf_counter()
    eigenvalues, vectors = spla.eigsh(K_free.tocsc(), k=count, M=M_free.tocsc(), sigma=0.0, which="LM")
    order = np.argsort(eigenvalues)
    eigenvalues, vectors = eigenvalues[order], vectors[:, order]
    solved = time.perf_counter()
    stiff = K_free @ vectors
    residual = float(np.max(np.linalg.norm(stiff - (M_free @ vectors) * eigenvalues, axis=0)
                            / np.linalg.norm(stiff, axis=0)))
    full = np.zeros((space.basis.N, count))
    full[free] = vectors
    shapes = np.moveaxis(full[space.node_dofs], -1, 0)
    info = SolverInfo("eigsh", 0, residual, int(K.shape[0]), int(free.sum()), assembled - start, solved - assembled)
    frequencies = np.sqrt(np.clip(eigenvalues, 0.0, None)) / (2 * np.pi)
    logger.info("%s modes (%s mass): %s Hz, %.2f s assembly + %.2f s solve", element, mass,
                np.array2string(frequencies, precision=4), info.assemble_seconds, info.solve_seconds)
    return ModalSolution(frequencies, shapes, element, mass, info)


# ---------------------------------------------------------------------------- error norms
def error_norms(mesh, solution: StaticSolution, displacement: Callable, gradient: Callable) -> tuple[float, float]:
    """L2 and H1-seminorm error of a finite-element solution against an exact field.

    Parameters
    ----------
    mesh : TetMesh -- the mesh ``solution`` was computed on
    solution : StaticSolution
    displacement : callable (k, 3) float -> (k, 3) float -- exact u [m]
    gradient : callable (k, 3) float -> (k, 3, 3) float -- exact du_a/dx_b [-]

    Returns
    -------
    (l2, h1) : float -- sqrt(int |u_h - u|^2) [m^2.5] and sqrt(int |grad(u_h - u)|^2) [m^1.5], the
        second equivalent to the energy norm. Optimal rates in the mesh size h: P1 h^2 and h,
        P2 h^3 and h^2.
    """
    space = _skfem_space(mesh, solution.element)
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
