"""Large input: a 5-million-point binary PLY scan pair through the whole ``tpvp plan``.

Run from the repository root::

    python benchmarks/large_scan.py                  # 5 M points per scan, float32 PLY
    python benchmarks/large_scan.py --points 2000000 --dtype float64
    python benchmarks/large_scan.py --skip-full      # only the reduced run (the target)

What it does:

1. densifies the bundled real tomato pair (Pheno4D 03-05 -> 03-06, metres, ~5 cm plant) to
   ``--points`` points per scan: each new point lies on the segment between a real point and one of
   its 7 nearest neighbours (so on the scanned surface), plus isotropic jitter of sigma
   ``--jitter`` (default 0.1 mm, i.e. within ~0.3 mm); deterministic (seed 0). Both scans are
   written as binary little-endian PLY with :func:`tpvp.io.write_point_cloud` in a temp folder;
2. runs ``tpvp plan --previous A --current B --output DIR`` in a *subprocess* for: the bundled
   small pair written as PLY (the anchor), the large pair reduced (default configuration) and the
   large pair at full resolution (``--set scene.reduce_above=100000000``). Wall time and peak RSS
   are those of the child process (``/usr/bin/time -v`` when present, else ``ru_maxrss`` of
   RUSAGE_CHILDREN, which is the largest child so far). A first small run warms the numba cache;
   its numbers are not reported;
3. prints a table: points per scan, wall time, peak RSS, views, coverage, path, the ratios to the
   anchor, and whether the plan (``plan_normalised.csv``'s view_index order) equals the plan of the
   full-resolution run. The per-stage seconds of ``results.json`` follow.

Target (issue "Nothing lost, nothing mixed"): the reduced 5 M run <= 15 s and <= 1.5 GB peak on
2 cores, with the full-resolution plan. Numbers are single runs and are reported, never asserted.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

try:
    import tpvp  # noqa: F401
except ImportError:  # not installed: run from a checkout
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from scipy.spatial import cKDTree

from tpvp.io import write_point_cloud
from tpvp.scene.samples import load_sample

FULL = ["--set", "scene.reduce_above=100000000"]


def densify(points: np.ndarray, n: int, jitter: float, seed: int = 0, chunk: int = 1_000_000) -> np.ndarray:
    """``n`` points on the surface sampled by ``points`` (see the module doc)."""
    rng = np.random.default_rng(seed)
    _, neighbours = cKDTree(points).query(points, k=8)
    out = np.empty((n, 3), dtype=np.float64)
    for start in range(0, n, chunk):
        m = min(chunk, n - start)
        src = rng.integers(len(points), size=m)
        nbr = neighbours[src, rng.integers(1, 8, size=m)]
        t = rng.random((m, 1))
        out[start:start + m] = (points[src] + t * (points[nbr] - points[src])
                                + rng.normal(scale=jitter, size=(m, 3)))
    return out


def run_plan(previous: Path, current: Path, output: Path, extra=()) -> dict:
    """One ``tpvp plan`` in a child process: wall seconds, peak RSS (MB), its stdout and results."""
    cmd = [sys.executable, "-m", "tpvp", "plan", "--previous", str(previous), "--current", str(current),
           "--output", str(output), *extra]
    timer = shutil.which("time") or ("/usr/bin/time" if os.path.exists("/usr/bin/time") else None)
    if timer:
        cmd = [timer, "-v", *cmd]
    env = {**os.environ, "TQDM_DISABLE": "1"}
    t = time.perf_counter()
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env)
    wall = time.perf_counter() - t
    if proc.returncode != 0:
        raise SystemExit(f"tpvp plan failed ({proc.returncode}):\n{proc.stdout}\n{proc.stderr}")
    match = re.search(r"Maximum resident set size \(kbytes\): (\d+)", proc.stderr)
    if match:
        peak_mb = int(match.group(1)) / 1024
    else:  # largest child so far (Linux: kB)
        peak_mb = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    cpu = sum(float(m) for m in re.findall(r"(?:User|System) time \(seconds\): ([\d.]+)", proc.stderr)) \
        if match else float("nan")
    results = json.loads((output / "results.json").read_text())
    with open(output / "plan_normalised.csv") as f:
        rows = list(csv.DictReader(line for line in f if not line.startswith("#")))
    return {"wall_s": wall, "cpu_s": cpu, "peak_mb": peak_mb, "stdout": proc.stdout, "results": results,
            "plan": [int(r["view_index"]) for r in rows]}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--points", type=int, default=5_000_000, help="points per large scan")
    parser.add_argument("--dtype", choices=("float32", "float64"), default="float32",
                        help="PLY property type of the large scans")
    parser.add_argument("--jitter", type=float, default=1e-4, help="jitter sigma (m)")
    parser.add_argument("--skip-full", action="store_true", help="skip the full-resolution run")
    parser.add_argument("--keep", type=Path, default=None, help="keep scans and outputs in this folder")
    args = parser.parse_args(argv)

    base = args.keep or Path(tempfile.mkdtemp(prefix="tpvp_large_"))
    base.mkdir(parents=True, exist_ok=True)
    try:
        prev_small, cur_small = load_sample("tomato_0305"), load_sample("tomato_0306")
        files = {"small_prev": base / "small_0305.ply", "small_cur": base / "small_0306.ply",
                 "large_prev": base / f"large_0305_{args.points}.ply",
                 "large_cur": base / f"large_0306_{args.points}.ply"}
        write_point_cloud(files["small_prev"], prev_small)
        write_point_cloud(files["small_cur"], cur_small)
        t = time.perf_counter()
        for key, pts in (("large_prev", prev_small), ("large_cur", cur_small)):
            if not files[key].exists():
                write_point_cloud(files[key], densify(pts, args.points, args.jitter), dtype=args.dtype)
        print(f"scans in {base} ({args.points:,} points per large scan, {args.dtype}, "
              f"{files['large_cur'].stat().st_size / 2**20:.0f} MiB each; generated in "
              f"{time.perf_counter() - t:.1f} s)")

        run_plan(files["small_prev"], files["small_cur"], base / "warm")  # numba cache warm-up
        runs = {"anchor (bundled pair)": (run_plan(files["small_prev"], files["small_cur"], base / "anchor"),
                                          f"{len(prev_small):,} / {len(cur_small):,}"),
                "large, reduced (default)": (run_plan(files["large_prev"], files["large_cur"], base / "reduced"),
                                             f"{args.points:,} / {args.points:,}")}
        if not args.skip_full:
            runs["large, full resolution"] = (run_plan(files["large_prev"], files["large_cur"], base / "full", FULL),
                                              f"{args.points:,} / {args.points:,}")
        anchor = runs["anchor (bundled pair)"][0]
        reference = runs.get("large, full resolution", (None,))[0]

        header = ("run", "points prev / cur", "wall s", "x anchor", "cpu s", "peak MB", "x anchor", "views",
                  "coverage %", "path m", "plan", "same plan as full")
        table = []
        for name, (r, points) in runs.items():
            res = r["results"]
            same = "n/a" if reference is None or name.startswith("anchor") else \
                ("yes" if r["plan"] == reference["plan"] else "NO")
            table.append((name, points, f"{r['wall_s']:.1f}", f"{r['wall_s'] / anchor['wall_s']:.2f}", f"{r['cpu_s']:.1f}",
                          f"{r['peak_mb']:.0f}", f"{r['peak_mb'] / anchor['peak_mb']:.2f}", str(res["views"]),
                          f"{100 * res['coverage']:.2f}", f"{res['path_length_m']:.2f}",
                          " ".join(map(str, r["plan"])), same))
        widths = [max(len(h), *(len(row[i]) for row in table)) for i, h in enumerate(header)]
        for row in (header, *table):
            print("  ".join(c.ljust(w) for c, w in zip(row, widths)))

        print(f"load average after the runs: {os.getloadavg()[0]:.2f} (wall times assume an otherwise idle machine)")
        print("\nseconds per stage (results.json; reading, scene and outputs are the rest of the wall time):")
        keys = ["compile", "warm_up", "registration", "inflation", "visibility", "selection", "path"]
        print("  " + "run".ljust(26) + "".join(k.rjust(13) for k in keys))
        for name, (r, _) in runs.items():
            res = r["results"]
            print("  " + name.ljust(26) + "".join(f"{res.get(f'seconds_{k}', float('nan')):13.2f}" for k in keys))
        for name, (r, _) in runs.items():
            notes = [line for line in r["stdout"].splitlines() if line.startswith("note:")]
            for line in notes:
                print(f"{name}: {line}")
            res = r["results"]
            print(f"{name}: Chamfer {res['chamfer_before_mm']:.3f} -> {res['chamfer_after_mm']:.3f} mm")
    finally:
        if args.keep is None:
            shutil.rmtree(base, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
