"""Every notebook runs unattended in quick mode and is stored without outputs."""

import json

import pytest

from tpvp.experiments.notebooks import notebook_paths, run_notebook

NOTEBOOKS = notebook_paths()


def test_there_is_a_notebook_per_experiment():
    names = [p.stem for p in NOTEBOOKS]
    assert names == ["01_getting_started", "02_table1_coverage_effort", "03_table2_plant_complexity",
                     "04_ablations_tables3_4", "05_greenhouse_rows_tables5_6", "06_pose_noise_table7",
                     "07_planning_time", "08_learned_baselines"]


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_stored_without_outputs(path):
    notebook = json.loads(path.read_text())
    for cell in notebook["cells"]:
        if cell["cell_type"] == "code":
            assert cell["outputs"] == [] and cell["execution_count"] is None, path.name
    first = next(c for c in notebook["cells"] if c["cell_type"] == "code")
    assert "quick = " in "".join(first["source"])


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_runs_in_quick_mode(path, tmp_path):
    run_notebook(path, quick=True, output=tmp_path, timeout=600)
    written = [p for p in tmp_path.rglob("*") if p.is_file() and p.suffix in (".png", ".csv")]
    assert written, f"{path.name} wrote no figure or table"
