"""ParaView (VTU/PVD) and Blender (OBJ/PC2) output: content read back, atomicity, NaN refused."""

import struct
import xml.etree.ElementTree as ET

import meshio
import numpy as np
import pytest

from volspring import Material, Model, State
from volspring.output import BlenderWriter, BoundarySurface, ParaViewWriter, read_pc2, read_pvd
from volspring.springs import spring_strains

from conftest import cube_mesh

RUBBER = Material(E=1e5, nu=0.3, density=1000.0)


@pytest.fixture
def mesh():
    return cube_mesh((2, 2, 2), size=(1.0, 0.5, 0.5))


@pytest.fixture
def model(mesh):
    return Model.from_mesh(mesh, RUBBER)


def states(model, count, *, seed=0):
    """Frames of a made-up motion: a growing shear plus noise, a frame every ten steps of 0.01 s, the time
    summed step by step as the integrators do (0.09999999999999999, not 0.1: see :func:`frame_times`)."""
    rng = np.random.default_rng(seed)
    x0 = model.rest_positions
    shear = np.array([[1.0, 0.0, 0.2], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]])
    frames, t = [], 0.0
    for k in range(count):
        frames.append(State(x0 + k * 0.05 * (x0 @ (shear - np.eye(3)).T) + 1e-3 * rng.standard_normal(x0.shape),
                            rng.standard_normal(x0.shape), t=t, step=10 * k))
        for _ in range(10):
            t += 0.01
    return frames


def frame_times(count):
    """The times the writer lists for :func:`states`: the decimals 0.0, 0.1, 0.2, ... (k / 10 is the float
    nearest each), not the summed floats."""
    return [k / 10 for k in range(count)]


def leftovers(directory):
    """Temporary files of atomic_path (dot-prefixed) left in a folder."""
    return sorted(path.name for path in directory.iterdir() if path.name.startswith("."))


# ---------------------------------------------------------------------- ParaView
def test_vtu_frames_read_back_equal_the_state(tmp_path, model, mesh):
    frames = states(model, 3)
    writer = ParaViewWriter(tmp_path, model)
    for k, state in enumerate(frames):
        writer(k, state)
    n = mesh.node_count
    for k, state in enumerate(frames):
        body = meshio.read(tmp_path / f"frame_{k:04d}.vtu")
        # VTU stores float64 in binary: the state comes back bit for bit, so exact equality.
        np.testing.assert_array_equal(body.points, state.x[:n])
        np.testing.assert_array_equal(body.cells_dict["tetra"], mesh.tets)
        np.testing.assert_array_equal(body.point_data["displacement"], state.x[:n] - mesh.points)
        np.testing.assert_array_equal(body.point_data["velocity"], state.v[:n])
        deformed = mesh.__class__.oriented(state.x[:n], mesh.tets)  # positive volumes of the sheared tets
        np.testing.assert_allclose(body.cell_data["volume_ratio"][0], deformed.tet_volumes / mesh.tet_volumes,
                                   rtol=1e-12)  # the same volumes computed twice: round-off only
        springs = meshio.read(tmp_path / f"frame_springs_{k:04d}.vtu")
        np.testing.assert_array_equal(springs.cells_dict["line"], model.springs)
        np.testing.assert_array_equal(springs.cell_data["strain"][0], spring_strains(model, state.x))
        np.testing.assert_array_equal(springs.point_data["velocity"], state.v)
    assert leftovers(tmp_path) == []


def test_pvd_lists_the_frames_with_their_real_times(tmp_path, model):
    frames = states(model, 4)
    writer = ParaViewWriter(tmp_path, model)
    for k, state in enumerate(frames):
        writer(k, state)
    for pvd in (tmp_path / "frame.pvd", tmp_path / "frame_springs.pvd"):
        root = ET.parse(pvd).getroot()  # valid XML, or this raises
        assert root.tag == "VTKFile" and root.get("type") == "Collection"
        entries = read_pvd(pvd)
        # Times are the frames' decimal times (not t += dt's floats), written with repr: exactly "0.1".
        assert [time for time, _ in entries] == frame_times(4) != [state.t for state in frames]
        assert [item.get("timestep") for item in root.iter("DataSet")] == ["0.0", "0.1", "0.2", "0.3"]
        assert all(file.is_file() and file.parent == tmp_path for _, file in entries)
        # Files are named relative to the PVD, so the folder can be moved.
        assert all("/" not in item.get("file") for item in root.iter("DataSet"))


def test_a_failing_frame_leaves_no_partial_file_and_a_valid_pvd(tmp_path, model, monkeypatch):
    frames = states(model, 3)
    writer = ParaViewWriter(tmp_path, model)
    writer(0, frames[0])
    writer(1, frames[1])
    real_write = meshio.write

    def write_half_then_fail(path, mesh, **kwargs):
        if mesh.cells[0].type == "line":  # the body file of the frame is already written
            path.write_bytes(b"<VTKFile half written")
            raise OSError("disk full")
        return real_write(path, mesh, **kwargs)

    monkeypatch.setattr(meshio, "write", write_half_then_fail)
    with pytest.raises(OSError, match="disk full"):
        writer(2, frames[2])
    monkeypatch.setattr(meshio, "write", real_write)
    assert leftovers(tmp_path) == []
    assert not (tmp_path / "frame_0002.vtu").exists() and not (tmp_path / "frame_springs_0002.vtu").exists()
    for pvd in ("frame.pvd", "frame_springs.pvd"):
        entries = read_pvd(tmp_path / pvd)
        assert [time for time, _ in entries] == frame_times(2)
        assert all(meshio.read(file).points.shape == (model.node_count, 3) for _, file in entries)
    # The writer goes on after the failure with the frame it could not write.
    writer(2, frames[2])
    assert len(read_pvd(tmp_path / "frame.pvd")) == 3


@pytest.mark.parametrize("where", ["x", "v"])
def test_nan_is_refused(tmp_path, model, where):
    frames = states(model, 2)
    writer = ParaViewWriter(tmp_path, model)
    writer(0, frames[0])
    bad = np.array(getattr(frames[1], where))
    bad[5, 1] = np.nan
    with pytest.raises(ValueError, match="node 5.*refusing to write NaN"):
        writer(1, frames[1].replace(**{where: bad}))
    assert sorted(path.name for path in tmp_path.iterdir()) == [
        "frame.pvd", "frame_0000.vtu", "frame_springs.pvd", "frame_springs_0000.vtu"]
    assert len(read_pvd(tmp_path / "frame.pvd")) == 1


def test_times_must_increase(tmp_path, model):
    frames = states(model, 2)
    writer = ParaViewWriter(tmp_path, model)
    writer(0, frames[1])
    with pytest.raises(ValueError, match="not after the previous frame"):
        writer(1, frames[0])


def test_resume_keeps_earlier_frames_and_continues_numbering(tmp_path, model):
    frames = states(model, 4)
    first = ParaViewWriter(tmp_path, model)
    for k, state in enumerate(frames[:3]):
        first(k, state)
    # A resumed run restarts from frame 2 (its checkpoint): frames 0 and 1 are kept.
    again = ParaViewWriter(tmp_path, model, first_frame=2)
    assert [time for time, _ in read_pvd(again.pvd_path)] == again.times == frame_times(2)
    for state in frames[2:]:
        again(0, state)
    entries = read_pvd(tmp_path / "frame.pvd")
    assert [time for time, _ in entries] == frame_times(4)
    assert [file.name for _, file in entries] == [f"frame_{k:04d}.vtu" for k in range(4)]
    with pytest.raises(ValueError, match="lists 4 frame"):
        ParaViewWriter(tmp_path, model, first_frame=9)


def test_model_without_mesh_writes_springs_only(tmp_path):
    string = Model.from_arrays(np.c_[np.arange(4.0), np.zeros((4, 2))], np.ones(4),
                                     [[0, 1], [1, 2], [2, 3]], stiffness=10.0)
    writer = ParaViewWriter(tmp_path, string)
    state = State(string.rest_positions * 1.5, np.zeros((4, 3)), t=0.0)
    writer(0, state)
    assert writer.pvd_path.name == "frame_springs.pvd" and not (tmp_path / "frame.pvd").exists()
    lines = meshio.read(tmp_path / "frame_springs_0000.vtu")
    np.testing.assert_allclose(lines.cell_data["strain"][0], 0.5, rtol=1e-15)  # every spring stretched by 1.5
    with pytest.raises(ValueError, match="nothing to write"):
        ParaViewWriter(tmp_path, string, springs=False)


# ---------------------------------------------------------------------- Blender
@pytest.fixture
def anchored(mesh):
    import trimesh

    from meshing import anchor

    ball = trimesh.creation.icosphere(subdivisions=2, radius=0.2)
    ball.apply_translation([0.5, 0.25, 0.25])
    return anchor(mesh, ball)


def read_obj(path):
    vertices, faces = [], []
    for line in path.read_text().splitlines():
        if line.startswith("v "):
            vertices.append([float(word) for word in line.split()[1:]])
        elif line.startswith("f "):
            faces.append([int(word) - 1 for word in line.split()[1:]])
    return np.array(vertices), np.array(faces)


def test_pc2_and_obj_hold_the_anchored_surface_per_frame(tmp_path, model, anchored):
    frames = states(model, 3)
    writer = BlenderWriter(tmp_path, anchored, start_frame=1.0, sample_rate=2.0)
    for k, state in enumerate(frames):
        writer(k, state)
    expected = np.array([anchored.deform(state.x) for state in frames])

    raw = (tmp_path / "frame.pc2").read_bytes()
    magic, version, points, start, rate, count = struct.unpack_from("<12siiffi", raw)
    assert (magic, version, points, start, rate, count) == (b"POINTCACHE2\0", 1, anchored.point_count, 1.0, 2.0, 3)
    assert len(raw) == 32 + 3 * points * 3 * 4  # header, then 3 samples of p float32 xyz, nothing else
    samples, _, _ = read_pc2(tmp_path / "frame.pc2")
    np.testing.assert_array_equal(samples, expected.astype(np.float32))  # float32 storage: exact after the cast

    objs = sorted(tmp_path.glob("frame_*.obj"))
    assert [path.name for path in objs] == ["frame_0000.obj", "frame_0001.obj", "frame_0002.obj"]
    for path, surface in zip(objs, expected):
        vertices, faces = read_obj(path)
        # %.9g keeps 9 significant digits: relative error <= 5e-9 of coordinates of order 1.
        np.testing.assert_allclose(vertices, surface, rtol=0, atol=1e-8)
        np.testing.assert_array_equal(faces, anchored.faces)
    assert leftovers(tmp_path) == []


def test_boundary_surface_is_the_default(tmp_path, model, mesh):
    frames = states(model, 2)
    writer = BlenderWriter(tmp_path, model, obj=False)
    for k, state in enumerate(frames):
        writer(k, state)
    surface = BoundarySurface.from_mesh(mesh)
    # A 2x2x2-cell box: all nodes but the single interior one are on the boundary.
    assert surface.point_count == mesh.node_count - 1
    assert len(surface.faces) == 2 * (2 * 4 + 2 * 4 + 2 * 4)  # two triangles per boundary quad
    samples, _, _ = read_pc2(writer.pc2_path)
    np.testing.assert_array_equal(samples[1], frames[1].x[surface.nodes].astype(np.float32))
    assert not list(tmp_path.glob("*.obj"))


def test_pc2_stays_valid_after_a_crash_and_resumes(tmp_path, model, anchored):
    frames = states(model, 4)
    writer = BlenderWriter(tmp_path, anchored)
    for k, state in enumerate(frames[:2]):
        writer(k, state)
    # A crash in the middle of appending frame 2: half its bytes reached the disk, the count did not.
    with open(writer.pc2_path, "ab") as file:
        file.write(b"\x01" * (6 * anchored.point_count))
    samples, _, _ = read_pc2(writer.pc2_path)
    assert len(samples) == 2
    again = BlenderWriter(tmp_path, anchored, first_frame=2)
    for state in frames[2:]:
        again(0, state)
    samples, _, _ = read_pc2(writer.pc2_path)
    expected = np.array([anchored.deform(state.x) for state in frames]).astype(np.float32)
    np.testing.assert_array_equal(samples, expected)
    assert writer.pc2_path.stat().st_size == 32 + expected.nbytes  # the crashed bytes were cut off


def test_blender_writer_refuses_nan_and_writes_nothing(tmp_path, model, anchored):
    frames = states(model, 2)
    writer = BlenderWriter(tmp_path, anchored)
    writer(0, frames[0])
    x = np.array(frames[1].x)
    x[3] = np.inf
    with pytest.raises(ValueError, match="node 3.*refusing to write NaN"):
        writer(1, frames[1].replace(x=x))
    assert len(read_pc2(writer.pc2_path)[0]) == 1
    assert sorted(path.name for path in tmp_path.iterdir()) == ["frame.pc2", "frame_0000.obj"]


def test_obj_write_failure_leaves_no_partial_file(tmp_path, model, anchored, monkeypatch):
    frames = states(model, 2)
    writer = BlenderWriter(tmp_path, anchored)
    writer(0, frames[0])
    from pathlib import Path

    def fail(self, text):
        Path.write_bytes(self, text[: len(text) // 2].encode())
        raise OSError("disk full")

    monkeypatch.setattr(Path, "write_text", fail)
    with pytest.raises(OSError, match="disk full"):
        writer(1, frames[1])
    monkeypatch.undo()
    assert leftovers(tmp_path) == [] and not (tmp_path / "frame_0001.obj").exists()
    assert len(read_pc2(writer.pc2_path)[0]) == 1


# ---------------------------------------------------------------------- recording the files written
@pytest.mark.parametrize("make", ["paraview", "blender"])
def test_writers_announce_a_frames_files_before_writing_them(tmp_path, model, anchored, make):
    announced = []

    def record(*paths):
        # Called before the frame's files exist under their final names (a crash then leaves no unlisted file).
        announced.append([(path.name, path.exists()) for path in paths])

    def writer(**options):
        if make == "paraview":
            return ParaViewWriter(tmp_path, model, record=record, **options)
        return BlenderWriter(tmp_path, anchored, record=record, **options)

    frames = states(model, 3)
    first = writer()
    for k, state in enumerate(frames[:2]):
        first(k, state)
    if make == "paraview":
        assert announced == [
            [("frame_0000.vtu", False), ("frame_springs_0000.vtu", False), ("frame.pvd", False),
             ("frame_springs.pvd", False)],
            [("frame_0001.vtu", False), ("frame_springs_0001.vtu", False), ("frame.pvd", True),
             ("frame_springs.pvd", True)]]
    else:
        assert announced == [[("frame_0000.obj", False), ("frame.pc2", False)],
                             [("frame_0001.obj", False), ("frame.pc2", True)]]
    announced.clear()
    again = writer(first_frame=1)  # resuming rewrites the collection files: announced first
    assert [name for name, _ in announced[0]] == (["frame.pvd", "frame_springs.pvd"] if make == "paraview"
                                                  else ["frame.pc2"])
    assert again.frame_paths()[0].name == ("frame_0001.vtu" if make == "paraview" else "frame_0001.obj")


def test_the_tet_series_carries_each_tets_rotation_free_strain(tmp_path, model, mesh):
    """Cell data ``strain`` is |U - I| of F = R U, the same on every rung: checked against scipy's polar
    decomposition on sheared, noisy frames."""
    from scipy.linalg import polar

    writer = ParaViewWriter(tmp_path, model)
    for k, state in enumerate(states(model, 2, seed=4)):
        writer(k, state)
        strain = meshio.read(tmp_path / f"frame_{k:04d}.vtu").cell_data["strain"][0]
        corners = state.x[mesh.tets]
        rest = mesh.points[mesh.tets]
        expected = []
        for now, before in zip(corners, rest):
            F = (now[1:] - now[0]).T @ np.linalg.inv((before[1:] - before[0]).T)
            expected.append(np.linalg.norm(polar(F)[1] - np.eye(3)))
        np.testing.assert_allclose(strain, expected, rtol=1e-9, atol=1e-12)
        assert (k == 0) or strain.max() > 0.01  # the sheared frame is strained


def test_a_run_folder_notes_what_the_run_is_beside_its_files(tmp_path):
    import json

    from volspring.output import RunFolder

    with RunFolder.open(tmp_path / "run", command=["volspring-sim", "beam.vtu"]) as run:
        run.note("model", {"rung": "smoothed", "alpha": 0.6})
        run.note("model", {"rung": "smoothed", "alpha": 0.5})  # a later note replaces the earlier
        for key, value, message in [("files", [], "part of the run manifest's layout"),
                                    ("model", {1, 2}, "note 'model': Object of type set")]:
            with pytest.raises(ValueError, match=message):
                run.note(key, value)
    manifest = json.loads((tmp_path / "run" / "volspring-run.json").read_text())
    assert manifest["model"] == {"rung": "smoothed", "alpha": 0.5} and manifest["status"] == "finished"
    with pytest.raises(RuntimeError, match="is finished: it cannot note 'model'"):
        run.note("model", {})


def test_a_surface_of_the_models_own_nodes_is_one_more_series(tmp_path):
    """A cloth (a model built from arrays) writes its triangles as NAME_surface.pvd, read back frame by frame,
    resumes like the other series, and the same triangles go to Blender through BoundarySurface.from_triangles."""
    from volspring.structures import cloth_grid, sheet_grid

    _, triangles = sheet_grid(1.0, 1.0, 3, 2)
    cloth = cloth_grid(1.0, 1.0, 3, 2, areal_density=0.2, membrane_stiffness=100.0)
    states = [State(cloth.rest_positions + 0.01 * k, np.full((cloth.node_count, 3), float(k)), 0.1 * k)
              for k in range(3)]
    writer = ParaViewWriter(tmp_path, cloth, name="cloth", triangles=triangles)
    for state in states[:2]:
        writer.write(state)
    resumed = ParaViewWriter(tmp_path, cloth, name="cloth", triangles=triangles, first_frame=2)
    resumed.write(states[2])
    frames = read_pvd(tmp_path / "cloth_surface.pvd")
    assert [time for time, _ in frames] == [0.0, 0.1, 0.2]
    for (_, file), state in zip(frames, states):
        data = meshio.read(file)
        assert np.array_equal(data.cells_dict["triangle"], triangles)
        assert np.array_equal(data.points, state.x) and np.array_equal(data.point_data["velocity"], state.v)
    with pytest.raises(ValueError, match="the model has 12 nodes"):
        ParaViewWriter(tmp_path, cloth, name="bad", triangles=triangles + 1)
    blender = BlenderWriter(tmp_path / "blender", BoundarySurface.from_triangles(triangles, cloth.node_count), name="c")
    blender(0, states[1])
    samples, _, _ = read_pc2(tmp_path / "blender" / "c.pc2")
    assert np.allclose(samples[0], states[1].x, rtol=0, atol=1e-6)  # PC2 stores float32
