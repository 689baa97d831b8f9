"""Greenhouse dataset tools: session discovery, cleaning, alignment to day one, Kaggle download.

The real dataset cannot be downloaded here; the generated rows of tpvp.synthetic.greenhouse, written in
the dataset's layouts by data_tools.greenhouse_standin (processed models, and raw captures with static
greenhouse structure, outliers, known rigid offsets and landmark files), go through the same path.
"""

from __future__ import annotations

import sys
import types
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.spatial import cKDTree

from data_tools import cli
from data_tools.cleaning import clean_scan, find_support_planes, fragment_mask
from data_tools.errors import CredentialsError, DatasetError, InputFileError, PointCloudError
from data_tools.greenhouse import MANIFEST_COLUMNS, clean_greenhouse, find_sessions, parse_date
from data_tools.kaggle_download import download_greenhouse, find_kaggle_credentials
from data_tools.greenhouse_standin import static_structure, write_processed_standin, write_raw_standin
from tpvp.errors import ConfigError
from helpers import tree_digest
from tpvp.io import read_point_cloud, write_point_cloud
from tpvp.scene.boxes import room_config
from tpvp.synthetic.greenhouse import generate_row


def quiet(*_):
    pass


@pytest.fixture(scope="module")
def raw(raw_standin):
    return raw_standin


@pytest.fixture(scope="module")
def cleaned(raw, tmp_path_factory):
    out = tmp_path_factory.mktemp("clean") / "dataset"
    table = clean_greenhouse(raw.folder, out, landmarks=raw.folder / "landmarks", progress=False, log=quiet)
    return out, table


# ----------------------------------------------------------------------------- discovery
def test_find_sessions_reports_what_was_found_and_skipped(tmp_path):
    box = room_config("room1").plant_box
    cloud = box.sample_uniform(50, 0)
    for name in ("Processed_3D_Model/room1_20250915.pcd", "captures/room1_20250915_polycam.ply",
                 "captures/room4-2025-09-18.ply", "captures/plant_scan.ply", "captures/room1_20251345.ply"):
        write_point_cloud(tmp_path / name, cloud)
    (tmp_path / "captures/room4_20250918_mesh.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    (tmp_path / "captures/room1_20250915.jpg").write_bytes(b"jpeg")
    (tmp_path / "captures/room4_20250918_landmarks.csv").write_text("x")
    found = find_sessions(tmp_path)
    assert [(s.site, str(s.date), s.path.name) for s in found.sessions] == [
        ("room1", "2025-09-15", "room1_20250915.pcd"), ("room4", "2025-09-18", "room4-2025-09-18.ply")]
    skipped = dict(found.skipped)
    assert "another file of room1 2025-09-15 was used: Processed_3D_Model/room1_20250915.pcd" in skipped["captures/room1_20250915_polycam.ply"]
    assert "room4-2025-09-18.ply" in skipped["captures/room4_20250918_mesh.obj"]
    assert "no room and date" in skipped["captures/plant_scan.ply"]
    assert [str(s.date) for s in find_sessions(tmp_path / "captures").sessions] == ["2025-09-15", "2025-09-18"]
    # Polycam-style folders: the session is named by the folders, the file name is generic.
    write_point_cloud(tmp_path / "polycam" / "room4" / "2025-09-22" / "pointcloud.ply", cloud)
    write_point_cloud(tmp_path / "polycam" / "room4_20250925" / "pointcloud.ply", cloud)
    assert [(s.site, str(s.date)) for s in find_sessions(tmp_path / "polycam").sessions] == [
        ("room4", "2025-09-22"), ("room4", "2025-09-25")]
    assert "not a valid date" in skipped["captures/room1_20251345.ply"]
    assert "not a point cloud" in skipped["captures/room1_20250915.jpg"]
    assert "landmarks file" in skipped["captures/room4_20250918_landmarks.csv"]
    report = found.report()
    assert "found 2 session(s)" in report and "skipped 6 file(s)" in report


def test_find_sessions_from_an_explicit_manifest(tmp_path):
    write_point_cloud(tmp_path / "a.ply", np.random.default_rng(0).random((10, 3)))
    (tmp_path / "lm.csv").write_text("")
    manifest = tmp_path / "list.csv"
    manifest.write_text("room,date,file,landmarks\nRoom1,2025-09-18,a.ply,lm.csv\nroom1,20250915,a.ply,\n")
    found = find_sessions(None, manifest=manifest)
    assert [(s.site, str(s.date), s.landmarks.name if s.landmarks else None) for s in found.sessions] == [
        ("room1", "2025-09-15", None), ("room1", "2025-09-18", "lm.csv")]
    manifest.write_text("site,date,file\nroom1,2025-09-18,missing.ply\n")
    with pytest.raises(InputFileError, match=r"row 2: file 'missing.ply' not found"):
        find_sessions(None, manifest=manifest)
    manifest.write_text("site,file\nroom1,a.ply\n")
    with pytest.raises(DatasetError, match="missing column"):
        find_sessions(None, manifest=manifest)
    manifest.write_text("site,date,file\nroom1,2025-09-18,a.ply\nroom1,2025-09-18,a.ply\n")
    with pytest.raises(DatasetError, match="listed twice"):
        find_sessions(None, manifest=manifest)


def test_find_sessions_errors(tmp_path):
    with pytest.raises(InputFileError, match="folder not found"):
        find_sessions(tmp_path / "nowhere")
    (tmp_path / "notes.txt").write_text("hello")
    with pytest.raises(InputFileError, match="no session scans found"):
        find_sessions(tmp_path)


@pytest.mark.parametrize("text", ["2025-9-18", "20251301", "yesterday", "2025/09/18"])
def test_parse_date_rejects_bad_dates(text):
    with pytest.raises(ConfigError, match="YYYY-MM-DD"):
        parse_date(text)


# ----------------------------------------------------------------------------- cleaning steps
def test_support_planes_remove_the_gutter_but_no_foliage():
    box = room_config("room1").plant_box
    plant = generate_row("room1", 0, 0, 0.01).points
    static, _ = static_structure(box)
    gutter = static[box.contains(static)]
    points = np.concatenate([plant, gutter])
    removed = find_support_planes(points, box)
    assert removed[len(plant):].mean() > 0.99  # the gutter
    assert removed[:len(plant)].mean() < 0.01  # plant points on the gutter's plane only


def test_fragment_mask_matches_brute_force_components():
    rng = np.random.default_rng(3)
    blobs = [rng.normal(c, 0.01, (n, 3)) for c, n in (((0, 0, 0), 400), ((1, 0, 0), 30), ((0, 1, 0), 3))]
    points = np.concatenate(blobs)
    keep = fragment_mask(points, 0.03, 0.05)
    # Brute force: components of the "voxels touch" graph by flood fill over all point pairs.
    keys = np.floor(points / 0.03).astype(int)
    touching = np.abs(keys[:, None, :] - keys[None, :, :]).max(axis=2) <= 1
    label = -np.ones(len(points), int)
    for start in range(len(points)):
        if label[start] < 0:
            label[start], stack = start, [start]
            while stack:
                for j in np.flatnonzero(touching[stack.pop()] & (label < 0)):
                    label[j] = start
                    stack.append(j)
    sizes = np.bincount(label, minlength=len(points))
    np.testing.assert_array_equal(keep, sizes[label] >= 0.05 * len(points))
    assert keep[:400].all() and not keep[430:].any()


def test_clean_scan_outside_the_box_is_a_clear_error():
    box = room_config("room1").plant_box
    with pytest.raises(PointCloudError, match="no point of the scan lies in the plant box"):
        clean_scan(box.sample_uniform(100, 0) + 50.0, box)


# ----------------------------------------------------------------------------- clean, end to end
def test_clean_raw_captures_recovers_offsets_keeps_plants_removes_background(raw, cleaned):
    out, table = cleaned
    assert list(table.columns) == list(MANIFEST_COLUMNS)
    assert list(table["date"]) == ["2025-09-15", "2025-09-18", "2025-09-22"]
    assert (table["reference_date"] == "2025-09-15").all()
    counts = table[["points_raw", "points_cropped", "points_supports_removed", "points_outliers_removed",
                    "points_downsampled", "points"]].to_numpy()
    assert (np.diff(counts, axis=1) <= 0).all()
    assert list(table["alignment"]) == ["reference day", "landmarks+icp(static)", "landmarks+icp(static)"]
    assert (table["fitness"].iloc[1:] > 0.9).all() and (table["inlier_rmse_m"].iloc[1:] < 0.015).all()
    box = room_config("room1").plant_box
    for k, row in table.iterrows():
        date = row["date"].replace("-", "")
        transform = np.loadtxt(out / row["transform_file"])
        truth = np.linalg.inv(raw.offsets[date])
        corners = box.corners()
        shift = np.linalg.norm((corners @ transform[:3, :3].T + transform[:3, 3])
                               - (corners @ truth[:3, :3].T + truth[:3, 3]), axis=1).max()
        assert shift < 0.005, (date, shift)
        model = read_point_cloud(out / row["file"], units="m")
        assert len(model) == row["points"]
        plant = generate_row("room1", 0, k, 0.01).points
        near_plant = cKDTree(plant).query(model)[0] <= 0.015
        assert near_plant.mean() > 0.995, "background, supports or outliers left"
        assert (cKDTree(model).query(plant)[0] <= 0.01).mean() > 0.98, "plant removed"
    saved = pd.read_csv(out / "manifest.csv")
    assert len(saved) == 3 and (out / "manifest.parquet").is_file()
    assert (out / "config" / "room1_bbx_config.yaml").is_file() and (out / "reference" / "room1_static.pcd").is_file()
    figure = (out / "report" / "room1_sessions.png").read_bytes()
    assert figure.startswith(b"\x89PNG") and len(figure) > 20_000
    assert not list(out.parent.glob(f".{out.name}.tpvp-staging-*")) and not list(out.parent.glob(f".{out.name}.tpvp-old-*"))


def test_cleaning_processed_models_again_is_harmless(tmp_path):
    folder = write_processed_standin(tmp_path / "kaggle", n_sessions=2)
    before = tree_digest(folder)
    out = tmp_path / "dataset"
    table = clean_greenhouse(folder.parent, out, progress=False, log=quiet)
    assert tree_digest(folder) == before  # raw data never modified
    assert list(table["alignment"]) == ["reference day", "identity"]
    for k, row in table.iterrows():
        original = read_point_cloud(folder / f"room1_{row['date'].replace('-', '')}.pcd", units="m")
        again = read_point_cloud(out / row["file"], units="m")
        # Downsampling moves points to voxel means, so compare by distance, not by voxel keys.
        kept = (cKDTree(again).query(original)[0] <= 0.01).mean()
        assert kept > 0.98, kept
        assert row["points_cropped"] == row["points_raw"] == len(original)  # nothing outside the box


@pytest.mark.slow
def test_existing_dataset_needs_force_and_interrupted_rebuild_changes_nothing(raw, cleaned, tmp_path, monkeypatch):
    out = tmp_path / "dataset"
    source = raw.folder
    table = clean_greenhouse(source, out, landmarks=source / "landmarks", progress=False, log=quiet)
    before = tree_digest(out)
    with pytest.raises(DatasetError, match="pass --force"):
        clean_greenhouse(source, out, progress=False, log=quiet)
    import data_tools.greenhouse as greenhouse

    calls = []
    real = greenhouse.write_session

    def interrupted(stage, scan, *args):
        calls.append(scan.name)
        if len(calls) == 2:  # the second session is half-written when the user hits Ctrl-C
            stage.path(f"Processed_3D_Model/{scan.name}.pcd").write_bytes(b"# .PCD v0.7\nVERSION")
            raise KeyboardInterrupt
        real(stage, scan, *args)

    monkeypatch.setattr(greenhouse, "write_session", interrupted)
    with pytest.raises(KeyboardInterrupt):
        clean_greenhouse(source, out, landmarks=source / "landmarks", force=True, progress=False, log=quiet)
    assert tree_digest(out) == before
    monkeypatch.setattr(greenhouse, "write_session", real)
    again = clean_greenhouse(source, out, landmarks=source / "landmarks", force=True, progress=False, log=quiet)
    pd.testing.assert_frame_equal(again, table)  # deterministic


def test_interrupted_first_run_leaves_no_output_folder(raw, tmp_path, monkeypatch):
    import data_tools.manifest as manifest

    def broken(*_a, **_k):
        raise KeyboardInterrupt

    monkeypatch.setattr(manifest, "write_table", broken)
    with pytest.raises(KeyboardInterrupt):
        clean_greenhouse(raw.folder, tmp_path / "new", landmarks=raw.folder / "landmarks", progress=False, log=quiet)
    assert not (tmp_path / "new").exists()


def bad_scans(folder: Path) -> dict:
    box = room_config("room1").plant_box
    good = box.sample_uniform(2000, 0)
    write_point_cloud(folder / "truncated" / "room1_20250915.ply", good)
    data = (folder / "truncated" / "room1_20250915.ply").read_bytes()
    (folder / "truncated" / "room1_20250915.ply").write_bytes(data[: len(data) // 2])
    (folder / "header").mkdir()
    (folder / "header" / "room1_20250915.ply").write_bytes(b"ply\nformat binary_middle_endian 1.0\nend_header\n")
    (folder / "empty").mkdir()
    (folder / "empty" / "room1_20250915.ply").write_bytes(b"")
    nan = good.copy()
    nan[5] = np.nan
    (folder / "nan").mkdir()
    (folder / "nan" / "room1_20250915.xyz").write_text("\n".join(" ".join(map(str, p)) for p in nan))
    write_point_cloud(folder / "mm" / "room1_20250915.ply", good * 1000.0)
    return {"truncated": "truncated", "header": "binary_middle_endian", "empty": "empty",
            "nan": "NaN", "mm": "millimetres"}


def test_bad_scans_give_one_clear_error_and_no_output(tmp_path):
    for case, match in bad_scans(tmp_path / "in").items():
        scan = next((tmp_path / "in" / case).iterdir())
        with pytest.raises((InputFileError, PointCloudError)) as info:
            clean_greenhouse(tmp_path / "in" / case, tmp_path / "out", progress=False, log=quiet)
        message = str(info.value)
        assert str(scan) in message and "\n" not in message, message
        assert match.lower() in message.lower(), message
        assert not (tmp_path / "out").exists()


def test_scans_in_millimetres_clean_with_units_mm(tmp_path):
    standin = write_raw_standin(tmp_path / "raw", n_sessions=1, units="mm")
    table = clean_greenhouse(standin.folder, tmp_path / "out", units="mm", progress=False, log=quiet)
    assert table["points"].iloc[0] > 0.8 * standin.plant_points / 1.2
    assert table["extent_z"].iloc[0] < 2.4


def test_output_inside_the_source_is_refused_before_anything_is_written(tmp_path):
    # An output inside the raw folder used to be accepted: a later clean of that folder would read
    # the dataset's Processed_3D_Model as raw scans (tests/test_data_outputs.py covers every command).
    folder = write_processed_standin(tmp_path / "kaggle", n_sessions=1)
    before = tree_digest(tmp_path)
    for output, why in ((tmp_path / "kaggle" / "clean", "lies inside the input"),
                        (tmp_path / "kaggle", "is the input"), (folder, "lies inside the input")):
        with pytest.raises(ConfigError, match=why):
            clean_greenhouse(tmp_path / "kaggle", output, force=True, progress=False, log=quiet)
    assert tree_digest(tmp_path) == before and not (tmp_path / "kaggle" / "clean").exists()


def test_site_without_box_configuration(tmp_path):
    write_point_cloud(tmp_path / "in" / "room7_20250915.ply", np.random.default_rng(0).random((100, 3)))
    with pytest.raises(InputFileError, match="no plant box for site 'room7'"):
        clean_greenhouse(tmp_path / "in", tmp_path / "out", progress=False, log=quiet)


# ----------------------------------------------------------------------------- Kaggle
@pytest.fixture
def no_credentials(tmp_path, monkeypatch):
    for var in ("KAGGLE_API_TOKEN", "KAGGLE_USERNAME", "KAGGLE_KEY", "KAGGLE_CONFIG_DIR", "XDG_CONFIG_HOME"):
        monkeypatch.delenv(var, raising=False)
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    return tmp_path / "home"


def test_missing_kaggle_credentials_say_how_to_create_a_token(no_credentials, tmp_path, capsys):
    with pytest.raises(CredentialsError, match="kaggle.com/settings/api"):
        download_greenhouse(tmp_path / "out", log=quiet)
    assert not (tmp_path / "out").exists()
    assert cli.main(["greenhouse", "download", "--output", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "no Kaggle credentials found" in err and "KAGGLE_API_TOKEN" in err


def test_malformed_kaggle_json(no_credentials):
    (no_credentials / ".kaggle").mkdir(parents=True)
    (no_credentials / ".kaggle" / "kaggle.json").write_text('{"username": "me"}')
    with pytest.raises(CredentialsError, match='needs both "username" and "key"'):
        find_kaggle_credentials()


def test_download_uses_kaggle_without_printing_the_token(no_credentials, tmp_path, monkeypatch, capsys):
    secret = "KGAT_0123456789abcdef"
    monkeypatch.setenv("KAGGLE_API_TOKEN", secret)
    calls = {}

    class FakeApi:
        def authenticate(self):
            calls["authenticated"] = True

        def dataset_download_files(self, dataset, path=None, force=False, quiet=True, unzip=False):
            calls.update(dataset=dataset, path=path, unzip=unzip)
            write_point_cloud(Path(path) / "Processed_3D_Model" / "room1_20250915.pcd", np.ones((3, 3)))

    module = types.ModuleType("kaggle.api.kaggle_api_extended")
    module.KaggleApi = FakeApi
    monkeypatch.setitem(sys.modules, "kaggle.api.kaggle_api_extended", module)
    assert cli.main(["greenhouse", "download", "--output", str(tmp_path / "raw")]) == 0
    out = capsys.readouterr()
    assert calls == {"authenticated": True, "dataset": "sicongpan/greenhouse-multi-session-row-dataset",
                     "path": str(tmp_path / "raw"), "unzip": True}
    assert "KAGGLE_API_TOKEN" in out.out and secret not in out.out + out.err
    assert (tmp_path / "raw" / "Processed_3D_Model" / "room1_20250915.pcd").is_file()


def test_kaggle_network_failure_is_one_clear_error(no_credentials, tmp_path, monkeypatch):
    monkeypatch.setenv("KAGGLE_USERNAME", "me")
    monkeypatch.setenv("KAGGLE_KEY", "0123abcd")

    class OfflineApi:
        def authenticate(self):
            pass

        def dataset_download_files(self, *a, **k):
            raise ConnectionError("Max retries exceeded with url: /api/v1/datasets/download\nmore")

    module = types.ModuleType("kaggle.api.kaggle_api_extended")
    module.KaggleApi = OfflineApi
    monkeypatch.setitem(sys.modules, "kaggle.api.kaggle_api_extended", module)
    with pytest.raises(Exception) as info:
        download_greenhouse(tmp_path / "raw", log=quiet)
    assert "offline?" in str(info.value) and "0123abcd" not in str(info.value) and "\n" not in str(info.value)


# ----------------------------------------------------------------------------- CLI
@pytest.mark.parametrize("argv", [[], ["pheno4d"], ["greenhouse"], ["greenhouse", "clean"], ["prepare-session"],
                                  ["pheno4d", "download"], ["pheno4d", "prepare"], ["greenhouse", "standin"]])
def test_every_command_has_help(argv, capsys):
    with pytest.raises(SystemExit) as info:
        cli.main(argv + ["--help"])
    assert info.value.code == 0 and "usage:" in capsys.readouterr().out


def test_cli_clean_prints_the_table(raw, tmp_path, capsys):
    code = cli.main(["greenhouse", "clean", str(raw.folder), "--landmarks", str(raw.folder / "landmarks"),
                     "--output", str(tmp_path / "ds")])
    out = capsys.readouterr().out
    assert code == 0 and "found 3 session(s)" in out and "landmarks+icp(static)" in out
    assert cli.main(["greenhouse", "clean", "--output", str(tmp_path / "x")]) == 2
