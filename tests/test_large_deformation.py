"""Large deformation of the nonlinear rungs against nonlinear references (issue 11).

1. Uniaxial stretch and compression of a cube to axial strains of +-50% on the smoothed rung,
   lateral faces free, three symmetry planes sliding, the face x = L moved. The element reproduces
   a homogeneous deformation exactly (patch test), and the nodal volume ratio of a homogeneous F is
   det F, so the answer is the smoothed energy density psi(F) = mu |F - R|^2 + (lambda / 2)(det F - 1)^2
   at F = diag(1 + e, s, s), minimised over s by scipy (the same energy solved by another method):
   the lateral stretch s, the axial stress P_11 = d psi / d F_11 and so the reaction on the moved
   face. Each strain is reached in steps, each step's Newton starting from the last answer mapped
   affinely along x (the homogeneous branch; see the stability note below).
2. A cantilever 1 x 0.1 x 0.1 m bent by gravity until its tip moves ~21% of its length, against
   scikit-fem's compressible Neo-Hookean (validation.nonlinear) solved by Newton with P2 elements on
   the same mesh. At that deflection the strains are small (~4% at the root) and the rotations large,
   so the two materials agree and the nonlinear ratio smoothed / P2 must equal the linear one (the
   discretisation error), while linear theory is clearly off (the load case really is nonlinear).
3. Inversion: tets reflected or crushed by hand keep energy, forces and stiffness finite; the
   static solve (the exact Hessian, falling back to the projected stiffness where its step fails) and
   implicit steps bring them back to rest.

Stability note (measured, structured 3^3 cube): the homogeneous compressed state loses stability
near -50% for both the smoothed rung and Neo-Hookean P2 on the same mesh (smallest eigenvalue of
the exact stiffness / (mu L) at -40%, -50%, -70%: smoothed nu 0.3 +0.025, -0.004, -0.114; Neo-Hookean
P2 +0.007, -0.001, -0.043): the lateral faces buckle (a structural instability, not the material's).
From a jittered start Newton then finds a buckled state of lower energy (smoothed, nu 0.3, -50%:
14130 J against 14655 J), so the compression checks follow the homogeneous branch by continuation.
"""

from __future__ import annotations

import time
import warnings

import numpy as np
import pytest
import scipy.optimize
import scipy.sparse.linalg as spla

from meshing import TetMesh, structured_box, tetrahedralize
from meshing.shapes import box
from volspring import Gravity, Material, Model, Pins, Scene
from volspring.assembly import stiffness_matrix
from volspring.elements.tet_kinematics import TetGradients
from volspring.integrators.implicit import ImplicitEuler
from volspring.scene import State
from volspring.statics import solve_static
from volspring.supports import Prescribed, Sliding
from validation.boundary import Box, Clamp
from validation.fem import solve_fem_static
from validation.nonlinear import (lame_constants, neo_hookean_density, neo_hookean_stress, neo_hookean_tangent,
                                  neo_hookean_uniaxial, solve_neo_hookean_static)

EDGE = 1.0  # [m] the cube
E_CUBE = 1e5  # [Pa]
ON_PLANE = 1e-9  # [m] a node lies on a face of the unit cube (the meshes' faces are exact planes)
#: Newton's relative force residual on the cubes; the homogeneous answers come out at 1e-11 or better.
CUBE_RTOL = 1e-10


# ---------------------------------------------------------------------------- meshes
@pytest.fixture(scope="module")
def cubes():
    """The unit cube as a structured Kuhn mesh (3^3 cells, 64 nodes) and as an unstructured gmsh mesh
    (101 nodes, 311 tets of every shape)."""
    unstructured = tetrahedralize(box(EDGE, EDGE, EDGE), size=0.4, seed=1)
    return {"structured": structured_box((3, 3, 3), (EDGE, EDGE, EDGE)),
            "gmsh": TetMesh.compact(unstructured.points + EDGE / 2, unstructured.tets)}


def _symmetry_planes(points):
    return [Sliding(np.abs(points[:, axis]) < ON_PLANE, "xyz"[axis]) for axis in range(3)]


def _pulled_face(points):
    return np.flatnonzero(np.abs(points[:, 0] - EDGE) < ON_PLANE)


def _uniaxial_scene(model, strain):
    """The cube on three sliding symmetry planes, its face x = EDGE held at x = (1 + strain) EDGE."""
    points = model.rest_positions
    face = _pulled_face(points)
    target = points[face].copy()
    target[:, 0] = (1.0 + strain) * EDGE
    return Scene(model, supports=_symmetry_planes(points) + [Prescribed.at(face, "x", target)])


def _uniaxial_path(model, strains, *, jitter=0.0, seed=0):
    """[(strain, x, reaction)] along ``strains``: each static solve starts from the last answer
    stretched along x to the new strain (plus ``jitter`` [m] of seeded noise); reaction [N] is the
    total x-force the moved face's support exerts (minus the elastic forces on those nodes)."""
    rng = np.random.default_rng(seed)
    x, previous, answers = model.rest_positions.copy(), 0.0, []
    face = _pulled_face(model.rest_positions)
    for strain in strains:
        start = x.copy()
        start[:, 0] *= (1.0 + strain) / (1.0 + previous)
        start += jitter * rng.standard_normal(start.shape)
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # a division by zero or an overflow is a failure here
            x = solve_static(_uniaxial_scene(model, strain), x0=start, rtol=CUBE_RTOL).x
        answers.append((strain, x, -model.forces(x)[face, 0].sum()))
        previous = strain
    return answers


# ---------------------------------------------------------------------------- the reference
def _smoothed_density(F, mu, lam):
    """psi(F) = mu |F - R|^2 + lambda / 2 (det F - 1)^2, written again here from the singular values."""
    sigma = np.linalg.svd(F, compute_uv=False)
    if np.linalg.det(F) < 0:
        sigma[-1] = -sigma[-1]
    return mu * np.sum((sigma - 1.0) ** 2) + 0.5 * lam * (np.linalg.det(F) - 1.0) ** 2


def uniaxial_reference(strain, mu, lam):
    """(s, P_11): the lateral stretch minimising psi(diag(1 + strain, s, s)) and the axial stress there [Pa].

    scipy's bounded scalar minimiser finds the minimum; as psi is flat there (it resolves s to ~1e-8
    only), Brent's root finder then polishes s on d psi / d s = 4 mu (s - 1) + 2 lambda (J - 1) a s
    (a = 1 + strain, J = a s^2, R = I for a positive diagonal F). P_11 = 2 mu (a - 1) + lambda (J - 1) s^2.
    """
    a = 1.0 + strain
    found = scipy.optimize.minimize_scalar(lambda s: _smoothed_density(np.diag([a, s, s]), mu, lam),
                                           bounds=(0.2, 5.0), method="bounded", options={"xatol": 1e-12})
    assert found.success

    def slope(s):
        return 4.0 * mu * (s - 1.0) + 2.0 * lam * (a * s * s - 1.0) * a * s

    s = scipy.optimize.brentq(slope, found.x * (1 - 1e-4), found.x * (1 + 1e-4), xtol=1e-15)
    return s, 2.0 * mu * (a - 1.0) + lam * (a * s * s - 1.0) * s * s


def test_the_reference_minimiser_is_a_minimum_of_the_density():
    mu, lam = lame_constants(E_CUBE, 0.45)
    for strain in (0.5, -0.5):
        s, P11 = uniaxial_reference(strain, mu, lam)
        a = 1.0 + strain
        psi = _smoothed_density(np.diag([a, s, s]), mu, lam)
        for ds in (1e-4, -1e-4):
            assert _smoothed_density(np.diag([a, s + ds, s + ds]), mu, lam) > psi
        h = 1e-6  # central difference of psi along F_11: O(h^2) + eps psi / h ~ 1e-6 of P_11 at most
        numeric = (_smoothed_density(np.diag([a + h, s, s]), mu, lam)
                   - _smoothed_density(np.diag([a - h, s, s]), mu, lam)) / (2 * h)
        assert numeric == pytest.approx(P11, rel=1e-6)


# ---------------------------------------------------------------------------- 1. uniaxial, smoothed rung
# Tolerance 1e-8: the element reproduces homogeneous deformation exactly, so what is left is Newton's
# stopping point, a force residual of CUBE_RTOL = 1e-10 relative, amplified by at most the stiffness
# ratio lambda / mu <= 50 (nu 0.49). Measured: lateral stretch, reaction and the whole field within
# 2e-11 on both meshes at every nu. A wrong nonlinear form (a missed rotation, the volume term of
# the linearised J) shows at 1e-3 or more at these strains.
UNIAXIAL_TOLERANCE = 1e-8


@pytest.mark.parametrize("nu", [0.3, 0.45, 0.49])
@pytest.mark.parametrize("mesh_name", ["structured", "gmsh"])
def test_uniaxial_stretch_and_compression_to_50_percent_match_the_minimised_energy(cubes, mesh_name, nu):
    mesh = cubes[mesh_name]
    model = Model.from_mesh(mesh, Material(E=E_CUBE, nu=nu, density=1000.0), model="smoothed")
    mu, lam = lame_constants(E_CUBE, nu)
    area = EDGE * EDGE  # [m^2] rest area of the moved face: the reaction is P_11 times it
    for path in ((0.25, 0.5), (-0.25, -0.5)):
        for strain, x, reaction in _uniaxial_path(model, path):
            s, P11 = uniaxial_reference(strain, mu, lam)
            homogeneous = mesh.points * np.array([1.0 + strain, s, s])
            assert np.abs(x - homogeneous).max() <= UNIAXIAL_TOLERANCE * EDGE, (strain, s)
            assert reaction == pytest.approx(P11 * area, rel=UNIAXIAL_TOLERANCE), strain


def test_uniaxial_stretch_from_a_jittered_start_finds_the_homogeneous_state(cubes):
    """In tension the homogeneous state is stable (smallest exact stiffness eigenvalue > 0, below):
    Newton started 2 cm (6% of the mesh size) off it on the unstructured mesh comes back to it."""
    mesh, nu = cubes["gmsh"], 0.45
    model = Model.from_mesh(mesh, Material(E=E_CUBE, nu=nu, density=1000.0), model="smoothed")
    mu, lam = lame_constants(E_CUBE, nu)
    for strain, x, reaction in _uniaxial_path(model, (0.25, 0.5), jitter=0.02, seed=3):
        s, P11 = uniaxial_reference(strain, mu, lam)
        assert np.abs(x - mesh.points * np.array([1.0 + strain, s, s])).max() <= UNIAXIAL_TOLERANCE * EDGE
        assert reaction == pytest.approx(P11 * EDGE**2, rel=UNIAXIAL_TOLERANCE)


def _smallest_free_eigenvalue(model, x, held):
    K = stiffness_matrix(model, x, clamp_compression=False).toarray()
    keep = ~held.ravel()
    return np.linalg.eigvalsh(K[np.ix_(keep, keep)])[0]


@pytest.mark.parametrize("nu", [0.3, 0.49])
def test_the_homogeneous_branch_is_stable_in_tension_and_until_the_faces_buckle(cubes, nu):
    """The sign of the exact stiffness's smallest eigenvalue on the homogeneous branch (module
    docstring): positive at +50% and at -40%, negative at -70% (as for Neo-Hookean P2 on this mesh)."""
    mesh = cubes["structured"]
    model = Model.from_mesh(mesh, Material(E=E_CUBE, nu=nu, density=1000.0), model="smoothed")
    mu, lam = lame_constants(E_CUBE, nu)
    held = _uniaxial_scene(model, 0.0).held
    smallest = {}
    for strain in (0.5, -0.4, -0.7):
        s, _ = uniaxial_reference(strain, mu, lam)
        x = mesh.points * np.array([1 + strain, s, s])
        smallest[strain] = _smallest_free_eigenvalue(model, x, held) / (mu * EDGE)
    # Measured / (mu EDGE): nu 0.3 +0.053, +0.025, -0.114; nu 0.49 +0.054, +0.038, -0.017 -- signs only.
    assert smallest[0.5] > 0 and smallest[-0.4] > 0 and smallest[-0.7] < 0, smallest


# ---------------------------------------------------------------------------- 1b. uniaxial, springs+volume
def test_springs_plus_volume_at_large_uniaxial_strain_reported(cubes, capsys):
    """The volume rung is measured, not held to the smoothed rung's standard: its springs are linear in
    their length (Hooke), not in F, and fail the patch test, so its large-strain response is the
    network's own and not homogeneous. Measured on the structured cube (error of the mean lateral
    stretch s of the face y = L, and of the reaction):

    ====== ===================== ===================== ===================== =====================
    nu     +25%                  +50%                  -25%                  -50%
    ====== ===================== ===================== ===================== =====================
    0.30   s -0.36%, F +10.6%    s -0.98%, F +19.6%    s -0.78%, F -18.2%    s -2.45%, F -26.6%
    0.45   s -0.12%, F +8.7%     s -0.55%, F +17.5%    s -0.37%, F -1.8%     s -2.37%, F -9.7%
    0.49   s +0.03%, F +8.5%     s -0.10%, F +17.4%    s -0.15%, F +1.4%     s -0.77%, F +9.0%
    ====== ===================== ===================== ===================== =====================

    Asserted loosely: in tension at nu >= 0.45 the volume term holds J near the material's and so the
    mean lateral stretch within 1% (measured <= 0.55%), and the axial force is 0-30% too stiff (measured
    8.5-17.5%: the springs stiffen in stretch where the material softens; with the network calibrated on
    all five deviatoric strains, before the axes-only probes, it was 54-68%). At -50% the face is far from
    flat (spread 16-22% of the edge) and the equilibrium found depends on the solver's path.
    """
    mesh = cubes["structured"]
    lines = []
    for nu in (0.3, 0.45, 0.49):
        model = Model.from_mesh(mesh, Material(E=E_CUBE, nu=nu, density=1000.0), model="springs+volume")
        mu, lam = lame_constants(E_CUBE, nu)
        side = np.abs(mesh.points[:, 1] - EDGE) < ON_PLANE
        for path in ((0.25, 0.5), (-0.25, -0.5)):
            for strain, x, reaction in _uniaxial_path(model, path):
                s, P11 = uniaxial_reference(strain, mu, lam)
                lateral = x[side, 1].mean() / EDGE
                lines.append(f"nu {nu:.2f} strain {strain:+.2f}: s {lateral / s - 1:+.2%}, reaction "
                             f"{reaction / (P11 * EDGE**2) - 1:+.1%}, spread {np.ptp(x[side, 1]) / EDGE:.1%}")
                assert np.isfinite(x).all()
                if nu >= 0.45 and strain > 0:
                    assert lateral == pytest.approx(s, rel=0.01), (nu, strain)
                    assert 1.0 < reaction / (P11 * EDGE**2) < 1.3, (nu, strain)
    with capsys.disabled():
        print("\nsprings+volume against the smoothed density's uniaxial answer:\n  " + "\n  ".join(lines))


# ---------------------------------------------------------------------------- the Neo-Hookean reference itself
def test_neo_hookean_stress_and_tangent_are_the_derivatives_of_its_density():
    rng = np.random.default_rng(2)
    F = np.eye(3)[:, :, None] + 0.3 * rng.standard_normal((3, 3, 20))
    F[:, :, np.linalg.det(np.moveaxis(F, -1, 0)) < 0.2] = np.eye(3)[:, :, None]  # ln J needs J > 0
    dF = rng.standard_normal((3, 3, 20))
    mu, lam, h = 3.0, 7.0, 1e-6
    # Central differences: O(h^2) truncation plus eps |psi| / h round-off, ~1e-9 here; 1e-6 leaves room.
    stress = (neo_hookean_density(F + h * dF, mu, lam) - neo_hookean_density(F - h * dF, mu, lam)) / (2 * h)
    assert np.allclose(stress, np.einsum("ij...,ij...", neo_hookean_stress(F, mu, lam), dF), rtol=1e-6, atol=1e-6)
    tangent = (neo_hookean_stress(F + h * dF, mu, lam) - neo_hookean_stress(F - h * dF, mu, lam)) / (2 * h)
    assert np.allclose(tangent, neo_hookean_tangent(F, dF, mu, lam), rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("strain", [0.5, -0.5])
def test_neo_hookean_p2_reproduces_its_uniaxial_stress_state(strain):
    """P2 holds the homogeneous field exactly, so the finite-element Newton must land on the scalar
    answer (neo_hookean_uniaxial): the reference's residual, tangent and load stepping checked at 50%."""
    E, nu = 1e6, 0.45
    cube = structured_box((2, 2, 2), (EDGE, EDGE, EDGE))
    clamps = [Clamp(Box.plane(a, 0.0), components=a) for a in "xyz"]
    clamps.append(Clamp(Box.plane("x", EDGE), components="x", displacement=(strain * EDGE, 0.0, 0.0)))
    solution = solve_neo_hookean_static(cube, (E, nu, 1000.0), clamp=clamps, element="P2", load_steps=2)
    s, P11 = neo_hookean_uniaxial(strain, E, nu)
    homogeneous = cube.points * np.array([strain, s - 1.0, s - 1.0])
    # Newton's rtol 1e-10, amplified by lambda / mu ~ 9: measured 4e-15 (field) and 3e-14 (reaction).
    assert np.abs(solution.displacement - homogeneous).max() <= 1e-8 * EDGE
    assert solution.reaction_in(Box.plane("x", EDGE))[0] == pytest.approx(P11 * EDGE**2, rel=1e-8)


# ---------------------------------------------------------------------------- 2. the bent cantilever
BEAM = {"length": 1.0, "side": 0.1, "E": 1e6, "density": 1000.0, "gravity": 1.5, "cells": (20, 2, 2)}


def _beam_tip(mesh, displacement):
    """(3,) mean displacement of the tip face x = L [m]."""
    return displacement[np.abs(mesh.points[:, 0] - BEAM["length"]) < ON_PLANE].mean(axis=0)


def bent_cantilever(nu, mesh=None):
    """Tip displacements [m] of the cantilever clamped at x = 0 under gravity -z on the smoothed rung
    (linear: one solve with the stiffness at rest; nonlinear: volspring's Newton) and of P2 on the same
    mesh (linear: validation.fem; nonlinear: validation.nonlinear), with wall times."""
    L, side = BEAM["length"], BEAM["side"]
    mesh = structured_box(BEAM["cells"], (L, side, side)) if mesh is None else mesh
    material = Material(E=BEAM["E"], nu=nu, density=BEAM["density"])
    g = np.array([0.0, 0.0, -BEAM["gravity"]])
    clamped = np.abs(mesh.points[:, 0]) < ON_PLANE
    out = {"mesh": mesh}
    start = time.perf_counter()
    # The scene's model: the smoothed rung's volume domains go to the free nodes where the clamp holds a
    # tet's every corner (Scene adapts the model to its supports), for the linear answer as for the nonlinear.
    scene = Scene(Model.from_mesh(mesh, material, model="smoothed"), forces=[Gravity(g=g)], pins=Pins(clamped))
    model = scene.model
    K = stiffness_matrix(model, free=~clamped, clamp_compression=False)
    u = np.zeros_like(mesh.points)
    u[~clamped] = spla.spsolve(K.tocsc(), (model.masses[~clamped, None] * g).ravel()).reshape(-1, 3)
    out["smoothed_linear"] = _beam_tip(mesh, u)
    # rtol 1e-9: a displacement of 1 m carries eps of round-off, times the stiffness ~E h = 5e4 N/m, so
    # the forces cannot be resolved below ~1e-11 N, 1e-8 of this load's norm (measured stall: 2e-11 N).
    result = solve_static(scene, rtol=1e-9)
    out["smoothed"] = _beam_tip(mesh, result.x - mesh.points)
    out["smoothed_seconds"] = time.perf_counter() - start
    start = time.perf_counter()
    fem = (BEAM["E"], nu, BEAM["density"])
    out["p2_linear"] = _beam_tip(mesh, solve_fem_static(mesh, fem, clamp=Box.plane("x", 0.0), gravity=g).displacement)
    out["p2_linear_seconds"] = time.perf_counter() - start
    nonlinear = solve_neo_hookean_static(mesh, fem, clamp=Box.plane("x", 0.0), gravity=g, load_steps=1)
    out["p2"] = _beam_tip(mesh, nonlinear.displacement)
    out["p2_seconds"] = time.perf_counter() - start - out["p2_linear_seconds"]
    out["p2_newton"] = nonlinear.newton_iterations
    return out


def _check_bent_cantilever(beam):
    linear_ratio = beam["smoothed_linear"][2] / beam["p2_linear"][2]
    ratio = beam["smoothed"][2] / beam["p2"][2]
    # 20% of the length, give or take: the load case is the one the issue asks for.
    assert 0.18 < -beam["p2"][2] / BEAM["length"] < 0.24
    # The load case is nonlinear: linear theory over-predicts the tip deflection by more than 3%
    # (measured at nu 0.3: P2 3.6%, smoothed 3.4%), and the tip moves back along the beam by more than
    # 10% of its deflection (measured 12%) where linear theory moves it by nothing (measured < 1e-13 m on
    # the structured mesh; 1e-5 (smoothed) and 1e-7 (P2) of the deflection on the unstructured one).
    for linear, nonlinear in (("p2_linear", "p2"), ("smoothed_linear", "smoothed")):
        assert beam[nonlinear][2] / beam[linear][2] < 0.97, (nonlinear, beam[nonlinear], beam[linear])
        assert abs(beam[linear][0]) < 1e-4 * -beam[linear][2] and -beam[nonlinear][0] > 0.1 * -beam[nonlinear][2]
    # The nonlinear ratio equals the linear one (the discretisation error, 0.968 at nu 0.3): measured
    # apart by 0.21% (nu 0.3), 0.24% (0.45), 0.28% (0.49); 0.16% on an unstructured gmsh beam (linear
    # ratio 1.017). The materials differ at second order in the strain (4% at the root) and the
    # discretisation errors of a bent and a straight beam differ a little; 1% is 3.5x the largest gap,
    # where a rotation the element did not remove would cost the whole 3.6% linear theory is off, or more.
    assert ratio == pytest.approx(linear_ratio, rel=0.01), (ratio, linear_ratio)
    # The shortening per squared deflection is geometry (u_x ~ 0.6 w^2 / L for an Euler beam), free of
    # the stiffness error: measured 0.5724 (smoothed) and 0.5727 (P2) at nu 0.3, 0.05% apart; 0.47% and
    # 0.66% apart at nu 0.45 and 0.49, 0.29% on the gmsh beam; 1% as above.
    shortening = [beam[name][0] / beam[name][2] ** 2 for name in ("smoothed", "p2")]
    assert shortening[0] == pytest.approx(shortening[1], rel=0.01), shortening


@pytest.fixture(scope="module")
def cantilever():
    return bent_cantilever(0.3)


def test_bent_cantilever_matches_neo_hookean_p2_as_closely_as_in_the_linear_range(cantilever, capsys):
    _check_bent_cantilever(cantilever)
    with capsys.disabled():
        beam = cantilever
        print(f"\nbent cantilever nu 0.3: tip z smoothed {beam['smoothed'][2]:.5f} m (linear "
              f"{beam['smoothed_linear'][2]:.5f}), P2 Neo-Hookean {beam['p2'][2]:.5f} m (linear "
              f"{beam['p2_linear'][2]:.5f}); ratio {beam['smoothed'][2] / beam['p2'][2]:.4f} (linear "
              f"{beam['smoothed_linear'][2] / beam['p2_linear'][2]:.4f}); {beam['smoothed_seconds']:.2f} s smoothed, "
              f"{beam['p2_seconds']:.2f} s Neo-Hookean P2 ({beam['p2_newton']} Newton iterations)")


def test_neo_hookean_p2_is_linear_p2_at_a_small_load(cantilever):
    """At 1/1000 of the load the Neo-Hookean reference is the linear one: its forms linearise right."""
    mesh, nu = cantilever["mesh"], 0.3
    g = (0.0, 0.0, -BEAM["gravity"] * 1e-3)
    small = solve_neo_hookean_static(mesh, (BEAM["E"], nu, BEAM["density"]), clamp=Box.plane("x", 0.0), gravity=g,
                                     load_steps=1)
    # The nonlinear part scales with the load: 1e-3 of the 3.6% seen at the full load, 4e-5; measured 3.6e-5.
    assert _beam_tip(mesh, small.displacement)[2] == pytest.approx(1e-3 * cantilever["p2_linear"][2], rel=1e-4)


@pytest.mark.slow
@pytest.mark.xfail(strict=True, reason="since the scene gives the clamped nodes' volume domains to their free "
                   "neighbours (1683b51, issue 11), the smoothed rung's linear tip moves along the beam by 3.4e-4 "
                   "(nu 0.45) and 4.6e-4 (0.49; 5.3e-4 before lambda above 20 mu went on merged pairs) of its "
                   "deflection on this structured mesh (bound 1e-4: the mirrored cells' pattern at the clamp is not symmetric "
                   "about the mid-plane), and its shortening per squared deflection is 1.06% and 1.42% (1.53%) from "
                   "P2's (bound 1%; 0.47% and 0.66% before 1683b51); the "
                   "unstructured beam passes. Open in issue 11")
@pytest.mark.parametrize("nu", [0.45, 0.49])
def test_bent_cantilever_nearly_incompressible(nu):
    _check_bent_cantilever(bent_cantilever(nu))


@pytest.mark.slow
def test_bent_cantilever_on_an_unstructured_mesh():
    L, side = BEAM["length"], BEAM["side"]
    mesh = tetrahedralize(box(L, side, side), size=0.04, seed=1)
    _check_bent_cantilever(bent_cantilever(0.3, TetMesh.compact(mesh.points + [L / 2, side / 2, side / 2],
                                                                mesh.tets)))


# ---------------------------------------------------------------------------- 3. inversion
def _reflected_node(mesh):
    """Positions with the interior node nearest the centre mirrored through the opposite face of one of
    its tets: that tet is exactly reflected (singular values 1, 1, -1) and its neighbours inverted."""
    points = mesh.points
    interior = np.flatnonzero(((points > ON_PLANE) & (points < EDGE - ON_PLANE)).all(axis=1))
    node = interior[np.argmin(np.linalg.norm(points[interior] - EDGE / 2, axis=1))]
    tet = mesh.tets[np.flatnonzero((mesh.tets == node).any(axis=1))[0]]
    a, b, c = points[tet[tet != node]]
    normal = np.cross(b - a, c - a)
    normal /= np.linalg.norm(normal)
    x = points.copy()
    x[node] -= 2.0 * np.dot(points[node] - a, normal) * normal
    return x


def _snapped_face(mesh, strain=-0.9):
    """Positions with the face x = EDGE moved to (1 + strain) EDGE and nothing else: the layers it passes
    through are crushed and inverted (on the gmsh cube some tets exactly reflected: F = diag(-1, 1, 1))."""
    x = mesh.points.copy()
    x[_pulled_face(mesh.points), 0] = (1.0 + strain) * EDGE
    return x


@pytest.mark.parametrize("mesh_name", ["structured", "gmsh"])
@pytest.mark.parametrize("state", ["reflected node", "snapped face"])
def test_energy_forces_and_stiffness_stay_finite_when_tets_invert(cubes, mesh_name, state):
    mesh = cubes[mesh_name]
    x = _reflected_node(mesh) if state == "reflected node" else _snapped_face(mesh)
    assert (np.linalg.det(TetGradients.at_rest(mesh.points, mesh.tets).deformation(x)) < 0).sum() >= 5
    model = Model.from_mesh(mesh, Material(E=E_CUBE, nu=0.49, density=1000.0), model="smoothed")
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a division by zero fails here even where numpy would go on
        assert np.isfinite(model.energy(x)) and model.energy(x) > 0
        assert np.isfinite(model.forces(x)).all()
        for exact in (False, True):
            assert np.isfinite(stiffness_matrix(model, x, clamp_compression=not exact).data).all(), exact


@pytest.mark.parametrize("nu", [0.3, 0.49])
def test_cube_crushed_to_minus_90_percent_springs_back(cubes, nu):
    """Crushed homogeneously to -90% (continuation along the homogeneous branch: the energy's answer
    still, to Newton's precision), then let go: the static solve returns it to its rest shape."""
    mesh = cubes["gmsh"]
    model = Model.from_mesh(mesh, Material(E=E_CUBE, nu=nu, density=1000.0), model="smoothed")
    mu, lam = lame_constants(E_CUBE, nu)
    (*_, (strain, x, reaction)) = _uniaxial_path(model, (-0.25, -0.5, -0.7, -0.9))
    s, P11 = uniaxial_reference(strain, mu, lam)
    assert np.abs(x - mesh.points * np.array([1.0 + strain, s, s])).max() <= UNIAXIAL_TOLERANCE * EDGE
    assert reaction == pytest.approx(P11 * EDGE**2, rel=UNIAXIAL_TOLERANCE)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        back = solve_static(Scene(model, supports=_symmetry_planes(mesh.points)), x0=x, rtol=CUBE_RTOL).x
    # No load, so the answer is the rest shape; measured within 3e-11 m (Newton's rtol on the forces).
    assert np.abs(back - mesh.points).max() <= 1e-8 * EDGE


@pytest.mark.parametrize("mesh_name", ["structured", "gmsh"])
@pytest.mark.parametrize("nu", [0.3, 0.49])
def test_a_reflected_tet_is_pushed_back_by_the_static_solve_and_by_implicit_steps(cubes, mesh_name, nu):
    mesh = cubes[mesh_name]
    model = Model.from_mesh(mesh, Material(E=E_CUBE, nu=nu, density=1000.0), model="smoothed")
    scene = Scene(model, supports=_symmetry_planes(mesh.points))
    x = _reflected_node(mesh)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        # The projected stiffness (the implicit step's): measured 4-5 Newton iterations, within 5e-14 m.
        back = solve_static(scene, x0=x, rtol=CUBE_RTOL, clamp_compression=True).x
        assert np.abs(back - mesh.points).max() <= 1e-8 * EDGE
        state, integrator = State(x, np.zeros_like(x), 0.0), ImplicitEuler(solver="direct")
        for _ in range(100):  # 2 s, ~5 periods of the cube's lowest mode; backward Euler damps them
            state = integrator.step(scene, state, 0.02)
    assert np.isfinite(state.x).all()
    # Measured energy left: 1e-6 to 5e-6 of the start's (0.03-0.5 J of 8e3-1e5 J); no tet inverted.
    assert model.energy(state.x) < 1e-4 * model.energy(x)
    assert (np.linalg.det(TetGradients.at_rest(mesh.points, mesh.tets).deformation(state.x)) > 0).all()


@pytest.mark.parametrize("mesh_name", ["structured", "gmsh"])
@pytest.mark.parametrize("nu", [0.3, 0.49])
def test_a_cube_with_its_face_snapped_to_minus_90_percent_is_pushed_back_by_the_static_solve(cubes, mesh_name, nu):
    """The face x = L moved to x = 0.1 L at once, the layers it crossed crushed and inverted (some tets
    exactly reflected on the gmsh mesh): with the projected stiffness the static solve undoes it."""
    mesh = cubes[mesh_name]
    model = Model.from_mesh(mesh, Material(E=E_CUBE, nu=nu, density=1000.0), model="smoothed")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        back = solve_static(Scene(model, supports=_symmetry_planes(mesh.points)), x0=_snapped_face(mesh),
                            rtol=CUBE_RTOL, clamp_compression=True).x
    # Measured 8-9 Newton iterations, within 9e-12 m of the rest shape.
    assert np.abs(back - mesh.points).max() <= 1e-8 * EDGE


@pytest.mark.parametrize("mesh_name", ["structured", "gmsh"])
def test_the_default_static_solve_pushes_back_a_snapped_face(cubes, mesh_name):
    """With inverted tets the exact Hessian is strongly indefinite: while any tet is inverted the static solve takes
    the projected stiffness's steps, then the exact Hessian's (it failed outright once, also because its shift was
    scaled by a negative mean diagonal). Measured: 13 and 20 Newton iterations, 9 and 10 with
    clamp_compression=True throughout. The exact Hessian's steps through the crushed states were sensitive to the
    model's round-off: 29 and 62 iterations to the rest shape at stop 35, and after a change of the volume gradients'
    last bits (stop 36) 51 iterations on the structured cube to an equilibrium with 2 tets still inverted and 7.8 kJ
    of energy left, which this test caught. The cap asks for convergence to the rest shape, not for a count: twice
    the default's 50."""
    mesh = cubes[mesh_name]
    model = Model.from_mesh(mesh, Material(E=E_CUBE, nu=0.49, density=1000.0), model="smoothed")
    back = solve_static(Scene(model, supports=_symmetry_planes(mesh.points)), x0=_snapped_face(mesh), rtol=CUBE_RTOL,
                        max_iterations=100).x
    assert np.abs(back - mesh.points).max() <= 1e-8 * EDGE


@pytest.mark.parametrize("mesh_name", ["structured", "gmsh"])
@pytest.mark.parametrize("nu", [0.3, 0.49])
def test_implicit_steps_bring_back_a_cube_with_its_face_snapped_to_minus_90_percent(cubes, nu, mesh_name):
    """With the volume on single nodes, nu 0.49 settled in a folded local minimum (some tets rotated by ~179
    degrees, 3280 J, on both meshes); with the volume on pairs of nodes (fewer, softer constraints) the
    fold is gone and the cube comes back."""
    mesh = cubes[mesh_name]
    model = Model.from_mesh(mesh, Material(E=E_CUBE, nu=nu, density=1000.0), model="smoothed")
    scene = Scene(model, supports=_symmetry_planes(mesh.points))
    x = _snapped_face(mesh)
    state, integrator = State(x, np.zeros_like(x), 0.0), ImplicitEuler(solver="direct")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for _ in range(100):  # 4 s, ~10 periods of the lowest mode
            state = integrator.step(scene, state, 0.04)
    assert np.isfinite(state.x).all()
    # Measured: 0.7e-6 to 3e-6 m from rest on both meshes at nu 0.3 and 0.49 (single-node volume at 0.49: 0.84 m).
    assert np.abs(state.x - mesh.points).max() <= 1e-3 * EDGE
