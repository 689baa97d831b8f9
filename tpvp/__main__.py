"""``python -m tpvp``: the command line, after checking that this Python has the dependencies.

Run with a Python that lacks them (the system ``python3`` instead of ``.venv``), it prints one line
naming the missing package and the fix, and exits with status 2 instead of a traceback. Ctrl-C
or SIGTERM at any moment ends it with one line and exit status 130: while the libraries load, at
once (nothing has been written yet); afterwards as a ``KeyboardInterrupt`` that the run's staged
outputs clean up after (docs/cli.md: exit status). :func:`run_checked` is shared with
``python -m data_tools``; the ``tpvp`` command is :func:`main`.
"""

import _thread
import atexit
import importlib.util
import os
import signal
import sys
import threading
from pathlib import Path

#: Import name -> distribution name (environment.txt) of the packages every command needs.
REQUIRED = {"numpy": "numpy", "scipy": "scipy", "numba": "numba", "open3d": "open3d-cpu",
            "trimesh": "trimesh", "torch": "torch", "pulp": "PuLP", "pandas": "pandas",
            "matplotlib": "matplotlib", "yaml": "PyYAML", "tqdm": "tqdm", "rerun": "rerun-sdk"}
_OWN = ("tpvp", "data_tools")


def missing_packages(names=REQUIRED) -> list[str]:
    """Import names of ``names`` that this Python cannot find (nothing is imported)."""
    missing = []
    for name in names:
        try:
            found = importlib.util.find_spec(name) is not None
        except (ImportError, ValueError):
            found = False
        if not found:
            missing.append(name)
    return missing


def _fix() -> str:
    root = Path(__file__).resolve().parent.parent
    venv = root / ".venv" / "bin" / "python"
    try:
        shown = os.path.relpath(root / ".venv")
    except ValueError:  # pragma: no cover - other drive (Windows)
        shown = ".."
    if shown.startswith(".."):
        shown = str(root / ".venv")
    if venv.exists() and Path(sys.prefix).resolve() != (root / ".venv").resolve():
        return f"use the project's environment: `source {shown}/bin/activate` (or run `{shown}/bin/python -m ...`)"
    where = "" if Path.cwd().resolve() == root else f"in {root} "
    return f"run `make demo` {where}once (it creates .venv), then `source {shown}/bin/activate`"


def missing_message(prog: str, name: str, more: int = 0) -> str:
    """The one-line message for a missing package ``name`` (``more`` others missing too)."""
    dist = REQUIRED.get(name, name)
    label = f"'{name}'" + (f" (pip: {dist})" if dist != name else "")
    extra = f" and {more} more" if more else ""
    return f"{prog}: missing package {label}{extra} in {sys.executable}: {_fix()}"


_STOPS = (signal.SIGINT, signal.SIGTERM)
REDELIVERY_DELAY_S = 0.01  # a swallowed interrupt is raised again this much later (:func:`_redeliver`)


def _stop_at_once(prog: str):
    """Start-up handler: nothing is written yet, so end at once. An interrupted C extension import
    (open3d, numba) would otherwise surface as a traceback or a misleading ``ImportError``."""
    def handler(signum, frame):
        os.write(2, f"{prog}: interrupted while starting; nothing was written\n".encode())
        os._exit(130)
    return handler


def _interrupt(received: list):
    """Run handler: a ``KeyboardInterrupt`` in this process (so staged outputs are cleaned up),
    for SIGTERM as for Ctrl-C; ``received`` remembers it. Once the command's step is published
    (:func:`tpvp.io.publish.arm_step`), the signal is only noted: the step is complete."""
    pid = os.getpid()

    def handler(signum, frame):
        if os.getpid() != pid:  # a forked child: the default action
            signal.signal(signum, signal.SIG_DFL)
            os.kill(os.getpid(), signum)
            return
        # Not loaded, or still loading (the signal came during its import): no step was published.
        step_published = getattr(sys.modules.get("tpvp.io.publish"), "step_published", None)
        if step_published is not None and step_published() is not None:
            sys.modules["tpvp.io.publish"].note_late_signal(signum)
            return
        received.append(signum)
        raise KeyboardInterrupt
    return handler


def _redeliver(received: list, previous_hook):
    """``sys.unraisablehook`` that raises a signal again whose ``KeyboardInterrupt`` was swallowed
    (raised inside a C callback, e.g. numba's cache loading through ctypes), instead of printing
    "Exception ignored" and running on. Once a signal arrived, any other unraisable error is the
    interrupt's debris (an object it left half built fails in its ``__del__``, e.g. llvmlite's
    while numba loads): not printed, the command reports the interrupt."""
    def hook(unraisable):
        if received:
            if isinstance(unraisable.exc_value, KeyboardInterrupt):
                # From another thread, a moment later: raised here (interrupt_main or raise_signal
                # in this thread run the handler before the hook returns), the KeyboardInterrupt
                # would be printed as the hook's own error and dropped.
                later = threading.Timer(REDELIVERY_DELAY_S, _thread.interrupt_main, (received[-1],))
                later.daemon = True
                later.start()
            return
        previous_hook(unraisable)
    return hook


def _end_interrupted(status: int) -> None:
    """End the process now with ``status``: after a Ctrl-C, CPython may have marked the
    KeyboardInterrupt as unhandled (when it passed through an extension's own Python code) and
    would end the process by SIGINT instead, whatever the command returned; an extension the
    interrupt left half set up may also print at teardown. The command has cleaned up already."""
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(status)


def run_checked(prog: str, load_main, exiting: bool = False) -> int:
    """Check the dependencies, then ``load_main()()`` (``load_main`` imports and returns the CLI's
    ``main``); a missing package, found up front or at import time, is one line and status 2; a
    Ctrl-C or SIGTERM, one line and status 130. ``exiting``: the process ends with the returned
    status (the commands' entry points), so a stop signal after the command ended is ignored."""
    previous = {signum: signal.getsignal(signum) for signum in _STOPS}
    previous_hook = sys.unraisablehook
    in_main_thread = threading.current_thread() is threading.main_thread()  # only it may set handlers
    received = []  # the signals that arrived once the command runs
    try:
        if in_main_thread:
            for signum in _STOPS:
                signal.signal(signum, _stop_at_once(prog))
        missing = missing_packages()
        if missing:
            print(missing_message(prog, missing[0], len(missing) - 1), file=sys.stderr)
            return 2
        try:
            main = load_main()
        except ModuleNotFoundError as exc:
            top = (exc.name or "").split(".")[0]
            if not top or top in _OWN:
                raise  # a bug in this project, not a missing dependency
            print(missing_message(prog, top), file=sys.stderr)
            return 2
        if in_main_thread:
            for signum in _STOPS:
                signal.signal(signum, _interrupt(received))
            sys.unraisablehook = _redeliver(received, previous_hook)
        try:
            status = main()
        except KeyboardInterrupt as exc:  # one the command did not report itself (e.g. while parsing)
            report = exc.report() if hasattr(exc, "report") else "interrupted; nothing was written"
            print(f"{prog}: {report}", file=sys.stderr)
            status = 130
        except Exception:
            if not received:
                raise
            # Ctrl-C inside an import or a C extension surfaces as another exception (open3d:
            # "ImportError: initialization failed"); the staged outputs were cleaned up on the way.
            print(f"{prog}: interrupted; nothing was published", file=sys.stderr)
            _end_interrupted(130)
        if received and status == 0:
            # A library swallowed the KeyboardInterrupt (an optional import that fails "cleanly")
            # and the command ran to its end: say so, and still end as interrupted.
            print(f"{prog}: interrupted, but the command had already finished (its outputs are complete)",
                  file=sys.stderr)
            status = 130
        if received:
            _end_interrupted(status)
        return status
    finally:
        if in_main_thread:
            # After an interrupt, a redelivered signal may still be pending: it must not kill the
            # process on its way out with the default handler. When the process ends here, the
            # status is decided: a signal while the interpreter shuts down (an atexit callback,
            # joining threads) must neither print a traceback nor change it. Ignored, not handled:
            # Python resets its own handlers to the default action late in the shutdown.
            for signum, handler in previous.items():
                signal.signal(signum, signal.SIG_IGN if received or exiting else handler)
            sys.unraisablehook = previous_hook


def main() -> int:
    """The ``tpvp`` command."""
    return exit_now(run_checked("tpvp", _load_main, exiting=True))


def exit_now(status: int) -> int:
    """End the process with ``status`` at once, once the command has ended: its standard streams
    flushed and its exit functions (atexit) run here, without the interpreter's teardown (freeing
    every module and numba's compiled code: about 0.3 s after ``tpvp plan``). Returns ``status``
    where that is not safe (the caller then exits as usual): a thread that is not a daemon still
    runs (the interpreter would wait for it), or a stream does not flush (a closed pipe)."""
    others = [t for t in threading.enumerate() if t is not threading.current_thread() and not t.daemon]
    if not isinstance(status, int) or threading.current_thread() is not threading.main_thread() or others:
        return status
    try:
        sys.stdout.flush()
        sys.stderr.flush()
        atexit._run_exitfuncs()
        sys.stdout.flush()
        sys.stderr.flush()
    except Exception:  # noqa: BLE001 - left to the usual exit, which reports it as it always has
        return status
    os._exit(status)


def _load_main():
    from tpvp.cli import prepare  # after the dependency check: a missing package is one line

    return prepare()  # loads the command's own modules and parses its options

if __name__ == "__main__":
    sys.exit(main())
