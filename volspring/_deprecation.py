"""Old public names that keep working for one release, with a warning naming the new one.

A module lists its renamed names in a module-level ``__getattr__`` (PEP 562)::

    def __getattr__(name):
        return deprecated_alias(__name__, name, {"SpringModel": ("volspring.Model", Model)})

and an old function that still runs (returning an old type) calls :func:`warn_deprecated` first::

    def assemble_bodies(bodies):
        warn_deprecated(f"{__name__}.assemble_bodies", "volspring.Model.from_bodies")

Every rename is recorded in CHANGELOG.md.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from typing import Any

__all__ = ["deprecated_alias", "warn_deprecated"]

#: The release after which the old names go.
REMOVED_IN = "0.3.0"


def deprecated_alias(module: str, name: str, renamed: dict):
    """The object behind an old name, with a DeprecationWarning; AttributeError for unknown names.

    Parameters
    ----------
    module : str
        the module asked (its ``__name__``)
    name : str
        the attribute asked for
    renamed : dict
        old name -> (new canonical path, object)
    """
    if name not in renamed:
        raise AttributeError(f"module {module!r} has no attribute {name!r}")
    new_path, value = renamed[name]
    warn_deprecated(f"{module}.{name}", new_path, stacklevel=4)
    return value


def warn_deprecated(old: str, new_path: str, *, stacklevel: int = 3) -> None:
    """A DeprecationWarning saying ``old`` goes in volspring ``REMOVED_IN`` and what to use instead.

    Parameters
    ----------
    old : str
        the old name, with its module (``"volspring.collision.assemble_bodies"``)
    new_path : str
        what to use instead
    stacklevel : int
        as for :func:`warnings.warn`; the default 3 points at the caller of the function that calls this one
    """
    warnings.warn(f"{old} is deprecated and will be removed in volspring {REMOVED_IN}; use {new_path}",
                  DeprecationWarning, stacklevel=stacklevel)


def moved_names(module: str, new_module: str, names) -> Callable[[str], Any]:
    """A module ``__getattr__`` for names that moved to ``new_module`` (warning once per access)."""
    import importlib

    def __getattr__(name):
        if name not in names:
            raise AttributeError(f"module {module!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(new_module), name)
        return deprecated_alias(module, name, {name: (f"{new_module}.{name}", value)})

    return __getattr__
