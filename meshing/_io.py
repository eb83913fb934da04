"""Atomic file writing: a crash never leaves a half-written output behind.

Every writer goes through :func:`atomic_path`: it writes a temporary file beside the target and
renames it onto the target when the write succeeds. An exception (``KeyboardInterrupt`` and the
termination signals that ``meshing._signals`` turns into exceptions included) removes the temporary
file; only a process killed outright (SIGKILL, a power cut) leaves one behind. It lives in ``meshing``,
the lowest layer, because the mesh writers use it too.

Such leftovers have a name nobody else uses, so they can be found and removed later
(:func:`remove_stale_temporaries`)::

    .{stem}.volspring-tmp-{pid}-{8 random hex digits}{suffixes}

for example ``.frame_0076.volspring-tmp-4711-3fa9c2e1.vtu`` for ``frame_0076.vtu`` written by
process 4711. The target's suffixes are kept so that writers picking a format by extension still
work; a writer that adds a companion file with another suffix (meshio's XDMF writer puts the
``.h5`` heavy data beside the ``.xdmf``) produces a name of the same pattern
(``.mesh.volspring-tmp-4711-3fa9c2e1.h5``). The process id tells a leftover from a temporary file
that another running process is still writing.
"""

from __future__ import annotations

import contextlib
import logging
import os
import re
import secrets
import time
from pathlib import Path

__all__ = ["TEMPORARY_MARKER", "atomic_path", "interruptions_first", "is_temporary_name", "remove_stale_temporaries"]

logger = logging.getLogger(__name__)

#: The part of a temporary file's name that marks it as volspring's.
TEMPORARY_MARKER = "volspring-tmp"
# "." + the target's stem + ".volspring-tmp-" + pid + "-" + random letters + the target's
# suffixes (or ".tmp"); the suffixes may be replaced by a companion's (".h5" beside ".xdmf").
_TEMPORARY = re.compile(rf"^\..*\.{TEMPORARY_MARKER}-(?P<pid>[0-9]+)-[A-Za-z0-9_]+\.[^/\\]+$")
_CREATE_FLAGS = os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)
_CREATE_ATTEMPTS = 100
#: A temporary file untouched for this long is stale even if its process id is in use again
#: (process ids are recycled; no single write of ours takes a day).
STALE_AFTER_SECONDS = 24 * 3600.0


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary path beside ``path``; rename it onto ``path`` only if the block succeeds.

    Parameters
    ----------
    path : path-like
        The file to write; missing parent folders are created.

    Yields
    ------
    Path
        The temporary file to write to, named as in the module docstring (it keeps ``path``'s
        suffixes so that writers that pick a format by extension still work).

    Notes
    -----
    On any exception, ``KeyboardInterrupt`` and ``meshing._signals.Interrupted``
    included, the temporary file is removed and ``path`` is left as it was.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> target = Path(tempfile.mkdtemp()) / "result.txt"
    >>> with atomic_path(target) as tmp:
    ...     _ = tmp.write_text("done")
    >>> target.read_text(), sorted(p.name for p in target.parent.iterdir())
    ('done', ['result.txt'])
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    prefix, suffix = f".{path.stem}.{TEMPORARY_MARKER}-{os.getpid()}-", "".join(path.suffixes) or ".tmp"
    tmp = None
    try:
        # The file is created inside the try, under a name chosen before (unlike tempfile.mkstemp):
        # a signal turned into an exception just as open() returns still removes it.
        for _ in range(_CREATE_ATTEMPTS):
            tmp = path.parent / f"{prefix}{secrets.token_hex(4)}{suffix}"
            try:
                os.close(os.open(tmp, _CREATE_FLAGS, 0o600))
                break
            except FileExistsError:
                tmp = None  # someone else's file: never remove it
        else:
            raise FileExistsError(f"could not create a temporary file beside {path} in {_CREATE_ATTEMPTS} attempts")
        with interruptions_first():
            yield tmp
        # The file was created readable by its owner only; give it the mode a plain open() would.
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException:
        if tmp is not None:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(tmp)
        raise


@contextlib.contextmanager
def interruptions_first():
    """Within the block, an interruption that clean-up code masked with an error of its own is raised instead.

    A signal turned into an exception (``KeyboardInterrupt``, ``meshing._signals.Interrupted``: both
    derive from ``BaseException`` only) can arrive inside a library's writer, whose clean-up then fails
    on the half-done state and raises an ordinary error with the interruption as its context: zipfile,
    under ``np.savez``, raises "Can't close the ZIP file while there is an open writing handle". A
    command would report that error (exit status 1) instead of the stop (130, 143). Here the first
    interruption in the error's context chain is raised, the masking error dropped.

    Examples
    --------
    >>> import io, zipfile
    >>> try:
    ...     with interruptions_first(), zipfile.ZipFile(io.BytesIO(), "w") as archive:
    ...         _ = archive.open("x", "w").write(b"half")
    ...         raise KeyboardInterrupt
    ... except KeyboardInterrupt:
    ...     print("interrupted")
    interrupted
    """
    try:
        yield
    except Exception as error:
        context = error.__context__
        while context is not None:
            if not isinstance(context, Exception):
                raise context from None
            context = context.__context__
        raise


def is_temporary_name(name) -> bool:
    """Whether a file name has the pattern of :func:`atomic_path`'s temporary files.

    Parameters
    ----------
    name : str or path-like
        A file name (only its last component is looked at).

    Returns
    -------
    bool

    Examples
    --------
    >>> is_temporary_name(".frame_0076.volspring-tmp-4711-k3j2x9a1.vtu")
    True
    >>> is_temporary_name(".frame_0076.k3j2x9a1.vtu"), is_temporary_name("frame_0076.vtu")
    (False, False)
    """
    return _TEMPORARY.match(Path(name).name) is not None


def _process_running(pid: int) -> bool:
    """Whether a process with this id exists on this machine (True when that cannot be told)."""
    if pid == os.getpid():
        return True  # this process: its temporary files may be in use by another thread
    if os.name != "posix":
        return True  # os.kill(pid, 0) would terminate the process on Windows; rely on the age instead
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return True  # exists, owned by someone else (or an id out of range: leave it to the age test)
    return True


def remove_stale_temporaries(folder, *, now=None) -> list:
    """Remove the temporary files that killed writers left in a folder (not in its subfolders).

    A file is removed only if its name has the exact pattern of :func:`atomic_path`'s temporary
    files (see the module docstring) and it is stale: the process that wrote it is not running
    on this machine, or the file has not been modified for :data:`STALE_AFTER_SECONDS`. Any
    other file is left alone, and so is a temporary file another running process is writing.

    Parameters
    ----------
    folder : path-like
        The folder to clean; a missing folder holds nothing to remove.
    now : float, optional
        The current time [s since the epoch], for tests; default ``time.time()``.

    Returns
    -------
    list of Path
        The files removed, sorted.
    """
    folder = Path(folder)
    now = time.time() if now is None else float(now)
    removed: list[Path] = []
    try:
        entries = list(os.scandir(folder))
    except (FileNotFoundError, NotADirectoryError):
        return removed
    for entry in entries:
        match = _TEMPORARY.match(entry.name)
        if match is None or not entry.is_file(follow_symlinks=False):
            continue
        try:
            age = now - entry.stat(follow_symlinks=False).st_mtime
        except FileNotFoundError:
            continue  # renamed or removed meanwhile by its writer
        if _process_running(int(match["pid"])) and age < STALE_AFTER_SECONDS:
            continue
        with contextlib.suppress(FileNotFoundError):
            os.unlink(entry.path)
            removed.append(Path(entry.path))
            logger.info("removed the stale temporary file %s", entry.path)
    return sorted(removed)
