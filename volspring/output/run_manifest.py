"""Run manifests: the ``volspring-run.json`` a run folder holds, listing every file its run wrote.

A :class:`volspring.output.RunFolder` writes the manifest (the rules are in
:mod:`volspring.output.run_folder`); :func:`read_manifest` reads and checks one. A run whose manifest
says "running" but whose process is gone counts as "interrupted".

Manifest layout (JSON)::

    {"format": "volspring-run", "version": 1,
     "command": ["volspring-sim", "bunny.mesh", "--out", "run"],   # argv of the run
     "started": "2025-01-31T09:12:44+00:00", "ended": null,          # UTC, ISO 8601
     "status": "running",            # running | finished | interrupted | failed
     "pid": 4711, "host": "lab-3", "volspring": "0.4.0",
     "earlier": [],                  # the sessions a resumed run continues: command, started, ended, status
     "files": ["frame.pvd", "frame_0000.vtu", ...]}                # relative to the folder, POSIX separators

A run may add entries of its own (:meth:`RunFolder.note <volspring.output.RunFolder.note>`). ``volspring sim``
adds, so that any output folder says how it was made and can be made again::

     "working_directory": "/home/me/sims",   # where the command ran: its relative paths start here
     "versions": {"python": "3.11.9", "platform": "Linux-6.8-x86_64-with-glibc2.39", "volspring": "0.1.0",
                  "numpy": "1.26.4", "scipy": "1.13.1", "pyamg": "5.2.1", "meshio": "5.3.5",
                  "gmsh": "4.13.1", "trimesh": "4.4.3", ...},        # None: not installed
     "scene": {...},                 # a scene file's run: the scene resolved, every default filled in
     "model": {"rung": "smoothed", "alpha": 0.6, "E": ..., "nu": ..., ...},
     "solver": {"integrator": "implicit_euler", "steps": 100, "frames": 26,
                "cg_iterations": {"mean": 4.2, "max": 9, "total": 420}, "hierarchy_rebuilds": 3,
                "seconds": {"forces": 0.2, "assembly": 0.1, "setup": 0.05, "solve": 0.3}},   # [s]
     "timings": {"wall_seconds": 2.1, "build_seconds": 0.4, "stepping_seconds": 1.5,
                 "writing_seconds": 0.2},    # [s]: stepping excludes the frames' writing
     "summary": ["body: ...", "run: ...", "end: ...", "output: ..."]   # the lines printed on stdout

``versions`` and ``working_directory`` are written when the run starts, ``solver`` when the stepping ends
(also when it diverged), ``timings`` and ``summary`` when it finished. They are entries of the run, not
of the layout: manifests of older runs lack them, and :func:`read_manifest` does not require them. To make
a run again, run its ``command`` in its ``working_directory`` with ``--overwrite`` (or another ``--out``):
the frames are the same, byte for byte, with the same ``versions`` on the same platform.
"""

from __future__ import annotations

import datetime
import json
import os
import platform
import shlex
import socket
from importlib import metadata
from pathlib import Path
from collections.abc import Sequence

__all__ = ["MANIFEST_NAME", "RECORDED_PACKAGES", "package_versions", "read_manifest"]

MANIFEST_NAME = "volspring-run.json"
MANIFEST_FORMAT = "volspring-run"
MANIFEST_VERSION = 1
STATUSES = ("running", "finished", "interrupted", "failed")
#: The distributions whose versions a run records (:func:`package_versions`): volspring and what its numbers
#: and files depend on (the solvers, the mesher, the readers and writers).
RECORDED_PACKAGES = ("volspring", "numpy", "scipy", "pyamg", "meshio", "gmsh", "trimesh", "scikit-fem", "networkx",
                     "h5py", "tqdm")


def package_versions(packages: Sequence[str] = RECORDED_PACKAGES) -> dict:
    """The Python version, the platform and the installed version of each package.

    Parameters
    ----------
    packages : sequence of str
        Distribution names, as ``pip`` knows them.

    Returns
    -------
    dict of str to str or None
        ``python``, ``platform`` (:func:`platform.platform`), then each package's version; None for a
        package that is not installed.

    Examples
    --------
    >>> versions = package_versions(["numpy", "no-such-package"])
    >>> sorted(versions), versions["no-such-package"]
    (['no-such-package', 'numpy', 'platform', 'python'], None)
    """
    versions: dict[str, str | None] = {"python": platform.python_version(), "platform": platform.platform()}
    for name in packages:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = None
    return versions


def read_manifest(path: str | os.PathLike[str]) -> dict:
    """Read and check a run manifest.

    Parameters
    ----------
    path : path-like
        A ``volspring-run.json`` file, or the folder holding one.

    Returns
    -------
    dict
        The manifest (layout in the module docstring).

    Raises
    ------
    FileNotFoundError
        If there is no manifest.
    ValueError
        If it is not valid JSON, not a volspring run manifest, or of a version this volspring does
        not read (a newer one).
    """
    path = Path(path)
    if path.is_dir():
        path = path / MANIFEST_NAME
    try:
        manifest = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as error:
        raise ValueError(f"{path} is not valid JSON ({error})") from None
    except UnicodeDecodeError as error:
        raise ValueError(f"{path} is not UTF-8 text ({error})") from None
    if not isinstance(manifest, dict) or manifest.get("format") != MANIFEST_FORMAT:
        found = manifest.get("format") if isinstance(manifest, dict) else type(manifest).__name__
        raise ValueError(f"{path} is not a volspring run manifest (format {found!r}, expected {MANIFEST_FORMAT!r})")
    version = manifest.get("version")
    if not isinstance(version, int) or not 1 <= version <= MANIFEST_VERSION:
        raise ValueError(f"{path} has manifest version {version!r}; this volspring reads versions 1 to "
                         f"{MANIFEST_VERSION} (a newer volspring wrote it?)")
    files, command = manifest.get("files"), manifest.get("command")
    if not isinstance(files, list) or not all(isinstance(file, str) for file in files):
        raise ValueError(f"{path}: 'files' must be a list of relative paths, got {type(files).__name__}")
    if not isinstance(command, list) or not all(isinstance(word, str) for word in command):
        raise ValueError(f"{path}: 'command' must be a list of arguments, got {type(command).__name__}")
    if manifest.get("status") not in STATUSES:
        raise ValueError(f"{path}: status {manifest.get('status')!r} is not one of {', '.join(STATUSES)}")
    return manifest


def _now() -> str:
    return datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")


def _process_alive(manifest: dict) -> bool:
    """Whether the process a "running" manifest names still runs (on this machine; elsewhere assume so)."""
    pid = manifest.get("pid")
    if not isinstance(pid, int) or pid <= 0:
        return False
    if manifest.get("host") != socket.gethostname():
        return True  # cannot tell: a run on another machine sharing the folder
    if pid == os.getpid():
        return False  # this process opens the folder again: the earlier RunFolder is not in use any more
    if os.name != "posix":
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return True
    return True


def _status(manifest: dict) -> str:
    """The status of a manifest's run, "interrupted" for a "running" one whose process is gone."""
    if manifest["status"] == "running" and not _process_alive(manifest):
        return "interrupted"
    return manifest["status"]


def _describe(manifest: dict, status: str) -> str:
    return f"{shlex.join(manifest['command'])}, started {manifest.get('started')}, {status}"
