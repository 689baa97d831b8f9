"""The experiments' runner: cases x methods from a registry, each (case, method) cached on its own,
run here, on local worker processes or on a Dask cluster (:mod:`tpvp.parallel`).

A *case* (a plant pair, a row pair) holds several methods; all methods of a case run in one
process so they share its scene (ground truth, oracle) and, through :func:`shared`, the work
several methods need (warm-up and registration, candidates). What differs between the plant and
the row experiments is one :class:`Experiment`: its methods, how a case builds its scene, the
columns every row gets from the scene, the order of the raw table, and its tables, the paper's
values and its figures (written by :func:`tpvp.experiments.results.write_results`).
"""

from __future__ import annotations

import hashlib
import json
import os
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable

import pandas as pd

from tpvp import __version__
from tpvp.config_loading import to_dict
from tpvp.errors import ConfigError
from tpvp.io import atomic_write_bytes
from tpvp.parallel import run_cases
from tpvp.provenance import code_digest
from tpvp.registry import Registry, load_reference

# Cached rows are keyed on the case, the method, the resolved configuration and the digest of the
# code (tpvp.provenance.code_digest): a row computed by other code is never read back as this
# code's. Bump this when the rows' meaning changes without a code change (e.g. a new column's data).
RESULTS_VERSION = 2


def experiment_cache() -> Path:
    """The experiments' per-task cache (``$TPVP_EXPERIMENT_CACHE`` or ``outputs/cache`` of the
    repository, as the ``tpvp experiments`` commands use from its root)."""
    return Path(os.environ.get("TPVP_EXPERIMENT_CACHE") or Path(__file__).resolve().parents[2] / "outputs" / "cache")


@dataclass(frozen=True)
class Experiment:
    """One family of experiments. ``scene(case, case_config, cache_dir)``: the case's scene (a
    module-level function, memoised by the caller); ``scene_columns(scene)``: columns added to
    every row; ``order``: the raw table's sort columns (``method`` sorts in the order asked).
    What its results folder holds (:func:`tpvp.experiments.results.write_results`): ``tables(raw)``
    (name -> aggregated table), ``paper`` (file name -> the paper's values) and
    ``figures(folder, raw, tables, config, **options)``."""

    name: str
    methods: Registry
    scene: Callable
    order: tuple
    scene_columns: Callable | None = None
    tables: Callable = dict
    paper: dict = field(default_factory=dict)
    figures: Callable | None = None
    reference: str = ""  # "module:attribute" where it is defined: worker processes import it from there

    def __reduce__(self):
        # The registry holds closures that cannot be pickled; a worker finds the experiment by name.
        if not self.reference:
            raise ValueError(f"{self.name}: an Experiment sent to worker processes needs its reference")
        return experiment_at, (self.reference,)


def experiment_at(reference: str) -> Experiment:
    """The :class:`Experiment` at ``"module:attribute"``."""
    return load_reference(reference)


def task_key(case, method: str, config) -> str:
    """The cache key of one (case, method): the case, the method, the case's resolved configuration
    and the code that computes it."""
    payload = {"case": asdict(case), "method": method, "config": to_dict(case.config(config)),
               "version": __version__, "results": RESULTS_VERSION, "code": code_digest()}
    return hashlib.sha256(json.dumps(payload, sort_keys=True, default=str).encode()).hexdigest()[:20]


def cached_table(path, compute):
    """The table at ``path`` (Parquet) when it is there and readable, else ``compute()`` written
    there atomically (no cache when ``path`` is None). A damaged entry is recomputed and replaced."""
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


_memo: dict = {"scene": None}


def shared(scene, key, compute):
    """This process's memo of what several methods of one scene need: ``compute()`` once per
    ``key`` while the scene stays the same (a new scene clears it)."""
    if _memo["scene"] is not scene:
        _memo.clear()
        _memo["scene"] = scene
    if key not in _memo:
        _memo[key] = compute()
    return _memo[key]


def clear_shared() -> None:
    """Forget what :func:`shared` holds (a test that runs a method alone)."""
    _memo.clear()
    _memo["scene"] = None


def run_task(experiment: Experiment, case, method: str, config, cache_dir=None) -> pd.DataFrame:
    """The rows of one (case, method), from the cache when present; written to it otherwise."""
    path = Path(cache_dir) / f"{task_key(case, method, config)}.parquet" if cache_dir else None
    function = experiment.methods.get(method)

    def compute():
        case_config = case.config(config)
        t0 = time.perf_counter()
        scene = experiment.scene(case, case_config, str(cache_dir) if cache_dir else None)
        rows = function(scene, case_config)
        seconds = time.perf_counter() - t0
        extra = experiment.scene_columns(scene) if experiment.scene_columns else {}
        return pd.DataFrame([{**case.labels(), "method": method, **row, **extra, "seconds_task": seconds}
                             for row in rows])

    return cached_table(path, compute)


def run_case_tasks(case, experiment: Experiment, methods, config, cache_dir=None) -> list:
    """Every method of one case in this process, each method's rows cached on their own."""
    return [run_task(experiment, case, method, config, cache_dir) for method in methods]


def run_experiments(experiment: Experiment, cases, methods, config, cache_dir=None, workers: int = 1,
                    progress: bool = True, scheduler=None) -> pd.DataFrame:
    """Every (case, method) task, here, in ``workers`` processes or on a Dask cluster when
    ``scheduler`` is given (an address ``tcp://host:8786`` or a ``distributed.Client``; the cache
    folder must then be one the workers share); the raw table of all rows."""
    methods = list(methods)
    for method in methods:
        experiment.methods.get(method)  # an unknown name fails before any work
    cases = list(cases)
    if not cases or not methods:
        raise ConfigError("no task: the case list or the method list is empty")
    tables = run_cases(run_case_tasks, cases, (experiment, methods, config, cache_dir), len(methods),
                       workers=workers, scheduler=scheduler, progress=progress, desc=experiment.name)
    raw = pd.concat(tables, ignore_index=True)
    order = {m: i for i, m in enumerate(methods)}
    return raw.sort_values(list(experiment.order), key=lambda c: c.map(order) if c.name == "method" else c,
                           kind="stable").reset_index(drop=True)


def cached_experiments(experiment: Experiment, cases, methods, config, cache_dir=None) -> pd.DataFrame | None:
    """:func:`run_experiments`' table read from the cache when every (case, method) is there,
    else None (nothing is computed)."""
    cases, methods = list(cases), list(methods)
    if not all_cached(cache_dir, (task_key(case, method, config) for case in cases for method in methods)):
        return None
    return run_experiments(experiment, cases, methods, config, cache_dir=cache_dir, progress=False)
