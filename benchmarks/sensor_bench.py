"""Speed of the virtual sensor against OctoMap's castRay, measured in the same process.

Run from the repository root::

    python benchmarks/sensor_bench.py           # full mode (a few minutes, one full-image OctoMap view)
    python benchmarks/sensor_bench.py --quick   # about a minute

The anchor is OctoMap (``pyoctomap``, pinned in ``benchmarks/requirements.txt``) executing the same
two measurement models ray by ray from Python, on an OcTree holding exactly the voxels of our grid:

* ``reference``: one ``castRay`` per occupied voxel centre in the frustum (in front of the camera,
  0 <= u <= 1280, 0 <= v <= 720 with the D435 intrinsics), toward that centre; the distinct hits are
  the view's observation;
* ``pixel``: one ``castRay`` per pixel of the 1280 x 720 image (directions from
  :func:`tpvp.sensor.camera.pixel_ray_directions`).

Ours: :func:`tpvp.sensor.observe` (one view), :func:`tpvp.sensor.observe_many` and
:func:`tpvp.visibility.visibility_matrix` (many views). Figures are medians over repeats; ratios are
anchor / ours. Speed targets are reported here, never asserted by the unit tests.
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import textwrap
import time
from importlib import metadata
from pathlib import Path

import numpy as np

try:
    import tpvp  # noqa: F401
except ImportError:  # not installed: run from a checkout
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numba
import pandas as pd

from tpvp.errors import SensorError
from tpvp.scene import voxels
from tpvp.scene.grid import build_grid
from tpvp.scene.normalise import normalise_plant
from tpvp.scene.samples import load_sample
from tpvp.sensor.camera import D435, in_frustum, look_at_rotation, pixel_ray_directions
from tpvp.sensor.sensor import SensorConfig, observe, observe_many
from tpvp.viewspace.single_plant import load_view_space
from tpvp.visibility import visibility_matrix

try:
    import pyoctomap
except ImportError:  # the anchor is optional; our figures are still printed
    pyoctomap = None

GT_RES = 0.002  # ground-truth voxels of single plants (docs/single_plant.md#ground-truth)
COVER_RES = 0.004  # set-cover resolution of single plants
MAX_RANGE = 1.0
ORIGIN = np.zeros(3)
PIXEL_ANCHOR_LIMIT_S = 30.0  # slower than this: time a stride-2 subset and scale by the ray count

REFERENCE = SensorConfig(model="reference", max_range=MAX_RANGE)
PIXEL = SensorConfig(model="pixel", max_range=MAX_RANGE, pixel_stride=1)


# ------------------------------------------------------------------------------------ helpers

def log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def timed(fn, *args, **kwargs):
    gc.collect()
    gc.disable()
    try:
        t0 = time.perf_counter()
        out = fn(*args, **kwargs)
        return time.perf_counter() - t0, out
    finally:
        gc.enable()


def median_time(fn, repeats: int):
    """Median and minimum wall time of ``fn()`` over ``repeats`` calls (seconds)."""
    times = [timed(fn)[0] for _ in range(repeats)]
    return statistics.median(times), min(times)


def per_view_time(grid, positions, config, repeats: int):
    """Median (over repeats) of the mean time of one ``observe`` call over ``positions``."""
    def sweep():
        for p in positions:
            observe(grid, p, ORIGIN, config)

    med, best = median_time(sweep, repeats)
    return med / len(positions), best / len(positions)


def fmt_ms(seconds) -> str:
    if seconds is None:
        return "-"
    ms = seconds * 1e3
    if ms >= 100_000:
        return f"{seconds:,.0f} s"
    if ms >= 10_000:
        return f"{seconds:.1f} s"
    if ms >= 100:
        return f"{ms:,.0f} ms"
    if ms >= 10:
        return f"{ms:.1f} ms"
    if ms >= 1:
        return f"{ms:.2f} ms"
    return f"{ms:.3f} ms"


def fmt_ratio(r) -> str:
    if r is None:
        return "-"
    return f"{r:,.0f}x" if r >= 100 else f"{r:.1f}x"


def met_text(checks: list[tuple[str, bool]]) -> str:
    if not checks:
        return "-"
    failed = [name for name, ok in checks if not ok]
    return "yes" if not failed else "no (" + ", ".join(failed) + ")"


# ------------------------------------------------------------------------------------ scenes

def tomato_points() -> np.ndarray:
    return normalise_plant(load_sample("tomato_0306"), largest_side=0.24, table=False).points


def octree_of(grid):
    """OctoMap OcTree holding exactly ``grid``'s occupied voxels (verified; raises otherwise)."""
    res = grid.resolution
    tree = pyoctomap.OcTree(res)
    for c in grid.centres:
        tree.updateNode(c, True)
    # 1. every voxel of ours is an occupied node of the tree
    for c in grid.centres:
        node = tree.search(c)
        if node is None or not tree.isNodeOccupied(node):
            raise SystemExit(f"OctoMap tree check failed: voxel centre {c} is not occupied in the tree")
    # 2. the tree's occupied leaves, expanded to the finest level, are exactly our voxels
    cells = []
    leaves = 0
    for it in tree.begin_leafs():
        leaves += 1
        coord = np.asarray(it.getCoordinate(), dtype=np.float64)
        size = it.getSize()
        node = tree.search(coord)
        if node is None or not tree.isNodeOccupied(node):
            continue  # free leaves cannot exist (nothing was inserted as free), but do not count them
        n = round(size / res)
        k0 = np.floor((coord - size / 2) / res + 0.5).astype(np.int64)
        ii, jj, kk = np.meshgrid(*(np.arange(k0[a], k0[a] + n) for a in range(3)), indexing="ij")
        cells.append(np.stack([ii.ravel(), jj.ravel(), kk.ravel()], axis=1))
    cells = np.concatenate(cells) if cells else np.zeros((0, 3), dtype=np.int64)
    ours = np.sort(voxels.encode_keys(grid.keys))
    theirs = np.sort(voxels.encode_keys(cells))
    if len(theirs) != len(np.unique(theirs)) or not np.array_equal(ours, theirs):
        raise SystemExit(f"OctoMap tree check failed: {len(theirs)} occupied cells in the tree, "
                         f"{len(ours)} voxels in our grid, or different voxels")
    return tree, {"leaves": leaves, "cells": len(theirs), "num_leaf_nodes": tree.getNumLeafNodes()}


# ------------------------------------------------------------------------------------ anchor

def anchor_reference_view(tree, grid, position, look_at=ORIGIN):
    """OctoMap, reference model: one castRay per frustum voxel centre. Returns (seconds, hit keys)."""
    centres = grid.centres
    res = grid.resolution
    end = np.zeros(3)
    cast = tree.castRay
    t0 = time.perf_counter()
    rotation = look_at_rotation(position, look_at)
    targets = centres[in_frustum(centres, position, rotation, D435)]
    hits = []
    for c in targets:
        if cast(position, c - position, end, True, MAX_RANGE):
            hits.append(end.copy())
    seconds = time.perf_counter() - t0
    keys = np.floor(np.asarray(hits).reshape(-1, 3) / res).astype(np.int64)
    return seconds, np.unique(voxels.encode_keys(keys)), len(targets)


def anchor_pixel_view(tree, grid, position, stride, look_at=ORIGIN):
    """OctoMap, pixel model: one castRay per (strided) pixel. Returns (seconds, hit codes, rays)."""
    res = grid.resolution
    end = np.zeros(3)
    cast = tree.castRay
    t0 = time.perf_counter()
    rotation = look_at_rotation(position, look_at)
    directions = pixel_ray_directions(rotation, D435, stride)
    hits = []
    for d in directions:
        if cast(position, d, end, True, MAX_RANGE):
            hits.append(end.copy())
    seconds = time.perf_counter() - t0
    keys = np.floor(np.asarray(hits).reshape(-1, 3) / res).astype(np.int64)
    return seconds, np.unique(voxels.encode_keys(keys)), len(directions)


def our_codes(grid, position, config):
    return np.unique(voxels.encode_keys(grid.keys[observe(grid, position, ORIGIN, config)]))


def compare(ours: np.ndarray, theirs: np.ndarray):
    return len(ours), len(theirs), len(np.setxor1d(ours, theirs, assume_unique=True))


# ------------------------------------------------------------------------------------ numba start-up

_COLD_SCRIPT = textwrap.dedent("""
    import json, time
    import numpy as np
    t0 = time.perf_counter()
    from tpvp.scene.grid import build_grid
    from tpvp.sensor.sensor import SensorConfig, observe, observe_many
    t_import = time.perf_counter() - t0
    rng = np.random.default_rng(0)
    grid = build_grid(rng.integers(-20, 20, size=(400, 3)), 0.002)
    pos = np.array([0.3, 0.2, 0.25])
    out = {"import": t_import}
    for model in ("reference", "pixel"):
        cfg = SensorConfig(model=model)
        t0 = time.perf_counter(); observe(grid, pos, np.zeros(3), cfg)
        out["observe_" + model] = time.perf_counter() - t0
        t0 = time.perf_counter(); observe_many(grid, pos[None], np.zeros(3), cfg)
        out["observe_many_" + model] = time.perf_counter() - t0
    print(json.dumps(out))
""")


def cold_compile_times():
    """First calls in a fresh interpreter with an empty numba cache (= true compile times)."""
    with tempfile.TemporaryDirectory(prefix="tpvp-numba-cold-") as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        proc = subprocess.run([sys.executable, "-c", _COLD_SCRIPT], check=False, env=env, capture_output=True, text=True,
                              timeout=900)
    if proc.returncode != 0:
        return None, proc.stderr.strip().splitlines()[-1:] or ["failed"]
    return json.loads(proc.stdout.strip().splitlines()[-1]), None


# ------------------------------------------------------------------------------------ main

def load_average() -> str:
    if not hasattr(os, "getloadavg"):
        return "?"
    return " / ".join(f"{x:.2f}" for x in os.getloadavg())


def environment_lines(load_at_start: str) -> list[str]:
    def version(pkg):
        try:
            return metadata.version(pkg)
        except metadata.PackageNotFoundError:
            return "not installed"

    cpu_model = "?"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu_model = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    try:
        affinity = len(os.sched_getaffinity(0))
    except AttributeError:
        affinity = "?"
    try:
        threading_layer = numba.threading_layer()
    except ValueError:
        threading_layer = "not initialised"
    return [
        (f"python {platform.python_version()} | numpy {np.__version__} | numba {numba.__version__} | "
         f"pyoctomap {version('pyoctomap')} | tpvp {version('tpvp')}"),
        f"CPU: {cpu_model} | os.cpu_count() = {os.cpu_count()} | usable cores (affinity) = {affinity}",
        (f"numba threads = {numba.get_num_threads()} (NUMBA_NUM_THREADS = {numba.config.NUMBA_NUM_THREADS}) "
         f"| threading layer = {threading_layer}"),
        f"load average (1/5/15 min) at the start = {load_at_start}",
    ]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true",
                        help="fewer repeats, OctoMap pixel anchor on a stride-8 subset scaled up (~1 min)")
    parser.add_argument("--repeats", type=int, default=None, help="repeats per figure (default 15, quick 3)")
    parser.add_argument("--no-greenhouse", action="store_true", help="skip the optional greenhouse-row section")
    parser.add_argument("--greenhouse-pixel-views", type=int, default=None,
                        help="greenhouse pixel model: time this many views and scale to 800 (default 4, quick 0)")
    args = parser.parse_args(argv)
    quick = args.quick
    repeats = args.repeats or (3 if quick else 15)
    big_repeats = 1 if quick else 3  # the 800-view greenhouse matrix
    notes: list[str] = []
    rows: list[dict] = []
    agreement: list[dict] = []

    def add(measurement, ours=None, anchor=None, target="-", checks=(), ours_text=None, anchor_text=None):
        ratio = anchor / ours if (anchor is not None and ours) else None
        rows.append({
            "measurement": measurement,
            "ours": ours_text or fmt_ms(ours),
            "anchor": anchor_text or fmt_ms(anchor),
            "ratio": fmt_ratio(ratio),
            "target": target,
            "met": met_text([(n, f(ours, ratio)) for n, f in checks]) if ours is not None else "-",
        })
        return ratio

    t_start = time.perf_counter()
    load_at_start = load_average()
    log(f"sensor_bench: {'quick' if quick else 'full'} mode, {repeats} repeats")

    # ---------------------------------------------------------------- scene
    plant = tomato_points()
    grid = build_grid(voxels.voxelise(plant, GT_RES), GT_RES)
    grid4 = build_grid(voxels.voxelise(plant, COVER_RES), COVER_RES)
    hemi = load_view_space("hemisphere")
    sphere = load_view_space("sphere")
    scene_line = (f"scene: tomato_0306, largest side 0.24 m, no table; {grid.size} voxels at 2 mm, "
                  f"{grid4.size} at 4 mm; views at 0.4 m looking at the origin; max range {MAX_RANGE} m")

    # ---------------------------------------------------------------- numba start-up
    log("numba: first calls in this process ...")
    startup = []
    for name, fn in [
        ("observe, reference", lambda: observe(grid, hemi[0], ORIGIN, REFERENCE)),
        ("observe, pixel", lambda: observe(grid, hemi[0], ORIGIN, PIXEL)),
        ("observe_many, reference", lambda: observe_many(grid, hemi[:2], ORIGIN, REFERENCE)),
        ("observe_many, pixel", lambda: observe_many(grid, hemi[:2], ORIGIN, PIXEL)),
    ]:
        first, _ = timed(fn)
        second, _ = timed(fn)
        startup.append({"call": name, "first call (this process)": fmt_ms(first), "second call": fmt_ms(second)})
    cold = None
    if quick:
        notes.append("numba compile time from an empty cache: not measured in --quick mode")
    else:
        log("numba: cold compile in a fresh interpreter with an empty cache ...")
        cold, err = cold_compile_times()
        if cold is None:
            notes.append(f"numba cold-compile subprocess failed: {err}")
        else:
            for entry in startup:
                key = entry["call"].replace(", ", "_")
                entry["cold compile (empty cache)"] = fmt_ms(cold[key])
    # warm the remaining per-grid caches
    for g in (grid, grid4):
        for cfg in (REFERENCE, PIXEL):
            visibility_matrix(g, sphere[:2], ORIGIN, cfg)

    # ---------------------------------------------------------------- OctoMap tree
    tree = None
    tree_line = "OctoMap anchor: pyoctomap not installed (pip install -r benchmarks/requirements.txt); anchors skipped"
    if pyoctomap is not None:
        log("OctoMap: building and checking the tree ...")
        t_tree, (tree, info) = timed(octree_of, grid)
        tree_line = (f"OctoMap OcTree(0.002): {info['cells']} occupied cells = our {grid.size} voxels (checked "
                     f"voxel by voxel, both ways); {info['leaves']} leaf nodes after OctoMap's automatic pruning "
                     f"of full 2x2x2 blocks; built + checked in {t_tree:.2f} s")

    # ---------------------------------------------------------------- reference, one view
    log("reference model: ours ...")
    ref_ours, ref_best = per_view_time(grid, hemi, REFERENCE, repeats)
    ref_anchor = None
    if tree is not None:
        views = range(4) if quick else range(len(hemi))
        log(f"reference model: OctoMap on {len(views)} hemisphere views ...")
        times, n_targets, tot = [], [], [0, 0, 0]
        differing = 0
        for v in views:
            seconds, theirs, n = anchor_reference_view(tree, grid, hemi[v])
            times.append(seconds)
            n_targets.append(n)
            a, b, d = compare(our_codes(grid, hemi[v], REFERENCE), theirs)
            tot = [tot[0] + a, tot[1] + b, tot[2] + d]
            differing += d > 0
        ref_anchor = float(np.mean(times))
        agreement.append({"model": "reference", "views": f"hemisphere {len(views)}",
                          "rays/view": f"{np.mean(n_targets):,.0f}", "voxels ours": tot[0],
                          "voxels OctoMap": tot[1], "sym. difference": tot[2], "views differing": differing})
        notes.append(f"reference anchor = mean over {len(views)} hemisphere views of the Python castRay loop "
                     f"(frustum test included), {np.mean(n_targets):,.0f} rays per view")
        if not quick:
            log("reference model: agreement on the 31 lower sphere views ...")
            tot, differing = [0, 0, 0], 0
            for v in range(len(hemi), len(sphere)):
                _, theirs, _ = anchor_reference_view(tree, grid, sphere[v])
                a, b, d = compare(our_codes(grid, sphere[v], REFERENCE), theirs)
                tot = [tot[0] + a, tot[1] + b, tot[2] + d]
                differing += d > 0
            agreement.append({"model": "reference", "views": f"sphere {len(sphere) - len(hemi)} (rows 32-62)",
                              "rays/view": "frustum", "voxels ours": tot[0], "voxels OctoMap": tot[1],
                              "sym. difference": tot[2], "views differing": differing})
    add("reference: one view, 2 mm plant (observe, mean of 32 hemisphere views)", ref_ours, ref_anchor,
        "<= 1 ms & >= 35x", [("time", lambda o, r: o <= 1e-3), ("ratio", lambda o, r: r is not None and r >= 35)])
    notes.append(f"ours per view = median over {repeats} sweeps of the mean time per view over the 32 hemisphere "
                 f"views; best sweep: reference {fmt_ms(ref_best)}")

    # ---------------------------------------------------------------- pixel, one view
    log("pixel model: ours ...")
    pix_ours, pix_best = per_view_time(grid, hemi, PIXEL, repeats)
    notes.append(f"best sweep: pixel {fmt_ms(pix_best)}")
    pix_anchor = None
    if tree is not None:
        view = 0
        log("pixel model: OctoMap pilot (stride 8) ...")
        pilot_s, pilot_codes, pilot_rays = anchor_pixel_view(tree, grid, hemi[view], 8)
        full_rays = D435.width * D435.height
        predicted = pilot_s * full_rays / pilot_rays
        if quick:
            stride, seconds, theirs, n_rays = 8, pilot_s, pilot_codes, pilot_rays
        elif predicted > PIXEL_ANCHOR_LIMIT_S:
            stride = 2
            log(f"pixel model: OctoMap on a stride-2 subset (full view predicted {predicted:.0f} s) ...")
            seconds, theirs, n_rays = anchor_pixel_view(tree, grid, hemi[view], stride)
        else:
            stride = 1
            log(f"pixel model: OctoMap on one full view ({full_rays:,} rays, ~{predicted:.0f} s) ...")
            seconds, theirs, n_rays = anchor_pixel_view(tree, grid, hemi[view], stride)
        pix_anchor = seconds * full_rays / n_rays
        if stride == 1:
            notes.append(f"pixel anchor: one full 1280x720 view (hemisphere view {view}), {n_rays:,} castRay calls "
                         f"timed in full ({seconds * 1e6 / n_rays:.1f} us per ray)")
        else:
            notes.append(f"pixel anchor: ESTIMATED from a stride-{stride} subset of hemisphere view {view} "
                         f"({n_rays:,} of {full_rays:,} rays, {seconds:.2f} s) scaled by the ray count "
                         f"x{full_rays / n_rays:g}")
        cfg = SensorConfig(model="pixel", max_range=MAX_RANGE, pixel_stride=stride)
        a, b, d = compare(our_codes(grid, hemi[view], cfg), theirs)
        agreement.append({"model": "pixel" if stride == 1 else f"pixel, stride {stride}",
                          "views": f"hemisphere view {view}", "rays/view": f"{n_rays:,}", "voxels ours": a,
                          "voxels OctoMap": b, "sym. difference": d, "views differing": int(d > 0)})
        if not quick:
            log("pixel model: agreement at stride 8 on all 32 hemisphere views ...")
            cfg8 = SensorConfig(model="pixel", max_range=MAX_RANGE, pixel_stride=8)
            tot, differing = [0, 0, 0], 0
            for v in range(len(hemi)):
                _, theirs, n8 = anchor_pixel_view(tree, grid, hemi[v], 8)
                a, b, d = compare(our_codes(grid, hemi[v], cfg8), theirs)
                tot = [tot[0] + a, tot[1] + b, tot[2] + d]
                differing += d > 0
            agreement.append({"model": "pixel, stride 8", "views": f"hemisphere {len(hemi)}",
                              "rays/view": f"{n8:,}", "voxels ours": tot[0], "voxels OctoMap": tot[1],
                              "sym. difference": tot[2], "views differing": differing})
        one, _ = median_time(lambda: observe(grid, hemi[view], ORIGIN, PIXEL), repeats)
        notes.append(f"ours on the anchor's own view (hemisphere {view}), pixel model: {fmt_ms(one)}")
    add("pixel: one full 1280x720 view, 2 mm plant (observe, mean of 32 hemisphere views)", pix_ours, pix_anchor,
        "<= 2 ms & >= 5000x", [("time", lambda o, r: o <= 2e-3), ("ratio", lambda o, r: r is not None and r >= 5000)])

    # ---------------------------------------------------------------- visibility matrix, 63 views at 4 mm
    log("visibility matrices ...")
    for cfg in (REFERENCE, PIXEL):
        med, _ = median_time(lambda cfg=cfg: visibility_matrix(grid4, sphere, ORIGIN, cfg), repeats)
        add(f"{cfg.model}: visibility_matrix, 63 sphere views, 4 mm plant", med, None, "<= 50 ms",
            [("time", lambda o, r: o <= 0.05)])

    # ---------------------------------------------------------------- 32 hemisphere views at 2 mm
    for cfg, per_view_anchor in ((REFERENCE, ref_anchor), (PIXEL, pix_anchor)):
        anchor32 = per_view_anchor * len(hemi) if per_view_anchor is not None else None
        for name, fn in (("observe_many", lambda cfg=cfg: observe_many(grid, hemi, ORIGIN, cfg)),
                         ("visibility_matrix", lambda cfg=cfg: visibility_matrix(grid, hemi, ORIGIN, cfg))):
            med, _ = median_time(fn, repeats)
            add(f"{cfg.model}: {name}, 32 hemisphere views, 2 mm plant", med, anchor32)
    notes.append("anchor of the 32-view rows = 32 x the anchor's time per view")

    # ---------------------------------------------------------------- optional greenhouse row
    greenhouse_line = None
    try:
        from tpvp.synthetic import greenhouse
        has_row = hasattr(greenhouse, "generate_row")
    except ImportError:
        has_row = False
    if args.no_greenhouse:
        greenhouse_line = "greenhouse section skipped (--no-greenhouse)"
    elif not has_row:
        greenhouse_line = "greenhouse section skipped: tpvp.synthetic.greenhouse.generate_row is not available yet"
    else:
        from tpvp.scene.boxes import room_config

        log("greenhouse row: generating ...")
        t_gen, row = timed(greenhouse.generate_row, "room1", seed=0, session=0, point_spacing=0.01)
        t_grid, grid3 = timed(lambda: build_grid(voxels.voxelise(row.points, 0.03), 0.03))
        room = room_config("room1")
        positions = np.asarray(room.candidate_positions[:800], dtype=np.float64)
        look_ats = room.plant_box.sample_uniform(len(positions), rng=np.random.default_rng(0))
        inside = grid3.is_occupied(positions)
        if inside.any():
            positions, look_ats = positions[~inside], look_ats[~inside]
        greenhouse_line = (f"greenhouse: room1 session 0 (seed 0, 1 cm point spacing: {len(row.points):,} points, "
                           f"generated in {t_gen:.1f} s) -> {grid3.size:,} voxels at 3 cm (grid {t_grid:.2f} s); "
                           f"{len(positions)} views = first 800 room1 candidates"
                           + (f" minus {int(inside.sum())} inside occupied voxels" if inside.any() else "")
                           + ", look-at uniform in the plant box (seed 0), max range 2.0 m")
        n_views = len(positions)
        sample = args.greenhouse_pixel_views
        if sample is None:
            sample = 0 if quick else 4
        for model in ("reference", "pixel"):
            cfg = SensorConfig(model=model, max_range=2.0)
            # The reference model runs on all views; the pixel model (optional here) on the first
            # `sample` views, scaled up to all views, because a single pixel view can take tens of seconds.
            n = n_views if model == "reference" else min(sample, n_views)
            if n == 0:
                notes.append("greenhouse pixel model not timed (--quick, or --greenhouse-pixel-views 0)")
                continue
            try:
                visibility_matrix(grid3, positions[:1], look_ats[:1], cfg)  # warm the per-grid caches
                log(f"greenhouse row: {model} visibility matrix, {n} views ...")
                med, _ = median_time(lambda n=n, cfg=cfg: visibility_matrix(grid3, positions[:n], look_ats[:n], cfg,
                                                               progress=False),
                                     big_repeats if n == n_views else 1)
            except SensorError as exc:
                notes.append(f"greenhouse {model}: {exc}")
                continue
            label = f"{model}: visibility_matrix, {n_views} greenhouse views, 3 cm row"
            if n < n_views:
                label += f" (ESTIMATED: {n} views x {n_views / n:g})"
                notes.append(f"greenhouse pixel: {n} views took {fmt_ms(med)} in total, "
                             f"{fmt_ms(med / n)} per view on average")
                med = med * n_views / n
            add(label, med, None, "<= 30 s", [("time", lambda o, r: o <= 30.0)])
        notes.append(f"greenhouse reference row: median of {big_repeats} run(s)")

    # ---------------------------------------------------------------- report
    pd.set_option("display.width", 250)
    pd.set_option("display.max_colwidth", 200)

    def table(records) -> str:
        frame = pd.DataFrame(records).astype(str)
        for col in frame.columns:  # left-align every column (to_string right-aligns the values)
            width = max(len(col), frame[col].str.len().max())
            frame[col] = frame[col].str.ljust(width)
        return frame.to_string(index=False, justify="left")

    out = []
    out.append(f"tpvp sensor benchmark ({'quick' if quick else 'full'} mode, {repeats} repeats; "
               f"ratio = anchor / ours; anchor = OctoMap castRay from Python, same process)")
    out.extend(environment_lines(load_at_start))
    out.append(scene_line)
    out.append(tree_line)
    if greenhouse_line:
        out.append(greenhouse_line)
    out.append("")
    out.append(table(rows))
    out.append("")
    out.append("Numba start-up (not included above; the kernels are cached on disk after the first compile):")
    out.append(table(startup))
    if cold is not None:
        out.append(f"(cold compile measured in a fresh interpreter with an empty NUMBA_CACHE_DIR; "
                   f"importing tpvp.sensor there took {fmt_ms(cold['import'])})")
    if agreement:
        out.append("")
        out.append("Agreement of hit sets, ours vs OctoMap (voxel counts summed over the views):")
        out.append(table(agreement))
    out.append("")
    out.append("Notes:")
    out.extend(f"- {n}" for n in notes)
    out.append(f"- total benchmark wall time {time.perf_counter() - t_start:.0f} s; load average at the end "
               f"{load_average()} "
               "(a shared 2-core machine: other processes inflate every figure of ours)")
    print("\n".join(out), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
