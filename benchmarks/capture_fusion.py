"""Capture import measured (issue 38): the stand-in phone's captures fused and compared with the
generated truth, a plan made from a fused cloud beside the plan made from the truth, and the fusion
speed of a 1,000-frame 256 x 192 capture.

* accuracy: plants (tomato and maize, seeds 0-2, 120-frame orbits, ``--scale plant``: 5 mm voxels)
  and rows (room1 and room4, the handheld walk, ``--scale row``: 1 cm): the Chamfer distance of the
  fused cloud to the truth (all of it, and what the capture saw), both directed means, the F-score
  at 5 mm (precision: share of fused points within 5 mm of the truth; recall: share of the truth
  within 5 mm of the fused cloud) and the point counts; the three layouts of one plant capture,
  their largest difference. ``--noise PROFILE`` writes every stand-in capture with that sensor
  noise profile's depth and pose errors (tpvp.sensor.noise.apply_depth_noise, noise seed = the
  scene's seed); ``--drift-m M --drift-deg D`` replace that profile's drift (reached at the last
  frame); ``--refine-poses`` aligns every frame to the model fused so far before integrating it
  (tpvp.fusion.refine), and the accuracy table then gives the largest correction and the frames
  that kept their carried one; ``--plants-only`` measures the plants alone.
* plan: the same plants, today's session (``today.ply``: two days later, the same 0.4 m scale) planned
  by ``tpvp plan`` from the fused capture and from the generated previous session (``truth.ply``):
  views, true coverage, path length.
* speed: a 1,000-frame orbit written as a depth folder, then read and fused (``--scale plant``);
  the anchor is reading the same frames' depth and colour images alone, in the same process.

Usage:
    python benchmarks/capture_fusion.py [--modes accuracy plan speed] [--work DIR] [--noise PROFILE]
        [--drift-m M --drift-deg D] [--refine-poses] [--plants-only] [--results FILE]
Writes benchmarks/results/capture_fusion.md (capture_fusion_PROFILE[_driftMmm][_refined].md under a
noise profile other than ideal, a drift or refinement; or FILE) with this command and prints the tables.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import tempfile
import time
from pathlib import Path

import pandas as pd

from data_tools.capture.formats import FORMATS, load_colour, load_depth, read_capture
from data_tools.capture.fusion import fuse_capture, fusion_config
from data_tools.capture.phone_standin import plant_scene, row_scene, write_standin
from results_file import write_results
from tpvp.io import read_point_cloud, write_point_cloud
from tpvp.metrics.geometry import nearest_distances

RESULTS = Path(__file__).resolve().parent / "results" / "capture_fusion.md"
SIZE = 0.4  # m, the plants' largest side
F_SCORE_MM = 5.0
NOISE = {"profile": "ideal", "name": "ideal"}  # the stand-in captures' noise profile (--noise, --drift-*)
PLANTS_ONLY = {"on": False}
REFINE = {"on": False}  # --refine-poses


def _standin(output: Path, fmt: str, scene, seed: int = 0, progress: bool = False) -> Path:
    return write_standin(output, fmt, scene, progress=progress, noise=NOISE["profile"], noise_seed=seed)


def _distances(fused, truth) -> dict:
    there_all, back_all = nearest_distances(fused, truth), nearest_distances(truth, fused)
    there, back = there_all.mean(), back_all.mean()
    precision = float((there_all <= F_SCORE_MM / 1000).mean())
    recall = float((back_all <= F_SCORE_MM / 1000).mean())
    f_score = 2 * precision * recall / (precision + recall) if precision + recall else 0.0
    return {"fused_to_truth_mm": 1000 * there, "truth_to_fused_mm": 1000 * back, "chamfer_mm": 500 * (there + back),
            f"F@{F_SCORE_MM:g}mm %": 100 * f_score}


def _fused(folder: Path, scale: str, extra: dict | None = None):
    start = time.perf_counter()
    capture = read_capture(folder)
    fused = fuse_capture(capture, fusion_config(scale, refine_poses=REFINE["on"]), progress=False)
    if extra is not None and REFINE["on"]:
        largest = fused.largest_correction()
        extra.update({"largest correction mm": largest.translation_mm, "largest correction deg": largest.rotation_deg,
                      "frames kept": sum(c.status.startswith("kept") for c in fused.corrections)})
    return fused.points, len(capture.frames), time.perf_counter() - start


def accuracy(work: Path) -> list:
    rows, layouts = [], []
    for species in ("tomato", "maize"):
        for seed in (0, 1, 2):
            folder = _standin(work / f"{species}{seed}", "nerfstudio", plant_scene(species, seed, SIZE), seed)
            rows.append(_accuracy_row(f"{species} seed {seed}", folder, "plant"))
    title = (f"Fused cloud against the generated truth (noise {NOISE['name']}, poses "
             f"{'refined' if REFINE['on'] else 'as reported'})")
    if PLANTS_ONLY["on"]:
        return [(title, pd.DataFrame(rows))]
    prepared = []
    for room in ("room1", "room4"):
        folder = _standin(work / room, "polycam", row_scene(room, 0))
        rows.append(_accuracy_row(f"{room} row seed 0", folder, "row"))
        prepared.append(_prepared_row(room, folder, work))
    scene = plant_scene("tomato", 0, SIZE)
    clouds = {fmt: _fused(_standin(work / f"layout_{fmt}", fmt, scene), "plant")[0]
              for fmt in FORMATS}
    for fmt in FORMATS:
        layouts.append({"layout": fmt, "points": len(clouds[fmt]),
                        "largest difference to nerfstudio's (m)": float(nearest_distances(clouds[fmt],
                                                                                          clouds["nerfstudio"]).max())})
    return [(title, pd.DataFrame(rows)),
            ("One capture in three layouts (tomato seed 0)", pd.DataFrame(layouts)),
            ("A fused row through prepare-session (a new dataset: its reference day)", pd.DataFrame(prepared))]


def _prepared_row(room: str, folder: Path, work: Path) -> dict:
    """The fused row handed to ``prepare-session`` as a new site's first day: what it keeps."""
    from data_tools.sessions import prepare_session

    points, _, _ = _fused(folder, "row")
    scan = write_point_cloud(work / f"{room}_fused.ply", points)
    row = prepare_session(work / f"dataset_{room}", room, "2025-09-15", scan)
    kept = read_point_cloud(work / f"dataset_{room}" / row["file"], units="m")
    truth, seen = read_point_cloud(folder / "truth.ply", units="m", return_labels=True)
    return {"room": room, "fused points": len(points), "points after prepare-session": len(kept),
            **{f"prepared vs seen truth: {k}": v for k, v in _distances(kept, truth[seen == 1]).items()}}


def _accuracy_row(name: str, folder: Path, scale: str) -> dict:
    truth, seen = read_point_cloud(folder / "truth.ply", units="m", return_labels=True)
    extra = {}
    points, frames, seconds = _fused(folder, scale, extra)
    row = {"case": name, "scale": scale, "frames": frames, "fused points": len(points),
           "truth points seen %": 100 * float((seen == 1).mean()), "seconds": seconds, **extra}
    row.update({f"all: {k}": v for k, v in _distances(points, truth).items()})
    row.update({f"seen: {k}": v for k, v in _distances(points, truth[seen == 1]).items()})
    return row


def _plan(previous: Path, current: Path, output: Path) -> dict:
    from tpvp.cli import main

    if main(["plan", "--previous", str(previous), "--current", str(current), "--output", str(output),
             "--units", "m"]) != 0:
        raise SystemExit(f"tpvp plan failed on {previous}")
    table = pd.read_csv(output / "results.csv")
    return table.iloc[0][["views", "coverage", "path_length_m", "chamfer_after_mm"]].to_dict()


def plan(work: Path) -> list:
    rows = []
    for species in ("tomato", "maize"):
        for seed in (0, 1, 2):
            scene = plant_scene(species, seed, SIZE)
            capture = _standin(work / f"pair_{species}{seed}", "nerfstudio", scene, seed)
            fused, _, _ = _fused(capture, "plant")
            fused_file = write_point_cloud(work / f"pair_{species}{seed}_fused.ply", fused)
            from_truth = _plan(capture / "truth.ply", capture / "today.ply", work / f"plan_truth_{species}{seed}")
            from_fused = _plan(fused_file, capture / "today.ply", work / f"plan_fused_{species}{seed}")
            rows.append({"case": f"{species} seed {seed}", "previous points (truth / fused)":
                         f"{len(scene.points)} / {len(fused)}",
                         "views (truth)": from_truth["views"], "views (fused)": from_fused["views"],
                         "coverage % (truth)": 100 * from_truth["coverage"],
                         "coverage % (fused)": 100 * from_fused["coverage"],
                         "path m (truth)": from_truth["path_length_m"], "path m (fused)": from_fused["path_length_m"],
                         "registration Chamfer mm (truth / fused)":
                         f"{from_truth['chamfer_after_mm']:.2f} / {from_fused['chamfer_after_mm']:.2f}"})
    return [("tpvp plan of today's plant from the fused capture of the previous session and from its truth "
             "(hemisphere, paper)", pd.DataFrame(rows))]


def speed(work: Path) -> list:
    folder = _standin(work / "thousand", "depth", plant_scene("tomato", 0, SIZE, frames=1000), progress=True)
    capture = read_capture(folder)
    start = time.perf_counter()
    for frame in capture.frames:
        depth, _ = load_depth(frame)
        load_colour(frame, depth.shape)
    reading = time.perf_counter() - start
    points, frames, fusing = _fused(folder, "plant")
    k = capture.frames[0].intrinsics
    return [("Fusion speed", pd.DataFrame([{
        "frames": frames, "poses": "refined" if REFINE["on"] else "as reported",
        "depth pixels": f"{k.width} x {k.height}", "fused points": len(points),
        "fusion s (read + integrate + extract + support)": fusing, "reading the images alone s (anchor)": reading,
        "fusion / anchor": fusing / reading, "ms per frame": 1000 * fusing / frames}]))]


MODES = {"accuracy": accuracy, "plan": plan, "speed": speed}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--modes", nargs="+", default=list(MODES), choices=list(MODES))
    parser.add_argument("--work", type=Path, default=None, help="folder for the captures (default: a temporary one)")
    parser.add_argument("--noise", default="ideal", help="the stand-in captures' sensor noise profile: ideal, "
                                                        "arm-rgbd, phone-lidar (default: %(default)s)")
    parser.add_argument("--drift-m", type=float, default=None, help="the profile's drift, m (default: the profile's)")
    parser.add_argument("--drift-deg", type=float, default=None, help="the profile's drift, degrees")
    parser.add_argument("--refine-poses", action="store_true", help="refine every frame's pose before integrating it")
    parser.add_argument("--plants-only", action="store_true", help="accuracy: the plants alone (no rows, layouts)")
    parser.add_argument("--results", type=Path, default=None, help="the results file (default: see the usage)")
    args = parser.parse_args()
    from tpvp.errors import TpvpError
    from tpvp.sensor.noise import noise_profile

    try:
        profile = noise_profile(args.noise)
        drift = {k: v for k, v in (("drift_m", args.drift_m), ("drift_deg", args.drift_deg)) if v is not None}
        profile = dataclasses.replace(profile, **drift)
    except TpvpError as error:
        parser.error(str(error))
    name = args.noise + (f"_drift{1000 * profile.drift_m:g}mm{profile.drift_deg:g}deg" if drift else "")
    NOISE["profile"], NOISE["name"] = (args.noise if not drift else profile), name
    PLANTS_ONLY["on"], REFINE["on"] = args.plants_only, args.refine_poses
    suffix = name + ("_refined" if args.refine_poses else "")
    results = args.results or (RESULTS if suffix == "ideal" else RESULTS.with_name(f"capture_fusion_{suffix}.md"))
    with tempfile.TemporaryDirectory() as temporary:
        work = args.work or Path(temporary)
        tables = []
        for mode in args.modes:
            start = time.perf_counter()
            tables += MODES[mode](work)
            print(f"{mode}: {time.perf_counter() - start:.0f} s")
            for title, table in tables:
                print(f"\n{title}\n{table.to_string(index=False)}")
    write_results(results, tables, f"modes {', '.join(args.modes)}; noise {name}"
                                   f"{'; poses refined' if args.refine_poses else ''}"
                                   f"{'; plants only' if args.plants_only else ''}; on 2 cores")
    print(json.dumps({"results": str(results)}))


if __name__ == "__main__":
    main()
