"""Blender's import script: what the writer generates (plain tests), and what Blender makes of it (bpy tests).

"Right axes": volspring's coordinates are Blender's world coordinates unchanged (both right-handed, z up,
metres), so the imported object's transform is the identity and its evaluated vertices at a frame equal
the written positions; gravity (0, 0, -g) points down Blender's -Z. Blender's default OBJ import (made
for y-up files) instead rotates the object 90 degrees about X: the negative control below shows the sag
going along +Y then.
"""

import importlib.util
import json
import runpy
import shutil
import subprocess
import sys

import numpy as np
import pytest

from volspring import Gravity, Material, Model, Pins, Scene
from volspring.output import BlenderWriter, BoundarySurface, read_pc2
from volspring.output.blender_import import (blender_frame_rate, import_script, import_script_path,
                                             write_import_script)
from volspring.simulate import simulate

from conftest import cube_mesh

FRAME_DT = 0.02  # 50 frames per second
NEEDS_BPY = "needs the blender extra: pip install volspring[blender]"


@pytest.fixture(scope="module")
def beam():
    """A 0.4 m beam along x, clamped at x = 0, sagging under gravity: (model, scene, surface)."""
    mesh = cube_mesh((4, 1, 1), size=(0.4, 0.1, 0.1))
    model = Model.from_mesh(mesh, Material(E=1e5, nu=0.3, density=1000.0), damping_ratio=0.02)
    scene = Scene(model, forces=[Gravity()], pins=Pins(np.flatnonzero(mesh.points[:, 0] == 0.0)))
    return model, scene, BoundarySurface.from_mesh(model)


def run_beam(folder, beam, *, duration=0.2, name="surface", **options):
    """Simulate the beam from rest into ``folder``; the writer and the states of its frames."""
    model, scene, surface = beam
    writer = BlenderWriter(folder, model, name=name, frame_dt=FRAME_DT, **options)
    frames = []
    simulate(scene, "implicit_euler", duration=duration, dt=0.01, frame_dt=FRAME_DT,
             callback=lambda k, state: (frames.append(state), writer(k, state)))
    return writer, frames


def script_namespace(path):
    """The script's constants and functions, without running its ``main`` (which needs bpy)."""
    return runpy.run_path(str(path), run_name="volspring_test")


# ---------------------------------------------------------------------- the script, without Blender
def test_the_script_opens_the_files_beside_it_at_the_runs_frame_rate(tmp_path, beam):
    writer, frames = run_beam(tmp_path / "beam", beam)
    script = writer.import_script_path
    assert script == tmp_path / "beam" / "surface_blender.py" and len(frames) == 11
    text = script.read_text()
    assert str(tmp_path) not in text  # file names only: the folder can move
    space = script_namespace(script)
    assert (space["OBJ_FILE"], space["PC2_FILE"], space["NAME"]) == ("surface_0000.obj", "surface.pc2", "surface")
    assert (space["FPS"], space["FPS_BASE"], space["FIRST_FRAME"]) == (50, 1.0, 1)
    assert (space["FORWARD_AXIS"], space["UP_AXIS"]) == ("Y", "Z")  # Blender's axes = volspring's
    assert space["script_folder"]() == script.parent
    header = space["read_cache_header"](writer.pc2_path)
    assert header == (beam[2].point_count, 11)
    assert space["frame_range"](header[1]) == (1, 11)  # frame 1 is the first sample, frame 11 the last

    # Moved elsewhere, the folder still opens: the script finds its files beside itself.
    moved = shutil.copytree(tmp_path / "beam", tmp_path / "elsewhere" / "beam")
    assert script_namespace(moved / script.name)["script_folder"]() == moved


def test_the_frame_range_follows_the_cache_as_the_run_goes_on(tmp_path, beam):
    model = beam[0]
    first, frames = run_beam(tmp_path, beam, duration=0.04)
    assert len(frames) == 3
    space = script_namespace(first.import_script_path)
    assert space["frame_range"](space["read_cache_header"](first.pc2_path)[1]) == (1, 3)
    # Resumed (as volspring-sim --resume does): the same script now shows all five frames.
    again = BlenderWriter(tmp_path, model, name="surface", frame_dt=FRAME_DT, first_frame=3)
    for state in frames[:2]:
        again.write(state)
    assert space["frame_range"](space["read_cache_header"](first.pc2_path)[1]) == (1, 5)
    with pytest.raises(ValueError, match="holds 0 frames"):
        space["frame_range"](0)


def test_the_script_is_announced_with_the_first_frame_only(tmp_path, beam):
    model, scene, _ = beam
    announced = []
    writer = BlenderWriter(tmp_path, model, frame_dt=FRAME_DT, record=lambda *paths: announced.append(
        [(path.name, path.exists()) for path in paths]))
    state = scene.initial_state()
    writer.write(state)
    writer.write(state)
    assert announced == [[("frame_0000.obj", False), ("frame.pc2", False), ("frame_blender.py", False)],
                         [("frame_0001.obj", False), ("frame.pc2", True)]]
    # Without frame_dt there is no frame rate to set: no script, and the files are as before.
    plain = BlenderWriter(tmp_path / "plain", model)
    plain.write(state)
    assert plain.import_script_path is None and sorted(p.name for p in plain.directory.iterdir()) == [
        "frame.pc2", "frame_0000.obj"]


@pytest.mark.parametrize("frame_dt, fps, fps_base", [
    (0.04, 25, 1.0), (1 / 30, 30, 1.0), (0.01, 100, 1.0), (0.003, 333, 0.999), (2.0, 1, 2.0), (1e-6, 32767, 0.032767)])
def test_the_frame_rate_is_one_frame_per_frame_step(frame_dt, fps, fps_base):
    got = blender_frame_rate(frame_dt)
    assert got[0] == fps
    # A few ulp (1e-15 is 4.5): fps_base is one product fps * frame_dt, compared with a decimal literal.
    assert got[1] == pytest.approx(fps_base, rel=1e-15)
    assert got[0] / got[1] == pytest.approx(1 / frame_dt, rel=1e-15)


@pytest.mark.parametrize("frame_dt, message", [(0.0, "not a finite number > 0"), (float("nan"), "not a finite"),
                                               (1e-12, "outside"), (1e7, "outside")])
def test_a_frame_step_blender_cannot_express_is_refused(tmp_path, beam, frame_dt, message):
    with pytest.raises(ValueError, match=f"frame_dt = .* s is {message}"):
        BlenderWriter(tmp_path, beam[0], frame_dt=frame_dt)
    assert list(tmp_path.iterdir()) == []  # refused before any file


def test_the_script_needs_both_files(tmp_path, beam):
    with pytest.raises(ValueError, match="needs both the OBJ and the PC2 .got obj=True, pc2=False"):
        BlenderWriter(tmp_path, beam[0], pc2=False, frame_dt=FRAME_DT)
    with pytest.raises(ValueError, match="name = 'a/b' must be"):
        import_script(name="a/b", frame_dt=FRAME_DT)
    # For a folder written without a script: the same text, written on its own.
    assert (write_import_script(tmp_path, name="surface", frame_dt=FRAME_DT).read_text()
            == import_script(name="surface", frame_dt=FRAME_DT))
    assert import_script_path(tmp_path, "surface").is_file()


# ---------------------------------------------------------------------- the script in Blender (bpy)
# Runs in a child Python that imports bpy (Blender as a module: one Blender per process), the way a
# user runs it: `blender --python SCRIPT` (runpy, __file__ the script), then from the Scripting tab
# (a text loaded from the file and run by text.run_script, where __file__ is "/<text name>"), then
# with Blender's default OBJ axes as the negative control. Each in a fresh startup file.
DRIVER = r'''
import json, runpy, sys
import bpy

script, out, name = sys.argv[1], sys.argv[2], sys.argv[3]
frames = [int(word) for word in sys.argv[4].split(",")]


def fresh():
    bpy.ops.wm.read_homefile(use_factory_startup=True)  # the startup file: Cube, Camera, Light


def observe():
    scene = bpy.context.scene
    body = bpy.data.objects[name]
    seen = {"objects": sorted(bpy.data.objects.keys()), "fps": scene.render.fps, "fps_base": scene.render.fps_base,
            "frame_start": scene.frame_start, "frame_end": scene.frame_end, "frame_current": scene.frame_current,
            "matrix_world": [list(row) for row in body.matrix_world], "world": {}}
    for frame in frames:
        scene.frame_set(frame)
        evaluated = body.evaluated_get(bpy.context.evaluated_depsgraph_get())
        seen["world"][frame] = [list(evaluated.matrix_world @ vertex.co) for vertex in evaluated.data.vertices]
    return seen


seen = {}
fresh()
runpy.run_path(script, run_name="__main__")
runpy.run_path(script, run_name="__main__")  # twice: the second run replaces the first import
seen["python"] = observe()

fresh()
text = bpy.data.texts.load(script)
with bpy.context.temp_override(edit_text=text):
    assert bpy.ops.text.run_script() == {"FINISHED"}
seen["text"] = observe()

fresh()
space = runpy.run_path(script, run_name="volspring_test")
space["main"].__globals__.update(FORWARD_AXIS="NEGATIVE_Z", UP_AXIS="Y")  # Blender's default OBJ axes
space["main"]()
seen["default_axes"] = observe()

with open(out, "w") as file:
    json.dump(seen, file)
'''


@pytest.mark.blender
@pytest.mark.skipif(importlib.util.find_spec("bpy") is None, reason=NEEDS_BPY)
def test_blender_shows_the_written_frames_upright_at_the_runs_frame_rate(tmp_path, beam):
    model, _, surface = beam
    writer, frames = run_beam(tmp_path / "beam", beam)
    samples, _, _ = read_pc2(writer.pc2_path)
    count = len(frames)
    checked = [1, 2, 6, count]
    driver = tmp_path / "driver.py"
    driver.write_text(DRIVER)
    child = subprocess.run([sys.executable, str(driver), str(writer.import_script_path), str(tmp_path / "seen.json"),
                            "surface", ",".join(map(str, checked))],
                           cwd=tmp_path, capture_output=True, text=True, timeout=600)
    assert child.returncode == 0, child.stderr[-3000:]
    seen = json.loads((tmp_path / "seen.json").read_text())

    fps, fps_base = blender_frame_rate(FRAME_DT)
    for mode in ("python", "text"):
        got = seen[mode]
        # One body, no startup cube, no second copy from running the script twice.
        assert got["objects"] == ["Camera", "Light", "surface"], mode
        assert np.array_equal(got["matrix_world"], np.eye(4)), mode  # volspring's axes are Blender's
        assert (got["fps"], got["fps_base"]) == (fps, np.float32(fps_base)), mode  # Blender keeps fps_base float32
        assert (got["frame_start"], got["frame_end"], got["frame_current"]) == (1, count, 1), mode
        for frame in checked:
            world = np.array(got["world"][str(frame)])
            # The PC2's float32 samples, bit for bit: frame f shows sample f - 1.
            assert np.array_equal(world, samples[frame - 1]), (mode, frame)
            # The simulated positions, within float32 rounding (half an ulp of 0.4 m is 1.5e-8 m).
            np.testing.assert_allclose(world, surface.deform(frames[frame - 1].x), rtol=0, atol=3e-8)
        rest = np.array(got["world"]["1"])
        np.testing.assert_allclose(rest, surface.deform(model.rest_positions), rtol=0, atol=3e-8)  # frame 1: rest

    # Gravity points down Blender's -Z: the beam's centroid moves mostly along -Z (some 9 cm; the one-cell
    # Kuhn split is not symmetric in y, so the beam also twists by about a centimetre).
    upright = np.array(seen["python"]["world"][str(count)]) - np.array(seen["python"]["world"]["1"])
    sag = upright.mean(axis=0)
    assert np.argmax(abs(sag)) == 2 and sag[2] < -0.01, sag
    # Negative control, Blender's default OBJ axes: the object turned 90 degrees about X, the sag along +Y.
    turned = seen["default_axes"]
    np.testing.assert_allclose(turned["matrix_world"], [[1, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]],
                               atol=1e-7)  # cos(pi / 2) in float32
    sideways = (np.array(turned["world"][str(count)]) - np.array(turned["world"]["1"])).mean(axis=0)
    assert np.argmax(abs(sideways)) == 1 and sideways[1] > 0.01, sideways
    # float32 rounding of coordinates below 0.5 m, and of the rotation's cos(pi / 2) = -4.4e-8.
    np.testing.assert_allclose(sideways, [sag[0], -sag[2], sag[1]], rtol=0, atol=1e-7)
