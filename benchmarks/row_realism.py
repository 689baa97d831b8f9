"""Realism figures and timings of the procedural greenhouse rows.

For room1 and room4 and each of the five sessions: points, occupied 1 cm voxels, bounding-box
extent in the plant-box frame (length x width x height, m), plants / leaves / trusses / fruits,
the time to generate that session on its own (``generate_row``), and the correspondences kept
from the previous session.

    python benchmarks/row_realism.py [--seed 0] [--spacing 0.004] [--rooms room1 room4]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from tpvp.scene.boxes import room_config
from tpvp.synthetic.greenhouse import DATES, generate_row, row_correspondences, row_summary


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--spacing", type=float, default=0.004, help="point spacing (m)")
    ap.add_argument("--voxel", type=float, default=0.01, help="voxel size for the occupied-voxel count (m)")
    ap.add_argument("--rooms", nargs="+", default=["room1", "room4"])
    args = ap.parse_args(argv)

    head = (
        f"{'room':6} {'date':9} {'points':>8} {'voxels':>7} {'L x W x H (m)':>19} "
        f"{'plants':>6} {'leaves':>6} {'truss':>5} {'fruits':>6} {'gen s':>6} {'corr':>8}"
    )
    print(f"seed {args.seed}, point spacing {args.spacing} m, voxels {args.voxel} m")
    for room in args.rooms:
        box = room_config(room).plant_box
        print(f"\n{room}: plant box {' x '.join(f'{v:.3f}' for v in box.extent)} m")
        print(head)
        prev = None
        times = []
        for k in range(len(DATES)):
            t0 = time.perf_counter()
            s = generate_row(room, seed=args.seed, session=k, point_spacing=args.spacing)
            dt = time.perf_counter() - t0
            times.append(dt)
            r = row_summary(s, args.voxel)
            ext = " x ".join(f"{v:.2f}" for v in r["extent"])
            corr = "-" if prev is None else str(row_correspondences(prev, s)[0].size)
            print(
                f"{room:6} {s.date:9} {r['points']:>8} {r['voxels']:>7} {ext:>19} "
                f"{r['plants']:>6} {r['leaves']:>6} {r['trusses']:>5} {r['fruits']:>6} {dt:>6.2f} {corr:>8}"
            )
            prev = s
        print(f"{room}: generation time per session {np.mean(times):.2f} s (max {np.max(times):.2f} s)")


if __name__ == "__main__":
    main()
