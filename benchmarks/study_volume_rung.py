"""How the springs+volume rung gets its spring scale s and bulk coefficient kappa: the study behind
:func:`volspring.ladder.network_moduli`.

The rung is ``s x springs(E = 1) + NodalStrain(shear 0, bulk kappa)``; s = mu / mu_1 and kappa = K - s K_1
from the network moduli (mu_1, K_1) of the unit springs. Each calibration below is a way to get
(mu_1, K_1), or (s, kappa) directly:

- probes of the network alone, boundary *held* on an affine strain (Dirichlet: an upper bound) or
  the body *free* under uniform tractions (Neumann: a lower bound), or their mean;
- over *all* five deviatoric tensors (shears too) or only the two normal ones, diag(1,-1,0) and
  diag(1,1,-2), that a uniaxial stress along an axis sees ("axes");
- "combined": (s, kappa) solved on the mesh so that the probe of the springs *plus* volume term gives
  K / mu (the moduli are homogeneous of degree one in (s, kappa), so a secant on r = kappa / s, one
  factorisation per step, then s from mu);
- the ideal network's constants (mu_1 = 2/5, K_1 = 2/3 per unit E: kappa = lambda - mu);
- "cube": the combined Neumann-axes calibration done on a jittered Delaunay cube, applied to any mesh.

Boxes (the project's structured boxes, jittered Delaunay cubes): a linear uniaxial stress test as
:func:`validation.springs.effective_constants` (sliding supports; the same numbers to 1e-3): per nu,
``nu_eff  V/V_exact  E/E`` (V: volume change per axial strain over 1 - 2 nu).

Held-out shapes (``--heldout``; P2 solves are cached in ``--cache``): per nu, ``u/u_P2`` (the
displacement of the node P2 moves most, along its direction), ``dV/dV_P2`` (linear volume change; in
bending it is a cancellation, the script prints net/gross |div u| so you can tell) and the calibrated
model's nu as the free shape answers uniaxial tractions along x, y, z (``nuN``) and with its boundary held
(``nuD``).

Run::

    OMP_NUM_THREADS=1 python benchmarks/study_volume_rung.py              # boxes, ~1 min
    OMP_NUM_THREADS=1 python benchmarks/study_volume_rung.py --heldout    # + held-out shapes, ~3 min
    OMP_NUM_THREADS=1 python benchmarks/study_volume_rung.py --cost       # calibration time, 3.7k-22k nodes

This is a study script, not a test.
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

NUS = (0.25, 0.3, 0.4, 0.45, 0.49, 0.499)


# ---------------------------------------------------------------------------- meshes
def box_meshes():
    from meshing import jittered_cube, structured_box
    from validation.cases import beam_cells

    return {"structured 4^3": structured_box((4, 4, 4), (1.0, 1.0, 1.0)),
            "Delaunay 5^3": jittered_cube(5),
            "beam 20x2x2": structured_box(beam_cells(1.0, 0.1, 2), (1.0, 0.1, 0.1)),
            "beam 10x1x1": structured_box(beam_cells(1.0, 0.1, 1), (1.0, 0.1, 0.1)),
            "Delaunay 8^3": jittered_cube(8, seed=1)}


# ---------------------------------------------------------------------------- operators and probes
def unit_springs(mesh, rule):
    from volspring import Material, Model

    return Model.from_mesh(mesh, Material(E=1.0, nu=0.3, density=1.0), rule=rule).spring_elements


def operators(mesh, rule):
    """(A, B): the unit springs' stiffness and the nodal volume term's with kappa = 1, at rest."""
    from volspring import Model
    from volspring.assembly import stiffness_matrix
    from volspring.elements import NodalStrain
    from volspring.ladder import _network_stiffness

    A = _network_stiffness(mesh, unit_springs(mesh, rule))
    volume = NodalStrain(mesh.points, mesh.tets, 0.0, 1.0)
    B = stiffness_matrix(Model(mesh.points, np.ones(mesh.node_count), (volume,))).tocsr()
    return A, B


def all_tensors():
    """The three shears, the two normal deviatoric tensors and I / sqrt(3), each of unit norm."""
    tensors = []
    for i, j in ((0, 1), (0, 2), (1, 2)):
        e = np.zeros((3, 3))
        e[i, j] = e[j, i] = 1.0 / math.sqrt(2.0)
        tensors.append(e)
    return tensors + [np.diag([1.0, -1.0, 0.0]) / math.sqrt(2.0), np.diag([1.0, 1.0, -2.0]) / math.sqrt(6.0),
                      np.eye(3) / math.sqrt(3.0)]


def held(K, mesh):
    """(6,) energies per volume, boundary held on each tensor of :func:`all_tensors`."""
    boundary = np.zeros(mesh.node_count, bool)
    boundary[mesh.boundary_nodes] = True
    fixed = np.repeat(boundary, 3)
    factor = splu(sp.csc_matrix(K[~fixed][:, ~fixed]))
    coupling = K[~fixed][:, fixed]
    centred = mesh.points - mesh.points.mean(axis=0)
    out = []
    for strain in all_tensors():
        u = (centred @ strain.T).ravel()
        u[~fixed] = factor.solve(-(coupling @ u[fixed]))
        out.append(0.5 * u @ (K @ u) / mesh.volume)
    return np.array(out)


def free(K, mesh):
    """(6,) compliances sigma : eps_mean of the free body under tractions sigma n, each tensor of :func:`all_tensors`."""
    from volspring.ladder import _rigid_modes

    R = sp.csr_matrix(np.linalg.qr(_rigid_modes(mesh.points))[0])
    factor = splu(sp.bmat([[K, R], [R.T, None]]).tocsc())
    faces = mesh.boundary_faces
    p = mesh.points[faces]
    area_normals = 0.5 * np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    out = []
    for stress in all_tensors():
        t = area_normals @ stress.T / 3.0
        f = np.stack([np.bincount(faces.ravel(), weights=np.repeat(t[:, c], 3), minlength=mesh.node_count)
                      for c in range(3)], axis=1).ravel()
        u = factor.solve(np.concatenate([f, np.zeros(6)]))[:-6]
        out.append(f @ u / mesh.volume)
    return np.array(out)


def moduli(kind, which, K, mesh):
    """(mu, K_bulk) by probe ``kind`` (held, free, mean) over ``which`` deviatoric tensors (all, axes)."""
    deviatoric = slice(0, 5) if which == "all" else slice(3, 5)
    results = []
    for probe in (("held", "free") if kind == "mean" else (kind,)):
        values = held(K, mesh) if probe == "held" else free(K, mesh)
        if probe == "held":
            results.append((values[deviatoric].mean(), 2.0 * values[5] / 3.0))
        else:
            results.append((1.0 / (2.0 * values[deviatoric].mean()), 1.0 / (3.0 * values[5])))
    return tuple(np.mean(results, axis=0))


def isotropic_nu(mu, bulk):
    return (3 * bulk - 2 * mu) / (2 * (3 * bulk + mu))


# ---------------------------------------------------------------------------- calibrations
def alone(kind, which):
    def calibrate(mesh, A, B, mu, bulk, memo):
        key = (kind, which)
        if key not in memo:
            memo[key] = moduli(kind, which, A, mesh)
        mu_1, bulk_1 = memo[key]
        s = mu / mu_1
        return s, max(bulk - s * bulk_1, 0.0)
    return calibrate


def ideal(mesh, A, B, mu, bulk, memo):
    s = mu / 0.4
    return s, max(bulk - s * 2.0 / 3.0, 0.0)


def combined(kind, which):
    """Secant on r = kappa / s until the probe of A + r B has K / mu of the material; then s = mu / mu(r)."""
    def calibrate(mesh, A, B, mu, bulk, memo):
        s0, kappa0 = alone(kind, which)(mesh, A, B, mu, bulk, memo)
        target = bulk / mu

        def residual(r):
            m, k = moduli(kind, which, A + r * B, mesh)
            return k / m - target, m

        r_a = kappa0 / s0
        f_a, m = residual(r_a)
        r_b = max(r_a - f_a * m, 0.0)
        f_b, m = residual(r_b)
        for _ in range(15):
            if abs(f_b) < 1e-4 * target or r_b == r_a:
                break
            r_a, r_b, f_a = r_b, max(r_b - f_b * (r_b - r_a) / (f_b - f_a), 0.0), f_b
            f_b, m = residual(r_b)
        return mu / m, r_b * mu / m
    return calibrate


_CUBE = {}


def on_a_cube(mesh, A, B, mu, bulk, memo):
    if "cube" not in _CUBE:
        from meshing import jittered_cube

        cube = jittered_cube(8, seed=1)
        _CUBE["cube"] = (cube, *operators(cube, _CUBE["rule"]), {})
    cube, Ac, Bc, memo_cube = _CUBE["cube"]
    return combined("free", "axes")(cube, Ac, Bc, mu, bulk, memo_cube)


CALIBRATIONS = {
    "held, all (before)": alone("held", "all"),
    "(d) ideal network": ideal,
    "free, all": alone("free", "all"),
    "(b) mean, all": alone("mean", "all"),
    "(a) held, all, combined": combined("held", "all"),
    "(a) free, all, combined": combined("free", "all"),
    "held, axes": alone("held", "axes"),
    "free, axes": alone("free", "axes"),
    "(b) mean, axes (chosen)": alone("mean", "axes"),
    "(a) mean, axes, combined": combined("mean", "axes"),
    "(c) cube, free axes comb.": on_a_cube,
}


def uniaxial(K, mesh):
    """Linear uniaxial stress along x (as validation.springs.effective_constants): E, nu, dV / (V eps)."""
    from volspring.elements.tet_kinematics import TetGradients

    low, high = mesh.bounds
    size = high - low
    tol = 1e-6 * float(np.linalg.norm(size))
    P = mesh.points
    fixed = np.zeros((mesh.node_count, 3), bool)
    for a in range(3):
        fixed[np.abs(P[:, a] - low[a]) < tol, a] = True
    top = np.abs(P[:, 0] - high[0]) < tol
    fixed[top, 0] = True
    u = np.zeros((mesh.node_count, 3))
    u[top, 0] = size[0]
    fixed, u = fixed.ravel(), u.ravel()
    u[~fixed] = splu(sp.csc_matrix(K[~fixed][:, ~fixed])).solve(-(K[~fixed][:, fixed] @ u[fixed]))
    E = float((K @ u).reshape(-1, 3)[top, 0].sum() / (size[1] * size[2]))
    U = u.reshape(-1, 3)
    nu = -np.mean([U[np.abs(P[:, a] - high[a]) < tol, a].mean() / size[a] for a in (1, 2)])
    kinematics = TetGradients.at_rest(mesh.points, mesh.tets)
    volume = float(kinematics.volumes @ np.trace(kinematics.deformation(U), axis1=1, axis2=2)) / mesh.volume
    return E, nu, volume


def material(nu):
    """mu and K per unit E."""
    return 1.0 / (2.0 * (1.0 + nu)), 1.0 / (3.0 * (1.0 - 2.0 * nu))


def study_boxes(rule, nus):
    print(f"Boxes, rule {rule}: per nu, nu_eff  V/V_exact  E/E (uniaxial stress along x)")
    print(" " * 43 + "".join(f"| nu = {nu:<14g}" for nu in nus))
    for name, mesh in box_meshes().items():
        A, B = operators(mesh, rule)
        memo = {}
        for label, calibrate in CALIBRATIONS.items():
            line = f"{name:15s} {label:27s}"
            for nu in nus:
                mu, bulk = material(nu)
                s, kappa = calibrate(mesh, A, B, mu, bulk, memo)
                E, found, volume = uniaxial(s * A + kappa * B, mesh)
                line += f"| {found:5.3f} {volume / (1 - 2 * nu):5.2f} {E:4.2f} "
            print(line, flush=True)


def study_heldout(rule, nus, cache):
    from validation.fem import solve_fem_static
    from validation.heldout import build_heldout_case, heldout_mesh
    from validation.springs import held_nodes
    from volspring.elements.tet_kinematics import TetGradients
    from volspring.ladder import _free_probe, _held_probe

    print(f"\nHeld-out shapes under gravity, rule {rule}: per nu, u/u_P2  dV/dV_P2 (net/gross |div u|)  nuN nuD")
    cache.mkdir(parents=True, exist_ok=True)
    for name in ("torus", "capsule", "l_bracket", "bunny"):
        mesh = heldout_mesh(name)
        A, B = operators(mesh, rule)
        kinematics = TetGradients.at_rest(mesh.points, mesh.tets)
        references = {}
        for nu in nus:
            case = build_heldout_case(f"{name}_gravity", nu=nu)
            path = cache / f"p2_{name}_{nu}.npz"
            if not path.is_file():
                p2 = solve_fem_static(case.mesh, case.material_tuple, element="P2", solver="amg", tolerance=1e-10,
                                      **case.fem_arguments())
                np.savez(path, u=p2.displacement, dv=p2.volume_change)
            with np.load(path) as stored:
                references[nu] = (case, stored["u"], float(stored["dv"]))
        memo = {}
        for label, calibrate in CALIBRATIONS.items():
            line = f"{name:10s} {label:27s}"
            for nu in nus:
                case, u_p2, dv_p2 = references[nu]
                mu, bulk = material(nu)
                s, kappa = calibrate(mesh, A, B, mu, bulk, memo)
                K = s * A + kappa * B
                free_dofs = np.repeat(~held_nodes(case), 3)
                load = (case.material.density * mesh.node_volumes()[:, None] * np.asarray(case.gravity)).ravel()
                u = np.zeros(3 * mesh.node_count)
                u[free_dofs] = splu(sp.csc_matrix(case.material.E * K[free_dofs][:, free_dofs])).solve(load[free_dofs])
                u = u.reshape(-1, 3)
                k = int(np.argmax(np.linalg.norm(u_p2, axis=1)))
                direction = u_p2[k] / np.linalg.norm(u_p2[k])
                div = np.trace(kinematics.deformation(u), axis1=1, axis2=2)
                net_gross = abs(kinematics.volumes @ div) / (kinematics.volumes @ np.abs(div))
                c = _free_probe(mesh, K)
                h = _held_probe(mesh, K)
                nu_free = isotropic_nu(1 / (2 * c[:2].mean()), 1 / (3 * c[2]))
                nu_held = isotropic_nu(h[:2].mean(), 2 * h[2] / 3)
                line += (f"| {u[k] @ direction / (u_p2[k] @ direction):5.3f} {kinematics.volumes @ div / dv_p2:6.2f} "
                         f"({net_gross:5.3f}) {nu_free:5.3f} {nu_held:5.3f} ")
            print(line, flush=True)


def study_cost():
    """Seconds on one core: the spring model's build on a fresh mesh (cold: the mesh's edges and faces are
    computed then) and again (warm), network_moduli, and the springs+volume model's build on a fresh mesh."""
    from meshing import jittered_cube, structured_box
    from volspring import Material, Model
    from volspring.ladder import network_moduli

    rubber = Material(E=1e6, nu=0.49, density=1000.0)
    print("\nCalibration cost (one core): seconds")
    for name, make in (("structured 30x10x10", lambda: structured_box((30, 10, 10), (3.0, 1.0, 1.0))),
                       ("Delaunay 14^3", lambda: jittered_cube(14, seed=2)),
                       ("Delaunay 27^3", lambda: jittered_cube(27, seed=2)),
                       ("structured 60x18x18", lambda: structured_box((60, 18, 18), (3.0, 1.0, 1.0)))):
        mesh = make()
        start = time.perf_counter()
        Model.from_mesh(mesh, rubber)
        cold = time.perf_counter() - start
        start = time.perf_counter()
        Model.from_mesh(mesh, rubber)
        warm = time.perf_counter() - start
        unit = unit_springs(mesh, "van_gelder")
        start = time.perf_counter()
        network_moduli(mesh, unit)
        probe = time.perf_counter() - start
        fresh = make()
        start = time.perf_counter()
        Model.from_mesh(fresh, rubber, model="springs+volume")
        rung = time.perf_counter() - start
        print(f"{name:20s} {mesh.node_count:6d} nodes: springs model {cold:5.2f} cold, {warm:5.2f} warm; "
              f"network_moduli {probe:5.2f} ({probe / cold:4.1f}x cold); springs+volume model {rung:5.2f} cold",
              flush=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rule", default="van_gelder", choices=("van_gelder", "lloyd"))
    parser.add_argument("--nu", type=float, nargs="+", default=list(NUS))
    parser.add_argument("--heldout", action="store_true", help="also the held-out shapes against P2")
    parser.add_argument("--cost", action="store_true", help="only the calibration's cost")
    parser.add_argument("--cache", type=Path, default=Path("/tmp/volspring_study_volume_rung"),
                        help="folder for the P2 solutions of the held-out shapes")
    args = parser.parse_args()
    _CUBE["rule"] = args.rule
    if args.cost:
        study_cost()
        return
    study_boxes(args.rule, args.nu)
    if args.heldout:
        study_heldout(args.rule, [nu for nu in args.nu if nu < 0.495], args.cache)


if __name__ == "__main__":
    main()
