"""Finite-strain reference: a compressible Neo-Hookean solid in scikit-fem, solved by Newton's method.

The stored energy per rest volume is scikit-fem's Neo-Hookean form (its docs' example 36)::

    psi(F) = mu / 2 (I_1 - 3) - mu ln J + lambda / 2 (J - 1)^2,    I_1 = F : F,  J = det F,

with mu and lambda the Lame constants of E and nu, so that it reduces to linear elasticity at small
strain (same mu and lambda as :mod:`validation.fem`). Its first Piola-Kirchhoff stress and its
derivative (the tangent, exact) are, with H = F^-T::

    P(F)      = mu (F - H) + lambda J (J - 1) H
    dP[dF]    = mu dF + (mu - lambda J (J - 1)) H dF^T H + lambda (2 J - 1) J (H : dF) H.

The weak forms are written with :mod:`skfem.helpers` (grad, det, inv, transpose, ddot) on the same
P1/P2 spaces, clamps and loads as the linear reference (:func:`validation.fem_assembly.skfem_space`,
:mod:`validation.boundary`), so the nonlinear and linear references differ only in the material
law. Loads are dead loads (gravity and tractions keep their direction and their size per rest
volume or area) and so are prescribed displacements; both are applied in ``load_steps`` equal
increments (an increment that fails is halved). Each increment starts from a tangent predictor that
moves the held dofs by their increment and the free ones by the tangent's answer (moving the held
dofs alone would invert the elements beside them), then Newton with a backtracking line search on
the total potential energy (a step is also shortened while it would invert the material anywhere:
ln J needs J > 0). The linear solves are sparse LU (:class:`volspring.solvers.DirectSolver`): the
reference is meant for meshes of a few thousand dofs, where LU is exact and fast.

Quadrature: order 2 for P2 (gradients of P2 are linear, so the linear part of the tangent is
integrated exactly, as in the linear reference; the remaining nonlinear terms vary slowly on an
element at the strains a reference is used for), order 1 for P1 (constant gradients: exact).

Examples
--------
One P1 cube cell on three symmetry planes, its face x = 1 pulled to x = 1.5: the Neo-Hookean
lateral stretch of uniaxial stress (:func:`neo_hookean_uniaxial`) comes out on every node.

>>> import numpy as np
>>> from meshing import structured_box
>>> from validation.boundary import Box, Clamp
>>> from validation.nonlinear import neo_hookean_uniaxial, solve_neo_hookean_static
>>> cube = structured_box((1, 1, 1), (1.0, 1.0, 1.0))
>>> clamps = [Clamp(Box.plane(a, 0.0), components=a) for a in "xyz"]
>>> clamps.append(Clamp(Box.plane("x", 1.0), components="x", displacement=(0.5, 0.0, 0.0)))
>>> solution = solve_neo_hookean_static(cube, (1e6, 0.3, 1000.0), clamp=clamps, element="P1", load_steps=2)
>>> stretch, _ = neo_hookean_uniaxial(0.5, 1e6, 0.3)
>>> bool(abs(solution.displacement[:, 1].min() + 1.0 - stretch) < 1e-9)
True
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

import numpy as np
import scipy.optimize
from skfem import BilinearForm, Functional, LinearForm, asm
from skfem.helpers import ddot, det, grad, inv, transpose

from validation.boundary import resolve_clamps, resolve_point_loads, resolve_tractions
from validation.fem import elastic_constants
from validation.fem_assembly import check_element, fixed_vector, load_vector, skfem_space
from volspring.errors import SolverNotConverged
from volspring.solvers import DirectSolver
from typing import TYPE_CHECKING, Any
from collections.abc import Callable

if TYPE_CHECKING:
    from meshing.mesh import TetMesh

__all__ = [
    "NonlinearSolution",
    "lame_constants",
    "neo_hookean_density",
    "neo_hookean_stress",
    "neo_hookean_tangent",
    "neo_hookean_uniaxial",
    "solve_neo_hookean_static",
]

logger = logging.getLogger(__name__)


def lame_constants(E: float, nu: float) -> tuple[float, float]:
    """(mu, lambda) [Pa] of Young's modulus E [Pa] and Poisson's ratio nu."""
    return E / (2.0 * (1.0 + nu)), E * nu / ((1.0 + nu) * (1.0 - 2.0 * nu))


# ---------------------------------------------------------------------------- the material law
def _matmul(A, B):
    return np.einsum("ik...,kj...->ij...", A, B)


def _identity_like(A):
    eye = np.zeros_like(A)
    for i in range(A.shape[0]):
        eye[i, i] = 1.0
    return eye


def neo_hookean_density(F: np.ndarray, mu: float, lam: float) -> np.ndarray:
    """psi(F) [J/m^3] of (3, 3, ...) deformation gradients (leading axes: the tensor; J must be > 0)."""
    J = det(F)
    return 0.5 * mu * (ddot(F, F) - 3.0) - mu * np.log(J) + 0.5 * lam * (J - 1.0) ** 2


def neo_hookean_stress(F: np.ndarray, mu: float, lam: float) -> np.ndarray:
    """P(F) = d psi / dF [Pa], the first Piola-Kirchhoff stress, of (3, 3, ...) deformation gradients."""
    J = det(F)
    H = transpose(inv(F))
    return mu * (F - H) + lam * J * (J - 1.0) * H


def neo_hookean_tangent(F: np.ndarray, dF: np.ndarray, mu: float, lam: float) -> np.ndarray:
    """dP[dF] [Pa], the exact derivative of :func:`neo_hookean_stress` at F in the direction dF (module docstring)."""
    J = det(F)
    H = transpose(inv(F))
    return (mu * dF + (mu - lam * J * (J - 1.0)) * _matmul(_matmul(H, transpose(dF)), H)
            + lam * (2.0 * J - 1.0) * J * ddot(H, dF) * H)


def neo_hookean_uniaxial(strain: float, E: float, nu: float) -> tuple[float, float]:
    """Uniaxial stress of the Neo-Hookean solid: F = diag(1 + strain, s, s) with P_22 = P_33 = 0.

    Returns
    -------
    s : float
        the lateral stretch [-]
    P11 : float
        the axial first Piola-Kirchhoff stress [Pa] (force per rest area)
    """
    mu, lam = lame_constants(E, nu)
    a = 1.0 + strain

    def lateral_stress(s):  # P_22 of diag(a, s, s): mu (s - 1/s) + lam J (J - 1) / s
        J = a * s * s
        return mu * (s - 1.0 / s) + lam * J * (J - 1.0) / s

    s = scipy.optimize.brentq(lateral_stress, 1e-3, 1e3, xtol=1e-15, rtol=4 * np.finfo(float).eps)
    J = a * s * s
    return float(s), float(mu * (a - 1.0 / a) + lam * J * (J - 1.0) / a)


# ---------------------------------------------------------------------------- the solve
@dataclass(frozen=True)
class NonlinearSolution:
    """A finite-strain static equilibrium of the Neo-Hookean solid.

    Attributes
    ----------
    displacement : (n, 3) float
        displacement of each mesh node [m] (P2: its vertex dofs)
    reaction_force : (3,) float
        total force the clamps exert on the body [N] (minus the total load; zero for a body held only by self-balancing
        clamps: see :meth:`reaction_in`)
    reactions : (N,) float
        the force each clamped dof exerts [N] (0 on free dofs)
    dof_locations : (N, 3) float
        where each dof sits [m] (a node or, for P2, an edge midpoint)
    dof_components : (N,) int
        the component (0, 1, 2) of each dof
    energy : float
        stored energy minus the work of the (dead) loads at the solution [J]
    dofs : (N,) float
        the whole finite-element vector, in scikit-fem's dof order [m]
    element : str
        ``"P1"`` or ``"P2"``
    newton_iterations : tuple of int
        Newton iterations of each load step taken (the predictor counts as one)
    residual : float
        final ||r_free|| / max(||f_ext||, ||f_int||) [-]
    seconds : float
        wall time of the whole solve [s]
    """

    displacement: np.ndarray
    reaction_force: np.ndarray
    reactions: np.ndarray
    dof_locations: np.ndarray
    dof_components: np.ndarray
    energy: float
    dofs: np.ndarray
    element: str
    newton_iterations: tuple
    residual: float
    seconds: float

    def reaction_in(self, region: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
        """(3,) float -- the total force [N] of the clamped dofs located in ``region`` (a callable on (k, 3)
        points, e.g. :class:`~validation.boundary.Box`): the reaction on one clamped face."""
        inside = np.asarray(region(self.dof_locations), dtype=bool)
        return np.bincount(self.dof_components[inside], weights=self.reactions[inside], minlength=3)


def solve_neo_hookean_static(mesh: TetMesh, material: Any, *, clamp: Any, gravity: np.ndarray | None = None,
                             traction: Any = None, point_loads: Any = None, element: str = "P2", load_steps: int = 4,
                             rtol: float = 1e-10, max_iterations: int = 30) -> NonlinearSolution:
    """Finite-strain static displacement of a clamped tet mesh, Neo-Hookean (module docstring).

    Parameters
    ----------
    mesh : TetMesh
        rest shape; points [m]
    material : (E, nu, density)
        see :func:`validation.fem.elastic_constants`
    clamp, gravity, traction, point_loads : as for :func:`validation.fem.solve_fem_static`; loads
        are dead loads, and prescribed displacements and loads grow together over the load steps
    element : {"P2", "P1"}
    load_steps : int
        load increments, each solved by Newton from the last (an increment whose predictor would invert the material, or
        whose Newton fails, is halved, down to 1/256 of it)
    rtol : float
        Newton stops at ||r_free|| <= rtol max(||f_ext||, ||f_int||)
    max_iterations : int
        Newton iterations allowed per load step

    Returns
    -------
    NonlinearSolution

    Raises
    ------
    SolverNotConverged
        A load step that does not converge (the load may exceed a limit point, or buckle the body).
    """
    element = check_element(element)
    if int(load_steps) < 1:
        raise ValueError(f"load_steps = {load_steps} must be >= 1")
    E, nu, density = elastic_constants(material)
    mu, lam = lame_constants(E, nu)
    start = time.perf_counter()
    fixed = resolve_clamps(mesh, clamp)
    space = skfem_space(mesh, element)
    basis = space.basis
    load = load_vector(space, density, gravity, None, resolve_tractions(mesh, traction),
                       resolve_point_loads(mesh, point_loads))
    is_fixed, prescribed = fixed_vector(space, fixed)
    free = ~is_fixed

    def deformation(u):
        gradient = grad(basis.interpolate(u))
        return gradient + _identity_like(gradient)

    # The forms take the deformation-dependent fields precomputed at the quadrature points: scikit-fem
    # calls a bilinear form once per pair of local basis functions (900 pairs for vector P2).
    @LinearForm
    def internal(v, w):
        return ddot(np.asarray(w["P"]), grad(v))

    @BilinearForm
    def tangent(du, v, w):
        dF, gv, H = grad(du), grad(v), np.asarray(w["H"])
        # (H dF^T H) : gv = (H dF^T) : (gv H^T), as two 3x3 products (a four-operand einsum is 4x slower)
        twisted = ddot(np.einsum("ik...,lk...->il...", H, dF), np.einsum("ij...,lj...->il...", gv, H))
        return mu * ddot(dF, gv) + np.asarray(w["a"]) * twisted + np.asarray(w["b"]) * ddot(H, dF) * ddot(H, gv)

    @Functional
    def stored(w):
        return np.asarray(w["psi"])

    def admissible(u):
        """J > 0 at every quadrature point (ln J is defined)."""
        return bool(np.all(det(deformation(u)) > 0))

    def stiffness(u):
        F = deformation(u)
        J = det(F)
        return asm(tangent, basis, H=transpose(inv(F)), a=mu - lam * J * (J - 1.0), b=lam * (2.0 * J - 1.0) * J).tocsr()

    def potential(u, f):
        return float(asm(stored, basis, psi=neo_hookean_density(deformation(u), mu, lam))) - float(f @ u)

    def residual(u, f):
        return f - asm(internal, basis, P=neo_hookean_stress(deformation(u), mu, lam))

    linear = DirectSolver()

    def newton(u, factor, target):
        """Equilibrium at load ``target`` from the one at ``factor``: a tangent predictor that moves the held
        dofs by their increment and the free ones by the tangent's answer, then Newton with a line search."""
        f = target * load
        K = stiffness(u)
        du = np.zeros_like(u)
        du[is_fixed] = (target - factor) * prescribed[is_fixed]
        rhs = residual(u, f)[free] - K[free][:, is_fixed] @ du[is_fixed]
        du[free], _ = linear.solve(K[free][:, free], rhs)
        u = u + du
        if not admissible(u):
            raise SolverNotConverged("the predictor inverts the material")
        for iteration in range(max_iterations + 1):
            r = residual(u, f)
            scale = max(float(np.linalg.norm(f)), float(np.linalg.norm(f - r)), np.finfo(float).tiny)
            relative = float(np.linalg.norm(r[free])) / scale
            if relative <= rtol:
                return u, iteration + 1, relative
            if iteration == max_iterations or not np.isfinite(relative):
                break
            K = stiffness(u)
            du = np.zeros_like(u)
            du[free], _ = linear.solve(K[free][:, free], r[free])
            u = _line_search(u, du, f, r, potential, residual, admissible, free)
        raise SolverNotConverged(f"relative residual {relative:.3g} after {max_iterations} Newton iterations "
                                 f"(expected <= {rtol:g})")

    u = np.zeros(basis.N)
    iterations, relative = [], 0.0
    factor, increment = 0.0, 1.0 / int(load_steps)
    smallest = increment / 2**8
    while factor < 1.0:
        target = min(1.0, factor + increment)
        try:
            u, count, relative = newton(u, factor, target)
        except SolverNotConverged as error:
            increment /= 2.0
            if increment < smallest:
                raise SolverNotConverged(f"Neo-Hookean solve stuck at load factor {factor:.4g}: {error} even with "
                                         f"a load increment of {2 * increment:.3g} (the load may exceed a limit "
                                         "point or buckle the body)") from error
            logger.debug("Neo-Hookean load increment halved to %.3g at factor %.4g: %s", increment, factor, error)
            continue
        iterations.append(count)
        factor = target
        logger.debug("Neo-Hookean load factor %.4g: %d Newton iterations, residual %.2g", factor, count, relative)
    reactions = np.where(is_fixed, -residual(u, load), 0.0)
    seconds = time.perf_counter() - start
    logger.info("%s Neo-Hookean solve: %d dofs, %d load steps, %d Newton iterations, %.2f s", element, basis.N,
                len(iterations), sum(iterations), seconds)
    return NonlinearSolution(u[space.node_dofs], np.bincount(space.components, weights=reactions, minlength=3),
                             reactions, basis.doflocs.T.copy(), space.components, potential(u, load), u, element,
                             tuple(iterations), relative, seconds)


def _line_search(u, du, f, r, potential, residual, admissible, free):
    """u + alpha du for the first alpha = 1, 1/2, ... that keeps J > 0 and lowers the energy (or, where the
    energy change drowns in round-off near the solution, the residual); SolverNotConverged if none does."""
    merit = potential(u, f)
    slope = float(r[free] @ du[free])  # -d(energy)/d(alpha) at alpha = 0
    norm = float(np.linalg.norm(r[free]))
    alpha = 1.0
    while alpha >= 2.0**-30:
        trial = u + alpha * du
        if admissible(trial):
            value = potential(trial, f)
            if value <= merit - 1e-4 * alpha * slope:
                return trial
            if abs(value - merit) <= 1e-12 * (abs(value) + abs(merit)) and \
                    np.linalg.norm(residual(trial, f)[free]) < norm:
                return trial
        alpha *= 0.5
    raise SolverNotConverged("Neo-Hookean Newton: no step along the Newton direction lowers the energy "
                             "(the tangent may be indefinite: a limit point or buckling)")
