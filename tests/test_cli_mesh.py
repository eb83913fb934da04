"""volspring-mesh: summary on success, one error line and no output file on failure."""

import numpy as np
import pytest

from meshing.cli import main
from meshing import TetMesh


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
    code = main([str(shared_data / "coarse_bunny.obj"), "-o", str(output), "--size", "15", "--mesher", "delaunay",
                 "--seed", "1", "--shells", "1", "--shell-thickness", "0.5", "--units", "mm"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "coarse_bunny.obj: 502 vertices, 1000 faces (x0.001 to m)" in captured.out
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
    assert code == 2  # a bad command line or bad input, found before the work
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
    assert main([str(source), "-o", str(output), "--size", "0.1"]) == 2  # bad input
    err = capsys.readouterr().err
    assert err.startswith("volspring-mesh: error: ") and fragment in err and err.count("\n") == 1
    assert not output.exists() and not output.parent.exists()


def test_unknown_output_extension_is_refused_before_meshing(tmp_path, capsys):
    output = tmp_path / "mesh.foo"
    assert main(["sphere:1", "-o", str(output), "--size", "1e-5"]) == 2  # meshing would fail too: it must not run
    err = capsys.readouterr().err
    assert "cannot tell the mesh format of output" in err and "'.foo'" in err
    assert list(tmp_path.iterdir()) == []


def test_write_failure_leaves_nothing(tmp_path, capsys):
    # The output's parent is a file: the atomic write cannot even create its temporary file.
    blocker = tmp_path / "blocker"
    blocker.write_text("")
    assert main(["sphere:0.5", "-o", str(blocker / "mesh.vtu"), "--size", "0.25"]) == 2  # found before meshing
    assert capsys.readouterr().err.startswith("volspring-mesh: error: ")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["blocker"]


# ---------------------------------------------------------------------- the output is checked before any meshing
@pytest.fixture
def no_meshing(monkeypatch):
    """Make meshing fail loudly: a test using this proves the command stopped before it."""
    import importlib

    # importlib: the package's `tetrahedralize` attribute is the function, which hides the module of that name.
    module = importlib.import_module("meshing.tetrahedralize")

    def must_not_run(*args, **kwargs):
        raise AssertionError("tetrahedralize ran although the output was already known to be unwritable")

    monkeypatch.setattr(module, "tetrahedralize", must_not_run)


def test_output_that_is_a_directory_fails_fast(tmp_path, capsys, no_meshing):
    output = tmp_path / "existing_dir.vtu"
    output.mkdir()
    assert main(["sphere:0.5", "-o", str(output), "--size", "0.25"]) == 2
    err = capsys.readouterr().err
    assert err == f"volspring-mesh: error: output {output} is a directory; expected a mesh file to write\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["existing_dir.vtu"] and not any(output.iterdir())


def test_output_under_a_file_fails_fast(tmp_path, capsys, no_meshing):
    blocker = tmp_path / "blocker"
    blocker.write_text("")
    output = blocker / "sub" / "mesh.vtu"
    assert main(["sphere:0.5", "-o", str(output), "--size", "0.25"]) == 2
    err = capsys.readouterr().err
    assert err == (f"volspring-mesh: error: cannot write output {output}: {blocker} is a file, "
                   f"not a directory\n")


def test_unknown_output_extension_fails_fast(tmp_path, capsys, no_meshing):
    assert main(["sphere:0.5", "-o", str(tmp_path / "mesh.foo"), "--size", "0.25"]) == 2
    assert "cannot tell the mesh format of output" in capsys.readouterr().err


def test_unwritable_output_folder_fails_fast(tmp_path, capsys, no_meshing, monkeypatch):
    import os

    # Tests often run as root, which may write anywhere: stand in for a read-only folder.
    real_access = os.access
    monkeypatch.setattr(os, "access", lambda path, mode: False if str(path) == str(tmp_path) else
                        real_access(path, mode))
    output = tmp_path / "mesh.vtu"
    assert main(["sphere:0.5", "-o", str(output), "--size", "0.25"]) == 2
    assert capsys.readouterr().err == (f"volspring-mesh: error: cannot write output {output}: "
                                       f"no permission to create files in {tmp_path}\n")


# ---------------------------------------------------------------------- a face wound the wrong way
def _box_with_one_face_reversed(path):
    import trimesh

    box = trimesh.creation.box(extents=(1.0, 1.0, 1.0))
    faces = box.faces.copy()
    faces[0] = faces[0, ::-1]
    trimesh.Trimesh(box.vertices, faces, process=False).export(path)


def test_wrong_winding_is_repaired(tmp_path, capsys, caplog):
    import logging

    source = tmp_path / "box.stl"
    _box_with_one_face_reversed(source)
    output = tmp_path / "box.vtu"
    with caplog.at_level(logging.INFO, logger="meshing.surface"):
        code = main([str(source), "-o", str(output), "--size", "0.5"])
    captured = capsys.readouterr()
    assert code == 0, captured.err
    assert "made the face winding consistent" in caplog.text
    assert "Traceback" not in captured.err
    assert TetMesh.read(output).volume == pytest.approx(1.0, rel=1e-6)  # STL stores float32: ~1e-7 relative


def test_missing_networkx_is_named(tmp_path, capsys, monkeypatch):
    import trimesh.repair
    from trimesh.exceptions import ExceptionWrapper

    # How trimesh holds a soft dependency that failed to import: the error comes when it is used.
    monkeypatch.setattr(trimesh.repair, "nx", ExceptionWrapper(ModuleNotFoundError("No module named 'networkx'")))
    source = tmp_path / "box.stl"
    _box_with_one_face_reversed(source)
    assert main([str(source), "-o", str(tmp_path / "box.vtu"), "--size", "0.5"]) == 1  # the machine, not the input
    err = capsys.readouterr().err
    assert err.startswith("volspring-mesh: error: ") and err.count("\n") == 1
    assert "making the face winding consistent needs the package networkx (pip install networkx)" in err


# ---------------------------------------------------------------------- units
def test_units_scale_the_input_and_the_lengths(shared_data, tmp_path, capsys):
    output = tmp_path / "bunny.vtu"
    code = main([str(shared_data / "coarse_bunny.obj"), "-o", str(output), "--size", "15", "--units", "mm",
                 "--method", "delaunay", "--seed", "1"])
    captured = capsys.readouterr()
    assert code == 0 and captured.err == ""
    mesh = TetMesh.read(output)
    # The README's 160 units across, in mm: about 0.16 m wide.
    assert 0.15 < np.ptp(mesh.points, axis=0).max() < 0.17
    assert "size 0.015 m" in captured.out


def test_units_apply_to_a_builtin_shape(tmp_path, capsys):
    output = tmp_path / "beam.vtu"
    assert main(["box:1000,100,100", "-o", str(output), "--size", "50", "--units", "mm"]) == 0
    capsys.readouterr()
    mesh = TetMesh.read(output)
    assert mesh.volume == pytest.approx(0.01, rel=1e-12)  # the gmsh box is exact: round-off only
    assert main(["box:1,0.1,0.1", "-o", str(output), "--size", "0.05", "--scale", "2"]) == 0
    assert TetMesh.read(output).volume == pytest.approx(0.08, rel=1e-12)  # scale 2 on every side: 8 x 0.01


def test_large_input_in_metres_warns_on_one_line(shared_data, tmp_path, capsys):
    code = main([str(shared_data / "coarse_bunny.obj"), "-o", str(tmp_path / "bunny.vtu"), "--size", "15",
                 "--method", "delaunay", "--seed", "1"])
    err = capsys.readouterr().err
    assert code == 0
    assert err.startswith("volspring-mesh: warning: ") and err.count("\n") == 1
    assert "262 m across" in err and "--units mm" in err


@pytest.mark.parametrize("argv, fragment", [
    (["--units", "inch"], "argument --units: invalid choice: 'inch'"),
    (["--scale", "0"], "scale = 0.0 is not a finite number > 0"),
    (["--scale", "nan"], "scale = nan is not a finite number > 0"),
])
def test_bad_units(tmp_path, capsys, argv, fragment, no_meshing):
    assert main(["sphere:1", "-o", str(tmp_path / "out.vtu"), "--size", "0.5", *argv]) == 2
    err = capsys.readouterr().err
    assert err.startswith("volspring-mesh: error: ") and fragment in err and err.count("\n") == 1
