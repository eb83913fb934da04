"""The scikit-fem side of the reference: vector P1/P2 spaces on a TetMesh and the assembled system.

Three elements (:data:`ELEMENTS`): ``"P1"`` and ``"P2"`` displacement tetrahedra, and ``"TH"``,
Taylor-Hood P2-P1: P2 displacement (the same vector space as ``"P2"``) with a continuous P1 pressure
(:func:`pressure_basis`) in the mixed u-p form of :func:`mixed_matrices`, which does not lock as
nu -> 1/2.

The TetMesh's ``(n, 3)`` points become scikit-fem's ``(3, n)`` only in :func:`skfem_space`, which
also records where each dof sits in TetMesh terms (nodes, edges, components), so the fixed dofs
and loads resolved by :mod:`validation.boundary` map onto the finite-element vector without
scikit-fem's own facet or edge numbering leaking out. Quadrature orders are chosen here, each
with the reason it is exact (or accurate enough).

Examples
--------
>>> import numpy as np
>>> from meshing import TetMesh
>>> from validation.fem_assembly import skfem_space, fem_stiffness_matrix
>>> corners = np.array([[i, j, k] for i in (0, 1) for j in (0, 1) for k in (0, 1)], dtype=float)
>>> tets = [[0, 4, 6, 7], [0, 4, 5, 7], [0, 2, 6, 7], [0, 2, 3, 7], [0, 1, 5, 7], [0, 1, 3, 7]]
>>> space = skfem_space(TetMesh.compact(corners, tets), "P2")
>>> int(space.basis.N), space.node_dofs.shape, space.edge_dofs.shape   # 3 x (8 nodes + 19 edges)
(81, (8, 3), (19, 3))
>>> fem_stiffness_matrix(space, 1e6, 0.3).shape
(81, 81)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from skfem import (Basis, BilinearForm, ElementTetP1, ElementTetP2, ElementVector, FacetBasis, LinearForm, MeshTet,
                   asm)
from skfem.helpers import ddot, div, dot, sym_grad
from skfem.models.elasticity import lame_parameters, linear_elasticity

from validation.boundary import FixedDofs, evaluate_vectors
from typing import TYPE_CHECKING, Any
from collections.abc import Callable
from collections.abc import Sequence

if TYPE_CHECKING:
    from meshing.mesh import TetMesh
    from numpy.typing import ArrayLike

__all__ = [
    "DISPLACEMENT_ELEMENTS",
    "ELEMENTS",
    "Space",
    "check_element",
    "fixed_vector",
    "load_vector",
    "mass_matrix",
    "mixed_matrices",
    "p1_prolongation",
    "pressure_basis",
    "skfem_space",
    "fem_stiffness_matrix",
]

#: Every element the linear reference knows: P1 and P2 displacement tets, and Taylor-Hood P2-P1 (``"TH"``).
ELEMENTS = ("P1", "P2", "TH")
#: The pure-displacement elements: those with a single stiffness matrix (what the nonlinear reference
#: and the AMG solver handle).
DISPLACEMENT_ELEMENTS = ("P1", "P2")
# The scalar element of each displacement component, and its polynomial order.
_COMPONENT_ELEMENTS = {"P1": (ElementTetP1, 1), "P2": (ElementTetP2, 2), "TH": (ElementTetP2, 2)}


def check_element(element: str, allowed: tuple = DISPLACEMENT_ELEMENTS) -> str:
    """``element`` if it is one of ``allowed`` (by default ``"P1"`` or ``"P2"``), else a ValueError naming it.

    The default leaves ``"TH"`` out, so a caller built on one stiffness matrix refuses it; the linear
    reference (:mod:`validation.fem`) passes ``allowed=ELEMENTS``.
    """
    if element not in allowed:
        raise ValueError(f"element = {element!r} is not one of {list(allowed)}")
    return element


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
class Space:
    """A vector P1/P2 scikit-fem basis on a TetMesh and where its dofs sit in TetMesh terms.

    For ``element="TH"`` it is the P2 displacement space of the Taylor-Hood pair.
    """

    element: str
    basis: Basis
    node_dofs: np.ndarray  # (n, 3) int -- the dof of component c at node i
    edge_dofs: np.ndarray  # (e, 3) int -- the same for each of mesh.edges (P2, TH); (0, 3) for P1
    components: np.ndarray  # (N,) int -- the component (0, 1, 2) of each dof

    @property
    def order(self) -> int:
        """Polynomial order of the displacement: 1 (P1) or 2 (P2, TH)."""
        return _COMPONENT_ELEMENTS[self.element][1]

    def with_intorder(self, intorder: int) -> Basis:
        return Basis(self.basis.mesh, self.basis.elem, intorder=intorder)


def skfem_space(mesh: TetMesh, element: str) -> Space:
    """The vector displacement space of ``element`` ("P1", "P2", or "TH": P2) on a TetMesh, its dofs located."""
    # The only place where the (n, 3) points become scikit-fem's (3, n).
    skmesh = MeshTet(np.ascontiguousarray(mesh.points.T), np.ascontiguousarray(mesh.tets.T))
    component, order = _COMPONENT_ELEMENTS[check_element(element, ELEMENTS)]
    # Gradients of P_k are P_(k-1) on affine tets, so order 2(k-1) integrates the stiffness exactly and
    # order k a constant body force. Order k costs a tenth of scikit-fem's default 2k for P2 (0.45 s
    # against 5.2 s at 525 nodes) and gives the same matrix to 1e-15.
    basis = Basis(skmesh, ElementVector(component()), intorder=order)
    node_dofs = basis.nodal_dofs.T
    edge_dofs = np.zeros((0, 3), dtype=np.int64)
    if order == 2:
        edge_dofs = basis.edge_dofs.T[_matching_rows(mesh.edges, np.sort(skmesh.edges, axis=0).T)]
    components = np.empty(basis.N, dtype=np.int64)
    for dofs in (node_dofs, edge_dofs):
        components[dofs] = np.arange(3)
    return Space(element, basis, node_dofs, edge_dofs, components)


def fixed_vector(space: Space, fixed: FixedDofs) -> tuple[np.ndarray, np.ndarray]:
    """(N,) bool fixed dofs and (N,) float their values [m]."""
    mask, values = np.zeros(space.basis.N, bool), np.zeros(space.basis.N)
    mask[space.node_dofs[fixed.node_mask]] = True
    values[space.node_dofs[fixed.node_mask]] = fixed.node_values[fixed.node_mask]
    if space.order == 2:
        mask[space.edge_dofs[fixed.edge_mask]] = True
        values[space.edge_dofs[fixed.edge_mask]] = fixed.edge_values[fixed.edge_mask]
    return mask, values


def fem_stiffness_matrix(space: Space, E: float, nu: float) -> sp.csr_matrix:
    """(N, N) CSR -- linear-elastic stiffness [N/m] for E [Pa] and nu, at the space's own quadrature order."""
    return asm(linear_elasticity(*lame_parameters(E, nu)), space.basis).tocsr()


def pressure_basis(space: Space) -> Basis:
    """The continuous P1 pressure basis of the Taylor-Hood pair, on ``space``'s mesh and quadrature.

    Its dofs are the mesh nodes in TetMesh order (scikit-fem keeps the vertex numbering), and it
    shares ``space``'s quadrature (order 2, as :func:`skfem_space` chooses for P2), as the mixed forms of
    :func:`mixed_matrices` need.
    """
    if space.order != 2:
        raise ValueError(f"the Taylor-Hood pressure pairs with a P2 displacement, not {space.element}")
    return Basis(space.basis.mesh, ElementTetP1(), intorder=space.order)


def mixed_matrices(space: Space, pressure: Basis, mu: float) -> tuple[sp.csr_matrix, sp.csr_matrix, sp.csr_matrix]:
    """The blocks of the Taylor-Hood u-p form of linear elasticity.

    The mixed problem is: find u (P2) and p (P1) with, for every v and q,
    ``2 mu (eps u, eps v) - (p, div v) = l(v)`` and ``-(div u, q) - (p, q) / lambda = 0``, i.e.
    ``[[A, -B^T], [-B, -C / lambda]] [u; p] = [f; 0]`` (symmetric, indefinite): p = -lambda div u
    is the pressure [Pa], positive in compression. As lambda -> infinity the second row becomes
    the incompressibility constraint and the pair stays stable (inf-sup), so the answer does not lock.

    Parameters
    ----------
    space : Space
        The P2 displacement space (``"TH"`` or ``"P2"``).
    pressure : skfem Basis
        :func:`pressure_basis` of ``space``.
    mu : float
        Shear modulus [Pa].

    Returns
    -------
    A : (N, N) CSR
        ``2 mu (eps u, eps v)`` [N/m]
    B : (n, N) CSR
        ``(div u, q)`` [m^2]
    C : (n, n) CSR
        ``(p, q)``, the P1 mass matrix [m^3]
    """
    # eps(P2) and div(P2) are P1 on affine tets: every integrand is quadratic, exact at order 2.
    A = asm(BilinearForm(lambda u, v, w: 2 * mu * ddot(sym_grad(u), sym_grad(v))), space.basis)
    B = asm(BilinearForm(lambda u, q, w: div(u) * q), space.basis, pressure)
    C = asm(BilinearForm(lambda p, q, w: p * q), pressure)
    return A.tocsr(), B.tocsr(), C.tocsr()


def mass_matrix(space: Space, density: float) -> sp.csr_matrix:
    """(N, N) CSR -- consistent mass [kg] for density [kg/m^3]."""
    # u . v of two P_k functions has degree 2k: integrated exactly by order 2k.
    return asm(BilinearForm(lambda u, v, w: density * dot(u, v)), space.with_intorder(2 * space.order)).tocsr()


def load_vector(space: Space, density: float, gravity: ArrayLike | None,
                body_force: Callable[[np.ndarray], np.ndarray] | None, tractions: Sequence[Any],
                point_forces: np.ndarray) -> np.ndarray:
    """(N,) float -- consistent nodal forces [N] of gravity [m/s^2], a body force callable [N/m^3], the
    resolved tractions (:func:`validation.boundary.resolve_tractions`) and (n, 3) point forces [N]."""
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
            return dot(evaluate_vectors(body_force, w.x.reshape(3, -1).T).T.reshape(w.x.shape), v)

        # A smooth, non-polynomial force: one order above 2k keeps the quadrature error below the
        # discretisation error (the convergence rates in tests/test_fem.py rely on it).
        load += asm(body, space.with_intorder(2 * space.order + 1))
    for faces, vector in tractions:
        facets = _matching_rows(np.sort(faces, axis=1), np.sort(basis.mesh.facets, axis=0).T)
        facet_basis = FacetBasis(basis.mesh, basis.elem, facets=facets, intorder=space.order)
        load += asm(LinearForm(lambda v, w: vector[0] * v[0] + vector[1] * v[1] + vector[2] * v[2]), facet_basis)
    np.add.at(load, space.node_dofs, point_forces)
    return load


def p1_prolongation(mesh: TetMesh, space: Space) -> sp.csr_matrix:
    """(N, N) float -- P1 interpolation into the P2 space: vertex dofs map to themselves, an edge dof
    takes the mean of its two end nodes. Only the columns of vertex dofs are non-zero."""
    edge_rows = space.edge_dofs.ravel()
    rows = np.concatenate([space.node_dofs.ravel(), edge_rows, edge_rows])
    columns = np.concatenate([space.node_dofs.ravel()] + [space.node_dofs[mesh.edges[:, k]].ravel() for k in (0, 1)])
    values = np.concatenate([np.ones(space.node_dofs.size), np.full(2 * edge_rows.size, 0.5)])
    return sp.csr_matrix((values, (rows, columns)), shape=(space.basis.N, space.basis.N))


def __getattr__(name):
    # 0.1 names that clashed with volspring's (volspring.statics, volspring.modes, volspring.assembly).
    from volspring._deprecation import deprecated_alias

    return deprecated_alias(__name__, name, {"stiffness_matrix": ("validation.fem_assembly.fem_stiffness_matrix", fem_stiffness_matrix)})
