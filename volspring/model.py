"""The spring model: rest shape, lumped masses, springs with stiffness and damping.

A model is static data. Build it from a tet mesh (or a :class:`SpringTopology` with shells)
and a :class:`Material`, where masses come from density x volume and stiffness from a
published rule, directly from arrays for strings, custom networks and tests, or from several
placed bodies (:meth:`Model.from_bodies`; :mod:`volspring.bodies`). One type holds one body or
many: ``node_body`` gives the body of every node, ``materials`` the material of every body.

How the springs' constants and the masses come from a mesh and a material (the stiffness rules,
virtual shells, damping, force laws) is :mod:`volspring.elements.spring_rules`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np
import scipy.sparse as sp

from volspring._deprecation import deprecated_alias
from volspring.bodies import checked_body_fields
from volspring.elements import ElementSet, NodalStrain, Springs
from volspring.elements.spring_rules import FORCE_LAWS, STIFFNESS_RULES, _effective_stiffness, springs_from_topology
from volspring.elements.springs import checked_pairs, per_item_array
from volspring.material import Material, _real_array, _real_number, _shown
from meshing.mesh import TetMesh
from meshing.topology import SpringTopology, kind_counts, vector_lengths
from collections.abc import Mapping
from collections.abc import Sequence
from typing import TYPE_CHECKING, cast

if TYPE_CHECKING:
    from collections.abc import Iterable

    from volspring.bodies import Body
    from numpy.typing import ArrayLike

__all__ = ["STIFFNESS_RULES", "FORCE_LAWS", "Model"]

def _checked_positions(name, value) -> np.ndarray:
    """(n, 3) float -- finite node positions [m], n > 0."""
    x = _real_array(name, value)
    if x.ndim != 2 or x.shape[1] != 3 or len(x) == 0:
        raise ValueError(f"{name} must have shape (n, 3) with n > 0, got {x.shape}")
    bad = ~np.isfinite(x).all(axis=1)
    if bad.any():
        node = int(np.flatnonzero(bad)[0])
        raise ValueError(f"{name}[{node}] = {x[node].tolist()} m is not finite ({int(bad.sum())} node(s) "
                         "with non-finite coordinates)")
    return x


@dataclass(frozen=True, eq=False)
class Model:
    """Immutable soft-body model: rest shape, lumped masses and element sets (springs, and whatever
    other internal physics it is given).

    Parameters
    ----------
    rest_positions : (n, 3) float
        rest positions of the nodes [m]
    masses : (n,) float
        lumped node masses [kg], > 0
    elements : sequence of ElementSet
        the internal forces (:mod:`volspring.elements`); at most one :class:`~volspring.elements.Springs`
    topology : SpringTopology or None
        where the model came from, if from a mesh (for several bodies, its mesh is the union of their placed tet meshes)
    material : Material or None
        the material of every body; None when bodies differ (or none given)
    rule : str
        the stiffness rule used, "arrays", or "mixed" (bodies with different rules)
    node_body : (n,) int, optional
        body id of every node, 0 to b - 1; default all 0 (one body)
    materials : sequence of Material or None, optional
        one per body; default ``(material,)`` for every body
    body_names : sequence of str, optional
        one per body; default all ""
    rung : str
        the model's rung of the ladder (:data:`volspring.ladder.MODELS`), "springs" by default; a model built from
        arrays or with extra element sets keeps the name it was given

    Notes
    -----
    Use :meth:`from_mesh`, :meth:`from_arrays` or :meth:`from_bodies` rather than the constructor,
    and :meth:`with_elements` to add element sets. All refuse input they would misread: a TypeError
    for what is not numbers (bools, strings; numpy scalars are numbers) or for non-integer spring
    indices or body ids, a ValueError for wrong shapes, non-finite values, masses <= 0, negative
    stiffness or damping, rest lengths <= 0, springs that leave the node range or join a node to
    itself, a ``node_body`` of the wrong length, a body with no node, ``materials`` or
    ``body_names`` not one per body, naming the first offender.

    The springs' arrays are reachable directly (``model.springs`` (s, 2), ``model.stiffness``,
    ``model.damping``, ``model.rest_lengths``, ``model.kinds``; empty without springs).

    Examples
    --------
    >>> import numpy as np
    >>> from volspring import Model
    >>> pair = Model.from_arrays([[0, 0, 0], [1, 0, 0]], [1.0, 1.0], [[0, 1]], stiffness=100.0)
    >>> pair.spring_count, float(pair.rest_lengths[0])
    (1, 1.0)
    """

    rest_positions: np.ndarray
    masses: np.ndarray
    elements: tuple = ()
    topology: SpringTopology | None = None
    material: Material | None = None
    rule: str = "arrays"
    # None (the default) is filled in by __post_init__: the attributes always hold the values.
    node_body: np.ndarray = cast("np.ndarray", None)
    materials: tuple = cast(tuple, None)
    body_names: tuple = cast(tuple, None)
    rung: str = "springs"

    if TYPE_CHECKING:  # what the constructor takes (__post_init__ checks and converts it, and fills in the defaults)
        def __init__(self, rest_positions: ArrayLike, masses: ArrayLike, elements: Iterable[ElementSet] = (),
                     topology: SpringTopology | None = None, material: Material | None = None, rule: str = "arrays",
                     node_body: ArrayLike | None = None, materials: Sequence[Material | None] | None = None,
                     body_names: Sequence[str] | None = None, rung: str = "springs") -> None: ...

    def __post_init__(self):
        x = _checked_positions("rest_positions", self.rest_positions)
        n = len(x)
        masses = _real_array("masses", self.masses).ravel()
        if masses.shape != (n,):
            raise ValueError(f"len(rest_positions) = {n}, but masses have shape {masses.shape}")
        masses = per_item_array("masses", masses, n, allow_zero=False)
        if isinstance(self.elements, ElementSet):
            raise TypeError(f"elements is a single {type(self.elements).__name__}; expected a sequence, "
                            "e.g. elements=[springs]")
        elements = tuple(self.elements)
        for index, element_set in enumerate(elements):
            if not isinstance(element_set, ElementSet):
                raise TypeError(f"elements[{index}] = {_shown(element_set)} is not a volspring ElementSet")
            element_set.check(n)
        if sum(isinstance(element_set, Springs) for element_set in elements) > 1:
            raise ValueError("a model takes at most one Springs element set; join the pairs into one")
        for name, array in (("rest_positions", x), ("masses", masses)):
            array.setflags(write=False)
            object.__setattr__(self, name, array)
        object.__setattr__(self, "elements", elements)
        node_body, materials, body_names, material = checked_body_fields(
            self.node_body, self.materials, self.body_names, self.material, n)
        for name, value in (("node_body", node_body), ("materials", materials), ("body_names", body_names),
                            ("material", material)):
            object.__setattr__(self, name, value)

    # ------------------------------------------------------------------ constructors
    @classmethod
    def from_arrays(cls, positions: ArrayLike, masses: ArrayLike, springs: ArrayLike, *,
                    stiffness: float | np.ndarray, damping: float | np.ndarray = 0.0,
                    rest_lengths: float | ArrayLike | None = None, law: str = "hooke") -> "Model":
        """A model from raw arrays (strings, custom networks, tests).

        Parameters
        ----------
        positions : (n, 3) float
            rest positions [m]
        masses : (n,) float
            node masses [kg]
        springs : (s, 2) int
            node pairs
        stiffness : float or (s,) float
            k [N/m] for ``law="hooke"``, [N] for ``law="strain"``
        damping : float or (s,) float
            k_d [N s/m]
        rest_lengths : (s,) float, optional
            defaults to the distances in ``positions`` [m]
        law : {"hooke", "strain"}

        Raises
        ------
        TypeError
            Numbers that are not numbers (bools, strings), spring indices that are not integers.
        ValueError
            See the class docstring; in particular a spring between two nodes at the same
            position without ``rest_lengths`` (its rest length would be 0), naming the spring.
        """
        positions = _checked_positions("positions", positions)
        springs = checked_pairs(springs, len(positions))
        if law not in FORCE_LAWS:
            raise ValueError(f"unknown force law {law!r}; known: {', '.join(FORCE_LAWS)}")
        if rest_lengths is None:
            rest_lengths = vector_lengths(positions[springs[:, 1]] - positions[springs[:, 0]])
            if (rest_lengths == 0).any():
                e = int(np.flatnonzero(rest_lengths == 0)[0])
                i, j = springs[e]
                raise ValueError(f"springs[{e}] = [{i}, {j}] joins two nodes at the same position "
                                 f"{positions[i].tolist()} m: its rest length would be 0; expected distinct "
                                 "positions, or rest_lengths > 0")
        else:
            rest_lengths = per_item_array("rest_lengths", rest_lengths, len(springs), allow_zero=False)
        stiffness = per_item_array("stiffness", stiffness, len(springs), allow_zero=True)
        stiffness = _effective_stiffness(stiffness, rest_lengths, law)
        return cls(positions, masses, (Springs(len(positions), springs, stiffness, damping, rest_lengths, 0),))

    @classmethod
    def from_mesh(cls, body: TetMesh | SpringTopology, material: Material, *, model: str = "springs",
                  rule: str = "van_gelder", stiffness: float | None = None, law: str = "hooke",
                  damping_ratio: float | None = None, damping: float | np.ndarray | None = None,
                  alpha: float | None = None, regions: np.ndarray | None = None,
                  materials: Mapping[int, Material] | None = None) -> "Model":
        """A model from a tet mesh (or a topology with shells) and a material, on a rung of the ladder.

        Parameters
        ----------
        body : TetMesh or SpringTopology
        material : Material
            of every tet (or every tet whose region ``materials`` does not name)
        model : {"springs", "springs+volume", "smoothed"}
            the rung (:mod:`volspring.ladder`): springs only, springs with a nodal volume term that honours nu, or the
            smoothed-strain element (FEM-accurate)
        rule : {"van_gelder", "lloyd", "uniform"}
            stiffness rule (see the module docstring)
        stiffness : float, optional
            the raw constant, >= 0, required by ``rule="uniform"`` only
        law : {"hooke", "strain"}
            how the raw ``uniform`` constant is read (``uniform`` only)
        damping_ratio : float, optional
            zeta >= 0: per spring (see the module docstring); for the continuum sets of the upper rungs, Rayleigh
            stiffness damping b = 2 zeta / omega_max (zeta at the model's highest frequency, as a spring's ratio is at
            its own)
        damping : float or (s,) float, optional
            k_d [N s/m] of the springs, instead of ``damping_ratio``
        alpha : float, optional
            ``model="smoothed"`` only: the weight in [0, 1] of the nodal (smoothed) shear; default
            :data:`volspring.ladder.DEFAULT_ALPHA`
        regions : (m,) int, optional
            a region tag per tet, for ``materials``; on the smoothed rung smoothing domains never cross regions
        materials : mapping of int to Material, optional
            the material of each region tag

        Raises
        ------
        ValueError
            Besides bad input: ``model="springs+volume"`` for a nu below the spring network's own
            (the volume term would need a negative coefficient), and ``model="smoothed"`` on a
            topology with shells (shells are springs).
        """
        from volspring import ladder

        if not isinstance(body, (TetMesh, SpringTopology)):
            raise TypeError(f"body must be a TetMesh or SpringTopology, got {type(body).__name__}")
        topology = body if isinstance(body, SpringTopology) else SpringTopology.from_mesh(body)
        if not isinstance(topology.mesh, TetMesh):
            raise TypeError(f"body must be a TetMesh or SpringTopology, got {type(body).__name__}")
        if not isinstance(material, Material):
            raise TypeError(f"material must be a volspring.Material, got {type(material).__name__}")
        if not isinstance(rule, str) or rule not in STIFFNESS_RULES:
            raise ValueError(f"unknown stiffness rule {rule!r}; known: {', '.join(STIFFNESS_RULES)}")
        if (rule == "uniform") != (stiffness is not None):
            raise ValueError("stiffness= is required by rule='uniform' and only by it"
                             f" (rule={rule!r}, stiffness={stiffness!r})")
        if not isinstance(law, str) or law not in FORCE_LAWS:
            raise ValueError(f"unknown force law {law!r}; known: {', '.join(FORCE_LAWS)}")
        if law != "hooke" and rule != "uniform":
            raise ValueError(f"law={law!r} applies to rule='uniform' only: rule={rule!r} gives the stiffness "
                             "k_e [N/m] directly")
        if stiffness is not None:
            stiffness = _real_number("stiffness", stiffness)
            if not (np.isfinite(stiffness) and stiffness >= 0):
                raise ValueError(f"stiffness = {stiffness} is not finite and >= 0")
        if damping_ratio is not None and damping is not None:
            raise ValueError("give damping_ratio or damping, not both")
        if damping_ratio is not None:
            damping_ratio = _real_number("damping_ratio", damping_ratio)
            if not np.isfinite(damping_ratio) or damping_ratio < 0:
                raise ValueError(f"damping_ratio = {damping_ratio} is not finite and >= 0")

        if not isinstance(model, str) or model not in ladder.MODELS:
            raise ValueError(f"unknown model {model!r}; known: {', '.join(ladder.MODELS)}")
        if alpha is not None and model != "smoothed":
            raise ValueError(f"alpha= is the smoothed rung's weight; model={model!r} takes none")
        mesh = topology.mesh
        tet_materials = ladder.TetMaterials.of(mesh.tet_count, material, regions=regions, materials=materials)
        uniform = regions is None
        moduli, densities = (None, None) if uniform else (tet_materials.E, tet_materials.density)
        if model == "springs":
            masses, spring_set = springs_from_topology(topology, material, rule=rule, stiffness=stiffness, law=law,
                                                       damping_ratio=damping_ratio, damping=damping,
                                                       tet_moduli=moduli, tet_densities=densities)
            elements = (spring_set,)
        elif model == "springs+volume":
            if rule == "uniform":
                raise ValueError("model='springs+volume' derives the springs from the material: use rule "
                                 "'van_gelder' or 'lloyd', not 'uniform'")
            _, unit = springs_from_topology(topology, material, rule=rule, tet_moduli=np.ones(mesh.tet_count))
            moduli, kappa = ladder.volume_rung_moduli(mesh, tet_materials, unit)
            masses, spring_set = springs_from_topology(topology, material, rule=rule, damping_ratio=damping_ratio,
                                                       damping=damping, tet_moduli=moduli, tet_densities=densities)
            elements = (spring_set, NodalStrain(topology.points, mesh.tets, 0.0, kappa, regions=tet_materials.regions,
                                                stand_in_bulk=ladder.stand_in_bulk(kappa, tet_materials.shear_modulus)))
        else:
            if topology.shell_node_count:
                raise ValueError("model='smoothed' takes a tet mesh without shells (shells are springs); "
                                 "give the TetMesh, or use model='springs'")
            if rule != "van_gelder" or stiffness is not None or damping is not None:
                raise ValueError("model='smoothed' has no springs: rule=, stiffness= and damping= do not apply "
                                 "(damping_ratio= does)")
            masses, _ = springs_from_topology(topology, material, rule="van_gelder", tet_densities=densities)
            elements = ladder.smoothed_elements(mesh, tet_materials, alpha=alpha)
        result = cls(topology.points, masses, elements, topology=topology, material=material,
                     rule="none" if model == "smoothed" else rule, rung=model)
        if damping_ratio and model != "springs":
            result = ladder.with_stiffness_damping(result, damping_ratio)
        return result

    @classmethod
    def from_bodies(cls, bodies: Sequence[Body]) -> "Model":
        """One model from several placed bodies (:class:`volspring.bodies.Body`).

        Each body is built with :meth:`from_mesh` and placed; the result has ``node_body``,
        ``materials`` and ``body_names`` set, and its topology's mesh is the union of the placed
        meshes: the mesh nodes of every body first, body after body, then the shell nodes
        (:mod:`volspring.bodies`). The bodies' initial motion is not part of the model: pass
        ``volspring.bodies.initial_velocities(bodies, model)`` to ``scene.initial_state(v=...)``.

        Parameters
        ----------
        bodies : sequence of Body

        Raises
        ------
        TypeError
            For an item that is not a Body, naming its index.
        ValueError
            For no bodies, a translation or velocity that is not 3 finite numbers, a rotation that
            is not proper; and whatever :meth:`from_mesh` refuses.

        Examples
        --------
        >>> import numpy as np
        >>> from meshing import TetMesh
        >>> from volspring import Material, Model
        >>> from volspring.bodies import Body
        >>> tet = TetMesh(np.array([[0., 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]), np.array([[0, 1, 2, 3]]))
        >>> rubber = Material(E=1e5, nu=0.3, density=1000.0)
        >>> model = Model.from_bodies([Body(tet, rubber), Body(tet, rubber, translation=(2, 0, 0))])
        >>> model.body_count, model.body_nodes(1).tolist(), model.material is rubber
        (2, [4, 5, 6, 7], True)
        """
        from volspring.bodies import assemble

        return assemble(cls, bodies)

    # ------------------------------------------------------------------ element sets
    def with_elements(self, *element_sets: ElementSet) -> "Model":
        """A copy with more element sets (e.g. a volume term), everything else shared."""
        return replace(self, elements=self.elements + element_sets)

    def supported(self, held: np.ndarray) -> "Model":
        """The model a scene simulates when its supports hold the nodes ``held`` ((n,) bool): each element set's
        :meth:`~volspring.elements.ElementSet.supported`; the model itself when no set changes (springs
        never do; the smoothed rung's volume pairs do)."""
        elements = tuple(element_set.supported(held) for element_set in self.elements)
        if all(new is old for new, old in zip(elements, self.elements)):
            return self
        return replace(self, elements=elements)

    @cached_property
    def spring_elements(self) -> Springs:
        """The model's :class:`~volspring.elements.Springs` (an empty set when it has none)."""
        for element_set in self.elements:
            if isinstance(element_set, Springs):
                return element_set
        return Springs(self.node_count, np.zeros((0, 2), dtype=np.int64), 0.0, 0.0, 1.0, 0)

    def forces(self, x: np.ndarray, v: np.ndarray | None = None) -> np.ndarray:
        """(n, 3) float -- internal forces of all element sets at positions x [m] (and velocities v [m/s],
        for the dampers) [N]."""
        if not self.elements:
            return np.zeros((self.node_count, 3))
        total = self.elements[0].forces(x, v)
        for element_set in self.elements[1:]:
            total += element_set.forces(x, v)
        return total

    def energy(self, x: np.ndarray) -> float:
        """Potential energy of all element sets at positions x [J]."""
        return float(sum(element_set.energy(x) for element_set in self.elements))

    # ------------------------------------------------------------------ sizes and the springs' arrays
    @property
    def node_count(self) -> int:
        return len(self.rest_positions)

    @property
    def total_mass(self) -> float:
        return float(self.masses.sum())

    @property
    def body_count(self) -> int:
        """b, the number of bodies (``len(materials)``)."""
        return len(self.materials)

    def body_nodes(self, body: int) -> np.ndarray:
        """(k,) int64 -- the nodes of one body, ascending (from :meth:`from_bodies`: mesh nodes, then shell nodes)."""
        if not 0 <= body < self.body_count:
            raise ValueError(f"body = {body} is not a body id in [0, {self.body_count - 1}]")
        return np.flatnonzero(self.node_body == body)

    @cached_property
    def body_masses(self) -> np.ndarray:
        """(b,) float -- mass of each body [kg]."""
        masses = np.bincount(self.node_body, weights=self.masses, minlength=self.body_count)
        masses.setflags(write=False)
        return masses

    @property
    def springs(self) -> np.ndarray:
        """(s, 2) int -- node pairs of the springs."""
        return self.spring_elements.pairs

    @property
    def stiffness(self) -> np.ndarray:
        """(s,) float -- effective linear stiffness k_e of each spring [N/m]."""
        return self.spring_elements.stiffness

    @property
    def damping(self) -> np.ndarray:
        """(s,) float -- damper coefficient k_d of each spring [N s/m]."""
        return self.spring_elements.damping

    @property
    def rest_lengths(self) -> np.ndarray:
        """(s,) float -- rest length of each spring [m]."""
        return self.spring_elements.rest_lengths

    @property
    def kinds(self) -> np.ndarray:
        """(s,) int -- index into ``SPRING_KINDS`` of each spring."""
        return self.spring_elements.kinds

    @property
    def spring_count(self) -> int:
        return self.spring_elements.spring_count

    @property
    def incidence(self) -> sp.csr_matrix:
        """(n, s) sparse -- see :attr:`volspring.elements.Springs.incidence`."""
        return self.spring_elements.incidence

    @property
    def difference(self) -> sp.csr_matrix:
        """(s, n) sparse -- see :attr:`volspring.elements.Springs.difference`."""
        return self.spring_elements.difference

    def kind_counts(self) -> dict:
        """Number of springs of each kind, by label (:func:`meshing.topology.kind_counts`)."""
        return kind_counts(self.kinds)

    def __repr__(self) -> str:
        others = "".join(f", {type(e).__name__} x {e.element_count}" for e in self.elements if not isinstance(e, Springs))
        bodies = f", {self.body_count} bodies" if self.body_count > 1 else ""
        return (f"Model({self.node_count} nodes{bodies}, {self.spring_count} springs{others}, rule={self.rule!r}, "
                f"mass {self.total_mass:.6g} kg)")


def __getattr__(name):
    # SpringModel was the name of Model before it took element sets other than springs (0.1.0).
    return deprecated_alias(__name__, name, {"SpringModel": ("volspring.Model", Model)})
