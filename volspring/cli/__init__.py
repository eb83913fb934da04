"""``volspring sim``: a minimal simulation from the command line.

A mesh file (any volume format meshio reads), a spring topology file from ``volspring-mesh``
(``NAME.vstopo.npz``: the tet mesh with its shells, which the model then has) or a built-in shape
(``box:1,0.1,0.1``), a rung of the model ladder (``--model springs``, ``springs+volume`` or ``smoothed``,
:mod:`volspring.ladder`), a material (and one per region tag of the mesh file, ``--region-material``), pins by regions (``--pin xmin``, ``--pin "x<0.01"``,
``--pin XMIN,YMIN,ZMIN,XMAX,YMAX,ZMAX``: :func:`volspring.regions.parse_region`), gravity, an integrator and a step; frames written as a
ParaView series (and optionally a Blender surface cache), checkpoints to resume from, progress on
stderr (tqdm) and a summary on stdout. A scene file (``volspring-sim scene.toml``, :mod:`volspring.scene_file`)
writes down several bodies, supports, fields, obstacles, contact, the integrator and the outputs; the flags
given override its values, and ``--set KEY.PATH=VALUE`` any of them.

Exit status, as every volspring command (:mod:`meshing._command_line`): 0 done, 1 the run failed while
stepping or writing, 2 a bad command line or bad input found before the first step (each one
``volspring-sim: error: ...`` line on stderr), 3 the simulation diverged (the output folder then holds
only the complete frames before it), 130 Ctrl-C and 143 SIGTERM (129 SIGHUP): one line saying where
the run stopped, its last checkpoint and the command that resumes it; no traceback, no temporary file.
``volspring sim`` is the same command (:mod:`volspring.command`).

The command reads in one direction, one module a step: :mod:`~volspring.cli._arguments` (the
options and their checks) -> :mod:`~volspring.cli._build` (mesh, model, scene) ->
:mod:`~volspring.cli._run` (output folder, stepping, frames, checkpoints) ->
:mod:`~volspring.cli._terminal` (progress bar, summary, one-line errors).

Examples
--------
>>> import tempfile
>>> from volspring.cli import main
>>> main(["box:0.2,0.05,0.05", "--size", "0.05", "--pin", "-0.1,-1,-1,-0.1,1,1",
...       "--duration", "0.01", "--dt", "0.005", "--out", tempfile.mkdtemp(), "--quiet"])
0
>>> main(["box:0.2,0.05,0.05", "--size", "0.05", "--pin", "xmin", "--duration", "0.01", "--quiet"])
0
>>> main(["box:0.2,0.05,0.05", "--size", "0.05", "--pin", "xmin", "--duration", "0.01", "--quiet",
...       "--model", "smoothed", "--nu", "0.49"])
0
"""

from volspring.cli._arguments import build_parser
from volspring.cli._run import main

__all__ = ["main", "build_parser"]
