"""Faults on a real machine (issue 28): a full disk and Ctrl-C / SIGTERM while a command starts.

    python benchmarks/real_faults.py full-disk [--tries 20]   # needs root: mounts small tmpfs
    python benchmarks/real_faults.py start-up [--tries 50]

``full-disk`` runs ``tpvp demo`` into a 4 MiB tmpfs filled so that between 0 and 2 MiB stay free
(evenly spread over the tries, so the run fails while writing the tables, the figures or the
recording), then frees the space and runs again into the same folder. ``start-up`` signals
``tpvp plan`` and ``python -m data_tools prepare-session`` at random moments (fixed seed) of their
first 1.5 s, SIGINT and SIGTERM alternately. Each prints one row per try and a verdict;
``tests/test_real_faults.py`` runs a few tries of each with the same functions.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PAIR = [str(ROOT / "tpvp" / "data" / "pheno4d" / f"tomato_{day}.xyz.gz") for day in ("0305", "0306")]
#: Before this, Python itself is starting (interpreter, site, the editable-install finder): no
#: program's handler is installed yet, and Python prints its own KeyboardInterrupt traceback.
PYTHON_START_S = 0.025
HANG_S = 120


class Unavailable(Exception):
    """This machine cannot mount a tmpfs (not root, or no mount permission in the container)."""


@contextlib.contextmanager
def mounted_tmpfs(size_bytes: int, read_only: bool = False):
    """A fresh tmpfs of ``size_bytes`` mounted on a new temporary folder (root only)."""
    folder = Path(tempfile.mkdtemp(prefix="tpvp-tmpfs-"))
    options = f"size={size_bytes}" + (",ro" if read_only else "")
    try:
        done = subprocess.run(["mount", "-t", "tmpfs", "-o", options, "tmpfs", str(folder)],
                              capture_output=True, text=True)
    except OSError as exc:
        folder.rmdir()
        raise Unavailable(f"cannot run mount: {exc}") from None
    if done.returncode != 0:
        folder.rmdir()
        raise Unavailable(f"cannot mount a tmpfs: {done.stderr.strip()}")
    try:
        yield folder
    finally:
        subprocess.run(["umount", "-l", str(folder)], capture_output=True)
        folder.rmdir()


def free_bytes(folder) -> int:
    st = os.statvfs(folder)
    return st.f_bavail * st.f_frsize


def fill(folder: Path, leave_free: int) -> Path:
    """A filler file that leaves about ``leave_free`` bytes free (page granularity)."""
    filler = folder / "filler.bin"
    with open(filler, "wb") as fh:
        fh.write(b"\0" * max(free_bytes(folder) - leave_free, 0))
    return filler


def run(args, timeout: float = HANG_S, **kwargs) -> dict:
    """Run a command; ``hung`` when it does not end within ``timeout`` seconds (then killed)."""
    start = time.monotonic()
    process = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT, **kwargs)
    try:
        out, err = process.communicate(timeout=timeout)
        hung = False
    except subprocess.TimeoutExpired:
        process.kill()
        out, err = process.communicate()
        hung = True
    return {"rc": process.returncode, "stdout": out, "stderr": err.strip().splitlines(),
            "seconds": time.monotonic() - start, "hung": hung}


def tpvp(*args) -> list[str]:
    return [sys.executable, "-m", "tpvp", *args]


def leftovers(output: Path) -> list[str]:
    """What a run left beside its output folder other than its (empty) lock file."""
    return sorted(p.name for p in output.parent.glob(f".{output.name}.tpvp-*") if not p.name.endswith("-lock"))


def full_disk_try(leave_free: int, size: int = 4 << 20) -> dict:
    """``tpvp demo`` into a tmpfs with ``leave_free`` bytes free, then again after freeing it."""
    with mounted_tmpfs(size) as disk:
        output = disk / "out"
        filler = fill(disk, leave_free)
        free = free_bytes(disk)
        full = run(tpvp("demo", "--output", str(output)))
        published_when_full = output.exists()
        left = leftovers(output)
        filler.unlink()
        again = run(tpvp("demo", "--output", str(output)))
        return {"free_bytes": free, "full": full, "published_when_full": published_when_full, "leftovers": left,
                "again": again, "published_after": (output / "recording.rrd").is_file()}


def full_disk_ok(result: dict) -> bool:
    full, again = result["full"], result["again"]
    failed_cleanly = (full["rc"] == 4 and len(full["stderr"]) == 1 and "nothing was published" in full["stderr"][0]
                      and not result["published_when_full"])
    succeeded = full["rc"] == 0 and result["published_when_full"]  # enough space after all
    return (not full["hung"] and (failed_cleanly or succeeded) and not result["leftovers"]
            and again["rc"] == 0 and result["published_after"])


def start_up_commands(scratch: Path, run: int) -> dict[str, list[str]]:
    """The two commands of the start-up test, writing new folders under ``scratch``. The scan is
    large enough (300,000 points) that preparing it outlasts the signal's latest moment."""
    import numpy as np

    from tpvp.io import write_point_cloud

    scan = scratch / "plant.ply"
    if not scan.exists():
        write_point_cloud(scan, np.random.default_rng(0).normal(0, 0.05, (300_000, 3)))
    return {"tpvp plan": tpvp("plan", "--previous", PAIR[0], "--current", PAIR[1],
                              "--output", str(scratch / f"plan-{run}")),
            "data_tools prepare-session": [sys.executable, "-m", "data_tools", "prepare-session", "--site", "bench3",
                                           "--date", "2025-10-02", "--scan", str(scan),
                                           "--dataset", str(scratch / f"dataset-{run}")]}


def start_up_try(command: list[str], delay: float, signum: int) -> dict:
    process = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    time.sleep(delay)
    process.send_signal(signum)
    try:
        _, err = process.communicate(timeout=HANG_S)
    except subprocess.TimeoutExpired:
        process.kill()
        _, err = process.communicate()
        return {"delay": delay, "signal": signum, "rc": None, "stderr": err.strip().splitlines()}
    return {"delay": delay, "signal": signum, "rc": process.returncode, "stderr": err.strip().splitlines()}


def start_up_ok(result: dict) -> bool:
    return result["rc"] == 130 and len(result["stderr"]) == 1 and "Traceback" not in result["stderr"][0]


def start_up_moments(tries: int, seed: int = 0, end: float = 1.5, start: float = PYTHON_START_S) -> list[tuple[float, int]]:
    """``tries`` (delay, signal) pairs: delays uniform in [start, end], SIGINT and SIGTERM alternately."""
    rng = random.Random(seed)
    return [(rng.uniform(start, end), signal.SIGINT if i % 2 == 0 else signal.SIGTERM) for i in range(tries)]


def _full_disk(tries: int) -> bool:
    levels = [round(i * (2 << 20) / max(tries - 1, 1)) for i in range(tries)]
    print(f"{'free bytes':>10}  {'rc':>3}  {'s':>5}  hung  left  again  message")
    good = 0
    for level in levels:
        result = full_disk_try(level)
        full = result["full"]
        ok = full_disk_ok(result)
        good += ok
        message = full["stderr"][-1] if full["stderr"] else ""
        print(f"{result['free_bytes']:>10}  {full['rc']:>3}  {full['seconds']:5.1f}  {str(full['hung']):>4}  "
              f"{len(result['leftovers']):>4}  {result['again']['rc']:>5}  {message[:110]}")
    print(f"full disk: {good} of {len(levels)} tries ended cleanly (exit 4 and one line, or enough space), "
          f"nothing left behind, and the next run published")
    return good == len(levels)


def _start_up(tries: int) -> bool:
    good = total = 0
    with tempfile.TemporaryDirectory() as scratch:
        for name in start_up_commands(Path(scratch), 0):
            print(f"{name}:")
            lines = set()
            for run, (delay, signum) in enumerate(start_up_moments(tries)):
                result = start_up_try(start_up_commands(Path(scratch), run)[name], delay, signum)
                ok = start_up_ok(result)
                good, total = good + ok, total + 1
                lines.update(result["stderr"][:1] if ok else [])
                if not ok:
                    print(f"  FAILED at {delay:.3f} s ({signal.Signals(signum).name}): rc {result['rc']}, "
                          f"{len(result['stderr'])} lines:\n" + "\n".join(f"    | {line}" for line in result["stderr"]))
            print("  lines seen:\n" + "\n".join(f"    {line}" for line in sorted(lines)))
    print(f"start-up: {good} of {total} signals ended with exit 130 and one line")
    return good == total


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="what", required=True)
    sub.add_parser("full-disk").add_argument("--tries", type=int, default=20)
    sub.add_parser("start-up").add_argument("--tries", type=int, default=50)
    args = parser.parse_args(argv)
    try:
        ok = _full_disk(args.tries) if args.what == "full-disk" else _start_up(args.tries)
    except Unavailable as exc:
        print(exc, file=sys.stderr)
        return 2
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
