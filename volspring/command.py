"""``volspring``: one command whose subcommands (``mesh``, ``sim``, ``validate``, ...) each package registers.

``volspring mesh ...`` runs :func:`meshing.cli.main`, ``volspring sim ...`` :func:`volspring.cli.main` and
``volspring validate ...`` :func:`validation.cli.main`, with the rest of the command line; ``python -m volspring``
is the same command. The subcommands are found through the entry points of the group :data:`GROUP` (each package
names its own in ``pyproject.toml``), so this module imports no layer above its own: a package installed later
adds its subcommand (``sweep``) without a change here. The scripts ``volspring-mesh``, ``volspring-sim`` and
``volspring-validate`` are aliases of the subcommands.

Every subcommand has ``--version``, ``-q/--quiet``, ``-v/--verbose`` and ``--progress/--no-progress``, and the same
exit statuses (:mod:`meshing._command_line`): 0 done, 1 the run failed, 2 a bad command line or bad input,
3 diverged, 130 interrupted (143 SIGTERM, 129 SIGHUP).

Examples
--------
>>> from volspring.command import commands, main
>>> list(commands())  # in help order: along the data path
['mesh', 'sim', 'validate', 'sweep']
>>> main(["--version"])  # doctest: +ELLIPSIS
volspring ...
0
"""

from __future__ import annotations

import difflib
import importlib
import sys

from meshing._command_line import (EXIT_DONE, EXIT_FAILED, EXIT_STATUS_EPILOG, EXIT_USAGE, error_line, invoked_as,
                                   version_text)
from collections.abc import Sequence

__all__ = ["GROUP", "commands", "main"]

PROG = "volspring"
#: The entry-point group of the subcommands: ``NAME = "package.module:main"``, ``main(argv) -> exit status``.
GROUP = "volspring.commands"
#: The order of the subcommands in ``--help`` (along the data path); others follow by name.
ORDER = ("mesh", "sim", "validate", "sweep")


def commands() -> dict:
    """The subcommands installed: name -> :class:`importlib.metadata.EntryPoint` (not loaded), in help order."""
    from importlib.metadata import entry_points

    found = {point.name: point for point in entry_points(group=GROUP)}
    return {name: found[name] for name in sorted(found, key=lambda name: (ORDER.index(name) if name in ORDER
                                                                          else len(ORDER), name))}


def _summary(point) -> str:
    """The first sentence of the module docstring of a subcommand, without its ``name``: prefix."""
    try:
        text = (importlib.import_module(point.module).__doc__ or "").strip()
    except ImportError as error:
        return f"(cannot be loaded: {error})"
    first = " ".join(text.split("\n\n")[0].split())
    return first.split(": ", 1)[1] if first.startswith("``") and ": " in first else first


def _help(found) -> str:
    width = max((len(name) for name in found), default=0)
    rows = "\n".join(f"  {name.ljust(width)}  {_summary(point)}" for name, point in found.items())
    return (f"usage: {PROG} COMMAND [OPTIONS ...]\n\n"
            "Volumetric soft bodies as tetrahedral mass-spring models, checked against FEM.\n\n"
            f"commands:\n{rows}\n\n"
            f"`{PROG} COMMAND --help` lists the options of a command; each is also installed as {PROG}-COMMAND.\n\n"
            "options:\n  -h, --help  show this help message and exit\n  --version   print the version and exit\n\n"
            + EXIT_STATUS_EPILOG.replace("PROG", f"{PROG}-COMMAND"))


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``volspring COMMAND ...`` with ``argv`` (default ``sys.argv[1:]``); returns the exit status.

    ``COMMAND`` is a subcommand of :func:`commands`, run with the rest of ``argv``; ``--help`` lists them,
    ``--version`` prints the version. A missing or unknown command is one line on stderr, exit status 2.
    """
    argv = sys.argv[1:] if argv is None else [str(token) for token in argv]
    found = commands()
    if not argv:
        return error_line(PROG, f"a command is required: {', '.join(found)} (see {PROG} --help)", EXIT_USAGE)
    name, rest = argv[0], argv[1:]
    if name in ("-h", "--help"):
        print(_help(found))
        return EXIT_DONE
    if name == "--version":
        print(version_text(PROG))
        return EXIT_DONE
    if name not in found:
        close = difflib.get_close_matches(name, list(found), n=1)
        hint = f"; did you mean {close[0]}?" if close else ""
        what = "option" if name.startswith("-") else "command"
        return error_line(PROG, f"unknown {what} {name!r}{hint} (commands: {', '.join(found)})", EXIT_USAGE)
    try:
        run = found[name].load()
    except ImportError as error:
        return error_line(PROG, f"the command {name} cannot be loaded ({found[name].value}): {error}", EXIT_FAILED)
    with invoked_as(f"{PROG} {name}"):  # its usage, --version and messages say "volspring sim", as typed
        return run(rest)
