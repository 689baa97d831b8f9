"""Every notebook runs unattended in reader's mode, shows what it makes, and is stored clean.

The executions go through :func:`tools.notebooks.run_notebooks`, the path ``make
notebooks`` takes, into one folder per test worker (``executed_notebooks``); each one is kept
(``outputs/cache/notebooks``) for the site test (tests/test_site.py) and ``make docs`` to copy.
"""

import json
import re

import nbformat
import pytest

from tools.notebooks import notebook_paths, run_notebooks, set_parameters

NOTEBOOKS = notebook_paths()
LOCAL_PATH = re.compile(r"(/work/|/home/|/tmp/|/root/|[A-Z]:\\\\)")
# a printed file path standing in for a figure or a table
PRINTED_FILE = re.compile(r"[\w./-]+\.(png|pdf|svg|csv)\b")


def test_there_is_a_notebook_per_experiment():
    names = [p.stem for p in NOTEBOOKS]
    assert names == ["01_getting_started", "02_table1_coverage_effort", "03_table2_plant_complexity",
                     "04_ablations_tables3_4", "05_greenhouse_rows_tables5_6", "06_pose_noise_table7",
                     "07_planning_time", "08_learned_baselines", "09_prepare_datasets", "10_real_session",
                     "11_season"]


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_stored_without_outputs_or_local_paths(path):
    notebook = json.loads(path.read_text())
    for cell in notebook["cells"]:
        if cell["cell_type"] == "code":
            assert cell["outputs"] == [] and cell["execution_count"] is None, path.name
        assert not LOCAL_PATH.search("".join(cell["source"])), f"{path.name} holds a local path"
    first = "".join(next(c for c in notebook["cells"] if c["cell_type"] == "code")["source"])
    # the parameters cell: the switch, what each mode costs, where the outputs go
    assert re.search(r"^full = False\s+#.*\b\d+ (s|min)\b", first, re.M), first  # a time, in s or min
    assert re.search(r"^output = \"\.\./outputs/reader/", first, re.M), first


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_stored_with_the_kernels_language_info(path):
    """JupyterLab writes the kernel's language_info into a notebook it opens and marks it modified
    when that changes anything: the stored one is the environment's (environment.txt's ipykernel on
    Python 3.11.7), so opening a notebook leaves it unmodified. (On another 3.11 patch release only
    the version differs, and JupyterLab marks the notebook modified.)"""
    from ipykernel.ipkernel import IPythonKernel

    stored, kernel = json.loads(path.read_text())["metadata"]["language_info"], dict(IPythonKernel.language_info)
    assert stored["version"].rsplit(".", 1)[0] == kernel.pop("version").rsplit(".", 1)[0] == "3.11"
    assert {k: v for k, v in stored.items() if k != "version"} == kernel


def test_set_parameters_keeps_the_comments():
    notebook = nbformat.v4.new_notebook(cells=[nbformat.v4.new_code_cell(
        'full = False  # reader: 1 min; full: 10 min\noutput = "../outputs/reader/x"  # here')])
    set_parameters(notebook, True, "/somewhere/else")
    assert notebook.cells[0].source == ("full = True  # reader: 1 min; full: 10 min\n"
                                        "output = '/somewhere/else'  # here")


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_runs_in_reader_mode_and_shows_its_figures_and_tables(path, executed_notebooks):
    # executed, never reused: the kept execution it leaves is what `make docs` copies
    entry = run_notebooks([path.stem], full=False, destination=executed_notebooks, progress=False, reuse=False)[path.stem]
    assert entry["errors"] == 0
    assert entry["images"] >= 1, f"{path.name} shows no figure"
    assert entry["tables"] >= 1, f"{path.name} shows no rendered table"
    executed = nbformat.read(executed_notebooks / f"{path.stem}.ipynb", as_version=4)
    for cell in executed.cells:
        for out in cell.get("outputs", []):
            text = out.get("text", "") + out.get("data", {}).get("text/plain", "")
            assert not PRINTED_FILE.search(text), f"{path.name} prints a file path instead of showing it: {text[:200]}"
            assert out.get("name") != "stderr", f"{path.name} writes to stderr: {text[:300]}"
            # its paper tables come from the full protocol's rows: nothing reduced
            assert "reduced run" not in (text + str(out.get("data", {}))).lower(), f"{path.name} shows a reduced run"
    assert (executed_notebooks / f"{path.stem}.html").stat().st_size > 0
    exported = [p for p in (executed_notebooks / path.stem).rglob("*") if p.suffix in (".png", ".csv")]
    assert exported, f"{path.name} exported no figure or table file"
    manifest = json.loads((executed_notebooks / "manifest.json").read_text())
    assert manifest[path.stem]["mode"] == "reader"
