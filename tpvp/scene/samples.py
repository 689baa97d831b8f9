"""The real Pheno4D scans bundled with the package (MIT licence, see tpvp/data/pheno4d)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tpvp.errors import ConfigError
from tpvp.io import read_point_cloud

DATA = Path(__file__).resolve().parent.parent / "data" / "pheno4d"
SAMPLES = {
    "tomato_0305": "tomato_0305.xyz.gz",
    "tomato_0306": "tomato_0306.xyz.gz",
    "maize_0313": "maize_0313.ply.gz",
}


def sample_path(name: str) -> Path:
    """Path of a bundled sample (gzip-compressed; :func:`tpvp.io.read_point_cloud` reads it as it is)."""
    if name not in SAMPLES:
        raise ConfigError(f"unknown bundled sample {name!r}; choose one of {', '.join(SAMPLES)}")
    return DATA / SAMPLES[name]


def load_sample(name: str) -> np.ndarray:
    """Points of a bundled scan, converted to metres (scanner frame)."""
    return read_point_cloud(sample_path(name), units="mm")
