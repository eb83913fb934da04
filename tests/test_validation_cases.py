"""The validation cases, the spring/FEM comparison and the studies' measuring tools."""

import numpy as np
import pytest

from meshing import structured_box
from validation.boundary import Box, Traction
from validation.cases import (CASE_NAMES, build_case, check_held, hanging_bar, own_mesh_case, parse_region,
                              uniaxial_compression)
from validation.compare import RULES, compare_static
from volspring.assembly import stiffness_matrix
from validation.springs import (case_scene, effective_constants, spring_frequencies, spring_model,
                                spring_static, traction_forces, uniform_stiffness)
from validation.studies import fit_rate, pareto_front, speed_study
from volspring import Material, Model


@pytest.fixture
def cache_folder(tmp_path):
    return tmp_path / "fem-cache"


def test_structured_box_counts_and_volume():
    mesh = structured_box((4, 3, 2), (2.0, 1.5, 1.0))
    assert mesh.node_count == 5 * 4 * 3
    assert mesh.tet_count == 6 * 4 * 3 * 2
    assert mesh.volume == pytest.approx(3.0, rel=1e-12)  # exact up to round-off
    assert structured_box((4, 3, 2), (2.0, 1.5, 1.0), pattern="kuhn").node_count == mesh.node_count
    with pytest.raises(ValueError, match="pattern"):
        structured_box((1, 1, 1), (1, 1, 1), pattern="diagonal")


@pytest.mark.parametrize("name", [n for n in CASE_NAMES if n != "own_mesh"])
def test_cases_stay_small_deformation(name, cache_folder):
    case = build_case(name, quick=True)
    if case.kind == "modes":
        assert case.analytic["first_frequency_hz"] == pytest.approx(8.848, rel=1e-3)  # Euler-Bernoulli, by hand
        return
    result = compare_static(case, rules=("van_gelder",), elements=("P2",), folder=cache_folder).results
    size = float(np.ptp(case.mesh.points, axis=0).max())
    # The cases are set to about 0.5% of the length; 1% is the small-deformation bound the issue asks for.
    # The compressed cube moves by its 1% strain plus the lateral bulge: sqrt(1 + 2 (0.3)^2) = 1.09%.
    bound = 0.011 if name == "uniaxial_compression" else 0.01
    assert result["fem"]["P2"]["max_displacement_m"] <= bound * size
    assert "warning" not in result


def test_mirrored_mesh_removes_the_sideways_sway_of_springs():
    """On the plain Kuhn grid every cell's springs lean the same way: a hanging bar sways sideways."""
    sway = {}
    for pattern in ("mirrored", "kuhn"):
        case = hanging_bar(per_width=2)
        mesh = structured_box(case.cells, (0.1, 0.1, 1.0), pattern=pattern)
        case = type(case)(**{**case.__dict__, "mesh": mesh, "tip_nodes": Box.plane("z", 0.0)(mesh.points)})
        u = spring_static(case, spring_model(mesh, case.material, "van_gelder")).displacement[case.tip_nodes]
        sway[pattern] = np.abs(u[:, :2].mean(axis=0)).max() / abs(u[:, 2].mean())
    assert sway["mirrored"] < 1e-8   # symmetric mesh: zero up to round-off
    assert sway["kuhn"] > 0.1        # measured 0.47: a large, systematic artefact


def test_newton_spring_solve_agrees_with_a_linear_solve_at_small_deformation():
    """Validation's answer is volspring's Newton solve; at 0.5% deflection it must equal K u = f."""
    from scipy.sparse.linalg import spsolve

    case = build_case("cantilever_gravity", quick=True)
    model = spring_model(case.mesh, case.material, "lloyd")
    newton = spring_static(case, model).displacement
    scene = case_scene(case, model)
    free = ~scene.held.ravel()
    K = stiffness_matrix(model).tocsr()[free][:, free]
    x = model.rest_positions
    linear = np.zeros(x.size)
    linear[free] = spsolve(K.tocsc(), scene.external_forces(x, np.zeros_like(x), 0.0).ravel()[free])
    # Geometric nonlinearity at 0.5% deflection is O(rotation^2) ~ 1e-4 relative; 1e-2 leaves room.
    assert np.abs(newton.ravel() - linear).max() < 1e-2 * np.abs(linear).max()


def test_rest_stiffness_has_the_rigid_motions_as_null_space():
    mesh = structured_box((2, 2, 2), (1.0, 1.0, 1.0))
    K = stiffness_matrix(spring_model(mesh, Material(1e6, 0.3, 1000.0), "van_gelder"))
    x = mesh.points - mesh.points.mean(axis=0)
    motions = [np.tile(np.eye(3)[c], (mesh.node_count, 1)) for c in range(3)]
    motions += [np.cross(np.eye(3)[c], x) for c in range(3)]
    scale = abs(K).max()
    for motion in motions:
        assert np.abs(K @ motion.ravel()).max() < 1e-10 * scale  # round-off of sums of k r r^T terms
    assert (np.linalg.eigvalsh(K.toarray()) > -1e-8 * scale).all()  # positive semi-definite


def test_traction_forces_total_the_load():
    mesh = structured_box((3, 2, 2), (1.0, 0.2, 0.1))
    forces = traction_forces(mesh, [Traction(Box.plane("x", 1.0), (0.0, 0.0, -500.0))])
    np.testing.assert_allclose(forces.sum(axis=0), [0.0, 0.0, -500.0 * 0.2 * 0.1], rtol=1e-12)
    assert np.count_nonzero(np.abs(forces).sum(axis=1)) == 3 * 3  # only the 9 nodes of the face x = 1


def test_spring_frequency_of_one_spring():
    model = Model.from_arrays([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], [1.0, 2.0, 1.0, 1.0],
                                    [[0, 1], [0, 2], [0, 3]], stiffness=50.0)
    held = np.array([True, False, True, True])
    # Node 1 (mass 2) on one spring along x: f = sqrt(k / m) / 2 pi; its other directions have no stiffness.
    frequencies, shapes = spring_frequencies(model, held, count=3)
    assert frequencies[-1] == pytest.approx(np.sqrt(50.0 / 2.0) / (2 * np.pi), rel=1e-10)
    assert np.abs(shapes[-1][held]).max() == 0.0


@pytest.mark.parametrize("rule", RULES)
def test_cauchy_limit_one_effective_nu_whatever_is_asked(rule):
    mesh = structured_box((3, 3, 3), (1.0, 1.0, 1.0))
    measured = {nu: effective_constants(mesh, spring_model(mesh, Material(1e6, nu, 1000.0), rule))
                for nu in (0.3, 0.45)}
    # The rules use E only: the same network, the same nu, to round-off.
    assert measured[0.3]["nu"] == pytest.approx(measured[0.45]["nu"], abs=1e-12)
    # ... and not what was asked: the network's own nu lies in 0.08-0.25 (REFERENCE.md section 2).
    assert 0.05 < measured[0.45]["nu"] < 0.26
    assert abs(measured[0.45]["nu"] - 0.45) > 0.15
    # Volume strain per strain follows the network's nu, not 1 - 2 x 0.45 = 0.1: several times too much.
    assert measured[0.45]["volume_strain_per_axial_strain"] > 4 * (1 - 2 * 0.45)


def test_uniform_rule_uses_the_mean_van_gelder_constant():
    mesh = structured_box((2, 1, 1), (1.0, 0.5, 0.5))
    material = Material(1e6, 0.3, 1000.0)
    model = spring_model(mesh, material, "uniform")
    assert np.allclose(model.stiffness, uniform_stiffness(mesh, material))
    assert uniform_stiffness(mesh, material) == pytest.approx(
        Model.from_mesh(mesh, material, rule="van_gelder").stiffness.mean())


def test_compression_runs_volspring_static_solve_on_sliding_supports_and_fem_matches_the_closed_form(cache_folder):
    case = uniaxial_compression(cells=2, nu=0.45)
    result = compare_static(case, rules=("lloyd",), elements=("P1",), folder=cache_folder).results
    assert result["springs"]["lloyd"]["solver"] == "newton"  # sliding supports run through volspring's own solve
    # Uniform strain: P1 is exact, the linearised volume change is (1 - 2 nu) eps V and the moved mesh's
    # volume (1 + eps)(1 - nu eps)^2 V - V; 1e-9 is round-off of the sparse solve.
    exact, eps = case.analytic["volume_change_m3"], -0.01
    assert result["fem"]["P1"]["volume_change_m3"] == pytest.approx(exact, rel=1e-9)
    moved = (1 + eps) * (1 - 0.45 * eps) ** 2 - 1
    assert result["fem"]["P1"]["deformed_volume_change_m3"] == pytest.approx(moved, rel=1e-9)
    assert abs(result["springs"]["lloyd"]["volume_change_error_vs_analytic"]) > 1.0  # springs lose far more


def test_parse_region_forms():
    mesh = structured_box((2, 2, 2), (2.0, 1.0, 1.0))
    assert parse_region("xmax", mesh)(mesh.points).sum() == 9
    assert parse_region("x < 0.5", mesh)(mesh.points).sum() == 9
    assert parse_region("z>0.9", mesh)(mesh.points).sum() == 9
    assert parse_region("box:-1,-1,-1,0,1,1", mesh)(mesh.points).sum() == 9
    for bad in ("left", "x<abc", "box:1,2,3"):
        with pytest.raises(ValueError, match="region"):
            parse_region(bad, mesh)


def test_own_mesh_errors():
    mesh = structured_box((4, 1, 1), (1.0, 0.25, 0.25))
    material = Material(1e6, 0.3, 1000.0)
    with pytest.raises(ValueError, match="contains no mesh node"):
        own_mesh_case(mesh, parse_region("x<-1", mesh), material=material)
    with pytest.raises(ValueError, match="one line"):  # an edge of the box: rotation about it is free
        check_held(mesh, (mesh.points[:, 0] == 0) & (mesh.points[:, 1] == 0))
    with pytest.raises(ValueError, match="nu = 0.5"):
        Material(1e6, 0.5, 1000.0)
    case = own_mesh_case(mesh, parse_region("xmin", mesh), material=material)
    assert case.kind == "static" and case.tip_nodes is None


def test_fit_rate_and_pareto_front():
    n = np.array([10.0, 80.0, 640.0])
    assert fit_rate(n, 3.0 * n**-0.5) == pytest.approx(-0.5, rel=1e-12)
    assert fit_rate([10.0], [1.0]) is None
    assert pareto_front([1.0, 2.0, 3.0, 0.5], [0.1, 0.2, 0.01, np.nan]) == [0, 2]


def test_speed_study_flags_unstable_steps_and_measures_the_frequency(cache_folder):
    study = speed_study(per_height=1, steps={"symplectic_euler": (0.9, 1.1)}, duration=0.3, drag_rate=30.0,
                        folder=cache_folder)
    stable, unstable = study["runs"]
    assert stable["stable"] and not unstable["stable"]
    # Below the critical step symplectic Euler's frequency error is (h omega_1)^2-small; the fit of the
    # damped modal trajectory is good to about 0.2% (measured 0.1%).
    assert abs(stable["first_frequency_error"]) < 5e-3
    # exp(-c T / 2) = exp(-4.5) of the initial amplitude is left at the end: 1% of the deflection.
    assert abs(stable["settled_deflection_error"]) < 2e-2
    # A diverged run's wall time is per simulated second it reached, not per second asked.
    assert unstable["simulated_s"] < study["duration_s"] <= stable["simulated_s"] < study["duration_s"] + stable["dt_s"]
    assert unstable["wall_seconds_per_simulated_second"] == pytest.approx(
        unstable["wall_seconds"] / unstable["simulated_s"], rel=1e-12)


def test_speed_study_runs_periods_of_the_loaded_mode_with_a_drag_that_settles(cache_folder):
    study = speed_study(per_height=1, steps={"implicit_euler": (100.0,)}, periods=3.0, folder=cache_folder)
    # The duration is three periods of the spring model's loaded mode, and the drag leaves 5e-5 (the
    # default residual_amplitude) of the motion at its end: both exact by construction.
    assert study["duration_s"] == pytest.approx(3.0 / study["spring_first_frequency_hz"], rel=1e-12)
    assert study["residual_amplitude"] == pytest.approx(5e-5, rel=1e-12)
    (run,) = study["runs"]
    assert run["stable"] and run["simulated_s"] >= study["duration_s"]
    # 100 x 2 / omega_max is far above the loaded mode's accuracy limit but settles: implicit Euler
    # damps the oscillation, so the end state is the equilibrium to well below the 5e-5 left by the drag.
    assert abs(run["settled_deflection_error"]) < 5e-5
