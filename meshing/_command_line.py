"""What the commands ``volspring mesh``, ``sim`` and ``validate`` share: exit statuses, the options every one
has, one-line errors, gmsh's log kept off stdout, and progress on stderr.

It lives in ``meshing``, the lowest layer, so that each package's command uses it without importing a layer
above its own. Only the commands import it: the library never prints.

Exit statuses (:data:`EXIT_STATUS_EPILOG`, the end of every command's ``--help``): 0 done, 1 the run failed
while computing or writing, 2 a bad command line or bad input found before the work, 3 the simulation diverged,
130 interrupted by Ctrl-C (128 + the signal number: 143 for SIGTERM, 129 for SIGHUP).

Progress (:func:`progress_bar`) goes through tqdm: on a terminal, a bar redrawn in place with its rate and time
left; in a log (stderr not a terminal), a short plain line at most every :data:`LOG_INTERVAL` seconds and never
a carriage return.

Examples
--------
>>> parser = Parser(prog="volspring-example", description="An example.")
>>> add_common_options(parser)
>>> args = parser.parse_args(["--no-progress", "-q"])
>>> args.progress, args.quiet, args.verbose
(False, True, False)
>>> try:
...     parser.parse_args(["--frobnicate"])
... except UsageError as error:
...     print(error)
unrecognized arguments: --frobnicate
"""

from __future__ import annotations

import argparse
import contextlib
import contextvars
import os
import sys

__all__ = ["EXIT_DIVERGED", "EXIT_DONE", "EXIT_FAILED", "EXIT_INTERRUPTED", "EXIT_STATUS_EPILOG", "EXIT_USAGE",
           "HelpFormatter", "LOG_INTERVAL", "Parser", "UsageError", "add_common_options", "advance_to",
           "command_name", "error_line", "invoked_as", "progress_bar", "progress_mode", "stderr_line",
           "stdout_to_stderr", "version_text"]

EXIT_DONE = 0         #: the command did what it was asked
EXIT_FAILED = 1       #: the run failed while computing or writing
EXIT_USAGE = 2        #: a bad command line or bad input (a value, a file), found before the work
EXIT_DIVERGED = 3     #: the simulation diverged
EXIT_INTERRUPTED = 130  #: Ctrl-C (SIGINT); SIGTERM gives 143 and SIGHUP 129: 128 + the signal number

EXIT_STATUS_EPILOG = """\
exit status:
  0    done
  1    the run failed while computing or writing
  2    bad command line or bad input (a value, a file, the output folder), found before the work
  3    the simulation diverged
  130  interrupted by Ctrl-C; 143 by SIGTERM, 129 by SIGHUP (128 + the signal number)
Errors are one line on stderr, "PROG: error: ..."; the summary is on stdout, progress and logs on stderr."""

#: The name a command was invoked by when it is not its own script's: ``volspring sim`` for ``volspring-sim``.
_INVOKED_AS: contextvars.ContextVar[str | None] = contextvars.ContextVar("volspring_invoked_as", default=None)


@contextlib.contextmanager
def invoked_as(name: str):
    """Within the block, commands call themselves ``name`` (the dispatcher's ``volspring sim``) in their usage,
    ``--help``, ``--version`` and every line they write on stderr, instead of their script's name."""
    token = _INVOKED_AS.set(name)
    try:
        yield
    finally:
        _INVOKED_AS.reset(token)


def command_name(prog: str) -> str:
    """The name the running command was invoked by: ``prog`` (``volspring-sim``), or ``volspring sim`` under the
    dispatcher (:func:`invoked_as`).

    >>> with invoked_as("volspring sim"):
    ...     command_name("volspring-sim")
    'volspring sim'
    >>> command_name("volspring-sim")
    'volspring-sim'
    """
    return _INVOKED_AS.get() or prog


#: Seconds between two progress lines when stderr is not a terminal (a log file, a CI job): a line every few
#: seconds says the run is alive without filling the log.
LOG_INTERVAL = 5.0
#: Seconds between two redraws of the bar on a terminal.
TERMINAL_INTERVAL = 0.1


class UsageError(Exception):
    """A bad command line (argparse's complaint), reported in one line with exit status 2."""


class HelpFormatter(argparse.RawDescriptionHelpFormatter, argparse.ArgumentDefaultsHelpFormatter):
    """``--help`` with each default said once: ``(default: X)`` is added only to an option whose help does not
    already name its default and whose default is a value (not None, False or an empty list); the epilog keeps
    its lines."""

    def _get_help_string(self, action):
        text = action.help or ""
        if (not action.option_strings or "default" in text or action.default in (None, False, [])
                or action.default is argparse.SUPPRESS or isinstance(action, argparse.BooleanOptionalAction)):
            return text
        return text + " (default: %(default)s)"


class Parser(argparse.ArgumentParser):
    """An argument parser whose errors raise :class:`UsageError` (one line, exit status 2) instead of printing
    the usage block and exiting, with :class:`HelpFormatter` and the exit statuses as the epilog."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("formatter_class", HelpFormatter)
        if kwargs.get("prog") is not None:
            kwargs["prog"] = command_name(kwargs["prog"])
        super().__init__(*args, **kwargs)
        if self.epilog is None:
            self.epilog = EXIT_STATUS_EPILOG.replace("PROG", self.prog)

    def error(self, message):
        raise UsageError(message)


def version_text(prog: str | None = None) -> str:
    """``volspring 0.1.0`` (or ``volspring-sim (volspring 0.1.0)``): the installed distribution's version.

    >>> version_text().startswith("volspring ")
    True
    """
    from importlib.metadata import PackageNotFoundError, version

    try:
        number = version("volspring")
    except PackageNotFoundError:  # run from a source tree that was never installed
        number = "unknown (not installed)"
    return f"volspring {number}" if prog in (None, "volspring") else f"{prog} (volspring {number})"


def add_common_options(parser, *, prog: str | None = None, progress: str = "progress on stderr") -> None:
    """Add the options every command has: ``--version``, ``-q/--quiet``, ``-v/--verbose``,
    ``--progress/--no-progress``.

    Parameters
    ----------
    parser : argparse.ArgumentParser or argument group
        Where to add them.
    prog : str, optional
        The command's name for ``--version``; default the parser's ``prog``.
    progress : str
        What the progress shows, for the help text.
    """
    prog = prog or getattr(parser, "prog", None)
    parser.add_argument("--version", action="version", version=version_text(None if prog is None else
                                                                             command_name(prog)),
                        help="print the version of volspring and exit")
    parser.add_argument("-q", "--quiet", action="store_true",
                        help="no progress and no summary (errors and warnings still go to stderr)")
    parser.add_argument("-v", "--verbose", action="store_true",
                        help="log the steps, and gmsh's output, on stderr (never on stdout)")
    parser.add_argument("--progress", action=argparse.BooleanOptionalAction, default=None,
                        help=f"{progress}: a bar with rate and time left on a terminal, a short line every "
                             f"{LOG_INTERVAL:g} s at most in a log (default: on, in a log after the first "
                             f"{LOG_INTERVAL:g} s)")


def error_line(prog: str, message, status: int) -> int:
    """Print ``PROG: error: MESSAGE`` on one line of stderr and return ``status``.

    >>> import contextlib, io
    >>> with contextlib.redirect_stderr(io.StringIO()) as err:
    ...     error_line("volspring-mesh", "size = 0 is not\\n a positive length", EXIT_USAGE)
    2
    >>> err.getvalue()
    'volspring-mesh: error: size = 0 is not a positive length\\n'
    """
    text = " ".join(str(message).split())  # one line, whatever the message holds
    stderr_line(prog, f"error: {text}")
    return status


def stderr_line(prog: str, text: str) -> None:
    """Print ``PROG: TEXT`` on stderr, ``PROG`` the name the command was invoked by (:func:`command_name`)."""
    print(f"{command_name(prog)}: {text}", file=sys.stderr)


def progress_mode(args, stream=None):
    """How to show progress: ``"bar"`` (stderr is a terminal), ``"lines"`` (it is not), or None (``--quiet``,
    ``--no-progress``); ``"lines!"`` when ``--progress`` asks for lines at once (no initial delay)."""
    stream = sys.stderr if stream is None else stream
    if getattr(args, "quiet", False) or args.progress is False:
        return None
    terminal = bool(getattr(stream, "isatty", lambda: False)())
    if terminal:
        return "bar"
    return "lines!" if args.progress else "lines"


class _Lines:
    """A file for tqdm that turns its carriage-return redraws into plain lines, one per redraw."""

    def __init__(self, stream):
        self.stream = stream
        self.encoding = getattr(stream, "encoding", None) or "utf-8"

    def write(self, text):
        line = text.replace("\r", "").strip()
        if line:
            self.stream.write(line + "\n")

    def flush(self):
        self.stream.flush()


def progress_bar(mode, *, total, desc: str, unit: str = "items", stream=None, scale: bool = False):
    """A tqdm progress bar on stderr in ``mode`` (:func:`progress_mode`); with mode None, a disabled one.

    Parameters
    ----------
    mode : {"bar", "lines", "lines!", None}
        A bar redrawn in place at most every :data:`TERMINAL_INTERVAL` s; plain lines at most every
        :data:`LOG_INTERVAL` s, the first after :data:`LOG_INTERVAL` s (``"lines!"``: at once); or nothing.
    total : float
        The count at 100 % (steps, stages, or 1.0 for a fraction).
    desc : str
        The label before the bar (the subcommand).
    unit : str
        What is counted, plural, for the count and the rate (``12/40 steps``, ``850.3 steps/s``).
    scale : bool
        ``total`` is a fraction (1.0): show the percentage, time and ETA, but no count or rate.
    """
    from tqdm import tqdm

    stream = sys.stderr if stream is None else stream
    unit = f" {unit}"  # tqdm glues the unit to the number
    counts = "" if scale else " {n_fmt}/{total_fmt}{unit}"
    rate = "" if scale else ", {rate_fmt}"
    if mode == "bar":
        return tqdm(total=total, desc=desc, unit=unit, file=stream, mininterval=TERMINAL_INTERVAL, leave=True,
                    dynamic_ncols=True,
                    bar_format="{desc}: {percentage:3.0f}%|{bar}|" + counts + " [{elapsed}<{remaining}" + rate
                               + "]{postfix}")
    if mode in ("lines", "lines!"):
        return tqdm(total=total, desc=desc, unit=unit, file=_Lines(stream), mininterval=LOG_INTERVAL,
                    maxinterval=max(LOG_INTERVAL, 10.0), delay=LOG_INTERVAL if mode == "lines" else 0.0,
                    leave=True, ascii=True,
                    bar_format="{desc}: {percentage:3.0f}%" + counts + " after {elapsed}, {remaining} left" + rate
                               + "{postfix}")
    return tqdm(total=total, disable=True)


def advance_to(bar, value, postfix: str | None = None) -> None:
    """Move ``bar`` to ``value`` (an absolute count) with the text ``postfix`` after it."""
    if postfix is not None:
        bar.set_postfix_str(postfix, refresh=False)
    bar.update(value - bar.n)


@contextlib.contextmanager
def stdout_to_stderr(enabled: bool = True):
    """Within the block, what C libraries (gmsh) write to the process's stdout goes to stderr, so that their
    log never mixes with a command's summary on stdout."""
    if not enabled:
        yield
        return
    sys.stdout.flush()
    try:
        saved = os.dup(1)
    except (OSError, ValueError):  # no file descriptor 1: nothing to redirect
        yield
        return
    try:
        os.dup2(2, 1)
        yield
    finally:
        with contextlib.suppress(OSError, ValueError):
            sys.stdout.flush()
        os.dup2(saved, 1)
        os.close(saved)
