"""Termination signals as exceptions, so that a stopped command cleans up like an interrupted one.

In ``meshing``, the lowest layer, so that every command (``volspring mesh`` as well as ``sim``, ``validate`` and
``sweep``) stops the same way without importing a layer above its own.

By default SIGTERM (``kill PID``, a job scheduler's or a container's stop) and SIGHUP (the
terminal closed) end a Python process on the spot: no ``finally`` block runs, temporary files
stay behind, a run folder's manifest still says "running". Inside :func:`handle_termination`
they raise :class:`Terminated` instead, which unwinds like Ctrl-C's ``KeyboardInterrupt``:
:func:`meshing._io.atomic_path` removes its temporary file, a
:class:`volspring.output.RunFolder` (a layer above) is marked interrupted, and the command exits with the
conventional status 128 + signal number (:func:`exit_status`: 143 for SIGTERM, 129 for SIGHUP,
130 for Ctrl-C).

Both exceptions derive from ``BaseException``, not ``Exception``, so a handler written for
errors (``except Exception``) does not swallow them.

Examples
--------
>>> import os, signal
>>> from meshing._signals import Terminated, exit_status, handle_termination
>>> try:
...     with handle_termination():
...         os.kill(os.getpid(), signal.SIGTERM)
... except Terminated as stop:
...     print(stop.signal_name, exit_status(stop))
SIGTERM 143
"""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import sys
import threading

__all__ = ["Interrupted", "Terminated", "exit_status", "handle_termination", "interruption_name",
           "interruptions_deferred"]

logger = logging.getLogger(__name__)

#: The signals turned into :class:`Terminated` (those this platform has).
TERMINATION_SIGNALS = tuple(getattr(signal, name) for name in ("SIGTERM", "SIGHUP") if hasattr(signal, name))

#: The signals :func:`interruptions_deferred` holds back: Ctrl-C's and the termination signals.
DEFERRED_SIGNALS = (signal.SIGINT, *TERMINATION_SIGNALS)

#: Seconds after which a signal dropped by a finalizer is sent again: long enough for the finalizer
#: and the hook that saw it to return, short next to any run a user would stop.
RESEND_DELAY = 0.01


class Interrupted(BaseException):
    """The process was asked to stop by a signal.

    Parameters
    ----------
    signum : int
        The signal number.

    Attributes
    ----------
    signum : int
        The signal number.
    signal_name : str
        Its name, such as ``"SIGTERM"``.
    exit_status : int
        The status a command conventionally exits with: 128 + ``signum`` (143 for SIGTERM).
    """

    def __init__(self, signum: int):
        self.signum = int(signum)
        try:
            self.signal_name = signal.Signals(self.signum).name
        except ValueError:
            self.signal_name = f"signal {self.signum}"
        self.exit_status = 128 + self.signum
        super().__init__(f"interrupted by {self.signal_name}")


class Terminated(Interrupted):
    """A termination signal (SIGTERM or SIGHUP) arrived inside :func:`handle_termination`."""


def exit_status(interruption: BaseException) -> int:
    """The conventional exit status for an interruption: 128 + the signal number.

    Parameters
    ----------
    interruption : Interrupted or KeyboardInterrupt

    Returns
    -------
    int
        ``interruption.exit_status`` for an :class:`Interrupted`; 130 (128 + SIGINT) for a
        ``KeyboardInterrupt``.

    Raises
    ------
    TypeError
        For any other exception.
    """
    if isinstance(interruption, Interrupted):
        return interruption.exit_status
    if isinstance(interruption, KeyboardInterrupt):
        return 128 + int(signal.SIGINT)
    raise TypeError(f"{type(interruption).__name__} is not an interruption (expected Interrupted or "
                    "KeyboardInterrupt)")


def interruption_name(interruption: BaseException) -> str:
    """``"SIGTERM"``, ``"SIGHUP"``, ... for an :class:`Interrupted`; ``"SIGINT (Ctrl-C)"`` for a ``KeyboardInterrupt``."""
    if isinstance(interruption, Interrupted):
        return interruption.signal_name
    if isinstance(interruption, KeyboardInterrupt):
        return "SIGINT (Ctrl-C)"
    raise TypeError(f"{type(interruption).__name__} is not an interruption (expected Interrupted or "
                    "KeyboardInterrupt)")


@contextlib.contextmanager
def handle_termination(signals=TERMINATION_SIGNALS):
    """Within the block, a termination signal raises :class:`Terminated` in the main thread.

    Parameters
    ----------
    signals : sequence of int, optional
        The signals to turn into :class:`Terminated`; default SIGTERM and SIGHUP.

    Yields
    ------
    None

    Notes
    -----
    - Python runs a signal handler in whatever Python code the main thread is executing, a
      finalizer included (a ``__del__``, a generator closed by the garbage collector), where an
      exception is printed as "Exception ignored" and dropped. The run would then go on as if the
      signal had not come. Inside the block such a :class:`Terminated` is not printed but sent
      again, from a helper thread so that it arrives once the finalizer is over, and is raised in
      the code the finalizer interrupted.
    - Every signal raises, including one arriving while an earlier one unwinds: a ``kill`` is
      never lost, at the cost of a second ``kill`` in quick succession possibly cutting a
      clean-up short (the temporary file it leaves is removed by the next run's
      :func:`meshing._io.remove_stale_temporaries`).
    - A signal whose disposition is "ignore" when the block starts (``nohup`` ignores SIGHUP) stays
      ignored.
    - The handlers in place before the block are restored when it ends, however it ends.
    - Python delivers signals to the main thread only: called from another thread this does
      nothing (the block runs with the handlers as they are).
    """
    if threading.current_thread() is not threading.main_thread():
        logger.debug("handle_termination outside the main thread: signals are left as they are")
        yield
        return

    def handler(signum, frame):
        raise Terminated(signum)

    previous_hook = sys.unraisablehook

    def unraisable(info):
        if isinstance(info.exc_value, Terminated):  # raised inside a finalizer, which drops it: send it again
            logger.debug("%s arrived in %r, which ignores exceptions; sending it again", info.exc_value.signal_name,
                         info.object)
            # Not from here, nor at once: the signal would be handled inside this hook, which drops it too.
            resend = threading.Timer(RESEND_DELAY, os.kill, args=(os.getpid(), info.exc_value.signum))
            resend.daemon = True
            resend.start()
            return
        previous_hook(info)

    previous = {}
    try:
        sys.unraisablehook = unraisable
        for signum in signals:
            before = signal.getsignal(signum)
            if before == signal.SIG_IGN:
                continue
            previous[signum] = before
            signal.signal(signum, handler)
        yield
    finally:
        for signum, before in previous.items():
            # getsignal returns None for a handler not installed from Python: restore the default then.
            signal.signal(signum, signal.SIG_DFL if before is None else before)
        if sys.unraisablehook is unraisable:
            sys.unraisablehook = previous_hook


@contextlib.contextmanager
def interruptions_deferred():
    """Within the block, Ctrl-C and the termination signals wait; the first that arrived is raised again when the
    block ends, to the handler it would have met (``KeyboardInterrupt``, :class:`Terminated`, the default action).

    For short library calls that an exception cut in the middle leaves in a state their own clean-up cannot handle.
    SIGTERM inside zipfile's ``ZipFile`` constructor (under ``np.savez``, a checkpoint) left an object without the
    attributes its finalizer reads, which then printed "Exception ignored ... AttributeError" under the command's
    one-line message (``tests/test_cli_sim.py``, by chance, with a checkpoint every step). A signal ignored when the
    block starts stays ignored; outside the main thread (where Python runs no handler) the block runs as it is.

    Yields
    ------
    None

    Examples
    --------
    >>> import signal
    >>> done = []
    >>> try:
    ...     with interruptions_deferred():
    ...         signal.raise_signal(signal.SIGINT)
    ...         done.append("the block ran to its end")
    ... except KeyboardInterrupt:
    ...     print(done, "then Ctrl-C")
    ['the block ran to its end'] then Ctrl-C
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    arrived: list[int] = []
    previous = {}
    try:
        for signum in DEFERRED_SIGNALS:
            before = signal.getsignal(signum)
            if before is None or before == signal.SIG_IGN:  # ignored, or a handler not installed from Python
                continue
            previous[signum] = before
            signal.signal(signum, lambda number, frame: arrived.append(number))
        yield
    finally:
        for signum, before in previous.items():
            signal.signal(signum, before)
        if arrived:
            signal.raise_signal(arrived[0])  # to the handler restored above: it raises here, after the block
