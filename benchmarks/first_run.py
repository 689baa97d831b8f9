"""Start-up costs on a fresh clone: ``import tpvp``, ``tpvp --help``, the first ``tpvp demo`` with
an empty numba cache, and ``tpvp plan`` on the bundled pair once the kernels are cached.

Every figure is the wall time of a fresh process (``python -c "import tpvp"``, ``python -m tpvp
demo``, ``python -m tpvp plan``), the median of ``--repeats`` runs. A fresh clone is emulated by an
empty ``NUMBA_CACHE_DIR`` (numba then compiles every kernel the command runs; Python's own bytecode
cache of tpvp, ~0.2 s to rebuild, is not emptied). "compile line" is what the demo prints as
``time: numba compile / cache load``. The warm plan runs on the cache the demo filled, after one
untimed run.

With ``--baseline PATH`` (another checkout, e.g. the code before a change) the same commands run
on both trees in the same process, alternating, and ``ratio`` = baseline / this tree (> 1: this
tree is faster); the baseline is the anchor. Targets (issues 25 and 36): compile line <= 8 s and the
whole first demo <= 25 s, warm plan <= 2.5 s, ``import tpvp`` <= 0.5 s, ``tpvp --help`` <= 0.3 s.
The demo's printed result (views, coverage, path length) and the warm plan's plan files must be
the same on both trees. ``--warm-only`` skips the first demo (the cold numba cache, ~25 s a run).

Usage: python benchmarks/first_run.py [--baseline /path/to/other/checkout] [--repeats 3]
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]
PAIR = [HERE / "tpvp" / "data" / "pheno4d" / f"tomato_{day}.xyz.gz" for day in ("0305", "0306")]
TARGETS = {"import tpvp": 0.5, "tpvp --help": 0.3, "first demo: compile line": 8.0,
           "first demo: whole command": 25.0, "warm plan": 2.5}
COLD = ("first demo: compile line", "first demo: whole command")
PLAN_FILES = ("plan.csv", "plan_normalised.csv", "plan.json")
RESULT_LINES = ("views (warm-up included)", "coverage of the oracle set", "path length")


def _run(tree: Path, args: list[str], numba_cache: str | None = None) -> tuple[float, str]:
    """Wall seconds and stdout of ``python args`` importing tpvp from ``tree``."""
    env = dict(os.environ, PYTHONPATH=str(tree))
    if numba_cache is not None:
        env["NUMBA_CACHE_DIR"] = numba_cache
    start = time.perf_counter()
    done = subprocess.run([sys.executable, *args], env=env, cwd=tree, capture_output=True, text=True)
    seconds = time.perf_counter() - start
    if done.returncode:
        raise SystemExit(f"{tree}: python {' '.join(args)} failed:\n{done.stderr[-2000:]}")
    return seconds, done.stdout


def _compile_line(stdout: str) -> float:
    found = re.search(r"numba compile / cache load\s+([0-9.]+) s", stdout)
    return float(found.group(1)) if found else float("nan")


def _result(stdout: str) -> str:
    return " | ".join(" ".join(line.split()) for line in stdout.splitlines()
                      if line.strip().startswith(RESULT_LINES))


def measure(trees: list[Path], repeats: int, scratch: Path, cold: bool = True) -> tuple[dict, dict]:
    """``(figures, results)``: per tree, per measurement, the list of seconds; per tree, the demo's
    result lines (or the warm plan's, without ``cold``) and its plan files."""
    names = ("python start", *(name for name in TARGETS if cold or name not in COLD))
    figures = {tree: {name: [] for name in names} for tree in trees}
    results = {}
    caches = {tree: str(scratch / f"numba-{i}") for i, tree in enumerate(trees)}
    plan = ["-m", "tpvp", "plan", "--previous", str(PAIR[0]), "--current", str(PAIR[1])]
    for r in range(repeats):
        for i, tree in enumerate(trees):
            print(f"  repeat {r + 1}/{repeats}, {tree} ...", file=sys.stderr, flush=True)
            out = scratch / f"out-{i}"
            figures[tree]["python start"].append(_run(tree, ["-c", "pass"])[0])
            figures[tree]["import tpvp"].append(_run(tree, ["-c", "import tpvp"])[0])
            figures[tree]["tpvp --help"].append(_run(tree, ["-m", "tpvp", "--help"])[0])
            if cold:
                with tempfile.TemporaryDirectory(dir=scratch) as empty:
                    seconds, stdout = _run(tree, ["-m", "tpvp", "demo", "--output", str(out / "demo")], empty)
                figures[tree]["first demo: whole command"].append(seconds)
                figures[tree]["first demo: compile line"].append(_compile_line(stdout))
                results.setdefault(tree, _result(stdout))
            if r == 0:  # fill this tree's cache with everything the plan runs
                _run(tree, [*plan, "--output", str(out / "plan")], caches[tree])
            seconds, stdout = _run(tree, [*plan, "--output", str(out / "plan")], caches[tree])
            figures[tree]["warm plan"].append(seconds)
            results.setdefault(tree, _result(stdout))
            results[tree] += "".join("\n" + (out / "plan" / name).read_text() for name in PLAN_FILES) if r == 0 else ""
    return figures, results


def table(figures: dict, trees: list[Path]) -> str:
    anchor = trees[0]
    names = list(figures[anchor])
    head = ["measurement (median s)", *[f"{t.name or t}" for t in trees]]
    if len(trees) > 1:
        head.append("ratio")
    head += ["target", "met", "all runs (this tree)"]
    rows = []
    for name in names:
        medians = [statistics.median(figures[t][name]) for t in trees]
        row = [name, *[f"{m:.2f}" for m in medians]]
        if len(trees) > 1:
            row.append(f"{medians[0] / medians[-1]:.2f}x")
        target = TARGETS.get(name)
        row += [f"<= {target:g}" if target else "-",
                ("yes" if medians[-1] <= target else "no") if target else "-",
                " ".join(f"{s:.2f}" for s in figures[trees[-1]][name])]
        rows.append(row)
    widths = [max(len(str(r[c])) for r in [head, *rows]) for c in range(len(head))]
    lines = ["| " + " | ".join(str(v).ljust(w) for v, w in zip(r, widths)) + " |" for r in [head, *rows]]
    lines.insert(1, "|" + "|".join("-" * (w + 2) for w in widths) + "|")
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--baseline", type=Path, default=None,
                        help="another checkout to measure in the same run (the anchor of the ratios)")
    parser.add_argument("--repeats", type=int, default=3, help="runs per measurement and tree (default 3)")
    parser.add_argument("--warm-only", action="store_true", help="skip the first demo with an empty numba cache")
    args = parser.parse_args(argv)
    trees = ([args.baseline.resolve()] if args.baseline else []) + [HERE]
    load = " / ".join(f"{x:.2f}" for x in os.getloadavg())
    with tempfile.TemporaryDirectory(prefix="tpvp-first-run-") as scratch:
        figures, results = measure(trees, args.repeats, Path(scratch), cold=not args.warm_only)
    print(f"first_run: {os.cpu_count()} cores, load average (1/5/15 min) {load} at the start, "
          f"{' / '.join(f'{x:.2f}' for x in os.getloadavg())} at the end; {args.repeats} runs per figure")
    for i, tree in enumerate(trees):
        role = "baseline (anchor)" if args.baseline and i == 0 else "this tree"
        print(f"  {role}: {tree}")
    print(table(figures, trees))
    for tree in trees:
        print(f"result ({tree.name}): {results[tree].splitlines()[0]}")
    same = len(set(results.values())) == 1
    if len(trees) > 1:
        print("results and plan files identical" if same else "RESULTS DIFFER")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
