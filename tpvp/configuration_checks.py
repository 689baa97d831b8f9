"""Checks that the configuration dataclasses of several stages share (one line naming the key)."""

from __future__ import annotations

from tpvp.errors import ConfigError


def check_positive(obj, *names):
    for name in names:
        v = getattr(obj, name)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not (v > 0 and v < float("inf")):
            raise ConfigError(f"{name} must be a positive number, got {v!r}")


def check_integer(obj, name, minimum):
    v = getattr(obj, name)
    if isinstance(v, bool) or not isinstance(v, int) or v < minimum:
        raise ConfigError(f"{name} must be an integer >= {minimum}, got {v!r}")
