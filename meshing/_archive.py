"""Versioned ``.npz`` archives: the plumbing under the topology and model files.

An archive is a compressed ``.npz`` (numpy's zip of ``.npy`` arrays, read without pickle) with two
entries besides its arrays: ``format``, a 0-d text array naming what the file holds
(``"volspring.spring_topology"``, ``"volspring.model"``), and ``version``, a 0-d integer array.
:func:`write_archive` writes one atomically (:func:`meshing._io.atomic_path`); :func:`read_archive`
checks the format name and version and reads every array, turning each way a file can be damaged
into one ``ValueError`` that names the file (and the array, where one is at fault);
:func:`take_array` checks one array's presence, shape and dtype. The readers of each format
(:mod:`meshing.topology_io`, :mod:`volspring.model_io`) say which arrays they expect.

It lives in ``meshing``, the lowest layer, because ``volspring``'s model files use it too.
"""

from __future__ import annotations

import os
import zipfile
import zlib
from pathlib import Path

import numpy as np

from meshing._io import atomic_path
from meshing._signals import interruptions_deferred

__all__ = ["labelled_codes", "read_archive", "take_array", "write_archive"]

# How np.load and zipfile fail on a damaged member (bad CRC, truncated stream, bad .npy header, an
# object array that would need pickle).
_DAMAGE = (OSError, EOFError, KeyError, ValueError, zipfile.BadZipFile, zlib.error)


def write_archive(path, arrays, *, format_name: str, version: int) -> Path:
    """Write ``arrays`` with their ``format`` and ``version`` entries to a compressed ``.npz``, atomically.

    Parameters
    ----------
    path : path-like
        The file to write; missing parent folders are created, and an existing file is replaced only
        once the new one is complete.
    arrays : dict of str to array
        The archive's arrays (names may hold ``/``), stored with their dtype and bytes unchanged.
    format_name : str
    version : int

    Returns
    -------
    Path
        ``path``.
    """
    path = Path(path)
    entries = {"format": np.asarray(format_name), "version": np.asarray(version, dtype=np.int64), **arrays}
    # A stop waits for the archive (meshing._signals.interruptions_deferred: zipfile cut in the middle cannot clean
    # up after itself). A file object, not a name: np.savez_compressed would add ".npz" to a name without it.
    with atomic_path(path) as tmp, open(tmp, "wb") as file, interruptions_deferred():
        np.savez_compressed(file, **entries)
    return path


def read_archive(path, *, format_name: str, versions, what: str):
    """Every array of an archive written by :func:`write_archive`, once its format and version are checked.

    Parameters
    ----------
    path : path-like
    format_name : str
        The ``format`` entry the file must hold.
    versions : tuple of int
        The format versions this reader understands.
    what : str
        What the file is, for messages ("spring topology", "model").

    Returns
    -------
    arrays : dict of str to ndarray
        Every entry but ``format`` and ``version``.
    version : int

    Raises
    ------
    FileNotFoundError
        When there is no file at ``path``.
    ValueError
        Naming the file: not a complete zip archive (truncated, another kind of file), a damaged
        array (naming it), no or another ``format``, or a ``version`` not in ``versions`` (naming the
        version found and those supported).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"no {what} file at {path}")
    if not zipfile.is_zipfile(path):
        raise ValueError(f"{path} is not a readable {what} file: it is not a complete .npz (zip) archive "
                         "(truncated, or another kind of file)")
    arrays = {}
    try:
        with np.load(path, allow_pickle=False) as archive:
            for name in archive.files:
                try:
                    arrays[name] = np.asarray(archive[name])
                except _DAMAGE as error:
                    raise ValueError(f"{path} is damaged: its array {name!r} cannot be read "
                                     f"({type(error).__name__}: {error})") from error
    except _DAMAGE as error:
        if os.fspath(path) in str(error):
            raise
        raise ValueError(f"{path} is not a readable {what} file (truncated or corrupt?): "
                         f"{type(error).__name__}: {error}") from error
    found = arrays.pop("format", None)
    if found is None or found.shape != () or found.dtype.kind != "U":
        raise ValueError(f"{path} is not a volspring {what} file: it has no 'format' entry naming {format_name!r}")
    if str(found) != format_name:
        raise ValueError(f"{path} holds format {str(found)!r}, not {format_name!r}: it is not a {what} file")
    version = arrays.pop("version", None)
    if version is None or version.shape != () or version.dtype.kind not in "iu":
        raise ValueError(f"{path} is damaged: its 'version' entry is missing or not an integer")
    version = int(version)
    if version not in versions:
        newer = " (written by a newer volspring? upgrade to read it)" if version > max(versions) else ""
        raise ValueError(f"{path} has {what} format version {version}; this volspring reads version(s) "
                         f"{', '.join(map(str, versions))}{newer}")
    return arrays, version


def take_array(arrays, name: str, path, *, shape: tuple, kind: str) -> np.ndarray:
    """One array of an archive, checked: present, of the given shape and dtype kind.

    Parameters
    ----------
    arrays : dict of str to ndarray
        From :func:`read_archive`.
    name : str
    path : path-like
        The file, for messages.
    shape : tuple of int or str
        The expected shape; a str entry (``"n"``) is a free length, named in the message.
    kind : {"f", "i", "b", "U"}
        Floating point, integer, bool or text.

    Returns
    -------
    ndarray
        The array as stored (dtype and bytes unchanged).

    Raises
    ------
    ValueError
        ``beam.vstopo.npz is damaged: array 'tets' has shape (5, 3) and dtype int64; expected shape
        (m, 4) of integers``, or naming the missing array.
    """
    if name not in arrays:
        raise ValueError(f"{path} is damaged or incomplete: the array {name!r} is missing")
    array = arrays[name]
    kinds = {"f": ("f", "floats"), "i": ("iu", "integers"), "b": ("b", "bools"), "U": ("U", "text")}[kind]
    fits = array.ndim == len(shape) and all(isinstance(want, str) or got == want
                                            for got, want in zip(array.shape, shape))
    if not fits or array.dtype.kind not in kinds[0]:
        expected = "(" + ", ".join(map(str, shape)) + ("," if len(shape) == 1 else "") + ")"
        raise ValueError(f"{path} is damaged: array {name!r} has shape {array.shape} and dtype {array.dtype}; "
                         f"expected shape {expected} of {kinds[1]}")
    return array


def labelled_codes(arrays, path, *, codes: str, labels: str, known) -> np.ndarray:
    """Integer codes stored with the labels they stood for, mapped onto the labels known now.

    A file stores ``codes`` (indices) and ``labels`` (the label of each index when it was written),
    so that codes stay readable if the known labels are reordered or extended.

    Parameters
    ----------
    arrays : dict of str to ndarray
    path : path-like
        The file, for messages.
    codes, labels : str
        Names of the code array (s,) and of the label array (k,).
    known : sequence of str
        The labels known now, in the order of their codes.

    Returns
    -------
    (s,) int8
        The codes as indices into ``known`` (the stored array itself when the labels agree).

    Raises
    ------
    ValueError
        For a code outside the stored labels or a label not in ``known``, naming the file.
    """
    values = take_array(arrays, codes, path, shape=("s",), kind="i")
    names = [str(label) for label in take_array(arrays, labels, path, shape=("k",), kind="U")]
    if values.size and (values.min() < 0 or values.max() >= len(names)):
        raise ValueError(f"{path} is damaged: {codes!r} holds codes {values.min()} to {values.max()}, but "
                         f"{labels!r} names {len(names)} label(s)")
    unknown = [name for name in names if name not in known]
    if unknown:
        raise ValueError(f"{path} uses {labels} {', '.join(map(repr, unknown))} unknown to this volspring "
                         f"(known: {', '.join(known)})")
    if names == list(known[: len(names)]):
        return values
    mapping = np.array([list(known).index(name) for name in names], dtype=np.int8)
    return mapping[values]
