"""Command line: ``tpvp demo`` and friends. A thin layer over the library.

Errors the user can fix (:class:`tpvp.errors.TpvpError`) are printed on one line, exit status 2.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from tpvp import __version__
from tpvp.config import config_yaml, derived_table, load_config, parse_overrides
from tpvp.cli_common import command_name, case_options, configuration_options, print_warnings, resolved_config
from tpvp.errors import TpvpError, install_warning_format, run_command
from tpvp.experiments import plants as plant_experiments
from tpvp.experiments import rows as row_experiments
from tpvp.experiments.frontier import coverage_frontier, write_frontier_files
from tpvp.experiments.greenhouse import build_row_scene, run_row_case
from tpvp.experiments.outputs import write_case_outputs, write_row_case_outputs
from tpvp.experiments.render_demo import RenderDemoConfig, run_render_demo
from tpvp.experiments.rows import QUICK, RowCase, dataset_cases
from tpvp.experiments.single_plant import build_scene, run_case, transfer
from tpvp.io import atomic_write_text, read_point_cloud
from tpvp.io.units import plant_size_warning
from tpvp.io.publish import staged_folder
from tpvp.jit import compile_kernels, plant_pieces
from tpvp.scene.boxes import ROOMS
from tpvp.scene.normalise import check_session_pair
from tpvp.scene.samples import load_sample
from tpvp.session.cli import add_session_parser
from tpvp.synthetic.scan import REFERENCES

STAGES = ["compile", "scene", "warm-up NBV", "registration", "inflation", "visibility", "view selection",
          "path", "outputs"]


def _print_case(result, summary, folder, compile_seconds, pieces):
    rows = [("views (warm-up included)", f"{result.n_views}"),
            ("coverage of the oracle set", f"{100 * result.coverage:.2f} %"),
            ("path length", f"{result.path_length:.2f} m (planning frame; "
                            f"{summary['path_length_scan_m']:.3f} m in the scan frame)"),
            ("coverage after warm-up", f"{100 * result.coverage_warm_up:.2f} %"),
            ("Chamfer transferred vs coarse", f"{summary['chamfer_before_mm']:.2f} -> "
                                              f"{summary['chamfer_after_mm']:.2f} mm (planning frame)"),
            ("view selection", f"{len(result.planned_views)} views, optimal={result.selection.optimal}"
             + (f", {result.set_cover.n_dropped_infeasible} unreachable voxels dropped"
                if hasattr(result.set_cover, "n_dropped_infeasible") else f"; {result.selection.status}")),
            ("time: warm-up / registration", f"{result.timings['warm_up']:.2f} s / {result.timings['registration']:.2f} s"),
            ("time: planning (inflation..path)", f"{result.timings['planning']:.2f} s"),
            ("time: numba compile / cache load", f"{compile_seconds:.2f} s (kernels: {', '.join(pieces)}; "
                                                 "not part of the run)")]
    _print_rows(rows, folder, "results, plan.csv in the scan frame, plan_normalised.csv, plan.json, config.yaml, "
                              "provenance.json, plan.png, coverage.png, recording.rrd")


def _print_rows(rows, folder, files: str) -> None:
    """A case's figures as aligned ``name  value`` lines, then what was written where."""
    width = max(len(k) for k, _ in rows)
    for key, value in rows:
        print(f"  {key:<{width}}  {value}")
    print(f"wrote {folder}/ ({files})")


def _print_frontier(frontier) -> None:
    print("coverage-effort frontier (plan per target on the prediction; optimum = perfect knowledge of "
          "today's plant):")
    table = frontier[["target", "views", "coverage", "path_length_m", "optimum_views", "optimum_coverage"]].copy()
    for column in ("coverage", "optimum_coverage"):
        table[column] = (100 * table[column]).map("{:.2f} %".format)
    print(table.to_string(index=False, float_format=lambda x: f"{x:.3g}"))


def _run_pair(previous, current, output, config, name="case", inputs=(), names=None, frontier=False):
    from tqdm.auto import tqdm

    frontier_table = None
    with staged_folder(output, inputs=inputs) as stage, \
            tqdm(total=len(STAGES), desc="tpvp", unit="stage", leave=False, disable=None) as bar:
        def step(stage_name):
            bar.update(1)
            bar.set_postfix_str(stage_name)

        bar.set_postfix_str("compile")
        pieces = plant_pieces(config)
        compile_seconds = compile_kernels(*pieces)
        step("scene")
        scene = build_scene(previous, current, config, **({"names": names} if names else {}))
        shared = transfer(scene, config, progress=step)  # warm-up + registration, reused by the frontier
        result = run_case(scene, config, progress=step, transferred=shared)
        step("outputs")
        written = write_case_outputs(stage.folder, scene, result, config, name,
                                     extra_summary={"seconds_compile": compile_seconds})
        summary = json.loads(written["results"].read_text())
        bar.update(1)
        if frontier:
            bar.set_postfix_str("frontier")
            frontier_table = coverage_frontier(scene, config, transferred=shared)
            write_frontier_files(stage.folder, frontier_table, name)
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


def _plan(args) -> int:
    config = resolved_config(args)
    previous, previous_units = read_point_cloud(args.previous, units=args.units, return_units=True,
                                                drop_invalid=args.drop_invalid)
    current, current_units = read_point_cloud(args.current, units=args.units, return_units=True,
                                              drop_invalid=args.drop_invalid)
    print(f"{args.previous.name}: units: {previous_units}; {args.current.name}: units: {current_units}")
    names = (str(args.previous), str(args.current))
    print_warnings(warning for warning in (plant_size_warning(previous, previous_units, names[0]),
                                            plant_size_warning(current, current_units, names[1])) if warning)
    check_session_pair(previous, current, names, units=(previous_units, current_units))  # before any work
    return _run_pair(previous, current, args.output, config, name=args.current.name,
                     inputs=(args.previous, args.current), names=names,
                     frontier=args.frontier)


def _render(args) -> int:
    with staged_folder(args.output) as stage:
        table, summary = run_render_demo(RenderDemoConfig(view_space=args.view_space, model=args.model),
                                         output=stage.folder)
        summary["depth_images"] = [Path(p).name for p in summary.get("depth_images", [])]
        atomic_write_text(stage.folder / "coverage_per_view.csv", table.to_csv(index=False))
        atomic_write_text(stage.folder / "summary.json", json.dumps(summary, indent=2) + "\n")
    out = stage.destination
    print(f"bundled real tomato ({summary['sample']}): {summary['plant_voxels']} plant voxels at 2 mm, "
          f"{summary['table_voxels']} table voxels")
    print(f"oracle visible set over {summary['views']} {args.view_space} views: "
          f"{summary['oracle_voxels']} voxels ({args.model} sensor, "
          f"{summary['render_ms_per_view']:.1f} ms/view)")
    print(table[["view", "seen_voxels", "new_voxels", "coverage"]].to_string(
        index=False, formatters={"coverage": "{:.2%}".format}))
    names = ["coverage_per_view.csv", "summary.json", *summary["depth_images"]]
    print(f"wrote {out}/ ({', '.join(names)})")
    return 0


def _show_config(args) -> int:
    config = resolved_config(args)
    print(config_yaml(config, f"resolved configuration {config.name!r} (setting: {config.setting})"), end="")
    if args.derived:
        print("# derived parameters (unless set explicitly):")
        for key, rule in derived_table(config.setting):
            print(f"#   {key} = {rule}")
    return 0


def _experiments_plants(args) -> int:
    config = resolved_config(args)
    cases = plant_experiments.default_cases(args.quick, args.dataset, args.plants, args.pairs, args.paper_subset,
                                            tuple(args.view_spaces), tuple(args.rotations), tuple(args.initial_views))
    methods = args.methods or list(plant_experiments.PLANT_METHODS.defaults())
    where = f"the Dask cluster {args.scheduler}" if args.scheduler else f"{args.workers} local worker(s)"
    print(f"{len(cases)} cases x {len(methods)} methods on {where}; cache {args.cache}")
    raw = plant_experiments.run_experiments(cases, methods, config, cache_dir=args.cache, workers=args.workers,
                                            scheduler=args.scheduler)
    comparison = plant_experiments.comparison_case(cases) if args.comparison else None
    written = plant_experiments.write_results(args.output, raw, config, comparison=comparison)
    print(plant_experiments.markdown(written["table1_coverage_effort"]))
    print(f"wrote {Path(args.output).absolute()}/ (raw_cases.csv, {', '.join(f'{n}.csv/.md' for n in written)}, "
          f"paper_values.csv, figures/{', comparison/' if comparison else ''})")
    return 0


def _row_config(args):
    if args.dataset is not None and args.reference:
        raise TpvpError(f"--reference applies to generated rows; the rows of {args.dataset} are used as they are")
    overrides = {"view_space": getattr(args, "room", "room1")}
    if args.cover_resolution is not None:
        overrides["selection.cover_resolution"] = args.cover_resolution
    if args.coverage_target is not None:
        overrides["selection.coverage_target"] = args.coverage_target
    if args.quick:
        overrides.update(QUICK)
    overrides.update(parse_overrides(args.set))
    config = load_config(args.config, overrides)
    if config.setting != "row":
        raise TpvpError(f"configuration {config.name!r} is for individual plants; use paper-row or a row YAML file")
    return config


def _greenhouse(args) -> int:
    from tqdm.auto import tqdm

    config = _row_config(args)
    if args.dataset is not None:
        cases = [c for c in dataset_cases(args.dataset) if c.room == args.room]
        if not cases:
            raise TpvpError(f"{args.dataset}: no two sessions of {args.room} to pair")
        if not 0 <= args.pair < len(cases):
            raise TpvpError(f"--pair {args.pair}: {args.dataset} has pairs 0..{len(cases) - 1} of {args.room}")
        case = cases[args.pair]
    else:
        if not 0 <= args.pair <= 3:
            raise TpvpError(f"--pair {args.pair}: a generated row has sessions 0..4, pairs 0..3")
        case = RowCase(args.room, args.pair, args.seed, reference=args.reference or "handheld")
    print(f"{case.name}: configuration {config.name!r}, covering voxel {100 * config.selection.cover_resolution:g} cm, "
          f"ground truth {100 * config.gt_resolution:g} cm")
    stages = ["scene and oracle", "registration", "inflation", "look-at targets", "visibility", "view selection",
              "path", "execution", "outputs"]
    inputs = case.files
    with staged_folder(args.output, inputs=inputs) as stage, \
            tqdm(total=len(stages), desc="tpvp greenhouse", unit="stage", leave=False, disable=None) as bar:
        def step(stage_name):
            bar.update(1)
            bar.set_postfix_str(stage_name)

        bar.set_postfix_str(stages[0])
        previous, current = case.load()
        scene = build_row_scene(previous, current, config, names=(f"{case.name} (previous)", f"{case.name} (current)"),
                                cache_dir=args.cache, date=case.date)
        result = run_row_case(scene, config, progress=step)
        step("outputs")
        write_row_case_outputs(stage.folder, scene, result, config, case.name)
    rows = [("views (15 passive included)", f"{result.n_views}"),
            ("coverage of the oracle set", f"{100 * result.coverage:.2f} % (passive sweep alone "
                                           f"{100 * result.coverage_passive:.2f} %)"),
            ("path length", f"{result.path_length:.2f} m (passive sweep {scene.room.passive_cost:.2f} m included; "
                            f"band path gap to its lower bound {100 * result.path.gap:.2f} %)"),
            ("Chamfer transferred vs coarse", f"{1e3 * result.transfer.alignment.chamfer_before:.2f} -> "
                                              f"{1e3 * result.transfer.alignment.chamfer_after:.2f} mm"),
            ("view selection", f"{len(result.selected)} of {len(result.candidates)} candidates, "
                               f"optimal={result.selection.optimal}"),
            ("time: oracle", f"{scene.timings['oracle']:.1f} s" + (" (from the cache)" if scene.oracle_cached else "")),
            ("time: registration / planning", f"{result.timings['registration']:.2f} s / {result.timings['planning']:.2f} s")]
    _print_rows(rows, stage.destination, "results.json/.csv, plan.csv, plan.json, config.yaml, provenance.json, "
                                         "plan.png, recording.rrd")
    print_warnings(result.warnings)
    return 0


def _experiments_rows(args) -> int:
    config = _row_config(args)
    cases = row_experiments.default_row_cases(args.quick, args.dataset, tuple(args.rooms),
                                              references=args.reference or ["handheld"])
    methods = args.methods or list(row_experiments.ALL_METHODS)
    where = f"the Dask cluster {args.scheduler}" if args.scheduler else f"{args.workers} local worker(s)"
    print(f"{len(cases)} cases x {len(methods)} methods on {where}; cache {args.cache}")
    raw = row_experiments.run_row_experiments(cases, methods, config, cache_dir=args.cache, workers=args.workers,
                                              scheduler=args.scheduler)
    written = row_experiments.write_results(args.output, raw, config)

    print(plant_experiments.markdown(written["table6_coverage_effort"]))
    print(f"wrote {Path(args.output).absolute()}/ (raw_cases.csv, {', '.join(f'{n}.csv/.md' for n in written)}, "
          f"paper_values.csv, figures/)")
    return 0


def _row_options(p, output, several_references: bool = False):
    configuration_options(p, output, "paper-row")
    p.add_argument("--dataset", type=Path, default=None,
                   help="a folder written by `python -m data_tools greenhouse clean` (Processed_3D_Model/"
                        "<room>_<date>.pcd; default: generated rows, offline)")
    p.add_argument("--reference", nargs="+" if several_references else None, default=None, choices=REFERENCES,
                   help="what of a generated row the reference holds: the complete row, what the room's candidate "
                        "positions see, or an emulated handheld phone capture" +
                        (" (several: each case once per reference, side by side in the tables)"
                         if several_references else "") + " (default: handheld; docs/greenhouse.md)")
    p.add_argument("--cover-resolution", type=float, default=None, metavar="M",
                   help="covering voxel of the set cover (paper: 0.10, 0.05, 0.04, 0.03; default: the "
                        "configuration's, 0.04)")
    p.add_argument("--quick", action="store_true",
                   help="coarse ground truth (2 cm), fewer covering voxels, budgets and draws, for a fast look")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="tpvp", description=__doc__.splitlines()[0])
    parser.add_argument("--version", action="version", version=f"tpvp {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    demo = sub.add_parser("demo", help="plan and execute on the bundled real tomato pair (no arguments needed)")
    case_options(demo, "outputs/demo")
    demo.set_defaults(func=_demo)
    plan = sub.add_parser("plan", help="plan the current session of your own plant from two scans")
    plan.add_argument("--previous", required=True, type=Path,
                      help="previous-session scan (ply/pcd/xyz/txt/pts/csv/obj/stl, optionally .gz)")
    plan.add_argument("--current", required=True, type=Path,
                      help="current-session scan (same formats); in the simulator it is the ground truth")
    plan.add_argument("--units", default="auto", choices=["auto", "m", "mm"],
                      help="units of the scans; auto: millimetres when the largest extent exceeds 10, and "
                           "says which it chose (default: %(default)s)")
    plan.add_argument("--drop-invalid", action="store_true",
                      help="drop points with NaN or infinite coordinates instead of refusing the scan")
    case_options(plan, "outputs/plan")
    plan.set_defaults(func=_plan)
    add_session_parser(sub)
    render = sub.add_parser("render", help="render the bundled real tomato from every view: coverage per view "
                                           "and depth images of a few views")
    render.add_argument("--output", default="outputs/render", help="output folder (default: %(default)s)")
    render.add_argument("--view-space", default="hemisphere", choices=["hemisphere", "sphere"],
                        help="hemisphere (with table) or sphere (no table) (default: %(default)s)")
    render.add_argument("--model", default="reference", choices=["reference", "pixel"],
                        help="sensor model (default: the authors' voxel-driven 'reference')")
    render.set_defaults(func=_render)
    experiments = sub.add_parser("experiments", help="the paper's experiments (tables, figures)")
    which = experiments.add_subparsers(dest="experiment", required=True)
    plant = which.add_parser("plants", help="individual plants: Tables I-IV, every baseline, the exact optimum")
    case_options(plant, "outputs/experiments/plants", case_options=False)
    plant.add_argument("--dataset", type=Path, default=None,
                       help="a folder written by `python -m data_tools pheno4d prepare` (default: generated "
                            "tomato and maize pairs plus the bundled real pair, offline)")
    plant.add_argument("--plants", nargs="+", default=None, help="only these plants of the dataset (e.g. Tomato01)")
    plant.add_argument("--pairs", nargs="+", type=int, default=None, help="only these rows of the dataset's pairs.csv")
    plant.add_argument("--paper-subset", action="store_true", help="plants 1-3 of each species, one pair each")
    plant.add_argument("--view-spaces", nargs="+", default=["hemisphere", "sphere"], help="(default: %(default)s)")
    plant.add_argument("--rotations", nargs="+", type=float, default=[0.0, 45.0], help="degrees about +Z (default: %(default)s)")
    plant.add_argument("--initial-views", nargs="+", type=int, default=[17, 8, 21], help="(default: %(default)s)")
    plant.add_argument("--methods", nargs="+", default=None,
                       help=f"methods to run ({plant_experiments.PLANT_METHODS.describe()})")
    plant.add_argument("--quick", action="store_true", help="a few cases: one tomato and one maize pair, rotation 0, view 17")
    plant.add_argument("--workers", type=int, default=2, help="parallel processes (default: %(default)s)")
    plant.add_argument("--scheduler", default=None, metavar="ADDRESS",
                       help="run the tasks on a Dask cluster, e.g. tcp://10.0.0.5:8786 (the cache folder must be "
                            "shared with its workers; default: local processes)")
    plant.add_argument("--no-comparison", dest="comparison", action="store_false",
                       help="skip the comparison figure (GMC, Ours and the exact optimum on the first sphere case, "
                            "with a rerun recording; about 30 s)")
    plant.add_argument("--cache", default="outputs/cache/plants",
                       help="cache folder of per-task rows; an interrupted run resumes (default: %(default)s)")
    plant.set_defaults(func=_experiments_plants)
    rows = which.add_parser("rows", help="greenhouse rows: Tables V-VI (Ours, random prior ladder, upper limits)")
    _row_options(rows, "outputs/experiments/rows", several_references=True)
    rows.add_argument("--rooms", nargs="+", default=list(ROOMS), choices=ROOMS, help="(default: %(default)s)")
    rows.add_argument("--methods", nargs="+", default=None,
                      help=f"methods to run (default: {', '.join(row_experiments.ALL_METHODS)}; also: "
                           f"{', '.join(sorted(set(row_experiments.ROW_METHODS.names()) - set(row_experiments.ALL_METHODS)))})")
    rows.add_argument("--workers", type=int, default=2, help="parallel processes (default: %(default)s)")
    rows.add_argument("--scheduler", default=None, metavar="ADDRESS",
                      help="run the tasks on a Dask cluster, e.g. tcp://10.0.0.5:8786 (default: local processes)")
    rows.add_argument("--cache", default="outputs/cache/rows",
                      help="cache folder of per-task rows and the oracles (default: %(default)s)")
    rows.set_defaults(func=_experiments_rows)
    green = sub.add_parser("greenhouse", help="plan and execute one greenhouse-row pair (generated by default)")
    _row_options(green, "outputs/greenhouse")
    green.add_argument("--room", default=ROOMS[0], choices=ROOMS, help="(default: %(default)s)")
    green.add_argument("--pair", type=int, default=0,
                       help="which consecutive pair: sessions K -> K+1 (default: %(default)s)")
    green.add_argument("--seed", type=int, default=0, help="seed of the generated row (default: %(default)s)")
    green.add_argument("--cache", default=None,
                       help="folder of cached oracles (default: $TPVP_CACHE_DIR or ~/.cache/tpvp)")
    green.set_defaults(func=_greenhouse)
    show = sub.add_parser("config", help="print the resolved configuration as YAML (save it, edit it, pass it "
                                         "back with --config)")
    case_options(show, None)
    show.add_argument("--derived", action="store_true", help="also list the derived parameters and their rules")
    show.set_defaults(func=_show_config)
    return parser


def main(argv=None) -> int:
    install_warning_format("tpvp")  # every warning one line, no module path or source line
    parser = build_parser()
    args = parser.parse_args(argv)
    return run_command(args, command_name(args))


if __name__ == "__main__":
    sys.exit(main())
