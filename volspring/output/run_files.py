"""The files of a run folder on disk: whether a path can take a run's outputs, and removing an earlier run's.

:func:`check_output_folder` checks, before any work, that a path is or can be created as a writable
folder; :func:`_inside` turns a name a manifest lists into a path that stays inside the folder (or
refuses it); :func:`_remove_listed` removes the files a manifest lists, and nothing else. Used by
:class:`volspring.output.RunFolder`; :func:`check_output_folder` is imported from :mod:`volspring.output`.
"""

from __future__ import annotations

import contextlib
import logging
import os
from pathlib import Path, PurePosixPath

from volspring.output.run_manifest import MANIFEST_NAME

__all__ = ["check_output_folder"]

# The logger of RunFolder, which these functions serve: one name to configure.
logger = logging.getLogger("volspring.output.run_folder")


def check_output_folder(path: str | os.PathLike[str], *, label: str = "output folder") -> Path:
    """Check that ``path`` is, or can be created as, a writable folder; nothing is created.

    Meant to run before any work, so that a bad output location is reported in seconds rather
    than after the computation.

    Parameters
    ----------
    path : path-like
        The folder.
    label : str
        How messages name it (a CLI passes its option, ``"--out"``).

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    NotADirectoryError
        If ``path``, or the closest of its parents that exists, is not a folder.
    PermissionError
        If the folder, or the closest existing parent it would be created in, is not writable.

    Examples
    --------
    >>> import tempfile
    >>> from pathlib import Path
    >>> file = Path(tempfile.mkdtemp()) / "report.html"
    >>> _ = file.write_text("")
    >>> check_output_folder(file, label="--out")
    Traceback (most recent call last):
    ...
    NotADirectoryError: --out .../report.html is an existing file, expected a folder (or a path where one can be created)
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise NotADirectoryError(f"{label} {path} is an existing file, expected a folder (or a path where one can "
                                 "be created)")
    existing = Path(os.path.abspath(path))
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise NotADirectoryError(f"{label} {path} cannot be created: {existing} is a file, not a folder")
    if not os.access(existing, os.W_OK | os.X_OK):
        if existing == Path(os.path.abspath(path)):
            raise PermissionError(f"{label} {path} is not writable (no permission to create files in it)")
        raise PermissionError(f"{label} {path} cannot be created: no permission to create folders in {existing}")
    return path


def _inside(folder: Path, relative: str):
    """``folder / relative`` if that stays inside ``folder`` (symbolic links resolved), else None."""
    pure = PurePosixPath(relative)
    if not relative or pure.is_absolute() or ".." in pure.parts or "\\" in relative:
        return None
    target = folder.joinpath(*pure.parts)
    try:
        target.parent.resolve().relative_to(folder.resolve())
    except ValueError:
        return None
    return target


def _remove_listed(folder: Path, files) -> list:
    """Remove the listed files that exist, then the folders they leave empty; return the files removed."""
    removed: list[str] = []
    parents: set[Path] = set()
    for file in files:
        target = _inside(folder, file)
        if target is None:
            logger.warning("not removing %r listed in %s: it is not inside the folder", file, folder / MANIFEST_NAME)
            continue
        if target.is_dir() and not target.is_symlink():
            logger.warning("not removing %s: the manifest lists it but it is a folder", target)
            continue
        with contextlib.suppress(FileNotFoundError):
            target.unlink()
            removed.append(target)
            parents.update(parent for parent in target.parents if folder in parent.parents)
    for parent in sorted(parents, key=lambda p: len(p.parts), reverse=True):  # deepest first
        with contextlib.suppress(OSError):
            parent.rmdir()  # only succeeds on a folder left empty
    if removed:
        logger.info("removed %d file(s) of the previous run in %s", len(removed), folder)
    return removed
