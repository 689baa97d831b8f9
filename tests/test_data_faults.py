"""Nothing lost, nothing mixed: the data tools' dataset writes under concurrency, Ctrl-C and a full
disk at every write step, inputs that overlap the output, and bad site/date names.

Every dataset write goes through :func:`tpvp.io.publish.staged_folder`: a second run on the same
dataset is refused at once (exit status 3), and a fault at any write step leaves the dataset wholly
old or wholly new, with a report that says which and nothing left beside it but the lock file.
"""

from __future__ import annotations

import fcntl
import json
import os
import shutil
import signal
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from data_tools import cli
from data_tools.errors import ConfigError, DatasetError
from data_tools.greenhouse import find_sessions
from data_tools.pheno4d import prepare_pheno4d
from data_tools.sessions import prepare_session
from helpers import tree_digest
from tpvp.io import faults, write_point_cloud

ROOT = Path(__file__).resolve().parents[1]
LOCK = ".dataset.tpvp-lock"


# ----------------------------------------------------------------------------- helpers
def layout(folder: Path) -> dict | None:
    """Every file (hidden ones included) with its SHA-256, every folder (an empty one too), and the
    run marker's file list (its time stamp differs between runs); None when ``folder`` is absent."""
    folder = Path(folder)
    if not folder.exists():
        return None
    files = tree_digest(folder)
    marker = folder / ".tpvp-run.json"
    if marker.is_file():
        files[".tpvp-run.json"] = json.loads(marker.read_text())["files"]
    folders = sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if p.is_dir())
    return {"files": files, "folders": folders}


def beside(folder: Path) -> list[str]:
    """What lies beside ``folder`` apart from itself and its lock file (staging or old copies)."""
    return sorted(p.name for p in folder.parent.iterdir() if p.name not in (folder.name, f".{folder.name}.tpvp-lock"))


def error_lines(err: str, command: str) -> list[str]:
    return [line for line in err.splitlines() if line.startswith(f"data_tools {command}:")]


def run(args, capsys, kind=None, at=0):
    """``python -m data_tools ARGS`` in this process, with fault ``kind`` at write step ``at``;
    returns (exit status, stderr)."""
    capsys.readouterr()
    with faults.inject(kind, at):
        status = cli.main([str(a) for a in args])
    return status, capsys.readouterr().err


def count_steps(args, capsys) -> tuple[int, int]:
    with faults.inject(None):
        status = cli.main([str(a) for a in args])
        steps = faults.steps()
    capsys.readouterr()
    return status, steps


@pytest.fixture
def sigint_raises():
    """SIGINT raises KeyboardInterrupt here, as in a terminal (a test runner may have changed it)."""
    if threading.current_thread() is not threading.main_thread():
        pytest.skip("signals reach the main thread only")
    saved = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, saved)


def check_fault_case(args, folder: Path, old, new, kind: str, at: int, steps: int, command: str, capsys,
                     retry_args, retry_after_new: tuple[int, str]):
    """One injected fault: exit status, wholly old or new, a truthful report, nothing beside the
    folder; a retry then behaves as after a clean run."""
    where = f"{kind} at step {at}/{steps}"
    status, err = run(args, capsys, kind, at)
    now = layout(folder)
    assert now in (old, new), f"{where}: the dataset is neither wholly old nor wholly new"
    assert beside(folder) == [], f"{where}: left {beside(folder)}"
    lines = error_lines(err, command)
    commit = at >= steps - 2  # the commit's two renames and the moment after it: Ctrl-C is held back (or after the
    # commit), they need no space
    if kind == "interrupt":
        assert status == 130, where
        assert len(lines) == 1 and "\n" not in lines[0], (where, err)
        assert ("published completely" in lines[0]) == (now == new) == commit, (where, lines)
        assert now == new or "nothing was written" in lines[0], (where, lines)
    elif commit:
        assert status == 0 and now == new and lines == [], (where, err)
    else:
        assert status == 4 and now == old, (where, status, err)
        assert len(lines) == 1 and "nothing was published" in lines[0] and "No space left" in lines[0], (where, lines)
    status, err = run(retry_args, capsys)
    if now == old:
        assert status == 0 and layout(folder) == new, (where, err)
    else:
        assert status == retry_after_new[0] and retry_after_new[1] in err, (where, err)
        assert layout(folder) == new
    assert beside(folder) == []


# ----------------------------------------------------------------------------- prepare-session
def small_plant(path: Path, seed: int) -> Path:
    rng = np.random.default_rng(seed)
    return write_point_cloud(path, rng.normal(0, 0.05, (3000, 3)))


@pytest.fixture(scope="module")
def bench(tmp_path_factory):
    """A dataset holding site bench1's reference day, and the scan of a new site bench2: adding a
    reference day involves no ICP, so the run is fast and its output the same bytes every time."""
    base = tmp_path_factory.mktemp("bench")
    scans = [small_plant(base / f"plant{k}.ply", k) for k in (1, 2)]
    prepare_session(base / "dataset", "bench1", "2025-10-01", scans[0])
    return base / "dataset", scans[1]


def test_prepare_session_fault_at_every_write_step(bench, tmp_path, capsys, sigint_raises):
    base, scan = bench
    clean = Path(shutil.copytree(base, tmp_path / "clean" / "dataset"))
    args = ["prepare-session", "--dataset", clean, "--site", "bench2", "--date", "2025-10-02", "--scan", scan]
    status, steps = count_steps(args, capsys)
    assert status == 0 and steps >= 7  # 2 clouds, transform, manifest + Parquet, file list, 2 renames
    old, new = layout(base), layout(clean)
    assert old != new
    again = Path(shutil.copytree(base, tmp_path / "again" / "dataset"))
    assert run(args[:2] + [again] + args[3:], capsys)[0] == 0 and layout(again) == new  # deterministic
    for kind in ("interrupt", "enospc"):
        for at in range(1, steps + 1):
            folder = Path(shutil.copytree(base, tmp_path / f"{kind}{at}" / "dataset"))
            case = args[:2] + [folder] + args[3:]
            check_fault_case(case, folder, old, new, kind, at, steps, "prepare-session", capsys,
                             retry_args=case, retry_after_new=(2, "already exists"))


def test_first_session_into_a_new_dataset_fault_leaves_no_folder(bench, tmp_path, capsys, sigint_raises):
    _, scan = bench
    args = ["prepare-session", "--dataset", tmp_path / "clean" / "dataset", "--site", "bench2",
            "--date", "2025-10-02", "--scan", scan]
    status, steps = count_steps(args, capsys)
    new = layout(tmp_path / "clean" / "dataset")
    assert status == 0 and new is not None
    for at in range(1, steps + 1):
        folder = tmp_path / f"interrupt{at}" / "dataset"
        folder.parent.mkdir()
        case = args[:2] + [folder] + args[3:]
        check_fault_case(case, folder, None, new, "interrupt", at, steps, "prepare-session", capsys,
                         retry_args=case, retry_after_new=(2, "already exists"))


# ----------------------------------------------------------------------------- pheno4d prepare
def pheno4d_source(folder: Path, plants=("Tomato01",), seed=0) -> Path:
    """A tiny Pheno4D folder: per plant two annotated days of 200 points (x y z label, mm)."""
    rng = np.random.default_rng(seed)
    for plant in plants:
        for mmdd in ("0305", "0306"):
            xyz = rng.uniform([0, 0, 0], [40, 30, 80], (200, 3))
            labels = rng.integers(0, 4, (200, 1))
            path = folder / plant / f"{plant[0]}{plant[-2:]}_{mmdd}_a.txt"
            path.parent.mkdir(parents=True, exist_ok=True)
            np.savetxt(path, np.hstack([xyz, labels]), fmt=["%.3f"] * 3 + ["%d"])
    return folder


@pytest.fixture(scope="module")
def pheno(tmp_path_factory):
    base = tmp_path_factory.mktemp("pheno")
    return {"new": pheno4d_source(base / "raw_new", ("Tomato01",), 1),
            "old": pheno4d_source(base / "raw_old", ("Maize02", "Tomato01"), 2)}


@pytest.mark.parametrize("case", ["first run", "--force over another dataset"])
def test_pheno4d_prepare_fault_at_every_write_step(pheno, tmp_path, capsys, sigint_raises, case):
    args = ["pheno4d", "prepare", pheno["new"], "--output"]
    force = ["--force"] if case != "first run" else []
    old_dataset = None
    if force:  # an existing dataset with a plant the new source lacks: it must not survive mixed in
        old_dataset = tmp_path / "old" / "dataset"
        prepare_pheno4d(pheno["old"], old_dataset, progress=False)
    clean = tmp_path / "clean" / "dataset"
    if old_dataset:
        shutil.copytree(old_dataset, clean)
    status, steps = count_steps(args + [clean] + force, capsys)
    assert status == 0 and steps >= 10  # 2 scans x 3 clouds, NOTICE, pairs + manifest (+ Parquet), 2 renames
    old, new = layout(old_dataset) if old_dataset else None, layout(clean)
    assert not any(name.startswith("Maize02") for name in new["files"])
    for kind in ("interrupt", "enospc"):
        for at in range(1, steps + 1):
            folder = tmp_path / f"{kind}{at}" / "dataset"
            if old_dataset:
                shutil.copytree(old_dataset, folder)
            else:
                folder.parent.mkdir()
            check_fault_case(args + [folder] + force, folder, old, new, kind, at, steps, "pheno4d prepare",
                             capsys, retry_args=args + [folder] + force,
                             retry_after_new=(0, "") if force else (2, "pass --force"))


# ----------------------------------------------------------------------------- concurrency
def start(args) -> subprocess.Popen:
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    env.pop("TPVP_FAULT", None)
    return subprocess.Popen([sys.executable, "-m", "data_tools", *map(str, args)], cwd=ROOT, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def finish(process) -> tuple[int, str]:
    _, err = process.communicate(timeout=120)
    return process.returncode, err


def assert_manifest_matches_files(dataset: Path) -> pd.DataFrame:
    """Every session of the manifest has its files, and every model and transform is in it."""
    table = pd.read_csv(dataset / "manifest.csv")
    listed = set(table["file"]) | set(table["transform_file"])
    on_disk = {p.relative_to(dataset).as_posix() for folder in ("Processed_3D_Model", "transforms")
               for p in (dataset / folder).iterdir()}
    assert listed == on_disk, f"orphaned: {on_disk - listed}, missing: {listed - on_disk}"
    return table


def test_two_prepare_session_runs_on_one_dataset(raw_standin, tmp_path):
    dataset = tmp_path / "dataset"
    prepare_session(dataset, "room1", "2025-09-15", raw_standin.scans["20250915"])
    runs = {date: start(["prepare-session", "--dataset", dataset, "--site", "room1", "--date", date,
                         "--scan", raw_standin.scans[date.replace("-", "")],
                         "--landmarks", raw_standin.landmarks[date.replace("-", "")]])
            for date in ("2025-09-18", "2025-09-22")}
    results = {date: finish(process) for date, process in runs.items()}
    table = assert_manifest_matches_files(dataset)
    statuses = sorted(status for status, _ in results.values())
    if statuses == [0, 0]:  # one finished before the other started: both sessions are kept
        assert list(table["date"]) == ["2025-09-15", "2025-09-18", "2025-09-22"]
    else:
        assert statuses == [0, 3], results
        won = next(date for date, (status, _) in results.items() if status == 0)
        _, err = next(result for result in results.values() if result[0] == 3)
        assert err.count("\n") == 1 and str(dataset) in err and "another run" in err, err
        assert list(table["date"]) == ["2025-09-15", won]
    assert beside(dataset) == []


def test_two_pheno4d_prepare_runs_into_one_output(tmp_path):
    out = tmp_path / "dataset"
    runs = [start(["pheno4d", "prepare", "--output", out]) for _ in range(2)]  # the bundled samples
    results = [finish(process) for process in runs]
    statuses = sorted(status for status, _ in results)
    assert statuses in ([0, 2], [0, 3]), results  # never both: the --force check is under the lock
    _, err = next(result for result in results if result[0] != 0)
    lines = error_lines(err, "pheno4d prepare")
    assert len(lines) == 1 and str(out) in lines[0], err
    assert ("another run" if statuses == [0, 3] else "pass --force") in lines[0]
    table = pd.read_csv(out / "manifest.csv")
    files = set(table["file"]) | set(table["normalised_file"]) | set(table["gt_file"])
    plants = {p.relative_to(out).as_posix() for p in out.glob("*/*")}
    assert files == plants and beside(out) == []


def test_a_held_lock_refuses_at_once_with_one_line(bench, tmp_path, capsys):
    base, scan = bench
    dataset = Path(shutil.copytree(base, tmp_path / "dataset"))
    before = layout(dataset)
    fd = os.open(tmp_path / LOCK, os.O_RDWR | os.O_CREAT)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        for args in (["prepare-session", "--dataset", dataset, "--site", "bench2", "--date", "2025-10-02",
                      "--scan", scan],
                     ["pheno4d", "prepare", "--output", dataset, "--force"]):
            status, err = run(args, capsys)
            assert status == 3 and err.count("\n") == 1 and str(dataset) in err and "another run" in err, err
    finally:
        os.close(fd)
    assert layout(dataset) == before and beside(dataset) == []


# ----------------------------------------------------------------------------- inputs
@pytest.mark.parametrize("where", ["output is the source", "output inside the source", "source inside the output"])
def test_pheno4d_output_overlapping_the_source_is_refused(tmp_path, capsys, where):
    if where == "source inside the output":
        output = tmp_path / "out"
        source = pheno4d_source(output / "raw")
    else:
        source = pheno4d_source(tmp_path / "raw")
        output = source if where == "output is the source" else source / "prepared"
    before = layout(tmp_path)
    status, err = run(["pheno4d", "prepare", source, "--output", output, "--force"], capsys)
    lines = error_lines(err, "pheno4d prepare")
    assert status == 2 and len(lines) == 1 and "input" in lines[0] and str(output) in lines[0], err
    assert layout(tmp_path) == before  # not one file written, not even a lock


def test_prepare_session_scan_inside_the_dataset_is_refused(bench, tmp_path, capsys):
    base, scan = bench
    dataset = Path(shutil.copytree(base, tmp_path / "dataset"))
    inside = Path(shutil.copy(scan, dataset / "new_scan.ply"))
    before = layout(dataset)
    status, err = run(["prepare-session", "--dataset", dataset, "--site", "bench2", "--date", "2025-10-02",
                       "--scan", inside], capsys)
    assert status == 2 and err.count("\n") == 1 and "input" in err and str(inside) in err, err
    assert layout(dataset) == before


# ----------------------------------------------------------------------------- names
@pytest.mark.parametrize("option, value", [
    ("--site", "../evil"), ("--site", ""), ("--site", "a/b"), ("--site", "room 1"), ("--site", "-x"),
    ("--site", "röom"), ("--site", "bench\n2"), ("--date", "2025-02-30"), ("--date", "tomorrow"),
    ("--date", "2025/10/02"), ("--date", ""),
])
def test_bad_site_or_date_is_one_line_naming_the_option(bench, tmp_path, capsys, option, value):
    base, scan = bench
    dataset = Path(shutil.copytree(base, tmp_path / "dataset"))
    before = layout(tmp_path)
    values = {"--site": "bench2", "--date": "2025-10-02", option: value}
    status, err = run(["prepare-session", "--dataset", dataset, f"--site={values['--site']}",
                       f"--date={values['--date']}", "--scan", scan], capsys)
    assert status == 2 and err.count("\n") == 1 and option in err, err
    assert layout(tmp_path) == before  # no lock, no folder: refused before anything


def test_bad_site_names_in_the_library_and_in_manifests(bench, tmp_path):
    _, scan = bench
    with pytest.raises(ConfigError, match=r"site must be 1-64 letters.*'\.\./x'"):
        prepare_session(tmp_path / "ds", "../x", "2025-10-02", scan)
    assert not (tmp_path / "ds").exists()
    manifest = tmp_path / "sessions.csv"
    manifest.write_text(f"site,date,file\n../room1,2025-09-15,{scan}\n")
    with pytest.raises(DatasetError, match=r"sessions\.csv, row 2: site must be"):
        find_sessions(None, manifest=manifest)


# ----------------------------------------------------------------------------- the list of written files
def test_files_added_by_prepare_session_may_be_replaced_by_a_rebuild(bench, pheno, tmp_path, capsys):
    """prepare-session lists its files in the dataset's .tpvp-run.json, so a --force rebuild (a whole
    new dataset) may replace them; a file nobody listed (the user's) makes the rebuild refuse."""
    base, scan = bench
    dataset = Path(shutil.copytree(base, tmp_path / "dataset"))
    assert run(["prepare-session", "--dataset", dataset, "--site", "bench2", "--date", "2025-10-02",
                "--scan", scan], capsys)[0] == 0
    listed = json.loads((dataset / ".tpvp-run.json").read_text())["files"]
    assert sorted(listed) == sorted(f for f in tree_digest(dataset) if f != ".tpvp-run.json")
    (dataset / "my_notes.txt").write_text("mine\n")
    before = layout(dataset)
    status, err = run(["pheno4d", "prepare", pheno["new"], "--output", dataset, "--force"], capsys)
    assert status == 2 and "my_notes.txt" in err and layout(dataset) == before, err
    (dataset / "my_notes.txt").unlink()
    assert run(["pheno4d", "prepare", pheno["new"], "--output", dataset, "--force"], capsys)[0] == 0
    assert not (dataset / "Processed_3D_Model").exists() and (dataset / "Tomato01").is_dir()
