"""The springs+volume rung's calibration (volspring.ladder.network_moduli, volume_rung_moduli).

The issue's goals for this rung: effective nu within 0.03 of the asked value for nu 0.25-0.49 on the
project's meshes and the held-out shapes, and volume change within 10% of the exact (or of P2) at nu
0.49. Effective constants are those of a uniaxial stress test on a box
(:func:`validation.springs.effective_constants`). The comparison of calibrations behind the rung is
``benchmarks/study_volume_rung.py``.
"""

import numpy as np
import pytest

from meshing import jittered_cube, structured_box
from validation.springs import effective_constants
from volspring import Material, Model
from volspring.ladder import network_moduli, network_poisson_ratio

#: The issue's goal: effective nu within 0.03 of the asked one.
NU_TOLERANCE = 0.03
#: The issue's goal: volume change within 10% of the exact one (1 - 2 nu per axial strain) at nu 0.49.
VOLUME_TOLERANCE = 0.10


@pytest.fixture(scope="module")
def meshes():
    return {"structured 4^3 (uniaxial_compression)": structured_box((4, 4, 4), (1.0, 1.0, 1.0)),
            "jittered Delaunay 5^3": jittered_cube()}


def uniaxial(mesh, nu):
    return effective_constants(mesh, Model.from_mesh(mesh, Material(E=1e6, nu=nu, density=1000.0),
                                                     model="springs+volume"))


@pytest.mark.parametrize("nu", [0.25, 0.3, 0.45, 0.49])
def test_effective_poisson_ratio_is_the_asked_one(meshes, nu):
    for name, mesh in meshes.items():
        found = uniaxial(mesh, nu)["nu"]
        # NU_TOLERANCE is the goal. Measured: 0.240-0.259, 0.291-0.306, 0.441-0.447, 0.481-0.485;
        # the calibration before (the mean of all five deviatoric energies, boundary held): 0.16-0.17,
        # 0.23, 0.43, 0.48.
        assert found == pytest.approx(nu, abs=NU_TOLERANCE), name


def test_volume_change_per_axial_strain_at_nu_049(meshes):
    for name, mesh in meshes.items():
        ratio = uniaxial(mesh, 0.49)["volume_strain_per_axial_strain"] / (1.0 - 2.0 * 0.49)
        # VOLUME_TOLERANCE is the goal. Measured 0.99-1.00 of the exact 1 - 2 nu; before: 1.25-1.42.
        assert ratio == pytest.approx(1.0, abs=VOLUME_TOLERANCE), name


def test_refuses_a_poisson_ratio_below_the_networks_and_names_the_accurate_rung(meshes):
    for mesh in meshes.values():
        unit_springs = Model.from_mesh(mesh, Material(E=1.0, nu=0.3, density=1.0)).spring_elements
        own = network_poisson_ratio(*network_moduli(mesh, unit_springs))
        # The network's own nu under uniaxial stress along the axes: 0.11-0.19 (a tet network is not
        # isotropic; its mean over all shears would say 0.25).
        assert 0.05 < own < 0.25
        with pytest.raises(ValueError, match=rf"cannot reach nu = {own - 0.01:g} .*Use model='smoothed'"):
            Model.from_mesh(mesh, Material(E=1e6, nu=own - 0.01, density=1000.0), model="springs+volume")
        Model.from_mesh(mesh, Material(E=1e6, nu=own + 0.01, density=1000.0), model="springs+volume")


# ---------------------------------------------------------------------- slow: more meshes, held-out shapes
@pytest.mark.slow
@pytest.mark.parametrize("nu", [0.25, 0.3, 0.4, 0.45, 0.49])
def test_effective_constants_on_a_beam_and_a_finer_delaunay_cube(nu):
    from validation.cases import beam_cells

    meshes = {"beam 20x2x2": structured_box(beam_cells(1.0, 0.1, 2), (1.0, 0.1, 0.1)),
              "beam 10x1x1": structured_box(beam_cells(1.0, 0.1, 1), (1.0, 0.1, 0.1)),
              "jittered Delaunay 8^3": jittered_cube(8, seed=1)}
    for name, mesh in meshes.items():
        found = uniaxial(mesh, nu)
        # The goals (NU_TOLERANCE, VOLUME_TOLERANCE). Measured: nu 0.023 low at most (the 20x2x2
        # beam at 0.49: its lateral faces do not stay flat, so the face-mean nu reads low while its volume
        # change is within 4%); volume 0.96-0.99 at 0.49. Before: nu up to 0.12 low, volume 1.21-1.38.
        assert found["nu"] == pytest.approx(nu, abs=NU_TOLERANCE), name
        if nu == 0.49:
            ratio = found["volume_strain_per_axial_strain"] / (1.0 - 2.0 * nu)
            assert ratio == pytest.approx(1.0, abs=VOLUME_TOLERANCE), name


@pytest.mark.slow
@pytest.mark.parametrize("name", ["torus", "capsule", "l_bracket", "bunny"])
def test_held_out_shapes_have_the_asked_poisson_ratio_under_free_uniaxial_stress(name):
    """nu of the calibrated model as the whole shape, free, answers uniform uniaxial tractions along x, y, z."""
    from validation.heldout import heldout_mesh
    from volspring.assembly import stiffness_matrix
    from volspring.ladder import _free_probe

    mesh = heldout_mesh(name)
    for nu in (0.25, 0.3, 0.45, 0.49):
        model = Model.from_mesh(mesh, Material(E=1.0, nu=nu, density=1.0), model="springs+volume")
        compliance = _free_probe(mesh, stiffness_matrix(model))
        found = network_poisson_ratio(1.0 / (2.0 * compliance[:2].mean()), 1.0 / (3.0 * compliance[2]))
        # NU_TOLERANCE is the goal. Measured within 0.007 (with the boundary held instead: 0.006).
        assert found == pytest.approx(nu, abs=NU_TOLERANCE)


@pytest.mark.slow
def test_held_out_bunny_volume_change_under_gravity_matches_p2_at_nu_049():
    """The bunny on its base is squeezed as a whole: its net volume change is 8% of the sum of the
    compressed and stretched parts (|div u| integrated) at nu 0.49, 72% at 0.3. The other held-out
    shapes bend: their net volume change is 0.1-0.7% of that sum, a cancellation whose ratio to P2
    says little about the material (the torus: -6, the capsule: 15 at nu 0.49; the L-bracket 1.04)."""
    import scipy.sparse as sp
    from scipy.sparse.linalg import spsolve

    from validation.fem import solve_fem_static
    from validation.heldout import build_heldout_case
    from validation.springs import held_nodes
    from volspring.assembly import stiffness_matrix
    from volspring.elements.tet_kinematics import TetGradients

    case = build_heldout_case("bunny_gravity", nu=0.49)
    p2 = solve_fem_static(case.mesh, case.material_tuple, element="P2", solver="amg", tolerance=1e-10,
                          **case.fem_arguments())
    # The linear response, as P2's: the nonlinear solve's second-order volume of the ears' rotation is a
    # tenth of this small net change.
    model = Model.from_mesh(case.mesh, case.material, model="springs+volume")
    free = np.repeat(~held_nodes(case), 3)
    load = (model.masses[:, None] * np.asarray(case.gravity)).ravel()
    u = np.zeros(3 * model.node_count)
    u[free] = spsolve(sp.csc_matrix(stiffness_matrix(model)[free][:, free]), load[free])
    kinematics = TetGradients.at_rest(case.mesh.points, case.mesh.tets)
    volume = float(kinematics.volumes @ np.trace(kinematics.deformation(u.reshape(-1, 3)), axis1=1, axis2=2))
    # VOLUME_TOLERANCE is the goal (vs FEM). Measured 1.04; the calibration before gave 1.05: the
    # volume term, not the spring scale, sets a squeezed body's volume change.
    assert volume / p2.volume_change == pytest.approx(1.0, abs=VOLUME_TOLERANCE)
