"""Implicit (backward) Euler, linearised once per step (Baraff & Witkin 1998), with optional Newton.

One step of size h from (x0, v0) solves, over the free nodes only,

    (M - h dF/dv - h^2 dF/dx) dv = h (f0 + h dF/dx v0) - A_fp dv_p,    v1 = v0 + dv,  x1 = x0 + h v1,

with dF/dx from the spring stiffness blocks (transverse term clamped under compression so the
matrix stays positive definite), dF/dv from the dampers, plus the Jacobians of scene forces that
provide one (e.g. ``Drag``); forces without one (gravity, fields) enter through f0 only.
Pinned and prescribed nodes are eliminated: their velocity change dv_p is set by where the pins
must be at t + h, and their coupling moves to the right-hand side. Every mode is damped by
1/sqrt(1 + h^2 omega^2) per step, so the scheme is stable for any h (first order accurate).

Linear solve. The default ``solver="amg"`` is CG preconditioned with smoothed aggregation on
the 3x3 block matrix with the rigid-body modes of the free nodes as near-null space
(:mod:`volspring.solvers`), started from the combination of the last :data:`WARM_START` steps' velocity changes
closest to this step's solution (in the system's energy norm). ``rtol=1e-3`` by default:
the linearisation itself makes an O(h^2) error per step, so a linear residual of 1e-3 of the
right-hand side is already below the scheme's own error at any step size where implicit Euler
is used for its stability; the error does not accumulate into instability because every step
solves for a new dv from the actual state. Use ``rtol=1e-6`` or ``solver="direct"`` for
checking, and ``newton_iterations`` for the fully implicit answer.

Matrix-free sets. A set that couples each node's 2-ring (the smoothed rung's nodal term,
:class:`~volspring.elements.NodalStrain`) is not assembled by the AMG solver: CG applies its
stiffness as a product (two sparse products per iteration, no 3x3 blocks computed per step), and
the hierarchy is built from the assembled sets plus the set's 1-ring stand-in
(:meth:`~volspring.elements.NodalStrain.preconditioner_blocks`). The answer is the same system's;
only the preconditioner differs. ``matrix_free=False`` assembles everything (as do the direct and
Jacobi solvers, and ``clamp_compression=False``, whose exact curvature has no product form).

Hierarchy policy. The AMG hierarchy is built from the step's own matrix and reused while it
still works. It is rebuilt at the start of a step when

- there is none yet, or the pattern changed (another model or pin set);
- the previous step needed more than ``rebuild_growth`` x max(5, n0) CG iterations, where n0
  is the iteration count of the step right after the last build;
- ``rebuild_every`` steps passed since the last build (off by default);
- dt differs from the build's dt by more than 25 %.

What the policy reads is kept in ``state.memory`` (keys ``implicit_euler.*``): the last velocity changes
(``dv_history``, what CG's first guess is made from), the last iteration count, and the step, time, dt, positions
and velocities at which the hierarchy was built, so a run resumed from a checkpoint rebuilds the very same
hierarchy from those positions and continues bit-identically.
"""

from __future__ import annotations

import logging
import math
import operator
import time
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import aslinearoperator

from meshing.geometry import rigid_body_modes
from volspring.assembly import BlockPattern, ModelLinearization, eliminate_held, held_unknowns
from volspring.integrators.base import Integrator
from volspring.integrators.cache import SolverCache
from volspring.scene import Scene, State
from volspring.solvers import LINEAR_SOLVERS, SolveInfo, make_linear_solver
from volspring.solvers.krylov import Deflation, times
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from scipy import sparse
    from scipy.sparse.linalg import LinearOperator
    from volspring.solvers.krylov import _LinearSolver

__all__ = ["ImplicitEuler", "ImplicitStepInfo", "SolverCache"]

logger = logging.getLogger(__name__)

_KEY = "implicit_euler."
#: The scene forces' Jacobian (contact) must reach more than this share of the unknowns beyond what it reached at
#: the last build, besides growing or shrinking by ``rebuild_growth``, to rebuild the AMG hierarchy: a resting
#: contact flickering between no and a few contacts does not rebuild every step (``benchmarks/bench_contact_cg.py``).
CONTACT_REBUILD_SHARE = 0.01
#: CG's first guess is the combination of this many previous velocity changes that is closest to the step's
#: solution in the system's energy norm (Fischer 1998: projection onto previous solutions). On the README beam
#: (10k nodes, dt = 0.01 s, steps 11-40 from rest) CG then needs 2.1 iterations a step and the step costs 41 mat-vecs,
#: against 7.9 and 81 from zero, 5.8 and 66 from the last change alone, 2.3 and 38 from three changes, 1.8 and 45
#: from eight (each change costs one product with the system; ``python benchmarks/bench_warm_start.py``; the mat-vec
#: figures vary by a few from run to run). Five rather than three: fewer iterations in the first steps of a motion.
#: The guess it replaces, the linear extrapolation of the last two changes, needed 5.7 iterations on the same states.
WARM_START = 5
#: Directions of the previous changes whose energy is below this share of the largest are left out of the guess
#: (nearly parallel changes: a rest state, a uniform free fall).
WARM_START_CUTOFF = 1e-12


@dataclass(frozen=True)
class ImplicitStepInfo:
    """What one implicit step did (``integrator.last_solve``).

    Parameters
    ----------
    iterations : int
        CG iterations of the linearised solve (0 for the direct solver)
    residual : float
        its relative residual [-]
    solves : tuple of SolveInfo
        the linearised solve, then one per Newton iteration
    newton_residuals : (k + 1,) float
        ||M (v1 - v0) - h F(x1, v1, t + h)|| over the free nodes [N s] after the linearised solve and after each Newton
        iteration
    forces_seconds : float
        spring forces with their Jacobian blocks (one pass) and scene forces [s]
    assembly_seconds : float
        scene-force Jacobians, refill of the matrix, right-hand side [s]
    setup_seconds : float
        AMG hierarchy (re)build in this step, 0 when reused [s]
    solve_seconds : float
        linear solves (CG iterations or triangular solves) [s]
    rebuilt : bool
        the AMG hierarchy was (re)built in this step
    """

    iterations: int
    residual: float
    solves: tuple
    newton_residuals: np.ndarray = field(default_factory=lambda: np.zeros(0))
    forces_seconds: float = 0.0
    assembly_seconds: float = 0.0
    setup_seconds: float = 0.0
    solve_seconds: float = 0.0
    rebuilt: bool = False


@dataclass
class _System:
    """The assembled implicit system at one (x, v, t, h) over the free nodes."""

    matrix: sp.bsr_matrix
    extra: sp.csr_matrix | None
    springs: ModelLinearization | None  # every element set's forces and blocks h^2 K + h C (None once used)
    forces: np.ndarray  # (n, 3) all forces at (x, v, t) [N]
    assembly_seconds: float
    extra_full: sp.csr_matrix | None  # -h dF/dv - h^2 dF/dx of scene forces, all unknowns
    extra_dfdx: sp.csr_matrix | None  # dF/dx of scene forces, all unknowns
    held: np.ndarray | None = None  # (3f,) bool held unknowns of partly held nodes, eliminated
    held_rhs: np.ndarray | None = None  # (3f,) what the held values put into the right-hand side (0 on held rows)
    operator: LinearOperator | None = None  # the sets applied as products (held unknowns masked), or None
    preconditioner_matrix: Callable[[], sp.bsr_matrix] | None = None  # () -> the matrix with their stand-in blocks
    operator_diagonal: Callable[[], np.ndarray | None] | None = None  # () -> (f, 3, 3) the operator's diagonal blocks
    folded: np.ndarray | None = None  # (f, 3) the scene forces' diagonal Jacobian term, folded into the matrix
    touched: int = 0  # free unknowns on which the scene forces' Jacobian has a row (contact's grow and shrink)
    stiffness_times: np.ndarray | None = None  # (n, 3) the element sets' dF/dx @ u for _assemble's ``times``

    def with_held(self, b) -> np.ndarray:
        """The right-hand side ``b`` with the held unknowns' rows set (see :func:`eliminate_held`)."""
        if self.held is None:
            return b
        b = b.copy()
        b[self.held] = 0.0
        return b + self.held_rhs

    @cached_property
    def stand_in(self) -> sp.bsr_matrix:
        """The matrix, with the stand-in blocks of the sets applied as products (what preconditioning sees)."""
        return self.matrix if self.preconditioner_matrix is None else self.preconditioner_matrix()

    @cached_property
    def whole(self) -> sp.bsr_matrix:
        """The matrix with the extra term added, BSR with 3x3 blocks (what the AMG hierarchy is given);
        with sets applied as products, their stand-in blocks instead of them."""
        return self.stand_in if self.extra is None else sp.bsr_matrix(self.stand_in + self.extra, blocksize=(3, 3))

    @cached_property
    def exact_diagonal(self) -> np.ndarray | None:
        """(f, 3, 3) -- the diagonal blocks of the system CG iterates on (matrix, extra term and the sets applied as
        products), where the AMG hierarchy is built from a stand-in for it; None where it is not (every set
        assembled) or a set does not give its diagonal."""
        if self.operator_diagonal is None:
            return None
        applied = self.operator_diagonal()
        if applied is None:
            return None
        from pyamg.util.utils import get_block_diag

        if self.held is not None:  # the operator is masked on the held unknowns' rows and columns (_assemble)
            keep = (~self.held).reshape(-1, 3).astype(np.float64)
            applied = applied * (keep[:, :, None] * keep[:, None, :])
        whole = self.matrix if self.extra is None else sp.bsr_matrix(self.matrix + self.extra, blocksize=(3, 3))
        return get_block_diag(whole, blocksize=3, inv_flag=False) + applied

    @property
    def products(self):
        """What CG adds to ``matrix @ p``: the extra term and the sets applied as products (or None)."""
        if self.operator is None:
            return self.extra
        if self.extra is None:
            return self.operator
        return self.operator + aslinearoperator(self.extra)


class ImplicitEuler(Integrator):
    """Linearised backward Euler with an AMG-preconditioned CG (or Jacobi-CG, or direct) solve.

    Parameters
    ----------
    solver : {"amg", "jacobi", "direct"}
        linear solver (see :mod:`volspring.solvers`)
    rtol : float
        CG relative residual target (see the module docstring for why 1e-3)
    maxiter : int
        CG iteration cap per solve
    newton_iterations : int
        extra Newton iterations on the nonlinear backward Euler equation M (v1 - v0) = h F(x0 + h v1, v1, t + h) after
        the linearised step (0: Baraff-Witkin)
    rebuild_growth : float
        rebuild the AMG hierarchy when the iteration count exceeds this factor times max(5, the count right after the
        last build)
    rebuild_every : int, optional
        also rebuild every this many steps
    clamp_compression : bool
        clamp the transverse stiffness of compressed springs at 0
    on_failure : {"raise", "warn"}
        what a solve that stops short of ``rtol`` does
    smoother : {"gauss_seidel", "block_gauss_seidel", "jacobi"}
        AMG smoother (:class:`~volspring.solvers.AMGConjugateGradient`)
    matrix_free : bool
        apply the sets that offer it as products (see the module docstring)
    warm_start : int
        how many previous velocity changes CG's first guess is made from (:data:`WARM_START`; 0: start from zero)
    timer : callable
        ``timer() -> seconds`` behind the step's timings and the linear solver's (default :func:`time.perf_counter`)

    Attributes
    ----------
    last_solve : ImplicitStepInfo or None
        what the last step did

    Examples
    --------
    >>> import numpy as np
    >>> from volspring import Gravity, Pins, Scene, Model
    >>> from volspring.integrators.implicit import ImplicitEuler
    >>> string = Model.from_arrays([[0, 0, 0], [0, 0, -1]], [1.0, 1.0], [[0, 1]], stiffness=1e6)
    >>> scene = Scene(string, forces=[Gravity()], pins=Pins([0]))
    >>> integrator = ImplicitEuler(solver="direct")
    >>> state = scene.initial_state()
    >>> for _ in range(200):
    ...     state = integrator.step(scene, state, 0.01)
    >>> round(float(state.x[1, 2]) + 1.0, 8)  # static extension m g / k
    -9.81e-06
    """

    name = "implicit_euler"
    order = 1
    explicit = False
    stability_limit = math.inf

    def __init__(self, *, solver: str = "amg", rtol: float = 1e-3, maxiter: int = 500, newton_iterations: int = 0,
                 rebuild_growth: float = 2.0, rebuild_every: int | None = None, clamp_compression: bool = True,
                 on_failure: str = "raise", smoother: str = "gauss_seidel", matrix_free: bool = True,
                 warm_start: int = WARM_START, timer: Callable[[], float] = time.perf_counter):
        if solver not in LINEAR_SOLVERS:
            raise ValueError(f"unknown solver {solver!r}; known: {', '.join(LINEAR_SOLVERS)}")
        if int(newton_iterations) < 0:
            raise ValueError(f"newton_iterations = {newton_iterations!r} is not >= 0")
        if not rebuild_growth > 1:
            raise ValueError(f"rebuild_growth = {rebuild_growth!r} is not > 1")
        if rebuild_every is not None and int(rebuild_every) < 1:
            raise ValueError(f"rebuild_every = {rebuild_every!r} is not >= 1")
        try:
            depth = -1 if isinstance(warm_start, bool) else operator.index(warm_start)  # ints, numpy integers
        except TypeError:
            depth = -1
        if depth < 0:
            raise ValueError(f"warm_start = {warm_start!r} is not a whole number >= 0 (previous steps to guess from)")
        options: dict[str, Any] = {"on_failure": on_failure}
        if solver != "direct":
            options.update(rtol=rtol, maxiter=maxiter)
        if solver == "amg":
            options.update(smoother=smoother)
        self._solver_options = options
        self.timer = timer
        self.method, self.rtol = solver, float(rtol)
        self.newton_iterations = int(newton_iterations)
        self.rebuild_growth = float(rebuild_growth)
        self.rebuild_every = None if rebuild_every is None else int(rebuild_every)
        self.clamp_compression = bool(clamp_compression)
        self.warm_start = depth
        self.matrix_free = bool(matrix_free) and solver == "amg" and self.clamp_compression
        self.last_solve: ImplicitStepInfo | None = None
        self.cache = self.new_cache()

    def new_cache(self) -> SolverCache:
        """An empty :class:`SolverCache` for one scene (see :mod:`volspring.integrators.cache`)."""
        return SolverCache(make_linear_solver(self.method, timer=self.timer, **self._solver_options),
                           matrix_free=self.matrix_free)

    @property
    def solver(self) -> _LinearSolver:
        """The linear solver of the default cache."""
        return self.cache.solver

    def __repr__(self) -> str:
        return (f"ImplicitEuler(solver={self.method!r}, rtol={self.rtol:g}, "
                f"newton_iterations={self.newton_iterations})")

    # ------------------------------------------------------------------ assembly
    def pattern(self, scene: Scene, cache: SolverCache | None = None) -> BlockPattern:
        """The block pattern for this scene's model and supports, built once and cached."""
        return (self.cache if cache is None else cache).pattern_for(scene)

    def _assemble(self, scene, pattern, x, v, t, h, prescribed=None, times=None) -> _System:
        """Forces and the system matrix at (x, v, t) for step h (and the element sets' dF/dx @ ``times``, (n, 3), when
        it is given: the step's right-hand side).

        The element sets' forces come out of the same pass as their blocks
        (:meth:`BlockPattern.linearize`), then the scene adds the external forces, so ``forces``
        equals ``scene.forces_at``. Held components of partly held nodes are eliminated
        (:func:`eliminate_held`), with ``prescribed`` (n, 3), the velocity change they must make,
        moved into the right-hand side.
        """
        springs = pattern.linearize(x, v, stiffness_scale=h * h, damping_scale=h,
                                    clamp_compression=self.clamp_compression)
        forces = scene.external_forces(x, v, t, out=springs.forces)
        clock = self.timer()
        # Before the matrix: the product's temporaries and the assembled blocks are then never alive at once (the
        # step's peak memory, at the matrix's assembly; 0.4 KiB per node less for the springs at 45k nodes).
        stiffness_times = None if times is None else pattern.dfdx_times(springs, times)
        dfdx, dfdv = scene.external_jacobian(x, v, t)
        diagonal = scene.model.masses[pattern.free_nodes]
        extra = extra_full = folded = None
        touched = 0
        if dfdx is not None or dfdv is not None:
            terms = [-h * dfdv if dfdv is not None else None, -h * h * dfdx if dfdx is not None else None]
            extra_full = sp.csr_matrix(sum(term for term in terms if term is not None))
            dofs = pattern.free_dofs()
            restricted = extra_full[dofs][:, dofs].tocoo()
            touched = int(np.count_nonzero(np.bincount(restricted.row, minlength=pattern.size)))
            if (restricted.row == restricted.col).all():
                # A diagonal term (e.g. drag) is folded into the diagonal blocks, so the AMG
                # hierarchy sees it too and CG pays nothing extra.
                folded = np.zeros(pattern.size)
                np.add.at(folded, restricted.row, restricted.data)
                folded = folded.reshape(-1, 3)
                diagonal = diagonal[:, None] + folded
            else:
                extra = restricted.tocsr()
        # Where every set is applied as a product (the smoothed rung), CG multiplies the matrix's diagonal blocks alone
        # (below): made so outright, unless the held unknowns' elimination needs the pattern.
        whole_pattern = pattern.assembles or scene.partly_held
        matrix = pattern.matrix(springs, diagonal) if whole_pattern else pattern.diagonal_matrix(diagonal)
        operator = pattern.operator(springs)

        def preconditioner():  # the matrix with the stand-in blocks of the sets applied as products
            standing_in = pattern.matrix(springs, diagonal, preconditioner=True)
            return standing_in if held is None else eliminate_held(pattern, standing_in, held)[0]

        def operator_diagonal():  # the diagonal blocks of the sets applied as products
            return pattern.operator_diagonal(springs)

        held = held_rhs = None
        if scene.partly_held:
            held = held_unknowns(pattern, scene.held)
            values = np.zeros(pattern.size) if prescribed is None else pattern.restrict(prescribed) * held
            coupling = matrix @ values + (extra @ values if extra is not None else 0.0)
            if operator is not None:
                coupling = coupling + operator @ values
                keep = (~held).astype(np.float64)
                operator = aslinearoperator(sp.diags(keep)) @ operator @ aslinearoperator(sp.diags(keep))
            matrix, _, extra = eliminate_held(pattern, matrix, held, extra=extra)
            # The held unknowns solve to 0 and are set outright (v1 already holds them).
            held_rhs = np.where(held, 0.0, -coupling)
        if not pattern.assembles and whole_pattern:
            # Every set is applied as a product (the smoothed rung): the matrix is the masses and diagonal scene terms
            # amid the stand-in's pattern of zero blocks, so CG multiplies its diagonal blocks alone (the same bits:
            # a zero block adds exact zeros; on the README beam 0.05 against 0.51 ms a product with scipy).
            matrix = pattern.diagonal_part(matrix)
        return _System(matrix, extra, springs, forces, self.timer() - clock, extra_full,
                       None if dfdx is None else sp.csr_matrix(dfdx), held, held_rhs, operator,
                       None if operator is None else preconditioner, None if operator is None else operator_diagonal,
                       folded, touched, stiffness_times)

    def linear_system(self, scene: Scene, state: State,
                      dt: float) -> tuple[sparse.spmatrix, sparse.spmatrix | None, BlockPattern]:
        """The linearised system of one step from ``state``, over the free unknowns.

        Returns
        -------
        matrix : (3f, 3f) BSR
            M - h dF/dv - h^2 dF/dx of every element set, assembled (also those the step applies as products), plus
            diagonal scene terms
        extra : (3f, 3f) CSR or None
            non-diagonal scene-force terms, applied separately
        pattern : BlockPattern
            numbering of the unknowns (``pattern.free_nodes``)
        """
        pattern = self.pattern(scene)
        if pattern.has_operator:
            pattern = BlockPattern(scene.model, scene.free)
        system = self._assemble(scene, pattern, state.x, state.v, state.t, float(dt))
        return system.matrix, system.extra, pattern

    # ------------------------------------------------------------------ hierarchy policy
    def _needs_rebuild(self, memory, pattern, step, dt, touched=0) -> str:
        """Why the hierarchy must be rebuilt at the start of this step ('' when it need not); ``touched``: the free
        unknowns the scene forces' Jacobian reaches in this step (:attr:`_System.touched`)."""
        if _KEY + "amg_step" not in memory:
            return "first build"
        if memory[_KEY + "amg_x"].shape != (pattern.model.node_count, 3) or \
                int(memory[_KEY + "amg_size"]) != pattern.size:
            return "pattern changed"
        reference = max(5, int(memory[_KEY + "amg_iterations"]))
        if int(memory.get(_KEY + "iterations", 0)) > self.rebuild_growth * reference:
            return f"iterations {int(memory[_KEY + 'iterations'])} > {self.rebuild_growth:g} x {reference}"
        if self.rebuild_every is not None and step - int(memory[_KEY + "amg_step"]) >= self.rebuild_every:
            return f"every {self.rebuild_every} steps"
        if not 0.8 <= dt / float(memory[_KEY + "amg_dt"]) <= 1.25:
            return f"dt changed from {float(memory[_KEY + 'amg_dt']):.3g} s to {dt:.3g} s"
        # Contact starting, ending, spreading or receding: a hierarchy built without the contact stiffness (or
        # with contact that is gone) preconditions poorly even with its levels updated (the coarsest keeps the build's).
        at_build = int(memory.get(_KEY + "amg_touched", 0))
        grown = touched > self.rebuild_growth * at_build or at_build > self.rebuild_growth * touched
        if grown and abs(touched - at_build) > CONTACT_REBUILD_SHARE * pattern.size:
            return f"the scene forces' Jacobian reaches {touched} unknowns, {at_build} at the build"
        return ""

    def _build(self, cache, pattern, system, x, step, t, dt, v):
        # A Jacobian outside the block pattern (contact couples nodes of different bodies) goes into
        # the hierarchy too, so that the preconditioner sees the contact stiffness CG iterates on.
        # Aggregates from the couplings of the system without it, though: see AMGConjugateGradient.build.
        seconds = cache.solver.build(system.whole, rigid_body_modes(x[pattern.free_nodes]),
                                     aggregation=None if system.extra is None else system.stand_in,
                                     exact_diagonal=system.exact_diagonal)
        cache.built(pattern, step, t, dt, x, v)
        # What the scene forces' Jacobian was at the build: the steps that reuse the hierarchy give it their change
        # (_solve; the stand-in blocks of sets applied as products, a linearisation of their own, stay the build's).
        cache.folded, cache.extra = system.folded, system.extra
        return seconds

    # ------------------------------------------------------------------ the step
    def advance(self, scene: Scene, state: State, dt: float, cache: SolverCache | None = None) -> State:
        h = float(dt)
        model = scene.model
        cache = self.cache if cache is None else cache
        memory = dict(state.memory)
        x0, v0, t0 = state.x, state.v, state.t
        pattern = cache.pattern_for(scene)

        # Velocity change of the held components: where the supports must be at t + h.
        v1 = v0.copy()
        dv_prescribed = np.zeros_like(v0)
        if scene.all_supports:
            held = scene.held
            target, _ = scene.support_motion(t0 + h)
            v1[held] = (target[held] - x0[held]) / h
            dv_prescribed[held] = v1[held] - v0[held]
        clock = self.timer()
        system = self._assemble(scene, pattern, x0, v0, t0, h, dv_prescribed, times=v0)
        f0 = system.forces
        forces_seconds = self.timer() - clock - system.assembly_seconds
        clock = self.timer()
        linearization = system.springs
        assert linearization is not None  # None only once used, below
        assert system.stiffness_times is not None
        rhs = h * f0 + (h * h) * system.stiffness_times
        if system.extra_dfdx is not None:
            rhs += (h * h) * (system.extra_dfdx @ v0.ravel()).reshape(-1, 3)
        if dv_prescribed.any():
            rhs += pattern.boundary_coupling(linearization, dv_prescribed)
            if system.extra_full is not None:
                rhs -= (system.extra_full @ dv_prescribed.ravel()).reshape(-1, 3)
        b = system.with_held(pattern.restrict(rhs))
        assembly_seconds = self.timer() - clock + system.assembly_seconds
        # The element sets' blocks are in the matrix and the right-hand side now: let them go before the build and
        # the solve, the step's peak memory (the springs' 72 bytes each: 0.46 KiB per node on the README beam).
        system.springs = linearization = None

        setup_seconds, rebuilt = 0.0, False
        if self.method == "amg" and pattern.size:
            reason = self._needs_rebuild(memory, pattern, state.step, h, system.touched)
            if reason:
                logger.debug("step %d: rebuilding the AMG hierarchy (%s)", state.step, reason)
                setup_seconds = self._build(cache, pattern, system, x0, state.step, t0, h, v0)
                rebuilt = True
                memory.update({_KEY + "amg_step": int(state.step), _KEY + "amg_t": float(t0),
                               _KEY + "amg_size": int(pattern.size),
                               _KEY + "amg_dt": h, _KEY + "amg_x": x0.copy(), _KEY + "amg_v": v0.copy(),
                               _KEY + "amg_touched": system.touched})
            elif not cache.matches(pattern, memory[_KEY + "amg_step"], memory[_KEY + "amg_t"],
                                   memory[_KEY + "amg_dt"], memory[_KEY + "amg_x"], memory[_KEY + "amg_v"]):
                # Resumed from a checkpoint (or a new or unpickled cache): rebuild the hierarchy
                # exactly as it was built, from the recorded state.
                x_b, v_b = memory[_KEY + "amg_x"], memory[_KEY + "amg_v"]
                t_b, h_b = float(memory[_KEY + "amg_t"]), float(memory[_KEY + "amg_dt"])
                old = self._assemble(scene, pattern, x_b, v_b, t_b, h_b)
                setup_seconds = self._build(cache, pattern, old, x_b, memory[_KEY + "amg_step"], t_b, h_b, v_b)

        history = _history(memory, pattern.size, self.warm_start)
        guess = _projected_guess(system, b, history) if len(history) and self.method != "direct" else None
        solves = []
        if pattern.size:
            dv, info = self._solve(cache, system, b, guess)
            solves.append(info)
        else:
            dv = np.zeros(0)
            solves.append(SolveInfo(self.method, 0, 0.0, True, self.rtol))
        if system.held is not None:
            dv[system.held] = 0.0
        v1[pattern.free_nodes] += dv.reshape(-1, 3)
        x1 = x0 + h * v1

        newton_residuals = []
        if self.newton_iterations and pattern.size:
            for iteration in range(self.newton_iterations + 1):
                # Residual of M (v1 - v0) = h F(x0 + h v1, v1, t + h), and its Jacobian at the same point.
                current = self._assemble(scene, pattern, x1, v1, t0 + h, h)
                residual = current.with_held(pattern.restrict(model.masses[:, None] * (v1 - v0) - h * current.forces))
                newton_residuals.append(float(np.linalg.norm(residual)))
                if iteration == self.newton_iterations:
                    break
                delta, info = self._solve(cache, current, -residual, None)
                solves.append(info)
                if current.held is not None:
                    delta[current.held] = 0.0
                v1[pattern.free_nodes] += delta.reshape(-1, 3)
                x1 = x0 + h * v1
            dv = pattern.restrict(v1 - v0)  # warm start the next step from the converged change

        first = solves[0]
        if rebuilt or _KEY + "amg_iterations" not in memory:
            memory[_KEY + "amg_iterations"] = int(first.iterations)
        memory.update({_KEY + "iterations": int(first.iterations), _KEY + "residual": float(first.residual)})
        for old in ("dv", "dv_before", "extrapolate"):  # the keys of earlier versions' warm start
            memory.pop(_KEY + old, None)
        if self.warm_start:  # the last warm_start velocity changes, oldest first
            kept = history[max(0, len(history) - self.warm_start + 1):]
            memory[_KEY + "dv_history"] = np.concatenate([kept, dv[None, :]])
        else:
            memory.pop(_KEY + "dv_history", None)
        self.last_solve = ImplicitStepInfo(
            int(first.iterations), float(first.residual), tuple(solves), np.asarray(newton_residuals, dtype=float),
            forces_seconds, assembly_seconds, setup_seconds, sum(info.solve_seconds for info in solves), rebuilt)
        return State(x1, v1, t0 + h, state.step + 1, memory)

    def _solve(self, cache, system, b, guess):
        """The step's velocity change and the solve's info; ``guess``: (x0, b - A x0, the deflation of the previous
        changes) or None (from zero)."""
        warm, residual, deflation = guess if guess is not None else (None, None, None)
        if self.method == "amg":
            # Contact changes from step to step: the kept hierarchy's finest and first coarse level get the change of
            # the scene forces' Jacobian since the build (AMGConjugateGradient.update), the prolongators stay; a step
            # without a change has the built levels (restore), so that a step's preconditioner depends on the build
            # and the step only, as in a resumed run.
            change = _scene_change(system, cache)
            if change is not None:
                cache.solver.update(change)
            else:
                cache.solver.restore()
        return cache.solver.solve(system.matrix, b, x0=warm, extra=system.products, r0=residual, deflation=deflation)


def _scene_change(system: _System, cache: SolverCache) -> sp.csr_matrix | None:
    """What the scene forces' Jacobian (contact: between bodies, and folded into the diagonal for an obstacle) gained
    on the free unknowns since the hierarchy's build; None where it is the same."""
    size = system.matrix.shape[0]
    change = None
    if system.extra is not None or cache.extra is not None:
        now = system.extra if system.extra is not None else sp.csr_matrix((size, size))
        change = now - cache.extra if cache.extra is not None else sp.csr_matrix(now, copy=True)
    folded = system.folded if system.folded is not None else 0.0
    built = cache.folded if cache.folded is not None else 0.0
    if not np.array_equal(folded, built):
        diagonal = np.broadcast_to(np.subtract(folded, built), (size // 3, 3)).ravel()
        if system.held is not None:  # eliminated rows stay identity rows
            diagonal = np.where(system.held, 0.0, diagonal)
        diagonal = sp.diags(diagonal, format="csr")
        change = diagonal if change is None else change + diagonal
    if change is None:
        return None
    change = sp.csr_matrix(change)
    change.eliminate_zeros()
    return change if change.nnz else None


def _history(memory: dict, size: int, depth: int) -> np.ndarray:
    """(k, size) float, k <= ``depth`` -- the last velocity changes kept in ``memory``, oldest first (none when the
    unknowns changed; a state written by an earlier version holds its last two as ``dv_before`` and ``dv``)."""
    history = memory.get(_KEY + "dv_history")
    if history is None:
        history = [memory[_KEY + key] for key in ("dv_before", "dv") if _KEY + key in memory]
        history = np.array(history) if history and len({np.shape(dv) for dv in history}) == 1 else np.zeros((0, size))
    history = np.asarray(history, dtype=np.float64)
    if depth == 0 or history.ndim != 2 or history.shape[1] != size:
        return np.zeros((0, size))
    return history[-depth:]


def _projected_guess(system: _System, b: np.ndarray,
                     history: np.ndarray) -> tuple[np.ndarray, np.ndarray, Deflation | None] | None:
    """CG's first guess: x0 = X c, the combination of the previous velocity changes X (the rows of ``history``)
    closest to the solution of A x = b in A's energy norm, (X^T A X) c = X^T b (Fischer 1998's projection onto
    previous solutions). No worse in that norm than any extrapolation of them, and than starting from zero; it costs
    one product with the system per previous change, and gives CG its first residual b - A x0 without another.
    Directions the changes hardly span (energy below :data:`WARM_START_CUTOFF` of the largest) are left out; None
    when nothing is left.

    The products serve CG once more where CG adds products to the matrix's (sets applied as products, whose AMG
    hierarchy was built from their stand-in, or a scene force's Jacobian such as contact's): the directions kept
    deflate CG's preconditioner (a :class:`~volspring.solvers.krylov.Deflation`), so that CG does not search again
    along what the guess settled. On the README beam (3,321 nodes, dt 0.01 s, steps
    3-32 from rest) that takes the smoothed rung from 6.1 to 5.5 CG iterations a step, its step from 68.8 to 61.1 ms
    with the ``fast`` extra (66.7 to 63.0 in another run) and from 124.4 to 120.5 ms without; the volume rung from
    5.7 to 5.3 iterations and 53.8 to 50.7 ms without the extra. The springs' hierarchy is built from their own
    matrix: there the deflation saved 0.14 of 2.1 iterations a step and cost about 0.3 ms a step more than it saved
    (3%). In ``benchmarks/bench_contact_rungs.py``'s contact scene it changes little (CG iterations 4.3 -> 4.2,
    4.9 -> 4.8 and 5.9 -> 5.9 on the three rungs). (Scratch ``ab_rung.py``, ``its38.py`` and ``defl_cost.py``,
    stop 38.)
    """
    vectors = history.T  # (N, k)
    products, applied = times(system.matrix, vectors), system.products  # the property builds a new operator per access
    if applied is not None:
        products += applied @ vectors
    gram = vectors.T @ products
    energies, directions = np.linalg.eigh(0.5 * (gram + gram.T))
    if not energies[-1] > 0.0:
        return None
    kept = energies > WARM_START_CUTOFF * energies[-1]
    directions, energies = directions[:, kept], energies[kept]
    coefficients = directions @ ((directions.T @ (vectors.T @ b)) / energies)
    deflation = None
    if applied is not None:  # CG's operator is more than the hierarchy's matrix: worth the deflation (see above)
        # W^T and (A W)^T as C-ordered rows: a copy of the transposed (N, k) products costs ten times their product.
        deflation = Deflation(directions.T @ history, directions.T @ products.T, energies)
    return vectors @ coefficients, b - products @ coefficients, deflation

