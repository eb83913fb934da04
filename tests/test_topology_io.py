"""Spring topology files: bit-identical round trips, version and damage checks naming the file, atomic writes."""

import zipfile

import numpy as np
import pytest

from conftest import rewritten_archive

from meshing import SpringTopology, add_shells, read_topology, structured_box, write_topology
from meshing.topology_io import TOPOLOGY_SUFFIX, TOPOLOGY_VERSION


@pytest.fixture(scope="module")
def shelled():
    return add_shells(structured_box((3, 2, 2), (0.3, 0.2, 0.2)), layers=2, thickness=0.02)


def _fields(topology):
    return {"mesh.points": topology.mesh.points, "mesh.tets": topology.mesh.tets, "points": topology.points,
            "springs": topology.springs, "kinds": topology.kinds, "shell_triangles": topology.shell_triangles,
            "shell_layer": topology.shell_layer}


@pytest.mark.parametrize("layers", [0, 2])
def test_round_trip_is_bit_identical(tmp_path, layers):
    mesh = structured_box((3, 2, 2), (0.3, 0.2, 0.2))
    topology = add_shells(mesh, layers=layers, thickness=0.02) if layers else SpringTopology.from_mesh(mesh)
    loaded = read_topology(write_topology(tmp_path / f"body{TOPOLOGY_SUFFIX}", topology))
    for name, array in _fields(topology).items():
        other = _fields(loaded)[name]
        assert other.dtype == array.dtype and np.array_equal(other, array), name  # same bits, same dtype
    assert loaded.shell_thickness == topology.shell_thickness
    assert loaded.kind_counts() == topology.kind_counts() and loaded.layer_count == layers
    assert np.array_equal(loaded.rest_lengths, topology.rest_lengths)


def test_units_scale_every_length(tmp_path, shelled):
    path = write_topology(tmp_path / "body.vstopo.npz", shelled)
    in_mm = read_topology(path, units="mm")
    assert np.array_equal(in_mm.points, shelled.points * 0.001)
    assert np.array_equal(in_mm.mesh.points, shelled.mesh.points * 0.001)
    assert in_mm.shell_thickness == shelled.shell_thickness * 0.001
    assert np.array_equal(in_mm.springs, shelled.springs)


def test_a_newer_version_is_refused_naming_file_and_versions(tmp_path, shelled):
    path = write_topology(tmp_path / "body.vstopo.npz", shelled)
    newer = rewritten_archive(path, tmp_path / "newer.vstopo.npz", version=np.asarray(999))
    with pytest.raises(ValueError, match=rf"newer.vstopo.npz has spring topology format version 999; this "
                                         rf"volspring reads version\(s\) {TOPOLOGY_VERSION} \(written by a newer"):
        read_topology(newer)


def test_another_format_is_refused(tmp_path, shelled):
    path = write_topology(tmp_path / "body.vstopo.npz", shelled)
    other = rewritten_archive(path, tmp_path / "model.npz", format=np.asarray("volspring.model"))
    with pytest.raises(ValueError, match="model.npz holds format 'volspring.model', not 'volspring.spring_topology'"):
        read_topology(other)
    plain = tmp_path / "plain.npz"
    np.savez(plain, points=shelled.points)  # an npz, but not ours
    with pytest.raises(ValueError, match="plain.npz is not a volspring spring topology file: it has no 'format'"):
        read_topology(plain)


def test_a_truncated_file_is_refused_naming_it(tmp_path, shelled):
    path = write_topology(tmp_path / "body.vstopo.npz", shelled)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError, match=r"body.vstopo.npz is not a readable spring topology file: it is not a "
                                         r"complete .npz"):
        read_topology(path)


def test_a_corrupt_array_is_refused_naming_file_and_array(tmp_path, shelled):
    path = write_topology(tmp_path / "body.vstopo.npz", shelled)
    with zipfile.ZipFile(path) as archive:
        member = archive.getinfo("points.npy")
    data = bytearray(path.read_bytes())
    # The member's compressed bytes start after its 30-byte local header, name and extra field.
    name_length, extra_length = (int.from_bytes(data[member.header_offset + k:member.header_offset + k + 2], "little")
                                 for k in (26, 28))
    start = member.header_offset + 30 + name_length + extra_length
    data[start + member.compress_size // 2] ^= 0xFF
    path.write_bytes(bytes(data))
    with pytest.raises(ValueError, match=r"body.vstopo.npz is damaged: its array 'points' cannot be read"):
        read_topology(path)


@pytest.mark.parametrize("changes, message", [
    ({"tets": None}, r"the array 'tets' is missing"),
    ({"springs": np.zeros((4, 3), dtype=np.int64)}, r"array 'springs' has shape \(4, 3\) and dtype int64; "
                                                    r"expected shape \(s, 2\) of integers"),
    ({"points": np.zeros((4, 3), dtype=np.int64)}, r"array 'points' has shape \(4, 3\) and dtype int64; "
                                                   r"expected shape \(n, 3\) of floats"),
    ({"version": None}, r"its 'version' entry is missing"),
    ({"mesh_node_count": np.asarray(0)}, r"mesh_node_count = 0"),
])
def test_missing_or_garbled_arrays_are_named(tmp_path, shelled, changes, message):
    path = write_topology(tmp_path / "body.vstopo.npz", shelled)
    bad = rewritten_archive(path, tmp_path / "bad.vstopo.npz", **changes)
    with pytest.raises(ValueError, match=r"bad\.vstopo\.npz .*" + message):
        read_topology(bad)


def test_the_topology_checks_run_on_load(tmp_path, shelled):
    path = write_topology(tmp_path / "body.vstopo.npz", shelled)
    springs = shelled.springs.copy()
    springs[3, 1] = shelled.node_count + 5  # a node that does not exist
    bad = rewritten_archive(path, tmp_path / "bad.vstopo.npz", springs=springs)
    with pytest.raises(ValueError, match=r"bad.vstopo.npz holds an invalid spring topology: springs index nodes"):
        read_topology(bad)
    tets = shelled.mesh.tets[:, [1, 0, 2, 3]]  # every tet inverted: TetMesh itself refuses it
    with pytest.raises(ValueError, match=r"bad2.vstopo.npz holds an invalid spring topology: .*negatively oriented"):
        read_topology(rewritten_archive(path, tmp_path / "bad2.vstopo.npz", tets=tets))


def test_kind_codes_follow_their_labels(tmp_path, shelled):
    # A file whose labels are stored in another order still reads each spring as the kind it was written as.
    path = write_topology(tmp_path / "body.vstopo.npz", shelled)
    order = np.array([3, 2, 1, 0])  # new code of each old code
    names = np.asarray(["shell_edge", "shell_diagonal", "shell", "tet_edge"])
    moved = rewritten_archive(path, tmp_path / "moved.vstopo.npz", kinds=order[shelled.kinds].astype(np.int8),
                       kind_names=names)
    assert np.array_equal(read_topology(moved).kinds, shelled.kinds)
    unknown = rewritten_archive(path, tmp_path / "unknown.vstopo.npz",
                         kind_names=np.asarray(["tet_edge", "bending", "a", "b"]))
    with pytest.raises(ValueError, match=r"unknown.vstopo.npz uses kind_names 'bending', 'a', 'b' unknown"):
        read_topology(unknown)


def test_no_file_is_a_file_not_found_error(tmp_path):
    with pytest.raises(FileNotFoundError, match="no spring topology file at .*absent.vstopo.npz"):
        read_topology(tmp_path / "absent.vstopo.npz")


def test_a_failed_write_leaves_no_file_and_keeps_the_old_one(tmp_path, shelled, monkeypatch):
    path = write_topology(tmp_path / "body.vstopo.npz", shelled)
    before = path.read_bytes()

    def broken(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(np, "savez_compressed", broken)
    with pytest.raises(OSError, match="disk full"):
        write_topology(path, SpringTopology.from_mesh(shelled.mesh))
    with pytest.raises(OSError, match="disk full"):
        write_topology(tmp_path / "new.vstopo.npz", shelled)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["body.vstopo.npz"]  # no temporary, no new file
    assert path.read_bytes() == before
