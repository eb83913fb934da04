"""Sweep files: a scene plus its values per key path in TOML, the same sweep as the command line's flags.

Checked: the example sweep file reads as written, a sweep file and the equivalent flags give the same table
row for row (every measured value bit for bit), a key path on the command line replaces the file's, and a bad
file is one line naming the key path (exit status 2) before any run.
"""

import csv
from pathlib import Path

import pytest

from volspring.sweep import TIMING_COLUMNS, is_sweep_file, read_sweep_file
from volspring.sweep.cli import main

ROOT = Path(__file__).resolve().parents[1]
TRADE = ROOT / "examples" / "sweeps" / "beam_trade.toml"
BEAM = ROOT / "examples" / "scenes" / "beam.toml"
# The README beam, coarse and short (about 0.1 s a run): 4 runs, 2 rungs x 2 steps, with a probe and 2 draws.
SMALL = f"""
scene = "{BEAM}"
samples = 2
seed = 5
[set]
"bodies[0].size" = 0.1
duration = 0.06
[grid]
"bodies[0].model" = ["springs", "smoothed"]
integrator.dt = [0.02, 0.03]
[random]
"bodies[0].material.E" = [1e6, 4e6]
[probes]
tip = [0.5, 0, 0]
"""
FLAGS = ["--set", "bodies[0].size=0.1", "--set", "duration=0.06", "--grid", "bodies[0].model=springs,smoothed",
         "--grid", "integrator.dt=0.02,0.03", "--random", "bodies[0].material.E=1e6:4e6", "--samples", "2",
         "--seed", "5", "--probe", "tip=0.5,0,0"]


def table(folder):
    with (Path(folder) / "results.csv").open() as file:
        return [{key: value for key, value in row.items() if key not in TIMING_COLUMNS} for row in csv.DictReader(file)]


def test_the_example_sweep_file_reads_as_written():
    sweep = read_sweep_file(TRADE)
    assert sweep.scene.resolve() == (ROOT / "examples" / "scenes" / "beam_vs_fem.toml").resolve()
    assert sweep.grid == {"duration": [1.5], "bodies[0].model": ["springs", "springs+volume", "smoothed"],
                          "integrator.dt": [0.01, 0.02, 0.05]}
    assert sweep.probes == {"tip": [0.5, 0.0, 0.0]} and sweep.random == {} and sweep.seed == 0
    assert is_sweep_file({"scene": "a.toml"}) and not is_sweep_file({"bodies": [], "scene": "x"})


def test_the_readme_shows_the_example_sweep_file():
    import re
    import tomllib

    readme = (ROOT / "README.md").read_text()
    section = readme[readme.index("## Sweeps"):]
    block, = re.findall(r"```toml\n(.*?)```", section[:section.index("\n## ", 1)], flags=re.S)
    shown, example = tomllib.loads(block), tomllib.loads(TRADE.read_text())
    assert shown == {key: value for key, value in example.items() if key != "description"}


def test_a_sweep_file_is_the_same_sweep_as_its_flags(tmp_path, capsys):
    (tmp_path / "small.toml").write_text(SMALL)
    assert main([tmp_path / "small.toml", "--workers", "0", "--out", tmp_path / "file", "--quiet"]) == 0
    assert main([BEAM, *FLAGS, "--workers", "0", "--out", tmp_path / "flags", "--quiet"]) == 0
    from_file, from_flags = table(tmp_path / "file"), table(tmp_path / "flags")
    assert len(from_file) == 8 and all(row["status"] == "done" for row in from_file)  # 2 x 2 x 2 draws
    assert from_file == from_flags  # the same run ids, parameters and measured values, bit for bit


def test_dotted_keys_and_inline_tables_in_set_name_key_paths(tmp_path):
    # [set] integrator.dt = 0.05 sets the step, not the whole integrator table to {dt = 0.05}.
    (tmp_path / "f.toml").write_text(f'scene = "{BEAM}"\n[set]\nintegrator.dt = 0.05\n'
                                     '"bodies[0].material" = {E = 2e6}\n[grid]\nduration = [0.1]\n')
    assert read_sweep_file(tmp_path / "f.toml").grid == {"integrator.dt": [0.05], "bodies[0].material.E": [2e6],
                                                         "duration": [0.1]}


def test_the_command_line_replaces_the_file_s_values_of_a_key_path(tmp_path, capsys):
    (tmp_path / "small.toml").write_text(SMALL)
    argv = [tmp_path / "small.toml", "--grid", "integrator.dt=0.03", "--random", "bodies[0].material.E=2e6:3e6",
            "--seed", "9", "--workers", "0", "--out", tmp_path / "out", "--quiet"]
    assert main(argv) == 0
    rows = table(tmp_path / "out")
    assert len(rows) == 4 and {row["integrator.dt"] for row in rows} == {"0.03"}
    assert all(2e6 <= float(row["bodies[0].material.E"]) < 3e6 for row in rows)


@pytest.mark.parametrize("text, message", [
    ('scene = "beam.toml"\nsamlpes = 2\n', "samlpes is not a known key; did you mean samples?"),
    ('[grid]\nduration = [0.1]\n', "scene is missing or not a string; expected the scene file it sweeps"),
    ('scene = "beam.toml"\n[grid]\n"bodies[0].model" = "springs"\n',
     'grid."bodies[0].model" = \'springs\' is not a list of values; expected [v1, v2, ...]'),
    ('scene = "beam.toml"\n[random]\nduration = [1]\n', "random.duration = [1] is not a range; expected [low, high]"),
    ('scene = "beam.toml"\n[set]\nduration = 1\n[grid]\nduration = [1, 2]\n', "grid.duration is also in [set]"),
    ('scene = "beam.toml"\n[probes]\ntip = [1, 2]\n', "probes.tip = [1, 2] is not a point"),
    ('scene = "beam.toml"\nseed = 1.5\n', "seed = 1.5 is not a whole number"),
    ('scene = "beam.toml"\ngrid = 3\n', "grid is int; expected a table ([grid])"),
])
def test_a_bad_sweep_file_is_one_line_naming_the_key_path(tmp_path, capsys, text, message):
    (tmp_path / "bad.toml").write_text(text)
    assert main([tmp_path / "bad.toml", "--workers", "0", "--out", tmp_path / "out"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("volspring-sweep: error: ") and message in err and err.count("\n") == 1, err
    assert not (tmp_path / "out" / "results.csv").exists()


def test_frequencies_are_measured_and_scale_as_the_square_root_of_stiffness(tmp_path):
    from volspring.modes import solve_modes
    from volspring.scene_file import assemble_scene, read_scene
    from volspring.sweep import run_sweep

    grid = {"bodies[0].size": [0.1], "duration": [0.02], "integrator.dt": [0.02], "bodies[0].material.E": [1e6, 4e6]}
    result = run_sweep(BEAM, grid, tmp_path, frequencies=2)
    soft, stiff = (record["measured"] for record in result.records)
    # K is linear in E and M does not depend on it: omega goes as sqrt(E), so 4 E doubles every frequency (to
    # round-off of the eigensolver, ~1e-12 relative on this 100-dof dense problem).
    assert stiff["frequency_1_hz"] / soft["frequency_1_hz"] == pytest.approx(2.0, rel=1e-9)
    assert stiff["frequency_2_hz"] / soft["frequency_2_hz"] == pytest.approx(2.0, rel=1e-9)
    # The same numbers as solve_modes on the scene at rest, bit for bit.
    scene = read_scene(BEAM, overrides=["bodies[0].size=0.1", "bodies[0].material.E=1e6"])
    direct = solve_modes(assemble_scene(scene, base=BEAM.parent).scene, count=2).frequencies
    assert [soft["frequency_1_hz"], soft["frequency_2_hz"]] == direct.tolist()
    # The sweep file's key, as the flag.
    (tmp_path / "f.toml").write_text(f'scene = "{BEAM}"\nfrequencies = 3\n[grid]\nduration = [0.0]\n')
    assert read_sweep_file(tmp_path / "f.toml").frequencies == 3
