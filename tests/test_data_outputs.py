"""Outputs never overlap inputs: every data-tools command that writes refuses an output that is,
lies inside or holds one of its inputs (a file, or a folder it reads: the raw folder it scans, the
landmarks and box folders), symbolic links followed, with one line (exit status 2) naming both,
before anything is read and with nothing written.

The writing commands with local inputs are ``greenhouse clean``, ``pheno4d prepare`` and
``prepare-session``; ``pheno4d download``, ``greenhouse download`` and ``greenhouse standin`` read
no local files. The fixtures are tiny files laid out like the real datasets: the refusals come
before any scan is read, so their contents never matter (the last tests check the legitimate
neighbours still run).
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

import data_tools.greenhouse as greenhouse
import data_tools.pheno4d as pheno4d
import data_tools.sessions as sessions
from data_tools import cli
from helpers import tree_digest
from tpvp.io import write_point_cloud
from tpvp.scene.boxes import DATA_DIR as BUNDLED_CONFIG_DIR


def snapshot(folder: Path) -> tuple[dict, list[str]]:
    """Every file with its SHA-256 and every folder (empty ones too) under ``folder``."""
    return tree_digest(folder), sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_dir())


def cloud(path: Path, seed: int = 0) -> Path:
    return write_point_cloud(path, np.random.default_rng(seed).normal(0, 0.05, (500, 3)))


@pytest.fixture
def no_reading(monkeypatch):
    """Reading a scan (or listing the Pheno4D source) fails the test: refusals come first."""
    def forbidden(*args, **kwargs):
        raise AssertionError(f"read before the overlap check: {args}")

    for module, name in ((greenhouse, "read_point_cloud"), (sessions, "read_point_cloud"),
                         (pheno4d, "find_scans")):
        monkeypatch.setattr(module, name, forbidden)


def refused(args, capsys, root: Path, output, item) -> str:
    """Run ``python -m data_tools ARGS``; it must exit 2 with one line naming ``output`` and the
    input ``item`` and leave ``root`` byte for byte as it was (not even a lock file)."""
    before = snapshot(root)
    capsys.readouterr()
    status = cli.main([str(a) for a in args])
    out, err = capsys.readouterr()
    assert status == 2 and out == "" and err.count("\n") == 1, (status, out, err)
    assert err.startswith("data_tools ") and f" {output} " in err and f" {item}" in err, err
    assert "inputs are only read" in err and "choose another dataset" in err, err
    assert snapshot(root) == before
    return err


# ----------------------------------------------------------------------------- greenhouse clean
@pytest.fixture
def kaggle(tmp_path):
    """A raw greenhouse folder: captures, landmarks, a box folder, a manifest listing the captures."""
    raw = tmp_path / "greenhouse_raw"
    for k, date in enumerate(("20250915", "20250918")):
        cloud(raw / "raw" / f"room1_{date}_raw.ply", k)
    (raw / "landmarks").mkdir()
    (raw / "landmarks" / "room1_20250918.csv").write_text("source_x,source_y,source_z,target_x,target_y,target_z\n")
    (raw / "boxes").mkdir()
    shutil.copy(BUNDLED_CONFIG_DIR / "room1_bbx_config.yaml", raw / "boxes")
    (raw / "list.csv").write_text("site,date,file\nroom1,2025-09-15,raw/room1_20250915_raw.ply\n"
                                  "room1,2025-09-18,raw/room1_20250918_raw.ply\n")
    return raw


@pytest.mark.parametrize("where", ["is the raw folder", "inside the raw folder", "deep inside it",
                                   "holds the raw folder", "holds a scan"])
def test_greenhouse_clean_output_overlapping_the_raw_folder(kaggle, tmp_path, capsys, no_reading, where):
    source, output, item = {
        "is the raw folder": (kaggle, kaggle, kaggle),
        "inside the raw folder": (kaggle, kaggle / "clean", kaggle),
        "deep inside it": (kaggle, kaggle / "raw" / "clean" / "dataset", kaggle),
        "holds the raw folder": (kaggle / "raw", kaggle, kaggle / "raw"),
        "holds a scan": (kaggle / "raw", tmp_path, kaggle / "raw"),
    }[where]
    err = refused(["greenhouse", "clean", source, "--output", output, "--force"], capsys, tmp_path, output, item)
    assert ("holds the input" if "holds" in where else "is the input" if where.startswith("is")
            else "lies inside the input") in err, err


@pytest.mark.parametrize("option, folder", [("--landmarks", "landmarks"), ("--config", "boxes")])
def test_greenhouse_clean_output_inside_the_landmarks_or_box_folder(kaggle, tmp_path, capsys, no_reading,
                                                                    option, folder):
    # A dataset inside the landmarks folder would put transforms/room1_20250918.txt where the next
    # run looks for landmark files.
    source, given = tmp_path / "scans", kaggle / folder
    shutil.copytree(kaggle / "raw", source)
    output = given / "dataset"
    refused(["greenhouse", "clean", source, option, given, "--output", output], capsys, tmp_path, output, given)


@pytest.mark.parametrize("where", ["is the manifest", "holds the manifest", "holds a listed scan",
                                   "is a listed scan"])
def test_greenhouse_clean_output_overlapping_a_manifest_or_its_scans(kaggle, tmp_path, capsys, no_reading, where):
    manifest = kaggle / "list.csv"
    if where == "holds a listed scan":  # the manifest elsewhere, its scans inside the output
        manifest = tmp_path / "lists" / "list.csv"
        manifest.parent.mkdir()
        manifest.write_text(f"site,date,file\nroom1,2025-09-15,{kaggle}/raw/room1_20250915_raw.ply\n")
    output, item = {
        "is the manifest": (manifest, manifest),
        "holds the manifest": (kaggle, manifest),
        "holds a listed scan": (kaggle / "raw", kaggle / "raw" / "room1_20250915_raw.ply"),
        "is a listed scan": (kaggle / "raw" / "room1_20250918_raw.ply", kaggle / "raw" / "room1_20250918_raw.ply"),
    }[where]
    refused(["greenhouse", "clean", "--manifest", manifest, "--output", output], capsys, tmp_path, output, item)


def test_greenhouse_clean_output_reaching_the_raw_folder_through_a_symbolic_link(kaggle, tmp_path, capsys,
                                                                                no_reading):
    (tmp_path / "work").mkdir()
    (tmp_path / "work" / "data").symlink_to(kaggle)  # data/clean is kaggle/clean
    output = tmp_path / "work" / "data" / "clean"
    err = refused(["greenhouse", "clean", kaggle, "--output", output], capsys, tmp_path, output, kaggle)
    assert "symbolic links" in err and str(kaggle / "clean") in err, err
    (tmp_path / "raw_link").symlink_to(kaggle)  # the input given through a link, the output inside the target
    refused(["greenhouse", "clean", tmp_path / "raw_link", "--output", kaggle / "clean"], capsys, tmp_path,
            kaggle / "clean", tmp_path / "raw_link")


# ----------------------------------------------------------------------------- pheno4d prepare
@pytest.fixture
def pheno(tmp_path):
    """A Pheno4D folder (two days of one tomato) and its ZIP archive beside it."""
    source = tmp_path / "Pheno4D"
    for mmdd in ("0305", "0306"):
        path = source / "Tomato01" / f"T01_{mmdd}_a.txt"
        path.parent.mkdir(parents=True, exist_ok=True)
        np.savetxt(path, np.random.default_rng(0).uniform(0, 50, (50, 3)), fmt="%.3f")
    shutil.make_archive(str(tmp_path / "Pheno4D"), "zip", tmp_path, "Pheno4D")
    return source


@pytest.mark.parametrize("where", ["is the folder", "inside the folder", "holds the folder", "is the zip",
                                   "holds the zip"])
def test_pheno4d_prepare_output_overlapping_the_source(pheno, tmp_path, capsys, no_reading, where):
    archive = tmp_path / "Pheno4D.zip"
    source, output = {
        "is the folder": (pheno, pheno), "inside the folder": (pheno, pheno / "Tomato01" / "prepared"),
        "holds the folder": (pheno, tmp_path), "is the zip": (archive, archive), "holds the zip": (archive, tmp_path),
    }[where]
    refused(["pheno4d", "prepare", source, "--output", output, "--force"], capsys, tmp_path, output, source)


# ----------------------------------------------------------------------------- prepare-session
@pytest.fixture
def new_scan(tmp_path):
    """A new scan and its landmarks file, each in its own folder; nothing is prepared yet."""
    scan = cloud(tmp_path / "scans" / "room1_20251002.ply", 3)
    marks = tmp_path / "landmarks" / "room1_20251002.csv"
    marks.parent.mkdir()
    marks.write_text("source_x,source_y,source_z,target_x,target_y,target_z\n")
    return scan, marks


@pytest.mark.parametrize("where", ["is the scan", "holds the scan", "inside the scan's path", "is the landmarks",
                                   "holds the landmarks", "holds the scan via a link"])
def test_prepare_session_dataset_overlapping_its_inputs(new_scan, tmp_path, capsys, no_reading, where):
    scan, marks = new_scan
    if where == "holds the scan via a link":  # the scan given through a link into the dataset
        (tmp_path / "scans" / "Processed_3D_Model").mkdir()
        target = tmp_path / "scans" / "Processed_3D_Model" / "room1_20251002.pcd"
        shutil.move(scan, target)
        scan.symlink_to(target)
    dataset, item = {
        "is the scan": (scan, scan), "holds the scan": (tmp_path / "scans", scan),
        "inside the scan's path": (scan / "dataset", scan), "is the landmarks": (marks, marks),
        "holds the landmarks": (tmp_path / "landmarks", marks), "holds the scan via a link": (tmp_path / "scans", scan),
    }[where]
    refused(["prepare-session", "--dataset", dataset, "--site", "room1", "--date", "2025-10-02", "--scan", scan,
             "--landmarks", marks], capsys, tmp_path, dataset, item)


# ----------------------------------------------------------------------------- what is still allowed
def test_prepare_session_dataset_beside_the_scan_is_fine(tmp_path, capsys):
    """The scan's own folder is not an input (only the file is read): a dataset next to it works."""
    scan = cloud(tmp_path / "bench2_20251002.ply", 3)
    before = tree_digest(tmp_path)
    status = cli.main(["prepare-session", "--dataset", str(tmp_path / "dataset"), "--site", "bench2",
                       "--date", "2025-10-02", "--scan", str(scan)])
    assert status == 0, capsys.readouterr().err
    assert (tmp_path / "dataset" / "Processed_3D_Model" / "bench2_20251002.pcd").is_file()
    assert {k: v for k, v in tree_digest(tmp_path).items() if not k.startswith(("dataset", ".dataset"))} == before


def test_greenhouse_clean_output_beside_the_raw_folder_is_fine(kaggle, tmp_path, capsys, monkeypatch):
    """An output beside the raw folder (and beside the manifest) passes the overlap check: the run
    gets as far as reading the first scan."""
    def first_read(*args, **kwargs):
        raise AssertionError("reached reading")

    monkeypatch.setattr(greenhouse, "read_point_cloud", first_read)
    for args in (["greenhouse", "clean", kaggle], ["greenhouse", "clean", "--manifest", kaggle / "list.csv"]):
        with pytest.raises(AssertionError, match="reached reading"):
            cli.main([str(a) for a in args] + ["--output", str(tmp_path / "greenhouse")])
