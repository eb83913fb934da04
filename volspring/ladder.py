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
    K_s and mu_s the network's own moduli and s = mu / mu_s the spring scale. For an ideal central-
    force network lambda_s = mu_s and kappa = lambda - mu (Golec et al. 2020); a real tet network is
    not ideal, so K_s and mu_s are *measured on the mesh itself* (:func:`network_moduli`: the
    network's energy under the six affine strains with its boundary nodes held on them). A
    nodal term does not lock like a per-tet one. It needs kappa >= 0, i.e. nu at or above the
    network's own (about 0.25): below, it refuses and names the accurate rung.
``"smoothed"``
    The node-based selective smoothed element (alpha-FEM / NS-FEM with nodal volume):
    :class:`~volspring.elements.CorotatedTets` with shear (1 - alpha) mu and
    :class:`~volspring.elements.NodalStrain` with shear alpha mu and bulk lambda, mu and lambda
    straight from E and nu, no calibration. It passes the patch test (exact E and nu on any mesh)
    and does not lock; its stiffness couples each node's 2-ring.

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

__all__ = ["DEFAULT_ALPHA", "MODELS", "TetMaterials", "network_moduli", "network_poisson_ratio", "smoothed_elements",
           "volume_rung_moduli"]

MODELS = ("springs", "springs+volume", "smoothed")
#: Weight of the nodal (smoothed) shear in the smoothed rung: the minimax of benchmarks/study_alpha.py over the
#: held-out shapes at nu 0.3-0.49 (worst deflection error vs P2: 5.2% at 0.65; 8% at 0.6 and 8.8% at 0.7).
DEFAULT_ALPHA = 0.65


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
    def of(cls, tet_count, material, *, regions=None, materials=None) -> "TetMaterials":
        """Per-tet materials from one ``material`` (the default) and optional ``materials`` per region tag.

        Parameters
        ----------
        tet_count : int
        material : Material -- for every tet whose region has no entry in ``materials``
        regions : (T,) int, optional -- a region tag per tet (>= 0)
        materials : mapping of int to Material, optional -- requires ``regions``
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


def _affine_strains():
    """Six strains: three orthonormal deviatoric normal/shear pairs and the volumetric one (unit Frobenius norm)."""
    strains = []
    for i, j in ((0, 1), (0, 2), (1, 2)):
        e = np.zeros((3, 3))
        e[i, j] = e[j, i] = 1.0 / math.sqrt(2.0)
        strains.append(e)
    strains.append(np.diag([1.0, -1.0, 0.0]) / math.sqrt(2.0))
    strains.append(np.diag([1.0, 1.0, -2.0]) / math.sqrt(6.0))
    strains.append(np.eye(3) / math.sqrt(3.0))
    return strains


def network_moduli(mesh, springs) -> tuple:
    """The shear and bulk modulus of a spring network on a tet mesh, measured on the mesh itself.

    The network is strained affinely on its boundary nodes (u = eps X) and relaxed inside (one
    sparse factorisation, six right-hand sides). An isotropic solid stores ``mu |eps|^2 V`` under a
    deviatoric eps of unit norm and ``(3/2) K V`` under eps = I / sqrt(3); the five deviatoric strains
    are averaged (a mesh is never exactly isotropic).

    Parameters
    ----------
    mesh : TetMesh -- the springs' nodes 0..n-1 are the mesh's nodes (springs to other nodes, shells,
        are left out)
    springs : Springs -- at rest

    Returns
    -------
    mu_s, K_s : float -- [Pa]
    """
    from scipy.sparse.linalg import splu

    from volspring.assembly import stiffness_matrix
    from volspring.elements import Springs
    from volspring.model import Model

    n = mesh.node_count
    inside = (springs.pairs < n).all(axis=1)
    network = Springs(n, springs.pairs[inside], springs.stiffness[inside], 0.0, springs.rest_lengths[inside], 0)
    K = stiffness_matrix(Model(mesh.points, np.ones(n), (network,)), mesh.points).tocsr()
    held = np.zeros(n, dtype=bool)
    held[mesh.boundary_nodes] = True
    held = np.repeat(held, 3)
    free = ~held
    factor = splu(sp.csc_matrix(K[free][:, free]))
    coupling = K[free][:, held]
    centred = mesh.points - mesh.points.mean(axis=0)
    energies = []
    for strain in _affine_strains():
        u = (centred @ strain.T).ravel()
        u[free] = factor.solve(-(coupling @ u[held]))
        energies.append(0.5 * u @ (K @ u))
    mu_s = float(np.mean(energies[:5])) / mesh.volume
    K_s = 2.0 * float(energies[5]) / (3.0 * mesh.volume)
    return mu_s, K_s


def network_poisson_ratio(mu_s, K_s) -> float:
    """nu of an isotropic solid with shear modulus mu_s and bulk modulus K_s."""
    return (3.0 * K_s - 2.0 * mu_s) / (2.0 * (3.0 * K_s + mu_s))


def smoothed_elements(mesh, tet_materials, *, alpha=None, stiffness_damping=0.0) -> tuple:
    """The smoothed rung's element sets: CorotatedTets((1 - alpha) mu) and NodalStrain(alpha mu, lambda)."""
    alpha = checked_alpha(alpha)
    mu, lam = tet_materials.shear_modulus, tet_materials.lame_lambda
    return (CorotatedTets(mesh.points, mesh.tets, (1.0 - alpha) * mu, stiffness_damping=stiffness_damping),
            NodalStrain(mesh.points, mesh.tets, alpha * mu, lam, regions=tet_materials.regions,
                        stiffness_damping=stiffness_damping))


def volume_rung_moduli(mesh, tet_materials, unit_springs) -> tuple:
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
