"""data_tools.pheno4d: finding scans in the real layout (folder and ZIP), preparing the bundled
samples and a small generated archive, one-line errors naming the file, and the download."""

import functools
import http.server
import re
import threading
import zipfile
from datetime import date

import numpy as np
import pandas as pd
import pytest

from data_tools.errors import ConfigError, DatasetError, InputFileError, PointCloudError
from data_tools.pheno4d import (
    MANIFEST_COLUMNS,
    PAIR_COLUMNS,
    Pheno4DConfig,
    ScanRecord,
    bundled_scans,
    download_pheno4d,
    find_scans,
    prepare_pheno4d,
)
from tpvp.io import read_point_cloud
from tpvp.scene.normalise import normalise_plant
from tpvp.scene.samples import DATA, load_sample
from tpvp.scene.voxels import voxel_centres

# --------------------------------------------------------------------------------------------
# a small archive in the real Pheno4D layout


def _plant_text(seed: int, n: int, label_columns: int) -> bytes:
    """A fake plant scan in millimetres: ``x y z`` plus ``label_columns`` integer columns."""
    rng = np.random.default_rng(seed)
    xyz = rng.uniform([0, 0, 0], [40, 30, 80], size=(n, 3)) + [100.0, -50.0, 20.0]
    cols = [np.round(xyz, 3)] + [rng.integers(0, 4, size=(n, 1)) for _ in range(label_columns)]
    rows = np.hstack(cols)
    fmt = ["%.3f"] * 3 + ["%d"] * label_columns
    return "".join(" ".join(f % v for f, v in zip(fmt, row)) + "\n" for row in rows).encode()


# name inside the archive -> (content, points)
RAW = {
    # Maize copies can carry a second label column (docs/data.md#pheno4d-text-files).
    "Pheno4D/Maize01/M01_0313_a.txt": (_plant_text(1, 300, 2), 300),
    "Pheno4D/Maize01/M01_0314_a.txt": (_plant_text(2, 320, 1), 320),
    "Pheno4D/Maize01/M01_0314.txt": (_plant_text(3, 350, 0), 350),  # unannotated twin: skipped
    "Pheno4D/Maize01/M01_0316.txt": (_plant_text(4, 330, 0), 330),
    "Pheno4D/Tomato01/T01_0305_a.txt": (_plant_text(5, 250, 1), 250),
    "Pheno4D/Tomato01/T01_0306_a.txt": (_plant_text(6, 260, 1), 260),
    "Pheno4D/README.txt": (b"Pheno4D dataset\n", None),
    "Pheno4D/Maize01/M1_0315.txt": (_plant_text(7, 10, 0), None),  # badly named
    "Pheno4D/Tomato01/T01_1345_a.txt": (_plant_text(8, 10, 1), None),  # no such date
}
EXPECTED_SKIPPED = [
    ("Pheno4D/Maize01/M01_0314.txt", "annotated twin Pheno4D/Maize01/M01_0314_a.txt used instead"),
    ("Pheno4D/Maize01/M1_0315.txt", "not a Pheno4D scan name (expected e.g. Maize01/M01_0313_a.txt)"),
    ("Pheno4D/README.txt", "not a Pheno4D scan name (expected e.g. Maize01/M01_0313_a.txt)"),
    ("Pheno4D/Tomato01/T01_1345_a.txt", "1345 is not a valid MMDD date in 2020"),
]
# (plant, MMDD, raw name, labelled) of the scans that must be prepared, in manifest order
EXPECTED_SCANS = [
    ("Maize01", "0313", "Pheno4D/Maize01/M01_0313_a.txt", True),
    ("Maize01", "0314", "Pheno4D/Maize01/M01_0314_a.txt", True),
    ("Maize01", "0316", "Pheno4D/Maize01/M01_0316.txt", False),
    ("Tomato01", "0305", "Pheno4D/Tomato01/T01_0305_a.txt", True),
    ("Tomato01", "0306", "Pheno4D/Tomato01/T01_0306_a.txt", True),
]


def _write_folder(root, files):
    for name, (content, _) in files.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(content)
    return root


def _write_zip(path, files, compression=zipfile.ZIP_DEFLATED):
    # A fixed member date: the same files give the same bytes (tests compare an archive with a
    # rewritten copy to prove it was not modified; writestr(name) would stamp the current time).
    with zipfile.ZipFile(path, "w", compression=compression) as zf:
        for name, (content, _) in files.items():
            zf.writestr(zipfile.ZipInfo(name, date_time=(2020, 3, 6, 0, 0, 0)), content, compress_type=compression)
    return path


@pytest.fixture(scope="module")
def raw(tmp_path_factory):
    base = tmp_path_factory.mktemp("raw")
    return {"folder": _write_folder(base / "extracted", RAW),
            "zip": _write_zip(base / "Pheno4D.zip", RAW)}


# --------------------------------------------------------------------------------------------
# find_scans


@pytest.mark.parametrize("kind", ["folder", "zip"])
def test_find_scans_real_layout(raw, kind):
    records, skipped = find_scans(raw[kind])
    assert skipped == EXPECTED_SKIPPED
    sep = "/" if kind == "folder" else "::"
    assert records == [
        ScanRecord(plant, plant.rstrip("0123456789").lower(), date(2020, int(mmdd[:2]), int(mmdd[2:])),
                   f"{raw[kind]}{sep}{name}", annotated)
        for plant, mmdd, name, annotated in EXPECTED_SCANS
    ]


def test_find_scans_errors_name_the_source(tmp_path):
    with pytest.raises(InputFileError, match=r"absent: not found; expected .*Maize01/M01_0313_a\.txt"):
        find_scans(tmp_path / "absent")
    (tmp_path / "empty" / "Maize01").mkdir(parents=True)
    (tmp_path / "empty" / "Maize01" / "notes.txt").write_text("x")
    with pytest.raises(InputFileError, match=r"empty: no Pheno4D scan found \(1 file\(s\) looked "
                                             r"at\); expected plant folders Maize01"):
        find_scans(tmp_path / "empty")
    not_zip = tmp_path / "Pheno4D.zip"
    not_zip.write_bytes(b"<html>proxy login page</html>")
    with pytest.raises(InputFileError, match=r"Pheno4D\.zip: not a folder nor a readable ZIP"):
        find_scans(not_zip)


def test_bundled_scans():
    records = bundled_scans()
    assert [(r.plant, r.species, r.date, r.annotated) for r in records] == [
        ("MaizeSample", "maize", date(2020, 3, 13), False),
        ("TomatoSample", "tomato", date(2020, 3, 5), False),
        ("TomatoSample", "tomato", date(2020, 3, 6), False),
    ]
    assert all(read_point_cloud(r.source, units="mm").shape[1] == 3 for r in records[1:])


def test_config_is_checked():
    assert Pheno4DConfig().gt_tag == "2mm" and Pheno4DConfig(gt_resolution=0.0015).gt_tag == "1p5mm"
    with pytest.raises(ConfigError, match="gt_resolution must be a positive number"):
        Pheno4DConfig(gt_resolution=0)
    with pytest.raises(ConfigError, match="centre must be 'bbox' or 'centroid'"):
        Pheno4DConfig(centre="middle")


# --------------------------------------------------------------------------------------------
# prepare_pheno4d


def test_prepare_bundled_samples(tmp_path):
    out = tmp_path / "pheno4d"
    manifest = prepare_pheno4d(None, out, progress=False)
    assert tuple(manifest.columns) == MANIFEST_COLUMNS
    assert list(manifest.plant) == ["MaizeSample", "TomatoSample", "TomatoSample"]
    assert list(manifest.date) == ["2020-03-13", "2020-03-05", "2020-03-06"]
    assert manifest.attrs["skipped"] == []
    assert manifest.labelled.dtype == bool and not manifest.labelled.any()
    # The CSV (table of record) and its Parquet copy hold the same table.
    on_disk = pd.read_csv(out / "manifest.csv")
    pd.testing.assert_frame_equal(on_disk, manifest, check_dtype=False)
    pd.testing.assert_frame_equal(pd.read_parquet(out / "manifest.parquet"), manifest)

    for row, name in zip(manifest.itertuples(), ["maize_0313", "tomato_0305", "tomato_0306"]):
        points = load_sample(name)
        scene = normalise_plant(points, largest_side=0.24)
        gt = voxel_centres(scene.points, 0.002)
        assert row.points == len(points)
        extent = np.array([row.extent_x, row.extent_y, row.extent_z])
        np.testing.assert_allclose(extent, np.ptp(points, axis=0))
        # The bundled tomato is a seedling: its largest side is 0.048 m.
        assert np.all((extent > 0.01) & (extent < 1.0))
        assert row.scale * extent.max() == pytest.approx(0.24)
        assert row.gt_voxels == len(gt)
        assert row.source == f"tpvp/data/pheno4d/{name}" + (".ply.gz" if "maize" in name else ".xyz.gz")
        # Files round-trip in metres, bit for bit (float64 PLY).
        np.testing.assert_array_equal(read_point_cloud(out / row.file, units="m"), points)
        np.testing.assert_array_equal(read_point_cloud(out / row.normalised_file, units="m"),
                                      scene.points)
        np.testing.assert_array_equal(read_point_cloud(out / row.gt_file, units="m"), gt)
        assert row.gt_file.endswith("_gt2mm.ply")

    pairs = pd.read_csv(out / "pairs.csv")
    assert tuple(pairs.columns) == PAIR_COLUMNS
    assert pairs.to_dict("records") == [{
        "plant": "TomatoSample", "species": "tomato", "previous_date": "2020-03-05",
        "current_date": "2020-03-06", "days_apart": 1,
        "previous_file": "TomatoSample/TomatoSample_0305.ply",
        "current_file": "TomatoSample/TomatoSample_0306.ply"}]
    assert "MIT" in (out / "NOTICE.md").read_text()
    assert (out / "LICENSE").read_bytes() == (DATA / "LICENSE").read_bytes()

    # Prepared already: a second run needs --force.
    with pytest.raises(DatasetError, match=r"manifest\.csv exists.*pass --force"):
        prepare_pheno4d(None, out, progress=False)


def _prepare(source, out, **kwargs):
    # The maize 0313 file has a second label column: the reader says it ignored it, naming the
    # raw file (for a ZIP: the member, not the temporary copy that was read).
    sep = "::" if source.is_file() else "/"
    with pytest.warns(UserWarning) as caught:
        manifest = prepare_pheno4d(source, out, progress=False, **kwargs)
    assert [str(w.message) for w in caught] == [
        f"{source}{sep}Pheno4D/Maize01/M01_0313_a.txt: 5 columns per line; read x y z from "
        f"columns 1, 2, 3, labels from column 4; ignored column(s) 5"]
    return manifest


def test_prepare_generated_archive_folder_and_zip_agree(raw, tmp_path):
    from_folder = _prepare(raw["folder"], tmp_path / "a")
    from_zip = _prepare(raw["zip"], tmp_path / "b")
    assert from_folder.attrs["skipped"] == from_zip.attrs["skipped"] == EXPECTED_SKIPPED
    assert list(from_zip.source) == [f"{raw['zip']}::{name}" for *_, name, _ in EXPECTED_SCANS]
    pd.testing.assert_frame_equal(from_folder.drop(columns="source"),
                                  from_zip.drop(columns="source"))
    # Files written from either source are identical (deterministic).
    assert (tmp_path / "b" / "pairs.csv").read_bytes() == (tmp_path / "a" / "pairs.csv").read_bytes()
    for row in from_folder.itertuples():
        for path in (row.file, row.normalised_file, row.gt_file):
            assert (tmp_path / "b" / path).read_bytes() == (tmp_path / "a" / path).read_bytes()

    m = from_zip
    assert [(p, d) for p, d in zip(m.plant, m.date)] == [
        (plant, f"2020-{mmdd[:2]}-{mmdd[2:]}") for plant, mmdd, *_ in EXPECTED_SCANS]
    assert list(m.points) == [RAW[name][1] for *_, name, _ in EXPECTED_SCANS]  # the _a twin won
    assert list(m.labelled) == [labelled for *_, labelled in EXPECTED_SCANS]
    assert list(m.species) == ["maize"] * 3 + ["tomato"] * 2
    assert np.all(np.isclose(m[["extent_x", "extent_y", "extent_z"]].max(axis=1) * m.scale, 0.24))

    # Labels survive (first label column), coordinates are in metres, soil (label 0) is left out.
    points, labels = read_point_cloud(tmp_path / "b" / m.file[0], units="m", return_labels=True)
    raw_table = np.loadtxt(raw["folder"] / EXPECTED_SCANS[0][2])
    plant = raw_table[:, 3] != 0
    assert m.plant_points[0] == plant.sum() < m.points[0]
    np.testing.assert_allclose(points, raw_table[plant, :3] / 1000)
    np.testing.assert_array_equal(labels, raw_table[plant, 3].astype(int))
    _, no_labels = read_point_cloud(tmp_path / "b" / m.file[2], units="m", return_labels=True)
    assert no_labels is None

    pairs = from_zip.attrs["pairs"]
    assert list(zip(pairs.plant, pairs.previous_date, pairs.current_date, pairs.days_apart)) == [
        ("Maize01", "2020-03-13", "2020-03-14", 1),
        ("Maize01", "2020-03-14", "2020-03-16", 2),
        ("Tomato01", "2020-03-05", "2020-03-06", 1),
    ]
    notice = (tmp_path / "b" / "NOTICE.md").read_text()
    assert "ipb.uni-bonn.de/data/pheno4d" in notice and "Pheno4D/README.txt" in notice

    # force=True prepares again over an existing dataset.
    again = _prepare(raw["zip"], tmp_path / "b", force=True)
    pd.testing.assert_frame_equal(again, from_zip)


BAD_MEMBERS = {
    "truncated": (b"1.0 2.0 3.0 1\n4.0 5.0 6.0 2\n7.0 8.", r"line 3 has 2 columns, earlier lines have 4"),
    "garbage": (b"\x89PNG\r\n\x1a\n\x00\x00\x00garbage", r"contains binary data"),
    "nan": (b"1 2 3 1\nnan 5 6 1\n7 8 9 2\n", r"1 of 3 points has NaN/inf coordinates"),
    "empty": (b"", r"empty file \(0 bytes\)"),
}


@pytest.mark.parametrize("problem", sorted(BAD_MEMBERS))
def test_bad_member_is_one_line_error_naming_it(tmp_path, problem):
    content, reason = BAD_MEMBERS[problem]
    files = {"Pheno4D/Tomato01/T01_0305_a.txt": RAW["Pheno4D/Tomato01/T01_0305_a.txt"],
             "Pheno4D/Tomato01/T01_0306_a.txt": (content, None)}
    archive = _write_zip(tmp_path / "Pheno4D.zip", files)
    out = tmp_path / "out"
    with pytest.raises((InputFileError, PointCloudError)) as err:
        prepare_pheno4d(archive, out, progress=False)
    message = str(err.value)
    assert message.startswith(f"{archive}::Pheno4D/Tomato01/T01_0306_a.txt: ")
    assert re.search(reason, message) and "\n" not in message
    assert "tpvp-pheno4d-" not in message  # the temporary copy is not what the user sees
    assert not (out / "manifest.csv").exists() and not (out / "pairs.csv").exists()
    assert archive.read_bytes() == _write_zip(tmp_path / "again.zip", files).read_bytes()


def test_bad_file_in_folder_names_it(tmp_path):
    # All points coincide: normalisation fails, and the error still names the file.
    files = {"Maize02/M02_0313.txt": (b"1 2 3\n1 2 3\n1 2 3\n", None)}
    folder = _write_folder(tmp_path / "raw", files)
    with pytest.raises(PointCloudError) as err:
        prepare_pheno4d(folder, tmp_path / "out", progress=False)
    message = str(err.value)  # the wording after "zero extent" belongs to tpvp.scene.normalise
    assert message.startswith(f"{folder / 'Maize02' / 'M02_0313.txt'}: plant cloud has zero extent")
    assert "coincide" in message and "\n" not in message
    assert not (tmp_path / "out" / "manifest.csv").exists()


def test_corrupt_zip_member_crc(tmp_path):
    content = RAW["Pheno4D/Tomato01/T01_0305_a.txt"][0]
    archive = _write_zip(tmp_path / "Pheno4D.zip", {"Tomato01/T01_0305_a.txt": (content, None)},
                         compression=zipfile.ZIP_STORED)
    data = archive.read_bytes()
    archive.write_bytes(data.replace(content[:20], b"9" + content[1:20], 1))
    with pytest.raises(InputFileError, match=r"Pheno4D\.zip::Tomato01/T01_0305_a\.txt: corrupt ZIP "
                                             r"member \(Bad CRC-32"):
        prepare_pheno4d(archive, tmp_path / "out", progress=False)


# --------------------------------------------------------------------------------------------
# download_pheno4d


class _QuietHandler(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args):
        pass


def test_download_pheno4d_from_local_server(raw, tmp_path):
    served = tmp_path / "served"
    served.mkdir()
    (served / "Pheno4D.zip").write_bytes(raw["zip"].read_bytes())
    handler = functools.partial(_QuietHandler, directory=str(served))
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    url = f"http://127.0.0.1:{server.server_address[1]}/Pheno4D.zip"
    out = tmp_path / "data"
    try:
        assert download_pheno4d(out, url=url, extract=False, progress=False) == out / "Pheno4D.zip"
        folder = download_pheno4d(out, url=url, progress=False)
    finally:
        server.shutdown()
        server.server_close()
    assert folder == out / "Pheno4D"
    # The archive's top folder "Pheno4D/" is the dataset root: no Pheno4D/Pheno4D nesting.
    assert sorted(p.name for p in folder.iterdir()) == ["Maize01", "README.txt", "Tomato01"]
    assert (folder / "Maize01" / "M01_0313_a.txt").read_bytes() == RAW["Pheno4D/Maize01/M01_0313_a.txt"][0]
    assert (out / "Pheno4D.zip.sha256").is_file()
    assert [p.name for p in out.iterdir() if p.name.startswith(".")] == []  # no temp folder left
    records, skipped = find_scans(folder)
    assert len(records) == len(EXPECTED_SCANS) and len(skipped) == len(EXPECTED_SKIPPED)
    # Extracted already: returned at once, even with the server gone.
    assert download_pheno4d(out, url=url, progress=False) == folder


def test_interrupted_forced_run_leaves_the_dataset_as_it_was(raw, tmp_path, monkeypatch):
    import data_tools.pheno4d as pheno4d
    from helpers import tree_digest

    out = tmp_path / "dataset"
    _prepare(raw["folder"], out)
    before = tree_digest(out)

    def interrupted(*_args):
        raise KeyboardInterrupt  # every scan is written (staged), the manifest is not

    monkeypatch.setattr(pheno4d, "session_pairs", interrupted)
    with pytest.raises(KeyboardInterrupt):
        _prepare(raw["zip"], out, force=True)
    assert tree_digest(out) == before


def test_soil_points_are_left_out_of_the_prepared_plant(tmp_path):
    files = {"Tomato01/T01_0305_a.txt": RAW["Pheno4D/Tomato01/T01_0305_a.txt"]}
    folder = _write_folder(tmp_path / "raw", files)
    raw_table = np.loadtxt(folder / "Tomato01" / "T01_0305_a.txt")
    plant = raw_table[:, 3] != 0
    kept = prepare_pheno4d(folder, tmp_path / "soil_removed", progress=False)
    whole = prepare_pheno4d(folder, tmp_path / "soil_kept", Pheno4DConfig(soil_label=None), progress=False)
    assert kept.points[0] == whole.points[0] == len(raw_table)
    assert kept.plant_points[0] == plant.sum() < len(raw_table) and whole.plant_points[0] == len(raw_table)
    np.testing.assert_allclose([kept.extent_x[0], kept.extent_y[0], kept.extent_z[0]],
                               np.ptp(raw_table[plant, :3], axis=0) / 1000)
    normalised, labels = read_point_cloud(tmp_path / "soil_removed" / kept.normalised_file[0], units="m",
                                          return_labels=True)
    assert len(normalised) == plant.sum() and (labels != 0).all()
    expected = normalise_plant(raw_table[plant, :3] / 1000, largest_side=0.24).points
    np.testing.assert_allclose(normalised, expected)
    assert kept.gt_voxels[0] == len(voxel_centres(expected, 0.002))
    metric = read_point_cloud(tmp_path / "soil_removed" / kept.file[0], units="m")
    np.testing.assert_allclose(metric, raw_table[plant, :3] / 1000)
    assert len(read_point_cloud(tmp_path / "soil_kept" / whole.file[0], units="m")) == len(raw_table)
