"""Run folders: the manifest lists every file a run wrote; a new run replaces those and nothing else.

Also the temporary files of atomic_path: a recognisable name, and their removal after a crash.
"""

import json
import os
import shlex
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

import meshing._io
from meshing._io import atomic_path, is_temporary_name, remove_stale_temporaries
from volspring import Material, Model, State
from meshing._signals import Terminated
from volspring.output import (BlenderWriter, ParaViewWriter, RunFolder, RunFolderRefused, check_output_folder,
                              read_manifest, read_pvd)
from volspring.output.run_folder import MANIFEST_NAME

from conftest import cube_mesh

SIM = ["volspring-sim", "box:1,0.5,0.5", "--out", "run"]
FLAGS = {"overwrite": "--overwrite", "resume": "--resume CHECKPOINT"}


@pytest.fixture(scope="module")
def model():
    return Model.from_mesh(cube_mesh((2, 1, 1), size=(1.0, 0.5, 0.5)), Material(E=1e5, nu=0.3, density=1000.0))


def states(model, count, *, start=0):
    x0 = model.rest_positions
    return [State(x0 + 0.01 * k * x0[:, [2, 0, 1]], np.zeros_like(x0), t=0.04 * k) for k in range(start, start + count)]


def simulate_into(folder, model, frame_count, *, command=SIM, start=0, **options):
    """What volspring-sim does with --out and --blender: ParaView and Blender series recorded in a run folder."""
    with RunFolder.open(folder, command=command, flags=FLAGS, **options) as run:
        writers = [ParaViewWriter(folder, model, first_frame=start, record=run.record),
                   BlenderWriter(folder, model, first_frame=start, record=run.record)]
        for k, state in enumerate(states(model, frame_count, start=start)):
            for writer in writers:
                writer(k, state)
    return run


def listing(folder):
    return sorted(str(path.relative_to(folder)) for path in folder.rglob("*") if path.is_file())


def frame_files(count):
    return sorted([f"frame_{k:04d}.vtu" for k in range(count)] + [f"frame_springs_{k:04d}.vtu" for k in range(count)]
                  + [f"frame_{k:04d}.obj" for k in range(count)] + ["frame.pvd", "frame_springs.pvd", "frame.pc2"])


def dead_pid():
    """The id of a process that has ended (ids are recycled slowly: nothing reuses it within the test)."""
    child = subprocess.Popen([sys.executable, "-c", ""])
    child.wait()
    return child.pid


# ---------------------------------------------------------------------- replacing a run
def test_a_shorter_run_with_overwrite_leaves_no_stale_frames(tmp_path, model):
    folder = tmp_path / "run"
    simulate_into(folder, model, 12)
    assert listing(folder) == frame_files(12) + [MANIFEST_NAME]
    run = simulate_into(folder, model, 3, overwrite=True)
    # Without the manifest, frames 3 to 11 of the first run (27 files) would stay, and Blender's
    # OBJ-sequence import and a glob over the VTU files would pick them up.
    assert listing(folder) == frame_files(3) + [MANIFEST_NAME]
    assert len(run.removed) == len(frame_files(12))
    assert sorted(run.files) == frame_files(3)
    assert [file.name for _, file in read_pvd(folder / "frame.pvd")] == [f"frame_{k:04d}.vtu" for k in range(3)]
    manifest = read_manifest(folder)
    assert manifest["status"] == "finished" and manifest["command"] == SIM


def test_overwrite_removes_only_the_listed_files(tmp_path, model):
    folder = tmp_path / "run"
    simulate_into(folder, model, 4)
    (folder / "notes.txt").write_text("mine")
    (folder / "frame_0099.obj").write_text("looks like ours, but no run listed it")
    (folder / "renders").mkdir()
    (folder / "renders" / "frame_0001.png").write_bytes(b"png")
    simulate_into(folder, model, 2, overwrite=True)
    assert listing(folder) == sorted(frame_files(2) + [MANIFEST_NAME, "notes.txt", "frame_0099.obj",
                                                       "renders/frame_0001.png"])


def test_a_manifest_never_removes_outside_its_folder(tmp_path):
    folder = tmp_path / "run"
    folder.mkdir()
    outside = tmp_path / "precious.txt"
    outside.write_text("keep")
    (folder / "inner").mkdir()
    os.symlink(tmp_path, folder / "link")  # a listed path through a link that leads out of the folder
    (folder / "inner" / "frame.vtu").write_text("ours")
    manifest = {"format": "volspring-run", "version": 1, "command": ["x"], "status": "finished",
                "files": ["../precious.txt", str(outside), "link/precious.txt", "inner", "inner/frame.vtu"]}
    (folder / MANIFEST_NAME).write_text(json.dumps(manifest))
    run = RunFolder.open(folder, command=["y"], overwrite=True)
    assert outside.read_text() == "keep"
    assert [path.name for path in run.removed] == ["frame.vtu"]
    assert not (folder / "inner").exists()  # the folder the run's files left empty


@pytest.mark.parametrize("command, fragment", [
    (SIM, "an earlier run of the same command"),
    (SIM + ["--dt", "0.01"], "another run"),
])
def test_refusal_names_the_folder_the_old_command_and_the_flag(tmp_path, model, command, fragment):
    folder = tmp_path / "run"
    simulate_into(folder, model, 3)
    with pytest.raises(RunFolderRefused) as caught:
        RunFolder.open(folder, command=command, flags=FLAGS)
    message = str(caught.value)
    assert message.startswith(f"{folder} holds the outputs of {fragment} ({shlex.join(SIM)}, started ")
    assert "finished), listed in volspring-run.json; pass --overwrite to remove them (12 file(s), nothing else)" \
        in message  # 3 VTU + 3 spring VTU + 3 OBJ + 2 PVD + 1 PC2
    assert "--resume" not in message  # a finished run is not offered to resume
    assert caught.value.reason == ("same_command" if command == SIM else "other_run")
    assert listing(folder) == frame_files(3) + [MANIFEST_NAME]  # nothing touched
    # The library's own wording when no flags are given:
    with pytest.raises(RunFolderRefused, match="pass overwrite=True to remove them"):
        RunFolder.open(folder, command=command)


def test_an_interrupted_run_is_offered_to_resume(tmp_path, model):
    folder = tmp_path / "run"
    with pytest.raises(KeyboardInterrupt):
        with RunFolder.open(folder, command=SIM) as run:
            writer = ParaViewWriter(folder, model, record=run.record)
            writer(0, states(model, 1)[0])
            raise KeyboardInterrupt
    assert read_manifest(folder)["status"] == "interrupted"
    with pytest.raises(RunFolderRefused, match=r"interrupted\), listed in volspring-run.json; pass --overwrite .*, "
                                               r"or --resume CHECKPOINT to continue it"):
        RunFolder.open(folder, command=SIM, flags=FLAGS)


def test_replace_same_command_replaces_its_own_outputs_only(tmp_path, model):
    folder = tmp_path / "report"
    simulate_into(folder, model, 5, command=["volspring-validate", "--out", "report"])
    run = RunFolder.open(folder, command=["volspring-validate", "--out", "report"], replace_same_command=True)
    assert len(run.removed) == len(frame_files(5)) and listing(folder) == [MANIFEST_NAME]
    run.finish()
    simulate_into(folder, model, 1, command=["volspring-validate", "--out", "report"])
    with pytest.raises(RunFolderRefused, match="another run"):
        RunFolder.open(folder, command=["volspring-validate", "--quick", "--out", "report"], replace_same_command=True)


# ---------------------------------------------------------------------- folders without a manifest
def test_missing_and_empty_folders_are_used(tmp_path):
    created = RunFolder.open(tmp_path / "a" / "b", command=["x"])
    assert created.path.is_dir() and read_manifest(created.path)["status"] == "running"
    (tmp_path / "empty").mkdir()
    (tmp_path / "empty" / ".DS_Store").write_bytes(b"")  # what a desktop drops into a folder it showed
    RunFolder.open(tmp_path / "empty", command=["x"]).finish()


def test_a_folder_with_unlisted_files_is_refused_and_overwrite_removes_none(tmp_path, model):
    folder = tmp_path / "run"
    folder.mkdir()
    names = ["frame_0000.vtu", "frame_0001.vtu", "frame_0002.vtu", "frame_0003.vtu", "frame_0155.obj"]
    for name in names:  # the outputs of a volspring older than manifests, or anyone's files
        (folder / name).write_text("old")
    with pytest.raises(RunFolderRefused) as caught:
        RunFolder.open(folder, command=SIM, flags=FLAGS)
    assert str(caught.value) == (
        f"{folder} is not empty (5 entries: frame_0000.vtu, frame_0001.vtu, frame_0002.vtu, ...) and holds no "
        "volspring-run.json, so volspring cannot tell which files are a run's outputs; pass --overwrite to write "
        "into it anyway (nothing in it is removed; files of the same names are replaced), or choose an empty or new "
        "folder")
    run = simulate_into(folder, model, 2, overwrite=True)
    assert run.removed == ()
    assert (folder / "frame_0155.obj").read_text() == "old" and (folder / "frame_0003.vtu").read_text() == "old"
    assert (folder / "frame_0001.vtu").read_text() != "old"  # replaced by this run, and listed
    assert "frame_0003.vtu" not in run.files


def test_a_run_that_wrote_nothing_does_not_block_the_folder(tmp_path):
    folder = tmp_path / "run"
    with pytest.raises(ValueError):
        with RunFolder.open(folder, command=["a"]):
            raise ValueError("bad input found late")
    assert read_manifest(folder)["status"] == "failed"
    RunFolder.open(folder, command=["b"]).finish()  # nothing to lose: no refusal


# ---------------------------------------------------------------------- resuming
def test_resume_keeps_the_files_and_extends_the_list(tmp_path, model):
    folder = tmp_path / "run"
    with pytest.raises(Terminated):
        with RunFolder.open(folder, command=SIM) as run:
            writer = ParaViewWriter(folder, model, record=run.record)
            for k, state in enumerate(states(model, 3)):
                writer(k, state)
            run.record(folder / "checkpoint.npz")
            (folder / "checkpoint.npz").write_bytes(b"state at frame 2")
            raise Terminated(signal.SIGTERM)
    first = read_manifest(folder)
    assert first["status"] == "interrupted"
    resumed_command = SIM + ["--resume", "run/checkpoint.npz"]
    run = RunFolder.open(folder, command=resumed_command, resume=True)
    assert run.resumed and run.removed == () and run.files == tuple(first["files"])
    writer = ParaViewWriter(folder, model, first_frame=2, record=run.record)
    for k, state in enumerate(states(model, 3, start=2)):
        writer(k, state)
    run.finish()
    manifest = read_manifest(folder)
    assert manifest["files"][:len(first["files"])] == first["files"]
    assert manifest["files"][len(first["files"]):] == ["frame_0003.vtu", "frame_springs_0003.vtu",
                                                       "frame_0004.vtu", "frame_springs_0004.vtu"]
    assert manifest["command"] == resumed_command and manifest["status"] == "finished"
    assert manifest["earlier"] == [{"command": SIM, "started": first["started"], "ended": first["ended"],
                                    "status": "interrupted"}]
    assert (folder / "checkpoint.npz").is_file()
    with pytest.raises(ValueError, match="overwrite=True and resume=True contradict"):
        RunFolder.open(folder, command=SIM, overwrite=True, resume=True)


def test_resume_into_a_folder_of_an_older_volspring(tmp_path):
    folder = tmp_path / "run"
    folder.mkdir()
    (folder / "frame_0000.vtu").write_text("old")
    run = RunFolder.open(folder, command=SIM, resume=True)  # the user says: continue here
    assert not run.resumed and run.files == () and (folder / "frame_0000.vtu").read_text() == "old"


# ---------------------------------------------------------------------- recording
def test_every_file_is_listed_before_it_appears(tmp_path, model, monkeypatch):
    folder = tmp_path / "run"
    real_replace = os.replace
    renamed = []

    def checked_replace(source, target):
        target = os.fspath(target)
        if os.path.basename(target) != MANIFEST_NAME:
            listed = read_manifest(folder)["files"]
            assert os.path.relpath(target, folder) in listed, f"{target} appears before the manifest lists it"
            renamed.append(os.path.basename(target))
        real_replace(source, target)

    monkeypatch.setattr(meshing._io.os, "replace", checked_replace)
    simulate_into(folder, model, 3)
    assert len(renamed) == 3 * 3 + 3 * 2 + 1  # 3 VTU/OBJ per frame, 2 PVD per frame, the PC2 created once


def test_one_manifest_write_per_frame(tmp_path, model, monkeypatch):
    writes = []
    real_write = RunFolder._write
    monkeypatch.setattr(RunFolder, "_write", lambda run: (writes.append(1), real_write(run)))
    folder = tmp_path / "run"
    run = RunFolder.open(folder, command=SIM)
    paraview = ParaViewWriter(folder, model, record=run.record)
    blender = BlenderWriter(folder, model, record=run.record)
    frames = states(model, 5)
    writes.clear()
    for k, state in enumerate(frames[:2]):
        paraview(k, state)  # alone, each writer lists a frame's files in one write
    assert len(writes) == 2
    writes.clear()
    for k, state in enumerate(frames[2:]):
        # A caller with several writers lists the frame's files of all of them at once: one write per frame.
        run.record(*paraview.frame_paths(), *blender.frame_paths())
        paraview(k, state)
        blender(k, state)
    assert len(writes) == 3
    writes.clear()
    run.record(folder / "frame.pvd", folder / "frame_0000.vtu")  # listed already: no write
    assert writes == []


def test_a_crash_in_the_middle_of_a_frame_leaves_only_listed_files(tmp_path, model, monkeypatch):
    import meshio

    folder = tmp_path / "run"
    real_write = meshio.write

    def die_on_the_third_springs_file(path, mesh, **kwargs):
        if mesh.cells[0].type == "line" and "_0002" in os.fspath(path):
            raise Terminated(signal.SIGTERM)
        return real_write(path, mesh, **kwargs)

    monkeypatch.setattr(meshio, "write", die_on_the_third_springs_file)
    with pytest.raises(Terminated):
        simulate_into(folder, model, 4)
    manifest = read_manifest(folder)
    assert manifest["status"] == "interrupted"
    on_disk = set(listing(folder)) - {MANIFEST_NAME}
    assert on_disk <= set(manifest["files"])
    assert "frame_0001.obj" in on_disk and not any(name.startswith(".") for name in on_disk)


def test_record_refuses_paths_outside_and_after_finish(tmp_path, monkeypatch):
    run = RunFolder.open(tmp_path / "run", command=["x"])
    monkeypatch.chdir(tmp_path)
    run.record("run/a.vtu")  # relative to the working directory, like open()
    run.record(tmp_path / "run" / "sub" / "b.vtu")
    assert run.files == ("a.vtu", "sub/b.vtu")
    with pytest.raises(ValueError, match=r"elsewhere.vtu is not inside the run folder"):
        run.record(tmp_path / "elsewhere.vtu")
    with pytest.raises(ValueError, match="is the run manifest"):
        run.record(tmp_path / "run" / MANIFEST_NAME)
    run.finish("failed")
    run.finish("finished")  # only the first call counts
    assert read_manifest(run.path)["status"] == "failed"
    with pytest.raises(RuntimeError, match="is failed: it cannot record"):
        run.record(tmp_path / "run" / "c.vtu")
    with pytest.raises(ValueError, match="status = 'done' is not one of finished, interrupted, failed"):
        run.finish("done")
    with pytest.raises(ValueError, match="must be a sequence of strings"):
        RunFolder.open(tmp_path / "other", command="volspring-sim box:1 --out other")


# ---------------------------------------------------------------------- the manifest
def test_a_newer_or_broken_manifest_is_refused_and_overwrite_leaves_its_files(tmp_path):
    folder = tmp_path / "run"
    folder.mkdir()
    (folder / "frame_0000.vtu").write_text("x")
    (folder / MANIFEST_NAME).write_text(json.dumps({"format": "volspring-run", "version": 2, "command": ["x"],
                                                    "status": "finished", "files": ["frame_0000.vtu"]}))
    with pytest.raises(RunFolderRefused, match=r"cannot be read \(.*manifest version 2; this volspring reads "
                                               r"versions 1 to 1 .*\); pass overwrite=True to start a new run"):
        RunFolder.open(folder, command=["y"])
    run = RunFolder.open(folder, command=["y"], overwrite=True)
    assert (folder / "frame_0000.vtu").is_file() and run.removed == ()
    (folder / MANIFEST_NAME).write_text("{not json")
    with pytest.raises(ValueError, match="is not valid JSON"):
        read_manifest(folder)
    (folder / MANIFEST_NAME).write_text(json.dumps({"format": "something-else"}))
    with pytest.raises(ValueError, match="is not a volspring run manifest"):
        read_manifest(folder)


def test_a_folder_another_process_is_writing_is_refused_even_with_overwrite(tmp_path):
    folder = tmp_path / "run"
    RunFolder.open(folder, command=SIM)
    manifest = read_manifest(folder)
    other = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        (folder / MANIFEST_NAME).write_text(json.dumps(manifest | {"pid": other.pid}))
        with pytest.raises(RunFolderRefused, match=rf"is being written by another run \(.*process {other.pid} on"):
            RunFolder.open(folder, command=SIM, overwrite=True)
    finally:
        other.kill()
        other.wait()
    # Its process gone, the run counts as interrupted.
    (folder / MANIFEST_NAME).write_text(json.dumps(manifest | {"pid": dead_pid(), "files": [MANIFEST_NAME]}))
    RunFolder.open(folder, command=SIM, overwrite=True).finish()


def test_output_folder_checks(tmp_path, monkeypatch):
    file = tmp_path / "report.html"
    file.write_text("")
    with pytest.raises(NotADirectoryError, match=rf"^--out {file} is an existing file, expected a folder"):
        check_output_folder(file, label="--out")
    with pytest.raises(NotADirectoryError, match=rf"^--out {file}/sub cannot be created: {file} is a file"):
        check_output_folder(file / "sub", label="--out")
    with pytest.raises(NotADirectoryError, match="is an existing file"):
        RunFolder.open(file, command=["x"])
    assert check_output_folder(tmp_path / "new" / "deeper") == tmp_path / "new" / "deeper"
    assert not (tmp_path / "new").exists()  # checking creates nothing
    monkeypatch.setattr(os, "access", lambda path, mode: False)  # a read-only folder (root may write anywhere)
    with pytest.raises(PermissionError, match=rf"^--out {tmp_path} is not writable"):
        check_output_folder(tmp_path, label="--out")
    with pytest.raises(PermissionError, match=rf"cannot be created: no permission to create folders in {tmp_path}"):
        check_output_folder(tmp_path / "new", label="--out")


# ---------------------------------------------------------------------- stale temporary files
def test_temporary_names_are_recognisable(tmp_path):
    with atomic_path(tmp_path / "frame_0076.vtu") as tmp:
        assert tmp.name.startswith(f".frame_0076.volspring-tmp-{os.getpid()}-") and tmp.name.endswith(".vtu")
        assert is_temporary_name(tmp)
        # meshio's XDMF writer puts its heavy data beside the temporary .xdmf, named after it:
        assert is_temporary_name(tmp.with_suffix(".h5"))
    with atomic_path(tmp_path / "mesh.xdmf") as tmp:
        assert is_temporary_name(tmp.with_suffix(".h5"))
    with atomic_path(tmp_path / "README") as tmp:  # no suffix: ".tmp"
        assert is_temporary_name(tmp) and tmp.suffix == ".tmp"
    for name in (".frame_0076.k3j2x9a1.vtu",  # the pattern of volspring 0.1: cannot be told from a user's file
                 "frame_0076.vtu", ".frame.volspring-tmp-12-abc", "frame.volspring-tmp-12-abc.vtu",
                 ".frame.volspring-tmp-x-abc.vtu", ".bashrc"):
        assert not is_temporary_name(name), name


def test_only_stale_temporaries_of_our_pattern_are_removed(tmp_path):
    gone, alive = dead_pid(), os.getppid()  # an ended process; pytest's parent, running
    stale = [f".frame_0076.volspring-tmp-{gone}-k3j2x9a1.vtu", f".mesh.volspring-tmp-{gone}-k3j2x9a1.h5",
             f".checkpoint.volspring-tmp-{gone}-abc_0123.npz"]
    kept = [f".frame_0077.volspring-tmp-{alive}-k3j2x9a1.vtu",  # another process is writing it
            ".frame_0076.k3j2x9a1.vtu", "frame_0076.vtu", ".hidden", f"frame.volspring-tmp-{gone}-k3j2x9a1.vtu"]
    for name in stale + kept:
        (tmp_path / name).write_bytes(b"x")
    (tmp_path / f".dir.volspring-tmp-{gone}-k3j2x9a1.vtu").mkdir()  # a folder: never ours
    removed = remove_stale_temporaries(tmp_path)
    assert sorted(path.name for path in removed) == sorted(stale)
    assert sorted(path.name for path in tmp_path.iterdir()) == sorted(kept + [f".dir.volspring-tmp-{gone}-k3j2x9a1.vtu"])
    # Untouched for over a day, a temporary file is stale even if its process id is in use again.
    later = time.time() + meshing._io.STALE_AFTER_SECONDS + 60
    assert [path.name for path in remove_stale_temporaries(tmp_path, now=later)] == [kept[0]]
    assert remove_stale_temporaries(tmp_path / "missing") == []


KILLED_WRITER = textwrap.dedent("""
    import sys, time
    from pathlib import Path
    from meshing._io import atomic_path
    from volspring.output import RunFolder

    folder = Path(sys.argv[1])
    run = RunFolder.open(folder, command=["writer"])
    for name in ("frame_0000.vtu", "vtu/case.vtu"):
        run.record(folder / name)
        with atomic_path(folder / name) as tmp:
            tmp.write_bytes(b"x" * 600_000)
            print("writing", tmp, flush=True)
            time.sleep(0.5 if name == "frame_0000.vtu" else 60)
""")


@pytest.mark.skipif(os.name != "posix", reason="SIGKILL")
def test_opening_removes_what_a_killed_run_left(tmp_path):
    script = tmp_path / "writer.py"
    script.write_text(KILLED_WRITER)
    folder = tmp_path / "run"
    child = subprocess.Popen([sys.executable, str(script), str(folder)], stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout.readline().startswith("writing ")
        assert child.stdout.readline().startswith("writing ")  # in vtu/, then killed there
        child.send_signal(signal.SIGKILL)
        child.wait(timeout=30)
    finally:
        if child.poll() is None:
            child.kill()
            child.wait()
    left = [path.name for path in (folder / "vtu").iterdir()]
    assert len(left) == 1 and is_temporary_name(left[0])  # what SIGKILL leaves: a 600 KB temporary file
    assert read_manifest(folder)["status"] == "running"  # and a manifest that could not be updated
    with pytest.raises(RunFolderRefused, match=r"holds the outputs of another run \(writer, started .*, "
                                               r"interrupted\)"):  # its process is gone
        RunFolder.open(folder, command=["next"])
    run = RunFolder.open(folder, command=["next"], overwrite=True)
    assert listing(folder) == [MANIFEST_NAME] and [path.name for path in run.removed] == ["frame_0000.vtu"]


# ---------------------------------------------------------------------- the run record: versions, timings, solver
def test_a_manifest_without_the_run_record_of_newer_runs_still_reads_and_is_replaced(tmp_path):
    # A manifest as volspring wrote it before runs recorded versions, timings, solver statistics and the summary.
    folder = tmp_path / "run"
    folder.mkdir()
    (folder / "frame_0000.vtu").write_text("x")
    (folder / MANIFEST_NAME).write_text(json.dumps({
        "format": "volspring-run", "version": 1, "command": SIM, "started": "2025-01-31T09:12:44+00:00",
        "ended": "2025-01-31T09:13:01+00:00", "status": "finished", "pid": 1, "host": "elsewhere",
        "volspring": "0.0.9", "earlier": [], "files": ["frame_0000.vtu"]}))
    old = read_manifest(folder)
    assert old["status"] == "finished" and "versions" not in old and "solver" not in old
    run = RunFolder.open(folder, command=SIM, overwrite=True)
    assert run.removed == (folder / "frame_0000.vtu",)


def test_a_sim_run_records_versions_timings_solver_statistics_and_its_summary(tmp_path, capsys):
    from volspring.cli import main
    from volspring.output.run_manifest import RECORDED_PACKAGES

    status = main(["box:0.2,0.05,0.05", "--size", "0.05", "--pin", "xmin", "--duration", "0.05", "--dt", "0.01",
                   "--frame-dt", "0.02", "--out", str(tmp_path / "run"), "--no-progress"])
    out = capsys.readouterr().out
    assert status == 0
    manifest = read_manifest(tmp_path / "run")
    assert manifest["summary"] == out.splitlines()  # what the terminal showed, line for line
    assert manifest["working_directory"] == os.getcwd()
    versions = manifest["versions"]
    assert versions["numpy"] == np.__version__ and set(RECORDED_PACKAGES) <= set(versions)
    assert versions["python"] == ".".join(map(str, sys.version_info[:3]))
    solver = manifest["solver"]
    assert solver["integrator"] == "implicit_euler" and solver["steps"] == 5
    assert solver["frames"] == 3  # t = 0, 0.02, 0.04
    iterations = solver["cg_iterations"]
    assert 1 <= iterations["mean"] <= iterations["max"] and iterations["total"] == round(5 * iterations["mean"])
    assert 1 <= solver["hierarchy_rebuilds"] <= 5  # the first step builds the AMG hierarchy
    timings = manifest["timings"]
    phases = timings["build_seconds"] + timings["stepping_seconds"] + timings["writing_seconds"]
    # The phases are disjoint parts of the run; rounding each to 1 us leaves at most 3 us over.
    assert all(value >= 0 for value in timings.values()) and phases <= timings["wall_seconds"] + 3e-6


def test_an_explicit_run_records_its_steps_without_solves(tmp_path, capsys):
    from volspring.cli import main

    status = main(["box:0.2,0.05,0.05", "--size", "0.05", "--pin", "xmin", "--duration", "1e-4", "--dt", "1e-5",
                   "--frame-dt", "5e-5", "--integrator", "verlet", "--out", str(tmp_path / "run"), "--quiet"])
    assert status == 0
    manifest = read_manifest(tmp_path / "run")
    assert manifest["solver"] == {"integrator": "verlet", "steps": 10, "frames": 3}  # no linear solves to count
    assert len(manifest["summary"]) >= 4 and capsys.readouterr().out == ""  # kept, though --quiet printed none
