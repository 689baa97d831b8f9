"""The command line: version, configuration commands and the checks made before any work."""

import json
import subprocess
import sys

import numpy as np
import pytest

from tpvp import __version__
from tpvp.cli import main
from tpvp.config_loading import load_config


def _one_error_line(capsys, *words):
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    for word in words:
        assert word in lines[0], lines[0]
    return lines[0]


def test_version(capsys):
    with pytest.raises(SystemExit) as info:
        main(["--version"])
    assert info.value.code == 0 and capsys.readouterr().out.strip() == f"tpvp {__version__}"


def _loaded_after(code: str) -> list[str]:
    """The heavy packages and tpvp command modules a fresh Python has loaded after ``code``."""
    probe = (f"import sys\n{code}\nprint(sorted(m for m in sys.modules if m.split('.')[0] in "
             "('numpy', 'scipy', 'numba', 'pandas', 'matplotlib', 'rerun', 'torch', 'open3d') or "
             "m.startswith('tpvp.commands')))")
    done = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, check=True)
    return eval(done.stdout.strip().splitlines()[-1])


def test_help_loads_no_command_and_no_numeric_package():
    """``tpvp --help`` builds the command list from tpvp.cli.COMMANDS alone (a few hundredths of
    a second; benchmarks/first_run.py times it)."""
    from tpvp.cli import COMMANDS, build_parser

    assert _loaded_after("from tpvp.cli import main\ntry: main(['--help'])\nexcept SystemExit: pass") == []
    listed = build_parser(None).format_help()
    assert all(name in listed for name in COMMANDS)


def test_plan_loads_neither_matplotlib_nor_rerun():
    """The plan's figures and recording are drawn by the drawing process (tpvp.viz.background)."""
    loaded = _loaded_after("from tpvp.cli import build_parser\nbuild_parser('plan')")
    assert "tpvp.commands.plant" in loaded and "numpy" in loaded
    assert not [m for m in loaded if m.startswith(("matplotlib", "rerun"))], loaded


def test_config_command_prints_a_loadable_resolved_configuration(tmp_path, capsys):
    assert main(["config", "--set", "gt_resolution=0.001", "--view-space", "sphere", "--derived"]) == 0
    out = capsys.readouterr().out
    assert "# derived parameters" in out and "inflation.gamma_far = 2.5 x gt_resolution" in out
    (tmp_path / "c.yaml").write_text(out)
    config = load_config(tmp_path / "c.yaml")
    assert config.view_space == "sphere" and config.inflation.gamma_far == pytest.approx(0.0025)


@pytest.mark.parametrize("argv, words", [
    (["demo", "--initial-view", "40"], ["initial_view 40", "32 views"]),
    (["demo", "--initial-view", "top"], ["'top'", "near_top"]),
    (["demo", "--set", "registration.iters=3"], ["unknown configuration key 'registration.iters'"]),
    (["demo", "--set", "nbv.method=random"], ["unknown NBV method 'random'"]),
    (["demo", "--config", "nowhere.yaml"], ["nowhere.yaml"]),
])
def test_bad_options_are_refused_before_any_work_on_one_line(tmp_path, capsys, argv, words):
    assert main([*argv, "--output", str(tmp_path / "out")]) == 2
    _one_error_line(capsys, *words)
    assert not (tmp_path / "out").exists()


def test_plan_refuses_an_out_of_range_initial_view_before_reading_scans(tmp_path, capsys):
    assert main(["plan", "--previous", str(tmp_path / "a.ply"), "--current", str(tmp_path / "b.ply"),
                 "--view-space", "sphere", "--initial-view", "63", "--output", str(tmp_path / "o")]) == 2
    _one_error_line(capsys, "initial_view 63", "63 views")


def test_unknown_view_space_is_one_line():
    result = subprocess.run([sys.executable, "-m", "tpvp", "plan", "--previous", "a", "--current", "b",
                             "--view-space", "cube"], capture_output=True, text=True)
    assert result.returncode == 2 and "Traceback" not in result.stderr
    assert "'cube' is neither one of hemisphere" in result.stderr


def test_plan_on_gzip_scans_says_which_units_it_chose(tmp_path, capsys):
    import gzip

    from tpvp.scene.samples import sample_path

    data = gzip.decompress(sample_path("tomato_0306").read_bytes())
    rows = np.loadtxt(data.decode().splitlines())[::4]  # a quarter of the points keeps it quick
    for name in ("day1.xyz.gz", "day2.xyz.gz"):
        (tmp_path / name).write_bytes(gzip.compress("\n".join(" ".join(map(str, r[:3])) for r in rows).encode()))
    assert main(["plan", "--previous", str(tmp_path / "day1.xyz.gz"), "--current", str(tmp_path / "day2.xyz.gz"),
                 "--set", "registration.embedded_deformation.iterations=5", "--output", str(tmp_path / "o")]) == 0
    out = capsys.readouterr().out
    assert "day1.xyz.gz: units: auto -> mm" in out
    for name in ("plan.csv", "plan_normalised.csv", "plan.json", "config.yaml", "provenance.json"):
        assert (tmp_path / "o" / name).stat().st_size > 0


def _cloud(path, points):
    np.savetxt(path, points)
    return str(path)


def test_implausible_scans_are_refused_in_the_scans_terms(tmp_path, capsys):
    rng = np.random.default_rng(0)
    plant = rng.normal(size=(3000, 3)) * 0.02
    good = _cloud(tmp_path / "good.xyz", plant)
    out = str(tmp_path / "o")
    three = _cloud(tmp_path / "three.xyz", plant[:3])
    assert main(["plan", "--previous", good, "--current", three, "--units", "m", "--output", out]) == 2
    _one_error_line(capsys, "three.xyz", "only 3 occupied 2 mm voxels")
    far = _cloud(tmp_path / "far.xyz", plant + [5.0, 0, 0])
    assert main(["plan", "--previous", far, "--current", good, "--units", "m", "--output", out]) == 2
    _one_error_line(capsys, "far.xyz", "good.xyz", "do not overlap", "m apart")
    small = _cloud(tmp_path / "small.xyz", plant / 1000)
    assert main(["plan", "--previous", small, "--current", good, "--units", "m", "--output", out]) == 2
    _one_error_line(capsys, "small.xyz", "different units")
    holes = plant.copy()
    holes[10] = np.nan
    nan = _cloud(tmp_path / "nan.xyz", holes)
    assert main(["plan", "--previous", nan, "--current", good, "--units", "m", "--output", out]) == 2
    _one_error_line(capsys, "nan.xyz", "--drop-invalid")
    assert not (tmp_path / "o").exists()


def test_a_previous_session_of_another_plant_is_warned_about(tmp_path, capsys):
    # The audit's case: the bundled real maize as the previous session of the real tomato ends at
    # 18.5 mm Chamfer (7.7 % of the plant); matching real and generated pairs end at 0.4-0.7 %.
    from tpvp.scene.samples import load_sample

    previous = _cloud(tmp_path / "maize.xyz", load_sample("maize_0313")[::4])
    current = _cloud(tmp_path / "tomato.xyz", load_sample("tomato_0306"))
    assert main(["plan", "--previous", previous, "--current", current, "--units", "m",
                 "--set", "registration.embedded_deformation.iterations=100", "--output", str(tmp_path / "o")]) == 0
    err = capsys.readouterr().err
    assert "warning: registration of" in err and "maize.xyz" in err and "same plant" in err
    assert "same plant" in json.loads((tmp_path / "o" / "results.json").read_text())["warnings"]


def test_demo_with_a_coverage_target_takes_fewer_views(tmp_path, capsys):
    assert main(["demo", "--coverage-target", "0.95", "--output", str(tmp_path / "out")]) == 0
    out = capsys.readouterr().out
    assert "of the coverable planning surface" in out
    results = json.loads((tmp_path / "out" / "results.json").read_text())
    assert results["set_cover_covered_weight"] >= 0.95 * results["set_cover_achievable_weight"]
    assert results["views"] < 7 and results["set_cover_optimal"]  # the full set cover takes 7 (README)
    assert "coverage_target: 0.95" in (tmp_path / "out" / "config.yaml").read_text()


@pytest.mark.slow
def test_demo_frontier_writes_the_table_and_figure(tmp_path, capsys):
    """--frontier adds the coverage-effort frontier of the case: one row per target, the plan's views
    never fewer for a higher target, the optimum never more views than the plan reaching the same
    true coverage would need."""
    import pandas as pd

    assert main(["demo", "--frontier", "--output", str(tmp_path / "out")]) == 0
    out = capsys.readouterr().out
    assert "coverage-effort frontier" in out
    frontier = pd.read_csv(tmp_path / "out" / "frontier.csv")
    assert (tmp_path / "out" / "frontier.png").stat().st_size > 10_000
    assert list(frontier["target"]) == sorted(frontier["target"]) and frontier["target"].iloc[-1] == 1.0
    assert frontier["views"].is_monotonic_increasing and frontier["optimum_views"].is_monotonic_increasing
    assert (frontier["optimum_coverage"] >= frontier["target"] - 1e-12).all()
    results = json.loads((tmp_path / "out" / "results.json").read_text())
    assert frontier["views"].iloc[-1] == results["views"]  # target 1.0 is the plan of the run itself
