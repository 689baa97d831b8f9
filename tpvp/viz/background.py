"""Figures and recordings drawn beside the computation.

A command that ends with drawings (``tpvp plan``: the plan and coverage figures, the rerun
recording; about a second) opens :func:`drawing_pool` before its work: one process forked then
loads the drawing libraries while the plan is computed, and once the plan is there draws its
files concurrently, in processes forked from it. Drawings are calls ``("module:function", args,
kwargs)`` of functions that write one file each (through the atomic writer), named so that the
process asking for them need not load matplotlib: :func:`draw` runs them in the pool, or here
without one.
"""

from __future__ import annotations

import importlib
import multiprocessing
import signal
import traceback
from concurrent.futures import ProcessPoolExecutor
from contextlib import contextmanager

from tpvp.errors import TpvpError
from tpvp.registry import load_reference

WORKERS = 2
#: What the drawing process loads while the plan is computed.
PRELOADED = ("tpvp.viz.figures", "tpvp.viz.rows", "tpvp.viz.recording", "rerun")
_FORK = multiprocessing.get_context("fork") if "fork" in multiprocessing.get_all_start_methods() else None


class DrawingPool:
    """The drawing process of :func:`drawing_pool`: it takes a list of calls, draws them in
    ``workers`` processes forked from itself and answers with their results, in order."""

    def __init__(self, workers: int):
        self._connection, theirs = _FORK.Pipe()
        self._process = _FORK.Process(target=_serve, args=(theirs, workers, self._connection),
                                      name="tpvp-drawing")
        self._process.start()
        theirs.close()

    def draw(self, calls) -> list:
        try:
            self._connection.send(list(calls))
            ok, answer = self._connection.recv()
        except (EOFError, OSError):  # killed from outside (out of memory, a signal to it alone)
            raise TpvpError(f"the drawing process ended (exit status {self._process.exitcode}) before "
                            "the figures were drawn") from None
        if isinstance(answer, BaseException):
            raise answer
        if not ok:
            raise TpvpError(f"drawing the figures failed: {answer}")
        return answer

    def close(self) -> None:
        """Wait for the drawing in progress (its files are whole or absent), then end the process."""
        try:
            self._connection.send(None)
        except OSError:  # it has already ended (a signal to the whole process group)
            pass
        self._process.join()
        self._connection.close()


def _serve(connection, workers: int, parents=None) -> None:
    # The fork copied the parent's end of the pipe too: closed, the parent's end is the parent's
    # alone, and a parent that ends without closing the pool (killed) ends this process's input.
    if parents is not None:
        parents.close()
    # Ctrl-C reaches the parent, which closes the pool; SIGTERM (to the whole group) ends it at once.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    for module in PRELOADED:  # the reason to start early
        importlib.import_module(module)
    _warm_up()
    with ProcessPoolExecutor(workers, mp_context=_FORK) as pool:  # forked from here: nothing to load
        while (calls := _receive(connection)) is not None:
            try:
                answer = (True, [future.result() for future in [pool.submit(_draw, *call) for call in calls]])
            except Exception as exc:  # noqa: BLE001 - raised again by the parent (a full disk stays an OSError)
                answer = (False, exc)
            try:
                connection.send(answer)
            except Exception:  # noqa: BLE001 - an exception that does not pickle: its line
                connection.send((False, "".join(traceback.format_exception_only(answer[1])).strip()))


def _receive(connection):
    """The next list of calls; None at the end, or when the parent has gone without closing the
    pool (killed: nothing to draw for)."""
    try:
        return connection.recv()
    except (EOFError, OSError):
        return None


def _warm_up() -> None:
    """Draw a 3D scatter into memory once: matplotlib loads its fonts and caches on the first
    figure, here, not in each drawing process forked later."""
    import io

    import matplotlib.pyplot as plt

    fig = plt.figure(figsize=(2, 2))
    ax = fig.add_subplot(projection="3d")
    ax.scatter([0, 1], [0, 1], [0, 1], label="x")
    ax.text(0, 0, 0, "1")
    ax.legend()
    fig.savefig(io.BytesIO(), format="png", dpi=30, bbox_inches="tight")
    plt.close(fig)


@contextmanager
def drawing_pool(workers: int = WORKERS):
    """A :class:`DrawingPool`, forked now (before the caller starts threads) and loading
    :data:`PRELOADED` (matplotlib, rerun) meanwhile; None where processes cannot be forked."""
    if _FORK is None:
        yield None
        return
    pool = DrawingPool(workers)
    try:
        yield pool
    finally:
        pool.close()


def _draw(name: str, args, kwargs):
    return load_reference(name)(*args, **kwargs)


def draw(calls, pool: DrawingPool | None = None) -> list:
    """The results of ``calls`` (``("module:function", args, kwargs)``, in order): drawn concurrently
    in ``pool`` (:func:`drawing_pool`), else one after another here."""
    if pool is None:
        return [_draw(*call) for call in calls]
    return pool.draw(calls)
