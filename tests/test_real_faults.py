"""Faults of a real machine (issue 28): a full disk (a real small tmpfs where the test may mount one,
a file-size limit everywhere), Ctrl-C / SIGTERM at random moments of start-up, mount points and
read-only file systems as output folders. The tries come from ``benchmarks/real_faults.py``, which
runs more of them."""

import json
import os
import resource
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from helpers import benchmark_module
from tpvp.errors import InputFileError, OutputWriteError
from tpvp.io import atomic_write_text, faults
from tpvp.io.publish import RUN_MARKER, RunInterrupted, staged_folder
from tpvp.viz.recording import write_recording

ROOT = Path(__file__).resolve().parent.parent


real_faults = benchmark_module("real_faults")


@pytest.fixture
def tmpfs():
    """``mount(size, read_only=False)``: a fresh tmpfs folder; the test is skipped where none can be mounted."""
    with __import__("contextlib").ExitStack() as stack:
        def mount(size=4 << 20, read_only=False):
            try:
                return stack.enter_context(real_faults.mounted_tmpfs(size, read_only))
            except real_faults.Unavailable as exc:
                pytest.skip(str(exc))
        yield mount


# --- the recording is written like every other output ---------------------------------------------

def _record(path):
    cloud = np.random.default_rng(0).normal(size=(500, 3))
    return write_recording(path, clouds={"cloud": (cloud, (200, 0, 0))},
                           cameras={"views": (np.array([[1.0, 0, 0]]), np.zeros(3))}, paths={"path": cloud[:5]})


def test_a_write_failure_of_the_recording_is_the_tools_own_error(tmp_path):
    with faults.inject("enospc", 1), pytest.raises(InputFileError, match="cannot write .*recording.rrd: No space left"):
        _record(tmp_path / "recording.rrd")
    assert list(tmp_path.iterdir()) == []  # no half-written recording, no temporary file


def test_the_recording_is_a_complete_rrd(tmp_path):
    rerun = Path(sys.executable).with_name("rerun")
    if not rerun.exists():
        pytest.skip("no rerun command beside this Python")
    path = _record(tmp_path / "recording.rrd")
    done = subprocess.run([str(rerun), "rrd", "verify", str(path)], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and "verified without error" in done.stdout + done.stderr


# --- a full disk ---------------------------------------------------------------------------------

@pytest.mark.slow
@pytest.mark.parametrize("free", [0, 100_000, 1_000_000], ids=["tables", "figures", "recording"])
def test_a_real_full_disk_ends_with_exit_4_and_the_next_run_publishes(tmpfs, free):
    tmpfs()  # skip here, not inside the try, where this machine cannot mount
    result = real_faults.full_disk_try(free)
    full = result["full"]
    assert not full["hung"] and full["rc"] == 4, full
    assert len(full["stderr"]) == 1 and "No space left on device" in full["stderr"][0], full["stderr"]
    assert "nothing was published" in full["stderr"][0] and ".tpvp-staging" not in full["stderr"][0]
    assert not result["published_when_full"] and result["leftovers"] == []
    assert result["again"]["rc"] == 0 and result["published_after"]


def _limit_file_size(limit):
    def apply():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit then fails with EFBIG
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    return apply


@pytest.mark.slow
def test_a_file_size_limit_is_a_full_disk_too(tmp_path):
    """Where no tmpfs can be mounted: a limit of 100 kB per file fails the first figure's write."""
    out = tmp_path / "out"
    full = real_faults.run(real_faults.tpvp("demo", "--output", str(out)), preexec_fn=_limit_file_size(100_000))
    assert not full["hung"] and full["rc"] == 4 and len(full["stderr"]) == 1, full
    assert "File too large" in full["stderr"][0] and "nothing was published" in full["stderr"][0]
    assert not out.exists() and real_faults.leftovers(out) == []
    again = real_faults.run(real_faults.tpvp("demo", "--output", str(out)))
    assert again["rc"] == 0 and (out / "recording.rrd").is_file()


# --- Ctrl-C and SIGTERM while starting -----------------------------------------------------------

@pytest.mark.parametrize("command", ["tpvp plan", "data_tools prepare-session"])
def test_a_signal_at_a_random_moment_of_start_up_is_exit_130_and_one_line(tmp_path, command):
    # From 0.1 s: on a loaded machine Python's own start (before any tpvp code) can outlast 25 ms.
    for run, (delay, signum) in enumerate(real_faults.start_up_moments(6, seed=7, start=0.1)):
        result = real_faults.start_up_try(real_faults.start_up_commands(tmp_path, run)[command], delay, signum)
        assert real_faults.start_up_ok(result), result
        assert "interrupted" in result["stderr"][0]


# --- mount points and read-only file systems -------------------------------------------------------

def _write_run(destination, texts):
    with staged_folder(destination) as stage:
        for name, text in texts.items():
            atomic_write_text(stage.path(name), text)


def _contents(folder: Path) -> dict:
    """The run's files (not the marker, the lock or a staging folder)."""
    files = {p.relative_to(folder).as_posix(): p for p in sorted(folder.rglob("*")) if p.is_file()}
    return {name: p.read_text() for name, p in files.items() if not name.startswith(".tpvp-")}


def test_a_mount_point_is_published_in_place(tmpfs):
    mount = tmpfs()
    _write_run(mount, {"a.txt": "old", "sub/b.txt": "old"})
    _write_run(mount, {"a.txt": "new", "c.txt": "new"})
    assert _contents(mount) == {"a.txt": "new", "c.txt": "new"}
    assert sorted(json.loads((mount / RUN_MARKER).read_text())["files"]) == ["a.txt", "c.txt"]
    assert sorted(p.name for p in mount.iterdir()) == [".tpvp-lock", RUN_MARKER, "a.txt", "c.txt"]
    (mount / "mine.txt").write_text("not a run's")
    with pytest.raises(Exception, match="holds files that no tpvp run recorded"):
        _write_run(mount, {"a.txt": "newer"})
    assert (mount / "mine.txt").read_text() == "not a run's"


@pytest.mark.parametrize("kind", ["interrupt", "enospc"])
def test_a_fault_at_any_step_leaves_a_mount_point_wholly_old_or_wholly_new(tmpfs, kind):
    mount = tmpfs()
    old, new = {"a.txt": "old", "b.txt": "old"}, {"a.txt": "new", "c.txt": "new", "d/e.txt": "new"}
    with faults.inject(None):
        _write_run(mount, new)
        steps = faults.steps()
    for step in range(1, steps + 1):
        _write_run(mount, old)
        try:
            with faults.inject(kind, step):
                _write_run(mount, new)
            published = True
        except RunInterrupted as exc:
            published = exc.published
        except OutputWriteError as exc:
            published = False
            assert "nothing was published" in str(exc) and ".tpvp-" not in str(exc)
        assert _contents(mount) == (new if published else old), (kind, step)
        assert sorted(p.name for p in mount.glob(".tpvp-*")) == [".tpvp-lock", RUN_MARKER], (kind, step)


@pytest.mark.parametrize("cut", ["moving the old entries out", "moving the new entries in"])
def test_a_commit_cut_inside_a_mount_point_is_repaired_by_the_next_run(tmpfs, cut):
    mount = tmpfs()
    _write_run(mount, {"a.txt": "old", "b.txt": "old"})
    old, staging = mount / ".tpvp-old-999", mount / ".tpvp-staging-999"
    old.mkdir()
    staging.mkdir()
    for name in ("a.txt", "b.txt"):
        (staging / name).write_text("new")
    (staging / RUN_MARKER).write_text(json.dumps({"files": ["a.txt", "b.txt"]}))
    if cut == "moving the old entries out":
        (mount / ".tpvp-commit-999").write_text("old\n")
        os.rename(mount / "a.txt", old / "a.txt")
        expected = {"a.txt": "old", "b.txt": "old"}
    else:
        (mount / ".tpvp-commit-999").write_text("new\n")
        for name in ("a.txt", "b.txt", RUN_MARKER):
            os.rename(mount / name, old / name)
        os.rename(staging / "a.txt", mount / "a.txt")
        expected = {"a.txt": "new", "b.txt": "new"}
    with staged_folder(mount, keep_existing=True) as stage:
        assert _contents(mount) == expected  # repaired before the run starts
        atomic_write_text(stage.path("z.txt"), "added")
    assert _contents(mount) == {**expected, "z.txt": "added"}
    assert sorted(p.name for p in mount.glob(".tpvp-*")) == [".tpvp-lock", RUN_MARKER]


def test_a_read_only_file_system_is_refused_before_any_work(tmpfs, tmp_path):
    mount = tmpfs(read_only=True)
    for destination in (mount, mount / "sub"):
        with pytest.raises(OutputWriteError, match="read-only file system; choose a folder on a writable disk"):
            with staged_folder(destination):
                pytest.fail("the run started")
    done = real_faults.run(real_faults.tpvp("demo", "--output", str(mount / "out")))
    assert done["rc"] == 4 and done["stderr"][-1].endswith("choose a folder on a writable disk"), done
    assert "views (warm-up included)" not in done["stdout"]  # refused before planning
