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

A run may add entries of its own (:meth:`RunFolder.note <volspring.output.RunFolder.note>`): ``volspring-sim``
records its model as ``"model": {"rung": "smoothed", "alpha": 0.6, "E": ..., "nu": ..., ...}``.
"""

from __future__ import annotations

import datetime
import json
import os
import shlex
import socket
from pathlib import Path

__all__ = ["MANIFEST_NAME", "read_manifest"]

MANIFEST_NAME = "volspring-run.json"
MANIFEST_FORMAT = "volspring-run"
MANIFEST_VERSION = 1
STATUSES = ("running", "finished", "interrupted", "failed")


def read_manifest(path) -> dict:
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
