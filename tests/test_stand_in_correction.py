"""The preconditioner's correction for a stand-in matrix (:func:`volspring.solvers.amg.stand_in_correction`) and the
exact diagonal blocks it is made from (the matrix-free sets' ``diagonal_blocks``)."""

import pickle

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import cube_mesh

from meshing.geometry import rigid_body_modes
from volspring import Gravity, Material, Model, Pins, Scene
from volspring.assembly import stiffness_matrix
from volspring.integrators.implicit import ImplicitEuler
from volspring.solvers import AMGConjugateGradient, amg

MATERIAL = Material(1e6, 0.45, 1000.0)


def _turned_and_strained(points, seed=0):
    """Positions turned by 0.4 rad about an oblique axis and strained by up to 3% at random: every twist and rotation of
    the sets' Hessians is in play."""
    axis = np.array([1.0, 2.0, 2.0]) / 3.0
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    R = np.eye(3) + np.sin(0.4) * K + (1 - np.cos(0.4)) * K @ K
    strained = points + 0.03 * np.random.default_rng(seed).uniform(-1, 1, points.shape) * np.ptp(points, axis=0)
    return strained @ R.T


@pytest.mark.parametrize("rung", ["smoothed", "springs+volume"])
def test_matrix_free_sets_give_the_diagonal_blocks_of_their_assembled_stiffness(rung):
    mesh = cube_mesh((4, 2, 2), (1.0, 0.5, 0.5))
    model = Model.from_mesh(mesh, MATERIAL, model=rung)
    x = _turned_and_strained(model.rest_positions)
    matrix_free = [element_set for element_set in model.elements if element_set.matrix_free]
    assert matrix_free  # both rungs apply a set as a product
    for element_set in matrix_free:
        alone = Model(model.rest_positions, model.masses, elements=(element_set,))
        assembled = stiffness_matrix(alone, x).tocsr()
        expected = np.stack([assembled[3 * i:3 * i + 3, 3 * i:3 * i + 3].toarray() for i in range(model.node_count)])
        blocks = element_set.diagonal_blocks(x)
        # The same sums in another order: rounding of the largest block, 1e-12 with room (measured 0 to 2e-16).
        assert np.abs(blocks - expected).max() <= 1e-12 * np.abs(expected).max(), type(element_set).__name__
        assert np.abs(expected).max() > 0


def _stand_in_system(cells=(12, 3, 3)):
    """(SPD BSR stand-in, rigid-body modes, the exact diagonal blocks of a softer operator): the stand-in is M + K
    with K a unit-spring Laplacian on the tets' edges, and the operator's diagonal is M + K's diagonal with every
    block's stiffness halved and one block stiffer than the stand-in's."""
    mesh = cube_mesh(cells, (1.0, 0.25, 0.25))
    points, tets = mesh.points, mesh.tets
    n = len(points)
    edges = np.unique(np.sort(np.concatenate([tets[:, [a, b]] for a in range(4) for b in range(a + 1, 4)]), axis=1),
                      axis=0)
    laplacian = sp.coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), shape=(n, n)).tocsr()
    laplacian = laplacian + laplacian.T
    laplacian = sp.diags(np.asarray(laplacian.sum(axis=1)).ravel()) - laplacian
    stiffness = sp.kron(laplacian, np.eye(3))
    matrix = sp.bsr_matrix(sp.identity(3 * n) * 0.01 + stiffness, blocksize=(3, 3))
    matrix.sort_indices()
    degree = laplacian.diagonal()[:, None, None]
    diagonal = (0.01 + degree) * np.eye(3)
    exact = (0.01 + 0.5 * degree) * np.eye(3)
    exact[0] = 2.0 * diagonal[0]
    return matrix, rigid_body_modes(points), exact, diagonal


def test_the_correction_adds_what_the_stand_in_lacks_and_only_that():
    matrix, _, exact, diagonal = _stand_in_system()
    blocks = amg.stand_in_correction(matrix, exact, 0.3).blocks
    dense = np.stack([blocks.tocsr()[3 * i:3 * i + 3, 3 * i:3 * i + 3].toarray() for i in range(len(exact))])
    expected = 0.3 * (np.linalg.inv(exact) - np.linalg.inv(diagonal))
    # Where the operator is softer (D^-1 > D_s^-1): omega (D^-1 - D_s^-1), to rounding of the eigen-decomposition.
    assert np.allclose(dense[1:], expected[1:], rtol=1e-12, atol=0)
    # Where it is stiffer (node 0): nothing, since the positive part of a negative definite block is zero.
    assert not dense[0].any()
    assert blocks.nnz == 9 * len(exact)  # block diagonal
    # The stand-in that is the operator: no correction at all.
    assert not amg.stand_in_correction(matrix, diagonal, 0.3).blocks.data.any()


def test_the_correction_is_positive_semidefinite_for_any_operator():
    matrix, _, _, diagonal = _stand_in_system()
    rng = np.random.default_rng(1)
    root = rng.standard_normal(diagonal.shape)
    exact = root @ np.swapaxes(root, 1, 2) + 0.1 * np.eye(3)  # SPD blocks, softer and stiffer in every direction
    blocks = amg.stand_in_correction(matrix, exact, 1.0).blocks.data
    # 1e-12 of the largest: rounding of the eigen-decomposition (the exact smallest eigenvalue is 0 or above).
    assert np.linalg.eigvalsh(blocks).min() >= -1e-12 * np.abs(blocks).max()


@pytest.mark.parametrize("case", ["indefinite", "shape", "weight"])
def test_the_correction_refuses_what_it_cannot_use(case):
    matrix, _, exact, _ = _stand_in_system()
    weight = 0.3
    if case == "indefinite":
        exact = exact.copy()
        exact[5] = -exact[5]
        match = "block 5 has eigenvalue"
    elif case == "shape":
        exact = exact[:-1]
        match = "expected"
    else:
        weight, match = -0.1, "weight"
    with pytest.raises(ValueError, match=match):
        amg.stand_in_correction(matrix, exact, weight)


def test_the_preconditioner_adds_the_correction_to_its_cycle_and_keeps_it_in_a_pickle():
    matrix, modes, exact, _ = _stand_in_system()
    r = np.random.default_rng(2).standard_normal(matrix.shape[0])
    plain, corrected = AMGConjugateGradient(max_coarse=20), AMGConjugateGradient(max_coarse=20)
    plain.build(matrix, modes)
    corrected.build(matrix, modes, exact_diagonal=exact)
    correction = amg.stand_in_correction(matrix, exact)
    assert np.array_equal(corrected.precondition(r), plain.precondition(r) + correction @ r)
    again = pickle.loads(pickle.dumps(corrected))
    assert np.array_equal(again.precondition(r), corrected.precondition(r))


def _cg_iterations(rung, weight, monkeypatch, steps=22):
    mesh = cube_mesh((24, 5, 5), (1.0, 0.2, 0.2))
    model = Model.from_mesh(mesh, MATERIAL, model=rung)
    scene = Scene(model, forces=[Gravity()], pins=Pins(np.flatnonzero(mesh.points[:, 0] == 0)))
    monkeypatch.setattr(amg, "STAND_IN_CORRECTION", weight)
    integrator = ImplicitEuler()
    state = scene.initial_state()
    counts = []
    for _ in range(steps):
        state = integrator.step(scene, state, 0.01)
        counts.append(integrator.last_solve.iterations)
    return sum(counts[2:])


def test_the_correction_saves_cg_iterations_on_the_smoothed_rung(monkeypatch):
    """The reason it is there. Measured on this 900-node beam, steps 3-22 at dt = 0.01 s: 157 CG iterations without
    the correction, 129 with it (0.82; the README beam: 6.45 -> 5.45 a step, benchmarks/study_stand_in.py)."""
    default = amg.STAND_IN_CORRECTION
    without = _cg_iterations("smoothed", 0.0, monkeypatch)
    with_it = _cg_iterations("smoothed", default, monkeypatch)
    # A tenth fewer at least: the README beam's smallest saving at nu 0.3-0.49 is 11% (0.89 of the iterations), this
    # beam's 18%; with the correction left out or its sign turned, the ratio is 1 or more.
    assert with_it <= 0.9 * without, (with_it, without)


def test_the_correction_adds_no_momentum_to_a_residual_that_has_none():
    """For a body in free flight A T = M T (T the translations): CG keeps the momentum where each preconditioned
    residual has none when the residual has none. Unprojected, the blocks alone break that (the two bodies of
    examples/scenes/two_bodies.toml changed their total momentum by 9.2e-5 of 0.52 kg m/s; tests/test_scene_file.py)."""
    matrix, _, exact, _ = _stand_in_system()  # no support: the Laplacian annihilates translations, A T = 0.01 T
    r = np.random.default_rng(3).standard_normal(matrix.shape[0]).reshape(-1, 3)
    r -= r.mean(axis=0)  # no momentum
    correction = amg.stand_in_correction(matrix, exact, 0.3)
    z = correction @ r.ravel()
    unprojected = correction.blocks @ r.ravel()
    # Rounding of sums over 208 nodes of entries of order 1: 1e-12 of the largest entry.
    assert np.abs(z.reshape(-1, 3).sum(axis=0)).max() <= 1e-12 * np.abs(z).max()
    assert np.abs(unprojected.reshape(-1, 3).sum(axis=0)).max() > 1e-3 * np.abs(unprojected).max()


def test_the_study_runs_each_weight_and_puts_the_default_back(monkeypatch, capsys):
    """benchmarks/study_stand_in.py at a tiny size: a row per rung and nu with a column per weight, and the module's
    weight as it was afterwards (each run sets its own)."""
    import importlib.util
    import sys
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "benchmarks" / "study_stand_in.py"
    spec = importlib.util.spec_from_file_location("study_stand_in", path)
    study = importlib.util.module_from_spec(spec)
    monkeypatch.setitem(sys.modules, spec.name, study)
    spec.loader.exec_module(study)
    default = amg.STAND_IN_CORRECTION
    seen = []
    original = study.iterations

    def logged(rung, nu, weight, **options):
        seen.append((rung, nu, weight))
        return original(rung, nu, weight, **options)

    monkeypatch.setattr(study, "iterations", logged)
    study.main(["--rungs", "smoothed", "--nu", "0.3", "0.45", "--weights", "0", "0.3", "--cells", "4", "1", "1",
                "--steps", "3"])
    assert seen == [("smoothed", nu, weight) for nu in (0.3, 0.45) for weight in (0.0, 0.3)]
    assert amg.STAND_IN_CORRECTION == default
    rows = [line for line in capsys.readouterr().out.splitlines() if line.startswith("smoothed")]
    assert len(rows) == 2 and all(row.count("(") == 2 for row in rows)
    study.main(["--build-cost", "--cells", "4", "1", "1"])
    assert "one V-cycle" in capsys.readouterr().out
