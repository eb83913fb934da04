"""The closed forms against published numbers and against each other."""

import numpy as np
import pytest

from validation import analytic


def test_cantilever_wavenumbers_match_the_tables():
    # beta_n L from every vibration handbook (e.g. Blevins, table 8-1), given to 4 decimals there.
    np.testing.assert_allclose(analytic.cantilever_wavenumbers(4), [1.8751, 4.6941, 7.8548, 10.9955], atol=5e-5)
    roots = analytic.cantilever_wavenumbers(8)
    # They solve cos x cosh x = -1 (to the 1e-14 brentq tolerance, amplified by cosh x ~ 1e10 at n = 8).
    np.testing.assert_allclose(np.cos(roots) * np.cosh(roots), -1.0, rtol=1e-3)
    # and approach (n - 1/2) pi.
    assert roots[-1] == pytest.approx(7.5 * np.pi, abs=1e-5)


def test_first_frequency_by_hand():
    # 1 m x 10 mm x 10 mm steel: f1 = 1.8751^2 / (2 pi) sqrt(E h^2 / (12 rho)) with L = 1; worked by hand.
    E, rho, h = 210e9, 7850.0, 0.01
    expected = 1.87510407**2 / (2 * np.pi) * np.sqrt(E * h**2 / (12 * rho))
    # 1e-8: the constant above is given to 9 digits.
    first = analytic.cantilever_frequencies(1.0, h, h, E=E, density=rho, count=1)[0]
    assert first == pytest.approx(expected, rel=1e-8)
    # Frequencies scale with h / L^2 (to round-off).
    f = analytic.cantilever_frequencies(2.0, h, 2 * h, E=E, density=rho, count=1)[0]
    assert f == pytest.approx(first / 2, rel=1e-12)


def test_deflections_by_hand():
    # P L^3 / 3EI with P = 1 N, L = 1 m, E = 12 Pa, b = h = 1 m (I = 1/12): exactly 1/3 m.
    assert analytic.cantilever_end_load_deflection(1, 1, 1, E=12.0, nu=0.25, force=1.0, shear=False) == pytest.approx(1 / 3)
    # Self-weight q L^4 / 8EI with q = rho g A = 1: 1/8.
    euler = analytic.cantilever_self_weight_deflection(1, 1, 1, E=12.0, nu=0.25, density=1.0, gravity=1.0, shear=False)
    assert euler == pytest.approx(1 / 8)
    # Timoshenko's shear term q L^2 / (2 kappa G A): G = 12 / 2.5 = 4.8, so 1 / (2 * 5/6 * 4.8) = 0.125.
    timoshenko = analytic.cantilever_self_weight_deflection(1, 1, 1, E=12.0, nu=0.25, density=1.0, gravity=1.0)
    assert timoshenko - euler == pytest.approx(0.125)


def test_volume_changes_agree():
    # Uniaxial: (1 + eps)(1 + lateral)^2 - 1 linearises to (1 - 2 nu) eps.
    eps, nu = 1e-6, 0.3
    exact = (1 + eps) * (1 + analytic.uniaxial_lateral_strain(eps, nu)) ** 2 - 1
    assert analytic.uniaxial_volume_strain(eps, nu) == pytest.approx(exact, rel=1e-5)  # O(eps) relative
    assert analytic.uniaxial_volume_strain(eps, 0.5) == 0.0  # incompressible
    # Hanging bar: volume change = (1 - 2 nu) * area * elongation.
    dv = analytic.hanging_bar_volume_change(2.0, 0.01, E=1e6, nu=0.25, density=1e3, gravity=10.0)
    assert dv == pytest.approx(0.5 * 0.01 * 1e3 * 10 * 4 / 2e6)
    # Bulk modulus: K = E / 3(1 - 2 nu) = lambda + 2 mu / 3.
    E, nu = 1e6, 0.3
    lam, mu = E * nu / ((1 + nu) * (1 - 2 * nu)), analytic.shear_modulus(E, nu)
    assert analytic.bulk_modulus(E, nu) == pytest.approx(lam + 2 * mu / 3)
