"""tpvp.viz.datasets: the figures and tables of notebook 09 (prepared datasets) and the command
lines it shows."""

from __future__ import annotations

import numpy as np
import pytest

from data_tools.alignment import read_landmarks
from data_tools.errors import CredentialsError, DatasetError
from data_tools.greenhouse import clean_greenhouse
from tpvp.scene.boxes import room_config
from tpvp.viz.datasets import (CLEANING_STEPS, alignment_residuals, error_row, plot_alignment_residuals,
                               plot_cleaning_steps, plot_prepared_pair, plot_session_preparation, run_cli,
                               show_command)


@pytest.fixture(scope="module")
def dataset(raw_standin, tmp_path_factory):
    """The shared raw stand-in's three room1 sessions, cleaned and aligned."""
    out = tmp_path_factory.mktemp("prepare") / "dataset"
    table = clean_greenhouse(raw_standin.folder, out, landmarks=raw_standin.folder / "landmarks", progress=False,
                             log=lambda *_: None)
    return out, table


def _is_png(path) -> bool:
    return path.is_file() and path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_alignment_residuals_measure_the_recovered_transforms(raw_standin, dataset):
    folder, table = dataset
    marks = {d: read_landmarks(p) for d, p in raw_standin.landmarks.items() if p}
    box = room_config("room1").plant_box
    residuals = alignment_residuals(folder, table, landmarks=marks, truth=raw_standin.offsets, box=box)
    assert list(residuals["session"]) == [f"room1 {d}" for d in table["date"]]
    reference, later = residuals.iloc[0], residuals.iloc[1:]
    assert reference["alignment"] == "reference day" and np.isnan(reference["landmarks after ICP RMSE (mm)"])
    assert reference["true error at box corners (mm)"] == pytest.approx(0.0, abs=1e-9)
    # the stand-in's landmarks carry 2 mm picking noise; the recovered transforms are sub-millimetre
    assert ((later["landmarks after ICP RMSE (mm)"] > 1) & (later["landmarks after ICP RMSE (mm)"] < 6)).all()
    assert (later["true error at box corners (mm)"] < 5).all() and (later["true rotation error (deg)"] < 0.1).all()
    assert np.allclose(later["ICP inlier RMSE (mm)"], 1000 * table["inlier_rmse_m"].iloc[1:])
    # without truth or landmarks: only the manifest's columns and empty residuals
    plain = alignment_residuals(folder, table)
    assert "true error at box corners (mm)" not in plain and plain["landmarks after ICP RMSE (mm)"].isna().all()


def test_a_wrong_transform_shows_in_the_true_error(raw_standin, dataset, tmp_path):
    import shutil

    folder, table = dataset
    copy = shutil.copytree(folder, tmp_path / "copy")
    last = table.iloc[-1]
    transform = np.loadtxt(copy / last["transform_file"])
    transform[:3, 3] += [0.01, 0, 0]  # 1 cm off
    np.savetxt(copy / last["transform_file"], transform)
    residuals = alignment_residuals(copy, table, truth=raw_standin.offsets, box=room_config("room1").plant_box)
    assert 9 < residuals["true error at box corners (mm)"].iloc[-1] < 11


def test_figures_are_written_as_png(raw_standin, dataset, tmp_path):
    folder, table = dataset
    rng = np.random.default_rng(0)
    plant = rng.normal(size=(500, 3)) * [0.02, 0.01, 0.03]
    assert _is_png(plot_prepared_pair(tmp_path / "pair.png", plant, plant * 1.1, plant * 5, plant[:100] * 5,
                                      names=("day 1", "day 2"), resolution=0.002, title="pair"))
    assert _is_png(plot_cleaning_steps(tmp_path / "steps.png", table, "steps"))
    assert all(column in table for column, _ in CLEANING_STEPS)
    last = table.iloc[-1]
    from tpvp.io import read_point_cloud

    assert _is_png(plot_session_preparation(
        tmp_path / "session.png", read_point_cloud(folder / "reference" / "room1_static.pcd", units="m"),
        read_point_cloud(raw_standin.scans[last["date"].replace("-", "")], units="m"),
        np.loadtxt(folder / last["transform_file"]), read_point_cloud(folder / last["file"], units="m"),
        box=room_config("room1").plant_box, title="new day"))
    residuals = alignment_residuals(folder, table, truth=raw_standin.offsets, box=room_config("room1").plant_box)
    assert _is_png(plot_alignment_residuals(tmp_path / "residuals.png", residuals, "residuals"))


def test_error_row_keeps_user_errors_and_lets_bugs_through():
    def user_error():
        raise DatasetError("data/x/manifest.csv exists: pass --force")

    assert error_row("exists", user_error) == {"situation": "exists", "error": "DatasetError",
                                               "message": "data/x/manifest.csv exists: pass --force"}
    assert error_row("fine", lambda: None)["error"] == "(no error)"
    with pytest.raises(ZeroDivisionError):
        error_row("bug", lambda: 1 / 0)


def test_run_cli_shows_a_one_line_error_without_credentials(tmp_path, capsys, monkeypatch):
    env = {"HOME": str(tmp_path / "home"), "KAGGLE_CONFIG_DIR": str(tmp_path / "home" / ".kaggle"),
           "XDG_CONFIG_HOME": None, "KAGGLE_API_TOKEN": None, "KAGGLE_USERNAME": None, "KAGGLE_KEY": None}
    result = run_cli("data_tools", "greenhouse", "download", "--output", "raw", cwd=tmp_path, env=env, timeout=120)
    assert result.returncode == 2 and result.shown == "python -m data_tools greenhouse download --output raw"
    assert "no Kaggle credentials found" in result.last_line and result.stderr.count("\n") == 1
    assert not (tmp_path / "raw").exists()
    shown = []
    monkeypatch.setattr("IPython.display.display", lambda obj: shown.append(obj.data))
    show_command(result)
    assert "$ python -m data_tools greenhouse download --output raw" in shown[0]
    assert "exit status 2" in shown[0] and "&lt;token&gt;" in shown[0]  # escaped: shown, not an HTML tag
    assert str(tmp_path) not in shown[0]


def test_credentials_error_class_in_process(tmp_path, monkeypatch):
    from data_tools.kaggle_download import download_greenhouse

    for var in ("KAGGLE_API_TOKEN", "KAGGLE_USERNAME", "KAGGLE_KEY", "XDG_CONFIG_HOME"):
        monkeypatch.setenv(var, "")  # empty counts as absent, as the notebook sets them
    monkeypatch.setenv("HOME", str(tmp_path))
    monkeypatch.setenv("KAGGLE_CONFIG_DIR", str(tmp_path / ".kaggle"))
    row = error_row("no token", download_greenhouse, tmp_path / "out")
    assert row["error"] == CredentialsError.__name__ and "kaggle.com/settings/api" in row["message"]
    assert "\n" not in row["message"]


def test_cleaning_steps_columns_match_the_manifest():
    from data_tools.greenhouse import MANIFEST_COLUMNS

    assert {c for c, _ in CLEANING_STEPS} <= set(MANIFEST_COLUMNS)


def test_show_command_drops_progress_bars(monkeypatch):
    from tpvp.viz.datasets import CommandResult

    result = CommandResult("python -m tpvp greenhouse", None, 0, "  views    385\n",
                           "oracle:  40%|####      | 2/5 [00:32<00:48, 16.10s/chunk]\nwarning: check\n", 1.0)
    shown = []
    monkeypatch.setattr("IPython.display.display", lambda obj: shown.append(obj.data))
    show_command(result)
    assert "views    385" in shown[0] and "warning: check" in shown[0] and "oracle:" not in shown[0]
