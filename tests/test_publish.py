"""Whole-run atomic outputs: one lock per destination, wholly old or wholly new after any fault."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from helpers import plan_folder, tree_digest
from tpvp.cli import main
from tpvp.errors import BusyError, ConfigError, OutputWriteError
from tpvp.io import atomic_write_text, faults
from tpvp.io.publish import RUN_MARKER, RunInterrupted, _lock, hold_folder, staged_file, staged_folder

ROOT = Path(__file__).resolve().parent.parent


def _write_run(destination, texts, **options):
    with staged_folder(destination, **options) as stage:
        for name, text in texts.items():
            atomic_write_text(stage.folder / name, text)
    return stage


def folder_digest(folder: Path) -> dict:
    """Every file's SHA-256, the run marker as its list of files (it also holds a timestamp)."""
    digest = tree_digest(folder)
    if RUN_MARKER in digest:
        digest[RUN_MARKER] = json.loads((folder / RUN_MARKER).read_text())["files"]
    return digest


def _leftovers(folder: Path):
    return sorted(p.name for p in folder.parent.iterdir()
                  if p.name.startswith(f".{folder.name}.tpvp-") and not p.name.endswith("-lock"))


def test_a_run_replaces_the_previous_run_as_a_whole(tmp_path):
    out = tmp_path / "out"
    _write_run(out, {"a.txt": "1", "b.txt": "1", "sub/c.txt": "1"})
    assert json.loads((out / RUN_MARKER).read_text())["files"] == ["a.txt", "b.txt", "sub/c.txt"]
    _write_run(out, {"a.txt": "2", "d.txt": "2"})
    # nothing of the first run is left beside the second one
    assert sorted(p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file()) == \
        sorted(["a.txt", "d.txt", RUN_MARKER])
    assert (out / "a.txt").read_text() == "2" and _leftovers(out) == []


def test_files_the_command_did_not_write_are_never_deleted(tmp_path):
    user = tmp_path / "mine"
    user.mkdir()
    (user / "notes.txt").write_text("mine")
    with pytest.raises(ConfigError, match="notes.txt"):
        _write_run(user, {"a.txt": "1"})
    assert [p.name for p in user.iterdir()] == ["notes.txt"] and _leftovers(user) == []
    out = tmp_path / "out"
    _write_run(out, {"a.txt": "1"})
    (out / "mine.txt").write_text("mine")
    with pytest.raises(ConfigError, match="mine.txt"):
        _write_run(out, {"a.txt": "2"})
    assert (out / "a.txt").read_text() == "1" and (out / "mine.txt").read_text() == "mine"


def test_inputs_and_the_working_folder_are_protected(tmp_path, monkeypatch):
    scan = tmp_path / "out" / "plan.csv"
    scan.parent.mkdir()
    scan.write_text("an input that has an output's name")
    with pytest.raises(ConfigError, match="plan.csv"):
        _write_run(tmp_path / "out", {"plan.csv": "x"}, inputs=[scan])
    raw = tmp_path / "raw"
    raw.mkdir()
    with pytest.raises(ConfigError, match="inside the input"):
        _write_run(raw / "prepared", {"a.txt": "x"}, inputs=[raw])
    monkeypatch.chdir(tmp_path / "out")
    with pytest.raises(ConfigError, match="folder you are working in"):
        _write_run(Path("."), {"a.txt": "x"})
    assert scan.read_text() == "an input that has an output's name"


def test_a_second_run_on_the_same_destination_is_refused(tmp_path):
    out = tmp_path / "out"
    with staged_folder(out) as stage:
        atomic_write_text(stage.folder / "a.txt", "first")
        with pytest.raises(BusyError, match="being written by another run"):
            _write_run(out, {"a.txt": "second"})
    assert (out / "a.txt").read_text() == "first"
    _write_run(tmp_path / "other", {"a.txt": "a sibling folder is not blocked"})


@pytest.mark.parametrize("kind", ["interrupt", "enospc"])
def test_a_fault_at_any_write_step_leaves_the_folder_wholly_old_or_wholly_new(tmp_path, kind):
    out = tmp_path / "out"
    old = {"a.txt": "old", "b.txt": "old"}
    new = {"a.txt": "new", "b.txt": "new", "c.txt": "new"}
    _write_run(out, old)
    old_digest = folder_digest(out)
    with faults.inject(None):
        _write_run(tmp_path / "count", new)
        steps = faults.steps()
    assert steps == len(new) + 3  # three file writes, the two renames of the commit, the moment after it
    for step in range(1, steps + 1):
        _write_run(out, old)
        try:
            with faults.inject(kind, step):
                _write_run(out, new)
            outcome = "published"
        except RunInterrupted as exc:
            outcome = "published" if exc.published else "kept"
            assert kind == "interrupt" and ("completely" in exc.report()) == exc.published
        except OutputWriteError as exc:
            outcome = "kept"
            assert kind == "enospc" and "nothing was published" in str(exc) and ".tpvp-staging" not in str(exc)
        digest = folder_digest(out)
        assert digest == (old_digest if outcome == "kept" else folder_digest(tmp_path / "count")), (kind, step)
        assert _leftovers(out) == [], (kind, step)
        # a Ctrl-C at a commit step is held back until the commit is done
        if kind == "interrupt" and step > len(new):
            assert outcome == "published"


def test_a_crash_between_the_two_renames_is_rolled_back_by_the_next_run(tmp_path):
    out = tmp_path / "out"
    _write_run(out, {"a.txt": "old"})
    os.rename(out, tmp_path / ".out.tpvp-old-999")  # as if killed right after the first rename
    (tmp_path / ".out.tpvp-staging-999").mkdir()
    with staged_folder(out) as stage:
        assert (out / "a.txt").read_text() == "old"  # restored before the run starts
        atomic_write_text(stage.folder / "a.txt", "new")
    assert (out / "a.txt").read_text() == "new" and _leftovers(out) == []


def _render(out, extra_env=None):
    env = {**os.environ, **(extra_env or {})}
    return subprocess.Popen([sys.executable, "-m", "tpvp", "render", "--output", str(out)], cwd=ROOT, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def test_two_processes_on_one_output(tmp_path):
    out = tmp_path / "render"
    first = _render(out)
    time.sleep(2.0)  # let the first one take the lock (it holds it for the whole run)
    second = _render(out)
    results = [(p.wait(timeout=300), p.stderr.read()) for p in (first, second)]
    codes = sorted(code for code, _ in results)
    assert codes in ([0, 3], [0, 0]), results  # [0, 0] only if the first finished within 2 s
    for code, err in results:
        if code == 3:
            assert len(err.strip().splitlines()) == 1 and "being written by another run" in err
    summary = json.loads((out / "summary.json").read_text())
    listed = json.loads((out / RUN_MARKER).read_text())["files"]
    assert summary["views"] == 32 and sorted(listed) == sorted(p.name for p in out.iterdir() if p.name != RUN_MARKER)


@pytest.fixture
def ctrl_c_raises():
    """Python's own Ctrl-C handler for the test, whatever the run inherited: a run started in the
    background of a shell ignores SIGINT, and would ignore the injected interrupt too."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


@pytest.mark.parametrize("step", [1, 3, 5])
@pytest.mark.usefixtures("ctrl_c_raises")
def test_cli_interrupted_at_a_step_says_truthfully_what_happened(tmp_path, capsys, step):
    out = tmp_path / "render"
    with faults.inject("interrupt", step):
        code = main(["render", "--output", str(out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 130 and len(err) == 1
    if out.exists():  # interrupted at the commit: published completely, and said so
        assert "published completely" in err[0] and (out / "summary.json").is_file()
    else:
        assert "nothing was written" in err[0]
    assert _leftovers(out) == []


def test_cli_disk_full_is_one_line_and_exit_4(tmp_path, capsys):
    out = tmp_path / "render"
    with faults.inject("enospc", 2):
        assert main(["render", "--output", str(out)]) == 4
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "No space left on device" in err[0] and "nothing was published" in err[0]
    assert str(out) in err[0] and not out.exists() and _leftovers(out) == []


# -- one file outputs (staged_file) -------------------------------------------------------------------


def test_a_file_output_is_locked_checked_and_replaced_whole(tmp_path):
    out = tmp_path / "cloud.ply"
    with staged_file(out) as staged:
        staged.write_text("first\n")
        assert not out.exists()  # nothing at the destination before the rename
        with pytest.raises(BusyError, match="being written by another run"), staged_file(out, force=True):
            pass
    assert out.read_text() == "first\n"
    with pytest.raises(ConfigError, match="exists: choose a new one, or --force"), staged_file(out):
        pass
    with pytest.raises(RuntimeError), staged_file(out, force=True) as staged:
        staged.write_text("half")
        raise RuntimeError("the writer failed")
    assert out.read_text() == "first\n" and sorted(p.name for p in tmp_path.iterdir()) == [".cloud.ply.tpvp-lock",
                                                                                               "cloud.ply"]
    with staged_file(out, force=True) as staged:
        staged.write_text("second\n")
    assert out.read_text() == "second\n"


_INTERRUPTED_FILE = """
import json, signal, sys
signal.signal(signal.SIGINT, signal.default_int_handler)  # a test worker may pass SIGINT on ignored
from pathlib import Path
from tpvp.io import atomic_write_text, faults
from tpvp.io.publish import RunInterrupted, staged_file

out, report = Path(sys.argv[1]), []
for step in (1, 2, 3):
    out.write_text("old\\n")
    try:
        with faults.inject("interrupt", step), staged_file(out, force=True) as staged:
            atomic_write_text(staged, "new\\n")
        report.append([step, "no interrupt", out.read_text()])
    except RunInterrupted as exc:
        report.append([step, exc.published, out.read_text()])
print(json.dumps(report))
"""


def test_a_file_output_interrupted_is_old_or_new(tmp_path):
    # In its own process: Ctrl-C reaches a process's main thread, which a test worker may not be.
    out = tmp_path / "goals.yaml"
    run = subprocess.run([sys.executable, "-c", _INTERRUPTED_FILE, str(out)], capture_output=True, text=True,
                         cwd=tmp_path, env=dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[1])))
    assert run.returncode == 0, run.stderr
    # step 1: the writer's own write, before the rename; 2: the rename (Ctrl-C held back, delivered
    # after it); 3: just after it
    assert json.loads(run.stdout) == [[1, False, "old\n"], [2, True, "new\n"], [3, True, "new\n"]]
    assert [p.name for p in tmp_path.iterdir() if "staging" in p.name] == []


def test_a_file_output_that_is_an_input_or_inside_one_is_refused(tmp_path):
    capture = tmp_path / "capture"
    (capture / "depth").mkdir(parents=True)
    for out, inputs in [(capture / "cloud.ply", [capture]), (tmp_path / "plan.csv", [tmp_path / "plan.csv"])]:
        with pytest.raises(ConfigError, match="inputs are only read"), staged_file(out, inputs=inputs):
            pass
    assert sorted(p.name for p in capture.iterdir()) == ["depth"]


def test_a_symbolic_link_to_a_folder_takes_the_same_lock(tmp_path):
    real, alias = tmp_path / "session", tmp_path / "alias"
    real.mkdir()
    alias.symlink_to(real)
    with hold_folder(real, what="session folder"):  # another run through the alias: its own descriptor
        with pytest.raises(BusyError, match="being written by another run"):
            os.close(_lock(alias, "session folder"))
    os.close(_lock(alias, "session folder"))  # released: the alias's lock is free again


def test_an_export_onto_the_plan_it_reads_leaves_the_plan_as_it_was(tmp_path, capsys):
    run = plan_folder(tmp_path)
    before = (run / "plan.csv").read_bytes()
    assert main(["export", "moveit", str(run), "--output", str(run / "plan.csv"), "--force"]) == 2
    assert "is the input" in capsys.readouterr().err
    assert (run / "plan.csv").read_bytes() == before


def test_a_second_capture_fuse_into_one_file_is_refused_before_any_work(tmp_path, capsys):
    from data_tools import cli as data_cli

    out = tmp_path / "cloud.ply"
    with staged_file(out) as staged:  # the first run, still fusing
        assert data_cli.main(["capture", "fuse", str(tmp_path / "no-capture"), "--output", str(out)]) == 3
        staged.write_text("the first run's cloud\n")
    assert "is being written by another run" in capsys.readouterr().err
    assert out.read_text() == "the first run's cloud\n"
