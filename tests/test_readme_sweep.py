"""The README's sweep section runs as written: every command of its shell blocks, in order, from a fresh folder.

The commands are taken from the README itself (a line ending in a backslash goes on), run with the example scenes
in reach as the README assumes (a clone's ``examples/`` beside them), and each must exit 0 and write what the
README says it writes. The cluster commands run too: ``dask scheduler`` on a free port instead of 8786 (the only
change: the address), one ``dask worker`` process, then the sweep with ``--scheduler``.
"""

import csv
import os
import re
import shlex
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
BIN = Path(sys.executable).parent
# Seconds a command may take on 2 busy cores before the test gives up on it (the slowest, the 9-run trade sweep
# on a local cluster, takes about 15 s [measured]); a hang, not a slow machine, is what this catches.
COMMAND_TIMEOUT = 300


def sweep_commands() -> list:
    """The commands of the shell blocks of the README's "## Sweeps" section, continuation lines joined."""
    text = README.read_text()
    section = text[text.index("## Sweeps"):]
    section = section[:section.index("\n## ", 1)]
    commands = []
    for block in re.findall(r"```bash\n(.*?)```", section, flags=re.S):
        for line in block.replace("\\\n", " ").splitlines():
            command = line.split("  #")[0].strip()
            if command:
                commands.append(command)
    return commands


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def test_the_readme_names_the_commands_this_test_runs():
    programs = [shlex.split(command)[0] for command in sweep_commands()]
    assert programs.count("volspring") >= 4 and "dask" in programs, programs


@pytest.mark.slow
def test_the_readme_sweep_section_runs_as_written(tmp_path):
    (tmp_path / "examples").symlink_to(ROOT / "examples")
    port = free_port()
    environment = {**os.environ, "PATH": f"{BIN}{os.pathsep}{os.environ['PATH']}",
                   "VOLSPRING_CACHE": str(tmp_path / "fem"), "OMP_NUM_THREADS": "1"}
    background = []
    try:
        for command in sweep_commands():
            command = command.replace("tcp://HOST:8786", f"tcp://127.0.0.1:{port}")
            words = shlex.split(command)
            if words[:2] == ["dask", "scheduler"]:
                words += ["--host", "127.0.0.1", "--port", str(port), "--no-dashboard"]
            if words[0] == "dask" or words[0].startswith("OMP_NUM_THREADS="):
                words = [word for word in words if not word.startswith("OMP_NUM_THREADS=")]
                if "--nworkers" in words:  # one worker process on this machine, not eight
                    words[words.index("--nworkers") + 1] = "1"
                background.append(subprocess.Popen(words, cwd=tmp_path, env=environment, stdout=subprocess.DEVNULL,
                                                   stderr=subprocess.DEVNULL))
                time.sleep(3 if words[1] == "scheduler" else 5)  # the scheduler listening, the worker joined
                continue
            done = subprocess.run(words, cwd=tmp_path, env=environment, capture_output=True, text=True,
                                  timeout=COMMAND_TIMEOUT)
            assert done.returncode == 0, f"{command}\n{done.stderr}"
    finally:
        for process in reversed(background):
            process.terminate()
            process.wait(timeout=30)
    for folder, runs in (("beam_sweep", 9), ("beam_random", 24), ("beam_cluster", 2), ("beam_trade", 9)):
        with (tmp_path / folder / "results.csv").open() as file:
            rows = list(csv.DictReader(file))
        assert len(rows) == runs and all(row["status"] == "done" for row in rows), folder
    assert (tmp_path / "trade-report" / "report.html").is_file()
