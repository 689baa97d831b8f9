"""Named choices of a pipeline stage: a registry maps a name to a factory or function.

A new method is one function plus one ``@REGISTRY.register("name")`` line; configurations and the
CLI refer to it by name, and the experiment code never changes.

Packages above the stages add methods without a stage importing them: a *plugin* module registers
its methods when imported, and a registry imports the plugins the first time it is asked for a name
it does not hold (or for the list of names). Plugins are the prior-guided NBV (:mod:`tpvp.nbv.prior`:
its scipy and visibility code stay out of ``import tpvp.nbv``), tpvp's learned planners
(:mod:`tpvp.learning.methods`) and any module another package declares under the entry-point group
``tpvp.plugins`` (``[project.entry-points."tpvp.plugins"] name = "package.module"``).
"""

from __future__ import annotations

import importlib
from importlib.metadata import entry_points

from tpvp.errors import ConfigError

BUILTIN_PLUGINS = ("tpvp.nbv.prior", "tpvp.learning.methods")
PLUGIN_GROUP = "tpvp.plugins"
_plugins_loaded = False


def load_reference(reference: str):
    """The object a ``"module:attribute"`` reference names, its module imported (a command's
    options, a drawing, an experiment sent to worker processes)."""
    module, _, attribute = reference.partition(":")
    return getattr(importlib.import_module(module), attribute)


def load_plugins() -> None:
    """Import every plugin module once (each registers its methods)."""
    global _plugins_loaded
    if _plugins_loaded:
        return
    _plugins_loaded = True
    modules = list(BUILTIN_PLUGINS)
    modules += [e.value for e in entry_points(group=PLUGIN_GROUP) if e.value not in modules]
    for module in modules:
        importlib.import_module(module)


class Registry:
    """Names -> objects (functions or factories) of one kind, e.g. ``Registry("NBV method")``."""

    def __init__(self, kind: str):
        self.kind = kind
        self._entries: dict[str, object] = {}
        self._help: dict[str, str] = {}
        self._defaults: list[str] = []  # registration order

    def register(self, name: str, help: str = "", default: bool = False):
        """Decorator: ``@NBV_METHODS.register("geometric", "one line of help")``. ``default``: the
        entry is one of :meth:`defaults` (e.g. a method the paper's protocol runs when none is named)."""
        def add(obj):
            if name in self._entries:
                raise ValueError(f"{self.kind} {name!r} is registered twice")
            self._entries[name] = obj
            self._help[name] = help or ((obj.__doc__ or "").strip().splitlines() or [""])[0]
            if default:
                self._defaults.append(name)
            return obj
        return add

    def unregister(self, name: str) -> None:
        """Remove an entry (tests that register a temporary method)."""
        self._entries.pop(name, None)
        self._help.pop(name, None)
        if name in self._defaults:
            self._defaults.remove(name)

    def defaults(self) -> tuple[str, ...]:
        """The entries registered with ``default=True``, in registration order."""
        load_plugins()
        return tuple(self._defaults)

    def describe(self) -> str:
        """One line for a command's help: the defaults, then the other names."""
        others = [name for name in self.names() if name not in self._defaults]
        return f"default: {', '.join(self.defaults())}" + (f"; also: {', '.join(others)}" if others else "")

    def get(self, name: str):
        """The entry called ``name``; an unknown name is one :class:`ConfigError` line listing the choices."""
        if isinstance(name, str) and name not in self._entries:
            load_plugins()
        try:
            return self._entries[name]
        except (KeyError, TypeError):
            raise ConfigError(f"unknown {self.kind} {name!r}; choose one of {', '.join(self.names())}") from None

    def names(self) -> list[str]:
        load_plugins()
        return sorted(self._entries)

    def help(self, name: str) -> str:
        return self._help.get(name, "")

    def __contains__(self, name) -> bool:
        if name not in self._entries:
            load_plugins()
        return name in self._entries
