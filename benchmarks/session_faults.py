"""Sessions that hold (issue 34): two commands on one session folder, and stop signals across a step.

    python benchmarks/session_faults.py concurrent   # every pair of commands, several delays
    python benchmarks/session_faults.py signals [--tries 50]

``concurrent`` runs two real ``tpvp session`` processes on one folder: add/add, plan/add,
add/plan and export/add. The first is held at its first write (``TPVP_FAULT=pause@1``: it has
read the state and not yet committed) until the second, started 0 or 1 s later, says it waits
(or, with ``--wait 0``, has ended); or both start 0.0-1.5 s apart without a pause. A try holds
when every capture a command reported is in the state, a refused command said so in one line with
exit 3, and the folder has no problem (no orphan file).

``signals`` sends SIGINT or SIGTERM (alternately) to ``session add`` and ``session plan``: at each
of their write steps (the commit's renames and the moment after it included, ``TPVP_FAULT=
interrupt@N``) and at random moments (fixed seed) of their run. A try holds when no traceback is
printed and exit status, line and folder agree: 0 and the step recorded (a late signal said to
have come after it), or 130, one line saying nothing was written, and the folder as it was.
``tests/test_session_faults.py`` runs some of each with the same functions.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import json
import os
import random
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PREVIOUS = ROOT / "tpvp" / "data" / "pheno4d" / "tomato_0305.xyz.gz"
HANG_S = 180
#: The views a bench session captures: the initial view and the warm-up's, then extra ones.
WARM_UP, EXTRA = (17, 3), (5, 6, 12)
PAIRS = ("add/add", "plan/add", "add/plan", "export/add")


def tpvp(*args) -> list[str]:
    return [sys.executable, "-m", "tpvp", "session", *map(str, args)]


def prepare(scratch: Path) -> dict[str, Path]:
    """Capture clouds (millimetres, the previous model's frame) of the stand-in camera and two
    session folders: ``one`` (the initial view captured) and ``ready`` (the warm-up done)."""
    from tpvp.config_loading import make_config
    from tpvp.io import read_point_cloud, write_point_cloud
    from tpvp.scene.samples import load_sample
    from tpvp.session import Session
    from tpvp.simulate.robot_camera import StandInCamera

    camera = StandInCamera(load_sample("tomato_0305"), load_sample("tomato_0306"), make_config("plant"))
    paths = {}
    for view in WARM_UP + EXTRA:
        paths[f"cloud{view}"] = write_point_cloud(scratch / f"cloud{view}.ply", 1e3 * camera.cloud(view))
    session = Session.start(scratch / "one", read_point_cloud(PREVIOUS, units="mm"), make_config("plant"),
                            str(PREVIOUS), units="mm")
    session.add(camera.cloud(WARM_UP[0]), WARM_UP[0], "cloud")
    shutil.copytree(scratch / "one", scratch / "ready")
    Session.open(scratch / "ready").add(camera.cloud(WARM_UP[1]), WARM_UP[1], "cloud")
    return {**paths, "one": scratch / "one", "ready": scratch / "ready"}


def copy_session(source: Path, folder: Path) -> Path:
    shutil.rmtree(folder, ignore_errors=True)
    for leftover in folder.parent.glob(f".{folder.name}.tpvp-*"):
        shutil.rmtree(leftover) if leftover.is_dir() else leftover.unlink()
    return Path(shutil.copytree(source, folder))


def state(folder: Path) -> dict:
    return json.loads((folder / "session.json").read_text())


def digest(folder: Path) -> dict:
    """Every file of the folder and its SHA-256 (a folder left exactly as it was has the same)."""
    return {p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def problems(folder: Path) -> list[str]:
    """The folder's problems (``tpvp session check``) and what a run left beside it."""
    from tpvp.session import Session

    found = [p.what for p in Session.problems(folder)]
    left = [p.name for p in folder.parent.glob(f".{folder.name}.tpvp-*") if not p.name.endswith("-lock")]
    return found + [f"left beside the folder: {name}" for name in sorted(left)]


def _finish(process: subprocess.Popen, read=()) -> dict:
    """The process's end: exit status (None: killed after :data:`HANG_S`), stdout, stderr lines
    (``read``: what was read of its stderr before)."""
    try:
        out, err = process.communicate(timeout=HANG_S)
        rc = process.returncode
    except subprocess.TimeoutExpired:
        process.kill()
        out, err = process.communicate()
        rc = None
    return {"rc": rc, "stdout": out, "stderr": ("".join(read) + err).strip().splitlines()}


def _start(argv, env=None) -> subprocess.Popen:
    return subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT,
                            env={**os.environ, **(env or {})})


# --- two commands on one folder --------------------------------------------------------------------

def pair_commands(pair: str, folder: Path, paths: dict, wait: float) -> list[tuple[str, list[str]]]:
    """The two commands of ``pair`` (first, second) on ``folder``: (their kind, argv)."""
    def command(kind: str, view: int) -> list[str]:
        if kind == "add":
            return tpvp("add", folder, "--cloud", paths[f"cloud{view}"], "--pose", view, "--wait", wait)
        if kind == "export":
            return tpvp("export", folder, "--model", folder.parent / f"{folder.name}-today.ply", "--wait", wait)
        return tpvp("plan", folder, "--wait", wait)
    first, second = pair.split("/")
    return [(first, command(first, EXTRA[0])), (second, command(second, EXTRA[1]))]


def concurrent_try(pair: str, folder: Path, paths: dict, delay: float, pause: bool, wait: float = 60) -> dict:
    """Run ``pair`` on a fresh copy of the ``ready`` session. ``pause``: the first command stops
    between its read and its commit (at its first write) until the second has started and either
    ended or said it waits; else the second starts ``delay`` seconds after the first."""
    copy_session(paths["ready"], folder)
    before = len(state(folder)["captures"])
    (first_kind, first), (second_kind, second) = pair_commands(pair, folder, paths, wait)
    go_on = folder.parent / f"{folder.name}.go-on"
    go_on.unlink(missing_ok=True)
    env = {"TPVP_FAULT": "pause@1", "TPVP_FAULT_PAUSE_S": str(HANG_S), "TPVP_FAULT_PAUSE_UNTIL": str(go_on)}
    a = _start(first, env if pause else None)
    if pause:  # until the first holds the folder and writes (it read the state before)
        deadline = time.monotonic() + HANG_S
        while not list(folder.parent.glob(f".{folder.name}.tpvp-staging-*")) and a.poll() is None \
                and time.monotonic() < deadline and not (first_kind == "export" and _exported(folder)):
            time.sleep(0.01)
    time.sleep(delay)
    b = _start(second)
    said = []
    if pause:  # the second has ended (refused) or says it waits: let the first go on
        said.append(b.stderr.readline())
        go_on.touch()
    results = [(first_kind, _finish(a)), (second_kind, _finish(b, said))]
    go_on.unlink(missing_ok=True)
    return {"pair": pair, "delay": delay, "pause": pause, "wait": wait, "before": before, "results": results,
            "state": state(folder), "problems": problems(folder)}


def _exported(folder: Path) -> bool:
    """Whether export has begun writing its model (the writer's temporary file of its staged file)."""
    return bool(list(folder.parent.glob(f"*{folder.name}-today.ply.tpvp-staging-*")))


def concurrent_ok(result: dict) -> list[str]:
    """Why the try failed (empty: it held)."""
    why = []
    views = [c["view"] for c in result["state"]["captures"][result["before"]:]]
    reported = []
    for kind, run in result["results"]:
        text = "\n".join(run["stderr"])
        if run["rc"] is None or "Traceback" in text:
            why.append(f"{kind}: hung or a traceback: {text[-300:]}")
        elif run["rc"] == 3:
            errors = [line for line in run["stderr"] if ": error: " in line]
            if len(errors) != 1 or "is being written by another run" not in errors[0]:
                why.append(f"{kind}: exit 3 without its one line: {run['stderr']}")
        elif run["rc"] != 0:
            why.append(f"{kind}: exit {run['rc']}: {run['stderr']}")
        elif kind == "add":
            reported += [int(line.split("view ")[1].split(",")[0]) for line in run["stdout"].splitlines()
                         if line.startswith("capture ")]
        elif kind == "plan" and "plan" not in result["state"]:
            why.append("plan: exit 0 but no plan in the state")
    if sorted(reported) != sorted(views):
        why.append(f"captures reported {reported}, recorded {views}")
    why += result["problems"]
    return why


# --- stop signals across a step --------------------------------------------------------------------

def step_command(kind: str, folder: Path, paths: dict) -> list[str]:
    if kind == "add":
        return tpvp("add", folder, "--cloud", paths[f"cloud{WARM_UP[1]}"])
    return tpvp("plan", folder)


def count_steps(kind: str, folder: Path, paths: dict) -> int:
    """The write steps of the step (its files, the commit's renames, the moment after), counted in
    this process on a scratch copy."""
    from tpvp.io import faults
    from tpvp.cli import main

    copy_session(paths["one" if kind == "add" else "ready"], folder)
    with faults.inject(None), contextlib.redirect_stdout(None), contextlib.redirect_stderr(None):
        assert main([str(a) for a in step_command(kind, folder, paths)[3:]]) == 0
        return faults.steps()


def signal_try(kind: str, folder: Path, paths: dict, signum: int, delay: float | None = None,
               step: int | None = None) -> dict:
    """``session add`` (of the warm-up's second view) or ``session plan`` on a fresh copy, signalled
    ``delay`` seconds after it starts, or at its write step ``step`` (SIGINT)."""
    copy_session(paths["one" if kind == "add" else "ready"], folder)
    before = digest(folder)
    env = {"TPVP_FAULT": f"interrupt@{step}"} if step is not None else None
    process = _start(step_command(kind, folder, paths), env)
    if delay is not None:
        time.sleep(delay)
        with contextlib.suppress(ProcessLookupError):
            process.send_signal(signum)
    run = _finish(process)
    after = state(folder)
    done = len(after["captures"]) == 2 if kind == "add" else "plan" in after
    return {"kind": kind, "delay": delay, "step": step, "signal": signal.Signals(signum).name, **run,
            "done": done, "unchanged": digest(folder) == before, "problems": problems(folder)}


def signal_ok(result: dict) -> list[str]:
    """Why the try failed (empty: it held)."""
    text = "\n".join(result["stderr"])
    why = []
    if result["rc"] is None:
        return ["hung"]
    if "Traceback" in text or "Exception ignored" in text:
        why.append(f"a traceback: {text[-400:]}")
    if result["rc"] == 0:
        if not result["done"]:
            why.append("exit 0 but the step is not in the folder")
        if result["stderr"] and not all("the step is complete" in line or ": warning: " in line
                                        for line in result["stderr"]):
            why.append(f"exit 0 with {result['stderr']}")
        if result["kind"] == "add" and "capture 2: view" not in result["stdout"]:
            why.append("exit 0 without the capture's line")
    elif result["rc"] == 130:
        if result["done"] or not result["unchanged"]:
            why.append("exit 130 but the folder changed")
        if len(result["stderr"]) != 1 or "interrupted" not in text or "nothing was written" not in text:
            why.append(f"exit 130 with {result['stderr']}")
    else:
        why.append(f"exit {result['rc']}: {result['stderr']}")
    return why + result["problems"]


def signal_moments(tries: int, duration: float, seed: int = 0) -> list[tuple[float, int]]:
    """``tries`` (delay, signal): delays uniform over the run (0.1 s to its end and 0.3 s beyond),
    SIGINT and SIGTERM alternately."""
    rng = random.Random(seed)
    return [(rng.uniform(0.1, duration + 0.3), signal.SIGINT if i % 2 == 0 else signal.SIGTERM)
            for i in range(tries)]


def timed(kind: str, folder: Path, paths: dict) -> float:
    """Seconds one run of the step takes here (the anchor of the random moments)."""
    copy_session(paths["one" if kind == "add" else "ready"], folder)
    start = time.monotonic()
    run = _finish(_start(step_command(kind, folder, paths)))
    assert run["rc"] == 0, run
    return time.monotonic() - start


# --- the command line --------------------------------------------------------------------------------

def _concurrent(scratch: Path, paths: dict) -> bool:
    good = total = 0
    print(f"{'pair':<11} {'pause':>5} {'delay':>5} {'wait':>4}  outcome")
    for pair in PAIRS:
        settings = [(True, 0.0, 60), (True, 1.0, 60), (True, 0.0, 0)] + [(False, d, 60) for d in (0.0, 0.3, 0.8, 1.5)]
        for pause, delay, wait in settings:
            result = concurrent_try(pair, scratch / "session", paths, delay, pause, wait)
            why = concurrent_ok(result)
            good, total = good + (not why), total + 1
            codes = ", ".join(f"{kind} {run['rc']}" for kind, run in result["results"])
            print(f"{pair:<11} {str(pause):>5} {delay:5.1f} {wait:>4}  {codes}; "
                  f"{len(result['state']['captures']) - result['before']} captures recorded"
                  + (f"; FAILED: {why}" if why else ""))
    print(f"concurrent: {good} of {total} tries held (every reported capture recorded, a refusal exit 3 and "
          f"one line, no problem in the folder)")
    return good == total


def _signals(scratch: Path, paths: dict, tries: int) -> bool:
    good = total = 0
    lines = set()
    for kind in ("add", "plan"):
        folder = scratch / f"signals-{kind}"
        steps = count_steps(kind, folder, paths)
        duration = timed(kind, folder, paths)
        random_tries = max(tries // 2 - steps, 0)
        print(f"session {kind}: {steps} write steps, {duration:.2f} s a run; {steps} signals at the write steps, "
              f"{random_tries} at random moments")
        runs = [dict(step=s, signum=signal.SIGINT) for s in range(1, steps + 1)]
        runs += [dict(delay=d, signum=s) for d, s in signal_moments(random_tries, duration)]
        outcomes = {}
        for run in runs:
            result = signal_try(kind, folder, paths, **run)
            why = signal_ok(result)
            good, total = good + (not why), total + 1
            outcomes[result["rc"]] = outcomes.get(result["rc"], 0) + 1
            lines.update(result["stderr"][-1:] if not why else [])
            if why:
                at = f"step {run['step']}" if "step" in run else f"{run['delay']:.3f} s"
                print(f"  FAILED at {at} ({result['signal']}): rc {result['rc']}: {why}")
        print(f"  exit status: {outcomes}")
    print("lines seen:\n" + "\n".join(f"  {line}" for line in sorted(lines)))
    print(f"signals: {good} of {total} tries held (no traceback; exit status, line and folder agree)")
    return good == total


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="what", required=True)
    sub.add_parser("concurrent")
    sub.add_parser("signals").add_argument("--tries", type=int, default=50)
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory() as scratch:
        paths = prepare(Path(scratch))
        ok = (_concurrent(Path(scratch), paths) if args.what == "concurrent"
              else _signals(Path(scratch), paths, args.tries))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
