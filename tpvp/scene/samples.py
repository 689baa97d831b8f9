"""The real Pheno4D scans bundled with the package (MIT licence, see tpvp/data/pheno4d)."""

from __future__ import annotations

import gzip
import os
import tempfile
from pathlib import Path

import numpy as np

from tpvp.errors import ConfigError

DATA = Path(__file__).resolve().parent.parent / "data" / "pheno4d"
SAMPLES = {
    "tomato_0305": "tomato_0305.xyz.gz",
    "tomato_0306": "tomato_0306.xyz.gz",
    "maize_0313": "maize_0313.ply.gz",
}


def sample_path(name: str) -> Path:
    """Path of an uncompressed copy of a bundled sample (unpacked once into a cache folder)."""
    if name not in SAMPLES:
        raise ConfigError(f"unknown bundled sample {name!r}; choose one of {', '.join(SAMPLES)}")
    cache = Path(os.environ.get("TPVP_CACHE", Path(tempfile.gettempdir()) / "tpvp-cache"))
    target = cache / SAMPLES[name][: -len(".gz")]
    if not target.is_file():
        cache.mkdir(parents=True, exist_ok=True)
        with gzip.open(DATA / SAMPLES[name], "rb") as src:
            payload = src.read()
        fd, tmp = tempfile.mkstemp(dir=cache, prefix=target.name, suffix=".part")
        with os.fdopen(fd, "wb") as out:
            out.write(payload)
        os.replace(tmp, target)
    return target


def load_sample(name: str) -> np.ndarray:
    """Points of a bundled scan, converted to metres (scanner frame)."""
    from tpvp.io import read_point_cloud

    return read_point_cloud(sample_path(name), units="mm")
