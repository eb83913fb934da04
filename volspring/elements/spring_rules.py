"""Springs and masses from a mesh and a material: the stiffness rules, virtual shells, damping.

Stiffness rules (``rule=``), per tet edge e, summed over the tets t that contain e:

``van_gelder``
    k_e = sum_t E V_t / l_e^2 (Van Gelder, "Approximate simulation of elastic membranes by
    triangulated spring meshes", JGT 3(2), 1998, 3D form).
``lloyd``
    k_e = sum_t (2 sqrt(2) / 25) E l_t with l_t = (6 sqrt(2) V_t)^(1/3), the edge length of the
    regular tet of volume V_t (Lloyd, Szekely, Harders, IEEE TVCG 13(5), 2007). A least-squares
    fit of six springs to one linear tet's FEM stiffness gives this exactly at nu = 1/4.
``uniform``
    k_e = ``stiffness`` for every spring: a raw constant, for comparisons with tools that take one.

Whatever the rule, a network of central springs behaves as an isotropic solid only with
lambda = mu, i.e. nu = 1/4 (the Cauchy limit): the material's nu is not reproduced.

Virtual shells. Between shell layer k-1 and k every shell triangle spans a prism of volume
V_p. Each spring of the prism (the 3 top edges, 3 straight and 6 diagonal springs) gets the
rule's contribution from V_p as if it were a tet of that volume (E V_p / l^2 for
``van_gelder``, (2 sqrt(2)/25) E (6 sqrt(2) V_p)^(1/3) for ``lloyd``), and the prism's mass
density x V_p goes in thirds to its 3 top nodes. The body's own nodes keep exactly the mass of
their tets, so the real body weighs density x mesh volume with or without shells.

Damping. ``damping_ratio`` zeta gives each spring k_d = 2 zeta sqrt(k_e m_ij), critical
damping of the two-body oscillator with reduced mass m_ij = m_i m_j / (m_i + m_j);
``damping`` gives k_d [N s/m] directly.

Force laws (``law=``) say how a raw constant is read: ``hooke`` f = k (l - l0) with k in N/m,
``strain`` f = k (l - l0) / l0 with k in N (the seed's strain form). The model stores the
effective linear stiffness k_e [N/m] either way; material rules give k_e directly.
"""

from __future__ import annotations

import numpy as np

from meshing.topology import SPRING_KINDS
from volspring.elements.springs import Springs
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from meshing.topology import SpringTopology
    from volspring.material import Material

__all__ = ["FORCE_LAWS", "NU_IGNORING_RULES", "STIFFNESS_RULES", "springs_from_topology"]

STIFFNESS_RULES = ("van_gelder", "lloyd", "uniform")
#: Rules that build pure springs from E alone: they cannot honour a Poisson ratio (the Cauchy limit).
NU_IGNORING_RULES = STIFFNESS_RULES
FORCE_LAWS = ("hooke", "strain")


def springs_from_topology(topology: SpringTopology, material: Material, *, rule: str, stiffness: float | None = None,
                          law: str = "hooke", damping_ratio: float | None = None,
                          damping: float | np.ndarray | None = None, tet_moduli: np.ndarray | None = None,
                          tet_densities: np.ndarray | None = None) -> tuple:
    """Masses and springs of a (checked) topology and material by a stiffness rule.

    Parameters
    ----------
    topology : SpringTopology
        a tet mesh's springs, with shells or not
    material : Material
    rule, stiffness, law, damping_ratio, damping
        as for :meth:`volspring.Model.from_mesh` (checked there)
    tet_moduli, tet_densities : (m,) float, optional
        E [Pa] and density [kg/m^3] of every mesh tet instead of the material's (materials per region; shells keep
        ``material``)

    Returns
    -------
    masses : (n,) float
        [kg]
    springs : Springs
    """
    mesh, n = topology.mesh, topology.node_count
    springs, lengths = topology.springs, topology.rest_lengths
    masses = np.zeros(n)
    if tet_densities is None:
        masses[: mesh.node_count] = material.density * mesh.node_volumes()
    else:
        masses[: mesh.node_count] = np.bincount(mesh.tets.ravel(), minlength=mesh.node_count,
                                                weights=np.repeat(tet_densities * mesh.tet_volumes / 4, 4))
    moduli = np.full(mesh.tet_count, material.E) if tet_moduli is None else tet_moduli
    k = np.zeros(len(springs))
    if rule == "uniform":
        k[:] = _effective_stiffness(np.full(len(springs), stiffness), lengths, law)
    else:
        edge_of_spring = _pair_index(springs, n, mesh.edges)
        if (edge_of_spring < 0).any():
            raise ValueError("the topology lacks springs for some tet edges")
        tet_edges = edge_of_spring[mesh.tet_edge_index]  # (m, 6) spring index of each tet edge
        contributions = _rule_stiffness(rule, np.repeat(moduli, 6), np.repeat(mesh.tet_volumes, 6),
                                        lengths[tet_edges.ravel()])
        k += np.bincount(tet_edges.ravel(), weights=contributions, minlength=len(springs))
    if topology.shell_node_count:
        prism_springs, prism_volumes, prism_tops = _shell_prisms(topology)
        masses += np.bincount(prism_tops.ravel(), weights=np.repeat(material.density * prism_volumes / 3, 3),
                              minlength=n)
        if rule != "uniform":
            contributions = _rule_stiffness(rule, material.E, np.repeat(prism_volumes, 12),
                                            lengths[prism_springs.ravel()])
            k += np.bincount(prism_springs.ravel(), weights=contributions, minlength=len(springs))
    if (masses <= 0).any():
        raise ValueError(f"{(masses <= 0).sum()} node(s) got no mass (shell nodes in no shell triangle?)")
    if damping_ratio is not None:
        m_i, m_j = masses[springs[:, 0]], masses[springs[:, 1]]
        damping = 2.0 * damping_ratio * np.sqrt(k * m_i * m_j / (m_i + m_j))
    return masses, Springs(n, springs, k, 0.0 if damping is None else damping, lengths, topology.kinds)


def _rule_stiffness(rule, E, volumes, lengths):
    """Per-(element, spring) contribution of one stiffness rule [N/m]."""
    if rule == "van_gelder":
        return E * volumes / lengths**2
    if rule == "lloyd":
        return (2.0 * np.sqrt(2.0) / 25.0) * E * np.cbrt(6.0 * np.sqrt(2.0) * volumes)
    raise ValueError(f"unknown stiffness rule {rule!r}; known: {', '.join(STIFFNESS_RULES)}")


def _pair_index(springs, node_count, pairs):
    """Index into ``springs`` of each (a, b) in ``pairs`` (either order); -1 where absent."""
    keys = springs.min(axis=1) * node_count + springs.max(axis=1)
    order = np.argsort(keys)
    query = pairs.min(axis=1) * node_count + pairs.max(axis=1)
    where = np.minimum(np.searchsorted(keys, query, sorter=order), len(keys) - 1)
    found = order[where]
    return np.where(keys[found] == query, found, -1)


def _effective_stiffness(k, rest_lengths, law):
    if law == "hooke":
        return k
    if law == "strain":
        return k / rest_lengths
    raise ValueError(f"unknown force law {law!r}; known: {', '.join(FORCE_LAWS)}")


def _shell_prisms(topology):
    """Prisms between consecutive shell layers.

    Returns
    -------
    springs : (p, 12) int
        spring index of each prism's 3 top edges, 3 straight and 6 diagonal springs
    volumes : (p,) float
        prism volumes [m^3]
    tops : (p, 3) int
        the prism's top-layer nodes
    """
    n = topology.node_count
    straight = topology.springs[topology.kinds == SPRING_KINDS.index("shell")]
    layer = topology.shell_layer
    child = np.where(layer[straight[:, 0]] > layer[straight[:, 1]], straight[:, 0], straight[:, 1])
    parent_of = np.full(n, -1)
    parent_of[child] = straight.sum(axis=1) - child
    top = topology.shell_triangles
    bottom = parent_of[top]
    if (bottom < 0).any():
        raise ValueError("a shell triangle has a node with no straight spring to the layer below")
    a0, b0, c0 = bottom.T
    a1, b1, c1 = top.T
    pairs = np.stack([(a1, b1), (b1, c1), (c1, a1), (a0, a1), (b0, b1), (c0, c1),
                      (a0, b1), (b0, a1), (b0, c1), (c0, b1), (c0, a1), (a0, c1)], axis=1)  # (2, 12, p)
    springs = _pair_index(topology.springs, n, pairs.reshape(2, -1).T).reshape(12, -1).T
    if (springs < 0).any():
        raise ValueError("a shell prism lacks one of its 12 springs (top edges, straight or diagonal)")
    x = topology.points
    split = [(a0, b0, c0, a1), (b0, c0, a1, b1), (c0, a1, b1, c1)]
    volumes = sum(np.abs(np.einsum("ij,ij->i", x[q] - x[p], np.cross(x[r] - x[p], x[s] - x[p]))) / 6
                  for p, q, r, s in split)
    return springs, volumes, top
