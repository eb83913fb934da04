"""volspring-mesh: summary on success, one error line and no output file on failure."""

import pytest

from meshing.cli import main
from volspring import TetMesh


@pytest.mark.parametrize("suffix", [".vtu", ".msh", ".mesh"])
def test_builtin_shape_to_file(tmp_path, capsys, suffix):
    output = tmp_path / f"beam{suffix}"
    assert main(["box:1,0.1,0.1", "-o", str(output), "--size", "0.05"]) == 0
    out = capsys.readouterr().out
    mesh = TetMesh.read(output)
    assert f"wrote {output} (gmsh)" in out if suffix == ".msh" else True
    assert f"tets: {mesh.tet_count}" in out and f"nodes: {mesh.node_count} mesh" in out
    assert f"springs: {len(mesh.edges)} ({len(mesh.edges)} tet_edge)" in out
    assert "relative difference +0.000e+00" in out  # the gmsh box is exact (see test_tetrahedralize)
    assert "min dihedral angle" in out and "radius ratio" in out


def test_bunny_with_delaunay_and_shells(shared_data, tmp_path, capsys):
    output = tmp_path / "bunny.vtu"
    code = main([str(shared_data / "coarse_bunny.obj"), "-o", str(output), "--size", "15", "--method", "delaunay",
                 "--seed", "1", "--shells", "1", "--shell-thickness", "0.5"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "coarse_bunny.obj: 502 vertices, 1000 faces" in captured.out
    assert "shell" in captured.out and "shell_diagonal" in captured.out and "shell_edge" in captured.out
    assert TetMesh.read(output).tet_count > 0


@pytest.mark.parametrize("argv, fragment", [
    (["cube:1", "--size", "0.1"], "unknown shape 'cube'"),
    (["sphere:1", "--size", "0"], "size = 0.0 is not a positive"),
    (["sphere:1", "--size", "-1"], "is not a positive"),
    (["sphere:1", "--size", "1e-5"], "too small for a body of volume 4.189"),
    (["sphere:1", "--size", "0.5", "--shells", "2"], "needs --shell-thickness"),
    (["sphere:1", "--size", "nope"], "invalid float value"),
])
def test_bad_arguments(tmp_path, capsys, argv, fragment):
    output = tmp_path / "out.vtu"
    code = main([argv[0], "-o", str(output), *argv[1:]])
    err = capsys.readouterr().err
    assert code != 0
    assert err.startswith("volspring-mesh: error: ") and fragment in err
    assert err.count("\n") == 1  # one line
    assert list(tmp_path.iterdir()) == []  # nothing left behind, not even a temporary file


@pytest.mark.parametrize("write, name, fragment", [
    (lambda path: path.write_text(""), "empty.stl", "the file is empty"),
    (lambda path: path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"), "open.obj", "open edge(s)"),
    (lambda path: path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv nan 0 1\nf 1 3 2\nf 1 2 4\nf 2 3 4\nf 1 4 3\n"),
     "nan.obj", "non-finite coordinates"),
    (lambda path: path.write_text("solid\n"), "body.step", "unknown surface file extension '.step'"),
])
def test_bad_surface_files(tmp_path, capsys, write, name, fragment):
    source = tmp_path / name
    write(source)
    output = tmp_path / "out" / "mesh.vtu"
    assert main([str(source), "-o", str(output), "--size", "0.1"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("volspring-mesh: error: ") and fragment in err and err.count("\n") == 1
    assert not output.exists() and not output.parent.exists()


def test_unknown_output_extension_is_refused_before_meshing(tmp_path, capsys):
    output = tmp_path / "mesh.foo"
    assert main(["sphere:1", "-o", str(output), "--size", "1e-5"]) == 1  # meshing would fail too: it must not run
    err = capsys.readouterr().err
    assert "cannot tell the mesh format of output" in err and "'.foo'" in err
    assert list(tmp_path.iterdir()) == []


def test_write_failure_leaves_nothing(tmp_path, capsys):
    # The output's parent is a file: the atomic write cannot even create its temporary file.
    blocker = tmp_path / "blocker"
    blocker.write_text("")
    assert main(["sphere:0.5", "-o", str(blocker / "mesh.vtu"), "--size", "0.25"]) == 1
    assert capsys.readouterr().err.startswith("volspring-mesh: error: ")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["blocker"]
