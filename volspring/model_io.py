"""Model files: a whole :class:`~volspring.Model` saved to one ``.npz`` file and loaded back bit for bit.

The file is a compressed ``.npz`` (numpy, read without pickle), by convention named
``NAME.vsmodel.npz`` (:data:`MODEL_SUFFIX`). Format ``"volspring.model"``, version 1, arrays:

``format``, ``version``
    ``"volspring.model"`` and 1, 0-d;
``rest_positions`` (n, 3) float64 [m], ``masses`` (n,) float64 [kg], ``node_body`` (n,) int64
    as in the model;
``materials`` (b, 3) float64 and ``material_given`` (b,) bool
    E [Pa], nu [-], density [kg/m^3] of every body, and whether the body has a material at all
    (a model from arrays has none: its row is NaN);
``body_names`` (b,) text, ``rule`` () text
    as in the model;
``rung`` () text
    the model's rung of the ladder (:data:`volspring.ladder.MODELS`); files written before the
    ladder have none and load as ``"springs"``, which they are;
``element_types`` (e,) text
    the type of every element set, in the model's order, as named in :data:`ELEMENT_SET_TYPES`
    (``"springs"``, ``"corotated_tets"``, ``"nodal_strain"``, ``"angle_springs"``,
    ``"dihedral_springs"``); set ``i``'s arrays are
    ``elements/i/NAME``. For springs: ``pairs`` (s, 2) int64, ``stiffness`` (s,) float64 [N/m],
    ``damping`` (s,) float64 [N s/m], ``rest_lengths`` (s,) float64 [m], ``kinds`` (s,) int8 with
    ``kind_names`` (k,) text (the labels of ``SPRING_KINDS``). For the continuum sets
    (:mod:`volspring.elements.continuum`), what their constructor takes, the rest positions being
    the model's first ``node_count``: ``node_count`` () int64, ``tets`` (T, 4) int64,
    ``stiffness_damping`` () float64 [s], and per tet ``shear`` (T,) float64 [Pa]; a nodal strain
    set also ``bulk`` (T,) float64 [Pa], ``stand_in_bulk`` (T,) float64 [Pa] (its preconditioner's volume
    coefficient; files without it take ``bulk``) and ``regions`` (T,) int64, and ``clusters`` (n,) int64 when
    its domains are clusters of nodes, with ``cluster_rule`` () text (``"pairs"`` or ``"merged pairs"``) when a
    rule made them, so that a scene gives them to its free nodes, and ``held`` (n,) bool once it has (its
    per-domain coefficients and smoothing domains are rebuilt from these). For angle and dihedral springs
    (:mod:`volspring.elements.angles`): ``chains`` (e, 3) or (e, 4) int64, ``stiffness`` (e,) float64 [N m/rad^2], ``rest_angles`` (e,) float64 [rad];
``has_topology`` () bool, and ``topology/NAME``
    the spring topology the model was built from, if any, in the layout of a topology file
    (:mod:`meshing.topology_io`: points, mesh_node_count, tets, springs, kinds, shell data).

Only element sets of the types in :data:`ELEMENT_SET_TYPES` can be stored: :func:`save_model`
refuses a model with any other (a user's volume term, say) with a TypeError naming its type, rather
than write a file that would load as another model; and a continuum set built on rest positions
other than the model's (which the file would not rebuild) with a ValueError. A volspring older than
the ladder reads the files of a springs model and refuses those with continuum sets, naming the
type; the format version stays 1, as no array of a version-1 file changed meaning. The write is atomic; :func:`load_model` checks
the format name and version (a newer version is refused naming the file, the version found and
those supported), refuses a missing or malformed array naming the file and the array, and builds the
model through its own checks, so a loaded model gives the same forces bit for bit.

Examples
--------
>>> import tempfile
>>> from pathlib import Path
>>> from meshing import structured_box
>>> from volspring import Material, Model, load_model, save_model
>>> model = Model.from_mesh(structured_box((2, 2, 2), (1.0, 1.0, 1.0)), Material(E=1e5, nu=0.3, density=1000.0))
>>> path = save_model(Path(tempfile.mkdtemp()) / "cube.vsmodel.npz", model)
>>> load_model(path)
Model(27 nodes, 98 springs, rule='van_gelder', mass 1000 kg)

Every rung of the ladder is stored, its element sets bit for bit:

>>> smoothed = Model.from_mesh(structured_box((2, 2, 2), (1.0, 1.0, 1.0)), Material(E=1e5, nu=0.45, density=1000.0),
...                            model="smoothed")
>>> loaded = load_model(save_model(Path(tempfile.mkdtemp()) / "cube.vsmodel.npz", smoothed))
>>> loaded.rung, [type(element_set).__name__ for element_set in loaded.elements]
('smoothed', ['CorotatedTets', 'NodalStrain', 'NodalStrain'])
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from meshing._archive import labelled_codes, read_archive, take_array, write_archive
from meshing.topology import SPRING_KINDS
from meshing.topology_io import topology_arrays, topology_from_arrays
from volspring.elements import AngleSprings, CorotatedTets, DihedralSprings, ElementSet, NodalStrain, Springs
from volspring.elements.continuum import CLUSTER_RULES
from volspring.elements.tet_kinematics import TetGradients
from volspring.material import Material
from volspring.model import Model
import os
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from collections.abc import Callable

__all__ = ["ELEMENT_SET_TYPES", "MODEL_FORMAT", "MODEL_SUFFIX", "MODEL_VERSION", "load_model", "save_model"]

MODEL_FORMAT = "volspring.model"
#: The format version written; :data:`READABLE_VERSIONS` are those read.
MODEL_VERSION = 1
READABLE_VERSIONS = (1,)
#: The conventional file name ending of a model file.
MODEL_SUFFIX = ".vsmodel.npz"


def _springs_arrays(springs: Springs) -> dict:
    return {"pairs": springs.pairs, "stiffness": springs.stiffness, "damping": springs.damping,
            "rest_lengths": springs.rest_lengths, "kinds": springs.kinds, "kind_names": np.asarray(SPRING_KINDS)}


def _springs_from_arrays(arrays, path, prefix, node_count) -> Springs:
    def take(name, shape, kind):
        return take_array(arrays, prefix + name, path, shape=shape, kind=kind)

    kinds = labelled_codes(arrays, path, codes=prefix + "kinds", labels=prefix + "kind_names", known=SPRING_KINDS)
    return Springs(node_count, take("pairs", ("s", 2), "i"), take("stiffness", ("s",), "f"),
                   take("damping", ("s",), "f"), take("rest_lengths", ("s",), "f"), kinds)


def _continuum_common(element_set) -> dict:
    return {"node_count": np.asarray(element_set.node_count, dtype=np.int64),
            "tets": np.asarray(element_set.kinematics.tets, dtype=np.int64),
            "stiffness_damping": np.asarray(element_set.stiffness_damping, dtype=np.float64)}


def _corotated_arrays(tets: CorotatedTets) -> dict:
    return _continuum_common(tets) | {"shear": np.asarray(tets.shear, dtype=np.float64)}


def _nodal_strain_arrays(nodal: NodalStrain) -> dict:
    arrays = _continuum_common(nodal) | nodal.per_tet()
    if nodal.clusters is not None:
        arrays["clusters"] = np.asarray(nodal.clusters, dtype=np.int64)
    if nodal.cluster_rule is not None:
        arrays["cluster_rule"] = np.asarray(nodal.cluster_rule)
    if nodal.held is not None:
        arrays["held"] = np.asarray(nodal.held, dtype=bool)
    return arrays


def _continuum_inputs(arrays, path, prefix, rest_positions):
    def take(name, shape, kind):
        return take_array(arrays, prefix + name, path, shape=shape, kind=kind)

    node_count = int(take("node_count", (), "i"))
    if not 0 < node_count <= len(rest_positions):
        raise ValueError(f"{path} is damaged: {prefix}node_count = {node_count}, but the model has "
                         f"{len(rest_positions)} nodes")
    return (rest_positions[:node_count], take("tets", ("T", 4), "i"), float(take("stiffness_damping", (), "f")),
            lambda name: take(name, ("T",), "f"))


def _corotated_from_arrays(arrays, path, prefix, rest_positions) -> CorotatedTets:
    rest, tets, damping, per_tet = _continuum_inputs(arrays, path, prefix, rest_positions)
    return CorotatedTets(rest, tets, per_tet("shear"), stiffness_damping=damping)


def _nodal_strain_from_arrays(arrays, path, prefix, rest_positions) -> NodalStrain:
    rest, tets, damping, per_tet = _continuum_inputs(arrays, path, prefix, rest_positions)
    regions = take_array(arrays, prefix + "regions", path, shape=("T",), kind="i")
    clusters = None  # files before node clusters have none: one domain per node
    if prefix + "clusters" in arrays:
        clusters = take_array(arrays, prefix + "clusters", path, shape=(len(rest),), kind="i")
    held = take_array(arrays, prefix + "held", path, shape=(len(rest),), kind="b") if prefix + "held" in arrays else None
    # Files before the stand-in's own bulk coefficient have none: the stand-in takes the bulk, as it did then.
    stand_in = per_tet("stand_in_bulk") if prefix + "stand_in_bulk" in arrays else None
    nodal = NodalStrain(rest, tets, per_tet("shear"), per_tet("bulk"), regions=regions, clusters=clusters, held=held,
                        stiffness_damping=damping, stand_in_bulk=stand_in)
    if prefix + "cluster_rule" in arrays:  # files before supported pairs have none: the clusters stay as stored
        rule = str(take_array(arrays, prefix + "cluster_rule", path, shape=(), kind="U"))
        if rule not in CLUSTER_RULES or clusters is None:
            raise ValueError(f"{path} is damaged: {prefix}cluster_rule = {rule!r}; expected one of "
                             f"{', '.join(map(repr, CLUSTER_RULES))}, with clusters")
        nodal.cluster_rule = rule
    return nodal


def _check_rebuilt_from(model, index, element_set) -> None:
    """Refuse a continuum set whose rest state is not the model's (the file rebuilds it from the model's)."""
    rest = model.rest_positions[: element_set.node_count]
    mine = element_set.kinematics
    rebuilt = TetGradients.at_rest(rest, mine.tets)
    if not (np.array_equal(rebuilt.volumes, mine.volumes) and np.array_equal(rebuilt.gradients, mine.gradients)):
        raise ValueError(f"cannot save model.elements[{index}], a {type(element_set).__name__}: it was built on rest "
                         "positions other than the model's, and a model file rebuilds it from the model's rest "
                         "positions; build it on model.rest_positions")


def _springs_from_file(arrays, path, prefix, rest_positions) -> Springs:
    return _springs_from_arrays(arrays, path, prefix, len(rest_positions))


def _joint_arrays(joints) -> dict:
    """AngleSprings (``triples``) and DihedralSprings (``quads``): their chains, stiffness and rest angles."""
    chains = joints.triples if isinstance(joints, AngleSprings) else joints.quads
    return {"chains": np.asarray(chains, dtype=np.int64), "stiffness": joints.stiffness,
            "rest_angles": joints.rest_angles}


def _joints_from_file(kind, width):
    def read(arrays, path, prefix, rest_positions):
        chains = take_array(arrays, prefix + "chains", path, shape=("e", width), kind="i")
        stiffness = take_array(arrays, prefix + "stiffness", path, shape=(len(chains),), kind="f")
        rest = take_array(arrays, prefix + "rest_angles", path, shape=(len(chains),), kind="f")
        return kind(len(rest_positions), chains, stiffness, rest)

    return read


#: The element-set types a model file can hold: name in the file -> (type, its arrays, the set from arrays).
ELEMENT_SET_TYPES: dict[str, tuple[type[ElementSet], Callable[[Any], dict], Callable[..., ElementSet]]] = {
                     "springs": (Springs, _springs_arrays, _springs_from_file),
                     "corotated_tets": (CorotatedTets, _corotated_arrays, _corotated_from_arrays),
                     "nodal_strain": (NodalStrain, _nodal_strain_arrays, _nodal_strain_from_arrays),
                     "angle_springs": (AngleSprings, _joint_arrays, _joints_from_file(AngleSprings, 3)),
                     "dihedral_springs": (DihedralSprings, _joint_arrays, _joints_from_file(DihedralSprings, 4))}


def save_model(path: str | os.PathLike[str], model: Model) -> Path:
    """Save a model (rest shape, masses, bodies, materials, element sets, topology) to a file, atomically.

    Parameters
    ----------
    path : path-like
        The file, by convention ``NAME.vsmodel.npz``; parent folders are created.
    model : Model

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    TypeError
        For something that is not a Model, or an element set of a type a model file cannot hold
        (not in :data:`ELEMENT_SET_TYPES`), naming the set and its type; nothing is written then.
    ValueError
        For a continuum set built on rest positions other than the model's; nothing is written then.
    """
    if not isinstance(model, Model):
        raise TypeError(f"model must be a volspring.Model, got {type(model).__name__}")
    given = np.array([material is not None for material in model.materials])
    materials = np.array([[m.E, m.nu, m.density] if m is not None else [np.nan] * 3 for m in model.materials])
    arrays = {
        "rest_positions": model.rest_positions,
        "masses": model.masses,
        "node_body": model.node_body,
        "materials": materials.reshape(-1, 3),
        "material_given": given,
        "body_names": np.array(model.body_names, dtype=str),
        "rule": np.asarray(model.rule),
        "rung": np.asarray(model.rung),
        "has_topology": np.asarray(model.topology is not None),
    }
    types = []
    for index, element_set in enumerate(model.elements):
        name = next((name for name, (kind, _, _) in ELEMENT_SET_TYPES.items() if type(element_set) is kind), None)
        if name is None:
            known = ", ".join(kind.__name__ for kind, _, _ in ELEMENT_SET_TYPES.values())
            raise TypeError(f"cannot save model.elements[{index}], a {type(element_set).__name__}: a model file "
                            f"holds element sets of the types {known} only, and would silently lose this one")
        if isinstance(element_set, (CorotatedTets, NodalStrain)):  # rebuilt from the model's rest positions
            _check_rebuilt_from(model, index, element_set)
        types.append(name)
        to_arrays = ELEMENT_SET_TYPES[name][1]
        arrays.update({f"elements/{index}/{key}": value for key, value in to_arrays(element_set).items()})
    arrays["element_types"] = np.array(types, dtype=str)
    if model.topology is not None:
        arrays.update(topology_arrays(model.topology, prefix="topology/"))
    return write_archive(path, arrays, format_name=MODEL_FORMAT, version=MODEL_VERSION)


def load_model(path: str | os.PathLike[str]) -> Model:
    """Load a model saved by :func:`save_model`.

    Parameters
    ----------
    path : path-like

    Returns
    -------
    Model
        With the saved arrays bit for bit, the same element sets in the same order, and the topology.

    Raises
    ------
    FileNotFoundError
        When there is no file at ``path``.
    ValueError
        Naming the file: not a model file (truncated, damaged, another format), a format version this
        volspring does not read (naming it and the versions supported), a missing or malformed array
        (naming it), an element-set type this volspring does not know, or a model its own checks refuse.
    """
    arrays, _ = read_archive(path, format_name=MODEL_FORMAT, versions=READABLE_VERSIONS, what="model")

    def take(name, shape, kind):
        return take_array(arrays, name, path, shape=shape, kind=kind)

    rest_positions = take("rest_positions", ("n", 3), "f")
    masses = take("masses", ("n",), "f")
    node_body = take("node_body", ("n",), "i")
    rows = take("materials", ("b", 3), "f")
    given = take("material_given", ("b",), "b")
    names = take("body_names", ("b",), "U")
    if not len(rows) == len(given) == len(names):
        raise ValueError(f"{path} is damaged: 'materials', 'material_given' and 'body_names' have "
                         f"{len(rows)}, {len(given)} and {len(names)} rows; expected one per body each")
    rule = str(take("rule", (), "U"))
    rung = str(take("rung", (), "U")) if "rung" in arrays else "springs"  # files from before the ladder
    types = [str(name) for name in take("element_types", ("e",), "U")]
    try:
        materials = tuple(Material(E=E, nu=nu, density=density) if present else None
                          for (E, nu, density), present in zip(rows.tolist(), given.tolist()))
        elements = []
        for index, name in enumerate(types):
            if name not in ELEMENT_SET_TYPES:
                raise ValueError(f"{path} holds an element set of type {name!r} (elements[{index}]), which this "
                                 f"volspring cannot read (known: {', '.join(ELEMENT_SET_TYPES)})")
            from_arrays = ELEMENT_SET_TYPES[name][2]
            elements.append(from_arrays(arrays, path, f"elements/{index}/", rest_positions))
        topology = None
        if bool(take("has_topology", (), "b")):
            topology = topology_from_arrays(arrays, path, prefix="topology/")
        return Model(rest_positions, masses, tuple(elements), topology=topology, rule=rule, node_body=node_body,
                     materials=materials, body_names=tuple(str(name) for name in names), rung=rung)
    except ValueError as error:
        if str(path) in str(error):
            raise
        raise ValueError(f"{path} holds an invalid model: {error}") from error
    except TypeError as error:  # the model's checks of types: a damaged file, to the reader
        raise ValueError(f"{path} holds an invalid model: {error}") from error
