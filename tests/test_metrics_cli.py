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


def test_demo_entry_point(tmp_path, capsys):
    assert main(["demo", "--output", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "oracle visible set over 32 hemisphere views" in out
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert summary["plant_voxels"] == 3890 and summary["oracle_voxels"] > 3000
    table = (tmp_path / "coverage_per_view.csv").read_text().splitlines()
    assert len(table) == 33
    assert float(table[-1].split(",")[-1]) == pytest.approx(1.0)
