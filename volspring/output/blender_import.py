"""Blender's import script: one command opens a Blender output folder as an animated scene.

:class:`~volspring.output.BlenderWriter` given ``frame_dt`` writes ``NAME_blender.py`` beside
``NAME_0000.obj`` and ``NAME.pc2``; the user runs ::

    blender --python beam/surface_blender.py

(or opens it in Blender's Scripting tab and presses Run Script). The script is plain text from
:data:`TEMPLATE`, holding file names only: it finds the files beside itself, so the folder can be
moved or copied to another machine. It

- imports the OBJ with Forward = Y, Up = Z. volspring's coordinates are Blender's (right-handed,
  z up, metres), so the right axes are no change at all: a point (x, y, z) is Blender's (X, Y, Z)
  and the object's transform is the identity. Blender's default OBJ axes (Forward -Z, Up Y, for
  the y-up files most tools write) put a 90 degree turn about X into the object's rotation: the
  body lies on its side and gravity points along +Y;
- adds a Mesh Cache modifier reading the PC2 (its default axes, Forward Y and Up Z, also leave
  the points as written) with ``frame_start = 1``: Blender shows sample ``frame - 1`` at a frame,
  so frame 1 is the first frame written (the rest shape of a run from rest);
- sets the scene's frame rate to one frame per ``frame_dt`` (:func:`blender_frame_rate`) and its
  frame range to 1 .. the number of samples, read from the PC2 header when the script runs (a run
  still going, stopped early or resumed shows the frames written so far);
- replaces an earlier import of the same cache, and in a new unsaved file removes the startup cube
  (a 2 m cube at the origin that hides a body of about a metre).

The PC2 header's own start frame and sample rate are not used: Blender's Mesh Cache in its
``FRAME`` time mode reads sample ``frame * frame_scale - frame_start`` whatever they say.

Examples
--------
>>> import tempfile
>>> from volspring.output.blender_import import write_import_script
>>> path = write_import_script(tempfile.mkdtemp(), name="surface", frame_dt=0.04)
>>> path.name
'surface_blender.py'
>>> "FPS, FPS_BASE = 25, 1.0" in path.read_text()
True
"""

from __future__ import annotations

import math
from pathlib import Path
from string import Template

from meshing._io import atomic_path
import os

__all__ = ["TEMPLATE", "blender_frame_rate", "import_script", "import_script_path", "write_import_script"]

#: Blender's limits on ``scene.render.fps`` (int) and ``scene.render.fps_base`` (float).
FPS_RANGE = (1, 32767)
FPS_BASE_RANGE = (1e-5, 1e6)

#: The import script; ``$``-placeholders are filled by :func:`import_script`.
TEMPLATE = Template('''\
"""Open volspring's Blender output ${obj_file} + ${pc2_file} as an animated scene.

Run it as

    blender --python ${script_file}

from any folder (the files are found beside this script), or open it in Blender's Scripting
tab (Text > Open) and press Run Script. Written by volspring ${version}; checked with Blender
4.2 and 5.0.

- ${obj_file} is imported with Forward = Y, Up = Z: volspring's coordinates are Blender's
  (z up, metres), so a point (x, y, z) is Blender's (X, Y, Z) and the object has no rotation.
  (Blender's default OBJ axes, made for y-up files, would lay the body on its side.)
- A Mesh Cache modifier reads ${pc2_file}: Blender frame 1 is the first frame written (the
  rest shape of a run from rest), frame k the k-th.
- The scene runs at ${fps_text} fps, one frame per ${frame_dt} s as simulated, over frames 1 to
  the number of frames in the cache (read from its header now, so a run still going or stopped
  early shows the frames written so far).
- An earlier import of this cache is replaced; in a new unsaved file the startup cube is removed.
"""

import struct
from pathlib import Path

NAME = ${name}
OBJ_FILE = ${obj_file_literal}
PC2_FILE = ${pc2_file_literal}
FRAME_DT = ${frame_dt}  # time between frames [s]
FPS, FPS_BASE = ${fps}, ${fps_base}  # Blender's frame rate is FPS / FPS_BASE = 1 / FRAME_DT
FIRST_FRAME = 1  # the Blender frame showing the cache's first sample
FORWARD_AXIS, UP_AXIS = "Y", "Z"  # the OBJ import's axes that keep x, y, z as they are
# magic, file version, point count, start frame, sample rate, sample count
PC2_HEADER = struct.Struct("<12siiffi")


def script_folder():
    """The folder holding this script (and the files it opens)."""
    here = Path(__file__)
    if here.is_file():  # blender --python FILE
        return here.resolve().parent
    import bpy

    # The Scripting tab sets __file__ to "<blend file>/<text name>"; the text knows its file.
    text = bpy.data.texts.get(here.name)
    if text is not None and text.filepath:
        return Path(bpy.path.abspath(text.filepath)).resolve().parent
    raise FileNotFoundError(f"cannot tell which folder {here.name} is in: run it as "
                            f"`blender --python path/to/{here.name}`, or open it with Text > Open")


def read_cache_header(pc2_path):
    """(point count, sample count) of a PC2 point cache."""
    with open(pc2_path, "rb") as file:
        header = file.read(PC2_HEADER.size)
    if len(header) < PC2_HEADER.size or not header.startswith(b"POINTCACHE2\\0"):
        raise ValueError(f"{pc2_path} is not a PC2 point cache (it starts with {header[:12]!r})")
    _, _, point_count, _, _, sample_count = PC2_HEADER.unpack(header)
    return point_count, sample_count


def frame_range(sample_count):
    """(first, last) scene frame showing the samples of a cache holding ``sample_count``."""
    if sample_count < 1:
        raise ValueError(f"{PC2_FILE} holds {sample_count} frames: the run wrote none yet")
    return FIRST_FRAME, FIRST_FRAME + sample_count - 1


def main():
    import bpy

    folder = script_folder()
    obj_path, pc2_path = folder / OBJ_FILE, folder / PC2_FILE
    for path in (obj_path, pc2_path):
        if not path.is_file():
            raise FileNotFoundError(f"{path} is missing: this script opens the files volspring wrote beside it")
    point_count, sample_count = read_cache_header(pc2_path)
    first, last = frame_range(sample_count)

    cube = bpy.data.objects.get("Cube")
    if not bpy.data.filepath and cube is not None and cube.type == "MESH" and len(cube.data.vertices) == 8:
        bpy.data.objects.remove(cube)  # the startup cube would hide a body at the origin
    for old in [item for item in bpy.data.objects if item.get("volspring_cache") == str(pc2_path)]:
        bpy.data.objects.remove(old)  # running the script again replaces its import

    before = set(bpy.data.objects.keys())
    bpy.ops.wm.obj_import(filepath=str(obj_path), forward_axis=FORWARD_AXIS, up_axis=UP_AXIS)
    new = [item for item in bpy.data.objects if item.name not in before]
    if len(new) != 1:
        raise RuntimeError(f"importing {obj_path} made {len(new)} objects, expected 1")
    body = new[0]
    if len(body.data.vertices) != point_count:
        raise ValueError(f"{OBJ_FILE} has {len(body.data.vertices)} vertices but {PC2_FILE} holds "
                         f"{point_count} points per frame: they are not from the same run")
    body.name = NAME
    body["volspring_cache"] = str(pc2_path)

    cache = body.modifiers.new("volspring cache", "MESH_CACHE")
    cache.cache_format = "PC2"
    cache.filepath = str(pc2_path)
    cache.time_mode, cache.play_mode = "FRAME", "SCENE"
    # At scene frame f the modifier reads sample f * frame_scale - frame_start: frame 1 shows sample 0.
    cache.frame_scale, cache.frame_start = 1.0, float(FIRST_FRAME)
    cache.forward_axis, cache.up_axis = "POS_Y", "POS_Z"  # the points as written, like the OBJ's

    scene = bpy.context.scene
    scene.render.fps, scene.render.fps_base = FPS, FPS_BASE
    scene.frame_start, scene.frame_end = first, last
    scene.frame_set(first)
    bpy.context.view_layer.objects.active = body
    body.select_set(True)
    print(f"volspring: {body.name} from {obj_path} with {PC2_FILE}: frames {first} to {last} at "
          f"{FPS / FPS_BASE:.6g} fps")


if __name__ == "__main__":
    main()
''')


def import_script_path(directory: str | os.PathLike[str], name: str) -> Path:
    """The import script of the Blender output ``name`` in ``directory``: ``NAME_blender.py``."""
    return Path(directory) / f"{name}_blender.py"


def blender_frame_rate(frame_dt: float) -> tuple:
    """Blender's frame rate for one frame every ``frame_dt`` seconds.

    Blender stores the rate as a whole number ``fps`` over a factor ``fps_base``; the whole number
    nearest to ``1 / frame_dt`` keeps ``fps_base`` near 1 (exactly 1 for 25, 30 or 100 frames per
    second, which Blender then names as presets).

    Parameters
    ----------
    frame_dt : float
        Time between frames [s], > 0.

    Returns
    -------
    fps : int
        ``scene.render.fps``, in [1, 32767].
    fps_base : float
        ``scene.render.fps_base``, so that ``fps / fps_base = 1 / frame_dt``.

    Examples
    --------
    >>> blender_frame_rate(0.04), blender_frame_rate(0.003), blender_frame_rate(2.0)
    ((25, 1.0), (333, 0.999), (1, 2.0))
    """
    frame_dt = float(frame_dt)
    if not (math.isfinite(frame_dt) and frame_dt > 0):
        raise ValueError(f"frame_dt = {frame_dt!r} s is not a finite number > 0")
    fps = min(max(round(1.0 / frame_dt), FPS_RANGE[0]), FPS_RANGE[1])
    fps_base = fps * frame_dt
    if not FPS_BASE_RANGE[0] <= fps_base <= FPS_BASE_RANGE[1]:
        shortest = FPS_BASE_RANGE[0] / FPS_RANGE[1]
        raise ValueError(f"frame_dt = {frame_dt!r} s is outside [{shortest:.3g}, {FPS_BASE_RANGE[1]:.0g}] s, "
                         f"the frame steps Blender's frame rate (fps in {list(FPS_RANGE)}, fps_base in "
                         f"{list(FPS_BASE_RANGE)}) can express")
    return fps, fps_base


def import_script(*, name: str, frame_dt: float) -> str:
    """The text of the import script for the Blender output ``name`` (see the module docstring).

    Parameters
    ----------
    name : str
        File name prefix of the output: the script opens ``NAME_0000.obj`` and ``NAME.pc2``.
    frame_dt : float
        Time between frames [s], > 0: the scene's frame rate is its inverse.

    Returns
    -------
    str
        Python source for Blender, holding file names relative to its own folder.
    """
    from volspring import __version__

    name = str(name)
    if not name or "/" in name or "\\" in name:
        raise ValueError(f"name = {name!r} must be a non-empty file name prefix without path separators")
    fps, fps_base = blender_frame_rate(frame_dt)
    obj_file, pc2_file = f"{name}_0000.obj", f"{name}.pc2"
    return TEMPLATE.substitute(
        name=repr(name), obj_file=obj_file, pc2_file=pc2_file, obj_file_literal=repr(obj_file),
        pc2_file_literal=repr(pc2_file), script_file=import_script_path("", name).name, version=__version__,
        frame_dt=repr(float(frame_dt)), fps=fps, fps_base=repr(fps_base), fps_text=f"{fps / fps_base:.6g}")


def write_import_script(directory: str | os.PathLike[str], *, name: str = "frame", frame_dt: float) -> Path:
    """Write the import script beside the Blender output ``name`` in ``directory``, atomically.

    Also for a folder written without one: the script reads the frame count from the cache when
    it runs, so only the frame step must be known.

    Parameters
    ----------
    directory : path-like
        The folder of ``NAME_0000.obj`` and ``NAME.pc2``.
    name : str
        Their file name prefix.
    frame_dt : float
        Time between frames [s], > 0.

    Returns
    -------
    Path
        ``directory / NAME_blender.py``.
    """
    path = import_script_path(directory, name)
    text = import_script(name=name, frame_dt=frame_dt)
    with atomic_path(path) as tmp:
        tmp.write_text(text)
    return path
