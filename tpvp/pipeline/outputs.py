"""What a plan leaves for a person and a robot, from what the planner knew: the results, the plan
(CSV + JSON; a plant's in the scan's own frame and in the planning frame, a row's in the room's
frame), the resolved configuration with its provenance, the plan figure and a rerun recording.

A simulated run adds what it measured on the ground truth (:class:`Measured`: the coverage, the
oracle, today's plant to draw under the plan, its own figures); a real session has none of it.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from tpvp.config_loading import config_yaml
from tpvp.io import atomic_write_text
from tpvp.io.plan import plan_table, write_plan
from tpvp.provenance import provenance
from tpvp.sensor.camera import look_at_rotations, rotation_to_quaternion
from tpvp.viz.background import draw
from tpvp.viz.geometry import path_polyline


@dataclass(frozen=True, eq=False)
class Measured:
    """What a simulated run measured of its plan on the ground truth: ``summary`` entries (the
    oracle's size, ...), today's plant (``plant``: drawn under the plan, recorded) and a function
    that lists the drawings of its own figures in the run's folder (:func:`tpvp.viz.background.draw`
    calls, each returning its file's path)."""

    summary: dict
    plant: np.ndarray
    figures: object = field(default=lambda folder: [])  # folder -> drawing calls (tpvp.viz.background)


def _results(result, measured: Measured | None) -> dict:
    """The result's summary; its coverages only where they were measured."""
    return {k: v for k, v in result.summary().items() if measured is not None or not k.startswith("coverage")}


def plan_frames(known, order, roles) -> tuple[dict, dict, dict]:
    """The executed views as plan tables in the scan frame and the planning frame, their frame
    descriptions and the transform between them."""
    space = known.view_space
    positions, look_ats = space.positions[order], space.look_ats[order]
    rotations = look_at_rotations(positions, look_ats)
    matrix = known.plant_from_scan
    scale = known.scan_scale
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


def write_plan_outputs(folder, known, result, config, name: str = "case", extra_summary: dict | None = None,
                       measured: Measured | None = None, pool=None) -> dict:
    """A plant plan (:class:`tpvp.pipeline.plan.PlanResult` planned on ``known``): results (JSON +
    CSV), the plan in both frames, ``config.yaml`` + ``provenance.json``, the plan figure and a
    rerun ``.rrd`` in ``folder``. Without ``measured`` the plan figure shows what was captured.
    The figures and the recording are drawn in ``pool`` (:func:`tpvp.viz.background.drawing_pool`)
    when one is given."""
    folder = Path(folder)
    order = result.order
    roles = ["initial"] + ["warm-up NBV"] * (len(result.executed_views) - 1) + ["planned"] * len(result.planned_views)
    tables, frames, extra = plan_frames(known, order, roles)
    plans = write_plan(folder, tables, frames, extra)

    summary = {"name": name, "configuration": config.name, "view_space": config.view_space,
               "initial_view": order[0], **(measured.summary if measured else {}),
               "scale_planning_per_scan_m": known.scan_scale,
               "path_length_scan_m": result.path_length / known.scan_scale,
               **{f"scan_{k}": v for k, v in (known.reduction or {}).items()},
               **_results(result, measured), **(extra_summary or {})}
    replans = [{"plan": f"re-plan {i}", **step.row()} for i, step in enumerate(result.replans, 1)]
    if replans:  # results.csv: the final plan's row, then one row per re-plan
        summary = {"plan": "final", **summary, "replan_steps": replans}
    _write_results(folder, summary, config, "tpvp plan/demo",
                   {"registration": getattr(config.registration.embedded_deformation, "seed", None)})

    space = known.view_space
    positions = space.positions[order]
    polyline = path_polyline(positions, *result.obstacle)
    shown = measured.plant if measured else result.clouds["coarse"]
    calls = [("tpvp.viz.figures:plot_plan", (folder / "plan.png", shown, space.positions, positions[:len(result.executed_views)],
                          space.positions[result.planned_views], polyline, f"{name}: {result.n_views} views"
                          + (f", {100 * result.coverage:.2f}% coverage, {result.path_length:.2f} m path" if measured
                             else f", {result.path_length / known.scan_scale:.3g} m path in the world frame "
                                  f"(drawn in the planning frame)")),
              {"obstacle": result.obstacle, "unit": "m" if measured else "planning units",
               "table_points": known.table_points if len(known.table_points) else None})]
    calls += measured.figures(folder) if measured else []
    truth = {"current_truth": (measured.plant, (120, 120, 120))} if measured else {}
    calls.append(("tpvp.viz.recording:write_recording", (folder / "recording.rrd",), dict(
        clouds={**truth, "previous": (result.clouds["previous"], (220, 60, 60)),
                "coarse": (result.clouds["coarse"], (40, 90, 220)), "transferred": (result.clouds["warped"], (230, 140, 30)),
                "inflation": (result.clouds["inflation"], (40, 180, 60))},
        cameras={"warm_up_views": (positions[:len(result.executed_views)], space.look_ats[result.executed_views]),
                 "planned_views": (space.positions[result.planned_views], space.look_ats[result.planned_views])},
        paths={"global_path": polyline})))
    *figures, rrd = draw(calls, pool)
    return {"results": folder / "results.json", "plan": plans["scan"], "plan_normalised": plans["normalised"],
            "plan_json": plans["json"], "config": folder / "config.yaml", "provenance": folder / "provenance.json",
            "figures": figures, "recording": rrd}


def write_row_plan_outputs(folder, known, result, config, name: str = "row case", extra_summary: dict | None = None,
                           measured: Measured | None = None, pool=None) -> dict:
    """A row plan (:class:`tpvp.pipeline.plan.PlanResult` planned on ``known``): results (JSON +
    CSV), the plan (passive sweep then the planned views, world frame), ``config.yaml`` +
    ``provenance.json``, the path from the top and the side, and a rerun ``.rrd`` (drawn in ``pool``
    when one is given)."""
    folder = Path(folder)
    room = known.room
    positions = np.concatenate([room.initial_positions, result.positions])
    look_ats = np.concatenate([room.initial_look_ats, result.look_ats])
    roles = ["passive"] * len(room.initial_positions) + ["planned"] * len(result.planned_views)
    quaternions = np.array([rotation_to_quaternion(r) for r in look_at_rotations(positions, look_ats)]).reshape(-1, 4)
    table = plan_table(positions, look_ats, quaternions, roles)
    table.insert(1, "candidate_position", [-1] * len(room.initial_positions)
                 + result.candidates.position_ids[result.planned_candidates].tolist())
    plans = write_plan(folder, {"world": table}, {"world": f"{room.room} world frame (the room's boxes; metres)"})
    summary = {"name": name, "configuration": config.name, "room": room.room,
               "cover_resolution_m": config.selection.cover_resolution, **(measured.summary if measured else {}),
               **_results(result, measured), **(extra_summary or {})}
    _write_results(folder, summary, config, "tpvp greenhouse", {"seed": config.seed})
    coverage = f"{100 * result.coverage:.2f} % coverage, " if measured else ""
    transfer = result.transfer
    truth = {"current_truth": (measured.plant, (120, 120, 120))} if measured else {}
    plan_png, rrd = draw([
        ("tpvp.viz.rows:plot_row_paths", (folder / "plan.png", room.plant_box,
                                          measured.plant if measured else known.coarse,
                                          {"Ours": (result.positions, f"{result.n_views} views (15 passive), "
                                                    f"{coverage}{result.path_length:.1f} m")},
                                          f"{name}: planned path (plant-box frame)"), {}),
        ("tpvp.viz.recording:write_recording", (folder / "recording.rrd",), dict(
            clouds={**truth, "previous": (known.previous, (220, 60, 60)), "coarse": (transfer.coarse, (40, 90, 220)),
                    "transferred": (transfer.alignment.warped, (230, 140, 30)),
                    "inflation": (result.clouds["inflation"], (40, 180, 60))},
            cameras={"passive_views": (room.initial_positions, room.initial_look_ats),
                     "planned_views": (result.positions, result.look_ats)},
            paths={"band_path": np.concatenate([room.initial_positions[-1:], result.positions])}))], pool)
    return {"results": folder / "results.json", "plan": plans["world"], "plan_json": plans["json"],
            "config": folder / "config.yaml", "provenance": folder / "provenance.json", "figures": [plan_png],
            "recording": rrd}


def _write_results(folder: Path, summary: dict, config, command: str, seeds: dict) -> None:
    """``results.json``, ``results.csv``, the resolved ``config.yaml`` and ``provenance.json``."""
    atomic_write_text(folder / "results.json", json.dumps(summary, indent=2, default=float) + "\n")
    steps = summary.get("replan_steps", [])
    row = {k: v for k, v in summary.items() if k != "replan_steps"}
    atomic_write_text(folder / "results.csv", pd.DataFrame([row, *steps]).to_csv(index=False))
    atomic_write_text(folder / "config.yaml", config_yaml(config, "resolved configuration of this run; "
                                                          f"re-run with: {command} --config config.yaml"))
    atomic_write_text(folder / "provenance.json", json.dumps(provenance(config, seeds), indent=2) + "\n")
