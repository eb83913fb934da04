"""The exact diagonal blocks of the matrix-free sets (``diagonal_blocks``)."""

import numpy as np
import pytest
from conftest import cube_mesh

from volspring import Material, Model
from volspring.assembly import stiffness_matrix

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
