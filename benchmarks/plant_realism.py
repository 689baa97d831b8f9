"""Realism of the generated single plants against the bundled real Pheno4D scans.

Every plant is set up as the single-plant experiments do it (largest bounding-box side 0.24 m,
bounding-box centre, supporting table, 2 mm ground-truth voxels) and rendered from the 32 hemisphere
views with the reference sensor. Columns: points, occupied voxels, bounding-box extent, horizontal
extent along the plant's own principal axes (independent of azimuth), oracle share of the voxels,
and the oracle coverage curve (greedy best views: coverage after 1, 2, 4 and 8 views), generation
time. Under the table: the real ranges and, per species, the mean over the generated seeds and how
many seeds fall inside the target ranges (tomato: the range of the two bundled real tomato scans;
maize: within ``MAIZE_TOLERANCE`` points of the one real maize scan). A second table reports session
pairs (correspondences, new leaves, displacement).

    python benchmarks/plant_realism.py [--seeds 6] [--seed-list 0 1 2 3 4 5 10 11 12]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
import pandas as pd

from tpvp.scene.grid import plant_grid
from tpvp.scene.normalise import normalise_plant
from tpvp.synthetic.plants import generate_plant, generate_session_pair
from tpvp.scene.samples import load_sample
from tpvp.viewspace.single_plant import load_view_space
from tpvp.visibility import oracle_voxels, visibility_matrix

CURVE_VIEWS = (1, 2, 4, 8)
REAL = ("tomato_0305", "tomato_0306", "maize_0313")
MAIZE_TOLERANCE = 3.0  # points of oracle share / cov@1 around the single real maize scan
TARGET_COLUMNS = ("oracle %", "cov@1")


def greedy_curve(matrix, oracle, steps=CURVE_VIEWS):
    """Coverage of the oracle after the best 1, 2, ... views chosen greedily."""
    dense = matrix.toarray()[:, oracle]
    covered = np.zeros(dense.shape[1], bool)
    curve = {}
    for k in range(1, max(steps) + 1):
        gains = (dense & ~covered).sum(axis=1)
        covered |= dense[int(np.argmax(gains))]
        if k in steps:
            curve[f"cov@{k}"] = covered.mean()
    return curve


def principal_horizontal_extent(points):
    xy = points[:, :2] - points[:, :2].mean(axis=0)
    _, vecs = np.linalg.eigh(np.cov(xy.T))
    return np.ptp(xy @ vecs[:, ::-1], axis=0)


def describe(name, seed, raw_points, views, seconds=None, leaves=None):
    scene = normalise_plant(raw_points, table=True)
    grid = plant_grid(scene.points, scene.table_points, 0.002)
    matrix = visibility_matrix(grid, views, np.zeros(3))
    oracle = oracle_voxels(matrix)
    ext = np.ptp(scene.points, axis=0)
    major, minor = principal_horizontal_extent(scene.points)
    return {"plant": name, "seed": seed, "points": len(raw_points), "voxels": int(grid.countable.sum()),
            "bbox (m)": f"{ext[0]:.3f} x {ext[1]:.3f} x {ext[2]:.3f}",
            "principal xy (m)": f"{major:.3f} x {minor:.3f}", "leaves": leaves,
            "oracle %": 100 * len(oracle) / grid.countable.sum(),
            **{k: 100 * v for k, v in greedy_curve(matrix, oracle).items()}, "gen s": seconds}


def target_ranges(table):
    """Per species, (low, high) of every target column: the real tomato scans' range; the real maize
    scan +- MAIZE_TOLERANCE."""
    real = table[table["plant"].str.startswith("real ")]
    ranges = {}
    for species in ("tomato", "maize"):
        part = real[real["plant"].str.startswith(f"real {species}")]
        if species == "maize":
            ranges[species] = {c: (part[c].min() - MAIZE_TOLERANCE, part[c].max() + MAIZE_TOLERANCE)
                               for c in TARGET_COLUMNS}
        else:
            ranges[species] = {c: (part[c].min(), part[c].max()) for c in TARGET_COLUMNS}
    return ranges


def inside(row, ranges):
    return all(lo <= row[c] <= hi for c, (lo, hi) in ranges.items())


def realism_summary(table) -> list[str]:
    """Lines under the table: the real scans, and per species the targets, the mean over the generated
    seeds and the seeds inside the targets."""
    ranges = target_ranges(table)
    real = table[table["plant"].str.startswith("real ")]
    scans = [f"{row['plant'][5:]} oracle {row['oracle %']:.1f} %, cov@1 {row['cov@1']:.1f} %"
             for _, row in real.iterrows()]
    lines = ["real scans: " + "; ".join(scans)]
    for species in ("tomato", "maize"):
        part = table[table["plant"] == species]
        if part.empty:
            continue
        target = ranges[species]
        what = "range of the real tomato scans" if species == "tomato" else \
            f"real maize scan +- {MAIZE_TOLERANCE:.0f} points"
        target_text = ", ".join(f"{c} {lo:.1f}-{hi:.1f}" for c, (lo, hi) in target.items())
        means = {c: part[c].mean() for c in TARGET_COLUMNS}
        mean_text = ", ".join(f"{c} {v:.1f}" for c, v in means.items())
        ok = [str(row["seed"]) for _, row in part.iterrows() if inside(row, target)]
        lines.append(f"{species}: target ({what}) {target_text}; mean over the {len(part)} seeds {mean_text} "
                     f"({'inside' if inside(means, target) else 'OUTSIDE'}); seeds inside {len(ok)} of "
                     f"{len(part)} ({' '.join(ok) if ok else 'none'})")
    return lines


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=6, help="seeds 0 .. N-1 (ignored with --seed-list)")
    parser.add_argument("--seed-list", type=int, nargs="+", default=None, help="explicit seeds, e.g. 0 1 2 10 11 12")
    parser.add_argument("--days", type=float, nargs="+", default=[1.0, 2.0, 3.0])
    args = parser.parse_args(argv)
    seeds = list(args.seed_list) if args.seed_list else list(range(args.seeds))
    views = load_view_space("hemisphere")
    rows = []
    for species in ("tomato", "maize"):
        for seed in seeds:
            started = time.perf_counter()
            plant = generate_plant(species, seed)
            seconds = time.perf_counter() - started
            rows.append(describe(species, seed, plant.points, views, seconds, plant.leaf_count))
    for name in REAL:
        rows.append(describe("real " + name, "", load_sample(name), views))
    table = pd.DataFrame(rows)
    ranges = target_ranges(table)
    table["in range"] = [("yes" if inside(row, ranges[row["plant"]]) else "no") if row["plant"] in ranges else ""
                         for _, row in table.iterrows()]
    print("hemisphere 32 views, table, 2 mm voxels, largest side 0.24 m; cov@k = oracle coverage "
          "after the k best views (greedy), %")
    print(table.to_string(index=False, float_format=lambda x: f"{x:.1f}", na_rep=""))
    generated = table[table["gen s"].notna()]
    for species in ("tomato", "maize"):
        part = generated[generated["plant"] == species]
        print(f"{species}: voxels {part['voxels'].min()}-{part['voxels'].max()}, "
              f"oracle {part['oracle %'].min():.1f}-{part['oracle %'].max():.1f} %, "
              f"cov@1 {part['cov@1'].min():.1f}-{part['cov@1'].max():.1f} %, "
              f"cov@2 {part['cov@2'].min():.1f}-{part['cov@2'].max():.1f} %, "
              f"generation {part['gen s'].mean():.3f} s mean / {part['gen s'].max():.3f} s max")
    for line in realism_summary(table):
        print(line)

    pairs = []
    for species in ("tomato", "maize"):
        for seed in seeds[:3]:
            for days in args.days:
                started = time.perf_counter()
                pair = generate_session_pair(species, seed, days=days)
                seconds = time.perf_counter() - started
                moved = np.linalg.norm(pair.displacement, axis=1) * 1000
                pairs.append({"plant": species, "seed": seed, "days": days,
                              "previous pts": len(pair.previous.points), "current pts": len(pair.current.points),
                              "correspondences": len(pair.correspondence_current_idx),
                              "leaves": f"{pair.previous.leaf_count}->{pair.current.leaf_count}",
                              "median mm": np.median(moved), "p95 mm": np.percentile(moved, 95),
                              "max mm": moved.max(), "gen s": seconds})
    print("\nsession pairs (displacement of corresponded points at the generated, real-size scale)")
    print(pd.DataFrame(pairs).to_string(index=False, float_format=lambda x: f"{x:.2f}"))


if __name__ == "__main__":
    main()
