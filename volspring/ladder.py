"""The ladder of models, from fast springs to FEM-accurate: which element sets a named model gets.

Every rung shares the lumped masses (density x a quarter of each tet's volume per corner) and
everything else (integrators, supports, collisions, output); it differs only in its element sets
(:mod:`volspring.elements`):

``"springs"``
    The tet edges as springs by a stiffness rule (van Gelder by default): the fastest rung, and
    the seed's model. Springs obey the Cauchy limit: whatever nu is asked, the network has its
    own effective Poisson ratio (about 0.16-0.25), so nearly incompressible bodies lose volume
    several times too fast.
``"springs+volume"``
    The springs, scaled so that the network's shear modulus is the material's, plus a nodal
    volume term (:class:`~volspring.elements.NodalStrain` with no shear) whose bulk coefficient is
    what the springs lack: kappa = K - s K_s, K = lambda + 2 mu / 3 the material's bulk modulus,
    K_s and mu_s the network's own moduli and s = mu / mu_s the spring scale. A nodal term does
    not lock like a per-tet one. It needs kappa >= 0, i.e. nu at or above the network's own
    (0.11-0.19 on the project's meshes): below, it refuses and names the accurate rung.

    *How K_s and mu_s are obtained* (:func:`network_moduli`). For an ideal central-force network
    lambda_s = mu_s, i.e. mu_s = 2/5 and K_s = 2/3 per unit E and kappa = lambda - mu (Golec et
    al. 2020). A real tet network is neither ideal nor isotropic: on a structured grid its
    modulus under normal deviatoric strain is twice its shear modulus (0.58 and 0.28 per unit E,
    van Gelder), on a jittered Delaunay cube 1.5 times; only gmsh's unstructured meshes come near
    isotropy. So mu_s and K_s are *measured on the mesh itself*, on the three tensors a uniaxial
    stress along x, y or z sees (the two normal deviatoric ones and the volumetric one), as the
    mean of two probes of the network alone: its boundary held on the affine strain (an upper
    bound) and the free body under the uniform traction (a lower bound). Measured
    (``benchmarks/study_volume_rung.py``, van Gelder springs): the effective nu of a uniaxial stress
    test for nu asked 0.25 / 0.3 / 0.45 / 0.49, and the volume change per axial strain at 0.49 over
    the exact 1 - 2 nu, ranges over a structured 4^3 cube, jittered Delaunay 5^3 and 8^3 cubes, and
    20x2x2 and 10x1x1 beams:

    ======================================  ===========================================  ===========
    calibration                             nu at 0.25 / 0.3 / 0.45 / 0.49                volume
    ======================================  ===========================================  ===========
    held, all five deviatoric (before)      .13-.20 / .21-.26 / .41-.43 / .46-.48         1.21-1.42
    ideal network, kappa = lambda - mu      .13-.20 / .21-.26 / .41-.44 / .46-.48         1.14-1.42
    free, all five                          .15-.20 / .18-.25 / .39-.43 / .46-.48         1.35-2.08
    mean of held and free, all five         .14-.20 / .20-.25 / .40-.43 / .46-.48         1.28-1.62
    held or free with the volume term,      as the probe alone, within 0.003              1.19-1.99
    (s, kappa) solved on the mesh
    held, axes                              .23-.25 / .29-.30 / .43-.45 / .47-.49         0.91-0.98
    free, axes                              .24-.27 / .29-.31 / .43-.45 / .47-.49         0.97-1.05
    **mean of held and free, axes**         .24-.26 / .29-.31 / .43-.45 / .47-.49         0.96-1.00
    the same on a Delaunay cube, applied    .20-.25 / .26-.30 / .42-.45 / .46-.49         1.00-1.24
    to every mesh
    ======================================  ===========================================  ===========

    The chosen mean keeps E at 0.99-1.06 of the material's (before: 1.16-1.45; the free probe alone
    gives 1.16 on the 10x1x1 beam, the held one alone 9% too little volume change there).
    The 20x2x2 beam's nu reads 0.023 low at 0.49 whatever the calibration: its lateral faces do not
    stay flat, and its volume change (4% off) is the better measure there. With the Lloyd rule the
    same choice gives nu .24-.27 / .29-.31 / .42-.45 / .46-.49 and volume 0.91-1.03.

    The anisotropy, not the boundary condition, was the error: weighting the shears (which a
    uniaxial stress along an axis does not see) made E 16-45% stiff and the volume change 1.2-1.4x
    too large. Solving for (s, kappa) with the volume term inside the probe (a secant on kappa / s,
    one factorisation of the 2-ring matrix per step) moves nu by 0.003 at most, at 40-70 times the
    cost, so the network is probed alone. On the
    held-out gmsh shapes (torus, capsule, L-bracket, bunny) the calibrated model's nu, free under
    uniaxial tractions along the axes or with its boundary held, is within 0.007 of the asked one (nu 0.25-0.49);
    the bunny's volume change under gravity (a body squeezed as a whole) is 1.04x P2's at nu 0.49.
    The other shapes bend: their net volume change is 0.1-0.7% of its compressed and stretched
    parts, a cancellation that no calibration makes meaningful. The price of the axes: the shear
    modulus of a structured grid is half the material's (it was 0.7x); torsion there is soft.
    The probes cost two AMG-CG solves of the network (3 right-hand sides each; sparse LU on small
    meshes): 0.4 s at 3-4k nodes and about 3 s at 20k, 5-7 times the spring model's build on a fresh
    mesh (the calibration before, one sparse LU: 0.7-1.3 s and 20-100 s).
``"smoothed"``
    The node-based selective smoothed element (alpha-FEM / NS-FEM with nodal volume):
    :class:`~volspring.elements.CorotatedTets` with shear (1 - alpha) mu, a
    :class:`~volspring.elements.NodalStrain` with shear alpha mu on node domains, and one with bulk
    min(lambda, :data:`PAIR_BULK_CAP` mu) on pairs of nodes (:func:`~volspring.elements.tet_kinematics.pair_nodes`:
    one volume constraint per node locks partially on coarse meshes whose nodes are mostly on the surface,
    ``benchmarks/study_locking.py``); above the cap (nu > 0.476) the rest of lambda is on the coarser domains of
    :func:`~volspring.elements.tet_kinematics.merged_pairs`, pairs with no interior node merged into a neighbour,
    which do not lock as nu -> 1/2 while the pairs' part keeps every volume change in between stiff. A scene
    gives both sets' volume to the nodes its supports leave free (:meth:`~volspring.elements.NodalStrain.supported`);
    mu and lambda come straight from E and nu, no calibration. It passes
    the patch test (exact E and nu on any mesh); its stiffness couples each node's 2-ring (the
    implicit step applies it as a product, :mod:`volspring.integrators.implicit`).

Materials per region: a model takes one material for the whole mesh, or a region tag per tet
(``regions``, e.g. gmsh physical groups, :func:`meshing.mesh_io.read_tet_regions`) and a
material per tag (``materials``); spring rules sum per-tet contributions with each tet's E,
smoothing domains never cross a region boundary, masses use each tet's density.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp

from volspring.elements import CorotatedTets, NodalStrain
from volspring.material import Material, _real_number, _shown
from collections.abc import Mapping
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from meshing.mesh import TetMesh
    from volspring.elements.springs import Springs

__all__ = ["DEFAULT_ALPHA", "MODELS", "PAIR_BULK_CAP", "STAND_IN_BULK_CAP", "TetMaterials", "network_moduli",
           "network_poisson_ratio", "smoothed_elements", "stand_in_bulk", "volume_rung_moduli"]

MODELS = ("springs", "springs+volume", "smoothed")
#: Weight of the nodal (smoothed) shear in the smoothed rung: the minimax of benchmarks/study_alpha.py over the
#: held-out shapes at nu 0.25-0.49 (worst deflection error vs Taylor-Hood: 4.5% at 0.65; 7.8% at 0.6 and 9.8% at
#: 0.7, volume domains given to the free nodes by the scene).
DEFAULT_ALPHA = 0.65
#: The volume terms' preconditioner stand-in takes min(kappa, this x mu) per tet (NodalStrain's ``stand_in_bulk``):
#: the per-tet stand-in locks where kappa >> mu, and capping it cut the CG iterations of 20 steps from rest on the
#: 3,321-node README beam by 15% (smoothed) and 12% (volume rung) at nu 0.499, 8% at 0.49 and 3-5% at 0.45;
#: no change up to nu 0.4 (kappa below the cap). A cap of 10 came within 2% of these iterations from nu 0.47 up
#: but saved nothing at 0.45; one of 3 cost the smoothed rung 2% more at 0.45 (NodalStrain.preconditioner_blocks
#: has the figures). ``benchmarks/bench_ladder.py --nu 0.499`` prints the steps.
STAND_IN_BULK_CAP = 5.0
#: The smoothed rung's volume term on node pairs takes min(lambda, this x mu) per tet; the rest of lambda goes on
#: merged pairs (:func:`smoothed_elements`). ``benchmarks/study_locking.py`` (the linearised rung against Taylor-Hood
#: on the held-out shapes refined once): the worst drift of the deflection from nu 0.45 to 0.499 over the four
#: shapes is 2.3% with a cap of 10, 0.7% with 16, 0.6% with 20 and 1.3% with 25 (4.9% on pairs alone, the bunny),
#: the worst error over nu 0.25-0.49 4.3% with each (4.8% on pairs alone). Of 16 and 20, 20: in Newton solves
#: from a cube with a face snapped to -90% (tests/test_large_deformation.py's, structured and gmsh cubes, nu 0.49
#: and 0.499, alpha 0.6-0.7, the default exact Hessian) 16 settled once in a folded equilibrium (one tet inverted)
#: and failed to converge once, 20 always came back, pairs alone failed twice. 20 leaves nu <= 0.476 as it was.
PAIR_BULK_CAP = 20.0


@dataclass(frozen=True, eq=False)
class TetMaterials:
    """The material of every tet: E [Pa], nu, density [kg/m^3] as (T,) arrays, and the region tags.

    Build with :meth:`of`.
    """

    E: np.ndarray
    nu: np.ndarray
    density: np.ndarray
    regions: np.ndarray | None

    @classmethod
    def of(cls, tet_count: int, material: Material, *, regions: np.ndarray | None = None,
           materials: Mapping[int, Material] | None = None) -> "TetMaterials":
        """Per-tet materials from one ``material`` (the default) and optional ``materials`` per region tag.

        Parameters
        ----------
        tet_count : int
        material : Material
            for every tet whose region has no entry in ``materials``
        regions : (T,) int, optional
            a region tag per tet (>= 0)
        materials : mapping of int to Material, optional
            requires ``regions``
        """
        if not isinstance(material, Material):
            raise TypeError(f"material must be a volspring.Material, got {type(material).__name__}")
        E = np.full(tet_count, material.E)
        nu = np.full(tet_count, material.nu)
        density = np.full(tet_count, material.density)
        if materials and regions is None:
            raise ValueError("materials= gives a material per region tag: it needs regions=, a tag per tet")
        if regions is not None:
            regions = np.asarray(regions)
            if regions.shape != (tet_count,) or regions.dtype.kind not in "iu":
                raise ValueError(f"regions must be ({tet_count},) integer tags, one per tet; got shape "
                                 f"{regions.shape}, dtype {regions.dtype}")
            if tet_count and regions.min() < 0:
                raise ValueError(f"regions hold {regions.min()}; expected tags >= 0")
            regions = regions.astype(np.int64)
            for tag, region_material in dict(materials or {}).items():
                if not isinstance(region_material, Material):
                    raise TypeError(f"materials[{tag!r}] = {_shown(region_material)} is not a volspring.Material")
                where = regions == tag
                if not where.any():
                    raise ValueError(f"materials names region {tag!r}, but no tet has that tag (tags present: "
                                     f"{np.unique(regions).tolist()})")
                E[where], nu[where], density[where] = region_material.E, region_material.nu, region_material.density
        return cls(E, nu, density, regions)

    @property
    def shear_modulus(self) -> np.ndarray:
        return self.E / (2.0 * (1.0 + self.nu))

    @property
    def lame_lambda(self) -> np.ndarray:
        return self.E * self.nu / ((1.0 + self.nu) * (1.0 - 2.0 * self.nu))

    @property
    def bulk_modulus(self) -> np.ndarray:
        return self.E / (3.0 * (1.0 - 2.0 * self.nu))


def checked_alpha(alpha) -> float:
    alpha = DEFAULT_ALPHA if alpha is None else _real_number("alpha", alpha)
    if not 0.0 <= alpha <= 1.0:
        raise ValueError(f"alpha = {alpha} is not in [0, 1] (the weight of the smoothed nodal shear)")
    return alpha


#: Above this many unknowns the probes solve by AMG-preconditioned CG instead of sparse LU: LU of a
#: tet-edge network grows faster than linearly (20 s to 100 s at 20k nodes, measured, against 0.5 s
#: for the spring model's build); smoothed aggregation keeps the probes a small multiple of the build.
PROBE_DIRECT_UNKNOWNS = 6000
#: Relative residual of the probes' CG solves: the energies are quadratic in the error, so 1e-4 leaves
#: them exact to far below the percent level that matters here.
PROBE_RTOL = 1e-4


def _probe_tensors():
    """The probes' three unit tensors: the two deviatoric ones with only normal (axis) components and I / sqrt(3).

    Together they span the diagonal tensors: a uniaxial stress or strain along x, y or z is a
    combination of them (the shear tensors are left out, see :func:`network_moduli`).
    """
    return (np.diag([1.0, -1.0, 0.0]) / math.sqrt(2.0), np.diag([1.0, 1.0, -2.0]) / math.sqrt(6.0),
            np.eye(3) / math.sqrt(3.0))


def _solve_spd(matrix, right_hand_sides, points):
    """Solutions of the SPD ``matrix`` (3 m unknowns, m nodes at ``points``) for each right-hand side.

    Sparse LU up to :data:`PROBE_DIRECT_UNKNOWNS`, else volspring's AMG-preconditioned CG (one hierarchy
    for all right-hand sides, the rigid modes as near-null space) to :data:`PROBE_RTOL`.
    """
    from meshing.geometry import rigid_body_modes
    from volspring.solvers import AMGConjugateGradient

    matrix = sp.csr_matrix(matrix)
    if matrix.shape[0] == 0:
        return [np.zeros(0) for _ in right_hand_sides]
    if matrix.shape[0] <= PROBE_DIRECT_UNKNOWNS:
        from scipy.sparse.linalg import splu

        factor = splu(sp.csc_matrix(matrix))
        return [factor.solve(b) for b in right_hand_sides]
    solver = AMGConjugateGradient(rtol=PROBE_RTOL)
    solver.build(sp.bsr_matrix(matrix, blocksize=(3, 3)), rigid_body_modes(points))
    return [solver.solve(matrix, b)[0] for b in right_hand_sides]


def _network_stiffness(mesh, springs):
    """(3 n, 3 n) CSR -- the stiffness at rest of the springs among the mesh's nodes (shell springs left out)."""
    from volspring.assembly import stiffness_matrix
    from volspring.elements import Springs
    from volspring.model import Model

    n = mesh.node_count
    inside = (springs.pairs < n).all(axis=1)
    network = Springs(n, springs.pairs[inside], springs.stiffness[inside], 0.0, springs.rest_lengths[inside], 0)
    return stiffness_matrix(Model(mesh.points, np.ones(n), (network,)), mesh.points).tocsr()


def _held_probe(mesh, stiffness) -> np.ndarray:
    """(3,) -- energy per volume with the boundary nodes held on each probe strain, the interior relaxed."""
    held = np.zeros(mesh.node_count, dtype=bool)
    held[mesh.boundary_nodes] = True
    held_dofs = np.repeat(held, 3)
    free = ~held_dofs
    centred = mesh.points - mesh.points.mean(axis=0)
    imposed = [(centred @ strain.T).ravel() for strain in _probe_tensors()]
    inner = stiffness[free][:, free]
    coupling = stiffness[free][:, held_dofs]
    relaxed = _solve_spd(inner, [-(coupling @ u[held_dofs]) for u in imposed], mesh.points[~held])
    energies = []
    for u, inside in zip(imposed, relaxed):
        u = u.copy()
        u[free] = inside
        energies.append(0.5 * u @ (stiffness @ u) / mesh.volume)
    return np.array(energies)


def _support_dofs(points, components) -> np.ndarray:
    """Six dofs per connected component that hold its rigid motions (a "3-2-1" support), as flat dof indices."""
    from scipy.linalg import qr

    from meshing.geometry import rigid_body_modes

    dofs = []
    for label in range(components.max() + 1):
        nodes = np.flatnonzero(components == label)
        p = points[nodes]
        a = int(np.argmax(np.linalg.norm(p - p.mean(axis=0), axis=1)))
        b = int(np.argmax(np.linalg.norm(p - p[a], axis=1)))
        c = int(np.argmax(np.linalg.norm(np.cross(p[b] - p[a], p - p[a]), axis=1)))
        candidates = np.repeat(nodes[[a, b, c]] * 3, 3) + np.tile(np.arange(3), 3)
        modes = rigid_body_modes(p)[np.repeat(np.array([a, b, c]) * 3, 3) + np.tile(np.arange(3), 3)]
        _, _, order = qr(modes.T, pivoting=True)
        dofs.append(candidates[np.sort(order[:6])])
    return np.concatenate(dofs)


def _free_probe(mesh, stiffness) -> np.ndarray:
    """(3,) -- compliance sigma : eps_mean of the free body under uniform tractions sigma n, each probe stress."""
    from scipy.sparse.csgraph import connected_components

    n = mesh.node_count
    _, components = connected_components(sp.csr_matrix((np.ones(mesh.tets.size), (np.repeat(mesh.tets[:, 0], 4),
                                                                                    mesh.tets.ravel())), (n, n)),
                                         directed=False)
    pinned = np.zeros(3 * n, dtype=bool)
    pinned[_support_dofs(mesh.points, components)] = True
    faces = mesh.boundary_faces
    corners = mesh.points[faces]
    area_normals = 0.5 * np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    loads = []
    for stress in _probe_tensors():
        traction = area_normals @ stress.T / 3.0  # each face's load sigma n A, a third to each corner
        loads.append(np.stack([np.bincount(faces.ravel(), weights=np.repeat(traction[:, c], 3), minlength=n)
                               for c in range(3)], axis=1).ravel())
    # The loads are self-equilibrated (a closed surface, a symmetric sigma): the supports carry nothing.
    # They are held as rows and columns of the identity (scaled), which keeps the 3 x 3 block structure.
    keep = sp.diags((~pinned).astype(float))
    scale = float(stiffness.diagonal().mean())
    held = (keep @ stiffness @ keep + sp.diags(pinned * scale)).tocsr()
    solved = _solve_spd(held, [np.where(pinned, 0.0, f) for f in loads], mesh.points)
    return np.array([f @ u for f, u in zip(loads, solved)]) / mesh.volume


def network_moduli(mesh: TetMesh, springs: Springs) -> tuple:
    """The shear and bulk modulus of a spring network on a tet mesh, measured on the mesh itself.

    Two probes of the network alone (each one sparse factorisation or AMG hierarchy, three
    right-hand sides), the mean of their moduli:

    - held: the boundary nodes on an affine strain u = eps X, the interior relaxed; energy per
      volume ``mu |eps|^2`` for a deviatoric eps of unit norm, ``(3/2) K`` for eps = I / sqrt(3).
      An upper bound (the boundary cannot relax).
    - free: the free body under uniform tractions sigma n (held only against rigid motion);
      compliance ``sigma : eps_mean = 1 / (2 mu)`` for a deviatoric sigma of unit norm, ``1 / (3 K)``
      for sigma = I / sqrt(3). A lower bound (the surface is softer than the bulk).

    The deviatoric tensors are the two normal ones, diag(1, -1, 0) / sqrt(2) and diag(1, 1, -2) /
    sqrt(6), not the shears: a uniaxial stress along x, y or z, and the bending and stretching of
    bodies along the axes, see only these (a tet network on a grid is cubic, not isotropic: on a
    structured box its shear modulus is half its normal one). Measured comparison: the module docstring.

    Parameters
    ----------
    mesh : TetMesh
        the springs' nodes 0..n-1 are the mesh's nodes (springs to other nodes, shells, are left out)
    springs : Springs
        at rest

    Returns
    -------
    mu_s, K_s : float
        [Pa]
    """
    stiffness = _network_stiffness(mesh, springs)
    held = _held_probe(mesh, stiffness)
    free = _free_probe(mesh, stiffness)
    mu_held, bulk_held = float(held[:2].mean()), 2.0 * float(held[2]) / 3.0
    mu_free, bulk_free = 1.0 / (2.0 * float(free[:2].mean())), 1.0 / (3.0 * float(free[2]))
    return 0.5 * (mu_held + mu_free), 0.5 * (bulk_held + bulk_free)


def network_poisson_ratio(mu_s: float, K_s: float) -> float:
    """nu of an isotropic solid with shear modulus mu_s and bulk modulus K_s."""
    return (3.0 * K_s - 2.0 * mu_s) / (2.0 * (3.0 * K_s + mu_s))


def smoothed_elements(mesh: TetMesh, tet_materials: TetMaterials, *, alpha: float | None = None,
                      stiffness_damping: float = 0.0, pair_bulk_cap: float = PAIR_BULK_CAP) -> tuple:
    """The smoothed rung's element sets: CorotatedTets((1 - alpha) mu), the nodal shear NodalStrain(alpha mu, 0)
    on node domains, the volume NodalStrain(0, min(lambda, pair_bulk_cap mu)) on pairs of nodes
    (:func:`~volspring.elements.tet_kinematics.pair_nodes`) and, where some tet's lambda is above that, a
    NodalStrain(0, the rest of lambda) on merged pairs (:func:`~volspring.elements.tet_kinematics.merged_pairs`).

    The two volume sets' bulk coefficients sum to lambda in every tet, so a uniform strain still sees exactly the
    material's moduli (the patch test); the preconditioner's stand-in keeps min(lambda, STAND_IN_BULK_CAP mu) on
    the pairs and nothing on the merged pairs, as with pairs alone. ``pair_bulk_cap`` (in units of mu, > 0; default
    :data:`PAIR_BULK_CAP`) is for studies: ``np.inf`` puts all of lambda on the pairs (the rung before merged pairs).
    """
    alpha = checked_alpha(alpha)
    cap = _real_number("pair_bulk_cap", pair_bulk_cap)
    if not cap > 0.0:
        raise ValueError(f"pair_bulk_cap = {cap!r}: expected a number > 0 (the pairs' bulk coefficient in units of "
                         "mu)")
    mu, lam = tet_materials.shear_modulus, tet_materials.lame_lambda
    on_pairs = np.minimum(lam, cap * mu)
    regions = tet_materials.regions
    elements = (CorotatedTets(mesh.points, mesh.tets, (1.0 - alpha) * mu, stiffness_damping=stiffness_damping),
                NodalStrain(mesh.points, mesh.tets, alpha * mu, 0.0, regions=regions,
                            stiffness_damping=stiffness_damping),
                NodalStrain(mesh.points, mesh.tets, 0.0, on_pairs, regions=regions, clusters="pairs",
                            stiffness_damping=stiffness_damping, stand_in_bulk=stand_in_bulk(lam, mu)))
    if (lam > on_pairs).any():
        elements += (NodalStrain(mesh.points, mesh.tets, 0.0, lam - on_pairs, regions=regions, clusters="merged pairs",
                                 stiffness_damping=stiffness_damping, stand_in_bulk=0.0),)
    return elements


def stand_in_bulk(kappa: np.ndarray, mu: np.ndarray) -> np.ndarray:
    """(T,) -- the volume term's preconditioner stand-in coefficient per tet: min(kappa, STAND_IN_BULK_CAP mu)."""
    return np.minimum(kappa, STAND_IN_BULK_CAP * mu)


def volume_rung_moduli(mesh: TetMesh, tet_materials: TetMaterials, unit_springs: Springs) -> tuple:
    """Per-tet spring modulus E'_t and bulk coefficient kappa_t of the ``"springs+volume"`` rung.

    ``unit_springs`` are the rule's springs for E = 1 in every tet (a rule is linear in each tet's
    E): their network moduli (mu_1, K_1) give E'_t = mu_t / mu_1 (network shear modulus = mu_t) and
    kappa_t = K_t - E'_t K_1. A ValueError names the first tet whose nu is below the network's own.
    """
    mu_unit, bulk_unit = network_moduli(mesh, unit_springs)
    modulus = tet_materials.shear_modulus / mu_unit
    kappa = tet_materials.bulk_modulus - modulus * bulk_unit
    # At nu equal to the network's own (1/4 for an ideal network) kappa is 0 up to round-off.
    kappa[(kappa < 0) & (kappa > -1e-9 * tet_materials.bulk_modulus)] = 0.0
    if (kappa < 0).any():
        t = int(np.argmin(kappa))
        raise ValueError(f"model 'springs+volume' cannot reach nu = {tet_materials.nu[t]:g} (tet {t}) on this mesh: the "
                         f"spring network alone has nu = {network_poisson_ratio(mu_unit, bulk_unit):.3f}, so its volume "
                         f"term would need a negative bulk coefficient ({kappa[t]:.4g} Pa); expected nu at or above "
                         "the network's. Use model='smoothed' (exact for any nu), or plain 'springs'")
    return modulus, kappa


def with_stiffness_damping(model, damping_ratio):
    """``model`` with Rayleigh stiffness damping b = 2 zeta / omega_max on its continuum sets.

    omega_max is the model's highest angular frequency, free-floating (:func:`volspring.stability.omega_max`):
    the highest mode gets the damping ratio zeta, a mode of frequency omega gets zeta omega / omega_max.
    """
    from volspring.stability import omega_max

    omega = omega_max(model)
    b = 2.0 * float(damping_ratio) / omega if omega > 0 else 0.0
    elements = tuple(element_set.with_stiffness_damping(b) if isinstance(element_set, (CorotatedTets, NodalStrain))
                     else element_set for element_set in model.elements)
    from dataclasses import replace

    return replace(model, elements=elements)
