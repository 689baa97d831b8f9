"""Issue 27.5, "row registration moves what did not move": the warp-field registration of every
Table VI pair (generated rows of ``tpvp experiments rows --quick``: room1 and room4, sessions
k -> k+1 for k = 0..3, seed 0, 2 cm ground truth) before and after the fix, and an unchanged row.

old: the authors' correspondence search (every previous-session point to its nearest coarse point
within 0.5 m) on a coarse cloud Q of voxel *centres*; new: correspondences searched from Q onto the
previous session (``registration.warp_field.correspondences = coarse-to-previous``) on a Q of the
observed points' voxel centroids (``build_row_scene``). Per pair: symmetric Chamfer of the
previous session (before) and of the transferred model (after) to Q and to the full current
ground truth, and Ours (``run_row_case``) at the 4 cm covering voxel: views (15 passive included)
and oracle coverage. Prints a markdown table (about 1.5 min on 2 cores):

    PYTHONPATH=$PWD python benchmarks/row_registration_identity.py > benchmarks/results/row_registration_identity.md
"""

from __future__ import annotations

import sys
import time
from dataclasses import replace

import numpy as np

from tpvp.simulate.greenhouse import build_row_scene, run_row_case
from tpvp.simulate.row_cases import RowCase, quick_config
from tpvp.metrics.geometry import chamfer_distance
from tpvp.scene import voxels

ROOMS, PAIRS, SEED = ("room1", "room4"), range(4), 0


def variants(scene, config):
    """(label, scene, config) of the old and the new code on one scene."""
    old_wf = replace(config.registration.warp_field, correspondences="previous-to-coarse")
    old = replace(config, registration=replace(config.registration, warp_field=old_wf))
    return [("old", replace(scene, known=replace(scene.known, coarse=scene.grid.centres[scene.passive_seen])), old), ("new", scene, config)]


def measure(scene, config) -> dict:
    result = run_row_case(scene, config)
    alignment = result.transfer.alignment
    reduced = voxels.voxel_centroids(scene.previous, config.registration.warp_field.voxel)  # what was warped
    moved = np.linalg.norm(alignment.warped - reduced, axis=1)
    return {"cd_q": (1e3 * alignment.chamfer_before, 1e3 * alignment.chamfer_after),
            "cd_gt": (1e3 * chamfer_distance(scene.previous, scene.current),
                      1e3 * chamfer_distance(alignment.warped, scene.current)),
            "moved": moved, "views": result.n_views, "coverage": 100 * result.coverage}


def main() -> None:
    start = time.perf_counter()
    lines = ["| room | pair | code | Chamfer to Q before -> after (mm) | to full current GT before -> after (mm) "
             "| mean displacement (mm) | Ours views | Ours coverage (%) |",
             "|---|---|---|---|---|---|---|---|"]
    for room in ROOMS:
        for k in PAIRS:
            case = RowCase(room, k, SEED)
            config = quick_config({"view_space": room})
            previous, current = case.load()
            cases = [("", previous)] + ([("unchanged", current)] if k == 0 else [])
            for tag, before in cases:
                scene = build_row_scene(before, current, config, cache_dir=False)
                for label, variant, variant_config in variants(scene, config):
                    row = measure(variant, variant_config)
                    name = f"{k}->{k + 1}" + (f" ({tag}: {k + 1}->{k + 1})" if tag else "")
                    lines.append(f"| {room} | {name} | {label} | {row['cd_q'][0]:.2f} -> {row['cd_q'][1]:.2f} "
                                 f"| {row['cd_gt'][0]:.2f} -> {row['cd_gt'][1]:.2f} | {1e3 * row['moved'].mean():.2f} "
                                 f"| {row['views']} | {row['coverage']:.2f} |")
                    print(lines[-1], file=sys.stderr, flush=True)
    print("\n".join(lines))
    print(f"\n{time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
