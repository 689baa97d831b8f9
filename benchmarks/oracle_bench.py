"""Greenhouse oracle on a generated row: our time against OctoMap's castRay on the same rays.

The oracle (docs/greenhouse.md#oracle) tries view-box grid points nearest first for every ground-truth voxel. Running
it with OctoMap would take hours (the paper), so the anchor is OctoMap's measured cost per castRay on
the same octree, for a random sample of the same kind of rays, times the number of rays our oracle
cast. Usage: python benchmarks/oracle_bench.py [--room room1] [--session 0] [--sample-rays 20000]
"""

from __future__ import annotations

import argparse
import os
import time

import numba
import numpy as np
import pandas as pd

from tpvp.scene import voxels
from tpvp.scene.boxes import room_config
from tpvp.scene.grid import build_grid
from tpvp.synthetic.greenhouse import generate_row
from tpvp.visibility.oracle import greenhouse_oracle


def octomap_seconds_per_ray(grid, viewpoints, sample_rays, seed=0):
    """Median cost of one OctoMap castRay (viewpoint -> voxel centre, max range 2 m)."""
    try:
        import pyoctomap
    except ImportError:
        return None
    tree = pyoctomap.OcTree(grid.resolution)
    for c in grid.centres:
        tree.updateNode(c, True)
    rng = np.random.default_rng(seed)
    origins = viewpoints[rng.integers(0, len(viewpoints), sample_rays)]
    targets = grid.centres[rng.integers(0, grid.size, sample_rays)]
    end = np.zeros(3)
    started = time.perf_counter()
    for o, t in zip(origins, targets):
        tree.castRay(o, t - o, end, True, 2.0)
    return (time.perf_counter() - started) / sample_rays


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--room", default="room1")
    parser.add_argument("--session", type=int, default=0)
    parser.add_argument("--sample-rays", type=int, default=20000)
    args = parser.parse_args()

    row = generate_row(args.room, seed=0, session=args.session)
    grid = build_grid(voxels.voxelise(row.points, 0.01), 0.01)
    viewpoints = room_config(args.room).view_box.grid(0.1)
    greenhouse_oracle(grid, viewpoints[:4])  # compile
    started = time.perf_counter()
    visible, rays = greenhouse_oracle(grid, viewpoints, return_rays=True, progress=True)
    ours = time.perf_counter() - started
    per_ray = octomap_seconds_per_ray(grid, viewpoints, args.sample_rays)
    anchor = None if per_ray is None else per_ray * rays
    table = pd.DataFrame([{
        "measurement": f"greenhouse oracle, {args.room} session {args.session}, 1 cm",
        "voxels": grid.size,
        "viewpoints": len(viewpoints),
        "rays": rays,
        "visible %": 100 * len(visible) / grid.size,
        "ours s": ours,
        "OctoMap s (est.)": anchor,
        "ratio": None if anchor is None else anchor / ours,
        "target": "<= 120 s",
        "met": "yes" if ours <= 120 else "no",
    }])
    print(f"numba threads {numba.get_num_threads()}, cpus {os.cpu_count()}")
    print(table.to_string(index=False, float_format=lambda x: f"{x:,.1f}"))


if __name__ == "__main__":
    main()
