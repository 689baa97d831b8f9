"""Run the step-by-step notebooks headless: quick mode (CI) or full mode (``make notebooks``).

The first code cell of each notebook is its parameters cell (``quick = ...``, ``output = ...``);
it is replaced before execution, so the stored notebooks stay free of outputs and local paths.
``python -m tpvp.experiments.notebooks [--quick] [--output DIR] [NAME ...]``.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

NOTEBOOKS = Path(__file__).resolve().parent.parent.parent / "notebooks"


def notebook_paths(names=()) -> list[Path]:
    paths = sorted(NOTEBOOKS.glob("[0-9][0-9]_*.ipynb"))
    if names:
        paths = [p for p in paths if p.stem in names or p.name in names]
    return paths


def run_notebook(path, quick: bool, output, timeout: int = 1800):
    """Execute one notebook with its parameters cell set to ``quick`` and ``output``; raises on
    any cell error. Returns the executed notebook (not written back)."""
    import nbformat
    from nbclient import NotebookClient

    notebook = nbformat.read(path, as_version=4)
    first = next(cell for cell in notebook.cells if cell.cell_type == "code")
    first.source = f"quick = {bool(quick)}\noutput = {str(Path(output))!r}\n"
    client = NotebookClient(notebook, timeout=timeout, kernel_name="python3",
                            resources={"metadata": {"path": str(Path(path).parent.parent)}})
    client.execute()
    return notebook


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", help="notebooks to run (default: all)")
    parser.add_argument("--quick", action="store_true", help="a few cases per notebook (as CI runs them)")
    parser.add_argument("--output", default="outputs/notebooks", help="figures and tables go here (default: %(default)s)")
    args = parser.parse_args(argv)
    for path in notebook_paths(args.names):
        print(f"running {path.name} ({'quick' if args.quick else 'full'} mode)", flush=True)
        run_notebook(path, args.quick, Path(args.output).absolute() / path.stem)
    return 0


if __name__ == "__main__":
    sys.exit(main())
