"""Deterministic fault injection for the fault tests: fail, interrupt or pause at the N-th write step.

Every write step of the library calls :func:`checkpoint` (each atomic file write before its rename,
each step of a folder commit, and the moment just after a commit). Normally it only counts. Under
:func:`inject` - or with the environment variable ``TPVP_FAULT=interrupt@N`` / ``enospc@N`` /
``pause@N`` for a subprocess - the N-th step (from 1) sends SIGINT to the process (as a Ctrl-C
would; the commit holds it back like a real one), raises ``OSError(ENOSPC)`` as a full disk would,
or sleeps ``TPVP_FAULT_PAUSE_S`` seconds (default 2: a slow disk, to make two commands overlap;
with ``TPVP_FAULT_PAUSE_UNTIL=FILE``, until that file exists, at most as long).
"""

from __future__ import annotations

import contextlib
import errno
import os
import signal
import time

KINDS = ("interrupt", "enospc", "pause")
#: Steps that allocate no space: a full disk does not fail them.
_NO_SPACE = ("commit", "swap", "published")
_state = {"kind": None, "at": 0, "count": 0}


def _from_environment() -> None:
    spec = os.environ.get("TPVP_FAULT", "")
    kind, _, at = spec.partition("@")
    if kind in KINDS and at.isdigit():
        _state.update(kind=kind, at=int(at), count=0)


def checkpoint(step: str) -> None:
    """Count one write step; trigger the injected fault when its number comes."""
    if _state["kind"] is None:
        return
    _state["count"] += 1
    if _state["count"] != _state["at"] or _state["kind"] not in KINDS:
        return
    if _state["kind"] == "interrupt":
        os.kill(os.getpid(), signal.SIGINT)
    elif _state["kind"] == "pause":
        until = os.environ.get("TPVP_FAULT_PAUSE_UNTIL")  # a file another process creates to let it go on
        deadline = time.monotonic() + float(os.environ.get("TPVP_FAULT_PAUSE_S", "2"))
        while time.monotonic() < deadline and not (until and os.path.exists(until)):
            time.sleep(0.01)
    elif step not in _NO_SPACE:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))


def steps() -> int:
    """Write steps counted since the last :func:`inject` (to enumerate every N of a run)."""
    return _state["count"]


@contextlib.contextmanager
def inject(kind: str | None, at: int = 0):
    """Within the block, the ``at``-th write step fails with ``kind`` (None: only count steps)."""
    if kind is not None and kind not in KINDS:
        raise ValueError(f"fault kind must be one of {KINDS}, got {kind!r}")
    saved = dict(_state)
    _state.update(kind=kind or "count", at=at, count=0)
    try:
        yield
    finally:
        _state.update(saved)


_from_environment()
