"""Static equilibrium of a scene: springs, the scene's loads and its pins.

:func:`solve_static` finds positions x of the free nodes where all forces balance,
F(x) = spring forces + scene forces (at zero velocity) = 0, by Newton's method on the total
potential energy Pi(x) = spring energy + the potentials of the scene's loads (``Gravity``...),
with a backtracking (Armijo) line search on Pi and a Levenberg-style shift when a step fails.

Newton step: K dx = F with K = -dF/dx over the free nodes (pinned nodes eliminated, held where
the pins put them at time ``t``). By default K is the exact Hessian of the spring energy
(``clamp_compression=False``): quadratic convergence near the solution, where K is positive
definite for any stable equilibrium (measured on a pinned rubber beam sagging 29 cm: 8 Newton
iterations to 1e-12). Far from it K may be indefinite (compressed springs); CG then reports
non-positive curvature and the step is retried with a shift (below). ``clamp_compression=True``
uses the clamped stiffness of the implicit step instead: positive semi-definite always, but a
quasi-Newton step that converges only linearly where springs are compressed (35 iterations to
1e-8 on the same beam).

While tets of the model's mesh are inverted (signed volume <= 0), the step takes the projected (clamped) stiffness
from the start: there the exact Hessian is strongly indefinite, and its Newton steps, even those that lower the
energy, can end at a stationary point with tets still inverted (measured: the smoothed rung's cube at nu 0.49 with
a face snapped through two layers of cells converged in 51 iterations to a state with 2 inverted tets and 7.8 kJ of
energy left; the projected steps bring it back to its rest shape, after which the exact Hessian's steps converge
quadratically).

Where K is singular (e.g. a string at rest has no transverse stiffness) or a step does not lower
the energy, the step is retried with the projected (clamped) stiffness, which is positive
semi-definite, plus mu d I (d the mean diagonal of K), mu growing tenfold from 1e-8, and mu shrinks
again after successful steps.

Linear solves use :mod:`volspring.solvers` (AMG-CG by default, to ``linear_rtol``: an inexact
Newton method); the AMG hierarchy is rebuilt for every Newton step since the stiffness changes
much more between Newton iterates than between time steps.

Convergence: ||F_free|| <= rtol ||load_free||, where the load is everything but the springs (the
scene's forces at x), or down to the round-off floor of the spring forces, whichever is larger:
the positions carry an error of eps |x|, so each node's force, a sum of stiffness times
displacement terms, cannot be resolved below eps |x|_max ||sum of its stiffnesses|| (the trace of its
diagonal stiffness block: k per spring, 2 mu V |g|^2 per tet corner) (measured: Newton stalls below this
floor on a stiff beam, E = 1e10 to 1e14 Pa, and on a strand of hair 10 m from the origin, where
rtol = 1e-8 asked for the impossible and the solve was reported as failed). A scene without pins has no static equilibrium under a net load (the body
would fall), and only one up to a rigid motion without: :func:`solve_static` refuses it.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from meshing.geometry import rigid_body_modes
from volspring.assembly import BlockPattern, eliminate_held, held_unknowns
from volspring.diagnostics import tet_inversion
from volspring.errors import SolverNotConverged
from volspring.solvers import make_linear_solver
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from volspring.scene import Scene

__all__ = ["StaticResult", "solve_static"]

logger = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class StaticResult:
    """The answer of :func:`solve_static`.

    Parameters
    ----------
    x : (n, 3) float
        equilibrium positions [m]
    residual : float
        ||F_free|| / ||load_free|| at x [-]
    iterations : int
        Newton iterations taken
    energy : float
        total potential energy at x [J]
    residual_history : (iterations + 1,) float
        relative residual before each iteration and at the end
    linear_iterations : tuple of int
        CG iterations of each Newton step (0 for the direct solver)
    """

    x: np.ndarray
    residual: float
    iterations: int
    energy: float
    residual_history: np.ndarray
    linear_iterations: tuple


def _potential(scene, x, t, conservative):
    if conservative:
        return scene.potential_energy(x, t)
    return None


def solve_static(scene: Scene, *, x0: np.ndarray | None = None, t: float = 0.0, rtol: float = 1e-8,
                 max_iterations: int = 50, solver: str = "amg", linear_rtol: float = 1e-4,
                 clamp_compression: bool = False) -> StaticResult:
    """Static equilibrium of ``scene`` under its loads and pins (see the module docstring).

    Parameters
    ----------
    scene : Scene
        model, loads (forces with ``potential_energy`` enter the line search merit; with a non-conservative force the
        merit is ||F|| instead) and pins
    x0 : (n, 3) float, optional
        starting positions [m]; the rest positions by default
    t : float
        time at which loads and pin positions are evaluated [s]
    rtol : float
        target ||F_free|| / ||load_free|| (raised to the round-off floor of the spring forces where that is larger; see
        the module docstring)
    max_iterations : int
        Newton iterations at most
    solver : {"amg", "jacobi", "direct"}
        linear solver of the Newton steps
    linear_rtol : float
        CG tolerance of each Newton step (inexact Newton)
    clamp_compression : bool
        use the clamped (positive semi-definite) stiffness instead of the exact Hessian (a quasi-Newton step; see the
        module docstring)

    Returns
    -------
    StaticResult

    Raises
    ------
    ValueError
        If the scene has no pins (no unique equilibrium).
    SolverNotConverged
        If ``max_iterations`` pass, or no step lowers the energy, naming the residual reached.

    Examples
    --------
    >>> from volspring import Gravity, Pins, Scene, Model
    >>> string = Model.from_arrays([[0, 0, 0], [0, 0, -1]], [1.0, 1.0], [[0, 1]], stiffness=100.0)
    >>> scene = Scene(string, forces=[Gravity()], pins=Pins([0]))
    >>> result = solve_static(scene, solver="direct")
    >>> round(float(result.x[1, 2]), 6)  # -1 - m g / k
    -1.0981
    """
    model = scene.model
    n = model.node_count
    x = np.array(model.rest_positions if x0 is None else x0, dtype=np.float64)
    if x.shape != (n, 3) or not np.isfinite(x).all():
        raise ValueError(f"x0 must be finite with shape ({n}, 3), got shape {x.shape}")
    zero = np.zeros_like(x)
    if not scene.all_supports:
        net = scene.external_forces(x, zero, t).sum(axis=0)
        if np.linalg.norm(net) > 0:
            raise ValueError(f"the scene has no pins: under the net load {np.round(net, 6).tolist()} N the body "
                             f"would fall with acceleration {np.round(net / model.total_mass, 6).tolist()} m/s^2 "
                             "and has no static equilibrium; pin some nodes")
        raise ValueError("the scene has no pins: its equilibrium is defined only up to a rigid motion "
                         "(the stiffness matrix is singular); pin at least three non-collinear nodes")
    scene.enforce_supports(x, zero.copy(), t)
    pattern = BlockPattern(model, scene.free)
    held = held_unknowns(pattern, scene.held) if scene.partly_held else None

    def restrict(vectors):
        """The free unknowns' rows of a per-node array, 0 on held components."""
        rows = pattern.restrict(vectors)
        if held is not None:
            rows[held] = 0.0
        return rows
    linear = make_linear_solver(solver, **({} if solver == "direct" else {"rtol": linear_rtol, "maxiter": 2000}))
    conservative = scene.conservative

    def evaluate(positions):
        springs = pattern.linearize(positions, stiffness_scale=1.0, clamp_compression=clamp_compression)
        load = scene.external_forces(positions, zero, t)
        return springs, load, springs.forces + load

    springs, load, force = evaluate(x)
    scale = float(np.linalg.norm(restrict(load)))
    if scale == 0.0:
        scale = max(float(np.linalg.norm(restrict(springs.forces))), np.finfo(float).tiny)
    residual = restrict(force)
    history = [float(np.linalg.norm(residual)) / scale]
    target = max(rtol, _roundoff_floor(pattern, x) / scale)
    if target > rtol:
        logger.info("static solve: rtol %.3g is below the round-off floor of the spring forces; converging to %.3g",
                    rtol, target)
    merit = _potential(scene, x, t, conservative)
    shift, linear_iterations = 0.0, []
    for iteration in range(max_iterations):
        if history[-1] <= target:
            break
        extra = _force_stiffness(scene, pattern, x, t)
        # |diagonal|: far from equilibrium the exact Hessian's diagonal can be negative, and a shift by a
        # negative mean would make the system less definite, not more.
        mean_diagonal = float(np.abs(pattern.matrix(springs).diagonal()).mean())
        tangent = springs
        if not clamp_compression and tet_inversion(model, x).count:  # the projected stiffness while tets are inverted
            tangent = pattern.linearize(x, stiffness_scale=1.0, clamp_compression=True)
        for attempt in range(13):
            step, info = _newton_step(linear, pattern, tangent, extra, residual, shift * mean_diagonal, x, held)
            accepted = step is not None and _line_search(scene, pattern, restrict, evaluate, x, step, residual, merit, t,
                                                         conservative)
            if accepted:
                break
            if tangent is springs and not clamp_compression:
                # The exact Hessian's step failed (indefinite far from equilibrium, e.g. at inverted tets):
                # retry with the projected stiffness, positive semi-definite, at the same shift first.
                tangent = pattern.linearize(x, stiffness_scale=1.0, clamp_compression=True)
                continue
            shift = max(1e-8, 10.0 * shift)
            logger.debug("static Newton iteration %d: step rejected, shift -> %.1e", iteration, shift)
        else:
            raise SolverNotConverged(f"static solve: no step lowers the energy at iteration {iteration}, relative "
                                     f"force residual {history[-1]:.3g} (expected <= {rtol:g}); the problem may "
                                     "be singular (too few pins) or unstable (buckling)")
        linear_iterations.append(info.iterations)
        x, springs, load, force, merit = accepted
        residual = restrict(force)
        history.append(float(np.linalg.norm(residual)) / scale)
        shift = shift / 10.0 if shift > 1e-8 else 0.0
    if history[-1] > target:
        raise SolverNotConverged(f"static solve did not converge in {max_iterations} Newton iterations: relative "
                                 f"force residual {history[-1]:.3g}, expected <= {target:.3g}")
    energy = scene.potential_energy(x, t)
    return StaticResult(x, history[-1], len(history) - 1, float(energy), np.array(history), tuple(linear_iterations))


def _force_stiffness(scene, pattern, x, t):
    """-dF/dx of the scene's forces over the free unknowns, or None."""
    dfdx, _ = scene.external_jacobian(x, np.zeros_like(x), t)
    if dfdx is None:
        return None
    dofs = pattern.free_dofs()
    return sp.csr_matrix(-dfdx)[dofs][:, dofs]


def _roundoff_floor(pattern, x) -> float:
    """eps |x|_max ||per free node, the trace of its diagonal stiffness block at rest|| [N]: the force resolution.

    Positions carry an error of eps |x|, so every element's force an error of its stiffness times that (k eps |x|
    for a spring, whatever its rest length; 2 mu V |g|^2 eps |x| for a tet corner). The trace of a node's
    diagonal block at rest sums those stiffnesses (k per spring), for every element set alike; at rest, because
    a crushed starting shape can make the current one arbitrarily large.
    """
    rest = pattern.linearize(pattern.model.rest_positions, stiffness_scale=1.0)
    diagonal = np.abs(pattern.matrix(rest).diagonal()).reshape(-1, 3).sum(axis=1)
    position = float(np.abs(x[pattern.free_nodes]).max()) if pattern.free_count else 0.0
    return float(np.finfo(float).eps * np.sqrt(3.0) * position * np.linalg.norm(diagonal))


def _newton_step(linear, pattern, linearization, extra, residual, shift, x, held=None):
    """Solve (K + shift I) dx = F; (None, None) when the solve fails (singular or indefinite K)."""
    stiffness = pattern.matrix(linearization, np.full(pattern.free_count, shift) if shift else None)
    if held is not None:  # the residual is 0 on held components, and so is the step
        stiffness, _, extra = eliminate_held(pattern, stiffness, held, extra=extra)
    try:
        if linear.method == "amg":
            linear.build(stiffness, rigid_body_modes(x[pattern.free_nodes]))
        step, info = linear.solve(stiffness, residual, extra=extra)
        if held is not None:
            step[held] = 0.0
        return step, info
    except (SolverNotConverged, np.linalg.LinAlgError, ArithmeticError, RuntimeError) as error:
        logger.debug("static Newton step failed (%s)", error)
        return None, None


def _line_search(scene, pattern, restrict, evaluate, x, step, residual, merit, t, conservative):
    """Backtracking from the full step; the accepted (x, springs, load, force, merit) or None."""
    step_nodes = np.zeros_like(x)
    step_nodes[pattern.free_nodes] = step.reshape(-1, 3)
    slope = float(np.dot(residual, step))  # -dPi/dalpha at alpha = 0
    if conservative and not slope > 0:
        return None
    norm = float(np.linalg.norm(residual))
    alpha = 1.0
    while alpha >= 1e-4:
        trial = x + alpha * step_nodes
        try:
            springs, load, force = evaluate(trial)
        except FloatingPointError:  # a spring collapsed to zero length
            alpha *= 0.5
            continue
        if conservative:
            value = scene.potential_energy(trial, t)
            if value <= merit - 1e-4 * alpha * slope:
                return trial, springs, load, force, value
            # Near the solution the energy change drowns in round-off of the energy itself:
            # there, a lower force residual decides.
            if abs(value - merit) <= 1e-12 * (abs(value) + abs(merit)) and \
                    np.linalg.norm(restrict(force)) < norm:
                return trial, springs, load, force, value
        elif np.linalg.norm(restrict(force)) <= (1.0 - 1e-4 * alpha) * norm:
            return trial, springs, load, force, None
        alpha *= 0.5
    return None
