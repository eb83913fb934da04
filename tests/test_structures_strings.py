"""Strings and hair: angle and dihedral springs, the builders, and their physics against analytic answers.

- AngleSprings / DihedralSprings: forces are minus the energy gradient, blocks the Hessian (exact for
  angles, Gauss-Newton for dihedrals: exact at rest), rotation invariance, PSD projection;
- a hanging chain pinned at both ends against an independent shooting solve of the same discrete
  chain of extensible (Hooke) links;
- a taut string's fundamental against f1 = c / (2 L), c = sqrt(T / rho);
- a clamped horizontal strand against the cantilever q L^4 / (8 EI);
- a curly strand keeps its curl under its own weight (the coil-spring estimate sets the scale);
- implicit Euler stays stable far above the explicit limit of stiff bending;
- the examples run and write line series.
"""

from __future__ import annotations


import numpy as np
import pytest
from conftest import dense_blocks, energy_gradient, load_example
from scipy.optimize import fsolve

from volspring import Drag, Gravity, Pins, Scene, State
from volspring.assembly import stiffness_matrix
from volspring.elements import AngleSprings, DihedralSprings
from volspring.elements.base import _block_product
from volspring.integrators import make_integrator
from volspring.modes import solve_modes
from volspring.output.paraview import read_pvd
from volspring.simulate import simulate
from volspring.statics import solve_static
from volspring.structures import hair, strand_points, string

RNG_SEED = 20240611



def _angle_sets(rng):
    triples = np.array([[0, 1, 2], [1, 2, 3], [2, 3, 4], [3, 4, 5], [5, 6, 7], [7, 2, 0]])
    stiffness = rng.uniform(0.5, 2.0, len(triples))
    return {"bent_rest": AngleSprings(8, triples, stiffness, rng.uniform(0.2, 3.0, len(triples))),
            "straight_rest": AngleSprings(8, triples, stiffness, np.pi)}


# ---------------------------------------------------------------------- the element sets
@pytest.mark.parametrize("name", ["bent_rest", "straight_rest"])
def test_angle_forces_are_the_energy_gradient_and_blocks_its_hessian(name):
    rng = np.random.default_rng(RNG_SEED)
    angles = _angle_sets(rng)[name]
    x = rng.standard_normal((8, 3))
    forces = angles.forces(x)
    # Central differences at h = 1e-6 on O(1) energies: truncation h^2 ~ 1e-12, round-off 1e-16 / h ~ 1e-10.
    assert np.abs(forces + energy_gradient(angles, x)).max() <= 1e-8 * np.abs(forces).max()
    u, h = rng.standard_normal(x.shape), 1e-6
    exact = _block_product(angles, angles.stiffness_blocks(x, clamp_compression=False), u)
    differenced = -(angles.forces(x + h * u) - angles.forces(x - h * u)) / (2 * h)
    assert np.abs(exact - differenced).max() <= 1e-8 * np.abs(differenced).max()


@pytest.mark.parametrize("offset", [0.0, 1e-9, 1e-5, 1e-2])
def test_a_straight_rest_is_smooth_where_the_strand_is_straight(offset):
    """At and near a straight line (theta = theta0 = pi) forces are finite and the Hessian matches differences."""
    rng = np.random.default_rng(RNG_SEED + 1)
    x = np.column_stack([np.arange(5.0), np.zeros(5), np.zeros(5)]) + offset * rng.standard_normal((5, 3))
    angles = AngleSprings(5, [[0, 1, 2], [1, 2, 3], [2, 3, 4]], 1.0, np.pi)
    u, h = rng.standard_normal(x.shape), 1e-6
    exact = _block_product(angles, angles.stiffness_blocks(x, clamp_compression=False), u)
    differenced = -(angles.forces(x + h * u) - angles.forces(x - h * u)) / (2 * h)
    assert np.isfinite(angles.forces(x)).all()
    # Same differencing budget as above (O(1) stiffness k / |a|^2 = 1 N/m).
    assert np.abs(exact - differenced).max() <= 1e-8 * np.abs(differenced).max()
    if offset == 0.0:  # the straight strand's transverse stiffness: k |1 -2 1|^2 / l^2 = 6 N/m on the middle node
        blocks = angles.stiffness_blocks(x, clamp_compression=False)
        assert blocks[0, 4, 1, 1] == pytest.approx(4.0, rel=1e-12)  # (j, j) block of one joint: k (2 / l)^2


def test_dihedral_forces_are_the_gradient_and_gauss_newton_is_the_hessian_at_rest():
    rng = np.random.default_rng(RNG_SEED + 2)
    x = rng.standard_normal((7, 3))
    quads = np.array([[0, 1, 2, 3], [1, 2, 3, 4], [6, 5, 0, 2]])
    twisted = DihedralSprings(7, quads, rng.uniform(0.5, 2.0, 3), rng.uniform(-3.0, 3.0, 3))
    forces = twisted.forces(x)
    # Same differencing budget as the angle springs.
    assert np.abs(forces + energy_gradient(twisted, x)).max() <= 1e-8 * np.abs(forces).max()
    at_rest = DihedralSprings.at_rest(x, quads, 1.0)
    u, h = rng.standard_normal(x.shape), 1e-6
    exact = _block_product(at_rest, at_rest.stiffness_blocks(x), u)
    differenced = -(at_rest.forces(x + h * u) - at_rest.forces(x - h * u)) / (2 * h)
    assert np.abs(exact - differenced).max() <= 1e-8 * np.abs(differenced).max()
    # Away from rest Gauss-Newton drops k (psi - psi0) d2psi: the negative control that the check above can fail.
    gauss_newton = _block_product(twisted, twisted.stiffness_blocks(x), u)
    full = -(twisted.forces(x + h * u) - twisted.forces(x - h * u)) / (2 * h)
    assert np.abs(gauss_newton - full).max() > 1e-2 * np.abs(full).max()


def test_bending_energy_and_forces_turn_with_a_rotation():
    from scipy.spatial.transform import Rotation

    rng = np.random.default_rng(RNG_SEED + 3)
    x = rng.standard_normal((8, 3))
    rotation = Rotation.from_rotvec([0.4, -1.1, 0.7]).as_matrix()
    turned = x @ rotation.T + np.array([1.0, -2.0, 3.0])
    quads = np.array([[0, 1, 2, 3], [4, 5, 6, 7]])
    for element_set in (*_angle_sets(rng).values(), DihedralSprings(8, quads, 1.0, 0.3)):
        # Rotating changes round-off only: 1e-12 relative on O(1) values.
        assert element_set.energy(turned) == pytest.approx(element_set.energy(x), rel=1e-12)
        np.testing.assert_allclose(element_set.forces(turned), element_set.forces(x) @ rotation.T,
                                   atol=1e-12 * np.abs(element_set.forces(x)).max())
        assert np.abs(element_set.forces(x).sum(axis=0)).max() <= 1e-12 * np.abs(element_set.forces(x)).max()


def test_projected_angle_blocks_are_symmetric_positive_semidefinite_and_exact_ones_are_not():
    rng = np.random.default_rng(RNG_SEED + 4)
    angles = _angle_sets(rng)["bent_rest"]
    x = rng.standard_normal((8, 3))
    projected = np.linalg.eigvalsh(dense_blocks(angles, angles.stiffness_blocks(x), 8))
    exact = np.linalg.eigvalsh(dense_blocks(angles, angles.stiffness_blocks(x, clamp_compression=False), 8))
    # Zero eigenvalues (rigid modes, clamped directions) come out at round-off: 1e-12 relative.
    assert projected.min() >= -1e-12 * projected.max()
    assert exact.min() < -1e-3 * exact.max()  # a bent joint away from rest is indefinite: the projection acts


def test_bad_joints_are_refused_with_the_offender_named():
    with pytest.raises(ValueError, match=r"triples\[1\] = \[1, 2, 1\] repeats a node"):
        AngleSprings(3, [[0, 1, 2], [1, 2, 1]], 1.0, np.pi)
    with pytest.raises(ValueError, match=r"rest_angles\[0\] = 4.0 rad is not in \[0, pi\]"):
        AngleSprings(3, [[0, 1, 2]], 1.0, 4.0)
    with pytest.raises(ValueError, match=r"stiffness\[0\] = -1.0"):
        AngleSprings(3, [[0, 1, 2]], -1.0, np.pi)
    with pytest.raises(ValueError, match="count = 1 nodes"):
        string([0, 0, 0], [1, 0, 0], count=1, mass=1.0, stiffness=1.0)
    with pytest.raises(ValueError, match="linear_density= .* or mass="):
        string([0, 0, 0], [1, 0, 0], count=3, stiffness=1.0)
    with pytest.raises(ValueError, match="curl_pitch"):
        strand_points([0, 0, 0], [0, 0, -1], 0.1, 10, curl_radius=0.01)


# ---------------------------------------------------------------------- strings
def test_a_chain_pinned_at_both_ends_hangs_as_the_discrete_catenary():
    """Independent answer: the same discrete chain solved by shooting (scipy fsolve on two unknowns).

    Each link carries a tension vector (H, V_i); at node i + 1 the weight m g raises V by m g, and the
    link's length is l0 + T / k (extensible, Hooke). H and V_0 are found so the chain ends at the
    second pin. Node masses are rho L / N inside (half at the pinned ends, which carry no link)."""
    count, span, rest, density, axial = 21, 1.0, 1.2, 0.5, 2000.0
    chain = string([0, 0, 0], [span, 0, 0], count=count, linear_density=density, axial_stiffness=axial,
                   rest_length=rest)
    guess = chain.rest_positions.copy()
    guess[:, 2] = -0.3 * np.sin(np.pi * guess[:, 0])  # start sagging: a straight slack chain has no stiffness
    result = solve_static(Scene(chain, forces=[Gravity()], pins=Pins([0, count - 1])), x0=guess, solver="direct")
    links, g = count - 1, 9.81
    node_weight, l0 = density * span / links * g, rest / links
    k = axial / l0

    def shape(unknowns):
        H, V = unknowns
        points = [np.zeros(2)]
        for _ in range(links):
            T = np.hypot(H, V)
            points.append(points[-1] + (l0 + T / k) * np.array([H, V]) / T)
            V += node_weight
        return np.array(points)

    solution = fsolve(lambda p: shape(p)[-1] - [span, 0.0], [3.0, -5.0], xtol=1e-13)
    expected = shape(solution)
    # Both solve the same equations to round-off: Newton to rtol 1e-8 of the load, fsolve to 1e-13:
    # positions agree to 1e-9 m on a 1 m chain (measured 2e-16).
    np.testing.assert_allclose(result.x[:, [0, 2]], expected, atol=1e-9)
    assert np.abs(result.x[:, 1]).max() == 0.0
    sag = -expected[:, 1].min()
    assert 0.25 < sag < 0.45  # a slack chain (1.2 m over 1 m) sags by a third of its span: not a flat line


@pytest.mark.parametrize("count", [11, 41])
def test_a_taut_string_sounds_at_c_over_2l(count):
    """f1 = c / (2 L), c = sqrt(T / rho); the lumped chain of N links gives (2 N / pi) sin(pi / (2 N)) of it."""
    length, density, tension = 1.0, 0.01, 10.0
    taut = string([0, 0, 0], [length, 0, 0], count=count, linear_density=density, axial_stiffness=1e4,
                  tension=tension)
    modes = solve_modes(Scene(taut, pins=Pins([0, count - 1])), count=4)
    f1 = np.sqrt(tension / density) / (2 * length)
    links = count - 1
    discrete = (2 * links / np.pi) * np.sin(np.pi / (2 * links))
    # The two transverse polarisations; the discrete dispersion exactly (eigh: round-off 1e-12).
    np.testing.assert_allclose(modes.frequencies[:2] / f1, discrete, rtol=1e-10)
    # Against the continuum: 1 - discrete ~ pi^2 / (24 N^2) (0.4% at N = 10, 0.03% at N = 40).
    assert abs(modes.frequencies[0] / f1 - 1) <= 1.01 * np.pi**2 / (24 * links**2)
    # The second harmonic near 2 f1 (the negative control: a string without tension has f = 0).
    assert modes.frequencies[2] / f1 == pytest.approx(2 * (2 * links / np.pi) * np.sin(np.pi / links) / 2, rel=1e-10)


# ---------------------------------------------------------------------- hair
def _cantilever_tip(links, *, root="clamped"):
    EI, EA, density, length, g = 1e-1, 1e3, 0.01, 0.2, 9.81
    segment = length / links
    points = strand_points([-segment, 0, 0], [1, 0, 0], length + segment, links + 2)  # node 1 at the clamp x = 0
    strand = hair(points, bending_stiffness=EI, axial_stiffness=EA, linear_density=density, root=root)
    result = solve_static(Scene(strand, forces=[Gravity()], pins=Pins([0, 1])), solver="direct")
    return -result.x[-1, 2] / (density * g * length**4 / (8 * EI))


def test_a_clamped_horizontal_strand_sags_like_a_cantilever():
    """Tip deflection q L^4 / (8 EI) at small sag (here 1e-3 L: geometric nonlinearity ~1e-6)."""
    links = np.array([10, 20, 40])
    ratios = np.array([_cantilever_tip(n) for n in links])
    # The lumped chain is a trapezoid rule of the moment integral: measured ratio 1 + 1 / N^2 (1.01 at N = 10),
    # plus the sag's own -8e-7 nonlinearity.
    np.testing.assert_allclose(ratios, 1 + 1.0 / links**2, atol=2e-6)
    slope = np.polyfit(np.log(links), np.log(ratios - 1), 1)[0]
    assert slope == pytest.approx(-2.0, abs=0.05)  # second-order convergence
    # Negative control: a uniform EI / l at the clamp joint is too soft by half a segment: error ~2 / N.
    assert _cantilever_tip(20, root="free") - 1 > 0.05


def _curvature_and_torsion(x):
    """Discrete curvature (per joint) and torsion (per middle edge) of a polyline [1/m]."""
    edges = np.diff(x, axis=0)
    lengths = np.linalg.norm(edges, axis=1)
    tangents = edges / lengths[:, None]
    turn = np.arctan2(np.linalg.norm(np.cross(tangents[:-1], tangents[1:]), axis=1),
                      np.einsum("ij,ij->i", tangents[:-1], tangents[1:]))
    binormals = np.cross(tangents[:-1], tangents[1:])
    binormals /= np.linalg.norm(binormals, axis=1)[:, None]
    twist = np.arctan2(np.einsum("ij,ij->i", np.cross(binormals[:-1], binormals[1:]), tangents[1:-1]),
                       np.einsum("ij,ij->i", binormals[:-1], binormals[1:]))
    return turn / (0.5 * (lengths[:-1] + lengths[1:])), twist / lengths[1:-1]


def _settled_curl(torsional_stiffness):
    """A 10 cm curl (R = 5 mm, pitch 10 mm) hanging from a clamped root, settled by implicit Euler with drag."""
    radius, pitch, length, count = 5e-3, 10e-3, 0.1, 61
    density, EI, EA = 6.5e-6, 8e-7, 1.0
    points = strand_points([0, 0, 0], [0, 0, -1], length, count, curl_radius=radius, curl_pitch=pitch)
    strand = hair(points, bending_stiffness=EI, axial_stiffness=EA, linear_density=density,
                  torsional_stiffness=torsional_stiffness)
    scene = Scene(strand, forces=[Gravity(), Drag(rate=30.0)], pins=Pins([0, 1]))
    result = simulate(scene, "implicit_euler", duration=1.0, dt=2e-3, frame_dt=1.0, guard="off")
    return points, result.state, dict(radius=radius, pitch=pitch, length=length, density=density, EI=EI)


def test_a_curly_strand_keeps_its_curl_under_its_own_weight():
    """Measure: the largest relative change of the discrete curvature kappa and torsion tau along the
    strand (a helix has R = kappa / (kappa^2 + tau^2), pitch 2 pi tau / (kappa^2 + tau^2), so these bound
    the changes of radius and pitch). Scale: a coil spring under its axial load F has dkappa = F R sin(a) / EI and
    dtau = F R cos(a) / GJ (a the helix angle); with F the whole weight these are 6.5e-5 and 8.3e-4 of kappa0,
    tau0. The clamped root also carries the coil's weight off its axis, so we allow 3x these."""
    rest, state, p = _settled_curl(None)
    assert np.abs(state.v).max() < 1e-6  # settled: 1 s is 30 drag times
    kappa0, tau0 = _curvature_and_torsion(rest)
    kappa, tau = _curvature_and_torsion(state.x)
    alpha = np.arctan2(p["pitch"], 2 * np.pi * p["radius"])
    weight = p["density"] * 9.81 * p["length"]
    GJ = p["EI"] / 1.3
    kappa_scale = weight * p["radius"] * np.sin(alpha) / p["EI"] / kappa0.mean()
    tau_scale = weight * p["radius"] * np.cos(alpha) / GJ / np.abs(tau0.mean())
    assert np.abs(kappa - kappa0).max() / kappa0.mean() <= 3 * kappa_scale
    assert np.abs(tau - tau0).max() / np.abs(tau0.mean()) <= 3 * tau_scale
    # The curl did respond to the load (the measure is not blind): at least 0.3x the scale.
    assert np.abs(tau - tau0).max() / np.abs(tau0.mean()) >= 0.3 * tau_scale
    # Negative control: without twist springs the dihedrals are free and the curl falls out of shape.
    _, loose, _ = _settled_curl(0.0)
    _, loose_tau = _curvature_and_torsion(loose.x)
    assert np.abs(loose_tau - tau0).max() / np.abs(tau0.mean()) > 1.0


def test_implicit_euler_is_stable_far_above_the_explicit_limit_of_stiff_bending():
    points = strand_points([0, 0, 0], [1, 0, 0], 0.2, 21)
    strand = hair(points, bending_stiffness=1.0, axial_stiffness=1e3, linear_density=0.01)
    scene = Scene(strand, pins=Pins([0, 1]))
    free = np.ones(strand.node_count, dtype=bool)
    free[[0, 1]] = False
    K = stiffness_matrix(strand, free=free).toarray()
    m = np.repeat(strand.masses[free], 3)
    omega_max = np.sqrt(np.linalg.eigvalsh(K / np.sqrt(np.outer(m, m))).max())
    v0 = np.zeros((strand.node_count, 3))
    v0[2:, 2] = 0.01 * np.arange(1, strand.node_count - 1)
    start = State(points.copy(), v0, 0.0)

    def energy_after(name, dt, steps):
        integrator, state = make_integrator(name), start
        for _ in range(steps):
            state = integrator.step(scene, state, dt)
            if not np.isfinite(state.x).all():
                return np.inf
        return scene.kinetic_energy(state.v) + scene.potential_energy(state.x)

    initial = scene.kinetic_energy(v0)
    # 100x the symplectic limit 2 / omega_max: implicit Euler only loses energy (it damps every mode).
    assert energy_after("implicit_euler", 200.0 / omega_max, 50) <= initial
    # Negative control: symplectic Euler 5% above its limit grows without bound.
    assert energy_after("symplectic_euler", 1.05 * 2.0 / omega_max, 2000) > 1e3 * initial


# ---------------------------------------------------------------------- examples
@pytest.mark.parametrize("script, name", [("plucked_string", "string"), ("hair", "hair")])
def test_example_scripts_write_line_series(tmp_path, script, name):
    # examples/plucked_string.py, not string.py: run as a script, that name would shadow the standard library's string.
    example = load_example(script)
    assert example.main([str(tmp_path / "out"), "--quick"]) == 0
    frames = read_pvd(tmp_path / "out" / f"{name}_springs.pvd")
    quick = example.SETTINGS["quick"]
    assert len(frames) == round(quick["duration"] / quick["frame_dt"]) + 1  # frame 0 plus one per frame_dt
    import meshio

    lines = meshio.read(frames[-1][1])
    assert [block.type for block in lines.cells] == ["line"]
    assert np.isfinite(lines.points).all()
    assert (tmp_path / "out" / f"{name}.pc2").is_file()


# ---------------------------------------------------------------------- the closed-form projection of the angle Hessian
def _joint_matrices(blocks):
    """(e, 9, 9) -- each joint's node blocks (e, 9, 3, 3) as one matrix."""
    return blocks.reshape(-1, 3, 3, 3, 3).transpose(0, 1, 3, 2, 4).reshape(-1, 9, 9)


@pytest.mark.parametrize("name", ["bent_rest", "straight_rest"])
def test_projected_angle_blocks_are_the_eigen_projection_in_edge_units(name):
    """The closed form is what an eigh of each joint's 6 x 6 Hessian in (da / |a|, db / |b|) with the negative
    eigenvalues set to 0 gives, taken back to the nodes (the module docstring); and each joint's 9 x 9 is PSD."""
    rng = np.random.default_rng(RNG_SEED + 5)
    angles = _angle_sets(rng)[name]
    x = rng.standard_normal((8, 3))
    i, j, k = angles.triples.T
    la, lb = np.linalg.norm(x[j] - x[i], axis=1), np.linalg.norm(x[k] - x[j], axis=1)
    exact = angles.stiffness_blocks(x, clamp_compression=False).reshape(-1, 3, 3, 3, 3)
    scaled = np.zeros((len(la), 6, 6))  # the edge Hessian in units of the edge lengths
    scaled[:, :3, :3] = exact[:, 0, 0] * (la * la)[:, None, None]
    scaled[:, :3, 3:] = -exact[:, 0, 2] * (la * lb)[:, None, None]
    scaled[:, 3:, :3] = np.swapaxes(scaled[:, :3, 3:], 1, 2)
    scaled[:, 3:, 3:] = exact[:, 2, 2] * (lb * lb)[:, None, None]
    values, vectors = np.linalg.eigh(scaled)
    assert (values < 0).any(axis=1).all()  # away from rest every joint is indefinite: the projection acts
    clamped = (vectors * np.maximum(values, 0.0)[:, None, :]) @ np.swapaxes(vectors, 1, 2)
    incidence = np.array([[-1.0, 0.0], [1.0, -1.0], [0.0, 1.0]])  # nodes from edges: a = x_j - x_i, b = x_k - x_j
    lengths = np.stack([la, lb], axis=1)
    D = np.einsum("pr,xy,er->eprxy", incidence, np.eye(3), 1.0 / lengths).reshape(-1, 3, 2, 3, 3)
    D = D.transpose(0, 1, 3, 2, 4).reshape(-1, 9, 6)  # node displacements -> (da / |a|, db / |b|), transposed
    expected = D @ clamped @ np.swapaxes(D, 1, 2)
    projected = _joint_matrices(angles.stiffness_blocks(x))
    # Two routes to one matrix: eigh and the closed form agree to round-off (1e-12 relative; measured 5e-15).
    assert np.abs(projected - expected).max() <= 1e-12 * np.abs(expected).max()
    assert np.array_equal(projected, np.swapaxes(projected, 1, 2))  # exactly symmetric, by construction
    assert np.linalg.eigvalsh(projected).min() >= -1e-12 * np.abs(projected).max()  # PSD to round-off


@pytest.mark.parametrize("offset", [0.0, 1e-9, 1e-3])
def test_projected_angle_blocks_are_the_exact_hessian_at_rest(offset):
    """At rest the Hessian k grad theta grad theta^T is PSD and the projection leaves it alone; at a straight
    rest too (offset 0: no plane at all), and close to rest the projection moves it by O(delta) only."""
    rng = np.random.default_rng(RNG_SEED + 6)
    x = rng.standard_normal((8, 3))
    triples = np.array([[0, 1, 2], [1, 2, 3], [2, 3, 4], [3, 4, 5], [5, 6, 7], [7, 2, 0]])
    line = np.column_stack([np.arange(5.0), np.zeros(5), np.zeros(5)])
    for positions, joints in ((x, triples), (line, triples[:3])):
        at_rest = AngleSprings.at_rest(positions, joints, rng.uniform(0.5, 2.0, len(joints)))
        moved = positions + offset * rng.standard_normal(positions.shape)
        exact = _joint_matrices(at_rest.stiffness_blocks(moved, clamp_compression=False))
        projected = _joint_matrices(at_rest.stiffness_blocks(moved))
        # At rest: round-off (phi - phi0 ~ 1e-16); moved by 1e-9 or 1e-3: the clamped eigenvalues are O(k delta).
        assert np.abs(projected - exact).max() <= max(1e-12, 10 * offset) * np.abs(exact).max()
    # Negative control: far from rest the projection does change the Hessian.
    bent = AngleSprings(8, triples, 1.0, rng.uniform(0.2, 3.0, len(triples)))
    exact = _joint_matrices(bent.stiffness_blocks(x, clamp_compression=False))
    assert np.abs(_joint_matrices(bent.stiffness_blocks(x)) - exact).max() > 1e-2 * np.abs(exact).max()


def test_angle_linearization_products_and_straight_joints():
    """The linearization's dF/dx @ u (through the edge blocks) is the product with its node blocks; a joint
    exactly straight gives finite, PSD blocks whether its rest is straight or bent (a cone point)."""
    rng = np.random.default_rng(RNG_SEED + 7)
    angles = _angle_sets(rng)["bent_rest"]
    x, u = rng.standard_normal((8, 3)), rng.standard_normal((8, 3))
    linearization = angles.linearize(x, stiffness_scale=0.25)
    blocks = angles.stiffness_blocks(x)
    np.testing.assert_allclose(linearization.blocks, 0.25 * blocks, rtol=1e-15, atol=0)  # one scaling, round-off
    np.testing.assert_allclose(linearization.stiffness, blocks, rtol=0, atol=0)
    expected = -_block_product(angles, blocks, u)
    # Same sums in another order: round-off, 1e-12 relative.
    assert np.abs(linearization.dfdx_times(u) - expected).max() <= 1e-12 * np.abs(expected).max()
    line = np.column_stack([np.arange(3.0), np.zeros(3), np.zeros(3)])
    for rest in (np.pi, 2.0):
        joint = AngleSprings(3, [[0, 1, 2]], 1.0, rest)
        for clamp in (True, False):
            matrix = _joint_matrices(joint.stiffness_blocks(line, clamp_compression=clamp))[0]
            assert np.isfinite(matrix).all()
            if clamp:
                assert np.linalg.eigvalsh(matrix).min() >= -1e-12 * np.abs(matrix).max()
