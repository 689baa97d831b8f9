"""``tpvp demo`` and ``tpvp plan``: one plant, from two scans to a plan."""

from __future__ import annotations

import json
import math
from pathlib import Path

from tpvp.cli_common import case_options, print_rows, print_warnings, resolved_config
from tpvp.errors import InputFileError
from tpvp.io import read_point_cloud
from tpvp.io.publish import staged_folder
from tpvp.io.units import plant_size_warning
from tpvp.pipeline.jit import compile_kernels, plant_pieces
from tpvp.scene.normalise import check_session_pair
from tpvp.scene.organs import LABEL_KINDS, check_organ_targets, organ_codes
from tpvp.scene.samples import load_sample
from tpvp.setcover.miss_model import coverage_statement
from tpvp.simulate.frontier import coverage_frontier, write_frontier_files
from tpvp.simulate.outputs import write_case_outputs
from tpvp.simulate.single_plant import build_scene, run_case, transfer
from tpvp.viz.background import drawing_pool

STAGES = ["compile", "scene", "warm-up NBV", "registration", "inflation", "visibility", "view selection",
          "path", "outputs"]


def _print_case(result, summary, folder, compile_seconds, pieces):
    rows = [("views (warm-up included)", f"{result.n_views}"),
            ("coverage of the oracle set", f"{100 * result.coverage:.2f} %"),
            *([("coverage per organ", ", ".join(f"{organ} {100 * value:.2f} %" for organ, value in
                                                result.organ_coverage.items()))] if result.organ_coverage else []),
            *([("true coverage, as the plan expects", coverage_statement(result.predicted_coverage,
                                                                         result.predicted_coverage_lower))]
              if math.isfinite(result.predicted_coverage) else []),
            ("path length", f"{result.path_length:.2f} m (planning frame; "
                            f"{summary['path_length_scan_m']:.3f} m in the scan frame)"),
            ("coverage after warm-up", f"{100 * result.coverage_captured:.2f} %"),
            ("Chamfer transferred vs coarse", f"{summary['chamfer_before_mm']:.2f} -> "
                                              f"{summary['chamfer_after_mm']:.2f} mm (planning frame)"),
            ("view selection", f"{len(result.planned_views)} views, optimal={result.selection.optimal}"
             + (f", {result.set_cover.n_dropped_infeasible} unreachable voxels dropped"
                if hasattr(result.set_cover, "n_dropped_infeasible") else f"; {result.selection.status}")),
            ("time: warm-up / registration", f"{result.timings['warm_up']:.2f} s / {result.timings['registration']:.2f} s"),
            ("time: planning (registration..path)", f"{result.timings['planning']:.2f} s"),
            ("time: numba compile / cache load", f"{compile_seconds:.2f} s (kernels: {', '.join(pieces)}; "
                                                 "not part of the run)")]
    rows += [(f"re-plan {i}", step.line()) for i, step in enumerate(result.replans, 1)]
    print_rows(rows, folder, "results, plan.csv in the scan frame, plan_normalised.csv, plan.json, config.yaml, "
                              "provenance.json, plan.png, coverage.png, recording.rrd")


def _print_frontier(frontier) -> None:
    print("coverage-effort frontier (plan per target on the prediction; optimum = perfect knowledge of "
          "today's plant):")
    table = frontier[["target", "views", "coverage", "path_length_m", "optimum_views", "optimum_coverage"]].copy()
    for column in ("coverage", "optimum_coverage"):
        table[column] = (100 * table[column]).map("{:.2f} %".format)
    print(table.to_string(index=False, float_format=lambda x: f"{x:.3g}"))


def _run_pair(previous, current, output, config, name="case", inputs=(), names=None, frontier=False,
              organs=(None, None)):
    from tqdm.auto import tqdm

    frontier_table = None
    # The drawing processes are forked first, before the bar's and the kernels' threads start.
    with staged_folder(output, inputs=inputs) as stage, drawing_pool() as pool, \
            tqdm(total=len(STAGES), desc="tpvp", unit="stage", leave=False, disable=None) as bar:
        def step(stage_name):
            bar.update(1)
            bar.set_postfix_str(stage_name)

        bar.set_postfix_str("compile")
        pieces = plant_pieces(config)
        compile_seconds = compile_kernels(*pieces)
        step("scene")
        scene = build_scene(previous, current, config, **({"names": names} if names else {}), organs=organs)
        shared = transfer(scene, config, progress=step)  # warm-up + registration, reused by the frontier
        result = run_case(scene, config, progress=step, transferred=shared)
        step("outputs")
        written = write_case_outputs(stage.folder, scene, result, config, name,
                                     extra_summary={"seconds_compile": compile_seconds}, pool=pool)
        summary = json.loads(written["results"].read_text())
        bar.update(1)
        if frontier:
            bar.set_postfix_str("frontier")
            frontier_table = coverage_frontier(scene, config, transferred=shared)
            write_frontier_files(stage.folder, frontier_table, name, pool)
    _print_case(result, summary, stage.destination, compile_seconds, pieces)
    if frontier_table is not None:
        _print_frontier(frontier_table)
        print("  (also frontier.csv, frontier.png)")
    reduction = scene.reduction
    for which in ("previous", "current"):
        if reduction[f"{which}_points_used"] < reduction[f"{which}_points"]:
            print(f"note: the {which} scan's {reduction[f'{which}_points']:,} points were reduced to "
                  f"{reduction[f'{which}_points_used']:,} voxel centroids at "
                  f"{1e3 * reduction['resolution_m']:g} mm (planning frame) before planning")
    print_warnings(result.warnings)
    return 0


def _demo(args) -> int:
    config = resolved_config(args)
    print("bundled real tomato (Pheno4D): previous session 2020-03-05, current 2020-03-06, "
          f"{config.view_space} view space, configuration {config.name!r}")
    return _run_pair(load_sample("tomato_0305"), load_sample("tomato_0306"), args.output, config,
                     name="tomato 03-05 -> 03-06", frontier=args.frontier)


def _labelled_scan(path, args):
    """``(points, units, organ codes or None)`` of a scan as ``--labels`` reads its labels."""
    points, labels, units = read_point_cloud(path, units=args.units, return_units=True, return_labels=True,
                                             drop_invalid=args.drop_invalid)
    if args.labels == "none":
        return points, units, None
    if labels is None:
        raise InputFileError(f"{path}: --labels {args.labels}: the scan has no label per point (a 'label' "
                             f"property of a PLY/PCD, or a fourth column of a text file)")
    return points, units, organ_codes(labels, args.labels)


def _plan(args) -> int:
    config = resolved_config(args)
    previous, previous_units, previous_organs = _labelled_scan(args.previous, args)
    check_organ_targets(config.selection.organ_target_values(), previous_organs, str(args.previous))
    current, current_units, current_organs = _labelled_scan(args.current, args)
    print(f"{args.previous.name}: units: {previous_units}; {args.current.name}: units: {current_units}")
    names = (str(args.previous), str(args.current))
    print_warnings(warning for warning in (plant_size_warning(previous, previous_units, names[0]),
                                            plant_size_warning(current, current_units, names[1])) if warning)
    check_session_pair(previous, current, names, units=(previous_units, current_units))  # before any work
    return _run_pair(previous, current, args.output, config, name=args.current.name,
                     inputs=(args.previous, args.current), names=names,
                     frontier=args.frontier, organs=(previous_organs, current_organs))


def demo_arguments(p) -> None:
    case_options(p, "outputs/demo")
    p.set_defaults(func=_demo)


def plan_arguments(p) -> None:
    p.add_argument("--previous", required=True, type=Path,
                   help="previous-session scan (ply/pcd/xyz/txt/pts/csv/obj/stl, optionally .gz)")
    p.add_argument("--current", required=True, type=Path,
                   help="current-session scan (same formats); in the simulator it is the ground truth")
    p.add_argument("--units", default="auto", choices=["auto", "m", "mm"],
                   help="units of the scans; auto: millimetres when the largest extent exceeds 10, and "
                        "says which it chose (default: %(default)s)")
    p.add_argument("--drop-invalid", action="store_true",
                   help="drop points with NaN or infinite coordinates instead of refusing the scan")
    p.add_argument("--labels", default="none", choices=["none", *LABEL_KINDS],
                   help="what the scans' point labels mean: organ (tpvp's organ codes: a Helios dataset), "
                        "pheno4d (0 soil, 1 stem, 2+ leaves), generated-row; with labels the results report "
                        "coverage per organ and --organ-targets can be met (default: %(default)s)")
    case_options(p, "outputs/plan")
    p.set_defaults(func=_plan)
