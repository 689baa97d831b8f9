"""The notebook runner: where a notebook's table rows come from, and publishing executed copies whole."""

import json

import nbformat
import pandas as pd
import pytest

from tpvp.experiments import notebooks
from tpvp.viz.notebook import beside_paper, mean_std


def _never():
    raise AssertionError("must not be called")


def test_full_mode_computes_and_keeps_the_rows_for_make_notebooks(tmp_path):
    rows = pd.DataFrame({"views": [3, 4]})
    results = notebooks.protocol_results(tmp_path / "02_x", "table1", True, lambda: rows, _never, _never)
    assert results.full_protocol and results.raw.equals(rows)
    assert pd.read_parquet(tmp_path / "02_x" / "results" / "table1.parquet").equals(rows)


def test_reader_mode_prefers_the_cache_then_the_published_rows_then_a_labelled_reduced_run(tmp_path, monkeypatch):
    monkeypatch.setenv("TPVP_NOTEBOOK_RESULTS", str(tmp_path / "published"))
    cached, published, reduced = (pd.DataFrame({"views": [v]}) for v in (1, 2, 3))
    output = tmp_path / "reader" / "02_x"

    results = notebooks.protocol_results(output, "table1", False, _never, lambda: cached, _never)
    assert results.full_protocol and results.raw.equals(cached) and "cache" in results.source

    results = notebooks.protocol_results(output, "table1", False, _never, lambda: None, lambda: reduced)
    assert not results.full_protocol and results.raw.equals(reduced) and "REDUCED" in results.source

    (tmp_path / "published" / "02_x" / "results").mkdir(parents=True)
    published.to_parquet(tmp_path / "published" / "02_x" / "results" / "table1.parquet")
    results = notebooks.protocol_results(output, "table1", False, _never, lambda: None, _never)
    assert results.full_protocol and results.raw.equals(published) and "make notebooks" in results.source
    assert not (output / "results").exists()  # reader's mode never writes rows that look like the protocol's


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
