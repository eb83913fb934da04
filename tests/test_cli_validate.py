"""volspring-validate's output folder: checked before any work, a manifest, --overwrite, interruptions, --units."""

import json
import os
import signal
import time

import pytest

import validation.report.html
import validation.report.runner
from conftest import signal_when_ready
from validation.cli import main
from meshing._io import is_temporary_name
from volspring.output import read_manifest

# The cheapest real run: the Cauchy study alone (about 2 s), which writes results.json and report.html.
CAUCHY = ["cauchy", "--quick", "--no-progress"]


@pytest.fixture
def no_work(monkeypatch):
    """Fail the test if the computation starts: the error must come before it."""
    def run_validation(**kwargs):
        raise AssertionError("the validation ran before the bad input was reported")

    monkeypatch.setattr(validation.report.runner, "run_validation", run_validation)


@pytest.fixture
def cache(tmp_path):
    return str(tmp_path / "cache")


@pytest.fixture
def beam_files(tmp_path):
    from meshing import structured_box

    metres, millimetres = tmp_path / "beam.vtu", tmp_path / "beam_mm.vtu"
    structured_box((4, 1, 1), (1.0, 0.25, 0.25)).write(metres)
    structured_box((4, 1, 1), (1000.0, 250.0, 250.0)).write(millimetres)
    return metres, millimetres


def one_error_line(capsys):
    error = capsys.readouterr().err.strip()
    assert "\n" not in error and "Traceback" not in error, error
    return error


# ---------------------------------------------------------------------- output locations, before any work
@pytest.mark.parametrize("where, expected", [
    ("out_file", "--out {file} is an existing file, expected a folder (or a path where one can be created)"),
    ("out_under_file", "--out {file}/report cannot be created: {file} is a file, not a folder"),
    ("cache_file", "--cache {file} is an existing file, expected a folder (or a path where one can be created)"),
    ("default_cache_file", "the FEM cache folder {file} is an existing file, expected a folder (or a path where one "
                           "can be created); choose another with --cache DIR or $VOLSPRING_CACHE"),
])
def test_bad_output_locations_fail_at_once(where, expected, tmp_path, no_work, capsys, monkeypatch):
    file = tmp_path / "report.html"
    file.write_text("an earlier report, kept")
    out, cache = str(tmp_path / "out"), ["--cache", str(tmp_path / "cache")]
    if where == "out_file":
        out = str(file)
    elif where == "out_under_file":
        out = str(file / "report")
    elif where == "cache_file":
        cache = ["--cache", str(file)]
    else:
        cache = []
        monkeypatch.setenv("VOLSPRING_CACHE", str(file))
    status = main(CAUCHY + ["--out", out] + cache)
    assert status == 2
    assert one_error_line(capsys) == f"volspring-validate: error: {expected.format(file=file)}"
    assert file.read_text() == "an earlier report, kept"


def test_an_unwritable_out_fails_at_once(tmp_path, no_work, capsys, monkeypatch):
    out = tmp_path / "out"
    out.mkdir()
    # Tests may run as root, who writes anywhere: a folder without write permission is simulated.
    monkeypatch.setattr(os, "access", lambda path, mode: os.fspath(path) != str(out))
    assert main(CAUCHY + ["--out", str(out), "--cache", str(tmp_path / "cache")]) == 2
    assert one_error_line(capsys) == (f"volspring-validate: error: --out {out} is not writable (no permission to "
                                      "create files in it)")


def test_a_folder_with_files_volspring_did_not_write_is_refused_before_any_work(tmp_path, no_work, capsys):
    out = tmp_path / "validation-report"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    assert main(CAUCHY + ["--out", str(out)]) == 2
    assert one_error_line(capsys).startswith(
        f"volspring-validate: error: {out} is not empty (1 entry: notes.txt) and holds no volspring-run.json, so "
        "volspring cannot tell which files are a run's outputs; pass --overwrite to write into it anyway")


# ---------------------------------------------------------------------- re-running into a report folder
def test_same_command_replaces_its_report_and_another_needs_overwrite(tmp_path, beam_files, cache, capsys):
    out = tmp_path / "validation-report"
    own = ["--mesh", str(beam_files[0]), "--clamp", "xmin", "--E", "1e8", "--out", str(out), "--cache", cache,
           "--no-progress"]
    assert main(own) == 0  # a first run into a new folder, as in the README
    manifest = read_manifest(out)
    assert manifest["status"] == "finished" and manifest["command"] == ["volspring-validate"] + own
    assert sorted(manifest["files"]) == ["report.html", "results.json", "vtu/own_mesh.vtu",
                                         "vtu/own_mesh_side_by_side.vtu"]
    capsys.readouterr()

    assert main(own) == 0  # the same command again: the report is regenerated in place
    assert "(replacing the 4 file(s) of the previous run)" in capsys.readouterr().out
    assert read_manifest(out)["started"] >= manifest["started"]

    other = CAUCHY + ["--out", str(out), "--cache", cache]
    assert main(other) == 2
    assert one_error_line(capsys) == (
        f"volspring-validate: error: {out} holds the outputs of another run (volspring-validate {' '.join(own)}, "
        f"started {read_manifest(out)['started']}, finished), listed in volspring-run.json; pass --overwrite to "
        "remove them (4 file(s), nothing else) and write this run's outputs there, or choose another folder")

    (out / "notes.txt").write_text("mine")
    (out / "vtu" / "my_view.pvsm").write_text("a ParaView state of mine")
    assert main(other + ["--overwrite"]) == 0
    listed = read_manifest(out)["files"]
    assert sorted(listed) == ["report.html", "results.json"]
    assert sorted(str(path.relative_to(out)) for path in out.rglob("*") if path.is_file()) == [
        "notes.txt", "report.html", "results.json", "volspring-run.json", "vtu/my_view.pvsm"]
    assert "cauchy" in json.loads((out / "results.json").read_text())["studies"]


# ---------------------------------------------------------------------- interruptions
@pytest.mark.parametrize("stop, status, name", [("ctrl-c", 130, "SIGINT (Ctrl-C)"), ("sigterm", 143, "SIGTERM")])
def test_an_interruption_while_computing(stop, status, name, tmp_path, cache, capsys, monkeypatch):
    def run_validation(**kwargs):
        if stop == "ctrl-c":
            raise KeyboardInterrupt
        os.kill(os.getpid(), signal.SIGTERM)  # what `kill PID` does; the handler raises here
        time.sleep(5)
        raise AssertionError("SIGTERM did not stop the run")

    monkeypatch.setattr(validation.report.runner, "run_validation", run_validation)
    before = signal.getsignal(signal.SIGTERM)
    out = tmp_path / "out"
    assert main(CAUCHY + ["--out", str(out), "--cache", cache]) == status
    assert one_error_line(capsys) == (f"volspring-validate: interrupted by {name}; nothing was written to {out} "
                                      f"({out}/volspring-run.json marks the run interrupted)")
    assert read_manifest(out)["status"] == "interrupted"
    assert signal.getsignal(signal.SIGTERM) == before


def test_sigterm_while_writing_leaves_complete_listed_files_only(tmp_path, cache, capsys, monkeypatch):
    real_html = validation.report.html.render_html

    def html_then_sigterm(results, figures):
        text = real_html(results, figures)
        os.kill(os.getpid(), signal.SIGTERM)  # inside atomic_path, while report.html is a temporary file
        return text

    monkeypatch.setattr(validation.report.html, "render_html", html_then_sigterm)
    out = tmp_path / "out"
    assert main(CAUCHY + ["--out", str(out), "--cache", cache]) == 143
    assert one_error_line(capsys) == (
        f"volspring-validate: interrupted by SIGTERM; {out} holds 1 complete file(s) of the report, listed in "
        f"{out}/volspring-run.json (marked interrupted); run the command again to redo it")
    assert sorted(path.name for path in out.iterdir()) == ["results.json", "volspring-run.json"]
    monkeypatch.undo()
    assert main(CAUCHY + ["--out", str(out), "--cache", cache]) == 0  # the same command redoes it
    assert (out / "report.html").is_file()


@pytest.mark.skipif(os.name != "posix", reason="POSIX signals")
@pytest.mark.parametrize("signum, status, name", [(signal.SIGTERM, 143, "SIGTERM"),
                                                  (signal.SIGINT, 130, "SIGINT (Ctrl-C)")])
def test_a_real_signal_gives_one_line_and_its_exit_status(signum, status, name, tmp_path):
    out, cache = tmp_path / "out", tmp_path / "cache"
    # The folder is claimed before the work starts; half a second later the --quick run (about 40 s)
    # is computing.
    returncode, stderr = signal_when_ready(["validation.cli", "--quick", "--out", out, "--cache", cache],
                                           out / "volspring-run.json", signum, settle=0.5)
    assert returncode == status
    last = stderr.strip().split("\r")[-1].split("\n")[-1]  # after the progress bar's line
    assert last.startswith(f"volspring-validate: interrupted by {name}; ") and "Traceback" not in stderr
    assert read_manifest(out)["status"] == "interrupted"
    left = [path for folder in (out, cache) if folder.exists() for path in folder.rglob("*")]
    assert not [path for path in left if is_temporary_name(path)]


# ---------------------------------------------------------------------- --units and --scale
def test_units_read_a_mesh_in_millimetres(tmp_path, beam_files, cache):
    metres, millimetres = beam_files
    tips = {}
    for name, options in (("m", ["--mesh", str(metres)]), ("mm", ["--mesh", str(millimetres), "--units", "mm"]),
                          ("scale", ["--mesh", str(millimetres), "--scale", "0.001"])):
        out = tmp_path / name
        assert main(options + ["--clamp", "x<0.01", "--E", "1e8", "--out", str(out), "--cache", cache,
                               "--no-progress"]) == 0
        case = json.loads((out / "results.json").read_text())["cases"]["own_mesh"]
        tips[name] = case["fem"]["P2"]["tip_deflection_m"]
    # The same beam in metres: only the rounding of 1000 * 0.001 differs, far below the solver's 1e-9.
    assert tips["mm"] == pytest.approx(tips["m"], rel=1e-9)
    assert tips["scale"] == pytest.approx(tips["m"], rel=1e-9)


@pytest.mark.parametrize("arguments, expected", [
    (["--mesh", "{mesh}", "--clamp", "xmin", "--scale", "0"], "--scale 0 is not a finite number > 0"),
    (["--mesh", "{mesh}", "--clamp", "xmin", "--scale", "nan"], "--scale nan is not a finite number > 0"),
    (["--units", "mm"], "--units and --scale apply to --mesh FILE, which is missing"),
    (["--scale", "2"], "--units and --scale apply to --mesh FILE, which is missing"),
])
def test_bad_units_and_scale(arguments, expected, beam_files, tmp_path, no_work, capsys):
    argv = [word.format(mesh=beam_files[0]) for word in arguments]
    assert main(argv + ["--out", str(tmp_path / "out"), "--cache", str(tmp_path / "cache"), "--no-progress"]) == 2
    assert one_error_line(capsys) == f"volspring-validate: error: {expected}"
    assert not (tmp_path / "out").exists()  # refused before the folder was claimed
