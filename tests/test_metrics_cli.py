"""Geometric metrics and the command line."""

import json

import numpy as np
import pytest

from tpvp.cli import main
from tpvp.errors import ConfigError, PointCloudError
from tpvp.metrics import chamfer_distance, f_score


def test_chamfer_and_fscore_against_brute_force():
    rng = np.random.default_rng(0)
    a = rng.normal(size=(60, 3))
    b = rng.normal(size=(45, 3))
    d = np.linalg.norm(a[:, None] - b[None], axis=2)
    assert chamfer_distance(a, b) == pytest.approx(0.5 * (d.min(1).mean() + d.min(0).mean()))
    score = f_score(a, b, 0.5)
    assert score.precision == pytest.approx((d.min(1) <= 0.5).mean())
    assert score.recall == pytest.approx((d.min(0) <= 0.5).mean())
    assert chamfer_distance(a, a) == 0
    assert f_score(a, a, 1e-9).f1 == 1.0
    with pytest.raises(ConfigError):
        f_score(a, b, 0)
    with pytest.raises(PointCloudError):
        chamfer_distance(a, np.zeros((0, 3)))


def test_render_entry_point(tmp_path, capsys):
    assert main(["render", "--output", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "oracle visible set over 32 hemisphere views" in out
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["plant_voxels"] == 3890 and summary["oracle_voxels"] > 3000
    table = (tmp_path / "coverage_per_view.csv").read_text().splitlines()
    assert len(table) == 33
    assert float(table[-1].split(",")[-1]) == pytest.approx(1.0)


def test_demo_entry_point_writes_every_output(tmp_path, capsys):
    assert main(["demo", "--output", str(tmp_path)]) == 0
    assert "coverage of the oracle set" in capsys.readouterr().out
    results = json.loads((tmp_path / "results.json").read_text())
    assert results["coverage"] > 0.95 and results["views"] >= 3 and results["set_cover_optimal"]
    plan = json.loads((tmp_path / "plan.json").read_text())
    assert len(plan["views"]) == results["views"]
    q = np.array([[v["qx"], v["qy"], v["qz"], v["qw"]] for v in plan["views"]])
    np.testing.assert_allclose(np.linalg.norm(q, axis=1), 1.0, atol=1e-5)
    for name in ("plan.csv", "results.csv", "plan.png", "coverage.png", "recording.rrd"):
        assert (tmp_path / name).stat().st_size > 0
    assert not list(tmp_path.glob(".*tmp*"))


def test_plan_command_reports_bad_input_on_one_line(tmp_path, capsys):
    missing = tmp_path / "nope.ply"
    assert main(["plan", "--previous", str(missing), "--current", str(missing), "--output", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "nope.ply" in err and "Traceback" not in err and len(err.strip().splitlines()) == 1
    far = tmp_path / "far.xyz"
    near = tmp_path / "near.xyz"
    rng = np.random.default_rng(0)
    np.savetxt(near, rng.normal(size=(500, 3)) * 0.03)
    np.savetxt(far, rng.normal(size=(500, 3)) * 0.03 + [5.0, 0, 0])
    assert main(["plan", "--previous", str(far), "--current", str(near), "--units", "m",
                 "--output", str(tmp_path / "o")]) == 2
    assert "Traceback" not in capsys.readouterr().err
