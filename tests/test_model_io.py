"""Model files: bit-identical round trips with the same forces, refused element sets, versions, damage, atomicity."""

import numpy as np
import pytest

from conftest import rewritten_archive

from meshing import add_shells, structured_box
from volspring import Material, Model, load_model, save_model
from volspring.bodies import Body
from volspring.elements import ElementSet
from volspring.model_io import MODEL_VERSION

RUBBER = Material(E=1e5, nu=0.3, density=1000.0)
STEEL = Material(E=2e11, nu=0.3, density=7800.0)


def shelled_model():
    topology = add_shells(structured_box((3, 2, 2), (0.3, 0.2, 0.2)), layers=1, thickness=0.02)
    return Model.from_mesh(topology, RUBBER, rule="lloyd", damping_ratio=0.1)


def two_body_model():
    cube = structured_box((2, 2, 2), (0.1, 0.1, 0.1))
    shelled = add_shells(structured_box((2, 1, 1), (0.2, 0.1, 0.1)), layers=1, thickness=0.01)
    return Model.from_bodies([Body(cube, RUBBER, name="cube"),
                              Body(shelled, STEEL, translation=(0.3, 0, 0), rule="van_gelder", damping=2.0,
                                   name="block")])


def arrays_model():
    return Model.from_arrays([[0, 0, 0], [1, 0, 0], [1, 1, 0]], [1.0, 2.0, 3.0], [[0, 1], [1, 2]],
                             stiffness=[100.0, 50.0], damping=0.5, rest_lengths=[0.9, 1.1])


def curly_hair_model():
    from volspring.structures import hair, strand_points

    return hair(strand_points([0, 0, 0], (0, 0, -1), 0.05, 12, curl_radius=0.004, curl_pitch=0.01),
                bending_stiffness=1e-6, axial_stiffness=10.0, linear_density=1e-3)


MODELS = {"shells": shelled_model, "two bodies": two_body_model, "arrays": arrays_model, "hair": curly_hair_model}


def _arrays(model):
    arrays = {"rest_positions": model.rest_positions, "masses": model.masses, "node_body": model.node_body,
              "springs": model.springs, "stiffness": model.stiffness, "damping": model.damping,
              "rest_lengths": model.rest_lengths, "kinds": model.kinds}
    if model.topology is not None:
        topology = model.topology
        arrays.update({"topology.points": topology.points, "topology.springs": topology.springs,
                       "topology.kinds": topology.kinds, "topology.tets": topology.mesh.tets,
                       "topology.shell_triangles": topology.shell_triangles,
                       "topology.shell_layer": topology.shell_layer})
    return arrays


@pytest.mark.parametrize("name", MODELS)
def test_round_trip_is_bit_identical_with_the_same_forces(tmp_path, name):
    model = MODELS[name]()
    loaded = load_model(save_model(tmp_path / "model.vsmodel.npz", model))
    saved, read = _arrays(model), _arrays(loaded)
    assert saved.keys() == read.keys()
    for key, array in saved.items():
        assert read[key].dtype == array.dtype and np.array_equal(read[key], array), key
    assert loaded.materials == model.materials and loaded.material == model.material
    assert loaded.body_names == model.body_names and loaded.rule == model.rule
    assert [type(e) for e in loaded.elements] == [type(e) for e in model.elements]
    assert (loaded.topology is None) == (model.topology is None)
    if model.topology is not None:
        assert loaded.topology.shell_thickness == model.topology.shell_thickness
    # A deformed, moving state: the same arrays through the same code give the same bits (exact equality).
    rng = np.random.default_rng(7)
    x = model.rest_positions + 0.01 * rng.standard_normal(model.rest_positions.shape)
    v = rng.standard_normal(x.shape)
    assert np.abs(model.forces(x, v)).max() > 0  # not vacuous
    assert np.array_equal(loaded.forces(x, v), model.forces(x, v))
    assert loaded.energy(x) == model.energy(x)


class _Anchors(ElementSet):
    """A set a model file does not know: zero-length springs from nodes to fixed points."""

    name = "anchors"

    def __init__(self, nodes):
        self.nodes = np.asarray(nodes).reshape(-1, 1)

    @property
    def stencil(self):
        return self.nodes

    def forces(self, x, v=None):
        return np.zeros_like(x)

    def energy(self, x):
        return 0.0

    def stiffness_blocks(self, x, *, clamp_compression=True):
        return np.zeros((len(self.nodes), 1, 3, 3))


def test_an_element_set_of_unknown_type_is_refused_not_dropped(tmp_path):
    model = shelled_model().with_elements(_Anchors([0, 1]))
    with pytest.raises(TypeError, match=r"cannot save model.elements\[1\], a _Anchors: a model file holds element "
                                        r"sets of the types Springs, CorotatedTets, NodalStrain, AngleSprings, DihedralSprings only"):
        save_model(tmp_path / "model.vsmodel.npz", model)
    assert list(tmp_path.iterdir()) == []


def test_a_newer_version_is_refused_naming_file_and_versions(tmp_path):
    path = save_model(tmp_path / "model.vsmodel.npz", shelled_model())
    newer = rewritten_archive(path, tmp_path / "newer.vsmodel.npz", version=np.asarray(999))
    with pytest.raises(ValueError, match=rf"newer.vsmodel.npz has model format version 999; this volspring reads "
                                         rf"version\(s\) {MODEL_VERSION} \(written by a newer volspring"):
        load_model(newer)


@pytest.mark.parametrize("make, changes, message", [
    (shelled_model, {"masses": None}, r"model.vsmodel.npz is damaged or incomplete: the array 'masses' is missing"),
    (shelled_model, {"elements/0/stiffness": np.ones(3)},
     r"model.vsmodel.npz holds an invalid model: stiffness has shape \(3,\)"),
    (shelled_model, {"topology/tets": None}, r"model.vsmodel.npz is damaged .*'topology/tets' is missing"),
    (shelled_model, {"element_types": np.asarray(["volume"])},
     r"model.vsmodel.npz holds an element set of type 'volume' \(elements\[0\]\), which this volspring cannot "
     r"read \(known: springs, corotated_tets, nodal_strain, angle_springs, dihedral_springs\)"),
    (arrays_model, {"masses": -np.ones(3)}, r"model.vsmodel.npz holds an invalid model: masses\[0\] = -1.0"),
    (arrays_model, {"format": np.asarray("volspring.spring_topology")},
     r"model.vsmodel.npz holds format 'volspring.spring_topology', not 'volspring.model'"),
])
def test_garbled_files_are_refused_naming_file_and_array(tmp_path, make, changes, message):
    path = save_model(tmp_path / "good.vsmodel.npz", make())
    bad = rewritten_archive(path, tmp_path / "model.vsmodel.npz", **changes)
    with pytest.raises(ValueError, match=message):
        load_model(bad)


def test_a_truncated_file_is_refused_naming_it(tmp_path):
    path = save_model(tmp_path / "model.vsmodel.npz", shelled_model())
    data = path.read_bytes()
    path.write_bytes(data[:-200])
    with pytest.raises(ValueError, match=r"model.vsmodel.npz is not a readable model file"):
        load_model(path)


def test_a_failed_write_leaves_no_file_and_keeps_the_old_one(tmp_path, monkeypatch):
    path = save_model(tmp_path / "model.vsmodel.npz", arrays_model())
    before = path.read_bytes()

    def broken(*args, **kwargs):
        raise KeyboardInterrupt  # the worst moment: Ctrl-C in the middle of the write

    monkeypatch.setattr(np, "savez_compressed", broken)
    with pytest.raises(KeyboardInterrupt):
        save_model(path, shelled_model())
    assert [p.name for p in tmp_path.iterdir()] == ["model.vsmodel.npz"]  # no temporary file
    assert path.read_bytes() == before
