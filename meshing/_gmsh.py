"""gmsh's global state behind a context manager: initialised on entry, always finalised on exit."""

from __future__ import annotations

import contextlib
import logging

__all__ = ["gmsh_session"]

logger = logging.getLogger(__name__)


@contextlib.contextmanager
def gmsh_session(*, verbose: bool = False, model: str = "volspring"):
    """Initialise gmsh, yield the ``gmsh`` module with a fresh model, and finalise it whatever happens.

    Parameters
    ----------
    verbose : bool
        let gmsh print its progress to the terminal (off by default)
    model : str
        name of the model added for the session

    Raises
    ------
    RuntimeError
        If a gmsh session is already open in this process (gmsh has one global state).

    Examples
    --------
    >>> with gmsh_session() as gmsh:
    ...     _ = gmsh.model.occ.addBox(0, 0, 0, 1, 1, 1)
    ...     gmsh.model.occ.synchronize()
    ...     len(gmsh.model.getEntities(3))
    1
    """
    import gmsh

    if gmsh.isInitialized():
        raise RuntimeError("a gmsh session is already open; gmsh keeps one global state per process")
    # readConfigFiles=False: a user's ~/.gmshrc must not change our meshes; interruptible=False: gmsh
    # must not install its own SIGINT handler, which only works in the main thread.
    gmsh.initialize(readConfigFiles=False, interruptible=False)
    try:
        gmsh.option.setNumber("General.Terminal", 1 if verbose else 0)
        gmsh.option.setNumber("General.Verbosity", 5 if verbose else 2)
        gmsh.model.add(model)
        yield gmsh
    finally:
        gmsh.finalize()
