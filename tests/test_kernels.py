"""The compiled kernels (volspring.kernels, the fast extra): numpy's results bit for bit, and the choice between them.

The tests marked ``fast`` need numba (skipped without it; .ci/run installs the extra and runs them). Every comparison
is exact (``np.array_equal`` on the bits): the kernels promise the same floating-point operations in the same order,
so no tolerance applies.
"""

import importlib.util
import sys

import numpy as np
import pytest

from meshing import structured_box
from volspring import Gravity, Material, Model, Pins, Scene, kernels
from volspring.assembly import BlockPattern
from volspring.errors import SpringCollapsed
from volspring.integrators.implicit import ImplicitEuler

HAS_NUMBA = importlib.util.find_spec("numba") is not None


def needs_numba(test):
    """Marked ``fast`` (.ci/run runs them with the extra installed), skipped without numba."""
    skip = pytest.mark.skipif(not HAS_NUMBA, reason="needs the fast extra: pip install -e '.[fast]'")
    return pytest.mark.fast(skip(test))


@pytest.fixture(autouse=True)
def restored_choice(monkeypatch):
    """Each test chooses for itself; the process's choice is put back after it."""
    monkeypatch.setattr(kernels, "_choice", kernels._choice)
    monkeypatch.delenv(kernels.ENVIRONMENT_VARIABLE, raising=False)


def bits(array):
    return np.ascontiguousarray(array).view(np.uint64)


def assert_same_bits(a, b):
    assert a.shape == b.shape
    assert np.array_equal(bits(a), bits(b)), f"{np.count_nonzero(bits(a) != bits(b))} entries differ"


def under_both(function):
    """``function()`` with numpy, then with the kernels."""
    kernels.select("numpy")
    reference = function()
    kernels.select("numba")
    return reference, function()


def assert_each_the_same_under_both(function):
    """Each array of the tuple ``function()`` returns is the same bits with numpy and with the kernels; numpy's
    arrays back."""
    numpy_result, kernel_result = under_both(function)
    for reference, result in zip(numpy_result, kernel_result, strict=True):
        assert_same_bits(reference, result)
    return numpy_result


def element_set(model_name, kind, wanted=lambda element_set: True):
    """The README-like beam (8 x 3 x 3 cells) on rung ``model_name`` and its first element set of type ``kind`` that
    ``wanted`` accepts."""
    model = beam_scene((8, 3, 3), model=model_name).model
    return model, next(each for each in model.elements if isinstance(each, kind) and wanted(each))


# ---------------------------------------------------------------------------- the choice
def test_a_choice_outside_the_three_is_refused_by_name():
    with pytest.raises(ValueError, match=r"kernels = 'cuda'; expected one of 'auto', 'numba', 'numpy'"):
        kernels.select("cuda")


def test_the_environment_variable_is_read_and_checked(monkeypatch):
    monkeypatch.setattr(kernels, "_choice", None)
    monkeypatch.setenv(kernels.ENVIRONMENT_VARIABLE, "NumPy ")
    assert kernels.active() == "numpy"
    monkeypatch.setattr(kernels, "_choice", None)
    monkeypatch.setenv(kernels.ENVIRONMENT_VARIABLE, "fortran")
    with pytest.raises(ValueError, match=r"VOLSPRING_KERNELS = 'fortran'; expected one of"):
        kernels.active()


def test_numpy_runs_when_chosen_and_auto_runs_numba_when_it_imports():
    assert kernels.select("numpy") == "numpy"
    assert kernels.compiled() is None
    assert kernels.select("auto") == ("numba" if HAS_NUMBA else "numpy")


def test_a_numba_that_fails_to_import_is_reported_and_numpy_runs(monkeypatch, caplog):
    import importlib

    original = importlib.import_module

    def refusing(name, *args):  # as numba refuses a numpy it does not support (numba itself is left alone)
        if name == "numba":
            raise ImportError("Numba needs NumPy 2.5 or less; got NumPy 9.0.")
        return original(name, *args)

    monkeypatch.setattr(kernels.importlib, "import_module", refusing)
    monkeypatch.setattr(kernels, "_module", None)
    monkeypatch.setattr(kernels, "_missing", None)
    assert kernels.select("auto") == "numpy"
    assert "numba is installed but does not import (Numba needs NumPy 2.5 or less" in caplog.text
    with pytest.raises(ImportError, match=r"Numba needs NumPy 2.5 or less.*pip install 'volspring\[fast\]'"):
        kernels.select("numba")


def test_without_numba_auto_falls_back_and_numba_is_refused_with_the_extra_named(monkeypatch):
    # numba made unimportable (sys.modules entries of None raise ImportError on import), whether it is installed or not
    monkeypatch.setitem(sys.modules, "numba", None)
    monkeypatch.setattr(kernels, "_module", None)
    monkeypatch.setattr(kernels, "_missing", None)
    assert kernels.select("auto") == "numpy"
    with pytest.raises(ImportError, match=r"numba does not import .*pip install 'volspring\[fast\]'"):
        kernels.select("numba")
    # and the model still steps, in numpy
    scene = beam_scene((6, 2, 2))
    state = ImplicitEuler().step(scene, scene.initial_state(), 0.01)
    assert np.isfinite(state.x).all() and state.x[:, 2].min() < 0.0


@needs_numba
def test_a_kernel_compiles_where_numba_has_nowhere_to_cache_it():
    # A function made from a string has no file, so numba finds no cache location for it and refuses cache=True
    # (RuntimeError), as it does for a read-only install and home: the kernel is then compiled in the process.
    from volspring import _compiled

    namespace = {}
    exec("def double(x):\n    return 2.0 * x\n", namespace)
    assert _compiled._jit(namespace["double"])(1.5) == 3.0


# ---------------------------------------------------------------------------- the kernels against numpy
def beam_scene(cells, *, model="springs", damping_ratio=None):
    mesh = structured_box(cells, (1.0, 0.2, 0.2))
    body = Model.from_mesh(mesh, Material(1e7, 0.45, 1000.0), model=model, damping_ratio=damping_ratio)
    return Scene(body, forces=[Gravity()], pins=Pins(np.flatnonzero(mesh.points[:, 0] == 0)))


def disturbed(model, scale, seed):
    """Positions and velocities off the rest shape: some springs stretched, some compressed (both block branches)."""
    rng = np.random.default_rng(seed)
    x = model.rest_positions + scale * rng.standard_normal(model.rest_positions.shape)
    return x, rng.standard_normal(x.shape)


@needs_numba
@pytest.mark.parametrize("with_velocities", [False, True])
@pytest.mark.parametrize("clamp", [True, False])
@pytest.mark.parametrize("scales", [(1.0, 0.0), (1e-4, 1e-2)])
def test_spring_forces_blocks_and_products_are_numpys_bit_for_bit(with_velocities, clamp, scales):
    model = beam_scene((8, 3, 3), damping_ratio=0.05).model
    springs = model.spring_elements
    assert springs.damping.any()  # the dampers' terms are in the comparison
    x, v = disturbed(model, 0.01, seed=1)
    stiffness_scale, damping_scale = scales

    def linearized():
        lin = springs.linearize(x, v if with_velocities else None, stiffness_scale=stiffness_scale,
                                damping_scale=damping_scale, clamp_compression=clamp)
        return lin, lin.dfdx_times(v)

    (numpy_lin, numpy_product), (kernel_lin, kernel_product) = under_both(linearized)
    transverse = 1.0 - springs.rest_lengths / numpy_lin.lengths
    assert (transverse < 0).any() and (transverse > 0).any()  # compressed and stretched springs both
    for name in ("forces", "blocks", "directions", "lengths", "transverse", "along"):
        assert_same_bits(getattr(numpy_lin, name), getattr(kernel_lin, name))
    assert_same_bits(numpy_product, kernel_product)


@needs_numba
def test_forces_vanish_exactly_at_the_rest_shape():
    """The kernel's lengths are the rest lengths' own sums (meshing.topology.vector_lengths), so nothing moves a
    body at rest: a different order of the three squares would leave forces of the order of round-off."""
    model = beam_scene((10, 3, 3)).model
    kernels.select("numba")
    forces = model.spring_elements.linearize(model.rest_positions, stiffness_scale=1.0).forces
    assert not forces.any()


@needs_numba
def test_a_collapsed_spring_is_named_as_numpy_names_it():
    model = beam_scene((4, 2, 2)).model
    springs = model.spring_elements
    x = model.rest_positions.copy()
    i, j = springs.pairs[7]
    x[j] = x[i]

    def collapse():
        with pytest.raises(SpringCollapsed) as caught:
            springs.linearize(x, stiffness_scale=1.0)
        return str(caught.value)

    numpy_message, kernel_message = under_both(collapse)
    assert kernel_message == numpy_message and "7" in kernel_message


@needs_numba
def test_positions_of_the_wrong_shape_are_refused_before_the_kernel_reads_them():
    # the compiled loops do not check their indices: a short array would be read past its end
    springs = beam_scene((4, 2, 2)).model.spring_elements
    kernels.select("numba")
    with pytest.raises(ValueError, match=r"x has shape \(10, 3\); expected \(45, 3\)"):
        springs.linearize(np.zeros((10, 3)), stiffness_scale=1.0)


def symmetric_batch(seed):
    """Symmetric 3x3 matrices of every kind the Jacobi rotations meet: F^T F of strains small and large (some need
    more than the four sweeps, which makes the whole batch sweep on), diagonal ones (nothing to rotate), repeated
    eigenvalues, zero, and one with a NaN on its diagonal (never converges)."""
    rng = np.random.default_rng(seed)
    F = np.eye(3) + np.concatenate([0.1 * rng.standard_normal((3000, 3, 3)), 3.0 * rng.standard_normal((50, 3, 3))])
    C = np.matmul(np.swapaxes(F, 1, 2), F)
    C[:10] = np.eye(3) * rng.uniform(0.5, 2.0, (10, 1, 1))
    C[10] = np.diag([2.0, 2.0, 1.0])
    C[11] = 0.0
    C[12, 0, 0] = np.nan
    return C


@needs_numba
def test_the_jacobi_eigensolver_is_numpys_bit_for_bit():
    from volspring.elements.tet_kinematics import _jacobi_eigh

    C = symmetric_batch(seed=4)
    numpy_result, kernel_result = under_both(lambda: _jacobi_eigh(C.copy()))
    assert not numpy_result[2][12] and numpy_result[2][:12].all()  # the NaN matrix alone did not converge
    for reference, result in zip(numpy_result, kernel_result):
        assert result.dtype == reference.dtype and result.flags.c_contiguous
        assert_same_bits(reference.astype(np.float64), result.astype(np.float64))


@needs_numba
@pytest.mark.parametrize("project", [True, False])
def test_the_corotation_is_numpys_bit_for_bit_inverted_tets_included(project):
    from volspring.elements.tet_kinematics import corotated, twist_rows

    rng = np.random.default_rng(5)
    F = np.eye(3) + 0.2 * rng.standard_normal((2000, 3, 3))
    F[:20, :, 2] *= -1.0  # inverted: LAPACK's path for these, the Jacobi path for the rest
    F[20] = np.diag([1.0, 1.0, 1e-3])  # nearly flat (LAPACK's path too)
    F[21] = np.diag([1.0, -1.0, 1.0])  # reflected: s_i + s_j = 0 for two twists
    vectors = rng.standard_normal((2000, 4, 3))

    def corotation():
        U, Vt, psi, P, coefficients = corotated(F, project=project)
        return U, Vt, psi, P, coefficients, twist_rows(U, Vt, vectors), twist_rows(U, Vt, vectors, coefficients)

    assert_each_the_same_under_both(corotation)


CONTINUUM_SETS = {"per-tet shear": ("smoothed", "CorotatedTets", lambda each: True),
                  "nodal shear": ("smoothed", "NodalStrain", lambda each: each.shear.any()),
                  "nodal volume": ("springs+volume", "NodalStrain", lambda each: each.bulk.any())}


@needs_numba
@pytest.mark.parametrize("which", list(CONTINUUM_SETS))
def test_a_continuum_sets_forces_products_and_blocks_are_numpys_bit_for_bit(which):
    import volspring.elements

    rung, kind, wanted = CONTINUUM_SETS[which]
    model, continuum = element_set(rung, getattr(volspring.elements, kind), wanted)
    x, u = disturbed(model, 0.02, seed=6)
    columns = np.random.default_rng(7).standard_normal(u.shape + (5,))

    def linearized():
        lin = continuum.linearize_operator(x, stiffness_scale=1e-4)
        return (lin.forces, lin.scaled_times(u), lin.dfdx_times(u), lin.scaled_times_many(columns),
                continuum.stiffness_blocks(x))

    forces, product, *_ = assert_each_the_same_under_both(linearized)
    assert np.abs(forces).max() > 0.0 and np.abs(product).max() > 0.0


@needs_numba
@pytest.mark.parametrize("kind", ["CorotatedTets", "NodalStrain"])
def test_a_product_with_the_wrong_rows_is_refused_before_the_kernel_reads_them(kind):
    # The compiled products index u by the mesh's nodes, unchecked: short arrays would be read past their end.
    import volspring.elements

    model, continuum = element_set("smoothed", getattr(volspring.elements, kind), lambda each: each.shear.any())
    x, _ = disturbed(model, 0.02, seed=6)
    kernels.select("numba")
    lin = continuum.linearize_operator(x)
    with pytest.raises(ValueError, match=r"u has 10 rows; expected 144"):
        lin.scaled_times(np.zeros((10, 3)))
    with pytest.raises(ValueError, match=r"u has 10 rows; expected 144"):
        lin.scaled_times_many(np.zeros((10, 3, 5)))


@needs_numba
def test_gradients_and_stresses_of_the_wrong_shape_are_refused_before_the_kernels_read_them():
    # gathered and spread read rows by the matrices' indices, unchecked: short arrays would be read past their end
    from volspring.elements import NodalStrain

    model, nodal = element_set("smoothed", NodalStrain, lambda each: each.shear.any())
    kinematics, domains = nodal.kinematics, nodal.domains
    kernels.select("numba")
    with pytest.raises(ValueError, match=r"expected \(144, 3\) values, one row per node; got shape \(10, 3\)"):
        domains.averaged(np.zeros((10, 3)))
    with pytest.raises(ValueError, match=rf"expected \({domains.domain_count}, 3, 3\) matrices"):
        domains.spread(np.zeros((10, 3, 3)))
    with pytest.raises(ValueError, match=rf"expected \({len(kinematics.tets)}, 3, 3\) matrices"):
        kinematics.spread(np.zeros((10, 3, 3)), model.node_count)
    with pytest.raises(ValueError, match=r"positions have 10 rows"):
        kinematics.deformation(np.zeros((10, 3)))
    with pytest.raises(ValueError, match=r"expected \(144, 3\) values, one row per node; got shape \(144, 2\)"):
        kinematics.deformation(np.zeros((model.node_count, 2)))  # rows enough, but two columns


def test_three_matrices_of_different_patterns_are_refused_as_one_kernel_layout():
    # The compiled gathers and spreads read one pattern for the three matrices of a tet set's or a domain set's
    # columns (shared by construction); matrices that do not share it must not be laid out as if they did.
    import scipy.sparse as sp

    from volspring.elements.tet_kinematics import _kernel_arrays

    one = sp.csr_matrix(np.array([[1.0, 0.0], [0.0, 2.0]]))
    other = sp.csr_matrix(np.array([[1.0, 3.0], [0.0, 2.0]]))
    indptr, indices, data = _kernel_arrays((one, one, one))
    assert data.shape == (2, 3) and np.array_equal(data[:, 1], one.data)
    with pytest.raises(ValueError, match="must share one sparsity pattern"):
        _kernel_arrays((one, other, one))


def random_bsr(rng, block_rows, block_columns, blocksize, density):
    """A BSR matrix of random blocks, some block rows empty, its block columns in no particular order."""
    import scipy.sparse as sp

    pattern = sp.random(block_rows, block_columns, density=density, random_state=rng, format="csr")
    pattern.data[:] = 1.0
    pattern = pattern.multiply(rng.random(block_rows)[:, None] > 0.1).tocsr()  # empty rows too
    indices = pattern.indices.copy()
    for row in range(block_rows):  # unsorted columns: the product's order follows the stored order
        rng.shuffle(indices[pattern.indptr[row]:pattern.indptr[row + 1]])
    data = rng.standard_normal((len(indices),) + blocksize)
    return sp.bsr_matrix((data, indices, pattern.indptr), shape=(block_rows * blocksize[0], block_columns * blocksize[1]))


@needs_numba
@pytest.mark.parametrize("sizes", [(3, 3, 6), (6, 3, 3), (6, 3, 6), (6, 6, 6), (2, 5, 4)])
def test_the_block_product_is_scipys_bit_for_bit(sizes):
    """The build's four block sizes (unrolled loops) and one other (loops of run-time length): the same block columns
    in the same order and the same bits as scipy's product."""
    from volspring.solvers.amg import _product

    R, N, C = sizes
    rng = np.random.default_rng(7)
    left, right = random_bsr(rng, 60, 40, (R, N), 0.1), random_bsr(rng, 40, 50, (N, C), 0.1)
    reference = left @ right
    kernels.select("numba")
    result = _product(left, right)
    assert result.blocksize == reference.blocksize and result.shape == reference.shape
    assert np.array_equal(result.indptr, reference.indptr) and np.array_equal(result.indices, reference.indices)
    assert_same_bits(reference.data, result.data)


@needs_numba
@pytest.mark.parametrize("columns", [None, 1, 5])
def test_the_system_product_is_scipys_bit_for_bit(columns):
    """The implicit step's BSR matrix times one vector, and times k vectors kept as rows (CG's guess: the transpose
    of its past changes, which the kernel reads without a copy), with unsorted block columns and empty block rows."""
    from volspring.solvers.krylov import times

    rng = np.random.default_rng(11)
    matrix = random_bsr(rng, 50, 50, (3, 3), 0.1)
    vectors = rng.standard_normal(150) if columns is None else rng.standard_normal((columns, 150)).T
    reference = matrix @ vectors
    kernels.select("numba")
    result = times(matrix, vectors)
    assert_same_bits(reference, result)
    # scipy's layout too: BLAS sums a product with an F-ordered array in another order, so the guess built on it
    # would not be the same bits.
    assert result.flags.c_contiguous


@needs_numba
@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("blocksize", [3, 2])
def test_the_point_wise_triangles_are_numpys_entry_for_entry(dtype, blocksize):
    """The finest level's triangles (a build makes them from the system matrix): the same row pointers, columns,
    index types, values (cast) and diagonal, with and without the kernels; the diagonal blocks' entries on the other
    side of the diagonal stored as zeros on both."""
    import scipy.sparse as sp

    from volspring.solvers.amg import _Triangles

    rng = np.random.default_rng(3)
    matrix = random_bsr(rng, 40, 40, (blocksize, blocksize), 0.15)
    matrix = sp.bsr_matrix(matrix + sp.eye(40 * blocksize), blocksize=(blocksize, blocksize))  # every diagonal block
    matrix.sort_indices()

    def triangles():
        made = _Triangles(matrix, point_wise=True, dtype=dtype)
        arrays = [array for half in (made.lower, made.upper) for array in (half.indptr, half.indices, half.data)]
        return arrays + [made.diagonal]

    numpy_arrays, kernel_arrays = under_both(triangles)
    for reference, result in zip(numpy_arrays, kernel_arrays, strict=True):
        assert reference.dtype == result.dtype and reference.shape == result.shape
        assert np.array_equal(reference.view(np.uint8), result.view(np.uint8))
    assert np.count_nonzero(numpy_arrays[2] == 0) >= 40 * blocksize * (blocksize - 1) // 2  # the cleared entries


@needs_numba
def test_triangles_without_a_diagonal_block_are_refused_as_numpy_refuses_them():
    import scipy.sparse as sp

    from volspring.solvers.amg import _Triangles

    matrix = sp.bsr_matrix(np.kron(np.array([[1.0, 1.0], [1.0, 0.0]]), np.ones((3, 3))), blocksize=(3, 3))
    matrix.eliminate_zeros()
    for choice in ("numpy", "numba"):
        kernels.select(choice)
        with pytest.raises(ValueError, match="every block row needs its diagonal block"):
            _Triangles(matrix, point_wise=True)


@needs_numba
def test_the_multigrid_hierarchy_is_the_same_bit_for_bit():
    """Every level's matrix, prolongation and restriction of one build (a coarsest level of 60 unknowns makes three
    levels: products with 3 x 3 and 6 x 6 blocks)."""
    from meshing.geometry import rigid_body_modes
    from volspring.solvers.amg import _smoothed_aggregation

    scene = beam_scene((30, 6, 6))
    matrix, _, pattern = ImplicitEuler().linear_system(scene, scene.initial_state(), 0.01)
    modes = rigid_body_modes(scene.model.rest_positions[pattern.free_nodes])

    def hierarchy():
        levels = _smoothed_aggregation(matrix.copy(), modes, theta=0.05, excluded=None, max_coarse=10).levels
        return [getattr(level, name) for level in levels for name in ("A", "P", "R") if hasattr(level, name)]

    numpy_levels, kernel_levels = under_both(hierarchy)
    assert len(numpy_levels) >= 7  # at least three levels
    for reference, result in zip(numpy_levels, kernel_levels):
        assert np.array_equal(reference.indptr, result.indptr) and np.array_equal(reference.indices, result.indices)
        assert_same_bits(np.asarray(reference.data), np.asarray(result.data))


def compiled_halves_apply(solver) -> bool:
    """Whether the V-cycle of ``solver`` runs its finest level by the compiled halves now."""
    from volspring.solvers.amg import _CompiledFinest

    finest = solver.hierarchy.levels[0]
    halves = _CompiledFinest.of(finest)
    return halves is not None and halves._arrays_of(finest.A) is not None


@needs_numba
def test_the_v_cycle_is_the_same_bit_for_bit():
    """One V-cycle on a three-level hierarchy, its finest level swept, restricted and prolonged by the compiled
    halves."""
    from meshing.geometry import rigid_body_modes
    from volspring.solvers.amg import AMGConjugateGradient

    scene = beam_scene((30, 6, 6))
    matrix, _, pattern = ImplicitEuler().linear_system(scene, scene.initial_state(), 0.01)
    modes = rigid_body_modes(scene.model.rest_positions[pattern.free_nodes])
    r = np.random.default_rng(5).standard_normal(matrix.shape[0])

    def cycle():
        solver = AMGConjugateGradient(max_coarse=10)
        solver.build(matrix, modes)
        return solver.precondition(r), compiled_halves_apply(solver), len(solver.hierarchy.levels)

    (reference, numpy_halves, levels), (result, kernel_halves, _) = under_both(cycle)
    assert levels >= 3
    assert not numpy_halves and kernel_halves  # the comparison is of the compiled halves against numpy's cycle
    assert_same_bits(reference, result)


@needs_numba
def test_the_v_cycle_follows_an_update_of_the_levels_bit_for_bit():
    """A contact step holds the built matrix plus the contact's change on the finest level (``update``), and the
    built one again after (``restore``): the compiled halves read the level's matrix of the moment, as numpy's cycle
    does. (Made from the matrices of the build, they preconditioned contact steps with the contact left out: 12.1-12.7
    CG iterations a step instead of 5.3-5.8 in ``bench_versions.py``'s contact scene.)"""
    import scipy.sparse as sp
    from meshing.geometry import rigid_body_modes
    from volspring.solvers.amg import AMGConjugateGradient

    scene = beam_scene((30, 6, 6))
    matrix, _, pattern = ImplicitEuler().linear_system(scene, scene.initial_state(), 0.01)
    modes = rigid_body_modes(scene.model.rest_positions[pattern.free_nodes])
    r = np.random.default_rng(5).standard_normal(matrix.shape[0])
    rows = np.arange(0, 60, 3)  # a stiff coupling between a few unknowns, as a contact adds: symmetric
    coupling = sp.coo_matrix((np.full(len(rows), 1e9), (rows, rows + 1)), shape=matrix.shape)
    change = (coupling + coupling.T + sp.diags(np.where(np.isin(np.arange(matrix.shape[0]), np.r_[rows, rows + 1]),
                                                         2e9, 0.0))).tocsr()

    def cycles():
        solver = AMGConjugateGradient(max_coarse=10)
        solver.build(matrix, modes)
        before = solver.precondition(r)
        solver.update(change)
        during = solver.precondition(r)
        assert compiled_halves_apply(solver) == (kernels.active() == "numba")  # on the updated triangles
        solver.restore()
        return before, during, solver.precondition(r)

    (before, during, after), kernel_cycles = under_both(cycles)
    assert not np.array_equal(before, during) and np.array_equal(before, after)  # the update changed the cycle
    for reference, result in zip((before, during, after), kernel_cycles):
        assert_same_bits(reference, result)


@needs_numba
@pytest.mark.parametrize("rung", ["springs", "springs+volume", "smoothed"])
def test_a_run_is_the_same_bit_for_bit_with_and_without_the_kernels(rung):
    """30 implicit steps of a 4,500-node beam under gravity, with dampers (damped springs, stiffness damping of the
    continuum terms), its AMG hierarchy built and kept as in any run: positions and velocities the same bits."""
    scene = beam_scene((44, 9, 9), model=rung, damping_ratio=0.02)
    assert scene.model.node_count == 4500

    def run():
        integrator, state = ImplicitEuler(), scene.initial_state()
        for _ in range(30):
            state = integrator.step(scene, state, 0.01)
        return state

    numpy_state, kernel_state = under_both(run)
    assert numpy_state.x[:, 2].min() < -1e-3  # the beam sagged: the comparison is of a real motion
    assert_same_bits(numpy_state.x, kernel_state.x)
    assert_same_bits(numpy_state.v, kernel_state.v)


@needs_numba
def test_a_contact_run_is_the_same_bit_for_bit_with_and_without_the_kernels():
    """Two cubes pressed together by a strong gravity (``bench_versions.py``'s contact scene): the contact steps
    update the hierarchy's finest levels, which the compiled V-cycle sweeps. This is the scene that found the halves
    sweeping the build's triangles instead (12.1-12.7 CG iterations a step instead of 5.3-5.8)."""
    from volspring.bodies import Body
    from volspring.collision import ContactForce

    cube = structured_box((5, 5, 5), (0.2, 0.2, 0.2))
    material = Material(1e7, 0.45, 1000.0)
    model = Model.from_bodies([Body(cube, material), Body(cube, material, translation=(0.0, 0.0, 0.199))])
    scene = Scene(model, forces=[Gravity(g=(0, 0, -100.0)), ContactForce(model)],
                  pins=Pins(np.flatnonzero(model.rest_positions[:, 2] == 0)))

    def run():
        integrator, state, iterations = ImplicitEuler(), scene.initial_state(), []
        for _ in range(15):
            state = integrator.step(scene, state, 0.01)
            iterations.append(integrator.last_solve.iterations)
        return state, iterations

    (numpy_state, numpy_iterations), (kernel_state, kernel_iterations) = under_both(run)
    assert numpy_iterations == kernel_iterations
    assert_same_bits(numpy_state.x, kernel_state.x)
    assert_same_bits(numpy_state.v, kernel_state.v)


@needs_numba
def test_the_matrix_is_the_same_bit_for_bit():
    scene = beam_scene((12, 4, 4), damping_ratio=0.05)
    pattern = BlockPattern(scene.model, scene.free)
    x, v = disturbed(scene.model, 0.005, seed=3)

    def data():
        linearization = pattern.linearize(x, v, stiffness_scale=1e-4, damping_scale=1e-2)
        return pattern.data(linearization, scene.model.masses[pattern.free_nodes]), linearization

    (reference, _), (data, linearization) = under_both(data)
    assert_same_bits(reference, data)
    # The kernel summed each spring's block where it made it: the blocks were never stored beside the matrix (the
    # step's peak memory).
    springs, = linearization.parts
    assert springs._blocks is None
