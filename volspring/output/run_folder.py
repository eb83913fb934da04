"""Run folders: a folder of outputs that knows which files its run wrote.

A command that writes a folder of files (``volspring-sim --out DIR``, ``volspring-validate --out
DIR``) opens it with :meth:`RunFolder.open`. The folder then holds a manifest,
``volspring-run.json``, listing every file the run wrote, so that a later run can replace them
all (and only them), instead of leaving the later frames of a longer earlier run beside the frames
of a shorter one, where a glob over the VTU files and Blender's OBJ-sequence import pick them up.

Rules applied by :meth:`RunFolder.open`:

- a missing or empty folder is used (and created);
- a folder holding another run's outputs (its manifest lists files that exist) is refused unless
  ``overwrite=True``; then only the files that manifest lists are removed, never anything else.
  An earlier run of the same command is refused the same way (a finished simulation is worth
  keeping), unless the caller opts in with ``replace_same_command=True`` (for a report that the
  command regenerates whole). A manifest whose files are all gone (a run that failed before
  writing) does not hold the folder;
- ``resume=True`` continues the run of the folder: its files are kept and new ones are added to
  the same list;
- a folder that is not empty but has no manifest (files volspring did not write, or the outputs of
  a volspring older than run manifests) is refused unless ``overwrite=True`` or ``resume=True``;
  even then nothing in it is removed, files of the same names are replaced;
- a folder another running process is writing (its manifest says "running" and names a live
  process on this machine) is refused whatever the options;
- opening removes the stale temporary files killed writers left
  (:func:`meshing._io.remove_stale_temporaries`).

Writers list a file *before* it appears under its final name (:meth:`RunFolder.record`), so a run
that dies at any point leaves no file its manifest does not list. The manifest is rewritten
atomically, once per :meth:`~RunFolder.record` call that brings a new name: a writer records all
the files of a frame in one call, and a name already listed costs nothing.

The manifest's layout and reading it are :mod:`volspring.output.run_manifest`; checking an output
location and removing the files a manifest lists are :mod:`volspring.output.run_files`.

Examples
--------
>>> import tempfile
>>> from pathlib import Path
>>> from volspring.output import RunFolder
>>> folder = Path(tempfile.mkdtemp()) / "run"
>>> with RunFolder.open(folder, command=["my-tool", "--out", "run"]) as run:
...     run.record(folder / "result.txt")           # listed before it exists
...     _ = (folder / "result.txt").write_text("42")
>>> run.status, run.files
('finished', ('result.txt',))
>>> RunFolder.open(folder, command=["my-tool", "--out", "run"])
Traceback (most recent call last):
...
volspring.output.run_folder.RunFolderRefused: ... an earlier run of the same command (my-tool --out run, ...)... pass overwrite=True ...
"""

from __future__ import annotations

import json
import logging
import os
import shlex
import socket
from pathlib import Path

from meshing._io import atomic_path, remove_stale_temporaries
from meshing._signals import Interrupted
from volspring.output.run_files import _inside, _remove_listed, check_output_folder
from volspring.output.run_manifest import (MANIFEST_FORMAT, MANIFEST_NAME, MANIFEST_VERSION, STATUSES, _describe,
                                           _now, _status, read_manifest)
from typing import Any, Literal
from collections.abc import Sequence

__all__ = ["MANIFEST_NAME", "RunFolder", "RunFolderRefused", "check_output_folder", "read_manifest"]

logger = logging.getLogger(__name__)

#: Files a desktop drops into folders it shows; they do not make a folder "not empty".
DESKTOP_FILES = frozenset({".DS_Store", "Thumbs.db", "desktop.ini"})
#: The entries of a manifest that :meth:`RunFolder.note` may not replace.
_LAYOUT_KEYS = frozenset({"format", "version", "command", "started", "ended", "status", "pid", "host", "volspring",
                          "earlier", "files"})
#: How a caller's user asks for each option, for refusal messages (a CLI passes its own flags).
DEFAULT_FLAGS = {"overwrite": "overwrite=True", "resume": "resume=True"}


class RunFolderRefused(ValueError):
    """The folder holds outputs this run must not mix with; the message says which and what to pass.

    Attributes
    ----------
    folder : Path
        The folder refused.
    reason : {"other_run", "same_command", "not_empty", "running", "unreadable"}
        Why: it holds another run's outputs; an earlier run of the same command; files without a
        manifest; a run still in progress; a manifest that cannot be read.
    previous : dict or None
        The manifest found there, if it could be read.
    """

    def __init__(self, message: str, *, folder: str | os.PathLike[str], reason: str,
                 previous: dict[str, Any] | None = None):
        super().__init__(message)
        self.folder, self.reason, self.previous = Path(folder), reason, previous


class RunFolder:
    """The output folder of one run, with the manifest of the files it wrote.

    Make one with :meth:`open`; writers call :meth:`record` before they write a file; the run
    ends with :meth:`finish` (or by leaving a ``with`` block). See the module docstring for the
    rules, and :mod:`volspring.output.run_manifest` for the manifest layout.

    Attributes
    ----------
    path : Path
        The folder.
    manifest_path : Path
        Its manifest, ``path / "volspring-run.json"``.
    command : list of str
        The command of this run.
    previous : dict or None
        The manifest found when opening (the run replaced or resumed), or None.
    removed : tuple of Path
        The files of the previous run removed when opening with ``overwrite=True``.
    resumed : bool
        Whether this run continues the previous one (``resume=True`` on a folder with a manifest).
    """

    def __init__(self, path: str | os.PathLike[str], manifest: dict, *, previous: dict[str, Any] | None = None,
                 removed: Sequence[str] = (), resumed: bool = False):
        self.path = Path(path)
        self.manifest_path = self.path / MANIFEST_NAME
        self._manifest = manifest
        self._listed = set(manifest["files"])
        self.previous, self.removed, self.resumed = previous, tuple(removed), bool(resumed)

    # ------------------------------------------------------------------ opening
    @classmethod
    def open(cls, path: str | os.PathLike[str], *, command: Sequence[str], overwrite: bool = False,
             resume: bool = False, replace_same_command: bool = False,
             flags: dict[str, Any] | None = None) -> "RunFolder":
        """Open ``path`` for a run of ``command``, following the rules of the module docstring.

        Parameters
        ----------
        path : path-like
            The output folder; created if missing.
        command : sequence of str
            The command line of the run (argv, program name first), stored in the manifest and
            compared with the previous run's.
        overwrite : bool
            Replace the outputs of the previous run: remove the files its manifest lists (and only
            those), or write into a non-empty folder without manifest (removing nothing).
        resume : bool
            Continue the previous run of the folder: keep its files and list new ones after them.
            Excludes ``overwrite``.
        replace_same_command : bool
            Treat a previous run of the same ``command`` as if ``overwrite`` were given (for
            outputs that the command regenerates whole, such as a report).
        flags : dict, optional
            How the user asks for ``"overwrite"`` and ``"resume"`` (``{"overwrite": "--overwrite"}``),
            for the refusal messages; an option missing from it is not suggested. Default the
            keyword arguments themselves.

        Returns
        -------
        RunFolder
            Status "running", with the manifest written.

        Raises
        ------
        RunFolderRefused
            If the folder holds outputs this run must not mix with (the message names the folder,
            the previous command and the option to pass).
        NotADirectoryError, PermissionError
            If ``path`` cannot be a writable folder (:func:`check_output_folder`).
        ValueError
            For ``overwrite`` and ``resume`` both true, or a ``command`` that is not a list of strings.
        """
        if isinstance(command, (str, bytes)) or not all(isinstance(word, str) for word in command):
            raise ValueError(f"command = {command!r} must be a sequence of strings (argv), not one string")
        command = list(command)
        if overwrite and resume:
            raise ValueError("overwrite=True and resume=True contradict each other: overwrite removes the previous "
                             "run's files, resume keeps them")
        flags = {"overwrite": DEFAULT_FLAGS["overwrite"]} | dict(DEFAULT_FLAGS if flags is None else flags)
        path = check_output_folder(path)
        path.mkdir(parents=True, exist_ok=True)
        remove_stale_temporaries(path)
        manifest_path = path / MANIFEST_NAME
        previous, removed, earlier, files = None, [], [], []
        if manifest_path.exists():
            try:
                previous = read_manifest(manifest_path)
            except (OSError, ValueError) as error:
                if not overwrite:
                    raise RunFolderRefused(
                        f"{path} holds a run manifest {MANIFEST_NAME} that cannot be read ({error}); "
                        + _offer(flags, "overwrite", "to start a new run there (the files it lists are left in place)"),
                        folder=path, reason="unreadable") from None
                logger.warning("%s cannot be read (%s); starting a new run there, leaving its files", manifest_path,
                               error)
        if previous is not None:
            for folder in sorted({(path / file).parent for file in previous["files"] if _inside(path, file)}):
                if folder != path:
                    remove_stale_temporaries(folder)
            status = _status(previous)
            described = _describe(previous, status)
            if status == "running":
                raise RunFolderRefused(
                    f"{path} is being written by another run ({described}, process {previous.get('pid')} on "
                    f"{previous.get('host')}); wait for it to end or stop it, or choose another folder",
                    folder=path, reason="running", previous=previous)
            present = [file for file in previous["files"] if (target := _inside(path, file)) and
                       (target.is_file() or target.is_symlink())]
            if resume:
                earlier = list(previous.get("earlier", [])) + [
                    {key: previous.get(key) for key in ("command", "started", "ended")} | {"status": status}]
                files = list(previous["files"])
            elif present and not (overwrite or (replace_same_command and previous["command"] == command)):
                same = previous["command"] == command
                alternatives = _offer(flags, "overwrite", f"to remove them ({len(present)} file(s), nothing else) "
                                                          "and write this run's outputs there")
                if status == "interrupted" and "resume" in flags:
                    alternatives += f", or {flags['resume']} to continue it"
                raise RunFolderRefused(
                    f"{path} holds the outputs of {'an earlier run of the same command' if same else 'another run'} "
                    f"({described}), listed in {MANIFEST_NAME}; {alternatives}, or choose another folder",
                    folder=path, reason="same_command" if same else "other_run", previous=previous)
            else:
                removed = _remove_listed(path, present)
        elif not (overwrite or resume):
            entries = sorted(entry.name for entry in os.scandir(path) if entry.name not in DESKTOP_FILES)
            if entries:
                shown = ", ".join(entries[:3]) + (", ..." if len(entries) > 3 else "")
                raise RunFolderRefused(
                    f"{path} is not empty ({len(entries)} entr{'y' if len(entries) == 1 else 'ies'}: {shown}) and "
                    f"holds no {MANIFEST_NAME}, so volspring cannot tell which files are a run's outputs; "
                    + _offer(flags, "overwrite", "to write into it anyway (nothing in it is removed; files of the "
                                                 "same names are replaced)") + ", or choose an empty or new folder",
                    folder=path, reason="not_empty")
        import volspring

        manifest = {"format": MANIFEST_FORMAT, "version": MANIFEST_VERSION, "command": command, "started": _now(),
                    "ended": None, "status": "running", "pid": os.getpid(), "host": socket.gethostname(),
                    "volspring": volspring.__version__, "earlier": earlier, "files": files}
        run = cls(path, manifest, previous=previous, removed=removed, resumed=resume and previous is not None)
        run._write()
        logger.info("opened %s for %s (%s)", path, shlex.join(command),
                    "resumed" if run.resumed else f"{len(removed)} file(s) of the previous run removed")
        return run

    # ------------------------------------------------------------------ recording
    @property
    def files(self) -> tuple:
        """The files listed, as POSIX paths relative to :attr:`path`, in the order first recorded."""
        return tuple(self._manifest["files"])

    @property
    def status(self) -> str:
        """"running" until :meth:`finish`, then the status given to it."""
        return self._manifest["status"]

    @property
    def command(self) -> list:
        return list(self._manifest["command"])

    def record(self, *paths: str | os.PathLike[str]) -> None:
        """List files in the manifest before they are written.

        Call it before a file appears under its final name (before the rename of
        :func:`meshing._io.atomic_path`), with all the files of one step at once: the manifest
        is rewritten once per call that brings a new name, and not at all for names listed
        already.

        Parameters
        ----------
        *paths : path-like
            Files inside the folder, as you would open them (absolute, or relative to the working
            directory: ``run.path / "checkpoint.npz"``).

        Raises
        ------
        ValueError
            For a path outside the folder, or the manifest itself.
        RuntimeError
            After :meth:`finish`.
        """
        if self.status != "running":
            raise RuntimeError(f"the run in {self.path} is {self.status}: it cannot record {paths[0] if paths else ''}")
        new = []
        for path in paths:
            relative = self._relative(path)
            if relative not in self._listed and relative not in new:
                new.append(relative)
        if new:
            self._manifest["files"].extend(new)
            self._listed.update(new)
            self._write()

    def _relative(self, path) -> str:
        folder = Path(os.path.abspath(self.path))
        target = Path(os.path.abspath(path))
        try:
            relative = target.relative_to(folder)
        except ValueError:
            try:  # the same place reached through a symbolic link
                relative = target.resolve().relative_to(folder.resolve())
            except ValueError:
                raise ValueError(f"{path} is not inside the run folder {self.path}") from None
        if not relative.parts:
            raise ValueError(f"{path} is the run folder itself, not a file in it")
        if relative.as_posix() == MANIFEST_NAME:
            raise ValueError(f"{path} is the run manifest; it is not an output to record")
        return relative.as_posix()

    def note(self, key: str, value: Any) -> None:
        """Record what the run is beside its files, e.g. ``note("model", {"rung": "smoothed", ...})``.

        Parameters
        ----------
        key : str
            A manifest entry of the run's own (not one of the manifest's layout: ``files``,
            ``command``, ``status``, ...).
        value : JSON-serialisable
            Replaces an earlier note of the same key.

        Raises
        ------
        ValueError
            For a key of the manifest's layout, or a value JSON cannot hold.
        RuntimeError
            After :meth:`finish`.
        """
        if key in _LAYOUT_KEYS or not isinstance(key, str):
            raise ValueError(f"note key {key!r} is part of the run manifest's layout; choose another name")
        if self.status != "running":
            raise RuntimeError(f"the run in {self.path} is {self.status}: it cannot note {key!r}")
        try:
            json.dumps(value)
        except (TypeError, ValueError) as error:
            raise ValueError(f"note {key!r}: {error}") from None
        self._manifest[key] = value
        self._write()

    # ------------------------------------------------------------------ ending
    def finish(self, status: str = "finished") -> None:
        """End the run: write its status to the manifest. Only the first call counts.

        Parameters
        ----------
        status : {"finished", "interrupted", "failed"}
        """
        if status not in STATUSES[1:]:
            raise ValueError(f"status = {status!r} is not one of {', '.join(STATUSES[1:])}")
        if self.status != "running":
            logger.debug("%s already ended as %s; ignoring finish(%r)", self.path, self.status, status)
            return
        self._manifest["status"] = status
        self._manifest["ended"] = _now()
        self._write()

    def __enter__(self) -> "RunFolder":
        return self

    def __exit__(self, kind, error, traceback) -> Literal[False]:
        """Finish as "finished", "interrupted" (Ctrl-C, a termination signal) or "failed" (another exception)."""
        if self.status != "running":
            return False
        if kind is None:
            self.finish("finished")
            return False
        status = "interrupted" if issubclass(kind, (KeyboardInterrupt, Interrupted)) else "failed"
        try:
            self.finish(status)
        except Exception as failure:  # do not hide the exception that ends the run
            logger.warning("could not mark %s %s: %s", self.manifest_path, status, failure)
        return False

    def _write(self) -> None:
        with atomic_path(self.manifest_path) as tmp:
            tmp.write_text(json.dumps(self._manifest, indent=1) + "\n", encoding="utf-8")

    def __repr__(self) -> str:
        return f"RunFolder({str(self.path)!r}, {self.status}, {len(self._listed)} file(s))"


def _offer(flags: dict, option: str, purpose: str) -> str:
    return f"pass {flags[option]} {purpose}"
