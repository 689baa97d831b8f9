"""Where a notebook's table rows come from (tpvp.experiments.notebooks), and the notebook runner
(tools/notebooks.py): publishing executed copies whole, keeping reader's-mode executions."""

import json

import nbformat
import pandas as pd
import pytest

from tpvp.errors import ConfigError
from tools import notebooks as runner
from tpvp.experiments import notebooks, shipped
from tpvp.viz.notebook import MAX_ROWS, beside_paper, conclusion, mean_std, paper_comparison, show_table, table_parts


def _never():
    raise AssertionError("must not be called")


class _Protocol:
    """A protocol whose rows come from the given functions."""

    setting = "plants"

    def __init__(self, run=_never, cached=_never):
        self._run, self._cached = run, cached

    def run(self, cache_dir, progress=True):
        return self._run()

    def cached(self, cache_dir):
        return self._cached()


def test_full_mode_computes_and_keeps_the_rows_for_make_notebooks(tmp_path, monkeypatch):
    rows = pd.DataFrame({"views": [3, 4]})
    monkeypatch.setitem(shipped.PROTOCOLS, "table1", _Protocol(run=lambda: rows))
    results = notebooks.protocol_results(tmp_path / "02_x", "table1", True)
    assert results.raw.equals(rows) and "computed in this run" in results.source
    assert pd.read_parquet(tmp_path / "02_x" / "results" / "table1.parquet").equals(rows)


def test_reader_mode_prefers_the_cache_then_the_published_then_the_shipped_rows(tmp_path, monkeypatch):
    monkeypatch.setenv("TPVP_NOTEBOOK_RESULTS", str(tmp_path / "published"))
    monkeypatch.setattr(shipped, "SHIPPED", tmp_path / "shipped")
    cached, published, shipped_rows = (pd.DataFrame({"views": [v]}) for v in (1, 2, 3))
    output = tmp_path / "reader" / "02_x"

    monkeypatch.setitem(shipped.PROTOCOLS, "table1", _Protocol(cached=lambda: cached))
    results = notebooks.protocol_results(output, "table1", False)
    assert results.raw.equals(cached) and "experiment cache" in results.source

    monkeypatch.setitem(shipped.PROTOCOLS, "table1", _Protocol(cached=lambda: None))
    with pytest.raises(ConfigError, match="no rows of protocol 'table1' are shipped: run `python -m "
                                          "tpvp.experiments.shipped refresh table1`"):
        notebooks.protocol_results(output, "table1", False)

    (tmp_path / "shipped").mkdir()
    shipped_rows.to_parquet(tmp_path / "shipped" / "table1.parquet")
    results = notebooks.protocol_results(output, "table1", False)
    assert results.raw.equals(shipped_rows) and "shipped with tpvp" in results.source

    (tmp_path / "published" / "02_x" / "results").mkdir(parents=True)
    published.to_parquet(tmp_path / "published" / "02_x" / "results" / "table1.parquet")
    results = notebooks.protocol_results(output, "table1", False)
    assert results.raw.equals(published) and "make notebooks" in results.source
    assert not (output / "results").exists()  # reader's mode never writes rows that look like the protocol's


def test_a_paper_table_is_compact_ours_beside_the_paper_with_the_difference():
    ours = pd.DataFrame({"view_space": ["hemisphere", "hemisphere"], "method": ["ours", "new"],
                         "sigma": [0.002, 0.01], "views_mean": [11.83, 5.0], "views_std": [2.43, 0.0],
                         "coverage_mean": [99.34, 90.0], "coverage_std": [0.29, 1.0]})
    paper = pd.DataFrame({"view_space": ["hemisphere"], "method": ["ours"], "views_mean": [11.06],
                          "coverage_mean": [98.77]})
    table = paper_comparison(ours, paper, ["view_space", "method"], {"views": ("views", "views"),
                             "coverage": ("coverage", "coverage (%)")}, keys=["method", "sigma"],
                             labels={"method": "Method"})
    assert table.columns.tolist() == ["Method", "sigma", "views: ours / paper / Δ", "coverage (%): ours / paper / Δ"]
    assert table.iloc[0].tolist() == ["ours", "0.002", "11.83 ± 2.43 / 11.06 / +0.77", "99.34 ± 0.29 / 98.77 / +0.57"]
    assert table.iloc[1].tolist() == ["new", "0.01", "5.00 ± 0.00 / – / –", "90.00 ± 1.00 / – / –"]


def test_a_conclusion_says_how_the_paper_tables_agree_then_what_to_take_away():
    said = conclusion(["Ours needs fewer views."], paper=["Table I: 3 of 4 values within 10 % of the paper's."])
    assert said.splitlines() == [
        "## Conclusion", "", "**Against the paper.**", "- Table I: 3 of 4 values within 10 % of the paper's.",
        "- What differs from the paper's setting, and why, is listed in [deviations.md](../docs/deviations.md).", "",
        "**What to take away.**", "- Ours needs fewer views."]
    assert "- This notebook reproduces no table of the paper." in conclusion(["a finding"], paper=[])
    with pytest.raises(ValueError, match="at least one finding"):
        conclusion([], paper=[])


def test_a_wide_table_is_shown_in_parts_that_repeat_its_keys():
    wide = pd.DataFrame({"case": ["a", "b"], "method": ["x", "y"], **{f"v{i}": [1.0, 2.0] for i in range(10)}})
    parts = table_parts(wide)
    assert [p.columns.tolist() for p in parts] == [["case", "method", *[f"v{i}" for i in range(6)]],
                                                   ["case", "method", *[f"v{i}" for i in range(6, 10)]]]
    one = table_parts(wide.iloc[:1])
    assert len(one) == 1 and one[0].columns.tolist() == ["quantity", "value"] and len(one[0]) == 12
    assert len(table_parts(wide.iloc[:, :5])) == 1 and table_parts(wide.iloc[:, :5])[0].equals(wide.iloc[:, :5])
    # a numeric key (a session number, a re-planning setting) is repeated too; a numeric value is not
    numbered = pd.DataFrame({"session": [2, 3], "replan_after": [0, 1], "views": [9, 8],
                             **{f"v{i}": [1.0, 2.0] for i in range(8)}})
    assert [p.columns[:3].tolist() for p in table_parts(numbered)] == [["session", "replan_after", "views"],
                                                                      ["session", "replan_after", "v5"]]


def test_a_long_table_shows_its_first_rows_and_links_every_row(tmp_path, monkeypatch):
    import IPython.display

    shown = []
    monkeypatch.setattr(IPython.display, "display", lambda *objects: shown.extend(objects))
    long = pd.DataFrame({"case": [f"c{i}" for i in range(MAX_ROWS + 5)], "views": range(MAX_ROWS + 5)})
    show_table(long, tmp_path / "long.csv", "Long", merge_std=False)
    assert pd.read_csv(tmp_path / "long.csv").equals(long)  # the CSV holds every row
    rendered = [o for o in shown if hasattr(o, "data") and hasattr(o.data, "shape")]
    assert [len(o.data) for o in rendered] == [MAX_ROWS]
    texts = [str(getattr(o, "data", "")) for o in shown]
    assert f"The first {MAX_ROWS} of {MAX_ROWS + 5} rows." in texts
    assert any('download="long.csv"' in t and f"{MAX_ROWS + 5:,} rows" in t for t in texts)
    shown.clear()
    show_table(long.head(3), None, merge_std=False)
    assert not any("download=" in str(getattr(o, "data", "")) for o in shown)  # short and narrow: no link


def test_mean_std_merges_and_the_paper_stands_beside():
    ours = pd.DataFrame({"method": ["ours", "gmc"], "budget": pd.array([pd.NA, 5], dtype="Int64"),
                         "views_mean": [11.0, 5.0], "views_std": [2.0, 0.0]})
    paper = pd.DataFrame({"method": ["gmc", "ours"], "budget": [5.0, float("nan")], "views_mean": [5, 11.06],
                          "coverage_mean": [91.1, 98.8]})
    table = beside_paper(ours, paper, on=["method", "budget"])
    assert table["paper_views"].tolist() == [11.06, 5]
    assert table["paper_coverage"].tolist() == [98.8, 91.1]
    assert mean_std(ours)["views"].tolist() == ["11.00 ± 2.00", "5.00 ± 0.00"]


def _notebook(path, source):
    nb = nbformat.v4.new_notebook(cells=[
        nbformat.v4.new_code_cell('full = False  # reader: 1 min\noutput = "../outputs/reader/x"'),
        nbformat.v4.new_code_cell(source)])
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    nbformat.write(nb, path)


@pytest.mark.slow
def test_a_failing_notebook_leaves_the_published_copies_whole(tmp_path, monkeypatch):
    folder = tmp_path / "notebooks"
    folder.mkdir()
    _notebook(folder / "01_ok.ipynb", "from pathlib import Path\nPath(output).mkdir(parents=True)\n"
                                      "(Path(output) / 'x.csv').write_text(str(full))\nprint('shown')")
    monkeypatch.setattr(runner, "NOTEBOOKS", folder)
    monkeypatch.setenv("TPVP_NOTEBOOK_CACHE", str(tmp_path / "kept"))
    destination = tmp_path / "published"
    done = runner.run_notebooks(["01_ok"], full=False, destination=destination, progress=False)
    assert done["01_ok"]["mode"] == "reader" and (destination / "01_ok" / "x.csv").read_text() == "False"
    executed = nbformat.read(destination / "01_ok.ipynb", as_version=4)
    assert executed.cells[1].outputs[0]["text"] == "shown\n"
    assert str(destination / "01_ok") in executed.cells[0].source  # the published path, not the staging one
    before = {p.relative_to(destination): p.read_bytes() for p in destination.rglob("*") if p.is_file()}

    _notebook(folder / "02_broken.ipynb", "raise RuntimeError('half way')")
    with pytest.raises(Exception, match="half way"):
        runner.run_notebooks(["01_ok", "02_broken"], full=True, destination=destination, progress=False)
    after = {p.relative_to(destination): p.read_bytes() for p in destination.rglob("*") if p.is_file()}
    assert after == before  # the first notebook's new copy was not published either
    assert json.loads((destination / "manifest.json").read_text())["01_ok"]["mode"] == "reader"
    assert [p.name for p in tmp_path.iterdir() if "staging" in p.name] == []


@pytest.mark.slow
def test_a_kept_reader_execution_is_reused_until_the_notebook_or_the_library_changes(tmp_path, monkeypatch):
    folder = tmp_path / "notebooks"
    folder.mkdir()
    # what the kernel sees: the runner's fresh experiment cache, not the caller's
    _notebook(folder / "01_ok.ipynb", "import os\nfrom pathlib import Path\nPath(output).mkdir(parents=True)\n"
                                      "(Path(output) / 'x.csv').write_text('1')\n"
                                      "print(os.environ['TPVP_EXPERIMENT_CACHE'].startswith(os.environ['CALLER']))")
    monkeypatch.setattr(runner, "NOTEBOOKS", folder)
    monkeypatch.setenv("TPVP_NOTEBOOK_CACHE", str(tmp_path / "kept"))
    monkeypatch.setenv("TPVP_EXPERIMENT_CACHE", str(tmp_path / "caller-cache"))
    monkeypatch.setenv("CALLER", str(tmp_path / "caller-cache"))
    first = runner.run_notebooks(["01_ok"], destination=tmp_path / "a", progress=False)["01_ok"]
    assert "reused_utc" not in first
    assert nbformat.read(tmp_path / "a" / "01_ok.ipynb", as_version=4).cells[1].outputs[0]["text"] == "False\n"
    key = runner.execution_key(folder / "01_ok.ipynb")
    kept = lambda: [p.name for p in (tmp_path / "kept" / "01_ok").iterdir() if not p.name.startswith(".")]  # noqa: E731
    assert kept() == [key]

    again = runner.run_notebooks(["01_ok"], destination=tmp_path / "b", progress=False)["01_ok"]
    assert "reused_utc" in again and again["executed_utc"] == first["executed_utc"]
    reused = (tmp_path / "b" / "01_ok.ipynb").read_text()
    assert str(tmp_path / "b" / "01_ok") in reused and str(tmp_path / "a") not in reused
    assert runner.FOLDER_TOKEN not in reused + (tmp_path / "b" / "01_ok.html").read_text()
    assert (tmp_path / "b" / "01_ok" / "x.csv").read_text() == "1"

    # executed when asked to, and again once the notebook changes; the older execution is dropped
    forced = runner.run_notebooks(["01_ok"], destination=tmp_path / "b", progress=False, reuse=False)["01_ok"]
    assert "reused_utc" not in forced
    _notebook(folder / "01_ok.ipynb", "print('changed')")
    changed = runner.run_notebooks(["01_ok"], destination=tmp_path / "b", progress=False)["01_ok"]
    assert "reused_utc" not in changed and not (tmp_path / "b" / "01_ok" / "x.csv").exists()
    assert kept() == [runner.execution_key(folder / "01_ok.ipynb")]
