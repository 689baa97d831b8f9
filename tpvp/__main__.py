"""``python -m tpvp``: the command line, after checking that this Python has the dependencies.

Run with a Python that lacks them (the system ``python3`` instead of ``.venv``), it prints one line
naming the missing package and the fix, and exits with status 2 instead of a traceback.
:func:`run_checked` is shared with ``python -m data_tools``.
"""

import importlib.util
import os
import sys
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


def run_checked(prog: str, load_main) -> int:
    """Check the dependencies, then ``load_main()()`` (``load_main`` imports and returns the CLI's
    ``main``); a missing package, found up front or at import time, is one line and status 2."""
    missing = missing_packages()
    if missing:
        print(missing_message(prog, missing[0], len(missing) - 1), file=sys.stderr)
        return 2
    try:
        main = load_main()
        return main()
    except ModuleNotFoundError as exc:
        top = (exc.name or "").split(".")[0]
        if not top or top in _OWN:
            raise  # a bug in this project, not a missing dependency
        print(missing_message(prog, top), file=sys.stderr)
        return 2


def _load_main():
    from tpvp.cli import main  # after the dependency check: a missing package is one line, not a traceback

    return main


if __name__ == "__main__":
    sys.exit(run_checked("tpvp", _load_main))
