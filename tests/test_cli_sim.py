"""``volspring-sim`` called through ``main([...])``: files produced, resume, and one-line errors."""

import re

import meshio
import numpy as np
import pytest

from volspring.checkpoint import load_checkpoint
from volspring.cli import main
from volspring.output import read_pc2, read_pvd

from conftest import cube_mesh, signal_when_ready

# A 0.2 m x 0.05 m x 0.05 m box of 4 x 1 x 1 Kuhn cells, clamped at x = 0: tiny and mesher-free.
PIN_END = ["--pin", "-1,-1,-1,0,1,1"]
FAST = ["--dt", "0.005", "--frame-dt", "0.01"]


@pytest.fixture(scope="module")
def beam_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("mesh") / "beam.vtu"
    cube_mesh((4, 1, 1), size=(0.2, 0.05, 0.05)).write(path)
    return path


def run(capsys, *argv):
    status = main([str(arg) for arg in argv])
    out, err = capsys.readouterr()
    return status, out, err


def test_a_run_writes_frames_surface_and_checkpoint(tmp_path, capsys, beam_file):
    status, out, err = run(capsys, beam_file, *PIN_END, *FAST, "--duration", "0.05", "--out", tmp_path,
                           "--blender", "--checkpoint-every", "2", "--no-progress")
    assert status == 0, err
    assert err == ""
    entries = read_pvd(tmp_path / "frame.pvd")
    # Frames at 0, 0.01, ..., 0.05: six of them; times agree with frame_dt up to the round-off of t += dt.
    np.testing.assert_allclose([time for time, _ in entries], np.arange(6) * 0.01, rtol=0, atol=1e-12)
    last = meshio.read(entries[-1][1])
    assert np.isfinite(last.points).all()
    pinned = np.isclose(last.points[:, 0] - last.point_data["displacement"][:, 0], 0.0)
    assert np.abs(last.point_data["displacement"][pinned]).max() == 0.0  # pinned nodes never move
    assert last.point_data["displacement"][:, 2].min() < -1e-6  # the free end sags under gravity
    assert len(read_pvd(tmp_path / "frame_springs.pvd")) == 6
    assert len(read_pc2(tmp_path / "surface.pc2")[0]) == 6 and len(list(tmp_path.glob("surface_*.obj"))) == 6
    final = load_checkpoint(tmp_path / "checkpoint.npz")
    assert final.step == 10 and final.x.tobytes() == last.points.tobytes()  # the end state, bit for bit
    assert "10 steps" in out and "6 frame(s)" in out and "springs" in out


def test_progress_in_a_log_is_plain_lines_on_stderr(tmp_path, capsys, beam_file):
    # capsys's stderr is not a terminal: --progress gives lines (the first at once), never a carriage return.
    status, out, err = run(capsys, beam_file, *PIN_END, *FAST, "--duration", "0.02", "--progress", "--quiet")
    assert (status, out, err) == (0, "", "")  # --quiet wins
    status, out, err = run(capsys, beam_file, *PIN_END, *FAST, "--duration", "0.02", "--progress")
    assert status == 0 and "\r" not in err and "\r" not in out and "sim:" not in out
    lines = err.splitlines()
    assert lines[0].startswith("sim:   0% 0/4 steps") and lines[-1].startswith("sim: 100% 4/4 steps")
    assert "steps/s, t = 0.02 s, frame 2" in lines[-1] and len(lines) <= 3


def test_progress_on_a_terminal_is_a_bar_with_rate_and_time_left(tmp_path, capsys, beam_file, monkeypatch):
    import io
    import sys

    class Terminal(io.StringIO):
        def isatty(self):
            return True

    terminal = Terminal()
    monkeypatch.setattr(sys, "stderr", terminal)
    status = main([str(beam_file), *PIN_END, *FAST, "--duration", "0.02"])  # the default on a terminal: a bar
    assert status == 0 and "\r" not in capsys.readouterr().out
    drawn = terminal.getvalue()
    assert drawn.startswith("\rsim:") and drawn.endswith("\n")
    last = drawn.rstrip("\n").split("\r")[-1]
    assert "100%|" in last and "4/4 steps [" in last and "<00:00" in last and "steps/s" in last


def test_quiet_prints_nothing(tmp_path, capsys, beam_file):
    assert run(capsys, beam_file, *PIN_END, *FAST, "--duration", "0.01", "--quiet") == (0, "", "")


def test_resumed_cli_run_equals_an_uninterrupted_one(tmp_path, capsys, beam_file):
    whole, parts = tmp_path / "whole", tmp_path / "parts"
    common = [beam_file, *PIN_END, *FAST, "--integrator", "verlet", "--E", "1e4", "--quiet"]  # h omega_max < 1
    assert run(capsys, *common, "--duration", "0.06", "--out", whole)[0] == 0
    assert run(capsys, *common, "--duration", "0.03", "--out", parts, "--checkpoint-every", "1", "--blender")[0] == 0
    status, _, err = run(capsys, *common, "--duration", "0.06", "--out", parts, "--blender",
                         "--resume", parts / "checkpoint.npz")
    assert status == 0, err
    a, b = read_pvd(whole / "frame.pvd"), read_pvd(parts / "frame.pvd")
    assert [time for time, _ in a] == [time for time, _ in b] and len(a) == 7
    assert [file.name for _, file in b] == [f"frame_{k:04d}.vtu" for k in range(7)]
    for (_, file_a), (_, file_b) in zip(a, b):
        # Bit-identical: the resumed run takes exactly the steps of the uninterrupted one.
        mesh_a, mesh_b = meshio.read(file_a), meshio.read(file_b)
        assert mesh_a.points.tobytes() == mesh_b.points.tobytes()
        assert mesh_a.point_data["velocity"].tobytes() == mesh_b.point_data["velocity"].tobytes()
    assert len(read_pc2(parts / "surface.pc2")[0]) == 7


def test_divergence_is_one_line_and_leaves_complete_frames(tmp_path, capsys, beam_file):
    # Symplectic Euler at 26x its stability limit (h omega_max ~ 52 for this stiff beam) blows up
    # within a few steps; the guard is off so that the run is attempted.
    status, out, err = run(capsys, beam_file, *PIN_END, "--E", "1e9", "--integrator", "symplectic_euler",
                           "--dt", "1e-3", "--frame-dt", "1e-3", "--duration", "1", "--guard", "off",
                           "--out", tmp_path, "--no-progress")
    assert status == 3
    # One error line, last; before it at most the one-line warning that tets turned inside out.
    lines = err.splitlines()
    assert lines[-1].startswith("volspring-sim: error: simulation diverged at step ")
    assert all(line.startswith("volspring-sim: warning: ") and "tets are inverted" in line for line in lines[:-1])
    assert len(lines) <= 2 and "worst node" in lines[-1] and "complete frame(s)" in lines[-1]
    entries = read_pvd(tmp_path / "frame.pvd")
    assert entries and all(np.isfinite(meshio.read(file).points).all() for _, file in entries)
    assert sorted(p.name for p in tmp_path.glob("frame_0*.vtu")) == [file.name for _, file in entries]
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_guard_raise_stops_before_the_first_step(tmp_path, capsys, beam_file):
    status, _, err = run(capsys, beam_file, *PIN_END, "--E", "1e9", "--integrator", "symplectic_euler",
                         "--dt", "1e-3", "--duration", "0.01", "--guard", "raise", "--out", tmp_path)
    assert status == 2 and len(err.splitlines()) == 1 and err.startswith("volspring-sim: error: ")
    assert not (tmp_path / "frame.pvd").exists()


@pytest.mark.parametrize("argv, status, message", [
    (["missing.msh"], 2, "INPUT 'missing.msh' is neither a mesh file nor a built-in shape"),
    (["blob:1,2"], 2, "unknown shape 'blob'"),
    (["box:1,1,0"], 2, "lz = 0.0 is not a positive finite length"),
    (["{mesh}", "--pin", "5,5,5,6,6,6"], 2, r"--pin 5,5,5,6,6,6 selects no node; the mesh spans \[0, 0.2\] x"),
    (["{mesh}", "--pin", "1,1,1"], 2, "--pin '1,1,1' is not 6 finite numbers"),
    (["{mesh}", "--pin", "0,0,0,-1,1,1"], 2, "xmin > xmax"),
    (["{mesh}", "--nu", "0.5"], 2, "nu = 0.5 is not in"),
    (["{mesh}", "--E", "-1"], 2, "E = -1.0 Pa is not > 0"),
    (["{mesh}", "--dt", "0"], 2, "--dt = 0 s is not a finite number > 0"),
    (["{mesh}", "--duration", "nan"], 2, "--duration = nan s"),
    (["{mesh}", "--gravity", "0,0"], 2, "--gravity '0,0' is not 3 finite numbers"),
    (["{mesh}", "--checkpoint-every", "2"], 2, "--checkpoint-every needs --out"),
    (["{mesh}", "--rule", "uniform"], 2, "--rule uniform needs --stiffness"),
    (["{mesh}", "--size", "0.1"], 2, "--size applies to built-in shapes only"),
    (["{mesh}", "--resume", "nowhere.npz"], 2, "no checkpoint file at nowhere.npz"),
    (["{mesh}", "--integrator", "leapfrog"], 2, "argument --integrator: invalid choice: 'leapfrog'"),
    (["{mesh}", "--dt", "fast"], 2, "argument --dt: invalid float value: 'fast'"),
    ([], 2, "the following arguments are required: INPUT"),
])
def test_bad_input_gives_one_error_line(capsys, beam_file, argv, status, message):
    argv = [str(beam_file) if arg == "{mesh}" else arg for arg in argv]
    got, out, err = run(capsys, *argv, "--duration", "0.01") if "--duration" not in argv else run(capsys, *argv)
    assert got == status
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("volspring-sim: error: ")
    assert re.search(message, lines[0]), lines[0]
    assert out == ""


def test_resume_refuses_a_checkpoint_of_another_mesh(tmp_path, capsys, beam_file):
    assert run(capsys, beam_file, *PIN_END, *FAST, "--duration", "0.01", "--out", tmp_path,
               "--checkpoint-every", "1", "--quiet")[0] == 0
    other = tmp_path / "other.vtu"
    cube_mesh((2, 1, 1), size=(0.2, 0.05, 0.05)).write(other)
    status, _, err = run(capsys, other, *PIN_END, *FAST, "--duration", "0.02", "--resume", tmp_path / "checkpoint.npz")
    assert status == 2 and "holds 20 nodes, the model has 12" in err and len(err.splitlines()) == 1
    status, _, err = run(capsys, beam_file, *PIN_END, *FAST, "--duration", "0.01",
                         "--resume", tmp_path / "checkpoint.npz")
    assert status == 2 and "already at --duration" in err


def test_help_exits_zero(capsys):
    assert main(["--help"]) == 0
    out = capsys.readouterr().out
    assert "--pin" in out and "--model {springs,springs+volume,smoothed}" in out and "--region-material" in out


def test_shape_input_is_meshed(tmp_path, capsys):
    status, out, err = run(capsys, "box:0.2,0.05,0.05", "--size", "0.05", "--mesher", "delaunay", "--seed", "1",
                           "--pin", "-0.1,-1,-1,-0.1,1,1", *FAST, "--duration", "0.01", "--out", tmp_path,
                           "--no-progress")
    assert status == 0, err
    assert "box:0.2,0.05,0.05 meshed by delaunay" in out
    assert len(read_pvd(tmp_path / "frame.pvd")) == 2


def test_unreadable_mesh_files_give_one_error_line(tmp_path, capsys):
    (tmp_path / "garbage.vtu").write_text("not xml at all")
    # meshio prints and calls sys.exit on such a file; the CLI must still say one line and return.
    status, out, err = run(capsys, tmp_path / "garbage.vtu")
    assert status == 2 and out == "" and len(err.splitlines()) == 1
    assert err.startswith(f"volspring-sim: error: cannot read {tmp_path / 'garbage.vtu'}")
    surface = tmp_path / "triangle.obj"
    surface.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    status, out, err = run(capsys, surface)
    assert status == 2 and len(err.splitlines()) == 1 and "no tetra cells (found triangle)" in err


def test_render_surface_is_anchored_in_file_order(tmp_path, capsys, beam_file):
    # A coarse "render" surface inside the beam, in a deliberate vertex order.
    vertices = np.array([[0.15, 0.01, 0.01], [0.05, 0.01, 0.01], [0.1, 0.04, 0.01], [0.1, 0.02, 0.04]])
    surface = tmp_path / "render.obj"
    surface.write_text("".join(f"v {x} {y} {z}\n" for x, y, z in vertices) + "f 1 2 3\nf 1 3 4\nf 1 4 2\nf 2 4 3\n")
    out_dir = tmp_path / "out"
    status, _, err = run(capsys, beam_file, *PIN_END, *FAST, "--duration", "0.01", "--out", out_dir,
                         "--blender", "--render-surface", surface, "--quiet")
    assert status == 0, err
    samples, _, _ = read_pc2(out_dir / "surface.pc2")
    assert samples.shape == (2, 4, 3)
    np.testing.assert_array_equal(samples[0], vertices.astype(np.float32))  # frame 0 is the rest shape
    status, _, err = run(capsys, beam_file, "--render-surface", surface, "--out", out_dir)
    assert status == 2 and "--render-surface needs --blender" in err


def test_nu_given_to_a_pure_spring_rule_says_it_is_ignored(tmp_path, capsys, beam_file):
    status, _, err = run(capsys, beam_file, *PIN_END, *FAST, "--duration", "0.01", "--nu", "0.3", "--quiet")
    assert status == 0
    assert err == ("volspring-sim: warning: --nu 0.3 is ignored by --model springs (--rule van_gelder): pure springs "
                   "have one effective Poisson ratio whatever nu is asked (the Cauchy limit; volspring-validate cauchy "
                   "measures it); --model smoothed honours nu (springs+volume too, for nu from about 0.25)\n")
    # Nobody asked for a nu: no warning; and the rungs that honour nu say nothing either.
    assert run(capsys, beam_file, *PIN_END, *FAST, "--duration", "0.01", "--quiet") == (0, "", "")
    for rung in ("springs+volume", "smoothed"):
        assert run(capsys, beam_file, *PIN_END, *FAST, "--duration", "0.01", "--nu", "0.3", "--model", rung,
                   "--quiet") == (0, "", "")


def test_the_summary_reports_inverted_tets(tmp_path, capsys, beam_file):
    status, out, _ = run(capsys, beam_file, *PIN_END, *FAST, "--duration", "0.01", "--no-progress")
    assert status == 0 and "tets: 0 of 24 inverted at the end, at most 0 at a frame; worst volume ratio" in out


def test_resume_with_another_run_is_refused_naming_what_differs(tmp_path, capsys, beam_file):
    common = [beam_file, *PIN_END, *FAST, "--quiet", "--out", tmp_path]
    assert run(capsys, *common, "--duration", "0.01", "--checkpoint-every", "1")[0] == 0
    checkpoint = tmp_path / "checkpoint.npz"
    for extra, message in [
        (["--E", "2e6"], "was written for another model: its stiffness, damping differ"),
        (["--density", "900"], "its damping, masses differ"),
        (["--pin", "-1,-1,-1,0.06,1,1"], "its pinned nodes differ"),
        (["--dt", "0.0025"], r"written with dt = 0.005 s; this run asks for dt = 0.0025 s"),
        (["--integrator", "verlet"], "written with integrator implicit_euler; this run uses verlet"),
        (["--newton-iterations", "2"], r"newton_iterations = 0 \(now 2\)"),
    ]:
        argv = [*common[:1], *(common[1:3] if "--pin" not in extra else []), *common[3:], "--duration", "0.02",
                "--resume", checkpoint, *extra]
        status, _, err = run(capsys, *argv)
        assert status == 2 and len(err.splitlines()) == 1, err
        assert re.search(message, err), err


@pytest.mark.parametrize("argv, message", [
    (["--newton-iterations", "-1"], "--newton-iterations = -1 is not >= 0"),
    (["--newton-iterations", "2", "--integrator", "verlet"], "--newton-iterations applies to --integrator implicit_euler"),
    (["--runaway-factor", "0"], r"--runaway-factor = 0 is not > 0"),
])
def test_solver_knobs_refuse_nonsense(capsys, beam_file, argv, message):
    status, _, err = run(capsys, beam_file, *PIN_END, *FAST, "--duration", "0.01", *argv)
    assert status == 2 and re.search(message, err), err


def test_out_that_is_a_file_is_refused_before_any_work(tmp_path, capsys, beam_file, monkeypatch):
    import volspring.cli._build

    target = tmp_path / "taken.txt"
    target.write_text("not a folder")
    monkeypatch.setattr(volspring.cli._build, "load_mesh", lambda args: pytest.fail("meshed before checking --out"))
    status, _, err = run(capsys, beam_file, "--out", target)
    assert status == 2 and f"--out {target} is an existing file, expected a folder" in err
    status, _, err = run(capsys, beam_file, "--out", target / "below")
    assert status == 2 and f"{target} is a file, not a folder" in err


@pytest.mark.parametrize("signal_name, status", [("SIGTERM", 143), ("SIGINT", 130)])
def test_an_interrupted_run_says_where_it_stopped_in_one_line(tmp_path, signal_name, status):
    import signal

    mesh = tmp_path / "beam.vtu"
    cube_mesh((20, 5, 5), size=(1.0, 0.2, 0.2)).write(mesh)
    out = tmp_path / "out"
    argv = [str(mesh), *PIN_END, "--dt", "0.01", "--frame-dt", "0.01", "--duration", "100", "--out", str(out),
            "--checkpoint-every", "1", "--no-progress"]
    # Once the first checkpoint exists, well into the stepping while frames are being written.
    returncode, stderr = signal_when_ready(["volspring.cli", *argv], out / "checkpoint.npz",
                                           getattr(signal, signal_name), settle=0.2)
    assert returncode == status, stderr
    lines = stderr.splitlines()
    assert len(lines) == 1 and "Traceback" not in stderr, stderr
    assert re.match(rf"volspring-sim: interrupted by {signal_name}.* at t = [\d.]+ s \(step \d+\); the last checkpoint "
                    rf"is {re.escape(str(out / 'checkpoint.npz'))} at t = [\d.]+ s; resume with: volspring-sim ",
                    lines[0]), lines[0]
    assert lines[0].endswith(f"--resume {out / 'checkpoint.npz'}")
    assert not [p.name for p in out.iterdir() if p.name.startswith(".")]  # no temporary file left
    assert load_checkpoint(out / "checkpoint.npz").step > 0
    import json
    assert json.loads((out / "volspring-run.json").read_text())["status"] == "interrupted"


def test_units_convert_the_input_and_the_lengths_given_with_it(tmp_path, capsys, beam_file):
    # The same beam drawn in millimetres, pinned by a box in millimetres: the same run as in metres.
    millimetres = tmp_path / "beam_mm.vtu"
    metres = cube_mesh((4, 1, 1), size=(0.2, 0.05, 0.05))
    type(metres)(metres.points * 1000.0, metres.tets).write(millimetres)
    status, out_m, _ = run(capsys, beam_file, *PIN_END, *FAST, "--duration", "0.02", "--no-progress")
    assert status == 0
    status, out_mm, err = run(capsys, millimetres, "--units", "mm", "--pin", "-1000,-1000,-1000,0,1000,1000", *FAST,
                              "--duration", "0.02", "--no-progress")
    assert status == 0 and err == ""
    mass = re.compile(r"mass ([\d.e+-]+) kg, (\d+) pinned")
    assert mass.search(out_mm).groups() == mass.search(out_m).groups()  # 0.5 kg of rubber, not 5e8 kg
    sag = re.compile(r"max displacement ([\d.e+-]+) m")
    # Coordinates x1000 then x0.001 differ from the metre file by round-off (1e-16 relative), which the
    # run carries along; six printed digits do not see it.
    assert sag.search(out_mm).group(1) == sag.search(out_m).group(1)


def test_a_huge_body_read_in_metres_gets_a_one_line_warning(tmp_path, capsys):
    huge = tmp_path / "beam_mm.vtu"
    mesh = cube_mesh((4, 1, 1), size=(0.2, 0.05, 0.05))
    type(mesh)(mesh.points * 1000.0, mesh.tets).write(huge)  # a 200 mm beam, read as 200 m
    status, _, err = run(capsys, huge, "--pin", "-1,-1,-1,0,1000,1000", *FAST, "--duration", "0.01", "--quiet")
    assert status == 0
    assert err.startswith("volspring-sim: warning: ") and "--units mm" in err and len(err.splitlines()) == 1


def test_a_shape_in_millimetres(tmp_path, capsys):
    status, out, err = run(capsys, "box:200,50,50", "--units", "mm", "--size", "50", "--pin", "-100,-100,-100,-100,100,100",
                           *FAST, "--duration", "0.01", "--no-progress")
    assert status == 0, err
    assert "box:0.2,0.05,0.05 meshed" in out and "mass 0.55 kg" in out  # 5e-4 m^3 of 1100 kg/m^3 rubber


def test_a_new_run_into_an_earlier_runs_folder_needs_overwrite_and_removes_only_its_files(tmp_path, capsys,
                                                                                          beam_file):
    import json

    out = tmp_path / "out"
    common = [beam_file, *PIN_END, *FAST, "--quiet", "--out", out, "--blender"]
    assert run(capsys, *common, "--duration", "0.1")[0] == 0  # 11 frames
    manifest = json.loads((out / "volspring-run.json").read_text())
    assert manifest["status"] == "finished" and "frame_0010.vtu" in manifest["files"]
    (out / "my_notes.txt").write_text("mine")  # a user's file beside the outputs
    # A shorter run into the same folder: refused without --overwrite, naming the folder and the flag.
    status, _, err = run(capsys, *common, "--duration", "0.03")
    assert status == 2 and len(err.splitlines()) == 1 and str(out) in err and "--overwrite" in err
    assert (out / "frame_0010.vtu").exists()  # nothing touched
    status, _, err = run(capsys, *common, "--duration", "0.03", "--overwrite")
    assert status == 0, err
    # Only the shorter run's frames remain (before, 156 stale files stayed for ParaView and Blender to find).
    assert sorted(p.name for p in out.glob("frame_0*.vtu")) == [f"frame_{k:04d}.vtu" for k in range(4)]
    assert sorted(p.name for p in out.glob("surface_*.obj")) == [f"surface_{k:04d}.obj" for k in range(4)]
    assert len(read_pvd(out / "frame.pvd")) == 4 and len(read_pc2(out / "surface.pc2")[0]) == 4
    assert (out / "my_notes.txt").read_text() == "mine"  # never anything volspring did not write
    listed = set(json.loads((out / "volspring-run.json").read_text())["files"])
    assert listed == {p.name for p in out.iterdir()} - {"my_notes.txt", "volspring-run.json"}


def test_stale_temporaries_of_a_killed_run_are_removed_by_the_next(tmp_path, capsys, beam_file):
    out = tmp_path / "out"
    out.mkdir()
    # What a SIGKILL mid-write leaves: a temporary named by a process that no longer runs.
    stale = out / ".frame_0076.volspring-tmp-999999999-3fa9c2e1.vtu"
    stale.write_bytes(b"\0" * 1000)
    status, _, err = run(capsys, beam_file, *PIN_END, *FAST, "--duration", "0.01", "--out", out, "--quiet")
    assert status == 0, err
    assert not stale.exists()


def test_resuming_keeps_the_frames_before_the_checkpoint_whatever_the_time_drift(tmp_path):
    """The PVD lists decimal times, the checkpoint the float that the steps added up to, which drifts from the
    decimal by more than 1e-6 dt after some 3e5 steps (measured from 259,000 steps at dt 0.01 to 1e-4): the
    frame at the checkpoint was then kept and written again, and the writer refused the duplicate."""
    from types import SimpleNamespace

    from volspring.cli._run import _frames_before
    from volspring.output.paraview import write_pvd

    write_pvd(tmp_path / "frame.pvd", [(0.0, "frame_0000.vtu"), (0.1, "frame_0001.vtu"), (0.2, "frame_0002.vtu")])
    args = SimpleNamespace(out=tmp_path, dt=0.01)
    drifted = 0.2 + 3e-8  # 3e-6 dt above the frame's decimal time
    assert _frames_before(args, drifted) == 2
    assert _frames_before(args, 0.2 - 3e-8) == 2


def test_blender_output_comes_with_its_import_script(tmp_path, capsys, beam_file):
    """--blender writes surface_blender.py beside the OBJ and PC2: one Blender frame per frame written."""
    import runpy

    status, _, err = run(capsys, beam_file, *PIN_END, *FAST, "--duration", "0.03", "--out", tmp_path, "--blender",
                         "--quiet")
    assert status == 0, err
    space = runpy.run_path(str(tmp_path / "surface_blender.py"), run_name="check")  # its main() needs Blender
    assert (space["FPS"], space["FPS_BASE"]) == (100, 1.0)  # --frame-dt 0.01 s
    assert space["frame_range"](space["read_cache_header"](tmp_path / "surface.pc2")[1]) == (1, 4)  # t = 0 .. 0.03
