"""Stopping parallel work: Ctrl-C ends the worker processes within seconds, through the command line too."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest


ROOT = Path(__file__).resolve().parent.parent
STOPPED_WITHIN_S = 10  # a task of a season's case runs for minutes: this is the pool's stop, not the task


def _descendants(pid: int, depth: int = 1) -> set[int]:
    """The process ids ``depth`` or more levels below ``pid`` (from /proc): with ``depth=2`` a
    pool's workers, forked by the forkserver below ``pid``, without the forkserver itself."""
    children: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                parent = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            except (OSError, IndexError, ValueError):
                continue
            children.setdefault(parent, []).append(int(entry.name))
    found, todo = set(), [(pid, 0)]
    while todo:
        parent, level = todo.pop()
        for child in children.get(parent, []):
            if level + 1 >= depth:
                found.add(child)
            todo.append((child, level + 1))
    return found


def _alive(pids) -> set[int]:
    alive = set()
    for pid in pids:
        try:
            state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            continue
        if state != "Z":
            alive.add(pid)
    return alive


_POOL = """
import os, signal, sys, threading, time
from tpvp.parallel import run_cases

signal.signal(signal.SIGINT, signal.default_int_handler)  # a test worker may pass SIGINT on ignored

if __name__ == "__main__":
    threading.Timer(2.0, os.kill, (os.getpid(), signal.SIGINT)).start()  # to the process, as Ctrl-C
    start = time.monotonic()
    try:
        run_cases(time.sleep, [120, 120, 120], (), 1, workers=2, progress=False)  # each would sleep 2 min
    except KeyboardInterrupt:
        print(time.monotonic() - start)
"""


def test_an_interrupt_stops_running_workers_at_once(tmp_path):
    # In its own process: Ctrl-C reaches a process's main thread, which a test worker may not be.
    script = tmp_path / "pool.py"
    script.write_text(_POOL)
    run = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=60,
                         env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert run.returncode == 0 and run.stdout.strip(), run.stderr
    assert float(run.stdout) < STOPPED_WITHIN_S
    assert run.stderr == ""  # no traceback from a worker, no leaked semaphore reported


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace")
    except OSError:
        return ""


def test_ctrl_c_during_a_season_ends_the_command_and_its_workers_within_seconds(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(ROOT), TPVP_EXPERIMENT_CACHE=str(tmp_path / "cache"))
    command = [sys.executable, "-m", "tpvp", "experiments", "season", "--quick", "--workers", "2",
               "--output", str(tmp_path / "season"), "--cache", str(tmp_path / "cache")]
    process = subprocess.Popen(command, cwd=tmp_path, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                               text=True, start_new_session=True)
    try:
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and process.poll() is None:  # the forkserver and both workers
            if len(_alive(_descendants(process.pid))) >= 3:
                break
            time.sleep(0.2)
        assert process.poll() is None, process.communicate()
        time.sleep(3)  # the workers are computing their first cases
        below = _descendants(process.pid)
        assert len(_alive(_descendants(process.pid, depth=2))) >= 2  # the two workers
        start = time.monotonic()
        os.killpg(process.pid, signal.SIGINT)  # as a terminal's Ctrl-C: to every process of the group
        _, err = process.communicate(timeout=60)
        took = time.monotonic() - start
    finally:
        if process.poll() is None:
            process.kill()
    assert process.returncode == 130, err
    assert took < STOPPED_WITHIN_S, f"{took:.1f} s"
    time.sleep(0.5)
    assert _alive(below) == set(), [(_cmdline(p)) for p in _alive(below)]
    assert "Traceback" not in err and "interrupted" in err.splitlines()[-1], err
    assert not (tmp_path / "season").exists()
