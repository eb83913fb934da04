"""The implicit step applies the continuum sets as products (matrix-free) and preconditions with a 1-ring
stand-in: the system it solves must be exactly the assembled one, supports and prescribed motion included."""

import numpy as np
import pytest

from meshing import structured_box
from volspring import Gravity, Material, Model, Pins, Scene
from volspring.assembly import BlockPattern
from volspring.integrators.implicit import ImplicitEuler
from volspring.supports import Prescribed, Sliding

RUBBER = Material(E=1e6, nu=0.45, density=1000.0)


@pytest.fixture(scope="module", params=["smoothed", "springs+volume"])
def bar(request):
    mesh = structured_box((6, 2, 2), (0.6, 0.2, 0.2))
    return mesh, Model.from_mesh(mesh, RUBBER, model=request.param)


def _in_model_numbering(pattern, vector):
    out = np.zeros((pattern.model.node_count, 3))
    out[pattern.free_nodes] = np.reshape(vector, (-1, 3))
    return out


def test_the_products_and_the_matrix_make_the_assembled_system(bar):
    mesh, model = bar
    rng = np.random.default_rng(3)
    x = mesh.points + 0.02 * rng.standard_normal(mesh.points.shape)  # strained and rotated tets
    v = rng.standard_normal(x.shape)
    free = mesh.points[:, 0] > 0.05
    assembled = BlockPattern(model, free)
    applied = BlockPattern(model, free, matrix_free=True)
    assert applied.has_operator and not assembled.has_operator
    options = dict(stiffness_scale=1e-4, damping_scale=1e-2)
    full, split = assembled.linearize(x, v, **options), applied.linearize(x, v, **options)
    # The same forces by another summation order (sparse products instead of bincount): round-off only.
    np.testing.assert_allclose(split.forces, full.forces, rtol=0, atol=1e-12 * abs(full.forces).max())
    u = rng.standard_normal(x.shape)
    reference = _in_model_numbering(assembled, assembled.matrix(full) @ assembled.restrict(u))
    product = applied.matrix(split) @ applied.restrict(u) + applied.operator(split) @ applied.restrict(u)
    # Round-off of sums over a few hundred blocks of size ~1e-4 E h: 1e-12 of the largest entry.
    scale = abs(reference).max()
    np.testing.assert_allclose(_in_model_numbering(applied, product), reference, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(applied.dfdx_times(split, u), assembled.dfdx_times(full, u), rtol=0,
                               atol=1e-12 * abs(assembled.dfdx_times(full, u)).max())
    prescribed = np.where(free[:, None], 0.0, u)
    coupling = assembled.boundary_coupling(full, prescribed)
    np.testing.assert_allclose(applied.boundary_coupling(split, prescribed)[free], coupling[free], rtol=0,
                               atol=1e-12 * abs(coupling).max())


@pytest.mark.parametrize("choice", ["numpy", "auto"])
def test_products_with_several_vectors_at_once_are_the_products_one_by_one_bit_for_bit(bar, choice, monkeypatch):
    """CG's first guess applies the operator to the last velocity changes at once (the sparse factors read once): each
    column must be the bits of the single product, so that the guess, and every run, stay what they were."""
    from volspring import kernels

    monkeypatch.setattr(kernels, "_choice", kernels._choice)  # the session's choice (VOLSPRING_KERNELS) comes back
    mesh, model = bar
    rng = np.random.default_rng(5)
    x = mesh.points + 0.02 * rng.standard_normal(mesh.points.shape)
    applied = BlockPattern(model, mesh.points[:, 0] > 0.05, matrix_free=True)
    kernels.select(choice)
    operator = applied.operator(applied.linearize(x, rng.standard_normal(x.shape), stiffness_scale=1e-4,
                                                  damping_scale=1e-2))
    vectors = rng.standard_normal((applied.size, 5))
    at_once = operator @ vectors
    one_by_one = np.stack([operator @ vectors[:, j] for j in range(5)], axis=1)
    assert at_once.shape == one_by_one.shape
    assert np.array_equal(at_once.view(np.int64), one_by_one.view(np.int64))


def test_the_stand_in_is_symmetric_positive_definite_and_on_the_one_ring(bar):
    mesh, model = bar
    applied = BlockPattern(model, mesh.points[:, 0] > 0.05, matrix_free=True)
    lin = applied.linearize(mesh.points, stiffness_scale=1.0)
    stand_in = applied.matrix(lin, 1e-9, preconditioner=True).toarray()
    assert np.allclose(stand_in, stand_in.T, rtol=0, atol=1e-9 * abs(stand_in).max())
    assert np.linalg.eigvalsh(stand_in).min() > 0
    # The 1-ring: as many 3x3 blocks as a pattern of the tets' edges (the 2-ring has several times more).
    assert applied.block_count < BlockPattern(model, mesh.points[:, 0] > 0.05).block_count / 2


def test_the_layouts_filled_at_every_linearisation_are_taken_by_scipy_as_they_are(bar):
    """The twist rows and the volume rows are CSR matrices made at every linearisation on a layout made once: scipy
    must keep its index arrays as given (int32 here), not convert them each time (0.9 ms a step on 15,360 tets)."""
    import scipy.sparse as sp

    from volspring.elements import CorotatedTets, NodalStrain

    _, model = bar
    layouts = [element_set._twist_layout for element_set in model.elements if isinstance(element_set, CorotatedTets)]
    layouts += [element_set.domains.volume_layout for element_set in model.elements
                if isinstance(element_set, NodalStrain) and element_set.bulk.any()]
    assert layouts
    for indices, indptr in layouts:
        matrix = sp.csr_matrix((np.ones(len(indices)), indices, indptr), shape=(len(indptr) - 1, 3 * model.node_count))
        assert np.shares_memory(matrix.indices, indices) and np.shares_memory(matrix.indptr, indptr)


def _held_in_part(mesh, model):
    """The bar under gravity, one end sliding in its plane (one node pinned), the other end pulled along x: partly
    held nodes, whose held components the step eliminates."""
    left = np.flatnonzero(mesh.points[:, 0] == 0.0)
    right = np.flatnonzero(np.isclose(mesh.points[:, 0], 0.6))
    start = mesh.points[right]
    return Scene(model, forces=[Gravity()], pins=Pins(left[:1]),
                 supports=[Sliding(left[1:], "x"), Prescribed(right, "x", motion=lambda t: start + [0.5 * t * t, 0, 0])])


def test_matrix_free_steps_equal_assembled_steps_with_sliding_and_prescribed_supports(bar):
    mesh, model = bar
    scene = _held_in_part(mesh, model)
    states = {}
    for matrix_free in (True, False):
        integrator = ImplicitEuler(rtol=1e-12, matrix_free=matrix_free)
        state = scene.initial_state()
        for _ in range(4):
            state = integrator.step(scene, state, 0.01)
        states[matrix_free] = state
        assert integrator.cache.pattern.has_operator == matrix_free
    # Both solve the same system to rtol 1e-12; the answers differ by that residual over the conditioning.
    displacement = abs(states[False].x - mesh.points).max()
    np.testing.assert_allclose(states[True].x, states[False].x, rtol=0, atol=1e-8 * displacement)


def test_the_direct_solver_and_exact_curvature_assemble_everything():
    assert not ImplicitEuler(solver="direct").matrix_free
    assert not ImplicitEuler(clamp_compression=False).matrix_free
    assert ImplicitEuler().matrix_free


@pytest.mark.parametrize("supports", ["held in part", "pinned"])
def test_a_step_whose_sets_are_all_products_multiplies_only_the_diagonal_blocks(bar, supports, monkeypatch):
    """Where no set is assembled (the smoothed rung) the step's matrix is the masses amid the stand-in's 1-ring of
    zero blocks: CG and its guess multiply the diagonal blocks alone, and every bit of the run stays what it was
    with the whole pattern: with partly held nodes, whose elimination edits the diagonal blocks of the whole
    pattern's matrix, and with pinned nodes alone, where the diagonal blocks are made without the pattern."""
    from types import SimpleNamespace

    from volspring.solvers import AMGConjugateGradient

    mesh, model = bar
    scene = _held_in_part(mesh, model) if supports == "held in part" else \
        Scene(model, forces=[Gravity()], pins=Pins(np.flatnonzero(mesh.points[:, 0] == 0.0)))
    solve, blocks = AMGConjugateGradient.solve, []

    def recording(self, matrix, *args, **kwargs):
        blocks.append(matrix.data.shape[0])
        return solve(self, matrix, *args, **kwargs)

    monkeypatch.setattr(AMGConjugateGradient, "solve", recording)

    def run():
        integrator, state = ImplicitEuler(), scene.initial_state()
        for _ in range(5):
            state = integrator.step(scene, state, 0.01)
        return integrator.cache.pattern, state

    pattern, compact = run()
    expected = pattern.block_count if pattern.assembles else pattern.free_count
    assert pattern.assembles == (model.rung != "smoothed")
    assert blocks == [expected] * 5, (blocks, pattern.free_count, pattern.block_count)
    monkeypatch.setattr(BlockPattern, "diagonal_part", lambda self, matrix: matrix)
    # The whole pattern's matrix, its blocks zero but the diagonal's (no linearisation: no set adds blocks).
    monkeypatch.setattr(BlockPattern, "diagonal_matrix",
                        lambda self, diagonal: self.matrix(SimpleNamespace(parts=(None,) * len(self.parts)), diagonal))
    _, whole = run()
    for name in ("x", "v"):
        assert np.array_equal(getattr(compact, name), getattr(whole, name)), name
