"""Running experiment cases: in this process, on local worker processes or on a Dask cluster.

A *case* (a plant pair, a row pair) holds several methods; all methods of a case run in one
process so they share its scene (ground truth, oracle, registration), and each (case, method)
caches its own rows. The plant and row experiments differ only in what a case task computes.
"""

from __future__ import annotations

from pathlib import Path

from tpvp.io import atomic_write_bytes
from tpvp.parallel import run_cases  # noqa: F401 (the experiments' runner)

# Cached rows are keyed on the case, the method and the resolved configuration, not on the source:
# a refactor keeps every cache. Bump this when a change alters any result (checked with
# benchmarks/reference_outputs.sh + benchmarks/compare_outputs.py before and after).
RESULTS_VERSION = 1


def cached_table(path, compute):
    """The table at ``path`` (Parquet) when it is there and readable, else ``compute()`` written
    there atomically (no cache when ``path`` is None). A damaged entry is recomputed and replaced."""
    import pandas as pd

    if path is not None and Path(path).is_file():
        try:
            return pd.read_parquet(path)
        except (OSError, ValueError):
            pass
    table = compute()
    if path is not None:
        atomic_write_bytes(path, table.to_parquet(index=False))
    return table


def all_cached(cache_dir, keys) -> bool:
    """Whether every task key has its table in ``cache_dir`` (nothing is read or computed)."""
    return cache_dir is not None and all((Path(cache_dir) / f"{key}.parquet").is_file() for key in keys)
