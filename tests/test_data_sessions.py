"""prepare-session: a new scan into a dataset - alignment, manifest, refusal to overwrite, no
partial output on bad input or interruption, raw input untouched."""

from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from data_tools import cli
from data_tools.errors import DatasetError, InputFileError, PointCloudError
from data_tools.greenhouse import clean_greenhouse
from data_tools.sessions import prepare_session
from tpvp.errors import ConfigError
from helpers import tree_digest
from tpvp.io import read_point_cloud, write_point_cloud
from tpvp.scene.boxes import room_config


@pytest.fixture(scope="module")
def standin(raw_standin):
    return raw_standin


@pytest.fixture(scope="module")
def base_dataset(standin, tmp_path_factory):
    """A dataset cleaned from the first two sessions; the third is the user's new scan."""
    out = tmp_path_factory.mktemp("ds") / "dataset"
    manifest = out.parent / "two.csv"  # absolute paths: the shared stand-in folder stays untouched
    manifest.write_text(f"site,date,file,landmarks\nroom1,2025-09-15,{standin.scans['20250915']},\n"
                        f"room1,2025-09-18,{standin.scans['20250918']},{standin.landmarks['20250918']}\n")
    clean_greenhouse(None, out, manifest=manifest, progress=False, log=lambda *_: None)
    return out


@pytest.fixture
def dataset(base_dataset, tmp_path):
    import shutil

    return Path(shutil.copytree(base_dataset, tmp_path / "dataset"))


def corner_shift(transform, truth) -> float:
    corners = room_config("room1").plant_box.corners()
    apply = lambda t: corners @ t[:3, :3].T + t[:3, 3]  # noqa: E731
    return float(np.linalg.norm(apply(transform) - apply(truth), axis=1).max())


def test_new_session_is_aligned_cleaned_and_appended(standin, dataset):
    scan = standin.scans["20250922"]
    raw_before = hashlib.sha256(scan.read_bytes()).hexdigest()
    row = prepare_session(dataset, "room1", "2025-09-22", scan, landmarks=standin.landmarks["20250922"])
    assert hashlib.sha256(scan.read_bytes()).hexdigest() == raw_before
    table = pd.read_csv(dataset / "manifest.csv")
    assert list(table["date"]) == ["2025-09-15", "2025-09-18", "2025-09-22"]
    assert row["reference_date"] == "2025-09-15" and row["alignment"] == "landmarks+icp(static)"
    assert row["fitness"] > 0.9
    transform = np.loadtxt(dataset / row["transform_file"])
    assert corner_shift(transform, np.linalg.inv(standin.offsets["20250922"])) < 0.005
    model = read_point_cloud(dataset / row["file"], units="m")
    assert len(model) == row["points"] and room_config("room1").plant_box.contains(model, tol=1e-4).all()
    assert pd.read_parquet(dataset / "manifest.parquet")["date"].tolist() == table["date"].tolist()
    assert not list(dataset.parent.glob(".dataset.tpvp-staging-*")) and not list(dataset.parent.glob(".dataset.tpvp-old-*"))


def test_existing_session_needs_force(standin, dataset, capsys):
    before = tree_digest(dataset)
    args = ["prepare-session", "--dataset", str(dataset), "--site", "room1", "--date", "2025-09-18",
            "--scan", str(standin.scans["20250918"]), "--landmarks", str(standin.landmarks["20250918"])]
    assert cli.main(args) == 2
    err = capsys.readouterr().err
    assert "already exists" in err and "--force" in err and err.count("\n") == 1
    assert tree_digest(dataset) == before
    assert cli.main(args + ["--force"]) == 0
    table = pd.read_csv(dataset / "manifest.csv")
    assert list(table["date"]) == ["2025-09-15", "2025-09-18"]
    # The reference day of other sessions cannot be swapped: their alignment would be wrong.
    with pytest.raises(DatasetError, match="reference day of 1 other session"):
        prepare_session(dataset, "room1", "2025-09-15", standin.scans["20250915"], force=True)
    # The dataset's own model cannot be its own new raw scan (it would be overwritten).
    own = dataset / table["file"].iloc[1]
    with pytest.raises(ConfigError, match="holds the input .*inputs are only read"):
        prepare_session(dataset, "room1", "2025-09-18", own, force=True)


def test_interruption_mid_write_leaves_the_dataset_as_it_was(standin, dataset, monkeypatch):
    import data_tools.sessions as sessions

    before = tree_digest(dataset)
    real = sessions.write_session

    def half_written(stage, scan, cleaned, alignment):
        real(stage, scan, cleaned, alignment)
        stage.path("manifest.csv").write_text("site,date\nroom1,")  # killed while writing the manifest
        raise KeyboardInterrupt

    monkeypatch.setattr(sessions, "write_session", half_written)
    with pytest.raises(KeyboardInterrupt):
        prepare_session(dataset, "room1", "2025-09-22", standin.scans["20250922"],
                        landmarks=standin.landmarks["20250922"])
    assert tree_digest(dataset) == before


def test_interruption_at_the_commit_is_held_back_until_the_dataset_is_whole(standin, dataset, tmp_path, capsys):
    """Ctrl-C while the files move into place: the commit (two renames) finishes first, and the
    report says the dataset was updated; a retry then needs --force like after any finished run."""
    import shutil
    import signal

    from tpvp.io import faults

    args = ["prepare-session", "--dataset", str(dataset), "--site", "room1", "--date", "2025-09-22",
            "--scan", str(standin.scans["20250922"]), "--landmarks", str(standin.landmarks["20250922"])]
    clean = Path(shutil.copytree(dataset, tmp_path / "clean"))
    with faults.inject(None):
        assert cli.main(args[:2] + [str(clean)] + args[3:]) == 0
        steps = faults.steps()
    capsys.readouterr()
    saved = signal.signal(signal.SIGINT, signal.default_int_handler)  # Ctrl-C as in a terminal
    try:
        with faults.inject("interrupt", steps - 2):  # the first rename of the commit
            assert cli.main(args) == 130
    finally:
        signal.signal(signal.SIGINT, saved)
    err = capsys.readouterr().err
    assert "published completely" in err and err.count("\n") == 1
    # ICP's RMSE may differ in its last bit between runs (open3d's parallel sums): compare the
    # manifest as a table, every other file byte for byte.
    new, expected = tree_digest(dataset), tree_digest(clean)
    tables = ("manifest.csv", "manifest.parquet")
    assert {k: v for k, v in new.items() if k not in tables} == {k: v for k, v in expected.items() if k not in tables}
    pd.testing.assert_frame_equal(pd.read_csv(dataset / "manifest.csv"), pd.read_csv(clean / "manifest.csv"))
    assert [p.name for p in dataset.parent.iterdir() if p.name.startswith(".dataset.")] == [".dataset.tpvp-lock"]
    assert cli.main(args) == 2 and "already exists" in capsys.readouterr().err


def test_first_session_of_a_site_starts_a_dataset(standin, tmp_path):
    row = prepare_session(tmp_path / "new", "room1", "20250915", standin.scans["20250915"])
    assert row["alignment"] == "reference day" and row["reference_date"] == "2025-09-15"
    assert (tmp_path / "new" / "reference" / "room1_static.pcd").is_file()
    assert (tmp_path / "new" / "config" / "room1_bbx_config.yaml").is_file()
    row = prepare_session(tmp_path / "new", "room1", "2025-09-18", standin.scans["20250918"],
                          landmarks=standin.landmarks["20250918"])
    assert corner_shift(np.loadtxt(tmp_path / "new" / row["transform_file"]),
                        np.linalg.inv(standin.offsets["20250918"])) < 0.005


def test_site_without_box_is_cleaned_without_crop(tmp_path):
    rng = np.random.default_rng(0)
    plant = rng.normal(0, 0.05, (5000, 3))
    write_point_cloud(tmp_path / "plant.ply", plant)
    row = prepare_session(tmp_path / "ds", "bench3", "2025-10-02", tmp_path / "plant.ply")
    assert row["points_cropped"] == row["points_raw"] == 5000 and row["points"] > 4000


def test_mesh_scan_is_sampled(tmp_path):
    import trimesh

    trimesh.creation.icosphere(subdivisions=3, radius=0.1).export(tmp_path / "plant.obj")
    row = prepare_session(tmp_path / "ds", "pot1", "2025-10-02", tmp_path / "plant.obj")
    model = read_point_cloud(tmp_path / "ds" / row["file"], units="m")
    radius = np.linalg.norm(model - model.mean(axis=0), axis=1)
    assert row["points_raw"] == 100_000 and len(model) == row["points"] > 1000
    assert np.abs(radius - 0.1).max() < 0.01


def bad_inputs(folder: Path, standin) -> list:
    good = read_point_cloud(standin.scans["20250922"], units="m")
    write_point_cloud(folder / "trunc.ply", good[:1000])
    data = (folder / "trunc.ply").read_bytes()
    (folder / "trunc.ply").write_bytes(data[: len(data) - 5000])
    (folder / "header.ply").write_bytes(b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n1\n2\n3\n")
    (folder / "empty.pcd").write_bytes(b"")
    nan = good[:100].copy()
    nan[3, 1] = np.nan
    (folder / "nan.xyz").write_text("\n".join(" ".join(map(str, p)) for p in nan))
    write_point_cloud(folder / "mm.ply", good * 1000.0)
    few = folder / "few.csv"
    few.write_text("source_x,source_y,source_z,target_x,target_y,target_z\n0,0,0,0,0,0\n1,0,0,1,0,0\n")
    scan = standin.scans["20250922"]
    return [  # (scan, landmarks, units, error type, file named, words)
        (folder / "trunc.ply", None, "m", InputFileError, folder / "trunc.ply", "truncated"),
        (folder / "header.ply", None, "m", InputFileError, folder / "header.ply", "property"),
        (folder / "empty.pcd", None, "m", InputFileError, folder / "empty.pcd", "empty"),
        (folder / "nan.xyz", None, "m", PointCloudError, folder / "nan.xyz", "NaN"),
        (folder / "mm.ply", None, "m", PointCloudError, folder / "mm.ply", "millimetres"),
        (scan, few, "m", InputFileError, few, "at least 3"),
        (folder / "missing.ply", None, "m", InputFileError, folder / "missing.ply", "not found"),
    ]


def test_bad_input_gives_one_clear_error_and_no_partial_output(standin, dataset, tmp_path):
    before = tree_digest(dataset)
    for scan, landmarks, units, error, named, words in bad_inputs(tmp_path, standin):
        with pytest.raises(error) as info:
            prepare_session(dataset, "room1", "2025-09-22", scan, landmarks=landmarks, units=units)
        message = str(info.value)
        assert str(named) in message and words.lower() in message.lower() and "\n" not in message, message
        assert tree_digest(dataset) == before


def test_millimetre_scan_of_a_new_site_is_caught_by_the_units_check(tmp_path):
    write_point_cloud(tmp_path / "row_mm.ply", room_config("room1").plant_box.sample_uniform(500, 0) * 1000)
    with pytest.raises(PointCloudError, match="millimetres"):
        prepare_session(tmp_path / "ds", "room1", "2025-09-15", tmp_path / "row_mm.ply")
    assert not (tmp_path / "ds").exists()


def test_bad_date_and_manifest(standin, dataset):
    with pytest.raises(ConfigError, match="YYYY-MM-DD"):
        prepare_session(dataset, "room1", "2025-13-40", standin.scans["20250922"])
    (dataset / "manifest.csv").write_text("site,date\nroom1,2025-09-15\n")
    with pytest.raises(DatasetError, match="missing column"):
        prepare_session(dataset, "room1", "2025-09-22", standin.scans["20250922"])
