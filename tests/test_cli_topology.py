"""Shells from the command line to the simulation: volspring-mesh writes the topology file, volspring-sim reads it."""

import meshio
import numpy as np
import pytest

from meshing import TetMesh, read_topology
from meshing.cli import main as _mesh_main
from volspring.cli import _build
from volspring.cli import main as sim_main
from volspring.cli._arguments import build_parser, joined_vectors

BOX = ["box:0.2,0.05,0.05", "--size", "0.05"]
SHELLS = ["--shells", "1", "--shell-thickness", "0.01"]
# The box spans x in [-0.1, 0.1]; its end face and the shell nodes just outside it are pinned.
PIN_END = ["--pin", "x<-0.095"]


def mesh_main(argv):
    return _mesh_main([str(arg) for arg in argv])


def test_mesh_with_shells_then_sim_simulates_the_shells(tmp_path, capsys):
    mesh_file = tmp_path / "beam.vtu"
    assert mesh_main([*BOX, *SHELLS, "-o", mesh_file]) == 0
    out = capsys.readouterr().out
    topology_file = tmp_path / "beam.vstopo.npz"  # the sidecar of a mesh format written with --shells
    assert f"and {topology_file} (spring topology: the tet mesh and 1 shell layer(s)" in out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["beam.vstopo.npz", "beam.vtu"]
    topology, mesh = read_topology(topology_file), TetMesh.read(mesh_file)
    assert np.array_equal(topology.mesh.tets, mesh.tets) and topology.layer_count == 1
    assert f"nodes: {mesh.node_count} mesh + {topology.shell_node_count} shell in 1 layer(s)" in out

    argv = [str(topology_file), *PIN_END, "--dt", "0.005", "--frame-dt", "0.01", "--duration", "0.01",
            "--out", str(tmp_path / "run"), "--no-progress"]
    assert sim_main(argv) == 0
    out = capsys.readouterr().out
    shell_springs = topology.spring_count - topology.kind_counts()["tet_edge"]
    assert (f"{mesh.node_count} nodes + {topology.shell_node_count} shell nodes in 1 layer(s), {mesh.tet_count} tets, "
            f"{topology.spring_count} springs ({shell_springs} shell springs)") in out
    # The run's spring frames hold every spring of the topology, shells included.
    springs = meshio.read(tmp_path / "run" / "frame_springs_0000.vtu")
    assert len(springs.points) == topology.node_count and len(springs.cells[0].data) == topology.spring_count

    # The model the command builds is Model.from_mesh of the topology, shells and all.
    args = build_parser().parse_args(joined_vectors(argv))
    body, origin = _build.load_mesh(args)
    model = _build.build_model(args, body)
    assert origin == str(topology_file)
    assert model.kind_counts() == topology.kind_counts() and model.kind_counts()["shell"] > 0
    assert model.node_count == topology.node_count and np.array_equal(model.springs, topology.springs)
    assert model.topology.shell_node_count == topology.shell_node_count


def test_the_same_mesh_file_without_the_topology_runs_as_before(tmp_path, capsys):
    mesh_file = tmp_path / "beam.vtu"
    assert mesh_main([*BOX, *SHELLS, "-o", mesh_file]) == 0
    capsys.readouterr()
    assert sim_main([mesh_file, *PIN_END, "--duration", "0.01", "--dt", "0.005"]) == 0
    mesh = TetMesh.read(mesh_file)
    assert f"body: {mesh_file}: {mesh.node_count} nodes, {mesh.tet_count} tets, {len(mesh.edges)} springs" in (
        capsys.readouterr().out)


@pytest.mark.parametrize("shells", [[], SHELLS])
def test_a_topology_output_is_the_only_file_written(tmp_path, capsys, shells):
    output = tmp_path / "beam.vstopo.npz"
    assert mesh_main([*BOX, *shells, "-o", output]) == 0
    out = capsys.readouterr().out
    assert f"wrote {output} (spring topology: the tet mesh and {'1 shell layer(s)' if shells else 'no shells'}" in out
    assert [p.name for p in tmp_path.iterdir()] == ["beam.vstopo.npz"]
    assert read_topology(output).layer_count == (1 if shells else 0)


def test_without_shells_a_mesh_output_gets_no_topology_file(tmp_path, capsys):
    assert mesh_main([*BOX, "-o", tmp_path / "beam.msh"]) == 0
    assert [p.name for p in tmp_path.iterdir()] == ["beam.msh"]


def test_a_failed_mesh_write_removes_the_topology_file_too(tmp_path, capsys, monkeypatch):
    def broken(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(TetMesh, "write", broken)
    assert mesh_main([*BOX, *SHELLS, "-o", tmp_path / "beam.vtu"]) == 1  # the run failed while writing
    assert "volspring-mesh: error: disk full" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_a_sidecar_that_is_a_folder_is_refused_before_meshing(tmp_path, capsys):
    (tmp_path / "beam.vstopo.npz").mkdir()
    assert mesh_main([*BOX, *SHELLS, "-o", tmp_path / "beam.vtu"]) == 2  # bad input: the output
    assert "beam.vstopo.npz: it is a directory" in capsys.readouterr().err
    assert [p.name for p in tmp_path.iterdir()] == ["beam.vstopo.npz"]


@pytest.mark.parametrize("extra, damage, message", [
    ([], lambda path: path.write_bytes(path.read_bytes()[:100]), "is not a readable spring topology file"),
    (["--size", "0.05"], lambda path: None, "--size applies to built-in shapes only"),
])
def test_sim_refuses_a_bad_topology_input_in_one_line(tmp_path, capsys, extra, damage, message):
    path = tmp_path / "beam.vstopo.npz"
    assert mesh_main([*BOX, *SHELLS, "-o", path]) == 0
    capsys.readouterr()
    damage(path)
    assert sim_main([path, *PIN_END, "--duration", "0.01", *extra]) == 2  # bad input
    err = capsys.readouterr().err
    assert err.startswith("volspring-sim: error: ") and message in err and err.count("\n") == 1
    assert str(path) in err or "--size" in message
