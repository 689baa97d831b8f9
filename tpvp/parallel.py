"""Running independent tasks: in this process, on local worker processes or on a Dask cluster.

The experiments run one task per case (a plant pair, a row pair); the learned planners' dataset
one per plant. A task is a module-level function returning a list; results arrive in completion order.
"""

from __future__ import annotations

import gc
import multiprocessing.util
import os
import signal
from concurrent.futures import ProcessPoolExecutor, as_completed
from multiprocessing import get_context

from tpvp.errors import ConfigError

SCHEDULER_TIMEOUT_S = 30  # connecting to a Dask scheduler
STOP_TIMEOUT_S = 5  # a terminated worker's time to exit before it is killed


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
            pool = ProcessPoolExecutor(max_workers=workers, mp_context=get_context("forkserver"),
                                       initializer=_worker_signals)
            try:
                futures = [pool.submit(case_tasks, case, *arguments) for case in cases]
                for future in as_completed(futures):
                    collect(future.result())
            except BaseException:
                _stop(pool)
                raise
            pool.shutdown()
    finally:
        if own:
            client.close()
        bar.close()
    return tables


def _stop(pool: ProcessPoolExecutor) -> None:
    """End a pool at once (Ctrl-C, a failed task): pending tasks cancelled, running ones killed.
    Shutting down as ``with`` does waits for the running tasks, minutes for a season's case;
    what they had cached is whole (atomic writes), so a resumed run is exact."""
    processes = list((getattr(pool, "_processes", None) or {}).values())
    for process in processes:
        process.terminate()
    for process in processes:
        process.join(timeout=STOP_TIMEOUT_S)
        if process.is_alive():
            process.kill()
    # with its workers gone the pool's manager thread ends at once; waiting for it releases the
    # queues' semaphores (else the resource tracker warns of leaked ones at exit)
    pool.shutdown(wait=True, cancel_futures=True)
    gc.collect()  # the queues' finalizers unlink their semaphores now: a Ctrl-C'd command ends with os._exit


def _worker_signals() -> None:
    """A worker's signals: Ctrl-C (sent to the whole terminal's process group) is left to the
    parent, which ends the workers with SIGTERM (:func:`_stop`); on SIGTERM a worker runs its
    finalizers before it exits, which unlink the semaphores numba and tqdm made in it (else the
    resource tracker reports them as leaked)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, _exit_cleanly)


def _exit_cleanly(signum, frame) -> None:
    multiprocessing.util._exit_function()  # what a worker's normal exit runs
    os._exit(128 + signum)


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
