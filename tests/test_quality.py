"""Tet quality figures: known values on known tets, and refusal of inverted or flat tets."""

import numpy as np
import pytest

from meshing.quality import (POOR_DIHEDRAL_DEGREES, QualitySummary, min_dihedral_angles, quality_summary,
                             radius_ratios, tet_volumes)
from conftest import cube_mesh

REGULAR = np.array([[1.0, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]])
REGULAR_TET = np.array([[0, 1, 3, 2]])  # positively oriented order
CORNER = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])


def test_regular_tet_scores_best():
    # Regular tet: dihedral arccos(1/3) = 70.5288 deg, radius ratio 1; 1e-12 is round-off.
    assert min_dihedral_angles(REGULAR, REGULAR_TET)[0] == pytest.approx(np.degrees(np.arccos(1 / 3)), abs=1e-12)
    assert radius_ratios(REGULAR, REGULAR_TET)[0] == pytest.approx(1.0, abs=1e-12)
    # Edge 2 sqrt(2): V = a^3 / (6 sqrt 2) = 8/3.
    assert tet_volumes(REGULAR, REGULAR_TET)[0] == pytest.approx(8 / 3, rel=1e-14)


def test_corner_tet_known_values():
    # The unit corner tet: smallest dihedral arccos(1/sqrt 3) = 54.7356 deg at the slanted face;
    # r_in = 1/(3 + sqrt 3), R = sqrt(3)/2, so 3 r_in / R = 2 sqrt(3) / (3 + sqrt 3) = 0.7321.
    assert min_dihedral_angles(CORNER, [[0, 1, 2, 3]])[0] == pytest.approx(np.degrees(np.arccos(1 / np.sqrt(3))))
    assert radius_ratios(CORNER, [[0, 1, 2, 3]])[0] == pytest.approx(2 * np.sqrt(3) / (3 + np.sqrt(3)))


def test_sliver_scores_poorly():
    # Four nearly coplanar points (a square lifted by 1e-3 at one corner): both figures near 0.
    sliver = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 1e-3], [0, 1, 0]])
    tet = [[0, 1, 2, 3]] if np.linalg.det(sliver[1:] - sliver[0]) > 0 else [[0, 1, 3, 2]]
    assert min_dihedral_angles(sliver, tet)[0] < 1.0
    assert radius_ratios(sliver, tet)[0] < 0.01


@pytest.mark.parametrize("tets, what", [([[0, 2, 1, 3]], "inverted"), ([[0, 1, 2, 2]], "zero volume")])
def test_inverted_or_flat_tets_are_errors(tets, what):
    for function in (tet_volumes, min_dihedral_angles, radius_ratios, quality_summary):
        with pytest.raises(ValueError, match="inverted or of zero volume, first is tet 0"):
            function(CORNER, tets)


def test_summary_of_a_kuhn_cube():
    mesh = cube_mesh((2, 2, 2))
    summary = quality_summary(mesh)
    assert isinstance(summary, QualitySummary)
    assert summary.tet_count == 48
    assert summary.volume_total == pytest.approx(1.0, rel=1e-14)  # round-off of 48 determinants
    # Every Kuhn tet is congruent: min dihedral 45 deg (1e-9: arccos near its flat spot loses digits).
    assert summary.dihedral_min == pytest.approx(45.0, abs=1e-9)
    assert summary.dihedral_p1 == pytest.approx(45.0, abs=1e-9)
    assert summary.poor_dihedral_count == 0 and summary.poor_radius_ratio_count == 0
    text = str(summary)
    assert "tets: 48" in text and "min dihedral angle" in text and f"below {POOR_DIHEDRAL_DEGREES:g}" in text
