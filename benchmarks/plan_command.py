"""Wall time of ``tpvp plan`` on the bundled real tomato pair, warm: this working tree against a
previous commit, in one run.

"Warm" is a run after an untimed one: numba's kernels are cached on disk (and Python's bytecode,
unless ``--no-bytecode-cache``). Every figure is the wall time of a fresh ``tpvp plan --previous
tomato_0305 --current tomato_0306`` process (the venv's ``tpvp`` script, tpvp imported from the
tree through PYTHONPATH), the median of ``--repeats`` runs; the trees alternate run by run, so a
load that comes and goes weighs on both alike. ``--baseline COMMIT`` checks the commit out in a
temporary ``git worktree`` under the system's temporary folder (removed at the end) and runs it
with the same venv; ``ratio`` = baseline median / this tree's median (> 1: this tree is faster).
The plan files (plan.csv, plan_normalised.csv, plan.json) of the two trees must be byte-identical:
the exit status is 1 when they differ. Target (issue 48): warm plan <= 2.5 s.

The medians are written to ``benchmarks/results/plan_command.csv`` (``--csv``) with the library's
atomic writer.

Usage: python benchmarks/plan_command.py [--baseline 275a9e1] [--repeats 3]
"""

from __future__ import annotations

import argparse
import csv
import io
import os
import statistics
import subprocess
import sys
import tempfile
import time
from contextlib import contextmanager
from datetime import datetime, timezone
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(HERE))
PAIR = [HERE / "tpvp" / "data" / "pheno4d" / f"tomato_{day}.xyz.gz" for day in ("0305", "0306")]
PLAN_FILES = ("plan.csv", "plan_normalised.csv", "plan.json")
TARGET_S = 2.5
CSV = HERE / "benchmarks" / "results" / "plan_command.csv"


def _git(*args: str) -> str:
    return subprocess.run(["git", "-C", str(HERE), *args], check=True, capture_output=True, text=True).stdout.strip()


@contextmanager
def worktree(commit: str):
    """A detached checkout of ``commit`` in a temporary folder, removed on the way out."""
    folder = Path(tempfile.mkdtemp(prefix="tpvp-plan-baseline-"))
    folder.rmdir()  # git worktree add makes it
    _git("worktree", "add", "--detach", "--quiet", str(folder), commit)
    try:
        yield folder
    finally:
        subprocess.run(["git", "-C", str(HERE), "worktree", "remove", "--force", str(folder)],
                       capture_output=True, text=True)
        subprocess.run(["git", "-C", str(HERE), "worktree", "prune"], capture_output=True, text=True)


def _command() -> list[str]:
    script = Path(sys.executable).with_name("tpvp")
    return [str(script)] if script.exists() else [sys.executable, "-m", "tpvp"]


def run_plan(tree: Path, output: Path, bytecode: bool) -> float:
    """Wall seconds of one ``tpvp plan`` of the bundled pair importing tpvp from ``tree``."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    if bytecode:
        env.pop("PYTHONDONTWRITEBYTECODE", None)
    args = [*_command(), "plan", "--previous", str(PAIR[0]), "--current", str(PAIR[1]), "--output", str(output)]
    start = time.perf_counter()
    done = subprocess.run(args, env=env, cwd=tree, capture_output=True, text=True)
    seconds = time.perf_counter() - start
    if done.returncode:
        raise SystemExit(f"{tree}: {' '.join(args)} failed (status {done.returncode}):\n{done.stderr[-2000:]}")
    return seconds


def measure(trees: dict, repeats: int, scratch: Path, bytecode: bool) -> tuple[dict, dict]:
    """Per tree label: the list of warm seconds, and its plan files' bytes."""
    seconds = {label: [] for label in trees}
    plans = {}
    for label, tree in trees.items():  # untimed: fills the numba (and bytecode) caches
        print(f"  warm-up run, {label} ({tree}) ...", file=sys.stderr, flush=True)
        run_plan(tree, scratch / f"{label}-warm-up", bytecode)
    for r in range(repeats):
        for label, tree in trees.items():
            out = scratch / f"{label}-{r}"
            seconds[label].append(run_plan(tree, out, bytecode))
            print(f"  repeat {r + 1}/{repeats}, {label}: {seconds[label][-1]:.2f} s", file=sys.stderr, flush=True)
            plans.setdefault(label, {name: (out / name).read_bytes() for name in PLAN_FILES})
    return seconds, plans


def write_csv(path: Path, rows: list[dict]) -> None:
    from tpvp.io import atomic_write_text

    text = io.StringIO()
    writer = csv.DictWriter(text, fieldnames=list(rows[0]), lineterminator="\n")
    writer.writeheader()
    writer.writerows(rows)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, text.getvalue())
    print(f"wrote {path}")


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", default=None, help="a commit to measure in the same run (git worktree)")
    parser.add_argument("--repeats", type=int, default=3, help="timed runs per tree (default: %(default)s)")
    parser.add_argument("--no-bytecode-cache", dest="bytecode", action="store_false",
                        help="keep PYTHONDONTWRITEBYTECODE from the environment (every run then compiles "
                             "tpvp's sources again, ~0.1 s); by default it is unset for the runs")
    parser.add_argument("--csv", type=Path, default=CSV, help="where the medians go (default: %(default)s)")
    args = parser.parse_args(argv)
    head = _git("rev-parse", "--short", "HEAD")
    dirty = bool(_git("status", "--porcelain", "--untracked-files=no"))
    load = " / ".join(f"{x:.2f}" for x in os.getloadavg())
    with tempfile.TemporaryDirectory(prefix="tpvp-plan-command-") as scratch, \
            (worktree(args.baseline) if args.baseline else _nothing()) as base:
        trees = {**({"baseline": base} if base else {}), "this tree": HERE}
        commits = {"baseline": _git("rev-parse", "--short", args.baseline) if base else "",
                   "this tree": head + (" + working tree" if dirty else "")}
        seconds, plans = measure(trees, args.repeats, Path(scratch), args.bytecode)
    medians = {label: statistics.median(values) for label, values in seconds.items()}
    print(f"plan_command: {os.cpu_count()} cores, load average (1/5/15 min) {load} at the start, "
          f"{' / '.join(f'{x:.2f}' for x in os.getloadavg())} at the end; {args.repeats} timed runs per tree, "
          f"bytecode cache {'on' if args.bytecode else 'as the environment says'}")
    rows = []
    for label in seconds:
        print(f"  {label:9s} {commits[label]:28s} median {medians[label]:.2f} s   runs "
              + " ".join(f"{s:.2f}" for s in seconds[label]))
        rows.append({"tree": label, "commit": commits[label], "median_s": f"{medians[label]:.3f}",
                     "runs_s": " ".join(f"{s:.3f}" for s in seconds[label]), "repeats": args.repeats,
                     "target_s": TARGET_S, "cores": os.cpu_count(), "load_at_start": load,
                     "date_utc": f"{datetime.now(timezone.utc):%Y-%m-%d}"})
    same = True
    if "baseline" in medians:
        ratio = medians["baseline"] / medians["this tree"]
        print(f"  ratio baseline / this tree: {ratio:.2f}x")
        for row in rows:
            row["ratio_baseline_over_this"] = f"{ratio:.3f}"
        same = plans["baseline"] == plans["this tree"]
        print("  plan files (" + ", ".join(PLAN_FILES) + "): " + ("byte-identical" if same else "DIFFER"))
    print(f"  target <= {TARGET_S:g} s: {'met' if medians['this tree'] <= TARGET_S else 'not met'}")
    write_csv(args.csv, rows)
    return 0 if same else 1


@contextmanager
def _nothing():
    yield None


if __name__ == "__main__":
    sys.exit(main())
