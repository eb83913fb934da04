"""One command-line convention: the ``volspring`` dispatcher and the options, exit statuses, help and progress
that ``volspring mesh``, ``sim`` and ``validate`` share (with the old spellings kept as aliases)."""

import io
import os
import re
import signal
import subprocess
import sys
from pathlib import Path

import pytest

import meshing._command_line
import validation.report.runner
from conftest import cube_mesh
from meshing import TetMesh
from meshing.cli import main as mesh_main
from validation.cli import main as validate_main
from volspring.cli import main as sim_main
from volspring.command import commands, main as volspring_main

MAINS = {"mesh": mesh_main, "sim": sim_main, "validate": validate_main}
PIN_END = ["--pin", "-1,-1,-1,0,1,1"]
FAST = ["--dt", "0.005", "--frame-dt", "0.01"]
SCRIPTS = Path(sys.executable).parent  # the venv's bin folder, where pip put the console scripts


@pytest.fixture(scope="module")
def beam_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("mesh") / "beam.vtu"
    cube_mesh((4, 1, 1), size=(0.2, 0.05, 0.05)).write(path)
    return path


def valid_argv(command, tmp_path, beam_file):
    """A quick run of each command that succeeds."""
    if command == "mesh":
        return ["box:0.2,0.05,0.05", "-o", str(tmp_path / "beam.vtu"), "--size", "0.05"]
    if command == "sim":
        return [str(beam_file), *PIN_END, *FAST, "--duration", "0.02"]
    return ["cauchy", "--quick", "--out", str(tmp_path / "report"), "--cache", str(tmp_path / "cache")]


def one_line(err, prefix):
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith(prefix), err
    return lines[0]


# ---------------------------------------------------------------------- the dispatcher
def test_each_package_registers_its_subcommand_as_an_entry_point():
    found = commands()
    assert list(found)[:3] == ["mesh", "sim", "validate"]  # along the data path
    assert {name: found[name].value for name in MAINS} == {
        "mesh": "meshing.cli:main", "sim": "volspring.cli:main", "validate": "validation.cli:main"}
    assert all(found[name].load() is MAINS[name] for name in MAINS)


def test_the_dispatcher_runs_a_subcommand_with_the_rest_of_the_line(tmp_path, capsys):
    out = tmp_path / "beam.vtu"
    assert volspring_main(["mesh", "box:0.2,0.05,0.05", "-o", out, "--size", "0.05"]) == 0
    assert TetMesh.read(out).tet_count > 0 and "tets: " in capsys.readouterr().out
    assert volspring_main(["sim", out, *PIN_END, *FAST, "--duration", "0.01", "-q"]) == 0


@pytest.mark.parametrize("argv, message", [
    ([], "volspring: error: a command is required: mesh, sim, validate"),
    (["mseh"], "volspring: error: unknown command 'mseh'; did you mean mesh? (commands: mesh, sim, validate, sweep)"),
    (["--frobnicate"], "volspring: error: unknown option '--frobnicate'"),
])
def test_the_dispatcher_refuses_a_missing_or_unknown_command_in_one_line(argv, message, capsys):
    assert volspring_main(argv) == 2
    captured = capsys.readouterr()
    assert one_line(captured.err, message) and captured.out == ""


def test_the_dispatcher_help_lists_the_commands_and_the_exit_statuses(capsys):
    assert volspring_main(["--help"]) == 0
    text = capsys.readouterr().out
    for name in MAINS:
        assert re.search(rf"^  {name} +\S", text, flags=re.M), text
    assert "exit status:" in text and "130  interrupted by Ctrl-C" in text


def test_version_everywhere(capsys):
    from importlib.metadata import version

    number = version("volspring")
    assert volspring_main(["--version"]) == 0
    assert capsys.readouterr().out == f"volspring {number}\n"
    for name, main in MAINS.items():
        assert main(["--version"]) == 0
        assert capsys.readouterr().out == f"volspring-{name} (volspring {number})\n"
        assert volspring_main([name, "--version"]) == 0  # through the dispatcher, named as typed
        assert capsys.readouterr().out == f"volspring {name} (volspring {number})\n"


@pytest.mark.parametrize("name", ["mesh", "sim", "validate", "sweep"])
def test_under_the_dispatcher_a_command_is_named_as_it_was_typed(name, tmp_path, capsys):
    # The usage, the help's last line and every error line say "volspring sim", not the alias volspring-sim.
    assert volspring_main([name, "--no-such-flag"]) == 2
    one_line(capsys.readouterr().err, f"volspring {name}: error: ")
    assert volspring_main([name, "--help"]) == 0
    text = capsys.readouterr().out
    assert text.startswith(f"usage: volspring {name} ") and f'"volspring {name}: error: ..."' in text
    assert meshing._command_line.command_name(f"volspring-{name}") == f"volspring-{name}"  # the name is restored


@pytest.mark.parametrize("argv, name", [
    (["volspring", "sim", "--version"], "volspring sim"), (["volspring-mesh", "--version"], "volspring-mesh"),
    (["volspring-sim", "--version"], "volspring-sim"), (["volspring-validate", "--version"], "volspring-validate"),
    (["python", "-m", "volspring", "validate", "--version"], "volspring validate")])
def test_the_installed_scripts_and_python_m_volspring(argv, name):
    from importlib.metadata import version

    # The console scripts pip installed from [project.scripts], and `python -m volspring`.
    command = [sys.executable, *argv[1:]] if argv[0] == "python" else [str(SCRIPTS / argv[0]), *argv[1:]]
    if argv[0] != "python" and not Path(command[0]).exists():
        pytest.skip(f"{argv[0]} is not installed next to {sys.executable} (pip install -e . installs it)")
    done = subprocess.run(command, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0 and done.stderr == "", done.stderr
    assert done.stdout == f"{name} (volspring {version('volspring')})\n", done.stdout


# ---------------------------------------------------------------------- the same flags everywhere, old spellings kept
def test_mesh_old_spellings_output_and_method_are_aliases(tmp_path, capsys):
    new, old = tmp_path / "new.vtu", tmp_path / "old.vtu"
    assert mesh_main(["box:0.2,0.05,0.05", "-o", str(new), "--size", "0.05", "--mesher", "delaunay",
                      "--seed", "1", "-q"]) == 0
    assert mesh_main(["box:0.2,0.05,0.05", "--output", str(old), "--size", "0.05", "--method", "delaunay",
                      "--seed", "1", "-q"]) == 0
    assert mesh_main(["box:0.2,0.05,0.05", "--out", str(tmp_path / "long.vtu"), "--size", "0.05", "-q"]) == 0
    a, b = TetMesh.read(new), TetMesh.read(old)
    assert a.points.tobytes() == b.points.tobytes() and a.tets.tobytes() == b.tets.tobytes()  # the same run
    assert capsys.readouterr() == ("", "")  # -q: no summary


def test_sim_out_method_and_no_progress_spellings(tmp_path, capsys, beam_file):
    from volspring.output import read_pvd

    short, long = tmp_path / "short", tmp_path / "long"
    assert sim_main([beam_file, *PIN_END, *FAST, "--duration", "0.02", "-o", short, "-q"]) == 0
    assert sim_main([beam_file, *PIN_END, *FAST, "--duration", "0.02", "--out", long, "--no-progress"]) == 0
    assert [t for t, _ in read_pvd(short / "frame.pvd")] == [t for t, _ in read_pvd(long / "frame.pvd")]
    capsys.readouterr()
    # --method, volspring mesh's earlier spelling of --mesher, means the same here.
    assert sim_main(["box:0.2,0.05,0.05", "--size", "0.05", "--method", "delaunay", "--seed", "1", *FAST,
                     "--pin", "-0.1,-1,-1,-0.1,1,1", "--duration", "0.01", "--no-progress"]) == 0
    assert "meshed by delaunay" in capsys.readouterr().out


def test_validate_out_rule_quiet_and_progress_spellings(tmp_path, capsys, monkeypatch):
    seen = {}

    def run_validation(**kwargs):
        seen.update(kwargs)
        raise RuntimeError("stop here: the options were read")

    monkeypatch.setattr(validation.report.runner, "run_validation", run_validation)
    argv = ["cauchy", "--quick", "-o", str(tmp_path / "out"), "--cache", str(tmp_path / "cache"), "--no-progress",
            "--rule", "lloyd,van_gelder", "--model", "springs"]
    assert validate_main(argv) == 1
    assert seen["rules"] == ("van_gelder", "lloyd") and seen["models"] == ("springs",)
    assert (tmp_path / "out" / "volspring-run.json").is_file()  # -o is --out
    capsys.readouterr()
    assert validate_main(["--rule", "hooke", "--out", str(tmp_path / "other")]) == 2
    assert one_line(capsys.readouterr().err, "volspring-validate: error: --rule 'hooke': unknown rule 'hooke'; "
                                             "known: van_gelder, lloyd, uniform")


@pytest.mark.parametrize("command", list(MAINS))
def test_every_command_has_the_common_options(command, capsys):
    assert MAINS[command](["--help"]) == 0
    text = capsys.readouterr().out
    for option in ("--version", "-q, --quiet", "-v, --verbose", "--progress, --no-progress", "-o "):
        assert option in text, (command, option)


# ---------------------------------------------------------------------- help and usage errors
@pytest.mark.parametrize("command", list(MAINS))
def test_help_ends_with_the_exit_statuses_and_says_each_default_once(command, capsys):
    assert MAINS[command](["--help"]) == 0
    text = capsys.readouterr().out
    assert text.rstrip().endswith(f'"volspring-{command}: error: ..."; the summary is on stdout, progress and logs '
                                  "on stderr.")
    for status in ("0    done", "1    the run failed", "2    bad command line or bad input", "3    the simulation "
                   "diverged", "130  interrupted by Ctrl-C; 143 by SIGTERM, 129 by SIGHUP"):
        assert status in text
    assert "default: None" not in text and "(default: False)" not in text
    # One entry per option: the lines from one "  -x" or "  --x" to the next.
    options = re.split(r"\n(?=  -)", text.split("options:", 1)[1].split("exit status:")[0])
    twice = [entry.split()[0] for entry in options if len(re.findall(r"default", entry, flags=re.I)) > 1]
    assert not twice, f"{command}: options whose help names the default twice: {twice}"


@pytest.mark.parametrize("command", list(MAINS))
def test_a_usage_error_is_one_line_with_status_2(command, tmp_path, beam_file, capsys):
    assert MAINS[command](valid_argv(command, tmp_path, beam_file) + ["--frobnicate"]) == 2
    captured = capsys.readouterr()
    assert one_line(captured.err, f"volspring-{command}: error: unrecognized arguments: --frobnicate")
    assert captured.out == "" and not list(tmp_path.iterdir())  # refused before any work


# ---------------------------------------------------------------------- the same exit statuses everywhere
def _fail_in_the_work(command, monkeypatch, exception):
    """Make the work of ``command`` raise ``exception`` (an instance, or a callable doing the raising)."""
    def broken(*args, **kwargs):
        if callable(exception):
            exception()
        raise exception

    if command == "mesh":
        import importlib

        monkeypatch.setattr(importlib.import_module("meshing.tetrahedralize"), "tetrahedralize", broken)
    elif command == "sim":
        import importlib

        # importlib: the package's `simulate` attribute is the function, which hides the module of that name.
        monkeypatch.setattr(importlib.import_module("volspring.simulate"), "simulate", broken)
    else:
        monkeypatch.setattr(validation.report.runner, "run_validation", broken)


def _sigterm():
    os.kill(os.getpid(), signal.SIGTERM)  # what `kill PID` does; the command's handler raises here
    raise AssertionError("SIGTERM did not stop the command")


FAILURES = [(0, None), (1, RuntimeError("the solver gave up")), (2, "bad input"),
            (3, FloatingPointError("simulation diverged at step 7")), (130, KeyboardInterrupt()), (143, _sigterm)]


@pytest.mark.parametrize("command, status, failure", [
    (command, status, failure) for command in MAINS for status, failure in FAILURES
    if not (command == "mesh" and status == 3)])  # meshing has no simulation to diverge
def test_exit_statuses_are_the_same_on_every_command(command, status, failure, tmp_path, beam_file, capsys,
                                                     monkeypatch):
    argv = valid_argv(command, tmp_path, beam_file)
    if command == "validate" and status == 0:
        argv += ["--rule", "van_gelder"]  # the Cauchy study alone, about 2 s
    elif failure == "bad input":
        argv += {"mesh": ["--shells", "-1"], "sim": ["--E", "-1"], "validate": ["--nu", "0.7"]}[command]
    elif failure is not None:
        _fail_in_the_work(command, monkeypatch, failure)
    before = signal.getsignal(signal.SIGTERM)
    assert MAINS[command](argv) == status
    captured = capsys.readouterr()
    assert signal.getsignal(signal.SIGTERM) == before  # the handler is put back
    if status == 0:
        assert captured.err == ""
        return
    line = one_line(captured.err, f"volspring-{command}: ")
    start, detail = {1: ("error: ", "the solver gave up"), 2: ("error: ", ""),
                     3: ("error: ", "simulation diverged at step 7"), 130: ("interrupted by SIGINT (Ctrl-C)", ""),
                     143: ("interrupted by SIGTERM", "")}[status]
    assert line.startswith(f"volspring-{command}: {start}") and detail in line, line
    assert captured.out == ""


def test_a_write_failure_in_mesh_and_sim_is_status_1(tmp_path, beam_file, capsys, monkeypatch):
    import volspring.output

    def full(*args, **kwargs):
        raise OSError("No space left on device")

    monkeypatch.setattr(TetMesh, "write", full)
    assert mesh_main(["box:0.2,0.05,0.05", "-o", str(tmp_path / "beam.vtu"), "--size", "0.05"]) == 1
    monkeypatch.setattr(volspring.output.ParaViewWriter, "__call__", full)
    assert sim_main([beam_file, *PIN_END, *FAST, "--duration", "0.02", "--out", tmp_path / "out"]) == 1
    err = capsys.readouterr().err.splitlines()
    assert err == ["volspring-mesh: error: No space left on device", "volspring-sim: error: No space left on device"]


# ---------------------------------------------------------------------- progress
@pytest.fixture
def short_interval(monkeypatch):
    """Lines every 0.2 s instead of 5 s, so that a run of a second or two shows the throttling."""
    monkeypatch.setattr(meshing._command_line, "LOG_INTERVAL", 0.2)
    return 0.2


def test_progress_in_a_log_is_a_few_plain_lines(tmp_path, capsys, short_interval):
    import time

    mesh = tmp_path / "beam.vtu"
    cube_mesh((16, 4, 4), size=(0.8, 0.2, 0.2)).write(mesh)
    started = time.perf_counter()
    # 400 steps, 400 frames: a redraw per frame would be 400 lines.
    assert sim_main([mesh, *PIN_END, "--dt", "0.0025", "--frame-dt", "0.0025", "--duration", "1",
                     "--progress"]) == 0
    elapsed = time.perf_counter() - started
    captured = capsys.readouterr()
    assert "\r" not in captured.err and "sim:" not in captured.out
    lines = captured.err.splitlines()
    # The first line at once (--progress), then one per interval at most, and the last at 100 %.
    assert 2 <= len(lines) <= elapsed / short_interval + 2, (elapsed, lines)
    assert all(len(line) < 120 and line.startswith("sim: ") for line in lines)
    assert lines[-1].startswith("sim: 100% 400/400 steps") and " left, " in lines[-1] and "steps/s" in lines[-1]


@pytest.mark.parametrize("command", list(MAINS))
def test_progress_on_a_non_terminal_never_writes_a_carriage_return(command, tmp_path, beam_file, capsys,
                                                                   short_interval):
    argv = valid_argv(command, tmp_path, beam_file) + (["--rule", "van_gelder"] if command == "validate" else [])
    assert MAINS[command](argv + ["--progress"]) == 0
    captured = capsys.readouterr()
    assert "\r" not in captured.err + captured.out
    lines = captured.err.splitlines()
    assert lines and lines[-1].startswith(f"{command}: 100%"), captured.err
    assert not any(line.startswith(f"{command}:") for line in captured.out.splitlines())


@pytest.mark.parametrize("command", list(MAINS))
def test_by_default_a_short_run_in_a_log_prints_no_progress(command, tmp_path, beam_file, capsys):
    # The first line comes after LOG_INTERVAL (5 s): a run shorter than that leaves a log clean.
    argv = valid_argv(command, tmp_path, beam_file) + (["--rule", "van_gelder"] if command == "validate" else [])
    assert MAINS[command](argv) == 0
    captured = capsys.readouterr()
    assert captured.err == "" and captured.out  # the summary, and nothing else


def test_mesh_progress_on_a_terminal_is_a_bar(tmp_path, capsys, monkeypatch):
    class Terminal(io.StringIO):
        def isatty(self):
            return True

    terminal = Terminal()
    monkeypatch.setattr(sys, "stderr", terminal)
    assert mesh_main(["box:0.2,0.05,0.05", "-o", str(tmp_path / "beam.vtu"), "--size", "0.05"]) == 0
    last = terminal.getvalue().rstrip("\n").split("\r")[-1]
    assert last.startswith("mesh: 100%|") and "5/5 stages" in last and ", done" in last


# ---------------------------------------------------------------------- -v: the log and gmsh's output on stderr only
@pytest.mark.parametrize("command", ["mesh", "sim"])
def test_verbose_logs_gmsh_on_stderr_never_in_the_summary(command, tmp_path, capfd):
    if command == "mesh":
        argv = ["box:0.2,0.05,0.05", "-o", str(tmp_path / "beam.vtu"), "--size", "0.05", "-v"]
    else:
        argv = ["box:0.2,0.05,0.05", "--size", "0.05", "--pin", "xmin", *FAST, "--duration", "0.01", "-v"]
    assert MAINS[command](argv) == 0
    out, err = capfd.readouterr()
    assert "Info" in err and "Meshing 3D" in err  # gmsh's own log, through file descriptor 1 redirected to 2
    assert "Info" not in out and "Meshing" not in out
    first = "input: built-in box" if command == "mesh" else "body: box:0.2,0.05,0.05 meshed by gmsh"
    assert out.startswith(first), out


# ---------------------------------------------------------------------- the notebook callback
def test_notebook_progress_follows_the_simulated_time_and_chains_a_callback():
    from volspring import Model, Scene, simulate
    from volspring.progress import notebook_progress

    scene = Scene(Model.from_arrays([[0, 0, 0], [1, 0, 0]], [1.0, 1.0], [[0, 1]], stiffness=100.0))
    seen, stream = [], io.StringIO()

    def mine(frame_index, state):
        seen.append((frame_index, state.step))
        return False if frame_index == 2 else None  # stop after the third frame

    with notebook_progress(0.1, then=mine, file=stream) as progress:
        result = simulate(scene, "verlet", duration=0.1, dt=0.01, frame_dt=0.02, callback=progress)
        # Stopped by `mine` at t = 0.04 s: the bar stands at 40 %, in simulated seconds.
        assert result.stopped_early and seen == [(0, 0), (1, 2), (2, 4)]
        assert progress.bar.n == pytest.approx(0.04, abs=1e-12) and progress.bar.total == 0.1
    text = stream.getvalue()
    assert "simulate:  40%" in text and "t = 0.04/0.1 s" in text and "frame 2" in text
    # A resumed run: the bar starts at the state's time.
    state = result.state
    with notebook_progress(0.06, start=state.t, file=io.StringIO()) as progress:
        simulate(scene, "verlet", duration=0.06, dt=0.01, state=state, frame_dt=0.02, callback=progress)
        assert progress.bar.n == pytest.approx(0.06, abs=1e-12)


@pytest.mark.parametrize("kwargs, message", [
    ({"duration": -1.0}, "duration = -1.0 s is not a finite number >= 0"),
    ({"duration": 1.0, "start": float("nan")}, "start = nan s is not a finite number"),
    ({"duration": 1.0, "then": 3}, "then = 3 is not callable"),
])
def test_notebook_progress_refuses_bad_arguments(kwargs, message):
    from volspring.progress import notebook_progress

    with pytest.raises((ValueError, TypeError), match=re.escape(message)):
        notebook_progress(**kwargs, file=io.StringIO())
