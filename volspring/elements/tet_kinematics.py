"""Deformation gradients of linear tets, their nodal averages, and the corotational kernel.

Shared by the continuum element sets (:mod:`volspring.elements.continuum`).

- A linear tet t with rest corners X_a has shape-function gradients g_ta (rest frame, sum over
  a is zero) and a constant deformation gradient F_t = sum_a x_a g_ta^T.
- A *smoothing domain* is a node together with the tets around it that share one material
  region (a node on a material interface has one domain per region). Its rest volume is
  V_d = sum V_t / 4 over those tets, its averaged gradient Fbar_d = sum (V_t / 4 V_d) F_t =
  sum_a x_a gbar_da^T is linear in the positions of the domain's *ring* (the nodes of its
  tets), and its current volume v_d = sum v_t / 4 sums to the body's volume over all domains.
- The corotational energy density psi(F) = |F - R|^2, R the rotation of F's polar
  decomposition (taken from a rotation-preserving SVD, F = U diag(s) V^T with det U = det V = 1,
  so an inverted F has s_3 < 0 and is pushed back), reduces to |eps|^2 at small strain, eps the
  linear strain. Its gradient is 2 (F - R); its Hessian (Smith, de Goes, Kim 2019, "Analytic
  eigensystems for isotropic distortion energies") is 2 (I - sum_r c_r q_r q_r^T) with the three
  twist directions q_r = U (e_i e_j^T - e_j e_i^T) V^T / sqrt(2) and c_r = 2 / (s_i + s_j); it
  is positive semi-definite exactly when every c_r <= 1, so the projection clamps c_r to 1.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

__all__ = ["SmoothingDomains", "TetGradients", "corotational", "domain_pairs"]

_TWIST_PAIRS = ((0, 1), (0, 2), (1, 2))


@dataclass(frozen=True, eq=False)
class TetGradients:
    """Rest volumes and shape-function gradients of a set of linear tets.

    Parameters
    ----------
    tets : (T, 4) int -- corner nodes
    volumes : (T,) float -- rest volumes [m^3], > 0
    gradients : (T, 4, 3) float -- g_ta [1/m]
    """

    tets: np.ndarray
    volumes: np.ndarray
    gradients: np.ndarray

    @classmethod
    def at_rest(cls, rest_positions, tets, *, owner="tets") -> "TetGradients":
        """The gradients of ``tets`` at ``rest_positions``; a ValueError names the first tet that is not
        positively oriented with a non-zero volume (``owner`` names the array in the message)."""
        tets = np.asarray(tets, dtype=np.int64)
        corners = np.asarray(rest_positions, dtype=np.float64)[tets]
        edges = np.transpose(corners[:, 1:] - corners[:, :1], (0, 2, 1))  # columns x_a - x_0
        volumes = np.linalg.det(edges) / 6.0
        scale = np.abs(edges).max(axis=(1, 2)) ** 3 if len(tets) else np.zeros(0)
        from meshing.tolerances import ZERO_VOLUME

        bad = ~(volumes > ZERO_VOLUME * scale)
        if bad.any():
            t = int(np.flatnonzero(bad)[0])
            raise ValueError(f"{owner}[{t}] = {tets[t].tolist()} has rest volume {volumes[t]:.6g} m^3; expected a "
                             f"positively oriented tet with volume > 0 ({int(bad.sum())} such tet(s); "
                             "meshing.TetMesh.oriented fixes the orientation)")
        inverse = np.linalg.inv(edges)
        gradients = np.empty((len(tets), 4, 3))
        gradients[:, 1:] = inverse
        gradients[:, 0] = -inverse.sum(axis=1)
        return cls(tets, volumes, gradients)

    def deformation(self, x) -> np.ndarray:
        """(T, 3, 3) float -- F_t at positions x."""
        return np.einsum("tai,taj->tij", x[self.tets], self.gradients)

    def scatter(self, per_corner, node_count) -> np.ndarray:
        """(n, 3) float -- the sum over tets of (T, 4, 3) per-corner vectors, by node."""
        nodes = self.tets.ravel()
        flat = per_corner.reshape(-1, 3)
        return np.stack([np.bincount(nodes, weights=flat[:, c], minlength=node_count) for c in range(3)], axis=1)


def corotational(F, *, project=True):
    """The corotational density psi = |F - R|^2 of each F, its gradient and Hessian pieces.

    Parameters
    ----------
    F : (m, 3, 3) float
    project : bool -- clamp the twist coefficients so that the Hessian is positive semi-definite

    Returns
    -------
    psi : (m,) float
    P : (m, 3, 3) float -- d psi / dF = 2 (F - R)
    twists : (m, 3, 3, 3) float -- q_r, r = 0..2, unit 3x3 directions
    coefficients : (m, 3) float -- c_r; the Hessian is 2 (I - sum_r c_r q_r q_r^T)
    """
    U, s, Vt = np.linalg.svd(F)
    flip_u = np.linalg.det(U) < 0
    flip_v = np.linalg.det(Vt) < 0
    U[flip_u, :, 2] *= -1.0
    s[flip_u, 2] *= -1.0
    Vt[flip_v, 2, :] *= -1.0
    s[flip_v, 2] *= -1.0
    R = U @ Vt
    psi = ((s - 1.0) ** 2).sum(axis=1)
    P = 2.0 * (F - R)
    twists = np.empty(F.shape[:1] + (3, 3, 3))
    coefficients = np.empty(F.shape[:1] + (3,))
    for r, (i, j) in enumerate(_TWIST_PAIRS):
        twists[:, r] = (U[:, :, i, None] * Vt[:, None, j, :] - U[:, :, j, None] * Vt[:, None, i, :]) / np.sqrt(2.0)
        total = s[:, i] + s[:, j]
        if project:
            # c = 2 / (s_i + s_j) <= 1 keeps 1 - c >= 0; s_i + s_j <= 0 (inverted) also clamps to 1.
            coefficients[:, r] = np.where(total > 2.0, 2.0 / np.where(total > 2.0, total, 1.0), 1.0)
        else:
            # At s_i + s_j = 0 (a tet reflected in the twist plane) R jumps and the Hessian does not
            # exist: take the projected value there rather than an infinite one.
            coefficients[:, r] = np.divide(2.0, total, out=np.ones_like(total), where=total != 0.0)
    return psi, P, twists, coefficients


class SmoothingDomains:
    """The smoothing domains of a tet mesh (see the module docstring), grouped by region.

    Parameters
    ----------
    gradients : TetGradients
    node_count : int
    regions : (T,) int, optional -- material region of every tet (domains never cross regions)

    Attributes
    ----------
    node : (d,) int -- the node of each domain
    region : (d,) int -- its region
    volumes : (d,) float -- V_d [m^3]
    ring_domain, ring_node : (r,) int -- the ring entries: domain and ring node, sorted by domain
    ring_gradient : (r, 3) float -- gbar_da of each ring entry [1/m]
    corner_entry : (T, 4, 4) int -- ring entry of (domain of corner c of tet t, node of corner a)
    corner_domain : (T, 4) int -- domain of corner c of tet t
    """

    def __init__(self, gradients: TetGradients, node_count: int, regions=None):
        tets = gradients.tets
        T = len(tets)
        regions = np.zeros(T, dtype=np.int64) if regions is None else np.asarray(regions, dtype=np.int64)
        region_count = int(regions.max()) + 1 if T else 1
        keys = tets * region_count + regions[:, None]  # (T, 4): domain key of each corner
        domain_keys, corner_domain = np.unique(keys, return_inverse=True)
        self.corner_domain = corner_domain.reshape(T, 4)
        self.node, self.region = np.divmod(domain_keys, region_count)
        self.volumes = np.bincount(self.corner_domain.ravel(), weights=np.repeat(gradients.volumes / 4.0, 4),
                                   minlength=len(domain_keys))
        # Ring entries: (domain of corner c, node of corner a) for every tet, corner pair.
        domain_of = np.broadcast_to(self.corner_domain[:, :, None], (T, 4, 4))
        node_of = np.broadcast_to(tets[:, None, :], (T, 4, 4))
        entry_keys = domain_of.astype(np.int64) * node_count + node_of
        unique_entries, corner_entry = np.unique(entry_keys, return_inverse=True)
        self.corner_entry = corner_entry.reshape(T, 4, 4)
        self.ring_domain, self.ring_node = np.divmod(unique_entries, node_count)
        weights = (gradients.volumes[:, None] / (4.0 * self.volumes[self.corner_domain]))[:, :, None, None]
        self.ring_gradient = self.sum_to_ring(weights * gradients.gradients[:, None, :, :])
        self.node_count = node_count

    @property
    def domain_count(self) -> int:
        return len(self.node)

    def sum_to_ring(self, per_corner_pair) -> np.ndarray:
        """(r, 3) float -- the sum of (T, 4, 4, 3) values per (domain corner, ring corner) into ring entries."""
        flat = np.broadcast_to(per_corner_pair, self.corner_entry.shape + (3,)).reshape(-1, 3)
        entries = self.corner_entry.ravel()
        return np.stack([np.bincount(entries, weights=flat[:, c], minlength=len(self.ring_node))
                         for c in range(3)], axis=1)

    @cached_property
    def _averaging(self):
        import scipy.sparse as sp

        shape = (self.domain_count, self.node_count)
        return tuple(sp.csr_matrix((self.ring_gradient[:, k], (self.ring_domain, self.ring_node)), shape=shape)
                     for k in range(3))

    def averaged(self, x) -> np.ndarray:
        """(d, 3, 3) float -- Fbar_d at positions x."""
        return np.stack([G @ x for G in self._averaging], axis=2)

    def spread(self, stress) -> np.ndarray:
        """(n, 3) float -- sum_d stress_d gbar_da per node a, for (d, 3, 3) ``stress`` (the transpose of
        :meth:`averaged`: forces are ``-spread(V_d P_d)``)."""
        return sum(G.T @ stress[:, :, k] for k, G in enumerate(self._averaging))

    @cached_property
    def pairs(self) -> tuple:
        """(first, second) : (p,) int -- every ordered pair of ring entries of one domain, grouped by domain."""
        counts = np.bincount(self.ring_domain, minlength=self.domain_count)
        return domain_pairs(counts)


def domain_pairs(counts) -> tuple:
    """All ordered pairs (p, q) of entries within each group, for groups of ``counts`` consecutive entries.

    >>> [a.tolist() for a in domain_pairs(np.array([2, 1]))]
    [[0, 0, 1, 1, 2], [0, 1, 0, 1, 2]]
    """
    counts = np.asarray(counts, dtype=np.int64)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    per_entry = np.repeat(counts, counts)  # group size of each entry
    entry = np.arange(counts.sum())
    first = np.repeat(entry, per_entry)
    group_start = np.repeat(np.repeat(starts, counts), per_entry)
    offsets = np.arange(len(first)) - np.repeat(np.cumsum(per_entry) - per_entry, per_entry)
    return first, group_start + offsets
