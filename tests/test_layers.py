"""The layering rules of docs/architecture.md, read from the code's AST (benchmarks/import_graph.py):
no import cycle, no stage importing ``learning`` or ``experiments``, few function-local imports of
tpvp's own modules and each with its reason, no private name imported from another package."""

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
MAX_LOCAL_IMPORTS = 20


@pytest.fixture(scope="module")
def report():
    spec = importlib.util.spec_from_file_location("import_graph", ROOT / "benchmarks" / "import_graph.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["import_graph"] = module  # dataclasses look their module up there
    spec.loader.exec_module(module)
    return module.analyse()


def test_no_import_cycle(report):
    assert report.cycles == []


def test_no_upward_import(report):
    assert sorted(report.upward) == []


def test_the_data_tools_import_neither_the_planner_nor_the_experiments(report):
    tools = [module for module in report.graph if module.startswith("data_tools")]
    assert "data_tools.greenhouse" in tools
    above = ("tpvp.config", "tpvp.pipeline", "tpvp.learning", "tpvp.experiments", "tpvp.session", "tpvp.cli",
             "tpvp.commands")
    for module in tools:
        assert [m for m in report.graph[module] if m.startswith(above)] == [], module


#: Modules that hold or make the simulator's ground truth.
TRUTH = ("tpvp.scene.simulator", "tpvp.experiments", "tpvp.synthetic", "tpvp.visibility.oracle_cache")


def test_the_planner_cannot_reach_the_ground_truth(report):
    """The pipeline loads nothing that holds the simulator's truth, and what it is given holds none:
    the simulation and a real session hand it the same kind of object."""
    from dataclasses import fields

    from tpvp.pipeline.plant import Known
    from tpvp.pipeline.row import RowKnown

    planners = [module for module in report.graph if module.startswith("tpvp.pipeline")]
    assert {"tpvp.pipeline.plant", "tpvp.pipeline.row"} <= set(planners)
    for module in planners:
        assert [m for m in report.reachable(module) if m.startswith(TRUTH)] == [], module
    truth_fields = {"current", "grid", "oracle", "truth_visibility", "passive_visibility", "passive_seen"}
    for known in (Known, RowKnown):
        assert truth_fields.isdisjoint(f.name for f in fields(known)), known


def test_a_real_session_runs_the_planner_not_the_experiments(report):
    sessions = [module for module in report.graph if module.startswith("tpvp.session")]
    assert "tpvp.session.plant" in sessions
    for module in sessions:
        assert [m for m in report.reachable(module) if m.startswith("tpvp.experiments")] == [], module


def test_function_local_imports_are_few_and_say_why(report):
    assert len(report.local) <= MAX_LOCAL_IMPORTS, report.local
    assert [(file, line) for file, line, text in report.local if "#" not in text] == []


def test_no_private_name_imported_across_packages(report):
    assert report.private == []


def test_a_stage_registry_finds_the_learned_methods_without_importing_torch():
    """The learned planners register through the plugin hook; listing them loads no network."""
    code = ("import sys; from tpvp.nbv.methods import NBV_METHODS; from tpvp.setcover.methods import "
            "SELECTION_METHODS; print('pc-nbv' in NBV_METHODS, 'ma-scvp' in SELECTION_METHODS.names(), "
            "'torch' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT)
    assert out.stdout.split() == ["True", "True", "False"]
