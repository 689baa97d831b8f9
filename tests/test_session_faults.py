"""Sessions that hold (issue 34): two commands on one session folder (real processes), a folder
damaged by hand (one line and exit 2 from every command, listed and repaired by `session check`),
stop signals across a step. The concurrent and signal tries come from
``benchmarks/session_faults.py``, which runs every pair and delay and 50 signal moments."""

import json
import os
import shutil
import signal
import sys

import numpy as np
import pytest

from helpers import benchmark_module, tree_digest
from tpvp.errors import BusyError
from tpvp.io import read_point_cloud
from tpvp.session import Session
from tpvp.cli import main

session_faults = benchmark_module("session_faults")


@pytest.fixture(scope="module")
def bench(tmp_path_factory):
    """Capture clouds and the ``one`` / ``ready`` sessions of the benchmark."""
    return session_faults.prepare(tmp_path_factory.mktemp("bench"))


@pytest.fixture(scope="module")
def planned_once(bench):
    """A session with its warm-up captured and a plan written (every file a session can hold)."""
    folder = session_faults.copy_session(bench["ready"], bench["ready"].parent / "planned")
    Session.open(folder).plan()
    return folder


@pytest.fixture
def planned(planned_once, tmp_path):
    return session_faults.copy_session(planned_once, tmp_path / "session")


# --- two commands on one folder --------------------------------------------------------------------

@pytest.mark.parametrize("pair", session_faults.PAIRS)
def test_a_second_command_waits_for_the_first_and_both_are_recorded(bench, tmp_path, pair):
    # The first command is paused between its read and its commit; the second starts then.
    result = session_faults.concurrent_try(pair, tmp_path / "session", bench, delay=0.0, pause=True)
    assert session_faults.concurrent_ok(result) == []
    assert [run["rc"] for _, run in result["results"]] == [0, 0]
    second = result["results"][1][1]
    assert any("is being written by another run; waiting for it" in line for line in second["stderr"])


def test_a_second_command_that_cannot_wait_is_refused_with_exit_3(bench, tmp_path):
    result = session_faults.concurrent_try("add/add", tmp_path / "session", bench, delay=0.0, pause=True, wait=0)
    assert session_faults.concurrent_ok(result) == []
    (_, first), (_, second) = result["results"]
    assert first["rc"] == 0 and second["rc"] == 3
    assert second["stderr"] == [f"tpvp session add: error: session folder {tmp_path / 'session'} is being written "
                                "by another run; run this command again when that one has finished (--wait "
                                "SECONDS waits longer)"]
    assert [c["view"] for c in result["state"]["captures"]] == [17, 3, session_faults.EXTRA[0]]


def test_a_commit_on_a_state_that_changed_since_it_was_read_is_refused(bench, tmp_path):
    """Without the lock held (the library used from two places): the second commit sees the first."""
    folder = session_faults.copy_session(bench["ready"], tmp_path / "session")
    first, second = Session.open(folder), Session.open(folder)
    first.add(read_point_cloud(bench["cloud5"], units="mm"), 5, "first")
    with pytest.raises(BusyError, match="changed since this command read it .* nothing was written"):
        second.add(read_point_cloud(bench["cloud6"], units="mm"), 6, "second")
    assert [c["view"] for c in Session.open(folder).captures] == [17, 3, 5]
    assert Session.problems(folder) == []


# --- a folder damaged by hand ----------------------------------------------------------------------

def _truncate(path):
    path.write_bytes(path.read_bytes()[: len(path.read_bytes()) // 2])


def _edit_state(change):
    def edit(folder):
        state = json.loads((folder / "session.json").read_text())
        change(state)
        (folder / "session.json").write_text(json.dumps(state))
    return edit


def _edit_line(name, line, column, value):
    """Replace one value of a CSV file's line (counting from 1) and column (from 0)."""
    def edit(folder):
        lines = (folder / name).read_text().splitlines()
        values = lines[line - 1].split(",")
        values[column] = value
        lines[line - 1] = ",".join(values)
        (folder / name).write_text("\n".join(lines) + "\n")
    return edit


def _cut_lines(name, keep):
    """Cut a text file after its first ``keep`` lines (a truncation at a line's end: every line left reads)."""
    def cut(folder):
        (folder / name).write_text("\n".join((folder / name).read_text().splitlines()[:keep]) + "\n")
    return cut


def _prediction_of_another_plan(folder):
    from tpvp.pipeline.replan import Prediction

    path = folder / "plan/prediction.npz"
    prediction = Prediction.from_bytes(path.read_bytes())
    path.write_bytes(Prediction(prediction.centres, prediction.resolution, prediction.visibility, 5).to_bytes())


# kind -> (damage, the line's key text, repairable)
DAMAGES = {
    "capture file gone": (lambda f: (f / "captures/001.npy").unlink(),
                          "captures/001.npy (capture 2, view 3) is missing (deleted?)", True),
    "centroids gone": (lambda f: (f / "captures/000_centroids.npy").unlink(),
                       "captures/000_centroids.npy (capture 1, view 17) is missing", True),
    "capture truncated": (lambda f: _truncate(f / "captures/001.npy"),
                          "captures/001.npy (capture 2, view 3) is damaged (truncated?", True),
    "orphan capture file": (lambda f: shutil.copy(f / "captures/001.npy", f / "captures/007.npy"),
                            "captures/007.npy is not a file of any capture in session.json", True),
    "plan file gone": (lambda f: (f / "plan/plan.csv").unlink(), "plan/plan.csv is missing (deleted?)", True),
    "previous model gone": (lambda f: (f / "previous.npy").unlink(),
                            "previous.npy (the previous model) is missing", False),
    "previous model truncated": (lambda f: _truncate(f / "previous.npy"),
                                 "previous.npy (the previous model) is damaged", False),
    "configuration gone": (lambda f: (f / "config.yaml").unlink(),
                           "config.yaml (the session's configuration) is missing", False),
    "state gone": (lambda f: (f / "session.json").unlink(), "session.json (the session's state) is missing", False),
    "state truncated": (lambda f: _truncate(f / "session.json"), "session.json: not valid JSON", False),
    "state malformed": (lambda f: (f / "session.json").write_text("{'format': 'tpvp-session'}"),
                        "session.json: not valid JSON", False),
    "captures key missing": (_edit_state(lambda s: s.pop("captures")), "session.json: no 'captures' key", False),
    "capture record edited": (_edit_state(lambda s: s["captures"][0].update(file="../../etc/passwd")),
                              "capture 1 has no valid 'file'", False),
    "version from the future": (_edit_state(lambda s: s.update(version=2, tpvp="9.0")),
                                "a session of format version 2 (tpvp 9.0); this tpvp reads version 1: update tpvp",
                                False),
    # every other file a step reads (issue 47): the plan's, the configuration, the organ labels
    "prediction truncated": (lambda f: _truncate(f / "plan/prediction.npz"),
                             "plan/prediction.npz is damaged (truncated?", True),
    "prediction gone": (lambda f: (f / "plan/prediction.npz").unlink(), "plan/prediction.npz is missing (deleted?)",
                        True),
    "prediction of another plan": (_prediction_of_another_plan,
                                   "plan/prediction.npz is the prediction of a plan made after 5 captures", True),
    "plan.csv not a number": (_edit_line("plan/plan.csv", 5, 9, "0.12.3"),
                              "plan/plan.csv is damaged (line 5, column 'qx': '0.12.3' is not a number)", True),
    "plan.csv infinite": (_edit_line("plan/plan.csv", 4, 3, "inf"),
                          "plan/plan.csv is damaged (line 4, column 'x': inf is not a finite number)", True),
    "plan.csv cut at a line's end": (_cut_lines("plan/plan.csv", 8),
                                     "plan/plan.csv is damaged (truncated? it holds 4 planned views, session.json's "
                                     "plan 6)", True),
    "plan.json truncated": (lambda f: _truncate(f / "plan/plan.json"),
                            "plan/plan.json is damaged (truncated? not valid JSON", True),
    "plan record edited": (_edit_state(lambda s: s["plan"].update(views_so_far="2")),
                           "session.json: the plan's 'views_so_far' is not a count (edited by hand?)", True),
    "planned view out of range": (_edit_state(lambda s: s["plan"]["planned_views"].__setitem__(0, 99)),
                                  "session.json: the plan names view 99, but this session's views are 0..31", True),
    "configuration truncated": (_cut_lines("config.yaml", 60),
                                "config.yaml (the session's configuration) is damaged (truncated? it has no ", False),
    "organ labels gone": (_edit_state(lambda s: s.update(previous_organs="previous_organs.npy")),
                          "previous_organs.npy (the previous model's organ labels) is missing (deleted?)", False),
    "organ labels damaged": (lambda f: np.save(f / "previous_organs.npy", np.full(len(np.load(f / "previous.npy")), 9)),
                             "previous_organs.npy (the previous model's organ labels) holds the organ code 9", False),
    "previous model empty": (lambda f: np.save(f / "previous.npy", np.zeros((0, 3))),
                             "previous.npy (the previous model) holds no points", False),
}


def _commands(folder, bench, tmp_path):
    cloud = bench[f"cloud{session_faults.EXTRA[0]}"]
    return {"add": ["add", folder, "--cloud", cloud, "--pose", session_faults.EXTRA[0]],
            "plan": ["plan", folder], "export": ["export", folder, "--model", tmp_path / "today.ply"]}


@pytest.mark.parametrize("damage", DAMAGES)
def test_a_damaged_folder_is_one_line_and_exit_2_from_every_command(planned, bench, tmp_path, capsys, damage):
    harm, text, repairable = DAMAGES[damage]
    harm(planned)
    before = tree_digest(planned)
    for name, argv in _commands(planned, bench, tmp_path).items():
        assert main(["session", *map(str, argv)]) == 2, name
        out, err = capsys.readouterr()
        lines = err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith(f"tpvp session {name}: error: "), (name, lines)
        assert text in lines[0], (name, lines[0])
        assert ("--repair` will" in lines[0]) == repairable, lines[0]
    assert not (tmp_path / "today.ply").exists()
    assert main(["session", "check", str(planned)]) == 2
    out, err = capsys.readouterr()
    assert any(text in line for line in out.splitlines() if line.startswith("problem: ")), out
    assert "1 problem" in err
    assert tree_digest(planned) == before  # nothing was changed by any of them


def test_repair_drops_what_is_gone_removes_orphans_and_the_session_goes_on(planned, bench, tmp_path, capsys):
    (planned / "captures/001.npy").unlink()
    shutil.copy(planned / "captures/000.npy", planned / "captures/004.npy")
    (planned / "plan/plan.json").unlink()
    assert main(["session", "check", str(planned)]) == 2
    out, err = capsys.readouterr()
    assert out.count("problem: ") == 3 and "3 problems; `tpvp session check" in err and "--repair` repairs 3" in err
    assert main(["session", "check", str(planned), "--repair"]) == 0
    out = capsys.readouterr().out
    assert "repair: drop capture 2 (view 3)" in out and "repair: remove captures/004.npy" in out
    assert "repair: drop the plan (run `tpvp session plan` again)" in out
    assert "a plant session, 1 capture, no plan yet; no problem found" in out
    assert "next: capture view 3 (warm-up NBV 1 of 1)" in out
    assert sorted(p.name for p in (planned / "captures").iterdir()) == ["000.npy", "000_centroids.npy"]
    assert not (planned / "plan").exists()
    assert main(["session", "add", str(planned), "--cloud", str(bench["cloud3"])]) == 0
    assert Session.open(planned).captures[-1]["file"] == "captures/001.npy"
    assert Session.problems(planned) == []


def test_a_damaged_prediction_is_one_line_for_the_re_plan_and_repaired_by_planning_again(planned, bench, capsys):
    """Issue 47's case: a planned view captured, then the prediction the re-plan reads damaged."""
    assert main(["session", "add", str(planned), "--cloud", str(bench["cloud5"])]) == 0
    _truncate(planned / "plan/prediction.npz")
    capsys.readouterr()
    assert main(["session", "plan", str(planned)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "plan/prediction.npz is damaged (truncated?" in err[0], err
    assert main(["session", "check", str(planned), "--repair"]) == 0
    out = capsys.readouterr().out
    assert "repair: drop the plan (run `tpvp session plan` again)" in out and "3 captures, no plan yet" in out
    assert main(["session", "plan", str(planned)]) == 0
    assert Session.problems(planned) == []


_READS = []  # while a list is appended here, the files opened for reading under its folder


def _record_reads(event, args):
    if event != "open" or not _READS or not isinstance(args[0], (str, os.PathLike)):
        return
    mode, flags = args[1], args[2]
    writes = any(c in mode for c in "wax+") if isinstance(mode, str) else flags & (os.O_WRONLY | os.O_RDWR)
    folder, reads = _READS[-1]
    path = os.path.abspath(os.fspath(args[0]))
    if not writes and path.startswith(f"{folder}{os.sep}"):
        reads.add(os.path.relpath(path, folder))


def _reads(folder, argv) -> set:
    """The files under ``folder`` that ``tpvp session ARGV`` opens for reading (its exit status 0)."""
    reads = set()
    _READS.append((os.path.abspath(folder), reads))
    try:
        assert main(["session", *map(str, argv)]) == 0, argv
    finally:
        _READS.clear()
    return reads


def test_check_reads_every_file_a_step_reads(planned, bench, tmp_path):
    """Each file a step opens (a capture added, the re-plan it asks for, the export) is one that
    `session check` reads: damage anywhere is found before a step meets it."""
    sys.addaudithook(_record_reads)  # idle (one test of a list) once this test is done
    steps = set()
    for argv in (["add", planned, "--cloud", bench["cloud5"]], ["plan", planned],
                 ["export", planned, "--model", tmp_path / "today.ply"]):
        steps |= _reads(planned, argv)
    checked = _reads(planned, ["check", planned])
    assert {"plan/prediction.npz", "previous.npy", "config.yaml", "session.json"} <= steps
    assert steps <= checked, sorted(steps - checked)


def test_check_on_a_sound_folder(planned, capsys):
    assert main(["session", "check", str(planned)]) == 0
    out = capsys.readouterr().out
    assert "a plant session, 2 captures, a plan of 6 views; no problem found" in out


# --- stop signals across a step --------------------------------------------------------------------

@pytest.mark.slow
@pytest.mark.parametrize("kind", ["add", "plan"])
def test_a_signal_at_the_commit_and_after_it_ends_with_the_step_complete(bench, tmp_path, kind):
    folder = tmp_path / "session"
    steps = session_faults.count_steps(kind, folder, bench)
    for step in (steps - 2, steps):  # the commit's first rename; the moment after the commit
        result = session_faults.signal_try(kind, folder, bench, signal.SIGINT, step=step)
        assert session_faults.signal_ok(result) == [], result
        assert result["rc"] == 0 and result["done"]
        done = "capture 2 was recorded" if kind == "add" else "the plan was written"
        assert result["stderr"] == [f"tpvp session {kind}: SIGINT received after {done}; the step is complete"]
    result = session_faults.signal_try(kind, folder, bench, signal.SIGINT, step=1)  # before the commit
    assert session_faults.signal_ok(result) == [] and result["rc"] == 130 and result["unchanged"], result


@pytest.mark.slow
@pytest.mark.parametrize("kind", ["add", "plan"])
def test_signals_at_random_moments_of_a_step_leave_status_line_and_folder_in_agreement(bench, tmp_path, kind):
    folder = tmp_path / "session"
    duration = session_faults.timed(kind, folder, bench)
    for delay, signum in session_faults.signal_moments(3, duration, seed=3):
        result = session_faults.signal_try(kind, folder, bench, signum, delay=delay)
        assert session_faults.signal_ok(result) == [], result


def test_after_a_signal_the_interrupts_debris_is_not_printed():
    """An object the interrupt left half built may fail in its ``__del__`` (llvmlite's, while numba
    loads): once a signal arrived, such an unraisable error is not printed; before, it is."""
    from types import SimpleNamespace

    from tpvp.__main__ import _redeliver

    printed = []
    debris = SimpleNamespace(exc_value=AttributeError("_as_parameter_"))
    _redeliver([], printed.append)(debris)
    assert printed == [debris]
    _redeliver([signal.SIGTERM], printed.append)(debris)
    assert printed == [debris]


def test_an_interrupt_swallowed_in_a_finaliser_is_raised_again_outside_the_hook():
    """A KeyboardInterrupt raised inside a ``__del__`` (a C callback) reaches the hook, not the
    command: the hook raises it again, after it has returned (raised in the hook, Python would print
    it as the hook's own error and drop it)."""
    import subprocess
    import sys

    script = """
import signal, sys
from tpvp.__main__ import _interrupt, _redeliver
received = []
signal.signal(signal.SIGINT, _interrupt(received))
sys.unraisablehook = _redeliver(received, sys.unraisablehook)
class Finaliser:
    def __del__(self):
        received.append(signal.SIGINT)
        raise KeyboardInterrupt
try:
    Finaliser()
    for _ in range(10**9):
        pass
except KeyboardInterrupt:
    print("raised again")
"""
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert done.stdout.strip() == "raised again" and done.stderr == "", (done.stdout, done.stderr)
