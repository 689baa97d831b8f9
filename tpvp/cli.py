"""Command line: ``tpvp demo`` and friends. A thin layer over the library.

Errors the user can fix (:class:`tpvp.errors.TpvpError`) are printed on one line, exit status 2.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from tpvp.errors import TpvpError


def _print_case(result, summary, written):
    rows = [("views (warm-up included)", f"{result.n_views}"),
            ("coverage of the oracle set", f"{100 * result.coverage:.2f} %"),
            ("path length", f"{result.path_length:.2f} m"),
            ("coverage after warm-up", f"{100 * result.coverage_warm_up:.2f} %"),
            ("Chamfer transferred vs coarse", f"{summary['chamfer_before_mm']:.2f} -> {summary['chamfer_after_mm']:.2f} mm"),
            ("set cover", f"{result.set_cover.objective:g} views, optimal={result.set_cover.optimal}, "
                          f"{result.set_cover.n_dropped_infeasible} unreachable voxels dropped"),
            ("time: warm-up / registration", f"{result.timings['warm_up']:.2f} s / {result.timings['registration']:.2f} s"),
            ("time: planning (inflation..path)", f"{result.timings['planning']:.2f} s")]
    width = max(len(k) for k, _ in rows)
    for key, value in rows:
        print(f"  {key:<{width}}  {value}")
    print(f"wrote {written['results'].parent}/ (results, plan.csv/json, plan.png, coverage.png, recording.rrd)")


def _run_pair(previous, current, output, view_space, initial_view, units="auto", name="case"):
    from tqdm.auto import tqdm

    from tpvp.experiments.single_plant import SinglePlantConfig, build_scene, run_case, write_case_outputs

    config = SinglePlantConfig(view_space=view_space, initial_view=initial_view)
    stages = ["scene", "warm-up NBV", "registration", "inflation", "visibility", "set cover", "path", "outputs"]
    with tqdm(total=len(stages), desc="tpvp", unit="stage", leave=False) as bar:
        bar.set_postfix_str("scene")
        scene = build_scene(previous, current, config)

        def step(stage):
            bar.update(1)
            bar.set_postfix_str(stage)

        result = run_case(scene, config, progress=step)
        step("outputs")
        written = write_case_outputs(output, scene, result, config, name)
        bar.update(1)
    _print_case(result, result.summary(), written)
    return 0


def _demo(args) -> int:
    from tpvp.scene.samples import load_sample

    print("bundled real tomato (Pheno4D): previous session 2020-03-05, current 2020-03-06, "
          f"{args.view_space} view space")
    return _run_pair(load_sample("tomato_0305"), load_sample("tomato_0306"), args.output, args.view_space,
                     args.initial_view, name="tomato 03-05 -> 03-06")


def _plan(args) -> int:
    from tpvp.io import read_point_cloud

    previous = read_point_cloud(args.previous, units=args.units)
    current = read_point_cloud(args.current, units=args.units)
    return _run_pair(previous, current, args.output, args.view_space, args.initial_view, name=args.current.name)


def _render(args) -> int:
    from tpvp.experiments.render_demo import RenderDemoConfig, run_render_demo
    from tpvp.io import atomic_write_text

    table, summary = run_render_demo(RenderDemoConfig(view_space=args.view_space, model=args.model))
    out = Path(args.output)
    atomic_write_text(out / "coverage_per_view.csv", table.to_csv(index=False))
    atomic_write_text(out / "summary.json", json.dumps(summary, indent=2) + "\n")
    print(f"bundled real tomato ({summary['sample']}): {summary['plant_voxels']} plant voxels at 2 mm, "
          f"{summary['table_voxels']} table voxels")
    print(f"oracle visible set over {summary['views']} {args.view_space} views: "
          f"{summary['oracle_voxels']} voxels ({args.model} sensor, "
          f"{summary['render_ms_per_view']:.1f} ms/view)")
    print(table[["view", "seen_voxels", "new_voxels", "coverage"]].to_string(
        index=False, formatters={"coverage": "{:.2%}".format}))
    print(f"wrote {out / 'coverage_per_view.csv'} and {out / 'summary.json'}")
    return 0


def _view_space(value: str) -> str:
    if value in ("hemisphere", "sphere") or Path(value).is_file():
        return value
    raise argparse.ArgumentTypeError(f"{value!r} is neither 'hemisphere', 'sphere' nor an existing file")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="tpvp", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)

    def common(p, output):
        p.add_argument("--output", default=output, help="output folder (default: %(default)s)")
        p.add_argument("--view-space", default="hemisphere", type=_view_space,
                       help="hemisphere (32 views, with table), sphere (63 views) or a file (default: %(default)s)")
        p.add_argument("--initial-view", type=int, default=17,
                       help="index of the initial view: 17 near-horizontal, 8 oblique, 21 near-top (default: %(default)s)")

    demo = sub.add_parser("demo", help="plan and execute on the bundled real tomato pair (no arguments needed)")
    common(demo, "outputs/demo")
    demo.set_defaults(func=_demo)
    plan = sub.add_parser("plan", help="plan the current session of your own plant from two scans")
    plan.add_argument("--previous", required=True, type=Path, help="previous-session scan (ply/pcd/xyz/txt/obj)")
    plan.add_argument("--current", required=True, type=Path,
                      help="current-session scan; in the simulator it is the ground truth")
    plan.add_argument("--units", default="auto", choices=["auto", "m", "mm"])
    common(plan, "outputs/plan")
    plan.set_defaults(func=_plan)
    render = sub.add_parser("render", help="render the bundled real tomato from every view; coverage per view")
    render.add_argument("--output", default="outputs/render")
    render.add_argument("--view-space", default="hemisphere", choices=["hemisphere", "sphere"])
    render.add_argument("--model", default="reference", choices=["reference", "pixel"],
                        help="sensor model (default: the authors' voxel-driven 'reference')")
    render.set_defaults(func=_render)
    return parser


def run_command(args, name: str) -> int:
    """Run ``args.func(args)``; a TpvpError becomes one line ``<name>: error: ...`` on stderr and
    exit status 2, Ctrl-C exit status 130 (outputs are written atomically, none is half-written)."""
    try:
        return args.func(args)
    except TpvpError as exc:
        print(f"{name}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{name}: interrupted; outputs are written atomically, none is half-written", file=sys.stderr)
        return 130


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    return run_command(args, f"tpvp {args.command}")


if __name__ == "__main__":
    sys.exit(main())
