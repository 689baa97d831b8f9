"""What one single-plant run leaves for a person and a robot: results, the plan in the scan's own
frame and in the planning frame, the resolved configuration with its provenance, figures and a
rerun recording."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

from tpvp.config import config_yaml
from tpvp.experiments.greenhouse import execute
from tpvp.io import atomic_write_text
from tpvp.io.plan import plan_table, write_plan
from tpvp.provenance import provenance
from tpvp.sensor.camera import look_at_rotations, rotation_to_quaternion
from tpvp.viz import plot_coverage, plot_plan, write_recording
from tpvp.viz.geometry import path_polyline, plan_geometry
from tpvp.viz.interactive import scene_3d
from tpvp.viz.rows import plot_row_paths


def plan_frames(scene, order, roles) -> tuple[dict, dict, dict]:
    """The executed views as plan tables in the scan frame and the planning frame, their frame
    descriptions and the transform between them."""
    space = scene.view_space
    positions, look_ats = space.positions[order], space.look_ats[order]
    rotations = look_at_rotations(positions, look_ats)
    matrix = scene.plant_from_scan
    scale = scene.scan_scale
    linear = matrix[:3, :3] / scale  # a proper rotation: scan -> planning frame
    # Inverse map p_scan = linear^T (p_plan - t) / scale; camera axes rotate with linear^T.
    to_scan = lambda p: (p - matrix[:3, 3]) @ linear / scale  # noqa: E731
    quats_plan = np.array([rotation_to_quaternion(r) for r in rotations]).reshape(-1, 4)
    quats_scan = np.array([rotation_to_quaternion(linear.T @ r) for r in rotations]).reshape(-1, 4)
    tables = {"scan": plan_table(to_scan(positions), to_scan(look_ats), quats_scan, roles),
              "normalised": plan_table(positions, look_ats, quats_plan, roles)}
    for table in tables.values():
        table.insert(1, "view_index", order)
    frames = {"scan": "the input scans' own frame, metres",
              "normalised": "planning frame: the current scan turned up-axis to +Z, scaled by "
                            f"{scale:.9g}, rotated about +Z and centred on its bounding box (plant_from_scan)"}
    extra = {"plant_from_scan": matrix.tolist(), "scale": scale,
             "plant_from_scan_note": "p_planning = M[:3, :3] @ p_scan + M[:3, 3]; the plan.csv views are in "
                                     "the scan frame, plan_normalised.csv in the planning frame"}
    return tables, frames, extra


def plan_3d(scene, result, title: str = ""):
    """An interactive (plotly) view of a plant plan: covered plant voxels (blue), observable but
    missed ones (red), the candidate views, the executed and planned views and the path."""
    geometry = plan_geometry(scene, result)
    plant = scene.grid.countable
    centres = scene.grid.centres
    covered, observable = geometry["covered"] & plant, geometry["observable"] & plant
    space = scene.view_space
    return scene_3d({"covered voxels": (centres[covered], "royalblue"),
                     "missed voxels (observable)": (centres[observable & ~covered], "red"),
                     "never observable": (centres[plant & ~observable], "lightgray")},
                    candidates=space.positions, executed=space.positions[result.executed_views],
                    selected=space.positions[result.planned_views], look_ats=space.look_ats[result.planned_views],
                    path_polyline=geometry["polyline"],
                    title=title or f"{result.n_views} views, {100 * result.coverage:.2f} % coverage")


def write_case_outputs(folder, scene, result, config, name: str = "case", extra_summary: dict | None = None) -> dict:
    """Results (JSON + CSV), the plan in both frames, ``config.yaml`` + ``provenance.json``, PNG
    figures and a rerun ``.rrd`` in ``folder``. A real session's scene (no ground truth: no
    ``grid``) has no coverage to report: its plan figure shows what was captured instead."""
    folder = Path(folder)
    simulated = getattr(scene, "grid", None) is not None
    order = result.order
    roles = ["initial"] + ["warm-up NBV"] * (len(result.executed_views) - 1) + ["planned"] * len(result.planned_views)
    tables, frames, extra = plan_frames(scene, order, roles)
    plans = write_plan(folder, tables, frames, extra)

    summary = {"name": name, "configuration": config.name, "view_space": config.view_space,
               "initial_view": order[0], **({"oracle_voxels": int(len(scene.oracle))} if simulated else {}),
               "scale_planning_per_scan_m": scene.scan_scale,
               "path_length_scan_m": result.path_length / scene.scan_scale,
               **{f"scan_{k}": v for k, v in (scene.reduction or {}).items()},
               **{k: v for k, v in result.summary().items() if simulated or not k.startswith("coverage")},
               **(extra_summary or {})}
    atomic_write_text(folder / "results.json", json.dumps(summary, indent=2, default=float) + "\n")
    atomic_write_text(folder / "results.csv", pd.DataFrame([summary]).to_csv(index=False))
    atomic_write_text(folder / "config.yaml", config_yaml(config, "resolved configuration of this run; "
                                                          "re-run with: tpvp plan/demo --config config.yaml"))
    seeds = {"registration": getattr(config.registration.embedded_deformation, "seed", None)}
    atomic_write_text(folder / "provenance.json", json.dumps(provenance(config, seeds), indent=2) + "\n")

    space = scene.view_space
    executed = space.positions[result.executed_views]
    if simulated:
        geometry = plan_geometry(scene, result)
        positions, polyline = geometry["positions"], geometry["polyline"]
    else:
        positions = space.positions[order]
        polyline = path_polyline(positions, *result.obstacle)
    shown = scene.current if simulated else result.clouds["coarse"]
    figures = [plot_plan(folder / "plan.png", shown, space.positions, executed, space.positions[result.planned_views],
                         polyline, f"{name}: {result.n_views} views"
                         + (f", {100 * result.coverage:.2f}% coverage, {result.path_length:.2f} m path" if simulated
                            else f", {result.path_length / scene.scan_scale:.3g} m path in the world frame "
                                 f"(drawn in the planning frame)"), obstacle=result.obstacle,
                         table_points=scene.table_points if len(scene.table_points) else None)]
    if simulated:
        plant = scene.grid.countable
        figures.append(plot_coverage(folder / "coverage.png", scene.grid.centres[plant], geometry["covered"][plant],
                                     geometry["observable"][plant], f"{name}: ground-truth voxels "
                                     f"({1e3 * config.gt_resolution:g} mm, planning frame)"))
    clouds = {"current_truth": (scene.current, (120, 120, 120))} if simulated else {}
    rrd = write_recording(
        folder / "recording.rrd",
        clouds={**clouds, "previous": (result.clouds["previous"], (220, 60, 60)),
                "coarse": (result.clouds["coarse"], (40, 90, 220)), "transferred": (result.clouds["warped"], (230, 140, 30)),
                "inflation": (result.clouds["inflation"], (40, 180, 60))},
        cameras={"warm_up_views": (positions[:len(result.executed_views)], space.look_ats[result.executed_views]),
                 "planned_views": (space.positions[result.planned_views], space.look_ats[result.planned_views])},
        paths={"global_path": polyline})
    return {"results": folder / "results.json", "plan": plans["scan"], "plan_normalised": plans["normalised"],
            "plan_json": plans["json"], "config": folder / "config.yaml", "provenance": folder / "provenance.json",
            "figures": figures, "recording": rrd}


def write_row_case_outputs(folder, scene, result, config, name: str = "row case", extra_summary: dict | None = None) -> dict:
    """What one greenhouse-row run leaves: results (JSON + CSV), the plan (passive sweep then the
    planned views, world frame), ``config.yaml`` + ``provenance.json``, the path from the top and
    the side, and a rerun ``.rrd``."""
    folder = Path(folder)
    room = scene.room
    positions = np.concatenate([room.initial_positions, result.positions])
    look_ats = np.concatenate([room.initial_look_ats, result.look_ats])
    roles = ["passive"] * len(room.initial_positions) + ["planned"] * len(result.selected)
    quaternions = np.array([rotation_to_quaternion(r) for r in look_at_rotations(positions, look_ats)]).reshape(-1, 4)
    table = plan_table(positions, look_ats, quaternions, roles)
    table.insert(1, "candidate_position", [-1] * len(room.initial_positions)
                 + result.candidates.position_ids[result.selected].tolist())
    plans = write_plan(folder, {"world": table}, {"world": f"{room.room} world frame (the room's boxes; metres)"})
    simulated = getattr(scene, "grid", None) is not None  # what a real session knows has no ground truth
    truth = {"oracle_voxels": int(len(scene.oracle)), "oracle_from_cache": scene.oracle_cached} if simulated else {}
    summary = {"name": name, "configuration": config.name, "room": room.room,
               "cover_resolution_m": config.selection.cover_resolution, **truth,
               **{k: v for k, v in result.summary().items() if simulated or not k.startswith("coverage")},
               **(extra_summary or {})}
    atomic_write_text(folder / "results.json", json.dumps(summary, indent=2, default=float) + "\n")
    atomic_write_text(folder / "results.csv", pd.DataFrame([summary]).to_csv(index=False))
    atomic_write_text(folder / "config.yaml", config_yaml(config, "resolved configuration of this run; "
                                                          "re-run with: tpvp greenhouse --config config.yaml"))
    atomic_write_text(folder / "provenance.json", json.dumps(provenance(config, {"seed": config.seed}), indent=2) + "\n")
    coverage = f"{100 * result.coverage:.2f} % coverage, " if simulated else ""
    plan_png = plot_row_paths(folder / "plan.png", room.plant_box, scene.current if simulated else scene.coarse,
                              {"Ours": (result.positions, f"{result.n_views} views (15 passive), "
                                        f"{coverage}{result.path_length:.1f} m")},
                              f"{name}: planned path (plant-box frame)")
    transfer = result.transfer
    truth_cloud = {"current_truth": (scene.current, (120, 120, 120))} if simulated else {}
    rrd = write_recording(
        folder / "recording.rrd",
        clouds={**truth_cloud, "previous": (scene.previous, (220, 60, 60)),
                "coarse": (transfer.coarse, (40, 90, 220)), "transferred": (transfer.alignment.warped, (230, 140, 30)),
                "inflation": (transfer.inflation.inflation, (40, 180, 60))},
        cameras={"passive_views": (room.initial_positions, room.initial_look_ats),
                 "planned_views": (result.positions, result.look_ats)},
        paths={"band_path": np.concatenate([room.initial_positions[-1:], result.positions])})
    return {"results": folder / "results.json", "plan": plans["world"], "plan_json": plans["json"],
            "config": folder / "config.yaml", "provenance": folder / "provenance.json", "figures": [plan_png],
            "recording": rrd}


def row_plan_3d(scene, result, title: str = ""):
    """An interactive (plotly) view of a row plan: the oracle voxels the passive sweep and the
    planned views covered (blue) and those they missed (red), the passive views (black), the
    planned views in execution order with their look-at rays, and the band path."""
    covered = np.union1d(execute(scene, result.positions, result.look_ats), scene.passive_seen)
    missed = np.setdiff1d(scene.oracle, covered)
    centres, room = scene.grid.centres, scene.room
    return scene_3d({"covered voxels": (centres[np.intersect1d(covered, scene.oracle)], "royalblue"),
                     "missed voxels (observable)": (centres[missed], "red")},
                    executed=room.initial_positions, selected=result.positions, look_ats=result.look_ats,
                    path_polyline=np.concatenate([room.initial_positions[-1:], result.positions]),
                    title=title or f"{result.n_views} views, {100 * result.coverage:.2f} % coverage")
