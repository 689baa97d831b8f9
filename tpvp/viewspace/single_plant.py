"""Positions of a single-plant view space as a bare ``(V, 3)`` array (for scripts and benchmarks)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tpvp.viewspace.space import get_view_space


def load_view_space(name_or_path: str | Path = "hemisphere", radius: float | None = None) -> np.ndarray:
    """Camera positions ``(V, 3)`` in metres relative to the plant centre (see
    :func:`tpvp.viewspace.space.get_view_space` for the names). ``radius`` moves the positions onto a
    sphere of that radius around their look-at (the bundled files use 0.4 m)."""
    space = get_view_space(name_or_path)
    if radius is not None:
        space = space.with_radius(radius)
    return np.array(space.positions)
