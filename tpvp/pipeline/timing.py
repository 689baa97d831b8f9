"""How the planner times its stages, plants and rows alike."""

from __future__ import annotations

import time
from contextlib import contextmanager


@contextmanager
def timed(timings: dict, key: str, say, stage: str):
    """Reports ``stage`` to ``say`` (a progress callback) and times the block into ``timings[key]``."""
    say(stage)
    t = time.perf_counter()
    yield
    timings[key] = time.perf_counter() - t
