"""The notebook runner: where a notebook's table rows come from, and publishing executed copies whole."""

import json

import nbformat
import pandas as pd
import pytest

from tpvp.errors import ConfigError
from tpvp.experiments import notebooks, shipped
from tpvp.viz.notebook import beside_paper, mean_std, paper_comparison, table_parts


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
    assert results.full_protocol and results.raw.equals(rows)
    assert pd.read_parquet(tmp_path / "02_x" / "results" / "table1.parquet").equals(rows)


def test_reader_mode_prefers_the_cache_then_the_published_then_the_shipped_rows(tmp_path, monkeypatch):
    monkeypatch.setenv("TPVP_NOTEBOOK_RESULTS", str(tmp_path / "published"))
    monkeypatch.setattr(shipped, "SHIPPED", tmp_path / "shipped")
    cached, published, shipped_rows, reduced = (pd.DataFrame({"views": [v]}) for v in (1, 2, 3, 4))
    output = tmp_path / "reader" / "02_x"

    monkeypatch.setitem(shipped.PROTOCOLS, "table1", _Protocol(cached=lambda: cached))
    results = notebooks.protocol_results(output, "table1", False, _never)
    assert results.full_protocol and results.raw.equals(cached) and "cache" in results.source

    monkeypatch.setitem(shipped.PROTOCOLS, "table1", _Protocol(cached=lambda: None))
    with pytest.raises(ConfigError, match="no rows of protocol 'table1' are shipped: run `python -m "
                                          "tpvp.experiments.shipped refresh table1`"):
        notebooks.protocol_results(output, "table1", False)
    results = notebooks.protocol_results(output, "table1", False, lambda: reduced)
    assert not results.full_protocol and results.raw.equals(reduced) and "REDUCED" in results.source

    (tmp_path / "shipped").mkdir()
    shipped_rows.to_parquet(tmp_path / "shipped" / "table1.parquet")
    results = notebooks.protocol_results(output, "table1", False, _never)
    assert results.full_protocol and results.raw.equals(shipped_rows) and "shipped with tpvp" in results.source

    (tmp_path / "published" / "02_x" / "results").mkdir(parents=True)
    published.to_parquet(tmp_path / "published" / "02_x" / "results" / "table1.parquet")
    results = notebooks.protocol_results(output, "table1", False, _never)
    assert results.full_protocol and results.raw.equals(published) and "make notebooks" in results.source
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


def test_a_wide_table_is_shown_in_parts_that_repeat_its_keys():
    wide = pd.DataFrame({"case": ["a", "b"], "method": ["x", "y"], **{f"v{i}": [1.0, 2.0] for i in range(10)}})
    parts = table_parts(wide)
    assert [p.columns.tolist() for p in parts] == [["case", "method", *[f"v{i}" for i in range(6)]],
                                                   ["case", "method", *[f"v{i}" for i in range(6, 10)]]]
    one = table_parts(wide.iloc[:1])
    assert len(one) == 1 and one[0].columns.tolist() == ["quantity", "value"] and len(one[0]) == 12
    assert len(table_parts(wide.iloc[:, :5])) == 1 and table_parts(wide.iloc[:, :5])[0].equals(wide.iloc[:, :5])


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
    monkeypatch.setattr(notebooks, "NOTEBOOKS", folder)
    destination = tmp_path / "published"
    done = notebooks.run_notebooks(["01_ok"], full=False, destination=destination, progress=False)
    assert done["01_ok"]["mode"] == "reader" and (destination / "01_ok" / "x.csv").read_text() == "False"
    executed = nbformat.read(destination / "01_ok.ipynb", as_version=4)
    assert executed.cells[1].outputs[0]["text"] == "shown\n"
    assert str(destination / "01_ok") in executed.cells[0].source  # the published path, not the staging one
    before = {p.relative_to(destination): p.read_bytes() for p in destination.rglob("*") if p.is_file()}

    _notebook(folder / "02_broken.ipynb", "raise RuntimeError('half way')")
    with pytest.raises(Exception, match="half way"):
        notebooks.run_notebooks(["01_ok", "02_broken"], full=True, destination=destination, progress=False)
    after = {p.relative_to(destination): p.read_bytes() for p in destination.rglob("*") if p.is_file()}
    assert after == before  # the first notebook's new copy was not published either
    assert json.loads((destination / "manifest.json").read_text())["01_ok"]["mode"] == "reader"
    assert [p.name for p in tmp_path.iterdir() if "staging" in p.name] == []
