"""Named choices of a pipeline stage: a registry maps a name to a factory or function.

A new method is one function plus one ``@REGISTRY.register("name")`` line; configurations and the
CLI refer to it by name, and the experiment code never changes.
"""

from __future__ import annotations

from tpvp.errors import ConfigError


class Registry:
    """Names -> objects (functions or factories) of one kind, e.g. ``Registry("NBV method")``."""

    def __init__(self, kind: str):
        self.kind = kind
        self._entries: dict[str, object] = {}
        self._help: dict[str, str] = {}

    def register(self, name: str, help: str = ""):
        """Decorator: ``@NBV_METHODS.register("geometric", "one line of help")``."""
        def add(obj):
            if name in self._entries:
                raise ValueError(f"{self.kind} {name!r} is registered twice")
            self._entries[name] = obj
            self._help[name] = help or ((obj.__doc__ or "").strip().splitlines() or [""])[0]
            return obj
        return add

    def unregister(self, name: str) -> None:
        """Remove an entry (tests that register a temporary method)."""
        self._entries.pop(name, None)
        self._help.pop(name, None)

    def get(self, name: str):
        """The entry called ``name``; an unknown name is one :class:`ConfigError` line listing the choices."""
        try:
            return self._entries[name]
        except (KeyError, TypeError):
            raise ConfigError(f"unknown {self.kind} {name!r}; choose one of {', '.join(self.names())}") from None

    def names(self) -> list[str]:
        return sorted(self._entries)

    def help(self, name: str) -> str:
        return self._help.get(name, "")

    def __contains__(self, name) -> bool:
        return name in self._entries
