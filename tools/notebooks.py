"""Execute the tutorial notebooks headless and keep what they show.

``python -m tools.notebooks [--full] [--output DIR] [NAME ...]`` (``make notebooks``
runs the full protocol) executes each notebook with its parameters cell set (``full``,
``output``) and publishes, as one folder through :func:`tpvp.io.publish.staged_folder`:

- ``<name>.ipynb``: the executed notebook, outputs included;
- ``<name>.html``: an HTML copy (figures embedded as data, plotly.js inline; equations rendered
  offline by the MathJax copy in ``mathjax/``);
- ``<name>/``: the figures (PNG, PDF for the paper's figures) and tables (CSV) it exported, and
  in the full protocol the raw results (``results/*.parquet``) that reader's mode reuses;
- ``index.html`` and ``manifest.json``: every notebook with its mode and wall time.

An interrupted run leaves the previous folder whole; running a subset keeps the other notebooks'
copies. The stored notebooks under ``notebooks/`` stay free of outputs and local paths.

Reader's mode runs as on a fresh clone (an empty experiment cache, nothing published: the paper
tables come from the shipped rows), so its execution depends only on the notebook and the
library. Each one is kept in ``outputs/cache/notebooks/`` (:func:`execution_cache`) under a key
of the notebook, the library's sources and data and ``environment.txt``; a later reader's-mode
run with the same key reuses it instead of executing (``make test`` runs every notebook, so the
``make docs`` after it only copies them).
"""

from __future__ import annotations

import argparse
import hashlib
import html
import importlib.util
import json
import os
import re
import shutil
import sys
import tempfile
import time
from datetime import datetime, timezone
from pathlib import Path

from tpvp.errors import BusyError, ConfigError, run_command
from tpvp.experiments.notebooks import published_results
from tpvp.io import atomic_write_text
from tpvp.io.publish import staged_folder

ROOT = Path(__file__).resolve().parent.parent
NOTEBOOKS = ROOT / "notebooks"
MANIFEST = "manifest.json"
MATHJAX = "mathjax"  # folder beside the HTML copies
EXECUTION = "execution.json"  # in a cached execution: its manifest entry
# Stands for the publishing folder in a cached execution's texts (the folder differs between runs).
FOLDER_TOKEN = "@TPVP-NOTEBOOK-FOLDER@"
FULL_TIMEOUT_S = 3 * 3600  # per cell; the longest full-protocol cell takes about 15 min on 2 cores
READER_TIMEOUT_S = 600


def notebook_paths(names=()) -> list[Path]:
    paths = sorted(NOTEBOOKS.glob("[0-9][0-9]_*.ipynb"))
    if names:
        unknown = set(names) - {p.stem for p in paths} - {p.name for p in paths}
        if unknown:
            raise ConfigError(f"no notebook named {', '.join(sorted(unknown))}; choose from "
                              f"{', '.join(p.stem for p in paths)}")
        paths = [p for p in paths if p.stem in names or p.name in names]
    return paths


# --------------------------------------------------------------------------------------------------
# executing and publishing
# --------------------------------------------------------------------------------------------------


def set_parameters(notebook, full: bool, output) -> None:
    """Set ``full`` and ``output`` in the first code cell, keeping its comments."""
    first = next(cell for cell in notebook.cells if cell.cell_type == "code")
    source = first.source
    for name, value in (("full", repr(bool(full))), ("output", repr(str(output)))):
        source, count = re.subn(rf"^({name}\s*=\s*)[^#\n]*?(\s*(#.*)?)$", lambda m: f"{m.group(1)}{value}{m.group(2)}",
                                source, count=1, flags=re.M)
        if not count:
            source += f"\n{name} = {value}"
    first.source = source


def run_notebook(path, full: bool, output, timeout: int | None = None, env=None):
    """Execute one notebook (kernel ``python3``, working folder ``notebooks/`` as in JupyterLab)
    with its parameters set and ``env`` added to the kernel's environment; raises
    ``nbclient.exceptions.CellExecutionError`` on a cell error. Returns the executed notebook."""
    import nbformat
    from nbclient import NotebookClient

    notebook = nbformat.read(path, as_version=4)
    set_parameters(notebook, full, output)
    client = NotebookClient(notebook, timeout=timeout or (FULL_TIMEOUT_S if full else READER_TIMEOUT_S),
                            kernel_name="python3", resources={"metadata": {"path": str(Path(path).parent)}})
    # No progress bars: a static page shows each of their redraws as a line of stderr.
    client.execute(env={**os.environ, **(env or {}), "TQDM_DISABLE": "1"})
    return notebook


# --------------------------------------------------------------------------------------------------
# reader's-mode executions, kept for reuse
# --------------------------------------------------------------------------------------------------


def execution_cache() -> Path:
    """Where reader's-mode executions are kept (``$TPVP_NOTEBOOK_CACHE`` or ``outputs/cache/notebooks``)."""
    return Path(os.environ.get("TPVP_NOTEBOOK_CACHE") or ROOT / "outputs" / "cache" / "notebooks")


def library_digest() -> bytes:
    """What every reader's-mode execution depends on besides its notebook: every file of the
    library (``tpvp/``, its shipped data and results included, ``data_tools/``), this runner
    (``tools/``) and the environment it was installed from. Compiled files and caches are left out."""
    digest = hashlib.sha256()
    files = [f for folder in ("tpvp", "data_tools", "tools") for f in (ROOT / folder).rglob("*")
             if f.is_file() and "__pycache__" not in f.parts and f.suffix != ".pyc"]
    for file in sorted([*files, ROOT / "environment.txt"]):
        if file.is_file():
            digest.update(file.relative_to(ROOT).as_posix().encode() + b"\0" + file.read_bytes())
    return digest.digest()


def execution_key(path, library: bytes | None = None) -> str:
    """The key of a reader's-mode execution of notebook ``path``: the notebook and the
    :func:`library_digest` (``library``: computed once by a run of several notebooks)."""
    return hashlib.sha256(Path(path).read_bytes() + (library or library_digest())).hexdigest()[:16]


def _cached_execution(stem: str, key: str) -> Path | None:
    folder = execution_cache() / stem / key
    return folder if (folder / EXECUTION).is_file() else None


def _keep_execution(stem: str, key: str, notebook_text: str, page: str, exported: Path, entry: dict) -> None:
    """Keep one execution (texts with :data:`FOLDER_TOKEN` for the publishing folder) and drop the
    notebook's older ones."""
    folder = execution_cache() / stem / key
    try:
        with staged_folder(folder, what="notebook execution cache") as stage:
            atomic_write_text(stage.path(f"{stem}.ipynb"), notebook_text)
            atomic_write_text(stage.path(f"{stem}.html"), page)
            if exported.is_dir():
                shutil.copytree(exported, stage.folder / stem)
            atomic_write_text(stage.path(EXECUTION), json.dumps(entry, indent=1) + "\n")
    except BusyError:
        return  # another run is keeping the same execution (same key: the same notebook and library)
    for old in (execution_cache() / stem).iterdir():
        if old.name != key and not old.name.startswith("."):
            shutil.rmtree(old, ignore_errors=True)


def mathjax_folder() -> Path | None:
    """MathJax 2.7 as the package jupyter-server-mathjax ships it (environment.txt): the HTML
    copies and the site render the notebooks' equations offline from a copy beside them. None when
    it is not installed (the equations then stay as TeX text)."""
    spec = importlib.util.find_spec("jupyter_server_mathjax")
    for location in (spec.submodule_search_locations or []) if spec else []:
        folder = Path(location) / "static"
        if (folder / "MathJax.js").is_file() and (folder / "config" / "TeX-AMS-MML_HTMLorMML-full.js").is_file():
            return folder
    return None


def copy_mathjax(source: Path, target: Path) -> None:
    """The parts of MathJax the pages use (no translations, tests or unpacked sources)."""
    shutil.copytree(source, target, ignore=shutil.ignore_patterns("localization", "*.md", "test*", "unpacked"),
                    dirs_exist_ok=True)


def html_copy(notebook) -> str:
    """An HTML page of an executed notebook: figures and plotly.js embedded; equations rendered
    by the MathJax copy in ``mathjax/`` beside the page."""
    from nbconvert import HTMLExporter

    exporter = HTMLExporter(template_name="lab", embed_images=True,
                            mathjax_url=f"{MATHJAX}/MathJax.js?config=TeX-AMS-MML_HTMLorMML-full,Safe")
    body, _ = exporter.from_notebook_node(notebook)
    return body


def _replace_paths(notebook, old: str, new: str) -> None:
    """Write the staging folder's path as the published one in sources and text outputs."""
    for cell in notebook.cells:
        cell.source = cell.source.replace(old, new)
        for out in cell.get("outputs", []):
            if "text" in out:
                out["text"] = out["text"].replace(old, new)
            for mime, value in out.get("data", {}).items():
                if mime.startswith("text/") and isinstance(value, str):
                    out["data"][mime] = value.replace(old, new)


def output_counts(notebook) -> dict:
    """What an executed notebook shows: images, rendered tables, interactive views, errors."""
    counts = {"images": 0, "tables": 0, "interactive": 0, "errors": 0}
    for cell in notebook.cells:
        for out in cell.get("outputs", []):
            data = out.get("data", {})
            counts["images"] += "image/png" in data
            text = data.get("text/html", "")
            counts["tables"] += "<table" in text
            counts["interactive"] += "plotly-graph-div" in text
            counts["errors"] += out.get("output_type") == "error"
    return counts


def _index_page(manifest: dict) -> str:
    rows = "\n".join(
        f"<tr><td><a href=\"{html.escape(stem)}.html\">{html.escape(stem)}</a></td><td>{entry['mode']}</td>"
        f"<td>{entry['seconds']:.0f} s</td><td>{entry['images']}</td><td>{entry['tables']}</td>"
        f"<td>{entry['executed_utc']}</td><td><a href=\"{html.escape(stem)}.ipynb\">.ipynb</a></td></tr>"
        for stem, entry in sorted(manifest.items()))
    return ("<!doctype html><html><head><meta charset=\"utf-8\"><title>tpvp notebooks</title>"
            "<style>body{font-family:sans-serif;margin:2em}td,th{padding:.3em .8em;border-bottom:1px solid #ddd}"
            "</style></head><body><h1>tpvp: executed notebooks</h1>"
            "<p>Made by <code>make notebooks</code> (full protocol) or <code>python -m tools.notebooks</code> "
            "(reader's mode). Each page is self-contained.</p><table><tr><th>notebook</th><th>mode</th>"
            "<th>wall time</th><th>figures</th><th>tables</th><th>executed</th><th>notebook file</th></tr>"
            f"{rows}</table></body></html>\n")


def run_notebooks(names=(), full: bool = False, destination=None, timeout: int | None = None,
                  progress: bool = True, reuse: bool = True) -> dict:
    """Execute the notebooks and publish them (see the module docstring) under ``destination``
    (default :func:`published_results`). Reader's mode keeps each execution and, with ``reuse``,
    copies a kept one whose key matches instead of executing. Returns the manifest entries of this run."""
    import nbformat

    paths = notebook_paths(names)
    destination = Path(destination or published_results()).absolute()
    mode = "full" if full else "reader"
    library = None if full else library_digest()  # the same for every notebook of this run
    done = {}
    with staged_folder(destination, keep_existing=True, what="notebook output folder") as stage, \
            tempfile.TemporaryDirectory(prefix="tpvp-reader-") as fresh:
        # reader's mode as on a fresh clone: nothing computed before, nothing published
        env = {} if full else {"TPVP_EXPERIMENT_CACHE": str(Path(fresh) / "cache"),
                               "TPVP_NOTEBOOK_RESULTS": str(Path(fresh) / "published")}
        manifest_path = stage.folder / MANIFEST
        manifest = json.loads(manifest_path.read_text()) if manifest_path.is_file() else {}
        for path in paths:
            output = stage.folder / path.stem
            shutil.rmtree(output, ignore_errors=True)  # hard links of the old copy: the published one stays
            key = None if full else execution_key(path, library)
            kept = _cached_execution(path.stem, key) if key and reuse else None
            if kept is not None:
                entry = json.loads((kept / EXECUTION).read_text())
                notebook_text, page = ((kept / f"{path.stem}.{ext}").read_text() for ext in ("ipynb", "html"))
                if (kept / path.stem).is_dir():
                    shutil.copytree(kept / path.stem, output)
                entry["reused_utc"] = datetime.now(timezone.utc).isoformat(timespec="seconds")
            else:
                if progress:
                    print(f"running {path.name} ({mode} mode) ...", flush=True)
                start = time.perf_counter()
                notebook = run_notebook(path, full, output, timeout, env)
                seconds = time.perf_counter() - start
                _replace_paths(notebook, str(stage.folder), FOLDER_TOKEN)
                notebook_text, page = nbformat.writes(notebook), html_copy(notebook)
                entry = {"mode": mode, "seconds": round(seconds, 1), **output_counts(notebook),
                         "executed_utc": datetime.now(timezone.utc).isoformat(timespec="seconds")}
                if key:
                    _keep_execution(path.stem, key, notebook_text, page, output, entry)
            atomic_write_text(stage.path(f"{path.stem}.ipynb"), notebook_text.replace(FOLDER_TOKEN, str(destination)))
            atomic_write_text(stage.path(f"{path.stem}.html"), page.replace(FOLDER_TOKEN, str(destination)))
            done[path.stem] = entry
            if progress:
                how = "kept execution of " + entry["executed_utc"][:16] if kept is not None else f"{entry['seconds']:.0f} s"
                print(f"  {path.stem}: {how}, {entry['images']} figures, {entry['tables']} tables", flush=True)
        mathjax = mathjax_folder()
        if mathjax is not None and not (stage.folder / MATHJAX / "MathJax.js").is_file():
            copy_mathjax(mathjax, stage.folder / MATHJAX)
        manifest.update(done)
        atomic_write_text(stage.path(MANIFEST), json.dumps(manifest, indent=1) + "\n")
        atomic_write_text(stage.path("index.html"), _index_page(manifest))
    return done


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", help="notebooks to run (default: all)")
    parser.add_argument("--full", action="store_true",
                        help="the paper's full protocol (make notebooks; about an hour on 2 cores with cold caches)")
    parser.add_argument("--output", default=None, help="publish here (default: outputs/notebooks in the repository)")
    parser.add_argument("--keep-full", action="store_true",
                        help="keep the published full-protocol copies; run the others in reader's mode (make docs)")
    parser.add_argument("--no-reuse", dest="reuse", action="store_false",
                        help="execute every notebook, even one whose reader's-mode execution is kept")
    args = parser.parse_args(argv)

    def run(args) -> int:
        names = args.names
        if args.keep_full:
            manifest_path = Path(args.output or published_results()) / MANIFEST
            manifest = json.loads(manifest_path.read_text()) if manifest_path.is_file() else {}
            names = [p.stem for p in notebook_paths(names) if manifest.get(p.stem, {}).get("mode") != "full"]
            if not names:
                print("every notebook's published copy is a full-protocol execution; kept")
                return 0
        run_notebooks(names, args.full, args.output, reuse=args.reuse)
        return 0
    args.func = run
    return run_command(args, "python -m tools.notebooks")


if __name__ == "__main__":
    sys.exit(main())
