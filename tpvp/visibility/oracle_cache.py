"""The greenhouse oracle kept on disk: computing it is the slowest step of a row case (minutes at
1 cm), and the same scene is planned many times (every covering voxel, every baseline).

An entry is keyed by the voxels, the viewpoints, the resolution, the range and the oracle's own
source code, so a changed scene, configuration or oracle never reuses an old set.
"""

from __future__ import annotations

import hashlib
import io
import os
from pathlib import Path

import numpy as np

from tpvp.io.atomic import atomic_write_bytes
from tpvp.visibility import oracle
from tpvp.visibility.oracle import greenhouse_oracle


def default_cache_dir() -> Path:
    """``$TPVP_CACHE_DIR`` or ``~/.cache/tpvp``: where slow, reusable results (oracles) are kept."""
    return Path(os.environ.get("TPVP_CACHE_DIR") or Path.home() / ".cache" / "tpvp")


def oracle_key(grid, viewpoints, max_range: float) -> str:
    """The cache key of the oracle of ``grid`` from ``viewpoints`` within ``max_range``."""
    digest = hashlib.sha256()
    for part in (np.ascontiguousarray(grid.keys, dtype=np.int64).tobytes(),
                 np.ascontiguousarray(grid.countable).tobytes(),
                 np.ascontiguousarray(viewpoints, dtype=np.float64).tobytes(),
                 repr((float(grid.resolution), float(max_range))).encode(),
                 Path(oracle.__file__).read_bytes()):  # a changed oracle never reuses old sets
        digest.update(hashlib.sha256(part).digest())
    return digest.hexdigest()[:24]


def cached_oracle(grid, viewpoints, max_range: float, cache_dir=None, progress=None) -> tuple[np.ndarray, bool]:
    """The greenhouse oracle of ``grid`` from ``viewpoints``, read from ``cache_dir/oracle/`` when
    this scene and configuration were computed before, computed and stored atomically otherwise
    (``cache_dir`` None: :func:`default_cache_dir`; False: no cache). Returns ``(voxel ids, whether
    it came from the cache)``."""
    path = None
    if cache_dir is not False:
        folder = Path(cache_dir) if cache_dir is not None else default_cache_dir()
        path = folder / "oracle" / f"{oracle_key(grid, viewpoints, max_range)}.npy"
        if path.is_file():
            try:
                return np.load(path, allow_pickle=False), True
            except (OSError, ValueError):
                pass  # a damaged entry is recomputed and replaced
    ids = greenhouse_oracle(grid, viewpoints, max_range, progress=progress)
    if path is not None:
        buffer = io.BytesIO()
        np.save(buffer, ids)
        atomic_write_bytes(path, buffer.getvalue())
    return ids, False
