"""Running experiment cases: in this process, on local worker processes or on a Dask cluster.

A *case* (a plant pair, a row pair) holds several methods; all methods of a case run in one
process so they share its scene (ground truth, oracle, registration), and each (case, method)
caches its own rows. The plant and row experiments differ only in what a case task computes.
"""

from __future__ import annotations

import hashlib
from concurrent.futures import ProcessPoolExecutor, as_completed
from functools import lru_cache
from multiprocessing import get_context
from pathlib import Path

from tpvp.errors import ConfigError

SCHEDULER_TIMEOUT_S = 30  # connecting to a Dask scheduler


@lru_cache(maxsize=1)
def code_fingerprint() -> str:
    """A hash of the package's source files: a code change without a version change must not
    reuse cached rows either."""
    digest = hashlib.sha256()
    root = Path(__file__).resolve().parent.parent
    for path in sorted(root.rglob("*.py")):
        digest.update(str(path.relative_to(root)).encode() + b"\0" + path.read_bytes())
    return digest.hexdigest()[:16]


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
        from tpvp.io import atomic_write_bytes

        atomic_write_bytes(path, table.to_parquet(index=False))
    return table


def all_cached(cache_dir, keys) -> bool:
    """Whether every task key has its table in ``cache_dir`` (nothing is read or computed)."""
    return cache_dir is not None and all((Path(cache_dir) / f"{key}.parquet").is_file() for key in keys)


def run_cases(case_tasks, cases, arguments: tuple, tasks_per_case: int, workers: int = 1, scheduler=None,
              progress: bool = True, desc: str = "experiments") -> list:
    """``case_tasks(case, *arguments)`` (a module-level function returning a list of tables) for
    every case: here when ``workers <= 1``, in ``workers`` processes, or on a Dask cluster when
    ``scheduler`` is given (an address ``tcp://host:8786`` or a ``distributed.Client``; a cache
    folder must then be one the workers share). Returns all tables, in completion order."""
    from tqdm.auto import tqdm

    cases = list(cases)
    tables = []
    client, own = _connect(scheduler) if scheduler is not None else (None, False)
    bar = tqdm(total=len(cases) * tasks_per_case, desc=desc, unit="task", disable=not progress)

    def collect(case_tables):
        tables.extend(case_tables)
        bar.update(len(case_tables))

    try:
        if client is not None:
            from distributed import as_completed as completed

            futures = [client.submit(case_tasks, case, *arguments, pure=False) for case in cases]
            for future in completed(futures):
                collect(future.result())
        elif workers <= 1:
            for case in cases:
                collect(case_tasks(case, *arguments))
        else:
            with ProcessPoolExecutor(max_workers=workers, mp_context=get_context("forkserver")) as pool:
                futures = [pool.submit(case_tasks, case, *arguments) for case in cases]
                for future in as_completed(futures):
                    collect(future.result())
    finally:
        if own:
            client.close()
        bar.close()
    return tables


def _connect(scheduler):
    """``(client, whether we opened it)`` for a Dask scheduler address or an existing Client."""
    try:
        from distributed import Client
    except ImportError:
        raise ConfigError("--scheduler needs the package 'distributed' (pip install distributed)") from None
    if isinstance(scheduler, Client):
        return scheduler, False
    try:
        return Client(scheduler, timeout=SCHEDULER_TIMEOUT_S), True
    except (OSError, TimeoutError) as exc:
        raise ConfigError(f"cannot reach the Dask scheduler {scheduler!r}: {exc}") from None
