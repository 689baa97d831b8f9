"""Every notebook runs unattended in reader's mode, shows what it makes, and is stored clean.

The executions go through :func:`tools.notebooks.run_notebooks`, the path ``make
notebooks`` takes, into one folder per test worker (``executed_notebooks``); each one is kept
(``outputs/cache/notebooks``) for the site test (tests/test_site.py) and ``make docs`` to copy.
"""

import io
import json
import re
import tokenize

import nbformat
import pytest

from tools.notebooks import notebook_paths, run_notebooks, set_parameters

NOTEBOOKS = notebook_paths()
LOCAL_PATH = re.compile(r"(/work/|/home/|/tmp/|/root/|[A-Z]:\\\\)")
# a printed file path standing in for a figure or a table
PRINTED_FILE = re.compile(r"[\w./-]+\.(png|pdf|svg|csv)\b")
# a sentence that compares, and a measured quantity (a number with a unit of the results)
COMPARES = re.compile(r"\b(fewer|more|less|better|worse|beats?|higher|lower|faster|slower|dominat\w*|"
                      r"outperform\w*|than|exceeds?)\b", re.I)
MEASURED = re.compile(r"\d[\d.,]*\s*(%|x\b|×|views?\b|mm\b|cm\b|m\b|s\b|points?\b)")
# Sentences with a comparative word and a number that state a setting or the paper's own figure, not
# a result of this repository's data (why, after each).
NOT_A_MEASURED_COMPARISON = {
    # 07: the paper's times, quoted from the paper
    "A finer means more voxels and more rays, which is why the paper's time grows from 250 s at 10 cm to 2,000 s "
    "at 3 cm.",
    # 09: the fusion's settings
    "5 mm voxels, a 1 cm truncation, depth up to 1.5 m, confidence medium or better) and extracts its zero crossings.",
}


def _prose_sentences(notebook: dict):
    for index, cell in enumerate(notebook["cells"]):
        if cell["cell_type"] != "markdown":
            continue
        text = re.sub(r"```.*?```|`[^`]*`|\$[^$]*\$", "", "".join(cell["source"]), flags=re.S)
        for sentence in re.split(r"(?<=[.!?:])\s+|\n\n", text):
            yield index, " ".join(sentence.split())


def _string_literals(source: str) -> list[str]:
    return [token.string for token in tokenize.generate_tokens(io.StringIO(source).readline)
            if token.type == tokenize.STRING]


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
    # a markdown cell under the title says what each mode computes (the comment above says it only in code)
    modes = [c for c in notebook["cells"][:3] if c["cell_type"] == "markdown"
             and "".join(c["source"]).startswith("**What each mode computes.**")]
    assert modes, f"{path.name}: no markdown cell says what reader's mode computes"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_prose_compares_no_measured_number_by_hand(path):
    """A comparison with a measured number is printed by code that evaluates it on the data shown
    (tpvp.experiments.claims), never typed into the prose, where a rerun cannot correct it."""
    hand_written = [f"cell {i}: {s}" for i, s in _prose_sentences(json.loads(path.read_text()))
                    if COMPARES.search(s) and MEASURED.search(s) and s not in NOT_A_MEASURED_COMPARISON]
    assert not hand_written, "\n".join(hand_written)


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_ends_with_a_conclusion_formatted_from_the_data(path):
    """The last cell displays the conclusion (tpvp.viz.notebook.show_conclusion); its sentences are
    formatted from the data: no number typed into their strings outside the formatted fields."""
    last = json.loads(path.read_text())["cells"][-1]
    source = "".join(last["source"])
    assert last["cell_type"] == "code" and "show_conclusion(" in source, f"{path.name} ends without its conclusion"
    typed = [text for text in _string_literals(source) if re.search(r"\d", re.sub(r"\{[^{}]*\}", "", text))]
    assert not typed, f"{path.name}'s conclusion types numbers: {typed}"


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
        html = [out.get("data", {}).get("text/html", "") for out in cell.get("outputs", [])]
        longest = max((len(re.findall(r"<tr\b", "".join(h))) - 1 for h in html), default=0)  # less the header
        assert longest <= 25 or any('class="tpvp-csv"' in "".join(h) for h in html), \
            f"{path.name}: a table of {longest} rows without its CSV link"
        for out in cell.get("outputs", []):
            text = out.get("text", "") + out.get("data", {}).get("text/plain", "")
            assert not PRINTED_FILE.search(text), f"{path.name} prints a file path instead of showing it: {text[:200]}"
            assert out.get("name") != "stderr", f"{path.name} writes to stderr: {text[:300]}"
            # its paper tables come from the full protocol's rows: nothing reduced
            assert "reduced run" not in (text + str(out.get("data", {}))).lower(), f"{path.name} shows a reduced run"
    conclusion = "".join(executed.cells[-1]["outputs"][0]["data"]["text/markdown"])
    assert conclusion.startswith("## Conclusion") and "**What to take away.**" in conclusion, path.name
    assert (executed_notebooks / f"{path.stem}.html").stat().st_size > 0
    exported = [p for p in (executed_notebooks / path.stem).rglob("*") if p.suffix in (".png", ".csv")]
    assert exported, f"{path.name} exported no figure or table file"
    manifest = json.loads((executed_notebooks / "manifest.json").read_text())
    assert manifest[path.stem]["mode"] == "reader"
